/* Log lines of the programs (the `stillheart` daemon and commands, the tools): levels, a name per
 * thread, and messages that repeat logged once or at most once a period.
 *
 * For programs only. The engine and capture modules (docs/architecture.md) never include this
 * header: a library function returns a status and a message, and the program that called it
 * decides whether and how to say it (scripts/check-includes.sh holds them to that).
 *
 * Two line styles, chosen once by sh_log_setup:
 *   SH_LOG_DAEMON  "-- INFO  [2026-12-01 09:14:05.898 main   ] -- message" (level, local wall-clock
 *                  time to the ms, the thread's name), as ustreamer's log; docs/daemon.md. In
 *                  the journal without the time ("-- INFO  [main   ] -- ..."): it has its own.
 *   SH_LOG_TOOL    "PROGRAM: message", as a command-line tool reports an error.
 * When stderr is the journal ($JOURNAL_STREAM names stderr's device and inode, as systemd sets it
 * for StandardError=journal), every line starts with the level's syslog priority, "<3>" to "<7>"
 * (sd-daemon(3)), which journald strips and keeps as the entry's priority.
 *
 * Lines go to stderr whole (one write each, under a lock): threads' lines never interleave.
 * Every function may be called from any thread. */
#ifndef STILLHEART_LOG_H
#define STILLHEART_LOG_H

#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* Most severe first: a line is written when its level is <= the level set. */
typedef enum { SH_LOG_ERROR, SH_LOG_WARN, SH_LOG_INFO, SH_LOG_DEBUG } sh_log_level;

typedef enum { SH_LOG_DAEMON, SH_LOG_TOOL } sh_log_style;

/* The style, the program's name (SH_LOG_TOOL's prefix; copied) and the most verbose level
 * written. Reads $JOURNAL_STREAM and stderr's identity, so call it again after redirecting
 * stderr. Before any call: SH_LOG_TOOL, "stillheart", SH_LOG_INFO. */
void sh_log_setup(sh_log_style style, const char *program, sh_log_level level);
void sh_log_set_level(sh_log_level level);
sh_log_level sh_log_get_level(void);

/* The calling thread's name in SH_LOG_DAEMON lines (at most 15 characters kept; copied). Each
 * thread sets its own when it starts; a thread that never did shows "-". */
void sh_log_set_thread(const char *name);

void sh_log_msg(sh_log_level level, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
void sh_log_error(const char *fmt, ...) __attribute__((format(printf, 1, 2)));
void sh_log_warn(const char *fmt, ...) __attribute__((format(printf, 1, 2)));
void sh_log_info(const char *fmt, ...) __attribute__((format(printf, 1, 2)));
void sh_log_debug(const char *fmt, ...) __attribute__((format(printf, 1, 2)));

/* A message that would repeat, one per call site (or per camera, ...), zero-initialized:
 *   period_s == 0  logged once, then only counted until sh_log_limit_clear (the condition has
 *                  gone away; the next occurrence is news again);
 *   period_s > 0   logged at most once per period_s seconds; a line that follows repeats not
 *                  logged ends with " (N more since the last)".
 * A call filtered out by the level neither logs nor arms the limit. */
typedef struct {
    double period_s;
    int armed;                     /* logged, and not cleared since (period 0) */
    int64_t last_ns;               /* when it was last logged (period > 0) */
    unsigned long long suppressed; /* occurrences not logged since the last line */
} sh_log_limit;

void sh_log_limited(sh_log_limit *lim, sh_log_level level, const char *fmt, ...)
    __attribute__((format(printf, 3, 4)));
/* Re-arms lim and returns how many occurrences it held back since its last line. */
unsigned long long sh_log_limit_clear(sh_log_limit *lim);

#ifdef __cplusplus
}
#endif
#endif
