/* The per-frame LU factorization (linalg.h, sh_linalg_lu_factor_inplace). Eigen's LU
 * (linalg.cpp, once per reference) copies the matrix into its own storage, its condition estimate
 * solves into temporaries, and its blocked products take their buffers from the heap past
 * EIGEN_STACK_ALLOCATION_LIMIT; a system refactored for every frame (the daemon's landmarks, a few hundred unknowns) must not
 * allocate, so this one is the textbook right-looking elimination in place. Its row updates are
 * contiguous and vectorize (-O3 for src/linalg in the Makefile). */
#include <math.h>
#include <string.h>

#include "stillheart/linalg.h"

/* Built for AVX-512 and AVX2 too, chosen when the program starts (gcc's target_clones, as
 * src/landmarks does): the row updates are the whole cost, and each element's a - l * b is the
 * same operation in every lane width (-ffp-contract=off), so every clone gives the same bits. */
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__)
#define LU_CLONES __attribute__((target_clones("arch=x86-64-v4", "avx2", "default")))
#else
#define LU_CLONES
#endif

/* Columns a panel: the rows below it are updated once per panel, each element kept in a
 * register through the panel's steps (LU_STRIP of a row at a time), where one column at a time
 * loaded and stored the whole trailing matrix for every step (a 150 x 150 system is 180 KB). */
#define LU_PANEL 16
#define LU_STRIP 8

/* a strip of a row as one value: gcc and clang make it the widest vectors the clone has (one
 * AVX-512 register, two AVX2 ones, four SSE2 or NEON ones), element by element the same
 * operations as the scalar tail */
typedef double strip __attribute__((vector_size(LU_STRIP * sizeof(double))));

/* Right-looking elimination by panels (LAPACK's dgetrf, its update in strips): every element
 * gets the same subtractions a_ij -= l_ik u_kj in the same order k as the elimination one column
 * at a time, so the same bits (test_lu_inplace checks them against that elimination): within a
 * panel its columns are updated at each step, the rows' parts beyond it after the panel, through
 * its steps in order; a row swap moves the row's own multipliers with it, and both rows miss the
 * same deferred updates. A zero multiplier updates nothing, as there. */
LU_CLONES sh_status sh_linalg_lu_factor_inplace(int n, double *restrict a, int *restrict src)
{
    if (n <= 0 || !a || !src) return sh_error_set(SH_EINVAL, "linalg: bad LU arguments");
    for (int i = 0; i < n; i++) src[i] = i;
    double big = 0, small = INFINITY;
    for (int k0 = 0; k0 < n; k0 += LU_PANEL) {
        const int k1 = k0 + LU_PANEL < n ? k0 + LU_PANEL : n;
        for (int k = k0; k < k1; k++) {
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
                for (int j = k + 1; j < k1; j++) ri[j] -= l * rk[j];
            }
        }
        /* the columns past the panel: the panel's rows below each step (they become U, in
         * order, each from the rows above it), then the rows below the panel */
        for (int i = k0 + 1; i < n && k1 < n; i++) {
            double *restrict ri = a + (size_t)i * n;
            const double *rows[LU_PANEL];
            double l[LU_PANEL];
            int q = 0;
            for (int k = k0; k < (i < k1 ? i : k1); k++)
                if (ri[k] != 0.0) rows[q] = a + (size_t)k * n, l[q++] = ri[k];
            int j = k1;
            for (; j + LU_STRIP <= n; j += LU_STRIP) {
                strip v, u;
                memcpy(&v, ri + j, sizeof v);
                for (int r = 0; r < q; r++) {
                    memcpy(&u, rows[r] + j, sizeof u);
                    v -= l[r] * u;
                }
                memcpy(ri + j, &v, sizeof v);
            }
            for (; j < n; j++)
                for (int r = 0; r < q; r++) ri[j] -= l[r] * rows[r][j];
        }
    }
    /* The pivots' spread: a cheap stand-in for the condition estimate this path cannot afford.
     * Below the threshold Eigen's rcond check (rbf.c) would also refuse the system. */
    if (!(small > 1e-15 * big))
        return sh_error_set(SH_EDEGENERATE, "linalg: the %d x %d system is numerically singular (pivots %.3g .. %.3g)",
                            n, n, small, big);
    return SH_OK;
}
