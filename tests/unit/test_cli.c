/* The `stillheart warp` command end to end: a synthetic video and its points file in, the
 * stabilized video, the .npy map and the e figures out; and its errors for bad input. */
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

#include "stillheart/points.h"
#include "stillheart/y4m.h"
#include "synth.h"

enum { W = 320, H = 200, FRAMES = 6, MARKERS = 12 };

static char binary[4096], dir[] = "/tmp/stillheart-cli-XXXXXX";
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

static void test_warp_end_to_end(void **state)
{
    (void)state;
    char args[8192];
    snprintf(args, sizeof args, "warp --method tps --threads 2 --points %s %s %s --map-out %s",
             path("points.csv"), path("in.y4m"), path("out.y4m"), path("map.npy"));
    int rc = run(args);
    if (rc != 0) fail_msg("exit %d: %s", rc, slurp(path("stderr")));
    double e_in, e_out;
    assert_int_equal(sscanf(slurp(path("stdout")), "residual motion e (lower is better): %lf -> %lf", &e_in, &e_out), 2);
    assert_true(e_out < 0.5 * e_in);

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

int main(int argc, char **argv)
{
    (void)argc;
    /* build/tests/test_cli -> build/stillheart */
    char self[4096];
    snprintf(self, sizeof self, "%s", argv[0]);
    snprintf(binary, sizeof binary, "%s/../stillheart", dirname(self));
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_warp_end_to_end),
        cmocka_unit_test(test_errors_name_the_problem),
    };
    return cmocka_run_group_tests(tests, setup, teardown);
}
