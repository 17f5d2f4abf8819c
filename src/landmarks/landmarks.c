/* Natural landmarks: where they may be chosen, and the tests each must pass per frame
 * (landmarks.h says why each test is there). */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "stillheart/landmarks.h"

struct sh_landmarks {
    sh_landmarks_params p;
    int width, height, n;
    sh_flow_pyramid *ref, *cur;
    float *ref_xy;   /* n pairs */
    float *fwd;      /* n pairs: forward result */
    float *back;     /* n pairs: backward result, and its starting guess */
    float *err;      /* n */
    uint8_t *st_fwd, *st_back;
};

const char *sh_landmark_verdict_name(sh_landmark_verdict v)
{
    static const char *const names[SH_LANDMARK_VERDICTS] = {"accepted", "lost", "photometric", "backward",
                                                            "disagrees"};
    return (unsigned)v < SH_LANDMARK_VERDICTS ? names[v] : "?";
}

void sh_landmarks_params_default(sh_landmarks_params *p)
{
    memset(p, 0, sizeof *p);
    p->max_points = 200;
    p->min_distance = 20;
    p->quality = 0.01;
    p->tag_margin = 2;
    p->highlight = 250;
    p->max_photometric = 12;
    p->max_backward_px = 0.5;
    p->max_disagreement_px = 3;
    sh_flow_params_default(&p->flow);
}

static sh_status check_params(const sh_landmarks_params *p)
{
    if (p->max_points < 1 || p->max_points > 100000)
        return sh_error_set(SH_EINVAL, "landmarks: max_points %d, not 1 to 100000", p->max_points);
    if (!(p->min_distance >= 0) || !(p->quality > 0 && p->quality <= 1) || !(p->tag_margin >= 0) ||
        p->highlight < 1 || p->highlight > 256)
        return sh_error_set(SH_EINVAL, "landmarks: min_distance, quality (0, 1], tag_margin >= 0 or highlight 1-256 "
                            "out of range");
    if (!(p->max_photometric > 0) || !(p->max_backward_px >= 0) || !(p->max_disagreement_px > 0))
        return sh_error_set(SH_EINVAL, "landmarks: max_photometric and max_disagreement_px must be > 0, "
                            "max_backward_px >= 0");
    return SH_OK;
}

/* Squared distance from (x, y) to the segment a-b. */
static double seg_dist2(double x, double y, double ax, double ay, double bx, double by)
{
    double dx = bx - ax, dy = by - ay, l2 = dx * dx + dy * dy;
    double t = l2 > 0 ? ((x - ax) * dx + (y - ay) * dy) / l2 : 0;
    t = t < 0 ? 0 : t > 1 ? 1 : t;
    double ex = ax + t * dx - x, ey = ay + t * dy - y;
    return ex * ex + ey * ey;
}

/* Inside the quad (either winding) or within r of its edges. */
static int near_quad(const double *q, double x, double y, double r)
{
    int pos = 0, neg = 0;
    for (int k = 0; k < 4; k++) {
        const double *a = q + 2 * k, *b = q + 2 * ((k + 1) % 4);
        if (seg_dist2(x, y, a[0], a[1], b[0], b[1]) <= r * r) return 1;
        double c = (b[0] - a[0]) * (y - a[1]) - (b[1] - a[1]) * (x - a[0]);
        pos += c > 0;
        neg += c < 0;
    }
    return !(pos && neg);
}

/* Clears every pixel of the mask near a tag: its quad grown by the quiet zone (an eighth of the
 * mean side), the margin and half a window. */
static void clear_tags(uint8_t *mask, int w, int h, const double *tags, int n_tags, double margin, int half_win)
{
    for (int t = 0; t < n_tags; t++) {
        const double *q = tags + 8 * t;
        double side = 0, x0 = INFINITY, x1 = -INFINITY, y0 = INFINITY, y1 = -INFINITY;
        for (int k = 0; k < 4; k++) {
            const double *a = q + 2 * k, *b = q + 2 * ((k + 1) % 4);
            side += hypot(b[0] - a[0], b[1] - a[1]) / 4;
            x0 = fmin(x0, a[0]), x1 = fmax(x1, a[0]), y0 = fmin(y0, a[1]), y1 = fmax(y1, a[1]);
        }
        if (!isfinite(side)) continue;
        double r = side / 8 + margin + half_win;
        int px0 = (int)fmax(0, floor(x0 - r)), px1 = (int)fmin(w - 1, ceil(x1 + r));
        int py0 = (int)fmax(0, floor(y0 - r)), py1 = (int)fmin(h - 1, ceil(y1 + r));
        for (int y = py0; y <= py1; y++)
            for (int x = px0; x <= px1; x++)
                if (near_quad(q, x, y, r)) mask[(size_t)y * w + x] = 0;
    }
}

/* Clears every pixel whose window (side 2 * half_win + 1) holds a highlight, through an integral
 * image of the highlight pixels. */
static sh_status clear_highlights(uint8_t *mask, const sh_plane *luma, int level, int half_win)
{
    int w = luma->width, h = luma->height;
    uint32_t *sum = calloc((size_t)(w + 1) * (h + 1), sizeof *sum);
    if (!sum) return sh_error_set(SH_ENOMEM, "landmarks: out of memory");
    for (int y = 0; y < h; y++) {
        uint32_t row = 0;
        for (int x = 0; x < w; x++) {
            row += luma->data[(size_t)y * luma->stride + x] >= level;
            sum[(size_t)(y + 1) * (w + 1) + x + 1] = sum[(size_t)y * (w + 1) + x + 1] + row;
        }
    }
    for (int y = 0; y < h; y++) {
        int ya = y - half_win < 0 ? 0 : y - half_win, yb = y + half_win + 1 > h ? h : y + half_win + 1;
        for (int x = 0; x < w; x++) {
            int xa = x - half_win < 0 ? 0 : x - half_win, xb = x + half_win + 1 > w ? w : x + half_win + 1;
            uint32_t c = sum[(size_t)yb * (w + 1) + xb] - sum[(size_t)ya * (w + 1) + xb] -
                         sum[(size_t)yb * (w + 1) + xa] + sum[(size_t)ya * (w + 1) + xa];
            if (c) mask[(size_t)y * w + x] = 0;
        }
    }
    free(sum);
    return SH_OK;
}

/* Where a landmark may be chosen (landmarks.h): the hull, off the tags and highlights, half a
 * window inside the image. */
static sh_status make_mask(const sh_landmarks_params *p, const sh_plane *ref, const sh_hull *hull,
                           const double *tags, int n_tags, uint8_t *mask)
{
    int w = ref->width, h = ref->height, half = p->flow.win / 2;
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++)
            mask[(size_t)y * w + x] = x >= half && x < w - half && y >= half && y < h - half &&
                                      (!hull || sh_hull_contains(hull, x, y));
    clear_tags(mask, w, h, tags, n_tags, p->tag_margin, half);
    return clear_highlights(mask, ref, p->highlight, half);
}

sh_status sh_landmarks_create(const sh_landmarks_params *params, const sh_plane *reference, const sh_hull *hull,
                              const double *tags, int n_tags, sh_landmarks **out)
{
    sh_status st = check_params(params);
    if (st != SH_OK) return st;
    if (!reference || !reference->data || reference->width < 2 || reference->height < 2 || n_tags < 0 ||
        (n_tags > 0 && !tags))
        return sh_error_set(SH_EINVAL, "landmarks: no reference plane, or tags missing");
    sh_landmarks *lm = calloc(1, sizeof *lm);
    if (!lm) return sh_error_set(SH_ENOMEM, "landmarks: out of memory");
    lm->p = *params;
    lm->width = reference->width;
    lm->height = reference->height;
    size_t m = (size_t)params->max_points;
    uint8_t *mask = malloc((size_t)lm->width * lm->height);
    lm->ref_xy = malloc(2 * m * sizeof *lm->ref_xy);
    lm->fwd = malloc(2 * m * sizeof *lm->fwd);
    lm->back = malloc(2 * m * sizeof *lm->back);
    lm->err = malloc(m * sizeof *lm->err);
    lm->st_fwd = malloc(m);
    lm->st_back = malloc(m);
    if (!mask || !lm->ref_xy || !lm->fwd || !lm->back || !lm->err || !lm->st_fwd || !lm->st_back) {
        free(mask);
        sh_landmarks_destroy(lm);
        return sh_error_set(SH_ENOMEM, "landmarks: out of memory");
    }
    st = make_mask(params, reference, hull, tags, n_tags, mask);
    if (st == SH_OK) {
        sh_flow_corner_params cp;
        sh_flow_corner_params_default(&cp);
        cp.max_points = params->max_points;
        cp.quality = params->quality;
        cp.min_distance = params->min_distance;
        sh_plane mp = {mask, lm->width, lm->height, lm->width};
        st = sh_flow_corners(reference, &mp, &cp, lm->ref_xy, &lm->n);
    }
    free(mask);
    if (st == SH_OK) st = sh_flow_pyramid_create(lm->width, lm->height, &params->flow, &lm->ref);
    if (st == SH_OK) st = sh_flow_pyramid_create(lm->width, lm->height, &params->flow, &lm->cur);
    if (st == SH_OK) st = sh_flow_pyramid_build(lm->ref, reference, 1);
    if (st != SH_OK) {
        sh_landmarks_destroy(lm);
        return st;
    }
    *out = lm;
    return SH_OK;
}

void sh_landmarks_destroy(sh_landmarks *lm)
{
    if (!lm) return;
    sh_flow_pyramid_destroy(lm->ref);
    sh_flow_pyramid_destroy(lm->cur);
    free(lm->ref_xy);
    free(lm->fwd);
    free(lm->back);
    free(lm->err);
    free(lm->st_fwd);
    free(lm->st_back);
    free(lm);
}

int sh_landmarks_count(const sh_landmarks *lm) { return lm->n; }
const float *sh_landmarks_reference(const sh_landmarks *lm) { return lm->ref_xy; }

sh_status sh_landmarks_track(sh_landmarks *lm, const sh_plane *luma, const float *predicted, float *xy,
                             uint8_t *verdict, sh_landmarks_counts *counts)
{
    if (!luma || luma->width != lm->width || luma->height != lm->height)
        return sh_error_set(SH_EINVAL, "landmarks: a %dx%d frame for a %dx%d reference", luma ? luma->width : 0,
                            luma ? luma->height : 0, lm->width, lm->height);
    const sh_landmarks_params *p = &lm->p;
    int n = lm->n, backward = p->max_backward_px > 0;
    if (counts) memset(counts, 0, sizeof *counts);
    if (n == 0) return SH_OK;
    /* the frame's gradients only when it is tracked from, by the backward test */
    sh_status st = sh_flow_pyramid_build(lm->cur, luma, backward);
    if (st == SH_OK)
        st = sh_flow_track(&p->flow, lm->ref, lm->cur, n, lm->ref_xy, predicted, lm->fwd, lm->st_fwd, lm->err);
    if (st == SH_OK && backward) {
        /* back from the result, starting where the prediction's inverse puts it: the result
         * minus the predicted displacement (without a prediction, at the result itself, as the
         * forward search started at the reference position) */
        for (int i = 0; i < 2 * n; i++) lm->back[i] = predicted ? lm->fwd[i] - (predicted[i] - lm->ref_xy[i]) : lm->fwd[i];
        st = sh_flow_track(&p->flow, lm->cur, lm->ref, n, lm->fwd, lm->back, lm->back, lm->st_back, NULL);
    }
    if (st != SH_OK) return st;
    for (int i = 0; i < n; i++) {
        const float *f = lm->fwd + 2 * i, *r = lm->ref_xy + 2 * i;
        sh_landmark_verdict v = SH_LANDMARK_ACCEPTED;
        if (lm->st_fwd[i] != SH_FLOW_OK || (backward && lm->st_back[i] != SH_FLOW_OK) || !isfinite(f[0]) ||
            !isfinite(f[1]))
            v = SH_LANDMARK_LOST;
        else if (!(lm->err[i] <= p->max_photometric))
            v = SH_LANDMARK_PHOTOMETRIC;
        else if (backward && !(hypot(lm->back[2 * i] - r[0], lm->back[2 * i + 1] - r[1]) <= p->max_backward_px))
            v = SH_LANDMARK_BACKWARD;
        else if (predicted && !(hypot(f[0] - predicted[2 * i], f[1] - predicted[2 * i + 1]) <= p->max_disagreement_px))
            v = SH_LANDMARK_DISAGREES;
        xy[2 * i] = f[0];
        xy[2 * i + 1] = f[1];
        verdict[i] = (uint8_t)v;
        if (counts) counts->verdicts[v]++;
    }
    return SH_OK;
}
