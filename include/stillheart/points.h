/* The points file: marker positions per frame, CSV with the header `frame,id,x,y`
 * (optionally followed by X,Y,Z columns for 3D markers), or `frame,id,X,Y,Z` (3D markers from
 * another tracker, no image positions: `stillheart warp3d` only), one row per visible marker
 * per frame. frame is the 0-based index into the video; id a non-negative marker id. */
#ifndef STILLHEART_POINTS_H
#define STILLHEART_POINTS_H

#include <stdio.h>

#include "stillheart/core.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Largest frame index accepted (about 46 hours at 60 fps): bounds the frame index a damaged
 * file can make us allocate. */
#define SH_POINTS_MAX_FRAME 10000000

typedef struct {
    int frame;
    int id;
    double x, y;    /* NaN when the file has no 2D columns (SH_POINTS_XYZ_ONLY) */
    double X, Y, Z; /* NaN when the file has no 3D columns */
} sh_point;

/* has_3d of a `frame,id,X,Y,Z` file; has_3d is 1 for `frame,id,x,y,X,Y,Z`, 0 for 2D only. */
#define SH_POINTS_XYZ_ONLY 2

typedef struct {
    sh_point *rows;  /* sorted by frame, then id */
    int count;
    int has_3d;      /* 0, 1 or SH_POINTS_XYZ_ONLY (no x, y) */
    int max_frame;   /* -1 when empty */
    int *frame_start;/* max_frame + 2 entries: rows of frame f are [frame_start[f], frame_start[f+1]) */
} sh_points;

/* Reads a whole points file ("-" = stdin). A bad header or row fails with the file name and
 * line number; a duplicated (frame, id) pair is an error too, and so is a last line without its
 * newline (a file cut inside a number would otherwise give a wrong, well-formed value). Every
 * number is a whole field: "2.5x" or "2 3" is refused, not read as 2.5 or 2. */
sh_status sh_points_read(const char *path, sh_points *points);
/* Parses a file already in memory (name used in messages). */
sh_status sh_points_parse(const char *text, size_t len, const char *name, sh_points *points);
void sh_points_destroy(sh_points *points);
/* SH_OK when the points have image positions (x, y), else SH_EFORMAT naming the file (name) and
 * its header: for whoever reads x, y (a 2D warp, a hull, test mode of the daemon). */
sh_status sh_points_need_2d(const sh_points *points, const char *name);

/* Removes every row whose id is min_id or more (landmark rows, SH_LANDMARK_ID_BASE, for a method
 * they do not help); frames keep their numbers. Returns how many rows went. */
int sh_points_drop_ids(sh_points *points, int min_id);

/* Rows of one frame (count 0 for frames beyond the file). */
const sh_point *sh_points_frame(const sh_points *points, int frame, int *count);

/* The markers two frames share: walks both lists (sorted by id, as sh_points_frame returns
 * them) and writes, for each id found in both, the id, the reference frame's x, y (into ref_xy,
 * when not NULL) and the current frame's. Returns the count (at most min(nref, ncur)). */
int sh_points_match(const sh_point *ref, int nref, const sh_point *cur, int ncur, int *ids,
                    double *ref_xy, double *cur_xy);
/* The same for 3D: only ids whose rows have finite X, Y, Z in both frames; writes the ids and the
 * current frame's X, Y, Z (3 a point). Returns the count. */
int sh_points_match_xyz(const sh_point *ref, int nref, const sh_point *cur, int ncur, int *ids,
                        double *cur_xyz);
/* The same for a 3D model that holds every landmark of the reference and fits each frame through
 * the ones it has (sh_warp3d_model_update_subset): the markers both frames have with X, Y, Z (ids
 * below min_id), then every reference row from min_id on with X, Y, Z, in id order; cur_xyz their
 * current positions (a landmark the frame lacks, or has without X, Y, Z: its reference position)
 * and use[k] whether the frame has it (use may be NULL). Returns the count; *used: how many are
 * used. */
int sh_points_match_xyz_keep(const sh_point *ref, int nref, const sh_point *cur, int ncur, int min_id, int *ids,
                             double *cur_xyz, unsigned char *use, int *used);

/* Writes rows as CSV with the header: frame,id,x,y, and X,Y,Z when has_3d; has_3d
 * SH_POINTS_XYZ_ONLY leaves out x,y. */
sh_status sh_points_write(FILE *out, const sh_point *rows, int count, int has_3d);

#ifdef __cplusplus
}
#endif
#endif
