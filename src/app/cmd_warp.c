/* stillheart warp: offline 2D stabilization of a Y4M video from a points file. */
#include <getopt.h>
#include <stdlib.h>
#include <string.h>

#include "stab.h"
#include "stillheart/landmarks.h"
#include "stillheart/log.h"

#define CACHE_SLOTS 8

static const sh_cli cli = {"stillheart warp"};

static void usage(FILE *out)
{
    fprintf(out,
        "usage: stillheart warp --points P.csv [OPTIONS] IN.y4m OUT.y4m\n\n"
        "Warps every frame of IN back onto the reference frame (paper Algorithm 1) and writes\n"
        "OUT in the same size and format. The map interpolates the markers of each frame that\n"
        "also appear in the reference frame; pixels outside the convex hull of the reference\n"
        "markers, or whose source lies outside the frame, are black. A frame with too few\n"
        "markers for the method is written unchanged and counted. OUT's header names the method\n"
        "(XSTILLHEART=method:NAME), which stillheart-eval reads; stillheart-eval also measures\n"
        "the paper's metric e (section V) of OUT and IN.\n\n"
        "options:\n"
        "  --points FILE      marker positions, CSV 'frame,id,x,y' (required); rows with ids\n"
        "                     from 1000000 are the tissue's landmarks (stillheart track\n"
        "                     --landmarks), left out for gaussian and rbf-local\n"
        "  --method NAME      affine | pwlinear | bspline | rbf-local | tps | gaussian\n"
        "                     (RBFs with the affine term; add -pure for the form without it,\n"
        "                     e.g. tps-pure). Default: tps, the least geometric error on the\n"
        "                     rendered phantoms (docs/warp.md)\n"
        "  --sigma S          RBF scale in pixels (default 95 for rbf-local, 100 for gaussian)\n"
        "  --levels L         B-spline levels (default: as many as exact interpolation needs;\n"
        "                     fewer approximate)\n"
        "  --smoothing LAMBDA RBF approximation instead of interpolation (default 0 = exact)\n"
        "  --landmark-smoothing LAMBDA\n"
        "                     with tps (the RBFs): the landmark rows' own smoothing, added to\n"
        "                     their diagonal of the system; the markers stay exact (default\n"
        "                     1000, as the daemon's [track] landmarks_smoothing; 0: the\n"
        "                     landmarks interpolated as well); for 1080p frames: a frame whose\n"
        "                     landmarks were found halved (4K: docs/landmarks.md) uses 4 times\n"
        "                     it. stillheart-eval needs the same value (its\n"
        "                     --landmark-smoothing). Another method refuses it\n"
        "  --reference N      0-based index of the reference frame (default 0)\n"
        "  --threads T        worker threads for the warp (default 1)\n"
        "  --max-error PX     largest tolerated error of the interpolated map (default 0.05)\n"
        "  --map-out FILE     write the last frame's map as .npy float32 H x W x 2\n"
        "                     (x, y in the current frame; NaN outside the hull)\n"
        "  --metric           also measure e of the input and the output and print it at the\n"
        "                     end (off by default: it converts every frame to RGB and costs\n"
        "                     several times the warp; stillheart-eval gives the same figures)\n"
        SH_CLI_USAGE
        "IN or OUT may be '-' for standard input / output (IN only with --reference 0; with\n"
        "OUT '-' the e figures of --metric go to standard error).\n");
}

/* The model for the set of ids (sorted), built on a miss and kept (modelcache.h), so a marker
 * that comes and goes costs one rebuild per distinct set, not one per frame. */
static sh_status cache_get(sh_modelcache *c, const int *ids, int n, sh_warp_model **out)
{
    sh_modelcache_entry *e;
    sh_status st = sh_modelcache_get(c, ids, n, &e);
    if (st == SH_OK) *out = e->model;
    return st;
}

/* e for the input against the reference frame, and for the output against the reference frame
 * warped by the model of all reference markers (ref_xy: their positions there). */
static int start_metrics(sh_warp_model *model, const double *ref_xy, sh_warp *warp,
                         const sh_image *ref, sh_image *scratch, int full_range,
                         sh_metric **in, sh_metric **out)
{
    return sh_warp_model_update(model, ref_xy) == SH_OK &&
           sh_warp_apply(warp, model, ref, scratch) == SH_OK &&
           sh_metric_create(ref, sh_warp_model_hull(model), full_range, in) == SH_OK &&
           sh_metric_create(scratch, sh_warp_model_hull(model), full_range, out) == SH_OK;
}

/* What the command line asks for; filled by parse_options only (the options/runtime split of
 * ustreamer: warp_job below holds what the run opens and counts). */
typedef struct {
    const char *points_path, *method, *map_out, *in_path, *out_path;
    sh_interp_params params; /* --method with --sigma, --levels and --smoothing applied */
    double max_error;
    double landmark_smoothing; /* --landmark-smoothing */
    int reference, threads, quiet;
    /* The paper's e is over R, G and B (section V): a Y'CbCr frame must be converted pixel by
     * pixel, since |dR| + |dG| + |dB| is no function of the planes' own differences, so it cannot
     * be computed exactly in the frame's planes. Over the hull only it still costs several times
     * the warp (issue 20: 77 % of the run at 1080p 4:4:4), so it is asked for, not paid for by
     * every run; stillheart-eval measures it anyway. */
    int metric;
} warp_options;

/* Fills o from argv: APP_GO_ON, or the exit code (usage and refusals printed). */
static int parse_options(int argc, char **argv, warp_options *o)
{
    static const struct option options[] = {
        {"points", required_argument, 0, 'p'}, {"method", required_argument, 0, 'm'},
        {"sigma", required_argument, 0, 's'},  {"levels", required_argument, 0, 'l'},
        {"smoothing", required_argument, 0, 'S'}, {"reference", required_argument, 0, 'r'},
        {"threads", required_argument, 0, 't'}, {"max-error", required_argument, 0, 'e'},
        {"map-out", required_argument, 0, 'M'}, {"metric", no_argument, 0, 'E'},
        {"landmark-smoothing", required_argument, 0, 'L'}, SH_CLI_OPTIONS, {0, 0, 0, 0}};
    memset(o, 0, sizeof *o);
    o->method = "tps";
    o->max_error = 0.05;
    o->landmark_smoothing = SH_LANDMARK_SMOOTHING;
    o->threads = 1;
    double sigma = 0, smoothing = 0;
    int levels = 0, have_sigma = 0, have_lm_smoothing = 0, opt;
    optind = 1;
    opterr = 0;
    while ((opt = getopt_long(argc, argv, ":h", options, NULL)) != -1) {
        switch (opt) {
        case 'p': o->points_path = optarg; break;
        case 'm': o->method = optarg; break;
        case 's': if (!sh_cli_parse_double("--sigma", optarg, 1e-6, 1e9, &sigma)) return 2;
                  have_sigma = 1; break;
        case 'l': if (!sh_cli_parse_int("--levels", optarg, 1, 20, &levels)) return 2; break;
        case 'S': if (!sh_cli_parse_double("--smoothing", optarg, 0, 1e12, &smoothing)) return 2; break;
        case 'r': if (!sh_cli_parse_int("--reference", optarg, 0, 1 << 30, &o->reference)) return 2; break;
        case 't': if (!sh_cli_parse_int("--threads", optarg, 1, 256, &o->threads)) return 2; break;
        case 'e': if (!sh_cli_parse_double("--max-error", optarg, 1e-4, 100, &o->max_error)) return 2; break;
        case 'M': o->map_out = optarg; break;
        case 'L': if (!sh_cli_parse_double("--landmark-smoothing", optarg, 0, 1e12, &o->landmark_smoothing)) return 2;
                  have_lm_smoothing = 1; break;
        case 'E': o->metric = 1; break;
        case 'h': usage(stdout); return 0;
        default: { int rc = sh_cli_option(&cli, opt, argv); if (rc >= 0) return rc; } break;
        }
    }
    o->quiet = sh_log_get_level() < SH_LOG_INFO;
    if (argc - optind != 2 || !o->points_path)
        return sh_cli_usage_error(&cli, "need --points and the input and output videos");
    o->in_path = argv[optind];
    o->out_path = argv[optind + 1];
    if (o->reference > 0 && !strcmp(o->in_path, "-")) {
        sh_log_error("--reference %d needs a file, not standard input",
                     o->reference);
        return 2;
    }
    /* an unknown method is a usage error, exit 2, as in warp3d and stillheart-eval */
    if (sh_interp_params_parse(o->method, &o->params) != SH_OK) return 1 + app_fail("--method");
    if (have_sigma) o->params.sigma = sigma;
    o->params.levels = levels;
    o->params.smoothing = smoothing;
    /* a smoothing the method has no use for does nothing: refused, as --smoothing is */
    if (have_lm_smoothing && !(sh_interp_method_smooths(o->params.method) && sh_landmarks_method_uses(o->params.method)))
        return sh_cli_usage_error(&cli, "--landmark-smoothing: %s %s the landmarks (a tps map approximates them)",
                                  o->method, sh_landmarks_method_uses(o->params.method) ? "interpolates" : "leaves out");
    return APP_GO_ON;
}

/* What one run opens and counts, from warp_open to warp_close. */
typedef struct {
    const warp_options *o;
    app_stab s;
    sh_modelcache_recipe recipe;
    sh_warp_model *model, *last_model; /* the current frame's; the last one that warped */
} warp_job;

/* The points, the input, the reference frame's markers and the model cache over them: 0, or 1
 * with the reason printed. */
static int open_input(warp_job *j)
{
    const warp_options *o = j->o;
    app_stab *s = &j->s;
    if (sh_points_read(o->points_path, &s->points) != SH_OK ||
        sh_points_need_2d(&s->points, o->points_path) != SH_OK)
        return app_fail("points");
    if (!sh_landmarks_method_uses(o->params.method)) {
        int n = sh_points_drop_ids(&s->points, SH_LANDMARK_ID_BASE);
        if (n) sh_log_info("%d landmark rows left out: %s is worse with them (docs/landmarks.md)", n, o->method);
    }
    if (sh_y4m_reader_open(o->in_path, &s->reader) != SH_OK) return app_fail("input");
    const sh_y4m_header *hdr = sh_y4m_reader_header(s->reader);
    j->recipe.width = hdr->width;
    j->recipe.height = hdr->height;
    /* --landmark-smoothing is given at 1080p: scaled to the frame as `stillheart track` scaled the
     * landmarks' lengths (sh_landmarks_smoothing) */
    j->recipe.point_smoothing = sh_landmarks_smoothing(o->landmark_smoothing,
                                                       sh_landmarks_reduction(NULL, hdr->width, hdr->height));
    s->ref_rows = sh_points_frame(&s->points, o->reference, &s->ref_count);
    if (s->ref_count < 3) {
        sh_log_error("%s: the reference frame %d has %d markers, need 3", o->points_path, o->reference, s->ref_count);
        return 1;
    }
    s->ids = malloc(sizeof(int) * (size_t)s->ref_count);
    s->cur = malloc(sizeof(double) * 2 * (size_t)s->ref_count);
    if (!s->ids || !s->cur) return app_fail("out of memory");
    if (sh_modelcache_create(&j->recipe, s->ref_rows, s->ref_count, CACHE_SLOTS, &s->cache) != SH_OK)
        return app_fail("models");
    return 0;
}

/* Everything the frame loop needs: 0, or 1 with the reason printed (warp_close frees either
 * way). */
static int warp_open(warp_job *j, const warp_options *o)
{
    memset(j, 0, sizeof *j);
    j->o = o;
    app_stab *s = &j->s;
    j->recipe.params = o->params;
    sh_warp_options_default(&j->recipe.wopts);
    j->recipe.wopts.max_error = o->max_error;
    j->recipe.smoothed_from = SH_LANDMARK_ID_BASE;
    if (open_input(j)) return 1;
    const sh_y4m_header *hdr = sh_y4m_reader_header(s->reader);
    if (sh_image_create(&s->in, hdr->format, hdr->width, hdr->height) != SH_OK ||
        sh_image_create(&s->out, hdr->format, hdr->width, hdr->height) != SH_OK ||
        (o->metric && sh_image_create(&s->ref, hdr->format, hdr->width, hdr->height) != SH_OK))
        return app_fail("frame buffers");
    if (sh_warp_create(o->threads, &s->warp) != SH_OK) return app_fail("threads");

    /* The reference model (all reference markers) and, with --metric, both metrics' reference
     * frames. */
    s->from_stdin = !strcmp(o->in_path, "-");
    /* From standard input (reference 0 only) the reference frame is the first one read below. */
    if (o->metric && !s->from_stdin && !app_read_frame_at(o->in_path, o->reference, &s->ref))
        return app_fail("reference frame");
    int nref = sh_points_match(s->ref_rows, s->ref_count, s->ref_rows, s->ref_count, s->ids, NULL, s->cur);
    if (cache_get(s->cache, s->ids, nref, &j->model) != SH_OK) return app_fail("reference markers");
    s->full_range = sh_y4m_header_full_range(hdr);
    if (o->metric && !s->from_stdin &&
        !start_metrics(j->model, s->cur, s->warp, &s->ref, &s->out, s->full_range, &s->metric_in,
                       &s->metric_out))
        return app_fail("reference frame");
    sh_y4m_header out_hdr = *hdr;
    if (app_stab_tag(&out_hdr, "method", &o->params, NULL)) return 1;
    return app_stab_start(s, "warp", o->out_path, &out_hdr);
}

/* Warps, writes and (--metric) measures the frame just read into s.in (job: the warp_job): 0,
 * or 1 with the reason printed. */
static int warp_frame(void *job)
{
    warp_job *j = job;
    app_stab *s = &j->s;
    /* --metric from standard input (reference 0): the reference frame is this one */
    if (j->o->metric && s->frames == j->o->reference && !s->metric_in) {
        sh_image_copy(&s->ref, &s->in);
        if (!start_metrics(j->model, s->cur, s->warp, &s->ref, &s->out, s->full_range, &s->metric_in,
                           &s->metric_out))
            return app_fail("reference frame");
    }
    int ncur;
    const sh_point *cur = sh_points_frame(&s->points, s->frames, &ncur);
    int n = sh_points_match(s->ref_rows, s->ref_count, cur, ncur, s->ids, NULL, s->cur);
    double t0 = app_now();
    const sh_image *shown = &s->out;
    if (n < 3 || cache_get(s->cache, s->ids, n, &j->model) != SH_OK ||
        sh_warp_update(s->warp, j->model, s->cur, NULL) != SH_OK ||
        sh_warp_apply(s->warp, j->model, &s->in, &s->out) != SH_OK) {
        shown = &s->in; /* nothing trustworthy to warp with: pass the frame through, counted */
        app_stab_raw(s, "warp", n, 3, j->o->quiet);
    } else {
        j->last_model = j->model;
    }
    s->warp_seconds += app_now() - t0;
    sh_log_debug("frame %d: %d of the reference frame's %d markers, %s", s->frames, n, s->ref_count,
                 shown == &s->in ? "written unstabilized" : "warped");
    if (sh_y4m_writer_write(s->writer, shown) != SH_OK) return app_fail("output");
    if (s->metric_in && (sh_metric_add(s->metric_in, &s->in) != SH_OK ||
                         sh_metric_add(s->metric_out, shown) != SH_OK))
        return app_fail("metric");
    s->frames++;
    sh_cli_progress_update(&s->progress, s->frames);
    return 0;
}

/* --map-out: the last stabilized frame's map: 0, or 1 with the reason printed. */
static int write_map(const warp_job *j, const char *path)
{
    if (!j->last_model) {
        sh_log_error("--map-out: no frame was stabilized");
        return 1;
    }
    float *map = malloc(sizeof(float) * 2 * (size_t)j->recipe.width * j->recipe.height);
    int rc = !map || sh_warp_model_map(j->last_model, map) != SH_OK
                 ? app_fail("map")
                 : !app_write_npy(path, map, j->recipe.height, j->recipe.width, 2);
    free(map);
    return rc;
}

/* The summary on stderr. */
static void report(const warp_job *j)
{
    const app_stab *s = &j->s;
    fprintf(stderr, "method %s: %d frames (%d unstabilized), %d marker sets built in %.1f ms, "
                    "warp %.2f ms/frame\n",
            j->o->method, s->frames, s->raw_frames, sh_modelcache_builds(s->cache),
            sh_modelcache_build_seconds(s->cache) * 1e3,
            s->frames ? s->warp_seconds * 1e3 / s->frames : 0.0);
    if (j->last_model && sh_warp_model_grid_spacing(j->last_model))
        fprintf(stderr, "grid spacing %d px, map error bound %.4f px\n",
                sh_warp_model_grid_spacing(j->last_model), sh_warp_model_error_bound(j->last_model));
}

int cmd_warp(int argc, char **argv)
{
    sh_log_setup(SH_LOG_TOOL, "stillheart warp", SH_LOG_INFO);
    warp_options o;
    int rc = parse_options(argc, argv, &o);
    if (rc != APP_GO_ON) return rc;
    warp_job j;
    sh_status st;
    rc = 1;
    if (warp_open(&j, &o) || app_stab_run(&j.s, warp_frame, &j, &st)) goto done;
    if (o.map_out && write_map(&j, o.map_out)) goto done;
    if (!o.quiet) report(&j);
    /* asked for by name: printed with --quiet too (which quiets the log, not the results) */
    if (o.metric) app_stab_print_e(&j.s, o.out_path);
    rc = st == SH_EEOF ? 0 : 1;
done:
    app_stab_close(&j.s);
    return rc;
}
