/* Marker detection: AprilTags (libapriltag) in a frame, in windows around predictions or over
 * the whole frame. Windows are views into the frame (no copy): libapriltag's image_u8_t borrows
 * the pixels with a moved origin, and the window's offset is added back to the results.
 *
 * Coordinates: pixel centres at integers (OpenCV's convention, as the rest of stillheart).
 * libapriltag 3.3 puts pixel centres at +0.5 (pixel i covers [i, i+1)), so the detector
 * subtracts SH_DETECT_APRILTAG_OFFSET (0.5) from every centre and corner it returns; the unit
 * test checks this against the phantom's ground truth and against a tag drawn with exact,
 * pixel-aligned edges. Corners are in libapriltag's order.
 *
 * Pixels: libapriltag reads packed 8-bit rows (one byte per pixel, any stride), so any
 * contiguous luminance plane works without a copy: GRAY8, the Y plane of I420/NV12/YUV444
 * (sh_detector_detect_plane). A YUYV frame's luma has a pixel step of 2: it must be copied
 * into a packed plane first. RGB24 is converted to grey (BT.601 luma) into a buffer the
 * detector owns, only inside the windows when detecting in windows.
 *
 * A detector holds one apriltag_detector per family, reused for every call (per-call overhead
 * matters); it is not thread-safe: one detector per thread (its own helpers, window_threads,
 * are its business). */
#ifndef STILLHEART_DETECT_H
#define STILLHEART_DETECT_H

#include "stillheart/image.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct {
    int id;
    double cx, cy;          /* tag centre */
    double corner[4][2];    /* libapriltag's order */
    double margin;          /* decision margin (higher: more certain) */
    int hamming;            /* bits corrected */
} sh_detection;

/* A search window in full-resolution pixel coordinates (clipped to the frame by the detector). */
typedef struct {
    int x, y, width, height;
} sh_window;

typedef struct sh_detector sh_detector;

typedef struct {
    const char *family;     /* tag36h11 (default), tag25h9, tag16h5, tagStandard41h12, ... */
    double quad_decimate;   /* full-frame scans (default 2, libapriltag's default) */
    double quad_sigma;      /* default 0 */
    int refine_edges;       /* default 1 */
    double decode_sharpening; /* default 0.25 */
    int threads;            /* libapriltag worker threads (default 1) */
    int max_hamming;        /* bits corrected at most (default 2, apriltag_detector_add_family's) */
    double window_decimate; /* quad decimation inside windows (default 1: full resolution).
                             * 2 with refine_edges is ~2.8x cheaper and as accurate on the
                             * phantom's ~93 px tags (bench_detect_track: 0.052 vs 0.044 px
                             * from the truth, docs/tracking.md); small tags need 1 */
    int merge_windows;      /* 1 (default): windows that overlap or lie close are merged into
                             * their bounding box when that costs fewer pixels than it saves in
                             * per-call overhead; tags seen by two windows are reported once
                             * (the view whose window edge stays half a module clear of its quad,
                             * else the higher decision margin: detect.c, collect) */
    int window_threads;     /* threads scanning the windows of one call (default 1): the
                             * caller's and window_threads - 1 helpers started at create, each
                             * with its own libapriltag detector, windows handed out largest
                             * first; the results are collected in window order, the same as
                             * with one thread. Whole-frame scans use `threads` alone */
} sh_detector_options;

/* libapriltag's pixel-centre offset, subtracted from its coordinates. */
#define SH_DETECT_APRILTAG_OFFSET 0.5
/* Windows per call at most. */
#define SH_DETECT_MAX_WINDOWS 256

void sh_detector_options_default(sh_detector_options *opts);
sh_status sh_detector_create(const sh_detector_options *opts, sh_detector **out);
void sh_detector_destroy(sh_detector *det);

/* The luminance plane the detector reads: GRAY8 and the Y plane of I420/YUV444 directly;
 * RGB24 is converted into a buffer the detector owns (sized at the first frame). */
/* Detects in the whole frame. Writes at most max detections (all of them, duplicates
 * included), *count = how many were found (may exceed max: then only max were written). */
sh_status sh_detector_detect(sh_detector *det, const sh_image *frame, sh_detection *out, int max,
                             int *count);
/* Detects in each window (at full resolution), results in frame coordinates. */
sh_status sh_detector_detect_windows(sh_detector *det, const sh_image *frame,
                                     const sh_window *windows, int num_windows,
                                     sh_detection *out, int max, int *count);

/* The same on a caller's 8-bit luminance plane (width x height, rows stride bytes apart,
 * stride >= width): windows NULL (or num_windows 0) scans the whole plane at quad_decimate,
 * otherwise each window at window_decimate. */
sh_status sh_detector_detect_plane(sh_detector *det, const uint8_t *luma, int width, int height,
                                   int stride, const sh_window *windows, int num_windows,
                                   sh_detection *out, int max, int *count);

/* The smallest tag's side in the image, px, as a tracker knows it from its last accepted quads
 * (0: not known, the default). Known, each scan is decimated further than the options' when that
 * keeps at least SH_DETECT_MODULE_PX decimated pixels per module of the family's border (a
 * 4K view's tags are twice the size of a 1080p view's: the same ratio at twice the decimation,
 * a quarter of the pixels), up to SH_DETECT_MAX_DECIMATE; never less than the options'. */
sh_status sh_detector_set_tag_side(sh_detector *det, double side_px);
/* The decimations the next whole-frame and windowed scans use. */
void sh_detector_decimation(const sh_detector *det, double *quad_decimate, double *window_decimate);
/* Decimated pixels per module kept: window_decimate 2 on the phantom's 93 px tag36h11 tags
 * (8 modules: 5.8 px) was measured as accurate as full resolution (docs/tracking.md) */
#define SH_DETECT_MODULE_PX 5.8
/* The largest decimation the tag size may choose: measured at 4K (195 px tags: corner error the
 * same as at 2, docs/tracking.md, "Decimation from the tags' size") */
#define SH_DETECT_MAX_DECIMATE 4

/* The windows the last windowed call actually scanned after clipping and merging (for
 * benchmarks and tests): returns their number, copies at most max of them. */
int sh_detector_last_windows(const sh_detector *det, sh_window *out, int max);

/* The family names the build knows, space separated. */
const char *sh_detector_families(void);

#ifdef __cplusplus
}
#endif
#endif
