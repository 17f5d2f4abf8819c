/* Tracker evaluation on the phantom's analytic truth (see sim.h). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "sim.h"

#define PI 3.14159265358979323846

void track_sim_default(track_sim_config *c)
{
    memset(c, 0, sizeof *c);
    c->preset = "invivo";
    c->cameras = 1;
    c->frames = 400;
    c->seed = 1;
    c->noise_px = 0.2;
    c->dropout = 0.01;
    c->partial_shift = 8.0;
    c->duplicate_rate = 0.0;
    c->hide_start = 7.0;
    c->spatial = SH_SPATIAL_FUSE;
}

static uint64_t rng_next(uint64_t *s)
{
    uint64_t z = (*s += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
}
static double urand(uint64_t *s) { return ((double)(rng_next(s) >> 11) + 0.5) / 9007199254740992.0; }
static double nrand(uint64_t *s) { return sqrt(-2 * log(urand(s))) * cos(2 * PI * urand(s)); }

/* A quad libapriltag fits to a partly hidden tag: the border it sees is cut or extended by the
 * occluder, so hidden corners land off by `shift` px. Half the time every hidden corner moves on
 * its own (the occluder covers corners); otherwise one side moves as a whole (an occluder along an
 * edge: the quad stays a parallelogram and only its size gives it away); an occluder over the
 * centre alone breaks a side too. The centre is where libapriltag puts it: the homography's image
 * of the tag centre, i.e. the intersection of the corrupted quad's diagonals. */
static void corrupt_quad(sh_detection *d, const int *vis, double shift, double noise, uint64_t *rng)
{
    int hidden = -1;
    for (int k = 0; k < 4; k++)
        if (!vis[k] && (hidden < 0 || urand(rng) < 0.5)) hidden = k;
    if (hidden >= 0 && urand(rng) < 0.5) {
        for (int k = 0; k < 4; k++) {
            if (vis[k]) continue;
            double a = 2 * PI * urand(rng);
            d->corner[k][0] += shift * cos(a);
            d->corner[k][1] += shift * sin(a);
        }
    } else {
        int k0 = hidden >= 0 ? hidden : (int)(urand(rng) * 4) & 3;
        int k1 = urand(rng) < 0.5 ? (k0 + 1) & 3 : (k0 + 3) & 3;
        double a = 2 * PI * urand(rng);
        for (int k = 0; k < 2; k++) {
            d->corner[k ? k1 : k0][0] += shift * cos(a);
            d->corner[k ? k1 : k0][1] += shift * sin(a);
        }
    }
    /* diagonals 0-2 and 1-3: p0 + s (p2 - p0) = p1 + u (p3 - p1) */
    double ax = d->corner[2][0] - d->corner[0][0], ay = d->corner[2][1] - d->corner[0][1];
    double bx = d->corner[3][0] - d->corner[1][0], by = d->corner[3][1] - d->corner[1][1];
    double cx = d->corner[1][0] - d->corner[0][0], cy = d->corner[1][1] - d->corner[0][1];
    double den = ax * by - ay * bx;
    if (fabs(den) < 1e-9) return;
    double s = (cx * by - cy * bx) / den;
    d->cx = d->corner[0][0] + s * ax + noise * nrand(rng);
    d->cy = d->corner[0][1] + s * ay + noise * nrand(rng);
}

/* The tracker for the phantom's rig: its calibration, swapped or scaled where the config asks. */
static sh_status sim_tracker_create(const track_sim_config *c, const sh_track_options *topts, const phantom_model *m,
                                    sh_tracker **t)
{
    sh_calib calib;
    phantom_calibration(m, &calib);
    if (c->swap_a != c->swap_b && c->swap_a < calib.num_cameras && c->swap_b < calib.num_cameras) {
        sh_calib_camera k = calib.cam[c->swap_a];
        calib.cam[c->swap_a] = calib.cam[c->swap_b];
        calib.cam[c->swap_b] = k;
    }
    if (c->t1_scale > 0 && calib.num_cameras > 1) {
        for (int a = 0; a < 3; a++) calib.cam[1].t[a] *= c->t1_scale;
        sh_calib_compute_p(&calib);
    }
    sh_track_options o = *topts;
    o.fps = m->fps;
    o.width = m->width;
    o.height = m->height;
    o.spatial = c->spatial;
    int ids[PHANTOM_MAX_MARKERS];
    for (int i = 0; i < m->num_markers; i++) ids[i] = m->marker[i].id;
    if (!c->auto_ids) {
        o.ids = ids;
        o.num_ids = m->num_markers;
    } else {
        o.ids = NULL;
        o.num_ids = 0;
    }
    return sh_tracker_create(&o, c->cameras > 1 ? &calib : NULL, t);
}

/* What a run adds up over its frames, and each marker's estimate in the frame before. */
typedef struct {
    double vis_px, vis_mm, hid_px, hid_mm, raw;
    long raw_n;
    int prev_status[PHANTOM_MAX_MARKERS], prev_age[PHANTOM_MAX_MARKERS];
    double prev_sig[PHANTOM_MAX_MARKERS];
} sim_sums;

/* One camera's detections at time tt: the visible markers with noise, dropouts and corrupted
 * quads, the decoy, and now and then a duplicated id; returns their count. */
static int sim_detect(const track_sim_config *c, const phantom_model *m, int cam, double tt, int hiding,
                      const int *hide, sh_detection *dets, unsigned char *corrupted, uint64_t *rng,
                      track_sim_result *r, sim_sums *sum)
{
    int count = 0;
    for (int i = 0; i < m->num_markers; i++) {
        if (hiding && hide[i]) continue;
        int vis[5], nvis = 0;
        for (int k = 0; k < 5; k++) nvis += vis[k] = phantom_marker_visible(m, cam, tt, i, k);
        if (nvis == 0) continue;
        if (urand(rng) < c->dropout) continue;
        int partial = nvis < 5;
        if (partial && (c->partial_shift <= 0 || urand(rng) > 0.3)) continue;
        sh_detection *d = &dets[count];
        memset(d, 0, sizeof *d);
        d->id = m->marker[i].id;
        double X[3], x, y;
        phantom_marker_point(m, i, 4, tt, X);
        if (!phantom_project(&m->cam[cam], X, &x, &y)) continue;
        d->cx = x + c->noise_px * nrand(rng);
        d->cy = y + c->noise_px * nrand(rng);
        if (cam == 0 && !partial) {
            sum->raw += hypot(d->cx - x, d->cy - y);
            sum->raw_n++;
        }
        for (int k = 0; k < 4; k++) {
            phantom_marker_point(m, i, k, tt, X);
            phantom_project(&m->cam[cam], X, &d->corner[k][0], &d->corner[k][1]);
            d->corner[k][0] += c->noise_px * nrand(rng);
            d->corner[k][1] += c->noise_px * nrand(rng);
        }
        if (partial) {
            corrupt_quad(d, vis, c->partial_shift, c->noise_px, rng);
            corrupted[i] = 1;
            r->corrupted_fed++;
        }
        d->margin = 50;
        count++;
        if (count >= SH_TRACK_MAX_DETECTIONS - 2) break;
    }
    /* the decoy: a real tag of the family off the heart */
    if (m->decoy) {
        double X[3], x, y;
        phantom_decoy_point(m, 4, tt, X);
        if (phantom_point_visible(m, cam, tt, X) && phantom_project(&m->cam[cam], X, &x, &y)) {
            sh_detection *d = &dets[count++];
            memset(d, 0, sizeof *d);
            d->id = m->decoy_id;
            d->cx = x + c->noise_px * nrand(rng);
            d->cy = y + c->noise_px * nrand(rng);
            for (int k = 0; k < 4; k++) {
                phantom_decoy_point(m, k, tt, X);
                phantom_project(&m->cam[cam], X, &d->corner[k][0], &d->corner[k][1]);
            }
            d->margin = 50;
        }
    }
    /* a duplicated id (as in a photo of many copies of one tag) far from the marker */
    if (c->duplicate_rate > 0 && urand(rng) < c->duplicate_rate && count > 0) {
        int k = (int)(urand(rng) * count);
        if (k >= count) k = count - 1;
        sh_detection *d = &dets[count++];
        *d = dets[k];
        d->cx = fmod(d->cx + 300, m->width);
        d->cy = fmod(d->cy + 200, m->height);
        for (int i = 0; i < m->num_markers; i++)
            if (m->marker[i].id == d->id) corrupted[i] = 1;
        r->corrupted_fed++;
    }
    return count;
}

/* Scores frame f's estimates against the truth: detection rate, errors of visible and hidden
 * markers, false corrections, and the trace rows. */
static void sim_score(const track_sim_config *c, const phantom_model *m, int f, double tt, int hiding,
                      const int *hide, const sh_track_estimate *est, int n, int counted,
                      unsigned char corrupted[][PHANTOM_MAX_MARKERS], FILE *trace, track_sim_result *r,
                      sim_sums *sum)
{
    if (counted) {
        /* the detection rate: every visible marker, whether the tracker reports it or not */
        for (int i = 0; i < m->num_markers; i++) {
            if ((hiding && hide[i]) || !phantom_marker_visible(m, 0, tt, i, 4)) continue;
            r->visible++;
            for (int q = 0; q < n; q++)
                if (est[q].id == m->marker[i].id && est[q].confirmed && est[q].status == SH_TRACK_MEASURED) {
                    r->found++;
                    break;
                }
        }
    }
    for (int q = 0; q < n; q++) {
        const sh_track_estimate *e = &est[q];
        int i = -1;
        for (int k = 0; k < m->num_markers; k++)
            if (m->marker[k].id == e->id) i = k;
        if (i < 0) {
            if (e->confirmed && e->status != SH_TRACK_LOST) r->decoy_reported++;
            continue;
        }
        int hidden_now = hiding && hide[i];
        int ps = sum->prev_status[i], pa = sum->prev_age[i];
        sum->prev_status[i] = (int)e->status;
        sum->prev_age[i] = e->age;
        double psig = sum->prev_sig[i];
        sum->prev_sig[i] = sqrt(fabs(e->cov[0]));
        if (e->status == SH_TRACK_LOST) {
            if (hidden_now) r->hid_lost++;
            continue;
        }
        if (!e->confirmed || !counted) continue;
        double X[3], x, y;
        phantom_marker_point(m, i, 4, tt, X);
        if (!phantom_project(&m->cam[0], X, &x, &y) || !e->in_view[0]) continue;
        double err = hypot(e->xy[0][0] - x, e->xy[0][1] - y);
        double emm = 0;
        if (e->dim == 3)
            emm = sqrt((e->pos[0] - X[0]) * (e->pos[0] - X[0]) + (e->pos[1] - X[1]) * (e->pos[1] - X[1]) +
                       (e->pos[2] - X[2]) * (e->pos[2] - X[2]));
        int corrupt_any = 0;
        for (int cam = 0; cam < c->cameras; cam++) corrupt_any |= corrupted[cam][i];
        if (e->status == SH_TRACK_MEASURED && corrupt_any && (e->dim == 2 ? err > 1.5 : emm > 1.0)) {
            r->false_corr++;
            if (getenv("SIM_DEBUG"))
                fprintf(stderr, "false: frame %d id %d err %.2f prev status %d prev age %d prev sigma %.3f\n", f, e->id,
                        err, ps, pa, psig);
        }
        if (hidden_now) {
            sum->hid_px += err;
            sum->hid_mm += emm;
            r->hid_count++;
            if (err > r->hid_max_px) r->hid_max_px = err;
        } else if (e->status == SH_TRACK_MEASURED) {
            sum->vis_px += err;
            sum->vis_mm += emm;
            r->vis_count++;
            if (err > r->vis_max_px) r->vis_max_px = err;
            if (emm > r->vis_max_mm) r->vis_max_mm = emm;
        }
        if (trace && hide[i] && tt >= c->hide_start - 1.0 && tt < c->hide_start + c->hide_duration + 1.0) {
            double sig = e->dim == 2 ? sqrt(0.5 * (e->cov[0] + e->cov[3])) : NAN;
            fprintf(trace, "%d,%.4f,%d,%d,%.4f,%.4f,%d,%d\n", f, tt, e->id, hidden_now, err, sig,
                    (int)e->status, e->spatial);
        }
    }
}

/* The phantom the config describes. */
static sh_status sim_model_build(const track_sim_config *c, phantom_model *m)
{
    phantom_options po;
    phantom_options_default(&po);
    po.preset = c->preset;
    po.cameras = c->cameras;
    po.frames = c->frames;
    po.seed = c->seed;
    po.occlusions = c->occlusions;
    po.camera_motion = c->camera_motion;
    po.camera_motion_at = c->camera_motion_at;
    po.first_beat = c->first_beat;
    po.first_beat_at = c->first_beat_at;
    po.dist = c->distortion;
    return phantom_model_build(&po, m);
}

sh_status track_sim_run(const track_sim_config *c, const sh_track_options *topts, track_sim_result *r)
{
    static phantom_model m;
    sh_status st = sim_model_build(c, &m);
    if (st) return st;
    memset(r, 0, sizeof *r);
    r->lock_frame = -1;
    r->true_heart_hz = m.heart_hz;
    r->true_resp_hz = m.resp_hz;
    sh_tracker *t;
    st = sim_tracker_create(c, topts, &m, &t);
    if (st) return st;

    uint64_t rng = c->seed * 7919 + 17;
    /* the markers to hide: a seeded pick of round(fraction * n) */
    int hide[PHANTOM_MAX_MARKERS] = {0};
    int nhide = (int)lround(c->hide_fraction * m.num_markers);
    for (int k = 0; k < nhide;) {
        int i = (int)(urand(&rng) * m.num_markers);
        if (i >= m.num_markers || hide[i]) continue;
        hide[i] = 1;
        k++;
    }
    FILE *trace = c->trace_path ? fopen(c->trace_path, "w") : NULL;
    if (trace) fprintf(trace, "frame,t,id,hidden,err_px,sigma_px,status,spatial\n");

    static sh_detection dets[SH_TRACK_MAX_CAMERAS][SH_TRACK_MAX_DETECTIONS];
    static unsigned char corrupted[SH_TRACK_MAX_CAMERAS][PHANTOM_MAX_MARKERS];
    sh_track_estimate est[SH_TRACK_MAX_MARKERS];
    sim_sums sum;
    memset(&sum, 0, sizeof sum);
    for (int f = 0; f < m.frames; f++) {
        double tt = f / m.fps;
        int hiding = tt >= c->hide_start && tt < c->hide_start + c->hide_duration;
        st = sh_tracker_predict(t, f);
        if (st) break;
        int count[SH_TRACK_MAX_CAMERAS] = {0};
        const sh_detection *dp[SH_TRACK_MAX_CAMERAS];
        memset(corrupted, 0, sizeof corrupted);
        for (int cam = 0; cam < c->cameras; cam++) {
            dp[cam] = dets[cam];
            count[cam] = sim_detect(c, &m, cam, tt, hiding, hide, dets[cam], corrupted[cam], &rng, r, &sum);
        }
        st = sh_tracker_update(t, dp, count, c->cameras);
        if (st) break;
        sh_track_stats ts;
        sh_tracker_stats(t, &ts);
        if (ts.locked && r->lock_frame < 0) r->lock_frame = f;
        int counted = ts.locked || c->all_frames; /* this frame's errors and counts are kept */
        int n = sh_tracker_estimates(t, est, SH_TRACK_MAX_MARKERS);
        sim_score(c, &m, f, tt, hiding, hide, est, n, counted, corrupted, trace, r, &sum);
    }
    if (trace) fclose(trace);
    r->false_corr += r->decoy_reported; /* the decoy counted per frame */
    if (r->vis_count) {
        r->vis_mean_px = sum.vis_px / r->vis_count;
        r->vis_mean_mm = sum.vis_mm / r->vis_count;
    }
    if (r->hid_count) {
        r->hid_mean_px = sum.hid_px / r->hid_count;
        r->hid_mean_mm = sum.hid_mm / r->hid_count;
    }
    r->raw_mean_px = sum.raw_n ? sum.raw / sum.raw_n : 0;
    sh_tracker_stats(t, &r->stats);
    sh_tracker_calibration(t, &r->calibration);
    r->heart_hz = r->stats.heart_hz;
    r->resp_hz = r->stats.resp_hz;
    sh_tracker_destroy(t);
    return st;
}
