/* OpenCV's camera model (pinhole, radial k1..k6, tangential p1 p2, thin prism s1..s4) for the
 * 3D engine, and the virtual cameras built from a real one. */
#include <math.h>
#include <string.h>

#include "warp3d_internal.h"

void w3_distort(const double *k, double x, double y, double *xd, double *yd)
{
    double r2 = x * x + y * y, r4 = r2 * r2, r6 = r4 * r2;
    double radial = (1 + k[0] * r2 + k[1] * r4 + k[4] * r6) / (1 + k[5] * r2 + k[6] * r4 + k[7] * r6);
    *xd = x * radial + 2 * k[2] * x * y + k[3] * (r2 + 2 * x * x) + k[8] * r2 + k[9] * r4;
    *yd = y * radial + k[2] * (r2 + 2 * y * y) + 2 * k[3] * x * y + k[10] * r2 + k[11] * r4;
}

int w3_has_distortion(const sh_calib_camera *cam)
{
    for (int i = 0; i < SH_CALIB_MAX_DIST; i++)
        if (cam->dist[i] != 0) return 1;
    return 0;
}

int sh_warp3d_project(const sh_calib_camera *c, const double X[3], double *x, double *y)
{
    double xc[3];
    for (int r = 0; r < 3; r++)
        xc[r] = c->R[3 * r] * X[0] + c->R[3 * r + 1] * X[1] + c->R[3 * r + 2] * X[2] + c->t[r];
    if (!(xc[2] > 1e-9)) return 0;
    double xn = xc[0] / xc[2], yn = xc[1] / xc[2], xd = xn, yd = yn;
    if (w3_has_distortion(c)) w3_distort(c->dist, xn, yn, &xd, &yd);
    *x = c->K[0] * xd + c->K[1] * yd + c->K[2];
    *y = c->K[4] * yd + c->K[5];
    return 1;
}

/* Normalized undistorted coordinates of a distorted pixel: Newton on the distortion. */
static int undistort(const sh_calib_camera *c, double x, double y, double *xn, double *yn)
{
    double yd = (y - c->K[5]) / c->K[4];
    double xd = (x - c->K[2] - c->K[1] * yd) / c->K[0];
    *xn = xd;
    *yn = yd;
    if (!w3_has_distortion(c)) return 1;
    double px = xd, py = yd;
    for (int it = 0; it < 50; it++) {
        double fx, fy, ax, ay, bx, by;
        const double e = 1e-7;
        w3_distort(c->dist, px, py, &fx, &fy);
        fx -= xd;
        fy -= yd;
        if (fabs(fx) < 1e-13 && fabs(fy) < 1e-13) {
            *xn = px;
            *yn = py;
            return 1;
        }
        w3_distort(c->dist, px + e, py, &ax, &ay);
        w3_distort(c->dist, px, py + e, &bx, &by);
        double j00 = (ax - fx - xd) / e, j10 = (ay - fy - yd) / e;
        double j01 = (bx - fx - xd) / e, j11 = (by - fy - yd) / e;
        double det = j00 * j11 - j01 * j10;
        if (!(fabs(det) > 1e-12)) return 0;
        px -= (j11 * fx - j01 * fy) / det;
        py -= (j00 * fy - j10 * fx) / det;
        if (!isfinite(px) || !isfinite(py)) return 0;
    }
    return 0;
}

void w3_camera_center(const sh_calib_camera *c, double C[3])
{
    for (int i = 0; i < 3; i++)
        C[i] = -(c->R[i] * c->t[0] + c->R[3 + i] * c->t[1] + c->R[6 + i] * c->t[2]);
}

int sh_warp3d_ray(const sh_calib_camera *c, double x, double y, double C[3], double d[3])
{
    double xn, yn;
    if (!undistort(c, x, y, &xn, &yn)) return 0;
    double dc[3] = {xn, yn, 1}, len = sqrt(xn * xn + yn * yn + 1);
    for (int i = 0; i < 3; i++)
        d[i] = (c->R[i] * dc[0] + c->R[3 + i] * dc[1] + c->R[6 + i] * dc[2]) / len;
    w3_camera_center(c, C);
    return 1;
}

static void pinhole_copy(const sh_calib_camera *cam, sh_calib_camera *out)
{
    *out = *cam;
    memset(out->dist, 0, sizeof out->dist);
    out->num_dist = 5;
}

static void compute_p(sh_calib_camera *c)
{
    for (int r = 0; r < 3; r++)
        for (int k = 0; k < 4; k++) {
            double s = 0;
            for (int j = 0; j < 3; j++) s += c->K[3 * r + j] * (k < 3 ? c->R[3 * j + k] : c->t[j]);
            c->P[4 * r + k] = s;
        }
}

void sh_warp3d_stereo_cameras(const sh_calib_camera *cam, double baseline, sh_calib_camera *left,
                              sh_calib_camera *right)
{
    pinhole_copy(cam, left);
    pinhole_copy(cam, right);
    left->t[0] += baseline / 2;  /* centre C - b/2 x_axis: t = -R C */
    right->t[0] -= baseline / 2;
    compute_p(left);
    compute_p(right);
}

void sh_warp3d_pose_camera(const sh_calib_camera *cam, const double centre[3], const double rvec[3],
                           const double tvec[3], sh_calib_camera *out)
{
    pinhole_copy(cam, out);
    double Rd[9], th = sqrt(rvec[0] * rvec[0] + rvec[1] * rvec[1] + rvec[2] * rvec[2]);
    double k[3] = {0, 0, 0};
    if (th > 0)
        for (int i = 0; i < 3; i++) k[i] = rvec[i] / th;
    double cs = cos(th), sn = sin(th), vc = 1 - cs;
    Rd[0] = cs + k[0] * k[0] * vc;        Rd[1] = k[0] * k[1] * vc - k[2] * sn; Rd[2] = k[0] * k[2] * vc + k[1] * sn;
    Rd[3] = k[1] * k[0] * vc + k[2] * sn; Rd[4] = cs + k[1] * k[1] * vc;        Rd[5] = k[1] * k[2] * vc - k[0] * sn;
    Rd[6] = k[2] * k[0] * vc - k[1] * sn; Rd[7] = k[2] * k[1] * vc + k[0] * sn; Rd[8] = cs + k[2] * k[2] * vc;
    double c[3];
    for (int r = 0; r < 3; r++)
        c[r] = cam->R[3 * r] * centre[0] + cam->R[3 * r + 1] * centre[1] + cam->R[3 * r + 2] * centre[2] +
               cam->t[r];
    for (int r = 0; r < 3; r++) {
        for (int col = 0; col < 3; col++) {
            double s = 0;
            for (int j = 0; j < 3; j++) s += Rd[3 * r + j] * cam->R[3 * j + col];
            out->R[3 * r + col] = s;
        }
        double s = 0;
        for (int j = 0; j < 3; j++) s += Rd[3 * r + j] * (cam->t[j] - c[j]);
        out->t[r] = s + c[r] + tvec[r];
    }
    compute_p(out);
}
