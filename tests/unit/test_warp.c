/* The 2D warp: map accuracy against exact evaluation, pixel sampling against closed forms,
 * and stabilization of a synthetic sequence whose motion is known exactly. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <cmocka.h>

#include "stillheart/metrics.h"
#include "stillheart/warp.h"
#include "synth.h"
#include "../../src/warp/warp_internal.h"

typedef struct {
    sh_interp *interp;
    sh_warp_model *model;
} built;

static built build(const char *method, const double *ref, int n, int w, int h,
                   const sh_warp_options *opts)
{
    built b = {0};
    sh_interp_params params;
    assert_int_equal(sh_interp_params_parse(method, &params), SH_OK);
    if (sh_interp_create(&params, ref, n, &b.interp) != SH_OK) fail_msg("%s: %s", method, sh_error_message());
    if (sh_warp_model_create(b.interp, ref, n, w, h, opts, &b.model) != SH_OK)
        fail_msg("%s: %s", method, sh_error_message());
    return b;
}

static void unbuild(built *b)
{
    sh_warp_model_destroy(b->model);
    sh_interp_destroy(b->interp);
}

/* Largest distance between the warp's map and the interpolant evaluated exactly, over every
 * pixel of the hull. The warp interpolates the displacement: map(q) = q + D(q). */
static double map_error(const built *b, const double *ref, const double *cur, int n, int w, int h)
{
    int ncoef = sh_interp_num_coefs(b->interp);
    double *coef = malloc(sizeof(double) * 2 * ncoef), disp[2 * 128];
    float *map = malloc(sizeof(float) * 2 * (size_t)w * h);
    for (int i = 0; i < 2 * n; i++) disp[i] = cur[i] - ref[i];
    assert_int_equal(sh_interp_fit(b->interp, disp, 2, coef), SH_OK);
    assert_int_equal(sh_warp_model_map(b->model, map), SH_OK);
    const sh_hull *hull = sh_warp_model_hull(b->model);
    double worst = 0;
    long inside = 0;
    for (int y = 0; y < h; y++) {
        for (int x = 0; x < w; x++) {
            const float *m = map + 2 * ((size_t)y * w + x);
            if (!sh_hull_contains(hull, x, y)) {
                assert_true(isnan(m[0]) && isnan(m[1]));
                continue;
            }
            double exact[2];
            assert_int_equal(sh_interp_eval(b->interp, coef, 2, x, y, exact), SH_OK);
            assert_false(isnan(m[0]));
            worst = fmax(worst, hypot(m[0] - (x + exact[0]), m[1] - (y + exact[1])));
            inside++;
        }
    }
    assert_true(inside > w * h / 4);
    free(coef);
    free(map);
    return worst;
}

static void moved_markers(const synth_motion *mo, double t, const double *ref, int n, double *cur)
{
    for (int i = 0; i < n; i++)
        synth_forward(mo, t, ref[2 * i], ref[2 * i + 1], &cur[2 * i], &cur[2 * i + 1]);
}

/* The accuracy tests' scene: 16 markers over 960x540 in a motion no affine map can follow. */
enum { TOL_W = 960, TOL_H = 540, TOL_N = 16 };
static void tolerance_markers(double *ref, double *cur)
{
    synth_motion mo = {TOL_W, TOL_H, 14};
    synth_markers(&mo, TOL_N, 3, ref);
    moved_markers(&mo, 0.3, ref, TOL_N, cur);
}

/* The bound: the grid-interpolated map is within 0.05 px of exact evaluation at every
 * pixel, for every method that uses the grid, with a motion no affine map can follow. */
static void test_grid_map_within_tolerance(void **state)
{
    (void)state;
    const int w = TOL_W, h = TOL_H, n = TOL_N;
    double ref[2 * n], cur[2 * n];
    tolerance_markers(ref, cur);
    const char *methods[] = {"bspline", "rbf-local", "tps", "gaussian", "tps-pure", "gaussian-pure"};
    for (size_t k = 0; k < sizeof methods / sizeof methods[0]; k++) {
        built b = build(methods[k], ref, n, w, h, NULL);
        assert_int_equal(sh_warp_model_update(b.model, cur), SH_OK);
        double err = map_error(&b, ref, cur, n, w, h);
        double bound = sh_warp_model_error_bound(b.model);
        printf("  %-14s grid %2d px  max error %.4f px  bound %.4f px\n", methods[k],
               sh_warp_model_grid_spacing(b.model), err, bound);
        assert_true(err <= 0.05);
        assert_true(err <= bound + 1e-6); /* the estimate really bounds the error */
        unbuild(&b);
    }
}

/* A TPS grid refined below opts.coarsest_spacing maps each update on its coarse level (every
 * other node) first and keeps it when its bound is within max_error: that map is as good as the
 * issue's bound asks, against exact evaluation at every pixel, and the estimate bounds it; with a
 * tolerance the coarse level cannot meet, the grid made is used; with coarsest_spacing 0 too. */
static void test_coarse_level_within_tolerance(void **state)
{
    (void)state;
    const int w = TOL_W, h = TOL_H, n = TOL_N;
    double ref[2 * n], cur[2 * n];
    tolerance_markers(ref, cur);
    const struct {
        double max_error;
        int coarsest, used;
    } cases[] = {{0.05, 16, 8}, {0.05, 0, 4}, {0.02, 16, 4}};
    for (size_t c = 0; c < sizeof cases / sizeof cases[0]; c++) {
        sh_warp_options opts;
        sh_warp_options_default(&opts);
        opts.grid_spacing = 4;
        opts.max_error = cases[c].max_error;
        opts.coarsest_spacing = cases[c].coarsest;
        built b = build("tps", ref, n, w, h, &opts);
        assert_int_equal(sh_warp_model_update(b.model, cur), SH_OK);
        double err = map_error(&b, ref, cur, n, w, h), bound = sh_warp_model_error_bound(b.model);
        printf("  tps, grid made 4 px, max error %g, coarsest %d: %d px used, max error %.4f px, bound %.4f px\n",
               cases[c].max_error, cases[c].coarsest, sh_warp_model_grid_spacing(b.model), err, bound);
        assert_int_equal(sh_warp_model_grid_spacing(b.model), cases[c].used);
        assert_int_equal(sh_warp_model_refinements(b.model), 0);
        assert_true(err <= bound + 1e-6);
        if (cases[c].max_error >= 0.05) assert_true(err <= 0.05);
        unbuild(&b);
    }
}

/* TPS keeps its grid rows as floats (grid.c, build_dense_rows): at the grid's nodes the map
 * is the interpolant itself, so there the warp's map and the exact interpolant may differ only by
 * the weights' rounding and the map's own float storage; with 150 points over a 1080p frame (the
 * daemon's markers and landmarks) that stays under 1e-3 px, fifty times below the tolerance.
 * Through every point, and through a subset (the grid then leaves out the terms of the points
 * not used: the exact map is the subset's own interpolant, sh_interp_fit_subset's). */
static void test_dense_rows_as_exact(void **state)
{
    (void)state;
    const int w = 1920, h = 1080, n = 150;
    synth_motion mo = {w, h, 14};
    double *ref = malloc(sizeof(double) * 4 * n), *cur = ref + 2 * n;
    unsigned char use[150];
    synth_markers(&mo, n, 9, ref);
    moved_markers(&mo, 0.35, ref, n, cur);
    for (int i = 0; i < n; i++) use[i] = i < 16 || i % 3 != 1;
    built b = build("tps", ref, n, w, h, NULL);
    for (int subset = 0; subset < 2; subset++) {
        const unsigned char *u = subset ? use : NULL;
        assert_int_equal(sh_warp_model_update_subset(b.model, cur, u), SH_OK);
        int ncoef = sh_interp_num_coefs(b.interp), step = sh_warp_model_grid_spacing(b.model);
        double *coef = malloc(sizeof(double) * 2 * ncoef), *disp = malloc(sizeof(double) * 2 * n);
        void *work = malloc(sh_interp_subset_work_size(b.interp));
        float *map = malloc(sizeof(float) * 2 * (size_t)w * h);
        for (int i = 0; i < 2 * n; i++) disp[i] = !u || u[i / 2] ? cur[i] - ref[i] : 0.0;
        if (u) assert_int_equal(sh_interp_fit_subset(b.interp, u, disp, 2, coef, work), SH_OK);
        else assert_int_equal(sh_interp_fit(b.interp, disp, 2, coef), SH_OK);
        assert_int_equal(sh_warp_model_map(b.model, map), SH_OK);
        double worst = 0;
        long nodes = 0;
        for (int y = 0; y < h; y += step)
            for (int x = 0; x < w; x += step) {
                const float *m = map + 2 * ((size_t)y * w + x);
                if (isnan(m[0])) continue;
                double exact[2] = {0, 0};
                assert_int_equal(sh_interp_eval(b.interp, coef, 2, x, y, exact), SH_OK);
                worst = fmax(worst, hypot(m[0] - (x + exact[0]), m[1] - (y + exact[1])));
                nodes++;
            }
        printf("  tps, %d points%s: %ld nodes, largest difference from the exact map %.2e px\n", n,
               u ? " (a subset)" : "", nodes, worst);
        assert_true(nodes > 1000);
        assert_true(worst < 1e-3);
        free(coef), free(disp), free(work), free(map);
    }
    unbuild(&b);
    free(ref);
}

/* TPS's dense grid rows on AVX2 (four nodes a register, grid.c) against the build's own path,
 * bit for bit: the whole map of 150-point TPS models over three frame sizes (chunks whose node
 * counts are not multiples of four: the last nodes take the scalar tail), through every point and
 * through a subset (the terms left out). */
static void test_dense_rows_avx2_same_bits(void **state)
{
    (void)state;
    if (warp_grid_dense_path(1) != 1) {
        print_message("  no AVX2 on this CPU: only the build's own path here\n");
        return;
    }
    const int sizes[3][2] = {{1920, 1080}, {1000, 700}, {1283, 721}};
    for (int c = 0; c < 3; c++) {
        const int w = sizes[c][0], h = sizes[c][1], n = 150;
        synth_motion mo = {w, h, 14 + c};
        double *ref = malloc(sizeof(double) * 4 * n), *cur = ref + 2 * n;
        synth_markers(&mo, n, 9 + c, ref);
        moved_markers(&mo, 0.35, ref, n, cur);
        built b = build("tps", ref, n, w, h, NULL);
        float *m0 = malloc(sizeof(float) * 2 * (size_t)w * h), *m1 = malloc(sizeof(float) * 2 * (size_t)w * h);
        assert_non_null(m0);
        assert_non_null(m1);
        unsigned char use[150];
        for (int i = 0; i < n; i++) use[i] = i < 16 || (i + c) % 4 != 0;
        for (int subset = 0; subset < 2; subset++) {
            assert_int_equal(warp_grid_dense_path(0), 0);
            assert_int_equal(sh_warp_model_update_subset(b.model, cur, subset ? use : NULL), SH_OK);
            assert_int_equal(sh_warp_model_map(b.model, m0), SH_OK);
            assert_int_equal(warp_grid_dense_path(1), 1);
            assert_int_equal(sh_warp_model_update_subset(b.model, cur, subset ? use : NULL), SH_OK);
            assert_int_equal(sh_warp_model_map(b.model, m1), SH_OK);
            assert_memory_equal(m0, m1, sizeof(float) * 2 * (size_t)w * h);
        }
        unbuild(&b);
        free(ref), free(m0), free(m1);
    }
}

/* A tighter tolerance forces refinement, and the refined grid honours it. */
static void test_grid_refines_for_tight_tolerance(void **state)
{
    (void)state;
    const int w = 480, h = 270, n = 12;
    synth_motion mo = {w, h, 10};
    double ref[2 * n], cur[2 * n];
    synth_markers(&mo, n, 5, ref);
    moved_markers(&mo, 0.6, ref, n, cur);
    sh_warp_options opts;
    sh_warp_options_default(&opts);
    opts.max_error = 0.002;
    built b = build("tps", ref, n, w, h, &opts);
    assert_int_equal(sh_warp_model_update(b.model, cur), SH_OK);
    assert_true(sh_warp_model_refinements(b.model) > 0);
    assert_true(sh_warp_model_grid_spacing(b.model) < 8);
    assert_true(map_error(&b, ref, cur, n, w, h) <= 0.002);
    unbuild(&b);
    /* A grid refined during an update through a subset (the two outermost points left out, the
     * hull shown smaller) still covers every point's hull: the next update through all of them
     * is within the tolerance everywhere in it. */
    unsigned char use[n];
    int left = 0, right = 0;
    for (int i = 1; i < n; i++) {
        if (ref[2 * i] < ref[2 * left]) left = i;
        if (ref[2 * i] > ref[2 * right]) right = i;
    }
    for (int i = 0; i < n; i++) use[i] = i != left && i != right;
    b = build("tps", ref, n, w, h, &opts);
    assert_int_equal(sh_warp_model_update_subset(b.model, cur, use), SH_OK);
    assert_true(sh_warp_model_refinements(b.model) > 0);
    assert_int_equal(sh_warp_model_update(b.model, cur), SH_OK);
    assert_true(map_error(&b, ref, cur, n, w, h) <= 0.002);
    /* Deferred (defer_refine, the live daemon): an update keeps its grid and says which spacing is
     * due; models created at each spacing in turn end where the refinement in place ended, with
     * the same map bit for bit (the same basis on the same grid). */
    unbuild(&b);
    b = build("tps", ref, n, w, h, &opts);
    assert_int_equal(sh_warp_model_update(b.model, cur), SH_OK);
    sh_warp_options dopts = opts;
    dopts.defer_refine = 1;
    built d = build("tps", ref, n, w, h, &dopts);
    int due, steps = 0, first_h = sh_warp_model_grid_spacing(d.model);
    assert_int_equal(sh_warp_model_update(d.model, cur), SH_OK);
    while ((due = sh_warp_model_finer_spacing(d.model))) {
        assert_int_equal(sh_warp_model_grid_spacing(d.model), first_h >> steps);
        assert_true(sh_warp_model_error_bound(d.model) > dopts.max_error);
        assert_int_equal(due, sh_warp_model_grid_spacing(d.model) / 2);
        sh_warp_model_destroy(d.model);
        dopts.grid_spacing = due;
        assert_int_equal(sh_warp_model_create(d.interp, ref, n, w, h, &dopts, &d.model), SH_OK);
        assert_int_equal(sh_warp_model_update(d.model, cur), SH_OK);
        steps++;
    }
    assert_int_equal(sh_warp_model_refinements(d.model), 0);
    assert_int_equal(steps, sh_warp_model_refinements(b.model));
    assert_int_equal(sh_warp_model_grid_spacing(d.model), sh_warp_model_grid_spacing(b.model));
    float *ma = malloc(sizeof(float) * 2 * (size_t)w * h), *mb = malloc(sizeof(float) * 2 * (size_t)w * h);
    assert_int_equal(sh_warp_model_map(d.model, ma), SH_OK);
    assert_int_equal(sh_warp_model_map(b.model, mb), SH_OK);
    assert_memory_equal(ma, mb, sizeof(float) * 2 * (size_t)w * h);
    assert_int_equal(sh_warp_model_finer_spacing(b.model), 0); /* never without defer_refine */
    free(ma), free(mb);
    unbuild(&d);
    unbuild(&b);
}

/* A model built over every point and updated through a subset gives the map of a model built on
 * that subset alone (within twice the grid's tolerance: each grid is within 0.05 px of its exact
 * map), wherever both are defined (pwlinear: test_update_subset_pwlinear). */
static void test_update_subset(void **state)
{
    (void)state;
    const int w = 480, h = 270, n = 30;
    synth_motion mo = {w, h, 10};
    double ref[2 * n], cur[2 * n], sref[2 * n], scur[2 * n];
    unsigned char use[n];
    synth_markers(&mo, n, 7, ref);
    moved_markers(&mo, 0.4, ref, n, cur);
    int s = 0;
    for (int i = 0; i < n; i++) {
        use[i] = i < 4 || i % 4 != 2; /* the first ones span the layout */
        if (use[i]) sref[2 * s] = ref[2 * i], sref[2 * s + 1] = ref[2 * i + 1], scur[2 * s] = cur[2 * i],
                    scur[2 * s + 1] = cur[2 * i + 1], s++;
        else cur[2 * i] = cur[2 * i + 1] = NAN; /* never read */
    }
    const char *methods[] = {"tps", "affine"};
    float *ma = malloc(sizeof(float) * 2 * (size_t)w * h), *mb = malloc(sizeof(float) * 2 * (size_t)w * h);
    assert_true(ma && mb);
    for (int k = 0; k < 2; k++) {
        built all = build(methods[k], ref, n, w, h, NULL), sub = build(methods[k], sref, s, w, h, NULL);
        assert_int_equal(sh_warp_model_update_subset(all.model, cur, use), SH_OK);
        assert_int_equal(sh_warp_model_update(sub.model, scur), SH_OK);
        assert_int_equal(sh_warp_model_map(all.model, ma), SH_OK);
        assert_int_equal(sh_warp_model_map(sub.model, mb), SH_OK);
        double worst = 0;
        long both = 0;
        for (size_t i = 0; i < (size_t)w * h; i++)
            if (!isnan(ma[2 * i]) && !isnan(mb[2 * i])) {
                worst = fmax(worst, hypot(ma[2 * i] - mb[2 * i], ma[2 * i + 1] - mb[2 * i + 1]));
                both++;
            }
        assert_true(both > (long)w * h / 4);
        if (!(worst <= 0.1)) fail_msg("%s: the subset's map differs by %.4f px", methods[k], worst);
        /* it shows what the subset's own model shows: the used points' hull */
        const sh_hull *ha = sh_warp_model_hull(all.model), *hb = sh_warp_model_hull(sub.model);
        assert_int_equal(ha->count, hb->count);
        for (int i = 0; i < ha->count; i++) assert_true(ha->x[i] == hb->x[i] && ha->y[i] == hb->y[i]);
        for (size_t i = 0; i < (size_t)w * h; i++) assert_true(isnan(ma[2 * i]) == isnan(mb[2 * i]));
        /* the exact map (no grid) at the markers' positions: the same function */
        for (int i = 0; i < s; i++) {
            double a[2], b[2];
            assert_int_equal(sh_warp_model_eval(all.model, sref[2 * i], sref[2 * i + 1], a), SH_OK);
            assert_int_equal(sh_warp_model_eval(sub.model, sref[2 * i], sref[2 * i + 1], b), SH_OK);
            assert_true(fabs(a[0] - b[0]) < 1e-6 && fabs(a[1] - b[1]) < 1e-6);
            if (k == 0) /* tps interpolates: through the used points themselves */
                assert_true(fabs(a[0] - scur[2 * i]) < 1e-6 && fabs(a[1] - scur[2 * i + 1]) < 1e-6);
        }
        unbuild(&all);
        unbuild(&sub);
    }
    /* piecewise linear through every point: its exact map passes through them, and is undefined
     * outside their hull */
    built pws = build("pwlinear", sref, s, w, h, NULL);
    assert_int_equal(sh_warp_model_update(pws.model, scur), SH_OK);
    for (int i = 0; i < s; i++) {
        double a[2];
        assert_int_equal(sh_warp_model_eval(pws.model, sref[2 * i], sref[2 * i + 1], a), SH_OK);
        assert_true(fabs(a[0] - scur[2 * i]) < 1e-9 && fabs(a[1] - scur[2 * i + 1]) < 1e-9);
    }
    double far[2];
    assert_int_equal(sh_warp_model_eval(pws.model, -50, -50, far), SH_ERANGE);
    unbuild(&pws);
    free(ma), free(mb);
}

/* Affine and piecewise linear maps are evaluated exactly (no grid). */
static void test_exact_methods(void **state)
{
    (void)state;
    const int w = 640, h = 360, n = 20;
    synth_motion mo = {w, h, 12};
    double ref[2 * n], cur[2 * n];
    synth_markers(&mo, n, 9, ref);
    moved_markers(&mo, 0.7, ref, n, cur);
    const char *methods[] = {"affine", "pwlinear"};
    for (int k = 0; k < 2; k++) {
        built b = build(methods[k], ref, n, w, h, NULL);
        assert_int_equal(sh_warp_model_update(b.model, cur), SH_OK);
        assert_int_equal(sh_warp_model_grid_spacing(b.model), 0);
        /* float storage of coordinates below 1024: 2^-13 px */
        assert_true(map_error(&b, ref, cur, n, w, h) <= 2e-3);
        unbuild(&b);
    }
}

static void fill_pattern(sh_image *img)
{
    for (int p = 0; p < img->num_planes; p++)
        for (int y = 0; y < img->plane[p].height; y++)
            for (int x = 0; x < img->plane[p].width * sh_pixfmt_channels(img->format); x++)
                img->plane[p].data[(size_t)y * img->plane[p].stride + x] =
                    (uint8_t)((x * 37 + y * 91 + p * 53 + (x * y) % 7) & 255);
}

/* Piecewise linear through a subset: the Delaunay triangles of the used points
 * (sh_interp_delaunay), so its map and its frames are, bit for bit, those of a model that qhull
 * built on the used points alone, given in another order; a later update through every point is
 * the whole model's again, and a subset too small for a triangle is refused, leaving the model
 * whole. */
static void test_update_subset_pwlinear(void **state)
{
    (void)state;
    const int w = 480, h = 270, n = 40;
    synth_motion mo = {w, h, 10};
    double ref[2 * n], cur[2 * n], part[2 * n], sref[2 * n], scur[2 * n];
    unsigned char use[n];
    synth_markers(&mo, n, 7, ref);
    moved_markers(&mo, 0.4, ref, n, cur);
    float *ma = malloc(sizeof(float) * 2 * (size_t)w * h), *mb = malloc(sizeof(float) * 2 * (size_t)w * h);
    sh_image in, oa, ob;
    assert_true(ma && mb);
    assert_int_equal(sh_image_create(&in, SH_PIX_I420, w, h), SH_OK);
    assert_int_equal(sh_image_create(&oa, SH_PIX_I420, w, h), SH_OK);
    assert_int_equal(sh_image_create(&ob, SH_PIX_I420, w, h), SH_OK);
    fill_pattern(&in);
    sh_warp *warp;
    assert_int_equal(sh_warp_create(2, &warp), SH_OK);
    built all = build("pwlinear", ref, n, w, h, NULL);
    for (int c = 0; c < 3; c++) {
        /* every third point left out, then every other, then every point (use NULL) */
        int s = 0;
        for (int i = 0; i < n; i++) {
            use[i] = c == 2 || (c == 0 ? i % 3 != 1 : i % 2 == 0);
            part[2 * i] = use[i] ? cur[2 * i] : NAN, part[2 * i + 1] = use[i] ? cur[2 * i + 1] : NAN;
        }
        for (int i = n - 1; i >= 0; i--) /* the subset's own model: its points in reverse order */
            if (use[i]) sref[2 * s] = ref[2 * i], sref[2 * s + 1] = ref[2 * i + 1], scur[2 * s] = cur[2 * i],
                        scur[2 * s + 1] = cur[2 * i + 1], s++;
        built sub = build("pwlinear", sref, s, w, h, NULL);
        assert_int_equal(sh_warp_update(warp, all.model, c == 2 ? cur : part, c == 2 ? NULL : use), SH_OK);
        assert_int_equal(sh_warp_model_update(sub.model, scur), SH_OK);
        assert_int_equal(sh_warp_model_map(all.model, ma), SH_OK);
        assert_int_equal(sh_warp_model_map(sub.model, mb), SH_OK);
        assert_memory_equal(ma, mb, sizeof(float) * 2 * (size_t)w * h);
        assert_int_equal(sh_warp_apply(warp, all.model, &in, &oa), SH_OK);
        assert_int_equal(sh_warp_apply(warp, sub.model, &in, &ob), SH_OK);
        for (int p = 0; p < 3; p++)
            for (int y = 0; y < in.plane[p].height; y++)
                assert_memory_equal(oa.plane[p].data + (size_t)y * oa.plane[p].stride,
                                    ob.plane[p].data + (size_t)y * ob.plane[p].stride, (size_t)in.plane[p].width);
        long inside = 0;
        for (size_t i = 0; i < (size_t)w * h; i++) inside += !isnan(ma[2 * i]);
        printf("  pwlinear through %d of %d points: %ld pixels mapped, the same bits as their own model's\n", s, n,
               inside);
        assert_true(inside > (long)w * h / 4);
        unbuild(&sub);
    }
    /* two points make no triangle: refused, and the model stays whole */
    memset(use, 0, sizeof use);
    use[0] = use[5] = 1;
    assert_int_equal(sh_warp_model_update_subset(all.model, cur, use), SH_EDEGENERATE);
    assert_int_equal(sh_warp_model_update(all.model, cur), SH_OK);
    assert_int_equal(sh_warp_model_map(all.model, mb), SH_OK);
    assert_memory_equal(ma, mb, sizeof(float) * 2 * (size_t)w * h);
    unbuild(&all);
    sh_warp_destroy(warp);
    sh_image_destroy(&in), sh_image_destroy(&oa), sh_image_destroy(&ob);
    free(ma), free(mb);
}

/* An integer translation of every marker: output(x, y) = input(x + dx, y + dy) exactly inside
 * the hull (where the source exists), black elsewhere, in every frame format. For every method
 * that reproduces affine maps (multilevel B-splines do not: their lattice values are weighted
 * means, so even constant data leave ripples between the points). */
static void test_translation_every_format(void **state)
{
    (void)state;
    const int w = 200, h = 120, dx = 6, dy = -4;
    double ref[] = {20, 15, 180, 20, 170, 105, 30, 100, 100, 60, 60, 40};
    int n = 6;
    double cur[12];
    for (int i = 0; i < n; i++) {
        cur[2 * i] = ref[2 * i] + dx;
        cur[2 * i + 1] = ref[2 * i + 1] + dy;
    }
    const sh_pixfmt formats[] = {SH_PIX_GRAY8, SH_PIX_RGB24, SH_PIX_I420, SH_PIX_YUV444};
    const char *methods[] = {"affine", "pwlinear", "tps", "rbf-local", "gaussian"};
    sh_warp *warp;
    assert_int_equal(sh_warp_create(1, &warp), SH_OK);
    for (int f = 0; f < 4; f++) {
        sh_image in, out;
        assert_int_equal(sh_image_create(&in, formats[f], w, h), SH_OK);
        assert_int_equal(sh_image_create(&out, formats[f], w, h), SH_OK);
        fill_pattern(&in);
        for (size_t k = 0; k < sizeof methods / sizeof methods[0]; k++) {
            built b = build(methods[k], ref, n, w, h, NULL);
            assert_int_equal(sh_warp_model_update(b.model, cur), SH_OK);
            assert_int_equal(sh_warp_apply(warp, b.model, &in, &out), SH_OK);
            const sh_hull *hull = sh_warp_model_hull(b.model);
            for (int p = 0; p < in.num_planes; p++) {
                int s = (formats[f] == SH_PIX_I420 && p > 0) ? 2 : 1;
                double off = s == 2 ? 0.5 : 0;
                int ch = sh_pixfmt_channels(formats[f]);
                uint8_t black = (p > 0) ? 128 : 0;
                for (int y = 0; y < in.plane[p].height; y++)
                    for (int x = 0; x < in.plane[p].width; x++) {
                        int sx = x + dx / s, sy = y + dy / s;
                        int inside = sh_hull_contains(hull, s * x + off, s * y + off);
                        for (int c = 0; c < ch; c++) {
                            uint8_t got = out.plane[p].data[(size_t)y * out.plane[p].stride + x * ch + c];
                            if (!inside) {
                                assert_int_equal(got, black);
                            } else if (sx >= 0 && sy >= 0 && sx < in.plane[p].width &&
                                       sy < in.plane[p].height) {
                                uint8_t want = in.plane[p].data[(size_t)sy * in.plane[p].stride + sx * ch + c];
                                if (got != want)
                                    fail_msg("%s %s plane %d (%d,%d,%d): %d != %d", methods[k],
                                             sh_pixfmt_name(formats[f]), p, x, y, c, got, want);
                            }
                        }
                    }
            }
            unbuild(&b);
        }
        sh_image_destroy(&in);
        sh_image_destroy(&out);
    }
    sh_warp_destroy(warp);
}

/* A translation past the fixed-point range (+-16384 px in plane units): the 4:2:0 chroma rows
 * cross it in their middle (chroma x = (32568 + X) / 2 passes 16384 at X = 200), where the row
 * fill leaves its fast cells for fill_linear's careful ones; the luma rows lie past it whole.
 * Every source position is far outside the frame: black inside the hull, as outside it. */
static void test_translation_beyond_range(void **state)
{
    (void)state;
    const int w = 480, h = 120;
    double ref[] = {20, 15, 460, 20, 450, 105, 30, 100, 240, 60, 120, 40};
    int n = 6;
    double cur[12];
    for (int i = 0; i < n; i++) {
        cur[2 * i] = ref[2 * i] + 32568;
        cur[2 * i + 1] = ref[2 * i + 1] + 3;
    }
    sh_warp *warp;
    assert_int_equal(sh_warp_create(1, &warp), SH_OK);
    sh_image in, out;
    assert_int_equal(sh_image_create(&in, SH_PIX_I420, w, h), SH_OK);
    assert_int_equal(sh_image_create(&out, SH_PIX_I420, w, h), SH_OK);
    fill_pattern(&in);
    const char *methods[] = {"tps", "bspline", "gaussian"};
    for (size_t k = 0; k < sizeof methods / sizeof methods[0]; k++) {
        built b = build(methods[k], ref, n, w, h, NULL);
        assert_int_equal(sh_warp_model_update(b.model, cur), SH_OK);
        fill_pattern(&out);
        assert_int_equal(sh_warp_apply(warp, b.model, &in, &out), SH_OK);
        for (int p = 0; p < 3; p++)
            for (int y = 0; y < out.plane[p].height; y++)
                for (int x = 0; x < out.plane[p].width; x++) {
                    uint8_t got = out.plane[p].data[(size_t)y * out.plane[p].stride + x];
                    if (got != (p ? 128 : 0))
                        fail_msg("%s plane %d (%d,%d): %d, not black", methods[k], p, x, y, got);
                }
        unbuild(&b);
    }
    sh_image_destroy(&in);
    sh_image_destroy(&out);
    sh_warp_destroy(warp);
}

/* Bilinear sampling against the closed form, at fractional positions (a rotation and scaling),
 * with black where the position leaves the frame (paper Algorithm 1). */
static void test_bilinear_closed_form(void **state)
{
    (void)state;
    const int w = 320, h = 200;
    synth_motion mo = {w, h, 0};
    sh_image in, out;
    assert_int_equal(sh_image_create(&in, SH_PIX_RGB24, w, h), SH_OK);
    assert_int_equal(sh_image_create(&out, SH_PIX_RGB24, w, h), SH_OK);
    synth_render(&mo, 0, &in);
    double ref[] = {5, 5, 314, 8, 310, 194, 9, 190};
    double a = 0.21, sc = 1.07, cx = 160, cy = 100, tx = 13.37, ty = -7.61, cur[8];
    for (int i = 0; i < 4; i++) {
        double u = ref[2 * i] - cx, v = ref[2 * i + 1] - cy;
        cur[2 * i] = cx + sc * (cos(a) * u - sin(a) * v) + tx;
        cur[2 * i + 1] = cy + sc * (sin(a) * u + cos(a) * v) + ty;
    }
    built b = build("affine", ref, 4, w, h, NULL);
    assert_int_equal(sh_warp_model_update(b.model, cur), SH_OK);
    sh_warp *warp;
    assert_int_equal(sh_warp_create(1, &warp), SH_OK);
    assert_int_equal(sh_warp_apply(warp, b.model, &in, &out), SH_OK);
    int black = 0, sampled = 0;
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            if (!sh_hull_contains(sh_warp_model_hull(b.model), x, y)) continue;
            double u = x - cx, v = y - cy;
            double mx = cx + sc * (cos(a) * u - sin(a) * v) + tx;
            double my = cy + sc * (sin(a) * u + cos(a) * v) + ty;
            const uint8_t *o = out.plane[0].data + (size_t)y * out.plane[0].stride + 3 * x;
            /* stay clear of the frame's edge by the fixed-point resolution */
            if (mx < -1e-3 || my < -1e-3 || mx > w - 1 + 1e-3 || my > h - 1 + 1e-3) {
                if (mx < -0.01 || my < -0.01 || mx > w - 0.99 || my > h - 0.99) {
                    assert_true(o[0] == 0 && o[1] == 0 && o[2] == 0);
                    black++;
                }
                continue;
            }
            int ix = (int)floor(mx), iy = (int)floor(my);
            if (ix >= w - 1) ix = w - 2;
            if (iy >= h - 1) iy = h - 2;
            if (ix < 0) ix = 0;
            if (iy < 0) iy = 0;
            double fx = mx - ix, fy = my - iy;
            for (int c = 0; c < 3; c++) {
                const uint8_t *p = in.plane[0].data + (size_t)iy * in.plane[0].stride + 3 * ix + c;
                const uint8_t *q = p + in.plane[0].stride;
                double want = (1 - fy) * ((1 - fx) * p[0] + fx * p[3]) + fy * ((1 - fx) * q[0] + fx * q[3]);
                /* two 8-bit roundings (1 level) and 1/128 px position steps (texture slope
                 * below 25 levels/px: 0.2 level) */
                if (fabs(o[c] - want) > 1.25)
                    fail_msg("(%d,%d,%d): %d vs %.3f", x, y, c, o[c], want);
            }
            sampled++;
        }
    assert_true(black > 100);
    assert_true(sampled > w * h / 2);
    sh_warp_destroy(warp);
    unbuild(&b);
    sh_image_destroy(&in);
    sh_image_destroy(&out);
}

/* Stripes on several threads give the very same bytes as one thread. */
static void test_threads_same_bytes(void **state)
{
    (void)state;
    const int w = 333, h = 211, n = 14;
    synth_motion mo = {w, h, 9};
    double ref[2 * n], cur[2 * n];
    synth_markers(&mo, n, 11, ref);
    moved_markers(&mo, 0.4, ref, n, cur);
    const sh_pixfmt formats[] = {SH_PIX_RGB24, SH_PIX_I420};
    for (int f = 0; f < 2; f++) {
        sh_image in, one, many;
        assert_int_equal(sh_image_create(&in, formats[f], w, h), SH_OK);
        assert_int_equal(sh_image_create(&one, formats[f], w, h), SH_OK);
        assert_int_equal(sh_image_create(&many, formats[f], w, h), SH_OK);
        synth_render(&mo, 0.4, &in);
        built b = build("tps", ref, n, w, h, NULL);
        assert_int_equal(sh_warp_model_update(b.model, cur), SH_OK);
        sh_warp *w1, *w3;
        assert_int_equal(sh_warp_create(1, &w1), SH_OK);
        assert_int_equal(sh_warp_create(3, &w3), SH_OK);
        for (int rep = 0; rep < 3; rep++) {
            assert_int_equal(sh_warp_apply(w1, b.model, &in, &one), SH_OK);
            assert_int_equal(sh_warp_apply(w3, b.model, &in, &many), SH_OK);
            for (int p = 0; p < in.num_planes; p++)
                for (int y = 0; y < in.plane[p].height; y++)
                    assert_memory_equal(one.plane[p].data + (size_t)y * one.plane[p].stride,
                                        many.plane[p].data + (size_t)y * many.plane[p].stride,
                                        (size_t)in.plane[p].width * sh_pixfmt_channels(formats[f]));
        }
        sh_warp_destroy(w1);
        sh_warp_destroy(w3);
        unbuild(&b);
        sh_image_destroy(&in);
        sh_image_destroy(&one);
        sh_image_destroy(&many);
    }
}

/* sh_warp_update shares the grid's nodes among the warp's threads: the map, its bound and the
 * refinements are sh_warp_model_update's bit for bit, for the dense rows (tps), the separable
 * kernel (gaussian), the CSR rows (bspline, rbf-local), through a subset, and when the tolerance
 * makes the update refine its grid (each finer grid made on the threads too). A small frame
 * (the aarch64 lane runs this under qemu) with 4 px cells, so that the threads take part (more
 * than 4096 nodes); the refining case starts at 8 px. */
static void test_update_on_threads_same_map(void **state)
{
    (void)state;
    const int w = 800, h = 450, n = 20;
    synth_motion mo = {w, h, 8};
    double ref[2 * n], cur[2 * n];
    unsigned char use[n];
    int coarse_used = 0;
    synth_markers(&mo, n, 5, ref);
    moved_markers(&mo, 0.35, ref, n, cur);
    for (int i = 0; i < n; i++) use[i] = i < 4 || i % 5 != 3;
    float *ma = malloc(sizeof(float) * 2 * (size_t)w * h), *mb = malloc(sizeof(float) * 2 * (size_t)w * h);
    assert_true(ma && mb);
    sh_warp *warp[2];
    assert_int_equal(sh_warp_create(2, &warp[0]), SH_OK);
    assert_int_equal(sh_warp_create(3, &warp[1]), SH_OK);
    /* coarse: the TPS grid's coarse level tried first (opts.coarsest_spacing 16), on the threads
     * too, kept or followed by the rest of the nodes; without, the grid made is the one used */
    const struct {
        const char *method;
        double max_error;
        int subset, coarse;
    } cases[] = {{"tps", 0.05, 0, 0},      {"tps", 0.05, 1, 0},     {"tps", 0.004, 0, 0}, {"gaussian", 0.05, 0, 0},
                 {"gaussian", 0.05, 1, 0}, {"bspline", 0.05, 0, 0}, {"rbf-local", 0.05, 0, 0},
                 {"tps", 0.05, 0, 1},      {"tps", 0.05, 1, 1},     {"tps", 0.004, 0, 1}};
    for (size_t c = 0; c < sizeof cases / sizeof cases[0]; c++) {
        for (int t = 0; t < 2; t++) {
            sh_warp_options opts;
            sh_warp_options_default(&opts);
            opts.max_error = cases[c].max_error;
            opts.grid_spacing = cases[c].max_error < 0.05 ? 8 : 4;
            opts.coarsest_spacing = cases[c].coarse ? 16 : 0;
            built one = build(cases[c].method, ref, n, w, h, &opts), many = build(cases[c].method, ref, n, w, h, &opts);
            const unsigned char *u = cases[c].subset ? use : NULL;
            for (int rep = 0; rep < 2; rep++) { /* the second update on the grid the first made */
                assert_int_equal(sh_warp_model_update_subset(one.model, cur, u), SH_OK);
                assert_int_equal(sh_warp_update(warp[t], many.model, cur, u), SH_OK);
                const sh_hull *hull = sh_warp_model_hull(many.model);
                int g = sh_warp_model_grid_spacing(many.model);
                assert_true(g > 0);
                /* the grid made, more than 4096 nodes so that the threads take part, or its
                 * coarse level */
                const int made = (cases[c].max_error < 0.05 ? 8 : 4) >> sh_warp_model_refinements(one.model);
                assert_true(g == made || (cases[c].coarse && g == 2 * made));
                coarse_used += g == 2 * made;
                assert_true(((hull->xmax - hull->xmin) / made) * ((hull->ymax - hull->ymin) / made) > 4096);
                assert_int_equal(g, sh_warp_model_grid_spacing(one.model));
                assert_int_equal(sh_warp_model_refinements(many.model), sh_warp_model_refinements(one.model));
                assert_true(sh_warp_model_error_bound(many.model) == sh_warp_model_error_bound(one.model));
                assert_int_equal(sh_warp_model_map(one.model, ma), SH_OK);
                assert_int_equal(sh_warp_model_map(many.model, mb), SH_OK);
                if (memcmp(ma, mb, sizeof(float) * 2 * (size_t)w * h) != 0)
                    fail_msg("%s (max error %g%s), %d threads: the maps differ", cases[c].method,
                             cases[c].max_error, cases[c].subset ? ", subset" : "", t ? 3 : 2);
            }
            if (cases[c].max_error < 0.05) assert_true(sh_warp_model_refinements(many.model) > 0);
            print_message("  %s, max error %g%s%s: %d px grid made, %d px used\n", cases[c].method, cases[c].max_error,
                          cases[c].subset ? ", subset" : "", cases[c].coarse ? ", coarse level" : "",
                          (cases[c].max_error < 0.05 ? 8 : 4) >> sh_warp_model_refinements(one.model),
                          sh_warp_model_grid_spacing(one.model));
            unbuild(&one);
            unbuild(&many);
        }
    }
    assert_int_equal(sh_warp_update(NULL, NULL, cur, NULL), SH_EINVAL);
    assert_true(coarse_used > 0); /* the coarse level was kept on some update */
    sh_warp_destroy(warp[0]);
    sh_warp_destroy(warp[1]);
    free(ma), free(mb);
}

/* sh_warp_apply_again writes black only where the hull's inside shrank; its output must be
 * sh_warp_apply's byte for byte into a fresh buffer, while the hull moves (a subset of markers
 * used each frame, so the inside grows and shrinks row by row), the frame moves, on 1 and 3
 * threads, with the caller's buffers taken in turn (2, and 5 where the warp remembers only 4:
 * those are written whole), and a buffer the warp has not seen before. The reference output is
 * prefilled with another value every frame, so that a pixel either path leaves unwritten shows. */
static void test_apply_again_same_bytes(void **state)
{
    (void)state;
    const int w = 333, h = 211, n = 30;
    synth_motion mo = {w, h, 9};
    double ref[2 * n], cur[2 * n];
    synth_markers(&mo, n, 5, ref);
    const sh_pixfmt formats[] = {SH_PIX_I420, SH_PIX_RGB24};
    unsigned rng = 12345;
    /* One model and one rendered sequence for the four cases of a format: each frame sets the
     * whole model (sh_warp_model_update_subset). The synthetic frames' sines, rendered anew for
     * every case, took minutes under qemu-aarch64's soft floating point. */
    enum { FRAMES = 24 };
    built b = build("tps", ref, n, w, h, NULL);
    for (int f = 0; f < 2; f++) {
        sh_image seq[FRAMES];
        for (int frame = 0; frame < FRAMES; frame++) {
            assert_int_equal(sh_image_create(&seq[frame], formats[f], w, h), SH_OK);
            synth_render(&mo, 0.05 * frame, &seq[frame]);
        }
        for (int threads = 1; threads <= 3; threads += 2) {
            for (int nbuf = 2; nbuf <= 5; nbuf += 3) {
                sh_image fresh, buf[5];
                assert_int_equal(sh_image_create(&fresh, formats[f], w, h), SH_OK);
                for (int i = 0; i < nbuf; i++) assert_int_equal(sh_image_create(&buf[i], formats[f], w, h), SH_OK);
                sh_warp *wa, *wr;
                assert_int_equal(sh_warp_create(threads, &wa), SH_OK);
                assert_int_equal(sh_warp_create(threads, &wr), SH_OK);
                long changed_rows = 0;
                for (int frame = 0; frame < FRAMES; frame++) {
                    double t = 0.05 * frame;
                    const sh_image *in = &seq[frame];
                    unsigned char use[n];
                    moved_markers(&mo, t, ref, n, cur);
                    for (int i = 0; i < n; i++) {
                        rng = rng * 1103515245u + 12345u;
                        /* every third frame all of them; otherwise about a third left out */
                        use[i] = frame % 3 == 0 || i < 3 || (rng >> 16) % 3 != 0;
                        if (!use[i]) cur[2 * i] = cur[2 * i + 1] = NAN;
                    }
                    assert_int_equal(sh_warp_model_update_subset(b.model, cur, use), SH_OK);
                    sh_image *out = &buf[frame % nbuf];
                    for (int p = 0; p < fresh.num_planes; p++)
                        memset(fresh.plane[p].data, 0x5a + frame, (size_t)fresh.plane[p].stride * fresh.plane[p].height);
                    if (frame < nbuf) /* never written: whatever a new buffer holds */
                        for (int p = 0; p < out->num_planes; p++)
                            memset(out->plane[p].data, 0xa5, (size_t)out->plane[p].stride * out->plane[p].height);
                    /* the first frame through sh_warp_apply, then again and again */
                    assert_int_equal((frame == 0 ? sh_warp_apply : sh_warp_apply_again)(wa, b.model, in, out), SH_OK);
                    assert_int_equal(sh_warp_apply(wr, b.model, in, &fresh), SH_OK);
                    for (int p = 0; p < in->num_planes; p++)
                        for (int y = 0; y < in->plane[p].height; y++) {
                            const uint8_t *a = out->plane[p].data + (size_t)y * out->plane[p].stride,
                                          *r = fresh.plane[p].data + (size_t)y * fresh.plane[p].stride;
                            size_t len = (size_t)in->plane[p].width * sh_pixfmt_channels(formats[f]);
                            assert_memory_equal(a, r, len);
                            if (frame >= nbuf && p == 0) changed_rows += memchr(r, 0, len) != NULL;
                        }
                }
                /* the outside was there to be kept: rows with black in them */
                assert_true(changed_rows > 0);
                sh_warp_destroy(wa);
                sh_warp_destroy(wr);
                sh_image_destroy(&fresh);
                for (int i = 0; i < nbuf; i++) sh_image_destroy(&buf[i]);
            }
        }
        for (int frame = 0; frame < FRAMES; frame++) sh_image_destroy(&seq[frame]);
    }
    unbuild(&b);
}

/* Paper Table II's shape on a sequence with known motion: every method lowers e, and every
 * local method beats affine, in e and in geometric error against the true motion. */
static void test_synthetic_sequence(void **state)
{
    (void)state;
    const int w = 480, h = 300, n = 25, frames = 8;
    synth_motion mo = {w, h, 10};
    double ref[2 * n], cur[2 * n];
    synth_markers(&mo, n, 21, ref);
    sh_image seq[frames], out;
    for (int t = 0; t < frames; t++) {
        assert_int_equal(sh_image_create(&seq[t], SH_PIX_RGB24, w, h), SH_OK);
        synth_render(&mo, (double)t / frames, &seq[t]);
    }
    assert_int_equal(sh_image_create(&out, SH_PIX_RGB24, w, h), SH_OK);
    sh_warp *warp;
    assert_int_equal(sh_warp_create(2, &warp), SH_OK);
    const char *methods[] = {"affine", "pwlinear", "bspline", "rbf-local", "tps", "gaussian"};
    double e_in = 0, e_out[6], geo[6];
    float *map = malloc(sizeof(float) * 2 * w * h);
    for (int k = 0; k < 6; k++) {
        built b = build(methods[k], ref, n, w, h, NULL);
        sh_metric *min = NULL, *mout = NULL;
        double geo_sum = 0;
        long geo_count = 0;
        for (int t = 0; t < frames; t++) {
            moved_markers(&mo, (double)t / frames, ref, n, cur);
            assert_int_equal(sh_warp_model_update(b.model, cur), SH_OK);
            assert_int_equal(sh_warp_apply(warp, b.model, &seq[t], &out), SH_OK);
            if (t == 0) {
                assert_int_equal(sh_metric_create(&seq[0], sh_warp_model_hull(b.model), 1, &min), SH_OK);
                assert_int_equal(sh_metric_create(&out, sh_warp_model_hull(b.model), 1, &mout), SH_OK);
            }
            assert_int_equal(sh_metric_add(min, &seq[t]), SH_OK);
            assert_int_equal(sh_metric_add(mout, &out), SH_OK);
            assert_int_equal(sh_warp_model_map(b.model, map), SH_OK);
            for (int y = 0; y < h; y += 3)
                for (int x = 0; x < w; x += 3) {
                    const float *m = map + 2 * ((size_t)y * w + x);
                    if (isnan(m[0])) continue;
                    double tx, ty;
                    synth_forward(&mo, (double)t / frames, x, y, &tx, &ty);
                    geo_sum += hypot(m[0] - tx, m[1] - ty);
                    geo_count++;
                }
        }
        e_in = sh_metric_e(min);
        e_out[k] = sh_metric_e(mout);
        geo[k] = geo_sum / geo_count;
        printf("  %-9s e %.4f -> %.4f   geometric error %.3f px\n", methods[k], e_in, e_out[k], geo[k]);
        assert_true(e_out[k] < 0.5 * e_in);
        sh_metric_destroy(min);
        sh_metric_destroy(mout);
        unbuild(&b);
    }
    for (int k = 1; k < 6; k++) {
        assert_true(e_out[k] < e_out[0]);
        assert_true(geo[k] < geo[0]);
    }
    free(map);
    sh_warp_destroy(warp);
    for (int t = 0; t < frames; t++) sh_image_destroy(&seq[t]);
    sh_image_destroy(&out);
}

static void test_bad_input(void **state)
{
    (void)state;
    double ref[] = {10, 10, 50, 50, 90, 90, 130, 130}; /* collinear */
    sh_interp_params params;
    sh_interp *interp = NULL;
    sh_warp_model *model = NULL;
    assert_int_equal(sh_interp_params_parse("tps", &params), SH_OK);
    if (sh_interp_create(&params, ref, 4, &interp) == SH_OK) {
        assert_int_not_equal(sh_warp_model_create(interp, ref, 4, 200, 200, NULL, &model), SH_OK);
        sh_interp_destroy(interp);
    }
    double good[] = {10, 10, 150, 20, 140, 150, 20, 140};
    assert_int_equal(sh_interp_create(&params, good, 4, &interp), SH_OK);
    sh_warp_options opts;
    sh_warp_options_default(&opts);
    opts.grid_spacing = 6; /* not a power of two */
    assert_int_equal(sh_warp_model_create(interp, good, 4, 200, 200, &opts, &model), SH_EINVAL);
    assert_int_equal(sh_warp_model_create(interp, good, 4, 200, 200, NULL, &model), SH_OK);
    double cur[] = {10, 10, 150, NAN, 140, 150, 20, 140};
    assert_int_equal(sh_warp_model_update(model, cur), SH_EINVAL);
    sh_image small, out;
    assert_int_equal(sh_image_create(&small, SH_PIX_GRAY8, 100, 100), SH_OK);
    assert_int_equal(sh_image_create(&out, SH_PIX_GRAY8, 100, 100), SH_OK);
    sh_warp *warp;
    assert_int_equal(sh_warp_create(1, &warp), SH_OK);
    assert_int_equal(sh_warp_apply(warp, model, &small, &out), SH_EINVAL);
    assert_int_equal(sh_warp_create(0, &(sh_warp *){NULL}), SH_EINVAL);
    sh_warp_destroy(warp);
    sh_image_destroy(&small);
    sh_image_destroy(&out);
    sh_warp_model_destroy(model);
    sh_interp_destroy(interp);
}

/* The row fill at every grid spacing, against the bilinear interpolation of the exact map at
 * the grid's nodes computed here in double: whole cells, cells cut by the hull's edge and pixels
 * on the last node column all get the nodes' values to within the 16.16 steps' rounding
 * (and the float map's 2^-15 px at these coordinates). Gaussian takes the separable node sum,
 * TPS the sparse rows. */
static void test_fill_every_spacing(void **state)
{
    (void)state;
    const int w = 330, h = 190, n = 12;
    synth_motion mo = {w, h, 9};
    double ref[2 * n], cur[2 * n], disp[2 * n];
    synth_markers(&mo, n, 11, ref);
    moved_markers(&mo, 0.4, ref, n, cur);
    for (int i = 0; i < 2 * n; i++) disp[i] = cur[i] - ref[i];
    float *map = malloc(sizeof(float) * 2 * (size_t)w * h);
    const char *methods[] = {"gaussian", "tps"};
    for (int mth = 0; mth < 2; mth++) {
        for (int sp = 1; sp <= 32; sp *= 2) {
            sh_warp_options opts;
            sh_warp_options_default(&opts);
            opts.grid_spacing = sp;
            opts.max_error = 1e9; /* keep this spacing */
            opts.coarsest_spacing = 0;
            built b = build(methods[mth], ref, n, w, h, &opts);
            assert_int_equal(sh_warp_model_update(b.model, cur), SH_OK);
            assert_int_equal(sh_warp_model_grid_spacing(b.model), sp);
            double coef[2 * 16];
            assert_true(sh_interp_num_coefs(b.interp) <= 16);
            assert_int_equal(sh_interp_fit(b.interp, disp, 2, coef), SH_OK);
            assert_int_equal(sh_warp_model_map(b.model, map), SH_OK);
            const sh_hull *hull = sh_warp_model_hull(b.model);
            /* the grid's geometry as sh_warp_model documents it: nodes at multiples of the
             * spacing, from the one at or left of / above the hull to the one at or past it */
            int gx0 = (int)floor(hull->xmin / sp) * sp, gy0 = (int)floor(hull->ymin / sp) * sp;
            int nx = ((int)ceil(hull->xmax / sp) * sp - gx0) / sp + 1;
            int ny = ((int)ceil(hull->ymax / sp) * sp - gy0) / sp + 1;
            double worst = 0;
            for (int y = 0; y < h; y++) {
                for (int x = 0; x < w; x++) {
                    if (!sh_hull_contains(hull, x, y)) continue;
                    int i = (x - gx0) / sp, j = (y - gy0) / sp;
                    if (i > nx - 2) i = nx - 2;
                    if (j > ny - 2) j = ny - 2;
                    double tx = (double)(x - gx0 - i * sp) / sp, ty = (double)(y - gy0 - j * sp) / sp;
                    double v[4][2];
                    for (int c = 0; c < 4; c++) {
                        double X = gx0 + (i + c % 2) * sp, Y = gy0 + (j + c / 2) * sp;
                        assert_int_equal(sh_interp_eval(b.interp, coef, 2, X, Y, v[c]), SH_OK);
                        v[c][0] += X;
                        v[c][1] += Y;
                    }
                    const float *m = map + 2 * ((size_t)y * w + x);
                    for (int c = 0; c < 2; c++) {
                        double top = v[0][c] + tx * (v[1][c] - v[0][c]);
                        double bottom = v[2][c] + tx * (v[3][c] - v[2][c]);
                        worst = fmax(worst, fabs(m[c] - (top + ty * (bottom - top))));
                    }
                }
            }
            if (getenv("SH_TEST_VERBOSE"))
                printf("  %-8s spacing %2d: fill vs bilinear of exact nodes %.2e px\n",
                       methods[mth], sp, worst);
            /* node value rounded to 2^-17, the step's rounding h 2^-17, float storage 2^-15 */
            assert_true(worst <= (sp + 1) * 0x1p-17 + 0x1p-15);
            unbuild(&b);
        }
    }
    free(map);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_grid_map_within_tolerance),
        cmocka_unit_test(test_grid_refines_for_tight_tolerance),
        cmocka_unit_test(test_fill_every_spacing),
        cmocka_unit_test(test_exact_methods),
        cmocka_unit_test(test_update_subset),
        cmocka_unit_test(test_update_subset_pwlinear),
        cmocka_unit_test(test_coarse_level_within_tolerance),
        cmocka_unit_test(test_dense_rows_as_exact),
        cmocka_unit_test(test_dense_rows_avx2_same_bits),
        cmocka_unit_test(test_translation_every_format),
        cmocka_unit_test(test_translation_beyond_range),
        cmocka_unit_test(test_bilinear_closed_form),
        cmocka_unit_test(test_threads_same_bytes),
        cmocka_unit_test(test_update_on_threads_same_map),
        cmocka_unit_test(test_apply_again_same_bytes),
        cmocka_unit_test(test_synthetic_sequence),
        cmocka_unit_test(test_bad_input),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
