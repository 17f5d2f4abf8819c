// make bench: camera pixel formats to the pipeline's formats (src/pixconv) beside OpenCV's
// cvtColor and libturbojpeg's own decoding, at 1920x1080, in one process, one thread each.
// The frame is the synthetic phantom (tools/synth) in each source format; MJPEG is that frame
// encoded by libturbojpeg at 4:2:2, quality 85 (what USB cameras send). Medians of repeated runs
// of thread CPU time; the ratio is ours / peer.
#include <algorithm>
#include <ctime>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <functional>
#include <thread>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#ifdef SH_HAVE_TURBOJPEG
#include <turbojpeg.h>
#endif

extern "C" {
#include "stillheart/pixconv.h"
#include "../synth/synth.h"
}

static double now_ms()
{
    timespec ts;
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return ts.tv_sec * 1e3 + ts.tv_nsec * 1e-6;
}

static double time_ms(const std::function<void()> &f, int repeat)
{
    f(); // warm
    std::vector<double> t;
    for (int i = 0; i < repeat; i++) {
        double a = now_ms();
        f();
        t.push_back(now_ms() - a);
    }
    std::sort(t.begin(), t.end());
    return t[t.size() / 2];
}

static void check(sh_status st, const char *what)
{
    if (st != SH_OK) {
        std::fprintf(stderr, "bench_pixconv: %s: %s\n", what, sh_error_message());
        std::exit(1);
    }
}

static void row(const char *name, double ours, const char *peer_name, double peer)
{
    if (peer > 0)
        std::printf("%-18s %9.3f  %-30s %9.3f  %6.2f\n", name, ours, peer_name, peer, ours / peer);
    else
        std::printf("%-18s %9.3f  %-30s %9s  %6s\n", name, ours, "(no peer)", "-", "-");
}

// Over 80 lines: the source frames in every format, then one row per conversion, ours and the
// peer's timed on the same buffers, read as the table it prints. It runs only in make bench.
int main()
{
    const int W = 1920, H = 1080, REPEAT = 21;
    cv::setNumThreads(1);
    synth_motion motion = {W, H, 12.0};
    sh_image rgb;
    check(sh_image_create(&rgb, SH_PIX_RGB24, W, H), "image");
    synth_render(&motion, 0.3, &rgb);
    cv::Mat mrgb(H, W, CV_8UC3, rgb.plane[0].data, (size_t)rgb.plane[0].stride);
    cv::Mat mbgr, mi420;
    cv::cvtColor(mrgb, mbgr, cv::COLOR_RGB2BGR);
    cv::cvtColor(mrgb, mi420, cv::COLOR_RGB2YUV_I420);
    // YUYV and NV12 from the I420 frame (chroma rows repeated / interleaved)
    std::vector<uint8_t> yuyv((size_t)W * H * 2), nv12((size_t)W * H * 3 / 2);
    const uint8_t *Y = mi420.data, *U = Y + W * H, *V = U + W * H / 4;
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x += 2) {
            uint8_t *p = &yuyv[(size_t)y * W * 2 + 2 * x];
            p[0] = Y[y * W + x];
            p[1] = U[(y / 2) * (W / 2) + x / 2];
            p[2] = Y[y * W + x + 1];
            p[3] = V[(y / 2) * (W / 2) + x / 2];
        }
    std::memcpy(nv12.data(), Y, (size_t)W * H);
    for (int i = 0; i < W * H / 4; i++) nv12[(size_t)W * H + 2 * i] = U[i], nv12[(size_t)W * H + 2 * i + 1] = V[i];

    sh_image gray, i420, out_rgb;
    check(sh_image_create(&gray, SH_PIX_GRAY8, W, H), "image");
    check(sh_image_create(&i420, SH_PIX_I420, W, H), "image");
    check(sh_image_create(&out_rgb, SH_PIX_RGB24, W, H), "image");
    sh_pixconv *conv;
    check(sh_pixconv_create(W, H, &conv), "pixconv");
    cv::Mat dst;

    std::printf("machine: %u cores; frame %dx%d; one thread; medians of %d runs, thread CPU time (ms)\n",
                std::thread::hardware_concurrency(), W, H, REPEAT);
    std::printf("%-18s %9s  %-30s %9s  %6s\n", "conversion", "ours ms", "peer", "peer ms", "ratio");

    auto ours = [&](sh_rawfmt f, const uint8_t *data, size_t bytes, int stride, sh_image *d) {
        return time_ms([&] {
            sh_raw raw = {f, W, H, stride, data, bytes};
            check(sh_pixconv_convert(conv, &raw, d), sh_rawfmt_name(f));
        }, REPEAT);
    };
    cv::Mat myuyv(H, W, CV_8UC2, yuyv.data()), mnv12(H * 3 / 2, W, CV_8UC1, nv12.data());
    row("YUYV -> RGB24", ours(SH_RAW_YUYV, yuyv.data(), yuyv.size(), 2 * W, &out_rgb), "cvtColor YUV2RGB_YUYV",
        time_ms([&] { cv::cvtColor(myuyv, dst, cv::COLOR_YUV2RGB_YUYV); }, REPEAT));
    row("YUYV -> GRAY8", ours(SH_RAW_YUYV, yuyv.data(), yuyv.size(), 2 * W, &gray), "cvtColor YUV2GRAY_YUYV",
        time_ms([&] { cv::cvtColor(myuyv, dst, cv::COLOR_YUV2GRAY_YUYV); }, REPEAT));
    row("YUYV -> I420", ours(SH_RAW_YUYV, yuyv.data(), yuyv.size(), 2 * W, &i420), "", 0);
    row("NV12 -> RGB24", ours(SH_RAW_NV12, nv12.data(), nv12.size(), W, &out_rgb), "cvtColor YUV2RGB_NV12",
        time_ms([&] { cv::cvtColor(mnv12, dst, cv::COLOR_YUV2RGB_NV12); }, REPEAT));
    row("NV12 -> I420", ours(SH_RAW_NV12, nv12.data(), nv12.size(), W, &i420), "", 0);
    row("NV12 -> GRAY8", ours(SH_RAW_NV12, nv12.data(), nv12.size(), W, &gray), "cvtColor YUV2GRAY_NV12",
        time_ms([&] { cv::cvtColor(mnv12, dst, cv::COLOR_YUV2GRAY_NV12); }, REPEAT));
    row("RGB24 -> I420", ours(SH_RAW_RGB24, mrgb.data, (size_t)W * H * 3, W * 3, &i420), "cvtColor RGB2YUV_I420",
        time_ms([&] { cv::cvtColor(mrgb, dst, cv::COLOR_RGB2YUV_I420); }, REPEAT));
    row("BGR24 -> GRAY8", ours(SH_RAW_BGR24, mbgr.data, (size_t)W * H * 3, W * 3, &gray), "cvtColor BGR2GRAY",
        time_ms([&] { cv::cvtColor(mbgr, dst, cv::COLOR_BGR2GRAY); }, REPEAT));
    row("BGR24 -> RGB24", ours(SH_RAW_BGR24, mbgr.data, (size_t)W * H * 3, W * 3, &out_rgb), "cvtColor BGR2RGB",
        time_ms([&] { cv::cvtColor(mbgr, dst, cv::COLOR_BGR2RGB); }, REPEAT));
    row("GREY -> I420", ours(SH_RAW_GREY, Y, (size_t)W * H, W, &i420), "", 0);
#ifdef SH_HAVE_TURBOJPEG
    tjhandle enc = tjInitCompress(), dec = tjInitDecompress();
    unsigned char *jpeg = nullptr;
    unsigned long jsize = 0;
    if (tjCompress2(enc, mrgb.data, W, W * 3, H, TJPF_RGB, &jpeg, &jsize, TJSAMP_422, 85, 0) != 0) {
        std::fprintf(stderr, "bench_pixconv: tjCompress2: %s\n", tjGetErrorStr2(enc));
        return 1;
    }
    std::printf("MJPEG: %lu bytes (4:2:2, quality 85)\n", jsize);
    std::vector<uint8_t> buf((size_t)W * H * 3);
    row("MJPEG -> RGB24", ours(SH_RAW_MJPEG, jpeg, jsize, 0, &out_rgb), "tjDecompress2 RGB",
        time_ms([&] { tjDecompress2(dec, jpeg, jsize, buf.data(), W, W * 3, H, TJPF_RGB, 0); }, REPEAT));
    row("MJPEG -> GRAY8", ours(SH_RAW_MJPEG, jpeg, jsize, 0, &gray), "tjDecompress2 GRAY",
        time_ms([&] { tjDecompress2(dec, jpeg, jsize, buf.data(), W, W, H, TJPF_GRAY, 0); }, REPEAT));
    row("MJPEG -> I420", ours(SH_RAW_MJPEG, jpeg, jsize, 0, &i420), "tjDecompressToYUV2 (4:2:2)",
        time_ms([&] { tjDecompressToYUV2(dec, jpeg, jsize, buf.data(), W, 1, H, 0); }, REPEAT));
    tjFree(jpeg);
    tjDestroy(enc);
    tjDestroy(dec);
#endif
    sh_pixconv_destroy(conv);
    sh_image_destroy(&gray);
    sh_image_destroy(&i420);
    sh_image_destroy(&out_rgb);
    sh_image_destroy(&rgb);
    return 0;
}
