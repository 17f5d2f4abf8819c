/* stillheart-eval: the paper's metric e (section V), its error image as a heatmap, and on phantom
 * sequences the geometric error of the stabilizing map against the ground truth.
 * Private to tools/eval: main.c parses the command line, the other files do one job each. */
#ifndef STILLHEART_EVAL_H
#define STILLHEART_EVAL_H

#include <stdio.h>

#include "phantom.h"
#include "stillheart/hull.h"
#include "stillheart/interp.h"
#include "stillheart/landmarks.h"
#include "stillheart/metrics.h"
#include "stillheart/points.h"
#include "stillheart/warp.h"
#include "stillheart/warp3d.h"

/* ---- geometric error (geometric.c) ---- */

typedef struct {
    const phantom_truth *truth;
    int camera;
    int reference;
    int stride;                /* sample spacing in pixels */
    int identity;              /* --method none: the map is q -> q (the unstabilized video) */
    sh_interp_params params;   /* as `stillheart warp` builds its interpolant */
    double landmark_smoothing; /* the smoothing of its landmark rows (ids from SH_LANDMARK_ID_BASE), as the warp's */
    sh_warp_options wopts;
    /* --cameras: the map of `stillheart warp3d`'s reference view of `camera` (calib->cam[camera]
     * both source and view), rebuilt from the points' X, Y, Z with p3 and vopts; NULL: 2D */
    const sh_calib *calib;
    sh_warp3d_params p3;
    sh_warp3d_view_options vopts;
} eval_geo_options;

typedef struct eval_geo eval_geo;

/* Samples the reference hull, locates every sample on the phantom in the reference frame.
 * width x height is the video's frame size; it must match the phantom's. */
sh_status eval_geo_create(const eval_geo_options *opts, const sh_points *points,
                          const sh_hull *hull, int width, int height, eval_geo **out);
void eval_geo_destroy(eval_geo *geo);
/* Adds frame t: rebuilds the map the warp used for it and compares with the truth. */
sh_status eval_geo_frame(eval_geo *geo, int t);

typedef struct {
    double mean, p95, max;
    long long samples;        /* (sample, frame) pairs measured */
    int points;               /* hull samples that see the heart in the reference frame */
    long long hidden;         /* pairs skipped: the truth says the point is hidden in frame t */
    long long unmapped;       /* pairs skipped: outside the warp's hull for that frame's markers */
    int raw_frames;           /* frames the warp left unstabilized (fewer than 3 markers) */
} eval_geo_result;

/* Statistics over every frame added (sorts the errors: call once, at the end). */
sh_status eval_geo_result_get(eval_geo *geo, eval_geo_result *res);

/* ---- natural landmarks against the truth (landmarks.c) ---- */

typedef struct {
    const phantom_truth *truth;
    int camera;
    int reference;
    sh_interp_params params;   /* the markers' map that predicts each landmark */
    double landmark_smoothing; /* the accepted landmarks' in the map fitted with them */
    sh_landmarks_params lp;
    int keep_rows;             /* fill eval_lm_result.rows (--landmarks-points) */
} eval_lm_options;

typedef struct {
    int seeded;                /* landmarks chosen in the reference */
    int frames;                /* frames after the reference with a markers' map */
    int unpredicted_frames;    /* frames without one (fewer than 3 markers shared) */
    long long verdicts[SH_LANDMARK_VERDICTS]; /* landmark-frames by verdict */
    long long measured;        /* accepted landmark-frames compared with the truth */
    long long hidden;          /* landmark-frames the truth says are hidden (instrument, blood) */
    long long accepted_hidden; /* of those, accepted: wrong */
    long long unjudged;        /* accepted, but the reference pixel had no truth */
    /* landmarks chosen where the reference frame showed something over the tissue (an instrument,
     * blood): judged against the tissue behind their pixel, in the accepted landmarks' errors
     * and over_1px too; their accepted landmark-frames, and those more than 1 px off */
    int chosen_covered;
    long long accepted_covered, over_1px_covered;
    long long over_1px;        /* accepted more than 1 px from the truth */
    /* accepted landmark-frames, and of them those more than 1 px off, whose window the truth says
     * was partly hidden (an instrument, blood, the view's edge) though its point was not */
    long long accepted_partly_hidden, over_1px_partly_hidden;
    /* landmark-frames whose window, where the truth puts the landmark, held a specular highlight
     * in that frame (a pixel at or above the landmarks' highlight level: where the camera clips,
     * the texture under it is gone; the landmarks were chosen where the reference had none), and
     * of them those accepted and those accepted more than 1 px off */
    long long lit, accepted_lit, over_1px_lit;
    double sum, mean, p99, max;        /* accepted landmarks' error (px) */
    double map_sum, map_mean, map_p99; /* the markers' map at the same landmarks (px) */
    double ms_median;          /* sh_landmarks_track per frame, thread CPU time */
    /* the hull's samples (every 8 px) against the truth: the markers' map, and the same method
     * fitted to the markers and the accepted landmarks together (px) */
    long long geo_samples;
    double geo_map_mean, geo_map_p95, geo_lm_mean, geo_lm_p95;
    /* with keep_rows: the landmarks as points-file rows, ids SH_LANDMARK_ID_BASE + k, all of
     * them in the reference at their reference positions, in each later frame the accepted ones
     * where they were found (as `stillheart track --landmarks` writes them); the caller frees */
    sh_point *rows;
    int nrows;
} eval_lm_result;

/* Runs the landmarks over the unstabilized video (its frames from the reference on) with the
 * markers of `points`. */
sh_status eval_landmarks_run(const eval_lm_options *o, const sh_points *points, const char *video_path,
                             eval_lm_result *r);
/* The result as --landmarks prints it, JSON or text (method: the markers' map's). */
void eval_landmarks_print(const eval_lm_result *r, const char *video_path, int reference, const char *method,
                          int json);
/* The 2D rows of `points` and r->rows together, sorted by frame and id: a points file that
 * `stillheart warp` takes, the truth's markers with the landmarks. */
sh_status eval_landmarks_write_points(const sh_points *points, const eval_lm_result *r, FILE *out);

/* ---- landmark rows against the truth (rows.c) ---- */

/* --landmark-rows: the landmark rows of points_path (their x, y in `camera`; with calib, their
 * X, Y, Z in every camera) against the phantom in truth_dir; prints JSON or text; the exit
 * status. */
int eval_rows_main(const char *truth_dir, const char *points_path, const sh_calib *calib, int camera, int reference,
                   int json);

/* ---- the texture's spatial spectrum (spectrum.c) ---- */

typedef struct eval_spectrum eval_spectrum;

/* Radially averaged power spectrum of n x n patches (n a power of two, 16..4096). */
sh_status eval_spectrum_create(int n, eval_spectrum **out);
void eval_spectrum_destroy(eval_spectrum *s);
/* Adds one patch (row stride in floats): its mean taken away, Hann-windowed, |FFT|^2 summed over
 * the integer rings round(|k|) = 0..n/2 cycles per patch. */
void eval_spectrum_add(eval_spectrum *s, const float *patch, int stride);
int eval_spectrum_patches(const eval_spectrum *s);
/* alpha of amplitude ~ 1/f^alpha: minus half the least-squares slope of log(mean power of ring
 * k) against log k over rings k0..k1. */
sh_status eval_spectrum_alpha(const eval_spectrum *s, int k0, int k1, double *alpha);

/* On a rendered phantom: 64 px patches, the band 4..16 cycles per patch (16 to 4 px periods),
 * and the octaves 2-4, 4-8, 8-16, 16-32. */
#define EVAL_SPECTRUM_K0 4
#define EVAL_SPECTRUM_K1 16
#define EVAL_SPECTRUM_OCTAVES 4

typedef struct {
    int frames, patches;          /* frames sampled (8 spread over the sequence), patches used */
    long long off_tissue;         /* patches in the hull left out: a tag, or tissue hidden, near */
    long long highlights;         /* left out: a pixel at or above 250 (specular highlight) */
    double contrast;              /* RMS contrast of the luma, std / mean, mean over patches */
    double alpha;                 /* over EVAL_SPECTRUM_K0..K1 */
    double octave_alpha[EVAL_SPECTRUM_OCTAVES];
} eval_spectrum_result;

/* The luma of 8 frames spread over the video, in 64 px patches on an 8 px grid (overlapping) that
 * lie wholly inside the hull of that frame's tag centres and see the tissue alone (the truth,
 * checked every 4 px, to 2 px around), without a highlight. */
sh_status eval_spectrum_run(const phantom_truth *truth, int camera, const char *video_path, eval_spectrum_result *r);
/* --spectrum: runs it on DIR's phantom and prints the result (JSON or text); the exit status. */
int eval_spectrum_main(const char *truth_dir, int camera, int json, const char *video_path);

/* ---- heatmap (heatmap.c) ---- */

/* Colour-maps the I_error grey image (NaN outside the hull) with contour lines at
 * k * max / (levels + 1), k = 1..levels, resamples it by scale (nearest pixel) and draws the
 * colour scale with its numbers in a strip along its top or bottom edge; writes a PNG. */
sh_status eval_heatmap_write(const char *path, const float *grey, int width, int height,
                             double max, int levels, double scale);

/* The viridis colour of s in [0, 1] (clamped). */
void eval_viridis(double s, unsigned char rgb[3]);

/* ---- drawing on RGB24 pictures (draw.c) ---- */

#define FONT_W 5
#define FONT_H 7

/* The glyph of c (upper case drawn as lower case): FONT_H rows of FONT_W characters, '#' ink,
 * '.' paper; NULL for a space or a character the face lacks (drawn blank). */
const char (*font_glyph(char c))[FONT_W + 1];
/* Width in pixels of s drawn at scale: FONT_W + 1 columns a character, less the last gap. */
int font_width(const char *s, int scale);
/* s with its top-left corner at (x, y), every font pixel a scale x scale square, clipped. */
void draw_text(sh_image *img, int x, int y, const char *s, int scale, const unsigned char rgb[3]);
/* The box [x0, x1) x [y0, y1), clipped to the picture. */
void draw_box(sh_image *img, int x0, int y0, int x1, int y1, const unsigned char rgb[3]);

/* ---- ground-truth points (export.c) ---- */

/* Writes the points file of the visible tag centres of camera c in DIR/markers.csv. */
sh_status eval_export_points(const char *dir, int camera, FILE *out, const char *out_name);

/* ---- progress (main.c) ---- */

double eval_now(void);

#endif
