/* stillheart warp: offline 2D stabilization of a Y4M video from a points file. */
#include <getopt.h>
#include <stdlib.h>
#include <string.h>

#include "app.h"
#include "stillheart/log.h"
#include "stillheart/metrics.h"
#include "stillheart/modelcache.h"
#include "stillheart/points.h"
#include "stillheart/warp.h"
#include "stillheart/y4m.h"

#define CACHE_SLOTS 8

static void usage(FILE *out)
{
    fprintf(out,
        "usage: stillheart warp --points P.csv [OPTIONS] IN.y4m OUT.y4m\n\n"
        "Warps every frame of IN back onto the reference frame (paper Algorithm 1) and writes\n"
        "OUT in the same size and format. The map interpolates the markers of each frame that\n"
        "also appear in the reference frame; pixels outside the convex hull of the reference\n"
        "markers, or whose source lies outside the frame, are black. A frame with too few\n"
        "markers for the method is written unchanged and counted. At the end the paper's\n"
        "metric e (section V) is printed for the input and the output.\n\n"
        "options:\n"
        "  --points FILE      marker positions, CSV 'frame,id,x,y' (required)\n"
        "  --method NAME      affine | pwlinear | bspline | rbf-local | tps | gaussian\n"
        "                     (RBFs with the affine term; add -pure for the form without it,\n"
        "                     e.g. tps-pure). Default: bspline, the paper's recommendation\n"
        "  --sigma S          RBF scale in pixels (default 95 for rbf-local, 100 for gaussian)\n"
        "  --levels L         B-spline levels (default: as many as exact interpolation needs;\n"
        "                     fewer approximate)\n"
        "  --smoothing LAMBDA RBF approximation instead of interpolation (default 0 = exact)\n"
        "  --reference N      0-based index of the reference frame (default 0)\n"
        "  --threads T        worker threads for the warp (default 1)\n"
        "  --max-error PX     largest tolerated error of the interpolated map (default 0.05)\n"
        "  --map-out FILE     write the last frame's map as .npy float32 H x W x 2\n"
        "                     (x, y in the current frame; NaN outside the hull)\n"
        "  --quiet            no progress line, no summary\n"
        "  --help             this text\n"
        "IN or OUT may be '-' for standard input / output (IN only with --reference 0; with\n"
        "OUT '-' the e figures go to standard error).\n");
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

static int fail(const char *what)
{
    sh_log_error("%s%s%s", what, *sh_error_message() ? ": " : "",
                 sh_error_message());
    return 1;
}

int cmd_warp(int argc, char **argv)
{
    sh_log_setup(SH_LOG_TOOL, "stillheart warp", SH_LOG_INFO);
    static const struct option options[] = {
        {"points", required_argument, 0, 'p'}, {"method", required_argument, 0, 'm'},
        {"sigma", required_argument, 0, 's'},  {"levels", required_argument, 0, 'l'},
        {"smoothing", required_argument, 0, 'S'}, {"reference", required_argument, 0, 'r'},
        {"threads", required_argument, 0, 't'}, {"max-error", required_argument, 0, 'e'},
        {"map-out", required_argument, 0, 'M'}, {"quiet", no_argument, 0, 'q'},
        {"help", no_argument, 0, 'h'},          {0, 0, 0, 0}};
    const char *points_path = NULL, *method = "bspline", *map_out = NULL;
    double sigma = 0, smoothing = 0, max_error = 0.05;
    int levels = 0, reference = 0, threads = 1, quiet = 0, have_sigma = 0;
    int opt;
    optind = 1;
    while ((opt = getopt_long(argc, argv, "", options, NULL)) != -1) {
        switch (opt) {
        case 'p': points_path = optarg; break;
        case 'm': method = optarg; break;
        case 's': if (!app_parse_double("--sigma", optarg, 1e-6, 1e9, &sigma)) return 2;
                  have_sigma = 1; break;
        case 'l': if (!app_parse_int("--levels", optarg, 1, 20, &levels)) return 2; break;
        case 'S': if (!app_parse_double("--smoothing", optarg, 0, 1e12, &smoothing)) return 2; break;
        case 'r': if (!app_parse_int("--reference", optarg, 0, 1 << 30, &reference)) return 2; break;
        case 't': if (!app_parse_int("--threads", optarg, 1, 256, &threads)) return 2; break;
        case 'e': if (!app_parse_double("--max-error", optarg, 1e-4, 100, &max_error)) return 2; break;
        case 'M': map_out = optarg; break;
        case 'q': quiet = 1; break;
        case 'h': usage(stdout); return 0;
        default: usage(stderr); return 2;
        }
    }
    if (argc - optind != 2 || !points_path) {
        sh_log_error("need --points and the input and output videos");
        usage(stderr);
        return 2;
    }
    const char *in_path = argv[optind], *out_path = argv[optind + 1];
    if (reference > 0 && !strcmp(in_path, "-")) {
        sh_log_error("--reference %d needs a file, not standard input",
                     reference);
        return 2;
    }

    sh_modelcache_recipe recipe;
    memset(&recipe, 0, sizeof recipe);
    if (sh_interp_params_parse(method, &recipe.params) != SH_OK) return fail("--method");
    if (have_sigma) recipe.params.sigma = sigma;
    recipe.params.levels = levels;
    recipe.params.smoothing = smoothing;
    sh_warp_options_default(&recipe.wopts);
    recipe.wopts.max_error = max_error;
    sh_modelcache *cache = NULL;

    int rc = 1;
    sh_points points = {0};
    sh_y4m_reader *reader = NULL;
    sh_y4m_writer *writer = NULL;
    sh_warp *warp = NULL;
    sh_metric *metric_in = NULL, *metric_out = NULL;
    sh_image in = {0}, out = {0}, ref = {0};
    int *ids = NULL;
    double *cur_xy = NULL;
    float *map = NULL;
    sh_warp_model *model = NULL, *last_model = NULL;

    if (sh_points_read(points_path, &points) != SH_OK) { fail("points"); goto done; }
    if (sh_y4m_reader_open(in_path, &reader) != SH_OK) { fail("input"); goto done; }
    const sh_y4m_header *hdr = sh_y4m_reader_header(reader);
    recipe.width = hdr->width;
    recipe.height = hdr->height;
    int ref_count;
    const sh_point *ref_rows = sh_points_frame(&points, reference, &ref_count);
    if (ref_count < 3) {
        sh_log_error("%s: the reference frame %d has %d markers, need 3", points_path, reference, ref_count);
        goto done;
    }
    ids = malloc(sizeof(int) * (size_t)ref_count);
    cur_xy = malloc(sizeof(double) * 2 * (size_t)ref_count);
    if (!ids || !cur_xy) { fail("out of memory"); goto done; }
    if (sh_modelcache_create(&recipe, ref_rows, ref_count, CACHE_SLOTS, &cache) != SH_OK) { fail("models"); goto done; }
    if (sh_image_create(&in, hdr->format, hdr->width, hdr->height) != SH_OK ||
        sh_image_create(&out, hdr->format, hdr->width, hdr->height) != SH_OK ||
        sh_image_create(&ref, hdr->format, hdr->width, hdr->height) != SH_OK) {
        fail("frame buffers");
        goto done;
    }
    if (sh_warp_create(threads, &warp) != SH_OK) { fail("threads"); goto done; }

    /* The reference model (all reference markers) and both metrics' reference frames. */
    int from_stdin = !strcmp(in_path, "-");
    /* From standard input (reference 0 only) the reference frame is the first one read below. */
    if (!from_stdin && !app_read_frame_at(in_path, reference, &ref)) { fail("reference frame"); goto done; }
    int nref = sh_points_match(ref_rows, ref_count, ref_rows, ref_count, ids, cur_xy);
    if (cache_get(cache, ids, nref, &model) != SH_OK) { fail("reference markers"); goto done; }
    int fr = sh_y4m_header_full_range(hdr);
    if (!from_stdin && !start_metrics(model, cur_xy, warp, &ref, &out, fr, &metric_in, &metric_out)) {
        fail("reference frame");
        goto done;
    }
    if (sh_y4m_writer_open(out_path, hdr, &writer) != SH_OK) { fail("output"); goto done; }

    app_progress progress;
    app_progress_start(&progress);
    if (quiet) progress.enabled = 0;
    int frames = 0, raw_frames = 0;
    double warp_seconds = 0;
    sh_status st;
    while ((st = sh_y4m_reader_read(reader, &in)) == SH_OK) {
        if (frames == reference && !metric_in) { /* standard input, reference 0 */
            sh_image_copy(&ref, &in);
            if (!start_metrics(model, cur_xy, warp, &ref, &out, fr, &metric_in, &metric_out)) {
                fail("reference frame");
                goto done;
            }
        }
        int ncur;
        const sh_point *cur = sh_points_frame(&points, frames, &ncur);
        int n = sh_points_match(ref_rows, ref_count, cur, ncur, ids, cur_xy);
        double t0 = app_now();
        const sh_image *shown = &out;
        if (n < 3 || cache_get(cache, ids, n, &model) != SH_OK ||
            sh_warp_model_update(model, cur_xy) != SH_OK ||
            sh_warp_apply(warp, model, &in, &out) != SH_OK) {
            shown = &in; /* nothing trustworthy to warp with: pass the frame through, counted */
            raw_frames++;
            if (!quiet)
                fprintf(stderr, "%sstillheart warp: frame %d left unstabilized (%d markers%s%s)\n",
                        progress.enabled ? "\n" : "", frames, n,
                        n >= 3 ? ": " : "", n >= 3 ? sh_error_message() : "");
        } else {
            last_model = model;
        }
        warp_seconds += app_now() - t0;
        if (sh_y4m_writer_write(writer, shown) != SH_OK) { fail("output"); goto done; }
        if (metric_in && (sh_metric_add(metric_in, &in) != SH_OK ||
                          sh_metric_add(metric_out, shown) != SH_OK)) {
            fail("metric");
            goto done;
        }
        frames++;
        app_progress_update(&progress, "warp", frames, 0);
    }
    app_progress_end(&progress);
    if (st != SH_EEOF) fail("input"); /* frames before the damage were written */
    if (sh_y4m_writer_close(writer) != SH_OK) { writer = NULL; fail("output"); goto done; }
    writer = NULL;

    if (map_out) {
        if (!last_model) {
            sh_log_error("--map-out: no frame was stabilized");
            goto done;
        }
        map = malloc(sizeof(float) * 2 * (size_t)recipe.width * recipe.height);
        if (!map || sh_warp_model_map(last_model, map) != SH_OK) { fail("map"); goto done; }
        if (!app_write_npy(map_out, map, recipe.height, recipe.width, 2)) goto done;
    }
    if (!quiet) {
        fprintf(stderr, "method %s: %d frames (%d unstabilized), %d marker sets built in %.1f ms, "
                        "warp %.2f ms/frame\n",
                method, frames, raw_frames, sh_modelcache_builds(cache), sh_modelcache_build_seconds(cache) * 1e3,
                frames ? warp_seconds * 1e3 / frames : 0.0);
        if (last_model && sh_warp_model_grid_spacing(last_model))
            fprintf(stderr, "grid spacing %d px, map error bound %.4f px\n",
                    sh_warp_model_grid_spacing(last_model), sh_warp_model_error_bound(last_model));
        /* stdout carries the video when OUT is "-": the figures go to stderr then */
        if (metric_in)
            fprintf(strcmp(out_path, "-") ? stdout : stderr,
                    "e input %.6f output %.6f (%d frames, %d hull pixels)\n", sh_metric_e(metric_in),
                    sh_metric_e(metric_out), sh_metric_frames(metric_in), sh_metric_pixels(metric_in));
    }
    rc = st == SH_EEOF ? 0 : 1;
done:
    if (writer) sh_y4m_writer_close(writer);
    sh_modelcache_destroy(cache);
    sh_y4m_reader_close(reader);
    sh_points_destroy(&points);
    sh_warp_destroy(warp);
    sh_metric_destroy(metric_in);
    sh_metric_destroy(metric_out);
    sh_image_destroy(&in);
    sh_image_destroy(&out);
    sh_image_destroy(&ref);
    free(ids);
    free(cur_xy);
    free(map);
    return rc;
}
