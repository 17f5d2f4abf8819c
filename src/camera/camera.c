/* Camera geometry: OpenCV's distortion model, its inverse, and triangulation (DLT + Gauss-Newton).
 * Plain C, fixed size: runs per marker per frame. */
#include <math.h>
#include <string.h>

#include "stillheart/camera.h"

static int finite_all(const double *a, int n)
{
    for (int i = 0; i < n; i++)
        if (!isfinite(a[i])) return 0;
    return 1;
}

sh_status sh_camera_check(const sh_calib_camera *cam, int index)
{
    if (!cam) return sh_error_set(SH_EINVAL, "camera %d: missing", index);
    if (!finite_all(cam->K, 9) || !finite_all(cam->dist, SH_CALIB_MAX_DIST) ||
        !finite_all(cam->R, 9) || !finite_all(cam->t, 3))
        return sh_error_set(SH_EINVAL, "camera %d: non-finite calibration value", index);
    if (!(cam->K[0] > 0) || !(cam->K[4] > 0) || cam->K[3] != 0 || cam->K[6] != 0 ||
        cam->K[7] != 0 || cam->K[8] != 1)
        return sh_error_set(SH_EINVAL,
                            "camera %d: K must be [fx s cx; 0 fy cy; 0 0 1] with fx, fy > 0", index);
    if (cam->dist[12] != 0 || cam->dist[13] != 0)
        return sh_error_set(SH_EUNSUPPORTED, "camera %d: tilted-sensor distortion (tx, ty) is not "
                                             "supported", index);
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) {
            double d = 0;
            for (int k = 0; k < 3; k++) d += cam->R[3 * i + k] * cam->R[3 * j + k];
            if (fabs(d - (i == j)) > 1e-6)
                return sh_error_set(SH_EINVAL, "camera %d: R is not a rotation (R R^T differs "
                                               "from I by %g)", index, fabs(d - (i == j)));
        }
    double det = cam->R[0] * (cam->R[4] * cam->R[8] - cam->R[5] * cam->R[7]) -
                 cam->R[1] * (cam->R[3] * cam->R[8] - cam->R[5] * cam->R[6]) +
                 cam->R[2] * (cam->R[3] * cam->R[7] - cam->R[4] * cam->R[6]);
    if (det < 0) return sh_error_set(SH_EINVAL, "camera %d: R is a reflection (det -1)", index);
    return SH_OK;
}

void sh_camera_distort(const sh_calib_camera *cam, double x, double y, double *xd, double *yd,
                       double J[4])
{
    const double *d = cam->dist;
    double k1 = d[0], k2 = d[1], p1 = d[2], p2 = d[3], k3 = d[4], k4 = d[5], k5 = d[6],
           k6 = d[7], s1 = d[8], s2 = d[9], s3 = d[10], s4 = d[11];
    double r2 = x * x + y * y;
    double a = 1 + r2 * (k1 + r2 * (k2 + r2 * k3));
    double b = 1 + r2 * (k4 + r2 * (k5 + r2 * k6));
    double rad = a / b;
    *xd = x * rad + 2 * p1 * x * y + p2 * (r2 + 2 * x * x) + r2 * (s1 + s2 * r2);
    *yd = y * rad + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y + r2 * (s3 + s4 * r2);
    if (J) {
        double da = k1 + r2 * (2 * k2 + 3 * k3 * r2);
        double db = k4 + r2 * (2 * k5 + 3 * k6 * r2);
        double drad = (da * b - a * db) / (b * b); /* d rad / d r2 */
        double ts_x = s1 + 2 * s2 * r2, ts_y = s3 + 2 * s4 * r2;
        J[0] = rad + 2 * x * x * drad + 2 * p1 * y + 6 * p2 * x + 2 * x * ts_x;
        J[1] = 2 * x * y * drad + 2 * p1 * x + 2 * p2 * y + 2 * y * ts_x;
        J[2] = 2 * x * y * drad + 2 * p1 * x + 2 * p2 * y + 2 * x * ts_y;
        J[3] = rad + 2 * y * y * drad + 6 * p1 * y + 2 * p2 * x + 2 * y * ts_y;
    }
}

sh_status sh_camera_project(const sh_calib_camera *cam, const double X[3], double uv[2], double J[6])
{
    const double *R = cam->R, *t = cam->t, *K = cam->K;
    double Xc = R[0] * X[0] + R[1] * X[1] + R[2] * X[2] + t[0];
    double Yc = R[3] * X[0] + R[4] * X[1] + R[5] * X[2] + t[1];
    double Zc = R[6] * X[0] + R[7] * X[1] + R[8] * X[2] + t[2];
    if (!(Zc > 1e-9)) return SH_ERANGE;
    double iz = 1.0 / Zc, x = Xc * iz, y = Yc * iz, xd, yd, D[4];
    sh_camera_distort(cam, x, y, &xd, &yd, J ? D : NULL);
    uv[0] = K[0] * xd + K[1] * yd + K[2];
    uv[1] = K[4] * yd + K[5];
    if (J) {
        /* d(x, y)/dXc = [iz 0 -x iz; 0 iz -y iz]; d/dX = that * R */
        double N[6];
        for (int j = 0; j < 3; j++) {
            N[j] = iz * (R[j] - x * R[6 + j]);
            N[3 + j] = iz * (R[3 + j] - y * R[6 + j]);
        }
        for (int j = 0; j < 3; j++) {
            double dxd = D[0] * N[j] + D[1] * N[3 + j];
            double dyd = D[2] * N[j] + D[3] * N[3 + j];
            J[j] = K[0] * dxd + K[1] * dyd;
            J[3 + j] = K[4] * dyd;
        }
    }
    return SH_OK;
}

sh_status sh_camera_undistort(const sh_calib_camera *cam, const double uv[2], double xn[2])
{
    const double *K = cam->K, *d = cam->dist;
    double yt = (uv[1] - K[5]) / K[4];
    double xt = (uv[0] - K[2] - K[1] * yt) / K[0];
    if (!isfinite(xt) || !isfinite(yt))
        return sh_error_set(SH_EINVAL, "undistort: non-finite pixel");
    /* OpenCV's fixed point for a start (cv::undistortPoints' iteration), then Newton */
    double x = xt, y = yt;
    for (int it = 0; it < 5; it++) {
        double r2 = x * x + y * y;
        double icdist = (1 + r2 * (d[5] + r2 * (d[6] + r2 * d[7]))) /
                        (1 + r2 * (d[0] + r2 * (d[1] + r2 * d[4])));
        if (!isfinite(icdist) || icdist <= 0) {
            x = xt;
            y = yt;
            break;
        }
        double dx = 2 * d[2] * x * y + d[3] * (r2 + 2 * x * x) + d[8] * r2 + d[9] * r2 * r2;
        double dy = d[2] * (r2 + 2 * y * y) + 2 * d[3] * x * y + d[10] * r2 + d[11] * r2 * r2;
        x = (xt - dx) * icdist;
        y = (yt - dy) * icdist;
    }
    double scale = 1 + fabs(xt) + fabs(yt);
    for (int it = 0; it < 50; it++) {
        double xd, yd, J[4];
        sh_camera_distort(cam, x, y, &xd, &yd, J);
        double ex = xd - xt, ey = yd - yt;
        if (fabs(ex) + fabs(ey) <= 1e-15 * scale) {
            xn[0] = x;
            xn[1] = y;
            return SH_OK;
        }
        double det = J[0] * J[3] - J[1] * J[2];
        if (!isfinite(det) || fabs(det) < 1e-12) break;
        double sx = (J[3] * ex - J[1] * ey) / det, sy = (-J[2] * ex + J[0] * ey) / det;
        x -= sx;
        y -= sy;
        if (fabs(sx) + fabs(sy) <= 1e-15 * (1 + fabs(x) + fabs(y))) {
            xn[0] = x;
            xn[1] = y;
            return SH_OK;
        }
    }
    /* accept a converged-to-rounding answer */
    double xd, yd;
    sh_camera_distort(cam, x, y, &xd, &yd, NULL);
    if (isfinite(x) && isfinite(y) && fabs(xd - xt) + fabs(yd - yt) < 1e-10 * scale) {
        xn[0] = x;
        xn[1] = y;
        return SH_OK;
    }
    return sh_error_set(SH_EDEGENERATE,
                        "undistort: pixel (%g, %g) is outside the region where the lens "
                        "distortion is invertible", uv[0], uv[1]);
}

void sh_camera_center(const sh_calib_camera *cam, double C[3])
{
    for (int i = 0; i < 3; i++)
        C[i] = -(cam->R[i] * cam->t[0] + cam->R[3 + i] * cam->t[1] + cam->R[6 + i] * cam->t[2]);
}

/* Inverse of a symmetric 3x3 matrix; returns the determinant (0: singular, inv untouched). */
static double inv3(const double M[9], double inv[9])
{
    double c00 = M[4] * M[8] - M[5] * M[7], c01 = M[5] * M[6] - M[3] * M[8],
           c02 = M[3] * M[7] - M[4] * M[6];
    double det = M[0] * c00 + M[1] * c01 + M[2] * c02;
    if (det == 0 || !isfinite(det)) return 0;
    double id = 1.0 / det;
    inv[0] = c00 * id;
    inv[1] = (M[2] * M[7] - M[1] * M[8]) * id;
    inv[2] = (M[1] * M[5] - M[2] * M[4]) * id;
    inv[3] = c01 * id;
    inv[4] = (M[0] * M[8] - M[2] * M[6]) * id;
    inv[5] = (M[2] * M[3] - M[0] * M[5]) * id;
    inv[6] = c02 * id;
    inv[7] = (M[1] * M[6] - M[0] * M[7]) * id;
    inv[8] = (M[0] * M[4] - M[1] * M[3]) * id;
    return det;
}

/* The linear guess X: (x r3 - r1) . X = t1 - x t3, (y r3 - r2) . X = t2 - y t3 on undistorted
 * coordinates, in least squares. */
static sh_status triangulate_linear(const sh_calib_camera *const *cams, const double *uv, int n, double *X)
{
    double M[9] = {0}, b[3] = {0};
    for (int i = 0; i < n; i++) {
        double xn[2];
        if (!finite_all(uv + 2 * i, 2))
            return sh_error_set(SH_EINVAL, "triangulate: non-finite pixel in view %d", i);
        sh_status st = sh_camera_undistort(cams[i], uv + 2 * i, xn);
        if (st) return st;
        const double *R = cams[i]->R, *t = cams[i]->t;
        for (int e = 0; e < 2; e++) {
            double a[3], rhs = t[e] - xn[e] * t[2];
            for (int j = 0; j < 3; j++) a[j] = xn[e] * R[6 + j] - R[3 * e + j];
            /* rows are unit-ish: normalise so every equation weighs the same angle */
            double l = sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]);
            for (int j = 0; j < 3; j++) a[j] /= l;
            rhs /= l;
            for (int j = 0; j < 3; j++) {
                b[j] += a[j] * rhs;
                for (int k = 0; k < 3; k++) M[3 * j + k] += a[j] * a[k];
            }
        }
    }
    double Mi[9];
    double tr = M[0] + M[4] + M[8];
    double det = inv3(M, Mi);
    if (!(det > 1e-12 * tr * tr * tr))
        return sh_error_set(SH_EDEGENERATE, "triangulate: rays are (nearly) parallel");
    for (int j = 0; j < 3; j++) X[j] = Mi[3 * j] * b[0] + Mi[3 * j + 1] * b[1] + Mi[3 * j + 2] * b[2];
    return SH_OK;
}

/* Gauss-Newton on the pixel reprojection error, distortion included, from X (refined in place):
 * at most max_iter steps; JtJi the inverse normal matrix at the result. */
static sh_status triangulate_refine(const sh_calib_camera *const *cams, const double *uv, int n, int max_iter,
                                   double *X, double *JtJi, int *iterations)
{
    double JtJ[9];
    int it = 0;
    for (;; it++) {
        double g[3] = {0};
        memset(JtJ, 0, sizeof JtJ);
        for (int i = 0; i < n; i++) {
            double p[2], J[6];
            if (sh_camera_project(cams[i], X, p, J))
                return sh_error_set(SH_EDEGENERATE, "triangulate: point behind camera %d", i);
            double r[2] = {p[0] - uv[2 * i], p[1] - uv[2 * i + 1]};
            for (int j = 0; j < 3; j++) {
                g[j] += J[j] * r[0] + J[3 + j] * r[1];
                for (int k = 0; k < 3; k++) JtJ[3 * j + k] += J[j] * J[k] + J[3 + j] * J[3 + k];
            }
        }
        if (!inv3(JtJ, JtJi))
            return sh_error_set(SH_EDEGENERATE, "triangulate: singular reprojection Jacobian");
        if (it == max_iter) break;
        double step = 0, nx = 0;
        for (int j = 0; j < 3; j++) {
            double s = JtJi[3 * j] * g[0] + JtJi[3 * j + 1] * g[1] + JtJi[3 * j + 2] * g[2];
            X[j] -= s;
            step += s * s;
            nx += X[j] * X[j];
        }
        if (step <= 1e-24 * (1 + nx)) {
            it++;
            /* one more pass below for the final Jacobian and errors */
            memset(JtJ, 0, sizeof JtJ);
            for (int i = 0; i < n; i++) {
                double p[2], J[6];
                if (sh_camera_project(cams[i], X, p, J))
                    return sh_error_set(SH_EDEGENERATE, "triangulate: point behind camera %d", i);
                for (int j = 0; j < 3; j++)
                    for (int k = 0; k < 3; k++)
                        JtJ[3 * j + k] += J[j] * J[k] + J[3 + j] * J[3 + k];
            }
            if (!inv3(JtJ, JtJi))
                return sh_error_set(SH_EDEGENERATE, "triangulate: singular reprojection Jacobian");
            break;
        }
    }
    *iterations = it;
    return SH_OK;
}

sh_status sh_camera_triangulate(const sh_calib_camera *const *cams, const double *uv, int n,
                                double sigma_px, int max_iter, sh_triangulation *out)
{
    if (!cams || !uv || !out || n < 2 || n > SH_CAMERA_MAX_VIEWS)
        return sh_error_set(SH_EINVAL, "triangulate: need 2 to %d views, got %d",
                            SH_CAMERA_MAX_VIEWS, n);
    if (sigma_px <= 0) sigma_px = 1;
    if (max_iter <= 0) max_iter = 10;
    double X[3], JtJi[9];
    int it = 0;
    sh_status st = triangulate_linear(cams, uv, n, X);
    if (st) return st;
    st = triangulate_refine(cams, uv, n, max_iter, X, JtJi, &it);
    if (st) return st;
    double ss = 0, mx = 0;
    for (int i = 0; i < n; i++) {
        double p[2];
        if (sh_camera_project(cams[i], X, p, NULL))
            return sh_error_set(SH_EDEGENERATE, "triangulate: point behind camera %d", i);
        double e2 = (p[0] - uv[2 * i]) * (p[0] - uv[2 * i]) + (p[1] - uv[2 * i + 1]) * (p[1] - uv[2 * i + 1]);
        ss += e2;
        if (e2 > mx) mx = e2;
    }
    memcpy(out->X, X, sizeof X);
    for (int j = 0; j < 9; j++) out->cov[j] = sigma_px * sigma_px * JtJi[j];
    out->rms = sqrt(ss / n);
    out->max_err = sqrt(mx);
    out->iterations = it;
    return SH_OK;
}
