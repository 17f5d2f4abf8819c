/* stillheart-calib against the renderer's truth: the default trinocular rig (1920x1080, lens
 * distortion, the sensor's usual noise) sees a 9x6 checkerboard of 8 mm squares in 20 poses
 * (stillheart-render --calib-target); the recovered cameras must match calibration.yaml:
 * focal lengths and principal points within 0.5 %, rotations relative to camera 0 within 0.1
 * degree, baselines within 0.5 %, reprojection RMS under 0.2 px. Besides OpenCV's own RMS, the
 * truth's 3D corners are carried into camera 0's frame and projected through the recovered
 * cameras (libstillheart's projection): an end-to-end check that needs nothing from the tool
 * but its file. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/wait.h>

#include <cmocka.h>

#include "phantom_testutil.h"
#include "stillheart/calib.h"
#include "stillheart/camera.h"
#include "stillheart/image.h"
#include "stillheart/png.h"
#include "stillheart/y4m.h"

#ifndef CALIB_BIN
#error "CALIB_BIN must name the stillheart-calib binary of this build"
#endif

#define BOARD "checkerboard:9x6:8"
#define CORNERS 54
#define FRAMES 20
#define DIST "-0.08,0.12,0.0004,-0.0003,0"

static const char *rig_dir(void)
{
    static const char *dir;
    if (!dir) dir = pt_render(0, "--calib-target " BOARD " --frames 20 --distortion=" DIST);
    return dir;
}

/* Runs a shell command; its exit status, its stdout in out (may be NULL). */
static int run(const char *cmd, char *out, size_t n)
{
    FILE *p = popen(cmd, "r");
    assert_non_null(p);
    size_t len = 0;
    char buf[4096];
    size_t k;
    while ((k = fread(buf, 1, sizeof buf, p)) > 0)
        if (out && len + k < n) memcpy(out + len, buf, k), len += k;
    if (out) out[len] = '\0';
    int st = pclose(p);
    return WIFEXITED(st) ? WEXITSTATUS(st) : -1;
}

static double rot_angle_deg(const double A[9], const double B[9])
{
    /* angle of A^T B */
    double tr = 0;
    for (int i = 0; i < 3; i++)
        for (int k = 0; k < 3; k++) tr += A[3 * k + i] * B[3 * k + i];
    double c = 0.5 * (tr - 1);
    return acos(c > 1 ? 1 : c < -1 ? -1 : c) * 180.0 / M_PI;
}

/* R_i R_0^T and the centre of camera i relative to camera 0 in camera 0's axes. */
static void relative(const sh_calib_camera *c0, const sh_calib_camera *ci, double R[9], double C[3])
{
    for (int a = 0; a < 3; a++)
        for (int b = 0; b < 3; b++) {
            R[3 * a + b] = 0;
            for (int k = 0; k < 3; k++) R[3 * a + b] += ci->R[3 * a + k] * c0->R[3 * b + k];
        }
    double C0[3], Ci[3];
    sh_camera_center(c0, C0);
    sh_camera_center(ci, Ci);
    for (int a = 0; a < 3; a++) {
        C[a] = 0;
        for (int k = 0; k < 3; k++) C[a] += c0->R[3 * a + k] * (Ci[k] - C0[k]);
    }
}

typedef struct {
    int frame, camera, corner;
    double x, y, X[3];
} truth_row;

static int read_board_csv(const char *path, truth_row *rows, int max)
{
    FILE *f = fopen(path, "r");
    assert_non_null(f);
    char line[512];
    assert_non_null(fgets(line, sizeof line, f));
    assert_string_equal(line, "frame,camera,corner,x,y,X,Y,Z\n");
    int n = 0;
    while (n < max && fgets(line, sizeof line, f)) {
        truth_row *r = &rows[n];
        assert_int_equal(sscanf(line, "%d,%d,%d,%lf,%lf,%lf,%lf,%lf", &r->frame, &r->camera, &r->corner, &r->x,
                                &r->y, &r->X[0], &r->X[1], &r->X[2]), 8);
        n++;
    }
    fclose(f);
    return n;
}

/* Over 80 lines: one calibration of the rendered rig (the slow part), judged four ways in turn:
 * OpenCV's RMS, intrinsics and relative poses against the truth, the truth's pixels triangulated
 * through the recovered rig, the corners found against their true pixels. The last two share the
 * board.csv rows; split, each part would need the run's files and the rows handed to it. */
static void test_recovers_the_rig(void **state)
{
    (void)state;
    const char *dir = rig_dir();
    assert_non_null(dir);
    char cmd[4096], out[8192], path[1024];
    snprintf(cmd, sizeof cmd, "'%s' --board " BOARD " --out '%s/est.yaml' --corners-out '%s/corners.csv' "
             "'%s/cam0.y4m' '%s/cam1.y4m' '%s/cam2.y4m'", CALIB_BIN, dir, dir, dir, dir, dir);
    assert_int_equal(run(cmd, out, sizeof out), 0);
    printf("%s", out);

    /* OpenCV's RMS: per camera (calibrateCamera) and per pair (stereoCalibrate) */
    int nrms = 0;
    for (const char *p = out; (p = strstr(p, "RMS ")) != NULL; p += 4) {
        double rms = atof(p + 4);
        assert_true(rms > 0 && rms < 0.2);
        nrms++;
    }
    assert_int_equal(nrms, 5);

    sh_calib truth, est;
    snprintf(path, sizeof path, "%s/calibration.yaml", dir);
    assert_int_equal(sh_calib_read(path, &truth), SH_OK);
    snprintf(path, sizeof path, "%s/est.yaml", dir);
    assert_int_equal(sh_calib_read(path, &est), SH_OK);
    assert_int_equal(est.num_cameras, 3);
    assert_int_equal(est.width, truth.width);
    assert_int_equal(est.height, truth.height);
    printf("# camera: fx fy cx cy relative error %%; rotation error deg; baseline error %%\n");
    for (int c = 0; c < 3; c++) {
        const double *Kt = truth.cam[c].K, *Ke = est.cam[c].K;
        static const int idx[4] = {0, 4, 2, 5};
        double rel[4];
        for (int k = 0; k < 4; k++) {
            rel[k] = 100 * fabs(Ke[idx[k]] - Kt[idx[k]]) / Kt[idx[k]];
            assert_true(rel[k] < 0.5);
        }
        double Rt[9], Ct[3], Re[9], Ce[3];
        relative(&truth.cam[0], &truth.cam[c], Rt, Ct);
        relative(&est.cam[0], &est.cam[c], Re, Ce);
        double ang = rot_angle_deg(Rt, Re);
        double bt = sqrt(Ct[0] * Ct[0] + Ct[1] * Ct[1] + Ct[2] * Ct[2]);
        double be = sqrt(Ce[0] * Ce[0] + Ce[1] * Ce[1] + Ce[2] * Ce[2]);
        double berr = c ? 100 * fabs(be - bt) / bt : 0;
        printf("# camera %d: %.3f %.3f %.3f %.3f %%; %.4f deg; baseline %.3f mm (true %.3f), %.3f %%\n", c, rel[0],
               rel[1], rel[2], rel[3], ang, be, bt, berr);
        assert_true(ang < 0.1);
        assert_true(berr < 0.5);
    }

    /* the true pixels of each corner triangulated through the recovered rig (libstillheart):
     * their reprojection residual says whether the three cameras agree, the distance to the true
     * corner (in camera 0's frame) what the rig measures */
    static truth_row rows[FRAMES * 3 * CORNERS];
    snprintf(path, sizeof path, "%s/board.csv", dir);
    int n = read_board_csv(path, rows, FRAMES * 3 * CORNERS);
    assert_int_equal(n, FRAMES * 3 * CORNERS);
    const sh_calib_camera *cams[3] = {&est.cam[0], &est.cam[1], &est.cam[2]};
    double res2 = 0, err2 = 0, err_max = 0;
    for (int f = 0; f < FRAMES; f++)
        for (int k = 0; k < CORNERS; k++) {
            double uv[6], X0[3];
            for (int c = 0; c < 3; c++) {
                const truth_row *r = &rows[(f * 3 + c) * CORNERS + k];
                assert_true(r->frame == f && r->camera == c && r->corner == k);
                uv[2 * c] = r->x, uv[2 * c + 1] = r->y;
            }
            const truth_row *r = &rows[f * 3 * CORNERS + k];
            const sh_calib_camera *t0 = &truth.cam[0];
            for (int a = 0; a < 3; a++)
                X0[a] = t0->R[3 * a] * r->X[0] + t0->R[3 * a + 1] * r->X[1] + t0->R[3 * a + 2] * r->X[2] + t0->t[a];
            sh_triangulation tr;
            assert_int_equal(sh_camera_triangulate(cams, uv, 3, 1, 0, &tr), SH_OK);
            res2 += tr.rms * tr.rms;
            double e2 = 0;
            for (int a = 0; a < 3; a++) e2 += (tr.X[a] - X0[a]) * (tr.X[a] - X0[a]);
            err2 += e2;
            err_max = fmax(err_max, sqrt(e2));
        }
    int np = FRAMES * CORNERS;
    printf("# true pixels triangulated through the recovered rig: reprojection RMS %.4f px, 3D error RMS %.3f mm "
           "(max %.3f) over %d corners\n", sqrt(res2 / np), sqrt(err2 / np), err_max, np);
    assert_true(sqrt(res2 / np) < 0.2);
    assert_true(sqrt(err2 / np) < 0.5);

    /* the corners found against their true pixels: the renderer's board and the detector */
    snprintf(path, sizeof path, "%s/corners.csv", dir);
    FILE *f = fopen(path, "r");
    assert_non_null(f);
    char line[256];
    assert_non_null(fgets(line, sizeof line, f));
    int m = 0;
    double det2 = 0;
    while (fgets(line, sizeof line, f)) {
        int fr, c, k;
        double x, y;
        assert_int_equal(sscanf(line, "%d,%d,%d,%lf,%lf", &fr, &c, &k, &x, &y), 5);
        const truth_row *r = &rows[(fr * 3 + c) * CORNERS + k];
        assert_true(r->frame == fr && r->camera == c && r->corner == k);
        det2 += (x - r->x) * (x - r->x) + (y - r->y) * (y - r->y);
        m++;
    }
    fclose(f);
    assert_int_equal(m, FRAMES * 3 * CORNERS); /* every view found */
    printf("# corners found vs true pixels: RMS %.4f px\n", sqrt(det2 / m));
    assert_true(sqrt(det2 / m) < 0.1);
}

static void unit(double a[3])
{
    double l = sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]);
    for (int k = 0; k < 3; k++) a[k] /= l;
}

/* --world board:N: the frame the board defines in view N (origin at corner 0, x along the first
 * row, z out of the printed face), built here from the truth's 3D corners; every recovered
 * camera must sit and look where the true one does in that frame. */
static void test_world_on_board(void **state)
{
    (void)state;
    const char *dir = rig_dir();
    assert_non_null(dir);
    enum { VIEW = 4 };
    char cmd[4096], out[8192], path[1024];
    snprintf(cmd, sizeof cmd, "'%s' --board " BOARD " --world board:%d --out '%s/world.yaml' '%s/cam0.y4m' "
             "'%s/cam1.y4m' '%s/cam2.y4m'", CALIB_BIN, VIEW, dir, dir, dir, dir);
    assert_int_equal(run(cmd, out, sizeof out), 0);
    static truth_row rows[FRAMES * 3 * CORNERS];
    snprintf(path, sizeof path, "%s/board.csv", dir);
    assert_int_equal(read_board_csv(path, rows, FRAMES * 3 * CORNERS), FRAMES * 3 * CORNERS);
    const truth_row *r = &rows[VIEW * 3 * CORNERS]; /* camera 0's rows of the view */
    assert_true(r[0].frame == VIEW && r[0].camera == 0 && r[0].corner == 0);
    const double *O = r[0].X;
    double x[3], yb[3], z[3], y[3];
    for (int k = 0; k < 3; k++) x[k] = r[1].X[k] - O[k], yb[k] = r[9].X[k] - O[k];
    unit(x);
    unit(yb);
    z[0] = -(x[1] * yb[2] - x[2] * yb[1]), z[1] = -(x[2] * yb[0] - x[0] * yb[2]), z[2] = -(x[0] * yb[1] - x[1] * yb[0]);
    unit(z);
    y[0] = z[1] * x[2] - z[2] * x[1], y[1] = z[2] * x[0] - z[0] * x[2], y[2] = z[0] * x[1] - z[1] * x[0];
    sh_calib truth, est;
    snprintf(path, sizeof path, "%s/calibration.yaml", dir);
    assert_int_equal(sh_calib_read(path, &truth), SH_OK);
    snprintf(path, sizeof path, "%s/world.yaml", dir);
    assert_int_equal(sh_calib_read(path, &est), SH_OK);
    for (int c = 0; c < 3; c++) {
        double C[3], Ce[3], d[3], Rw[9];
        sh_camera_center(&truth.cam[c], C);
        sh_camera_center(&est.cam[c], Ce);
        for (int k = 0; k < 3; k++) d[k] = C[k] - O[k];
        double ct[3] = {x[0] * d[0] + x[1] * d[1] + x[2] * d[2], y[0] * d[0] + y[1] * d[1] + y[2] * d[2],
                        z[0] * d[0] + z[1] * d[1] + z[2] * d[2]};
        /* board world -> camera: R [x y z] */
        const double *R = truth.cam[c].R;
        for (int a = 0; a < 3; a++) {
            Rw[3 * a] = R[3 * a] * x[0] + R[3 * a + 1] * x[1] + R[3 * a + 2] * x[2];
            Rw[3 * a + 1] = R[3 * a] * y[0] + R[3 * a + 1] * y[1] + R[3 * a + 2] * y[2];
            Rw[3 * a + 2] = R[3 * a] * z[0] + R[3 * a + 1] * z[1] + R[3 * a + 2] * z[2];
        }
        double dist = sqrt((ct[0] - Ce[0]) * (ct[0] - Ce[0]) + (ct[1] - Ce[1]) * (ct[1] - Ce[1]) +
                           (ct[2] - Ce[2]) * (ct[2] - Ce[2]));
        double ang = rot_angle_deg(Rw, est.cam[c].R);
        printf("# --world board:%d: camera %d at (%.2f, %.2f, %.2f) mm, true (%.2f, %.2f, %.2f): %.3f mm, "
               "%.4f deg\n", VIEW, c, Ce[0], Ce[1], Ce[2], ct[0], ct[1], ct[2], dist, ang);
        assert_true(dist < 1.0);
        assert_true(ang < 0.1);
    }
    snprintf(cmd, sizeof cmd, "'%s' --board " BOARD " --world board:99 --out '%s/x.yaml' '%s/cam0.y4m' "
             "'%s/cam1.y4m' 2>&1", CALIB_BIN, dir, dir, dir);
    assert_int_equal(run(cmd, out, sizeof out), 1);
    assert_non_null(strstr(out, "--world board:99"));
}

/* Image folders give the same calibration as the videos they came from. */
static void test_image_folders(void **state)
{
    (void)state;
    const char *dir = rig_dir();
    assert_non_null(dir);
    char path[1024], cmd[4096], a[8192], b[8192];
    for (int c = 0; c < 2; c++) {
        snprintf(path, sizeof path, "%s/cam%d.y4m", dir, c);
        sh_y4m_reader *rd;
        assert_int_equal(sh_y4m_reader_open(path, &rd), SH_OK);
        const sh_y4m_header *h = sh_y4m_reader_header(rd);
        sh_image img, grey;
        assert_int_equal(sh_image_create(&img, h->format, h->width, h->height), SH_OK);
        snprintf(path, sizeof path, "%s/png%d", dir, c);
        assert_int_equal(mkdir(path, 0777), 0);
        for (int f = 0; sh_y4m_reader_read(rd, &img) == SH_OK; f++) {
            /* the luma plane alone: what the tool reads from the video */
            assert_int_equal(sh_image_wrap(&grey, SH_PIX_GRAY8, img.width, img.height, img.plane[0].data), SH_OK);
            grey.plane[0].stride = img.plane[0].stride;
            snprintf(path, sizeof path, "%s/png%d/view%02d.png", dir, c, f);
            assert_int_equal(sh_png_write(path, &grey, 0), SH_OK);
        }
        sh_image_destroy(&img);
        sh_y4m_reader_close(rd);
    }
    snprintf(cmd, sizeof cmd, "'%s' --board " BOARD " --out '%s/v.yaml' '%s/cam0.y4m' '%s/cam1.y4m'", CALIB_BIN,
             dir, dir, dir);
    assert_int_equal(run(cmd, a, sizeof a), 0);
    snprintf(cmd, sizeof cmd, "'%s' --board " BOARD " --out '%s/p.yaml' '%s/png0' '%s/png1'", CALIB_BIN, dir, dir,
             dir);
    assert_int_equal(run(cmd, b, sizeof b), 0);
    /* the same numbers except the file name on the last line */
    char *la = strstr(a, "wrote"), *lb = strstr(b, "wrote");
    assert_non_null(la);
    assert_non_null(lb);
    *la = *lb = '\0';
    assert_string_equal(a, b);
}

static void test_errors(void **state)
{
    (void)state;
    const char *dir = rig_dir();
    assert_non_null(dir);
    char cmd[4096], out[8192];
    /* a video without the board: exit 1 naming the camera and the count (a board of another
     * size would do too, but OpenCV takes seconds per frame to give up on it) */
    char grey_path[1024];
    snprintf(grey_path, sizeof grey_path, "%s/grey.y4m", dir);
    sh_y4m_header h;
    memset(&h, 0, sizeof h);
    h.width = 320, h.height = 240, h.format = SH_PIX_GRAY8, h.fps_num = 25, h.fps_den = 1;
    sh_y4m_writer *w;
    sh_image img;
    assert_int_equal(sh_y4m_writer_open(grey_path, &h, &w), SH_OK);
    assert_int_equal(sh_image_create(&img, SH_PIX_GRAY8, 320, 240), SH_OK);
    memset(img.plane[0].data, 128, (size_t)img.plane[0].stride * 240);
    for (int f = 0; f < 3; f++) assert_int_equal(sh_y4m_writer_write(w, &img), SH_OK);
    sh_image_destroy(&img);
    assert_int_equal(sh_y4m_writer_close(w), SH_OK);
    snprintf(cmd, sizeof cmd, "'%s' --board " BOARD " --out '%s/x.yaml' '%s' '%s' 2>&1", CALIB_BIN, dir, grey_path,
             grey_path);
    assert_int_equal(run(cmd, out, sizeof out), 1);
    assert_non_null(strstr(out, "camera 0"));
    assert_non_null(strstr(out, "found in 0 of 3 frames"));
    /* cameras of different image sizes */
    snprintf(cmd, sizeof cmd, "'%s' --board " BOARD " --out '%s/x.yaml' '%s/cam0.y4m' '%s' 2>&1", CALIB_BIN, dir,
             dir, grey_path);
    assert_int_equal(run(cmd, out, sizeof out), 1);
    assert_non_null(strstr(out, "one image size for the whole rig"));
    /* more views required than there are */
    snprintf(cmd, sizeof cmd, "'%s' --board " BOARD " --every 5 --min-views 5 --out '%s/x.yaml' '%s/cam0.y4m' "
             "'%s/cam1.y4m' 2>&1", CALIB_BIN, dir, dir, dir);
    assert_int_equal(run(cmd, out, sizeof out), 1);
    assert_non_null(strstr(out, "found in 4 of 4 frames, at least 5 needed"));
    /* an input that is not there */
    snprintf(cmd, sizeof cmd, "'%s' --board " BOARD " --out '%s/x.yaml' '%s/cam0.y4m' /nonexistent 2>&1",
             CALIB_BIN, dir, dir);
    assert_int_equal(run(cmd, out, sizeof out), 1);
    assert_non_null(strstr(out, "/nonexistent"));
    struct stat st;
    char path[1024];
    snprintf(path, sizeof path, "%s/x.yaml", dir);
    assert_int_not_equal(stat(path, &st), 0); /* nothing written on failure */
    /* the command line */
    static const char *bad[] = {
        "--out x.yaml a b",                                      /* no --board */
        "--board " BOARD " a b",                                 /* no --out */
        "--board " BOARD " --out x.yaml a",                      /* one camera */
        "--board " BOARD " --out x.yaml a b c d",                /* four */
        "--board checkerboard:9x7:8 --out x.yaml a b",           /* symmetric board */
        "--board checkerboard:9x6 --out x.yaml a b",             /* no square size */
        "--board chessboard:9x6:8 --out x.yaml a b",
        "--board " BOARD " --every 0 --out x.yaml a b",
        "--board " BOARD " --min-views 2 --out x.yaml a b",
        "--board " BOARD " --bogus --out x.yaml a b",
        "--board " BOARD " --world board:x --out x.yaml a b",
        "--board " BOARD " --world camera1 --out x.yaml a b",
    };
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        snprintf(cmd, sizeof cmd, "'%s' %s 2>/dev/null", CALIB_BIN, bad[i]);
        if (run(cmd, NULL, 0) != 2) fail_msg("accepted: %s", bad[i]);
    }
    snprintf(cmd, sizeof cmd, "'%s' --help", CALIB_BIN);
    assert_int_equal(run(cmd, out, sizeof out), 0);
    assert_non_null(strstr(out, "--board"));
    assert_non_null(strstr(out, "Camera 0 is the world frame"));
}

static int teardown_all(void **state)
{
    (void)state;
    pt_cleanup();
    return 0;
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_recovers_the_rig),
        cmocka_unit_test(test_world_on_board),
        cmocka_unit_test(test_image_folders),
        cmocka_unit_test(test_errors),
    };
    return cmocka_run_group_tests(tests, NULL, teardown_all);
}
