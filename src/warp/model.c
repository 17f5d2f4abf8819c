/* The map from reference to current positions: built per reference, updated per frame. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "warp_internal.h"

/* The second difference averages f'' over two cells; the largest |f''| inside a cell can exceed
 * the average at its corners. Measured on TPS, Gaussian, local RBF and B-spline maps of
 * non-affine motions (tests/unit/test_warp.c), the true error stays below 0.6 x the raw
 * estimate; 1.5 leaves a margin over that. */
#define ERROR_SAFETY 1.5
/* Long spans are cut so that 16.16 fixed-point stepping (error 2^-17 px per step) stays small. */
#define MAX_SPAN 64

void sh_warp_options_default(sh_warp_options *opts)
{
    opts->max_error = 0.05;
    opts->grid_spacing = 8;
}

static void free_grid(sh_warp_model *m)
{
    free(m->row_start);
    free(m->index);
    free(m->weight);
    free(m->map);
    m->row_start = m->index = NULL;
    m->weight = m->map = NULL;
}

void sh_warp_model_destroy(sh_warp_model *m)
{
    if (!m) return;
    free_grid(m);
    free(m->coef);
    free(m->tri_map);
    free(m->tri_ybounds);
    free((void *)m->ref_xy);
    free(m->disp);
    free(m);
}

static sh_status build_grid(sh_warp_model *m, int h)
{
    free_grid(m);
    m->h = h;
    m->gx0 = (int)floor(m->hull.xmin / h) * h;
    m->gy0 = (int)floor(m->hull.ymin / h) * h;
    m->nx = ((int)ceil(m->hull.xmax / h) * h - m->gx0) / h + 1;
    m->ny = ((int)ceil(m->hull.ymax / h) * h - m->gy0) / h + 1;
    size_t nodes = (size_t)m->nx * (size_t)m->ny;
    int max_terms = sh_interp_max_terms(m->interp);
    size_t cap = nodes * (size_t)max_terms;
    m->row_start = malloc(sizeof(int) * (nodes + 1));
    m->index = malloc(sizeof(int) * cap);
    m->weight = malloc(sizeof(double) * cap);
    m->map = malloc(sizeof(double) * 2 * nodes);
    if (!m->row_start || !m->index || !m->weight || !m->map)
        return sh_error_set(SH_ENOMEM, "warp: grid of %zu nodes does not fit in memory", nodes);
    size_t used = 0;
    for (int j = 0; j < m->ny; j++) {
        for (int i = 0; i < m->nx; i++) {
            size_t node = (size_t)j * m->nx + i;
            m->row_start[node] = (int)used;
            int k = sh_interp_basis(m->interp, m->gx0 + (double)i * h, m->gy0 + (double)j * h,
                                    m->index + used, m->weight + used);
            if (k < 0) return (sh_status)k;
            used += (size_t)k;
        }
    }
    m->row_start[nodes] = (int)used;
    return SH_OK;
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
        (m->opts.grid_spacing & (m->opts.grid_spacing - 1))) {
        st = sh_error_set(SH_EINVAL, "warp: max_error must be > 0 and grid spacing a power of two");
        goto fail;
    }
    if ((st = sh_hull_compute(ref_xy, n, &m->hull)) != SH_OK) goto fail;

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
        m->tri_map = malloc(sizeof(double) * 6 * (size_t)m->ntri);
        m->tri_ybounds = malloc(sizeof(double) * 2 * (size_t)m->ntri);
        if (!m->tri_map || !m->tri_ybounds) {
            st = sh_error_set(SH_ENOMEM, "warp: out of memory");
            goto fail;
        }
        for (int t = 0; t < m->ntri; t++) {
            double y0 = ref[2 * tri[3 * t] + 1], y1 = ref[2 * tri[3 * t + 1] + 1],
                   y2 = ref[2 * tri[3 * t + 2] + 1];
            m->tri_ybounds[2 * t] = fmin(y0, fmin(y1, y2));
            m->tri_ybounds[2 * t + 1] = fmax(y0, fmax(y1, y2));
        }
    } else if (sh_interp_method(interp) == SH_METHOD_AFFINE) {
        m->kind = MODEL_AFFINE;
    } else {
        m->kind = MODEL_GRID;
        if ((st = build_grid(m, m->opts.grid_spacing)) != SH_OK) goto fail;
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

static void grid_map(sh_warp_model *m)
{
    size_t nodes = (size_t)m->nx * (size_t)m->ny;
    for (size_t node = 0; node < nodes; node++) {
        double x = 0, y = 0;
        for (int k = m->row_start[node]; k < m->row_start[node + 1]; k++) {
            const double *c = m->coef + 2 * (size_t)m->index[k];
            x += m->weight[k] * c[0];
            y += m->weight[k] * c[1];
        }
        int i = (int)(node % (size_t)m->nx), j = (int)(node / (size_t)m->nx);
        m->map[2 * node] = m->gx0 + (double)i * m->h + x;
        m->map[2 * node + 1] = m->gy0 + (double)j * m->h + y;
    }
}

/* |second difference| of component c at node (i, j) along the axis (di, dj); nodes on the
 * grid's edge take their inner neighbour's value. */
static double second_difference(const sh_warp_model *m, int i, int j, int di, int dj, int c)
{
    int len = di ? m->nx : m->ny, pos = di ? i : j;
    if (len < 3) return INFINITY;
    if (pos == 0) { i += di; j += dj; }
    if (pos == len - 1) { i -= di; j -= dj; }
    const double *mid = m->map + 2 * ((size_t)j * m->nx + i) + c;
    ptrdiff_t step = 2 * ((ptrdiff_t)dj * m->nx + di);
    return fabs(mid[-step] - 2 * mid[0] + mid[step]);
}

/* max over cells of the bilinear interpolation error bound h^2/8 (|f_xx| + |f_yy|), with the
 * second derivatives taken from second differences at the cell's corners. */
static double grid_error_bound(const sh_warp_model *m)
{
    if (m->h == 1) return 0; /* every pixel is a node */
    double worst = 0;
    for (int j = 0; j + 1 < m->ny; j++) {
        for (int i = 0; i + 1 < m->nx; i++) {
            double e2 = 0;
            for (int c = 0; c < 2; c++) {
                double exx = 0, eyy = 0;
                for (int corner = 0; corner < 4; corner++) {
                    int ci = i + (corner & 1), cj = j + (corner >> 1);
                    exx = fmax(exx, second_difference(m, ci, cj, 1, 0, c));
                    eyy = fmax(eyy, second_difference(m, ci, cj, 0, 1, c));
                }
                double e = ERROR_SAFETY * (exx + eyy) / 8;
                e2 += e * e;
            }
            worst = fmax(worst, sqrt(e2));
        }
    }
    return worst;
}

sh_status sh_warp_model_update(sh_warp_model *m, const double *cur_xy)
{
    if (!m || !cur_xy) return sh_error_set(SH_EINVAL, "warp: no positions");
    for (int i = 0; i < 2 * m->n; i++)
        if (!isfinite(cur_xy[i]))
            return sh_error_set(SH_EINVAL, "warp: current position of point %d is not finite", i / 2);
    sh_status st;
    switch (m->kind) {
    case MODEL_AFFINE: {
        if ((st = sh_interp_fit(m->interp, cur_xy, 2, m->coef)) != SH_OK) return st;
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
        for (int i = 0; i < 2 * m->n; i++) m->disp[i] = cur_xy[i] - m->ref_xy[i];
        if ((st = sh_interp_fit(m->interp, m->disp, 2, m->coef)) != SH_OK) return st;
        grid_map(m);
        m->error_bound = grid_error_bound(m);
        while (m->error_bound > m->opts.max_error && m->h > 1) {
            if ((st = build_grid(m, m->h / 2)) != SH_OK) return st;
            m->refinements++;
            grid_map(m);
            m->error_bound = grid_error_bound(m);
        }
        return SH_OK;
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

/* Emits [x0, x1] of an affine map a (full-resolution coordinates) in plane coordinates,
 * cut into pieces of at most MAX_SPAN pixels, each starting from an exact evaluation. */
static void emit_affine(const plane_geometry *g, double Y, int x0, int x1, const double *a,
                        span_sink sink, void *ctx)
{
    for (int s = x0; s <= x1; s += MAX_SPAN) {
        int e = s + MAX_SPAN - 1 < x1 ? s + MAX_SPAN - 1 : x1;
        double X = g->scale * s + g->ox;
        warp_span span = {
            .x0 = s, .x1 = e,
            .sx = (a[0] + a[1] * X + a[2] * Y - g->ox) / g->scale,
            .sy = (a[3] + a[4] * X + a[5] * Y - g->oy) / g->scale,
            .dsx = a[1], .dsy = a[4], /* d/dx of (a X - o)/s with X = s x + o */
        };
        sink(ctx, &span);
    }
}

static void triangle_row(const sh_warp_model *m, int t, double Y, double *lo, double *hi)
{
    *lo = INFINITY;
    *hi = -INFINITY;
    const int *v = m->tri + 3 * t;
    for (int e = 0; e < 3; e++) {
        const double *p = m->ref_xy + 2 * v[e], *q = m->ref_xy + 2 * v[(e + 1) % 3];
        double ya = fmin(p[1], q[1]), yb = fmax(p[1], q[1]);
        if (Y < ya - 1e-9 || Y > yb + 1e-9) continue;
        double x;
        if (yb - ya < 1e-12) {
            *lo = fmin(*lo, fmin(p[0], q[0]));
            *hi = fmax(*hi, fmax(p[0], q[0]));
            continue;
        }
        double t01 = (Y - p[1]) / (q[1] - p[1]);
        t01 = t01 < 0 ? 0 : (t01 > 1 ? 1 : t01);
        x = p[0] + t01 * (q[0] - p[0]);
        *lo = fmin(*lo, x);
        *hi = fmax(*hi, x);
    }
}

void warp_model_row_spans(const sh_warp_model *m, const plane_geometry *g, int py, span_sink sink,
                          void *ctx)
{
    int first, last;
    if (!sh_hull_plane_row(&m->hull, py, g->width, g->scale, g->ox, g->oy, &first, &last)) return;
    double Y = g->scale * py + g->oy;
    switch (m->kind) {
    case MODEL_AFFINE:
        emit_affine(g, Y, first, last, m->affine, sink, ctx);
        return;
    case MODEL_TRIANGLES:
        for (int t = 0; t < m->ntri; t++) {
            if (Y < m->tri_ybounds[2 * t] - 1e-7 || Y > m->tri_ybounds[2 * t + 1] + 1e-7) continue;
            double lo, hi;
            triangle_row(m, t, Y, &lo, &hi);
            if (!(lo <= hi)) continue;
            /* Closed intervals with a hair of slack: pixels on a shared edge may be written twice
             * (with the same value, the map being continuous) but never left out. */
            int s = (int)ceil((lo - g->ox) / g->scale - 1e-7);
            int e = (int)floor((hi - g->ox) / g->scale + 1e-7);
            if (s < first) s = first;
            if (e > last) e = last;
            if (s <= e) emit_affine(g, Y, s, e, m->tri_map + 6 * t, sink, ctx);
        }
        return;
    case MODEL_GRID: {
        const int h = m->h;
        double fy = (Y - m->gy0) / h;
        int j = (int)floor(fy);
        if (j > m->ny - 2) j = m->ny - 2;
        if (j < 0) j = 0;
        double ty = fy - j;
        int x = first;
        while (x <= last) {
            double X = g->scale * x + g->ox;
            int i = (int)floor((X - m->gx0) / h);
            if (i > m->nx - 2) i = m->nx - 2;
            if (i < 0) i = 0;
            double cell_end = m->gx0 + (double)(i + 1) * h; /* exclusive, full-res coordinates */
            int e = (int)ceil((cell_end - g->ox) / g->scale) - 1;
            if (i == m->nx - 2 || e > last) e = last;
            if (e < x) e = x;
            const double *n00 = m->map + 2 * ((size_t)j * m->nx + i), *n01 = n00 + 2,
                         *n10 = n00 + 2 * m->nx, *n11 = n10 + 2;
            double Xc = m->gx0 + (double)i * h;
            warp_span span = {.x0 = x, .x1 = e};
            double *start[2] = {&span.sx, &span.sy}, *step[2] = {&span.dsx, &span.dsy};
            const double off[2] = {g->ox, g->oy};
            for (int c = 0; c < 2; c++) {
                double left = n00[c] + ty * (n10[c] - n00[c]);
                double right = n01[c] + ty * (n11[c] - n01[c]);
                double slope = (right - left) / h;
                *start[c] = (left + slope * (X - Xc) - off[c]) / g->scale;
                *step[c] = slope; /* per plane pixel: slope * scale / scale */
            }
            sink(ctx, &span);
            x = e + 1;
        }
        return;
    }
    }
}

typedef struct {
    float *row;
} map_ctx;

static void map_sink(void *ctx, const warp_span *s)
{
    float *row = ((map_ctx *)ctx)->row;
    for (int x = s->x0; x <= s->x1; x++) {
        row[2 * x] = (float)(s->sx + (x - s->x0) * s->dsx);
        row[2 * x + 1] = (float)(s->sy + (x - s->x0) * s->dsy);
    }
}

sh_status sh_warp_model_map(const sh_warp_model *m, float *map)
{
    if (!m || !map) return sh_error_set(SH_EINVAL, "warp: no map buffer");
    plane_geometry g = {.scale = 1, .ox = 0, .oy = 0, .width = m->width, .height = m->height};
    for (size_t i = 0; i < (size_t)m->width * m->height * 2; i++) map[i] = NAN;
    for (int y = 0; y < m->height; y++) {
        map_ctx ctx = {map + (size_t)y * m->width * 2};
        warp_model_row_spans(m, &g, y, map_sink, &ctx);
    }
    return SH_OK;
}
