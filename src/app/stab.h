/* Private to `stillheart warp` and `warp3d`: what their runs share. A Y4M video in, the
 * stabilized one out, the markers from a points file, the models from the model cache, and the
 * paper's metric e of input and output against the reference frame. Each command's job holds an
 * app_stab and adds its own; the command fills it (the opening differs), the functions below
 * run the frames, report and free. */
#ifndef STILLHEART_APP_STAB_H
#define STILLHEART_APP_STAB_H

#include "app.h"
#include "stillheart/metrics.h"
#include "stillheart/modelcache.h"
#include "stillheart/points.h"
#include "stillheart/warp.h"
#include "stillheart/y4m.h"

typedef struct {
    sh_points points;
    const sh_point *ref_rows; /* the reference frame's markers (in points) */
    int ref_count;
    sh_modelcache *cache;
    sh_y4m_reader *reader;
    sh_y4m_writer *writer;
    sh_warp *warp;
    sh_metric *metric_in, *metric_out; /* NULL until the reference frame is measured */
    sh_image in, out, ref;
    int *ids;     /* the current frame's markers ... */
    double *cur;  /* ... and their positions (x, y or X, Y, Z each) */
    int full_range, from_stdin;
    sh_cli_progress progress;
    int frames, raw_frames;
    double warp_seconds;
} app_stab;

/* "stillheart CMD: WHAT: the library's message" (WHAT alone without one); returns 1. */
int app_fail(const char *what);

/* Opens the output with the header hdr and starts the progress line, labelled command, over the
 * frames the input holds (cli.h: none with --quiet or off a terminal): 0, or 1 with the reason
 * printed. */
int app_stab_start(app_stab *s, const char *command, const char *out_path, const sh_y4m_header *hdr);

/* Reads every frame into s->in and calls step(job) on it (0: go on; 1: it printed why the run
 * stops), then closes the output. *st: how the input ended (SH_EEOF: whole; anything else is
 * reported, the frames before it are written). 0, or 1 when a step or the output failed. */
int app_stab_run(app_stab *s, int (*step)(void *job), void *job, sh_status *st);

/* A frame written unstabilized (n of its markers usable, min needed): counted, and said on
 * stderr unless quiet, with the library's reason when there were markers enough. */
void app_stab_raw(app_stab *s, const char *command, int n, int min, int quiet);

/* The metric e of input and output, when measured, and the change in per cent: on stdout, or
 * on stderr when out_path is "-" (stdout carries the video then). */
void app_stab_print_e(const app_stab *s, const char *out_path);

/* The output's XSTILLHEART=KIND:NAME tag (y4m.h; KIND "method" or "method3d") over the tags hdr
 * took from the input; b, the 3D displacement's interpolant, is added as /NAME when it differs
 * from a. 0, or 1 with the reason printed. */
int app_stab_tag(sh_y4m_header *hdr, const char *kind, const sh_interp_params *a, const sh_interp_params *b);

void app_stab_close(app_stab *s);

#endif
