/* stillheart detect: every raw AprilTag detection of every frame, as CSV. */
#include <getopt.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "app.h"
#include "stillheart/detect.h"
#include "stillheart/imageio.h"
#include "stillheart/log.h"
#include "stillheart/y4m.h"

#define MAX_DETECTIONS 4096

static const sh_cli cli = {"stillheart detect"};

static void usage(FILE *out)
{
    fprintf(out,
        "usage: stillheart detect [OPTIONS] IN.(y4m|png|jpg)\n\n"
        "Detects AprilTags (libapriltag) in every frame of IN and prints every raw detection as\n"
        "CSV with the header\n"
        "  frame,id,cx,cy,x0,y0,x1,y1,x2,y2,x3,y3,margin\n"
        "frame: 0-based frame index (0 for a still image); cx,cy: tag centre; x0,y0..x3,y3: the\n"
        "four corners in libapriltag's order; margin: libapriltag's decision margin. Coordinates\n"
        "are pixels with pixel centres at integers (OpenCV's convention, as the phantom's\n"
        "markers.csv): libapriltag's own numbers are 0.5 px larger. Duplicates (several tags\n"
        "with the same id in a frame) are all printed; deciding which to trust is the tracker's\n"
        "job. A Y4M video is read through its luma (Y) plane; a colour PNG is converted to grey\n"
        "(BT.601 luma), a colour JPEG gives its own Y plane (as libapriltag's tests read it).\n\n"
        "Search: every frame is scanned whole (--full-frame, the default): search windows need\n"
        "predictions, which are the tracker's job (stillheart track). --windows is a simple\n"
        "stand-in: each frame is searched in windows around the previous frame's detections,\n"
        "and whole again when fewer tags than at the last full scan are found.\n\n"
        "options:\n"
        "  --family F        tag family (default tag36h11); known: %s\n"
        "  --full-frame      scan each frame whole (the default)\n"
        "  --windows         search windows around the previous frame's tags (see above)\n"
        "  --window-scale S  window edge over the tag's extent with --windows (default 1.6)\n"
        "  --decimate D      quad decimation of whole-frame scans (default 2, libapriltag's);\n"
        "                    windows always work at full resolution\n"
        "  --sigma S         Gaussian blur of the quad image, px (default 0)\n"
        "  --sharpening X    decode sharpening (default 0.25)\n"
        "  --no-refine-edges do not snap edges to gradients after decimation\n"
        "  --max-hamming N   bit errors corrected at most, 0..3 (default 2)\n"
        "  --threads T       libapriltag worker threads (default 1)\n"
        "  --json            one JSON object on stdout instead of the CSV: {\"input\", \"family\",\n"
        "                    \"frames\" (read), \"detections\": [{\"frame\", \"id\", \"cx\", \"cy\",\n"
        "                    \"corners\": [[x0, y0], .. [x3, y3]], \"margin\"}, ...]}, the CSV's\n"
        "                    numbers; \"error\" (null, or why the run stopped) last\n"
        SH_CLI_USAGE
        "IN may be '-' for a Y4M stream on standard input.\n",
        sh_detector_families());
}

static int ends_with(const char *s, const char *suffix)
{
    size_t n = strlen(s), m = strlen(suffix);
    return n >= m && !strcasecmp(s + n - m, suffix);
}

/* The CSV rows, or with json the members of the "detections" array. */
static void print_detections(sh_cli_json *json, int frame, const sh_detection *d, int n)
{
    for (int i = 0; i < n && json; i++) {
        sh_cli_json_object(json, NULL);
        sh_cli_json_int(json, "frame", frame);
        sh_cli_json_int(json, "id", d[i].id);
        sh_cli_json_number(json, "cx", d[i].cx);
        sh_cli_json_number(json, "cy", d[i].cy);
        sh_cli_json_array(json, "corners");
        for (int k = 0; k < 4; k++) {
            sh_cli_json_array(json, NULL);
            sh_cli_json_number(json, NULL, d[i].corner[k][0]);
            sh_cli_json_number(json, NULL, d[i].corner[k][1]);
            sh_cli_json_end(json);
        }
        sh_cli_json_end(json);
        sh_cli_json_number(json, "margin", d[i].margin);
        sh_cli_json_end(json);
    }
    for (int i = 0; i < n && !json; i++) {
        printf("%d,%d,%.4f,%.4f", frame, d[i].id, d[i].cx, d[i].cy);
        for (int k = 0; k < 4; k++) printf(",%.4f,%.4f", d[i].corner[k][0], d[i].corner[k][1]);
        printf(",%.3f\n", d[i].margin);
    }
}

/* Windows around last frame's tags: a square of scale x the tag's larger extent. */
static int windows_from(const sh_detection *d, int n, double scale, sh_window *w)
{
    int k = 0;
    for (int i = 0; i < n && k < SH_DETECT_MAX_WINDOWS; i++) {
        double x0 = d[i].corner[0][0], x1 = x0, y0 = d[i].corner[0][1], y1 = y0;
        for (int c = 1; c < 4; c++) {
            x0 = fmin(x0, d[i].corner[c][0]), x1 = fmax(x1, d[i].corner[c][0]);
            y0 = fmin(y0, d[i].corner[c][1]), y1 = fmax(y1, d[i].corner[c][1]);
        }
        double half = 0.5 * scale * fmax(x1 - x0, y1 - y0);
        w[k].x = (int)floor(d[i].cx - half);
        w[k].y = (int)floor(d[i].cy - half);
        w[k].width = w[k].height = (int)ceil(2 * half) + 1;
        k++;
    }
    return k;
}

/* What the command line asks for; filled by parse_options only (the options/runtime split of
 * ustreamer: detect_job below holds what the run opens). */
typedef struct {
    sh_detector_options det;
    int use_windows, json;
    double scale; /* --window-scale */
    const char *in;
} detect_options;

/* Fills o from argv: APP_GO_ON, or the exit code (usage and refusals printed). */
static int parse_options(int argc, char **argv, detect_options *o)
{
    static const struct option options[] = {
        {"family", required_argument, 0, 'f'},     {"full-frame", no_argument, 0, 'F'},
        {"windows", no_argument, 0, 'w'},          {"window-scale", required_argument, 0, 'W'},
        {"decimate", required_argument, 0, 'd'},   {"sigma", required_argument, 0, 's'},
        {"sharpening", required_argument, 0, 'S'}, {"no-refine-edges", no_argument, 0, 'R'},
        {"max-hamming", required_argument, 0, 'H'}, {"threads", required_argument, 0, 't'},
        {"json", no_argument, 0, 'j'},             SH_CLI_OPTIONS, {0, 0, 0, 0}};
    sh_detector_options_default(&o->det);
    o->use_windows = o->json = 0;
    o->scale = 1.6;
    int opt;
    optind = 1;
    opterr = 0;
    while ((opt = getopt_long(argc, argv, ":h", options, NULL)) != -1) {
        switch (opt) {
        case 'f': o->det.family = optarg; break;
        case 'F': o->use_windows = 0; break;
        case 'w': o->use_windows = 1; break;
        case 'W': if (!sh_cli_parse_double("--window-scale", optarg, 1.0, 10.0, &o->scale)) return 2; break;
        case 'd': if (!sh_cli_parse_double("--decimate", optarg, 1.0, 16.0, &o->det.quad_decimate)) return 2; break;
        case 's': if (!sh_cli_parse_double("--sigma", optarg, -10.0, 10.0, &o->det.quad_sigma)) return 2; break;
        case 'S': if (!sh_cli_parse_double("--sharpening", optarg, 0.0, 10.0, &o->det.decode_sharpening)) return 2; break;
        case 'R': o->det.refine_edges = 0; break;
        case 'H': if (!sh_cli_parse_int("--max-hamming", optarg, 0, 3, &o->det.max_hamming)) return 2; break;
        case 't': if (!sh_cli_parse_int("--threads", optarg, 1, 64, &o->det.threads)) return 2; break;
        case 'j': o->json = 1; break;
        case 'h': usage(stdout); return 0;
        default: { int rc = sh_cli_option(&cli, opt, argv); if (rc >= 0) return rc; } break;
        }
    }
    if (optind != argc - 1) return sh_cli_usage_error(&cli, "expected one input file");
    o->in = argv[optind];
    return APP_GO_ON;
}

/* The detector and its buffers, from detect_open to detect_close. */
typedef struct {
    sh_detector *det;
    sh_detection *found, *prev; /* this frame's detections, the last frame's (--windows) */
    sh_window *win;
    int nprev, full_count;      /* full_count: tags found at the last whole-frame scan */
    sh_cli_json json, *out;     /* out: &json with --json, else NULL (CSV) */
    int frames;                 /* read */
} detect_job;

/* 0, or 1 with the reason printed (detect_close frees either way). */
static int detect_open(detect_job *j, const detect_options *o)
{
    memset(j, 0, sizeof *j);
    if (sh_detector_create(&o->det, &j->det) != SH_OK) {
        sh_log_error("%s", sh_error_message());
        return 1;
    }
    j->found = malloc(MAX_DETECTIONS * sizeof *j->found);
    j->prev = malloc(MAX_DETECTIONS * sizeof *j->prev);
    j->win = malloc(SH_DETECT_MAX_WINDOWS * sizeof *j->win);
    if (!j->found || !j->prev || !j->win) {
        sh_log_error("out of memory");
        return 1;
    }
    return 0;
}

static void detect_close(detect_job *j)
{
    free(j->found);
    free(j->prev);
    free(j->win);
    sh_detector_destroy(j->det);
}

/* A Y4M file by its name or its first bytes (anything else is read as an image). */
static int is_video(const char *path)
{
    if (!strcmp(path, "-") || ends_with(path, ".y4m")) return 1;
    int video = 0;
    FILE *f = fopen(path, "rb");
    char magic[9] = {0};
    if (f) {
        video = fread(magic, 1, 9, f) == 9 && !memcmp(magic, "YUV4MPEG2", 9);
        fclose(f);
    }
    return video;
}

/* A still image: its detections as frame 0. 0, or 1 with the reason printed. */
static int detect_image(detect_job *j, const char *path)
{
    sh_image img;
    int n = 0, rc = 0;
    if (sh_imageio_read_gray(path, &img) != SH_OK ||
        sh_detector_detect(j->det, &img, j->found, MAX_DETECTIONS, &n) != SH_OK) {
        sh_log_error("%s", sh_error_message());
        rc = 1;
    } else {
        print_detections(j->out, 0, j->found, n < MAX_DETECTIONS ? n : MAX_DETECTIONS);
        j->frames = 1;
    }
    sh_image_destroy(&img);
    return rc;
}

/* One video frame: whole, or in windows around the last frame's tags (--windows) and whole
 * again when some were lost. 0, or 1 with the reason printed. */
static int detect_frame(detect_job *j, const detect_options *o, const sh_image *frame, int index)
{
    int n = 0;
    sh_status st;
    if (o->use_windows && j->nprev > 0) {
        int nw = windows_from(j->prev, j->nprev, o->scale, j->win);
        st = sh_detector_detect_windows(j->det, frame, j->win, nw, j->found, MAX_DETECTIONS, &n);
        if (st == SH_OK && n < j->full_count) /* lost some: look everywhere again */
            st = sh_detector_detect(j->det, frame, j->found, MAX_DETECTIONS, &n), j->full_count = n;
    } else {
        st = sh_detector_detect(j->det, frame, j->found, MAX_DETECTIONS, &n);
        j->full_count = n;
    }
    if (st != SH_OK) {
        sh_log_error("%s: frame %d: %s", o->in, index,
                     sh_error_message());
        return 1;
    }
    if (n > MAX_DETECTIONS) n = MAX_DETECTIONS;
    print_detections(j->out, index, j->found, n);
    j->frames = index + 1;
    memcpy(j->prev, j->found, (size_t)n * sizeof *j->found);
    j->nprev = n;
    return 0;
}

/* Every frame of a Y4M video: 0, or 1 with the reason printed (the frames before it are
 * printed). */
static int detect_video(detect_job *j, const detect_options *o)
{
    sh_y4m_reader *reader = NULL;
    if (sh_y4m_reader_open(o->in, &reader) != SH_OK) {
        sh_log_error("%s", sh_error_message());
        return 1;
    }
    const sh_y4m_header *hdr = sh_y4m_reader_header(reader);
    sh_image frame;
    if (sh_image_create(&frame, hdr->format, hdr->width, hdr->height) != SH_OK) {
        sh_log_error("%s", sh_error_message());
        sh_y4m_reader_close(reader);
        return 1;
    }
    int rc = 0;
    for (int index = 0;; index++) {
        sh_status st = sh_y4m_reader_read(reader, &frame);
        if (st == SH_EEOF) break;
        if (st != SH_OK) {
            sh_log_error("%s", sh_error_message());
            rc = 1;
            break;
        }
        if ((rc = detect_frame(j, o, &frame, index))) break;
    }
    sh_image_destroy(&frame);
    sh_y4m_reader_close(reader);
    return rc;
}

int cmd_detect(int argc, char **argv)
{
    sh_log_setup(SH_LOG_TOOL, "stillheart detect", SH_LOG_INFO);
    detect_options o;
    int rc = parse_options(argc, argv, &o);
    if (rc != APP_GO_ON) return rc;
    detect_job j;
    if (!(rc = detect_open(&j, &o))) {
        if (o.json) {
            /* the document stays whole when a frame fails: "error" says why it ends early */
            j.out = &j.json;
            sh_cli_json_start(j.out, stdout);
            sh_cli_json_object(j.out, NULL);
            sh_cli_json_string(j.out, "input", o.in);
            sh_cli_json_string(j.out, "family", o.det.family);
            sh_cli_json_array(j.out, "detections");
        } else {
            printf("frame,id,cx,cy,x0,y0,x1,y1,x2,y2,x3,y3,margin\n");
        }
        rc = is_video(o.in) ? detect_video(&j, &o) : detect_image(&j, o.in);
        if (o.json) {
            sh_cli_json_end(j.out);
            sh_cli_json_int(j.out, "frames", j.frames);
            sh_cli_json_string(j.out, "error", rc ? sh_error_message() : NULL);
            sh_cli_json_end(j.out);
        }
    }
    if (fflush(stdout) != 0) {
        sh_log_error("cannot write the output");
        rc = 1;
    }
    detect_close(&j);
    return rc;
}
