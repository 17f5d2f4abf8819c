/* The 3D engine against closed forms: a paraboloid seen by a camera with lens distortion, its
 * markers moved rigidly. The truth (ray-paraboloid intersection, OpenCV's distortion by hand,
 * the stereo disparity f b / Z) is computed here, independently of the engine. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include <cmocka.h>

#include "stillheart/imageio.h"
#include "stillheart/warp3d.h"

#define W 1280
#define H 720
#define Z0 20.0   /* apex height, mm */
#define CURV 0.004 /* Z = Z0 - CURV (X^2 + Y^2) */

static double surface_z(double X, double Y)
{
    return Z0 - CURV * (X * X + Y * Y);
}

/* A camera 500 mm above the patch, tilted by 12 degrees about its x axis, with distortion. */
static void make_camera(sh_calib_camera *c, int distorted)
{
    memset(c, 0, sizeof *c);
    double a = 12 * M_PI / 180;
    /* camera axes in world: x = (1,0,0), y = (0,-cos a, sin a)... looking down and forward */
    double R[9] = {1, 0, 0, 0, -cos(a), -sin(a), 0, sin(a), -cos(a)};
    memcpy(c->R, R, sizeof R);
    double C[3] = {0, -500 * sin(a), 500 * cos(a)}; /* looks at the origin */
    for (int r = 0; r < 3; r++) c->t[r] = -(R[3 * r] * C[0] + R[3 * r + 1] * C[1] + R[3 * r + 2] * C[2]);
    double K[9] = {1100, 0, 640.5, 0, 1100, 359.5, 0, 0, 1};
    memcpy(c->K, K, sizeof K);
    c->num_dist = 5;
    if (distorted) {
        c->dist[0] = -0.12, c->dist[1] = 0.05, c->dist[2] = 0.0008, c->dist[3] = -0.0005,
        c->dist[4] = 0.01;
    }
}

/* OpenCV's projection, written out (k1 k2 p1 p2 k3). */
static void project(const sh_calib_camera *c, const double X[3], double *x, double *y)
{
    double q[3];
    for (int r = 0; r < 3; r++) q[r] = c->R[3 * r] * X[0] + c->R[3 * r + 1] * X[1] + c->R[3 * r + 2] * X[2] + c->t[r];
    double a = q[0] / q[2], b = q[1] / q[2], r2 = a * a + b * b;
    const double *k = c->dist;
    double rad = 1 + k[0] * r2 + k[1] * r2 * r2 + k[4] * r2 * r2 * r2;
    double xd = a * rad + 2 * k[2] * a * b + k[3] * (r2 + 2 * a * a);
    double yd = b * rad + k[2] * (r2 + 2 * b * b) + 2 * k[3] * a * b;
    *x = c->K[0] * xd + c->K[2];
    *y = c->K[4] * yd + c->K[5];
}

/* The world point of the true paraboloid seen at pixel (x, y): undistortion by fixed-point
 * iteration (as cv::undistortPoints), then the ray's quadratic. */
static int locate(const sh_calib_camera *c, double x, double y, double P[3])
{
    double xd = (x - c->K[2]) / c->K[0], yd = (y - c->K[5]) / c->K[4], a = xd, b = yd;
    const double *k = c->dist;
    /* the fixed point converges in tens of steps; 200 at every pixel were most of this test's
     * time, and minutes of it under qemu-aarch64's soft floating point */
    for (int it = 0; it < 200; it++) {
        double r2 = a * a + b * b, rad = 1 + k[0] * r2 + k[1] * r2 * r2 + k[4] * r2 * r2 * r2;
        double dx = 2 * k[2] * a * b + k[3] * (r2 + 2 * a * a), dy = k[2] * (r2 + 2 * b * b) + 2 * k[3] * a * b;
        double na = (xd - dx) / rad, nb = (yd - dy) / rad;
        int done = fabs(na - a) + fabs(nb - b) < 1e-15;
        a = na;
        b = nb;
        if (done) break;
    }
    double dc[3] = {a, b, 1}, d[3], C[3];
    for (int i = 0; i < 3; i++) {
        d[i] = c->R[i] * dc[0] + c->R[3 + i] * dc[1] + c->R[6 + i] * dc[2];
        C[i] = -(c->R[i] * c->t[0] + c->R[3 + i] * c->t[1] + c->R[6 + i] * c->t[2]);
    }
    double A = CURV * (d[0] * d[0] + d[1] * d[1]);
    double B = 2 * CURV * (C[0] * d[0] + C[1] * d[1]) + d[2];
    double Cc = CURV * (C[0] * C[0] + C[1] * C[1]) + C[2] - Z0;
    double disc = B * B - 4 * A * Cc;
    if (disc < 0) return 0;
    double t1 = (-B - sqrt(disc)) / (2 * A), t2 = (-B + sqrt(disc)) / (2 * A);
    double t = t1 > 0 && (t1 < t2 || t2 <= 0) ? t1 : t2;
    if (!(t > 0)) return 0;
    for (int i = 0; i < 3; i++) P[i] = C[i] + t * d[i];
    return 1;
}

static void rotation(const double axis[3], double angle, double R[9])
{
    double l = sqrt(axis[0] * axis[0] + axis[1] * axis[1] + axis[2] * axis[2]);
    double k[3] = {axis[0] / l, axis[1] / l, axis[2] / l}, c = cos(angle), s = sin(angle), v = 1 - c;
    double M[9] = {c + k[0] * k[0] * v, k[0] * k[1] * v - k[2] * s, k[0] * k[2] * v + k[1] * s,
                   k[1] * k[0] * v + k[2] * s, c + k[1] * k[1] * v, k[1] * k[2] * v - k[0] * s,
                   k[2] * k[0] * v - k[1] * s, k[2] * k[1] * v + k[0] * s, c + k[2] * k[2] * v};
    memcpy(R, M, sizeof M);
}

static void transform(const double R[9], const double t[3], const double X[3], double Y[3])
{
    for (int r = 0; r < 3; r++) Y[r] = R[3 * r] * X[0] + R[3 * r + 1] * X[1] + R[3 * r + 2] * X[2] + t[r];
}

/* 4 x 4 markers on the paraboloid (symmetric: the fitted plane is Z = const). */
static int make_markers(double *ref)
{
    int n = 0;
    for (int j = 0; j < 4; j++)
        for (int i = 0; i < 4; i++) {
            double X = -45 + 30 * i, Y = -45 + 30 * j;
            ref[3 * n] = X, ref[3 * n + 1] = Y, ref[3 * n + 2] = surface_z(X, Y);
            n++;
        }
    return n;
}

static const double motion_axis[3] = {0.3, -1, 0.4};
static const double motion_t[3] = {4, -3, 2.5};
#define MOTION_ANGLE (4 * M_PI / 180)

/* A model through ref with `method` for both interpolants, and camera cam's view of it. */
static void model_and_view(const char *method, const double *ref, int n, const sh_calib_camera *cam,
                           sh_warp3d_model **model, sh_warp3d_view **view)
{
    sh_warp3d_params params;
    sh_warp3d_params_default(&params);
    assert_int_equal(sh_interp_params_parse(method, &params.surface), SH_OK);
    assert_int_equal(sh_interp_params_parse(method, &params.displacement), SH_OK);
    if (sh_warp3d_model_create(&params, ref, n, model) != SH_OK) fail_msg("%s", sh_error_message());
    if (sh_warp3d_view_create(*model, cam, cam, W, H, NULL, view) != SH_OK) fail_msg("%s", sh_error_message());
}

/* The largest distance, over the view's hull every `step` px, between the view's map and where
 * the surface point seen there is after the rigid motion (Rm, motion_t): every hull pixel mapped. */
static double rigid_error(const sh_warp3d_view *view, const sh_calib_camera *cam, const double Rm[9], int step,
                          int *samples)
{
    float *map = malloc(sizeof(float) * 2 * W * H);
    assert_non_null(map);
    assert_int_equal(sh_warp_model_map(sh_warp3d_view_map_model(view), map), SH_OK);
    const sh_hull *hull = sh_warp3d_view_hull(view);
    double worst = 0;
    *samples = 0;
    for (int y = 0; y < H; y += step)
        for (int x = 0; x < W; x += step) {
            if (!sh_hull_contains(hull, x, y)) continue;
            double P[3], Q[3], tx, ty;
            assert_true(locate(cam, x, y, P));
            transform(Rm, motion_t, P, Q);
            project(cam, Q, &tx, &ty);
            const float *m = map + 2 * ((size_t)y * W + x);
            assert_false(isnan(m[0]));
            worst = fmax(worst, hypot(m[0] - tx, m[1] - ty));
            (*samples)++;
        }
    free(map);
    return worst;
}

static void test_rigid_motion_removed_exactly(void **state)
{
    (void)state;
    sh_calib_camera cam;
    make_camera(&cam, 1);
    double ref[48], cur[48], Rm[9];
    int n = make_markers(ref);
    rotation(motion_axis, MOTION_ANGLE, Rm);
    for (int i = 0; i < n; i++) transform(Rm, motion_t, ref + 3 * i, cur + 3 * i);

    const char *methods[] = {"bspline", "tps", "pwlinear"};
    for (size_t mi = 0; mi < sizeof methods / sizeof methods[0]; mi++) {
        sh_warp3d_model *model;
        sh_warp3d_view *view;
        model_and_view(methods[mi], ref, n, &cam, &model, &view);
        assert_int_equal(sh_warp3d_model_update(model, cur), SH_OK);
        assert_int_equal(sh_warp3d_view_update(view), SH_OK);
        int samples;
        double worst = rigid_error(view, &cam, Rm, 3, &samples);
        printf("rigid motion, %s: %d samples, largest error %.4f px (grid %d px)\n", methods[mi],
               samples, worst, sh_warp3d_view_grid_spacing(view));
        assert_true(samples > 4000);
        assert_true(worst < 0.05);
        sh_warp3d_view_destroy(view);
        sh_warp3d_model_destroy(model);
    }
}

/* sh_warp3d_model_update_subset: the surface moved rigidly, every other marker used and the
 * others' current positions NaN (not read): the displacement's trend (affine in 3D over the
 * surface) takes the motion whole, so the map is the true one as with every marker; with every
 * marker used it is the full update's; too few used, or pwlinear, are refused. */
static void test_subset_update(void **state)
{
    (void)state;
    sh_calib_camera cam;
    make_camera(&cam, 1);
    double ref[48], cur[48], half[48], Rm[9];
    int n = make_markers(ref);
    unsigned char use[16], all[16], three[16];
    rotation(motion_axis, MOTION_ANGLE, Rm);
    for (int i = 0; i < n; i++) {
        transform(Rm, motion_t, ref + 3 * i, cur + 3 * i);
        use[i] = i % 2 == 0, all[i] = 1, three[i] = i < 3;
        for (int c = 0; c < 3; c++) half[3 * i + c] = use[i] ? cur[3 * i + c] : NAN;
    }
    const char *methods[] = {"tps", "bspline"};
    for (size_t mi = 0; mi < sizeof methods / sizeof methods[0]; mi++) {
        sh_warp3d_model *model;
        sh_warp3d_view *view;
        model_and_view(methods[mi], ref, n, &cam, &model, &view);
        if (sh_warp3d_model_update_subset(model, half, use) != SH_OK) fail_msg("%s", sh_error_message());
        assert_int_equal(sh_warp3d_view_update(view), SH_OK);
        int samples;
        double worst = rigid_error(view, &cam, Rm, 5, &samples);
        printf("rigid motion through 8 of 16 markers, %s: largest error %.4f px\n", methods[mi], worst);
        assert_true(worst < 0.05);
        /* every marker used: the full update's displacement */
        double a[3], b[3];
        assert_int_equal(sh_warp3d_model_update_subset(model, cur, all), SH_OK);
        sh_warp3d_model_point(model, 3, -2, 1, 1, a);
        assert_int_equal(sh_warp3d_model_update(model, cur), SH_OK);
        sh_warp3d_model_point(model, 3, -2, 1, 1, b);
        for (int c = 0; c < 3; c++) assert_true(fabs(a[c] - b[c]) < 1e-9);
        assert_int_equal(sh_warp3d_model_update_subset(model, cur, three), SH_EDEGENERATE);
        sh_warp3d_view_destroy(view);
        sh_warp3d_model_destroy(model);
    }
    sh_warp3d_params params;
    sh_warp3d_params_default(&params);
    assert_int_equal(sh_interp_params_parse("pwlinear", &params.displacement), SH_OK);
    sh_warp3d_model *model;
    assert_int_equal(sh_warp3d_model_create(&params, ref, n, &model), SH_OK);
    assert_int_equal(sh_warp3d_model_update_subset(model, cur, use), SH_EINVAL);
    sh_warp3d_model_destroy(model);
}

/* Gaussian dots glued to the paraboloid at known (X, Y), rendered by ray casting (the current
 * frame: the surface moved rigidly by Rm, t). */
#define DOTS 9
static double dot_xy[DOTS][2];

static uint8_t render_pixel(const sh_calib_camera *cam, const double Rm[9], const double t[3], double x,
                            double y)
{
    /* the moved surface seen at (x, y) is the reference surface seen by the camera moved back */
    sh_calib_camera back = *cam; /* X_cam = R (Rm X0 + t) + t_c */
    for (int r = 0; r < 3; r++) {
        for (int c = 0; c < 3; c++) {
            double s = 0;
            for (int j = 0; j < 3; j++) s += cam->R[3 * r + j] * Rm[3 * j + c];
            back.R[3 * r + c] = s;
        }
        back.t[r] = cam->t[r] + cam->R[3 * r] * t[0] + cam->R[3 * r + 1] * t[1] + cam->R[3 * r + 2] * t[2];
    }
    double P[3];
    if (!locate(&back, x, y, P)) return 0;
    double v = 20;
    for (int d = 0; d < DOTS; d++) {
        double dx = P[0] - dot_xy[d][0], dy = P[1] - dot_xy[d][1];
        v += 220 * exp(-(dx * dx + dy * dy) / (2 * 1.2 * 1.2));
    }
    return (uint8_t)lrint(fmin(v, 255));
}

static void centroid(const sh_image *img, int x0, double px, double py, double *cx, double *cy)
{
    double sw = 0, sx = 0, sy = 0;
    for (int y = (int)py - 9; y <= (int)py + 9; y++)
        for (int x = (int)px - 9; x <= (int)px + 9; x++) {
            double w = img->plane[0].data[(size_t)y * img->plane[0].stride + x0 + x] - 20.0;
            if (w < 2) continue;
            sw += w, sx += w * x, sy += w * y;
        }
    *cx = sx / sw;
    *cy = sy / sw;
}

/* Dot d's true pixels in the two eyes and its depth (closed form, not the engine). */
static void dot_truth(const sh_calib_camera eye[2], int d, double *xl, double *yl, double *xr, double *yr,
                      double *depth)
{
    double P[3] = {dot_xy[d][0], dot_xy[d][1], surface_z(dot_xy[d][0], dot_xy[d][1])};
    project(&eye[0], P, xl, yl);
    project(&eye[1], P, xr, yr);
    *depth = eye[0].R[6] * P[0] + eye[0].R[7] * P[1] + eye[0].R[8] * P[2] + eye[0].t[2];
}

/* Over 80 lines: for each of two baselines the side-by-side frame, then the sbs-half layout cut
 * from that same frame, both against the closed-form disparity of the same dots. */
static void test_stereo_disparity(void **state)
{
    (void)state;
    sh_calib_camera cam;
    make_camera(&cam, 1);
    double ref[48], cur[48], Rm[9];
    int n = make_markers(ref);
    rotation(motion_axis, MOTION_ANGLE, Rm);
    for (int i = 0; i < n; i++) transform(Rm, motion_t, ref + 3 * i, cur + 3 * i);
    for (int d = 0; d < DOTS; d++) dot_xy[d][0] = -30 + 30 * (d % 3), dot_xy[d][1] = -30 + 30 * (d / 3);

    sh_image frame;
    assert_int_equal(sh_image_create(&frame, SH_PIX_GRAY8, W, H), SH_OK);
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++)
            frame.plane[0].data[(size_t)y * frame.plane[0].stride + x] = render_pixel(&cam, Rm, motion_t, x, y);

    sh_warp3d_model *model;
    assert_int_equal(sh_warp3d_model_create(NULL, ref, n, &model), SH_OK);
    assert_int_equal(sh_warp3d_model_update(model, cur), SH_OK);
    const double baselines[] = {6, 20};
    for (int bi = 0; bi < 2; bi++) {
        double b = baselines[bi];
        sh_calib_camera eye[2];
        sh_warp3d_stereo_cameras(&cam, b, &eye[0], &eye[1]);
        sh_image sbs;
        assert_int_equal(sh_image_create(&sbs, SH_PIX_GRAY8, 2 * W, H), SH_OK);
        sh_warp *warp;
        assert_int_equal(sh_warp_create(1, &warp), SH_OK);
        for (int e = 0; e < 2; e++) {
            sh_warp3d_view *view;
            if (sh_warp3d_view_create(model, &eye[e], &cam, W, H, NULL, &view) != SH_OK)
                fail_msg("%s", sh_error_message());
            assert_int_equal(sh_warp3d_view_update(view), SH_OK);
            assert_int_equal(sh_warp3d_view_apply(warp, view, &frame, &sbs, e * W, 0), SH_OK);
            sh_warp3d_view_destroy(view);
        }
        double worst = 0;
        for (int d = 0; d < DOTS; d++) {
            double xl, yl, xr, yr, depth;
            dot_truth(eye, d, &xl, &yl, &xr, &yr, &depth);
            double expected = cam.K[0] * b / depth; /* closed form */
            double lx, ly, rx, ry;
            centroid(&sbs, 0, xl, yl, &lx, &ly);
            centroid(&sbs, W, xr, yr, &rx, &ry);
            double err = fabs((lx - rx) - expected);
            worst = fmax(worst, fmax(err, fabs(ly - ry)));
            assert_true(fabs(xl - xr - expected) < 1e-9);
        }
        printf("stereo baseline %g mm: largest disparity error %.4f px\n", b, worst);
        assert_true(worst < 0.25);
        /* the squeezed layout (sbs-half): each eye halved along x into one W x H frame; pixel i
         * of a half covers full pixels 2i and 2i + 1, so x_half = (x - 0.5) / 2 and the
         * disparity halves */
        sh_image half;
        assert_int_equal(sh_image_create(&half, SH_PIX_GRAY8, W, H), SH_OK);
        for (int e = 0; e < 2; e++) {
            sh_image one = sbs;
            one.owned = NULL;
            one.width = one.plane[0].width = W;
            one.plane[0].data += e * W;
            assert_int_equal(sh_warp3d_squeeze(&one, 0, &half, e * W / 2, 0), SH_OK);
        }
        double worst_half = 0;
        for (int d = 0; d < DOTS; d++) {
            double xl, yl, xr, yr, depth;
            dot_truth(eye, d, &xl, &yl, &xr, &yr, &depth);
            double lx, ly, rx, ry;
            centroid(&half, 0, (xl - 0.5) / 2, yl, &lx, &ly);
            centroid(&half, W / 2, (xr - 0.5) / 2, yr, &rx, &ry);
            worst_half = fmax(worst_half, fabs((lx - rx) - cam.K[0] * b / depth / 2));
            worst_half = fmax(worst_half, fabs(lx - (xl - 0.5) / 2)); /* and each eye where it belongs */
        }
        printf("stereo baseline %g mm, sbs-half: largest disparity / position error %.4f px (half width)\n", b,
               worst_half);
        assert_true(worst_half < 0.25);
        sh_image_destroy(&half);
        sh_warp_destroy(warp);
        sh_image_destroy(&sbs);
    }
    sh_warp3d_model_destroy(model);
    sh_image_destroy(&frame);
}

/* The squeeze of the half-resolution layouts against closed forms: a ramp 10 x + y halved
 * along x is 20 x + y + 5 (pairs 10 (2x) + y and 10 (2x + 1) + y, rounded up), along y
 * 10 x + 2 y + 1. */
static void test_squeeze(void **state)
{
    (void)state;
    sh_image full, out;
    assert_int_equal(sh_image_create(&full, SH_PIX_GRAY8, 16, 8), SH_OK);
    assert_int_equal(sh_image_create(&out, SH_PIX_GRAY8, 16, 8), SH_OK);
    for (int y = 0; y < 8; y++)
        for (int x = 0; x < 16; x++) full.plane[0].data[(size_t)y * full.plane[0].stride + x] = (uint8_t)(10 * x + y);
    memset(out.plane[0].data, 0, (size_t)out.plane[0].stride * 8);
    assert_int_equal(sh_warp3d_squeeze(&full, 0, &out, 8, 0), SH_OK);
    for (int y = 0; y < 8; y++)
        for (int x = 0; x < 16; x++)
            assert_int_equal(out.plane[0].data[(size_t)y * out.plane[0].stride + x], x < 8 ? 0 : 20 * (x - 8) + y + 5);
    assert_int_equal(sh_warp3d_squeeze(&full, 1, &out, 0, 4), SH_OK);
    for (int y = 4; y < 8; y++)
        for (int x = 0; x < 16; x++)
            assert_int_equal(out.plane[0].data[(size_t)y * out.plane[0].stride + x], 10 * x + 2 * (y - 4) + 1);
    assert_int_equal(sh_warp3d_squeeze(&full, 0, &out, 9, 0), SH_EINVAL); /* past the edge */
    assert_int_equal(sh_warp3d_squeeze(&full, 2, &out, 0, 0), SH_EINVAL);
    sh_image_destroy(&full);
    sh_image_destroy(&out);
    /* 4:2:0: chroma halves with luma; widths / heights a multiple of 4, even offsets */
    sh_image a, b, c;
    assert_int_equal(sh_image_create(&a, SH_PIX_I420, 8, 4), SH_OK);
    assert_int_equal(sh_image_create(&b, SH_PIX_I420, 8, 4), SH_OK);
    assert_int_equal(sh_image_create(&c, SH_PIX_I420, 6, 4), SH_OK);
    for (int p = 0; p < 3; p++)
        for (int y = 0; y < a.plane[p].height; y++)
            for (int x = 0; x < a.plane[p].width; x++)
                a.plane[p].data[(size_t)y * a.plane[p].stride + x] = (uint8_t)(100 * p + 4 * x);
    assert_int_equal(sh_warp3d_squeeze(&a, 0, &b, 4, 0), SH_OK);
    for (int p = 0; p < 3; p++)
        for (int y = 0; y < b.plane[p].height; y++)
            for (int x = b.plane[p].width / 2; x < b.plane[p].width; x++)
                assert_int_equal(b.plane[p].data[(size_t)y * b.plane[p].stride + x],
                                 100 * p + 8 * (x - b.plane[p].width / 2) + 2);
    assert_int_equal(sh_warp3d_squeeze(&c, 0, &b, 0, 0), SH_EINVAL); /* 6 wide */
    assert_int_equal(sh_warp3d_squeeze(&a, 1, &b, 0, 1), SH_EINVAL); /* odd offset */
    assert_int_equal(sh_warp3d_squeeze(&a, 0, &c, 4, 0), SH_EINVAL); /* no room */
    sh_image_destroy(&a);
    sh_image_destroy(&b);
    sh_image_destroy(&c);
}

/* The stereo layouts' frames and windows, from their definitions: sbs 2W x H, tb W x 2H, the
 * halves W x H; eye 1 right of or below eye 0; a window is the same memory at the offset. */
static void test_stereo_layouts(void **state)
{
    (void)state;
    static const struct { const char *name; int w, h, x1, y1; } want[] = {
        {"sbs", 2 * 8, 12, 8, 0}, {"tb", 8, 2 * 12, 0, 12}, {"sbs-half", 8, 12, 4, 0}, {"tb-half", 8, 12, 0, 6}};
    for (int l = 0; l < 4; l++) {
        sh_warp3d_layout layout;
        int fw, fh;
        assert_int_equal(sh_warp3d_layout_parse(want[l].name, &layout), SH_OK);
        assert_string_equal(sh_warp3d_layout_name(layout), want[l].name);
        assert_int_equal(sh_warp3d_layout_size(layout, SH_PIX_I420, 8, 12, &fw, &fh), SH_OK);
        assert_int_equal(fw, want[l].w);
        assert_int_equal(fh, want[l].h);
        /* each eye's picture a constant: the frame holds eye 0's value left or above x1/y1 */
        sh_image eye[2], frame;
        assert_int_equal(sh_image_create(&frame, SH_PIX_I420, fw, fh), SH_OK);
        for (int e = 0; e < 2; e++) {
            assert_int_equal(sh_image_create(&eye[e], SH_PIX_I420, 8, 12), SH_OK);
            for (int p = 0; p < 3; p++)
                for (int y = 0; y < eye[e].plane[p].height; y++)
                    memset(eye[e].plane[p].data + (size_t)y * eye[e].plane[p].stride, 50 + 100 * e + p,
                           (size_t)eye[e].plane[p].width);
            assert_int_equal(sh_warp3d_layout_place(layout, e, &eye[e], &frame), SH_OK);
        }
        for (int p = 0; p < 3; p++) {
            int s = p ? 2 : 1;
            for (int y = 0; y < frame.plane[p].height; y++)
                for (int x = 0; x < frame.plane[p].width; x++) {
                    int e = (want[l].x1 && x >= want[l].x1 / s) || (want[l].y1 && y >= want[l].y1 / s);
                    assert_int_equal(frame.plane[p].data[(size_t)y * frame.plane[p].stride + x], 50 + 100 * e + p);
                }
        }
        sh_image view;
        if (sh_warp3d_layout_half(layout)) {
            assert_int_equal(sh_warp3d_layout_window(layout, 1, &frame, 8, 12, &view), SH_EINVAL);
        } else {
            assert_int_equal(sh_warp3d_layout_window(layout, 1, &frame, 8, 12, &view), SH_OK);
            assert_int_equal(view.width, 8);
            assert_int_equal(view.height, 12);
            assert_ptr_equal(view.plane[0].data, frame.plane[0].data + (size_t)want[l].y1 * frame.plane[0].stride + want[l].x1);
            assert_ptr_equal(view.plane[1].data, frame.plane[1].data + (size_t)(want[l].y1 / 2) * frame.plane[1].stride + want[l].x1 / 2);
            assert_int_equal(view.plane[2].stride, frame.plane[2].stride);
            assert_null(view.owned);
        }
        for (int e = 0; e < 2; e++) sh_image_destroy(&eye[e]);
        sh_image_destroy(&frame);
    }
    /* what cannot be made: a squeezed side that does not halve into whole chroma, oversize */
    int fw, fh;
    assert_int_equal(sh_warp3d_layout_size(SH_WARP3D_TB_HALF, SH_PIX_I420, 8, 6, &fw, &fh), SH_EINVAL);
    assert_int_equal(sh_warp3d_layout_size(SH_WARP3D_TB_HALF, SH_PIX_GRAY8, 8, 6, &fw, &fh), SH_OK);
    assert_int_equal(sh_warp3d_layout_size(SH_WARP3D_SBS_HALF, SH_PIX_GRAY8, 7, 6, &fw, &fh), SH_EINVAL);
    assert_int_equal(sh_warp3d_layout_size(SH_WARP3D_SBS, SH_PIX_GRAY8, SH_IMAGE_MAX_SIZE / 2 + 1, 6, &fw, &fh), SH_EINVAL);
    assert_int_equal(sh_warp3d_layout_size(SH_WARP3D_SBS, SH_PIX_GRAY8, SH_IMAGE_MAX_SIZE / 2, 6, &fw, &fh), SH_OK);
    sh_warp3d_layout layout;
    assert_int_equal(sh_warp3d_layout_parse("side-by-side", &layout), SH_EINVAL);
    /* windows outside the frame, or on an odd 4:2:0 offset */
    sh_image img, view;
    assert_int_equal(sh_image_create(&img, SH_PIX_I420, 16, 8), SH_OK);
    assert_int_equal(sh_image_window(&img, 1, 0, 8, 8, &view), SH_EINVAL);
    assert_int_equal(sh_image_window(&img, 10, 0, 8, 8, &view), SH_EINVAL);
    assert_int_equal(sh_image_window(&img, 8, 0, 8, 8, &view), SH_OK);
    assert_int_equal(view.plane[1].width, 4);
    sh_image_destroy(&img);
}

/* The reference view under the rigid motion gives back the reference picture. */
static void test_reference_view_image(void **state)
{
    (void)state;
    sh_calib_camera cam;
    make_camera(&cam, 1);
    double ref[48], cur[48], Rm[9], I[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1}, zero[3] = {0, 0, 0};
    int n = make_markers(ref);
    rotation(motion_axis, MOTION_ANGLE, Rm);
    for (int i = 0; i < n; i++) transform(Rm, motion_t, ref + 3 * i, cur + 3 * i);
    sh_image frame, refimg, out;
    assert_int_equal(sh_image_create(&frame, SH_PIX_GRAY8, W, H), SH_OK);
    assert_int_equal(sh_image_create(&refimg, SH_PIX_GRAY8, W, H), SH_OK);
    assert_int_equal(sh_image_create(&out, SH_PIX_GRAY8, W, H), SH_OK);
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++) {
            frame.plane[0].data[(size_t)y * frame.plane[0].stride + x] = render_pixel(&cam, Rm, motion_t, x, y);
            refimg.plane[0].data[(size_t)y * refimg.plane[0].stride + x] = render_pixel(&cam, I, zero, x, y);
        }
    sh_warp3d_model *model;
    sh_warp3d_view *view;
    sh_warp *warp;
    assert_int_equal(sh_warp3d_model_create(NULL, ref, n, &model), SH_OK);
    assert_int_equal(sh_warp3d_view_create(model, &cam, &cam, W, H, NULL, &view), SH_OK);
    assert_int_equal(sh_warp_create(2, &warp), SH_OK);
    assert_int_equal(sh_warp3d_model_update(model, cur), SH_OK);
    assert_int_equal(sh_warp3d_view_update(view), SH_OK);
    assert_int_equal(sh_warp3d_view_apply(warp, view, &frame, &out, 0, 0), SH_OK);
    const sh_hull *hull = sh_warp3d_view_hull(view);
    double sum = 0;
    int count = 0, outside_black = 1;
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++) {
            int a = out.plane[0].data[(size_t)y * out.plane[0].stride + x];
            if (!sh_hull_contains(hull, x, y)) {
                if (a != 0 && !sh_hull_contains(hull, x + 1, y) && !sh_hull_contains(hull, x - 1, y))
                    outside_black = 0;
                continue;
            }
            sum += abs(a - refimg.plane[0].data[(size_t)y * refimg.plane[0].stride + x]);
            count++;
        }
    printf("reference view: mean |stabilized - reference| %.3f levels over %d pixels\n", sum / count, count);
    assert_true(outside_black);
    assert_true(sum / count < 0.6);
    sh_warp_destroy(warp);
    sh_warp3d_view_destroy(view);
    sh_warp3d_model_destroy(model);
    sh_image_destroy(&frame);
    sh_image_destroy(&refimg);
    sh_image_destroy(&out);
}

static void test_ply_on_surface(void **state)
{
    (void)state;
    double ref[48];
    int n = make_markers(ref);
    sh_warp3d_model *model;
    sh_warp3d_ply *ply;
    assert_int_equal(sh_warp3d_model_create(NULL, ref, n, &model), SH_OK);
    assert_int_equal(sh_warp3d_ply_create(model, 2.0, 1, &ply), SH_OK);
    char path[] = "/tmp/test_warp3d_XXXXXX";
    int fd = mkstemp(path);
    assert_true(fd >= 0);
    close(fd);
    assert_int_equal(sh_warp3d_ply_write(ply, model, 0, NULL, NULL, path), SH_OK);
    FILE *f = fopen(path, "rb");
    assert_non_null(f);
    char line[256];
    int vertices = -1, faces = -1;
    while (fgets(line, sizeof line, f) && strcmp(line, "end_header\n")) {
        sscanf(line, "element vertex %d", &vertices);
        sscanf(line, "element face %d", &faces);
    }
    /* 90 x 90 mm hull at 2 mm: 46 x 46 lattice points */
    assert_int_equal(vertices, 46 * 46);
    assert_int_equal(faces, 2 * 45 * 45);
    double worst = 0;
    for (int k = 0; k < vertices; k++) {
        unsigned char rec[15];
        assert_int_equal(fread(rec, 1, 15, f), 15);
        float p[3];
        memcpy(p, rec, 12);
        worst = fmax(worst, fabs(p[2] - surface_z(p[0], p[1])));
    }
    fclose(f);
    unlink(path);
    assert_true(worst < 1e-4);
    sh_warp3d_ply_destroy(ply);
    sh_warp3d_model_destroy(model);
}

/* The textured mesh: every vertex on the paraboloid, its texture coordinate its pixel in the
 * camera (this file's closed-form projection) over the frame's size, the
 * lattice's triangles, and the texture the frame itself.
 * Over 80 lines: one export read back file by file in the order the files name each other (OBJ, its
 * MTL, the PNG texture). */
static void test_obj_textured(void **state)
{
    (void)state;
    double ref[48];
    int n = make_markers(ref);
    sh_calib_camera cam;
    make_camera(&cam, 1);
    sh_warp3d_model *model;
    sh_warp3d_ply *ply, *cloud;
    assert_int_equal(sh_warp3d_model_create(NULL, ref, n, &model), SH_OK);
    assert_int_equal(sh_warp3d_ply_create(model, 2.0, 1, &ply), SH_OK);
    assert_int_equal(sh_warp3d_ply_create(model, 2.0, 0, &cloud), SH_OK);
    sh_image rgb;
    assert_int_equal(sh_image_create(&rgb, SH_PIX_RGB24, W, H), SH_OK);
    for (int y = 0; y < H; y++)
        for (int x = 0; x < 3 * W; x++) rgb.plane[0].data[(size_t)y * rgb.plane[0].stride + x] = (uint8_t)(x ^ y);
    char dir[] = "/tmp/test_warp3d_obj_XXXXXX", base[64], path[80];
    assert_non_null(mkdtemp(dir));
    snprintf(base, sizeof base, "%s/mesh", dir);
    assert_int_equal(sh_warp3d_obj_write(cloud, model, 0, &rgb, &cam, base), SH_EINVAL); /* no triangles */
    assert_int_equal(sh_warp3d_obj_write(ply, model, 0, &rgb, &cam, base), SH_OK);
    snprintf(path, sizeof path, "%s.obj", base);
    FILE *f = fopen(path, "r");
    assert_non_null(f);
    static double v[46 * 46][3];
    int nv = 0, nvt = 0, nf = 0, mtl = 0;
    double worst_z = 0, worst_t = 0;
    char line[256];
    while (fgets(line, sizeof line, f)) {
        double a, b, c;
        int i[6];
        if (sscanf(line, "v %lf %lf %lf", &a, &b, &c) == 3) {
            assert_true(nv < 46 * 46);
            v[nv][0] = a, v[nv][1] = b, v[nv][2] = c;
            worst_z = fmax(worst_z, fabs(c - surface_z(a, b)));
            nv++;
        } else if (sscanf(line, "vt %lf %lf", &a, &b) == 2) {
            double uv[2];
            assert_true(nvt < nv);
            project(&cam, v[nvt], &uv[0], &uv[1]);
            worst_t = fmax(worst_t, fmax(fabs(a * W - 0.5 - uv[0]), fabs((1 - b) * H - 0.5 - uv[1])));
            nvt++;
        } else if (sscanf(line, "f %d/%d %d/%d %d/%d", &i[0], &i[1], &i[2], &i[3], &i[4], &i[5]) == 6) {
            for (int k = 0; k < 6; k++) assert_true(i[k] >= 1 && i[k] <= nv);
            nf++;
        } else if (!strcmp(line, "mtllib mesh.mtl\n")) {
            mtl = 1;
        }
    }
    fclose(f);
    /* 90 x 90 mm hull at 2 mm: 46 x 46 lattice points */
    assert_int_equal(nv, 46 * 46);
    assert_int_equal(nvt, nv);
    assert_int_equal(nf, 2 * 45 * 45);
    assert_true(mtl);
    printf("OBJ: %d vertices, |z - surface| max %.2e mm, |texture coordinate - pixel| max %.2e px\n", nv, worst_z,
           worst_t);
    assert_true(worst_z < 1e-4);
    assert_true(worst_t < 1e-3); /* 7 decimals of W or H */
    snprintf(path, sizeof path, "%s.mtl", base);
    f = fopen(path, "r");
    assert_non_null(f);
    int map = 0;
    while (fgets(line, sizeof line, f)) map |= !strcmp(line, "map_Kd mesh.png\n");
    fclose(f);
    assert_true(map);
    snprintf(path, sizeof path, "%s.png", base);
    sh_image back;
    if (sh_imageio_read(path, &back) == SH_OK) { /* built with libpng */
        assert_int_equal(back.format, SH_PIX_RGB24);
        for (int y = 0; y < H; y++)
            assert_memory_equal(back.plane[0].data + (size_t)y * back.plane[0].stride,
                                rgb.plane[0].data + (size_t)y * rgb.plane[0].stride, 3 * W);
        sh_image_destroy(&back);
    }
    char cmd[128];
    snprintf(cmd, sizeof cmd, "rm -rf '%s'", dir);
    assert_int_equal(system(cmd), 0);
    sh_image_destroy(&rgb);
    sh_warp3d_ply_destroy(ply);
    sh_warp3d_ply_destroy(cloud);
    sh_warp3d_model_destroy(model);
}

/* sh_warp3d_model_create_smoothed and sh_warp3d_pixels_per_mm against a 2D TPS in the image's
 * pixels. A flat patch facing a pinhole camera at depth D is seen at f / D px a mm (the closed
 * form); the model's displacement through markers (met exactly) and landmarks (smoothed by
 * lambda / s^2 over mm) must be the 2D TPS through the same points' pixels with the landmarks
 * smoothed by lambda, which sh_interp computes on its own. Tilted by 30 degrees before a distant
 * camera (nearly affine), the scale is the geometric mean of f / D and f cos 30 / D. */
#define SM_MARKERS 8
#define SM_POINTS 24
static void test_smoothed_model_in_pixels(void **state)
{
    (void)state;
    const double f = 800, depth = 250, lambda_px = 1000;
    sh_calib_camera cam;
    memset(&cam, 0, sizeof cam);
    double K[9] = {f, 0, 640.5, 0, f, 359.5, 0, 0, 1}, R[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
    memcpy(cam.K, K, sizeof K);
    memcpy(cam.R, R, sizeof R);
    cam.t[2] = depth;
    cam.num_dist = 5;
    double ref[3 * SM_POINTS], cur[3 * SM_POINTS], px[2 * SM_POINTS], disp[2 * SM_POINTS];
    double lam_mm[SM_POINTS], lam_px[SM_POINTS];
    unsigned lcg = 12345;
    for (int i = 0; i < SM_POINTS; i++) {
        double XY[2];
        for (int c = 0; c < 2; c++) {
            lcg = lcg * 1103515245u + 12345u;
            XY[c] = ((lcg >> 8) % 8001) / 100.0 - 40;
        }
        const double X = XY[0], Y = XY[1];
        lcg = lcg * 1103515245u + 12345u;
        double noise = i < SM_MARKERS ? 0 : ((lcg >> 8) % 201) / 1000.0 - 0.1; /* a landmark's error, mm */
        disp[2 * i] = 0.8 + 0.01 * X - 0.005 * Y + 0.3 * sin(X / 15) + noise;
        disp[2 * i + 1] = -0.4 + 0.004 * X + 0.2 * cos(Y / 12) - noise;
        double P[3] = {X, Y, 0}, C[3] = {X + disp[2 * i], Y + disp[2 * i + 1], 0};
        memcpy(ref + 3 * i, P, sizeof P);
        memcpy(cur + 3 * i, C, sizeof C);
        px[2 * i] = f * X / depth + 640.5, px[2 * i + 1] = f * Y / depth + 359.5;
        lam_px[i] = i < SM_MARKERS ? 0 : lambda_px;
    }
    double s;
    assert_int_equal(sh_warp3d_pixels_per_mm(&cam, ref, SM_POINTS, &s), SH_OK);
    assert_true(fabs(s - f / depth) < 1e-9 * f / depth);
    for (int i = 0; i < SM_POINTS; i++) lam_mm[i] = lam_px[i] / (s * s);

    sh_warp3d_params params;
    sh_warp3d_params_default(&params);
    assert_int_equal(sh_interp_params_parse("tps", &params.surface), SH_OK);
    assert_int_equal(sh_interp_params_parse("tps", &params.displacement), SH_OK);
    sh_warp3d_model *m;
    if (sh_warp3d_model_create_smoothed(&params, ref, SM_POINTS, lam_mm, &m) != SH_OK) fail_msg("%s", sh_error_message());
    assert_int_equal(sh_warp3d_model_update(m, cur), SH_OK);
    sh_interp_params tps;
    assert_int_equal(sh_interp_params_parse("tps", &tps), SH_OK);
    sh_interp *it;
    assert_int_equal(sh_interp_create_smoothed(&tps, px, SM_POINTS, lam_px, &it), SH_OK);
    double *coef = calloc(2 * (size_t)sh_interp_num_coefs(it), sizeof *coef);
    assert_non_null(coef);
    assert_int_equal(sh_interp_fit(it, disp, 2, coef), SH_OK);
    double origin[3], axes[9], worst = 0, marker_worst = 0, landmark_off = 0;
    sh_warp3d_model_frame(m, origin, axes);
    for (int q = 0; q < 25 + SM_POINTS; q++) {
        /* a 5 x 5 grid over the patch, then the points themselves */
        double Q[3] = {q < 25 ? -35 + 17.5 * (q % 5) : ref[3 * (q - 25)], q < 25 ? -35 + 17.5 * (q / 5) : ref[3 * (q - 25) + 1], 0};
        double d[3] = {Q[0] - origin[0], Q[1] - origin[1], Q[2] - origin[2]};
        double u = d[0] * axes[0] + d[1] * axes[1] + d[2] * axes[2], v = d[0] * axes[3] + d[1] * axes[4] + d[2] * axes[5];
        double a[3], b[3], h2[2];
        sh_warp3d_model_point(m, u, v, 1, 0, a);
        sh_warp3d_model_point(m, u, v, 1, 1, b);
        assert_int_equal(sh_interp_eval(it, coef, 2, f * Q[0] / depth + 640.5, f * Q[1] / depth + 359.5, h2), SH_OK);
        for (int c = 0; c < 2; c++) worst = fmax(worst, fabs(b[c] - a[c] - h2[c]));
        assert_true(fabs(b[2] - a[2]) < 1e-9);
        if (q >= 25) {
            int i = q - 25;
            double off = hypot(b[0] - a[0] - disp[2 * i], b[1] - a[1] - disp[2 * i + 1]);
            if (i < SM_MARKERS) marker_worst = fmax(marker_worst, off);
            else landmark_off = fmax(landmark_off, off);
        }
    }
    printf("smoothed 3D model against the pixels' TPS: %.2e mm; markers met to %.1e mm, landmarks up to %.3f mm off\n",
           worst, marker_worst, landmark_off);
    assert_true(worst < 1e-8);
    assert_true(marker_worst < 1e-9);
    assert_true(landmark_off > 0.01); /* approximated, not met */
    free(coef);
    sh_interp_destroy(it);
    sh_warp3d_model_destroy(m);

    /* the same patch turned 30 degrees about X, 20 times farther and seen 20 times closer up */
    double tilted[3 * SM_POINTS], c30 = cos(M_PI / 6), s30 = sin(M_PI / 6);
    for (int i = 0; i < SM_POINTS; i++)
        tilted[3 * i] = ref[3 * i], tilted[3 * i + 1] = c30 * ref[3 * i + 1], tilted[3 * i + 2] = s30 * ref[3 * i + 1];
    cam.K[0] = cam.K[4] = 20 * f;
    cam.t[2] = 20 * depth;
    assert_int_equal(sh_warp3d_pixels_per_mm(&cam, tilted, SM_POINTS, &s), SH_OK);
    printf("tilted 30 degrees: %.5f px/mm, the closed form's %.5f\n", s, f / depth * sqrt(c30));
    assert_true(fabs(s / (f / depth * sqrt(c30)) - 1) < 0.01);
    /* on a line, or behind the camera: no scale */
    double line[9] = {0, 0, 0, 1, 1, 0, 2, 2, 0};
    assert_int_equal(sh_warp3d_pixels_per_mm(&cam, line, 3, &s), SH_EDEGENERATE);
    cam.t[2] = -20 * depth;
    assert_int_equal(sh_warp3d_pixels_per_mm(&cam, tilted, SM_POINTS, &s), SH_EDEGENERATE);
    /* a smoothing below 0 or not finite is refused */
    lam_mm[SM_MARKERS] = -1;
    assert_int_equal(sh_warp3d_model_create_smoothed(&params, ref, SM_POINTS, lam_mm, &m), SH_EINVAL);
    lam_mm[SM_MARKERS] = NAN;
    assert_int_equal(sh_warp3d_model_create_smoothed(&params, ref, SM_POINTS, lam_mm, &m), SH_EINVAL);
}

/* A B-spline through two landmarks 0.002 mm apart besides the 16 markers: exact interpolation
 * would need a lattice past the size limit (refused); with the landmarks' smoothing the markers
 * set the levels, and a rigid motion of every point is still removed everywhere (the trend holds
 * it exactly, whatever the interpolant makes of the close pair). */
static void test_bspline_levels_from_markers(void **state)
{
    (void)state;
    sh_calib_camera cam;
    make_camera(&cam, 1);
    double ref[3 * 18], cur[3 * 18], lambda[18] = {0}, Rm[9];
    int n = make_markers(ref);
    const double at[2][2] = {{7, -11}, {7.002, -11.001}};
    for (int k = 0; k < 2; k++, n++) {
        ref[3 * n] = at[k][0], ref[3 * n + 1] = at[k][1], ref[3 * n + 2] = surface_z(at[k][0], at[k][1]);
        lambda[n] = 1;
    }
    rotation(motion_axis, MOTION_ANGLE, Rm);
    for (int i = 0; i < n; i++) transform(Rm, motion_t, ref + 3 * i, cur + 3 * i);
    sh_warp3d_params params;
    sh_warp3d_params_default(&params);
    sh_warp3d_model *m;
    assert_int_equal(sh_warp3d_model_create(&params, ref, n, &m), SH_EDEGENERATE);
    if (sh_warp3d_model_create_smoothed(&params, ref, n, lambda, &m) != SH_OK) fail_msg("%s", sh_error_message());
    sh_warp3d_view *view;
    assert_int_equal(sh_warp3d_view_create(m, &cam, &cam, W, H, NULL, &view), SH_OK);
    assert_int_equal(sh_warp3d_model_update(m, cur), SH_OK);
    assert_int_equal(sh_warp3d_view_update(view), SH_OK);
    int samples;
    double worst = rigid_error(view, &cam, Rm, 5, &samples);
    printf("bspline, two landmarks 0.002 mm apart, the markers' levels: rigid motion's largest error %.4f px over %d "
           "samples\n", worst, samples);
    assert_true(samples > 1000 && worst < 0.05);
    sh_warp3d_view_destroy(view);
    sh_warp3d_model_destroy(m);
}

static void test_bad_input(void **state)
{
    (void)state;
    double line[12] = {0, 0, 0, 1, 1, 1, 2, 2, 2, 3, 3, 3}, ref[48];
    sh_warp3d_model *model = NULL;
    assert_int_equal(sh_warp3d_model_create(NULL, line, 4, &model), SH_EDEGENERATE);
    assert_int_equal(sh_warp3d_model_create(NULL, line, 3, &model), SH_EINVAL);
    int n = make_markers(ref);
    ref[5] = NAN;
    assert_int_equal(sh_warp3d_model_create(NULL, ref, n, &model), SH_EINVAL);
    n = make_markers(ref);
    assert_int_equal(sh_warp3d_model_create(NULL, ref, n, &model), SH_OK);
    double cur[48];
    memcpy(cur, ref, sizeof cur);
    cur[7] = INFINITY;
    assert_int_equal(sh_warp3d_model_update(model, cur), SH_EINVAL);
    sh_calib_camera cam;
    make_camera(&cam, 0);
    sh_warp3d_view *view = NULL;
    sh_warp3d_view_options o;
    sh_warp3d_view_options_default(&o);
    o.warp.grid_spacing = 12;
    assert_int_equal(sh_warp3d_view_create(model, &cam, &cam, W, H, &o, &view), SH_EINVAL);
    /* a camera looking away */
    sh_calib_camera away = cam;
    for (int i = 0; i < 9; i++) away.R[i] = -away.R[i] * (i < 6 ? 1 : 1);
    away.R[0] = 1, away.R[1] = 0, away.R[2] = 0;
    for (int r = 0; r < 3; r++) away.t[r] = 0;
    away.R[3] = 0, away.R[4] = 1, away.R[5] = 0, away.R[6] = 0, away.R[7] = 0, away.R[8] = 1;
    away.t[2] = -500; /* every marker behind the camera */
    assert_int_equal(sh_warp3d_view_create(model, &away, &cam, W, H, NULL, &view), SH_EDEGENERATE);
    sh_warp3d_model_destroy(model);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_rigid_motion_removed_exactly),
        cmocka_unit_test(test_subset_update),
        cmocka_unit_test(test_stereo_disparity),
        cmocka_unit_test(test_squeeze),
        cmocka_unit_test(test_stereo_layouts),
        cmocka_unit_test(test_reference_view_image),
        cmocka_unit_test(test_ply_on_surface),
        cmocka_unit_test(test_obj_textured),
        cmocka_unit_test(test_smoothed_model_in_pixels),
        cmocka_unit_test(test_bspline_levels_from_markers),
        cmocka_unit_test(test_bad_input),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
