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
        "  --help            this text\n"
        "IN may be '-' for a Y4M stream on standard input.\n",
        sh_detector_families());
}

static int ends_with(const char *s, const char *suffix)
{
    size_t n = strlen(s), m = strlen(suffix);
    return n >= m && !strcasecmp(s + n - m, suffix);
}

static void print_detections(int frame, const sh_detection *d, int n)
{
    for (int i = 0; i < n; i++) {
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

int cmd_detect(int argc, char **argv)
{
    sh_log_setup(SH_LOG_TOOL, "stillheart detect", SH_LOG_INFO);
    static const struct option options[] = {
        {"family", required_argument, 0, 'f'},     {"full-frame", no_argument, 0, 'F'},
        {"windows", no_argument, 0, 'w'},          {"window-scale", required_argument, 0, 'W'},
        {"decimate", required_argument, 0, 'd'},   {"sigma", required_argument, 0, 's'},
        {"sharpening", required_argument, 0, 'S'}, {"no-refine-edges", no_argument, 0, 'R'},
        {"max-hamming", required_argument, 0, 'H'}, {"threads", required_argument, 0, 't'},
        {"help", no_argument, 0, 'h'},             {0, 0, 0, 0}};
    sh_detector_options o;
    sh_detector_options_default(&o);
    int use_windows = 0;
    double scale = 1.6;
    int opt;
    optind = 1;
    while ((opt = getopt_long(argc, argv, "", options, NULL)) != -1) {
        switch (opt) {
        case 'f': o.family = optarg; break;
        case 'F': use_windows = 0; break;
        case 'w': use_windows = 1; break;
        case 'W': if (!app_parse_double("--window-scale", optarg, 1.0, 10.0, &scale)) return 2; break;
        case 'd': if (!app_parse_double("--decimate", optarg, 1.0, 16.0, &o.quad_decimate)) return 2; break;
        case 's': if (!app_parse_double("--sigma", optarg, -10.0, 10.0, &o.quad_sigma)) return 2; break;
        case 'S': if (!app_parse_double("--sharpening", optarg, 0.0, 10.0, &o.decode_sharpening)) return 2; break;
        case 'R': o.refine_edges = 0; break;
        case 'H': if (!app_parse_int("--max-hamming", optarg, 0, 3, &o.max_hamming)) return 2; break;
        case 't': if (!app_parse_int("--threads", optarg, 1, 64, &o.threads)) return 2; break;
        case 'h': usage(stdout); return 0;
        default: usage(stderr); return 2;
        }
    }
    if (optind != argc - 1) {
        sh_log_error("expected one input file");
        usage(stderr);
        return 2;
    }
    const char *in = argv[optind];
    sh_detector *det = NULL;
    if (sh_detector_create(&o, &det) != SH_OK) {
        sh_log_error("%s", sh_error_message());
        return 1;
    }
    sh_detection *found = malloc(MAX_DETECTIONS * sizeof *found);
    sh_detection *prev = malloc(MAX_DETECTIONS * sizeof *prev);
    sh_window *win = malloc(SH_DETECT_MAX_WINDOWS * sizeof *win);
    int rc = 0;
    if (!found || !prev || !win) {
        sh_log_error("out of memory");
        rc = 1;
        goto done;
    }
    printf("frame,id,cx,cy,x0,y0,x1,y1,x2,y2,x3,y3,margin\n");

    int is_video = !strcmp(in, "-") || ends_with(in, ".y4m");
    if (!is_video) {
        FILE *f = fopen(in, "rb");
        char magic[9] = {0};
        if (f) {
            is_video = fread(magic, 1, 9, f) == 9 && !memcmp(magic, "YUV4MPEG2", 9);
            fclose(f);
        }
    }
    if (!is_video) {
        sh_image img;
        int n = 0;
        if (sh_imageio_read_gray(in, &img) != SH_OK ||
            sh_detector_detect(det, &img, found, MAX_DETECTIONS, &n) != SH_OK) {
            sh_log_error("%s", sh_error_message());
            rc = 1;
        } else {
            print_detections(0, found, n < MAX_DETECTIONS ? n : MAX_DETECTIONS);
        }
        sh_image_destroy(&img);
        goto done;
    }

    sh_y4m_reader *reader = NULL;
    if (sh_y4m_reader_open(in, &reader) != SH_OK) {
        sh_log_error("%s", sh_error_message());
        rc = 1;
        goto done;
    }
    const sh_y4m_header *hdr = sh_y4m_reader_header(reader);
    sh_image frame;
    if (sh_image_create(&frame, hdr->format, hdr->width, hdr->height) != SH_OK) {
        sh_log_error("%s", sh_error_message());
        sh_y4m_reader_close(reader);
        rc = 1;
        goto done;
    }
    int nprev = 0, full_count = 0;
    for (int index = 0;; index++) {
        sh_status st = sh_y4m_reader_read(reader, &frame);
        if (st == SH_EEOF) break;
        if (st != SH_OK) {
            sh_log_error("%s", sh_error_message());
            rc = 1;
            break;
        }
        int n = 0;
        if (use_windows && nprev > 0) {
            int nw = windows_from(prev, nprev, scale, win);
            st = sh_detector_detect_windows(det, &frame, win, nw, found, MAX_DETECTIONS, &n);
            if (st == SH_OK && n < full_count) /* lost some: look everywhere again */
                st = sh_detector_detect(det, &frame, found, MAX_DETECTIONS, &n), full_count = n;
        } else {
            st = sh_detector_detect(det, &frame, found, MAX_DETECTIONS, &n);
            full_count = n;
        }
        if (st != SH_OK) {
            sh_log_error("%s: frame %d: %s", in, index,
                         sh_error_message());
            rc = 1;
            break;
        }
        if (n > MAX_DETECTIONS) n = MAX_DETECTIONS;
        print_detections(index, found, n);
        memcpy(prev, found, (size_t)n * sizeof *found);
        nprev = n;
    }
    sh_image_destroy(&frame);
    sh_y4m_reader_close(reader);
done:
    if (fflush(stdout) != 0) {
        sh_log_error("cannot write the output");
        rc = 1;
    }
    free(found);
    free(prev);
    free(win);
    sh_detector_destroy(det);
    return rc;
}
