/* A view of the stabilized surface: the per-reference ray casting on a grid over the output
 * image, the per-frame projection of the moved surface points, and rendering through the 2D
 * engine (the view's map is an sh_warp_model of kind MODEL_GRID). */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "../warp/warp_internal.h"
#include "warp3d_internal.h"

/* As the 2D engine's grid (src/warp/grid.c): the second difference at the nodes understates
 * the largest curvature inside a cell; 2 leaves a margin. */
#define ERROR_SAFETY 2.0
/* Where a node whose ray misses the surface sends its pixels: outside every frame (black). */
#define MISS_COORD -1e7

struct sh_warp3d_view {
    const sh_warp3d_model *model;
    sh_calib_camera vcam, scam;
    int width, height;
    sh_warp3d_view_options opts;
    sh_warp_model *wm;        /* hull, grid geometry and map, as the 2D engine reads them */
    double bx0, bx1, by0, by1;/* the hull's box clipped to the image */
    double *S;                /* per node: reference world point (NaN: the ray missed) */
    double *b;                /* per node: displacement trend basis */
    int *row_start, *index;   /* per node: sparse basis of the displacement interpolant */
    double *weight;
    double *curv;
    double error_bound;
};

void sh_warp3d_view_options_default(sh_warp3d_view_options *opts)
{
    sh_warp_options_default(&opts->warp);
    opts->depth_scale = 1;
}

/* Intersection of the ray C + tau d with the surface Z' = k s(X', Y'): Newton on tau from the
 * fitted plane's intersection. */
static int intersect(const sh_warp3d_model *m, double k, const double C[3], const double d[3],
                     double uv[2])
{
    double a[3], b[3];
    for (int r = 0; r < 3; r++) {
        a[r] = b[r] = 0;
        for (int i = 0; i < 3; i++) {
            a[r] += m->axes[3 * r + i] * (C[i] - m->origin[i]);
            b[r] += m->axes[3 * r + i] * d[i];
        }
    }
    if (!(fabs(b[2]) > 1e-9)) return 0;
    double tau = -a[2] / b[2];
    const double eps = 1e-4 * m->scale;
    for (int it = 0; it < 60; it++) {
        double u = a[0] + tau * b[0], v = a[1] + tau * b[1];
        double g = a[2] + tau * b[2] - k * sh_warp3d_model_height(m, u, v);
        double sp = sh_warp3d_model_height(m, u + eps * b[0], v + eps * b[1]);
        double sm = sh_warp3d_model_height(m, u - eps * b[0], v - eps * b[1]);
        double dg = b[2] - k * (sp - sm) / (2 * eps);
        if (!(fabs(dg) > 1e-12)) return 0;
        double step = g / dg;
        tau -= step;
        if (!isfinite(tau)) return 0;
        if (fabs(step) < 1e-10 * m->scale) {
            if (tau <= 0) return 0;
            uv[0] = a[0] + tau * b[0];
            uv[1] = a[1] + tau * b[1];
            return 1;
        }
    }
    return 0;
}

sh_status sh_warp3d_model_locate(const sh_warp3d_model *model, const sh_calib_camera *cam, double depth_scale,
                                 double x, double y, double uv[2])
{
    double C[3], d[3];
    if (!sh_warp3d_ray(cam, x, y, C, d) || !intersect(model, depth_scale, C, d, uv))
        return sh_error_set(SH_ERANGE, "warp3d: the ray through (%g, %g) misses the surface", x, y);
    return SH_OK;
}

sh_status sh_warp3d_view_locate(const sh_warp3d_view *v, double x, double y, double uv[2])
{
    return sh_warp3d_model_locate(v->model, &v->vcam, v->opts.depth_scale, x, y, uv);
}

/* A grid of the view: its geometry (as the 2D engine's sh_warp_model holds it) and, per node, what
 * the reference fixes (the surface point its ray hits, the displacement's basis there) and the
 * map the last update projected. */
struct sh_warp3d_grid {
    int h, gx0, gy0, nx, ny;
    double *S;                /* per node: reference world point (NaN: the ray missed) */
    double *b;                /* per node: displacement trend basis */
    int *row_start, *index;   /* per node: sparse basis of the displacement interpolant */
    double *weight;
    double *curv;
    double *map;
};

static void grid_free(sh_warp3d_grid *g)
{
    free(g->S);
    free(g->b);
    free(g->row_start);
    free(g->index);
    free(g->weight);
    free(g->curv);
    free(g->map);
    memset(g, 0, sizeof *g);
}

/* g for spacing h, its map not projected. Reads only what the view's creation fixed and the
 * model's reference surface and interpolant (never the coefficients an update writes), so it may
 * run beside sh_warp3d_view_update and sh_warp3d_model_update on another thread. */
static sh_status grid_build(const sh_warp3d_view *v, int h, sh_warp3d_grid *g)
{
    const sh_warp3d_model *m = v->model;
    memset(g, 0, sizeof *g);
    g->h = h;
    g->gx0 = (int)floor(v->bx0 / h) * h;
    g->gy0 = (int)floor(v->by0 / h) * h;
    g->nx = ((int)ceil(v->bx1 / h) * h - g->gx0) / h + 1;
    g->ny = ((int)ceil(v->by1 / h) * h - g->gy0) / h + 1;
    if (g->nx < 2) g->nx = 2;
    if (g->ny < 2) g->ny = 2;
    size_t nodes = (size_t)g->nx * (size_t)g->ny;
    int max_terms = sh_interp_max_terms(m->h_interp);
    g->S = malloc(sizeof(double) * 3 * nodes);
    g->b = malloc(sizeof(double) * W3_H_TREND * nodes);
    g->row_start = malloc(sizeof(int) * (nodes + 1));
    g->index = malloc(sizeof(int) * nodes * (size_t)max_terms);
    g->weight = malloc(sizeof(double) * nodes * (size_t)max_terms);
    g->curv = malloc(sizeof(double) * 4 * nodes);
    g->map = malloc(sizeof(double) * 2 * nodes);
    if (!g->S || !g->b || !g->row_start || !g->index || !g->weight || !g->curv || !g->map) {
        grid_free(g);
        return sh_error_set(SH_ENOMEM, "warp3d: grid of %zu nodes does not fit in memory", nodes);
    }
    size_t used = 0;
    for (int j = 0; j < g->ny; j++) {
        for (int i = 0; i < g->nx; i++) {
            size_t node = (size_t)j * g->nx + i;
            double C[3], d[3], uv[2];
            g->row_start[node] = (int)used;
            double *S = g->S + 3 * node;
            if (!sh_warp3d_ray(&v->vcam, g->gx0 + (double)i * h, g->gy0 + (double)j * h, C, d) ||
                !intersect(m, v->opts.depth_scale, C, d, uv)) {
                S[0] = S[1] = S[2] = NAN;
                continue;
            }
            w3_surface_point(m, uv[0], uv[1], 1, S);
            w3_h_basis(m, uv[0], uv[1], g->b + W3_H_TREND * node);
            int k = sh_interp_basis(m->h_interp, uv[0], uv[1], g->index + used, g->weight + used);
            if (k < 0) {
                grid_free(g);
                return (sh_status)k;
            }
            used += (size_t)k;
        }
    }
    g->row_start[nodes] = (int)used;
    return SH_OK;
}

/* Puts g in v's place and v's old grid in g's. */
static void grid_exchange(sh_warp3d_view *v, sh_warp3d_grid *g)
{
    sh_warp_model *wm = v->wm;
    sh_warp3d_grid old = {wm->h, wm->gx0, wm->gy0, wm->nx, wm->ny, v->S, v->b, v->row_start, v->index,
                          v->weight, v->curv, wm->map};
    wm->h = g->h, wm->gx0 = g->gx0, wm->gy0 = g->gy0, wm->nx = g->nx, wm->ny = g->ny;
    v->S = g->S, v->b = g->b, v->row_start = g->row_start, v->index = g->index;
    v->weight = g->weight, v->curv = g->curv, wm->map = g->map;
    *g = old;
}

/* v's grid at spacing h (the old one kept when that fails). */
static sh_status build_grid(sh_warp3d_view *v, int h)
{
    sh_warp3d_grid g;
    sh_status st = grid_build(v, h, &g);
    if (st != SH_OK) return st;
    grid_exchange(v, &g);
    grid_free(&g);
    return SH_OK;
}

void sh_warp3d_view_destroy(sh_warp3d_view *v)
{
    if (!v) return;
    if (v->wm) {
        sh_warp3d_grid g = {0};
        grid_exchange(v, &g); /* the view's arrays into g, to free */
        grid_free(&g);
        sh_warp_model_destroy(v->wm);
    }
    free(v);
}

sh_status sh_warp3d_view_create(const sh_warp3d_model *m, const sh_calib_camera *view_cam,
                                const sh_calib_camera *source_cam, int width, int height,
                                const sh_warp3d_view_options *opts, sh_warp3d_view **out)
{
    if (!m || !view_cam || !source_cam || !out || width < 2 || height < 2 ||
        width > SH_IMAGE_MAX_SIZE || height > SH_IMAGE_MAX_SIZE)
        return sh_error_set(SH_EINVAL, "warp3d: invalid view arguments");
    for (int c = 0; c < 2; c++) {
        const sh_calib_camera *cam = c ? source_cam : view_cam;
        if (cam->dist[12] != 0 || cam->dist[13] != 0)
            return sh_error_set(SH_EUNSUPPORTED, "warp3d: tilted sensors (tx, ty) are not supported");
        if (!(fabs(cam->K[0]) > 0) || !(fabs(cam->K[4]) > 0))
            return sh_error_set(SH_EINVAL, "warp3d: camera matrix with a zero focal length");
    }
    sh_warp3d_view *v = calloc(1, sizeof *v);
    if (!v) return sh_error_set(SH_ENOMEM, "warp3d: out of memory");
    v->model = m;
    v->vcam = *view_cam;
    v->scam = *source_cam;
    v->width = width;
    v->height = height;
    if (opts) v->opts = *opts;
    else sh_warp3d_view_options_default(&v->opts);
    sh_status st = SH_OK;
    v->wm = calloc(1, sizeof *v->wm);
    if (!v->wm) {
        free(v);
        return sh_error_set(SH_ENOMEM, "warp3d: out of memory");
    }
    sh_warp_model *wm = v->wm;
    wm->kind = MODEL_GRID;
    wm->width = width;
    wm->height = height;
    wm->opts = v->opts.warp;
    if (!(v->opts.warp.max_error > 0) || v->opts.warp.grid_spacing < 1 ||
        (v->opts.warp.grid_spacing & (v->opts.warp.grid_spacing - 1)) ||
        !(v->opts.depth_scale > 0) || !(v->opts.depth_scale < 1e3)) {
        st = sh_error_set(SH_EINVAL, "warp3d: max_error must be > 0, the grid spacing a power of "
                                     "two and the depth scale in (0, 1000)");
        goto fail;
    }
    /* the hull: the reference markers (on the surface as this view sees it) projected */
    double *xy = malloc(sizeof(double) * 2 * (size_t)m->n);
    if (!xy) {
        st = sh_error_set(SH_ENOMEM, "warp3d: out of memory");
        goto fail;
    }
    for (int i = 0; i < m->n; i++) {
        double X[3];
        w3_surface_point(m, m->uv[2 * i], m->uv[2 * i + 1], v->opts.depth_scale, X);
        if (!sh_warp3d_project(&v->vcam, X, xy + 2 * i, xy + 2 * i + 1)) {
            free(xy);
            st = sh_error_set(SH_EDEGENERATE, "warp3d: marker %d is behind the view's camera", i);
            goto fail;
        }
    }
    st = sh_hull_compute(xy, m->n, &wm->hull);
    free(xy);
    if (st != SH_OK) goto fail;
    v->bx0 = fmax(wm->hull.xmin, 0);
    v->by0 = fmax(wm->hull.ymin, 0);
    v->bx1 = fmin(wm->hull.xmax, width - 1);
    v->by1 = fmin(wm->hull.ymax, height - 1);
    if (!(v->bx0 <= v->bx1 && v->by0 <= v->by1)) {
        st = sh_error_set(SH_EDEGENERATE, "warp3d: the markers' hull lies outside the view");
        goto fail;
    }
    if ((st = build_grid(v, v->opts.warp.grid_spacing)) != SH_OK) goto fail;
    *out = v;
    return SH_OK;
fail:
    sh_warp3d_view_destroy(v);
    return st;
}

static void project_nodes(sh_warp3d_view *v)
{
    const sh_warp3d_model *m = v->model;
    sh_warp_model *wm = v->wm;
    const size_t nodes = (size_t)wm->nx * (size_t)wm->ny;
    const int terms = m->h_terms;
    const double *coef = m->h_coef, *trend = m->h_trend;
    for (size_t node = 0; node < nodes; node++) {
        const double *S = v->S + 3 * node, *b = v->b + W3_H_TREND * node;
        double *out = wm->map + 2 * node;
        if (S[0] != S[0]) {
            out[0] = out[1] = MISS_COORD;
            continue;
        }
        double X[3] = {S[0], S[1], S[2]};
        for (int k = 0; k < terms; k++) {
            X[0] += b[k] * trend[3 * k];
            X[1] += b[k] * trend[3 * k + 1];
            X[2] += b[k] * trend[3 * k + 2];
        }
        const int *index = v->index + v->row_start[node];
        const double *weight = v->weight + v->row_start[node];
        int n = v->row_start[node + 1] - v->row_start[node];
        for (int k = 0; k < n; k++) {
            const double *c = coef + 3 * (size_t)index[k];
            X[0] += weight[k] * c[0];
            X[1] += weight[k] * c[1];
            X[2] += weight[k] * c[2];
        }
        if (!sh_warp3d_project(&v->scam, X, out, out + 1)) out[0] = out[1] = MISS_COORD;
    }
}

/* fmax for the curvatures (each |.| or NaN, so no signed zero to choose between): NaN only when
 * both are. Inline: libm's fmax is a call per comparison, 13 a cell (0.3 ms a frame of the
 * daemon's stereo pair at 1080p, issue 20). */
static inline double max_or_nan(double a, double b)
{
    return b > a || a != a ? b : a;
}

/* The 2D engine's bound (src/warp/grid.c): per cell h^2/8 (|f_xx| + |f_yy|) from the second
 * differences at its corners; cells touching a missed node are left out (they are black). */
static double error_bound(sh_warp3d_view *v)
{
    const sh_warp_model *wm = v->wm;
    if (wm->h == 1) return 0;
    if (wm->nx < 3 || wm->ny < 3) return INFINITY;
    const int nx = wm->nx, ny = wm->ny;
    const size_t row = 2 * (size_t)nx;
    double *curv = v->curv;
    for (int j = 0; j < ny; j++) {
        int jc = j == 0 ? 1 : (j == ny - 1 ? ny - 2 : j);
        for (int i = 0; i < nx; i++) {
            int ic = i == 0 ? 1 : (i == nx - 1 ? nx - 2 : i);
            const double *mx = wm->map + 2 * ((size_t)j * nx + ic);
            const double *my = wm->map + 2 * ((size_t)jc * nx + i);
            double *c = curv + 4 * ((size_t)j * nx + i);
            if (mx[-2] == MISS_COORD || mx[0] == MISS_COORD || mx[2] == MISS_COORD ||
                my[-(ptrdiff_t)row] == MISS_COORD || my[0] == MISS_COORD || my[row] == MISS_COORD) {
                c[0] = c[1] = c[2] = c[3] = NAN;
                continue;
            }
            c[0] = fabs(mx[-2] - 2 * mx[0] + mx[2]);
            c[1] = fabs(mx[-1] - 2 * mx[1] + mx[3]);
            c[2] = fabs(my[-(ptrdiff_t)row] - 2 * my[0] + my[row]);
            c[3] = fabs(my[1 - (ptrdiff_t)row] - 2 * my[1] + my[row + 1]);
        }
    }
    double worst = 0;
    for (int j = 0; j + 1 < ny; j++) {
        for (int i = 0; i + 1 < nx; i++) {
            const double *a = curv + 4 * ((size_t)j * nx + i), *b = a + 4, *c = a + 4 * nx,
                         *d = c + 4;
            double e[4];
            for (int k = 0; k < 4; k++) e[k] = max_or_nan(max_or_nan(a[k], b[k]), max_or_nan(c[k], d[k]));
            double ex = e[0] + e[2], ey = e[1] + e[3];
            if (ex == ex && ey == ey) worst = max_or_nan(worst, ex * ex + ey * ey);
        }
    }
    return ERROR_SAFETY / 8 * sqrt(worst);
}

sh_status sh_warp3d_view_update(sh_warp3d_view *v)
{
    if (!v) return sh_error_set(SH_EINVAL, "warp3d: no view");
    sh_status st;
    project_nodes(v);
    v->error_bound = error_bound(v);
    while (!v->opts.warp.defer_refine && v->error_bound > v->opts.warp.max_error && v->wm->h > 1) {
        if ((st = build_grid(v, v->wm->h / 2)) != SH_OK) return st;
        v->wm->refinements++;
        project_nodes(v);
        v->error_bound = error_bound(v);
    }
    v->wm->error_bound = v->error_bound;
    return SH_OK;
}

sh_status sh_warp3d_view_grid_build(const sh_warp3d_view *v, int h, sh_warp3d_grid **out)
{
    *out = NULL;
    if (!v || h < 1 || (h & (h - 1))) return sh_error_set(SH_EINVAL, "warp3d: grid spacing %d is not a power of two", h);
    sh_warp3d_grid *g = malloc(sizeof *g);
    if (!g) return sh_error_set(SH_ENOMEM, "warp3d: out of memory");
    sh_status st = grid_build(v, h, g);
    if (st != SH_OK) {
        free(g);
        return st;
    }
    *out = g;
    return SH_OK;
}

void sh_warp3d_view_grid_swap(sh_warp3d_view *v, sh_warp3d_grid *grid)
{
    grid_exchange(v, grid);
    v->wm->refinements++;
    project_nodes(v);
    v->wm->error_bound = v->error_bound = error_bound(v);
}

void sh_warp3d_grid_destroy(sh_warp3d_grid *grid)
{
    if (!grid) return;
    grid_free(grid);
    free(grid);
}

const sh_warp_model *sh_warp3d_view_map_model(const sh_warp3d_view *v)
{
    return v->wm;
}

const sh_hull *sh_warp3d_view_hull(const sh_warp3d_view *v)
{
    return &v->wm->hull;
}

int sh_warp3d_view_grid_spacing(const sh_warp3d_view *v)
{
    return v->wm->h;
}

double sh_warp3d_view_error_bound(const sh_warp3d_view *v)
{
    return v->error_bound;
}

sh_status sh_warp3d_view_apply(sh_warp *warp, const sh_warp3d_view *v, const sh_image *current,
                               sh_image *out, int ox, int oy)
{
    if (!v || !current || !out) return sh_error_set(SH_EINVAL, "warp3d: missing argument");
    if (current->width != v->width || current->height != v->height || out->format != current->format ||
        ox < 0 || oy < 0 || ox + v->width > out->width || oy + v->height > out->height ||
        (out->format == SH_PIX_I420 && ((ox | oy) & 1)))
        return sh_error_set(SH_EINVAL, "warp3d: frame %dx%d, view %dx%d at (%d, %d) of output %dx%d",
                            current->width, current->height, v->width, v->height, ox, oy,
                            out->width, out->height);
    sh_image window;
    sh_status st = sh_image_window(out, ox, oy, v->width, v->height, &window);
    return st == SH_OK ? sh_warp_apply(warp, v->wm, current, &window) : st;
}
