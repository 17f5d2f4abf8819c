/* The map from reference to current positions: built per reference, updated per frame. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "warp_internal.h"

void sh_warp_options_default(sh_warp_options *opts)
{
    opts->max_error = 0.05;
    opts->grid_spacing = 16;
    opts->coarsest_spacing = 16;
    opts->defer_refine = 0;
}

/* Triangles listed per band of TRIANGLE_BAND rows, so a row visits only the few triangles
 * that can cross it: band b's are tris[start[b] .. start[b + 1]). With tris NULL, only start is
 * made (the counts); next: bands ints of scratch. */
static void list_bands(const sh_warp_model *m, const double *ybounds, int ntri, int *start, int *tris, int *next)
{
    if (!tris) memset(start, 0, sizeof(int) * ((size_t)m->bands + 1));
    else memset(next, 0, sizeof(int) * (size_t)m->bands);
    for (int t = 0; t < ntri; t++) {
        int b0 = (int)((ybounds[2 * t] - 1e-6 - m->band_origin) / TRIANGLE_BAND);
        int b1 = (int)((ybounds[2 * t + 1] + 1e-6 - m->band_origin) / TRIANGLE_BAND);
        for (int b = b0 < 0 ? 0 : b0; b <= b1 && b < m->bands; b++) {
            if (tris) tris[start[b] + next[b]++] = t;
            else start[b + 1]++;
        }
    }
    if (!tris)
        for (int b = 0; b < m->bands; b++) start[b + 1] += start[b];
}

static sh_status build_bands(sh_warp_model *m)
{
    double y0 = m->hull.ymin - 1;
    m->band_origin = y0;
    m->bands = (int)((m->hull.ymax + 1 - y0) / TRIANGLE_BAND) + 1;
    m->band_start = m->band_start_all = calloc((size_t)m->bands + 1, sizeof(int));
    int *next = calloc((size_t)m->bands, sizeof(int));
    if (!m->band_start || !next) {
        free(next);
        return sh_error_set(SH_ENOMEM, "warp: out of memory");
    }
    list_bands(m, m->tri_ybounds, m->ntri, m->band_start, NULL, next);
    m->band_tris = m->band_tris_all = malloc(sizeof(int) * ((size_t)m->band_start[m->bands] + 1));
    if (m->band_tris) list_bands(m, m->tri_ybounds, m->ntri, m->band_start, m->band_tris, next);
    free(next);
    return m->band_tris ? SH_OK : sh_error_set(SH_ENOMEM, "warp: out of memory");
}

static void triangle_ybounds(const double *ref, const int *tri, int ntri, double *ybounds)
{
    for (int t = 0; t < ntri; t++) {
        double y0 = ref[2 * tri[3 * t] + 1], y1 = ref[2 * tri[3 * t + 1] + 1], y2 = ref[2 * tri[3 * t + 2] + 1];
        ybounds[2 * t] = fmin(y0, fmin(y1, y2));
        ybounds[2 * t + 1] = fmax(y0, fmax(y1, y2));
    }
}

/* The triangles of every point in use again (after a subset's). */
static void all_triangles(sh_warp_model *m)
{
    m->ntri = sh_interp_triangles(m->interp, &m->tri);
    m->tri_ybounds = m->ybounds_all;
    m->band_start = m->band_start_all;
    m->band_tris = m->band_tris_all;
    m->span_start = m->span_start_all;
    m->hull = m->hull_all;
}

/* The Delaunay triangles of the used points alone (sh_interp_delaunay: qhull's, in the same
 * canonical form as the interp's, so the map is bit for bit that of a model built on those points
 * alone), their bands and hull. The first call allocates for any subset; the later ones
 * nothing. */
static sh_status subset_triangles(sh_warp_model *m, const unsigned char *use)
{
    size_t n = (size_t)m->n;
    /* each made once (a call after running out of memory makes the ones still missing); a
     * subset's triangles are 2n - 5 at most, each band's too */
    if (!m->tri_work) m->tri_work = malloc(sh_interp_delaunay_work_size(m->n));
    if (!m->sub_tri) m->sub_tri = malloc(sizeof(int) * 6 * n);
    if (!m->sub_index) m->sub_index = malloc(sizeof(int) * n);
    if (!m->sub_ybounds) m->sub_ybounds = malloc(sizeof(double) * 4 * n);
    if (!m->sub_band_start) m->sub_band_start = malloc(sizeof(int) * ((size_t)m->bands + 1));
    if (!m->sub_band_tris) m->sub_band_tris = malloc(sizeof(int) * (2 * n * (size_t)m->bands + 1));
    if (!m->sub_band_next) m->sub_band_next = malloc(sizeof(int) * (size_t)m->bands);
    if (!m->subset_xy) m->subset_xy = malloc(sizeof(double) * 2 * n);
    if (!m->tri_work || !m->sub_tri || !m->sub_index || !m->sub_ybounds || !m->sub_band_start || !m->sub_band_tris ||
        !m->sub_band_next || !m->subset_xy)
        return sh_error_set(SH_ENOMEM, "warp: out of memory");
    int s = 0;
    for (int i = 0; i < m->n; i++)
        if (use[i]) {
            m->subset_xy[2 * s] = m->ref_xy[2 * i], m->subset_xy[2 * s + 1] = m->ref_xy[2 * i + 1];
            m->sub_index[s++] = i;
        }
    int nt = 0;
    sh_status st = sh_interp_delaunay(m->subset_xy, s, m->tri_work, m->sub_tri, &nt);
    if (st == SH_OK) st = sh_hull_compute(m->subset_xy, s, &m->hull);
    if (st != SH_OK) {
        all_triangles(m); /* a failed update leaves a whole model behind */
        return st;
    }
    for (int k = 0; k < 3 * nt; k++) m->sub_tri[k] = m->sub_index[m->sub_tri[k]];
    m->tri = m->sub_tri;
    m->ntri = nt;
    triangle_ybounds(m->ref_xy, m->tri, nt, m->sub_ybounds);
    m->tri_ybounds = m->sub_ybounds;
    list_bands(m, m->tri_ybounds, nt, m->sub_band_start, NULL, m->sub_band_next);
    list_bands(m, m->tri_ybounds, nt, m->sub_band_start, m->sub_band_tris, m->sub_band_next);
    m->band_start = m->sub_band_start;
    m->band_tris = m->sub_band_tris;
    m->span_start = NULL;
    return SH_OK;
}

void sh_warp_model_destroy(sh_warp_model *m)
{
    if (!m) return;
    warp_grid_free(m);
    free(m->coef);
    free(m->tri_map);
    free(m->ybounds_all);
    free(m->band_start_all);
    free(m->band_tris_all);
    free(m->span_start_all);
    free(m->spans);
    free(m->tri_work);
    free(m->sub_tri);
    free(m->sub_index);
    free(m->sub_ybounds);
    free(m->sub_band_start);
    free(m->sub_band_tris);
    free(m->sub_band_next);
    free((void *)m->ref_xy);
    free(m->disp);
    free(m->subset_work);
    free(m->subset_xy);
    free(m);
}

sh_status sh_warp_model_create(const sh_interp *interp, const double *ref_xy, int n, int width,
                               int height, const sh_warp_options *opts, sh_warp_model **out)
{
    if (!interp || !ref_xy || !out || width <= 0 || height <= 0)
        return sh_error_set(SH_EINVAL, "warp: invalid model arguments");
    if (n != sh_interp_num_points(interp))
        return sh_error_set(SH_EINVAL, "warp: %d points given, the interpolant has %d", n,
                            sh_interp_num_points(interp));
    sh_warp_model *m = calloc(1, sizeof *m);
    if (!m) return sh_error_set(SH_ENOMEM, "warp: out of memory");
    m->interp = interp;
    m->n = n;
    m->width = width;
    m->height = height;
    if (opts) m->opts = *opts;
    else sh_warp_options_default(&m->opts);
    sh_status st = SH_OK;
    if (!(m->opts.max_error > 0) || m->opts.grid_spacing < 1 ||
        (m->opts.grid_spacing & (m->opts.grid_spacing - 1)) || m->opts.coarsest_spacing < 0 ||
        (m->opts.coarsest_spacing & (m->opts.coarsest_spacing - 1))) {
        st = sh_error_set(SH_EINVAL, "warp: max_error must be > 0 and grid spacings powers of two");
        goto fail;
    }
    if ((st = sh_hull_compute(ref_xy, n, &m->hull)) != SH_OK) goto fail;
    m->hull_all = m->hull;

    double *ref = malloc(sizeof(double) * 2 * (size_t)n);
    m->disp = malloc(sizeof(double) * 2 * (size_t)n);
    m->coef = malloc(sizeof(double) * 2 * (size_t)sh_interp_num_coefs(interp));
    if (!ref || !m->disp || !m->coef) {
        free(ref);
        st = sh_error_set(SH_ENOMEM, "warp: out of memory");
        goto fail;
    }
    memcpy(ref, ref_xy, sizeof(double) * 2 * (size_t)n);
    m->ref_xy = ref;

    const int *tri;
    m->ntri = sh_interp_triangles(interp, &tri);
    if (m->ntri > 0) {
        m->kind = MODEL_TRIANGLES;
        m->tri = tri;
        /* room for a subset's triangles too (2n - 5 at most: sh_warp_model_update_subset) */
        m->tri_map = malloc(sizeof(double) * 6 * (size_t)(m->ntri > 2 * n ? m->ntri : 2 * n));
        m->tri_ybounds = m->ybounds_all = malloc(sizeof(double) * 2 * (size_t)m->ntri);
        if (!m->tri_map || !m->tri_ybounds) {
            st = sh_error_set(SH_ENOMEM, "warp: out of memory");
            goto fail;
        }
        triangle_ybounds(ref, tri, m->ntri, m->tri_ybounds);
        if ((st = build_bands(m)) != SH_OK || (st = warp_model_list_spans(m)) != SH_OK) goto fail;
        m->span_start_all = m->span_start;
    } else if (sh_interp_method(interp) == SH_METHOD_AFFINE) {
        m->kind = MODEL_AFFINE;
    } else {
        m->kind = MODEL_GRID;
        if ((st = warp_grid_build(m, m->opts.grid_spacing)) != SH_OK) goto fail;
    }
    *out = m;
    return SH_OK;
fail:
    sh_warp_model_destroy(m);
    return st;
}

/* The affine map through three point pairs: solves [p1-p0 p2-p0] M = [q1-q0 q2-q0]. */
static int triangle_map(const double *p0, const double *p1, const double *p2, const double *q0,
                        const double *q1, const double *q2, double *a)
{
    double ux = p1[0] - p0[0], uy = p1[1] - p0[1], vx = p2[0] - p0[0], vy = p2[1] - p0[1];
    double det = ux * vy - vx * uy;
    if (fabs(det) < 1e-12) return 0;
    for (int c = 0; c < 2; c++) {
        double du = q1[c] - q0[c], dv = q2[c] - q0[c];
        double gx = (du * vy - dv * uy) / det; /* d(current)/dX */
        double gy = (dv * ux - du * vx) / det; /* d(current)/dY */
        a[3 * c + 1] = gx;
        a[3 * c + 2] = gy;
        a[3 * c] = q0[c] - gx * p0[0] - gy * p0[1];
    }
    return 1;
}

/* The interpolant's coefficients for values (n x 2) and the hull: through every point, or
 * through the used ones alone and their hull. */
static sh_status fit(sh_warp_model *m, const double *values, const unsigned char *use)
{
    if (!use) {
        m->hull = m->hull_all;
        return sh_interp_fit(m->interp, values, 2, m->coef);
    }
    if (!m->subset_work) {
        size_t bytes = sh_interp_subset_work_size(m->interp);
        if (!bytes)
            return sh_error_set(SH_EINVAL, "warp: %s cannot leave points out (its basis depends on which are used)",
                                sh_interp_method_name(sh_interp_method(m->interp)));
        if (!(m->subset_work = malloc(bytes)) || !(m->subset_xy = malloc(sizeof(double) * 2 * (size_t)m->n)))
            return sh_error_set(SH_ENOMEM, "warp: out of memory");
    }
    int s = 0;
    for (int i = 0; i < m->n; i++)
        if (use[i]) m->subset_xy[2 * s] = m->ref_xy[2 * i], m->subset_xy[2 * s + 1] = m->ref_xy[2 * i + 1], s++;
    sh_status st = sh_interp_fit_subset(m->interp, use, values, 2, m->coef, m->subset_work);
    if (st == SH_OK) st = sh_hull_compute(m->subset_xy, s, &m->hull);
    return st;
}

sh_status sh_warp_model_update(sh_warp_model *m, const double *cur_xy)
{
    return sh_warp_model_update_subset(m, cur_xy, NULL);
}

sh_status sh_warp_model_update_subset(sh_warp_model *m, const double *cur_xy, const unsigned char *use)
{
    return warp_model_update_with(m, cur_xy, use, NULL, NULL, 1);
}

sh_status warp_model_update_with(sh_warp_model *m, const double *cur_xy, const unsigned char *use,
                                 warp_grid_fn map, void *ctx, int slots)
{
    if (!m || !cur_xy) return sh_error_set(SH_EINVAL, "warp: no positions");
    for (int i = 0; i < 2 * m->n; i++)
        if ((!use || use[i / 2]) && !isfinite(cur_xy[i]))
            return sh_error_set(SH_EINVAL, "warp: current position of point %d is not finite", i / 2);
    sh_status st;
    switch (m->kind) {
    case MODEL_AFFINE: {
        if ((st = fit(m, cur_xy, use)) != SH_OK) return st;
        double o[2], ex[2], ey[2];
        /* Read the map off the interpolant so its internal scaling stays its own business. */
        if ((st = sh_interp_eval(m->interp, m->coef, 2, 0, 0, o)) != SH_OK ||
            (st = sh_interp_eval(m->interp, m->coef, 2, 1024, 0, ex)) != SH_OK ||
            (st = sh_interp_eval(m->interp, m->coef, 2, 0, 1024, ey)) != SH_OK)
            return st;
        for (int c = 0; c < 2; c++) {
            m->affine[3 * c] = o[c];
            m->affine[3 * c + 1] = (ex[c] - o[c]) / 1024;
            m->affine[3 * c + 2] = (ey[c] - o[c]) / 1024;
        }
        return SH_OK;
    }
    case MODEL_TRIANGLES:
        if (!use) all_triangles(m);
        else if ((st = subset_triangles(m, use)) != SH_OK) return st;
        for (int t = 0; t < m->ntri; t++) {
            const int *v = m->tri + 3 * t;
            if (!triangle_map(m->ref_xy + 2 * v[0], m->ref_xy + 2 * v[1], m->ref_xy + 2 * v[2],
                              cur_xy + 2 * v[0], cur_xy + 2 * v[1], cur_xy + 2 * v[2],
                              m->tri_map + 6 * t))
                return sh_error_set(SH_EDEGENERATE, "warp: triangle %d has no area", t);
        }
        return SH_OK;
    case MODEL_GRID:
        /* Interpolate the displacement, not the position: the same map for every method that
         * reproduces affine functions, and for the others (B-splines, RBFs without the affine
         * term) a translation stays exact and the map tends to the identity, not to zero, away
         * from the markers. */
        for (int i = 0; i < 2 * m->n; i++) m->disp[i] = !use || use[i / 2] ? cur_xy[i] - m->ref_xy[i] : 0.0;
        if ((st = fit(m, m->disp, use)) != SH_OK) return st;
        if ((st = warp_grid_map(m, map, ctx, slots, 1)) != SH_OK) return st;
        while (!m->opts.defer_refine && m->error_bound > m->opts.max_error && m->h > 1) {
            /* Halving, not a jump predicted from h^2 scaling: a coarse grid can overstate the
             * curvature of a map with finer structure (multilevel B-splines) and overshoot.
             * The new grid's coarse level is the grid that just failed: not tried again. */
            if ((st = warp_grid_build(m, m->h / 2)) != SH_OK) return st;
            m->refinements++;
            if ((st = warp_grid_map(m, map, ctx, slots, 0)) != SH_OK) return st;
        }
        return SH_OK;
    }
    return SH_EINVAL;
}

sh_status sh_warp_model_eval(const sh_warp_model *m, double x, double y, double *out)
{
    switch (m->kind) {
    case MODEL_AFFINE:
        out[0] = m->affine[0] + m->affine[1] * x + m->affine[2] * y;
        out[1] = m->affine[3] + m->affine[4] * x + m->affine[5] * y;
        return SH_OK;
    case MODEL_GRID: {
        double d[2] = {0, 0};
        sh_status st = sh_interp_eval(m->interp, m->coef, 2, x, y, d);
        out[0] = x + d[0];
        out[1] = y + d[1];
        return st;
    }
    case MODEL_TRIANGLES:
        for (int t = 0; t < m->ntri; t++) {
            const int *v = m->tri + 3 * t;
            const double *p0 = m->ref_xy + 2 * v[0], *p1 = m->ref_xy + 2 * v[1], *p2 = m->ref_xy + 2 * v[2];
            double ux = p1[0] - p0[0], uy = p1[1] - p0[1], vx = p2[0] - p0[0], vy = p2[1] - p0[1];
            double det = ux * vy - vx * uy, wx = x - p0[0], wy = y - p0[1];
            double b1 = (wx * vy - vx * wy) / det, b2 = (ux * wy - wx * uy) / det;
            /* a point on a shared edge belongs to either triangle: both give the same map there */
            if (b1 < -1e-9 || b2 < -1e-9 || b1 + b2 > 1 + 1e-9) continue;
            const double *a = m->tri_map + 6 * t;
            out[0] = a[0] + a[1] * x + a[2] * y;
            out[1] = a[3] + a[4] * x + a[5] * y;
            return SH_OK;
        }
        out[0] = out[1] = NAN;
        return sh_error_set(SH_ERANGE, "warp: (%g, %g) is outside the triangulation", x, y);
    }
    return SH_EINVAL;
}

const sh_hull *sh_warp_model_hull(const sh_warp_model *m)
{
    return &m->hull;
}

int sh_warp_model_grid_spacing(const sh_warp_model *m)
{
    return m->kind == MODEL_GRID ? m->h : 0;
}

double sh_warp_model_error_bound(const sh_warp_model *m)
{
    return m->kind == MODEL_GRID ? m->error_bound : 0;
}

int sh_warp_model_refinements(const sh_warp_model *m)
{
    return m->refinements;
}

int sh_warp_model_finer_spacing(const sh_warp_model *m)
{
    return m->kind == MODEL_GRID && m->opts.defer_refine && m->error_bound > m->opts.max_error && m->h > 1 ? m->h / 2
                                                                                                          : 0;
}

sh_status sh_warp_model_map(const sh_warp_model *m, float *map)
{
    if (!m || !map) return sh_error_set(SH_EINVAL, "warp: no map buffer");
    plane_geometry g = {.scale = 1, .ox = 0, .oy = 0, .width = m->width, .height = m->height};
    int32_t *fx = malloc(sizeof(int32_t) * 2 * (size_t)m->width), *fy = fx + m->width;
    if (!fx) return sh_error_set(SH_ENOMEM, "warp: out of memory");
    for (size_t i = 0; i < (size_t)m->width * m->height * 2; i++) map[i] = NAN;
    for (int y = 0; y < m->height; y++) {
        int first, last;
        if (!warp_model_row_extent(m, &g, y, &first, &last)) continue;
        warp_model_row_fill(m, &g, y, first, last, fx, fy);
        float *row = map + (size_t)y * m->width * 2;
        for (int x = first; x <= last; x++) {
            row[2 * x] = (float)fx[x - first] / (1 << WARP_FRAC_BITS);
            row[2 * x + 1] = (float)fy[x - first] / (1 << WARP_FRAC_BITS);
        }
    }
    free(fx);
    return SH_OK;
}
