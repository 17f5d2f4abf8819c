/* Models per marker set: the interpolant and warp model (2D), or the surface model and its views
 * (3D), over the reference positions of one set of markers, kept in a small least-recently-used
 * table so that a marker that comes and goes costs one build per distinct set, not one per frame.
 * `stillheart warp`, `stillheart warp3d` and the daemon's models (src/daemon/run_model.c) all key,
 * build and free their models here.
 *
 * A library module, not a file of src/app: the daemon's pipeline is to become a library of its
 * own (issue 15), and this is the one place that it and the two commands can all link without
 * linking each other; it depends on the engine only (interp, warp, warp3d, points, calib).
 *
 * An entry owns what it holds; sh_modelcache_entry_clear frees it and leaves the entry empty (n
 * 0). Entries are plain structs: moving one (`*dst = *src`, then clearing src with memset) moves
 * its models, as the daemon does between its helper thread and its table. */
#ifndef STILLHEART_MODELCACHE_H
#define STILLHEART_MODELCACHE_H

#include "stillheart/calib.h"
#include "stillheart/interp.h"
#include "stillheart/points.h"
#include "stillheart/warp.h"
#include "stillheart/warp3d.h"

#ifdef __cplusplus
extern "C" {
#endif

/* How an entry's models are built. */
typedef struct {
    int three_d;                     /* 0: interp + warp model over x, y; 1: warp3d over X, Y, Z */
    int width, height;               /* the map (2D) or each view (3D), in pixels */
    sh_interp_params params;         /* 2D */
    sh_warp_options wopts;           /* 2D */
    double point_smoothing;          /* RBFs: > 0: the rows whose id is smoothed_from or more get
                                      * this smoothing of their own (sh_interp_create_smoothed): the
                                      * tissue's landmarks, less certain than the markers (callers set
                                      * smoothed_from to SH_LANDMARK_ID_BASE); 0: none. In the map's
                                      * pixels; in 3D in source_cam's, converted to the surface's
                                      * millimetres (sh_warp3d_pixels_per_mm) for the RBF
                                      * interpolants of p3 */
    int smoothed_from;
    sh_warp3d_params p3;             /* 3D */
    sh_warp3d_view_options vopts;    /* 3D */
    sh_calib_camera view_cam[2];     /* 3D: the cameras the views are seen from ... */
    sh_calib_camera source_cam;      /* ... and the one the frames come from */
    int nviews;                      /* 3D: 0..2 views */
    double ply_spacing;              /* 3D: > 0: a PLY exporter of the surface too */
    int ply_mesh;
} sh_modelcache_recipe;

typedef struct {
    int n;                           /* markers in the set; 0: empty */
    int *ids;                        /* sorted */
    double *ref_xy, *ref_xyz;        /* their reference positions, 2n and 3n */
    sh_interp *interp;               /* 2D */
    sh_warp_model *model;            /* 2D */
    sh_warp3d_model *m3;             /* 3D */
    sh_warp3d_view *view[2];         /* 3D: recipe nviews of them */
    sh_warp3d_ply *ply;              /* 3D, with ply_spacing */
    unsigned long last_used;         /* the table's clock at the last lookup that found it */
} sh_modelcache_entry;

/* Empties e and sets its key: ids (n, sorted) and their reference positions from ref (nref rows
 * sorted by id, each id of ids among them). Nothing is built yet. */
sh_status sh_modelcache_entry_set(sh_modelcache_entry *e, const sh_point *ref, int nref, const int *ids, int n);
/* Builds e's models by the recipe over the positions sh_modelcache_entry_set gathered. On error
 * the models are freed again; the key stays. */
sh_status sh_modelcache_entry_build(sh_modelcache_entry *e, const sh_modelcache_recipe *r);
/* Frees everything e holds; e is empty afterwards. */
void sh_modelcache_entry_clear(sh_modelcache_entry *e);
/* 1 when e holds the set ids (n, sorted). */
int sh_modelcache_entry_is(const sh_modelcache_entry *e, const int *ids, int n);

/* The lookup in a table of count entries (reached through entry(i, table)): the index of the
 * entry holding ids, its stamp renewed from *clock; else -1, and *victim the index to build the
 * set in: an empty entry first, else the least recently used; entries for which keep(i, table)
 * is 1 are never chosen (*victim -1 when every one is kept). keep may be NULL. */
int sh_modelcache_lookup(void *table, int count, sh_modelcache_entry *(*entry)(void *table, int i),
                         int (*keep)(void *table, int i), unsigned long *clock, const int *ids, int n,
                         int *victim);

/* A table that builds on a miss, for callers on one thread. */
typedef struct sh_modelcache sh_modelcache;
/* slots: how many sets are kept; ref (nref rows sorted by id) is copied. */
sh_status sh_modelcache_create(const sh_modelcache_recipe *r, const sh_point *ref, int nref, int slots,
                               sh_modelcache **out);
void sh_modelcache_destroy(sh_modelcache *c);
/* The entry for ids (sorted, each in the reference), built on a miss in place of the least
 * recently used one. Valid until the next sh_modelcache_get. */
sh_status sh_modelcache_get(sh_modelcache *c, const int *ids, int n, sh_modelcache_entry **out);
/* Models built so far, and the seconds their builds took. */
int sh_modelcache_builds(const sh_modelcache *c);
double sh_modelcache_build_seconds(const sh_modelcache *c);

#ifdef __cplusplus
}
#endif
#endif
