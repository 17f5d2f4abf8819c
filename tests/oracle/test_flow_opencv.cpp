// src/flow against OpenCV 4's cv::calcOpticalFlowPyrLK and cv::goodFeaturesToTrack, the oracle
// and the peer that issue 19 names, on the synthetic sequence (tools/synth): a smooth texture
// under a known non-affine deformation, at the sizes and motions of a beating heart. Host builds
// only (the aarch64 build has no OpenCV); the unit test test_flow checks the same code against
// closed forms on every architecture.
#include <opencv2/imgproc.hpp>
#include <opencv2/video/tracking.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <vector>

extern "C" {
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>

#include <cmocka.h>

#include "stillheart/flow.h"
#include "synth.h"
}

// a failed check names what differed before cmocka ends the case
#define CHECK(cond, ...)                                                                           \
    do {                                                                                           \
        if (!(cond)) {                                                                             \
            print_message(__VA_ARGS__);                                                            \
            print_message("\n");                                                                   \
        }                                                                                          \
        assert_true(cond);                                                                         \
    } while (0)

static cv::Mat render(const synth_motion &m, double t)
{
    sh_image img;
    assert_int_equal(sh_image_create(&img, SH_PIX_GRAY8, m.width, m.height), SH_OK);
    synth_render(&m, t, &img);
    cv::Mat out(m.height, m.width, CV_8UC1);
    for (int y = 0; y < m.height; y++)
        std::copy(img.plane[0].data + (size_t)y * img.plane[0].stride,
                  img.plane[0].data + (size_t)y * img.plane[0].stride + m.width, out.ptr(y));
    sh_image_destroy(&img);
    return out;
}

static sh_plane view(const cv::Mat &m)
{
    sh_plane p;
    p.data = const_cast<uint8_t *>(m.ptr());
    p.width = m.cols;
    p.height = m.rows;
    p.stride = (int)m.step;
    return p;
}

// Points followed from frame 0 to frame t by both trackers: the same status for nearly all,
// and the same position, within issue 19's 0.05 px, for every point both keep.
static void compare_tracking(int w, int h, double amplitude, double t, int levels)
{
    synth_motion m = {w, h, amplitude};
    cv::Mat f0 = render(m, 0.0), f1 = render(m, t);
    sh_flow_corner_params cp;
    sh_flow_corner_params_default(&cp);
    cp.max_points = 300;
    cp.min_distance = 7;
    std::vector<float> xy(2 * cp.max_points);
    int n = 0;
    sh_plane v0 = view(f0), v1 = view(f1);
    assert_int_equal(sh_flow_corners(&v0, nullptr, &cp, xy.data(), &n), SH_OK);
    xy.resize(2 * n);
    // and a grid, so that weak and edge points are compared too, not only the best corners
    for (int y = 3; y < h; y += h / 9)
        for (int x = 2; x < w; x += w / 11) {
            xy.push_back((float)x + 0.25f);
            xy.push_back((float)y + 0.5f);
        }
    n = (int)xy.size() / 2;
    sh_flow_params prm;
    sh_flow_params_default(&prm);
    prm.levels = levels;
    sh_flow_pyramid *a = nullptr, *b = nullptr;
    assert_int_equal(sh_flow_pyramid_create(w, h, &prm, &a), SH_OK);
    assert_int_equal(sh_flow_pyramid_create(w, h, &prm, &b), SH_OK);
    assert_int_equal(sh_flow_pyramid_build(a, &v0, 1), SH_OK);
    assert_int_equal(sh_flow_pyramid_build(b, &v1, 0), SH_OK);
    std::vector<float> out(2 * n), err(n);
    std::vector<uint8_t> st(n);
    assert_int_equal(
        sh_flow_track(&prm, a, b, n, xy.data(), nullptr, out.data(), st.data(), err.data()), SH_OK);
    std::vector<cv::Point2f> p0(n), p1;
    for (int i = 0; i < n; i++) p0[i] = cv::Point2f(xy[2 * i], xy[2 * i + 1]);
    std::vector<uchar> cst;
    std::vector<float> cerr;
    cv::calcOpticalFlowPyrLK(f0, f1, p0, p1, cst, cerr, cv::Size(prm.win, prm.win), levels,
                             cv::TermCriteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS,
                                              prm.max_iter, prm.eps),
                             0, (double)prm.min_eig);
    int both = 0, differ = 0;
    double worst = 0, worst_err = 0, truth_sum = 0;
    int worst_at = -1;
    for (int i = 0; i < n; i++) {
        if ((st[i] == SH_FLOW_OK) != (cst[i] != 0)) {
            differ++;
            continue;
        }
        if (!cst[i]) continue;
        both++;
        double d = std::hypot(out[2 * i] - p1[i].x, out[2 * i + 1] - p1[i].y);
        if (d > worst) {
            worst = d;
            worst_at = i;
        }
        worst_err = std::max(worst_err, (double)std::fabs(err[i] - cerr[i]));
        double fx, fy;
        synth_forward(&m, t, xy[2 * i], xy[2 * i + 1], &fx, &fy);
        truth_sum += std::hypot(p1[i].x - fx, p1[i].y - fy);
    }
    print_message("%dx%d, amplitude %.0f px, t %.2f, %d levels: %d points, %d kept by both, %d "
                "by one only; largest difference %.5f px (point %d), error measure %.5f; "
                "OpenCV's mean distance from the truth %.4f px\n",
                w, h, amplitude, t, levels, n, both, differ, worst, worst_at, worst_err,
                both ? truth_sum / both : 0.0);
    CHECK(worst <= 0.05, "positions differ by %.4f px at point %d (%.2f, %.2f)", worst, worst_at,
          worst_at >= 0 ? xy[2 * worst_at] : 0.f, worst_at >= 0 ? xy[2 * worst_at + 1] : 0.f);
    CHECK(differ * 100 <= n, "status differs for %d of %d points", differ, n);
    CHECK(both * 10 >= n * 8, "only %d of %d points kept by both", both, n);
    sh_flow_pyramid_destroy(a);
    sh_flow_pyramid_destroy(b);
}

// The corners: OpenCV's choice from the same frame and parameters, nearly point for point.
static void compare_corners(int w, int h)
{
    synth_motion m = {w, h, 5.0};
    cv::Mat f0 = render(m, 0.3);
    sh_flow_corner_params cp;
    sh_flow_corner_params_default(&cp);
    cp.max_points = 400;
    cp.min_distance = 9;
    cp.quality = 0.02;
    std::vector<float> xy(2 * cp.max_points);
    int n = 0;
    sh_plane v = view(f0);
    assert_int_equal(sh_flow_corners(&v, nullptr, &cp, xy.data(), &n), SH_OK);
    std::vector<cv::Point2f> cv_pts;
    cv::goodFeaturesToTrack(f0, cv_pts, cp.max_points, cp.quality, cp.min_distance, cv::noArray(),
                            cp.block, false);
    int same = 0;
    for (int i = 0; i < n; i++)
        for (const cv::Point2f &q : cv_pts)
            if (std::fabs(q.x - xy[2 * i]) < 0.5f && std::fabs(q.y - xy[2 * i + 1]) < 0.5f) {
                same++;
                break;
            }
    print_message("corners %dx%d: ours %d, OpenCV %zu, the same pixel %d\n", w, h, n, cv_pts.size(),
                same);
    CHECK(std::abs(n - (int)cv_pts.size()) * 50 <= (int)cv_pts.size(), "counts %d and %zu", n,
          cv_pts.size());
    CHECK(same * 100 >= n * 95, "only %d of %d corners on OpenCV's pixels", same, n);
}

static void test_corners_match_opencv(void **state)
{
    (void)state;
    compare_corners(640, 480);
}

static void test_tracking_matches_opencv(void **state)
{
    (void)state;
    compare_tracking(640, 480, 6.0, 0.05, 3);  // a small step: frame to frame
    compare_tracking(640, 480, 6.0, 0.25, 3);  // the reference to the beat's peak
    compare_tracking(640, 480, 20.0, 0.25, 3); // a fast motion, beyond one window
    compare_tracking(640, 480, 20.0, 0.25, 0); // the base level alone
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_corners_match_opencv),
        cmocka_unit_test(test_tracking_matches_opencv),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
