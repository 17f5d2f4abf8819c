/* The paper's metric e (section V) against the formula worked by hand on small images. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include <cmocka.h>

#include "stillheart/metrics.h"

static void set_gray(sh_image *img, const uint8_t *values)
{
    for (int y = 0; y < img->height; y++)
        memcpy(img->plane[0].data + (size_t)y * img->plane[0].stride, values + y * img->width,
               (size_t)img->width);
}

/* A 4x3 grey image, hull = the square (0,0)-(2,2) holding 9 pixel centres. Frame 1 differs by
 * 51 at one hull pixel, frame 2 by 255 at two hull pixels and by 100 outside the hull.
 * I_error sums: 0 (reference) + 51 + 510 over k = 3 frames, p = 9 pixels, one channel:
 * e = (51 + 510) / (255 * 3 * 9) = 561 / 6885. */
static void test_e_by_hand(void **state)
{
    (void)state;
    sh_image ref, f1, f2;
    assert_int_equal(sh_image_create(&ref, SH_PIX_GRAY8, 4, 3), SH_OK);
    assert_int_equal(sh_image_create(&f1, SH_PIX_GRAY8, 4, 3), SH_OK);
    assert_int_equal(sh_image_create(&f2, SH_PIX_GRAY8, 4, 3), SH_OK);
    const uint8_t r[12] = {10, 20, 30, 40, 50, 60, 70, 80, 0, 255, 128, 7};
    uint8_t a[12], b[12];
    memcpy(a, r, 12);
    memcpy(b, r, 12);
    a[5] = 60 + 51;
    b[8] = 255;   /* (0,2): inside */
    b[9] = 0;     /* (1,2): inside */
    b[3] = 140;   /* (3,0): outside the hull */
    set_gray(&ref, r);
    set_gray(&f1, a);
    set_gray(&f2, b);
    double square[] = {0, 0, 2, 0, 2, 2, 0, 2};
    sh_hull hull;
    assert_int_equal(sh_hull_compute(square, 4, &hull), SH_OK);
    sh_metric *m;
    assert_int_equal(sh_metric_create(&ref, &hull, 1, &m), SH_OK);
    assert_int_equal(sh_metric_add(m, &ref), SH_OK);
    assert_int_equal(sh_metric_add(m, &f1), SH_OK);
    assert_int_equal(sh_metric_add(m, &f2), SH_OK);
    assert_int_equal(sh_metric_pixels(m), 9);
    assert_int_equal(sh_metric_frames(m), 3);
    assert_true(fabs(sh_metric_e(m) - 561.0 / 6885.0) < 1e-12);
    float grey[12];
    assert_int_equal(sh_metric_error_image(m, grey), SH_OK);
    assert_true(isnan(grey[3]));                       /* outside */
    assert_true(fabs(grey[5] - 51.0 / 765.0) < 1e-6);  /* 51 / (255 * 3) */
    assert_true(fabs(grey[8] - 255.0 / 765.0) < 1e-6);
    assert_true(grey[0] == 0.0f);
    sh_metric_destroy(m);
    sh_image_destroy(&ref);
    sh_image_destroy(&f1);
    sh_image_destroy(&f2);
}

/* RGB: e sums the three channels' means (so a shift of 255 in every channel of every hull pixel
 * in one of two frames gives e = 3 * 255 / (255 * 2) = 1.5). */
static void test_e_sums_channels(void **state)
{
    (void)state;
    sh_image ref, other;
    assert_int_equal(sh_image_create(&ref, SH_PIX_RGB24, 5, 5), SH_OK);
    assert_int_equal(sh_image_create(&other, SH_PIX_RGB24, 5, 5), SH_OK);
    for (int y = 0; y < 5; y++) memset(other.plane[0].data + (size_t)y * other.plane[0].stride, 255, 15);
    double tri[] = {0, 0, 4, 0, 0, 4};
    sh_hull hull;
    assert_int_equal(sh_hull_compute(tri, 3, &hull), SH_OK);
    sh_metric *m;
    assert_int_equal(sh_metric_create(&ref, &hull, 1, &m), SH_OK);
    assert_int_equal(sh_metric_pixels(m), 15); /* 5 + 4 + 3 + 2 + 1 centres on or under the diagonal */
    assert_int_equal(sh_metric_add(m, &ref), SH_OK);
    assert_int_equal(sh_metric_add(m, &other), SH_OK);
    assert_true(fabs(sh_metric_e(m) - 1.5) < 1e-12);
    sh_image small;
    assert_int_equal(sh_image_create(&small, SH_PIX_RGB24, 4, 5), SH_OK);
    assert_int_equal(sh_metric_add(m, &small), SH_EINVAL);
    sh_metric_destroy(m);
    sh_image_destroy(&ref);
    sh_image_destroy(&other);
    sh_image_destroy(&small);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_e_by_hand),
        cmocka_unit_test(test_e_sums_channels),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
