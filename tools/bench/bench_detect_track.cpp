// make bench: detection plus tracking per frame (what `stillheart track` and the daemon do each
// frame: the tracker's predict, its windows and one reacquisition band, AprilTag detection in
// them, the update) beside full-frame libapriltag detection with the library's default settings
// (decimate 2, refine edges, sharpening 0.25) on the same frames in the same run, one thread.
//
// Frames: the phantom renderer of this build (exvivo preset, tag36h11 tags, 23 fps, one camera),
// twice: 1920x1080 with the preset's 16 tags, and 3840x2160 with 32 (issue 20's 4K endoscopes).
// The tracker runs from frame 0 (its rates lock at ~4.2 s); frames from timed_from on are timed,
// each one by the full-frame detector and by the tracked pipeline, interleaved, thread CPU time,
// medians over PASSES replays. Found-all: in every timed frame, every tag the full-frame detection
// finds is among the pipeline's detections (same id, centre within 1 px).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <string>
#include <thread>
#include <utility>
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

typedef std::vector<std::vector<std::pair<int, std::pair<double, double>>>> Truth; // per frame: id, centre

// markers.csv: frame,camera,id,point,x,y,visible; the centres ("c") of camera 0
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

// One recording and how it is replayed.
struct Recording {
    std::string video;
    Truth truth;
    int loop;       // frames in the file: a longer replay wraps round (periodic recordings only)
    int frames;     // frames replayed, the tracker running from frame 0
    int timed_from; // first timed frame: after the rates lock
    int num_ids;    // the listed ids, 0..num_ids-1
};

// windows at decimate 1, at decimate 2 (the daemon's), and at decimate 2 without an id list
// (auto ids: one reacquisition band of the frame is scanned every frame as well)
static const double wdec[3] = {1, 2, 2};
static const bool listed[3] = {true, true, false};

// The scan of a timed frame: what the windows covered, whether every full-frame tag is among the
// pipeline's, and both sets of centres against the truth.
static void score_frame(Result &r, const sh_detector *wd, const sh_detection *full, int nf, const sh_detection *dets,
                        int n, const std::vector<std::pair<int, std::pair<double, double>>> &truth)
{
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
    score(dets, n, truth, r.err_sum, r.err_max, r.err_n);
    score(full, nf, truth, r.ferr_sum, r.ferr_max, r.ferr_n);
}

// What the header line tells about the frames: their size and rate, and the tags of the first
// timed frame as the full-frame detector sees them.
struct Seen {
    int W = 0, H = 0, tags = 0;
    double fps = 0, tag_px = 0;
    bool unlocked = false;
};

// Over 80 lines: one replay read top to bottom, the full-frame detector and the tracked pipeline
// timed interleaved in one frame loop (the fairness of the comparison); the pipeline is the one of
// cmd_track.c, and splitting it would hide the timing points between its calls.
static void replay(const Recording &rec, int mode, Result &r, Seen &seen)
{
    static sh_detection full[1024], dets[SH_TRACK_MAX_DETECTIONS];
    sh_window win[SH_TRACK_MAX_MARKERS + 1];
    sh_detector *fd, *wd;
    bench_check("bench_detect_track", sh_detector_create(nullptr, &fd), "detector"); // libapriltag's defaults
    sh_detector_options o;
    sh_detector_options_default(&o);
    o.window_decimate = wdec[mode];
    bench_check("bench_detect_track", sh_detector_create(&o, &wd), "detector");
    sh_y4m_reader *rd;
    bench_check("bench_detect_track", sh_y4m_reader_open(rec.video.c_str(), &rd), "open");
    const sh_y4m_header *hd = sh_y4m_reader_header(rd);
    seen.W = hd->width;
    seen.H = hd->height;
    seen.fps = (double)hd->fps_num / hd->fps_den;
    sh_image img;
    bench_check("bench_detect_track", sh_image_create(&img, hd->format, seen.W, seen.H), "image");
    sh_track_options to;
    sh_track_options_default(&to);
    to.fps = seen.fps;
    to.width = seen.W;
    to.height = seen.H;
    int ids[SH_TRACK_MAX_MARKERS];
    for (int i = 0; i < rec.num_ids; i++) ids[i] = i;
    to.ids = listed[mode] ? ids : nullptr;
    to.num_ids = listed[mode] ? rec.num_ids : 0;
    sh_tracker *t;
    bench_check("bench_detect_track", sh_tracker_create(&to, nullptr, &t), "tracker");
    for (int f = 0; f < rec.frames; f++) {
        if (f > 0 && f % rec.loop == 0) { // the periodic recording's end joins its start
            sh_y4m_reader_close(rd);
            bench_check("bench_detect_track", sh_y4m_reader_open(rec.video.c_str(), &rd), "open");
        }
        bench_check("bench_detect_track", sh_y4m_reader_read(rd, &img), "read");
        bool timed = f >= rec.timed_from;
        if (f == rec.timed_from) {
            sh_track_stats st;
            sh_tracker_stats(t, &st);
            seen.unlocked = seen.unlocked || !st.locked;
        }
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
            bench_check("bench_detect_track",
                        sh_detector_detect_windows(wd, &img, win, nw + nb, dets, SH_TRACK_MAX_DETECTIONS, &n),
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
        score_frame(r, wd, full, nf, dets, n, rec.truth[f % rec.loop]);
        if (mode == 0 && f == rec.timed_from && seen.tags == 0) {
            seen.tags = nf;
            for (int i = 0; i < nf; i++)
                seen.tag_px += std::hypot(full[i].corner[0][0] - full[i].corner[2][0],
                                          full[i].corner[0][1] - full[i].corner[2][1]) /
                               std::sqrt(2.0) / nf;
        }
    }
    sh_tracker_destroy(t);
    sh_image_destroy(&img);
    sh_y4m_reader_close(rd);
    sh_detector_destroy(fd);
    sh_detector_destroy(wd);
}

// The three modes x passes replays of one recording, then its table. The load average is the
// machine's (2 shared cores here): printed at the start and at the end of the replays.
static void run_recording(const Recording &rec, int passes)
{
    double load0 = -1, load1 = -1;
    getloadavg(&load0, 1);
    Result res[3];
    Seen seen;
    for (int mode = 0; mode < 3; mode++)
        for (int pass = 0; pass < passes; pass++) replay(rec, mode, res[mode], seen);
    getloadavg(&load1, 1);
    if (seen.unlocked)
        std::printf("  (warning: the tracker's rates had not locked by frame %d)\n", rec.timed_from);
    std::printf("machine: %u cores, load %.2f at start, %.2f at end; one thread; %dx%d phantom frames at %.0f "
                "fps, %d tags of ~%.0f px found full frame; frames %d-%d timed (tracker locked)%s, %d replays; "
                "medians of thread CPU time per frame\n",
                std::thread::hardware_concurrency(), load0, load1, seen.W, seen.H, seen.fps, seen.tags, seen.tag_px,
                rec.timed_from, rec.frames - 1,
                rec.frames > rec.loop ? (", a " + std::to_string(rec.loop) + "-frame periodic recording looped").c_str()
                                      : "",
                passes);
    for (int mode = 0; mode < 3; mode++) {
        const Result &r = res[mode];
        if (!listed[mode]) std::printf("  no id list, a reacquisition band every frame:\n");
        double fm = bench_median(r.full), tm = bench_median(r.track);
        std::printf("  windows at decimate %.0f: full-frame libapriltag (defaults) %6.2f ms, detect+track "
                    "%5.2f ms (detection %5.2f, tracker %4.2f), %4.1fx faster; %.1f windows, %.0f%% of the "
                    "frame scanned; every full-frame tag found in %d of %d frames (%d missed)\n",
                    wdec[mode], fm, tm, bench_median(r.detect_part), bench_median(r.tracker_part), fm / tm,
                    (double)r.windows / r.frames, 100.0 * r.px / ((double)r.frames * seen.W * seen.H), r.found_all,
                    r.frames, r.missed);
        std::printf("    centres against the phantom's truth: windows mean %.3f px (max %.3f), full frame "
                    "mean %.3f px (max %.3f)\n",
                    r.err_sum / std::max(1L, r.err_n), r.err_max, r.ferr_sum / std::max(1L, r.ferr_n), r.ferr_max);
    }
    std::fflush(stdout);
}

static bool render(const std::string &rbin, const std::string &args, const std::string &dir)
{
    std::string cmd = "'" + rbin + "' --preset exvivo --rig paper --cameras 1 --quiet " + args + " --out '" + dir +
                      "' >/dev/null";
    if (std::system(cmd.c_str()) == 0) return true;
    std::fprintf(stderr, "bench_detect_track: the renderer failed: %s\n", cmd.c_str());
    return false;
}

// The 4K recording (820 MB) is made once and kept in BENCH_DETECT_TRACK_4K_DIR (default
// out/bench-detect-track-4k, as the other benches keep theirs); .complete is written after it.
// 66 frames: two whole beats at 23 fps (--periodic rounds 0.7 Hz to 0.697), so it loops without a
// jump. 32 tags of the preset's 10 mm do not fit on its 100x80 mm patch (the renderer refuses:
// spacing 11.5 mm < 13.5 mm with their quiet zones); 8 mm, the invivo preset's size, is the largest
// whole millimetre that does.
static bool recording_4k(const std::string &rbin, std::string &dir)
{
    const char *env = std::getenv("BENCH_DETECT_TRACK_4K_DIR");
    dir = env && *env ? env : "out/bench-detect-track-4k";
    if (access((dir + "/.complete").c_str(), F_OK) == 0) return true;
    std::printf("rendering 66 phantom frames (3840x2160, exvivo, 32 tags of 8 mm, periodic) into %s, once...\n",
                dir.c_str());
    std::fflush(stdout);
    std::system(("mkdir -p '" + dir + "'").c_str());
    if (!render(rbin, "--width 3840 --height 2160 --markers 32 --tag-size 8 --periodic --seed 3 --frames 66", dir))
        return false;
    FILE *f = std::fopen((dir + "/.complete").c_str(), "w");
    if (f) std::fclose(f);
    return f != nullptr;
}

int main(int argc, char **argv)
{
#ifndef SH_HAVE_APRILTAG
    (void)argc;
    (void)argv;
    std::printf("bench_detect_track: built without libapriltag, skipped\n");
    return 0;
#else
    (void)argc;
    std::string rbin = bench_renderer("bench_detect_track", argv[0]);
    if (rbin.empty()) return 0;
    const int PASSES = 3;
    char dir[] = "/tmp/sh_bench_detect_track_XXXXXX";
    if (!mkdtemp(dir)) return 1;
    std::printf("rendering 130 phantom frames (1920x1080, exvivo, 16 tags)...\n");
    std::fflush(stdout);
    if (!render(rbin, "--frames 130", dir)) return 1;
    // 1080p: 130 frames, timed from 100 (4.3 s, past the lock at ~4.2 s)
    Recording hd = {std::string(dir) + "/cam0.y4m", read_truth(std::string(dir) + "/markers.csv", 130), 130, 130,
                    100, 16};
    run_recording(hd, PASSES);
    std::system((std::string("rm -rf ") + dir).c_str());

    // 4K: the 66-frame recording played 2.5 times. Timed from frame 132 (5.7 s, well past the lock
    // at ~4.2 s = frame 97, and the start of the third loop), 33 frames: one whole beat, fast and
    // slow phases (the second beat of the recording repeats the first but for the sensor noise).
    std::string dir4k;
    if (!recording_4k(rbin, dir4k)) return 1;
    Recording uhd = {dir4k + "/cam0.y4m", read_truth(dir4k + "/markers.csv", 66), 66, 165, 132, 32};
    run_recording(uhd, PASSES);
    return 0;
#endif
}
