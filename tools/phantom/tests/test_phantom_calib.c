/* The phantom's calibrations pass the load checks of calib.h, with margins printed: both presets,
 * one to three cameras, the sizes our tests render at, and every lens distortion a test of ours
 * renders with (none, and the k1 k2 p1 p2 k3 lists of the render, tracking, warp3d and
 * calibration tests). Each goes through the file as stillheart-render writes it and is loaded
 * as the daemon loads it (sh_calib_read). */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <cmocka.h>

#include <math.h>
#include <stdio.h>
#include <string.h>
#include <unistd.h>

#include "../phantom.h"

static const double dists[][5] = {
    {0, 0, 0, 0, 0},
    {-0.08, 0.12, 0.0004, -0.0003, 0},
    {-0.2, 0.2, 0, 0, 0},
    {-0.2, 0.3, 0.001, 0.0005, -0.1},
    {-0.25, 0.4, 0.0012, -0.0007, -0.3},
    {-0.35, 0.9, 0.002, -0.0015, 0},
};

static void test_phantom_calibrations_load(void **state)
{
    (void)state;
    static const char *const presets[] = {"exvivo", "invivo"};
    static const int sizes[][2] = {{1920, 1080}, {640, 360}, {320, 180}};
    char path[64];
    snprintf(path, sizeof path, "/tmp/sh-test-phantom-calib-%d.yaml", (int)getpid());
    sh_calib_limits lim;
    sh_calib_limits_default(&lim);
    sh_calib_margins all = {{INFINITY, -INFINITY}, INFINITY, 0, 0, INFINITY, {INFINITY, -INFINITY}, INFINITY};
    int n = 0;
    for (int p = 0; p < 2; p++)
        for (int cams = 1; cams <= 3; cams++)
            for (int s = 0; s < 3; s++)
                for (size_t d = 0; d < sizeof dists / sizeof dists[0]; d++) {
                    phantom_options o;
                    phantom_options_default(&o);
                    o.preset = presets[p];
                    o.cameras = cams;
                    o.width = sizes[s][0];
                    o.height = sizes[s][1];
                    o.frames = 2;
                    o.dist = d ? dists[d] : NULL;
                    phantom_model m;
                    assert_int_equal(phantom_model_build(&o, &m), SH_OK);
                    sh_calib cal, back;
                    phantom_calibration(&m, &cal);
                    assert_int_equal(sh_calib_write(path, &cal), SH_OK);
                    if (sh_calib_read(path, &back) != SH_OK) fail_msg("%s", sh_error_message());
                    sh_calib_margins mg;
                    assert_int_equal(sh_calib_check(&back, path, NULL, &mg), SH_OK);
                    all.fov_deg[0] = fmin(all.fov_deg[0], mg.fov_deg[0]);
                    all.fov_deg[1] = fmax(all.fov_deg[1], mg.fov_deg[1]);
                    all.pp_edge_px = fmin(all.pp_edge_px, mg.pp_edge_px);
                    all.t_max = fmax(all.t_max, mg.t_max);
                    all.rotation_err = fmax(all.rotation_err, mg.rotation_err);
                    all.separation = fmin(all.separation, mg.separation);
                    all.dist_factor[0] = fmin(all.dist_factor[0], mg.dist_factor[0]);
                    all.dist_factor[1] = fmax(all.dist_factor[1], mg.dist_factor[1]);
                    all.dist_slope = fmin(all.dist_slope, mg.dist_slope);
                    n++;
                }
    unlink(path);
    print_message("%d phantom calibrations loaded. Margins (value / limit): field of view %.2f..%.2f deg / %g..%g; "
                  "principal point %.1f px inside the edge / 0; |t| %.1f / %g; rotation error %.2g / %g; camera "
                  "centres %.3g of their distance apart / %g; radial factor %.3f..%.3f / %g..%g; smallest slope of "
                  "the distorted radius %.3f / > 0\n",
                  n, all.fov_deg[0], all.fov_deg[1], lim.fov_min_deg, lim.fov_max_deg, all.pp_edge_px, all.t_max,
                  lim.rig_scale, all.rotation_err, lim.rotation_tol, all.separation, lim.same_pose, all.dist_factor[0],
                  all.dist_factor[1], lim.dist_factor_min, lim.dist_factor_max, all.dist_slope);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_phantom_calibrations_load),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
