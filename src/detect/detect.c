/* AprilTag detection through libapriltag (Debian's 3.3), in the whole frame or in windows.
 *
 * A window is the frame's image_u8_t with buf moved to the window's origin and width/height
 * shrunk (stride unchanged): no pixel is copied. Coordinates come back in libapriltag's
 * convention (pixel centres at +0.5) relative to the window; the window origin is added and
 * SH_DETECT_APRILTAG_OFFSET subtracted, giving frame coordinates with pixel centres at
 * integers. */
#include "stillheart/detect.h"

#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

/* One set of defaults with or without libapriltag: callers fill the options before they learn
 * whether a detector can be created. */
void sh_detector_options_default(sh_detector_options *opts)
{
    if (!opts) return;
    memset(opts, 0, sizeof *opts);
    opts->family = "tag36h11";
    opts->quad_decimate = 2.0;
    opts->quad_sigma = 0.0;
    opts->refine_edges = 1;
    opts->decode_sharpening = 0.25;
    opts->threads = 1;
    opts->max_hamming = 2;
    opts->window_decimate = 1.0;
    opts->merge_windows = 1;
    opts->window_threads = 1;
}

#ifdef SH_HAVE_APRILTAG

#include <pthread.h>

#include <apriltag/apriltag.h>
#include <apriltag/tag16h5.h>
#include <apriltag/tag25h9.h>
#include <apriltag/tag36h10.h>
#include <apriltag/tag36h11.h>
#include <apriltag/tagCircle21h7.h>
#include <apriltag/tagCircle49h12.h>
#include <apriltag/tagCustom48h12.h>
#include <apriltag/tagStandard41h12.h>
#include <apriltag/tagStandard52h13.h>

static const struct {
    const char *name;
    apriltag_family_t *(*create)(void);
    void (*destroy)(apriltag_family_t *);
} families[] = {
    {"tag36h11", tag36h11_create, tag36h11_destroy},
    {"tag36h10", tag36h10_create, tag36h10_destroy},
    {"tag25h9", tag25h9_create, tag25h9_destroy},
    {"tag16h5", tag16h5_create, tag16h5_destroy},
    {"tagStandard41h12", tagStandard41h12_create, tagStandard41h12_destroy},
    {"tagStandard52h13", tagStandard52h13_create, tagStandard52h13_destroy},
    {"tagCircle21h7", tagCircle21h7_create, tagCircle21h7_destroy},
    {"tagCircle49h12", tagCircle49h12_create, tagCircle49h12_destroy},
    {"tagCustom48h12", tagCustom48h12_create, tagCustom48h12_destroy},
};
#define NUM_FAMILIES ((int)(sizeof families / sizeof families[0]))

/* Fixed cost of one libapriltag call, in pixels of a decimation-1 window: merging two windows
 * pays off when their bounding box adds fewer pixels than this. An estimate: on the exvivo
 * phantom (tools/bench/bench_detect.cpp) 16 separate 1.6x windows and the 6 merged ones cost
 * the same within noise, so the call overhead is small beside the pixels' cost there. */
#define CALL_COST_PIXELS 6000

/* Detections of one windowed scan whose cut flag is kept for the choice between two views of a
 * tag; beyond them (more tags than any rig has) the choice falls back on the decision margin. */
#define CUT_SLOTS 1024

/* A helper thread of a windowed scan, with its own libapriltag detector (its buffers and worker
 * pool are per call state). The family is the caller's: libapriltag 3.3 builds the family's
 * decode table (about 30 MB for tag36h11 at 2 bits) when the first detector adds it and only
 * reads it while decoding; another detector adding it finds it built, and the first detector
 * destroyed frees it (each of them checks). */
typedef struct {
    struct sh_detector *det;
    apriltag_detector_t *td;
    pthread_t thread;
    int started;
} helper;

struct sh_detector {
    apriltag_detector_t *td;
    apriltag_family_t *tf;
    void (*tf_destroy)(apriltag_family_t *);
    sh_detector_options opts;
    uint8_t *gray;          /* RGB24 -> grey, sized at the first RGB frame */
    size_t gray_size;
    int gray_width, gray_height;
    sh_window scan[SH_DETECT_MAX_WINDOWS];
    int num_scan;
    /* per reported detection of a windowed scan (the first CUT_SLOTS): whether its window may
     * have cut it (cut_view) */
    unsigned char cut[CUT_SLOTS];
    /* window_threads > 1: helpers scanning a call's windows beside the caller */
    int nhelpers;
    helper *helpers;
    pthread_mutex_t mu;
    pthread_cond_t go, done;
    int sync_made;          /* mu, go and done initialized */
    unsigned generation;    /* bumped per call that wakes the helpers */
    int busy;               /* helpers still scanning this call's windows */
    int quit;
    double quad_dec, win_dec; /* the decimations in use (sh_detector_set_tag_side) */
    const uint8_t *base;    /* this call's plane and its stride */
    int stride;
    int next;               /* windows handed out so far, in order[] */
    int order[SH_DETECT_MAX_WINDOWS];       /* scan[] indices, largest window first */
    zarray_t *found[SH_DETECT_MAX_WINDOWS]; /* per scan[] window: libapriltag's detections */
};

const char *sh_detector_families(void)
{
    return "tag36h11 tag36h10 tag25h9 tag16h5 tagStandard41h12 tagStandard52h13 tagCircle21h7 "
           "tagCircle49h12 tagCustom48h12";
}

/* A window of the plane at base (rows stride bytes apart) through libapriltag's detector td:
 * its detections relative to the window, NULL when libapriltag failed. */
static zarray_t *detect_view(apriltag_detector_t *td, const uint8_t *base, int stride, const sh_window *w)
{
    /* image_u8_t's geometry is const: build it by initialization. libapriltag only reads the
     * pixels (a blur or decimation works on its own copy). */
    image_u8_t im = {.width = w->width, .height = w->height, .stride = stride,
                     .buf = (uint8_t *)(uintptr_t)(base + (size_t)w->y * (size_t)stride + (size_t)w->x)};
    return apriltag_detector_detect(td, &im);
}

/* Scans windows on td until none is left to hand out (the caller's thread and each helper). */
static void scan_windows(sh_detector *det, apriltag_detector_t *td)
{
    for (;;) {
        pthread_mutex_lock(&det->mu);
        int i = det->next < det->num_scan ? det->order[det->next++] : -1;
        pthread_mutex_unlock(&det->mu);
        if (i < 0) return;
        det->found[i] = detect_view(td, det->base, det->stride, &det->scan[i]);
    }
}

static void *helper_main(void *arg)
{
    helper *h = arg;
    sh_detector *det = h->det;
    unsigned seen = 0;
    pthread_mutex_lock(&det->mu);
    for (;;) {
        while (!det->quit && det->generation == seen) pthread_cond_wait(&det->go, &det->mu);
        if (det->quit) break;
        seen = det->generation;
        h->td->quad_decimate = (float)det->win_dec;
        pthread_mutex_unlock(&det->mu);
        scan_windows(det, h->td);
        pthread_mutex_lock(&det->mu);
        if (--det->busy == 0) pthread_cond_signal(&det->done);
    }
    pthread_mutex_unlock(&det->mu);
    return NULL;
}

/* The lock (always: one thread hands the windows out to itself through it too) and, with
 * window_threads > 1, the helpers, each with a detector of its own set up as det's, on det's
 * family. */
static sh_status start_helpers(sh_detector *det)
{
    pthread_mutex_init(&det->mu, NULL);
    pthread_cond_init(&det->go, NULL);
    pthread_cond_init(&det->done, NULL);
    det->sync_made = 1;
    int n = det->opts.window_threads - 1;
    if (n <= 0) return SH_OK;
    det->helpers = calloc((size_t)n, sizeof *det->helpers);
    if (!det->helpers) return sh_error_set(SH_ENOMEM, "detect: cannot allocate the helpers");
    for (int k = 0; k < n; k++) {
        helper *h = &det->helpers[k];
        det->nhelpers = k + 1; /* stop_helpers frees up to here */
        h->det = det;
        h->td = apriltag_detector_create();
        if (!h->td) return sh_error_set(SH_ENOMEM, "detect: cannot create a helper's libapriltag detector");
        apriltag_detector_add_family_bits(h->td, det->tf, det->opts.max_hamming);
        h->td->quad_decimate = (float)det->opts.window_decimate; /* helpers only scan windows */
        h->td->quad_sigma = det->td->quad_sigma;
        h->td->refine_edges = det->td->refine_edges;
        h->td->decode_sharpening = det->td->decode_sharpening;
        h->td->nthreads = det->td->nthreads;
        h->td->debug = 0;
        if (pthread_create(&h->thread, NULL, helper_main, h))
            return sh_error_set(SH_ENOMEM, "detect: cannot start helper thread %d", k + 1);
        h->started = 1;
    }
    return SH_OK;
}

static void stop_helpers(sh_detector *det)
{
    if (!det->sync_made) return;
    pthread_mutex_lock(&det->mu);
    det->quit = 1;
    pthread_cond_broadcast(&det->go);
    pthread_mutex_unlock(&det->mu);
    for (int k = 0; k < det->nhelpers; k++) {
        helper *h = &det->helpers[k];
        if (h->started) pthread_join(h->thread, NULL);
        if (h->td) apriltag_detector_destroy(h->td);
    }
    free(det->helpers);
    pthread_mutex_destroy(&det->mu);
    pthread_cond_destroy(&det->go);
    pthread_cond_destroy(&det->done);
}

sh_status sh_detector_create(const sh_detector_options *opts, sh_detector **out)
{
    if (!out) return sh_error_set(SH_EINVAL, "detect: missing argument");
    *out = NULL;
    sh_detector_options o;
    if (opts)
        o = *opts;
    else
        sh_detector_options_default(&o);
    if (!o.family) o.family = "tag36h11";
    int f = -1;
    for (int i = 0; i < NUM_FAMILIES; i++)
        if (!strcmp(o.family, families[i].name)) f = i;
    if (f < 0)
        return sh_error_set(SH_EINVAL, "detect: unknown tag family '%s' (known: %s)", o.family,
                            sh_detector_families());
    if (!(o.quad_decimate >= 1.0 && o.quad_decimate <= 16.0))
        return sh_error_set(SH_EINVAL, "detect: quad_decimate %g outside [1, 16]", o.quad_decimate);
    if (!(o.window_decimate >= 1.0 && o.window_decimate <= 16.0))
        return sh_error_set(SH_EINVAL, "detect: window_decimate %g outside [1, 16]",
                            o.window_decimate);
    if (!(o.quad_sigma >= -10.0 && o.quad_sigma <= 10.0))
        return sh_error_set(SH_EINVAL, "detect: quad_sigma %g outside [-10, 10]", o.quad_sigma);
    if (!(o.decode_sharpening >= 0.0 && o.decode_sharpening <= 10.0))
        return sh_error_set(SH_EINVAL, "detect: decode_sharpening %g outside [0, 10]",
                            o.decode_sharpening);
    if (o.threads < 1 || o.threads > 64)
        return sh_error_set(SH_EINVAL, "detect: threads %d outside [1, 64]", o.threads);
    if (o.max_hamming < 0 || o.max_hamming > 3)
        return sh_error_set(SH_EINVAL, "detect: max_hamming %d outside [0, 3]", o.max_hamming);
    if (o.window_threads < 1 || o.window_threads > 64)
        return sh_error_set(SH_EINVAL, "detect: window_threads %d outside [1, 64]", o.window_threads);

    sh_detector *det = calloc(1, sizeof *det);
    if (!det) return sh_error_set(SH_ENOMEM, "detect: cannot allocate the detector");
    det->opts = o;
    det->opts.family = families[f].name; /* a static string: the caller's may not outlive us */
    det->quad_dec = o.quad_decimate;
    det->win_dec = o.window_decimate;
    det->tf = families[f].create();
    det->tf_destroy = families[f].destroy;
    det->td = apriltag_detector_create();
    if (!det->tf || !det->td) {
        sh_detector_destroy(det);
        return sh_error_set(SH_ENOMEM, "detect: cannot create the libapriltag detector");
    }
    apriltag_detector_add_family_bits(det->td, det->tf, o.max_hamming);
    det->td->quad_decimate = (float)o.quad_decimate;
    det->td->quad_sigma = (float)o.quad_sigma;
    det->td->refine_edges = o.refine_edges != 0;
    det->td->decode_sharpening = o.decode_sharpening;
    det->td->nthreads = o.threads;
    det->td->debug = 0;
    sh_status st = start_helpers(det);
    if (st != SH_OK) {
        sh_detector_destroy(det);
        return st;
    }
    *out = det;
    return SH_OK;
}

void sh_detector_destroy(sh_detector *det)
{
    if (!det) return;
    stop_helpers(det);
    if (det->td) apriltag_detector_destroy(det->td);
    if (det->tf && det->tf_destroy) det->tf_destroy(det->tf);
    free(det->gray);
    free(det);
}

/* Whether the window (ox, oy, ww, wh) may have cut the tag: its quad comes within half a module
 * (the quad's mean side over the family's width at the border) of a window edge that is not the
 * frame's. A window edge across the black border still decodes, with that side fitted inside the
 * border, a few px off (test_detect: 2.7-3.8 px on a 96 px tag); a window that holds half of the
 * one-module quiet zone, as the tracker's do (track.c, TRK_WINDOW_QUIET), shows the real edge. */
static int cut_view(const sh_detection *s, int ox, int oy, int ww, int wh, int fw, int fh,
                    int modules)
{
    double side = 0;
    for (int k = 0; k < 4; k++)
        side += 0.25 * hypot(s->corner[(k + 1) % 4][0] - s->corner[k][0],
                             s->corner[(k + 1) % 4][1] - s->corner[k][1]);
    double room = 0.5 * side / (modules > 0 ? modules : 1);
    /* pixel centres at integers: the window's pixels span [ox - 0.5, ox + ww - 0.5) */
    for (int k = 0; k < 4; k++) {
        double x = s->corner[k][0], y = s->corner[k][1];
        if ((ox > 0 && x - (ox - 0.5) < room) || (ox + ww < fw && (ox + ww - 0.5) - x < room) ||
            (oy > 0 && y - (oy - 0.5) < room) || (oy + wh < fh && (oy + wh - 0.5) - y < room))
            return 1;
    }
    return 0;
}

/* Copies libapriltag's detections (window-relative) into out[*n...], in frame coordinates.
 * With dedup (windowed scans), a detection of the same id whose centre lies within a quarter of
 * the tag's edge of one already reported (the same tag seen by two windows) is one tag: the view
 * that its window did not cut is kept (a cut view can have the higher decision margin: a
 * reacquisition band's edge across a tag already in its own window gave 1-6 px errors at 4K),
 * and between views alike the clearer one. */
static void collect(sh_detector *det, zarray_t *dets, const sh_window *win, int fw, int fh,
                    int dedup, sh_detection *out, int max, int *n)
{
    const double off = SH_DETECT_APRILTAG_OFFSET;
    const int ox = win->x, oy = win->y;
    for (int i = 0; i < zarray_size(dets); i++) {
        apriltag_detection_t *d;
        zarray_get(dets, i, &d);
        sh_detection s;
        s.id = d->id;
        s.cx = d->c[0] + ox - off;
        s.cy = d->c[1] + oy - off;
        for (int k = 0; k < 4; k++) {
            s.corner[k][0] = d->p[k][0] + ox - off;
            s.corner[k][1] = d->p[k][1] + oy - off;
        }
        s.margin = d->decision_margin;
        s.hamming = d->hamming;
        int cut = 0;
        if (dedup) {
            cut = cut_view(&s, ox, oy, win->width, win->height, fw, fh, det->tf->width_at_border);
            double ex = s.corner[1][0] - s.corner[0][0], ey = s.corner[1][1] - s.corner[0][1];
            double tol2 = (ex * ex + ey * ey) / 16.0;
            int dup = 0;
            int seen = *n < max ? *n : max;
            for (int j = 0; j < seen && !dup; j++) {
                double dx = out[j].cx - s.cx, dy = out[j].cy - s.cy;
                if (out[j].id == s.id && dx * dx + dy * dy <= tol2) {
                    dup = 1;
                    int cut_j = j < CUT_SLOTS ? det->cut[j] : cut;
                    if (cut < cut_j || (cut == cut_j && s.margin > out[j].margin)) {
                        out[j] = s;
                        if (j < CUT_SLOTS) det->cut[j] = (unsigned char)cut;
                    }
                }
            }
            if (dup) continue;
        }
        if (*n < max) out[*n] = s;
        if (*n < max && *n < CUT_SLOTS) det->cut[*n] = (unsigned char)cut;
        (*n)++;
    }
}

static long area(const sh_window *w)
{
    return (long)w->width * (long)w->height;
}

/* The planned windows (det->scan) of the plane at base, scanned by the caller's thread and the
 * helpers, largest first so that they finish together; their detections collected in window
 * order, so the result is one thread's. Collecting stops at a window libapriltag failed on, as
 * one thread scanning them in order would have stopped. */
static sh_status scan(sh_detector *det, const uint8_t *base, int fw, int fh, int stride, sh_detection *out,
                      int max, int *n)
{
    int m = det->num_scan;
    for (int i = 0; i < m; i++) { /* insertion sort: a few dozen windows */
        int j = i;
        while (j > 0 && area(&det->scan[det->order[j - 1]]) < area(&det->scan[i])) {
            det->order[j] = det->order[j - 1];
            j--;
        }
        det->order[j] = i;
    }
    det->base = base;
    det->stride = stride;
    det->next = 0;
    int wake = det->nhelpers > 0 && m > 1;
    if (wake) {
        pthread_mutex_lock(&det->mu);
        det->busy = det->nhelpers;
        det->generation++;
        pthread_cond_broadcast(&det->go);
        pthread_mutex_unlock(&det->mu);
    }
    scan_windows(det, det->td);
    if (wake) {
        pthread_mutex_lock(&det->mu);
        while (det->busy > 0) pthread_cond_wait(&det->done, &det->mu);
        pthread_mutex_unlock(&det->mu);
    }
    sh_status st = SH_OK;
    for (int i = 0; i < m; i++) {
        if (!det->found[i] && st == SH_OK)
            st = sh_error_set(SH_ENOMEM, "detect: libapriltag failed on a %dx%d image", det->scan[i].width,
                              det->scan[i].height);
        if (det->found[i] && st == SH_OK) collect(det, det->found[i], &det->scan[i], fw, fh, 1, out, max, n);
        if (det->found[i]) apriltag_detections_destroy(det->found[i]);
        det->found[i] = NULL;
    }
    return st;
}

/* Clips the windows to the frame, drops empty ones, and (when asked) merges pairs whose
 * bounding box costs fewer extra pixels than one call: greedily, until nothing merges. */
static sh_status plan_windows(sh_detector *det, int width, int height, const sh_window *win,
                              int nwin)
{
    int n = 0;
    for (int i = 0; i < nwin; i++) {
        long x0 = win[i].x, y0 = win[i].y;
        long x1 = x0 + (long)win[i].width, y1 = y0 + (long)win[i].height;
        if (x0 < 0) x0 = 0;
        if (y0 < 0) y0 = 0;
        if (x1 > width) x1 = width;
        if (y1 > height) y1 = height;
        if (x1 - x0 < 8 || y1 - y0 < 8) continue; /* nothing a tag fits in */
        det->scan[n++] = (sh_window){(int)x0, (int)y0, (int)(x1 - x0), (int)(y1 - y0)};
    }
    if (det->opts.merge_windows) {
        int merged = 1;
        while (merged) {
            merged = 0;
            for (int i = 0; i < n && !merged; i++)
                for (int j = i + 1; j < n && !merged; j++) {
                    sh_window *a = &det->scan[i], *b = &det->scan[j];
                    int x0 = a->x < b->x ? a->x : b->x, y0 = a->y < b->y ? a->y : b->y;
                    int x1 = a->x + a->width > b->x + b->width ? a->x + a->width : b->x + b->width;
                    int y1 = a->y + a->height > b->y + b->height ? a->y + a->height
                                                                  : b->y + b->height;
                    sh_window u = {x0, y0, x1 - x0, y1 - y0};
                    /* pixels scanned now: a + b (overlap scanned twice) */
                    if (area(&u) - (area(a) + area(b)) <= CALL_COST_PIXELS) {
                        *a = u;
                        det->scan[j] = det->scan[--n];
                        merged = 1;
                    }
                }
        }
    }
    det->num_scan = n;
    return SH_OK;
}

sh_status sh_detector_detect_plane(sh_detector *det, const uint8_t *luma, int width, int height,
                                   int stride, const sh_window *windows, int num_windows,
                                   sh_detection *out, int max, int *count)
{
    if (count) *count = 0;
    if (!det || !luma || !count || (max > 0 && !out) || max < 0 || num_windows < 0 ||
        (num_windows > 0 && !windows))
        return sh_error_set(SH_EINVAL, "detect: missing argument");
    if (width <= 0 || height <= 0 || width > SH_IMAGE_MAX_SIZE || height > SH_IMAGE_MAX_SIZE ||
        stride < width)
        return sh_error_set(SH_EINVAL, "detect: invalid plane %dx%d stride %d", width, height,
                            stride);
    if (num_windows > SH_DETECT_MAX_WINDOWS)
        return sh_error_set(SH_ERANGE, "detect: %d windows (at most %d)", num_windows,
                            SH_DETECT_MAX_WINDOWS);
    int n = 0;
    sh_status st;
    if (!windows || num_windows == 0) {
        det->td->quad_decimate = (float)det->quad_dec;
        det->num_scan = 0;
        const sh_window whole = {0, 0, width, height};
        zarray_t *dets = detect_view(det->td, luma, stride, &whole);
        if (!dets)
            return sh_error_set(SH_ENOMEM, "detect: libapriltag failed on a %dx%d image", width, height);
        collect(det, dets, &whole, width, height, 0, out, max, &n);
        apriltag_detections_destroy(dets);
        st = SH_OK;
    } else {
        det->td->quad_decimate = (float)det->win_dec;
        plan_windows(det, width, height, windows, num_windows);
        st = scan(det, luma, width, height, stride, out, max, &n);
    }
    *count = n;
    return st;
}

sh_status sh_detector_set_tag_side(sh_detector *det, double side_px)
{
    if (!det || !(side_px >= 0) || !isfinite(side_px))
        return sh_error_set(SH_EINVAL, "detect: tag side %g px", side_px);
    double d = 1;
    if (side_px > 0) {
        int modules = det->tf->width_at_border > 0 ? det->tf->width_at_border : 1;
        d = floor(side_px / modules / SH_DETECT_MODULE_PX);
        if (d > SH_DETECT_MAX_DECIMATE) d = SH_DETECT_MAX_DECIMATE;
    }
    det->quad_dec = fmax(det->opts.quad_decimate, d);
    det->win_dec = fmax(det->opts.window_decimate, d);
    return SH_OK;
}

void sh_detector_decimation(const sh_detector *det, double *quad_decimate, double *window_decimate)
{
    if (quad_decimate) *quad_decimate = det->quad_dec;
    if (window_decimate) *window_decimate = det->win_dec;
}

int sh_detector_last_windows(const sh_detector *det, sh_window *out, int max)
{
    if (!det) return 0;
    for (int i = 0; i < det->num_scan && i < max; i++) out[i] = det->scan[i];
    return det->num_scan;
}

/* BT.601 luma, Y = (77 R + 150 G + 29 B + 128) >> 8, of the given rectangle. */
static void rgb_to_gray(const sh_plane *rgb, uint8_t *gray, int gstride, int x0, int y0, int w,
                        int h)
{
    for (int y = y0; y < y0 + h; y++) {
        const uint8_t *s = rgb->data + (size_t)y * (size_t)rgb->stride + (size_t)x0 * 3;
        uint8_t *d = gray + (size_t)y * (size_t)gstride + (size_t)x0;
        for (int x = 0; x < w; x++, s += 3)
            d[x] = (uint8_t)((77u * s[0] + 150u * s[1] + 29u * s[2] + 128u) >> 8);
    }
}

static sh_status detect_image(sh_detector *det, const sh_image *frame, const sh_window *windows,
                              int num_windows, sh_detection *out, int max, int *count)
{
    if (count) *count = 0;
    if (!det || !frame || !frame->plane[0].data)
        return sh_error_set(SH_EINVAL, "detect: missing frame");
    const sh_plane *p = &frame->plane[0];
    switch (frame->format) {
    case SH_PIX_GRAY8:
    case SH_PIX_I420:
    case SH_PIX_YUV444:
        return sh_detector_detect_plane(det, p->data, p->width, p->height, p->stride, windows,
                                        num_windows, out, max, count);
    case SH_PIX_RGB24:
        break;
    default:
        return sh_error_set(SH_EUNSUPPORTED, "detect: pixel format %d not supported",
                            (int)frame->format);
    }
    int w = p->width, h = p->height;
    if (w <= 0 || h <= 0 || w > SH_IMAGE_MAX_SIZE || h > SH_IMAGE_MAX_SIZE)
        return sh_error_set(SH_EINVAL, "detect: invalid frame %dx%d", w, h);
    if (!det->gray) {
        det->gray_size = (size_t)w * (size_t)h;
        det->gray = malloc(det->gray_size);
        if (!det->gray) return sh_error_set(SH_ENOMEM, "detect: cannot allocate %dx%d grey", w, h);
        det->gray_width = w;
        det->gray_height = h;
    } else if ((size_t)w * (size_t)h > det->gray_size) {
        return sh_error_set(SH_ERANGE, "detect: RGB frame %dx%d larger than the first (%dx%d)", w,
                            h, det->gray_width, det->gray_height);
    }
    if (!windows || num_windows == 0) {
        rgb_to_gray(p, det->gray, w, 0, 0, w, h);
    } else {
        if (num_windows > SH_DETECT_MAX_WINDOWS)
            return sh_error_set(SH_ERANGE, "detect: %d windows (at most %d)", num_windows,
                                SH_DETECT_MAX_WINDOWS);
        plan_windows(det, w, h, windows, num_windows);
        for (int i = 0; i < det->num_scan; i++)
            rgb_to_gray(p, det->gray, w, det->scan[i].x, det->scan[i].y, det->scan[i].width,
                        det->scan[i].height);
    }
    return sh_detector_detect_plane(det, det->gray, w, h, w, windows, num_windows, out, max,
                                    count);
}

sh_status sh_detector_detect(sh_detector *det, const sh_image *frame, sh_detection *out, int max,
                             int *count)
{
    return detect_image(det, frame, NULL, 0, out, max, count);
}

sh_status sh_detector_detect_windows(sh_detector *det, const sh_image *frame,
                                     const sh_window *windows, int num_windows,
                                     sh_detection *out, int max, int *count)
{
    if (!windows || num_windows <= 0) {
        if (count) *count = 0;
        if (det) det->num_scan = 0;
        return SH_OK; /* no window, nothing to look at */
    }
    return detect_image(det, frame, windows, num_windows, out, max, count);
}

#else /* !SH_HAVE_APRILTAG */

const char *sh_detector_families(void)
{
    return "";
}

sh_status sh_detector_create(const sh_detector_options *opts, sh_detector **out)
{
    (void)opts;
    if (out) *out = NULL;
    return sh_error_set(SH_EUNSUPPORTED, "detect: built without libapriltag");
}

void sh_detector_destroy(sh_detector *det)
{
    (void)det;
}

sh_status sh_detector_detect(sh_detector *det, const sh_image *frame, sh_detection *out, int max,
                             int *count)
{
    (void)det, (void)frame, (void)out, (void)max;
    if (count) *count = 0;
    return sh_error_set(SH_EUNSUPPORTED, "detect: built without libapriltag");
}

sh_status sh_detector_detect_windows(sh_detector *det, const sh_image *frame,
                                     const sh_window *windows, int num_windows,
                                     sh_detection *out, int max, int *count)
{
    (void)det, (void)frame, (void)windows, (void)num_windows, (void)out, (void)max;
    if (count) *count = 0;
    return sh_error_set(SH_EUNSUPPORTED, "detect: built without libapriltag");
}

sh_status sh_detector_detect_plane(sh_detector *det, const uint8_t *luma, int width, int height,
                                   int stride, const sh_window *windows, int num_windows,
                                   sh_detection *out, int max, int *count)
{
    (void)det, (void)luma, (void)width, (void)height, (void)stride, (void)windows;
    (void)num_windows, (void)out, (void)max;
    if (count) *count = 0;
    return sh_error_set(SH_EUNSUPPORTED, "detect: built without libapriltag");
}

int sh_detector_last_windows(const sh_detector *det, sh_window *out, int max)
{
    (void)det, (void)out, (void)max;
    return 0;
}

sh_status sh_detector_set_tag_side(sh_detector *det, double side_px)
{
    (void)det, (void)side_px;
    return sh_error_set(SH_EUNSUPPORTED, "detect: built without libapriltag");
}

void sh_detector_decimation(const sh_detector *det, double *quad_decimate, double *window_decimate)
{
    (void)det, (void)quad_decimate, (void)window_decimate;
}

#endif
