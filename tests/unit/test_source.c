/* Sources: Y4M replay timing (closed form: frame k due at start + k/fps, timestamped so),
 * as-fast-as-possible replay, looping (and the discontinuity it flags), the pollable fd, held-frame limits, and the errors of a
 * missing file or device. V4L2 capture itself is tested against real drivers in tests/vm/. */
#include <poll.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include <cmocka.h>

#include "stillheart/source.h"
#include "stillheart/y4m.h"

enum { W = 32, H = 16, N = 6 };

static char path[64], spec[80];

/* A Y4M file of N I420 frames at num/den fps; frame n's luma is all n. X tags: extra. */
static void write_y4m_tagged(int num, int den, const char *extra)
{
    sh_y4m_header h;
    memset(&h, 0, sizeof h);
    snprintf(h.extra, sizeof h.extra, "%s", extra);
    h.width = W;
    h.height = H;
    h.format = SH_PIX_I420;
    h.fps_num = num;
    h.fps_den = den;
    sh_y4m_writer *w;
    assert_int_equal(sh_y4m_writer_open(path, &h, &w), SH_OK);
    sh_image img;
    assert_int_equal(sh_image_create(&img, SH_PIX_I420, W, H), SH_OK);
    for (int n = 0; n < N; n++) {
        for (int y = 0; y < H; y++) memset(img.plane[0].data + y * img.plane[0].stride, n, W);
        assert_int_equal(sh_y4m_writer_write(w, &img), SH_OK);
    }
    sh_image_destroy(&img);
    assert_int_equal(sh_y4m_writer_close(w), SH_OK);
}

static void write_y4m(int num, int den) { write_y4m_tagged(num, den, ""); }

static int setup(void **state)
{
    (void)state;
    snprintf(path, sizeof path, "/tmp/sh-test-source-%d.y4m", (int)getpid());
    snprintf(spec, sizeof spec, "y4m:%s", path);
    return 0;
}

static int teardown(void **state)
{
    (void)state;
    unlink(path);
    return 0;
}

static void test_realtime_schedule(void **state)
{
    (void)state;
    write_y4m(50, 1); /* 20 ms a frame */
    sh_source_options o;
    sh_source_options_default(&o);
    o.camera = 2;
    o.loop = 1;
    sh_source *s;
    assert_int_equal(sh_source_open(spec, &o, &s), SH_OK);
    sh_rawfmt f;
    int w, h, fn, fd;
    assert_int_equal(sh_source_format(s, &f, &w, &h, &fn, &fd), SH_OK);
    assert_int_equal(f, SH_RAW_I420);
    assert_int_equal(w, W);
    assert_int_equal(fn, 50);
    assert_int_equal(fd, 1);
    int64_t before = sh_monotonic_ns();
    assert_int_equal(sh_source_start(s), SH_OK);
    int64_t t0 = 0;
    for (int k = 0; k < 2 * N + 2; k++) {
        sh_source_frame fr;
        int got;
        assert_int_equal(sh_source_dequeue(s, -1, &fr, &got), SH_OK);
        assert_int_equal(got, 1);
        int64_t now = sh_monotonic_ns();
        if (k == 0) {
            t0 = fr.timestamp_ns;
            assert_true(t0 >= before && t0 <= now);
        }
        assert_int_equal(fr.camera, 2);
        assert_int_equal(fr.sequence, (uint64_t)k);
        assert_true(fr.timestamp_ns - t0 == (int64_t)k * 20000000); /* exactly k/fps */
        assert_true(now >= fr.timestamp_ns);                        /* never early */
        assert_true(now - fr.timestamp_ns < 100000000);             /* and on time (loose: loaded CI) */
        assert_int_equal(fr.raw.data[0], k % N);                    /* looping */
        assert_int_equal(fr.raw.bytes, (size_t)W * H * 3 / 2);
        assert_int_equal(sh_source_release(s, &fr), SH_OK);
    }
    sh_source_stats st;
    sh_source_get_stats(s, &st);
    assert_int_equal(st.frames, 2 * N + 2);
    sh_source_close(s);
}

static void test_ntsc_rate_and_poll(void **state)
{
    (void)state;
    write_y4m(30000, 1001);
    sh_source_options o;
    sh_source_options_default(&o);
    sh_source *s;
    assert_int_equal(sh_source_open(spec, &o, &s), SH_OK);
    assert_int_equal(sh_source_start(s), SH_OK);
    int64_t t0 = 0;
    for (int k = 0; k < N; k++) {
        struct pollfd p = {.fd = sh_source_fd(s), .events = POLLIN};
        assert_true(p.fd >= 0);
        assert_int_equal(poll(&p, 1, 1000), 1); /* readable when the frame is due */
        int64_t now = sh_monotonic_ns();
        sh_source_frame fr;
        int got;
        assert_int_equal(sh_source_dequeue(s, 0, &fr, &got), SH_OK);
        assert_int_equal(got, 1);
        if (!k) t0 = fr.timestamp_ns;
        /* floor(k * 1001e9 / 30000) */
        assert_true(fr.timestamp_ns - t0 == (int64_t)k * 1001000000000LL / 30000);
        assert_true(now >= fr.timestamp_ns);
        /* the next one is not due yet */
        if (k == 0) {
            sh_source_frame fr2;
            assert_int_equal(sh_source_dequeue(s, 0, &fr2, &got), SH_OK);
            assert_int_equal(got, 0);
        }
        assert_int_equal(sh_source_release(s, &fr), SH_OK);
    }
    sh_source_frame fr;
    int got;
    assert_int_equal(sh_source_dequeue(s, -1, &fr, &got), SH_EEOF); /* no loop */
    sh_source_close(s);
}

/* The file replayed as fast as asked, looping; started. */
static sh_source *start_fast_loop(void)
{
    sh_source_options o;
    sh_source_options_default(&o);
    o.realtime = 0;
    o.loop = 1;
    sh_source *s;
    assert_int_equal(sh_source_open(spec, &o, &s), SH_OK);
    assert_int_equal(sh_source_start(s), SH_OK);
    return s;
}

static void test_fast_replay(void **state)
{
    (void)state;
    write_y4m(1, 1); /* one frame a second: real time would take N s */
    sh_source *s = start_fast_loop();
    int64_t begin = sh_monotonic_ns(), t0 = 0;
    sh_source_frame held[2];
    for (int k = 0; k < 3 * N; k++) {
        int got;
        sh_source_frame *fr = &held[k % 2];
        assert_int_equal(sh_source_dequeue(s, 0, fr, &got), SH_OK);
        assert_int_equal(got, 1);
        if (!k) t0 = fr->timestamp_ns;
        assert_true(fr->timestamp_ns - t0 == (int64_t)k * 1000000000);
        if (k == 1) {
            /* two held: no third slot */
            sh_source_frame extra;
            assert_int_equal(sh_source_dequeue(s, 0, &extra, &got), SH_EINVAL);
        }
        if (k) assert_int_equal(sh_source_release(s, &held[(k - 1) % 2]), SH_OK);
    }
    assert_int_equal(sh_source_release(s, &held[(3 * N - 1) % 2]), SH_OK);
    assert_true(sh_monotonic_ns() - begin < 500000000);
    sh_source_frame fr;
    fr.slot = 0;
    assert_int_equal(sh_source_release(s, &fr), SH_EINVAL); /* not held */
    sh_source_close(s);
}

/* A loop flags the first frame of each new pass a discontinuity (the scene jumps there), and
 * only it; a file tagged XLOOP=SEAMLESS (its end joins its start) flags none, and the tag counts
 * only as a whole word (XLOOP=SEAMLESSLY is another tag). */
static void test_loop_discontinuity(void **state)
{
    (void)state;
    for (int seamless = 0; seamless < 2; seamless++) {
        write_y4m_tagged(25, 1, seamless ? "XCOLORRANGE=LIMITED " SH_Y4M_LOOP_SEAMLESS : "XLOOP=SEAMLESSLY");
        sh_source *s = start_fast_loop();
        for (int k = 0; k < 3 * N; k++) {
            int got;
            sh_source_frame fr;
            assert_int_equal(sh_source_dequeue(s, 0, &fr, &got), SH_OK);
            assert_int_equal(got, 1);
            assert_int_equal(fr.raw.data[0], k % N);
            assert_int_equal(fr.discontinuity, !seamless && k > 0 && k % N == 0);
            assert_int_equal(sh_source_release(s, &fr), SH_OK);
        }
        sh_source_close(s);
    }
}

static void test_errors(void **state)
{
    (void)state;
    sh_source *s = NULL;
    sh_source_options o;
    sh_source_options_default(&o);
    assert_int_not_equal(sh_source_open("y4m:/nonexistent/x.y4m", &o, &s), SH_OK);
    assert_non_null(strstr(sh_error_message(), "/nonexistent/x.y4m"));
    assert_int_equal(sh_source_open("v4l2:/dev/video-stillheart-missing", &o, &s), SH_EIO);
    assert_non_null(strstr(sh_error_message(), "/dev/video-stillheart-missing"));
    assert_int_equal(sh_source_open("v4l2:/dev/null", &o, &s), SH_EUNSUPPORTED);
    assert_non_null(strstr(sh_error_message(), "not a V4L2 device"));
    assert_int_equal(sh_source_open("webcam:0", &o, &s), SH_EINVAL);
    assert_non_null(strstr(sh_error_message(), "webcam:0"));
    assert_int_equal(sh_source_open("y4m:", &o, &s), SH_EINVAL);
    o.format = SH_RAW_I420;
    assert_int_equal(sh_source_open("v4l2:/dev/video0", &o, &s), SH_EUNSUPPORTED);
    assert_null(s);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_realtime_schedule),
        cmocka_unit_test(test_ntsc_rate_and_poll),
        cmocka_unit_test(test_fast_replay),
        cmocka_unit_test(test_loop_discontinuity),
        cmocka_unit_test(test_errors),
    };
    return cmocka_run_group_tests(tests, setup, teardown);
}
