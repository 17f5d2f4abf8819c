/* Piecewise linear interpolation on the Delaunay triangles of the reference points (libqhull_r,
 * the same options as SciPy's Delaunay, so the triangulation matches LinearNDInterpolator's).
 * Point location goes through a bucket grid of triangles: the warp asks for tens of thousands of
 * basis rows per reference. */
#include "interp_internal.h"

#include <libqhull_r/qhull_ra.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* Barycentric tolerance: points on the hull boundary (up to rounding) count as inside. */
#define BARY_EPS 1e-9

typedef struct {
    int ntri;
    int *tri;     /* 3 * ntri, positive signed area */
    double *bary; /* 6 per triangle: x0, y0 and the rows of the inverse edge matrix */
    sh_bucket_grid grid;
} pwl_impl;

static void pwl_destroy(void *p)
{
    pwl_impl *w = p;
    if (!w) return;
    free(w->tri);
    free(w->bary);
    sh_bucket_grid_free(&w->grid);
    free(w);
}

static sh_status pwl_fit(const sh_interp *it, const double *values, int dim, double *coef)
{
    memcpy(coef, values, sizeof(double) * (size_t)it->n * (size_t)dim);
    return SH_OK;
}

static int pwl_basis(const sh_interp *it, double x, double y, int *index, double *weight)
{
    const pwl_impl *w = it->impl;
    const sh_bucket_grid *g = &w->grid;
    int ci = sh_bucket_coord(x, g->x0, g->inv_cell, g->nx);
    int cj = sh_bucket_coord(y, g->y0, g->inv_cell, g->ny);
    if (ci < 0 || cj < 0 || ci >= g->nx || cj >= g->ny) return 0;
    int c = cj * g->nx + ci;
    /* Near an edge several triangles pass the tolerant test: take the one the point is deepest
     * in, so interior points never get extrapolated weights. */
    int best = -1;
    double best_min = -BARY_EPS, l[3] = {0, 0, 0};
    for (int s = g->start[c]; s < g->start[c + 1]; s++) {
        int t = g->items[s];
        const double *b = w->bary + 6 * t;
        double dx = x - b[0], dy = y - b[1];
        double l1 = b[2] * dx + b[3] * dy, l2 = b[4] * dx + b[5] * dy, l0 = 1.0 - l1 - l2;
        double mn = fmin(l0, fmin(l1, l2));
        if (mn >= best_min) {
            best = t, best_min = mn;
            l[0] = l0, l[1] = l1, l[2] = l2;
            if (mn >= 0) break;
        }
    }
    if (best < 0) return 0;
    for (int k = 0; k < 3; k++) {
        index[k] = w->tri[3 * best + k];
        weight[k] = l[k];
    }
    return 3;
}

static const sh_interp_ops pwl_ops = {pwl_fit, pwl_basis, NULL, pwl_destroy, NULL, NULL};

/* Runs qhull; on success *tri holds *ntri triangles (vertex triples, any orientation). */
static sh_status delaunay(const double *xy, int n, int **tri, int *ntri)
{
    char flags[] = "qhull d Qt Qbb Qc Qz Q12";
    coordT *pts = malloc(sizeof(coordT) * 2 * (size_t)n);
    char *msg = NULL;
    size_t msglen = 0;
    /* qhull reports into a memory stream: library code never prints, the message goes to
     * sh_error_set. */
    FILE *err = open_memstream(&msg, &msglen);
    if (!pts || !err) {
        free(pts);
        if (err) fclose(err);
        free(msg);
        return sh_error_set(SH_ENOMEM, "interp pwlinear: out of memory");
    }
    for (int i = 0; i < 2 * n; i++) pts[i] = xy[i];
    qhT qh_qh;
    qhT *qh = &qh_qh;
    qh_zero(qh, err);
    int exitcode = qh_new_qhull(qh, 2, n, pts, False, flags, NULL, err);
    sh_status st = SH_OK;
    *tri = NULL;
    *ntri = 0;
    if (exitcode) {
        fflush(err);
        /* First line of qhull's report is the reason; the rest is diagnostics. */
        char first[200] = "";
        if (msg) {
            size_t k = strcspn(msg, "\n");
            snprintf(first, sizeof first, "%.*s", (int)(k < 199 ? k : 199), msg);
        }
        st = sh_error_set(SH_EDEGENERATE, "interp pwlinear: Delaunay triangulation failed: %s",
                          first);
    } else {
        facetT *facet;
        vertexT *vertex, **vertexp;
        int count = 0;
        FORALLfacets if (!facet->upperdelaunay) count++;
        *tri = malloc(sizeof(int) * 3 * (size_t)(count > 0 ? count : 1));
        if (!*tri) {
            st = sh_error_set(SH_ENOMEM, "interp pwlinear: out of memory");
        } else {
            FORALLfacets {
                if (facet->upperdelaunay) continue;
                int k = 0, v[3] = {-1, -1, -1};
                FOREACHvertex_(facet->vertices) {
                    if (k < 3) v[k] = qh_pointid(qh, vertex->point);
                    k++;
                }
                if (k != 3 || v[0] < 0 || v[0] >= n || v[1] < 0 || v[1] >= n || v[2] < 0 || v[2] >= n)
                    continue;
                memcpy(*tri + 3 * *ntri, v, sizeof v);
                (*ntri)++;
            }
        }
    }
    int curlong, totlong;
    qh_freeqhull(qh, !qh_ALL);
    qh_memfreeshort(qh, &curlong, &totlong);
    fclose(err);
    free(msg);
    free(pts);
    return st;
}

static sh_status build(sh_interp *it, pwl_impl *w)
{
    int n = it->n;
    const double *p = it->ref;
    int *raw, nraw;
    sh_status st = delaunay(p, n, &raw, &nraw);
    if (st != SH_OK) return st;
    w->tri = malloc(sizeof(int) * 3 * (size_t)(nraw > 0 ? nraw : 1));
    w->bary = malloc(sizeof(double) * 6 * (size_t)(nraw > 0 ? nraw : 1));
    double *boxes = malloc(sizeof(double) * 4 * (size_t)(nraw > 0 ? nraw : 1));
    char *used = calloc((size_t)n, 1);
    int *scratch = malloc(sizeof(int) * (size_t)(nraw > 0 ? nraw : 1));
    if (!w->tri || !w->bary || !boxes || !used || !scratch) {
        st = sh_error_set(SH_ENOMEM, "interp pwlinear: out of memory");
        goto done;
    }
    /* The canonical form (positive area, slivers out, an order of positions, not of qhull's
     * facets): a warp through these triangles is then bit for bit the one through
     * sh_interp_delaunay's of the same points in another order (the daemon's landmarks). */
    nraw = sh_interp_triangles_canonical(p, raw, nraw, scratch);
    double x0 = p[0], y0 = p[1], x1 = p[0], y1 = p[1];
    for (int i = 1; i < n; i++) {
        x0 = fmin(x0, p[2 * i]), x1 = fmax(x1, p[2 * i]);
        y0 = fmin(y0, p[2 * i + 1]), y1 = fmax(y1, p[2 * i + 1]);
    }
    double extent = fmax(x1 - x0, y1 - y0);
    for (int t = 0; t < nraw; t++) {
        int v[3] = {raw[3 * t], raw[3 * t + 1], raw[3 * t + 2]};
        const double *a = p + 2 * v[0], *b = p + 2 * v[1], *c = p + 2 * v[2];
        double area = (b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1]);
        int k = w->ntri++;
        memcpy(w->tri + 3 * k, v, sizeof v);
        double *m = w->bary + 6 * k;
        m[0] = a[0], m[1] = a[1];
        m[2] = (c[1] - a[1]) / area, m[3] = -(c[0] - a[0]) / area;
        m[4] = -(b[1] - a[1]) / area, m[5] = (b[0] - a[0]) / area;
        double *bx = boxes + 4 * k;
        double pad = 1e-7 * extent;
        bx[0] = fmin(a[0], fmin(b[0], c[0])) - pad, bx[2] = fmax(a[0], fmax(b[0], c[0])) + pad;
        bx[1] = fmin(a[1], fmin(b[1], c[1])) - pad, bx[3] = fmax(a[1], fmax(b[1], c[1])) + pad;
        used[v[0]] = used[v[1]] = used[v[2]] = 1;
    }
    if (w->ntri == 0) {
        st = sh_error_set(SH_EDEGENERATE, "interp pwlinear: the reference points span no triangle");
        goto done;
    }
    for (int i = 0; i < n; i++)
        if (!used[i]) {
            st = sh_error_set(SH_EDEGENERATE,
                              "interp pwlinear: reference point %d (%g, %g) is in no triangle: it "
                              "nearly coincides with another", i, p[2 * i], p[2 * i + 1]);
            goto done;
        }
    /* About one triangle per cell on average keeps location O(1). */
    double pad = 1e-6 * extent;
    double gx0 = x0 - pad, gy0 = y0 - pad, wx = x1 - x0 + 2 * pad, wy = y1 - y0 + 2 * pad;
    double cell = sqrt(wx * wy / w->ntri);
    if (!(cell > 0)) cell = extent;
    int nx = (int)ceil(wx / cell), ny = (int)ceil(wy / cell);
    if (nx < 1) nx = 1;
    if (ny < 1) ny = 1;
    if (nx > 1024) nx = 1024;
    if (ny > 1024) ny = 1024;
    cell = fmax(wx / nx, wy / ny);
    st = sh_bucket_grid_build(&w->grid, boxes, w->ntri, gx0, gy0, cell, nx, ny);
done:
    free(raw);
    free(boxes);
    free(used);
    free(scratch);
    return st;
}

sh_status sh_interp_pwlinear_init(sh_interp *it)
{
    sh_status st = sh_interp_check_distinct(it->ref, it->n, "pwlinear");
    if (st != SH_OK) return st;
    if (sh_interp_collinear(it->ref, it->n))
        return sh_error_set(SH_EDEGENERATE,
                            "interp pwlinear: the %d reference points are collinear: no triangle",
                            it->n);
    pwl_impl *w = calloc(1, sizeof *w);
    if (!w) return sh_error_set(SH_ENOMEM, "interp pwlinear: out of memory");
    st = build(it, w);
    if (st != SH_OK) {
        pwl_destroy(w);
        return st;
    }
    it->impl = w;
    it->ops = &pwl_ops;
    it->num_coefs = it->n;
    it->max_terms = 3;
    it->triangles = w->tri;
    it->ntri = w->ntri;
    return SH_OK;
}
