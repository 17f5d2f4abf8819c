/* Private to src/warp: the model's layout and the span interface between the map (model.c, grid.c)
 * and the pixel loops (sample.c). */
#ifndef STILLHEART_WARP_INTERNAL_H
#define STILLHEART_WARP_INTERNAL_H

#include "stillheart/warp.h"

/* Rows per band of the triangle index. */
#define TRIANGLE_BAND 16

typedef enum { MODEL_AFFINE, MODEL_TRIANGLES, MODEL_GRID } model_kind;

struct sh_warp_model {
    model_kind kind;
    const sh_interp *interp;
    int n, width, height;
    sh_hull hull;
    sh_warp_options opts;
    double *coef;            /* num_coefs x 2 */
    double affine[6];        /* x = a0 + a1 X + a2 Y, y = a3 + a4 X + a5 Y */

    /* Triangles: those of every point (the interp's), or after an update through a subset those
     * of the used points alone (sub below); tri, ntri, tri_ybounds, band_start, band_tris and
     * span_start point at the set in use. */
    int ntri;
    const int *tri;          /* the interp's, or sub_tri */
    double *tri_map;         /* per triangle: an affine map as in affine[] (room for both sets) */
    double *tri_ybounds;     /* per triangle: ymin, ymax of the reference triangle */
    int bands;               /* triangles per band of rows: band b lists band_tris[band_start[b] */
    double band_origin;      /*   .. band_start[b + 1]), rows from band_origin + b * band */
    int *band_start, *band_tris;
    int *span_start;         /* full-resolution row y: spans[3 span_start[y] .. 3 span_start[y + 1]) */
    int32_t *spans;          /*   as (triangle or -1 for none, first pixel, last pixel); span_start */
                             /*   NULL for a subset's triangles: the rows find them through the bands */
    double *ybounds_all;     /* every point's (the interp's triangles): what they own */
    int *band_start_all, *band_tris_all, *span_start_all;
    void *tri_work;          /* a subset's: made by the first subset update, for any subset */
    int *sub_tri, *sub_index; /* (sh_interp_delaunay's work; 6n; the used points' indices, n; */
    double *sub_ybounds;     /*   2n triangles at most; bands + 1; bands x 2n; bands) */
    int *sub_band_start, *sub_band_tris, *sub_band_next;
    const double *ref_xy;    /* copy, n x 2 */
    double *disp;            /* displacement of the last update, n x 2 */
    void *subset_work;       /* sh_interp_fit_subset's, made by the first subset update */
    double *subset_xy;       /* its scratch: the used points' reference positions, for their hull */
    sh_hull hull_all;        /* every point's hull (hull: the last update's points') */

    int h, gx0, gy0, nx, ny; /* grid: node (i, j) sits at (gx0 + i h, gy0 + j h): the one the */
                             /*   last update's map is on (fill, bound), which may be the */
                             /*   coarse level of the grid built (below) */
    int bh, bnx, bny;        /* the grid built: its spacing and nodes, (bnx - 1) and (bny - 1) even */
    double *bmap;            /*   its map; map points at bmap or cmap */
    double *cmap;            /* the coarse level's (dense rows): nodes of even i and j, spacing 2 bh */
    int pass;                /* what warp_model_grid_rows makes (grid.c, GRID_PASS_*) */
    int *row_start, *index;  /* CSR basis rows, one per node */
    double *weight;
    float *dense;            /* or, when every row holds every coefficient in order: */
    int dense_terms;         /*   nodes x dense_terms weights (grid.c's chunks), and no CSR; */
    double *dense_coef;      /*   grid_map's scratch: the x coefficients, then the y ones; */
    int *dense_used, dense_nused; /* the terms whose coefficients are not both 0 */
    double *map;             /* per node: current x, y */
    int sep_n;               /* > 0: the kernel terms factor per axis (Gaussian), n of them; */
    double *sep_x;           /*   per pair of node columns, per k: their two factors; */
    double *sep_y;           /*   per node row: the n factors; the CSR rows hold only the rest */
    double *sep_row;         /*   (affine terms). Scratch: 4n per thread (sep_slots of them), */
    int sep_slots;           /*   coef times one row's factors */
    double *curvature;       /* per node: second differences (grid_error_bound's scratch) */
    double error_bound;
    int refinements;
};

/* grid.c: the grid of spacing h over every point's hull, its basis rows made (the old grid
 * freed first); and everything it holds freed. */
sh_status warp_grid_build(sh_warp_model *m, int h);
void warp_grid_free(sh_warp_model *m);
/* Its largest interpolation error, from the map's second differences at the nodes. */
double warp_grid_error_bound(sh_warp_model *m);

/* The grid's node rows j0..j1-1 of the last fit, thread `slot` of those the update was made
 * for (warp_model_update_with). Rows apart write apart: threads may share a map. */
void warp_model_grid_rows(sh_warp_model *m, int j0, int j1, int slot);

/* Makes all `rows` node rows of m's grid with warp_model_grid_rows, on up to `slots` threads. */
typedef void (*warp_grid_fn)(void *ctx, sh_warp_model *m, int rows);

/* The grid's map from the last fit, on this thread (map NULL) or by map over `slots` threads,
 * and its bound (m->error_bound). With coarse_ok and dense rows, the coarse level first: kept
 * when its bound is within max_error (m->h is then 2 bh). */
sh_status warp_grid_map(sh_warp_model *m, warp_grid_fn map, void *ctx, int slots, int coarse_ok);

/* sh_warp_model_update_subset with the grid's map made by map(ctx, ...) (NULL: here, on this
 * thread). */
sh_status warp_model_update_with(sh_warp_model *m, const double *cur_xy, const unsigned char *use,
                                 warp_grid_fn map, void *ctx, int slots);

/* Where a plane's pixels sit in full-resolution coordinates: X = scale * x + ox. */
typedef struct {
    double scale, ox, oy;
    int width, height;
} plane_geometry;

/* The scale and offsets of plane p of img (chroma siting of 4:2:0 planes); width and height
 * are left to the caller. */
void warp_plane_offsets(const sh_image *img, int p, plane_geometry *g);

/* Source positions are 16.16 fixed point; anything beyond +-2^14 px (outside every frame) is
 * clamped to that, so the int32 never overflows. */
#define WARP_FRAC_BITS 16
#define WARP_COORD_LIMIT (1 << 30)

/* Lists the triangles' spans of every full-resolution row (after the bands), so that a frame's
 * row fill only evaluates the triangles' affine maps. */
sh_status warp_model_list_spans(sh_warp_model *m);

/* Pixels [*first, *last] of plane row py lie inside the hull; returns 0 when none do. */
int warp_model_row_extent(const sh_warp_model *model, const plane_geometry *geom, int py,
                          int *first, int *last);

/* Source positions (source plane coordinates, 16.16) of the row's pixels first..last, as
 * given by warp_model_row_extent, into fx[0..last-first] and fy[...]. */
void warp_model_row_fill(const sh_warp_model *model, const plane_geometry *geom, int py,
                         int first, int last, int32_t *fx, int32_t *fy);

/* Prepares the pixel loops' tables; called once before the first row. */
void warp_sample_init(void);

/* Fills dst[0..count-1] (pixels, `channels` bytes each) by bilinear sampling of src at the
 * positions fx, fy; black (`black` in every channel) where a position leaves the plane. */
void warp_sample_row(const sh_plane *src, int channels, uint8_t black, uint8_t *dst,
                     const int32_t *fx, const int32_t *fy, int count);

/* One-channel planes take the widest loop the CPU has (x86-64: AVX-512, else AVX2, else SSE2;
 * chosen in warp_sample_init). This puts the widest one up to `wanted` in use instead (0 the
 * build's own SIMD path, 1 AVX2, 2 AVX-512), so tests and benches can run each on one machine;
 * returns the level now in use. Not to be called while another thread samples. */
int warp_sample_path(int wanted);

/* TPS's dense grid rows take AVX2 where the CPU has it (grid.c, four nodes a register, the
 * same bits). This puts AVX2 (wanted 1, where the CPU has it) or the build's own path (0) in use, for
 * tests and benches; returns the level now in use. Not to be called while another thread maps. */
int warp_grid_dense_path(int wanted);

/* The RGB path's definition in portable C: the SSE2 and NEON paths of warp_sample_row give
 * exactly these bytes (tests/unit/test_sample_simd.c). */
void warp_sample_row_rgb_portable(const sh_plane *src, uint8_t black, uint8_t *dst,
                                  const int32_t *fx, const int32_t *fy, int count);

/* The same for one-channel planes: one rounding of the exact bilinear sum. */
void warp_sample_row_gray_portable(const sh_plane *src, uint8_t black, uint8_t *dst,
                                   const int32_t *fx, const int32_t *fy, int count);

#endif
