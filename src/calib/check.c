/* Calibrations checked for physical sense at load (calib.h, sh_calib_check). Each bound is one
 * no real rig of ours comes near and every unit slip or copied block crosses: see docs/3d.md,
 * "Calibration files", for the bounds and the margins our phantom's rigs keep. */
#include "stillheart/calib.h"

#include <math.h>
#include <stdio.h>

#define PI 3.14159265358979323846
#define DIST_SAMPLES 64

void sh_calib_limits_default(sh_calib_limits *l)
{
    l->fov_min_deg = 1;
    l->fov_max_deg = 170;
    l->rig_scale = 10000;
    l->rotation_tol = 1e-5;
    l->same_pose = 1e-4;
    l->dist_factor_min = 0.2;
    l->dist_factor_max = 5;
}

static double fov_deg(double size, double f) { return 2 * atan(size / (2 * f)) * 180 / PI; }

/* Largest |(R R^T - I)_ij| and |det R - 1|. */
static double rotation_error(const double *R)
{
    double e = 0;
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) {
            double d = R[3 * i] * R[3 * j] + R[3 * i + 1] * R[3 * j + 1] + R[3 * i + 2] * R[3 * j + 2] - (i == j);
            e = fmax(e, fabs(d));
        }
    double det = R[0] * (R[4] * R[8] - R[5] * R[7]) - R[1] * (R[3] * R[8] - R[5] * R[6]) +
                 R[2] * (R[3] * R[7] - R[4] * R[6]);
    return fmax(e, fabs(det - 1)); /* NaN: callers compare with !(e <= tol) */
}

/* OpenCV's radial factor (1 + k1 r^2 + k2 r^4 + k3 r^6) / (1 + k4 r^2 + k5 r^4 + k6 r^6). */
static double radial(const sh_calib_camera *k, double r)
{
    double r2 = r * r, r4 = r2 * r2, r6 = r4 * r2;
    const double *d = k->dist;
    double num = 1 + d[0] * r2 + d[1] * r4 + (k->num_dist >= 5 ? d[4] * r6 : 0);
    double den = k->num_dist >= 8 ? 1 + d[5] * r2 + d[6] * r4 + d[7] * r6 : 1;
    return num / den;
}

/* The radial distortion out to the image's farthest corner (normalized radius from the pixel
 * corners: the distortion moves them by the factor, which the bounds keep moderate): its factor
 * range and the smallest slope of r f(r) over DIST_SAMPLES steps. */
static void distortion_range(const sh_calib *c, const sh_calib_camera *k, double *lo, double *hi,
                             double *slope)
{
    double rmax = 0;
    for (int i = 0; i < 4; i++) {
        double x = ((i & 1) ? c->width - 0.5 : -0.5) - k->K[2], y = ((i & 2) ? c->height - 0.5 : -0.5) - k->K[5];
        double xn = x / k->K[0], yn = y / k->K[4];
        rmax = fmax(rmax, sqrt(xn * xn + yn * yn));
    }
    *lo = *hi = 1;
    *slope = INFINITY;
    double prev = 0;
    for (int i = 1; i <= DIST_SAMPLES; i++) {
        double r = rmax * i / DIST_SAMPLES, f = radial(k, r);
        *lo = fmin(*lo, f);
        *hi = fmax(*hi, f);
        if (!isfinite(f)) *lo = -INFINITY;
        double step = (r * f - prev) / (rmax / DIST_SAMPLES);
        *slope = rmax > 0 ? fmin(*slope, step) : *slope;
        prev = r * f;
    }
}

/* One camera's own fields; the margins take its extremes. */
static sh_status check_camera(const sh_calib *c, int i, const char *name, const sh_calib_limits *l,
                              sh_calib_margins *m)
{
    const sh_calib_camera *k = &c->cam[i];
    const double *K = k->K;
    for (int j = 0; j < 9; j++)
        if (!isfinite(K[j]) || !isfinite(k->R[j]))
            return sh_error_set(SH_EFORMAT, "%s: camera %d: %s_%d holds a value that is not finite", name, i,
                                isfinite(K[j]) ? "R" : "K", i);
    if (fabs(K[3]) > 1e-9 || fabs(K[6]) > 1e-9 || fabs(K[7]) > 1e-9 || fabs(K[8] - 1) > 1e-9)
        return sh_error_set(SH_EFORMAT, "%s: camera %d: K_%d is not a camera matrix (0 below the diagonal, "
                            "last row 0 0 1)", name, i, i);
    for (int a = 0; a < 2; a++) {
        double f = K[4 * a], size = a ? c->height : c->width, fov = f > 0 ? fov_deg(size, f) : NAN;
        if (!(fov >= l->fov_min_deg && fov <= l->fov_max_deg))
            return sh_error_set(SH_EFORMAT, "%s: camera %d: K_%d: %s = %g gives a field of view of %.3g degrees "
                                "over %g pixels (allowed %g to %g)", name, i, i, a ? "fy" : "fx", f, fov, size,
                                l->fov_min_deg, l->fov_max_deg);
        m->fov_deg[0] = fmin(m->fov_deg[0], fov);
        m->fov_deg[1] = fmax(m->fov_deg[1], fov);
        double p = K[2 + 3 * a], edge = fmin(p + 0.5, size - 0.5 - p);
        if (!(edge >= 0))
            return sh_error_set(SH_EFORMAT, "%s: camera %d: K_%d: the principal point %s = %g lies outside the "
                                "image (-0.5 to %g)", name, i, i, a ? "cy" : "cx", p, size - 0.5);
        m->pp_edge_px = fmin(m->pp_edge_px, edge);
    }
    for (int j = 0; j < k->num_dist; j++)
        if (!isfinite(k->dist[j]))
            return sh_error_set(SH_EFORMAT, "%s: camera %d: dist_%d[%d] is not finite", name, i, i, j);
    if (k->num_dist >= 4 && !(fabs(k->dist[2]) <= 0.5 && fabs(k->dist[3]) <= 0.5))
        return sh_error_set(SH_EFORMAT, "%s: camera %d: dist_%d: tangential terms p1 = %g, p2 = %g (at most 0.5)",
                            name, i, i, k->dist[2], k->dist[3]);
    double lo, hi, slope;
    distortion_range(c, k, &lo, &hi, &slope);
    if (!(lo >= l->dist_factor_min && hi <= l->dist_factor_max))
        return sh_error_set(SH_EFORMAT, "%s: camera %d: dist_%d: the radial factor runs from %.3g to %.3g over the "
                            "image (allowed %g to %g)", name, i, i, lo, hi, l->dist_factor_min,
                            l->dist_factor_max);
    if (!(slope > 0))
        return sh_error_set(SH_EFORMAT, "%s: camera %d: dist_%d folds the image (the distorted radius stops rising "
                            "before the corners)", name, i, i);
    m->dist_factor[0] = fmin(m->dist_factor[0], lo);
    m->dist_factor[1] = fmax(m->dist_factor[1], hi);
    m->dist_slope = fmin(m->dist_slope, slope);
    double re = rotation_error(k->R);
    if (!(re <= l->rotation_tol))
        return sh_error_set(SH_EFORMAT, "%s: camera %d: R_%d is not a rotation (off by %.3g, allowed %g)", name, i,
                            i, re, l->rotation_tol);
    m->rotation_err = fmax(m->rotation_err, re);
    double tn = hypot(hypot(k->t[0], k->t[1]), k->t[2]); /* 1e300 stays 1e300 */
    if (!(tn <= l->rig_scale))
        return sh_error_set(SH_EFORMAT, "%s: camera %d: t_%d: |t| = %g, beyond the rig scale %g", name, i, i, tn,
                            l->rig_scale);
    m->t_max = fmax(m->t_max, tn);
    return SH_OK;
}

sh_status sh_calib_check(const sh_calib *c, const char *name, const sh_calib_limits *limits, sh_calib_margins *margins)
{
    sh_calib_limits def;
    if (!limits) {
        sh_calib_limits_default(&def);
        limits = &def;
    }
    if (!name) name = "calibration";
    sh_calib_margins m = {{INFINITY, -INFINITY}, INFINITY, 0, 0, INFINITY, {INFINITY, -INFINITY}, INFINITY};
    if (!c || c->num_cameras < 1 || c->num_cameras > SH_CALIB_MAX_CAMERAS || c->width < 1 || c->height < 1)
        return sh_error_set(SH_EFORMAT, "%s: no cameras or no image size", name);
    double C[SH_CALIB_MAX_CAMERAS][3];
    for (int i = 0; i < c->num_cameras; i++) {
        sh_status st = check_camera(c, i, name, limits, &m);
        if (st != SH_OK) return st;
        const double *R = c->cam[i].R, *t = c->cam[i].t;
        for (int a = 0; a < 3; a++) C[i][a] = -(R[a] * t[0] + R[3 + a] * t[1] + R[6 + a] * t[2]); /* -R^T t */
        for (int j = 0; j < i; j++) {
            double d = 0, ni = 0, nj = 0;
            for (int a = 0; a < 3; a++) {
                d += (C[i][a] - C[j][a]) * (C[i][a] - C[j][a]);
                ni += C[i][a] * C[i][a];
                nj += C[j][a] * C[j][a];
            }
            double far = sqrt(fmax(ni, nj)), sep = far > 0 ? sqrt(d) / far : sqrt(d) > 0 ? INFINITY : 0;
            if (!(sep > limits->same_pose))
                return sh_error_set(SH_EFORMAT, "%s: camera %d: R_%d, t_%d: at the pose of camera %d (centres %g apart, "
                                    "%.3g of their distance from the origin; at least %g)", name, i, i, i, j,
                                    sqrt(d), sep, limits->same_pose);
            m.separation = fmin(m.separation, sep);
        }
    }
    if (margins) *margins = m;
    return SH_OK;
}
