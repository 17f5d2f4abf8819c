/* Landmarks in 3D on a calibrated rig (landmarks.h, "In 3D"): the searches in the cameras other
 * than the primary and the triangulation, shared by `stillheart track --cameras --landmarks` and
 * the daemon's [track] landmarks with [method] calibration. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "stillheart/camera.h"
#include "stillheart/landmarks.h"
#include "stillheart/warp3d.h"

#define MAXCAM SH_CALIB_MAX_CAMERAS

struct sh_landmarks_rig {
    sh_calib calib;
    int primary, ncam;
    sh_landmarks *lm;       /* the choice, and every camera's searches (the others' through
                             * affine windows, each its own view: sh_landmarks_track_view) */
    int n, cap;             /* landmarks; markers a frame at most */
    double *mref, *mcur;    /* cap pairs: the markers a camera's prediction is made from */
    float *pred;            /* n pairs */
    sh_interp_mapper *map[MAXCAM]; /* the markers' TPS into each camera (built again when they change) */
    float *xy[MAXCAM];      /* n pairs a camera */
    uint8_t *verdict[MAXCAM];
    double *X;              /* n triples: the frame's triangulated positions */
    double *ref_X;          /* n triples: the reference's (NaN without one) */
    uint8_t *in3d;          /* n */
};

/* The markers' map from the primary's reference to camera c at every landmark (rig->pred): TPS
 * through the markers camera c sees now (the primary: cur_xy; another: cur_xyz projected).
 * SH_EDEGENERATE when fewer than 3. */
static sh_status predict(sh_landmarks_rig *rig, int c, const double *ref_xy, const double *cur_xy,
                         const double *cur_xyz, int n)
{
    int m = 0;
    for (int k = 0; k < n; k++) {
        double uv[2];
        if (c == rig->primary) {
            if (!isfinite(cur_xy[2 * k]) || !isfinite(cur_xy[2 * k + 1])) continue;
            uv[0] = cur_xy[2 * k], uv[1] = cur_xy[2 * k + 1];
        } else {
            const double *X = &cur_xyz[3 * k];
            if (!isfinite(X[0]) || !isfinite(X[1]) || !isfinite(X[2]) ||
                sh_camera_project(&rig->calib.cam[c], X, uv, NULL) != SH_OK)
                continue;
        }
        rig->mref[2 * m] = ref_xy[2 * k], rig->mref[2 * m + 1] = ref_xy[2 * k + 1];
        rig->mcur[2 * m] = uv[0], rig->mcur[2 * m + 1] = uv[1];
        m++;
    }
    if (m < 3) return sh_error_set(SH_EDEGENERATE, "landmarks: %d markers seen by camera %d, 3 needed", m, c);
    return sh_interp_mapper_map(rig->map[c], rig->mref, rig->mcur, m, sh_landmarks_reference(rig->lm), rig->n,
                                rig->pred);
}

/* Moves camera c's prediction p of a landmark that the primary sees at x0 onto the epipolar line
 * of x0: the point of the primary's ray nearest camera c's ray through p, seen by camera c. The
 * map's error across the line is gone; what is left lies along it, where depth decides. Unchanged
 * when the rays are parallel or the point is not in front of both cameras. */
static void onto_epipolar_line(const sh_landmarks_rig *rig, int c, const float x0[2], float p[2])
{
    double C0[3], d0[3], Cc[3], dc[3];
    if (!sh_warp3d_ray(&rig->calib.cam[rig->primary], x0[0], x0[1], C0, d0) ||
        !sh_warp3d_ray(&rig->calib.cam[c], p[0], p[1], Cc, dc))
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
    if (sh_camera_project(&rig->calib.cam[c], X, uv, NULL) != SH_OK) return;
    p[0] = (float)uv[0], p[1] = (float)uv[1];
}

/* Camera c (not the primary): every landmark searched from its prediction moved onto the epipolar
 * line of the primary's position (rig->xy[primary]) and judged. Without its frame (luma NULL) or a
 * prediction (fewer than 3 markers with X, Y, Z in front of it) every landmark is lost there. */
static sh_status match_camera(sh_landmarks_rig *rig, int c, const sh_plane *luma, const double *ref_xy,
                              const double *cur_xyz, int n)
{
    if (!luma || predict(rig, c, ref_xy, NULL, cur_xyz, n) != SH_OK) {
        memset(rig->verdict[c], SH_LANDMARK_LOST, (size_t)rig->n);
        return SH_OK;
    }
    for (int i = 0; i < rig->n; i++) onto_epipolar_line(rig, c, &rig->xy[rig->primary][2 * i], &rig->pred[2 * i]);
    /* camera c sees the tissue from elsewhere, its windows foreshortened unlike the primary's: its
     * searches always warp the reference window by the local affine of the markers' map into it
     * (measured: docs/landmarks.md, "In 3D") */
    return sh_landmarks_track_view(rig->lm, c < rig->primary ? c + 1 : c, luma, rig->pred, rig->xy[c], rig->verdict[c],
                                   NULL);
}

/* Landmark i in 3D from the primary's position and every other camera that accepted it, into
 * rig->X: 1; 0 when no other camera did; -1 when refused (a view farther than
 * SH_LANDMARKS_MAX_REPROJ_PX from it, or degenerate). */
static int triangulate(sh_landmarks_rig *rig, int i)
{
    const sh_calib_camera *cams[MAXCAM];
    double uv[2 * MAXCAM];
    int n = 0;
    for (int k = 0; k < rig->ncam; k++) {
        /* the primary first: the order the offline tool always had (its primary is camera 0) */
        int c = k == 0 ? rig->primary : k <= rig->primary ? k - 1 : k;
        if (c != rig->primary && rig->verdict[c][i] != SH_LANDMARK_ACCEPTED) continue;
        cams[n] = &rig->calib.cam[c];
        uv[2 * n] = rig->xy[c][2 * i], uv[2 * n + 1] = rig->xy[c][2 * i + 1];
        n++;
    }
    if (n < 2) return 0;
    sh_triangulation t;
    if (sh_camera_triangulate(cams, uv, n, 1, 0, &t) != SH_OK || !(t.max_err <= SH_LANDMARKS_MAX_REPROJ_PX)) return -1;
    memcpy(&rig->X[3 * i], t.X, sizeof t.X);
    return 1;
}

static sh_status allocate(sh_landmarks_rig *rig)
{
    size_t n = (size_t)rig->n + 1, m = (size_t)rig->cap;
    rig->mref = malloc(2 * m * sizeof *rig->mref);
    rig->mcur = malloc(2 * m * sizeof *rig->mcur);
    rig->pred = malloc(2 * n * sizeof *rig->pred);
    rig->X = malloc(3 * n * sizeof *rig->X);
    rig->ref_X = malloc(3 * n * sizeof *rig->ref_X);
    rig->in3d = calloc(n, 1);
    int ok = rig->mref && rig->mcur && rig->pred && rig->X && rig->ref_X && rig->in3d;
    sh_interp_params tps;
    sh_interp_params_default(&tps, SH_METHOD_TPS);
    for (int c = 0; c < rig->ncam; c++) {
        rig->xy[c] = malloc(2 * n * sizeof *rig->xy[c]);
        rig->verdict[c] = malloc(n);
        ok = ok && rig->xy[c] && rig->verdict[c] && sh_interp_mapper_create(&tps, &rig->map[c]) == SH_OK;
    }
    return ok ? SH_OK : sh_error_set(SH_ENOMEM, "landmarks: out of memory");
}

/* The reference frame: each landmark matched in the other cameras from its reference position
 * (the markers' map there is the identity in the primary) and triangulated. */
static sh_status reference(sh_landmarks_rig *rig, const sh_plane *const *luma, const double *ref_xy,
                           const double *ref_xyz, int n)
{
    memcpy(rig->xy[rig->primary], sh_landmarks_reference(rig->lm), 2 * (size_t)rig->n * sizeof(float));
    memset(rig->verdict[rig->primary], SH_LANDMARK_ACCEPTED, (size_t)rig->n);
    sh_status st = SH_OK;
    for (int c = 0; c < rig->ncam && st == SH_OK; c++)
        if (c != rig->primary) st = match_camera(rig, c, luma[c], ref_xy, ref_xyz, n);
    for (int i = 0; i < rig->n && st == SH_OK; i++) {
        rig->in3d[i] = triangulate(rig, i) == 1;
        for (int k = 0; k < 3; k++) rig->ref_X[3 * i + k] = rig->in3d[i] ? rig->X[3 * i + k] : NAN;
    }
    return st;
}

sh_status sh_landmarks_rig_create(const sh_landmarks_params *params, const sh_calib *calib, int primary,
                                  const sh_plane *const *luma, const double *ref_xy, const double *ref_xyz, int n,
                                  const double *tags, int n_tags, sh_landmarks_rig **out)
{
    *out = NULL;
    if (!params || !calib || !luma || !ref_xy || !ref_xyz || calib->num_cameras < 2 ||
        calib->num_cameras > MAXCAM || primary < 0 || primary >= calib->num_cameras || n < 3)
        return sh_error_set(SH_EINVAL, "landmarks in 3D: a rig of 2 to %d cameras, its primary among them, and 3 "
                                       "markers or more", MAXCAM);
    if (!luma[primary]) return sh_error_set(SH_EINVAL, "landmarks in 3D: no frame of the primary camera");
    for (int c = 0; c < calib->num_cameras; c++)
        if (luma[c] && (luma[c]->width != luma[primary]->width || luma[c]->height != luma[primary]->height))
            return sh_error_set(SH_EINVAL, "landmarks in 3D: camera %d's frame is not the primary's size", c);
    sh_landmarks_rig *rig = calloc(1, sizeof *rig);
    if (!rig) return sh_error_set(SH_ENOMEM, "landmarks: out of memory");
    rig->calib = *calib;
    rig->primary = primary;
    rig->ncam = calib->num_cameras;
    rig->cap = n;
    sh_hull hull;
    sh_status st = sh_hull_compute(ref_xy, n, &hull);
    /* the other cameras' affine windows are fitted through the neighbours */
    if (st == SH_OK && params->neighbours < 2)
        st = sh_error_set(SH_EINVAL, "landmarks in 3D: the other cameras' affine windows need neighbours >= 2");
    if (st == SH_OK) st = sh_landmarks_create(params, luma[primary], &hull, tags, n_tags, &rig->lm);
    if (st == SH_OK) {
        rig->n = sh_landmarks_count(rig->lm);
        st = allocate(rig);
    }
    if (st == SH_OK) st = reference(rig, luma, ref_xy, ref_xyz, n);
    if (st != SH_OK) {
        sh_landmarks_rig_destroy(rig);
        return st;
    }
    *out = rig;
    return SH_OK;
}

void sh_landmarks_rig_destroy(sh_landmarks_rig *rig)
{
    if (!rig) return;
    sh_landmarks_destroy(rig->lm);
    for (int c = 0; c < MAXCAM; c++) free(rig->xy[c]), free(rig->verdict[c]), sh_interp_mapper_destroy(rig->map[c]);
    free(rig->mref), free(rig->mcur), free(rig->pred), free(rig->X), free(rig->ref_X), free(rig->in3d);
    free(rig);
}

const sh_landmarks *sh_landmarks_rig_primary(const sh_landmarks_rig *rig) { return rig->lm; }
const uint8_t *sh_landmarks_rig_in_3d(const sh_landmarks_rig *rig) { return rig->in3d; }
const double *sh_landmarks_rig_reference_xyz(const sh_landmarks_rig *rig) { return rig->ref_X; }

sh_status sh_landmarks_rig_track(sh_landmarks_rig *rig, const sh_plane *const *luma, const double *ref_xy,
                                 const double *cur_xy, const double *cur_xyz, int n, float *xy, double *xyz,
                                 uint8_t *use, sh_landmarks_rig_counts *counts)
{
    sh_landmarks_rig_counts own;
    if (!counts) counts = &own;
    memset(counts, 0, sizeof *counts);
    if (n < 0 || n > rig->cap) return sh_error_set(SH_EINVAL, "landmarks in 3D: %d markers, at most %d", n, rig->cap);
    memset(use, 0, (size_t)rig->n);
    /* no landmark is used without the markers' map: nothing to judge them by */
    if (predict(rig, rig->primary, ref_xy, cur_xy, NULL, n) != SH_OK) return SH_OK;
    counts->mapped = 1;
    int p = rig->primary;
    sh_status st = sh_landmarks_track(rig->lm, luma[p], rig->pred, rig->xy[p], rig->verdict[p], &counts->primary);
    for (int c = 0; c < rig->ncam && st == SH_OK; c++)
        if (c != p) st = match_camera(rig, c, luma[c], ref_xy, cur_xyz, n);
    if (st != SH_OK) return st;
    for (int i = 0; i < rig->n; i++) {
        if (rig->verdict[p][i] != SH_LANDMARK_ACCEPTED || !rig->in3d[i]) continue;
        int t = triangulate(rig, i);
        counts->unmatched += t == 0;
        counts->inconsistent += t < 0;
        use[i] = t == 1;
        counts->used += use[i];
    }
    memcpy(xy, rig->xy[p], 2 * (size_t)rig->n * sizeof *xy);
    memcpy(xyz, rig->X, 3 * (size_t)rig->n * sizeof *xyz);
    return SH_OK;
}
