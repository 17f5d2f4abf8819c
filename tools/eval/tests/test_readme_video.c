/* The README's "Stabilize your own video" run as written: its commands are read from README.md
 * between the own-video markers (so the two cannot drift apart) and run by sh in an empty folder
 * on a rendered phantom clip encoded to MP4 with ffmpeg, as a user's clip would come; then what
 * they made is read back: the Y4M, the points, both stabilized videos, the heatmaps at the clip's
 * size, and the side-by-side MP4 three clips wide with every frame. Needs ffmpeg, which
 * scripts/install-deps.sh installs: where it is missing the test is skipped, and says so. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <cmocka.h>

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "shell.h"
#include "stillheart/imageio.h"

#if !defined(README) || !defined(APP_BIN) || !defined(EVAL_BIN) || !defined(RENDER_BIN)
#error "README, APP_BIN, EVAL_BIN and RENDER_BIN must name this tree's README and this build's programs"
#endif

/* 2.6 s at the phantom's 23 frames/s: a short clip, as `track` without --ids judges a file shorter
 * than its first 10 s whole. */
#define FRAMES 60
#define CW 640
#define CH 360

static char tmp[256];

/* The lines of the sh blocks between the markers into out (a script). Returns how many. */
static int extract(const char *readme, FILE *out)
{
    FILE *f = fopen(readme, "r");
    assert_non_null(f);
    char line[1024];
    int inside = 0, fence = 0, n = 0;
    while (fgets(line, sizeof line, f)) {
        if (!strncmp(line, "<!-- own-video:begin", 20)) inside = 1;
        else if (!strncmp(line, "<!-- own-video:end", 18)) inside = 0;
        else if (inside && !strncmp(line, "```", 3)) fence = !fence && !strncmp(line, "```sh", 5);
        else if (inside && fence && line[0] != '#' && line[0] != '\n') fputs(line, out), n++;
    }
    fclose(f);
    return n;
}

static void expect_png_size(const char *name, int w, int h)
{
    char p[512];
    snprintf(p, sizeof p, "%s/run/%s", tmp, name);
    sh_image img;
    assert_int_equal(sh_imageio_read(p, &img), SH_OK);
    assert_int_equal(img.width, w);
    assert_int_equal(img.height, h);
    sh_image_destroy(&img);
}

/* ffprobe's width,height,frames of a video in the run folder, e.g. "1920,360,240". */
static void expect_video(const char *name, const char *want)
{
    int rc = test_run("ffprobe -v error -select_streams v:0 -count_frames -show_entries "
                      "stream=width,height,nb_read_frames -of csv=p=0 '%s/run/%s'", tmp, name);
    test_out[strcspn(test_out, "\n")] = '\0';
    if (rc != 0 || strcmp(test_out, want)) {
        print_error("%s: ffprobe says '%s' (exit status %d), want '%s'\n", name, test_out, rc, want);
        fail();
    }
}

static void test_readme_section_runs(void **state)
{
    (void)state;
    if (test_run("command -v ffmpeg && command -v ffprobe") != 0) {
        print_message("skipped: ffmpeg not installed (sh scripts/install-deps.sh installs it)\n");
        skip();
    }
    /* under qemu-aarch64 (tools/cross/run-lanes.sh) the same commands cost minutes and show
     * nothing the host run does not: the programs' arithmetic has tests of its own there */
    if (getenv("SH_TEST_EMULATED")) {
        print_message("skipped: the README's run is the host suite's (SH_TEST_EMULATED)\n");
        skip();
    }
    snprintf(tmp, sizeof tmp, "/tmp/sh_test_readme_video_XXXXXX");
    assert_non_null(mkdtemp(tmp));
    char script[512];
    snprintf(script, sizeof script, "%s/own-video.sh", tmp);
    FILE *s = fopen(script, "w");
    assert_non_null(s);
    fputs("set -eux\n", s);
    int n = extract(README, s);
    assert_int_equal(fclose(s), 0);
    assert_true(n >= 8); /* convert, track, 2 warps, 2 evals, 2 encodes */

    /* the user's clip: a rendered phantom, encoded as a camera or phone would hand it over */
    assert_int_equal(test_run("'%s' --preset exvivo --frames %d --quiet --out '%s/render' > '%s/render.log' 2>&1",
                        RENDER_BIN, FRAMES, tmp, tmp), 0);
    assert_int_equal(test_run("mkdir -p '%s/run' '%s/bin' && ln -s '%s' '%s/bin/stillheart' && "
                        "ln -s '%s' '%s/bin/stillheart-eval'", tmp, tmp, APP_BIN, tmp, EVAL_BIN, tmp), 0);
    assert_int_equal(test_run("ffmpeg -nostdin -v error -i '%s/render/cam0.y4m' -pix_fmt yuv420p -crf 18 "
                        "'%s/run/clip.mp4'", tmp, tmp), 0);
    int rc = test_run("cd '%s/run' && PATH='%s/bin':\"$PATH\" sh '%s' < /dev/null > '%s/run.log' 2>&1",
                tmp, tmp, script, tmp);
    if (rc != 0) {
        test_run("tail -n 40 '%s/run.log'", tmp);
        print_error("%s\n", test_out);
        fail_msg("the README's commands failed (exit status %d); the log: %s/run.log (KEEP=1 keeps it)",
                 rc, tmp);
    }
    char want[64];
    snprintf(want, sizeof want, "%d,%d,%d", CW, CH, FRAMES);
    expect_video("clip.y4m", want);
    expect_video("bspline.y4m", want);
    expect_video("tps.y4m", want);
    expect_video("tps.mp4", want);
    expect_png_size("bspline.png", CW, CH);
    expect_png_size("tps.png", CW, CH);
    snprintf(want, sizeof want, "%d,%d,%d", 3 * CW, CH, FRAMES);
    expect_video("side-by-side.mp4", want);
    /* at least three markers in frame 0 of the points, as the README says the clip needs */
    assert_int_equal(test_run("test \"$(grep -c '^0,' '%s/run/P.csv')\" -ge 3", tmp), 0);
    if (!getenv("KEEP")) assert_int_equal(test_run("rm -rf '%s'", tmp), 0);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_readme_section_runs),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
