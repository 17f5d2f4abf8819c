/* The geometric error of a stabilized phantom video.
 *
 * Output pixel q of stabilized frame t shows the current frame's content at f_t(q), the map the
 * warp used; it should show the surface point that q showed in the reference frame N, which the
 * truth puts at g_t(q) in frame t. The error is |f_t(q) - g_t(q)| in pixels.
 *
 * f_t is rebuilt exactly as `stillheart warp` builds it (src/app/cmd_warp.c), through the same
 * model cache (modelcache.h, one slot, the warp's recipe): an interpolant on the
 * reference positions of the markers frame t shares with frame N, a warp model on it, updated with
 * frame t's positions, and sh_warp_model_map for the map the executor samples with (grid
 * interpolation and fixed-point rounding included). A frame with fewer than 3 shared markers, or
 * whose model the library refuses, was passed through raw by the warp: its map is the identity.
 * With a calibration (--cameras), f_t is `stillheart warp3d`'s reference view instead
 * (src/app/cmd_warp3d.c), through the same model cache and recipe: a 3D model on the reference
 * X, Y, Z of the markers frame t shares with frame N (4 at least; with landmark rows, every
 * landmark of frame N in the model, smoothed as warp3d smooths it, and the frame's displacement
 * fitted through the ones it has, as warp3d does), its view from the phantom's
 * camera, the reference frame's map made first as warp3d makes it; the view's grid refines with
 * what it has seen, so the map may differ from warp3d's within the view's max_error where the two
 * saw different frames before. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "eval.h"
#include "stillheart/modelcache.h"

struct eval_geo {
    eval_geo_options o;
    const sh_points *points;
    const sh_point *ref_rows;
    int ref_count, width, height;
    /* samples: pixel (x, y) of the reference frame and the material point it sees */
    int n;
    int *sx, *sy;
    phantom_content *seen; /* what each sample shows in the reference frame: tissue or sticker */
    /* the model for the current marker set, built as the warp's or warp3d's (one slot of its
     * cache: the same recipe, landmark rows' smoothing included; in 3D the view from the
     * phantom's camera) */
    sh_modelcache *cache;
    int builds;            /* 3D: the cache's builds when the last model's reference map was made */
    double *cur_xyz;       /* 3D: the frame's X, Y, Z */
    int landmarks;         /* 3D: as warp3d, every model holds all the reference's landmarks */
    unsigned char *use;    /*   and each frame uses the ones it has */
    int *ids;
    double *cur_xy;
    float *map;
    /* every measured error, for the percentile */
    float *err;
    long long count, cap;
    double sum, max;
    long long hidden, unmapped;
    int raw_frames;
};

void eval_geo_destroy(eval_geo *g)
{
    if (!g) return;
    sh_modelcache_destroy(g->cache);
    free(g->cur_xyz);
    free(g->use);
    free(g->sx);
    free(g->sy);
    free(g->seen);
    free(g->ids);
    free(g->cur_xy);
    free(g->map);
    free(g->err);
    free(g);
}

sh_status eval_geo_create(const eval_geo_options *opts, const sh_points *points,
                          const sh_hull *hull, int width, int height, eval_geo **out)
{
    const phantom_model *pm = phantom_truth_model(opts->truth);
    if (opts->camera < 0 || opts->camera >= pm->num_cameras)
        return sh_error_set(SH_EINVAL, "--camera %d: the phantom has %d camera(s)", opts->camera,
                            pm->num_cameras);
    if (opts->calib && (opts->camera >= opts->calib->num_cameras || opts->calib->width != width ||
                        opts->calib->height != height))
        return sh_error_set(SH_EINVAL, "--cameras: camera %d of a %d-camera calibration for %dx%d, the video is %dx%d",
                            opts->camera, opts->calib->num_cameras, opts->calib->width, opts->calib->height, width,
                            height);
    if (pm->width != width || pm->height != height)
        return sh_error_set(SH_EINVAL, "the phantom's images are %dx%d, the video's %dx%d",
                            pm->width, pm->height, width, height);
    eval_geo *g = calloc(1, sizeof *g);
    if (!g) return sh_error_set(SH_ENOMEM, "geometric error: out of memory");
    g->o = *opts;
    g->points = points;
    g->width = width;
    g->height = height;
    g->ref_rows = sh_points_frame(points, opts->reference, &g->ref_count);

    long long cap = 0;
    for (int y = 0; y < height; y += opts->stride) {
        int first, last;
        if (sh_hull_plane_row(hull, y, width, 1, 0, 0, &first, &last))
            cap += (last - first) / opts->stride + 1;
    }
    cap += 1;
    size_t npix = (size_t)width * height;
    g->sx = malloc(sizeof(int) * (size_t)cap);
    g->sy = malloc(sizeof(int) * (size_t)cap);
    g->seen = malloc(sizeof(phantom_content) * (size_t)cap);
    g->ids = malloc(sizeof(int) * (size_t)(g->ref_count + 1));
    g->cur_xy = malloc(sizeof(double) * 2 * (size_t)(g->ref_count + 1));
    g->map = opts->identity ? NULL : malloc(sizeof(float) * 2 * npix);
    g->cur_xyz = malloc(sizeof(double) * 3 * (size_t)(g->ref_count + 1));
    g->use = malloc((size_t)g->ref_count + 1);
    if (!g->sx || !g->sy || !g->seen || !g->ids || !g->cur_xy || !g->cur_xyz || !g->use ||
        (!opts->identity && !g->map)) {
        eval_geo_destroy(g);
        return sh_error_set(SH_ENOMEM, "geometric error: out of memory");
    }
    /* warp3d's choice (src/app/cmd_warp3d.c): landmark rows with X, Y, Z in the reference, and a
     * displacement that can leave points out */
    for (int k = 0; opts->calib && k < g->ref_count; k++)
        g->landmarks |= g->ref_rows[k].id >= SH_LANDMARK_ID_BASE && isfinite(g->ref_rows[k].X) &&
                        isfinite(g->ref_rows[k].Y) && isfinite(g->ref_rows[k].Z) &&
                        opts->p3.displacement.method != SH_METHOD_PWLINEAR;
    /* Samples on the stride lattice (multiples of stride, so runs with different hulls share
     * their points); a pixel that does not see the patch, or sees it hidden, has no truth. */
    for (int y = 0; y < height; y += opts->stride) {
        int first, last;
        if (!sh_hull_plane_row(hull, y, width, 1, 0, 0, &first, &last)) continue;
        for (int x = (first + opts->stride - 1) / opts->stride * opts->stride; x <= last;
             x += opts->stride) {
            /* a sticker moves with its own rigid patch, not with the tissue under it */
            phantom_content seen;
            if (phantom_truth_locate_content(opts->truth, opts->camera, opts->reference, x, y,
                                             &seen) != SH_OK ||
                !phantom_truth_content_visible(opts->truth, opts->camera, opts->reference, &seen))
                continue;
            g->sx[g->n] = x;
            g->sy[g->n] = y;
            g->seen[g->n] = seen;
            g->n++;
        }
    }
    if (!opts->identity) {
        sh_modelcache_recipe r = {.width = width, .height = height, .params = opts->params, .wopts = opts->wopts,
                                  .point_smoothing = sh_landmarks_smoothing(opts->landmark_smoothing,
                                                                            sh_landmarks_reduction(NULL, width, height)),
                                  .smoothed_from = SH_LANDMARK_ID_BASE};
        if (opts->calib) {
            r.three_d = 1;
            r.p3 = opts->p3;
            r.vopts = opts->vopts;
            r.view_cam[0] = r.source_cam = opts->calib->cam[opts->camera];
            r.nviews = 1;
        }
        sh_status st = sh_modelcache_create(&r, g->ref_rows, g->ref_count, 1, &g->cache);
        if (st != SH_OK) {
            eval_geo_destroy(g);
            return st;
        }
    }
    *out = g;
    return SH_OK;
}

/* 3D: the map of frame t into g->map; 0 when warp3d passed the frame through raw. */
static int frame_map3(eval_geo *g, int t)
{
    int ncur;
    const sh_point *cur = sh_points_frame(g->points, t, &ncur);
    int used, n = g->landmarks ? sh_points_match_xyz_keep(g->ref_rows, g->ref_count, cur, ncur, SH_LANDMARK_ID_BASE,
                                                          g->ids, g->cur_xyz, g->use, &used)
                               : (used = sh_points_match_xyz(g->ref_rows, g->ref_count, cur, ncur, g->ids, g->cur_xyz));
    if (used < 4) return 0;
    sh_modelcache_entry *e;
    if (sh_modelcache_get(g->cache, g->ids, n, &e) != SH_OK) return 0;
    /* a new model's reference map first, as warp3d's: its view's grid refines with what it saw */
    if (sh_modelcache_builds(g->cache) != g->builds && sh_warp3d_view_update(e->view[0]) != SH_OK) return 0;
    g->builds = sh_modelcache_builds(g->cache);
    return sh_warp3d_model_update_subset(e->m3, g->cur_xyz, g->landmarks ? g->use : NULL) == SH_OK &&
           sh_warp3d_view_update(e->view[0]) == SH_OK &&
           sh_warp_model_map(sh_warp3d_view_map_model(e->view[0]), g->map) == SH_OK;
}

/* The map of frame t into g->map; returns 0 when the warp passed the frame through raw. */
static int frame_map(eval_geo *g, int t)
{
    if (g->o.identity) return 0;
    if (g->o.calib) return frame_map3(g, t);
    int ncur;
    const sh_point *cur = sh_points_frame(g->points, t, &ncur);
    int n = sh_points_match(g->ref_rows, g->ref_count, cur, ncur, g->ids, NULL, g->cur_xy);
    sh_modelcache_entry *e;
    if (n < 3 || sh_modelcache_get(g->cache, g->ids, n, &e) != SH_OK) return 0;
    return sh_warp_model_update(e->model, g->cur_xy) == SH_OK && sh_warp_model_map(e->model, g->map) == SH_OK;
}

sh_status eval_geo_frame(eval_geo *g, int t)
{
    int mapped = frame_map(g, t);
    if (!mapped && !g->o.identity) g->raw_frames++;
    if (g->count + g->n > g->cap) {
        long long cap = g->cap ? g->cap * 2 : 1 << 16;
        while (cap < g->count + g->n) cap *= 2;
        float *e = realloc(g->err, sizeof(float) * (size_t)cap);
        if (!e) return sh_error_set(SH_ENOMEM, "geometric error: out of memory at frame %d", t);
        g->err = e;
        g->cap = cap;
    }
    for (int i = 0; i < g->n; i++) {
        double gx, gy;
        if (!phantom_truth_content_visible(g->o.truth, g->o.camera, t, &g->seen[i]) ||
            phantom_truth_project_content(g->o.truth, g->o.camera, t, &g->seen[i], &gx, &gy) !=
                SH_OK) {
            g->hidden++;
            continue;
        }
        double fx = g->sx[i], fy = g->sy[i];
        if (mapped) {
            const float *m = g->map + ((size_t)g->sy[i] * g->width + g->sx[i]) * 2;
            if (isnan(m[0])) {
                g->unmapped++;
                continue;
            }
            fx = m[0];
            fy = m[1];
        }
        double e = hypot(fx - gx, fy - gy);
        g->sum += e;
        if (e > g->max) g->max = e;
        g->err[g->count++] = (float)e;
    }
    return SH_OK;
}

static int cmp_float(const void *a, const void *b)
{
    float x = *(const float *)a, y = *(const float *)b;
    return (x > y) - (x < y);
}

sh_status eval_geo_result_get(eval_geo *g, eval_geo_result *r)
{
    memset(r, 0, sizeof *r);
    r->samples = g->count;
    r->points = g->n;
    r->hidden = g->hidden;
    r->unmapped = g->unmapped;
    r->raw_frames = g->raw_frames;
    if (g->count == 0) {
        r->mean = r->p95 = r->max = NAN;
        return SH_OK;
    }
    qsort(g->err, (size_t)g->count, sizeof(float), cmp_float);
    /* Nearest rank: the smallest error that at least 95% of the samples do not exceed. */
    long long k = (long long)ceil(0.95 * (double)g->count) - 1;
    r->mean = g->sum / (double)g->count;
    r->p95 = g->err[k < 0 ? 0 : k];
    r->max = g->max;
    return SH_OK;
}
