// make bench: the 2D warp at 4K (3840x2160 I420, the daemon's format), issue 20's three figures
// in one process:
//   - one thread, per frame (map update + warp), beside OpenCV's cv::remap of the same frame
//     (three planes: Y with a precomputed CV_32FC2 map, U and V with its half-size copy; one
//     thread), goal <= 0.5;
//   - beside a streaming copy of the frame's bytes with a cold cache (memcpy after 64 MiB of
//     other writes: the physical floor of one frame in and one out), goal <= 4;
//   - two threads against one, wall time, goal >= 1.8 (the map update's grid nodes shared
//     among the threads too: sh_warp_update).
// tps and bspline, 16 and 32 markers of the synthetic deformation (tools/synth). Medians of
// repeated runs, thread CPU time for one thread (ours and the peer alternating), wall time for
// the thread comparison; the machine's cores and load printed.
#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <thread>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

extern "C" {
#include "stillheart/warp.h"
#include "../synth/synth.h"
}
#include "bench_frames.h"

static double wall_ms()
{
    timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec * 1e3 + ts.tv_nsec * 1e-6;
}

static void check(sh_status st, const char *what) { bench_check("bench_warp4k", st, what); }

// memcpy of the frame's bytes after the caches were filled with something else
static double cold_copy_ms(const std::vector<uint8_t> &src, std::vector<uint8_t> &dst, std::vector<uint8_t> &evict)
{
    std::memset(evict.data(), (int)(evict[0] + 1), evict.size());
    double t0 = bench_now_ms();
    std::memcpy(dst.data(), src.data(), src.size());
    return bench_now_ms() - t0;
}

int main()
{
    const int W = 3840, H = 2160, REPEAT = 9;
    cv::setNumThreads(1);
    double load[3] = {0, 0, 0};
    if (getloadavg(load, 3) < 1) load[0] = -1;
    sh_image frame, out;
    cv::Mat packed;
    bench_i420_frame(W, H, &frame, &packed);
    check(sh_image_create(&out, SH_PIX_I420, W, H), "image");
    const size_t bytes = (size_t)W * H * 3 / 2;
    std::vector<uint8_t> csrc(packed.data, packed.data + bytes), cdst(bytes), evict(64u << 20);
    std::printf("machine: %u cores, load %.2f; frame %dx%d I420 (%.1f MB); medians of %d runs\n",
                std::thread::hardware_concurrency(), load[0], W, H, bytes / 1e6, REPEAT);
    std::printf("%-9s %3s %10s %10s %7s %10s %7s %10s %7s\n", "method", "mk", "ours ms", "remap ms", "ratio",
                "copy ms", "/copy", "2 thr ms", "1/2");
    synth_motion motion = {W, H, 12.0};
    sh_warp *warp1, *warp2;
    check(sh_warp_create(1, &warp1), "warp");
    check(sh_warp_create(2, &warp2), "warp");
    cv::Mat y(H, W, CV_8UC1, frame.plane[0].data, (size_t)frame.plane[0].stride);
    cv::Mat u(H / 2, W / 2, CV_8UC1, frame.plane[1].data, (size_t)frame.plane[1].stride);
    cv::Mat v(H / 2, W / 2, CV_8UC1, frame.plane[2].data, (size_t)frame.plane[2].stride);
    cv::Mat dy, du, dv;
    for (int markers : {16, 32}) {
        std::vector<double> ref(2 * markers), cur(2 * markers);
        synth_markers(&motion, markers, 7, ref.data());
        for (int i = 0; i < markers; i++)
            synth_forward(&motion, 0.3, ref[2 * i], ref[2 * i + 1], &cur[2 * i], &cur[2 * i + 1]);
        for (const char *name : {"tps", "bspline"}) {
            sh_interp_params params;
            check(sh_interp_params_parse(name, &params), "method");
            sh_interp *interp;
            sh_warp_model *model;
            check(sh_interp_create(&params, ref.data(), markers, &interp), name);
            check(sh_warp_model_create(interp, ref.data(), markers, W, H, nullptr, &model), name);
            check(sh_warp_model_update(model, cur.data()), name);
            std::vector<float> map((size_t)W * H * 2);
            check(sh_warp_model_map(model, map.data()), "map");
            cv::Mat map32(H, W, CV_32FC2, map.data()), maphalf;
            cv::resize(map32, maphalf, cv::Size(W / 2, H / 2), 0, 0, cv::INTER_NEAREST);
            maphalf *= 0.5;
            std::vector<double> ours, peer, ratio, copy, two, speedup;
            for (int r = 0; r < REPEAT; r++) {
                double t0 = bench_now_ms();
                check(sh_warp_update(warp1, model, cur.data(), nullptr), name);
                check(sh_warp_apply(warp1, model, &frame, &out), name);
                double t1 = bench_now_ms();
                cv::remap(y, dy, map32, cv::noArray(), cv::INTER_LINEAR, cv::BORDER_CONSTANT);
                cv::remap(u, du, maphalf, cv::noArray(), cv::INTER_LINEAR, cv::BORDER_CONSTANT);
                cv::remap(v, dv, maphalf, cv::noArray(), cv::INTER_LINEAR, cv::BORDER_CONSTANT);
                double t2 = bench_now_ms();
                ours.push_back(t1 - t0);
                peer.push_back(t2 - t1);
                ratio.push_back((t1 - t0) / (t2 - t1));
                copy.push_back(cold_copy_ms(csrc, cdst, evict));
                // wall time, one thread then two, back to back
                double w0 = wall_ms();
                check(sh_warp_update(warp1, model, cur.data(), nullptr), name);
                check(sh_warp_apply(warp1, model, &frame, &out), name);
                double w1 = wall_ms();
                check(sh_warp_update(warp2, model, cur.data(), nullptr), name);
                check(sh_warp_apply(warp2, model, &frame, &out), name);
                double w2 = wall_ms();
                two.push_back(w2 - w1);
                speedup.push_back((w1 - w0) / (w2 - w1));
            }
            double o = bench_median(ours), c = bench_median(copy);
            std::printf("%-9s %3d %10.2f %10.2f %7.3f %10.2f %7.2f %10.2f %7.2f\n", name, markers, o,
                        bench_median(peer), bench_median(ratio), c, o / c, bench_median(two), bench_median(speedup));
            std::fflush(stdout);
            sh_warp_model_destroy(model);
            sh_interp_destroy(interp);
        }
    }
    std::printf("goals (issue 20): ratio <= 0.5, /copy <= 4, 1/2 >= 1.8\n");
    sh_warp_destroy(warp1);
    sh_warp_destroy(warp2);
    sh_image_destroy(&frame);
    sh_image_destroy(&out);
    return 0;
}
