/* The grid over the hull on which the map of a smooth method is evaluated each update: its
 * basis rows (dense, separable or CSR), the map at its nodes, and the bound on the error of
 * interpolating the map bilinearly between them. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "warp_internal.h"

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

/* The second difference averages f'' over two cells; the largest |f''| inside a cell can exceed
 * the average at its corners. Measured on TPS, Gaussian, local RBF and B-spline maps of
 * non-affine motions (tests/unit/test_warp.c), the true error reaches 1.2 x the raw estimate;
 * 2 leaves a margin over that. */
#define ERROR_SAFETY 2.0

/* The dense rows' chunks (build_dense_rows): runs of DENSE_CHUNK nodes in the grid's order
 * (across node rows) whose terms lie side by side; long enough that each term's weights are a
 * stream of 4 KB for the prefetcher, short enough that their sums (2 x 8 bytes a node) stay in
 * the L1 cache while the terms stream past. */
#define DENSE_CHUNK 1024

/* The dense rows' order: the coarse level's nodes (even i and j) first, row by row, then the
 * rest row by row, so that each level's weights are read alone (a coarse pass reads a quarter of
 * them). The first of the rest in node row j: */
static inline size_t rest_start(const sh_warp_model *m, size_t j)
{
    const size_t cnx = ((size_t)m->bnx + 1) / 2, cny = ((size_t)m->bny + 1) / 2;
    return cnx * cny + (j + 1) / 2 * ((size_t)m->bnx - cnx) + j / 2 * (size_t)m->bnx;
}

static inline size_t dense_index(const sh_warp_model *m, size_t i, size_t j)
{
    if (!(i & 1) && !(j & 1)) return j / 2 * (((size_t)m->bnx + 1) / 2) + i / 2;
    return rest_start(m, j) + (j & 1 ? i : i / 2);
}

/* chunk c's nodes: DENSE_CHUNK but for the grid's last */
static inline size_t dense_width(const sh_warp_model *m, size_t c)
{
    const size_t nodes = (size_t)m->bnx * (size_t)m->bny;
    return nodes - c * DENSE_CHUNK < DENSE_CHUNK ? nodes - c * DENSE_CHUNK : DENSE_CHUNK;
}

void warp_grid_free(sh_warp_model *m)
{
    free(m->row_start);
    free(m->index);
    free(m->weight);
    if (m->map != m->bmap && m->map != m->cmap) free(m->map); /* a 3D view's own */
    free(m->bmap);
    free(m->cmap);
    m->bmap = m->cmap = NULL;
    free(m->curvature);
    free(m->sep_x);
    free(m->sep_y);
    free(m->sep_row);
    free(m->dense);
    free(m->dense_coef);
    free(m->dense_used);
    m->dense = NULL;
    m->dense_coef = NULL;
    m->dense_used = NULL;
    m->dense_terms = 0;
    m->row_start = m->index = NULL;
    m->weight = m->map = m->curvature = m->sep_x = m->sep_y = m->sep_row = NULL;
    m->sep_n = m->sep_slots = 0;
}

/* A Gaussian kernel's factors per node column and row (see sh_interp_kernel_factors); returns
 * 0 with nothing allocated for the other methods. */
static sh_status build_separable(sh_warp_model *m)
{
    const int n = m->n, h = m->h;
    m->sep_y = malloc(sizeof(double) * (size_t)m->ny * n);
    if (!m->sep_y) return sh_error_set(SH_ENOMEM, "warp: out of memory");
    if (sh_interp_kernel_factors(m->interp, 1, m->gy0, m->sep_y) != n) {
        free(m->sep_y);
        m->sep_y = NULL;
        return SH_OK;
    }
    const size_t pairs = ((size_t)m->nx + 1) / 2;
    m->sep_x = calloc(2 * pairs * (size_t)n, sizeof(double));
    m->sep_row = malloc(sizeof(double) * 4 * (size_t)n);
    double *f = malloc(sizeof(double) * (size_t)n);
    if (!m->sep_x || !m->sep_row || !f) {
        free(f);
        return sh_error_set(SH_ENOMEM, "warp: out of memory");
    }
    for (int j = 1; j < m->ny; j++)
        sh_interp_kernel_factors(m->interp, 1, m->gy0 + (double)j * h, m->sep_y + (size_t)j * n);
    for (int i = 0; i < m->nx; i++) { /* an odd grid's last pair keeps a zero column */
        sh_interp_kernel_factors(m->interp, 0, m->gx0 + (double)i * h, f);
        for (int k = 0; k < n; k++) m->sep_x[2 * ((size_t)(i / 2) * n + k) + i % 2] = f[k];
    }
    free(f);
    m->sep_n = n;
    m->sep_slots = 1;
    return SH_OK;
}

/* Rows that hold every coefficient in order (the dense RBFs: TPS) are kept as floats without
 * the CSR's indices: warp_grid_map streams the basis every update (nodes x (n + 3) terms, 10 MB
 * at 1080p for 150 points), and 4 bytes a term instead of 12 cut that traffic and the model's
 * memory to a third. A weight's rounding moves the map by far less than the grid's tolerance
 * (test_dense_rows_as_exact).
 * They are stored term by term in chunks of DENSE_CHUNK nodes (dense_width), the coarse level's
 * nodes first (dense_index):
 * an update through a subset of the points (the landmarks a frame accepts: about half of
 * them) has zero coefficients for the rest, and their weights are then never read, where a
 * node's whole row of terms would be. Returns 1 when the rows were stored so, 0 when they are
 * not dense (nothing kept), or an error. */
static int build_dense_rows(sh_warp_model *m, size_t nodes, int max_terms, int *row_index, double *row_weight)
{
    if (m->sep_n) return 0;
    for (size_t node = 0; node < nodes; node++) {
        size_t i = node % (size_t)m->nx, j = node / (size_t)m->nx;
        int k = sh_interp_basis(m->interp, m->gx0 + (double)i * m->h, m->gy0 + (double)j * m->h, row_index,
                                row_weight);
        if (k < 0) return k;
        int dense = k == max_terms;
        for (int t = 0; dense && t < k; t++) dense = row_index[t] == t;
        if (!dense) {
            free(m->dense);
            m->dense = NULL;
            return 0;
        }
        if (!m->dense && !(m->dense = malloc(sizeof(float) * nodes * (size_t)max_terms)))
            return sh_error_set(SH_ENOMEM, "warp: grid of %zu nodes does not fit in memory", nodes);
        const size_t at = dense_index(m, i, j), c = at / DENSE_CHUNK, width = dense_width(m, c);
        float *w = m->dense + c * DENSE_CHUNK * (size_t)max_terms + at % DENSE_CHUNK;
        for (int t = 0; t < k; t++) w[(size_t)t * width] = (float)row_weight[t];
    }
    const size_t coarse = (((size_t)m->bnx + 1) / 2) * (((size_t)m->bny + 1) / 2);
    if (!(m->dense_coef = malloc(sizeof(double) * 2 * (size_t)max_terms)) ||
        !(m->dense_used = malloc(sizeof(int) * (size_t)max_terms)) || !(m->cmap = malloc(sizeof(double) * 2 * coarse)))
        return sh_error_set(SH_ENOMEM, "warp: out of memory");
    m->dense_terms = max_terms;
    return 1;
}

sh_status warp_grid_build(sh_warp_model *m, int h)
{
    warp_grid_free(m);
    m->h = h;
    /* Every point's hull, not the last update's: a grid refined while a subset update showed a
     * smaller hull must still cover the next update through all of them. */
    const sh_hull *all = &m->hull_all;
    m->gx0 = (int)floor(all->xmin / h) * h;
    m->gy0 = (int)floor(all->ymin / h) * h;
    m->nx = ((int)ceil(all->xmax / h) * h - m->gx0) / h + 1;
    m->ny = ((int)ceil(all->ymax / h) * h - m->gy0) / h + 1;
    /* odd counts, so that the coarse level's every other node ends on the last */
    m->nx += !(m->nx & 1);
    m->ny += !(m->ny & 1);
    m->bh = h, m->bnx = m->nx, m->bny = m->ny;
    size_t nodes = (size_t)m->nx * (size_t)m->ny;
    sh_status st = build_separable(m);
    if (st != SH_OK) return st;
    int max_terms = sh_interp_max_terms(m->interp);
    m->map = m->bmap = malloc(sizeof(double) * 2 * nodes);
    m->curvature = malloc(sizeof(double) * 4 * nodes);
    int *row_index = malloc(sizeof(int) * (size_t)max_terms);
    double *row_weight = malloc(sizeof(double) * (size_t)max_terms);
    if (!m->map || !m->curvature || !row_index || !row_weight) {
        free(row_index);
        free(row_weight);
        return sh_error_set(SH_ENOMEM, "warp: grid of %zu nodes does not fit in memory", nodes);
    }
    int dense = build_dense_rows(m, nodes, max_terms, row_index, row_weight);
    if (dense) {
        free(row_index);
        free(row_weight);
        return dense < 0 ? (sh_status)dense : SH_OK;
    }
    /* separable: the CSR rows keep only the terms past the kernel's n */
    size_t cap = nodes * (size_t)(max_terms - m->sep_n) + 1;
    m->row_start = malloc(sizeof(int) * (nodes + 1));
    m->index = malloc(sizeof(int) * cap);
    m->weight = malloc(sizeof(double) * cap);
    if (!m->row_start || !m->index || !m->weight) {
        free(row_index);
        free(row_weight);
        return sh_error_set(SH_ENOMEM, "warp: grid of %zu nodes does not fit in memory", nodes);
    }
    size_t used = 0;
    for (int j = 0; j < m->ny; j++) {
        for (int i = 0; i < m->nx; i++) {
            size_t node = (size_t)j * m->nx + i;
            m->row_start[node] = (int)used;
            double x = m->gx0 + (double)i * h, y = m->gy0 + (double)j * h;
            if (!m->sep_n) {
                int k = sh_interp_basis(m->interp, x, y, m->index + used, m->weight + used);
                if (k < 0) {
                    free(row_index);
                    free(row_weight);
                    return (sh_status)k;
                }
                used += (size_t)k;
                continue;
            }
            int k = sh_interp_basis(m->interp, x, y, row_index, row_weight);
            for (int t = 0; t < k; t++) {
                if (row_index[t] < m->sep_n) continue;
                m->index[used] = row_index[t];
                m->weight[used++] = row_weight[t];
            }
        }
    }
    free(row_index);
    free(row_weight);
    m->row_start[nodes] = (int)used;
    return SH_OK;
}

/* The separable kernel part of grid row j's values, sum_k gx_k(x_i) (gy_k(y_j) c_k), into
 * out (x, y per node): the bracket once per row, then two node columns at a time (their
 * factors side by side in sep_x), so each factor pair is loaded once for x and y. */
static void separable_row(sh_warp_model *m, size_t j, double *out, int slot)
{
    const int n = m->sep_n;
    double *a = m->sep_row + 4 * (size_t)slot * n; /* per k: c_x gy, twice; c_y gy, twice */
    for (int k = 0; k < n; k++) {
        double g = m->sep_y[j * (size_t)n + k];
        a[4 * k] = a[4 * k + 1] = m->coef[2 * k] * g;
        a[4 * k + 2] = a[4 * k + 3] = m->coef[2 * k + 1] * g;
    }
    for (int i = 0; i < m->nx; i += 2) {
        const double *f = m->sep_x + 2 * (size_t)(i / 2) * n;
        double x[2], y[2]; /* columns i and i + 1 */
#if defined(__SSE2__)
        /* four chains to hide the adder's latency */
        __m128d sx = _mm_setzero_pd(), sy = _mm_setzero_pd(), tx = sx, ty = sx;
        int k = 0;
        for (; k + 2 <= n; k += 2) {
            __m128d g = _mm_loadu_pd(f + 2 * k), h = _mm_loadu_pd(f + 2 * k + 2);
            sx = _mm_add_pd(sx, _mm_mul_pd(g, _mm_loadu_pd(a + 4 * k)));
            sy = _mm_add_pd(sy, _mm_mul_pd(g, _mm_loadu_pd(a + 4 * k + 2)));
            tx = _mm_add_pd(tx, _mm_mul_pd(h, _mm_loadu_pd(a + 4 * k + 4)));
            ty = _mm_add_pd(ty, _mm_mul_pd(h, _mm_loadu_pd(a + 4 * k + 6)));
        }
        if (k < n) {
            __m128d g = _mm_loadu_pd(f + 2 * k);
            sx = _mm_add_pd(sx, _mm_mul_pd(g, _mm_loadu_pd(a + 4 * k)));
            sy = _mm_add_pd(sy, _mm_mul_pd(g, _mm_loadu_pd(a + 4 * k + 2)));
        }
        _mm_storeu_pd(x, _mm_add_pd(sx, tx));
        _mm_storeu_pd(y, _mm_add_pd(sy, ty));
#else
        x[0] = x[1] = y[0] = y[1] = 0;
        for (int k = 0; k < n; k++) {
            for (int c = 0; c < 2; c++) {
                x[c] += f[2 * k + c] * a[4 * k + c];
                y[c] += f[2 * k + c] * a[4 * k + 2 + c];
            }
        }
#endif
        out[2 * i] = x[0], out[2 * i + 1] = y[0];
        if (i + 1 < m->nx) out[2 * i + 2] = x[1], out[2 * i + 3] = y[1];
    }
}

/* count nodes' displacements from a chunk's weights w (term t's at w + t stride), x into ax and
 * y into ay: per node the terms' products added one after the other in the order of used, the
 * terms with zero coefficients left out (each would add w * 0, a zero, which leaves a sum as it
 * was: leaving them out keeps the bits). Four terms a pass, so that each node's sums are loaded
 * and stored once per four terms; the SIMD path does the same operations per node across its
 * lanes, so every path gives these bits. */
static void dense_chunk_portable(const float *restrict w, size_t stride, size_t count, const int *used,
                                 int nused, const double *restrict cx, const double *restrict cy,
                                 double *restrict ax, double *restrict ay)
{
    for (size_t i = 0; i < count; i++) ax[i] = ay[i] = 0;
    for (int u = 0; u < nused; u += 4) {
        const int q = nused - u < 4 ? nused - u : 4;
        for (size_t i = 0; i < count; i++) {
            double x = ax[i], y = ay[i];
            for (int l = 0; l < q; l++) {
                const double v = w[(size_t)used[u + l] * stride + i];
                x += v * cx[used[u + l]];
                y += v * cy[used[u + l]];
            }
            ax[i] = x, ay[i] = y;
        }
    }
}

#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#define GRID_AVX2 1

/* -1: not chosen yet (the first map chooses by the CPU); read and set atomically, as the grid's
 * rows may be mapped on several threads */
static int dense_level = -1;

int warp_grid_dense_path(int wanted)
{
    const int level = wanted >= 1 && __builtin_cpu_supports("avx2") ? 1 : 0;
    __atomic_store_n(&dense_level, level, __ATOMIC_RELAXED);
    return level;
}

/* dense_chunk_portable four nodes a register: a term's four weights widened to doubles, times
 * its coefficient broadcast. */
__attribute__((target("avx2"))) static void dense_chunk_avx2(const float *restrict w, size_t stride,
                                                             size_t count, const int *used, int nused,
                                                             const double *restrict cx,
                                                             const double *restrict cy, double *restrict ax,
                                                             double *restrict ay)
{
    const size_t v = count & ~(size_t)3;
    for (size_t i = 0; i < count; i++) ax[i] = ay[i] = 0;
    for (int u = 0; u < nused; u += 4) {
        const int q = nused - u < 4 ? nused - u : 4;
        const float *wt[4];
        __m256d c[4], d[4];
        for (int l = 0; l < 4; l++) {
            const int t = used[u + (l < q ? l : 0)];
            wt[l] = w + (size_t)t * stride;
            c[l] = _mm256_set1_pd(cx[t]), d[l] = _mm256_set1_pd(cy[t]);
        }
        for (size_t i = 0; i < v; i += 4) {
            __m256d x = _mm256_loadu_pd(ax + i), y = _mm256_loadu_pd(ay + i);
            for (int l = 0; l < q; l++) {
                const __m256d g = _mm256_cvtps_pd(_mm_loadu_ps(wt[l] + i));
                x = _mm256_add_pd(x, _mm256_mul_pd(g, c[l]));
                y = _mm256_add_pd(y, _mm256_mul_pd(g, d[l]));
            }
            _mm256_storeu_pd(ax + i, x), _mm256_storeu_pd(ay + i, y);
        }
        for (size_t i = v; i < count; i++)
            for (int l = 0; l < q; l++) {
                const double g = wt[l][i];
                ax[i] += g * cx[used[u + l]];
                ay[i] += g * cy[used[u + l]];
            }
    }
}
#else
int warp_grid_dense_path(int wanted)
{
    (void)wanted;
    return 0;
}
#endif

/* What warp_model_grid_rows makes: every node of its rows; the coarse level's rows; the rest of
 * its rows (the dense rows' passes, warp_grid_map). */
enum { GRID_PASS_ALL, GRID_PASS_COARSE, GRID_PASS_REST };

/* The dense rows' nodes s0..s1-1 in their order (dense_index), a chunk (or the part of one in the
 * range) at a time, with AVX2 where the CPU has it; node (i, j) is the first, the others follow
 * on the coarse level's nodes (coarse) or on the rest. Each goes into bmap, a coarse one into
 * cmap too. */
static void dense_nodes(const sh_warp_model *m, size_t s0, size_t s1, int coarse, size_t i, size_t j)
{
    const double *cx = m->dense_coef, *cy = cx + m->dense_terms;
    const size_t bnx = (size_t)m->bnx, cnx = (bnx + 1) / 2;
    double ax[DENSE_CHUNK], ay[DENSE_CHUNK];
#ifdef GRID_AVX2
    int level = __atomic_load_n(&dense_level, __ATOMIC_RELAXED);
    if (level < 0) level = warp_grid_dense_path(1);
#endif
    for (size_t k = s0; k < s1;) {
        const size_t c = k / DENSE_CHUNK, width = dense_width(m, c), off = k % DENSE_CHUNK;
        const size_t count = s1 - k < width - off ? s1 - k : width - off;
        const float *w = m->dense + c * DENSE_CHUNK * (size_t)m->dense_terms + off;
#ifdef GRID_AVX2
        if (level == 1) dense_chunk_avx2(w, width, count, m->dense_used, m->dense_nused, cx, cy, ax, ay);
        else
#endif
            dense_chunk_portable(w, width, count, m->dense_used, m->dense_nused, cx, cy, ax, ay);
        for (size_t e = 0; e < count; e++, k++) {
            double *b = m->bmap + 2 * (j * bnx + i);
            b[0] = m->gx0 + (double)i * m->bh + ax[e];
            b[1] = m->gy0 + (double)j * m->bh + ay[e];
            if (coarse) {
                double *cm = m->cmap + 2 * (j / 2 * cnx + i / 2);
                cm[0] = b[0], cm[1] = b[1];
                if ((i += 2) >= bnx) i = 0, j += 2;
            } else if ((i += j & 1 ? 1 : 2) >= bnx) {
                j++;
                i = j & 1 ? 0 : 1;
            }
        }
    }
}

void warp_model_grid_rows(sh_warp_model *m, int j0, int j1, int slot)
{
    if (m->dense) {
        const size_t cnx = ((size_t)m->bnx + 1) / 2, a = (size_t)j0, b = (size_t)j1;
        if (m->pass == GRID_PASS_COARSE) { /* rows of the coarse level */
            dense_nodes(m, a * cnx, b * cnx, 1, 0, 2 * a);
            return;
        }
        if (m->pass == GRID_PASS_ALL) dense_nodes(m, (a + 1) / 2 * cnx, (b + 1) / 2 * cnx, 1, 0, (a + 1) / 2 * 2);
        if (a < b) dense_nodes(m, rest_start(m, a), rest_start(m, b), 0, a & 1 ? 0 : 1, a);
        return;
    }
    for (size_t node = (size_t)j0 * (size_t)m->nx, j = (size_t)j0; j < (size_t)j1; j++) {
        double *row = m->map + 2 * node;
        if (m->sep_n) separable_row(m, j, row, slot);
        for (size_t i = 0; i < (size_t)m->nx; i++, node++) {
            double xy[2];
            const int *index = m->index + m->row_start[node];
            const double *weight = m->weight + m->row_start[node];
            int terms = m->row_start[node + 1] - m->row_start[node];
#if defined(__SSE2__)
            /* x and y side by side in one register; two chains to hide the adder's latency */
            __m128d even = _mm_setzero_pd(), odd = _mm_setzero_pd();
            int k = 0;
            for (; k + 2 <= terms; k += 2) {
                even = _mm_add_pd(even, _mm_mul_pd(_mm_set1_pd(weight[k]),
                                                   _mm_loadu_pd(m->coef + 2 * (size_t)index[k])));
                odd = _mm_add_pd(odd, _mm_mul_pd(_mm_set1_pd(weight[k + 1]),
                                                 _mm_loadu_pd(m->coef + 2 * (size_t)index[k + 1])));
            }
            if (k < terms)
                even = _mm_add_pd(even, _mm_mul_pd(_mm_set1_pd(weight[k]),
                                                   _mm_loadu_pd(m->coef + 2 * (size_t)index[k])));
            _mm_storeu_pd(xy, _mm_add_pd(even, odd));
#else
            xy[0] = xy[1] = 0;
            for (int k = 0; k < terms; k++) {
                xy[0] += weight[k] * m->coef[2 * (size_t)index[k]];
                xy[1] += weight[k] * m->coef[2 * (size_t)index[k] + 1];
            }
#endif
            double sep[2] = {0, 0};
            if (m->sep_n) sep[0] = row[2 * i], sep[1] = row[2 * i + 1];
            m->map[2 * node] = m->gx0 + (double)i * m->h + (xy[0] + sep[0]);
            m->map[2 * node + 1] = m->gy0 + (double)j * m->h + (xy[1] + sep[1]);
        }
    }
}

/* The map in use (fill, bound, spacing): the grid made, or its coarse level (dense rows). */
static void use_level(sh_warp_model *m, int coarse)
{
    m->h = m->bh << coarse;
    m->nx = coarse ? (m->bnx + 1) / 2 : m->bnx;
    m->ny = coarse ? (m->bny + 1) / 2 : m->bny;
    m->map = coarse ? m->cmap : m->bmap;
}

/* Rows of the grid's map made by the pass (on this thread when map is NULL) */
static void map_rows(sh_warp_model *m, warp_grid_fn map, void *ctx, int pass, int rows)
{
    m->pass = pass;
    if (map) map(ctx, m, rows);
    else warp_model_grid_rows(m, 0, rows, 0);
}

/* The grid's map from the last fit: the dense rows' coefficients apart, then every node row,
 * on this thread or by map over `slots` threads (each with its own separable scratch); or, for
 * the dense rows of a grid refined below opts.coarsest_spacing, the coarse level first (a
 * quarter of the nodes), the rest only when its bound is over max_error. */
sh_status warp_grid_map(sh_warp_model *m, warp_grid_fn map, void *ctx, int slots, int coarse_ok)
{
    double *cx = m->dense_coef, *cy = cx + m->dense_terms;
    m->dense_nused = 0;
    for (int k = 0; k < m->dense_terms; k++) {
        cx[k] = m->coef[2 * k], cy[k] = m->coef[2 * k + 1];
        if (cx[k] != 0 || cy[k] != 0) m->dense_used[m->dense_nused++] = k;
    }
    if (map && m->sep_n && slots > m->sep_slots) {
        double *a = realloc(m->sep_row, sizeof(double) * 4 * (size_t)m->sep_n * (size_t)slots);
        if (!a) return sh_error_set(SH_ENOMEM, "warp: out of memory");
        m->sep_row = a;
        m->sep_slots = slots;
    }
    use_level(m, 0);
    const int cnx = (m->bnx + 1) / 2, cny = (m->bny + 1) / 2;
    int pass = GRID_PASS_ALL;
    if (m->dense && coarse_ok && 2 * m->bh <= m->opts.coarsest_spacing && cnx >= 3 && cny >= 3) {
        map_rows(m, map, ctx, GRID_PASS_COARSE, cny);
        use_level(m, 1);
        m->error_bound = warp_grid_error_bound(m);
        if (m->error_bound <= m->opts.max_error) return SH_OK;
        use_level(m, 0);
        pass = GRID_PASS_REST;
    }
    map_rows(m, map, ctx, pass, m->bny);
    m->error_bound = warp_grid_error_bound(m);
    return SH_OK;
}

#if !defined(__SSE2__) /* the SSE2 path takes _mm_max_pd; clang warns of an unused inline */
static inline double max2(double a, double b)
{
    return a > b ? a : b; /* maxsd: fmax is a libm call, and the values are never NaN here */
}
#endif

/* Per node, |second difference| of x and y along both axes (nodes on the grid's edge take
 * their inner neighbour's), then per cell the bilinear interpolation error bound
 * h^2/8 (|f_xx| + |f_yy|) with each second derivative's largest value at the cell's corners.
 * x and y sit side by side in the map, so each step works on both at once (SSE2: one register). */
double warp_grid_error_bound(sh_warp_model *m)
{
    if (m->h == 1) return 0; /* every pixel is a node */
    if (m->nx < 3 || m->ny < 3) return INFINITY;
    const int nx = m->nx, ny = m->ny;
    const ptrdiff_t row = 2 * (ptrdiff_t)nx;
    double *curv = m->curvature; /* per node: |dxx x|, |dxx y|, |dyy x|, |dyy y| */
    for (int j = 0; j < ny; j++) {
        int jc = j == 0 ? 1 : (j == ny - 1 ? ny - 2 : j);
        for (int i = 0; i < nx; i++) {
            int ic = i == 0 ? 1 : (i == nx - 1 ? nx - 2 : i);
            const double *mx = m->map + 2 * ((size_t)j * nx + ic);
            const double *my = m->map + 2 * ((size_t)jc * nx + i);
            double *c = curv + 4 * ((size_t)j * nx + i);
#if defined(__SSE2__)
            const __m128d two = _mm_set1_pd(2.0), sign = _mm_set1_pd(-0.0);
            __m128d dxx = _mm_add_pd(_mm_sub_pd(_mm_loadu_pd(mx - 2), _mm_mul_pd(two, _mm_loadu_pd(mx))),
                                     _mm_loadu_pd(mx + 2));
            __m128d dyy = _mm_add_pd(_mm_sub_pd(_mm_loadu_pd(my - row), _mm_mul_pd(two, _mm_loadu_pd(my))),
                                     _mm_loadu_pd(my + row));
            _mm_storeu_pd(c, _mm_andnot_pd(sign, dxx));
            _mm_storeu_pd(c + 2, _mm_andnot_pd(sign, dyy));
#else
            c[0] = fabs(mx[-2] - 2 * mx[0] + mx[2]);
            c[1] = fabs(mx[-1] - 2 * mx[1] + mx[3]);
            c[2] = fabs(my[-row] - 2 * my[0] + my[row]);
            c[3] = fabs(my[1 - row] - 2 * my[1] + my[row + 1]);
#endif
        }
    }
    double worst = 0;
#if defined(__SSE2__)
    __m128d worst2 = _mm_setzero_pd();
#endif
    for (int j = 0; j + 1 < ny; j++) {
        for (int i = 0; i + 1 < nx; i++) {
            const double *a = curv + 4 * ((size_t)j * nx + i), *b = a + 4, *c = a + 4 * nx,
                         *d = c + 4;
#if defined(__SSE2__)
            __m128d exx = _mm_max_pd(_mm_max_pd(_mm_loadu_pd(a), _mm_loadu_pd(b)),
                                     _mm_max_pd(_mm_loadu_pd(c), _mm_loadu_pd(d)));
            __m128d eyy = _mm_max_pd(_mm_max_pd(_mm_loadu_pd(a + 2), _mm_loadu_pd(b + 2)),
                                     _mm_max_pd(_mm_loadu_pd(c + 2), _mm_loadu_pd(d + 2)));
            __m128d e = _mm_add_pd(exx, eyy), sq = _mm_mul_pd(e, e); /* ex, ey; squared */
            worst2 = _mm_max_pd(worst2, _mm_add_sd(sq, _mm_unpackhi_pd(sq, sq)));
#else
            double e[4];
            for (int k = 0; k < 4; k++) e[k] = max2(max2(a[k], b[k]), max2(c[k], d[k]));
            double ex = e[0] + e[2], ey = e[1] + e[3];
            worst = max2(worst, ex * ex + ey * ey);
#endif
        }
    }
#if defined(__SSE2__)
    worst = _mm_cvtsd_f64(worst2);
#endif
    return ERROR_SAFETY / 8 * sqrt(worst);
}
