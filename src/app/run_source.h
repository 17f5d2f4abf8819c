/* Private to stillheart run: the daemon's frame source. A thread reads frames and hands the
 * newest to the processing thread through a three-buffer mailbox (one being filled, one waiting,
 * one being processed): when processing falls behind, the waiting frame is the oldest and is
 * dropped and counted, never queued. As fast as possible (no real time), nothing is dropped: the
 * source waits for processing instead. */
#ifndef STILLHEART_RUN_SOURCE_H
#define STILLHEART_RUN_SOURCE_H

#include <stdint.h>

#include "stillheart/config.h"
#include "stillheart/image.h"
#include "stillheart/y4m.h"

/* The daemon's logger ("-- LEVEL [time thread] -- message"). */
typedef void (*run_log_fn)(const char *level, const char *thread, const char *fmt, ...);

typedef struct {
    sh_image img;      /* the frame, in the working format of run_source_header */
    int index;         /* frame index in the file (from 0 again after a loop) */
    int64_t avail_ns;  /* CLOCK_MONOTONIC time it became available to processing */
} run_frame;

typedef struct run_source run_source;

/* Opens the configured source ([source] spec, realtime, loop) and allocates its buffers; a missing
 * file fails here (sh_error_message names it). */
sh_status run_source_open(const sh_config *cfg, run_log_fn log, run_source **out);
/* The frames' geometry, format and rate, as a Y4M header (also what a Y4M record gets). */
const sh_y4m_header *run_source_header(const run_source *rs);
/* Frames per second of the stream (0: unknown). */
double run_source_fps(const run_source *rs);
sh_status run_source_start(run_source *rs);
/* The newest frame, waiting up to timeout_ms; NULL on timeout or at the end. The frame stays
 * valid until the next call. */
const run_frame *run_source_take(run_source *rs, int timeout_ms);
/* 1 once the source has ended (no loop, or failed) and its last frame was taken. */
int run_source_ended(run_source *rs);
/* Pacing can change at run time (SIGHUP). */
void run_source_set_pacing(run_source *rs, int realtime, int loop);
uint64_t run_source_dropped(run_source *rs);
/* Stops the thread (if started) and frees everything. */
void run_source_destroy(run_source *rs);

#endif
