/* Private to the daemon (src/daemon): one frame's processing (run_proc.c), between the source
 * (run_source.h) and the sinks: markers, reference, gate, model, warp. */
#ifndef STILLHEART_RUN_PROC_H
#define STILLHEART_RUN_PROC_H

#include "run_source.h"
#include "stillheart/display.h"

typedef struct run_proc run_proc;

/* What the frame size decides of a 2D config (docs/daemon.md, "What a config must imply"): the
 * [method] makes a model from [gating] min_markers markers spread evenly over width x height
 * frames, the most favourable layout they allow; SH_EINVAL naming the key and where it was set
 * when it does not (a Gaussian so wide that the system is singular). run_proc_create checks it;
 * a reload that changes only gating keys calls it itself. */
sh_status run_proc_check(const sh_config *cfg, const sh_y4m_header *hdr);
/* Tracker and detector from [detect], models from [method] (built on a helper thread), markers
 * from [run] points in test mode. fps: the stream's (0: 30). With [method] calibration (as many
 * cameras as configured, 2+): tracking in 3D over every camera's frames and warp3d. */
sh_status run_proc_create(const sh_config *cfg, const sh_y4m_header *hdr, double fps, int cameras, run_proc **out);
void run_proc_destroy(run_proc *p);
/* The frames run_proc_frame returns: the output camera's geometry, or with [method] view =
 * stereo the layout's frame of two eyes ([method] layout). The sinks are made for these. */
const sh_y4m_header *run_proc_header(const run_proc *p);
/* SIGHUP: the keys of effect SH_CONFIG_GATING ([sink] outside among them) take effect from the
 * next frame. */
void run_proc_set_gating(run_proc *p, const sh_config *cfg);
/* The next frame with at least min_markers detected markers becomes the reference (its models
 * are built beside the running ones and swapped in when ready). */
void run_proc_request_reference(run_proc *p);
/* Processes one frame (img: the output camera's; cams: every camera's frame of the set, NULL
 * where missing, read in 3D only; index and epoch as in run_frame): returns what to show (img itself when raw,
 * in stereo img in each eye's place) and fills info's status,
 * reason, markers_used and residual_px (-1 when not measured; never NaN). The returned image
 * stays valid until the next call. */
const sh_image *run_proc_frame(run_proc *p, const sh_image *img, const sh_image *const *cams, int index,
                               unsigned epoch, sh_display_frame_info *info);
int run_proc_builds(const run_proc *p);
int run_proc_refined(const run_proc *p);
/* 1 while the tracker's rates are locked; 0 before, and always in test mode (no tracker). */
int run_proc_locked(const run_proc *p);
/* The markers (ids and output-camera positions) the last frame's map was made from, then the
 * landmarks it used (ids from SH_LANDMARK_ID_BASE): their count, 0 when that frame was shown raw.
 * Valid until the next run_proc_frame. */
int run_proc_markers(const run_proc *p, const int **ids, const double **xy);
/* The processing thread's CPU time in the last frame's stages, ms (the warp's helper threads
 * not counted): markers (detection and tracker), model (selection,
 * model lookup, map update, residual), warp (with [sink] outside's fill; 0 when not warped). */
void run_proc_times(const run_proc *p, double *markers_ms, double *model_ms, double *warp_ms);
/* [track] landmarks: the last frame's accepted landmarks and the CPU ms their stage took (the
 * prediction, the search and the tests; not in model_ms); 0 and 0 without landmarks. */
void run_proc_landmarks(const run_proc *p, int *accepted, double *ms);

#endif
