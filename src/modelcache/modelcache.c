/* Models per marker set (modelcache.h): an entry's key and models, the lookup in a table of them,
 * and the one-thread table that builds on a miss. */
#include "stillheart/modelcache.h"

#include <stdlib.h>
#include <string.h>

static void free_models(sh_modelcache_entry *e)
{
    for (int v = 0; v < 2; v++) sh_warp3d_view_destroy(e->view[v]), e->view[v] = NULL;
    sh_warp3d_ply_destroy(e->ply);
    sh_warp3d_model_destroy(e->m3);
    sh_warp_model_destroy(e->model);
    sh_interp_destroy(e->interp);
    e->ply = NULL;
    e->m3 = NULL;
    e->model = NULL;
    e->interp = NULL;
}

void sh_modelcache_entry_clear(sh_modelcache_entry *e)
{
    free_models(e);
    free(e->ids);
    free(e->ref_xy);
    free(e->ref_xyz);
    memset(e, 0, sizeof *e);
}

sh_status sh_modelcache_entry_set(sh_modelcache_entry *e, const sh_point *ref, int nref, const int *ids, int n)
{
    sh_modelcache_entry_clear(e);
    if (n < 1) return sh_error_set(SH_EINVAL, "models: an empty marker set");
    e->ids = malloc(sizeof(int) * (size_t)n);
    e->ref_xy = malloc(sizeof(double) * 2 * (size_t)n);
    e->ref_xyz = malloc(sizeof(double) * 3 * (size_t)n);
    if (!e->ids || !e->ref_xy || !e->ref_xyz) {
        sh_modelcache_entry_clear(e);
        return sh_error_set(SH_ENOMEM, "models: out of memory");
    }
    for (int k = 0, r = 0; k < n; k++) {
        while (r < nref && ref[r].id != ids[k]) r++;
        if (r == nref) {
            sh_modelcache_entry_clear(e);
            return sh_error_set(SH_EINVAL, "models: marker %d is not in the reference", ids[k]);
        }
        e->ids[k] = ids[k];
        e->ref_xy[2 * k] = ref[r].x;
        e->ref_xy[2 * k + 1] = ref[r].y;
        e->ref_xyz[3 * k] = ref[r].X;
        e->ref_xyz[3 * k + 1] = ref[r].Y;
        e->ref_xyz[3 * k + 2] = ref[r].Z;
    }
    e->n = n;
    return SH_OK;
}

/* 1 when the recipe smooths some of e's rows (the ones from smoothed_from on). */
static int smooths_rows(const sh_modelcache_entry *e, const sh_modelcache_recipe *r)
{
    for (int i = 0; r->point_smoothing > 0 && i < e->n; i++)
        if (e->ids[i] >= r->smoothed_from) return 1;
    return 0;
}

/* Each row's own smoothing, the recipe's divided by scale^2 for the smoothed rows and 0 for the
 * others, in *out (to free). */
static sh_status row_smoothings(const sh_modelcache_entry *e, const sh_modelcache_recipe *r, double scale,
                                double **out)
{
    double *lambda = malloc(sizeof(double) * (size_t)e->n);
    if (!lambda) return sh_error_set(SH_ENOMEM, "models: out of memory");
    for (int i = 0; i < e->n; i++) lambda[i] = e->ids[i] >= r->smoothed_from ? r->point_smoothing / (scale * scale) : 0.0;
    *out = lambda;
    return SH_OK;
}

/* Another method than the RBFs has no smoothing: its rows are interpolated exactly, as without
 * it (sh_interp_create_smoothed would refuse). */
static sh_status build_interp(sh_modelcache_entry *e, const sh_modelcache_recipe *r)
{
    if (!sh_interp_method_smooths(r->params.method) || !smooths_rows(e, r))
        return sh_interp_create(&r->params, e->ref_xy, e->n, &e->interp);
    double *lambda;
    sh_status st = row_smoothings(e, r, 1, &lambda);
    if (st == SH_OK) st = sh_interp_create_smoothed(&r->params, e->ref_xy, e->n, lambda, &e->interp);
    free(lambda);
    return st;
}

/* The smoothing is given in the source camera's pixels, as in 2D; over the surface's millimetres
 * it is divided by the square of the pixels a millimetre spans there (sh_warp3d_model_create_smoothed
 * says why that is the same fit for TPS, and what a B-spline makes of it). */
static sh_status build_model3(sh_modelcache_entry *e, const sh_modelcache_recipe *r)
{
    if (!smooths_rows(e, r)) return sh_warp3d_model_create(&r->p3, e->ref_xyz, e->n, &e->m3);
    /* only an RBF reads the value; a B-spline only which rows have one */
    double scale = 1, *lambda = NULL;
    sh_status st = sh_interp_method_smooths(r->p3.surface.method) || sh_interp_method_smooths(r->p3.displacement.method)
                       ? sh_warp3d_pixels_per_mm(&r->source_cam, e->ref_xyz, e->n, &scale)
                       : SH_OK;
    if (st == SH_OK) st = row_smoothings(e, r, scale, &lambda);
    if (st == SH_OK) st = sh_warp3d_model_create_smoothed(&r->p3, e->ref_xyz, e->n, lambda, &e->m3);
    free(lambda);
    return st;
}

sh_status sh_modelcache_entry_build(sh_modelcache_entry *e, const sh_modelcache_recipe *r)
{
    sh_status st;
    if (r->three_d) {
        st = build_model3(e, r);
        for (int v = 0; v < r->nviews && v < 2 && st == SH_OK; v++)
            st = sh_warp3d_view_create(e->m3, &r->view_cam[v], &r->source_cam, r->width, r->height, &r->vopts,
                                       &e->view[v]);
        if (st == SH_OK && r->ply_spacing > 0) st = sh_warp3d_ply_create(e->m3, r->ply_spacing, r->ply_mesh, &e->ply);
    } else {
        st = build_interp(e, r);
        if (st == SH_OK)
            st = sh_warp_model_create(e->interp, e->ref_xy, e->n, r->width, r->height, &r->wopts, &e->model);
    }
    if (st != SH_OK) free_models(e);
    return st;
}

int sh_modelcache_entry_is(const sh_modelcache_entry *e, const int *ids, int n)
{
    return e->n > 0 && e->n == n && !memcmp(e->ids, ids, sizeof(int) * (size_t)n);
}

int sh_modelcache_lookup(void *table, int count, sh_modelcache_entry *(*entry)(void *table, int i),
                         int (*keep)(void *table, int i), unsigned long *clock, const int *ids, int n,
                         int *victim)
{
    *victim = -1;
    for (int i = 0; i < count; i++) {
        sh_modelcache_entry *e = entry(table, i);
        if (sh_modelcache_entry_is(e, ids, n)) {
            e->last_used = ++*clock;
            return i;
        }
        if (keep && keep(table, i)) continue;
        if (*victim < 0) {
            *victim = i;
            continue;
        }
        const sh_modelcache_entry *v = entry(table, *victim);
        if (v->n > 0 && (e->n == 0 || e->last_used < v->last_used)) *victim = i;
    }
    return -1;
}

struct sh_modelcache {
    sh_modelcache_recipe recipe;
    sh_point *ref;
    int nref, count;
    unsigned long clock;
    int builds;
    int64_t build_ns;
    sh_modelcache_entry slot[];
};

sh_status sh_modelcache_create(const sh_modelcache_recipe *r, const sh_point *ref, int nref, int slots,
                               sh_modelcache **out)
{
    if (slots < 1 || nref < 0) return sh_error_set(SH_EINVAL, "models: %d slots, %d reference markers", slots, nref);
    sh_modelcache *c = calloc(1, sizeof *c + sizeof(sh_modelcache_entry) * (size_t)slots);
    sh_point *copy = malloc(sizeof(sh_point) * (size_t)(nref ? nref : 1));
    if (!c || !copy) {
        free(c);
        free(copy);
        return sh_error_set(SH_ENOMEM, "models: out of memory");
    }
    memcpy(copy, ref, sizeof(sh_point) * (size_t)nref);
    c->recipe = *r;
    c->ref = copy;
    c->nref = nref;
    c->count = slots;
    *out = c;
    return SH_OK;
}

void sh_modelcache_destroy(sh_modelcache *c)
{
    if (!c) return;
    for (int i = 0; i < c->count; i++) sh_modelcache_entry_clear(&c->slot[i]);
    free(c->ref);
    free(c);
}

static sh_modelcache_entry *slot_of(void *table, int i) { return &((sh_modelcache *)table)->slot[i]; }

sh_status sh_modelcache_get(sh_modelcache *c, const int *ids, int n, sh_modelcache_entry **out)
{
    int victim;
    int hit = sh_modelcache_lookup(c, c->count, slot_of, NULL, &c->clock, ids, n, &victim);
    if (hit >= 0) {
        *out = &c->slot[hit];
        return SH_OK;
    }
    sh_modelcache_entry *e = &c->slot[victim];
    int64_t t0 = sh_monotonic_ns();
    sh_status st = sh_modelcache_entry_set(e, c->ref, c->nref, ids, n);
    if (st == SH_OK) st = sh_modelcache_entry_build(e, &c->recipe);
    if (st != SH_OK) {
        sh_modelcache_entry_clear(e); /* a set that failed is tried again when it comes back */
        return st;
    }
    e->last_used = ++c->clock;
    c->builds++;
    c->build_ns += sh_monotonic_ns() - t0;
    *out = e;
    return SH_OK;
}

int sh_modelcache_builds(const sh_modelcache *c) { return c->builds; }

double sh_modelcache_build_seconds(const sh_modelcache *c) { return (double)c->build_ns * 1e-9; }
