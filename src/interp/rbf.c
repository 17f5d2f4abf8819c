/* Radial basis functions: locally supported, thin plate spline, Gaussian, with or without the
 * affine term. create factors the (n+3) system once (Eigen, partial pivoting); fit is a forward
 * and back substitution over the stored factor, with no allocation and no shared state.
 *
 * The affine term's basis is g [1, u, v] with u, v centred and scaled coordinates and g the
 * largest kernel entry: the same space of functions as [1, x, y] and the same side conditions,
 * but a matrix whose blocks are of comparable size (TPS kernel entries reach 1e7 in pixels), so
 * its condition estimate measures the geometry, not the units. */
#include "interp_internal.h"
#include "stillheart/linalg.h"

#include <math.h>
#include <stdlib.h>

typedef struct {
    sh_method kind;
    int affine;
    int m; /* n + 3 * affine */
    double sigma, inv_sigma2;
    double cx, cy, inv_scale;
    double poly_gain; /* the affine basis is poly_gain * [1, u, v] */
    double *lu;
    int *src;
    double *kern;        /* the kernel between points i >= j, at i (i + 1) / 2 + j: for subset fits */
    sh_bucket_grid grid; /* rbf-local: points bucketed by sigma-wide cells */
} rbf_impl;

static inline double kernel(const rbf_impl *r, double r2)
{
    switch (r->kind) {
    case SH_METHOD_TPS: return r2 > 0 ? 0.5 * r2 * log(r2) : 0.0; /* r^2 log r */
    case SH_METHOD_GAUSSIAN: return exp(-r2 * r->inv_sigma2);
    default: {
        if (r2 >= r->sigma * r->sigma) return 0.0;
        double t = sqrt(r2) / r->sigma;
        return 1.0 - t * t * (3.0 - 2.0 * t);
    }
    }
}

static void rbf_destroy(void *p)
{
    rbf_impl *r = p;
    if (!r) return;
    free(r->lu);
    free(r->src);
    free(r->kern);
    sh_bucket_grid_free(&r->grid);
    free(r);
}

static sh_status rbf_fit(const sh_interp *it, const double *values, int dim, double *coef)
{
    const rbf_impl *r = it->impl;
    sh_linalg_lu_solve(r->m, r->lu, r->src, values, it->n, dim, coef);
    return SH_OK;
}

static int poly_terms(const sh_interp *it, const rbf_impl *r, double x, double y, int *index,
                      double *weight)
{
    if (!r->affine) return 0;
    index[0] = it->n, index[1] = it->n + 1, index[2] = it->n + 2;
    weight[0] = r->poly_gain;
    weight[1] = r->poly_gain * (x - r->cx) * r->inv_scale;
    weight[2] = r->poly_gain * (y - r->cy) * r->inv_scale;
    return 3;
}

static int rbf_basis_dense(const sh_interp *it, double x, double y, int *index, double *weight)
{
    const rbf_impl *r = it->impl;
    const double *p = it->ref;
    for (int i = 0; i < it->n; i++) {
        double dx = x - p[2 * i], dy = y - p[2 * i + 1];
        index[i] = i;
        weight[i] = kernel(r, dx * dx + dy * dy);
    }
    return it->n + poly_terms(it, r, x, y, index + it->n, weight + it->n);
}

/* Only the points closer than sigma: they lie in the query's cell or its eight neighbours. */
static int rbf_basis_local(const sh_interp *it, double x, double y, int *index, double *weight)
{
    const rbf_impl *r = it->impl;
    const sh_bucket_grid *g = &r->grid;
    const double *p = it->ref;
    int ci = sh_bucket_coord(x, g->x0, g->inv_cell, g->nx);
    int cj = sh_bucket_coord(y, g->y0, g->inv_cell, g->ny);
    int k = 0;
    for (int j = cj - 1; j <= cj + 1; j++) {
        if (j < 0 || j >= g->ny) continue;
        for (int i = ci - 1; i <= ci + 1; i++) {
            if (i < 0 || i >= g->nx) continue;
            int c = j * g->nx + i;
            for (int s = g->start[c]; s < g->start[c + 1]; s++) {
                int q = g->items[s];
                double dx = x - p[2 * q], dy = y - p[2 * q + 1], r2 = dx * dx + dy * dy;
                if (r2 >= r->sigma * r->sigma) continue;
                index[k] = q;
                weight[k] = kernel(r, r2);
                k++;
            }
        }
    }
    return k + poly_terms(it, r, x, y, index + k, weight + k);
}

/* Direct sum, so eval needs no basis buffer of n terms. */
static sh_status rbf_eval(const sh_interp *it, const double *coef, int dim, double x, double y,
                          double *out)
{
    const rbf_impl *r = it->impl;
    const double *p = it->ref;
    for (int i = 0; i < it->n; i++) {
        double dx = x - p[2 * i], dy = y - p[2 * i + 1];
        double w = kernel(r, dx * dx + dy * dy);
        if (w == 0.0) continue;
        for (int d = 0; d < dim; d++) out[d] += w * coef[i * dim + d];
    }
    if (r->affine) {
        double u = (x - r->cx) * r->inv_scale, v = (y - r->cy) * r->inv_scale;
        const double *c = coef + (size_t)it->n * dim;
        for (int d = 0; d < dim; d++)
            out[d] += r->poly_gain * (c[d] + u * c[dim + d] + v * c[2 * dim + d]);
    }
    return SH_OK;
}

/* The work of a subset fit: the system (m x m at most), its right-hand side and solution (3
 * columns at most), the used points gathered, the pivot rows and the map from used to all. */
static size_t rbf_subset_work(const sh_interp *it)
{
    const rbf_impl *r = it->impl;
    size_t m = (size_t)r->m, n = (size_t)it->n;
    return sizeof(double) * (m * m + 6 * m + 2 * n) + sizeof(int) * (m + n);
}

/* The system sh_interp_rbf_init builds, over the s used points only, with the same affine basis
 * (this interpolant's centre, scale and gain): the interpolant through them alone. Its kernel
 * entries come from the table init kept, the same values: the daemon refits through the frame's
 * accepted landmarks every frame, and TPS's logarithms took a sixth of that fit's time (116 of
 * 216 points: 0.155 -> 0.128 ms). */
static sh_status rbf_fit_subset(const sh_interp *it, const unsigned char *use, int s, const double *values, int dim,
                                double *coef, void *work)
{
    const rbf_impl *r = it->impl;
    const char *name = sh_interp_method_name(r->kind);
    int n = it->n, ms = s + 3 * r->affine;
    double *a = work, *rhs = a + (size_t)ms * ms, *x = rhs + 3 * (size_t)ms, *q = x + 3 * (size_t)ms;
    int *src = (int *)(q + 2 * (size_t)n), *at = src + ms;
    for (int i = 0, k = 0; i < n; i++)
        if (use[i]) {
            at[k] = i;
            q[2 * k] = it->ref[2 * i], q[2 * k + 1] = it->ref[2 * i + 1];
            for (int d = 0; d < dim; d++) rhs[k * dim + d] = values[i * dim + d];
            k++;
        }
    if (r->affine && (s < 3 || sh_interp_collinear(q, s)))
        return sh_error_set(SH_EDEGENERATE, "interp %s: the %d points used are collinear or too few for the affine term",
                            name, s);
    for (int i = 0; i < s; i++) {
        const double *row = r->kern + (size_t)at[i] * (at[i] + 1) / 2;
        for (int j = 0; j <= i; j++) a[(size_t)i * ms + j] = a[(size_t)j * ms + i] = row[at[j]];
        a[(size_t)i * ms + i] += it->params.smoothing + (it->point_smoothing ? it->point_smoothing[at[i]] : 0.0);
        for (int c = 0; c < 3 * r->affine; c++) {
            double g = r->poly_gain;
            double v = c == 0 ? g : c == 1 ? g * (q[2 * i] - r->cx) * r->inv_scale : g * (q[2 * i + 1] - r->cy) * r->inv_scale;
            a[(size_t)i * ms + s + c] = a[(size_t)(s + c) * ms + i] = v;
        }
    }
    for (int c = 0; c < 3 * r->affine; c++)
        for (int e = 0; e < 3; e++) a[(size_t)(s + c) * ms + s + e] = 0.0;
    sh_status st = sh_linalg_lu_factor_inplace(ms, a, src);
    if (st != SH_OK)
        return sh_error_set(SH_EDEGENERATE, "interp %s: the system of the %d points used: %s", name, s,
                            sh_error_message());
    sh_linalg_lu_solve(ms, a, src, rhs, s, dim, x);
    for (int i = 0; i < (n + 3 * r->affine) * dim; i++) coef[i] = 0.0;
    for (int k = 0; k < s; k++)
        for (int d = 0; d < dim; d++) coef[at[k] * dim + d] = x[k * dim + d];
    for (int c = 0; c < 3 * r->affine; c++)
        for (int d = 0; d < dim; d++) coef[(n + c) * dim + d] = x[(s + c) * dim + d];
    return SH_OK;
}

static const sh_interp_ops dense_ops = {rbf_fit, rbf_basis_dense, rbf_eval, rbf_destroy, rbf_subset_work, rbf_fit_subset};
static const sh_interp_ops local_ops = {rbf_fit, rbf_basis_local, rbf_eval, rbf_destroy, rbf_subset_work, rbf_fit_subset};

static sh_status build_local_grid(const sh_interp *it, rbf_impl *r, int *max_near)
{
    const double *p = it->ref;
    int n = it->n;
    double x0 = p[0], y0 = p[1], x1 = p[0], y1 = p[1];
    for (int i = 1; i < n; i++) {
        x0 = fmin(x0, p[2 * i]), x1 = fmax(x1, p[2 * i]);
        y0 = fmin(y0, p[2 * i + 1]), y1 = fmax(y1, p[2 * i + 1]);
    }
    /* Cells no smaller than sigma (so 3x3 cells cover the support), and not absurdly many. */
    double cell = r->sigma;
    while ((x1 - x0) / cell > 4096 || (y1 - y0) / cell > 4096) cell *= 2;
    int nx = (int)((x1 - x0) / cell) + 1, ny = (int)((y1 - y0) / cell) + 1;
    double *boxes = malloc(sizeof(double) * 4 * (size_t)n);
    if (!boxes) return sh_error_set(SH_ENOMEM, "interp rbf-local: out of memory");
    for (int i = 0; i < n; i++) {
        boxes[4 * i] = boxes[4 * i + 2] = p[2 * i];
        boxes[4 * i + 1] = boxes[4 * i + 3] = p[2 * i + 1];
    }
    sh_status st = sh_bucket_grid_build(&r->grid, boxes, n, x0, y0, cell, nx, ny);
    free(boxes);
    if (st != SH_OK) return st;
    /* Bound on the neighbours of any query: the most points in any 3x3 block of cells. */
    int most = 0;
    for (int j = 0; j < ny; j++)
        for (int i = 0; i < nx; i++) {
            int c = 0;
            for (int b = j - 1; b <= j + 1; b++)
                for (int a = i - 1; a <= i + 1; a++)
                    if (a >= 0 && a < nx && b >= 0 && b < ny)
                        c += r->grid.start[b * nx + a + 1] - r->grid.start[b * nx + a];
            if (c > most) most = c;
        }
    *max_near = most;
    return SH_OK;
}

sh_status sh_interp_rbf_init(sh_interp *it)
{
    const sh_interp_params *pa = &it->params;
    const char *name = sh_interp_method_name(pa->method);
    int n = it->n;
    const double *p = it->ref;
    sh_status st = sh_interp_check_distinct(p, n, name);
    if (st != SH_OK) return st;
    if (pa->affine_term && sh_interp_collinear(p, n))
        return sh_error_set(SH_EDEGENERATE,
                            "interp %s: the reference points are collinear, so the affine term is "
                            "undetermined (use the -pure variant)", name);
    rbf_impl *r = calloc(1, sizeof *r);
    if (!r) return sh_error_set(SH_ENOMEM, "interp %s: out of memory", name);
    r->kind = pa->method;
    r->affine = pa->affine_term;
    r->m = n + 3 * r->affine;
    r->sigma = pa->sigma;
    r->inv_sigma2 = pa->sigma > 0 ? 1.0 / (pa->sigma * pa->sigma) : 0.0;
    size_t m = (size_t)r->m;
    r->lu = malloc(sizeof(double) * m * m);
    r->src = malloc(sizeof(int) * m);
    r->kern = malloc(sizeof(double) * (size_t)n * (n + 1) / 2);
    if (!r->lu || !r->src || !r->kern) {
        rbf_destroy(r);
        return sh_error_set(SH_ENOMEM, "interp %s: out of memory for %d points", name, n);
    }
    double sx = 0, sy = 0;
    for (int i = 0; i < n; i++) sx += p[2 * i], sy += p[2 * i + 1];
    r->cx = sx / n, r->cy = sy / n;
    double spread = 0;
    for (int i = 0; i < n; i++)
        spread = fmax(spread, fmax(fabs(p[2 * i] - r->cx), fabs(p[2 * i + 1] - r->cy)));
    r->inv_scale = spread > 0 ? 1.0 / spread : 1.0;

    double *a = r->lu, kmax = 0;
    for (size_t i = 0; i < m * m; i++) a[i] = 0.0;
    for (int i = 0; i < n; i++) {
        for (int j = 0; j <= i; j++) {
            double dx = p[2 * i] - p[2 * j], dy = p[2 * i + 1] - p[2 * j + 1];
            double k = kernel(r, dx * dx + dy * dy);
            a[i * m + j] = a[j * m + i] = r->kern[(size_t)i * (i + 1) / 2 + j] = k;
            kmax = fmax(kmax, fabs(k));
        }
        a[i * m + i] += pa->smoothing + (it->point_smoothing ? it->point_smoothing[i] : 0.0);
    }
    r->poly_gain = kmax > 0 ? kmax : 1.0;
    for (int i = 0; i < n && r->affine; i++) {
        double g = r->poly_gain;
        double row[3] = {g, g * (p[2 * i] - r->cx) * r->inv_scale,
                         g * (p[2 * i + 1] - r->cy) * r->inv_scale};
        for (int c = 0; c < 3; c++) a[i * m + n + c] = a[(size_t)(n + c) * m + i] = row[c];
    }
    double rcond;
    st = sh_linalg_lu_factor(r->m, r->lu, r->src, &rcond);
    /* Below this the solution carries no correct digits: the kernel cannot separate the points
     * (e.g. Gaussian with sigma much larger than their spacing). */
    if (st == SH_OK && !(rcond > 1e-15))
        st = sh_error_set(SH_EDEGENERATE,
                          "interp %s: the interpolation system is singular for these %d points "
                          "(rcond %.3g); try smoothing or another sigma", name, n, rcond);
    int near = n;
    if (st == SH_OK && r->kind == SH_METHOD_RBF_LOCAL) st = build_local_grid(it, r, &near);
    if (st != SH_OK) {
        rbf_destroy(r);
        return st;
    }
    it->impl = r;
    it->ops = r->kind == SH_METHOD_RBF_LOCAL ? &local_ops : &dense_ops;
    it->num_coefs = r->m;
    it->max_terms = near + 3 * r->affine;
    return SH_OK;
}
