/* stillheart warp3d: offline 3D stabilization (paper Algorithm 2) of one camera's Y4M video
 * from 3D marker positions and the rig's calibration; virtual views and PLY export. */
#include <errno.h>
#include <getopt.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "stab.h"
#include "stillheart/calib.h"
#include "stillheart/landmarks.h"
#include "stillheart/log.h"
#include "stillheart/warp3d.h"

#define CACHE_SLOTS 4

static const sh_cli cli = {"stillheart warp3d"};

static void usage(FILE *out)
{
    fprintf(out,
        "usage: stillheart warp3d --cameras CALIB.yaml --points P3.csv [OPTIONS] IN.y4m OUT.y4m\n\n"
        "3D stabilization (paper section IV, Algorithm 2): the reference surface is fitted to the\n"
        "reference frame's 3D markers, the displacement of every later frame's markers is\n"
        "interpolated over it, and each output pixel takes its colour from where its surface\n"
        "point is now, projected into the camera IN was filmed with (lens distortion honoured).\n"
        "Pixels outside the convex hull of the reference markers (as the output camera sees them)\n"
        "are black. A frame with fewer than 4 usable markers is written unchanged and counted.\n\n"
        "options:\n"
        "  --cameras FILE     calibration (OpenCV FileStorage YAML: K_i, dist_i, R_i, t_i)\n"
        "  --points FILE      markers, CSV 'frame,id,x,y,X,Y,Z' or 'frame,id,X,Y,Z' (world\n"
        "                     mm; x,y are not used, X,Y,Z are required); ids from 1000000 are\n"
        "                     the tissue's landmarks (stillheart track --cameras --landmarks),\n"
        "                     left out when either interpolant is gaussian or rbf-local\n"
        "  --camera K         the camera IN comes from (default 0)\n"
        "  --method NAME      interpolant of the surface and of the displacement (over the\n"
        "                     surface's plane, mm): affine | pwlinear | bspline | rbf-local |\n"
        "                     tps | gaussian (and -pure forms). Default tps, as for\n"
        "                     `stillheart warp`\n"
        "  --surface-method NAME, --displacement-method NAME\n"
        "                     set one of the two only\n"
        "  --sigma MM         RBF scale in mm (surface and displacement)\n"
        "  --landmark-smoothing LAMBDA\n"
        "                     with tps (the RBFs): the landmark rows' own smoothing in the\n"
        "                     surface and the displacement, given in the pixels of 1080p\n"
        "                     frames as `stillheart warp`'s (default 1000, as the daemon's\n"
        "                     [track] landmarks_smoothing) and converted to the surface's mm\n"
        "                     by the camera's pixels per mm there; the markers stay exact; 0:\n"
        "                     the landmarks interpolated as well. Refused when neither\n"
        "                     interpolant is an RBF\n"
        "  --reference N      0-based reference frame (default 0)\n"
        "  --view V           reference: the camera's own view (default; OUT has IN's size)\n"
        "                     stereo: a left/right pair of virtual cameras (see --baseline,\n"
        "                     --layout)\n"
        "                     pose:RX,RY,RZ[,TX,TY,TZ]: a virtual camera, the scene turned about\n"
        "                     the markers' centre by the rotation vector (degrees, camera axes)\n"
        "                     and shifted by T (mm, camera axes)\n"
        "  --baseline MM      stereo: distance between the virtual eyes (default 10)\n"
        "  --layout L         stereo: sbs (side by side, OUT is 2W x H, default) or tb (top-\n"
        "                     bottom, W x 2H); sbs-half / tb-half: the same squeezed into\n"
        "                     W x H (each eye at half width / height, as 3D TVs take it; W resp.\n"
        "                     H a multiple of 4 for 4:2:0); left eye left / on top\n"
        "  --depth-scale S    exaggerate the surface's relief along its normal (default 1)\n"
        "  --threads T        worker threads for the rendering (default 1)\n"
        "  --max-error PX     largest tolerated error of the interpolated map (default 0.05)\n"
        "  --export-ply DIR   write the stabilized (current) surface of every exported frame to\n"
        "                     DIR/frame_NNNNNN.ply (binary PLY, world mm, colour from IN)\n"
        "  --ply-spacing MM   lattice spacing of the export over the surface (default 1)\n"
        "  --ply-mesh         add the lattice's triangles (a mesh instead of a point cloud)\n"
        "  --ply-texture      also write each exported surface as a textured mesh beside its PLY:\n"
        "                     frame_NNNNNN.obj, .mtl and .png (IN's frame; implies --ply-mesh)\n"
        "  --ply-every N      export every N-th frame (default 1)\n"
        "  --metric           also print the paper's metric e of the input and the output\n"
        "                     (--view reference only; every frame is converted to RGB for it,\n"
        "                     6-9 times the run's time without it)\n"
        SH_CLI_USAGE
        "OUT's header names the interpolants (XSTILLHEART=method3d:NAME[/NAME]).\n");
}

/* pose:RX,RY,RZ[,TX,TY,TZ] */
static int parse_pose(const char *text, double rvec[3], double tvec[3])
{
    double v[6] = {0, 0, 0, 0, 0, 0};
    int count = 0;
    const char *p = text;
    while (*p && count < 6) {
        char *end;
        v[count] = strtod(p, &end);
        if (end == p || !isfinite(v[count])) return 0;
        count++;
        if (*end == ',') p = end + 1;
        else if (*end == '\0') p = end;
        else return 0;
    }
    if (*p || (count != 3 && count != 6)) return 0;
    for (int i = 0; i < 3; i++) {
        rvec[i] = v[i] * M_PI / 180;
        tvec[i] = v[3 + i];
    }
    return 1;
}

/* Writes the stabilized frame: one view, or the two eyes in their layout. Raw: the input in
 * every view's place. Half layouts render each eye into `eye` (W x H) and squeeze it. */
static sh_status render(sh_warp *warp, const sh_modelcache_entry *s, int nviews, sh_warp3d_layout layout,
                        sh_image *eye, const sh_image *in, sh_image *out, int raw)
{
    if (nviews == 1) return raw ? sh_image_copy(out, in) : sh_warp3d_view_apply(warp, s->view[0], in, out, 0, 0);
    if (!raw) return sh_warp3d_stereo_apply(warp, (const sh_warp3d_view *const *)s->view, NULL, layout, in, eye, out);
    sh_status st = sh_warp3d_layout_place(layout, 0, in, out);
    return st == SH_OK ? sh_warp3d_layout_place(layout, 1, in, out) : st;
}

/* What the command line asks for; filled by parse_options only (the options/runtime split of
 * ustreamer: warp3d_job below holds what the run opens and counts). */
typedef struct {
    const char *calib_path, *points_path, *method, *view, *layout, *ply_dir, *in_path, *out_path;
    sh_warp3d_params p3; /* --method, --surface-method, --displacement-method and --sigma */
    double baseline, depth_scale, max_error, ply_spacing;
    double landmark_smoothing;  /* --landmark-smoothing, at 1080p */
    int camera, reference, threads, quiet, ply_mesh, ply_every, ply_texture;
    int stereo, pose;           /* --view ... */
    sh_warp3d_layout layout_id; /* ... and --layout */
    double rvec[3], tvec[3];    /* --view pose: */
    /* e is over R, G and B (paper section V), so every input and output frame is converted to
     * RGB: 85 % of a 1080p run (issue 20, as in `stillheart warp`), asked for, not paid for by
     * every run; stillheart-eval measures the same e. */
    int metric;
} warp3d_options;

/* --view and --layout: APP_GO_ON, or the exit code with the refusal printed. */
static int parse_view(warp3d_options *o)
{
    if (!strcmp(o->view, "stereo")) o->stereo = 1;
    else if (!strncmp(o->view, "pose:", 5)) {
        if (!parse_pose(o->view + 5, o->rvec, o->tvec)) {
            sh_log_error("--view %s: want pose:RX,RY,RZ[,TX,TY,TZ]", o->view);
            return 2;
        }
        o->pose = 1;
    } else if (strcmp(o->view, "reference")) {
        sh_log_error("--view %s: reference, stereo or pose:...", o->view);
        return 2;
    }
    if (sh_warp3d_layout_parse(o->layout, &o->layout_id) != SH_OK) {
        sh_log_error("--layout %s: sbs, tb, sbs-half or tb-half", o->layout);
        return 2;
    }
    /* e compares each output pixel with the same pixel of the warped reference frame, in the
     * camera IN was filmed with; a virtual camera's pixels are other points of the surface */
    if (o->metric && (o->stereo || o->pose)) {
        sh_log_error("--metric: with --view reference only, not %s", o->view);
        return 2;
    }
    return APP_GO_ON;
}

/* The interpolants: --method, or --surface-method / --displacement-method for one of them;
 * APP_GO_ON, or the exit code with the refusal printed. */
static int parse_methods(warp3d_options *o, const char *smethod, const char *dmethod, int have_sigma,
                         double sigma)
{
    sh_warp3d_params_default(&o->p3);
    if (sh_interp_params_parse(smethod ? smethod : o->method, &o->p3.surface) != SH_OK ||
        sh_interp_params_parse(dmethod ? dmethod : o->method, &o->p3.displacement) != SH_OK) {
        app_fail("--method");
        return 2;
    }
    if (have_sigma) o->p3.surface.sigma = o->p3.displacement.sigma = sigma;
    return APP_GO_ON;
}

/* Fills o from argv: APP_GO_ON, or the exit code (usage and refusals printed). */
static int parse_options(int argc, char **argv, warp3d_options *o)
{
    static const struct option options[] = {
        {"cameras", required_argument, 0, 'C'}, {"points", required_argument, 0, 'p'},
        {"camera", required_argument, 0, 'k'}, {"method", required_argument, 0, 'm'},
        {"surface-method", required_argument, 0, 'A'}, {"displacement-method", required_argument, 0, 'D'},
        {"sigma", required_argument, 0, 's'}, {"reference", required_argument, 0, 'r'},
        {"view", required_argument, 0, 'v'}, {"baseline", required_argument, 0, 'b'},
        {"layout", required_argument, 0, 'L'}, {"depth-scale", required_argument, 0, 'z'},
        {"threads", required_argument, 0, 't'}, {"max-error", required_argument, 0, 'e'},
        {"export-ply", required_argument, 0, 'P'}, {"ply-spacing", required_argument, 0, 'S'},
        {"ply-mesh", no_argument, 0, 'M'}, {"ply-texture", no_argument, 0, 'T'}, {"ply-every", required_argument, 0, 'E'},
        {"metric", no_argument, 0, 'R'}, {"landmark-smoothing", required_argument, 0, 'l'}, SH_CLI_OPTIONS,
        {0, 0, 0, 0}};
    memset(o, 0, sizeof *o);
    o->method = "tps", o->view = "reference", o->layout = "sbs";
    o->baseline = 10, o->depth_scale = 1, o->max_error = 0.05, o->ply_spacing = 1;
    o->threads = 1, o->ply_every = 1, o->landmark_smoothing = SH_LANDMARK_SMOOTHING;
    const char *smethod = NULL, *dmethod = NULL;
    double sigma = 0;
    int have_sigma = 0, have_lm_smoothing = 0, opt;
    optind = 1;
    opterr = 0;
    while ((opt = getopt_long(argc, argv, ":h", options, NULL)) != -1) {
        switch (opt) {
        case 'C': o->calib_path = optarg; break;
        case 'p': o->points_path = optarg; break;
        case 'k': if (!sh_cli_parse_int("--camera", optarg, 0, SH_CALIB_MAX_CAMERAS - 1, &o->camera)) return 2; break;
        case 'm': o->method = optarg; break;
        case 'A': smethod = optarg; break;
        case 'D': dmethod = optarg; break;
        case 's': if (!sh_cli_parse_double("--sigma", optarg, 1e-6, 1e9, &sigma)) return 2;
                  have_sigma = 1; break;
        case 'r': if (!sh_cli_parse_int("--reference", optarg, 0, 1 << 30, &o->reference)) return 2; break;
        case 'v': o->view = optarg; break;
        case 'b': if (!sh_cli_parse_double("--baseline", optarg, 0, 1e4, &o->baseline)) return 2; break;
        case 'L': o->layout = optarg; break;
        case 'z': if (!sh_cli_parse_double("--depth-scale", optarg, 0.01, 100, &o->depth_scale)) return 2; break;
        case 't': if (!sh_cli_parse_int("--threads", optarg, 1, 256, &o->threads)) return 2; break;
        case 'e': if (!sh_cli_parse_double("--max-error", optarg, 1e-4, 100, &o->max_error)) return 2; break;
        case 'P': o->ply_dir = optarg; break;
        case 'S': if (!sh_cli_parse_double("--ply-spacing", optarg, 1e-3, 1e4, &o->ply_spacing)) return 2; break;
        case 'M': o->ply_mesh = 1; break;
        case 'T': o->ply_texture = o->ply_mesh = 1; break;
        case 'E': if (!sh_cli_parse_int("--ply-every", optarg, 1, 1 << 30, &o->ply_every)) return 2; break;
        case 'R': o->metric = 1; break;
        case 'l': if (!sh_cli_parse_double("--landmark-smoothing", optarg, 0, 1e12, &o->landmark_smoothing)) return 2;
                  have_lm_smoothing = 1; break;
        case 'h': usage(stdout); return 0;
        default: { int rc = sh_cli_option(&cli, opt, argv); if (rc >= 0) return rc; } break;
        }
    }
    o->quiet = sh_log_get_level() < SH_LOG_INFO;
    if (argc - optind != 2 || !o->calib_path || !o->points_path)
        return sh_cli_usage_error(&cli, "need --cameras, --points and the input and output videos");
    o->in_path = argv[optind];
    o->out_path = argv[optind + 1];
    if (!strcmp(o->in_path, "-") && o->reference > 0) {
        sh_log_error("--reference %d needs a file, not standard input", o->reference);
        return 2;
    }
    int rc = parse_view(o);
    if (rc == APP_GO_ON) rc = parse_methods(o, smethod, dmethod, have_sigma, sigma);
    /* a smoothing no interpolant has a use for does nothing: refused, as in `stillheart warp` */
    if (rc == APP_GO_ON && have_lm_smoothing &&
        !(sh_interp_method_smooths(o->p3.surface.method) || sh_interp_method_smooths(o->p3.displacement.method)))
        return sh_cli_usage_error(&cli, "--landmark-smoothing: neither interpolant is an RBF (tps approximates the "
                                  "landmarks)");
    return rc;
}

/* What one run opens and counts, from warp3d_open to warp3d_close. */
typedef struct {
    const warp3d_options *o;
    app_stab s;
    sh_modelcache_recipe recipe;
    sh_modelcache_entry *slot; /* the models of the current frame's marker set */
    sh_calib calib;
    int nref;                  /* the reference frame's markers with X,Y,Z */
    /* the reference has landmark rows: every model holds all of them, and each frame is fitted
     * through the ones it has (use; sh_warp3d_model_update_subset) */
    int landmarks;
    unsigned char *use;
    sh_y4m_header out_hdr;
    sh_image rgb, eye;         /* --export-ply's colours; a half layout's eye */
    int exported;
} warp3d_job;

/* The calibration, the points, the input and the reference frame's 3D markers (their
 * positions left in cur_xyz): 0, or 1 with the reason printed. */
static int open_input(warp3d_job *j)
{
    const warp3d_options *o = j->o;
    app_stab *s = &j->s;
    if (sh_calib_read(o->calib_path, &j->calib) != SH_OK) return app_fail("cameras");
    if (o->camera >= j->calib.num_cameras) {
        sh_log_error("--camera %d: %s has %d cameras", o->camera, o->calib_path,
                     j->calib.num_cameras);
        return 1;
    }
    if (sh_points_read(o->points_path, &s->points) != SH_OK) return app_fail("points");
    if (!s->points.has_3d) {
        sh_log_error("%s has no X,Y,Z columns", o->points_path);
        return 1;
    }
    if (!sh_landmarks_method_uses(o->p3.surface.method) || !sh_landmarks_method_uses(o->p3.displacement.method)) {
        int n = sh_points_drop_ids(&s->points, SH_LANDMARK_ID_BASE);
        if (n) sh_log_info("%d landmark rows left out: %s is worse with them (docs/landmarks.md)", n, o->method);
    }
    if (sh_y4m_reader_open(o->in_path, &s->reader) != SH_OK) return app_fail("input");
    const sh_y4m_header *hdr = sh_y4m_reader_header(s->reader);
    if (j->calib.width != hdr->width || j->calib.height != hdr->height) {
        sh_log_error("%s is %dx%d, the calibration %s is for %dx%d", o->in_path,
                     hdr->width, hdr->height, o->calib_path, j->calib.width, j->calib.height);
        return 1;
    }
    j->recipe.width = hdr->width;
    j->recipe.height = hdr->height;
    j->recipe.source_cam = j->calib.cam[o->camera];
    /* given at 1080p, scaled to the frame as `stillheart track` scaled the landmarks' lengths
     * (sh_landmarks_smoothing); the models convert it to the surface's mm */
    j->recipe.point_smoothing = sh_landmarks_smoothing(o->landmark_smoothing,
                                                       sh_landmarks_reduction(NULL, hdr->width, hdr->height));
    j->recipe.smoothed_from = SH_LANDMARK_ID_BASE;
    s->ref_rows = sh_points_frame(&s->points, o->reference, &s->ref_count);
    s->ids = malloc(sizeof(int) * ((size_t)s->ref_count + 1));
    s->cur = malloc(sizeof(double) * 3 * ((size_t)s->ref_count + 1));
    if (!s->ids || !s->cur) return app_fail("out of memory");
    j->nref = sh_points_match_xyz(s->ref_rows, s->ref_count, s->ref_rows, s->ref_count, s->ids, s->cur);
    /* pwlinear cannot leave points out (its triangles depend on which are used): a model per set */
    for (int i = 0; i < j->nref; i++)
        j->landmarks |= s->ids[i] >= SH_LANDMARK_ID_BASE && o->p3.displacement.method != SH_METHOD_PWLINEAR;
    if (j->landmarks && !(j->use = malloc((size_t)s->ref_count + 1))) return app_fail("out of memory");
    if (j->nref < 4) {
        sh_log_error("%s: the reference frame %d has %d markers with X,Y,Z, need 4",
                     o->points_path, o->reference, j->nref);
        return 1;
    }
    return 0;
}

/* The cameras the output is seen from (--view), posed from the reference markers: 0, or 1 with
 * the reason printed. */
static int set_views(warp3d_job *j)
{
    const warp3d_options *o = j->o;
    app_stab *s = &j->s;
    sh_modelcache_recipe *r = &j->recipe;
    double *ref_xyz = malloc(sizeof(double) * 3 * (size_t)j->nref);
    if (!ref_xyz) return app_fail("out of memory");
    memcpy(ref_xyz, s->cur, sizeof(double) * 3 * (size_t)j->nref);
    if (o->stereo) {
        sh_warp3d_stereo_cameras(&r->source_cam, o->baseline, &r->view_cam[0], &r->view_cam[1]);
        r->nviews = 2;
    } else if (o->pose) {
        /* the markers' centre: landmark rows (stillheart track --landmarks) would move it with
         * how many of them frame 0 has */
        double c[3] = {0, 0, 0};
        int nm = 0;
        for (int i = 0; i < j->nref; i++) nm += s->ids[i] < SH_LANDMARK_ID_BASE;
        for (int i = 0; i < j->nref; i++)
            if (s->ids[i] < SH_LANDMARK_ID_BASE || nm == 0)
                for (int k = 0; k < 3; k++) c[k] += ref_xyz[3 * i + k] / (nm ? nm : j->nref);
        sh_warp3d_pose_camera(&r->source_cam, c, o->rvec, o->tvec, &r->view_cam[0]);
        r->nviews = 1;
    } else {
        r->view_cam[0] = r->source_cam;
        r->nviews = 1;
    }
    free(ref_xyz);
    return 0;
}

/* The output's size (--view stereo, --layout), the frame buffers, the warp's threads and the PLY
 * folder: 0, or 1 with the reason printed. */
static int open_output(warp3d_job *j)
{
    const warp3d_options *o = j->o;
    app_stab *s = &j->s;
    const sh_y4m_header *hdr = sh_y4m_reader_header(s->reader);
    j->out_hdr = *hdr;
    if (app_stab_tag(&j->out_hdr, "method3d", &o->p3.surface, &o->p3.displacement)) return 1;
    if (o->stereo && sh_warp3d_layout_size(o->layout_id, hdr->format, hdr->width, hdr->height, &j->out_hdr.width,
                                           &j->out_hdr.height) != SH_OK)
        return app_fail("--layout");
    if (sh_image_create(&s->in, hdr->format, hdr->width, hdr->height) != SH_OK ||
        sh_image_create(&s->out, hdr->format, j->out_hdr.width, j->out_hdr.height) != SH_OK ||
        (o->metric && sh_image_create(&s->ref, hdr->format, hdr->width, hdr->height) != SH_OK) ||
        (o->ply_dir && sh_image_create(&j->rgb, SH_PIX_RGB24, hdr->width, hdr->height) != SH_OK) ||
        (o->stereo && sh_warp3d_layout_half(o->layout_id) && sh_image_create(&j->eye, hdr->format, hdr->width, hdr->height) != SH_OK))
        return app_fail("frame buffers");
    if (sh_warp_create(o->threads, &s->warp) != SH_OK) return app_fail("threads");
    if (o->ply_dir) {
        if (mkdir(o->ply_dir, 0777) != 0 && errno != EEXIST) {
            sh_log_error("--export-ply %s: cannot create the folder", o->ply_dir);
            return 1;
        }
        j->recipe.ply_spacing = o->ply_spacing;
        j->recipe.ply_mesh = o->ply_mesh;
    }
    return 0;
}

/* --metric: e's two references, the reference frame as filmed (s->ref) and as stabilized
 * (s->out), over the hull of view: 0, or 1 with the reason printed. */
static int start_metrics(app_stab *s, const sh_warp3d_view *view)
{
    const sh_hull *hull = sh_warp3d_view_hull(view);
    if (sh_metric_create(&s->ref, hull, s->full_range, &s->metric_in) != SH_OK ||
        sh_metric_create(&s->out, hull, s->full_range, &s->metric_out) != SH_OK)
        return app_fail("reference frame");
    return 0;
}

/* The reference view's map of the reference frame, and with --metric that frame read again and
 * stabilized for e: 0, or 1 with the reason printed. */
static int start_reference(warp3d_job *j)
{
    const warp3d_options *o = j->o;
    app_stab *s = &j->s;
    /* made with --metric or not: a view's grid only ever refines, so this map is part of what
     * the frames before the reference are warped with (a depth-scaled view of the phantom with
     * --reference 29 --max-error 0.02 differs without it), and --metric must not change OUT */
    if (sh_warp3d_model_update(j->slot->m3, s->cur) != SH_OK || sh_warp3d_view_update(j->slot->view[0]) != SH_OK)
        return app_fail("reference frame");
    if (!o->metric) return 0;
    if (!app_read_frame_at(o->in_path, o->reference, &s->ref) ||
        render(s->warp, j->slot, 1, o->layout_id, NULL, &s->ref, &s->out, 0) != SH_OK)
        return app_fail("reference frame");
    return start_metrics(s, j->slot->view[0]);
}

/* Everything the frame loop needs, up to the reference frame's models and metrics and the open
 * output: 0, or 1 with the reason printed (warp3d_close frees either way). */
static int warp3d_open(warp3d_job *j, const warp3d_options *o)
{
    memset(j, 0, sizeof *j);
    j->o = o;
    app_stab *s = &j->s;
    j->recipe.three_d = 1;
    j->recipe.p3 = o->p3;
    sh_warp3d_view_options_default(&j->recipe.vopts);
    j->recipe.vopts.warp.max_error = o->max_error;
    j->recipe.vopts.depth_scale = o->depth_scale;
    if (open_input(j) || set_views(j) || open_output(j)) return 1;
    if (sh_modelcache_create(&j->recipe, s->ref_rows, s->ref_count, CACHE_SLOTS, &s->cache) != SH_OK)
        return app_fail("models");
    if (sh_modelcache_get(s->cache, s->ids, j->nref, &j->slot) != SH_OK) return app_fail("reference markers");
    s->full_range = sh_y4m_header_full_range(sh_y4m_reader_header(s->reader));
    s->from_stdin = !strcmp(o->in_path, "-");
    /* From standard input (reference 0) the reference frame is the first one: warp3d_frame. */
    if (!o->stereo && !o->pose && !s->from_stdin && start_reference(j)) return 1;
    return app_stab_start(s, "warp3d", o->out_path, &j->out_hdr);
}

/* --export-ply of the frame just stabilized: 0, or 1 with the reason printed. */
static int export_ply(warp3d_job *j)
{
    const warp3d_options *o = j->o;
    const app_stab *s = &j->s;
    const sh_modelcache_entry *e = j->slot;
    char path[4096];
    snprintf(path, sizeof path, "%s/frame_%06d.ply", o->ply_dir, s->frames);
    if (sh_image_to_rgb(&s->in, &j->rgb, s->full_range) != SH_OK ||
        sh_warp3d_ply_write(e->ply, e->m3, 1, &j->rgb, &j->recipe.source_cam, path) != SH_OK)
        return app_fail("--export-ply");
    snprintf(path, sizeof path, "%s/frame_%06d", o->ply_dir, s->frames);
    if (o->ply_texture && sh_warp3d_obj_write(e->ply, e->m3, 1, &j->rgb, &j->recipe.source_cam, path) != SH_OK)
        return app_fail("--export-ply");
    j->exported++;
    return 0;
}

/* Stabilizes, writes, measures and exports the frame just read into s.in (job: the warp3d_job):
 * 0, or 1 with the reason printed. */
static int warp3d_frame(void *job)
{
    warp3d_job *j = job;
    const warp3d_options *o = j->o;
    app_stab *s = &j->s;
    int ncur, nviews = j->recipe.nviews;
    const sh_point *cur = sh_points_frame(&s->points, s->frames, &ncur);
    int used, n = j->landmarks ? sh_points_match_xyz_keep(s->ref_rows, s->ref_count, cur, ncur, SH_LANDMARK_ID_BASE,
                                                          s->ids, s->cur, j->use, &used)
                               : (used = sh_points_match_xyz(s->ref_rows, s->ref_count, cur, ncur, s->ids, s->cur));
    double t0 = app_now();
    int raw = used < 4 || sh_modelcache_get(s->cache, s->ids, n, &j->slot) != SH_OK ||
              sh_warp3d_model_update_subset(j->slot->m3, s->cur, j->landmarks ? j->use : NULL) != SH_OK;
    for (int v = 0; v < nviews && !raw; v++)
        raw = sh_warp3d_view_update(j->slot->view[v]) != SH_OK;
    if (!raw && render(s->warp, j->slot, nviews, o->layout_id, &j->eye, &s->in, &s->out, 0) != SH_OK) raw = 1;
    if (raw) {
        app_stab_raw(s, "warp3d", used, 4, o->quiet);
        render(s->warp, j->slot, nviews, o->layout_id, &j->eye, &s->in, &s->out, 1);
    }
    s->warp_seconds += app_now() - t0;
    if (s->frames == o->reference && s->from_stdin && o->metric && !s->metric_in && !raw) {
        if (sh_image_copy(&s->ref, &s->in) != SH_OK) return app_fail("reference frame");
        if (start_metrics(s, j->slot->view[0])) return 1;
    }
    if (sh_y4m_writer_write(s->writer, &s->out) != SH_OK) return app_fail("output");
    if (s->metric_in && (sh_metric_add(s->metric_in, &s->in) != SH_OK || sh_metric_add(s->metric_out, &s->out) != SH_OK))
        return app_fail("metric");
    if (o->ply_dir && !raw && s->frames % o->ply_every == 0 && export_ply(j)) return 1;
    s->frames++;
    sh_cli_progress_update(&s->progress, s->frames);
    return 0;
}

/* The summary on stderr. */
static void report(const warp3d_job *j)
{
    const warp3d_options *o = j->o;
    const app_stab *s = &j->s;
    fprintf(stderr, "warp3d %s view, %s: %d frames (%d unstabilized), %d marker sets built in "
                    "%.1f ms, %.2f ms/frame",
            o->stereo ? "stereo" : o->pose ? "pose" : "reference", o->method, s->frames, s->raw_frames,
            sh_modelcache_builds(s->cache), sh_modelcache_build_seconds(s->cache) * 1e3,
            s->frames ? s->warp_seconds * 1e3 / s->frames : 0.0);
    if (o->ply_dir) fprintf(stderr, ", %d PLY files", j->exported);
    fprintf(stderr, "\n");
}

static void warp3d_close(warp3d_job *j)
{
    app_stab_close(&j->s);
    sh_image_destroy(&j->rgb);
    sh_image_destroy(&j->eye);
    free(j->use);
}

int cmd_warp3d(int argc, char **argv)
{
    sh_log_setup(SH_LOG_TOOL, "stillheart warp3d", SH_LOG_INFO);
    warp3d_options o;
    int rc = parse_options(argc, argv, &o);
    if (rc != APP_GO_ON) return rc;
    warp3d_job j;
    sh_status st;
    rc = 1;
    if (warp3d_open(&j, &o) || app_stab_run(&j.s, warp3d_frame, &j, &st)) goto done;
    if (!o.quiet) report(&j);
    /* asked for by name: printed with --quiet too (which quiets the log, not the results) */
    if (o.metric) app_stab_print_e(&j.s, o.out_path);
    rc = st == SH_EEOF ? 0 : 1;
done:
    warp3d_close(&j);
    return rc;
}
