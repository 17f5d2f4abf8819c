/* The daemon's models per marker set, built on a helper thread (run.h says what and why).
 *
 * A "generation" is one reference with its slots (one per marker set seen, LRU). The processing
 * thread owns the slot table's shape (which ids a slot holds, evictions); the helper thread only
 * fills a slot in state BUILDING and marks it READY or FAILED, under the mutex. A model in a
 * READY slot is used by the processing thread alone, so the per-frame path takes the mutex only
 * to look at states. Evicted models and a replaced generation are freed by the helper, so that no
 * free of a large grid basis lands on a published frame either. Live (not test mode), a 2D map
 * whose grid is too coarse for the frame is not refined on the processing thread either: the
 * helper builds the finer grid's model and the next update swaps it in (refine_swap).
 *
 * Over 600 lines: the slot table, the helper thread and the swaps share one mutex and one set of
 * invariants (who may touch a slot in which state); split, each half would need the other's. */
#include <math.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "run_model.h"
#include "stillheart/modelcache.h"
#include "stillheart/warp3d.h"

#define SLOTS 8

enum { EMPTY = 0, BUILDING, READY, FAILED };
/* A READY 2D model's finer grid: asked by the processing thread, taken and made by the helper,
 * ready to swap; failed ones are not asked again (the map keeps its coarser grid). */
enum { REFINE_NONE = 0, REFINE_ASKED, REFINE_TAKEN, REFINE_READY, REFINE_FAILED };

/* A slot: the marker set's entry (modelcache.h: key, models, LRU stamp) and what the daemon adds. */
struct run_model {
    sh_modelcache_entry e; /* 3D: the surface and its views (the output camera's, or the two eyes) */
    double uv[2 * SH_TRACK_MAX_MARKERS]; /* 3D: each marker's surface parameter (for the residual; NaN
                                     * where the view's ray misses); not the landmarks' */
    run_models *owner; /* its camera, for the 3D residual; its lock, for refine_swap */
    double *coef;   /* the interpolant's coefficients, 2 columns (for the residual) */
    double vals[2 * SH_TRACK_MAX_MARKERS];
    int state;
    int taken;      /* the helper is building it */
    char err[160];  /* why the build failed */
    int refine, refine_h;  /* REFINE_*, and the spacing asked for */
    int refine_view;       /* 3D: the view whose grid it is */
    sh_warp_model *finer;  /* REFINE_READY, 2D: the model on the finer grid, to swap in */
    sh_warp3d_grid *finer_grid; /* REFINE_READY, 3D: the view's finer grid */
};

typedef struct generation generation;
struct generation {
    sh_point ref[SH_TRACK_MAX_MARKERS];
    int nref, frame;
    run_model *full; /* the full set's slot: the swap waits for it */
    run_model slot[SLOTS];
    unsigned long clock;
    /* landmarks: chosen by the helper (choosing 1 until then; in test mode no full slot yet) from
     * a copy of the reference frame's luma (3D: every camera's; freed once chosen) and tags; rows
     * = ref then the landmarks, sorted by id (the models' keys are made from it); in 3D only the
     * landmarks triangulated in the reference are rows (ids SH_LANDMARK_ID_BASE + the rig's
     * index) */
    int choosing, choice_taken;
    uint8_t *luma[SH_CALIB_MAX_CAMERAS];
    int nluma, width, height;
    double *tags;
    int ntags;
    sh_landmarks *lm;      /* 2D */
    sh_landmarks_rig *rig; /* 3D */
    int nlm;
    sh_point *rows;
    int nrows;
    char note[160]; /* why it has no landmarks, though asked (written under the lock) */
    /* Live, with landmarks: a reference is first swapped in with its markers alone (its full set
     * built before the choice), so its frames are stabilized while the landmarks are chosen; up
     * is then the same reference with them, swapped in by run_models_poll once its full set's
     * model is built. NULL in test mode (wait), whose references wait for their landmarks. */
    generation *up;
    int told; /* its note handed to the processing thread (run_models_poll) */
    generation *trash_next;
};

struct run_models {
    sh_modelcache_recipe recipe; /* 2D, or 3D after run_models_set_3d (the camera's own view, or two eyes) */
    int wait;
    pthread_mutex_t mu;
    pthread_cond_t cv;      /* the helper waits for work; waiters for results */
    pthread_t helper;
    int started, stop;
    generation *cur, *next; /* in use / being built */
    generation *prev;       /* cur before its landmarks came (its up): kept until the next
                             * swap, as the processing thread's fallback model may be one of its */
    char note[160];         /* the last note run_models_poll handed over */
    /* to free on the helper, a list through their trash_next: never inline, as the helper may
     * be choosing a discarded generation's landmarks from its frame outside the lock */
    generation *trash;
    run_model *evicted[SLOTS * 2];
    int nevicted;
    int builds;
    run_model *pinned;      /* the model last handed out: never evicted (the fallback) */
    sh_warp_model *replaced[4]; /* grids swapped out by refine_swap, to free on the helper */
    sh_warp3d_grid *replaced_grid[4]; /* the same, of 3D views */
    int refined;            /* finer grids built by the helper and swapped in */
    sh_landmarks_params lp; /* max_points 0: no landmarks */
    sh_calib calib;         /* 3D: the rig, for the landmarks */
    int camera;             /* 3D: the output camera's index in it */
};

static void model_free(run_model *md)
{
    sh_warp_model_destroy(md->finer);
    sh_warp3d_grid_destroy(md->finer_grid);
    sh_modelcache_entry_clear(&md->e);
    free(md->coef);
    memset(md, 0, sizeof *md);
}

static void generation_free(generation *g)
{
    if (!g) return;
    generation_free(g->up);
    for (int i = 0; i < SLOTS; i++) model_free(&g->slot[i]);
    sh_landmarks_destroy(g->lm);
    sh_landmarks_rig_destroy(g->rig);
    for (int c = 0; c < g->nluma; c++) free(g->luma[c]);
    free(g->tags), free(g->rows);
    free(g);
}

static run_model *slot_for(run_models *m, generation *g, const int *ids, int n);

/* The rows the models' keys are made from: the markers, then the landmarks when there are any. */
static const sh_point *rows_of(const generation *g, int *n)
{
    *n = g->rows ? g->nrows : g->nref;
    return g->rows ? g->rows : g->ref;
}

/* Builds md's models (its entry's key set) and what the residual needs beside them. */
static sh_status model_build(run_models *m, run_model *md)
{
    md->owner = m;
    const sh_modelcache_entry *e = &md->e;
    sh_status st = sh_modelcache_entry_build(&md->e, &m->recipe);
    if (st != SH_OK) return st;
    if (m->recipe.three_d) {
        /* where the output camera's ray through the marker meets the surface: the residual is
         * measured in that camera whichever cameras the views are seen from (the markers'
         * alone: the landmarks after them have no detection to measure it against) */
        for (int k = 0; k < run_model_markers(md); k++)
            if (sh_warp3d_model_locate(e->m3, &m->recipe.source_cam, m->recipe.vopts.depth_scale, e->ref_xy[2 * k],
                                       e->ref_xy[2 * k + 1], &md->uv[2 * k]) != SH_OK)
                md->uv[2 * k] = md->uv[2 * k + 1] = NAN;
        return SH_OK;
    }
    md->coef = malloc(sizeof(double) * 2 * (size_t)sh_interp_num_coefs(e->interp));
    if (!md->coef) return sh_error_set(SH_ENOMEM, "model: out of memory");
    return SH_OK;
}

/* 3D: the same residual, the map at a marker's reference pixel being the projection of its
 * surface point displaced by h. */
static void refine_swap(run_model *md);
static void refine_ask(run_model *md);

static sh_status update_3d(const run_models *m, run_model *md, const double *cur_xyz, const double *det_xy,
                           const unsigned char *use, double *residual)
{
    refine_swap(md);
    sh_status st = sh_warp3d_model_update_subset(md->e.m3, cur_xyz, use);
    for (int v = 0; v < m->recipe.nviews && st == SH_OK; v++) st = sh_warp3d_view_update(md->e.view[v]);
    if (st != SH_OK) return st;
    refine_ask(md);
    double worst = -1;
    for (int k = 0; k < run_model_markers(md); k++) {
        if (!isfinite(det_xy[2 * k])) continue;
        double X[3], x = NAN, y = NAN;
        if (isfinite(md->uv[2 * k])) {
            sh_warp3d_model_point(md->e.m3, md->uv[2 * k], md->uv[2 * k + 1], 1.0, 1, X);
            if (!sh_warp3d_project(&m->recipe.source_cam, X, &x, &y)) x = y = NAN;
        }
        double r = hypot(x - det_xy[2 * k], y - det_xy[2 * k + 1]);
        if (!(r <= worst)) worst = r; /* a NaN wins: never hidden */
    }
    *residual = worst;
    return SH_OK;
}

/* The residual of a map through a subset: read off the warp model's own fit (sh_warp_model_eval),
 * as a second fit would factor the subset's system again. */
static sh_status residual_subset(run_model *md, const double *det_xy, double *residual)
{
    const sh_modelcache_entry *e = &md->e;
    double worst = -1;
    for (int k = 0; k < e->n; k++) {
        double q[2];
        if (!isfinite(det_xy[2 * k])) continue;
        if (sh_warp_model_eval(e->model, e->ref_xy[2 * k], e->ref_xy[2 * k + 1], q) != SH_OK) {
            worst = NAN;
            break;
        }
        double r = hypot(q[0] - det_xy[2 * k], q[1] - det_xy[2 * k + 1]);
        if (!(r <= worst)) worst = r; /* a NaN wins: never hidden */
    }
    *residual = worst;
    return SH_OK;
}

/* Live models are made with defer_refine (run_models_create, run_models_set_3d): a grid too coarse
 * for a frame's map would otherwise be rebuilt inside that frame's update, 15-100 ms with the
 * landmarks' 130-140 points at 1080p in 2D (measured: refinements to 4 and 2 px), 235 ms for a 3D
 * view through 119 points (three 1080p cameras, 200 landmarks asked: docs/landmarks.md), a frame
 * or several lost in real time. Here what the helper built on the finer grid (a 2D model, or a 3D
 * view's grid) replaces the old one before the update, and after it a finer grid is asked for
 * when the map's bound wants one; meanwhile the map is within its bound, not max_error (0.05-0.34
 * px measured as refinements came due on the phantom in 2D with and without landmarks). */
static void refine_swap(run_model *md)
{
    run_models *m = md->owner;
    int live = m && (m->recipe.three_d ? m->recipe.vopts.warp.defer_refine : m->recipe.wopts.defer_refine);
    if (!live) return;
    pthread_mutex_lock(&m->mu);
    if (md->refine == REFINE_READY) {
        sh_warp_model *old = NULL;
        sh_warp3d_grid *old_grid = NULL;
        if (md->finer_grid) {
            sh_warp3d_view_grid_swap(md->e.view[md->refine_view], md->finer_grid);
            old_grid = md->finer_grid; /* the view's old grid, now */
            md->finer_grid = NULL;
        } else {
            old = md->e.model;
            md->e.model = md->finer;
            md->finer = NULL;
        }
        md->refine = REFINE_NONE;
        m->refined++;
        for (int i = 0; i < 4 && (old || old_grid); i++) {
            if (old && !m->replaced[i]) m->replaced[i] = old, old = NULL;
            else if (old_grid && !m->replaced_grid[i]) m->replaced_grid[i] = old_grid, old_grid = NULL;
        }
        pthread_cond_broadcast(&m->cv);
        pthread_mutex_unlock(&m->mu);
        /* the helper's list is full: here, once in a long while */
        sh_warp_model_destroy(old);
        sh_warp3d_grid_destroy(old_grid);
        return;
    }
    pthread_mutex_unlock(&m->mu);
}

static void refine_ask(run_model *md)
{
    run_models *m = md->owner;
    int h = 0, view = 0;
    if (m && m->recipe.three_d) {
        for (int v = 0; v < m->recipe.nviews && !h; v++)
            if ((h = sh_warp_model_finer_spacing(sh_warp3d_view_map_model(md->e.view[v])))) view = v;
    } else if (m && m->recipe.wopts.defer_refine) {
        h = sh_warp_model_finer_spacing(md->e.model);
    }
    if (!h) return;
    pthread_mutex_lock(&m->mu);
    if (md->refine == REFINE_NONE) {
        md->refine = REFINE_ASKED;
        md->refine_h = h;
        md->refine_view = view;
        pthread_cond_broadcast(&m->cv);
    }
    pthread_mutex_unlock(&m->mu);
}

sh_status run_model_update(run_model *md, sh_warp *warp, const double *cur_xy, const double *cur_xyz,
                           const double *det_xy, const unsigned char *use, double *residual)
{
    const sh_modelcache_entry *e = &md->e;
    if (e->m3) return update_3d(md->owner, md, cur_xyz, det_xy, use, residual);
    refine_swap(md);
    /* use NULL: every point (sh_warp_model_update) */
    sh_status st = warp ? sh_warp_update(warp, e->model, cur_xy, use)
                        : sh_warp_model_update_subset(e->model, cur_xy, use);
    if (st != SH_OK) return st;
    refine_ask(md);
    if (use) return residual_subset(md, det_xy, residual);
    /* The map at a marker's reference position, f(q) = q + D(q), against where the detector saw
     * it this frame: the tracker's smoothing plus what an approximating method leaves out. */
    for (int k = 0; k < 2 * e->n; k++) md->vals[k] = cur_xy[k] - e->ref_xy[k];
    st = sh_interp_fit(e->interp, md->vals, 2, md->coef);
    if (st != SH_OK) return st;
    double worst = -1;
    for (int k = 0; k < e->n; k++) {
        double d[2];
        if (!isfinite(det_xy[2 * k])) continue; /* predicted this frame: nothing to compare */
        if (sh_interp_eval(e->interp, md->coef, 2, e->ref_xy[2 * k], e->ref_xy[2 * k + 1], d) != SH_OK) {
            worst = NAN;
            break;
        }
        double ex = e->ref_xy[2 * k] + d[0] - det_xy[2 * k], ey = e->ref_xy[2 * k + 1] + d[1] - det_xy[2 * k + 1];
        double r = sqrt(ex * ex + ey * ey);
        if (!(r <= worst)) worst = r; /* a NaN wins: never hidden */
    }
    *residual = worst;
    return SH_OK;
}

sh_status run_residual(const sh_interp_params *params, const double *ref_xy, const double *cur_xy,
                       const double *det_xy, int n, double *residual)
{
    if (n < 1 || n > SH_TRACK_MAX_MARKERS) return sh_error_set(SH_EINVAL, "residual: %d markers", n);
    run_models m;
    memset(&m, 0, sizeof m);
    m.recipe.params = *params;
    sh_warp_options_default(&m.recipe.wopts);
    m.recipe.width = m.recipe.height = 2;
    for (int k = 0; k < n; k++) { /* a frame that holds the points */
        if (ref_xy[2 * k] + 2 > m.recipe.width) m.recipe.width = (int)ref_xy[2 * k] + 2;
        if (ref_xy[2 * k + 1] + 2 > m.recipe.height) m.recipe.height = (int)ref_xy[2 * k + 1] + 2;
    }
    run_model *md = calloc(1, sizeof *md);
    if (!md) return sh_error_set(SH_ENOMEM, "residual: out of memory");
    sh_point ref[SH_TRACK_MAX_MARKERS]; /* the entry's key: ids 0..n-1 at these positions */
    int ids[SH_TRACK_MAX_MARKERS];
    for (int k = 0; k < n; k++) {
        memset(&ref[k], 0, sizeof ref[k]);
        ref[k].id = ids[k] = k;
        ref[k].x = ref_xy[2 * k];
        ref[k].y = ref_xy[2 * k + 1];
    }
    sh_status st = sh_modelcache_entry_set(&md->e, ref, n, ids, n);
    if (st == SH_OK) st = model_build(&m, md);
    if (st == SH_OK) st = run_model_update(md, NULL, cur_xy, NULL, det_xy, NULL, residual);
    model_free(md);
    free(md);
    return st;
}

/* ---- the helper thread ---- */
/* Outside the lock: g's landmarks from its frame, inside its markers' hull and off its tags (3D:
 * chosen in the output camera's frame, matched in the others' and triangulated). g itself is not
 * touched until the result is stored (under the lock) by the caller. */
static sh_status choose_landmarks(const run_models *m, const generation *g, sh_landmarks **lm, sh_landmarks_rig **rig)
{
    double xy[2 * SH_TRACK_MAX_MARKERS], xyz[3 * SH_TRACK_MAX_MARKERS];
    for (int k = 0; k < g->nref; k++) {
        xy[2 * k] = g->ref[k].x, xy[2 * k + 1] = g->ref[k].y;
        xyz[3 * k] = g->ref[k].X, xyz[3 * k + 1] = g->ref[k].Y, xyz[3 * k + 2] = g->ref[k].Z;
    }
    sh_plane planes[SH_CALIB_MAX_CAMERAS];
    const sh_plane *luma[SH_CALIB_MAX_CAMERAS];
    for (int c = 0; c < g->nluma; c++) {
        planes[c] = (sh_plane){g->luma[c], g->width, g->height, g->width};
        luma[c] = g->luma[c] ? &planes[c] : NULL;
    }
    if (m->recipe.three_d)
        return sh_landmarks_rig_create(&m->lp, &m->calib, m->camera, luma, xy, xyz, g->nref, g->tags, g->ntags, rig);
    sh_hull hull;
    sh_status st = sh_hull_compute(xy, g->nref, &hull);
    if (st == SH_OK) st = sh_landmarks_create(&m->lp, luma[0], &hull, g->tags, g->ntags, lm);
    return st;
}

/* Under the lock, after choose_landmarks: the landmarks' rows (markers, then the landmarks: in 3D
 * the ones with a reference X, Y, Z) and the full-set slot, whose key holds them all, of t: g
 * itself, or, live where g is in use or about to be (its markers' full set built first), a new
 * generation g->up (run_models_poll swaps it in), as the processing thread reads a generation in
 * use without the lock. Without landmarks (none found, or the choice failed: g's note says why)
 * the markers go on alone. */
static void landmarks_chosen(run_models *m, generation *g, sh_landmarks *lm, sh_landmarks_rig *rig, sh_status st)
{
    g->choosing = 0;
    generation *t = g;
    if (!m->wait && g->full && (g == m->cur || g == m->next)) {
        if (!(t = calloc(1, sizeof *t))) {
            snprintf(g->note, sizeof g->note, "landmarks: out of memory");
            sh_landmarks_destroy(lm);
            sh_landmarks_rig_destroy(rig);
            pthread_cond_broadcast(&m->cv);
            return;
        }
        memcpy(t->ref, g->ref, sizeof(sh_point) * (size_t)g->nref);
        t->nref = g->nref;
        t->frame = g->frame;
    }
    t->lm = lm;
    t->rig = rig;
    const sh_landmarks *primary = rig ? sh_landmarks_rig_primary(rig) : lm;
    const uint8_t *in3d = rig ? sh_landmarks_rig_in_3d(rig) : NULL;
    const double *X = rig ? sh_landmarks_rig_reference_xyz(rig) : NULL;
    int chosen = st == SH_OK && primary ? sh_landmarks_count(primary) : 0;
    t->nlm = 0;
    for (int k = 0; k < chosen; k++) t->nlm += !in3d || in3d[k];
    if (st != SH_OK)
        snprintf(g->note, sizeof g->note, "landmarks not chosen: %s", sh_error_message());
    else if (!chosen)
        snprintf(g->note, sizeof g->note, "no landmarks found inside the markers' hull (no corner textured enough)");
    else if (!t->nlm)
        snprintf(g->note, sizeof g->note, "none of the %d landmarks chosen was matched in another camera", chosen);
    if (t->nlm && !(t->rows = malloc(sizeof(sh_point) * (size_t)(t->nref + t->nlm)))) {
        snprintf(g->note, sizeof g->note, "landmarks: out of memory");
        t->nlm = 0;
    }
    if (!t->nlm) {
        sh_landmarks_destroy(t->lm);
        sh_landmarks_rig_destroy(t->rig);
        t->lm = NULL;
        t->rig = NULL;
        if (t != g) { /* g goes on with its markers' slot */
            free(t);
            pthread_cond_broadcast(&m->cv);
            return;
        }
    }
    int ids[SH_TRACK_MAX_MARKERS + RUN_MAX_LANDMARKS];
    for (int i = 0; i < t->nref; i++) ids[i] = t->ref[i].id;
    if (t->nlm) {
        memcpy(t->rows, t->ref, sizeof(sh_point) * (size_t)t->nref);
        const float *at = sh_landmarks_reference(primary);
        for (int k = 0, j = 0; k < chosen; k++) {
            if (in3d && !in3d[k]) continue;
            ids[t->nref + j] = SH_LANDMARK_ID_BASE + k;
            t->rows[t->nref + j] = (sh_point){.frame = t->frame, .id = SH_LANDMARK_ID_BASE + k, .x = at[2 * k],
                                              .y = at[2 * k + 1], .X = X ? X[3 * k] : NAN, .Y = X ? X[3 * k + 1] : NAN,
                                              .Z = X ? X[3 * k + 2] : NAN};
            j++;
        }
        t->nrows = t->nref + t->nlm;
    }
    t->full = slot_for(m, t, ids, t->nref + t->nlm);
    if (t != g) g->up = t;
    pthread_cond_broadcast(&m->cv);
}

static run_model *find_building(generation *g)
{
    if (!g) return NULL;
    for (int i = 0; i < SLOTS; i++)
        if (g->slot[i].state == BUILDING && !g->slot[i].taken) return &g->slot[i];
    return NULL;
}

/* g's landmarks, to be chosen and not taken yet */
static int to_choose(const generation *g) { return g && g->choosing && !g->choice_taken; }

/* g is one the processing thread uses or may swap in (not one in the trash) */
static int live_generation(const run_models *m, const generation *g)
{
    return g && (g == m->cur || g == m->next || (m->cur && g == m->cur->up) || (m->next && g == m->next->up));
}

static run_model *find_refine(generation *g)
{
    if (!g) return NULL;
    for (int i = 0; i < SLOTS; i++)
        if (g->slot[i].state == READY && g->slot[i].refine == REFINE_ASKED) return &g->slot[i];
    return NULL;
}

/* Under the lock, unlocked while it builds: md's model again on the finer grid it asked for (3D:
 * its view's grid), for refine_swap. The interpolant, reference positions and view it reads are
 * freed only by this thread; the result lands only if md still holds the model (view) it was
 * asked for (not evicted, not replaced). */
static void refine_model(run_models *m, run_model *md)
{
    sh_warp_model *asked_for = md->e.model, *fresh = NULL;
    sh_warp3d_view *view = m->recipe.three_d ? md->e.view[md->refine_view] : NULL;
    sh_warp3d_grid *grid = NULL;
    const sh_interp *interp = md->e.interp;
    const double *ref_xy = md->e.ref_xy;
    int n = md->e.n;
    sh_warp_options o = m->recipe.wopts;
    o.grid_spacing = md->refine_h;
    md->refine = REFINE_TAKEN;
    pthread_mutex_unlock(&m->mu);
    sh_status st = view ? sh_warp3d_view_grid_build(view, o.grid_spacing, &grid)
                        : sh_warp_model_create(interp, ref_xy, n, m->recipe.width, m->recipe.height, &o, &fresh);
    pthread_mutex_lock(&m->mu);
    int still = view ? md->e.view[md->refine_view] == view : md->e.model == asked_for;
    if (still && md->refine == REFINE_TAKEN) {
        md->refine = st == SH_OK ? REFINE_READY : REFINE_FAILED;
        if (st == SH_OK) {
            md->finer = fresh, md->finer_grid = grid;
            fresh = NULL, grid = NULL;
        }
    }
    pthread_mutex_unlock(&m->mu);
    sh_warp_model_destroy(fresh);
    sh_warp3d_grid_destroy(grid);
    pthread_mutex_lock(&m->mu);
}

static void *helper_main(void *arg)
{
    run_models *m = arg;
    pthread_mutex_lock(&m->mu);
    for (;;) {
        /* stopping: builds still queued are not started (run_models_destroy frees them and the
         * trash), so a stop waits for one build at most, not for the queue */
        if (m->stop) break;
        generation *trash = m->trash;
        if (trash) m->trash = trash->trash_next;
        sh_warp_model *replaced = NULL;
        sh_warp3d_grid *replaced_grid = NULL;
        for (int i = 0; i < 4 && !trash && !replaced && !replaced_grid; i++) {
            if (m->replaced[i]) { replaced = m->replaced[i]; m->replaced[i] = NULL; }
            else if (m->replaced_grid[i]) { replaced_grid = m->replaced_grid[i]; m->replaced_grid[i] = NULL; }
        }
        if (replaced || replaced_grid) {
            pthread_mutex_unlock(&m->mu);
            sh_warp_model_destroy(replaced);
            sh_warp3d_grid_destroy(replaced_grid);
            pthread_mutex_lock(&m->mu);
            continue;
        }
        run_model evicted;
        int have_evicted = 0;
        if (!trash && m->nevicted) {
            evicted = *m->evicted[--m->nevicted];
            free(m->evicted[m->nevicted]);
            have_evicted = 1;
        }
        /* the next reference's model first (live: its markers' alone, which ends the raw frames),
         * then the landmarks of the next or the one in use, before the full set's model whose key
         * holds them */
        run_model *job = find_building(m->next);
        generation *job_gen = job ? m->next : NULL;
        generation *choose = job ? NULL : to_choose(m->next) ? m->next : to_choose(m->cur) ? m->cur : NULL;
        if (choose && !trash && !have_evicted) {
            /* the landmarks before the full set's model, whose key holds them */
            choose->choice_taken = 1;
            pthread_mutex_unlock(&m->mu);
            sh_landmarks *lm = NULL;
            sh_landmarks_rig *rig = NULL;
            sh_status st = choose_landmarks(m, choose, &lm, &rig);
            /* the frame's copy is needed no more (only this thread reads or frees it) */
            for (int c = 0; c < choose->nluma; c++) free(choose->luma[c]), choose->luma[c] = NULL;
            pthread_mutex_lock(&m->mu);
            /* stored even when choose was replaced meanwhile (it then waits in the trash, and
             * generation_free frees what it holds) */
            landmarks_chosen(m, choose, lm, rig, st);
            continue;
        }
        /* the next reference first, then the one in use with its landmarks: the running one
         * still works meanwhile */
        generation *ups[2] = {m->next ? m->next->up : NULL, m->cur ? m->cur->up : NULL};
        for (int i = 0; i < 2 && !job; i++)
            if ((job = find_building(ups[i]))) job_gen = ups[i];
        if (!job) { job = find_building(m->cur); job_gen = job ? m->cur : NULL; }
        /* then the finer grids of models in use (new models first: without one a set is not shown) */
        run_model *refine = !trash && !have_evicted && !job ? find_refine(m->cur) : NULL;
        if (refine) {
            refine_model(m, refine);
            continue;
        }
        if (!trash && !have_evicted && !job) {
            pthread_cond_wait(&m->cv, &m->mu);
            continue;
        }
        if (trash || have_evicted) {
            pthread_mutex_unlock(&m->mu);
            generation_free(trash);
            if (have_evicted) model_free(&evicted);
            pthread_mutex_lock(&m->mu);
            continue;
        }
        /* Build outside the lock on a private copy: the processing thread may evict the slot
         * or replace the generation meanwhile; the result lands only if the slot still asks. */
        run_model tmp;
        memset(&tmp, 0, sizeof tmp);
        /* the key copied from the generation's reference, which only this thread frees */
        int nrows;
        const sh_point *rows = rows_of(job_gen, &nrows);
        sh_status st = sh_modelcache_entry_set(&tmp.e, rows, nrows, job->e.ids, job->e.n);
        if (st != SH_OK) { /* out of memory: the set is marked failed like a model that would not build */
            job->state = FAILED;
            snprintf(job->err, sizeof job->err, "%s", sh_error_message());
            pthread_cond_broadcast(&m->cv);
            continue;
        }
        job->taken = 1;
        pthread_mutex_unlock(&m->mu);
        st = model_build(m, &tmp);
        pthread_mutex_lock(&m->mu);
        int still = live_generation(m, job_gen) && job->state == BUILDING && job->taken &&
                    sh_modelcache_entry_is(&job->e, tmp.e.ids, tmp.e.n);
        if (still) {
            unsigned long lu = job->e.last_used;
            if (st == SH_OK) {
                model_free(job); /* its key: tmp has its own */
                *job = tmp;
                job->state = READY;
                m->builds++;
            } else {
                model_free(&tmp);
                job->state = FAILED;
                snprintf(job->err, sizeof job->err, "%s", sh_error_message());
            }
            job->taken = 0;
            job->e.last_used = lu;
            pthread_cond_broadcast(&m->cv);
        } else {
            pthread_mutex_unlock(&m->mu);
            model_free(&tmp);
            pthread_mutex_lock(&m->mu);
        }
    }
    pthread_mutex_unlock(&m->mu);
    return NULL;
}

sh_status run_models_create(const sh_interp_params *params, const sh_warp_options *wopts, int width,
                            int height, int wait, run_models **out)
{
    run_models *m = calloc(1, sizeof *m);
    if (!m) return sh_error_set(SH_ENOMEM, "models: out of memory");
    m->recipe.params = *params;
    m->recipe.wopts = *wopts;
    m->recipe.width = width;
    m->recipe.height = height;
    /* live: refinements on the helper (refine_swap); test mode refines in the update, as stillheart
     * warp does, so that its frames stay warp's */
    m->recipe.wopts.defer_refine = !wait;
    m->wait = wait;
    pthread_mutex_init(&m->mu, NULL);
    pthread_cond_init(&m->cv, NULL);
    if (pthread_create(&m->helper, NULL, helper_main, m)) {
        run_models_destroy(m);
        return sh_error_set(SH_ENOMEM, "models: cannot start the helper thread");
    }
    m->started = 1;
    *out = m;
    return SH_OK;
}

void run_models_destroy(run_models *m)
{
    if (!m) return;
    pthread_mutex_lock(&m->mu);
    m->stop = 1;
    pthread_cond_broadcast(&m->cv);
    pthread_mutex_unlock(&m->mu);
    if (m->started) pthread_join(m->helper, NULL);
    generation_free(m->prev);
    generation_free(m->cur);
    generation_free(m->next);
    while (m->trash) {
        generation *g = m->trash;
        m->trash = g->trash_next;
        generation_free(g);
    }
    for (int i = 0; i < m->nevicted; i++) { model_free(m->evicted[i]); free(m->evicted[i]); }
    for (int i = 0; i < 4; i++) sh_warp_model_destroy(m->replaced[i]), sh_warp3d_grid_destroy(m->replaced_grid[i]);
    pthread_mutex_destroy(&m->mu);
    pthread_cond_destroy(&m->cv);
    free(m);
}

/* Under the mutex: hands g to the helper to free. */
static void discard(run_models *m, generation *g)
{
    if (!g) return;
    g->trash_next = m->trash;
    m->trash = g;
    pthread_cond_broadcast(&m->cv);
}

typedef struct {
    run_models *m;
    generation *g;
} lookup_ctx;

static sh_modelcache_entry *slot_entry(void *table, int i) { return &((lookup_ctx *)table)->g->slot[i].e; }

/* A slot being built is not evicted (the helper holds it), nor the one in use. */
static int slot_kept(void *table, int i)
{
    const lookup_ctx *c = table;
    return c->g->slot[i].state == BUILDING || &c->g->slot[i] == c->m->pinned;
}

/* Under the mutex: slot for ids in g (a hit, or a new BUILDING slot in place of the LRU one). */
static run_model *slot_for(run_models *m, generation *g, const int *ids, int n)
{
    lookup_ctx ctx = {m, g};
    int v, hit = sh_modelcache_lookup(&ctx, SLOTS, slot_entry, slot_kept, &g->clock, ids, n, &v);
    if (hit >= 0) return &g->slot[hit];
    if (v < 0) return NULL; /* every slot building: ask again next frame */
    run_model *victim = &g->slot[v];
    if (victim->state == READY || victim->state == FAILED) {
        run_model *e = m->nevicted < SLOTS * 2 ? malloc(sizeof *e) : NULL;
        if (e) {
            *e = *victim;
            m->evicted[m->nevicted++] = e;
        } else {
            model_free(victim);
        }
    }
    memset(victim, 0, sizeof *victim);
    /* fails for ids not in the reference (the caller's bug) or out of memory: asked again */
    int nrows;
    const sh_point *rows = rows_of(g, &nrows);
    if (sh_modelcache_entry_set(&victim->e, rows, nrows, ids, n) != SH_OK) return NULL;
    victim->state = BUILDING;
    victim->e.last_used = ++g->clock;
    pthread_cond_broadcast(&m->cv);
    return victim;
}

void run_models_set_landmarks(run_models *m, const sh_landmarks_params *lp, double smoothing)
{
    m->lp = *lp;
    /* the RBFs' (TPS; in 3D its surface's and displacement's, converted to their mm by the
     * models: modelcache.h); given at 1080p, scaled to the frame's pixels as the landmarks'
     * lengths are (sh_landmarks_smoothing) */
    m->recipe.point_smoothing =
        sh_landmarks_smoothing(smoothing, sh_landmarks_reduction(lp, m->recipe.width, m->recipe.height));
    m->recipe.smoothed_from = SH_LANDMARK_ID_BASE;
}

/* g's copy of what the landmarks are chosen from (a NULL luma: a camera whose frame is missing). */
static sh_status keep_frame(generation *g, const sh_plane *const *luma, int nluma, int primary, const double *tags,
                            int ntags)
{
    g->width = luma[primary]->width;
    g->height = luma[primary]->height;
    g->nluma = nluma;
    g->tags = malloc(sizeof(double) * 8 * (size_t)(ntags > 0 ? ntags : 1));
    if (!g->tags) return sh_error_set(SH_ENOMEM, "reference: out of memory for its frame");
    for (int c = 0; c < nluma; c++) {
        if (!luma[c]) continue;
        if (luma[c]->width != g->width || luma[c]->height != g->height)
            return sh_error_set(SH_EINVAL, "reference: camera %d's frame is %dx%d, not %dx%d", c, luma[c]->width,
                                luma[c]->height, g->width, g->height);
        if (!(g->luma[c] = malloc((size_t)g->width * (size_t)g->height)))
            return sh_error_set(SH_ENOMEM, "reference: out of memory for its frame");
        for (int y = 0; y < g->height; y++)
            memcpy(g->luma[c] + (size_t)y * g->width, luma[c]->data + (size_t)y * luma[c]->stride, (size_t)g->width);
    }
    if (ntags > 0) memcpy(g->tags, tags, sizeof(double) * 8 * (size_t)ntags);
    g->ntags = ntags;
    g->choosing = 1;
    return SH_OK;
}

sh_status run_models_set_reference(run_models *m, const sh_point *ref, int n, int frame, const sh_plane *const *luma,
                                   const double *tags, int ntags)
{
    if (n < 1 || n > SH_TRACK_MAX_MARKERS) return sh_error_set(SH_EINVAL, "reference: %d markers", n);
    generation *g = calloc(1, sizeof *g);
    if (!g) return sh_error_set(SH_ENOMEM, "reference: out of memory");
    memcpy(g->ref, ref, sizeof(sh_point) * (size_t)n);
    g->nref = n;
    g->frame = frame;
    if (m->lp.max_points > 0) {
        /* 2D: the output camera's frame (luma[0]); 3D: every camera's, in the calibration's order */
        int nluma = m->recipe.three_d ? m->calib.num_cameras : 1;
        int primary = m->recipe.three_d ? m->camera : 0;
        sh_status st = luma && luma[primary] ? keep_frame(g, luma, nluma, primary, tags, ntags)
                                             : sh_error_set(SH_EINVAL, "reference: no frame for the landmarks");
        if (st != SH_OK) {
            generation_free(g);
            return st;
        }
    }
    int ids[SH_TRACK_MAX_MARKERS];
    for (int i = 0; i < n; i++) ids[i] = ref[i].id;
    pthread_mutex_lock(&m->mu);
    discard(m, m->next);
    m->next = g;
    /* test mode: the helper chooses the landmarks, then asks for the full set with them; live, the
     * markers' full set is built first and the landmarks come after (generation.up) */
    if (g->choosing && m->wait)
        pthread_cond_broadcast(&m->cv);
    else
        g->full = slot_for(m, g, ids, n);
    while (m->wait && (g->choosing || (g->full && g->full->state == BUILDING))) pthread_cond_wait(&m->cv, &m->mu);
    pthread_mutex_unlock(&m->mu);
    return SH_OK;
}

sh_landmarks *run_models_landmarks(run_models *m)
{
    /* cur changes only in run_models_poll, on the calling (processing) thread */
    return m->cur ? m->cur->lm : NULL;
}

sh_landmarks_rig *run_models_rig(run_models *m)
{
    return m->cur ? m->cur->rig : NULL;
}

const char *run_models_landmarks_note(const run_models *m)
{
    return m->note;
}

/* g's full-set model built (or failed): nothing left to wait for */
static int full_done(const generation *g) { return !g->full || g->full->state != BUILDING; }

int run_models_poll(run_models *m, int *frame, int *n)
{
    pthread_mutex_lock(&m->mu);
    int ev = 0;
    /* the swap waits for the full-set model (slot 0 of a fresh generation); in test mode for the
     * landmarks too, whose full set it is */
    generation *g = m->next;
    if (g && (!g->choosing || g->full) && full_done(g)) {
        discard(m, m->prev);
        discard(m, m->cur);
        m->prev = NULL;
        m->pinned = NULL;
        m->cur = g;
        m->next = NULL;
        m->note[0] = 0;
        ev |= RUN_MODELS_REFERENCE;
        if (frame) *frame = g->frame;
        if (n) *n = g->nref;
    }
    g = m->cur;
    if (g && g->up && full_done(g->up)) {
        generation *u = g->up;
        g->up = NULL;
        if (u->full && u->full->state == FAILED) { /* the markers go on alone */
            snprintf(g->note, sizeof g->note, "the model with its landmarks failed: %.120s", u->full->err);
            discard(m, u);
        } else { /* g is kept while the processing thread may hold one of its models */
            discard(m, m->prev);
            m->prev = g;
            m->pinned = NULL;
            m->cur = u;
            ev |= RUN_MODELS_LANDMARKS;
        }
    }
    g = m->cur;
    if (g && !g->choosing && !g->up && g->note[0] && !g->told) {
        g->told = 1;
        snprintf(m->note, sizeof m->note, "%s", g->note);
        ev |= RUN_MODELS_NO_LANDMARKS;
    }
    if (ev && !(ev & RUN_MODELS_REFERENCE) && frame) *frame = m->cur->frame;
    if (ev && !(ev & RUN_MODELS_REFERENCE) && n) *n = m->cur->nref;
    pthread_mutex_unlock(&m->mu);
    return ev;
}

int run_models_pending(run_models *m)
{
    pthread_mutex_lock(&m->mu);
    int p = m->next != NULL;
    pthread_mutex_unlock(&m->mu);
    return p;
}

const sh_point *run_models_reference(const run_models *m, int *n)
{
    /* cur changes only in run_models_poll, on the calling (processing) thread */
    *n = m->cur ? m->cur->nref : 0;
    return m->cur ? m->cur->ref : NULL;
}

int run_models_get(run_models *m, const int *ids, int n, run_model **out)
{
    if (!m->cur) return 0;
    /* every model of a reference with landmarks holds them all (a frame picks its subset) */
    int key[SH_TRACK_MAX_MARKERS + RUN_MAX_LANDMARKS], nlm = m->cur->nlm;
    if (nlm) {
        if (n > SH_TRACK_MAX_MARKERS) return sh_error_set(SH_EINVAL, "model: %d markers", n), -1;
        memcpy(key, ids, sizeof(int) * (size_t)n);
        for (int k = 0; k < nlm; k++) key[n + k] = m->cur->rows[m->cur->nref + k].id;
        ids = key;
        n += nlm;
    }
    pthread_mutex_lock(&m->mu);
    run_model *s = slot_for(m, m->cur, ids, n);
    while (m->wait && s && s->state == BUILDING) pthread_cond_wait(&m->cv, &m->mu);
    int r = !s ? 0 : s->state == READY ? 1 : s->state == FAILED ? -1 : 0;
    if (r == -1) sh_error_set(SH_EDEGENERATE, "model for %d markers: %s", n, s->err);
    pthread_mutex_unlock(&m->mu);
    if (r == 1) *out = m->pinned = s;
    return r;
}

const sh_warp_model *run_model_warp(const run_model *md)
{
    return md->e.view[0] ? sh_warp3d_view_map_model(md->e.view[0]) : md->e.model;
}

int run_model_views(const run_model *md, const sh_warp3d_view *views[2])
{
    int n = md->owner ? md->owner->recipe.nviews : 0;
    for (int v = 0; v < 2; v++) views[v] = v < n ? md->e.view[v] : NULL;
    return n;
}

sh_status run_models_set_3d(run_models *m, const sh_calib *calib, int camera, double baseline)
{
    if (camera < 0 || camera >= calib->num_cameras)
        return sh_error_set(SH_EINVAL, "calibration: no camera %d (%d cameras)", camera, calib->num_cameras);
    if (baseline < 0 || !isfinite(baseline)) return sh_error_set(SH_EINVAL, "stereo: baseline %g mm", baseline);
    sh_modelcache_recipe *r = &m->recipe;
    r->source_cam = r->view_cam[0] = calib->cam[camera];
    r->nviews = 1;
    if (baseline > 0) {
        sh_warp3d_stereo_cameras(&calib->cam[camera], baseline, &r->view_cam[0], &r->view_cam[1]);
        r->nviews = 2;
    }
    sh_warp3d_params_default(&r->p3);
    r->p3.surface = r->p3.displacement = r->params;
    sh_warp3d_view_options_default(&r->vopts);
    /* live, the views' finer grids are built on the helper and swapped in (refine_swap) as the 2D
     * models' are; the model's own 2D grid is not used */
    r->vopts.warp = r->wopts;
    r->wopts.defer_refine = 0;
    r->three_d = 1;
    m->calib = *calib;
    m->camera = camera;
    return SH_OK;
}

const int *run_model_ids(const run_model *md, int *n)
{
    *n = md->e.n;
    return md->e.ids;
}

int run_model_markers(const run_model *md)
{
    int k = 0;
    while (k < md->e.n && md->e.ids[k] < SH_LANDMARK_ID_BASE) k++;
    return k;
}

const double *run_model_ref_xy(const run_model *md) { return md->e.ref_xy; }

int run_models_builds(const run_models *m) { return m->builds; }

/* refined changes only in refine_swap, on the calling (processing) thread */
int run_models_refined(const run_models *m) { return m->refined; }
