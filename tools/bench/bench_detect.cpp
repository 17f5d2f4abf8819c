// make bench: AprilTag detection in windows beside full-frame libapriltag detection with the
// library's default settings, on the same 1080p phantom frames (16 tag36h11 tags), one thread.
//
// Frames come from the phantom renderer of this build (build/stillheart-render, exvivo preset,
// one camera); windows are squares of 1.6x the tag's extent around the true centres (what a
// tracker with a good prediction asks for). Both sides run through libapriltag on the same
// grey plane; full frame = libapriltag's defaults (decimate 2, refine edges, sharpening 0.25).
// Per-frame medians of thread CPU time over REPEAT passes.
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
#include "stillheart/y4m.h"
}

struct Truth {
    int id;
    double p[5][2];
};

// Over 80 lines: one benchmark read top to bottom: render, ground truth, windows, each mode timed
// over the same frames and checked against the truth, then the table. It runs only in make bench.
int main()
{
#ifndef SH_HAVE_APRILTAG
    std::printf("bench_detect: built without libapriltag, skipped\n");
    return 0;
#else
    const char *render = std::getenv("STILLHEART_RENDER");
    std::string rbin = render ? render : "build/stillheart-render";
    if (access(rbin.c_str(), X_OK) != 0) {
        std::printf("bench_detect: no phantom renderer at %s (needs OSMesa), skipped\n",
                    rbin.c_str());
        return 0;
    }
    const int FRAMES = 8, REPEAT = 5;
    char dir[] = "/tmp/sh_bench_detect_XXXXXX";
    if (!mkdtemp(dir)) return 1;
    std::string cmd = "'" + rbin + "' --preset exvivo --rig paper --cameras 1 --quiet --frames " +
                      std::to_string(FRAMES) + " --out " + dir + " >/dev/null";
    if (std::system(cmd.c_str()) != 0) {
        std::fprintf(stderr, "bench_detect: the renderer failed\n");
        return 1;
    }
    // ground truth
    std::vector<std::vector<Truth>> truth(FRAMES);
    {
        FILE *f = std::fopen((std::string(dir) + "/markers.csv").c_str(), "r");
        char line[512];
        if (!f || !std::fgets(line, sizeof line, f)) return 1;
        while (std::fgets(line, sizeof line, f)) {
            int fr, cam, id, vis;
            char pt[8];
            double x, y;
            if (std::sscanf(line, "%d,%d,%d,%7[^,],%lf,%lf,%d", &fr, &cam, &id, pt, &x, &y, &vis) != 7 ||
                fr >= FRAMES)
                continue;
            auto &v = truth[fr];
            auto it = std::find_if(v.begin(), v.end(), [&](const Truth &t) { return t.id == id; });
            if (it == v.end()) {
                v.push_back(Truth{id, {}});
                it = v.end() - 1;
            }
            int k = pt[0] == 'c' ? 4 : pt[0] - '0';
            it->p[k][0] = x;
            it->p[k][1] = y;
        }
        std::fclose(f);
    }
    std::vector<sh_image> frames(FRAMES);
    sh_y4m_reader *rd;
    bench_check("bench_detect", sh_y4m_reader_open((std::string(dir) + "/cam0.y4m").c_str(), &rd), "open");
    const sh_y4m_header *hd = sh_y4m_reader_header(rd);
    for (auto &f : frames) {
        bench_check("bench_detect", sh_image_create(&f, hd->format, hd->width, hd->height), "image");
        bench_check("bench_detect", sh_y4m_reader_read(rd, &f), "read");
    }
    const int W = hd->width, H = hd->height;
    sh_y4m_reader_close(rd);
    std::system((std::string("rm -rf ") + dir).c_str());

    const double scales[2] = {1.6, 1.3};
    std::vector<std::vector<sh_window>> wins[2];
    double tag_px = 0;
    for (int si = 0; si < 2; si++) {
    wins[si].resize(FRAMES);
    tag_px = 0;
    for (int fr = 0; fr < FRAMES; fr++)
        for (auto &t : truth[fr]) {
            double x0 = 1e9, x1 = -1e9, y0 = 1e9, y1 = -1e9;
            for (int k = 0; k < 4; k++) {
                x0 = std::min(x0, t.p[k][0]), x1 = std::max(x1, t.p[k][0]);
                y0 = std::min(y0, t.p[k][1]), y1 = std::max(y1, t.p[k][1]);
            }
            double ext = std::max(x1 - x0, y1 - y0), half = 0.5 * scales[si] * ext;
            tag_px += ext / (FRAMES * truth[fr].size());
            wins[si][fr].push_back(sh_window{(int)std::floor(t.p[4][0] - half),
                                             (int)std::floor(t.p[4][1] - half),
                                             (int)std::ceil(2 * half), (int)std::ceil(2 * half)});
        }
    }

    std::printf("machine: %u cores; %d phantom frames %dx%d (exvivo, %zu tags of ~%.0f px); one "
                "thread; medians of %d passes, thread CPU time per frame\n",
                std::thread::hardware_concurrency(), FRAMES, W, H,
                truth[0].size(), tag_px, REPEAT);

    static sh_detection dets[1024];
    struct Mode {
        const char *name;
        int windows;
        double wdec;
        int merge;
        double fdec;
        int scale;
    } modes[] = {
        {"full frame, libapriltag defaults (decimate 2)", 0, 1, 1, 2.0, 0},
        {"full frame, decimate 1", 0, 1, 1, 1.0, 0},
        {"16 windows 1.6x, decimate 1, separate calls", 1, 1.0, 0, 2.0, 0},
        {"16 windows 1.6x, decimate 1, merged", 1, 1.0, 1, 2.0, 0},
        {"16 windows 1.3x, decimate 1, merged", 1, 1.0, 1, 2.0, 1},
        {"16 windows 1.6x, decimate 2, merged", 1, 2.0, 1, 2.0, 0},
        {"16 windows 1.3x, decimate 2, merged", 1, 2.0, 1, 2.0, 1},
    };
    double full_ms = 0;
    for (const Mode &m : modes) {
        sh_detector_options o;
        sh_detector_options_default(&o);
        o.quad_decimate = m.fdec;
        o.window_decimate = m.wdec;
        o.merge_windows = m.merge;
        sh_detector *det;
        bench_check("bench_detect", sh_detector_create(&o, &det), "detector");
        std::vector<double> t;
        int found_min = 1 << 30, found_max = 0, calls = 0;
        double worst = 0;
        for (int r = 0; r < REPEAT; r++)
            for (int fr = 0; fr < FRAMES; fr++) {
                int n = 0;
                double t0 = bench_now_ms();
                if (m.windows)
                    bench_check("bench_detect", sh_detector_detect_windows(det, &frames[fr], wins[m.scale][fr].data(),
                                                     (int)wins[m.scale][fr].size(), dets, 1024, &n),
                          "detect");
                else
                    bench_check("bench_detect", sh_detector_detect(det, &frames[fr], dets, 1024, &n), "detect");
                t.push_back(bench_now_ms() - t0);
                if (m.windows) calls = sh_detector_last_windows(det, nullptr, 0);
                int found = 0;
                for (int i = 0; i < n; i++)
                    for (auto &tt : truth[fr])
                        if (tt.id == dets[i].id &&
                            std::hypot(dets[i].cx - tt.p[4][0], dets[i].cy - tt.p[4][1]) < 2) {
                            found++;
                            for (int k = 0; k < 4; k++)
                                worst = std::max(worst, std::hypot(dets[i].corner[k][0] - tt.p[k][0],
                                                                   dets[i].corner[k][1] - tt.p[k][1]));
                        }
                found_min = std::min(found_min, found);
                found_max = std::max(found_max, n);
            }
        double ms = bench_median(t);
        if (!m.windows && m.fdec == 2.0) full_ms = ms;
        std::printf("  %-46s %7.2f ms/frame  found >= %d of %zu (reported <= %d), worst corner "
                    "%.2f px%s",
                    m.name, ms, found_min, truth[0].size(), found_max, worst,
                    m.windows ? "" : "\n");
        if (m.windows)
            std::printf(", %d calls, %.1fx faster than full frame\n", calls, full_ms / ms);
        sh_detector_destroy(det);
    }
    for (auto &f : frames) sh_image_destroy(&f);
    return 0;
#endif
}
