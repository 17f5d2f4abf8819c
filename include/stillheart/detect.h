/* Marker detection: AprilTags (libapriltag) in a frame, in windows around predictions or over
 * the whole frame. Windows are views into the frame (no copy): libapriltag's image_u8_t borrows
 * the pixels with a moved origin, and the window's offset is added back to the results.
 *
 * Coordinates: pixel centres at integers (OpenCV's convention, as the rest of stillheart).
 * libapriltag reports the same convention for its centre and corners... the implementation
 * documents and tests whatever offset it applies. Corners are in libapriltag's order. */
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
} sh_detector_options;

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

#ifdef __cplusplus
}
#endif
#endif
