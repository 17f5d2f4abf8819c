/* PNG output: the file's signature and IHDR checked byte by byte against the PNG spec (RFC
 * 2083), pixels read back with libpng's own decoder, YUV against the JFIF closed form. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <cmocka.h>

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "stillheart/png.h"

#ifdef SH_HAVE_PNG
#include <png.h>

static char path[64];

static int setup(void **state)
{
    (void)state;
    snprintf(path, sizeof path, "/tmp/sh_test_png_XXXXXX");
    int fd = mkstemp(path);
    if (fd < 0) return -1;
    close(fd);
    return 0;
}

static int teardown(void **state)
{
    (void)state;
    unlink(path);
    return 0;
}

static uint32_t be32(const uint8_t *p)
{
    return (uint32_t)p[0] << 24 | (uint32_t)p[1] << 16 | (uint32_t)p[2] << 8 | p[3];
}

/* Signature, then the IHDR chunk: length 13, "IHDR", width, height, depth, colour type. */
static void check_ihdr(int width, int height, int colour_type)
{
    uint8_t head[26];
    FILE *f = fopen(path, "rb");
    assert_non_null(f);
    assert_int_equal(fread(head, 1, sizeof head, f), sizeof head);
    fclose(f);
    assert_memory_equal(head, "\x89PNG\r\n\x1a\n", 8);
    assert_int_equal(be32(head + 8), 13);
    assert_memory_equal(head + 12, "IHDR", 4);
    assert_int_equal(be32(head + 16), (uint32_t)width);
    assert_int_equal(be32(head + 20), (uint32_t)height);
    assert_int_equal(head[24], 8);
    assert_int_equal(head[25], colour_type); /* 0 grey, 2 truecolour */
}

/* Decodes the file with libpng into packed rows of `format`. */
static uint8_t *decode(png_uint_32 format, int *w, int *h)
{
    png_image im;
    memset(&im, 0, sizeof im);
    im.version = PNG_IMAGE_VERSION;
    assert_true(png_image_begin_read_from_file(&im, path));
    im.format = format;
    uint8_t *buf = malloc(PNG_IMAGE_SIZE(im));
    assert_true(png_image_finish_read(&im, NULL, buf, 0, NULL));
    *w = (int)im.width;
    *h = (int)im.height;
    return buf;
}

static void test_gray8(void **state)
{
    (void)state;
    sh_image img;
    assert_int_equal(sh_image_create(&img, SH_PIX_GRAY8, 3, 2), SH_OK);
    memcpy(img.plane[0].data, "\x00\x80\xff", 3);
    memcpy(img.plane[0].data + img.plane[0].stride, "\x01\x02\x03", 3);
    assert_int_equal(sh_png_write(path, &img, 0), SH_OK);
    check_ihdr(3, 2, 0);
    int w, h;
    uint8_t *px = decode(PNG_FORMAT_GRAY, &w, &h);
    assert_int_equal(w, 3);
    assert_int_equal(h, 2);
    assert_memory_equal(px, "\x00\x80\xff\x01\x02\x03", 6);
    free(px);
    sh_image_destroy(&img);
}

static void test_rgb24(void **state)
{
    (void)state;
    sh_image img;
    assert_int_equal(sh_image_create(&img, SH_PIX_RGB24, 2, 2), SH_OK);
    memcpy(img.plane[0].data, "\xff\x00\x00\x00\xff\x00", 6);
    memcpy(img.plane[0].data + img.plane[0].stride, "\x00\x00\xff\x10\x20\x30", 6);
    assert_int_equal(sh_png_write(path, &img, 0), SH_OK);
    check_ihdr(2, 2, 2);
    int w, h;
    uint8_t *px = decode(PNG_FORMAT_RGB, &w, &h);
    assert_memory_equal(px, "\xff\x00\x00\x00\xff\x00\x00\x00\xff\x10\x20\x30", 12);
    free(px);
    sh_image_destroy(&img);
}

/* Uniform chroma, so the JFIF closed form applies with no interpolation. */
static void test_yuv_converted(void **state)
{
    (void)state;
    sh_pixfmt formats[] = {SH_PIX_I420, SH_PIX_YUV444};
    for (int k = 0; k < 2; k++) {
        sh_image img;
        assert_int_equal(sh_image_create(&img, formats[k], 4, 2), SH_OK);
        for (int y = 0; y < 2; y++)
            for (int x = 0; x < 4; x++) img.plane[0].data[y * img.plane[0].stride + x] = (uint8_t)(40 + 50 * x + 20 * y);
        for (int p = 1; p < 3; p++)
            for (int y = 0; y < img.plane[p].height; y++)
                memset(img.plane[p].data + y * img.plane[p].stride, p == 1 ? 90 : 180,
                       (size_t)img.plane[p].width);
        assert_int_equal(sh_png_write(path, &img, 1), SH_OK);
        check_ihdr(4, 2, 2);
        int w, h;
        uint8_t *px = decode(PNG_FORMAT_RGB, &w, &h);
        for (int y = 0; y < 2; y++)
            for (int x = 0; x < 4; x++) {
                double Y = 40 + 50 * x + 20 * y, want[3] = {
                    Y + 1.402 * (180 - 128),
                    Y - 0.34414 * (90 - 128) - 0.71414 * (180 - 128),
                    Y + 1.772 * (90 - 128)};
                for (int c = 0; c < 3; c++) {
                    double wc = want[c] < 0 ? 0 : want[c] > 255 ? 255 : want[c];
                    assert_true(fabs(px[(y * 4 + x) * 3 + c] - wc) <= 0.5 + 1e-3);
                }
            }
        free(px);
        sh_image_destroy(&img);
    }
}

static void test_errors(void **state)
{
    (void)state;
    sh_image img;
    assert_int_equal(sh_image_create(&img, SH_PIX_GRAY8, 64, 64), SH_OK);
    assert_int_equal(sh_png_write("/nonexistent-dir/x.png", &img, 0), SH_EIO);
    assert_non_null(strstr(sh_error_message(), "/nonexistent-dir/x.png"));
    if (access("/dev/full", W_OK) == 0) {
        assert_int_equal(sh_png_write("/dev/full", &img, 0), SH_EIO);
        assert_non_null(strstr(sh_error_message(), "/dev/full"));
        assert_int_equal(access("/dev/full", F_OK), 0); /* a device is never removed */
    }
    assert_int_equal(sh_png_write(path, NULL, 0), SH_EINVAL);
    sh_image_destroy(&img);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_gray8),
        cmocka_unit_test(test_rgb24),
        cmocka_unit_test(test_yuv_converted),
        cmocka_unit_test(test_errors),
    };
    return cmocka_run_group_tests(tests, setup, teardown);
}

#else /* built without libpng: the writer must say so, not pretend */

static void test_unsupported(void **state)
{
    (void)state;
    sh_image img;
    assert_int_equal(sh_image_create(&img, SH_PIX_GRAY8, 2, 2), SH_OK);
    assert_int_equal(sh_png_write("/tmp/never.png", &img, 0), SH_EUNSUPPORTED);
    sh_image_destroy(&img);
}

int main(void)
{
    const struct CMUnitTest tests[] = {cmocka_unit_test(test_unsupported)};
    return cmocka_run_group_tests(tests, NULL, NULL);
}
#endif
