/* stillheart-eval: how still is a stabilized video? The paper's e (section V, Table II), its
 * error image as a heatmap (Figures 2 and 3), and on phantom sequences the geometric error. */
#include <errno.h>
#include <getopt.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include "eval.h"
#include "stillheart/cli.h"
#include "stillheart/log.h"
#include "stillheart/y4m.h"

#define PROG "stillheart-eval"

static const sh_cli cli = {PROG};

static void usage(FILE *f)
{
    fprintf(f,
        "usage: " PROG " --points P.csv [options] STABILIZED.y4m [ORIGINAL.y4m]\n"
        "       " PROG " --truth DIR --export-points OUT.csv [--camera C]\n"
        "       " PROG " --truth DIR --points P.csv --landmarks N [options] ORIGINAL.y4m\n"
        "       " PROG " --truth DIR --spectrum [--camera C] [--json] VIDEO.y4m\n"
        "Measures the residual motion of a stabilized video as the paper does (section V):\n"
        "  I_error(x,y,c) = 1/k sum_t |I_t(x,y,c) - I_N(x,y,c)|,  e = sum_c 1/p sum_(x,y) I_error\n"
        "over all k frames of the video (the reference frame N included, as `stillheart warp`\n"
        "counts), the R, G, B channels in [0, 1] (YUV converted with BT.601, full range when the\n"
        "Y4M header says XCOLORRANGE=FULL, else limited; a mono video counts its one channel), and\n"
        "the p pixels whose centre lies in the convex hull of frame N's markers in P.csv.\n"
        "With ORIGINAL (the unstabilized input) its e is reported too, over the same hull.\n\n"
        "  --points P.csv     marker positions per frame (frame,id,x,y[,X,Y,Z]), as given to\n"
        "                     `stillheart warp`; frame N's markers make the hull\n"
        "  --reference N      0-based reference frame (default 0)\n"
        "  --heatmap OUT.png  I_error averaged over the channels (grey in [0, 1]) in the viridis\n"
        "                     colour map, with contour lines (white) of its local mean at\n"
        "                     --contours levels evenly spaced below --heatmap-max; dark grey\n"
        "                     outside the hull; the video's size times --heatmap-scale, with the\n"
        "                     colour scale and its numbers (0, the contour levels, the top) in a\n"
        "                     strip along the bottom edge, or the top one if fewer hull pixels\n"
        "                     lie under it there (left out of a picture too small for it)\n"
        "  --heatmap-scale S  the heatmap's size as a multiple of the video's, 1/64..8 (default 1:\n"
        "                     it stacks beside the video, e.g. with ffmpeg's hstack)\n"
        "  --heatmap-max V    grey value shown as the top of the map (default 0.2; larger\n"
        "                     values saturate), fixed so that heatmaps compare\n"
        "  --contours L       number of contour levels (default 4; 0: none)\n"
        "  --json             one JSON object on stdout instead of the table: the file names\n"
        "                     stabilized, original, points and heatmap (null when not given),\n"
        "                     e_stabilized, e_original (null without ORIGINAL), frames, pixels, reference,\n"
        "                     geometric {method, camera, stride, mean, p95, max, samples,\n"
        "                     points, hidden, unmapped, raw_frames} (null without --truth)\n"
        SH_CLI_USAGE "\n"
        "Geometric error on phantom sequences (stillheart-render folders):\n"
        "  --truth DIR        the phantom folder (DIR/phantom.txt) the video was rendered from.\n"
        "                     For every hull pixel q of frame N on a lattice of --geo-stride px,\n"
        "                     the map f_t(q) the warp used in frame t (rebuilt from P.csv as\n"
        "                     `stillheart warp --method M` builds it) is compared with g_t(q),\n"
        "                     where the surface point seen at q in frame N truly is in frame t:\n"
        "                     mean, 95th percentile (nearest rank) and max of |f_t(q) - g_t(q)|\n"
        "                     in pixels over all samples and frames. Pairs the truth says are\n"
        "                     hidden in frame t (or at q in frame N) are skipped and counted, as\n"
        "                     are pixels outside the warp's hull when markers were missing.\n"
        "                     Frames the warp left raw (fewer than 3 markers) have f_t(q) = q.\n"
        "  --cameras CALIB    STABILIZED is `stillheart warp3d`'s reference view (its default): its\n"
        "                     map is rebuilt from P.csv's X,Y,Z as warp3d builds it, the camera\n"
        "                     --camera of CALIB (the render's calibration.yaml) both source and\n"
        "                     view; the method from the header's method3d:NAME[/NAME] or --method\n"
        "                     (NAME or SURFACE/DISPLACEMENT); frames with fewer than 4 markers\n"
        "                     are raw\n"
        "  --camera C         camera of the phantom the video shows (default 0)\n"
        "  --geo-stride S     sample spacing in pixels (default 4)\n"
        "  --method M         the warp's method: affine, pwlinear, bspline, rbf-local, tps,\n"
        "                     gaussian, their -pure forms, or none (the map is the identity: the\n"
        "                     geometric error of the unstabilized video). Default: the method\n"
        "                     STABILIZED's header names (XSTILLHEART=method:NAME, as `stillheart\n"
        "                     warp` and `run` write it); a video without it needs --method, and\n"
        "                     one that names another method is refused (exit 2)\n"
        "  --sigma S, --levels L, --smoothing LAMBDA, --max-error PX\n"
        "                     as for `stillheart warp`; give the values the warp ran with\n"
        "  --export-points OUT.csv\n"
        "                     with --truth: writes the points file of DIR/markers.csv's visible\n"
        "                     tag centres (point c) of --camera ('-' = standard output), the\n"
        "                     ground-truth correspondences for `stillheart warp`, and exits\n"
        "Natural landmarks on phantom sequences (issue 19; docs/landmarks.md):\n"
        "  --landmarks N      instead of the above: up to N landmarks of the tissue chosen in\n"
        "                     ORIGINAL's frame N (--reference) inside its markers' hull, off the\n"
        "                     tags and highlights, then found in every later frame starting from\n"
        "                     the markers' map of --method (default tps) fitted to P.csv's\n"
        "                     markers, and judged (accepted, lost, photometric, backward,\n"
        "                     disagrees); the accepted ones against the truth: mean, p99 and max\n"
        "                     px, how many more than 1 px off or hidden (both wrong), and how\n"
        "                     many had part of their window hidden by the truth (instrument,\n"
        "                     blood, the view's edge) and of those more than 1 px off, beside the\n"
        "                     markers' map at the same points; the time per frame (one thread);\n"
        "                     the geometric error over the hull of the markers' map and of the\n"
        "                     same method fitted to the markers and the accepted landmarks\n"
        "                     (each map as the warp makes it: the displacement interpolated)\n"
        "  --landmarks-points OUT.csv\n"
        "                     also writes P.csv's rows (2D columns) with the landmarks' (ids from\n"
        "                     1000000: all of them in frame N at their reference positions, in\n"
        "                     each later frame the accepted ones), as `stillheart track\n"
        "                     --landmarks` writes them, for `stillheart warp`\n"
        "  --lm-photometric G, --lm-backward PX, --lm-disagreement PX\n"
        "                     the tests' thresholds (defaults 12 grey levels, 0.5 px, 3 px;\n"
        "                     --lm-backward 0: no backward test)\n"
        "  --lm-distance PX, --lm-quality Q\n"
        "                     the choice's spacing and corner threshold (a fraction of the\n"
        "                     strongest corner's response; defaults 14 px, 0.003)\n"
        "  --landmark-smoothing LAMBDA\n"
        "                     with TPS (the RBFs): the smoothing of the landmarks in the map,\n"
        "                     added to their diagonal of its system, the markers' left exact\n"
        "                     (default 1000; 0: the landmarks interpolated too), for 1080p\n"
        "                     frames: 4 times it at 4K, where the landmarks are found in the\n"
        "                     frame halved. With --points of landmark rows (ids from 1000000),\n"
        "                     give the warp's value (with --cameras, warp3d's: its surface\n"
        "                     and displacement)\n"
        "  --lm-sparse        for markers too sparse for their map (four at the corners): the\n"
        "                     disagreement bound follows the frame's measured map error\n"
        "                     (--lm-bound-factor 4) and the neighbour test expects a plane\n"
        "                     (--lm-plane), and the searches use 3 pyramid levels, not 1 (the\n"
        "                     map may be 10 px off), the windows must correlate\n"
        "                     (--lm-correlation 0.4), each pass is used at once (--lm-confirm 1)\n"
        "                     and the choice is balanced over the field (--lm-balance 40), as\n"
        "                     `stillheart track --landmarks-sparse`\n"
        "  --lm-bound-factor K  the bound: K times the median distance from the map of the\n"
        "                     landmarks the tests before it keep, never below --lm-disagreement\n"
        "  --lm-plane         the neighbour test expects the planes through three neighbours\n"
        "  --lm-square        the forward search's window square, not pre-warped by the\n"
        "                     markers' map's local affine (sh_landmarks_params.affine, the\n"
        "                     default since 2026-12-06)\n"
        "  --lm-jump K        the photometric test also holds a landmark's window difference to\n"
        "                     K times its median over the last 16 frames the landmark was\n"
        "                     accepted in (default 2.5, since 2026-12-06; 0: not)\n"
        "  --lm-relative K    the photometric test also holds the windows' difference, and\n"
        "                     their centres', to K times its median over the frame's landmarks\n"
        "                     (default 2.5, since 2026-12-07; 0: not)\n"
        "  --lm-correlation R the photometric test also holds the windows at the result to a\n"
        "                     normalized cross-correlation of at least R (0 to 1: 0, not tested,\n"
        "                     the default; 0.4 with --lm-sparse, given after it to change)\n"
        "  --lm-refine K      the reference's windows averaged with the matches of the first K\n"
        "                     frames that accept landmarks (default 16, since 2026-12-07; 0:\n"
        "                     the reference frame's own)\n"
        "  --lm-confirm K     a landmark used from its K-th pass of every test after the\n"
        "                     reference on, its first K-1 counted unconfirmed (1-1000; default\n"
        "                     4, since 2026-12-07; 1 with --lm-sparse, given after it to change;\n"
        "                     1: at once)\n"
        "  --lm-balance N     the choice ranked within N px cells, each cell's strongest corner\n"
        "                     taken as at least a tenth of the frame's (0-4096; 0: strongest\n"
        "                     first, the default; 40 with --lm-sparse, given after it to change)\n"
        "  --lm-reduce K      the landmarks chosen and found in the frame halved K times (0-4;\n"
        "                     default: automatic, once at 4K, none at 1080p), every length of\n"
        "                     the tests in the halved frame's pixels\n"
        "The phantom's texture (docs/landmarks.md):\n"
        "  --spectrum         instead of the above: the luma's amplitude spectrum ~ 1/f^alpha over\n"
        "                     64 px patches of tissue alone inside the tags' hull (8 frames of\n"
        "                     VIDEO, the truth's tags and occluders): alpha over 4..16 cycles per\n"
        "                     patch and per octave, and the RMS contrast\n"
        "\nLandmark rows against the truth: " PROG " --truth DIR --points P.csv --landmark-rows\n"
        "    [--cameras CALIB] [--camera C] [--reference N] [--json]\n"
        "  --landmark-rows    the rows of P.csv with ids from 1000000 (`stillheart track\n"
        "                     --landmarks`), each landmark's material point located from its row\n"
        "                     in frame N: every later row's x, y against where the truth puts the\n"
        "                     point in camera C (rows the truth says are hidden counted: wrong\n"
        "                     ones); with --cameras, every row's X,Y,Z (frame N's too) projected\n"
        "                     into each camera that sees the point, the worst of them: mean, p99,\n"
        "                     max and rows over 1 px. A landmark chosen where frame N showed the\n"
        "                     instrument or blood is judged against the tissue behind, never\n"
        "                     hidden, and counted apart (covered)\n"
        "STABILIZED may be '-' (standard input) with --reference 0.\n");
}

double eval_now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + ts.tv_nsec * 1e-9;
}

static int fail(const char *what)
{
    const char *m = sh_error_message();
    sh_log_error("%s%s%s", what, *m ? ": " : "", m);
    return 1;
}

/* One video being measured: its reader, a frame buffer and the metric against its frame N. */
typedef struct {
    const char *path;
    sh_y4m_reader *reader;
    sh_image frame;
    sh_metric *metric;
    int full_range;
} video;

static void video_close(video *v)
{
    sh_y4m_reader_close(v->reader);
    sh_image_destroy(&v->frame);
    sh_metric_destroy(v->metric);
}

/* Opens the video and, unless it streams, builds the metric from a first pass to frame N (so any
 * frame can be the reference without holding the video in memory). */
static sh_status video_open(video *v, const char *path, int reference, const sh_hull *hull)
{
    v->path = path;
    sh_status st = sh_y4m_reader_open(path, &v->reader);
    if (st != SH_OK) return st;
    const sh_y4m_header *h = sh_y4m_reader_header(v->reader);
    v->full_range = sh_y4m_header_full_range(h);
    if ((st = sh_image_create(&v->frame, h->format, h->width, h->height)) != SH_OK) return st;
    if (!strcmp(path, "-")) {
        if (reference != 0)
            return sh_error_set(SH_EINVAL, "--reference %d needs a file, not standard input",
                                reference);
        return SH_OK; /* the metric is made from the first frame as it streams by */
    }
    sh_y4m_reader *r;
    if ((st = sh_y4m_reader_open(path, &r)) != SH_OK) return st;
    for (int i = 0; i <= reference && st == SH_OK; i++) st = sh_y4m_reader_read(r, &v->frame);
    sh_y4m_reader_close(r);
    if (st == SH_EEOF) return sh_error_set(SH_EINVAL, "%s has no frame %d", path, reference);
    if (st != SH_OK) return st;
    return sh_metric_create(&v->frame, hull, v->full_range, &v->metric);
}

/* Reads frame t and adds it; SH_EEOF at the end. */
static sh_status video_next(video *v, const sh_hull *hull, int t)
{
    sh_status st = sh_y4m_reader_read(v->reader, &v->frame);
    if (st != SH_OK) return st;
    if (!v->metric && t == 0 &&
        (st = sh_metric_create(&v->frame, hull, v->full_range, &v->metric)) != SH_OK)
        return st;
    return sh_metric_add(v->metric, &v->frame);
}

typedef struct {
    const char *points_path, *truth_dir, *heatmap, *method, *export_out;
    const char *calib_path;          /* --cameras: STABILIZED is warp3d's reference view */
    sh_calib calib;
    int reference, camera, stride, json, contours;
    double heatmap_max, heatmap_scale;
    eval_geo_options geo;
    double sigma, smoothing, max_error; /* --sigma (when have_sigma), --smoothing, --max-error */
    double landmark_smoothing;          /* --landmark-smoothing */
    int levels, have_sigma;
    char tagged_method[SH_Y4M_MAX_EXTRA]; /* the method the video's header named (o.method then) */
    int landmarks;                   /* --landmarks N: 0 when not asked */
    const char *landmarks_points;    /* --landmarks-points OUT.csv */
    int spectrum;                    /* --spectrum */
    int landmark_rows;               /* --landmark-rows */
    sh_landmarks_params lp;
} options;

static void report(const options *o, const video *stab, const video *orig, const eval_geo *geo,
                   const eval_geo_result *g)
{
    double e_orig = orig->metric ? sh_metric_e(orig->metric) : NAN;
    if (o->json) {
        sh_cli_json j;
        sh_cli_json_start(&j, stdout);
        sh_cli_json_object(&j, NULL);
        sh_cli_json_string(&j, "stabilized", stab->path);
        sh_cli_json_string(&j, "original", orig->metric ? orig->path : NULL);
        sh_cli_json_string(&j, "points", o->points_path);
        sh_cli_json_int(&j, "reference", o->reference);
        sh_cli_json_int(&j, "frames", sh_metric_frames(stab->metric));
        sh_cli_json_int(&j, "pixels", sh_metric_pixels(stab->metric));
        sh_cli_json_number(&j, "e_stabilized", sh_metric_e(stab->metric));
        sh_cli_json_number(&j, "e_original", e_orig);
        sh_cli_json_string(&j, "heatmap", o->heatmap);
        if (geo) {
            sh_cli_json_object(&j, "geometric");
            sh_cli_json_string(&j, "method", o->method);
            sh_cli_json_int(&j, "camera", o->camera);
            sh_cli_json_int(&j, "stride", o->stride);
            sh_cli_json_number(&j, "mean", g->mean);
            sh_cli_json_number(&j, "p95", g->p95);
            sh_cli_json_number(&j, "max", g->max);
            sh_cli_json_int(&j, "samples", g->samples);
            sh_cli_json_int(&j, "points", g->points);
            sh_cli_json_int(&j, "hidden", g->hidden);
            sh_cli_json_int(&j, "unmapped", g->unmapped);
            sh_cli_json_int(&j, "raw_frames", g->raw_frames);
            sh_cli_json_end(&j);
        } else {
            sh_cli_json_null(&j, "geometric");
        }
        sh_cli_json_end(&j);
        return;
    }
    printf("%s: reference frame %d, %d frames, %d hull pixels\n", stab->path, o->reference,
           sh_metric_frames(stab->metric), sh_metric_pixels(stab->metric));
    printf("  %-28s %10s  %s\n", "video", "e", "(residual motion, lower is better)");
    printf("  %-28s %10.6f\n", "stabilized", sh_metric_e(stab->metric));
    if (orig->metric) printf("  %-28s %10.6f\n", "original (unstabilized)", e_orig);
    if (geo) {
        printf("geometric error, method %s, camera %d, every %d px (px):\n", o->method, o->camera,
               o->stride);
        printf("  %10s %10s %10s %12s\n", "mean", "p95", "max", "samples");
        printf("  %10.4f %10.4f %10.4f %12lld\n", g->mean, g->p95, g->max, g->samples);
        printf("  (%d hull points see the heart in frame %d; skipped: %lld hidden, %lld outside "
               "the warp's hull; %d frames left raw)\n",
               g->points, o->reference, g->hidden, g->unmapped, g->raw_frames);
    }
    if (o->heatmap) printf("heatmap: %s\n", o->heatmap);
}

static int known_method(const char *name)
{
    sh_interp_params p;
    return sh_interp_params_parse(name, &p) == SH_OK;
}

/* warp3d's interpolants: NAME for both, or SURFACE/DISPLACEMENT (its header's form). */
static sh_status parse_method3d(const char *m, sh_interp_params *surface, sh_interp_params *displacement)
{
    char a[64];
    const char *slash = strchr(m, '/');
    size_t len = slash ? (size_t)(slash - m) : strlen(m);
    if (len >= sizeof a) return sh_error_set(SH_EINVAL, "unknown method '%s'", m);
    memcpy(a, m, len);
    a[len] = '\0';
    sh_status st = sh_interp_params_parse(a, surface);
    return st != SH_OK ? st : sh_interp_params_parse(slash ? slash + 1 : a, displacement);
}

/* The method whose map --truth measures: --method, else the one the video's header names
 * (XSTILLHEART=method:NAME, written by `stillheart warp` and `run`; with --cameras
 * method3d:NAME[/NAME], written by `stillheart warp3d`); given both, they must agree.
 * 0, or 2 with the refusal printed. */
static int resolve_method(options *o, const char *path, const sh_y4m_header *h)
{
    char tag[SH_Y4M_MAX_EXTRA];
    int tagged = sh_y4m_header_tag(h, SH_Y4M_STILLHEART, tag, sizeof tag);
    /* 2D: method:NAME (stillheart warp, run); 3D: method3d:NAME or method3d:SURFACE/DISPLACEMENT */
    const char *kind = o->calib_path ? "method3d:" : "method:";
    const char *named = tagged && !strncmp(tag, kind, strlen(kind)) ? tag + strlen(kind) : NULL;
    if (tagged && !named) {
        if (!o->truth_dir) return 0; /* e does not depend on the method */
        sh_log_error("%s: its header says %s=%s, not %sNAME; --truth measures the map of %s", path,
                     SH_Y4M_STILLHEART, tag, kind,
                     o->calib_path ? "`stillheart warp3d` (with --cameras)" : "`stillheart warp` (without --cameras)");
        return 2;
    }
    sh_interp_params s3, d3;
    if (named && strcmp(named, "none") &&
        (o->calib_path ? parse_method3d(named, &s3, &d3) != SH_OK : !known_method(named))) {
        sh_log_error("%s: its header names the method '%s', which this stillheart-eval does not know",
                     path, named);
        return 2;
    }
    if (o->method && named && strcmp(o->method, named)) {
        sh_log_error("--method %s, but %s was stabilized with %s (its header: %s=%s); give the "
                     "method it was made with, or none for an unstabilized video", o->method, path,
                     named, SH_Y4M_STILLHEART, tag);
        return 2;
    }
    if (!o->method && named) {
        snprintf(o->tagged_method, sizeof o->tagged_method, "%s", named);
        o->method = o->tagged_method;
        if (o->truth_dir) sh_log_info("method %s, as %s's header says", o->method, path);
    }
    if (!o->method && o->truth_dir) {
        sh_log_error("--truth: %s does not say which method stabilized it (no %s tag); give "
                     "--method (none for an unstabilized video)", path, SH_Y4M_STILLHEART);
        return 2;
    }
    return 0;
}

/* The interpolant exactly as `stillheart warp` configures it from the same options: 0, or 2
 * with the refusal printed. */
static int geo_method(options *o)
{
    o->geo.camera = o->camera;
    o->geo.reference = o->reference;
    o->geo.stride = o->stride;
    o->geo.identity = !strcmp(o->method, "none");
    if (!o->geo.identity && o->calib_path) {
        o->geo.calib = &o->calib;
        sh_warp3d_params_default(&o->geo.p3);
        if (parse_method3d(o->method, &o->geo.p3.surface, &o->geo.p3.displacement) != SH_OK) return 1 + fail("--method");
        if (o->have_sigma) o->geo.p3.surface.sigma = o->geo.p3.displacement.sigma = o->sigma;
        sh_warp3d_view_options_default(&o->geo.vopts);
        o->geo.vopts.warp.max_error = o->max_error;
        /* the 2D parameters name the surface's method (the landmark rows' test) */
        o->geo.params = o->geo.p3.surface;
        o->geo.landmark_smoothing = o->landmark_smoothing;
    } else if (!o->geo.identity) {
        if (sh_interp_params_parse(o->method, &o->geo.params) != SH_OK) return 1 + fail("--method");
        if (o->have_sigma) o->geo.params.sigma = o->sigma;
        o->geo.params.levels = o->levels;
        o->geo.params.smoothing = o->smoothing;
        o->geo.landmark_smoothing = o->landmark_smoothing;
    }
    sh_warp_options_default(&o->geo.wopts);
    o->geo.wopts.max_error = o->max_error;
    return 0;
}

/* --landmarks: the landmarks over the original video, judged against the truth. */
static int landmarks(options *o, const char *video_path)
{
    eval_lm_options lo = {0};
    if (sh_interp_params_parse(o->method ? o->method : "tps", &lo.params) != SH_OK) return 1 + fail("--method");
    if (o->have_sigma) lo.params.sigma = o->sigma;
    lo.params.levels = o->levels;
    lo.params.smoothing = o->smoothing;
    lo.landmark_smoothing = o->landmark_smoothing;
    lo.lp = o->lp;
    lo.camera = o->camera;
    lo.reference = o->reference;
    lo.keep_rows = o->landmarks_points != NULL;
    sh_points points;
    phantom_truth *truth = NULL;
    if (sh_points_read(o->points_path, &points) != SH_OK) return fail("--points");
    int rc = 1;
    eval_lm_result r;
    if (phantom_truth_open(o->truth_dir, &truth) != SH_OK) {
        fail("--truth");
        goto done;
    }
    lo.truth = truth;
    if (eval_landmarks_run(&lo, &points, video_path, &r) != SH_OK) {
        fail(video_path);
        goto done;
    }
    if (o->landmarks_points) {
        FILE *out = fopen(o->landmarks_points, "w");
        sh_status st = !out ? sh_error_set(SH_EIO, "cannot create: %s", strerror(errno))
                            : eval_landmarks_write_points(&points, &r, out);
        if (out && fclose(out) != 0 && st == SH_OK) st = sh_error_set(SH_EIO, "write failed");
        free(r.rows);
        if (st != SH_OK) {
            fail(o->landmarks_points);
            goto done;
        }
    }
    eval_landmarks_print(&r, video_path, o->reference, o->method ? o->method : "tps", o->json);
    rc = fflush(stdout) == 0 ? 0 : 1;
done:
    phantom_truth_close(truth);
    sh_points_destroy(&points);
    return rc;
}

/* The measurement itself, once the options are known. */
/* Reads both videos frame by frame, feeding the metrics and the geometric error; 0, or -1 after
 * saying why (a read error, or videos of different lengths or too short for the reference). */
static int compare_frames(const options *o, video *stab, video *orig, const char *stab_path, const char *orig_path,
                          eval_geo *geo, const sh_hull *hull)
{
    sh_cli_progress bar;
    long long total = sh_y4m_reader_whole_frames(stab->reader);
    sh_cli_progress_start(&bar, "eval", total < 0 || total > 1 << 30 ? 0 : (int)total, "frames");
    int t = 0;
    sh_status st;
    while ((st = video_next(stab, hull, t)) == SH_OK) {
        if (orig_path) {
            sh_status so = video_next(orig, hull, t);
            if (so == SH_EEOF) {
                sh_cli_progress_end(&bar);
                sh_log_error("%s has %d frames, %s more", orig_path, t, stab_path);
                return -1;
            }
            if (so != SH_OK) { fail("original video"); return -1; }
        }
        if (geo && eval_geo_frame(geo, t) != SH_OK) { fail("geometric error"); return -1; }
        t++;
        sh_cli_progress_update(&bar, t);
    }
    sh_cli_progress_end(&bar);
    if (st != SH_EEOF) { fail("stabilized video"); return -1; }
    if (orig_path && video_next(orig, hull, t) != SH_EEOF) {
        sh_log_error("%s has more frames than %s (%d)", orig_path, stab_path, t);
        return -1;
    }
    if (t <= o->reference) {
        sh_log_error("%s has no frame %d", stab_path, o->reference);
        return -1;
    }
    return 0;
}

/* --heatmap: the stabilized video's per-pixel error as an image; 0, or -1 after saying why. */
static int write_heatmap(const options *o, const video *stab)
{
    const sh_image *f = &stab->frame;
    float *grey = malloc(sizeof(float) * (size_t)f->width * f->height);
    if (!grey) { fail("out of memory"); return -1; }
    int rc = 0;
    if (sh_metric_error_image(stab->metric, grey) != SH_OK ||
        eval_heatmap_write(o->heatmap, grey, f->width, f->height, o->heatmap_max,
                           o->contours, o->heatmap_scale) != SH_OK) {
        fail("--heatmap");
        rc = -1;
    }
    free(grey);
    return rc;
}

static int evaluate(options *o, const char *stab_path, const char *orig_path)
{
    int rc = 1;
    sh_points points = {0};
    video stab = {0}, orig = {0};
    phantom_truth *truth = NULL;
    eval_geo *geo = NULL;
    double *xy = NULL;
    sh_hull hull;

    if (sh_points_read(o->points_path, &points) != SH_OK ||
        sh_points_need_2d(&points, o->points_path) != SH_OK)
        return fail("points");
    int nref;
    const sh_point *ref = sh_points_frame(&points, o->reference, &nref);
    if (nref < 3) {
        sh_log_error("%s: the reference frame %d has %d markers, need 3",
                     o->points_path, o->reference, nref);
        goto done;
    }
    xy = malloc(sizeof(double) * 2 * (size_t)nref);
    if (!xy) { fail("out of memory"); goto done; }
    for (int i = 0; i < nref; i++) xy[2 * i] = ref[i].x, xy[2 * i + 1] = ref[i].y;
    if (sh_hull_compute(xy, nref, &hull) != SH_OK) {
        sh_log_error("%s: frame %d's markers: %s", o->points_path, o->reference,
                     sh_error_message());
        goto done;
    }
    if (video_open(&stab, stab_path, o->reference, &hull) != SH_OK) { fail("stabilized video"); goto done; }
    if ((rc = resolve_method(o, stab_path, sh_y4m_reader_header(stab.reader))) ||
        (o->truth_dir && (rc = geo_method(o))))
        goto done;
    rc = 1;
    const sh_image *f = &stab.frame;
    if (orig_path) {
        if (video_open(&orig, orig_path, o->reference, &hull) != SH_OK) { fail("original video"); goto done; }
        if (orig.frame.width != f->width || orig.frame.height != f->height) {
            sh_log_error("%s is %dx%d, %s is %dx%d", orig_path, orig.frame.width,
                         orig.frame.height, stab_path, f->width, f->height);
            goto done;
        }
    }
    if (o->truth_dir) {
        if (phantom_truth_open(o->truth_dir, &truth) != SH_OK) { fail("--truth"); goto done; }
        o->geo.truth = truth;
        /* the map the warp used: without landmark rows for a method that leaves them out (the
         * hull stays the markers': landmarks are chosen inside it) */
        if (!o->geo.identity && (!sh_landmarks_method_uses(o->geo.params.method) ||
                                 (o->geo.calib && !sh_landmarks_method_uses(o->geo.p3.displacement.method))))
            sh_points_drop_ids(&points, SH_LANDMARK_ID_BASE);
        if (eval_geo_create(&o->geo, &points, &hull, f->width, f->height, &geo) != SH_OK) {
            sh_log_error("%s: %s", o->truth_dir, sh_error_message());
            goto done;
        }
    }

    if (compare_frames(o, &stab, &orig, stab_path, orig_path, geo, &hull) != 0) goto done;

    if (o->heatmap && write_heatmap(o, &stab) != 0) goto done;
    eval_geo_result g = {0};
    if (geo) eval_geo_result_get(geo, &g);
    report(o, &stab, &orig, geo, &g);
    rc = fflush(stdout) == 0 ? 0 : 1;
done:
    eval_geo_destroy(geo);
    phantom_truth_close(truth);
    video_close(&stab);
    video_close(&orig);
    sh_points_destroy(&points);
    free(xy);
    return rc;
}

int main(int argc, char **argv)
{
    sh_log_setup(SH_LOG_TOOL, PROG, SH_LOG_INFO);
    static const struct option long_opts[] = {
        {"points", required_argument, 0, 'p'},   {"reference", required_argument, 0, 'r'},
        {"truth", required_argument, 0, 'T'},    {"camera", required_argument, 0, 'c'},
        {"method", required_argument, 0, 'm'},   {"sigma", required_argument, 0, 's'},
        {"levels", required_argument, 0, 'l'},   {"smoothing", required_argument, 0, 'S'},
        {"max-error", required_argument, 0, 'e'}, {"geo-stride", required_argument, 0, 'g'},
        {"heatmap", required_argument, 0, 'H'},  {"heatmap-max", required_argument, 0, 'X'},
        {"contours", required_argument, 0, 'C'}, {"export-points", required_argument, 0, 'E'},
        {"heatmap-scale", required_argument, 0, 'Z'},
        {"landmarks", required_argument, 0, 'L'}, {"lm-photometric", required_argument, 0, 1001},
        {"lm-backward", required_argument, 0, 1002}, {"lm-disagreement", required_argument, 0, 1003},
        {"lm-sparse", no_argument, 0, 1004}, {"lm-bound-factor", required_argument, 0, 1005},
        {"lm-plane", no_argument, 0, 1006}, {"lm-square", no_argument, 0, 1009},
        {"landmarks-points", required_argument, 0, 1007},
        {"spectrum", no_argument, 0, 1008}, {"cameras", required_argument, 0, 1010},
        {"landmark-rows", no_argument, 0, 1011}, {"lm-distance", required_argument, 0, 1012},
        {"lm-quality", required_argument, 0, 1013}, {"landmark-smoothing", required_argument, 0, 1014},
        {"lm-jump", required_argument, 0, 1015}, {"lm-reduce", required_argument, 0, 1016},
        {"lm-correlation", required_argument, 0, 1017}, {"lm-refine", required_argument, 0, 1018},
        {"lm-relative", required_argument, 0, 1019}, {"lm-confirm", required_argument, 0, 1020},
        {"lm-balance", required_argument, 0, 1021},
        {"json", no_argument, 0, 'j'},           SH_CLI_OPTIONS, {0, 0, 0, 0}};
    options o = {.stride = 4, .heatmap_max = 0.2, .heatmap_scale = 1, .contours = 4, .max_error = 0.05,
                 .landmark_smoothing = SH_LANDMARK_SMOOTHING};
    sh_landmarks_params_default(&o.lp);
    int opt;
    opterr = 0;
    while ((opt = getopt_long(argc, argv, ":h", long_opts, NULL)) != -1) {
        switch (opt) {
        case 'p': o.points_path = optarg; break;
        case 'r': if (!sh_cli_parse_int("--reference", optarg, 0, SH_POINTS_MAX_FRAME, &o.reference)) return 2; break;
        case 'T': o.truth_dir = optarg; break;
        case 1010: o.calib_path = optarg; break;
        case 1011: o.landmark_rows = 1; break;
        case 'c': if (!sh_cli_parse_int("--camera", optarg, 0, PHANTOM_MAX_CAMERAS - 1, &o.camera)) return 2; break;
        case 'm': o.method = optarg; break;
        case 's': if (!sh_cli_parse_double("--sigma", optarg, 1e-6, 1e9, &o.sigma)) return 2;
                  o.have_sigma = 1; break;
        case 'l': if (!sh_cli_parse_int("--levels", optarg, 1, 20, &o.levels)) return 2; break;
        case 'S': if (!sh_cli_parse_double("--smoothing", optarg, 0, 1e12, &o.smoothing)) return 2; break;
        case 'e': if (!sh_cli_parse_double("--max-error", optarg, 1e-4, 100, &o.max_error)) return 2; break;
        case 'g': if (!sh_cli_parse_int("--geo-stride", optarg, 1, 4096, &o.stride)) return 2; break;
        case 'H': o.heatmap = optarg; break;
        case 'X': if (!sh_cli_parse_double("--heatmap-max", optarg, 1e-6, 1, &o.heatmap_max)) return 2; break;
        case 'Z': if (!sh_cli_parse_double("--heatmap-scale", optarg, 1.0 / 64, 8, &o.heatmap_scale)) return 2; break;
        case 'C': if (!sh_cli_parse_int("--contours", optarg, 0, 32, &o.contours)) return 2; break;
        case 'E': o.export_out = optarg; break;
        case 'j': o.json = 1; break;
        case 'L': if (!sh_cli_parse_int("--landmarks", optarg, 1, 100000, &o.landmarks)) return 2;
                  o.lp.max_points = o.landmarks; break;
        case 1001: if (!sh_cli_parse_double("--lm-photometric", optarg, 1e-3, 255, &o.lp.max_photometric)) return 2; break;
        case 1002: if (!sh_cli_parse_double("--lm-backward", optarg, 0, 1000, &o.lp.max_backward_px)) return 2; break;
        case 1003: if (!sh_cli_parse_double("--lm-disagreement", optarg, 1e-3, 1000, &o.lp.max_disagreement_px)) return 2; break;
        case 1004: sh_landmarks_params_make_sparse(&o.lp); break; /* over the options given before */
        case 1005: if (!sh_cli_parse_double("--lm-bound-factor", optarg, 0, 1000, &o.lp.bound_factor)) return 2; break;
        case 1006: o.lp.plane = 1; break;
        case 1009: o.lp.affine = 0; break;
        case 1012: if (!sh_cli_parse_double("--lm-distance", optarg, 1, 1000, &o.lp.min_distance)) return 2; break;
        case 1013: if (!sh_cli_parse_double("--lm-quality", optarg, 1e-6, 1, &o.lp.quality)) return 2; break;
        case 1014: if (!sh_cli_parse_double("--landmark-smoothing", optarg, 0, 1e12, &o.landmark_smoothing)) return 2; break;
        case 1015: if (!sh_cli_parse_double("--lm-jump", optarg, 0, 1000, &o.lp.max_jump)) return 2;
                   if (o.lp.max_jump > 0 && o.lp.max_jump < 1) return sh_cli_usage_error(&cli, "--lm-jump: 0 (no test) or 1 to 1000");
                   break;
        case 1016: if (!sh_cli_parse_int("--lm-reduce", optarg, 0, 4, &o.lp.reduce)) return 2; break;
        case 1017: if (!sh_cli_parse_double("--lm-correlation", optarg, 0, 0.999, &o.lp.min_correlation)) return 2; break;
        case 1018: if (!sh_cli_parse_int("--lm-refine", optarg, 0, 1000, &o.lp.refine)) return 2; break;
        case 1020: if (!sh_cli_parse_int("--lm-confirm", optarg, 1, 1000, &o.lp.confirm)) return 2; break;
        case 1021: if (!sh_cli_parse_int("--lm-balance", optarg, 0, 4096, &o.lp.balance_cell)) return 2;
                   if (o.lp.balance_cell && !(o.lp.balance_floor > 0)) { /* the sparse tests' floor */
                       sh_landmarks_params sparse;
                       sh_landmarks_params_sparse(&sparse);
                       o.lp.balance_floor = sparse.balance_floor;
                   }
                   break;
        case 1019: if (!sh_cli_parse_double("--lm-relative", optarg, 0, 1000, &o.lp.max_relative)) return 2;
                   if (o.lp.max_relative > 0 && o.lp.max_relative < 1) return sh_cli_usage_error(&cli, "--lm-relative: 0 (no test) or 1 to 1000");
                   break;
        case 1007: o.landmarks_points = optarg; break;
        case 1008: o.spectrum = 1; break;
        case 'h': usage(stdout); return 0;
        default: { int rc = sh_cli_option(&cli, opt, argv); if (rc >= 0) return rc; } break;
        }
    }

    if (o.export_out) {
        if (!o.truth_dir || optind != argc) {
            return sh_cli_usage_error(&cli, "--export-points needs --truth DIR and no videos");
        }
        int to_stdout = !strcmp(o.export_out, "-");
        FILE *out = to_stdout ? stdout : fopen(o.export_out, "w");
        if (!out) {
            sh_log_error("%s: cannot create: %s", o.export_out, strerror(errno));
            return 1;
        }
        sh_status st = eval_export_points(o.truth_dir, o.camera, out, o.export_out);
        if (!to_stdout && fclose(out) != 0 && st == SH_OK)
            st = sh_error_set(SH_EIO, "%s: write failed", o.export_out);
        return st == SH_OK ? 0 : fail("--export-points");
    }
    if (o.spectrum) {
        if (!o.truth_dir || argc - optind != 1) return sh_cli_usage_error(&cli, "--spectrum needs --truth DIR and one video");
        return eval_spectrum_main(o.truth_dir, o.camera, o.json, argv[optind]);
    }
    if (o.landmark_rows) {
        if (!o.truth_dir || !o.points_path || optind != argc)
            return sh_cli_usage_error(&cli, "--landmark-rows needs --truth DIR and --points, and no video");
        if (o.calib_path && sh_calib_read(o.calib_path, &o.calib) != SH_OK) return fail("--cameras");
        return eval_rows_main(o.truth_dir, o.points_path, o.calib_path ? &o.calib : NULL, o.camera, o.reference, o.json);
    }
    if (o.landmarks_points && !o.landmarks) return sh_cli_usage_error(&cli, "--landmarks-points needs --landmarks N");
    if (o.landmarks) {
        if (!o.truth_dir || !o.points_path || argc - optind != 1)
            return sh_cli_usage_error(&cli, "--landmarks needs --truth DIR, --points and the original video");
        return landmarks(&o, argv[optind]);
    }
    if (!o.points_path || argc - optind < 1 || argc - optind > 2)
        return sh_cli_usage_error(&cli, "need --points and the stabilized video (and optionally the original)");
    sh_interp_params named, named3;
    if (o.method && strcmp(o.method, "none") &&
        (o.calib_path ? parse_method3d(o.method, &named, &named3) : sh_interp_params_parse(o.method, &named)) != SH_OK)
        return 1 + fail("--method"); /* a usage error, exit 2, as in warp and warp3d */
    if (o.calib_path && !o.truth_dir) return sh_cli_usage_error(&cli, "--cameras goes with --truth");
    if (o.calib_path && sh_calib_read(o.calib_path, &o.calib) != SH_OK) return fail("--cameras");
    return evaluate(&o, argv[optind], argc - optind == 2 ? argv[optind + 1] : NULL);
}
