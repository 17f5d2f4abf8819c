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

/* Writes the file (doubles with 17 significant digits, so reading gives back the same bits). */
sh_status sh_calib_write(const char *path, const sh_calib *calib);
/* Reads a file; errors name the file and line. */
sh_status sh_calib_read(const char *path, sh_calib *calib);
/* Parses a file already in memory (name used in messages). Exposed for fuzzing. */
sh_status sh_calib_parse(const char *text, size_t len, const char *name, sh_calib *calib);

#ifdef __cplusplus
}
#endif
#endif
