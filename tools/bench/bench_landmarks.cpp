// make bench: issue 19's cost row, the whole landmark path of a frame (sh_landmarks_track: the
// frame's band-pass, its pyramid, forward Lucas-Kanade from the markers' prediction, the
// photometric test, backward Lucas-Kanade from the prediction's inverse, the disagreement and
// neighbour tests) beside OpenCV doing the same work: the band-pass as two cv::boxFilter to float,
// a difference and a scaled conversion to 8 bits; cv::buildOpticalFlowPyramid of the band-passed
// frame (with its gradients when the backward search starts from it); cv::calcOpticalFlowPyrLK
// forward from the same predictions (OPTFLOW_USE_INITIAL_FLOW), and backward from the same
// inverse guesses; the same tests but the neighbours'. Both keep the reference's pyramid (with
// gradients), built once. Also without the backward test (its own row: ours with
// max_backward_px 0, OpenCV forward only, no gradients of the frame), and with the defaults of
// before 2026-12-06 (square forward windows, the backward search on every level, no test of the
// windows' centres, and no refined reference), beside the same OpenCV work. The defaults' forward
// windows are pre-warped by the map's local affine (sh_landmarks_params.affine), which OpenCV has
// no search for, and their backward search runs on the frame's level alone where OpenCV's runs on
// every level. And with four tags, the corners of the field: the landmarks chosen inside those
// four's hull, predicted by TPS on them, judged by the tests for sparse markers (sh_landmarks_params_sparse), beside
// OpenCV's two searches from the same predictions. The goal: at most 3 ms a 1080p frame
// with 200 landmarks on one thread, and at most OpenCV's time.
//
// Frames: the phantom renderer of this build (exvivo preset, paper rig, 1920x1080, seed 1, with
// the instrument and blood), FRAMES frames rendered into a temporary directory per run (about
// 2 s). The landmarks are chosen in frame 0 as the product chooses them: inside the hull of the
// truth's tag centres, off the tags' quads; min_distance MIN_DIST (the default, 14 px: 20 px
// leaves 126 on this patch). Each later frame's prediction is TPS on the truth's tag centres
// (timed on its own row: `stillheart track --landmarks` pays it each frame too). One thread
// (cv::setNumThreads(1)), thread CPU time, medians over every frame of PASSES replays, ours and
// OpenCV's interleaved frame by frame so that both see the same load. The checksum (FNV-1a of
// every frame's positions' bits and verdicts, first pass) says whether a change of the code
// changed a result. The reference is refined (sh_landmarks_params.refine) in the first pass's
// first 16 frames: their time is also printed apart, the medians are of every frame.
// Once per reference, choosing them (sh_landmarks_create: the mask of the hull, the tags and the
// highlights, the band-pass, Shi-Tomasi corners, the reference's pyramid and windows and the
// refinement's sums) beside OpenCV's band-pass, cv::goodFeaturesToTrack in the hull and
// cv::buildOpticalFlowPyramid with gradients: medians of CHOICES runs. It is what delays a new
// reference's landmarks in the daemon, whose markers alone stabilize its frames meanwhile
// (docs/landmarks.md, "Choosing them" and "The markers alone while they are chosen").
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/video/tracking.hpp>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <map>
#include <string>
#include <thread>
#include <vector>

#include <unistd.h>

#include "bench_detect_util.h"

extern "C" {
#include "stillheart/hull.h"
#include "stillheart/interp.h"
#include "stillheart/landmarks.h"
#include "stillheart/warp.h"
#include "stillheart/y4m.h"
}

static const int FRAMES = 40, PASSES = 3, POINTS = 200, CHOICES = 7;
static const double MIN_DIST = 14;

struct Marker {
    double c[2], q[8];
    bool visible;
};
typedef std::vector<std::map<int, Marker>> Truth; // per frame: id -> centre, quad

// markers.csv: frame,camera,id,point,x,y,visible,...; points 0-3 the quad's corners, c the centre
static Truth read_truth(const std::string &path, int frames)
{
    Truth t(frames);
    FILE *f = std::fopen(path.c_str(), "r");
    char line[512];
    if (!f || !std::fgets(line, sizeof line, f)) return t;
    while (std::fgets(line, sizeof line, f)) {
        int fr, cam, id, vis;
        char pt[8];
        double x, y;
        if (std::sscanf(line, "%d,%d,%d,%7[^,],%lf,%lf,%d", &fr, &cam, &id, pt, &x, &y, &vis) != 7 || cam != 0 ||
            fr < 0 || fr >= frames)
            continue;
        Marker &m = t[fr][id];
        if (pt[0] == 'c') {
            m.c[0] = x, m.c[1] = y, m.visible = vis != 0;
        } else if (pt[0] >= '0' && pt[0] <= '3') {
            m.q[2 * (pt[0] - '0')] = x, m.q[2 * (pt[0] - '0') + 1] = y;
        }
    }
    std::fclose(f);
    return t;
}

// OpenCV's band-pass of the same definition: 3x3 mean minus 11x11 mean (float), times the gain,
// around 128, to 8 bits (its borders reflect where ours clip the boxes: the same work).
static void cv_band(const cv::Mat &in, cv::Mat &fine, cv::Mat &coarse, cv::Mat &out, int band, double gain)
{
    cv::boxFilter(in, fine, CV_32F, cv::Size(3, 3));
    cv::boxFilter(in, coarse, CV_32F, cv::Size(2 * band + 1, 2 * band + 1));
    cv::subtract(fine, coarse, fine);
    fine.convertTo(out, CV_8U, gain, 128);
}

struct Timed {
    std::vector<double> ours, cv, ours_fwd, cv_fwd, ours_old, predict, ours4, cv4;
    std::vector<double> map_markers, map_lm, map_lm_exact; // the model's update, one thread
};

// The map's side of the landmarks' cost: a TPS warp model over frame 0's visible tag centres and
// every landmark after them (as the daemon's models hold them: its model stage), updated each frame
// through the tags the frame shows and the landmarks accepted (sh_warp_model_update_subset),
// against the same model's tags alone; grids refined in the update as `stillheart warp` does (the
// daemon refines on its helper), so after the first frames the medians are those of the refined
// grid and of its coarse level where a frame's map allows it (how many of each: printed).
struct MapTerms {
    sh_interp *interp = nullptr;
    sh_warp_model *model = nullptr;
    std::vector<int> ids; // the tags' ids, in the model's order
    int n = 0;            // tags + landmarks
    std::map<int, int> spacing; // updates per grid spacing used (the coarse level's or the grid's)
    ~MapTerms()
    {
        sh_warp_model_destroy(model);
        sh_interp_destroy(interp);
    }
    void build(const std::map<int, Marker> &frame0, const float *lref, int nl, double smoothing, int W, int H)
    {
        std::vector<double> xy, lambda;
        for (const auto &kv : frame0)
            if (kv.second.visible) ids.push_back(kv.first), xy.push_back(kv.second.c[0]), xy.push_back(kv.second.c[1]);
        lambda.assign(ids.size(), 0.0);
        for (int i = 0; i < nl; i++) xy.push_back(lref[2 * i]), xy.push_back(lref[2 * i + 1]), lambda.push_back(smoothing);
        n = (int)xy.size() / 2;
        sh_interp_params ip;
        sh_interp_params_default(&ip, SH_METHOD_TPS);
        sh_warp_options wo;
        sh_warp_options_default(&wo);
        bench_check("bench_landmarks", sh_interp_create_smoothed(&ip, xy.data(), n, lambda.data(), &interp), "map");
        bench_check("bench_landmarks", sh_warp_model_create(interp, xy.data(), n, W, H, &wo, &model), "map");
    }
    // frame t's update through its tags and, when xy is given, the accepted landmarks: ms
    double update(const std::map<int, Marker> &frame, const float *xy, const uint8_t *verdict)
    {
        std::vector<double> cur(2 * (size_t)n, 0.0);
        std::vector<unsigned char> use(n, 0);
        for (size_t k = 0; k < ids.size(); k++) {
            auto it = frame.find(ids[k]);
            if (it == frame.end() || !it->second.visible) continue;
            use[k] = 1, cur[2 * k] = it->second.c[0], cur[2 * k + 1] = it->second.c[1];
        }
        for (int i = 0; xy && i < n - (int)ids.size(); i++) {
            size_t k = ids.size() + (size_t)i;
            if (verdict[i] != SH_LANDMARK_ACCEPTED) continue;
            use[k] = 1, cur[2 * k] = xy[2 * i], cur[2 * k + 1] = xy[2 * i + 1];
        }
        double a = bench_now_ms();
        bench_check("bench_landmarks", sh_warp_model_update_subset(model, cur.data(), use.data()), "map update");
        const double ms = bench_now_ms() - a;
        spacing[sh_warp_model_grid_spacing(model)]++;
        return ms;
    }
    std::string grids() const
    {
        std::string s;
        for (const auto &kv : spacing) s += (s.empty() ? "" : ", ") + std::to_string(kv.second) + " on " + std::to_string(kv.first) + " px";
        return s;
    }
};

// The four visible markers of a frame nearest the corners of the field (least x+y, x-y, -x+y,
// -x-y), as tools/eval/corners.awk picks them for `make landmarks-table` and table2's 4-tag rows.
static std::vector<int> corner_ids(const std::map<int, Marker> &frame)
{
    std::vector<int> ids;
    const int sign[4][2] = {{1, 1}, {1, -1}, {-1, 1}, {-1, -1}};
    for (const auto &d : sign) {
        int pick = -1;
        double best = 0;
        for (const auto &kv : frame) {
            double v = d[0] * kv.second.c[0] + d[1] * kv.second.c[1];
            if (kv.second.visible && (pick < 0 || v < best)) best = v, pick = kv.first;
        }
        ids.push_back(pick);
    }
    return ids;
}

int main(int argc, char **argv)
{
    (void)argc;
    std::string rbin = bench_renderer("bench_landmarks", argv[0]);
    if (rbin.empty()) return 0;
    cv::setNumThreads(1);
    char dir[] = "/tmp/sh_bench_landmarks_XXXXXX";
    if (!mkdtemp(dir)) return 1;
    std::printf("rendering %d phantom frames (1920x1080, exvivo, seed 1, occlusions)...\n", FRAMES);
    std::fflush(stdout);
    std::string cmd = "'" + rbin + "' --preset exvivo --rig paper --cameras 1 --occlusions --seed 1 --quiet --frames " +
                      std::to_string(FRAMES) + " --out '" + dir + "' >/dev/null";
    if (std::system(cmd.c_str()) != 0) {
        std::fprintf(stderr, "bench_landmarks: the renderer failed: %s\n", cmd.c_str());
        return 1;
    }
    Truth truth = read_truth(std::string(dir) + "/markers.csv", FRAMES);
    sh_y4m_reader *rd = nullptr;
    bench_check("bench_landmarks", sh_y4m_reader_open((std::string(dir) + "/cam0.y4m").c_str(), &rd), "recording");
    const sh_y4m_header *hd = sh_y4m_reader_header(rd);
    const int W = hd->width, H = hd->height, full_range = sh_y4m_header_full_range(hd);
    const sh_pixfmt format = hd->format; // the header goes with the reader, closed below
    sh_image img;
    bench_check("bench_landmarks", sh_image_create(&img, hd->format, W, H), "frame");
    std::vector<cv::Mat> frames;
    for (int t = 0; t < FRAMES; t++) {
        bench_check("bench_landmarks", sh_y4m_reader_read(rd, &img), "frame");
        cv::Mat m(H, W, CV_8UC1);
        for (int y = 0; y < H; y++)
            std::memcpy(m.ptr(y), img.plane[0].data + (size_t)y * img.plane[0].stride, (size_t)W);
        frames.push_back(m);
    }
    sh_image_destroy(&img);
    sh_y4m_reader_close(rd);
    std::system((std::string("rm -rf ") + dir).c_str());

    // frame 0: the hull of the visible tags' centres, their quads, the landmarks
    std::vector<double> cxy, quads;
    for (const auto &kv : truth[0])
        if (kv.second.visible) {
            cxy.push_back(kv.second.c[0]), cxy.push_back(kv.second.c[1]);
            quads.insert(quads.end(), kv.second.q, kv.second.q + 8);
        }
    sh_hull hull;
    bench_check("bench_landmarks", sh_hull_compute(cxy.data(), (int)cxy.size() / 2, &hull), "hull");
    sh_landmarks_params lp;
    sh_landmarks_params_default(&lp);
    lp.highlight = sh_landmarks_highlight_level(format, full_range); // the renders' range, as the product takes it
    lp.max_points = POINTS;
    lp.min_distance = MIN_DIST;
    sh_landmarks_params lp_fwd = lp, lp_old = lp;
    lp_fwd.max_backward_px = 0;
    lp_old.affine = 0, lp_old.back_levels = -1, lp_old.core = 0, lp_old.refine = 0;
    sh_plane ref = {frames[0].ptr(), W, H, (int)frames[0].step};
    sh_landmarks *lm = nullptr, *lm_fwd = nullptr, *lm_old = nullptr;
    bench_check("bench_landmarks", sh_landmarks_create(&lp, &ref, &hull, quads.data(), (int)quads.size() / 8, &lm),
                "landmarks");
    bench_check("bench_landmarks",
                sh_landmarks_create(&lp_fwd, &ref, &hull, quads.data(), (int)quads.size() / 8, &lm_fwd), "landmarks");
    bench_check("bench_landmarks",
                sh_landmarks_create(&lp_old, &ref, &hull, quads.data(), (int)quads.size() / 8, &lm_old), "landmarks");
    // four tags (corners of the field): landmarks inside their hull, off every tag's quad (the
    // others are still drawn on the tissue), with the tests for sparse markers
    const std::vector<int> corners = corner_ids(truth[0]);
    std::vector<double> cxy4;
    for (int id : corners) cxy4.push_back(truth[0].at(id).c[0]), cxy4.push_back(truth[0].at(id).c[1]);
    sh_hull hull4;
    bench_check("bench_landmarks", sh_hull_compute(cxy4.data(), 4, &hull4), "hull of 4 tags");
    sh_landmarks_params lp4 = lp;
    sh_landmarks_params_sparse(&lp4);
    lp4.highlight = lp.highlight;
    sh_landmarks *lm4 = nullptr;
    bench_check("bench_landmarks", sh_landmarks_create(&lp4, &ref, &hull4, quads.data(), (int)quads.size() / 8, &lm4),
                "landmarks, 4 tags");
    const int n4 = sh_landmarks_count(lm4);
    const float *lref4 = sh_landmarks_reference(lm4);
    const int n = sh_landmarks_count(lm);
    const float *lref = sh_landmarks_reference(lm);
    MapTerms map_markers, map_lm, map_lm_exact;
    map_markers.build(truth[0], lref, 0, 0, W, H);
    map_lm.build(truth[0], lref, n, SH_LANDMARK_SMOOTHING, W, H);
    map_lm_exact.build(truth[0], lref, n, 0, W, H);
    double bx0 = W, bx1 = 0, by0 = H, by1 = 0;
    for (int i = 0; i < n; i++) {
        bx0 = std::min(bx0, (double)lref[2 * i]), bx1 = std::max(bx1, (double)lref[2 * i]);
        by0 = std::min(by0, (double)lref[2 * i + 1]), by1 = std::max(by1, (double)lref[2 * i + 1]);
    }

    // OpenCV's reference: band-passed with the gain ours chose the same way (the 99th percentile
    // of |fine - coarse| to 100 grey levels), its pyramid with gradients, once
    const sh_flow_params &fp = lp.flow;
    cv::Size win(fp.win, fp.win);
    cv::TermCriteria crit(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, fp.max_iter, fp.eps);
    cv::Mat fine, coarse, band, cv_band_ref;
    double gain;
    {
        cv::boxFilter(frames[0], fine, CV_32F, cv::Size(3, 3));
        cv::boxFilter(frames[0], coarse, CV_32F, cv::Size(2 * lp.band + 1, 2 * lp.band + 1));
        cv::Mat d = cv::abs(fine - coarse);
        std::vector<float> v(d.begin<float>(), d.end<float>());
        std::nth_element(v.begin(), v.begin() + (long)v.size() * 99 / 100, v.end());
        gain = std::min(16.0, std::max(1.0, 100.0 / (std::floor(v[v.size() * 99 / 100]) + 1)));
        cv_band(frames[0], fine, coarse, cv_band_ref, lp.band, gain);
    }
    // choosing the landmarks, once per reference (the header's last paragraph)
    std::vector<double> choose_ours, choose_cv;
    cv::Mat hull_mask = cv::Mat::zeros(H, W, CV_8UC1);
    {
        std::vector<cv::Point> poly;
        for (int i = 0; i < hull.count; i++) poly.emplace_back((int)std::lrint(hull.x[i]), (int)std::lrint(hull.y[i]));
        cv::fillConvexPoly(hull_mask, poly, cv::Scalar(255));
    }
    for (int k = 0; k < CHOICES; k++) {
        sh_landmarks *again = nullptr;
        double a = bench_now_ms();
        bench_check("bench_landmarks",
                    sh_landmarks_create(&lp, &ref, &hull, quads.data(), (int)quads.size() / 8, &again), "landmarks");
        choose_ours.push_back(bench_now_ms() - a);
        sh_landmarks_destroy(again);
        cv::Mat f, c, b;
        std::vector<cv::Point2f> pts;
        std::vector<cv::Mat> pyr;
        a = bench_now_ms();
        cv_band(frames[0], f, c, b, lp.band, gain);
        cv::goodFeaturesToTrack(b, pts, POINTS, lp.quality, MIN_DIST, hull_mask, 3, false);
        cv::buildOpticalFlowPyramid(b, pyr, win, fp.levels, true);
        choose_cv.push_back(bench_now_ms() - a);
    }
    // the sparse tests search more levels (sh_landmarks_params_sparse): their own reference pyramid
    std::vector<cv::Mat> cv_ref_pyr, cv_ref_pyr4, cv_cur_pyr;
    cv::buildOpticalFlowPyramid(cv_band_ref, cv_ref_pyr, win, fp.levels, true);
    cv::buildOpticalFlowPyramid(cv_band_ref, cv_ref_pyr4, win, lp4.flow.levels, true);
    std::vector<cv::Point2f> p0(n), p1(n), p2(n), q0(n4), q1(n4), q2(n4);
    for (int i = 0; i < n; i++) p0[i] = cv::Point2f(lref[2 * i], lref[2 * i + 1]);
    for (int i = 0; i < n4; i++) q0[i] = cv::Point2f(lref4[2 * i], lref4[2 * i + 1]);
    std::vector<uchar> cst, cst2;
    std::vector<float> cerr, cerr2;
    // OpenCV's searches of one frame on `levels` levels above it (ref: the reference's pyramid
    // of as many): its band-pass and pyramid (with gradients), forward from the predictions pred
    // of the points `from` into `to`, backward from the prediction's inverse into `back`
    auto cv_round_trip = [&](const cv::Mat &frame, const float *pred, const std::vector<cv::Point2f> &from,
                             std::vector<cv::Point2f> &to, std::vector<cv::Point2f> &back,
                             const std::vector<cv::Mat> &ref, int levels) {
        cv_band(frame, fine, coarse, band, lp.band, gain);
        cv::buildOpticalFlowPyramid(band, cv_cur_pyr, win, levels, true);
        for (size_t i = 0; i < from.size(); i++) to[i] = cv::Point2f(pred[2 * i], pred[2 * i + 1]);
        cv::calcOpticalFlowPyrLK(ref, cv_cur_pyr, from, to, cst, cerr, win, levels, crit,
                                 cv::OPTFLOW_USE_INITIAL_FLOW, fp.min_eig);
        for (size_t i = 0; i < from.size(); i++) back[i] = to[i] - (cv::Point2f(pred[2 * i], pred[2 * i + 1]) - from[i]);
        cv::calcOpticalFlowPyrLK(cv_cur_pyr, ref, to, back, cst2, cerr2, win, levels, crit,
                                 cv::OPTFLOW_USE_INITIAL_FLOW, fp.min_eig);
    };

    // the predictions: TPS on the truth's centres that frame t shares with frame 0
    sh_interp_params ip;
    sh_interp_params_default(&ip, SH_METHOD_TPS);
    std::vector<std::vector<float>> pred(FRAMES, std::vector<float>(2 * n));
    std::vector<float> xy(2 * std::max(n, n4)), pred4(2 * n4);
    std::vector<uint8_t> verdict(std::max(n, n4));
    long accepted4 = 0, judged4 = 0, frames4 = 0;
    Timed tm;
    uint64_t hash = 1469598103934665603ull;
    long accepted = 0, accepted_fwd = 0, accepted_old = 0, cv_accepted = 0, cv_accepted_fwd = 0, judged = 0, again = 0, again_frames = 0, whole = 0;
    for (int pass = 0; pass < PASSES; pass++)
        for (int t = 1; t < FRAMES; t++) {
            std::vector<double> r, c;
            for (const auto &kv : truth[t]) {
                auto it = truth[0].find(kv.first);
                if (!kv.second.visible || it == truth[0].end() || !it->second.visible) continue;
                r.push_back(it->second.c[0]), r.push_back(it->second.c[1]);
                c.push_back(kv.second.c[0]), c.push_back(kv.second.c[1]);
            }
            float *pr = pred[t].data();
            double a = bench_now_ms();
            bench_check("bench_landmarks", sh_interp_map_points(&ip, r.data(), c.data(), (int)r.size() / 2, lref, n, pr),
                        "prediction");
            tm.predict.push_back(bench_now_ms() - a);
            sh_plane cur = {frames[t].ptr(), W, H, (int)frames[t].step};
            sh_landmarks_counts cnt;

            // ours, with the backward test
            a = bench_now_ms();
            bench_check("bench_landmarks", sh_landmarks_track(lm, &cur, pr, xy.data(), verdict.data(), &cnt), "track");
            tm.ours.push_back(bench_now_ms() - a);
            if (pass == 0) {
                for (int i = 0; i < n; i++) {
                    uint32_t b[2];
                    std::memcpy(b, &xy[2 * i], sizeof b);
                    for (uint32_t v : {b[0], b[1], (uint32_t)verdict[i]})
                        for (int k = 0; k < 4; k++) hash = (hash ^ ((v >> (8 * k)) & 0xff)) * 1099511628211ull;
                }
                accepted += cnt.verdicts[SH_LANDMARK_ACCEPTED];
                judged += n;
                again += cnt.searched_again;
                again_frames += cnt.searched_again > 0;
                whole += cnt.whole_frame;
            }

            // the map through the tags, and through the tags and the accepted landmarks
            tm.map_markers.push_back(map_markers.update(truth[t], nullptr, nullptr));
            tm.map_lm.push_back(map_lm.update(truth[t], xy.data(), verdict.data()));
            tm.map_lm_exact.push_back(map_lm_exact.update(truth[t], xy.data(), verdict.data()));

            // OpenCV, with the backward search
            a = bench_now_ms();
            cv_round_trip(frames[t], pr, p0, p1, p2, cv_ref_pyr, fp.levels);
            long ok = 0;
            for (int i = 0; i < n; i++)
                ok += cst[i] && cst2[i] && cerr[i] <= lp.max_photometric &&
                      std::hypot(p2[i].x - p0[i].x, p2[i].y - p0[i].y) <= lp.max_backward_px &&
                      std::hypot(p1[i].x - pr[2 * i], p1[i].y - pr[2 * i + 1]) <= lp.max_disagreement_px;
            tm.cv.push_back(bench_now_ms() - a);
            if (pass == 0) cv_accepted += ok;

            // without the backward test
            a = bench_now_ms();
            bench_check("bench_landmarks", sh_landmarks_track(lm_fwd, &cur, pr, xy.data(), verdict.data(), &cnt),
                        "track");
            tm.ours_fwd.push_back(bench_now_ms() - a);
            if (pass == 0) accepted_fwd += cnt.verdicts[SH_LANDMARK_ACCEPTED];
            a = bench_now_ms();
            cv_band(frames[t], fine, coarse, band, lp.band, gain);
            cv::buildOpticalFlowPyramid(band, cv_cur_pyr, win, fp.levels, false);
            for (int i = 0; i < n; i++) p1[i] = cv::Point2f(pr[2 * i], pr[2 * i + 1]);
            cv::calcOpticalFlowPyrLK(cv_ref_pyr, cv_cur_pyr, p0, p1, cst, cerr, win, fp.levels, crit,
                                     cv::OPTFLOW_USE_INITIAL_FLOW, fp.min_eig);
            ok = 0;
            for (int i = 0; i < n; i++)
                ok += cst[i] && cerr[i] <= lp.max_photometric &&
                      std::hypot(p1[i].x - pr[2 * i], p1[i].y - pr[2 * i + 1]) <= lp.max_disagreement_px;
            tm.cv_fwd.push_back(bench_now_ms() - a);
            if (pass == 0) cv_accepted_fwd += ok;

            // the defaults before 2026-12-06: square windows, the backward search on every level
            a = bench_now_ms();
            bench_check("bench_landmarks", sh_landmarks_track(lm_old, &cur, pr, xy.data(), verdict.data(), &cnt),
                        "track");
            tm.ours_old.push_back(bench_now_ms() - a);
            if (pass == 0) accepted_old += cnt.verdicts[SH_LANDMARK_ACCEPTED];

            // four tags: the prediction from those of the corner tags that frame t shares with
            // frame 0 (three make an affine map), then ours with the sparse tests beside
            // OpenCV's forward and backward searches from the same predictions
            std::vector<double> r4, c4;
            for (int id : corners) {
                auto it = truth[t].find(id);
                if (it == truth[t].end() || !it->second.visible) continue;
                r4.push_back(truth[0].at(id).c[0]), r4.push_back(truth[0].at(id).c[1]);
                c4.push_back(it->second.c[0]), c4.push_back(it->second.c[1]);
            }
            if (r4.size() < 6) continue;
            bench_check("bench_landmarks",
                        sh_interp_map_points(&ip, r4.data(), c4.data(), (int)r4.size() / 2, lref4, n4, pred4.data()),
                        "prediction, 4 tags");
            a = bench_now_ms();
            bench_check("bench_landmarks", sh_landmarks_track(lm4, &cur, pred4.data(), xy.data(), verdict.data(), &cnt),
                        "track, 4 tags");
            tm.ours4.push_back(bench_now_ms() - a);
            if (pass == 0) accepted4 += cnt.verdicts[SH_LANDMARK_ACCEPTED], judged4 += n4, frames4++;
            a = bench_now_ms();
            cv_round_trip(frames[t], pred4.data(), q0, q1, q2, cv_ref_pyr4, lp4.flow.levels);
            tm.cv4.push_back(bench_now_ms() - a);
        }
    double load[3] = {0, 0, 0};
    if (getloadavg(load, 3) < 1) load[0] = -1;
    std::printf("machine: %u cores, load %.2f; frame %dx%d, %d landmarks (of %d asked, min_distance %.0f px) in "
                "%.0fx%.0f px of the frame, window %d, %d pyramid level(s) (%d with the sparse tests), band %d; one "
                "thread, medians of %zu frames "
                "(thread CPU time)\n",
                std::thread::hardware_concurrency(), load[0], W, H, n, POINTS, MIN_DIST, bx1 - bx0, by1 - by0, fp.win,
                fp.levels, lp4.flow.levels, lp.band, tm.ours.size());
    std::printf("%-40s %12s %12s %8s\n", "per frame", "stillheart", "OpenCV", "ratio");
    double o = bench_median(tm.ours), c = bench_median(tm.cv), of = bench_median(tm.ours_fwd),
           cf = bench_median(tm.cv_fwd);
    std::printf("%-40s %9.3f ms %9.3f ms %8.2f\n", "landmarks, with the backward test", o, c, o / c);
    std::printf("%-40s %9.3f ms %9.3f ms %8.2f\n", "landmarks, without it", of, cf, of / cf);
    const double oa = bench_median(tm.ours_old);
    std::printf("%-40s %9.3f ms %9.3f ms %8.2f\n", "landmarks, the defaults before 2026-12-06", oa, c, oa / c);
    const double o4 = bench_median(tm.ours4), c4 = bench_median(tm.cv4);
    std::printf("%-40s %9.3f ms %9.3f ms %8.2f\n", "landmarks, 4 tags, sparse tests", o4, c4, o4 / c4);
    {
        // the reference refined (sh_landmarks_params.refine) in the first frames of the first pass:
        // their cost apart, as a reference's first frames pay it once
        const size_t k = std::min(tm.ours.size(), (size_t)lp.refine);
        std::vector<double> during(tm.ours.begin(), tm.ours.begin() + (long)k), after(tm.ours.begin() + (long)k, tm.ours.end());
        if (k > 0 && !after.empty())
            std::printf("%-40s %9.3f ms (slowest %.3f ms; the frames after: %.3f ms)\n", "  while the reference is refined",
                        bench_median(during), *std::max_element(during.begin(), during.end()), bench_median(after));
    }
    std::printf("%-40s %9.3f ms\n", "the prediction (TPS on the tags)", bench_median(tm.predict));
    const double co = bench_median(choose_ours), cc = bench_median(choose_cv);
    std::printf("%-40s %9.3f ms %9.3f ms %8.2f\n", "choosing them, once per reference", co, cc, co / cc);
    std::printf("%-40s %9.3f ms %9.3f ms\n", "the slowest frame, with the backward test",
                *std::max_element(tm.ours.begin(), tm.ours.end()), *std::max_element(tm.cv.begin(), tm.cv.end()));
    std::printf("accepted of %ld landmark-frames: %ld ours (%ld without the backward test, %ld with the defaults "
                "before 2026-12-06), %ld OpenCV's tests but the neighbours' (%ld); checksum %016llx\n",
                judged, accepted, accepted_fwd, accepted_old, cv_accepted, cv_accepted_fwd, (unsigned long long)hash);
    std::printf("4 tags (ids %d %d %d %d, the corners of the field): %d landmarks, %ld accepted of %ld landmark-frames "
                "in %ld frames (the sparse tests; OpenCV's row: its two searches alone)\n",
                corners[0], corners[1], corners[2], corners[3], n4, accepted4, judged4, frames4);
    std::printf("searches that left the part of the frame built around the predictions, done again on a larger "
                "part: %ld in %ld of %d frames; the whole frame built in %ld\n",
                again, again_frames, FRAMES - 1, whole);
    const double mm = bench_median(tm.map_markers), ml = bench_median(tm.map_lm), mx = bench_median(tm.map_lm_exact);
    std::printf("the map's update (TPS model, %d tags and %d landmarks, %.0f a frame accepted; the updates' grids):\n",
                (int)map_markers.ids.size(), n, (double)accepted / (FRAMES - 1));
    std::printf("%-40s %9.3f ms (%s)\n", "  through the tags alone", mm, map_markers.grids().c_str());
    std::printf("%-40s %9.3f ms (%+.3f ms: the extra map terms; %s)\n", "  and the landmarks, smoothed (default)", ml, ml - mm,
                map_lm.grids().c_str());
    std::printf("%-40s %9.3f ms (%+.3f ms; %s)\n", "  and the landmarks, interpolated", mx, mx - mm, map_lm_exact.grids().c_str());
    std::printf("issue 19's goal, at most 3 ms and at most OpenCV's time: %s with the backward test, %s without it; "
                "with the extra map terms %.3f ms: %s\n",
                o <= 3 && o <= c ? "held" : "not held", of <= 3 && of <= cf ? "held" : "not held", o + ml - mm,
                o + ml - mm <= 3 ? "held" : "not held");
    sh_landmarks_destroy(lm);
    sh_landmarks_destroy(lm_fwd);
    sh_landmarks_destroy(lm_old);
    sh_landmarks_destroy(lm4);
    return 0;
}
