/* stillheart run with several cameras, run as a program (the binary next to this test's folder):
 * two replayed cameras form complete sets and the configured output camera is the one warped (its
 * record equals `stillheart warp` of that camera's file, not of the other's), also looping and
 * from a `stillheart record` recording of the two (rec:DIR); a camera that ends
 * early leaves the other going with incomplete sets; a missing camera file or device, a gap in
 * the camera numbering, an output camera that is not configured and a missing GPIO chip are
 * refused at start, naming what is wrong. */
#include <limits.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cmocka.h>

#include "stillheart/y4m.h"

enum { W = 64, H = 48, N = 8, SHORT = 4, FPS = 25 };
static char tmp[64], bin[PATH_MAX + 16], cmd[4096], out[16384];

static int run(const char *fmt, ...)
    __attribute__((format(printf, 1, 2)));
static int run(const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(cmd, sizeof cmd, fmt, ap);
    va_end(ap);
    char full[4200];
    snprintf(full, sizeof full, "%s 2>&1", cmd);
    FILE *p = popen(full, "r");
    assert_non_null(p);
    size_t n = fread(out, 1, sizeof out - 1, p);
    out[n] = 0;
    int st = pclose(p);
    return WIFEXITED(st) ? WEXITSTATUS(st) : -1;
}

/* Fails with the command and what it printed. */
static void ok(int rc)
{
    if (rc != 0) fail_msg("exit %d: %s\n%s", rc, cmd, out);
}

/* A Y4M of n frames; camera c's frame k, pixel i = (k * 7 + i * (c + 1) + 40 * c) & 255, so the
 * two cameras differ everywhere. */
static void write_y4m(const char *name, int c, int n, int fps)
{
    sh_y4m_header h;
    memset(&h, 0, sizeof h);
    h.width = W;
    h.height = H;
    h.format = SH_PIX_I420;
    h.fps_num = fps;
    h.fps_den = 1;
    char path[128];
    snprintf(path, sizeof path, "%s/%s", tmp, name);
    sh_y4m_writer *w;
    assert_int_equal(sh_y4m_writer_open(path, &h, &w), SH_OK);
    sh_image img;
    assert_int_equal(sh_image_create(&img, SH_PIX_I420, W, H), SH_OK);
    for (int k = 0; k < n; k++) {
        for (int p = 0; p < 3; p++)
            for (int y = 0; y < img.plane[p].height; y++)
                for (int x = 0; x < img.plane[p].width; x++)
                    img.plane[p].data[y * img.plane[p].stride + x] =
                        (uint8_t)((k * 7 + (y * img.plane[p].width + x) * (c + 1) + 40 * c) & 255);
        assert_int_equal(sh_y4m_writer_write(w, &img), SH_OK);
    }
    sh_image_destroy(&img);
    assert_int_equal(sh_y4m_writer_close(w), SH_OK);
}

static void write_file(const char *name, const char *text)
{
    char path[128];
    snprintf(path, sizeof path, "%s/%s", tmp, name);
    FILE *f = fopen(path, "w");
    assert_non_null(f);
    fputs(text, f);
    fclose(f);
}

static int setup(void **state)
{
    (void)state;
    char self[PATH_MAX];
    ssize_t n = readlink("/proc/self/exe", self, sizeof self - 1);
    assert_true(n > 0);
    self[n] = 0;
    *strrchr(self, '/') = 0; /* BUILD/tests */
    snprintf(bin, sizeof bin, "%s/../stillheart", self);
    snprintf(tmp, sizeof tmp, "/tmp/sh-test-dsrc-%d", (int)getpid());
    run("rm -rf %s && mkdir -p %s", tmp, tmp);
    write_y4m("cam0.y4m", 0, N, FPS);
    write_y4m("cam1.y4m", 1, N, FPS);
    write_y4m("short1.y4m", 1, SHORT, FPS);
    write_y4m("long0.y4m", 0, 40, FPS);
    write_y4m("double1.y4m", 1, 2 * N, 2 * FPS);
    /* four markers drifting a little each frame: an affine map that is not the identity */
    char pts[4096] = "frame,id,x,y\n";
    for (int k = 0; k < N; k++)
        for (int id = 0; id < 4; id++) {
            char row[64];
            snprintf(row, sizeof row, "%d,%d,%.2f,%.2f\n", k, id, 10.0 + 40 * (id & 1) + 0.5 * k,
                     8.0 + 30 * (id >> 1) + 0.25 * k * (id & 1));
            strcat(pts, row);
        }
    write_file("points.csv", pts);
    return 0;
}

static int teardown(void **state)
{
    (void)state;
    run("rm -rf %s", tmp);
    return 0;
}

#define RUN_ARGS "--group= --sink none --points %s/points.csv --method affine --min-markers 3 --threads 1"

/* The output camera (1) is warped: the daemon's record equals stillheart warp of cam1.y4m, and
 * not of cam0.y4m; all N sets are complete. As fast as possible: nothing dropped. */
static void test_two_cameras_output_warped(void **state)
{
    (void)state;
    char ini[512];
    snprintf(ini, sizeof ini,
             "[source]\nrealtime = no\nloop = no\noutput = 1\n"
             "[camera0]\nspec = y4m:%s/cam0.y4m\n[camera1]\nspec = y4m:%s/cam1.y4m\n",
             tmp, tmp);
    write_file("two.ini", ini);
    for (int c = 0; c < 2; c++)
        ok(run("%s warp --method affine --threads 1 --points %s/points.csv %s/cam%d.y4m "
                             "%s/warp%d.y4m --quiet",
                             bin, tmp, tmp, c, tmp, c));
    ok(run("%s run --config %s/two.ini " RUN_ARGS " --record %s/rec.y4m", bin, tmp, tmp, tmp));
    char want[64];
    snprintf(want, sizeof want, "sets: %d (0 incomplete), 0 dropped while processing was behind", N);
    if (!strstr(out, want)) fail_msg("no '%s' in:\n%s", want, out);
    assert_non_null(strstr(out, "camera 1 (y4m:"));
    ok(run("cmp %s/rec.y4m %s/warp1.y4m", tmp, tmp));
    assert_int_not_equal(run("cmp %s/rec.y4m %s/warp0.y4m", tmp, tmp), 0);
}

/* The same from the command line only, in real time: the threads run freely and the sets still
 * form by timestamp. */
static void test_two_cameras_realtime_cli(void **state)
{
    (void)state;
    ok(run("%s run --camera0-spec y4m:%s/cam0.y4m --camera1-spec y4m:%s/cam1.y4m --output-camera 1 "
                         "--realtime --no-loop " RUN_ARGS " --record %s/rt.y4m",
                         bin, tmp, tmp, tmp, tmp));
    char want[64];
    snprintf(want, sizeof want, "sets: %d (0 incomplete)", N);
    if (!strstr(out, want)) fail_msg("no '%s' in:\n%s", want, out);
}

/* Frame k of a (the daemon's record) equals frame k % period of b (stillheart warp's); n frames. */
static void assert_frames_repeat(const char *a, const char *b, int n, int period)
{
    char pa[128], pb[128];
    snprintf(pa, sizeof pa, "%s/%s", tmp, a);
    snprintf(pb, sizeof pb, "%s/%s", tmp, b);
    sh_y4m_reader *ra, *rb = NULL;
    assert_int_equal(sh_y4m_reader_open(pa, &ra), SH_OK);
    sh_image ia, ib;
    assert_int_equal(sh_image_create(&ia, SH_PIX_I420, W, H), SH_OK);
    assert_int_equal(sh_image_create(&ib, SH_PIX_I420, W, H), SH_OK);
    for (int k = 0; k < n; k++) {
        if (k % period == 0) {
            sh_y4m_reader_close(rb);
            assert_int_equal(sh_y4m_reader_open(pb, &rb), SH_OK);
        }
        assert_int_equal(sh_y4m_reader_read(ra, &ia), SH_OK);
        assert_int_equal(sh_y4m_reader_read(rb, &ib), SH_OK);
        for (int p = 0; p < 3; p++)
            for (int y = 0; y < ia.plane[p].height; y++)
                if (memcmp(ia.plane[p].data + y * ia.plane[p].stride, ib.plane[p].data + y * ib.plane[p].stride,
                           (size_t)ia.plane[p].width))
                    fail_msg("frame %d, plane %d, row %d differs", k, p, y);
    }
    assert_int_equal(sh_y4m_reader_read(ra, &ia), SH_EEOF);
    sh_image_destroy(&ia);
    sh_image_destroy(&ib);
    sh_y4m_reader_close(ra);
    sh_y4m_reader_close(rb);
}

/* Two cameras looping: the frame numbers (the points file's) start again with each loop, so two
 * and a half loops show warp's frames 0..N-1, 0..N-1, 0..N/2-1. */
static void test_two_cameras_loop(void **state)
{
    (void)state;
    ok(run("%s run --camera0-spec y4m:%s/cam0.y4m --camera1-spec y4m:%s/cam1.y4m --output-camera 1 "
           "--no-realtime --loop --max-frames %d " RUN_ARGS " --record %s/loop.y4m",
           bin, tmp, tmp, 2 * N + N / 2, tmp, tmp));
    assert_frames_repeat("loop.y4m", "warp1.y4m", 2 * N + N / 2, N);
}

/* A recording of the two cameras replayed: [cameraN] rec:DIR is camera N of it, so the frames
 * shown for camera 1 are again stillheart warp's of cam1.y4m (the header differs: a recording
 * keeps no Y4M extras). Sets within 19 ms (under half the 40 ms period) on both sides, so that a
 * slow start of one replay under a loaded machine cannot split them. */
static void test_recording_cameras(void **state)
{
    (void)state;
    ok(run("%s record --source y4m:%s/cam0.y4m --source y4m:%s/cam1.y4m --fast --tolerance-ms 19 --max-wait-ms 1000 "
           "--frames %d %s/rig",
           bin, tmp, tmp, N, tmp));
    ok(run("%s run --camera0-spec rec:%s/rig --camera1-spec rec:%s/rig --output-camera 1 --no-realtime --no-loop "
           "--sync-tolerance-ms 19 " RUN_ARGS " --record %s/fromrec.y4m",
           bin, tmp, tmp, tmp, tmp));
    char want[64];
    snprintf(want, sizeof want, "sets: %d (0 incomplete)", N);
    if (!strstr(out, want)) fail_msg("no '%s' in:\n%s", want, out);
    assert_frames_repeat("fromrec.y4m", "warp1.y4m", N, N);
}

/* Camera 1 ends after SHORT frames: camera 0 (shown) goes on; its last sets are incomplete. */
static void test_camera_ends_others_go_on(void **state)
{
    (void)state;
    ok(run("%s run --camera0-spec y4m:%s/cam0.y4m --camera1-spec y4m:%s/short1.y4m "
                         "--no-realtime --no-loop " RUN_ARGS " --record %s/short.y4m --stats",
                         bin, tmp, tmp, tmp, tmp));
    char want[64];
    snprintf(want, sizeof want, "sets: %d (%d incomplete)", N, N - SHORT);
    if (!strstr(out, want)) fail_msg("no '%s' in:\n%s", want, out);
    snprintf(want, sizeof want, "stats: %d published", N);
    assert_non_null(strstr(out, want));
    ok(run("cmp %s/short.y4m %s/warp0.y4m", tmp, tmp));
}

/* Camera 1 at twice camera 0's rate: its odd frames fall between camera 0's and form sets of
 * their own. As fast as possible, that is the case where every camera has a frame waiting in a
 * set no other frame will complete; the sets are let go incomplete, nothing stalls, and every
 * frame of camera 0 (shown) is warped as stillheart warp does. */
static void test_cameras_at_two_rates(void **state)
{
    (void)state;
    ok(run("%s run --camera0-spec y4m:%s/cam0.y4m --camera1-spec y4m:%s/double1.y4m --no-realtime --no-loop "
           RUN_ARGS " --record %s/rates.y4m --stats",
           bin, tmp, tmp, tmp, tmp));
    char want[64];
    snprintf(want, sizeof want, "stats: %d published", N);
    if (!strstr(out, want) || !strstr(out, "0 dropped while processing was behind")) fail_msg("in:\n%s", out);
    assert_frames_repeat("rates.y4m", "warp0.y4m", N, N);
}

/* systemd's STATUS names the cameras delivering: in real time, camera 0 runs 40 frames (1.6 s),
 * camera 1 ends after SHORT; the STATUS sent after a second says so. */
static void test_status_names_cameras(void **state)
{
    (void)state;
    struct sockaddr_un a = {.sun_family = AF_UNIX};
    snprintf(a.sun_path, sizeof a.sun_path, "%s/notify", tmp);
    int fd = socket(AF_UNIX, SOCK_DGRAM, 0);
    assert_true(fd >= 0);
    assert_int_equal(bind(fd, (struct sockaddr *)&a, sizeof a), 0);
    ok(run("NOTIFY_SOCKET=%s %s run --camera0-spec y4m:%s/long0.y4m --camera1-spec y4m:%s/short1.y4m --realtime "
           "--no-loop " RUN_ARGS " --quiet",
           a.sun_path, bin, tmp, tmp, tmp));
    char msg[512], statuses[4096] = "";
    ssize_t n;
    while ((n = recv(fd, msg, sizeof msg - 1, MSG_DONTWAIT)) > 0) {
        msg[n] = 0;
        if (!strncmp(msg, "STATUS=", 7) && strlen(statuses) + (size_t)n + 2 < sizeof statuses) {
            strcat(statuses, msg);
            strcat(statuses, "\n");
        }
    }
    close(fd);
    if (!strstr(statuses, "1/2 cameras (camera 1 ended)")) fail_msg("STATUS lines:\n%s", statuses);
}

static void refused(const char *args, int want_rc, const char *want1, const char *want2)
{
    int rc = run("%s run --group= --sink none %s", bin, args);
    if (want_rc >= 0) assert_int_equal(rc, want_rc);
    else assert_int_not_equal(rc, 0);
    if (!strstr(out, want1) || (want2 && !strstr(out, want2)))
        fail_msg("'%s' / '%s' not in:\n%s", want1, want2 ? want2 : "", out);
}

static void test_refusals(void **state)
{
    (void)state;
    char a[1024];
    snprintf(a, sizeof a, "--camera0-spec y4m:%s/cam0.y4m --camera1-spec y4m:%s/nope.y4m", tmp, tmp);
    refused(a, -1, "[camera1] spec", "nope.y4m");
    snprintf(a, sizeof a, "--camera0-spec y4m:%s/cam0.y4m --camera1-spec v4l2:/dev/video-sh-none", tmp);
    refused(a, -1, "[camera1] spec", "/dev/video-sh-none");
    snprintf(a, sizeof a, "--camera0-spec y4m:%s/cam0.y4m --camera2-spec y4m:%s/cam1.y4m", tmp, tmp);
    refused(a, 2, "[camera2] spec: set while [camera1] spec is empty", NULL);
    snprintf(a, sizeof a, "--camera0-spec y4m:%s/cam0.y4m --output-camera 1", tmp);
    refused(a, 2, "[source] output: camera 1, but 1 camera is configured", NULL);
    refused("--camera1-spec webcam", 2, "[camera1] spec: 'webcam' is not v4l2:", NULL);
    refused("--camera0-size 640", 2, "[camera0] size: '640' is not WIDTHxHEIGHT", NULL);
    snprintf(a, sizeof a, "--camera0-spec y4m:%s/cam0.y4m --trigger in --trigger-chip sh-no-such-chip --trigger-line 3",
             tmp);
    refused(a, -1, "[trigger]", "sh-no-such-chip");
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_two_cameras_output_warped),
        cmocka_unit_test(test_two_cameras_realtime_cli),
        cmocka_unit_test(test_two_cameras_loop),
        cmocka_unit_test(test_recording_cameras),
        cmocka_unit_test(test_camera_ends_others_go_on),
        cmocka_unit_test(test_cameras_at_two_rates),
        cmocka_unit_test(test_status_names_cameras),
        cmocka_unit_test(test_refusals),
    };
    return cmocka_run_group_tests(tests, setup, teardown);
}
