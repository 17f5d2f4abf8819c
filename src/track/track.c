/* Marker tracker: a Kalman filter per marker and coordinate over a baseline + Fourier series of the
 * heartbeat and respiration (rotating form), rates estimated online from all markers' recent
 * tracks; gating, duplicates, loss, search windows, reacquisition bands, 2D or 3D, and the
 * spatial estimate of occluded markers from their visible neighbours. See docs/tracking.md.
 *
 * Everything is sized at create (one allocation); nothing allocates per frame. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "track_internal.h"

void sh_track_options_default(sh_track_options *o)
{
    memset(o, 0, sizeof *o);
    o->heart_harmonics = 3;
    o->resp_harmonics = 1;
    o->heart_min_hz = 0.6;
    o->heart_max_hz = 3.5;
    o->resp_min_hz = 0.1;
    o->resp_max_hz = 0.55;
    o->meas_sigma = 0.3;
    o->q_base = 0.3;
    o->q_harm = 0.2;
    o->accel = 1500;
    o->gate = 16;
    o->max_reproj = 3;
    o->lost_after = 2;
    o->min_motion = 0.3;
    o->window_sigmas = 4;
    o->min_window = 48;
    o->reacquire_bands = 4;
    o->spatial = SH_SPATIAL_FUSE;
}

float *trk_hist_at(sh_tracker *t, int mi, int a)
{
    return t->hist + ((size_t)mi * 3 + a) * SH_TRACK_HISTORY;
}

sh_status sh_tracker_create(const sh_track_options *opts, const sh_calib *calib, sh_tracker **out)
{
    if (!opts || !out) return sh_error_set(SH_EINVAL, "tracker: missing options");
    *out = NULL;
    const sh_track_options *o = opts;
    if (!(o->fps > 0 && o->fps <= 1000))
        return sh_error_set(SH_EINVAL, "tracker: fps %g outside (0, 1000]", o->fps);
    if (o->width < 1 || o->height < 1 || o->width > 16384 || o->height > 16384)
        return sh_error_set(SH_EINVAL, "tracker: image size %dx%d", o->width, o->height);
    if (o->heart_harmonics < 1 || o->heart_harmonics > HMAX)
        return sh_error_set(SH_EINVAL, "tracker: heart harmonics %d outside 1..%d", o->heart_harmonics, HMAX);
    if (o->resp_harmonics < 0 || o->resp_harmonics > RMAX)
        return sh_error_set(SH_EINVAL, "tracker: respiration harmonics %d outside 0..%d",
                            o->resp_harmonics, RMAX);
    if (!(o->heart_min_hz > 0 && o->heart_max_hz > o->heart_min_hz) ||
        (o->resp_harmonics > 0 && !(o->resp_min_hz > 0 && o->resp_max_hz > o->resp_min_hz &&
                                    o->resp_max_hz < o->heart_min_hz)))
        return sh_error_set(SH_EINVAL, "tracker: rate bands must be positive, ordered, and the "
                                       "respiration band below the heart band");
    if (!(o->meas_sigma > 0) || !(o->q_base >= 0) || !(o->q_harm >= 0) || !(o->accel > 0) ||
        !(o->gate > 0) || !(o->lost_after > 0) || !(o->max_reproj > 0) || !(o->window_sigmas > 0) ||
        o->min_window < 8 || o->reacquire_bands < 1 || o->reacquire_bands > 64 ||
        !(o->min_motion >= 0) || !(o->camera_px >= 0))
        return sh_error_set(SH_EINVAL, "tracker: a noise, gate, window or timing option is out of range");
    if (o->num_ids < 0 || o->num_ids > MAXM || (o->num_ids > 0 && !o->ids))
        return sh_error_set(SH_ERANGE, "tracker: %d marker ids (at most %d)", o->num_ids, MAXM);
    for (int i = 0; i < o->num_ids; i++) {
        if (o->ids[i] < 0) return sh_error_set(SH_EINVAL, "tracker: negative marker id %d", o->ids[i]);
        for (int j = 0; j < i; j++)
            if (o->ids[i] == o->ids[j])
                return sh_error_set(SH_EINVAL, "tracker: marker id %d listed twice", o->ids[i]);
    }
    int ncam = 1, dim = 2;
    if (calib && calib->num_cameras > 1) {
        if (calib->num_cameras > MAXC)
            return sh_error_set(SH_ERANGE, "tracker: %d cameras (at most %d)", calib->num_cameras, MAXC);
        for (int c = 0; c < calib->num_cameras; c++) {
            sh_status st = sh_camera_check(&calib->cam[c], c);
            if (st) return st;
        }
        ncam = calib->num_cameras;
        dim = 3;
    }
    sh_tracker *t = calloc(1, sizeof *t);
    if (!t) return sh_error_set(SH_ENOMEM, "tracker: out of memory");
    t->hist = malloc(sizeof(float) * MAXM * 3 * SH_TRACK_HISTORY);
    t->scratch = malloc(sizeof(double) * MAXM * 3 * SH_TRACK_HISTORY);
    t->ring_len = (int)ceil(o->lost_after * o->fps) + 2;
    t->ring_x = malloc(sizeof(double) * (size_t)t->ring_len * MAXM * 3 * NS);
    t->ring_ok = calloc((size_t)t->ring_len * MAXM, 1);
    t->ring_frame = malloc(sizeof(int) * (size_t)t->ring_len);
    if (!t->hist || !t->scratch || !t->ring_x || !t->ring_ok || !t->ring_frame || trk_rates_init(t) != SH_OK) {
        sh_tracker_destroy(t);
        return sh_error_set(SH_ENOMEM, "tracker: out of memory");
    }
    for (size_t i = 0; i < (size_t)MAXM * 3 * SH_TRACK_HISTORY; i++) t->hist[i] = NAN;
    for (int i = 0; i < t->ring_len; i++) t->ring_frame[i] = -1;
    t->o = *o;
    t->o.ids = NULL;
    if (t->o.camera_px == 0) t->o.camera_px = fmax(2.0, 0.004 * hypot(o->width, o->height));
    t->num_ids = o->num_ids;
    for (int i = 0; i < o->num_ids; i++) t->ids[i] = o->ids[i];
    t->dim = dim;
    t->ncam = ncam;
    if (calib) t->calib = *calib;
    for (int c = 0; c < MAXC; c++) t->cams[c] = &t->calib.cam[c];
    t->unit = dim == 2 ? 1.0 : 0.0;
    /* keep >= 8 s of history whatever the frame rate */
    t->decim = (int)ceil(o->fps * 8.0 / SH_TRACK_HISTORY);
    if (t->decim < 1) t->decim = 1;
    t->hist_last = -1;
    t->prev_frame = -1;
    /* whitelisted markers have their slots from the start */
    for (int i = 0; i < t->num_ids; i++) t->m[i].id = t->ids[i];
    t->nm = t->num_ids;
    *out = t;
    return SH_OK;
}

void sh_tracker_destroy(sh_tracker *t)
{
    if (!t) return;
    free(t->hist);
    free(t->scratch);
    free(t->ring_x);
    free(t->ring_ok);
    free(t->ring_frame);
    trk_rates_free(t);
    free(t);
}

int sh_tracker_dim(const sh_tracker *t) { return t->dim; }
int sh_tracker_num_cameras(const sh_tracker *t) { return t->ncam; }

/* ---- per frame ---- */

static int slot_of(const sh_tracker *t, int id)
{
    for (int i = 0; i < t->nm; i++)
        if (t->m[i].id == id) return i;
    return -1;
}

void trk_marker_pos(const sh_tracker *t, const marker *mk, double *p, double *var)
{
    for (int a = 0; a < t->dim; a++) {
        p[a] = trk_hx(t, &mk->f[a]);
        if (var) var[a] = trk_hph(t, &mk->f[a]);
    }
}

sh_status sh_tracker_predict(sh_tracker *t, int frame)
{
    if (!t) return sh_error_set(SH_EINVAL, "tracker: missing");
    if (frame < 0 || frame > 2000000000) return sh_error_set(SH_EINVAL, "tracker: frame %d", frame);
    if (t->started && frame < t->frame)
        return sh_error_set(SH_EINVAL, "tracker: frame %d after frame %d", frame, t->frame);
    if (!t->started) {
        t->started = 1;
        t->frame = frame;
        t->next_rates = frame + (int)ceil(t->o.fps * 0.5);
        /* first history sample */
    }
    int steps = frame - t->frame;
    if (steps > 0) {
        double dt = steps / t->o.fps, F[NS * NS];
        trk_transition(t, dt, F);
        for (int i = 0; i < t->nm; i++) {
            marker *mk = &t->m[i];
            if (!mk->init) continue;
            for (int a = 0; a < t->dim; a++) trk_predict_filter(t, &mk->f[a], F, dt);
            mk->age += steps;
        }
    }
    t->frame = frame;
    /* clear the history samples up to this frame */
    long s = frame / t->decim;
    if (s > t->hist_last + SH_TRACK_HISTORY) t->hist_last = s - SH_TRACK_HISTORY;
    while (t->hist_last < s) {
        t->hist_last++;
        long k = t->hist_last % SH_TRACK_HISTORY;
        for (int i = 0; i < MAXM * 3; i++) t->hist[(size_t)i * SH_TRACK_HISTORY + k] = NAN;
    }
    t->updated = 0;
    for (int i = 0; i < t->nm; i++) {
        marker *mk = &t->m[i];
        mk->measured = 0;
        mk->spatial = 0;
        if (mk->init) trk_marker_pos(t, mk, mk->pos, NULL);
    }
    return SH_OK;
}

/* Beyond the tag's black border a window holds at least TRK_WINDOW_MARGIN px and at least
 * TRK_WINDOW_QUIET of the tag's half-size: libapriltag finds the border by its edge against the
 * white quiet zone outside it, and a window that cuts into that zone too closely loses the tag.
 * 4 px + 4 sigma was enough at 1080p, but the prediction's misfit after the lock grows with the
 * image scale (a 4K view of the same heart moves twice the pixels) while sigma, from noises given in
 * px, does not: on a 4K phantom (exvivo, seed 3, 198 frames) the windows lost 114 of 3168 tags
 * after the lock, every frame of the fast phase degraded. An eighth of the half-size (half of
 * tag36h11's one-module quiet zone, which is a quarter of the half-size) grows with the tag's image,
 * i.e. with the scale: 0 lost at 4K, the same detections and errors at 1080p, where it adds about
 * 2 px a side. */
#define TRK_WINDOW_MARGIN 4
#define TRK_WINDOW_QUIET 0.125

sh_status sh_tracker_windows(const sh_tracker *t, int cam, sh_window *out, int max, int *count)
{
    if (!t || !count || (max > 0 && !out) || cam < 0 || cam >= t->ncam)
        return sh_error_set(SH_EINVAL, "tracker windows: bad arguments (camera %d)", cam);
    int n = 0;
    for (int i = 0; i < t->nm; i++) {
        const marker *mk = &t->m[i];
        if (!mk->init || mk->lost) continue;
        double xy[2], S[4];
        if (!trk_predicted_xy(t, mk, cam, NULL, NULL, xy, S)) continue;
        double tr = S[0] + S[3], det = S[0] * S[3] - S[1] * S[2];
        double lmax = 0.5 * tr + sqrt(fmax(0, 0.25 * tr * tr - det));
        /* the tag's bounding box (a tag seen square-on fills half its circumscribed circle's
         * square: per-call cost grows with the pixels) plus the prediction's uncertainty plus a
         * margin for the tag's white border; before a detection, a square of the largest extent */
        double hw[2];
        for (int a = 0; a < 2; a++) {
            double ext = mk->half[cam][a] > 0 ? mk->half[cam][a]
                         : mk->extent[cam] > 0 ? mk->extent[cam] : 0.5 * t->o.min_window;
            hw[a] = ext + t->o.window_sigmas * sqrt(lmax) + fmax(TRK_WINDOW_MARGIN, TRK_WINDOW_QUIET * ext);
            if (hw[a] < 0.5 * t->o.min_window) hw[a] = 0.5 * t->o.min_window;
        }
        if (!isfinite(xy[0]) || !isfinite(xy[1]) || !isfinite(hw[0]) || !isfinite(hw[1])) continue;
        double x0 = floor(xy[0] - hw[0]), y0 = floor(xy[1] - hw[1]);
        double x1 = ceil(xy[0] + hw[0]) + 1, y1 = ceil(xy[1] + hw[1]) + 1;
        if (x0 < 0) x0 = 0;
        if (y0 < 0) y0 = 0;
        if (x1 > t->o.width) x1 = t->o.width;
        if (y1 > t->o.height) y1 = t->o.height;
        if (x1 - x0 < 8 || y1 - y0 < 8) continue;
        if (n < max) out[n] = (sh_window){(int)x0, (int)y0, (int)(x1 - x0), (int)(y1 - y0)};
        n++;
    }
    *count = n < max ? n : max;
    return SH_OK;
}

sh_status sh_tracker_reacquire(sh_tracker *t, int cam, sh_window *out, int *count)
{
    if (!t || !out || !count || cam < 0 || cam >= t->ncam)
        return sh_error_set(SH_EINVAL, "tracker reacquire: bad arguments (camera %d)", cam);
    int need = t->num_ids == 0;
    for (int i = 0; i < t->nm && !need; i++)
        if (!t->m[i].init || t->m[i].lost) need = 1;
    *count = 0;
    if (!need) return SH_OK;
    int nb = t->o.reacquire_bands;
    double ext = 0;
    for (int i = 0; i < t->nm; i++)
        for (int c = 0; c < t->ncam; c++) ext = fmax(ext, t->m[i].extent[c]);
    /* a tag spans at most 2 ext rows: bands overlapping by ext (plus its white border) hold every
     * tag whole in one of them */
    int overlap = (int)fmax(1.25 * ext + 4, 0.05 * t->o.height);
    int b = (t->band + cam) % nb;
    int y0 = (int)((long)t->o.height * b / nb) - overlap;
    int y1 = (int)((long)t->o.height * (b + 1) / nb) + overlap;
    if (y0 < 0) y0 = 0;
    if (y1 > t->o.height) y1 = t->o.height;
    *out = (sh_window){0, y0, t->o.width, y1 - y0};
    *count = 1;
    return SH_OK;
}

int sh_tracker_rescan(const sh_tracker *t, int cam, const sh_detection *det, int n)
{
    if (!t || cam < 0 || cam >= t->ncam || (n > 0 && !det)) return 0;
    int expected = 0, found = 0;
    for (int i = 0; i < t->nm; i++) {
        const marker *mk = &t->m[i];
        double xy[2], S[4];
        if (!mk->init || mk->lost || !trk_predicted_xy(t, mk, cam, NULL, NULL, xy, S)) continue;
        if (!(xy[0] >= 0 && xy[1] >= 0 && xy[0] < t->o.width && xy[1] < t->o.height)) continue;
        expected++;
        for (int k = 0; k < n; k++)
            if (det[k].id == mk->id) {
                found++;
                break;
            }
    }
    return expected >= 3 && 2 * found < expected;
}

double sh_tracker_tag_side(const sh_tracker *t, int cam)
{
    if (!t || cam < 0 || cam >= t->ncam) return 0;
    double best = 0;
    for (int i = 0; i < t->nm; i++) {
        const marker *mk = &t->m[i];
        if (!mk->init || mk->lost || !mk->quad_ok[cam]) continue;
        double side = 0;
        for (int k = 0; k < 4; k++)
            side += 0.25 * hypot(mk->quad[cam][(k + 1) % 4][0] - mk->quad[cam][k][0],
                                 mk->quad[cam][(k + 1) % 4][1] - mk->quad[cam][k][1]);
        if (side > 0 && (best == 0 || side < best)) best = side;
    }
    return best;
}

/* Counts each marker's detections per camera (a negative or untracked id, or a centre not
 * finite, counts as unknown); with auto ids an unseen id takes a new slot. */
static void assign_detections(sh_tracker *t, const sh_detection *const *det, const int *count, int num_cameras)
{
    for (int i = 0; i < t->nm; i++)
        for (int c = 0; c < MAXC; c++) t->m[i].ndet[c] = t->m[i].used[c] = 0;
    /* ids: count per camera, new slots for unseen ids in auto mode */
    for (int c = 0; c < num_cameras; c++)
        for (int k = 0; k < count[c]; k++) {
            const sh_detection *d = &det[c][k];
            if (d->id < 0 || !isfinite(d->cx) || !isfinite(d->cy)) {
                t->stats.unknown++;
                continue;
            }
            int s = slot_of(t, d->id);
            if (s < 0 && t->num_ids == 0 && t->nm < MAXM) {
                s = t->nm++;
                memset(&t->m[s], 0, sizeof t->m[s]);
                t->m[s].id = d->id;
            }
            if (s < 0) {
                t->stats.unknown++;
                continue;
            }
            if (t->m[s].ndet[c]++ == 0) t->m[s].det[c] = k;
        }
}

/* The detections that are evidence, for a safety gate downstream. */
static void keep_evidence(sh_tracker *t, const sh_detection *const *det)
{
    for (int i = 0; i < t->nm; i++) {
        marker *mk = &t->m[i];
        for (int c = 0; c < t->ncam; c++) {
            mk->det_ok[c] = mk->ndet[c] == 1 &&
                            ((mk->measured && mk->used[c]) || (mk->cons == 1 && mk->cons_well[c]));
            if (mk->det_ok[c]) {
                const sh_detection *d = &det[c][mk->det[c]];
                mk->det_xy[c][0] = d->cx;
                mk->det_xy[c][1] = d->cy;
            }
        }
    }
}

/* This frame's states, for the spatial model. */
static void record_states(sh_tracker *t)
{
    int q = t->frame % t->ring_len;
    t->ring_frame[q] = t->frame;
    double *rx = t->ring_x + (size_t)q * MAXM * 3 * NS;
    unsigned char *rok = t->ring_ok + (size_t)q * MAXM;
    for (int j = 0; j < t->nm; j++) {
        rok[j] = (unsigned char)(t->m[j].init && t->m[j].measured);
        if (rok[j])
            for (int a = 0; a < t->dim; a++) memcpy(rx + ((size_t)j * 3 + a) * NS, t->m[j].f[a].x, sizeof(double) * NS);
    }
}

/* The reported estimates: every marker's position and variances, lost when unseen too long,
 * else corrected by its neighbours when unseen this frame. */
static void report_estimates(sh_tracker *t)
{
    /* before the rates are known the constant-velocity model is no predictor worth reporting for
     * more than a fifth of a second */
    int lost_frames = (int)ceil((t->locked ? t->o.lost_after : fmin(0.2, t->o.lost_after)) * t->o.fps);
    for (int i = 0; i < t->nm; i++) {
        marker *mk = &t->m[i];
        if (!mk->init) continue;
        double var[3];
        trk_marker_pos(t, mk, mk->pos, var);
        memset(mk->cov, 0, sizeof mk->cov);
        for (int a = 0; a < t->dim; a++) mk->cov[a * t->dim + a] = var[a];
    }
    for (int i = 0; i < t->nm; i++) {
        marker *mk = &t->m[i];
        if (!mk->init) continue;
        double var[3];
        for (int a = 0; a < t->dim; a++) var[a] = mk->cov[a * t->dim + a];
        if (!mk->measured && mk->age > lost_frames) {
            if (!mk->lost) t->stats.lost++;
            mk->lost = 1;
            continue;
        }
        if (!mk->measured && t->o.spatial == SH_SPATIAL_FUSE && t->locked) {
            double corr[3], vs[3];
            if (trk_spatial_estimate(t, mk, i, corr, vs)) {
                /* the correction is believed in proportion to how unsure the prediction is */
                for (int a = 0; a < t->dim; a++) {
                    double w = var[a] / (var[a] + vs[a]);
                    mk->pos[a] += w * corr[a];
                    mk->cov[a * t->dim + a] = var[a] * vs[a] / (var[a] + vs[a]);
                }
                mk->spatial = 1;
            }
        }
        /* confirmation: a listed id at once; with auto ids below, when judged */
        if (!mk->confirmed && t->num_ids > 0) mk->confirmed = 1;
    }
}

sh_status sh_tracker_update(sh_tracker *t, const sh_detection *const *det, const int *count,
                            int num_cameras)
{
    if (!t || (num_cameras > 0 && (!det || !count)))
        return sh_error_set(SH_EINVAL, "tracker update: missing detections");
    if (!t->started) return sh_error_set(SH_EINVAL, "tracker update: sh_tracker_predict first");
    if (t->updated) return sh_error_set(SH_EINVAL, "tracker update: frame %d updated twice", t->frame);
    if (num_cameras != t->ncam)
        return sh_error_set(SH_EINVAL, "tracker update: %d cameras given, the tracker has %d",
                            num_cameras, t->ncam);
    for (int c = 0; c < num_cameras; c++)
        if (count[c] < 0 || count[c] > SH_TRACK_MAX_DETECTIONS || (count[c] > 0 && !det[c]))
            return sh_error_set(SH_ERANGE, "tracker update: camera %d: %d detections (at most %d)",
                                c, count[c], SH_TRACK_MAX_DETECTIONS);
    t->updated = 1;
    t->stats.frames++;
    assign_detections(t, det, count, num_cameras);
    trk_calib_observe(t, det, num_cameras);
    /* the detections against each other first: a motion they agree on is taken at once */
    trk_consensus(t, det, num_cameras);
    /* markers the spatial model can vouch for are gated against it: first every marker whose own
     * prediction is sure (seen last frame, or rates not locked yet), then the others against
     * their prediction corrected by those neighbours (a marker unseen for a while has a wide
     * gate of its own, which a partly hidden tag's quad would pass) */
    for (int pass = 0; pass < 2; pass++)
        for (int i = 0; i < t->nm; i++) {
            marker *mk = &t->m[i];
            int vouch = (!t->locked || t->frame < mk->cut_until) &&
                        t->o.spatial == SH_SPATIAL_FUSE && mk->init && mk->age > 1;
            if (vouch != pass) continue;
            trk_update_marker(t, i, det, num_cameras);
            if (pass == 0 && mk->measured) trk_marker_pos(t, mk, mk->pos, NULL);
        }
    keep_evidence(t, det);
    record_states(t);
    report_estimates(t);
    if (t->frame >= t->next_rates) {
        if (t->num_ids == 0) trk_confirm_auto(t);
        trk_estimate_rates(t);
        t->next_rates = t->frame + (int)ceil(t->o.fps * 0.5);
    }
    for (int i = 0; i < t->nm; i++) {
        marker *mk = &t->m[i];
        mk->prev_frame = mk->measured ? t->frame : -1;
        if (mk->measured) memcpy(mk->prev_pos, mk->pos, sizeof mk->prev_pos);
    }
    t->prev_frame = t->frame;
    t->band = (t->band + 1) % t->o.reacquire_bands;
    return SH_OK;
}

int sh_tracker_estimates(const sh_tracker *t, sh_track_estimate *out, int max)
{
    if (!t || !out || max <= 0) return 0;
    /* id order */
    int order[MAXM], n = 0;
    for (int i = 0; i < t->nm; i++)
        if (t->m[i].init) order[n++] = i;
    for (int i = 1; i < n; i++)
        for (int j = i; j > 0 && t->m[order[j - 1]].id > t->m[order[j]].id; j--) {
            int tmp = order[j];
            order[j] = order[j - 1];
            order[j - 1] = tmp;
        }
    int w = 0;
    for (int q = 0; q < n && w < max; q++) {
        const marker *mk = &t->m[order[q]];
        sh_track_estimate *e = &out[w++];
        memset(e, 0, sizeof *e);
        e->id = mk->id;
        e->dim = t->dim;
        e->confirmed = mk->confirmed;
        e->age = mk->age;
        e->seen = mk->seen;
        e->spatial = mk->spatial;
        e->status = mk->lost ? SH_TRACK_LOST : mk->measured ? SH_TRACK_MEASURED : SH_TRACK_PREDICTED;
        for (int c = 0; c < t->ncam; c++) {
            e->det_ok[c] = mk->det_ok[c];
            e->det_xy[c][0] = mk->det_ok[c] ? mk->det_xy[c][0] : NAN;
            e->det_xy[c][1] = mk->det_ok[c] ? mk->det_xy[c][1] : NAN;
        }
        if (mk->lost) {
            for (int a = 0; a < 3; a++) e->pos[a] = NAN;
            for (int a = 0; a < 9; a++) e->cov[a] = NAN;
            continue;
        }
        memcpy(e->pos, mk->pos, sizeof e->pos);
        memcpy(e->cov, mk->cov, sizeof e->cov);
        for (int c = 0; c < t->ncam; c++) {
            if (t->dim == 2) {
                e->xy[c][0] = mk->pos[0];
                e->xy[c][1] = mk->pos[1];
                e->in_view[c] = 1;
            } else {
                e->in_view[c] = sh_camera_project(t->cams[c], mk->pos, e->xy[c], NULL) == SH_OK;
            }
        }
    }
    return w;
}

void sh_tracker_stats(const sh_tracker *t, sh_track_stats *stats)
{
    if (t && stats) *stats = t->stats;
}

void sh_track_rate_text(double hz, char *out, size_t cap)
{
    if (hz > 0) snprintf(out, cap, "%.3f Hz", hz);
    else snprintf(out, cap, "not estimated yet");
}

void sh_tracker_motion(const sh_tracker *t, sh_track_motion *out)
{
    if (t && out) *out = t->motion;
}
