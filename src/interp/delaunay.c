/* The Delaunay triangulation of a point set without allocating (sh_interp_delaunay), and the
 * canonical form of a triangle list that pwlinear's qhull triangles share with it.
 *
 * Why by hand when qhull does it: the daemon's pwlinear with natural landmarks needs the
 * triangulation of each frame's accepted points, a new set every frame on the processing thread,
 * which allocates nothing (DESIGN.md); qhull allocates. A few hundred points at most, so the
 * simplest robust construction serves: a sweep in (x, y) order fanning each point to the hull
 * edges it sees (any triangulation of the hull), then Lawson's edge flips until every interior
 * edge is locally Delaunay, which for points in general position is the Delaunay triangulation,
 * qhull's (tests/unit/test_interp.c compares them). O(n^2) at worst; 0.1 ms for 200 points. */
#include "interp_internal.h"

#include <math.h>
#include <stdint.h>
#include <string.h>

/* Twice the signed area of (a, b, c): > 0 when c lies left of a -> b in (x, y). */
static double orient(const double *a, const double *b, const double *c)
{
    return (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]);
}

/* > 0 when d lies inside the circle through a, b, c (orient(a, b, c) > 0) beyond the rounding
 * of the determinant (a relative bound, generous against Shewchuk's 1e-15: nearly cocircular
 * quads are left as they are rather than flipped back and forth). */
static int incircle(const double *a, const double *b, const double *c, const double *d)
{
    double adx = a[0] - d[0], ady = a[1] - d[1], bdx = b[0] - d[0], bdy = b[1] - d[1];
    double cdx = c[0] - d[0], cdy = c[1] - d[1];
    double al = adx * adx + ady * ady, bl = bdx * bdx + bdy * bdy, cl = cdx * cdx + cdy * cdy;
    double det = al * (bdx * cdy - cdx * bdy) + bl * (cdx * ady - adx * cdy) + cl * (adx * bdy - bdx * ady);
    double perm = al * (fabs(bdx * cdy) + fabs(cdx * bdy)) + bl * (fabs(cdx * ady) + fabs(adx * cdy)) +
                  cl * (fabs(adx * bdy) + fabs(bdx * ady));
    return det > 1e-12 * perm;
}

typedef int (*less_fn)(const void *ctx, int i, int j);

static void sift(int *a, int root, int n, less_fn less, const void *ctx)
{
    for (;;) {
        int c = 2 * root + 1;
        if (c >= n) return;
        if (c + 1 < n && less(ctx, a[c], a[c + 1])) c++;
        if (!less(ctx, a[root], a[c])) return;
        int t = a[root];
        a[root] = a[c], a[c] = t;
        root = c;
    }
}

/* Heapsort: qsort may allocate (glibc's merge sort for arrays over 1 KB). */
static void heap_sort(int *a, int n, less_fn less, const void *ctx)
{
    for (int i = n / 2 - 1; i >= 0; i--) sift(a, i, n, less, ctx);
    for (int e = n - 1; e > 0; e--) {
        int t = a[0];
        a[0] = a[e], a[e] = t;
        sift(a, 0, e, less, ctx);
    }
}

static int point_less(const void *ctx, int i, int j)
{
    const double *p = ctx;
    return p[2 * i] < p[2 * j] || (p[2 * i] == p[2 * j] && p[2 * i + 1] < p[2 * j + 1]);
}

typedef struct {
    const double *xy;
    const int *tri;
} tri_ctx;

/* Triangles by their first two vertices' positions, x then y (a canonical triangle is fixed by
 * them: two with the same first edge and positive area would overlap). */
static int tri_less(const void *ctx, int s, int t)
{
    const tri_ctx *c = ctx;
    for (int k = 0; k < 2; k++) {
        const double *p = c->xy + 2 * c->tri[3 * s + k], *q = c->xy + 2 * c->tri[3 * t + k];
        if (p[0] != q[0]) return p[0] < q[0];
        if (p[1] != q[1]) return p[1] < q[1];
    }
    return 0;
}

/* Edges (3 t + k: triangle t's edge opposite its vertex k) by their two vertices, unordered. */
static uint64_t edge_key(const int *tri, int e)
{
    int t = e / 3, k = e % 3;
    uint32_t a = (uint32_t)tri[3 * t + (k + 1) % 3], b = (uint32_t)tri[3 * t + (k + 2) % 3];
    return a < b ? (uint64_t)a << 32 | b : (uint64_t)b << 32 | a;
}

static int edge_less(const void *ctx, int e, int f)
{
    return edge_key(ctx, e) < edge_key(ctx, f);
}

size_t sh_interp_delaunay_work_size(int n)
{
    /* order, hull next and prev (n each); neighbours, an edge list and the sort's triangle
     * order (3 per triangle, 2n triangles at most) */
    return n < 3 ? 0 : sizeof(int) * (3 * (size_t)n + 3 * 6 * (size_t)n);
}

int sh_interp_triangles_canonical(const double *xy, int *tri, int ntri, int *scratch)
{
    double x0 = INFINITY, y0 = INFINITY, x1 = -INFINITY, y1 = -INFINITY;
    for (int t = 0; t < 3 * ntri; t++) {
        const double *p = xy + 2 * tri[t];
        x0 = fmin(x0, p[0]), x1 = fmax(x1, p[0]), y0 = fmin(y0, p[1]), y1 = fmax(y1, p[1]);
    }
    double extent = fmax(x1 - x0, y1 - y0);
    int kept = 0;
    for (int t = 0; t < ntri; t++) {
        int v[3] = {tri[3 * t], tri[3 * t + 1], tri[3 * t + 2]};
        double area = orient(xy + 2 * v[0], xy + 2 * v[1], xy + 2 * v[2]);
        /* slivers of (near) zero area between (nearly) collinear or cocircular points cover
         * nothing, and their barycentric map would divide by ~0 */
        if (fabs(area) <= 1e-12 * extent * extent) continue;
        if (area < 0) {
            int s = v[1];
            v[1] = v[2], v[2] = s;
        }
        int f = 0;
        for (int k = 1; k < 3; k++)
            if (point_less(xy, v[k], v[f])) f = k;
        for (int k = 0; k < 3; k++) tri[3 * kept + k] = v[(f + k) % 3];
        kept++;
    }
    tri_ctx c = {xy, tri};
    for (int t = 0; t < kept; t++) scratch[t] = t;
    heap_sort(scratch, kept, tri_less, &c);
    /* apply the permutation in place, cycle by cycle (scratch[t]: the old index of new t) */
    for (int t = 0; t < kept; t++) {
        if (scratch[t] < 0) continue;
        int v[3] = {tri[3 * t], tri[3 * t + 1], tri[3 * t + 2]};
        int cur = t;
        for (;;) {
            int from = scratch[cur];
            scratch[cur] = -1;
            if (from == t) {
                memcpy(tri + 3 * cur, v, sizeof v);
                break;
            }
            memcpy(tri + 3 * cur, tri + 3 * from, sizeof v);
            cur = from;
        }
    }
    return kept;
}

/* Any triangulation of the points' hull: points in (x, y) order, each outside the hull of the
 * ones before (it is their lexicographic maximum), fanned to every hull edge it sees. The hull is
 * a ring (next, prev) in counterclockwise order, that is with orient > 0 inside. Returns the
 * triangle count (at most 2n: tri's room), or -1 when every point is collinear or rounding
 * breaks the hull's convexity. */
static int sweep(const double *xy, int n, int *order, int *next, int *prev, int *tri)
{
    for (int i = 0; i < n; i++) order[i] = i;
    heap_sort(order, n, point_less, xy);
    const double *p0 = xy + 2 * order[0], *p1 = xy + 2 * order[1];
    int k = 2;
    while (k < n && orient(p0, p1, xy + 2 * order[k]) == 0) k++;
    if (k == n) return -1;
    /* the collinear run order[0..k-1] (in order along its line) and the first point off it */
    int c = order[k], nt = 0;
    int left = orient(p0, p1, xy + 2 * c) > 0;
    for (int j = 0; j + 1 < k; j++) {
        int a = order[j], b = order[j + 1];
        tri[3 * nt] = left ? a : b, tri[3 * nt + 1] = left ? b : a, tri[3 * nt + 2] = c;
        nt++;
        if (left) next[a] = b, prev[b] = a;
        else next[b] = a, prev[a] = b;
    }
    int first = order[0], last = order[k - 1];
    if (left) next[last] = c, prev[c] = last, next[c] = first, prev[first] = c;
    else next[first] = c, prev[c] = first, next[c] = last, prev[last] = c;
    int s = c;
    for (int i = k + 1; i < n; i++) {
        int p = order[i];
        const double *pp = xy + 2 * p;
        /* s, the point before, is on the hull and nearest in order: the edges p sees form one
         * chain through it */
        int u = s, w = s, hull = i; /* the hull has at most i vertices */
        while (orient(xy + 2 * w, xy + 2 * next[w], pp) < 0 && hull-- > 0) {
            if (nt >= 2 * n) return -1;
            tri[3 * nt] = w, tri[3 * nt + 1] = p, tri[3 * nt + 2] = next[w];
            nt++;
            w = next[w];
        }
        while (orient(xy + 2 * prev[u], xy + 2 * u, pp) < 0 && hull-- > 0) {
            if (nt >= 2 * n) return -1;
            tri[3 * nt] = prev[u], tri[3 * nt + 1] = p, tri[3 * nt + 2] = u;
            nt++;
            u = prev[u];
        }
        /* sees no edge, or (rounding on a nearly collinear hull) every edge: neither happens
         * for distinct points in exact arithmetic; refused rather than looped on */
        if (u == w || hull < 0) return -1;
        next[u] = p, prev[p] = u, next[p] = w, prev[w] = p;
        s = p;
    }
    return nt;
}

/* nb[3 t + k]: the triangle across t's edge opposite vertex k, -1 on the hull. */
static void link(const int *tri, int nt, int *nb, int *edges)
{
    for (int e = 0; e < 3 * nt; e++) edges[e] = e, nb[e] = -1;
    heap_sort(edges, 3 * nt, edge_less, tri);
    for (int i = 0; i + 1 < 3 * nt; i++) {
        int e = edges[i], f = edges[i + 1];
        if (edge_key(tri, e) != edge_key(tri, f)) continue;
        nb[e] = f / 3, nb[f] = e / 3;
        i++;
    }
}

static int find_side(const int *nb, int t, int u)
{
    for (int k = 0; k < 3; k++)
        if (nb[3 * t + k] == u) return k;
    return -1;
}

/* Lawson's flips: each interior edge whose opposite vertex lies inside the circle of its triangle
 * is replaced by the quad's other diagonal, until none is left. Returns 0 when it does not settle
 * within a bound no exact run exceeds. */
static int flip_all(const double *xy, int *tri, int *nb, int nt, int n)
{
    long budget = (long)n * n + 100;
    for (int flipped = 1; flipped;) {
        flipped = 0;
        for (int t = 0; t < nt; t++) {
            for (int k = 0; k < 3; k++) {
                int u = nb[3 * t + k];
                if (u < 0) continue;
                int j = find_side(nb, u, t);
                int a = tri[3 * t + k], p = tri[3 * t + (k + 1) % 3], q = tri[3 * t + (k + 2) % 3];
                int d = tri[3 * u + j];
                const double *A = xy + 2 * a, *P = xy + 2 * p, *Q = xy + 2 * q, *D = xy + 2 * d;
                if (!incircle(A, P, Q, D) || orient(A, P, D) <= 0 || orient(A, D, Q) <= 0) continue;
                if (--budget < 0) return 0;
                /* t = (a, p, q), u = (d, q, p) become t = (a, p, d), u = (a, d, q) */
                int n_ap = nb[3 * t + (k + 2) % 3], n_qa = nb[3 * t + (k + 1) % 3];
                /* u shares the edge the other way round: it is (d, q, p) from d */
                int n_pd = nb[3 * u + (j + 1) % 3], n_dq = nb[3 * u + (j + 2) % 3];
                tri[3 * t] = a, tri[3 * t + 1] = p, tri[3 * t + 2] = d;
                nb[3 * t] = n_pd, nb[3 * t + 1] = u, nb[3 * t + 2] = n_ap;
                tri[3 * u] = a, tri[3 * u + 1] = d, tri[3 * u + 2] = q;
                nb[3 * u] = n_dq, nb[3 * u + 1] = n_qa, nb[3 * u + 2] = t;
                if (n_pd >= 0) nb[3 * n_pd + find_side(nb, n_pd, u)] = t;
                if (n_qa >= 0) nb[3 * n_qa + find_side(nb, n_qa, t)] = u;
                flipped = 1;
                k = 3; /* t has changed: on to the next triangle */
            }
        }
    }
    return 1;
}

sh_status sh_interp_delaunay(const double *xy, int n, void *work, int *tri, int *ntri)
{
    *ntri = 0;
    if (n < 3) return sh_error_set(SH_EDEGENERATE, "delaunay: %d points, need 3", n);
    int *order = work, *next = order + n, *prev = next + n, *nb = prev + n, *edges = nb + 6 * (size_t)n,
        *scratch = edges + 6 * (size_t)n;
    int nt = sweep(xy, n, order, next, prev, tri);
    if (nt < 0)
        return sh_error_set(SH_EDEGENERATE, "delaunay: the %d points are collinear or coincide: no triangulation", n);
    link(tri, nt, nb, edges);
    if (!flip_all(xy, tri, nb, nt, n))
        return sh_error_set(SH_EDEGENERATE, "delaunay: the flips of %d points did not settle", n);
    *ntri = sh_interp_triangles_canonical(xy, tri, nt, scratch);
    return SH_OK;
}
