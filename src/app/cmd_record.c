/* stillheart record: what the cameras deliver, stored as delivered (record.h), grouped into
 * frame sets (sync.h); and a recording converted to Y4M for other tools. */
#include <getopt.h>
#include <poll.h>
#include <signal.h>
#include <stdlib.h>
#include <string.h>

#include "app.h"
#include "stillheart/config.h"
#include "stillheart/daemon.h"
#include "stillheart/log.h"
#include "stillheart/pixconv.h"
#include "stillheart/record.h"
#include "stillheart/source.h"
#include "stillheart/sync.h"
#include "stillheart/y4m.h"

#define MAX_SOURCES SH_SYNC_MAX_CAMERAS

static void usage(FILE *out)
{
    fprintf(out,
        "usage: stillheart record --source SPEC [--source SPEC ...] --frames N [OPTIONS] OUT/\n"
        "       stillheart record --config FILE --frames N OUT/\n"
        "       stillheart record --to-y4m REC OUT.y4m [--camera C]\n\n"
        "Records what the cameras deliver: raw frames in the format they come in, their\n"
        "sequence numbers and capture timestamps, and the frame sets they form, in OUT/ (an\n"
        "append-only file: a killed recorder or a full disk loses at most the frame being\n"
        "written). Replay a recording with the source spec rec:OUT/ (camera chosen by index).\n"
        "The cameras come from the command line (the first --source is camera 0, the next\n"
        "camera 1, ...) or from the daemon's config file (--config: its [cameraN], [trigger] and\n"
        "[source] keys, as `stillheart run` reads them; firmware-config/stillheart.ini).\n\n"
        "sources:\n"
        "  v4l2:/dev/videoN   a V4L2 camera\n"
        "  y4m:FILE           a Y4M file replayed at its frame rate (--fast: at once)\n"
        "  rec:DIR            camera 0 of a recording\n\n"
        "options:\n"
        "  --frames N         frames per camera to record (required)\n"
        "  --config FILE      cameras, formats, controls, sets and trigger from the INI file\n"
        "                     (then none of the camera options below)\n"
        "  --format F         ask the cameras for GREY, YUYV, NV12, RGB24, BGR24 or MJPEG\n"
        "  --size WxH         ask the cameras for this size\n"
        "  --fps N            ask the cameras for this frame rate\n"
        "  --exposure V --gain V --white-balance K   camera controls (manual)\n"
        "  --tolerance-ms T   frames of one set lie within T ms of each other (default 5)\n"
        "  --max-wait-ms T    a set waits this long for a missing camera (default 100)\n"
        "  --fast             replay sources as fast as possible\n"
        "  --trigger-out CHIP:LINE[:low]  drive the cameras' trigger line at --fps (libgpiod)\n"
        "  --trigger-in CHIP:LINE[:low]   timestamp a strobe or master trigger line's edges\n"
        "  --pulse-ms T       trigger pulse width (default 1)\n"
        "  --trigger-offset-ms T  a frame's timestamp minus its trigger edge, expected (default 0)\n"
        "  --to-y4m REC OUT.y4m  convert camera --camera C (default 0) of recording REC to Y4M\n"
        "                     (a damaged recording: every good record converted, then what was\n"
        "                     lost said and exit status 1)\n"
        "  --help             this text\n");
}

static volatile sig_atomic_t stop_requested;
static void on_signal(int sig)
{
    (void)sig;
    stop_requested = 1;
}

static int to_y4m(const char *rec_path, const char *out_path, int camera)
{
    sh_rec_reader *r;
    if (sh_rec_reader_open(rec_path, &r) != SH_OK) {
        sh_log_error("%s", sh_error_message());
        return 1;
    }
    const sh_rec_stream *s = sh_rec_reader_stream(r, camera);
    if (!s) {
        sh_log_error("%s: no camera %d", rec_path, camera);
        sh_rec_reader_close(r);
        return 1;
    }
    sh_y4m_header h;
    sh_daemon_y4m_header(s->format, s->width, s->height, s->fps_num, s->fps_den, &h);
    int rc = 1;
    sh_image img;
    sh_pixconv *conv = NULL;
    sh_y4m_writer *w = NULL;
    if (sh_image_create(&img, h.format, h.width, h.height) != SH_OK ||
        sh_pixconv_create(h.width, h.height, &conv) != SH_OK || sh_y4m_writer_open(out_path, &h, &w) != SH_OK) {
        sh_log_error("%s", sh_error_message());
        goto out;
    }
    sh_rec_record rec;
    long frames = 0, bad = 0;
    while (sh_rec_reader_next(r, &rec) == SH_OK) {
        if (rec.type != SH_REC_FRAME || rec.camera != camera) continue;
        if (sh_pixconv_convert(conv, &rec.raw, &img) != SH_OK) {
            sh_log_warn("%s: frame %llu skipped: %s", rec_path,
                        (unsigned long long)rec.sequence, sh_error_message());
            bad++;
            continue;
        }
        if (sh_y4m_writer_write(w, &img) != SH_OK) {
            sh_log_error("%s", sh_error_message());
            goto out;
        }
        frames++;
    }
    sh_log_info("%ld frames of camera %d written to %s (%ld not convertible)", frames, camera, out_path, bad);
    rc = 0;
    if (sh_rec_reader_lost_bytes(r)) { /* every good record is converted; the loss is still an error */
        sh_log_warn("WARNING: %s is damaged: %llu record(s) skipped%s, %llu bytes lost; the records around the "
                    "damage were converted",
                rec_path, (unsigned long long)sh_rec_reader_skipped(r),
                sh_rec_reader_truncated(r) ? " and a torn last record" : "",
                (unsigned long long)sh_rec_reader_lost_bytes(r));
        rc = 1;
    }
out:
    if (w && sh_y4m_writer_close(w) != SH_OK) {
        sh_log_error("%s", sh_error_message());
        rc = 1;
    }
    sh_pixconv_destroy(conv);
    sh_image_destroy(&img);
    sh_rec_reader_close(r);
    return rc;
}

int cmd_record(int argc, char **argv)
{
    sh_log_setup(SH_LOG_TOOL, "stillheart record", SH_LOG_INFO);
    static const struct option longopts[] = {
        {"source", required_argument, 0, 's'},   {"frames", required_argument, 0, 'n'},
        {"config", required_argument, 0, 'c'},   {"format", required_argument, 0, 'f'},
        {"size", required_argument, 0, 'z'},     {"fps", required_argument, 0, 'r'},
        {"exposure", required_argument, 0, 'e'}, {"gain", required_argument, 0, 'g'},
        {"white-balance", required_argument, 0, 'w'}, {"tolerance-ms", required_argument, 0, 't'},
        {"max-wait-ms", required_argument, 0, 'm'}, {"fast", no_argument, 0, 'F'},
        {"to-y4m", required_argument, 0, 'y'},   {"camera", required_argument, 0, 'C'},
        {"trigger-out", required_argument, 0, 'O'}, {"trigger-in", required_argument, 0, 'I'},
        {"pulse-ms", required_argument, 0, 'p'}, {"trigger-offset-ms", required_argument, 0, 'x'},
        {"help", no_argument, 0, 'h'},           {0, 0, 0, 0}};
    const char *specs[MAX_SOURCES];
    int nspec = 0, frames = 0, camera = 0, tol_ms = 5, wait_ms = 100;
    const char *to_y4m_rec = NULL, *trigger_spec = NULL, *config_path = NULL;
    int camera_opts = 0; /* options the config file gives instead */
    int trigger_out = 0, pulse_ms = 1, offset_ms = 0;
    sh_source_options o;
    sh_source_options_default(&o);
    optind = 1;
    int ch;
    while ((ch = getopt_long(argc, argv, "", longopts, NULL)) != -1) {
        camera_opts += strchr("sfzregwtmFOIpx", ch) != NULL;
        switch (ch) {
        case 's':
            if (nspec >= MAX_SOURCES) {
                fprintf(stderr, "--source: at most %d cameras\n", MAX_SOURCES);
                return 2;
            }
            specs[nspec++] = optarg;
            break;
        case 'n': if (!app_parse_int("--frames", optarg, 1, 100000000, &frames)) return 2; break;
        case 'c': config_path = optarg; break;
        case 'f': {
            sh_rawfmt f;
            if (sh_rawfmt_parse(optarg, &f) != SH_OK) {
                fprintf(stderr, "--format: %s\n", sh_error_message());
                return 2;
            }
            o.format = (int)f;
            break;
        }
        case 'z':
            if (sscanf(optarg, "%dx%d", &o.width, &o.height) != 2 || o.width <= 0 || o.height <= 0 ||
                o.width > SH_IMAGE_MAX_SIZE || o.height > SH_IMAGE_MAX_SIZE) {
                fprintf(stderr, "--size: WxH, not '%s'\n", optarg);
                return 2;
            }
            break;
        case 'r':
            if (!app_parse_int("--fps", optarg, 1, 1000, &o.fps_num)) return 2;
            o.fps_den = 1;
            break;
        case 'e': if (!app_parse_int("--exposure", optarg, 0, 100000000, &o.exposure)) return 2; break;
        case 'g': if (!app_parse_int("--gain", optarg, 0, 100000000, &o.gain)) return 2; break;
        case 'w': if (!app_parse_int("--white-balance", optarg, 1000, 20000, &o.white_balance)) return 2; break;
        case 't': if (!app_parse_int("--tolerance-ms", optarg, 1, 1000, &tol_ms)) return 2; break;
        case 'm': if (!app_parse_int("--max-wait-ms", optarg, 1, 100000, &wait_ms)) return 2; break;
        case 'F': o.realtime = 0; break;
        case 'y': to_y4m_rec = optarg; break;
        case 'C': if (!app_parse_int("--camera", optarg, 0, MAX_SOURCES - 1, &camera)) return 2; break;
        case 'O': trigger_spec = optarg, trigger_out = 1; break;
        case 'I': trigger_spec = optarg, trigger_out = 0; break;
        case 'p': if (!app_parse_int("--pulse-ms", optarg, 1, 1000, &pulse_ms)) return 2; break;
        case 'x': if (!app_parse_int("--trigger-offset-ms", optarg, -1000, 1000, &offset_ms)) return 2; break;
        case 'h': usage(stdout); return 0;
        default: usage(stderr); return 2;
        }
    }
    if (to_y4m_rec) {
        if (optind != argc - 1) {
            fprintf(stderr, "stillheart record --to-y4m REC OUT.y4m: one output file\n");
            return 2;
        }
        return to_y4m(to_y4m_rec, argv[optind], camera);
    }
    if (config_path && camera_opts) {
        sh_log_error("--config gives the cameras, their formats and controls, the sets and the "
                        "trigger ([cameraN], [source], [trigger]); set them there, not with --source, --format, ...");
        return 2;
    }
    static sh_config cfg; /* the specs and the trigger chip point into it */
    if (config_path) {
        char err[SH_CONFIG_ERR];
        sh_config_default(&cfg);
        if (sh_config_load_file(&cfg, config_path, err) != SH_OK || sh_config_check(&cfg, err) != SH_OK) {
            sh_log_error("%s", err);
            return 2;
        }
        nspec = sh_config_cameras(&cfg);
        for (int i = 0; i < nspec; i++) specs[i] = cfg.camera[i].spec;
    }
    if (!nspec || !frames || optind != argc - 1) {
        usage(stderr);
        return 2;
    }
    const char *out_dir = argv[optind];
    char chip[64] = "";
    sh_gpio_options go = {chip, 0, 0, trigger_out, 0, (int64_t)pulse_ms * 1000000};
    int have_trigger = trigger_spec != NULL;
    if (trigger_spec) {
        const char *c1 = strchr(trigger_spec, ':');
        char *end;
        if (!c1 || c1 == trigger_spec || (size_t)(c1 - trigger_spec) >= sizeof chip) {
            fprintf(stderr, "--trigger-%s: CHIP:LINE[:low], not '%s'\n", trigger_out ? "out" : "in", trigger_spec);
            return 2;
        }
        memcpy(chip, trigger_spec, (size_t)(c1 - trigger_spec));
        long line = strtol(c1 + 1, &end, 10);
        if (end == c1 + 1 || line < 0 || line > 1023 || (*end && strcmp(end, ":low"))) {
            fprintf(stderr, "--trigger-%s: CHIP:LINE[:low], not '%s'\n", trigger_out ? "out" : "in", trigger_spec);
            return 2;
        }
        go.line = (unsigned)line;
        go.active_low = *end != 0;
        if (trigger_out) {
            if (o.fps_num <= 0) {
                fprintf(stderr, "--trigger-out: give the frame rate with --fps\n");
                return 2;
            }
            go.period_ns = 1000000000LL / o.fps_num;
        }
    }
    sh_gpio_trigger *trig = NULL;

    sh_source *src[MAX_SOURCES] = {0};
    sh_rec_writer *w = NULL;
    sh_sync *sync = NULL;
    int rc = 1;
    long done[MAX_SOURCES] = {0};
    int ended[MAX_SOURCES] = {0};
    uint64_t damaged[MAX_SOURCES] = {0}; /* replays: damage already reported */
    for (int i = 0; i < nspec; i++) {
        sh_source_options oi = o;
        oi.camera = i;
        if (!strncmp(specs[i], "rec:", 4)) oi.camera = 0;
        if (config_path) sh_daemon_camera_options(&cfg, i, &oi); /* rec:DIR: its camera i */
        if (sh_source_open(specs[i], &oi, &src[i]) != SH_OK) {
            sh_log_error("%s%d%s: %s", config_path ? "[camera" : "camera ", i,
                         config_path ? "] spec" : "", sh_error_message());
            goto out;
        }
    }
    sh_sync_options so = {nspec, (int64_t)tol_ms * 1000000, (int64_t)wait_ms * 1000000, (int64_t)offset_ms * 1000000};
    if (config_path) { /* the defaults follow camera 0's rate, as in the daemon */
        int num = 0, den = 0;
        sh_source_format(src[0], NULL, NULL, NULL, &num, &den);
        sh_daemon_sync_options(&cfg, nspec, num, den, &so);
        have_trigger = sh_daemon_gpio_options(&cfg, num, den, &go);
        trigger_out = go.output;
    }
    if (have_trigger && sh_gpio_trigger_open(&go, &trig) != SH_OK) {
        sh_log_error("%s", sh_error_message());
        goto out;
    }
    if (sh_sync_create(&so, &sync) != SH_OK || sh_rec_writer_create(out_dir, &w) != SH_OK) {
        sh_log_error("%s", sh_error_message());
        goto out;
    }
    for (int i = 0; i < nspec; i++) {
        sh_rec_stream s;
        memset(&s, 0, sizeof s);
        s.camera = i;
        sh_source_format(src[i], &s.format, &s.width, &s.height, &s.fps_num, &s.fps_den);
        s.stride = sh_source_stride(src[i]);
        snprintf(s.source, sizeof s.source, "%s", specs[i]);
        if (sh_rec_writer_stream(w, &s) != SH_OK) {
            sh_log_error("%s", sh_error_message());
            goto out;
        }
        sh_log_info("camera %d: %s, %dx%d %s at %d/%d fps", i, specs[i], s.width, s.height,
                    sh_rawfmt_name(s.format), s.fps_num, s.fps_den);
    }
    /* started back to back, after the stream records are written: a replay's schedule starts at
     * its start, so the gap between two starts would offset the cameras' stamps */
    for (int i = 0; i < nspec; i++)
        if (sh_source_start(src[i]) != SH_OK) {
            sh_log_error("%s", sh_error_message());
            goto out;
        }
    if (trig && sh_gpio_trigger_start(trig) != SH_OK) {
        sh_log_error("%s", sh_error_message());
        goto out;
    }
    struct sigaction sa;
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = on_signal;
    sigaction(SIGINT, &sa, NULL);
    sigaction(SIGTERM, &sa, NULL);
    for (;;) {
        int active = 0;
        for (int i = 0; i < nspec; i++) active += !ended[i] && done[i] < frames;
        if (!active || stop_requested) break;
        struct pollfd p[MAX_SOURCES + 1];
        for (int i = 0; i < nspec; i++) {
            p[i].fd = ended[i] || done[i] >= frames ? -1 : sh_source_fd(src[i]);
            p[i].events = POLLIN;
            p[i].revents = 0;
        }
        p[nspec].fd = trig ? sh_gpio_trigger_fd(trig) : -1;
        p[nspec].events = POLLIN;
        p[nspec].revents = 0;
        poll(p, (nfds_t)nspec + 1, 100);
        if (trig) {
            int64_t edge;
            int got;
            if (sh_gpio_trigger_service(trig, &edge, &got) != SH_OK) {
                sh_log_error("%s", sh_error_message());
                goto out;
            }
            if (got) sh_sync_trigger(sync, edge);
        }
        for (int i = 0; i < nspec; i++) {
            if (ended[i] || done[i] >= frames) continue;
            sh_source_frame f;
            int got;
            sh_status st = sh_source_dequeue(src[i], 0, &f, &got);
            sh_source_stats ss;
            sh_source_get_stats(src[i], &ss);
            if (ss.damaged != damaged[i]) { /* a replay went past damage (or ends at it: then the error follows) */
                damaged[i] = ss.damaged;
                sh_log_warn("WARNING: %s", sh_source_damage(src[i]));
            }
            if (st == SH_EEOF) {
                ended[i] = 1;
                continue;
            }
            if (st != SH_OK) {
                sh_log_error("%s", sh_error_message());
                goto out;
            }
            if (!got) continue;
            st = sh_rec_writer_frame(w, i, f.sequence, f.timestamp_ns, &f.raw);
            sh_sync_disposition d;
            if (st == SH_OK) st = sh_sync_push(sync, i, f.sequence, f.timestamp_ns, NULL, &d);
            sh_source_release(src[i], &f);
            if (st != SH_OK) goto write_failed;
            done[i]++;
        }
        sh_frame_set set;
        while (sh_sync_pop(sync, &set))
            if (sh_rec_writer_set(w, &set) != SH_OK) goto write_failed;
    }
    sh_sync_flush(sync);
    sh_frame_set set;
    while (sh_sync_pop(sync, &set))
        if (sh_rec_writer_set(w, &set) != SH_OK) goto write_failed;
    sh_sync_stats ss;
    sh_sync_get_stats(sync, &ss);
    for (int i = 0; i < nspec; i++) {
        sh_source_stats st;
        sh_source_get_stats(src[i], &st);
        sh_log_info("camera %d: %ld frames recorded; %llu skipped as damaged, %llu dropped by the "
                    "driver, %llu losses, %llu reopens",
                    i, done[i], (unsigned long long)st.errors, (unsigned long long)st.drops,
                    (unsigned long long)st.losses, (unsigned long long)st.reopens);
    }
    sh_log_info("%llu sets (%llu incomplete), %llu late and %llu duplicate frames",
                (unsigned long long)ss.sets, (unsigned long long)ss.incomplete, (unsigned long long)ss.late,
                (unsigned long long)ss.duplicates);
    if (trig)
        sh_log_info("%llu trigger edges %s %s line %u", (unsigned long long)sh_gpio_trigger_edges(trig),
                    trigger_out ? "driven on" : "read from", go.chip, go.line);
    rc = stop_requested ? 130 : 0;
    goto out;
write_failed:
    sh_log_error("%s", sh_error_message());
out:
    if (w && sh_rec_writer_close(w) != SH_OK) {
        sh_log_error("%s", sh_error_message());
        rc = 1;
    }
    sh_gpio_trigger_close(trig);
    sh_sync_destroy(sync);
    for (int i = 0; i < nspec; i++) sh_source_close(src[i]);
    return rc;
}
