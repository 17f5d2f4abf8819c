/* The tracker's window loops (sampling, a step's comparison, the error measure): the SIMD paths
 * of this build (SSE2 and, where the CPU has it, AVX-512 on x86-64; NEON on AArch64) against the
 * portable C definitions, bit for bit, on random pixels including the extremes (0 and 255, whose
 * gradients reach +-4080, the largest Scharr's), at random sub-pixel positions up to one window
 * outside the level, for every window side; and the windows' gradients against Scharr's kernel.
 * Run under qemu-aarch64 by `make check-arm64`, this is the NEON path's test. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include <cmocka.h>

#include "../../src/flow/flow_internal.h"

static uint64_t rng = 0x9e3779b97f4a7c15u;
static uint32_t next_u32(void)
{
    rng ^= rng << 13;
    rng ^= rng >> 7;
    rng ^= rng << 17;
    return (uint32_t)(rng >> 16);
}

/* A level of w x h with `pad` of border and FLOW_SLACK after its plane, filled at random;
 * `extreme` draws only 0 and 255, whose Scharr gradients reach the largest, +-4080. */
typedef struct {
    flow_level l;
    uint8_t *img;
} level_mem;

static void level_make(level_mem *m, int w, int h, int pad, int extreme)
{
    m->l.width = w;
    m->l.height = h;
    m->l.stride = w + 2 * pad;
    size_t n = (size_t)m->l.stride * (size_t)(h + 2 * pad), origin = (size_t)pad * m->l.stride + pad;
    m->img = malloc(n + FLOW_SLACK);
    assert_non_null(m->img);
    for (size_t i = 0; i < n + FLOW_SLACK; i++) m->img[i] = extreme ? (next_u32() & 1) * 255 : (uint8_t)next_u32();
    m->l.img = m->img + origin;
}

static void level_free(level_mem *m)
{
    free(m->img);
}

/* A window's gradients against Scharr's kernel written out pixel by pixel (3 and 10 across, -1
 * and 1 along), zero outside the level and past the window's win + 1 columns. */
static void check_gradients(const level_mem *m, int ix, int iy, int win)
{
    const int gs = FLOW_GROW(win);
    static int16_t gx[(SH_FLOW_MAX_WIN + 1) * FLOW_GROW(SH_FLOW_MAX_WIN)], gy[sizeof gx / sizeof *gx];
    flow_window_gradients(&m->l, ix, iy, win, gx, gy);
    for (int y = 0; y <= win; y++)
        for (int x = 0; x < gs; x++) {
            const int X = ix + x, Y = iy + y;
            int ex = 0, ey = 0;
            if (x <= win && X >= 0 && X < m->l.width && Y >= 0 && Y < m->l.height) {
                const int s = m->l.stride;
#define P(dx, dy) ((int)m->l.img[(ptrdiff_t)(Y + (dy)) * s + X + (dx)])
                ex = -3 * P(-1, -1) + 3 * P(1, -1) - 10 * P(-1, 0) + 10 * P(1, 0) - 3 * P(-1, 1) + 3 * P(1, 1);
                ey = -3 * P(-1, -1) - 10 * P(0, -1) - 3 * P(1, -1) + 3 * P(-1, 1) + 10 * P(0, 1) + 3 * P(1, 1);
#undef P
            }
            if (gx[y * gs + x] != ex || gy[y * gs + x] != ey)
                fail_msg("win %d corner (%d, %d): gradient at (%d, %d) is (%d, %d), Scharr's (%d, %d)", win, ix, iy,
                         x, y, gx[y * gs + x], gy[y * gs + x], ex, ey);
        }
}

static void random_weights(int w[4], int corner)
{
    if (corner) { /* all the weight on one sample: the largest products */
        memset(w, 0, 4 * sizeof *w);
        w[next_u32() % 4] = 1 << 14;
        return;
    }
    int left = 1 << 14;
    for (int k = 0; k < 3; k++) {
        w[k] = (int)(next_u32() % (uint32_t)(left + 1));
        left -= w[k];
    }
    w[3] = left;
}

static void compare(int win, int extreme, int trials)
{
    const int w = 97, h = 71, wr = FLOW_WROW(win);
    level_mem m, n;
    level_make(&m, w, h, win, extreme);
    level_make(&n, w, h, win, extreme);
    size_t cells = (size_t)win * (size_t)wr;
    /* both results' pixels and gradients, one block */
    int16_t *block = malloc(6 * cells * 2);
    assert_non_null(block);
    int16_t *I0 = block, *X0 = I0 + cells, *Y0 = X0 + cells, *I1 = Y0 + cells, *X1 = I1 + cells, *Y1 = X1 + cells;
    for (int t = 0; t < trials; t++) {
        /* a window's corner anywhere the tracker may put it: -win .. size - 1 */
        int ix = (int)(next_u32() % (uint32_t)(w + win)) - win;
        int iy = (int)(next_u32() % (uint32_t)(h + win)) - win;
        int wt[4];
        random_weights(wt, extreme || t % 7 == 0);
        int64_t a0[3], a1[3], b0[2], b1[2];
        memset(I1, 0x55, cells * 2); /* whatever was there before: the lanes past the side too */
        memset(X1, 0x55, cells * 2);
        memset(Y1, 0x55, cells * 2);
        check_gradients(&m, ix, iy, win);
        flow_window_prev_portable(&m.l, ix, iy, wt, win, I0, X0, Y0, a0);
        flow_window_prev(&m.l, ix, iy, wt, win, I1, X1, Y1, a1);
        assert_memory_equal(I0, I1, cells * 2);
        assert_memory_equal(X0, X1, cells * 2);
        assert_memory_equal(Y0, Y1, cells * 2);
        assert_memory_equal(a0, a1, sizeof a0);
        int jx = (int)(next_u32() % (uint32_t)(w + win)) - win;
        int jy = (int)(next_u32() % (uint32_t)(h + win)) - win;
        random_weights(wt, extreme || t % 5 == 0);
        flow_window_mismatch_portable(&n.l, jx, jy, wt, win, I0, X0, Y0, b0);
        flow_window_mismatch(&n.l, jx, jy, wt, win, I0, X0, Y0, b1);
        assert_memory_equal(b0, b1, sizeof b0);
        const int64_t e0 = flow_window_abs_mismatch_portable(&n.l, jx, jy, wt, win, I0);
        assert_true(flow_window_abs_mismatch(&n.l, jx, jy, wt, win, I0) == e0);
#ifdef FLOW_X86
        /* both x86 loops, whichever the dispatch above chose */
        flow_window_mismatch_sse2(&n.l, jx, jy, wt, win, I0, X0, Y0, b1);
        assert_memory_equal(b0, b1, sizeof b0);
        assert_true(flow_window_abs_mismatch_sse2(&n.l, jx, jy, wt, win, I0) == e0);
        if (flow_window_avx512()) {
            flow_window_mismatch_avx512(&n.l, jx, jy, wt, win, I0, X0, Y0, b1);
            assert_memory_equal(b0, b1, sizeof b0);
            assert_true(flow_window_abs_mismatch_avx512(&n.l, jx, jy, wt, win, I0) == e0);
        }
#endif
    }
    free(block);
    level_free(&m);
    level_free(&n);
}

/* The warped window (sh_flow_track_windows_warped's level-0 template): random 2x2 matrices that
 * turn, shear and scale the window by up to 2 (the landmarks refuse more), from random starts
 * that keep every sample and its neighbour inside the padded level, as lk.c checks before it
 * samples. The dispatched loop (AVX-512 where the CPU has it) against the portable one. */
static void compare_warped(int win, int extreme, int trials)
{
    const int w = 97, h = 71, wr = FLOW_WROW(win), pad = win;
    level_mem m;
    level_make(&m, w, h, pad, extreme);
    size_t cells = (size_t)win * (size_t)wr;
    /* both results' pixels and gradients, one block */
    int16_t *block = malloc(6 * cells * 2);
    assert_non_null(block);
    int16_t *I0 = block, *X0 = I0 + cells, *Y0 = X0 + cells, *I1 = Y0 + cells, *X1 = I1 + cells, *Y1 = X1 + cells;
    int compared = 0;
    for (int t = 0; t < trials; t++) {
        double M[4];
        for (int k = 0; k < 4; k++) M[k] = ((double)(next_u32() % 2001) / 1000.0 - 1.0) * (k == 0 || k == 3 ? 1.0 : 0.7);
        M[0] += 1.0, M[3] += 1.0;
        const double one = 65536.0, hw = win / 2 + 1;
        const int32_t col[2] = {(int32_t)lrint(M[0] * one), (int32_t)lrint(M[2] * one)};
        const int32_t row[2] = {(int32_t)lrint(M[1] * one), (int32_t)lrint(M[3] * one)};
        /* the samples' reach from the centre, as lk.c bounds it */
        const double ex = hw * (fabs(M[0]) + fabs(M[1])), ey = hw * (fabs(M[2]) + fabs(M[3]));
        const double lox = -pad + ex, hix = w + pad - ex - 2, loy = -pad + ey, hiy = h + pad - ey - 2;
        if (!(hix > lox && hiy > loy)) continue;
        const double px = lox + (hix - lox) * (double)(next_u32() % 10007) / 10007.0;
        const double py = loy + (hiy - loy) * (double)(next_u32() % 10007) / 10007.0;
        const int32_t start[2] = {(int32_t)lrint((px + pad - hw * (M[0] + M[1])) * one),
                                  (int32_t)lrint((py + pad - hw * (M[2] + M[3])) * one)};
        int64_t a0[3], a1[3];
        memset(I1, 0x55, cells * 2);
        memset(X1, 0x55, cells * 2);
        memset(Y1, 0x55, cells * 2);
        flow_window_prev_warped_portable(&m.l, pad, start, col, row, win, I0, X0, Y0, a0);
        flow_window_prev_warped(&m.l, pad, start, col, row, win, I1, X1, Y1, a1);
        assert_memory_equal(I0, I1, cells * 2);
        assert_memory_equal(X0, X1, cells * 2);
        assert_memory_equal(Y0, Y1, cells * 2);
        assert_memory_equal(a0, a1, sizeof a0);
        compared++;
    }
    assert_true(compared >= trials / 2); /* the level has room for most matrices */
    free(block);
    level_free(&m);
}

static void test_warped_every_window_side(void **state)
{
    (void)state;
    for (int win = 5; win <= SH_FLOW_MAX_WIN; win += 2) compare_warped(win, 0, 60);
    compare_warped(SH_FLOW_MAX_WIN, 1, 200);
    compare_warped(21, 1, 200);
}

static void test_every_window_side(void **state)
{
    (void)state;
    for (int win = 5; win <= SH_FLOW_MAX_WIN; win += 2) compare(win, 0, 40);
}

/* The largest values everywhere: the bounds of the 32-bit lane sums (window.c) at their limit,
 * the largest window included. */
static void test_extremes(void **state)
{
    (void)state;
    compare(SH_FLOW_MAX_WIN, 1, 200);
    compare(21, 1, 200);
}

int main(void)
{
#ifdef FLOW_X86
    /* what this CPU can check: the AVX-512 loop only where it runs */
    print_message("window comparison: portable, SSE2%s\n",
                  flow_window_avx512() ? ", AVX-512" : " (no AVX-512 on this CPU)");
#endif
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_every_window_side),
        cmocka_unit_test(test_extremes),
        cmocka_unit_test(test_warped_every_window_side),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
