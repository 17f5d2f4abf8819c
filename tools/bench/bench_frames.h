// The display benchmarks' frame (bench_screen, bench_show): the synthetic phantom (tools/synth)
// as I420, converted by OpenCV, which also gives it packed for cvtColor, the peer's input.
#ifndef STILLHEART_BENCH_FRAMES_H
#define STILLHEART_BENCH_FRAMES_H

#include <algorithm>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

extern "C" {
#include "stillheart/image.h"
#include "../synth/synth.h"
}
#include "bench_detect_util.h"

// i420 (created here, W x H) and *packed (OpenCV's one-buffer I420, for cvtColor).
static inline void bench_i420_frame(int W, int H, sh_image *i420, cv::Mat *packed)
{
    sh_image rgb;
    bench_check("bench", sh_image_create(&rgb, SH_PIX_RGB24, W, H), "image");
    bench_check("bench", sh_image_create(i420, SH_PIX_I420, W, H), "image");
    synth_motion motion = {W, H, 12.0};
    synth_render(&motion, 0.3, &rgb);
    cv::Mat mrgb(H, W, CV_8UC3, rgb.plane[0].data, (size_t)rgb.plane[0].stride);
    cv::cvtColor(mrgb, *packed, cv::COLOR_RGB2YUV_I420);
    for (int p = 0; p < 3; p++) {
        const uint8_t *src = packed->data + (p == 0 ? 0 : (size_t)W * H + (p - 1) * (size_t)W * H / 4);
        int pw = p ? W / 2 : W;
        for (int y = 0; y < i420->plane[p].height; y++)
            std::copy(src + (size_t)y * pw, src + (size_t)(y + 1) * pw, i420->plane[p].data + (size_t)y * i420->plane[p].stride);
    }
    sh_image_destroy(&rgb);
}

#endif
