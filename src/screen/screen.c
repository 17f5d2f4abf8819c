/* Scaling, letterboxing and the status overlay into an XRGB8888 buffer (screen.h). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "stillheart/screen.h"
#include "screen_internal.h"

static int imax(int a, int b) { return a > b ? a : b; }
static int imin(int a, int b) { return a < b ? a : b; }

/* The badge's text: the longest status word sets its size for every status. */
#define BADGE_CELLS 10 /* "STABILIZED" */

sh_screen_layout sh_screen_layout_for(int frame_w, int frame_h, int screen_w, int screen_h)
{
    sh_screen_layout l;
    memset(&l, 0, sizeof l);
    l.border = imax(2, screen_h / 160);
    l.scale = imax(1, screen_h / 240);
    if (frame_w > 0 && frame_h > 0 && screen_w > 0 && screen_h > 0) {
        long long fw = frame_w, fh = frame_h, sw = screen_w, sh = screen_h;
        int pw, ph;
        if (fw * sh <= fh * sw) { /* as tall as the screen, bars left and right */
            ph = screen_h;
            pw = (int)((2 * fw * sh + fh) / (2 * fh));
        } else {                  /* as wide as the screen, bars above and below */
            pw = screen_w;
            ph = (int)((2 * fh * sw + fw) / (2 * fw));
        }
        pw = imin(imax(pw, 1), screen_w);
        ph = imin(imax(ph, 1), screen_h);
        l.picture = (sh_screen_rect){(screen_w - pw) / 2, (screen_h - ph) / 2, pw, ph};
    }
    int pad = 2 * l.scale;
    l.badge = (sh_screen_rect){l.picture.x + l.border + pad, l.picture.y + l.border + pad,
                               BADGE_CELLS * SH_SCREEN_CELL_W * l.scale + pad, 7 * l.scale + 2 * pad};
    return l;
}

int sh_screen_overlay_parse(const char *text, sh_screen_overlay *out)
{
    static const char *const names[] = {"off", "minimal", "full"};
    for (int i = 0; i < 3; i++)
        if (text && !strcmp(text, names[i])) {
            *out = (sh_screen_overlay)i;
            return 1;
        }
    return 0;
}

const char *sh_screen_overlay_name(sh_screen_overlay overlay)
{
    return overlay == SH_SCREEN_OVERLAY_OFF ? "off" : overlay == SH_SCREEN_OVERLAY_MINIMAL ? "minimal" : "full";
}

uint32_t sh_screen_status_colour(uint32_t status)
{
    return status == 1 ? SH_SCREEN_STABILIZED : status == 2 ? SH_SCREEN_DEGRADED : SH_SCREEN_RAW;
}

const char *sh_screen_status_word(uint32_t status)
{
    return status == 1 ? "STABILIZED" : status == 2 ? "DEGRADED" : "RAW";
}

void sh_screen_fill(const sh_screen_buffer *dst, sh_screen_rect r, uint32_t colour)
{
    int x0 = imax(r.x, 0), y0 = imax(r.y, 0);
    int x1 = imin(r.x + r.width, dst->width), y1 = imin(r.y + r.height, dst->height);
    for (int y = y0; y < y1; y++) {
        uint32_t *row = (uint32_t *)((uint8_t *)dst->pixels + (size_t)y * (size_t)dst->stride);
        for (int x = x0; x < x1; x++) row[x] = colour;
    }
}

int sh_screen_draw_text(const sh_screen_buffer *dst, int x, int y, int scale, uint32_t colour,
                        const char *text, int cap)
{
    int n = 0;
    for (; n < cap && text[n]; n++) {
        const uint8_t *g = sh_screen_glyph((unsigned char)text[n]);
        int cx = x + n * SH_SCREEN_CELL_W * scale;
        for (int r = 0; r < 7; r++)
            for (int k = 0; k < 5; k++)
                if (g[r] & (0x10 >> k))
                    sh_screen_fill(dst, (sh_screen_rect){cx + k * scale, y + r * scale, scale, scale}, colour);
    }
    return n * SH_SCREEN_CELL_W * scale;
}

/* BT.601 YUV to RGB in 16.16 fixed point: multiplies and adds on int32 that the compiler
 * vectorizes (make bench: bench_screen), exact to the last bit against the formula's rounding
 * but for ties. */
typedef struct {
    int32_t y0, ky, rv, gu, gv, bu;
} yuv_coeffs;

static yuv_coeffs coeffs(int full_range)
{
    double ky = full_range ? 1.0 : 255.0 / 219.0, kc = full_range ? 1.0 : 255.0 / 224.0;
    return (yuv_coeffs){full_range ? 0 : 16, (int32_t)lrint(ky * 65536), (int32_t)lrint(1.402 * kc * 65536),
                        (int32_t)lrint(-0.344136 * kc * 65536), (int32_t)lrint(-0.714136 * kc * 65536),
                        (int32_t)lrint(1.772 * kc * 65536)};
}

static inline uint32_t clamp8(int32_t v)
{
    v = v < 0 ? 0 : v;
    v = v > (255 << 16) ? (255 << 16) : v;
    return (uint32_t)v >> 16;
}

/* With x86-64's SSE2 baseline gcc vectorizes the 32-bit multiplies below by pmuludq pairs: a
 * 1080p I420 frame took 2.9 ms, against 1.3 ms for OpenCV's cvtColor, and at 1080p60 every
 * millisecond here is one of publish-to-flip latency (docs/display.md). Built also for AVX2
 * (vpmulld, 8 lanes) and picked at load time (an ifunc, as src/pixconv does), it takes 1.0 ms
 * (make bench: bench_screen). The same integer C in each clone: equal bit for bit. AArch64
 * needs no clone: NEON multiplies 32-bit lanes in its baseline. */
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__)
#define SCREEN_CLONES __attribute__((target_clones("avx2", "default")))
#else
#define SCREEN_CLONES
#endif

/* One frame row (sy) converted to XRGB8888, every pixel of it (n = frame width). */
SCREEN_CLONES static void convert_row(uint32_t *restrict out, const sh_image *f, int sy, const yuv_coeffs *c)
{
    const int n = f->width;
    const uint8_t *restrict p0 = f->plane[0].data + (size_t)sy * (size_t)f->plane[0].stride;
    if (f->format == SH_PIX_RGB24) {
        for (int x = 0; x < n; x++)
            out[x] = (uint32_t)p0[3 * x] << 16 | (uint32_t)p0[3 * x + 1] << 8 | p0[3 * x + 2];
        return;
    }
    const int32_t ky = c->ky, y0 = c->y0, rv = c->rv, gu = c->gu, gv = c->gv, bu = c->bu;
    if (f->format == SH_PIX_GRAY8) {
        for (int x = 0; x < n; x++) {
            uint32_t l = clamp8((p0[x] - y0) * ky + 32768);
            out[x] = l << 16 | l << 8 | l;
        }
        return;
    }
    const int half = f->format == SH_PIX_I420, cy = half ? sy >> 1 : sy;
    const uint8_t *restrict pu = f->plane[1].data + (size_t)cy * (size_t)f->plane[1].stride;
    const uint8_t *restrict pv = f->plane[2].data + (size_t)cy * (size_t)f->plane[2].stride;
    if (!half) {
        for (int x = 0; x < n; x++) {
            int32_t l = (p0[x] - y0) * ky + 32768, u = pu[x] - 128, v = pv[x] - 128;
            out[x] = clamp8(l + rv * v) << 16 | clamp8(l + gu * u + gv * v) << 8 | clamp8(l + bu * u);
        }
        return;
    }
    /* I420: two luma samples per chroma sample, the chroma terms once per pair */
    for (int i = 0; i < n / 2; i++) {
        int32_t u = pu[i] - 128, v = pv[i] - 128;
        int32_t r = rv * v, g = gu * u + gv * v, b = bu * u;
        int32_t l0 = (p0[2 * i] - y0) * ky + 32768, l1 = (p0[2 * i + 1] - y0) * ky + 32768;
        out[2 * i] = clamp8(l0 + r) << 16 | clamp8(l0 + g) << 8 | clamp8(l0 + b);
        out[2 * i + 1] = clamp8(l1 + r) << 16 | clamp8(l1 + g) << 8 | clamp8(l1 + b);
    }
    if (n & 1) {
        int32_t u = pu[n / 2] - 128, v = pv[n / 2] - 128, l = (p0[n - 1] - y0) * ky + 32768;
        out[n - 1] = clamp8(l + rv * v) << 16 | clamp8(l + gu * u + gv * v) << 8 | clamp8(l + bu * u);
    }
}

/* The picture row from a converted frame row: nearest sample by a DDA (sx = floor((2x + 1) fw /
 * (2 pw)) without a division per pixel). */
static void sample_row(uint32_t *restrict out, int pw, const uint32_t *restrict row, int fw)
{
    long long den = 2LL * pw, step = 2LL * fw, rem = fw % den;
    int sx = (int)(fw / den);
    for (int x = 0; x < pw; x++) {
        out[x] = row[sx];
        for (rem += step; rem >= den; rem -= den) sx++;
    }
}

sh_status sh_screen_draw_frame(const sh_screen_buffer *dst, const sh_screen_layout *layout,
                               const sh_image *frame, int full_range)
{
    return sh_screen_draw_frame_band(dst, layout, frame, full_range, 0, dst->height);
}

sh_status sh_screen_draw_frame_band(const sh_screen_buffer *dst, const sh_screen_layout *layout,
                                    const sh_image *frame, int full_range, int y0, int y1)
{
    /* a frame as wide as the picture is converted straight into it; any other through one row */
    uint32_t *row = NULL;
    if (frame->width > 0 && frame->width != layout->picture.width &&
        !(row = malloc((size_t)frame->width * sizeof *row)))
        return sh_error_set(SH_ENOMEM, "screen: out of memory for a %d-pixel row", frame->width);
    sh_status st = screen_draw_band(dst, layout, frame, full_range, y0, y1, row);
    free(row);
    return st;
}

sh_status screen_draw_band(const sh_screen_buffer *dst, const sh_screen_layout *layout, const sh_image *frame,
                           int full_range, int y0, int y1, uint32_t *row)
{
    const sh_screen_rect p = layout->picture;
    if (!dst->pixels || dst->stride < dst->width * 4 || p.x < 0 || p.y < 0 || p.width < 1 || p.height < 1 ||
        p.x + p.width > dst->width || p.y + p.height > dst->height)
        return sh_error_set(SH_EINVAL, "screen: picture %dx%d+%d+%d does not fit a %dx%d buffer",
                            p.width, p.height, p.x, p.y, dst->width, dst->height);
    if (frame->format != SH_PIX_GRAY8 && frame->format != SH_PIX_I420 && frame->format != SH_PIX_YUV444 &&
        frame->format != SH_PIX_RGB24)
        return sh_error_set(SH_EINVAL, "screen: cannot show %s frames", sh_pixfmt_name(frame->format));
    if (frame->width < 1 || frame->height < 1)
        return sh_error_set(SH_EINVAL, "screen: empty frame");
    y0 = imax(y0, 0);
    y1 = imin(y1, dst->height);
    if (y0 >= y1) return SH_OK;
    if (frame->width != p.width && !row) return sh_error_set(SH_EINVAL, "screen: no row to scale a frame through");
    const yuv_coeffs c = coeffs(full_range);
    /* the bars, clipped to the band's rows */
    const int top = imin(p.y, y1), bottom = imax(p.y + p.height, y0);
    sh_screen_fill(dst, (sh_screen_rect){0, y0, dst->width, top - y0}, SH_SCREEN_BLACK);
    sh_screen_fill(dst, (sh_screen_rect){0, bottom, dst->width, y1 - bottom}, SH_SCREEN_BLACK);
    const int py0 = imax(p.y, y0), py1 = imin(p.y + p.height, y1);
    sh_screen_fill(dst, (sh_screen_rect){0, py0, p.x, py1 - py0}, SH_SCREEN_BLACK);
    sh_screen_fill(dst, (sh_screen_rect){p.x + p.width, py0, dst->width - p.x - p.width, py1 - py0}, SH_SCREEN_BLACK);
    const uint32_t *prev = NULL;
    int prev_sy = -1;
    for (int y = py0 - p.y; y < py1 - p.y; y++) {
        int sy = (int)(((2LL * y + 1) * frame->height) / (2LL * p.height));
        uint32_t *out = (uint32_t *)((uint8_t *)dst->pixels + (size_t)(p.y + y) * (size_t)dst->stride) + p.x;
        if (sy == prev_sy) { /* upscaled: the same frame row again */
            memcpy(out, prev, (size_t)p.width * sizeof *out);
        } else if (!row) {
            convert_row(out, frame, sy, &c);
        } else {
            convert_row(row, frame, sy, &c);
            sample_row(out, p.width, row, frame->width);
        }
        prev = out;
        prev_sy = sy;
    }
    return SH_OK;
}

void sh_screen_draw_status(const sh_screen_buffer *dst, const sh_screen_layout *layout,
                           sh_screen_overlay overlay, uint32_t status, const char *reason,
                           int reason_cap)
{
    if (overlay == SH_SCREEN_OVERLAY_OFF) return;
    const sh_screen_rect p = layout->picture;
    const int b = imin(layout->border, imin(p.width, p.height) / 2);
    const uint32_t c = sh_screen_status_colour(status);
    sh_screen_fill(dst, (sh_screen_rect){p.x, p.y, p.width, b}, c);
    sh_screen_fill(dst, (sh_screen_rect){p.x, p.y + p.height - b, p.width, b}, c);
    sh_screen_fill(dst, (sh_screen_rect){p.x, p.y, b, p.height}, c);
    sh_screen_fill(dst, (sh_screen_rect){p.x + p.width - b, p.y, b, p.height}, c);
    if (overlay != SH_SCREEN_OVERLAY_FULL) return;
    const int s = layout->scale, pad = 2 * s;
    sh_screen_fill(dst, layout->badge, c);
    sh_screen_draw_text(dst, layout->badge.x + pad, layout->badge.y + pad, s, SH_SCREEN_BLACK,
                        sh_screen_status_word(status), BADGE_CELLS);
    int n = 0;
    while (n < reason_cap && reason[n]) n++;
    /* as many characters as fit inside the frame, on a black band */
    int room = (p.width - 2 * b - 2 * pad) / (SH_SCREEN_CELL_W * s);
    n = imin(n, imax(room, 0));
    if (n == 0) return;
    sh_screen_rect band = {p.x + b, p.y + p.height - b - (7 * s + 2 * pad),
                           n * SH_SCREEN_CELL_W * s + 2 * pad - s, 7 * s + 2 * pad};
    sh_screen_fill(dst, band, SH_SCREEN_BLACK);
    sh_screen_draw_text(dst, band.x + pad, band.y + pad, s, SH_SCREEN_WHITE, reason, n);
}

void sh_screen_draw_no_signal(const sh_screen_buffer *dst, double since_s)
{
    sh_screen_fill(dst, (sh_screen_rect){0, 0, dst->width, dst->height}, SH_SCREEN_BLACK);
    const int s = imax(1, dst->height / 240);
    char line[64];
    if (since_s >= 0)
        snprintf(line, sizeof line, "LAST FRAME %.0f S AGO", floor(fmin(since_s, 9.99e12)));
    else
        snprintf(line, sizeof line, "NO FRAME YET");
    const char *big = "NO SIGNAL";
    /* centred on the glyphs: a text's last cell ends with a blank column */
    int wbig = (int)strlen(big) * SH_SCREEN_CELL_W * 2 * s - 2 * s;
    int wline = (int)strlen(line) * SH_SCREEN_CELL_W * s - s;
    sh_screen_draw_text(dst, (dst->width - wbig) / 2, dst->height / 2 - 8 * 2 * s, 2 * s, SH_SCREEN_WHITE, big, 64);
    sh_screen_draw_text(dst, (dst->width - wline) / 2, dst->height / 2 + 2 * s, s, SH_SCREEN_WHITE, line, 64);
}
