/* Private to src/interp: the interpolant object and what each method file provides. */
#ifndef STILLHEART_INTERP_INTERNAL_H
#define STILLHEART_INTERP_INTERNAL_H

#include "stillheart/interp.h"

#include <stddef.h>

/* Basis rows of at most this many terms are evaluated through a stack buffer. */
#define SH_INTERP_STACK_TERMS 16

typedef struct {
    sh_status (*fit)(const sh_interp *it, const double *values, int dim, double *coef);
    int (*basis)(const sh_interp *it, double x, double y, int *index, double *weight);
    /* NULL: sh_interp_eval goes through basis (max_terms <= SH_INTERP_STACK_TERMS). */
    sh_status (*eval)(const sh_interp *it, const double *coef, int dim, double x, double y,
                      double *out);
    void (*destroy)(void *impl);
    /* NULL: the method has no fit on a subset (sh_interp_fit_subset). The work's size, in bytes,
     * and the fit; interp.c has checked the arguments and counted the used points (s >= 1). */
    size_t (*subset_work)(const sh_interp *it);
    sh_status (*fit_subset)(const sh_interp *it, const unsigned char *use, int s, const double *values, int dim,
                            double *coef, void *work);
} sh_interp_ops;

struct sh_interp {
    sh_interp_params params;
    int n;
    double *ref; /* 2n, the reference points */
    double *point_smoothing; /* n, each point's own smoothing (RBFs), or NULL: none */
    int num_coefs;
    int max_terms;
    const sh_interp_ops *ops;
    void *impl;
    const int *triangles; /* pwlinear only */
    int ntri;
};

/* Method constructors: fill ops, impl, num_coefs, max_terms (and triangles) of an interp whose
 * params, n and ref are set and already checked for finiteness and the minimum count. */
sh_status sh_interp_affine_init(sh_interp *it);
sh_status sh_interp_pwlinear_init(sh_interp *it);
sh_status sh_interp_bspline_init(sh_interp *it);
sh_status sh_interp_rbf_init(sh_interp *it);

/* Shared checks. Each returns SH_OK or an SH_EDEGENERATE naming the points and the method. */
sh_status sh_interp_check_distinct(const double *xy, int n, const char *method);
/* 1 when all points lie on one line (within 1e-9 of their extent), coincident points included. */
int sh_interp_collinear(const double *xy, int n);

/* delaunay.c: tri's ntri triangles (vertex indices into xy) in canonical form, in place: positive
 * area, each from its vertex smallest in (x, y), sorted by position (sh_interp_delaunay); slivers
 * of no area left out. scratch: ntri ints. Returns the count kept. */
int sh_interp_triangles_canonical(const double *xy, int *tri, int ntri, int *scratch);

/* A uniform bucket grid over a rectangle: items (points, triangles) registered in every cell their
 * bounding box meets, stored CSR-style. */
typedef struct {
    double x0, y0, inv_cell;
    int nx, ny;
    int *start; /* nx*ny + 1 */
    int *items;
} sh_bucket_grid;

/* boxes: count x (xmin, ymin, xmax, ymax). */
sh_status sh_bucket_grid_build(sh_bucket_grid *g, const double *boxes, int count, double x0,
                               double y0, double cell, int nx, int ny);
void sh_bucket_grid_free(sh_bucket_grid *g);
/* Cell coordinate of v along an axis of n cells, clamped to [-2, n + 1] so far-away queries
 * cannot overflow an int. */
static inline int sh_bucket_coord(double v, double origin, double inv_cell, int n)
{
    double c = (v - origin) * inv_cell;
    if (!(c > -2.0)) return -2;
    if (c > (double)n + 1.0) return n + 1;
    int i = (int)c;
    return (double)i > c ? i - 1 : i;
}

#endif
