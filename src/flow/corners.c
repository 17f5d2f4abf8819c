/* Shi-Tomasi corners, chosen as cv::goodFeaturesToTrack chooses them (its oracle): the minimum
 * eigenvalue of the summed gradient products over a block (Sobel 3x3 gradients, mirrored
 * borders), responses at most `quality` of the strongest dropped, 3x3 local maxima away from
 * the frame's edge, strongest first, none closer than min_distance to one already taken. The
 * sums are exact integers, so ties and order are the same on every architecture. */
#include "flow_internal.h"

#include <math.h>
#include <stdlib.h>

#define MAX_CORNERS 100000

void sh_flow_corner_params_default(sh_flow_corner_params *p)
{
    p->max_points = 200;
    p->quality = 0.01;
    p->min_distance = 10.0;
    p->block = 3;
    p->balance_cell = 0;
    p->balance_floor = 0;
}

typedef struct {
    float v;
    int at; /* y * width + x */
} candidate;

/* Strongest first; equal responses by position, the later pixel first, as OpenCV's sort of
 * pointers into its response image orders them. */
static int stronger(const void *a, const void *b)
{
    const candidate *p = a, *q = b;
    if (p->v != q->v) return p->v > q->v ? -1 : 1;
    return (p->at < q->at) - (p->at > q->at);
}

/* Sobel 3x3 gradients of every pixel (mirrored borders) into g (dx, dy pairs). */
static void sobel(const sh_plane *img, int16_t *g)
{
    const int w = img->width, h = img->height;
    for (int y = 0; y < h; y++) {
        const uint8_t *a = img->data + (size_t)flow_reflect101(y - 1, h) * (size_t)img->stride;
        const uint8_t *b = img->data + (size_t)y * (size_t)img->stride;
        const uint8_t *c = img->data + (size_t)flow_reflect101(y + 1, h) * (size_t)img->stride;
        for (int x = 0; x < w; x++) {
            int l = flow_reflect101(x - 1, w), r = flow_reflect101(x + 1, w);
            g[2 * ((size_t)y * w + x)] = (int16_t)(a[r] - a[l] + 2 * (b[r] - b[l]) + c[r] - c[l]);
            g[2 * ((size_t)y * w + x) + 1] =
                (int16_t)(c[l] - a[l] + 2 * (c[x] - a[x]) + c[r] - a[r]);
        }
    }
}

/* The minimum eigenvalue of each pixel's block-summed gradient products, in OpenCV's scale
 * (gradients divided by 4 * block * 255), into eig. colsum: 3 * width int64 of scratch. */
static void min_eigen(const int16_t *g, int w, int h, int block, int64_t *colsum, float *eig)
{
    const int r = block / 2;
    const double s = 1.0 / (4.0 * block * 255.0), s2 = s * s;
    for (int y = 0; y < h; y++) {
        for (int x = 0; x < w; x++) {
            int64_t xx = 0, xy = 0, yy = 0;
            for (int k = -r; k <= r; k++) {
                const int16_t *p = g + 2 * ((size_t)flow_reflect101(y + k, h) * w + x);
                xx += p[0] * p[0];
                xy += p[0] * p[1];
                yy += p[1] * p[1];
            }
            colsum[3 * x] = xx;
            colsum[3 * x + 1] = xy;
            colsum[3 * x + 2] = yy;
        }
        for (int x = 0; x < w; x++) {
            int64_t xx = 0, xy = 0, yy = 0;
            for (int k = -r; k <= r; k++) {
                const int64_t *c = colsum + 3 * flow_reflect101(x + k, w);
                xx += c[0];
                xy += c[1];
                yy += c[2];
            }
            double a = 0.5 * s2 * (double)xx, b = s2 * (double)xy, c = 0.5 * s2 * (double)yy;
            eig[(size_t)y * w + x] = (float)((a + c) - sqrt((a - c) * (a - c) + b * b));
        }
    }
}

static int allowed(const sh_plane *mask, int x, int y)
{
    return !mask || mask->data[(size_t)y * (size_t)mask->stride + (size_t)x] != 0;
}

/* Local maxima over 3x3 of the thresholded responses, inside the mask, off the frame's edge,
 * into out (NULL: only counted). */
static int collect(const float *eig, int w, int h, const sh_plane *mask, candidate *out)
{
    int n = 0;
    for (int y = 1; y < h - 1; y++)
        for (int x = 1; x < w - 1; x++) {
            const float *e = eig + (size_t)y * w + x;
            float v = *e;
            if (v == 0.f || !allowed(mask, x, y)) continue;
            int peak = 1;
            for (int dy = -1; dy <= 1 && peak; dy++)
                for (int dx = -1; dx <= 1; dx++)
                    if (e[dy * w + dx] > v) {
                        peak = 0;
                        break;
                    }
            if (!peak) continue;
            if (out) out[n] = (candidate){v, y * w + x};
            n++;
        }
    return n;
}

/* balance_cell (sh_flow_corner_params): each candidate's response over its cell's strongest,
 * floored at balance_floor times top (the mask's strongest). 0 where out of memory. */
static int balance(candidate *c, int nc, int w, int h, const sh_flow_corner_params *prm, float top)
{
    const int cell = prm->balance_cell, gw = (w + cell - 1) / cell, gh = (h + cell - 1) / cell;
    float *best = calloc((size_t)gw * (size_t)gh, sizeof *best);
    if (!best) return 0;
    for (int i = 0; i < nc; i++) {
        float *b = &best[(c[i].at / w) / cell * gw + (c[i].at % w) / cell];
        if (c[i].v > *b) *b = c[i].v;
    }
    const float floor_v = (float)(prm->balance_floor * top);
    for (int i = 0; i < nc; i++) {
        const float b = best[(c[i].at / w) / cell * gw + (c[i].at % w) / cell];
        c[i].v /= b > floor_v ? b : floor_v;
    }
    free(best);
    return 1;
}

/* The side of the distance grid's cells: the distance, or 0 (no grid, no check) below 1 px. */
static int grid_cell(const sh_flow_corner_params *prm)
{
    return prm->min_distance >= 1.0 ? (int)lrint(prm->min_distance) : 0;
}

/* Takes candidates in order, skipping any closer than min_distance to one taken, with a grid
 * of cells one distance wide so that each check looks at the 3x3 cells around it only. */
static int spread(const candidate *c, int nc, int w, int h, const sh_flow_corner_params *prm,
                  int *head, int *next, float *xy)
{
    const double d2 = prm->min_distance * prm->min_distance;
    const int cell = grid_cell(prm);
    const int gw = cell ? (w + cell - 1) / cell : 1, gh = cell ? (h + cell - 1) / cell : 1;
    for (int i = 0; i < gw * gh; i++) head[i] = -1;
    int n = 0;
    for (int i = 0; i < nc && n < prm->max_points; i++) {
        int x = c[i].at % w, y = c[i].at / w, good = 1;
        if (cell) {
            int cx = x / cell, cy = y / cell;
            for (int gy = cy > 0 ? cy - 1 : 0; good && gy <= cy + 1 && gy < gh; gy++)
                for (int gx = cx > 0 ? cx - 1 : 0; good && gx <= cx + 1 && gx < gw; gx++)
                    for (int m = head[gy * gw + gx]; m >= 0; m = next[m]) {
                        double dx = x - xy[2 * m], dy = y - xy[2 * m + 1];
                        if (dx * dx + dy * dy < d2) {
                            good = 0;
                            break;
                        }
                    }
            if (!good) continue;
            next[n] = head[cy * gw + cx];
            head[cy * gw + cx] = n;
        }
        xy[2 * n] = (float)x;
        xy[2 * n + 1] = (float)y;
        n++;
    }
    return n;
}

sh_status sh_flow_corners(const sh_plane *luma, const sh_plane *mask,
                          const sh_flow_corner_params *prm, float *xy, int *n)
{
    if (!luma || !luma->data || !prm || !xy || !n)
        return sh_error_set(SH_EINVAL, "flow: corners: missing argument");
    *n = 0;
    const int w = luma->width, h = luma->height;
    if (w < 3 || h < 3 || w > SH_IMAGE_MAX_SIZE || h > SH_IMAGE_MAX_SIZE || luma->stride < w)
        return sh_error_set(SH_EINVAL, "flow: corners: frame %dx%d (stride %d)", w, h,
                            luma->stride);
    if (mask && (!mask->data || mask->width != w || mask->height != h || mask->stride < w))
        return sh_error_set(SH_EINVAL, "flow: corners: mask %dx%d for a %dx%d frame",
                            mask->width, mask->height, w, h);
    if (prm->max_points < 1 || prm->max_points > MAX_CORNERS || !(prm->quality > 0) ||
        prm->quality > 1 || !(prm->min_distance >= 0) || prm->min_distance > w + h ||
        prm->block < 3 || prm->block > 31 || prm->block % 2 == 0 || prm->balance_cell < 0 ||
        prm->balance_cell > 4096 || !(prm->balance_floor >= 0 && prm->balance_floor <= 1))
        return sh_error_set(SH_EINVAL,
                            "flow: corners: %d points, quality %g, distance %g, block %d, balance %d "
                            "(floor %g): need 1..%d points, quality in (0, 1], distance 0..%d, an "
                            "odd block 3..31, a balance cell 0..4096 with a floor in [0, 1]",
                            prm->max_points, prm->quality, prm->min_distance, prm->block,
                            prm->balance_cell, prm->balance_floor, MAX_CORNERS, w + h);
    const size_t px = (size_t)w * (size_t)h;
    const int cell = grid_cell(prm);
    const size_t cells = cell ? (size_t)((w + cell - 1) / cell) * (size_t)((h + cell - 1) / cell) : 1;
    int16_t *g = malloc(px * 2 * sizeof *g);
    float *eig = malloc(px * sizeof *eig);
    int64_t *colsum = malloc((size_t)w * 3 * sizeof *colsum);
    int *head = malloc(cells * sizeof *head), *next = malloc((size_t)prm->max_points * sizeof *next);
    candidate *cand = NULL;
    sh_status st = SH_OK;
    if (!g || !eig || !colsum || !head || !next) goto nomem;
    sobel(luma, g);
    min_eigen(g, w, h, prm->block, colsum, eig);
    free(g); /* the largest scratch: not needed past the responses */
    g = NULL;
    float top = 0.f;
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++)
            if (allowed(mask, x, y) && eig[(size_t)y * w + x] > top) top = eig[(size_t)y * w + x];
    const float floor_v = (float)(top * prm->quality);
    for (size_t i = 0; i < px; i++)
        if (!(eig[i] > floor_v)) eig[i] = 0.f;
    /* counted first: a plateau of equal responses makes every pixel of it a maximum (as in
     * OpenCV), so the count has no useful bound short of the frame's size */
    int nc = collect(eig, w, h, mask, NULL);
    cand = malloc((size_t)(nc > 0 ? nc : 1) * sizeof *cand);
    if (!cand) goto nomem;
    collect(eig, w, h, mask, cand);
    if (prm->balance_cell > 0 && !balance(cand, nc, w, h, prm, top)) goto nomem;
    qsort(cand, (size_t)nc, sizeof *cand, stronger);
    *n = spread(cand, nc, w, h, prm, head, next, xy);
    goto out;
nomem:
    st = sh_error_set(SH_ENOMEM, "flow: corners: out of memory for a %dx%d frame", w, h);
out:
    free(g);
    free(eig);
    free(colsum);
    free(cand);
    free(head);
    free(next);
    return st;
}
