/* stillheart record: what the cameras deliver, stored as delivered (record.h), grouped into
 * frame sets (sync.h); and a recording converted to Y4M for other tools. */
#include <getopt.h>
#include <poll.h>
#include <signal.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

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

static const sh_cli cli = {"stillheart record"};

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
        "  --sync-ms T        make the recording durable (fdatasync) every T ms, so power loss\n"
        "                     loses at most about T ms (default: [sink] record_sync_ms with\n"
        "                     --config, else 1000; 0: after every record)\n"
        "  --to-y4m REC OUT.y4m  convert camera --camera C (default 0) of recording REC to Y4M\n"
        "                     (a damaged recording: every good record converted, then what was\n"
        "                     lost said and exit status 1); a progress line (MB of the\n"
        "                     recording read, ETA) on standard error when it is a terminal\n"
        SH_CLI_USAGE);
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
    /* the recording's frames of every camera in MB: the bytes behind the progress line's ETA */
    struct stat fst;
    char file[4096];
    snprintf(file, sizeof file, "%s/" SH_REC_FILE, rec_path);
    double read_mb = 0;
    sh_cli_progress progress;
    sh_cli_progress_start(&progress, "record --to-y4m",
                          stat(file, &fst) && stat(rec_path, &fst) ? 0 : (int)(fst.st_size >> 20), "MB");
    while (sh_rec_reader_next(r, &rec) == SH_OK) {
        if (rec.type == SH_REC_FRAME) { /* 40: the record's header */
            read_mb += (double)(rec.raw.bytes + 40) / (1 << 20);
            sh_cli_progress_update(&progress, (int)read_mb);
        }
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
    sh_cli_progress_end(&progress);
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

/* What the command line asks for, apart from the state of a recording (record_job). */
typedef struct {
    const char *specs[MAX_SOURCES];
    int nspec, frames, camera, tol_ms, wait_ms, sync_ms;
    const char *to_y4m_rec, *trigger_spec, *config_path, *out_dir;
    int camera_opts; /* options the config file gives instead */
    int trigger_out, pulse_ms, offset_ms;
    sh_source_options src;
} record_options;

/* The value options; 0 when the value was wrong (said on stderr). */
static int parse_value(record_options *o, int ch, const char *arg)
{
    switch (ch) {
    case 'n': return sh_cli_parse_int("--frames", arg, 1, 100000000, &o->frames);
    case 'f': {
        sh_rawfmt f;
        if (sh_rawfmt_parse(arg, &f) != SH_OK) {
            fprintf(stderr, "--format: %s\n", sh_error_message());
            return 0;
        }
        o->src.format = (int)f;
        return 1;
    }
    case 'z':
        if (sscanf(arg, "%dx%d", &o->src.width, &o->src.height) != 2 || o->src.width <= 0 || o->src.height <= 0 ||
            o->src.width > SH_IMAGE_MAX_SIZE || o->src.height > SH_IMAGE_MAX_SIZE) {
            fprintf(stderr, "--size: WxH, not '%s'\n", arg);
            return 0;
        }
        return 1;
    case 'r':
        o->src.fps_den = 1;
        return sh_cli_parse_int("--fps", arg, 1, 1000, &o->src.fps_num);
    case 'e': return sh_cli_parse_int("--exposure", arg, 0, 100000000, &o->src.exposure);
    case 'g': return sh_cli_parse_int("--gain", arg, 0, 100000000, &o->src.gain);
    case 'w': return sh_cli_parse_int("--white-balance", arg, 1000, 20000, &o->src.white_balance);
    case 't': return sh_cli_parse_int("--tolerance-ms", arg, 1, 1000, &o->tol_ms);
    case 'm': return sh_cli_parse_int("--max-wait-ms", arg, 1, 100000, &o->wait_ms);
    case 'C': return sh_cli_parse_int("--camera", arg, 0, MAX_SOURCES - 1, &o->camera);
    case 'p': return sh_cli_parse_int("--pulse-ms", arg, 1, 1000, &o->pulse_ms);
    case 'x': return sh_cli_parse_int("--trigger-offset-ms", arg, -1000, 1000, &o->offset_ms);
    case 'S': return sh_cli_parse_int("--sync-ms", arg, 0, 60000, &o->sync_ms);
    }
    return 0;
}

/* -1: go on; else the exit status (0 after --help). */
static int parse_options(int argc, char **argv, record_options *o)
{
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
        {"sync-ms", required_argument, 0, 'S'},  SH_CLI_OPTIONS,
        {0, 0, 0, 0}};
    memset(o, 0, sizeof *o);
    o->tol_ms = 5, o->wait_ms = 100, o->pulse_ms = 1, o->sync_ms = -1;
    sh_source_options_default(&o->src);
    optind = 1;
    opterr = 0;
    int ch;
    while ((ch = getopt_long(argc, argv, ":h", longopts, NULL)) != -1) {
        o->camera_opts += ch > 0 && ch < 0x100 && strchr("sfzregwtmFOIpx", ch) != NULL;
        switch (ch) {
        case 's':
            if (o->nspec >= MAX_SOURCES) {
                fprintf(stderr, "--source: at most %d cameras\n", MAX_SOURCES);
                return 2;
            }
            o->specs[o->nspec++] = optarg;
            break;
        case 'c': o->config_path = optarg; break;
        case 'F': o->src.realtime = 0; break;
        case 'y': o->to_y4m_rec = optarg; break;
        case 'O': o->trigger_spec = optarg, o->trigger_out = 1; break;
        case 'I': o->trigger_spec = optarg, o->trigger_out = 0; break;
        case 'h': usage(stdout); return 0;
        case '?': case ':': case SH_CLI_VERSION: case SH_CLI_LOG_LEVEL: case SH_CLI_QUIET: {
            int rc = sh_cli_option(&cli, ch, argv);
            if (rc >= 0) return rc;
            break;
        }
        default: if (!parse_value(o, ch, optarg)) return 2;
        }
    }
    return -1;
}

/* --trigger-out/--trigger-in CHIP:LINE[:low] into go (its chip pointing into chip[64]); 0 when
 * the spec is wrong (said on stderr). */
static int parse_trigger(const record_options *o, sh_gpio_options *go, char *chip)
{
    const char *spec = o->trigger_spec, *c1 = strchr(spec, ':'), *dir = o->trigger_out ? "out" : "in";
    char *end;
    if (!c1 || c1 == spec || (size_t)(c1 - spec) >= 64) {
        fprintf(stderr, "--trigger-%s: CHIP:LINE[:low], not '%s'\n", dir, spec);
        return 0;
    }
    memcpy(chip, spec, (size_t)(c1 - spec));
    chip[c1 - spec] = 0;
    long line = strtol(c1 + 1, &end, 10);
    if (end == c1 + 1 || line < 0 || line > 1023 || (*end && strcmp(end, ":low"))) {
        fprintf(stderr, "--trigger-%s: CHIP:LINE[:low], not '%s'\n", dir, spec);
        return 0;
    }
    go->line = (unsigned)line;
    go->active_low = *end != 0;
    if (o->trigger_out) {
        if (o->src.fps_num <= 0) {
            fprintf(stderr, "--trigger-out: give the frame rate with --fps\n");
            return 0;
        }
        go->period_ns = 1000000000LL / o->src.fps_num;
    }
    return 1;
}

/* A recording being made: the cameras, their sets, the trigger and the writer. */
typedef struct {
    const record_options *opt;
    const sh_config *cfg; /* --config; NULL: the command line's cameras */
    int nspec, have_trigger, trigger_out;
    char chip[64];
    sh_gpio_options go;
    sh_source *src[MAX_SOURCES];
    sh_gpio_trigger *trig;
    sh_rec_writer *w;
    sh_sync *sync;
    long done[MAX_SOURCES];
    int ended[MAX_SOURCES];
    uint64_t damaged[MAX_SOURCES]; /* replays: damage already reported */
} record_job;

/* Opens the cameras, the trigger, the sets and the writer; 0 (said) on failure. */
static int job_open(record_job *j)
{
    const record_options *o = j->opt;
    for (int i = 0; i < j->nspec; i++) {
        sh_source_options oi = o->src;
        oi.camera = i;
        if (!strncmp(o->specs[i], "rec:", 4)) oi.camera = 0;
        if (j->cfg) sh_daemon_camera_options(j->cfg, i, &oi); /* rec:DIR: its camera i */
        if (sh_source_open(o->specs[i], &oi, &j->src[i]) != SH_OK) {
            sh_log_error("%s%d%s: %s", j->cfg ? "[camera" : "camera ", i, j->cfg ? "] spec" : "", sh_error_message());
            return 0;
        }
    }
    sh_sync_options so = {j->nspec, (int64_t)o->tol_ms * 1000000, (int64_t)o->wait_ms * 1000000,
                          (int64_t)o->offset_ms * 1000000};
    if (j->cfg) { /* the defaults follow camera 0's rate, as in the daemon */
        int num = 0, den = 0;
        sh_source_format(j->src[0], NULL, NULL, NULL, &num, &den);
        sh_daemon_sync_options(j->cfg, j->nspec, num, den, &so);
        j->have_trigger = sh_daemon_gpio_options(j->cfg, num, den, &j->go);
        j->trigger_out = j->go.output;
    }
    int sync_ms = o->sync_ms >= 0 ? o->sync_ms : j->cfg ? j->cfg->record_sync_ms : 1000;
    if ((j->have_trigger && sh_gpio_trigger_open(&j->go, &j->trig) != SH_OK) ||
        sh_sync_create(&so, &j->sync) != SH_OK || sh_rec_writer_create(o->out_dir, &j->w) != SH_OK ||
        sh_rec_writer_set_sync(j->w, sync_ms) != SH_OK) {
        sh_log_error("%s", sh_error_message());
        return 0;
    }
    for (int i = 0; i < j->nspec; i++) {
        sh_rec_stream s;
        memset(&s, 0, sizeof s);
        s.camera = i;
        sh_source_format(j->src[i], &s.format, &s.width, &s.height, &s.fps_num, &s.fps_den);
        s.stride = sh_source_stride(j->src[i]);
        snprintf(s.source, sizeof s.source, "%s", o->specs[i]);
        if (sh_rec_writer_stream(j->w, &s) != SH_OK) {
            sh_log_error("%s", sh_error_message());
            return 0;
        }
        sh_log_info("camera %d: %s, %dx%d %s at %d/%d fps", i, o->specs[i], s.width, s.height,
                    sh_rawfmt_name(s.format), s.fps_num, s.fps_den);
    }
    /* started after the stream records are written, every replay's schedule at one instant: a
     * gap between two starts would offset the cameras' stamps */
    int64_t t0 = sh_monotonic_ns();
    for (int i = 0; i < j->nspec; i++)
        if (sh_source_start_at(j->src[i], t0) != SH_OK) {
            sh_log_error("%s", sh_error_message());
            return 0;
        }
    if (j->trig && sh_gpio_trigger_start(j->trig) != SH_OK) {
        sh_log_error("%s", sh_error_message());
        return 0;
    }
    return 1;
}

/* Takes camera i's next frame, if there is one, into the recording and the sets; 0 (said) on a
 * camera or write error. */
static int take_frame(record_job *j, int i)
{
    sh_source_frame f;
    int got;
    sh_status st = sh_source_dequeue(j->src[i], 0, &f, &got);
    sh_source_stats ss;
    sh_source_get_stats(j->src[i], &ss);
    if (ss.damaged != j->damaged[i]) { /* a replay went past damage (or ends at it: then the error follows) */
        j->damaged[i] = ss.damaged;
        sh_log_warn("WARNING: %s", sh_source_damage(j->src[i]));
    }
    if (st == SH_EEOF) {
        j->ended[i] = 1;
        return 1;
    }
    if (st == SH_OK && got) {
        st = sh_rec_writer_frame(j->w, i, f.sequence, f.timestamp_ns, &f.raw);
        sh_sync_disposition d;
        if (st == SH_OK) st = sh_sync_push(j->sync, i, f.sequence, f.timestamp_ns, NULL, &d);
        sh_source_release(j->src[i], &f);
        j->done[i] += st == SH_OK;
    }
    if (st != SH_OK) sh_log_error("%s", sh_error_message());
    return st == SH_OK;
}

/* Writes the sets formed so far; 0 (said) on a write error. */
static int write_sets(record_job *j)
{
    sh_frame_set set;
    while (sh_sync_pop(j->sync, &set))
        if (sh_rec_writer_set(j->w, &set) != SH_OK) {
            sh_log_error("%s", sh_error_message());
            return 0;
        }
    return 1;
}

/* Waits up to 100 ms for frames or a trigger edge and records what came; -1 when every camera
 * is done, 0 (said) on an error, 1 to go on. */
static int job_step(record_job *j)
{
    int active = 0, n = j->nspec;
    for (int i = 0; i < n; i++) active += !j->ended[i] && j->done[i] < j->opt->frames;
    if (!active) return -1;
    struct pollfd p[MAX_SOURCES + 1];
    for (int i = 0; i < n; i++) {
        p[i].fd = j->ended[i] || j->done[i] >= j->opt->frames ? -1 : sh_source_fd(j->src[i]);
        p[i].events = POLLIN;
        p[i].revents = 0;
    }
    p[n].fd = j->trig ? sh_gpio_trigger_fd(j->trig) : -1;
    p[n].events = POLLIN;
    p[n].revents = 0;
    poll(p, (nfds_t)n + 1, 100);
    if (j->trig) {
        int64_t edge;
        int got;
        if (sh_gpio_trigger_service(j->trig, &edge, &got) != SH_OK) {
            sh_log_error("%s", sh_error_message());
            return 0;
        }
        if (got) sh_sync_trigger(j->sync, edge);
    }
    for (int i = 0; i < n; i++)
        if (!j->ended[i] && j->done[i] < j->opt->frames && !take_frame(j, i)) return 0;
    return write_sets(j);
}

static void job_report(const record_job *j)
{
    sh_sync_stats ss;
    sh_sync_get_stats(j->sync, &ss);
    for (int i = 0; i < j->nspec; i++) {
        sh_source_stats st;
        sh_source_get_stats(j->src[i], &st);
        sh_log_info("camera %d: %ld frames recorded; %llu skipped as damaged, %llu dropped by the "
                    "driver, %llu losses, %llu reopens",
                    i, j->done[i], (unsigned long long)st.errors, (unsigned long long)st.drops,
                    (unsigned long long)st.losses, (unsigned long long)st.reopens);
    }
    sh_log_info("%llu sets (%llu incomplete), %llu late and %llu duplicate frames",
                (unsigned long long)ss.sets, (unsigned long long)ss.incomplete, (unsigned long long)ss.late,
                (unsigned long long)ss.duplicates);
    if (j->trig)
        sh_log_info("%llu trigger edges %s %s line %u", (unsigned long long)sh_gpio_trigger_edges(j->trig),
                    j->trigger_out ? "driven on" : "read from", j->go.chip, j->go.line);
}

/* Closes everything; 0 when the recording could not be completed (said). */
static int job_close(record_job *j)
{
    int ok = 1;
    if (j->w && sh_rec_writer_close(j->w) != SH_OK) {
        sh_log_error("%s", sh_error_message());
        ok = 0;
    }
    sh_gpio_trigger_close(j->trig);
    sh_sync_destroy(j->sync);
    for (int i = 0; i < j->nspec; i++) sh_source_close(j->src[i]);
    return ok;
}

/* The cameras from the config file (--config) into o->specs and cfg; 0 (said) when it is refused. */
static int load_config(record_options *o, sh_config *cfg)
{
    if (o->camera_opts) {
        sh_log_error("--config gives the cameras, their formats and controls, the sets and the "
                     "trigger ([cameraN], [source], [trigger]); set them there, not with --source, --format, ...");
        return 0;
    }
    char err[SH_CONFIG_ERR];
    sh_config_default(cfg);
    if (sh_config_load_file(cfg, o->config_path, err) != SH_OK || sh_config_check(cfg, err) != SH_OK) {
        sh_log_error("%s", err);
        return 0;
    }
    o->nspec = sh_config_cameras(cfg);
    for (int i = 0; i < o->nspec; i++) o->specs[i] = cfg->camera[i].spec;
    return 1;
}

int cmd_record(int argc, char **argv)
{
    sh_log_setup(SH_LOG_TOOL, "stillheart record", SH_LOG_INFO);
    record_options o;
    int rc = parse_options(argc, argv, &o);
    if (rc >= 0) return rc;
    if (o.to_y4m_rec) {
        if (optind != argc - 1) return sh_cli_usage_error(&cli, "--to-y4m REC OUT.y4m: one output file");
        return to_y4m(o.to_y4m_rec, argv[optind], o.camera);
    }
    static sh_config cfg; /* the specs point into it */
    if (o.config_path && !load_config(&o, &cfg)) return 2;
    if (!o.nspec || !o.frames || optind != argc - 1)
        return sh_cli_usage_error(&cli, "need --source (or --config), --frames and the output folder");
    o.out_dir = argv[optind];
    record_job j = {.opt = &o, .cfg = o.config_path ? &cfg : NULL, .nspec = o.nspec};
    j.go = (sh_gpio_options){j.chip, 0, 0, o.trigger_out, 0, (int64_t)o.pulse_ms * 1000000};
    j.have_trigger = o.trigger_spec != NULL, j.trigger_out = o.trigger_out;
    if (o.trigger_spec && !parse_trigger(&o, &j.go, j.chip)) return 2;

    rc = 1;
    if (job_open(&j)) {
        struct sigaction sa;
        memset(&sa, 0, sizeof sa);
        sa.sa_handler = on_signal;
        sigaction(SIGINT, &sa, NULL);
        sigaction(SIGTERM, &sa, NULL);
        int step = 1;
        while (!stop_requested && (step = job_step(&j)) > 0) continue;
        if (stop_requested || step < 0) {
            sh_sync_flush(j.sync);
            if (write_sets(&j)) {
                job_report(&j);
                rc = stop_requested ? 130 : 0;
            }
        }
    }
    if (!job_close(&j)) rc = 1;
    return rc;
}
