/* 3D stabilization on a rendered phantom, against the 2D engine and the phantom's truth:
 *  - e (paper, section V) and the geometric error of 3D stabilization (multilevel B-splines)
 *    within 15% of 2D multilevel B-splines on the same sequence and markers (paper Table II:
 *    0.042 vs 0.037);
 *  - a PLY export of the reference frame lies on the phantom's true surface (0.2 mm RMS).
 * The markers are the renderer's ground-truth tag centres (2D for the 2D engine, world X,Y,Z for
 * the 3D one); the geometric error follows stillheart-eval: hull pixels every 4 px located on the
 * tissue in the reference frame, compared with where that tissue is in frame t. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cmocka.h>

#include "phantom.h"
#include "phantom_testutil.h"
#include "stillheart/calib.h"
#include "stillheart/camera.h"
#include "stillheart/metrics.h"
#include "stillheart/warp3d.h"
#include "stillheart/y4m.h"

#define FRAMES 60
#define STRIDE 4
#define MAXM PHANTOM_MAX_MARKERS

typedef struct {
    const char *dir;
    phantom_truth *truth;
    phantom_csv csv;
    sh_calib calib;
    int width, height, n;
    int ids[MAXM];
} sequence;

/* The visible tag centres of camera 0 in frame f, in the order of ids; 0 when one is missing. */
static int markers(const sequence *s, int f, double *xy, double *xyz)
{
    for (int i = 0; i < s->n; i++) {
        const phantom_csv_row *r = phantom_csv_find(&s->csv, f, 0, s->ids[i], PHANTOM_POINTS - 1);
        if (!r || !r->visible) return 0;
        xy[2 * i] = r->x, xy[2 * i + 1] = r->y;
        xyz[3 * i] = r->X, xyz[3 * i + 1] = r->Y, xyz[3 * i + 2] = r->Z;
    }
    return 1;
}

static void open_sequence(sequence *s, const char *preset, int frames, int cameras, int slot)
{
    char args[256], path[4096];
    snprintf(args, sizeof args, "--preset %s --frames %d --cameras %d --width 960 --height 540",
             preset, frames, cameras);
    s->dir = pt_render(slot, args);
    assert_non_null(s->dir);
    if (phantom_truth_open(s->dir, &s->truth) != SH_OK) fail_msg("%s", sh_error_message());
    snprintf(path, sizeof path, "%s/markers.csv", s->dir);
    if (phantom_csv_read(path, &s->csv) != SH_OK) fail_msg("%s", sh_error_message());
    snprintf(path, sizeof path, "%s/calibration.yaml", s->dir);
    if (sh_calib_read(path, &s->calib) != SH_OK) fail_msg("%s", sh_error_message());
    s->width = s->calib.width;
    s->height = s->calib.height;
    s->n = phantom_truth_num_markers(s->truth);
    for (int i = 0; i < s->n; i++)
        assert_int_equal(phantom_truth_marker(s->truth, 0, 0, i, 4, &s->ids[i], NULL, NULL, NULL, NULL), SH_OK);
}

static void close_sequence(sequence *s)
{
    phantom_csv_free(&s->csv);
    phantom_truth_close(s->truth);
}

typedef struct {
    int count;
    double *x, *y, *u, *v; /* hull samples and their tissue point in the reference frame */
    double sum;
    long long pairs;
} geo;

static void geo_init(geo *g, const sequence *s, const sh_hull *hull)
{
    memset(g, 0, sizeof *g);
    size_t cap = (size_t)(s->width / STRIDE + 1) * (s->height / STRIDE + 1);
    g->x = malloc(sizeof(double) * cap), g->y = malloc(sizeof(double) * cap);
    g->u = malloc(sizeof(double) * cap), g->v = malloc(sizeof(double) * cap);
    assert_true(g->x && g->y && g->u && g->v);
    for (int y = 0; y < s->height; y += STRIDE)
        for (int x = 0; x < s->width; x += STRIDE) {
            double u, v;
            if (!sh_hull_contains(hull, x, y) ||
                phantom_truth_locate(s->truth, 0, 0, x, y, &u, &v) != SH_OK ||
                !phantom_truth_visible(s->truth, 0, 0, u, v))
                continue;
            g->x[g->count] = x, g->y[g->count] = y, g->u[g->count] = u, g->v[g->count] = v;
            g->count++;
        }
}

static void geo_add(geo *g, const sequence *s, int t, const float *map, int width)
{
    for (int i = 0; i < g->count; i++) {
        double gx, gy;
        if (!phantom_truth_visible(s->truth, 0, t, g->u[i], g->v[i]) ||
            phantom_truth_project(s->truth, 0, t, g->u[i], g->v[i], &gx, &gy) != SH_OK)
            continue;
        const float *m = map + 2 * ((size_t)g->y[i] * width + (size_t)g->x[i]);
        if (isnan(m[0])) continue;
        g->sum += hypot(m[0] - gx, m[1] - gy);
        g->pairs++;
    }
}

static void geo_free(geo *g)
{
    free(g->x), free(g->y), free(g->u), free(g->v);
}

/* Over 80 lines: the 2D and the 3D engine side by side on the same frames; most of the length is
 * their objects made and freed in pairs, and one loop feeds both the same input, which a split
 * would hide. */
static void compare(const char *preset, double tolerance)
{
    sequence s;
    open_sequence(&s, preset, FRAMES, 1, 0);
    char path[4096];
    snprintf(path, sizeof path, "%s/cam0.y4m", s.dir);
    double ref_xy[2 * MAXM], ref_xyz[3 * MAXM], xy[2 * MAXM], xyz[3 * MAXM];
    assert_true(markers(&s, 0, ref_xy, ref_xyz));

    sh_interp_params ip;
    sh_interp_params_default(&ip, SH_METHOD_BSPLINE);
    sh_interp *interp;
    sh_warp_model *m2;
    sh_warp3d_model *m3;
    sh_warp3d_view *v3;
    sh_warp *warp;
    assert_int_equal(sh_interp_create(&ip, ref_xy, s.n, &interp), SH_OK);
    assert_int_equal(sh_warp_model_create(interp, ref_xy, s.n, s.width, s.height, NULL, &m2), SH_OK);
    assert_int_equal(sh_warp3d_model_create(NULL, ref_xyz, s.n, &m3), SH_OK);
    if (sh_warp3d_view_create(m3, &s.calib.cam[0], &s.calib.cam[0], s.width, s.height, NULL, &v3) != SH_OK)
        fail_msg("%s", sh_error_message());
    assert_int_equal(sh_warp_create(1, &warp), SH_OK);

    sh_y4m_reader *r;
    assert_int_equal(sh_y4m_reader_open(path, &r), SH_OK);
    const sh_y4m_header *h = sh_y4m_reader_header(r);
    sh_image in, out2, out3;
    assert_int_equal(sh_image_create(&in, h->format, s.width, s.height), SH_OK);
    assert_int_equal(sh_image_create(&out2, h->format, s.width, s.height), SH_OK);
    assert_int_equal(sh_image_create(&out3, h->format, s.width, s.height), SH_OK);
    float *map = malloc(sizeof(float) * 2 * (size_t)s.width * s.height);
    assert_non_null(map);
    sh_metric *e2 = NULL, *e3 = NULL;
    const sh_hull *hull = sh_warp_model_hull(m2);
    geo g2, g3;
    geo_init(&g2, &s, hull);
    geo_init(&g3, &s, hull);
    int used = 0;
    for (int t = 0; sh_y4m_reader_read(r, &in) == SH_OK; t++) {
        if (!markers(&s, t, xy, xyz)) continue; /* both engines skip the same frames */
        assert_int_equal(sh_warp_model_update(m2, xy), SH_OK);
        assert_int_equal(sh_warp_apply(warp, m2, &in, &out2), SH_OK);
        assert_int_equal(sh_warp3d_model_update(m3, xyz), SH_OK);
        assert_int_equal(sh_warp3d_view_update(v3), SH_OK);
        assert_int_equal(sh_warp3d_view_apply(warp, v3, &in, &out3, 0, 0), SH_OK);
        if (t == 0) {
            assert_int_equal(sh_metric_create(&out2, hull, 0, &e2), SH_OK);
            assert_int_equal(sh_metric_create(&out3, hull, 0, &e3), SH_OK);
        }
        assert_int_equal(sh_metric_add(e2, &out2), SH_OK);
        assert_int_equal(sh_metric_add(e3, &out3), SH_OK);
        assert_int_equal(sh_warp_model_map(m2, map), SH_OK);
        geo_add(&g2, &s, t, map, s.width);
        assert_int_equal(sh_warp_model_map(sh_warp3d_view_map_model(v3), map), SH_OK);
        geo_add(&g3, &s, t, map, s.width);
        used++;
    }
    double ge2 = g2.sum / (double)g2.pairs, ge3 = g3.sum / (double)g3.pairs;
    printf("%s, %d frames: e 2D %.5f 3D %.5f (%+.1f%%); geometric mean 2D %.4f px 3D %.4f px "
           "(%+.1f%%); 3D grid %d px, bound %.4f px\n",
           preset, used, sh_metric_e(e2), sh_metric_e(e3),
           100 * (sh_metric_e(e3) / sh_metric_e(e2) - 1), ge2, ge3, 100 * (ge3 / ge2 - 1),
           sh_warp3d_view_grid_spacing(v3), sh_warp3d_view_error_bound(v3));
    assert_true(used > FRAMES / 2);
    assert_true(sh_metric_e(e3) <= (1 + tolerance) * sh_metric_e(e2));
    assert_true(ge3 <= (1 + tolerance) * ge2);

    geo_free(&g2);
    geo_free(&g3);
    free(map);
    sh_metric_destroy(e2);
    sh_metric_destroy(e3);
    sh_image_destroy(&in);
    sh_image_destroy(&out2);
    sh_image_destroy(&out3);
    sh_y4m_reader_close(r);
    sh_warp_destroy(warp);
    sh_warp3d_view_destroy(v3);
    sh_warp3d_model_destroy(m3);
    sh_warp_model_destroy(m2);
    sh_interp_destroy(interp);
    close_sequence(&s);
}

static void test_exvivo_3d_vs_2d(void **state)
{
    (void)state;
    compare("exvivo", 0.15);
}

static void test_invivo_3d_vs_2d(void **state)
{
    (void)state;
    compare("invivo", 0.15);
}

/* Distance from P to the true surface at time t: Gauss-Newton on the material (u, v). */
static double surface_distance(const phantom_model *pm, double t, const float P[3])
{
    double u = 0, v = 0, best = INFINITY;
    /* start from the nearest point of a coarse lattice */
    for (double a = -pm->size_u / 2; a <= pm->size_u / 2; a += 2)
        for (double b = -pm->size_v / 2; b <= pm->size_v / 2; b += 2) {
            double X[3];
            phantom_surface(pm, a, b, t, X);
            double d = (X[0] - P[0]) * (X[0] - P[0]) + (X[1] - P[1]) * (X[1] - P[1]) + (X[2] - P[2]) * (X[2] - P[2]);
            if (d < best) best = d, u = a, v = b;
        }
    for (int it = 0; it < 30; it++) {
        double X[3], Xu[3], Xv[3], e = 1e-5;
        phantom_surface(pm, u, v, t, X);
        phantom_surface(pm, u + e, v, t, Xu);
        phantom_surface(pm, u, v + e, t, Xv);
        double a[3], b[3], r[3];
        for (int k = 0; k < 3; k++) a[k] = (Xu[k] - X[k]) / e, b[k] = (Xv[k] - X[k]) / e, r[k] = X[k] - P[k];
        double aa = a[0] * a[0] + a[1] * a[1] + a[2] * a[2], ab = a[0] * b[0] + a[1] * b[1] + a[2] * b[2],
               bb = b[0] * b[0] + b[1] * b[1] + b[2] * b[2];
        double ar = a[0] * r[0] + a[1] * r[1] + a[2] * r[2], br = b[0] * r[0] + b[1] * r[1] + b[2] * r[2];
        double det = aa * bb - ab * ab;
        u -= (bb * ar - ab * br) / det;
        v -= (aa * br - ab * ar) / det;
    }
    double X[3];
    phantom_surface(pm, u, v, t, X);
    return sqrt((X[0] - P[0]) * (X[0] - P[0]) + (X[1] - P[1]) * (X[1] - P[1]) + (X[2] - P[2]) * (X[2] - P[2]));
}

static void ply_on_true_surface(const char *preset, int slot)
{
    sequence s;
    open_sequence(&s, preset, 1, 1, slot);
    double xy[2 * MAXM], xyz[3 * MAXM];
    assert_true(markers(&s, 0, xy, xyz));
    sh_warp3d_model *m3;
    sh_warp3d_ply *ply;
    assert_int_equal(sh_warp3d_model_create(NULL, xyz, s.n, &m3), SH_OK);
    assert_int_equal(sh_warp3d_ply_create(m3, 1.0, 0, &ply), SH_OK);
    char path[4096];
    snprintf(path, sizeof path, "%s/reference.ply", s.dir);
    assert_int_equal(sh_warp3d_ply_write(ply, m3, 0, NULL, NULL, path), SH_OK);
    FILE *f = fopen(path, "rb");
    assert_non_null(f);
    char line[256];
    int vertices = -1;
    while (fgets(line, sizeof line, f) && strcmp(line, "end_header\n")) sscanf(line, "element vertex %d", &vertices);
    assert_true(vertices > 1000);
    const phantom_model *pm = phantom_truth_model(s.truth);
    double sum2 = 0, worst = 0;
    for (int k = 0; k < vertices; k++) {
        unsigned char rec[15];
        assert_int_equal(fread(rec, 1, 15, f), 15);
        float P[3];
        memcpy(P, rec, 12);
        double d = surface_distance(pm, 0.0, P);
        sum2 += d * d;
        worst = fmax(worst, d);
    }
    fclose(f);
    double rms = sqrt(sum2 / vertices);
    printf("%s: PLY of the reference surface: %d points, distance to the true surface RMS %.4f mm, "
           "max %.4f mm\n", preset, vertices, rms, worst);
    assert_true(rms < 0.2);
    sh_warp3d_ply_destroy(ply);
    sh_warp3d_model_destroy(m3);
    close_sequence(&s);
}

static void test_ply_exvivo(void **state)
{
    (void)state;
    ply_on_true_surface("exvivo", 1);
}

static void test_ply_invivo(void **state)
{
    (void)state;
    ply_on_true_surface("invivo", 2);
}

/* Colour from the best-facing camera per pixel against the one chosen camera, for the reference
 * view of camera 0 on the trinocular phantom: each output pixel's surface point (reference
 * frame) picks the camera whose ray meets the surface most squarely, and takes its colour
 * through that camera's own map. Measured: the geometric error (hull pixels every 4 px, each
 * against where its tissue truly is in the camera that coloured it) and e.
 * Over 80 lines: one scenario read top to bottom: the camera each hull pixel picks, from the
 * reference surface, then every frame warped through the three views into a mosaic and measured
 * beside camera 0 alone. The pick map, the views, the readers and the metrics live across all of
 * it. */
static void test_best_facing_colour(void **state)
{
    (void)state;
    enum { NC = 3, NF = 20 };
    sequence s;
    open_sequence(&s, "exvivo", NF, NC, 0);
    double ref_xy[2 * MAXM], ref_xyz[3 * MAXM], xy[2 * MAXM], xyz[3 * MAXM];
    assert_true(markers(&s, 0, ref_xy, ref_xyz));
    sh_warp3d_model *m3;
    sh_warp3d_view *v[NC];
    sh_warp *warp;
    assert_int_equal(sh_warp3d_model_create(NULL, ref_xyz, s.n, &m3), SH_OK);
    for (int k = 0; k < NC; k++)
        if (sh_warp3d_view_create(m3, &s.calib.cam[0], &s.calib.cam[k], s.width, s.height, NULL, &v[k]) != SH_OK)
            fail_msg("%s", sh_error_message());
    assert_int_equal(sh_warp_create(1, &warp), SH_OK);
    const sh_hull *hull = sh_warp3d_view_hull(v[0]);
    /* the choice, per pixel of the hull, from the reference surface */
    uint8_t *best = calloc((size_t)s.width * s.height, 1);
    assert_non_null(best);
    double C[NC][3];
    for (int k = 0; k < NC; k++) sh_camera_center(&s.calib.cam[k], C[k]);
    int share[NC] = {0};
    for (int y = 0; y < s.height; y++)
        for (int x = 0; x < s.width; x++) {
            double uv[2], X[3], a[3], b[3], c[3], d[3];
            if (!sh_hull_contains(hull, x, y) || sh_warp3d_view_locate(v[0], x, y, uv) != SH_OK) continue;
            sh_warp3d_model_point(m3, uv[0], uv[1], 1, 0, X);
            sh_warp3d_model_point(m3, uv[0] + 0.5, uv[1], 1, 0, a);
            sh_warp3d_model_point(m3, uv[0] - 0.5, uv[1], 1, 0, b);
            sh_warp3d_model_point(m3, uv[0], uv[1] + 0.5, 1, 0, c);
            sh_warp3d_model_point(m3, uv[0], uv[1] - 0.5, 1, 0, d);
            double eu[3] = {a[0] - b[0], a[1] - b[1], a[2] - b[2]}, ev[3] = {c[0] - d[0], c[1] - d[1], c[2] - d[2]};
            double n[3] = {eu[1] * ev[2] - eu[2] * ev[1], eu[2] * ev[0] - eu[0] * ev[2], eu[0] * ev[1] - eu[1] * ev[0]};
            double top = -2;
            int pick = 0;
            for (int k = 0; k < NC; k++) {
                double r[3] = {C[k][0] - X[0], C[k][1] - X[1], C[k][2] - X[2]};
                double cosang = fabs(n[0] * r[0] + n[1] * r[1] + n[2] * r[2]) /
                                (sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]) * sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2]));
                if (cosang > top) top = cosang, pick = k;
            }
            best[(size_t)y * s.width + x] = (uint8_t)pick;
            share[pick]++;
        }
    /* hull samples: the tissue each sees in the reference frame (camera 0) */
    geo g;
    geo_init(&g, &s, hull);
    double sum1 = 0, sumb = 0;
    long long pairs = 0;
    sh_y4m_reader *r[NC];
    sh_image in[NC], out[NC], mosaic;
    for (int k = 0; k < NC; k++) {
        char path[4096];
        snprintf(path, sizeof path, "%s/cam%d.y4m", s.dir, k);
        assert_int_equal(sh_y4m_reader_open(path, &r[k]), SH_OK);
        const sh_y4m_header *h = sh_y4m_reader_header(r[k]);
        assert_int_equal(sh_image_create(&in[k], h->format, s.width, s.height), SH_OK);
        assert_int_equal(sh_image_create(&out[k], h->format, s.width, s.height), SH_OK);
    }
    assert_int_equal(sh_image_create(&mosaic, in[0].format, s.width, s.height), SH_OK);
    float *map[NC];
    for (int k = 0; k < NC; k++) assert_non_null(map[k] = malloc(sizeof(float) * 2 * (size_t)s.width * s.height));
    sh_metric *e1 = NULL, *eb = NULL;
    for (int t = 0; t < NF; t++) {
        for (int k = 0; k < NC; k++) assert_int_equal(sh_y4m_reader_read(r[k], &in[k]), SH_OK);
        if (!markers(&s, t, xy, xyz)) continue;
        assert_int_equal(sh_warp3d_model_update(m3, xyz), SH_OK);
        for (int k = 0; k < NC; k++) {
            assert_int_equal(sh_warp3d_view_update(v[k]), SH_OK);
            assert_int_equal(sh_warp3d_view_apply(warp, v[k], &in[k], &out[k], 0, 0), SH_OK);
            assert_int_equal(sh_warp_model_map(sh_warp3d_view_map_model(v[k]), map[k]), SH_OK);
        }
        /* the mosaic: every plane from the camera its (top-left) luma pixel chose */
        for (int p = 0; p < mosaic.num_planes; p++) {
            int sub = mosaic.format == SH_PIX_I420 && p > 0;
            for (int y = 0; y < mosaic.plane[p].height; y++)
                for (int x = 0; x < mosaic.plane[p].width; x++) {
                    int k = best[(size_t)(sub ? 2 * y : y) * s.width + (sub ? 2 * x : x)];
                    mosaic.plane[p].data[(size_t)y * mosaic.plane[p].stride + x] =
                        out[k].plane[p].data[(size_t)y * out[k].plane[p].stride + x];
                }
        }
        if (!e1) {
            assert_int_equal(sh_metric_create(&out[0], hull, 0, &e1), SH_OK);
            assert_int_equal(sh_metric_create(&mosaic, hull, 0, &eb), SH_OK);
        }
        assert_int_equal(sh_metric_add(e1, &out[0]), SH_OK);
        assert_int_equal(sh_metric_add(eb, &mosaic), SH_OK);
        for (int i = 0; i < g.count; i++) {
            int k = best[(size_t)g.y[i] * s.width + (size_t)g.x[i]];
            double gx0, gy0, gxk, gyk;
            if (!phantom_truth_visible(s.truth, 0, t, g.u[i], g.v[i]) || !phantom_truth_visible(s.truth, k, t, g.u[i], g.v[i]) ||
                phantom_truth_project(s.truth, 0, t, g.u[i], g.v[i], &gx0, &gy0) != SH_OK ||
                phantom_truth_project(s.truth, k, t, g.u[i], g.v[i], &gxk, &gyk) != SH_OK)
                continue;
            size_t at = 2 * ((size_t)g.y[i] * s.width + (size_t)g.x[i]);
            if (isnan(map[0][at]) || isnan(map[k][at])) continue;
            sum1 += hypot(map[0][at] - gx0, map[0][at + 1] - gy0);
            sumb += hypot(map[k][at] - gxk, map[k][at + 1] - gyk);
            pairs++;
        }
    }
    printf("best-facing colour (exvivo, %d frames, 3 cameras, reference view of camera 0): pixels choosing "
           "camera 0/1/2: %d/%d/%d; geometric mean camera 0 alone %.4f px, best-facing %.4f px; e %.5f vs %.5f\n",
           NF, share[0], share[1], share[2], sum1 / (double)pairs, sumb / (double)pairs, sh_metric_e(e1),
           sh_metric_e(eb));
    assert_true(pairs > 1000);
    for (int k = 0; k < NC; k++) {
        free(map[k]);
        sh_image_destroy(&in[k]);
        sh_image_destroy(&out[k]);
        sh_y4m_reader_close(r[k]);
        sh_warp3d_view_destroy(v[k]);
    }
    sh_image_destroy(&mosaic);
    sh_metric_destroy(e1);
    sh_metric_destroy(eb);
    geo_free(&g);
    free(best);
    sh_warp_destroy(warp);
    sh_warp3d_model_destroy(m3);
    close_sequence(&s);
}

/* The command: a stereo pair (side by side) from the phantom's ground truth, PLY export, and
 * refusals. */
static int run(const char *args)
{
    char cmd[8192];
    snprintf(cmd, sizeof cmd, "'%s' warp3d %s >/dev/null 2>&1", APP_BIN, args);
    int rc = system(cmd);
    return rc == -1 ? -1 : WEXITSTATUS(rc);
}

static void test_cli(void **state)
{
    (void)state;
    const char *dir = pt_render(3, "--preset exvivo --frames 3 --cameras 2 --width 320 --height 180");
    assert_non_null(dir);
    char args[4096], cmd[4096];
    snprintf(cmd, sizeof cmd, "'%s' --truth '%s' --export-points '%s/p3.csv' --camera 1", EVAL_BIN,
             dir, dir);
    assert_int_equal(system(cmd), 0);
    snprintf(args, sizeof args,
             "--quiet --cameras '%s/calibration.yaml' --points '%s/p3.csv' --camera 1 --view stereo "
             "--baseline 8 --export-ply '%s/ply' --ply-texture '%s/cam1.y4m' '%s/sbs.y4m'",
             dir, dir, dir, dir, dir);
    assert_int_equal(run(args), 0);
    snprintf(cmd, sizeof cmd, "%s/sbs.y4m", dir);
    FILE *f = fopen(cmd, "rb");
    assert_non_null(f);
    char line[256];
    assert_non_null(fgets(line, sizeof line, f));
    fclose(f);
    assert_non_null(strstr(line, " W640 H180 "));
    /* the squeezed layouts keep the input's size */
    static const char *halves[2] = {"sbs-half", "tb-half"};
    for (int i = 0; i < 2; i++) {
        snprintf(args, sizeof args, "--quiet --cameras '%s/calibration.yaml' --points '%s/p3.csv' --camera 1 "
                 "--view stereo --layout %s '%s/cam1.y4m' '%s/half.y4m'", dir, dir, halves[i], dir, dir);
        assert_int_equal(run(args), 0);
        snprintf(cmd, sizeof cmd, "%s/half.y4m", dir);
        f = fopen(cmd, "rb");
        assert_non_null(f);
        assert_non_null(fgets(line, sizeof line, f));
        fclose(f);
        assert_non_null(strstr(line, " W320 H180 "));
    }
    static const char *exported[] = {"ply", "obj", "mtl", "png"};
    for (int i = 0; i < 4; i++) {
        snprintf(cmd, sizeof cmd, "%s/ply/frame_000002.%s", dir, exported[i]);
        f = fopen(cmd, "rb");
        assert_non_null(f);
        fclose(f);
    }
    /* 3D markers alone (frame,id,X,Y,Z, as another tracker gives them): the same video, byte for
     * byte, as from the file with the 2D columns too, which warp3d does not use; the output's
     * header names the interpolant; the 2D warp refuses the file */
    snprintf(cmd, sizeof cmd, "cut -d, -f1,2,5-7 '%s/p3.csv' > '%s/xyz.csv' && head -1 '%s/xyz.csv' | "
             "grep -qx 'frame,id,X,Y,Z'", dir, dir, dir);
    assert_int_equal(system(cmd), 0);
    for (int i = 0; i < 2; i++) {
        snprintf(args, sizeof args, "--quiet --cameras '%s/calibration.yaml' --points '%s/%s' --camera 1 "
                 "'%s/cam1.y4m' '%s/ref%d.y4m'", dir, dir, i ? "xyz.csv" : "p3.csv", dir, dir, i);
        assert_int_equal(run(args), 0);
    }
    snprintf(cmd, sizeof cmd, "cmp -s '%s/ref0.y4m' '%s/ref1.y4m'", dir, dir);
    assert_int_equal(system(cmd), 0);
    snprintf(cmd, sizeof cmd, "%s/ref1.y4m", dir);
    f = fopen(cmd, "rb");
    assert_non_null(f);
    assert_non_null(fgets(line, sizeof line, f));
    fclose(f);
    assert_non_null(strstr(line, " XSTILLHEART=method3d:tps\n"));
    snprintf(cmd, sizeof cmd, "'%s' warp --quiet --points '%s/xyz.csv' '%s/cam1.y4m' '%s/x.y4m' 2>/dev/null",
             APP_BIN, dir, dir, dir);
    int rc = system(cmd);
    assert_true(WIFEXITED(rc) && WEXITSTATUS(rc) == 1);

    assert_int_equal(run("--help"), 0);
    snprintf(args, sizeof args, "--cameras '%s/calibration.yaml' --points '%s/p3.csv' --view sideways "
             "'%s/cam1.y4m' '%s/x.y4m'", dir, dir, dir, dir);
    assert_int_equal(run(args), 2);
    snprintf(args, sizeof args, "--cameras '%s/calibration.yaml' --points '%s/p3.csv' --camera 3 "
             "'%s/cam1.y4m' '%s/x.y4m'", dir, dir, dir, dir);
    assert_int_equal(run(args), 1);
    /* a 2D points file has no X,Y,Z */
    snprintf(cmd, sizeof cmd, "printf 'frame,id,x,y\\n0,1,2,3\\n' > '%s/p2.csv'", dir);
    assert_int_equal(system(cmd), 0);
    snprintf(args, sizeof args, "--cameras '%s/calibration.yaml' --points '%s/p2.csv' "
             "'%s/cam0.y4m' '%s/x.y4m'", dir, dir, dir, dir);
    assert_int_equal(run(args), 1);
}

/* `warp3d ARGS`, its standard output in DIR/out.txt and its standard error in DIR/err.txt: the
 * exit status. */
static int run_to(const char *dir, const char *args)
{
    char cmd[16384];
    snprintf(cmd, sizeof cmd, "'%s' warp3d %s >'%s/out.txt' 2>'%s/err.txt'", APP_BIN, args, dir, dir);
    int rc = system(cmd);
    return rc == -1 ? -1 : WEXITSTATUS(rc);
}

/* DIR/NAME's text (static storage, up to 64 KiB). */
static const char *text_of(const char *dir, const char *name)
{
    static char text[1 << 16];
    char path[4096];
    snprintf(path, sizeof path, "%s/%s", dir, name);
    FILE *f = fopen(path, "rb");
    assert_non_null(f);
    text[fread(text, 1, sizeof text - 1, f)] = '\0';
    fclose(f);
    return text;
}

/* --metric (issue 20: e converts every frame to RGB, so it is asked for, as in `stillheart
 * warp`): the same video with and without it; e only with it, with --quiet too, and the figures
 * stillheart-eval gives for the same videos; to standard output the video goes there and e to
 * standard error; refused for a virtual view. The second case is a depth-scaled view whose grid
 * refines on the reference frame's map: without that map made ahead of the frames, --metric or
 * not, frame 0 differs from byte 68952 on. */
static void test_cli_metric(void **state)
{
    (void)state;
    const char *d = pt_render(3, "--preset exvivo --frames 30 --cameras 1 --width 640 --height 360");
    assert_non_null(d);
    char args[8192], common[4096], plain[1024], metric[1024];
    snprintf(args, sizeof args, "'%s' --truth '%s' --export-points '%s/p3.csv'", EVAL_BIN, d, d);
    assert_int_equal(system(args), 0);
    snprintf(plain, sizeof plain, "%s/plain.y4m", d);
    snprintf(metric, sizeof metric, "%s/metric.y4m", d);
    static const char *cases[2] = {"", "--depth-scale 3 --reference 29 --max-error 0.02"};
    double e_in, e_out;
    for (int i = 1; i >= 0; i--) { /* the default last: its videos and e are checked below */
        snprintf(common, sizeof common, "%s --cameras '%s/calibration.yaml' --points '%s/p3.csv' '%s/cam0.y4m'",
                 cases[i], d, d, d);
        snprintf(args, sizeof args, "%s '%s'", common, plain);
        assert_int_equal(run_to(d, args), 0);
        assert_string_equal(text_of(d, "out.txt"), "");
        snprintf(args, sizeof args, "--quiet --metric %s '%s'", common, metric);
        assert_int_equal(run_to(d, args), 0);
        int frames, pixels;
        assert_int_equal(sscanf(text_of(d, "out.txt"), "residual motion e (lower is better): %lf -> %lf, "
                                "%*[^(](%d frames, %d hull pixels)", &e_in, &e_out, &frames, &pixels), 4);
        assert_true(e_out < 0.5 * e_in);
        assert_int_equal(frames, 30);
        assert_true(pt_same_file(plain, metric));
    }
    snprintf(args, sizeof args, "'%s' --quiet --json --points '%s/p3.csv' '%s' '%s/cam0.y4m' >'%s/out.txt'",
             EVAL_BIN, d, metric, d, d);
    assert_int_equal(system(args), 0);
    const char *json = text_of(d, "out.txt");
    const char *out = strstr(json, "\"e_stabilized\": "), *orig = strstr(json, "\"e_original\": ");
    assert_true(out && orig);
    /* warp3d prints 6 decimals */
    assert_float_equal(e_out, strtod(out + sizeof "\"e_stabilized\": " - 1, NULL), 5e-7);
    assert_float_equal(e_in, strtod(orig + sizeof "\"e_original\": " - 1, NULL), 5e-7);

    snprintf(args, sizeof args, "--quiet --metric %s -", common);
    assert_int_equal(run_to(d, args), 0);
    assert_non_null(strstr(text_of(d, "err.txt"), "residual motion e (lower is better): "));
    snprintf(metric, sizeof metric, "%s/out.txt", d);
    assert_true(pt_same_file(plain, metric));
    snprintf(args, sizeof args, "--metric --view stereo %s '%s/x.y4m'", common, d);
    assert_int_equal(run_to(d, args), 2);
    assert_non_null(strstr(text_of(d, "err.txt"), "--metric: with --view reference only"));
}

static int teardown(void **state)
{
    (void)state;
    pt_cleanup();
    return 0;
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_exvivo_3d_vs_2d),
        cmocka_unit_test(test_invivo_3d_vs_2d),
        cmocka_unit_test(test_ply_exvivo),
        cmocka_unit_test(test_ply_invivo),
        cmocka_unit_test(test_best_facing_colour),
        cmocka_unit_test(test_cli),
        cmocka_unit_test(test_cli_metric),
    };
    return cmocka_run_group_tests(tests, NULL, teardown);
}
