/* stillheart warp3d: offline 3D stabilization (paper Algorithm 2) of one camera's Y4M video
 * from 3D marker positions and the rig's calibration; virtual views and PLY export. */
#include <errno.h>
#include <getopt.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "app.h"
#include "stillheart/calib.h"
#include "stillheart/log.h"
#include "stillheart/metrics.h"
#include "stillheart/modelcache.h"
#include "stillheart/points.h"
#include "stillheart/warp3d.h"
#include "stillheart/y4m.h"

#define CACHE_SLOTS 4

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
        "  --points FILE      markers, CSV 'frame,id,x,y,X,Y,Z' (world mm; the X,Y,Z columns\n"
        "                     are required)\n"
        "  --camera K         the camera IN comes from (default 0)\n"
        "  --method NAME      interpolant of the surface and of the displacement (over the\n"
        "                     surface's plane, mm): affine | pwlinear | bspline | rbf-local |\n"
        "                     tps | gaussian (and -pure forms). Default bspline\n"
        "  --surface-method NAME, --displacement-method NAME\n"
        "                     set one of the two only\n"
        "  --sigma MM         RBF scale in mm (surface and displacement)\n"
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
        "  --quiet            no progress line, no summary\n"
        "  --help             this text\n"
        "With --view reference the paper's metric e is printed for the input and the output.\n");
}

static int has_xyz(const sh_point *p)
{
    return isfinite(p->X) && isfinite(p->Y) && isfinite(p->Z);
}

/* Markers of this frame that the reference frame also has, both with 3D positions. */
static int common_markers(const sh_point *ref, int nref, const sh_point *cur, int ncur, int *ids,
                          double *cur_xyz)
{
    int n = 0;
    for (int i = 0, j = 0; i < nref && j < ncur;) {
        if (ref[i].id < cur[j].id) i++;
        else if (ref[i].id > cur[j].id) j++;
        else {
            if (has_xyz(&ref[i]) && has_xyz(&cur[j])) {
                ids[n] = cur[j].id;
                cur_xyz[3 * n] = cur[j].X;
                cur_xyz[3 * n + 1] = cur[j].Y;
                cur_xyz[3 * n + 2] = cur[j].Z;
                n++;
            }
            i++, j++;
        }
    }
    return n;
}

static int fail(const char *what)
{
    sh_log_error("%s%s%s", what, *sh_error_message() ? ": " : "",
                 sh_error_message());
    return 1;
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
static sh_status render(sh_warp *warp, const sh_modelcache_entry *s, int nviews, int tb, int half, sh_image *eye,
                        const sh_image *in, sh_image *out, int raw)
{
    if (half && nviews == 2) {
        for (int v = 0; v < 2; v++) {
            sh_status st = raw ? SH_OK : sh_warp3d_view_apply(warp, s->view[v], in, eye, 0, 0);
            if (st == SH_OK)
                st = sh_warp3d_squeeze(raw ? in : eye, tb, out, tb ? 0 : v * in->width / 2, tb ? v * in->height / 2 : 0);
            if (st != SH_OK) return st;
        }
        return SH_OK;
    }
    for (int v = 0; v < nviews; v++) {
        int ox = tb ? 0 : v * in->width, oy = tb ? v * in->height : 0;
        sh_status st;
        if (raw) {
            if (nviews == 1) return sh_image_copy(out, in);
            for (int p = 0; p < in->num_planes; p++) {
                int sub = in->format == SH_PIX_I420 && p > 0;
                int px = sub ? ox / 2 : ox, py = sub ? oy / 2 : oy;
                size_t bpp = (size_t)(p == 0 ? sh_pixfmt_channels(in->format) : 1);
                for (int y = 0; y < in->plane[p].height; y++)
                    memcpy(out->plane[p].data + (size_t)(py + y) * out->plane[p].stride + px * bpp,
                           in->plane[p].data + (size_t)y * in->plane[p].stride,
                           (size_t)in->plane[p].width * bpp);
            }
            continue;
        }
        if ((st = sh_warp3d_view_apply(warp, s->view[v], in, out, ox, oy)) != SH_OK) return st;
    }
    return SH_OK;
}

int cmd_warp3d(int argc, char **argv)
{
    sh_log_setup(SH_LOG_TOOL, "stillheart warp3d", SH_LOG_INFO);
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
        {"quiet", no_argument, 0, 'q'}, {"help", no_argument, 0, 'h'}, {0, 0, 0, 0}};
    const char *calib_path = NULL, *points_path = NULL, *method = "bspline", *smethod = NULL,
               *dmethod = NULL, *view = "reference", *layout = "sbs", *ply_dir = NULL;
    double sigma = 0, baseline = 10, depth_scale = 1, max_error = 0.05, ply_spacing = 1;
    int camera = 0, reference = 0, threads = 1, quiet = 0, have_sigma = 0, ply_mesh = 0, ply_every = 1, ply_texture = 0;
    int opt;
    optind = 1;
    while ((opt = getopt_long(argc, argv, "", options, NULL)) != -1) {
        switch (opt) {
        case 'C': calib_path = optarg; break;
        case 'p': points_path = optarg; break;
        case 'k': if (!app_parse_int("--camera", optarg, 0, SH_CALIB_MAX_CAMERAS - 1, &camera)) return 2; break;
        case 'm': method = optarg; break;
        case 'A': smethod = optarg; break;
        case 'D': dmethod = optarg; break;
        case 's': if (!app_parse_double("--sigma", optarg, 1e-6, 1e9, &sigma)) return 2;
                  have_sigma = 1; break;
        case 'r': if (!app_parse_int("--reference", optarg, 0, 1 << 30, &reference)) return 2; break;
        case 'v': view = optarg; break;
        case 'b': if (!app_parse_double("--baseline", optarg, 0, 1e4, &baseline)) return 2; break;
        case 'L': layout = optarg; break;
        case 'z': if (!app_parse_double("--depth-scale", optarg, 0.01, 100, &depth_scale)) return 2; break;
        case 't': if (!app_parse_int("--threads", optarg, 1, 256, &threads)) return 2; break;
        case 'e': if (!app_parse_double("--max-error", optarg, 1e-4, 100, &max_error)) return 2; break;
        case 'P': ply_dir = optarg; break;
        case 'S': if (!app_parse_double("--ply-spacing", optarg, 1e-3, 1e4, &ply_spacing)) return 2; break;
        case 'M': ply_mesh = 1; break;
        case 'T': ply_texture = ply_mesh = 1; break;
        case 'E': if (!app_parse_int("--ply-every", optarg, 1, 1 << 30, &ply_every)) return 2; break;
        case 'q': quiet = 1; break;
        case 'h': usage(stdout); return 0;
        default: usage(stderr); return 2;
        }
    }
    if (argc - optind != 2 || !calib_path || !points_path) {
        sh_log_error("need --cameras, --points and the input and output videos");
        usage(stderr);
        return 2;
    }
    const char *in_path = argv[optind], *out_path = argv[optind + 1];
    if (!strcmp(in_path, "-") && reference > 0) {
        sh_log_error("--reference %d needs a file, not standard input", reference);
        return 2;
    }
    int stereo = 0, tb = 0, half = 0, pose = 0;
    double rvec[3] = {0, 0, 0}, tvec[3] = {0, 0, 0};
    if (!strcmp(view, "stereo")) stereo = 1;
    else if (!strncmp(view, "pose:", 5)) {
        if (!parse_pose(view + 5, rvec, tvec)) {
            sh_log_error("--view %s: want pose:RX,RY,RZ[,TX,TY,TZ]", view);
            return 2;
        }
        pose = 1;
    } else if (strcmp(view, "reference")) {
        sh_log_error("--view %s: reference, stereo or pose:...", view);
        return 2;
    }
    if (!strcmp(layout, "tb") || !strcmp(layout, "tb-half")) tb = 1;
    half = !strcmp(layout, "sbs-half") || !strcmp(layout, "tb-half");
    if (!tb && !half && strcmp(layout, "sbs")) {
        sh_log_error("--layout %s: sbs, tb, sbs-half or tb-half", layout);
        return 2;
    }

    sh_modelcache_recipe recipe;
    memset(&recipe, 0, sizeof recipe);
    recipe.three_d = 1;
    sh_warp3d_params_default(&recipe.p3);
    if (sh_interp_params_parse(smethod ? smethod : method, &recipe.p3.surface) != SH_OK ||
        sh_interp_params_parse(dmethod ? dmethod : method, &recipe.p3.displacement) != SH_OK) {
        fail("--method");
        return 2;
    }
    if (have_sigma) recipe.p3.surface.sigma = recipe.p3.displacement.sigma = sigma;
    sh_warp3d_view_options_default(&recipe.vopts);
    recipe.vopts.warp.max_error = max_error;
    recipe.vopts.depth_scale = depth_scale;
    sh_modelcache *cache = NULL;

    int rc = 1;
    sh_calib calib;
    sh_points points = {0};
    sh_y4m_reader *reader = NULL;
    sh_y4m_writer *writer = NULL;
    sh_warp *warp = NULL;
    sh_metric *metric_in = NULL, *metric_out = NULL;
    sh_image in = {0}, out = {0}, ref = {0}, rgb = {0}, eye = {0};
    int *ids = NULL;
    double *cur_xyz = NULL;

    if (sh_calib_read(calib_path, &calib) != SH_OK) { fail("cameras"); goto done; }
    if (camera >= calib.num_cameras) {
        sh_log_error("--camera %d: %s has %d cameras", camera, calib_path,
                     calib.num_cameras);
        goto done;
    }
    if (sh_points_read(points_path, &points) != SH_OK) { fail("points"); goto done; }
    if (!points.has_3d) {
        sh_log_error("%s has no X,Y,Z columns", points_path);
        goto done;
    }
    if (sh_y4m_reader_open(in_path, &reader) != SH_OK) { fail("input"); goto done; }
    const sh_y4m_header *hdr = sh_y4m_reader_header(reader);
    if (calib.width != hdr->width || calib.height != hdr->height) {
        sh_log_error("%s is %dx%d, the calibration %s is for %dx%d", in_path,
                     hdr->width, hdr->height, calib_path, calib.width, calib.height);
        goto done;
    }
    recipe.width = hdr->width;
    recipe.height = hdr->height;
    recipe.source_cam = calib.cam[camera];
    int ref_count;
    const sh_point *ref_rows = sh_points_frame(&points, reference, &ref_count);
    ids = malloc(sizeof(int) * ((size_t)ref_count + 1));
    cur_xyz = malloc(sizeof(double) * 3 * ((size_t)ref_count + 1));
    if (!ids || !cur_xyz) { fail("out of memory"); goto done; }
    int nref = common_markers(ref_rows, ref_count, ref_rows, ref_count, ids, cur_xyz);
    if (nref < 4) {
        sh_log_error("%s: the reference frame %d has %d markers with X,Y,Z, need 4",
                     points_path, reference, nref);
        goto done;
    }
    double *ref_xyz = malloc(sizeof(double) * 3 * (size_t)nref);
    if (!ref_xyz) { fail("out of memory"); goto done; }
    memcpy(ref_xyz, cur_xyz, sizeof(double) * 3 * (size_t)nref);
    if (stereo) {
        sh_warp3d_stereo_cameras(&recipe.source_cam, baseline, &recipe.view_cam[0], &recipe.view_cam[1]);
        recipe.nviews = 2;
    } else if (pose) {
        double c[3] = {0, 0, 0};
        for (int i = 0; i < nref; i++)
            for (int k = 0; k < 3; k++) c[k] += ref_xyz[3 * i + k] / nref;
        sh_warp3d_pose_camera(&recipe.source_cam, c, rvec, tvec, &recipe.view_cam[0]);
        recipe.nviews = 1;
    } else {
        recipe.view_cam[0] = recipe.source_cam;
        recipe.nviews = 1;
    }
    free(ref_xyz);

    sh_y4m_header out_hdr = *hdr;
    if (stereo && !half) {
        if (tb) out_hdr.height *= 2;
        else out_hdr.width *= 2;
    }
    if (stereo && half && (tb ? hdr->height : hdr->width) % (hdr->format == SH_PIX_I420 ? 4 : 2)) {
        sh_log_error("--layout %s: the frame's %s (%d) must be a multiple of %d", layout,
                     tb ? "height" : "width", tb ? hdr->height : hdr->width, hdr->format == SH_PIX_I420 ? 4 : 2);
        goto done;
    }
    if (out_hdr.width > SH_IMAGE_MAX_SIZE || out_hdr.height > SH_IMAGE_MAX_SIZE) {
        sh_log_error("the stereo frame %dx%d is too large", out_hdr.width,
                     out_hdr.height);
        goto done;
    }
    if (sh_image_create(&in, hdr->format, hdr->width, hdr->height) != SH_OK ||
        sh_image_create(&out, hdr->format, out_hdr.width, out_hdr.height) != SH_OK ||
        sh_image_create(&ref, hdr->format, hdr->width, hdr->height) != SH_OK ||
        (ply_dir && sh_image_create(&rgb, SH_PIX_RGB24, hdr->width, hdr->height) != SH_OK) ||
        (stereo && half && sh_image_create(&eye, hdr->format, hdr->width, hdr->height) != SH_OK)) {
        fail("frame buffers");
        goto done;
    }
    if (sh_warp_create(threads, &warp) != SH_OK) { fail("threads"); goto done; }
    if (ply_dir) {
        if (mkdir(ply_dir, 0777) != 0 && errno != EEXIST) {
            sh_log_error("--export-ply %s: cannot create the folder", ply_dir);
            goto done;
        }
        recipe.ply_spacing = ply_spacing;
        recipe.ply_mesh = ply_mesh;
    }
    if (sh_modelcache_create(&recipe, ref_rows, ref_count, CACHE_SLOTS, &cache) != SH_OK) { fail("models"); goto done; }
    sh_modelcache_entry *slot;
    if (sh_modelcache_get(cache, ids, nref, &slot) != SH_OK) { fail("reference markers"); goto done; }
    int fr = sh_y4m_header_full_range(hdr);
    int from_stdin = !strcmp(in_path, "-");
    int measure = !stereo && !pose;
    if (measure && !from_stdin) {
        if (!app_read_frame_at(in_path, reference, &ref)) { fail("reference frame"); goto done; }
        if (sh_warp3d_model_update(slot->m3, cur_xyz) != SH_OK ||
            sh_warp3d_view_update(slot->view[0]) != SH_OK ||
            render(warp, slot, 1, 0, 0, NULL, &ref, &out, 0) != SH_OK ||
            sh_metric_create(&ref, sh_warp3d_view_hull(slot->view[0]), fr, &metric_in) != SH_OK ||
            sh_metric_create(&out, sh_warp3d_view_hull(slot->view[0]), fr, &metric_out) != SH_OK) {
            fail("reference frame");
            goto done;
        }
    }
    if (sh_y4m_writer_open(out_path, &out_hdr, &writer) != SH_OK) { fail("output"); goto done; }

    app_progress progress;
    app_progress_start(&progress);
    if (quiet) progress.enabled = 0;
    int frames = 0, raw_frames = 0, exported = 0;
    double warp_seconds = 0;
    sh_status st;
    char ply_path[4096];
    while ((st = sh_y4m_reader_read(reader, &in)) == SH_OK) {
        int ncur;
        const sh_point *cur = sh_points_frame(&points, frames, &ncur);
        int n = common_markers(ref_rows, ref_count, cur, ncur, ids, cur_xyz);
        double t0 = app_now();
        int raw = n < 4 || sh_modelcache_get(cache, ids, n, &slot) != SH_OK ||
                  sh_warp3d_model_update(slot->m3, cur_xyz) != SH_OK;
        for (int v = 0; v < recipe.nviews && !raw; v++)
            raw = sh_warp3d_view_update(slot->view[v]) != SH_OK;
        if (!raw && render(warp, slot, recipe.nviews, tb, half, &eye, &in, &out, 0) != SH_OK) raw = 1;
        if (raw) {
            raw_frames++;
            if (!quiet)
                fprintf(stderr, "%sstillheart warp3d: frame %d left unstabilized (%d markers%s%s)\n",
                        progress.enabled ? "\n" : "", frames, n, n >= 4 ? ": " : "",
                        n >= 4 ? sh_error_message() : "");
            render(warp, slot, recipe.nviews, tb, half, &eye, &in, &out, 1);
        }
        warp_seconds += app_now() - t0;
        if (frames == reference && from_stdin && measure && !metric_in && !raw) {
            sh_image_copy(&ref, &in);
            if (sh_metric_create(&ref, sh_warp3d_view_hull(slot->view[0]), fr, &metric_in) != SH_OK ||
                sh_metric_create(&out, sh_warp3d_view_hull(slot->view[0]), fr, &metric_out) != SH_OK) {
                fail("reference frame");
                goto done;
            }
        }
        if (sh_y4m_writer_write(writer, &out) != SH_OK) { fail("output"); goto done; }
        if (metric_in && (sh_metric_add(metric_in, &in) != SH_OK || sh_metric_add(metric_out, &out) != SH_OK)) {
            fail("metric");
            goto done;
        }
        if (ply_dir && !raw && frames % ply_every == 0) {
            snprintf(ply_path, sizeof ply_path, "%s/frame_%06d.ply", ply_dir, frames);
            if (sh_image_to_rgb(&in, &rgb, fr) != SH_OK ||
                sh_warp3d_ply_write(slot->ply, slot->m3, 1, &rgb, &recipe.source_cam, ply_path) != SH_OK) {
                fail("--export-ply");
                goto done;
            }
            snprintf(ply_path, sizeof ply_path, "%s/frame_%06d", ply_dir, frames);
            if (ply_texture && sh_warp3d_obj_write(slot->ply, slot->m3, 1, &rgb, &recipe.source_cam, ply_path) != SH_OK) {
                fail("--export-ply");
                goto done;
            }
            exported++;
        }
        frames++;
        app_progress_update(&progress, "warp3d", frames, 0);
    }
    app_progress_end(&progress);
    if (st != SH_EEOF) fail("input");
    if (sh_y4m_writer_close(writer) != SH_OK) { writer = NULL; fail("output"); goto done; }
    writer = NULL;
    if (!quiet) {
        fprintf(stderr, "warp3d %s view, %s: %d frames (%d unstabilized), %d marker sets built in "
                        "%.1f ms, %.2f ms/frame",
                stereo ? "stereo" : pose ? "pose" : "reference", method, frames, raw_frames,
                sh_modelcache_builds(cache), sh_modelcache_build_seconds(cache) * 1e3, frames ? warp_seconds * 1e3 / frames : 0.0);
        if (ply_dir) fprintf(stderr, ", %d PLY files", exported);
        fprintf(stderr, "\n");
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
    sh_image_destroy(&rgb);
    sh_image_destroy(&eye);
    free(ids);
    free(cur_xyz);
    return rc;
}
