/* The shape test of a detection (docs/tracking.md, "Partial occlusions"): is the quad a tag seen
 * whole, or one that an occluder cut or extended?
 *
 * A partly hidden tag that still decodes has its quad fitted to the border libapriltag could see:
 * the hidden corners, or a whole side, land off, and the centre (the homography's image of the tag
 * centre, i.e. the crossing of the quad's diagonals) moves with them. The centre's motion alone
 * cannot tell this from the heart moving while the filter is unsure of its prediction, which is
 * exactly when a marker hidden for seconds is. The quad's shape can, independently of the motion
 * model:
 *
 *  1. the centre must be the crossing of the diagonals (a planar square seen through any pinhole
 *     camera: the homography fixes it);
 *  2. the quad must be an affine image of a square up to its perspective part: the 2 degrees of
 *     freedom an affine fit of 4 points leaves. That part is about e (e / Z) sin(tilt) for a tag of
 *     half-size e at depth Z, below 0.006 e on the phantoms; TRK_PERSP_MAX bounds it at 0.01 e
 *     (e / Z = 1/50 at any tilt). One corner off by s shows as s/2 there;
 *  3. against the marker's last accepted quad, the affine map between them must stretch across a
 *     side or change the size by less than the heart can in the time between them: a side moved
 *     by s keeps the quad a parallelogram but stretches it by s / side. TRK_STRETCH_RATE bounds
 *     the change per second (the phantoms reach 0.85 /s, a tag turning or approaching quickly).
 *
 * Each bound is added to the detector's noise at the motion gate's chi-square (meas_sigma per
 * coordinate); a quad refused here is counted in stats.misshapen. */
#include <math.h>
#include <string.h>

#include "track_internal.h"

#define TRK_PERSP_MAX 0.01    /* largest perspective part of a square, over its half-size */
#define TRK_STRETCH_RATE 1.5  /* relative stretch or change of size per second of age */

/* the unit square in libapriltag's corner order (any cyclic order would do: the fit is affine) */
static const double square[4][2] = {{-1, 1}, {1, 1}, {1, -1}, {-1, -1}};

/* Least-squares affine fit of centred offsets q_k = A p_k: A and the sum of squared residuals. */
static double affine_fit(const double p[4][2], const double q[4][2], double A[4])
{
    double pp[4] = {0}, qp[4] = {0};
    for (int k = 0; k < 4; k++) {
        pp[0] += p[k][0] * p[k][0];
        pp[1] += p[k][0] * p[k][1];
        pp[3] += p[k][1] * p[k][1];
        qp[0] += q[k][0] * p[k][0];
        qp[1] += q[k][0] * p[k][1];
        qp[2] += q[k][1] * p[k][0];
        qp[3] += q[k][1] * p[k][1];
    }
    pp[2] = pp[1];
    double det = pp[0] * pp[3] - pp[1] * pp[2];
    if (!(fabs(det) > 1e-12)) return INFINITY;
    double inv[4] = {pp[3] / det, -pp[1] / det, -pp[2] / det, pp[0] / det};
    A[0] = qp[0] * inv[0] + qp[1] * inv[2];
    A[1] = qp[0] * inv[1] + qp[1] * inv[3];
    A[2] = qp[2] * inv[0] + qp[3] * inv[2];
    A[3] = qp[2] * inv[1] + qp[3] * inv[3];
    double ss = 0;
    for (int k = 0; k < 4; k++) {
        double rx = q[k][0] - (A[0] * p[k][0] + A[1] * p[k][1]);
        double ry = q[k][1] - (A[2] * p[k][0] + A[3] * p[k][1]);
        ss += rx * rx + ry * ry;
    }
    return ss;
}

/* singular values of a 2x2 matrix */
static void singular2(const double A[4], double *s1, double *s2)
{
    double a = A[0] * A[0] + A[2] * A[2], b = A[0] * A[1] + A[2] * A[3], c = A[1] * A[1] + A[3] * A[3];
    double m = 0.5 * (a + c), d = sqrt(0.25 * (a - c) * (a - c) + b * b);
    *s1 = sqrt(m + d);
    *s2 = sqrt(fmax(0, m - d));
}

/* centred corners of a detection, and its half-size (RMS centre-to-corner distance) */
static double centred(const sh_detection *d, double q[4][2])
{
    double gx = 0, gy = 0;
    for (int k = 0; k < 4; k++) {
        gx += 0.25 * d->corner[k][0];
        gy += 0.25 * d->corner[k][1];
    }
    double e2 = 0;
    for (int k = 0; k < 4; k++) {
        q[k][0] = d->corner[k][0] - gx;
        q[k][1] = d->corner[k][1] - gy;
        e2 += 0.25 * (q[k][0] * q[k][0] + q[k][1] * q[k][1]);
    }
    return sqrt(e2);
}

/* Tests 2 and 3 of `q` (centred corners, half-size e) against reference `p`, `age` frames old,
 * or against the square when p is NULL. */
/* Test 3 of q (centred corners, half-size e) against reference p, `age` frames older. */
static int stretch_ok(const sh_tracker *t, const double p[4][2], int age, const double q[4][2], double e)
{
    double sig2 = t->o.meas_sigma * t->o.meas_sigma;
    double since = (age > 0 ? age : 1) / t->o.fps, fs = TRK_STRETCH_RATE * since;
    double A[4] = {1, 0, 0, 1};
    affine_fit(p, q, A);
    double s1, s2;
    singular2(A, &s1, &s2);
    /* stretch across a side and change of size, in pixels at the tag's size; both quads carry
     * the detector's noise */
    double stretch = (s1 - s2) * e, sc = fabs(sqrt(s1 * s2) - 1) * e;
    double lim = fmin(fs, 1.0) * e + sqrt(t->o.gate * 2 * sig2);
    return stretch <= lim && sc <= lim;
}

static int shape_ok(const sh_tracker *t, const marker *mk, int c, const double q[4][2], double e)
{
    double sig2 = t->o.meas_sigma * t->o.meas_sigma;
    /* 2: the perspective part, against the square (2 degrees of freedom) */
    double A[4] = {1, 0, 0, 1};
    double ss = affine_fit(square, q, A);
    if (!(sqrt(ss) <= TRK_PERSP_MAX * e + sqrt(t->o.gate * sig2))) return 0;
    /* 3: against the last accepted quad */
    return !mk->quad_ok[c] ||
           stretch_ok(t, (const double(*)[2])mk->quad[c], t->frame - mk->quad_frame[c], q, e);
}

int trk_quad_similar(const sh_tracker *t, const double ref[4][2], int age, const sh_detection *d)
{
    double q[4][2];
    double e = centred(d, q);
    return e > 0 && stretch_ok(t, ref, age, q, e);
}

void trk_quad_centred(const sh_detection *d, double q[4][2]) { centred(d, q); }

int trk_quad_check(sh_tracker *t, marker *mk, int c, const sh_detection *d)
{
    double q[4][2];
    double e = centred(d, q);
    if (!isfinite(e) || e <= 0) return 0;
    /* 1: centre at the diagonals' crossing p0 + s (p2 - p0) = p1 + u (p3 - p1) */
    double ax = d->corner[2][0] - d->corner[0][0], ay = d->corner[2][1] - d->corner[0][1];
    double bx = d->corner[3][0] - d->corner[1][0], by = d->corner[3][1] - d->corner[1][1];
    double cx = d->corner[1][0] - d->corner[0][0], cy = d->corner[1][1] - d->corner[0][1];
    double den = ax * by - ay * bx;
    if (!(fabs(den) > 1e-9)) return 0;
    double s = (cx * by - cy * bx) / den;
    double ex = d->cx - (d->corner[0][0] + s * ax), ey = d->cy - (d->corner[0][1] + s * ay);
    double sig2 = t->o.meas_sigma * t->o.meas_sigma;
    if (!((ex * ex + ey * ey) / (2 * sig2) <= t->o.gate)) return 0;
    return shape_ok(t, mk, c, q, e);
}

void trk_quad_learn(sh_tracker *t, marker *mk, int c, const sh_detection *d)
{
    double q[4][2];
    if (!(centred(d, q) > 0)) return;
    memcpy(mk->quad[c], q, sizeof q);
    mk->quad_frame[c] = t->frame;
    mk->quad_ok[c] = 1;
}
