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

sh_status track_sim_run(const track_sim_config *c, const sh_track_options *topts, track_sim_result *r)
{
    static phantom_model m;
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
    sh_status st = phantom_model_build(&po, &m);
    if (st) return st;
    memset(r, 0, sizeof *r);
    r->lock_frame = -1;
    r->true_heart_hz = m.heart_hz;
    r->true_resp_hz = m.resp_hz;

    sh_calib calib;
    phantom_calibration(&m, &calib);
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
    o.fps = m.fps;
    o.width = m.width;
    o.height = m.height;
    o.spatial = c->spatial;
    int ids[PHANTOM_MAX_MARKERS];
    for (int i = 0; i < m.num_markers; i++) ids[i] = m.marker[i].id;
    if (!c->auto_ids) {
        o.ids = ids;
        o.num_ids = m.num_markers;
    } else {
        o.ids = NULL;
        o.num_ids = 0;
    }
    sh_tracker *t;
    st = sh_tracker_create(&o, c->cameras > 1 ? &calib : NULL, &t);
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
    double vis_px = 0, vis_mm = 0, hid_px = 0, hid_mm = 0, raw = 0;
    long raw_n = 0;
    int prev_status[PHANTOM_MAX_MARKERS] = {0}, prev_age[PHANTOM_MAX_MARKERS] = {0};
    double prev_sig[PHANTOM_MAX_MARKERS] = {0};
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
            for (int i = 0; i < m.num_markers; i++) {
                if (hiding && hide[i]) continue;
                int vis[5], nvis = 0;
                for (int k = 0; k < 5; k++) nvis += vis[k] = phantom_marker_visible(&m, cam, tt, i, k);
                if (nvis == 0) continue;
                if (urand(&rng) < c->dropout) continue;
                int partial = nvis < 5;
                if (partial && (c->partial_shift <= 0 || urand(&rng) > 0.3)) continue;
                sh_detection *d = &dets[cam][count[cam]];
                memset(d, 0, sizeof *d);
                d->id = m.marker[i].id;
                double X[3], x, y;
                phantom_marker_point(&m, i, 4, tt, X);
                if (!phantom_project(&m.cam[cam], X, &x, &y)) continue;
                d->cx = x + c->noise_px * nrand(&rng);
                d->cy = y + c->noise_px * nrand(&rng);
                if (cam == 0 && !partial) {
                    raw += hypot(d->cx - x, d->cy - y);
                    raw_n++;
                }
                for (int k = 0; k < 4; k++) {
                    phantom_marker_point(&m, i, k, tt, X);
                    phantom_project(&m.cam[cam], X, &d->corner[k][0], &d->corner[k][1]);
                    d->corner[k][0] += c->noise_px * nrand(&rng);
                    d->corner[k][1] += c->noise_px * nrand(&rng);
                }
                if (partial) {
                    corrupt_quad(d, vis, c->partial_shift, c->noise_px, &rng);
                    corrupted[cam][i] = 1;
                    r->corrupted_fed++;
                }
                d->margin = 50;
                count[cam]++;
                if (count[cam] >= SH_TRACK_MAX_DETECTIONS - 2) break;
            }
            /* the decoy: a real tag of the family off the heart */
            if (m.decoy) {
                double X[3], x, y;
                phantom_decoy_point(&m, 4, tt, X);
                if (phantom_point_visible(&m, cam, tt, X) && phantom_project(&m.cam[cam], X, &x, &y)) {
                    sh_detection *d = &dets[cam][count[cam]++];
                    memset(d, 0, sizeof *d);
                    d->id = m.decoy_id;
                    d->cx = x + c->noise_px * nrand(&rng);
                    d->cy = y + c->noise_px * nrand(&rng);
                    for (int k = 0; k < 4; k++) {
                        phantom_decoy_point(&m, k, tt, X);
                        phantom_project(&m.cam[cam], X, &d->corner[k][0], &d->corner[k][1]);
                    }
                    d->margin = 50;
                }
            }
            /* a duplicated id (as in a photo of many copies of one tag) far from the marker */
            if (c->duplicate_rate > 0 && urand(&rng) < c->duplicate_rate && count[cam] > 0) {
                int k = (int)(urand(&rng) * count[cam]);
                if (k >= count[cam]) k = count[cam] - 1;
                sh_detection *d = &dets[cam][count[cam]++];
                *d = dets[cam][k];
                d->cx = fmod(d->cx + 300, m.width);
                d->cy = fmod(d->cy + 200, m.height);
                for (int i = 0; i < m.num_markers; i++)
                    if (m.marker[i].id == d->id) corrupted[cam][i] = 1;
                r->corrupted_fed++;
            }
        }
        st = sh_tracker_update(t, dp, count, c->cameras);
        if (st) break;
        sh_track_stats ts;
        sh_tracker_stats(t, &ts);
        if (ts.locked && r->lock_frame < 0) r->lock_frame = f;
        int counted = ts.locked || c->all_frames; /* this frame's errors and counts are kept */
        int n = sh_tracker_estimates(t, est, SH_TRACK_MAX_MARKERS);
        if (counted) {
            /* the detection rate: every visible marker, whether the tracker reports it or not */
            for (int i = 0; i < m.num_markers; i++) {
                if ((hiding && hide[i]) || !phantom_marker_visible(&m, 0, tt, i, 4)) continue;
                r->visible++;
                for (int q = 0; q < n; q++)
                    if (est[q].id == m.marker[i].id && est[q].confirmed && est[q].status == SH_TRACK_MEASURED) {
                        r->found++;
                        break;
                    }
            }
        }
        for (int q = 0; q < n; q++) {
            const sh_track_estimate *e = &est[q];
            int i = -1;
            for (int k = 0; k < m.num_markers; k++)
                if (m.marker[k].id == e->id) i = k;
            if (i < 0) {
                if (e->confirmed && e->status != SH_TRACK_LOST) r->decoy_reported++;
                continue;
            }
            int hidden_now = hiding && hide[i];
            int ps = prev_status[i], pa = prev_age[i];
            prev_status[i] = (int)e->status;
            prev_age[i] = e->age;
            double psig = prev_sig[i];
            prev_sig[i] = sqrt(fabs(e->cov[0]));
            (void)ps;
            (void)pa;
            if (e->status == SH_TRACK_LOST) {
                if (hidden_now) r->hid_lost++;
                continue;
            }
            if (!e->confirmed || !counted) continue;
            double X[3], x, y;
            phantom_marker_point(&m, i, 4, tt, X);
            if (!phantom_project(&m.cam[0], X, &x, &y) || !e->in_view[0]) continue;
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
                hid_px += err;
                hid_mm += emm;
                r->hid_count++;
                if (err > r->hid_max_px) r->hid_max_px = err;
            } else if (e->status == SH_TRACK_MEASURED) {
                vis_px += err;
                vis_mm += emm;
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
    if (trace) fclose(trace);
    r->decoy_reported = r->decoy_reported; /* counted per frame */
    r->false_corr += r->decoy_reported;
    if (r->vis_count) {
        r->vis_mean_px = vis_px / r->vis_count;
        r->vis_mean_mm = vis_mm / r->vis_count;
    }
    if (r->hid_count) {
        r->hid_mean_px = hid_px / r->hid_count;
        r->hid_mean_mm = hid_mm / r->hid_count;
    }
    r->raw_mean_px = raw_n ? raw / raw_n : 0;
    sh_tracker_stats(t, &r->stats);
    sh_tracker_calibration(t, &r->calibration);
    r->heart_hz = r->stats.heart_hz;
    r->resp_hz = r->stats.resp_hz;
    sh_tracker_destroy(t);
    return st;
}
