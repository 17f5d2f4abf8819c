/* YUV -> RGB (BT.601) with bilinear chroma upsampling that honours the 4:2:0 siting.
 *
 * Coefficients come from the BT.601 luma weights Kr = 0.299, Kb = 0.114 (Kg = 1 - Kr - Kb):
 *   R = Y' + 2(1-Kr) Cr,  B = Y' + 2(1-Kb) Cb,  G = Y' - (2Kb(1-Kb) Cb + 2Kr(1-Kr) Cr) / Kg
 * with, full range (JFIF):  Y' = Y,               Cb = U - 128,              Cr = V - 128
 *       limited range:      Y' = (Y-16)*255/219,  Cb = (U-128)*255/224,      Cr likewise.
 *
 * Upsampling weights are quarters in each direction, so an upsampled chroma value is an exact
 * integer in sixteenths (0..4080). That lets every term be a table lookup in double precision:
 * a pixel costs three additions and a rounding, and the result equals the closed form. */
#include "stillheart/image.h"

#include <math.h>
#include <pthread.h>

#define C16_MAX (255 * 16)

typedef struct {
    double y[256];               /* Y' */
    double r_cr[C16_MAX + 1];    /* 2(1-Kr) Cr, indexed by chroma in sixteenths */
    double g_cb[C16_MAX + 1], g_cr[C16_MAX + 1];
    double b_cb[C16_MAX + 1];
} yuv_tables;

static void build_tables(yuv_tables *t, int full_range)
{
    const double kr = 0.299, kb = 0.114, kg = 1.0 - kr - kb;
    const double ys = full_range ? 1.0 : 255.0 / 219.0, yo = full_range ? 0.0 : 16.0;
    const double cs = full_range ? 1.0 : 255.0 / 224.0;
    for (int i = 0; i < 256; i++) t->y[i] = ys * (i - yo);
    for (int i = 0; i <= C16_MAX; i++) {
        double c = cs * (i / 16.0 - 128.0);
        t->r_cr[i] = 2.0 * (1.0 - kr) * c;
        t->b_cb[i] = 2.0 * (1.0 - kb) * c;
        t->g_cb[i] = -2.0 * kb * (1.0 - kb) / kg * c;
        t->g_cr[i] = -2.0 * kr * (1.0 - kr) / kg * c;
    }
}

/* Built once per range, on first use (building costs more than converting a small frame). */
static yuv_tables tables[2];
static pthread_once_t tables_once[2] = {PTHREAD_ONCE_INIT, PTHREAD_ONCE_INIT};
static void build_limited(void) { build_tables(&tables[0], 0); }
static void build_full(void) { build_tables(&tables[1], 1); }

static inline uint8_t clamp_round(double v)
{
    v = floor(v + 0.5);
    return (uint8_t)(v < 0.0 ? 0.0 : v > 255.0 ? 255.0 : v);
}

/* Bilinear taps for luma coordinate x when chroma sample k sits at luma position 2k + off/2
 * (off in half-luma units: 0 co-sited, 1 centred between two luma samples, 2 on the odd luma).
 * The chroma coordinate in quarters is q = 2x - off; weights are quarters summing to 4. */
typedef struct {
    int a, b, wa, wb;
} taps;

static inline taps tap(int x, int off, int n)
{
    int q = 2 * x - off;
    int a = q >= 0 ? q / 4 : -((-q + 3) / 4); /* floor(q / 4) */
    int frac = q - 4 * a;
    taps t = {a, a + 1, 4 - frac, frac};
    if (t.a < 0) t.a = 0;
    if (t.b < 0) t.b = 0;
    if (t.a > n - 1) t.a = n - 1;
    if (t.b > n - 1) t.b = n - 1;
    return t;
}

/* Chroma value of plane c at luma (x, y) in sixteenths, for the precomputed row taps. */
static inline int sample16(const sh_plane *c, taps v, taps h)
{
    const uint8_t *r0 = c->data + (size_t)v.a * (size_t)c->stride;
    const uint8_t *r1 = c->data + (size_t)v.b * (size_t)c->stride;
    return v.wa * (h.wa * r0[h.a] + h.wb * r0[h.b]) + v.wb * (h.wa * r1[h.a] + h.wb * r1[h.b]);
}

static inline void put(uint8_t *out, const yuv_tables *t, int y, int u16, int v16)
{
    double yy = t->y[y];
    out[0] = clamp_round(yy + t->r_cr[v16]);
    out[1] = clamp_round(yy + t->g_cb[u16] + t->g_cr[v16]);
    out[2] = clamp_round(yy + t->b_cb[u16]);
}

static void convert_i420(const sh_image *src, sh_image *dst, const yuv_tables *t)
{
    /* Offsets (half-luma units) of the chroma grid: horizontal for both planes, vertical per
     * plane because PAL-DV puts Cr on even lines and Cb on odd ones. */
    int hoff = 1, voff_u = 1, voff_v = 1;
    if (src->siting == SH_CHROMA_LEFT) hoff = 0;
    if (src->siting == SH_CHROMA_PALDV) hoff = 0, voff_v = 0, voff_u = 2;
    const sh_plane *U = &src->plane[1], *V = &src->plane[2];
    for (int y = 0; y < src->height; y++) {
        const uint8_t *ly = src->plane[0].data + (size_t)y * (size_t)src->plane[0].stride;
        uint8_t *out = dst->plane[0].data + (size_t)y * (size_t)dst->plane[0].stride;
        taps vu = tap(y, voff_u, U->height), vv = tap(y, voff_v, V->height);
        for (int x = 0; x < src->width; x++) {
            taps h = tap(x, hoff, U->width);
            put(out + 3 * x, t, ly[x], sample16(U, vu, h), sample16(V, vv, h));
        }
    }
}

static void convert_444(const sh_image *src, sh_image *dst, const yuv_tables *t)
{
    for (int y = 0; y < src->height; y++) {
        const uint8_t *ly = src->plane[0].data + (size_t)y * (size_t)src->plane[0].stride;
        const uint8_t *lu = src->plane[1].data + (size_t)y * (size_t)src->plane[1].stride;
        const uint8_t *lv = src->plane[2].data + (size_t)y * (size_t)src->plane[2].stride;
        uint8_t *out = dst->plane[0].data + (size_t)y * (size_t)dst->plane[0].stride;
        for (int x = 0; x < src->width; x++) put(out + 3 * x, t, ly[x], 16 * lu[x], 16 * lv[x]);
    }
}

sh_status sh_image_to_rgb(const sh_image *src, sh_image *dst, int full_range)
{
    if (!src || !dst || dst->format != SH_PIX_RGB24 || dst->width != src->width ||
        dst->height != src->height || !src->plane[0].data || !dst->plane[0].data)
        return sh_error_set(SH_EINVAL, "image: to_rgb needs an RGB24 destination of the same "
                                       "size (%dx%d)", src ? src->width : 0,
                            src ? src->height : 0);
    switch (src->format) {
    case SH_PIX_RGB24:
        return sh_image_copy(dst, src);
    case SH_PIX_GRAY8:
        for (int y = 0; y < src->height; y++) {
            const uint8_t *in = src->plane[0].data + (size_t)y * (size_t)src->plane[0].stride;
            uint8_t *out = dst->plane[0].data + (size_t)y * (size_t)dst->plane[0].stride;
            for (int x = 0; x < src->width; x++) out[3 * x] = out[3 * x + 1] = out[3 * x + 2] = in[x];
        }
        return SH_OK;
    case SH_PIX_I420:
    case SH_PIX_YUV444: {
        int k = full_range ? 1 : 0;
        pthread_once(&tables_once[k], k ? build_full : build_limited);
        if (src->format == SH_PIX_I420) convert_i420(src, dst, &tables[k]);
        else convert_444(src, dst, &tables[k]);
        return SH_OK;
    }
    }
    return sh_error_set(SH_EINVAL, "image: unknown pixel format %d", (int)src->format);
}
