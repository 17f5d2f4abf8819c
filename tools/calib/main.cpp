// stillheart-calib: calibrates a rig of 2-3 synchronized cameras from views of a checkerboard
// with OpenCV (Zhang's method, as the paper cites): corners by cv::findChessboardCorners and
// cv::cornerSubPix, each camera's K and distortion by cv::calibrateCamera, then each camera's
// pose relative to camera 0 by cv::stereoCalibrate with the intrinsics fixed. Camera 0 is the
// world frame (R_0 = I, t_0 = 0, millimetres as the board's squares). Writes the calibration
// YAML of include/stillheart/calib.h. OpenCV stays in this tool: the daemon never links it.
#include <getopt.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <stdexcept>
#include <string>
#include <vector>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include "input.h"

extern "C" {
#include "stillheart/calib.h"
#include "stillheart/cli.h"
#include "stillheart/log.h"
}

namespace {

void usage(FILE *f)
{
    std::fprintf(f,
"usage: stillheart-calib --board checkerboard:COLSxROWS:SQUARE_MM --out CALIB.yaml [options]\n"
"                        CAM0 CAM1 [CAM2]\n"
"Calibrates two or three synchronized cameras from views of a planar checkerboard: each camera's\n"
"intrinsics and lens distortion (cv::calibrateCamera), then the rig's extrinsics against camera 0\n"
"(cv::stereoCalibrate, intrinsics fixed). Camera 0 is the world frame: R_0 = I, t_0 = 0; t_i\n"
"is in the units of SQUARE_MM (millimetres). --world puts the world on the board instead.\n"
"\n"
"  CAMi               camera i's views: a Y4M video, or a folder of PNG / JPEG images taken\n"
"                     in name order. Frame n of every camera must be taken at the same time\n"
"                     (a triggered rig, or a board held still); the luma plane is used\n"
"  --board SPEC       checkerboard:COLSxROWS:SQUARE_MM: COLS x ROWS inner corners (OpenCV's\n"
"                     patternSize: a 10 x 7 squares board has 9x6), one count odd and one even\n"
"                     so that the board's orientation shows (the square beyond the first\n"
"                     corner is black), squares of SQUARE_MM\n"
"  --out FILE         the calibration YAML (OpenCV FileStorage: num_cameras, image_width,\n"
"                     image_height, K_i, dist_i (k1 k2 p1 p2 k3), R_i, t_i, P_i = K_i [R_i|t_i])\n"
"  --every N          use every N-th frame (default 1)\n"
"  --min-views N      fewest views with the board per camera and per camera pair (default 8)\n"
"  --k3               estimate k3 too (default: k1 k2 p1 p2 with k3 = 0; a narrow lens cannot\n"
"                     tell k3 from k1 and k2, and a free k3 costs focal-length accuracy)\n"
"  --no-tangential    p1 = p2 = 0 (a narrow lens cannot tell a small decentring from a shift of\n"
"                     the principal point: without them the principal point is better defined)\n"
"  --world W          the world frame of the file: camera0 (default), or board:N, the board as\n"
"                     camera 0 sees it in frame N (0-based input frame): origin at its first\n"
"                     inner corner, x along the first row (corner 0 to 1), z out of the printed\n"
"                     face towards the cameras, y = z cross x (a board lying on the table gives\n"
"                     z up, as the renderer's world)\n"
"  --corners-out FILE every corner found, as CSV frame,camera,corner,x,y (OpenCV pixels,\n"
"                     corner r * COLS + c is board point (c, r) * SQUARE_MM)\n"
SH_CLI_USAGE
"\n"
"Prints per camera the views used, K, distortion and reprojection RMS (px), and per camera\n"
"pair the views used, stereo RMS, baseline and rotation. Exit status: 0 written, 1 failed\n"
"(the board not found in enough views, unreadable input), 2 bad command line.\n");
}

struct board_spec {
    int cols = 0, rows = 0;
    double square = 0;
};

bool parse_board(const char *s, board_spec &b)
{
    char tail;
    if (std::sscanf(s, "checkerboard:%dx%d:%lf%c", &b.cols, &b.rows, &b.square, &tail) != 3) return false;
    return b.cols >= 3 && b.rows >= 3 && b.cols <= 40 && b.rows <= 40 && (b.cols + b.rows) % 2 == 1 &&
           b.square > 0 && std::isfinite(b.square);
}

// Brightness around p (a 3 x 3 px patch, bilinear).
double patch(const cv::Mat &img, cv::Point2f p)
{
    cv::Mat out;
    cv::getRectSubPix(img, cv::Size(3, 3), p, out, CV_32F);
    return cv::mean(out)[0];
}

// Finds the board's inner corners in one view, refined to subpixel, in board order (corner
// r * cols + c). findChessboardCorners may start from either end of the board; the colour of
// the square beyond the first corner (black, see --help) says which, so that every camera of a
// view numbers the corners alike (stereoCalibrate pairs them by index).
bool find_corners(const cv::Mat &grey, const board_spec &b, std::vector<cv::Point2f> &corners)
{
    cv::Size pattern(b.cols, b.rows);
    if (!cv::findChessboardCorners(grey, pattern, corners, cv::CALIB_CB_ADAPTIVE_THRESH | cv::CALIB_CB_NORMALIZE_IMAGE | cv::CALIB_CB_FAST_CHECK))
        return false;
    // the search window must hold one corner only: under half the smallest square side seen
    double side = 1e9;
    for (int r = 0; r < b.rows; r++)
        for (int c = 0; c < b.cols; c++) {
            const cv::Point2f &p = corners[r * b.cols + c];
            if (c + 1 < b.cols) side = std::min(side, (double)cv::norm(corners[r * b.cols + c + 1] - p));
            if (r + 1 < b.rows) side = std::min(side, (double)cv::norm(corners[(r + 1) * b.cols + c] - p));
        }
    int half = std::max(2, std::min(15, (int)(0.4 * side)));
    cv::cornerSubPix(grey, corners, cv::Size(half, half), cv::Size(-1, -1),
                     cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 100, 1e-4));
    cv::Point2f c0 = corners[0], step_c = corners[1] - c0, step_r = corners[b.cols] - c0;
    // diagonal squares share a colour: compare with the square beside the outer one
    double outer = patch(grey, c0 - 0.5f * (step_c + step_r)), beside = patch(grey, c0 + 0.5f * (step_c - step_r));
    if (outer > beside) std::reverse(corners.begin(), corners.end());
    return true;
}

struct camera_views {
    std::vector<std::vector<cv::Point2f>> pts; // per frame; empty when the board was not found
    int found = 0;
};

std::vector<cv::Point3f> board_points(const board_spec &b)
{
    std::vector<cv::Point3f> X;
    for (int r = 0; r < b.rows; r++)
        for (int c = 0; c < b.cols; c++) X.emplace_back((float)(c * b.square), (float)(r * b.square), 0.f);
    return X;
}

double rotation_deg(const cv::Mat &R)
{
    cv::Mat rv;
    cv::Rodrigues(R, rv);
    return cv::norm(rv) * 180.0 / M_PI;
}

struct options {
    board_spec board;
    const char *out = nullptr, *corners_out = nullptr;
    int every = 1, min_views = 8, k3 = 0, no_tangential = 0, quiet = 0;
    int world_frame = -1; // --world board:N; -1: camera 0
    std::vector<std::string> inputs;
};

// Reads every input frame by frame, finds the board in every --every-th frame of each camera
// (writing --corners-out as it goes) and refuses a rig whose cameras saw it too seldom.
void read_views(const options &o, std::vector<camera_views> &views, cv::Size &size)
{
    size_t n = o.inputs.size();
    std::vector<std::unique_ptr<calib_input>> in;
    for (const auto &p : o.inputs) in.push_back(calib_input_open(p));
    for (size_t c = 1; c < n; c++)
        if (in[c]->count() >= 0 && in[0]->count() >= 0 && in[c]->count() != in[0]->count())
            throw std::runtime_error(in[c]->name() + " holds " + std::to_string(in[c]->count()) + " images, " +
                                     in[0]->name() + " " + std::to_string(in[0]->count()) +
                                     ": the cameras' views must pair up frame by frame");
    int frames = 0;
    FILE *cf = nullptr;
    if (o.corners_out) {
        cf = std::fopen(o.corners_out, "w");
        if (!cf) throw std::runtime_error(std::string(o.corners_out) + ": " + std::strerror(errno));
        std::fprintf(cf, "frame,camera,corner,x,y\n");
    }
    for (int f = 0;; f++) {
        std::vector<cv::Mat> grey(n);
        size_t got = 0;
        for (size_t c = 0; c < n; c++) got += in[c]->next(grey[c]) ? 1 : 0;
        if (got == 0) break;
        if (got != n) {
            if (cf) std::fclose(cf);
            throw std::runtime_error("the inputs end at different frames (near frame " + std::to_string(f) +
                                     "): the cameras' views must pair up frame by frame");
        }
        for (size_t c = 0; c < n; c++) {
            if (size.area() == 0) size = grey[c].size();
            if (grey[c].size() != size) {
                if (cf) std::fclose(cf);
                throw std::runtime_error(in[c]->name() + ": frame " + std::to_string(f) + " is " +
                                         std::to_string(grey[c].cols) + "x" + std::to_string(grey[c].rows) +
                                         ", the first camera's " + std::to_string(size.width) + "x" +
                                         std::to_string(size.height) + ": one image size for the whole rig");
            }
            std::vector<cv::Point2f> pts;
            if (f % o.every == 0 && find_corners(grey[c], o.board, pts)) {
                views[c].found++;
                for (size_t k = 0; cf && k < pts.size(); k++)
                    std::fprintf(cf, "%d,%zu,%zu,%.4f,%.4f\n", f, c, k, pts[k].x, pts[k].y);
            } else {
                pts.clear();
            }
            views[c].pts.push_back(pts);
        }
        frames++;
    }
    if (cf && (std::ferror(cf) | std::fclose(cf)))
        throw std::runtime_error(std::string(o.corners_out) + ": write error");
    int used = (frames + o.every - 1) / o.every;
    for (size_t c = 0; c < n; c++)
        if (views[c].found < o.min_views)
            throw std::runtime_error("camera " + std::to_string(c) + " (" + in[c]->name() + "): the board (" +
                                     std::to_string(o.board.cols) + "x" + std::to_string(o.board.rows) +
                                     " inner corners) found in " + std::to_string(views[c].found) + " of " +
                                     std::to_string(used) + " frames, at least " + std::to_string(o.min_views) +
                                     " needed (--min-views); check --board and that the whole board is in view");
}

// Each camera's intrinsics from its own views (calibrateCamera).
void calibrate_each(const options &o, const std::vector<camera_views> &views, const std::vector<cv::Point3f> &X,
                    cv::Size size, const cv::TermCriteria &crit, std::vector<cv::Mat> &K, std::vector<cv::Mat> &D)
{
    int flags = (o.k3 ? 0 : cv::CALIB_FIX_K3) | (o.no_tangential ? cv::CALIB_ZERO_TANGENT_DIST : 0);
    for (size_t c = 0; c < views.size(); c++) {
        std::vector<std::vector<cv::Point3f>> obj;
        std::vector<std::vector<cv::Point2f>> img;
        for (const auto &p : views[c].pts)
            if (!p.empty()) obj.push_back(X), img.push_back(p);
        std::vector<cv::Mat> rv, tv;
        double rms = cv::calibrateCamera(obj, img, size, K[c], D[c], rv, tv, flags, crit);
        if (!o.quiet) {
            const double *k = K[c].ptr<double>(), *d = D[c].ptr<double>();
            std::printf("camera %zu: %zu views, fx %.3f fy %.3f cx %.3f cy %.3f, dist %.5f %.5f %.6f %.6f %.5f, "
                        "RMS %.4f px\n", c, obj.size(), k[0], k[4], k[2], k[5], d[0], d[1], d[2], d[3], d[4], rms);
        }
    }
}

// Every camera's pose relative to camera 0 from the frames both saw (stereoCalibrate, intrinsics
// fixed); camera 0 is the identity.
void calibrate_pairs(const options &o, const std::vector<camera_views> &views, const std::vector<cv::Point3f> &X,
                     cv::Size size, const cv::TermCriteria &crit, std::vector<cv::Mat> &K, std::vector<cv::Mat> &D,
                     std::vector<cv::Mat> &R, std::vector<cv::Mat> &T)
{
    R[0] = cv::Mat::eye(3, 3, CV_64F);
    T[0] = cv::Mat::zeros(3, 1, CV_64F);
    for (size_t c = 1; c < views.size(); c++) {
        std::vector<std::vector<cv::Point3f>> obj;
        std::vector<std::vector<cv::Point2f>> img0, imgc;
        for (size_t f = 0; f < views[0].pts.size(); f++)
            if (!views[0].pts[f].empty() && !views[c].pts[f].empty())
                obj.push_back(X), img0.push_back(views[0].pts[f]), imgc.push_back(views[c].pts[f]);
        if ((int)obj.size() < o.min_views)
            throw std::runtime_error("cameras 0 and " + std::to_string(c) + " saw the board together in " +
                                     std::to_string(obj.size()) + " frames, at least " +
                                     std::to_string(o.min_views) + " needed (--min-views)");
        cv::Mat E, F;
        double rms = cv::stereoCalibrate(obj, img0, imgc, K[0], D[0], K[c], D[c], size, R[c], T[c], E, F,
                                         cv::CALIB_FIX_INTRINSIC, crit);
        if (!o.quiet)
            std::printf("stereo 0-%zu: %zu views, RMS %.4f px, baseline %.3f mm, rotation %.4f deg, "
                        "t %.3f %.3f %.3f\n", c, obj.size(), rms, cv::norm(T[c]), rotation_deg(R[c]),
                        T[c].at<double>(0), T[c].at<double>(1), T[c].at<double>(2));
    }
}

// --world board:N: the poses moved into the board's frame of frame N.
void to_board_world(const options &o, const std::vector<camera_views> &views, const std::vector<cv::Point3f> &X,
                    const std::vector<cv::Mat> &K, const std::vector<cv::Mat> &D, std::vector<cv::Mat> &R,
                    std::vector<cv::Mat> &T)
{
    // board -> camera 0 by solvePnP with the final intrinsics; F turns the board's z (into
    // the board) round to point out of its face: X_board = F X_world
    if ((size_t)o.world_frame >= views[0].pts.size() || views[0].pts[o.world_frame].empty())
        throw std::runtime_error("--world board:" + std::to_string(o.world_frame) + ": camera 0 did not find the "
                                 "board in that frame");
    cv::Mat rv, tb, Rb;
    cv::solvePnP(X, views[0].pts[o.world_frame], K[0], D[0], rv, tb);
    cv::Rodrigues(rv, Rb);
    cv::Mat F = cv::Mat::diag(cv::Mat(cv::Vec3d(1, -1, -1)));
    for (size_t c = 0; c < views.size(); c++) {
        T[c] = R[c] * tb + T[c];
        R[c] = R[c] * Rb * F;
    }
}

int run(const options &o)
{
    size_t n = o.inputs.size();
    std::vector<camera_views> views(n);
    cv::Size size;
    read_views(o, views, size);

    const std::vector<cv::Point3f> X = board_points(o.board);
    cv::TermCriteria crit(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, 100, 1e-12);
    std::vector<cv::Mat> K(n), D(n), R(n), T(n);
    calibrate_each(o, views, X, size, crit, K, D);
    calibrate_pairs(o, views, X, size, crit, K, D, R, T);
    if (o.world_frame >= 0) to_board_world(o, views, X, K, D, R, T);
    sh_calib cal;
    std::memset(&cal, 0, sizeof cal);
    cal.num_cameras = (int)n;
    cal.width = size.width;
    cal.height = size.height;
    for (size_t c = 0; c < n; c++) {
        sh_calib_camera &k = cal.cam[c];
        std::memcpy(k.K, K[c].ptr<double>(), sizeof k.K);
        k.num_dist = 5;
        for (int i = 0; i < 5; i++) k.dist[i] = D[c].at<double>(i);
        std::memcpy(k.R, R[c].ptr<double>(), sizeof k.R);
        std::memcpy(k.t, T[c].ptr<double>(), sizeof k.t);
    }
    sh_calib_compute_p(&cal);
    if (sh_calib_write(o.out, &cal) != SH_OK) throw std::runtime_error(sh_error_message());
    if (!o.quiet) std::printf("wrote %s\n", o.out);
    return 0;
}

bool parse_int(const char *s, int lo, int hi, int &out)
{
    char *end;
    errno = 0;
    long v = std::strtol(s, &end, 10);
    if (end == s || *end || errno || v < lo || v > hi) return false;
    out = (int)v;
    return true;
}

} // namespace

int main(int argc, char **argv)
{
    options o;
    enum { O_BOARD = 256, O_OUT, O_EVERY, O_MIN, O_K3, O_CORNERS, O_NOTAN, O_WORLD };
    static const struct option opts[] = {
        {"board", 1, 0, O_BOARD}, {"out", 1, 0, O_OUT}, {"every", 1, 0, O_EVERY}, {"min-views", 1, 0, O_MIN},
        {"k3", 0, 0, O_K3}, {"corners-out", 1, 0, O_CORNERS}, SH_CLI_OPTIONS,
        {"no-tangential", 0, 0, O_NOTAN}, {"world", 1, 0, O_WORLD}, {0, 0, 0, 0}};
    int ch;
    const char *board = nullptr;
#define BAD(...) do { std::fprintf(stderr, "stillheart-calib: " __VA_ARGS__); std::fputc('\n', stderr); return 2; } while (0)
    static const sh_cli cli = {"stillheart-calib"};
    sh_log_setup(SH_LOG_TOOL, "stillheart-calib", SH_LOG_INFO);
    opterr = 0;
    while ((ch = getopt_long(argc, argv, ":h", opts, nullptr)) != -1) {
        switch (ch) {
        case O_BOARD:
            board = optarg;
            if (!parse_board(optarg, o.board))
                BAD("--board '%s': checkerboard:COLSxROWS:SQUARE_MM, 3 to 40 inner corners each way, one count "
                    "odd and one even, squares > 0 (e.g. checkerboard:9x6:25)", optarg);
            break;
        case O_OUT: o.out = optarg; break;
        case O_EVERY: if (!parse_int(optarg, 1, 100000, o.every)) BAD("--every '%s': a count from 1", optarg); break;
        case O_MIN: if (!parse_int(optarg, 3, 100000, o.min_views)) BAD("--min-views '%s': 3 or more", optarg); break;
        case O_K3: o.k3 = 1; break;
        case O_NOTAN: o.no_tangential = 1; break;
        case O_WORLD:
            if (!std::strcmp(optarg, "camera0")) o.world_frame = -1;
            else if (std::strncmp(optarg, "board:", 6) || !parse_int(optarg + 6, 0, 1 << 30, o.world_frame))
                BAD("--world '%s': camera0 or board:N (a frame index)", optarg);
            break;
        case O_CORNERS: o.corners_out = optarg; break;
        case 'h': usage(stdout); return 0;
        default: { int rc = sh_cli_option(&cli, ch, argv); if (rc >= 0) return rc; } break;
        }
    }
    o.quiet = sh_log_get_level() < SH_LOG_INFO;
    for (int i = optind; i < argc; i++) o.inputs.push_back(argv[i]);
    if (!board) return sh_cli_usage_error(&cli, "--board is required");
    if (!o.out) return sh_cli_usage_error(&cli, "--out is required");
    if (o.inputs.size() < 2 || o.inputs.size() > 3)
        return sh_cli_usage_error(&cli, "%zu camera inputs: give two or three", o.inputs.size());
#undef BAD
    try {
        return run(o);
    } catch (const std::exception &e) {
        std::fprintf(stderr, "stillheart-calib: %s\n", e.what());
        return 1;
    }
}
