/* Dispatch, parameters and the checks every method shares. */
#include "interp_internal.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static const char *const method_names[SH_METHOD_COUNT] = {
    "affine", "pwlinear", "bspline", "rbf-local", "tps", "gaussian",
};

#define VALID_NAMES \
    "affine, pwlinear, bspline, rbf-local, tps, gaussian, rbf-local-pure, tps-pure, gaussian-pure"

static int is_rbf(sh_method m)
{
    return m == SH_METHOD_RBF_LOCAL || m == SH_METHOD_TPS || m == SH_METHOD_GAUSSIAN;
}

static int uses_sigma(sh_method m)
{
    return m == SH_METHOD_RBF_LOCAL || m == SH_METHOD_GAUSSIAN;
}

void sh_interp_params_default(sh_interp_params *params, sh_method method)
{
    if (!params) return;
    memset(params, 0, sizeof *params);
    params->method = method;
    params->affine_term = is_rbf(method);
    params->sigma = method == SH_METHOD_RBF_LOCAL ? 95.0 : method == SH_METHOD_GAUSSIAN ? 100.0 : 0.0;
    params->levels = 0;
    params->smoothing = 0.0;
}

sh_status sh_interp_params_parse(const char *name, sh_interp_params *params)
{
    if (!name || !params) return sh_error_set(SH_EINVAL, "interp: no method name");
    for (int m = 0; m < SH_METHOD_COUNT; m++) {
        size_t len = strlen(method_names[m]);
        if (strncmp(name, method_names[m], len) != 0) continue;
        if (name[len] == '\0') {
            sh_interp_params_default(params, (sh_method)m);
            return SH_OK;
        }
        if (is_rbf((sh_method)m) && strcmp(name + len, "-pure") == 0) {
            sh_interp_params_default(params, (sh_method)m);
            params->affine_term = 0;
            return SH_OK;
        }
    }
    return sh_error_set(SH_EINVAL, "interp: unknown method '%s' (valid: " VALID_NAMES ")", name);
}

const char *sh_interp_method_name(sh_method method)
{
    if ((int)method < 0 || method >= SH_METHOD_COUNT) return "unknown";
    return method_names[method];
}

void sh_interp_params_name(const sh_interp_params *p, char *out, size_t cap)
{
    if (!cap) return;
    snprintf(out, cap, "%s%s", sh_interp_method_name(p->method),
             is_rbf(p->method) && !p->affine_term ? "-pure" : "");
}

/* "Option does nothing" is refused: a value the method would ignore is a mistake upstream. */
sh_status sh_interp_params_check(const sh_interp_params *p)
{
    if ((int)p->method < 0 || p->method >= SH_METHOD_COUNT)
        return sh_error_set(SH_EINVAL, "interp: unknown method %d (valid: " VALID_NAMES ")",
                            (int)p->method);
    const char *name = method_names[p->method];
    if (!isfinite(p->smoothing) || p->smoothing < 0)
        return sh_error_set(SH_EINVAL, "interp %s: smoothing must be finite and >= 0", name);
    if (p->smoothing != 0 && !is_rbf(p->method))
        return sh_error_set(SH_EINVAL, "interp %s: smoothing applies to the RBF methods only",
                            name);
    if (p->levels < 0)
        return sh_error_set(SH_EINVAL, "interp %s: levels must be >= 0 (0 = automatic)", name);
    if (p->levels != 0 && p->method != SH_METHOD_BSPLINE)
        return sh_error_set(SH_EINVAL, "interp %s: levels apply to bspline only", name);
    if (p->levels > sh_interp_bspline_max_levels()) {
        /* the coarsest lattice is at least one cell each way, so the finest one of L levels has
         * at least (2^(L-1) + 3)^2 control points whatever the points */
        double side = ldexp(1, p->levels - 1) + 3;
        return sh_error_set(SH_EINVAL, "interp %s: %d levels make a lattice of at least %.0f control points, "
                            "more than the %d a fit may use (at most %d levels)", name, p->levels, side * side,
                            SH_INTERP_BSPLINE_MAX_CONTROL, sh_interp_bspline_max_levels());
    }
    if (uses_sigma(p->method)) {
        if (!isfinite(p->sigma) || !(p->sigma > 0))
            return sh_error_set(SH_EINVAL, "interp %s: sigma must be finite and > 0 (got %g)",
                                name, p->sigma);
    } else if (p->sigma != 0) {
        return sh_error_set(SH_EINVAL, "interp %s: sigma applies to rbf-local and gaussian only",
                            name);
    }
    if (is_rbf(p->method) && p->affine_term != 0 && p->affine_term != 1)
        return sh_error_set(SH_EINVAL, "interp %s: affine_term must be 0 or 1", name);
    return SH_OK;
}

static int min_points(const sh_interp_params *p)
{
    switch (p->method) {
    case SH_METHOD_AFFINE:
    case SH_METHOD_PWLINEAR: return 3;
    case SH_METHOD_BSPLINE: return 1;
    default: return p->affine_term ? 3 : 1;
    }
}

sh_status sh_interp_create(const sh_interp_params *params, const double *ref_xy, int n,
                           sh_interp **out)
{
    return sh_interp_create_smoothed(params, ref_xy, n, NULL, out);
}

int sh_interp_method_smooths(sh_method m)
{
    return m == SH_METHOD_TPS || m == SH_METHOD_GAUSSIAN || m == SH_METHOD_RBF_LOCAL;
}

sh_status sh_interp_create_smoothed(const sh_interp_params *params, const double *ref_xy, int n,
                                    const double *point_smoothing, sh_interp **out)
{
    if (!out) return sh_error_set(SH_EINVAL, "interp: no output pointer");
    *out = NULL;
    if (!params || (n > 0 && !ref_xy) || n < 0)
        return sh_error_set(SH_EINVAL, "interp: invalid arguments");
    sh_status st = sh_interp_params_check(params);
    if (st != SH_OK) return st;
    const char *name = method_names[params->method];
    for (int i = 0; i < n; i++)
        if (!isfinite(ref_xy[2 * i]) || !isfinite(ref_xy[2 * i + 1]))
            return sh_error_set(SH_EINVAL, "interp %s: reference point %d is not finite", name, i);
    int smoothed = 0;
    for (int i = 0; point_smoothing && i < n; i++) {
        if (!(point_smoothing[i] >= 0 && point_smoothing[i] <= 1e12))
            return sh_error_set(SH_EINVAL, "interp %s: point %d's smoothing %g is not in [0, 1e12]", name, i,
                                point_smoothing[i]);
        smoothed |= point_smoothing[i] > 0;
    }
    if (smoothed && !sh_interp_method_smooths(params->method))
        return sh_error_set(SH_EINVAL, "interp %s: has no smoothing (only the RBFs approximate)", name);
    if (n < min_points(params))
        return sh_error_set(SH_EDEGENERATE, "interp %s: %d reference points, needs at least %d",
                            name, n, min_points(params));
    sh_interp *it = calloc(1, sizeof *it);
    if (!it) return sh_error_set(SH_ENOMEM, "interp: out of memory");
    it->params = *params;
    it->n = n;
    it->ref = malloc(sizeof(double) * 2 * (size_t)n);
    if (smoothed) it->point_smoothing = malloc(sizeof(double) * (size_t)n);
    if (!it->ref || (smoothed && !it->point_smoothing)) {
        sh_interp_destroy(it);
        return sh_error_set(SH_ENOMEM, "interp: out of memory");
    }
    memcpy(it->ref, ref_xy, sizeof(double) * 2 * (size_t)n);
    if (smoothed) memcpy(it->point_smoothing, point_smoothing, sizeof(double) * (size_t)n);
    switch (params->method) {
    case SH_METHOD_AFFINE: st = sh_interp_affine_init(it); break;
    case SH_METHOD_PWLINEAR: st = sh_interp_pwlinear_init(it); break;
    case SH_METHOD_BSPLINE: st = sh_interp_bspline_init(it); break;
    default: st = sh_interp_rbf_init(it); break;
    }
    if (st != SH_OK) {
        sh_interp_destroy(it);
        return st;
    }
    *out = it;
    return SH_OK;
}

void sh_interp_destroy(sh_interp *it)
{
    if (!it) return;
    if (it->ops && it->ops->destroy) it->ops->destroy(it->impl);
    free(it->ref);
    free(it->point_smoothing);
    free(it);
}

sh_method sh_interp_method(const sh_interp *it) { return it ? it->params.method : SH_METHOD_COUNT; }
int sh_interp_num_points(const sh_interp *it) { return it ? it->n : 0; }
int sh_interp_num_coefs(const sh_interp *it) { return it ? it->num_coefs : 0; }
int sh_interp_max_terms(const sh_interp *it) { return it ? it->max_terms : 0; }

sh_status sh_interp_fit(const sh_interp *it, const double *values, int dim, double *coef)
{
    if (!it || !values || !coef) return sh_error_set(SH_EINVAL, "interp fit: null argument");
    if (dim < 1 || dim > 3)
        return sh_error_set(SH_EINVAL, "interp fit: dim must be 1..3 (got %d)", dim);
    for (int i = 0; i < it->n * dim; i++)
        if (!isfinite(values[i]))
            return sh_error_set(SH_EINVAL, "interp fit: value %d of point %d is not finite",
                                i % dim, i / dim);
    return it->ops->fit(it, values, dim, coef);
}

size_t sh_interp_subset_work_size(const sh_interp *it)
{
    return it && it->ops->subset_work ? it->ops->subset_work(it) : 0;
}

sh_status sh_interp_fit_subset(const sh_interp *it, const unsigned char *use, const double *values, int dim,
                               double *coef, void *work)
{
    if (!it || !use || !values || !coef || !work) return sh_error_set(SH_EINVAL, "interp fit: null argument");
    if (!it->ops->fit_subset)
        return sh_error_set(SH_EINVAL, "interp %s: no fit on a subset of the points (its basis depends on which are used)",
                            method_names[it->params.method]);
    if (dim < 1 || dim > 3) return sh_error_set(SH_EINVAL, "interp fit: dim must be 1..3 (got %d)", dim);
    int s = 0;
    for (int i = 0; i < it->n; i++) {
        if (!use[i]) continue;
        s++;
        for (int d = 0; d < dim; d++)
            if (!isfinite(values[i * dim + d]))
                return sh_error_set(SH_EINVAL, "interp fit: value %d of point %d is not finite", d, i);
    }
    if (s < min_points(&it->params))
        return sh_error_set(SH_EDEGENERATE, "interp %s: %d points used, needs at least %d",
                            method_names[it->params.method], s, min_points(&it->params));
    return it->ops->fit_subset(it, use, s, values, dim, coef, work);
}

int sh_interp_basis(const sh_interp *it, double x, double y, int *index, double *weight)
{
    if (!it || !index || !weight) return sh_error_set(SH_EINVAL, "interp basis: null argument");
    if (!isfinite(x) || !isfinite(y))
        return sh_error_set(SH_EINVAL, "interp basis: query point is not finite");
    return it->ops->basis(it, x, y, index, weight);
}

int sh_interp_kernel_factors(const sh_interp *it, int axis, double v, double *f)
{
    if (!it || !f || axis < 0 || axis > 1 || it->params.method != SH_METHOD_GAUSSIAN) return 0;
    /* the factors of rbf.c's exp(-r^2 / sigma^2), computed the same way */
    const double s = it->params.sigma, inv_sigma2 = s > 0 ? 1.0 / (s * s) : 0.0;
    for (int k = 0; k < it->n; k++) {
        double d = v - it->ref[2 * k + axis];
        f[k] = exp(-d * d * inv_sigma2);
    }
    return it->n;
}

sh_status sh_interp_eval(const sh_interp *it, const double *coef, int dim, double x, double y,
                         double *out)
{
    if (!it || !coef || !out) return sh_error_set(SH_EINVAL, "interp eval: null argument");
    if (dim < 1 || dim > 3)
        return sh_error_set(SH_EINVAL, "interp eval: dim must be 1..3 (got %d)", dim);
    for (int d = 0; d < dim; d++) out[d] = 0;
    if (!isfinite(x) || !isfinite(y))
        return sh_error_set(SH_EINVAL, "interp eval: query point is not finite");
    if (it->ops->eval) return it->ops->eval(it, coef, dim, x, y, out);
    int index[SH_INTERP_STACK_TERMS];
    double weight[SH_INTERP_STACK_TERMS];
    int k = it->ops->basis(it, x, y, index, weight);
    if (k < 0) return (sh_status)k;
    if (k == 0 && it->params.method == SH_METHOD_PWLINEAR)
        return sh_error_set(SH_ERANGE, "interp pwlinear: (%g, %g) is outside the convex hull", x, y);
    for (int t = 0; t < k; t++)
        for (int d = 0; d < dim; d++) out[d] += weight[t] * coef[(size_t)index[t] * dim + d];
    return SH_OK;
}

struct sh_interp_mapper {
    sh_interp_params params;
    sh_interp *it;   /* NULL until a call succeeds in building it */
    double *ref;     /* its reference points: room for 2 cap */
    double *coef;    /* its coefficients: 2 num_coefs */
    int cap;
};

sh_status sh_interp_mapper_create(const sh_interp_params *params, sh_interp_mapper **out)
{
    if (!params || !out) return sh_error_set(SH_EINVAL, "interp: no mapper parameters");
    sh_interp_mapper *m = calloc(1, sizeof *m);
    if (!m) return sh_error_set(SH_ENOMEM, "interp: out of memory");
    m->params = *params;
    *out = m;
    return SH_OK;
}

void sh_interp_mapper_destroy(sh_interp_mapper *m)
{
    if (!m) return;
    sh_interp_destroy(m->it);
    free(m->ref);
    free(m->coef);
    free(m);
}

/* The interpolant through ref_xy, kept from the last call when it is the same. */
static sh_status mapper_build(sh_interp_mapper *m, const double *ref_xy, int n)
{
    if (m->it && n == m->it->n && !memcmp(ref_xy, m->ref, sizeof(double) * 2 * (size_t)n)) return SH_OK;
    sh_interp_destroy(m->it);
    m->it = NULL;
    if (n > m->cap) {
        free(m->ref);
        if (!(m->ref = malloc(sizeof(double) * 2 * (size_t)n))) {
            m->cap = 0;
            return sh_error_set(SH_ENOMEM, "interp: out of memory");
        }
        m->cap = n;
    }
    sh_interp *it;
    sh_status st = sh_interp_create(&m->params, ref_xy, n, &it);
    if (st != SH_OK) return st;
    /* a B-spline's coefficients are its lattice's, not one per point */
    double *coef = realloc(m->coef, 2 * (size_t)sh_interp_num_coefs(it) * sizeof *coef);
    if (!coef) {
        sh_interp_destroy(it);
        return sh_error_set(SH_ENOMEM, "interp: out of memory");
    }
    m->coef = coef;
    memcpy(m->ref, ref_xy, sizeof(double) * 2 * (size_t)n);
    m->it = it;
    return SH_OK;
}

/* The 2D map of fitted coefficients at the count points `at`, into out as floats; NaN where the
 * method has no value. */
static void eval_at(const sh_interp *it, const double *coef, const float *at, int count, float *out)
{
    for (int i = 0; i < count; i++) {
        double v[2];
        if (sh_interp_eval(it, coef, 2, at[2 * i], at[2 * i + 1], v) != SH_OK) v[0] = v[1] = NAN;
        out[2 * i] = (float)v[0];
        out[2 * i + 1] = (float)v[1];
    }
}

sh_status sh_interp_mapper_map(sh_interp_mapper *m, const double *ref_xy, const double *cur_xy, int n,
                               const float *at, int count, float *out)
{
    if (!m || !ref_xy || !cur_xy || (count > 0 && (!at || !out)))
        return sh_error_set(SH_EINVAL, "interp: no points to map");
    sh_status st = mapper_build(m, ref_xy, n);
    if (st == SH_OK) st = sh_interp_fit(m->it, cur_xy, 2, m->coef);
    if (st == SH_OK) eval_at(m->it, m->coef, at, count, out);
    return st;
}

sh_status sh_interp_map_points(const sh_interp_params *params, const double *ref_xy, const double *cur_xy, int n,
                               const float *at, int count, float *out)
{
    sh_interp_mapper *m;
    sh_status st = sh_interp_mapper_create(params, &m);
    if (st == SH_OK) st = sh_interp_mapper_map(m, ref_xy, cur_xy, n, at, count, out);
    sh_interp_mapper_destroy(m);
    return st;
}

sh_status sh_interp_map_points_smoothed(const sh_interp_params *params, const double *ref_xy, const double *cur_xy,
                                        int n, const double *point_smoothing, const float *at, int count, float *out)
{
    if (!ref_xy || !cur_xy || (count > 0 && (!at || !out))) return sh_error_set(SH_EINVAL, "interp: no points to map");
    sh_interp *it;
    sh_status st = sh_interp_create_smoothed(params, ref_xy, n, point_smoothing, &it);
    if (st != SH_OK) return st;
    double *coef = malloc(sizeof(double) * 2 * (size_t)sh_interp_num_coefs(it));
    st = coef ? sh_interp_fit(it, cur_xy, 2, coef) : sh_error_set(SH_ENOMEM, "interp: out of memory");
    if (st == SH_OK) eval_at(it, coef, at, count, out);
    free(coef);
    sh_interp_destroy(it);
    return st;
}

int sh_interp_triangles(const sh_interp *it, const int **triangles)
{
    if (triangles) *triangles = it ? it->triangles : NULL;
    return it ? it->ntri : 0;
}

/* ---- shared checks ---- */

/* qsort has no context argument in C11: sort copies that carry their index (no global state). */
typedef struct {
    double x, y;
    int i;
} keyed_point;

static int cmp_keyed(const void *a, const void *b)
{
    const keyed_point *p = a, *q = b;
    if (p->x != q->x) return p->x < q->x ? -1 : 1;
    if (p->y != q->y) return p->y < q->y ? -1 : 1;
    return p->i - q->i;
}

sh_status sh_interp_check_distinct(const double *xy, int n, const char *method)
{
    keyed_point *k = malloc(sizeof *k * (size_t)(n > 0 ? n : 1));
    if (!k) return sh_error_set(SH_ENOMEM, "interp: out of memory");
    for (int i = 0; i < n; i++) k[i] = (keyed_point){xy[2 * i], xy[2 * i + 1], i};
    qsort(k, (size_t)n, sizeof *k, cmp_keyed);
    for (int i = 1; i < n; i++) {
        if (k[i].x == k[i - 1].x && k[i].y == k[i - 1].y) {
            sh_status st = sh_error_set(SH_EDEGENERATE,
                                        "interp %s: reference points %d and %d coincide at (%g, %g)",
                                        method, k[i - 1].i, k[i].i, k[i].x, k[i].y);
            free(k);
            return st;
        }
    }
    free(k);
    return SH_OK;
}

int sh_interp_collinear(const double *xy, int n)
{
    if (n < 3) return 1;
    /* The point farthest from the first spans the line; then the widest distance from it. */
    int far = 0;
    double best = 0;
    for (int i = 1; i < n; i++) {
        double dx = xy[2 * i] - xy[0], dy = xy[2 * i + 1] - xy[1], d = dx * dx + dy * dy;
        if (d > best) best = d, far = i;
    }
    if (best == 0) return 1;
    double ux = xy[2 * far] - xy[0], uy = xy[2 * far + 1] - xy[1], len = sqrt(best);
    double wide = 0;
    for (int i = 1; i < n; i++) {
        double c = fabs(ux * (xy[2 * i + 1] - xy[1]) - uy * (xy[2 * i] - xy[0])) / len;
        if (c > wide) wide = c;
    }
    return wide <= 1e-9 * len;
}

/* ---- bucket grid ---- */

sh_status sh_bucket_grid_build(sh_bucket_grid *g, const double *boxes, int count, double x0,
                               double y0, double cell, int nx, int ny)
{
    memset(g, 0, sizeof *g);
    g->x0 = x0;
    g->y0 = y0;
    g->inv_cell = 1.0 / cell;
    g->nx = nx;
    g->ny = ny;
    size_t cells = (size_t)nx * (size_t)ny;
    g->start = calloc(cells + 1, sizeof(int));
    if (!g->start) return sh_error_set(SH_ENOMEM, "interp: out of memory (bucket grid)");
    /* Two passes: count, then place; the ranges come from the same clamped coordinates. */
    for (int pass = 0; pass < 2; pass++) {
        for (int t = 0; t < count; t++) {
            const double *b = boxes + 4 * t;
            int i0 = sh_bucket_coord(b[0], x0, g->inv_cell, nx), i1 = sh_bucket_coord(b[2], x0, g->inv_cell, nx);
            int j0 = sh_bucket_coord(b[1], y0, g->inv_cell, ny), j1 = sh_bucket_coord(b[3], y0, g->inv_cell, ny);
            if (i0 < 0) i0 = 0;
            if (j0 < 0) j0 = 0;
            if (i1 > nx - 1) i1 = nx - 1;
            if (j1 > ny - 1) j1 = ny - 1;
            for (int j = j0; j <= j1; j++)
                for (int i = i0; i <= i1; i++) {
                    size_t c = (size_t)j * nx + i;
                    if (pass == 0) g->start[c + 1]++;
                    else g->items[g->start[c]++] = t;
                }
        }
        if (pass == 0) {
            for (size_t c = 0; c < cells; c++) g->start[c + 1] += g->start[c];
            g->items = malloc(sizeof(int) * (size_t)(g->start[cells] > 0 ? g->start[cells] : 1));
            if (!g->items) {
                sh_bucket_grid_free(g);
                return sh_error_set(SH_ENOMEM, "interp: out of memory (bucket grid)");
            }
        }
    }
    /* Placing advanced each start to its cell's end; shift back. */
    for (size_t c = cells; c > 0; c--) g->start[c] = g->start[c - 1];
    g->start[0] = 0;
    return SH_OK;
}

void sh_bucket_grid_free(sh_bucket_grid *g)
{
    free(g->start);
    free(g->items);
    g->start = NULL;
    g->items = NULL;
}
