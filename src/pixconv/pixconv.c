/* Camera pixel formats to GRAY8 / I420 / RGB24 (see pixconv.h for the conventions).
 *
 * BT.601 limited range, from the luma weights Kr = 0.299, Kb = 0.114, Kg = 1 - Kr - Kb:
 *   Y' = (Y - 16) 255/219,  Cb = (U - 128) 255/224,  Cr = (V - 128) 255/224
 *   R = Y' + 2(1-Kr) Cr,  G = Y' - (2Kb(1-Kb) Cb + 2Kr(1-Kr) Cr) / Kg,  B = Y' + 2(1-Kb) Cb
 * and the inverse for RGB input. Fixed point with 14 fractional bits: every product fits in
 * int32 and the loops are plain element-wise code gcc vectorizes at -O3.
 *
 * About 610 lines in one file, on purpose: every row loop is a static function that the
 * dispatch (sh_pixconv_convert) must see to inline, and gcc's code for those loops changes
 * with what it sees around them (measured with objdump when the dispatch was split); one
 * translation unit per format would cut the loops from the dispatch or copy the plane set-up. */
#include "stillheart/pixconv.h"

#include <stdlib.h>
#include <string.h>
#include <strings.h>

#include <linux/videodev2.h>

#ifdef SH_HAVE_TURBOJPEG
#include <turbojpeg.h>
#endif

/* The RGB24 loops read or write 3-byte pixels: gcc vectorizes their interleaving only with
 * byte shuffles (SSSE3 pshufb, AVX2), which x86-64's SSE2 baseline lacks. The frame loops below
 * are therefore built three times and the best one for the CPU is picked at load time (an
 * ifunc). The code is the same integer C in each, so the results are identical bit for bit.
 * AArch64 needs no clones: NEON's ld3/st3 are baseline and gcc uses them. */
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__)
#define SH_CLONES __attribute__((target_clones("avx2", "ssse3", "default")))
#else
#define SH_CLONES
#endif
/* Row kernels must be inlined into each clone to be built for its instruction set. */
#if defined(__GNUC__)
#define ROW static inline __attribute__((always_inline))
#else
#define ROW static inline
#endif

#define KR 0.299
#define KB 0.114
#define KG (1.0 - KR - KB)
#define SHIFT 14
#define FIX(x) ((int32_t)((x) * (1 << SHIFT) + ((x) < 0 ? -0.5 : 0.5)))
#define HALF (1 << (SHIFT - 1))

/* YUV -> RGB */
#define C_Y FIX(255.0 / 219.0)
#define C_RV FIX(2.0 * (1.0 - KR) * 255.0 / 224.0)
#define C_GU FIX(-2.0 * KB * (1.0 - KB) / KG * 255.0 / 224.0)
#define C_GV FIX(-2.0 * KR * (1.0 - KR) / KG * 255.0 / 224.0)
#define C_BU FIX(2.0 * (1.0 - KB) * 255.0 / 224.0)
/* RGB -> YUV */
#define C_YR FIX(KR * 219.0 / 255.0)
#define C_YG FIX(KG * 219.0 / 255.0)
#define C_YB FIX(KB * 219.0 / 255.0)
#define C_UR FIX(-KR / (2.0 * (1.0 - KB)) * 224.0 / 255.0)
#define C_UG FIX(-KG / (2.0 * (1.0 - KB)) * 224.0 / 255.0)
#define C_UB FIX(0.5 * 224.0 / 255.0)
#define C_VR FIX(0.5 * 224.0 / 255.0)
#define C_VG FIX(-KG / (2.0 * (1.0 - KR)) * 224.0 / 255.0)
#define C_VB FIX(-KB / (2.0 * (1.0 - KR)) * 224.0 / 255.0)

static inline uint8_t clip(int32_t v)
{
    v >>= SHIFT;
    return (uint8_t)(v < 0 ? 0 : v > 255 ? 255 : v);
}

static const struct {
    const char *name;
    uint32_t fourcc;
} formats[SH_RAW_COUNT] = {
    [SH_RAW_GREY] = {"GREY", V4L2_PIX_FMT_GREY},   [SH_RAW_YUYV] = {"YUYV", V4L2_PIX_FMT_YUYV},
    [SH_RAW_NV12] = {"NV12", V4L2_PIX_FMT_NV12},   [SH_RAW_RGB24] = {"RGB24", V4L2_PIX_FMT_RGB24},
    [SH_RAW_BGR24] = {"BGR24", V4L2_PIX_FMT_BGR24}, [SH_RAW_MJPEG] = {"MJPEG", V4L2_PIX_FMT_MJPEG},
    [SH_RAW_I420] = {"I420", V4L2_PIX_FMT_YUV420}, [SH_RAW_YUV444] = {"YUV444", V4L2_PIX_FMT_YUV444M},
};

const char *sh_rawfmt_name(sh_rawfmt format)
{
    return (unsigned)format < SH_RAW_COUNT ? formats[format].name : "unknown";
}

sh_status sh_rawfmt_parse(const char *name, sh_rawfmt *out)
{
    static const struct {
        const char *alias;
        sh_rawfmt f;
    } aliases[] = {{"gray8", SH_RAW_GREY}, {"gray", SH_RAW_GREY}, {"rgb", SH_RAW_RGB24},
                   {"bgr", SH_RAW_BGR24}, {"mjpg", SH_RAW_MJPEG}, {"jpeg", SH_RAW_MJPEG},
                   {"yuv420", SH_RAW_I420}, {"yuyv422", SH_RAW_YUYV}};
    if (!name || !out) return sh_error_set(SH_EINVAL, "pixel format: no name");
    for (int i = 0; i < SH_RAW_COUNT; i++)
        if (!strcasecmp(name, formats[i].name)) return *out = (sh_rawfmt)i, SH_OK;
    for (size_t i = 0; i < sizeof aliases / sizeof aliases[0]; i++)
        if (!strcasecmp(name, aliases[i].alias)) return *out = aliases[i].f, SH_OK;
    return sh_error_set(SH_EUNSUPPORTED,
                        "pixel format '%s' unknown (GREY, YUYV, NV12, RGB24, BGR24, MJPEG, I420, YUV444)",
                        name);
}

uint32_t sh_rawfmt_fourcc(sh_rawfmt format)
{
    return (unsigned)format < SH_RAW_COUNT ? formats[format].fourcc : 0;
}

sh_status sh_rawfmt_from_fourcc(uint32_t fourcc, sh_rawfmt *out)
{
    for (int i = 0; i < SH_RAW_COUNT; i++)
        if (formats[i].fourcc == fourcc) return *out = (sh_rawfmt)i, SH_OK;
    if (fourcc == V4L2_PIX_FMT_JPEG) return *out = SH_RAW_MJPEG, SH_OK;
    if (fourcc == V4L2_PIX_FMT_YUV444) return *out = SH_RAW_YUV444, SH_OK;
    return sh_error_set(SH_EUNSUPPORTED, "pixel format %c%c%c%c not supported", (char)(fourcc & 0xff),
                        (char)((fourcc >> 8) & 0xff), (char)((fourcc >> 16) & 0xff),
                        (char)((fourcc >> 24) & 0xff));
}

int sh_rawfmt_min_stride(sh_rawfmt format, int width)
{
    if (width <= 0 || width > SH_IMAGE_MAX_SIZE) return 0;
    switch (format) {
    case SH_RAW_GREY: case SH_RAW_NV12: case SH_RAW_I420: case SH_RAW_YUV444: return width;
    case SH_RAW_YUYV: return 2 * width;
    case SH_RAW_RGB24: case SH_RAW_BGR24: return 3 * width;
    default: return 0;
    }
}

static int even_needed(sh_rawfmt f) { return f == SH_RAW_YUYV || f == SH_RAW_NV12 || f == SH_RAW_I420; }

size_t sh_raw_frame_size(sh_rawfmt format, int width, int height, int stride)
{
    int min = sh_rawfmt_min_stride(format, width);
    if (!min || stride < min || height <= 0 || height > SH_IMAGE_MAX_SIZE) return 0;
    if (even_needed(format) && ((width | height) & 1)) return 0;
    size_t rows = (size_t)stride * (size_t)height;
    switch (format) {
    case SH_RAW_NV12: return rows + rows / 2;
    case SH_RAW_I420: return rows + 2 * ((size_t)(stride / 2) * (size_t)(height / 2));
    case SH_RAW_YUV444: return 3 * rows;
    default: return rows;
    }
}

sh_status sh_raw_check(const sh_raw *s)
{
    if (!s || (unsigned)s->format >= SH_RAW_COUNT)
        return sh_error_set(SH_EINVAL, "raw frame: bad format");
    if (s->width <= 0 || s->height <= 0 || s->width > SH_IMAGE_MAX_SIZE || s->height > SH_IMAGE_MAX_SIZE)
        return sh_error_set(SH_EFORMAT, "raw %s frame: bad size %dx%d", sh_rawfmt_name(s->format),
                            s->width, s->height);
    if (!s->data) return sh_error_set(SH_EINVAL, "raw frame: no data");
    if (s->format == SH_RAW_MJPEG) return s->bytes ? SH_OK : sh_error_set(SH_EFORMAT, "MJPEG frame: empty");
    if (even_needed(s->format) && ((s->width | s->height) & 1))
        return sh_error_set(SH_EFORMAT, "raw %s frame: odd size %dx%d", sh_rawfmt_name(s->format),
                            s->width, s->height);
    size_t need = sh_raw_frame_size(s->format, s->width, s->height, s->stride);
    if (!need)
        return sh_error_set(SH_EFORMAT, "raw %s frame: stride %d too small for width %d",
                            sh_rawfmt_name(s->format), s->stride, s->width);
    if (s->bytes < need)
        return sh_error_set(SH_EFORMAT, "raw %s frame %dx%d: %zu bytes, %zu needed", sh_rawfmt_name(s->format),
                            s->width, s->height, s->bytes, need);
    return SH_OK;
}

/* ---- row kernels ---- */

static void yuyv_row_gray(const uint8_t *restrict s, uint8_t *restrict y, int w)
{
    for (int x = 0; x < w; x++) y[x] = s[2 * x];
}

/* YUV 4:2:x rows to RGB24 in chunks: the samples are first gathered into int16 arrays, the chroma
 * terms computed once per chroma sample, the pixels as int16 x int16 -> int32 products (gcc turns
 * these into SSE2/NEON widening multiplies), then interleaved. 13 fractional bits keep every
 * coefficient within int16. Strides are compile-time constants at each call (inlined). */
#define CS 13
#define FIX13(x) ((int16_t)((x) * (1 << CS) + ((x) < 0 ? -0.5 : 0.5)))
#define CHUNK 128

static inline uint8_t clip13(int32_t v)
{
    v >>= CS;
    return (uint8_t)(v < 0 ? 0 : v > 255 ? 255 : v);
}

ROW void yuv422_row_rgb(const uint8_t *restrict y, int ystep, const uint8_t *restrict u,
                                  const uint8_t *restrict v, int cstep, uint8_t *restrict o, int w)
{
    const int16_t cy = FIX13(255.0 / 219.0), crv = FIX13(2.0 * (1.0 - KR) * 255.0 / 224.0),
                  cgu = FIX13(-2.0 * KB * (1.0 - KB) / KG * 255.0 / 224.0),
                  cgv = FIX13(-2.0 * KR * (1.0 - KR) / KG * 255.0 / 224.0),
                  cbu = FIX13(2.0 * (1.0 - KB) * 255.0 / 224.0);
    int16_t Y[CHUNK], U[CHUNK / 2], V[CHUNK / 2];
    int32_t tr[CHUNK], tg[CHUNK], tb[CHUNK]; /* per pixel: each chroma term written twice */
    uint8_t R[CHUNK], G[CHUNK], B[CHUNK];
    for (int x0 = 0; x0 < w; x0 += CHUNK) {
        int n = w - x0 < CHUNK ? w - x0 : CHUNK, c0 = x0 / 2;
        for (int i = 0; i < n; i++) Y[i] = (int16_t)(y[(x0 + i) * ystep] - 16);
        for (int i = 0; i < n / 2; i++) {
            U[i] = (int16_t)(u[(c0 + i) * cstep] - 128);
            V[i] = (int16_t)(v[(c0 + i) * cstep] - 128);
        }
        for (int i = 0; i < n / 2; i++) {
            tr[2 * i] = tr[2 * i + 1] = (int32_t)V[i] * crv + (1 << (CS - 1));
            tg[2 * i] = tg[2 * i + 1] = (int32_t)U[i] * cgu + (int32_t)V[i] * cgv + (1 << (CS - 1));
            tb[2 * i] = tb[2 * i + 1] = (int32_t)U[i] * cbu + (1 << (CS - 1));
        }
        for (int i = 0; i < n; i++) {
            int32_t yy = (int32_t)Y[i] * cy;
            R[i] = clip13(yy + tr[i]);
            G[i] = clip13(yy + tg[i]);
            B[i] = clip13(yy + tb[i]);
        }
        uint8_t *q = o + 3 * x0;
        for (int i = 0; i < n; i++) {
            q[3 * i] = R[i];
            q[3 * i + 1] = G[i];
            q[3 * i + 2] = B[i];
        }
    }
}

ROW void yuyv_row_rgb(const uint8_t *restrict s, uint8_t *restrict o, int w)
{
    yuv422_row_rgb(s, 2, s + 1, s + 3, 4, o, w);
}

/* YUV444 (replay only): one chroma sample per pixel. */
static void yuv_pair_rgb(uint8_t *restrict o, int y, int u, int v)
{
    int32_t yy = C_Y * (y - 16) + HALF;
    int32_t r = C_RV * (v - 128), g = C_GU * (u - 128) + C_GV * (v - 128), b = C_BU * (u - 128);
    o[0] = clip(yy + r);
    o[1] = clip(yy + g);
    o[2] = clip(yy + b);
}

ROW void rgb_row_y(const uint8_t *restrict s, int ri, int bi, uint8_t *restrict y, int w)
{
    for (int x = 0; x < w; x++) {
        int32_t v = C_YR * s[3 * x + ri] + C_YG * s[3 * x + 1] + C_YB * s[3 * x + bi] + (16 << SHIFT) + HALF;
        y[x] = (uint8_t)(v >> SHIFT); /* 16..235 by construction */
    }
}

/* Chroma of a 2x2 block from the sums of R, G, B over it (sums of 4: one more factor 1/4). The
 * two rows are first summed and de-interleaved into int16 arrays, a chunk at a time (stride-3
 * loads, which the clones vectorize), then the pairs summed (stride 2). */
ROW void rgb_rows_uv(const uint8_t *restrict s0, const uint8_t *restrict s1, int ri, int bi,
                     uint8_t *restrict u, uint8_t *restrict v, int cw)
{
    int16_t R[CHUNK], G[CHUNK], B[CHUNK];
    for (int c0 = 0; c0 < cw; c0 += CHUNK / 2) {
        const int n = cw - c0 < CHUNK / 2 ? cw - c0 : CHUNK / 2;
        const uint8_t *restrict a = s0 + 6 * (size_t)c0, *restrict b = s1 + 6 * (size_t)c0;
        for (int i = 0; i < 2 * n; i++) {
            R[i] = (int16_t)(a[3 * i + ri] + b[3 * i + ri]);
            G[i] = (int16_t)(a[3 * i + 1] + b[3 * i + 1]);
            B[i] = (int16_t)(a[3 * i + bi] + b[3 * i + bi]);
        }
        for (int x = 0; x < n; x++) {
            int32_t r = R[2 * x] + R[2 * x + 1], g = G[2 * x] + G[2 * x + 1], bb = B[2 * x] + B[2 * x + 1];
            int32_t uu = C_UR * r + C_UG * g + C_UB * bb + (128 << (SHIFT + 2)) + (1 << (SHIFT + 1));
            int32_t vv = C_VR * r + C_VG * g + C_VB * bb + (128 << (SHIFT + 2)) + (1 << (SHIFT + 1));
            u[c0 + x] = (uint8_t)(uu >> (SHIFT + 2));
            v[c0 + x] = (uint8_t)(vv >> (SHIFT + 2));
        }
    }
}

/* ---- frame loops (cloned per instruction set; the row kernels inline into each clone) ---- */

SH_CLONES static void frame_yuyv_rgb(const uint8_t *src, int ss, uint8_t *dst, int ds, int w, int h)
{
    for (int y = 0; y < h; y++) yuyv_row_rgb(src + (size_t)y * ss, dst + (size_t)y * ds, w);
}

/* 4:2:0 (NV12: cstep 2, I420: cstep 1) to RGB24: each chroma row serves two luma rows. */
SH_CLONES static void frame_yuv420_rgb(const uint8_t *src, int ss, const uint8_t *cb, const uint8_t *cr, int cs,
                                       int cstep, uint8_t *dst, int ds, int w, int h)
{
    for (int y = 0; y < h; y++) {
        const uint8_t *yr = src + (size_t)y * ss, *ur = cb + (size_t)(y >> 1) * cs, *vr = cr + (size_t)(y >> 1) * cs;
        if (cstep == 2) yuv422_row_rgb(yr, 1, ur, vr, 2, dst + (size_t)y * ds, w);
        else yuv422_row_rgb(yr, 1, ur, vr, 1, dst + (size_t)y * ds, w);
    }
}

/* RGB24 or BGR24 (ri = 0 or 2) to BT.601 luma, and to 2x2 chroma when U and V are given. */
SH_CLONES static void frame_rgb_yuv(const uint8_t *src, int ss, int ri, uint8_t *Y, int ys, uint8_t *U, int us,
                                    uint8_t *V, int vs, int w, int h)
{
    for (int y = 0; y < h; y++) {
        if (ri == 0) rgb_row_y(src + (size_t)y * ss, 0, 2, Y + (size_t)y * ys, w);
        else rgb_row_y(src + (size_t)y * ss, 2, 0, Y + (size_t)y * ys, w);
    }
    if (!U) return;
    for (int y = 0; y < h / 2; y++) {
        const uint8_t *r0 = src + (size_t)(2 * y) * ss;
        if (ri == 0) rgb_rows_uv(r0, r0 + ss, 0, 2, U + (size_t)y * us, V + (size_t)y * vs, w / 2);
        else rgb_rows_uv(r0, r0 + ss, 2, 0, U + (size_t)y * us, V + (size_t)y * vs, w / 2);
    }
}

SH_CLONES static void frame_bgr_rgb(const uint8_t *src, int ss, uint8_t *dst, int ds, int w, int h)
{
    for (int y = 0; y < h; y++) {
        const uint8_t *restrict r = src + (size_t)y * ss;
        uint8_t *restrict o = dst + (size_t)y * ds;
        for (int x = 0; x < w; x++) {
            o[3 * x] = r[3 * x + 2];
            o[3 * x + 1] = r[3 * x + 1];
            o[3 * x + 2] = r[3 * x];
        }
    }
}

SH_CLONES static void frame_grey_rgb(const uint8_t *src, int ss, uint8_t *dst, int ds, int w, int h)
{
    for (int y = 0; y < h; y++) {
        const uint8_t *restrict r = src + (size_t)y * ss;
        uint8_t *restrict o = dst + (size_t)y * ds;
        for (int x = 0; x < w; x++) o[3 * x] = o[3 * x + 1] = o[3 * x + 2] = r[x];
    }
}

static void copy_rows(const uint8_t *s, int ss, uint8_t *d, int ds, int bytes, int rows)
{
    for (int r = 0; r < rows; r++) memcpy(d + (size_t)r * ds, s + (size_t)r * ss, (size_t)bytes);
}

static void fill_rows(uint8_t *d, int ds, int bytes, int rows, uint8_t value)
{
    for (int r = 0; r < rows; r++) memset(d + (size_t)r * ds, value, (size_t)bytes);
}

/* ---- MJPEG ---- */

struct sh_pixconv {
    int max_w, max_h;
    uint8_t *scratch; /* native-subsampling planes of one frame */
#ifdef SH_HAVE_TURBOJPEG
    tjhandle tj;
#endif
};

sh_status sh_pixconv_create(int max_width, int max_height, sh_pixconv **out)
{
    if (!out || max_width <= 0 || max_height <= 0 || max_width > SH_IMAGE_MAX_SIZE ||
        max_height > SH_IMAGE_MAX_SIZE)
        return sh_error_set(SH_EINVAL, "pixconv: bad maximum size %dx%d", max_width, max_height);
    sh_pixconv *c = calloc(1, sizeof *c);
    if (!c) return sh_error_set(SH_ENOMEM, "pixconv: out of memory");
    c->max_w = max_width;
    c->max_h = max_height;
    /* 4:4:4 planes, rounded up to the MCU (16 px) in each direction. */
    size_t w16 = ((size_t)max_width + 15) & ~(size_t)15, h16 = ((size_t)max_height + 15) & ~(size_t)15;
    c->scratch = malloc(3 * w16 * h16);
#ifdef SH_HAVE_TURBOJPEG
    c->tj = tjInitDecompress();
    if (!c->scratch || !c->tj) {
        sh_pixconv_destroy(c);
        return sh_error_set(SH_ENOMEM, "pixconv: cannot create the JPEG decoder");
    }
#else
    if (!c->scratch) {
        sh_pixconv_destroy(c);
        return sh_error_set(SH_ENOMEM, "pixconv: out of memory");
    }
#endif
    *out = c;
    return SH_OK;
}

void sh_pixconv_destroy(sh_pixconv *c)
{
    if (!c) return;
#ifdef SH_HAVE_TURBOJPEG
    if (c->tj) tjDestroy(c->tj);
#endif
    free(c->scratch);
    free(c);
}

#ifdef SH_HAVE_TURBOJPEG
static sh_status mjpeg_convert(sh_pixconv *c, const sh_raw *s, sh_image *d)
{
    if (!c) return sh_error_set(SH_EINVAL, "MJPEG: no decoder (sh_pixconv_create)");
    int w, h, sub, cs;
    if (tjDecompressHeader3(c->tj, s->data, (unsigned long)s->bytes, &w, &h, &sub, &cs) != 0)
        return sh_error_set(SH_EFORMAT, "MJPEG frame: %s", tjGetErrorStr2(c->tj));
    if (w != s->width || h != s->height)
        return sh_error_set(SH_EFORMAT, "MJPEG frame is %dx%d, %dx%d expected", w, h, s->width, s->height);
    if (w > c->max_w || h > c->max_h)
        return sh_error_set(SH_ERANGE, "MJPEG frame %dx%d larger than %dx%d", w, h, c->max_w, c->max_h);
    int flags = TJFLAG_NOREALLOC | TJFLAG_STOPONWARNING;
    if (d->format == SH_PIX_RGB24 || d->format == SH_PIX_GRAY8) {
        int pf = d->format == SH_PIX_RGB24 ? TJPF_RGB : TJPF_GRAY;
        if (tjDecompress2(c->tj, s->data, (unsigned long)s->bytes, d->plane[0].data, w, d->plane[0].stride, h,
                          pf, flags) != 0)
            return sh_error_set(SH_EFORMAT, "MJPEG frame: %s", tjGetErrorStr2(c->tj));
        return SH_OK;
    }
    /* I420 */
    d->siting = SH_CHROMA_CENTER;
    if (sub == TJSAMP_420) {
        unsigned char *planes[3] = {d->plane[0].data, d->plane[1].data, d->plane[2].data};
        int strides[3] = {d->plane[0].stride, d->plane[1].stride, d->plane[2].stride};
        if (tjDecompressToYUVPlanes(c->tj, s->data, (unsigned long)s->bytes, planes, w, strides, h, flags) != 0)
            return sh_error_set(SH_EFORMAT, "MJPEG frame: %s", tjGetErrorStr2(c->tj));
        return SH_OK;
    }
    if (sub == TJSAMP_GRAY) {
        unsigned char *planes[3] = {d->plane[0].data, NULL, NULL};
        int strides[3] = {d->plane[0].stride, 0, 0};
        if (tjDecompressToYUVPlanes(c->tj, s->data, (unsigned long)s->bytes, planes, w, strides, h, flags) != 0)
            return sh_error_set(SH_EFORMAT, "MJPEG frame: %s", tjGetErrorStr2(c->tj));
        fill_rows(d->plane[1].data, d->plane[1].stride, d->plane[1].width, d->plane[1].height, 128);
        fill_rows(d->plane[2].data, d->plane[2].stride, d->plane[2].width, d->plane[2].height, 128);
        return SH_OK;
    }
    if (sub != TJSAMP_422 && sub != TJSAMP_444)
        return sh_error_set(SH_EUNSUPPORTED, "MJPEG frame: chroma subsampling %d not supported", sub);
    int cw = tjPlaneWidth(1, w, sub), chh = tjPlaneHeight(1, h, sub);
    unsigned char *planes[3] = {d->plane[0].data, c->scratch, c->scratch + (size_t)cw * chh};
    int strides[3] = {d->plane[0].stride, cw, cw};
    if (tjDecompressToYUVPlanes(c->tj, s->data, (unsigned long)s->bytes, planes, w, strides, h, flags) != 0)
        return sh_error_set(SH_EFORMAT, "MJPEG frame: %s", tjGetErrorStr2(c->tj));
    int hs = sub == TJSAMP_444 ? 2 : 1; /* horizontal step in the native plane */
    for (int p = 1; p <= 2; p++) {
        sh_plane *o = &d->plane[p];
        for (int y = 0; y < o->height; y++) {
            const uint8_t *r0 = planes[p] + (size_t)(2 * y) * cw;
            const uint8_t *r1 = planes[p] + (size_t)(2 * y + 1 < chh ? 2 * y + 1 : 2 * y) * cw;
            uint8_t *q = o->data + (size_t)y * o->stride;
            if (hs == 1) {
                for (int x = 0; x < o->width; x++) q[x] = (uint8_t)((r0[x] + r1[x] + 1) >> 1);
            } else {
                for (int x = 0; x < o->width; x++) {
                    int x1 = 2 * x + 1 < cw ? 2 * x + 1 : 2 * x;
                    q[x] = (uint8_t)((r0[2 * x] + r0[x1] + r1[2 * x] + r1[x1] + 2) >> 2);
                }
            }
        }
    }
    return SH_OK;
}
#endif

/* ---- dispatch ---- */

/* The dispatch's own loops, moved out as they were. Not cloned (SH_CLONES) and always inlined:
 * gcc builds sh_pixconv_convert as when they were written in it (objdump: the same instructions,
 * a few registers aside). */

/* YUYV's chroma, each pair of rows averaged: I420 with the 4:2:2 samples' left siting. */
ROW void frame_yuyv_chroma(const uint8_t *src, int ss, uint8_t *U, int us, uint8_t *V, int vs, int cw, int ch)
{
    for (int y = 0; y < ch; y++) {
        const uint8_t *r0 = src + (size_t)(2 * y) * ss, *r1 = r0 + ss;
        uint8_t *u = U + (size_t)y * us, *v = V + (size_t)y * vs;
        for (int x = 0; x < cw; x++) {
            u[x] = (uint8_t)((r0[4 * x + 1] + r1[4 * x + 1] + 1) >> 1);
            v[x] = (uint8_t)((r0[4 * x + 3] + r1[4 * x + 3] + 1) >> 1);
        }
    }
}

/* 4:2:0 chroma already at I420's size: copied, or de-interleaved (NV12: step 2). */
ROW void frame_yuv420_chroma(const uint8_t *cb, const uint8_t *cr, int cs, int step, uint8_t *U, int us,
                             uint8_t *V, int vs, int cw, int ch)
{
    for (int y = 0; y < ch; y++) {
        const uint8_t *b = cb + (size_t)y * cs, *r = cr + (size_t)y * cs;
        uint8_t *u = U + (size_t)y * us, *v = V + (size_t)y * vs;
        for (int x = 0; x < cw; x++) {
            u[x] = b[x * step];
            v[x] = r[x * step];
        }
    }
}

ROW void frame_yuv444_rgb(const uint8_t *src, const uint8_t *cb, const uint8_t *cr, int ss, uint8_t *Y, int ys,
                          int w, int h)
{
    for (int y = 0; y < h; y++) {
        const uint8_t *yr = src + (size_t)y * ss, *ur = cb + (size_t)y * ss, *vr = cr + (size_t)y * ss;
        uint8_t *o = Y + (size_t)y * ys;
        for (int x = 0; x < w; x++) yuv_pair_rgb(o + 3 * x, yr[x], ur[x], vr[x]);
    }
}

/* 4:4:4 chroma to I420: each 2x2 block averaged (centre siting). */
ROW void frame_yuv444_chroma(const uint8_t *cb, const uint8_t *cr, int ss, uint8_t *U, int us, uint8_t *V, int vs,
                             int cw, int ch)
{
    for (int p = 0; p < 2; p++) {
        const uint8_t *pl = p ? cr : cb;
        uint8_t *o = p ? V : U;
        int os = p ? vs : us;
        for (int y = 0; y < ch; y++) {
            const uint8_t *r0 = pl + (size_t)(2 * y) * ss, *r1 = r0 + ss;
            uint8_t *q = o + (size_t)y * os;
            for (int x = 0; x < cw; x++)
                q[x] = (uint8_t)((r0[2 * x] + r0[2 * x + 1] + r1[2 * x] + r1[2 * x + 1] + 2) >> 2);
        }
    }
}

/* About 95 lines on purpose: the checks, the plane set-up, then one flat case per camera format,
 * each the same steps (the RGB24 loop, else the luma plane, then I420's chroma and its siting).
 * Split per format, each piece would repeat the set-up; the checks in a function of their own,
 * even an inlined one, change gcc's register allocation of the whole function, loops included. */
sh_status sh_pixconv_convert(sh_pixconv *conv, const sh_raw *s, sh_image *d)
{
    sh_status st = sh_raw_check(s);
    if (st != SH_OK) return st;
    if (!d || d->width != s->width || d->height != s->height)
        return sh_error_set(SH_EINVAL, "pixconv: destination is not %dx%d", s->width, s->height);
    if (d->format != SH_PIX_GRAY8 && d->format != SH_PIX_I420 && d->format != SH_PIX_RGB24)
        return sh_error_set(SH_EUNSUPPORTED, "pixconv: destination %s not supported", sh_pixfmt_name(d->format));
    if (d->format == SH_PIX_I420 && ((s->width | s->height) & 1))
        return sh_error_set(SH_EUNSUPPORTED, "pixconv: I420 needs an even size, not %dx%d", s->width, s->height);
    const int w = s->width, h = s->height, ss = s->stride;
    const uint8_t *src = s->data;
    uint8_t *Y = d->plane[0].data;
    const int ys = d->plane[0].stride;
    uint8_t *U = d->num_planes > 1 ? d->plane[1].data : NULL, *V = d->num_planes > 2 ? d->plane[2].data : NULL;
    const int us = d->num_planes > 1 ? d->plane[1].stride : 0, vs = d->num_planes > 2 ? d->plane[2].stride : 0;
    const int cw = w / 2, ch = h / 2;

    switch (s->format) {
    case SH_RAW_MJPEG:
#ifdef SH_HAVE_TURBOJPEG
        return mjpeg_convert(conv, s, d);
#else
        (void)conv;
        return sh_error_set(SH_EUNSUPPORTED, "MJPEG: built without libturbojpeg");
#endif
    case SH_RAW_GREY:
        if (d->format == SH_PIX_RGB24) {
            frame_grey_rgb(src, ss, Y, ys, w, h);
            return SH_OK;
        }
        copy_rows(src, ss, Y, ys, w, h);
        if (d->format == SH_PIX_I420) {
            d->siting = SH_CHROMA_CENTER;
            fill_rows(U, us, cw, ch, 128);
            fill_rows(V, vs, cw, ch, 128);
        }
        return SH_OK;
    case SH_RAW_YUYV:
        if (d->format == SH_PIX_RGB24) {
            frame_yuyv_rgb(src, ss, Y, ys, w, h);
            return SH_OK;
        }
        for (int y = 0; y < h; y++) yuyv_row_gray(src + (size_t)y * ss, Y + (size_t)y * ys, w);
        if (d->format == SH_PIX_I420) {
            d->siting = SH_CHROMA_LEFT;
            frame_yuyv_chroma(src, ss, U, us, V, vs, cw, ch);
        }
        return SH_OK;
    case SH_RAW_NV12:
    case SH_RAW_I420: {
        const uint8_t *cb = src + (size_t)ss * h, *cr;
        int cs, step;
        if (s->format == SH_RAW_NV12) cs = ss, step = 2, cr = cb + 1;
        else cs = ss / 2, step = 1, cr = cb + (size_t)cs * ch;
        if (d->format == SH_PIX_RGB24) {
            frame_yuv420_rgb(src, ss, cb, cr, cs, step, Y, ys, w, h);
            return SH_OK;
        }
        copy_rows(src, ss, Y, ys, w, h);
        if (d->format == SH_PIX_I420) {
            d->siting = s->format == SH_RAW_NV12 ? SH_CHROMA_LEFT : SH_CHROMA_CENTER;
            frame_yuv420_chroma(cb, cr, cs, step, U, us, V, vs, cw, ch);
        }
        return SH_OK;
    }
    case SH_RAW_YUV444: {
        const uint8_t *cb = src + (size_t)ss * h, *cr = cb + (size_t)ss * h;
        if (d->format == SH_PIX_RGB24) {
            frame_yuv444_rgb(src, cb, cr, ss, Y, ys, w, h);
            return SH_OK;
        }
        copy_rows(src, ss, Y, ys, w, h);
        if (d->format == SH_PIX_I420) {
            d->siting = SH_CHROMA_CENTER;
            frame_yuv444_chroma(cb, cr, ss, U, us, V, vs, cw, ch);
        }
        return SH_OK;
    }
    case SH_RAW_RGB24:
    case SH_RAW_BGR24: {
        int ri = s->format == SH_RAW_RGB24 ? 0 : 2;
        if (d->format == SH_PIX_RGB24) {
            if (ri == 0) copy_rows(src, ss, Y, ys, 3 * w, h);
            else frame_bgr_rgb(src, ss, Y, ys, w, h);
            return SH_OK;
        }
        if (d->format == SH_PIX_I420) d->siting = SH_CHROMA_CENTER;
        frame_rgb_yuv(src, ss, ri, Y, ys, d->format == SH_PIX_I420 ? U : NULL, us, V, vs, w, h);
        return SH_OK;
    }
    default:
        return sh_error_set(SH_EINVAL, "pixconv: bad source format");
    }
}
