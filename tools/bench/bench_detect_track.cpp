// make bench: detection plus tracking per 1080p frame (what `stillheart track` and the daemon do
// each frame: the tracker's predict, its windows and one reacquisition band, AprilTag detection in
// them, the update) beside full-frame libapriltag detection with the library's default settings
// (decimate 2, refine edges, sharpening 0.25) on the same frames in the same run, one thread.
//
// Frames: the phantom renderer of this build (exvivo preset: 16 tag36h11 tags, 23 fps, one camera,
// 1920x1080). The tracker runs from frame 0 (its rates lock at ~4.2 s); frames from TIMED_FROM on
// are timed, each one by the full-frame detector and by the tracked pipeline, interleaved, thread
// CPU time, medians over PASSES replays. Found-all: in every timed frame, every tag the full-frame
// detection finds is among the pipeline's detections (same id, centre within 1 px).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <string>
#include <thread>
#include <vector>

#include <unistd.h>

#include "bench_detect_util.h"

extern "C" {
#include "stillheart/detect.h"
#include "stillheart/track.h"
#include "stillheart/y4m.h"
}

// Same id, same place (within 1 px): one tag seen by two overlapping windows (as cmd_track.c).
static int dedupe(sh_detection *d, int n)
{
    int w = 0;
    for (int i = 0; i < n; i++) {
        bool dup = false;
        for (int j = 0; j < w && !dup; j++)
            dup = d[j].id == d[i].id && std::fabs(d[j].cx - d[i].cx) < 1 && std::fabs(d[j].cy - d[i].cy) < 1;
        if (!dup) d[w++] = d[i];
    }
    return w;
}

struct Result {
    std::vector<double> full, track, detect_part, tracker_part;
    int frames = 0, found_all = 0, missed = 0, windows = 0;
    long px = 0;
    double err_sum = 0, err_max = 0, ferr_sum = 0, ferr_max = 0; // centres vs the phantom's truth
    long err_n = 0, ferr_n = 0;
};

// markers.csv: frame,camera,id,point,x,y,visible; the centres ("c") of camera 0
static std::vector<std::vector<std::pair<int, std::pair<double, double>>>> read_truth(const std::string &path,
                                                                                     int frames)
{
    std::vector<std::vector<std::pair<int, std::pair<double, double>>>> t(frames);
    FILE *f = std::fopen(path.c_str(), "r");
    char line[512];
    if (!f || !std::fgets(line, sizeof line, f)) return t;
    while (std::fgets(line, sizeof line, f)) {
        int fr, cam, id, vis;
        char pt[8];
        double x, y;
        if (std::sscanf(line, "%d,%d,%d,%7[^,],%lf,%lf,%d", &fr, &cam, &id, pt, &x, &y, &vis) == 7 &&
            cam == 0 && pt[0] == 'c' && vis && fr >= 0 && fr < frames)
            t[fr].push_back({id, {x, y}});
    }
    std::fclose(f);
    return t;
}

static void score(const sh_detection *d, int n, const std::vector<std::pair<int, std::pair<double, double>>> &truth,
                  double &sum, double &mx, long &cnt)
{
    for (int i = 0; i < n; i++)
        for (const auto &t : truth)
            if (t.first == d[i].id) {
                double e = std::hypot(d[i].cx - t.second.first, d[i].cy - t.second.second);
                sum += e;
                mx = std::max(mx, e);
                cnt++;
            }
}

// Over 80 lines: one benchmark read top to bottom: render, then three modes x PASSES replays in
// which the full-frame detector and the tracked pipeline are timed interleaved in one frame loop
// (the fairness of the comparison), then the table. It runs only in make bench.
int main(int argc, char **argv)
{
#ifndef SH_HAVE_APRILTAG
    (void)argc;
    (void)argv;
    std::printf("bench_detect_track: built without libapriltag, skipped\n");
    return 0;
#else
    (void)argc;
    std::string rbin;
    if (const char *env = std::getenv("STILLHEART_RENDER")) rbin = env;
    else {
        // $(BUILD)/bench/bench_detect_track -> $(BUILD)/stillheart-render
        std::string self = argv[0];
        size_t slash = self.rfind('/');
        rbin = (slash == std::string::npos ? std::string(".") : self.substr(0, slash)) + "/../stillheart-render";
    }
    if (access(rbin.c_str(), X_OK) != 0) {
        std::printf("bench_detect_track: no phantom renderer at %s (needs OSMesa), skipped\n", rbin.c_str());
        return 0;
    }
    const int FRAMES = 130, TIMED_FROM = 100, PASSES = 3;
    char dir[] = "/tmp/sh_bench_detect_track_XXXXXX";
    if (!mkdtemp(dir)) return 1;
    std::string cmd = "'" + rbin + "' --preset exvivo --rig paper --cameras 1 --quiet --frames " +
                      std::to_string(FRAMES) + " --out " + dir + " >/dev/null";
    std::printf("rendering %d phantom frames (1920x1080, exvivo, 16 tags)...\n", FRAMES);
    std::fflush(stdout);
    if (std::system(cmd.c_str()) != 0) {
        std::fprintf(stderr, "bench_detect_track: the renderer failed\n");
        return 1;
    }
    const std::string video = std::string(dir) + "/cam0.y4m";
    const auto truth = read_truth(std::string(dir) + "/markers.csv", FRAMES);

    static sh_detection full[1024], dets[SH_TRACK_MAX_DETECTIONS];
    sh_window win[SH_TRACK_MAX_MARKERS + 1];
    // windows at decimate 1, at decimate 2 (the daemon's), and at decimate 2 without an id list
    // (auto ids: one reacquisition band of the frame is scanned every frame as well)
    const double wdec[3] = {1, 2, 2};
    const bool listed[3] = {true, true, false};
    Result res[3];
    int W = 0, H = 0, tags = 0;
    double tag_px = 0, fps = 0;
    for (int mode = 0; mode < 3; mode++)
        for (int pass = 0; pass < PASSES; pass++) {
            sh_detector *fd, *wd;
            bench_check("bench_detect_track", sh_detector_create(nullptr, &fd), "detector"); // libapriltag's defaults
            sh_detector_options o;
            sh_detector_options_default(&o);
            o.window_decimate = wdec[mode];
            bench_check("bench_detect_track", sh_detector_create(&o, &wd), "detector");
            sh_y4m_reader *rd;
            bench_check("bench_detect_track", sh_y4m_reader_open(video.c_str(), &rd), "open");
            const sh_y4m_header *hd = sh_y4m_reader_header(rd);
            W = hd->width;
            H = hd->height;
            fps = (double)hd->fps_num / hd->fps_den;
            sh_image img;
            bench_check("bench_detect_track", sh_image_create(&img, hd->format, W, H), "image");
            sh_track_options to;
            sh_track_options_default(&to);
            to.fps = fps;
            to.width = W;
            to.height = H;
            int ids[16];
            for (int i = 0; i < 16; i++) ids[i] = i;
            to.ids = listed[mode] ? ids : nullptr;
            to.num_ids = listed[mode] ? 16 : 0;
            sh_tracker *t;
            bench_check("bench_detect_track", sh_tracker_create(&to, nullptr, &t), "tracker");
            Result &r = res[mode];
            for (int f = 0; f < FRAMES; f++) {
                bench_check("bench_detect_track", sh_y4m_reader_read(rd, &img), "read");
                bool timed = f >= TIMED_FROM;
                int nf = 0;
                if (timed) {
                    double t0 = bench_now_ms();
                    bench_check("bench_detect_track", sh_detector_detect(fd, &img, full, 1024, &nf), "full frame");
                    r.full.push_back(bench_now_ms() - t0);
                }
                // the tracked pipeline, as cmd_track.c runs it
                double t0 = bench_now_ms();
                bench_check("bench_detect_track", sh_tracker_predict(t, f), "predict");
                int nw = 0, nb = 0, n = 0;
                bench_check("bench_detect_track", sh_tracker_windows(t, 0, win, SH_TRACK_MAX_MARKERS, &nw), "windows");
                bench_check("bench_detect_track", sh_tracker_reacquire(t, 0, &win[nw], &nb), "reacquire");
                double t1 = bench_now_ms();
                if (f == 0 || nw == 0)
                    bench_check("bench_detect_track", sh_detector_detect(wd, &img, dets, SH_TRACK_MAX_DETECTIONS, &n), "detect");
                else
                    bench_check("bench_detect_track", sh_detector_detect_windows(wd, &img, win, nw + nb, dets, SH_TRACK_MAX_DETECTIONS, &n),
                          "detect windows");
                double t2 = bench_now_ms();
                if (n > SH_TRACK_MAX_DETECTIONS) n = SH_TRACK_MAX_DETECTIONS;
                n = dedupe(dets, n);
                const sh_detection *dp[1] = {dets};
                bench_check("bench_detect_track", sh_tracker_update(t, dp, &n, 1), "update");
                double t3 = bench_now_ms();
                if (!timed) continue;
                r.track.push_back(t3 - t0);
                r.detect_part.push_back(t2 - t1);
                r.tracker_part.push_back((t1 - t0) + (t3 - t2));
                r.frames++;
                sh_window scanned[SH_DETECT_MAX_WINDOWS];
                int ns = sh_detector_last_windows(wd, scanned, SH_DETECT_MAX_WINDOWS);
                r.windows += ns;
                for (int k = 0; k < ns && k < SH_DETECT_MAX_WINDOWS; k++)
                    r.px += (long)scanned[k].width * scanned[k].height;
                bool all = true;
                for (int i = 0; i < nf; i++) {
                    bool hit = false;
                    for (int j = 0; j < n && !hit; j++)
                        hit = dets[j].id == full[i].id && std::fabs(dets[j].cx - full[i].cx) < 1 &&
                              std::fabs(dets[j].cy - full[i].cy) < 1;
                    if (!hit) r.missed++;
                    all = all && hit;
                }
                r.found_all += all;
                score(dets, n, truth[f], r.err_sum, r.err_max, r.err_n);
                score(full, nf, truth[f], r.ferr_sum, r.ferr_max, r.ferr_n);
                if (mode == 0 && pass == 0 && f == TIMED_FROM) {
                    tags = nf;
                    for (int i = 0; i < nf; i++)
                        tag_px += std::hypot(full[i].corner[0][0] - full[i].corner[2][0],
                                             full[i].corner[0][1] - full[i].corner[2][1]) /
                                  std::sqrt(2.0) / nf;
                }
            }
            sh_track_stats st;
            sh_tracker_stats(t, &st);
            if (!st.locked) std::printf("  (warning: the tracker's rates had not locked by frame %d)\n", FRAMES);
            sh_tracker_destroy(t);
            sh_image_destroy(&img);
            sh_y4m_reader_close(rd);
            sh_detector_destroy(fd);
            sh_detector_destroy(wd);
        }
    std::system((std::string("rm -rf ") + dir).c_str());

    std::printf("machine: %u cores; one thread; %dx%d phantom frames at %.0f fps, %d tags of ~%.0f px "
                "found full frame; frames %d-%d timed (tracker locked), %d replays; medians of thread "
                "CPU time per frame\n",
                std::thread::hardware_concurrency(), W, H, fps, tags, tag_px, TIMED_FROM, FRAMES - 1, PASSES);
    for (int mode = 0; mode < 3; mode++) {
        const Result &r = res[mode];
        if (!listed[mode]) std::printf("  no id list, a reacquisition band every frame:\n");
        double fm = bench_median(r.full), tm = bench_median(r.track);
        std::printf("  windows at decimate %.0f: full-frame libapriltag (defaults) %6.2f ms, detect+track "
                    "%5.2f ms (detection %5.2f, tracker %4.2f), %4.1fx faster; %.1f windows, %.0f%% of the "
                    "frame scanned; every full-frame tag found in %d of %d frames (%d missed)\n",
                    wdec[mode], fm, tm, bench_median(r.detect_part), bench_median(r.tracker_part), fm / tm,
                    (double)r.windows / r.frames, 100.0 * r.px / ((double)r.frames * W * H), r.found_all,
                    r.frames, r.missed);
        std::printf("    centres against the phantom's truth: windows mean %.3f px (max %.3f), full frame "
                    "mean %.3f px (max %.3f)\n",
                    r.err_sum / std::max(1L, r.err_n), r.err_max, r.ferr_sum / std::max(1L, r.ferr_n), r.ferr_max);
    }
    return 0;
#endif
}
