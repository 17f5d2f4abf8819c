/* Private to src/warp: the model's layout and the span interface between the map (model.c)
 * and the pixel loops (sample.c). */
#ifndef STILLHEART_WARP_INTERNAL_H
#define STILLHEART_WARP_INTERNAL_H

#include "stillheart/warp.h"

typedef enum { MODEL_AFFINE, MODEL_TRIANGLES, MODEL_GRID } model_kind;

struct sh_warp_model {
    model_kind kind;
    const sh_interp *interp;
    int n, width, height;
    sh_hull hull;
    sh_warp_options opts;
    double *coef;            /* num_coefs x 2 */
    double affine[6];        /* x = a0 + a1 X + a2 Y, y = a3 + a4 X + a5 Y */

    int ntri;
    const int *tri;          /* owned by interp */
    double *tri_map;         /* per triangle: an affine map as in affine[] */
    double *tri_ybounds;     /* per triangle: ymin, ymax of the reference triangle */
    const double *ref_xy;    /* copy, n x 2 */
    double *disp;            /* displacement of the last update, n x 2 */

    int h, gx0, gy0, nx, ny; /* grid: node (i, j) sits at (gx0 + i h, gy0 + j h) */
    int *row_start, *index;  /* CSR basis rows, one per node */
    double *weight;
    double *map;             /* per node: current x, y */
    double error_bound;
    int refinements;
};

/* One stretch of a plane row over which the source position moves linearly:
 * pixel x in [x0, x1] samples the source plane at (sx + (x - x0) dsx, sy + (x - x0) dsy). */
typedef struct {
    int x0, x1;
    double sx, sy, dsx, dsy;
} warp_span;

/* Where a plane's pixels sit in full-resolution coordinates: X = scale * x + ox. */
typedef struct {
    double scale, ox, oy;
    int width, height;
} plane_geometry;

typedef void (*span_sink)(void *ctx, const warp_span *span);

/* Calls sink for every span of plane row py inside the hull, in increasing x, splitting long
 * spans so that fixed-point stepping stays exact to 1e-3 px. */
void warp_model_row_spans(const sh_warp_model *model, const plane_geometry *geom, int py,
                          span_sink sink, void *ctx);

/* Prepares the pixel loops' tables; called once before the first span. */
void warp_sample_init(void);

/* Pixel loops: fill dst[x0..x1] (plane row) by bilinear sampling of src along the span;
 * black (value `black` in every channel) where the position leaves the source plane. */
void warp_sample_span(const sh_plane *src, int channels, uint8_t black, uint8_t *dst_row,
                      const warp_span *span);

#endif
