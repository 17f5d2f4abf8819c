/* sh_image_to_rgb against published closed forms.
 *
 * Full range: JFIF 1.02 ("Conversion to and from RGB"), E. Hamilton, C-Cube Microsystems, 1992:
 *   R = Y + 1.402 (Cr-128);  G = Y - 0.34414 (Cb-128) - 0.71414 (Cr-128);  B = Y + 1.772 (Cb-128)
 * Limited range: ITU-R BT.601 studio swing, as tabulated in Wikipedia "YCbCr" (ITU-R BT.601
 * conversion, 8-bit):
 *   R = 1.164383 (Y-16) + 1.596027 (Cr-128)
 *   G = 1.164383 (Y-16) - 0.391762 (Cb-128) - 0.812968 (Cr-128)
 *   B = 1.164383 (Y-16) + 2.017232 (Cb-128)
 * The published constants are rounded, so a result is accepted when it is the rounding of the
 * closed form to within 0.5 plus a small allowance for that rounding of the constants.
 * Chroma upsampling weights are worked out by hand per siting in the tables below. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <cmocka.h>

#include <math.h>
#include <string.h>

#include "stillheart/image.h"

static void reference_rgb(double y, double u, double v, int full, double rgb[3])
{
    if (full) {
        rgb[0] = y + 1.402 * (v - 128);
        rgb[1] = y - 0.34414 * (u - 128) - 0.71414 * (v - 128);
        rgb[2] = y + 1.772 * (u - 128);
    } else {
        rgb[0] = 1.164383 * (y - 16) + 1.596027 * (v - 128);
        rgb[1] = 1.164383 * (y - 16) - 0.391762 * (u - 128) - 0.812968 * (v - 128);
        rgb[2] = 1.164383 * (y - 16) + 2.017232 * (u - 128);
    }
    for (int c = 0; c < 3; c++) rgb[c] = rgb[c] < 0 ? 0 : rgb[c] > 255 ? 255 : rgb[c];
}

static void check_pixel(const uint8_t *got, double y, double u, double v, int full, int x, int row)
{
    double want[3];
    reference_rgb(y, u, v, full, want);
    for (int c = 0; c < 3; c++) {
        if (fabs(got[c] - want[c]) > 0.5 + 2e-3) {
            print_error("pixel (%d,%d) channel %d: got %d, closed form %.4f (Y %.3f U %.3f "
                        "V %.3f, %s range)\n",
                        x, row, c, got[c], want[c], y, u, v, full ? "full" : "limited");
            fail();
        }
    }
}

static const uint8_t yuv_cases[][3] = {
    {0, 0, 0},      {255, 255, 255}, {16, 128, 128}, {235, 128, 128}, {81, 90, 240},
    {145, 54, 34},  {41, 240, 110},  {128, 128, 128}, {200, 30, 200}, {50, 200, 60},
    {170, 166, 16}, {106, 202, 222}, {1, 254, 3},    {240, 16, 240},  {99, 127, 129},
};

static void test_yuv444_closed_form(void **state)
{
    (void)state;
    const int n = sizeof yuv_cases / sizeof yuv_cases[0];
    sh_image src, dst;
    assert_int_equal(sh_image_create(&src, SH_PIX_YUV444, n, 1), SH_OK);
    assert_int_equal(sh_image_create(&dst, SH_PIX_RGB24, n, 1), SH_OK);
    for (int i = 0; i < n; i++)
        for (int p = 0; p < 3; p++) src.plane[p].data[i] = yuv_cases[i][p];
    for (int full = 0; full <= 1; full++) {
        assert_int_equal(sh_image_to_rgb(&src, &dst, full), SH_OK);
        for (int i = 0; i < n; i++)
            check_pixel(dst.plane[0].data + 3 * i, yuv_cases[i][0], yuv_cases[i][1],
                        yuv_cases[i][2], full, i, 0);
    }
    /* exact anchors: limited black and white, full-range grey */
    src.plane[0].data[0] = 16, src.plane[1].data[0] = 128, src.plane[2].data[0] = 128;
    src.plane[0].data[1] = 235, src.plane[1].data[1] = 128, src.plane[2].data[1] = 128;
    assert_int_equal(sh_image_to_rgb(&src, &dst, 0), SH_OK);
    assert_memory_equal(dst.plane[0].data, "\0\0\0\xff\xff\xff", 6);
    src.plane[0].data[0] = 77;
    assert_int_equal(sh_image_to_rgb(&src, &dst, 1), SH_OK);
    assert_memory_equal(dst.plane[0].data, "\x4d\x4d\x4d", 3);
    sh_image_destroy(&src);
    sh_image_destroy(&dst);
}

/* Weights of chroma samples 0 and 1 for luma positions 0..3 (a 4x4 frame has 2x2 chroma). */
static const double W_CENTRED[4][2] = {{1, 0}, {0.75, 0.25}, {0.25, 0.75}, {0, 1}};
static const double W_COSITED[4][2] = {{1, 0}, {0.5, 0.5}, {0, 1}, {0, 1}};
/* PAL-DV Cb sits on the odd luma lines 1 and 3: line 0 takes line 1's sample. */
static const double W_ODD_LINE[4][2] = {{1, 0}, {1, 0}, {0.5, 0.5}, {0, 1}};

static double upsample(const uint8_t c[2][2], const double (*wh)[2], const double (*wv)[2], int x,
                       int y)
{
    double s = 0;
    for (int i = 0; i < 2; i++)
        for (int j = 0; j < 2; j++) s += wv[y][i] * wh[x][j] * c[i][j];
    return s;
}

static void test_i420_siting(void **state)
{
    (void)state;
    static const uint8_t U[2][2] = {{100, 160}, {140, 60}}, V[2][2] = {{90, 170}, {150, 110}};
    struct {
        sh_chroma_siting siting;
        const double (*wh)[2], (*wv_u)[2], (*wv_v)[2];
    } cases[] = {
        {SH_CHROMA_CENTER, W_CENTRED, W_CENTRED, W_CENTRED},
        {SH_CHROMA_LEFT, W_COSITED, W_CENTRED, W_CENTRED},
        {SH_CHROMA_PALDV, W_COSITED, W_ODD_LINE, W_COSITED},
    };
    sh_image src, dst;
    assert_int_equal(sh_image_create(&src, SH_PIX_I420, 4, 4), SH_OK);
    assert_int_equal(sh_image_create(&dst, SH_PIX_RGB24, 4, 4), SH_OK);
    for (int y = 0; y < 4; y++)
        for (int x = 0; x < 4; x++) src.plane[0].data[y * src.plane[0].stride + x] = (uint8_t)(60 + 9 * x + 23 * y);
    for (int i = 0; i < 2; i++)
        for (int j = 0; j < 2; j++) {
            src.plane[1].data[i * src.plane[1].stride + j] = U[i][j];
            src.plane[2].data[i * src.plane[2].stride + j] = V[i][j];
        }
    for (size_t k = 0; k < sizeof cases / sizeof cases[0]; k++) {
        src.siting = cases[k].siting;
        for (int full = 0; full <= 1; full++) {
            assert_int_equal(sh_image_to_rgb(&src, &dst, full), SH_OK);
            for (int y = 0; y < 4; y++)
                for (int x = 0; x < 4; x++)
                    check_pixel(dst.plane[0].data + y * dst.plane[0].stride + 3 * x,
                                60 + 9 * x + 23 * y, upsample(U, cases[k].wh, cases[k].wv_u, x, y),
                                upsample(V, cases[k].wh, cases[k].wv_v, x, y), full, x, y);
        }
    }
    sh_image_destroy(&src);
    sh_image_destroy(&dst);
}

/* Odd sizes: the last chroma column/row serves a single luma column/row; no reads outside. */
static void test_i420_odd_size_edges(void **state)
{
    (void)state;
    sh_image src, dst;
    assert_int_equal(sh_image_create(&src, SH_PIX_I420, 5, 3), SH_OK);
    assert_int_equal(sh_image_create(&dst, SH_PIX_RGB24, 5, 3), SH_OK);
    memset(src.plane[0].data, 128, (size_t)src.plane[0].stride * 3);
    /* chroma 3x2: V = 128 except the last column, 200; U neutral */
    for (int i = 0; i < 2; i++) src.plane[2].data[i * src.plane[2].stride + 2] = 200;
    assert_int_equal(sh_image_to_rgb(&src, &dst, 1), SH_OK);
    /* jpeg: luma x = 4 sits at chroma 1.75 -> V = 0.25*128 + 0.75*200 = 182; x = 3 -> 1.25 -> 146 */
    check_pixel(dst.plane[0].data + 2 * dst.plane[0].stride + 12, 128, 128, 182, 1, 4, 2);
    check_pixel(dst.plane[0].data + 2 * dst.plane[0].stride + 9, 128, 128, 146, 1, 3, 2);
    sh_image_destroy(&src);
    sh_image_destroy(&dst);
}

static void test_gray_rgb_and_errors(void **state)
{
    (void)state;
    sh_image g, rgb, out;
    assert_int_equal(sh_image_create(&g, SH_PIX_GRAY8, 3, 2), SH_OK);
    assert_int_equal(sh_image_create(&rgb, SH_PIX_RGB24, 3, 2), SH_OK);
    assert_int_equal(sh_image_create(&out, SH_PIX_RGB24, 3, 2), SH_OK);
    memcpy(g.plane[0].data, "\x00\x10\xff", 3);
    memcpy(g.plane[0].data + g.plane[0].stride, "\x7f\x80\x01", 3);
    for (int full = 0; full <= 1; full++) { /* grey is replicated, never range-expanded */
        assert_int_equal(sh_image_to_rgb(&g, &out, full), SH_OK);
        assert_memory_equal(out.plane[0].data, "\x00\x00\x00\x10\x10\x10\xff\xff\xff", 9);
        assert_memory_equal(out.plane[0].data + out.plane[0].stride,
                            "\x7f\x7f\x7f\x80\x80\x80\x01\x01\x01", 9);
    }
    memcpy(rgb.plane[0].data, "abcdefghi", 9);
    memcpy(rgb.plane[0].data + rgb.plane[0].stride, "jklmnopqr", 9);
    assert_int_equal(sh_image_to_rgb(&rgb, &out, 0), SH_OK);
    assert_memory_equal(out.plane[0].data, "abcdefghi", 9);
    assert_memory_equal(out.plane[0].data + out.plane[0].stride, "jklmnopqr", 9);

    sh_image small;
    assert_int_equal(sh_image_create(&small, SH_PIX_RGB24, 2, 2), SH_OK);
    assert_int_equal(sh_image_to_rgb(&g, &small, 0), SH_EINVAL);
    assert_int_equal(sh_image_to_rgb(&g, &g, 0), SH_EINVAL);
    assert_int_equal(sh_image_to_rgb(NULL, &out, 0), SH_EINVAL);
    sh_image_destroy(&small);
    sh_image_destroy(&g);
    sh_image_destroy(&rgb);
    sh_image_destroy(&out);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_yuv444_closed_form),
        cmocka_unit_test(test_i420_siting),
        cmocka_unit_test(test_i420_odd_size_edges),
        cmocka_unit_test(test_gray_rgb_and_errors),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
