/* stillheart track: AprilTag detection in the tracker's windows, the Kalman tracker, and the
 * points file of `stillheart warp` (with X,Y,Z when calibrated cameras are given). */
#include <getopt.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "app.h"
#include "stillheart/calib.h"
#include "stillheart/detect.h"
#include "stillheart/log.h"
#include "stillheart/points.h"
#include "stillheart/track.h"
#include "stillheart/y4m.h"
#include "track_landmarks.h"

#define MAX_DET SH_TRACK_MAX_DETECTIONS

static const sh_cli cli = {"stillheart track"};

static void usage(FILE *out)
{
    fprintf(out,
        "usage: stillheart track [OPTIONS] IN.y4m [IN2.y4m [IN3.y4m]] > points.csv\n\n"
        "Tracks the AprilTag markers of a recording and writes the points file of\n"
        "`stillheart warp`: `frame,id,x,y`, one row per marker per frame (pixels of the first\n"
        "camera), and `X,Y,Z` (calibration units) with --cameras. Detection runs in windows\n"
        "around the tracker's predictions, with a full-frame scan spread over frames to find\n"
        "lost markers. A marker hidden for a while is still written (predicted from its own\n"
        "rhythm and its neighbours); one unseen for longer than --lost-after is not.\n\n"
        "Markers: --ids lists them; without it a first pass over the first 10 s (or the whole of\n"
        "a shorter file) keeps every tag seen consistently unless its motion says it is not on\n"
        "the heart: still while its neighbours move, or moving unlike them (on an instrument).\n"
        "What is left out, and why, is said on standard error. Then the recording is tracked\n"
        "from its start with those ids (IN must then be files).\n\n"
        "options:\n"
        "  --cameras FILE     calibration YAML (OpenCV FileStorage): one IN per camera, 3D tracking\n"
        "  --ids LIST         marker ids, e.g. 0-15 or 1,4,7\n"
        "  --family F         tag family (default tag36h11)\n"
        "  --fps F            frame rate when the Y4M header has none (default 30)\n"
        "  --noise PX         detection noise, px (default 0.3)\n"
        "  --lost-after S     seconds unseen before a marker is dropped (default 2)\n"
        "  --spatial off|fuse occluded markers from time only, or also from neighbours (default fuse)\n"
        "  --measured-only    write only markers detected in that frame\n"
        "  --landmarks N      also up to N landmarks of the tissue (docs/landmarks.md): chosen in\n"
        "                     frame 0 (--reference) inside its markers' hull and off its tags,\n"
        "                     written as rows with ids from 1000000 (their positions there), then\n"
        "                     in each frame after it the ones found and accepted (from a\n"
        "                     landmark's fourth pass of every test on; --landmarks-sparse: its\n"
        "                     first), which\n"
        "                     `stillheart warp` and `warp3d` take as correspondences like the\n"
        "                     markers; off by default.\n"
        "                     With --cameras, chosen in the first camera and matched in the others\n"
        "                     along epipolar lines: a row only for a landmark triangulated within\n"
        "                     0.5 px of every camera that accepted it, two at least\n"
        "  --landmarks-sparse with --landmarks, for markers too sparse for their map to come\n"
        "                     within 3 px of the tissue (four at the corners of the field): the\n"
        "                     disagreement bound follows the map's error measured on each frame,\n"
        "                     the neighbour test expects a plane, the searches use 3 pyramid\n"
        "                     levels, not 1, the windows must correlate (r >= 0.4, against\n"
        "                     blood over faint texture), and the choice is balanced over the\n"
        "                     field (ranked within 40 px cells: weak texture gets landmarks too);\n"
        "                     with four tags, ask --landmarks 400: the map between them rests on\n"
        "                     the landmarks alone (docs/landmarks.md)\n"
        "  --landmarks-square with --landmarks, the forward search's reference window square, not\n"
        "                     warped by the markers' map's local affine at each landmark (the\n"
        "                     default since 2026-12-06, with a third as many landmarks over 1 px\n"
        "                     off where the tissue deforms: docs/landmarks.md)\n"
        "  --landmarks-refine K\n"
        "                     with --landmarks, the reference's windows averaged with the\n"
        "                     landmarks' matches in the first K frames after it (default 16; 0:\n"
        "                     the reference frame's own): half as many landmarks over 1 px off\n"
        "                     on the phantom; those K frames cost 0.7-1 ms more each at 1080p\n"
        "                     (docs/landmarks.md, \"The reference refined\")\n"
        "  --landmarks-confirm K\n"
        "                     with --landmarks, a landmark used from its K-th pass of every test\n"
        "                     after the reference on, its first K-1 counted `unconfirmed` (1 to\n"
        "                     1000; default 4, and 1 with --landmarks-sparse): a window chosen on\n"
        "                     an instrument's or blood's edge passes a few times before the cover\n"
        "                     moves against the tissue. With four tags on the phantom, from\n"
        "                     covered references 4 took the hidden ones accepted from 11 to 0\n"
        "                     (of 37 310) and from 18 to 5 (of 65 717, the tags alone), the map\n"
        "                     6-14 %% farther from the truth (docs/landmarks.md, \"Confirmed\n"
        "                     before used\")\n"
        "  --reference N      with --landmarks, the frame they are chosen in (default 0): give\n"
        "                     `stillheart warp` the same --reference; frames before it have none.\n"
        "                     Choose a frame where no instrument or blood covers the tissue: a\n"
        "                     landmark chosen on one follows it (docs/landmarks.md, \"An instrument\n"
        "                     in the reference\")\n"
        "  --landmarks-carry  with --landmarks (2D): a frame with 2 of the reference's markers,\n"
        "                     too few for their map, after a frame whose landmarks were written\n"
        "                     (frames with fewer than 2 detected between them, where nothing is\n"
        "                     searched): the landmarks searched from that frame's, and written\n"
        "                     when at each marker detected in both frames (two at least) the\n"
        "                     median motion of its 8 nearest landmarks accepted in both lies\n"
        "                     within 3 px of its own (docs/landmarks.md, \"Carried frames\"); for\n"
        "                     four tags, where two hidden leave too few\n"
        "  --stats            tracking figures on standard error at the end\n"
        "  --json             with --stats: the figures as one JSON object, the last line on\n"
        "                     standard error (standard output carries the points): frames,\n"
        "                     heart_hz and respiration_hz (null before an estimate), detections\n"
        "                     {used, gated, duplicated, unknown, inconsistent_3d, misshapen, held,\n"
        "                     jumped}, markers_lost, camera_moved_frames, ids [...], calibration\n"
        "                     {samples, median_px, worst_camera, worst_px, behind} (null in 2D);\n"
        "                     with --landmarks, landmarks {chosen, accepted, lost, photometric,\n"
        "                     backward, disagrees, deviates: camera 0's landmark-frames; with\n"
        "                     --cameras also in_3d, unmatched_3d, inconsistent_3d; with\n"
        "                     --landmarks-carry also carried_frames, not_carried_frames}\n"
        SH_CLI_USAGE
        "A progress line (frames, ETA) is shown on standard error when it is a terminal.\n");
}

static int parse_ids(const char *text, int *ids, int *n)
{
    *n = 0;
    const char *p = text;
    while (*p) {
        char *end;
        long a = strtol(p, &end, 10), b;
        if (end == p || a < 0 || a > 1000000) return 0;
        p = end;
        b = a;
        if (*p == '-') {
            p++;
            b = strtol(p, &end, 10);
            if (end == p || b < a || b > 1000000) return 0;
            p = end;
        }
        for (long v = a; v <= b; v++) {
            if (*n >= SH_TRACK_MAX_MARKERS) return 0;
            ids[(*n)++] = (int)v;
        }
        if (*p == ',') p++;
        else if (*p) return 0;
    }
    return *n > 0;
}

/* Same id, same place (within 1 px): one tag found by two overlapping windows. */
static int dedupe(sh_detection *d, int n)
{
    int w = 0;
    for (int i = 0; i < n; i++) {
        int dup = 0;
        for (int j = 0; j < w && !dup; j++)
            dup = d[j].id == d[i].id && fabs(d[j].cx - d[i].cx) < 1 && fabs(d[j].cy - d[i].cy) < 1;
        if (!dup) d[w++] = d[i];
    }
    return w;
}

/* What the command line asks for; filled by parse_options only (the options/runtime split of
 * ustreamer: track_job and track_pass below hold what the run opens). */
typedef struct {
    const char *in[SH_TRACK_MAX_CAMERAS];
    int ncam;
    const char *calib_path, *family;
    int ids[SH_TRACK_MAX_MARKERS], nids; /* --ids; none: found by a first pass */
    double fps;
    sh_track_options topts; /* --noise, --lost-after, --spatial */
    int measured_only, stats, json;
    int landmarks; /* --landmarks N; 0: none */
    int landmarks_sparse; /* --landmarks-sparse */
    int landmarks_square; /* --landmarks-square */
    int landmarks_carry; /* --landmarks-carry */
    int landmarks_refine, refine_given; /* --landmarks-refine K (sh_landmarks_params_default's without) */
    int landmarks_confirm; /* --landmarks-confirm K; 0: not given, the tests' own */
    int reference, reference_given; /* --reference N: the landmarks' frame */
} track_options;

/* Fills o from argv: APP_GO_ON, or the exit code (usage and refusals printed). */
static int parse_options(int argc, char **argv, track_options *o)
{
    static const struct option longopts[] = {
        {"cameras", required_argument, 0, 'c'}, {"ids", required_argument, 0, 'i'},
        {"family", required_argument, 0, 'f'},  {"fps", required_argument, 0, 'r'},
        {"noise", required_argument, 0, 'n'},   {"lost-after", required_argument, 0, 'l'},
        {"spatial", required_argument, 0, 's'}, {"measured-only", no_argument, 0, 'm'},
        {"stats", no_argument, 0, 'S'},         {"json", no_argument, 0, 'j'},
        {"landmarks", required_argument, 0, 'L'}, {"landmarks-sparse", no_argument, 0, 'P'},
        {"landmarks-square", no_argument, 0, 'A'}, {"landmarks-carry", no_argument, 0, 'K'},
        {"landmarks-refine", required_argument, 0, 'F'}, {"reference", required_argument, 0, 'R'},
        {"landmarks-confirm", required_argument, 0, 'C'}, SH_CLI_OPTIONS, {0, 0, 0, 0}};
    memset(o, 0, sizeof *o);
    sh_track_options_default(&o->topts);
    sh_landmarks_params lp;
    sh_landmarks_params_default(&lp);
    o->landmarks_refine = lp.refine;
    optind = 1;
    opterr = 0;
    int ch;
    while ((ch = getopt_long(argc, argv, ":h", longopts, NULL)) != -1) {
        switch (ch) {
        case 'c': o->calib_path = optarg; break;
        case 'i':
            if (!parse_ids(optarg, o->ids, &o->nids))
                return sh_cli_usage_error(&cli, "--ids: '%s' is not a list like 0-15 or 1,4,7 (at most %d ids)",
                                          optarg, SH_TRACK_MAX_MARKERS);
            break;
        case 'f': o->family = optarg; break;
        case 'r': if (!sh_cli_parse_double("--fps", optarg, 0.1, 1000, &o->fps)) return 2; break;
        case 'n': if (!sh_cli_parse_double("--noise", optarg, 0.01, 20, &o->topts.meas_sigma)) return 2; break;
        case 'l': if (!sh_cli_parse_double("--lost-after", optarg, 0.1, 60, &o->topts.lost_after)) return 2; break;
        case 's':
            if (!strcmp(optarg, "off")) o->topts.spatial = SH_SPATIAL_OFF;
            else if (!strcmp(optarg, "fuse")) o->topts.spatial = SH_SPATIAL_FUSE;
            else return sh_cli_usage_error(&cli, "--spatial: off or fuse, not '%s'", optarg);
            break;
        case 'm': o->measured_only = 1; break;
        case 'S': o->stats = 1; break;
        case 'j': o->json = 1; break;
        case 'L': if (!sh_cli_parse_int("--landmarks", optarg, 1, 100000, &o->landmarks)) return 2; break;
        case 'P': o->landmarks_sparse = 1; break;
        case 'A': o->landmarks_square = 1; break;
        case 'K': o->landmarks_carry = 1; break;
        case 'F':
            if (!sh_cli_parse_int("--landmarks-refine", optarg, 0, 1000, &o->landmarks_refine)) return 2;
            o->refine_given = 1;
            break;
        case 'C': if (!sh_cli_parse_int("--landmarks-confirm", optarg, 1, 1000, &o->landmarks_confirm)) return 2; break;
        case 'R':
            if (!sh_cli_parse_int("--reference", optarg, 0, 1 << 30, &o->reference)) return 2;
            o->reference_given = 1;
            break;
        case 'h': usage(stdout); return 0;
        default: { int rc = sh_cli_option(&cli, ch, argv); if (rc >= 0) return rc; } break;
        }
    }
    if (o->json && !o->stats) return sh_cli_usage_error(&cli, "--json goes with --stats");
    o->ncam = argc - optind;
    if (o->ncam < 1 || o->ncam > SH_TRACK_MAX_CAMERAS)
        return sh_cli_usage_error(&cli, "need one to %d videos", SH_TRACK_MAX_CAMERAS);
    for (int c = 0; c < o->ncam; c++) o->in[c] = argv[optind + c];
    if (o->landmarks_sparse && !o->landmarks) return sh_cli_usage_error(&cli, "--landmarks-sparse goes with --landmarks");
    if (o->landmarks_square && !o->landmarks) return sh_cli_usage_error(&cli, "--landmarks-square goes with --landmarks");
    if (o->refine_given && !o->landmarks) return sh_cli_usage_error(&cli, "--landmarks-refine goes with --landmarks");
    if (o->landmarks_carry && !o->landmarks) return sh_cli_usage_error(&cli, "--landmarks-carry goes with --landmarks");
    if (o->landmarks_confirm && !o->landmarks)
        return sh_cli_usage_error(&cli, "--landmarks-confirm goes with --landmarks");
    /* the markers' rows do not depend on a reference: only the landmarks are chosen in one */
    if (o->reference_given && !o->landmarks) return sh_cli_usage_error(&cli, "--reference goes with --landmarks");
    if (o->landmarks_carry && o->calib_path)
        return sh_cli_usage_error(&cli, "--landmarks-carry is 2D: in 3D each landmark needs the markers' map into "
                                        "every camera");
    return APP_GO_ON;
}

/* What both passes share, from track_open to track_close. */
typedef struct {
    const track_options *o;
    sh_calib calib;
    int have_calib;
    sh_detector *det;
    sh_track_options topts; /* the options' with the frame rate, then the ids */
    int ids[SH_TRACK_MAX_MARKERS], nids;
} track_job;

/* The calibration (--cameras) and the detector: 0, or the exit code with the reason printed. */
static int track_open(track_job *job, const track_options *o)
{
    memset(job, 0, sizeof *job);
    job->o = o;
    job->topts = o->topts;
    memcpy(job->ids, o->ids, sizeof job->ids);
    job->nids = o->nids;
    if (o->calib_path) {
        if (sh_calib_read(o->calib_path, &job->calib) != SH_OK) {
            sh_log_error("%s", sh_error_message());
            return 1;
        }
        if (job->calib.num_cameras != o->ncam) {
            sh_log_error("%s has %d cameras, %d videos given", o->calib_path,
                         job->calib.num_cameras, o->ncam);
            return 2;
        }
        job->have_calib = o->ncam > 1;
        if (o->ncam == 1)
            sh_log_info("one camera: tracking in pixels (the calibration's "
                            "3D needs two or more)");
    } else if (o->ncam > 1) {
        sh_log_error("%d videos need --cameras (their calibration)", o->ncam);
        return 2;
    }
    job->topts.fps = o->fps;
    sh_detector_options dopts;
    sh_detector_options_default(&dopts);
    if (o->family) dopts.family = o->family;
    if (sh_detector_create(&dopts, &job->det) != SH_OK) {
        sh_log_error("%s", sh_error_message());
        return 1;
    }
    return 0;
}

static void track_close(track_job *job) { sh_detector_destroy(job->det); }

/* One pass's readers and tracker, from pass_open to pass_close. */
typedef struct {
    sh_y4m_reader *rd[SH_TRACK_MAX_CAMERAS];
    sh_image img[SH_TRACK_MAX_CAMERAS];
    sh_tracker *t;
    sh_window win[SH_TRACK_MAX_CAMERAS][SH_TRACK_MAX_MARKERS + 1];
    sh_track_estimate est[SH_TRACK_MAX_MARKERS];
    sh_point rows[SH_TRACK_MAX_MARKERS]; /* the frame's marker rows (write_rows) */
    int nrows;
    int measured[SH_TRACK_MAX_MARKERS];  /* the ids of those detected in the frame */
    int nmeasured;
    int ndet0;                           /* camera 0's detections of the frame */
    track_landmarks *lm;                 /* --landmarks, from the reference frame on */
} track_pass;

/* Each camera's detections of the current frame (static: too large for the stack). */
static sh_detection dets[SH_TRACK_MAX_CAMERAS][MAX_DET];

/* The library's message for a failed call: 1. */
static int fail(void)
{
    sh_log_error("%s", sh_error_message());
    return 1;
}

/* The videos (of one size), their frame buffers and the tracker: 0, or 1 with the reason
 * printed (pass_close frees either way). */
static int pass_open(const track_job *job, track_pass *p)
{
    memset(p, 0, sizeof *p);
    int width = 0, height = 0;
    double fps = 0;
    for (int c = 0; c < job->o->ncam; c++) {
        if (sh_y4m_reader_open(job->o->in[c], &p->rd[c]) != SH_OK) return fail();
        const sh_y4m_header *h = sh_y4m_reader_header(p->rd[c]);
        if (c == 0) {
            width = h->width;
            height = h->height;
            if (h->fps_num > 0 && h->fps_den > 0) fps = (double)h->fps_num / h->fps_den;
        } else if (h->width != width || h->height != height) {
            sh_log_error("%s is %dx%d, %s is %dx%d: the cameras must match",
                         job->o->in[c], h->width, h->height, job->o->in[0], width, height);
            return 1;
        }
        if (sh_image_create(&p->img[c], h->format, h->width, h->height) != SH_OK) return fail();
    }
    if (job->have_calib && (job->calib.width != width || job->calib.height != height))
        sh_log_warn("warning: calibration is for %dx%d, video is %dx%d",
                    job->calib.width, job->calib.height, width, height);
    sh_track_options o = job->topts;
    if (fps > 0 && o.fps <= 0) o.fps = fps;
    if (o.fps <= 0) o.fps = 30;
    o.width = width;
    o.height = height;
    if (sh_tracker_create(&o, job->have_calib ? &job->calib : NULL, &p->t) != SH_OK) return fail();
    return 0;
}

static void pass_close(const track_job *job, track_pass *p)
{
    track_landmarks_destroy(p->lm);
    sh_tracker_destroy(p->t);
    for (int c = 0; c < job->o->ncam; c++) {
        sh_image_destroy(&p->img[c]);
        if (p->rd[c]) sh_y4m_reader_close(p->rd[c]);
    }
}

/* Camera c's tags in frame f, into dets[c]: in the tracker's windows, whole when it has none or
 * asks for a rescan. 0, or 1 with the reason printed. */
static int detect_camera(const track_job *job, track_pass *p, int c, int f, int *count)
{
    int nw = 0, nb = 0, n = 0;
    sh_window *win = p->win[c];
    if (sh_tracker_windows(p->t, c, win, SH_TRACK_MAX_MARKERS, &nw) != SH_OK) return fail();
    if (sh_tracker_reacquire(p->t, c, &win[nw], &nb) != SH_OK) return fail();
    sh_status st;
    if (f == 0 || nw == 0) st = sh_detector_detect(job->det, &p->img[c], dets[c], MAX_DET, &n);
    else st = sh_detector_detect_windows(job->det, &p->img[c], win, nw + nb, dets[c], MAX_DET, &n);
    if (st == SH_OK && f > 0 && nw > 0 && sh_tracker_rescan(p->t, c, dets[c], n < MAX_DET ? n : MAX_DET))
        st = sh_detector_detect(job->det, &p->img[c], dets[c], MAX_DET, &n);
    if (st != SH_OK) {
        sh_log_error("%s: frame %d: %s", job->o->in[c], f, sh_error_message());
        return 1;
    }
    if (n > MAX_DET) n = MAX_DET;
    *count = dedupe(dets[c], n);
    return 0;
}

/* Frame f's rows of the points file (the header before frame 0): 0, or 1 with the reason
 * printed. */
static int write_rows(const track_job *job, track_pass *p, int f, FILE *out)
{
    sh_point *rows = p->rows;
    int n = sh_tracker_estimates(p->t, p->est, SH_TRACK_MAX_MARKERS), nr = 0;
    p->nmeasured = 0;
    for (int k = 0; k < n; k++) {
        const sh_track_estimate *e = &p->est[k];
        if (!e->confirmed || e->status == SH_TRACK_LOST || !e->in_view[0]) continue;
        if (job->o->measured_only && e->status != SH_TRACK_MEASURED) continue;
        if (e->status == SH_TRACK_MEASURED) p->measured[p->nmeasured++] = e->id;
        sh_point *r = &rows[nr++];
        r->frame = f;
        r->id = e->id;
        r->x = e->xy[0][0];
        r->y = e->xy[0][1];
        r->X = e->dim == 3 ? e->pos[0] : NAN;
        r->Y = e->dim == 3 ? e->pos[1] : NAN;
        r->Z = e->dim == 3 ? e->pos[2] : NAN;
    }
    int ok = f != 0 || fprintf(out, "frame,id,x,y%s\n", job->have_calib ? ",X,Y,Z" : "") >= 0;
    for (int k = 0; k < nr && ok; k++) {
        const sh_point *r = &rows[k];
        ok = (job->have_calib
                  ? fprintf(out, "%d,%d,%.4f,%.4f,%.5f,%.5f,%.5f\n", r->frame, r->id, r->x, r->y, r->X, r->Y, r->Z)
                  : fprintf(out, "%d,%d,%.4f,%.4f\n", r->frame, r->id, r->x, r->y)) >= 0;
    }
    if (!ok) sh_log_error("writing the points: write error");
    p->nrows = nr;
    if (!ok || !job->o->landmarks) return !ok;
    /* the tissue's landmarks after the frame's markers (their ids sort after) */
    if (f == job->o->reference) {
        int full = sh_y4m_header_full_range(sh_y4m_reader_header(p->rd[0]));
        track_landmarks_options lo = {job->o->landmarks, job->o->landmarks_sparse, !job->o->landmarks_square,
                                      job->o->landmarks_carry, job->o->ncam, full,
                                      job->have_calib ? &job->calib : NULL, job->o->landmarks_refine,
                                      job->o->landmarks_confirm, job->o->reference};
        return track_landmarks_start(&lo, p->img, dets[0], p->ndet0, rows, nr, p->measured, p->nmeasured, out,
                                     &p->lm);
    }
    return p->lm && track_landmarks_frame(p->lm, p->img, f, rows, nr, p->measured, p->nmeasured, out);
}

enum { FRAME_DONE, FRAME_FAILED, FRAME_END };

/* Frame f of every camera through the tracker, its rows to out (when not NULL): FRAME_DONE,
 * FRAME_END when a video has ended, FRAME_FAILED with the reason printed. */
static int pass_frame(const track_job *job, track_pass *p, int f, FILE *out)
{
    int eof = 0, ncam = job->o->ncam;
    for (int c = 0; c < ncam; c++) {
        sh_status st = sh_y4m_reader_read(p->rd[c], &p->img[c]);
        if (st == SH_EEOF) {
            if (c > 0 && !eof)
                sh_log_warn("warning: %s ends at frame %d before %s",
                            job->o->in[c], f, job->o->in[0]);
            eof = 1;
        } else if (st != SH_OK) {
            fail();
            return FRAME_FAILED;
        }
    }
    if (eof) return FRAME_END;
    if (sh_tracker_predict(p->t, f) != SH_OK) {
        fail();
        return FRAME_FAILED;
    }
    const sh_detection *dp[SH_TRACK_MAX_CAMERAS];
    int count[SH_TRACK_MAX_CAMERAS];
    for (int c = 0; c < ncam; c++) {
        if (detect_camera(job, p, c, f, &count[c])) return FRAME_FAILED;
        dp[c] = dets[c];
    }
    p->ndet0 = count[0];
    if (sh_tracker_update(p->t, dp, count, ncam) != SH_OK) {
        fail();
        return FRAME_FAILED;
    }
    return out && write_rows(job, p, f, out) ? FRAME_FAILED : FRAME_DONE;
}

/* --stats --json: the figures of pass_report as one JSON object on stderr. */
static void stats_json(const track_job *job, track_pass *p)
{
    sh_track_stats s;
    sh_tracker_stats(p->t, &s);
    sh_track_calibration cc;
    sh_tracker_calibration(p->t, &cc);
    sh_cli_json j;
    sh_cli_json_start(&j, stderr);
    sh_cli_json_object(&j, NULL);
    sh_cli_json_int(&j, "frames", s.frames);
    sh_cli_json_number(&j, "heart_hz", s.heart_hz > 0 ? s.heart_hz : NAN);
    sh_cli_json_number(&j, "respiration_hz", s.resp_hz > 0 ? s.resp_hz : NAN);
    sh_cli_json_object(&j, "detections");
    sh_cli_json_int(&j, "used", s.accepted);
    sh_cli_json_int(&j, "gated", s.gated);
    sh_cli_json_int(&j, "duplicated", s.duplicates);
    sh_cli_json_int(&j, "unknown", s.unknown);
    sh_cli_json_int(&j, "inconsistent_3d", s.inconsistent);
    sh_cli_json_int(&j, "misshapen", s.misshapen);
    sh_cli_json_int(&j, "held", s.held);
    sh_cli_json_int(&j, "jumped", s.jumped);
    sh_cli_json_end(&j);
    sh_cli_json_int(&j, "markers_lost", s.lost);
    sh_cli_json_int(&j, "camera_moved_frames", s.camera_moves);
    sh_cli_json_array(&j, "ids");
    for (int k = 0; k < job->nids; k++) sh_cli_json_int(&j, NULL, job->ids[k]);
    sh_cli_json_end(&j);
    if (cc.samples) {
        sh_cli_json_object(&j, "calibration");
        sh_cli_json_int(&j, "samples", cc.samples);
        sh_cli_json_number(&j, "median_px", cc.median_px);
        sh_cli_json_int(&j, "worst_camera", cc.worst_camera);
        sh_cli_json_number(&j, "worst_px", cc.worst_px);
        sh_cli_json_number(&j, "behind", cc.failed);
        sh_cli_json_end(&j);
    } else {
        sh_cli_json_null(&j, "calibration");
    }
    if (p->lm) {
        track_landmarks_stats ls;
        track_landmarks_stats_get(p->lm, &ls);
        sh_cli_json_object(&j, "landmarks");
        sh_cli_json_int(&j, "chosen", ls.chosen);
        for (int v = 0; v < SH_LANDMARK_VERDICTS; v++)
            sh_cli_json_int(&j, sh_landmark_verdict_name((sh_landmark_verdict)v), ls.verdicts[v]);
        if (job->o->landmarks_carry) {
            sh_cli_json_int(&j, "carried_frames", ls.carried);
            sh_cli_json_int(&j, "not_carried_frames", ls.not_carried);
        }
        if (job->have_calib) {
            sh_cli_json_int(&j, "in_3d", ls.in_3d);
            sh_cli_json_int(&j, "unmatched_3d", ls.unmatched);
            sh_cli_json_int(&j, "inconsistent_3d", ls.inconsistent);
        }
        sh_cli_json_end(&j);
    }
    sh_cli_json_end(&j);
}

/* --stats with --landmarks: what became of them. */
static void landmarks_report(const track_job *job, const track_pass *p)
{
    if (!p->lm) return;
    track_landmarks_stats s;
    track_landmarks_stats_get(p->lm, &s);
    const long long *v = s.verdicts;
    sh_log_info("landmarks: %d chosen; landmark-frames of camera 0: accepted %lld, lost %lld, photometric %lld, "
                "backward %lld, disagrees %lld, deviates %lld, unconfirmed %lld",
                s.chosen, v[SH_LANDMARK_ACCEPTED], v[SH_LANDMARK_LOST], v[SH_LANDMARK_PHOTOMETRIC],
                v[SH_LANDMARK_BACKWARD], v[SH_LANDMARK_DISAGREES], v[SH_LANDMARK_DEVIATES],
                v[SH_LANDMARK_UNCONFIRMED]);
    if (job->o->landmarks_carry)
        sh_log_info("landmarks carried %lld frames with too few markers; in %lld more they did not vouch for the map",
                    s.carried, s.not_carried);
    if (job->have_calib)
        sh_log_info("landmarks in 3D: %d with a reference (matched in frame 0); of camera 0's accepted, %lld matched "
                    "by no other camera, %lld refused by the reprojection test (%.1f px)",
                    s.in_3d, s.unmatched, s.inconsistent, SH_LANDMARKS_MAX_REPROJ_PX);
}

/* The end of a pass: the verdicts on every tag seen (sh_tracker_judge_ids, when asked for) and,
 * with --stats on the writing pass, the tracking figures. */
static void pass_report(const track_job *job, track_pass *p, FILE *out, sh_track_id *judged, int *njudged)
{
    if (judged) *njudged = sh_tracker_judge_ids(p->t, judged, SH_TRACK_MAX_MARKERS);
    if (!job->o->stats || !out) return;
    if (job->o->json) {
        stats_json(job, p);
        return;
    }
    sh_track_stats s;
    sh_tracker_stats(p->t, &s);
    char heart[48], resp[48];
    sh_track_rate_text(s.heart_hz, heart, sizeof heart);
    sh_track_rate_text(s.resp_hz, resp, sizeof resp);
    sh_log_info("%ld frames, heart %s, respiration %s; detections used %ld, "
                "gated %ld, duplicated ids %ld, unknown ids %ld, inconsistent 3D %ld, taken on their "
                "neighbours' agreement %ld; markers lost %ld; camera moved in %ld frames",
                s.frames, heart, resp, s.accepted, s.gated, s.duplicates, s.unknown,
                s.inconsistent, s.jumped, s.lost, s.camera_moves);
    sh_track_calibration cc;
    sh_tracker_calibration(p->t, &cc);
    if (cc.samples)
        sh_log_info("calibration: reprojection median %.3f px over the last %d markers seen by two or more "
                    "cameras, camera %d's views %.3f px, %.0f %% behind a camera",
                    cc.median_px, cc.samples, cc.worst_camera, cc.worst_px, 100 * cc.failed);
    landmarks_report(job, p);
}

/* One pass: max_frames (< 0: all). out NULL: no output; judged (when not NULL) gets the verdicts
 * on every tag seen at the end. Returns 0 on success. */
static int run_pass(const track_job *job, int max_frames, FILE *out, sh_track_id *judged, int *njudged)
{
    track_pass p;
    int rc = pass_open(job, &p);
    sh_cli_progress progress;
    long long total = rc ? -1 : sh_y4m_reader_whole_frames(p.rd[0]);
    if (max_frames >= 0 && (total < 0 || total > max_frames)) total = max_frames;
    sh_cli_progress_start(&progress, out ? "track" : "track: finding the markers",
                          total < 0 || total > 1 << 30 ? 0 : (int)total, "frames");
    int f;
    for (f = 0; !rc && (max_frames < 0 || f < max_frames); f++) {
        int step = pass_frame(job, &p, f, out);
        if (step == FRAME_END) break;
        rc = step == FRAME_FAILED;
        sh_cli_progress_update(&progress, f + 1);
    }
    sh_cli_progress_end(&progress);
    if (!rc && out && job->o->landmarks && f <= job->o->reference) {
        /* the markers are written, but what was asked for is not there: not a success */
        sh_log_error("--reference %d: %s has %d frames, no landmarks chosen", job->o->reference, job->o->in[0], f);
        rc = 1;
    }
    if (!rc) pass_report(job, &p, out, judged, njudged);
    pass_close(job, &p);
    return rc;
}

/* The first pass's verdicts on standard error: what is kept, and every tag left out or kept
 * without a comparison (all: every tag), with why. The kept ids into ids; returns their count. */
static int report_ids(const sh_track_id *v, int n, int *ids, const char *in, int all)
{
    char list[1024] = "", why[256];
    int nk = 0;
    size_t len = 0;
    for (int k = 0; k < n; k++) {
        if (!v[k].keep) continue;
        ids[nk++] = v[k].id;
        /* ranges: 0-15,17 */
        int run_end = k + 1 < n && v[k + 1].keep && v[k + 1].id == v[k].id + 1;
        int run_in = nk > 1 && ids[nk - 2] == v[k].id - 1;
        if (run_in && run_end) continue;
        if (len < sizeof list)
            len += (size_t)snprintf(list + len, sizeof list - len, "%s%d", run_in ? "-" : nk > 1 ? "," : "", v[k].id);
    }
    sh_log_info("markers found in %s: %d of the %d tags seen (ids %s)", in, nk, n, nk ? list : "none");
    for (int k = 0; k < n; k++) {
        if (v[k].keep && v[k].verdict == SH_TRACK_ID_KEPT && !all) continue;
        sh_track_id_text(&v[k], why, sizeof why);
        if (v[k].keep) sh_log_info("tag %d kept as a marker, %s", v[k].id, why);
        else sh_log_warn("warning: tag %d left out, %s", v[k].id, why);
    }
    return nk;
}

/* Without --ids: the markers among the tags of the first 10 s (a short file is judged whole), by
 * a first pass. 0, or the exit code with the reason printed. */
static int find_ids(track_job *job)
{
    const track_options *o = job->o;
    for (int c = 0; c < o->ncam; c++)
        if (!strcmp(o->in[c], "-")) {
            sh_log_error("standard input needs --ids (the markers are found "
                            "in a first pass over the file)");
            return 2;
        }
    double f0 = o->fps > 0 ? o->fps : 30;
    sh_track_id judged[SH_TRACK_MAX_MARKERS];
    int nj = 0;
    if (run_pass(job, (int)(f0 * 10), NULL, judged, &nj) != 0) return 1;
    if ((job->nids = report_ids(judged, nj, job->ids, o->in[0], o->stats)) == 0) {
        sh_log_error("no tag seen consistently in the first 10 s of %s (give the markers with --ids)", o->in[0]);
        return 1;
    }
    return 0;
}

int cmd_track(int argc, char **argv)
{
    sh_log_setup(SH_LOG_TOOL, "stillheart track", SH_LOG_INFO);
    track_options o;
    int rc = parse_options(argc, argv, &o);
    if (rc != APP_GO_ON) return rc;
    track_job job;
    if ((rc = track_open(&job, &o))) return rc;
    if (job.nids == 0) rc = find_ids(&job);
    if (rc == 0) {
        job.topts.ids = job.ids;
        job.topts.num_ids = job.nids;
        rc = run_pass(&job, -1, stdout, NULL, NULL);
        if (rc == 0 && fflush(stdout) != 0) {
            sh_log_error("writing the points: write error");
            rc = 1;
        }
    }
    track_close(&job);
    return rc;
}
