/* Private to the daemon (src/daemon): models per marker set built on a helper thread, with their
 * leave-one-out residual (run_model.c). */
#ifndef STILLHEART_RUN_MODEL_H
#define STILLHEART_RUN_MODEL_H

#include <stddef.h>
#include "stillheart/calib.h"
#include "stillheart/core.h"
#include "stillheart/interp.h"
#include "stillheart/landmarks.h"
#include "stillheart/points.h"
#include "stillheart/track.h"
#include "stillheart/warp.h"
#include "stillheart/warp3d.h"

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
 * which is also the one whose frames are warped; with baseline > 0 (mm) seen instead by the two
 * eyes of a stereo pair around it (sh_warp3d_stereo_cameras). */
sh_status run_models_set_3d(run_models *m, const sh_calib *calib, int camera, double baseline);
void run_models_destroy(run_models *m);
/* Natural landmarks (issue 19, landmarks.h; before the first reference, after run_models_set_3d):
 * with lp->max_points > 0 every new reference chooses up to that many landmarks in its frame (on
 * the helper thread, after its markers' full-set model live, before it in test mode: a corner
 * search takes tens of ms; run_models_poll says when they come; in 3D
 * chosen in the output camera's frame, matched in the others' and triangulated:
 * sh_landmarks_rig), and every model of that reference holds them after its markers, ids
 * SH_LANDMARK_ID_BASE + k (in 3D only the k triangulated in the reference), so that a frame uses
 * any subset of them without a new model (run_model_update's use). smoothing: the landmark rows'
 * own in a 2D RBF map ([track] landmarks_smoothing, sh_interp_create_smoothed). */
void run_models_set_landmarks(run_models *m, const sh_landmarks_params *lp, double smoothing);
#define RUN_MAX_LANDMARKS 2000 /* [track] landmarks' bound (config.c) */
/* Requests a new reference (markers sorted by id, n <= SH_TRACK_MAX_MARKERS); its full-set model is
 * built first. A reference still being built is replaced. frame: for the log. With landmarks:
 * luma, the reference frame's luma plane (2D: luma[0]; 3D: one per calibration camera, NULL for
 * one whose frame is missing), and tags (ntags quads, 8 doubles each: the output camera's
 * markers' corners, which landmarks keep off) are copied; otherwise they may be NULL. */
sh_status run_models_set_reference(run_models *m, const sh_point *ref, int n, int frame, const sh_plane *const *luma,
                                   const double *tags, int ntags);
/* The reference in use's landmarks, NULL when it has none (none asked, none found, or their
 * choice failed: run_models_landmarks_note says why); for the processing thread alone. */
sh_landmarks *run_models_landmarks(run_models *m);
/* The same in 3D: the rig's (its landmark k is id SH_LANDMARK_ID_BASE + k of the models). */
sh_landmarks_rig *run_models_rig(run_models *m);
/* Why the reference in use has no landmarks though they were asked for: the note that came with
 * run_models_poll's RUN_MODELS_NO_LANDMARKS ("" otherwise). */
const char *run_models_landmarks_note(const run_models *m);
/* What run_models_poll swapped in (bits). Live, with landmarks, a new reference comes first with
 * its markers alone (REFERENCE: run_models_landmarks NULL), so that its frames are stabilized while
 * its landmarks are chosen on the helper (tens of ms at 1080p), and then again with them
 * (LANDMARKS: the same reference, frame and markers), or NO_LANDMARKS when none could be had. In
 * test mode a reference comes with its landmarks (REFERENCE alone, or with NO_LANDMARKS). A model
 * run_models_get gave before a LANDMARKS swap stays valid until the next REFERENCE. */
enum { RUN_MODELS_REFERENCE = 1, RUN_MODELS_LANDMARKS = 2, RUN_MODELS_NO_LANDMARKS = 4 };
/* Swaps in a new reference once its full-set model is built, or the landmarks of the one in use
 * once theirs is: the RUN_MODELS_* bits of what it did (and the reference's frame and marker
 * count), 0 when nothing. */
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
 * marker not detected, and for every landmark). *residual is -1 when no marker was detected, NaN
 * if the map cannot be evaluated at a marker. use: NULL, or per point whether the map goes
 * through it (a landmark refused this frame is left out). warp: the executor whose
 * threads share a 2D grid's nodes (sh_warp_update), or NULL for this thread alone. */
sh_status run_model_update(run_model *md, sh_warp *warp, const double *cur_xy, const double *cur_xyz,
                           const double *det_xy, const unsigned char *use, double *residual);
/* The model's markers: the first run_model_markers(md) of its ids (the rest are landmarks), and
 * the reference positions of all its points (2 n doubles, the ids' order). */
int run_model_markers(const run_model *md);
const double *run_model_ref_xy(const run_model *md);
/* The map a frame is warped with: the 2D model's, or the first 3D view's. */
const sh_warp_model *run_model_warp(const run_model *md);
/* 3D: the model's views (views[v] NULL past their count): 1, the output camera's own, or 2, the
 * left and right eyes. 0 in 2D. */
int run_model_views(const run_model *md, const sh_warp3d_view *views[2]);
const int *run_model_ids(const run_model *md, int *n);
int run_models_builds(const run_models *m);
/* Live: how many models were swapped for one on a finer grid built by the helper (refine_swap). */
int run_models_refined(const run_models *m);
/* The residual alone, on a model built here (tests). */
sh_status run_residual(const sh_interp_params *params, const double *ref_xy, const double *cur_xy,
                       const double *det_xy, int n, double *residual);

#endif
