/* The beating-heart phantom: an analytic model of a deforming heart patch seen by 1-3 calibrated
 * cameras, and the ground-truth queries on it.
 *
 * The renderer (tools/render) draws this model and the evaluator queries it; both link this
 * library, so the pixels in a rendered video and the truth returned here come from one function.
 *
 * Frames and units
 *   World = the calibration frame: millimetres, Z up out of the table, the patch near Z = 0..20.
 *   Material coordinates (u, v), mm: a point of the heart surface is named by where it sits on the
 *   rest-shape patch, u in [-size_u/2, size_u/2], v in [-size_v/2, size_v/2]. X(u, v, t) is its
 *   world position at time t = frame / fps seconds. Blood blobs and the texture are glued to
 *   (u, v), so they move with the tissue; markers are stickers glued at their centre (below).
 *   Pixels follow OpenCV: the centre of the top-left pixel is (0, 0), and x, y are in the
 *   distorted image (OpenCV's k1 k2 p1 p2 k3 model). libapriltag reports corners with the centre of
 *   the top-left pixel at (0.5, 0.5): subtract 0.5 from its detections before comparing.
 *
 * Markers are flat stickers glued at their centre: a tag is the parallelogram
 *   X(c, t) + a dX/du(c, t) + b dX/dv(c, t), |a|, |b| <= its half extent, where c = (u, v) of its
 *   centre. It stays flat (so a detector's homography fits it exactly and the image diagonals
 *   meet at the projected centre) but stretches, shears, turns and tilts with the tissue under
 *   its centre. tag_size is the black border's edge in material mm (on the dome's slopes the
 *   sticker is up to ~5% larger in 3D). Over its extent a sticker departs from the tissue
 *   under it by up to ~0.8 mm (~6 px at 1080p at its rim), so the truth tells the two apart:
 *   phantom_truth_locate_content() says whether a pixel sees a sticker or the tissue, and
 *   phantom_truth_where() follows whichever is seen.
 *   Point 0..3 are the outer corners of the black border in libapriltag's detection order (for a
 *   tag seen upright: bottom-left, bottom-right, top-right, top-left, i.e. (a, b) =
 *   (-s/2, -s/2), (s/2, -s/2), (s/2, s/2), (-s/2, s/2)); point 4 (`c` in the CSV) is the centre,
 *   a point of the tissue as well as of the sticker.
 *
 * The decoy (with --occlusions): a tag of the same family on a rigid card lying beside the heart.
 *   Its id is not among the markers' ids and it has no rows in markers.csv: a tracker that
 *   reports it has been fooled. phantom_truth_decoy() gives its pixels.
 *
 * Every function returning sh_status records a one-line message with sh_error_set on failure.
 * The truth functions only read the loaded model: call them from any number of threads. A
 * locate costs ~3 us (Newton, a few iterations), a project ~0.1 us (one core, 1080p). */
#ifndef STILLHEART_PHANTOM_H
#define STILLHEART_PHANTOM_H

#include <stdint.h>

#include "stillheart/calib.h"
#include "stillheart/core.h"

#ifdef __cplusplus
extern "C" {
#endif

#define PHANTOM_MAX_CAMERAS 3
#define PHANTOM_MAX_MARKERS 64
#define PHANTOM_MAX_BLOBS 8
#define PHANTOM_MAX_PADS 2
#define PHANTOM_POINTS 5 /* corners 0..3, then the centre */
#define PHANTOM_PARAMS_FILE "phantom.txt"

typedef struct {
    double fx, fy, cx, cy;
    double dist[5]; /* k1 k2 p1 p2 k3 */
    double R[9];    /* world -> camera rotation, row major */
    double t[3];    /* world -> camera translation, mm */
} phantom_camera;

typedef struct {
    int id;
    double u, v;    /* tag centre, material mm */
} phantom_marker;

typedef struct {
    double u, v, radius; /* material mm */
    double t0, t1;       /* seconds: grows from t0, shrinks back until t1 */
} phantom_blob;

/* A stabilizer pad: a capsule of radius pad_radius lying on the rest surface along the material
 * segment (u0, v0)-(u1, v1); the tissue around it is held at its rest position. */
typedef struct {
    double u0, v0, u1, v1;
} phantom_pad;

typedef struct {
    /* sequence and image */
    double fps;
    int frames;
    int width, height;
    uint64_t seed;
    /* rest shape: a dome over the size_u x size_v patch */
    double size_u, size_v;
    double dome_height, dome_su, dome_sv, dome_u, dome_v;
    /* heartbeat: activation c(t) = (1 - cos phi)/2 + 0.12 sin 2 phi, phi = 2 pi heart_hz t' +
     * heart_phase, where t' lags by delay * (u + size_u/2) / size_u (a contraction wave) */
    double heart_hz, heart_phase, delay;
    double contraction;                 /* in-plane shrink toward the dome centre at c = 1 */
    double twist, twist_radius;         /* rotation angle (rad) at radius twist_radius, c = 1 */
    double lift, lift_u, lift_v, lift_sigma;           /* out-of-plane bulge, mm */
    double push, push_u, push_v, push_sigma, push_phase; /* local in-plane bulge, mm */
    /* respiration: r(t) = (1 - cos 2 pi resp_hz t)/2 shifts by r * resp_shift and tilts about X */
    double resp_hz, resp_shift[3], resp_tilt;
    /* stabilizer: motion is scaled by prod_pads (1 - exp(-d^2 / pad_falloff^2)) */
    int num_pads;
    phantom_pad pad[PHANTOM_MAX_PADS];
    double pad_falloff, pad_radius;
    /* markers */
    char family[32];
    double tag_size; /* mm, outer edge of the black border */
    int num_markers;
    phantom_marker marker[PHANTOM_MAX_MARKERS];
    /* cameras */
    int num_cameras;
    phantom_camera cam[PHANTOM_MAX_CAMERAS];
    /* occlusions: an instrument shaft (capsule) whose tip moves from shaft_p0 to shaft_p1 and
     * back as (1 - cos 2 pi t / shaft_period)/2, its axis running from the tip along shaft_dir */
    int shaft;
    double shaft_p0[3], shaft_p1[3], shaft_dir[3], shaft_length, shaft_radius, shaft_period;
    int num_blobs;
    phantom_blob blob[PHANTOM_MAX_BLOBS];
    int decoy, decoy_id;
    double decoy_center[3], decoy_yaw; /* flat on a card, normal +Z */
    /* appearance (renderer only; kept so a sequence can be re-rendered from its file) */
    double noise, exposure;
    /* a moved or bumped endoscope: everything the cameras see (surface, pads, shaft, decoy) is
     * translated by d(t) = s(t) cam_motion_shift, world mm, parallel to camera 0's image plane.
     * PHANTOM_CAM_PAN: s = (1 - cos(pi (t - t0) / dur)) / 2 over [t0, t0 + dur], 0 before and 1
     * after; PHANTOM_CAM_BUMP: s = 0 before t0, 1 from t0 on (t0 is a frame's time, so the step
     * falls between two frames). phantom.txt carries these keys only when cam_motion is set. */
    int cam_motion;
    double cam_motion_t0, cam_motion_dur, cam_motion_shift[3];
    /* a sudden first beat: the heart's (lagged) time tl is warped so that the heart rests at
     * phase 0 (c = 0) while tl < first_beat_at, then rises from phase 0 to pi four times faster
     * than normal, then beats at heart_hz, phase continuous. Respiration keeps the clock. */
    int first_beat;
    double first_beat_at;
    /* the tissue texture's contrast about its mean colour (renderer only): 0 as designed (1);
     * phantom.txt carries it only when set */
    double texture_contrast;
    /* the tissue texture's minification (renderer only): 0 the nearest mip level, 1 trilinear
     * (the two nearest blended: no seam where the level changes); phantom.txt carries it only
     * when 1 */
    int texture_trilinear;
    /* how long a blood blob takes to grow to its radius, and to shrink back, in seconds: 0 the
     * designed 0.4 s (PHANTOM_BLOOD_SPREAD); its time at full size is the same whatever it is.
     * phantom.txt carries it only when set */
    double blood_spread;
} phantom_model;

enum { PHANTOM_CAM_NONE = 0, PHANTOM_CAM_PAN = 1, PHANTOM_CAM_BUMP = 2 };
/* The pan's length and how far each motion moves the image of the patch centre in camera 0. */
#define PHANTOM_PAN_SECONDS 0.25
#define PHANTOM_PAN_FRACTION 0.06
#define PHANTOM_BUMP_FRACTION 0.03
/* How much faster than heart_hz the first contraction runs. */
#define PHANTOM_FIRST_BEAT_SPEEDUP 4.0
/* How long a blood blob grows, and shrinks, unless --blood-spread says otherwise (seconds). */
#define PHANTOM_BLOOD_SPREAD 0.4

/* ---- the model (model.c, camera.c) ---- */

/* World position of material point (u, v) at time t (seconds). Defined for every (u, v), so
 * Newton iterations may step outside the patch. Includes the camera motion below. */
void phantom_surface(const phantom_model *m, double u, double v, double t, double X[3]);
/* The camera motion's translation d(t) of the whole scene, world mm (0 without one). */
void phantom_camera_motion(const phantom_model *m, double t, double d[3]);
/* The heart's warped time: tl itself unless first_beat is set (see phantom_model). */
double phantom_heart_time(const phantom_model *m, double tl);
/* Unit normal (pointing up, toward the cameras) at (u, v, t). */
void phantom_surface_normal(const phantom_model *m, double u, double v, double t, double n[3]);
/* 1 when (u, v) lies on the patch. */
int phantom_on_patch(const phantom_model *m, double u, double v);

/* Projects a world point into camera pixels (distorted). Returns 0 when the point is not in
 * front of the camera (then x, y are unset). */
int phantom_project(const phantom_camera *c, const double X[3], double *x, double *y);
/* Camera centre in world coordinates. */
void phantom_camera_center(const phantom_camera *c, double C[3]);
/* Normalised undistorted ray coordinates (X/Z, Y/Z) of a distorted pixel (fixed point). */
void phantom_undistort(const phantom_camera *c, double x, double y, double *xn, double *yn);
/* The model's cameras as a calibration (K, k1 k2 p1 p2 k3, R, t, P = K [R | t]): what
 * stillheart-render writes beside its videos. */
void phantom_calibration(const phantom_model *m, sh_calib *cal);

/* Material coordinates of marker index i's point k (0..3 corners, 4 centre): where on the
 * tissue the point sits (what a blood blob covers). */
void phantom_marker_uv(const phantom_model *m, int i, int k, double *u, double *v);
/* Marker i's sticker at time t: its centre O and the axes ea (along u), eb (along v) per mm. */
void phantom_tag_frame(const phantom_model *m, int i, double t, double O[3], double ea[3], double eb[3]);
/* World position of marker i's point k at time t (see "Markers" above). */
void phantom_marker_point(const phantom_model *m, int i, int k, double t, double X[3]);
/* Visibility of marker i's point k in camera c at time t (blobs, facing, occluders, image). */
int phantom_marker_visible(const phantom_model *m, int c, double t, int i, int k);
/* World position and visibility of sticker i's point (a, b) (mm along ea, eb) at time t. */
void phantom_sticker_point(const phantom_model *m, int i, double a, double b, double t, double X[3]);
int phantom_sticker_visible(const phantom_model *m, int c, double t, int i, double a, double b);

/* Tip and far end of the shaft's axis at time t. */
void phantom_shaft_axis(const phantom_model *m, double t, double tip[3], double end[3]);
/* Current radius of blob b at time t (0 when absent). */
double phantom_blob_radius(const phantom_model *m, int b, double t);
/* Bits across a family's sticker (apriltag_to_image's width, plus a one-bit white margin for
 * families whose outer ring holds data) and, in border_bits, across its black border; 0 for a
 * family we do not draw. */
int phantom_sticker_bits(const char *family, int *border_bits);
/* Edge of a marker's sticker (mm, material) and of the decoy's card. */
double phantom_sticker_size(const phantom_model *m);
double phantom_decoy_card(const phantom_model *m);
/* World endpoints of stabilizer pad i's axis (a capsule of radius pad_radius) at time t (the
 * pads are fixed to the tissue's rest shape; only a camera motion moves them). */
void phantom_pad_axis(const phantom_model *m, int i, double t, double a[3], double b[3]);
/* World positions of the decoy's corners (0..3, libapriltag order) and centre (4) at time t. */
void phantom_decoy_point(const phantom_model *m, int k, double t, double X[3]);

/* Visibility of the surface point (u, v) in camera c at time t: in the image, facing the camera,
 * not under a blood blob, not behind the shaft, a stabilizer pad or the decoy card. */
int phantom_visible(const phantom_model *m, int c, double t, double u, double v);
/* Visibility of an arbitrary world point (no blob/facing test): in the image and not occluded. */
int phantom_point_visible(const phantom_model *m, int c, double t, const double X[3]);

/* ---- presets (preset.c) ---- */

typedef struct {
    const char *preset;   /* "exvivo" or "invivo" */
    int frames;           /* <= 0: the preset's */
    int cameras;          /* 1..3 */
    int width, height;
    uint64_t seed;
    int occlusions;
    double bpm;           /* <= 0: the preset's */
    int markers;          /* <= 0: the preset's */
    double tag_size;      /* <= 0: 10 mm */
    const char *family;   /* NULL: tag36h11 */
    const int *ids;       /* NULL: 0..markers-1 */
    int num_ids;
    const int *only;      /* NULL: every marker; else the markers are laid out as without it and
                           * only those with these ids kept (the others' tissue bare): four tags
                           * at the corners of the field without the stickers between them */
    int num_only;
    double fps;           /* <= 0: the preset's */
    const double *dist;   /* NULL: no lens distortion; else k1 k2 p1 p2 k3 for every camera */
    double noise;         /* < 0: default */
    double exposure;      /* <= 0: 1 */
    int periodic;         /* 1: heart and respiration rates rounded to whole cycles over the
                           * sequence, so that it loops without a jump (frame `frames` = frame 0) */
    int camera_motion;    /* PHANTOM_CAM_NONE, _PAN (6 % of the width over 0.25 s) or _BUMP (3 %
                           * of the width between two frames); not with periodic */
    double camera_motion_at; /* seconds; <= 0: 40 % into the sequence. A bump moves the first
                              * frame at or after it */
    int first_beat;       /* 1: rest, then a first contraction 4x faster; not with periodic */
    double first_beat_at; /* seconds of rest from frame 0; <= 0: 0.5 s */
    double texture_contrast; /* <= 0 or 1: the texture as designed; else its contrast scaled */
    int texture_trilinear;   /* 1: the tissue texture filtered trilinearly (phantom_model's) */
    double blood_spread;     /* <= 0: PHANTOM_BLOOD_SPREAD; else the blobs' growth and shrinking
                              * time, seconds (phantom_model's); with occlusions only */
} phantom_options;

void phantom_options_default(phantom_options *o);
/* The presets' random numbers (splitmix64): the next word, and a uniform double in [lo, hi). */
uint64_t phantom_splitmix(uint64_t *s);
double phantom_uniform(uint64_t *s, double lo, double hi);
/* Builds the model for the options; refuses impossible ones (too many markers for the patch,
 * duplicate ids, lens distortion that folds the image) with a message. */
sh_status phantom_model_build(const phantom_options *o, phantom_model *m);

/* ---- the parameter file (params.c) ---- */

sh_status phantom_model_write(const phantom_model *m, const char *path);
sh_status phantom_model_read(const char *path, phantom_model *m);
/* Parses a file already in memory (name used in messages). Exposed for fuzzing. */
sh_status phantom_model_parse(const char *text, size_t len, const char *name, phantom_model *m);

/* ---- ground truth (truth.c) ---- */

typedef struct phantom_truth phantom_truth;

/* Loads DIR/phantom.txt as written by stillheart-render. */
sh_status phantom_truth_open(const char *dir, phantom_truth **out);
void phantom_truth_close(phantom_truth *truth);
const phantom_model *phantom_truth_model(const phantom_truth *truth);

/* Material point (u, v) seen at pixel (x, y) of camera c in frame f: Newton on (u, v) of the
 * distorted projection, to 1e-9 px. SH_ERANGE when the pixel does not see the heart patch (then
 * u, v still hold the solution on the analytic surface's extension, when one was found). */
sh_status phantom_truth_locate(const phantom_truth *truth, int c, int frame, double x, double y,
                               double *u, double *v);
/* Pixel of material point (u, v) in camera c at frame f. SH_ERANGE when behind the camera. */
sh_status phantom_truth_project(const phantom_truth *truth, int c, int frame, double u, double v,
                                double *x, double *y);
/* What a pixel sees: the tissue, or a marker's sticker (drawn over the tissue). */
typedef struct {
    int marker;  /* -1: the tissue; else the index of the marker whose sticker is seen */
    double u, v; /* tissue: material coordinates. Sticker: u_c + a, v_c + b for sticker point
                  * (a, b), i.e. the material point it was laid on */
} phantom_content;

/* The content seen at pixel (x, y) of camera c in frame f (stickers win over the tissue, as
 * they are drawn). Errors as phantom_truth_locate. */
sh_status phantom_truth_locate_content(const phantom_truth *truth, int c, int frame, double x,
                                       double y, phantom_content *p);
/* Pixel of that content in camera c at frame f. */
sh_status phantom_truth_project_content(const phantom_truth *truth, int c, int frame,
                                        const phantom_content *p, double *x, double *y);
/* 1 when the content is visible in camera c at frame f (blobs, facing, occluders, image). */
int phantom_truth_content_visible(const phantom_truth *truth, int c, int frame,
                                  const phantom_content *p);

/* Where the content seen at (x, y) of camera c in ref_frame (tissue or sticker) is, in camera
 * c's pixels, in frame f. For many pixels, locate_content once in the reference frame and
 * project_content per frame instead. */
sh_status phantom_truth_where(const phantom_truth *truth, int c, int ref_frame, double x, double y,
                              int frame, double *x_t, double *y_t);
/* 1 when material point (u, v) is visible in camera c at frame f (see phantom_visible). This
 * judges the tissue alone: a sticker over it does not count (phantom_truth_content_visible on
 * what locate_content found tells what is seen). */
int phantom_truth_visible(const phantom_truth *truth, int c, int frame, double u, double v);
/* Same as `frame` above but at any time (seconds), for sub-frame queries. */
sh_status phantom_truth_project_at(const phantom_truth *truth, int c, double t, double u, double v,
                                   double *x, double *y);

int phantom_truth_num_markers(const phantom_truth *truth);
/* Marker index i (0..num_markers-1) point k (0..3 corners, 4 centre) in camera c, frame f:
 * pixel, world position (mm) and visibility. Any output pointer may be NULL. */
sh_status phantom_truth_marker(const phantom_truth *truth, int c, int frame, int i, int k,
                               int *id, double *x, double *y, double X[3], int *visible);
/* The decoy's point k (0..4) in camera c at frame f. SH_EINVAL when there is no decoy. */
sh_status phantom_truth_decoy(const phantom_truth *truth, int c, int frame, int k, int *id,
                              double *x, double *y, int *visible);

/* ---- markers.csv (markers_csv.c) ---- */

typedef struct {
    int frame, camera, id;
    int point; /* 0..3 corners, 4 = centre ('c') */
    double x, y;
    int visible;
    double X, Y, Z;
} phantom_csv_row;

typedef struct {
    phantom_csv_row *rows;
    int count;
} phantom_csv;

#define PHANTOM_CSV_HEADER "frame,camera,id,point,x,y,visible,X,Y,Z"

/* Reads markers.csv; a bad header or row fails naming the file and line. */
sh_status phantom_csv_read(const char *path, phantom_csv *csv);
sh_status phantom_csv_parse(const char *text, size_t len, const char *name, phantom_csv *csv);
void phantom_csv_free(phantom_csv *csv);
/* The row for (frame, camera, id, point), or NULL. Rows are kept in file order; the lookup is a
 * binary search when the file is sorted as the renderer writes it, else a scan. */
const phantom_csv_row *phantom_csv_find(const phantom_csv *csv, int frame, int camera, int id,
                                        int point);

#ifdef __cplusplus
}
#endif
#endif
