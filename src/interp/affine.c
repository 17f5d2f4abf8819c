/* Least-squares affine map. The basis is [1, u, v] with u, v the coordinates centred on the
 * points' mean and scaled by their spread, so the normal system stays well conditioned for pixel
 * coordinates; the map is still linear in the values: coef = pinv(A) values. */
#include "interp_internal.h"
#include "stillheart/linalg.h"

#include <math.h>
#include <stdlib.h>

typedef struct {
    double cx, cy, inv_scale;
    double *pinv; /* 3 x n */
} affine_impl;

static void affine_destroy(void *p)
{
    affine_impl *a = p;
    if (!a) return;
    free(a->pinv);
    free(a);
}

static sh_status affine_fit(const sh_interp *it, const double *values, int dim, double *coef)
{
    const affine_impl *a = it->impl;
    int n = it->n;
    for (int k = 0; k < 3; k++) {
        const double *row = a->pinv + (size_t)k * n;
        for (int d = 0; d < dim; d++) {
            double s = 0;
            for (int i = 0; i < n; i++) s += row[i] * values[i * dim + d];
            coef[k * dim + d] = s;
        }
    }
    return SH_OK;
}

static int affine_basis(const sh_interp *it, double x, double y, int *index, double *weight)
{
    const affine_impl *a = it->impl;
    index[0] = 0, index[1] = 1, index[2] = 2;
    weight[0] = 1.0;
    weight[1] = (x - a->cx) * a->inv_scale;
    weight[2] = (y - a->cy) * a->inv_scale;
    return 3;
}

static size_t affine_subset_work(const sh_interp *it) { return sizeof(double) * 2 * (size_t)it->n; }

/* Least squares over the used points in the same [1, u, v] basis: the 3 x 3 normal equations,
 * solved in closed form (Cramer), well conditioned in the centred and scaled coordinates. */
static sh_status affine_fit_subset(const sh_interp *it, const unsigned char *use, int s, const double *values, int dim,
                                   double *coef, void *work)
{
    const affine_impl *a = it->impl;
    double *q = work;
    for (int i = 0, k = 0; i < it->n; i++)
        if (use[i]) q[2 * k] = it->ref[2 * i], q[2 * k + 1] = it->ref[2 * i + 1], k++;
    if (s < 3 || sh_interp_collinear(q, s))
        return sh_error_set(SH_EDEGENERATE, "interp affine: the %d points used are collinear or too few", s);
    double N[3][3] = {{0}}, b[3][3] = {{0}};
    for (int i = 0; i < it->n; i++) {
        if (!use[i]) continue;
        double row[3] = {1.0, (it->ref[2 * i] - a->cx) * a->inv_scale, (it->ref[2 * i + 1] - a->cy) * a->inv_scale};
        for (int j = 0; j < 3; j++) {
            for (int k = 0; k < 3; k++) N[j][k] += row[j] * row[k];
            for (int d = 0; d < dim; d++) b[j][d] += row[j] * values[i * dim + d];
        }
    }
    double det = N[0][0] * (N[1][1] * N[2][2] - N[1][2] * N[2][1]) - N[0][1] * (N[1][0] * N[2][2] - N[1][2] * N[2][0]) +
                 N[0][2] * (N[1][0] * N[2][1] - N[1][1] * N[2][0]);
    if (!(fabs(det) > 1e-12 * (double)s * s * s))
        return sh_error_set(SH_EDEGENERATE, "interp affine: the %d points used are nearly collinear", s);
    for (int d = 0; d < dim; d++)
        for (int c = 0; c < 3; c++) {
            double M[3][3];
            for (int j = 0; j < 3; j++)
                for (int k = 0; k < 3; k++) M[j][k] = k == c ? b[j][d] : N[j][k];
            double dc = M[0][0] * (M[1][1] * M[2][2] - M[1][2] * M[2][1]) - M[0][1] * (M[1][0] * M[2][2] - M[1][2] * M[2][0]) +
                        M[0][2] * (M[1][0] * M[2][1] - M[1][1] * M[2][0]);
            coef[c * dim + d] = dc / det;
        }
    return SH_OK;
}

static const sh_interp_ops affine_ops = {affine_fit, affine_basis, NULL, affine_destroy, affine_subset_work,
                                         affine_fit_subset};

sh_status sh_interp_affine_init(sh_interp *it)
{
    int n = it->n;
    const double *p = it->ref;
    if (sh_interp_collinear(p, n))
        return sh_error_set(SH_EDEGENERATE,
                            "interp affine: the %d reference points are collinear (or coincide)", n);
    affine_impl *a = calloc(1, sizeof *a);
    double *m = malloc(sizeof(double) * 3 * (size_t)n);
    if (a) a->pinv = malloc(sizeof(double) * 3 * (size_t)n);
    if (!a || !m || !a->pinv) {
        free(m);
        affine_destroy(a);
        return sh_error_set(SH_ENOMEM, "interp affine: out of memory");
    }
    double sx = 0, sy = 0;
    for (int i = 0; i < n; i++) sx += p[2 * i], sy += p[2 * i + 1];
    a->cx = sx / n, a->cy = sy / n;
    double spread = 0;
    for (int i = 0; i < n; i++)
        spread = fmax(spread, fmax(fabs(p[2 * i] - a->cx), fabs(p[2 * i + 1] - a->cy)));
    a->inv_scale = 1.0 / spread; /* > 0: not all points coincide */
    for (int i = 0; i < n; i++) {
        m[3 * i] = 1.0;
        m[3 * i + 1] = (p[2 * i] - a->cx) * a->inv_scale;
        m[3 * i + 2] = (p[2 * i + 1] - a->cy) * a->inv_scale;
    }
    double rcond;
    sh_status st = sh_linalg_pinv(n, 3, m, a->pinv, &rcond);
    free(m);
    if (st == SH_OK && !(rcond > 1e-12))
        st = sh_error_set(SH_EDEGENERATE,
                          "interp affine: the reference points are nearly collinear (rcond %g)", rcond);
    if (st != SH_OK) {
        affine_destroy(a);
        return st;
    }
    it->impl = a;
    it->ops = &affine_ops;
    it->num_coefs = 3;
    it->max_terms = 3;
    return SH_OK;
}
