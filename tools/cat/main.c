/* stillheart-cat: the display buffer as a Y4M stream on stdout, so that
 * `stillheart-cat | ffplay -` shows the live view and `| ffmpeg ...` records it.
 *
 * The stream holds whole frames only. Each frame (its FRAME line and its bytes) is formatted
 * into one buffer and handed to write() until all of it is out; stdio is not used for the
 * stream, because a buffered stream flushes in pieces and a process that dies between two
 * pieces leaves half a frame. SIGINT and SIGTERM only set a flag, looked at between frames: the
 * frame being written is finished, the next one is not begun. */
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
#include "stillheart/log.h"
#include "stillheart/y4m.h"

static const sh_cli cli = {"stillheart-cat"};

static void usage(FILE *out)
{
    fprintf(out,
        "usage: stillheart-cat [--name NAME] [--owner USER] [--count N] [--timeout S] [--follow] > OUT.y4m\n\n"
        "Reads the frames the stillheart daemon publishes to its shared-memory display buffer\n"
        "and writes them to standard output as YUV4MPEG2 (mono, 4:2:0 or 4:4:4 as published;\n"
        "RGB frames are converted to 4:4:4, BT.601 full range). Starts with the newest frame;\n"
        "a frame the reader could not keep up with is skipped, never repeated. A daemon that is\n"
        "restarted (killed, crashed, or replaced by a new one) is followed: its new segment is\n"
        "opened and its frames written on, never one of the old daemon's after them.\n\n"
        "options:\n"
        "  --name NAME     shared-memory segment (default %s)\n"
        "  --owner USER    user name or uid the segment must belong to (default: the user running\n"
        "                  stillheart-cat); a segment of anyone else is refused, naming its owner\n"
        "  --count N       stop after N frames (default: until the daemon stops)\n"
        "  --timeout S     give up when no new frame arrives for S seconds (default 5; 0: wait\n"
        "                  forever); a segment that is not there yet (the daemon starting, or\n"
        "                  restarting) is waited for as long\n"
        "  --follow        when the daemon stops cleanly, wait for the next one (within the\n"
        "                  timeout) instead of ending the stream\n"
        "  -v, --verbose   each frame's status (stabilized / degraded / raw and why) and the\n"
        "                  segment's generation on stderr (also with --log-level debug)\n"
        SH_CLI_USAGE "\n"
        "Standard output must be a pipe or a file (a terminal is refused): stillheart-cat | ffplay -\n\n"
        "Exit status: 0 at --count or the daemon's clean stop (or a signal: SIGINT, SIGTERM end\n"
        "the frame in hand first), 1 an error or the timeout, 2 bad usage or a terminal as\n"
        "standard output, 3 the daemon came back with another frame size (a Y4M stream has\n"
        "one size: start stillheart-cat again).\n",
        SH_DISPLAY_DEFAULT_NAME);
}

static volatile sig_atomic_t stop_signal;

static void on_stop(int sig) { stop_signal = sig; }

static double now_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + (double)ts.tv_nsec / 1e9;
}

/* All of buf to stdout: a write cut short by a signal goes on where it stopped. */
static int write_all(const unsigned char *buf, size_t n)
{
    while (n > 0) {
        ssize_t k = write(STDOUT_FILENO, buf, n);
        if (k < 0 && errno == EINTR) continue;
        if (k <= 0) return -1;
        buf += k;
        n -= (size_t)k;
    }
    return 0;
}

/* What the Y4M writer put into the memory stream since the last call, out in one piece. */
static int flush_stream(FILE *mem, const unsigned char *buf)
{
    long n = ftell(mem);
    if (n < 0 || write_all(buf, (size_t)n) != 0) return -1;
    rewind(mem);
    return 0;
}

/* BT.601 full range: Y4M carries no RGB. */
static void rgb_to_yuv444(const sh_image *rgb, sh_image *yuv)
{
    for (int y = 0; y < rgb->height; y++) {
        const uint8_t *s = rgb->plane[0].data + (size_t)y * rgb->plane[0].stride;
        uint8_t *py = yuv->plane[0].data + (size_t)y * yuv->plane[0].stride;
        uint8_t *pu = yuv->plane[1].data + (size_t)y * yuv->plane[1].stride;
        uint8_t *pv = yuv->plane[2].data + (size_t)y * yuv->plane[2].stride;
        for (int x = 0; x < rgb->width; x++, s += 3) {
            double r = s[0], g = s[1], b = s[2];
            double v[3] = {0.299 * r + 0.587 * g + 0.114 * b,
                           128 - 0.168736 * r - 0.331264 * g + 0.5 * b,
                           128 + 0.5 * r - 0.418688 * g - 0.081312 * b};
            uint8_t *out[3] = {py + x, pu + x, pv + x};
            for (int c = 0; c < 3; c++) *out[c] = (uint8_t)fmin(255, fmax(0, floor(v[c] + 0.5)));
        }
    }
}

typedef struct {
    sh_display_reader_options ropt;
    const char *name;
    long count;
    double timeout;
    int verbose;
} cat_args;

/* Fills *a from the command line; returns -1 to go on, or the exit status (0 after --help, 2 for
 * a usage error). */
static int parse_args(int argc, char **argv, cat_args *a)
{
    static const struct option options[] = {
        {"name", required_argument, 0, 'n'}, {"count", required_argument, 0, 'c'},
        {"timeout", required_argument, 0, 't'}, {"verbose", no_argument, 0, 'v'},
        {"owner", required_argument, 0, 'o'}, {"follow", no_argument, 0, 'f'},
        SH_CLI_OPTIONS, {0, 0, 0, 0}};
    a->ropt = (sh_display_reader_options){.owner_uid = SH_DISPLAY_OWNER_SELF, .follow = 0};
    a->name = SH_DISPLAY_DEFAULT_NAME;
    a->count = 0;
    a->timeout = 5;
    a->verbose = 0;
    int opt;
    char *end;
    opterr = 0;
    while ((opt = getopt_long(argc, argv, ":hv", options, NULL)) != -1) {
        switch (opt) {
        case 'n': a->name = optarg; break;
        case 'c':
            a->count = strtol(optarg, &end, 10);
            if (*end || a->count < 0) {
                fprintf(stderr, "stillheart-cat: --count: '%s' is not a whole number >= 0\n", optarg);
                return 2;
            }
            break;
        case 't':
            a->timeout = strtod(optarg, &end);
            if (*end || !(a->timeout >= 0) || a->timeout > 86400) {
                fprintf(stderr, "stillheart-cat: --timeout: '%s' is not a number of seconds in [0, 86400]\n", optarg);
                return 2;
            }
            break;
        case 'v': a->verbose = 1; break;
        case 'f': a->ropt.follow = 1; break;
        case 'o':
            if (!sh_cli_parse_user("--owner", optarg, &a->ropt.owner_uid)) return 2;
            break;
        case 'h': usage(stdout); return 0;
        default: { int rc = sh_cli_option(&cli, opt, argv); if (rc >= 0) return rc; } break;
        }
    }
    if (optind != argc) return sh_cli_usage_error(&cli, "'%s': no operands (the video goes to standard output)", argv[optind]);
    if (sh_log_get_level() >= SH_LOG_DEBUG) a->verbose = 1;
    return -1;
}

/* The Y4M stream: frames are written into a memory buffer, then flushed to standard output. */
typedef struct {
    sh_pixfmt format;
    sh_image frame, converted;
    sh_y4m_writer *w;
    FILE *mem;
    unsigned char *buf;
} cat_stream;

/* Logs frame info (with -v), converts RGB and writes the frame to standard output; 0, or 1 after
 * saying why. */
static int emit_frame(const cat_args *a, sh_display_reader *r, cat_stream *s, const sh_display_frame_info *info)
{
    if (a->verbose)
        fprintf(stderr, "frame %llu %s%s%s markers %u residual %.3f generation %016llx\n",
                (unsigned long long)info->sequence,
                info->status == SH_DISPLAY_STABILIZED ? "stabilized"
                : info->status == SH_DISPLAY_DEGRADED ? "degraded" : "raw",
                info->reason[0] ? ": " : "", info->reason, info->markers_used, (double)info->residual_px,
                (unsigned long long)sh_display_reader_header(r)->generation);
    if (s->format == SH_PIX_RGB24) rgb_to_yuv444(&s->frame, &s->converted);
    if (sh_y4m_writer_write(s->w, s->format == SH_PIX_RGB24 ? &s->converted : &s->frame) != SH_OK) {
        fprintf(stderr, "stillheart-cat: %s\n", sh_error_message());
        return 1;
    }
    if (flush_stream(s->mem, s->buf) != 0) {
        fprintf(stderr, "stillheart-cat: <stdout>: write error: %s\n", strerror(errno));
        return 1;
    }
    return 0;
}

/* Copies frames until --count, the timeout, a signal or the daemon's clean end; the exit status. */
static int copy_frames(const cat_args *a, sh_display_reader *r, cat_stream *s, const sh_y4m_header *yh)
{
    double last_frame = now_s();
    for (long n = 0; (a->count == 0 || n < a->count) && !stop_signal;) {
        sh_display_frame_info info;
        /* short waits, so that a signal ends the wait at once; the timeout counts from the
         * last frame */
        sh_status st = sh_display_reader_next(r, &s->frame, &info, 100);
        if (st == SH_EIO && !stop_signal && (a->timeout == 0 || now_s() - last_frame < a->timeout)) continue;
        if (stop_signal) break;
        if (st == SH_EEOF && a->count == 0) break; /* the daemon stopped cleanly */
        if (st == SH_ERANGE) {
            const sh_display_header *now = sh_display_reader_header(r);
            fprintf(stderr, "stillheart-cat: %s: the daemon came back with %ux%u %s frames, this stream is %ux%u %s: "
                    "ending it (start stillheart-cat again)\n", a->name, now->width, now->height,
                    sh_pixfmt_name((sh_pixfmt)now->format), yh->width, yh->height, sh_pixfmt_name(s->format));
            return 3;
        }
        if (st == SH_EIO) {
            fprintf(stderr, "stillheart-cat: %s: no new frame in %g s\n", a->name, a->timeout);
            return 1;
        }
        if (st != SH_OK) {
            fprintf(stderr, "stillheart-cat: %s: %s\n", a->name, sh_error_message());
            return 1;
        }
        last_frame = now_s();
        if (emit_frame(a, r, s, &info) != 0) return 1;
        n++;
    }
    return 0;
}

/* Opens the Y4M stream for the reader's format and copies frames; the exit status. */
static int stream(const cat_args *a, sh_display_reader *r)
{
    const sh_display_header *h = sh_display_reader_header(r);
    cat_stream s = {.format = (sh_pixfmt)h->format};
    int rc = 1;
    sh_y4m_header yh = {.width = (int)h->width, .height = (int)h->height,
                        .format = s.format == SH_PIX_RGB24 ? SH_PIX_YUV444 : s.format,
                        .siting = (sh_chroma_siting)h->siting, .interlace = 'p',
                        .aspect_num = 1, .aspect_den = 1};
    if (h->full_range || s.format == SH_PIX_RGB24) strcpy(yh.extra, "XCOLORRANGE=FULL");
    /* room for the stream header (its tags are at most SH_Y4M_MAX_EXTRA bytes) or for one
     * frame: its FRAME line and at most three full planes */
    size_t cap = SH_Y4M_MAX_EXTRA + 512 + (size_t)h->width * (size_t)h->height * 3;
    if (sh_image_create(&s.frame, s.format, (int)h->width, (int)h->height) != SH_OK ||
        (s.format == SH_PIX_RGB24 &&
         sh_image_create(&s.converted, SH_PIX_YUV444, (int)h->width, (int)h->height) != SH_OK)) {
        fprintf(stderr, "stillheart-cat: %s\n", sh_error_message());
        goto done;
    }
    if (!(s.buf = malloc(cap)) || !(s.mem = fmemopen(s.buf, cap, "w")) || setvbuf(s.mem, NULL, _IONBF, 0) != 0) {
        fprintf(stderr, "stillheart-cat: cannot make a frame buffer: %s\n", strerror(errno));
        goto done;
    }
    if (sh_y4m_writer_open_file(s.mem, "<stdout>", &yh, &s.w) != SH_OK) {
        fprintf(stderr, "stillheart-cat: %s\n", sh_error_message());
        goto done;
    }
    if (flush_stream(s.mem, s.buf) != 0) {
        fprintf(stderr, "stillheart-cat: <stdout>: write error: %s\n", strerror(errno));
        goto done;
    }
    rc = copy_frames(a, r, &s, &yh);
done:
    sh_y4m_writer_close(s.w); /* its stream is the memory buffer: nothing of it is left unwritten */
    if (s.mem) fclose(s.mem);
    free(s.buf);
    sh_image_destroy(&s.frame);
    sh_image_destroy(&s.converted);
    return rc;
}

int main(int argc, char **argv)
{
    cat_args a;
    sh_log_setup(SH_LOG_TOOL, "stillheart-cat", SH_LOG_INFO);
    int prc = parse_args(argc, argv, &a);
    if (prc >= 0) return prc;
    /* as gzip and ffmpeg do: binary video on a terminal only garbles it */
    if (isatty(STDOUT_FILENO)) {
        fprintf(stderr, "stillheart-cat: standard output is a terminal: pipe the video to a player or a file,\n"
                        "  e.g. stillheart-cat | ffplay -f yuv4mpegpipe -i -   or   stillheart-cat --count 100 > out.y4m\n");
        return 2;
    }
    signal(SIGPIPE, SIG_IGN); /* a closed player shows as a write error, handled below */
    struct sigaction sa;
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = on_stop;
    sigemptyset(&sa.sa_mask);
    sigaction(SIGINT, &sa, NULL);
    sigaction(SIGTERM, &sa, NULL);
    /* the daemon may be starting: its segment appears, then becomes valid, within the timeout
     * (waited for in short steps, so that a signal ends the wait at once) */
    sh_display_reader *r = NULL;
    double give_up = a.timeout > 0 ? now_s() + a.timeout : INFINITY;
    sh_status ost;
    while ((ost = sh_display_reader_open(a.name, &a.ropt, 100, &r)) != SH_OK) {
        if (ost == SH_EINVAL || stop_signal || now_s() >= give_up) {
            fprintf(stderr, "stillheart-cat: %s\n", sh_error_message());
            return stop_signal ? 128 + stop_signal : 1;
        }
    }
    int rc = stream(&a, r);
    sh_display_reader_close(r);
    if (rc == 0 && stop_signal) {
        /* end as the signal would have ended it, for the shell and the process that sent it */
        signal(stop_signal, SIG_DFL);
        raise(stop_signal);
    }
    return rc;
}
