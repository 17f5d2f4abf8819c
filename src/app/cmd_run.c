/* stillheart run: the daemon. A source thread replays frames into a one-slot mailbox (the oldest
 * frame is dropped and counted when processing falls behind, never queued); the processing
 * thread tracks the markers (detection in the Kalman tracker's windows, or a points file in test
 * mode), matches them to the reference, takes the model for that marker set (built on a helper
 * thread), gates, warps and publishes to the shared-memory display buffer with status, reason,
 * markers used and residual.
 *
 * Here: options, start-up, signals, the control socket, sinks, systemd and statistics. The
 * source thread and the mailbox are in run_source.c; one frame's processing in run_proc.c
 * (run_track.c: tracker and selection, run_model.c: models and residual). */
#include <errno.h>
#ifdef __GLIBC__
#include <malloc.h>
#endif
#include <math.h>
#include <pthread.h>
#include <signal.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "app.h"
#include "run.h"
#include "run_proc.h"
#include "run_source.h"
#include "stillheart/config.h"
#include "stillheart/detect.h"
#include "stillheart/display.h"
#include "stillheart/notify.h"
#include "stillheart/points.h"
#include "stillheart/warp.h"
#include "stillheart/y4m.h"

#define LAT_CAP (1 << 20)

/* ---- logging: "-- LEVEL [monotonic thread] -- message", as ustreamer does ---- */
static int64_t mono_ns(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (int64_t)ts.tv_sec * 1000000000 + ts.tv_nsec;
}

static int log_quiet;
static pthread_mutex_t log_mu = PTHREAD_MUTEX_INITIALIZER;
static __attribute__((format(printf, 3, 4))) void logm(const char *level, const char *thread,
                                                        const char *fmt, ...)
{
    if (log_quiet && strcmp(level, "ERROR") && strcmp(level, "WARN"))
        return;
    char msg[768];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    pthread_mutex_lock(&log_mu);
    fprintf(stderr, "-- %-5s [%.3f %-7s] -- %s\n", level, (double)mono_ns() / 1e9, thread, msg);
    pthread_mutex_unlock(&log_mu);
}
/* A repeating error is logged once until `ok` clears its guard. */
#define LOG_ONCE(guard, ...) do { if (!(guard)) { logm(__VA_ARGS__); (guard) = 1; } } while (0)

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
        "  --print-config     print the resulting config as INI and exit\n"
        "  --quiet            errors and warnings only\n"
        "signals: SIGTERM/SIGINT stop (segment marked closed), SIGHUP reloads the config file,\n"
        "SIGUSR1 takes a new reference frame.\n");
}

typedef struct {
    const char *config_path;
    int max_frames, stats, print_config;
    const char *trace_path;
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
        if (!strcmp(name, "quiet")) { log_quiet = 1; continue; }
        if (!strcmp(name, "stats")) { if (ro) ro->stats = 1; continue; }
        if (!strcmp(name, "print-config")) { if (ro) ro->print_config = 1; continue; }
        const char *section, *key;
        int flag;
        int is_cfg = sh_config_option(name, &section, &key, &flag);
        int negated = 0;
        if (!is_cfg && !strncmp(name, "no-", 3) && sh_config_option(name + 3, &section, &key, &flag) && flag)
            is_cfg = negated = 1;
        if (!is_cfg && strcmp(name, "config") && strcmp(name, "max-frames") && strcmp(name, "trace")) {
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

static sh_status load_config(sh_config *cfg, const char *path, int argc, char **argv, char *err)
{
    sh_config_default(cfg);
    if (path && sh_config_load_file(cfg, path, err) != SH_OK) return SH_EINVAL;
    if (apply_cli(cfg, NULL, argc, argv, err)) return SH_EINVAL;
    return sh_config_check(cfg, err);
}

static int cmp_float(const void *a, const void *b)
{
    float x = *(const float *)a, y = *(const float *)b;
    return (x > y) - (x < y);
}

/* The frame shown while the output camera is lost: black in the display's format and range. */
static sh_status black_frame(const sh_y4m_header *hdr, sh_image *img)
{
    sh_status st = sh_image_create(img, hdr->format, hdr->width, hdr->height);
    if (st != SH_OK) return st;
    uint8_t luma = strstr(hdr->extra, "XCOLORRANGE=FULL") || hdr->format == SH_PIX_RGB24 ? 0 : 16;
    for (int p = 0; p < img->num_planes; p++)
        for (int y = 0; y < img->plane[p].height; y++)
            memset(img->plane[p].data + (size_t)y * img->plane[p].stride, p ? 128 : luma,
                   (size_t)img->plane[p].width * (size_t)sh_pixfmt_channels(hdr->format));
    return SH_OK;
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

int cmd_run(int argc, char **argv)
{
    char err[SH_CONFIG_ERR];
    sh_config cfg;
    run_opts ro = {0};
    sh_config_default(&cfg);
    int a = apply_cli(&cfg, &ro, argc, argv, err); /* first pass: --config and run-only options */
    if (a == 1) { usage(stdout); return 0; }
    if (a == 2) { fprintf(stderr, "stillheart run: %s\n", err); return 2; }
    if (load_config(&cfg, ro.config_path, argc, argv, err) != SH_OK) {
        fprintf(stderr, "stillheart run: %s\n", err);
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
    int rc = 1;
    run_source *src = NULL;
    run_proc *proc = NULL;
    run_ctl *ctl = NULL;
    sh_display_writer *disp = NULL;
    run_record *rec = NULL;
    FILE *trace = NULL;
    sh_image black;
    memset(&black, 0, sizeof black);
    float *lat = malloc(sizeof(float) * LAT_CAP);
    if (!lat) { fprintf(stderr, "stillheart run: out of memory\n"); goto done; }

    if (run_source_open(&cfg, logm, &src) != SH_OK) {
        fprintf(stderr, "stillheart run: %s\n", sh_error_message());
        goto done;
    }
    const sh_y4m_header *hdr = run_source_header(src);
    sh_y4m_header hcopy = *hdr;
    if (run_proc_create(&cfg, hdr, run_source_fps(src), run_source_cameras(src), logm, &proc) != SH_OK) {
        fprintf(stderr, "stillheart run: %s\n", sh_error_message());
        goto done;
    }
    const char *shm_name = NULL;
    if (!strncmp(cfg.sink, "shm:", 4)) {
        shm_name = cfg.sink + 4;
        if (sh_display_writer_create(shm_name, hdr->format, hdr->width, hdr->height, cfg.slots,
                                     strstr(hdr->extra, "XCOLORRANGE=FULL") != NULL,
                                     cfg.group[0] ? cfg.group : NULL, &disp) != SH_OK) {
            fprintf(stderr, "stillheart run: [sink] display: %s\n", sh_error_message());
            goto done;
        }
    }
    if (black_frame(hdr, &black) != SH_OK) {
        fprintf(stderr, "stillheart run: %s\n", sh_error_message());
        goto done;
    }
    if (cfg.record[0] && run_record_open(cfg.record, &hcopy, &rec) != SH_OK) {
        fprintf(stderr, "stillheart run: [sink] record: %s\n", sh_error_message());
        goto done;
    }
    if (ro.trace_path && !(trace = fopen(ro.trace_path, "w"))) {
        fprintf(stderr, "stillheart run: --trace: %s: %s\n", ro.trace_path, strerror(errno));
        goto done;
    }
    if (trace) fprintf(trace, "index,status,markers,residual,reason,markers_ms,model_ms,warp_ms,latency_ms\n");
    if (cfg.control[0] && run_ctl_open(cfg.control, &ctl) != SH_OK) {
        fprintf(stderr, "stillheart run: [run] control: %s\n", sh_error_message());
        goto done;
    }

    struct sigaction sa;
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = on_signal;
    sigemptyset(&sa.sa_mask);
    sigaction(SIGTERM, &sa, NULL);
    sigaction(SIGINT, &sa, NULL);
    sigaction(SIGHUP, &sa, NULL);
    sigaction(SIGUSR1, &sa, NULL);
    signal(SIGPIPE, SIG_IGN);

    if (run_source_start(src) != SH_OK) { fprintf(stderr, "stillheart run: %s\n", sh_error_message()); goto done; }
    logm("INFO", "main", "source %s %dx%d %s %.3f fps (%s%s), sink %s, method %s, %s",
         cfg.source, hdr->width, hdr->height, sh_pixfmt_name(hdr->format), run_source_fps(src),
         cfg.realtime ? "real time" : "as fast as possible", cfg.loop ? ", looping" : "", cfg.sink,
         cfg.method_name, cfg.points[0] ? "markers from the points file (test mode)" : "markers detected");
    sh_notify("READY=1\nSTATUS=started, waiting for the reference frame");

    uint64_t wd_usec = cfg.watchdog ? sh_notify_watchdog_usec() : 0;
    int64_t last_ping = mono_ns(), last_status = mono_ns();
    uint64_t published = 0, published_at_ping = 0, published_at_status = 0, raw_count = 0, degraded_count = 0;
    long rss_start = 0, rss_max = 0, rss_1min = 0; /* warm-up (detector, caches) is over after a minute */
    int64_t t_start = mono_ns();
    size_t nlat = 0;
    uint32_t last_status_shown = 99;
    char last_reason[44] = "";
    char status_line[160] = "starting: no frame yet";
    static const char *names[] = {"raw", "stabilized", "degraded"};
    /* The output camera lost: a black raw frame per frame period tells the display, and the
     * watchdog is kept alive while every thread still goes round (a restart cannot bring a
     * camera back; source.h is reopening it). */
    int64_t period = run_source_fps(src) > 0 ? (int64_t)(1e9 / run_source_fps(src)) : 40000000;
    int lost = 0, wd_held = 0;
    int64_t lost_since = 0, last_black = 0;
    uint64_t black_count = 0;
    char lost_text[96] = "", stale[160] = "";
    sh_display_frame_info shown_info; /* the last published frame's, for STATUS */
    memset(&shown_info, 0, sizeof shown_info);

    while (!sig_stop) {
        if (sig_hup) {
            sig_hup = 0;
            sh_config fresh;
            if (load_config(&fresh, ro.config_path, argc, argv, err) != SH_OK) {
                logm("ERROR", "main", "reload refused, keeping the running config: %s", err);
            } else {
                /* live: gating; the rest needs a restart */
                int restart = run_source_config_changed(&fresh, &cfg) || strcmp(fresh.sink, cfg.sink) ||
                              strcmp(fresh.method_name, cfg.method_name) || fresh.threads != cfg.threads ||
                              strcmp(fresh.points, cfg.points) || fresh.slots != cfg.slots ||
                              memcmp(&fresh.method, &cfg.method, sizeof cfg.method) ||
                              strcmp(fresh.family, cfg.family) || strcmp(fresh.record, cfg.record);
                cfg.min_markers = fresh.min_markers;
                cfg.max_residual_px = fresh.max_residual_px;
                cfg.max_sigma_px = fresh.max_sigma_px;
                cfg.dropout_ms = fresh.dropout_ms;
                run_proc_set_gating(proc, &cfg);
                restart |= memcmp(fresh.ids, cfg.ids, sizeof cfg.ids) || strcmp(fresh.control, cfg.control);
                logm("INFO", "main", "config reloaded (gating)%s",
                     restart ? "; source/sink/method/ids/threads/control changes take effect at restart" : "");
            }
        }
        int refs = ctl ? run_ctl_poll(ctl, status_line) : 0;
        if (sig_usr1 || refs) {
            logm("INFO", "main", "new reference requested (%s)", sig_usr1 ? "SIGUSR1" : "control socket");
            sig_usr1 = 0;
            run_proc_request_reference(proc);
        }
        int wait_ms = lost ? (int)(period / 1000000) : 100;
        const run_frame *s = run_source_take(src, wait_ms < 1 ? 1 : wait_ms > 100 ? 100 : wait_ms);
        if (!s) {
            if (run_source_ended(src)) break;
            int why = run_source_output_lost(src, lost_text, sizeof lost_text);
            int64_t now = mono_ns();
            if (why && !lost) {
                lost = 1;
                lost_since = now;
                last_black = 0;
                last_status_shown = 99; /* the first camera frame back is logged */
                logm("WARN", "main", "%s: black raw frames shown until it returns", lost_text);
            }
            if (why && now - last_black >= period) {
                memset(&shown_info, 0, sizeof shown_info);
                shown_info.status = SH_DISPLAY_RAW;
                shown_info.residual_px = -1; /* capture_ns 0: no camera frame */
                snprintf(shown_info.reason, sizeof shown_info.reason, "%s",
                         why == 1 ? "output camera lost" : "no sets with the output camera");
                if (disp && sh_display_writer_publish(disp, &black, &shown_info) != SH_OK)
                    logm("ERROR", "main", "publish: %s", sh_error_message());
                if (rec && run_record_write(rec, &black) != SH_OK) { /* what was shown, PNGs numbered as the display */
                    logm("ERROR", "main", "[sink] record: %s; recording stopped", sh_error_message());
                    run_record_close(rec);
                    rec = NULL;
                }
                black_count++;
                last_black = now;
                if (snprintf(status_line, sizeof status_line, "%s: black raw frames, %llu published, %llu dropped",
                             lost_text, (unsigned long long)published, (unsigned long long)run_source_dropped(src)) < 0)
                    status_line[0] = 0;
            }
        } else {
            if (lost) {
                logm("INFO", "main", "the output camera's frames are back after %.1f s (%llu black frames shown)",
                     (double)(mono_ns() - lost_since) / 1e9, (unsigned long long)black_count);
                lost = 0;
            }
            sh_display_frame_info info;
            memset(&info, 0, sizeof info);
            info.capture_ns = s->avail_ns;
            const sh_image *shown = run_proc_frame(proc, &s->img, s->cam, s->index, s->epoch, &info);
            uint32_t status = info.status;
            if (status == SH_DISPLAY_RAW) raw_count++;
            if (status == SH_DISPLAY_DEGRADED) degraded_count++;
            if (status != last_status_shown ||
                (status != SH_DISPLAY_STABILIZED && strncmp(last_reason, info.reason, 12))) {
                logm(status == SH_DISPLAY_RAW && published ? "WARN" : "INFO", "main", "frame %d: %s%s%s", s->index,
                     names[status], info.reason[0] ? ": " : "", info.reason);
                last_status_shown = status;
                memcpy(last_reason, info.reason, sizeof last_reason);
            }
            if (disp) {
                info.publish_ns = mono_ns();
                if (sh_display_writer_publish(disp, shown, &info) != SH_OK)
                    logm("ERROR", "main", "publish: %s", sh_error_message());
            }
            if (rec && run_record_write(rec, shown) != SH_OK) {
                logm("ERROR", "main", "[sink] record: %s; recording stopped", sh_error_message());
                run_record_close(rec);
                rec = NULL;
            }
            int64_t done_ns = mono_ns();
            if (nlat < LAT_CAP) lat[nlat++] = (float)((double)(done_ns - s->avail_ns) / 1e6);
            published++;
            if (published == 30) rss_start = rss_kb();
            if ((published & 63) == 0) { long r = rss_kb(); if (r > rss_max) rss_max = r; }
            if (!rss_1min && done_ns - t_start >= 60000000000LL) rss_1min = rss_kb();
            snprintf(status_line, sizeof status_line,
                     "frame %d: %s%s%s, %u markers, residual %.2f px, %llu published, %llu dropped", s->index,
                     names[status], info.reason[0] ? ": " : "", info.reason, info.markers_used,
                     (double)info.residual_px, (unsigned long long)published,
                     (unsigned long long)run_source_dropped(src));
            if (trace) {
                double tm, tmod, tw;
                run_proc_times(proc, &tm, &tmod, &tw);
                fprintf(trace, "%d,%s,%u,%.3f,\"%s\",%.3f,%.3f,%.3f,%.3f\n", s->index, names[status], info.markers_used,
                        (double)info.residual_px, info.reason, tm, tmod, tw, (double)(done_ns - s->avail_ns) / 1e6);
            }
            shown_info = info;
        }
        /* systemd: STATUS each second; WATCHDOG while frames progress, or while the output camera
         * is lost and every thread still goes round. A hung processing loop sends neither. */
        int64_t now = mono_ns();
        if ((published || black_count) && now - last_status >= 1000000000) {
            double fps = (double)(published - published_at_status) * 1e9 / (double)(now - last_status);
            char cams[128];
            run_source_online(src, cams, sizeof cams);
            sh_notifyf("STATUS=%s%s%.1f fps, %u markers, %s%s%s, %llu dropped, %s", lost ? lost_text : "",
                       lost ? ": " : "", fps, shown_info.markers_used, names[shown_info.status],
                       shown_info.reason[0] ? " " : "", shown_info.reason,
                       (unsigned long long)run_source_dropped(src), cams);
            last_status = now;
            published_at_status = published;
        }
        if (wd_usec && now - last_ping >= (int64_t)wd_usec * 500) {
            int progress = published > published_at_ping;
            int alive = !progress && lost && run_source_alive(src, (int64_t)wd_usec * 500, stale, sizeof stale);
            if (progress || alive) {
                sh_notify("WATCHDOG=1");
                last_ping = now;
                published_at_ping = published;
                wd_held = 0;
            } else if (lost) {
                LOG_ONCE(wd_held, "ERROR", "main", "watchdog held back: %s", stale);
            }
        }
        if (s && ro.max_frames && published >= (uint64_t)ro.max_frames) break;
    }
    sh_notify("STOPPING=1");
    sig_stop = 1;
    rc = 0;
    if (ro.stats || !log_quiet) {
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
                (unsigned long long)degraded_count, (unsigned long long)run_source_dropped(src), med, p99, mx,
                rss_start, rss_1min, rss_max, r, run_proc_builds(proc), (unsigned long long)black_count);
    }
done:
    sig_stop = 1;
    run_source_destroy(src);
    if (rec && run_record_skipped(rec))
        logm("WARN", "main", "[sink] record: %llu frames not recorded (the PNG writer fell behind)",
             (unsigned long long)run_record_skipped(rec));
    if (rec && run_record_close(rec) != SH_OK) { logm("ERROR", "main", "[sink] record: %s", sh_error_message()); rc = 1; }
    run_ctl_close(ctl);
    if (trace && fclose(trace)) { logm("ERROR", "main", "--trace: %s", strerror(errno)); rc = 1; }
    if (disp) sh_display_writer_destroy(disp, 0); /* marked closed; readers see the end */
    run_proc_destroy(proc);
    sh_image_destroy(&black);
    free(lat);
    return rc;
}
