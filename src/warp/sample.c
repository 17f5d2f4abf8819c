/* The per-pixel loop: bilinear sampling at 16.16 fixed-point positions.
 *
 * The bilinear weights use 7-bit fractions (1/128 px, finer than OpenCV's 1/32); products fit
 * 32-bit integers (255 * 128 * 128 < 2^23). */
#include <pthread.h>
#include <string.h>

#include "warp_internal.h"

#define FRAC_BITS WARP_FRAC_BITS
#define WEIGHT_BITS 7
#define ONE (1 << WEIGHT_BITS)

static inline int weight_of(int32_t f)
{
    return (f >> (FRAC_BITS - WEIGHT_BITS)) & (ONE - 1);
}

static inline uint8_t blend(const uint8_t *p00, const uint8_t *p01, const uint8_t *p10,
                            const uint8_t *p11, int wx, int wy)
{
    int top = p00[0] * (ONE - wx) + p01[0] * wx;
    int bottom = p10[0] * (ONE - wx) + p11[0] * wx;
    return (uint8_t)((top * (ONE - wy) + bottom * wy + (1 << (2 * WEIGHT_BITS - 1))) >>
                     (2 * WEIGHT_BITS));
}

/* Any position, checked: black outside the plane (paper: "if inside I_c"); a position on the
 * last row or column repeats the edge for the missing taps, whose weight is then 0. */
static void sample_checked(const sh_plane *src, int channels, int32_t fx, int32_t fy,
                           uint8_t black, uint8_t *out)
{
    int32_t max_x = (int32_t)(src->width - 1) << FRAC_BITS;
    int32_t max_y = (int32_t)(src->height - 1) << FRAC_BITS;
    if (fx < 0 || fy < 0 || fx > max_x || fy > max_y) {
        memset(out, black, (size_t)channels);
        return;
    }
    int ix = fx >> FRAC_BITS, iy = fy >> FRAC_BITS;
    int ix1 = ix + 1 < src->width ? ix + 1 : ix, iy1 = iy + 1 < src->height ? iy + 1 : iy;
    int wx = weight_of(fx), wy = weight_of(fy);
    const uint8_t *r0 = src->data + (size_t)iy * src->stride;
    const uint8_t *r1 = src->data + (size_t)iy1 * src->stride;
    for (int c = 0; c < channels; c++)
        out[c] = blend(r0 + ix * channels + c, r0 + ix1 * channels + c, r1 + ix * channels + c,
                       r1 + ix1 * channels + c, wx, wy);
}

/* One channel, the one definition every path computes bit for bit: the exact bilinear sum of
 * the four taps rounded once (blend). Positions on the last row or column, or off the plane,
 * take sample_checked, as in the SIMD paths. */
void warp_sample_row_gray_portable(const sh_plane *src, uint8_t black, uint8_t *dst,
                                   const int32_t *fx, const int32_t *fy, int count)
{
    const unsigned last_x = (unsigned)src->width - 1, last_y = (unsigned)src->height - 1;
    const size_t stride = (size_t)src->stride;
    for (int k = 0; k < count; k++) {
        unsigned ix = (unsigned)(fx[k] >> FRAC_BITS), iy = (unsigned)(fy[k] >> FRAC_BITS);
        if (ix >= last_x || iy >= last_y) { /* negative positions wrap to huge: checked too */
            sample_checked(src, 1, fx[k], fy[k], black, dst + k);
            continue;
        }
        const uint8_t *p = src->data + iy * stride + ix;
        dst[k] = blend(p, p + 1, p + stride, p + stride + 1, weight_of(fx[k]), weight_of(fy[k]));
    }
}

/* RGB24, the one definition every path computes bit for bit (warp_sample_row_rgb_portable):
 * the two source rows are blended vertically and rounded to 8 bits, for the left tap's and the
 * right tap's channels, then those horizontally. Two roundings instead of one: at most 1 level
 * from the exact bilinear value. Positions whose 8-byte loads would leave the row (the last 3
 * columns: ix >= width - 3) or the plane take sample_checked, as do the SIMD paths. */
static inline int round7(int v)
{
    return (v + (1 << (WEIGHT_BITS - 1))) >> WEIGHT_BITS;
}

void warp_sample_row_rgb_portable(const sh_plane *src, uint8_t black, uint8_t *dst,
                                  const int32_t *fx, const int32_t *fy, int count)
{
    const int fast_x = src->width > 3 ? src->width - 3 : 0, last_y = src->height - 1;
    const size_t stride = (size_t)src->stride;
    for (int k = 0; k < count; k++, dst += 3) {
        int ix = fx[k] >> FRAC_BITS, iy = fy[k] >> FRAC_BITS;
        if (ix < 0 || iy < 0 || ix >= fast_x || iy >= last_y) {
            sample_checked(src, 3, fx[k], fy[k], black, dst);
            continue;
        }
        const uint8_t *p = src->data + (size_t)iy * stride + (size_t)ix * 3u, *q = p + stride;
        int wx = weight_of(fx[k]), wy = weight_of(fy[k]);
        for (int c = 0; c < 3; c++) {
            int left = round7(p[c] * (ONE - wy) + q[c] * wy);
            int right = round7(p[c + 3] * (ONE - wy) + q[c + 3] * wy);
            dst[c] = (uint8_t)round7(left * (ONE - wx) + right * wx);
        }
    }
}

/* SSE2 (part of x86-64) and NEON (part of AArch64): one pixel per step in 8 lanes, the row's
 * 8 bytes R0 G0 B0 R1 G1 B1 . . ; lanes 0-2 are then blended with lanes 3-5. */
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

static inline uint32_t blend_rgb(const uint8_t *p, size_t stride, int wx, int wy, __m128i zero,
                                 __m128i round)
{
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

static inline void sample_one(const sh_plane *src, uint8_t black, uint8_t *dst, int32_t fx,
                              int32_t fy, int fast_x, int last_y)
{
    int ix = fx >> FRAC_BITS, iy = fy >> FRAC_BITS;
    if (ix < 0 || iy < 0 || ix >= fast_x || iy >= last_y) {
        sample_checked(src, 3, fx, fy, black, dst);
        return;
    }
    const size_t stride = (size_t)src->stride;
    uint32_t rgb = blend_rgb(src->data + (size_t)iy * stride + (size_t)ix * 3u, stride,
                             weight_of(fx), weight_of(fy), _mm_setzero_si128(),
                             _mm_set1_epi16(1 << (WEIGHT_BITS - 1)));
    memcpy(dst, &rgb, 3);
}

static void sample_row_rgb(const sh_plane *src, uint8_t black, uint8_t *dst, const int32_t *fx,
                           const int32_t *fy, int count)
{
    const uint8_t *const data = src->data; /* dst's stores could alias *src: read once */
    const __m128i zero = _mm_setzero_si128(), round = _mm_set1_epi16(1 << (WEIGHT_BITS - 1));
    const size_t stride = (size_t)src->stride;
    /* The 8-byte loads read 2 bytes past the right tap: 2 spare pixels keep them in the row. */
    const int fast_x = src->width > 3 ? src->width - 3 : 0, last_y = src->height - 1;
    int k = 0;
    if (src->stride <= 32767) {
        /* Four pixels' addresses and weights at once: (iy << 16 | ix) madd (stride << 16 | 3)
         * = iy * stride + ix * 3, valid once both are known to lie in 0..32767. */
        const __m128i addr_mul = _mm_set1_epi32((int)((uint32_t)src->stride << 16 | 3u));
        const __m128i lim_x = _mm_set1_epi32(fast_x), lim_y = _mm_set1_epi32(last_y);
        const __m128i wmask = _mm_set1_epi32(ONE - 1);
        /* The last pixel stays for the tail loop: it must not store a 4th byte. */
        for (; k + 4 < count; k += 4) {
            __m128i px = _mm_loadu_si128((const __m128i *)(fx + k));
            __m128i py = _mm_loadu_si128((const __m128i *)(fy + k));
            __m128i ix = _mm_srai_epi32(px, FRAC_BITS), iy = _mm_srai_epi32(py, FRAC_BITS);
            /* inside: 0 <= ix < fast_x and 0 <= iy < last_y (signed compares) */
            __m128i bad = _mm_or_si128(_mm_or_si128(_mm_cmplt_epi32(ix, zero), _mm_cmplt_epi32(iy, zero)),
                                       _mm_or_si128(_mm_cmpgt_epi32(ix, _mm_sub_epi32(lim_x, _mm_set1_epi32(1))),
                                                    _mm_cmpgt_epi32(iy, _mm_sub_epi32(lim_y, _mm_set1_epi32(1)))));
            if (_mm_movemask_epi8(bad)) { /* pixel by pixel: the inside ones as always */
                for (int q = k; q < k + 4; q++, dst += 3)
                    sample_one(src, black, dst, fx[q], fy[q], fast_x, last_y);
                continue;
            }
            int32_t off[4], wx[4], wy[4];
            _mm_storeu_si128((__m128i *)off, _mm_madd_epi16(_mm_or_si128(_mm_slli_epi32(iy, 16), ix), addr_mul));
            _mm_storeu_si128((__m128i *)wx, _mm_and_si128(_mm_srai_epi32(px, FRAC_BITS - WEIGHT_BITS), wmask));
            _mm_storeu_si128((__m128i *)wy, _mm_and_si128(_mm_srai_epi32(py, FRAC_BITS - WEIGHT_BITS), wmask));
            for (int q = 0; q < 4; q++, dst += 3) {
                uint32_t rgb = blend_rgb(data + off[q], stride, wx[q], wy[q], zero, round);
                /* A 4-byte store is cheaper; its spare byte lands on the next pixel, which is
                 * written next (the row's last pixel is left to the tail loop). */
                memcpy(dst, &rgb, 4);
            }
        }
    }
    for (; k < count; k++, dst += 3)
        sample_one(src, black, dst, fx[k], fy[k], fast_x, last_y);
}
/* One channel, 8 pixels per step: positions, checks and weights in 32-bit lanes; each pixel's
 * two taps of a row are one 16-bit load into a word lane (pinsrw), the rows widened to 16 bits
 * give (left, right) pairs that pmaddwd weighs by (ONE - wx, wx): top and bottom, exact, below
 * 2^15; (top, bottom) pairs weighed by (ONE - wy, wy) are the portable sum, below 2^22. */
static inline __m128i weight_pairs(__m128i pos, __m128i wmask)
{
    __m128i w = _mm_and_si128(_mm_srli_epi32(pos, FRAC_BITS - WEIGHT_BITS), wmask);
    return _mm_or_si128(_mm_slli_epi32(w, 16), _mm_sub_epi32(_mm_set1_epi32(ONE), w));
}

static inline __m128i gray_sums(__m128i top, __m128i bottom, __m128i wx, __m128i wy)
{
    __m128i t = _mm_madd_epi16(top, wx), b = _mm_madd_epi16(bottom, wx);
    __m128i v = _mm_madd_epi16(_mm_or_si128(t, _mm_slli_epi32(b, 16)), wy);
    return _mm_srli_epi32(_mm_add_epi32(v, _mm_set1_epi32(1 << (2 * WEIGHT_BITS - 1))),
                          2 * WEIGHT_BITS);
}

static inline uint16_t load_pair(const uint8_t *p)
{
    uint16_t v;
    memcpy(&v, p, 2);
    return v;
}

static void sample_row_gray(const sh_plane *src, uint8_t black, uint8_t *dst, const int32_t *fx,
                            const int32_t *fy, int count)
{
    const uint8_t *const data = src->data, *const below = data + src->stride;
    int k = 0;
    /* offsets by pmaddwd of (ix, iy) words with (1, stride): ix, iy (below SH_IMAGE_MAX_SIZE)
     * and the stride in 0..32767 */
    if (src->stride <= 32767 && src->width >= 2 && src->height >= 2) {
        const __m128i zero = _mm_setzero_si128();
        const __m128i addr_mul = _mm_set1_epi32((int)((uint32_t)src->stride << 16 | 1u));
        /* The integer parts of 16.16 positions fit words. Inside: ix <= width - 2 and
         * iy <= height - 2 as unsigned words (negatives read as >= 32768), where the saturating
         * unsigned difference with that limit is 0. */
        const __m128i lim_x = _mm_set1_epi16((short)(src->width - 2));
        const __m128i lim_y = _mm_set1_epi16((short)(src->height - 2));
        const __m128i wmask = _mm_set1_epi32(ONE - 1);
        for (; k + 8 <= count; k += 8) {
            __m128i px0 = _mm_loadu_si128((const __m128i *)(fx + k));
            __m128i px1 = _mm_loadu_si128((const __m128i *)(fx + k + 4));
            __m128i py0 = _mm_loadu_si128((const __m128i *)(fy + k));
            __m128i py1 = _mm_loadu_si128((const __m128i *)(fy + k + 4));
            __m128i ix = _mm_packs_epi32(_mm_srai_epi32(px0, FRAC_BITS), _mm_srai_epi32(px1, FRAC_BITS));
            __m128i iy = _mm_packs_epi32(_mm_srai_epi32(py0, FRAC_BITS), _mm_srai_epi32(py1, FRAC_BITS));
            __m128i beyond = _mm_or_si128(_mm_subs_epu16(ix, lim_x), _mm_subs_epu16(iy, lim_y));
            if (_mm_movemask_epi8(_mm_cmpeq_epi16(beyond, zero)) != 0xffff) {
                /* pixel by pixel: the inside ones as always */
                warp_sample_row_gray_portable(src, black, dst + k, fx + k, fy + k, 8);
                continue;
            }
            int32_t off[8];
            _mm_storeu_si128((__m128i *)off, _mm_madd_epi16(_mm_unpacklo_epi16(ix, iy), addr_mul));
            _mm_storeu_si128((__m128i *)(off + 4), _mm_madd_epi16(_mm_unpackhi_epi16(ix, iy), addr_mul));
            /* Read the offsets back from memory: gcc would otherwise take them out of the
             * registers lane by lane (movd, pshufd: 22 instructions for 8 against 10). */
            __asm__ volatile("" : : "m"(off) : "memory");
            __m128i top = zero, bottom = zero;
#define PAIR(q)                                                         \
            top = _mm_insert_epi16(top, load_pair(data + off[q]), q);   \
            bottom = _mm_insert_epi16(bottom, load_pair(below + off[q]), q)
            PAIR(0); PAIR(1); PAIR(2); PAIR(3); PAIR(4); PAIR(5); PAIR(6); PAIR(7);
#undef PAIR
            __m128i v0 = gray_sums(_mm_unpacklo_epi8(top, zero), _mm_unpacklo_epi8(bottom, zero),
                                   weight_pairs(px0, wmask), weight_pairs(py0, wmask));
            __m128i v1 = gray_sums(_mm_unpackhi_epi8(top, zero), _mm_unpackhi_epi8(bottom, zero),
                                   weight_pairs(px1, wmask), weight_pairs(py1, wmask));
            v0 = _mm_packs_epi32(v0, v1);
            _mm_storel_epi64((__m128i *)(dst + k), _mm_packus_epi16(v0, v0));
        }
    }
    warp_sample_row_gray_portable(src, black, dst + k, fx + k, fy + k, count - k);
}

/* AVX2, where the CPU has it (chosen once at run time; the build stays x86-64's baseline): the
 * 16 pinsrw of SSE2's 8 pixels are the loop's bound (two uops each, all on one shuffle port),
 * so each row's taps come from one gather of a 32-bit word per pixel, bytes (p, p + 1, p + 2,
 * p + 3), and pshufb keeps (p, p + 1) as the same word pairs. The weights and sums are SSE2's
 * operations on 8 lanes at once, so the bytes are the portable ones. Reading p + 3 takes
 * ix <= width - 4; the block's other cases go SSE2's way. */
#if defined(__GNUC__) && (defined(__x86_64__) || defined(__i386__))
#include <immintrin.h>
#define SH_WARP_AVX2 1

__attribute__((target("avx2"))) static void sample_row_gray_avx2(const sh_plane *src, uint8_t black,
                                                                   uint8_t *dst, const int32_t *fx,
                                                                   const int32_t *fy, int count)
{
    const uint8_t *const data = src->data, *const below = data + src->stride;
    int k = 0;
    /* offsets are the gather's signed 32-bit indices */
    if (src->width >= 4 && src->height >= 2 && (int64_t)src->stride * src->height <= INT32_MAX) {
        const __m256i lim_x = _mm256_set1_epi32(src->width - 4), lim_y = _mm256_set1_epi32(src->height - 2);
        const __m256i stride = _mm256_set1_epi32(src->stride), wmask = _mm256_set1_epi32(ONE - 1);
        const __m256i one = _mm256_set1_epi32(ONE), half = _mm256_set1_epi32(1 << (2 * WEIGHT_BITS - 1));
        const __m256i pairs = _mm256_setr_epi8(0, -1, 1, -1, 4, -1, 5, -1, 8, -1, 9, -1, 12, -1, 13, -1,
                                               0, -1, 1, -1, 4, -1, 5, -1, 8, -1, 9, -1, 12, -1, 13, -1);
        const __m256i bytes = _mm256_setr_epi8(0, 4, 8, 12, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1,
                                               0, 4, 8, 12, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1);
        const __m256i halves = _mm256_setr_epi32(0, 4, 1, 1, 1, 1, 1, 1);
        for (; k + 8 <= count; k += 8) {
            __m256i px = _mm256_loadu_si256((const __m256i *)(fx + k));
            __m256i py = _mm256_loadu_si256((const __m256i *)(fy + k));
            __m256i ix = _mm256_srai_epi32(px, FRAC_BITS), iy = _mm256_srai_epi32(py, FRAC_BITS);
            /* unsigned: negatives are huge */
            __m256i inside = _mm256_and_si256(_mm256_cmpeq_epi32(_mm256_max_epu32(ix, lim_x), lim_x),
                                              _mm256_cmpeq_epi32(_mm256_max_epu32(iy, lim_y), lim_y));
            if (_mm256_movemask_epi8(inside) != -1) {
                sample_row_gray(src, black, dst + k, fx + k, fy + k, 8);
                continue;
            }
            __m256i off = _mm256_add_epi32(_mm256_mullo_epi32(iy, stride), ix);
            __m256i top = _mm256_shuffle_epi8(_mm256_i32gather_epi32((const int *)data, off, 1), pairs);
            __m256i bottom = _mm256_shuffle_epi8(_mm256_i32gather_epi32((const int *)below, off, 1), pairs);
            __m256i w = _mm256_and_si256(_mm256_srli_epi32(px, FRAC_BITS - WEIGHT_BITS), wmask);
            __m256i wx = _mm256_or_si256(_mm256_slli_epi32(w, 16), _mm256_sub_epi32(one, w));
            w = _mm256_and_si256(_mm256_srli_epi32(py, FRAC_BITS - WEIGHT_BITS), wmask);
            __m256i wy = _mm256_or_si256(_mm256_slli_epi32(w, 16), _mm256_sub_epi32(one, w));
            __m256i t = _mm256_madd_epi16(top, wx), b = _mm256_madd_epi16(bottom, wx);
            __m256i v = _mm256_madd_epi16(_mm256_or_si256(t, _mm256_slli_epi32(b, 16)), wy);
            v = _mm256_srli_epi32(_mm256_add_epi32(v, half), 2 * WEIGHT_BITS);
            v = _mm256_permutevar8x32_epi32(_mm256_shuffle_epi8(v, bytes), halves);
            _mm_storel_epi64((__m128i *)(dst + k), _mm256_castsi256_si128(v));
        }
    }
    sample_row_gray(src, black, dst + k, fx + k, fy + k, count - k);
}

/* AVX-512 (F and BW), where the CPU has it: AVX2's loop on 16 lanes, its gathers of 16 words
 * and the inside test a mask compare; the same operations on each lane, so the same bytes.
 * perf on the 4K warp (32 markers, one thread) put about two thirds of the frame's time in
 * AVX2's loop, bound by its instruction count, not by memory: 16 lanes take 0.75-0.78 of its
 * time (docs/warp.md). Blocks with a pixel outside go AVX2's way, 8 at a time. */
__attribute__((target("avx512f,avx512bw"))) static void sample_row_gray_avx512(const sh_plane *src,
                                                                               uint8_t black, uint8_t *dst,
                                                                               const int32_t *fx,
                                                                               const int32_t *fy, int count)
{
    const uint8_t *const data = src->data, *const below = data + src->stride;
    int k = 0;
    if (src->width >= 4 && src->height >= 2 && (int64_t)src->stride * src->height <= INT32_MAX) {
        const __m512i lim_x = _mm512_set1_epi32(src->width - 4), lim_y = _mm512_set1_epi32(src->height - 2);
        const __m512i stride = _mm512_set1_epi32(src->stride), wmask = _mm512_set1_epi32(ONE - 1);
        const __m512i one = _mm512_set1_epi32(ONE), half = _mm512_set1_epi32(1 << (2 * WEIGHT_BITS - 1));
        /* AVX2's `pairs` in each 128-bit lane: bytes (0, -, 1, -, 4, -, 5, -, ...) */
        const __m512i pairs = _mm512_set4_epi32((int)0x800d800cu, (int)0x80098008u, (int)0x80058004u,
                                                (int)0x80018000u);
        for (; k + 16 <= count; k += 16) {
            __m512i px = _mm512_loadu_si512(fx + k), py = _mm512_loadu_si512(fy + k);
            __m512i ix = _mm512_srai_epi32(px, FRAC_BITS), iy = _mm512_srai_epi32(py, FRAC_BITS);
            /* unsigned: negatives are huge */
            if ((__mmask16)(_mm512_cmple_epu32_mask(ix, lim_x) & _mm512_cmple_epu32_mask(iy, lim_y)) != 0xffff) {
                sample_row_gray_avx2(src, black, dst + k, fx + k, fy + k, 16);
                continue;
            }
            __m512i off = _mm512_add_epi32(_mm512_mullo_epi32(iy, stride), ix);
            __m512i top = _mm512_shuffle_epi8(_mm512_i32gather_epi32(off, (const void *)data, 1), pairs);
            __m512i bottom = _mm512_shuffle_epi8(_mm512_i32gather_epi32(off, (const void *)below, 1), pairs);
            __m512i w = _mm512_and_si512(_mm512_srli_epi32(px, FRAC_BITS - WEIGHT_BITS), wmask);
            __m512i wx = _mm512_or_si512(_mm512_slli_epi32(w, 16), _mm512_sub_epi32(one, w));
            w = _mm512_and_si512(_mm512_srli_epi32(py, FRAC_BITS - WEIGHT_BITS), wmask);
            __m512i wy = _mm512_or_si512(_mm512_slli_epi32(w, 16), _mm512_sub_epi32(one, w));
            __m512i t = _mm512_madd_epi16(top, wx), b = _mm512_madd_epi16(bottom, wx);
            __m512i v = _mm512_madd_epi16(_mm512_or_si512(t, _mm512_slli_epi32(b, 16)), wy);
            v = _mm512_srli_epi32(_mm512_add_epi32(v, half), 2 * WEIGHT_BITS);
            _mm_storeu_si128((__m128i *)(dst + k), _mm512_cvtepi32_epi8(v)); /* v <= 255: exact */
        }
    }
    sample_row_gray_avx2(src, black, dst + k, fx + k, fy + k, count - k);
}
#endif
#elif defined(__aarch64__) && defined(__ARM_NEON)
#include <arm_neon.h>

static void init_weights(void) {}

/* umull/umlal on the 8 bytes of each row with the weights (<= 128, so they fit a byte) give
 * exact 16-bit sums (<= 255 * 128); rshrn #7 is (v + 64) >> 7 narrowed, the portable round7. */
static inline uint8x8_t blend_rgb(const uint8_t *p, size_t stride, int wx, int wy)
{
    uint16x8_t v = vmull_u8(vld1_u8(p), vdup_n_u8((uint8_t)(ONE - wy)));
    v = vmlal_u8(v, vld1_u8(p + stride), vdup_n_u8((uint8_t)wy));
    uint8x8_t t = vrshrn_n_u16(v, WEIGHT_BITS);
    uint16x8_t h = vmull_u8(t, vdup_n_u8((uint8_t)(ONE - wx)));
    h = vmlal_u8(h, vext_u8(t, t, 3), vdup_n_u8((uint8_t)wx));
    return vrshrn_n_u16(h, WEIGHT_BITS);
}

static inline void sample_one(const sh_plane *src, uint8_t black, uint8_t *dst, int32_t fx,
                              int32_t fy, int fast_x, int last_y)
{
    int ix = fx >> FRAC_BITS, iy = fy >> FRAC_BITS;
    if (ix < 0 || iy < 0 || ix >= fast_x || iy >= last_y) {
        sample_checked(src, 3, fx, fy, black, dst);
        return;
    }
    const size_t stride = (size_t)src->stride;
    uint8x8_t rgb = blend_rgb(src->data + (size_t)iy * stride + (size_t)ix * 3u, stride,
                              weight_of(fx), weight_of(fy));
    uint8_t b[8];
    vst1_u8(b, rgb);
    memcpy(dst, b, 3);
}

static void sample_row_rgb(const sh_plane *src, uint8_t black, uint8_t *dst, const int32_t *fx,
                           const int32_t *fy, int count)
{
    const uint8_t *const data = src->data; /* dst's stores could alias *src: read once */
    const size_t stride = (size_t)src->stride;
    /* The 8-byte loads read 2 bytes past the right tap: 2 spare pixels keep them in the row. */
    const int fast_x = src->width > 3 ? src->width - 3 : 0, last_y = src->height - 1;
    int k = 0;
    if (src->stride <= 32767) {
        /* Four pixels' checks, offsets (iy * stride + ix * 3 < 2^31 once both lie in
         * 0..32767) and weights at once. */
        const uint32x4_t lim_x = vdupq_n_u32((uint32_t)fast_x), lim_y = vdupq_n_u32((uint32_t)last_y);
        const int32x4_t wmask = vdupq_n_s32(ONE - 1);
        /* The last pixel stays for the tail loop: it must not store a 4th byte. */
        for (; k + 4 < count; k += 4) {
            int32x4_t px = vld1q_s32(fx + k), py = vld1q_s32(fy + k);
            uint32x4_t ix = vreinterpretq_u32_s32(vshrq_n_s32(px, FRAC_BITS));
            uint32x4_t iy = vreinterpretq_u32_s32(vshrq_n_s32(py, FRAC_BITS));
            /* inside: ix < fast_x and iy < last_y as unsigned (negatives wrap to huge) */
            uint32x4_t bad = vorrq_u32(vcgeq_u32(ix, lim_x), vcgeq_u32(iy, lim_y));
            if (vmaxvq_u32(bad)) { /* pixel by pixel: the inside ones as always */
                for (int q = k; q < k + 4; q++, dst += 3)
                    sample_one(src, black, dst, fx[q], fy[q], fast_x, last_y);
                continue;
            }
            uint32x4_t off = vmlaq_n_u32(vmulq_n_u32(ix, 3u), iy, (uint32_t)stride);
            /* the weights as bytes, w = [wx0..3 wy0..3] and ONE - w, taken by lane below */
            uint16x4_t wx = vmovn_u32(vreinterpretq_u32_s32(vandq_s32(vshrq_n_s32(px, FRAC_BITS - WEIGHT_BITS), wmask)));
            uint16x4_t wy = vmovn_u32(vreinterpretq_u32_s32(vandq_s32(vshrq_n_s32(py, FRAC_BITS - WEIGHT_BITS), wmask)));
            uint8x8_t w = vmovn_u16(vcombine_u16(wx, wy)), iw = vsub_u8(vdup_n_u8(ONE), w);
            /* A 4-byte store is cheaper; its spare byte lands on the next pixel, which is
             * written next (the row's last pixel is left to the tail loop). */
#define PIXEL(q)                                                                           \
            do {                                                                           \
                const uint8_t *p = data + vgetq_lane_u32(off, q);                          \
                uint16x8_t v = vmull_u8(vld1_u8(p), vdup_lane_u8(iw, 4 + (q)));            \
                v = vmlal_u8(v, vld1_u8(p + stride), vdup_lane_u8(w, 4 + (q)));            \
                uint8x8_t t = vrshrn_n_u16(v, WEIGHT_BITS);                                \
                uint16x8_t h = vmull_u8(t, vdup_lane_u8(iw, q));                           \
                h = vmlal_u8(h, vext_u8(t, t, 3), vdup_lane_u8(w, q));                     \
                uint32_t word = vget_lane_u32(vreinterpret_u32_u8(vrshrn_n_u16(h, WEIGHT_BITS)), 0); \
                memcpy(dst + 3 * (q), &word, 4);                                           \
            } while (0)
            PIXEL(0); PIXEL(1); PIXEL(2); PIXEL(3);
#undef PIXEL
            dst += 12;
        }
    }
    for (; k < count; k++, dst += 3)
        sample_one(src, black, dst, fx[k], fy[k], fast_x, last_y);
}
/* One channel, 8 pixels per step: checks, offsets and weights in 32-bit lanes, narrowed to
 * bytes; each pixel's two taps of a row are one 16-bit load into a word lane (ld1 to a lane:
 * ld2's register pairs cost gcc 12 moves and spills), split into left and right bytes by xtn
 * and shrn #8; umull/umlal give top and bottom exactly in 16 bits (<= 255 * 128), umull/umlal
 * of those by (ONE - wy, wy) the portable sum in 32 bits, and rshrn #14 its rounding. */
static void sample_row_gray(const sh_plane *src, uint8_t black, uint8_t *dst, const int32_t *fx,
                            const int32_t *fy, int count)
{
    const uint8_t *const data = src->data;
    const size_t stride = (size_t)src->stride;
    int k = 0;
    /* offsets iy * stride + ix below 2^29 (iy below SH_IMAGE_MAX_SIZE) */
    if (src->stride <= 32767 && src->width >= 2 && src->height >= 2) {
        const uint32x4_t lim_x = vdupq_n_u32((uint32_t)src->width - 1);
        const uint32x4_t lim_y = vdupq_n_u32((uint32_t)src->height - 1);
        const uint32x4_t wmask = vdupq_n_u32(ONE - 1);
        for (; k + 8 <= count; k += 8) {
            int32x4_t px0 = vld1q_s32(fx + k), px1 = vld1q_s32(fx + k + 4);
            int32x4_t py0 = vld1q_s32(fy + k), py1 = vld1q_s32(fy + k + 4);
            uint32x4_t ix0 = vreinterpretq_u32_s32(vshrq_n_s32(px0, FRAC_BITS));
            uint32x4_t ix1 = vreinterpretq_u32_s32(vshrq_n_s32(px1, FRAC_BITS));
            uint32x4_t iy0 = vreinterpretq_u32_s32(vshrq_n_s32(py0, FRAC_BITS));
            uint32x4_t iy1 = vreinterpretq_u32_s32(vshrq_n_s32(py1, FRAC_BITS));
            /* inside: ix < width - 1 and iy < height - 1 as unsigned (negatives wrap to huge) */
            uint32x4_t bad = vorrq_u32(vorrq_u32(vcgeq_u32(ix0, lim_x), vcgeq_u32(ix1, lim_x)),
                                       vorrq_u32(vcgeq_u32(iy0, lim_y), vcgeq_u32(iy1, lim_y)));
            if (vmaxvq_u32(bad)) { /* pixel by pixel: the inside ones as always */
                warp_sample_row_gray_portable(src, black, dst + k, fx + k, fy + k, 8);
                continue;
            }
            uint32x4_t off0 = vmlaq_n_u32(ix0, iy0, (uint32_t)stride);
            uint32x4_t off1 = vmlaq_n_u32(ix1, iy1, (uint32_t)stride);
            uint16x8_t top = vdupq_n_u16(0), bottom = top;
#define PAIR(v, q)                                                                 \
            do {                                                                   \
                const uint8_t *p = data + vgetq_lane_u32(v, (q) & 3);              \
                top = vld1q_lane_u16((const uint16_t *)(const void *)p, top, q);   \
                bottom = vld1q_lane_u16((const uint16_t *)(const void *)(p + stride), bottom, q); \
            } while (0)
            PAIR(off0, 0); PAIR(off0, 1); PAIR(off0, 2); PAIR(off0, 3);
            PAIR(off1, 4); PAIR(off1, 5); PAIR(off1, 6); PAIR(off1, 7);
#undef PAIR
#define WEIGHTS(p0, p1)                                                                    \
            vmovn_u16(vcombine_u16(                                                        \
                vmovn_u32(vandq_u32(vreinterpretq_u32_s32(vshrq_n_s32(p0, FRAC_BITS - WEIGHT_BITS)), wmask)), \
                vmovn_u32(vandq_u32(vreinterpretq_u32_s32(vshrq_n_s32(p1, FRAC_BITS - WEIGHT_BITS)), wmask))))
            uint8x8_t wx = WEIGHTS(px0, px1), wy = WEIGHTS(py0, py1);
#undef WEIGHTS
            uint8x8_t iwx = vsub_u8(vdup_n_u8(ONE), wx);
            /* each word is a row's left tap in its low byte, the right one in its high byte */
            uint16x8_t t = vmlal_u8(vmull_u8(vmovn_u16(top), iwx), vshrn_n_u16(top, 8), wx);
            uint16x8_t b = vmlal_u8(vmull_u8(vmovn_u16(bottom), iwx), vshrn_n_u16(bottom, 8), wx);
            uint16x8_t wy16 = vmovl_u8(wy), iwy16 = vsubq_u16(vdupq_n_u16(ONE), wy16);
            uint32x4_t lo = vmlal_u16(vmull_u16(vget_low_u16(t), vget_low_u16(iwy16)),
                                      vget_low_u16(b), vget_low_u16(wy16));
            uint32x4_t hi = vmlal_u16(vmull_u16(vget_high_u16(t), vget_high_u16(iwy16)),
                                      vget_high_u16(b), vget_high_u16(wy16));
            uint16x8_t v = vcombine_u16(vrshrn_n_u32(lo, 2 * WEIGHT_BITS), vrshrn_n_u32(hi, 2 * WEIGHT_BITS));
            vst1_u8(dst + k, vmovn_u16(v));
        }
    }
    warp_sample_row_gray_portable(src, black, dst + k, fx + k, fy + k, count - k);
}
#else
static void init_weights(void) {}

static void sample_row_rgb(const sh_plane *src, uint8_t black, uint8_t *dst, const int32_t *fx,
                           const int32_t *fy, int count)
{
    warp_sample_row_rgb_portable(src, black, dst, fx, fy, count);
}

static void sample_row_gray(const sh_plane *src, uint8_t black, uint8_t *dst, const int32_t *fx,
                            const int32_t *fy, int count)
{
    warp_sample_row_gray_portable(src, black, dst, fx, fy, count);
}
#endif

#ifdef SH_WARP_AVX2
typedef void (*gray_fn)(const sh_plane *, uint8_t, uint8_t *, const int32_t *, const int32_t *, int);
static gray_fn gray_row = sample_row_gray;
#else
#define gray_row sample_row_gray /* one loop: called directly, inlined */
#endif

/* The widest one-channel loop up to `wanted` (0 the build's SIMD path, 1 AVX2, 2 AVX-512) that
 * the CPU has, put in use; returns its level. */
static int choose_gray(int wanted)
{
#ifdef SH_WARP_AVX2
    if (wanted >= 2 && __builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512bw")) {
        gray_row = sample_row_gray_avx512;
        return 2;
    }
    if (wanted >= 1 && __builtin_cpu_supports("avx2")) {
        gray_row = sample_row_gray_avx2;
        return 1;
    }
    gray_row = sample_row_gray;
#else
    (void)wanted;
#endif
    return 0;
}

static void init_tables(void)
{
    init_weights();
    choose_gray(2);
}

void warp_sample_init(void)
{
    static pthread_once_t once = PTHREAD_ONCE_INIT;
    pthread_once(&once, init_tables);
}

int warp_sample_path(int wanted)
{
    warp_sample_init();
    return choose_gray(wanted);
}

void warp_sample_row(const sh_plane *src, int channels, uint8_t black, uint8_t *dst,
                     const int32_t *fx, const int32_t *fy, int count)
{
    if (channels == 3) sample_row_rgb(src, black, dst, fx, fy, count);
    else gray_row(src, black, dst, fx, fy, count);
}
