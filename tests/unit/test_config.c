/* The daemon's INI config: every key from text, refusals naming file, line and key, all or nothing,
 * command-line names, and the shipped example parses. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include <cmocka.h>

#include "stillheart/config.h"

static void test_defaults_check(void **state)
{
    (void)state;
    sh_config c;
    char err[SH_CONFIG_ERR];
    sh_config_default(&c);
    assert_int_equal(sh_config_check(&c, err), SH_OK);
    assert_int_equal(c.method.method, SH_METHOD_TPS);
}

static void test_parse_every_kind(void **state)
{
    (void)state;
    sh_config c;
    char err[SH_CONFIG_ERR];
    sh_config_default(&c);
    const char *text = "; comment\n"
                       "[source]\nspec = y4m:/tmp/x.y4m\nrealtime = no\nloop = off\n"
                       "[detect]\nfamily = tag36h11\nids = 1,3, 5-9\n"
                       "[method]\nname = gaussian\nsigma = 80\n"
                       "[gating]\nmin_markers = 4\nmax_residual_px = 2.5\ndropout_ms = 150\n"
                       "[run]\nthreads = 3\n"
                       "[sink]\ndisplay = shm:/abc\nslots = 5\ngroup =\n";
    assert_int_equal(sh_config_parse_string(&c, text, "t.ini", err), SH_OK);
    assert_string_equal(c.source, "y4m:/tmp/x.y4m");
    assert_int_equal(c.realtime, 0);
    assert_int_equal(c.loop, 0);
    assert_int_equal(c.ids[0], 0);
    assert_int_equal(c.ids[1], 1);
    assert_int_equal(c.ids[3], 1);
    assert_int_equal(c.ids[4], 0);
    for (int i = 5; i <= 9; i++)
        assert_int_equal(c.ids[i], 1);
    assert_int_equal(c.ids[10], 0);
    assert_int_equal(c.method.method, SH_METHOD_GAUSSIAN);
    assert_true(c.method.sigma == 80.0);
    assert_int_equal(c.min_markers, 4);
    assert_true(c.max_residual_px == 2.5);
    assert_int_equal(c.dropout_ms, 150);
    assert_int_equal(c.threads, 3);
    assert_string_equal(c.sink, "shm:/abc");
    assert_int_equal(c.slots, 5);
    assert_string_equal(c.group, "");
    assert_int_equal(sh_config_check(&c, err), SH_OK);
}

/* Each refusal names file, line, section and key; the config is left as it was. */
static void test_refusals(void **state)
{
    (void)state;
    static const struct {
        const char *text, *want;
    } cases[] = {
        {"[gating]\n\nmin_markers = x\n", "bad.ini:3: [gating] min_markers: 'x' is not a whole number"},
        {"[gating]\nmin_markers = 0\n", "bad.ini:2: [gating] min_markers:"},
        {"[gating]\nmax_residual_px = nan\n", "bad.ini:2: [gating] max_residual_px: 'nan'"},
        {"[sink]\nslots = 2\n", "bad.ini:2: [sink] slots:"},
        {"[method]\nname = spline\n", "bad.ini:2: [method] name: unknown method 'spline'"},
        {"[detect]\nids = 3-1\n", "bad.ini:2: [detect] ids:"},
        {"[detect]\nids = 2000\n", "bad.ini:2: [detect] ids:"},
        {"[source]\nrealtime = maybe\n", "bad.ini:2: [source] realtime:"},
        {"[source]\nspeed = 3\n", "bad.ini:2: [source] speed: unknown key"},
        {"[nosuch]\nx = 3\n", "bad.ini:2: [nosuch] x: unknown section"},
        {"[run]\nthreads = 2\nthreads = 99\n", "bad.ini:3: [run] threads:"},
        {"[run]\njust text\n", "bad.ini:2:"},
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        sh_config c, before;
        char err[SH_CONFIG_ERR];
        sh_config_default(&c);
        before = c;
        sh_status st = sh_config_parse_string(&c, cases[i].text, "bad.ini", err);
        if (st == SH_OK || strncmp(err, cases[i].want, strlen(cases[i].want)) != 0)
            fail_msg("case %zu: got '%s', want '%s...'", i, err, cases[i].want);
        assert_memory_equal(&c, &before, sizeof c);
    }
}

static void test_check_across_keys(void **state)
{
    (void)state;
    sh_config c;
    char err[SH_CONFIG_ERR];
    sh_config_default(&c);
    assert_int_equal(sh_config_set(&c, "detect", "ids", "0-3", "command line", 0, err), SH_OK);
    assert_int_not_equal(sh_config_check(&c, err), SH_OK);
    assert_non_null(strstr(err, "[detect] ids"));
    sh_config_default(&c);
    assert_int_equal(sh_config_set(&c, "sink", "display", "file:x", "command line", 0, err), SH_OK);
    assert_int_not_equal(sh_config_check(&c, err), SH_OK);
    assert_non_null(strstr(err, "[sink] display"));
    sh_config_default(&c);
    assert_int_equal(sh_config_set(&c, "gating", "min_markers", "2", "command line", 0, err), SH_OK);
    assert_int_not_equal(sh_config_check(&c, err), SH_OK);
    /* no line: the origin only */
    assert_int_not_equal(sh_config_set(&c, "run", "threads", "-1", "command line", 0, err), SH_OK);
    assert_string_equal(err, "command line: [run] threads: '-1' is not a whole number in 1..64");
}

static void test_options_and_write_round_trip(void **state)
{
    (void)state;
    const char *s, *k;
    int flag;
    assert_int_equal(sh_config_option("max-residual", &s, &k, &flag), 1);
    assert_string_equal(s, "gating");
    assert_string_equal(k, "max_residual_px");
    assert_int_equal(flag, 0);
    assert_int_equal(sh_config_option("loop", &s, &k, &flag), 1);
    assert_int_equal(flag, 1);
    assert_int_equal(sh_config_option("nosuch", &s, &k, &flag), 0);

    sh_config a, b;
    char err[SH_CONFIG_ERR];
    sh_config_default(&a);
    assert_int_equal(sh_config_set(&a, "method", "name", "rbf-local", "x", 0, err), SH_OK);
    assert_int_equal(sh_config_set(&a, "method", "sigma", "123.5", "x", 0, err), SH_OK);
    char *buf = NULL;
    size_t len = 0;
    FILE *f = open_memstream(&buf, &len);
    sh_config_write(&a, f);
    fclose(f);
    memset(&b, 0x5a, sizeof b);
    sh_config_default(&b);
    assert_int_equal(sh_config_parse_string(&b, buf, "written", err), SH_OK);
    free(buf);
    assert_string_equal(b.method_name, "rbf-local");
    assert_true(b.method.sigma == 123.5);
    assert_memory_equal(&a, &b, sizeof a);
}

static void test_files(void **state)
{
    (void)state;
    sh_config c;
    char err[SH_CONFIG_ERR];
    sh_config_default(&c);
    assert_int_equal(sh_config_load_file(&c, "/nonexistent/stillheart.ini", err), SH_EIO);
    assert_non_null(strstr(err, "/nonexistent/stillheart.ini: cannot open"));
    /* the shipped example: every key, every value valid */
    assert_int_equal(sh_config_load_file(&c, "firmware-config/stillheart.ini", err), SH_OK);
    assert_int_equal(sh_config_check(&c, err), SH_OK);
}

int main(int argc, char **argv)
{
    (void)argc;
    /* run from the repository root whatever the caller's directory (build/tests/...) */
    char path[4096];
    ssize_t n = readlink("/proc/self/exe", path, sizeof path - 1);
    if (n > 0 && access("firmware-config/stillheart.ini", R_OK) != 0) {
        path[n] = 0;
        for (int up = 0; up < 4; up++) {
            char *slash = strrchr(path, '/');
            if (!slash)
                break;
            *slash = 0;
            if (chdir(path) == 0 && access("firmware-config/stillheart.ini", R_OK) == 0)
                break;
        }
    }
    (void)argv;
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_defaults_check),
        cmocka_unit_test(test_parse_every_kind),
        cmocka_unit_test(test_refusals),
        cmocka_unit_test(test_check_across_keys),
        cmocka_unit_test(test_options_and_write_round_trip),
        cmocka_unit_test(test_files),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
