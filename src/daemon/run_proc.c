/* The daemon's processing of one frame: markers (tracker or points file), reference, selection,
 * model, gate, warp. docs/daemon.md ("Safety gating") is the specification of the gate. Over 600
 * lines: the gate is one sequence over one frame's state (the markers, the reference, the models,
 * the landmarks, the frame carried from the one before), each step reading what the steps before
 * left in run_proc; split into files, each would take the whole struct and the others' helpers. */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "run_model.h"
#include "run_track.h"
#include "run_proc.h"
#include "stillheart/detect.h"
#include "stillheart/landmarks.h"
#include "stillheart/log.h"

struct run_proc {
    sh_config cfg;
    run_models *models;
    run_tracker *tracker; /* NULL in test mode (points file) */
    sh_points points;
    sh_warp *warp;
    sh_warp_outside *outside[2]; /* [sink] outside = dimmed-raw (one per eye): made at start, as a reload may turn it on */
    sh_image out;         /* what is shown when warped, and in stereo the raw frame in each eye's place */
    int out_kept;         /* out holds the warp's last output into it as the warp wrote it */
    sh_y4m_header out_hdr;/* the shown frames: the output camera's, or the stereo layout's */
    int stereo;           /* [method] view = stereo */
    sh_warp3d_layout layout;
    sh_image eye;         /* stereo, squeezed layouts: one eye at full size before it is halved */
    double fps;
    int want_ref;
    run_marker mk[SH_TRACK_MAX_MARKERS];
    int three_d, out_cam;
    sh_calib calib;
    run_model *last;      /* the last model used: the fallback while another set is built */
    sh_log_limit model_err, track_err; /* an error logged once until a frame goes through */
    unsigned epoch;       /* the last frame's (run_frame): a change restarts the tracker */
    double ms[3];         /* this frame: markers (detection + tracker), model update, warp */
    /* a moved camera (docs/daemon.md, "A moved endoscope"): raw while it moves, then a new
     * reference (or the old one) once it has been still for RUN_SETTLE_FRAMES frames */
    int moving, still, await_ref;
    int calib_off;        /* the calibration does not fit what the cameras see (logged once) */
    double moved_px;      /* largest one-frame motion of this episode */
    /* the markers (and landmarks) the last warped frame's map was made from (run_proc_markers);
     * room for SH_TRACK_MAX_MARKERS + lm_cap points */
    int used_n, *used_ids;
    double *used_xy;
    /* [track] landmarks (lm_cap 0: none): the model's points are its markers, then the
     * reference's landmarks; this frame's positions, detections and which are used */
    int lm_cap;
    sh_detector *lm_det;        /* test mode: the reference frame's tags (the tracker has them otherwise) */
    sh_image lm_gray[SH_CALIB_MAX_CAMERAS]; /* an RGB24 frame's luma (2D: [0]; 3D: each camera's) */
    float *lm_pred, *lm_xy;     /* lm_cap pairs */
    sh_interp_mapper *lm_map;   /* 2D: the markers' TPS predicting them (built again per marker set) */
    uint8_t *lm_verdict;        /* lm_cap: the landmarks' verdicts, then 1 where used */
    double *lm_xyz;             /* 3D: lm_cap triples */
    double *all_xy, *all_det;   /* (SH_TRACK_MAX_MARKERS + lm_cap) pairs */
    double *all_xyz;            /* 3D: as many triples */
    unsigned char *all_use;
    long long lm_verdicts[SH_LANDMARK_VERDICTS];
    long long lm_unmatched, lm_inconsistent; /* 3D: sh_landmarks_rig_counts' */
    int lm_frames, lm_accepted; /* frames the landmarks were looked for in; this frame's accepted */
    int lm_ref_frame;           /* the frame the reference was taken from (-1: none yet) */
    int lm_found;               /* this frame's landmarks were searched in 2D (lm_xy, lm_verdict) */
    /* [gating] landmarks_carry (2D): the last frame stabilized with its landmarks found (-1: none),
     * the last frame processed that the chain from it reaches (lm_last, then each frame raw for its
     * markers with nothing to search: carried()), the last frame processed before this one and
     * this one; a carried frame's copy of the frame before's landmarks (lm_cap pairs, lm_cap); the
     * markers lm_last's map went through that were detected there, and where */
    int lm_last, chain, processed, current;
    float *carry_xy;
    uint8_t *carry_ok;
    int carry_n, carry_ids[SH_TRACK_MAX_MARKERS];
    double carry_det[2 * SH_TRACK_MAX_MARKERS];
    double lm_ms;               /* this frame's landmark stage, CPU ms */
    sh_log_limit lm_err;
};

#define RUN_SETTLE_FRAMES 2

/* This thread's CPU time: on a shared machine wall time mostly measures the neighbours. */
static double now_ms(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return (double)ts.tv_sec * 1e3 + (double)ts.tv_nsec / 1e6;
}

void run_proc_times(const run_proc *p, double *markers_ms, double *model_ms, double *warp_ms)
{
    *markers_ms = p->ms[0];
    *model_ms = p->ms[1];
    *warp_ms = p->ms[2];
}

void run_proc_landmarks(const run_proc *p, int *accepted, double *ms)
{
    *accepted = p->lm_accepted;
    *ms = p->lm_ms;
}

/* The buffers of [track] landmarks (and of the points a map is made from, which they join). */
static sh_status landmarks_create(run_proc *p, const sh_config *cfg, const sh_y4m_header *hdr)
{
    p->lm_cap = cfg->landmarks;
    size_t most = SH_TRACK_MAX_MARKERS + (size_t)p->lm_cap;
    p->used_ids = malloc(sizeof(int) * most);
    p->used_xy = malloc(sizeof(double) * 2 * most);
    if (!p->used_ids || !p->used_xy) return sh_error_set(SH_ENOMEM, "processing: out of memory");
    if (!p->lm_cap) return SH_OK;
    p->lm_pred = malloc(sizeof(float) * 2 * (size_t)p->lm_cap);
    p->lm_xy = malloc(sizeof(float) * 2 * (size_t)p->lm_cap);
    p->lm_verdict = malloc((size_t)p->lm_cap);
    p->carry_xy = malloc(sizeof(float) * 2 * (size_t)p->lm_cap);
    p->carry_ok = malloc((size_t)p->lm_cap);
    p->all_xy = malloc(sizeof(double) * 2 * most);
    p->all_det = malloc(sizeof(double) * 2 * most);
    p->all_use = malloc(most);
    if (p->three_d) {
        p->lm_xyz = malloc(sizeof(double) * 3 * (size_t)p->lm_cap);
        p->all_xyz = malloc(sizeof(double) * 3 * most);
    }
    if (!p->lm_pred || !p->lm_xy || !p->lm_verdict || !p->carry_xy || !p->carry_ok || !p->all_xy || !p->all_det ||
        !p->all_use || (p->three_d && (!p->lm_xyz || !p->all_xyz)))
        return sh_error_set(SH_ENOMEM, "processing: out of memory for %d landmarks", p->lm_cap);
    sh_interp_params tps;
    sh_interp_params_default(&tps, SH_METHOD_TPS);
    sh_status st = sh_interp_mapper_create(&tps, &p->lm_map);
    if (st != SH_OK) return st;
    sh_landmarks_params lp;
    if (cfg->landmarks_sparse)
        sh_landmarks_params_sparse(&lp);
    else
        sh_landmarks_params_default(&lp);
    lp.affine = cfg->landmarks_affine;
    lp.refine = cfg->landmarks_refine;
    if (cfg->landmarks_confirm) lp.confirm = cfg->landmarks_confirm;
    lp.max_points = p->lm_cap;
    lp.highlight = sh_landmarks_highlight_level(hdr->format, sh_y4m_header_full_range(hdr));
    run_models_set_landmarks(p->models, &lp, cfg->landmarks_smoothing);
    if (!cfg->points[0]) return SH_OK;
    sh_detector_options dopt;
    sh_detector_options_default(&dopt);
    dopt.family = cfg->family;
    return sh_detector_create(&dopt, &p->lm_det);
}

/* The most favourable layout of n markers a width x height frame allows (n >= 3): the centres of
 * a grid of cells as near square as the frame makes them, filled row by row. At least two rows
 * and two columns, so three or more points are never collinear. */
static void spread_layout(int n, int width, int height, double *xy)
{
    int cols = 2, rows = 2;
    while (cols * rows < n) {
        if ((double)width / (cols + 1) >= (double)height / (rows + 1)) cols++;
        else rows++;
    }
    for (int k = 0; k < n; k++) {
        xy[2 * k] = (k % cols + 0.5) * width / cols;
        xy[2 * k + 1] = (k / cols + 0.5) * height / rows;
    }
}

sh_status run_proc_check(const sh_config *cfg, const sh_y4m_header *hdr)
{
    if (cfg->calibration[0]) return SH_OK; /* 3D: the method interpolates over the surface, not these pixels */
    sh_interp_params method;
    sh_config_method(cfg, &method);
    int n = cfg->min_markers > 3 ? cfg->min_markers : 3; /* run_proc_frame makes no model from fewer */
    if (n > SH_TRACK_MAX_MARKERS) n = SH_TRACK_MAX_MARKERS;
    double xy[2 * SH_TRACK_MAX_MARKERS];
    spread_layout(n, hdr->width, hdr->height, xy);
    sh_interp *it = NULL;
    sh_status st = sh_interp_create(&method, xy, n, &it);
    sh_interp_destroy(it);
    if (st == SH_OK || st == SH_ENOMEM) return st;
    /* the key whose value decided: the kernel's scale, the lattice's levels, else the method */
    const char *key = method.method == SH_METHOD_GAUSSIAN || method.method == SH_METHOD_RBF_LOCAL ? "sigma"
                      : method.method == SH_METHOD_BSPLINE ? "levels" : "name";
    char where[SH_CONFIG_ERR], why[512];
    sh_config_where(cfg, "method", key, where, sizeof where);
    snprintf(why, sizeof why, "%s", sh_error_message());
    return sh_error_set(SH_EINVAL, "%s: no model on %dx%d frames, not even from [gating] min_markers = %d markers "
                        "spread evenly over the frame: %s", where, hdr->width, hdr->height, n,
                        strncmp(why, "interp ", 7) ? why : why + 7);
}

/* [method] layout's numbers are sh_warp3d_layout's (config.c's choices in the same order) */
_Static_assert(SH_WARP3D_SBS == 0 && SH_WARP3D_TB == 1 && SH_WARP3D_SBS_HALF == 2 && SH_WARP3D_TB_HALF == 3,
               "[method] layout: the config's choices follow sh_warp3d_layout");

/* The shown frames' header: the output camera's, or with [method] view = stereo the layout's frame
 * of two such eyes; a layout the frames cannot take is refused naming the key. */
static sh_status out_frames(run_proc *p, const sh_config *cfg, const sh_y4m_header *hdr)
{
    p->out_hdr = *hdr;
    p->stereo = p->three_d && cfg->view == SH_VIEW_STEREO;
    p->layout = (sh_warp3d_layout)cfg->layout;
    if (!p->stereo) return SH_OK;
    if (sh_warp3d_layout_size(p->layout, hdr->format, hdr->width, hdr->height, &p->out_hdr.width,
                              &p->out_hdr.height) == SH_OK)
        return SH_OK;
    char where[SH_CONFIG_ERR], why[512];
    snprintf(why, sizeof why, "%s", sh_error_message());
    sh_config_where(cfg, "method", "layout", where, sizeof where);
    return sh_error_set(SH_EINVAL, "%s: %dx%d camera frames: %s", where, hdr->width, hdr->height, why);
}

const sh_y4m_header *run_proc_header(const run_proc *p) { return &p->out_hdr; }

sh_status run_proc_create(const sh_config *cfg, const sh_y4m_header *hdr, double fps, int cameras,
                          run_proc **out)
{
    sh_status cst = run_proc_check(cfg, hdr);
    if (cst != SH_OK) return cst;
    run_proc *p = calloc(1, sizeof *p);
    if (!p) return sh_error_set(SH_ENOMEM, "processing: out of memory");
    p->cfg = *cfg;
    p->out_cam = cfg->output_camera;
    p->lm_ref_frame = -1;
    p->lm_last = p->chain = p->processed = p->current = -1;
    if (cfg->calibration[0]) {
        sh_status st = sh_calib_read(cfg->calibration, &p->calib);
        if (st == SH_OK && (p->calib.num_cameras < 2 || p->calib.num_cameras != cameras))
            st = sh_error_set(SH_EINVAL, "[method] calibration: %s has %d cameras, %d configured (3D needs the same "
                              "2 or more, [camera0] first)", cfg->calibration, p->calib.num_cameras, cameras);
        if (st == SH_OK && (p->calib.width != hdr->width || p->calib.height != hdr->height))
            st = sh_error_set(SH_EINVAL, "[method] calibration: %s is for %dx%d, the output camera gives %dx%d",
                              cfg->calibration, p->calib.width, p->calib.height, hdr->width, hdr->height);
        if (st != SH_OK) {
            if (st != SH_EINVAL) sh_error_set(st, "[method] calibration: %s", sh_error_message());
            free(p);
            return st;
        }
        p->three_d = 1;
    }
    p->fps = fps > 0 ? fps : 30;
    sh_warp_options wopts;
    sh_warp_options_default(&wopts);
    /* the spacing asked for is also the coarsest a TPS map goes back to (sh_warp_options) */
    if (cfg->grid > 0) wopts.grid_spacing = wopts.coarsest_spacing = (int)cfg->grid;
    sh_status st = out_frames(p, cfg, hdr);
    if (st == SH_OK) st = sh_image_create(&p->out, hdr->format, p->out_hdr.width, p->out_hdr.height);
    if (st == SH_OK && p->stereo && sh_warp3d_layout_half(p->layout))
        st = sh_image_create(&p->eye, hdr->format, hdr->width, hdr->height);
    /* test mode waits for every model: its output must equal `stillheart warp`'s frame by frame */
    sh_interp_params method;
    sh_config_method(cfg, &method);
    if (st == SH_OK) st = run_models_create(&method, &wopts, hdr->width, hdr->height, cfg->points[0] != 0, &p->models);
    if (st == SH_OK && p->three_d) st = run_models_set_3d(p->models, &p->calib, p->out_cam, p->stereo ? cfg->baseline : 0);
    if (st == SH_OK) st = sh_warp_create(cfg->threads, &p->warp);
    for (int v = 0; v < 1 + p->stereo && st == SH_OK; v++)
        st = sh_warp_outside_create(hdr->format, hdr->width, hdr->height, sh_y4m_header_full_range(hdr), &p->outside[v]);
    if (st == SH_OK && cfg->points[0]) {
        st = sh_points_read(cfg->points, &p->points);
        if (st == SH_OK) st = sh_points_need_2d(&p->points, cfg->points);
        if (st != SH_OK) st = sh_error_set(st, "[run] points: %s", sh_error_message());
    } else if (st == SH_OK) {
        st = run_tracker_create(cfg, p->three_d ? &p->calib : NULL, p->out_cam, hdr->width, hdr->height, p->fps,
                                &p->tracker);
    }
    if (st == SH_OK) st = landmarks_create(p, cfg, hdr);
    if (st != SH_OK) {
        run_proc_destroy(p);
        return st;
    }
    *out = p;
    return SH_OK;
}

void run_proc_destroy(run_proc *p)
{
    if (!p) return;
    if (p->tracker) {
        char line[320];
        run_tracker_summary(p->tracker, line, sizeof line);
        sh_log_info("%s", line);
    }
    if (p->lm_frames) {
        const long long *v = p->lm_verdicts;
        long long all = 0;
        for (int i = 0; i < SH_LANDMARK_VERDICTS; i++) all += v[i];
        sh_log_info("landmarks: %d frames, %lld landmark-frames: accepted %lld, lost %lld, photometric %lld, "
                    "backward %lld, disagrees %lld, deviates %lld, unconfirmed %lld", p->lm_frames, all,
                    v[SH_LANDMARK_ACCEPTED], v[SH_LANDMARK_LOST], v[SH_LANDMARK_PHOTOMETRIC],
                    v[SH_LANDMARK_BACKWARD], v[SH_LANDMARK_DISAGREES], v[SH_LANDMARK_DEVIATES],
                    v[SH_LANDMARK_UNCONFIRMED]);
        if (p->three_d)
            sh_log_info("landmarks in 3D: of the accepted, %lld matched by no other camera, %lld refused by the "
                        "reprojection test (%.1f px); the others triangulated and used", p->lm_unmatched,
                        p->lm_inconsistent, SH_LANDMARKS_MAX_REPROJ_PX);
    }
    sh_detector_destroy(p->lm_det);
    for (int c = 0; c < SH_CALIB_MAX_CAMERAS; c++) sh_image_destroy(&p->lm_gray[c]);
    free(p->lm_pred), free(p->lm_xy), free(p->lm_verdict), free(p->all_xy), free(p->all_det), free(p->all_use);
    free(p->lm_xyz), free(p->all_xyz), free(p->carry_xy), free(p->carry_ok);
    sh_interp_mapper_destroy(p->lm_map);
    free(p->used_ids), free(p->used_xy);
    run_models_destroy(p->models);
    run_tracker_destroy(p->tracker);
    sh_points_destroy(&p->points);
    sh_warp_destroy(p->warp);
    sh_warp_outside_destroy(p->outside[0]);
    sh_warp_outside_destroy(p->outside[1]);
    sh_image_destroy(&p->out);
    sh_image_destroy(&p->eye);
    free(p);
}

void run_proc_set_gating(run_proc *p, const sh_config *cfg)
{
    sh_config_copy_keys(&p->cfg, cfg, SH_CONFIG_GATING);
}

/* The reason field holds 43 characters: longer reasons are cut (the counts come first). */
static __attribute__((format(printf, 2, 3))) void reason(sh_display_frame_info *info, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(info->reason, sizeof info->reason, fmt, ap);
    va_end(ap);
}

void run_proc_request_reference(run_proc *p) { p->want_ref = 1; }

int run_proc_builds(const run_proc *p) { return run_models_builds(p->models); }
int run_proc_refined(const run_proc *p) { return run_models_refined(p->models); }

int run_proc_locked(const run_proc *p) { return p->tracker && run_tracker_locked(p->tracker); }

int run_proc_markers(const run_proc *p, const int **ids, const double **xy)
{
    *ids = p->used_ids;
    *xy = p->used_xy;
    return p->used_n;
}

/* The markers of this frame, sorted by id. */
static int markers(run_proc *p, const sh_image *img, const sh_image *const *cams, int index, unsigned epoch)
{
    int n = 0;
    if (!p->tracker) {
        int cnt;
        const sh_point *rows = sh_points_frame(&p->points, index, &cnt);
        for (int i = 0; i < cnt && n < SH_TRACK_MAX_MARKERS; i++) {
            const sh_point *r = &rows[i];
            /* a file of `stillheart track --landmarks` holds landmark rows: not markers ([track]
             * landmarks follows its own) */
            if (r->id >= SH_LANDMARK_ID_BASE) continue;
            if (!isfinite(r->x) || !isfinite(r->y) || (p->three_d && !(isfinite(r->X) && isfinite(r->Y) && isfinite(r->Z))))
                continue;
            p->mk[n] = (run_marker){.id = r->id, .x = r->x, .y = r->y, .dx = r->x, .dy = r->y, .sigma = 0, .age = 0,
                                    .X = r->X, .Y = r->Y, .Z = r->Z};
            n++;
        }
        return n;
    }
    const sh_image *only[1] = {img};
    if (epoch != p->epoch && !p->epoch)
        sh_log_info("frame %d: the replay started again and its scene jumps there (it is not tagged "
               "XLOOP=SEAMLESS): tracking starts afresh at every loop", index);
    p->epoch = epoch;
    if (run_tracker_frame(p->tracker, p->three_d ? cams : only, index, epoch, p->mk, &n) != SH_OK) {
        sh_log_limited(&p->track_err, SH_LOG_ERROR, "tracker: %s", sh_error_message());
        return 0;
    }
    sh_log_limit_clear(&p->track_err);
    return n;
}

/* Each camera's luma plane of this frame (2D: img's alone, into luma[0]; 3D: cams', NULL for a
 * missing one). */
static sh_status lumas(run_proc *p, const sh_image *img, const sh_image *const *cams, const sh_plane **luma)
{
    if (!p->three_d) return sh_landmarks_luma(img, &p->lm_gray[0], &luma[0]);
    sh_status st = SH_OK;
    for (int c = 0; c < p->calib.num_cameras && st == SH_OK; c++) {
        luma[c] = NULL;
        if (cams[c]) st = sh_landmarks_luma(cams[c], &p->lm_gray[c], &luma[c]);
    }
    return st;
}

/* With landmarks: the reference frame's luma planes and its tags' corners (the tracker's
 * detections of this frame in the output camera; in test mode a detection of the whole frame), for
 * run_models_set_reference. 0 when they cannot be had (logged): the reference waits for a later
 * frame. */
static int reference_frame(run_proc *p, const sh_image *img, const sh_image *const *cams, const sh_plane **luma,
                           double *tags, int *ntags)
{
    *ntags = 0;
    if (!p->lm_cap) return 1;
    sh_detection own[SH_TRACK_MAX_DETECTIONS];
    const sh_detection *d = own;
    int n = 0;
    sh_status st = lumas(p, img, cams, luma);
    if (st == SH_OK && p->tracker)
        n = run_tracker_detections(p->tracker, &d);
    else if (st == SH_OK)
        st = sh_detector_detect(p->lm_det, img, own, SH_TRACK_MAX_DETECTIONS, &n);
    if (st != SH_OK) {
        sh_log_limited(&p->lm_err, SH_LOG_ERROR, "reference: landmarks: %s", sh_error_message());
        return 0;
    }
    if (n > SH_TRACK_MAX_DETECTIONS) n = SH_TRACK_MAX_DETECTIONS;
    for (int i = 0; i < n; i++)
        for (int k = 0; k < 4; k++) tags[8 * i + 2 * k] = d[i].corner[k][0], tags[8 * i + 2 * k + 1] = d[i].corner[k][1];
    *ntags = n;
    return 1;
}

static void take_reference(run_proc *p, const sh_image *img, const sh_image *const *cams, int index, int nm)
{
    sh_point ref[SH_TRACK_MAX_MARKERS];
    int n = 0;
    for (int i = 0; i < nm; i++)
        if (p->mk[i].age == 0) /* detected in this very frame: no prediction in a reference */
            ref[n++] = (sh_point){.frame = index, .id = p->mk[i].id, .x = p->mk[i].x, .y = p->mk[i].y,
                                  .X = p->mk[i].X, .Y = p->mk[i].Y, .Z = p->mk[i].Z};
    int first = run_models_reference(p->models, &(int){0}) == NULL;
    int due = p->want_ref ? n >= p->cfg.min_markers
            : !first || run_models_pending(p->models) ? 0
            : p->cfg.reference_frame > 0 ? index == p->cfg.reference_frame - 1
            : n >= p->cfg.min_markers;
    if (!due || n < 3) return;
    const sh_plane *luma[SH_CALIB_MAX_CAMERAS] = {NULL};
    double tags[8 * SH_TRACK_MAX_DETECTIONS];
    int ntags;
    if (!reference_frame(p, img, cams, luma, tags, &ntags)) return;
    if (run_models_set_reference(p->models, ref, n, index, luma, tags, ntags) != SH_OK) {
        sh_log_error("reference: %s", sh_error_message());
        return;
    }
    p->want_ref = 0;
    sh_log_info("frame %d: %d markers taken as the new reference; its models are being built", index, n);
}

/* Falls back on the last model while sel's is built: usable when every one of its markers still
 * has an estimate within max_sigma_px (a prediction is fine: the status says degraded), and when
 * they are 3 or more (a carried frame's model of 2 has no markers' map to find its landmarks by:
 * carried() alone uses it). */
static int fallback(run_proc *p, int nm, double *xy, double *xyz, double *det)
{
    if (!p->last || run_model_markers(p->last) < 3) return 0;
    int n = run_model_markers(p->last); /* its landmarks are found by landmarks() */
    const int *ids = run_model_ids(p->last, &(int){0});
    for (int k = 0, c = 0; k < n; k++) {
        while (c < nm && p->mk[c].id < ids[k]) c++;
        if (c == nm || p->mk[c].id != ids[k] || p->mk[c].sigma > p->cfg.max_sigma_px) return 0;
        xy[2 * k] = p->mk[c].x;
        xy[2 * k + 1] = p->mk[c].y;
        xyz[3 * k] = p->mk[c].X;
        xyz[3 * k + 1] = p->mk[c].Y;
        xyz[3 * k + 2] = p->mk[c].Z;
        det[2 * k] = p->mk[c].dx;
        det[2 * k + 1] = p->mk[c].dy;
    }
    return n;
}

/* 3D: frames stay raw until enough markers seen by every camera say the calibration fits, and
 * whenever the recent ones say it does not (docs/3d.md, "Is the calibration right?"): a wrong
 * calibration (swapped cameras, a moved camera, another rig's file) bends the surface and still
 * passes the residual gate. 1 while this frame must be shown raw for it. */
#define RUN_CALIB_MIN_MARKERS 8
static int calibration_off(run_proc *p, int index, sh_display_frame_info *info)
{
    if (!p->tracker || !p->three_d) return 0;
    sh_track_calibration cc;
    run_tracker_calibration(p->tracker, &cc);
    if (cc.samples < RUN_CALIB_MIN_MARKERS) {
        reason(info, "checking the calibration (%d markers)", cc.samples);
        return 1;
    }
    int off = !(cc.median_px <= p->cfg.max_calibration_px);
    if (off && !p->calib_off)
        sh_log_error("frame %d: the calibration does not match the cameras: median reprojection error %.2f px "
                     "over the last %d markers seen by two or more cameras ([gating] max_calibration_px = "
                     "%.2f), camera %d's views %.2f px, %.0f %% behind a camera: raw frames", index,
                     cc.median_px, cc.samples, p->cfg.max_calibration_px, cc.worst_camera, cc.worst_px,
                     100 * cc.failed);
    else if (!off && p->calib_off)
        sh_log_info("frame %d: the calibration fits the cameras again (median reprojection error %.2f px)", index,
                    cc.median_px);
    p->calib_off = off;
    if (off) reason(info, "calibration mismatch: camera %d %.1f px", cc.worst_camera, cc.worst_px);
    return off;
}

/* Follows the tracker's word on a moved camera; 1 while this frame must be shown raw for it. */
static int camera_motion(run_proc *p, int index, sh_display_frame_info *info)
{
    if (!p->tracker) return 0;
    sh_track_motion mo;
    run_tracker_motion(p->tracker, &mo);
    if (mo.camera) {
        if (!p->moving)
            sh_log_info("frame %d: the camera is moving (%.1f px in one frame): raw frames until it settles",
                   index, mo.shift_px);
        p->moving = 1;
        p->still = 0;
        p->moved_px = fmax(p->moved_px, mo.shift_px);
        p->await_ref = 0;
    } else if (p->moving && ++p->still >= RUN_SETTLE_FRAMES) {
        p->moving = 0;
        if (p->cfg.on_camera_motion == SH_CAMERA_MOTION_NEW) {
            p->want_ref = p->await_ref = 1;
            sh_log_info("frame %d: the camera has settled (it moved up to %.1f px a frame): a new "
                   "reference is taken ([reference] on_camera_motion = new)", index, p->moved_px);
        } else {
            sh_log_info("frame %d: the camera has settled (it moved up to %.1f px a frame): the "
                   "reference is kept ([reference] on_camera_motion = keep)", index, p->moved_px);
        }
        p->moved_px = 0;
    }
    if (p->moving) {
        reason(info, "camera moving");
        return 1;
    }
    return 0;
}

/* The gates before any model: a moving camera, a calibration that does not fit, a reference
 * awaited or not there yet. 1 when the frame goes on (the reference in use in *ref, *nref). */
static int reference_ready(run_proc *p, const sh_image *img, const sh_image *const *cams, int index, int nm,
                           sh_display_frame_info *info, const sh_point **ref, int *nref)
{
    if (camera_motion(p, index, info) || calibration_off(p, index, info)) return 0;
    take_reference(p, img, cams, index, nm);
    int ref_frame, ref_n, ev = run_models_poll(p->models, &ref_frame, &ref_n);
    if (ev & RUN_MODELS_REFERENCE) {
        p->last = NULL; /* it belonged to the old reference, now freed */
        p->await_ref = 0;
        p->lm_ref_frame = ref_frame;
    }
    if (ev) {
        /* the landmarks found last were the old reference's (or none: its markers alone); the
         * last model stays across a LANDMARKS swap (run_model.h), a fallback while the frame's
         * set with the landmarks is built */
        p->lm_last = -1;
        sh_landmarks *lm = run_models_landmarks(p->models);
        sh_landmarks_rig *rig = run_models_rig(p->models);
        if (lm) {
            sh_log_info("reference: frame %d, %d markers, %d landmarks", ref_frame, ref_n, sh_landmarks_count(lm));
        } else if (rig) {
            int chosen = sh_landmarks_count(sh_landmarks_rig_primary(rig)), in3d = 0;
            for (int k = 0; k < chosen; k++) in3d += sh_landmarks_rig_in_3d(rig)[k];
            sh_log_info("reference: frame %d, %d markers, %d landmarks (of %d chosen in camera %d, the ones matched "
                        "in another camera and triangulated)", ref_frame, ref_n, in3d, chosen, p->out_cam);
        }
        else if (ev & RUN_MODELS_NO_LANDMARKS)
            sh_log_warn("reference: frame %d, %d markers; %s", ref_frame, ref_n, run_models_landmarks_note(p->models));
        else if (p->lm_cap)
            sh_log_info("reference: frame %d, %d markers; its landmarks are being chosen (its markers alone "
                        "until then)", ref_frame, ref_n);
        else
            sh_log_info("reference: frame %d, %d markers", ref_frame, ref_n);
    }
    if (p->await_ref) {
        /* the old reference is a view the camera has left: the live picture until the new one */
        reason(info, "camera moved: new reference (%d markers)", nm);
        return 0;
    }
    *ref = run_models_reference(p->models, nref);
    if (!*ref) {
        reason(info, run_models_pending(p->models) ? "building the reference (%d markers)" : "no reference yet (%d markers)", nm);
        return 0;
    }
    return 1;
}

/* The markers matched to the reference, gated on their number and their uncertainty: 1 when the
 * frame goes on with sel. */
static int selection_ok(run_proc *p, const sh_point *ref, int nref, int nm, run_selection *sel,
                        sh_display_frame_info *info)
{
    run_select(&p->cfg, p->fps, ref, nref, p->mk, nm, sel);
    info->markers_used = (uint32_t)sel->n;
    int need = p->cfg.min_markers > 3 ? p->cfg.min_markers : 3;
    if (sel->n < need) {
        if (sel->stale)
            reason(info, "too few markers (%d < %d, %d stale)", sel->n, need, sel->stale);
        else
            reason(info, "too few markers (%d < %d)", sel->n, need);
        return 0;
    }
    if (sel->worst_sigma > p->cfg.max_sigma_px) {
        reason(info, "uncertain: marker %d %.1f px > %.1f", sel->worst_id,
                 sel->worst_sigma, p->cfg.max_sigma_px);
        return 0;
    }
    return 1;
}

/* The positions a model is updated with: the selection's, or the fallback's (fallback()). */
typedef struct {
    double xy[2 * SH_TRACK_MAX_MARKERS], xyz[3 * SH_TRACK_MAX_MARKERS], det[2 * SH_TRACK_MAX_MARKERS];
} run_positions;

/* The model of sel's marker set; while it is being built the last one, with its own markers'
 * positions in fb (*building set). NULL when neither can be used (info says why). */
static run_model *model_for(run_proc *p, int nm, const run_selection *sel, run_positions *fb, int *building,
                            sh_display_frame_info *info)
{
    run_model *md = NULL;
    int got = run_models_get(p->models, sel->ids, sel->n, &md);
    if (got < 0) {
        sh_log_limited(&p->model_err, SH_LOG_ERROR, "%s", sh_error_message());
        reason(info, "model failed (%d markers)", sel->n);
        return NULL;
    }
    sh_log_limit_clear(&p->model_err);
    if (got == 1) {
        p->last = md; /* the model run_models keeps from eviction (pinned) */
        return md;
    }
    int n = fallback(p, nm, fb->xy, fb->xyz, fb->det);
    if (!n) {
        reason(info, "model for %d markers building", sel->n);
        return NULL;
    }
    *building = 1;
    info->markers_used = (uint32_t)n;
    return p->last;
}

/* A warped frame's status: degraded while its own model is built or when markers were predicted. */
static void warped_status(const run_selection *sel, int building, sh_display_frame_info *info)
{
    if (building) {
        info->status = SH_DISPLAY_DEGRADED;
        reason(info, "model for %d markers building", sel->n);
    } else if (sel->predicted) {
        info->status = SH_DISPLAY_DEGRADED;
        reason(info, "dropout: %d markers predicted", sel->predicted);
    } else {
        info->status = SH_DISPLAY_STABILIZED;
        info->reason[0] = 0;
    }
}

/* The warped frame into p->out: one view, or the two eyes in their layout; [sink] outside's fill. */
static sh_status warp(run_proc *p, const run_model *md, const sh_image *img)
{
    int dimmed = p->cfg.outside == SH_OUTSIDE_DIMMED_RAW;
    if (p->stereo) {
        const sh_warp3d_view *views[2];
        if (run_model_views(md, views) != 2) return sh_error_set(SH_EINVAL, "stereo: the model has no two eyes");
        p->out_kept = 0;
        return sh_warp3d_stereo_apply(p->warp, views, dimmed ? p->outside : NULL, p->layout, img, &p->eye, &p->out);
    }
    /* the black outside the hull written again only where it changed, when out holds the warp's
     * own last output (not the dimmed frame's outside, nor a stereo pair) */
    sh_status st = (p->out_kept ? sh_warp_apply_again : sh_warp_apply)(p->warp, run_model_warp(md), img, &p->out);
    p->out_kept = st == SH_OK && !dimmed;
    if (st == SH_OK && dimmed) st = sh_warp_outside_apply(p->outside[0], run_model_warp(md), img, &p->out);
    return st;
}

/* A frame shown raw: the camera's as it is, or in stereo in each eye's place of the layout (both
 * eyes see the unstabilized frame: nothing of it is passed off as depth). */
static const sh_image *raw(run_proc *p, const sh_image *img)
{
    if (!p->stereo) return img;
    p->out_kept = 0;
    if (sh_warp3d_layout_place(p->layout, 0, img, &p->out) != SH_OK ||
        sh_warp3d_layout_place(p->layout, 1, img, &p->out) != SH_OK) {
        /* cannot happen with the frames the layout was sized for: black rather than a stale pair */
        sh_log_limited(&p->model_err, SH_LOG_ERROR, "stereo: %s", sh_error_message());
        sh_image_clear(&p->out);
    }
    return &p->out;
}

static const sh_image *frame(run_proc *p, const sh_image *img, const sh_image *const *cams, int index,
                             unsigned epoch, sh_display_frame_info *info);

/* 2D: the nlm landmarks of the reference (all of them, as the model holds) predicted by the markers' TPS map of this frame, found
 * in img and judged; p->lm_xy their positions, p->lm_verdict 1 where accepted. The accepted
 * count, or -1 (sh_error_message says why). */
static int search_2d(run_proc *p, const run_model *md, const sh_image *img, const double *xy, int nmk, int nlm)
{
    sh_landmarks *lm = run_models_landmarks(p->models);
    const sh_plane *y;
    sh_landmarks_counts c;
    sh_status st = lm && sh_landmarks_count(lm) == nlm
                       ? SH_OK
                       : sh_error_set(SH_EINVAL, "the model's landmarks are not the reference's");
    if (st == SH_OK) st = sh_landmarks_luma(img, &p->lm_gray[0], &y);
    if (st == SH_OK)
        st = sh_interp_mapper_map(p->lm_map, run_model_ref_xy(md), xy, nmk, sh_landmarks_reference(lm), nlm, p->lm_pred);
    if (st == SH_OK) st = sh_landmarks_track(lm, y, p->lm_pred, p->lm_xy, p->lm_verdict, &c);
    if (st != SH_OK) return -1;
    for (int k = 0; k < nlm; k++) p->lm_verdict[k] = p->lm_verdict[k] == SH_LANDMARK_ACCEPTED;
    for (int v = 0; v < SH_LANDMARK_VERDICTS; v++) p->lm_verdicts[v] += c.verdicts[v];
    p->lm_frames++;
    return c.verdicts[SH_LANDMARK_ACCEPTED];
}

/* 3D: the same with a calibrated rig (sh_landmarks_rig): every camera searched (cams), the
 * landmarks triangulated; p->lm_xyz their X, Y, Z, p->lm_verdict 1 where used. The used count,
 * or -1. */
static int search_3d(run_proc *p, const run_model *md, const sh_image *img, const sh_image *const *cams,
                     const double *xy, const double *xyz, int nmk)
{
    sh_landmarks_rig *rig = run_models_rig(p->models);
    const sh_plane *y[SH_CALIB_MAX_CAMERAS];
    sh_landmarks_rig_counts c;
    sh_status st = rig ? lumas(p, img, cams, y) : sh_error_set(SH_EINVAL, "the model's landmarks are not the reference's");
    if (st == SH_OK)
        st = sh_landmarks_rig_track(rig, y, run_model_ref_xy(md), xy, xyz, nmk, p->lm_xy, p->lm_xyz, p->lm_verdict, &c);
    if (st != SH_OK) return -1;
    if (c.mapped) {
        for (int v = 0; v < SH_LANDMARK_VERDICTS; v++) p->lm_verdicts[v] += c.primary.verdicts[v];
        p->lm_unmatched += c.unmatched;
        p->lm_inconsistent += c.inconsistent;
        p->lm_frames++;
    }
    return c.used;
}

/* The reference frame itself (built before it is warped: test mode, or a reference made at
 * once): its landmarks are where the reference has them, every one in 2D, the triangulated
 * ones in 3D, as `stillheart track --landmarks` writes frame 0. Searched again, the reference
 * would be one more frame in their histories (max_jump) than the offline path gives them. The
 * count, or -1. */
static int at_reference(run_proc *p, int nlm)
{
    sh_landmarks_rig *rig = p->three_d ? run_models_rig(p->models) : NULL;
    const sh_landmarks *lm = rig ? sh_landmarks_rig_primary(rig) : run_models_landmarks(p->models);
    if (!lm || (!rig && sh_landmarks_count(lm) != nlm)) {
        sh_error_set(SH_EINVAL, "the model's landmarks are not the reference's");
        return -1;
    }
    const int n = sh_landmarks_count(lm);
    memcpy(p->lm_xy, sh_landmarks_reference(lm), 2 * (size_t)n * sizeof *p->lm_xy);
    if (rig) {
        memcpy(p->lm_verdict, sh_landmarks_rig_in_3d(rig), (size_t)n);
        memcpy(p->lm_xyz, sh_landmarks_rig_reference_xyz(rig), 3 * (size_t)n * sizeof *p->lm_xyz);
    } else {
        memset(p->lm_verdict, 1, (size_t)n);
    }
    int used = 0;
    for (int i = 0; i < n; i++) used += p->lm_verdict[i];
    return used;
}

/* A model with landmarks (ids after its markers': SH_LANDMARK_ID_BASE + the landmark's index in
 * the reference's; in 3D only those with a reference X, Y, Z): this frame's positions of all its
 * points into p->all_xy (the markers' xy, then each landmark found in img) and in 3D p->all_xyz,
 * their detections into p->all_det (NaN for the landmarks: the residual is the markers'), and
 * which the map goes through into p->all_use (the markers, and the landmarks landmarks.h accepts
 * and, in 3D, triangulates). Each landmark's search starts where the markers' TPS map puts it, as
 * in `stillheart track --landmarks`, whatever [method] is. A failure leaves every landmark out
 * (the markers' map alone), logged. */
static void landmarks(run_proc *p, const run_model *md, const sh_image *img, const sh_image *const *cams, int index,
                      const double *xy, const double *xyz, const double *det)
{
    double t0 = now_ms();
    int n, nmk = run_model_markers(md);
    const int *ids = run_model_ids(md, &n);
    memcpy(p->all_xy, xy, sizeof(double) * 2 * (size_t)nmk);
    if (p->three_d) memcpy(p->all_xyz, xyz, sizeof(double) * 3 * (size_t)nmk);
    memcpy(p->all_det, det, sizeof(double) * 2 * (size_t)nmk);
    memset(p->all_use, 1, (size_t)nmk);
    memset(p->all_use + nmk, 0, (size_t)(n - nmk));
    int got = index == p->lm_ref_frame ? at_reference(p, n - nmk)
              : p->three_d            ? search_3d(p, md, img, cams, xy, xyz, nmk)
                                      : search_2d(p, md, img, xy, nmk, n - nmk);
    p->lm_accepted = got > 0 ? got : 0;
    p->lm_found = got >= 0 && !p->three_d;
    if (got < 0) {
        sh_log_limited(&p->lm_err, SH_LOG_ERROR, "landmarks: %s (the markers alone)", sh_error_message());
    } else {
        sh_log_limit_clear(&p->lm_err);
        for (int k = nmk; k < n; k++) {
            int i = ids[k] - SH_LANDMARK_ID_BASE;
            p->all_xy[2 * k] = p->lm_xy[2 * i];
            p->all_xy[2 * k + 1] = p->lm_xy[2 * i + 1];
            if (p->three_d) memcpy(&p->all_xyz[3 * k], &p->lm_xyz[3 * i], sizeof(double) * 3);
            p->all_use[k] = p->lm_verdict[i];
        }
    }
    for (int k = nmk; k < n; k++) {
        if (!p->all_use[k]) p->all_xy[2 * k] = p->all_xy[2 * k + 1] = NAN; /* never read */
        p->all_det[2 * k] = p->all_det[2 * k + 1] = NAN;
    }
    p->lm_ms = now_ms() - t0;
}

/* The points the last warped frame's map went through: the model's markers, then the landmarks
 * it used. */
static void keep_used(run_proc *p, const run_model *md, const double *xy, const unsigned char *use)
{
    int mn;
    const int *mids = run_model_ids(md, &mn);
    p->used_n = 0;
    for (int k = 0; k < mn; k++) {
        if (use && !use[k]) continue;
        p->used_ids[p->used_n] = mids[k];
        p->used_xy[2 * p->used_n] = xy[2 * k];
        p->used_xy[2 * p->used_n + 1] = xy[2 * k + 1];
        p->used_n++;
    }
}

/* md updated through xy (and xyz in 3D; use: the points it goes through, NULL: all), gated on its
 * residual at the markers' detections det, and img warped with it into p->out: 1 when warped (info
 * says why not). t1: when the markers were done; the update's time counts from there, less the
 * landmarks'. */
static int update_and_warp(run_proc *p, run_model *md, const sh_image *img, const double *xy, const double *xyz,
                           const double *det, const unsigned char *use, double t1, sh_display_frame_info *info)
{
    double residual;
    sh_status ust = run_model_update(md, p->warp, xy, xyz, det, use, &residual);
    double t2 = now_ms();
    p->ms[1] = t2 - t1 - p->lm_ms;
    if (ust != SH_OK) {
        reason(info, "model update failed");
        return 0;
    }
    if (!isfinite(residual)) {
        reason(info, "map not defined at a marker");
        return 0;
    }
    info->residual_px = (float)residual; /* -1: every marker predicted, nothing to compare */
    if (residual > p->cfg.max_residual_px) {
        reason(info, "residual %.1f px > %.1f", residual, p->cfg.max_residual_px);
        return 0;
    }
    sh_status wst = warp(p, md, img);
    p->ms[2] = now_ms() - t2;
    if (wst != SH_OK) {
        sh_log_limited(&p->model_err, SH_LOG_ERROR, "warp: %s", sh_error_message());
        reason(info, "warp failed");
        return 0;
    }
    keep_used(p, md, xy, use);
    return 1;
}

/* After a frame stabilized (nm markers in p->mk): with its landmarks found in 2D, it may carry the
 * next (p->lm_last), and its map's markers detected in it are kept for that (their detections: the
 * check compares motions the detector saw, not the tracker's estimates, which lag a fast motion);
 * else the chain is broken. */
static void carry_from(run_proc *p, int index, int nm)
{
    p->lm_last = p->chain = p->lm_found ? index : -1;
    p->carry_n = 0;
    for (int k = 0, c = 0; k < p->used_n && p->lm_found; k++) {
        int id = p->used_ids[k];
        while (c < nm && p->mk[c].id < id) c++;
        if (id >= SH_LANDMARK_ID_BASE || c == nm || p->mk[c].id != id || p->mk[c].age != 0) continue;
        p->carry_ids[p->carry_n] = id;
        p->carry_det[2 * p->carry_n] = p->mk[c].dx;
        p->carry_det[2 * p->carry_n + 1] = p->mk[c].dy;
        p->carry_n++;
    }
}

/* The markers detected in this frame (p->mk, nm of them) that are in the reference (ref, nref; both
 * sorted by id) and were detected in the map of the frame before (carry_from): their ids,
 * reference positions, detections there and now (dprev, det), and positions now (xy: the
 * tracker's, which the map goes through as every frame's does). Their count. */
static int seen_twice(const run_proc *p, int nm, const sh_point *ref, int nref, int *ids, double *sref, double *dprev,
                      double *det, double *xy)
{
    int nb = 0;
    for (int c = 0, r = 0; c < nm; c++) {
        const run_marker *mk = &p->mk[c];
        while (r < nref && ref[r].id < mk->id) r++;
        if (mk->age != 0 || r == nref || ref[r].id != mk->id) continue;
        int u = 0;
        while (u < p->carry_n && p->carry_ids[u] != mk->id) u++;
        if (u == p->carry_n) continue;
        ids[nb] = mk->id;
        sref[2 * nb] = ref[r].x, sref[2 * nb + 1] = ref[r].y;
        dprev[2 * nb] = p->carry_det[2 * u], dprev[2 * nb + 1] = p->carry_det[2 * u + 1];
        det[2 * nb] = mk->dx, det[2 * nb + 1] = mk->dy;
        xy[2 * nb] = mk->x, xy[2 * nb + 1] = mk->y;
        nb++;
    }
    return nb;
}

/* A carried frame's points into p->all_*: md's markers among the nb detected (ids, positions xy,
 * detections det; the others left out), then its landmarks accepted (p->lm_xy, p->lm_verdict). 0
 * when md lacks one of the nb markers (the last model, while theirs is built). */
static int carried_points(run_proc *p, const run_model *md, const int *ids, int nb, const double *xy,
                          const double *det)
{
    int npts, nmk = run_model_markers(md), held = 0;
    const int *mids = run_model_ids(md, &npts);
    for (int k = 0; k < nmk; k++) {
        int j = 0;
        while (j < nb && ids[j] != mids[k]) j++;
        p->all_use[k] = j < nb;
        held += j < nb;
        p->all_xy[2 * k] = j < nb ? xy[2 * j] : NAN;
        p->all_xy[2 * k + 1] = j < nb ? xy[2 * j + 1] : NAN;
        p->all_det[2 * k] = j < nb ? det[2 * j] : NAN;
        p->all_det[2 * k + 1] = j < nb ? det[2 * j + 1] : NAN;
    }
    for (int k = nmk; k < npts; k++) {
        int i = mids[k] - SH_LANDMARK_ID_BASE;
        p->all_use[k] = p->lm_verdict[i];
        p->all_xy[2 * k] = p->all_use[k] ? p->lm_xy[2 * i] : NAN;
        p->all_xy[2 * k + 1] = p->all_use[k] ? p->lm_xy[2 * i + 1] : NAN;
        p->all_det[2 * k] = p->all_det[2 * k + 1] = NAN;
    }
    return held == nb;
}

/* carried() with nothing to search in this frame (one marker seen in both frames, or no landmark
 * accepted in the one before), which is shown raw: it leaves the landmarks found last as they
 * were, so the next may still be carried from them, as across frames dropped; their predictions
 * there rest on the markers' motion since, and the check on the markers detected in both frames
 * (sh_landmarks_carry). A frame raw for anything else (the camera moved, the calibration is off,
 * the landmarks searched and refused) ends the chain. NULL. */
static const sh_image *unsearched(run_proc *p)
{
    p->chain = p->current;
    return NULL;
}

/* [gating] landmarks_carry: a frame that would be raw for its markers (too few, one too uncertain,
 * or no model for them yet), right after a frame stabilized with its landmarks found (2D). The
 * markers detected in both frames and the landmarks, searched from the
 * frame before's and judged as every frame's, make its map when the landmarks move as those
 * markers do (sh_landmarks_carry); the frame is shown degraded, warped by the model of those
 * markers and the landmarks (or, while it is built, the last model with its other markers left
 * out), over the hull of the points used (a marker not seen lies outside it). NULL when not (info
 * says why, or keeps "too few markers" when nothing was tried). */
static const sh_image *carried(run_proc *p, const sh_image *img, int index, int nm, const sh_point *ref, int nref,
                               double t1, sh_display_frame_info *info)
{
    /* the chain holds across frames never processed (dropped while the processing was busy) and
     * frames shown raw without a landmark search (unsearched), not across one whose landmarks
     * were searched and not used */
    if (!p->cfg.landmarks_carry || !p->lm_cap || p->three_d || p->lm_last < 0 || p->chain != p->processed)
        return NULL;
    int ids[SH_TRACK_MAX_MARKERS];
    double sref[2 * SH_TRACK_MAX_MARKERS], dprev[2 * SH_TRACK_MAX_MARKERS], det[2 * SH_TRACK_MAX_MARKERS],
        snow[2 * SH_TRACK_MAX_MARKERS];
    int nb = seen_twice(p, nm, ref, nref, ids, sref, dprev, det, snow);
    sh_landmarks *lm = run_models_landmarks(p->models);
    if (!lm) return NULL;
    if (nb < SH_LANDMARKS_CARRY_SEEN) return unsearched(p);
    double t0 = now_ms();
    int n = sh_landmarks_count(lm);
    memcpy(p->carry_xy, p->lm_xy, sizeof(float) * 2 * (size_t)n);
    memcpy(p->carry_ok, p->lm_verdict, (size_t)n);
    const sh_plane *y;
    sh_landmarks_counts c;
    sh_landmarks_carry_report r;
    sh_status st = sh_landmarks_luma(img, &p->lm_gray[0], &y);
    if (st == SH_OK)
        st = sh_landmarks_carry(lm, y, p->carry_xy, p->carry_ok, sref, dprev, det, nb, p->cfg.max_residual_px,
                                p->lm_pred, p->lm_xy, p->lm_verdict, &c, &r);
    p->lm_ms = now_ms() - t0;
    if (st != SH_OK) {
        sh_log_limited(&p->lm_err, SH_LOG_ERROR, "landmarks: %s (the frame raw)", sh_error_message());
        return NULL;
    }
    if (!r.searched) return unsearched(p); /* none accepted before */
    for (int v = 0; v < SH_LANDMARK_VERDICTS; v++) p->lm_verdicts[v] += c.verdicts[v];
    p->lm_frames++;
    p->lm_accepted = c.verdicts[SH_LANDMARK_ACCEPTED];
    for (int k = 0; k < n; k++) p->lm_verdict[k] = p->lm_verdict[k] == SH_LANDMARK_ACCEPTED;
    if (!r.carried) {
        if (r.support < SH_LANDMARKS_CARRY_SUPPORT)
            reason(info, "too few markers (%d); landmarks: %d by one", nb, r.support);
        else
            reason(info, "too few markers (%d); landmarks %.1f px off", nb, r.worst_px);
        return NULL;
    }
    /* the model of those markers and the landmarks; while it is built (live), the last model with
     * its other markers left out, as long as it holds these */
    run_model *md = NULL;
    int got = run_models_get(p->models, ids, nb, &md);
    if (got < 0) {
        sh_log_limited(&p->model_err, SH_LOG_ERROR, "%s", sh_error_message());
        reason(info, "carried: model failed (%d markers)", nb);
        return NULL;
    }
    if (got == 1) p->last = md;
    else md = p->last;
    if (!md || !carried_points(p, md, ids, nb, snow, det)) {
        reason(info, "carried: model for %d markers building", nb);
        return NULL;
    }
    if (!update_and_warp(p, md, img, p->all_xy, NULL, p->all_det, p->all_use, t1, info)) return NULL;
    info->status = SH_DISPLAY_DEGRADED;
    info->markers_used = (uint32_t)nb;
    reason(info, "carried: %d markers, %d landmarks", nb, p->lm_accepted);
    p->lm_found = 1;
    carry_from(p, index, nm);
    return &p->out;
}

const sh_image *run_proc_frame(run_proc *p, const sh_image *img, const sh_image *const *cams, int index,
                               unsigned epoch, sh_display_frame_info *info)
{
    const sh_image *shown = frame(p, img, cams, index, epoch, info);
    return info->status == SH_DISPLAY_RAW ? raw(p, img) : shown;
}

/* run_proc_frame's work: the warped frame, or img when the frame is shown raw (info says so). */
static const sh_image *frame(run_proc *p, const sh_image *img, const sh_image *const *cams, int index,
                             unsigned epoch, sh_display_frame_info *info)
{
    double t0 = now_ms();
    p->ms[0] = p->ms[1] = p->ms[2] = 0;
    p->lm_ms = 0;
    p->lm_accepted = 0;
    p->lm_found = 0;
    p->processed = p->current;
    p->current = index;
    int nm = markers(p, img, cams, index, epoch);
    double t1 = now_ms();
    p->ms[0] = t1 - t0;
    info->status = SH_DISPLAY_RAW;
    info->residual_px = -1; /* not measured */
    info->markers_used = 0;
    p->used_n = 0;
    const sh_point *ref;
    int nref;
    run_selection sel;
    if (!reference_ready(p, img, cams, index, nm, info, &ref, &nref)) return img;
    /* too few markers, an uncertain one, or no model for them yet: raw, unless the landmarks carry
     * the frame on the markers detected in it */
    const sh_image *shown;
    if (!selection_ok(p, ref, nref, nm, &sel, info))
        return (shown = carried(p, img, index, nm, ref, nref, t1, info)) ? shown : img;
    run_positions fb;
    int building = 0;
    run_model *md = model_for(p, nm, &sel, &fb, &building, info);
    if (!md) return (shown = carried(p, img, index, nm, ref, nref, t1, info)) ? shown : img;
    const double *xy = building ? fb.xy : sel.xy, *xyz = building ? fb.xyz : sel.xyz,
                 *det = building ? fb.det : sel.det;
    const unsigned char *use = NULL;
    int npts;
    run_model_ids(md, &npts);
    if (npts > run_model_markers(md)) { /* the reference has landmarks */
        landmarks(p, md, img, cams, index, xy, xyz, det);
        xy = p->all_xy, det = p->all_det, use = p->all_use;
        if (p->three_d) xyz = p->all_xyz;
    }
    if (!update_and_warp(p, md, img, xy, xyz, det, use, t1, info)) return img;
    warped_status(&sel, building, info);
    carry_from(p, index, nm);
    return &p->out;
}
