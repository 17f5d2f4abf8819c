/* stillheart-synth: a test recording with a known answer, made on the spot: a smooth texture
 * moved by a known non-uniform motion (tools/synth/synth.c), as Y4M, with the exact marker
 * positions as a points file for `stillheart warp`. */
#include <errno.h>
#include <getopt.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "stillheart/cli.h"
#include "stillheart/log.h"
#include "stillheart/points.h"
#include "stillheart/y4m.h"
#include "synth.h"

static const sh_cli cli = {"stillheart-synth"};

static void usage(FILE *out)
{
    fprintf(out,
        "usage: stillheart-synth [OPTIONS] --out DIR\n\n"
        "Writes DIR/video.y4m, a textured surface moved by a known smooth non-uniform motion\n"
        "(one period over the sequence; frame 0 is undeformed), and DIR/points.csv, the exact\n"
        "positions of markers on it ('frame,id,x,y'), ready for 'stillheart warp'.\n\n"
        "options:\n"
        "  --width W        frame width (default 640)\n"
        "  --height H       frame height (default 360)\n"
        "  --frames N       number of frames (default 24)\n"
        "  --markers M      number of markers (default 16)\n"
        "  --amplitude A    motion scale in pixels (default 10)\n"
        "  --format F       i420 (default), gray8 or yuv444\n"
        "  --seed S         marker layout (default 1)\n"
        "  --out DIR        output folder (created if missing)\n"
        SH_CLI_USAGE);
}

/* mkdir -p */
static int make_dirs(const char *path)
{
    char buf[4096];
    if (snprintf(buf, sizeof buf, "%s", path) >= (int)sizeof buf) {
        errno = ENAMETOOLONG;
        return 0;
    }
    for (char *p = buf + 1; *p; p++) {
        if (*p != '/') continue;
        *p = 0;
        if (mkdir(buf, 0777) != 0 && errno != EEXIST) return 0;
        *p = '/';
    }
    return mkdir(buf, 0777) == 0 || errno == EEXIST;
}

typedef struct {
    int width, height, frames, markers, amplitude, seed;
    sh_pixfmt format;
    const char *out_dir;
} synth_args;

/* Fills *a from the command line; returns -1 to go on, or the exit status (0 after --help, 2 for
 * a usage error). */
static int parse_args(int argc, char **argv, synth_args *a)
{
    static const struct option options[] = {
        {"width", required_argument, 0, 'w'}, {"height", required_argument, 0, 'y'},
        {"frames", required_argument, 0, 'n'}, {"markers", required_argument, 0, 'm'},
        {"amplitude", required_argument, 0, 'a'}, {"format", required_argument, 0, 'f'},
        {"seed", required_argument, 0, 's'}, {"out", required_argument, 0, 'o'},
        SH_CLI_OPTIONS, {0, 0, 0, 0}};
    *a = (synth_args){.width = 640, .height = 360, .frames = 24, .markers = 16, .amplitude = 10, .seed = 1,
                      .format = SH_PIX_I420, .out_dir = NULL};
    int opt;
    opterr = 0;
    while ((opt = getopt_long(argc, argv, ":h", options, NULL)) != -1) {
        switch (opt) {
        case 'w': if (!sh_cli_parse_int("--width", optarg, 16, SH_IMAGE_MAX_SIZE, &a->width)) return 2; break;
        case 'y': if (!sh_cli_parse_int("--height", optarg, 16, SH_IMAGE_MAX_SIZE, &a->height)) return 2; break;
        case 'n': if (!sh_cli_parse_int("--frames", optarg, 1, 100000, &a->frames)) return 2; break;
        case 'm': if (!sh_cli_parse_int("--markers", optarg, 3, 1000, &a->markers)) return 2; break;
        case 'a': if (!sh_cli_parse_int("--amplitude", optarg, 0, 1000, &a->amplitude)) return 2; break;
        case 's': if (!sh_cli_parse_int("--seed", optarg, 0, 1 << 30, &a->seed)) return 2; break;
        case 'f':
            if (!strcmp(optarg, "i420")) a->format = SH_PIX_I420;
            else if (!strcmp(optarg, "gray8")) a->format = SH_PIX_GRAY8;
            else if (!strcmp(optarg, "yuv444")) a->format = SH_PIX_YUV444;
            else {
                sh_log_error("--format: '%s' is not i420, gray8 or yuv444", optarg);
                return 2;
            }
            break;
        case 'o': a->out_dir = optarg; break;
        case 'h': usage(stdout); return 0;
        default: { int rc = sh_cli_option(&cli, opt, argv); if (rc >= 0) return rc; } break;
        }
    }
    if (!a->out_dir || optind != argc) return sh_cli_usage_error(&cli, "need --out DIR and no operands");
    return -1;
}

/* Renders every frame into the video and keeps the markers' exact positions in rows; the exit
 * status. */
static int write_video(const synth_args *a, const char *video, sh_point *rows)
{
    synth_motion motion = {a->width, a->height, a->amplitude};
    sh_y4m_header h = {.width = a->width, .height = a->height, .format = a->format, .fps_num = 25,
                       .fps_den = 1, .aspect_num = 1, .aspect_den = 1, .interlace = 'p'};
    strcpy(h.extra, SH_Y4M_FULL_RANGE); /* synth_render writes full-range BT.601 */
    double *ref = malloc(sizeof(double) * 2 * a->markers);
    sh_image img = {0};
    sh_y4m_writer *w = NULL;
    int rc = 1;
    if (!ref || sh_image_create(&img, a->format, a->width, a->height) != SH_OK ||
        sh_y4m_writer_open(video, &h, &w) != SH_OK) {
        sh_log_error("%s", sh_error_message());
        goto done;
    }
    synth_markers(&motion, a->markers, (unsigned)a->seed, ref);
    sh_cli_progress progress;
    sh_cli_progress_start(&progress, "stillheart-synth", a->frames, "frames");
    for (int t = 0; t < a->frames; t++) {
        double phase = (double)t / a->frames;
        synth_render(&motion, phase, &img);
        if (sh_y4m_writer_write(w, &img) != SH_OK) {
            sh_log_error("%s", sh_error_message());
            goto done;
        }
        for (int i = 0; i < a->markers; i++) {
            sh_point *p = &rows[(size_t)t * a->markers + i];
            *p = (sh_point){.frame = t, .id = i};
            synth_forward(&motion, phase, ref[2 * i], ref[2 * i + 1], &p->x, &p->y);
        }
        sh_cli_progress_update(&progress, t + 1);
    }
    sh_cli_progress_end(&progress);
    sh_status st = sh_y4m_writer_close(w);
    w = NULL;
    if (st != SH_OK) {
        sh_log_error("%s: %s", video, sh_error_message());
        goto done;
    }
    rc = 0;
done:
    if (w) sh_y4m_writer_close(w);
    sh_image_destroy(&img);
    free(ref);
    return rc;
}

int main(int argc, char **argv)
{
    sh_log_setup(SH_LOG_TOOL, "stillheart-synth", SH_LOG_INFO);
    synth_args a;
    int prc = parse_args(argc, argv, &a);
    if (prc >= 0) return prc;
    if (!make_dirs(a.out_dir)) {
        sh_log_error("%s: %s", a.out_dir, strerror(errno));
        return 1;
    }
    char video[4096], points[4096];
    snprintf(video, sizeof video, "%s/video.y4m", a.out_dir);
    snprintf(points, sizeof points, "%s/points.csv", a.out_dir);
    sh_point *rows = malloc(sizeof(sh_point) * (size_t)a.markers * a.frames);
    if (!rows) {
        sh_log_error("out of memory for %d x %d points", a.markers, a.frames);
        return 1;
    }
    int rc = write_video(&a, video, rows);
    if (rc == 0) {
        FILE *f = fopen(points, "w");
        if (!f || sh_points_write(f, rows, a.markers * a.frames, 0) != SH_OK || fclose(f) != 0) {
            sh_log_error("%s: %s", points, strerror(errno));
            rc = 1;
        } else {
            printf("%s\n%s\n", video, points);
        }
    }
    free(rows);
    return rc;
}
