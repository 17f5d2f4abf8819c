/* The daemon: `stillheart run` as a module. Frames from the configured cameras (a thread each,
 * grouped into sets, a one-set mailbox that drops the oldest when processing falls behind) are
 * tracked, matched to the reference, warped with the model of their marker set (built on a
 * helper thread) and published to the shared-memory display buffer (display.h) and the record,
 * with status, reason, markers used and residual. When the output camera is lost a black raw
 * frame per frame period is published instead, so that the display says so. systemd hears
 * READY, RELOADING, STOPPING, STATUS each second and WATCHDOG while frames progress (notify.h).
 * docs/daemon.md is the manual, docs/architecture.md its place among the modules.
 *
 * Ownership: sh_daemon_create copies the config and the options (the strings they point to
 * must outlive the daemon); sh_daemon_destroy frees everything it opened.
 * Threads: the caller's thread runs the loop (sh_daemon_run); the daemon starts one per camera,
 * the trigger's, the model builder, the warp's helpers and the control socket's, and joins them
 * all before sh_daemon_destroy returns. Nothing here may be called from two threads at once.
 * Signals: the program's handlers only set the flags of an sh_daemon_signals (the one thing a
 * handler may do: store to a volatile sig_atomic_t); the loop polls them at least every 100 ms
 * and clears the ones it acts on. The daemon installs no handler of its own.
 * Errors: every function returns a status with the message in sh_error_message() (core.h), which
 * the program words as it words its other refusals. Unlike the library modules below it, the
 * daemon is a program-side module: what happens at run time, when there is no caller to return it
 * to (a camera lost, a reload refused, a record write failing), it logs through log.h. */
#ifndef STILLHEART_DAEMON_H
#define STILLHEART_DAEMON_H

#include <signal.h>
#include <stddef.h>
#include <stdio.h>

#include "stillheart/config.h"
#include "stillheart/core.h"
#include "stillheart/pixconv.h"
#include "stillheart/source.h"
#include "stillheart/sync.h"
#include "stillheart/y4m.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Set by the program's signal handlers, polled (and cleared when acted on) by sh_daemon_run. */
typedef struct {
    volatile sig_atomic_t stop;      /* SIGTERM, SIGINT: stop after the current frame */
    volatile sig_atomic_t reload;    /* SIGHUP: read the config again and apply it */
    volatile sig_atomic_t reference; /* SIGUSR1: take the next good frame as the new reference */
} sh_daemon_signals;

/* Reads the config again for a reload (the program's file and command line, sh_config_check
 * passed): SH_OK, or a refusal with its reason in err (SH_CONFIG_ERR bytes). */
typedef sh_status (*sh_daemon_load_fn)(void *ctx, sh_config *fresh, char *err);

typedef struct {
    int max_frames;                /* stop after this many published frames; 0: no limit */
    const char *trace_path;        /* one CSV line per published frame; NULL: none */
    const char *trace_points_path; /* the markers each warped frame's map was made from; NULL: none */
    sh_daemon_load_fn load;        /* SIGHUP's config; NULL: a reload is refused */
    void *load_ctx;
} sh_daemon_options;

typedef struct sh_daemon sh_daemon;

/* Opens every piece of the pipeline from cfg (sh_config_check passed) and the trace files; the
 * cameras are not started yet. On error nothing stays open and the message names the piece
 * ("[sink] display: ...", "--trace: FILE: ..."). SH_EINVAL when the input cannot run whatever
 * restarts (a replayed camera file, the points or calibration file: missing or bad); any other
 * status for what a restart can mend (a device, the display's name, a trace file). */
sh_status sh_daemon_create(const sh_config *cfg, const sh_daemon_options *opt, sh_daemon **out);
/* Starts the cameras, logs what runs and tells systemd READY. */
sh_status sh_daemon_start(sh_daemon *d);
/* The loop, until sig->stop, max_frames published or the end of a replay (SH_OK; systemd hears
 * STOPPING), or until a reload leaves the pipeline unable to run (the previous cameras did not
 * come back: SH_EIO, logged; the program exits non-zero for systemd to restart it). SH_EFORMAT
 * when the output camera's input ended in an error (a replay's file damaged where good frames
 * lie behind the damage, logged where it was met): a stop that a restart cannot mend. */
sh_status sh_daemon_run(sh_daemon *d, sh_daemon_signals *sig);
/* The summary of the run so far, one line without newline ("stats: N published ..."): frames
 * published, raw, degraded, dropped, latency median / p99 / max, RSS, models built, black
 * frames, sets dropped after the tracker's first lock of the rates (or that it never locked). */
void sh_daemon_stats(sh_daemon *d, char *line, size_t cap);
/* The same as one JSON object and a newline on out (`stillheart run --stats --json`): published,
 * raw, degraded, dropped, latency_ms {median, p99, max}, rss_kb {start, at_1_min, max, end},
 * models_built, black_frames, published_at_lock, dropped_after_lock; a figure never measured
 * (no lock yet: the last two) is null. */
void sh_daemon_stats_json(sh_daemon *d, FILE *out);
/* Stops every thread, closes the pipeline (the display segment marked closed) and the trace
 * files. SH_OK unless the record or a trace file could not be written (logged). NULL: nothing. */
sh_status sh_daemon_destroy(sh_daemon *d);

/* ---- the config's cameras as the capture modules take them (also `stillheart record --config`) ---- */
/* source.h options of [cameraN] (and [source] realtime, loop, camera_timeout_ms). */
void sh_daemon_camera_options(const sh_config *cfg, int camera, sh_source_options *o);
/* sync.h options for the cameras; fps_num/den: camera 0's rate (for the defaults). */
void sh_daemon_sync_options(const sh_config *cfg, int cameras, int fps_num, int fps_den, sh_sync_options *o);
/* [trigger] as sh_gpio_options (chip points into cfg); 0 when mode is off. fps as above. */
int sh_daemon_gpio_options(const sh_config *cfg, int fps_num, int fps_den, sh_gpio_options *o);
/* The Y4M header of a raw format's frames converted by pixconv (GRAY8 or I420). */
void sh_daemon_y4m_header(sh_rawfmt format, int width, int height, int fps_num, int fps_den, sh_y4m_header *h);

#ifdef __cplusplus
}
#endif

#endif
