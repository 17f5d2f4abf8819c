/* Private to stillheart run: the processing side of the daemon (run_model.c: models per marker
 * set built on a helper thread, with their leave-one-out residual; run_track.c: the markers of a
 * frame from the Kalman tracker and the safety gate; run_ctl.c: the control socket; run_sink.c:
 * recording what was shown). The source side is run_source.h. */
#ifndef STILLHEART_RUN_H
#define STILLHEART_RUN_H

#include <stddef.h>
#include <stdint.h>

#include "stillheart/calib.h"
#include "stillheart/config.h"
#include "stillheart/detect.h"
#include "stillheart/image.h"
#include "stillheart/interp.h"
#include "stillheart/points.h"
#include "stillheart/track.h"
#include "stillheart/warp.h"
#include "stillheart/y4m.h"
#include "run_source.h" /* run_log_fn */

#define RUN_MAX_MARKERS SH_TRACK_MAX_MARKERS /* the tracker's limit */

/* ---- models (run_model.c) ----
 * Everything that depends on the reference (the interpolant, the warp's grid basis, and the n
 * leave-one-out interpolants of the residual) is built on a helper thread. The processing thread
 * asks for the model of a marker set and gets it when it is ready; a new reference is built
 * beside the running one and swapped in by run_models_poll, so frames keep being published with
 * the old reference meanwhile. With wait = 1 every request blocks until built (deterministic
 * output: the test mode that must equal `stillheart warp` frame for frame). */
typedef struct run_models run_models;
typedef struct run_model run_model;

sh_status run_models_create(const sh_interp_params *params, const sh_warp_options *wopts, int width,
                            int height, int wait, run_models **out);
/* 3D (before the first reference): models are warp3d surfaces over the markers' world positions
 * (params: the interpolant of surface and displacement), seen by calibration camera `camera`,
 * which is also the one whose frames are warped. */
sh_status run_models_set_3d(run_models *m, const sh_calib *calib, int camera);
void run_models_destroy(run_models *m);
/* Requests a new reference (markers sorted by id, n <= RUN_MAX_MARKERS); its full-set model is
 * built first. A reference still being built is replaced. frame: for the log. */
sh_status run_models_set_reference(run_models *m, const sh_point *ref, int n, int frame);
/* Swaps in a new reference once its full-set model is built: returns 1 (and its frame and
 * marker count) when it did, 0 otherwise. */
int run_models_poll(run_models *m, int *frame, int *n);
/* 1 while a new reference is being built (the old one is still in use). */
int run_models_pending(run_models *m);
/* The reference in use (NULL and n = 0 before the first one is swapped in). */
const sh_point *run_models_reference(const run_models *m, int *n);
/* The model for ids (sorted, a subset of the reference's): 1 ready (*out set), 0 being built,
 * -1 its build failed (sh_error_message says why, once). */
int run_models_get(run_models *m, const int *ids, int n, run_model **out);
/* Map for the current positions cur_xy (n points in the model's id order, x0,y0,x1,y1,...) and
 * the residual: the largest distance, over the markers detected this frame, between where the
 * map puts the marker's reference position and where the detector saw it (det_xy; NaN for a
 * marker not detected). *residual is -1 when no marker was detected, NaN if the map cannot be
 * evaluated at a marker. */
sh_status run_model_update(run_model *md, const double *cur_xy, const double *cur_xyz, const double *det_xy,
                           double *residual);
const sh_warp_model *run_model_warp(const run_model *md);
const int *run_model_ids(const run_model *md, int *n);
int run_models_builds(const run_models *m);
/* The residual alone, on a model built here (tests). */
sh_status run_residual(const sh_interp_params *params, const double *ref_xy, const double *cur_xy,
                       const double *det_xy, int n, double *residual);

/* ---- markers and gate (run_track.c) ---- */
typedef struct {
    int id;
    double x, y;      /* camera 0 pixels */
    double dx, dy;    /* the detection this frame (NaN when not detected) */
    double sigma;     /* 1-sigma position uncertainty, px (largest axis; 0 from a points file) */
    int age;          /* frames since it was last detected (0: this frame) */
    double X, Y, Z;   /* 3D: world position, mm (calibration units) */
} run_marker;

typedef struct run_tracker run_tracker;
/* cfg: [detect] family and ids (at most RUN_MAX_MARKERS ids); fps 0: 30. calib: NULL for 2D, or
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
/* What the last frame's detections said that the motion model did not expect (a moved camera). */
void run_tracker_motion(const run_tracker *t, sh_track_motion *out);
/* 3D: how well the calibration fits what the cameras see (sh_tracker_calibration). */
void run_tracker_calibration(const run_tracker *rt, sh_track_calibration *out);
/* The frame rate the tracker assumes (ages in ms use it). */
double run_tracker_fps(const run_tracker *t);
/* One line of the tracker's counters (sh_tracker_stats), for the log at exit. */
void run_tracker_summary(const run_tracker *t, char *out, size_t cap);

typedef struct {
    int ids[RUN_MAX_MARKERS];
    double xy[2 * RUN_MAX_MARKERS];
    double det[2 * RUN_MAX_MARKERS]; /* their detections (NaN: predicted) */
    double xyz[3 * RUN_MAX_MARKERS]; /* 3D: their world positions */
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

/* ---- control socket (run_ctl.c) ----
 * A local UNIX stream socket served by a thread of its own: one command line per connection
 * ("reference", "status"), one reply line. Rights come from the peer's credentials: root and the
 * service's uid may do anything, control_group members "reference" and "status", display_group
 * members "status" ("" control group: none; "" display group: the process's group). Every
 * answered or refused command is logged with the peer's uid and pid. */
typedef struct run_ctl run_ctl;
enum { RUN_CTL_BAD = 0, RUN_CTL_STATUS = 1, RUN_CTL_REFERENCE = 2, RUN_CTL_REFUSED = 4 };
sh_status run_ctl_open(const char *path, const char *control_group, const char *display_group, run_ctl **out);
void run_ctl_close(run_ctl *c);
/* New groups for a running socket (a reload); an unknown group is refused, the old ones kept. */
sh_status run_ctl_groups(run_ctl *c, const char *control_group, const char *display_group);
/* The line "status" is answered with from now on. */
void run_ctl_set_status(run_ctl *c, const char *status_line);
/* "reference" requests accepted since the last call. */
int run_ctl_references(run_ctl *c);
/* One command (data: len bytes, up to the first newline) from a peer with rights (RUN_CTL_STATUS |
 * RUN_CTL_REFERENCE) -> reply (one printable line, NUL-terminated). Returns RUN_CTL_REFERENCE or
 * RUN_CTL_STATUS for a command carried out, RUN_CTL_REFUSED for one the rights do not allow,
 * RUN_CTL_BAD for anything else. */
int run_ctl_command(const char *data, size_t len, int rights, const char *status_line, char *reply, size_t cap);

/* ---- recording what was shown (run_sink.c): y4m FILE, FILE.y4m or png:DIR ---- */
typedef struct run_record run_record;
/* Never over an earlier recording: the first free name of spec, spec-2, spec-3, ...
 * (run_record_path); a Y4M file is flushed every sync_ms and made durable beside. */
sh_status run_record_open(const char *spec, const sh_y4m_header *hdr, int sync_ms, run_record **out);
const char *run_record_path(const run_record *r);
sh_status run_record_write(run_record *r, const sh_image *shown);
/* Frames the PNG writer could not keep up with (not recorded). */
uint64_t run_record_skipped(const run_record *r);
/* Writes what is queued, closes; an error when a file could not be written. */
sh_status run_record_close(run_record *r);

#endif
