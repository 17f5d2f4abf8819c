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
#include <sys/resource.h>
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

/* A Y4M file of N frames of format f (every plane's bytes varied per frame) with the given
 * chroma siting. */
static void write_y4m_planes(sh_pixfmt f, sh_chroma_siting siting)
{
    sh_y4m_header h;
    memset(&h, 0, sizeof h);
    h.width = W;
    h.height = H;
    h.format = f;
    h.siting = siting;
    h.fps_num = 25;
    h.fps_den = 1;
    sh_y4m_writer *w;
    assert_int_equal(sh_y4m_writer_open(path, &h, &w), SH_OK);
    sh_image img;
    assert_int_equal(sh_image_create(&img, f, W, H), SH_OK);
    for (int n = 0; n < N; n++) {
        for (int p = 0; p < img.num_planes; p++)
            for (int y = 0; y < img.plane[p].height; y++)
                for (int x = 0; x < img.plane[p].width; x++)
                    img.plane[p].data[y * img.plane[p].stride + x] = (uint8_t)(37 * n + 11 * p + 5 * x + 3 * y);
        assert_int_equal(sh_y4m_writer_write(w, &img), SH_OK);
    }
    sh_image_destroy(&img);
    assert_int_equal(sh_y4m_writer_close(w), SH_OK);
}

/* sh_source_dequeue_into gives the image sh_source_dequeue and sh_pixconv_convert give, frame
 * for frame over two loops, siting included: read straight in for I420 (a C420mpeg2 file: the
 * raw frame's siting is pixconv's centre, not the header's) and grey; a 4:4:4 file is left to
 * the caller's conversion (direct 0, dst untouched). */
static void test_dequeue_into(void **state)
{
    (void)state;
    const struct { sh_pixfmt file, work; int direct; } cases[] = {
        {SH_PIX_I420, SH_PIX_I420, 1}, {SH_PIX_GRAY8, SH_PIX_GRAY8, 1}, {SH_PIX_YUV444, SH_PIX_I420, 0}};
    for (size_t c = 0; c < sizeof cases / sizeof cases[0]; c++) {
        write_y4m_planes(cases[c].file, SH_CHROMA_LEFT);
        sh_source *a = start_fast_loop(), *b = start_fast_loop();
        sh_image ia, ib;
        assert_int_equal(sh_image_create(&ia, cases[c].work, W, H), SH_OK);
        assert_int_equal(sh_image_create(&ib, cases[c].work, W, H), SH_OK);
        for (int k = 0; k < 2 * N; k++) {
            sh_source_frame fa, fb;
            int got = 0, direct = -1;
            assert_int_equal(sh_source_dequeue(a, 0, &fa, &got), SH_OK);
            assert_int_equal(got, 1);
            assert_int_equal(sh_pixconv_convert(NULL, &fa.raw, &ia), SH_OK);
            ib.siting = SH_CHROMA_PALDV; /* neither pixconv nor a direct read may leave this */
            if (cases[c].work == SH_PIX_GRAY8) ia.siting = ib.siting;
            memset(ib.plane[0].data, 7, (size_t)ib.plane[0].stride * H);
            assert_int_equal(sh_source_dequeue_into(b, 0, &ib, &fb, &got, &direct), SH_OK);
            assert_int_equal(got, 1);
            assert_int_equal(direct, cases[c].direct);
            assert_int_equal(fb.sequence, fa.sequence);
            if (!direct) {
                assert_int_equal(ib.plane[0].data[0], 7); /* untouched */
                assert_int_equal(sh_pixconv_convert(NULL, &fb.raw, &ib), SH_OK);
            } else {
                assert_null(fb.raw.data);
            }
            assert_int_equal(ib.siting, ia.siting);
            for (int p = 0; p < ia.num_planes; p++)
                for (int y = 0; y < ia.plane[p].height; y++)
                    assert_memory_equal(ib.plane[p].data + y * ib.plane[p].stride, ia.plane[p].data + y * ia.plane[p].stride,
                                        (size_t)ia.plane[p].width);
            assert_int_equal(sh_source_release(a, &fa), SH_OK);
            assert_int_equal(sh_source_release(b, &fb), SH_OK);
        }
        sh_image_destroy(&ia);
        sh_image_destroy(&ib);
        sh_source_close(a);
        sh_source_close(b);
    }
}

/* Two replays of one rig started 30 ms apart (as a loaded machine may start them): each one's
 * own start puts its schedule 30 ms after the other's, more than the quarter period a frame set
 * allows; sh_source_start_at with one clock gives frame k of both the stamp clock + k/fps
 * exactly, however late the second start. */
static void test_replays_share_a_start(void **state)
{
    (void)state;
    write_y4m(25, 1); /* 40 ms a frame: sets take stamps within 10 ms */
    sh_source_options o;
    sh_source_options_default(&o);
    o.realtime = 0;
    for (int shared = 0; shared < 2; shared++) {
        sh_source *s[2];
        int64_t clock = sh_monotonic_ns();
        for (int c = 0; c < 2; c++) {
            assert_int_equal(sh_source_open(spec, &o, &s[c]), SH_OK);
            if (c) usleep(30000);
            assert_int_equal(shared ? sh_source_start_at(s[c], clock) : sh_source_start(s[c]), SH_OK);
        }
        for (int k = 0; k < N; k++) {
            int64_t ts[2];
            for (int c = 0; c < 2; c++) {
                sh_source_frame fr;
                int got;
                assert_int_equal(sh_source_dequeue(s[c], 0, &fr, &got), SH_OK);
                assert_int_equal(got, 1);
                ts[c] = fr.timestamp_ns;
                assert_int_equal(sh_source_release(s[c], &fr), SH_OK);
            }
            if (shared) {
                assert_true(ts[0] == clock + (int64_t)k * 40000000 && ts[1] == ts[0]);
            } else if (ts[1] - ts[0] < 30000000) {
                fail_msg("frame %d: started 30 ms apart, the stamps differ by only %lld ns", k, (long long)(ts[1] - ts[0]));
            }
        }
        for (int c = 0; c < 2; c++) sh_source_close(s[c]);
    }
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

enum { FRAME_REC = 6 + W * H * 3 / 2 }; /* "FRAME\n" and an I420 frame */

/* The file's bytes, and the offset of its first FRAME line (the header's length). */
static unsigned char *slurp(size_t *len, size_t *header)
{
    FILE *f = fopen(path, "rb");
    assert_non_null(f);
    unsigned char *buf = malloc(1 << 16);
    *len = fread(buf, 1, 1 << 16, f);
    fclose(f);
    const unsigned char *nl = memchr(buf, '\n', *len);
    assert_non_null(nl);
    *header = (size_t)(nl - buf) + 1;
    assert_memory_equal(buf + *header, "FRAME\n", 6);
    assert_int_equal(*len, *header + (size_t)N * FRAME_REC); /* the layout counted by hand */
    return buf;
}

static void put_file(const unsigned char *buf, size_t len)
{
    FILE *f = fopen(path, "wb");
    assert_non_null(f);
    assert_int_equal(fwrite(buf, 1, len, f), len);
    assert_int_equal(fclose(f), 0);
}

/* Replays the file (loop or not) for up to `max` frames; returns the frames delivered, and the
 * status that ended it (SH_OK when max was reached) in *end. Frame k's luma must be k mod good. */
static int replay(int loop, int max, int good, sh_status *end, sh_source_stats *stats, char *damage)
{
    sh_source_options o;
    sh_source_options_default(&o);
    o.realtime = 0;
    o.loop = loop;
    sh_source *s;
    assert_int_equal(sh_source_open(spec, &o, &s), SH_OK);
    assert_int_equal(sh_source_start(s), SH_OK);
    int k = 0;
    *end = SH_OK;
    for (; k < max; k++) {
        int got = 0;
        sh_source_frame fr;
        sh_status st = sh_source_dequeue(s, 0, &fr, &got);
        if (st != SH_OK) {
            *end = st;
            if (st != SH_EEOF) snprintf(damage + 512, 512, "%s", sh_error_message());
            break;
        }
        assert_int_equal(got, 1);
        assert_int_equal(fr.raw.data[0], k % good);
        assert_int_equal(sh_source_release(s, &fr), SH_OK);
    }
    sh_source_get_stats(s, stats);
    snprintf(damage, 512, "%s", sh_source_damage(s));
    sh_source_close(s);
    return k;
}

static void expect_in(const char *text, const char *needle)
{
    if (!strstr(text, needle)) {
        print_error("'%s' lacks '%s'\n", text, needle);
        fail();
    }
}

/* A damaged FRAME line mid-stream: the frames before it, then an error saying where and how
 * much was lost, looping or not (a loop would show the first 3 frames as if they were the
 * file). A torn last frame (a killed recorder): the whole good part, looped with the damage
 * described once, or, not looping, ended by the error rather than a clean end. */
static void test_damaged_replays(void **state)
{
    (void)state;
    write_y4m(25, 1);
    size_t len, hdr;
    unsigned char *buf = slurp(&len, &hdr);
    char damage[1024], want[256];
    sh_status end;
    sh_source_stats st;

    buf[hdr + 3 * FRAME_REC + 4] = 'X'; /* FRAMX at frame 3 */
    put_file(buf, len);
    for (int loop = 0; loop < 2; loop++) {
        assert_int_equal(replay(loop, 4 * N, N, &end, &st, damage), 3);
        assert_int_equal(end, SH_EFORMAT);
        snprintf(want, sizeof want, "%s: frame 3: bad FRAME line at byte %zu; %d bytes (3 frames)", path,
                 hdr + 3 * FRAME_REC, 3 * FRAME_REC);
        expect_in(damage + 512, want);
        expect_in(damage, want);
        expect_in(damage, "the replay stops there");
        assert_int_equal(st.damaged, 1);
        assert_int_equal(st.lost_bytes, 3 * FRAME_REC);
        assert_int_equal(st.frames, 3);
    }

    buf[hdr + 3 * FRAME_REC + 4] = 'E';
    size_t cut = hdr + 5 * FRAME_REC + 100; /* frame 5: its FRAME line and 94 bytes */
    put_file(buf, cut);
    assert_int_equal(replay(0, 4 * N, 5, &end, &st, damage), 5);
    assert_int_equal(end, SH_EFORMAT);
    snprintf(want, sizeof want, "%s: frame 5 truncated (94 of %d bytes) at byte %zu; 100 bytes (1 frame)", path,
             FRAME_REC - 6, hdr + 5 * FRAME_REC);
    expect_in(damage + 512, want);
    assert_int_equal(st.damaged, 1);
    assert_int_equal(st.lost_bytes, 100);
    assert_int_equal(replay(1, 3 * 5, 5, &end, &st, damage), 15);
    assert_int_equal(end, SH_OK);
    expect_in(damage, want);
    expect_in(damage, "the frames before it are looped");
    assert_int_equal(st.damaged, 1); /* once, not on each of the three passes */
    assert_int_equal(st.errors, 1);
    free(buf);
}

/* A header that promises more than its file holds is refused at open, before a frame is
 * allocated: the 184 KB file saying W16384 H16384 (a 4:4:4 frame is 768 MiB). Peak
 * RSS is measured around the open. Sizes that would overflow are refused by the header. */
static void test_hostile_headers(void **state)
{
    (void)state;
    static const char *const heads[] = {"YUV4MPEG2 W16384 H16384 F25:1 C444\n", "YUV4MPEG2 W16384 H16384 F25:1\n",
                                        "YUV4MPEG2 W2147483647 H2147483647 F25:1\n",
                                        "YUV4MPEG2 W4294967297 H3 F25:1\n", "YUV4MPEG2 W32 H16 F25:1\n"};
    /* 16384^2 x 3 and x 1.5 bytes a frame; the rest of the file is 184000 less the header */
    static const char *const why[] = {"16384x16384 yuv444 frames of 805306368 bytes, the file holds %zu after",
                                      "16384x16384 i420 frames of 402653184 bytes, the file holds %zu after",
                                      "W2147483647", "W4294967297", "no frame in the file"};
    unsigned char *buf = calloc(1, 184000);
    struct rusage ru;
    getrusage(RUSAGE_SELF, &ru);
    long before = ru.ru_maxrss;
    for (int i = 0; i < 5; i++) {
        size_t n = strlen(heads[i]);
        memcpy(buf, heads[i], n);
        memcpy(buf + n, "FRAME\n", 6);
        put_file(buf, i == 4 ? n : 184000);
        sh_source_options o;
        sh_source_options_default(&o);
        sh_source *s = NULL;
        assert_int_equal(sh_source_open(spec, &o, &s), SH_EFORMAT);
        assert_null(s);
        expect_in(sh_error_message(), path);
        char want[160];
        snprintf(want, sizeof want, why[i], 184000 - n);
        expect_in(sh_error_message(), want);
    }
    /* a file that holds its frame: the options' bound, not the file, refuses it (at its size: accepted) */
    size_t n = strlen(heads[4]);
    memcpy(buf, heads[4], n);
    memcpy(buf + n, "FRAME\n", 6);
    put_file(buf, n + 6 + 32 * 16 * 3 / 2);
    sh_source_options o;
    sh_source_options_default(&o);
    assert_int_equal(o.max_frame_pixels, 3840 * 2160);
    sh_source *s = NULL;
    o.max_frame_pixels = 32 * 16 - 1;
    assert_int_equal(sh_source_open(spec, &o, &s), SH_ERANGE);
    assert_null(s);
    expect_in(sh_error_message(), "32x16 frames (512 pixels) are more than the 511 pixels a stream may have");
    o.max_frame_pixels = 32 * 16;
    assert_int_equal(sh_source_open(spec, &o, &s), SH_OK);
    sh_source_close(s);
    getrusage(RUSAGE_SELF, &ru);
    print_message("peak RSS %ld KiB before the hostile headers, %ld KiB after\n", before, ru.ru_maxrss);
    assert_true(ru.ru_maxrss - before < 16 * 1024);
    free(buf);
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
        cmocka_unit_test(test_dequeue_into),
        cmocka_unit_test(test_replays_share_a_start),
        cmocka_unit_test(test_loop_discontinuity),
        cmocka_unit_test(test_damaged_replays),
        cmocka_unit_test(test_hostile_headers),
        cmocka_unit_test(test_errors),
    };
    return cmocka_run_group_tests(tests, setup, teardown);
}
