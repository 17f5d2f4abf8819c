/* The warp's samplers, RGB24 and one channel: the SIMD path of this build (SSE2 on x86-64, NEON
 * on AArch64; and one channel's AVX2 and AVX-512 loops where the CPU has them) against the portable C
 * definition, bit for bit, on random positions inside, across the edges and far outside the
 * plane, on planes of several sizes and strides, at several alignments. Run under qemu-aarch64
 * by `make check-arm64`, this is the NEON paths' test. */
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

typedef void (*portable_fn)(const sh_plane *, uint8_t, uint8_t *, const int32_t *, const int32_t *, int);

/* The paths this machine has: the build's SIMD path (0), and on an x86-64 CPU with them the
 * one-channel AVX2 (1) and AVX-512 (2) loops. Puts `path` in use; 0 when the CPU lacks it. */
static int use_path(int path)
{
    return warp_sample_path(path) == path;
}

static const char *const path_names[] = {"SIMD", "AVX2", "AVX-512"};
enum { PATHS = 3 };

/* The plane's buffer is exactly stride x height bytes, so that a read past it shows under ASan. */
static void compare_on(int channels, int width, int height, int stride, int count, int spread)
{
    const portable_fn portable = channels == 3 ? warp_sample_row_rgb_portable : warp_sample_row_gray_portable;
    /* one-channel blocks are 8 pixels (16 with AVX-512), RGB's 4: every start within a block */
    const int starts = channels == 3 ? 3 : 16;
    uint8_t *data = malloc((size_t)stride * (size_t)height);
    assert_non_null(data);
    for (size_t i = 0; i < (size_t)stride * (size_t)height; i++) data[i] = (uint8_t)next_u32();
    sh_plane plane = {data, width, height, stride};
    int32_t *fx = malloc(sizeof(int32_t) * (size_t)count), *fy = malloc(sizeof(int32_t) * (size_t)count);
    const size_t bytes = (size_t)count * (size_t)channels + 1;
    uint8_t *simd = malloc(bytes), *ref = malloc(bytes);
    assert_true(fx && fy && simd && ref);
    for (int k = 0; k < count; k++) {
        /* positions in [-spread, size + spread) px with any 16-bit fraction; runs of inside
         * positions so that the blocks take their fast path often */
        int64_t rx = (int64_t)(next_u32() % (uint32_t)((width + 2 * spread) << 8)) - ((int64_t)spread << 8);
        int64_t ry = (int64_t)(next_u32() % (uint32_t)((height + 2 * spread) << 8)) - ((int64_t)spread << 8);
        fx[k] = (int32_t)(rx * 256 + (next_u32() & 255));
        fy[k] = (int32_t)(ry * 256 + (next_u32() & 255));
    }
    for (int path = 0; path < PATHS; path++) {
        if (!use_path(path)) continue;
        for (int start = 0; start < starts; start++) {
            int n = count - start;
            memset(simd, 0xa5, bytes);
            memset(ref, 0xa5, bytes);
            warp_sample_row(&plane, channels, 7, simd, fx + start, fy + start, n);
            portable(&plane, 7, ref, fx + start, fy + start, n);
            for (size_t k = 0; k < bytes; k++) {
                if (simd[k] != ref[k])
                    fail_msg("%d channel(s), %dx%d stride %d, start %d, %s: byte %zu (pixel %zu): simd %u, "
                             "portable %u", channels, width, height, stride, start, path_names[path], k,
                             k / (size_t)channels, simd[k], ref[k]);
            }
        }
    }
    warp_sample_path(PATHS - 1);
    free(data); free(fx); free(fy); free(simd); free(ref);
}

static void test_inside(void **state)
{
    (void)state;
    compare_on(3, 640, 480, 640 * 3, 200000, 0);
    compare_on(3, 97, 61, 97 * 3 + 5, 50000, 0);
}

static void test_edges_and_outside(void **state)
{
    (void)state;
    compare_on(3, 64, 48, 64 * 3, 100000, 4);
    compare_on(3, 5, 4, 16, 20000, 3);
    compare_on(3, 2, 2, 6, 5000, 2);
    compare_on(3, 1, 1, 3, 1000, 1);
}

static void test_wide_stride(void **state)
{
    (void)state;
    /* stride > 32767: the 4-pixel blocks are skipped, the tail loop does it all */
    compare_on(3, 11000, 3, 33003, 30000, 2);
}

static void extreme_positions(int channels)
{
    const portable_fn portable = channels == 3 ? warp_sample_row_rgb_portable : warp_sample_row_gray_portable;
    uint8_t data[8 * 3 * 8];
    for (size_t i = 0; i < sizeof data; i++) data[i] = (uint8_t)(i * 37);
    sh_plane plane = {data, 8, 8, 8 * channels};
    const int32_t v[] = {INT32_MIN, INT32_MIN + 1, -1, 0, 1, 65535, 65536, (6 << 16) + 65535,
                         7 << 16, (7 << 16) - 1, (7 << 16) + 1, 5 << 16, (4 << 16) + 32768,
                         INT32_MAX - 1, INT32_MAX};
    enum { N = sizeof v / sizeof v[0] };
    int32_t fx[N * N], fy[N * N];
    for (int i = 0; i < N; i++)
        for (int j = 0; j < N; j++) { fx[i * N + j] = v[i]; fy[i * N + j] = v[j]; }
    uint8_t simd[N * N * 3], ref[N * N * 3];
    portable(&plane, 0, ref, fx, fy, N * N);
    for (int path = 0; path < PATHS; path++) {
        if (!use_path(path)) continue;
        warp_sample_row(&plane, channels, 0, simd, fx, fy, N * N);
        assert_memory_equal(simd, ref, (size_t)(N * N * channels));
    }
    warp_sample_path(PATHS - 1);
}

static void test_extreme_positions(void **state)
{
    (void)state;
    extreme_positions(3);
    extreme_positions(1);
}

/* One channel: the 8-pixel blocks inside, across the edges, far outside; odd strides, the
 * plane's last column and row (a block's taps there are the row's last two bytes), planes too
 * small for the blocks or too wide (stride > 32767: no blocks), the tallest plane there is
 * (SH_IMAGE_MAX_SIZE rows). */
static void test_gray(void **state)
{
    (void)state;
    compare_on(1, 640, 480, 640, 200000, 0);
    compare_on(1, 97, 61, 101, 50000, 0);
    compare_on(1, 1920, 8, 1920, 50000, 0);
    compare_on(1, 64, 48, 64, 100000, 4);
    compare_on(1, 64, 48, 67, 100000, 40);
    compare_on(1, 5, 4, 7, 20000, 3);
    compare_on(1, 2, 2, 2, 5000, 2);
    compare_on(1, 2, 1, 3, 2000, 1);
    compare_on(1, 1, 1, 1, 1000, 1);
    compare_on(1, 3, SH_IMAGE_MAX_SIZE, 3, 30000, 2);
    compare_on(1, SH_IMAGE_MAX_SIZE, 3, 33001, 30000, 2);
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

/* One channel: one rounding of the exact sum, on numbers worked by hand. */
static void test_gray_portable_by_hand(void **state)
{
    (void)state;
    /* 3x3, taps 10 200 / 30 40 at (0.25, 0.75): wx = 32, wy = 96; top = 10 * 96 + 200 * 32 =
     * 7360, bottom = 30 * 96 + 40 * 32 = 4160; (7360 * 32 + 4160 * 96 + 8192) >> 14 = 39
     * (exact bilinear 38.75) */
    uint8_t b[9] = {10, 200, 0, 30, 40, 0, 0, 0, 0};
    sh_plane pb = {b, 3, 3, 3};
    int32_t fx = 1 << 14, fy = 3 << 14;
    uint8_t out;
    warp_sample_row_gray_portable(&pb, 0, &out, &fx, &fy, 1);
    assert_int_equal(out, 39);
    /* 2x2 10 200 / 30 40 at (1, 0.75), the last column (checked path): 200 * 128 * 32 +
     * 40 * 128 * 96 + 8192 >> 14 = 80 (exact 80) */
    sh_plane pa = {b, 2, 2, 3};
    fx = 1 << 16;
    warp_sample_row_gray_portable(&pa, 0, &out, &fx, &fy, 1);
    assert_int_equal(out, 80);
    /* taps 0 255 / 255 255 at (0.5, 0.5): (255 * 64) * 64 + (255 * 128) * 64 = 3133440,
     * + 8192 >> 14 = 191 (exact 191.25) */
    uint8_t c[9] = {0, 255, 0, 255, 255, 0, 0, 0, 0};
    sh_plane pc = {c, 3, 3, 3};
    fx = fy = 1 << 15;
    warp_sample_row_gray_portable(&pc, 0, &out, &fx, &fy, 1);
    assert_int_equal(out, 191);
}

int main(void)
{
    /* which of the paths this CPU runs (the others pass unchecked here; AVX-512 is not in
     * Debian 12's qemu either) */
    for (int path = 0; path < PATHS; path++)
        print_message("sampler path %s: %s\n", path_names[path], use_path(path) ? "compared" : "not on this CPU");
    warp_sample_path(PATHS - 1);
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_portable_by_hand),
        cmocka_unit_test(test_inside),
        cmocka_unit_test(test_edges_and_outside),
        cmocka_unit_test(test_wide_stride),
        cmocka_unit_test(test_extreme_positions),
        cmocka_unit_test(test_gray_portable_by_hand),
        cmocka_unit_test(test_gray),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
