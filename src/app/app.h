/* Private to the stillheart command: the subcommands and their shared helpers. */
#ifndef STILLHEART_APP_H
#define STILLHEART_APP_H

#include <stdio.h>

#include "stillheart/image.h"

#define STILLHEART_VERSION "0.1.0"

int cmd_warp(int argc, char **argv);
int cmd_detect(int argc, char **argv);
int cmd_warp3d(int argc, char **argv);
int cmd_track(int argc, char **argv);
int cmd_record(int argc, char **argv);
int cmd_run(int argc, char **argv);
int cmd_ctl(int argc, char **argv);

/* What a subcommand's parse_options returns when the command goes on; anything else is the exit
 * code (0 after --help). */
#define APP_GO_ON (-1)

/* Parses a whole decimal number / a finite real; on failure prints "OPTION: reason" and
 * returns 0. */
int app_parse_int(const char *option, const char *text, int min, int max, int *out);
int app_parse_double(const char *option, const char *text, double min, double max, double *out);

/* A progress line on stderr when it is a terminal: "label  done/total  rate". */
typedef struct {
    int enabled;
    double start, last;
} app_progress;
void app_progress_start(app_progress *p);
void app_progress_update(app_progress *p, const char *label, int done, int total);
void app_progress_end(app_progress *p);

/* Monotonic seconds (sh_monotonic_ns), for the commands' timings. */
double app_now(void);

/* Reads frame `index` of the Y4M file path into img (a second pass over the file, so any frame
 * can be the reference without holding the video in memory); 0, with the message set, when it
 * cannot. */
int app_read_frame_at(const char *path, int index, sh_image *img);

/* Writes a float32 array of shape (h, w, 2) as NumPy .npy (version 1.0, little endian). */
int app_write_npy(const char *path, const float *data, int h, int w, int depth);

#endif
