/* stillheart-show: the display on the box's own monitor. Reads the daemon's display segment and
 * shows the newest frame on a DRM/KMS output (src/kms), scaled and letterboxed, with its status
 * visible (src/screen), page flips on vblank; "NO SIGNAL" with the time since the last frame
 * when no frame has come for --stale seconds (the daemon stopped, crashed or not there yet).
 *
 * One loop: wait for a frame newer than the one shown (never more than 100 ms, so that NO SIGNAL
 * and its clock appear on time), draw it into the buffer that is not scanned out, flip, and wait
 * for the flip's event before touching the other buffer. Frames that arrive meanwhile are not
 * queued: the next wait returns the newest. On one thread the frame is drawn where it lies in
 * the segment (sh_display_reader_view: no copy of it, and the drawing kept only when the writer
 * stayed out of its slot); the drawing may instead be shared, in horizontal bands, with
 * --threads - 1 helper threads, from a copy (a view is read on one thread only). The drawing is
 * most of the display's own part of publish-to-flip. */
#include <errno.h>
#include <getopt.h>
#include <math.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "stillheart/cli.h"
#include "stillheart/display.h"
#include "stillheart/kms.h"
#include "stillheart/log.h"
#include "stillheart/notify.h"
#include "stillheart/screen.h"

static const sh_cli cli = {"stillheart-show"};

static void usage(FILE *out)
{
    fprintf(out,
        "usage: stillheart-show [--device DEV] [--connector NAME] [--mode WxH[@R]] [--name NAME]\n"
        "                       [--owner USER] [--overlay off|minimal|full] [--stale S] [--stats]\n"
        "                       [--trace FILE] [--threads N]\n\n"
        "Shows the frames the stillheart daemon publishes (its shared-memory display buffer) on a\n"
        "monitor through DRM/KMS, without X or Wayland: the newest frame, scaled to the mode with\n"
        "black bars, page flips on vblank. The status is shown on the picture (--overlay); when no\n"
        "frame has come for --stale seconds (the daemon stopped, crashed, or is not there yet) the\n"
        "screen says NO SIGNAL and how long ago the last frame came. A restarted daemon is followed.\n\n"
        "options:\n"
        "  --device DEV       DRM device (default /dev/dri/card0)\n"
        "  --connector NAME   output, e.g. HDMI-A-1 (default: the first with a monitor)\n"
        "  --mode WxH[@R]     mode, e.g. 1920x1080@60 (default: the monitor's preferred mode)\n"
        "  --name NAME        shared-memory segment (default %s)\n"
        "  --owner USER       user name or uid the segment must belong to (default: the user\n"
        "                     running stillheart-show)\n"
        "  --overlay MODE     off: the picture exactly as published, nothing drawn on it;\n"
        "                     minimal: a thin frame in the status colour (green stabilized, amber\n"
        "                     degraded, red raw); full (default): also a badge naming the status\n"
        "                     and the reason as a line of text\n"
        "  --stale S          seconds without a new frame before NO SIGNAL (default 0.5)\n"
        "  --stats            latency on stderr every 5 s and at the end: capture-to-scanout (the\n"
        "                     flip's vblank time minus the frame's capture time),\n"
        "                     publish-to-flip, and publish-to-present (the display's own part:\n"
        "                     waking, copying and drawing, up to the flip's request; the rest of\n"
        "                     publish-to-flip is the wait for the vblank), median / p99 / max in ms\n"
        "  --trace FILE       one CSV line per frame shown: sequence,status,capture_ns,\n"
        "                     publish_ns,present_ns,flip_ns (CLOCK_MONOTONIC); a file that cannot\n"
        "                     be written is refused at start, and one that fails later is closed\n"
        "                     with an error while the screen goes on\n"
        "  --threads N        threads that draw each frame, in bands (1-8, default 1): one thread\n"
        "                     draws the frame where it lies in the segment, more draw from a\n"
        "                     copy of it (about 0.4 ms at 1080p); a 1080p frame's conversion\n"
        "                     takes about 1 ms on one core, 0.5 on two, but a helper woken once\n"
        "                     a frame can cost what it saves (make bench: bench_show measures\n"
        "                     both on the box)\n"
        SH_CLI_USAGE "\n"
        "Exit status: 0 after SIGINT or SIGTERM, 1 the device refused (no such device,\n"
        "connector or mode; DRM master held by another process) or failed, or the --trace\n"
        "file could not be written, 2 bad usage.\n",
        SH_DISPLAY_DEFAULT_NAME);
}

typedef struct {
    sh_kms_options kms;
    sh_display_reader_options ropt;
    const char *name;
    sh_screen_overlay overlay;
    double stale;
    int stats;
    const char *trace;
    int threads;
} show_args;

/* Fills *a; -1 to go on, else the exit status (0 after --help, 2 a usage error). */
static int parse_args(int argc, char **argv, show_args *a)
{
    static const struct option options[] = {
        {"device", required_argument, 0, 'd'}, {"connector", required_argument, 0, 'c'},
        {"mode", required_argument, 0, 'm'}, {"name", required_argument, 0, 'n'},
        {"owner", required_argument, 0, 'o'}, {"overlay", required_argument, 0, 'O'},
        {"stale", required_argument, 0, 's'}, {"stats", no_argument, 0, 'S'},
        {"trace", required_argument, 0, 't'}, {"threads", required_argument, 0, 'T'},
        SH_CLI_OPTIONS, {0, 0, 0, 0}};
    memset(a, 0, sizeof *a);
    a->kms.device = "/dev/dri/card0";
    a->ropt = (sh_display_reader_options){.owner_uid = SH_DISPLAY_OWNER_SELF, .follow = 1};
    a->name = SH_DISPLAY_DEFAULT_NAME;
    a->overlay = SH_SCREEN_OVERLAY_FULL;
    a->stale = 0.5;
    a->threads = 1;
    int opt;
    opterr = 0;
    while ((opt = getopt_long(argc, argv, ":h", options, NULL)) != -1) {
        switch (opt) {
        case 'd': a->kms.device = optarg; break;
        case 'c': a->kms.connector = optarg; break;
        case 'm':
            if (sh_kms_parse_mode(optarg, &a->kms.width, &a->kms.height, &a->kms.refresh) != SH_OK)
                return sh_cli_usage_error(&cli, "--mode: %s", sh_error_message());
            break;
        case 'n': a->name = optarg; break;
        case 'o':
            if (!sh_cli_parse_user("--owner", optarg, &a->ropt.owner_uid)) return 2;
            break;
        case 'O':
            if (!sh_screen_overlay_parse(optarg, &a->overlay))
                return sh_cli_usage_error(&cli, "--overlay: '%s' is not off, minimal or full", optarg);
            break;
        case 's':
            if (!sh_cli_parse_double("--stale", optarg, 0.05, 3600, &a->stale)) return 2;
            break;
        case 'S': a->stats = 1; break;
        case 't': a->trace = optarg; break;
        case 'T':
            if (!sh_cli_parse_int("--threads", optarg, 1, 8, &a->threads)) return 2;
            break;
        case 'h': usage(stdout); return 0;
        default: { int rc = sh_cli_option(&cli, opt, argv); if (rc >= 0) return rc; } break;
        }
    }
    if (optind != argc) return sh_cli_usage_error(&cli, "'%s': no operands", argv[optind]);
    return -1;
}

static volatile sig_atomic_t stop_signal;
static void on_stop(int sig) { stop_signal = sig; }

static int64_t now_ns(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (int64_t)ts.tv_sec * 1000000000 + ts.tv_nsec;
}

static double now_s(void) { return (double)now_ns() / 1e9; }

/* The newest latency samples (ns), a ring; summarized as median / p99 / max. */
#define LAT_CAP 65536
typedef struct {
    int64_t v[LAT_CAP];
    size_t n, next;
} lat_ring;

static void lat_add(lat_ring *l, int64_t ns)
{
    l->v[l->next] = ns;
    l->next = (l->next + 1) % LAT_CAP;
    if (l->n < LAT_CAP) l->n++;
}

static int cmp_i64(const void *a, const void *b)
{
    int64_t x = *(const int64_t *)a, y = *(const int64_t *)b;
    return (x > y) - (x < y);
}

/* "median 12.3 p99 15.0 max 16.1 ms (n 600)" or "no samples" */
static void lat_summary(const lat_ring *l, char *out, size_t cap)
{
    if (l->n == 0) {
        snprintf(out, cap, "no samples");
        return;
    }
    static int64_t s[LAT_CAP];
    memcpy(s, l->v, l->n * sizeof s[0]);
    qsort(s, l->n, sizeof s[0], cmp_i64);
    size_t p99 = (size_t)ceil(0.99 * (double)l->n) - 1;
    snprintf(out, cap, "median %.2f p99 %.2f max %.2f ms (n %zu)", (double)s[(l->n - 1) / 2] / 1e6,
             (double)s[p99] / 1e6, (double)s[l->n - 1] / 1e6, l->n);
}

typedef struct {
    const show_args *a;
    sh_kms *kms;
    sh_screen_painter *painter;
    sh_kms_info ki;
    sh_display_reader *r;
    sh_image frame;
    int draw_failed;               /* the painter failed: said, and the screen stops */
    double last_frame, started;    /* monotonic s; last_frame < 0: none yet */
    int no_signal;                 /* what the screen shows: 1 NO SIGNAL, 0 a frame */
    long long no_signal_secs;      /* the seconds NO SIGNAL shows */
    uint64_t last_seq, generation, frames, skipped;
    lat_ring cap2scan, pub2flip, pub2present;
    FILE *trace;                   /* --trace, NULL when not asked or after a write failed */
} show_state;

/* The back buffer as a screen.h buffer. */
static sh_screen_buffer back_buffer(show_state *s)
{
    sh_screen_buffer b = {NULL, s->ki.width, s->ki.height, 0};
    sh_kms_back(s->kms, &b.pixels, &b.stride);
    return b;
}

/* Flips to the back buffer and waits for it; 0, or -1 after saying why. *present_ns (when not
 * NULL): the time the flip was asked for. */
static int flip(show_state *s, int64_t *present_ns, int64_t *flip_ns)
{
    if (present_ns) *present_ns = now_ns();
    if (sh_kms_present(s->kms) != SH_OK || sh_kms_wait(s->kms, 1000, flip_ns) != SH_OK) {
        sh_log_error("%s", sh_error_message());
        return -1;
    }
    return 0;
}

/* The frame into the back buffer: a view of it in the segment (sh_display_reader_view, one
 * thread), or the reader's copy of it. The painter on one thread reads it holding nothing, so
 * the reader may abandon it (display.h). */
static sh_status draw_picture(void *ctx, const sh_image *frame, const sh_display_frame_info *info)
{
    (void)info;
    show_state *s = ctx;
    sh_screen_buffer b = back_buffer(s);
    sh_screen_layout l = sh_screen_layout_for(frame->width, frame->height, b.width, b.height);
    /* the header of the segment the frame is in: a daemon come back meanwhile may have another range */
    sh_status st = sh_screen_painter_draw(s->painter, &b, &l, frame, (int)sh_display_reader_header(s->r)->full_range);
    if (st != SH_OK) s->draw_failed = 1;
    return st;
}

/* The frame is in the back buffer (draw_picture): its status over it, the flip, the figures. */
static int show_frame(show_state *s, const sh_display_frame_info *info)
{
    const sh_display_header *h = sh_display_reader_header(s->r);
    sh_screen_buffer b = back_buffer(s);
    sh_screen_layout l = sh_screen_layout_for((int)h->width, (int)h->height, b.width, b.height);
    sh_screen_draw_status(&b, &l, s->a->overlay, info->status, info->reason, (int)sizeof info->reason);
    int64_t present_ns, flip_ns;
    if (flip(s, &present_ns, &flip_ns) != 0) return -1;
    if (s->no_signal) sh_log_info("signal: frame %llu shown", (unsigned long long)info->sequence);
    s->no_signal = 0;
    if (s->frames && s->generation == sh_display_reader_header(s->r)->generation && info->sequence > s->last_seq + 1)
        s->skipped += info->sequence - s->last_seq - 1;
    s->generation = sh_display_reader_header(s->r)->generation;
    s->last_seq = info->sequence;
    s->frames++;
    if (info->capture_ns > 0) lat_add(&s->cap2scan, flip_ns - info->capture_ns);
    if (info->publish_ns > 0) {
        lat_add(&s->pub2flip, flip_ns - info->publish_ns);
        lat_add(&s->pub2present, present_ns - info->publish_ns);
    }
    if (s->trace && (fprintf(s->trace, "%llu,%u,%lld,%lld,%lld,%lld\n", (unsigned long long)info->sequence,
                             info->status, (long long)info->capture_ns, (long long)info->publish_ns,
                             (long long)present_ns, (long long)flip_ns) < 0 || fflush(s->trace) != 0)) {
        /* the screen matters more than its trace: say so once and go on without it */
        sh_log_error("--trace %s: %s; no more trace lines", s->a->trace, strerror(errno));
        fclose(s->trace);
        s->trace = NULL;
    }
    return 0;
}

/* NO SIGNAL, drawn again only when the seconds it shows change. */
static int show_no_signal(show_state *s, double now)
{
    double since = s->last_frame < 0 ? -1 : now - s->last_frame;
    long long secs = since < 0 ? -1 : (long long)since;
    if (s->no_signal && secs == s->no_signal_secs) return 0;
    if (!s->no_signal)
        sh_log_info("NO SIGNAL: %s", since < 0 ? "no frame yet" : "no new frame");
    sh_screen_buffer b = back_buffer(s);
    sh_screen_draw_no_signal(&b, since);
    s->no_signal = 1;
    s->no_signal_secs = secs;
    return flip(s, NULL, NULL);
}

/* A frame sized from the reader's header (at open, and when the daemon came back at another
 * size), for the copy of each frame that several drawing threads take; on one thread each frame
 * is drawn where it lies in the segment (sh_display_reader_view), saving two copies of it (at
 * 1080p, about 0.4 ms of publish-to-flip). 0 or -1. */
static int size_frame(show_state *s)
{
    const sh_display_header *h = sh_display_reader_header(s->r);
    sh_image_destroy(&s->frame);
    if (s->a->threads > 1 &&
        sh_image_create(&s->frame, (sh_pixfmt)h->format, (int)h->width, (int)h->height) != SH_OK) {
        sh_log_error("%s", sh_error_message());
        return -1;
    }
    sh_log_info("%s: %ux%u %s frames", s->a->name, h->width, h->height, sh_pixfmt_name((sh_pixfmt)h->format));
    return 0;
}

static void report(show_state *s, const char *when)
{
    char c[96], p[96], d[96];
    lat_summary(&s->cap2scan, c, sizeof c);
    lat_summary(&s->pub2flip, p, sizeof p);
    lat_summary(&s->pub2present, d, sizeof d);
    if (s->a->stats)
        fprintf(stderr, "stillheart-show: stats%s: %llu frames shown, %llu skipped; capture-to-scanout %s; "
                "publish-to-flip %s; publish-to-present %s\n", when, (unsigned long long)s->frames,
                (unsigned long long)s->skipped, c, p, d);
    sh_notifyf("STATUS=%s, %llu frames shown; capture-to-scanout %s; publish-to-flip %s",
               s->no_signal ? "NO SIGNAL" : "showing", (unsigned long long)s->frames, c, p);
}

/* One turn of the loop: a frame shown, NO SIGNAL, or nothing new; 0, or -1 to stop with an error. */
static int step(show_state *s)
{
    double now = now_s();
    if (!s->r) {
        static sh_log_limit lim;
        sh_status st = sh_display_reader_open(s->a->name, &s->a->ropt, 0, &s->r);
        if (st == SH_OK) {
            if (size_frame(s) != 0) return -1;
        } else {
            if (st == SH_EINVAL) sh_log_limited(&lim, SH_LOG_WARN, "%s", sh_error_message());
            if (now - (s->last_frame < 0 ? s->started : s->last_frame) >= s->a->stale && show_no_signal(s, now) != 0)
                return -1;
            nanosleep(&(struct timespec){0, 50 * 1000000}, NULL);
            return 0;
        }
    }
    double due = (s->last_frame < 0 ? s->started : s->last_frame) + s->a->stale;
    int wait_ms = (int)fmax(1, fmin(100, (due - now) * 1e3));
    if (s->no_signal) wait_ms = 100;
    sh_display_frame_info info;
    uint64_t generation = sh_display_reader_header(s->r)->generation;
    sh_status st = s->a->threads > 1 ? sh_display_reader_next(s->r, &s->frame, &info, wait_ms)
                                     : sh_display_reader_view(s->r, draw_picture, s, &info, wait_ms);
    now = now_s();
    if (st == SH_OK && s->a->threads > 1) st = draw_picture(s, &s->frame, &info);
    if (s->draw_failed) {
        sh_log_error("%s", sh_error_message());
        return -1;
    }
    /* a daemon come back at another size: its frames are shown at once, the size said */
    if (st == SH_OK && s->a->threads == 1 && sh_display_reader_header(s->r)->generation != generation &&
        size_frame(s) != 0)
        return -1;
    if (st == SH_OK) {
        s->last_frame = now;
        return show_frame(s, &info);
    }
    if (st == SH_ERANGE) return size_frame(s);
    if (st != SH_EIO) { /* the name taken by another owner, or the segment gone: open it anew */
        sh_log_warn("%s", sh_error_message());
        sh_display_reader_close(s->r);
        s->r = NULL;
    }
    if (now >= due) return show_no_signal(s, now);
    return 0;
}

static int run(const show_args *a, sh_kms *kms, FILE *trace)
{
    static show_state s; /* the latency rings are 1 MiB: not on the stack */
    s.a = a;
    s.trace = trace;
    s.kms = kms;
    sh_kms_get_info(kms, &s.ki);
    s.started = now_s();
    s.last_frame = -1;
    s.no_signal_secs = -2;
    if (sh_screen_painter_create(a->threads, &s.painter) != SH_OK) {
        sh_log_error("--threads %d: %s", a->threads, sh_error_message());
        if (s.trace) fclose(s.trace);
        return 1;
    }
    sh_log_info("%s (%s): %s %dx%d@%.2f, overlay %s, %d drawing thread%s", a->kms.device, s.ki.driver, s.ki.connector,
                s.ki.width, s.ki.height, s.ki.refresh, sh_screen_overlay_name(a->overlay), a->threads,
                a->threads > 1 ? "s" : "");
    /* the screen at once, before the daemon's first frame: NO SIGNAL */
    if (show_no_signal(&s, s.started) != 0) {
        sh_screen_painter_destroy(s.painter);
        if (s.trace) fclose(s.trace);
        return 1;
    }
    sh_notify("READY=1");
    uint64_t wd = sh_notify_watchdog_usec();
    double last_ping = 0, last_report = s.started;
    int rc = 0;
    while (!stop_signal && rc == 0) {
        rc = step(&s) != 0;
        double now = now_s();
        if (wd && now - last_ping >= wd / 2e6) {
            sh_notify("WATCHDOG=1");
            last_ping = now;
        }
        if (now - last_report >= 5) {
            report(&s, "");
            last_report = now;
        }
    }
    report(&s, " (end)");
    if (s.trace && fclose(s.trace) != 0) {
        sh_log_error("--trace %s: %s", a->trace, strerror(errno));
        rc = 1;
    }
    sh_display_reader_close(s.r);
    sh_image_destroy(&s.frame);
    sh_screen_painter_destroy(s.painter);
    return rc;
}

int main(int argc, char **argv)
{
    show_args a;
    sh_log_setup(SH_LOG_TOOL, "stillheart-show", SH_LOG_INFO);
    int prc = parse_args(argc, argv, &a);
    if (prc >= 0) return prc;
    struct sigaction sa;
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = on_stop;
    sigemptyset(&sa.sa_mask);
    sigaction(SIGINT, &sa, NULL);
    sigaction(SIGTERM, &sa, NULL);
    /* the trace before the device: a path that cannot be written is refused before the screen
     * is taken */
    FILE *trace = NULL;
    if (a.trace) {
        if (!(trace = fopen(a.trace, "w"))) {
            sh_log_error("--trace %s: %s", a.trace, strerror(errno));
            return 1;
        }
        fprintf(trace, "sequence,status,capture_ns,publish_ns,present_ns,flip_ns\n");
    }
    sh_kms *kms;
    if (sh_kms_create(&a.kms, &kms) != SH_OK) {
        sh_log_error("%s", sh_error_message());
        if (trace) fclose(trace);
        return 1;
    }
    int rc = run(&a, kms, trace);
    sh_kms_destroy(kms);
    return rc;
}
