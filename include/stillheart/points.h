/* The points file: marker positions per frame, CSV with the header `frame,id,x,y`
 * (optionally followed by X,Y,Z columns for 3D markers), one row per visible marker per frame.
 * frame is the 0-based index into the video; id a non-negative marker id. */
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
    double x, y;
    double X, Y, Z; /* NaN when the file has no 3D columns */
} sh_point;

typedef struct {
    sh_point *rows;  /* sorted by frame, then id */
    int count;
    int has_3d;
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

/* Rows of one frame (count 0 for frames beyond the file). */
const sh_point *sh_points_frame(const sh_points *points, int frame, int *count);

/* The markers two frames share: walks both lists (sorted by id, as sh_points_frame returns
 * them) and writes, for each id found in both, the id and the current frame's x, y. Returns the
 * count (at most min(nref, ncur)). */
int sh_points_match(const sh_point *ref, int nref, const sh_point *cur, int ncur, int *ids,
                    double *cur_xy);

/* Writes rows as CSV with the header (and the 3D columns when has_3d). */
sh_status sh_points_write(FILE *out, const sh_point *rows, int count, int has_3d);

#ifdef __cplusplus
}
#endif
#endif
