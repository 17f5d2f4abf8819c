/* stillheart track --landmarks N (issue 19): the tissue's landmarks as extra rows of the points
 * file, with ids from SH_LANDMARK_ID_BASE (landmark k: base + k). The reference is frame 0, or
 * the frame --reference names ("frame 0" below): there they are chosen, and their rows give their
 * reference positions; in each later frame the accepted ones (landmarks.h's tests) are written, so
 * that `stillheart warp` (with the same --reference) and stillheart-eval take them as
 * correspondences like the markers they share with that frame. Frames before it have none.
 * With a calibrated rig (--cameras, two or three videos) they are chosen in camera 0 and matched
 * in the other cameras, frame by frame, each search started on the epipolar line of camera 0's
 * position and its reference window warped by the local affine of the markers' map into that
 * camera (as camera 0 does unless --landmarks-square), by sh_landmarks_rig: a landmark's row carries
 * the X, Y, Z triangulated from every camera that accepted it, and is written only when camera 0
 * and at least one other accepted it and the triangulation reprojects within
 * SH_LANDMARKS_MAX_REPROJ_PX in each (docs/landmarks.md, "In 3D"); a landmark not matched so in
 * frame 0 has no reference in 3D and is never written. Private to src/app. */
#ifndef STILLHEART_APP_TRACK_LANDMARKS_H
#define STILLHEART_APP_TRACK_LANDMARKS_H

#include <stdio.h>

#include "stillheart/calib.h"
#include "stillheart/detect.h"
#include "stillheart/image.h"
#include "stillheart/landmarks.h"
#include "stillheart/points.h"

typedef struct {
    int n;                 /* up to n landmarks */
    int sparse, affine;    /* --landmarks-sparse, not --landmarks-square */
    int carry;             /* --landmarks-carry (2D): frames with fewer than 3 markers carried by
                            * the landmarks (landmarks.h, "Carried frames") */
    int ncam;              /* videos; with calib and ncam > 1, landmarks in 3D */
    int full_range;        /* the videos' samples are full range (sh_landmarks_highlight_level) */
    const sh_calib *calib; /* NULL: 2D (camera 0 alone) */
    int refine;            /* --landmarks-refine (sh_landmarks_params.refine) */
    int confirm;           /* --landmarks-confirm (sh_landmarks_params.confirm); 0: the tests' own */
    int reference;         /* --reference: the frame they are chosen in */
} track_landmarks_options;

typedef struct {
    int chosen;                                /* landmarks chosen in frame 0 */
    int in_3d;                                 /* of them, matched and triangulated in frame 0 */
    long long verdicts[SH_LANDMARK_VERDICTS];  /* camera 0's landmark-frames by verdict */
    long long unmatched;  /* 3D: accepted in camera 0, by no other camera */
    long long inconsistent; /* 3D: accepted in two or more, refused by the reprojection test */
    long long carried;      /* --landmarks-carry: frames with fewer than 3 markers whose landmarks
                             * were written */
    long long not_carried;  /* and those searched whose landmarks did not vouch for the map */
} track_landmarks_stats;

typedef struct track_landmarks track_landmarks;

/* The reference frame o->reference (frames: one image per camera): up to o->n landmarks inside
 * the hull of camera 0's marker rows and off the tags detected there; their rows written
 * (measured: the nmeasured ids of the rows detected there, which --landmarks-carry's first frame
 * checks against). 0, or 1 with the reason printed. With fewer than 3 marker rows there is no
 * hull: a warning, 0 and *tl NULL (the markers go on without landmarks). */
int track_landmarks_start(const track_landmarks_options *o, const sh_image *frames, const sh_detection *dets, int ndet,
                          const sh_point *rows, int nrows, const int *measured, int nmeasured, FILE *out,
                          track_landmarks **tl);
/* Frame f: each landmark predicted by the markers' map (TPS on the marker rows f shares with
 * frame 0), found and judged (in 3D, in every camera); the accepted ones written. With carry, a
 * frame with 2 such rows (fewer than the map's 3) right after a frame whose landmarks were
 * written: predicted from that frame's, and written when they vouch for the map
 * (sh_landmarks_carry) at the markers detected in both frames (measured: the nmeasured ids of
 * the rows that are this frame's detections, not the tracker's predictions). 0, or 1 with the
 * reason printed. */
int track_landmarks_frame(track_landmarks *tl, const sh_image *frames, int f, const sh_point *rows, int nrows,
                          const int *measured, int nmeasured, FILE *out);
void track_landmarks_stats_get(const track_landmarks *tl, track_landmarks_stats *s);
void track_landmarks_destroy(track_landmarks *tl);

#endif
