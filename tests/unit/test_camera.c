/* Camera geometry against closed forms: P X for a distortion-free camera, OpenCV's distortion
 * formulas evaluated by hand, exact triangulation of projected points, and the statistics of
 * triangulation under pixel noise (chi-square with 2n - 3 degrees of freedom). */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include <cmocka.h>

#include "stillheart/camera.h"

/* a camera at C looking at target, rolled */
static void look_at(sh_calib_camera *c, const double C[3], const double target[3], double roll,
                    double f, double cx, double cy)
{
    memset(c, 0, sizeof *c);
    double z[3] = {target[0] - C[0], target[1] - C[1], target[2] - C[2]};
    double l = sqrt(z[0] * z[0] + z[1] * z[1] + z[2] * z[2]);
    for (int i = 0; i < 3; i++) z[i] /= l;
    double x[3] = {1 - z[0] * z[0], -z[0] * z[1], -z[0] * z[2]};
    l = sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2]);
    for (int i = 0; i < 3; i++) x[i] /= l;
    double y[3] = {z[1] * x[2] - z[2] * x[1], z[2] * x[0] - z[0] * x[2], z[0] * x[1] - z[1] * x[0]};
    double cr = cos(roll), sr = sin(roll);
    for (int i = 0; i < 3; i++) {
        c->R[i] = cr * x[i] + sr * y[i];
        c->R[3 + i] = -sr * x[i] + cr * y[i];
        c->R[6 + i] = z[i];
    }
    for (int i = 0; i < 3; i++)
        c->t[i] = -(c->R[3 * i] * C[0] + c->R[3 * i + 1] * C[1] + c->R[3 * i + 2] * C[2]);
    c->K[0] = f;
    c->K[4] = f * 1.001;
    c->K[2] = cx;
    c->K[5] = cy;
    c->K[8] = 1;
    c->num_dist = 5;
}

static void rig(sh_calib *calib, int distorted)
{
    memset(calib, 0, sizeof *calib);
    calib->num_cameras = 3;
    calib->width = 1920;
    calib->height = 1080;
    double T[3] = {0, 0, 8};
    double C0[3] = {-60, -20, 500}, C1[3] = {60, -20, 500}, C2[3] = {0, 70, 480};
    look_at(&calib->cam[0], C0, T, 0.02, 2200, 959.5, 539.5);
    look_at(&calib->cam[1], C1, T, -0.03, 2150, 961.0, 541.0);
    look_at(&calib->cam[2], C2, T, 0.05, 2250, 958.0, 538.0);
    if (distorted) {
        double d[3][5] = {{-0.12, 0.09, 0.0007, -0.0005, -0.02},
                          {-0.08, 0.05, -0.0004, 0.0006, 0.01},
                          {-0.15, 0.12, 0.0002, 0.0003, -0.03}};
        for (int i = 0; i < 3; i++) memcpy(calib->cam[i].dist, d[i], sizeof d[i]);
    }
    sh_calib_compute_p(calib);
}

/* deterministic normal variates */
static uint64_t rng_state = 12345;
static double uniform01(void)
{
    rng_state = rng_state * 6364136223846793005ull + 1442695040888963407ull;
    return ((double)(rng_state >> 11) + 0.5) * (1.0 / 9007199254740992.0);
}
static double gauss(void)
{
    return sqrt(-2 * log(uniform01())) * cos(2 * 3.14159265358979323846 * uniform01());
}

static void test_project_pinhole_is_P(void **state)
{
    (void)state;
    sh_calib calib;
    rig(&calib, 0);
    for (int c = 0; c < 3; c++) {
        const sh_calib_camera *cam = &calib.cam[c];
        assert_int_equal(sh_camera_check(cam, c), SH_OK);
        for (int k = 0; k < 50; k++) {
            double X[3] = {-50 + 100 * uniform01(), -40 + 80 * uniform01(), 20 * uniform01()};
            double uv[2];
            assert_int_equal(sh_camera_project(cam, X, uv, NULL), SH_OK);
            const double *P = cam->P;
            double w = P[8] * X[0] + P[9] * X[1] + P[10] * X[2] + P[11];
            double u = (P[0] * X[0] + P[1] * X[1] + P[2] * X[2] + P[3]) / w;
            double v = (P[4] * X[0] + P[5] * X[1] + P[6] * X[2] + P[7]) / w;
            assert_true(fabs(uv[0] - u) < 1e-9 && fabs(uv[1] - v) < 1e-9);
        }
    }
}

/* The distortion formulas evaluated by hand at one point for each coefficient alone. */
static void test_distort_closed_form(void **state)
{
    (void)state;
    sh_calib_camera cam;
    memset(&cam, 0, sizeof cam);
    double x = 0.3, y = -0.2, r2 = 0.13, xd, yd;
    struct {
        int k;
        double v, ex, ey;
    } cases[] = {
        {0, 0.1, 0.3 * (1 + 0.1 * r2), -0.2 * (1 + 0.1 * r2)},
        {1, -0.2, 0.3 * (1 - 0.2 * r2 * r2), -0.2 * (1 - 0.2 * r2 * r2)},
        {4, 0.5, 0.3 * (1 + 0.5 * r2 * r2 * r2), -0.2 * (1 + 0.5 * r2 * r2 * r2)},
        {2, 0.01, 0.3 + 2 * 0.01 * 0.3 * -0.2, -0.2 + 0.01 * (r2 + 2 * 0.04)},
        {3, 0.02, 0.3 + 0.02 * (r2 + 2 * 0.09), -0.2 + 2 * 0.02 * 0.3 * -0.2},
        {5, 0.3, 0.3 / (1 + 0.3 * r2), -0.2 / (1 + 0.3 * r2)},
        {6, 0.3, 0.3 / (1 + 0.3 * r2 * r2), -0.2 / (1 + 0.3 * r2 * r2)},
        {7, 0.3, 0.3 / (1 + 0.3 * r2 * r2 * r2), -0.2 / (1 + 0.3 * r2 * r2 * r2)},
        {8, 0.01, 0.3 + 0.01 * r2, -0.2},
        {9, 0.01, 0.3 + 0.01 * r2 * r2, -0.2},
        {10, 0.01, 0.3, -0.2 + 0.01 * r2},
        {11, 0.01, 0.3, -0.2 + 0.01 * r2 * r2},
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        memset(cam.dist, 0, sizeof cam.dist);
        cam.dist[cases[i].k] = cases[i].v;
        sh_camera_distort(&cam, x, y, &xd, &yd, NULL);
        assert_true(fabs(xd - cases[i].ex) < 1e-15 && fabs(yd - cases[i].ey) < 1e-15);
    }
}

static void test_jacobians_match_differences(void **state)
{
    (void)state;
    sh_calib calib;
    rig(&calib, 1);
    sh_calib_camera *cam = &calib.cam[0];
    /* every coefficient in play for the distortion Jacobian */
    double d[12] = {-0.1, 0.05, 0.001, -0.002, 0.01, 0.02, -0.01, 0.005, 0.001, -0.001, 0.002, 0.0005};
    memcpy(cam->dist, d, sizeof d);
    for (int k = 0; k < 20; k++) {
        double x = -0.4 + 0.8 * uniform01(), y = -0.3 + 0.6 * uniform01(), J[4], h = 1e-6;
        double xd, yd, a0, a1, b0, b1;
        sh_camera_distort(cam, x, y, &xd, &yd, J);
        sh_camera_distort(cam, x + h, y, &a0, &a1, NULL);
        sh_camera_distort(cam, x - h, y, &b0, &b1, NULL);
        assert_true(fabs(J[0] - (a0 - b0) / (2 * h)) < 1e-7 && fabs(J[2] - (a1 - b1) / (2 * h)) < 1e-7);
        sh_camera_distort(cam, x, y + h, &a0, &a1, NULL);
        sh_camera_distort(cam, x, y - h, &b0, &b1, NULL);
        assert_true(fabs(J[1] - (a0 - b0) / (2 * h)) < 1e-7 && fabs(J[3] - (a1 - b1) / (2 * h)) < 1e-7);
    }
    for (int k = 0; k < 20; k++) {
        double X[3] = {-50 + 100 * uniform01(), -40 + 80 * uniform01(), 20 * uniform01()};
        double uv[2], J[6], p[2], m[2], h = 1e-4;
        assert_int_equal(sh_camera_project(cam, X, uv, J), SH_OK);
        for (int j = 0; j < 3; j++) {
            double Xp[3] = {X[0], X[1], X[2]}, Xm[3] = {X[0], X[1], X[2]};
            Xp[j] += h;
            Xm[j] -= h;
            sh_camera_project(cam, Xp, p, NULL);
            sh_camera_project(cam, Xm, m, NULL);
            assert_true(fabs(J[j] - (p[0] - m[0]) / (2 * h)) < 1e-5);
            assert_true(fabs(J[3 + j] - (p[1] - m[1]) / (2 * h)) < 1e-5);
        }
    }
}

static void test_undistort_round_trip(void **state)
{
    (void)state;
    sh_calib calib;
    rig(&calib, 1);
    for (int c = 0; c < 3; c++) {
        const sh_calib_camera *cam = &calib.cam[c];
        for (int gy = 0; gy <= 10; gy++)
            for (int gx = 0; gx <= 10; gx++) {
                double uv[2] = {1919.0 * gx / 10, 1079.0 * gy / 10}, xn[2], xd, yd;
                assert_int_equal(sh_camera_undistort(cam, uv, xn), SH_OK);
                sh_camera_distort(cam, xn[0], xn[1], &xd, &yd, NULL);
                double u = cam->K[0] * xd + cam->K[1] * yd + cam->K[2], v = cam->K[4] * yd + cam->K[5];
                assert_true(fabs(u - uv[0]) < 1e-9 && fabs(v - uv[1]) < 1e-9);
            }
    }
}

static void exact_recovery(int distorted)
{
    sh_calib calib;
    rig(&calib, distorted);
    const sh_calib_camera *cams[3] = {&calib.cam[0], &calib.cam[1], &calib.cam[2]};
    for (int n = 2; n <= 3; n++)
        for (int k = 0; k < 100; k++) {
            double X[3] = {-50 + 100 * uniform01(), -40 + 80 * uniform01(), 25 * uniform01()};
            double uv[6];
            for (int i = 0; i < n; i++) assert_int_equal(sh_camera_project(cams[i], X, uv + 2 * i, NULL), SH_OK);
            sh_triangulation tr;
            assert_int_equal(sh_camera_triangulate(cams, uv, n, 0.2, 0, &tr), SH_OK);
            for (int j = 0; j < 3; j++) assert_true(fabs(tr.X[j] - X[j]) < 1e-8);
            assert_true(tr.rms < 1e-8);
        }
}

static void test_triangulate_exact_pinhole(void **state)
{
    (void)state;
    exact_recovery(0);
}

static void test_triangulate_exact_distorted(void **state)
{
    (void)state;
    exact_recovery(1);
}

/* With Gaussian pixel noise sigma, the least-squares reprojection error sum over 2n coordinates
 * with 3 unknowns is sigma^2 chi^2(2n - 3): mean (2n - 3) sigma^2. The position error against the
 * returned covariance is chi^2(3): mean 3. */
static void test_triangulate_noise_statistics(void **state)
{
    (void)state;
    sh_calib calib;
    rig(&calib, 1);
    const sh_calib_camera *cams[3] = {&calib.cam[0], &calib.cam[1], &calib.cam[2]};
    double sigma = 0.3;
    for (int n = 2; n <= 3; n++) {
        double sum_ss = 0, sum_m = 0;
        int trials = 4000;
        for (int k = 0; k < trials; k++) {
            double X[3] = {-50 + 100 * uniform01(), -40 + 80 * uniform01(), 25 * uniform01()};
            double uv[6];
            for (int i = 0; i < n; i++) {
                sh_camera_project(cams[i], X, uv + 2 * i, NULL);
                uv[2 * i] += sigma * gauss();
                uv[2 * i + 1] += sigma * gauss();
            }
            sh_triangulation tr;
            assert_int_equal(sh_camera_triangulate(cams, uv, n, sigma, 0, &tr), SH_OK);
            sum_ss += tr.rms * tr.rms * n;
            double e[3] = {tr.X[0] - X[0], tr.X[1] - X[1], tr.X[2] - X[2]}, ci[9];
            /* e^T cov^-1 e by solving with Cramer's rule */
            const double *C = tr.cov;
            double det = C[0] * (C[4] * C[8] - C[5] * C[7]) - C[1] * (C[3] * C[8] - C[5] * C[6]) +
                         C[2] * (C[3] * C[7] - C[4] * C[6]);
            ci[0] = (C[4] * C[8] - C[5] * C[7]) / det;
            ci[1] = (C[2] * C[7] - C[1] * C[8]) / det;
            ci[2] = (C[1] * C[5] - C[2] * C[4]) / det;
            ci[3] = ci[1];
            ci[4] = (C[0] * C[8] - C[2] * C[6]) / det;
            ci[5] = (C[2] * C[3] - C[0] * C[5]) / det;
            ci[6] = ci[2];
            ci[7] = ci[5];
            ci[8] = (C[0] * C[4] - C[1] * C[3]) / det;
            double m = 0;
            for (int a = 0; a < 3; a++)
                for (int b = 0; b < 3; b++) m += e[a] * ci[3 * a + b] * e[b];
            sum_m += m;
        }
        double mean_ss = sum_ss / trials / (sigma * sigma), mean_m = sum_m / trials;
        /* chi^2(k) mean k, standard error sqrt(2k / trials) */
        double k = 2 * n - 3;
        assert_true(fabs(mean_ss - k) < 5 * sqrt(2 * k / trials));
        assert_true(fabs(mean_m - 3) < 5 * sqrt(6.0 / trials));
    }
}

static void test_degenerate_and_bad_input(void **state)
{
    (void)state;
    sh_calib calib;
    rig(&calib, 0);
    const sh_calib_camera *same[2] = {&calib.cam[0], &calib.cam[0]};
    double X[3] = {1, 2, 3}, uv[4];
    sh_camera_project(&calib.cam[0], X, uv, NULL);
    uv[2] = uv[0];
    uv[3] = uv[1];
    sh_triangulation tr;
    assert_int_equal(sh_camera_triangulate(same, uv, 2, 1, 0, &tr), SH_EDEGENERATE);
    const sh_calib_camera *one[1] = {&calib.cam[0]};
    assert_int_equal(sh_camera_triangulate(one, uv, 1, 1, 0, &tr), SH_EINVAL);
    const sh_calib_camera *two[2] = {&calib.cam[0], &calib.cam[1]};
    double bad[4] = {NAN, 1, 2, 3};
    assert_int_equal(sh_camera_triangulate(two, bad, 2, 1, 0, &tr), SH_EINVAL);
    double behind[3] = {0, 0, 2000};
    assert_int_equal(sh_camera_project(&calib.cam[0], behind, uv, NULL), SH_ERANGE);
    sh_calib_camera c = calib.cam[1];
    c.R[0] = 2;
    assert_int_equal(sh_camera_check(&c, 1), SH_EINVAL);
    c = calib.cam[1];
    c.dist[12] = 0.1;
    assert_int_equal(sh_camera_check(&c, 1), SH_EUNSUPPORTED);
    c = calib.cam[1];
    c.K[0] = 0;
    assert_int_equal(sh_camera_check(&c, 1), SH_EINVAL);
    double C[3];
    sh_camera_center(&calib.cam[2], C);
    assert_true(fabs(C[0]) < 1e-9 && fabs(C[1] - 70) < 1e-9 && fabs(C[2] - 480) < 1e-9);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_project_pinhole_is_P),
        cmocka_unit_test(test_distort_closed_form),
        cmocka_unit_test(test_jacobians_match_differences),
        cmocka_unit_test(test_undistort_round_trip),
        cmocka_unit_test(test_triangulate_exact_pinhole),
        cmocka_unit_test(test_triangulate_exact_distorted),
        cmocka_unit_test(test_triangulate_noise_statistics),
        cmocka_unit_test(test_degenerate_and_bad_input),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
