/* OpenCV's camera model (pinhole, radial k1..k6, tangential p1 p2, thin prism s1..s4) for the
 * 3D engine, and the virtual cameras built from a real one. */
#include <math.h>
#include <string.h>

#include "stillheart/camera.h"
#include "warp3d_internal.h"

/* The projection and the undistortion are libstillheart's (include/stillheart/camera.h): one
 * implementation of OpenCV's model for the tracker's triangulation and the 3D engine. */
int sh_warp3d_project(const sh_calib_camera *c, const double X[3], double *x, double *y)
{
    double uv[2];
    if (sh_camera_project(c, X, uv, NULL) != SH_OK) return 0;
    *x = uv[0];
    *y = uv[1];
    return 1;
}

int sh_warp3d_ray(const sh_calib_camera *c, double x, double y, double C[3], double d[3])
{
    double uv[2] = {x, y}, xn[2];
    if (sh_camera_undistort(c, uv, xn) != SH_OK) return 0;
    double dc[3] = {xn[0], xn[1], 1}, len = sqrt(xn[0] * xn[0] + xn[1] * xn[1] + 1);
    for (int i = 0; i < 3; i++)
        d[i] = (c->R[i] * dc[0] + c->R[3 + i] * dc[1] + c->R[6 + i] * dc[2]) / len;
    sh_camera_center(c, C);
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
