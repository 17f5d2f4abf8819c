// The calibration file against OpenCV, the library its readers will use: cv::FileStorage reads
// calibration.yaml, and cv::projectPoints with its K, dist, R, t puts every ground-truth 3D
// point of markers.csv on the CSV's pixel within 0.01 px (lens distortion included).
#include <cmath>
#include <cstdarg>
#include <cstddef>
#include <csetjmp>
#include <cstdio>
#include <string>
#include <vector>

#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>

#include "../phantom.h"
#include "phantom_testutil.h"

// last: cmocka's fail() macro would break std::basic_ios::fail in the C++ headers
extern "C" {
#include <cmocka.h>
}

static void check_dir(const char *dir, int cameras)
{
    cv::FileStorage fs(std::string(dir) + "/calibration.yaml", cv::FileStorage::READ);
    assert_true(fs.isOpened());
    assert_int_equal((int)fs["num_cameras"], cameras);
    phantom_csv csv;
    assert_int_equal(phantom_csv_read((std::string(dir) + "/markers.csv").c_str(), &csv), SH_OK);
    double worst = 0;
    int n = 0;
    for (int c = 0; c < cameras; c++) {
        cv::Mat K, dist, R, t, P, rvec;
        fs["K_" + std::to_string(c)] >> K;
        fs["dist_" + std::to_string(c)] >> dist;
        fs["R_" + std::to_string(c)] >> R;
        fs["t_" + std::to_string(c)] >> t;
        fs["P_" + std::to_string(c)] >> P;
        assert_true(K.rows == 3 && K.cols == 3 && R.rows == 3 && t.total() == 3 && P.rows == 3 && P.cols == 4);
        assert_int_equal((int)dist.total(), 5);
        // P = K [R | t]
        cv::Mat Rt;
        cv::hconcat(R, t, Rt);
        assert_true(cv::norm(P - K * Rt, cv::NORM_INF) < 1e-9 * cv::norm(P, cv::NORM_INF));
        cv::Rodrigues(R, rvec);
        std::vector<cv::Point3d> X;
        std::vector<cv::Point2d> want;
        for (int i = 0; i < csv.count; i++)
            if (csv.rows[i].camera == c) {
                X.emplace_back(csv.rows[i].X, csv.rows[i].Y, csv.rows[i].Z);
                want.emplace_back(csv.rows[i].x, csv.rows[i].y);
            }
        std::vector<cv::Point2d> got;
        cv::projectPoints(X, rvec, t, K, dist, got);
        for (size_t i = 0; i < got.size(); i++) worst = std::fmax(worst, cv::norm(got[i] - want[i]));
        n += (int)got.size();
    }
    std::printf("# %s: %d points, worst |projectPoints - CSV| = %.2e px\n", dir, n, worst);
    assert_true(n > 0);
    assert_true(worst < 0.01);
    phantom_csv_free(&csv);
}

static void test_projectpoints_matches_csv(void **state)
{
    (void)state;
    const char *dir = pt_render(0, "--preset exvivo --frames 4 --fps 3 --cameras 3 --width 640 --height 360 "
                                   "--seed 4 --distortion -0.25,0.4,0.0012,-0.0007,-0.3");
    assert_non_null(dir);
    check_dir(dir, 3);
    dir = pt_render(1, "--preset invivo --frames 3 --cameras 1 --width 480 --height 270 --seed 9");
    assert_non_null(dir);
    check_dir(dir, 1);
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
        cmocka_unit_test_teardown(test_projectpoints_matches_csv, teardown),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
