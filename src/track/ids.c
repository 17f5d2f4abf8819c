/* Auto ids: which tags are markers on the heart (sh_tracker_judge_ids; docs/tracking.md).
 *
 * A tag's motion being small is no evidence: parts of the heart move by a pixel or two (near a
 * stabilizer pad, near the base), and refusing them drops correspondences the warp needs. What a
 * tag off the heart shows is a motion its neighbours do not predict: the surface is smooth, so a
 * tag on it moves much as the tags around it do (not equally: amplitudes differ by 2-4x across a
 * heart, but in step), while a tag on a card beside it stays still as they move, and one on an
 * instrument moves with the instrument, out of step with them. So every tag's displacement over
 * the history is set against the distance-weighted mean displacement of the others, and only
 * that comparison can leave a tag out. Reads the history only: nothing is written, nothing
 * allocated. */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "track_internal.h"

#define JUDGE_MIN_TAGS 3     /* other tags needed to predict one from its neighbours */
#define JUDGE_MIN_SEEN 3     /* samples a tag needs at least to be judged at all */
#define JUDGE_SEEN_FRACTION 0.05 /* ... and this share of the history's samples */
#define JUDGE_MIN_COMMON 8   /* samples where both it and its neighbours were seen */
#define JUDGE_NOISE_SNR 5    /* predicted motion over the detection noise before it counts */
#define JUDGE_QUIET 3        /* own RMS motion below this many times its noise's: not measurable */
#define JUDGE_STILL 0.25     /* ... and below this share of the predicted: still */
#define JUDGE_UNLIKE 0.3     /* share of its motion the neighbours' explains below this: unlike */

typedef struct {
    int cand;                /* seen consistently: a neighbour of the others */
    int seen;
    double mean[3], noise;   /* state units */
} tag_stats;

static const float *hist_of(const sh_tracker *t, int mi, int a)
{
    return t->hist + ((size_t)mi * 3 + a) * SH_TRACK_HISTORY;
}

/* The history's samples, oldest first: ring index of sample q in [0, n). */
static int hist_span(const sh_tracker *t, long *first)
{
    long n = t->hist_last + 1 < SH_TRACK_HISTORY ? t->hist_last + 1 : SH_TRACK_HISTORY;
    if (n < 0) n = 0;
    *first = t->hist_last - n + 1;
    return (int)n;
}

static int sample_at(const sh_tracker *t, int mi, long s, double *p)
{
    long k = s % SH_TRACK_HISTORY;
    for (int a = 0; a < t->dim; a++) {
        float v = hist_of(t, mi, a)[k];
        if (!isfinite(v)) return 0;
        p[a] = v;
    }
    return 1;
}

/* Seen count, mean position and detection noise (RMS of second differences of consecutive
 * samples over sqrt(6): white noise's, a smooth motion adds little to it). */
static void tag_summary(const sh_tracker *t, int mi, long first, int n, tag_stats *ts)
{
    memset(ts, 0, sizeof *ts);
    double p[3], q[2][3], dd = 0;
    int run = 0, nd = 0;
    for (int i = 0; i < n; i++) {
        if (!sample_at(t, mi, first + i, p)) {
            run = 0;
            continue;
        }
        ts->seen++;
        for (int a = 0; a < t->dim; a++) ts->mean[a] += p[a];
        if (run >= 2)
            for (int a = 0; a < t->dim; a++) {
                double d2 = q[0][a] - 2 * q[1][a] + p[a];
                dd += d2 * d2;
            }
        nd += run >= 2;
        memcpy(q[0], q[1], sizeof q[0]);
        memcpy(q[1], p, sizeof q[1]);
        run++;
    }
    for (int a = 0; a < t->dim && ts->seen; a++) ts->mean[a] /= ts->seen;
    ts->noise = nd ? sqrt(dd / (6.0 * nd * t->dim)) : 0;
    ts->cand = ts->seen >= JUDGE_MIN_SEEN && ts->seen >= JUDGE_SEEN_FRACTION * n;
}

static double dist(const sh_tracker *t, const tag_stats *a, const tag_stats *b)
{
    double s = 0;
    for (int k = 0; k < t->dim; k++) s += (a->mean[k] - b->mean[k]) * (a->mean[k] - b->mean[k]);
    return sqrt(s);
}

/* Tag mi against the prediction of the candidates not in `out` (excluded): its own RMS motion,
 * the prediction's, and the share of its motion's variance that a linear map of the prediction
 * explains (least squares over the samples where both exist). Returns the number of such
 * samples. Weights fall off with the distance beyond its nearest neighbour, on half the tags'
 * typical spacing (sigma): the nearest ones speak for the surface around it, the heart's motion
 * changes direction and amplitude within a few spacings. */
static int compare(const sh_tracker *t, int mi, const tag_stats *ts, const unsigned char *out,
                   long first, int n, double sigma, double *own, double *pred, double *explained)
{
    double w[MAXM], wall = 0, dmin = INFINITY;
    for (int j = 0; j < t->nm; j++)
        if (j != mi && ts[j].cand && !out[j]) dmin = fmin(dmin, dist(t, &ts[mi], &ts[j]));
    for (int j = 0; j < t->nm; j++) {
        w[j] = 0;
        if (j == mi || !ts[j].cand || out[j]) continue;
        double z = (dist(t, &ts[mi], &ts[j]) - dmin) / sigma;
        w[j] = exp(-0.5 * z * z);
        wall += w[j];
    }
    /* sums of o (own), r (predicted) and their products, dim x dim */
    double so[3] = {0}, sr[3] = {0}, soo[3] = {0}, srr[9] = {0}, sro[9] = {0};
    int m = 0, d = t->dim;
    for (int i = 0; i < n && wall > 0; i++) {
        double p[3], q[3], pr[3] = {0}, ws = 0;
        if (!sample_at(t, mi, first + i, p)) continue;
        for (int j = 0; j < t->nm; j++) {
            if (w[j] <= 0 || !sample_at(t, j, first + i, q)) continue;
            for (int a = 0; a < d; a++) pr[a] += w[j] * (q[a] - ts[j].mean[a]);
            ws += w[j];
        }
        /* most of its neighbourhood seen: a prediction from far tags alone is another one */
        if (ws < 0.5 * wall) continue;
        for (int a = 0; a < d; a++) {
            p[a] -= ts[mi].mean[a];
            pr[a] /= ws;
        }
        for (int a = 0; a < d; a++) {
            so[a] += p[a];
            sr[a] += pr[a];
            soo[a] += p[a] * p[a];
            for (int b = 0; b < d; b++) {
                srr[a * d + b] += pr[a] * pr[b];
                sro[a * d + b] += pr[a] * p[b];
            }
        }
        m++;
    }
    *own = *pred = *explained = 0;
    if (m == 0) return 0;
    double voo = 0, vrr = 0, ridge = 0;
    for (int a = 0; a < d; a++) {
        soo[a] -= so[a] * so[a] / m;
        for (int b = 0; b < d; b++) {
            srr[a * d + b] -= sr[a] * sr[b] / m;
            sro[a * d + b] -= sr[a] * so[b] / m;
        }
        voo += soo[a];
        vrr += srr[a * d + a];
    }
    *own = sqrt(fmax(0, voo) / m);
    *pred = sqrt(fmax(0, vrr) / m);
    if (!(voo > 0) || !(vrr > 0)) return m;
    /* own axis b ~ sum_a c_ab predicted_a: one small least-squares system per own axis; the ridge
     * keeps it solvable when the neighbours move along a single line */
    ridge = 1e-9 * vrr;
    double left = 0;
    for (int b = 0; b < d; b++) {
        double A[9], c[3];
        for (int k = 0; k < d * d; k++) A[k] = srr[k];
        for (int a = 0; a < d; a++) {
            A[a * d + a] += ridge;
            c[a] = sro[a * d + b];
        }
        if (!trk_chol_solve(A, c, d, NULL)) return m;
        double fit = 0;
        for (int a = 0; a < d; a++) fit += c[a] * sro[a * d + b];
        left += soo[b] - fit;
    }
    *explained = fmax(0, 1 - left / voo);
    return m;
}

/* Judges every candidate against the candidates not in `out`; the verdicts in v (slot order). */
static void judge_round(const sh_tracker *t, const tag_stats *ts, const unsigned char *out, long first,
                        int n, double sigma, double noise, sh_track_id *v)
{
    double u = t->unit > 0 ? t->unit : 1;
    int others = 0;
    for (int j = 0; j < t->nm; j++) others += ts[j].cand && !out[j];
    for (int i = 0; i < t->nm; i++) {
        if (!ts[i].cand) continue;
        sh_track_id *r = &v[i];
        if (others - !out[i] < JUDGE_MIN_TAGS) {
            r->verdict = SH_TRACK_ID_ALONE;
            continue;
        }
        double own, pred, expl, sn = ts[i].noise;
        int m = compare(t, i, ts, out, first, n, sigma, &own, &pred, &expl);
        r->motion_px = own / u;
        r->predicted_px = pred / u;
        r->noise_px = sn / u;
        /* its motion above its noise: white noise alone gives own = sn sqrt(dim) */
        int quiet = own < JUDGE_QUIET * sn * sqrt(t->dim);
        if (!quiet && own > 0) {
            /* the share of its motion above the noise that theirs explains */
            double var = own * own, nv = sn * sn * t->dim, left = (1 - expl) * var;
            expl = 1 - fmax(0, left - nv) / fmax(var - nv, 1e-12 * var);
        }
        r->explained = fmax(0, expl);
        /* the neighbours' motion measurable above the tags' usual noise (not its own: a tag on a
         * fast instrument has large second differences) */
        if (m < JUDGE_MIN_COMMON || pred < fmax(t->o.min_motion * u, JUDGE_NOISE_SNR * noise))
            r->verdict = SH_TRACK_ID_UNJUDGED;
        else if (quiet && own < JUDGE_STILL * pred) r->verdict = SH_TRACK_ID_STILL;
        else if (quiet) r->verdict = SH_TRACK_ID_QUIET;
        else if (r->explained < JUDGE_UNLIKE) r->verdict = SH_TRACK_ID_UNLIKE;
        else r->verdict = SH_TRACK_ID_KEPT;
    }
}

/* Verdicts in slot order (v[t->nm]). Two rounds: the tags the first leaves out are no one's
 * neighbours in the second (a still card beside the heart would pull its neighbours' predictions
 * towards still). */
static void judge_all(const sh_tracker *t, sh_track_id *v)
{
    tag_stats ts[MAXM];
    long first;
    int n = hist_span(t, &first);
    double nn[MAXM], noises[MAXM];
    int nc = 0;
    for (int i = 0; i < t->nm; i++) {
        sh_track_id *r = &v[i];
        memset(r, 0, sizeof *r);
        r->id = t->m[i].id;
        tag_summary(t, i, first, n, &ts[i]);
        /* in frames: one history sample every decim frames */
        r->frames = n * t->decim;
        r->seen = ts[i].seen * t->decim;
        r->verdict = ts[i].cand ? SH_TRACK_ID_KEPT : SH_TRACK_ID_RARE;
        if (ts[i].cand) noises[nc++] = ts[i].noise;
    }
    /* the tags' typical spacing: the median distance to the nearest other one */
    int k = 0;
    for (int i = 0; i < t->nm; i++) {
        if (!ts[i].cand) continue;
        double d = INFINITY;
        for (int j = 0; j < t->nm; j++)
            if (j != i && ts[j].cand) d = fmin(d, dist(t, &ts[i], &ts[j]));
        if (isfinite(d)) nn[k++] = d;
    }
    double sigma = k ? 0.5 * trk_median(nn, k) : 0;
    double noise = trk_median(noises, nc);
    if (!(sigma > 0)) sigma = 1;
    unsigned char out[MAXM] = {0};
    judge_round(t, ts, out, first, n, sigma, noise, v);
    int any = 0;
    for (int i = 0; i < t->nm; i++) {
        out[i] = v[i].verdict == SH_TRACK_ID_STILL || v[i].verdict == SH_TRACK_ID_UNLIKE;
        any |= out[i];
    }
    if (!any) return;
    sh_track_id second[MAXM];
    memcpy(second, v, sizeof second[0] * (size_t)t->nm);
    judge_round(t, ts, out, first, n, sigma, noise, second);
    /* those left out in the first round keep that verdict unless the second clears them */
    for (int i = 0; i < t->nm; i++)
        if (!out[i] || second[i].verdict == SH_TRACK_ID_KEPT) v[i] = second[i];
}

static int keeps(sh_track_id_verdict v)
{
    return v == SH_TRACK_ID_KEPT || v == SH_TRACK_ID_UNJUDGED || v == SH_TRACK_ID_QUIET || v == SH_TRACK_ID_ALONE;
}

int sh_tracker_judge_ids(const sh_tracker *t, sh_track_id *out, int max)
{
    if (!t || !out || max <= 0) return 0;
    sh_track_id v[MAXM];
    int order[MAXM], n = 0;
    if (t->num_ids > 0) {
        for (int i = 0; i < t->nm; i++) {
            memset(&v[i], 0, sizeof v[i]);
            v[i].id = t->m[i].id;
            v[i].seen = t->m[i].seen;
        }
    } else {
        judge_all(t, v);
    }
    for (int i = 0; i < t->nm; i++) {
        v[i].keep = keeps(v[i].verdict);
        order[n++] = i;
    }
    for (int i = 1; i < n; i++)
        for (int j = i; j > 0 && v[order[j - 1]].id > v[order[j]].id; j--) {
            int tmp = order[j];
            order[j] = order[j - 1];
            order[j - 1] = tmp;
        }
    int w = n < max ? n : max;
    for (int i = 0; i < w; i++) out[i] = v[order[i]];
    return w;
}

void trk_confirm_auto(sh_tracker *t)
{
    int due = 0;
    for (int i = 0; i < t->nm && !due; i++) due = t->m[i].seen > t->o.fps;
    if (!due) return;
    sh_track_id v[MAXM];
    judge_all(t, v);
    for (int i = 0; i < t->nm; i++) {
        marker *mk = &t->m[i];
        if (mk->seen <= t->o.fps) continue;
        /* the evidence grows with the history: a verdict against withdraws the confirmation
         * (an instrument can move in step with the heart for a second); online the first second
         * may not have shown the neighbours' motion yet, so an unjudged tag waits a few beats */
        switch (v[i].verdict) {
        case SH_TRACK_ID_KEPT:
        case SH_TRACK_ID_ALONE: mk->confirmed = 1; break;
        case SH_TRACK_ID_UNJUDGED:
        case SH_TRACK_ID_QUIET: mk->confirmed |= mk->seen > 5 * t->o.fps; break;
        default: mk->confirmed = 0; break;
        }
    }
}

void sh_track_id_text(const sh_track_id *v, char *out, size_t cap)
{
    if (!v || !out || cap == 0) return;
    switch (v->verdict) {
    case SH_TRACK_ID_KEPT:
        snprintf(out, cap, "moves with its neighbours (%.2f px RMS, %.0f %% explained by theirs)", v->motion_px,
                 100 * v->explained);
        break;
    case SH_TRACK_ID_UNJUDGED:
        snprintf(out, cap, "not compared: its neighbours move too little (%.2f px RMS) or too rarely with it to tell",
                 v->predicted_px);
        break;
    case SH_TRACK_ID_QUIET:
        snprintf(out, cap, "not compared: it hardly moves (%.2f px RMS, noise %.2f px), nor much less than its "
                           "neighbours (%.2f px)", v->motion_px, v->noise_px, v->predicted_px);
        break;
    case SH_TRACK_ID_ALONE:
        snprintf(out, cap, "not compared: fewer than %d other tags seen to compare it with", JUDGE_MIN_TAGS);
        break;
    case SH_TRACK_ID_RARE:
        snprintf(out, cap, "seen in %d of %d frames: too few to be a marker", v->seen, v->frames);
        break;
    case SH_TRACK_ID_STILL:
        snprintf(out, cap, "still (%.2f px RMS) while its neighbours move %.2f px: not on the heart",
                 v->motion_px, v->predicted_px);
        break;
    case SH_TRACK_ID_UNLIKE:
        snprintf(out, cap, "moves unlike its neighbours (%.2f px RMS, %.0f %% explained by theirs): "
                           "not on the heart", v->motion_px, 100 * v->explained);
        break;
    }
}
