/* The image pyramid, in OpenCV's integer arithmetic (cv::pyrDown), so that the tracker sees the
 * same numbers as its oracle; with gradients, the pixels their Scharr gradients are made of too
 * (the windows make them: flow_window_gradients). */
#include "flow_internal.h"

#include <math.h>
#include <stddef.h>
#include <stdlib.h>
#include <string.h>

void sh_flow_params_default(sh_flow_params *p)
{
    p->win = 21;
    p->levels = 3;
    p->max_iter = 30;
    p->eps = 0.01;
    p->min_eig = 1e-4;
}

static size_t round64(size_t n)
{
    return (n + 63) / 64 * 64;
}

static sh_status check_params(const sh_flow_params *p)
{
    if (!p) return sh_error_set(SH_EINVAL, "flow: no parameters");
    if (p->win < 5 || p->win > SH_FLOW_MAX_WIN || p->win % 2 == 0)
        return sh_error_set(SH_EINVAL, "flow: window %d px, need an odd side in 5..%d", p->win,
                            SH_FLOW_MAX_WIN);
    if (p->levels < 0 || p->levels > SH_FLOW_MAX_LEVELS)
        return sh_error_set(SH_EINVAL, "flow: %d pyramid levels, need 0..%d", p->levels,
                            SH_FLOW_MAX_LEVELS);
    /* 100 steps at most, as OpenCV clamps them: a point that has not settled by then will not */
    if (p->max_iter < 1 || p->max_iter > 100 || !(p->eps >= 0) || !(p->min_eig >= 0))
        return sh_error_set(SH_EINVAL, "flow: steps %d, eps %g, min_eig %g: need 1..100 steps and "
                            "eps, min_eig >= 0", p->max_iter, p->eps, p->min_eig);
    return SH_OK;
}

sh_status sh_flow_pyramid_create(int width, int height, const sh_flow_params *params,
                                 sh_flow_pyramid **out)
{
    if (!out) return sh_error_set(SH_EINVAL, "flow: no output");
    *out = NULL;
    sh_status st = check_params(params);
    if (st != SH_OK) return st;
    if (width < 2 || height < 2 || width > SH_IMAGE_MAX_SIZE || height > SH_IMAGE_MAX_SIZE)
        return sh_error_set(SH_EINVAL, "flow: frame %dx%d, need 2..%d px a side", width, height,
                            SH_IMAGE_MAX_SIZE);
    sh_flow_pyramid *pyr = calloc(1, sizeof *pyr);
    if (!pyr) return sh_error_set(SH_ENOMEM, "flow: out of memory");
    pyr->pad = params->win;
    int w = width, h = height;
    size_t bytes = 0;
    for (int k = 0;; k++) {
        flow_level *l = &pyr->level[k];
        l->width = w;
        l->height = h;
        l->stride = w + 2 * pyr->pad;
        size_t n = (size_t)l->stride * (size_t)(h + 2 * pyr->pad);
        bytes += round64(n + FLOW_SLACK);
        pyr->levels = k;
        /* as cv::buildOpticalFlowPyramid: a level no larger than the window is not built */
        int nw = (w + 1) / 2, nh = (h + 1) / 2;
        if (k == params->levels || nw <= params->win || nh <= params->win) break;
        w = nw;
        h = nh;
    }
    pyr->block = calloc(1, bytes);
    pyr->rows = malloc(sizeof(uint16_t) * (size_t)(width + 4));
    if (!pyr->block || !pyr->rows) {
        sh_flow_pyramid_destroy(pyr);
        return sh_error_set(SH_ENOMEM, "flow: out of memory for a %dx%d pyramid", width, height);
    }
    char *p = pyr->block;
    for (int k = 0; k <= pyr->levels; k++) {
        flow_level *l = &pyr->level[k];
        size_t n = (size_t)l->stride * (size_t)(l->height + 2 * pyr->pad);
        size_t origin = (size_t)pyr->pad * (size_t)l->stride + (size_t)pyr->pad;
        l->img = (uint8_t *)p + origin;
        p += round64(n + FLOW_SLACK);
    }
    *out = pyr;
    return SH_OK;
}

void sh_flow_pyramid_destroy(sh_flow_pyramid *pyr)
{
    if (!pyr) return;
    free(pyr->block);
    free(pyr->rows);
    free(pyr);
}

int sh_flow_pyramid_levels(const sh_flow_pyramid *pyr)
{
    return pyr ? pyr->levels : 0;
}

/* Fills the level's border by mirroring its pixels, rows first, then whole padded rows: only
 * the rows and columns of box b (level coordinates, reaching into the border on the sides where
 * it touches the level's edge; the whole padded level when built in full). */
static void pad_image(flow_level *l, int pad, const int b[4])
{
    const int y0 = b[1] > 0 ? b[1] : 0, y1 = b[3] < l->height ? b[3] : l->height;
    for (int y = y0; y < y1; y++) {
        uint8_t *row = l->img + (size_t)y * (size_t)l->stride;
        for (int x = 1; x <= pad; x++) {
            if (b[0] < 0) row[-x] = row[flow_reflect101(-x, l->width)];
            if (b[2] > l->width) row[l->width - 1 + x] = row[flow_reflect101(l->width - 1 + x, l->width)];
        }
    }
    const size_t len = (size_t)(b[2] - b[0]);
    for (int y = 1; y <= pad; y++) {
        const uint8_t *top = l->img + (size_t)flow_reflect101(-y, l->height) * (size_t)l->stride;
        const uint8_t *bot =
            l->img + (size_t)flow_reflect101(l->height - 1 + y, l->height) * (size_t)l->stride;
        if (b[1] < 0) memcpy(l->img - (ptrdiff_t)y * l->stride + b[0], top + b[0], len);
        if (b[3] > l->height)
            memcpy(l->img + (ptrdiff_t)(l->height - 1 + y) * l->stride + b[0], bot + b[0], len);
    }
}

/* cv::pyrDown: the 5x5 binomial kernel ([1 4 6 4 1] / 16 in each direction) at every second
 * pixel, mirrored borders, rounded (sum + 128) >> 8, for the pixels of dst in box b (level
 * coordinates; the parts outside the level ignored). Columns first, into one row of 16-bit
 * sums: a column's sum is at most 16 * 255 and the whole at most 256 * 255 + 128 < 2^16, so
 * 16-bit lanes hold them exactly and the compiler's vectorizer can use 8 or 16 of them. */
static void reduce(const flow_level *src, flow_level *dst, uint16_t *rows, const int b[4])
{
    uint16_t *restrict t = rows + 2;
    const int sw = src->width;
    const int dx0 = b[0] > 0 ? b[0] : 0, dx1 = b[2] < dst->width ? b[2] : dst->width;
    const int dy0 = b[1] > 0 ? b[1] : 0, dy1 = b[3] < dst->height ? b[3] : dst->height;
    /* the column sums dst's columns [dx0, dx1) read: [2 dx0 - 2, 2 dx1 + 1), mirrored at the edges */
    const int sx0 = 2 * dx0 - 2 > 0 ? 2 * dx0 - 2 : 0, sx1 = 2 * dx1 + 1 < sw ? 2 * dx1 + 1 : sw;
    for (int y = dy0; y < dy1; y++) {
        const uint8_t *r[5];
        for (int k = 0; k < 5; k++)
            r[k] = src->img + (size_t)flow_reflect101(2 * y - 2 + k, src->height) *
                                  (size_t)src->stride;
        const uint8_t *restrict r0 = r[0], *restrict r1 = r[1], *restrict r2 = r[2],
                                *restrict r3 = r[3], *restrict r4 = r[4];
        for (int x = sx0; x < sx1; x++)
            t[x] = (uint16_t)(r0[x] + 4 * (r1[x] + r3[x]) + 6 * r2[x] + r4[x]);
        for (int k = 1; k <= 2; k++) {
            if (2 * dx0 - 2 < 0) t[-k] = t[flow_reflect101(-k, sw)];
            if (2 * dx1 + 1 > sw) t[sw - 1 + k] = t[flow_reflect101(sw - 1 + k, sw)];
        }
        uint8_t *restrict d = dst->img + (size_t)y * (size_t)dst->stride;
        for (int x = dx0; x < dx1; x++) {
            const uint16_t *c = t + 2 * x;
            d[x] = (uint8_t)((uint16_t)(c[-2] + 4 * (c[-1] + c[1]) + 6 * c[0] + c[2] + 128) >> 8);
        }
    }
}

/* One side of a part of a level [*lo, *hi) (level coordinates) of size n: a side at or past the
 * level's edge reaches through the border (pad), and a part that reaches one edge keeps the
 * pad + 1 pixels next to it that its mirror copies. */
static void snap(int *lo, int *hi, int n, int pad)
{
    for (int k = 0; k < 2; k++) {
        if (*lo <= 0) {
            *lo = -pad;
            if (*hi < pad + 1) *hi = pad + 1;
        }
        if (*hi >= n) {
            *hi = n + pad;
            if (*lo > n - 1 - pad) *lo = n - 1 - pad;
        }
    }
}

/* What sh_flow_pyramid_build_box builds of each level (flow_level's img_box and grad_box) for a
 * box of points (level 0 coordinates): at level k, every pixel a window centred within
 * box / 2^k reads (its corner floor(c - half), win + 1 pixels with the bilinear neighbour, one
 * more each way for the float's rounding) and, with gradients, the neighbours they are made of;
 * then the pixels the level above reduces from; each side snapped to the level's edge (snap). */
static void plan(const sh_flow_pyramid *pyr, const float box[4], int with_gradients, int img[][4],
                 int grad[][4])
{
    const int pad = pyr->pad, half = (pad - 1) / 2, g = with_gradients != 0;
    for (int k = pyr->levels; k >= 0; k--) {
        const flow_level *l = &pyr->level[k];
        const float s = 1.0f / (float)(1 << k);
        int b[4];
        for (int a = 0; a < 2; a++) {
            /* the box clamped to where a window may lie at all (its corner within one window
             * of the level), before any conversion to int */
            float n = (float)(a ? l->height : l->width);
            float lo = box[a] * s, hi = box[a + 2] * s;
            lo = lo > -(float)pad ? lo : -(float)pad;
            lo = lo < n + (float)pad ? lo : n + (float)pad;
            hi = hi > lo ? hi : lo;
            hi = hi < n + (float)pad ? hi : n + (float)pad;
            b[a] = (int)floorf(lo) - half - 1 - g;
            b[a + 2] = (int)floorf(hi) + half + 3 + g;
        }
        if (k < pyr->levels) {
            /* the pixels the level above reduces from: [2 x0 - 2, 2 x1 + 1) of its own */
            const int *u = img[k + 1];
            for (int a = 0; a < 2; a++) {
                const int n = a ? pyr->level[k + 1].height : pyr->level[k + 1].width;
                int lo = u[a] > 0 ? u[a] : 0, hi = u[a + 2] < n ? u[a + 2] : n;
                if (2 * lo - 2 < b[a]) b[a] = 2 * lo - 2;
                if (2 * hi + 1 > b[a + 2]) b[a + 2] = 2 * hi + 1;
            }
        }
        snap(&b[0], &b[2], l->width, pad);
        snap(&b[1], &b[3], l->height, pad);
        memcpy(img[k], b, sizeof b);
        /* gradients one pixel inside the pixels (their neighbours), except through a border
         * (zero there) */
        for (int a = 0; a < 2; a++) {
            int n = a ? l->height : l->width;
            grad[k][a] = g ? (b[a] < 0 ? b[a] : b[a] + 1) : 0;
            grad[k][a + 2] = g ? (b[a + 2] > n ? b[a + 2] : b[a + 2] - 1) : 0;
        }
    }
}

static sh_status check_frame(const sh_flow_pyramid *pyr, const sh_plane *luma)
{
    if (!pyr || !luma || !luma->data)
        return sh_error_set(SH_EINVAL, "flow: no pyramid or no frame");
    const flow_level *l0 = &pyr->level[0];
    if (luma->width != l0->width || luma->height != l0->height || luma->stride < luma->width)
        return sh_error_set(SH_EINVAL, "flow: frame %dx%d (stride %d), pyramid made for %dx%d",
                            luma->width, luma->height, luma->stride, l0->width, l0->height);
    return SH_OK;
}

/* Builds the parts img[k] (and gradients in grad[k]) of every level from luma. */
static void build(sh_flow_pyramid *pyr, const sh_plane *luma, int with_gradients, int img[][4],
                  int grad[][4])
{
    flow_level *l0 = &pyr->level[0];
    const int *b = img[0];
    const int x0 = b[0] > 0 ? b[0] : 0, x1 = b[2] < l0->width ? b[2] : l0->width;
    const int y0 = b[1] > 0 ? b[1] : 0, y1 = b[3] < l0->height ? b[3] : l0->height;
    for (int y = y0; y < y1; y++)
        memcpy(l0->img + (size_t)y * (size_t)l0->stride + x0,
               luma->data + (size_t)y * (size_t)luma->stride + x0, (size_t)(x1 - x0));
    pad_image(l0, pyr->pad, img[0]);
    for (int k = 1; k <= pyr->levels; k++) {
        reduce(&pyr->level[k - 1], &pyr->level[k], pyr->rows, img[k]);
        pad_image(&pyr->level[k], pyr->pad, img[k]);
    }
    pyr->has_gradients = with_gradients != 0;
    for (int k = 0; k <= pyr->levels; k++) {
        memcpy(pyr->level[k].img_box, img[k], sizeof img[k]);
        memcpy(pyr->level[k].grad_box, grad[k], sizeof grad[k]);
    }
}

sh_status sh_flow_pyramid_build(sh_flow_pyramid *pyr, const sh_plane *luma, int with_gradients)
{
    sh_status st = check_frame(pyr, luma);
    if (st != SH_OK) return st;
    int img[SH_FLOW_MAX_LEVELS + 1][4], grad[SH_FLOW_MAX_LEVELS + 1][4];
    for (int k = 0; k <= pyr->levels; k++) {
        const flow_level *l = &pyr->level[k];
        const int all[4] = {-pyr->pad, -pyr->pad, l->width + pyr->pad, l->height + pyr->pad};
        memcpy(img[k], all, sizeof all);
        memcpy(grad[k], all, sizeof all);
        if (!with_gradients) memset(grad[k], 0, sizeof grad[k]);
    }
    build(pyr, luma, with_gradients, img, grad);
    return SH_OK;
}

static sh_status check_box(const float box[4])
{
    if (!box || !(box[0] <= box[2]) || !(box[1] <= box[3]))
        return sh_error_set(SH_EINVAL, "flow: no box, or one with x0 > x1, y0 > y1 or NaN");
    return SH_OK;
}

sh_status sh_flow_pyramid_box_part(const sh_flow_pyramid *pyr, const float box[4], int with_gradients,
                                   int part[4])
{
    if (!pyr || !part) return sh_error_set(SH_EINVAL, "flow: no pyramid");
    sh_status st = check_box(box);
    if (st != SH_OK) return st;
    int img[SH_FLOW_MAX_LEVELS + 1][4], grad[SH_FLOW_MAX_LEVELS + 1][4];
    plan(pyr, box, with_gradients, img, grad);
    const flow_level *l0 = &pyr->level[0];
    part[0] = img[0][0] > 0 ? img[0][0] : 0;
    part[1] = img[0][1] > 0 ? img[0][1] : 0;
    part[2] = img[0][2] < l0->width ? img[0][2] : l0->width;
    part[3] = img[0][3] < l0->height ? img[0][3] : l0->height;
    return SH_OK;
}

sh_status sh_flow_pyramid_build_box(sh_flow_pyramid *pyr, const sh_plane *luma, int with_gradients,
                                    const float box[4])
{
    sh_status st = check_frame(pyr, luma);
    if (st == SH_OK) st = check_box(box);
    if (st != SH_OK) return st;
    int img[SH_FLOW_MAX_LEVELS + 1][4], grad[SH_FLOW_MAX_LEVELS + 1][4];
    plan(pyr, box, with_gradients, img, grad);
    build(pyr, luma, with_gradients, img, grad);
    return SH_OK;
}

/* Whether part a (x0, y0, x1, y1) lies within part b. */
static int within(const int a[4], const int b[4])
{
    return a[0] >= b[0] && a[1] >= b[1] && a[2] <= b[2] && a[3] <= b[3];
}

sh_status sh_flow_pyramid_update_box(sh_flow_pyramid *pyr, const sh_plane *luma, const float box[4])
{
    sh_status st = check_frame(pyr, luma);
    if (st == SH_OK) st = check_box(box);
    if (st != SH_OK) return st;
    const int g = pyr->has_gradients;
    int img[SH_FLOW_MAX_LEVELS + 1][4], grad[SH_FLOW_MAX_LEVELS + 1][4], kept[SH_FLOW_MAX_LEVELS + 1][2][4];
    plan(pyr, box, g, img, grad);
    for (int k = 0; k <= pyr->levels; k++) {
        const flow_level *l = &pyr->level[k];
        if (!within(img[k], l->img_box) || (g && !within(grad[k], l->grad_box)))
            return sh_error_set(SH_EINVAL, "flow: update: the box reaches past what level %d was built for", k);
        memcpy(kept[k][0], l->img_box, sizeof l->img_box);
        memcpy(kept[k][1], l->grad_box, sizeof l->grad_box);
    }
    build(pyr, luma, g, img, grad);
    for (int k = 0; k <= pyr->levels; k++) {
        memcpy(pyr->level[k].img_box, kept[k][0], sizeof kept[k][0]);
        memcpy(pyr->level[k].grad_box, kept[k][1], sizeof kept[k][1]);
    }
    return SH_OK;
}
