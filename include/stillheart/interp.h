/* Scattered-data interpolants of the paper (section III-B, Table I), built once per reference.
 *
 * Every method is linear in the values it interpolates:
 *     value(q) = sum_k  basis_k(q) * coef[index_k],   coef = L(values)  (a linear map)
 * sh_interp_create does all the work that depends on the reference positions only (Delaunay
 * triangulation, factoring the RBF system, the B-spline lattices); sh_interp_fit turns the
 * current values into coefficients (cheap: a back-substitution or a B-spline pass), and
 * sh_interp_basis gives the sparse basis row at any point, which the warp caches on its grid. */
#ifndef STILLHEART_INTERP_H
#define STILLHEART_INTERP_H

#include "stillheart/core.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef enum {
    SH_METHOD_AFFINE = 0, /* least-squares affine map, >= 3 non-collinear points */
    SH_METHOD_PWLINEAR,   /* linear on the Delaunay triangles of the reference points (libqhull_r) */
    SH_METHOD_BSPLINE,    /* multilevel B-splines, Lee, Wolberg & Shin 1997 */
    SH_METHOD_RBF_LOCAL,  /* phi(r) = 1 - (r/s)^2 (3 - 2 r/s) for r < s, else 0 */
    SH_METHOD_TPS,        /* phi(r) = r^2 log r */
    SH_METHOD_GAUSSIAN,   /* phi(r) = exp(-r^2 / s^2) */
    SH_METHOD_COUNT
} sh_method;

typedef struct {
    sh_method method;
    int affine_term;  /* RBFs: 1 = add r1 + r2 x + r3 y with its three side conditions */
    double sigma;     /* RBFs: scale s in pixels (paper: 95 local, 100 Gaussian). TPS and the
                         other methods have no scale and refuse a non-zero value. */
    int levels;       /* B-spline: number of levels; 0 = as many as exact interpolation needs */
    double smoothing; /* RBFs: 0 = interpolate; lambda > 0 approximates (lambda added to the
                         kernel matrix's diagonal). Other methods refuse a non-zero value. */
} sh_interp_params;

/* B-spline: the most control points of the finest lattice. A fit costs O(lattice) per frame
 * (about 3 ms per million control points and component here), so the cap keeps it a few ms;
 * 8 MiB per component. */
#define SH_INTERP_BSPLINE_MAX_CONTROL (1 << 20)

/* Paper defaults for the method: affine term on, sigma 95 / 100, automatic levels, exact. */
void sh_interp_params_default(sh_interp_params *params, sh_method method);

/* Parses a method name as the command line spells it: affine, pwlinear, bspline, rbf-local,
 * tps, gaussian, and the variants without the affine term: rbf-local-pure, tps-pure,
 * gaussian-pure. Fills params with that method's defaults. */
sh_status sh_interp_params_parse(const char *name, sh_interp_params *params);
const char *sh_interp_method_name(sh_method method);
/* The name sh_interp_params_parse reads back as params' method and affine term (tps, tps-pure,
 * ...), in out (cap bytes, truncated); sigma, levels and smoothing are not part of it. */
void sh_interp_params_name(const sh_interp_params *params, char *out, size_t cap);
/* The checks sh_interp_create makes of params before it sees a point (SH_EINVAL and a message
 * "interp METHOD: ..."): a value the method would ignore (sigma, levels, smoothing of another
 * method), sigma not > 0, and more B-spline levels than sh_interp_bspline_max_levels. */
sh_status sh_interp_params_check(const sh_interp_params *params);
/* The most B-spline levels whose finest lattice can hold SH_INTERP_BSPLINE_MAX_CONTROL control
 * points: with one coarse cell each way (the fewest) level L has (2^(L-1) + 3)^2 (10 levels).
 * Whether that many fit a given layout depends on its bounding box (up to four coarse cells
 * along its longer side): sh_interp_create says. */
int sh_interp_bspline_max_levels(void);

typedef struct sh_interp sh_interp;

/* ref_xy: n points as x0,y0,x1,y1,...; copied. Degenerate input (too few points, collinear,
 * duplicates, NaN/inf) returns SH_EDEGENERATE or SH_EINVAL with a message naming the problem. */
sh_status sh_interp_create(const sh_interp_params *params, const double *ref_xy, int n,
                           sh_interp **out);
/* The same with a smoothing of each point's own (point_smoothing: n values >= 0, copied; NULL: none),
 * added to its diagonal entry of the RBF system besides params->smoothing: a point known less
 * precisely than the others (a natural landmark beside the markers, landmarks.h) is approximated,
 * the others still interpolated where theirs is 0. The fit then leaves point k off by
 * point_smoothing[k] times its kernel coefficient. The RBFs only: another method refuses a
 * non-zero value (SH_EINVAL), as it refuses params->smoothing. sh_interp_fit_subset keeps each used
 * point's own. */
sh_status sh_interp_create_smoothed(const sh_interp_params *params, const double *ref_xy, int n,
                                    const double *point_smoothing, sh_interp **out);
/* 1 for the methods that take a smoothing (params->smoothing, point_smoothing): the RBFs, which
 * approximate through the diagonal of their system; the others interpolate (affine fits by least
 * squares) with no such term. */
int sh_interp_method_smooths(sh_method method);
void sh_interp_destroy(sh_interp *interp);

sh_method sh_interp_method(const sh_interp *interp);
int sh_interp_num_points(const sh_interp *interp);
int sh_interp_num_coefs(const sh_interp *interp);
/* Upper bound on the terms sh_interp_basis writes at any point. */
int sh_interp_max_terms(const sh_interp *interp);
/* A B-spline's number of levels (the ones asked, or with levels 0 the ones its points needed);
 * 0 for another method. */
int sh_interp_bspline_levels(const sh_interp *interp);

/* values: n x dim (row-major, dim 1..3), in the order of the reference points.
 * coef: num_coefs x dim, caller-allocated. No allocation; safe to call from several threads
 * on the same interp with different buffers (every method: the B-spline levels are multiplied
 * out at create time and refined in place inside coef). Cost per call: O(n) for affine and
 * piecewise linear, O(n^2 dim) for the RBFs, O(levels n^2 dim + lattice dim) for B-splines. */
sh_status sh_interp_fit(const sh_interp *interp, const double *values, int dim, double *coef);

/* The interpolant through the points with use[k] != 0 alone, as if the others were not there, in
 * this interpolant's coefficient layout: a left-out point's coefficients are 0, so that
 * sh_interp_basis, sh_interp_eval and a warp grid built over all the points give its map. For
 * correspondences that come and go every frame (natural landmarks, landmarks.h): one interpolant
 * and one grid basis per reference instead of one per subset. Affine and the RBFs: up to rounding
 * the function sh_interp_create on the used points gives (the affine part keeps this
 * interpolant's centring and scale: the same functions). Bspline: the multilevel B-spline
 * iteration over the used points on this interpolant's lattices (their box and levels come from
 * every point, so it is not sh_interp_create's on the used points; with the automatic levels,
 * which separate every point and so any subset, it passes through them too). Pwlinear refuses
 * (SH_EINVAL): its triangles depend on which points are used. values: n x dim as for
 * sh_interp_fit (a left-out point's values are not read).
 * work: sh_interp_subset_work_size(interp) bytes, aligned for double; nothing is allocated.
 * SH_EDEGENERATE for too few used points, collinear ones where the method has an affine part, or
 * a singular system. Cost: O(s^3) for s used points with the RBFs (the system is factored anew),
 * O(levels (16 s + lattice)) with bspline. */
size_t sh_interp_subset_work_size(const sh_interp *interp);
sh_status sh_interp_fit_subset(const sh_interp *interp, const unsigned char *use, const double *values, int dim,
                               double *coef, void *work);

/* Sparse basis row at (x, y): writes count (index, weight) pairs and returns count (>= 0).
 * Piecewise linear returns 0 terms outside the convex hull of the reference points. */
int sh_interp_basis(const sh_interp *interp, double x, double y, int *index, double *weight);

/* Gaussian RBFs only (with or without the affine term): the kernel term of point k at (x, y)
 * is the product gx_k(x) gy_k(y), which lets a regular grid's basis be stored per axis (the
 * warp's grid: nx + ny rows of n factors instead of nx ny rows of n terms). Writes
 * f[k] = exp(-(v - p_k)^2 / sigma^2), p_k the point's coordinate along axis (0: x, 1: y), for
 * the n points and returns n; returns 0 for every other method. The basis row's other terms
 * (the affine term's, indices n .. n + 2) are sh_interp_basis's. */
int sh_interp_kernel_factors(const sh_interp *interp, int axis, double v, double *f);

/* One-shot, for a set of correspondences that changes with every call: the interpolant of params
 * through the n points ref_xy (x0,y0,...) with 2D values cur_xy, evaluated at the count points
 * `at` (x0,y0,... as floats) into out (count pairs). A point where the method has no value
 * (piecewise linear outside the hull) gets NaN. Allocates the interpolant and its coefficients;
 * errors as sh_interp_create and sh_interp_fit. */
sh_status sh_interp_map_points(const sh_interp_params *params, const double *ref_xy, const double *cur_xy, int n,
                               const float *at, int count, float *out);

/* sh_interp_map_points through sh_interp_create_smoothed (point_smoothing as there; NULL: none). */
sh_status sh_interp_map_points_smoothed(const sh_interp_params *params, const double *ref_xy, const double *cur_xy,
                                        int n, const double *point_smoothing, const float *at, int count, float *out);

/* sh_interp_map_points, every frame, where the reference points stay the same for many calls (natural
 * landmarks predicted by the map of the markers a frame shares with its reference): the
 * interpolant and its coefficients are made again only when n or ref_xy differ from the last
 * successful call's, so that a call with the same reference allocates nothing and skips the
 * interpolant's build (its system's factoring). The values are sh_interp_map_points' bit for bit.
 * After an error the next call builds afresh. */
typedef struct sh_interp_mapper sh_interp_mapper;
sh_status sh_interp_mapper_create(const sh_interp_params *params, sh_interp_mapper **out);
void sh_interp_mapper_destroy(sh_interp_mapper *mapper);
sh_status sh_interp_mapper_map(sh_interp_mapper *mapper, const double *ref_xy, const double *cur_xy, int n,
                               const float *at, int count, float *out);

/* value(x, y) = sum basis * coef, for dim components. Piecewise linear outside the convex hull:
 * SH_ERANGE with out set to 0 (no silent zero map). */
sh_status sh_interp_eval(const sh_interp *interp, const double *coef, int dim, double x, double y,
                         double *out);

/* Piecewise linear only: the Delaunay triangles as vertex-index triples (3 * count ints,
 * counter-clockwise in image coordinates as drawn with y down: i.e. positive signed area
 * (x1-x0)(y2-y0) - (x2-x0)(y1-y0) > 0), in sh_interp_delaunay's canonical form (each from its
 * vertex smallest in (x, y), sorted by position: independent of the points' order). Other
 * methods: count 0. */
int sh_interp_triangles(const sh_interp *interp, const int **triangles);

/* The Delaunay triangulation of n >= 3 distinct points xy (x0,y0,...), not all collinear, without
 * allocating: for a set that changes every frame (pwlinear through a frame's natural landmarks,
 * sh_warp_model_update_subset). For points in general position it is pwlinear's (qhull's); where
 * four or more are cocircular within rounding either diagonal may come out. work:
 * sh_interp_delaunay_work_size(n) bytes, aligned for int; tri: room for 6n ints. Writes
 * *ntri triangles as index triples in the canonical form sh_interp_triangles gives: positive
 * signed area, each starting at its vertex smallest in (x, then y), the list sorted by its first
 * two vertices' positions, so that the same points in any order give the same triangles in the
 * same order, at the same positions; slivers of no area (within 1e-12 of the extent squared) left
 * out. SH_EDEGENERATE when the points are collinear. */
size_t sh_interp_delaunay_work_size(int n);
sh_status sh_interp_delaunay(const double *xy, int n, void *work, int *tri, int *ntri);

/* B-spline only, for tests and diagnostics (allocates): runs the textbook multilevel iteration on
 * values (n x dim) and writes the largest absolute residual at the reference points after each
 * level (max_residual_per_level: *levels entries; pass NULL first to learn *levels). */
sh_status sh_interp_bspline_residuals(const sh_interp *interp, const double *values, int dim,
                                      double *max_residual_per_level, int *levels);

#ifdef __cplusplus
}
#endif
#endif
