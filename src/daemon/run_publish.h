/* Private to the daemon (src/daemon): the publisher thread (run_publish.c). What is shown goes to
 * the sinks (the display segment, the record, the V4L2 output) on a thread of its own, so that the
 * processing thread goes on with the next frame while the last one is copied out: at 4K the
 * segment's copy alone is about 1.1-1.5 ms a frame (docs/daemon.md, "At 4K"). One frame in flight
 * at most; the caller keeps its pixels and info as they are until it has waited for it. */
#ifndef STILLHEART_RUN_PUBLISH_H
#define STILLHEART_RUN_PUBLISH_H

#include <stdint.h>

#include "stillheart/core.h"
#include "stillheart/display.h"
#include "stillheart/image.h"

typedef struct run_publisher run_publisher;
/* What publishing one frame is: called on the publisher thread, one frame at a time. */
typedef void (*run_publish_fn)(void *ctx, const sh_image *shown, const sh_display_frame_info *info);

sh_status run_publisher_create(run_publish_fn fn, void *ctx, run_publisher **out);
/* Waits for the frame in flight, then stops the thread. */
void run_publisher_destroy(run_publisher *p);
/* Hands one frame to fn. The frame handed before was waited for (run_publisher_wait); shown's
 * pixels and *info stay the caller's and unchanged until run_publisher_wait returns. */
void run_publisher_submit(run_publisher *p, const sh_image *shown, const sh_display_frame_info *info);
/* Waits until the frame handed last is published: 1 and *done_ns the moment fn returned
 * (CLOCK_MONOTONIC), or 0 when no frame was handed since the last wait. What fn wrote is visible
 * to the caller afterwards (the pipeline's sinks it stopped, its log). */
int run_publisher_wait(run_publisher *p, int64_t *done_ns);

#endif
