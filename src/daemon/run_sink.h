/* Private to the daemon (src/daemon): its sinks besides the display segment, recording what was
 * shown (run_sink.c) and the V4L2 output (run_v4l2out.c). */
#ifndef STILLHEART_RUN_SINK_H
#define STILLHEART_RUN_SINK_H

#include <stdint.h>
#include "stillheart/core.h"
#include "stillheart/image.h"
#include "stillheart/y4m.h"

/* ---- recording what was shown (run_sink.c): y4m FILE, FILE.y4m or png:DIR ---- */
typedef struct run_record run_record;
/* Never over an earlier recording: the first free name of spec, spec-2, spec-3, ...
 * (run_record_path); a Y4M file is flushed every sync_ms and made durable beside. */
sh_status run_record_open(const char *spec, const sh_y4m_header *hdr, int sync_ms, run_record **out);
const char *run_record_path(const run_record *r);
sh_status run_record_write(run_record *r, const sh_image *shown);
/* Frames the PNG writer could not keep up with (not recorded). */
uint64_t run_record_skipped(const run_record *r);
/* Writes what is queued, closes; an error when a file could not be written. */
sh_status run_record_close(run_record *r);

/* ---- the V4L2 output (run_v4l2out.c): [sink] v4l2 = /dev/videoN (a v4l2loopback device) ---- */
typedef struct run_v4l2out run_v4l2out;
/* Opens path and sets its output format to hdr's frames (GRAY8, RGB24 or I420); refuses, saying
 * which, a path that is not a device, not V4L2, without a video output, or a format the device
 * does not take as asked. */
sh_status run_v4l2out_open(const char *path, const sh_y4m_header *hdr, run_v4l2out **out);
const char *run_v4l2out_path(const run_v4l2out *o);
/* One frame, never waiting: one the device does not take now is counted (run_v4l2out_not_taken)
 * and SH_OK; an error only when the device is gone or broken (write's errno). */
sh_status run_v4l2out_write(run_v4l2out *o, const sh_image *shown);
uint64_t run_v4l2out_written(const run_v4l2out *o);
uint64_t run_v4l2out_not_taken(const run_v4l2out *o);
void run_v4l2out_close(run_v4l2out *o);

#endif
