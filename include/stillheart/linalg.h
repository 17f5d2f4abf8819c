/* Dense linear algebra that runs once per reference (RBF systems, least squares), over Eigen.
 * Eigen lives only in src/linalg/linalg.cpp; this header is plain C. Matrices are row-major. */
#ifndef STILLHEART_LINALG_H
#define STILLHEART_LINALG_H

#include "stillheart/core.h"

#ifdef __cplusplus
extern "C" {
#endif

/* LU factorization with partial pivoting of the n x n matrix a (overwritten by L and U: unit
 * lower triangle below the diagonal, U on and above it). src[i] is the row of the original matrix
 * that became row i. rcond: Eigen's estimate of the reciprocal 1-norm condition number (0 for a
 * singular matrix). Fails only for bad arguments or lack of memory; the caller judges rcond. */
sh_status sh_linalg_lu_factor(int n, double *a, int *src, double *rcond);

/* The same factorization (the same layout, for sh_linalg_lu_solve) without allocating and without
 * the condition estimate: for a system refactored every frame. SH_EDEGENERATE when a pivot is
 * zero or the pivots span more than 1e15 (a system no digit of whose solution would be right). */
sh_status sh_linalg_lu_factor_inplace(int n, double *a, int *src);

/* Solves A x = b for dim right-hand sides with the factor of sh_linalg_lu_factor. b holds nb
 * rows of dim values (row-major); rows nb..n-1 of b are taken as zero (the side conditions of an
 * RBF system). x: n x dim, must not overlap b. No allocation; reentrant. */
void sh_linalg_lu_solve(int n, const double *lu, const int *src, const double *b, int nb, int dim,
                        double *x);

/* Moore-Penrose pseudo-inverse of the rows x cols matrix a (rows >= cols), by SVD: pinv is
 * cols x rows. rcond: smallest over largest singular value (0 when a is 0). */
sh_status sh_linalg_pinv(int rows, int cols, const double *a, double *pinv, double *rcond);

#ifdef __cplusplus
}
#endif
#endif
