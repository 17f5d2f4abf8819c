/* The tracker's window loops (sampling, a step's comparison, the error measure): the SIMD paths
 * of this build (SSE2 and, where the CPU has it, AVX-512 on x86-64; NEON on AArch64) against the
 * portable C definitions, bit for bit, on random pixels and gradients including the extremes (0
 * and 255, +-4080, the largest Scharr gradients), at random sub-pixel positions up to one window
 * outside the level, for every window side. Run under qemu-aarch64 by `make check-arm64`, this is
 * the NEON path's test. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
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

/* A level of w x h with `pad` of border and FLOW_SLACK after each plane, filled at random;
 * `extreme` draws only the largest values. */
typedef struct {
    flow_level l;
    uint8_t *img;
    int16_t *gx, *gy;
} level_mem;

static void level_make(level_mem *m, int w, int h, int pad, int extreme)
{
    m->l.width = w;
    m->l.height = h;
    m->l.stride = w + 2 * pad;
    size_t n = (size_t)m->l.stride * (size_t)(h + 2 * pad), origin = (size_t)pad * m->l.stride + pad;
    m->img = malloc(n + FLOW_SLACK);
    m->gx = malloc(2 * n + FLOW_SLACK);
    m->gy = malloc(2 * n + FLOW_SLACK);
    assert_non_null(m->img);
    assert_non_null(m->gx);
    assert_non_null(m->gy);
    for (size_t i = 0; i < n + FLOW_SLACK; i++) m->img[i] = extreme ? (next_u32() & 1) * 255 : (uint8_t)next_u32();
    for (size_t i = 0; i < n + FLOW_SLACK / 2; i++) {
        int a = (int)(next_u32() % 8161) - 4080, b = (int)(next_u32() % 8161) - 4080;
        if (extreme) {
            a = (next_u32() & 1) ? 4080 : -4080;
            b = (next_u32() & 1) ? 4080 : -4080;
        }
        m->gx[i] = (int16_t)a;
        m->gy[i] = (int16_t)b;
    }
    m->l.img = m->img + origin;
    m->l.gx = m->gx + origin;
    m->l.gy = m->gy + origin;
}

static void level_free(level_mem *m)
{
    free(m->img);
    free(m->gx);
    free(m->gy);
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
    int16_t *I0 = malloc(cells * 2), *X0 = malloc(cells * 2), *Y0 = malloc(cells * 2);
    int16_t *I1 = malloc(cells * 2), *X1 = malloc(cells * 2), *Y1 = malloc(cells * 2);
    assert_non_null(I0);
    assert_non_null(Y1);
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
    free(I0);
    free(X0);
    free(Y0);
    free(I1);
    free(X1);
    free(Y1);
    level_free(&m);
    level_free(&n);
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
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
