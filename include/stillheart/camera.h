/* Camera geometry: projection with OpenCV's lens distortion model, undistortion, triangulation.
 *
 * Cameras are the calibration file's (include/stillheart/calib.h): X_cam = R X + t, pixels
 * (u, v) = K (x'', y'', 1) with (x'', y'') the distorted normalised coordinates of OpenCV's model:
 *   x' = Xc/Zc, y' = Yc/Zc, r2 = x'^2 + y'^2,
 *   radial = (1 + k1 r2 + k2 r2^2 + k3 r2^3) / (1 + k4 r2 + k5 r2^2 + k6 r2^3)
 *   x'' = x' radial + 2 p1 x'y' + p2 (r2 + 2 x'^2) + s1 r2 + s2 r2^2
 *   y'' = y' radial + p1 (r2 + 2 y'^2) + 2 p2 x'y' + s3 r2 + s4 r2^2
 * (coefficients k1 k2 p1 p2 k3 k4 k5 k6 s1 s2 s3 s4, as cv::projectPoints; the tilted-sensor
 * terms tx ty must be 0). Pixel centres at integers (OpenCV's convention).
 *
 * Everything here is allocation-free and fixed-size: it runs per frame per marker. */
#ifndef STILLHEART_CAMERA_H
#define STILLHEART_CAMERA_H

#include "stillheart/calib.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Most cameras a triangulation takes (the calibration file's maximum). */
#define SH_CAMERA_MAX_VIEWS SH_CALIB_MAX_CAMERAS

/* SH_OK when the camera's numbers are usable (finite, fx fy > 0, R a rotation to 1e-6, no
 * tilted-sensor terms); else SH_EINVAL / SH_EUNSUPPORTED with a message naming camera index. */
sh_status sh_camera_check(const sh_calib_camera *cam, int index);

/* Distorts normalised coordinates (x', y') -> (x'', y''); J (2x2 row major, may be NULL) is
 * d(x'', y'') / d(x', y'). */
void sh_camera_distort(const sh_calib_camera *cam, double xn, double yn, double *xd, double *yd,
                       double J[4]);

/* Projects world point X into pixels. J (2x3 row major, may be NULL): d(u, v) / dX.
 * SH_ERANGE when X is not in front of the camera (Zc <= 1e-9): uv untouched. */
sh_status sh_camera_project(const sh_calib_camera *cam, const double X[3], double uv[2],
                            double J[6]);

/* Pixel -> undistorted normalised coordinates (x', y') (the inverse of distort o K: Newton
 * iterations to 1e-12, started from OpenCV's fixed point). SH_EDEGENERATE when the iteration does
 * not converge (a pixel outside the region where the distortion is invertible). */
sh_status sh_camera_undistort(const sh_calib_camera *cam, const double uv[2], double xn[2]);

/* Camera centre in world coordinates (-R^T t). */
void sh_camera_center(const sh_calib_camera *cam, double C[3]);

typedef struct {
    double X[3];      /* world point */
    double cov[9];    /* its covariance (world units^2) for pixel noise sigma_px per coordinate */
    double rms;       /* RMS reprojection error over the views, pixels */
    double max_err;   /* largest reprojection error of one view, pixels */
    int iterations;   /* Gauss-Newton steps taken */
} sh_triangulation;

/* Triangulates one point seen at uv[2i], uv[2i+1] by cams[i], i < n (2 <= n <= SH_CAMERA_MAX_VIEWS):
 * linear triangulation on the undistorted normalised coordinates (DLT, inhomogeneous form), then
 * Gauss-Newton on the pixel reprojection error with distortion (at most max_iter steps, 0: 10).
 * sigma_px: the pixel noise used for cov (<= 0: 1). SH_EDEGENERATE for parallel rays or a point
 * behind a camera. */
sh_status sh_camera_triangulate(const sh_calib_camera *const *cams, const double *uv, int n,
                                double sigma_px, int max_iter, sh_triangulation *out);

#ifdef __cplusplus
}
#endif
#endif
