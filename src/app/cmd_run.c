/* stillheart run: the daemon. A source thread replays frames into a one-slot mailbox (the oldest
 * frame is dropped and counted when processing falls behind, never queued); the processing
 * thread tracks the markers (detection in the Kalman tracker's windows, or a points file in test
 * mode), matches them to the reference, takes the model for that marker set (built on a helper
 * thread), gates, warps and publishes to the shared-memory display buffer with status, reason,
 * markers used and residual.
 *
 * Here: options, the loop, signals, systemd and statistics. Opening, closing and, on SIGHUP,
 * swapping the pipeline's pieces (source, processing, display, record, control socket) is in
 * run_pipeline.c; the source thread and the mailbox in run_source.c; one frame's processing in
 * run_proc.c (run_track.c: tracker and selection, run_model.c: models and residual). */
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
#include "../daemon/run_pipeline.h"
#include "stillheart/config.h"
#include "stillheart/detect.h"
#include "stillheart/display.h"
#include "stillheart/log.h"
#include "stillheart/notify.h"
#include "stillheart/points.h"
#include "stillheart/warp.h"
#include "stillheart/y4m.h"

#define LAT_CAP (1 << 20)
/* LSB's "program is not configured" (systemd shows 6/NOTCONFIGURED); the unit's
 * RestartPreventExitStatus names it, and 2 (a config refused), beside it. */
#define RUN_EXIT_NOT_CONFIGURED 6

/* One frame to the display. The writer makes its segment anew when it finds it shrunk, unlinked
 * or replaced under it (display.h); that is logged at most once a second (someone meddling could
 * otherwise fill the log), as is a publish that fails (the name taken by another user). */
static void display_publish(sh_display_writer *d, const sh_image *img, const sh_display_frame_info *info)
{
    static sh_log_limit failed = {.period_s = 1}, remade_lim = {.period_s = 1};
    static uint64_t remade_logged;
    if (sh_display_writer_publish(d, img, info) != SH_OK) {
        sh_log_limited(&failed, SH_LOG_ERROR, "publish: %s", sh_error_message());
        return;
    }
    uint64_t remade = sh_display_writer_remade(d);
    if (remade != remade_logged) {
        sh_log_limited(&remade_lim, SH_LOG_WARN, "display: the segment was shrunk, changed, unlinked or replaced "
                       "under the daemon and made anew (generation %016llx; %llu times so far)",
                       (unsigned long long)sh_display_writer_generation(d), (unsigned long long)remade);
        remade_logged = remade;
    }
}

/* ---- signals ---- */
static volatile sig_atomic_t sig_stop, sig_hup, sig_usr1;
static void on_signal(int s)
{
    if (s == SIGHUP) sig_hup = 1;
    else if (s == SIGUSR1) sig_usr1 = 1;
    else sig_stop = 1;
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
        "  --stats            print a summary line at exit (fps, latency, drops, RSS)\n"
        "  --trace FILE       one CSV line per published frame: index, status, markers, residual, reason,\n"
        "                     stage CPU times (markers, model, warp) and latency in ms\n"
        "  --trace-points FILE  the markers each warped frame's map was made from, as a points file\n"
        "                     (frame,id,x,y: the output camera's pixels; raw frames have no rows)\n"
        "  --print-config     print the resulting config as INI and exit\n"
        "  --quiet            errors and warnings only\n"
        "signals: SIGTERM/SIGINT stop (segment marked closed). SIGHUP reloads the config file and\n"
        "applies every key in place: changed cameras are closed and the new ones opened, changed\n"
        "processing starts again with a new reference, the display segment is kept unless its name,\n"
        "size, format or slots change; a config that cannot run is refused and the running one kept\n"
        "(the previous cameras reopened). SIGUSR1 takes a new reference frame (so does `stillheart ctl\n"
        "reference` on the [run] control socket).\n"
        "exit status: 0 stopped by a signal or --max-frames, 1 a failure at run time (systemd restarts\n"
        "the service), 2 a bad config or command line, 6 not configured: no camera named.\n");
}

typedef struct {
    const char *config_path;
    int max_frames, stats, print_config;
    const char *trace_path, *trace_points_path;
} run_opts;

/* Applies argv over cfg; run-only options go to ro. Returns 0 ok, 2 usage error, 1 help. */
static int apply_cli(sh_config *cfg, run_opts *ro, int argc, char **argv, char *err)
{
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i];
        if (strncmp(a, "--", 2)) {
            snprintf(err, SH_CONFIG_ERR, "command line: '%s': not an option", a);
            return 2;
        }
        char name[64];
        const char *val = NULL;
        const char *eq = strchr(a + 2, '=');
        size_t n = eq ? (size_t)(eq - a - 2) : strlen(a + 2);
        if (n >= sizeof name) { snprintf(err, SH_CONFIG_ERR, "command line: '%s': unknown option", a); return 2; }
        memcpy(name, a + 2, n);
        name[n] = 0;
        if (eq) val = eq + 1;
        if (!strcmp(name, "help")) return 1;
        if (!strcmp(name, "quiet")) { sh_log_set_level(SH_LOG_WARN); continue; }
        if (!strcmp(name, "stats")) { if (ro) ro->stats = 1; continue; }
        if (!strcmp(name, "print-config")) { if (ro) ro->print_config = 1; continue; }
        const char *section, *key;
        int flag;
        int is_cfg = sh_config_option(name, &section, &key, &flag);
        int negated = 0;
        if (!is_cfg && !strncmp(name, "no-", 3) && sh_config_option(name + 3, &section, &key, &flag) && flag)
            is_cfg = negated = 1;
        if (!is_cfg && strcmp(name, "config") && strcmp(name, "max-frames") && strcmp(name, "trace") &&
            strcmp(name, "trace-points")) {
            snprintf(err, SH_CONFIG_ERR, "command line: --%s: unknown option (stillheart run --help)", name);
            return 2;
        }
        if (!val) {
            if (flag) val = negated ? "0" : "1";
            else if (i + 1 < argc) val = argv[++i];
            else { snprintf(err, SH_CONFIG_ERR, "command line: --%s needs a value", name); return 2; }
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

static int cmp_float(const void *a, const void *b)
{
    float x = *(const float *)a, y = *(const float *)b;
    return (x > y) - (x < y);
}

/* The output camera's frame period, ns (25 fps when the source does not say). */
static int64_t frame_period(run_source *src)
{
    return run_source_fps(src) > 0 ? (int64_t)(1e9 / run_source_fps(src)) : 40000000;
}

static long rss_kb(void)
{
    FILE *f = fopen("/proc/self/statm", "r");
    long pages = 0, res = 0;
    if (f) {
        if (fscanf(f, "%ld %ld", &pages, &res) != 2) res = 0;
        fclose(f);
    }
    return res * (sysconf(_SC_PAGESIZE) / 1024);
}

/* SIGHUP: the config file and the command line again, applied to every piece of the pipeline.
 * systemd hears RELOADING=1 and READY=1 around it, and a watchdog ping on either side: opening
 * cameras can take a second. Returns -1 when the pipeline cannot run on (the previous cameras
 * did not come back: the daemon exits non-zero and systemd restarts it), 1 when the cameras were
 * closed and opened (the new ones or the previous ones again), else 0. */
static int reload(run_pipeline *pl, const run_opts *ro, int argc, char **argv, uint64_t wd_usec)
{
    char err[SH_CONFIG_ERR], what[640];
    sh_notifyf("RELOADING=1\nMONOTONIC_USEC=%llu\nSTATUS=reloading the config", (unsigned long long)(sh_monotonic_ns() / 1000));
    if (wd_usec) sh_notify("WATCHDOG=1");
    sh_config fresh;
    run_reload r = RUN_RELOAD_REFUSED;
    int cams = 0;
    if (load_config(&fresh, ro->config_path, argc, argv, err, NULL) != SH_OK) {
        snprintf(what, sizeof what, "reload refused, keeping the running config: %s", err);
    } else {
        cams = (sh_config_changes(&fresh, &pl->cfg) & SH_CONFIG_SOURCE) != 0;
        r = run_pipeline_reload(pl, &fresh, what, sizeof what);
    }
    if (r == RUN_RELOAD_FATAL) {
        sh_log_error("%s; exiting for systemd to restart the service", what);
        sh_notifyf("STATUS=%s", what);
        return -1;
    }
    if (r == RUN_RELOAD_REFUSED) sh_log_error("%s", what);
    else if (what[0]) sh_log_info("config reloaded: %s", what);
    else sh_log_info("config reloaded (gating)");
    sh_notifyf("READY=1\nSTATUS=%s", r == RUN_RELOAD_APPLIED ? "config reloaded" : what);
    if (wd_usec) sh_notify("WATCHDOG=1");
    return cams;
}

int cmd_run(int argc, char **argv)
{
    char err[SH_CONFIG_ERR];
    sh_config cfg;
    run_opts ro = {0};
    /* Refusals of the command line and the config are worded as every command's
     * ("stillheart run: ..."); once the daemon runs, its lines are log lines (docs/daemon.md). */
    sh_log_setup(SH_LOG_TOOL, "stillheart run", SH_LOG_INFO);
    sh_config_default(&cfg);
    int a = apply_cli(&cfg, &ro, argc, argv, err); /* first pass: --config and run-only options */
    if (a == 1) { usage(stdout); return 0; }
    if (a == 2) { sh_log_error("%s", err); return 2; }
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
    int rc = 1, fatal = 0;
    run_pipeline pl;
    memset(&pl, 0, sizeof pl);
    FILE *trace = NULL, *trace_points = NULL;
    float *lat = malloc(sizeof(float) * LAT_CAP);
    if (!lat) { fprintf(stderr, "stillheart run: out of memory\n"); goto done; }

    sh_log_setup(SH_LOG_DAEMON, "stillheart run", sh_log_get_level());
    sh_log_set_thread("main");
    if (run_pipeline_open(&pl, &cfg) != SH_OK) {
        fprintf(stderr, "stillheart run: %s\n", sh_error_message());
        goto done;
    }
    if (ro.trace_path && !(trace = fopen(ro.trace_path, "w"))) {
        fprintf(stderr, "stillheart run: --trace: %s: %s\n", ro.trace_path, strerror(errno));
        goto done;
    }
    if (trace) fprintf(trace, "index,status,markers,residual,reason,markers_ms,model_ms,warp_ms,latency_ms\n");
    if (ro.trace_points_path && !(trace_points = fopen(ro.trace_points_path, "w"))) {
        fprintf(stderr, "stillheart run: --trace-points: %s: %s\n", ro.trace_points_path, strerror(errno));
        goto done;
    }
    if (trace_points) fprintf(trace_points, "frame,id,x,y\n");

    struct sigaction sa;
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = on_signal;
    sigemptyset(&sa.sa_mask);
    sigaction(SIGTERM, &sa, NULL);
    sigaction(SIGINT, &sa, NULL);
    sigaction(SIGHUP, &sa, NULL);
    sigaction(SIGUSR1, &sa, NULL);
    signal(SIGPIPE, SIG_IGN);

    if (run_pipeline_start(&pl) != SH_OK) { fprintf(stderr, "stillheart run: %s\n", sh_error_message()); goto done; }
    sh_log_info("source %s %dx%d %s %.3f fps (%s%s), sink %s, method %s, %s",
         cfg.camera[0].spec, pl.hdr.width, pl.hdr.height, sh_pixfmt_name(pl.hdr.format), run_source_fps(pl.src),
         cfg.realtime ? "real time" : "as fast as possible", cfg.loop ? ", looping" : "", cfg.sink,
         cfg.method_name, cfg.points[0] ? "markers from the points file (test mode)" : "markers detected");
    sh_notify("READY=1\nSTATUS=started, waiting for the reference frame");

    uint64_t wd_usec = cfg.watchdog ? sh_notify_watchdog_usec() : 0;
    int64_t last_ping = sh_monotonic_ns(), last_status = sh_monotonic_ns();
    uint64_t published = 0, published_at_ping = 0, published_at_status = 0, raw_count = 0, degraded_count = 0;
    long rss_start = 0, rss_max = 0, rss_1min = 0; /* warm-up (detector, caches) is over after a minute */
    int64_t t_start = sh_monotonic_ns();
    size_t nlat = 0;
    uint32_t last_status_shown = 99;
    char last_reason[44] = "";
    char status_line[160] = "starting: no frame yet";
    static const char *names[] = {"raw", "stabilized", "degraded"};
    /* The output camera lost: a black raw frame per frame period tells the display, and the
     * watchdog is kept alive while every thread still goes round (a restart cannot bring a
     * camera back; source.h is reopening it). */
    int64_t period = frame_period(pl.src);
    int lost = 0;
    sh_log_limit wd_held = {0}; /* logged once until the pings resume */
    int64_t lost_since = 0, last_black = 0;
    uint64_t black_count = 0;
    char lost_text[96] = "", stale[160] = "";
    sh_display_frame_info shown_info; /* the last published frame's, for STATUS */
    memset(&shown_info, 0, sizeof shown_info);

    while (!sig_stop) {
        if (sig_hup) {
            sig_hup = 0;
            int cams = reload(&pl, &ro, argc, argv, wd_usec);
            if (cams < 0) { fatal = 1; break; }
            wd_usec = pl.cfg.watchdog ? sh_notify_watchdog_usec() : 0;
            last_ping = sh_monotonic_ns();
            published_at_ping = published;
            if (cams) { /* a new stream: its rate, and nothing lost yet; its first frame is logged */
                period = frame_period(pl.src);
                lost = 0;
                sh_log_limit_clear(&wd_held);
                last_status_shown = 99;
            }
        }
        int refs = pl.ctl ? run_ctl_references(pl.ctl) : 0;
        if (sig_usr1 || refs) {
            sh_log_info("new reference requested (%s)", sig_usr1 ? "SIGUSR1" : "control socket");
            sig_usr1 = 0;
            run_proc_request_reference(pl.proc);
        }
        int wait_ms = lost ? (int)(period / 1000000) : 100;
        const run_frame *s = run_source_take(pl.src, wait_ms < 1 ? 1 : wait_ms > 100 ? 100 : wait_ms);
        if (!s) {
            if (run_source_ended(pl.src)) break;
            int why = run_source_output_lost(pl.src, lost_text, sizeof lost_text);
            int64_t now = sh_monotonic_ns();
            if (why && !lost) {
                lost = 1;
                lost_since = now;
                last_black = 0;
                last_status_shown = 99; /* the first camera frame back is logged */
                sh_log_warn("%s: black raw frames shown until it returns", lost_text);
            }
            if (why && now - last_black >= period) {
                memset(&shown_info, 0, sizeof shown_info);
                shown_info.status = SH_DISPLAY_RAW;
                shown_info.residual_px = -1; /* capture_ns 0: no camera frame */
                snprintf(shown_info.reason, sizeof shown_info.reason, "%s",
                         why == 1 ? "output camera lost" : "no sets with the output camera");
                if (pl.disp) display_publish(pl.disp, &pl.black, &shown_info);
                if (pl.rec && run_record_write(pl.rec, &pl.black) != SH_OK) { /* what was shown, PNGs numbered as the display */
                    sh_log_error("[sink] record: %s; recording stopped", sh_error_message());
                    run_record_close(pl.rec);
                    pl.rec = NULL;
                }
                black_count++;
                last_black = now;
                if (snprintf(status_line, sizeof status_line, "%s: black raw frames, %llu published, %llu dropped",
                             lost_text, (unsigned long long)published, (unsigned long long)run_pipeline_dropped(&pl)) < 0)
                    status_line[0] = 0;
            }
        } else {
            if (lost) {
                sh_log_info("the output camera's frames are back after %.1f s (%llu black frames shown)",
                     (double)(sh_monotonic_ns() - lost_since) / 1e9, (unsigned long long)black_count);
                lost = 0;
            }
            sh_display_frame_info info;
            memset(&info, 0, sizeof info);
            info.capture_ns = s->avail_ns;
            const sh_image *shown = run_proc_frame(pl.proc, &s->img, s->cam, s->index, s->epoch, &info);
            uint32_t status = info.status;
            if (status == SH_DISPLAY_RAW) raw_count++;
            if (status == SH_DISPLAY_DEGRADED) degraded_count++;
            if (status != last_status_shown ||
                (status != SH_DISPLAY_STABILIZED && strncmp(last_reason, info.reason, 12))) {
                sh_log_msg(status == SH_DISPLAY_RAW && published ? SH_LOG_WARN : SH_LOG_INFO, "frame %d: %s%s%s", s->index,
                     names[status], info.reason[0] ? ": " : "", info.reason);
                last_status_shown = status;
                memcpy(last_reason, info.reason, sizeof last_reason);
            }
            if (pl.disp) {
                info.publish_ns = sh_monotonic_ns();
                display_publish(pl.disp, shown, &info);
            }
            if (pl.rec && run_record_write(pl.rec, shown) != SH_OK) {
                sh_log_error("[sink] record: %s; recording stopped", sh_error_message());
                run_record_close(pl.rec);
                pl.rec = NULL;
            }
            int64_t done_ns = sh_monotonic_ns();
            if (nlat < LAT_CAP) lat[nlat++] = (float)((double)(done_ns - s->avail_ns) / 1e6);
            published++;
            if (published == 30) rss_start = rss_kb();
            if ((published & 63) == 0) { long r = rss_kb(); if (r > rss_max) rss_max = r; }
            if (!rss_1min && done_ns - t_start >= 60000000000LL) rss_1min = rss_kb();
            snprintf(status_line, sizeof status_line,
                     "frame %d: %s%s%s, %u markers, residual %.2f px, %llu published, %llu dropped", s->index,
                     names[status], info.reason[0] ? ": " : "", info.reason, info.markers_used,
                     (double)info.residual_px, (unsigned long long)published,
                     (unsigned long long)run_pipeline_dropped(&pl));
            if (trace) {
                double tm, tmod, tw;
                run_proc_times(pl.proc, &tm, &tmod, &tw);
                fprintf(trace, "%d,%s,%u,%.3f,\"%s\",%.3f,%.3f,%.3f,%.3f\n", s->index, names[status], info.markers_used,
                        (double)info.residual_px, info.reason, tm, tmod, tw, (double)(done_ns - s->avail_ns) / 1e6);
            }
            if (trace_points) {
                const int *ids;
                const double *xy;
                int n = run_proc_markers(pl.proc, &ids, &xy);
                for (int k = 0; k < n; k++)
                    fprintf(trace_points, "%d,%d,%.4f,%.4f\n", s->index, ids[k], xy[2 * k], xy[2 * k + 1]);
            }
            shown_info = info;
        }
        if (pl.ctl) run_ctl_set_status(pl.ctl, status_line);
        /* systemd: STATUS each second; WATCHDOG while frames progress, or while the output camera
         * is lost and every thread still goes round. A hung processing loop sends neither. */
        int64_t now = sh_monotonic_ns();
        if ((published || black_count) && now - last_status >= 1000000000) {
            double fps = (double)(published - published_at_status) * 1e9 / (double)(now - last_status);
            char cams[128];
            run_source_online(pl.src, cams, sizeof cams);
            sh_notifyf("STATUS=%s%s%.1f fps, %u markers, %s%s%s, %llu dropped, %s", lost ? lost_text : "",
                       lost ? ": " : "", fps, shown_info.markers_used, names[shown_info.status],
                       shown_info.reason[0] ? " " : "", shown_info.reason,
                       (unsigned long long)run_pipeline_dropped(&pl), cams);
            last_status = now;
            published_at_status = published;
        }
        if (wd_usec && now - last_ping >= (int64_t)wd_usec * 500) {
            int progress = published > published_at_ping;
            int alive = !progress && lost && run_source_alive(pl.src, (int64_t)wd_usec * 500, stale, sizeof stale);
            if (progress || alive) {
                sh_notify("WATCHDOG=1");
                last_ping = now;
                published_at_ping = published;
                sh_log_limit_clear(&wd_held);
            } else if (lost) {
                sh_log_limited(&wd_held, SH_LOG_ERROR, "watchdog held back: %s", stale);
            }
        }
        if (s && ro.max_frames && published >= (uint64_t)ro.max_frames) break;
    }
    sh_notify("STOPPING=1");
    sig_stop = 1;
    rc = fatal; /* non-zero: systemd's Restart=on-failure starts the service again */
    if (ro.stats || sh_log_get_level() >= SH_LOG_INFO) {
        qsort(lat, nlat, sizeof *lat, cmp_float);
        double med = nlat ? lat[nlat / 2] : 0, p99 = nlat ? lat[(size_t)((double)(nlat - 1) * 0.99)] : 0,
               mx = nlat ? lat[nlat - 1] : 0;
        long r = rss_kb();
        if (r > rss_max) rss_max = r;
        fprintf(ro.stats ? stdout : stderr,
                "stats: %llu published (%llu raw, %llu degraded), %llu dropped, latency ms median %.2f "
                "p99 %.2f max %.2f, RSS kB start %ld at 1 min %ld max %ld end %ld, %d models built, "
                "%llu black frames (output camera lost)\n",
                (unsigned long long)published, (unsigned long long)raw_count,
                (unsigned long long)degraded_count, (unsigned long long)run_pipeline_dropped(&pl), med, p99, mx,
                rss_start, rss_1min, rss_max, r, run_pipeline_builds(&pl), (unsigned long long)black_count);
    }
done:
    sig_stop = 1;
    if (run_pipeline_close(&pl) != SH_OK) rc = 1;
    if (trace && fclose(trace)) { sh_log_error("--trace: %s", strerror(errno)); rc = 1; }
    if (trace_points && fclose(trace_points)) { sh_log_error("--trace-points: %s", strerror(errno)); rc = 1; }
    free(lat);
    return rc;
}
