/* The tracker's two window loops, where its time goes: sampling the previous frame's window
 * (once per point and level) and comparing the next frame's with it (once per step); and the
 * error measure (once per point and search). Each has a portable C definition and an 8-lane
 * version for SSE2 (part of x86-64) and, but the error measure, NEON (part of AArch64); the two
 * comparisons also a 32-lane AVX-512 one, chosen at run time. The affine windows' sampling
 * through a matrix (once per point and frame) has a portable definition and a 16-lane AVX-512
 * one, which gathers its samples. All compute the same integers:
 * every product and sum is exact, so the SIMD and the portable results are equal bit for bit
 * (test_flow_simd), and make bench (bench_flow, bench_landmarks) shows what the lanes buy.
 *
 * Bounds that keep the lanes' 32-bit sums exact: a pixel is at most 255 and a gradient at most
 * 16 * 255 = 4080 in magnitude, a bilinear weight at most 2^14, so one sample's weighted sum is
 * below 2^27 and fits; a difference d is at most 32 * 255 = 8160, and one row's sum of d * g
 * over at most FLOW_WROW(63) = 64 lanes is at most 64 * 8160 * 4080 < 2^31 (and of g * g less).
 * Rows are added into 64-bit totals. The windows' gradients (flow_window_gradients) are made
 * here too, once per window, in the portable C every sampler shares.
 *
 * Over 600 lines: each loop's portable definition and its SSE2, NEON and AVX-512 versions side
 * by side, so that a change to one is made beside those it must match bit for bit. */
#include "flow_internal.h"

#include <string.h>

#define W_BITS 14
#define DESCALE(x, n) (((x) + (1 << ((n)-1))) >> (n))

void flow_window_gradients(const flow_level *l, int ix, int iy, int win, int16_t *gx, int16_t *gy)
{
    const int gs = FLOW_GROW(win), s = l->stride;
    /* the window's columns [ix, ix + win] that lie in the level: [x0, x1) of the rows' */
    const int x0 = ix < 0 ? (-ix < win + 1 ? -ix : win + 1) : 0;
    int x1 = l->width - ix < win + 1 ? l->width - ix : win + 1;
    x1 = x1 > x0 ? x1 : x0;
    for (int y = 0; y <= win; y++) {
        int16_t *restrict rx = gx + y * gs, *restrict ry = gy + y * gs;
        memset(rx, 0, sizeof *rx * (size_t)gs);
        memset(ry, 0, sizeof *ry * (size_t)gs);
        if (iy + y < 0 || iy + y >= l->height) continue;
        const uint8_t *restrict a = l->img + (ptrdiff_t)(iy + y - 1) * s + ix;
        const uint8_t *restrict b = a + s, *restrict c = b + s;
        for (int x = x0; x < x1; x++) {
            rx[x] = (int16_t)(3 * (a[x + 1] - a[x - 1] + c[x + 1] - c[x - 1]) + 10 * (b[x + 1] - b[x - 1]));
            ry[x] = (int16_t)(3 * (c[x - 1] - a[x - 1] + c[x + 1] - a[x + 1]) + 10 * (c[x] - a[x]));
        }
    }
}

void flow_window_prev_portable(const flow_level *l, int ix, int iy, const int w[4], int win,
                               int16_t *I, int16_t *gx, int16_t *gy, int64_t a[3])
{
    const int wr = FLOW_WROW(win), s = l->stride, gs = FLOW_GROW(win);
    int16_t lgx[(SH_FLOW_MAX_WIN + 1) * FLOW_GROW(SH_FLOW_MAX_WIN)], lgy[sizeof lgx / sizeof *lgx];
    flow_window_gradients(l, ix, iy, win, lgx, lgy);
    int64_t s11 = 0, s12 = 0, s22 = 0;
    for (int y = 0; y < win; y++) {
        const uint8_t *p = l->img + (ptrdiff_t)(iy + y) * s + ix;
        const int16_t *dx = lgx + y * gs, *dy = lgy + y * gs;
        int16_t *ri = I + y * wr, *rx = gx + y * wr, *ry = gy + y * wr;
        for (int x = 0; x < win; x++) {
            int v = p[x] * w[0] + p[x + 1] * w[1] + p[x + s] * w[2] + p[x + s + 1] * w[3];
            int vx = dx[x] * w[0] + dx[x + 1] * w[1] + dx[x + gs] * w[2] + dx[x + gs + 1] * w[3];
            int vy = dy[x] * w[0] + dy[x + 1] * w[1] + dy[x + gs] * w[2] + dy[x + gs + 1] * w[3];
            vx = DESCALE(vx, W_BITS);
            vy = DESCALE(vy, W_BITS);
            ri[x] = (int16_t)DESCALE(v, W_BITS - 5);
            rx[x] = (int16_t)vx;
            ry[x] = (int16_t)vy;
            s11 += vx * vx;
            s12 += vx * vy;
            s22 += vy * vy;
        }
        for (int x = win; x < wr; x++) ri[x] = rx[x] = ry[x] = 0;
    }
    a[0] = s11;
    a[1] = s12;
    a[2] = s22;
}

void flow_window_mismatch_portable(const flow_level *l, int ix, int iy, const int w[4], int win,
                                   const int16_t *I, const int16_t *gx, const int16_t *gy,
                                   int64_t b[2])
{
    const int wr = FLOW_WROW(win), s = l->stride;
    int64_t s1 = 0, s2 = 0;
    for (int y = 0; y < win; y++) {
        const uint8_t *p = l->img + (ptrdiff_t)(iy + y) * s + ix;
        const int16_t *ri = I + y * wr, *rx = gx + y * wr, *ry = gy + y * wr;
        for (int x = 0; x < win; x++) {
            int v = p[x] * w[0] + p[x + 1] * w[1] + p[x + s] * w[2] + p[x + s + 1] * w[3];
            int d = DESCALE(v, W_BITS - 5) - ri[x];
            s1 += d * rx[x];
            s2 += d * ry[x];
        }
    }
    b[0] = s1;
    b[1] = s2;
}

int64_t flow_window_abs_mismatch_portable(const flow_level *l, int ix, int iy, const int w[4], int win,
                                          const int16_t *I)
{
    const int wr = FLOW_WROW(win), s = l->stride;
    int64_t sa = 0;
    for (int y = 0; y < win; y++) {
        const uint8_t *p = l->img + (ptrdiff_t)(iy + y) * s + ix;
        for (int x = 0; x < win; x++) {
            int v = p[x] * w[0] + p[x + 1] * w[1] + p[x + s] * w[2] + p[x + s + 1] * w[3];
            int d = DESCALE(v, W_BITS - 5) - I[y * wr + x];
            sa += d < 0 ? -d : d;
        }
    }
    return sa;
}

/* The warped template's side: the window and a pixel each side, for the gradients of its border */
#define WARP_T (SH_FLOW_MAX_WIN + 2)

/* The positions step in 16.16 fixed point from the template's corner, and each sample's
 * bilinear weights are its fractions rounded to 1/128 px (7 bits each way, 14 bits together, as
 * the other samplers' weights): integers only, so every architecture gets the same template,
 * within 1/256 px of where the matrix puts each sample. The template is sampled a pixel wider on
 * each side than the window, so that the gradients of its border pixels are its own; they are
 * those of the 8-bit image in Scharr units, as the pyramid's (the template is in 1/32 grey
 * levels: the Scharr sum descaled by 5 bits). */
void flow_window_prev_warped_portable(const flow_level *l, int pad, const int32_t start[2], const int32_t col[2],
                                      const int32_t row[2], int win, int16_t *I, int16_t *gx, int16_t *gy,
                                      int64_t a[3])
{
    const int side = win + 2, wr = FLOW_WROW(win), st = l->stride;
    int16_t t[WARP_T * WARP_T];
    int32_t rx = start[0], ry = start[1];
    for (int y = 0; y < side; y++, rx += row[0], ry += row[1]) {
        int32_t X = rx, Y = ry;
        for (int x = 0; x < side; x++, X += col[0], Y += col[1]) {
            int fx = ((X & 0xffff) + 256) >> 9, fy = ((Y & 0xffff) + 256) >> 9; /* 0..128 */
            const uint8_t *q = l->img + (ptrdiff_t)((Y >> 16) - pad) * st + ((X >> 16) - pad);
            int v = (q[0] * (128 - fx) + q[1] * fx) * (128 - fy) + (q[st] * (128 - fx) + q[st + 1] * fx) * fy;
            t[y * WARP_T + x] = (int16_t)DESCALE(v, W_BITS - 5);
        }
    }
    int64_t s11 = 0, s12 = 0, s22 = 0;
    for (int y = 0; y < win; y++) {
        const int16_t *u = t + y * WARP_T, *m = u + WARP_T, *c = m + WARP_T;
        for (int x = 0; x < win; x++) {
            int dx = 3 * (u[x + 2] - u[x] + c[x + 2] - c[x]) + 10 * (m[x + 2] - m[x]);
            int dy = 3 * (c[x] - u[x] + c[x + 2] - u[x + 2]) + 10 * (c[x + 1] - u[x + 1]);
            dx = DESCALE(dx, 5);
            dy = DESCALE(dy, 5);
            I[y * wr + x] = m[x + 1];
            gx[y * wr + x] = (int16_t)dx;
            gy[y * wr + x] = (int16_t)dy;
            s11 += dx * dx;
            s12 += dx * dy;
            s22 += dy * dy;
        }
        for (int x = win; x < wr; x++) I[y * wr + x] = gx[y * wr + x] = gy[y * wr + x] = 0;
    }
    a[0] = s11, a[1] = s12, a[2] = s22;
}

#if defined(__SSE2__)
#include <emmintrin.h>

static int64_t hsum32(__m128i v)
{
    int32_t t[4];
    _mm_storeu_si128((__m128i *)t, v);
    return (int64_t)t[0] + t[1] + t[2] + t[3];
}

/* 8 bilinear samples of 16-bit values at a (row r0, columns x..x+7) and the row below,
 * weights as pairs (w0, w1) and (w2, w3) in 16-bit lanes: madd multiplies and adds each pair.
 * Returns the two halves' 32-bit sums, not yet descaled. */
static inline void bilinear8(__m128i a, __m128i b, __m128i c, __m128i d, __m128i w01,
                             __m128i w23, __m128i *lo, __m128i *hi)
{
    *lo = _mm_add_epi32(_mm_madd_epi16(_mm_unpacklo_epi16(a, b), w01),
                        _mm_madd_epi16(_mm_unpacklo_epi16(c, d), w23));
    *hi = _mm_add_epi32(_mm_madd_epi16(_mm_unpackhi_epi16(a, b), w01),
                        _mm_madd_epi16(_mm_unpackhi_epi16(c, d), w23));
}

static inline __m128i load8u(const uint8_t *p)
{
    return _mm_unpacklo_epi8(_mm_loadl_epi64((const __m128i *)p), _mm_setzero_si128());
}

static inline __m128i load8s(const int16_t *p)
{
    return _mm_loadu_si128((const __m128i *)p);
}

/* All ones in the first `left` 16-bit lanes (all 8 when left >= 8), zero in the others */
static inline __m128i lanes_kept(int left)
{
    return left >= 8 ? _mm_set1_epi16(-1)
                     : _mm_cmpgt_epi16(_mm_set1_epi16((short)left), _mm_setr_epi16(0, 1, 2, 3, 4, 5, 6, 7));
}

/* (v + 2^(n-1)) >> n on both halves, packed back to 16 bits (the values fit: no saturation) */
static inline __m128i descale_pack(__m128i lo, __m128i hi, int n)
{
    const __m128i r = _mm_set1_epi32(1 << (n - 1));
    return _mm_packs_epi32(_mm_sra_epi32(_mm_add_epi32(lo, r), _mm_cvtsi32_si128(n)),
                           _mm_sra_epi32(_mm_add_epi32(hi, r), _mm_cvtsi32_si128(n)));
}

void flow_window_prev(const flow_level *l, int ix, int iy, const int w[4], int win, int16_t *I,
                      int16_t *gx, int16_t *gy, int64_t a[3])
{
    const int wr = FLOW_WROW(win), s = l->stride, gs = FLOW_GROW(win);
    const __m128i w01 = _mm_set1_epi32((int)((uint32_t)w[1] << 16 | (uint32_t)w[0]));
    const __m128i w23 = _mm_set1_epi32((int)((uint32_t)w[3] << 16 | (uint32_t)w[2]));
    int16_t lgx[(SH_FLOW_MAX_WIN + 1) * FLOW_GROW(SH_FLOW_MAX_WIN)], lgy[sizeof lgx / sizeof *lgx];
    flow_window_gradients(l, ix, iy, win, lgx, lgy);
    int64_t s11 = 0, s12 = 0, s22 = 0;
    for (int y = 0; y < win; y++) {
        const uint8_t *p = l->img + (ptrdiff_t)(iy + y) * s + ix;
        const int16_t *dx = lgx + y * gs, *dy = lgy + y * gs;
        int16_t *ri = I + y * wr, *rx = gx + y * wr, *ry = gy + y * wr;
        __m128i q11 = _mm_setzero_si128(), q12 = q11, q22 = q11;
        for (int x = 0; x < wr; x += 8) {
            __m128i lo, hi;
            /* lanes past the side: zero, so that they add nothing to any sum */
            const __m128i keep = lanes_kept(win - x);
            bilinear8(load8u(p + x), load8u(p + x + 1), load8u(p + x + s), load8u(p + x + s + 1),
                      w01, w23, &lo, &hi);
            __m128i vi = _mm_and_si128(descale_pack(lo, hi, W_BITS - 5), keep);
            bilinear8(load8s(dx + x), load8s(dx + x + 1), load8s(dx + x + gs),
                      load8s(dx + x + gs + 1), w01, w23, &lo, &hi);
            __m128i vx = _mm_and_si128(descale_pack(lo, hi, W_BITS), keep);
            bilinear8(load8s(dy + x), load8s(dy + x + 1), load8s(dy + x + gs),
                      load8s(dy + x + gs + 1), w01, w23, &lo, &hi);
            __m128i vy = _mm_and_si128(descale_pack(lo, hi, W_BITS), keep);
            _mm_storeu_si128((__m128i *)(ri + x), vi);
            _mm_storeu_si128((__m128i *)(rx + x), vx);
            _mm_storeu_si128((__m128i *)(ry + x), vy);
            q11 = _mm_add_epi32(q11, _mm_madd_epi16(vx, vx));
            q12 = _mm_add_epi32(q12, _mm_madd_epi16(vx, vy));
            q22 = _mm_add_epi32(q22, _mm_madd_epi16(vy, vy));
        }
        s11 += hsum32(q11);
        s12 += hsum32(q12);
        s22 += hsum32(q22);
    }
    a[0] = s11;
    a[1] = s12;
    a[2] = s22;
}

void flow_window_mismatch_sse2(const flow_level *l, int ix, int iy, const int w[4], int win,
                               const int16_t *I, const int16_t *gx, const int16_t *gy, int64_t b[2])
{
    const int wr = FLOW_WROW(win), s = l->stride;
    const __m128i w01 = _mm_set1_epi32((int)((uint32_t)w[1] << 16 | (uint32_t)w[0]));
    const __m128i w23 = _mm_set1_epi32((int)((uint32_t)w[3] << 16 | (uint32_t)w[2]));
    int64_t s1 = 0, s2 = 0;
    for (int y = 0; y < win; y++) {
        const uint8_t *p = l->img + (ptrdiff_t)(iy + y) * s + ix;
        const int16_t *ri = I + y * wr, *rx = gx + y * wr, *ry = gy + y * wr;
        __m128i q1 = _mm_setzero_si128(), q2 = q1;
        for (int x = 0; x < wr; x += 8) {
            __m128i lo, hi;
            bilinear8(load8u(p + x), load8u(p + x + 1), load8u(p + x + s), load8u(p + x + s + 1),
                      w01, w23, &lo, &hi);
            /* past the side the gradients are zero: d * 0 adds nothing */
            __m128i d = _mm_sub_epi16(descale_pack(lo, hi, W_BITS - 5), load8s(ri + x));
            q1 = _mm_add_epi32(q1, _mm_madd_epi16(d, load8s(rx + x)));
            q2 = _mm_add_epi32(q2, _mm_madd_epi16(d, load8s(ry + x)));
        }
        s1 += hsum32(q1);
        s2 += hsum32(q2);
    }
    b[0] = s1;
    b[1] = s2;
}

/* |d| summed: past the side the template is zero but the samples are not, so those lanes are
 * masked off; a row's 32-bit sum is at most 64 * 8160. */
int64_t flow_window_abs_mismatch_sse2(const flow_level *l, int ix, int iy, const int w[4], int win,
                                      const int16_t *I)
{
    const int wr = FLOW_WROW(win), s = l->stride;
    const __m128i w01 = _mm_set1_epi32((int)((uint32_t)w[1] << 16 | (uint32_t)w[0]));
    const __m128i w23 = _mm_set1_epi32((int)((uint32_t)w[3] << 16 | (uint32_t)w[2]));
    const __m128i one = _mm_set1_epi16(1), zero = _mm_setzero_si128();
    int64_t sa = 0;
    for (int y = 0; y < win; y++) {
        const uint8_t *p = l->img + (ptrdiff_t)(iy + y) * s + ix;
        const int16_t *ri = I + y * wr;
        __m128i q = zero;
        for (int x = 0; x < wr; x += 8) {
            __m128i lo, hi;
            const __m128i keep = lanes_kept(win - x);
            bilinear8(load8u(p + x), load8u(p + x + 1), load8u(p + x + s), load8u(p + x + s + 1),
                      w01, w23, &lo, &hi);
            __m128i d =
                _mm_and_si128(_mm_sub_epi16(descale_pack(lo, hi, W_BITS - 5), load8s(ri + x)), keep);
            d = _mm_max_epi16(d, _mm_sub_epi16(zero, d));
            q = _mm_add_epi32(q, _mm_madd_epi16(d, one));
        }
        sa += hsum32(q);
    }
    return sa;
}

#if defined(__GNUC__)
#include <immintrin.h>

int flow_window_avx512(void)
{
    return __builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512bw");
}

/* 32 bilinear samples of row p (and the row s below it) in 1/32 grey levels, lanes outside k
 * zero (the loads masked: nothing past them is read). */
__attribute__((target("avx512f,avx512bw"))) static inline __m512i
sample32(const uint8_t *p, int s, __mmask32 k, __m512i w01, __m512i w23)
{
#define LOAD32U(q) _mm512_cvtepu8_epi16(_mm512_castsi512_si256(_mm512_maskz_loadu_epi8((__mmask64)k, (q))))
    const __m512i a = LOAD32U(p), b = LOAD32U(p + 1), c = LOAD32U(p + s), d = LOAD32U(p + s + 1);
#undef LOAD32U
    const __m512i rnd = _mm512_set1_epi32(1 << (W_BITS - 6));
    __m512i lo = _mm512_add_epi32(_mm512_madd_epi16(_mm512_unpacklo_epi16(a, b), w01),
                                  _mm512_madd_epi16(_mm512_unpacklo_epi16(c, d), w23));
    __m512i hi = _mm512_add_epi32(_mm512_madd_epi16(_mm512_unpackhi_epi16(a, b), w01),
                                  _mm512_madd_epi16(_mm512_unpackhi_epi16(c, d), w23));
    lo = _mm512_srai_epi32(_mm512_add_epi32(lo, rnd), W_BITS - 5);
    hi = _mm512_srai_epi32(_mm512_add_epi32(hi, rnd), W_BITS - 5);
    return _mm512_packs_epi32(lo, hi);
}

/* |d| summed, 32 lanes a step; a lane's 32-bit sum is at most 2 * 8160 a step, 126 steps at most */
__attribute__((target("avx512f,avx512bw"))) int64_t
flow_window_abs_mismatch_avx512(const flow_level *l, int ix, int iy, const int w[4], int win, const int16_t *I)
{
    const int wr = FLOW_WROW(win), s = l->stride;
    const __m512i w01 = _mm512_set1_epi32((int)((uint32_t)w[1] << 16 | (uint32_t)w[0]));
    const __m512i w23 = _mm512_set1_epi32((int)((uint32_t)w[3] << 16 | (uint32_t)w[2]));
    const __m512i one = _mm512_set1_epi16(1);
    __m512i q = _mm512_setzero_si512();
    for (int y = 0; y < win; y++) {
        const uint8_t *p = l->img + (ptrdiff_t)(iy + y) * s + ix;
        const int16_t *ri = I + y * wr;
        for (int x = 0; x < win; x += 32) {
            const int left = win - x;
            const __mmask32 k = left >= 32 ? 0xffffffffu : (1u << left) - 1;
            const __m512i d =
                _mm512_sub_epi16(sample32(p + x, s, k, w01, w23), _mm512_maskz_loadu_epi16(k, ri + x));
            q = _mm512_add_epi32(q, _mm512_madd_epi16(_mm512_abs_epi16(d), one));
        }
    }
    return _mm512_reduce_add_epi32(q);
}

/* flow_window_prev_warped_portable on 16 lanes of 32 bits: a template row's positions, weights
 * and offsets side by side, its 2x2 neighbours gathered as two 32-bit words a sample (the bytes at
 * the sample and the row below; the two bytes past each are read and ignored: they lie in the
 * pad, the next row or the plane's FLOW_SLACK), then the Scharr sums and the window's values.
 * Every product is the portable one's, exact in 32 bits (a sample's weighted sum is at most
 * 255 * 2^14; a gradient at most 4080, so a lane adds at most 4 * 4080^2 a row); the sums are
 * added into 64 bits a row. */
__attribute__((target("avx512f,avx512bw"))) void
flow_window_prev_warped_avx512(const flow_level *l, int pad, const int32_t start[2], const int32_t col[2],
                               const int32_t row[2], int win, int16_t *I, int16_t *gx, int16_t *gy, int64_t a[3])
{
    const int side = win + 2, wr = FLOW_WROW(win), st = l->stride;
    int16_t t[WARP_T * WARP_T];
    const __m512i lane = _mm512_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
    const __m512i lo16 = _mm512_set1_epi32(0xffff), byte = _mm512_set1_epi32(0xff), w128 = _mm512_set1_epi32(128);
    const __m512i half = _mm512_set1_epi32(256), padv = _mm512_set1_epi32(pad), stv = _mm512_set1_epi32(st);
    const __m512i cx = _mm512_set1_epi32(col[0]), cy = _mm512_set1_epi32(col[1]);
    {
        /* the samples' box, its rows fetched at once: the gathers below would wait for them one
         * row at a time */
        int32_t xs[4] = {start[0], start[0] + (side - 1) * col[0], start[0] + (side - 1) * row[0],
                         start[0] + (side - 1) * (col[0] + row[0])};
        int32_t ys[4] = {start[1], start[1] + (side - 1) * col[1], start[1] + (side - 1) * row[1],
                         start[1] + (side - 1) * (col[1] + row[1])};
        int32_t x0 = xs[0], x1 = xs[0], y0 = ys[0], y1 = ys[0];
        for (int c = 1; c < 4; c++) {
            x0 = xs[c] < x0 ? xs[c] : x0, x1 = xs[c] > x1 ? xs[c] : x1;
            y0 = ys[c] < y0 ? ys[c] : y0, y1 = ys[c] > y1 ? ys[c] : y1;
        }
        const uint8_t *b = l->img + (ptrdiff_t)((y0 >> 16) - pad) * st + ((x0 >> 16) - pad);
        const int cols = (x1 >> 16) - (x0 >> 16) + 2, rows = (y1 >> 16) - (y0 >> 16) + 2;
        for (int r = 0; r < rows; r++) {
            for (int c = 0; c < cols; c += 64) _mm_prefetch((const char *)(b + (ptrdiff_t)r * st + c), _MM_HINT_T0);
            _mm_prefetch((const char *)(b + (ptrdiff_t)r * st + cols - 1), _MM_HINT_T0);
        }
    }
    int32_t rx = start[0], ry = start[1];
    for (int y = 0; y < side; y++, rx += row[0], ry += row[1]) {
        for (int x = 0; x < side; x += 16) {
            const int left = side - x;
            const __mmask16 k = left >= 16 ? 0xffff : (__mmask16)((1u << left) - 1);
            const __m512i n = _mm512_add_epi32(lane, _mm512_set1_epi32(x));
            const __m512i X = _mm512_add_epi32(_mm512_set1_epi32(rx), _mm512_mullo_epi32(n, cx));
            const __m512i Y = _mm512_add_epi32(_mm512_set1_epi32(ry), _mm512_mullo_epi32(n, cy));
            const __m512i fx = _mm512_srli_epi32(_mm512_add_epi32(_mm512_and_si512(X, lo16), half), 9);
            const __m512i fy = _mm512_srli_epi32(_mm512_add_epi32(_mm512_and_si512(Y, lo16), half), 9);
            const __m512i off = _mm512_add_epi32(_mm512_mullo_epi32(_mm512_sub_epi32(_mm512_srai_epi32(Y, 16), padv), stv),
                                                 _mm512_sub_epi32(_mm512_srai_epi32(X, 16), padv));
            const __m512i g0 = _mm512_mask_i32gather_epi32(_mm512_setzero_si512(), k, off, l->img, 1);
            const __m512i g1 = _mm512_mask_i32gather_epi32(_mm512_setzero_si512(), k, _mm512_add_epi32(off, stv), l->img, 1);
            const __m512i gx0 = _mm512_sub_epi32(w128, fx), gy0 = _mm512_sub_epi32(w128, fy);
            const __m512i top = _mm512_add_epi32(_mm512_mullo_epi32(_mm512_and_si512(g0, byte), gx0),
                                                 _mm512_mullo_epi32(_mm512_and_si512(_mm512_srli_epi32(g0, 8), byte), fx));
            const __m512i bot = _mm512_add_epi32(_mm512_mullo_epi32(_mm512_and_si512(g1, byte), gx0),
                                                 _mm512_mullo_epi32(_mm512_and_si512(_mm512_srli_epi32(g1, 8), byte), fx));
            __m512i v = _mm512_add_epi32(_mm512_mullo_epi32(top, gy0), _mm512_mullo_epi32(bot, fy));
            v = _mm512_srai_epi32(_mm512_add_epi32(v, half), W_BITS - 5);
            _mm512_mask_storeu_epi16(t + y * WARP_T + x, (__mmask32)k, _mm512_castsi256_si512(_mm512_cvtepi32_epi16(v)));
        }
    }
#define LOAD16(p) _mm512_cvtepi16_epi32(_mm512_castsi512_si256(_mm512_maskz_loadu_epi16((__mmask32)k, (p))))
    const __m512i r5 = _mm512_set1_epi32(16), three = _mm512_set1_epi32(3), ten = _mm512_set1_epi32(10);
    int64_t s11 = 0, s12 = 0, s22 = 0;
    for (int y = 0; y < win; y++) {
        const int16_t *u = t + y * WARP_T, *m = u + WARP_T, *c = m + WARP_T;
        __m512i q11 = _mm512_setzero_si512(), q12 = q11, q22 = q11;
        for (int x = 0; x < wr; x += 16) {
            const int left = win - x, room = wr - x;
            /* lanes past the side: every load zero, so every value stored there is zero */
            const __mmask16 k = left >= 16 ? 0xffff : left <= 0 ? 0 : (__mmask16)((1u << left) - 1);
            const __mmask16 ks = room >= 16 ? 0xffff : (__mmask16)((1u << room) - 1);
            const __m512i u0 = LOAD16(u + x), u1 = LOAD16(u + x + 1), u2 = LOAD16(u + x + 2);
            const __m512i m0 = LOAD16(m + x), m1 = LOAD16(m + x + 1), m2 = LOAD16(m + x + 2);
            const __m512i c0 = LOAD16(c + x), c1 = LOAD16(c + x + 1), c2 = LOAD16(c + x + 2);
            __m512i dx = _mm512_add_epi32(
                _mm512_mullo_epi32(three, _mm512_add_epi32(_mm512_sub_epi32(u2, u0), _mm512_sub_epi32(c2, c0))),
                _mm512_mullo_epi32(ten, _mm512_sub_epi32(m2, m0)));
            __m512i dy = _mm512_add_epi32(
                _mm512_mullo_epi32(three, _mm512_add_epi32(_mm512_sub_epi32(c0, u0), _mm512_sub_epi32(c2, u2))),
                _mm512_mullo_epi32(ten, _mm512_sub_epi32(c1, u1)));
            dx = _mm512_srai_epi32(_mm512_add_epi32(dx, r5), 5);
            dy = _mm512_srai_epi32(_mm512_add_epi32(dy, r5), 5);
            _mm512_mask_storeu_epi16(I + y * wr + x, (__mmask32)ks, _mm512_castsi256_si512(_mm512_cvtepi32_epi16(m1)));
            _mm512_mask_storeu_epi16(gx + y * wr + x, (__mmask32)ks, _mm512_castsi256_si512(_mm512_cvtepi32_epi16(dx)));
            _mm512_mask_storeu_epi16(gy + y * wr + x, (__mmask32)ks, _mm512_castsi256_si512(_mm512_cvtepi32_epi16(dy)));
            q11 = _mm512_add_epi32(q11, _mm512_mullo_epi32(dx, dx));
            q12 = _mm512_add_epi32(q12, _mm512_mullo_epi32(dx, dy));
            q22 = _mm512_add_epi32(q22, _mm512_mullo_epi32(dy, dy));
        }
        s11 += _mm512_reduce_add_epi32(q11);
        s12 += _mm512_reduce_add_epi32(q12);
        s22 += _mm512_reduce_add_epi32(q22);
    }
#undef LOAD16
    a[0] = s11, a[1] = s12, a[2] = s22;
}

/* A window row, up to 32 columns, a step: the SSE2 loop's arithmetic on 32 lanes (unpack and pack
 * stay within each 128-bit lane, so the lanes come back in order). The loads are masked to the
 * window's columns: past the side every sample, template value and gradient is zero, and nothing
 * past the window's last column (and its bilinear neighbour) is read. A lane's 32-bit sum grows by
 * at most 2 * 8160 * 4080 a step (one madd: two products), so 32 steps stay below 2^31; they are
 * added into 64-bit totals every 32 steps and at the end. */
__attribute__((target("avx512f,avx512bw"))) void
flow_window_mismatch_avx512(const flow_level *l, int ix, int iy, const int w[4], int win, const int16_t *I,
                            const int16_t *gx, const int16_t *gy, int64_t b[2])
{
    const int wr = FLOW_WROW(win), s = l->stride;
    const __m512i w01 = _mm512_set1_epi32((int)((uint32_t)w[1] << 16 | (uint32_t)w[0]));
    const __m512i w23 = _mm512_set1_epi32((int)((uint32_t)w[3] << 16 | (uint32_t)w[2]));
    __m512i q1 = _mm512_setzero_si512(), q2 = q1, t1 = q1, t2 = q1;
    int steps = 0;
    for (int y = 0; y < win; y++) {
        const uint8_t *p = l->img + (ptrdiff_t)(iy + y) * s + ix;
        const int16_t *ri = I + y * wr, *rx = gx + y * wr, *ry = gy + y * wr;
        for (int x = 0; x < win; x += 32) {
            const int left = win - x;
            const __mmask32 k = left >= 32 ? 0xffffffffu : (1u << left) - 1;
            const __m512i diff =
                _mm512_sub_epi16(sample32(p + x, s, k, w01, w23), _mm512_maskz_loadu_epi16(k, ri + x));
            q1 = _mm512_add_epi32(q1, _mm512_madd_epi16(diff, _mm512_maskz_loadu_epi16(k, rx + x)));
            q2 = _mm512_add_epi32(q2, _mm512_madd_epi16(diff, _mm512_maskz_loadu_epi16(k, ry + x)));
            if (++steps == 32 || (y == win - 1 && x + 32 >= win)) {
                t1 = _mm512_add_epi64(t1, _mm512_cvtepi32_epi64(_mm512_castsi512_si256(q1)));
                t1 = _mm512_add_epi64(t1, _mm512_cvtepi32_epi64(_mm512_extracti64x4_epi64(q1, 1)));
                t2 = _mm512_add_epi64(t2, _mm512_cvtepi32_epi64(_mm512_castsi512_si256(q2)));
                t2 = _mm512_add_epi64(t2, _mm512_cvtepi32_epi64(_mm512_extracti64x4_epi64(q2, 1)));
                q1 = q2 = _mm512_setzero_si512();
                steps = 0;
            }
        }
    }
    b[0] = _mm512_reduce_add_epi64(t1);
    b[1] = _mm512_reduce_add_epi64(t2);
}
#endif

void flow_window_mismatch(const flow_level *l, int ix, int iy, const int w[4], int win,
                          const int16_t *I, const int16_t *gx, const int16_t *gy, int64_t b[2])
{
#if defined(__GNUC__)
    if (flow_window_avx512()) {
        flow_window_mismatch_avx512(l, ix, iy, w, win, I, gx, gy, b);
        return;
    }
#endif
    flow_window_mismatch_sse2(l, ix, iy, w, win, I, gx, gy, b);
}

int64_t flow_window_abs_mismatch(const flow_level *l, int ix, int iy, const int w[4], int win, const int16_t *I)
{
#if defined(__GNUC__)
    if (flow_window_avx512()) return flow_window_abs_mismatch_avx512(l, ix, iy, w, win, I);
#endif
    return flow_window_abs_mismatch_sse2(l, ix, iy, w, win, I);
}

#elif defined(__aarch64__) && defined(__ARM_NEON)
#include <arm_neon.h>

/* 8 bilinear samples of 16-bit values (a, b on this row, c, d on the next) as two 32-bit
 * halves, not yet descaled: widening multiply-accumulates. */
static inline void bilinear8(int16x8_t a, int16x8_t b, int16x8_t c, int16x8_t d,
                             const int16x4_t w[4], int32x4_t *lo, int32x4_t *hi)
{
    int32x4_t l = vmull_s16(vget_low_s16(a), w[0]);
    l = vmlal_s16(l, vget_low_s16(b), w[1]);
    l = vmlal_s16(l, vget_low_s16(c), w[2]);
    *lo = vmlal_s16(l, vget_low_s16(d), w[3]);
    int32x4_t h = vmull_s16(vget_high_s16(a), w[0]);
    h = vmlal_s16(h, vget_high_s16(b), w[1]);
    h = vmlal_s16(h, vget_high_s16(c), w[2]);
    *hi = vmlal_s16(h, vget_high_s16(d), w[3]);
}

static inline int16x8_t load8u(const uint8_t *p)
{
    return vreinterpretq_s16_u16(vmovl_u8(vld1_u8(p)));
}

/* (v + 2^(n-1)) >> n narrowed: vrshrn is exactly that (the values fit 16 bits) */
#define DESCALE_PACK(lo, hi, n) vcombine_s16(vrshrn_n_s32((lo), (n)), vrshrn_n_s32((hi), (n)))

/* d * g summed into 32-bit lanes */
static inline int32x4_t dot8(int32x4_t acc, int16x8_t d, int16x8_t g)
{
    acc = vmlal_s16(acc, vget_low_s16(d), vget_low_s16(g));
    return vmlal_s16(acc, vget_high_s16(d), vget_high_s16(g));
}

void flow_window_prev(const flow_level *l, int ix, int iy, const int w[4], int win, int16_t *I,
                      int16_t *gx, int16_t *gy, int64_t a[3])
{
    static const int16_t lane[8] = {0, 1, 2, 3, 4, 5, 6, 7};
    const int wr = FLOW_WROW(win), s = l->stride, gs = FLOW_GROW(win);
    const int16x4_t wv[4] = {vdup_n_s16((int16_t)w[0]), vdup_n_s16((int16_t)w[1]),
                             vdup_n_s16((int16_t)w[2]), vdup_n_s16((int16_t)w[3])};
    const int16x8_t lanes = vld1q_s16(lane);
    int16_t lgx[(SH_FLOW_MAX_WIN + 1) * FLOW_GROW(SH_FLOW_MAX_WIN)], lgy[sizeof lgx / sizeof *lgx];
    flow_window_gradients(l, ix, iy, win, lgx, lgy);
    int64_t s11 = 0, s12 = 0, s22 = 0;
    for (int y = 0; y < win; y++) {
        const uint8_t *p = l->img + (ptrdiff_t)(iy + y) * s + ix;
        const int16_t *dx = lgx + y * gs, *dy = lgy + y * gs;
        int16_t *ri = I + y * wr, *rx = gx + y * wr, *ry = gy + y * wr;
        int32x4_t q11 = vdupq_n_s32(0), q12 = q11, q22 = q11;
        for (int x = 0; x < wr; x += 8) {
            int32x4_t lo, hi;
            /* lanes past the side: zero, so that they add nothing to any sum */
            const int16x8_t keep =
                vreinterpretq_s16_u16(vcltq_s16(lanes, vdupq_n_s16((int16_t)(win - x))));
            bilinear8(load8u(p + x), load8u(p + x + 1), load8u(p + x + s), load8u(p + x + s + 1),
                      wv, &lo, &hi);
            int16x8_t vi = vandq_s16(DESCALE_PACK(lo, hi, W_BITS - 5), keep);
            bilinear8(vld1q_s16(dx + x), vld1q_s16(dx + x + 1), vld1q_s16(dx + x + gs),
                      vld1q_s16(dx + x + gs + 1), wv, &lo, &hi);
            int16x8_t vx = vandq_s16(DESCALE_PACK(lo, hi, W_BITS), keep);
            bilinear8(vld1q_s16(dy + x), vld1q_s16(dy + x + 1), vld1q_s16(dy + x + gs),
                      vld1q_s16(dy + x + gs + 1), wv, &lo, &hi);
            int16x8_t vy = vandq_s16(DESCALE_PACK(lo, hi, W_BITS), keep);
            vst1q_s16(ri + x, vi);
            vst1q_s16(rx + x, vx);
            vst1q_s16(ry + x, vy);
            q11 = dot8(q11, vx, vx);
            q12 = dot8(q12, vx, vy);
            q22 = dot8(q22, vy, vy);
        }
        s11 += vaddlvq_s32(q11);
        s12 += vaddlvq_s32(q12);
        s22 += vaddlvq_s32(q22);
    }
    a[0] = s11;
    a[1] = s12;
    a[2] = s22;
}

void flow_window_mismatch(const flow_level *l, int ix, int iy, const int w[4], int win,
                          const int16_t *I, const int16_t *gx, const int16_t *gy, int64_t b[2])
{
    const int wr = FLOW_WROW(win), s = l->stride;
    const int16x4_t wv[4] = {vdup_n_s16((int16_t)w[0]), vdup_n_s16((int16_t)w[1]),
                             vdup_n_s16((int16_t)w[2]), vdup_n_s16((int16_t)w[3])};
    int64_t s1 = 0, s2 = 0;
    for (int y = 0; y < win; y++) {
        const uint8_t *p = l->img + (ptrdiff_t)(iy + y) * s + ix;
        const int16_t *ri = I + y * wr, *rx = gx + y * wr, *ry = gy + y * wr;
        int32x4_t q1 = vdupq_n_s32(0), q2 = q1;
        for (int x = 0; x < wr; x += 8) {
            int32x4_t lo, hi;
            bilinear8(load8u(p + x), load8u(p + x + 1), load8u(p + x + s), load8u(p + x + s + 1),
                      wv, &lo, &hi);
            /* past the side the gradients are zero: d * 0 adds nothing */
            int16x8_t d = vsubq_s16(DESCALE_PACK(lo, hi, W_BITS - 5), vld1q_s16(ri + x));
            q1 = dot8(q1, d, vld1q_s16(rx + x));
            q2 = dot8(q2, d, vld1q_s16(ry + x));
        }
        s1 += vaddlvq_s32(q1);
        s2 += vaddlvq_s32(q2);
    }
    b[0] = s1;
    b[1] = s2;
}

/* once per point and search: NEON lanes not measured to pay here */
int64_t flow_window_abs_mismatch(const flow_level *l, int ix, int iy, const int w[4], int win, const int16_t *I)
{
    return flow_window_abs_mismatch_portable(l, ix, iy, w, win, I);
}

#else
int64_t flow_window_abs_mismatch(const flow_level *l, int ix, int iy, const int w[4], int win, const int16_t *I)
{
    return flow_window_abs_mismatch_portable(l, ix, iy, w, win, I);
}

void flow_window_prev(const flow_level *l, int ix, int iy, const int w[4], int win, int16_t *I,
                      int16_t *gx, int16_t *gy, int64_t a[3])
{
    flow_window_prev_portable(l, ix, iy, w, win, I, gx, gy, a);
}

void flow_window_mismatch(const flow_level *l, int ix, int iy, const int w[4], int win,
                          const int16_t *I, const int16_t *gx, const int16_t *gy, int64_t b[2])
{
    flow_window_mismatch_portable(l, ix, iy, w, win, I, gx, gy, b);
}
#endif

void flow_window_prev_warped(const flow_level *l, int pad, const int32_t start[2], const int32_t col[2],
                             const int32_t row[2], int win, int16_t *I, int16_t *gx, int16_t *gy, int64_t a[3])
{
#ifdef FLOW_X86
    if (flow_window_avx512()) {
        flow_window_prev_warped_avx512(l, pad, start, col, row, win, I, gx, gy, a);
        return;
    }
#endif
    flow_window_prev_warped_portable(l, pad, start, col, row, win, I, gx, gy, a);
}
