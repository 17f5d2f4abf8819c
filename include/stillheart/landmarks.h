/* Natural landmarks (issue 19): points of the tissue's own texture, chosen in the reference
 * frame and found again in each new frame, with every test a landmark must pass before a map
 * may use it.
 *
 * Chosen once per reference (sh_landmarks_create): Shi-Tomasi corners of the reference luma
 * (src/flow), strongest first and spread by a minimum distance, only where a tracking window
 * sees tissue alone: inside the markers' hull (when one is given), off the tags (each tag's quad
 * grown by its quiet zone, a margin and half a window, so no window sees a tag's sticker, which
 * moves rigidly and not as the tissue), off specular highlights (no window holds a pixel at or above
 * the highlight level, which follows the frames' range: sh_landmarks_highlight_level; a highlight
 * moves with the light and the view, not with the tissue), and
 * half a window inside the image.
 *
 * Both the choice and the search see the frames band-passed (unless band is 0): the mean over 3x3
 * pixels minus the mean over a box `band` pixels each way from the centre (5 by default, about
 * half the default 21 px window's side), scaled by a gain the reference fixes (its 99th
 * percentile of |difference| to 100 grey levels) around 128.
 * The fine box takes out the pixel noise, whose own corners would otherwise be chosen and then
 * refused; the coarse one takes out the shading that sweeps over the tissue as the heart turns
 * under the light (and the broad lobes of highlights): structure coarser than half a window
 * says little about where the window lies, but a brightness ramp across it moves a
 * translation-only match (on the phantom, started at the truth itself, by 0.86 px in the mean
 * with raw frames; docs/landmarks.md). It needs a texture with detail finer than half a window,
 * as tissue has (vessels, capillaries); one made only of waves a window or more long loses most
 * of its signal to it.
 *
 * Every length here (the window, the spacing, the band-pass's boxes, the tests' bounds) was
 * measured on 1920x1080 frames. A larger frame of the same field (4K) is first halved by 2x2
 * means (`reduce`, sh_landmarks_reduction), and all of the above happens in the halved frame;
 * positions in and out stay the frame's own. Unhalved at 4K, a window would cover a quarter of
 * the tissue: on the phantom half as many landmarks passed, and the map's error fell by a quarter
 * instead of a half (docs/landmarks.md, "At 4K").
 *
 * Found per frame (sh_landmarks_track) against the reference itself, not the previous frame:
 * errors do not accumulate, and a landmark hidden for a while (an instrument, blood) is found
 * again when it shows, with nothing to re-seed. A new reference chooses anew. Pyramidal
 * Lucas-Kanade starts from the caller's prediction (the markers' map evaluated at the
 * landmark's reference position), so only the map's local error is left to find. A landmark is
 * accepted only when all of these hold, tested in this order (the first that fails is its
 * verdict):
 *  - LOST: Lucas-Kanade kept it (its window textured enough, inside the image), both ways;
 *  - PHOTOMETRIC: the two windows at the result differ by at most max_photometric grey levels
 *    (mean absolute difference): an occluder replaces the window's content, and the difference
 *    becomes the texture's own contrast; and so do their centres (`core`), so that a point an
 *    occluder's edge covers is refused even when the rest of its window matches; and the
 *    windows' difference is at most max_jump times the landmark's own median over the last
 *    frames it was accepted in (in this view), so that an occluder that looks like the tissue,
 *    which the fixed bound lets through, is refused by the change it makes all the same; and
 *    both differences are at most max_relative times their median over the frame's landmarks,
 *    so that a window which matches worse than the frame's own noise explains is refused from
 *    the reference's first frame on, before it has a past (an instrument's edge the tissue
 *    slides under); and, with min_correlation (the sparse tests), the windows correlate;
 *  - BACKWARD: found again from the result back in the reference, it lands within
 *    max_backward_px of where it started (Kalal, Mikolajczyk and Matas, "Forward-backward error:
 *    automatic detection of tracking failures", ICPR 2010): the backward search starts from the
 *    prediction's inverse, not from the answer, so a window that fits two places fails it (on
 *    back_levels pyramid levels: the inverse of a prediction that is within the disagreement
 *    bound of the result is within it of the answer);
 *  - DISAGREES: it lies within max_disagreement_px of the markers' prediction: a landmark that
 *    disagrees with the map by more than the map's own expected error is dropped, not averaged
 *    in (with bound_factor, that error is measured on the frame: sh_landmarks_params_sparse);
 *  - DEVIATES: its correction of the map (its position minus the prediction) lies within
 *    max_deviation_px of the median correction of its `neighbours` nearest landmarks (by
 *    reference position) that passed the tests above, and at least 3 of them did. The map's
 *    own error is smooth between the markers, so neighbours that are right correct it alike;
 *    one whose window matched the wrong place, consistently both ways and within the map's
 *    reach, stands out. This test needs a prediction.
 * With `affine` (the default since 2026-12-06), the forward search's finest reference window is
 * sampled through the inverse of the markers' map's local affine at the landmark: a
 * translation-only search is biased where the tissue deforms across its window, which is where
 * most landmarks accepted more than 1 px off were (docs/landmarks.md, "The tail").
 * Only the part of the frame the searches read is band-passed and put in the pyramid: the part
 * around the box of the predictions grown by the disagreement bound and 8 px
 * (sh_flow_pyramid_build_box). A search that leaves it is done again on a larger part around
 * where it started and where it stopped (reaching 32, 64, 128 px further), then on the whole
 * frame; the results are the whole frame's, bit for bit, whatever part was built (counts says
 * how many searches were done again). Nothing is allocated per frame. */
#ifndef STILLHEART_LANDMARKS_H
#define STILLHEART_LANDMARKS_H

#include <stdint.h>

#include "stillheart/calib.h"
#include "stillheart/core.h"
#include "stillheart/flow.h"
#include "stillheart/hull.h"
#include "stillheart/image.h"
#include "stillheart/interp.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Points files give landmark k the id SH_LANDMARK_ID_BASE + k (`stillheart track --landmarks`):
 * far above any tag family's ids, so the rows sort after the markers'. */
#define SH_LANDMARK_ID_BASE 1000000

/* The smoothing of a landmark row in the map (sh_interp_create_smoothed; the RBFs, TPS among them):
 * a landmark is found to 0.2-0.3 px, a marker's centre to a few hundredths, so the map approximates
 * the landmarks and interpolates the markers. In the kernel's units (px^2 log px at the frame's
 * scale); measured on 1080p phantoms (docs/landmarks.md, "Weights"). `stillheart warp
 * --landmark-smoothing`, the daemon's [track] landmarks_smoothing, stillheart-eval's
 * --landmark-smoothing. */
#define SH_LANDMARK_SMOOTHING 1000.0

/* Whether a 2D method is better with landmark rows than without. Measured on the phantom through
 * `stillheart track --landmarks`, `warp` and stillheart-eval (docs/landmarks.md): TPS, piecewise
 * linear, B-splines and affine gain; the Gaussian and local RBFs, exact through landmarks 20 px
 * apart, lose (their systems nearly singular at those scales), so their warps leave the rows out. */
int sh_landmarks_method_uses(sh_method method);

/* The highlight level (sh_landmarks_params.highlight) for frames of this format whose samples are
 * full range (0..255: a Y4M tagged XCOLORRANGE=FULL) or not: 250, the default, where an 8-bit
 * camera clips; in limited range (16..235, BT.601/709's studio swing: Y4M's default, most
 * cameras' YUV, the phantom's renders) the white is 235, so 250 is never reached, and the same
 * 98 % of the white is 231. RGB frames' luma is full range whatever full_range says
 * (sh_landmarks_luma makes it). Callers pass the frames they give the landmarks. */
int sh_landmarks_highlight_level(sh_pixfmt format, int full_range);

typedef enum {
    SH_LANDMARK_ACCEPTED = 0,
    SH_LANDMARK_LOST,
    SH_LANDMARK_PHOTOMETRIC,
    SH_LANDMARK_BACKWARD,
    SH_LANDMARK_DISAGREES,
    SH_LANDMARK_DEVIATES,
    SH_LANDMARK_UNCONFIRMED,
    SH_LANDMARK_VERDICTS
} sh_landmark_verdict;

/* "accepted", "lost", "photometric", "backward", "disagrees", "deviates", "unconfirmed". */
const char *sh_landmark_verdict_name(sh_landmark_verdict v);

typedef struct {
    int max_points;             /* at most this many landmarks (200) */
    double min_distance;        /* px between two landmarks (14) */
    double quality;             /* corner response relative to the strongest allowed (0.003) */
    int balance_cell;           /* the choice ranked within cells of this side (px of the frame
                                 * the landmarks are chosen in), each cell's strongest taken as at
                                 * least balance_floor of the strongest allowed: a field whose
                                 * texture is weak in part still gets landmarks there
                                 * (sh_flow_corner_params). 0 (the defaults): strongest first;
                                 * the sparse tests' 40, floor 0.1. 0 to 4096 */
    double balance_floor;       /* 0 to 1 */
    double tag_margin;          /* px kept clear beyond each tag's white quiet zone, which is
                                 * taken as one module, an eighth of the quad's side (the
                                 * families' tags have one white module round their black
                                 * border) (2) */
    int highlight;              /* luma at or above which a pixel is a specular highlight (250,
                                 * where an 8-bit camera clips, for full-range frames; callers
                                 * pass sh_landmarks_highlight_level of their frames' range) */
    int band;                   /* the band-pass's coarse box, px each way (5; 0: raw frames) */
    double max_photometric;     /* grey levels of the frames tracked (band-passed or raw) (12) */
    double max_backward_px;     /* px (0.5: half of the 1 px a landmark must be good to);
                                 * 0 turns the backward test off (and its cost) */
    double max_disagreement_px; /* px (3) */
    int neighbours;             /* landmarks whose corrections a landmark's is checked against
                                 * (8; 0: no such test) */
    double max_deviation_px;    /* px (0.5: half of the 1 px bound, as the backward test) */
    /* For markers too sparse for their map to come within a few px of the tissue (four at the
     * corners of the field: docs/landmarks.md), sh_landmarks_params_sparse: */
    double bound_factor;        /* > 0: the disagreement bound of each frame is this times the
                                 * median distance from the markers' map of the landmarks that
                                 * passed the tests before it (the map's error measured on the
                                 * frame), never below max_disagreement_px (0: max_disagreement_px) */
    int plane;                  /* 1: the deviation test expects the median of what the planes
                                 * through each three neighbours that surround the landmark
                                 * predict, their median where no three do (0: their median);
                                 * at most 16 neighbours */
    int affine;                 /* 1: each forward search's level-0 reference window is sampled
                                 * through the inverse of the markers' map's local affine at the
                                 * landmark (the least-squares affine of the predictions of it and
                                 * its neighbours), so that a translation matches a window that the
                                 * tissue sheared or scaled (sh_flow_track_windows_warped); needs
                                 * neighbours >= 2, and is used where there is a prediction (0:
                                 * square windows). The default */
    int back_levels;            /* pyramid levels above the frame of the backward search, 0 to
                                 * flow.levels (0); -1: flow.levels, as the forward search (the
                                 * sparse tests': their predictions may be 10 px off, and so is the
                                 * backward search's start) */
    int core;                   /* side of the windows' centre whose difference (mean absolute,
                                 * sh_flow_window_difference) is held to max_photometric too: odd,
                                 * 1 to flow.win (7); 0: not tested */
    double max_jump;            /* the windows' difference held to this many times the median of
                                 * the landmark's own in the last 16 frames it was accepted in (a
                                 * grey level where that is less; from its third such frame on),
                                 * so that an occluder's edge over a window whose texture it
                                 * resembles is refused (2.5); 0: not tested. 1 to 1000 */
    double max_relative;        /* the windows' difference, and their centres' (`core`), held
                                 * to this many times its median over the landmarks the frame's
                                 * search kept (LOST aside), and never below this many grey levels:
                                 * a matched window differs from the reference by the frame's
                                 * noise, alike for every landmark, and one that differs by
                                 * several times that holds something the reference did not
                                 * (2.5, the jump test's factor); 0: not tested. 1 to 1000 */
    double min_correlation;     /* the windows at the result held to at least this normalized
                                 * cross-correlation (sh_flow_window_correlation): a uniform
                                 * occluder (blood) over a window whose texture is too faint for
                                 * the differences above to tell from the noise leaves the frame's
                                 * window noise, which correlates with the reference's no better
                                 * than chance. 0 (the defaults): not tested; the sparse tests'
                                 * 0.4. 0 to 1 (below 1) */
    int refine;                 /* the reference's windows averaged with the matches of the
                                 * first `refine` frames (of the primary view, with a prediction)
                                 * that accept landmarks: each pixel a landmark's search reads
                                 * there, sampled where the accepted landmarks near it put it
                                 * (through the map's local affine), so that the windows hold a
                                 * fraction of the reference frame's noise (16; 0: the reference
                                 * frame's own windows). 0 to 1000 */
    int confirm;                /* a landmark passes every test this many times after the
                                 * reference before it is accepted: its first confirm - 1 passes
                                 * in sh_landmarks_track (the primary view; a rig's other views
                                 * are used only where it accepts) are UNCONFIRMED, not used. 4;
                                 * the sparse tests' 1: at once. 1 to 1000 */
    int reduce;                 /* halvings of the frame before anything else: the landmarks
                                 * are chosen and found in the frame averaged over blocks of
                                 * 2^reduce x 2^reduce pixels, and every length above (and the
                                 * tracker's window) is in that frame's pixels; positions in and
                                 * out stay the frame's own. -1 (the default): automatic,
                                 * sh_landmarks_reduction, so that the lengths keep the meaning
                                 * they were measured with on 1920x1080 frames when the same field
                                 * comes at 4K. 0 to 4 */
    sh_flow_params flow;        /* the tracker (sh_flow_params_default, but 1 level above the
                                 * frame, enough for searches that start within a few px of the
                                 * answer, as predicted ones do: a caller that tracks without
                                 * predictions, or with a map farther off, raises it; and steps
                                 * down to 0.03 px, not 0.01) */
} sh_landmarks_params;

void sh_landmarks_params_default(sh_landmarks_params *p);
/* The defaults changed for a markers' map that may lie farther from the tissue than the
 * defaults' 3 px (four markers at the corners of the field): bound_factor 4, plane 1,
 * 3 pyramid levels for both searches, and min_correlation 0.4. */
void sh_landmarks_params_sparse(sh_landmarks_params *p);
/* Those changes alone, made to p in place (the other parameters as they are). */
void sh_landmarks_params_make_sparse(sh_landmarks_params *p);

/* The halvings a width x height frame gets: p->reduce when it is 0 or more, else (p NULL too) the
 * number k >= 0 that brings the frame's geometric mean side, sqrt(width height), nearest to
 * 1920x1080's (1440 px) on a log scale, k = round(log2(sqrt(width height) / 1440)): 0 up to 2036 px
 * (2560x1440 included), 1 for 3840x2160. The parameters' lengths were measured at 1080p: at 4K the
 * same field covers twice the pixels each way, and a 21 px window or a 14 px spacing would cover a
 * quarter of the tissue they were chosen for. */
int sh_landmarks_reduction(const sh_landmarks_params *p, int width, int height);

/* The landmarks' smoothing in a map of the frame's pixels for landmarks found after `reduce`
 * halvings (sh_landmarks_reduction): lambda (SH_LANDMARK_SMOOTHING's units, the kernel's, px^2 log
 * px at 1080p) times 4^reduce. A landmark found in the halved frame is as far off in its pixels as
 * one found at 1080p, so twice as far in the frame's, and the kernel's entries grow with the square
 * of the lengths: the same balance between the landmarks' errors and the map's bending. */
double sh_landmarks_smoothing(double lambda, int reduce);

typedef struct sh_landmarks sh_landmarks;

/* Chooses the landmarks in the reference luma plane. hull: only inside it (NULL: anywhere);
 * tags: n_tags quads as 4 corners x (x, y) each, 8 doubles a tag (NULL with 0). Fewer than
 * max_points (even none) is not an error: the texture decides. SH_EINVAL for bad parameters. */
sh_status sh_landmarks_create(const sh_landmarks_params *params, const sh_plane *reference,
                              const sh_hull *hull, const double *tags, int n_tags, sh_landmarks **out);
void sh_landmarks_destroy(sh_landmarks *lm);

int sh_landmarks_count(const sh_landmarks *lm);
/* Their reference positions, x0,y0,... (count pairs), strongest corner first. */
const float *sh_landmarks_reference(const sh_landmarks *lm);

typedef struct {
    int verdicts[SH_LANDMARK_VERDICTS]; /* landmarks of the frame by verdict */
    /* cost, not results: searches that left the part of the frame built around the
     * predictions and were done again on a larger part, and whether the whole frame had to be
     * built in the end (sh_landmarks_track) */
    int searched_again, whole_frame;
    double bound_px; /* the frame's disagreement bound, px of the frame (0 without a prediction) */
} sh_landmarks_counts;

/* Finds the landmarks in a luma plane of the reference's size. predicted: count pairs, where
 * the markers' map puts each landmark (NULL: no map; then the search starts at the reference
 * position and DISAGREES is not tested). xy: count pairs, each landmark's position (its last
 * estimate when not accepted); verdict: count values; counts may be NULL. */
sh_status sh_landmarks_track(sh_landmarks *lm, const sh_plane *luma, const float *predicted, float *xy,
                             uint8_t *verdict, sh_landmarks_counts *counts);

/* sh_landmarks_track in another view of the same reference: the rig's other cameras, which see
 * the tissue foreshortened unlike the primary, search with the primary's choice and reference
 * windows, with affine windows whatever params.affine says, and each view (1 to
 * SH_CALIB_MAX_CAMERAS - 1; sh_landmarks_track's is 0) keeps its own history for max_jump.
 * SH_EINVAL for another view, or when params.neighbours < 2 (the local affine is fitted through
 * the neighbours). */
sh_status sh_landmarks_track_view(sh_landmarks *lm, int view, const sh_plane *luma, const float *predicted,
                                  float *xy, uint8_t *verdict, sh_landmarks_counts *counts);

/* The luma plane landmarks are chosen and found in: plane 0 of a grey or YUV frame (a view, no
 * copy), or the BT.601 luma of an RGB24 frame computed into buf (made, or made again at another
 * size, as needed; zeroed by the caller before first use, destroyed with sh_image_destroy). */
sh_status sh_landmarks_luma(const sh_image *frame, sh_image *buf, const sh_plane **out);


/* ---- Carried frames: too few markers, the landmarks carry the map (docs/landmarks.md,
 * "Carried frames") ----
 * With four tags at the corners of the field, an instrument or blood over two of them leaves too
 * few for a markers' map (fewer than 3), and such a frame was shown raw, though the landmarks
 * between the tags are found where they were. Such a frame may rest on the markers still seen
 * and the landmarks, on three conditions: the landmarks' searches start from the frame before
 * (its landmarks, moved by the markers' motion), as no map predicts them; each is still found
 * against the reference and judged by every test of sh_landmarks_track, so no error carries from
 * frame to frame; and the landmarks found must move as the markers seen move
 * (sh_landmarks_carry). The map then goes through the markers seen and the landmarks, over
 * their hull: the part of the field beyond it, at a marker not seen, is not shown stabilized. The
 * callers carry from the last frame stabilized with its landmarks found: frames since in which no
 * landmark was searched (fewer than two markers seen, nothing to check them by; or never
 * processed) leave its landmarks as they were and do not break the chain; one whose landmarks were
 * searched and not used does. */

/* A landmark not accepted in the frame before is predicted by the median displacement of its 8
 * nearest that were, and a marker seen is judged by the 8 nearest landmarks accepted in both
 * frames, at least 3 of them: the deviation test's 8 and 3, for the same reason (a median of
 * fewer says little). Their median motion between the frames is compared with the
 * marker's: the motion from one frame to the next varies far less across the 60-120 px between a
 * corner tag and its nearest landmarks (the tag, its quiet zone and half a window keep them off)
 * than the displacement from the reference does. On a four-tag render the median of 8 put the
 * tags' motion within 1.07 px at the p90 and 1.72 px at the p99 (16: 1.13, 1.94; 32: 1.23, 2.14),
 * where a plane through the 16 nearest put the tags themselves within 1.5-3.1 px at the p90 (8:
 * 2.1-3.7; 32: 1.6-4.5) and 18 px at most (docs/landmarks.md, "Carried frames"). */
#define SH_LANDMARKS_CARRY_NEAR 8
#define SH_LANDMARKS_CARRY_SUPPORT 3
/* Markers that must be seen: two. The landmarks' map is checked at each; a shift, rotation or
 * scale common to the landmarks (a search gone wrong the same way everywhere) moves at least one
 * of two points, where one point is blind to rotation and scale about it. */
#define SH_LANDMARKS_CARRY_SEEN 2

typedef struct {
    int searched;    /* 1: the landmarks were searched (xy, verdict and counts written) */
    int carried;     /* 1: the landmarks vouch for carrying the frame's map (below) */
    int support;     /* the fewest landmarks accepted in both frames found among the
                      * SH_LANDMARKS_CARRY_NEAR nearest a marker seen (0 when not searched) */
    int thin;        /* that marker (-1: none) */
    double worst_px; /* the largest distance, over the markers seen, between a marker's motion
                      * since the frame before and the median motion of its nearest landmarks */
    int worst;       /* that marker (-1: none) */
} sh_landmarks_carry_report;

/* A frame without a markers' map, right after one whose landmarks were found (prev_xy, prev_ok:
 * count each, that frame's positions and 1 where accepted; predicted and xy, count pairs each,
 * must be other buffers: nothing is allocated, for the daemon's frames). The nseen
 * markers seen in both frames: their reference positions (seen_ref), where they were (seen_prev)
 * and where they are (seen_xy), nseen pairs each.
 * Each landmark is predicted at its reference position plus its displacement in the frame before
 * (its own where it was accepted there, else the median of those of its SH_LANDMARKS_CARRY_NEAR
 * nearest that were), plus the seen markers' mean motion (into predicted); then found and judged as
 * sh_landmarks_track does (xy, verdict, counts). r->carried is 1 when, at each marker seen, the
 * median motion since the frame before of its SH_LANDMARKS_CARRY_NEAR nearest landmarks accepted
 * in both frames (at least SH_LANDMARKS_CARRY_SUPPORT of them) is within max_px of its own: the
 * landmarks, found without the markers, move as the detector sees the markers move (the daemon
 * passes [gating] max_residual_px). A search gone wrong the same way over a part of the field,
 * which the tests of each landmark against its neighbours cannot see, moves those landmarks
 * unlike the markers there. With fewer than SH_LANDMARKS_CARRY_SEEN markers seen, or none
 * accepted before, nothing is searched and r->carried is 0. SH_EINVAL for bad arguments; r may
 * be NULL. */
sh_status sh_landmarks_carry(sh_landmarks *lm, const sh_plane *luma, const float *prev_xy, const uint8_t *prev_ok,
                             const double *seen_ref, const double *seen_prev, const double *seen_xy, int nseen,
                             double max_px, float *predicted, float *xy, uint8_t *verdict,
                             sh_landmarks_counts *counts, sh_landmarks_carry_report *r);

/* ---- In 3D: a calibrated rig (docs/landmarks.md, "In 3D") ----
 * The landmarks are chosen in one camera (the primary: the one whose frames are shown) and found
 * in every other camera of the rig, each search started on the epipolar line of the primary's
 * position and its reference window warped by the local affine of the markers' map into that
 * camera (a camera elsewhere sees the tissue foreshortened unlike the primary); each landmark is
 * triangulated (sh_camera_triangulate) from the primary and every other camera that accepted it.
 * The reference frame does this once: a landmark not matched and triangulated there has no
 * reference in 3D and is never used. */

/* The largest reprojection error, px, of any view of a triangulated landmark: half of the 1 px a
 * landmark must be good to, as the backward test; with two cameras the triangulation splits the
 * distance from the epipolar line between the two views. */
#define SH_LANDMARKS_MAX_REPROJ_PX 0.5

typedef struct sh_landmarks_rig sh_landmarks_rig;

/* Chooses the landmarks in camera `primary`'s reference luma (as sh_landmarks_create, inside the
 * hull of the markers' ref_xy, off the tags), then matches them into every other camera's
 * reference luma and triangulates them. luma: calib->num_cameras planes of the reference frame,
 * in the calibration's order (NULL for a camera whose frame is missing: nothing is found there);
 * ref_xy, ref_xyz: the n reference markers' positions in the primary (n pairs) and their X, Y, Z
 * (n triples; NaN where unknown: that marker does not predict the other cameras), n >= 3. Later
 * frames pass at most n markers. SH_EINVAL for bad arguments. */
sh_status sh_landmarks_rig_create(const sh_landmarks_params *params, const sh_calib *calib, int primary,
                                  const sh_plane *const *luma, const double *ref_xy, const double *ref_xyz, int n,
                                  const double *tags, int n_tags, sh_landmarks_rig **out);
void sh_landmarks_rig_destroy(sh_landmarks_rig *rig);

/* The primary camera's landmarks (count, reference positions). */
const sh_landmarks *sh_landmarks_rig_primary(const sh_landmarks_rig *rig);
/* Of them, the ones with a reference in 3D (count values, 1 or 0), and their X, Y, Z (count
 * triples, NaN where none). */
const uint8_t *sh_landmarks_rig_in_3d(const sh_landmarks_rig *rig);
const double *sh_landmarks_rig_reference_xyz(const sh_landmarks_rig *rig);

typedef struct {
    int mapped;                  /* 0: no markers' map into the primary (fewer than 3 markers,
                                  * or none fitted through them): nothing searched or used */
    sh_landmarks_counts primary; /* the primary camera's search */
    int used;                    /* accepted in the primary and triangulated */
    int unmatched;               /* accepted in the primary, with a 3D reference, by no other
                                  * camera */
    int inconsistent;            /* accepted in two or more, a view beyond
                                  * SH_LANDMARKS_MAX_REPROJ_PX */
} sh_landmarks_rig_counts;

/* One frame of the rig (luma: a plane per camera, as at create, NULL where missing): the n
 * markers' reference positions in the primary (ref_xy), where the primary sees them now (cur_xy)
 * and their X, Y, Z now (cur_xyz, NaN where unknown). Each landmark is predicted in the primary by TPS through the
 * markers, in another camera by TPS between the reference positions and the markers' X, Y, Z
 * projected into it, then found and judged (sh_landmarks_track) and triangulated. Out: xy (count
 * pairs, the primary's positions), xyz (count triples) and use (count values: 1 where accepted in
 * the primary, with a 3D reference and triangulated within SH_LANDMARKS_MAX_REPROJ_PX; xyz is
 * meaningful there alone). counts may be NULL. The rig's buffers are made at create; the TPS
 * predictions allocate as sh_interp_map_points does (the 2D daemon's do too). */
sh_status sh_landmarks_rig_track(sh_landmarks_rig *rig, const sh_plane *const *luma, const double *ref_xy,
                                 const double *cur_xy, const double *cur_xyz, int n, float *xy, double *xyz,
                                 uint8_t *use, sh_landmarks_rig_counts *counts);

#ifdef __cplusplus
}
#endif
#endif
