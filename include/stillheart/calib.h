/* Camera calibration files: OpenCV FileStorage YAML as cv::FileStorage writes and reads it.
 *
 * Keys: num_cameras, image_width, image_height, and per camera i (0-based) K_i (3x3), dist_i
 * (1xN or Nx1, N = 4, 5, 8, 12 or 14: k1 k2 p1 p2 [k3 [k4 k5 k6 [s1..s4 [tx ty]]]]), R_i (3x3)
 * and t_i (3x1) mapping world to camera (X_cam = R X + t, as cv::stereoCalibrate and
 * cv::solvePnP return them), and P_i = K_i [R_i | t_i] (3x4, optional on reading: computed when
 * absent). Matrices are `!!opencv-matrix` maps with rows, cols, dt (d or f) and data.
 * Only that subset of YAML is parsed: no libyaml, and other keys are skipped. */
#ifndef STILLHEART_CALIB_H
#define STILLHEART_CALIB_H

#include "stillheart/core.h"

#ifdef __cplusplus
extern "C" {
#endif

#define SH_CALIB_MAX_CAMERAS 4
#define SH_CALIB_MAX_DIST 14

typedef struct {
    double K[9];                    /* row major */
    double dist[SH_CALIB_MAX_DIST]; /* unused coefficients are 0 */
    int num_dist;                   /* as written in the file (5 for our renderer) */
    double R[9];
    double t[3];
    double P[12];
} sh_calib_camera;

typedef struct {
    int num_cameras;
    int width, height;
    sh_calib_camera cam[SH_CALIB_MAX_CAMERAS];
} sh_calib;

/* Fills P = K [R | t] for every camera. */
void sh_calib_compute_p(sh_calib *calib);

/* What a calibration must satisfy to be loaded: bounds on what a real rig can be, so that a
 * typo, a unit slip or a copied block is refused before it is used (docs/3d.md, "Calibration
 * files"). Defaults (sh_calib_limits_default) in brackets. */
typedef struct {
    double fov_min_deg, fov_max_deg; /* each axis' field of view, 2 atan(size / 2f) [1, 170] */
    double rig_scale;       /* |t| at most this, world units (mm in ours) [10000: 10 m] */
    double rotation_tol;    /* max |(R R^T - I)_ij| and |det R - 1| [1e-5: a float file passes] */
    double same_pose;       /* two camera centres closer than this fraction of the farther one's
                             * distance from the world origin are one pose [1e-4] */
    double dist_factor_min, dist_factor_max; /* radial distortion factor over the image [0.2, 5] */
} sh_calib_limits;

/* How far a calibration is from the limits (sh_calib_check fills it; for tests and tools). */
typedef struct {
    double fov_deg[2];       /* smallest and largest field of view over cameras and axes */
    double pp_edge_px;       /* smallest distance from a principal point to the image's edge */
    double t_max;            /* largest |t| */
    double rotation_err;     /* largest rotation error (as rotation_tol) */
    double separation;       /* smallest distance between two centres over the farther's distance
                              * from the origin (INFINITY for one camera) */
    double dist_factor[2];   /* smallest / largest radial factor over the image */
    double dist_slope;       /* smallest d(r_distorted)/dr over the image (> 0: no fold) */
} sh_calib_margins;

void sh_calib_limits_default(sh_calib_limits *limits);
/* Checks a calibration against the limits (NULL: the defaults): every camera's focal lengths
 * give a field of view within bounds, its principal point lies inside the image, K's last row
 * is 0 0 1, its radial distortion neither folds the image (r_distorted rises with r out to the
 * image's corners) nor scales it beyond the factor bounds, its tangential terms are at most 0.5,
 * R is a rotation within rotation_tol, |t| is within rig_scale, and no two cameras share a
 * pose. A refusal (SH_EFORMAT) names `name` (the file), the camera and the field. margins may
 * be NULL. */
sh_status sh_calib_check(const sh_calib *calib, const char *name, const sh_calib_limits *limits,
                         sh_calib_margins *margins);

/* Writes the file (doubles with 17 significant digits, so reading gives back the same bits). */
sh_status sh_calib_write(const char *path, const sh_calib *calib);
/* Reads a file and checks it against the limits (NULL: the defaults); errors name the file and
 * the line, or the camera and field. */
sh_status sh_calib_load(const char *path, const sh_calib_limits *limits, sh_calib *calib);
/* sh_calib_load with the default limits. */
sh_status sh_calib_read(const char *path, sh_calib *calib);
/* Parses a file already in memory (name used in messages), without sh_calib_check. Exposed for
 * fuzzing. */
sh_status sh_calib_parse(const char *text, size_t len, const char *name, sh_calib *calib);

#ifdef __cplusplus
}
#endif
#endif
