/* The daemon's processing pieces (src/daemon/run_model.c, run_track.c): the residual against its
 * closed form, the dropout / staleness rule of the selection, and the helper-thread models (a new
 * reference is swapped in only once built; the old one stays in use meanwhile). */
#include <math.h>
#include <stdlib.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <string.h>
#include <time.h>

#include <cmocka.h>

#include "../../src/daemon/run_model.h"
#include "../../src/daemon/run_track.h"

#define N 9

/* a 3x3 grid of markers, 100 px apart, slightly irregular */
static void grid(double *xy)
{
    for (int i = 0; i < N; i++) {
        xy[2 * i] = 200 + 100 * (i % 3) + 7 * (i == 4);
        xy[2 * i + 1] = 150 + 100 * (i / 3) - 5 * (i == 2);
    }
}

/* TPS interpolates: the map at a marker is its tracked position, so the residual is the largest
 * distance between tracked and detected positions. */
static void test_residual_tps(void **state)
{
    (void)state;
    sh_interp_params p;
    sh_interp_params_parse("tps", &p);
    double ref[2 * N], cur[2 * N], det[2 * N], r;
    grid(ref);
    for (int i = 0; i < 2 * N; i++) cur[i] = det[i] = ref[i] + (i & 1 ? -4.0 : 6.0) + 0.01 * i * i;
    assert_int_equal(run_residual(&p, ref, cur, det, N, &r), SH_OK);
    assert_true(r < 1e-6);
    det[2 * 5] += 3;
    det[2 * 5 + 1] += 4; /* the detector saw marker 5 elsewhere: 5 px */
    det[2 * 7] = det[2 * 7 + 1] = NAN; /* marker 7 predicted: not compared */
    assert_int_equal(run_residual(&p, ref, cur, det, N, &r), SH_OK);
    assert_true(fabs(r - 5) < 1e-6);
    for (int i = 0; i < 2 * N; i++) det[i] = NAN;
    assert_int_equal(run_residual(&p, ref, cur, det, N, &r), SH_OK);
    assert_true(r == -1);
}

/* Least-squares affine: one marker moved by e off a translation leaves residual
 * |e| max(1 - h_jj, max_k |h_kj|), h the hat matrix X (X^T X)^-1 X^T of X = [1 x y]. */
static void test_residual_affine_leverage(void **state)
{
    (void)state;
    sh_interp_params p;
    sh_interp_params_parse("affine", &p);
    double ref[2 * N], cur[2 * N], r;
    grid(ref);
    for (int j = 0; j < N; j++) {
        for (int i = 0; i < N; i++) {
            cur[2 * i] = ref[2 * i] + 2.5;
            cur[2 * i + 1] = ref[2 * i + 1] - 1.5;
        }
        cur[2 * j] += 0.6;
        cur[2 * j + 1] += 0.8; /* |e| = 1 */
        assert_int_equal(run_residual(&p, ref, cur, cur, N, &r), SH_OK);
        double m[3][3] = {{0}};
        for (int i = 0; i < N; i++) {
            double row[3] = {1, ref[2 * i], ref[2 * i + 1]};
            for (int a = 0; a < 3; a++)
                for (int b = 0; b < 3; b++) m[a][b] += row[a] * row[b];
        }
        double det = m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0]) +
                     m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
        double inv[3][3];
        for (int a = 0; a < 3; a++)
            for (int b = 0; b < 3; b++) {
                int a1 = (b + 1) % 3, a2 = (b + 2) % 3, b1 = (a + 1) % 3, b2 = (a + 2) % 3;
                inv[a][b] = (m[a1][b1] * m[a2][b2] - m[a1][b2] * m[a2][b1]) / det;
            }
        double want = 0;
        double xj[3] = {1, ref[2 * j], ref[2 * j + 1]};
        for (int k = 0; k < N; k++) {
            double xk[3] = {1, ref[2 * k], ref[2 * k + 1]}, h = 0;
            for (int a = 0; a < 3; a++)
                for (int b = 0; b < 3; b++) h += xk[a] * inv[a][b] * xj[b];
            double e = fabs((k == j) - h);
            if (e > want) want = e;
        }
        assert_true(fabs(r - want) < 1e-9);
    }
}

/* dropout_ms at 20 fps: age 4 (200 ms) is still used and predicted, age 5 is stale */
static void test_select_dropout(void **state)
{
    (void)state;
    sh_config cfg;
    sh_config_default(&cfg);
    cfg.dropout_ms = 200;
    sh_point ref[5];
    run_marker m[4];
    for (int i = 0; i < 5; i++) ref[i] = (sh_point){.frame = 0, .id = 2 * i, .x = 10.0 * i, .y = 5.0 * i, .X = NAN, .Y = NAN, .Z = NAN};
    /* ids 0, 2, 4, 6 tracked (8 lost); 4 unseen 4 frames, 6 unseen 5 frames */
    int ages[4] = {0, 0, 4, 5};
    double sig[4] = {0.2, 0.3, 2.5, 9};
    for (int i = 0; i < 4; i++) m[i] = (run_marker){.id = 2 * i, .x = 1.0 + i, .y = 2.0 + i, .dx = 1.0 + i, .dy = 2.0 + i,
                                   .sigma = sig[i], .age = ages[i], .X = NAN, .Y = NAN, .Z = NAN};
    run_selection sel;
    run_select(&cfg, 20, ref, 5, m, 4, &sel);
    assert_int_equal(sel.n, 3);
    assert_int_equal(sel.predicted, 1);
    assert_int_equal(sel.stale, 1);
    assert_int_equal(sel.ids[2], 4);
    assert_int_equal(sel.worst_id, 4);
    assert_true(sel.worst_sigma == 2.5);
    assert_true(sel.xy[4] == 3.0 && sel.det[5] == 4.0);
}

static void wait_ms(int ms)
{
    struct timespec ts = {0, ms * 1000000L};
    nanosleep(&ts, NULL);
}

/* a new reference is built beside the old one, which stays in use until the swap */
static void test_models_swap(void **state)
{
    (void)state;
    sh_interp_params p;
    sh_interp_params_parse("tps", &p);
    sh_warp_options wo;
    sh_warp_options_default(&wo);
    run_models *m;
    assert_int_equal(run_models_create(&p, &wo, 640, 480, 0, &m), SH_OK);
    double xy[2 * N];
    grid(xy);
    sh_point ref[N];
    int ids[N], nref, frame, n;
    for (int i = 0; i < N; i++) {
        ref[i] = (sh_point){.frame = 0, .id = i, .x = xy[2 * i], .y = xy[2 * i + 1], .X = NAN, .Y = NAN, .Z = NAN};
        ids[i] = i;
    }
    assert_null(run_models_reference(m, &nref));
    assert_int_equal(run_models_set_reference(m, ref, N, 3, NULL, NULL, 0), SH_OK);
    int swapped = 0;
    for (int t = 0; t < 2000 && !swapped; t++) {
        swapped = run_models_poll(m, &frame, &n);
        if (!swapped) wait_ms(5);
    }
    assert_true(swapped);
    assert_int_equal(frame, 3);
    assert_int_equal(n, N);
    run_model *md = NULL;
    assert_int_equal(run_models_get(m, ids, N, &md), 1); /* the full set came with the swap */
    /* second reference: until swapped, the first stays (same pointer, same positions) */
    for (int i = 0; i < N; i++) ref[i].x += 1;
    assert_int_equal(run_models_set_reference(m, ref, N, 9, NULL, NULL, 0), SH_OK);
    assert_true(run_models_pending(m));
    const sh_point *r0 = run_models_reference(m, &nref);
    assert_true(r0 && r0[0].x == xy[0]);
    /* a subset of the running reference is built on request meanwhile */
    int got = 0;
    for (int t = 0; t < 2000 && got != 1; t++) {
        got = run_models_get(m, ids + 1, N - 1, &md);
        if (got != 1) wait_ms(5);
    }
    assert_int_equal(got, 1);
    swapped = 0;
    for (int t = 0; t < 2000 && !swapped; t++) {
        swapped = run_models_poll(m, &frame, &n);
        if (!swapped) wait_ms(5);
    }
    assert_true(swapped);
    assert_int_equal(frame, 9);
    assert_true(run_models_reference(m, &nref)[0].x == xy[0] + 1);
    assert_true(run_models_builds(m) >= 3);
    run_models_destroy(m);
}

/* Models m of one reference (N markers, ids 0..N-1: the reference is set by the caller), updated
 * with xy, xyz (3D) and det until the map's grid is want's: live, no update rebuilds a grid (a 2D
 * model is replaced whole, a 3D view's grid swapped: its count is the swaps), and the map is then
 * want's (mb), bit for bit; in test mode the first update refines in place. Destroys m. */
static void refine_until_want(run_models *m, int wait, int three_d, const double *xy, const double *xyz,
                              const double *det, const sh_warp_model *want, const float *mb, float *ma)
{
    int ids[N];
    for (int i = 0; i < N; i++) ids[i] = i;
    int swapped = 0, frame, n;
    for (int t = 0; t < 2000 && !swapped; t++) {
        swapped = run_models_poll(m, &frame, &n);
        if (!swapped) wait_ms(5);
    }
    assert_true(swapped);
    run_model *md = NULL;
    for (int t = 0; t < 2000 && run_models_get(m, ids, N, &md) != 1; t++) wait_ms(5);
    assert_non_null(md);
    double residual;
    int frames = 0;
    do {
        assert_int_equal(run_model_update(md, NULL, xy, xyz, det, NULL, &residual), SH_OK);
        if (!wait)
            assert_int_equal(sh_warp_model_refinements(run_model_warp(md)), three_d ? run_models_refined(m) : 0);
        if (sh_warp_model_grid_spacing(run_model_warp(md)) != sh_warp_model_grid_spacing(want)) wait_ms(5);
    } while (++frames < 2000 && sh_warp_model_grid_spacing(run_model_warp(md)) != sh_warp_model_grid_spacing(want));
    assert_int_equal(run_models_refined(m), wait ? 0 : sh_warp_model_refinements(want));
    if (wait) assert_int_equal(frames, 1);
    assert_int_equal(sh_warp_model_map(run_model_warp(md), ma), SH_OK);
    assert_memory_equal(ma, mb, sizeof(float) * 2 * 640 * 480);
    run_models_destroy(m);
}

/* Live, a map whose grid is too coarse is not refined in the frame's update: the helper builds
 * the finer grid's model and a later update swaps it in, until the grid is the one a refinement in
 * place reaches (the same map, bit for bit); test mode refines in place, as stillheart warp does. */
static void test_models_refine_on_helper(void **state)
{
    (void)state;
    sh_interp_params p;
    sh_interp_params_parse("tps", &p);
    sh_warp_options wo;
    sh_warp_options_default(&wo);
    wo.max_error = 0.002; /* a tolerance this map's 16 px grid cannot meet */
    double xy[2 * N], cur[2 * N], det[2 * N];
    grid(xy);
    sh_point ref[N];
    for (int i = 0; i < N; i++) {
        ref[i] = (sh_point){.frame = 0, .id = i, .x = xy[2 * i], .y = xy[2 * i + 1], .X = NAN, .Y = NAN, .Z = NAN};
        double dx = xy[2 * i] - 300, dy = xy[2 * i + 1] - 250; /* a bulge: no affine map follows it */
        cur[2 * i] = xy[2 * i] + 12 * exp(-(dx * dx + dy * dy) / 8000.0);
        cur[2 * i + 1] = xy[2 * i + 1] - 9 * exp(-(dx * dx + dy * dy) / 8000.0);
        det[2 * i] = det[2 * i + 1] = NAN;
    }
    /* the refinement in place, for comparison */
    sh_interp *it;
    sh_warp_model *inplace;
    assert_int_equal(sh_interp_create(&p, xy, N, &it), SH_OK);
    assert_int_equal(sh_warp_model_create(it, xy, N, 640, 480, &wo, &inplace), SH_OK);
    assert_int_equal(sh_warp_model_update(inplace, cur), SH_OK);
    assert_true(sh_warp_model_refinements(inplace) >= 2);
    float *ma = malloc(sizeof(float) * 2 * 640 * 480), *mb = malloc(sizeof(float) * 2 * 640 * 480);
    assert_int_equal(sh_warp_model_map(inplace, mb), SH_OK);
    for (int wait = 0; wait <= 1; wait++) {
        run_models *m;
        assert_int_equal(run_models_create(&p, &wo, 640, 480, wait, &m), SH_OK);
        assert_int_equal(run_models_set_reference(m, ref, N, 0, NULL, NULL, 0), SH_OK);
        refine_until_want(m, wait, 0, cur, NULL, det, inplace, mb, ma);
    }
    free(ma), free(mb);
    sh_warp_model_destroy(inplace);
    sh_interp_destroy(it);
}

/* The same in 3D: live, a view whose grid is too coarse is not refined in the frame's update; the
 * helper builds the finer grid (sh_warp3d_view_grid_build) and a later update swaps it in, until
 * the view's map is, bit for bit, the one a view refined in its update reaches (warp3d.h). The
 * surface: 9 points on a bowl 500 mm before a pinhole camera, a bulge of 12 mm moving them. */
static void test_models_refine_3d_on_helper(void **state)
{
    (void)state;
    sh_interp_params p;
    sh_interp_params_parse("tps", &p);
    sh_warp_options wo;
    sh_warp_options_default(&wo);
    wo.max_error = 0.002;
    sh_calib calib;
    memset(&calib, 0, sizeof calib);
    calib.num_cameras = 2, calib.width = 640, calib.height = 480;
    for (int c = 0; c < 2; c++) {
        sh_calib_camera *cam = &calib.cam[c];
        cam->K[0] = cam->K[4] = 500, cam->K[2] = 320, cam->K[5] = 240, cam->K[8] = 1;
        cam->R[0] = cam->R[4] = cam->R[8] = 1;
        cam->t[0] = -60.0 * c; /* the second camera 60 mm to the right */
        cam->num_dist = 5;
    }
    sh_calib_compute_p(&calib);
    double xyz[3 * N], cur[3 * N], xy[2 * N], det[2 * N];
    sh_point ref[N];
    for (int i = 0; i < N; i++) {
        double X = -150 + 150 * (i % 3) + 9 * (i == 4), Y = -120 + 120 * (i / 3), Z = 500 + 0.0006 * (X * X + Y * Y);
        xyz[3 * i] = X, xyz[3 * i + 1] = Y, xyz[3 * i + 2] = Z;
        xy[2 * i] = 320 + 500 * X / Z, xy[2 * i + 1] = 240 + 500 * Y / Z;
        double bump = exp(-((X - 40) * (X - 40) + Y * Y) / 12000.0);
        cur[3 * i] = X + 12 * bump, cur[3 * i + 1] = Y - 9 * bump, cur[3 * i + 2] = Z - 10 * bump;
        ref[i] = (sh_point){.frame = 0, .id = i, .x = xy[2 * i], .y = xy[2 * i + 1], .X = X, .Y = Y, .Z = Z};
        det[2 * i] = det[2 * i + 1] = NAN;
    }
    /* the refinement in the view's own update, for comparison */
    sh_warp3d_params p3;
    sh_warp3d_params_default(&p3);
    p3.surface = p3.displacement = p;
    sh_warp3d_view_options vo;
    sh_warp3d_view_options_default(&vo);
    vo.warp = wo;
    sh_warp3d_model *model;
    sh_warp3d_view *inplace;
    assert_int_equal(sh_warp3d_model_create(&p3, xyz, N, &model), SH_OK);
    assert_int_equal(sh_warp3d_view_create(model, &calib.cam[0], &calib.cam[0], 640, 480, &vo, &inplace), SH_OK);
    assert_int_equal(sh_warp3d_model_update(model, cur), SH_OK);
    assert_int_equal(sh_warp3d_view_update(inplace), SH_OK);
    const sh_warp_model *want = sh_warp3d_view_map_model(inplace);
    assert_true(sh_warp_model_refinements(want) >= 2);
    float *ma = malloc(sizeof(float) * 2 * 640 * 480), *mb = malloc(sizeof(float) * 2 * 640 * 480);
    assert_int_equal(sh_warp_model_map(want, mb), SH_OK);
    for (int wait = 0; wait <= 1; wait++) {
        run_models *m;
        assert_int_equal(run_models_create(&p, &wo, 640, 480, wait, &m), SH_OK);
        assert_int_equal(run_models_set_3d(m, &calib, 0, 0), SH_OK);
        assert_int_equal(run_models_set_reference(m, ref, N, 0, NULL, NULL, 0), SH_OK);
        refine_until_want(m, wait, 1, xy, cur, det, want, mb, ma);
    }
    free(ma), free(mb);
    sh_warp3d_view_destroy(inplace);
    sh_warp3d_model_destroy(model);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_residual_tps),
        cmocka_unit_test(test_residual_affine_leverage),
        cmocka_unit_test(test_select_dropout),
        cmocka_unit_test(test_models_swap),
        cmocka_unit_test(test_models_refine_on_helper),
        cmocka_unit_test(test_models_refine_3d_on_helper),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
