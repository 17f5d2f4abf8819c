/* Frames whose markers are too few for a map of their own: the landmarks' predictions carried
 * from the frame before, and whether the landmarks found then vouch for the map they make
 * (landmarks.h, docs/landmarks.md "Carried frames"). Only the public view of sh_landmarks: the
 * reference positions. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "stillheart/landmarks.h"

/* The k nearest landmarks (reference positions) to (x, y) among those with ok[i] and, when verdict
 * is given, accepted there, skipping `self`: their indices into near, nearest first; the count
 * found. n is small (hundreds) and carried frames are few: a scan, no index. */
static int nearest(const float *ref, int n, const uint8_t *ok, const uint8_t *verdict, int self, double x, double y,
                   int k, int *near, double *d2)
{
    int m = 0;
    for (int i = 0; i < n; i++) {
        if (i == self || !ok[i] || (verdict && verdict[i] != SH_LANDMARK_ACCEPTED)) continue;
        double dx = ref[2 * i] - x, dy = ref[2 * i + 1] - y, d = dx * dx + dy * dy;
        int j;
        if (m < k) j = m++;
        else if (d < d2[k - 1]) j = k - 1; /* the farthest kept makes room */
        else continue;
        while (j > 0 && d2[j - 1] > d) {
            d2[j] = d2[j - 1];
            near[j] = near[j - 1];
            j--;
        }
        d2[j] = d;
        near[j] = i;
    }
    return m;
}

static int by_value(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

/* The median of v[0..m-1] (m >= 1), reordering v. */
static double median(double *v, int m)
{
    qsort(v, (size_t)m, sizeof *v, by_value);
    return m % 2 ? v[m / 2] : 0.5 * (v[m / 2 - 1] + v[m / 2]);
}

/* The median displacement (position minus reference) of the landmarks in idx[0..m-1]. */
static void median_displacement(const float *ref, const float *xy, const int *idx, int m, double *dx, double *dy)
{
    double vx[SH_LANDMARKS_CARRY_NEAR], vy[SH_LANDMARKS_CARRY_NEAR];
    for (int j = 0; j < m; j++) {
        vx[j] = xy[2 * idx[j]] - ref[2 * idx[j]];
        vy[j] = xy[2 * idx[j] + 1] - ref[2 * idx[j] + 1];
    }
    *dx = median(vx, m);
    *dy = median(vy, m);
}

/* The predictions: each landmark at its reference position plus its displacement in the frame
 * before (its own where it was accepted there, else the median of its SH_LANDMARKS_CARRY_NEAR
 * nearest that were), plus shift. 0 when none was accepted before (nothing to carry). */
static int predict(const sh_landmarks *lm, const float *prev_xy, const uint8_t *prev_ok, const double shift[2],
                   float *predicted)
{
    const int n = sh_landmarks_count(lm);
    const float *ref = sh_landmarks_reference(lm);
    int ok = 0;
    for (int i = 0; i < n; i++) ok += prev_ok[i] && isfinite(prev_xy[2 * i]) && isfinite(prev_xy[2 * i + 1]);
    if (ok == 0) return 0;
    int near[SH_LANDMARKS_CARRY_NEAR];
    double d2[SH_LANDMARKS_CARRY_NEAR];
    for (int i = 0; i < n; i++) {
        double dx, dy;
        if (prev_ok[i] && isfinite(prev_xy[2 * i]) && isfinite(prev_xy[2 * i + 1])) {
            dx = prev_xy[2 * i] - ref[2 * i];
            dy = prev_xy[2 * i + 1] - ref[2 * i + 1];
        } else {
            /* an accepted landmark with a NaN position among them: the isfinite below refuses */
            int m = nearest(ref, n, prev_ok, NULL, i, ref[2 * i], ref[2 * i + 1], SH_LANDMARKS_CARRY_NEAR, near, d2);
            median_displacement(ref, prev_xy, near, m, &dx, &dy);
        }
        predicted[2 * i] = (float)(ref[2 * i] + dx + shift[0]);
        predicted[2 * i + 1] = (float)(ref[2 * i + 1] + dy + shift[1]);
        if (!isfinite(predicted[2 * i]) || !isfinite(predicted[2 * i + 1])) return 0;
    }
    return 1;
}

/* The check (landmarks.h): 1 when each marker seen moves as its nearest landmarks accepted in the
 * frame before (prev_ok) and in this one (verdict) do; r filled. */
static int check(const sh_landmarks *lm, const float *prev_xy, const uint8_t *prev_ok, const float *xy,
                 const uint8_t *verdict, const double *seen_ref, const double *seen_prev, const double *seen_xy,
                 int nseen, double max_px, sh_landmarks_carry_report *r)
{
    const int n = sh_landmarks_count(lm);
    const float *ref = sh_landmarks_reference(lm);
    int near[SH_LANDMARKS_CARRY_NEAR], ok = 1;
    double d2[SH_LANDMARKS_CARRY_NEAR], mx[SH_LANDMARKS_CARRY_NEAR], my[SH_LANDMARKS_CARRY_NEAR];
    r->support = SH_LANDMARKS_CARRY_NEAR;
    for (int k = 0; ok && k < nseen; k++) {
        const double *q = &seen_ref[2 * k];
        int m = nearest(ref, n, prev_ok, verdict, -1, q[0], q[1], SH_LANDMARKS_CARRY_NEAR, near, d2);
        if (m < r->support) r->support = m, r->thin = k;
        if (m < SH_LANDMARKS_CARRY_SUPPORT) return 0;
        for (int j = 0; j < m; j++) {
            mx[j] = (double)xy[2 * near[j]] - prev_xy[2 * near[j]];
            my[j] = (double)xy[2 * near[j] + 1] - prev_xy[2 * near[j] + 1];
        }
        double ex = median(mx, m) - (seen_xy[2 * k] - seen_prev[2 * k]);
        double ey = median(my, m) - (seen_xy[2 * k + 1] - seen_prev[2 * k + 1]);
        double e = hypot(ex, ey);
        if (!(e <= r->worst_px)) r->worst_px = e, r->worst = k; /* a NaN wins */
        ok = e <= max_px;
    }
    return ok;
}

sh_status sh_landmarks_carry(sh_landmarks *lm, const sh_plane *luma, const float *prev_xy, const uint8_t *prev_ok,
                             const double *seen_ref, const double *seen_prev, const double *seen_xy, int nseen,
                             double max_px, float *predicted, float *xy, uint8_t *verdict,
                             sh_landmarks_counts *counts, sh_landmarks_carry_report *r)
{
    sh_landmarks_carry_report rep = {.searched = 0, .carried = 0, .support = 0, .thin = -1, .worst_px = 0, .worst = -1};
    if (r) *r = rep;
    if (!lm || !luma || !prev_xy || !prev_ok || !predicted || !xy || !verdict || nseen < 0 ||
        (nseen > 0 && (!seen_ref || !seen_prev || !seen_xy)) || !(max_px > 0) || xy == prev_xy ||
        predicted == prev_xy || predicted == xy)
        return sh_error_set(SH_EINVAL, "landmarks carry: bad arguments");
    if (nseen < SH_LANDMARKS_CARRY_SEEN) return SH_OK; /* nothing to vouch for the landmarks */
    double shift[2] = {0, 0};
    for (int k = 0; k < nseen; k++) {
        shift[0] += (seen_xy[2 * k] - seen_prev[2 * k]) / nseen;
        shift[1] += (seen_xy[2 * k + 1] - seen_prev[2 * k + 1]) / nseen;
    }
    if (predict(lm, prev_xy, prev_ok, shift, predicted)) {
        sh_status st = sh_landmarks_track(lm, luma, predicted, xy, verdict, counts);
        if (st != SH_OK) return st;
        rep.searched = 1;
        rep.carried = check(lm, prev_xy, prev_ok, xy, verdict, seen_ref, seen_prev, seen_xy, nseen, max_px, &rep);
    }
    if (r) *r = rep;
    return SH_OK;
}
