/* OpenCV's cvtColor for the pixconv tests: dst packed (RGB24 rows of 3*width, I420 planes). */
#ifndef STILLHEART_CV_ORACLE_H
#define STILLHEART_CV_ORACLE_H
#ifdef __cplusplus
extern "C" {
#endif
typedef enum {
    CV_ORACLE_YUYV_TO_RGB,
    CV_ORACLE_NV12_TO_RGB,
    CV_ORACLE_I420_TO_RGB,
    CV_ORACLE_RGB_TO_I420,
    CV_ORACLE_BGR_TO_I420,
    CV_ORACLE_BGR_TO_RGB,
    CV_ORACLE_YUYV_TO_GRAY
} cv_oracle_op;
/* 0 on success. */
int cv_oracle_convert(cv_oracle_op op, const unsigned char *src, int width, int height, int stride,
                      unsigned char *dst);
/* The OpenCV library's version ("4.6.0"), named in the generated tests/ref/pixconv_ref.h. */
const char *cv_oracle_version(void);
#ifdef __cplusplus
}
#endif
#endif
