/* stillheart-show, run as a program, where no display is needed: --help names every option,
 * and each refusal exits with its status and a line naming what was wrong (bad --mode,
 * --overlay, --stale, --owner, --threads, an operand: 2; a device that is not there or not a KMS device, a
 * --trace file that cannot be written: 1, the trace refused before the device is opened).
 * The display itself is tested on a real KMS driver in make vmtest (tests/vm/show.sh). */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include <cmocka.h>

#include "shell.h"

static void expect(int status, const char *args, const char *message)
{
    int rc = test_run("%s %s", SHOW_BIN, args);
    if (rc != status || !strstr(test_out, message))
        fail_msg("stillheart-show %s: exit %d, printed '%s'; want exit %d and '%s'", args, rc, test_out, status,
                 message);
}

static void test_help(void **state)
{
    (void)state;
    assert_int_equal(test_run("%s --help", SHOW_BIN), 0);
    const char *opts[] = {"--device DEV", "--connector NAME", "--mode WxH[@R]", "--name NAME", "--owner USER",
                          "--overlay MODE", "--stale S", "--stats", "--trace FILE", "--threads N", "NO SIGNAL"};
    for (size_t i = 0; i < sizeof opts / sizeof opts[0]; i++) assert_non_null(strstr(test_out, opts[i]));
}

static void test_usage_refusals(void **state)
{
    (void)state;
    expect(2, "--mode 640", "--mode: mode '640': not WxH or WxH@R");
    expect(2, "--mode 640x480@", "--mode: mode '640x480@': not WxH or WxH@R");
    expect(2, "--overlay none", "--overlay: 'none' is not off, minimal or full");
    expect(2, "--stale 0", "--stale");
    expect(2, "--stale soon", "--stale");
    expect(2, "--owner no-such-user-here", "--owner: no user 'no-such-user-here'");
    expect(2, "/dev/dri/card0", "'/dev/dri/card0': no operands");
    expect(2, "--bogus", "--bogus");
    expect(2, "--device", "--device");
    expect(2, "--trace", "--trace");
    expect(2, "--threads 0", "--threads");
    expect(2, "--threads 9", "--threads");
}

static void test_trace_refusal(void **state)
{
    (void)state;
    expect(1, "--trace /nonexistent/dir/trace.csv --device /dev/null",
           "--trace /nonexistent/dir/trace.csv: No such file or directory");
}

static void test_device_refusals(void **state)
{
    (void)state;
#ifndef SH_HAVE_DRM
    expect(1, "--device /nonexistent/card0", "built without libdrm");
    return;
#endif
    expect(1, "--device /nonexistent/card0", "/nonexistent/card0: No such file or directory (no such device");
    expect(1, "--device /dev/null", "/dev/null: not a KMS display device");
    /* a user by name or by uid is taken: the device is what refuses */
    expect(1, "--owner root --device /nonexistent/card0", "/nonexistent/card0: No such file");
    expect(1, "--owner 0 --device /nonexistent/card0", "/nonexistent/card0: No such file");
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_help),
        cmocka_unit_test(test_usage_refusals),
        cmocka_unit_test(test_device_refusals),
        cmocka_unit_test(test_trace_refusal),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
