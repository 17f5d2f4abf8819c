/* Natural landmarks: where they may be chosen, and the tests each must pass per frame
 * (landmarks.h says why each test is there). Over 600 lines: the choice, the band-pass the
 * choice and the searches share, the searches on a part of the frame and the tests are one
 * object's state (its buffers sized once per reference); split, each part would need the
 * others' internals. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "stillheart/landmarks.h"

/* The band-pass built for AVX-512 and AVX2 too, chosen when the program starts (gcc's
 * target_clones, an ifunc, as src/pixconv does): the same C, and with -ffp-contract=off the same
 * float operations in every lane, so the same bytes (bench_landmarks' checksum). AVX-512's wider
 * lanes took 0.2-0.3 ms off a 1080p frame's 3.2; AVX2's alone was within the noise. */
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__)
#define LM_CLONES __attribute__((target_clones("arch=x86-64-v4", "avx2", "default")))
#else
#define LM_CLONES
#endif

/* The band-pass's fine box: 3x3, against the pixel noise */
#define BAND_FINE 1

/* The jump test (max_jump): a landmark's window differences of its last JUMP_HISTORY accepted
 * frames in each view, and how many it needs before it is tested. 16 frames are half a second at
 * 30 frames/s, a good part of a heartbeat: the median spans the beat's shading and deformation and
 * ignores the odd frame. 3: a median of fewer says little about the landmark. */
#define JUMP_HISTORY 16
#define JUMP_MIN 3
/* The level below which a median says nothing: a grey level of the band-passed frame, its
 * quantisation step. On frames without noise a landmark that does not move has windows that differ
 * by less (sampled at the same sub-pixel phase); one that moves then differs by its interpolation's
 * error, a grey level or two, a jump that is no occluder. */
#define JUMP_FLOOR 1.0f

struct sh_landmarks {
    sh_landmarks_params p;
    int width, height, n;  /* the frame the landmarks are found in: reduced `reduce` times */
    int reduce, full_width, full_height; /* the halvings, and the frames' own size */
    uint8_t *small;        /* width x height: the reduced frame (reduce > 0) */
    uint16_t *acc;         /* full_width: a row of blocks' column sums (reduce_part) */
    float *ref_full;       /* n pairs: the reference positions in the frame's pixels */
    float *pred;           /* n pairs: the predictions in the reduced frame's */
    sh_flow_pyramid *ref, *cur;
    sh_flow_windows *ref_win; /* the reference's windows around the landmarks, every level */
    float *ref_xy;   /* n pairs */
    float *fwd;      /* n pairs: forward result */
    float *back;     /* n pairs: backward result, and its starting guess */
    float *err;      /* n */
    float *core_err; /* n: the windows' centres' difference at the forward result (p.core) */
    float *corr;     /* n: the windows' correlation at the forward result (p.min_correlation) */
    uint8_t *st_fwd, *st_back;
    int *near;       /* n x neighbours: each landmark's nearest others in the reference */
    float *scratch;  /* 2 x neighbours */
    uint32_t *colsum;   /* 2 w: the band-pass's boxes' column sums */
    uint32_t *prefix;   /* w + 1: the coarse box's column sums' prefix sums along a row */
    int *cols;          /* 4 w ints and 2 w floats: the boxes' columns (band_pass) */
    uint8_t *band;   /* w x h: the band-passed frame the tracker sees */
    float gain;      /* the band-pass's, fixed by the reference */
    /* the searches done again on the whole frame (sh_landmarks_track): their landmarks' indices,
     * and per landmark 2 + 2 + 2 + 1 floats, 2 statuses */
    int *redo;
    float *redo_xy;
    uint8_t *redo_st;
    int *voters;     /* a landmark's neighbours that vote (deviations) */
    float *tri;      /* 2 tri_cap: what the planes through three of them predict (expected) */
    int tri_cap;
    float *dist;     /* n: distances from the map (adaptive_bound) */
    float *jac;      /* 4 n: the markers' map's local affine at each landmark (affine) */
    float *warp;     /* 4 n: the forward searches' reference windows' matrices, J^-1, by search */
    int affine;      /* this frame's searches through the local affine (p.affine, or 1 in a
                      * view other than 0: sh_landmarks_track_view) */
    /* the jump test: per view (SH_CALIB_MAX_CAMERAS), per landmark, the last JUMP_HISTORY window
     * differences where it was accepted (a ring), how many of them there are, where the next goes;
     * and this frame's limit on the difference, per landmark */
    float *hist;
    uint8_t *hist_n, *hist_at;
    float *jump_limit;
    /* per landmark: the primary view's frames it passed every test in since the reference (confirm) */
    uint16_t *passed;
    float relative[2]; /* this frame's limits on the windows' difference and their centres' (max_relative) */
    /* the reference refined (p.refine): the sums and counts of the samples of every pixel of the
     * part rpart of the reduced frame (the reference's own pixel counted once), while frames are
     * still to come (refined < p.refine; freed after); rbox: the box of points whose windows read
     * the pixels refined (sh_flow_pyramid_update_box's). And this frame's: the plane its pyramid
     * was built from, valid in part `built` */
    float *rsum;
    uint32_t *rcnt;         /* at most 1 + refine (1000) times the landmarks (100000): no overflow */
    int rpart[4], refined;
    float rbox[4];
    sh_plane src;
    int built[4];
};

const char *sh_landmark_verdict_name(sh_landmark_verdict v)
{
    static const char *const names[SH_LANDMARK_VERDICTS] = {"accepted", "lost", "photometric", "backward",
                                                            "disagrees", "deviates", "unconfirmed"};
    return (unsigned)v < SH_LANDMARK_VERDICTS ? names[v] : "?";
}

int sh_landmarks_method_uses(sh_method method)
{
    return method != SH_METHOD_GAUSSIAN && method != SH_METHOD_RBF_LOCAL;
}

int sh_landmarks_highlight_level(sh_pixfmt format, int full_range)
{
    /* 16 + 250 / 255 * (235 - 16) = 230.7 */
    return full_range || format == SH_PIX_RGB24 ? 250 : 231;
}

void sh_landmarks_params_default(sh_landmarks_params *p)
{
    memset(p, 0, sizeof *p);
    p->max_points = 200;
    /* As many as asked, spread over the hull. A threshold of 1 % of the strongest corner's response
     * ties how many are chosen to that one corner, not to whether a window can be followed, which
     * the tests decide each frame: at 20 px and 1 % 83-161 of 200 were chosen on the eight renders
     * of docs/landmarks.md, at 14 px and 0.3 % 200 (186 on one), and the geometric error fell on
     * every render (16 tags, ex vivo 0.382 to 0.362 px over the seeds' means, in vivo 0.381 to 0.351;
     * with the landmarks' smoothing, SH_LANDMARK_SMOOTHING, to 0.318 and 0.308). 10 px crowds the
     * 200 into the most textured patches. With the smoothing the TPS map through them needs no
     * finer grid than through fewer (docs/landmarks.md, "The choice's density", "Weights"). */
    p->min_distance = 14;
    p->quality = 0.003;
    p->balance_cell = 0;
    p->balance_floor = 0;
    p->tag_margin = 2;
    p->highlight = 250;
    p->max_photometric = 12;
    p->max_backward_px = 0.5;
    p->max_disagreement_px = 3;
    p->band = 5;
    p->neighbours = 8;
    p->max_deviation_px = 0.5;
    sh_flow_params_default(&p->flow);
    /* One level above the frame, not OpenCV's three. A landmark is accepted only within
     * max_disagreement_px (3) of its prediction, where its searches start, and one level halves
     * that to 1.5 px, well inside a search's reach; and the band-pass takes out wavelengths past
     * about 22 px, so that levels 2 and 3 hold little of the texture (level 3's backward searches
     * took 11.6 steps on average, level 0's 6.4). Measured on the eight renders of docs/landmarks.md:
     * the same accepted landmarks, error and tail with 1, 2 or 3 levels, at half the cost; with
     * none, 9 % more over 1 px. */
    p->flow.levels = 1;
    /* A search stops at a step shorter than 0.03 px, not OpenCV's 0.01: a tenth of the 0.2-0.3 px
     * the accepted landmarks lie from the truth, a sixteenth of the backward test's 0.5 px.
     * Measured on the same eight renders: 1 % more accepted, 166 over 1 px instead of 174, the
     * same geometric error, 8-12 % less time. */
    p->flow.eps = 0.03;
    p->reduce = -1;
    /* Since 2026-12-06, measured on the eight renders of docs/landmarks.md (16 tags, 200 frames,
     * instrument and blood) against the square windows, the backward search on both levels and no
     * centre test of before: 87 accepted landmark-frames over 1 px of 174 409 instead of 273 of
     * 161 458, every render's map error lower (ex vivo 0.318 to 0.298 px over the seeds' means, in
     * vivo 0.308 to 0.284), none of the 9 561 hidden ones accepted either way, and 0.2 ms less
     * a frame (bench_landmarks). The affine windows alone cut the tail as much but cost 0.2 ms; a
     * backward search on the frame's level alone pays for them (its start is within the 3 px bound
     * of its answer), but then accepted 2 hidden landmarks, windows an instrument's edge half
     * covered that the coarser level's wider search had refused; the centre test refuses those
     * (and 23 others of 174 432, none of them hidden), so the guarantee no longer rests on it. */
    p->affine = 1;
    p->back_levels = 0;
    p->core = 7;
    /* The centre test did not catch an instrument's edge over the point on an unseen render (a
     * pan, docs/landmarks.md), where the instrument's grey was the tissue's: its window differed
     * by 8.2 grey levels, within the 12 any landmark may, but 5 times its own median of the frames
     * before, where the accepted landmarks' ratio stays below 2.5 in 999 of 1 000 landmark-frames
     * within 0.5 px of the truth (2.9 without the backward test). At 2.5 it refuses 0.08 % of the
     * accepted landmark-frames on the eight renders, 0.5 % on four unseen ones, 2.7 % on two
     * rendered without noise and 1.3-1.6 % at 4K, the map's error within 0.001 px but on those
     * (up to 0.011 px); and it does not depend on the searches: with no backward test at all, 1
     * hidden landmark-frame of 14 renders accepted, not 10. */
    p->max_jump = 2.5;
    /* The jump test's factor against the frame's median, which every landmark has from the first
     * frame: with an instrument in the reference, windows on its edge matched the frames after it
     * by 2-5 grey levels (the frame's median 1.4) while the tissue slid under it by up to 3 px,
     * within every other test (docs/landmarks.md, "An instrument in the reference"). */
    p->max_relative = 2.5;
    /* The reference frame's noise is in every frame's search: in the windows' difference, which
     * the photometric tests hold, and in the gradients every step solves with. On the phantom two
     * scenes with a noiseless reference frame (the rest as noisy) had 6 accepted landmark-frames
     * over 1 px instead of 36. Averaging the windows with the first 16 frames' matches leaves a
     * seventeenth of the reference's noise variance in them, 6 % of a difference's with the
     * frame's own; a landmark's error from the reference's noise stays in its own matches (they
     * were aligned with it), but each pixel's average rests on those of every landmark near it,
     * whose errors are independent. 8 frames left 50 over 1 px, 32 left 42; more blur the windows
     * with their matches' scatter. Measured on the eight standard renders: 40 accepted
     * landmark-frames over 1 px instead of 80, 13 % more accepted, the map's error lower on every
     * render (docs/landmarks.md, "The reference refined"). */
    p->refine = 16;
    /* Right after a reference a window on the edge of an instrument or blood matches as tissue
     * does: neither has moved yet. It goes wrong once the cover moves against the tissue, a few
     * frames on, and is refused from then; its few passes before are what was wrong. From 11 other
     * references of the eight standard renders (a cover in many), stillheart-eval with the truth's
     * markers accepted 13 landmark-frames the truth hides, 33 of landmarks chosen on a cover more
     * than 1 px from the tissue behind; `stillheart track` 6 and 37. Held back until a landmark's
     * 2nd, 3rd, 4th pass: 7, 3, 0 hidden (the track: 5, 3, 0), the 1 px tail 496 -> 457, 440, 418,
     * for 1.5-4.5 % of the landmark-frames, the map 0.3 % (ex vivo) and 0.9 % (in vivo) farther at
     * 4 from those references, 0.1 and 0.4 % from frame 0 (docs/landmarks.md, "Confirmed before
     * used"). 6: 0 hidden, the map 2-3 % farther. */
    p->confirm = 4;
}

void sh_landmarks_params_sparse(sh_landmarks_params *p)
{
    sh_landmarks_params_default(p);
    sh_landmarks_params_make_sparse(p);
}

void sh_landmarks_params_make_sparse(sh_landmarks_params *p)
{
    p->bound_factor = 4;
    p->plane = 1;
    /* the four corner markers' map lies 3-5 px from the tissue, at worst 11: their searches
     * start that far off, and need the pyramid's reach (with 1 level, 0.98 px of geometric error
     * against 0.69 with 3; 4 levels gain nothing) */
    p->flow.levels = 3;
    p->back_levels = -1;
    /* Blood between four tags covers landmarks whose map is the landmarks alone, and 400 asked
     * reach windows of texture as faint as the noise (a band-passed contrast of 3 grey levels),
     * which a uniform blob differs from by no more than their own frames do: on the phantom 4
     * hidden landmark-frames of 366 733 were accepted without this test. Over a blob the
     * frame's window is noise: a 21 px window of noise smoothed over 3x3 px holds about 49
     * independent samples, so chance correlations spread by about 1/sqrt(49) = 0.14, and the
     * search, which seeks the best match, ends up to 2-3 of those above 0; 0.4 is about 3. It
     * refuses all 4 and 0.6 % of the accepted, the map's error within 0.01 px on every render,
     * and the landmarks over 1 px 624 to 516 (docs/landmarks.md, "Four tags through the
     * product"). */
    p->min_correlation = 0.4;
    /* Held back, a landmark leaves its first frames to a map this far off: on the eight standard
     * renders' four corner tags, from frame 0, confirm 4 put the map with the landmarks 3.0 % (ex
     * vivo) and 4.7 % (in vivo) farther from the truth (docs/landmarks.md, "Confirmed before
     * used"), where the 16 tags' lost 0.1-0.4 %. */
    p->confirm = 1;
    /* Four tags' map rests on the landmarks alone between them, where the 16 tags' has markers:
     * a part of the field whose texture is weak, which the 200 strongest corners leave bare
     * (ex vivo seed 2's left half: 0-2 landmarks per 80 px square against 10-17 on its vessels),
     * is where it fails. Ranked within 40 px cells (about three spacings), each cell's best
     * taken as at least a tenth of the frame's best, the strong texture keeps its order and a
     * weak cell's best corners come in with the strong cells' middling ones: with four tags
     * rendered alone and 200 landmarks the geometric error falls 17 % ex vivo and 3 % in vivo,
     * seed 2 0.81 -> 0.53 px, every other render within 2 %, with 400 -3.5 % and +0.7 % (docs/
     * landmarks.md, "A choice balanced over the field"). With 16 tags the same tripled the
     * landmarks over 1 px off for no gain in the map: the defaults keep the strongest first. */
    p->balance_cell = 40;
    p->balance_floor = 0.1;
}

static sh_status check_params(const sh_landmarks_params *p)
{
    if (p->max_points < 1 || p->max_points > 100000)
        return sh_error_set(SH_EINVAL, "landmarks: max_points %d, not 1 to 100000", p->max_points);
    if (p->balance_cell < 0 || p->balance_cell > 4096 || !(p->balance_floor >= 0 && p->balance_floor <= 1))
        return sh_error_set(SH_EINVAL, "landmarks: balance cell %d (0 to 4096), floor %g (0 to 1)", p->balance_cell,
                            p->balance_floor);
    if (!(p->min_distance >= 0) || !(p->quality > 0 && p->quality <= 1) || !(p->tag_margin >= 0) ||
        p->highlight < 1 || p->highlight > 256)
        return sh_error_set(SH_EINVAL, "landmarks: min_distance, quality (0, 1], tag_margin >= 0 or highlight 1-256 "
                            "out of range");
    if (p->band != 0 && (p->band <= BAND_FINE || p->band > 64))
        return sh_error_set(SH_EINVAL, "landmarks: band %d: 0 (none) or %d to 64", p->band, BAND_FINE + 1);
    if (p->neighbours < 0 || p->neighbours > 64 || !(p->max_deviation_px > 0))
        return sh_error_set(SH_EINVAL, "landmarks: neighbours %d (0 to 64) or max_deviation_px not > 0", p->neighbours);
    if (!(p->bound_factor >= 0 && p->bound_factor <= 1000) || (p->plane && p->neighbours > 16))
        return sh_error_set(SH_EINVAL, "landmarks: bound_factor 0 to 1000, or plane with more than 16 neighbours");
    if ((p->affine != 0 && p->affine != 1) || (p->affine && p->neighbours < 2))
        return sh_error_set(SH_EINVAL, "landmarks: affine %d: 0 or 1, and 1 needs neighbours >= 2", p->affine);
    if (p->back_levels < -1 || p->back_levels > p->flow.levels)
        return sh_error_set(SH_EINVAL, "landmarks: back_levels %d: -1 or 0 to the tracker's %d levels", p->back_levels,
                            p->flow.levels);
    if (p->core < 0 || (p->core > 0 && (p->core % 2 == 0 || p->core > p->flow.win)))
        return sh_error_set(SH_EINVAL, "landmarks: core %d: 0 or odd, at most the window's %d", p->core, p->flow.win);
    if (p->refine < 0 || p->refine > 1000)
        return sh_error_set(SH_EINVAL, "landmarks: refine %d: 0 (the reference's own windows) to 1000", p->refine);
    if (p->confirm < 1 || p->confirm > 1000)
        return sh_error_set(SH_EINVAL, "landmarks: confirm %d: 1 (at once) to 1000", p->confirm);
    if (!(p->max_jump == 0 || (p->max_jump >= 1 && p->max_jump <= 1000)))
        return sh_error_set(SH_EINVAL, "landmarks: max_jump %g: 0 (no test) or 1 to 1000", p->max_jump);
    if (!(p->max_relative == 0 || (p->max_relative >= 1 && p->max_relative <= 1000)))
        return sh_error_set(SH_EINVAL, "landmarks: max_relative %g: 0 (no test) or 1 to 1000", p->max_relative);
    if (!(p->min_correlation >= 0 && p->min_correlation < 1))
        return sh_error_set(SH_EINVAL, "landmarks: min_correlation %g: 0 (no test) up to 1", p->min_correlation);
    if (p->reduce < -1 || p->reduce > 4)
        return sh_error_set(SH_EINVAL, "landmarks: reduce %d: -1 (automatic) or 0 to 4", p->reduce);
    if (!(p->max_photometric > 0) || !(p->max_backward_px >= 0) || !(p->max_disagreement_px > 0))
        return sh_error_set(SH_EINVAL, "landmarks: max_photometric and max_disagreement_px must be > 0, "
                            "max_backward_px >= 0");
    return SH_OK;
}

int sh_landmarks_reduction(const sh_landmarks_params *p, int width, int height)
{
    if (p && p->reduce >= 0) return p->reduce;
    if (width < 1 || height < 1) return 0;
    long k = lround(log2(sqrt((double)width * height) / 1440.0));
    return k < 0 ? 0 : k > 4 ? 4 : (int)k;
}

double sh_landmarks_smoothing(double lambda, int reduce) { return ldexp(lambda, 2 * reduce); }

/* A position between the frame's pixels and the reduced frame's: pixel centres at integers, a
 * reduced pixel the mean of a block of 2^k x 2^k, its centre at the block's. */
static inline float to_small(float v, int k) { return k ? (v + 0.5f) / (float)(1 << k) - 0.5f : v; }
static inline float to_full(float v, int k) { return k ? (v + 0.5f) * (float)(1 << k) - 0.5f : v; }

/* The frame's blocks of 2^reduce x 2^reduce pixels averaged (rounded to nearest) into lm->small,
 * for the reduced frame's pixels in r (x0, y0, x1, y1, half-open): a row's blocks summed down the
 * rows into lm->acc, then across. Exact integers, so any part is the same function of the frame. */
static void reduce_part(sh_landmarks *lm, const sh_plane *src, const int r[4])
{
    const int k = lm->reduce, b = 1 << k;
    const uint32_t half = 1u << (2 * k - 1);
    uint16_t *restrict acc = lm->acc;
    for (int y = r[1]; y < r[3]; y++) {
        const uint8_t *in = src->data + (size_t)b * y * src->stride;
        for (int x = b * r[0]; x < b * r[2]; x++) acc[x] = in[x];
        for (int dy = 1; dy < b; dy++) {
            const uint8_t *row = in + (size_t)dy * src->stride;
            for (int x = b * r[0]; x < b * r[2]; x++) acc[x] = (uint16_t)(acc[x] + row[x]);
        }
        uint8_t *out = lm->small + (size_t)y * lm->width;
        for (int x = r[0]; x < r[2]; x++) {
            uint32_t t = 0;
            for (int dx = 0; dx < b; dx++) t += acc[b * x + dx];
            out[x] = (uint8_t)((t + half) >> (2 * k));
        }
    }
}

/* The brightest pixel of each block of the reference, for the highlight test (a highlight a pixel
 * wide is still one in the reduced frame), into out (width x height of the reduced frame). */
static void reduce_max(const sh_landmarks *lm, const sh_plane *src, uint8_t *out)
{
    const int b = 1 << lm->reduce;
    for (int y = 0; y < lm->height; y++)
        for (int x = 0; x < lm->width; x++) {
            uint8_t m = 0;
            for (int dy = 0; dy < b; dy++)
                for (int dx = 0; dx < b; dx++) {
                    uint8_t v = src->data[(size_t)(b * y + dy) * src->stride + b * x + dx];
                    m = v > m ? v : m;
                }
            out[(size_t)y * lm->width + x] = m;
        }
}

/* Squared distance from (x, y) to the segment a-b. */
static double seg_dist2(double x, double y, double ax, double ay, double bx, double by)
{
    double dx = bx - ax, dy = by - ay, l2 = dx * dx + dy * dy;
    double t = l2 > 0 ? ((x - ax) * dx + (y - ay) * dy) / l2 : 0;
    t = t < 0 ? 0 : t > 1 ? 1 : t;
    double ex = ax + t * dx - x, ey = ay + t * dy - y;
    return ex * ex + ey * ey;
}

/* Inside the quad (either winding) or within r of its edges. */
static int near_quad(const double *q, double x, double y, double r)
{
    int pos = 0, neg = 0;
    for (int k = 0; k < 4; k++) {
        const double *a = q + 2 * k, *b = q + 2 * ((k + 1) % 4);
        if (seg_dist2(x, y, a[0], a[1], b[0], b[1]) <= r * r) return 1;
        double c = (b[0] - a[0]) * (y - a[1]) - (b[1] - a[1]) * (x - a[0]);
        pos += c > 0;
        neg += c < 0;
    }
    return !(pos && neg);
}

/* Clears every pixel of the mask near a tag: its quad grown by the quiet zone (an eighth of the
 * mean side), the margin and half a window. */
static void clear_tags(uint8_t *mask, int w, int h, const double *tags, int n_tags, double margin, int half_win)
{
    for (int t = 0; t < n_tags; t++) {
        const double *q = tags + 8 * t;
        double side = 0, x0 = INFINITY, x1 = -INFINITY, y0 = INFINITY, y1 = -INFINITY;
        for (int k = 0; k < 4; k++) {
            const double *a = q + 2 * k, *b = q + 2 * ((k + 1) % 4);
            side += hypot(b[0] - a[0], b[1] - a[1]) / 4;
            x0 = fmin(x0, a[0]), x1 = fmax(x1, a[0]), y0 = fmin(y0, a[1]), y1 = fmax(y1, a[1]);
        }
        if (!isfinite(side)) continue;
        double r = side / 8 + margin + half_win;
        int px0 = (int)fmax(0, floor(x0 - r)), px1 = (int)fmin(w - 1, ceil(x1 + r));
        int py0 = (int)fmax(0, floor(y0 - r)), py1 = (int)fmin(h - 1, ceil(y1 + r));
        for (int y = py0; y <= py1; y++)
            for (int x = px0; x <= px1; x++)
                if (near_quad(q, x, y, r)) mask[(size_t)y * w + x] = 0;
    }
}

/* Clears every pixel whose window (side 2 * half_win + 1) holds a highlight, through an integral
 * image of the highlight pixels. */
static sh_status clear_highlights(uint8_t *mask, const sh_plane *luma, int level, int half_win)
{
    int w = luma->width, h = luma->height;
    uint32_t *sum = calloc((size_t)(w + 1) * (h + 1), sizeof *sum);
    if (!sum) return sh_error_set(SH_ENOMEM, "landmarks: out of memory");
    for (int y = 0; y < h; y++) {
        uint32_t row = 0;
        for (int x = 0; x < w; x++) {
            row += luma->data[(size_t)y * luma->stride + x] >= level;
            sum[(size_t)(y + 1) * (w + 1) + x + 1] = sum[(size_t)y * (w + 1) + x + 1] + row;
        }
    }
    for (int y = 0; y < h; y++) {
        int ya = y - half_win < 0 ? 0 : y - half_win, yb = y + half_win + 1 > h ? h : y + half_win + 1;
        for (int x = 0; x < w; x++) {
            if (!mask[(size_t)y * w + x]) continue; /* most of the frame: outside the hull */
            int xa = x - half_win < 0 ? 0 : x - half_win, xb = x + half_win + 1 > w ? w : x + half_win + 1;
            uint32_t c = sum[(size_t)yb * (w + 1) + xb] - sum[(size_t)ya * (w + 1) + xb] -
                         sum[(size_t)yb * (w + 1) + xa] + sum[(size_t)ya * (w + 1) + xa];
            if (c) mask[(size_t)y * w + x] = 0;
        }
    }
    free(sum);
    return SH_OK;
}

/* Where a landmark may be chosen (landmarks.h): the hull, off the tags and highlights, half a
 * window inside the image. ref: the reduced frame (its brightest pixels); the hull is in the
 * frame's own pixels, the tags in the reduced frame's. */
static sh_status make_mask(const sh_landmarks_params *p, const sh_plane *ref, int reduce, const sh_hull *hull,
                           const double *tags, int n_tags, uint8_t *mask)
{
    int w = ref->width, h = ref->height, half = p->flow.win / 2;
    /* the hull's span once a row (sh_hull_contains for each pixel was 40 ms of a 1080p frame's) */
    for (int y = 0; y < h; y++) {
        double lo = -INFINITY, hi = INFINITY;
        const int row = y >= half && y < h - half &&
                        (!hull || sh_hull_row_accepts(hull, to_full((float)y, reduce), &lo, &hi));
        for (int x = 0; x < w; x++) {
            const double fx = to_full((float)x, reduce);
            mask[(size_t)y * w + x] = row && x >= half && x < w - half && lo <= fx && fx <= hi;
        }
    }
    clear_tags(mask, w, h, tags, n_tags, p->tag_margin, half);
    return clear_highlights(mask, ref, p->highlight, half);
}

/* v[lo] + ... + v[hi - 1] */
static inline uint32_t cols_sum(const uint32_t *v, int lo, int hi)
{
    uint32_t t = 0;
    for (int k = lo; k < hi; k++) t += v[k];
    return t;
}

/* The band-pass (landmarks.h): 128 + gain (mean over (2 r1 + 1)^2 - mean over (2 r2 + 1)^2),
 * r1 = BAND_FINE, clamped to 0..255, the boxes clipped at the image's edge. gain <= 0: chosen
 * here so that the 99th percentile of |mean difference| maps to 100 grey levels (within 1..16),
 * which uses the 8 bits without clipping the texture; the reference sets it and every frame
 * keeps it.
 *
 * The box sums are exact integers, kept as running sums: per column, the sum over each box's
 * rows (a row added as it enters, one taken away as it leaves); then per row the fine box's
 * three such columns added, and the coarse box's as the difference of a prefix sum of them.
 * Sequential memory and no division per pixel. Only the
 * pixels of a part of the frame are made (a frame's, the part its pyramid reads): each is the
 * same function of the frame's pixels wherever the part lies, as the sums are exact. Inlined, as
 * column_add is, into each of band_pass's clones (LM_CLONES), so that each is built for its target. */
static inline __attribute__((always_inline)) void band_row(const sh_landmarks *lm, int w, int y, int h, int r2,
                                                           const int part[4], int pass, uint32_t *hist)
{
    const int r1 = BAND_FINE;
    const uint32_t *v1 = lm->colsum, *v2 = v1 + w;
    uint32_t *restrict p2 = lm->prefix;
    const int *l1 = lm->cols, *m1 = l1 + w, *l2 = m1 + w, *m2 = l2 + w;
    const float *iw1 = (const float *)(m2 + w), *iw2 = iw1 + w;
    /* the coarse box's prefix sums over the columns the part's boxes reach, indexed by column:
     * p2[c0] = 0 (a serial loop: the fine box, three columns, is summed directly instead, in
     * the vectorized loops below) */
    const int c0 = part[0] - r2 > 0 ? part[0] - r2 : 0, c1 = part[2] + r2 < w ? part[2] + r2 : w;
    /* the running sum in a register: through memory, each step would wait for the last store */
    uint32_t run2 = 0;
    p2[c0] = 0;
    for (int x = c0; x < c1; x++) {
        run2 += v2[x];
        p2[x + 1] = run2;
    }
    int a1 = y - r1 < 0 ? 0 : y - r1, b1 = y + r1 + 1 > h ? h : y + r1 + 1;
    int a2 = y - r2 < 0 ? 0 : y - r2, b2 = y + r2 + 1 > h ? h : y + r2 + 1;
    const float ih1 = 1.0f / (float)(b1 - a1), ih2 = 1.0f / (float)(b2 - a2), gain = lm->gain;
    uint8_t *restrict out = lm->band + (size_t)y * w;
    if (pass) {
        for (int x = part[0]; x < part[2]; x++) {
            float s1 = (float)cols_sum(v1, l1[x], m1[x]) * (ih1 * iw1[x]);
            float s2 = (float)(p2[m2[x]] - p2[l2[x]]) * (ih2 * iw2[x]);
            float d = fabsf(s1 - s2);
            hist[d >= 255 ? 255 : (int)d]++;
        }
        return;
    }
    /* the columns whose boxes the image's sides do not clip, with their constant widths (the
     * same arithmetic: 1 / width is the same float either way), in a loop gcc vectorizes; then
     * the ones near the sides. A box's sum is below 2^24, so the difference of two prefix sums
     * converts exactly through int32 (which vectorizes, where uint32 does not). The rounding to
     * an integer is lrintf's (the current mode, to nearest even by default) without the call:
     * adding 1.5 * 2^23 to a value in [0, 255] leaves no fraction bits, and taking it away
     * again is exact (no -ffast-math here, and -ffp-contract=off). */
    const float round = 0x1.8p23f;
    const int xa = r2 < w ? r2 : w, xb = w - r2 - 1 > xa ? w - r2 - 1 : xa;
    const int x0 = part[0] > xa ? part[0] : xa, x1 = part[2] < xb ? part[2] : xb;
    const float k1 = ih1 * (1.0f / (float)(2 * r1 + 1)), k2 = ih2 * (1.0f / (float)(2 * r2 + 1));
    for (int x = x0; x < x1; x++) {
        uint32_t f = 0;
        for (int k = -r1; k <= r1; k++) f += v1[x + k];
        float s1 = (float)(int32_t)f * k1;
        float s2 = (float)(int32_t)(p2[x + r2 + 1] - p2[x - r2]) * k2;
        /* rounded, then clamped to 0..255 as integers (float compares are branches to gcc): the
         * same as clamped then rounded, 0 and 255 being integers; |v| < 128 + 16 * 255 < 2^22,
         * where the rounding above holds */
        int32_t q = (int32_t)(((128 + gain * (s1 - s2)) + round) - round);
        q = q > 0 ? q : 0;
        out[x] = (uint8_t)(q < 255 ? q : 255);
    }
    for (int x = part[0]; x < part[2]; x++) {
        if (x == x0 && x0 < x1) x = x1;
        if (x >= part[2]) break;
        float s1 = (float)cols_sum(v1, l1[x], m1[x]) * (ih1 * iw1[x]);
        float s2 = (float)(p2[m2[x]] - p2[l2[x]]) * (ih2 * iw2[x]);
        float v = 128 + gain * (s1 - s2);
        v = v > 0 ? v : 0;
        v = v < 255 ? v : 255;
        out[x] = (uint8_t)(int32_t)((v + round) - round);
    }
}

/* Adds (sign 1) or takes away (-1) row y of src, columns [x0, x1), to a box's column sums. */
static inline __attribute__((always_inline)) void column_add(uint32_t *restrict v, const sh_plane *src, int y,
                                                             int x0, int x1, int sign)
{
    const uint8_t *restrict in = src->data + (size_t)y * src->stride;
    if (sign > 0)
        for (int x = x0; x < x1; x++) v[x] += in[x];
    else
        for (int x = x0; x < x1; x++) v[x] -= in[x];
}

/* The boxes' column ranges and reciprocal widths, once per reference. */
static void band_columns(sh_landmarks *lm, int r1, int r2)
{
    const int w = lm->width;
    int *l1 = lm->cols, *m1 = l1 + w, *l2 = m1 + w, *m2 = l2 + w;
    float *iw1 = (float *)(m2 + w), *iw2 = iw1 + w;
    for (int x = 0; x < w; x++) {
        l1[x] = x - r1 < 0 ? 0 : x - r1, m1[x] = x + r1 + 1 > w ? w : x + r1 + 1;
        l2[x] = x - r2 < 0 ? 0 : x - r2, m2[x] = x + r2 + 1 > w ? w : x + r2 + 1;
        iw1[x] = 1.0f / (float)(m1[x] - l1[x]);
        iw2[x] = 1.0f / (float)(m2[x] - l2[x]);
    }
}

/* The band-passed pixels of src in part (x0, y0, x1, y1, half-open, within the frame) into
 * lm->band; first the gain when it is not set yet (the whole frame then). */
LM_CLONES static void band_pass(sh_landmarks *lm, const sh_plane *src, int r2, const int part[4])
{
    const int r1 = BAND_FINE;
    const int w = src->width, h = src->height;
    /* the columns whose sums the part's boxes read */
    const int c0 = part[0] - r2 > 0 ? part[0] - r2 : 0, c1 = part[2] + r2 < w ? part[2] + r2 : w;
    uint32_t hist[256] = {0};
    for (int pass = lm->gain <= 0; pass >= 0; pass--) {
        uint32_t *v1 = lm->colsum, *v2 = v1 + w;
        memset(v1 + c0, 0, (size_t)(c1 - c0) * sizeof *v1);
        memset(v2 + c0, 0, (size_t)(c1 - c0) * sizeof *v2);
        /* the first row's boxes: rows [y0 - r, y0 + r] within the frame */
        const int y0 = part[1];
        for (int y = y0 - r1 > 0 ? y0 - r1 : 0; y < h && y <= y0 + r1; y++) column_add(v1, src, y, c0, c1, 1);
        for (int y = y0 - r2 > 0 ? y0 - r2 : 0; y < h && y <= y0 + r2; y++) column_add(v2, src, y, c0, c1, 1);
        for (int y = y0; y < part[3]; y++) {
            if (y > y0) {
                if (y + r1 < h) column_add(v1, src, y + r1, c0, c1, 1);
                if (y - r1 - 1 >= 0) column_add(v1, src, y - r1 - 1, c0, c1, -1);
                if (y + r2 < h) column_add(v2, src, y + r2, c0, c1, 1);
                if (y - r2 - 1 >= 0) column_add(v2, src, y - r2 - 1, c0, c1, -1);
            }
            band_row(lm, w, y, h, r2, part, pass, hist);
        }
        if (pass) {
            uint64_t want = (uint64_t)w * h * 99 / 100, seen = 0;
            int k = 0;
            while (k < 255 && (seen += hist[k]) < want) k++;
            float g = 100.0f / (float)(k + 1);
            lm->gain = g < 1 ? 1 : g > 16 ? 16 : g;
        }
    }
}

/* Each landmark's `neighbours` nearest others by reference position (fewer when there are fewer
 * landmarks), nearest first: a partial insertion sort per landmark, O(n^2 k) once per reference. */
static void find_neighbours(sh_landmarks *lm)
{
    int n = lm->n, k = lm->p.neighbours < n - 1 ? lm->p.neighbours : n - 1;
    float *d = lm->scratch;
    for (int i = 0; i < n; i++) {
        int *row = lm->near + (size_t)i * lm->p.neighbours, have = 0;
        for (int j = 0; j < n; j++) {
            if (j == i) continue;
            float dx = lm->ref_xy[2 * j] - lm->ref_xy[2 * i], dy = lm->ref_xy[2 * j + 1] - lm->ref_xy[2 * i + 1];
            float dj = dx * dx + dy * dy;
            if (have == k && dj >= d[k - 1]) continue;
            int at = have < k ? have++ : k - 1;
            while (at > 0 && d[at - 1] > dj) {
                d[at] = d[at - 1];
                row[at] = row[at - 1];
                at--;
            }
            d[at] = dj;
            row[at] = j;
        }
        for (int m = have; m < lm->p.neighbours; m++) row[m] = -1;
    }
}

static int cmp_float(const void *a, const void *b)
{
    float x = *(const float *)a, y = *(const float *)b;
    return (x > y) - (x < y);
}

/* The median of v[0..m) (m >= 1), reordering v. */
static float median(float *v, int m)
{
    qsort(v, (size_t)m, sizeof *v, cmp_float);
    return m & 1 ? v[m / 2] : 0.5f * (v[m / 2 - 1] + v[m / 2]);
}

/* The object's buffers, sized once per reference (nothing is allocated per frame). */
static sh_status allocate(sh_landmarks *lm)
{
    const sh_landmarks_params *params = &lm->p;
    size_t m = (size_t)params->max_points;
    lm->ref_full = malloc(2 * m * sizeof *lm->ref_full);
    lm->pred = malloc(2 * m * sizeof *lm->pred);
    if (lm->reduce) {
        lm->small = malloc((size_t)lm->width * lm->height);
        lm->acc = malloc((size_t)lm->full_width * sizeof *lm->acc);
    }
    lm->ref_xy = malloc(2 * m * sizeof *lm->ref_xy);
    lm->fwd = malloc(2 * m * sizeof *lm->fwd);
    lm->back = malloc(2 * m * sizeof *lm->back);
    lm->err = malloc(m * sizeof *lm->err);
    lm->core_err = malloc(m * sizeof *lm->core_err);
    lm->corr = malloc(m * sizeof *lm->corr);
    lm->hist = malloc(SH_CALIB_MAX_CAMERAS * JUMP_HISTORY * m * sizeof *lm->hist);
    lm->hist_n = calloc(SH_CALIB_MAX_CAMERAS * m, 1);
    lm->hist_at = calloc(SH_CALIB_MAX_CAMERAS * m, 1);
    lm->jump_limit = malloc(m * sizeof *lm->jump_limit);
    lm->passed = calloc(m, sizeof *lm->passed);
    lm->st_fwd = malloc(m);
    lm->st_back = malloc(m);
    lm->near = malloc(m * (size_t)(params->neighbours + 1) * sizeof *lm->near);
    lm->scratch = malloc(2 * (size_t)(params->neighbours + 1) * sizeof *lm->scratch);
    lm->colsum = malloc(2 * (size_t)lm->width * sizeof *lm->colsum);
    lm->prefix = malloc(((size_t)lm->width + 1) * sizeof *lm->prefix);
    lm->band = malloc((size_t)lm->width * lm->height);
    lm->cols = malloc(6 * (size_t)lm->width * sizeof(int));
    lm->redo = malloc(m * sizeof *lm->redo);
    lm->redo_xy = malloc(7 * m * sizeof *lm->redo_xy);
    lm->redo_st = malloc(2 * m);
    lm->dist = malloc(m * sizeof *lm->dist);
    lm->jac = malloc(4 * m * sizeof *lm->jac);
    lm->warp = malloc(4 * m * sizeof *lm->warp);
    lm->voters = malloc(((size_t)params->neighbours + 1) * sizeof *lm->voters);
    lm->tri_cap = params->neighbours * (params->neighbours - 1) * (params->neighbours - 2) / 6 + 1;
    lm->tri = malloc(2 * (size_t)lm->tri_cap * sizeof *lm->tri);
    if (!lm->ref_xy || !lm->fwd || !lm->back || !lm->err || !lm->core_err || !lm->corr || !lm->st_fwd || !lm->st_back || !lm->near ||
        !lm->scratch || !lm->colsum || !lm->prefix || !lm->band || !lm->cols || !lm->redo || !lm->redo_xy ||
        !lm->redo_st || !lm->voters || !lm->dist || !lm->tri || !lm->ref_full || !lm->pred || !lm->jac ||
        !lm->warp || !lm->hist || !lm->hist_n || !lm->hist_at || !lm->jump_limit || !lm->passed ||
        (lm->reduce && (!lm->small || !lm->acc)))
        return sh_error_set(SH_ENOMEM, "landmarks: out of memory");
    return SH_OK;
}

/* The box x0, y0, x1, y1 (x1, y1 past the end) of mask's allowed pixels grown by margin, within the
 * w x h frame; the whole frame when none is allowed. The corners are looked for in it alone: a
 * pixel `margin` or more inside it, where every allowed one lies, has the gradients (1 px each
 * way), the summed block (block / 2) and the 3x3 maximum (1 px) of the whole frame's search, and
 * the strongest response, the ties' row-major order and the spacing are the same within it, so
 * the same corners are chosen, at a fraction of the cost (the hull is an eighth of a 1080p frame
 * in the bench: 35 ms of the whole frame's responses and 16 MB of scratch, docs/landmarks.md). */
static void mask_box(const uint8_t *mask, int w, int h, int margin, int box[4])
{
    int x0 = w, y0 = h, x1 = -1, y1 = -1;
    for (int y = 0; y < h; y++) {
        const uint8_t *row = mask + (size_t)y * w, *on = memchr(row, 1, (size_t)w);
        if (!on) continue;
        int first = (int)(on - row), last = w - 1;
        while (!row[last]) last--;
        if (y0 > y) y0 = y;
        y1 = y;
        if (x0 > first) x0 = first;
        if (x1 < last) x1 = last;
    }
    if (x1 < 0) {
        box[0] = box[1] = 0, box[2] = w, box[3] = h;
        return;
    }
    box[0] = x0 - margin > 0 ? x0 - margin : 0;
    box[1] = y0 - margin > 0 ? y0 - margin : 0;
    box[2] = x1 + 1 + margin < w ? x1 + 1 + margin : w;
    box[3] = y1 + 1 + margin < h ? y1 + 1 + margin : h;
}

/* The choice (landmarks.h): where a window may lie, in the reference reduced (`reduce`) and
 * band-passed (its gain set here), then the corners there. *band: the plane the reference's
 * pyramid is built from. */
static sh_status choose(sh_landmarks *lm, const sh_plane *reference, const sh_hull *hull, const double *tags,
                        int n_tags, sh_plane *band)
{
    const sh_landmarks_params *params = &lm->p;
    uint8_t *mask = malloc((size_t)lm->width * lm->height);
    double *small_tags = lm->reduce && n_tags > 0 ? malloc(8 * (size_t)n_tags * sizeof *small_tags) : NULL;
    if (!mask || (lm->reduce && n_tags > 0 && !small_tags)) {
        free(mask), free(small_tags);
        return sh_error_set(SH_ENOMEM, "landmarks: out of memory");
    }
    sh_plane ref = *reference;
    if (lm->reduce) {
        /* the mask's highlights from each block's brightest pixel (mask holds them for the while) */
        reduce_max(lm, reference, mask);
        reduce_part(lm, reference, (const int[4]){0, 0, lm->width, lm->height});
        ref = (sh_plane){lm->small, lm->width, lm->height, lm->width};
        for (int i = 0; i < 8 * n_tags; i++) small_tags[i] = to_small((float)tags[i], lm->reduce);
        tags = small_tags;
    }
    const sh_plane bright = lm->reduce ? (sh_plane){mask, lm->width, lm->height, lm->width} : ref;
    uint8_t *allowed = lm->reduce ? lm->band : mask; /* lm->band is free until the band-pass */
    sh_status st = make_mask(params, &bright, lm->reduce, hull, tags, n_tags, allowed);
    if (lm->reduce) memcpy(mask, allowed, (size_t)lm->width * lm->height);
    free(small_tags);
    *band = ref;
    if (params->band > 0) {
        const int all[4] = {0, 0, lm->width, lm->height};
        band_columns(lm, BAND_FINE, params->band);
        band_pass(lm, &ref, params->band, all);
        *band = (sh_plane){lm->band, lm->width, lm->height, lm->width};
    }
    if (st == SH_OK) {
        sh_flow_corner_params cp;
        sh_flow_corner_params_default(&cp);
        cp.max_points = params->max_points;
        cp.quality = params->quality;
        cp.min_distance = params->min_distance;
        cp.balance_cell = params->balance_cell;
        cp.balance_floor = params->balance_floor;
        int box[4];
        mask_box(mask, lm->width, lm->height, 2 + cp.block / 2, box);
        const size_t at = (size_t)box[1] * (size_t)band->stride + (size_t)box[0];
        const sh_plane bp = {band->data + at, box[2] - box[0], box[3] - box[1], band->stride};
        const sh_plane mp = {mask + (size_t)box[1] * lm->width + box[0], box[2] - box[0], box[3] - box[1], lm->width};
        st = sh_flow_corners(&bp, &mp, &cp, lm->ref_xy, &lm->n);
        for (int i = 0; st == SH_OK && i < lm->n; i++)
            lm->ref_xy[2 * i] += (float)box[0], lm->ref_xy[2 * i + 1] += (float)box[1];
    }
    free(mask);
    for (int i = 0; st == SH_OK && i < 2 * lm->n; i++) lm->ref_full[i] = to_full(lm->ref_xy[i], lm->reduce);
    return st;
}

/* The reference refined (landmarks.h, refine): the pixels a window's search reads at the
 * frame's level, with its gradients and bilinear neighbours (REFINE_REACH past the window's half
 * side), around each landmark's reference position are averaged with where the matches of the
 * first `refine` frames put them. Those farther off would come through the map's local affine
 * from farther than it was fitted for: refining the pixels 21 px round each (all the coarser
 * level's window reads) put twice as many landmark-frames over 1 px on the eight renders. */
#define REFINE_REACH 2

static void box_add(const sh_landmarks *lm, float box[4], float x, float y);
static void box_grow(float box[4], float r);

/* The sums start from the reference (band: the plane its pyramid was built from), counted once,
 * over the part of the frame sh_flow_pyramid_update_box reads for the box of the positions grown
 * by the reach: every pixel the refinement changes lies in that box. */
static sh_status refine_start(sh_landmarks *lm, const sh_plane *band)
{
    const float reach = (float)(lm->p.flow.win / 2 + REFINE_REACH);
    float *b = lm->rbox;
    b[0] = b[1] = INFINITY, b[2] = b[3] = -INFINITY;
    for (int i = 0; i < lm->n; i++) box_add(lm, b, lm->ref_xy[2 * i], lm->ref_xy[2 * i + 1]);
    box_grow(b, reach);
    sh_status st = sh_flow_pyramid_box_part(lm->ref, b, 1, lm->rpart);
    if (st != SH_OK) return st;
    const int *r = lm->rpart, w = r[2] - r[0];
    const size_t area = (size_t)w * (size_t)(r[3] - r[1]);
    lm->rsum = malloc(area * sizeof *lm->rsum);
    lm->rcnt = malloc(area * sizeof *lm->rcnt);
    if (!lm->rsum || !lm->rcnt) return sh_error_set(SH_ENOMEM, "landmarks: out of memory");
    for (int y = r[1]; y < r[3]; y++)
        for (int x = r[0]; x < r[2]; x++) {
            const size_t o = (size_t)(y - r[1]) * (size_t)w + (size_t)(x - r[0]);
            lm->rsum[o] = band->data[(size_t)y * band->stride + x];
            lm->rcnt[o] = 1;
        }
    return SH_OK;
}

/* One row of a landmark's pixels into the sums: pixels x0..x1-1 of row y (reference), each
 * sampled at f + J (x - r, y - r) in src (bilinear), every sample inside the part built. The
 * same float operations per pixel wherever it is called and in every clone (-ffp-contract=off),
 * so that the vectorized clones add the same sums. */
LM_CLONES static void refine_row(const sh_plane *src, const float *J, float rx, float ry, float fx, float fy, int x0,
                                 int x1, int y, float *restrict sum, uint32_t *restrict cnt)
{
    const float dy = (float)y - ry, ox = fx + J[1] * dy, oy = fy + J[3] * dy;
    const ptrdiff_t st = src->stride;
    for (int x = x0; x < x1; x++) {
        const float dx = (float)x - rx, sx = ox + J[0] * dx, sy = oy + J[2] * dx;
        const int ix = (int)sx, iy = (int)sy;
        const float ax = sx - (float)ix, ay = sy - (float)iy;
        const uint8_t *p = src->data + (ptrdiff_t)iy * st + ix;
        sum[x - x0] += (1 - ay) * ((1 - ax) * (float)p[0] + ax * (float)p[1]) +
                       ay * ((1 - ax) * (float)p[st] + ax * (float)p[st + 1]);
        cnt[x - x0]++;
    }
}

/* One frame into the refinement: each accepted landmark's pixels (within the reach of its
 * reference position) sampled where its match puts them, through the markers' map's local affine
 * when the searches used it (bilinear, from the plane the frame's pyramid was built from, where
 * it was built: a window whose samples would reach past that is left out of this frame's sums).
 * Every landmark near a pixel adds its sample, so a window's refined pixels rest on its
 * neighbours' matches too: on the eight renders 40 accepted landmark-frames over 1 px, against 60
 * when each pixel took only its nearest landmark's. The pyramid and the windows are made anew
 * after the 1st, 2nd, 4th, ... frame and the last (each halves the reference's share of the
 * noise, so the early frames gain at once, for log2(refine) + 2 updates of a part of the
 * pyramid); after the last, the sums are freed. */
static sh_status refine(sh_landmarks *lm, const uint8_t *verdict)
{
    const int R = lm->p.flow.win / 2 + REFINE_REACH, *r = lm->rpart, w = r[2] - r[0], *b = lm->built;
    static const float identity[4] = {1, 0, 0, 1};
    int used = 0;
    for (int i = 0; i < lm->n; i++) {
        if (verdict[i] != SH_LANDMARK_ACCEPTED) continue;
        const float *J = lm->affine ? lm->jac + 4 * i : identity;
        const float rx = lm->ref_xy[2 * i], ry = lm->ref_xy[2 * i + 1], fx = lm->fwd[2 * i], fy = lm->fwd[2 * i + 1];
        const int cx = (int)lrintf(rx), cy = (int)lrintf(ry);
        const int x0 = cx - R > r[0] ? cx - R : r[0], x1 = cx + R + 1 < r[2] ? cx + R + 1 : r[2];
        const int y0 = cy - R > r[1] ? cy - R : r[1], y1 = cy + R + 1 < r[3] ? cy + R + 1 : r[3];
        if (x0 >= x1 || y0 >= y1) continue;
        /* the samples' box: the affine's extremes are at the corners; a pixel's margin for the
         * rounding of the per-pixel sums and the bilinear neighbour */
        float lo[2] = {INFINITY, INFINITY}, hi[2] = {-INFINITY, -INFINITY};
        for (int c = 0; c < 4; c++) {
            const float dx = (float)(c & 1 ? x1 - 1 : x0) - rx, dy = (float)(c & 2 ? y1 - 1 : y0) - ry;
            const float s[2] = {fx + J[0] * dx + J[1] * dy, fy + J[2] * dx + J[3] * dy};
            for (int a = 0; a < 2; a++) lo[a] = s[a] < lo[a] ? s[a] : lo[a], hi[a] = s[a] > hi[a] ? s[a] : hi[a];
        }
        if (!(lo[0] >= (float)b[0] + 1 && lo[1] >= (float)b[1] + 1 && hi[0] < (float)b[2] - 2 && hi[1] < (float)b[3] - 2))
            continue;
        for (int y = y0; y < y1; y++) {
            const size_t o = (size_t)(y - r[1]) * (size_t)w + (size_t)(x0 - r[0]);
            refine_row(&lm->src, J, rx, ry, fx, fy, x0, x1, y, lm->rsum + o, lm->rcnt + o);
        }
        used = 1;
    }
    if (!used) return SH_OK;
    const int k = ++lm->refined;
    if ((k & (k - 1)) != 0 && k != lm->p.refine) return SH_OK;
    /* the refined part into the band's buffer (this frame is done with it), rounded as lrintf
     * does (to nearest, even on a tie: 1.5 2^23 added and taken away, exact in [0, 255]), then the
     * pyramid and the windows made anew from it */
    const float round = 0x1.8p23f;
    for (int y = r[1]; y < r[3]; y++) {
        const float *sum = lm->rsum + (size_t)(y - r[1]) * (size_t)w;
        const uint32_t *cnt = lm->rcnt + (size_t)(y - r[1]) * (size_t)w;
        uint8_t *out = lm->band + (size_t)y * lm->width + r[0];
        for (int x = 0; x < w; x++) out[x] = (uint8_t)(int32_t)((sum[x] / (float)cnt[x] + round) - round);
    }
    const sh_plane plane = {lm->band, lm->width, lm->height, lm->width};
    sh_status st = sh_flow_pyramid_update_box(lm->ref, &plane, lm->rbox);
    if (st != SH_OK) return st;
    sh_flow_windows_refresh(lm->ref_win);
    if (k == lm->p.refine) {
        free(lm->rsum), free(lm->rcnt);
        lm->rsum = NULL, lm->rcnt = NULL;
    }
    return SH_OK;
}

sh_status sh_landmarks_create(const sh_landmarks_params *params, const sh_plane *reference, const sh_hull *hull,
                              const double *tags, int n_tags, sh_landmarks **out)
{
    sh_status st = check_params(params);
    if (st != SH_OK) return st;
    if (!reference || !reference->data || reference->width < 2 || reference->height < 2 || n_tags < 0 ||
        (n_tags > 0 && !tags))
        return sh_error_set(SH_EINVAL, "landmarks: no reference plane, or tags missing");
    int k = sh_landmarks_reduction(params, reference->width, reference->height);
    if (k && ((reference->width >> k) <= params->flow.win || (reference->height >> k) <= params->flow.win))
        return sh_error_set(SH_EINVAL, "landmarks: a %dx%d frame halved %d times is no larger than a %d px window",
                            reference->width, reference->height, k, params->flow.win);
    sh_landmarks *lm = calloc(1, sizeof *lm);
    if (!lm) return sh_error_set(SH_ENOMEM, "landmarks: out of memory");
    lm->p = *params;
    lm->reduce = k;
    lm->full_width = reference->width;
    lm->full_height = reference->height;
    lm->width = reference->width >> k;
    lm->height = reference->height >> k;
    sh_plane band;
    st = allocate(lm);
    if (st == SH_OK) st = choose(lm, reference, hull, tags, n_tags, &band);
    if (st == SH_OK && params->neighbours > 0) find_neighbours(lm);
    if (st == SH_OK) st = sh_flow_pyramid_create(lm->width, lm->height, &params->flow, &lm->ref);
    if (st == SH_OK) st = sh_flow_pyramid_create(lm->width, lm->height, &params->flow, &lm->cur);
    if (st == SH_OK) st = sh_flow_pyramid_build(lm->ref, &band, 1);
    if (st == SH_OK) st = sh_flow_windows_create(&params->flow, lm->ref, lm->n, lm->ref_xy, &lm->ref_win);
    if (st == SH_OK && params->refine > 0 && lm->n > 0) st = refine_start(lm, &band);
    if (st != SH_OK) {
        sh_landmarks_destroy(lm);
        return st;
    }
    *out = lm;
    return SH_OK;
}

void sh_landmarks_destroy(sh_landmarks *lm)
{
    if (!lm) return;
    sh_flow_pyramid_destroy(lm->ref);
    sh_flow_pyramid_destroy(lm->cur);
    sh_flow_windows_destroy(lm->ref_win);
    free(lm->ref_xy);
    free(lm->fwd);
    free(lm->back);
    free(lm->err);
    free(lm->core_err);
    free(lm->corr);
    free(lm->st_fwd);
    free(lm->st_back);
    free(lm->near);
    free(lm->scratch);
    free(lm->colsum);
    free(lm->prefix);
    free(lm->band);
    free(lm->cols);
    free(lm->redo);
    free(lm->redo_xy);
    free(lm->redo_st);
    free(lm->small), free(lm->acc), free(lm->ref_full), free(lm->pred);
    free(lm->voters), free(lm->tri), free(lm->dist);
    free(lm->jac), free(lm->warp);
    free(lm->hist), free(lm->hist_n), free(lm->hist_at), free(lm->jump_limit), free(lm->passed);
    free(lm->rsum), free(lm->rcnt);
    free(lm);
}

int sh_landmarks_count(const sh_landmarks *lm) { return lm->n; }
const float *sh_landmarks_reference(const sh_landmarks *lm) { return lm->ref_full; }

/* The last test: a landmark's correction of the map (its position minus the prediction) against
 * the median correction of its nearest landmarks that passed the others. The map's own error is
 * smooth between the markers, so correct neighbours correct it alike; a landmark whose window
 * matched the wrong place, consistently both ways and within the map's reach, stands out. Too
 * few neighbours to tell (fewer than 3 that passed): refused, as nothing vouches for it. */
/* What landmark i's correction is expected to be from its m voters q[] (their corrections vx, vy,
 * relative to the markers' map): their median, or with `plane` the median of what the plane
 * through each three of them whose triangle contains i (barycentric weights all >= 0:
 * interpolated, as extrapolating blows their errors up) predicts at i; the plain median when no
 * triangle contains it. */
static void expected(sh_landmarks *lm, int i, const int *q, int m, float *vx, float *vy, float *ex, float *ey)
{
    int t = 0;
    if (lm->p.plane) {
        float *tx = lm->tri, *ty = lm->tri + lm->tri_cap;
        const float *r = lm->ref_xy, xi = r[2 * i], yi = r[2 * i + 1];
        for (int a = 0; a < m; a++)
            for (int b = a + 1; b < m; b++)
                for (int c = b + 1; c < m; c++) {
                    float ax = r[2 * q[a]] - xi, ay = r[2 * q[a] + 1] - yi, bx = r[2 * q[b]] - xi,
                          by = r[2 * q[b] + 1] - yi, cx = r[2 * q[c]] - xi, cy = r[2 * q[c] + 1] - yi;
                    float d = (bx - ax) * (cy - ay) - (cx - ax) * (by - ay);
                    if (!(fabsf(d) > 0)) continue;
                    float wa = (bx * cy - cx * by) / d, wb = (cx * ay - ax * cy) / d, wc = 1 - wa - wb;
                    if (!(wa >= 0 && wb >= 0 && wc >= 0))
                        continue;
                    tx[t] = wa * vx[a] + wb * vx[b] + wc * vx[c];
                    ty[t++] = wa * vy[a] + wb * vy[b] + wc * vy[c];
                }
        if (t > 0) {
            *ex = median(tx, t), *ey = median(ty, t);
            return;
        }
    }
    *ex = median(vx, m), *ey = median(vy, m);
}

static void deviations(sh_landmarks *lm, const float *predicted, uint8_t *verdict)
{
    const int k = lm->p.neighbours, min_voters = 3;
    float *vx = lm->scratch, *vy = lm->scratch + k + 1;
    int *qs = lm->voters;
    for (int i = 0; i < lm->n; i++) {
        if (verdict[i] != SH_LANDMARK_ACCEPTED) continue;
        int m = 0;
        for (int j = 0; j < k; j++) {
            int q = lm->near[(size_t)i * k + j];
            /* the neighbours' verdicts from the first four tests: SH_LANDMARK_DEVIATES is set only
             * here, after every landmark's first four, so compare with it too */
            if (q < 0 || (verdict[q] != SH_LANDMARK_ACCEPTED && verdict[q] != SH_LANDMARK_DEVIATES)) continue;
            qs[m] = q;
            vx[m] = lm->fwd[2 * q] - predicted[2 * q];
            vy[m++] = lm->fwd[2 * q + 1] - predicted[2 * q + 1];
        }
        if (m < min_voters) {
            verdict[i] = SH_LANDMARK_DEVIATES;
            continue;
        }
        float mx, my;
        expected(lm, i, qs, m, vx, vy, &mx, &my);
        float dx = lm->fwd[2 * i] - predicted[2 * i] - mx, dy = lm->fwd[2 * i + 1] - predicted[2 * i + 1] - my;
        if (!(hypotf(dx, dy) <= lm->p.max_deviation_px)) verdict[i] = SH_LANDMARK_DEVIATES;
    }
}

/* Forward from the reference to the frame for m landmarks, idx[j] (NULL: j), from guess (NULL:
 * from their reference positions), then, with the backward test, back from the result,
 * starting where the prediction's inverse puts it: the result minus the predicted displacement
 * (without a prediction, at the result itself, as the forward search started at the reference
 * position). guess, fwd, st_fwd, err, back, st_back: at j. */
static sh_status searches(const sh_landmarks *lm, int m, const int *idx, const float *guess, float *fwd,
                          uint8_t *st_fwd, float *err, float *back, uint8_t *st_back)
{
    const sh_landmarks_params *p = &lm->p;
    /* with `affine`, the reference's level-0 window sampled through the inverse of the map's
     * local affine: what the frame's window about the match looks like */
    float *warp = NULL;
    if (lm->affine && guess) {
        warp = lm->warp;
        for (int j = 0; j < m; j++) {
            const float *J = lm->jac + 4 * (idx ? idx[j] : j);
            float det = J[0] * J[3] - J[1] * J[2], *w = warp + 4 * j;
            w[0] = J[3] / det, w[1] = -J[1] / det, w[2] = -J[2] / det, w[3] = J[0] / det;
        }
    }
    sh_status st = sh_flow_track_windows_warped(&p->flow, lm->ref_win, lm->cur, m, idx, guess, warp, fwd, st_fwd, err);
    if (st != SH_OK) return st;
    /* the centres, and the whole windows' correlation, on the part of the frame built for these
     * searches (search_again builds another for the ones it does again) */
    for (int j = 0; (p->core || p->min_correlation > 0) && j < m; j++) {
        const int i = idx ? idx[j] : j, ok = st_fwd[j] == SH_FLOW_OK;
        const float rx = lm->ref_xy[2 * i], ry = lm->ref_xy[2 * i + 1], fx = fwd[2 * j], fy = fwd[2 * j + 1];
        if (p->core) lm->core_err[i] = ok ? sh_flow_window_difference(lm->ref, rx, ry, lm->cur, fx, fy, p->core) : NAN;
        if (p->min_correlation > 0)
            lm->corr[i] = ok ? sh_flow_window_correlation(lm->ref, rx, ry, lm->cur, fx, fy, p->flow.win) : NAN;
    }
    if (!(p->max_backward_px > 0)) return SH_OK;
    for (int j = 0; j < m; j++) {
        const float *r = lm->ref_xy + 2 * (idx ? idx[j] : j);
        back[2 * j] = guess ? fwd[2 * j] - (guess[2 * j] - r[0]) : fwd[2 * j];
        back[2 * j + 1] = guess ? fwd[2 * j + 1] - (guess[2 * j + 1] - r[1]) : fwd[2 * j + 1];
    }
    /* the backward search stays a translation's, with `affine` too: measured, warping it as
     * well (through J) accepted 6 % more landmarks but a third more of them over 1 px off
     * (docs/landmarks.md); unwarped, where the window deforms its bias shows in the round trip */
    sh_flow_params back_flow = p->flow;
    if (p->back_levels >= 0) back_flow.levels = p->back_levels;
    return sh_flow_track(&back_flow, lm->cur, lm->ref, m, fwd, back, back, st_back, NULL);
}

/* The markers' map's local affine at each landmark (`affine`): the least-squares affine through
 * the predictions of the landmark and its `neighbours` nearest landmarks against their reference
 * positions, the map's own derivative over about the neighbours' spread (20-60 px). The
 * identity where they are too few or in a line, or where it folds or changes the area by more
 * than twice (det outside [1/2, 2]): the heart does neither between two frames (the phantom's
 * truth stays within 0.79-1.25 over a window, its markers' map within 0.84-1.16), so such a fit
 * is the map's error, not the tissue's deformation. */
static void local_affine(sh_landmarks *lm, const float *predicted)
{
    const int k = lm->p.neighbours;
    for (int i = 0; i < lm->n; i++) {
        float *J = lm->jac + 4 * i;
        J[0] = 1, J[1] = 0, J[2] = 0, J[3] = 1;
        int q[65], m = 0;
        q[m++] = i;
        for (int j = 0; j < k; j++)
            if (lm->near[(size_t)i * k + j] >= 0) q[m++] = lm->near[(size_t)i * k + j];
        if (m < 3) continue;
        double rx = 0, ry = 0, px = 0, py = 0;
        for (int j = 0; j < m; j++)
            rx += lm->ref_xy[2 * q[j]], ry += lm->ref_xy[2 * q[j] + 1], px += predicted[2 * q[j]], py += predicted[2 * q[j] + 1];
        rx /= m, ry /= m, px /= m, py /= m;
        double sxx = 0, sxy = 0, syy = 0, uxx = 0, uxy = 0, uyx = 0, uyy = 0;
        for (int j = 0; j < m; j++) {
            double dx = lm->ref_xy[2 * q[j]] - rx, dy = lm->ref_xy[2 * q[j] + 1] - ry;
            double ex = predicted[2 * q[j]] - px, ey = predicted[2 * q[j] + 1] - py;
            sxx += dx * dx, sxy += dx * dy, syy += dy * dy;
            uxx += ex * dx, uxy += ex * dy, uyx += ey * dx, uyy += ey * dy;
        }
        double det = sxx * syy - sxy * sxy;
        if (!(det > 1e-6 * (sxx + syy) * (sxx + syy))) continue;
        double a = (uxx * syy - uxy * sxy) / det, b = (uxy * sxx - uxx * sxy) / det;
        double c = (uyx * syy - uyy * sxy) / det, d = (uyy * sxx - uyx * sxy) / det, area = a * d - b * c;
        if (!(area >= 0.5 && area <= 2)) continue;
        J[0] = (float)a, J[1] = (float)b, J[2] = (float)c, J[3] = (float)d;
    }
}

/* Where the frame's searches are expected: the box of their starting positions, grown by
 * SEARCH_REACH px plus the disagreement bound. An accepted landmark ends within
 * max_disagreement_px of its prediction, which its backward search starts from; SEARCH_REACH
 * covers the steps of the searches on their way. A search that leaves it costs time, not
 * results (search_again). */
#define SEARCH_REACH 8
/* Rounds of search_again on parts of the frame (each reaching twice as far as the last) before
 * the whole frame is built */
#define AGAIN_ROUNDS 3

/* Grows box (x0, y0, x1, y1) to hold (x, y) when a search could read the frame from there at
 * all: finite, within a window of the frame. */
static void box_add(const sh_landmarks *lm, float box[4], float x, float y)
{
    const float lim = (float)lm->p.flow.win;
    if (!(x >= -lim && x <= (float)lm->width + lim && y >= -lim && y <= (float)lm->height + lim)) return;
    box[0] = x < box[0] ? x : box[0], box[2] = x > box[2] ? x : box[2];
    box[1] = y < box[1] ? y : box[1], box[3] = y > box[3] ? y : box[3];
}

static void box_grow(float box[4], float r)
{
    if (!(box[0] <= box[2])) box[0] = box[1] = box[2] = box[3] = 0; /* no search reads the frame */
    box[0] -= r, box[1] -= r, box[2] += r, box[3] += r;
}

/* The frame reduced (reduce > 0) and band-passed (unless band is 0) in the part of it a pyramid
 * built for box reads, and that pyramid; the whole frame when box is NULL. box and the part are
 * in the reduced frame's pixels. */
static sh_status build_part(sh_landmarks *lm, const sh_plane *luma, const float *box)
{
    const int backward = lm->p.max_backward_px > 0;
    int part[4] = {0, 0, lm->width, lm->height};
    sh_status st = box ? sh_flow_pyramid_box_part(lm->cur, box, backward, part) : SH_OK;
    sh_plane band = *luma;
    if (st == SH_OK && lm->reduce) {
        /* the part and the band-pass's boxes around it */
        const int r = lm->p.band, red[4] = {part[0] - r > 0 ? part[0] - r : 0, part[1] - r > 0 ? part[1] - r : 0,
                                            part[2] + r < lm->width ? part[2] + r : lm->width,
                                            part[3] + r < lm->height ? part[3] + r : lm->height};
        reduce_part(lm, luma, red);
        band = (sh_plane){lm->small, lm->width, lm->height, lm->width};
    }
    if (st == SH_OK && lm->p.band > 0) {
        band_pass(lm, &band, lm->p.band, part);
        band = (sh_plane){lm->band, lm->width, lm->height, lm->width};
    }
    if (st != SH_OK) return st;
    /* where the refinement may sample this frame: the first part built, or the whole frame */
    if (!box || lm->built[2] <= lm->built[0]) memcpy(lm->built, part, sizeof part);
    lm->src = band;
    return box ? sh_flow_pyramid_build_box(lm->cur, &band, backward, box) : sh_flow_pyramid_build(lm->cur, &band, backward);
}

/* The landmarks whose searches read outside the part of the frame built for them, searched
 * again: one whose forward search did, and one whose backward search did after its forward
 * search succeeded (after a failed one its verdict is LOST either way). Each round builds the
 * part around where those searches started and where they were when they stopped (the backward
 * search reads the frame only at the forward result), reaching twice as far as the round
 * before; after AGAIN_ROUNDS the whole frame. A point's search reads the same pixels whatever
 * part holds them, so the results are those of the whole frame. counts: searches done again,
 * and whether the whole frame was built. */
static sh_status search_again(sh_landmarks *lm, const sh_plane *luma, const float *predicted, int *again,
                              int *whole)
{
    const int backward = lm->p.max_backward_px > 0;
    const size_t k = (size_t)lm->p.max_points;
    float *guess = lm->redo_xy, *fwd = guess + 2 * k, *back = fwd + 2 * k, *err = back + 2 * k;
    uint8_t *st_fwd = lm->redo_st, *st_back = st_fwd + k;
    const float *start = predicted ? predicted : lm->ref_xy;
    for (int round = 0;; round++) {
        int m = 0;
        float box[4] = {INFINITY, INFINITY, -INFINITY, -INFINITY};
        for (int i = 0; i < lm->n; i++)
            if (lm->st_fwd[i] == SH_FLOW_UNBUILT ||
                (backward && lm->st_fwd[i] == SH_FLOW_OK && lm->st_back[i] == SH_FLOW_UNBUILT)) {
                lm->redo[m++] = i;
                box_add(lm, box, start[2 * i], start[2 * i + 1]);
                box_add(lm, box, lm->fwd[2 * i], lm->fwd[2 * i + 1]);
            }
        if (m == 0) return SH_OK;
        *again += m;
        *whole = round == AGAIN_ROUNDS;
        box_grow(box, (float)lm->p.max_disagreement_px + (float)(SEARCH_REACH << (round + 2)));
        sh_status st = build_part(lm, luma, *whole ? NULL : box);
        if (st != SH_OK) return st;
        for (int j = 0; predicted && j < m; j++) {
            int i = lm->redo[j];
            guess[2 * j] = predicted[2 * i], guess[2 * j + 1] = predicted[2 * i + 1];
        }
        st = searches(lm, m, lm->redo, predicted ? guess : NULL, fwd, st_fwd, err, back, st_back);
        if (st != SH_OK) return st;
        for (int j = 0; j < m; j++) {
            int i = lm->redo[j];
            lm->fwd[2 * i] = fwd[2 * j], lm->fwd[2 * i + 1] = fwd[2 * j + 1];
            lm->back[2 * i] = back[2 * j], lm->back[2 * i + 1] = back[2 * j + 1];
            lm->err[i] = err[j];
            lm->st_fwd[i] = st_fwd[j];
            if (backward) lm->st_back[i] = st_back[j];
        }
    }
}

/* The first three tests (landmarks.h) for landmark i: its verdict from them. */
static sh_landmark_verdict first_three(const sh_landmarks *lm, int i)
{
    const sh_landmarks_params *p = &lm->p;
    const int backward = p->max_backward_px > 0;
    const float *f = lm->fwd + 2 * i, *r = lm->ref_xy + 2 * i;
    if (lm->st_fwd[i] != SH_FLOW_OK || (backward && lm->st_back[i] != SH_FLOW_OK) || !isfinite(f[0]) ||
        !isfinite(f[1]))
        return SH_LANDMARK_LOST;
    if (!(lm->err[i] <= p->max_photometric) || (p->core && !(lm->core_err[i] <= p->max_photometric)) ||
        !(lm->err[i] <= lm->jump_limit[i]) || !(lm->err[i] <= lm->relative[0]) ||
        (p->core && !(lm->core_err[i] <= lm->relative[1])) ||
        (p->min_correlation > 0 && !(lm->corr[i] >= p->min_correlation)))
        return SH_LANDMARK_PHOTOMETRIC;
    if (backward && !(hypot(lm->back[2 * i] - r[0], lm->back[2 * i + 1] - r[1]) <= p->max_backward_px))
        return SH_LANDMARK_BACKWARD;
    return SH_LANDMARK_ACCEPTED;
}

/* The first four tests, the disagreement bound `bound` px (without a prediction not tested). */
static void first_tests(const sh_landmarks *lm, const float *predicted, double bound, uint8_t *verdict)
{
    for (int i = 0; i < lm->n; i++) {
        const float *f = lm->fwd + 2 * i;
        sh_landmark_verdict v = first_three(lm, i);
        if (v == SH_LANDMARK_ACCEPTED && predicted &&
            !(hypot(f[0] - predicted[2 * i], f[1] - predicted[2 * i + 1]) <= bound))
            v = SH_LANDMARK_DISAGREES;
        verdict[i] = (uint8_t)v;
    }
}

/* The disagreement bound of the frame from its own data: bound_factor times the median distance
 * from the markers' map of the landmarks the tests before it (lost, photometric, backward) keep,
 * never below max_disagreement_px. */
static double adaptive_bound(sh_landmarks *lm, const float *predicted, double floor_px)
{
    float *d = lm->dist;
    int m = 0;
    for (int i = 0; i < lm->n; i++)
        if (first_three(lm, i) == SH_LANDMARK_ACCEPTED)
            d[m++] = hypotf(lm->fwd[2 * i] - predicted[2 * i], lm->fwd[2 * i + 1] - predicted[2 * i + 1]);
    if (m == 0) return floor_px;
    double b = lm->p.bound_factor * median(d, m);
    return b > floor_px ? b : floor_px;
}

/* The relative test's limits on this frame's window differences and their centres': max_relative
 * times their medians over the landmarks Lucas-Kanade kept (the frame's noise, whatever the
 * landmarks' verdicts: an occluder over most of them would raise it, and the fixed bound holds
 * then), never below max_relative grey levels (a noiseless frame's windows match to a fraction of
 * one); infinite without the test. */
static void relative_limits(sh_landmarks *lm)
{
    const double k = lm->p.max_relative;
    lm->relative[0] = lm->relative[1] = INFINITY;
    if (!(k > 0)) return;
    for (int c = 0; c < (lm->p.core ? 2 : 1); c++) {
        const float *v = c ? lm->core_err : lm->err;
        int m = 0;
        for (int i = 0; i < lm->n; i++)
            if (lm->st_fwd[i] == SH_FLOW_OK && isfinite(v[i])) lm->dist[m++] = v[i];
        if (m == 0) continue;
        const float med = median(lm->dist, m);
        lm->relative[c] = (float)k * (med > 1.f ? med : 1.f);
    }
}

/* The jump test's limit on each landmark's window difference in this frame of a view: max_jump
 * times the median of its history there (never below JUMP_FLOOR); none (infinite) without the
 * test, with too short a history, or where the difference is within max_jump times the floor,
 * which every limit is at least (no median needed for a verdict it cannot change). */
static void jump_limits(sh_landmarks *lm, int view)
{
    const size_t base = (size_t)view * (size_t)lm->p.max_points;
    const float least = (float)lm->p.max_jump * JUMP_FLOOR;
    float v[JUMP_HISTORY];
    for (int i = 0; i < lm->n; i++) {
        const int k = lm->hist_n[base + i];
        lm->jump_limit[i] = INFINITY;
        if (!(lm->p.max_jump > 0) || k < JUMP_MIN || lm->err[i] <= least) continue;
        memcpy(v, lm->hist + (base + (size_t)i) * JUMP_HISTORY, (size_t)k * sizeof *v);
        float m = median(v, k);
        lm->jump_limit[i] = (float)lm->p.max_jump * (m > JUMP_FLOOR ? m : JUMP_FLOOR);
    }
}

/* The accepted landmarks' window differences into the view's histories. Not a difference of
 * exactly 0: the frame is the reference there (a caller searched the reference frame itself),
 * which says nothing of the differences where the tissue has moved, and would give the landmark
 * a history that a caller starting after the reference does not. */
static void jump_remember(sh_landmarks *lm, int view, const uint8_t *verdict)
{
    if (!(lm->p.max_jump > 0)) return; /* no test: no history to keep */
    const size_t base = (size_t)view * (size_t)lm->p.max_points;
    for (int i = 0; i < lm->n; i++) {
        if (verdict[i] != SH_LANDMARK_ACCEPTED || !(lm->err[i] > 0)) continue;
        uint8_t *at = &lm->hist_at[base + i], *k = &lm->hist_n[base + i];
        lm->hist[(base + (size_t)i) * JUMP_HISTORY + *at] = lm->err[i];
        *at = (uint8_t)((*at + 1) % JUMP_HISTORY);
        if (*k < JUMP_HISTORY) (*k)++;
    }
}

/* The confirmation (confirm): a landmark that passed every test is UNCONFIRMED until it has
 * passed them confirm times since the reference. The primary view's frames only, as the
 * refinement: the reference is its frame, and a rig's other views are searched in the reference's
 * own set too (their matches there give the landmarks their place in 3D), where a landmark
 * is used only where the primary accepts it anyway. A search of the reference frame itself (a
 * window difference of exactly 0, as jump_remember) neither counts nor is held back. After the
 * history and the refinement, which take every pass as before. */
static void confirm(sh_landmarks *lm, uint8_t *verdict)
{
    if (lm->p.confirm <= 1) return;
    uint16_t *passed = lm->passed;
    for (int i = 0; i < lm->n; i++) {
        if (verdict[i] != SH_LANDMARK_ACCEPTED || !(lm->err[i] > 0)) continue;
        if (passed[i] < lm->p.confirm) passed[i]++;
        if (passed[i] < lm->p.confirm) verdict[i] = SH_LANDMARK_UNCONFIRMED;
    }
}

static sh_status track(sh_landmarks *lm, int view, const sh_plane *luma, const float *predicted, float *xy,
                       uint8_t *verdict, sh_landmarks_counts *counts);

sh_status sh_landmarks_track(sh_landmarks *lm, const sh_plane *luma, const float *predicted, float *xy,
                             uint8_t *verdict, sh_landmarks_counts *counts)
{
    lm->affine = lm->p.affine;
    return track(lm, 0, luma, predicted, xy, verdict, counts);
}

sh_status sh_landmarks_track_view(sh_landmarks *lm, int view, const sh_plane *luma, const float *predicted,
                                  float *xy, uint8_t *verdict, sh_landmarks_counts *counts)
{
    if (view < 1 || view >= SH_CALIB_MAX_CAMERAS)
        return sh_error_set(SH_EINVAL, "landmarks: view %d, not 1 to %d", view, SH_CALIB_MAX_CAMERAS - 1);
    if (lm->p.neighbours < 2)
        return sh_error_set(SH_EINVAL, "landmarks: affine windows need neighbours >= 2, not %d", lm->p.neighbours);
    lm->affine = 1;
    return track(lm, view, luma, predicted, xy, verdict, counts);
}

static sh_status track(sh_landmarks *lm, int view, const sh_plane *luma, const float *predicted, float *xy,
                       uint8_t *verdict, sh_landmarks_counts *counts)
{
    if (!luma || luma->width != lm->full_width || luma->height != lm->full_height)
        return sh_error_set(SH_EINVAL, "landmarks: a %dx%d frame for a %dx%d reference", luma ? luma->width : 0,
                            luma ? luma->height : 0, lm->full_width, lm->full_height);
    const sh_landmarks_params *p = &lm->p;
    int n = lm->n, again = 0, whole = 0;
    if (counts) memset(counts, 0, sizeof *counts);
    if (n == 0) return SH_OK;
    if (predicted && lm->reduce) {
        for (int i = 0; i < 2 * n; i++) lm->pred[i] = to_small(predicted[i], lm->reduce);
        predicted = lm->pred;
    }
    /* only the part of the frame the searches are expected to read: band-passed, and its
     * pyramid (with the gradients only when the frame is tracked from, by the backward test) */
    float box[4] = {INFINITY, INFINITY, -INFINITY, -INFINITY};
    const float *start = predicted ? predicted : lm->ref_xy;
    if (lm->affine && predicted) local_affine(lm, predicted);
    for (int i = 0; i < n; i++) box_add(lm, box, start[2 * i], start[2 * i + 1]);
    box_grow(box, (float)p->max_disagreement_px + SEARCH_REACH);
    lm->built[0] = lm->built[1] = lm->built[2] = lm->built[3] = 0;
    sh_status st = build_part(lm, luma, box);
    if (st == SH_OK) st = searches(lm, n, NULL, predicted, lm->fwd, lm->st_fwd, lm->err, lm->back, lm->st_back);
    if (st == SH_OK) st = search_again(lm, luma, predicted, &again, &whole);
    if (st != SH_OK) return st;
    jump_limits(lm, view);
    relative_limits(lm);
    double bound = p->max_disagreement_px;
    if (predicted && p->bound_factor > 0) bound = adaptive_bound(lm, predicted, bound);
    first_tests(lm, predicted, bound, verdict);
    if (predicted && p->neighbours > 0) deviations(lm, predicted, verdict);
    jump_remember(lm, view, verdict);
    /* the primary view's frames only: the reference is its frame */
    if (lm->rsum && view == 0 && predicted) st = refine(lm, verdict);
    if (st != SH_OK) return st;
    if (view == 0) confirm(lm, verdict);
    for (int i = 0; i < 2 * n; i++) xy[i] = to_full(lm->fwd[i], lm->reduce);
    if (counts) {
        for (int i = 0; i < n; i++) counts->verdicts[verdict[i]]++;
        counts->searched_again = again;
        counts->whole_frame = whole;
        counts->bound_px = predicted ? ldexp(bound, lm->reduce) : 0;
    }
    return SH_OK;
}

sh_status sh_landmarks_luma(const sh_image *f, sh_image *buf, const sh_plane **out)
{
    if (f->format != SH_PIX_RGB24) {
        *out = &f->plane[0];
        return SH_OK;
    }
    if (!buf->owned || buf->width != f->width || buf->height != f->height) {
        sh_image_destroy(buf);
        sh_status st = sh_image_create(buf, SH_PIX_GRAY8, f->width, f->height);
        if (st != SH_OK) return st;
    }
    for (int y = 0; y < f->height; y++) {
        const uint8_t *in = f->plane[0].data + (size_t)y * f->plane[0].stride;
        uint8_t *o = buf->plane[0].data + (size_t)y * buf->plane[0].stride;
        for (int x = 0; x < f->width; x++)
            o[x] = (uint8_t)((77 * in[3 * x] + 150 * in[3 * x + 1] + 29 * in[3 * x + 2] + 128) >> 8);
    }
    *out = &buf->plane[0];
    return SH_OK;
}
