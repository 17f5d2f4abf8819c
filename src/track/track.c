/* Marker tracker: a Kalman filter per marker and coordinate over a baseline + Fourier series of the
 * heartbeat and respiration (rotating form), rates estimated online from all markers' recent
 * tracks; gating, duplicates, loss, search windows, reacquisition bands, 2D or 3D, and the
 * spatial estimate of occluded markers from their visible neighbours. See docs/tracking.md.
 *
 * Everything is sized at create (one allocation); nothing allocates per frame. */
#include <math.h>
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
    o->min_motion = 2.0;
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
        !(o->min_motion >= 0))
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
    if (!t->hist || !t->scratch || !t->ring_x || !t->ring_ok || !t->ring_frame) {
        sh_tracker_destroy(t);
        return sh_error_set(SH_ENOMEM, "tracker: out of memory");
    }
    for (size_t i = 0; i < (size_t)MAXM * 3 * SH_TRACK_HISTORY; i++) t->hist[i] = NAN;
    for (int i = 0; i < t->ring_len; i++) t->ring_frame[i] = -1;
    t->o = *o;
    t->o.ids = NULL;
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

static void marker_pos(const sh_tracker *t, const marker *mk, double *p, double *var)
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
        if (mk->init) marker_pos(t, mk, mk->pos, NULL);
    }
    return SH_OK;
}

/* predicted image position and 2x2 covariance of marker mk in camera c; 0 when not in view */
static int predicted_xy(const sh_tracker *t, const marker *mk, int c, double xy[2], double S[4])
{
    double p[3], var[3];
    marker_pos(t, mk, p, var);
    if (t->dim == 2) {
        xy[0] = p[0];
        xy[1] = p[1];
        S[0] = var[0];
        S[1] = S[2] = 0;
        S[3] = var[1];
        return 1;
    }
    double J[6];
    if (sh_camera_project(t->cams[c], p, xy, J)) return 0;
    for (int i = 0; i < 2; i++)
        for (int j = 0; j < 2; j++) {
            double s = 0;
            for (int k = 0; k < 3; k++) s += J[3 * i + k] * var[k] * J[3 * j + k];
            S[2 * i + j] = s;
        }
    return 1;
}

sh_status sh_tracker_windows(const sh_tracker *t, int cam, sh_window *out, int max, int *count)
{
    if (!t || !count || (max > 0 && !out) || cam < 0 || cam >= t->ncam)
        return sh_error_set(SH_EINVAL, "tracker windows: bad arguments (camera %d)", cam);
    int n = 0;
    for (int i = 0; i < t->nm; i++) {
        const marker *mk = &t->m[i];
        if (!mk->init || mk->lost) continue;
        double xy[2], S[4];
        if (!predicted_xy(t, mk, cam, xy, S)) continue;
        double tr = S[0] + S[3], det = S[0] * S[3] - S[1] * S[2];
        double lmax = 0.5 * tr + sqrt(fmax(0, 0.25 * tr * tr - det));
        double ext = mk->extent[cam] > 0 ? mk->extent[cam] : 0.5 * t->o.min_window;
        double half = ext + t->o.window_sigmas * sqrt(lmax) + 4;
        if (half < 0.5 * t->o.min_window) half = 0.5 * t->o.min_window;
        if (!isfinite(xy[0]) || !isfinite(xy[1]) || !isfinite(half)) continue;
        double x0 = floor(xy[0] - half), y0 = floor(xy[1] - half);
        double x1 = ceil(xy[0] + half) + 1, y1 = ceil(xy[1] + half) + 1;
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
    int overlap = (int)fmax(2 * ext + 8, 0.05 * t->o.height);
    int b = (t->band + cam) % nb;
    int y0 = (int)((long)t->o.height * b / nb) - overlap;
    int y1 = (int)((long)t->o.height * (b + 1) / nb) + overlap;
    if (y0 < 0) y0 = 0;
    if (y1 > t->o.height) y1 = t->o.height;
    *out = (sh_window){0, y0, t->o.width, y1 - y0};
    *count = 1;
    return SH_OK;
}

/* Spatial estimate for marker `self`, unseen since frame t0: every neighbour measured now and at
 * t0 is predicted open loop from its state at t0 (as `self` is); the neighbours' errors of those
 * predictions (what the temporal model got wrong: a rate change, an irregular beat, a drift) are
 * interpolated at `self` by a distance-weighted affine fit (moving least squares over the first
 * two coordinates: the surface is a graph over them) and added to its own prediction. Writes the
 * correction and its variance; 0 when no neighbour qualifies. */
static int spatial_estimate(const sh_tracker *t, const marker *mk, int self, double *corr, double *var)
{
    int slot = -1;
    for (int q = 0; q < t->ring_len; q++)
        if (t->ring_frame[q] == mk->last_frame) slot = q;
    if (slot < 0 || mk->last_frame >= t->frame) return 0;
    const double *rx = t->ring_x + (size_t)slot * MAXM * 3 * NS;
    const unsigned char *rok = t->ring_ok + (size_t)slot * MAXM;
    double F[NS * NS];
    trk_transition(t, (t->frame - mk->last_frame) / t->o.fps, F);
    double ref_self[3];
    for (int a = 0; a < t->dim; a++) ref_self[a] = trk_hx(t, (const axis_filter *)(rx + ((size_t)self * 3 + a) * NS));
    int nn = 0;
    double d2[MAXM], ref[MAXM][2], err[MAXM][3];
    for (int j = 0; j < t->nm; j++) {
        if (j == self || !t->m[j].measured || !rok[j]) continue;
        for (int a = 0; a < t->dim; a++) {
            const double *x0 = rx + ((size_t)j * 3 + a) * NS;
            double h[NS], pred = 0, r0 = trk_hx(t, (const axis_filter *)x0);
            trk_h_row(t, h);
            for (int i = 0; i < NS; i++) {
                if (h[i] == 0) continue;
                for (int k = 0; k < NS; k++) pred += h[i] * F[i * NS + k] * x0[k];
            }
            err[nn][a] = t->m[j].pos[a] - pred;
            if (a < 2) ref[nn][a] = r0 - ref_self[a];
        }
        d2[nn] = ref[nn][0] * ref[nn][0] + ref[nn][1] * ref[nn][1];
        nn++;
    }
    if (nn < 1) return 0;
    /* bandwidth: distance to the 4th nearest neighbour */
    double best[4] = {INFINITY, INFINITY, INFINITY, INFINITY};
    for (int k = 0; k < nn; k++) {
        double v = d2[k];
        for (int q = 0; q < 4; q++)
            if (v < best[q]) {
                double tmp = best[q];
                best[q] = v;
                v = tmp;
            }
    }
    double h2 = best[nn < 4 ? nn - 1 : 3];
    if (!(h2 > 0)) h2 = 1;
    double A[9] = {0}, B[3][3] = {{0}}, wsum = 0, w[MAXM];
    for (int k = 0; k < nn; k++) {
        w[k] = exp(-d2[k] / (2 * h2));
        double phi[3] = {1, ref[k][0], ref[k][1]};
        for (int a = 0; a < 3; a++)
            for (int b = 0; b < 3; b++) A[3 * a + b] += w[k] * phi[a] * phi[b];
        for (int a = 0; a < t->dim; a++)
            for (int b = 0; b < 3; b++) B[a][b] += w[k] * phi[b] * err[k][a];
        wsum += w[k];
    }
    /* ridge on the slopes keeps 1-2 neighbours or a line of them usable (a translation) */
    A[4] += 1e-2 * h2 * wsum;
    A[8] += 1e-2 * h2 * wsum;
    double c00 = A[4] * A[8] - A[5] * A[7], c01 = A[5] * A[6] - A[3] * A[8], c02 = A[3] * A[7] - A[4] * A[6];
    double det = A[0] * c00 + A[1] * c01 + A[2] * c02;
    if (!(fabs(det) > 0)) return 0;
    double r0 = c00 / det, r1 = (A[2] * A[7] - A[1] * A[8]) / det, r2 = (A[1] * A[5] - A[2] * A[4]) / det;
    double u = t->unit > 0 ? t->unit : 1;
    for (int a = 0; a < t->dim; a++) {
        corr[a] = r0 * B[a][0] + r1 * B[a][1] + r2 * B[a][2];
        /* the weighted scatter of the neighbours' errors about the correction, plus detection noise */
        double ss = 0;
        for (int k = 0; k < nn; k++) ss += w[k] * (err[k][a] - corr[a]) * (err[k][a] - corr[a]);
        var[a] = ss / wsum + t->o.meas_sigma * t->o.meas_sigma * u * u;
    }
    return 1;
}

static void apply_measurement(sh_tracker *t, int mi, const double *z, const double *r)
{
    marker *mk = &t->m[mi];
    double u = t->unit > 0 ? t->unit : 1;
    if (!mk->init || mk->lost) {
        if (!mk->init) {
            for (int a = 0; a < t->dim; a++) {
                double vv = t->o.accel * u * 0.1;
                trk_init_filter(&mk->f[a], z[a], r[a], t->locked ? 0 : vv * vv);
                if (t->locked) {
                    double amp = 20.0 * u;
                    for (int k = 0; k < t->nh; k++) {
                        int i = 2 + 2 * k;
                        mk->f[a].P[i * NS + i] = mk->f[a].P[(i + 1) * NS + i + 1] = amp * amp;
                    }
                }
            }
            mk->init = 1;
        } else {
            /* back from lost: the baseline restarts at the detection, the rhythm is kept */
            for (int a = 0; a < t->dim; a++) {
                double big = 16 * u * u;
                mk->f[a].P[0] += big;
                trk_update_filter(t, &mk->f[a], z[a], r[a]);
            }
        }
        mk->lost = 0;
    } else {
        for (int a = 0; a < t->dim; a++) trk_update_filter(t, &mk->f[a], z[a], r[a]);
    }
    mk->measured = 1;
    mk->last_frame = t->frame;
    mk->age = 0;
    mk->seen++;
    long k = t->hist_last % SH_TRACK_HISTORY;
    if (t->frame % t->decim == 0)
        for (int a = 0; a < t->dim; a++) trk_hist_at(t, mi, a)[k] = (float)z[a];
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
    for (int i = 0; i < t->nm; i++)
        for (int c = 0; c < MAXC; c++) t->m[i].ndet[c] = 0;
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
    double u = t->unit > 0 ? t->unit : 1;
    double sig2 = t->o.meas_sigma * t->o.meas_sigma;
    for (int i = 0; i < t->nm; i++) {
        marker *mk = &t->m[i];
        double uv[2 * MAXC];
        const sh_calib_camera *vc[MAXC];
        int cam_of[MAXC], nv = 0, gated_now = 0;
        for (int c = 0; c < num_cameras; c++) {
            if (mk->ndet[c] == 0) continue;
            if (mk->ndet[c] > 1) {
                t->stats.duplicates += mk->ndet[c];
                continue;
            }
            const sh_detection *d = &det[c][mk->det[c]];
            double z[2] = {d->cx, d->cy};
            /* every detection of a known marker is gated, a lost one's too (its covariance has
             * grown with the time unseen); only a run of rejections as long as the reacquire
             * delay lets a lost marker restart from the detections alone */
            int valve = 0;
            if (mk->lost && mk->rejects >= (int)ceil(t->o.fps * 0.5)) {
                /* ... and only when those detections agree with each other (a steady offset) */
                double mx = mk->rej_sum[0] / mk->rejects, my = mk->rej_sum[1] / mk->rejects;
                double spread2 = mk->rej_ss / mk->rejects - mx * mx - my * my;
                valve = spread2 < 1.5 * 1.5;
            }
            if (mk->init && !valve) {
                double xy[2], S[4];
                if (!predicted_xy(t, mk, c, xy, S)) {
                    t->stats.gated++;
                    continue;
                }
                S[0] += sig2;
                S[3] += sig2;
                double e0 = z[0] - xy[0], e1 = z[1] - xy[1];
                double dt = S[0] * S[3] - S[1] * S[2];
                double m2 = (S[3] * e0 * e0 - (S[1] + S[2]) * e0 * e1 + S[0] * e1 * e1) / dt;
                if (!(m2 <= t->o.gate)) {
                    t->stats.gated++;
                    if (!gated_now) {
                        if (mk->rejects == 0) mk->rej_sum[0] = mk->rej_sum[1] = mk->rej_ss = 0;
                        mk->rej_sum[0] += e0;
                        mk->rej_sum[1] += e1;
                        mk->rej_ss += e0 * e0 + e1 * e1;
                    }
                    gated_now = 1;
                    continue;
                }
            }
            double ext = 0;
            for (int q = 0; q < 4; q++)
                ext = fmax(ext, hypot(d->corner[q][0] - d->cx, d->corner[q][1] - d->cy));
            if (isfinite(ext) && ext < 0.5 * t->o.width) mk->extent[c] = ext;
            uv[2 * nv] = z[0];
            uv[2 * nv + 1] = z[1];
            vc[nv] = t->cams[c];
            cam_of[nv++] = c;
        }
        (void)cam_of;
        if (nv == 0) {
            mk->rejects = gated_now ? mk->rejects + 1 : 0;
            continue;
        }
        double zm[3], rm[3];
        if (t->dim == 2) {
            zm[0] = uv[0];
            zm[1] = uv[1];
            rm[0] = rm[1] = sig2;
        } else {
            if (nv < 2) continue; /* one view does not fix a point in space */
            sh_triangulation tr;
            sh_status st = sh_camera_triangulate(vc, uv, nv, t->o.meas_sigma, 5, &tr);
            if ((st || tr.max_err > t->o.max_reproj) && nv == 3) {
                /* one bad view among three: the best consistent pair */
                double best = INFINITY;
                sh_triangulation bt;
                for (int drop = 0; drop < 3; drop++) {
                    const sh_calib_camera *pc[2];
                    double puv[4];
                    int q = 0;
                    for (int v = 0; v < 3; v++)
                        if (v != drop) {
                            pc[q] = vc[v];
                            puv[2 * q] = uv[2 * v];
                            puv[2 * q + 1] = uv[2 * v + 1];
                            q++;
                        }
                    sh_triangulation pt;
                    if (sh_camera_triangulate(pc, puv, 2, t->o.meas_sigma, 5, &pt) == SH_OK &&
                        pt.max_err < best) {
                        best = pt.max_err;
                        bt = pt;
                    }
                }
                if (best <= t->o.max_reproj) {
                    tr = bt;
                    st = SH_OK;
                    t->stats.inconsistent++;
                }
            }
            if (st || tr.max_err > t->o.max_reproj) {
                t->stats.inconsistent++;
                continue;
            }
            if (t->unit == 0) {
                /* mm per pixel at this depth in camera 0: the scale of the pixel-valued options */
                double C[3];
                sh_camera_center(t->cams[0], C);
                double dd = sqrt((tr.X[0] - C[0]) * (tr.X[0] - C[0]) + (tr.X[1] - C[1]) * (tr.X[1] - C[1]) +
                                 (tr.X[2] - C[2]) * (tr.X[2] - C[2]));
                t->unit = dd / t->cams[0]->K[0];
                u = t->unit;
            }
            for (int a = 0; a < 3; a++) {
                zm[a] = tr.X[a];
                rm[a] = tr.cov[4 * a];
            }
        }
        t->stats.accepted += nv;
        mk->rejects = 0;
        apply_measurement(t, i, zm, rm);
    }
    /* this frame's states for the spatial model */
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
    /* reported estimates */
    /* before the rates are known the constant-velocity model is no predictor worth reporting for
     * more than a fifth of a second */
    int lost_frames = (int)ceil((t->locked ? t->o.lost_after : fmin(0.2, t->o.lost_after)) * t->o.fps);
    for (int i = 0; i < t->nm; i++) {
        marker *mk = &t->m[i];
        if (!mk->init) continue;
        double var[3];
        marker_pos(t, mk, mk->pos, var);
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
            if (spatial_estimate(t, mk, i, corr, vs)) {
                /* the correction is believed in proportion to how unsure the prediction is */
                for (int a = 0; a < t->dim; a++) {
                    double w = var[a] / (var[a] + vs[a]);
                    mk->pos[a] += w * corr[a];
                    mk->cov[a * t->dim + a] = var[a] * vs[a] / (var[a] + vs[a]);
                }
                mk->spatial = 1;
            }
        }
        /* confirmation: a listed id, or (auto) a marker that moves with the heart */
        if (!mk->confirmed) {
            if (t->num_ids > 0) mk->confirmed = 1;
            else if (t->locked) {
                double amp2 = 0;
                for (int a = 0; a < t->dim; a++)
                    for (int k = 0; k < t->nh; k++)
                        amp2 += mk->f[a].x[2 + 2 * k] * mk->f[a].x[2 + 2 * k] +
                                mk->f[a].x[3 + 2 * k] * mk->f[a].x[3 + 2 * k];
                if (mk->seen > t->o.fps && sqrt(amp2) >= t->o.min_motion * u) mk->confirmed = 1;
            }
        }
    }
    /* rates, every half second */
    if (t->frame >= t->next_rates) {
        trk_estimate_rates(t);
        t->next_rates = t->frame + (int)ceil(t->o.fps * 0.5);
    }
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
