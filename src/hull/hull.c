#include "stillheart/hull.h"

#include <math.h>
#include <stdlib.h>

/* Boundary tolerance: a marker lying exactly on the hull must keep its own pixel. */
#define HULL_EPS 1e-9

typedef struct {
    double x, y;
} vec2;

/* Up to this many points the scratch is on the stack (24 KB): the daemon computes the hull of
 * each frame's markers and natural landmarks, a few hundred, on the processing thread, which
 * allocates nothing. */
#define HULL_STACK_POINTS 512

static int less_xy(vec2 p, vec2 q)
{
    return p.x < q.x || (p.x == q.x && p.y < q.y);
}

static void sift(vec2 *a, int root, int n)
{
    for (;;) {
        int c = 2 * root + 1;
        if (c >= n) return;
        if (c + 1 < n && less_xy(a[c], a[c + 1])) c++;
        if (!less_xy(a[root], a[c])) return;
        vec2 t = a[root];
        a[root] = a[c], a[c] = t;
        root = c;
    }
}

/* Heapsort by x, then y: glibc's qsort allocates for arrays over 1 KB (64 points). */
static void sort_xy(vec2 *a, int n)
{
    for (int i = n / 2 - 1; i >= 0; i--) sift(a, i, n);
    for (int e = n - 1; e > 0; e--) {
        vec2 t = a[0];
        a[0] = a[e], a[e] = t;
        sift(a, 0, e);
    }
}

static double cross(vec2 o, vec2 a, vec2 b)
{
    return (a.x - o.x) * (b.y - o.y) - (a.y - o.y) * (b.x - o.x);
}

sh_status sh_hull_compute(const double *xy, int n, sh_hull *hull)
{
    if (!xy || !hull || n < 0) return sh_error_set(SH_EINVAL, "hull: no points");
    for (int i = 0; i < 2 * n; i++)
        if (!isfinite(xy[i])) return sh_error_set(SH_EINVAL, "hull: point %d is not finite", i / 2);
    if (n < 3) return sh_error_set(SH_EDEGENERATE, "hull: %d points, need at least 3", n);

    vec2 stack[3 * HULL_STACK_POINTS];
    vec2 *pts = n <= HULL_STACK_POINTS ? stack : malloc(sizeof(vec2) * (size_t)n * 3);
    if (!pts) return sh_error_set(SH_ENOMEM, "hull: out of memory");
    vec2 *chain = pts + n;
    for (int i = 0; i < n; i++) pts[i] = (vec2){xy[2 * i], xy[2 * i + 1]};
    sort_xy(pts, n);

    int k = 0;
    for (int i = 0; i < n; i++) { /* lower chain */
        while (k >= 2 && cross(chain[k - 2], chain[k - 1], pts[i]) <= 0) k--;
        chain[k++] = pts[i];
    }
    for (int i = n - 2, lower = k + 1; i >= 0; i--) { /* upper chain */
        while (k >= lower && cross(chain[k - 2], chain[k - 1], pts[i]) <= 0) k--;
        chain[k++] = pts[i];
    }
    k--; /* the last point repeats the first */

    sh_status st = SH_OK;
    if (k < 3) {
        st = sh_error_set(SH_EDEGENERATE, "hull: the points are collinear or coincide");
    } else if (k > SH_HULL_MAX_VERTICES) {
        st = sh_error_set(SH_ERANGE, "hull: %d vertices, at most %d", k, SH_HULL_MAX_VERTICES);
    } else {
        /* Monotone chain runs counter-clockwise in y-up axes, i.e. clockwise on screen; keep
         * the order as built (positive cross products), which the row scan does not depend on. */
        hull->count = k;
        hull->xmin = hull->ymin = INFINITY;
        hull->xmax = hull->ymax = -INFINITY;
        for (int i = 0; i < k; i++) {
            hull->x[i] = chain[i].x;
            hull->y[i] = chain[i].y;
            hull->xmin = fmin(hull->xmin, chain[i].x);
            hull->xmax = fmax(hull->xmax, chain[i].x);
            hull->ymin = fmin(hull->ymin, chain[i].y);
            hull->ymax = fmax(hull->ymax, chain[i].y);
        }
    }
    if (pts != stack) free(pts);
    return st;
}

int sh_hull_row(const sh_hull *hull, double y, double *x0, double *x1)
{
    if (y < hull->ymin - HULL_EPS || y > hull->ymax + HULL_EPS) return 0;
    double lo = INFINITY, hi = -INFINITY;
    for (int i = 0; i < hull->count; i++) {
        int j = (i + 1) % hull->count;
        double ya = hull->y[i], yb = hull->y[j], xa = hull->x[i], xb = hull->x[j];
        if ((y < fmin(ya, yb) - HULL_EPS) || (y > fmax(ya, yb) + HULL_EPS)) continue;
        if (fabs(yb - ya) < HULL_EPS) { /* horizontal edge: both ends lie on the line */
            lo = fmin(lo, fmin(xa, xb));
            hi = fmax(hi, fmax(xa, xb));
            continue;
        }
        double t = (y - ya) / (yb - ya);
        t = t < 0 ? 0 : (t > 1 ? 1 : t);
        double x = xa + t * (xb - xa);
        lo = fmin(lo, x);
        hi = fmax(hi, x);
    }
    if (!(lo <= hi)) return 0;
    *x0 = lo;
    *x1 = hi;
    return 1;
}

int sh_hull_contains(const sh_hull *hull, double x, double y)
{
    double x0, x1;
    return sh_hull_row(hull, y, &x0, &x1) && x >= x0 - HULL_EPS && x <= x1 + HULL_EPS;
}

int sh_hull_row_accepts(const sh_hull *hull, double y, double *lo, double *hi)
{
    double x0, x1;
    if (!sh_hull_row(hull, y, &x0, &x1)) return 0;
    *lo = x0 - HULL_EPS;
    *hi = x1 + HULL_EPS;
    return 1;
}

int sh_hull_plane_row(const sh_hull *hull, int py, int width, double scale, double offset_x,
                      double offset_y, int *first, int *last)
{
    double x0, x1;
    if (!sh_hull_row(hull, scale * py + offset_y, &x0, &x1)) return 0;
    double f = ceil((x0 - offset_x) / scale - HULL_EPS);
    double l = floor((x1 - offset_x) / scale + HULL_EPS);
    if (f < 0) f = 0;
    if (l > width - 1) l = width - 1;
    if (f > l) return 0;
    *first = (int)f;
    *last = (int)l;
    return 1;
}
