/* The average-difference image as the paper shows it (Figures 2 and 3): I_error in grey, colour
 * mapped, with contour lines, dark outside the hull, cropped to the hull's bounding box and a
 * margin (the rest of the frame is not measured, and a figure should show what was). */
#include <math.h>
#include <stdlib.h>

#include "eval.h"
#include "stillheart/png.h"

/* Viridis (matplotlib's perceptually uniform map) sampled at nine points: linear interpolation
 * between them stays within a few levels of the full table, and the map reads the same in grey. */
static const unsigned char viridis[9][3] = {
    {68, 1, 84},    {71, 44, 122},  {59, 81, 139},  {44, 113, 142}, {33, 144, 141},
    {39, 173, 129}, {92, 200, 99},  {170, 220, 50}, {253, 231, 37},
};

static void colour(double s, unsigned char *rgb)
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

/* The box [x0, x1) x [y0, y1) around the hull pixels, with a margin. */
static void crop_box(const float *grey, int w, int h, int margin, int *x0, int *y0, int *x1, int *y1)
{
    *x0 = w, *y0 = h, *x1 = *y1 = 0;
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++)
            if (!isnan(grey[(size_t)y * w + x])) {
                if (x < *x0) *x0 = x;
                if (x >= *x1) *x1 = x + 1;
                if (y < *y0) *y0 = y;
                if (y >= *y1) *y1 = y + 1;
            }
    if (*x1 == 0) { /* no hull pixel: show the whole frame */
        *x0 = *y0 = 0, *x1 = w, *y1 = h;
        return;
    }
    *x0 = *x0 > margin ? *x0 - margin : 0;
    *y0 = *y0 > margin ? *y0 - margin : 0;
    *x1 = *x1 + margin < w ? *x1 + margin : w;
    *y1 = *y1 + margin < h ? *y1 + margin : h;
}

sh_status eval_heatmap_write(const char *path, const float *grey, int w, int h, double max,
                             int levels)
{
    if (!(max > 0)) return sh_error_set(SH_EINVAL, "heatmap: scale %g must be positive", max);
    /* About 1% of the frame: wide enough to smooth a marker's black and white cells into the
     * residual motion around it. */
    int r = (w < h ? w : h) / 100;
    if (r < 1) r = 1;
    int cx0, cy0, cx1, cy1;
    crop_box(grey, w, h, 2 * r, &cx0, &cy0, &cx1, &cy1);
    float *sm = smooth(grey, w, h, r);
    sh_image img = {0};
    sh_status st = sh_image_create(&img, SH_PIX_RGB24, cx1 - cx0, cy1 - cy0);
    if (!sm || st != SH_OK) {
        free(sm);
        sh_image_destroy(&img);
        return st != SH_OK ? st : sh_error_set(SH_ENOMEM, "heatmap: out of memory");
    }
    /* Contour index of a smoothed value: 0 below the first level, levels above the last. */
    double step = max / (levels + 1);
#define LEVEL(v) ((int)fmin(floor((v) / step), (double)levels))
    for (int y = cy0; y < cy1; y++) {
        unsigned char *row = img.plane[0].data + (size_t)(y - cy0) * img.plane[0].stride;
        for (int x = cx0; x < cx1; x++) {
            size_t o = (size_t)y * w + x;
            unsigned char *p = row + 3 * (x - cx0);
            if (isnan(grey[o])) {
                p[0] = p[1] = p[2] = 40;
                continue;
            }
            colour(grey[o] / max, p);
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
    st = sh_png_write(path, &img, 1);
    free(sm);
    sh_image_destroy(&img);
    return st;
}
