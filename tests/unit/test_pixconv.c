/* Pixel-format conversions against independent references: OpenCV's cvtColor (built with the
 * OpenCV oracle), the BT.601 closed form evaluated in double precision, and libturbojpeg's own
 * decoding for MJPEG. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <cmocka.h>

#include "stillheart/pixconv.h"
#ifdef SH_HAVE_OPENCV_ORACLE
#include "cv_oracle.h"
#endif
#ifdef SH_HAVE_TURBOJPEG
#include <turbojpeg.h>
#endif

enum { W = 64, H = 48, PAD = 24 };

static uint32_t rng = 12345;
static uint8_t rnd(void)
{
    rng = rng * 1664525u + 1013904223u;
    return (uint8_t)(rng >> 24);
}
static void fill(uint8_t *p, size_t n)
{
    for (size_t i = 0; i < n; i++) p[i] = rnd();
}

/* Legal BT.601 limited-range samples (16..235): OpenCV clamps Y - 16 at 0 before scaling, a
 * choice of its own for illegal luma, so the comparison with it stays inside the legal range. */
static void fill_legal(uint8_t *p, size_t n)
{
    for (size_t i = 0; i < n; i++) p[i] = (uint8_t)(16 + rnd() % 220);
}

static double clampd(double v) { return v < 0 ? 0 : v > 255 ? 255 : v; }

/* BT.601 limited-range YUV -> RGB, closed form. */
static void ref_rgb(int y, int u, int v, double out[3])
{
    const double kr = 0.299, kb = 0.114, kg = 1 - kr - kb;
    double Y = (y - 16) * 255.0 / 219.0, cb = (u - 128) * 255.0 / 224.0, cr = (v - 128) * 255.0 / 224.0;
    out[0] = clampd(Y + 2 * (1 - kr) * cr);
    out[1] = clampd(Y - (2 * kb * (1 - kb) * cb + 2 * kr * (1 - kr) * cr) / kg);
    out[2] = clampd(Y + 2 * (1 - kb) * cb);
}

static void ref_yuv(double r, double g, double b, double out[3])
{
    const double kr = 0.299, kb = 0.114, kg = 1 - kr - kb;
    double yp = kr * r + kg * g + kb * b;
    out[0] = 16 + yp * 219.0 / 255.0;
    out[1] = 128 + (b - yp) / (2 * (1 - kb)) * 224.0 / 255.0;
    out[2] = 128 + (r - yp) / (2 * (1 - kr)) * 224.0 / 255.0;
}

#ifdef SH_HAVE_OPENCV_ORACLE /* its only user (not in the OpenCV-less aarch64 build) */
static int max_diff(const uint8_t *a, const uint8_t *b, size_t n)
{
    int m = 0;
    for (size_t i = 0; i < n; i++) {
        int d = abs((int)a[i] - (int)b[i]);
        if (d > m) m = d;
    }
    return m;
}
#endif

/* Packs an image's planes (for comparisons with packed references). */
static void pack(const sh_image *img, uint8_t *out)
{
    for (int p = 0; p < img->num_planes; p++) {
        int bytes = img->plane[p].width * (img->format == SH_PIX_RGB24 ? 3 : 1);
        for (int y = 0; y < img->plane[p].height; y++) {
            memcpy(out, img->plane[p].data + (size_t)y * img->plane[p].stride, (size_t)bytes);
            out += bytes;
        }
    }
}

static void convert(sh_rawfmt f, const uint8_t *data, size_t bytes, int stride, sh_pixfmt to, uint8_t *packed,
                    sh_image *keep)
{
    sh_raw raw = {f, W, H, stride, data, bytes};
    sh_image img;
    assert_int_equal(sh_image_create(&img, to, W, H), SH_OK);
    assert_int_equal(sh_pixconv_convert(NULL, &raw, &img), SH_OK);
    pack(&img, packed);
    if (keep) *keep = img;
    else sh_image_destroy(&img);
}

static void test_yuyv(void **state)
{
    (void)state;
    int stride = 2 * W + PAD;
    size_t n = (size_t)stride * H;
    uint8_t *src = malloc(n), rgb[W * H * 3], gray[W * H], i420[W * H * 3 / 2];
    fill_legal(src, n);
    convert(SH_RAW_YUYV, src, n, stride, SH_PIX_RGB24, rgb, NULL);
    convert(SH_RAW_YUYV, src, n, stride, SH_PIX_GRAY8, gray, NULL);
    sh_image keep;
    convert(SH_RAW_YUYV, src, n, stride, SH_PIX_I420, i420, &keep);
    assert_int_equal(keep.siting, SH_CHROMA_LEFT);
    sh_image_destroy(&keep);
    double worst = 0;
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++) {
            const uint8_t *s = src + (size_t)y * stride + 4 * (x / 2);
            double ref[3];
            ref_rgb(s[2 * (x & 1)], s[1], s[3], ref);
            for (int c = 0; c < 3; c++) worst = fmax(worst, fabs(rgb[(y * W + x) * 3 + c] - ref[c]));
            assert_int_equal(gray[y * W + x], s[2 * (x & 1)]);
        }
    assert_true(worst <= 1.0); /* fixed point rounds within one level of the closed form */
    for (int y = 0; y < H / 2; y++)
        for (int x = 0; x < W / 2; x++) {
            const uint8_t *a = src + (size_t)(2 * y) * stride + 4 * x, *b = a + stride;
            assert_int_equal(i420[W * H + y * W / 2 + x], (a[1] + b[1] + 1) / 2);
            assert_int_equal(i420[W * H + W * H / 4 + y * W / 2 + x], (a[3] + b[3] + 1) / 2);
        }
#ifdef SH_HAVE_OPENCV_ORACLE
    uint8_t cv[W * H * 3];
    assert_int_equal(cv_oracle_convert(CV_ORACLE_YUYV_TO_RGB, src, W, H, stride, cv), 0);
    assert_true(max_diff(cv, rgb, sizeof cv) <= 1);
    assert_int_equal(cv_oracle_convert(CV_ORACLE_YUYV_TO_GRAY, src, W, H, stride, cv), 0);
    assert_memory_equal(cv, gray, sizeof gray);
#endif
    free(src);
}

static void test_nv12(void **state)
{
    (void)state;
    int stride = W + PAD;
    size_t n = (size_t)stride * H * 3 / 2;
    uint8_t *src = malloc(n), rgb[W * H * 3], i420[W * H * 3 / 2], gray[W * H];
    fill_legal(src, n);
    convert(SH_RAW_NV12, src, n, stride, SH_PIX_RGB24, rgb, NULL);
    convert(SH_RAW_NV12, src, n, stride, SH_PIX_I420, i420, NULL);
    convert(SH_RAW_NV12, src, n, stride, SH_PIX_GRAY8, gray, NULL);
    const uint8_t *uv = src + (size_t)stride * H;
    double worst = 0;
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++) {
            const uint8_t *c = uv + (size_t)(y / 2) * stride + 2 * (x / 2);
            double ref[3];
            ref_rgb(src[(size_t)y * stride + x], c[0], c[1], ref);
            for (int k = 0; k < 3; k++) worst = fmax(worst, fabs(rgb[(y * W + x) * 3 + k] - ref[k]));
            assert_int_equal(gray[y * W + x], src[(size_t)y * stride + x]);
            assert_int_equal(i420[y * W + x], src[(size_t)y * stride + x]);
        }
    assert_true(worst <= 1.0);
    for (int y = 0; y < H / 2; y++)
        for (int x = 0; x < W / 2; x++) {
            assert_int_equal(i420[W * H + y * W / 2 + x], uv[(size_t)y * stride + 2 * x]);
            assert_int_equal(i420[W * H * 5 / 4 + y * W / 2 + x], uv[(size_t)y * stride + 2 * x + 1]);
        }
#ifdef SH_HAVE_OPENCV_ORACLE
    uint8_t cv[W * H * 3];
    assert_int_equal(cv_oracle_convert(CV_ORACLE_NV12_TO_RGB, src, W, H, stride, cv), 0);
    assert_true(max_diff(cv, rgb, sizeof cv) <= 1);
#endif
    free(src);
}

static void test_i420_raw(void **state)
{
    (void)state;
    size_t n = W * H * 3 / 2;
    uint8_t src[W * H * 3 / 2], rgb[W * H * 3], i420[W * H * 3 / 2];
    fill_legal(src, n);
    convert(SH_RAW_I420, src, n, W, SH_PIX_RGB24, rgb, NULL);
    convert(SH_RAW_I420, src, n, W, SH_PIX_I420, i420, NULL);
    assert_memory_equal(src, i420, n);
#ifdef SH_HAVE_OPENCV_ORACLE
    uint8_t cv[W * H * 3];
    assert_int_equal(cv_oracle_convert(CV_ORACLE_I420_TO_RGB, src, W, H, W, cv), 0);
    assert_true(max_diff(cv, rgb, sizeof cv) <= 1);
#else
    (void)rgb;
#endif
}

static void check_rgb_input(sh_rawfmt f)
{
    int stride = 3 * W + PAD;
    size_t n = (size_t)stride * H;
    uint8_t *src = malloc(n), i420[W * H * 3 / 2], gray[W * H], rgb[W * H * 3];
    fill(src, n);
    convert(f, src, n, stride, SH_PIX_I420, i420, NULL);
    convert(f, src, n, stride, SH_PIX_GRAY8, gray, NULL);
    convert(f, src, n, stride, SH_PIX_RGB24, rgb, NULL);
    int ri = f == SH_RAW_RGB24 ? 0 : 2;
    double worst_y = 0, worst_c = 0;
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++) {
            const uint8_t *p = src + (size_t)y * stride + 3 * x;
            double ref[3];
            ref_yuv(p[ri], p[1], p[2 - ri], ref);
            worst_y = fmax(worst_y, fabs(i420[y * W + x] - ref[0]));
            assert_int_equal(gray[y * W + x], i420[y * W + x]);
            assert_int_equal(rgb[(y * W + x) * 3], p[ri]);
            assert_int_equal(rgb[(y * W + x) * 3 + 1], p[1]);
            assert_int_equal(rgb[(y * W + x) * 3 + 2], p[2 - ri]);
        }
    for (int y = 0; y < H / 2; y++)
        for (int x = 0; x < W / 2; x++) {
            double r = 0, g = 0, b = 0;
            for (int k = 0; k < 4; k++) {
                const uint8_t *p = src + (size_t)(2 * y + k / 2) * stride + 3 * (2 * x + k % 2);
                r += p[ri] / 4.0, g += p[1] / 4.0, b += p[2 - ri] / 4.0;
            }
            double ref[3];
            ref_yuv(r, g, b, ref);
            worst_c = fmax(worst_c, fabs(i420[W * H + y * W / 2 + x] - ref[1]));
            worst_c = fmax(worst_c, fabs(i420[W * H * 5 / 4 + y * W / 2 + x] - ref[2]));
        }
    /* rounded to nearest, with 14-bit coefficients: within 0.6 of the closed form */
    assert_true(worst_y <= 0.6);
    assert_true(worst_c <= 0.6);
#ifdef SH_HAVE_OPENCV_ORACLE
    uint8_t cv[W * H * 3 / 2];
    assert_int_equal(cv_oracle_convert(f == SH_RAW_RGB24 ? CV_ORACLE_RGB_TO_I420 : CV_ORACLE_BGR_TO_I420, src, W,
                                       H, stride, cv),
                     0);
    /* OpenCV's luma is the same closed form; its chroma takes one pixel of each 2x2 block, ours
     * the block's mean, so only the Y plane is compared. */
    assert_true(max_diff(cv, i420, W * H) <= 1);
    if (f == SH_RAW_BGR24) {
        uint8_t cv3[W * H * 3];
        assert_int_equal(cv_oracle_convert(CV_ORACLE_BGR_TO_RGB, src, W, H, stride, cv3), 0);
        assert_memory_equal(cv3, rgb, sizeof rgb);
    }
#endif
    free(src);
}

static void test_rgb(void **state)
{
    (void)state;
    check_rgb_input(SH_RAW_RGB24);
    check_rgb_input(SH_RAW_BGR24);
}

static void test_grey_yuv444(void **state)
{
    (void)state;
    int stride = W + PAD;
    uint8_t src[(W + PAD) * H * 3], out[W * H * 3];
    fill(src, sizeof src);
    convert(SH_RAW_GREY, src, (size_t)stride * H, stride, SH_PIX_I420, out, NULL);
    for (int y = 0; y < H; y++) assert_memory_equal(out + y * W, src + y * stride, W);
    for (int i = W * H; i < W * H * 3 / 2; i++) assert_int_equal(out[i], 128);
    convert(SH_RAW_GREY, src, (size_t)stride * H, stride, SH_PIX_RGB24, out, NULL);
    for (int i = 0; i < W * H; i++)
        assert_true(out[3 * i] == src[(i / W) * stride + i % W] && out[3 * i + 1] == out[3 * i] &&
                    out[3 * i + 2] == out[3 * i]);
    convert(SH_RAW_YUV444, src, (size_t)stride * H * 3, stride, SH_PIX_I420, out, NULL);
    const uint8_t *u = src + (size_t)stride * H;
    for (int y = 0; y < H / 2; y++)
        for (int x = 0; x < W / 2; x++) {
            const uint8_t *a = u + (size_t)(2 * y) * stride + 2 * x;
            assert_int_equal(out[W * H + y * W / 2 + x], (a[0] + a[1] + a[stride] + a[stride + 1] + 2) / 4);
        }
}

static void test_bad_input(void **state)
{
    (void)state;
    uint8_t buf[W * H * 2];
    sh_image img;
    assert_int_equal(sh_image_create(&img, SH_PIX_I420, W, H), SH_OK);
    sh_raw raw = {SH_RAW_YUYV, W, H, 2 * W, buf, sizeof buf - 1};
    assert_int_equal(sh_pixconv_convert(NULL, &raw, &img), SH_EFORMAT);
    assert_non_null(strstr(sh_error_message(), "bytes"));
    raw.bytes = sizeof buf;
    raw.stride = W; /* smaller than a row */
    assert_int_equal(sh_pixconv_convert(NULL, &raw, &img), SH_EFORMAT);
    raw.stride = 2 * W;
    raw.width = W - 1;
    assert_int_equal(sh_pixconv_convert(NULL, &raw, &img), SH_EFORMAT);
    raw.width = W;
    raw.format = SH_RAW_MJPEG;
    assert_int_not_equal(sh_pixconv_convert(NULL, &raw, &img), SH_OK);
    sh_image_destroy(&img);
    sh_rawfmt f;
    assert_int_equal(sh_rawfmt_parse("yuyv", &f), SH_OK);
    assert_int_equal(f, SH_RAW_YUYV);
    assert_int_equal(sh_rawfmt_parse("mjpg", &f), SH_OK);
    assert_int_equal(f, SH_RAW_MJPEG);
    assert_int_equal(sh_rawfmt_parse("XYZ", &f), SH_EUNSUPPORTED);
    assert_int_equal(sh_rawfmt_from_fourcc(sh_rawfmt_fourcc(SH_RAW_NV12), &f), SH_OK);
    assert_int_equal(f, SH_RAW_NV12);
}

#ifdef SH_HAVE_TURBOJPEG
/* A smooth test picture (JPEG keeps it recognisable), encoded at the given subsampling. */
static unsigned char *encode(int sub, unsigned long *size)
{
    static uint8_t rgb[W * H * 3];
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++) {
            rgb[(y * W + x) * 3] = (uint8_t)(x * 4);
            rgb[(y * W + x) * 3 + 1] = (uint8_t)(y * 5);
            rgb[(y * W + x) * 3 + 2] = (uint8_t)(128 + 60 * sin(x * 0.3 + y * 0.2));
        }
    tjhandle tj = tjInitCompress();
    unsigned char *jpeg = NULL;
    *size = 0;
    assert_int_equal(tjCompress2(tj, rgb, W, W * 3, H, TJPF_RGB, &jpeg, size, sub, 90, 0), 0);
    tjDestroy(tj);
    return jpeg;
}

static void test_mjpeg(void **state)
{
    (void)state;
    sh_pixconv *conv;
    assert_int_equal(sh_pixconv_create(W, H, &conv), SH_OK);
    tjhandle tj = tjInitDecompress();
    const int subs[] = {TJSAMP_420, TJSAMP_422, TJSAMP_444};
    for (int k = 0; k < 3; k++) {
        unsigned long size;
        unsigned char *jpeg = encode(subs[k], &size);
        sh_raw raw = {SH_RAW_MJPEG, W, H, 0, jpeg, size};
        uint8_t ref[W * H * 3], out[W * H * 3];
        sh_image img;
        /* RGB and GRAY: libturbojpeg's own decode, byte for byte */
        assert_int_equal(sh_image_create(&img, SH_PIX_RGB24, W, H), SH_OK);
        assert_int_equal(sh_pixconv_convert(conv, &raw, &img), SH_OK);
        pack(&img, out);
        sh_image_destroy(&img);
        assert_int_equal(tjDecompress2(tj, jpeg, size, ref, W, W * 3, H, TJPF_RGB, 0), 0);
        assert_memory_equal(ref, out, W * H * 3);
        assert_int_equal(sh_image_create(&img, SH_PIX_GRAY8, W, H), SH_OK);
        assert_int_equal(sh_pixconv_convert(conv, &raw, &img), SH_OK);
        pack(&img, out);
        assert_int_equal(tjDecompress2(tj, jpeg, size, ref, W, W, H, TJPF_GRAY, 0), 0);
        assert_memory_equal(ref, out, W * H);
        sh_image_destroy(&img);
        /* I420: the JPEG's own planes, chroma averaged down to 4:2:0 */
        assert_int_equal(sh_image_create(&img, SH_PIX_I420, W, H), SH_OK);
        assert_int_equal(sh_pixconv_convert(conv, &raw, &img), SH_OK);
        pack(&img, out);
        sh_image_destroy(&img);
        unsigned char *planes[3] = {ref, ref + W * H, ref + 2 * W * H};
        int cw = tjPlaneWidth(1, W, subs[k]), ch = tjPlaneHeight(1, H, subs[k]);
        int strides[3] = {W, cw, cw};
        planes[2] = planes[1] + cw * ch;
        assert_int_equal(tjDecompressToYUVPlanes(tj, jpeg, size, planes, W, strides, H, 0), 0);
        assert_memory_equal(ref, out, W * H);
        int fx = W / 2 == cw ? 1 : 2, fy = H / 2 == ch ? 1 : 2;
        for (int p = 1; p <= 2; p++)
            for (int y = 0; y < H / 2; y++)
                for (int x = 0; x < W / 2; x++) {
                    int sum = 0;
                    for (int dy = 0; dy < fy; dy++)
                        for (int dx = 0; dx < fx; dx++) sum += planes[p][(fy * y + dy) * cw + fx * x + dx];
                    int n = fx * fy, expect = (sum + n / 2) / n;
                    assert_int_equal(out[W * H + (p - 1) * W * H / 4 + y * W / 2 + x], expect);
                }
        /* a damaged JPEG is refused, not decoded to garbage */
        jpeg[size / 2] ^= 0xff;
        jpeg[size / 2 + 1] = 0xff;
        jpeg[size / 2 + 2] = 0xd9;
        assert_int_equal(sh_image_create(&img, SH_PIX_I420, W, H), SH_OK);
        sh_status st = sh_pixconv_convert(conv, &raw, &img);
        sh_image_destroy(&img);
        raw.bytes = 10;
        assert_int_equal(sh_image_create(&img, SH_PIX_I420, W, H), SH_OK);
        assert_int_equal(sh_pixconv_convert(conv, &raw, &img), SH_EFORMAT);
        sh_image_destroy(&img);
        (void)st;
        tjFree(jpeg);
    }
    tjDestroy(tj);
    sh_pixconv_destroy(conv);
}
#endif

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_yuyv),   cmocka_unit_test(test_nv12),        cmocka_unit_test(test_i420_raw),
        cmocka_unit_test(test_rgb),    cmocka_unit_test(test_grey_yuv444), cmocka_unit_test(test_bad_input),
#ifdef SH_HAVE_TURBOJPEG
        cmocka_unit_test(test_mjpeg),
#endif
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
