/* Calibrations checked at load (calib.h): a plausible two-camera rig (a 90 mm baseline 50 cm
 * from the scene, 23 degrees across, as our phantom's) loads; each absurd field is refused with
 * the file, the camera and the field named: fx = 1e308, t = 1e300, the same camera twice, a
 * non-orthonormal R, a principal point outside the image, a K that is no camera matrix, a fold
 * in the distortion, huge tangential terms. A configured rig scale moves the |t| bound. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <cmocka.h>

#include <math.h>
#include <stdio.h>
#include <string.h>
#include <unistd.h>

#include "stillheart/calib.h"

static char path[64];

/* Camera 0 looks down -Z from (-45, 0, 500) and camera 1 from (45, 0, 500), both turned by pi
 * about x (R = diag(1, -1, -1)), so t = -R C; fx 787.5 over 320 pixels is 2 atan(160 / 787.5) =
 * 22.97 degrees. */
static void good(sh_calib *c)
{
    memset(c, 0, sizeof *c);
    c->num_cameras = 2;
    c->width = 320;
    c->height = 180;
    for (int i = 0; i < 2; i++) {
        sh_calib_camera *k = &c->cam[i];
        double K[9] = {787.5, 0, 159.5 + i, 0, 787.5, 89.5, 0, 0, 1}, R[9] = {1, 0, 0, 0, -1, 0, 0, 0, -1};
        memcpy(k->K, K, sizeof K);
        memcpy(k->R, R, sizeof R);
        k->t[0] = i ? -45 : 45;
        k->t[1] = 0;
        k->t[2] = 500;
        k->dist[0] = -0.1;
        k->dist[1] = 0.05;
        k->num_dist = 5;
    }
    sh_calib_compute_p(c);
}

static sh_status load(const sh_calib *c, const sh_calib_limits *lim)
{
    assert_int_equal(sh_calib_write(path, c), SH_OK);
    sh_calib back;
    return sh_calib_load(path, lim, &back);
}

static void expect_refused(const sh_calib *c, const char *field, const char *why)
{
    if (load(c, NULL) != SH_EFORMAT) fail_msg("accepted, expected a refusal with '%s'", field);
    const char *msg = sh_error_message();
    if (!strstr(msg, path) || !strstr(msg, field) || !strstr(msg, why)) {
        print_error("'%s' lacks '%s', '%s' or '%s'\n", msg, path, field, why);
        fail();
    }
}

static void test_good_rig_loads(void **state)
{
    (void)state;
    sh_calib c;
    good(&c);
    assert_int_equal(load(&c, NULL), SH_OK);
    sh_calib_margins m;
    assert_int_equal(sh_calib_check(&c, path, NULL, &m), SH_OK);
    assert_true(fabs(m.fov_deg[1] - 2 * atan(160 / 787.5) * 180 / M_PI) < 1e-9);
    assert_true(fabs(m.fov_deg[0] - 2 * atan(90 / 787.5) * 180 / M_PI) < 1e-9);
    assert_true(fabs(m.t_max - sqrt(45 * 45 + 500 * 500)) < 1e-9);
    assert_true(fabs(m.separation - 90 / sqrt(45 * 45 + 500 * 500)) < 1e-12); /* centres 90 apart */
    assert_true(fabs(m.pp_edge_px - 90) < 1e-12);                              /* cy 89.5 of 180 */
    assert_true(m.rotation_err == 0);
}

static void test_absurd_fields_refused(void **state)
{
    (void)state;
    sh_calib c;
    good(&c);
    c.cam[0].K[0] = 1e308;
    expect_refused(&c, "camera 0: K_0: fx = 1e+308", "field of view of 0 degrees");
    good(&c);
    c.cam[1].K[4] = 1.0;
    expect_refused(&c, "camera 1: K_1: fy = 1", "(allowed 1 to 170)");
    good(&c);
    c.cam[1].K[4] = -787.5;
    expect_refused(&c, "camera 1: K_1: fy = -787.5", "field of view");
    good(&c);
    c.cam[1].t[2] = 1e300;
    expect_refused(&c, "camera 1: t_1: |t| = 1e+300", "beyond the rig scale 10000");
    good(&c);
    c.cam[1] = c.cam[0];
    expect_refused(&c, "camera 1: R_1, t_1: at the pose of camera 0", "centres 0 apart");
    good(&c);
    c.cam[1].R[0] = 1.001; /* a stretch: R R^T - I has 0.002001 on the diagonal */
    expect_refused(&c, "camera 1: R_1 is not a rotation", "off by 0.002");
    good(&c);
    c.cam[0].R[0] = -1; /* diag(-1, -1, -1): a reflection, orthogonal with det -1 */
    expect_refused(&c, "camera 0: R_0 is not a rotation", "off by 2");
    good(&c);
    c.cam[0].K[2] = 320;
    expect_refused(&c, "camera 0: K_0: the principal point cx = 320", "outside the image (-0.5 to 319.5)");
    good(&c);
    c.cam[1].K[5] = -1;
    expect_refused(&c, "camera 1: K_1: the principal point cy = -1", "outside");
    good(&c);
    c.cam[0].K[6] = 0.5;
    expect_refused(&c, "camera 0: K_0 is not a camera matrix", "last row 0 0 1");
    good(&c);
    c.cam[1].dist[0] = -9.2; /* k1 r^2 = -0.5 at the corner: r (1 + k1 r^2) turns back at r^2 = 1/27.6 */
    expect_refused(&c, "camera 1: dist_1 folds the image", "corners");
    good(&c);
    c.cam[1].dist[0] = 200; /* a factor 1 + 200 * 0.0543 = 11.9 at the corner */
    expect_refused(&c, "camera 1: dist_1: the radial factor runs from 1", "(allowed 0.2 to 5)");
    good(&c);
    c.cam[0].dist[3] = 0.9;
    expect_refused(&c, "camera 0: dist_0: tangential terms", "p2 = 0.9");
}

/* A configured rig scale is the |t| bound: 600 passes the 502.0 mm of the good rig, 500 does not. */
static void test_rig_scale(void **state)
{
    (void)state;
    sh_calib c;
    good(&c);
    sh_calib_limits lim;
    sh_calib_limits_default(&lim);
    lim.rig_scale = 600;
    assert_int_equal(load(&c, &lim), SH_OK);
    lim.rig_scale = 500;
    assert_int_equal(load(&c, &lim), SH_EFORMAT);
    assert_non_null(strstr(sh_error_message(), "camera 0: t_0: |t| = 502.02"));
    assert_non_null(strstr(sh_error_message(), "rig scale 500"));
}

int main(void)
{
    snprintf(path, sizeof path, "/tmp/sh-test-calib-%d.yaml", (int)getpid());
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_good_rig_loads),
        cmocka_unit_test(test_absurd_fields_refused),
        cmocka_unit_test(test_rig_scale),
    };
    int rc = cmocka_run_group_tests(tests, NULL, NULL);
    unlink(path);
    return rc;
}
