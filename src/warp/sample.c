/* The per-pixel loop: bilinear sampling along a span in 16.16 fixed point.
 *
 * Positions step by a constant per pixel, so each pixel costs two integer adds for its source
 * position; the bilinear weights use 7-bit fractions (1/128 px), finer than OpenCV's 1/32, and
 * the products fit 32-bit integers (255 * 128 * 128 < 2^23). */
#include <math.h>
#include <string.h>

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
    if (channels == 3) sample_run(src, 3, black, dst, count, fx, fy, dfx, dfy);
    else sample_run(src, 1, black, dst, count, fx, fy, dfx, dfy);
}
