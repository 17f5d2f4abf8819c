/* The reference surface and the displacement model (paper IV-B, IV-C). */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "stillheart/linalg.h"
#include "warp3d_internal.h"

void sh_warp3d_params_default(sh_warp3d_params *p)
{
    if (!p) return;
    sh_interp_params_default(&p->surface, SH_METHOD_BSPLINE);
    sh_interp_params_default(&p->displacement, SH_METHOD_BSPLINE);
    p->surface_trend = 3;
}

/* Eigen-decomposition of a symmetric 3x3 matrix by Jacobi rotations: a is destroyed, its
 * diagonal ends as the eigenvalues, the columns of v the eigenvectors. */
static void jacobi3(double a[9], double v[9])
{
    for (int i = 0; i < 9; i++) v[i] = i % 4 == 0;
    for (int sweep = 0; sweep < 50; sweep++) {
        double off = fabs(a[1]) + fabs(a[2]) + fabs(a[5]);
        if (off < 1e-300) return;
        for (int p = 0; p < 2; p++) {
            for (int q = p + 1; q < 3; q++) {
                double apq = a[3 * p + q];
                if (fabs(apq) < 1e-300) continue;
                double theta = (a[3 * q + q] - a[3 * p + p]) / (2 * apq);
                double t = (theta >= 0 ? 1 : -1) / (fabs(theta) + sqrt(theta * theta + 1));
                double c = 1 / sqrt(t * t + 1), s = t * c;
                for (int k = 0; k < 3; k++) { /* a = J^T a J */
                    double akp = a[3 * k + p], akq = a[3 * k + q];
                    a[3 * k + p] = c * akp - s * akq;
                    a[3 * k + q] = s * akp + c * akq;
                }
                for (int k = 0; k < 3; k++) {
                    double apk = a[3 * p + k], aqk = a[3 * q + k];
                    a[3 * p + k] = c * apk - s * aqk;
                    a[3 * q + k] = s * apk + c * aqk;
                }
                for (int k = 0; k < 3; k++) {
                    double vkp = v[3 * k + p], vkq = v[3 * k + q];
                    v[3 * k + p] = c * vkp - s * vkq;
                    v[3 * k + q] = s * vkp + c * vkq;
                }
            }
        }
    }
}

static void s_basis(const sh_warp3d_model *m, double u, double v, double *q)
{
    double a = u / m->scale, b = v / m->scale;
    q[0] = 1;
    q[1] = a;
    q[2] = b;
    q[3] = a * a;
    q[4] = a * b;
    q[5] = b * b;
    q[6] = a * a * a;
    q[7] = a * a * b;
    q[8] = a * b * b;
    q[9] = b * b * b;
}

double sh_warp3d_model_height(const sh_warp3d_model *m, double u, double v)
{
    double q[W3_MAX_TREND], s = 0, r = 0;
    s_basis(m, u, v, q);
    for (int k = 0; k < m->s_terms; k++) s += m->s_trend[k] * q[k];
    /* piecewise linear: no residual outside the hull (SH_ERANGE leaves r = 0) */
    sh_interp_eval(m->s_interp, m->s_coef, 1, u, v, &r);
    return s + r;
}

void w3_h_basis(const sh_warp3d_model *m, double u, double v, double *b)
{
    b[0] = 1;
    b[1] = u / m->scale;
    b[2] = v / m->scale;
    if (m->h_terms > 3) b[3] = sh_warp3d_model_height(m, u, v) / m->scale;
}

void w3_surface_point(const sh_warp3d_model *m, double u, double v, double depth_scale, double X[3])
{
    double z = depth_scale * sh_warp3d_model_height(m, u, v);
    for (int i = 0; i < 3; i++)
        X[i] = m->origin[i] + u * m->axes[i] + v * m->axes[3 + i] + z * m->axes[6 + i];
}

void sh_warp3d_model_point(const sh_warp3d_model *m, double u, double v, double depth_scale,
                           int current, double X[3])
{
    w3_surface_point(m, u, v, depth_scale, X);
    if (!current) return;
    double b[W3_H_TREND], r[3] = {0, 0, 0};
    w3_h_basis(m, u, v, b);
    sh_interp_eval(m->h_interp, m->h_coef, 3, u, v, r);
    for (int c = 0; c < 3; c++) {
        double h = r[c];
        for (int k = 0; k < m->h_terms; k++) h += b[k] * m->h_trend[3 * k + c];
        X[c] += h;
    }
}

void sh_warp3d_model_destroy(sh_warp3d_model *m)
{
    if (!m) return;
    free(m->ref);
    free(m->uv);
    free(m->height);
    sh_interp_destroy(m->s_interp);
    free(m->s_coef);
    free(m->h_pinv);
    free(m->h_basis);
    sh_interp_destroy(m->h_interp);
    free(m->subset_work);
    free(m->h_coef);
    free(m->disp);
    free(m->resid);
    free(m);
}

int sh_warp3d_model_num_points(const sh_warp3d_model *m)
{
    return m->n;
}

void sh_warp3d_model_frame(const sh_warp3d_model *m, double origin[3], double axes[9])
{
    memcpy(origin, m->origin, sizeof m->origin);
    memcpy(axes, m->axes, sizeof m->axes);
}

const sh_hull *sh_warp3d_model_uv_hull(const sh_warp3d_model *m)
{
    return &m->uv_hull;
}

/* The centroid and covariance of n world points (xyz: 3n). */
static void centre_cov(const double *xyz, int n, double c[3], double cov[9])
{
    memset(c, 0, 3 * sizeof *c);
    memset(cov, 0, 9 * sizeof *cov);
    for (int i = 0; i < n; i++)
        for (int k = 0; k < 3; k++) c[k] += xyz[3 * i + k] / n;
    for (int i = 0; i < n; i++) {
        double d[3] = {xyz[3 * i] - c[0], xyz[3 * i + 1] - c[1], xyz[3 * i + 2] - c[2]};
        for (int r = 0; r < 3; r++)
            for (int k = 0; k < 3; k++) cov[3 * r + k] += d[r] * d[k] / n;
    }
}

/* The PCA frame: origin at the centroid, e1 along the largest spread, normal along the
 * smallest (pointing to world +Z, the phantom's up), e2 = normal x e1. */
static sh_status fit_frame(sh_warp3d_model *m)
{
    const int n = m->n;
    double c[3], cov[9];
    centre_cov(m->ref, n, c, cov);
    double vec[9];
    jacobi3(cov, vec);
    int order[3] = {0, 1, 2};
    for (int a = 0; a < 3; a++)
        for (int b = a + 1; b < 3; b++)
            if (cov[4 * order[b]] > cov[4 * order[a]]) {
                int t = order[a];
                order[a] = order[b];
                order[b] = t;
            }
    double l0 = cov[4 * order[0]], l1 = cov[4 * order[1]];
    if (!(l0 > 0) || !(l1 > 1e-6 * l0))
        return sh_error_set(SH_EDEGENERATE, "warp3d: the %d reference markers lie on a line", n);
    double e1[3], nrm[3];
    for (int k = 0; k < 3; k++) {
        e1[k] = vec[3 * k + order[0]];
        nrm[k] = vec[3 * k + order[2]];
    }
    if (nrm[2] < 0 || (nrm[2] == 0 && nrm[1] < 0))
        for (int k = 0; k < 3; k++) nrm[k] = -nrm[k];
    double e2[3] = {nrm[1] * e1[2] - nrm[2] * e1[1], nrm[2] * e1[0] - nrm[0] * e1[2],
                    nrm[0] * e1[1] - nrm[1] * e1[0]};
    memcpy(m->origin, c, sizeof c);
    memcpy(m->axes, e1, sizeof e1);
    memcpy(m->axes + 3, e2, sizeof e2);
    memcpy(m->axes + 6, nrm, sizeof nrm);
    m->scale = sqrt(l0 + l1);
    return SH_OK;
}

/* The areas the points span, in cam's image and in their own plane (the two largest principal
 * spreads), as covariance determinants: their ratio is s^4 for a plane the camera sees scaled by s
 * px/mm, and the product of the two scales for one it foreshortens. */
sh_status sh_warp3d_pixels_per_mm(const sh_calib_camera *cam, const double *xyz, int n, double *out)
{
    if (!cam || !xyz || !out || n < 3) return sh_error_set(SH_EINVAL, "warp3d: the pixel scale needs 3 points or more");
    double *in = malloc(sizeof(double) * 3 * (size_t)n);
    if (!in) return sh_error_set(SH_ENOMEM, "warp3d: out of memory");
    double px[2] = {0, 0}, pp[3] = {0, 0, 0};
    int k = 0;
    for (int i = 0; i < n; i++) {
        double x, y;
        if (!sh_warp3d_project(cam, xyz + 3 * i, &x, &y) || !isfinite(x) || !isfinite(y)) continue;
        memcpy(in + 3 * k, xyz + 3 * i, 3 * sizeof(double));
        px[0] += x, px[1] += y;
        pp[0] += x * x, pp[1] += x * y, pp[2] += y * y;
        k++;
    }
    double c[3], cov[9], vec[9];
    if (k >= 3) centre_cov(in, k, c, cov);
    free(in);
    if (k < 3) return sh_error_set(SH_EDEGENERATE, "warp3d: %d of %d points in front of the camera", k, n);
    jacobi3(cov, vec);
    double a = cov[0], b = cov[4], d = cov[8]; /* the eigenvalues; the plane's two are the largest */
    double plane = a <= b && a <= d ? b * d : b <= d ? a * d : a * b;
    double mx = px[0] / k, my = px[1] / k;
    double det = (pp[0] / k - mx * mx) * (pp[2] / k - my * my) - (pp[1] / k - mx * my) * (pp[1] / k - mx * my);
    if (!(plane > 0) || !(det > 0))
        return sh_error_set(SH_EDEGENERATE, "warp3d: the points lie on a line (no pixel scale)");
    *out = pow(det / plane, 0.25);
    return SH_OK;
}

/* Least-squares trend: coef (terms) of values over the basis rows a (n x terms). */
static sh_status trend_pinv(const double *a, int n, int terms, double *pinv, double *rcond)
{
    return sh_linalg_pinv(n, terms, a, pinv, rcond);
}

/* A B-spline's automatic levels are the ones the points with no smoothing of their own (the
 * markers) need: the less certain ones closer together than that lattice resolves are
 * approximated, not allowed to set it. Landmarks chosen 14 px apart lie about 1 mm apart on the
 * phantom's surface, and exact interpolation through such a pair needs a lattice of over a
 * million control points there (over the markers' box and its margin); in 2D the same levels
 * brought the map 1 % closer to the truth (docs/landmarks.md, "Weights"). The levels into
 * *levels (untouched when the markers are too few for a B-spline of their own). */
static sh_status markers_levels(const sh_interp_params *params, const double *uv, int n, const double *lambda,
                                int *levels)
{
    double *xy = malloc(sizeof(double) * 2 * (size_t)n);
    if (!xy) return sh_error_set(SH_ENOMEM, "warp3d: out of memory");
    int k = 0;
    for (int i = 0; i < n; i++)
        if (!(lambda[i] > 0)) xy[2 * k] = uv[2 * i], xy[2 * k + 1] = uv[2 * i + 1], k++;
    sh_interp *it = NULL;
    if (k < n && k >= 3 && sh_interp_create(params, xy, k, &it) == SH_OK) *levels = sh_interp_bspline_levels(it);
    sh_interp_destroy(it);
    free(xy);
    return SH_OK;
}

/* An interpolant over the points' (u, v); lambda (may be NULL): each point's own smoothing, taken by
 * the RBFs; a B-spline's levels set by the points without one; the other methods interpolate
 * every point. */
static sh_status create_interp(const sh_interp_params *params, const double *uv, int n, const double *lambda,
                               sh_interp **out)
{
    if (lambda && sh_interp_method_smooths(params->method))
        return sh_interp_create_smoothed(params, uv, n, lambda, out);
    if (lambda && params->method == SH_METHOD_BSPLINE && params->levels == 0) {
        sh_interp_params p = *params;
        sh_status st = markers_levels(params, uv, n, lambda, &p.levels);
        return st == SH_OK ? sh_interp_create(&p, uv, n, out) : st;
    }
    return sh_interp_create(params, uv, n, out);
}

/* The surface: a trend of the markers' heights over (u, v) by least squares (the degree asked,
 * lowered while the markers make it ill-conditioned), the residual interpolated. a, pinv: room
 * for W3_MAX_TREND x n. */
static sh_status fit_surface(sh_warp3d_model *m, const sh_warp3d_params *params, const double *lambda, double *a,
                             double *pinv)
{
    sh_status st;
    int n = m->n;
    double rcond = 0;
    static const int terms_of_degree[4] = {0, 3, 6, 10};
    int degree = params->surface_trend;
    while (degree > 1 && n < terms_of_degree[degree] + 2) degree--;
    m->s_terms = terms_of_degree[degree];
    for (;;) {
        for (int i = 0; i < n; i++) {
            double q[W3_MAX_TREND];
            s_basis(m, m->uv[2 * i], m->uv[2 * i + 1], q);
            memcpy(a + (size_t)i * m->s_terms, q, sizeof(double) * (size_t)m->s_terms);
        }
        if ((st = trend_pinv(a, n, m->s_terms, pinv, &rcond)) != SH_OK) return st;
        if (rcond > 1e-8 || m->s_terms == 3) break;
        m->s_terms = terms_of_degree[--degree]; /* markers on a conic or cubic: a lower degree */
    }
    if (!(rcond > 1e-10))
        return sh_error_set(SH_EDEGENERATE, "warp3d: reference markers too close to a line");
    for (int k = 0; k < m->s_terms; k++) {
        double s = 0;
        for (int i = 0; i < n; i++) s += pinv[(size_t)k * n + i] * m->height[i];
        m->s_trend[k] = s;
    }
    if ((st = create_interp(&params->surface, m->uv, n, lambda, &m->s_interp)) != SH_OK) return st;
    m->s_coef = calloc((size_t)sh_interp_num_coefs(m->s_interp), sizeof(double));
    if (!m->s_coef) return sh_error_set(SH_ENOMEM, "warp3d: out of memory");
    for (int i = 0; i < n; i++) {
        double q[W3_MAX_TREND], s = 0;
        s_basis(m, m->uv[2 * i], m->uv[2 * i + 1], q);
        for (int k = 0; k < m->s_terms; k++) s += m->s_trend[k] * q[k];
        m->resid[i] = m->height[i] - s;
    }
    return sh_interp_fit(m->s_interp, m->resid, 1, m->s_coef);
}

/* The displacement's trend: 1, u, v, s (an affine map of 3D space restricted to the surface);
 * markers on a plane make s constant: then 1, u, v. Then its interpolant. */
static sh_status fit_displacement(sh_warp3d_model *m, const sh_warp3d_params *params, const double *lambda)
{
    sh_status st;
    double rcond = 0;
    int n = m->n;
    m->h_terms = 4;
    for (;;) {
        for (int i = 0; i < n; i++) w3_h_basis(m, m->uv[2 * i], m->uv[2 * i + 1], m->h_basis + (size_t)i * m->h_terms);
        if ((st = trend_pinv(m->h_basis, n, m->h_terms, m->h_pinv, &rcond)) != SH_OK) return st;
        if (rcond > 1e-6 || m->h_terms == 3) break;
        m->h_terms = 3;
    }
    if ((st = create_interp(&params->displacement, m->uv, n, lambda, &m->h_interp)) != SH_OK) return st;
    m->h_coef = calloc(3 * (size_t)sh_interp_num_coefs(m->h_interp), sizeof(double));
    if (!m->h_coef) return sh_error_set(SH_ENOMEM, "warp3d: out of memory");
    return SH_OK;
}

sh_status sh_warp3d_model_create(const sh_warp3d_params *params, const double *ref_xyz, int n,
                                 sh_warp3d_model **out)
{
    return sh_warp3d_model_create_smoothed(params, ref_xyz, n, NULL, out);
}

sh_status sh_warp3d_model_create_smoothed(const sh_warp3d_params *params, const double *ref_xyz, int n,
                                          const double *point_smoothing, sh_warp3d_model **out)
{
    if (!ref_xyz || !out || n < 4)
        return sh_error_set(SH_EINVAL, "warp3d: need at least 4 reference markers, got %d", n);
    for (int i = 0; i < 3 * n; i++)
        if (!isfinite(ref_xyz[i]))
            return sh_error_set(SH_EINVAL, "warp3d: reference marker %d is not finite", i / 3);
    for (int i = 0; point_smoothing && i < n; i++)
        if (!(point_smoothing[i] >= 0) || !isfinite(point_smoothing[i]))
            return sh_error_set(SH_EINVAL, "warp3d: point %d's smoothing %g is not a finite value >= 0", i,
                                point_smoothing[i]);
    sh_warp3d_params def;
    if (!params) {
        sh_warp3d_params_default(&def);
        params = &def;
    }
    if (params->surface_trend < 1 || params->surface_trend > 3)
        return sh_error_set(SH_EINVAL, "warp3d: surface trend must be 1 (plane), 2 (quadric) or 3 (cubic)");
    sh_warp3d_model *m = calloc(1, sizeof *m);
    if (!m) return sh_error_set(SH_ENOMEM, "warp3d: out of memory");
    m->n = n;
    sh_status st = SH_OK;
    m->ref = malloc(sizeof(double) * 3 * (size_t)n);
    m->uv = malloc(sizeof(double) * 2 * (size_t)n);
    m->height = malloc(sizeof(double) * (size_t)n);
    m->h_pinv = malloc(sizeof(double) * W3_H_TREND * (size_t)n);
    m->h_basis = malloc(sizeof(double) * W3_H_TREND * (size_t)n);
    m->disp = malloc(sizeof(double) * 3 * (size_t)n);
    m->resid = malloc(sizeof(double) * 3 * (size_t)n);
    double *a = malloc(sizeof(double) * W3_MAX_TREND * (size_t)n);
    double *pinv = malloc(sizeof(double) * W3_MAX_TREND * (size_t)n);
    if (!m->ref || !m->uv || !m->height || !m->h_pinv || !m->h_basis || !m->disp || !m->resid ||
        !a || !pinv) {
        st = sh_error_set(SH_ENOMEM, "warp3d: out of memory");
        goto done;
    }
    memcpy(m->ref, ref_xyz, sizeof(double) * 3 * (size_t)n);
    if ((st = fit_frame(m)) != SH_OK) goto done;
    for (int i = 0; i < n; i++) {
        double d[3];
        for (int k = 0; k < 3; k++) d[k] = m->ref[3 * i + k] - m->origin[k];
        m->uv[2 * i] = d[0] * m->axes[0] + d[1] * m->axes[1] + d[2] * m->axes[2];
        m->uv[2 * i + 1] = d[0] * m->axes[3] + d[1] * m->axes[4] + d[2] * m->axes[5];
        m->height[i] = d[0] * m->axes[6] + d[1] * m->axes[7] + d[2] * m->axes[8];
    }
    if ((st = sh_hull_compute(m->uv, n, &m->uv_hull)) != SH_OK) goto done;

    if ((st = fit_surface(m, params, point_smoothing, a, pinv)) != SH_OK) goto done;
    if ((st = fit_displacement(m, params, point_smoothing)) != SH_OK) goto done;
    st = sh_warp3d_model_update(m, ref_xyz); /* h = 0 until the first frame */
done:
    free(a);
    free(pinv);
    if (st != SH_OK) {
        sh_warp3d_model_destroy(m);
        return st;
    }
    *out = m;
    return SH_OK;
}

sh_status sh_warp3d_model_update(sh_warp3d_model *m, const double *cur)
{
    if (!m || !cur) return sh_error_set(SH_EINVAL, "warp3d: no positions");
    const int n = m->n, t = m->h_terms;
    for (int i = 0; i < 3 * n; i++) {
        if (!isfinite(cur[i]))
            return sh_error_set(SH_EINVAL, "warp3d: current position of marker %d is not finite", i / 3);
        m->disp[i] = cur[i] - m->ref[i];
    }
    for (int k = 0; k < t; k++)
        for (int c = 0; c < 3; c++) {
            double s = 0;
            for (int i = 0; i < n; i++) s += m->h_pinv[(size_t)k * n + i] * m->disp[3 * i + c];
            m->h_trend[3 * k + c] = s;
        }
    for (int i = 0; i < n; i++)
        for (int c = 0; c < 3; c++) {
            double s = m->disp[3 * i + c];
            for (int k = 0; k < t; k++) s -= m->h_basis[(size_t)i * t + k] * m->h_trend[3 * k + c];
            m->resid[3 * i + c] = s;
        }
    return sh_interp_fit(m->h_interp, m->resid, 3, m->h_coef);
}

/* The trend over the used points by its normal equations (t <= 4 unknowns: on the stack), then the
 * residual's interpolant through them. */
sh_status sh_warp3d_model_update_subset(sh_warp3d_model *m, const double *cur, const unsigned char *use)
{
    if (!use) return sh_warp3d_model_update(m, cur);
    if (!m || !cur) return sh_error_set(SH_EINVAL, "warp3d: no positions");
    const int n = m->n, t = m->h_terms;
    int s = 0;
    for (int i = 0; i < n; i++) {
        if (!use[i]) continue;
        s++;
        for (int c = 0; c < 3; c++) {
            if (!isfinite(cur[3 * i + c]))
                return sh_error_set(SH_EINVAL, "warp3d: current position of point %d is not finite", i);
            m->disp[3 * i + c] = cur[3 * i + c] - m->ref[3 * i + c];
        }
    }
    if (s < t) return sh_error_set(SH_EDEGENERATE, "warp3d: %d points used, the displacement's trend has %d terms", s, t);
    if (!m->subset_work && !(m->subset_work = malloc(sh_interp_subset_work_size(m->h_interp) + 1)))
        return sh_error_set(SH_ENOMEM, "warp3d: out of memory");
    double ata[W3_H_TREND * W3_H_TREND] = {0}, atd[W3_H_TREND * 3] = {0};
    int src[W3_H_TREND];
    for (int i = 0; i < n; i++) {
        if (!use[i]) continue;
        const double *b = m->h_basis + (size_t)i * t;
        for (int k = 0; k < t; k++) {
            for (int l = 0; l < t; l++) ata[k * t + l] += b[k] * b[l];
            for (int c = 0; c < 3; c++) atd[k * 3 + c] += b[k] * m->disp[3 * i + c];
        }
    }
    if (sh_linalg_lu_factor_inplace(t, ata, src) != SH_OK)
        return sh_error_set(SH_EDEGENERATE, "warp3d: the %d points used do not determine the displacement's trend", s);
    sh_linalg_lu_solve(t, ata, src, atd, t, 3, m->h_trend);
    for (int i = 0; i < n; i++) {
        if (!use[i]) continue;
        for (int c = 0; c < 3; c++) {
            double r = m->disp[3 * i + c];
            for (int k = 0; k < t; k++) r -= m->h_basis[(size_t)i * t + k] * m->h_trend[3 * k + c];
            m->resid[3 * i + c] = r;
        }
    }
    return sh_interp_fit_subset(m->h_interp, use, m->resid, 3, m->h_coef, m->subset_work);
}
