// make bench: the 2D engine beside OpenCV's cv::remap on the same frames, in one process.
//
// 1920x1080 RGB24, 16 and 80 markers, every method, one thread. Per reference: building the
// interpolant and the warp model (grid basis or triangles) and the first update. Per frame:
// the map update from new marker positions plus the warp of the frame. The peer: cv::remap
// (INTER_LINEAR, BORDER_CONSTANT) with a precomputed CV_32FC2 map of the same frame, one thread.
// Medians of repeated runs of thread CPU time, ours and the peer's alternating; the ratio is the
// median of ours / peer over those pairs (goal <= 0.5 per frame).
#include <algorithm>
#include <ctime>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <thread>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

extern "C" {
#include "stillheart/warp.h"
#include "../synth/synth.h"
}

// CPU time of this thread: both sides run on this one thread, and on a shared machine it
// leaves out the time other processes hold the core.
static double now_ms()
{
    timespec ts;
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return ts.tv_sec * 1e3 + ts.tv_nsec * 1e-6;
}

static double median(std::vector<double> v)
{
    std::sort(v.begin(), v.end());
    return v[v.size() / 2];
}

static void check(sh_status st, const char *what)
{
    if (st != SH_OK) {
        std::fprintf(stderr, "bench_warp: %s: %s\n", what, sh_error_message());
        std::exit(1);
    }
}

int main(int argc, char **argv)
{
    // Optional filters for profiling one case: bench_warp [METHOD [MARKERS [REPEAT]]]
    const char *only_method = argc > 1 ? argv[1] : nullptr;
    int only_markers = argc > 2 ? std::atoi(argv[2]) : 0;
    const int W = 1920, H = 1080, REPEAT = argc > 3 ? std::max(1, std::atoi(argv[3])) : 15;
    cv::setNumThreads(1);
    synth_motion motion = {W, H, 12.0};
    sh_image frame, out;
    check(sh_image_create(&frame, SH_PIX_RGB24, W, H), "image");
    check(sh_image_create(&out, SH_PIX_RGB24, W, H), "image");
    synth_render(&motion, 0.3, &frame);
    cv::Mat src(H, W, CV_8UC3, frame.plane[0].data, (size_t)frame.plane[0].stride);
    cv::Mat dst(H, W, CV_8UC3);

    sh_warp *warp;
    check(sh_warp_create(1, &warp), "warp");
    std::printf("machine: %u cores; frame %dx%d RGB24; one thread; medians of %d runs, thread CPU time\n",
                std::thread::hardware_concurrency(), W, H, REPEAT);
    std::printf("%-9s %4s %9s %9s %9s %9s %7s %5s %8s\n", "method", "mk", "ref ms", "frame ms",
                "(map ms)", "remap ms", "ratio", "grid", "err px");
    const char *methods[] = {"affine", "pwlinear", "bspline", "rbf-local", "tps", "gaussian"};
    for (int markers : {16, 80}) {
        if (only_markers && markers != only_markers) continue;
        std::vector<double> ref(2 * markers), cur(2 * markers);
        synth_markers(&motion, markers, 7, ref.data());
        for (int i = 0; i < markers; i++)
            synth_forward(&motion, 0.3, ref[2 * i], ref[2 * i + 1], &cur[2 * i], &cur[2 * i + 1]);
        for (const char *name : methods) {
            if (only_method && std::strcmp(only_method, name) != 0) continue;
            sh_interp_params params;
            check(sh_interp_params_parse(name, &params), "method");
            std::vector<double> build_ms, frame_ms, map_ms, remap_ms;
            sh_interp *interp = nullptr;
            sh_warp_model *model = nullptr;
            for (int r = 0; r < 5; r++) {
                sh_warp_model_destroy(model);
                sh_interp_destroy(interp);
                double t0 = now_ms();
                check(sh_interp_create(&params, ref.data(), markers, &interp), name);
                check(sh_warp_model_create(interp, ref.data(), markers, W, H, nullptr, &model), name);
                check(sh_warp_model_update(model, cur.data()), name);
                build_ms.push_back(now_ms() - t0);
            }
            // The peer gets the same map (NaN outside the hull). Ours and the peer alternate, so
            // both see the same load on a shared machine; the ratio is the median of the pairs'.
            std::vector<float> map((size_t)W * H * 2);
            check(sh_warp_model_map(model, map.data()), "map");
            cv::Mat map32(H, W, CV_32FC2, map.data());
            std::vector<double> ratio;
            for (int r = 0; r < REPEAT; r++) {
                double t0 = now_ms();
                check(sh_warp_model_update(model, cur.data()), name);
                double t1 = now_ms();
                check(sh_warp_apply(warp, model, &frame, &out), name);
                double t2 = now_ms();
                cv::remap(src, dst, map32, cv::noArray(), cv::INTER_LINEAR, cv::BORDER_CONSTANT);
                double t3 = now_ms();
                frame_ms.push_back(t2 - t0);
                map_ms.push_back(t1 - t0);
                remap_ms.push_back(t3 - t2);
                ratio.push_back((t2 - t0) / (t3 - t2));
            }
            double f = median(frame_ms), p = median(remap_ms);
            std::printf("%-9s %4d %9.2f %9.2f %9.2f %9.2f %7.3f %5d %8.4f\n", name, markers,
                        median(build_ms), f, median(map_ms), p, median(ratio),
                        sh_warp_model_grid_spacing(model), sh_warp_model_error_bound(model));
            std::fflush(stdout);
            sh_warp_model_destroy(model);
            sh_interp_destroy(interp);
        }
    }
    sh_warp_destroy(warp);
    sh_image_destroy(&frame);
    sh_image_destroy(&out);
    return 0;
}
