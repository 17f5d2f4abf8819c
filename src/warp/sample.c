/* The per-pixel loop: bilinear sampling along a span in 16.16 fixed point.
 *
 * Positions step by a constant per pixel, so each pixel costs two integer adds for its source
 * position; the bilinear weights use 7-bit fractions (1/128 px), finer than OpenCV's 1/32, and
 * the products fit 32-bit integers (255 * 128 * 128 < 2^23). */
#include <math.h>
#include <string.h>

#include <pthread.h>

#include "warp_internal.h"

#define FRAC_BITS 16
#define WEIGHT_BITS 7
#define ONE (1 << WEIGHT_BITS)
/* Fixed-point positions must stay within int32 along a whole span. */
#define SAFE_COORD 16000.0

static inline uint8_t blend(const uint8_t *p00, const uint8_t *p01, const uint8_t *p10,
                            const uint8_t *p11, int wx, int wy)
{
    int top = p00[0] * (ONE - wx) + p01[0] * wx;
    int bottom = p10[0] * (ONE - wx) + p11[0] * wx;
    return (uint8_t)((top * (ONE - wy) + bottom * wy + (1 << (2 * WEIGHT_BITS - 1))) >>
                     (2 * WEIGHT_BITS));
}

/* A sample whose 2x2 footprint crosses the last row or column: the position is inside the
 * plane (paper: "if inside I_c"), so the missing taps repeat the edge (their weight is 0 when
 * the position lies exactly on the edge, and the position never lies beyond it). */
static void sample_edge(const sh_plane *src, int channels, int32_t fx, int32_t fy, uint8_t black,
                        uint8_t *out)
{
    int32_t max_x = (int32_t)(src->width - 1) << FRAC_BITS;
    int32_t max_y = (int32_t)(src->height - 1) << FRAC_BITS;
    if (fx < 0 || fy < 0 || fx > max_x || fy > max_y) {
        memset(out, black, (size_t)channels);
        return;
    }
    int ix = fx >> FRAC_BITS, iy = fy >> FRAC_BITS;
    int ix1 = ix + 1 < src->width ? ix + 1 : ix, iy1 = iy + 1 < src->height ? iy + 1 : iy;
    int wx = (fx >> (FRAC_BITS - WEIGHT_BITS)) & (ONE - 1);
    int wy = (fy >> (FRAC_BITS - WEIGHT_BITS)) & (ONE - 1);
    const uint8_t *r0 = src->data + (size_t)iy * src->stride;
    const uint8_t *r1 = src->data + (size_t)iy1 * src->stride;
    for (int c = 0; c < channels; c++)
        out[c] = blend(r0 + ix * channels + c, r0 + ix1 * channels + c, r1 + ix * channels + c,
                       r1 + ix1 * channels + c, wx, wy);
}

static inline void sample_run(const sh_plane *src, const int channels, uint8_t black,
                              uint8_t *dst, int count, int32_t fx, int32_t fy, int32_t dfx,
                              int32_t dfy)
{
    const unsigned last_x = (unsigned)src->width - 1, last_y = (unsigned)src->height - 1;
    const size_t stride = (size_t)src->stride;
    for (int k = 0; k < count; k++, fx += dfx, fy += dfy, dst += channels) {
        unsigned ix = (unsigned)(fx >> FRAC_BITS), iy = (unsigned)(fy >> FRAC_BITS);
        if (ix >= last_x || iy >= last_y) {
            sample_edge(src, channels, fx, fy, black, dst);
            continue;
        }
        int wx = (fx >> (FRAC_BITS - WEIGHT_BITS)) & (ONE - 1);
        int wy = (fy >> (FRAC_BITS - WEIGHT_BITS)) & (ONE - 1);
        const uint8_t *p = src->data + iy * stride + ix * (unsigned)channels;
        for (int c = 0; c < channels; c++)
            dst[c] = blend(p + c, p + channels + c, p + stride + c, p + stride + channels + c, wx, wy);
    }
}

/* Whether every position of the span (a segment: its ends bound it) has its 2x2 footprint, and
 * the 8 bytes the vector loads read, inside the plane. */
static inline int span_inside(const sh_plane *src, int count, int32_t fx, int32_t fy, int32_t dfx,
                              int32_t dfy, int spare_x)
{
    int32_t ex = fx + (count - 1) * dfx, ey = fy + (count - 1) * dfy;
    int32_t lo_x = fx < ex ? fx : ex, hi_x = fx < ex ? ex : fx;
    int32_t lo_y = fy < ey ? fy : ey, hi_y = fy < ey ? ey : fy;
    return lo_x >= 0 && lo_y >= 0 && (hi_x >> FRAC_BITS) < src->width - 1 - spare_x &&
           (hi_y >> FRAC_BITS) < src->height - 1;
}

/* One channel, every footprint inside the plane (span_inside): no per-pixel checks. */
static void sample_run_gray_inside(const sh_plane *src, uint8_t *dst, int count, int32_t fx,
                                   int32_t fy, int32_t dfx, int32_t dfy)
{
    const size_t stride = (size_t)src->stride;
    for (int k = 0; k < count; k++, fx += dfx, fy += dfy) {
        const uint8_t *p = src->data + (size_t)(fy >> FRAC_BITS) * stride + (size_t)(fx >> FRAC_BITS);
        int wx = (fx >> (FRAC_BITS - WEIGHT_BITS)) & (ONE - 1);
        int wy = (fy >> (FRAC_BITS - WEIGHT_BITS)) & (ONE - 1);
        dst[k] = blend(p, p + 1, p + stride, p + stride + 1, wx, wy);
    }
}

/* RGB24, one pixel per step in 8 lanes of 16 bits: the two source rows' 8 bytes
 * (R0 G0 B0 R1 G1 B1 . .) are blended vertically and rounded to 8 bits, then lanes 0-2 with
 * lanes 3-5 horizontally. Two roundings instead of one: at most 1 level from the exact
 * bilinear value. SSE2 is part of x86-64; other targets take the scalar loop. */
#if defined(__SSE2__)
#include <emmintrin.h>

static __m128i weight_lo[ONE], weight_hi[ONE]; /* [ONE - w] * 8, [w] * 8 */

static void init_weights(void)
{
    for (int w = 0; w < ONE; w++) {
        weight_lo[w] = _mm_set1_epi16((short)(ONE - w));
        weight_hi[w] = _mm_set1_epi16((short)w);
    }
}

static inline uint32_t bilinear_rgb(const uint8_t *p, size_t stride, int32_t fx, int32_t fy,
                                    __m128i zero, __m128i round)
{
    int wx = (fx >> (FRAC_BITS - WEIGHT_BITS)) & (ONE - 1);
    int wy = (fy >> (FRAC_BITS - WEIGHT_BITS)) & (ONE - 1);
    __m128i top = _mm_unpacklo_epi8(_mm_loadl_epi64((const __m128i *)p), zero);
    __m128i bottom = _mm_unpacklo_epi8(_mm_loadl_epi64((const __m128i *)(p + stride)), zero);
    __m128i v = _mm_add_epi16(_mm_mullo_epi16(top, weight_lo[wy]),
                              _mm_mullo_epi16(bottom, weight_hi[wy]));
    v = _mm_srli_epi16(_mm_add_epi16(v, round), WEIGHT_BITS);
    __m128i h = _mm_add_epi16(_mm_mullo_epi16(v, weight_lo[wx]),
                              _mm_mullo_epi16(_mm_srli_si128(v, 6), weight_hi[wx]));
    h = _mm_srli_epi16(_mm_add_epi16(h, round), WEIGHT_BITS);
    return (uint32_t)_mm_cvtsi128_si32(_mm_packus_epi16(h, h));
}

static void sample_run_rgb(const sh_plane *src, uint8_t black, uint8_t *dst, int count,
                           int32_t fx, int32_t fy, int32_t dfx, int32_t dfy)
{
    const __m128i zero = _mm_setzero_si128(), round = _mm_set1_epi16(1 << (WEIGHT_BITS - 1));
    const size_t stride = (size_t)src->stride;
    /* The 8-byte loads read 2 bytes past the right tap: 2 spare pixels keep them in the row. */
    if (src->width < 4 || !span_inside(src, count, fx, fy, dfx, dfy, 2)) {
        for (int k = 0; k < count; k++, fx += dfx, fy += dfy, dst += 3) {
            unsigned ix = (unsigned)(fx >> FRAC_BITS), iy = (unsigned)(fy >> FRAC_BITS);
            if (src->width < 4 || ix >= (unsigned)src->width - 3 || iy >= (unsigned)src->height - 1) {
                sample_run(src, 3, black, dst, 1, fx, fy, 0, 0);
                continue;
            }
            uint32_t rgb = bilinear_rgb(src->data + iy * stride + ix * 3u, stride, fx, fy, zero, round);
            memcpy(dst, &rgb, 3);
        }
        return;
    }
    /* The common case: no bounds to check. A 4-byte store is cheaper; its spare byte lands on
     * the next pixel, which the loop writes next; the last pixel stores exactly 3. */
    for (int k = 0; k < count - 1; k++, fx += dfx, fy += dfy, dst += 3) {
        uint32_t rgb = bilinear_rgb(src->data + (size_t)(fy >> FRAC_BITS) * stride +
                                        (size_t)(fx >> FRAC_BITS) * 3u,
                                    stride, fx, fy, zero, round);
        memcpy(dst, &rgb, 4);
    }
    uint32_t rgb = bilinear_rgb(src->data + (size_t)(fy >> FRAC_BITS) * stride +
                                    (size_t)(fx >> FRAC_BITS) * 3u,
                                stride, fx, fy, zero, round);
    memcpy(dst, &rgb, 3);
}
#else
static void init_weights(void) {}

static void sample_run_rgb(const sh_plane *src, uint8_t black, uint8_t *dst, int count,
                           int32_t fx, int32_t fy, int32_t dfx, int32_t dfy)
{
    sample_run(src, 3, black, dst, count, fx, fy, dfx, dfy);
}
#endif

void warp_sample_init(void)
{
    static pthread_once_t once = PTHREAD_ONCE_INIT;
    pthread_once(&once, init_weights);
}

void warp_sample_span(const sh_plane *src, int channels, uint8_t black, uint8_t *dst_row,
                      const warp_span *s)
{
    int count = s->x1 - s->x0 + 1;
    uint8_t *dst = dst_row + (size_t)s->x0 * channels;
    double ex = s->sx + (count - 1) * s->dsx, ey = s->sy + (count - 1) * s->dsy;
    if (!(fabs(s->sx) < SAFE_COORD && fabs(s->sy) < SAFE_COORD && fabs(ex) < SAFE_COORD &&
          fabs(ey) < SAFE_COORD)) {
        /* Far outside any frame (or NaN): nothing to sample. */
        memset(dst, black, (size_t)count * channels);
        return;
    }
    int32_t fx = (int32_t)lrint(s->sx * (1 << FRAC_BITS));
    int32_t fy = (int32_t)lrint(s->sy * (1 << FRAC_BITS));
    int32_t dfx = (int32_t)lrint(s->dsx * (1 << FRAC_BITS));
    int32_t dfy = (int32_t)lrint(s->dsy * (1 << FRAC_BITS));
    if (channels == 3) sample_run_rgb(src, black, dst, count, fx, fy, dfx, dfy);
    else if (span_inside(src, count, fx, fy, dfx, dfy, 0)) sample_run_gray_inside(src, dst, count, fx, fy, dfx, dfy);
    else sample_run(src, 1, black, dst, count, fx, fy, dfx, dfy);
}
