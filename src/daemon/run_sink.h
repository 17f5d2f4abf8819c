/* Private to the daemon (src/daemon): recording what was shown (run_sink.c). */
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

#endif
