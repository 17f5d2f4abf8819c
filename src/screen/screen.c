/* Scaling, letterboxing and the status overlay into an XRGB8888 buffer (screen.h). */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "stillheart/screen.h"

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

/* BT.601 YUV to RGB in 16.16 fixed point, one table per term: a pixel is five lookups, two
 * additions per channel and a clamp. */
typedef struct {
    int32_t y[256], rv[256], gu[256], gv[256], bu[256];
} yuv_tables;

static void make_tables(yuv_tables *t, int full_range)
{
    double ky = full_range ? 1.0 : 255.0 / 219.0, kc = full_range ? 1.0 : 255.0 / 224.0;
    double y0 = full_range ? 0 : 16;
    for (int i = 0; i < 256; i++) {
        double c = (i - 128) * kc * 65536.0;
        t->y[i] = (int32_t)lrint((i - y0) * ky * 65536.0) + 32768; /* + 0.5: round at the shift */
        t->rv[i] = (int32_t)lrint(1.402 * c);
        t->gu[i] = (int32_t)lrint(-0.344136 * c);
        t->gv[i] = (int32_t)lrint(-0.714136 * c);
        t->bu[i] = (int32_t)lrint(1.772 * c);
    }
}

static inline uint32_t clamp8(int32_t v) { return v < 0 ? 0u : v >= (256 << 16) ? 255u : (uint32_t)v >> 16; }

static inline uint32_t yuv_pixel(const yuv_tables *t, int y, int u, int v)
{
    int32_t l = t->y[y];
    return clamp8(l + t->rv[v]) << 16 | clamp8(l + t->gu[u] + t->gv[v]) << 8 | clamp8(l + t->bu[u]);
}

/* One screen row of the picture from frame row sy: the source column advances by a DDA
 * (sx = floor((2x + 1) * fw / (2 pw)) without a division per pixel). */
static void scale_row(uint32_t *out, int pw, const sh_image *f, int sy, const yuv_tables *t)
{
    long long num = f->width, den = 2LL * pw, step = 2LL * f->width;
    int sx = (int)(num / den);
    long long rem = num % den;
    const uint8_t *p0 = f->plane[0].data + (size_t)sy * (size_t)f->plane[0].stride;
    const uint8_t *pu = NULL, *pv = NULL;
    int cshift = 0;
    if (f->format == SH_PIX_I420) {
        cshift = 1;
        pu = f->plane[1].data + (size_t)(sy >> 1) * (size_t)f->plane[1].stride;
        pv = f->plane[2].data + (size_t)(sy >> 1) * (size_t)f->plane[2].stride;
    } else if (f->format == SH_PIX_YUV444) {
        pu = f->plane[1].data + (size_t)sy * (size_t)f->plane[1].stride;
        pv = f->plane[2].data + (size_t)sy * (size_t)f->plane[2].stride;
    }
    for (int x = 0; x < pw; x++) {
        switch (f->format) {
        case SH_PIX_RGB24: {
            const uint8_t *s = p0 + 3 * (size_t)sx;
            out[x] = (uint32_t)s[0] << 16 | (uint32_t)s[1] << 8 | s[2];
            break;
        }
        case SH_PIX_GRAY8: out[x] = yuv_pixel(t, p0[sx], 128, 128); break;
        default: out[x] = yuv_pixel(t, p0[sx], pu[sx >> cshift], pv[sx >> cshift]); break;
        }
        for (rem += step; rem >= den; rem -= den) sx++;
    }
}

sh_status sh_screen_draw_frame(const sh_screen_buffer *dst, const sh_screen_layout *layout,
                               const sh_image *frame, int full_range)
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
    yuv_tables t;
    make_tables(&t, full_range);
    sh_screen_fill(dst, (sh_screen_rect){0, 0, dst->width, p.y}, SH_SCREEN_BLACK);
    sh_screen_fill(dst, (sh_screen_rect){0, p.y + p.height, dst->width, dst->height - p.y - p.height}, SH_SCREEN_BLACK);
    sh_screen_fill(dst, (sh_screen_rect){0, p.y, p.x, p.height}, SH_SCREEN_BLACK);
    sh_screen_fill(dst, (sh_screen_rect){p.x + p.width, p.y, dst->width - p.x - p.width, p.height}, SH_SCREEN_BLACK);
    for (int y = 0; y < p.height; y++) {
        int sy = (int)(((2LL * y + 1) * frame->height) / (2LL * p.height));
        uint32_t *row = (uint32_t *)((uint8_t *)dst->pixels + (size_t)(p.y + y) * (size_t)dst->stride) + p.x;
        scale_row(row, p.width, frame, sy, &t);
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
