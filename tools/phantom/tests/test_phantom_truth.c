/* The ground-truth library: the parameter file round-trips bit for bit, locate inverts project,
 * where(ref -> ref) is the identity, marker truth equals the renderer's CSV, the calibration file
 * reads back as the model's cameras, the motion is non-affine, --periodic loops without a jump,
 * and the readers refuse garbage. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

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

static void test_params_round_trip(void **state)
{
    (void)state;
    phantom_options o;
    phantom_options_default(&o);
    o.preset = "invivo";
    o.occlusions = 1;
    o.seed = 0xfedcba9876543210ull; /* beyond 2^53: must not go through a double */
    phantom_model a, b;
    assert_int_equal(phantom_model_build(&o, &a), SH_OK);
    char path[] = "/tmp/phantom-params-XXXXXX";
    int fd = mkstemp(path);
    assert_true(fd >= 0);
    assert_int_equal(phantom_model_write(&a, path), SH_OK);
    assert_int_equal(phantom_model_read(path, &b), SH_OK);
    remove(path);
    assert_memory_equal(&a, &b, sizeof a); /* both were zeroed first: padding compares too */
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
        cmocka_unit_test(test_locate_inverts_project),
        cmocka_unit_test(test_markers_match_csv),
        cmocka_unit_test(test_calibration_reads_back),
        cmocka_unit_test(test_motion_is_not_affine),
        cmocka_unit_test(test_periodic_loops_without_a_jump),
        cmocka_unit_test(test_readers_refuse_garbage),
    };
    return cmocka_run_group_tests(tests, NULL, teardown);
}
