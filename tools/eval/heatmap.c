/* The average-difference image as the paper shows it (Figures 2 and 3): I_error in grey, colour
 * mapped, with contour lines, dark outside the hull, at the video's size (or a stated scale), so
 * that it stands beside the video it measures, with its colour scale and the scale's numbers. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "eval.h"
#include "stillheart/png.h"

/* Viridis (matplotlib's perceptually uniform map) sampled at nine points: linear interpolation
 * between them stays within a few levels of the full table, and the map reads the same in grey. */
static const unsigned char viridis[9][3] = {
    {68, 1, 84},    {71, 44, 122},  {59, 81, 139},  {44, 113, 142}, {33, 144, 141},
    {39, 173, 129}, {92, 200, 99},  {170, 220, 50}, {253, 231, 37},
};

void eval_viridis(double s, unsigned char rgb[3])
{
    s = s < 0 ? 0 : s > 1 ? 1 : s;
    double f = s * 8;
    int i = (int)f;
    if (i > 7) i = 7;
    f -= i;
    for (int c = 0; c < 3; c++)
        rgb[c] = (unsigned char)lrint(viridis[i][c] + f * (viridis[i + 1][c] - viridis[i][c]));
}

/* Box mean over the hull pixels only, by summed-area tables: the raw image is speckled by sensor
 * noise, and contours of the raw values would be noise, not the residual motion's shape. */
static float *smooth(const float *grey, int w, int h, int r)
{
    size_t W = (size_t)w + 1;
    double *s = calloc(W * (size_t)(h + 1), sizeof(double));
    double *n = calloc(W * (size_t)(h + 1), sizeof(double));
    float *out = malloc(sizeof(float) * (size_t)w * h);
    if (!s || !n || !out) {
        free(s);
        free(n);
        free(out);
        return NULL;
    }
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            float v = grey[(size_t)y * w + x];
            int in = !isnan(v);
            size_t i = (size_t)(y + 1) * W + x + 1;
            s[i] = (in ? v : 0) + s[i - 1] + s[i - W] - s[i - W - 1];
            n[i] = in + n[i - 1] + n[i - W] - n[i - W - 1];
        }
    for (int y = 0; y < h; y++) {
        int y0 = y - r < 0 ? 0 : y - r, y1 = y + r + 1 > h ? h : y + r + 1;
        for (int x = 0; x < w; x++) {
            size_t o = (size_t)y * w + x;
            if (isnan(grey[o])) {
                out[o] = NAN;
                continue;
            }
            int x0 = x - r < 0 ? 0 : x - r, x1 = x + r + 1 > w ? w : x + r + 1;
            size_t a = (size_t)y0 * W + x0, b = (size_t)y0 * W + x1, c = (size_t)y1 * W + x0,
                   d = (size_t)y1 * W + x1;
            out[o] = (float)((s[d] - s[b] - s[c] + s[a]) / (n[d] - n[b] - n[c] + n[a]));
        }
    }
    free(s);
    free(n);
    return out;
}

/* The colour scale: a bar from 0 to max in the colour map, white ticks where the contour lines
 * are, and the numbers of its ends and ticks under it (a tick's number is left out where it would
 * run into its neighbour's). The strip goes along the edge with fewer hull pixels under it: it
 * hides part of the picture, and the picture keeps the video's size so that it stacks beside it. */
static void legend(sh_image *img, const int *hull_rows, double max, int levels)
{
    int W = img->width, H = img->height;
    int s = H / 180 > 1 ? H / 180 : 1, pad = 2 * s, barh = 6 * s;
    int hs = pad + barh + pad + FONT_H * s + pad;
    if (W < 64 * s || H < 2 * hs) return; /* no room for a readable scale */
    long top = 0, bottom = 0;
    for (int y = 0; y < hs; y++) top += hull_rows[y], bottom += hull_rows[H - 1 - y];
    int y0 = bottom <= top ? H - hs : 0;
    static const unsigned char dark[3] = {20, 20, 20}, white[3] = {255, 255, 255};
    draw_box(img, 0, y0, W, y0 + hs, dark);
    int bx0 = pad, bx1 = W - pad, by = y0 + pad;
    for (int x = bx0; x < bx1; x++) {
        unsigned char c[3];
        eval_viridis((double)(x - bx0) / (bx1 - 1 - bx0), c);
        draw_box(img, x, by, x + 1, by + barh, c);
    }
    int n = levels + 2, ty = by + barh + pad, last_right = -1;
    char last[32];
    snprintf(last, sizeof last, "%g", max);
    int last_left = bx1 - font_width(last, s);
    for (int k = 0; k < n; k++) {
        int x = bx0 + (int)lrint((double)k / (n - 1) * (bx1 - 1 - bx0));
        if (k > 0 && k < n - 1) draw_box(img, x, by, x + s, by + barh, white);
        char label[32];
        snprintf(label, sizeof label, "%g", max * k / (n - 1));
        int w = font_width(label, s), lx = x - w / 2;
        if (lx < bx0) lx = bx0;
        if (lx + w > bx1) lx = bx1 - w;
        if (k < n - 1 && (lx <= last_right + 2 * s || lx + w + 2 * s >= last_left)) continue;
        draw_text(img, lx, ty, label, s, white);
        last_right = lx + w;
    }
}

sh_status eval_heatmap_write(const char *path, const float *grey, int w, int h, double max,
                             int levels, double scale)
{
    if (!(max > 0))
        return sh_error_set(SH_EINVAL, "heatmap: the colour scale's top %g must be positive", max);
    int ow = (int)lrint(w * scale), oh = (int)lrint(h * scale);
    if (!(scale > 0) || ow < 1 || oh < 1 || ow > SH_IMAGE_MAX_SIZE || oh > SH_IMAGE_MAX_SIZE)
        return sh_error_set(SH_EINVAL, "heatmap: %dx%d at scale %g is no picture (1..%d px a side)",
                            w, h, scale, SH_IMAGE_MAX_SIZE);
    /* About 1% of the frame: wide enough to smooth a marker's black and white cells into the
     * residual motion around it. */
    int r = (w < h ? w : h) / 100;
    if (r < 1) r = 1;
    float *sm = smooth(grey, w, h, r);
    unsigned char *rgb = malloc((size_t)w * h * 3);
    int *hull_rows = calloc((size_t)oh, sizeof(int)); /* hull pixels in each row of the picture */
    sh_image img = {0};
    sh_status st = sh_image_create(&img, SH_PIX_RGB24, ow, oh);
    if (!sm || !rgb || !hull_rows || st != SH_OK) {
        free(sm);
        free(rgb);
        free(hull_rows);
        sh_image_destroy(&img);
        return st != SH_OK ? st : sh_error_set(SH_ENOMEM, "heatmap: out of memory");
    }
    /* Contour index of a smoothed value: 0 below the first level, levels above the last. */
    double step = max / (levels + 1);
#define LEVEL(v) ((int)fmin(floor((v) / step), (double)levels))
    for (int y = 0; y < h; y++) {
        for (int x = 0; x < w; x++) {
            size_t o = (size_t)y * w + x;
            unsigned char *p = rgb + 3 * o;
            if (isnan(grey[o])) {
                p[0] = p[1] = p[2] = 40;
                continue;
            }
            eval_viridis(grey[o] / max, p);
            if (levels <= 0) continue;
            /* A line on the higher side of each level crossing, one pixel wide. */
            int l = LEVEL(sm[o]), edge = 0;
            static const int dx[4] = {1, -1, 0, 0}, dy[4] = {0, 0, 1, -1};
            for (int k = 0; k < 4 && !edge; k++) {
                int xx = x + dx[k], yy = y + dy[k];
                if (xx < 0 || yy < 0 || xx >= w || yy >= h) continue;
                float q = sm[(size_t)yy * w + xx];
                edge = !isnan(q) && LEVEL(q) < l;
            }
            if (edge) p[0] = p[1] = p[2] = 255;
        }
    }
#undef LEVEL
    /* nearest pixel: a heatmap's cells stay sharp, and scale 1 is the image itself */
    for (int y = 0; y < oh; y++) {
        int sy = (int)((y + 0.5) / scale);
        if (sy >= h) sy = h - 1;
        unsigned char *row = img.plane[0].data + (size_t)y * img.plane[0].stride;
        for (int x = 0; x < ow; x++) {
            int sx = (int)((x + 0.5) / scale);
            if (sx >= w) sx = w - 1;
            size_t o = (size_t)sy * w + sx;
            memcpy(row + 3 * x, rgb + 3 * o, 3);
            hull_rows[y] += !isnan(grey[o]);
        }
    }
    legend(&img, hull_rows, max, levels);
    st = sh_png_write(path, &img, 1);
    free(sm);
    free(rgb);
    free(hull_rows);
    sh_image_destroy(&img);
    return st;
}
