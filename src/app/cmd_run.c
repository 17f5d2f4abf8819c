/* stillheart run: the daemon. A source thread replays frames into a one-slot mailbox (the oldest
 * frame is dropped and counted when processing falls behind, never queued); the processing
 * thread finds the markers (detection, or a points file in test mode), matches them to the
 * reference, takes the model for that marker set from a cache, warps, gates and publishes to
 * the shared-memory display buffer with status, reason, markers used and residual.
 *
 * The source thread and the mailbox are in run_source.c. */
#include <errno.h>
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
#include "run_source.h"
#include "stillheart/config.h"
#include "stillheart/detect.h"
#include "stillheart/display.h"
#include "stillheart/notify.h"
#include "stillheart/points.h"
#include "stillheart/warp.h"
#include "stillheart/y4m.h"

#define CACHE_SLOTS 8
#define MAX_MARKERS 256
#define MAX_DET 512
#define LAT_CAP (1 << 20)
#define WIN_HALF 128   /* search window half-size around a marker's last position, px */
#define SCAN_EVERY 15  /* frames between full-frame scans while a marker is missing */

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

/* ---- model cache per marker set (as cmd_warp) ---- */
typedef struct {
    int n;
    int ids[MAX_MARKERS];
    double ref_xy[2 * MAX_MARKERS];
    sh_interp *interp;
    sh_warp_model *model;
    unsigned long last_used;
} model_slot;

typedef struct {
    sh_interp_params params;
    sh_warp_options wopts;
    int width, height;
    sh_point ref[MAX_MARKERS];
    int nref;
    model_slot slot[CACHE_SLOTS];
    unsigned long clock;
    int builds;
} model_cache;

static void slot_clear(model_slot *s)
{
    sh_warp_model_destroy(s->model);
    sh_interp_destroy(s->interp);
    s->model = NULL;
    s->interp = NULL;
    s->n = 0;
    s->last_used = 0;
}

static sh_status cache_get(model_cache *c, const int *ids, int n, sh_warp_model **out)
{
    model_slot *victim = &c->slot[0];
    for (int i = 0; i < CACHE_SLOTS; i++) {
        model_slot *s = &c->slot[i];
        if (s->model && s->n == n && !memcmp(s->ids, ids, sizeof(int) * (size_t)n)) {
            s->last_used = ++c->clock;
            *out = s->model;
            return SH_OK;
        }
        if (!s->model || s->last_used < victim->last_used) victim = s;
    }
    slot_clear(victim);
    memcpy(victim->ids, ids, sizeof(int) * (size_t)n);
    victim->n = n;
    for (int k = 0, r = 0; k < n; k++) {
        while (c->ref[r].id != ids[k]) r++;
        victim->ref_xy[2 * k] = c->ref[r].x;
        victim->ref_xy[2 * k + 1] = c->ref[r].y;
    }
    sh_status st = sh_interp_create(&c->params, victim->ref_xy, n, &victim->interp);
    if (st == SH_OK)
        st = sh_warp_model_create(victim->interp, victim->ref_xy, n, c->width, c->height, &c->wopts,
                                  &victim->model);
    if (st != SH_OK) {
        slot_clear(victim);
        return st;
    }
    victim->last_used = ++c->clock;
    c->builds++;
    *out = victim->model;
    return SH_OK;
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
        "  --print-config     print the resulting config as INI and exit\n"
        "  --quiet            errors and warnings only\n"
        "signals: SIGTERM/SIGINT stop (segment marked closed), SIGHUP reloads the config file,\n"
        "SIGUSR1 takes a new reference frame.\n");
}

typedef struct {
    const char *config_path;
    int max_frames, stats, print_config;
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
        if (!is_cfg && strcmp(name, "config") && strcmp(name, "max-frames")) {
            snprintf(err, SH_CONFIG_ERR, "command line: --%s: unknown option (stillheart run --help)", name);
            return 2;
        }
        if (!val) {
            if (flag) val = negated ? "0" : "1";
            else if (i + 1 < argc) val = argv[++i];
            else { snprintf(err, SH_CONFIG_ERR, "command line: --%s needs a value", name); return 2; }
        }
        if (!strcmp(name, "config")) { if (ro) ro->config_path = val; continue; }
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

/* ---- markers of one frame ---- */
static int by_id(const void *a, const void *b)
{
    const sh_point *p = a, *q = b;
    return (p->id > q->id) - (p->id < q->id);
}

/* Detections -> sorted, id-filtered points, duplicates (an id seen twice) dropped entirely. */
static int detections_to_points(const sh_config *cfg, const sh_detection *d, int nd, sh_point *out)
{
    int n = 0;
    for (int i = 0; i < nd && n < MAX_MARKERS; i++) {
        if (d[i].id < 0 || d[i].id >= SH_CONFIG_MAX_IDS || !cfg->ids[d[i].id]) continue;
        if (!isfinite(d[i].cx) || !isfinite(d[i].cy)) continue;
        out[n].frame = 0;
        out[n].id = d[i].id;
        out[n].x = d[i].cx;
        out[n].y = d[i].cy;
        out[n].X = out[n].Y = out[n].Z = NAN;
        n++;
    }
    qsort(out, (size_t)n, sizeof *out, by_id);
    int m = 0;
    for (int i = 0; i < n;) {
        int j = i + 1;
        while (j < n && out[j].id == out[i].id) j++;
        if (j == i + 1) out[m++] = out[i];
        i = j;
    }
    return m;
}

static int cmp_float(const void *a, const void *b)
{
    float x = *(const float *)a, y = *(const float *)b;
    return (x > y) - (x < y);
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

    if (strncmp(cfg.source, "y4m:", 4)) {
        fprintf(stderr, "stillheart run: [source] spec: '%s': this build's daemon replays y4m:FILE only "
                        "(live capture: docs/daemon.md)\n", cfg.source);
        return 2;
    }
    int rc = 1;
    run_source *src = NULL;
    sh_points points = {0};
    sh_detector *det = NULL;
    sh_display_writer *disp = NULL;
    sh_y4m_writer *rec = NULL;
    sh_warp *warp = NULL;
    sh_image out = {0};
    model_cache *cache = calloc(1, sizeof *cache);
    sh_detection *dets = malloc(sizeof(sh_detection) * MAX_DET);
    float *lat = malloc(sizeof(float) * LAT_CAP);
    if (!cache || !dets || !lat) { fprintf(stderr, "stillheart run: out of memory\n"); goto done; }

    if (run_source_open(&cfg, logm, &src) != SH_OK) {
        fprintf(stderr, "stillheart run: [source] spec: %s\n", sh_error_message());
        goto done;
    }
    const sh_y4m_header *hdr = run_source_header(src);
    sh_y4m_header hcopy = *hdr;
    if (sh_image_create(&out, hdr->format, hdr->width, hdr->height) != SH_OK) goto done;
    cache->params = cfg.method;
    sh_warp_options_default(&cache->wopts);
    if (cfg.grid > 0) cache->wopts.grid_spacing = (int)cfg.grid;
    cache->width = hdr->width;
    cache->height = hdr->height;
    if (cfg.points[0]) {
        if (sh_points_read(cfg.points, &points) != SH_OK) {
            fprintf(stderr, "stillheart run: [run] points: %s\n", sh_error_message());
            goto done;
        }
    } else {
        sh_detector_options dopt;
        sh_detector_options_default(&dopt);
        dopt.family = cfg.family;
        dopt.window_decimate = 2; /* ~2.4x cheaper, as accurate on ~100 px tags (detect.h) */
        if (sh_detector_create(&dopt, &det) != SH_OK) {
            fprintf(stderr, "stillheart run: [detect] family: %s\n", sh_error_message());
            goto done;
        }
    }
    if (sh_warp_create(cfg.threads, &warp) != SH_OK) { fprintf(stderr, "stillheart run: [run] threads: %s\n", sh_error_message()); goto done; }
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
    if (cfg.record[0] && sh_y4m_writer_open(cfg.record, &hcopy, &rec) != SH_OK) {
        fprintf(stderr, "stillheart run: [sink] record: %s\n", sh_error_message());
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
    int have_ref = 0, want_ref = 0;
    int ref_frame_index = -1;
    int64_t last_seen[MAX_MARKERS];
    sh_point held[MAX_MARKERS]; /* last position of each reference marker (index as in ref) */
    sh_point cur[MAX_MARKERS];
    int ids[MAX_MARKERS];
    double cur_xy[2 * MAX_MARKERS];
    long rss_start = 0, rss_max = 0;
    size_t nlat = 0;
    int det_err_once = 0, warp_err_once = 0;
    uint32_t last_status_shown = 99;
    sh_window win[SH_DETECT_MAX_WINDOWS];
    uint64_t last_scan = 0;
    int64_t last_frame_ns = 0, prev_now = 0; /* when the previous frame's markers were seen */
    char last_reason[44] = "";

    while (!sig_stop) {
        if (sig_hup) {
            sig_hup = 0;
            sh_config fresh;
            if (load_config(&fresh, ro.config_path, argc, argv, err) != SH_OK) {
                logm("ERROR", "main", "reload refused, keeping the running config: %s", err);
            } else {
                /* live: gating, pacing; the rest needs a restart */
                int restart = strcmp(fresh.source, cfg.source) || strcmp(fresh.sink, cfg.sink) ||
                              strcmp(fresh.method_name, cfg.method_name) || fresh.threads != cfg.threads ||
                              strcmp(fresh.points, cfg.points) || fresh.slots != cfg.slots ||
                              memcmp(&fresh.method, &cfg.method, sizeof cfg.method) ||
                              strcmp(fresh.family, cfg.family) || strcmp(fresh.record, cfg.record);
                cfg.min_markers = fresh.min_markers;
                cfg.max_residual_px = fresh.max_residual_px;
                cfg.max_sigma_px = fresh.max_sigma_px;
                cfg.dropout_ms = fresh.dropout_ms;
                memcpy(cfg.ids, fresh.ids, sizeof cfg.ids);
                run_source_set_pacing(src, fresh.realtime, fresh.loop);
                cfg.realtime = fresh.realtime;
                cfg.loop = fresh.loop;
                logm("INFO", "main", "config reloaded (gating, ids, pacing)%s",
                     restart ? "; source/sink/method/threads changes take effect at restart" : "");
            }
        }
        if (sig_usr1) {
            sig_usr1 = 0;
            want_ref = 1;
            logm("INFO", "main", "new reference requested");
        }
        const run_frame *s = run_source_take(src, 100);
        int64_t now = mono_ns();
        if (s && published) last_frame_ns = prev_now;
        if (!s) {
            if (run_source_ended(src)) break;
            continue;
        }
        /* markers of this frame */
        int ncur = 0;
        if (cfg.points[0]) {
            int cnt;
            const sh_point *rows = sh_points_frame(&points, s->index, &cnt);
            for (int i = 0; i < cnt && ncur < MAX_MARKERS; i++)
                if (rows[i].id >= 0 && rows[i].id < SH_CONFIG_MAX_IDS && isfinite(rows[i].x) && isfinite(rows[i].y))
                    cur[ncur++] = rows[i];
        } else {
            /* windows around the markers' last positions; a full-frame scan before the
             * reference and, at most every SCAN_EVERY frames, while a marker is missing */
            int nd = 0, nwin = 0, missing = 0;
            if (have_ref)
                for (int r = 0; r < cache->nref && nwin < SH_DETECT_MAX_WINDOWS; r++) {
                    missing += last_seen[r] != last_frame_ns;
                    win[nwin].x = (int)held[r].x - WIN_HALF;
                    win[nwin].y = (int)held[r].y - WIN_HALF;
                    win[nwin].width = win[nwin].height = 2 * WIN_HALF;
                    nwin++;
                }
            int full = !have_ref || (missing && published - last_scan >= SCAN_EVERY);
            if (full) last_scan = published;
            sh_status dst = full ? sh_detector_detect(det, &s->img, dets, MAX_DET, &nd)
                                 : sh_detector_detect_windows(det, &s->img, win, nwin, dets, MAX_DET, &nd);
            if (dst != SH_OK) {
                LOG_ONCE(det_err_once, "ERROR", "main", "detect: %s", sh_error_message());
                nd = 0;
            } else {
                det_err_once = 0;
            }
            ncur = detections_to_points(&cfg, dets, nd < MAX_DET ? nd : MAX_DET, cur);
        }
        /* reference: the first good frame (all ids present... at least min_markers), frame N, or on request */
        int take_ref = !have_ref && ((cfg.reference_frame == 0 && ncur >= cfg.min_markers) ||
                                     (cfg.reference_frame > 0 && s->index == cfg.reference_frame - 1));
        if (want_ref && ncur >= cfg.min_markers) take_ref = 1;
        if (take_ref) {
            /* The new reference's models are built lazily by the cache on this thread; the old
             * ones are dropped here. (docs/daemon.md: building them off-thread is left to do.) */
            for (int i = 0; i < CACHE_SLOTS; i++) slot_clear(&cache->slot[i]);
            memcpy(cache->ref, cur, sizeof(sh_point) * (size_t)ncur);
            cache->nref = ncur;
            for (int i = 0; i < ncur; i++) { held[i] = cur[i]; last_seen[i] = now; }
            have_ref = 1;
            want_ref = 0;
            ref_frame_index = s->index;
            logm("INFO", "main", "reference: frame %d, %d markers", s->index, ncur);
        }
        sh_display_frame_info info;
        memset(&info, 0, sizeof info);
        info.capture_ns = s->avail_ns;
        info.residual_px = NAN;
        const sh_image *shown = &s->img;
        uint32_t status = SH_DISPLAY_RAW;
        if (!have_ref) {
            snprintf(info.reason, sizeof info.reason, "no reference yet (%d markers)", ncur);
        } else {
            /* match to the reference; markers missing for up to dropout_ms are held at their
             * last position (degraded); longer, they leave the set */
            int n = 0, held_used = 0;
            for (int r = 0, c = 0; r < cache->nref; r++) {
                while (c < ncur && cur[c].id < cache->ref[r].id) c++;
                if (c < ncur && cur[c].id == cache->ref[r].id) {
                    held[r] = cur[c];
                    last_seen[r] = now;
                } else if ((now - last_seen[r]) / 1000000 > cfg.dropout_ms) {
                    continue;
                } else {
                    held_used++;
                }
                ids[n] = cache->ref[r].id;
                cur_xy[2 * n] = held[r].x;
                cur_xy[2 * n + 1] = held[r].y;
                n++;
            }
            int finite = 1;
            for (int i = 0; i < 2 * n; i++) finite &= isfinite(cur_xy[i]) != 0;
            sh_warp_model *model = NULL;
            info.markers_used = (uint32_t)n;
            if (n < cfg.min_markers || n < 3) {
                snprintf(info.reason, sizeof info.reason, "too few markers (%d < %d)", n, cfg.min_markers);
            } else if (!finite) {
                snprintf(info.reason, sizeof info.reason, "non-finite marker position");
            } else if (cache_get(cache, ids, n, &model) != SH_OK || sh_warp_model_update(model, cur_xy) != SH_OK ||
                       sh_warp_apply(warp, model, &s->img, &out) != SH_OK) {
                LOG_ONCE(warp_err_once, "ERROR", "main", "warp: %s", sh_error_message());
                snprintf(info.reason, sizeof info.reason, "model failed");
            } else {
                warp_err_once = 0;
                shown = &out;
                if (held_used) {
                    status = SH_DISPLAY_DEGRADED;
                    snprintf(info.reason, sizeof info.reason, "dropout: %d markers held", held_used);
                } else {
                    status = SH_DISPLAY_STABILIZED;
                }
            }
        }
        info.status = status;
        if (status == SH_DISPLAY_RAW) raw_count++;
        if (status == SH_DISPLAY_DEGRADED) degraded_count++;
        if (status != last_status_shown || (status != SH_DISPLAY_STABILIZED && strncmp(last_reason, info.reason, 12))) {
            static const char *names[] = {"raw", "stabilized", "degraded"};
            logm(status == SH_DISPLAY_RAW && have_ref ? "WARN" : "INFO", "main", "frame %d: %s%s%s", s->index,
                 names[status], info.reason[0] ? ": " : "", info.reason);
            last_status_shown = status;
            memcpy(last_reason, info.reason, sizeof last_reason);
        }
        if (disp) {
            info.publish_ns = mono_ns();
            if (sh_display_writer_publish(disp, shown, &info) != SH_OK)
                logm("ERROR", "main", "publish: %s", sh_error_message());
        }
        if (rec && sh_y4m_writer_write(rec, shown) != SH_OK) {
            logm("ERROR", "main", "[sink] record: %s; recording stopped", sh_error_message());
            sh_y4m_writer_close(rec);
            rec = NULL;
        }
        int64_t done_ns = mono_ns();
        if (nlat < LAT_CAP) lat[nlat++] = (float)((double)(done_ns - s->avail_ns) / 1e6);
        published++;
        if (published == 30) rss_start = rss_kb();
        if ((published & 63) == 0) { long r = rss_kb(); if (r > rss_max) rss_max = r; }
        /* systemd: STATUS each second, WATCHDOG only while frames progress */
        if (done_ns - last_status >= 1000000000) {
            double fps = (double)(published - published_at_status) * 1e9 / (double)(done_ns - last_status);
            static const char *names[] = {"raw", "stabilized", "degraded"};
            sh_notifyf("STATUS=%.1f fps, %u markers, %s%s%s, %llu dropped", fps, info.markers_used,
                       names[status], info.reason[0] ? " " : "", info.reason, (unsigned long long)run_source_dropped(src));
            last_status = done_ns;
            published_at_status = published;
        }
        if (wd_usec && done_ns - last_ping >= (int64_t)wd_usec * 500 && published > published_at_ping) {
            sh_notify("WATCHDOG=1");
            last_ping = done_ns;
            published_at_ping = published;
        }
        prev_now = now;
        if (ro.max_frames && published >= (uint64_t)ro.max_frames) break;
    }
    sh_notify("STOPPING=1");
    sig_stop = 1;
    rc = 0;
    (void)ref_frame_index;
    if (ro.stats || !log_quiet) {
        qsort(lat, nlat, sizeof *lat, cmp_float);
        double med = nlat ? lat[nlat / 2] : 0, p99 = nlat ? lat[(size_t)((double)(nlat - 1) * 0.99)] : 0,
               mx = nlat ? lat[nlat - 1] : 0;
        long r = rss_kb();
        if (r > rss_max) rss_max = r;
        fprintf(ro.stats ? stdout : stderr,
                "stats: %llu published (%llu raw, %llu degraded), %llu dropped, latency ms median %.2f "
                "p99 %.2f max %.2f, RSS kB start %ld max %ld end %ld, %d models built\n",
                (unsigned long long)published, (unsigned long long)raw_count,
                (unsigned long long)degraded_count, (unsigned long long)run_source_dropped(src), med, p99, mx,
                rss_start, rss_max, r, cache->builds);
    }
done:
    sig_stop = 1;
    run_source_destroy(src);
    if (rec && sh_y4m_writer_close(rec) != SH_OK) { logm("ERROR", "main", "[sink] record: %s", sh_error_message()); rc = 1; }
    if (disp) sh_display_writer_destroy(disp, 0); /* marked closed; readers see the end */
    if (cache) for (int i = 0; i < CACHE_SLOTS; i++) slot_clear(&cache->slot[i]);
    free(cache);
    free(dets);
    free(lat);
    sh_warp_destroy(warp);
    sh_detector_destroy(det);
    sh_points_destroy(&points);
    sh_image_destroy(&out);
    return rc;
}
