/* OpenCV's cvtColor behind a C interface, for tests/unit/test_pixconv.c (the independent
 * reference the conversions are compared with) and make_pixconv_ref.c (the same reference stored
 * in tests/ref/pixconv_ref.h for builds without OpenCV). Test code only; never in the library. */
#include "cv_oracle.h"

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <string>

extern "C" int cv_oracle_convert(cv_oracle_op op, const unsigned char *src, int width, int height,
                                 int stride, unsigned char *dst)
{
    try {
        switch (op) {
        case CV_ORACLE_YUYV_TO_RGB: {
            cv::Mat s(height, width, CV_8UC2, (void *)src, (size_t)stride), d(height, width, CV_8UC3, dst);
            cv::cvtColor(s, d, cv::COLOR_YUV2RGB_YUYV);
            return d.data == dst ? 0 : -1;
        }
        case CV_ORACLE_NV12_TO_RGB: {
            cv::Mat s(height * 3 / 2, width, CV_8UC1, (void *)src, (size_t)stride), d(height, width, CV_8UC3, dst);
            cv::cvtColor(s, d, cv::COLOR_YUV2RGB_NV12);
            return d.data == dst ? 0 : -1;
        }
        case CV_ORACLE_I420_TO_RGB: {
            cv::Mat s(height * 3 / 2, width, CV_8UC1, (void *)src), d(height, width, CV_8UC3, dst);
            cv::cvtColor(s, d, cv::COLOR_YUV2RGB_I420);
            return d.data == dst ? 0 : -1;
        }
        case CV_ORACLE_RGB_TO_I420:
        case CV_ORACLE_BGR_TO_I420: {
            cv::Mat s(height, width, CV_8UC3, (void *)src, (size_t)stride), d(height * 3 / 2, width, CV_8UC1, dst);
            cv::cvtColor(s, d, op == CV_ORACLE_RGB_TO_I420 ? cv::COLOR_RGB2YUV_I420 : cv::COLOR_BGR2YUV_I420);
            return d.data == dst ? 0 : -1;
        }
        case CV_ORACLE_BGR_TO_RGB: {
            cv::Mat s(height, width, CV_8UC3, (void *)src, (size_t)stride), d(height, width, CV_8UC3, dst);
            cv::cvtColor(s, d, cv::COLOR_BGR2RGB);
            return d.data == dst ? 0 : -1;
        }
        case CV_ORACLE_YUYV_TO_GRAY: {
            cv::Mat s(height, width, CV_8UC2, (void *)src, (size_t)stride), d(height, width, CV_8UC1, dst);
            cv::cvtColor(s, d, cv::COLOR_YUV2GRAY_YUYV);
            return d.data == dst ? 0 : -1;
        }
        }
    } catch (const cv::Exception &) {
        return -1;
    }
    return -1;
}

extern "C" const char *cv_oracle_version(void)
{
    static const std::string v = cv::getVersionString(); /* the library loaded, not the headers */
    return v.c_str();
}
