/* libFuzzer: arbitrary bytes as a calibration YAML. A refusal names the file; anything accepted
 * has 1..SH_CALIB_MAX_CAMERAS cameras with finite K, R, t and P = K [R | t] when the file gave
 * no P. Then the load checks (sh_calib_check): a refusal names the file and a camera, and what
 * passes keeps within the default limits. */
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "stillheart/calib.h"

static void check(int ok)
{
    if (!ok) abort();
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    sh_calib c;
    if (sh_calib_parse((const char *)data, size, "fuzz.yaml", &c) != SH_OK) {
        check(strncmp(sh_error_message(), "fuzz.yaml", 9) == 0);
        return 0;
    }
    check(c.num_cameras >= 1 && c.num_cameras <= SH_CALIB_MAX_CAMERAS);
    check(c.width >= 1 && c.height >= 1);
    for (int i = 0; i < c.num_cameras; i++) {
        const sh_calib_camera *k = &c.cam[i];
        check(k->num_dist == 0 || k->num_dist == 4 || k->num_dist == 5 || k->num_dist == 8 ||
              k->num_dist == 12 || k->num_dist == 14);
        for (int j = 0; j < 9; j++) check(isfinite(k->K[j]) && isfinite(k->R[j]));
        for (int j = 0; j < 3; j++) check(isfinite(k->t[j]));
        for (int j = k->num_dist; j < SH_CALIB_MAX_DIST; j++) check(k->dist[j] == 0);
    }
    sh_calib_limits l;
    sh_calib_limits_default(&l);
    sh_calib_margins m;
    if (sh_calib_check(&c, "fuzz.yaml", NULL, &m) != SH_OK) {
        check(strncmp(sh_error_message(), "fuzz.yaml: camera ", 18) == 0);
        return 0;
    }
    check(m.fov_deg[0] >= l.fov_min_deg && m.fov_deg[1] <= l.fov_max_deg && m.pp_edge_px >= 0);
    check(m.t_max <= l.rig_scale && m.rotation_err <= l.rotation_tol && m.separation > l.same_pose);
    check(m.dist_factor[0] >= l.dist_factor_min && m.dist_factor[1] <= l.dist_factor_max && m.dist_slope > 0);
    return 0;
}
