/* Private to the daemon (src/daemon): the pipeline's pieces (source, processing, shared-memory display,
 * record, V4L2 output, control socket) opened together from one config at start and swapped together when
 * SIGHUP brings a new one (run_pipeline.c). daemon.c drives the loop over them. */
#ifndef STILLHEART_RUN_PIPELINE_H
#define STILLHEART_RUN_PIPELINE_H

#include <stddef.h>
#include <stdint.h>

#include "run_ctl.h"
#include "run_sink.h"
#include "run_proc.h"
#include "run_source.h"
#include "stillheart/config.h"
#include "stillheart/display.h"
#include "stillheart/image.h"
#include "stillheart/y4m.h"

/* A file as stat saw it (all 0: none, or unreadable); rewritten in place, it differs. */
typedef struct {
    int64_t ino, size, mtime_ns;
} run_file_stamp;

typedef struct {
    sh_config cfg;            /* what every piece below was opened with */
    run_source *src;          /* NULL only after a reload that could not bring any camera back */
    run_proc *proc;
    sh_display_writer *disp;  /* NULL: [sink] display = none */
    run_record *rec;          /* NULL: no record, or it was stopped by a write error */
    run_ctl *ctl;             /* NULL: no control socket */
    run_v4l2out *v4l2;        /* NULL: no [sink] v4l2, or it was stopped by a write error */
    sh_y4m_header hdr;        /* the output camera's frames (a copy: the source's goes with it) */
    sh_y4m_header out_hdr;    /* the shown frames, which the sinks are made for: hdr's, or a stereo layout's */
    sh_image black;           /* shown while the output camera is lost, in out_hdr's geometry */
    uint64_t dropped_before;  /* dropped sets and models built by sources and processing */
    int builds_before;        /*   replaced by reloads, for the totals at exit */
    int refined_before;
    run_file_stamp calib_file, points_file; /* [method] calibration, [run] points when opened */
} run_pipeline;

/* Opens every piece from cfg (sh_config_check passed), the source not yet started. On error
 * nothing stays open and sh_error_message names the piece ("[sink] display: ..."); the status is
 * SH_EINVAL exactly when the input cannot run, whatever restarts (a replayed file, the points or
 * calibration file: the exit-code table, docs/daemon.md), never for what a restart can mend. */
sh_status run_pipeline_open(run_pipeline *p, const sh_config *cfg);
sh_status run_pipeline_start(run_pipeline *p);

typedef enum {
    RUN_RELOAD_APPLIED,  /* every piece runs with the fresh config */
    RUN_RELOAD_REFUSED,  /* a piece of the fresh config failed: the running config and pieces are
                          * kept (the previous cameras reopened when they had been closed) */
    RUN_RELOAD_FATAL     /* the previous cameras (or display) could not be reopened either: the
                          * pipeline cannot run, the daemon must exit non-zero */
} run_reload;

/* Applies fresh (sh_config_check passed) to every piece: a piece whose keys did not change is
 * kept (the display segment also when its name, geometry, format and slots stay); the others are
 * opened from fresh and swapped in. Cameras are closed before the new ones open (a V4L2 device
 * opens once). what gets one line for the log: what changed ("" when only gating did, or
 * nothing), or why it was refused. */
run_reload run_pipeline_reload(run_pipeline *p, const sh_config *fresh, char *what, size_t cap);

/* Sets dropped and models built since start, over every source and processing reloads replaced. */
uint64_t run_pipeline_dropped(run_pipeline *p);
int run_pipeline_builds(const run_pipeline *p);
/* Models swapped for a finer grid built off the processing thread (run_models_refined), in all. */
int run_pipeline_refined(const run_pipeline *p);

/* Closes a V4L2 output (NULL: none), logging the frames it took and those it did not. */
void run_pipeline_v4l2_close(run_v4l2out *o);

/* Closes everything (the display segment marked closed: readers see the end). SH_OK unless the
 * record could not be written (logged). */
sh_status run_pipeline_close(run_pipeline *p);

#endif
