/* Multilevel B-splines (Lee, Wolberg & Shin 1997), combined by refinement into one lattice.
 *
 * Level k has square cells of side h0 / 2^k over the bounding box of the reference points and
 * fits the residual the levels before it left at the points. Each level's control values are a
 * sparse linear map of that residual (phi_c = sum_p w_cp^3 r_p / (S_p D_c), S_p = sum_c w_cp^2,
 * D_c = sum_p w_cp^2), and the residual after level k is (I - M_k) times the one before, where
 * M_k evaluates level k's lattice at the points. Since the levels are fixed at create time, create
 * multiplies these out: T_k = (I - M_{k-1}) ... (I - M_0) maps the values to the residual that
 * level k fits. fit then needs no scratch at all: it refines the accumulated lattice in place in
 * the caller's coef buffer (the coarse lattice sits in its top-left corner with the finest row
 * stride) and scatters T_k values into it, level by level. So fit allocates nothing and is
 * reentrant, at the price of (levels - 1) n^2 doubles and an O(levels n^3) create, which is
 * nothing for the tens to hundreds of markers a heart carries. */
#include "interp_internal.h"

/* Margin of the lattice around the points' bounding box: more than the warp's grid cells. */
#define MBA_MARGIN_PX 64.0
#define MBA_MARGIN_FRACTION 0.05

#include <math.h>
#include <stdlib.h>
#include <string.h>

#define MBA_MAX_LEVELS 24
/* Finest lattice control points (interp.h's SH_INTERP_BSPLINE_MAX_CONTROL). */
#define MBA_MAX_CONTROL SH_INTERP_BSPLINE_MAX_CONTROL

typedef struct {
    double x0, y0, x1, y1; /* the points' bounding box and a margin; basis clamps queries into it */
    double h0;
    int m0, n0; /* cells of the coarsest level along x and y */
    int levels;
    int W, H;        /* finest lattice: (m0 2^(levels-1) + 3) x (n0 2^(levels-1) + 3) */
    int *cell;       /* levels x n x 2: first control point (column, row) of each point */
    double *w;       /* levels x n x 16: B-spline weights of each point, row by row */
    double *scatter; /* levels x n x 16: w^3 / (S_p D_c) */
    double *T;       /* (levels - 1) x n x n: T_1 .. T_{levels-1}; T_0 = I */
} mba_impl;

/* Index, in a lattice `stride` control points wide, of tap t (row t / 4, column t % 4) of the
 * 4 x 4 block whose first control point is cell[0], cell[1] (a point's, as `cell` stores them). */
static inline size_t tap(const int *cell, int t, int stride)
{
    return (size_t)(cell[1] + t / 4) * stride + cell[0] + t % 4;
}

static void cubic_weights(double u, double b[4])
{
    double u2 = u * u, u3 = u2 * u, v = 1.0 - u;
    b[0] = v * v * v / 6.0;
    b[1] = (3.0 * u3 - 6.0 * u2 + 4.0) / 6.0;
    b[2] = (-3.0 * u3 + 3.0 * u2 + 3.0 * u + 1.0) / 6.0;
    b[3] = u3 / 6.0;
}

/* Cell and tensor weights of (x, y) at a level of `cells_x` x `cells_y` cells of side h. */
static void locate(const mba_impl *b, double x, double y, double h, int cells_x, int cells_y,
                   int *ci, int *cj, double w[16])
{
    x = fmin(fmax(x, b->x0), b->x1);
    y = fmin(fmax(y, b->y0), b->y1);
    double s = (x - b->x0) / h, t = (y - b->y0) / h;
    int i = (int)floor(s), j = (int)floor(t);
    if (i > cells_x - 1) i = cells_x - 1;
    if (j > cells_y - 1) j = cells_y - 1;
    if (i < 0) i = 0;
    if (j < 0) j = 0;
    double bx[4], by[4];
    cubic_weights(s - i, bx);
    cubic_weights(t - j, by);
    for (int r = 0; r < 4; r++)
        for (int c = 0; c < 4; c++) w[4 * r + c] = by[r] * bx[c];
    *ci = i, *cj = j;
}

/* In-place refinement along one axis: m + 3 coarse control values at a[0], a[stride], ... become
 * 2m + 3 fine ones, by the (1/8, 1/2, 3/4, 1/2, 1/8) stencil. Going backwards, fine entry P reads
 * coarse entries up to (P + 3) / 2 <= P, so only the first three need saving. */
static void refine1d(double *a, size_t stride, int m, int dim)
{
    double head[3][3];
    for (int q = 0; q < 3; q++)
        for (int d = 0; d < dim; d++) head[q][d] = a[(size_t)q * stride + d];
#define COARSE(q, d) ((q) < 3 ? head[q][d] : a[(size_t)(q) * stride + (d)])
    for (int P = 2 * m + 2; P >= 0; P--) {
        int Q = (P + 1) / 2;
        for (int d = 0; d < dim; d++) {
            double f = (P & 1) ? (COARSE(Q - 1, d) + 6.0 * COARSE(Q, d) + COARSE(Q + 1, d)) / 8.0
                               : (COARSE(Q, d) + COARSE(Q + 1, d)) / 2.0;
            a[(size_t)P * stride + d] = f;
        }
    }
#undef COARSE
}

/* Rows first (contiguous), then the columns as whole-row combinations: going down the rows
 * column by column would stride through the whole lattice once per column. Fine row P reads
 * coarse rows up to (P + 3) / 2, so rows 3 and up go backwards in place, and rows 0..2 (which
 * read coarse rows 0..2 only) are done last, one column at a time from locals. */
static void refine2d(double *lat, int W, int mc, int nc, int dim)
{
    size_t rs = (size_t)W * dim, len = (size_t)(2 * mc + 3) * dim;
    for (int r = 0; r < nc + 3; r++) refine1d(lat + r * rs, (size_t)dim, mc, dim);
    for (int P = 2 * nc + 2; P >= 3; P--) {
        int Q = (P + 1) / 2;
        double *dst = lat + (size_t)P * rs;
        const double *c0 = lat + (size_t)(Q - 1) * rs, *c1 = c0 + rs, *c2 = c1 + rs;
        if (P & 1)
            for (size_t e = 0; e < len; e++) dst[e] = (c0[e] + 6.0 * c1[e] + c2[e]) / 8.0;
        else
            for (size_t e = 0; e < len; e++) dst[e] = (c1[e] + c2[e]) / 2.0;
    }
    for (size_t e = 0; e < len; e++) {
        double c0 = lat[e], c1 = lat[rs + e], c2 = lat[2 * rs + e];
        lat[e] = (c0 + c1) / 2.0;
        lat[rs + e] = (c0 + 6.0 * c1 + c2) / 8.0;
        lat[2 * rs + e] = (c1 + c2) / 2.0;
    }
}

static sh_status mba_fit(const sh_interp *it, const double *values, int dim, double *coef)
{
    const mba_impl *b = it->impl;
    int n = it->n, W = b->W;
    for (int r = 0; r < b->n0 + 3; r++)
        memset(coef + (size_t)r * W * dim, 0, sizeof(double) * (size_t)(b->m0 + 3) * dim);
    for (int k = 0; k < b->levels; k++) {
        if (k > 0) refine2d(coef, W, b->m0 << (k - 1), b->n0 << (k - 1), dim);
        const double *T = k > 0 ? b->T + (size_t)(k - 1) * n * n : NULL;
        for (int p = 0; p < n; p++) {
            double r[3];
            for (int d = 0; d < dim; d++) {
                if (!T) {
                    r[d] = values[p * dim + d];
                    continue;
                }
                double s = 0;
                const double *row = T + (size_t)p * n;
                for (int q = 0; q < n; q++) s += row[q] * values[q * dim + d];
                r[d] = s;
            }
            const int *c = b->cell + 2 * ((size_t)k * n + p);
            const double *a = b->scatter + 16 * ((size_t)k * n + p);
            for (int rr = 0; rr < 4; rr++) {
                double *dst = coef + ((size_t)(c[1] + rr) * W + c[0]) * dim;
                for (int cc = 0; cc < 4; cc++)
                    for (int d = 0; d < dim; d++) dst[cc * dim + d] += a[4 * rr + cc] * r[d];
            }
        }
    }
    return SH_OK;
}

static int mba_basis(const sh_interp *it, double x, double y, int *index, double *weight)
{
    const mba_impl *b = it->impl;
    int L = b->levels - 1, i, j;
    locate(b, x, y, ldexp(b->h0, -L), b->m0 << L, b->n0 << L, &i, &j, weight);
    for (int r = 0; r < 4; r++)
        for (int c = 0; c < 4; c++) index[4 * r + c] = (j + r) * b->W + i + c;
    return 16;
}

static void mba_destroy(void *p)
{
    mba_impl *b = p;
    if (!b) return;
    free(b->cell);
    free(b->w);
    free(b->scatter);
    free(b->T);
    free(b);
}

static size_t lattice_size(const mba_impl *b, int levels)
{
    return (size_t)((b->m0 << (levels - 1)) + 3) * (size_t)((b->n0 << (levels - 1)) + 3);
}

/* A subset fit's work: the residuals at the points (3 values each at most) and one level's D_c. */
static size_t mba_subset_work(const sh_interp *it)
{
    const mba_impl *b = it->impl;
    return sizeof(double) * (3 * (size_t)it->n + lattice_size(b, b->levels));
}

/* The textbook iteration over the used points alone, on this interpolant's lattices (its box,
 * cells and levels; each point's weights are create's): level k scatters the residual the levels
 * before it left at the used points, with D_c summed over those points only, into the accumulated
 * lattice, and the residual is then read off that lattice at them. The T operators cannot serve:
 * they are products over every point. O(levels (16 s + lattice)) a fit, no allocation. With
 * every point used it is mba_fit's spline (test_interp). */
static sh_status mba_fit_subset(const sh_interp *it, const unsigned char *use, int s, const double *values, int dim,
                                double *coef, void *work)
{
    (void)s;
    const mba_impl *b = it->impl;
    int n = it->n, W = b->W;
    double *r = work, *D = r + 3 * (size_t)n;
    for (int p = 0; p < n; p++)
        for (int d = 0; d < dim; d++) r[p * dim + d] = use[p] ? values[p * dim + d] : 0.0;
    for (int row = 0; row < b->n0 + 3; row++)
        memset(coef + (size_t)row * W * dim, 0, sizeof(double) * (size_t)(b->m0 + 3) * dim);
    for (int k = 0; k < b->levels; k++) {
        if (k > 0) refine2d(coef, W, b->m0 << (k - 1), b->n0 << (k - 1), dim);
        int Wk = (b->m0 << k) + 3;
        const int *cell = b->cell + 2 * (size_t)k * n;
        const double *w = b->w + 16 * (size_t)k * n;
        memset(D, 0, sizeof(double) * lattice_size(b, k + 1));
        for (int q = 0; q < n; q++)
            if (use[q])
                for (int t = 0; t < 16; t++)
                    D[tap(cell + 2 * q, t, Wk)] += w[16 * q + t] * w[16 * q + t];
        for (int q = 0; q < n; q++) {
            if (!use[q]) continue;
            const double *wq = w + 16 * q;
            double S = 0;
            for (int t = 0; t < 16; t++) S += wq[t] * wq[t];
            for (int t = 0; t < 16; t++) {
                double Dc = D[tap(cell + 2 * q, t, Wk)];
                double a = Dc > 0 ? wq[t] * wq[t] * wq[t] / (S * Dc) : 0.0;
                double *dst = coef + tap(cell + 2 * q, t, W) * dim;
                for (int d = 0; d < dim; d++) dst[d] += a * r[q * dim + d];
            }
        }
        if (k + 1 == b->levels) break;
        for (int q = 0; q < n; q++) {
            if (!use[q]) continue;
            for (int d = 0; d < dim; d++) {
                double f = 0;
                for (int t = 0; t < 16; t++)
                    f += w[16 * q + t] * coef[tap(cell + 2 * q, t, W) * dim + d];
                r[q * dim + d] = values[q * dim + d] - f;
            }
        }
    }
    return SH_OK;
}

static const sh_interp_ops mba_ops = {mba_fit, mba_basis, NULL, mba_destroy, mba_subset_work, mba_fit_subset};

/* M_k[q][p] = sum over the control points both see of w_cq * scatter_cp. */
static void level_operator(const mba_impl *b, int k, int n, double *M)
{
    const int *cell = b->cell + 2 * (size_t)k * n;
    const double *w = b->w + 16 * (size_t)k * n, *a = b->scatter + 16 * (size_t)k * n;
    for (int q = 0; q < n; q++)
        for (int p = 0; p < n; p++) {
            int di = cell[2 * p] - cell[2 * q], dj = cell[2 * p + 1] - cell[2 * q + 1];
            double s = 0;
            if (abs(di) <= 3 && abs(dj) <= 3)
                for (int r = 0; r < 4; r++)
                    for (int c = 0; c < 4; c++) {
                        int rq = r + dj, cq = c + di; /* p's control point in q's 4x4 block */
                        if (rq >= 0 && rq < 4 && cq >= 0 && cq < 4)
                            s += w[16 * q + 4 * rq + cq] * a[16 * p + 4 * r + c];
                    }
            M[(size_t)q * n + p] = s;
        }
}

/* Weights and scatter coefficients of level k (needs b->cell, w, scatter sized for it). */
static sh_status level_setup(const sh_interp *it, mba_impl *b, int k)
{
    int n = it->n, mk = b->m0 << k, nk = b->n0 << k, Wk = mk + 3;
    const double *p = it->ref;
    double *D = calloc((size_t)Wk * (size_t)(nk + 3), sizeof(double));
    if (!D) return sh_error_set(SH_ENOMEM, "interp bspline: out of memory at level %d", k);
    int *cell = b->cell + 2 * (size_t)k * n;
    double *w = b->w + 16 * (size_t)k * n, *a = b->scatter + 16 * (size_t)k * n;
#define AT(q, t) D[tap(cell + 2 * (q), t, Wk)]
    for (int q = 0; q < n; q++) {
        locate(b, p[2 * q], p[2 * q + 1], ldexp(b->h0, -k), mk, nk, &cell[2 * q], &cell[2 * q + 1],
               w + 16 * q);
        for (int t = 0; t < 16; t++) AT(q, t) += w[16 * q + t] * w[16 * q + t];
    }
    for (int q = 0; q < n; q++) {
        double S = 0;
        for (int t = 0; t < 16; t++) S += w[16 * q + t] * w[16 * q + t];
        for (int t = 0; t < 16; t++) {
            double wt = w[16 * q + t], Dc = AT(q, t);
            a[16 * q + t] = Dc > 0 ? wt * wt * wt / (S * Dc) : 0.0;
        }
    }
#undef AT
    free(D);
    return SH_OK;
}

/* T_{k+1} = T_k - M_k T_k (T_0 = I), into slot k; skips M's zeros (far pairs at fine levels).
 * Returns the largest entry of T_{k+1}: 0 up to rounding once level k interpolates exactly. */
static double next_residual_operator(const mba_impl *b, int k, int n, double *M)
{
    level_operator(b, k, n, M);
    double *Tn = b->T + (size_t)k * n * n, biggest = 0;
    const double *Tp = k > 0 ? b->T + (size_t)(k - 1) * n * n : NULL;
    for (int q = 0; q < n; q++) {
        double *row = Tn + (size_t)q * n;
        for (int j = 0; j < n; j++) row[j] = Tp ? Tp[(size_t)q * n + j] : (q == j);
        for (int s = 0; s < n; s++) {
            double m = M[(size_t)q * n + s];
            if (m == 0.0) continue;
            if (!Tp) {
                row[s] -= m;
                continue;
            }
            const double *src = Tp + (size_t)s * n;
            for (int j = 0; j < n; j++) row[j] -= m * src[j];
        }
        for (int j = 0; j < n; j++) biggest = fmax(biggest, fabs(row[j]));
    }
    return biggest;
}

int sh_interp_bspline_max_levels(void)
{
    int levels = 1;
    while (levels < MBA_MAX_LEVELS && ((1L << levels) + 3) * ((1L << levels) + 3) <= MBA_MAX_CONTROL) levels++;
    return levels;
}

/* The points' bounding box with its margin, and the coarsest level's cells. */
static void coarse_lattice(mba_impl *b, const double *p, int n)
{
    b->x0 = b->x1 = p[0], b->y0 = b->y1 = p[1];
    for (int i = 1; i < n; i++) {
        b->x0 = fmin(b->x0, p[2 * i]), b->x1 = fmax(b->x1, p[2 * i]);
        b->y0 = fmin(b->y0, p[2 * i + 1]), b->y1 = fmax(b->y1, p[2 * i + 1]);
    }
    /* The lattice covers a margin around the points, so the spline continues smoothly past the
     * outermost ones: the warp's grid nodes around the hull lie up to a grid cell outside, and a
     * value clamped there would put a kink into the interpolated map. */
    double margin = MBA_MARGIN_PX + MBA_MARGIN_FRACTION * fmax(b->x1 - b->x0, b->y1 - b->y0);
    b->x0 -= margin, b->y0 -= margin, b->x1 += margin, b->y1 += margin;
    /* Square cells, one along the shorter side, at most four along the longer one (a thin box
     * would otherwise start with a needlessly fine lattice). */
    double wx = b->x1 - b->x0, wy = b->y1 - b->y0;
    b->h0 = fmax(fmin(wx, wy), fmax(wx, wy) / 4);
    if (!(b->h0 > 0)) b->h0 = 1.0;
    b->m0 = (int)fmax(1, ceil(wx / b->h0));
    b->n0 = (int)fmax(1, ceil(wy / b->h0));
}

/* With spacing <= dmin / 4 no control point (support 4 cells wide) sees two points: that level
 * reproduces its residual exactly. Often a level earlier already does; the residual operator
 * tells, and sh_interp_bspline_init's loop stops there. Returns that level count (one more than
 * MBA_MAX_LEVELS when even those are too coarse); closest and dmin: the closest pair. */
static int automatic_levels(const mba_impl *b, const double *p, int n, int closest[2], double *dmin)
{
    for (int i = 0; i < n; i++)
        for (int j = i + 1; j < n; j++) {
            double d = fmax(fabs(p[2 * i] - p[2 * j]), fabs(p[2 * i + 1] - p[2 * j + 1]));
            if (d < *dmin) *dmin = d, closest[0] = i, closest[1] = j;
        }
    int target = 1;
    while (target <= MBA_MAX_LEVELS && ldexp(b->h0, -(target - 1)) > *dmin / 4) target++;
    return target;
}

/* The refusal when the levels asked (or needed: automatic) outgrow MBA_MAX_CONTROL. */
static sh_status too_many_levels(const mba_impl *b, int automatic, int target, const int closest[2], double dmin)
{
    double wx = b->x1 - b->x0, wy = b->y1 - b->y0;
    if (automatic)
        return sh_error_set(SH_EDEGENERATE,
                            "interp bspline: points %d and %d are %g px apart in a %g x %g "
                            "box: exact interpolation needs a lattice of more than %d "
                            "control points", closest[0], closest[1], dmin, wx, wy,
                            MBA_MAX_CONTROL);
    return sh_error_set(SH_EINVAL, "interp bspline: %d levels make a lattice of more "
                        "than %d control points", target, MBA_MAX_CONTROL);
}

sh_status sh_interp_bspline_init(sh_interp *it)
{
    int n = it->n;
    const double *p = it->ref;
    sh_status st = sh_interp_check_distinct(p, n, "bspline");
    if (st != SH_OK) return st;
    mba_impl *b = calloc(1, sizeof *b);
    double *M = malloc(sizeof(double) * (size_t)n * n);
    if (!b || !M) {
        free(b);
        free(M);
        return sh_error_set(SH_ENOMEM, "interp bspline: out of memory");
    }
    coarse_lattice(b, p, n);

    int automatic = it->params.levels == 0, target = it->params.levels;
    int closest[2] = {0, 0};
    double dmin = INFINITY;
    if (automatic) target = automatic_levels(b, p, n, closest, &dmin);
    int cap = target < MBA_MAX_LEVELS ? target : MBA_MAX_LEVELS;
    b->cell = malloc(sizeof(int) * 2 * (size_t)cap * n);
    b->w = malloc(sizeof(double) * 16 * (size_t)cap * n);
    b->scatter = malloc(sizeof(double) * 16 * (size_t)cap * n);
    b->T = malloc(sizeof(double) * (size_t)cap * n * n);
    if (!b->cell || !b->w || !b->scatter || !b->T) {
        st = sh_error_set(SH_ENOMEM, "interp bspline: out of memory for %d levels", cap);
        goto fail;
    }
    int levels = 0;
    for (int k = 0; !levels; k++) {
        if (k >= MBA_MAX_LEVELS || lattice_size(b, k + 1) > MBA_MAX_CONTROL) {
            st = too_many_levels(b, automatic, target, closest, dmin);
            goto fail;
        }
        if ((st = level_setup(it, b, k)) != SH_OK) goto fail;
        if (k + 1 == target) {
            levels = k + 1;
        } else {
            double left = next_residual_operator(b, k, n, M);
            if (automatic && left <= 1e-13) levels = k + 1;
        }
    }
    free(M);
    b->levels = levels;
    b->W = (b->m0 << (levels - 1)) + 3;
    b->H = (b->n0 << (levels - 1)) + 3;
    it->impl = b;
    it->ops = &mba_ops;
    it->num_coefs = b->W * b->H;
    it->max_terms = 16;
    return SH_OK;
fail:
    free(M);
    mba_destroy(b);
    return st;
}

int sh_interp_bspline_levels(const sh_interp *it)
{
    return it && it->params.method == SH_METHOD_BSPLINE ? ((const mba_impl *)it->impl)->levels : 0;
}

sh_status sh_interp_bspline_residuals(const sh_interp *it, const double *values, int dim,
                                      double *max_residual_per_level, int *levels)
{
    if (!it || !values || !levels || dim < 1 || dim > 3)
        return sh_error_set(SH_EINVAL, "interp bspline residuals: invalid arguments");
    if (it->params.method != SH_METHOD_BSPLINE)
        return sh_error_set(SH_EINVAL, "interp %s: residuals per level are for bspline only",
                            sh_interp_method_name(it->params.method));
    const mba_impl *b = it->impl;
    *levels = b->levels;
    if (!max_residual_per_level) return SH_OK;
    int n = it->n;
    /* The textbook iteration, level by level on its own lattice: an independent path from the
     * pre-multiplied operators fit uses. */
    double *r = malloc(sizeof(double) * (size_t)n * dim);
    double *phi = malloc(sizeof(double) * lattice_size(b, b->levels) * dim);
    if (!r || !phi) {
        free(r);
        free(phi);
        return sh_error_set(SH_ENOMEM, "interp bspline: out of memory");
    }
    memcpy(r, values, sizeof(double) * (size_t)n * dim);
    for (int k = 0; k < b->levels; k++) {
        int Wk = (b->m0 << k) + 3;
        size_t size = lattice_size(b, k + 1) * dim;
        memset(phi, 0, sizeof(double) * size);
        const int *cell = b->cell + 2 * (size_t)k * n;
        const double *w = b->w + 16 * (size_t)k * n, *a = b->scatter + 16 * (size_t)k * n;
        for (int q = 0; q < n; q++)
            for (int t = 0; t < 16; t++)
                for (int d = 0; d < dim; d++)
                    phi[tap(cell + 2 * q, t, Wk) * dim + d] +=
                        a[16 * q + t] * r[q * dim + d];
        double mx = 0;
        for (int q = 0; q < n; q++)
            for (int d = 0; d < dim; d++) {
                double s = 0;
                for (int t = 0; t < 16; t++)
                    s += w[16 * q + t] *
                         phi[tap(cell + 2 * q, t, Wk) * dim + d];
                r[q * dim + d] -= s;
                mx = fmax(mx, fabs(r[q * dim + d]));
            }
        max_residual_per_level[k] = mx;
    }
    free(r);
    free(phi);
    return SH_OK;
}
