/* Natural landmarks on a phantom sequence against its ground truth (issue 19): how many are
 * chosen, what becomes of them frame by frame (accepted, or refused by which test), and how far
 * each accepted one lies from where the truth puts its surface point, beside the markers' own
 * map at the same points (what a landmark could correct).
 *
 * Per frame t after the reference N, as a stabilizer would: the markers' map of frame t (an
 * interpolant on the reference positions of the markers t shares with N, the method of
 * --method, fitted to their positions in t: the points file's, from `stillheart track`)
 * predicts each landmark; sh_landmarks_track finds it and judges it. An accepted landmark is
 * wrong when the truth says its surface point is hidden in frame t (an instrument, blood), and
 * else off by its distance to the truth. The tags' quads that keep landmarks off the stickers
 * are the truth's in frame N (the product takes the detector's). */
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "eval.h"
#include "stillheart/cli.h"
#include "stillheart/y4m.h"

/* The hull's samples (every GEO_STRIDE px) and what each sees in the reference: where the two
 * maps are compared with the truth. */
#define GEO_STRIDE 8
/* A landmark's window as the truth sees it: WIN_SIDE x WIN_SIDE samples across its search window
 * (the 21 px side 3.3 px apart), located in the reference; one of them hidden in a frame says an
 * occluder (or the view's edge) was over part of what the search compared. */
#define WIN_SIDE 7
#define WIN_SAMPLES (WIN_SIDE * WIN_SIDE)

typedef struct {
    int n;
    float *x, *y;
    phantom_content *seen;
    float *err_map, *err_lm;
    long long count, cap;
} geo_samples;

typedef struct {
    double *ref_xy, *cur_xy, *values;
    int *ids;
    float *pred, *xy;
    uint8_t *verdict;
    phantom_content *seen;
    uint8_t *covered;     /* the reference pixel's tissue was behind something there */
    phantom_content *win; /* WIN_SAMPLES a landmark; marker -2: no truth in the reference */
    float *err, *map_err;
    long long count, cap;
    double *ms;
} scratch;

static void scratch_free(scratch *s)
{
    free(s->ref_xy), free(s->cur_xy), free(s->values), free(s->ids);
    free(s->pred), free(s->xy), free(s->verdict), free(s->seen), free(s->covered), free(s->win), free(s->err), free(s->map_err), free(s->ms);
}

static int cmp_float(const void *a, const void *b)
{
    float x = *(const float *)a, y = *(const float *)b;
    return (x > y) - (x < y);
}

static double pct(float *v, long long n, double q)
{
    if (n == 0) return NAN;
    qsort(v, (size_t)n, sizeof *v, cmp_float);
    long long k = (long long)ceil(q * (double)n) - 1;
    return v[k < 0 ? 0 : k];
}

/* The map of the method through n points at `at`, as the warp makes it (src/warp/model.c): the
 * displacement (cur - ref) interpolated and added to the position. For the methods that reproduce
 * affine functions (affine, piecewise linear, the RBFs with their affine term: TPS) that is the
 * map of the positions themselves, which is interpolated instead, so that their figures stay those
 * measured before, bit for bit (through the displacements they differ in the last bits, and 0-5
 * of 25 000 landmark-frames a render change verdict). B-splines and the RBFs without the affine
 * term tend to zero away from the points: through the positions their map sags between them
 * (B-splines through the truth's 16 markers of exvivo seed 1: 15.0 px over the hull, and 438
 * landmark-frames accepted instead of 25 000), through the displacements it tends to the
 * identity, as the warp's. lambda: each point's smoothing (NULL: none). */
static sh_status map_displacement(const sh_interp_params *params, const double *ref, const double *cur, int n,
                                  const double *lambda, const float *at, int count, float *out)
{
    const sh_method m = params->method;
    if (m == SH_METHOD_AFFINE || m == SH_METHOD_PWLINEAR || (sh_interp_method_smooths(m) && params->affine_term))
        return lambda ? sh_interp_map_points_smoothed(params, ref, cur, n, lambda, at, count, out)
                      : sh_interp_map_points(params, ref, cur, n, at, count, out);
    double *d = malloc(2 * (size_t)n * sizeof(double));
    if (!d) return sh_error_set(SH_ENOMEM, "landmarks: out of memory");
    for (int i = 0; i < 2 * n; i++) d[i] = cur[i] - ref[i];
    sh_status st = lambda ? sh_interp_map_points_smoothed(params, ref, d, n, lambda, at, count, out)
                          : sh_interp_map_points(params, ref, d, n, at, count, out);
    for (int i = 0; st == SH_OK && i < 2 * count; i++) out[i] += at[i];
    free(d);
    return st;
}

/* The method through the m markers and the k - m accepted landmarks after them, each landmark with
 * the smoothing of its own the warp gives it (SH_LANDMARK_SMOOTHING; the markers exact). */
static sh_status map_with_landmarks(const eval_lm_options *o, const double *ref, const double *cur, int m, int k,
                                    const float *at, int count, float *out)
{
    double *lambda = NULL;
    const phantom_model *pm = phantom_truth_model(o->truth);
    const double own = sh_landmarks_smoothing(o->landmark_smoothing, sh_landmarks_reduction(&o->lp, pm->width, pm->height));
    if (own > 0 && sh_interp_method_smooths(o->params.method) && k > m) {
        if (!(lambda = malloc(sizeof(double) * (size_t)k))) return sh_error_set(SH_ENOMEM, "landmarks: out of memory");
        for (int i = 0; i < k; i++) lambda[i] = i < m ? 0.0 : own;
    }
    sh_status st = map_displacement(&o->params, ref, cur, k, lambda, at, count, out);
    free(lambda);
    return st;
}

/* The hull's samples against the truth in frame t: the markers' map (s->ref_xy/cur_xy, m) and
 * the same with the accepted landmarks added as correspondences. */
static sh_status compare_maps(const eval_lm_options *o, int t, int m, const float *lm_ref, int n, scratch *s,
                              geo_samples *g)
{
    if (g->count + g->n > g->cap) {
        long long cap = g->cap ? g->cap * 2 : 1 << 16;
        while (cap < g->count + g->n) cap *= 2;
        float *a = realloc(g->err_map, sizeof(float) * (size_t)cap), *b = a ? realloc(g->err_lm, sizeof(float) * (size_t)cap) : NULL;
        if (a) g->err_map = a;
        if (b) g->err_lm = b;
        if (!a || !b) return sh_error_set(SH_ENOMEM, "landmarks: out of memory at frame %d", t);
        g->cap = cap;
    }
    double *ref_all = malloc(2 * (size_t)(m + n) * sizeof(double)), *cur_all = malloc(2 * (size_t)(m + n) * sizeof(double));
    float *at = malloc(2 * (size_t)g->n * sizeof(float)), *fm = malloc(2 * (size_t)g->n * sizeof(float));
    float *fl = malloc(2 * (size_t)g->n * sizeof(float));
    sh_status st = SH_OK;
    if (!ref_all || !cur_all || !at || !fm || !fl) st = sh_error_set(SH_ENOMEM, "landmarks: out of memory");
    int k = m;
    if (st == SH_OK) {
        memcpy(ref_all, s->ref_xy, 2 * (size_t)m * sizeof(double));
        memcpy(cur_all, s->cur_xy, 2 * (size_t)m * sizeof(double));
        /* the accepted ones only: a refused landmark filled in with the markers' prediction
         * pins the map to the markers' error there (measured: 0.56 px mean instead of 0.39 on
         * exvivo with occlusions, seed 1) */
        for (int i = 0; i < n; i++) {
            if (s->verdict[i] != SH_LANDMARK_ACCEPTED) continue;
            ref_all[2 * k] = lm_ref[2 * i], ref_all[2 * k + 1] = lm_ref[2 * i + 1];
            cur_all[2 * k] = s->xy[2 * i], cur_all[2 * k + 1] = s->xy[2 * i + 1];
            k++;
        }
        for (int i = 0; i < g->n; i++) at[2 * i] = g->x[i], at[2 * i + 1] = g->y[i];
    }
    /* an interpolant the method refuses (too few, degenerate) leaves the frame out */
    if (st == SH_OK && map_displacement(&o->params, s->ref_xy, s->cur_xy, m, NULL, at, g->n, fm) == SH_OK &&
        map_with_landmarks(o, ref_all, cur_all, m, k, at, g->n, fl) == SH_OK) {
        for (int i = 0; i < g->n; i++) {
            double gx, gy;
            if (!phantom_truth_content_visible(o->truth, o->camera, t, &g->seen[i]) ||
                phantom_truth_project_content(o->truth, o->camera, t, &g->seen[i], &gx, &gy) != SH_OK ||
                isnan(fm[2 * i]) || isnan(fl[2 * i]))
                continue;
            g->err_map[g->count] = (float)hypot(fm[2 * i] - gx, fm[2 * i + 1] - gy);
            g->err_lm[g->count++] = (float)hypot(fl[2 * i] - gx, fl[2 * i + 1] - gy);
        }
    }
    free(ref_all), free(cur_all), free(at), free(fm), free(fl);
    return st;
}

/* The markers' map of frame t at every landmark (s->pred); 0 when fewer than 3 markers are
 * shared with the reference, or the interpolant refuses them. */
static int predict(const eval_lm_options *o, const sh_points *points, const sh_point *ref, int nref, int t,
                   const float *lm_ref, int n, scratch *s, int *m_out)
{
    int ncur;
    const sh_point *cur = sh_points_frame(points, t, &ncur);
    int m = sh_points_match(ref, nref, cur, ncur, s->ids, s->ref_xy, s->cur_xy);
    if (m < 3) return 0;
    *m_out = m;
    if (map_displacement(&o->params, s->ref_xy, s->cur_xy, m, NULL, lm_ref, n, s->pred) != SH_OK) return 0;
    /* piecewise linear has no value outside the hull of the markers frame t shares */
    for (int i = 0; i < 2 * n; i++)
        if (isnan(s->pred[i])) return 0;
    return 1;
}

/* With keep_rows: frame t's landmark rows, every landmark (verdict NULL: the reference) or the
 * accepted ones. */
static sh_status keep_rows(const eval_lm_options *o, int t, int n, const float *xy, const uint8_t *verdict,
                           eval_lm_result *r)
{
    if (!o->keep_rows) return SH_OK;
    sh_point *rows = realloc(r->rows, sizeof(sh_point) * ((size_t)r->nrows + (size_t)n));
    if (!rows) return sh_error_set(SH_ENOMEM, "landmarks: out of memory at frame %d", t);
    r->rows = rows;
    for (int i = 0; i < n; i++)
        if (!verdict || verdict[i] == SH_LANDMARK_ACCEPTED)
            rows[r->nrows++] = (sh_point){.frame = t, .id = SH_LANDMARK_ID_BASE + i, .x = xy[2 * i],
                                          .y = xy[2 * i + 1], .X = NAN, .Y = NAN, .Z = NAN};
    return SH_OK;
}

static int by_frame_id(const void *a, const void *b)
{
    const sh_point *p = a, *q = b;
    if (p->frame != q->frame) return (p->frame > q->frame) - (p->frame < q->frame);
    return (p->id > q->id) - (p->id < q->id);
}

sh_status eval_landmarks_write_points(const sh_points *points, const eval_lm_result *r, FILE *out)
{
    size_t n = (size_t)points->count + (size_t)r->nrows;
    sh_point *all = malloc(sizeof(sh_point) * (n ? n : 1));
    if (!all) return sh_error_set(SH_ENOMEM, "landmarks: out of memory");
    if (points->count) memcpy(all, points->rows, sizeof(sh_point) * (size_t)points->count);
    if (r->nrows) memcpy(all + points->count, r->rows, sizeof(sh_point) * (size_t)r->nrows);
    qsort(all, n, sizeof *all, by_frame_id);
    sh_status st = sh_points_write(out, all, (int)n, 0);
    free(all);
    return st;
}

static double cpu_ms(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return (double)ts.tv_sec * 1e3 + (double)ts.tv_nsec / 1e6;
}

/* Whether the truth says part of landmark i's window is hidden in frame t. */
static int partly_hidden(const eval_lm_options *o, int t, const scratch *s, int i)
{
    const phantom_content *w = s->win + (size_t)i * WIN_SAMPLES;
    for (int a = 0; a < WIN_SAMPLES; a++)
        if (w[a].marker != -2 && !phantom_truth_content_visible(o->truth, o->camera, t, &w[a])) return 1;
    return 0;
}

/* Whether the frame's luma holds a pixel at or above level in the square of side 2 half + 1
 * about (x, y) (clipped to the frame). */
static int lit(const sh_plane *luma, double x, double y, int half, int level)
{
    int x0 = (int)lround(x) - half, y0 = (int)lround(y) - half;
    for (int v = y0 < 0 ? 0 : y0; v <= y0 + 2 * half && v < luma->height; v++) {
        const uint8_t *row = luma->data + (size_t)v * luma->stride;
        for (int u = x0 < 0 ? 0 : x0; u <= x0 + 2 * half && u < luma->width; u++)
            if (row[u] >= level) return 1;
    }
    return 0;
}

/* Accepted landmarks of one frame (its luma) against the truth; half: half a search window in the
 * frame's pixels. */
static sh_status judge(const eval_lm_options *o, int t, int n, const sh_plane *luma, int half, scratch *s,
                       eval_lm_result *r)
{
    if (s->count + n > s->cap) {
        long long cap = s->cap ? s->cap * 2 : 1 << 14;
        while (cap < s->count + n) cap *= 2;
        float *e = realloc(s->err, sizeof(float) * (size_t)cap), *me = e ? realloc(s->map_err, sizeof(float) * (size_t)cap) : NULL;
        if (e) s->err = e;
        if (me) s->map_err = me;
        if (!e || !me) return sh_error_set(SH_ENOMEM, "landmarks: out of memory at frame %d", t);
        s->cap = cap;
    }
    for (int i = 0; i < n; i++) {
        int accepted = s->verdict[i] == SH_LANDMARK_ACCEPTED;
        double gx, gy;
        if (s->seen[i].marker == -2) { /* no truth in the reference: not judged */
            r->unjudged += accepted;
            continue;
        }
        if (s->covered[i]) {
            /* Chosen on what covered the tissue in the reference (an instrument, blood): the
             * landmark still says where the tissue behind its pixel went, and is judged by that,
             * whether the cover is still there or not; never counted as hidden, as it was never
             * seen. A window on an instrument that moves over the tissue is off by the difference. */
            if (phantom_truth_project_content(o->truth, o->camera, t, &s->seen[i], &gx, &gy) != SH_OK) {
                r->unjudged += accepted;
                continue;
            }
        } else if (!phantom_truth_content_visible(o->truth, o->camera, t, &s->seen[i]) ||
                   phantom_truth_project_content(o->truth, o->camera, t, &s->seen[i], &gx, &gy) != SH_OK) {
            r->hidden++;
            r->accepted_hidden += accepted;
            continue;
        }
        const int hl = lit(luma, gx, gy, half, o->lp.highlight);
        r->lit += hl;
        if (!accepted) continue;
        double e = hypot(s->xy[2 * i] - gx, s->xy[2 * i + 1] - gy);
        const int part = partly_hidden(o, t, s, i);
        r->over_1px += e > 1;
        r->accepted_covered += s->covered[i];
        r->over_1px_covered += s->covered[i] && e > 1;
        r->accepted_partly_hidden += part;
        r->over_1px_partly_hidden += part && e > 1;
        r->accepted_lit += hl;
        r->over_1px_lit += hl && e > 1;
        if (e > r->max) r->max = e;
        r->sum += e;
        s->err[s->count] = (float)e;
        double me = hypot(s->pred[2 * i] - gx, s->pred[2 * i + 1] - gy);
        r->map_sum += me;
        s->map_err[s->count++] = (float)me;
    }
    return SH_OK;
}

/* At the reference: the tags' black-border quads (the truth's) that keep landmarks off the
 * stickers, the markers' hull, the landmarks, what each one's pixel sees, and the hull's samples. */
static sh_status start(const eval_lm_options *o, const sh_point *ref, int nref, const sh_plane *luma, scratch *s,
                       geo_samples *g, sh_landmarks **lm)
{
    const int t = o->reference, mt = phantom_truth_model(o->truth)->num_markers;
    int nt = 0;
    for (int i = 0; i < mt; i++) {
        int vis = 1;
        for (int k = 0; k < 4 && vis; k++)
            if (phantom_truth_marker(o->truth, o->camera, t, i, k, NULL, &s->values[8 * nt + 2 * k],
                                     &s->values[8 * nt + 2 * k + 1], NULL, &vis) != SH_OK)
                vis = 0;
        nt += vis;
    }
    double *cxy = malloc(2 * (size_t)nref * sizeof(double));
    sh_hull hull;
    for (int k = 0; cxy && k < nref; k++) cxy[2 * k] = ref[k].x, cxy[2 * k + 1] = ref[k].y;
    sh_status st = !cxy ? sh_error_set(SH_ENOMEM, "landmarks: out of memory") : sh_hull_compute(cxy, nref, &hull);
    free(cxy);
    if (st == SH_OK) st = sh_landmarks_create(&o->lp, luma, &hull, s->values, nt, lm);
    if (st != SH_OK) return st;
    int n = sh_landmarks_count(*lm);
    const float *lr = sh_landmarks_reference(*lm);
    for (int i = 0; i < n; i++)
        if (phantom_truth_locate_content(o->truth, o->camera, t, lr[2 * i], lr[2 * i + 1], &s->seen[i]) != SH_OK)
            s->seen[i].marker = -2;
        else if (!phantom_truth_content_visible(o->truth, o->camera, t, &s->seen[i]))
            s->covered[i] = 1;
    /* each window's samples, over the frame's pixels the search's window covers (2^k times its
     * side where the landmarks are found in the frame halved k times) */
    const double half = (o->lp.flow.win - 1) / 2.0 * (double)(1 << sh_landmarks_reduction(&o->lp, luma->width, luma->height));
    for (int i = 0; i < n; i++)
        for (int a = 0; a < WIN_SAMPLES; a++) {
            phantom_content *c = &s->win[(size_t)i * WIN_SAMPLES + a];
            double x = lr[2 * i] + half * (2.0 * (a % WIN_SIDE) / (WIN_SIDE - 1) - 1),
                   y = lr[2 * i + 1] + half * (2.0 * (a / WIN_SIDE) / (WIN_SIDE - 1) - 1);
            if (phantom_truth_locate_content(o->truth, o->camera, t, x, y, c) != SH_OK ||
                !phantom_truth_content_visible(o->truth, o->camera, t, c))
                c->marker = -2;
        }
    /* the samples: lattice points of the hull whose pixel sees the heart in the reference */
    size_t cap = (size_t)(luma->width / GEO_STRIDE + 1) * (size_t)(luma->height / GEO_STRIDE + 1);
    g->x = malloc(cap * sizeof(float));
    g->y = malloc(cap * sizeof(float));
    g->seen = malloc(cap * sizeof(phantom_content));
    if (!g->x || !g->y || !g->seen) return sh_error_set(SH_ENOMEM, "landmarks: out of memory");
    for (int y = 0; y < luma->height; y += GEO_STRIDE)
        for (int x = 0; x < luma->width; x += GEO_STRIDE) {
            if (!sh_hull_contains(&hull, x, y)) continue;
            phantom_content c;
            if (phantom_truth_locate_content(o->truth, o->camera, t, x, y, &c) != SH_OK ||
                !phantom_truth_content_visible(o->truth, o->camera, t, &c))
                continue;
            g->x[g->n] = (float)x, g->y[g->n] = (float)y, g->seen[g->n++] = c;
        }
    return SH_OK;
}

sh_status eval_landmarks_run(const eval_lm_options *o, const sh_points *points, const char *video_path,
                             eval_lm_result *r)
{
    memset(r, 0, sizeof *r);
    int nref;
    const sh_point *ref = sh_points_frame(points, o->reference, &nref);
    const phantom_model *pm = phantom_truth_model(o->truth);
    sh_y4m_reader *rd;
    sh_status st = sh_y4m_reader_open(video_path, &rd);
    if (st != SH_OK) return st;
    const sh_y4m_header *h = sh_y4m_reader_header(rd);
    if (h->width != pm->width || h->height != pm->height) {
        sh_y4m_reader_close(rd);
        return sh_error_set(SH_EINVAL, "the phantom's images are %dx%d, %s's %dx%d", pm->width, pm->height,
                            video_path, h->width, h->height);
    }
    /* the highlight level follows the frames' range, as in the product */
    eval_lm_options ranged = *o;
    ranged.lp.highlight = sh_landmarks_highlight_level(h->format, sh_y4m_header_full_range(h));
    o = &ranged;
    /* the search's window, in the frame's pixels (the landmarks may see it halved) */
    const int half = (o->lp.flow.win / 2) << sh_landmarks_reduction(&o->lp, h->width, h->height);
    sh_image frame = {0};
    sh_landmarks *lm = NULL;
    scratch s = {0};
    geo_samples g = {0};
    int n = 0, mt = pm->num_markers;
    size_t m = (size_t)(nref > 0 ? nref : 1), lmax = (size_t)o->lp.max_points;
    s.ref_xy = malloc(2 * m * sizeof(double));
    s.cur_xy = malloc(2 * m * sizeof(double));
    s.ids = malloc(m * sizeof(int));
    s.values = malloc(8 * (size_t)(mt > 0 ? mt : 1) * sizeof(double));
    s.pred = malloc(2 * lmax * sizeof(float));
    s.xy = malloc(2 * lmax * sizeof(float));
    s.verdict = malloc(lmax);
    s.seen = malloc(lmax * sizeof(phantom_content));
    s.covered = calloc(lmax, 1);
    s.win = malloc(lmax * WIN_SAMPLES * sizeof(phantom_content));
    s.ms = malloc(sizeof(double) * (size_t)(points->max_frame + 2));
    if (!s.ref_xy || !s.cur_xy || !s.ids || !s.values || !s.pred || !s.xy || !s.verdict || !s.seen || !s.covered || !s.win || !s.ms)
        st = sh_error_set(SH_ENOMEM, "landmarks: out of memory");
    if (st == SH_OK) st = sh_image_create(&frame, h->format, h->width, h->height);
    int frames_timed = 0;
    for (int t = 0; st == SH_OK; t++) {
        if ((st = sh_y4m_reader_read(rd, &frame)) != SH_OK) break;
        if (t == o->reference) {
            if ((st = start(o, ref, nref, &frame.plane[0], &s, &g, &lm)) != SH_OK) break;
            for (int i = 0; i < sh_landmarks_count(lm); i++) r->chosen_covered += s.covered[i];
            n = r->seeded = sh_landmarks_count(lm);
            st = keep_rows(o, t, n, sh_landmarks_reference(lm), NULL, r);
            continue;
        }
        if (!lm) continue; /* before the reference */
        int m_used;
        if (!predict(o, points, ref, nref, t, sh_landmarks_reference(lm), n, &s, &m_used)) {
            r->unpredicted_frames++;
            continue;
        }
        sh_landmarks_counts c;
        double t0 = cpu_ms();
        st = sh_landmarks_track(lm, &frame.plane[0], s.pred, s.xy, s.verdict, &c);
        s.ms[frames_timed++] = cpu_ms() - t0;
        if (st != SH_OK) break;
        r->frames++;
        for (int v = 0; v < SH_LANDMARK_VERDICTS; v++) r->verdicts[v] += c.verdicts[v];
        st = judge(o, t, n, &frame.plane[0], half, &s, r);
        if (st == SH_OK) st = keep_rows(o, t, n, s.xy, s.verdict, r);
        if (st == SH_OK) st = compare_maps(o, t, m_used, sh_landmarks_reference(lm), n, &s, &g);
    }
    if (st == SH_EEOF) st = lm ? SH_OK : sh_error_set(SH_EINVAL, "%s has no frame %d", video_path, o->reference);
    if (st == SH_OK) {
        r->measured = s.count;
        r->mean = s.count ? r->sum / (double)s.count : NAN;
        r->map_mean = s.count ? r->map_sum / (double)s.count : NAN;
        r->p99 = pct(s.err, s.count, 0.99);
        r->map_p99 = pct(s.map_err, s.count, 0.99);
        float *ms = malloc(sizeof(float) * (size_t)(frames_timed + 1));
        for (int i = 0; ms && i < frames_timed; i++) ms[i] = (float)s.ms[i];
        r->ms_median = ms ? pct(ms, frames_timed, 0.5) : NAN;
        free(ms);
        r->geo_samples = g.count;
        double a = 0, b = 0;
        for (long long i = 0; i < g.count; i++) a += g.err_map[i], b += g.err_lm[i];
        r->geo_map_mean = g.count ? a / (double)g.count : NAN;
        r->geo_lm_mean = g.count ? b / (double)g.count : NAN;
        r->geo_map_p95 = pct(g.err_map, g.count, 0.95);
        r->geo_lm_p95 = pct(g.err_lm, g.count, 0.95);
    }
    if (st != SH_OK) free(r->rows), r->rows = NULL, r->nrows = 0;
    free(g.x), free(g.y), free(g.seen), free(g.err_map), free(g.err_lm);
    sh_landmarks_destroy(lm);
    sh_image_destroy(&frame);
    sh_y4m_reader_close(rd);
    scratch_free(&s);
    return st;
}

/* The result as stillheart-eval --landmarks prints it: one JSON object, or lines of text. */
void eval_landmarks_print(const eval_lm_result *r, const char *video_path, int reference, const char *method,
                          int json)
{
    if (json) {
        sh_cli_json j;
        sh_cli_json_start(&j, stdout);
        sh_cli_json_object(&j, NULL);
        sh_cli_json_int(&j, "seeded", r->seeded);
        sh_cli_json_int(&j, "frames", r->frames);
        sh_cli_json_int(&j, "unpredicted_frames", r->unpredicted_frames);
        for (int v = 0; v < SH_LANDMARK_VERDICTS; v++)
            sh_cli_json_int(&j, sh_landmark_verdict_name((sh_landmark_verdict)v), r->verdicts[v]);
        sh_cli_json_int(&j, "measured", r->measured);
        sh_cli_json_int(&j, "hidden", r->hidden);
        sh_cli_json_int(&j, "accepted_hidden", r->accepted_hidden);
        sh_cli_json_int(&j, "unjudged", r->unjudged);
        sh_cli_json_int(&j, "chosen_covered", r->chosen_covered);
        sh_cli_json_int(&j, "accepted_covered", r->accepted_covered);
        sh_cli_json_int(&j, "over_1px_covered", r->over_1px_covered);
        sh_cli_json_int(&j, "over_1px", r->over_1px);
        sh_cli_json_int(&j, "accepted_partly_hidden", r->accepted_partly_hidden);
        sh_cli_json_int(&j, "over_1px_partly_hidden", r->over_1px_partly_hidden);
        sh_cli_json_int(&j, "highlight", r->lit);
        sh_cli_json_int(&j, "accepted_highlight", r->accepted_lit);
        sh_cli_json_int(&j, "over_1px_highlight", r->over_1px_lit);
        sh_cli_json_number(&j, "mean", r->mean);
        sh_cli_json_number(&j, "p99", r->p99);
        sh_cli_json_number(&j, "max", r->max);
        sh_cli_json_number(&j, "map_mean", r->map_mean);
        sh_cli_json_number(&j, "map_p99", r->map_p99);
        sh_cli_json_number(&j, "ms_median", r->ms_median);
        sh_cli_json_object(&j, "geometric");
        sh_cli_json_int(&j, "samples", r->geo_samples);
        sh_cli_json_number(&j, "markers_mean", r->geo_map_mean);
        sh_cli_json_number(&j, "markers_p95", r->geo_map_p95);
        sh_cli_json_number(&j, "landmarks_mean", r->geo_lm_mean);
        sh_cli_json_number(&j, "landmarks_p95", r->geo_lm_p95);
        sh_cli_json_end(&j);
        sh_cli_json_end(&j);
    } else {
        long long all = 0;
        for (int v = 0; v < SH_LANDMARK_VERDICTS; v++) all += r->verdicts[v];
        printf("%s: %d landmarks chosen in frame %d, %d frames after it (%d without a markers' map)\n", video_path,
               r->seeded, reference, r->frames, r->unpredicted_frames);
        printf("landmark-frames: %lld; accepted %lld, lost %lld, photometric %lld, backward %lld, disagrees %lld, "
               "deviates %lld, unconfirmed %lld\n", all, r->verdicts[SH_LANDMARK_ACCEPTED],
               r->verdicts[SH_LANDMARK_LOST], r->verdicts[SH_LANDMARK_PHOTOMETRIC], r->verdicts[SH_LANDMARK_BACKWARD],
               r->verdicts[SH_LANDMARK_DISAGREES], r->verdicts[SH_LANDMARK_DEVIATES],
               r->verdicts[SH_LANDMARK_UNCONFIRMED]);
        printf("accepted against the truth (px): mean %.4f, p99 %.4f, max %.4f over %lld; more than 1 px off: %lld; "
               "accepted while hidden: %lld of %lld hidden\n", r->mean, r->p99, r->max, r->measured, r->over_1px,
               r->accepted_hidden, r->hidden);
        printf("chosen where something covered the tissue in frame %d: %d; accepted %lld, of them more than 1 px from "
               "the tissue behind: %lld\n", reference, r->chosen_covered, r->accepted_covered, r->over_1px_covered);
        printf("accepted with part of the window hidden: %lld, of them more than 1 px off: %lld\n",
               r->accepted_partly_hidden, r->over_1px_partly_hidden);
        printf("with a highlight in the window: %lld, of them accepted %lld, accepted more than 1 px off %lld\n",
               r->lit, r->accepted_lit, r->over_1px_lit);
        printf("the markers' map (%s) at the same landmarks (px): mean %.4f, p99 %.4f\n",
               method, r->map_mean, r->map_p99);
        printf("landmark tracking per frame: %.2f ms (median, one thread)\n", r->ms_median);
        printf("geometric error over the hull (%lld samples, px): the markers' map mean %.4f, p95 %.4f; with the "
               "accepted landmarks mean %.4f, p95 %.4f\n", r->geo_samples, r->geo_map_mean, r->geo_map_p95,
               r->geo_lm_mean, r->geo_lm_p95);
    }
}
