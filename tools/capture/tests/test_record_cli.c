/* stillheart record, run as a program: two replayed cameras recorded and converted back to Y4M
 * give the input frames byte for byte; the same two cameras from a config file (--config, the
 * daemon's [cameraN] sections) give the same recording; a recording with a flipped byte converts
 * every good record and exits 1 saying what was lost; the refusals (a missing camera, an
 * existing recording, --config mixed with camera options, a bad or missing config) exit non-zero
 * with a message naming what was wrong.
 *
 * Timing: each replayed camera's schedule starts when `record` starts it, one after the other,
 * so the two cameras' stamps differ by the time between the two starts. On a loaded machine or
 * under qemu-aarch64 that can be tens of ms, so the input runs at 5 fps and the sets are formed
 * within 99 ms (just under half the 200 ms period): a set is complete whenever the two starts lie
 * less than 99 ms apart, whatever the speed of the machine. Frames that arrive late are stamped
 * by the schedule, not by their arrival, and are waited for up to --max-wait-ms. */
#include <setjmp.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include <cmocka.h>

#include "shell.h"

#include "stillheart/y4m.h"

enum { W = 48, H = 32, N = 6, FPS = 5 };
static char tmp[64];

static int setup(void **state)
{
    (void)state;
    snprintf(tmp, sizeof tmp, "/tmp/sh-test-reccli-%d", (int)getpid());
    test_run("rm -rf %s && mkdir -p %s", tmp, tmp);
    /* an input Y4M: frame n, pixel i = n * 7 + i */
    sh_y4m_header h;
    memset(&h, 0, sizeof h);
    h.width = W;
    h.height = H;
    h.format = SH_PIX_I420;
    h.fps_num = FPS;
    h.fps_den = 1;
    char path[128];
    snprintf(path, sizeof path, "%s/in.y4m", tmp);
    sh_y4m_writer *w;
    assert_int_equal(sh_y4m_writer_open(path, &h, &w), SH_OK);
    sh_image img;
    assert_int_equal(sh_image_create(&img, SH_PIX_I420, W, H), SH_OK);
    for (int n = 0; n < N; n++) {
        for (int p = 0; p < 3; p++)
            for (int y = 0; y < img.plane[p].height; y++)
                for (int x = 0; x < img.plane[p].width; x++)
                    img.plane[p].data[y * img.plane[p].stride + x] = (uint8_t)(n * 7 + x + y * 3 + p * 50);
        assert_int_equal(sh_y4m_writer_write(w, &img), SH_OK);
    }
    sh_image_destroy(&img);
    assert_int_equal(sh_y4m_writer_close(w), SH_OK);
    return 0;
}

static int teardown(void **state)
{
    (void)state;
    test_run("rm -rf %s", tmp);
    return 0;
}

static void test_record_and_convert(void **state)
{
    (void)state;
    assert_int_equal(test_run("%s record --source y4m:%s/in.y4m --source y4m:%s/in.y4m --tolerance-ms 99 --max-wait-ms 1000 "
                         "--frames %d %s/rec",
                         RECORD_BIN, tmp, tmp, N, tmp),
                     0);
    assert_non_null(strstr(test_out, "6 sets (0 incomplete)"));
    assert_int_equal(test_run("%s record --to-y4m %s/rec %s/cam1.y4m --camera 1", RECORD_BIN, tmp, tmp), 0);
    /* same frames as the input */
    char a[128], b[128];
    snprintf(a, sizeof a, "%s/in.y4m", tmp);
    snprintf(b, sizeof b, "%s/cam1.y4m", tmp);
    sh_y4m_reader *ra, *rb;
    assert_int_equal(sh_y4m_reader_open(a, &ra), SH_OK);
    assert_int_equal(sh_y4m_reader_open(b, &rb), SH_OK);
    assert_int_equal(sh_y4m_reader_header(rb)->fps_num, FPS);
    sh_image ia, ib;
    assert_int_equal(sh_image_create(&ia, SH_PIX_I420, W, H), SH_OK);
    assert_int_equal(sh_image_create(&ib, SH_PIX_I420, W, H), SH_OK);
    int n = 0;
    while (sh_y4m_reader_read(ra, &ia) == SH_OK) {
        assert_int_equal(sh_y4m_reader_read(rb, &ib), SH_OK);
        for (int p = 0; p < 3; p++)
            for (int y = 0; y < ia.plane[p].height; y++)
                assert_memory_equal(ia.plane[p].data + y * ia.plane[p].stride,
                                    ib.plane[p].data + y * ib.plane[p].stride, ia.plane[p].width);
        n++;
    }
    assert_int_equal(n, N);
    assert_int_equal(sh_y4m_reader_read(rb, &ib), SH_EEOF);
    sh_image_destroy(&ia);
    sh_image_destroy(&ib);
    sh_y4m_reader_close(ra);
    sh_y4m_reader_close(rb);
    /* and the recording replays as a source */
    assert_int_equal(test_run("%s record --source rec:%s/rec --fast --frames 4 %s/rec2", RECORD_BIN, tmp, tmp), 0);
    assert_non_null(strstr(test_out, "4 frames recorded"));
    /* an existing recording is not overwritten */
    assert_int_equal(test_run("%s record --source y4m:%s/in.y4m --frames 1 %s/rec", RECORD_BIN, tmp, tmp), 1);
    assert_non_null(strstr(test_out, "already"));
}

/* The cameras of a config file, as the daemon reads them: the same sets and frames as the
 * --source form above (run first: it made rec/ and cam1.y4m). */
static void test_record_config(void **state)
{
    (void)state;
    char path[128];
    snprintf(path, sizeof path, "%s/rig.ini", tmp);
    FILE *f = fopen(path, "w");
    assert_non_null(f);
    fprintf(f, "[source]\nsync_tolerance_ms = 99\nsync_wait_ms = 1000\n[camera0]\nspec = y4m:%s/in.y4m\n"
               "[camera1]\nspec = y4m:%s/in.y4m\n[trigger]\nmode = off\n",
            tmp, tmp);
    fclose(f);
    assert_int_equal(test_run("%s record --config %s --frames %d %s/rec_cfg", RECORD_BIN, path, N, tmp), 0);
    assert_non_null(strstr(test_out, "6 sets (0 incomplete)"));
    assert_non_null(strstr(test_out, "camera 1: y4m:"));
    for (int c = 0; c < 2; c++) {
        assert_int_equal(test_run("%s record --to-y4m %s/rec_cfg %s/cfg%d.y4m --camera %d", RECORD_BIN, tmp, tmp, c, c), 0);
        assert_int_equal(test_run("%s record --to-y4m %s/rec %s/src%d.y4m --camera %d", RECORD_BIN, tmp, tmp, c, c), 0);
        assert_int_equal(test_run("cmp %s/cfg%d.y4m %s/src%d.y4m", tmp, c, tmp, c), 0);
    }
    /* refusals: camera options beside --config, a missing file, a bad key, a missing camera */
    assert_int_equal(test_run("%s record --config %s --source y4m:%s/in.y4m --frames 1 %s/r", RECORD_BIN, path, tmp, tmp), 2);
    assert_non_null(strstr(test_out, "--config gives the cameras"));
    assert_int_equal(test_run("%s record --config %s/none.ini --frames 1 %s/r", RECORD_BIN, tmp, tmp), 2);
    assert_non_null(strstr(test_out, "none.ini: cannot open"));
    f = fopen(path, "w");
    assert_non_null(f);
    fprintf(f, "[camera0]\nspec = y4m:%s/in.y4m\nfps = fast\n", tmp);
    fclose(f);
    assert_int_equal(test_run("%s record --config %s --frames 1 %s/r", RECORD_BIN, path, tmp), 2);
    assert_non_null(strstr(test_out, "rig.ini:3: [camera0] fps: 'fast'"));
    f = fopen(path, "w");
    assert_non_null(f);
    fprintf(f, "[camera0]\nspec = y4m:%s/in.y4m\n[camera1]\nspec = y4m:%s/gone.y4m\n", tmp, tmp);
    fclose(f);
    assert_int_equal(test_run("%s record --config %s --frames 1 %s/r", RECORD_BIN, path, tmp), 1);
    assert_non_null(strstr(test_out, "[camera1] spec: "));
    assert_non_null(strstr(test_out, "gone.y4m"));
}

/* A recording with one byte flipped in the middle: --to-y4m converts every good record, then says
 * what was lost (one record, resynced past) and exits 1. */
static void test_convert_damaged(void **state)
{
    (void)state;
    assert_int_equal(test_run("rm -rf %s/dmg && cp -r %s/rec %s/dmg", tmp, tmp, tmp), 0);
    char path[128];
    snprintf(path, sizeof path, "%s/dmg/recording.shrec", tmp);
    FILE *f = fopen(path, "r+b");
    assert_non_null(f);
    assert_int_equal(fseek(f, 0, SEEK_END), 0);
    long mid = ftell(f) / 2;
    assert_int_equal(fseek(f, mid, SEEK_SET), 0);
    int c = fgetc(f);
    assert_int_equal(fseek(f, mid, SEEK_SET), 0);
    fputc(c ^ 0x10, f);
    assert_int_equal(fclose(f), 0);
    int frames = 0;
    for (int cam = 0; cam < 2; cam++) {
        assert_int_equal(test_run("%s record --to-y4m %s/dmg %s/dmg%d.y4m --camera %d", RECORD_BIN, tmp, tmp, cam, cam), 1);
        assert_non_null(strstr(test_out, "WARNING"));
        assert_non_null(strstr(test_out, "is damaged: 1 record(s) skipped"));
        const char *n = strstr(test_out, " frames of camera");
        assert_non_null(n);
        while (n > test_out && n[-1] >= '0' && n[-1] <= '9') n--;
        frames += atoi(n);
    }
    /* the flip is in one record: a frame of either camera, or a set */
    assert_true(frames == 2 * N || frames == 2 * N - 1);
    /* replayed as a source, the damage is said at WARNING when met and the end is an error */
    assert_int_equal(test_run("%s record --source rec:%s/dmg --fast --frames 100 %s/again", RECORD_BIN, tmp, tmp), 1);
    assert_non_null(strstr(test_out, "WARNING: rec:"));
    assert_non_null(strstr(test_out, "/dmg: damaged recording: 1 record(s) skipped"));
}

static void test_refusals(void **state)
{
    (void)state;
    assert_int_equal(test_run("%s record --source v4l2:/dev/video-missing --frames 1 %s/r", RECORD_BIN, tmp), 1);
    assert_non_null(strstr(test_out, "/dev/video-missing"));
    assert_int_equal(test_run("%s record --source webcam --frames 1 %s/r", RECORD_BIN, tmp), 1);
    assert_int_equal(test_run("%s record --to-y4m %s/nothing %s/x.y4m", RECORD_BIN, tmp, tmp), 1);
    assert_non_null(strstr(test_out, "nothing"));
    assert_int_equal(test_run("%s record --source y4m:%s/in.y4m %s/r", RECORD_BIN, tmp, tmp), 2); /* no --frames */
    /* a trigger line on a chip that is not there, with or without libgpiod in the build */
    assert_int_equal(test_run("%s record --source y4m:%s/in.y4m --trigger-out gpiochip-missing:1 --fps 25 --frames 1 %s/t",
                         RECORD_BIN, tmp, tmp),
                     1);
    assert_non_null(strstr(test_out, "gpiochip-missing"));
    assert_int_equal(test_run("%s record --source y4m:%s/in.y4m --trigger-out gpiochip0 --frames 1 %s/t", RECORD_BIN,
                         tmp, tmp),
                     2);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_record_and_convert),
        cmocka_unit_test(test_convert_damaged),
        cmocka_unit_test(test_record_config),
        cmocka_unit_test(test_refusals),
    };
    return cmocka_run_group_tests(tests, setup, teardown);
}
