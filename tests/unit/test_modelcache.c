/* Models per marker set (modelcache.h): the LRU table's hits, evictions and failures, an entry's
 * key and positions from the reference rows, and its model equal to one built directly. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include <cmocka.h>

#include "stillheart/modelcache.h"

#define W 64
#define H 48

/* Five markers: ids 2, 4, 6, 8, 10 on a pentagon-ish spread; 3D positions on the plane Z = 100. */
static sh_point ref[5];

static int reference(void **state)
{
    (void)state;
    static const double xy[5][2] = {{10, 8}, {50, 10}, {54, 40}, {12, 38}, {30, 24}};
    for (int i = 0; i < 5; i++) {
        memset(&ref[i], 0, sizeof ref[i]);
        ref[i].id = 2 * (i + 1);
        ref[i].x = xy[i][0];
        ref[i].y = xy[i][1];
        ref[i].X = xy[i][0];
        ref[i].Y = xy[i][1];
        ref[i].Z = 100;
    }
    return 0;
}

static void recipe_2d(sh_modelcache_recipe *r)
{
    memset(r, 0, sizeof *r);
    assert_int_equal(sh_interp_params_parse("tps", &r->params), SH_OK);
    sh_warp_options_default(&r->wopts);
    r->width = W;
    r->height = H;
}

static void test_entry_key_and_positions(void **state)
{
    (void)state;
    sh_modelcache_entry e;
    memset(&e, 0, sizeof e);
    const int ids[] = {4, 8, 10};
    assert_int_equal(sh_modelcache_entry_set(&e, ref, 5, ids, 3), SH_OK);
    assert_int_equal(e.n, 3);
    assert_true(sh_modelcache_entry_is(&e, ids, 3));
    const int other[] = {4, 8, 6};
    assert_false(sh_modelcache_entry_is(&e, other, 3));
    assert_false(sh_modelcache_entry_is(&e, ids, 2));
    /* ids 4, 8, 10 are rows 1, 3, 4 */
    assert_true(e.ref_xy[0] == 50 && e.ref_xy[1] == 10 && e.ref_xy[2] == 12 && e.ref_xy[3] == 38 &&
                e.ref_xy[4] == 30 && e.ref_xy[5] == 24);
    assert_true(e.ref_xyz[2] == 100 && e.ref_xyz[3] == 12);
    const int missing[] = {4, 5};
    assert_int_equal(sh_modelcache_entry_set(&e, ref, 5, missing, 2), SH_EINVAL);
    assert_int_equal(e.n, 0); /* left empty */
    sh_modelcache_entry_clear(&e);
}

/* The cached model maps every pixel as a model built by hand from the same markers does. */
/* The entry's map of all five markers after an update equals the one of an interpolant and model
 * built directly, with each point's smoothing lambda (NULL: none). */
static void check_direct_build(const sh_modelcache_recipe *r, const double *lambda)
{
    sh_modelcache *c;
    assert_int_equal(sh_modelcache_create(r, ref, 5, 2, &c), SH_OK);
    const int ids[] = {2, 4, 6, 8, 10};
    sh_modelcache_entry *e;
    assert_int_equal(sh_modelcache_get(c, ids, 5, &e), SH_OK);
    double xy[10];
    for (int i = 0; i < 5; i++) xy[2 * i] = ref[i].x, xy[2 * i + 1] = ref[i].y;
    sh_interp *interp;
    sh_warp_model *model;
    assert_int_equal(sh_interp_create_smoothed(&r->params, xy, 5, lambda, &interp), SH_OK);
    assert_int_equal(sh_warp_model_create(interp, xy, 5, W, H, &r->wopts, &model), SH_OK);
    double cur[10];
    for (int i = 0; i < 10; i++) cur[i] = xy[i] + (i % 2 ? 1.5 : -0.75) + 0.1 * i;
    assert_int_equal(sh_warp_model_update(model, cur), SH_OK);
    assert_int_equal(sh_warp_model_update(e->model, cur), SH_OK);
    float *a = malloc(sizeof(float) * 2 * W * H), *b = malloc(sizeof(float) * 2 * W * H);
    assert_non_null(a);
    assert_non_null(b);
    assert_int_equal(sh_warp_model_map(model, a), SH_OK);
    assert_int_equal(sh_warp_model_map(e->model, b), SH_OK);
    assert_memory_equal(a, b, sizeof(float) * 2 * W * H);
    free(a);
    free(b);
    sh_warp_model_destroy(model);
    sh_interp_destroy(interp);
    sh_modelcache_destroy(c);
}

static void test_model_equals_direct_build(void **state)
{
    (void)state;
    sh_modelcache_recipe r;
    recipe_2d(&r);
    check_direct_build(&r, NULL);
}

/* point_smoothing goes to the rows from smoothed_from on (ids 8 and 10 here), and only with a
 * method that smooths: bspline interpolates them as before. */
static void test_point_smoothing_by_id(void **state)
{
    (void)state;
    sh_modelcache_recipe r;
    recipe_2d(&r);
    r.point_smoothing = 500;
    r.smoothed_from = 8;
    const double lambda[5] = {0, 0, 0, 500, 500};
    check_direct_build(&r, lambda);
    assert_int_equal(sh_interp_params_parse("bspline", &r.params), SH_OK);
    check_direct_build(&r, NULL);
}

/* In 3D the smoothing is given in the source camera's pixels: the markers' plane Z = 100 faces a
 * pinhole camera of focal length 200 at the origin, 2 px a mm (f / Z), so the rows from
 * smoothed_from on get 500 / 2^2 in the surface's mm; a model built directly with those values
 * moves every point as the entry's does, and tps misses row 8's position (approximated). A
 * B-spline gets the rows too (its levels are the markers': warp3d.h). */
static void test_point_smoothing_3d(void **state)
{
    (void)state;
    sh_modelcache_recipe r;
    memset(&r, 0, sizeof r);
    r.three_d = 1;
    r.width = W;
    r.height = H;
    sh_warp3d_params_default(&r.p3);
    assert_int_equal(sh_interp_params_parse("tps", &r.p3.surface), SH_OK);
    assert_int_equal(sh_interp_params_parse("tps", &r.p3.displacement), SH_OK);
    const double K[9] = {200, 0, 32, 0, 200, 24, 0, 0, 1}, R[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
    memcpy(r.source_cam.K, K, sizeof K);
    memcpy(r.source_cam.R, R, sizeof R);
    r.source_cam.num_dist = 5;
    r.point_smoothing = 500;
    r.smoothed_from = 8;
    const int ids[] = {2, 4, 6, 8, 10};
    double xyz[15], cur[15];
    for (int i = 0; i < 5; i++) {
        xyz[3 * i] = ref[i].X, xyz[3 * i + 1] = ref[i].Y, xyz[3 * i + 2] = ref[i].Z;
        for (int c = 0; c < 3; c++) cur[3 * i + c] = xyz[3 * i + c] + 0.3 * sin(1.7 * i + c) + (c == 2) * 0.2 * i;
    }
    for (int k = 0; k < 2; k++) {
        if (k) assert_int_equal(sh_interp_params_parse("bspline", &r.p3.displacement), SH_OK);
        if (k) assert_int_equal(sh_interp_params_parse("bspline", &r.p3.surface), SH_OK);
        const double lambda[5] = {0, 0, 0, 125, 125};
        sh_modelcache *c;
        assert_int_equal(sh_modelcache_create(&r, ref, 5, 1, &c), SH_OK);
        sh_modelcache_entry *e;
        assert_int_equal(sh_modelcache_get(c, ids, 5, &e), SH_OK);
        sh_warp3d_model *m;
        assert_int_equal(sh_warp3d_model_create_smoothed(&r.p3, xyz, 5, lambda, &m), SH_OK);
        assert_int_equal(sh_warp3d_model_update(m, cur), SH_OK);
        assert_int_equal(sh_warp3d_model_update(e->m3, cur), SH_OK);
        double worst = 0, off = 0;
        for (int q = 0; q < 9; q++) {
            double u = -20 + 5 * q, v = 12 - 3 * q, a[3], b[3];
            sh_warp3d_model_point(m, u, v, 1, 1, a);
            sh_warp3d_model_point(e->m3, u, v, 1, 1, b);
            for (int j = 0; j < 3; j++) worst = fmax(worst, fabs(a[j] - b[j]));
        }
        /* smoothed, the entry misses row 8's current position */
        double origin[3], axes[9], d[3], p[3];
        sh_warp3d_model_frame(e->m3, origin, axes);
        for (int j = 0; j < 3; j++) d[j] = xyz[9 + j] - origin[j];
        sh_warp3d_model_point(e->m3, d[0] * axes[0] + d[1] * axes[1] + d[2] * axes[2],
                              d[0] * axes[3] + d[1] * axes[4] + d[2] * axes[5], 1, 1, p);
        for (int j = 0; j < 3; j++) off = fmax(off, fabs(p[j] - cur[9 + j]));
        assert_true(worst < 1e-9);
        if (!k) assert_true(off > 1e-3);
        sh_warp3d_model_destroy(m);
        sh_modelcache_destroy(c);
    }
}

/* Two slots: A, B, A, C keeps A and C (B least recently used); B again is a fourth build. A set
 * whose model cannot be built is refused and not kept. */
static void test_lru_and_failures(void **state)
{
    (void)state;
    sh_modelcache_recipe r;
    recipe_2d(&r);
    sh_modelcache *c;
    assert_int_equal(sh_modelcache_create(&r, ref, 5, 2, &c), SH_OK);
    const int A[] = {2, 4, 6, 8}, B[] = {2, 4, 6, 10}, C[] = {4, 6, 8, 10};
    sh_modelcache_entry *e, *ea;
    assert_int_equal(sh_modelcache_get(c, A, 4, &ea), SH_OK);
    assert_int_equal(sh_modelcache_get(c, B, 4, &e), SH_OK);
    assert_int_equal(sh_modelcache_get(c, A, 4, &e), SH_OK);
    assert_ptr_equal(e, ea);
    assert_int_equal(sh_modelcache_builds(c), 2);
    assert_int_equal(sh_modelcache_get(c, C, 4, &e), SH_OK);
    assert_int_equal(sh_modelcache_builds(c), 3);
    assert_int_equal(sh_modelcache_get(c, A, 4, &e), SH_OK); /* still there */
    assert_int_equal(sh_modelcache_builds(c), 3);
    assert_int_equal(sh_modelcache_get(c, B, 4, &e), SH_OK); /* evicted: built again */
    assert_int_equal(sh_modelcache_builds(c), 4);
    /* two markers: too few for tps */
    const int two[] = {2, 4};
    assert_int_not_equal(sh_modelcache_get(c, two, 2, &e), SH_OK);
    assert_int_not_equal(sh_modelcache_get(c, two, 2, &e), SH_OK);
    assert_int_equal(sh_modelcache_builds(c), 4);
    assert_true(sh_modelcache_build_seconds(c) >= 0);
    sh_modelcache_destroy(c);
}

/* The lookup over a caller's table: kept entries are never the victim, an empty one comes first. */
typedef struct {
    sh_modelcache_entry e[3];
    int kept[3];
} table3;

static sh_modelcache_entry *entry_of(void *t, int i) { return &((table3 *)t)->e[i]; }
static int kept_of(void *t, int i) { return ((table3 *)t)->kept[i]; }

static void test_lookup_keeps_and_prefers_empty(void **state)
{
    (void)state;
    table3 t;
    memset(&t, 0, sizeof t);
    const int A[] = {2, 4, 6}, B[] = {4, 6, 8}, C[] = {6, 8, 10};
    assert_int_equal(sh_modelcache_entry_set(&t.e[0], ref, 5, A, 3), SH_OK);
    assert_int_equal(sh_modelcache_entry_set(&t.e[2], ref, 5, B, 3), SH_OK);
    t.e[0].last_used = 1;
    t.e[2].last_used = 2;
    unsigned long clock = 2;
    int victim;
    assert_int_equal(sh_modelcache_lookup(&t, 3, entry_of, kept_of, &clock, C, 3, &victim), -1);
    assert_int_equal(victim, 1); /* the empty one */
    assert_int_equal(sh_modelcache_lookup(&t, 3, entry_of, kept_of, &clock, B, 3, &victim), 2);
    assert_true(t.e[2].last_used == 3 && clock == 3);
    assert_int_equal(sh_modelcache_entry_set(&t.e[1], ref, 5, C, 3), SH_OK);
    t.e[1].last_used = ++clock;
    const int D[] = {2, 8, 10};
    assert_int_equal(sh_modelcache_lookup(&t, 3, entry_of, kept_of, &clock, D, 3, &victim), -1);
    assert_int_equal(victim, 0); /* least recently used */
    t.kept[0] = 1;
    assert_int_equal(sh_modelcache_lookup(&t, 3, entry_of, kept_of, &clock, D, 3, &victim), -1);
    assert_int_equal(victim, 2); /* the next least recently used */
    t.kept[1] = t.kept[2] = 1;
    assert_int_equal(sh_modelcache_lookup(&t, 3, entry_of, kept_of, &clock, D, 3, &victim), -1);
    assert_int_equal(victim, -1);
    for (int i = 0; i < 3; i++) sh_modelcache_entry_clear(&t.e[i]);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_entry_key_and_positions),
        cmocka_unit_test(test_model_equals_direct_build),
        cmocka_unit_test(test_point_smoothing_by_id),
        cmocka_unit_test(test_point_smoothing_3d),
        cmocka_unit_test(test_lru_and_failures),
        cmocka_unit_test(test_lookup_keeps_and_prefers_empty),
    };
    return cmocka_run_group_tests(tests, reference, NULL);
}
