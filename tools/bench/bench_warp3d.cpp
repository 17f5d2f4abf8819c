// make bench: 3D stabilization (reference view, stereo pair) beside the 2D engine, in one run.
//
// 1920x1080 RGB24, 16 markers on a beating dome seen by a camera with lens distortion, one
// thread, multilevel B-splines for both. The 2D engine gets the markers' projections, the 3D
// engine their 3D positions. Per reference: the interpolants and the model (2D: grid basis;
// 3D: surface fit, ray casting of the grid). Per frame: the update from new marker positions
// plus the rendering (2D: map update + warp; 3D: displacement fit, node projection, warp; stereo:
// both eyes into one side-by-side frame). Medians of thread CPU time over frames of a beat,
// after a warm-up beat (grids refined to their final spacing). Goal: 3D <= 1.5x 2D, stereo <= 3x.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <vector>

extern "C" {
#include "stillheart/warp.h"
#include "stillheart/warp3d.h"
#include "../synth/synth.h"
}

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
        std::fprintf(stderr, "bench_warp3d: %s: %s\n", what, sh_error_message());
        std::exit(1);
    }
}

// The dome at activation c in [0, 1]: contracts in plane, lifts and twists.
static void dome(double u, double v, double c, double X[3])
{
    double a = 0.04 * c, s = 1 - 0.05 * c;
    double x = s * (u * std::cos(a) - v * std::sin(a)), y = s * (u * std::sin(a) + v * std::cos(a));
    X[0] = x;
    X[1] = y;
    X[2] = (25 + 5 * c) * std::exp(-(u * u + v * v) / (2 * 60.0 * 60.0)) + 2 * c;
}

// Over 80 lines: one benchmark: the scene, the 2D engine, the 3D view and the stereo pair set up
// side by side, the per-frame lambdas over them timed interleaved after a warm-up beat, then the
// table. It runs only in make bench.
int main()
{
    const int W = 1920, H = 1080, N = 16, PHASES = 24;
    sh_calib_camera cam;
    std::memset(&cam, 0, sizeof cam);
    double K[9] = {2300, 0, 959.5, 0, 2300, 539.5, 0, 0, 1};
    std::memcpy(cam.K, K, sizeof K);
    double R[9] = {1, 0, 0, 0, -1, 0, 0, 0, -1}; // looking down at the dome from Z = 330
    std::memcpy(cam.R, R, sizeof R);
    cam.t[2] = 330;
    cam.num_dist = 5;
    cam.dist[0] = -0.08, cam.dist[1] = 0.02;

    std::vector<double> ref3(3 * N), ref2(2 * N);
    std::vector<std::vector<double>> cur3(PHASES, std::vector<double>(3 * N)),
        cur2(PHASES, std::vector<double>(2 * N));
    for (int i = 0; i < N; i++) {
        double u = -84 + 56 * (i % 4) + 6 * std::sin(i), v = -45 + 30 * (i / 4) + 4 * std::cos(i);
        dome(u, v, 0, &ref3[3 * i]);
        sh_warp3d_project(&cam, &ref3[3 * i], &ref2[2 * i], &ref2[2 * i + 1]);
        for (int p = 0; p < PHASES; p++) {
            double c = 0.5 - 0.5 * std::cos(2 * M_PI * p / PHASES);
            dome(u, v, c, &cur3[p][3 * i]);
            sh_warp3d_project(&cam, &cur3[p][3 * i], &cur2[p][2 * i], &cur2[p][2 * i + 1]);
        }
    }

    synth_motion motion = {W, H, 12.0};
    sh_image frame, out, sbs;
    check(sh_image_create(&frame, SH_PIX_RGB24, W, H), "image");
    check(sh_image_create(&out, SH_PIX_RGB24, W, H), "image");
    check(sh_image_create(&sbs, SH_PIX_RGB24, 2 * W, H), "image");
    synth_render(&motion, 0.3, &frame);
    sh_warp *warp;
    check(sh_warp_create(1, &warp), "warp");

    // per reference
    double t0 = now_ms();
    sh_interp_params ip;
    sh_interp_params_default(&ip, SH_METHOD_BSPLINE);
    sh_interp *interp;
    sh_warp_model *m2;
    check(sh_interp_create(&ip, ref2.data(), N, &interp), "2D interpolant");
    check(sh_warp_model_create(interp, ref2.data(), N, W, H, NULL, &m2), "2D model");
    double build2 = now_ms() - t0;
    t0 = now_ms();
    sh_warp3d_model *m3;
    sh_warp3d_view *view, *eye[2];
    check(sh_warp3d_model_create(NULL, ref3.data(), N, &m3), "3D model");
    check(sh_warp3d_view_create(m3, &cam, &cam, W, H, NULL, &view), "3D view");
    double build3 = now_ms() - t0;
    sh_calib_camera lr[2];
    sh_warp3d_stereo_cameras(&cam, 12, &lr[0], &lr[1]);
    t0 = now_ms();
    for (int e = 0; e < 2; e++) check(sh_warp3d_view_create(m3, &lr[e], &cam, W, H, NULL, &eye[e]), "eye");
    double build_st = now_ms() - t0;

    auto run2 = [&](int p) {
        check(sh_warp_model_update(m2, cur2[p].data()), "2D update");
        check(sh_warp_apply(warp, m2, &frame, &out), "2D warp");
    };
    auto run3 = [&](int p) {
        check(sh_warp3d_model_update(m3, cur3[p].data()), "3D update");
        check(sh_warp3d_view_update(view), "3D view update");
        check(sh_warp3d_view_apply(warp, view, &frame, &out, 0, 0), "3D warp");
    };
    auto run_st = [&](int p) {
        check(sh_warp3d_model_update(m3, cur3[p].data()), "3D update");
        for (int e = 0; e < 2; e++) {
            check(sh_warp3d_view_update(eye[e]), "eye update");
            check(sh_warp3d_view_apply(warp, eye[e], &frame, &sbs, e * W, 0), "eye warp");
        }
    };
    for (int p = 0; p < PHASES; p++) run2(p), run3(p), run_st(p); // warm-up: final grids
    std::vector<double> t2, t3, tst;
    for (int rep = 0; rep < 3; rep++)
        for (int p = 0; p < PHASES; p++) {
            double a = now_ms();
            run2(p);
            double b = now_ms();
            run3(p);
            double c = now_ms();
            run_st(p);
            double d = now_ms();
            t2.push_back(b - a), t3.push_back(c - b), tst.push_back(d - c);
        }
    long hull2 = 0;
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++) hull2 += sh_hull_contains(sh_warp3d_view_hull(view), x, y);
    std::printf("frame %dx%d RGB24, %d markers, one thread, bspline; hull %.0f%% of the frame; "
                "medians of %zu frames, thread CPU time\n",
                W, H, N, 100.0 * hull2 / ((double)W * H), t2.size());
    std::printf("  %-28s %10s %10s %8s %s\n", "", "reference", "per frame", "x 2D", "grid");
    double m2f = median(t2), m3f = median(t3), mstf = median(tst);
    std::printf("  %-28s %8.2f ms %7.2f ms %8s %d px\n", "2D engine", build2, m2f, "1.00",
                sh_warp_model_grid_spacing(m2));
    std::printf("  %-28s %8.2f ms %7.2f ms %8.2f %d px (goal <= 1.5)\n", "3D, reference view", build3,
                m3f, m3f / m2f, sh_warp3d_view_grid_spacing(view));
    std::printf("  %-28s %8.2f ms %7.2f ms %8.2f %d px (goal <= 3)\n", "3D, stereo pair (2 x WxH)",
                build_st, mstf, mstf / m2f, sh_warp3d_view_grid_spacing(eye[0]));
    sh_warp3d_view_destroy(eye[0]);
    sh_warp3d_view_destroy(eye[1]);
    sh_warp3d_view_destroy(view);
    sh_warp3d_model_destroy(m3);
    sh_warp_model_destroy(m2);
    sh_interp_destroy(interp);
    sh_warp_destroy(warp);
    sh_image_destroy(&frame);
    sh_image_destroy(&out);
    sh_image_destroy(&sbs);
    return 0;
}
