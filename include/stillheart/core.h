/* Status codes and error reporting shared by every stillheart module.
 *
 * Every public function returns an sh_status.  A failing function records a one-line message
 * (naming the file, line, frame or device concerned) in a thread-local buffer; the caller that
 * decides what to do with the failure (the CLI, the daemon) prints it with sh_error_message().
 * Library code never prints and never aborts on input. */
#ifndef STILLHEART_CORE_H
#define STILLHEART_CORE_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

typedef enum {
    SH_OK = 0,
    SH_EINVAL = -1,     /* bad argument or bad input data */
    SH_ENOMEM = -2,     /* allocation failed */
    SH_EIO = -3,        /* read/write error, file missing */
    SH_EFORMAT = -4,    /* malformed file content (header, row, frame) */
    SH_EDEGENERATE = -5,/* geometry the method cannot use (too few, collinear, duplicate points) */
    SH_EEOF = -6,       /* clean end of stream: not an error for readers' callers */
    SH_EUNSUPPORTED = -7,
    SH_ERANGE = -8      /* value outside the sizes fixed at start */
} sh_status;

/* Records the message for the calling thread and returns code, so callers write
 * `return sh_error_set(SH_EFORMAT, "%s: frame %d truncated", path, n);` */
sh_status sh_error_set(sh_status code, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 2, 3)))
#endif
    ;

/* The calling thread's last message ("" if none). Valid until the thread's next sh_error_set. */
const char *sh_error_message(void);

/* A short name for a status code ("invalid argument", ...). */
const char *sh_status_name(sh_status code);

/* Line by line through a text in memory, for the line-oriented parsers (the config's INI, the
 * calibration YAML, phantom files): '\n' ends a line, and so does the text's end. */
typedef struct {
    const char *text, *name; /* name: the file, for messages */
    size_t len, pos;
    int lineno; /* the line last returned, from 1 */
} sh_lines;
void sh_lines_init(sh_lines *it, const char *text, size_t len, const char *name);
/* The next line, without its '\n', into line (cap bytes): SH_OK, SH_EEOF after the last, or
 * SH_EFORMAT "NAME:N: line too long" (cap bytes or more) / "NAME:N: NUL byte". */
sh_status sh_lines_next(sh_lines *it, char *line, size_t cap);

/* CLOCK_MONOTONIC now, in nanoseconds: frame timestamps, deadlines and logs on one clock. */
int64_t sh_monotonic_ns(void);

#ifdef __cplusplus
}
#endif
#endif
