/* Pinhole cameras with OpenCV's lens distortion model (k1 k2 p1 p2 k3), written out exactly as
 * cv::projectPoints computes it so that the calibration file reproduces our pixels. */
#include <math.h>
#include <string.h>

#include "phantom.h"

int phantom_project(const phantom_camera *c, const double X[3], double *x, double *y)
{
    const double *R = c->R;
    double xc = R[0] * X[0] + R[1] * X[1] + R[2] * X[2] + c->t[0];
    double yc = R[3] * X[0] + R[4] * X[1] + R[5] * X[2] + c->t[1];
    double zc = R[6] * X[0] + R[7] * X[1] + R[8] * X[2] + c->t[2];
    if (!(zc > 1e-9)) return 0;
    double a = xc / zc, b = yc / zc;
    double r2 = a * a + b * b;
    const double *d = c->dist;
    double radial = 1.0 + r2 * (d[0] + r2 * (d[1] + r2 * d[4]));
    double xd = a * radial + 2.0 * d[2] * a * b + d[3] * (r2 + 2.0 * a * a);
    double yd = b * radial + d[2] * (r2 + 2.0 * b * b) + 2.0 * d[3] * a * b;
    *x = c->fx * xd + c->cx;
    *y = c->fy * yd + c->cy;
    return 1;
}

void phantom_camera_center(const phantom_camera *c, double C[3])
{
    /* C = -R^T t */
    for (int i = 0; i < 3; i++)
        C[i] = -(c->R[i] * c->t[0] + c->R[3 + i] * c->t[1] + c->R[6 + i] * c->t[2]);
}

void phantom_undistort(const phantom_camera *c, double x, double y, double *xn, double *yn)
{
    /* OpenCV's fixed-point iteration; converges for the mild distortion the model accepts. */
    const double *d = c->dist;
    double x0 = (x - c->cx) / c->fx, y0 = (y - c->cy) / c->fy;
    double a = x0, b = y0;
    for (int it = 0; it < 50; it++) {
        double r2 = a * a + b * b;
        double radial = 1.0 + r2 * (d[0] + r2 * (d[1] + r2 * d[4]));
        double dx = 2.0 * d[2] * a * b + d[3] * (r2 + 2.0 * a * a);
        double dy = d[2] * (r2 + 2.0 * b * b) + 2.0 * d[3] * a * b;
        a = (x0 - dx) / radial;
        b = (y0 - dy) / radial;
    }
    *xn = a;
    *yn = b;
}

void phantom_calibration(const phantom_model *m, sh_calib *cal)
{
    memset(cal, 0, sizeof *cal);
    cal->num_cameras = m->num_cameras;
    cal->width = m->width;
    cal->height = m->height;
    for (int c = 0; c < m->num_cameras; c++) {
        const phantom_camera *pc = &m->cam[c];
        sh_calib_camera *k = &cal->cam[c];
        double K[9] = {pc->fx, 0, pc->cx, 0, pc->fy, pc->cy, 0, 0, 1};
        memcpy(k->K, K, sizeof K);
        memcpy(k->dist, pc->dist, sizeof pc->dist);
        k->num_dist = 5;
        memcpy(k->R, pc->R, sizeof pc->R);
        memcpy(k->t, pc->t, sizeof pc->t);
    }
    sh_calib_compute_p(cal);
}
