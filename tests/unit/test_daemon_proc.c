/* The daemon's processing pieces (src/daemon/run_model.c, run_track.c): the residual against its
 * closed form, the dropout / staleness rule of the selection, and the helper-thread models (a new
 * reference is swapped in only once built; the old one stays in use meanwhile; live, its landmarks
 * come after its markers). */
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
#include "synth.h"

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

/* Polls m every 0.2 ms (often enough to see a reference's markers before its landmarks) until it
 * swaps something in, 10 s at most: its RUN_MODELS_* bits, 0 when nothing came. */
static int poll_until(run_models *m, int *frame, int *n)
{
    int ev = 0;
    for (int t = 0; t < 50000 && !(ev = run_models_poll(m, frame, n)); t++)
        nanosleep(&(struct timespec){0, 200000L}, NULL);
    return ev;
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
    assert_true(poll_until(m, &frame, &n));
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
    assert_true(poll_until(m, &frame, &n));
    assert_int_equal(frame, 9);
    assert_true(run_models_reference(m, &nref)[0].x == xy[0] + 1);
    assert_true(run_models_builds(m) >= 3);
    run_models_destroy(m);
}

/* Live (wait 0) or test-mode models of TPS maps on 640x480 frames, with up to 40 landmarks a
 * reference (the module's other defaults). */
static run_models *landmark_models(int wait)
{
    sh_interp_params p;
    sh_interp_params_parse("tps", &p);
    sh_warp_options wo;
    sh_warp_options_default(&wo);
    sh_landmarks_params lp;
    sh_landmarks_params_default(&lp);
    lp.max_points = 40;
    run_models *m;
    assert_int_equal(run_models_create(&p, &wo, 640, 480, wait, &m), SH_OK);
    run_models_set_landmarks(m, &lp, SH_LANDMARK_SMOOTHING);
    return m;
}

/* A 640x480 frame of the synthetic texture, for the landmarks. */
static void texture_frame(sh_image *img)
{
    assert_int_equal(sh_image_create(img, SH_PIX_GRAY8, 640, 480), SH_OK);
    const synth_motion mo = {640, 480, 6.0};
    synth_render(&mo, 0, img);
}

/* The landmarks of one reference with luma (a 640x480 frame of the synthetic texture, or a flat
 * one) on models m, live or in test mode: what run_models_poll swaps in, in order, and the models
 * the N markers get on the way. Live, the reference comes first with its markers alone, a model
 * of theirs in use (md0, its N points), then again with its landmarks (the same frame, markers and
 * positions; its full set's model, N markers then the landmarks, ready with the swap), and md0
 * stays usable (the processing thread's fallback: ASan would see it freed); in test mode it
 * comes once, with them. Returns the first poll's bits (REFERENCE | LANDMARKS live: both were
 * ready at once, nothing to check of the split). */
static int landmarks_arrive(int wait, const sh_plane *luma, int *nlm_out)
{
    run_models *m = landmark_models(wait);
    double xy[2 * N];
    grid(xy);
    sh_point ref[N];
    int ids[N], frame = -1, n = -1, nref, npts;
    for (int i = 0; i < N; i++) {
        ref[i] = (sh_point){.frame = 5, .id = i, .x = xy[2 * i], .y = xy[2 * i + 1], .X = NAN, .Y = NAN, .Z = NAN};
        ids[i] = i;
    }
    assert_int_equal(run_models_set_reference(m, ref, N, 5, &luma, NULL, 0), SH_OK);
    int first = poll_until(m, &frame, &n), ev = first;
    assert_true(first & RUN_MODELS_REFERENCE);
    assert_int_equal(frame, 5);
    assert_int_equal(n, N);
    run_model *md0 = NULL;
    assert_int_equal(run_models_get(m, ids, N, &md0), 1); /* the full set came with the swap */
    if (!wait && first == RUN_MODELS_REFERENCE) {
        assert_null(run_models_landmarks(m));
        assert_string_equal(run_models_landmarks_note(m), "");
        run_model_ids(md0, &npts);
        assert_int_equal(npts, N);
        frame = n = -1;
        ev = poll_until(m, &frame, &n);
        assert_int_equal(frame, 5);
        assert_int_equal(n, N);
        const sh_point *r = run_models_reference(m, &nref);
        assert_int_equal(nref, N);
        for (int i = 0; i < N; i++) assert_true(r[i].id == i && r[i].x == xy[2 * i] && r[i].y == xy[2 * i + 1]);
        double cur[2 * N], residual;
        for (int i = 0; i < 2 * N; i++) cur[i] = xy[i] + 0.5;
        assert_int_equal(run_model_update(md0, NULL, cur, NULL, cur, NULL, &residual), SH_OK);
        assert_true(residual < 1e-6); /* TPS through the markers: the map at each is where it is */
    }
    *nlm_out = run_models_landmarks(m) ? sh_landmarks_count(run_models_landmarks(m)) : 0;
    run_model *md = NULL;
    if (ev & RUN_MODELS_LANDMARKS || (wait && *nlm_out)) {
        assert_false(ev & RUN_MODELS_NO_LANDMARKS);
        assert_true(*nlm_out > 0);
        assert_int_equal(run_models_get(m, ids, N, &md), 1);
        const int *mids = run_model_ids(md, &npts);
        assert_int_equal(npts, N + *nlm_out);
        assert_int_equal(run_model_markers(md), N);
        assert_int_equal(mids[N], SH_LANDMARK_ID_BASE);
    } else {
        assert_true(ev & RUN_MODELS_NO_LANDMARKS);
        assert_null(run_models_landmarks(m));
        assert_non_null(strstr(run_models_landmarks_note(m), "no landmarks found"));
    }
    assert_int_equal(run_models_poll(m, &frame, &n), 0); /* nothing more to swap */
    run_models_destroy(m);
    return first;
}

/* Live, a new reference's frames are stabilized by its markers while its landmarks are chosen
 * (docs/daemon.md); in test mode it waits for them. The split is the helper's order (the markers'
 * model, then the choice, then the model with the landmarks), but a poll may come after both: up
 * to 8 references until one is seen split. A frame without texture: the reference goes on with
 * its markers alone and says why. */
static void test_models_landmarks_after_markers(void **state)
{
    (void)state;
    sh_image img;
    texture_frame(&img);
    int nlm, split = 0, with = 0;
    for (int k = 0; k < 8 && !split; k++) {
        split = landmarks_arrive(0, &img.plane[0], &nlm) == RUN_MODELS_REFERENCE;
        assert_true(nlm > 0);
    }
    assert_true(split);
    assert_int_equal(landmarks_arrive(1, &img.plane[0], &with), RUN_MODELS_REFERENCE);
    assert_int_equal(with, nlm); /* the same choice either way */
    memset(img.plane[0].data, 128, (size_t)img.plane[0].stride * 480);
    assert_true(landmarks_arrive(0, &img.plane[0], &nlm) & RUN_MODELS_REFERENCE);
    assert_int_equal(nlm, 0);
    assert_int_equal(landmarks_arrive(1, &img.plane[0], &nlm), RUN_MODELS_REFERENCE | RUN_MODELS_NO_LANDMARKS);
    assert_int_equal(nlm, 0);
    sh_image_destroy(&img);
}

/* A new reference while the one in use waits for its landmarks (the camera moved and settled):
 * the old one's may still come before the new one is built, never after it. */
static void test_models_landmarks_replaced(void **state)
{
    (void)state;
    sh_image img;
    texture_frame(&img);
    const sh_plane *luma = &img.plane[0];
    run_models *m = landmark_models(0);
    double xy[2 * N];
    grid(xy);
    sh_point ref[N];
    for (int i = 0; i < N; i++)
        ref[i] = (sh_point){.frame = 5, .id = i, .x = xy[2 * i], .y = xy[2 * i + 1], .X = NAN, .Y = NAN, .Z = NAN};
    int frame, n, nref;
    assert_int_equal(run_models_set_reference(m, ref, N, 5, &luma, NULL, 0), SH_OK);
    assert_true(poll_until(m, &frame, &n) & RUN_MODELS_REFERENCE);
    for (int i = 0; i < N; i++) ref[i].x += 1;
    assert_int_equal(run_models_set_reference(m, ref, N, 9, &luma, NULL, 0), SH_OK);
    int seen = 0, done = 0;
    for (int k = 0; k < 10 && !done; k++) {
        int ev = poll_until(m, &frame, &n);
        assert_true(ev != 0);
        seen |= ev & RUN_MODELS_REFERENCE;
        assert_int_equal(frame, seen ? 9 : 5);
        done = seen && run_models_landmarks(m);
    }
    assert_true(done);
    const sh_point *r = run_models_reference(m, &nref);
    assert_true(nref == N && r[0].x == xy[0] + 1);
    assert_int_equal(run_models_poll(m, &frame, &n), 0);
    run_models_destroy(m);
    sh_image_destroy(&img);
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
    int frame, n;
    assert_true(poll_until(m, &frame, &n));
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
        cmocka_unit_test(test_models_landmarks_after_markers),
        cmocka_unit_test(test_models_landmarks_replaced),
        cmocka_unit_test(test_models_refine_on_helper),
        cmocka_unit_test(test_models_refine_3d_on_helper),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
