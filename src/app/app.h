/* Private to the stillheart command: the subcommands and their shared helpers. */
#ifndef STILLHEART_APP_H
#define STILLHEART_APP_H

#include <stdio.h>

#include "stillheart/cli.h"
#include "stillheart/image.h"

int cmd_warp(int argc, char **argv);
int cmd_detect(int argc, char **argv);
int cmd_warp3d(int argc, char **argv);
int cmd_track(int argc, char **argv);
int cmd_record(int argc, char **argv);
int cmd_run(int argc, char **argv);
int cmd_ctl(int argc, char **argv);

/* What a subcommand's parse_options returns when the command goes on; anything else is the exit
 * code (0 after --help or --version). */
#define APP_GO_ON (-1)

/* Monotonic seconds (sh_monotonic_ns), for the commands' timings. */
double app_now(void);

/* Reads frame `index` of the Y4M file path into img (a second pass over the file, so any frame
 * can be the reference without holding the video in memory); 0, with the message set, when it
 * cannot. */
int app_read_frame_at(const char *path, int index, sh_image *img);

/* Writes a float32 array of shape (h, w, 2) as NumPy .npy (version 1.0, little endian). */
int app_write_npy(const char *path, const float *data, int h, int w, int depth);

#endif
