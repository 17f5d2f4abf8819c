/* The per-marker half of the tracker's update (track.c runs it for every marker): the shape and
 * motion gates, the confirmation of lost or suspect markers, triangulation in 3D, and the Kalman
 * update; and the predictions it gates against (the marker's own, or corrected by the motion of its
 * neighbours: the spatial model). See docs/tracking.md. */
#include <math.h>
#include <string.h>

#include "track_internal.h"

/* predicted image position and 2x2 covariance of marker mk in camera c; 0 when not in view.
 * shift, fvar (or NULL): a correction of the state-space position and the variance after it. */
int trk_predicted_xy(const sh_tracker *t, const marker *mk, int c, const double *shift,
                        const double *fvar, double xy[2], double S[4])
{
    double p[3], var[3];
    trk_marker_pos(t, mk, p, var);
    if (shift)
        for (int a = 0; a < t->dim; a++) {
            p[a] += shift[a];
            var[a] = fvar[a];
        }
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

int trk_ring_at(const sh_tracker *t, int frame, const double **rx, const unsigned char **rok)
{
    int slot = -1;
    for (int q = 0; q < t->ring_len; q++)
        if (t->ring_frame[q] == frame) slot = q;
    if (slot < 0 || frame >= t->frame) return 0;
    *rx = t->ring_x + (size_t)slot * MAXM * 3 * NS;
    *rok = t->ring_ok + (size_t)slot * MAXM;
    return 1;
}

/* Spatial estimate for marker `self`, unseen since frame t0: every neighbour measured now and at
 * t0 is predicted open loop from its state at t0 (as `self` is); the neighbours' errors of those
 * predictions (what the temporal model got wrong: a rate change, an irregular beat, a drift) are
 * interpolated at `self` by a distance-weighted affine fit (moving least squares over the first
 * two coordinates: the surface is a graph over them) and added to its own prediction. Writes the
 * correction and its variance; 0 when no neighbour qualifies. */
int trk_spatial_estimate(const sh_tracker *t, const marker *mk, int self, double *corr, double *var)
{
    const double *rx;
    const unsigned char *rok;
    if (!trk_ring_at(t, mk->last_frame, &rx, &rok)) return 0;
    double F[NS * NS];
    trk_transition(t, (t->frame - mk->last_frame) / t->o.fps, F);
    double ref_self[3];
    for (int a = 0; a < t->dim; a++) ref_self[a] = trk_hx(t, (const axis_filter *)(rx + ((size_t)self * 3 + a) * NS));
    int nn = 0;
    double ref[MAXM][2], err[MAXM][3];
    unsigned char use[MAXM];
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
            if (a < 2) ref[nn][a] = r0;
        }
        use[nn++] = 1;
    }
    if (nn < 1 || !trk_field_at((const double(*)[2])ref, (const double(*)[3])err, use, nn, -1, t->dim, ref_self,
                                corr, var))
        return 0;
    /* the weighted scatter of the neighbours' errors about the correction, plus detection noise */
    double u = t->unit > 0 ? t->unit : 1;
    for (int a = 0; a < t->dim; a++) var[a] += t->o.meas_sigma * t->o.meas_sigma * u * u;
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

/* A lost (or suspect) marker is updated only on three detections, a few frames apart, whose offsets
 * from the prediction agree and whose quads have the same shape (its gate has grown wide while it
 * was unseen; a partly hidden tag's quad that passes it lands off in a new direction and with
 * another side cut each time, the tag itself does not). */
#define TRK_CONFIRM 2    /* successive agreeing pairs needed: two random cuts agree by chance ~5 % */
#define TRK_SUSPECT_S 2.0 /* seconds a marker whose quad was refused for its shape stays suspect */

static int confirmed_return(sh_tracker *t, marker *mk, int c, const sh_detection *d, double e0, double e1)
{
    double d0 = e0 - mk->pend_off[c][0], d1 = e1 - mk->pend_off[c][1];
    double sig2 = t->o.meas_sigma * t->o.meas_sigma;
    int last = mk->pend_frame[c] - 1;
    int ok = mk->pend_frame[c] > 0 && last < t->frame && last >= t->frame - 3 &&
             (d0 * d0 + d1 * d1) / (2 * sig2) <= t->o.gate &&
             trk_quad_similar(t, (const double(*)[2])mk->pend_quad[c], t->frame - last, d);
    mk->pend_agree[c] = ok ? mk->pend_agree[c] + 1 : 0;
    mk->pend_frame[c] = t->frame + 1;
    mk->pend_off[c][0] = e0;
    mk->pend_off[c][1] = e1;
    trk_quad_centred(d, mk->pend_quad[c]);
    return mk->pend_agree[c] >= TRK_CONFIRM;
}

/* A marker unseen for a while: its prediction corrected by its neighbours, as reported, in
 * shift with variance fvar; returns whether it is (not when its detection agrees with the other
 * markers' detections: that is the better evidence, consensus.c). */
static int fused_shift(sh_tracker *t, marker *mk, int i, double *shift, double *fvar)
{
    double corr[3], vs[3];
    int fused = mk->cons != 1 && (!t->locked || t->frame < mk->cut_until) && t->o.spatial == SH_SPATIAL_FUSE &&
                mk->init && mk->age > 1 &&
                trk_spatial_estimate(t, mk, i, corr, vs);
    if (fused) {
        double p[3], var[3];
        trk_marker_pos(t, mk, p, var);
        for (int a = 0; a < t->dim; a++) {
            shift[a] = var[a] / (var[a] + vs[a]) * corr[a];
            fvar[a] = var[a] * vs[a] / (var[a] + vs[a]);
        }
    }
    return fused;
}

/* Whether detection d of marker mk in camera c passes the shape test, the gate and, for a lost
 * or suspect marker, the confirmation; counts what it refuses. shift: the fused correction of
 * the prediction or NULL; *gated_now: set once a detection of this frame failed the gate. */
static int detection_accepted(sh_tracker *t, marker *mk, int c, const sh_detection *d, const double *shift,
                              const double *fvar, int *gated_now)
{
    double sig2 = t->o.meas_sigma * t->o.meas_sigma;
    double z[2] = {d->cx, d->cy};
    /* Before the rates lock, a lost marker's constant-velocity prediction has drifted on for
     * longer than it is worth (it is lost after 0.2 s), and neither it nor the offsets from it
     * settle, so gating against it kept the marker lost for good: a start that drops frames
     * (a busy box at 1080p) lost most markers that way and never stabilized. It starts
     * afresh, as at its first sighting, from its next detection that passes the shape test. */
    int well_shaped = trk_quad_check(t, mk, c, d);
    if (!t->locked && mk->lost && t->dim == 2 && well_shaped) mk->init = 0;
    if (!well_shaped) {
        t->stats.misshapen++;
        /* an occluder is cutting this tag: its next quads may be cut in ways the shape test
         * cannot see (a side moved along itself), so they need confirming for a while */
        mk->suspect_until = mk->cut_until = t->frame + (int)ceil(t->o.fps * TRK_SUSPECT_S);
        return 0;
    }
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
    if (!mk->init || valve) return 1;
    double xy[2], S[4];
    if (!trk_predicted_xy(t, mk, c, shift, fvar, xy, S)) {
        t->stats.gated++;
        return 0;
    }
    S[0] += sig2;
    S[3] += sig2;
    double e0 = z[0] - xy[0], e1 = z[1] - xy[1];
    double dt = S[0] * S[3] - S[1] * S[2];
    double m2 = (S[3] * e0 * e0 - (S[1] + S[2]) * e0 * e1 + S[0] * e1 * e1) / dt;
    if (!(m2 <= t->o.gate)) {
        t->stats.gated++;
        if (!*gated_now) {
            if (mk->rejects == 0) mk->rej_sum[0] = mk->rej_sum[1] = mk->rej_ss = 0;
            mk->rej_sum[0] += e0;
            mk->rej_sum[1] += e1;
            mk->rej_ss += e0 * e0 + e1 * e1;
        }
        *gated_now = 1;
        return 0;
    }
    if ((mk->lost || t->frame < mk->suspect_until) && !confirmed_return(t, mk, c, d, e0, e1)) {
        t->stats.held++;
        return 0;
    }
    return 1;
}

/* Keeps the extent of an accepted quad around its centre in camera c (a sane one only). */
static void learn_extent(sh_tracker *t, marker *mk, int c, const sh_detection *d)
{
    double ext = 0;
    for (int q = 0; q < 4; q++)
        ext = fmax(ext, hypot(d->corner[q][0] - d->cx, d->corner[q][1] - d->cy));
    if (isfinite(ext) && ext < 0.5 * t->o.width) {
        mk->extent[c] = ext;
        for (int a = 0; a < 2; a++) {
            double h = 0;
            for (int q = 0; q < 4; q++) h = fmax(h, fabs(d->corner[q][a] - (a ? d->cy : d->cx)));
            mk->half[c][a] = h;
        }
    }
}

/* The measurement zm and its variances rm from the nv accepted views uv (cameras vc): the pixel
 * itself in 2D, the triangulated point in 3D; 0 when the views do not make one. */
static int measurement(sh_tracker *t, const sh_calib_camera *const *vc, const double *uv, int nv, double *zm,
                       double *rm)
{
    double sig2 = t->o.meas_sigma * t->o.meas_sigma;
    if (t->dim == 2) {
        zm[0] = uv[0];
        zm[1] = uv[1];
        rm[0] = rm[1] = sig2;
        return 1;
    }
    if (nv < 2) return 0; /* one view does not fix a point in space */
    sh_triangulation tr;
    int pair;
    if (!trk_triangulate(t, vc, uv, nv, &tr, &pair)) {
        t->stats.inconsistent++;
        return 0;
    }
    t->stats.inconsistent += pair; /* one view of three dropped */
    if (t->unit == 0) {
        /* mm per pixel at this depth in camera 0: the scale of the pixel-valued options */
        double C[3];
        sh_camera_center(t->cams[0], C);
        double dd = sqrt((tr.X[0] - C[0]) * (tr.X[0] - C[0]) + (tr.X[1] - C[1]) * (tr.X[1] - C[1]) +
                         (tr.X[2] - C[2]) * (tr.X[2] - C[2]));
        t->unit = dd / t->cams[0]->K[0];
    }
    for (int a = 0; a < 3; a++) {
        zm[a] = tr.X[a];
        rm[a] = tr.cov[4 * a];
    }
    return 1;
}

/* Gates, triangulates (3D) and applies this frame's detections of marker i. */
void trk_update_marker(sh_tracker *t, int i, const sh_detection *const *det, int num_cameras)
{
    marker *mk = &t->m[i];
    double uv[2 * MAXC];
    const sh_calib_camera *vc[MAXC];
    int cam_of[MAXC], nv = 0, gated_now = 0;
    double shift[3] = {0, 0, 0}, fvar[3] = {0, 0, 0};
    int fused = fused_shift(t, mk, i, shift, fvar);
    for (int c = 0; c < num_cameras; c++) {
        if (mk->ndet[c] == 0) continue;
        if (mk->ndet[c] > 1) {
            t->stats.duplicates += mk->ndet[c];
            continue;
        }
        const sh_detection *d = &det[c][mk->det[c]];
        if (!detection_accepted(t, mk, c, d, fused ? shift : NULL, fvar, &gated_now)) continue;
        learn_extent(t, mk, c, d);
        uv[2 * nv] = d->cx;
        uv[2 * nv + 1] = d->cy;
        vc[nv] = t->cams[c];
        cam_of[nv++] = c;
    }
    if (nv == 0) {
        mk->rejects = gated_now ? mk->rejects + 1 : 0;
        return;
    }
    double zm[3], rm[3];
    if (!measurement(t, vc, uv, nv, zm, rm)) return;
    t->stats.accepted += nv;
    mk->rejects = 0;
    apply_measurement(t, i, zm, rm);
    for (int v = 0; v < nv; v++) mk->used[cam_of[v]] = 1;
    for (int v = 0; v < nv; v++) trk_quad_learn(t, mk, cam_of[v], &det[cam_of[v]][mk->det[cam_of[v]]]);
}
