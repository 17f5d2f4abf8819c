/* stillheart track --landmarks (track_landmarks.h). */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "stillheart/hull.h"
#include "stillheart/interp.h"
#include "stillheart/log.h"
#include "track_landmarks.h"

struct track_landmarks {
    sh_landmarks *lm;
    int n;
    sh_point *ref;     /* frame 0's marker rows, sorted by id */
    int nref;
    int *ids;          /* nref: the ids a frame shares with frame 0 */
    double *ref_xy, *cur_xy; /* nref pairs: frame 0's positions (for its hull), then per frame the
                              * shared markers' reference and current positions */
    float *pred, *xy;  /* n pairs */
    uint8_t *verdict;  /* n */
    sh_image gray;     /* RGB24 frames' luma */
    long long verdicts[SH_LANDMARK_VERDICTS];
};

static int by_id(const void *a, const void *b)
{
    int x = ((const sh_point *)a)->id, y = ((const sh_point *)b)->id;
    return (x > y) - (x < y);
}

static int fail(const char *what)
{
    sh_log_error("--landmarks: %s: %s", what, sh_error_message());
    return 1;
}

static const sh_plane *luma(track_landmarks *tl, const sh_image *f)
{
    const sh_plane *y;
    return sh_landmarks_luma(f, &tl->gray, &y) == SH_OK ? y : NULL;
}

/* The accepted landmarks of frame f (all of them at frame 0, at their reference positions). */
static int write_landmarks(const track_landmarks *tl, int f, const float *xy, FILE *out)
{
    for (int i = 0; i < tl->n; i++) {
        if (f > 0 && tl->verdict[i] != SH_LANDMARK_ACCEPTED) continue;
        if (fprintf(out, "%d,%d,%.4f,%.4f\n", f, SH_LANDMARK_ID_BASE + i, xy[2 * i], xy[2 * i + 1]) < 0) {
            sh_log_error("writing the points: write error");
            return 1;
        }
    }
    return 0;
}

int track_landmarks_start(int n, int sparse, int affine, const sh_image *frame, const sh_detection *dets, int ndet, const sh_point *rows,
                          int nrows, FILE *out, track_landmarks **out_tl)
{
    *out_tl = NULL;
    if (nrows < 3) {
        /* the markers are still tracked and written: only the landmarks are given up */
        sh_log_warn("--landmarks: frame 0 has %d markers, the hull that bounds the landmarks needs 3: "
                    "no landmarks", nrows);
        return 0;
    }
    track_landmarks *tl = calloc(1, sizeof *tl);
    double *tags = malloc(8 * (size_t)(ndet > 0 ? ndet : 1) * sizeof *tags);
    if (tl) {
        tl->ref = malloc((size_t)nrows * sizeof *tl->ref);
        tl->ids = malloc((size_t)nrows * sizeof *tl->ids);
        tl->ref_xy = malloc(2 * (size_t)nrows * sizeof *tl->ref_xy);
        tl->cur_xy = malloc(2 * (size_t)nrows * sizeof *tl->cur_xy);
    }
    if (!tl || !tags || !tl->ref || !tl->ids || !tl->ref_xy || !tl->cur_xy) {
        free(tags);
        track_landmarks_destroy(tl);
        sh_log_error("--landmarks: out of memory");
        return 1;
    }
    /* sorted by id, as sh_points_match walks them */
    memcpy(tl->ref, rows, (size_t)nrows * sizeof *rows);
    qsort(tl->ref, (size_t)nrows, sizeof *tl->ref, by_id);
    tl->nref = nrows;
    rows = tl->ref;
    for (int k = 0; k < nrows; k++) tl->ref_xy[2 * k] = rows[k].x, tl->ref_xy[2 * k + 1] = rows[k].y;
    for (int d = 0; d < ndet; d++)
        for (int k = 0; k < 4; k++) tags[8 * d + 2 * k] = dets[d].corner[k][0], tags[8 * d + 2 * k + 1] = dets[d].corner[k][1];
    sh_hull hull;
    sh_landmarks_params p;
    if (sparse)
        sh_landmarks_params_sparse(&p);
    else
        sh_landmarks_params_default(&p);
    p.affine = affine;
    p.max_points = n;
    const sh_plane *y = luma(tl, frame);
    int rc = 0;
    if (!y || sh_hull_compute(tl->ref_xy, nrows, &hull) != SH_OK ||
        sh_landmarks_create(&p, y, &hull, tags, ndet, &tl->lm) != SH_OK)
        rc = fail("frame 0");
    free(tags);
    if (!rc) {
        tl->n = sh_landmarks_count(tl->lm);
        tl->pred = malloc(2 * (size_t)(tl->n + 1) * sizeof *tl->pred);
        tl->xy = malloc(2 * (size_t)(tl->n + 1) * sizeof *tl->xy);
        tl->verdict = malloc((size_t)tl->n + 1);
        if (!tl->pred || !tl->xy || !tl->verdict) {
            sh_log_error("--landmarks: out of memory");
            rc = 1;
        }
    }
    if (!rc) {
        sh_log_info("%d landmarks chosen in frame 0 (ids %d on)", tl->n, SH_LANDMARK_ID_BASE);
        rc = write_landmarks(tl, 0, sh_landmarks_reference(tl->lm), out);
    }
    if (rc) {
        track_landmarks_destroy(tl);
        return rc;
    }
    *out_tl = tl;
    return 0;
}

/* The markers' map of the frame at every landmark (tl->pred): 0 when fewer than 3 markers are
 * shared with frame 0 (no landmark is written then: nothing to judge them by). */
static int predict(track_landmarks *tl, const sh_point *rows, int nrows)
{
    sh_point *cur = malloc((size_t)(nrows > 0 ? nrows : 1) * sizeof *cur);
    if (!cur) return 0;
    memcpy(cur, rows, (size_t)nrows * sizeof *cur);
    qsort(cur, (size_t)nrows, sizeof *cur, by_id);
    /* the shared markers' reference positions go into ref_xy (its whole-set use, the hull, is over) */
    int m = sh_points_match(tl->ref, tl->nref, cur, nrows, tl->ids, tl->ref_xy, tl->cur_xy);
    free(cur);
    if (m < 3) return 0;
    sh_interp_params ip;
    sh_interp_params_default(&ip, SH_METHOD_TPS);
    return sh_interp_map_points(&ip, tl->ref_xy, tl->cur_xy, m, sh_landmarks_reference(tl->lm), tl->n, tl->pred) ==
           SH_OK;
}

int track_landmarks_frame(track_landmarks *tl, const sh_image *frame, int f, const sh_point *rows, int nrows,
                          FILE *out)
{
    if (tl->n == 0 || !predict(tl, rows, nrows)) return 0;
    sh_landmarks_counts c;
    const sh_plane *y = luma(tl, frame);
    if (!y || sh_landmarks_track(tl->lm, y, tl->pred, tl->xy, tl->verdict, &c) != SH_OK) {
        sh_log_error("--landmarks: frame %d: %s", f, sh_error_message());
        return 1;
    }
    for (int v = 0; v < SH_LANDMARK_VERDICTS; v++) tl->verdicts[v] += c.verdicts[v];
    return write_landmarks(tl, f, tl->xy, out);
}

void track_landmarks_counts(const track_landmarks *tl, long long verdicts[SH_LANDMARK_VERDICTS], int *chosen)
{
    memcpy(verdicts, tl->verdicts, sizeof tl->verdicts);
    *chosen = tl->n;
}

void track_landmarks_destroy(track_landmarks *tl)
{
    if (!tl) return;
    sh_landmarks_destroy(tl->lm);
    sh_image_destroy(&tl->gray);
    free(tl->ref), free(tl->ids), free(tl->ref_xy), free(tl->cur_xy), free(tl->pred), free(tl->xy), free(tl->verdict);
    free(tl);
}
