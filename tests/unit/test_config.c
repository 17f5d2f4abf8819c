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
    sh_interp_params m;
    sh_config_method(&c, &m);
    assert_int_equal(m.method, SH_METHOD_TPS);
    assert_int_equal(c.outside, SH_OUTSIDE_BLACK); /* the paper's black: outputs as before the key */
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
                       "[sink]\ndisplay = shm:/abc\nslots = 5\ngroup =\noutside = Dimmed-Raw\n";
    assert_int_equal(sh_config_parse_string(&c, text, "t.ini", err), SH_OK);
    assert_string_equal(c.camera[0].spec, "y4m:/tmp/x.y4m");
    assert_int_equal(c.realtime, 0);
    assert_int_equal(c.loop, 0);
    assert_int_equal(c.ids[0], 0);
    assert_int_equal(c.ids[1], 1);
    assert_int_equal(c.ids[3], 1);
    assert_int_equal(c.ids[4], 0);
    for (int i = 5; i <= 9; i++)
        assert_int_equal(c.ids[i], 1);
    assert_int_equal(c.ids[10], 0);
    sh_interp_params m;
    sh_config_method(&c, &m);
    assert_int_equal(m.method, SH_METHOD_GAUSSIAN);
    assert_true(m.sigma == 80.0);
    assert_int_equal(c.min_markers, 4);
    assert_true(c.max_residual_px == 2.5);
    assert_int_equal(c.dropout_ms, 150);
    assert_int_equal(c.threads, 3);
    assert_string_equal(c.sink, "shm:/abc");
    assert_int_equal(c.slots, 5);
    assert_string_equal(c.group, "");
    assert_int_equal(c.outside, SH_OUTSIDE_DIMMED_RAW);
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
        {"[camera1]\nspec = webcam\n", "bad.ini:2: [camera1] spec: 'webcam' is not v4l2:"},
        {"[camera0]\nspec = v4l2:\n", "bad.ini:2: [camera0] spec:"},
        {"[camera0]\n\nformat = yuv9\n", "bad.ini:3: [camera0] format: unknown pixel format 'yuv9'"},
        {"[camera2]\nsize = 640\n", "bad.ini:2: [camera2] size: '640' is not WIDTHxHEIGHT"},
        {"[camera2]\nsize = 0x480\n", "bad.ini:2: [camera2] size:"},
        {"[camera0]\nfps = 0/1\n", "bad.ini:2: [camera0] fps: '0/1' is not a frame rate"},
        {"[camera0]\nfps = 30/0\n", "bad.ini:2: [camera0] fps:"},
        {"[camera0]\nfps = 2000\n", "bad.ini:2: [camera0] fps:"},
        {"[camera3]\nexposure = short\n", "bad.ini:2: [camera3] exposure: 'short' is not auto or a whole number"},
        {"[camera1]\nwhite_balance = 100\n", "bad.ini:2: [camera1] white_balance:"},
        {"[camera4]\nspec = y4m:x\n", "bad.ini:2: [camera4] spec: unknown section"},
        {"[source]\noutput = 4\n", "bad.ini:2: [source] output:"},
        {"[trigger]\nmode = sideways\n", "bad.ini:2: [trigger] mode: 'sideways' is not one of off|out|in"},
        {"[trigger]\npolarity = up\n", "bad.ini:2: [trigger] polarity:"},
        {"[trigger]\npulse_us = 0\n", "bad.ini:2: [trigger] pulse_us:"},
        {"[sink]\n\noutside = grey\n", "bad.ini:3: [sink] outside: 'grey' is not one of black|dimmed-raw"},
        {"[sink]\noutside =\n", "bad.ini:2: [sink] outside: '' is not one of black|dimmed-raw"},
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

/* Cameras and trigger: values as written, [source] spec is camera 0's, the option names. */
static void test_cameras_and_trigger(void **state)
{
    (void)state;
    sh_config c;
    char err[SH_CONFIG_ERR];
    sh_config_default(&c);
    assert_int_equal(sh_config_cameras(&c), 1);
    assert_true(c.camera[0].exposure == SH_CONFIG_CTRL_UNSET);
    const char *text = "[source]\nrealtime = no\noutput = 1\nsync_tolerance_ms = 4.5\nsync_wait_ms = 80\n"
                       "camera_timeout_ms = 500\nqueue_ms = 80\n"
                       "[camera0]\nspec = v4l2:/dev/video0\nformat = YUYV\nsize = 1920x1080\nfps = 30000/1001\n"
                       "exposure = 120\ngain = 0\nwhite_balance = 4600\n"
                       "[camera1]\nspec = libcamera:imx219\nformat = mjpeg\nsize = 640X480\nfps = 29.97\n"
                       "exposure = auto\n"
                       "[trigger]\nmode = OUT\nchip = /dev/gpiochip1\nline = 17\npolarity = low\nfps = 30\n"
                       "pulse_us = 2000\noffset_us = -1500\n";
    assert_int_equal(sh_config_parse_string(&c, text, "t.ini", err), SH_OK);
    assert_int_equal(sh_config_check(&c, err), SH_OK);
    assert_int_equal(sh_config_cameras(&c), 2);
    assert_string_equal(c.camera[0].spec, "v4l2:/dev/video0");
    assert_string_equal(c.camera[0].format, "YUYV");
    assert_int_equal(c.camera[0].width, 1920);
    assert_int_equal(c.camera[0].height, 1080);
    assert_int_equal(c.camera[0].fps_num, 30000);
    assert_int_equal(c.camera[0].fps_den, 1001);
    assert_int_equal(c.camera[0].exposure, 120);
    assert_int_equal(c.camera[0].gain, 0);
    assert_int_equal(c.camera[0].white_balance, 4600);
    assert_string_equal(c.camera[1].spec, "libcamera:imx219");
    assert_int_equal(c.camera[1].width, 640);
    assert_int_equal(c.camera[1].fps_num, 2997); /* 29.97 = 2997/100 */
    assert_int_equal(c.camera[1].fps_den, 100);
    assert_true(c.camera[1].exposure == SH_CONFIG_CTRL_UNSET);
    assert_int_equal(c.output_camera, 1);
    assert_true(c.sync_tolerance_ms == 4.5 && c.sync_wait_ms == 80);
    assert_int_equal(c.camera_timeout_ms, 500);
    assert_int_equal(c.queue_ms, 80);
    assert_int_equal(c.trigger, SH_TRIGGER_OUT);
    assert_string_equal(c.trigger_chip, "/dev/gpiochip1");
    assert_int_equal(c.trigger_line, 17);
    assert_int_equal(c.trigger_active_low, 1);
    assert_true(c.trigger_fps == 30);
    assert_int_equal(c.trigger_pulse_us, 2000);
    assert_int_equal(c.trigger_offset_us, -1500);
    /* [source] spec is camera 0's */
    assert_int_equal(sh_config_set(&c, "source", "spec", "y4m:a.y4m", "x", 0, err), SH_OK);
    assert_string_equal(c.camera[0].spec, "y4m:a.y4m");

    /* written back and read again: the same */
    char *buf = NULL;
    size_t len = 0;
    FILE *f = open_memstream(&buf, &len);
    sh_config_write(&c, f);
    fclose(f);
    assert_null(strstr(buf, "[camera2]")); /* absent cameras are not written */
    sh_config d;
    sh_config_default(&d);
    assert_int_equal(sh_config_parse_string(&d, buf, "written", err), SH_OK);
    free(buf);
    assert_int_equal(sh_config_changes(&c, &d), 0);

    const char *sec, *key;
    int flag = 1;
    assert_int_equal(sh_config_option("camera2-white-balance", &sec, &key, &flag), 1);
    assert_string_equal(sec, "camera2");
    assert_string_equal(key, "white_balance");
    assert_int_equal(flag, 0);
    assert_int_equal(sh_config_option("trigger-pulse-us", &sec, &key, &flag), 1);
    assert_string_equal(key, "pulse_us");
    assert_int_equal(sh_config_option("source", &sec, &key, &flag), 1);
    assert_string_equal(sec, "source");
    assert_int_equal(sh_config_option("camera4-spec", &sec, &key, &flag), 0);
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
    /* cameras from 0 without gaps; the output camera among them; a trigger needs a chip and a
     * pulse shorter than its period */
    sh_config_default(&c);
    assert_int_equal(sh_config_set(&c, "camera2", "spec", "y4m:b.y4m", "x", 0, err), SH_OK);
    assert_int_not_equal(sh_config_check(&c, err), SH_OK);
    assert_non_null(strstr(err, "[camera2] spec: set while [camera1] spec is empty"));
    sh_config_default(&c);
    assert_int_equal(sh_config_set(&c, "source", "output", "1", "x", 0, err), SH_OK);
    assert_int_not_equal(sh_config_check(&c, err), SH_OK);
    assert_non_null(strstr(err, "[source] output: camera 1, but 1 camera is configured"));
    sh_config_default(&c);
    assert_int_equal(sh_config_set(&c, "trigger", "mode", "in", "x", 0, err), SH_OK);
    assert_int_equal(sh_config_check(&c, err), SH_OK);
    assert_int_equal(sh_config_set(&c, "trigger", "chip", "", "x", 0, err), SH_OK);
    assert_int_not_equal(sh_config_check(&c, err), SH_OK);
    assert_non_null(strstr(err, "[trigger] chip: empty"));
    sh_config_default(&c);
    assert_int_equal(sh_config_set(&c, "trigger", "mode", "out", "x", 0, err), SH_OK);
    assert_int_equal(sh_config_set(&c, "trigger", "fps", "100", "x", 0, err), SH_OK);
    assert_int_equal(sh_config_set(&c, "trigger", "pulse_us", "10000", "x", 0, err), SH_OK); /* = 1/100 s */
    assert_int_not_equal(sh_config_check(&c, err), SH_OK);
    assert_non_null(strstr(err, "[trigger] pulse_us"));
    assert_int_equal(sh_config_set(&c, "trigger", "pulse_us", "9999", "x", 0, err), SH_OK);
    assert_int_equal(sh_config_check(&c, err), SH_OK);
    /* no line: the origin only */
    assert_int_not_equal(sh_config_set(&c, "run", "threads", "-1", "command line", 0, err), SH_OK);
    assert_string_equal(err, "command line: [run] threads: '-1' is not a whole number in 1..64");
}

/* The processing side's keys: record FILE.y4m or png:DIR, the control socket's path length (a
 * sockaddr_un holds 107 bytes and the NUL), the tracker's 64 ids, calibration written back. */
static void test_processing_keys(void **state)
{
    (void)state;
    sh_config c;
    char err[SH_CONFIG_ERR];
    const char *ok_rec[] = {"shown.y4m", "png:frames", "png:/var/lib/stillheart/png"};
    const char *bad_rec[] = {"png:", "shown.avi", "png"};
    for (int i = 0; i < 3; i++) {
        sh_config_default(&c);
        assert_int_equal(sh_config_set(&c, "sink", "record", ok_rec[i], "x", 0, err), SH_OK);
        assert_int_equal(sh_config_check(&c, err), SH_OK);
        sh_config_default(&c);
        assert_int_equal(sh_config_set(&c, "sink", "record", bad_rec[i], "x", 0, err), SH_OK);
        assert_int_not_equal(sh_config_check(&c, err), SH_OK);
        assert_non_null(strstr(err, "[sink] record"));
    }
    char path[130];
    memset(path, 'a', sizeof path);
    path[0] = '/';
    path[107] = 0; /* 107 bytes: fits */
    sh_config_default(&c);
    assert_int_equal(sh_config_set(&c, "run", "control", path, "x", 0, err), SH_OK);
    assert_int_equal(sh_config_check(&c, err), SH_OK);
    path[107] = 'a';
    path[108] = 0;
    assert_int_equal(sh_config_set(&c, "run", "control", path, "x", 0, err), SH_OK);
    assert_int_not_equal(sh_config_check(&c, err), SH_OK);
    assert_non_null(strstr(err, "[run] control"));
    sh_config_default(&c);
    assert_int_equal(sh_config_set(&c, "detect", "ids", "0-64", "x", 0, err), SH_OK); /* 65 */
    assert_int_not_equal(sh_config_check(&c, err), SH_OK);
    assert_non_null(strstr(err, "at most 64"));
    assert_int_equal(sh_config_set(&c, "detect", "ids", "0-63", "x", 0, err), SH_OK);
    assert_int_equal(sh_config_check(&c, err), SH_OK);
    const char *section, *key;
    int flag;
    assert_true(sh_config_option("control", &section, &key, &flag) && !strcmp(key, "control") && !flag);
    assert_true(sh_config_option("calibration", &section, &key, &flag) && !strcmp(section, "method"));
    assert_int_equal(sh_config_set(&c, "method", "calibration", "rig.yaml", "x", 0, err), SH_OK);
    assert_int_equal(sh_config_set(&c, "run", "control", "/run/stillheart/control", "x", 0, err), SH_OK);
    char *buf = NULL;
    size_t len = 0;
    FILE *f = open_memstream(&buf, &len);
    sh_config_write(&c, f);
    fclose(f);
    assert_non_null(strstr(buf, "calibration = rig.yaml\n"));
    assert_non_null(strstr(buf, "control = /run/stillheart/control\n"));
    free(buf);
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
    assert_int_equal(sh_config_set(&a, "sink", "outside", "dimmed-raw", "x", 0, err), SH_OK);
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
    sh_interp_params m;
    sh_config_method(&b, &m);
    assert_true(m.sigma == 123.5);
    assert_int_equal(b.outside, SH_OUTSIDE_DIMMED_RAW);
    assert_int_equal(sh_config_changes(&a, &b), 0);
}

/* The effect classes as docs/daemon.md names them ("When each key's change takes effect"). */
static unsigned effect_from_doc(const char *word)
{
    static const struct {
        const char *word;
        unsigned effect;
    } words[] = {{"live", SH_CONFIG_LIVE},       {"gating", SH_CONFIG_GATING}, {"cameras", SH_CONFIG_SOURCE},
                 {"processing", SH_CONFIG_PROCESSING}, {"display", SH_CONFIG_DISPLAY}, {"record", SH_CONFIG_RECORD},
                 {"control", SH_CONFIG_CONTROL},
                 {"output", SH_CONFIG_V4L2}};
    for (size_t i = 0; i < sizeof words / sizeof words[0]; i++)
        if (!strcmp(word, words[i].word))
            return words[i].effect;
    fail_msg("docs/daemon.md: unknown effect '%s'", word);
    return 0;
}

/* The documented effect of [section] key ([cameraN] for cameras 0..3); 0 when the docs have no row. */
static unsigned documented_effect(const char *section, const char *key)
{
    char sec[32];
    snprintf(sec, sizeof sec, "%s", !strncmp(section, "camera", 6) ? "cameraN" : section);
    FILE *f = fopen("docs/daemon.md", "r");
    assert_non_null(f);
    char line[512], want[128], word[32];
    snprintf(want, sizeof want, "| `[%s] %s` | ", sec, key);
    unsigned effect = 0;
    while (fgets(line, sizeof line, f))
        if (!strncmp(line, want, strlen(want)) && sscanf(line + strlen(want), "%31[a-z]", word) == 1)
            effect = effect_from_doc(word);
    fclose(f);
    return effect;
}

/* Every key of the table has an effect, one, and the one docs/daemon.md gives it. */
static void test_every_key_has_its_documented_effect(void **state)
{
    (void)state;
    const char *section, *key;
    sh_config_effect effect;
    int n = 0;
    for (int i = 0; sh_config_key(i, &section, &key, &effect); i++, n++) {
        unsigned doc = documented_effect(section, key);
        if (!doc)
            fail_msg("[%s] %s: no row in docs/daemon.md's table of effects", section, key);
        if (!effect || (effect & (effect - 1)))
            fail_msg("[%s] %s: effect %#x is not one class", section, key, (unsigned)effect);
        if (effect != doc)
            fail_msg("[%s] %s: the table says %#x, docs/daemon.md %#x", section, key, (unsigned)effect, doc);
    }
    assert_true(n >= 60); /* 4 cameras x 7 keys and the rest: the walk saw the table */
}

/* Changing each key alone reports its documented class and nothing else; copying that class
 * over undoes it; the log's description names the option. Values: the first of a list that the
 * key takes and that differs from the default. */
static void test_changing_each_key_reports_its_effect(void **state)
{
    (void)state;
    static const char *const values[] = {"y4m:other.y4m", "nv12",  "640x480", "25",     "keep", "out",
                                         "low",           "no",    "7",       "2.5",    "gaussian",
                                         "1,3",           "1",     "4600",    "0",      "yes",
                                         "dimmed-raw",    "stereo", "tb"};
    const char *section, *key;
    sh_config_effect effect;
    for (int i = 0; sh_config_key(i, &section, &key, &effect); i++) {
        unsigned doc = documented_effect(section, key);
        sh_config a, b;
        char err[SH_CONFIG_ERR];
        sh_config_default(&a);
        int changed = 0;
        for (size_t v = 0; v < sizeof values / sizeof values[0] && !changed; v++) {
            b = a;
            changed = sh_config_set(&b, section, key, values[v], "x", 0, err) == SH_OK && sh_config_changes(&a, &b);
        }
        if (!changed)
            fail_msg("[%s] %s: no test value changes it", section, key);
        if (sh_config_changes(&a, &b) != doc)
            fail_msg("[%s] %s: a change reports %#x, docs/daemon.md says %#x", section, key, sh_config_changes(&a, &b),
                     doc);
        char text[512] = "";
        sh_config_describe(&a, &b, doc, text, sizeof text);
        if (!strstr(text, " -> "))
            fail_msg("[%s] %s: described as '%s'", section, key, text);
        char other[256] = "";
        sh_config_describe(&a, &b, ~doc, other, sizeof other);
        if (other[0])
            fail_msg("[%s] %s: other classes described: '%s'", section, key, other);
        sh_config_copy_keys(&a, &b, doc);
        assert_int_equal(sh_config_changes(&a, &b), 0);
    }
}

static void test_files(void **state)
{
    (void)state;
    sh_config c;
    char err[SH_CONFIG_ERR];
    sh_config_default(&c);
    assert_int_equal(sh_config_load_file(&c, "/nonexistent/stillheart.ini", err), SH_EIO);
    assert_non_null(strstr(err, "/nonexistent/stillheart.ini: cannot open"));
    /* the shipped example: every key, every value valid; it names no camera (an unedited install
     * names no file that is not there), and with one it runs */
    assert_int_equal(sh_config_load_file(&c, "firmware-config/stillheart.ini", err), SH_OK);
    assert_int_equal(sh_config_cameras(&c), 0);
    assert_int_equal(sh_config_check(&c, err), SH_EINVAL);
    assert_non_null(strstr(err, "[camera0] spec: empty, no camera configured"));
    assert_string_equal(c.control, "/run/stillheart/control");
    assert_string_equal(c.control_group, "");
    assert_int_equal(sh_config_set(&c, "camera0", "spec", "v4l2:/dev/video0", "x", 0, err), SH_OK);
    assert_int_equal(sh_config_check(&c, err), SH_OK);
    /* [run] control_group: a group name, also --control-group */
    const char *section, *key;
    int flag;
    assert_true(sh_config_option("control-group", &section, &key, &flag) && !strcmp(section, "run") &&
                !strcmp(key, "control_group") && !flag);
    assert_int_equal(sh_config_set(&c, "run", "control_group", "surgeons", "x", 0, err), SH_OK);
    assert_string_equal(c.control_group, "surgeons");
}

/* "[method] name = METHOD" on line 2 and "KEY = VALUE" on line 5 of m.ini, parsed and checked. */
static sh_status check_file(const char *method, const char *section, const char *key, const char *value, char *err)
{
    sh_config c;
    char text[256];
    sh_config_default(&c);
    snprintf(text, sizeof text, "[method]\nname = %s\n\n[%s]\n%s = %s\n", method, section, key, value);
    assert_int_equal(sh_config_parse_string(&c, text, "m.ini", err), SH_OK);
    return sh_config_check(&c, err);
}

/* [method] values that could never make a model (issue 16), each refused by sh_config_check
 * with the place it was set: FILE:LINE from a file, the option and its value from the command
 * line. The bounds, from the modules that refuse them: the warp's grid spacing a power of two
 * (sh_warp_model_create); at most 10 B-spline levels, since even one coarse cell each way makes
 * (2^(L-1) + 3)^2 control points and 2^20 is the most a fit uses ((2^10 + 3)^2 = 1054729 at
 * L = 11); sigma, levels and smoothing only for the methods that use them (sh_interp_create);
 * min_markers at least 3 (the daemon makes no model from fewer). The nearest valid values pass. */
static void test_method_refusals(void **state)
{
    (void)state;
    static const struct {
        const char *method, *section, *key, *value, *option, *want;
    } bad[] = {
        {"tps", "method", "grid", "3", "grid", "3 px is not a power of two"},
        {"tps", "method", "grid", "0.5", "grid", "0.5 px is not a power of two"},
        {"tps", "method", "grid", "12", "grid", "12 px is not a power of two"},
        {"bspline", "method", "grid", "255", "grid", "255 px is not a power of two"},
        {"bspline", "method", "levels", "16", "levels", "bspline: 16 levels make a lattice of at least 1073938441 control points"},
        {"bspline", "method", "levels", "11", "levels", "bspline: 11 levels make a lattice of at least 1054729 control points"},
        {"tps", "method", "levels", "3", "levels", "tps: levels apply to bspline only"},
        {"tps", "method", "sigma", "50", "sigma", "tps: sigma applies to rbf-local and gaussian only"},
        {"bspline", "method", "sigma", "1", "sigma", "bspline: sigma applies to rbf-local and gaussian only"},
        {"gaussian", "method", "sigma", "0", "sigma", "gaussian: sigma must be finite and > 0"},
        {"rbf-local-pure", "method", "sigma", "0", "sigma", "rbf-local: sigma must be finite and > 0"},
        {"affine", "method", "smoothing", "1", "smoothing", "affine: smoothing applies to the RBF methods only"},
        {"bspline", "method", "smoothing", "0.5", "smoothing", "bspline: smoothing applies to the RBF methods only"},
        {"affine", "gating", "min_markers", "2", "min-markers", "2 is fewer than affine needs (3)"},
        {"gaussian-pure", "gating", "min_markers", "1", "min-markers", "1 is fewer than gaussian-pure needs (3)"},
        /* the stereo pair: a view of the 3D surface, so only with a calibration; its keys only with it */
        {"tps", "method", "view", "stereo", "view", "stereo needs a calibrated rig ([method] calibration)"},
        {"tps", "method", "baseline", "20", "baseline", "20 mm, but only the stereo view has eyes"},
        {"tps", "method", "layout", "tb-half", "layout", "only the stereo view has a layout"},
        /* the landmarks' smoothing: only with landmarks (and, below, a tps map) */
        {"tps", "track", "landmarks_smoothing", "500", "landmarks-smoothing", "500, but there are no landmarks"},
        {"tps", "track", "landmarks_refine", "0", "landmarks-refine", "0, but there are no landmarks"},
        {"tps", "track", "landmarks_confirm", "1", "landmarks-confirm", "1, but there are no landmarks"},
        /* carried frames rest on the landmarks */
        {"tps", "gating", "landmarks_carry", "yes", "landmarks-carry", "yes, but there are no landmarks"},
    };
    static const struct {
        const char *method, *section, *key, *value;
    } good[] = {
        {"tps", "method", "grid", "0"},          {"tps", "method", "grid", "1"},
        {"tps", "method", "grid", "2"},          {"tps", "method", "grid", "4"},
        {"tps", "method", "grid", "16"},         {"bspline", "method", "grid", "256"},
        {"bspline", "method", "levels", "10"},   {"bspline", "method", "levels", "0"},
        {"gaussian", "method", "sigma", "0.001"}, {"rbf-local", "method", "sigma", "1e6"},
        {"tps", "method", "sigma", "-1"},        {"tps-pure", "method", "smoothing", "1"},
        {"affine", "gating", "min_markers", "3"},  {"tps", "method", "view", "reference"},
        {"tps", "method", "baseline", "10"},     {"tps", "method", "layout", "sbs"},
        {"bspline", "track", "landmarks_smoothing", "1000"},
    };
    char err[SH_CONFIG_ERR], want[SH_CONFIG_ERR];
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        snprintf(want, sizeof want, "m.ini:5: [%s] %s: %s", bad[i].section, bad[i].key, bad[i].want);
        if (check_file(bad[i].method, bad[i].section, bad[i].key, bad[i].value, err) != SH_EINVAL ||
            strncmp(err, want, strlen(want)))
            fail_msg("file case %zu: got '%s', want '%s...'", i, err, want);
        sh_config c;
        sh_config_default(&c);
        assert_int_equal(sh_config_set(&c, "method", "name", bad[i].method, "command line", 0, err), SH_OK);
        assert_int_equal(sh_config_set(&c, bad[i].section, bad[i].key, bad[i].value, "command line", 0, err), SH_OK);
        snprintf(want, sizeof want, "command line: --%s %s: %s", bad[i].option, bad[i].value, bad[i].want);
        if (sh_config_check(&c, err) != SH_EINVAL || strncmp(err, want, strlen(want)))
            fail_msg("command-line case %zu: got '%s', want '%s...'", i, err, want);
    }
    for (size_t i = 0; i < sizeof good / sizeof good[0]; i++)
        if (check_file(good[i].method, good[i].section, good[i].key, good[i].value, err) != SH_OK)
            fail_msg("valid case %zu (%s %s = %s) refused: %s", i, good[i].method, good[i].key, good[i].value, err);
    /* with landmarks: a tps map takes the landmarks' smoothing, in 2D and in 3D (its surface and
     * displacement), bspline (which interpolates them) refuses it */
    const char *methods[] = {"tps", "bspline", "tps"};
    for (int k = 0; k < 3; k++) {
        sh_config c;
        sh_config_default(&c);
        if (k == 2) snprintf(c.calibration, sizeof c.calibration, "rig.yaml");
        assert_int_equal(sh_config_set(&c, "method", "name", methods[k], "command line", 0, err), SH_OK);
        assert_int_equal(sh_config_set(&c, "track", "landmarks", "100", "command line", 0, err), SH_OK);
        assert_int_equal(sh_config_set(&c, "track", "landmarks_smoothing", "500", "command line", 0, err), SH_OK);
        assert_int_equal(sh_config_check(&c, err), k == 1 ? SH_EINVAL : SH_OK);
        if (k == 1) assert_non_null(strstr(err, "500, but bspline interpolates the landmarks"));
    }
    /* carried frames: with landmarks in 2D, not in 3D (every camera's landmarks need the markers' map) */
    for (int k = 0; k < 2; k++) {
        sh_config c;
        sh_config_default(&c);
        assert_int_equal(sh_config_set(&c, "track", "landmarks", "100", "command line", 0, err), SH_OK);
        assert_int_equal(sh_config_set(&c, "gating", "landmarks_carry", "yes", "command line", 0, err), SH_OK);
        if (k) snprintf(c.calibration, sizeof c.calibration, "rig.yaml");
        assert_int_equal(sh_config_check(&c, err), k ? SH_EINVAL : SH_OK);
        if (k) assert_non_null(strstr(err, "yes, but in 3D ([method] calibration)"));
    }
}

/* Where a key was set: the last place wins, a key's other name is recorded under it, a default
 * has no place, more files than the table holds fall back to that, and the place is no part of
 * the value (a reload of the same values from other lines changes nothing). */
static void test_origins(void **state)
{
    (void)state;
    sh_config a, b;
    char err[SH_CONFIG_ERR], where[SH_CONFIG_ERR];
    sh_config_default(&a);
    sh_config_where(&a, "method", "grid", where, sizeof where);
    assert_string_equal(where, "[method] grid");
    assert_int_equal(sh_config_parse_string(&a, "[source]\nspec = y4m:a.y4m\n[method]\n\ngrid = 8\n", "a.ini", err), SH_OK);
    sh_config_where(&a, "method", "grid", where, sizeof where);
    assert_string_equal(where, "a.ini:5: [method] grid");
    sh_config_where(&a, "camera0", "spec", where, sizeof where);
    assert_string_equal(where, "a.ini:2: [camera0] spec");
    assert_int_equal(sh_config_set(&a, "method", "grid", "16", "command line", 0, err), SH_OK);
    sh_config_where(&a, "method", "grid", where, sizeof where);
    assert_string_equal(where, "command line: --grid 16");
    sh_config_where(&a, "method", "nosuch", where, sizeof where);
    assert_string_equal(where, "[method] nosuch");

    sh_config_default(&b);
    assert_int_equal(sh_config_parse_string(&b, "; moved down\n\n[method]\ngrid = 16\n[source]\nspec = y4m:a.y4m\n",
                                            "b.ini", err), SH_OK);
    assert_int_equal(sh_config_changes(&a, &b), 0);

    const char *files[] = {"1.ini", "2.ini", "3.ini", "4.ini", "5.ini"};
    sh_config_default(&a);
    for (int i = 0; i < 5; i++)
        assert_int_equal(sh_config_set(&a, "method", "grid", "4", files[i], 7, err), SH_OK);
    sh_config_where(&a, "method", "grid", where, sizeof where);
    assert_string_equal(where, "[method] grid");
    assert_int_equal(sh_config_set(&a, "method", "grid", "4", "2.ini", 9, err), SH_OK);
    sh_config_where(&a, "method", "grid", where, sizeof where);
    assert_string_equal(where, "2.ini:9: [method] grid");
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
        cmocka_unit_test(test_cameras_and_trigger),
        cmocka_unit_test(test_check_across_keys),
        cmocka_unit_test(test_method_refusals),
        cmocka_unit_test(test_origins),
        cmocka_unit_test(test_processing_keys),
        cmocka_unit_test(test_options_and_write_round_trip),
        cmocka_unit_test(test_files),
        cmocka_unit_test(test_every_key_has_its_documented_effect),
        cmocka_unit_test(test_changing_each_key_reports_its_effect),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
