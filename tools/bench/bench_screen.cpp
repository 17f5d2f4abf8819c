// make bench: what stillheart-show spends per frame on the CPU (src/screen) before the page flip:
// an I420 frame converted (BT.601) and scaled into a 1920x1080 XRGB8888 scanout buffer, beside
// OpenCV's cvtColor COLOR_YUV2BGRA_I420 (plus resize INTER_NEAREST when the sizes differ), and
// the full overlay. The frame is the synthetic phantom (tools/synth). One thread; medians of
// repeated runs of thread CPU time; the ratio is ours / peer.
#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <functional>
#include <thread>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

extern "C" {
#include "stillheart/screen.h"
#include "../synth/synth.h"
}
#include "bench_frames.h"

static double time_ms(const std::function<void()> &f, int repeat)
{
    f(); // warm
    std::vector<double> t;
    for (int i = 0; i < repeat; i++) {
        double a = bench_now_ms();
        f();
        t.push_back(bench_now_ms() - a);
    }
    return bench_median(t);
}

static void check(sh_status st, const char *what) { bench_check("bench_screen", st, what); }

int main()
{
    const int SW = 1920, SH = 1080, REPEAT = 15;
    cv::setNumThreads(1);
    std::vector<uint32_t> screen((size_t)SW * SH);
    sh_screen_buffer b = {screen.data(), SW, SH, SW * 4};
    cv::Mat mscreen(SH, SW, CV_8UC4, screen.data()), tmp;
    std::printf("machine: %u cores; screen %dx%d XRGB8888; one thread; medians of %d runs, thread CPU time (ms)\n",
                std::thread::hardware_concurrency(), SW, SH, REPEAT);
    std::printf("%-28s %9s  %-36s %9s  %6s\n", "frame to screen", "ours ms", "peer", "peer ms", "ratio");
    const int sizes[][2] = {{1920, 1080}, {1280, 720}, {3840, 2160}};
    for (const auto &s : sizes) {
        int W = s[0], H = s[1];
        sh_image i420;
        cv::Mat mi420;
        bench_i420_frame(W, H, &i420, &mi420);
        sh_screen_layout l = sh_screen_layout_for(W, H, SW, SH);
        double ours = time_ms([&] { check(sh_screen_draw_frame(&b, &l, &i420, 0), "draw"); }, REPEAT);
        double peer = time_ms([&] {
            if (W == SW && H == SH) cv::cvtColor(mi420, mscreen, cv::COLOR_YUV2BGRA_I420);
            else {
                cv::cvtColor(mi420, tmp, cv::COLOR_YUV2BGRA_I420);
                cv::resize(tmp, mscreen, mscreen.size(), 0, 0, cv::INTER_NEAREST);
            }
        }, REPEAT);
        char name[64];
        std::snprintf(name, sizeof name, "I420 %dx%d", W, H);
        std::printf("%-28s %9.3f  %-36s %9.3f  %6.2f\n", name, ours,
                    W == SW && H == SH ? "cvtColor YUV2BGRA_I420" : "cvtColor YUV2BGRA_I420 + resize NN", peer,
                    ours / peer);
        sh_image_destroy(&i420);
    }
    sh_screen_layout l = sh_screen_layout_for(SW, SH, SW, SH);
    const char reason[44] = "markers lost: 5 of 16 visible";
    std::printf("%-28s %9.3f\n", "overlay full (raw + reason)", time_ms([&] {
        sh_screen_draw_status(&b, &l, SH_SCREEN_OVERLAY_FULL, 0, reason, (int)sizeof reason); }, REPEAT));
    std::printf("%-28s %9.3f\n", "NO SIGNAL", time_ms([&] { sh_screen_draw_no_signal(&b, 12.0); }, REPEAT));
    return 0;
}
