// The only home of Eigen in stillheart: factorizations done once per reference. The per-frame
// solve is plain loops over the stored factor so that it neither allocates nor locks.
#include "stillheart/linalg.h"

// GCC's flow analysis sees through Eigen's triangular products and warns about a temporary it
// cannot prove initialized (a known false positive of Eigen 3.4 with GCC 12+).
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#endif
#include <Eigen/Dense>
#include <cmath>
#include <new>

namespace {
using RowMat = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
}

extern "C" sh_status sh_linalg_lu_factor(int n, double *a, int *src, double *rcond)
{
    if (n <= 0 || !a || !src || !rcond) return sh_error_set(SH_EINVAL, "linalg: bad LU arguments");
    try {
        Eigen::Map<RowMat> m(a, n, n);
        Eigen::PartialPivLU<RowMat> lu(m);
        *rcond = lu.rcond();
        if (!std::isfinite(*rcond)) *rcond = 0;
        m = lu.matrixLU();
        // Eigen's P maps row i of A to row indices(i) of P A; we want the inverse direction.
        const auto &idx = lu.permutationP().indices();
        for (int i = 0; i < n; i++) src[idx(i)] = i;
    } catch (const std::bad_alloc &) {
        return sh_error_set(SH_ENOMEM, "linalg: no memory for a %d x %d LU factorization", n, n);
    }
    return SH_OK;
}

extern "C" void sh_linalg_lu_solve(int n, const double *lu, const int *src, const double *b, int nb,
                                   int dim, double *x)
{
    for (int i = 0; i < n; i++) {
        int r = src[i];
        for (int d = 0; d < dim; d++) x[i * dim + d] = r < nb ? b[r * dim + d] : 0.0;
    }
    for (int i = 1; i < n; i++) {
        const double *row = lu + (size_t)i * n;
        for (int j = 0; j < i; j++) {
            double l = row[j];
            if (l == 0.0) continue;
            for (int d = 0; d < dim; d++) x[i * dim + d] -= l * x[j * dim + d];
        }
    }
    for (int i = n - 1; i >= 0; i--) {
        const double *row = lu + (size_t)i * n;
        for (int j = i + 1; j < n; j++) {
            double u = row[j];
            if (u == 0.0) continue;
            for (int d = 0; d < dim; d++) x[i * dim + d] -= u * x[j * dim + d];
        }
        for (int d = 0; d < dim; d++) x[i * dim + d] /= row[i];
    }
}

extern "C" sh_status sh_linalg_pinv(int rows, int cols, const double *a, double *pinv,
                                    double *rcond)
{
    if (rows < cols || cols <= 0 || !a || !pinv || !rcond)
        return sh_error_set(SH_EINVAL, "linalg: bad pseudo-inverse arguments");
    try {
        Eigen::Map<const RowMat> m(a, rows, cols);
        Eigen::JacobiSVD<Eigen::MatrixXd> svd(m, Eigen::ComputeThinU | Eigen::ComputeThinV);
        const auto &s = svd.singularValues();
        double smax = s(0), smin = s(cols - 1);
        *rcond = smax > 0 ? smin / smax : 0;
        Eigen::VectorXd inv(cols);
        for (int i = 0; i < cols; i++) inv(i) = s(i) > 0 ? 1.0 / s(i) : 0.0;
        Eigen::Map<RowMat> p(pinv, cols, rows);
        p = svd.matrixV() * inv.asDiagonal() * svd.matrixU().transpose();
    } catch (const std::bad_alloc &) {
        return sh_error_set(SH_ENOMEM, "linalg: no memory for a %d x %d pseudo-inverse", rows, cols);
    }
    return SH_OK;
}
