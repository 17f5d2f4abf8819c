/* The daemon's markers: detection in the Kalman tracker's windows (include/stillheart/track.h,
 * docs/tracking.md), the estimates as correspondences, and their match to the reference. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "run_track.h"
#include "stillheart/track.h"

#define MAX_DET SH_TRACK_MAX_DETECTIONS

struct run_tracker {
    sh_track_options opts;
    int ids[SH_TRACK_MAX_MARKERS];
    sh_calib calib;
    int ncam, out_cam;
    sh_tracker *t;
    sh_detector *det;
    int last_index, frame, started;
    unsigned epoch;
    sh_detection dets[SH_TRACK_MAX_CAMERAS][MAX_DET];
    int ndets[SH_TRACK_MAX_CAMERAS]; /* the last frame's, after merging */
    sh_window win[SH_TRACK_MAX_MARKERS + 1];
    sh_track_estimate est[SH_TRACK_MAX_MARKERS];
};

sh_status run_tracker_create(const sh_config *cfg, const sh_calib *calib, int out_cam, int width, int height,
                             double fps, run_tracker **out)
{
    run_tracker *rt = calloc(1, sizeof *rt);
    if (!rt) return sh_error_set(SH_ENOMEM, "tracker: out of memory");
    rt->ncam = calib ? calib->num_cameras : 1;
    rt->out_cam = calib ? out_cam : 0;
    if (calib) rt->calib = *calib;
    sh_track_options_default(&rt->opts);
    int n = 0;
    for (int i = 0; i < SH_CONFIG_MAX_IDS; i++)
        if (cfg->ids[i]) {
            if (n == SH_TRACK_MAX_MARKERS) {
                free(rt);
                return sh_error_set(SH_EINVAL, "[detect] ids: '%s': the tracker follows at most %d markers",
                                    cfg->ids_text, SH_TRACK_MAX_MARKERS);
            }
            rt->ids[n++] = i;
        }
    rt->opts.ids = rt->ids;
    rt->opts.num_ids = n;
    rt->opts.fps = fps > 0 ? fps : 30;
    rt->opts.width = width;
    rt->opts.height = height;
    sh_detector_options dopt;
    sh_detector_options_default(&dopt);
    dopt.family = cfg->family;
    dopt.window_decimate = 2; /* ~2.4x cheaper, as accurate on ~100 px tags (detect.h) */
    /* the windows scanned by as many threads as the warp's: detection no longer leaves a core
     * idle (docs/daemon.md, "At 4K"); the same detections in the same order */
    dopt.window_threads = cfg->threads > 0 ? cfg->threads : 1;
    sh_status st = sh_detector_create(&dopt, &rt->det);
    if (st == SH_OK) st = sh_tracker_create(&rt->opts, calib ? &rt->calib : NULL, &rt->t);
    if (st != SH_OK) {
        run_tracker_destroy(rt);
        return st;
    }
    *out = rt;
    return SH_OK;
}

void run_tracker_destroy(run_tracker *rt)
{
    if (!rt) return;
    sh_tracker_destroy(rt->t);
    sh_detector_destroy(rt->det);
    free(rt);
}

double run_tracker_fps(const run_tracker *rt) { return rt->opts.fps; }

int run_tracker_detections(const run_tracker *rt, const sh_detection **out)
{
    *out = rt->dets[rt->out_cam];
    return rt->ndets[rt->out_cam];
}

void run_tracker_motion(const run_tracker *rt, sh_track_motion *out) { sh_tracker_motion(rt->t, out); }

void run_tracker_calibration(const run_tracker *rt, sh_track_calibration *out) { sh_tracker_calibration(rt->t, out); }

int run_tracker_locked(const run_tracker *rt)
{
    sh_track_stats s;
    sh_tracker_stats(rt->t, &s);
    return s.locked;
}

void run_tracker_summary(const run_tracker *rt, char *out, size_t cap)
{
    sh_track_stats s;
    sh_tracker_stats(rt->t, &s);
    char heart[48], resp[48];
    sh_track_rate_text(s.heart_hz, heart, sizeof heart);
    sh_track_rate_text(s.resp_hz, resp, sizeof resp);
    snprintf(out, cap, "tracker: %ld frames, heart %s%s, respiration %s; detections used %ld, gated %ld, "
             "duplicated ids %ld, unknown ids %ld, inconsistent 3D %ld, taken on their neighbours' agreement %ld; "
             "markers lost %ld; camera moved in %ld frames",
             s.frames, heart, s.locked ? " (locked)" : "", resp, s.accepted, s.gated, s.duplicates,
             s.unknown, s.inconsistent, s.jumped, s.lost, s.camera_moves);
}

/* One tag seen by two overlapping windows comes back twice; the tracker would discard an id
 * detected twice as ambiguous, so copies within a pixel of each other are merged first. */
static int merge_copies(sh_detection *d, int n)
{
    int kept = 0;
    for (int i = 0; i < n; i++) {
        int j = 0;
        while (j < kept && !(d[j].id == d[i].id && fabs(d[j].cx - d[i].cx) < 1 && fabs(d[j].cy - d[i].cy) < 1)) j++;
        if (j == kept) d[kept++] = d[i];
    }
    return kept;
}

sh_status run_tracker_frame(run_tracker *rt, const sh_image *const *cams, int index, unsigned epoch, run_marker *out,
                            int *n)
{
    *n = 0;
    if (rt->started && (index <= rt->last_index || epoch != rt->epoch)) {
        /* time went backwards or the scene jumped (a replay started again): the filters' history
         * no longer applies */
        sh_tracker *fresh;
        sh_status st = sh_tracker_create(&rt->opts, rt->ncam > 1 ? &rt->calib : NULL, &fresh);
        if (st != SH_OK) return st;
        sh_tracker_destroy(rt->t);
        rt->t = fresh;
        rt->started = 0;
    }
    /* frames dropped by the mailbox still count as time for the filters */
    rt->frame = rt->started ? rt->frame + (index - rt->last_index) : 0;
    rt->last_index = index;
    rt->epoch = epoch;
    sh_status st = sh_tracker_predict(rt->t, rt->frame);
    if (st != SH_OK) return st;
    const sh_detection *dp[SH_TRACK_MAX_CAMERAS];
    int count[SH_TRACK_MAX_CAMERAS];
    for (int c = 0; c < rt->ncam; c++) {
        int nw = 0, nb = 0, nd = 0;
        dp[c] = rt->dets[c];
        count[c] = 0;
        if (!cams[c]) continue; /* this set lacks camera c */
        /* at 4K the tags are twice the pixels of 1080p's: as many decimated pixels per module
         * at twice the decimation (detect.h), a quarter of the pixels to scan */
        st = sh_detector_set_tag_side(rt->det, sh_tracker_tag_side(rt->t, c));
        if (st == SH_OK) st = sh_tracker_windows(rt->t, c, rt->win, SH_TRACK_MAX_MARKERS, &nw);
        if (st == SH_OK) st = sh_tracker_reacquire(rt->t, c, &rt->win[nw], &nb);
        if (st != SH_OK) return st;
        st = !rt->started || nw == 0
                 ? sh_detector_detect(rt->det, cams[c], rt->dets[c], MAX_DET, &nd)
                 : sh_detector_detect_windows(rt->det, cams[c], rt->win, nw + nb, rt->dets[c], MAX_DET, &nd);
        if (st == SH_OK && rt->started && nw > 0 && sh_tracker_rescan(rt->t, c, rt->dets[c], nd < MAX_DET ? nd : MAX_DET))
            st = sh_detector_detect(rt->det, cams[c], rt->dets[c], MAX_DET, &nd);
        if (st != SH_OK) nd = 0; /* a detector failure is a frame without detections */
        count[c] = merge_copies(rt->dets[c], nd < MAX_DET ? nd : MAX_DET);
    }
    memcpy(rt->ndets, count, sizeof(int) * (size_t)rt->ncam);
    rt->started = 1;
    st = sh_tracker_update(rt->t, dp, count, rt->ncam);
    if (st != SH_OK) return st;
    int ne = sh_tracker_estimates(rt->t, rt->est, SH_TRACK_MAX_MARKERS);
    for (int k = 0; k < ne; k++) {
        const sh_track_estimate *e = &rt->est[k];
        int oc = rt->out_cam;
        if (!e->confirmed || e->status == SH_TRACK_LOST || e->status == SH_TRACK_NEW || !e->in_view[oc]) continue;
        if (!isfinite(e->xy[oc][0]) || !isfinite(e->xy[oc][1])) continue;
        run_marker *m = &out[(*n)++];
        m->id = e->id;
        m->x = e->xy[oc][0];
        m->y = e->xy[oc][1];
        m->X = e->dim == 3 ? e->pos[0] : NAN;
        m->Y = e->dim == 3 ? e->pos[1] : NAN;
        m->Z = e->dim == 3 ? e->pos[2] : NAN;
        if (e->dim == 2) { /* largest axis of the 2x2 covariance: sqrt of its larger eigenvalue */
            double a = e->cov[0], b = e->cov[1], d = e->cov[3];
            double l = 0.5 * (a + d) + sqrt(0.25 * (a - d) * (a - d) + b * b);
            m->sigma = sqrt(l > 0 ? l : 0);
        } else { /* mm -> px at the marker's depth in the output camera; sqrt(trace) bounds the
                  * largest axis from above */
            const sh_calib_camera *k = &rt->calib.cam[oc];
            double z = k->R[6] * e->pos[0] + k->R[7] * e->pos[1] + k->R[8] * e->pos[2] + k->t[2];
            double tr = e->cov[0] + e->cov[4] + e->cov[8];
            m->sigma = z > 0 ? sqrt(tr > 0 ? tr : 0) * k->K[0] / z : INFINITY;
        }
        m->age = e->age;
        /* the safety gate compares the estimate with this frame's detection whenever it is
         * evidence (well shaped, agreeing with the other markers'), used by the tracker or not:
         * an estimate the tracker held against a plain detection must not pass as stabilized */
        m->dx = e->det_ok[oc] ? e->det_xy[oc][0] : NAN;
        m->dy = e->det_ok[oc] ? e->det_xy[oc][1] : NAN;
    }
    return st;
}

void run_select(const sh_config *cfg, double fps, const sh_point *ref, int nref, const run_marker *m,
                int nm, run_selection *sel)
{
    memset(sel, 0, sizeof *sel);
    sel->worst_id = -1;
    double frame_ms = 1000.0 / (fps > 0 ? fps : 30);
    for (int r = 0, c = 0; r < nref; r++) {
        while (c < nm && m[c].id < ref[r].id) c++;
        if (c == nm || m[c].id != ref[r].id) continue;
        const run_marker *k = &m[c];
        if (k->age * frame_ms > cfg->dropout_ms) {
            sel->stale++;
            continue;
        }
        sel->ids[sel->n] = k->id;
        sel->xy[2 * sel->n] = k->x;
        sel->xy[2 * sel->n + 1] = k->y;
        sel->det[2 * sel->n] = k->dx;
        sel->det[2 * sel->n + 1] = k->dy;
        sel->xyz[3 * sel->n] = k->X;
        sel->xyz[3 * sel->n + 1] = k->Y;
        sel->xyz[3 * sel->n + 2] = k->Z;
        sel->n++;
        sel->predicted += k->age > 0;
        if (sel->worst_id < 0 || k->sigma > sel->worst_sigma) {
            sel->worst_id = k->id;
            sel->worst_sigma = k->sigma;
        }
    }
}
