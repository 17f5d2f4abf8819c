/* src/kms where no display is needed: the mode syntax (WxH, WxH@R) and its refusals, and the
 * device refusals this machine can show (a path that is not there, a file that is not a KMS
 * device). The output itself is tested on a real KMS driver in make vmtest (tests/vm/show.sh). */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include <cmocka.h>

#include "stillheart/kms.h"

static void test_parse_mode(void **state)
{
    (void)state;
    int w, h;
    double r;
    assert_int_equal(sh_kms_parse_mode("1920x1080@60", &w, &h, &r), SH_OK);
    assert_int_equal(w, 1920);
    assert_int_equal(h, 1080);
    assert_true(r == 60);
    assert_int_equal(sh_kms_parse_mode("640x480", &w, &h, &r), SH_OK);
    assert_int_equal(w, 640);
    assert_int_equal(h, 480);
    assert_true(r == 0);
    assert_int_equal(sh_kms_parse_mode("1280X720@59.94", &w, &h, &r), SH_OK);
    assert_true(r == 59.94);
    const char *bad[] = {"", "x480", "640x", "640x480@", "640x480@abc", "0x480", "640x0", "640x480x",
                         "-1x2", "640 x 480", "99999x480", "640x480@0", "640x480@60Hz", " 640x480"};
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        w = h = -7;
        assert_int_equal(sh_kms_parse_mode(bad[i], &w, &h, &r), SH_EINVAL);
        assert_int_equal(w, -7); /* nothing written on a refusal */
        assert_non_null(strstr(sh_error_message(), "not WxH or WxH@R"));
    }
    assert_int_equal(sh_kms_parse_mode(NULL, &w, &h, &r), SH_EINVAL);
}

static void test_create_refusals(void **state)
{
    (void)state;
    sh_kms *k = (sh_kms *)1;
    sh_kms_options o = {.device = "/nonexistent/dri/card0"};
    sh_status st = sh_kms_create(&o, &k);
    assert_null(k);
#ifdef SH_HAVE_DRM
    assert_int_equal(st, SH_EIO);
    assert_non_null(strstr(sh_error_message(), "/nonexistent/dri/card0: No such file or directory (no such device"));
    o.device = "/dev/null";
    assert_int_equal(sh_kms_create(&o, &k), SH_EINVAL);
    assert_null(k);
    assert_non_null(strstr(sh_error_message(), "/dev/null: not a KMS display device"));
#else
    assert_int_equal(st, SH_EUNSUPPORTED);
    assert_non_null(strstr(sh_error_message(), "built without libdrm"));
#endif
    sh_kms_destroy(NULL);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_parse_mode),
        cmocka_unit_test(test_create_refusals),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
