/* The image pyramid and its gradients, in OpenCV's integer arithmetic (cv::pyrDown, the Scharr
 * gradients of calcOpticalFlowPyrLK), so that the tracker sees the same numbers as its oracle. */
#include "flow_internal.h"

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
        bytes += round64(n + FLOW_SLACK) + 2 * round64(2 * n + FLOW_SLACK);
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
        l->gx = (int16_t *)p + origin;
        p += round64(2 * n + FLOW_SLACK);
        l->gy = (int16_t *)p + origin;
        p += round64(2 * n + FLOW_SLACK);
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

/* Fills the level's border by mirroring its pixels, rows first, then whole padded rows. */
static void pad_image(flow_level *l, int pad)
{
    for (int y = 0; y < l->height; y++) {
        uint8_t *row = l->img + (size_t)y * (size_t)l->stride;
        for (int x = 1; x <= pad; x++) {
            row[-x] = row[flow_reflect101(-x, l->width)];
            row[l->width - 1 + x] = row[flow_reflect101(l->width - 1 + x, l->width)];
        }
    }
    for (int y = 1; y <= pad; y++) {
        const uint8_t *top = l->img + (size_t)flow_reflect101(-y, l->height) * (size_t)l->stride;
        const uint8_t *bot =
            l->img + (size_t)flow_reflect101(l->height - 1 + y, l->height) * (size_t)l->stride;
        memcpy(l->img - (size_t)y * (size_t)l->stride - pad, top - pad, (size_t)l->stride);
        memcpy(l->img + (size_t)(l->height - 1 + y) * (size_t)l->stride - pad, bot - pad,
               (size_t)l->stride);
    }
}

/* cv::pyrDown: the 5x5 binomial kernel ([1 4 6 4 1] / 16 in each direction) at every second
 * pixel, mirrored borders, rounded (sum + 128) >> 8. Columns first, into one row of 16-bit
 * sums: a column's sum is at most 16 * 255 and the whole at most 256 * 255 + 128 < 2^16, so
 * 16-bit lanes hold them exactly and the compiler's vectorizer can use 8 or 16 of them. */
static void reduce(const flow_level *src, flow_level *dst, uint16_t *rows)
{
    uint16_t *t = rows + 2;
    const int sw = src->width;
    for (int y = 0; y < dst->height; y++) {
        const uint8_t *r[5];
        for (int k = 0; k < 5; k++)
            r[k] = src->img + (size_t)flow_reflect101(2 * y - 2 + k, src->height) *
                                  (size_t)src->stride;
        const uint8_t *r0 = r[0], *r1 = r[1], *r2 = r[2], *r3 = r[3], *r4 = r[4];
        for (int x = 0; x < sw; x++)
            t[x] = (uint16_t)(r0[x] + 4 * (r1[x] + r3[x]) + 6 * r2[x] + r4[x]);
        for (int k = 1; k <= 2; k++) {
            t[-k] = t[flow_reflect101(-k, sw)];
            t[sw - 1 + k] = t[flow_reflect101(sw - 1 + k, sw)];
        }
        uint8_t *d = dst->img + (size_t)y * (size_t)dst->stride;
        for (int x = 0; x < dst->width; x++) {
            const uint16_t *c = t + 2 * x;
            d[x] = (uint8_t)((uint16_t)(c[-2] + 4 * (c[-1] + c[1]) + 6 * c[0] + c[2] + 128) >> 8);
        }
    }
}

/* Scharr's 3x3 gradients ([3 10 3] across, [-1 0 1] along), unscaled (32 times the pixel
 * difference per pixel) as OpenCV's tracker keeps them; the padded image supplies the mirrored
 * neighbours of edge pixels. The gradients' border stays zero from the allocation (calloc). */
static void gradients(flow_level *l)
{
    for (int y = 0; y < l->height; y++) {
        const uint8_t *a = l->img + (size_t)(y - 1) * (size_t)l->stride;
        const uint8_t *b = a + l->stride, *c = b + l->stride;
        int16_t *gx = l->gx + (size_t)y * (size_t)l->stride;
        int16_t *gy = l->gy + (size_t)y * (size_t)l->stride;
        for (int x = 0; x < l->width; x++) {
            gx[x] = (int16_t)(3 * (a[x + 1] - a[x - 1] + c[x + 1] - c[x - 1]) +
                              10 * (b[x + 1] - b[x - 1]));
            gy[x] = (int16_t)(3 * (c[x - 1] - a[x - 1] + c[x + 1] - a[x + 1]) + 10 * (c[x] - a[x]));
        }
    }
}

sh_status sh_flow_pyramid_build(sh_flow_pyramid *pyr, const sh_plane *luma, int with_gradients)
{
    if (!pyr || !luma || !luma->data)
        return sh_error_set(SH_EINVAL, "flow: no pyramid or no frame");
    flow_level *l0 = &pyr->level[0];
    if (luma->width != l0->width || luma->height != l0->height || luma->stride < luma->width)
        return sh_error_set(SH_EINVAL, "flow: frame %dx%d (stride %d), pyramid made for %dx%d",
                            luma->width, luma->height, luma->stride, l0->width, l0->height);
    for (int y = 0; y < l0->height; y++)
        memcpy(l0->img + (size_t)y * (size_t)l0->stride,
               luma->data + (size_t)y * (size_t)luma->stride, (size_t)l0->width);
    pad_image(l0, pyr->pad);
    for (int k = 1; k <= pyr->levels; k++) {
        reduce(&pyr->level[k - 1], &pyr->level[k], pyr->rows);
        pad_image(&pyr->level[k], pyr->pad);
    }
    pyr->has_gradients = with_gradients != 0;
    if (with_gradients)
        for (int k = 0; k <= pyr->levels; k++) gradients(&pyr->level[k]);
    return SH_OK;
}
