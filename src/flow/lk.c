/* Pyramidal Lucas-Kanade (Bouguet 2000) for one point at a time, coarse to fine.
 *
 * Each level solves the 2x2 normal equations of the window's brightness constancy by
 * Gauss-Newton steps. The numbers follow cv::calcOpticalFlowPyrLK (OpenCV's lkpyramid.cpp),
 * its oracle: pixels sampled with 14-bit bilinear weights and kept as 1/32 grey levels, Scharr
 * gradients, the structure tensor and the step's right-hand side scaled by 2^-20, the same
 * stopping rules (a step shorter than eps; two steps that cancel, which is an oscillation
 * across the minimum, halved), and the same minimum-eigenvalue test. The sums are 64-bit
 * integers where OpenCV adds floats: exact, so every architecture gets the same result. */
#include "flow_internal.h"

#include <string.h>

#include <math.h>
#include <stdlib.h>

#define W_BITS 14
#define W_ONE (1 << W_BITS)
#define DESCALE(x, n) (((x) + (1 << ((n)-1))) >> (n))
#define FLT_SCALE (1.0f / (1 << 20))

/* Bilinear weights of the fractions (a, b) in 14 bits, summing to exactly 2^14: top-left,
 * top-right, bottom-left, bottom-right. */
static void bilinear(float a, float b, int w[4])
{
    w[0] = (int)lrintf((1.f - a) * (1.f - b) * W_ONE);
    w[1] = (int)lrintf(a * (1.f - b) * W_ONE);
    w[2] = (int)lrintf((1.f - a) * b * W_ONE);
    w[3] = W_ONE - w[0] - w[1] - w[2];
}

/* Whether a window whose top-left corner is at (x, y) may be read on level l: its integer
 * corner floor(x), floor(y) up to one window outside the level, which the pad holds. Tested on
 * the float, before any conversion, so that a diverging step or NaN is refused, not truncated. */
static int inside(const flow_level *l, float x, float y, int win)
{
    return x >= (float)-win && x < (float)l->width && y >= (float)-win && y < (float)l->height;
}

/* Whether the pixels a window at integer corner (ix, iy) reads, [ix, ix + win] x [iy, iy + win]
 * with the bilinear neighbour, were built (flow_level's img_box or grad_box). */
static int built(const int b[4], int ix, int iy, int win)
{
    return ix >= b[0] && iy >= b[1] && ix + win + 1 <= b[2] && iy + win + 1 <= b[3];
}

/* A search that reached an unbuilt part of a pyramid stops there: its position (nx, ny) on
 * level lv, in level 0 px, tells the caller where it was going. */
static uint8_t unbuilt(float nx, float ny, int lv, float *qx, float *qy)
{
    *qx = nx * (float)(1 << lv);
    *qy = ny * (float)(1 << lv);
    return SH_FLOW_UNBUILT;
}

/* The previous frame's window, rows FLOW_WROW(win) apart. */
typedef struct {
    int16_t img[SH_FLOW_MAX_WIN * FLOW_WROW(SH_FLOW_MAX_WIN)]; /* 1/32 grey levels */
    int16_t gx[SH_FLOW_MAX_WIN * FLOW_WROW(SH_FLOW_MAX_WIN)];  /* Scharr units */
    int16_t gy[SH_FLOW_MAX_WIN * FLOW_WROW(SH_FLOW_MAX_WIN)];
} window;

/* A point's window in the previous frame on level lv: sampled into I, gx, gy with its sums, or
 * why not (outside the image, or in a part of the pyramid not built). */
enum { PREV_SAMPLED, PREV_OUTSIDE, PREV_UNBUILT };

static int sample_prev(const flow_level *L0, float px, float py, int lv, int win, int16_t *I,
                       int16_t *gx, int16_t *gy, int64_t sum[3])
{
    const float half = (float)(win - 1) * 0.5f;
    float sx = px * (1.0f / (float)(1 << lv)) - half, sy = py * (1.0f / (float)(1 << lv)) - half;
    if (!inside(L0, sx, sy, win)) return PREV_OUTSIDE;
    int ix = (int)floorf(sx), iy = (int)floorf(sy);
    if (!built(L0->grad_box, ix, iy, win)) return PREV_UNBUILT;
    int w[4];
    bilinear(sx - (float)ix, sy - (float)iy, w);
    flow_window_prev(L0, ix, iy, w, win, I, gx, gy, sum);
    return PREV_SAMPLED;
}

/* The previous frame's level-0 window about (px, py) sampled through the 2x2 matrix M (row
 * major): T(d) = prev(p + M d) for the window's offsets d, with T's own Scharr gradients and their
 * sums (sh_flow_track_windows_warped says why; flow_window_prev_warped samples it). Here: whether
 * the samples' box may be read, and where they start and step, in 16.16 fixed point offset by the
 * pad so that every position is >= 0 and shifts floor it. */
static int sample_prev_warped(const flow_level *L, int pad, float px, float py, int win, const float M[4],
                              int16_t *I, int16_t *gx, int16_t *gy, int64_t sum[3])
{
    const int h = win / 2 + 1;
    /* the samples' box: the template's corners, and the bilinear neighbour */
    const double ex = h * (fabs((double)M[0]) + fabs((double)M[1])), ey = h * (fabs((double)M[2]) + fabs((double)M[3]));
    if (!(px - ex >= (double)-pad && px + ex + 1 < (double)(L->width + pad) && py - ey >= (double)-pad &&
          py + ey + 1 < (double)(L->height + pad)))
        return PREV_OUTSIDE;
    const int *b = L->img_box;
    if (!((int)floor(px - ex) >= b[0] && (int)floor(py - ey) >= b[1] && (int)floor(px + ex) + 2 <= b[2] &&
          (int)floor(py + ey) + 2 <= b[3]))
        return PREV_UNBUILT;
    const double one = 65536.0;
    const int32_t col[2] = {(int32_t)lrint(M[0] * one), (int32_t)lrint(M[2] * one)};
    const int32_t row[2] = {(int32_t)lrint(M[1] * one), (int32_t)lrint(M[3] * one)};
    const int32_t start[2] = {(int32_t)lrint((px + pad - h * ((double)M[0] + (double)M[1])) * one),
                              (int32_t)lrint((py + pad - h * ((double)M[2] + (double)M[3])) * one)};
    flow_window_prev_warped(L, pad, start, col, row, win, I, gx, gy, sum);
    return PREV_SAMPLED;
}

/* A fixed previous frame's windows around fixed points, every level (sh_flow_windows_create):
 * for point i and level l, state[i (levels + 1) + l], its sums and its samples. */
struct sh_flow_windows {
    const sh_flow_pyramid *pyr; /* what they were sampled from: warped windows are sampled anew */
    int n, win, levels, params_levels, width, height;
    size_t len;      /* samples of one array of a window: win * FLOW_WROW(win) */
    float *xy;       /* n pairs */
    uint8_t *state;  /* PREV_* */
    int64_t *sum;    /* 3 a window */
    int16_t *data;   /* I, gx, gy a window */
};

/* The previous frame's window of point ci (at px, py) on level lv: on level 0 with a warp M,
 * sampled through it into s; else from cache when it is not NULL, else sampled from prev into
 * s. */
static int prev_window(const sh_flow_pyramid *prev, const sh_flow_windows *cache, int ci, int lv,
                       float px, float py, const float *M, int win, window *s, const int16_t **I,
                       const int16_t **gx, const int16_t **gy, int64_t sum[3])
{
    if (M && lv == 0) {
        const sh_flow_pyramid *src = cache ? cache->pyr : prev;
        *I = s->img, *gx = s->gx, *gy = s->gy;
        return sample_prev_warped(&src->level[0], src->pad, px, py, win, M, s->img, s->gx, s->gy, sum);
    }
    if (!cache) {
        *I = s->img, *gx = s->gx, *gy = s->gy;
        return sample_prev(&prev->level[lv], px, py, lv, win, s->img, s->gx, s->gy, sum);
    }
    size_t k = (size_t)ci * (size_t)(cache->levels + 1) + (size_t)lv;
    memcpy(sum, cache->sum + 3 * k, 3 * sizeof *sum);
    *I = cache->data + 3 * k * cache->len;
    *gx = *I + cache->len;
    *gy = *gx + cache->len;
    return cache->state[k];
}

/* One point through every level. p: its position in prev; q: the starting position in next.
 * The previous frame's windows are sampled from prev, or taken from cache (point ci) when it
 * is not NULL. */
static uint8_t track_point(const sh_flow_params *prm, const sh_flow_pyramid *prev,
                           const sh_flow_windows *cache, int ci, const sh_flow_pyramid *next,
                           int levels, float px, float py, const float *M, float *qx, float *qy,
                           float *err, window *s)
{
    const int win = prm->win;
    const float half = (float)(win - 1) * 0.5f;
    const double eps2 = prm->eps * prm->eps;
    uint8_t status = SH_FLOW_OK;
    float nx = *qx * (1.0f / (float)(1 << levels)), ny = *qy * (1.0f / (float)(1 << levels));
    for (int lv = levels; lv >= 0; lv--) {
        const flow_level *L1 = &next->level[lv];
        if (lv != levels) {
            nx *= 2.f;
            ny *= 2.f;
        }
        const int16_t *I, *GX, *GY;
        int64_t sum[3];
        int ps = prev_window(prev, cache, ci, lv, px, py, M, win, s, &I, &GX, &GY, sum);
        if (ps == PREV_OUTSIDE) {
            if (lv == 0) status = SH_FLOW_OUTSIDE;
            continue;
        }
        if (ps == PREV_UNBUILT) return unbuilt(nx, ny, lv, qx, qy);
        int w[4];
        const float a11 = (float)sum[0] * FLT_SCALE, a12 = (float)sum[1] * FLT_SCALE,
                    a22 = (float)sum[2] * FLT_SCALE;
        float det = a11 * a22 - a12 * a12;
        float min_eig = (a22 + a11 - sqrtf((a11 - a22) * (a11 - a22) + 4.f * a12 * a12)) /
                        (float)(2 * win * win);
        if (min_eig < prm->min_eig || det < 1.1920929e-7f) { /* FLT_EPSILON, as OpenCV */
            if (lv == 0) status = SH_FLOW_FLAT;
            continue;
        }
        float inv = 1.f / det;
        float cx = nx - half, cy = ny - half, ddx = 0.f, ddy = 0.f;
        for (int j = 0; j < prm->max_iter; j++) {
            if (!inside(L1, cx, cy, win)) {
                if (lv == 0) status = SH_FLOW_OUTSIDE;
                break;
            }
            int jx = (int)floorf(cx), jy = (int)floorf(cy);
            if (!built(L1->img_box, jx, jy, win)) return unbuilt(nx, ny, lv, qx, qy);
            bilinear(cx - (float)jx, cy - (float)jy, w);
            flow_window_mismatch(L1, jx, jy, w, win, I, GX, GY, sum);
            const float b1 = (float)sum[0] * FLT_SCALE, b2 = (float)sum[1] * FLT_SCALE;
            float dx = (a12 * b2 - a22 * b1) * inv, dy = (a12 * b1 - a11 * b2) * inv;
            cx += dx;
            cy += dy;
            nx = cx + half;
            ny = cy + half;
            if ((double)dx * dx + (double)dy * dy <= eps2) break;
            if (j > 0 && fabsf(dx + ddx) < 0.01f && fabsf(dy + ddy) < 0.01f) {
                nx -= dx * 0.5f;
                ny -= dy * 0.5f;
                break;
            }
            ddx = dx;
            ddy = dy;
        }
        /* the last step may have left the image: said so whether or not err is asked for */
        if (lv == 0 && status == SH_FLOW_OK) {
            float ex = nx - half, ey = ny - half;
            if (!inside(L1, ex, ey, win)) {
                status = SH_FLOW_OUTSIDE;
            } else if (err) {
                int jx = (int)floorf(ex), jy = (int)floorf(ey);
                if (!built(L1->img_box, jx, jy, win)) return unbuilt(nx, ny, lv, qx, qy);
                bilinear(ex - (float)jx, ey - (float)jy, w);
                *err = (float)flow_window_abs_mismatch(L1, jx, jy, w, win, I) * (1.f / (float)(32 * win * win));
            }
        }
    }
    *qx = nx;
    *qy = ny;
    return status;
}

/* The points' loop of sh_flow_track and sh_flow_track_windows: point idx[j] (j when idx is
 * NULL) of xy, its guess, out, status and err at j. */
static void track_points(const sh_flow_params *params, const sh_flow_pyramid *prev,
                         const sh_flow_windows *cache, const sh_flow_pyramid *next, int levels,
                         int n, const int *idx, const float *xy, const float *guess,
                         const float *warp, float *out, uint8_t *status, float *err)
{
    window s; /* 24 KB at the largest window: the stack, not the heap, in the per-frame path */
    for (int j = 0; j < n; j++) {
        const int i = idx ? idx[j] : j;
        float px = xy[2 * i], py = xy[2 * i + 1];
        float qx = guess ? guess[2 * j] : px, qy = guess ? guess[2 * j + 1] : py;
        if (err) err[j] = 0.f;
        /* NaN or far outside any frame: refused before the levels' arithmetic sees it */
        const float far = 4.f * SH_IMAGE_MAX_SIZE;
        if (!(fabsf(px) < far && fabsf(py) < far && fabsf(qx) < far && fabsf(qy) < far)) {
            out[2 * j] = px;
            out[2 * j + 1] = py;
            status[j] = SH_FLOW_OUTSIDE;
            continue;
        }
        status[j] = track_point(params, prev, cache, i, next, levels, px, py,
                                warp ? warp + 4 * j : NULL, &qx, &qy, err ? &err[j] : NULL, &s);
        out[2 * j] = qx;
        out[2 * j + 1] = qy;
    }
}

sh_status sh_flow_track(const sh_flow_params *params, const sh_flow_pyramid *prev,
                        const sh_flow_pyramid *next, int n, const float *xy, const float *guess,
                        float *out, uint8_t *status, float *err)
{
    if (!params || !prev || !next || n < 0 || (n > 0 && (!xy || !out || !status)))
        return sh_error_set(SH_EINVAL, "flow: track: missing argument");
    if (params->win != prev->pad || params->win != next->pad ||
        prev->level[0].width != next->level[0].width ||
        prev->level[0].height != next->level[0].height)
        return sh_error_set(SH_EINVAL, "flow: track: the pyramids differ in size or window");
    if (!prev->has_gradients)
        return sh_error_set(SH_EINVAL, "flow: track: the previous pyramid has no gradients");
    int levels = params->levels;
    if (levels > prev->levels) levels = prev->levels;
    if (levels > next->levels) levels = next->levels;
    track_points(params, prev, NULL, next, levels, n, NULL, xy, guess, NULL, out, status, err);
    return SH_OK;
}

sh_status sh_flow_windows_create(const sh_flow_params *params, const sh_flow_pyramid *prev, int n,
                                 const float *xy, sh_flow_windows **out)
{
    if (!out) return sh_error_set(SH_EINVAL, "flow: windows: no output");
    *out = NULL;
    if (!params || !prev || n < 0 || (n > 0 && !xy))
        return sh_error_set(SH_EINVAL, "flow: windows: missing argument");
    if (params->win != prev->pad || !prev->has_gradients)
        return sh_error_set(SH_EINVAL, "flow: windows: a pyramid of another window, or without gradients");
    sh_flow_windows *c = calloc(1, sizeof *c);
    if (!c) return sh_error_set(SH_ENOMEM, "flow: out of memory");
    c->pyr = prev;
    c->n = n;
    c->win = params->win;
    c->params_levels = params->levels;
    c->width = prev->level[0].width;
    c->height = prev->level[0].height;
    c->levels = params->levels < prev->levels ? params->levels : prev->levels;
    c->len = (size_t)params->win * FLOW_WROW(params->win);
    const size_t k = (size_t)(n > 0 ? n : 1) * (size_t)(c->levels + 1);
    c->xy = malloc(2 * (size_t)(n > 0 ? n : 1) * sizeof *c->xy);
    c->state = malloc(k);
    c->sum = malloc(3 * k * sizeof *c->sum);
    c->data = malloc(3 * k * c->len * sizeof *c->data);
    if (!c->xy || !c->state || !c->sum || !c->data) {
        sh_flow_windows_destroy(c);
        return sh_error_set(SH_ENOMEM, "flow: out of memory for %d points' windows", n);
    }
    for (int i = 0; i < 2 * n; i++) c->xy[i] = xy[i];
    sh_flow_windows_refresh(c);
    *out = c;
    return SH_OK;
}

void sh_flow_windows_refresh(sh_flow_windows *c)
{
    const float *xy = c->xy;
    for (int i = 0; i < c->n; i++)
        for (int lv = 0; lv <= c->levels; lv++) {
            size_t e = (size_t)i * (size_t)(c->levels + 1) + (size_t)lv;
            int16_t *I = c->data + 3 * e * c->len;
            /* a point refused before any level (sh_flow_track's far test) is never looked up */
            const float far = 4.f * SH_IMAGE_MAX_SIZE;
            c->state[e] = fabsf(xy[2 * i]) < far && fabsf(xy[2 * i + 1]) < far
                              ? (uint8_t)sample_prev(&c->pyr->level[lv], xy[2 * i], xy[2 * i + 1], lv,
                                                     c->win, I, I + c->len, I + 2 * c->len,
                                                     c->sum + 3 * e)
                              : PREV_OUTSIDE;
        }
}

void sh_flow_windows_destroy(sh_flow_windows *c)
{
    if (!c) return;
    free(c->xy);
    free(c->state);
    free(c->sum);
    free(c->data);
    free(c);
}

sh_status sh_flow_track_windows_warped(const sh_flow_params *params, const sh_flow_windows *prev,
                                       const sh_flow_pyramid *next, int m, const int *idx,
                                       const float *guess, const float *warp, float *out,
                                       uint8_t *status, float *err)
{
    if (!params || !prev || !next || m < 0 || (m > 0 && (!out || !status)))
        return sh_error_set(SH_EINVAL, "flow: track: missing argument");
    if (params->win != prev->win || params->win != next->pad || params->levels != prev->params_levels ||
        prev->width != next->level[0].width || prev->height != next->level[0].height)
        return sh_error_set(SH_EINVAL, "flow: track: windows made with another window, levels or frame size");
    for (int j = 0; idx && j < m; j++)
        if (idx[j] < 0 || idx[j] >= prev->n)
            return sh_error_set(SH_EINVAL, "flow: track: point %d of %d", idx[j], prev->n);
    if (!idx && m > prev->n)
        return sh_error_set(SH_EINVAL, "flow: track: %d points of %d", m, prev->n);
    int levels = prev->levels;
    if (levels > next->levels) levels = next->levels;
    track_points(params, NULL, prev, next, levels, m, idx, prev->xy, guess, warp, out, status, err);
    return SH_OK;
}

sh_status sh_flow_track_windows(const sh_flow_params *params, const sh_flow_windows *prev,
                                const sh_flow_pyramid *next, int m, const int *idx,
                                const float *guess, float *out, uint8_t *status, float *err)
{
    return sh_flow_track_windows_warped(params, prev, next, m, idx, guess, NULL, out, status, err);
}

/* A side x side window of level l whose top-left sample is at (x0, y0), with the searches'
 * bilinear weights, in 1/32 grey levels, rows FLOW_WROW(side) apart; 0 where it is not inside
 * the built part of the level (the caller has checked side). */
static int sample_window(const flow_level *l, float x0, float y0, int side, int16_t *I)
{
    if (!inside(l, x0, y0, side)) return 0;
    const int ix = (int)floorf(x0), iy = (int)floorf(y0);
    if (!built(l->img_box, ix, iy, side)) return 0;
    int w[4];
    bilinear(x0 - (float)ix, y0 - (float)iy, w);
    const int wr = FLOW_WROW(side), s = l->stride;
    for (int y = 0; y < side; y++) {
        const uint8_t *r = l->img + (ptrdiff_t)(iy + y) * s + ix;
        for (int x = 0; x < side; x++)
            I[y * wr + x] = (int16_t)DESCALE(r[x] * w[0] + r[x + 1] * w[1] + r[x + s] * w[2] + r[x + s + 1] * w[3],
                                             W_BITS - 5);
        for (int x = side; x < wr; x++) I[y * wr + x] = 0;
    }
    return 1;
}

float sh_flow_window_correlation(const sh_flow_pyramid *prev, float px, float py, const sh_flow_pyramid *next,
                                 float qx, float qy, int side)
{
    if (!prev || !next || side < 1 || side > SH_FLOW_MAX_WIN || side % 2 == 0) return NAN;
    const float half = (float)(side - 1) * 0.5f;
    int16_t A[SH_FLOW_MAX_WIN * FLOW_WROW(SH_FLOW_MAX_WIN)], B[SH_FLOW_MAX_WIN * FLOW_WROW(SH_FLOW_MAX_WIN)];
    if (!sample_window(&prev->level[0], px - half, py - half, side, A) ||
        !sample_window(&next->level[0], qx - half, qy - half, side, B))
        return NAN;
    /* sums of 16-bit samples over at most 65 x 65: exact in 64 bits */
    int64_t sa = 0, sb = 0, saa = 0, sbb = 0, sab = 0;
    const int wr = FLOW_WROW(side);
    for (int y = 0; y < side; y++)
        for (int x = 0; x < side; x++) {
            const int64_t a = A[y * wr + x], b = B[y * wr + x];
            sa += a, sb += b, saa += a * a, sbb += b * b, sab += a * b;
        }
    const double n = (double)side * side, va = (double)saa - (double)sa * (double)sa / n,
                 vb = (double)sbb - (double)sb * (double)sb / n;
    if (!(va > 0 && vb > 0)) return NAN;
    return (float)(((double)sab - (double)sa * (double)sb / n) / sqrt(va * vb));
}

float sh_flow_window_difference(const sh_flow_pyramid *prev, float px, float py, const sh_flow_pyramid *next,
                                float qx, float qy, int side)
{
    if (!prev || !next || side < 1 || side > SH_FLOW_MAX_WIN || side % 2 == 0) return NAN;
    const flow_level *b = &next->level[0];
    const float half = (float)(side - 1) * 0.5f;
    const float bx = qx - half, by = qy - half;
    /* prev's window as the searches' template, then the error measure's sum against next's */
    int16_t I[SH_FLOW_MAX_WIN * FLOW_WROW(SH_FLOW_MAX_WIN)];
    if (!sample_window(&prev->level[0], px - half, py - half, side, I) || !inside(b, bx, by, side)) return NAN;
    const int jx = (int)floorf(bx), jy = (int)floorf(by);
    if (!built(b->img_box, jx, jy, side)) return NAN;
    int w[4];
    bilinear(bx - (float)jx, by - (float)jy, w);
    return (float)flow_window_abs_mismatch(b, jx, jy, w, side, I) * (1.f / (float)(32 * side * side));
}
