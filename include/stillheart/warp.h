/* The 2D warp (paper Algorithm 1), split as docs/architecture.md explains ("Once per reference,
 * once per frame"):
 *
 *  - sh_warp_model: everything that depends on the reference positions of one marker set
 *    (the convex hull, the interpolant's basis cached on a grid, or the Delaunay triangles).
 *    Built once per reference and marker set; sh_warp_model_update then gives the map for the
 *    current positions (a small sparse matrix product on the grid).
 *  - sh_warp: the executor (worker threads, stripes) that fills the output frame: for every
 *    output pixel inside the hull, the map interpolated from the grid (or exact, for affine and
 *    piecewise linear), then a bilinear sample of the current frame; black outside the hull
 *    and where the map leaves the current frame.
 *
 * Coordinates: pixel (x, y) has its centre at (x, y), in the full-resolution (luma / RGB) plane.
 *
 * Grid error: between grid nodes the map is interpolated bilinearly. Its error is bounded by
 * h^2/8 (|f_xx| + |f_yy|); each update estimates that bound for every cell from the second
 * differences of the map on the grid. When the bound exceeds max_error the grid is refined
 * (spacing halved, basis rebuilt: the only time an update allocates) until it holds; the finer
 * grid then stays for the model's later frames. */
#ifndef STILLHEART_WARP_H
#define STILLHEART_WARP_H

#include "stillheart/hull.h"
#include "stillheart/image.h"
#include "stillheart/interp.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct {
    double max_error;  /* largest tolerated map error in pixels (default 0.05) */
    int grid_spacing;  /* initial grid spacing in pixels, a power of two (default 16) */
    int coarsest_spacing; /* a 2D TPS model's grid refined below this (a power of two; default
                        * 16) maps each update on every other node first, and keeps that map
                        * when its bound is within max_error: a frame's smooth map does not pay
                        * for the finest grid an earlier frame needed. 0: never. (3D views'
                        * grids do not.) */
    int defer_refine;  /* 0 (default): an update whose bound exceeds max_error refines the grid
                        * there and then (a new basis: tens of ms with many points). 1: it keeps
                        * the grid and its larger bound, and sh_warp_model_finer_spacing says
                        * which spacing is due, for a caller with a deadline to build a model
                        * with it elsewhere and swap it in. */
} sh_warp_options;

void sh_warp_options_default(sh_warp_options *opts);

typedef struct sh_warp_model sh_warp_model;

/* interp must be built on the same ref_xy (n points) and outlive the model. width x height is
 * the frame geometry (full-resolution plane). */
sh_status sh_warp_model_create(const sh_interp *interp, const double *ref_xy, int n, int width,
                               int height, const sh_warp_options *opts, sh_warp_model **out);
void sh_warp_model_destroy(sh_warp_model *model);

/* The current positions of the same n points, in the same order. */
sh_status sh_warp_model_update(sh_warp_model *model, const double *cur_xy);
/* The map through the points with use[k] != 0 alone (sh_interp_fit_subset: affine, the RBFs and
 * bspline; pwlinear: the Delaunay triangles of the used points, sh_interp_delaunay, so the map is
 * bit for bit that of a model built on them alone; SH_EDEGENERATE when they span no triangle, and
 * the model is then every point's again); use NULL: every point, as sh_warp_model_update. The
 * hull, what the warp shows, becomes the used points' (a model built on those points alone would
 * show the same: where the map is interpolated between points trusted this frame); use NULL
 * restores every point's. A left-out point's position is not read. The first such update
 * allocates the fit's or the triangulation's work, once per model, for any subset. */
sh_status sh_warp_model_update_subset(sh_warp_model *model, const double *cur_xy, const unsigned char *use);

/* The map of the last update at reference point (x, y), evaluated exactly (the interpolant, not
 * the grid the warp samples): its current-frame position into out[0..1]. Piecewise linear outside
 * its triangles: SH_ERANGE and NaN. */
sh_status sh_warp_model_eval(const sh_warp_model *model, double x, double y, double *out);

const sh_hull *sh_warp_model_hull(const sh_warp_model *model);
/* Grid spacing in use (0 for the exact methods: affine, piecewise linear). */
int sh_warp_model_grid_spacing(const sh_warp_model *model);
/* Estimated largest map error of the last update, pixels (0 for the exact methods). */
double sh_warp_model_error_bound(const sh_warp_model *model);
/* How often updates had to refine the grid. */
int sh_warp_model_refinements(const sh_warp_model *model);
/* With defer_refine: the spacing (half the one in use) that the last update's map needs because
 * its bound exceeds max_error; 0 when none is due (and always without defer_refine, or for the
 * exact methods). */
int sh_warp_model_finer_spacing(const sh_warp_model *model);

/* The map exactly as the warp uses it: map[(y * width + x) * 2 + {0,1}] = current-frame x, y
 * of output pixel (x, y); NaN outside the hull. map holds width * height * 2 floats. */
sh_status sh_warp_model_map(const sh_warp_model *model, float *map);

typedef struct sh_warp sh_warp;

/* threads >= 1: the frame is cut into that many stripes (the caller's thread does one). */
sh_status sh_warp_create(int threads, sh_warp **out);
void sh_warp_destroy(sh_warp *warp);

/* sh_warp_model_update_subset (use NULL: sh_warp_model_update) with the grid's nodes shared
 * among the warp's threads: the same map and bound, bit for bit. Before a warp on those
 * threads, the update no longer runs on one while the others wait (at 4K, 32 markers: 0.3-0.45
 * of a 3 ms frame on two threads). */
sh_status sh_warp_update(sh_warp *warp, sh_warp_model *model, const double *cur_xy, const unsigned char *use);

/* out and current: same format and size as the model's frame. Allocation-free once it has seen
 * the frame size and the output buffer (it notes which pixels of each row it left inside the
 * hull, for the last 4 buffers it wrote). */
sh_status sh_warp_apply(sh_warp *warp, const sh_warp_model *model, const sh_image *current,
                        sh_image *out);
/* The same output byte for byte, into an out that holds what this warp's last apply into it
 * wrote, untouched since (a buffer the caller takes in turn): of the outside, only the pixels
 * that were inside the hull there and are not now are written black; the rest already is. At
 * 4K the whole outside is about 0.5 ms of memset a frame. An out this warp has not written, or
 * not among its last 4 buffers, is written whole. The caller that wrote into out otherwise
 * (another fill of the outside, a raw frame) calls sh_warp_apply. */
sh_status sh_warp_apply_again(sh_warp *warp, const sh_warp_model *model, const sh_image *current,
                              sh_image *out);

/* Outside the hull (docs/warp.md, "Outside the hull"): the warp leaves it black, as the paper
 * does. sh_warp_outside shows there the current, unstabilized frame instead, dimmed, with a
 * boundary line, so that instruments approaching from the edge stay visible while the
 * stabilized region stays unmistakable:
 *  - dimmed: each sample halfway to black, (v + b + 1) >> 1, where b is black: 0 for RGB24 and
 *    full-range luma, 16 for limited-range luma, 128 (neutral) for chroma;
 *  - boundary: the outside pixels within SH_WARP_OUTSIDE_LINE full-resolution pixels of an
 *    inside pixel of the same plane (Chebyshev distance, in that plane's pixels: 1 in 4:2:0
 *    chroma), painted cyan, RGB (0, 255, 255): BT.601 Y 170 Cb 166 Cr 16 in limited range,
 *    Y 179 Cb 171 Cr 1 in full range;
 *  - inside: not touched; the bytes are the warp's.
 * "Inside" is the warp's own test per plane (pixel centres in or on the hull, chroma at its
 * siting), so the stabilized pixels are the warp's byte for byte. */
#define SH_WARP_OUTSIDE_LINE 2

typedef struct sh_warp_outside sh_warp_outside;

/* For frames of this format and size; full_range: the frames' range (black and the colour's
 * code values; ignored for RGB24). Everything a frame needs is allocated here. */
sh_status sh_warp_outside_create(sh_pixfmt format, int width, int height, int full_range,
                                 sh_warp_outside **out);
void sh_warp_outside_destroy(sh_warp_outside *o);

/* out holds sh_warp_apply's output of model for current: its pixels outside the hull become
 * current's dimmed, or the boundary colour. The pixel runs of each row are made once per hull
 * (again only when the model's hull or the frames' siting differs from the last call's);
 * allocation-free. */
sh_status sh_warp_outside_apply(sh_warp_outside *o, const sh_warp_model *model,
                                const sh_image *current, sh_image *out);

#ifdef __cplusplus
}
#endif
#endif
