/* The warp's RGB sampler: the SIMD path of this build (SSE2 on x86-64, NEON on AArch64) against
 * the portable C definition, bit for bit, on random positions inside, across the edges and far
 * outside the plane, on planes of several sizes and strides. Run under qemu-aarch64 by
 * `make check-arm64`, this is the NEON path's test. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include <cmocka.h>

#include "../../src/warp/warp_internal.h"

static uint64_t rng = 0x9e3779b97f4a7c15u;
static uint32_t next_u32(void)
{
    rng ^= rng << 13; rng ^= rng >> 7; rng ^= rng << 17;
    return (uint32_t)(rng >> 16);
}

static void compare_on(int width, int height, int stride, int count, int spread)
{
    uint8_t *data = malloc((size_t)stride * (size_t)height);
    assert_non_null(data);
    for (size_t i = 0; i < (size_t)stride * (size_t)height; i++) data[i] = (uint8_t)next_u32();
    sh_plane plane = {data, width, height, stride};
    int32_t *fx = malloc(sizeof(int32_t) * (size_t)count), *fy = malloc(sizeof(int32_t) * (size_t)count);
    uint8_t *simd = malloc((size_t)count * 3 + 1), *ref = malloc((size_t)count * 3 + 1);
    assert_true(fx && fy && simd && ref);
    for (int k = 0; k < count; k++) {
        /* positions in [-spread, size + spread) px with any 16-bit fraction; runs of inside
         * positions so that the 4-pixel blocks take their fast path often */
        int64_t rx = (int64_t)(next_u32() % (uint32_t)((width + 2 * spread) << 8)) - ((int64_t)spread << 8);
        int64_t ry = (int64_t)(next_u32() % (uint32_t)((height + 2 * spread) << 8)) - ((int64_t)spread << 8);
        fx[k] = (int32_t)(rx * 256 + (next_u32() & 255));
        fy[k] = (int32_t)(ry * 256 + (next_u32() & 255));
    }
    for (int start = 0; start < 3; start++) {
        int n = count - start;
        memset(simd, 0xa5, (size_t)count * 3 + 1);
        memset(ref, 0xa5, (size_t)count * 3 + 1);
        warp_sample_init();
        warp_sample_row(&plane, 3, 7, simd, fx + start, fy + start, n);
        warp_sample_row_rgb_portable(&plane, 7, ref, fx + start, fy + start, n);
        for (int k = 0; k < 3 * count + 1; k++) {
            if (simd[k] != ref[k])
                fail_msg("%dx%d stride %d: byte %d (pixel %d): simd %u, portable %u", width, height,
                         stride, k, k / 3, simd[k], ref[k]);
        }
    }
    free(data); free(fx); free(fy); free(simd); free(ref);
}

static void test_inside(void **state)
{
    (void)state;
    compare_on(640, 480, 640 * 3, 200000, 0);
    compare_on(97, 61, 97 * 3 + 5, 50000, 0);
}

static void test_edges_and_outside(void **state)
{
    (void)state;
    compare_on(64, 48, 64 * 3, 100000, 4);
    compare_on(5, 4, 16, 20000, 3);
    compare_on(2, 2, 6, 5000, 2);
    compare_on(1, 1, 3, 1000, 1);
}

static void test_wide_stride(void **state)
{
    (void)state;
    /* stride > 32767: the 4-pixel blocks are skipped, the tail loop does it all */
    compare_on(11000, 3, 33003, 30000, 2);
}

static void test_extreme_positions(void **state)
{
    (void)state;
    uint8_t data[8 * 3 * 8];
    for (size_t i = 0; i < sizeof data; i++) data[i] = (uint8_t)(i * 37);
    sh_plane plane = {data, 8, 8, 24};
    const int32_t v[] = {INT32_MIN, INT32_MIN + 1, -1, 0, 1, 65535, 65536, (7 << 16) - 1, 7 << 16,
                         (7 << 16) + 1, 5 << 16, (4 << 16) + 32768, INT32_MAX - 1, INT32_MAX};
    enum { N = sizeof v / sizeof v[0] };
    int32_t fx[N * N], fy[N * N];
    for (int i = 0; i < N; i++)
        for (int j = 0; j < N; j++) { fx[i * N + j] = v[i]; fy[i * N + j] = v[j]; }
    uint8_t simd[N * N * 3], ref[N * N * 3];
    warp_sample_init();
    warp_sample_row(&plane, 3, 0, simd, fx, fy, N * N);
    warp_sample_row_rgb_portable(&plane, 0, ref, fx, fy, N * N);
    assert_memory_equal(simd, ref, sizeof simd);
}

/* The definition itself, on numbers worked by hand: two roundings. */
static void test_portable_by_hand(void **state)
{
    (void)state;
    /* 4x2 plane; pixel (0,0) = (0, 100, 255), (1,0) = (128, 0, 10), (0,1) = (255, 255, 0),
     * (1,1) = (1, 2, 3); the rest 0. Position (0.5, 0.25): wx = 64, wy = 32. */
    uint8_t data[2 * 12] = {0, 100, 255, 128, 0, 10, 0, 0, 0, 0, 0, 0,
                            255, 255, 0, 1, 2, 3, 0, 0, 0, 0, 0, 0};
    sh_plane plane = {data, 4, 2, 12};
    int32_t fx = 1 << 15, fy = 1 << 14;
    uint8_t out[3];
    warp_sample_row_rgb_portable(&plane, 0, out, &fx, &fy, 1);
    /* R: left (0*96 + 255*32 + 64) >> 7 = 64, right (128*96 + 1*32 + 64) >> 7 = 96,
     *    (64*64 + 96*64 + 64) >> 7 = 80
     * G: left (100*96 + 255*32 + 64) >> 7 = 139, right (0 + 2*32 + 64) >> 7 = 1,
     *    (139*64 + 1*64 + 64) >> 7 = 70
     * B: left (255*96 + 0 + 64) >> 7 = 191, right (10*96 + 3*32 + 64) >> 7 = 8,
     *    (191*64 + 8*64 + 64) >> 7 = 100 */
    assert_int_equal(out[0], 80);
    assert_int_equal(out[1], 70);
    assert_int_equal(out[2], 100);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_portable_by_hand),
        cmocka_unit_test(test_inside),
        cmocka_unit_test(test_edges_and_outside),
        cmocka_unit_test(test_wide_stride),
        cmocka_unit_test(test_extreme_positions),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
