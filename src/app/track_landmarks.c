/* stillheart track --landmarks (track_landmarks.h). */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "stillheart/hull.h"
#include "stillheart/interp.h"
#include "stillheart/log.h"
#include "track_landmarks.h"

#define MAXCAM SH_CALIB_MAX_CAMERAS

struct track_landmarks {
    sh_landmarks *lm;      /* 2D: camera 0's landmarks */
    sh_landmarks_rig *rig; /* 3D: the rig's (landmarks.h, "In 3D") */
    int n;
    int reference;         /* the frame they were chosen in (--reference; "frame 0" below) */
    int ncam;              /* > 1: landmarks in 3D */
    const sh_calib *calib;
    sh_point *ref;         /* the reference's marker rows, sorted by id */
    int nref;
    int *ids;              /* nref: the ids a frame shares with frame 0 */
    double *ref_xy, *cur_xy; /* nref pairs: frame 0's positions (for its hull), then per frame the
                              * shared markers' reference positions and where camera 0 sees them */
    double *cur_xyz;       /* 3D: nref triples, the shared markers' X, Y, Z */
    float *pred;           /* 2D: n pairs */
    float *xy;             /* n pairs: each landmark's position in camera 0 */
    uint8_t *verdict;      /* 2D: n */
    double *X;             /* 3D: n x 3, the frame's triangulated positions */
    uint8_t *keep;         /* n: written in this frame */
    /* --landmarks-carry (2D): the last frame whose landmarks were searched and written (xy and
     * keep hold them), and its markers shared with frame 0 and detected there (ids, where they
     * were); the last frame the chain from it reaches (prev_f, then each frame after it in which
     * no landmark was searched: -2 once one was searched and not written) */
    int carry, prev_f, chain_f;
    int *prev_ids;
    double *prev_xy;
    int nprev;
    float *lm_prev;        /* n pairs: a carried frame's copy of the frame before's xy */
    uint8_t *ok_prev;      /* n: and of its keep */
    double *both;          /* 3 nref pairs: the markers seen in both frames: their frame 0
                            * positions, where they were, where they are */
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

/* The markers' map from camera 0's reference to this frame at every landmark (tl->pred): TPS on
 * the marker rows cur (sorted by id) shares with frame 0 (*m of them: their ids, reference
 * positions and positions now in tl->ids, ref_xy, cur_xy). 0 when fewer than 3. */
static int predict(track_landmarks *tl, const sh_point *cur, int ncur, int *m)
{
    /* the shared markers' reference positions go into ref_xy (its whole-set use, the hull, is over) */
    *m = sh_points_match(tl->ref, tl->nref, cur, ncur, tl->ids, tl->ref_xy, tl->cur_xy);
    if (*m < 3) return 0;
    sh_interp_params ip;
    sh_interp_params_default(&ip, SH_METHOD_TPS);
    return sh_interp_map_points(&ip, tl->ref_xy, tl->cur_xy, *m, sh_landmarks_reference(tl->lm), tl->n, tl->pred) ==
           SH_OK;
}

/* Whether id is among the n ids of list. */
static int listed(const int *list, int n, int id)
{
    for (int k = 0; k < n; k++)
        if (list[k] == id) return 1;
    return 0;
}

/* --landmarks-carry: a frame with fewer than 3 of frame 0's markers (m of them in tl->ids,
 * ref_xy, cur_xy), the frame before's landmarks written: the landmarks predicted from those,
 * found, judged, and kept when they move as the markers detected in both frames move
 * (sh_landmarks_carry, with the daemon's default [gating] max_residual_px; a row the tracker
 * predicted is no detection to check them by, as in the daemon). 1 when the frame's landmarks are
 * kept, 0 when they were searched and are not, -1 when nothing was searched (fewer than two such
 * markers, or no landmark accepted before), -2 when the search failed (said). */
#define TRACK_CARRY_MAX_PX 3.0
static int carry(track_landmarks *tl, const sh_plane *y, int f, int m, const int *measured, int nmeasured,
                 sh_landmarks_counts *cnt)
{
    double *sref = tl->both, *sprev = tl->both + 2 * tl->nref, *snow = tl->both + 4 * tl->nref;
    int nb = 0;
    for (int k = 0; k < m; k++)
        for (int j = 0; j < tl->nprev && listed(measured, nmeasured, tl->ids[k]); j++)
            if (tl->prev_ids[j] == tl->ids[k]) {
                sref[2 * nb] = tl->ref_xy[2 * k], sref[2 * nb + 1] = tl->ref_xy[2 * k + 1];
                sprev[2 * nb] = tl->prev_xy[2 * j], sprev[2 * nb + 1] = tl->prev_xy[2 * j + 1];
                snow[2 * nb] = tl->cur_xy[2 * k], snow[2 * nb + 1] = tl->cur_xy[2 * k + 1];
                nb++;
            }
    memcpy(tl->lm_prev, tl->xy, 2 * (size_t)tl->n * sizeof *tl->xy);
    memcpy(tl->ok_prev, tl->keep, (size_t)tl->n);
    memset(cnt, 0, sizeof *cnt);
    sh_landmarks_carry_report r;
    if (sh_landmarks_carry(tl->lm, y, tl->lm_prev, tl->ok_prev, sref, sprev, snow, nb, TRACK_CARRY_MAX_PX, tl->pred,
                           tl->xy, tl->verdict, cnt, &r) != SH_OK) {
        sh_log_warn("--landmarks-carry: frame %d: %s", f, sh_error_message());
        return -2; /* xy may be half written: the chain ends */
    }
    if (!r.searched) return -1;
    for (int i = 0; i < tl->n; i++) tl->keep[i] = tl->verdict[i] == SH_LANDMARK_ACCEPTED;
    sh_log_debug("--landmarks-carry: frame %d: %d markers seen here and before, %d landmarks accepted; %s: at least "
                 "%d landmarks by each marker, the worst %.2f px off their motion",
                 f, nb, cnt->verdicts[SH_LANDMARK_ACCEPTED], r.carried ? "carried" : "not carried", r.support,
                 r.worst_px);
    return r.carried;
}

/* In 3D: the markers cur (sorted by id) shares with frame 0 (sh_points_match: their reference
 * positions and where camera 0 sees them), and their X, Y, Z, for sh_landmarks_rig_track. */
static int shared_markers(track_landmarks *tl, const sh_point *cur, int ncur)
{
    int m = sh_points_match(tl->ref, tl->nref, cur, ncur, tl->ids, tl->ref_xy, tl->cur_xy);
    for (int k = 0, j = 0; k < m; k++, j++) {
        while (cur[j].id != tl->ids[k]) j++; /* both sorted by id: the row is there */
        tl->cur_xyz[3 * k] = cur[j].X, tl->cur_xyz[3 * k + 1] = cur[j].Y, tl->cur_xyz[3 * k + 2] = cur[j].Z;
    }
    return m;
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
    tl->xy = malloc(2 * n * sizeof *tl->xy);
    tl->keep = malloc(n);
    int ok = tl->xy && tl->keep;
    if (tl->ncam > 1) {
        tl->X = malloc(3 * n * sizeof *tl->X);
        ok = ok && tl->X;
    } else {
        tl->pred = malloc(2 * n * sizeof *tl->pred);
        tl->verdict = malloc(n);
        tl->lm_prev = malloc(2 * n * sizeof *tl->lm_prev);
        tl->ok_prev = malloc(n);
        ok = ok && tl->pred && tl->verdict && tl->lm_prev && tl->ok_prev;
    }
    if (!ok) sh_log_error("--landmarks: out of memory");
    return !ok;
}

/* Every camera's luma plane of the frame into y; 0, or 1 with the reason printed. */
static int lumas(track_landmarks *tl, const sh_image *frames, int f, const sh_plane **y)
{
    for (int c = 0; c < tl->ncam; c++)
        if (!(y[c] = luma(tl, c, &frames[c]))) {
            sh_log_error("--landmarks: camera %d, frame %d: %s", c, f, sh_error_message());
            return 1;
        }
    return 0;
}

/* In 3D, frame 0: the landmarks chosen in camera 0 and matched in the others (sh_landmarks_rig);
 * the ones triangulated there have a reference in 3D and are written. 0, or 1 with the reason
 * printed. */
static int start_3d(track_landmarks *tl, const sh_landmarks_params *p, const sh_image *frames, const double *tags,
                    int ntags, const char *where)
{
    const sh_plane *y[MAXCAM];
    if (lumas(tl, frames, tl->reference, y)) return 1;
    for (int k = 0; k < tl->nref; k++)
        tl->cur_xyz[3 * k] = tl->ref[k].X, tl->cur_xyz[3 * k + 1] = tl->ref[k].Y, tl->cur_xyz[3 * k + 2] = tl->ref[k].Z;
    if (sh_landmarks_rig_create(p, tl->calib, 0, y, tl->ref_xy, tl->cur_xyz, tl->nref, tags, ntags, &tl->rig) != SH_OK)
        return fail(where);
    const sh_landmarks *lm = sh_landmarks_rig_primary(tl->rig);
    tl->n = tl->stats.chosen = sh_landmarks_count(lm);
    if (allocate(tl)) return 1;
    const uint8_t *in3d = sh_landmarks_rig_in_3d(tl->rig);
    memcpy(tl->xy, sh_landmarks_reference(lm), 2 * (size_t)tl->n * sizeof *tl->xy);
    memcpy(tl->X, sh_landmarks_rig_reference_xyz(tl->rig), 3 * (size_t)tl->n * sizeof *tl->X);
    for (int i = 0; i < tl->n; i++) tl->stats.in_3d += tl->keep[i] = in3d[i];
    sh_log_info("%d landmarks chosen in camera 0's %s (ids %d on), %d of them matched in camera%s 1%s "
                "and triangulated (the others are not written)",
                tl->n, where, SH_LANDMARK_ID_BASE, tl->stats.in_3d, tl->ncam > 2 ? "s" : "", tl->ncam > 2 ? " or 2" : "");
    return 0;
}

int track_landmarks_start(const track_landmarks_options *o, const sh_image *frames, const sh_detection *dets, int ndet,
                          const sh_point *rows, int nrows, const int *measured, int nmeasured, FILE *out,
                          track_landmarks **out_tl)
{
    *out_tl = NULL;
    char where[32];
    snprintf(where, sizeof where, "frame %d", o->reference);
    if (nrows < 3) {
        /* the markers are still tracked and written: only the landmarks are given up */
        sh_log_warn("--landmarks: %s has %d markers, the hull that bounds the landmarks needs 3: "
                    "no landmarks", where, nrows);
        return 0;
    }
    track_landmarks *tl = calloc(1, sizeof *tl);
    double *tags = malloc(8 * (size_t)(ndet > 0 ? ndet : 1) * sizeof *tags);
    if (tl) {
        tl->ncam = o->calib && o->ncam > 1 ? o->ncam : 1;
        tl->calib = o->calib;
        tl->reference = o->reference;
        tl->ref = malloc((size_t)nrows * sizeof *tl->ref);
        tl->ids = malloc((size_t)nrows * sizeof *tl->ids);
        tl->ref_xy = malloc(2 * (size_t)nrows * sizeof *tl->ref_xy);
        tl->cur_xy = malloc(2 * (size_t)nrows * sizeof *tl->cur_xy);
        tl->cur_xyz = malloc(3 * (size_t)nrows * sizeof *tl->cur_xyz);
        tl->prev_ids = malloc((size_t)nrows * sizeof *tl->prev_ids);
        tl->prev_xy = malloc(2 * (size_t)nrows * sizeof *tl->prev_xy);
        tl->both = malloc(6 * (size_t)nrows * sizeof *tl->both);
        tl->carry = o->carry && !(o->calib && o->ncam > 1);
        tl->prev_f = tl->chain_f = -2;
    }
    if (!tl || !tags || !tl->ref || !tl->ids || !tl->ref_xy || !tl->cur_xy || !tl->cur_xyz || !tl->prev_ids ||
        !tl->prev_xy || !tl->both) {
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
    sh_landmarks_params p;
    if (o->sparse)
        sh_landmarks_params_sparse(&p);
    else
        sh_landmarks_params_default(&p);
    p.affine = o->affine;
    p.refine = o->refine;
    if (o->confirm) p.confirm = o->confirm;
    p.max_points = o->n;
    p.highlight = sh_landmarks_highlight_level(frames[0].format, o->full_range);
    int rc = 0;
    if (tl->ncam > 1) {
        rc = start_3d(tl, &p, frames, tags, ndet, where);
    } else {
        sh_hull hull;
        const sh_plane *y = luma(tl, 0, &frames[0]);
        if (!y || sh_hull_compute(tl->ref_xy, nrows, &hull) != SH_OK ||
            sh_landmarks_create(&p, y, &hull, tags, ndet, &tl->lm) != SH_OK)
            rc = fail(where);
        if (!rc) {
            tl->n = tl->stats.chosen = sh_landmarks_count(tl->lm);
            rc = allocate(tl);
        }
        if (!rc) {
            memcpy(tl->xy, sh_landmarks_reference(tl->lm), 2 * (size_t)tl->n * sizeof *tl->xy);
            memset(tl->keep, 1, (size_t)tl->n);
            sh_log_info("%d landmarks chosen in %s (ids %d on)", tl->n, where, SH_LANDMARK_ID_BASE);
        }
    }
    free(tags);
    if (!rc) rc = write_landmarks(tl, tl->reference, tl->xy, out);
    if (!rc && tl->carry) { /* the reference: every landmark where it was chosen, every marker detected */
        tl->prev_f = tl->chain_f = tl->reference;
        tl->nprev = 0;
        for (int k = 0; k < nrows; k++) {
            if (!listed(measured, nmeasured, tl->ref[k].id)) continue;
            tl->prev_ids[tl->nprev] = tl->ref[k].id;
            tl->prev_xy[2 * tl->nprev] = tl->ref_xy[2 * k], tl->prev_xy[2 * tl->nprev + 1] = tl->ref_xy[2 * k + 1];
            tl->nprev++;
        }
    }
    if (rc) {
        track_landmarks_destroy(tl);
        return rc;
    }
    *out_tl = tl;
    return 0;
}

/* In 3D, frame f (cur: its marker rows, sorted by id): every camera searched, the landmarks
 * triangulated (sh_landmarks_rig_track); the ones used written. */
static int frame_3d(track_landmarks *tl, const sh_image *frames, int f, const sh_point *cur, int ncur, FILE *out)
{
    const sh_plane *y[MAXCAM];
    if (lumas(tl, frames, f, y)) return 1;
    int m = shared_markers(tl, cur, ncur);
    sh_landmarks_rig_counts rc;
    if (sh_landmarks_rig_track(tl->rig, y, tl->ref_xy, tl->cur_xy, tl->cur_xyz, m, tl->xy, tl->X, tl->keep, &rc) !=
        SH_OK) {
        sh_log_error("--landmarks: frame %d: %s", f, sh_error_message());
        return 1;
    }
    if (!rc.mapped) return 0; /* no landmark is written without the markers' map: nothing to judge them by */
    for (int v = 0; v < SH_LANDMARK_VERDICTS; v++) tl->stats.verdicts[v] += rc.primary.verdicts[v];
    tl->stats.unmatched += rc.unmatched;
    tl->stats.inconsistent += rc.inconsistent;
    return write_landmarks(tl, f, tl->xy, out);
}

int track_landmarks_frame(track_landmarks *tl, const sh_image *frames, int f, const sh_point *rows, int nrows,
                          const int *measured, int nmeasured, FILE *out)
{
    if (tl->n == 0) return 0;
    sh_point *cur = sorted(rows, nrows);
    if (!cur) return 1;
    if (tl->ncam > 1) {
        int rc = frame_3d(tl, frames, f, cur, nrows, out);
        free(cur);
        return rc;
    }
    /* no landmark is written without the markers' map (nothing to judge them by) or, with
     * --landmarks-carry, the frame before's landmarks vouching for them */
    int m, mapped = predict(tl, cur, nrows, &m);
    free(cur);
    /* the chain reaches over frames without a landmark search (fewer than two of its markers
     * detected), as the daemon's does: the next is predicted from prev_f's landmarks and the
     * markers' motion since, and checked on the markers detected in both */
    int linked = tl->carry && tl->prev_f >= 0 && tl->chain_f == f - 1;
    int chain = linked && m >= SH_LANDMARKS_CARRY_SEEN;
    tl->chain_f = -2;
    if (!mapped && !chain) {
        if (linked) tl->chain_f = f;
        return 0;
    }
    sh_landmarks_counts cnt;
    const sh_plane *y = luma(tl, 0, &frames[0]);
    if (!y) {
        sh_log_error("--landmarks: frame %d: %s", f, sh_error_message());
        return 1;
    }
    if (!mapped) {
        int kept = carry(tl, y, f, m, measured, nmeasured, &cnt);
        tl->stats.carried += kept == 1;
        tl->stats.not_carried += kept == 0;
        /* a frame searched and not carried counts its verdicts too, as the daemon's do */
        for (int v = 0; v < SH_LANDMARK_VERDICTS && kept >= 0; v++) tl->stats.verdicts[v] += cnt.verdicts[v];
        if (kept == -1) tl->chain_f = f; /* nothing searched */
        if (kept != 1) return 0;
    } else if (sh_landmarks_track(tl->lm, y, tl->pred, tl->xy, tl->verdict, &cnt) != SH_OK) {
        sh_log_error("--landmarks: frame %d: %s", f, sh_error_message());
        return 1;
    } else {
        for (int i = 0; i < tl->n; i++) tl->keep[i] = tl->verdict[i] == SH_LANDMARK_ACCEPTED;
        for (int v = 0; v < SH_LANDMARK_VERDICTS; v++) tl->stats.verdicts[v] += cnt.verdicts[v];
    }
    tl->prev_f = tl->chain_f = f;
    tl->nprev = 0;
    for (int k = 0; k < m; k++) {
        if (!listed(measured, nmeasured, tl->ids[k])) continue;
        tl->prev_ids[tl->nprev] = tl->ids[k];
        tl->prev_xy[2 * tl->nprev] = tl->cur_xy[2 * k], tl->prev_xy[2 * tl->nprev + 1] = tl->cur_xy[2 * k + 1];
        tl->nprev++;
    }
    return write_landmarks(tl, f, tl->xy, out);
}

void track_landmarks_stats_get(const track_landmarks *tl, track_landmarks_stats *s)
{
    *s = tl->stats;
}

void track_landmarks_destroy(track_landmarks *tl)
{
    if (!tl) return;
    sh_landmarks_destroy(tl->lm);
    sh_landmarks_rig_destroy(tl->rig);
    for (int c = 0; c < MAXCAM; c++) sh_image_destroy(&tl->gray[c]);
    free(tl->ref), free(tl->ids), free(tl->ref_xy), free(tl->cur_xy), free(tl->cur_xyz), free(tl->pred), free(tl->xy);
    free(tl->verdict), free(tl->X), free(tl->keep), free(tl->prev_ids), free(tl->prev_xy), free(tl->both);
    free(tl->lm_prev), free(tl->ok_prev);
    free(tl);
}
