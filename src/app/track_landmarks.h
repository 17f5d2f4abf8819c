/* stillheart track --landmarks N (issue 19): the tissue's landmarks as extra rows of the points
 * file, with ids from SH_LANDMARK_ID_BASE (landmark k: base + k). The reference is frame 0:
 * there they are chosen, and their rows give their reference positions; in each later frame the
 * accepted ones (landmarks.h's tests) are written, so that `stillheart warp` and stillheart-eval
 * take them as correspondences like the markers they share with frame 0. Private to src/app. */
#ifndef STILLHEART_APP_TRACK_LANDMARKS_H
#define STILLHEART_APP_TRACK_LANDMARKS_H

#include <stdio.h>

#include "stillheart/detect.h"
#include "stillheart/image.h"
#include "stillheart/landmarks.h"
#include "stillheart/points.h"

typedef struct track_landmarks track_landmarks;

/* Frame 0 of camera 0: up to n landmarks (with sparse, sh_landmarks_params_sparse's tests), inside the hull of its marker rows and off the tags
 * detected there; their rows written. 0, or 1 with the reason printed. With fewer than 3 marker
 * rows there is no hull: a warning, 0 and *tl NULL (the markers go on without landmarks). */
int track_landmarks_start(int n, int sparse, int affine, const sh_image *frame, const sh_detection *dets, int ndet, const sh_point *rows,
                          int nrows, FILE *out, track_landmarks **tl);
/* Frame f: each landmark predicted by the markers' map (TPS on the marker rows f shares with
 * frame 0), found and judged; the accepted ones written. 0, or 1 with the reason printed. */
int track_landmarks_frame(track_landmarks *tl, const sh_image *frame, int f, const sh_point *rows, int nrows,
                          FILE *out);
/* Landmark-frames by verdict so far, and how many landmarks were chosen. */
void track_landmarks_counts(const track_landmarks *tl, long long verdicts[SH_LANDMARK_VERDICTS], int *chosen);
void track_landmarks_destroy(track_landmarks *tl);

#endif
