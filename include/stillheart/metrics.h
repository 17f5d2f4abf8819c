/* The paper's stabilization quality metric (section V):
 *   I_error(x, y, c) = 1/k sum_t |I_t(x, y, c) - I_ref(x, y, c)|     (intensities in [0, 1])
 *   e = sum_c ( 1/p sum_{(x,y) in hull} I_error(x, y, c) )
 * over the k frames added, the p pixels inside the convex hull of the reference markers, and
 * the R, G, B channels (YUV frames are converted to RGB first; GRAY8 counts one channel). */
#ifndef STILLHEART_METRICS_H
#define STILLHEART_METRICS_H

#include "stillheart/hull.h"
#include "stillheart/image.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct sh_metric sh_metric;

/* reference: the reference frame (any format); hull: where the metric counts; full_range for
 * the YUV to RGB conversion. */
sh_status sh_metric_create(const sh_image *reference, const sh_hull *hull, int full_range,
                           sh_metric **out);
void sh_metric_destroy(sh_metric *metric);

/* Adds one frame I_t (same size as the reference). */
sh_status sh_metric_add(sh_metric *metric, const sh_image *frame);

int sh_metric_frames(const sh_metric *metric);
int sh_metric_pixels(const sh_metric *metric); /* p */
/* e over the frames added so far (0 when none). */
double sh_metric_e(const sh_metric *metric);

/* I_error converted to grey (mean over channels, in [0, 1]) per pixel, NaN outside the hull:
 * width x height floats. */
sh_status sh_metric_error_image(const sh_metric *metric, float *grey);

#ifdef __cplusplus
}
#endif
#endif
