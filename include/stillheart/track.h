/* Marker tracking: one Kalman filter per marker, fixed size, allocation-free after create.
 *
 * Motion model (docs/tracking.md says why): per coordinate, a slowly drifting baseline plus a
 * Fourier series of the heartbeat (SH_TRACK_MAX_HEART_HARMONICS harmonics of f_h) and of
 * respiration (harmonics of f_r), in rotating (oscillator) form so that a rate change only changes
 * the rotation per frame. f_h and f_r are common to the whole heart and are estimated online from
 * the recent tracks of all markers (a harmonic-sum periodogram, refined, then least squares), and
 * re-estimated every half second. Until the rates are locked a marker follows a constant-velocity
 * model with wide gates.
 *
 * 2D mode (no calibration, one camera): the state is the tag centre in pixels.
 * 3D mode (calibration with 2+ cameras): the state is the world position (calibration units, mm);
 * a marker's detections are gated per camera against the projected prediction, the accepted ones
 * triangulated (camera.h), and the filter updated with the triangulated point; estimates are
 * back-projected into every camera.
 *
 * Per frame:
 *   sh_tracker_predict(t, frame)              advance every filter to `frame`
 *   sh_tracker_windows(t, cam, ...)           where the detector should look in camera cam
 *   sh_tracker_reacquire(t, cam, ...)         the strip of the frame to scan for lost markers
 *   sh_tracker_rescan(t, cam, ...)            whether the windows missed most markers
 *   sh_tracker_update(t, detections...)       gate, flag duplicates, update, report
 *   sh_tracker_estimates(t, ...)              positions with covariance, age and status
 * Nothing allocates after sh_tracker_create. */
#ifndef STILLHEART_TRACK_H
#define STILLHEART_TRACK_H

#include "stillheart/calib.h"
#include "stillheart/detect.h"

#ifdef __cplusplus
extern "C" {
#endif

#define SH_TRACK_MAX_MARKERS 64
#define SH_TRACK_MAX_CAMERAS SH_CALIB_MAX_CAMERAS
#define SH_TRACK_MAX_HEART_HARMONICS 4
#define SH_TRACK_MAX_RESP_HARMONICS 2
#define SH_TRACK_MAX_DETECTIONS 256 /* per camera per frame */
#define SH_TRACK_HISTORY 512        /* samples kept per marker for rate estimation */

typedef enum {
    SH_SPATIAL_OFF = 0,  /* occluded markers from their own filter only (time) */
    SH_SPATIAL_FUSE = 1  /* plus the displacement of visible neighbours (space), fused */
} sh_spatial_mode;

typedef struct {
    double fps;              /* frame rate (required) */
    int width, height;       /* image size (windows are clipped to it; required) */
    const int *ids;          /* the marker ids to track (copied); NULL: any id seen, confirmed
                              * once seen for a second unless its motion is evidence that it is
                              * not on the heart (sh_tracker_judge_ids, every half second: a
                              * confirmation is withdrawn when the evidence comes later) */
    int num_ids;
    int heart_harmonics;     /* 1..SH_TRACK_MAX_HEART_HARMONICS (default 3) */
    int resp_harmonics;      /* 0..SH_TRACK_MAX_RESP_HARMONICS (default 1) */
    double heart_min_hz, heart_max_hz; /* default 0.6 .. 3.5 */
    double resp_min_hz, resp_max_hz;   /* default 0.1 .. 0.55 */
    double meas_sigma;       /* detection noise per pixel coordinate, px (default 0.3) */
    double q_base;           /* baseline random walk, px / sqrt(s) (default 0.3) */
    double q_harm;           /* harmonic coefficient random walk, px / sqrt(s) (default 0.2) */
    double accel;            /* before lock: white acceleration, px / s^2 (default 1500) */
    double gate;             /* Mahalanobis^2 gate per camera (chi^2, 2 dof; default 16) */
    double max_reproj;       /* 3D: largest reprojection error of a triangulation, px (default 3) */
    double lost_after;       /* seconds unseen before a marker is lost (default 2) */
    double min_motion;       /* auto ids: the RMS motion (px) a tag's neighbours must predict for
                              * it before its not following them counts (default 0.3) */
    double window_sigmas;    /* window half-size = tag extent + this x sigma (default 4) */
    int min_window;          /* smallest window side, px (default 48) */
    int reacquire_bands;     /* full frame scanned in this many bands, one per frame (default 4) */
    sh_spatial_mode spatial; /* default SH_SPATIAL_FUSE */
    double camera_px;        /* a motion the model did not expect, rigid in the image and at least
                              * this large in one frame, is the camera's (sh_track_motion.camera);
                              * 0 (default): 0.4 % of the image diagonal, at least 2 px */
} sh_track_options;

void sh_track_options_default(sh_track_options *o);

typedef enum {
    SH_TRACK_NEW = 0,      /* never seen */
    SH_TRACK_MEASURED,     /* updated with a detection this frame */
    SH_TRACK_PREDICTED,    /* not seen this frame; estimate from the model (age > 0) */
    SH_TRACK_LOST          /* unseen longer than lost_after: no estimate is reported */
} sh_track_status;

typedef struct {
    int id;
    sh_track_status status;
    int confirmed;             /* reported as a correspondence (auto ids: judged on the heart) */
    int dim;                   /* 2 or 3 */
    double pos[3];             /* 2D: x, y (px); 3D: X, Y, Z (calibration units) */
    double cov[9];             /* dim x dim covariance of pos */
    double xy[SH_TRACK_MAX_CAMERAS][2]; /* image position per camera (3D: back-projected) */
    int in_view[SH_TRACK_MAX_CAMERAS];  /* xy valid (in front of the camera) */
    int age;                   /* frames since the last accepted detection */
    int seen;                  /* frames with an accepted detection in all */
    int spatial;               /* this frame's estimate used the neighbours (spatial model) */
    /* this frame's detection of it in camera c when it is evidence: a single well-shaped quad
     * that was used, or that agrees with the other markers' detections (what a safety gate
     * compares the estimates with, even when the tracker did not use it) */
    int det_ok[SH_TRACK_MAX_CAMERAS];
    double det_xy[SH_TRACK_MAX_CAMERAS][2];
} sh_track_estimate;

/* What the detections of this frame said that the motion model did not expect
 * (sh_tracker_motion; docs/tracking.md). */
typedef struct {
    int agreed;           /* markers whose detections agree with each other (0: not judged) */
    int jumped;           /* of them, outside their own gate: taken all the same (their
                           * baseline's variance raised) */
    int surface;          /* at least half of those that agree jumped: the whole surface moved */
    int camera;           /* they moved by one translation of the image: the camera moved, not
                           * the heart */
    double shift_px;      /* that translation's length, output camera pixels (camera = 1) */
    double rigid_left_px; /* RMS of what the translation leaves of their motion, px */
} sh_track_motion;

typedef struct {
    long frames;
    long accepted;      /* detections used (per camera) */
    long gated;         /* detections rejected by the gate (per camera) */
    long duplicates;    /* detections of an id seen twice in one camera's frame (never used) */
    long unknown;       /* detections of ids not tracked (decoys, ids outside the list) */
    long inconsistent;  /* 3D: triangulations rejected for reprojection error */
    long lost;          /* markers that became lost */
    int locked;         /* rates estimated */
    double heart_hz, resp_hz; /* current estimates (0 when none) */
    long misshapen;     /* detections refused for their quad's shape (a partly hidden tag whose
                         * corners an occluder moved: docs/tracking.md) */
    long held;          /* detections of a lost or suspect marker held back until two more agree
                         * with them (docs/tracking.md) */
    long jumped;        /* detections outside their own gate taken because the other markers'
                         * detections agree with them (a motion the model did not expect) */
    long camera_moves;  /* frames whose unexpected motion was a rigid motion of the image */
} sh_track_stats;

typedef struct sh_tracker sh_tracker;

/* calib: NULL (or one camera) for 2D tracking in pixels; 2+ cameras for 3D tracking. The
 * calibration is copied. */
sh_status sh_tracker_create(const sh_track_options *opts, const sh_calib *calib, sh_tracker **out);
void sh_tracker_destroy(sh_tracker *t);

int sh_tracker_dim(const sh_tracker *t);
int sh_tracker_num_cameras(const sh_tracker *t);

/* Advances every filter to frame index `frame` (>= the last one; the first call sets time 0). */
sh_status sh_tracker_predict(sh_tracker *t, int frame);

/* Search windows for camera cam around the current predictions of every tracked, not lost marker,
 * sized from the prediction's covariance and the marker's apparent size. At most max written. */
sh_status sh_tracker_windows(const sh_tracker *t, int cam, sh_window *out, int max, int *count);

/* The part of camera cam's frame to scan at full frame this frame, when some marker is lost or
 * not yet acquired (or, with auto ids, always): the frame in reacquire_bands overlapping bands,
 * one per frame in turn. *count = 0 or 1. */
sh_status sh_tracker_reacquire(sh_tracker *t, int cam, sh_window *out, int *count);

/* 1 when camera cam's detections in the windows (det, n) hold fewer than half of the tracked
 * markers the windows were for (at least 3 of them): the scene moved further than the windows
 * reach (a bumped endoscope), and the caller should detect in the whole frame instead. */
int sh_tracker_rescan(const sh_tracker *t, int cam, const sh_detection *det, int n);
/* The smallest side (mean of its four) of the tracked markers' last accepted quads in camera cam,
 * px; 0 before any (sh_detector_set_tag_side: the detector's decimation follows it). */
double sh_tracker_tag_side(const sh_tracker *t, int cam);

/* Updates with this frame's detections: det[c] (count[c] entries) for camera c < num_cameras.
 * Must follow sh_tracker_predict for the same frame. */
sh_status sh_tracker_update(sh_tracker *t, const sh_detection *const *det, const int *count,
                            int num_cameras);

/* Every marker the tracker knows (lost ones included, with status SH_TRACK_LOST), in id order. */
int sh_tracker_estimates(const sh_tracker *t, sh_track_estimate *out, int max);

void sh_tracker_stats(const sh_tracker *t, sh_track_stats *stats);
/* A rate of the stats for people: "1.167 Hz", or "not estimated yet" for 0 (no estimate), never
 * a made-up "0.000 Hz". */
void sh_track_rate_text(double hz, char *out, size_t cap);

/* Auto ids: which of the tags seen so far are markers on the heart, and why a tag is not.
 * The heart's surface is smooth, so each tag's motion over the history (the last 8 s or more) is
 * compared with the motion its neighbours predict for it (their displacements weighted by
 * distance). A tag seen consistently is kept unless that is evidence against it: it stays still
 * while its neighbours move, or it moves in a way theirs does not explain (with an instrument):
 * the surface stretches and turns between tags, so a heart tag's motion is a linear map of its
 * neighbours' (other amplitude, other direction), but in step with it.
 * "Still" is a motion not measurable above its detections' noise while its neighbours' is 4x
 * larger: a heart tag moving a fifth as much as its neighbours, in step, is kept. With too few
 * other tags, or too little motion (around it, or of its own when that is not evidence), nothing
 * can be compared: it is kept, and the verdict says so. docs/tracking.md has the thresholds and why. */
typedef enum {
    SH_TRACK_ID_KEPT = 0,   /* moves as its neighbours predict */
    SH_TRACK_ID_UNJUDGED,   /* kept: its neighbours move too little (or too rarely at the same
                             * time) to tell */
    SH_TRACK_ID_QUIET,      /* kept: it hardly moves itself, but neither do its neighbours 4x more */
    SH_TRACK_ID_ALONE,      /* kept: fewer than 3 other tags seen consistently to compare with */
    SH_TRACK_ID_RARE,       /* left out: seen in too few frames (a misread id, a glimpse) */
    SH_TRACK_ID_STILL,      /* left out: still while its neighbours move */
    SH_TRACK_ID_UNLIKE      /* left out: moves unlike its neighbours */
} sh_track_id_verdict;

typedef struct {
    int id;
    int keep;               /* a marker on the heart (KEPT, UNJUDGED, QUIET, ALONE) */
    sh_track_id_verdict verdict;
    int seen, frames;       /* frames of the history with a detection of it, of its frames
                             * (counted in history samples: above 64 fps, one every few frames) */
    double motion_px;       /* RMS of its own motion, px */
    double predicted_px;    /* RMS of the motion its neighbours predict for it, px (0: none) */
    double noise_px;        /* its detections' noise per coordinate, px (from second differences) */
    double explained;       /* share of its motion's variance above the noise that a linear map of
                             * the predicted motion explains (R^2; 0: none) */
} sh_track_id;

/* Every tag the tracker knows, in id order, at most max; returns how many were written. With
 * an id list every listed marker is kept (verdict KEPT) unjudged. Reads only: callable any time. */
int sh_tracker_judge_ids(const sh_tracker *t, sh_track_id *out, int max);
/* One line for people: why a tag was kept or left out ("still (0.03 px) while its neighbours
 * move 3.30 px"). */
void sh_track_id_text(const sh_track_id *v, char *out, size_t cap);

/* The unexpected motion of the last updated frame (all zero when there was none). */
void sh_tracker_motion(const sh_tracker *t, sh_track_motion *out);

/* 3D: how well the calibration fits what the cameras see, over the last 256 markers detected
 * once by two or more cameras in a frame, each triangulated from all of its views before any gate
 * (src/track/calcheck.c says why before). A correct calibration leaves the detector's noise; a
 * wrong one (swapped cameras, a moved camera, another rig's file) leaves pixels. All zero, and
 * worst_camera -1, in 2D or before the first such marker. */
typedef struct {
    int samples;        /* markers in the window */
    double median_px;   /* median of their RMS reprojection errors (INFINITY when most of them
                         * triangulate behind a camera or not at all) */
    int worst_camera;   /* the camera whose views' median reprojection error is largest (its
                         * own median, over the markers it saw) */
    double worst_px;    /* that median */
    double failed;      /* fraction of them with no point in front of every camera */
} sh_track_calibration;
void sh_tracker_calibration(const sh_tracker *t, sh_track_calibration *out);

#ifdef __cplusplus
}
#endif
#endif
