/* Detections against each other before each against its model (docs/tracking.md, "When the
 * detections disagree with the model").
 *
 * The motion model is fitted to a few seconds of history; a unique-id AprilTag in a well-shaped
 * quad is much stronger evidence. When the heart makes a motion the model has not seen (a first
 * beat faster than any before it, a beat early or late) or the endoscope is moved or bumped,
 * markers are detected outside their own gates, and gating each against its own prediction
 * throws away exactly the evidence that tells what happened. So before the per-marker gate,
 * every marker detected once, well shaped, is compared with what its neighbours' detections say:
 * its innovation (detection minus prediction) against a smooth field interpolated from the
 * others' (leave-one-out, distance-weighted affine fit, as the spatial model); or, when its own
 * prediction has drifted, its displacement since it was last accepted against theirs. A lone
 * outlier (a cut quad, a tag moved by an instrument) disagrees with its neighbours both ways and
 * is still refused. When the agreeing markers all moved by one translation of the image (the
 * camera moved, not the heart), every marker, seen or not, and its history follow the view, and
 * the frame is flagged (sh_tracker_motion). An agreeing marker still outside its own gate has the
 * variance of its baseline raised so that the ordinary update takes its detection. */
#include <math.h>
#include <string.h>

#include "track_internal.h"

#define CONS_MIN 3      /* markers needed for a consensus (an affine field has 3 unknowns/axis) */
#define CONS_MAD_K 3.0  /* a marker agrees within this many robust sigmas of the others */
#define RIGID_FRAC 0.25 /* a translation leaving less than this fraction of the motion: the camera's */

/* Triangulates nv views; with three, falls back to the best consistent pair. 0 when no
 * consistent point; *pair = 1 when one view was dropped. */
int trk_triangulate(const sh_tracker *t, const sh_calib_camera *const *vc, const double *uv, int nv,
                    sh_triangulation *tr, int *pair)
{
    *pair = 0;
    if (nv < 2) return 0;
    sh_status st = sh_camera_triangulate(vc, uv, nv, t->o.meas_sigma, 5, tr);
    if (st == SH_OK && tr->max_err <= t->o.max_reproj) return 1;
    if (nv != 3) return 0;
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
        if (sh_camera_triangulate(pc, puv, 2, t->o.meas_sigma, 5, &pt) == SH_OK && pt.max_err < best) {
            best = pt.max_err;
            bt = pt;
        }
    }
    if (!(best <= t->o.max_reproj)) return 0;
    *tr = bt;
    *pair = 1;
    return 1;
}

int trk_field_at(const double (*pos)[2], const double (*val)[3], const unsigned char *use, int n, int self,
                 int dim, const double at[2], double *out, double *var)
{
    double d2[MAXM], best[4] = {INFINITY, INFINITY, INFINITY, INFINITY};
    int nn = 0;
    for (int j = 0; j < n; j++) {
        if (!use[j] || j == self) continue;
        double dx = pos[j][0] - at[0], dy = pos[j][1] - at[1];
        double v = d2[j] = dx * dx + dy * dy;
        nn++;
        for (int q = 0; q < 4; q++)
            if (v < best[q]) {
                double tmp = best[q];
                best[q] = v;
                v = tmp;
            }
    }
    if (nn < 1) return 0;
    double h2 = best[nn < 4 ? nn - 1 : 3];
    if (!(h2 > 0)) h2 = 1;
    double A[9] = {0}, B[3][3] = {{0}}, wsum = 0, w[MAXM];
    for (int j = 0; j < n; j++) {
        if (!use[j] || j == self) continue;
        w[j] = exp(-d2[j] / (2 * h2));
        double phi[3] = {1, pos[j][0] - at[0], pos[j][1] - at[1]};
        for (int a = 0; a < 3; a++)
            for (int b = 0; b < 3; b++) A[3 * a + b] += w[j] * phi[a] * phi[b];
        for (int a = 0; a < dim; a++)
            for (int b = 0; b < 3; b++) B[a][b] += w[j] * phi[b] * val[j][a];
        wsum += w[j];
    }
    /* ridge on the slopes: one or two contributors, or a line of them, give a translation */
    A[4] += 1e-2 * h2 * wsum;
    A[8] += 1e-2 * h2 * wsum;
    double c00 = A[4] * A[8] - A[5] * A[7], c01 = A[5] * A[6] - A[3] * A[8], c02 = A[3] * A[7] - A[4] * A[6];
    double det = A[0] * c00 + A[1] * c01 + A[2] * c02;
    if (!(fabs(det) > 0)) return 0;
    /* the fit is centred at `at`: its value there is the constant term (first row of A^-1 B) */
    double r0 = c00 / det, r1 = (A[2] * A[7] - A[1] * A[8]) / det, r2 = (A[1] * A[5] - A[2] * A[4]) / det;
    for (int a = 0; a < dim; a++) {
        out[a] = r0 * B[a][0] + r1 * B[a][1] + r2 * B[a][2];
        double ss = 0;
        for (int j = 0; j < n; j++)
            if (use[j] && j != self) ss += w[j] * (val[j][a] - out[a]) * (val[j][a] - out[a]);
        var[a] = ss / wsum;
    }
    return 1;
}

/* Moves marker i's baseline (and its states kept for the spatial model) by d, with var added to
 * the baseline's variance, and its history by h (the camera moved: its past positions are where
 * the heart would have been seen from the new view); either may be NULL. */
static void shift_marker(sh_tracker *t, int i, const double *d, const double *var, const double *h)
{
    marker *mk = &t->m[i];
    for (int a = 0; a < t->dim; a++) {
        if (d) {
            mk->f[a].x[0] += d[a];
            mk->f[a].P[0] += var[a];
            mk->pos[a] += d[a];
            for (int q = 0; q < t->ring_len; q++)
                if (t->ring_frame[q] >= 0) t->ring_x[(((size_t)q * MAXM + i) * 3 + a) * NS] += d[a];
        }
        if (h) {
            float *hs = trk_hist_at(t, i, a);
            for (int k = 0; k < SH_TRACK_HISTORY; k++)
                if (!isnan(hs[k])) hs[k] += (float)h[a];
        }
    }
}

/* The common translation of the vectors v[k] (over use[k]) and the RMS of what it leaves; 0 when
 * fewer than CONS_MIN. */
static int translation(const double (*v)[3], const unsigned char *use, int n, int dim, double m[3], double *left)
{
    int cnt = 0;
    m[0] = m[1] = m[2] = 0;
    for (int k = 0; k < n; k++)
        if (use[k]) {
            for (int a = 0; a < dim; a++) m[a] += v[k][a];
            cnt++;
        }
    if (cnt < CONS_MIN) return 0;
    for (int a = 0; a < dim; a++) m[a] /= cnt;
    double ss = 0;
    for (int k = 0; k < n; k++)
        if (use[k])
            for (int a = 0; a < dim; a++) ss += (v[k][a] - m[a]) * (v[k][a] - m[a]);
    *left = sqrt(ss / cnt);
    return 1;
}

static double norm(const double *v, int dim)
{
    double s = 0;
    for (int a = 0; a < dim; a++) s += v[a] * v[a];
    return sqrt(s);
}

/* One marker's candidate measurement this frame: its single well-shaped detection in each
 * camera that has one, as a state-space point (2D: the centre; 3D: triangulated) with its
 * variance. 0 when it has none usable. */
static int candidate(sh_tracker *t, marker *mk, const sh_detection *const *det, int num_cameras,
                     double z[3], double r[3])
{
    double uv[2 * MAXC];
    const sh_calib_camera *vc[MAXC];
    int nv = 0;
    for (int c = 0; c < num_cameras; c++) {
        if (mk->ndet[c] != 1) continue;
        const sh_detection *d = &det[c][mk->det[c]];
        if (!trk_quad_check(t, mk, c, d)) continue;
        mk->cons_well[c] = 1;
        uv[2 * nv] = d->cx;
        uv[2 * nv + 1] = d->cy;
        vc[nv++] = t->cams[c];
    }
    if (nv == 0) return 0;
    double sig2 = t->o.meas_sigma * t->o.meas_sigma;
    if (t->dim == 2) {
        z[0] = uv[0];
        z[1] = uv[1];
        r[0] = r[1] = sig2;
        return 1;
    }
    sh_triangulation tr;
    int pair;
    if (t->unit == 0 || !trk_triangulate(t, vc, uv, nv, &tr, &pair)) return 0;
    for (int a = 0; a < 3; a++) {
        z[a] = tr.X[a];
        r[a] = tr.cov[4 * a];
    }
    return 1;
}

/* This frame's candidates: per marker its position (the prediction), detection (state space),
 * innovation and detection variance; cand: it has a usable detection; use: it agrees. */
typedef struct {
    double pos[MAXM][2], e[MAXM][3], z[MAXM][3], r[MAXM][3];
    unsigned char cand[MAXM], use[MAXM];
    int nc, inliers;
} frame_set;

/* The deviation of candidate i's innovation from the field of the others in use at its place
 * (INFINITY when there is no field). */
static double deviation(const sh_tracker *t, const frame_set *fs, int i)
{
    double f[3], fv[3], s = 0;
    if (!trk_field_at(fs->pos, fs->e, fs->use, t->nm, i, t->dim, fs->pos[i], f, fv)) return INFINITY;
    for (int a = 0; a < t->dim; a++) s += (fs->e[i][a] - f[a]) * (fs->e[i][a] - f[a]);
    return sqrt(s);
}

/* The detection noise of marker i and of the field (about as much): the floor of agreement. */
static double noise_floor(const sh_tracker *t, const frame_set *fs, int i)
{
    double rr = 0;
    for (int a = 0; a < t->dim; a++) rr += fs->r[i][a];
    return sqrt(t->o.gate * 2 * rr / t->dim);
}

/* Whether what the consensus motion leaves of candidate i's innovation is within its own gate,
 * widened by how far the others' motion is from one smooth field (the field's scatter): the
 * marker moved with its neighbours, as far as the heart's deformation lets one tell. A lone
 * outlier keeps its whole deviation; a corner marker on a heart that bulges keeps only what the
 * bulge adds, which the others' scatter shows. */
static int explained(const sh_tracker *t, const frame_set *fs, int i)
{
    double f[3], fv[3], m2 = 0;
    if (!trk_field_at(fs->pos, fs->e, fs->use, t->nm, i, t->dim, fs->pos[i], f, fv)) return 0;
    for (int a = 0; a < t->dim; a++) {
        double r = fs->e[i][a] - f[a];
        m2 += r * r / (trk_hph(t, &t->m[i].f[a]) + fs->r[i][a] + fv[a]);
    }
    return m2 <= t->o.gate;
}

/* For a candidate whose innovation disagrees, its own prediction may have drifted (cut or missed
 * for a few frames, refitted badly, a beat its rhythm did not expect): then the innovation says
 * more about its model than about its detection. Does its detection agree with its neighbours' by
 * how far each moved since its last accepted detection, at t0? Its displacement against the
 * field of the agreeing neighbours' displacements over the same time (their states at t0 are kept
 * for the spatial model), within the detection noise and tol (the innovations' bound). A tag left
 * behind on an instrument when the camera moved stays where it was while its neighbours moved:
 * refused however long it stays. Not for a marker an occluder is at (a quad of it was refused
 * for its shape lately): its next quads may be cut in ways the shape test cannot see, and they
 * are confirmed one after another instead (gate.c). */
static int displacement_agrees(const sh_tracker *t, const frame_set *fs, int i, double tol)
{
    const marker *mk = &t->m[i];
    const double *rx;
    const unsigned char *rok;
    if (t->frame < mk->suspect_until || !trk_ring_at(t, mk->last_frame, &rx, &rok)) return 0;
    double p0[MAXM][2], d[MAXM][3];
    unsigned char use[MAXM] = {0};
    int n = 0;
    for (int j = 0; j < t->nm; j++) {
        if ((j != i && !fs->use[j]) || !rok[j]) continue;
        for (int a = 0; a < t->dim; a++) {
            double x0 = trk_hx(t, (const axis_filter *)(rx + ((size_t)j * 3 + a) * NS));
            d[j][a] = fs->z[j][a] - x0;
            if (a < 2) p0[j][a] = x0;
        }
        use[j] = j != i;
        n += j != i;
    }
    double f[3], var[3], dev = 0;
    if (n < CONS_MIN || !rok[i] ||
        !trk_field_at((const double(*)[2])p0, (const double(*)[3])d, use, t->nm, i, t->dim, p0[i], f, var))
        return 0;
    for (int a = 0; a < t->dim; a++) dev += (d[i][a] - f[a]) * (d[i][a] - f[a]);
    return sqrt(dev) <= fmax(noise_floor(t, fs, i), tol);
}

/* Leave-one-out agreement: sets fs->use and fs->inliers; 0 when no majority of at least CONS_MIN
 * agrees on anything. The worst marker is left out of the others' fits one at a time (an outlier
 * pulls its neighbours' fits toward it, so judging all at once with its pull in them can make it
 * look no worse than they do) while it deviates more than the floor and 3 robust sigmas of how
 * well the others, without it, predict each other (how smooth this frame's motion is); then the
 * ones left out are judged once more against the final set. */
static int agree(const sh_tracker *t, frame_set *fs)
{
    double dev[MAXM], tol = 0;
    fs->inliers = fs->nc;
    for (;;) {
        int worst = -1;
        for (int i = 0; i < t->nm; i++) {
            if (!fs->use[i]) continue;
            dev[i] = deviation(t, fs, i);
            if (worst < 0 || dev[i] > dev[worst]) worst = i;
        }
        if (worst < 0) return 0;
        double others[MAXM];
        int no = 0;
        fs->use[worst] = 0;
        for (int i = 0; i < t->nm; i++)
            if (fs->use[i]) {
                double d = deviation(t, fs, i);
                if (isfinite(d)) others[no++] = d;
            }
        tol = fmax(noise_floor(t, fs, worst), no ? CONS_MAD_K * 1.4826 * trk_median(others, no) : 0);
        if (!(dev[worst] > tol)) {
            fs->use[worst] = 1;
            break;
        }
        /* no majority agrees on anything */
        if (--fs->inliers < CONS_MIN || 2 * fs->inliers < fs->nc) return 0;
    }
    unsigned char back[MAXM] = {0};
    for (int i = 0; i < t->nm; i++)
        back[i] = fs->cand[i] && !fs->use[i] &&
                  (deviation(t, fs, i) <= fmax(tol, noise_floor(t, fs, i)) || explained(t, fs, i) ||
                   displacement_agrees(t, fs, i, tol));
    for (int i = 0; i < t->nm; i++)
        if (back[i]) {
            fs->use[i] = 1;
            fs->inliers++;
        }
    return 1;
}

/* The camera moved when the agreeing markers all moved by one translation of at least camera_px
 * that leaves little else: either beyond what the model predicted (their innovations; not in the
 * frame after the filters were refitted to their history, whose first prediction can be off for
 * all alike: fresh) or since the last frame (their steps: before the rates lock the
 * constant-velocity model follows a smooth pan within its gates). The heart's own motion
 * contracts, twists and bulges: no one translation leaves it small. Then every marker follows the
 * view: its history by the whole translation, its baseline by what its prediction missed of it,
 * and before the rates lock its constant velocity loses what all markers share (the camera's: a
 * pan's velocity left in the state would overshoot at every frame after the camera stops, and a
 * bump taken by the update would put its jump into the velocity). */
static void camera(sh_tracker *t, frame_set *fs, int fresh)
{
    double u = t->unit > 0 ? t->unit : 1, thr = t->o.camera_px * u;
    double te[3], le, ts[3] = {0, 0, 0}, ls = 0, step[MAXM][3];
    unsigned char stepped[MAXM] = {0};
    for (int i = 0; i < t->nm; i++) {
        marker *mk = &t->m[i];
        if (!fs->use[i] || t->prev_frame < 0 || mk->prev_frame != t->prev_frame) continue;
        for (int a = 0; a < t->dim; a++) step[i][a] = fs->z[i][a] - mk->prev_pos[a];
        stepped[i] = 1;
    }
    if (!translation((const double(*)[3])fs->e, fs->use, t->nm, t->dim, te, &le)) return;
    int gap = t->frame - t->prev_frame;
    int by_innov = !fresh && norm(te, t->dim) >= thr && le <= RIGID_FRAC * norm(te, t->dim);
    int by_step = !by_innov && gap > 0 &&
                  translation((const double(*)[3])step, stepped, t->nm, t->dim, ts, &ls) &&
                  norm(ts, t->dim) >= thr * gap && ls <= RIGID_FRAC * norm(ts, t->dim);
    if (!by_innov && !by_step) return;
    const double *hist = by_innov ? te : ts;
    double tv[3];
    for (int a = 0; a < t->dim; a++) tv[a] = le * le / t->dim + t->o.meas_sigma * t->o.meas_sigma * u * u;
    double vm[3] = {0, 0, 0};
    int nv = 0;
    for (int i = 0; i < t->nm; i++) {
        if (!t->m[i].init || t->m[i].lost) continue;
        shift_marker(t, i, te, tv, hist);
        for (int a = 0; a < t->dim; a++) vm[a] += t->m[i].f[a].x[1];
        nv++;
    }
    /* before the lock: the velocity all markers share is the camera's, and goes with it */
    for (int i = 0; i < t->nm && !t->locked && nv; i++)
        if (t->m[i].init && !t->m[i].lost)
            for (int a = 0; a < t->dim; a++) t->m[i].f[a].x[1] -= vm[a] / nv;
    for (int i = 0; i < t->nm; i++)
        for (int a = 0; a < t->dim && fs->cand[i]; a++) fs->e[i][a] -= te[a];
    t->motion.camera = 1;
    t->motion.shift_px = norm(hist, t->dim) / u;
    t->motion.rigid_left_px = (by_innov ? le : ls) / u;
    t->stats.camera_moves++;
}

/* Agreeing markers still outside their own gate: the heart moved as the model did not expect.
 * The variance of their baseline grows by what the innovation exceeds (adaptive process noise),
 * so that the ordinary update takes the detection and moves the baseline most; the rhythm keeps
 * its covariance and learns from the updates that follow. Widening the whole covariance (a
 * fading memory) was tried first: one detection then threw the harmonics about, and on irregular
 * beats the next predictions were off by hundreds of pixels. Before the lock the model is a
 * constant velocity, and a marker outside its gate is one whose velocity lags the beat: the
 * excess then also goes into the velocity, as a velocity step at the start of the last step
 * (x, x/dt, x/dt^2), so the update takes the velocity that explains the innovation; left in the
 * position alone, the lag grew frame after frame until the consensus refused the marker (a
 * 110 beats/min heart at 4K, docs/tracking.md). As an acceleration over the step instead (the
 * model's own dt^4/4 : dt^3/2 : dt^2) the update moved the velocity twice as far and, on a
 * stronger bulge, overshot until a marker was lost. */
static void widen_baselines(sh_tracker *t, const frame_set *fs)
{
    int jumped = 0;
    double dt = (t->prev_frame >= 0 ? t->frame - t->prev_frame : 1) / t->o.fps;
    for (int i = 0; i < t->nm; i++) {
        if (!fs->use[i]) continue;
        marker *mk = &t->m[i];
        double m2 = 0;
        for (int a = 0; a < t->dim; a++) m2 += fs->e[i][a] * fs->e[i][a] / (trk_hph(t, &mk->f[a]) + fs->r[i][a]);
        if (m2 <= t->o.gate) continue;
        for (int a = 0; a < t->dim; a++) {
            double x = fmax(0, fs->e[i][a] * fs->e[i][a] - trk_hph(t, &mk->f[a]) - fs->r[i][a]);
            mk->f[a].P[0] += x;
            if (!t->locked && dt > 0) { /* a velocity step at the start of the last step */
                mk->f[a].P[1] += x / dt;
                mk->f[a].P[NS] += x / dt;
                mk->f[a].P[NS + 1] += x / (dt * dt);
            }
        }
        jumped++;
    }
    t->motion.jumped = jumped;
    t->motion.surface = 2 * jumped >= fs->inliers && jumped >= 2;
    t->stats.jumped += jumped;
}

void trk_consensus(sh_tracker *t, const sh_detection *const *det, int num_cameras)
{
    t->motion = (sh_track_motion){0};
    int fresh = t->fresh_fit;
    t->fresh_fit = 0;
    frame_set fs;
    memset(fs.cand, 0, sizeof fs.cand);
    memset(fs.use, 0, sizeof fs.use);
    fs.nc = 0;
    for (int i = 0; i < t->nm; i++) {
        marker *mk = &t->m[i];
        mk->cons = 0;
        memset(mk->cons_well, 0, sizeof mk->cons_well);
        if (!mk->init || mk->lost) continue;
        fs.pos[i][0] = mk->pos[0];
        fs.pos[i][1] = mk->pos[1];
        if (!candidate(t, mk, det, num_cameras, fs.z[i], fs.r[i])) continue;
        for (int a = 0; a < t->dim; a++) fs.e[i][a] = fs.z[i][a] - mk->pos[a];
        fs.cand[i] = fs.use[i] = 1;
        fs.nc++;
    }
    if (fs.nc < CONS_MIN || !agree(t, &fs)) return;
    for (int i = 0; i < t->nm; i++)
        if (fs.cand[i]) t->m[i].cons = fs.use[i] ? 1 : 2;
    t->motion.agreed = fs.inliers;
    camera(t, &fs, fresh);
    widen_baselines(t, &fs);
}
