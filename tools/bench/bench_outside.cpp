// make bench: [sink] outside = dimmed-raw (sh_warp_outside) per frame, beside what the frame costs
// anyway: the warp itself (sh_warp_apply, one thread) and a plain memcpy of the frame.
//
// 1920x1080, I420 (the daemon's usual frames) and RGB24, the synthetic phantom (tools/synth) with
// 16 markers over the middle of the frame (tps): the hull leaves about half the pixels outside.
// Per frame: the outside fill with its runs already made (they are made once per model, also
// timed: "runs ms"). Ours, the warp and memcpy alternate, so all see the same load on a shared
// machine; medians of thread CPU time, ratios the medians of the per-run ratios.
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <thread>
#include <vector>

#include "bench_detect_util.h"

extern "C" {
#include "stillheart/warp.h"
#include "../synth/synth.h"
}

static void check(sh_status st, const char *what) { bench_check("bench_outside", st, what); }

// The fraction of the luma (or RGB) plane's pixels outside the hull: where the map is NaN.
static double outside_fraction(const sh_warp_model *model, int w, int h)
{
    std::vector<float> map((size_t)w * h * 2);
    check(sh_warp_model_map(model, map.data()), "map");
    size_t out = 0;
    for (size_t i = 0; i < (size_t)w * h; i++) out += map[2 * i] != map[2 * i];
    return (double)out / ((double)w * h);
}

int main(int argc, char **argv)
{
    const int W = 1920, H = 1080, MARKERS = 16, REPEAT = argc > 1 ? std::max(1, std::atoi(argv[1])) : 31;
    synth_motion motion = {W, H, 12.0};
    std::vector<double> ref(2 * MARKERS), cur(2 * MARKERS);
    synth_markers(&motion, MARKERS, 7, ref.data());
    for (int i = 0; i < MARKERS; i++)
        synth_forward(&motion, 0.3, ref[2 * i], ref[2 * i + 1], &cur[2 * i], &cur[2 * i + 1]);
    sh_interp_params params;
    check(sh_interp_params_parse("tps", &params), "method");
    sh_interp *interp = nullptr;
    sh_warp_model *model = nullptr;
    check(sh_interp_create(&params, ref.data(), MARKERS, &interp), "interp");
    check(sh_warp_model_create(interp, ref.data(), MARKERS, W, H, nullptr, &model), "model");
    check(sh_warp_model_update(model, cur.data()), "update");
    sh_warp *warp;
    check(sh_warp_create(1, &warp), "warp");
    double load[3] = {0, 0, 0};
    if (getloadavg(load, 3) < 1) load[0] = -1;
    std::printf("machine: %u cores, load %.2f; frame %dx%d, %d markers (tps), %.0f %% of the pixels outside the "
                "hull; one thread; medians of %d runs, thread CPU time (ms)\n",
                std::thread::hardware_concurrency(), load[0], W, H, MARKERS, 100 * outside_fraction(model, W, H),
                REPEAT);
    std::printf("%-6s %9s %10s %9s %9s %12s %14s\n", "format", "runs ms", "outside ms", "warp ms", "memcpy ms",
                "outside/warp", "outside/memcpy");
    for (sh_pixfmt f : {SH_PIX_I420, SH_PIX_RGB24}) {
        sh_image frame, out;
        check(sh_image_create(&frame, f, W, H), "image");
        check(sh_image_create(&out, f, W, H), "image");
        synth_render(&motion, 0.3, &frame);
        size_t bytes = sh_image_packed_size(f, W, H);
        std::vector<uint8_t> a(bytes, 1), b(bytes);
        std::vector<double> runs_ms, outside_ms, warp_ms, copy_ms, r_warp, r_copy;
        for (int r = 0; r < 5; r++) { // the runs: a fresh fill's first frame, less a later frame's cost
            sh_warp_outside *o;
            check(sh_warp_outside_create(f, W, H, 1, &o), "outside");
            double t0 = bench_now_ms();
            check(sh_warp_outside_apply(o, model, &frame, &out), "outside");
            double t1 = bench_now_ms();
            check(sh_warp_outside_apply(o, model, &frame, &out), "outside");
            double t2 = bench_now_ms();
            runs_ms.push_back((t1 - t0) - (t2 - t1));
            sh_warp_outside_destroy(o);
        }
        sh_warp_outside *o;
        check(sh_warp_outside_create(f, W, H, 1, &o), "outside");
        check(sh_warp_outside_apply(o, model, &frame, &out), "outside"); // runs made: warm
        for (int r = 0; r < REPEAT; r++) {
            double t0 = bench_now_ms();
            check(sh_warp_apply(warp, model, &frame, &out), "warp");
            double t1 = bench_now_ms();
            check(sh_warp_outside_apply(o, model, &frame, &out), "outside");
            double t2 = bench_now_ms();
            std::memcpy(b.data(), a.data(), bytes);
            double t3 = bench_now_ms();
            warp_ms.push_back(t1 - t0);
            outside_ms.push_back(t2 - t1);
            copy_ms.push_back(t3 - t2);
            r_warp.push_back((t2 - t1) / (t1 - t0));
            r_copy.push_back((t2 - t1) / (t3 - t2));
        }
        std::printf("%-6s %9.3f %10.3f %9.3f %9.3f %12.3f %14.2f\n", sh_pixfmt_name(f), bench_median(runs_ms),
                    bench_median(outside_ms), bench_median(warp_ms), bench_median(copy_ms), bench_median(r_warp), bench_median(r_copy));
        std::fflush(stdout);
        if (b[bytes / 2] != 1) return 1; // the copy is used: not optimized away
        sh_warp_outside_destroy(o);
        sh_image_destroy(&frame);
        sh_image_destroy(&out);
    }
    sh_warp_destroy(warp);
    sh_warp_model_destroy(model);
    sh_interp_destroy(interp);
    return 0;
}
