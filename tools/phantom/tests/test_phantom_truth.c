/* The ground-truth library: the parameter file round-trips bit for bit, locate inverts project,
 * where(ref -> ref) is the identity, marker truth equals the renderer's CSV, the calibration file
 * reads back as the model's cameras, the motion is non-affine, --periodic loops without a jump,
 * a moved endoscope (pan, bump) and a sudden first beat follow their closed forms, and the
 * readers refuse garbage.
 *
 * Over 600 lines: one test per claim listed above, all of one library, sharing the renders and the
 * model helpers (motion pairs, projected centres) defined once here. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include <cmocka.h>

#include "../phantom.h"
#include "phantom_testutil.h"
#include "stillheart/calib.h"

static const char *render_small(void)
{
    static const char *dir;
    if (!dir)
        dir = pt_render(0, "--preset invivo --frames 6 --fps 4 --cameras 3 --width 640 --height 360 "
                           "--seed 21 --occlusions --distortion -0.2,0.3,0.001,0.0005,-0.1");
    assert_non_null(dir);
    return dir;
}

/* m written to phantom.txt and read back is m, bit for bit (models are zeroed before they are
 * filled: padding compares too). */
static void assert_round_trip(const phantom_model *m)
{
    char path[] = "/tmp/phantom-params-XXXXXX";
    int fd = mkstemp(path);
    assert_true(fd >= 0);
    close(fd);
    phantom_model back;
    assert_int_equal(phantom_model_write(m, path), SH_OK);
    assert_int_equal(phantom_model_read(path, &back), SH_OK);
    remove(path);
    assert_memory_equal(m, &back, sizeof *m);
}

static void test_params_round_trip(void **state)
{
    (void)state;
    phantom_options o;
    phantom_options_default(&o);
    o.preset = "invivo";
    o.occlusions = 1;
    o.seed = 0xfedcba9876543210ull; /* beyond 2^53: must not go through a double */
    phantom_model a;
    assert_int_equal(phantom_model_build(&o, &a), SH_OK);
    assert_round_trip(&a);
    /* the texture's contrast and trilinear filter, written only when set, read back as given */
    o.texture_contrast = 0.5;
    o.texture_trilinear = 1;
    assert_int_equal(phantom_model_build(&o, &a), SH_OK);
    assert_true(a.texture_contrast == 0.5);
    assert_int_equal(a.texture_trilinear, 1);
    assert_round_trip(&a);
}

/* --only-markers: the markers laid out as without it, only the listed ids kept; everything drawn
 * after the layout (motion, instrument, texture) the same, as the same random numbers come first,
 * and the blood and the decoy where they are with every marker (not all three blobs on the four
 * kept, as when the blobs were placed on the markers kept). */
static void test_only_markers(void **state)
{
    (void)state;
    phantom_options o;
    phantom_options_default(&o);
    o.preset = "exvivo";
    o.occlusions = 1;
    o.seed = 2;
    phantom_model all, some;
    assert_int_equal(phantom_model_build(&o, &all), SH_OK);
    static const int corners[4] = {15, 0, 12, 3};
    o.only = corners;
    o.num_only = 4;
    assert_int_equal(phantom_model_build(&o, &some), SH_OK);
    assert_int_equal(all.num_markers, 16);
    assert_int_equal(some.num_markers, 4);
    for (int k = 0; k < 4; k++) {
        int found = 0;
        for (int i = 0; i < all.num_markers; i++)
            if (all.marker[i].id == some.marker[k].id) {
                assert_true(all.marker[i].u == some.marker[k].u && all.marker[i].v == some.marker[k].v);
                found = 1;
            }
        assert_true(found);
    }
    assert_true(some.heart_hz == all.heart_hz && some.contraction == all.contraction);
    assert_memory_equal(some.shaft_p0, all.shaft_p0, sizeof all.shaft_p0);
    assert_memory_equal(some.shaft_p1, all.shaft_p1, sizeof all.shaft_p1);
    assert_int_equal(some.num_blobs, all.num_blobs);
    assert_memory_equal(some.blob, all.blob, sizeof all.blob);
    assert_int_equal(some.decoy_id, all.decoy_id);
    assert_memory_equal(some.decoy_center, all.decoy_center, sizeof all.decoy_center);
    /* an id that is not a marker's, or one twice, is refused */
    static const int absent[2] = {0, 40}, twice[2] = {3, 3};
    o.only = absent, o.num_only = 2;
    assert_int_equal(phantom_model_build(&o, &some), SH_EINVAL);
    o.only = twice;
    assert_int_equal(phantom_model_build(&o, &some), SH_EINVAL);
}

static void test_locate_inverts_project(void **state)
{
    (void)state;
    phantom_truth *t;
    assert_int_equal(phantom_truth_open(render_small(), &t), SH_OK);
    const phantom_model *m = phantom_truth_model(t);
    double worst = 0;
    int solved = 0;
    for (int c = 0; c < m->num_cameras; c++)
        for (int f = 0; f < m->frames; f += 2)
            for (double u = -45; u <= 45; u += 9)
                for (double v = -35; v <= 35; v += 7) {
                    double x, y, u2, v2, x2, y2;
                    assert_int_equal(phantom_truth_project(t, c, f, u, v, &x, &y), SH_OK);
                    assert_int_equal(phantom_truth_locate(t, c, f, x, y, &u2, &v2), SH_OK);
                    worst = fmax(worst, hypot(u2 - u, v2 - v));
                    /* where(ref = frame) returns the pixel itself */
                    assert_int_equal(phantom_truth_where(t, c, f, x, y, f, &x2, &y2), SH_OK);
                    worst = fmax(worst, hypot(x2 - x, y2 - y));
                    solved++;
                }
    printf("# %d points: worst locate/where error %.3g\n", solved, worst);
    assert_true(worst < 1e-6);
    /* the patch's corner region holds no sticker: tissue */
    {
        double x, y;
        phantom_content pc;
        assert_int_equal(phantom_truth_project(t, 0, 0, -48, -38, &x, &y), SH_OK);
        assert_int_equal(phantom_truth_locate_content(t, 0, 0, x, y, &pc), SH_OK);
        assert_int_equal(pc.marker, -1);
        assert_true(fabs(pc.u + 48) < 1e-6 && fabs(pc.v + 38) < 1e-6);
    }
    /* a pixel on the drape sees no heart */
    double u, v;
    assert_int_equal(phantom_truth_locate(t, 0, 0, 2, 2, &u, &v), SH_ERANGE);
    assert_int_equal(phantom_truth_locate(t, 7, 0, 2, 2, &u, &v), SH_EINVAL);
    phantom_truth_close(t);
}

static void test_markers_match_csv(void **state)
{
    (void)state;
    const char *dir = render_small();
    phantom_truth *t;
    assert_int_equal(phantom_truth_open(dir, &t), SH_OK);
    char path[512];
    snprintf(path, sizeof path, "%s/markers.csv", dir);
    phantom_csv csv;
    assert_int_equal(phantom_csv_read(path, &csv), SH_OK);
    const phantom_model *m = phantom_truth_model(t);
    assert_int_equal(csv.count, m->frames * m->num_cameras * m->num_markers * PHANTOM_POINTS);
    double worst = 0, worst_where = 0;
    for (int i = 0; i < csv.count; i++) {
        const phantom_csv_row *r = &csv.rows[i];
        int idx = -1;
        for (int k = 0; k < m->num_markers; k++)
            if (m->marker[k].id == r->id) idx = k;
        assert_true(idx >= 0);
        int id, vis;
        double x, y, X[3];
        assert_int_equal(phantom_truth_marker(t, r->camera, r->frame, idx, r->point, &id, &x, &y, X, &vis), SH_OK);
        assert_int_equal(id, r->id);
        assert_int_equal(vis, r->visible);
        worst = fmax(worst, fmax(hypot(x - r->x, y - r->y), fabs(X[2] - r->Z)));
        if (r->frame > 0) {
            /* the corner or centre seen in frame 0 is, in frame f, where the CSV says: where()
             * follows the sticker, not the tissue under it */
            const phantom_csv_row *r0 = phantom_csv_find(&csv, 0, r->camera, r->id, r->point);
            assert_non_null(r0);
            phantom_content pc;
            assert_int_equal(phantom_truth_locate_content(t, r->camera, 0, r0->x, r0->y, &pc), SH_OK);
            assert_int_equal(pc.marker, idx);
            assert_int_equal(phantom_truth_content_visible(t, r->camera, r->frame, &pc), r->visible);
            double xt, yt;
            assert_int_equal(phantom_truth_where(t, r->camera, 0, r0->x, r0->y, r->frame, &xt, &yt), SH_OK);
            worst_where = fmax(worst_where, hypot(xt - r->x, yt - r->y));
        }
    }
    printf("# %d rows: truth vs CSV %.3g, where(0 -> f) vs CSV %.3g px (corners and centres)\n",
           csv.count, worst, worst_where);
    assert_true(worst < 2e-6);       /* the CSV prints 6 decimals */
    assert_true(worst_where < 1e-4); /* the frame-0 pixel itself was rounded to 1e-6 */
    int hidden = 0;
    for (int i = 0; i < csv.count; i++) hidden += !csv.rows[i].visible;
    assert_true(hidden > 0); /* with --occlusions something is covered */
    phantom_csv_free(&csv);
    phantom_truth_close(t);
}

static void test_calibration_reads_back(void **state)
{
    (void)state;
    const char *dir = render_small();
    phantom_truth *t;
    assert_int_equal(phantom_truth_open(dir, &t), SH_OK);
    const phantom_model *m = phantom_truth_model(t);
    char path[512];
    snprintf(path, sizeof path, "%s/calibration.yaml", dir);
    sh_calib cal;
    assert_int_equal(sh_calib_read(path, &cal), SH_OK);
    assert_int_equal(cal.num_cameras, m->num_cameras);
    assert_int_equal(cal.width, m->width);
    assert_int_equal(cal.height, m->height);
    for (int c = 0; c < m->num_cameras; c++) {
        const phantom_camera *pc = &m->cam[c];
        assert_true(cal.cam[c].K[0] == pc->fx && cal.cam[c].K[2] == pc->cx && cal.cam[c].K[4] == pc->fy &&
                    cal.cam[c].K[5] == pc->cy);
        assert_memory_equal(cal.cam[c].R, pc->R, sizeof pc->R);
        assert_memory_equal(cal.cam[c].t, pc->t, sizeof pc->t);
        assert_memory_equal(cal.cam[c].dist, pc->dist, sizeof pc->dist);
        assert_int_equal(cal.cam[c].num_dist, 5);
        /* P projects like the pinhole part of the model: check on a world point */
        double X[3] = {10, -5, 12}, xn, yn;
        const double *P = cal.cam[c].P;
        double w = P[8] * X[0] + P[9] * X[1] + P[10] * X[2] + P[11];
        xn = (P[0] * X[0] + P[1] * X[1] + P[2] * X[2] + P[3]) / w;
        yn = (P[4] * X[0] + P[5] * X[1] + P[6] * X[2] + P[7]) / w;
        phantom_camera und = *pc;
        memset(und.dist, 0, sizeof und.dist);
        double x, y;
        assert_true(phantom_project(&und, X, &x, &y));
        assert_true(hypot(x - xn, y - yn) < 1e-9);
    }
    phantom_truth_close(t);
}

/* The motion must be beyond any affine map: fit one to the marker centres (least squares, 2D)
 * between frame 0 and each frame and require a residual of pixels somewhere. */
static void test_motion_is_not_affine(void **state)
{
    (void)state;
    phantom_options o;
    phantom_options_default(&o);
    phantom_model m;
    assert_int_equal(phantom_model_build(&o, &m), SH_OK);
    double worst = 0;
    for (int f = 1; f < 40; f++) {
        double A[3][3] = {{0}}, bx[3] = {0}, by[3] = {0}, p0[PHANTOM_MAX_MARKERS][2], p1[PHANTOM_MAX_MARKERS][2];
        for (int i = 0; i < m.num_markers; i++) {
            double X[3];
            phantom_marker_point(&m, i, 4, 0, X);
            phantom_project(&m.cam[0], X, &p0[i][0], &p0[i][1]);
            phantom_marker_point(&m, i, 4, f / m.fps, X);
            phantom_project(&m.cam[0], X, &p1[i][0], &p1[i][1]);
            double r[3] = {p0[i][0], p0[i][1], 1};
            for (int a = 0; a < 3; a++) {
                for (int b = 0; b < 3; b++) A[a][b] += r[a] * r[b];
                bx[a] += r[a] * p1[i][0];
                by[a] += r[a] * p1[i][1];
            }
        }
        /* Cramer's rule on the 3x3 normal equations */
        double det = A[0][0] * (A[1][1] * A[2][2] - A[1][2] * A[2][1]) - A[0][1] * (A[1][0] * A[2][2] - A[1][2] * A[2][0]) +
                     A[0][2] * (A[1][0] * A[2][1] - A[1][1] * A[2][0]);
        double sx[3], sy[3];
        for (int k = 0; k < 3; k++) {
            double Mx[3][3], My[3][3];
            memcpy(Mx, A, sizeof A);
            memcpy(My, A, sizeof A);
            for (int a = 0; a < 3; a++) Mx[a][k] = bx[a], My[a][k] = by[a];
#define DET(M) (M[0][0] * (M[1][1] * M[2][2] - M[1][2] * M[2][1]) - M[0][1] * (M[1][0] * M[2][2] - M[1][2] * M[2][0]) + \
                M[0][2] * (M[1][0] * M[2][1] - M[1][1] * M[2][0]))
            sx[k] = DET(Mx) / det;
            sy[k] = DET(My) / det;
#undef DET
        }
        for (int i = 0; i < m.num_markers; i++) {
            double ex = sx[0] * p0[i][0] + sx[1] * p0[i][1] + sx[2] - p1[i][0];
            double ey = sy[0] * p0[i][0] + sy[1] * p0[i][1] + sy[2] - p1[i][1];
            worst = fmax(worst, hypot(ex, ey));
        }
    }
    printf("# exvivo 1080p: worst affine residual over a beat %.2f px\n", worst);
    assert_true(worst > 3.0);
}

/* --periodic: the surface at t = frames / fps is the surface at t = 0 for both presets (heart and
 * respiration in whole cycles), the rates moved by less than 10 %; a sequence too short to hold
 * whole cycles near the asked rate is refused. */
static void test_periodic_loops_without_a_jump(void **state)
{
    (void)state;
    const char *presets[] = {"exvivo", "invivo"};
    for (int p = 0; p < 2; p++) {
        phantom_options o;
        phantom_options_default(&o);
        o.preset = presets[p];
        o.frames = 129;
        o.periodic = 1;
        phantom_model m, plain;
        assert_int_equal(phantom_model_build(&o, &m), SH_OK);
        o.periodic = 0;
        assert_int_equal(phantom_model_build(&o, &plain), SH_OK);
        double dur = m.frames / m.fps;
        assert_true(fabs(m.heart_hz / plain.heart_hz - 1) <= 0.1);
        assert_true(fabs(m.heart_hz * dur - round(m.heart_hz * dur)) < 1e-9);
        if (plain.resp_hz > 0) assert_true(fabs(m.resp_hz * dur - round(m.resp_hz * dur)) < 1e-9);
        double worst = 0, moved = 0;
        for (double u = -40; u <= 40; u += 20)
            for (double v = -30; v <= 30; v += 15) {
                double a[3], b[3], c[3];
                phantom_surface(&m, u, v, 0, a);
                phantom_surface(&m, u, v, dur, b);
                phantom_surface(&m, u, v, 0.3 * dur, c);
                worst = fmax(worst, hypot(hypot(a[0] - b[0], a[1] - b[1]), a[2] - b[2]));
                moved = fmax(moved, hypot(hypot(a[0] - c[0], a[1] - c[1]), a[2] - c[2]));
            }
        assert_true(worst < 1e-9);
        assert_true(moved > 0.5); /* mm: the heart does move in between */
    }
    phantom_options o;
    phantom_options_default(&o);
    o.frames = 10; /* 0.43 s: 0.3 beats at 0.7 Hz */
    o.periodic = 1;
    phantom_model m;
    assert_int_not_equal(phantom_model_build(&o, &m), SH_OK);
}

/* Camera 0's depth of a world point: how far along its optical axis (mm). */
static double depth0(const phantom_model *m, const double X[3])
{
    const phantom_camera *c = &m->cam[0];
    return c->R[6] * X[0] + c->R[7] * X[1] + c->R[8] * X[2] + c->t[2];
}

/* Pixel of marker i's centre in camera 0 at time t. */
static void centre_px(const phantom_model *m, int i, double t, double *x, double *y)
{
    double X[3];
    phantom_marker_point(m, i, 4, t, X);
    assert_true(phantom_project(&m->cam[0], X, x, y));
}

/* A pair of models from the same options, with and without the camera motion. */
static void motion_pair(int kind, double at, const double *dist, int width, int height,
                        phantom_model *mv, phantom_model *still)
{
    phantom_options o;
    phantom_options_default(&o);
    o.cameras = 1;
    o.width = width;
    o.height = height;
    o.dist = dist;
    o.occlusions = 1;
    assert_int_equal(phantom_model_build(&o, still), SH_OK);
    o.camera_motion = kind;
    o.camera_motion_at = at;
    assert_int_equal(phantom_model_build(&o, mv), SH_OK);
    /* the motion changes nothing else about the sequence */
    phantom_model tmp = *still;
    tmp.cam_motion = mv->cam_motion;
    tmp.cam_motion_t0 = mv->cam_motion_t0;
    tmp.cam_motion_dur = mv->cam_motion_dur;
    memcpy(tmp.cam_motion_shift, mv->cam_motion_shift, sizeof tmp.cam_motion_shift);
    assert_memory_equal(&tmp, mv, sizeof tmp);
}

/* A bump: a translation parallel to camera 0's image plane along its x axis moves a point's
 * undistorted pixel by fx L / depth along x and not at all along y (pinhole projection). So:
 * the patch centre's image moves by 3 % of the width from the frame before the bump to the one
 * at it, beyond what the heart itself does; every marker centre by that times the centre's depth
 * over its own (~2 % apart on the dome), within 0.5 px of 3 % at 640 px; nothing moves before
 * the bump and the shift holds after it. With lens distortion the centre still moves by 3 %.
 * Over 80 lines: the one bump on one pair of models, checked in the order stated above (centre,
 * markers, the step, the rigid things, the truth's inverse). */
static void test_camera_bump_closed_form(void **state)
{
    (void)state;
    static phantom_model mv, still;
    const int W = 640;
    motion_pair(PHANTOM_CAM_BUMP, 0.5, NULL, W, 360, &mv, &still);
    double fps = mv.fps;
    int f0 = (int)ceil(0.5 * fps); /* the first frame at or after 0.5 s (0.5 * 23 is not whole) */
    assert_true(mv.cam_motion_t0 == f0 / fps);
    double target = 0.03 * W, worst_closed = 0, worst_plain = 0;
    /* the patch centre, where the heart has it at the bump */
    double P[3], Q[3], x0, y0, x1, y1;
    phantom_surface(&still, 0, 0, f0 / fps, P);
    phantom_surface(&mv, 0, 0, f0 / fps, Q);
    assert_true(phantom_project(&mv.cam[0], P, &x0, &y0) && phantom_project(&mv.cam[0], Q, &x1, &y1));
    printf("# bump: patch centre moved by %.9f px (3%% of %d = %.3f)\n", x1 - x0, W, target);
    assert_true(fabs((x1 - x0) - target) < 1e-6 && fabs(y1 - y0) < 1e-6);
    double zc = depth0(&mv, P);
    for (int f = 0; f < mv.frames; f += f < f0 + 3 ? 1 : 37) {
        double t = f / fps;
        for (int i = 0; i < mv.num_markers; i++) {
            double xm, ym, xs, ys, X[3];
            centre_px(&mv, i, t, &xm, &ym);
            centre_px(&still, i, t, &xs, &ys);
            if (f < f0) {
                assert_true(xm == xs && ym == ys); /* nothing before the bump */
                continue;
            }
            phantom_marker_point(&still, i, 4, t, X);
            double want = target * zc / depth0(&mv, X);
            worst_closed = fmax(worst_closed, hypot(xm - xs - want, ym - ys));
            worst_plain = fmax(worst_plain, hypot(xm - xs - target, ym - ys));
        }
    }
    /* between the two frames around the bump: (with motion) - (without) displacement */
    double worst_step = 0;
    for (int i = 0; i < mv.num_markers; i++) {
        double a[2], b[2], c[2], d[2];
        centre_px(&mv, i, (f0 - 1) / fps, &a[0], &a[1]);
        centre_px(&mv, i, f0 / fps, &b[0], &b[1]);
        centre_px(&still, i, (f0 - 1) / fps, &c[0], &c[1]);
        centre_px(&still, i, f0 / fps, &d[0], &d[1]);
        double dx = (b[0] - a[0]) - (d[0] - c[0]), dy = (b[1] - a[1]) - (d[1] - c[1]);
        worst_step = fmax(worst_step, hypot(dx - target, dy));
    }
    printf("# bump: markers off fx L / depth by %.3g px, off 3%% by %.3f px (held), step off 3%% by %.3f px\n",
           worst_closed, worst_plain, worst_step);
    assert_true(worst_closed < 1e-6);
    assert_true(worst_plain < 0.5);
    assert_true(worst_step < 0.5);
    /* the rigid things move alike: the decoy's centre by fx L / its depth */
    double D0[3], D1[3], dx0, dy0, dx1, dy1;
    phantom_decoy_point(&still, 4, f0 / fps, D0);
    phantom_decoy_point(&mv, 4, f0 / fps, D1);
    assert_true(phantom_project(&mv.cam[0], D0, &dx0, &dy0) && phantom_project(&mv.cam[0], D1, &dx1, &dy1));
    assert_true(fabs(dx1 - dx0 - target * zc / depth0(&mv, D0)) < 1e-6 && fabs(dy1 - dy0) < 1e-6);
    double T0[3], E0[3], T1[3], E1[3];
    phantom_shaft_axis(&still, f0 / fps, T0, E0);
    phantom_shaft_axis(&mv, f0 / fps, T1, E1);
    for (int k = 0; k < 3; k++) assert_true(fabs(T1[k] - T0[k] - mv.cam_motion_shift[k]) < 1e-9);

    /* the truth's inverse follows the moved scene: locate inverts project after the bump */
    {
        char path[] = "/tmp/phantom-bump-XXXXXX";
        assert_non_null(mkdtemp(path));
        char file[64];
        snprintf(file, sizeof file, "%s/%s", path, PHANTOM_PARAMS_FILE);
        assert_int_equal(phantom_model_write(&mv, file), SH_OK);
        phantom_truth *t;
        assert_int_equal(phantom_truth_open(path, &t), SH_OK);
        double worst_locate = 0;
        for (double u = -45; u <= 45; u += 15)
            for (double v = -35; v <= 35; v += 14) {
                double x, y, u2, v2;
                assert_int_equal(phantom_truth_project(t, 0, f0 + 2, u, v, &x, &y), SH_OK);
                assert_int_equal(phantom_truth_locate(t, 0, f0 + 2, x, y, &u2, &v2), SH_OK);
                worst_locate = fmax(worst_locate, hypot(u2 - u, v2 - v));
            }
        assert_true(worst_locate < 1e-6);
        phantom_truth_close(t);
        remove(file);
        rmdir(path);
    }

    /* lens distortion: the centre's distorted image still moves by 3 % of the width */
    static const double dist[5] = {-0.2, 0.3, 0.001, 0.0005, -0.1};
    motion_pair(PHANTOM_CAM_BUMP, 0.5, dist, W, 360, &mv, &still);
    phantom_surface(&still, 0, 0, f0 / fps, P);
    phantom_surface(&mv, 0, 0, f0 / fps, Q);
    assert_true(phantom_project(&mv.cam[0], P, &x0, &y0) && phantom_project(&mv.cam[0], Q, &x1, &y1));
    assert_true(fabs(hypot(x1 - x0, y1 - y0) - target) < 1e-6);
}

/* A pan: the same translation, 6 % of the width, on the ramp s = (1 - cos(pi (t - t0) / 0.25)) / 2:
 * the patch centre's image is off its still position by 6 % s(t) (times the depth at t0 over the
 * depth at t), every marker's by that with its own depth (within 0.5 px of 6 % s(t) at 320 px),
 * nothing before t0, all of it after t0 + 0.25 s, and no frame-to-frame step larger than the
 * ramp's steepest, pi / 2 of 6 % per 0.25 s. */
static void test_camera_pan_closed_form(void **state)
{
    (void)state;
    static phantom_model mv, still;
    const int W = 320;
    const double t0 = 1.1;
    motion_pair(PHANTOM_CAM_PAN, t0, NULL, W, 360, &mv, &still);
    double fps = mv.fps, full = 0.06 * W;
    double P0[3];
    phantom_surface(&still, 0, 0, t0, P0);
    double z0 = depth0(&mv, P0), worst = 0, worst_closed = 0, worst_markers = 0, prev = 0, max_step = 0;
    int moving = 0;
    for (int f = 0; f < (int)((t0 + 0.6) * fps); f++) {
        double t = f / fps, e = (t - t0) / 0.25;
        double s = e <= 0 ? 0 : e >= 1 ? 1 : 0.5 * (1 - cos(M_PI * e));
        double P[3], Q[3], xs, ys, xm, ym;
        phantom_surface(&still, 0, 0, t, P);
        phantom_surface(&mv, 0, 0, t, Q);
        assert_true(phantom_project(&mv.cam[0], P, &xs, &ys) && phantom_project(&mv.cam[0], Q, &xm, &ym));
        double off = xm - xs;
        worst = fmax(worst, hypot(off - full * s * z0 / depth0(&mv, P), ym - ys));
        if (e <= 0) assert_true(off == 0 && ym == ys);
        if (e > 0 && e < 1) moving++;
        max_step = fmax(max_step, off - prev);
        prev = off;
        for (int i = 0; i < mv.num_markers; i++) {
            double a, b, c, d, X[3];
            centre_px(&mv, i, t, &a, &b);
            centre_px(&still, i, t, &c, &d);
            phantom_marker_point(&still, i, 4, t, X);
            worst_closed = fmax(worst_closed, hypot(a - c - full * s * z0 / depth0(&mv, X), b - d));
            worst_markers = fmax(worst_markers, hypot(a - c - full * s, b - d));
        }
    }
    double steepest = full * (M_PI / 2) / (0.25 * fps);
    printf("# pan: centre off the ramp by %.3g px, markers by %.3g px (%.3f px from 6 %% alone); %d frames "
           "in the pan, largest step %.2f px (ramp's steepest %.2f)\n", worst, worst_closed, worst_markers,
           moving, max_step, steepest);
    assert_true(worst < 1e-6);
    assert_true(worst_closed < 1e-6);
    assert_true(worst_markers < 0.5);
    assert_true(fabs(prev - full * z0 / depth0(&mv, P0)) < 0.5); /* all of it, held */
    assert_true(moving >= (int)(0.25 * fps) - 1);                /* spread over 0.25 s */
    assert_true(max_step <= steepest + 0.1);
}

/* The first beat, from its definition: the heart rests at phase 0 (activation 0) until
 * first_beat_at, rises from phase 0 to pi in an eighth of a period (4x the rate), then beats at
 * the normal rate from phase pi on. Where the contraction wave has no lag (u = -size_u/2) the
 * surface is the plain model's at the time of that phase; everywhere after the first beat it is
 * the plain model's shifted by a constant. Exvivo: no respiration, so the tissue is still. */
static void test_first_beat(void **state)
{
    (void)state;
    phantom_options o;
    phantom_options_default(&o);
    o.cameras = 1;
    static phantom_model m, plain;
    assert_int_equal(phantom_model_build(&o, &plain), SH_OK);
    o.first_beat = 1;
    assert_int_equal(phantom_model_build(&o, &m), SH_OK);
    assert_true(m.first_beat == 1 && m.first_beat_at == 0.5);
    double hz = m.heart_hz, fps = m.fps, T0 = m.first_beat_at;
    double rest = -m.heart_phase / (2 * M_PI * hz), fast = 1.0 / (8 * hz);
    /* rest: every marker still until T0, whatever its lag */
    double moved_rest = 0;
    for (int f = 1; f / fps < T0; f++)
        for (int i = 0; i < m.num_markers; i++) {
            double A[3], B[3];
            phantom_marker_point(&m, i, 4, 0, A);
            phantom_marker_point(&m, i, 4, f / fps, B);
            moved_rest = fmax(moved_rest, hypot(hypot(A[0] - B[0], A[1] - B[1]), A[2] - B[2]));
        }
    assert_true(moved_rest < 1e-9);
    double worst = 0;
    for (double v = -30; v <= 30; v += 15) {
        /* the fast rise at the unlagged edge, sub-frame times included */
        for (double t = T0; t <= T0 + fast; t += fast / 7) {
            double A[3], B[3];
            phantom_surface(&m, -0.5 * m.size_u, v, t, A);
            phantom_surface(&plain, -0.5 * m.size_u, v, rest + 4 * (t - T0), B);
            worst = fmax(worst, hypot(hypot(A[0] - B[0], A[1] - B[1]), A[2] - B[2]));
        }
        /* after it, everywhere: the normal beat, phase continuous */
        for (double u = -40; u <= 40; u += 20)
            for (double t = T0 + fast + m.delay; t < 12; t += 0.37) {
                double A[3], B[3];
                phantom_surface(&m, u, v, t, A);
                phantom_surface(&plain, u, v, t + rest - T0 + 3 * fast, B);
                worst = fmax(worst, hypot(hypot(A[0] - B[0], A[1] - B[1]), A[2] - B[2]));
            }
    }
    assert_true(worst < 1e-9);
    /* The first contraction is the fastest motion: per frame, camera 0 pixels. The phase runs 4x
     * faster in it, but it is a rise, and the activation (1 - cos phi) / 2 + 0.12 sin 2 phi rises
     * at most at 0.370 per radian (phi = 0.55) while it falls at up to 0.74 (phi = 3 pi / 2): so
     * about 2x the steepest normal motion, not 4x. */
    double first = 0, later = 0;
    double end = T0 + fast + m.delay; /* the lagged side finishes its fast rise by then */
    for (int f = 1; f < m.frames; f++) {
        double t = f / fps;
        if (t <= T0) continue;
        for (int i = 0; i < m.num_markers; i++) {
            double a, b, c, d;
            centre_px(&m, i, (f - 1) / fps, &a, &b);
            centre_px(&m, i, t, &c, &d);
            double step = hypot(c - a, d - b);
            if ((f - 1) / fps < end) first = fmax(first, step);
            else later = fmax(later, step);
        }
    }
    printf("# first beat: rest still to %.2g mm; largest step %.2f px in the first contraction, %.2f px "
           "after (x%.2f)\n", moved_rest, first, later, first / later);
    assert_true(first > 1.5 * later);
}

/* phantom.txt as phantom_model_write writes it for m, into text (at most cap - 1 bytes). */
static void written_text(const phantom_model *m, char *text, size_t cap)
{
    char path[] = "/tmp/phantom-params-XXXXXX";
    int fd = mkstemp(path);
    assert_true(fd >= 0);
    close(fd);
    assert_int_equal(phantom_model_write(m, path), SH_OK);
    FILE *f = fopen(path, "r");
    assert_non_null(f);
    size_t n = fread(text, 1, cap - 1, f);
    text[n] = '\0';
    fclose(f);
    remove(path);
}

/* The new keys round-trip, appear only when used (files rendered before them read unchanged), are
 * checked, and --periodic refuses motions that happen once. */
static void test_motion_params(void **state)
{
    (void)state;
    phantom_options o;
    phantom_options_default(&o);
    o.preset = "invivo";
    o.occlusions = 1;
    o.camera_motion = PHANTOM_CAM_PAN;
    o.first_beat = 1;
    o.first_beat_at = 0.7;
    phantom_model a, b;
    assert_int_equal(phantom_model_build(&o, &a), SH_OK);
    assert_true(a.cam_motion == PHANTOM_CAM_PAN && a.cam_motion_dur == 0.25);
    assert_true(a.cam_motion_t0 == 0.4 * a.frames / a.fps); /* the default start */
    assert_round_trip(&a);
    o.camera_motion = 0;
    o.first_beat = 0;
    assert_int_equal(phantom_model_build(&o, &a), SH_OK);
    static char text[65536];
    written_text(&a, text, sizeof text);
    assert_null(strstr(text, "cam_motion"));
    assert_null(strstr(text, "first_beat"));
    /* a pan without its length, an unknown motion, a first beat without a rate */
    static const char *extra[] = {"cam_motion 1\ncam_motion_t0 1\ncam_motion_shift 1 0 0\n",
                                  "cam_motion 3\ncam_motion_t0 1\ncam_motion_dur 0\ncam_motion_shift 1 0 0\n",
                                  "cam_motion 1\ncam_motion_t0 1\ncam_motion_dur 0\ncam_motion_shift 1 0 0\n",
                                  "first_beat 1\n", "first_beat 2\nfirst_beat_at 1\n"};
    for (size_t i = 0; i < sizeof extra / sizeof extra[0]; i++) {
        char buf[sizeof text + 256];
        snprintf(buf, sizeof buf, "%s%s", text, extra[i]);
        if (phantom_model_parse(buf, strlen(buf), "p.txt", &b) != SH_EFORMAT) fail_msg("accepted: %s", extra[i]);
    }
    char buf[sizeof text + 256];
    snprintf(buf, sizeof buf, "%sfirst_beat 1\nfirst_beat_at 0.25\n", text);
    assert_int_equal(phantom_model_parse(buf, strlen(buf), "p.txt", &b), SH_OK);
    assert_true(b.first_beat == 1 && b.first_beat_at == 0.25 && b.cam_motion == 0);
    o.frames = 129;
    o.periodic = 1;
    for (int k = 0; k < 2; k++) {
        o.camera_motion = k ? 0 : PHANTOM_CAM_BUMP;
        o.first_beat = k;
        assert_int_equal(phantom_model_build(&o, &a), SH_EINVAL);
        assert_non_null(strstr(sh_error_message(), "--periodic"));
    }
}

/* --blood-spread: each blob grows linearly from nothing to its radius over the spread (half of it
 * at half the spread), at the same place and start as with the designed 0.4 s, and stays at full
 * size as long; phantom.txt carries it only when set, and refuses it out of range. */
#define assert_near(a, b, tol) assert_true(fabs((a) - (b)) < (tol))
static void test_blood_spread(void **state)
{
    (void)state;
    phantom_options o;
    phantom_options_default(&o);
    o.occlusions = 1;
    phantom_model a, b;
    assert_int_equal(phantom_model_build(&o, &a), SH_OK);
    assert_true(a.blood_spread == 0 && a.num_blobs > 0);
    o.blood_spread = 2.0;
    assert_int_equal(phantom_model_build(&o, &b), SH_OK);
    assert_true(b.blood_spread == 2.0 && b.num_blobs == a.num_blobs);
    for (int i = 0; i < a.num_blobs; i++) {
        const phantom_blob *x = &a.blob[i], *y = &b.blob[i];
        assert_true(x->u == y->u && x->v == y->v && x->radius == y->radius && x->t0 == y->t0);
        assert_near(phantom_blob_radius(&a, i, x->t0 + 0.2), 0.5 * x->radius, 1e-9);
        assert_near(phantom_blob_radius(&b, i, y->t0 + 1.0), 0.5 * y->radius, 1e-9);
        assert_near(phantom_blob_radius(&b, i, y->t0 + 0.2), 0.1 * y->radius, 1e-9);
        assert_true(phantom_blob_radius(&b, i, y->t0 + 2.1) == y->radius);
        /* at full size from t0 + spread to t1 - spread: as long with either spread */
        assert_near((y->t1 - 2.0) - (y->t0 + 2.0), (x->t1 - 0.4) - (x->t0 + 0.4), 1e-9);
        assert_near(phantom_blob_radius(&b, i, y->t1 - 0.5), 0.25 * y->radius, 1e-9);
        assert_true(phantom_blob_radius(&b, i, y->t1) == 0 && phantom_blob_radius(&b, i, y->t0) == 0);
    }
    assert_round_trip(&b);
    phantom_model c;
    static char text[65536];
    written_text(&a, text, sizeof text);
    assert_null(strstr(text, "blood_spread"));
    static const char *bad[] = {"blood_spread -1\n", "blood_spread 61\n", "blood_spread nan\n"};
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        char buf[sizeof text + 64];
        snprintf(buf, sizeof buf, "%s%s", text, bad[i]);
        if (phantom_model_parse(buf, strlen(buf), "p.txt", &c) != SH_EFORMAT) fail_msg("accepted: %s", bad[i]);
    }
    /* without the blood it would do nothing, and beyond a minute it is refused */
    o.occlusions = 0;
    assert_int_equal(phantom_model_build(&o, &c), SH_EINVAL);
    o.occlusions = 1;
    o.blood_spread = 61;
    assert_int_equal(phantom_model_build(&o, &c), SH_EINVAL);
}

static void test_readers_refuse_garbage(void **state)
{
    (void)state;
    static const char *csvs[] = {
        "",
        "frame,camera,id,point,x,y,visible,X,Y\n",
        PHANTOM_CSV_HEADER "\n0,0,1,c,1,2,1,3,4\n",
        PHANTOM_CSV_HEADER "\n0,0,1,7,1,2,1,3,4,5\n",
        PHANTOM_CSV_HEADER "\n0,0,1,c,1,2,2,3,4,5\n",
        PHANTOM_CSV_HEADER "\n0,0,-1,c,1,2,1,3,4,5\n",
        PHANTOM_CSV_HEADER "\n0,0,1,c,1e999,2,1,3,4,5\n",
    };
    for (size_t i = 0; i < sizeof csvs / sizeof csvs[0]; i++) {
        phantom_csv csv;
        assert_int_equal(phantom_csv_parse(csvs[i], strlen(csvs[i]), "t.csv", &csv), SH_EFORMAT);
    }
    phantom_csv ok;
    const char *good = PHANTOM_CSV_HEADER "\r\n3,1,5,c,1.5,2.5,0,-3,4,5e-1\r\n";
    assert_int_equal(phantom_csv_parse(good, strlen(good), "t.csv", &ok), SH_OK);
    assert_int_equal(ok.count, 1);
    assert_true(ok.rows[0].point == 4 && ok.rows[0].Z == 0.5 && ok.rows[0].visible == 0);
    assert_non_null(phantom_csv_find(&ok, 3, 1, 5, 4));
    assert_null(phantom_csv_find(&ok, 3, 1, 5, 3));
    phantom_csv_free(&ok);

    static const char *yamls[] = {
        "",
        "num_cameras: 1\n",
        "%YAML:1.0\nnum_cameras: 1\nimage_width: 4\nimage_height: 4\n",
        "%YAML:1.0\nnum_cameras: 1\nimage_width: 4\nimage_height: 4\nK_0: !!opencv-matrix\n   rows: 3\n"
        "   cols: 3\n   dt: d\n   data: [ 1, 0, 0, 0, 1, 0, 0, 0 ]\n",
        "%YAML:1.0\nnum_cameras: 1\nK_0: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n   data: [ 1, 0,\n",
        "%YAML:1.0\nnum_cameras: 9\n",
    };
    for (size_t i = 0; i < sizeof yamls / sizeof yamls[0]; i++) {
        sh_calib cal;
        assert_int_equal(sh_calib_parse(yamls[i], strlen(yamls[i]), "t.yaml", &cal), SH_EFORMAT);
    }
    static const char *params[] = {"", "stillheart-phantom 1\nfps 0\n", "stillheart-phantom 2\n",
                                   "stillheart-phantom 1\nbogus 1\n"};
    for (size_t i = 0; i < sizeof params / sizeof params[0]; i++) {
        phantom_model m;
        assert_int_equal(phantom_model_parse(params[i], strlen(params[i]), "p.txt", &m), SH_EFORMAT);
    }
}

static int teardown(void **state)
{
    (void)state;
    pt_cleanup();
    return 0;
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_params_round_trip),
        cmocka_unit_test(test_only_markers),
        cmocka_unit_test(test_locate_inverts_project),
        cmocka_unit_test(test_markers_match_csv),
        cmocka_unit_test(test_calibration_reads_back),
        cmocka_unit_test(test_motion_is_not_affine),
        cmocka_unit_test(test_periodic_loops_without_a_jump),
        cmocka_unit_test(test_camera_bump_closed_form),
        cmocka_unit_test(test_camera_pan_closed_form),
        cmocka_unit_test(test_first_beat),
        cmocka_unit_test(test_motion_params),
        cmocka_unit_test(test_blood_spread),
        cmocka_unit_test(test_readers_refuse_garbage),
    };
    return cmocka_run_group_tests(tests, NULL, teardown);
}
