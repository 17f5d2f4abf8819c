/* stillheart-eval end to end: e against NumPy (tests/ref/make_eval_ref.py), the geometric error
 * against closed forms on phantoms built with tools/phantom, the exported points, the errors. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <cmocka.h>

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>

#include "eval_ref.h"
#include "shell.h"
#include "phantom.h"

#ifndef EVAL_BIN
#error "EVAL_BIN must name the stillheart-eval binary of this build"
#endif
#ifndef APP_BIN
#error "APP_BIN must name the stillheart binary of this build"
#endif

static char tmp[256];

static void path(char *out, const char *name)
{
    snprintf(out, 512, "%s/%s", tmp, name);
}

/* Runs the evaluator with args; stdout and stderr land in out and err (NUL-terminated). */
static int run(const char *args, char *out, size_t nout, char *err, size_t nerr)
{
    char cmd[8192], po[512], pe[512];
    path(po, "stdout");
    path(pe, "stderr");
    snprintf(cmd, sizeof cmd, "'%s' %s > '%s' 2> '%s'", EVAL_BIN, args, po, pe);
    int rc = system(cmd);
    const char *files[2] = {po, pe};
    char *bufs[2] = {out, err};
    size_t sizes[2] = {nout, nerr};
    for (int i = 0; i < 2; i++) {
        FILE *f = fopen(files[i], "rb");
        size_t n = f ? fread(bufs[i], 1, sizes[i] - 1, f) : 0;
        bufs[i][n] = '\0';
        if (f) fclose(f);
    }
    return rc;
}

/* ---- e against NumPy ---- */

static int pixel(int x, int y, int t, int p, int seed)
{
    return (31 * x * x + 17 * y + 13 * x * y + 101 * t + 59 * p + 7 * t * x * y + 211 * seed) % 256;
}

/* Writes the frames make_eval_ref.py describes: space "mono", "420jpeg" or "444". */
static void write_y4m(const char *file, const char *space, int frames, int full, int seed)
{
    FILE *f = fopen(file, "wb");
    assert_non_null(f);
    fprintf(f, "YUV4MPEG2 W%d H%d F25:1 Ip A1:1 C%s%s\n", EVAL_REF_WIDTH, EVAL_REF_HEIGHT, space,
            full ? " XCOLORRANGE=FULL" : "");
    int planes = strcmp(space, "mono") ? 3 : 1, sub = !strcmp(space, "420jpeg");
    for (int t = 0; t < frames; t++) {
        fputs("FRAME\n", f);
        for (int p = 0; p < planes; p++) {
            int w = p && sub ? (EVAL_REF_WIDTH + 1) / 2 : EVAL_REF_WIDTH;
            int h = p && sub ? (EVAL_REF_HEIGHT + 1) / 2 : EVAL_REF_HEIGHT;
            for (int y = 0; y < h; y++)
                for (int x = 0; x < w; x++) fputc(pixel(x, y, t, p, seed), f);
        }
    }
    assert_int_equal(fclose(f), 0);
}

static void write_ref_points(const char *file, int frames)
{
    FILE *f = fopen(file, "w");
    assert_non_null(f);
    fputs("frame,id,x,y\n", f);
    for (int t = 0; t < frames; t++)
        for (int i = 0; i < 5; i++)
            fprintf(f, "%d,%d,%.17g,%.17g\n", t, i, eval_ref_markers[i][0], eval_ref_markers[i][1]);
    assert_int_equal(fclose(f), 0);
}

static void check_e(const char *space, int frames, int ref, int full, int seed, double e, int pixels)
{
    char video[512], pts[512], args[4096], out[8192], err[8192];
    path(video, "small.y4m");
    path(pts, "small.csv");
    write_y4m(video, space, frames, full, seed);
    write_ref_points(pts, frames);
    snprintf(args, sizeof args, "--json --reference %d --points '%s' '%s'", ref, pts, video);
    assert_int_equal(run(args, out, sizeof out, err, sizeof err), 0);
    assert_float_equal(test_json_num(out, "e_stabilized"), e, 1e-9);
    assert_int_equal((int)test_json_num(out, "pixels"), pixels);
    assert_int_equal((int)test_json_num(out, "frames"), frames);
}

static void test_e_mono(void **state)
{
    (void)state;
    check_e("mono", 4, 1, 0, 0, EVAL_REF_MONO_E, EVAL_REF_MONO_PIXELS);
}

static void test_e_i420(void **state)
{
    (void)state;
    check_e("420jpeg", 3, 0, 0, 1, EVAL_REF_I420_E, EVAL_REF_I420_PIXELS);
}

static void test_e_444_full_range(void **state)
{
    (void)state;
    check_e("444", 3, 2, 1, 2, EVAL_REF_YUV444_FULL_E, EVAL_REF_YUV444_FULL_PIXELS);
}

/* With the original video, both e; the table names both; the heatmap is written. */
static void test_e_original_and_heatmap(void **state)
{
    (void)state;
    char stab[512], orig[512], pts[512], png[512], args[4096], out[8192], err[8192];
    path(stab, "stab.y4m");
    path(orig, "orig.y4m");
    path(pts, "pts.csv");
    path(png, "heat.png");
    write_y4m(stab, "420jpeg", 3, 0, 1);
    write_y4m(orig, "420jpeg", 3, 0, 3);
    write_ref_points(pts, 3);
    snprintf(args, sizeof args, "--json --heatmap '%s' --points '%s' '%s' '%s'", png, pts, stab, orig);
    assert_int_equal(run(args, out, sizeof out, err, sizeof err), 0);
    assert_float_equal(test_json_num(out, "e_stabilized"), EVAL_REF_I420_E, 1e-9);
    assert_float_equal(test_json_num(out, "e_original"), EVAL_REF_I420_ORIGINAL_E, 1e-9);
    FILE *f = fopen(png, "rb");
    assert_non_null(f);
    unsigned char sig[8];
    assert_int_equal(fread(sig, 1, 8, f), 8);
    fclose(f);
    assert_memory_equal(sig, "\x89PNG\r\n\x1a\n", 8);
    snprintf(args, sizeof args, "--points '%s' '%s' '%s'", pts, stab, orig);
    assert_int_equal(run(args, out, sizeof out, err, sizeof err), 0);
    assert_non_null(strstr(out, "stabilized"));
    assert_non_null(strstr(out, "original"));
}

/* ---- geometric error on phantoms ---- */

#define PW 320
#define PH 180

/* A phantom folder (phantom.txt only: the truth needs nothing else) for the exvivo preset at
 * 320x180, one camera; still = 1 stops the heart (no beat, no respiration in exvivo). */
static phantom_truth *make_phantom(const char *name, int frames, int still, char *dir)
{
    phantom_options o;
    phantom_options_default(&o);
    o.preset = "exvivo";
    o.frames = frames;
    o.cameras = 1;
    o.width = PW;
    o.height = PH;
    phantom_model m;
    assert_int_equal(phantom_model_build(&o, &m), SH_OK);
    if (still) m.heart_hz = 0; /* the activation is then constant in time */
    snprintf(dir, 512, "%s/%s", tmp, name);
    char cmd[600], file[600];
    snprintf(cmd, sizeof cmd, "mkdir -p '%s'", dir);
    assert_int_equal(system(cmd), 0);
    snprintf(file, sizeof file, "%s/" PHANTOM_PARAMS_FILE, dir);
    assert_int_equal(phantom_model_write(&m, file), SH_OK);
    phantom_truth *truth;
    assert_int_equal(phantom_truth_open(dir, &truth), SH_OK);
    return truth;
}

/* Points file: the true tag centres of truth frame `from` for every frame 0..frames-1, the
 * frames after the first shifted by (dx, dy); or, with from < 0, each frame's own centres. */
static void write_truth_points(const char *file, const phantom_truth *truth, int frames, int from,
                               double dx, double dy)
{
    FILE *f = fopen(file, "w");
    assert_non_null(f);
    fputs("frame,id,x,y\n", f);
    for (int t = 0; t < frames; t++)
        for (int i = 0; i < phantom_truth_num_markers(truth); i++) {
            int id, vis;
            double x, y;
            assert_int_equal(phantom_truth_marker(truth, 0, from < 0 ? t : from, i, PHANTOM_POINTS - 1,
                                                  &id, &x, &y, NULL, &vis), SH_OK);
            if (!vis) continue;
            fprintf(f, "%d,%d,%.17g,%.17g\n", t, id, x + (t ? dx : 0), y + (t ? dy : 0));
        }
    assert_int_equal(fclose(f), 0);
}

static void write_grey_video(const char *file, int frames)
{
    FILE *f = fopen(file, "wb");
    assert_non_null(f);
    fprintf(f, "YUV4MPEG2 W%d H%d F23:1 Ip A1:1 Cmono\n", PW, PH);
    static unsigned char row[PW];
    memset(row, 128, sizeof row);
    for (int t = 0; t < frames; t++) {
        fputs("FRAME\n", f);
        for (int y = 0; y < PH; y++) fwrite(row, 1, PW, f);
    }
    assert_int_equal(fclose(f), 0);
}

static void geo(const char *dir, const char *pts, const char *video, const char *method,
                double *mean, double *p95, double *max, double *samples)
{
    char args[4096], out[8192], err[8192];
    snprintf(args, sizeof args, "--json --truth '%s' --method %s --points '%s' '%s'", dir, method,
             pts, video);
    int rc = run(args, out, sizeof out, err, sizeof err);
    if (rc != 0) fprintf(stderr, "%s", err);
    assert_int_equal(rc, 0);
    *mean = test_json_num(out, "mean");
    *p95 = test_json_num(out, "p95");
    *max = test_json_num(out, "max");
    *samples = test_json_num(out, "samples");
}

/* The reference frame against itself: the map is the identity and so is the truth. */
static void test_geometric_reference_is_zero(void **state)
{
    (void)state;
    char dir[512], pts[512], video[512];
    phantom_truth *truth = make_phantom("beating", 3, 0, dir);
    path(pts, "beating.csv");
    path(video, "one.y4m");
    write_truth_points(pts, truth, 1, -1, 0, 0);
    write_grey_video(video, 1);
    static const char *methods[] = {"bspline", "affine", "pwlinear", "tps"};
    for (int k = 0; k < 4; k++) {
        double mean, p95, max, samples;
        geo(dir, pts, video, methods[k], &mean, &p95, &max, &samples);
        assert_true(samples > 100);
        assert_true(max < 1e-6);
        assert_true(mean < 1e-6 && p95 < 1e-6);
    }
    phantom_truth_close(truth);
}

/* A still heart whose markers the points file shifts by (dx, dy) in frame 1: the truth says
 * nothing moved, so frame 1's error is |f_1(q) - q| and frame 0's is 0. Methods that reproduce
 * translations map every sample by exactly (dx, dy): error hypot(dx, dy) everywhere (dx, dy are
 * binary fractions, so the warp's 16.16 fixed point holds them exactly). Multilevel B-splines
 * only approximate a constant between the markers (lattice control points no marker reaches keep
 * the coarser level's value), so they get the warp's error budget. */
static void test_geometric_known_shift(void **state)
{
    (void)state;
    char dir[512], pts[512], video[512];
    phantom_truth *truth = make_phantom("still", 2, 1, dir);
    const double dx = 1.5, dy = -2.25, d = hypot(dx, dy);
    path(pts, "shift.csv");
    path(video, "two.y4m");
    write_truth_points(pts, truth, 2, 0, dx, dy);
    write_grey_video(video, 2);
    static const char *methods[] = {"affine", "pwlinear", "rbf-local", "tps", "gaussian", "bspline"};
    for (int k = 0; k < 6; k++) {
        double mean, p95, max, samples;
        double tol = strcmp(methods[k], "bspline") ? 1e-6 : 0.05;
        geo(dir, pts, video, methods[k], &mean, &p95, &max, &samples);
        assert_true(samples > 200);
        assert_float_equal(max, d, tol);
        assert_float_equal(p95, d, tol);
        assert_float_equal(mean, d / 2, tol / 2);
    }
    /* The unstabilized map (identity) against the same still truth: no error at all. */
    double mean, p95, max, samples;
    geo(dir, pts, video, "none", &mean, &p95, &max, &samples);
    assert_true(max < 1e-6);
    phantom_truth_close(truth);
}

/* On the beating heart with perfect correspondences the warp beats doing nothing. */
static void test_geometric_beating(void **state)
{
    (void)state;
    char dir[512], pts[512], video[512];
    phantom_truth *truth = make_phantom("beating3", 12, 0, dir);
    path(pts, "beating3.csv");
    path(video, "twelve.y4m");
    write_truth_points(pts, truth, 12, -1, 0, 0);
    write_grey_video(video, 12);
    double mean, p95, max, samples, mean0, p950, max0;
    geo(dir, pts, video, "none", &mean0, &p950, &max0, &samples);
    geo(dir, pts, video, "bspline", &mean, &p95, &max, &samples);
    assert_true(mean0 > 0.1);
    assert_true(mean < 0.5 * mean0);
    assert_true(p95 >= mean && max >= p95);
    phantom_truth_close(truth);
}

/* The method comes from the video: `stillheart warp` tags its output (XSTILLHEART=method:NAME)
 * and --truth without --method measures that method's map, the same figures as naming it; a
 * --method the tag contradicts, and an untagged video without --method, are refused (exit 2)
 * with both names, resp. the option to give. */
static void test_method_from_header(void **state)
{
    (void)state;
    char dir[512], pts[512], video[512], warped[512], cmd[4096], args[4096], out[8192], err[8192];
    phantom_truth *truth = make_phantom("tagged", 2, 1, dir);
    path(pts, "tagged.csv");
    path(video, "tagged-in.y4m");
    path(warped, "tagged-out.y4m");
    write_truth_points(pts, truth, 2, 0, 1.5, -2.25);
    phantom_truth_close(truth);
    write_grey_video(video, 2);
    snprintf(cmd, sizeof cmd, "'%s' warp --quiet --method gaussian --points '%s' '%s' '%s'", APP_BIN, pts,
             video, warped);
    assert_int_equal(system(cmd), 0);

    double mean, p95, max, samples;
    geo(dir, pts, warped, "gaussian", &mean, &p95, &max, &samples);
    snprintf(args, sizeof args, "--json --truth '%s' --points '%s' '%s'", dir, pts, warped);
    assert_int_equal(run(args, out, sizeof out, err, sizeof err), 0);
    assert_non_null(strstr(out, "\"method\": \"gaussian\""));
    assert_float_equal(test_json_num(out, "mean"), mean, 0);
    assert_float_equal(test_json_num(out, "max"), max, 0);
    assert_true(max > 2); /* the shift's hypot(1.5, 2.25): a map measured, not the identity */
    assert_non_null(strstr(err, "gaussian"));

    snprintf(args, sizeof args, "--json --truth '%s' --method tps --points '%s' '%s'", dir, pts, warped);
    int rc = run(args, out, sizeof out, err, sizeof err);
    assert_true(WIFEXITED(rc) && WEXITSTATUS(rc) == 2);
    assert_non_null(strstr(err, "--method tps"));
    assert_non_null(strstr(err, "with gaussian"));
    assert_string_equal(out, "");
    /* e alone does not need the method, but a contradiction is refused all the same */
    snprintf(args, sizeof args, "--method none --points '%s' '%s'", pts, warped);
    rc = run(args, out, sizeof out, err, sizeof err);
    assert_true(WIFEXITED(rc) && WEXITSTATUS(rc) == 2);

    snprintf(args, sizeof args, "--json --truth '%s' --points '%s' '%s'", dir, pts, video);
    rc = run(args, out, sizeof out, err, sizeof err);
    assert_true(WIFEXITED(rc) && WEXITSTATUS(rc) == 2);
    assert_non_null(strstr(err, "give --method"));
    assert_non_null(strstr(err, "tagged-in.y4m"));
    snprintf(args, sizeof args, "--json --points '%s' '%s'", pts, video); /* e needs no method */
    assert_int_equal(run(args, out, sizeof out, err, sizeof err), 0);
}

/* ---- the points export and the errors ---- */

static void test_export_points(void **state)
{
    (void)state;
    char dir[512], file[600], args[4096], out[8192], err[8192];
    phantom_truth *truth = make_phantom("export", 2, 0, dir);
    phantom_truth_close(truth);
    snprintf(file, sizeof file, "%s/markers.csv", dir);
    FILE *f = fopen(file, "w");
    assert_non_null(f);
    fputs(PHANTOM_CSV_HEADER "\n"
          "0,0,5,c,10.5,20.25,1,1,2,3\n"
          "0,0,5,0,11,21,1,1,2,3\n"
          "0,0,3,c,30,40,1,4,5,6\n"
          "0,1,3,c,99,99,1,4,5,6\n"
          "1,0,3,c,31,41,0,4,5,6\n"
          "1,0,5,c,12,22,1,1,2,3\n", f);
    assert_int_equal(fclose(f), 0);
    snprintf(args, sizeof args, "--truth '%s' --export-points -", dir);
    assert_int_equal(run(args, out, sizeof out, err, sizeof err), 0);
    assert_string_equal(out, "frame,id,x,y,X,Y,Z\n0,3,30,40,4,5,6\n0,5,10.5,20.25,1,2,3\n"
                             "1,5,12,22,1,2,3\n");
    snprintf(args, sizeof args, "--truth '%s' --camera 2 --export-points -", dir);
    assert_int_not_equal(run(args, out, sizeof out, err, sizeof err), 0);
    assert_non_null(strstr(err, "markers.csv"));
}

static void test_errors_name_the_file(void **state)
{
    (void)state;
    char video[512], pts[512], bad[512], args[4096], out[8192], err[8192];
    path(video, "err.y4m");
    path(pts, "err.csv");
    path(bad, "bad.csv");
    write_y4m(video, "mono", 2, 0, 0);
    write_ref_points(pts, 2);

    snprintf(args, sizeof args, "--points '%s' '%s/missing.y4m'", pts, tmp);
    assert_int_not_equal(run(args, out, sizeof out, err, sizeof err), 0);
    assert_non_null(strstr(err, "missing.y4m"));
    assert_ptr_equal(strchr(err, '\n'), err + strlen(err) - 1); /* one line */

    snprintf(args, sizeof args, "--points '%s/nope.csv' '%s'", tmp, video);
    assert_int_not_equal(run(args, out, sizeof out, err, sizeof err), 0);
    assert_non_null(strstr(err, "nope.csv"));

    FILE *f = fopen(bad, "w");
    assert_non_null(f);
    fputs("frame,id,x,y\n0,1,2.5,3\n0,2,abc,4\n", f);
    assert_int_equal(fclose(f), 0);
    snprintf(args, sizeof args, "--points '%s' '%s'", bad, video);
    assert_int_not_equal(run(args, out, sizeof out, err, sizeof err), 0);
    assert_non_null(strstr(err, "bad.csv:3"));

    snprintf(args, sizeof args, "--points '%s' --reference 1 '%s'", pts, video);
    assert_int_equal(run(args, out, sizeof out, err, sizeof err), 0);
    snprintf(args, sizeof args, "--points '%s' --reference 7 '%s'", pts, video);
    assert_int_not_equal(run(args, out, sizeof out, err, sizeof err), 0);
    assert_non_null(strstr(err, "err.csv"));

    snprintf(args, sizeof args, "--points '%s' --method tps --truth '%s/nodir' '%s'", pts, tmp, video);
    assert_int_not_equal(run(args, out, sizeof out, err, sizeof err), 0);
    assert_non_null(strstr(err, "nodir"));

    snprintf(args, sizeof args, "--points '%s' --method warpdrive '%s'", pts, video);
    assert_int_not_equal(run(args, out, sizeof out, err, sizeof err), 0);
    assert_non_null(strstr(err, "warpdrive"));

    assert_int_equal(run("--help", out, sizeof out, err, sizeof err), 0);
    assert_non_null(strstr(out, "--geo-stride"));
    assert_non_null(strstr(out, "default 4"));
}

static int setup(void **state)
{
    (void)state;
    snprintf(tmp, sizeof tmp, "/tmp/test-eval-XXXXXX");
    return mkdtemp(tmp) ? 0 : -1;
}

static int teardown(void **state)
{
    (void)state;
    char cmd[400];
    snprintf(cmd, sizeof cmd, "rm -rf '%s'", tmp);
    return system(cmd) == 0 ? 0 : -1;
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_e_mono),
        cmocka_unit_test(test_e_i420),
        cmocka_unit_test(test_e_444_full_range),
        cmocka_unit_test(test_e_original_and_heatmap),
        cmocka_unit_test(test_geometric_reference_is_zero),
        cmocka_unit_test(test_geometric_known_shift),
        cmocka_unit_test(test_geometric_beating),
        cmocka_unit_test(test_method_from_header),
        cmocka_unit_test(test_export_points),
        cmocka_unit_test(test_errors_name_the_file),
    };
    return cmocka_run_group_tests(tests, setup, teardown);
}
