/* Private to the daemon (src/daemon): the markers of a frame from the Kalman tracker, and the
 * selection of the ones matched to the reference (run_track.c). */
#ifndef STILLHEART_RUN_TRACK_H
#define STILLHEART_RUN_TRACK_H

#include <stddef.h>
#include "stillheart/calib.h"
#include "stillheart/config.h"
#include "stillheart/image.h"
#include "stillheart/points.h"
#include "stillheart/track.h"

/* ---- markers and gate (run_track.c) ---- */
/* One frame's marker as processing needs it: its position, this frame's detection, how uncertain
 * and how old it is (the selection's dropout rule). Two marker types cross the daemon, for this
 * reason: run_marker carries that tracking state, sh_point (points.h) is a bare position with its
 * frame, which is what a points file holds and what a reference is (run_model.c keys its models by
 * sh_point sets; a reference has no age or uncertainty). The tracker's sh_track_estimate (per-camera
 * views, full covariance) stays inside run_track.c, converted once into run_marker there; a points
 * file's rows become run_markers in run_proc.c (detected this frame, uncertainty 0). */
typedef struct {
    int id;
    double x, y;      /* camera 0 pixels */
    double dx, dy;    /* the detection this frame (NaN when not detected) */
    double sigma;     /* 1-sigma position uncertainty, px (largest axis; 0 from a points file) */
    int age;          /* frames since it was last detected (0: this frame) */
    double X, Y, Z;   /* 3D: world position, mm (calibration units) */
} run_marker;

typedef struct run_tracker run_tracker;
/* cfg: [detect] family and ids (at most SH_TRACK_MAX_MARKERS ids); fps 0: 30. calib: NULL for 2D, or
 * 2+ cameras for 3D tracking over every camera's frames (out_cam: the one whose pixels count). */
sh_status run_tracker_create(const sh_config *cfg, const sh_calib *calib, int out_cam, int width, int height,
                             double fps, run_tracker **out);
void run_tracker_destroy(run_tracker *t);
/* Detects in each camera's frame (cams[c], NULL when the set lacks it; 2D: cams[0] only) in the
 * tracker's windows plus a reacquisition band (the whole frame when nothing is tracked),
 * updates the filters and writes every confirmed, not lost marker in the output camera's view,
 * sorted by id. index: the frame's index in the stream; an index that does not advance (a restarted
 * camera) or a new epoch (a discontinuity, run_frame) restarts the tracker. */
sh_status run_tracker_frame(run_tracker *t, const sh_image *const *cams, int index, unsigned epoch, run_marker *out,
                            int *n);
/* The output camera's detections of the last frame (their count; 0 before the first). */
int run_tracker_detections(const run_tracker *t, const sh_detection **out);
/* What the last frame's detections said that the motion model did not expect (a moved camera). */
void run_tracker_motion(const run_tracker *t, sh_track_motion *out);
/* 3D: how well the calibration fits what the cameras see (sh_tracker_calibration). */
void run_tracker_calibration(const run_tracker *rt, sh_track_calibration *out);
/* The frame rate the tracker assumes (ages in ms use it). */
double run_tracker_fps(const run_tracker *t);
/* 1 while the tracker's heart (and respiration) rates are locked (sh_track_stats.locked). */
int run_tracker_locked(const run_tracker *t);
/* One line of the tracker's counters (sh_tracker_stats), for the log at exit. */
void run_tracker_summary(const run_tracker *t, char *out, size_t cap);

typedef struct {
    int ids[SH_TRACK_MAX_MARKERS];
    double xy[2 * SH_TRACK_MAX_MARKERS];
    double det[2 * SH_TRACK_MAX_MARKERS]; /* their detections (NaN: predicted) */
    double xyz[3 * SH_TRACK_MAX_MARKERS]; /* 3D: their world positions */
    int n;            /* markers matched to the reference and used */
    int predicted;    /* of them, not detected this frame (age > 0) */
    int stale;        /* matched but unseen longer than dropout_ms: left out */
    int worst_id;     /* the most uncertain used marker */
    double worst_sigma;
} run_selection;

/* Matches the markers to the reference: a marker unseen for more than dropout_ms (age / fps)
 * leaves the set. */
void run_select(const sh_config *cfg, double fps, const sh_point *ref, int nref, const run_marker *m,
                int nm, run_selection *sel);

#endif
