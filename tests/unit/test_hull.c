/* The convex hull (src/hull) against its definition: every point inside or on it, every vertex
 * one of the points, the boundary convex and turning one way, and each vertex extreme (a line
 * through it leaves every point on one side). On the stack's sizes (the daemon's frames: markers
 * and landmarks) and beyond them, with duplicates and collinear runs. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>

#include <cmocka.h>

#include "stillheart/hull.h"

static uint64_t rng_state = 0x9E3779B97F4A7C15ULL;
static double uniform(double lo, double hi)
{
    rng_state ^= rng_state >> 12;
    rng_state ^= rng_state << 25;
    rng_state ^= rng_state >> 27;
    return lo + (hi - lo) * (double)((rng_state * 2685821657736338717ULL) >> 11) / 9007199254740992.0;
}

static void check_hull(const double *xy, int n)
{
    sh_hull h;
    assert_int_equal(sh_hull_compute(xy, n, &h), SH_OK);
    assert_true(h.count >= 3);
    for (int i = 0; i < n; i++) assert_true(sh_hull_contains(&h, xy[2 * i], xy[2 * i + 1]));
    for (int v = 0; v < h.count; v++) {
        int found = 0;
        for (int i = 0; i < n && !found; i++) found = xy[2 * i] == h.x[v] && xy[2 * i + 1] == h.y[v];
        assert_true(found);
        /* strictly convex: no vertex on its neighbours' line, every turn the same way */
        int a = (v + h.count - 1) % h.count, b = (v + 1) % h.count;
        double turn = (h.x[v] - h.x[a]) * (h.y[b] - h.y[v]) - (h.y[v] - h.y[a]) * (h.x[b] - h.x[v]);
        assert_true(turn > 0);
        /* every point on the inner side of the edge v -> b */
        for (int i = 0; i < n; i++) {
            double s = (h.x[b] - h.x[v]) * (xy[2 * i + 1] - h.y[v]) - (h.y[b] - h.y[v]) * (xy[2 * i] - h.x[v]);
            assert_true(s >= -1e-9);
        }
    }
}

static void test_hull_definition(void **state)
{
    (void)state;
    static const int sizes[] = {3, 4, 16, 64, 65, 200, 512, 513, 2000};
    for (size_t k = 0; k < sizeof sizes / sizeof *sizes; k++) {
        int n = sizes[k];
        double *xy = malloc(sizeof(double) * 2 * (size_t)n);
        assert_non_null(xy);
        for (int i = 0; i < n; i++) xy[2 * i] = uniform(0, 1920), xy[2 * i + 1] = uniform(0, 1080);
        check_hull(xy, n);
        /* duplicates and a collinear run along the bottom edge */
        if (n >= 16) {
            for (int i = 0; i < n / 4; i++) xy[2 * i] = xy[2 * (n - 1 - i)], xy[2 * i + 1] = xy[2 * (n - 1 - i) + 1];
            for (int i = n / 4; i < n / 2; i++) xy[2 * i] = 100.0 * (i - n / 4), xy[2 * i + 1] = 1100;
            check_hull(xy, n);
        }
        free(xy);
    }
    /* a square's four corners out of a grid of points on and inside it */
    double grid[2 * 25];
    for (int i = 0; i < 25; i++) grid[2 * i] = 10.0 * (i % 5), grid[2 * i + 1] = 10.0 * (i / 5);
    sh_hull h;
    assert_int_equal(sh_hull_compute(grid, 25, &h), SH_OK);
    assert_int_equal(h.count, 4);
    assert_true(h.xmin == 0 && h.xmax == 40 && h.ymin == 0 && h.ymax == 40);
    double line[] = {0, 0, 1, 1, 2, 2, 3, 3};
    assert_int_equal(sh_hull_compute(line, 4, &h), SH_EDEGENERATE);
    double bad[] = {0, 0, 1, NAN, 2, 0};
    assert_int_equal(sh_hull_compute(bad, 3, &h), SH_EINVAL);
}

/* A row's accepted span against the triangle (0, 0), (30, 0), (0, 60), whose right edge is
 * x = 30 - y / 2: [0, 30 - y / 2] within the tolerance, none above or below it; and sh_hull_contains
 * decides as the span does, points on the edges included, over a grid and at random. */
static void test_row_accepts(void **state)
{
    (void)state;
    double tri[] = {0, 0, 30, 0, 0, 60};
    sh_hull h;
    assert_int_equal(sh_hull_compute(tri, 3, &h), SH_OK);
    double lo, hi;
    for (double y = 0; y <= 60; y += 0.25) {
        assert_true(sh_hull_row_accepts(&h, y, &lo, &hi));
        assert_float_equal(lo, 0, 1e-8);
        assert_float_equal(hi, 30 - y / 2, 1e-8);
        assert_true(lo < 0 && hi > 30 - y / 2 - 1e-12); /* the tolerance widens, never narrows */
    }
    assert_false(sh_hull_row_accepts(&h, -0.001, &lo, &hi));
    assert_false(sh_hull_row_accepts(&h, 60.001, &lo, &hi));
    for (int i = 0; i < 20000; i++) {
        double x = i < 10000 ? (i % 100) * 0.5 - 10 : uniform(-10, 40);
        double y = i < 10000 ? (i / 100) * 0.75 - 5 : uniform(-5, 65);
        int in = sh_hull_row_accepts(&h, y, &lo, &hi) && lo <= x && x <= hi;
        assert_int_equal(in, sh_hull_contains(&h, x, y));
        if (fabs(x - (30 - y / 2)) > 1e-6 && fabs(x) > 1e-6 && fabs(y) > 1e-6)
            assert_int_equal(in, x >= 0 && y >= 0 && x <= 30 - y / 2);
    }
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_hull_definition),
        cmocka_unit_test(test_row_accepts),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
