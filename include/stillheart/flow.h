/* Sparse optical flow: the tissue's own points, chosen in one frame and followed into the next
 * (issue 19, natural landmarks).
 *
 * Two jobs, both on 8-bit luma planes:
 *  - sh_flow_corners picks well-textured points: the minimum eigenvalue of the gradients'
 *    structure tensor (Shi and Tomasi, "Good features to track", CVPR 1994), local maxima only,
 *    strongest first, no two closer than a given distance, only where the caller's mask allows
 *    (away from the tags, inside the hull, off specular highlights: the caller decides).
 *  - sh_flow_track follows points from one pyramid to the next with pyramidal Lucas-Kanade
 *    (J.-Y. Bouguet, "Pyramidal implementation of the Lucas Kanade feature tracker", Intel 2000).
 *
 * OpenCV's cv::goodFeaturesToTrack and cv::calcOpticalFlowPyrLK implement the same two papers
 * and are the oracle and the peer of this module (tests/oracle, tools/bench/bench_flow.cpp). The
 * tracker follows OpenCV's arithmetic where it decides a result: the pyramid is the 5-tap
 * binomial [1 4 6 4 1]/16 reduction, the gradients are Scharr's, the window's samples are
 * bilinear with 14-bit integer weights, and its stopping rules and the minimum-eigenvalue test
 * are the same, so the two agree to a few thousandths of a pixel on points both keep. The sums
 * are exact integers here (OpenCV adds floats), so the result is the same on every architecture.
 *
 * Coordinates: pixel (x, y) has its centre at (x, y), as everywhere in stillheart.
 * Nothing here allocates per frame: pyramids and scratch are sized at _create. */
#ifndef STILLHEART_FLOW_H
#define STILLHEART_FLOW_H

#include <stdint.h>

#include "stillheart/core.h"
#include "stillheart/image.h"

#ifdef __cplusplus
extern "C" {
#endif

#define SH_FLOW_MAX_LEVELS 6  /* pyramid levels above the base */
#define SH_FLOW_MAX_WIN 63    /* largest window side */

typedef struct {
    int win;          /* window side in pixels, odd, 5..SH_FLOW_MAX_WIN (21, as OpenCV's default) */
    int levels;       /* pyramid levels above the base, 0..SH_FLOW_MAX_LEVELS (3) */
    int max_iter;     /* Gauss-Newton steps per level, 1..100 (30) */
    double eps;       /* px: a level stops when its step is shorter (0.01) */
    double min_eig;   /* the window's smallest structure-tensor eigenvalue, normalized as
                       * OpenCV's minEigThreshold, below which a point is lost (1e-4) */
} sh_flow_params;

/* OpenCV's defaults for calcOpticalFlowPyrLK: win 21, 3 levels, 30 steps, 0.01 px, 1e-4. */
void sh_flow_params_default(sh_flow_params *p);

/* A frame's image pyramid, padded by the window so that windows reaching past the image edge
 * read its mirror (the edge pixel not repeated). A window's Scharr gradients are made with it,
 * from the pixels around it. */
typedef struct sh_flow_pyramid sh_flow_pyramid;

/* For frames of width x height (each at least 2 px; at most SH_IMAGE_MAX_SIZE) and params'
 * levels and window. A level smaller than the window is not built, as OpenCV does not build it:
 * the pyramid then has fewer levels (sh_flow_pyramid_levels). */
sh_status sh_flow_pyramid_create(int width, int height, const sh_flow_params *params,
                                 sh_flow_pyramid **out);
void sh_flow_pyramid_destroy(sh_flow_pyramid *pyr);
/* Levels above the base actually built (at most params->levels). */
int sh_flow_pyramid_levels(const sh_flow_pyramid *pyr);

/* Fills the pyramid from a luma plane of the size it was created for; SH_EINVAL otherwise.
 * gradients: also what each level's gradients are made of (the pixels next to those a window
 * reads), which only a pyramid tracked *from* needs (a fixed reference frame's, built once; or
 * every frame's when points go frame to frame). */
sh_status sh_flow_pyramid_build(sh_flow_pyramid *pyr, const sh_plane *luma, int gradients);

/* Builds only what searches near a box of points can read: box is x0, y0, x1, y1 (level 0 px,
 * x0 <= x1, y0 <= y1), and each level gets the pixels (and with gradients their neighbours)
 * that a window centred anywhere in the box scaled to the level reads, with what the levels above
 * are reduced from; the rest of the pyramid is left as it was. A search that would read anything
 * else stops with SH_FLOW_UNBUILT, so a point either gets the same result, bit for bit, as from
 * sh_flow_pyramid_build or that status (a caller then builds the whole frame and tracks it
 * again). luma need only hold valid pixels in sh_flow_pyramid_box_part's rectangle: the rest is
 * not read. For a fixed set of points moving in a known area of a larger frame (the landmarks
 * around their prediction) this is a fraction of the work. */
sh_status sh_flow_pyramid_build_box(sh_flow_pyramid *pyr, const sh_plane *luma, int gradients,
                                    const float box[4]);
/* A pyramid already built (whole, or for a box containing this one) made anew where searches
 * near box read it, from luma, keeping the rest and what counts as built: when luma differs from
 * the frame the pyramid was built from only inside box (level 0 px), the pyramid is then the one
 * sh_flow_pyramid_build gives for luma, bit for bit, at a fraction of the work (the plan of
 * sh_flow_pyramid_build_box keeps every pixel outside its parts clear of the box's pixels). With
 * the gradients the pyramid was built with. luma need only hold valid pixels in
 * sh_flow_pyramid_box_part's rectangle. SH_EINVAL when a part of a level reaches past what was
 * built there. The landmarks' reference, refined where its windows lie (landmarks.h, refine). */
sh_status sh_flow_pyramid_update_box(sh_flow_pyramid *pyr, const sh_plane *luma, const float box[4]);
/* The frame's pixels sh_flow_pyramid_build_box reads for box: [part[0], part[2]) x
 * [part[1], part[3]), within the frame. */
sh_status sh_flow_pyramid_box_part(const sh_flow_pyramid *pyr, const float box[4], int gradients,
                                   int part[4]);

typedef enum {
    SH_FLOW_OK = 0,     /* followed */
    SH_FLOW_FLAT,       /* its window's texture is too weak to locate it (min_eig) */
    SH_FLOW_OUTSIDE,    /* its window left the image */
    SH_FLOW_UNBUILT     /* its window reached a part of a pyramid that sh_flow_pyramid_build_box
                         * did not build (out is then where the search was) */
} sh_flow_status;

/* Follows n points from prev to next (pyramids of the same size and params; prev built with
 * its gradients, else SH_EINVAL). xy: x0,y0,... in prev; out: their positions in next.
 * status[i] says whether point i was followed; err[i] (may be NULL) is the mean absolute difference of the two windows at the
 * result, in grey levels (OpenCV's default error measure). When guess is not NULL it holds a
 * starting position in next for each point (OpenCV's OPTFLOW_USE_INITIAL_FLOW): the heartbeat
 * model's prediction. Points whose status is not OK have out set to their last estimate. out
 * may be xy or guess: each point is read before its result is written. */
sh_status sh_flow_track(const sh_flow_params *params, const sh_flow_pyramid *prev,
                        const sh_flow_pyramid *next, int n, const float *xy, const float *guess,
                        float *out, uint8_t *status, float *err);

/* A fixed previous frame's windows around fixed points, sampled once on every level (the
 * reference's around the landmarks, which are found in every new frame): what sh_flow_track
 * samples anew for each point on each call. prev: built with its gradients; xy: n points. It
 * holds 6 win * (win rounded up to 8) bytes a point and level (about 3 KB at the default window:
 * 2.4 MB for 200 points on 4 levels), allocated here. */
typedef struct sh_flow_windows sh_flow_windows;
sh_status sh_flow_windows_create(const sh_flow_params *params, const sh_flow_pyramid *prev, int n,
                                 const float *xy, sh_flow_windows **out);
void sh_flow_windows_destroy(sh_flow_windows *windows);
/* The windows sampled again, at the same points, from the pyramid they were made from, after it
 * changed (sh_flow_pyramid_update_box): as sh_flow_windows_create would make them now, without
 * allocating. */
void sh_flow_windows_refresh(sh_flow_windows *windows);
/* sh_flow_track from windows: the same results, bit for bit, as sh_flow_track(params, prev, next,
 * ...) with the prev and points they were made from, for m of their points: idx[j] (NULL: j) is
 * the point whose guess, out, status and err are at j. params as at _create. */
sh_status sh_flow_track_windows(const sh_flow_params *params, const sh_flow_windows *prev,
                                const sh_flow_pyramid *next, int m, const int *idx,
                                const float *guess, float *out, uint8_t *status, float *err);

/* sh_flow_track_windows with the previous frame's level-0 window of point j (at p) sampled
 * through the 2x2 matrix M = warp + 4 j (row major; warp NULL: sh_flow_track_windows itself):
 * T(d) = prev(p + M d) for each offset d of the window, and the step's gradients T's own (Scharr,
 * as the pyramid's). Translation-only Lucas-Kanade is biased where the tissue deforms across the
 * window; when the next frame is the previous one under a local affine J about the point, M =
 * J^-1 makes the window the next frame shows about the match, which a translation then fits.
 * The levels above keep the square windows: they only bring the search near. The samples step in
 * fixed point and their bilinear weights are rounded to 1/128 px (integers only: the same result
 * on every architecture). The pyramid the windows were made from must be kept, unchanged, while
 * they are used with a warp: the level-0 windows are sampled from it. */
sh_status sh_flow_track_windows_warped(const sh_flow_params *params, const sh_flow_windows *prev,
                                       const sh_flow_pyramid *next, int m, const int *idx,
                                       const float *guess, const float *warp, float *out,
                                       uint8_t *status, float *err);

/* The mean absolute difference, in grey levels, of two side x side windows of level 0: prev's
 * centred at (px, py) and next's at (qx, qy), each sampled with the searches' bilinear weights
 * (14 bits) in 1/32 grey levels, as sh_flow_track's error measure is over its whole window. NaN
 * where a window is not inside the part of its pyramid that was built (a window may reach one
 * window's width past the level's edge, into the mirrored border), or side is not odd in
 * 1..SH_FLOW_MAX_WIN. The landmarks' test of the window's centre: whether the point itself, not
 * only most of the window around it, looks as it did. */
float sh_flow_window_difference(const sh_flow_pyramid *prev, float px, float py, const sh_flow_pyramid *next,
                                float qx, float qy, int side);
/* The normalized cross-correlation (Pearson's r, -1 to 1) of the same two windows, sampled as
 * sh_flow_window_difference samples them; NaN where it is NaN, or where either window is flat.
 * The landmarks' test of the window's structure: a uniform occluder leaves the frame's window
 * noise, which correlates with the reference's texture no better than chance, where texture too
 * faint for the difference to tell from noise still correlates. */
float sh_flow_window_correlation(const sh_flow_pyramid *prev, float px, float py, const sh_flow_pyramid *next,
                                 float qx, float qy, int side);

typedef struct {
    int max_points;      /* at most this many, strongest first */
    double quality;      /* relative to the strongest response in the mask (0.01) */
    double min_distance; /* px between any two chosen points (10) */
    int block;           /* side of the gradients' summing window, odd, 3..31 (3 as OpenCV) */
    /* 0 (OpenCV's order, the default): strongest first over the whole mask. N > 0: each corner
     * ranked by its response over the strongest in its N x N cell of the plane (cells from its
     * top left), that strongest taken as at least balance_floor times the mask's strongest: a
     * cell of strong texture keeps its order, a cell of weak but trackable texture has its best
     * corners taken with the strong cells' middling ones rather than after all of them. 0..4096 */
    int balance_cell;
    double balance_floor; /* 0..1; with balance_cell (0: each cell's strongest ranks first) */
} sh_flow_corner_params;

void sh_flow_corner_params_default(sh_flow_corner_params *p);

/* Chooses up to params->max_points corners of luma, writing x0,y0,... into xy (room for
 * max_points pairs) and the count into *n. mask (may be NULL) is a plane of the same size: a
 * pixel may become a corner only where it is non-zero. Responses are local maxima of the
 * minimum eigenvalue over 3x3 pixels, at least quality times the strongest in the mask, taken
 * strongest first (ties by position, so the choice is the same on every run; with
 * balance_cell, strongest for their cell) with no two closer than min_distance. About 8 bytes
 * of scratch a pixel (the gradients, then the responses) are allocated per call: this runs
 * once per reference or re-seeding, not per frame. */
sh_status sh_flow_corners(const sh_plane *luma, const sh_plane *mask,
                          const sh_flow_corner_params *params, float *xy, int *n);

#ifdef __cplusplus
}
#endif
#endif
