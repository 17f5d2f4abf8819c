/* The `stillheart warp` command end to end: a synthetic video and its points file in, the
 * stabilized video, the .npy map and (--metric) the e figures out; and its errors for bad
 * input. */
#include <libgen.h>
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cmocka.h>

#include "shell.h"
#include "stillheart/points.h"
#include "stillheart/y4m.h"
#include "synth.h"

enum { W = 320, H = 200, FRAMES = 6, MARKERS = 12 };

static char binary[4200], bindir[4096], dir[] = "/tmp/stillheart-cli-XXXXXX";
static synth_motion motion = {W, H, 8};
static double ref_xy[2 * MARKERS];

static char *path(const char *name)
{
    static char buf[8][4200];
    static int next;
    char *p = buf[next++ % 8];
    snprintf(p, 4200, "%s/%s", dir, name);
    return p;
}

/* Runs the command line; returns the exit status, stdout and stderr in the given files. */
static int run(const char *args)
{
    char cmd[16384];
    snprintf(cmd, sizeof cmd, "%s %s >%s 2>%s", binary, args, path("stdout"), path("stderr"));
    int st = system(cmd);
    return WIFEXITED(st) ? WEXITSTATUS(st) : -1;
}

/* Runs a program of the build folder (stillheart-cat, ...) with args, as run. */
static int run_tool(const char *program, const char *args)
{
    char cmd[16384];
    snprintf(cmd, sizeof cmd, "%s/%s %s >%s 2>%s", bindir, program, args, path("stdout"), path("stderr"));
    int st = system(cmd);
    return WIFEXITED(st) ? WEXITSTATUS(st) : -1;
}

static int lines(const char *text)
{
    int n = 0;
    for (; *text; text++) n += *text == '\n';
    return n;
}

static char *slurp(const char *file)
{
    static char text[1 << 16];
    FILE *f = fopen(file, "rb");
    size_t n = f ? fread(text, 1, sizeof text - 1, f) : 0;
    if (f) fclose(f);
    text[n] = 0;
    return text;
}

static int setup(void **state)
{
    (void)state;
    assert_non_null(mkdtemp(dir));
    sh_y4m_header h = {.width = W, .height = H, .format = SH_PIX_I420, .fps_num = 25,
                       .fps_den = 1, .siting = SH_CHROMA_CENTER};
    strcpy(h.extra, "XCOLORRANGE=FULL");
    sh_y4m_writer *w;
    assert_int_equal(sh_y4m_writer_open(path("in.y4m"), &h, &w), SH_OK);
    sh_image img;
    assert_int_equal(sh_image_create(&img, SH_PIX_I420, W, H), SH_OK);
    synth_markers(&motion, MARKERS, 4, ref_xy);
    FILE *csv = fopen(path("points.csv"), "w");
    fprintf(csv, "frame,id,x,y\n");
    for (int t = 0; t < FRAMES; t++) {
        synth_render(&motion, (double)t / FRAMES, &img);
        assert_int_equal(sh_y4m_writer_write(w, &img), SH_OK);
        for (int i = 0; i < MARKERS; i++) {
            if (t == 3 && i == 5) continue; /* a marker missing in one frame */
            double x, y;
            synth_forward(&motion, (double)t / FRAMES, ref_xy[2 * i], ref_xy[2 * i + 1], &x, &y);
            fprintf(csv, "%d,%d,%.6f,%.6f\n", t, 100 + i, x, y);
        }
    }
    fclose(csv);
    assert_int_equal(sh_y4m_writer_close(w), SH_OK);
    sh_image_destroy(&img);
    return 0;
}

static int teardown(void **state)
{
    (void)state;
    char cmd[4200];
    snprintf(cmd, sizeof cmd, "%s %s", getenv("KEEP") ? "true" : "rm -rf", dir);
    return system(cmd);
}

/* Files a and b hold the same bytes. */
static int same_file(const char *a, const char *b)
{
    char cmd[9000];
    snprintf(cmd, sizeof cmd, "cmp -s '%s' '%s'", a, b);
    return system(cmd) == 0;
}

/* --metric (issue 20: off by default, it cost 3/4 of the run): without it nothing on stdout;
 * with it, --quiet included, the paper's e of input and output on stdout, the same figures as
 * stillheart-eval's on the same videos, and the same video written. */
static void test_warp_metric(void **state)
{
    (void)state;
    char args[8192];
    snprintf(args, sizeof args, "warp --method tps --points %s %s %s", path("points.csv"),
             path("in.y4m"), path("plain.y4m"));
    int rc = run(args);
    if (rc != 0) fail_msg("exit %d: %s", rc, slurp(path("stderr")));
    assert_string_equal(slurp(path("stdout")), "");
    assert_non_null(strstr(slurp(path("stderr")), "frames (0 unstabilized)"));

    snprintf(args, sizeof args, "warp --quiet --metric --method tps --points %s %s %s",
             path("points.csv"), path("in.y4m"), path("metric.y4m"));
    rc = run(args);
    if (rc != 0) fail_msg("--metric: exit %d: %s", rc, slurp(path("stderr")));
    assert_string_equal(slurp(path("stderr")), "");
    double e_in, e_out;
    int frames, pixels;
    assert_int_equal(sscanf(slurp(path("stdout")),
                            "residual motion e (lower is better): %lf -> %lf, %*[^(](%d frames, %d hull pixels)",
                            &e_in, &e_out, &frames, &pixels), 4);
    assert_true(e_out < 0.5 * e_in);
    assert_int_equal(frames, FRAMES);
    assert_true(same_file(path("plain.y4m"), path("metric.y4m")));

    snprintf(args, sizeof args, "--quiet --json --points %s %s %s", path("points.csv"), path("metric.y4m"),
             path("in.y4m"));
    assert_int_equal(run_tool("stillheart-eval", args), 0);
    const char *json = slurp(path("stdout"));
    assert_float_equal(e_out, test_json_num(json, "e_stabilized"), 5e-7); /* warp prints 6 decimals */
    assert_float_equal(e_in, test_json_num(json, "e_original"), 5e-7);
    assert_int_equal(pixels, (int)test_json_num(json, "pixels"));

    /* to standard output the video goes there, and e to standard error */
    snprintf(args, sizeof args, "warp --quiet --metric --points %s %s -", path("points.csv"), path("in.y4m"));
    assert_int_equal(run(args), 0);
    assert_true(same_file(path("plain.y4m"), path("stdout")));
    assert_non_null(strstr(slurp(path("stderr")), "residual motion e (lower is better): "));
}

static void test_warp_end_to_end(void **state)
{
    (void)state;
    char args[8192];
    snprintf(args, sizeof args, "warp --method tps --threads 2 --points %s %s %s --map-out %s",
             path("points.csv"), path("in.y4m"), path("out.y4m"), path("map.npy"));
    int rc = run(args);
    if (rc != 0) fail_msg("exit %d: %s", rc, slurp(path("stderr")));

    sh_y4m_reader *r;
    assert_int_equal(sh_y4m_reader_open(path("out.y4m"), &r), SH_OK);
    const sh_y4m_header *h = sh_y4m_reader_header(r);
    assert_int_equal(h->width, W);
    assert_int_equal(h->height, H);
    assert_int_equal(h->format, SH_PIX_I420);
    assert_non_null(strstr(h->extra, "XCOLORRANGE=FULL"));
    sh_image img;
    assert_int_equal(sh_image_create(&img, SH_PIX_I420, W, H), SH_OK);
    int frames = 0;
    while (sh_y4m_reader_read(r, &img) == SH_OK) frames++;
    assert_int_equal(frames, FRAMES);
    sh_y4m_reader_close(r);
    sh_image_destroy(&img);

    /* The map of the last frame: .npy float32 (H, W, 2), NaN outside the hull, and inside it
     * follows the true motion: its error is a small part of the motion itself (12 markers
     * cannot resolve the motion's bumps exactly, so not zero). */
    FILE *f = fopen(path("map.npy"), "rb");
    assert_non_null(f);
    unsigned char head[10];
    assert_int_equal(fread(head, 1, 10, f), 10);
    assert_memory_equal(head, "\x93NUMPY\x01\x00", 8);
    int hlen = head[8] | head[9] << 8;
    char dict[256] = {0};
    assert_true(hlen < 256);
    assert_int_equal(fread(dict, 1, (size_t)hlen, f), (size_t)hlen);
    assert_int_equal((10 + hlen) % 64, 0);
    assert_non_null(strstr(dict, "'descr': '<f4'"));
    char shape[64];
    snprintf(shape, sizeof shape, "'shape': (%d, %d, 2)", H, W);
    assert_non_null(strstr(dict, shape));
    float *map = malloc(sizeof(float) * 2 * W * H);
    assert_int_equal(fread(map, sizeof(float), 2 * W * H, f), 2 * W * H);
    fclose(f);
    assert_true(isnan(map[0]) && isnan(map[1])); /* corner pixel: outside the hull */
    double sum = 0, moved = 0;
    int inside = 0;
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++) {
            const float *m = map + 2 * (y * W + x);
            if (isnan(m[0])) continue;
            double tx, ty;
            synth_forward(&motion, (double)(FRAMES - 1) / FRAMES, x, y, &tx, &ty);
            sum += hypot(m[0] - tx, m[1] - ty);
            moved += hypot(x - tx, y - ty);
            inside++;
        }
    assert_true(inside > W * H / 4);
    printf("  map vs true motion: mean error %.3f px, mean motion %.3f px, %d hull pixels\n",
           sum / inside, moved / inside, inside);
    assert_true(sum < 0.25 * moved);
    free(map);
}

static void test_errors_name_the_problem(void **state)
{
    (void)state;
    char args[8192];
    snprintf(args, sizeof args, "warp --points %s/nothing.csv %s %s", dir, path("in.y4m"),
             path("x.y4m"));
    assert_int_not_equal(run(args), 0);
    assert_non_null(strstr(slurp(path("stderr")), "nothing.csv"));

    snprintf(args, sizeof args, "warp --method spline --points %s %s %s", path("points.csv"),
             path("in.y4m"), path("x.y4m"));
    assert_int_not_equal(run(args), 0);
    assert_non_null(strstr(slurp(path("stderr")), "spline"));

    snprintf(args, sizeof args, "warp --threads zero --points %s %s %s", path("points.csv"),
             path("in.y4m"), path("x.y4m"));
    assert_int_equal(run(args), 2);
    assert_non_null(strstr(slurp(path("stderr")), "--threads"));

    /* the landmarks' smoothing with a method that interpolates them does nothing: refused */
    snprintf(args, sizeof args, "warp --method bspline --landmark-smoothing 500 --points %s %s %s", path("points.csv"),
             path("in.y4m"), path("x.y4m"));
    assert_int_equal(run(args), 2);
    assert_non_null(strstr(slurp(path("stderr")), "bspline interpolates the landmarks"));
    /* warp3d: refused when neither the surface's nor the displacement's interpolant smooths, taken with tps */
    snprintf(args, sizeof args, "warp3d --method bspline --landmark-smoothing 500 --cameras %s --points %s %s %s",
             path("rig.yaml"), path("points.csv"), path("in.y4m"), path("x.y4m"));
    assert_int_equal(run(args), 2);
    assert_non_null(strstr(slurp(path("stderr")), "--landmark-smoothing: neither interpolant is an RBF"));
    snprintf(args, sizeof args, "warp3d --surface-method bspline --landmark-smoothing 500 --cameras %s --points %s %s %s",
             path("nothing.yaml"), path("points.csv"), path("in.y4m"), path("x.y4m"));
    assert_int_not_equal(run(args), 2); /* the displacement is tps: the option passes, the missing file fails */
    assert_non_null(strstr(slurp(path("stderr")), "nothing.yaml"));

    FILE *bad = fopen(path("bad.csv"), "w");
    fprintf(bad, "frame,id,x,y\n0,1,10,10\n0,2,abc,5\n");
    fclose(bad);
    snprintf(args, sizeof args, "warp --points %s %s %s", path("bad.csv"), path("in.y4m"),
             path("x.y4m"));
    assert_int_not_equal(run(args), 0);
    assert_non_null(strstr(slurp(path("stderr")), "bad.csv:3"));

    assert_int_equal(run("warp --help"), 0);
    assert_non_null(strstr(slurp(path("stdout")), "--map-out"));
}


/* Every program and subcommand keeps the one convention (issue 18): -h and --help print the
 * usage on stdout and nothing on stderr, exit 0; --version prints the version of
 * debian/changelog; an unknown option is one line on stderr naming it and the --help hint, exit
 * 2; a value option takes "--opt=VALUE" and "--opt VALUE" alike (a bad value is named in the
 * refusal either way). A program not built here (its library missing) is skipped. */
static const struct {
    const char *program, *sub, *name; /* binary in the build folder, subcommand, name in the hint */
    const char *value_opt, *bad_value;  /* a value option and a value it refuses (NULL: none) */
    int value_rc;                       /* the exit status of that refusal */
} programs[] = {
    {"stillheart", "", "stillheart", NULL, NULL, 0},
    {"stillheart", "warp", "stillheart warp", "--threads", "zero", 2},
    {"stillheart", "warp3d", "stillheart warp3d", "--threads", "zero", 2},
    {"stillheart", "detect", "stillheart detect", "--threads", "zero", 2},
    {"stillheart", "track", "stillheart track", "--fps", "zero", 2},
    {"stillheart", "record", "stillheart record", "--frames", "zero", 2},
    {"stillheart", "run", "stillheart run", "--max-frames", "zero", 2},
    {"stillheart", "ctl", "stillheart ctl", "--socket", "/nonexistent/zero", 3},
    {"stillheart-cat", "", "stillheart-cat", "--count", "zero", 2},
    {"stillheart-show", "", "stillheart-show", "--stale", "zero", 2},
    {"stillheart-eval", "", "stillheart-eval", "--reference", "zero", 2},
    {"stillheart-render", "", "stillheart-render", "--frames", "zero", 2},
    {"stillheart-synth", "", "stillheart-synth", "--frames", "zero", 2},
    {"stillheart-calib", "", "stillheart-calib", "--every", "zero", 2},
    {"stillheart-trackeval", "", "stillheart-trackeval", "--frames", "zero", 2},
    {"stillheart-vmprobe", "", "stillheart-vmprobe", NULL, NULL, 0},
};

/* The version in debian/changelog's first line, "stillheart (0.1.0) ...", of the source tree
 * (this binary's build folder's parent). */
static void changelog_version(char *out, size_t cap)
{
    char file[4200];
    snprintf(file, sizeof file, "%s/../debian/changelog", bindir);
    char *text = slurp(file), *open = strchr(text, '('), *close = open ? strchr(open, ')') : NULL;
    if (!open || !close) fail_msg("%s: no version in its first line", file);
    char *dash = memchr(open, '-', (size_t)(close - open)); /* the Debian revision, if any */
    if (dash) close = dash;
    snprintf(out, cap, "%.*s", (int)(close - open - 1), open + 1);
}

static void test_every_program_one_convention(void **state)
{
    (void)state;
    char version[64], args[8192], want[256];
    changelog_version(version, sizeof version);
    int checked = 0;
    for (size_t i = 0; i < sizeof programs / sizeof programs[0]; i++) {
        char exe[4200];
        snprintf(exe, sizeof exe, "%s/%s", bindir, programs[i].program);
        if (access(exe, X_OK)) {
            printf("  %s: not built here, skipped\n", programs[i].name);
            continue;
        }
        const char *sub = programs[i].sub, *name = programs[i].name;
        for (int k = 0; k < 2; k++) {
            snprintf(args, sizeof args, "%s %s", sub, k ? "--help" : "-h");
            int rc = run_tool(programs[i].program, args);
            if (rc != 0 || !strstr(slurp(path("stdout")), "usage:") || *slurp(path("stderr")))
                fail_msg("%s %s: exit %d, stderr '%s'", name, k ? "--help" : "-h", rc, slurp(path("stderr")));
        }
        snprintf(args, sizeof args, "%s --version", sub);
        snprintf(want, sizeof want, "%s %s\n", name, version);
        if (run_tool(programs[i].program, args) != 0 || strcmp(slurp(path("stdout")), want))
            fail_msg("%s --version: '%s', not '%s'", name, slurp(path("stdout")), want);

        snprintf(args, sizeof args, "%s --no-such-option", sub);
        int rc = run_tool(programs[i].program, args);
        char *err = slurp(path("stderr"));
        snprintf(want, sizeof want, "'%s --help'", name);
        if (rc != 2 || lines(err) != 1 || !strstr(err, "--no-such-option") || !strstr(err, want))
            fail_msg("%s --no-such-option: exit %d, stderr '%s'", name, rc, err);

        for (int k = 0; programs[i].value_opt && k < 2; k++) {
            /* ctl needs a command to reach the socket */
            snprintf(args, sizeof args, "%s %s%s%s%s", sub, programs[i].value_opt, k ? " " : "=", programs[i].bad_value,
                     !strcmp(sub, "ctl") ? " status" : "");
            rc = run_tool(programs[i].program, args);
            err = slurp(path("stderr"));
            if (rc != programs[i].value_rc || lines(err) != 1 || !strstr(err, programs[i].bad_value))
                fail_msg("%s %s%s%s: exit %d, stderr '%s'", name, programs[i].value_opt, k ? " " : "=",
                         programs[i].bad_value, rc, err);
        }
        checked++;
    }
    printf("  %d programs and subcommands checked\n", checked);
    assert_true(checked >= 9); /* stillheart, its 7 subcommands, stillheart-synth: always built */
}

/* --log-level and --quiet choose what is said on stderr: warp's summary is info, its refusals
 * errors; debug shows at least what info shows. */
static void test_log_level(void **state)
{
    (void)state;
    char args[8192];
    const char *levels[] = {"error", "warning", "info", "debug"};
    size_t len[4];
    for (int k = 0; k < 4; k++) {
        snprintf(args, sizeof args, "warp --log-level %s --points=%s %s %s", levels[k], path("points.csv"),
                 path("in.y4m"), path("x.y4m"));
        int rc = run(args);
        if (rc != 0) fail_msg("--log-level %s: exit %d: %s", levels[k], rc, slurp(path("stderr")));
        len[k] = strlen(slurp(path("stderr")));
        int summary = strstr(slurp(path("stderr")), "frames (") != NULL;
        if (summary != (k >= 2)) fail_msg("--log-level %s: summary %s", levels[k], summary ? "shown" : "missing");
    }
    assert_int_equal(len[0], 0);
    assert_true(len[3] > len[2]);
    assert_non_null(strstr(slurp(path("stderr")), "frame 0: 12 of the reference frame's 12 markers, warped"));
    snprintf(args, sizeof args, "warp --quiet --points %s %s %s", path("points.csv"), path("in.y4m"), path("x.y4m"));
    assert_int_equal(run(args), 0);
    assert_string_equal(slurp(path("stderr")), "");
    /* an error is said at every level */
    snprintf(args, sizeof args, "warp --log-level=error --points %s/none.csv %s %s", dir, path("in.y4m"), path("x.y4m"));
    assert_int_equal(run(args), 1);
    assert_non_null(strstr(slurp(path("stderr")), "none.csv"));
    assert_int_equal(run("warp --log-level loud"), 2);
    assert_non_null(strstr(slurp(path("stderr")), "loud"));
}

/* python3's json module reads file; expr (Python, over the document d) must be true. Skipped
 * without python3. */
static void assert_json(const char *file, const char *expr)
{
    if (system("command -v python3 >/dev/null 2>&1") != 0) {
        printf("  python3 missing: %s not parsed\n", file);
        return;
    }
    char cmd[16384];
    snprintf(cmd, sizeof cmd,
             "python3 -c 'import json, sys; d = json.load(open(sys.argv[1])); sys.exit(0 if (%s) else 3)' %s",
             expr, file);
    int st = system(cmd);
    if (!WIFEXITED(st) || WEXITSTATUS(st) != 0)
        fail_msg("%s: not JSON or not (%s): %s", file, expr, slurp(file));
}

/* The last line of a file, into a file of its own (the JSON line after log lines). */
static void last_line(const char *from, const char *to)
{
    char *text = slurp(from);
    size_t n = strlen(text);
    while (n && text[n - 1] == '\n') text[--n] = 0;
    char *start = strrchr(text, '\n');
    FILE *f = fopen(to, "w");
    assert_non_null(f);
    fputs(start ? start + 1 : text, f);
    fclose(f);
}

/* --json of detect, stillheart-eval, track --stats and run --stats: JSON python3 reads, with the figures of the
 * video made in setup (FRAMES frames, no tags in it). */
static void test_json_outputs(void **state)
{
    (void)state;
    char args[8192], expr[512];
    snprintf(args, sizeof args, "detect --json %s", path("in.y4m"));
    assert_int_equal(run(args), 0);
    rename(path("stdout"), path("detect.json"));
    snprintf(expr, sizeof expr, "d[\"frames\"] == %d and d[\"detections\"] == [] and d[\"error\"] is None", FRAMES);
    assert_json(path("detect.json"), expr);

    snprintf(args, sizeof args, "--json --points=%s %s", path("points.csv"), path("in.y4m"));
    assert_int_equal(run_tool("stillheart-eval", args), 0);
    rename(path("stdout"), path("eval.json"));
    snprintf(expr, sizeof expr, "d[\"frames\"] == %d and d[\"e_original\"] is None and d[\"geometric\"] is None and "
             "d[\"e_stabilized\"] > 0", FRAMES);
    assert_json(path("eval.json"), expr);

    snprintf(args, sizeof args, "track --ids 0-3 --stats --json %s", path("in.y4m"));
    int rc = run(args);
    if (rc != 0) fail_msg("track --stats --json: exit %d: %s", rc, slurp(path("stderr")));
    last_line(path("stderr"), path("track.json"));
    snprintf(expr, sizeof expr,
             "d[\"frames\"] == %d and d[\"ids\"] == [0, 1, 2, 3] and d[\"heart_hz\"] is None and "
             "d[\"detections\"][\"used\"] == 0 and d[\"calibration\"] is None", FRAMES);
    assert_json(path("track.json"), expr);
    assert_string_equal(slurp(path("stdout")), "frame,id,x,y\n"); /* the points stay on stdout */
    assert_int_equal(run("track --json -"), 2);                    /* --json goes with --stats */

    snprintf(args, sizeof args, "run --source y4m:%s --realtime no --no-loop --max-frames 100 --sink none --stats --json --quiet", path("in.y4m"));
    rc = run(args);
    if (rc != 0) fail_msg("run --stats --json: exit %d: %s", rc, slurp(path("stderr")));
    rename(path("stdout"), path("run.json"));
    snprintf(expr, sizeof expr,
             "d[\"published\"] == %d and d[\"raw\"] == %d and d[\"latency_ms\"][\"median\"] >= 0 and "
             "d[\"rss_kb\"][\"at_1_min\"] is None", FRAMES, FRAMES);
    assert_json(path("run.json"), expr);

    /* The text line of a run too short for the start's sample (30 frames) leaves it out, as
     * the JSON's null, rather than print 0 kB. */
    snprintf(args, sizeof args, "run --source y4m:%s --realtime no --no-loop --max-frames 100 --sink none --stats --quiet", path("in.y4m"));
    rc = run(args);
    if (rc != 0) fail_msg("run --stats: exit %d: %s", rc, slurp(path("stderr")));
    const char *line = slurp(path("stdout"));
    if (!strstr(line, "RSS kB max ") || strstr(line, "start 0")) fail_msg("stats line: %s", line);
}

/* The config's booleans on run's command line: --KEY, --no-KEY, --KEY=WORD and --KEY WORD. */
static void test_run_booleans(void **state)
{
    (void)state;
    static const struct {
        const char *args, *want;
    } cases[] = {
        {"--realtime", "realtime = yes"},        {"--no-realtime", "realtime = no"},
        {"--realtime 0", "realtime = no"},       {"--realtime no --loop", "realtime = no"},
        {"--realtime=false", "realtime = no"},   {"--realtime=yes", "realtime = yes"},
        {"--no-loop", "loop = no"},              {"--loop on", "loop = yes"},
        {"--loop=0 --realtime true", "realtime = yes"},
    };
    char args[512];
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        snprintf(args, sizeof args, "run %s --print-config", cases[i].args);
        int rc = run(args);
        if (rc != 0 || !strstr(slurp(path("stdout")), cases[i].want))
            fail_msg("run %s: exit %d, no '%s': %s", cases[i].args, rc, cases[i].want, slurp(path("stderr")));
    }
    assert_int_equal(run("run --realtime=maybe --print-config"), 2);
    assert_non_null(strstr(slurp(path("stderr")), "maybe"));
    assert_int_equal(run("run --no-realtime=1 --print-config"), 2);
    assert_int_equal(run("run --realtime maybe --print-config"), 2); /* not a boolean: an operand */
    assert_int_equal(run("run --stats=no --json --print-config"), 2); /* --json needs --stats */
}

int main(int argc, char **argv)
{
    (void)argc;
    /* build/tests/test_cli -> build/stillheart */
    char self[4096];
    snprintf(self, sizeof self, "%s", argv[0]);
    snprintf(bindir, sizeof bindir, "%s/..", dirname(self));
    snprintf(binary, sizeof binary, "%s/stillheart", bindir);
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_warp_end_to_end),
        cmocka_unit_test(test_warp_metric),
        cmocka_unit_test(test_errors_name_the_problem),
        cmocka_unit_test(test_every_program_one_convention),
        cmocka_unit_test(test_log_level),
        cmocka_unit_test(test_json_outputs),
        cmocka_unit_test(test_run_booleans),
    };
    return cmocka_run_group_tests(tests, setup, teardown);
}
