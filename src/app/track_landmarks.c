/* stillheart track --landmarks (track_landmarks.h). */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "stillheart/camera.h"
#include "stillheart/hull.h"
#include "stillheart/interp.h"
#include "stillheart/log.h"
#include "stillheart/warp3d.h"
#include "track_landmarks.h"

#define MAXCAM SH_CALIB_MAX_CAMERAS

struct track_landmarks {
    sh_landmarks *lm;
    sh_landmarks *lm_other; /* 3D: the other cameras' searches (affine windows), unless lm's are */
    int n;
    int ncam;              /* > 1: landmarks in 3D */
    const sh_calib *calib;
    sh_point *ref;         /* frame 0's marker rows, sorted by id */
    int nref;
    int *ids;              /* nref: the ids a frame shares with frame 0 */
    double *ref_xy, *cur_xy; /* nref pairs: frame 0's positions (for its hull), then per frame the
                              * shared markers' reference positions and where a camera sees them */
    float *pred;           /* n pairs */
    float *xy[MAXCAM];     /* n pairs a camera: each landmark's position */
    uint8_t *verdict[MAXCAM];
    double *X;             /* 3D: n x 3, the frame's triangulated positions */
    uint8_t *in3d;         /* 3D: 1 where frame 0 triangulated the landmark (its reference) */
    uint8_t *keep;         /* n: written in this frame */
    sh_image gray[MAXCAM]; /* RGB24 frames' luma */
    track_landmarks_stats stats;
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

static const sh_plane *luma(track_landmarks *tl, int c, const sh_image *f)
{
    const sh_plane *y;
    return sh_landmarks_luma(f, &tl->gray[c], &y) == SH_OK ? y : NULL;
}

/* Frame f's rows: the landmarks marked in tl->keep, camera 0's position (and X, Y, Z in 3D). */
static int write_landmarks(const track_landmarks *tl, int f, const float *xy, FILE *out)
{
    for (int i = 0; i < tl->n; i++) {
        if (!tl->keep[i]) continue;
        int rc = tl->ncam > 1 ? fprintf(out, "%d,%d,%.4f,%.4f,%.5f,%.5f,%.5f\n", f, SH_LANDMARK_ID_BASE + i, xy[2 * i],
                                        xy[2 * i + 1], tl->X[3 * i], tl->X[3 * i + 1], tl->X[3 * i + 2])
                              : fprintf(out, "%d,%d,%.4f,%.4f\n", f, SH_LANDMARK_ID_BASE + i, xy[2 * i], xy[2 * i + 1]);
        if (rc < 0) {
            sh_log_error("writing the points: write error");
            return 1;
        }
    }
    return 0;
}

/* The markers' map from camera 0's reference to camera c in this frame at every landmark
 * (tl->pred): TPS on the marker rows cur (sorted by id) shares with frame 0, where camera c sees
 * them (camera 0: the rows' x, y; another: their X, Y, Z projected). 0 when fewer than 3. */
static int predict(track_landmarks *tl, int c, const sh_point *cur, int ncur)
{
    int m = 0;
    if (c == 0) {
        /* the shared markers' reference positions go into ref_xy (its whole-set use, the hull, is over) */
        m = sh_points_match(tl->ref, tl->nref, cur, ncur, tl->ids, tl->ref_xy, tl->cur_xy);
    } else {
        for (int i = 0, j = 0; i < tl->nref && j < ncur;) {
            if (tl->ref[i].id < cur[j].id) {
                i++;
            } else if (tl->ref[i].id > cur[j].id) {
                j++;
            } else {
                double X[3] = {cur[j].X, cur[j].Y, cur[j].Z}, uv[2];
                if (isfinite(X[0]) && isfinite(X[1]) && isfinite(X[2]) &&
                    sh_camera_project(&tl->calib->cam[c], X, uv, NULL) == SH_OK) {
                    tl->ref_xy[2 * m] = tl->ref[i].x, tl->ref_xy[2 * m + 1] = tl->ref[i].y;
                    tl->cur_xy[2 * m] = uv[0], tl->cur_xy[2 * m + 1] = uv[1];
                    m++;
                }
                i++, j++;
            }
        }
    }
    if (m < 3) return 0;
    sh_interp_params ip;
    sh_interp_params_default(&ip, SH_METHOD_TPS);
    return sh_interp_map_points(&ip, tl->ref_xy, tl->cur_xy, m, sh_landmarks_reference(tl->lm), tl->n, tl->pred) ==
           SH_OK;
}

/* Moves camera c's prediction p of a landmark that camera 0 sees at x0 onto the epipolar line of
 * x0: the point of camera 0's ray nearest camera c's ray through p, seen by camera c. The map's
 * error across the line is gone; what is left lies along it, where depth decides. Unchanged when
 * the rays are parallel or the point is not in front of both cameras. */
static void onto_epipolar_line(const track_landmarks *tl, int c, const float x0[2], float p[2])
{
    double C0[3], d0[3], Cc[3], dc[3];
    if (!sh_warp3d_ray(&tl->calib->cam[0], x0[0], x0[1], C0, d0) || !sh_warp3d_ray(&tl->calib->cam[c], p[0], p[1], Cc, dc))
        return;
    double w[3] = {C0[0] - Cc[0], C0[1] - Cc[1], C0[2] - Cc[2]};
    double b = d0[0] * dc[0] + d0[1] * dc[1] + d0[2] * dc[2];
    double d = d0[0] * w[0] + d0[1] * w[1] + d0[2] * w[2];
    double e = dc[0] * w[0] + dc[1] * w[1] + dc[2] * w[2];
    double den = 1 - b * b; /* both directions are unit vectors */
    if (den < 1e-12) return;
    double s = (b * e - d) / den;
    if (!(s > 0)) return;
    double X[3] = {C0[0] + s * d0[0], C0[1] + s * d0[1], C0[2] + s * d0[2]}, uv[2];
    if (sh_camera_project(&tl->calib->cam[c], X, uv, NULL) != SH_OK) return;
    p[0] = (float)uv[0], p[1] = (float)uv[1];
}

/* Camera c (> 0) of the frame: every landmark searched from its prediction moved onto the
 * epipolar line of camera 0's position (tl->xy[0]), through affine windows, and judged. Without
 * a prediction (fewer than 3 markers with X, Y, Z) every landmark is lost there. 0, or 1 with the
 * reason printed. */
static int match_camera(track_landmarks *tl, int c, const sh_image *frame, int f, const sh_point *cur, int ncur)
{
    if (!predict(tl, c, cur, ncur)) {
        memset(tl->verdict[c], SH_LANDMARK_LOST, (size_t)tl->n);
        return 0;
    }
    for (int i = 0; i < tl->n; i++) onto_epipolar_line(tl, c, &tl->xy[0][2 * i], &tl->pred[2 * i]);
    const sh_plane *y = luma(tl, c, frame);
    if (!y || sh_landmarks_track(tl->lm_other ? tl->lm_other : tl->lm, y, tl->pred, tl->xy[c], tl->verdict[c], NULL) != SH_OK) {
        sh_log_error("--landmarks: camera %d, frame %d: %s", c, f, sh_error_message());
        return 1;
    }
    return 0;
}

/* Landmark i in 3D from camera 0's position and every other camera that accepted it, into
 * tl->X: 1; 0 when no other camera did; -1 when the triangulation is refused (a view farther than
 * TRACK_LANDMARKS_MAX_REPROJ_PX from it, or degenerate). */
static int triangulate(track_landmarks *tl, int i)
{
    const sh_calib_camera *cams[MAXCAM];
    double uv[2 * MAXCAM];
    int n = 0;
    for (int c = 0; c < tl->ncam; c++) {
        if (c > 0 && tl->verdict[c][i] != SH_LANDMARK_ACCEPTED) continue;
        cams[n] = &tl->calib->cam[c];
        uv[2 * n] = tl->xy[c][2 * i], uv[2 * n + 1] = tl->xy[c][2 * i + 1];
        n++;
    }
    if (n < 2) return 0;
    sh_triangulation t;
    if (sh_camera_triangulate(cams, uv, n, 1, 0, &t) != SH_OK || !(t.max_err <= TRACK_LANDMARKS_MAX_REPROJ_PX))
        return -1;
    memcpy(&tl->X[3 * i], t.X, sizeof t.X);
    return 1;
}

/* The frame's rows, sorted by id (the caller frees), or NULL with the reason printed. */
static sh_point *sorted(const sh_point *rows, int nrows)
{
    sh_point *cur = malloc((size_t)(nrows > 0 ? nrows : 1) * sizeof *cur);
    if (!cur) {
        sh_log_error("--landmarks: out of memory");
        return NULL;
    }
    memcpy(cur, rows, (size_t)nrows * sizeof *cur);
    qsort(cur, (size_t)nrows, sizeof *cur, by_id);
    return cur;
}

static int allocate(track_landmarks *tl)
{
    size_t n = (size_t)tl->n + 1;
    tl->pred = malloc(2 * n * sizeof *tl->pred);
    tl->keep = malloc(n);
    int ok = tl->pred && tl->keep;
    for (int c = 0; c < tl->ncam; c++) {
        tl->xy[c] = malloc(2 * n * sizeof *tl->xy[c]);
        tl->verdict[c] = malloc(n);
        ok = ok && tl->xy[c] && tl->verdict[c];
    }
    if (tl->ncam > 1) {
        tl->X = malloc(3 * n * sizeof *tl->X);
        tl->in3d = calloc(n, 1);
        ok = ok && tl->X && tl->in3d;
    }
    if (!ok) sh_log_error("--landmarks: out of memory");
    return !ok;
}

/* In 3D, frame 0: each landmark matched in the other cameras from its reference position and
 * triangulated; the ones that are have a reference in 3D (tl->in3d) and are written. 0, or 1
 * with the reason printed. */
static int reference_3d(track_landmarks *tl, const sh_image *frames, const sh_point *rows, int nrows)
{
    sh_point *cur = sorted(rows, nrows);
    if (!cur) return 1;
    memcpy(tl->xy[0], sh_landmarks_reference(tl->lm), 2 * (size_t)tl->n * sizeof *tl->xy[0]);
    memset(tl->verdict[0], SH_LANDMARK_ACCEPTED, (size_t)tl->n);
    int rc = 0;
    for (int c = 1; c < tl->ncam && !rc; c++) rc = match_camera(tl, c, &frames[c], 0, cur, nrows);
    free(cur);
    for (int i = 0; i < tl->n && !rc; i++) tl->in3d[i] = tl->keep[i] = triangulate(tl, i) == 1;
    for (int i = 0; i < tl->n && !rc; i++) tl->stats.in_3d += tl->in3d[i];
    if (!rc)
        sh_log_info("%d landmarks chosen in camera 0's frame 0 (ids %d on), %d of them matched in camera%s 1%s "
                    "and triangulated (the others are not written)",
                    tl->n, SH_LANDMARK_ID_BASE, tl->stats.in_3d, tl->ncam > 2 ? "s" : "", tl->ncam > 2 ? " or 2" : "");
    return rc;
}

int track_landmarks_start(const track_landmarks_options *o, const sh_image *frames, const sh_detection *dets, int ndet,
                          const sh_point *rows, int nrows, FILE *out, track_landmarks **out_tl)
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
        tl->ncam = o->calib && o->ncam > 1 ? o->ncam : 1;
        tl->calib = o->calib;
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
    for (int k = 0; k < nrows; k++) tl->ref_xy[2 * k] = tl->ref[k].x, tl->ref_xy[2 * k + 1] = tl->ref[k].y;
    for (int d = 0; d < ndet; d++)
        for (int k = 0; k < 4; k++) tags[8 * d + 2 * k] = dets[d].corner[k][0], tags[8 * d + 2 * k + 1] = dets[d].corner[k][1];
    sh_hull hull;
    sh_landmarks_params p;
    if (o->sparse)
        sh_landmarks_params_sparse(&p);
    else
        sh_landmarks_params_default(&p);
    p.affine = o->affine;
    p.max_points = o->n;
    const sh_plane *y = luma(tl, 0, &frames[0]);
    int rc = 0;
    if (!y || sh_hull_compute(tl->ref_xy, nrows, &hull) != SH_OK ||
        sh_landmarks_create(&p, y, &hull, tags, ndet, &tl->lm) != SH_OK)
        rc = fail("frame 0");
    /* The other cameras see the tissue from elsewhere, its windows foreshortened unlike camera
     * 0's: their searches always warp the reference window by the local affine of the markers'
     * map into that camera (measured: docs/landmarks.md, "In 3D"). The same choice, as it does
     * not depend on `affine`. */
    if (!rc && tl->ncam > 1 && !o->affine) {
        p.affine = 1;
        if (sh_landmarks_create(&p, y, &hull, tags, ndet, &tl->lm_other) != SH_OK) rc = fail("frame 0");
    }
    free(tags);
    if (!rc) {
        tl->n = tl->stats.chosen = sh_landmarks_count(tl->lm);
        rc = allocate(tl);
    }
    if (!rc && tl->ncam > 1) {
        rc = reference_3d(tl, frames, rows, nrows);
    } else if (!rc) {
        memset(tl->keep, 1, (size_t)tl->n);
        sh_log_info("%d landmarks chosen in frame 0 (ids %d on)", tl->n, SH_LANDMARK_ID_BASE);
    }
    if (!rc) rc = write_landmarks(tl, 0, sh_landmarks_reference(tl->lm), out);
    if (rc) {
        track_landmarks_destroy(tl);
        return rc;
    }
    *out_tl = tl;
    return 0;
}

int track_landmarks_frame(track_landmarks *tl, const sh_image *frames, int f, const sh_point *rows, int nrows,
                          FILE *out)
{
    if (tl->n == 0) return 0;
    sh_point *cur = sorted(rows, nrows);
    if (!cur) return 1;
    /* no landmark is written without the markers' map: nothing to judge them by */
    int rc = 0, mapped = predict(tl, 0, cur, nrows);
    sh_landmarks_counts cnt;
    const sh_plane *y = mapped ? luma(tl, 0, &frames[0]) : NULL;
    if (mapped && (!y || sh_landmarks_track(tl->lm, y, tl->pred, tl->xy[0], tl->verdict[0], &cnt) != SH_OK)) {
        sh_log_error("--landmarks: frame %d: %s", f, sh_error_message());
        rc = 1;
    }
    for (int c = 1; c < tl->ncam && mapped && !rc; c++) rc = match_camera(tl, c, &frames[c], f, cur, nrows);
    free(cur);
    if (!mapped || rc) return rc;
    for (int v = 0; v < SH_LANDMARK_VERDICTS; v++) tl->stats.verdicts[v] += cnt.verdicts[v];
    for (int i = 0; i < tl->n; i++) {
        tl->keep[i] = tl->verdict[0][i] == SH_LANDMARK_ACCEPTED;
        if (!tl->keep[i] || tl->ncam == 1) continue;
        int t = tl->in3d[i] ? triangulate(tl, i) : 0;
        if (tl->in3d[i] && t == 0) tl->stats.unmatched++;
        if (t < 0) tl->stats.inconsistent++;
        tl->keep[i] = t == 1;
    }
    return write_landmarks(tl, f, tl->xy[0], out);
}

void track_landmarks_stats_get(const track_landmarks *tl, track_landmarks_stats *s)
{
    *s = tl->stats;
}

void track_landmarks_destroy(track_landmarks *tl)
{
    if (!tl) return;
    sh_landmarks_destroy(tl->lm);
    sh_landmarks_destroy(tl->lm_other);
    for (int c = 0; c < MAXCAM; c++) {
        sh_image_destroy(&tl->gray[c]);
        free(tl->xy[c]), free(tl->verdict[c]);
    }
    free(tl->ref), free(tl->ids), free(tl->ref_xy), free(tl->cur_xy), free(tl->pred), free(tl->X), free(tl->in3d);
    free(tl->keep);
    free(tl);
}
