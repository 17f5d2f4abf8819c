/* The daemon's loop (daemon.h): take the newest set from the source, process it, publish what to
 * show, tell systemd; or, while the output camera is lost, publish a black raw frame per frame
 * period. Opening, closing and, on SIGHUP, swapping the pipeline's pieces (source, processing,
 * display, record, control socket) is run_pipeline.c; the source thread and the mailbox
 * run_source.c; one frame's processing run_proc.c (run_track.c: tracker and selection,
 * run_model.c: models and residual). */
#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "run_pipeline.h"
#include "stillheart/cli.h"
#include "stillheart/daemon.h"
#include "stillheart/display.h"
#include "stillheart/log.h"
#include "stillheart/notify.h"
#include "stillheart/warp3d.h"

#define LAT_CAP (1 << 20)

static const char *const status_names[] = {"raw", "stabilized", "degraded"};

/* The loop's state: counters, what was shown, systemd, the output camera lost. */
struct sh_daemon {
    run_pipeline pl;
    sh_daemon_options opt;
    FILE *trace, *trace_points;
    int fatal;                     /* a reload left the pipeline unable to run */

    /* counters and latency (the stats line) */
    uint64_t published, raw_count, degraded_count, black_count;
    float *lat;                    /* ms from a set's availability to its publication */
    size_t nlat;
    int64_t t_start;
    long rss_start, rss_max, rss_1min; /* warm-up (detector, caches) is over after a minute */
    /* the tracker's first lock of the rates: sets dropped before it (the first full-frame scans,
     * a constant-velocity guess) are the start's; one after it is the box not keeping up */
    int locked;
    uint64_t published_at_lock, dropped_at_lock;

    /* what was shown (the log's status changes, STATUS, the control socket's status line) */
    uint32_t last_status_shown;    /* 99: none yet, the next frame is logged */
    char last_reason[44];
    char status_line[160];
    char status_json[RUN_CTL_STATUS_MAX]; /* the same as one JSON object (status-json) */
    char status_scratch[RUN_CTL_STATUS_MAX]; /* written each frame through status_file (fmemopen, */
    FILE *status_file;                       /* opened once: no allocation a frame) */
    sh_display_frame_info shown_info; /* the last published frame's, for STATUS */

    /* systemd */
    uint64_t wd_usec;              /* 0: no watchdog */
    int64_t last_ping, last_status;
    uint64_t published_at_ping, published_at_status;
    sh_log_limit wd_held;          /* "watchdog held back" logged once until the pings resume */

    /* The output camera lost: a black raw frame per frame period tells the display, and the
     * watchdog is kept alive while every thread still goes round (a restart cannot bring a
     * camera back; source.h is reopening it). */
    int64_t period;                /* the output camera's frame period, ns */
    int lost;
    int64_t lost_since, last_black;
    char lost_text[96], stale[160];
};

/* The output camera's frame period, ns (25 fps when the source does not say). */
static int64_t frame_period(run_source *src)
{
    return run_source_fps(src) > 0 ? (int64_t)(1e9 / run_source_fps(src)) : 40000000;
}

/* Resident set from /proc/self/statm (its second field, in pages); 0 where it cannot be read.
 * Sampled every 64 frames: read with open and read into the stack, as a FILE would be allocated
 * (tools/alloc/per-frame.sh). */
static long rss_kb(void)
{
    char buf[128];
    int fd = open("/proc/self/statm", O_RDONLY | O_CLOEXEC);
    if (fd < 0) return 0;
    ssize_t n = read(fd, buf, sizeof buf - 1);
    close(fd);
    if (n <= 0) return 0;
    buf[n] = 0;
    char *end;
    strtol(buf, &end, 10); /* the program's size */
    long res = strtol(end, NULL, 10);
    return res > 0 ? res * (sysconf(_SC_PAGESIZE) / 1024) : 0;
}

static int cmp_float(const void *a, const void *b)
{
    float x = *(const float *)a, y = *(const float *)b;
    return (x > y) - (x < y);
}

/* Closes the trace files: 0, or -1 when one could not be written (logged). */
static int close_traces(sh_daemon *d)
{
    int bad = 0;
    if (d->trace && fclose(d->trace)) { sh_log_error("--trace: %s", strerror(errno)); bad = -1; }
    if (d->trace_points && fclose(d->trace_points)) { sh_log_error("--trace-points: %s", strerror(errno)); bad = -1; }
    d->trace = d->trace_points = NULL;
    return bad;
}

sh_status sh_daemon_create(const sh_config *cfg, const sh_daemon_options *opt, sh_daemon **out)
{
    *out = NULL;
    sh_daemon *d = calloc(1, sizeof *d);
    float *lat = malloc(sizeof(float) * LAT_CAP);
    if (!d || !lat) {
        free(d);
        free(lat);
        return sh_error_set(SH_ENOMEM, "out of memory");
    }
    d->lat = lat;
    if (opt) d->opt = *opt;
    sh_status st = run_pipeline_open(&d->pl, cfg); /* on error nothing stays open */
    if (st != SH_OK) {
        free(d->lat);
        free(d);
        return st;
    }
    if (!(d->status_file = fmemopen(d->status_scratch, sizeof d->status_scratch, "w"))) {
        sh_daemon_destroy(d);
        return sh_error_set(SH_ENOMEM, "out of memory");
    }
    const char *which = NULL, *path = NULL;
    if (d->opt.trace_path && !(d->trace = fopen(d->opt.trace_path, "w"))) which = "--trace", path = d->opt.trace_path;
    if (d->trace)
        fprintf(d->trace, "index,status,markers,residual,reason,markers_ms,model_ms,warp_ms,latency_ms,landmarks,"
                "landmarks_ms\n");
    if (!which && d->opt.trace_points_path && !(d->trace_points = fopen(d->opt.trace_points_path, "w")))
        which = "--trace-points", path = d->opt.trace_points_path;
    if (d->trace_points) fprintf(d->trace_points, "frame,id,x,y\n");
    if (which) {
        char msg[512];
        snprintf(msg, sizeof msg, "%s: %s: %s", which, path, strerror(errno));
        sh_daemon_destroy(d);
        return sh_error_set(SH_EIO, "%s", msg);
    }
    *out = d;
    return SH_OK;
}

sh_status sh_daemon_start(sh_daemon *d)
{
    run_pipeline *pl = &d->pl;
    const sh_config *cfg = &pl->cfg;
    sh_status st = run_pipeline_start(pl);
    if (st != SH_OK) return st;
    char shown[96] = "";
    if (cfg->view == SH_VIEW_STEREO)
        snprintf(shown, sizeof shown, " shown as a %dx%d stereo pair (%s, baseline %g mm)", pl->out_hdr.width,
                 pl->out_hdr.height, sh_warp3d_layout_name((sh_warp3d_layout)cfg->layout), cfg->baseline);
    sh_log_info("source %s %dx%d %s %.3f fps (%s%s), sink %s%s, method %s, %s",
         cfg->camera[0].spec, pl->hdr.width, pl->hdr.height, sh_pixfmt_name(pl->hdr.format), run_source_fps(pl->src),
         cfg->realtime ? "real time" : "as fast as possible", cfg->loop ? ", looping" : "", cfg->sink, shown,
         cfg->method_name, cfg->points[0] ? "markers from the points file (test mode)" : "markers detected");
    sh_notify("READY=1\nSTATUS=started, waiting for the reference frame");

    d->wd_usec = cfg->watchdog ? sh_notify_watchdog_usec() : 0;
    d->last_ping = d->last_status = d->t_start = sh_monotonic_ns();
    d->last_status_shown = 99;
    snprintf(d->status_line, sizeof d->status_line, "starting: no frame yet");
    snprintf(d->status_json, sizeof d->status_json, "{\"state\": \"starting\"}");
    d->period = frame_period(pl->src);
    return SH_OK;
}

/* ---- systemd ---- */

static void ping_watchdog(const sh_daemon *d)
{
    if (d->wd_usec) sh_notify("WATCHDOG=1");
}

/* STATUS each second, once a frame (camera or black) was published. */
static void notify_status(sh_daemon *d, int64_t now)
{
    if (!(d->published || d->black_count) || now - d->last_status < 1000000000) return;
    double fps = (double)(d->published - d->published_at_status) * 1e9 / (double)(now - d->last_status);
    char cams[128];
    run_source_online(d->pl.src, cams, sizeof cams);
    const sh_display_frame_info *s = &d->shown_info;
    sh_notifyf("STATUS=%s%s%.1f fps, %u markers, %s%s%s, %llu dropped, %s", d->lost ? d->lost_text : "",
               d->lost ? ": " : "", fps, s->markers_used, status_names[s->status], s->reason[0] ? " " : "",
               s->reason, (unsigned long long)run_pipeline_dropped(&d->pl), cams);
    d->last_status = now;
    d->published_at_status = d->published;
}

/* WATCHDOG at half the watchdog period while frames progress, or while the output camera is
 * lost and every thread still goes round. A hung processing loop sends neither. */
static void notify_watchdog(sh_daemon *d, int64_t now)
{
    if (!d->wd_usec || now - d->last_ping < (int64_t)d->wd_usec * 500) return;
    int progress = d->published > d->published_at_ping;
    int alive = !progress && d->lost &&
                run_source_alive(d->pl.src, (int64_t)d->wd_usec * 500, d->stale, sizeof d->stale);
    if (progress || alive) {
        sh_notify("WATCHDOG=1");
        d->last_ping = now;
        d->published_at_ping = d->published;
        sh_log_limit_clear(&d->wd_held);
    } else if (d->lost) {
        sh_log_limited(&d->wd_held, SH_LOG_ERROR, "watchdog held back: %s", d->stale);
    }
}

/* SIGHUP: the config again (the program's loader), applied to every piece of the pipeline.
 * systemd hears RELOADING=1 and READY=1 around it, and a watchdog ping on either side: opening
 * cameras can take a second. Returns -1 when the pipeline cannot run on (the previous cameras
 * did not come back: the daemon exits non-zero and systemd restarts it), 1 when the cameras were
 * closed and opened (the new ones or the previous ones again), else 0. */
static int apply_reload(sh_daemon *d)
{
    char err[SH_CONFIG_ERR], what[640];
    sh_notifyf("RELOADING=1\nMONOTONIC_USEC=%llu\nSTATUS=reloading the config", (unsigned long long)(sh_monotonic_ns() / 1000));
    ping_watchdog(d);
    sh_config fresh;
    run_reload r = RUN_RELOAD_REFUSED;
    int cams = 0;
    snprintf(err, sizeof err, "no way to read the config again");
    if (!d->opt.load || d->opt.load(d->opt.load_ctx, &fresh, err) != SH_OK) {
        snprintf(what, sizeof what, "reload refused, keeping the running config: %s", err);
    } else {
        cams = (sh_config_changes(&fresh, &d->pl.cfg) & SH_CONFIG_SOURCE) != 0;
        r = run_pipeline_reload(&d->pl, &fresh, what, sizeof what);
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
    ping_watchdog(d);
    return cams;
}

/* A reload, and the loop's state after it: the watchdog's period may have changed; new cameras
 * are a new stream (their rate, nothing lost yet, their first frame logged). -1: fatal. */
static int reload(sh_daemon *d)
{
    int cams = apply_reload(d);
    if (cams < 0) return -1;
    d->wd_usec = d->pl.cfg.watchdog ? sh_notify_watchdog_usec() : 0;
    d->last_ping = sh_monotonic_ns();
    d->published_at_ping = d->published;
    if (cams) {
        d->period = frame_period(d->pl.src);
        d->lost = 0;
        sh_log_limit_clear(&d->wd_held);
        d->last_status_shown = 99;
    }
    return 0;
}

/* ---- publishing ---- */

/* One frame to the display. The writer makes its segment anew when it finds it shrunk, unlinked
 * or replaced under it (display.h); that is logged at most once a second (someone meddling could
 * otherwise fill the log), as is a publish that fails (the name taken by another user). */
static void display_publish(sh_display_writer *w, const sh_image *img, const sh_display_frame_info *info)
{
    static sh_log_limit failed = {.period_s = 1}, remade_lim = {.period_s = 1};
    static uint64_t remade_logged;
    if (sh_display_writer_publish(w, img, info) != SH_OK) {
        sh_log_limited(&failed, SH_LOG_ERROR, "publish: %s", sh_error_message());
        return;
    }
    uint64_t remade = sh_display_writer_remade(w);
    if (remade != remade_logged) {
        sh_log_limited(&remade_lim, SH_LOG_WARN, "display: the segment was shrunk, changed, unlinked or replaced "
                       "under the daemon and made anew (generation %016llx; %llu times so far)",
                       (unsigned long long)sh_display_writer_generation(w), (unsigned long long)remade);
        remade_logged = remade;
    }
}

/* What is shown, a camera frame or a black one: to the display (the writer stamps publish_ns),
 * then to the record, numbered as the display's frames, and to the V4L2 output. A record or a
 * V4L2 device that cannot be written is stopped; the display goes on. The V4L2 output gets every
 * shown frame whatever its status, as the segment does; the status itself is only in the
 * segment's header (V4L2 frames carry none). */
static void publish(sh_daemon *d, const sh_image *shown, const sh_display_frame_info *info)
{
    run_pipeline *pl = &d->pl;
    if (pl->disp) display_publish(pl->disp, shown, info);
    if (pl->rec && run_record_write(pl->rec, shown) != SH_OK) {
        sh_log_error("[sink] record: %s; recording stopped", sh_error_message());
        run_record_close(pl->rec);
        pl->rec = NULL;
    }
    if (pl->v4l2 && run_v4l2out_write(pl->v4l2, shown) != SH_OK) {
        sh_log_error("[sink] v4l2: %s; publishing there stopped", sh_error_message());
        run_pipeline_v4l2_close(pl->v4l2);
        pl->v4l2 = NULL;
    }
}

/* status-json: what status_line says, as one JSON object on one line. state "running" with the
 * last published frame (info, index), or "camera lost" with the black frames' reason. A text
 * that does not fit keeps the last one. */
static void set_status_json(sh_daemon *d, const char *state, int index, const sh_display_frame_info *info)
{
    FILE *f = d->status_file;
    rewind(f);
    clearerr(f);
    sh_cli_json j;
    sh_cli_json_start(&j, f);
    sh_cli_json_object(&j, NULL);
    sh_cli_json_string(&j, "state", state);
    if (d->lost) sh_cli_json_string(&j, "lost", d->lost_text);
    if (info && !d->lost) {
        sh_cli_json_int(&j, "frame", index);
        sh_cli_json_string(&j, "status", status_names[info->status]);
        sh_cli_json_string(&j, "reason", info->reason[0] ? info->reason : NULL);
        sh_cli_json_int(&j, "markers", info->markers_used);
        sh_cli_json_number(&j, "residual_px", info->residual_px >= 0 ? (double)info->residual_px : NAN);
    }
    sh_cli_json_int(&j, "published", (long long)d->published);
    sh_cli_json_int(&j, "black_frames", (long long)d->black_count);
    sh_cli_json_int(&j, "dropped", (long long)run_pipeline_dropped(&d->pl));
    sh_cli_json_end(&j);
    long len = fflush(f) == 0 && !ferror(f) ? ftell(f) : -1;
    /* the whole object and its newline, with room to spare (a stream at its end has cut it) */
    if (len > 1 && len < (long)sizeof d->status_scratch - 1 && d->status_scratch[len - 1] == '\n') {
        memcpy(d->status_json, d->status_scratch, (size_t)len - 1);
        d->status_json[len - 1] = 0; /* the newline: the reply is one line */
    }
}

/* No set to show: when the output camera is lost (or no set holds its frame), a black raw frame
 * per frame period, with the reason the display shows. */
static void output_lost(sh_daemon *d)
{
    int why = run_source_output_lost(d->pl.src, d->lost_text, sizeof d->lost_text);
    int64_t now = sh_monotonic_ns();
    if (why && !d->lost) {
        d->lost = 1;
        d->lost_since = now;
        d->last_black = 0;
        d->last_status_shown = 99; /* the first camera frame back is logged */
        sh_log_warn("%s: black raw frames shown until it returns", d->lost_text);
    }
    if (!why || now - d->last_black < d->period) return;
    sh_display_frame_info *info = &d->shown_info;
    memset(info, 0, sizeof *info);
    info->status = SH_DISPLAY_RAW;
    info->residual_px = -1; /* capture_ns 0: no camera frame */
    snprintf(info->reason, sizeof info->reason, "%s",
             why == 1 ? "output camera lost" : "no sets with the output camera");
    publish(d, &d->pl.black, info);
    d->black_count++;
    d->last_black = now;
    if (snprintf(d->status_line, sizeof d->status_line, "%s: black raw frames, %llu published, %llu dropped",
                 d->lost_text, (unsigned long long)d->published,
                 (unsigned long long)run_pipeline_dropped(&d->pl)) < 0)
        d->status_line[0] = 0;
    set_status_json(d, "camera lost", 0, NULL);
}

/* A change of status (or of a degraded or raw frame's reason) is one log line; a frame shown raw
 * after frames were published is a warning. */
static void log_status_change(sh_daemon *d, int index, const sh_display_frame_info *info)
{
    uint32_t status = info->status;
    if (status == d->last_status_shown &&
        (status == SH_DISPLAY_STABILIZED || !strncmp(d->last_reason, info->reason, 12)))
        return;
    sh_log_msg(status == SH_DISPLAY_RAW && d->published ? SH_LOG_WARN : SH_LOG_INFO, "frame %d: %s%s%s", index,
               status_names[status], info->reason[0] ? ": " : "", info->reason);
    d->last_status_shown = status;
    memcpy(d->last_reason, info->reason, sizeof d->last_reason);
}

/* Resident memory: after 30 frames (start), every 64 frames (max), after a minute (warm-up over). */
static void sample_memory(sh_daemon *d, int64_t now)
{
    if (d->published == 30) d->rss_start = rss_kb();
    if ((d->published & 63) == 0) {
        long r = rss_kb();
        if (r > d->rss_max) d->rss_max = r;
    }
    if (!d->rss_1min && now - d->t_start >= 60000000000LL) d->rss_1min = rss_kb();
}

/* --trace and --trace-points: one frame's lines. */
static void trace_frame(sh_daemon *d, const run_frame *s, const sh_display_frame_info *info, double latency_ms)
{
    if (d->trace) {
        double tm, tmod, tw, tl;
        int nl;
        run_proc_times(d->pl.proc, &tm, &tmod, &tw);
        run_proc_landmarks(d->pl.proc, &nl, &tl);
        fprintf(d->trace, "%d,%s,%u,%.3f,\"%s\",%.3f,%.3f,%.3f,%.3f,%d,%.3f\n", s->index, status_names[info->status],
                info->markers_used, (double)info->residual_px, info->reason, tm, tmod, tw, latency_ms, nl, tl);
    }
    if (d->trace_points) {
        const int *ids;
        const double *xy;
        int n = run_proc_markers(d->pl.proc, &ids, &xy);
        for (int k = 0; k < n; k++)
            fprintf(d->trace_points, "%d,%d,%.4f,%.4f\n", s->index, ids[k], xy[2 * k], xy[2 * k + 1]);
    }
}

/* One set from the source: processed, published, counted, traced. */
static void camera_frame(sh_daemon *d, const run_frame *s)
{
    if (d->lost) {
        sh_log_info("the output camera's frames are back after %.1f s (%llu black frames shown)",
                    (double)(sh_monotonic_ns() - d->lost_since) / 1e9, (unsigned long long)d->black_count);
        d->lost = 0;
    }
    sh_display_frame_info info;
    memset(&info, 0, sizeof info);
    /* the set's capture time (the driver's timestamp, or the trigger edge), so that a display's
     * capture-to-scanout counts the camera's delivery too; the time it reached processing where
     * a source gives none */
    info.capture_ns = s->capture_ns > 0 ? s->capture_ns : s->avail_ns;
    const sh_image *shown = run_proc_frame(d->pl.proc, &s->img, s->cam, s->index, s->epoch, &info);
    if (info.status == SH_DISPLAY_RAW) d->raw_count++;
    if (info.status == SH_DISPLAY_DEGRADED) d->degraded_count++;
    log_status_change(d, s->index, &info);
    publish(d, shown, &info);
    int64_t done_ns = sh_monotonic_ns();
    double latency_ms = (double)(done_ns - s->avail_ns) / 1e6;
    if (d->nlat < LAT_CAP) d->lat[d->nlat++] = (float)latency_ms;
    d->published++;
    if (!d->locked && run_proc_locked(d->pl.proc)) {
        d->locked = 1;
        d->published_at_lock = d->published;
        d->dropped_at_lock = run_pipeline_dropped(&d->pl);
        sh_log_info("frame %d: the tracker's rates locked, %llu frames published and %llu sets dropped before", s->index,
                    (unsigned long long)d->published, (unsigned long long)d->dropped_at_lock);
    }
    sample_memory(d, done_ns);
    snprintf(d->status_line, sizeof d->status_line,
             "frame %d: %s%s%s, %u markers, residual %.2f px, %llu published, %llu dropped", s->index,
             status_names[info.status], info.reason[0] ? ": " : "", info.reason, info.markers_used,
             (double)info.residual_px, (unsigned long long)d->published,
             (unsigned long long)run_pipeline_dropped(&d->pl));
    set_status_json(d, "running", s->index, &info);
    trace_frame(d, s, &info, latency_ms);
    d->shown_info = info;
}

sh_status sh_daemon_run(sh_daemon *d, sh_daemon_signals *sig)
{
    while (!sig->stop) {
        if (sig->reload) {
            sig->reload = 0;
            if (reload(d) < 0) { d->fatal = 1; break; }
        }
        int refs = d->pl.ctl ? run_ctl_references(d->pl.ctl) : 0;
        if (sig->reference || refs) {
            sh_log_info("new reference requested (%s)", sig->reference ? "SIGUSR1" : "control socket");
            sig->reference = 0;
            run_proc_request_reference(d->pl.proc);
        }
        /* while lost, wake each frame period to publish the black frame on time */
        int wait_ms = d->lost ? (int)(d->period / 1000000) : 100;
        const run_frame *s = run_source_take(d->pl.src, wait_ms < 1 ? 1 : wait_ms > 100 ? 100 : wait_ms);
        if (s) camera_frame(d, s);
        else if (run_source_ended(d->pl.src)) break;
        else output_lost(d);
        if (d->pl.ctl) run_ctl_set_status(d->pl.ctl, d->status_line, d->status_json);
        int64_t now = sh_monotonic_ns();
        notify_status(d, now);
        notify_watchdog(d, now);
        if (s && d->opt.max_frames && d->published >= (uint64_t)d->opt.max_frames) break;
    }
    sh_notify("STOPPING=1");
    if (d->fatal) return sh_error_set(SH_EIO, "a reload left the pipeline unable to run");
    if (d->pl.src && run_source_ended(d->pl.src) && run_source_failed(d->pl.src))
        return sh_error_set(SH_EFORMAT, "the output camera ended in an error (above)");
    return SH_OK;
}

/* The figures of the stats line and of its JSON. */
typedef struct {
    int have_latency;
    double lat_median, lat_p99, lat_max;
    long rss_end;
} stats_figures;

static void stats_measure(sh_daemon *d, stats_figures *f)
{
    size_t n = d->nlat;
    memset(f, 0, sizeof *f);
    if (n) {
        qsort(d->lat, n, sizeof *d->lat, cmp_float);
        f->have_latency = 1;
        f->lat_median = d->lat[n / 2];
        f->lat_p99 = d->lat[(size_t)((double)(n - 1) * 0.99)];
        f->lat_max = d->lat[n - 1];
    }
    f->rss_end = rss_kb();
    if (f->rss_end > d->rss_max) d->rss_max = f->rss_end;
}

/* Numbers that were never measured are not printed as 0: no latency before a frame is published,
 * no start RSS in a run of fewer than 30 frames, no one-minute RSS in a run shorter than a minute. */
void sh_daemon_stats(sh_daemon *d, char *line, size_t cap)
{
    stats_figures f;
    stats_measure(d, &f);
    char lat[96] = "latency: no frame published", start[40] = "", at1[40] = "";
    char lock[96] = "the tracker's rates not locked";
    if (f.have_latency)
        snprintf(lat, sizeof lat, "latency ms median %.2f p99 %.2f max %.2f", f.lat_median, f.lat_p99, f.lat_max);
    if (d->rss_start) snprintf(start, sizeof start, " start %ld", d->rss_start);
    if (d->rss_1min) snprintf(at1, sizeof at1, " at 1 min %ld", d->rss_1min);
    uint64_t dropped = run_pipeline_dropped(&d->pl);
    if (d->locked)
        snprintf(lock, sizeof lock, "%llu dropped after the tracker's first lock (at frame %llu published)",
                 (unsigned long long)(dropped - d->dropped_at_lock), (unsigned long long)d->published_at_lock);
    snprintf(line, cap,
             "stats: %llu published (%llu raw, %llu degraded), %llu dropped, %s, RSS kB%s%s max %ld "
             "end %ld, %d models built, %llu black frames (output camera lost), %d grids refined off the "
             "processing thread, %s",
             (unsigned long long)d->published, (unsigned long long)d->raw_count,
             (unsigned long long)d->degraded_count, (unsigned long long)dropped, lat, start, at1, d->rss_max,
             f.rss_end, run_pipeline_builds(&d->pl), (unsigned long long)d->black_count, run_pipeline_refined(&d->pl),
             lock);
}

/* The same figures; what was never measured is null. */
void sh_daemon_stats_json(sh_daemon *d, FILE *out)
{
    stats_figures f;
    stats_measure(d, &f);
    sh_cli_json j;
    sh_cli_json_start(&j, out);
    sh_cli_json_object(&j, NULL);
    sh_cli_json_int(&j, "published", (long long)d->published);
    sh_cli_json_int(&j, "raw", (long long)d->raw_count);
    sh_cli_json_int(&j, "degraded", (long long)d->degraded_count);
    sh_cli_json_int(&j, "dropped", (long long)run_pipeline_dropped(&d->pl));
    sh_cli_json_object(&j, "latency_ms");
    sh_cli_json_number(&j, "median", f.have_latency ? f.lat_median : NAN);
    sh_cli_json_number(&j, "p99", f.have_latency ? f.lat_p99 : NAN);
    sh_cli_json_number(&j, "max", f.have_latency ? f.lat_max : NAN);
    sh_cli_json_end(&j);
    sh_cli_json_object(&j, "rss_kb");
    if (d->rss_start) sh_cli_json_int(&j, "start", d->rss_start);
    else sh_cli_json_null(&j, "start");
    if (d->rss_1min) sh_cli_json_int(&j, "at_1_min", d->rss_1min);
    else sh_cli_json_null(&j, "at_1_min");
    sh_cli_json_int(&j, "max", d->rss_max);
    sh_cli_json_int(&j, "end", f.rss_end);
    sh_cli_json_end(&j);
    sh_cli_json_int(&j, "models_built", run_pipeline_builds(&d->pl));
    sh_cli_json_int(&j, "black_frames", (long long)d->black_count);
    if (d->locked) {
        sh_cli_json_int(&j, "published_at_lock", (long long)d->published_at_lock);
        sh_cli_json_int(&j, "dropped_after_lock", (long long)(run_pipeline_dropped(&d->pl) - d->dropped_at_lock));
    } else {
        sh_cli_json_null(&j, "published_at_lock");
        sh_cli_json_null(&j, "dropped_after_lock");
    }
    sh_cli_json_int(&j, "grids_refined", run_pipeline_refined(&d->pl));
    sh_cli_json_end(&j);
}

sh_status sh_daemon_destroy(sh_daemon *d)
{
    if (!d) return SH_OK;
    sh_status st = run_pipeline_close(&d->pl);
    if (close_traces(d) && st == SH_OK) st = sh_error_set(SH_EIO, "a trace file could not be written");
    if (d->status_file) fclose(d->status_file);
    free(d->lat);
    free(d);
    return st;
}
