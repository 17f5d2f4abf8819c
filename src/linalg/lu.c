/* The per-frame LU factorization (linalg.h, sh_linalg_lu_factor_inplace). Eigen's LU
 * (linalg.cpp, once per reference) copies the matrix into its own storage, its condition estimate
 * solves into temporaries, and its blocked products take their buffers from the heap past
 * EIGEN_STACK_ALLOCATION_LIMIT; a system refactored for every frame (the daemon's landmarks, a few hundred unknowns) must not
 * allocate, so this one is the textbook right-looking elimination in place. Its row updates are
 * contiguous and vectorize (-O3 for src/linalg in the Makefile). */
#include <math.h>

#include "stillheart/linalg.h"

/* Built for AVX-512 and AVX2 too, chosen when the program starts (gcc's target_clones, as
 * src/landmarks does): the row updates are the whole cost, and each element's a - l * b is the
 * same operation in every lane width (-ffp-contract=off), so every clone gives the same bits. */
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__)
#define LU_CLONES __attribute__((target_clones("arch=x86-64-v4", "avx2", "default")))
#else
#define LU_CLONES
#endif

LU_CLONES sh_status sh_linalg_lu_factor_inplace(int n, double *restrict a, int *restrict src)
{
    if (n <= 0 || !a || !src) return sh_error_set(SH_EINVAL, "linalg: bad LU arguments");
    for (int i = 0; i < n; i++) src[i] = i;
    double big = 0, small = INFINITY;
    for (int k = 0; k < n; k++) {
        int p = k;
        double best = fabs(a[(size_t)k * n + k]);
        for (int i = k + 1; i < n; i++) {
            double v = fabs(a[(size_t)i * n + k]);
            if (v > best) best = v, p = i;
        }
        if (!(best > 0) || !isfinite(best))
            return sh_error_set(SH_EDEGENERATE, "linalg: the %d x %d system is singular (column %d)", n, n, k);
        if (best > big) big = best;
        if (best < small) small = best;
        if (p != k) {
            double *rk = a + (size_t)k * n, *rp = a + (size_t)p * n;
            for (int j = 0; j < n; j++) {
                double t = rk[j];
                rk[j] = rp[j];
                rp[j] = t;
            }
            int t = src[k];
            src[k] = src[p];
            src[p] = t;
        }
        const double *restrict rk = a + (size_t)k * n;
        double inv = 1.0 / rk[k];
        for (int i = k + 1; i < n; i++) {
            double *restrict ri = a + (size_t)i * n;
            double l = ri[k] * inv;
            ri[k] = l;
            if (l == 0.0) continue;
            for (int j = k + 1; j < n; j++) ri[j] -= l * rk[j];
        }
    }
    /* The pivots' spread: a cheap stand-in for the condition estimate this path cannot afford.
     * Below the threshold Eigen's rcond check (rbf.c) would also refuse the system. */
    if (!(small > 1e-15 * big))
        return sh_error_set(SH_EDEGENERATE, "linalg: the %d x %d system is numerically singular (pivots %.3g .. %.3g)",
                            n, n, small, big);
    return SH_OK;
}
