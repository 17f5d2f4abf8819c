/* stillheart run: the daemon's command line. Options (defaults, the config file, the command line,
 * which wins), --help, the signal handlers, and starting and stopping the daemon, which is the
 * module src/daemon (include/stillheart/daemon.h: the loop, the pipeline, systemd). */
#include <errno.h>
#ifdef __GLIBC__
#include <malloc.h>
#endif
#include <math.h>
#include <signal.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "app.h"
#include "stillheart/config.h"
#include "stillheart/daemon.h"
#include "stillheart/log.h"

/* LSB's "program is not configured" (systemd shows 6/NOTCONFIGURED); the unit's
 * RestartPreventExitStatus names it, and 2 (a config refused), beside it. */
#define RUN_EXIT_NOT_CONFIGURED 6

/* ---- signals ---- */
/* The handlers only set the daemon's flags (daemon.h); its loop polls them. */
static sh_daemon_signals sig;
static void on_signal(int s)
{
    if (s == SIGHUP) sig.reload = 1;
    else if (s == SIGUSR1) sig.reference = 1;
    else sig.stop = 1;
}

/* Before anything slow (a config on a slow disk, a camera that takes seconds to open, a FIFO
 * with no writer yet): a SIGHUP or SIGUSR1 of an operator's script in that time must not end
 * the daemon by their default action, and a SIGTERM is a stop once it can run. SA_RESTART: an
 * open() or read() of the start-up that a signal interrupts goes on instead of failing with
 * EINTR; the loop still wakes at once, as poll() and nanosleep() are never restarted. */
static void catch_signals(void)
{
    struct sigaction sa;
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = on_signal;
    sa.sa_flags = SA_RESTART;
    sigemptyset(&sa.sa_mask);
    sigaction(SIGTERM, &sa, NULL);
    sigaction(SIGINT, &sa, NULL);
    sigaction(SIGHUP, &sa, NULL);
    sigaction(SIGUSR1, &sa, NULL);
    signal(SIGPIPE, SIG_IGN);
}

/* ---- configuration: defaults, file, command line (which wins) ---- */
static void usage(FILE *out)
{
    fprintf(out,
        "usage: stillheart run [--config FILE] [--KEY VALUE ...]\n\n"
        "The daemon: frames from the source, stabilized onto the reference, published to the\n"
        "shared-memory display buffer (read it with stillheart-cat). Without --config the embedded\n"
        "defaults run the phantom demo (make run-demo). Keys (firmware-config/stillheart.ini):\n");
    sh_config_usage(out);
    fprintf(out,
        "run-only options:\n"
        "  --config FILE      INI file (keys above; the command line wins)\n"
        "  --max-frames N     stop after N published frames (tests, bench)\n"
        "  --stats            print a summary line at exit (fps, latency, drops, RSS, the sets dropped\n"
        "                     after the tracker's first lock of the rates) on standard output, even\n"
        "                     with --quiet (at the info level it is printed there anyway; the log is\n"
        "                     on standard error)\n"
        "  --json             with --stats: the summary as one JSON object on standard output:\n"
        "                     published, raw, degraded, dropped, latency_ms {median, p99, max},\n"
        "                     rss_kb {start, at_1_min, max, end}, models_built, black_frames,\n"
        "                     published_at_lock, dropped_after_lock (null: never measured)\n"
        "  --trace FILE       one CSV line per published frame: index, status, markers, residual, reason,\n"
        "                     stage CPU times (markers, model, warp) and latency in ms\n"
        "  --trace-points FILE  the markers each warped frame's map was made from, as a points file\n"
        "                     (frame,id,x,y: the output camera's pixels; raw frames have no rows)\n"
        "  --print-config     print the resulting config as INI and exit\n"
        SH_CLI_USAGE
        "Every option takes its value as --KEY VALUE or --KEY=VALUE; a 0|1 key (and --stats, --json,\n"
        "--print-config) also as --KEY (yes), --no-KEY (no), --KEY=yes|no|true|false|on|off|1|0 or\n"
        "--KEY followed by one of those words.\n"
        "signals: SIGTERM/SIGINT stop (segment marked closed). SIGHUP reloads the config file and\n"
        "applies every key in place: changed cameras are closed and the new ones opened, changed\n"
        "processing starts again with a new reference, the display segment is kept unless its name,\n"
        "size, format or slots change; a config that cannot run is refused and the running one kept\n"
        "(the previous cameras reopened). SIGUSR1 takes a new reference frame (so does `stillheart ctl\n"
        "reference` on the [run] control socket).\n"
        "exit status (the unit's RestartPreventExitStatus=2 6 follows it):\n"
        "  0  stopped by a signal, --max-frames or the end of a replay\n"
        "  1  a fault a restart can mend: a device or the display's name unavailable at start, a\n"
        "     reload that left no camera, a record or trace file that could not be written\n"
        "  2  what no restart mends: a bad config or command line (also one from which no model can\n"
        "     come on the frames: docs/daemon.md); a missing or bad points, calibration or replayed\n"
        "     camera file at start; a camera whose frames are over [source] max_frame_pixels; a\n"
        "     replay damaged where frames lie behind the damage\n"
        "  6  not configured: no camera named\n");
}

typedef struct {
    const char *config_path;
    int max_frames, stats, json, print_config;
    const char *trace_path, *trace_points_path;
} run_opts;

/* A boolean option's value: "--NAME" (1), "--no-NAME" (0), "--NAME=V" or "--NAME V" with V one
 * of cli.h's boolean words (the next argument only when it is one: run takes no operands). *i
 * steps over a value taken from the next argument. 0 when the value is not a boolean. */
static int flag_value(const char *name, const char *val, int negated, int argc, char **argv, int *i, int *out,
                      char *err)
{
    if (negated && val) {
        snprintf(err, SH_CONFIG_ERR, "--no-%s takes no value; try 'stillheart run --help'", name);
        return 0;
    }
    if (!val && !negated && *i + 1 < argc && sh_cli_parse_bool(argv[*i + 1], out)) {
        ++*i;
        return 1;
    }
    if (!val) {
        *out = !negated;
        return 1;
    }
    if (sh_cli_parse_bool(val, out)) return 1;
    snprintf(err, SH_CONFIG_ERR, "--%s: '%s' is not yes/no, true/false, on/off or 1/0", name, val);
    return 0;
}

/* Applies argv over cfg; run-only options go to ro. Returns 0 ok, 2 usage error, 1 help, 3
 * --version. Every option takes "--NAME VALUE" and "--NAME=VALUE"; booleans as flag_value. */
static int apply_cli(sh_config *cfg, run_opts *ro, int argc, char **argv, char *err)
{
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i];
        if (!strcmp(a, "-h")) return 1;
        if (strncmp(a, "--", 2)) {
            snprintf(err, SH_CONFIG_ERR, "'%s': not an option; try 'stillheart run --help'", a);
            return 2;
        }
        char name[64];
        const char *val = NULL;
        const char *eq = strchr(a + 2, '=');
        size_t n = eq ? (size_t)(eq - a - 2) : strlen(a + 2);
        if (n >= sizeof name) {
            snprintf(err, SH_CONFIG_ERR, "unknown option '%.80s'; try 'stillheart run --help'", a);
            return 2;
        }
        memcpy(name, a + 2, n);
        name[n] = 0;
        if (eq) val = eq + 1;
        if (!strcmp(name, "help")) return 1;
        if (!strcmp(name, "version")) return 3;
        const char *section, *key;
        int flag, on;
        int is_cfg = sh_config_option(name, &section, &key, &flag);
        int negated = 0;
        int run_flag = !strcmp(name, "stats") || !strcmp(name, "print-config") || !strcmp(name, "json") ||
                       !strcmp(name, "quiet");
        if (!is_cfg && !run_flag && !strncmp(name, "no-", 3)) {
            if (sh_config_option(name + 3, &section, &key, &flag) && flag) is_cfg = negated = 1;
            else if (strcmp(name + 3, "quiet") && (!strcmp(name + 3, "stats") || !strcmp(name + 3, "print-config") ||
                                                   !strcmp(name + 3, "json")))
                run_flag = negated = 1;
            if (negated) memmove(name, name + 3, strlen(name + 3) + 1);
        }
        if (!is_cfg && !run_flag && strcmp(name, "config") && strcmp(name, "max-frames") && strcmp(name, "trace") &&
            strcmp(name, "trace-points") && strcmp(name, "log-level")) {
            snprintf(err, SH_CONFIG_ERR, "unknown option '--%s'; try 'stillheart run --help'", name);
            return 2;
        }
        if (run_flag || (is_cfg && flag)) {
            if (!flag_value(name, val, negated, argc, argv, &i, &on, err)) return 2;
            if (is_cfg) val = on ? "1" : "0";
            else {
                if (!strcmp(name, "quiet")) { if (on) sh_log_set_level(SH_LOG_WARN); }
                else if (ro && !strcmp(name, "stats")) ro->stats = on;
                else if (ro && !strcmp(name, "json")) ro->json = on;
                else if (ro && !strcmp(name, "print-config")) ro->print_config = on;
                continue;
            }
        }
        if (!val) {
            if (i + 1 < argc) val = argv[++i];
            else { snprintf(err, SH_CONFIG_ERR, "option '--%s' needs a value; try 'stillheart run --help'", name); return 2; }
        }
        if (!strcmp(name, "log-level")) {
            if (sh_cli_set_log_level(val)) continue;
            snprintf(err, SH_CONFIG_ERR, "--log-level: '%s' is not error, warning, info or debug", val);
            return 2;
        }
        if (!strcmp(name, "config")) { if (ro) ro->config_path = val; continue; }
        if (!strcmp(name, "trace")) { if (ro) ro->trace_path = val; continue; }
        if (!strcmp(name, "trace-points")) { if (ro) ro->trace_points_path = val; continue; }
        if (!strcmp(name, "max-frames")) {
            char *end;
            long v = strtol(val, &end, 10);
            if (*end || end == val || v < 0 || v > 1000000000) {
                snprintf(err, SH_CONFIG_ERR, "command line: --max-frames: '%s' is not a whole number", val);
                return 2;
            }
            if (ro) ro->max_frames = (int)v;
            continue;
        }
        if (sh_config_set(cfg, section, key, val, "command line", 0, err) != SH_OK) return 2;
    }
    return 0;
}

/* Defaults, file, command line, checks. *unconfigured (when not NULL) is set when everything
 * parsed but no camera is named: the state of an unedited install. */
static sh_status load_config(sh_config *cfg, const char *path, int argc, char **argv, char *err, int *unconfigured)
{
    sh_config_default(cfg);
    if (path && sh_config_load_file(cfg, path, err) != SH_OK) return SH_EINVAL;
    if (apply_cli(cfg, NULL, argc, argv, err)) return SH_EINVAL;
    if (unconfigured) *unconfigured = sh_config_cameras(cfg) == 0;
    return sh_config_check(cfg, err);
}

/* SIGHUP's config (sh_daemon_load_fn): the file and the command line again. */
typedef struct {
    const run_opts *ro;
    int argc;
    char **argv;
} reload_ctx;

static sh_status load_again(void *ctx, sh_config *fresh, char *err)
{
    const reload_ctx *c = ctx;
    return load_config(fresh, c->ro->config_path, c->argc, c->argv, err, NULL);
}

int cmd_run(int argc, char **argv)
{
    char err[SH_CONFIG_ERR];
    sh_config cfg;
    run_opts ro = {0};
    /* Refusals of the command line and the config are worded as every command's
     * ("stillheart run: ..."); once the daemon runs, its lines are log lines (docs/daemon.md). */
    sh_log_setup(SH_LOG_TOOL, "stillheart run", SH_LOG_INFO);
    catch_signals();
    sh_config_default(&cfg);
    int a = apply_cli(&cfg, &ro, argc, argv, err); /* first pass: --config and run-only options */
    if (a == 1) { usage(stdout); return 0; }
    if (a == 3) { printf("stillheart run %s\n", SH_VERSION); return 0; }
    if (a == 2) { sh_log_error("%s", err); return 2; }
    if (ro.json && !ro.stats) { sh_log_error("--json goes with --stats; try 'stillheart run --help'"); return 2; }
    int unconfigured = 0;
    if (load_config(&cfg, ro.config_path, argc, argv, err, &unconfigured) != SH_OK) {
        if (unconfigured) { /* an unedited install: one line, and an exit status the unit does not restart on */
            sh_log_error("not configured: no camera named (%s%s[camera0] spec: v4l2:/dev/videoN, libcamera:NAME, "
                         "y4m:FILE or rec:DIR)", ro.config_path ? ro.config_path : "", ro.config_path ? ": " : "");
            return RUN_EXIT_NOT_CONFIGURED;
        }
        sh_log_error("%s", err);
        return 2;
    }
    if (ro.print_config) { sh_config_write(&cfg, stdout); return 0; }

#ifdef __GLIBC__
    /* Models (about 2 MB each at 1080p), frames and grids get mappings of their own and go back
     * to the kernel when freed. Left to itself glibc raises its mmap threshold at the first such
     * free and serves later blocks from the heaps of whichever thread allocates (the model
     * builder, the processing thread), where a day of model rebuilds fragments and creeps. */
    mallopt(M_MMAP_THRESHOLD, 256 * 1024);
#endif
    reload_ctx rctx = {&ro, argc, argv};
    sh_daemon_options dopt = {.max_frames = ro.max_frames, .trace_path = ro.trace_path,
                              .trace_points_path = ro.trace_points_path, .load = load_again, .load_ctx = &rctx};
    sh_daemon *d = NULL;
    int rc = 1;
    sh_log_setup(SH_LOG_DAEMON, "stillheart run", sh_log_get_level());
    sh_log_set_thread("main");
    sh_status cst = sh_daemon_create(&cfg, &dopt, &d);
    if (cst != SH_OK) { /* the exit-code table (usage): 2 for input no restart mends */
        fprintf(stderr, "stillheart run: %s\n", sh_error_message());
        return cst == SH_EINVAL ? 2 : 1;
    }

    if (sh_daemon_start(d) != SH_OK) {
        fprintf(stderr, "stillheart run: %s\n", sh_error_message());
    } else {
        /* a failure here (a reload that could not bring the cameras back) is logged; non-zero:
         * systemd's Restart=on-failure starts the service again */
        sh_status st = sh_daemon_run(d, &sig);
        rc = st == SH_OK ? 0 : st == SH_EFORMAT ? 2 : 1; /* 2: RestartPreventExitStatus */
        if (st == SH_EFORMAT) sh_log_error("%s: exit status 2", sh_error_message());
        if (ro.stats && ro.json) {
            sh_daemon_stats_json(d, stdout);
        } else if (ro.stats || sh_log_get_level() >= SH_LOG_INFO) {
            char line[512];
            sh_daemon_stats(d, line, sizeof line);
            /* one stream for the summary whether asked for or not (the log is on stderr) */
            fprintf(stdout, "%s\n", line);
        }
    }
    if (sh_daemon_destroy(d) != SH_OK) rc = 1;
    return rc;
}
