/* Y4M reader and writer. Expected bytes and pixel values are built here from the YUV4MPEG2
 * layout (header line, "FRAME\n", packed Y then U then V planes), independently of the code.
 *
 * Over 600 lines: the reader's and the writer's tests share the byte builders at the top (the
 * expected bytes, made from the layout, not from the code): one file keeps one oracle for both. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <cmocka.h>

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>
#include <unistd.h>

#include "stillheart/y4m.h"

static char tmpdir[256];

static int setup(void **state)
{
    (void)state;
    snprintf(tmpdir, sizeof tmpdir, "/tmp/sh_test_y4m_XXXXXX");
    return mkdtemp(tmpdir) ? 0 : -1;
}

static int teardown(void **state)
{
    (void)state;
    char cmd[300];
    snprintf(cmd, sizeof cmd, "rm -rf '%s'", tmpdir);
    return system(cmd) == 0 ? 0 : -1;
}

static const char *tmp_path(const char *name)
{
    static char path[2][400];
    static int k;
    k ^= 1;
    snprintf(path[k], sizeof path[k], "%s/%s", tmpdir, name);
    return path[k];
}

static void write_bytes(const char *path, const void *data, size_t len)
{
    FILE *f = fopen(path, "wb");
    assert_non_null(f);
    assert_int_equal(fwrite(data, 1, len, f), len);
    assert_int_equal(fclose(f), 0);
}

static uint8_t *slurp(const char *path, size_t *len)
{
    FILE *f = fopen(path, "rb");
    assert_non_null(f);
    size_t cap = 1 << 16, n = 0;
    uint8_t *buf = malloc(cap);
    size_t got;
    while ((got = fread(buf + n, 1, cap - n, f)) > 0) {
        n += got;
        if (n == cap) buf = realloc(buf, cap *= 2);
    }
    fclose(f);
    *len = n;
    return buf;
}

/* A stream: header, then `frames` frames of `frame_bytes` bytes, byte k of frame f = 7k+31f+1. */
static uint8_t *make_stream(const char *header, int frames, size_t frame_bytes, size_t *len)
{
    size_t hlen = strlen(header);
    size_t total = hlen + (size_t)frames * (6 + frame_bytes);
    uint8_t *buf = malloc(total), *p = buf;
    memcpy(p, header, hlen);
    p += hlen;
    for (int f = 0; f < frames; f++) {
        memcpy(p, "FRAME\n", 6);
        p += 6;
        for (size_t k = 0; k < frame_bytes; k++) *p++ = (uint8_t)(7 * k + 31 * (size_t)f + 1);
    }
    *len = total;
    return buf;
}

/* Packed byte index of (plane, x, y) for the spec's layout. */
static uint8_t expected_sample(int f, size_t plane_offset, int plane_w, int x, int y)
{
    size_t k = plane_offset + (size_t)y * (size_t)plane_w + (size_t)x;
    return (uint8_t)(7 * k + 31 * (size_t)f + 1);
}

typedef struct {
    const char *tag;
    sh_pixfmt format;
    sh_chroma_siting siting;
    int chroma_w, chroma_h, planes; /* for a 5x3 frame */
} colour_case;

static const colour_case colour_cases[] = {
    {"mono", SH_PIX_GRAY8, SH_CHROMA_CENTER, 0, 0, 1},
    {"420jpeg", SH_PIX_I420, SH_CHROMA_CENTER, 3, 2, 3},
    {"420mpeg2", SH_PIX_I420, SH_CHROMA_LEFT, 3, 2, 3},
    {"420paldv", SH_PIX_I420, SH_CHROMA_PALDV, 3, 2, 3},
    {"444", SH_PIX_YUV444, SH_CHROMA_CENTER, 5, 3, 3},
};

/* Read then write every colour space: the output is the input, byte for byte, and the pixels
 * land where the spec's packed layout puts them (the images have padded strides). */
static void test_round_trip_every_colour_space(void **state)
{
    (void)state;
    for (size_t c = 0; c < sizeof colour_cases / sizeof colour_cases[0]; c++) {
        const colour_case *cc = &colour_cases[c];
        char header[256];
        snprintf(header, sizeof header,
                 "YUV4MPEG2 W5 H3 F30000:1001 It A128:117 C%s XCOLORRANGE=FULL XYSCSS=%s Zfuture\n",
                 cc->tag, cc->tag);
        size_t luma = 15, chroma = (size_t)(cc->chroma_w * cc->chroma_h);
        size_t frame_bytes = luma + (cc->planes == 3 ? 2 * chroma : 0), len;
        uint8_t *in = make_stream(header, 3, frame_bytes, &len);
        const char *src = tmp_path("in.y4m"), *dst = tmp_path("out.y4m");
        write_bytes(src, in, len);

        sh_y4m_reader *r;
        assert_int_equal(sh_y4m_reader_open(src, &r), SH_OK);
        const sh_y4m_header *h = sh_y4m_reader_header(r);
        assert_int_equal(h->width, 5);
        assert_int_equal(h->height, 3);
        assert_int_equal(h->format, cc->format);
        if (cc->format == SH_PIX_I420) assert_int_equal(h->siting, cc->siting);
        assert_int_equal(h->fps_num, 30000);
        assert_int_equal(h->fps_den, 1001);
        assert_int_equal(h->aspect_num, 128);
        assert_int_equal(h->aspect_den, 117);
        assert_int_equal(h->interlace, 't');
        char extra[128];
        snprintf(extra, sizeof extra, "XCOLORRANGE=FULL XYSCSS=%s Zfuture", cc->tag);
        assert_string_equal(h->extra, extra);

        sh_y4m_writer *w;
        assert_int_equal(sh_y4m_writer_open(dst, h, &w), SH_OK);
        sh_image img;
        assert_int_equal(sh_image_create(&img, h->format, h->width, h->height), SH_OK);
        assert_true(img.plane[0].stride > 5); /* the padded path is exercised */
        for (int f = 0; f < 3; f++) {
            assert_int_equal(sh_y4m_reader_frame_index(r), f);
            assert_int_equal(sh_y4m_reader_read(r, &img), SH_OK);
            if (cc->format == SH_PIX_I420) assert_int_equal(img.siting, cc->siting);
            assert_int_equal(img.plane[0].data[2 * img.plane[0].stride + 4],
                             expected_sample(f, 0, 5, 4, 2));
            if (cc->planes == 3) {
                assert_int_equal(img.plane[1].data[1 * img.plane[1].stride + 2],
                                 expected_sample(f, luma, cc->chroma_w, 2, 1));
                assert_int_equal(img.plane[2].data[0 * img.plane[2].stride + 1],
                                 expected_sample(f, luma + chroma, cc->chroma_w, 1, 0));
            }
            assert_int_equal(sh_y4m_writer_write(w, &img), SH_OK);
        }
        assert_int_equal(sh_y4m_reader_read(r, &img), SH_EEOF);
        assert_int_equal(sh_y4m_reader_read(r, &img), SH_EEOF);
        assert_int_equal(sh_y4m_reader_frame_index(r), 3);
        sh_y4m_reader_close(r);
        assert_int_equal(sh_y4m_writer_close(w), SH_OK);

        size_t olen;
        uint8_t *out = slurp(dst, &olen);
        assert_int_equal(olen, len);
        assert_memory_equal(out, in, len);
        free(out);
        free(in);
        sh_image_destroy(&img);
    }
}

static sh_status open_header(const char *header, sh_y4m_reader **r)
{
    const char *p = tmp_path("h.y4m");
    write_bytes(p, header, strlen(header));
    return sh_y4m_reader_open(p, r);
}

static void test_default_and_plain_420(void **state)
{
    (void)state;
    sh_y4m_reader *r;
    assert_int_equal(open_header("YUV4MPEG2 W4 H2\n", &r), SH_OK);
    assert_int_equal(sh_y4m_reader_header(r)->format, SH_PIX_I420);
    assert_int_equal(sh_y4m_reader_header(r)->siting, SH_CHROMA_CENTER);
    assert_int_equal(sh_y4m_reader_header(r)->fps_num, 0);
    assert_int_equal(sh_y4m_reader_header(r)->interlace, 0);
    assert_string_equal(sh_y4m_reader_header(r)->extra, "");
    sh_image img;
    assert_int_equal(sh_image_create(&img, SH_PIX_I420, 4, 2), SH_OK);
    assert_int_equal(sh_y4m_reader_read(r, &img), SH_EEOF); /* header only: a clean end */
    sh_image_destroy(&img);

    /* written back with the explicit tag of the same siting */
    char *buf = NULL;
    size_t len = 0;
    FILE *mem = open_memstream(&buf, &len);
    sh_y4m_writer *w;
    assert_int_equal(sh_y4m_writer_open_file(mem, "mem", sh_y4m_reader_header(r), &w), SH_OK);
    assert_int_equal(sh_y4m_writer_close(w), SH_OK);
    fclose(mem);
    assert_string_equal(buf, "YUV4MPEG2 W4 H2 C420jpeg\n");
    free(buf);
    sh_y4m_reader_close(r);

    assert_int_equal(open_header("YUV4MPEG2 W4 H2 C420 I?\n", &r), SH_OK);
    assert_int_equal(sh_y4m_reader_header(r)->siting, SH_CHROMA_CENTER);
    assert_string_equal(sh_y4m_reader_header(r)->extra, "I?");
    sh_y4m_reader_close(r);
}

static void expect_error(const char *header, sh_status code, const char *needle)
{
    sh_y4m_reader *r = (sh_y4m_reader *)1;
    assert_int_equal(open_header(header, &r), code);
    assert_null(r);
    if (!strstr(sh_error_message(), needle) || !strstr(sh_error_message(), tmp_path("h.y4m"))) {
        print_error("message '%s' lacks '%s' or the file name\n", sh_error_message(), needle);
        fail();
    }
}

static void test_unsupported_colour_spaces(void **state)
{
    (void)state;
    expect_error("YUV4MPEG2 W4 H2 C422\n", SH_EUNSUPPORTED, "C422");
    expect_error("YUV4MPEG2 W4 H2 C444alpha\n", SH_EUNSUPPORTED, "C444alpha");
    expect_error("YUV4MPEG2 W4 H2 C420p10 XYSCSS=420P10\n", SH_EUNSUPPORTED, "C420p10");
    expect_error("YUV4MPEG2 C411 W4 H2\n", SH_EUNSUPPORTED, "C411");
}

static void test_damaged_headers(void **state)
{
    (void)state;
    expect_error("", SH_EFORMAT, "empty");
    expect_error("YUV4MPEG W4 H2\n", SH_EFORMAT, "magic");
    expect_error("YUV4MPEG2X W4 H2\n", SH_EFORMAT, "magic");
    expect_error("YUV4MPEG2 W4 H2", SH_EFORMAT, "not terminated");
    expect_error("YUV4MPEG2 W0 H2\n", SH_EFORMAT, "W0");
    expect_error("YUV4MPEG2 W-4 H2\n", SH_EFORMAT, "W-4");
    expect_error("YUV4MPEG2 W4 H32768\n", SH_EFORMAT, "H32768");
    expect_error("YUV4MPEG2 W99999999999 H2\n", SH_EFORMAT, "W99999999999");
    expect_error("YUV4MPEG2 W4x H2\n", SH_EFORMAT, "W4x");
    expect_error("YUV4MPEG2 W4\n", SH_EFORMAT, "H (height)");
    expect_error("YUV4MPEG2 H4\n", SH_EFORMAT, "W (width)");
    expect_error("YUV4MPEG2 W4 H2 W4\n", SH_EFORMAT, "repeats W");
    expect_error("YUV4MPEG2 W4 H2 F30\n", SH_EFORMAT, "F30");
    expect_error("YUV4MPEG2 W4 H2 F30:0\n", SH_EFORMAT, "F30:0");
    expect_error("YUV4MPEG2 W4 H2 A1:0\n", SH_EFORMAT, "A1:0");

    char big[1400] = "YUV4MPEG2 W4 H2";
    while (strlen(big) < 1200) strcat(big, " XPAD=0123456789");
    strcat(big, "\n");
    expect_error(big, SH_EFORMAT, "extra tags exceed");
    char huge[2000] = "YUV4MPEG2 W4 H2 X";
    while (strlen(huge) < 1900) strcat(huge, "x");
    strcat(huge, "\n");
    expect_error(huge, SH_EFORMAT, "longer than");

    sh_y4m_header h;
    assert_int_equal(sh_y4m_header_parse("YUV4MPEG2  W4  H2 ", 18, &h), SH_OK);
    assert_int_equal(h.width, 4);
    assert_int_equal(sh_y4m_header_parse("YUV4MPEG2 W4 H\0", 15, &h), SH_EFORMAT);
}

/* 3 frames of a 4x2 mono stream with `tail` replacing the third frame. */
static const char *stream_with_third(const char *tail, size_t tail_len)
{
    size_t len;
    uint8_t *base = make_stream("YUV4MPEG2 W4 H2 Cmono\n", 2, 8, &len);
    uint8_t *buf = malloc(len + tail_len);
    memcpy(buf, base, len);
    memcpy(buf + len, tail, tail_len);
    const char *p = tmp_path("t.y4m");
    write_bytes(p, buf, len + tail_len);
    free(base);
    free(buf);
    return p;
}

static void expect_third_frame_error(const char *tail, size_t tail_len, const char *reason)
{
    const char *p = stream_with_third(tail, tail_len);
    sh_y4m_reader *r;
    assert_int_equal(sh_y4m_reader_open(p, &r), SH_OK);
    sh_image img;
    assert_int_equal(sh_image_create(&img, SH_PIX_GRAY8, 4, 2), SH_OK);
    for (int f = 0; f < 2; f++) {
        assert_int_equal(sh_y4m_reader_read(r, &img), SH_OK);
        assert_int_equal(img.plane[0].data[img.plane[0].stride + 3], expected_sample(f, 0, 4, 3, 1));
    }
    assert_int_equal(sh_y4m_reader_read(r, &img), SH_EFORMAT);
    char want[600];
    snprintf(want, sizeof want, "%s: frame 2", p);
    if (!strstr(sh_error_message(), want) || !strstr(sh_error_message(), reason)) {
        print_error("message '%s' lacks '%s' or '%s'\n", sh_error_message(), want, reason);
        fail();
    }
    assert_int_equal(sh_y4m_reader_frame_index(r), 2);
    /* where: after the 22-byte header and two frames of "FRAME\n" + 8 bytes; what is lost: the
     * tail, in bytes and in (started) 14-byte frames */
    sh_y4m_damage d;
    assert_int_equal(sh_y4m_reader_damage(r, &d), 1);
    assert_int_equal(d.frame, 2);
    assert_int_equal(d.offset, 22 + 2 * 14);
    assert_int_equal(d.lost, (long long)tail_len);
    assert_int_equal(d.frames_lost, ((long long)tail_len + 13) / 14);
    snprintf(want, sizeof want, "at byte 50; %zu bytes (%lld frame%s) from there to the end not read", tail_len,
             d.frames_lost, d.frames_lost == 1 ? "" : "s");
    if (!strstr(sh_error_message(), want)) {
        print_error("message '%s' lacks '%s'\n", sh_error_message(), want);
        fail();
    }
    assert_int_equal(sh_y4m_reader_read(r, &img), SH_EFORMAT); /* stays failed */
    sh_y4m_reader_close(r);
    sh_image_destroy(&img);
}

static void test_truncated_and_damaged_frames(void **state)
{
    (void)state;
    expect_third_frame_error("FRAME\nabc", 9, "truncated (3 of 8 bytes)");
    expect_third_frame_error("FRAME\n", 6, "truncated (0 of 8 bytes)");
    expect_third_frame_error("FRA", 3, "truncated FRAME line");
    expect_third_frame_error("FRAMX\n12345678", 14, "bad FRAME line");
    expect_third_frame_error("FRAMES\n12345678", 15, "bad FRAME line");
    expect_third_frame_error("\n", 1, "bad FRAME line");
    /* damage with good frames behind it: all of them counted as lost */
    expect_third_frame_error("FRAMX\n12345678FRAME\n12345678FRAME\n1234", 38, "bad FRAME line");
}

/* The header's frame size against the file's: refused at open when the file after the header
 * holds less than one frame; whole frames counted from the file's size. */
static void test_frame_size_against_file(void **state)
{
    (void)state;
    expect_error("YUV4MPEG2 W16384 H16384 C444\nFRAME\n0123456789", SH_EFORMAT,
                 "promises 16384x16384 yuv444 frames of 805306368 bytes, the file holds 16 after its header");
    expect_error("YUV4MPEG2 W4 H2 Cmono\nFRAME\n1234567", SH_EFORMAT, "frames of 8 bytes, the file holds 13");
    expect_error("YUV4MPEG2 W2147483647 H2147483647\n", SH_EFORMAT, "W2147483647");
    expect_error("YUV4MPEG2 W16384 H16385\n", SH_EFORMAT, "H16385");
    sh_y4m_reader *r;
    assert_int_equal(open_header("YUV4MPEG2 W4 H2 Cmono\nFRAME\n12345678FRAME\n12345678FRAME\n12", &r), SH_OK);
    assert_int_equal(sh_y4m_reader_whole_frames(r), 2);
    sh_image img;
    assert_int_equal(sh_image_create(&img, SH_PIX_GRAY8, 4, 2), SH_OK);
    assert_int_equal(sh_y4m_reader_read(r, &img), SH_OK);
    assert_int_equal(sh_y4m_reader_whole_frames(r), 1);
    assert_int_equal(sh_y4m_reader_damage(r, NULL), 0);
    sh_y4m_reader_close(r);
    sh_image_destroy(&img);
    /* a stream of unknown size (a pipe here, as fmemopen) is not measured */
    static char text[] = "YUV4MPEG2 W4 H2 Cmono\nFRAME\n12";
    FILE *mem = fmemopen(text, sizeof text - 1, "rb");
    assert_int_equal(sh_y4m_reader_open_file(mem, "mem", &r), SH_OK);
    assert_int_equal(sh_y4m_reader_whole_frames(r), -1);
    sh_y4m_reader_close(r);
    fclose(mem);
}

/* The bound on a frame's pixels, where the file's size cannot help (a stream of unknown size,
 * fmemopen here as a pipe) and where it does not (a file holding the frames): 3840x2160 is the
 * default bound exactly (image.h), one more column is refused, and a caller's bound replaces it. */
static sh_status open_mem(const char *text, sh_y4m_reader **r)
{
    static char buf[128];
    snprintf(buf, sizeof buf, "%s", text);
    FILE *mem = fmemopen(buf, strlen(buf), "rb");
    assert_non_null(mem);
    sh_status st = sh_y4m_reader_open_file(mem, "pipe", r);
    if (st == SH_OK) sh_y4m_reader_close(*r);
    fclose(mem);
    return st;
}

static void expect_in_message(const char *needle)
{
    if (!strstr(sh_error_message(), needle)) {
        print_error("message '%s' lacks '%s'\n", sh_error_message(), needle);
        fail();
    }
}

static void test_frame_pixels_bounded(void **state)
{
    (void)state;
    sh_y4m_reader *r;
    assert_int_equal(open_mem("YUV4MPEG2 W16384 H16384 C444\nFRAME\n0123", &r), SH_ERANGE);
    expect_in_message("pipe: 16384x16384 frames (268435456 pixels) are more than the 8294400 pixels a stream may have");
    assert_int_equal(open_mem("YUV4MPEG2 W3841 H2160 Cmono\nFRAME\n0123", &r), SH_ERANGE);
    expect_in_message("3841x2160 frames (8296560 pixels)");
    assert_int_equal(open_mem("YUV4MPEG2 W3840 H2160 C444\nFRAME\n0123", &r), SH_OK);
    assert_int_equal(open_mem("YUV4MPEG2 W2160 H3840\n", &r), SH_OK);
    /* a regular file that holds its frames: the file's size is no bound, the caller's is */
    const char data[] = "YUV4MPEG2 W4 H2 Cmono\nFRAME\n12345678FRAME\n12345678";
    const char *p = tmp_path("bounded.y4m");
    write_bytes(p, data, sizeof data - 1);
    r = (sh_y4m_reader *)1;
    assert_int_equal(sh_y4m_reader_open_max(p, 7, &r), SH_ERANGE);
    assert_null(r);
    expect_in_message(p);
    expect_in_message("4x2 frames (8 pixels) are more than the 7 pixels");
    assert_int_equal(sh_y4m_reader_open_max(p, 8, &r), SH_OK);
    assert_int_equal(sh_y4m_reader_whole_frames(r), 2);
    sh_y4m_reader_close(r);
}

static void test_frame_parameters_skipped(void **state)
{
    (void)state;
    const char data[] = "YUV4MPEG2 W2 H1 Cmono\nFRAME Ixyz XFOO=1\nabFRAME\ncd";
    const char *p = tmp_path("params.y4m");
    write_bytes(p, data, sizeof data - 1);
    sh_y4m_reader *r;
    assert_int_equal(sh_y4m_reader_open(p, &r), SH_OK);
    sh_image img;
    assert_int_equal(sh_image_create(&img, SH_PIX_GRAY8, 2, 1), SH_OK);
    assert_int_equal(sh_y4m_reader_read(r, &img), SH_OK);
    assert_memory_equal(img.plane[0].data, "ab", 2);
    assert_int_equal(sh_y4m_reader_read(r, &img), SH_OK);
    assert_memory_equal(img.plane[0].data, "cd", 2);
    assert_int_equal(sh_y4m_reader_read(r, &img), SH_EEOF);
    sh_y4m_reader_close(r);
    sh_image_destroy(&img);
}

static void test_wrong_image_refused(void **state)
{
    (void)state;
    sh_y4m_reader *r;
    assert_int_equal(open_header("YUV4MPEG2 W4 H2 C444\n", &r), SH_OK);
    sh_image img;
    assert_int_equal(sh_image_create(&img, SH_PIX_I420, 4, 2), SH_OK);
    assert_int_equal(sh_y4m_reader_read(r, &img), SH_EINVAL);
    sh_y4m_reader_close(r);
    sh_image_destroy(&img);
}

/* Another format's first bytes: the refusal names what it looks like and the ffmpeg command that
 * converts it (issue 18's wording), instead of a Y4M header that is too long or not terminated. */
static void expect_not_y4m(const char *file, const void *head, size_t n, const char *kind,
                           const char *command)
{
    char bytes[4096] = {0}; /* the rest as a container would go on: binary, no newline soon */
    memcpy(bytes, head, n);
    for (size_t i = n; i < sizeof bytes; i++) bytes[i] = (char)(0x80 + i % 61);
    const char *p = tmp_path(file);
    write_bytes(p, bytes, sizeof bytes);
    sh_y4m_reader *r = (sh_y4m_reader *)1;
    assert_int_equal(sh_y4m_reader_open(p, &r), SH_EFORMAT);
    assert_null(r);
    char want[1024];
    snprintf(want, sizeof want, "%s is not a Y4M video (%s); convert it: %s", p, kind, command);
    assert_string_equal(sh_error_message(), want);
}

static void test_other_formats_name_ffmpeg(void **state)
{
    (void)state;
    char cmd[1024];
    /* an MP4's first box: size, "ftyp", brand */
    snprintf(cmd, sizeof cmd, "ffmpeg -i %s/clip.mp4 -pix_fmt yuv420p -f yuv4mpegpipe %s/clip.y4m",
             tmpdir, tmpdir);
    expect_not_y4m("clip.mp4", "\0\0\0\x20" "ftypisom\0\0\2\0", 16, "it looks like MP4", cmd);
    snprintf(cmd, sizeof cmd, "ffmpeg -i %s/a.mov -pix_fmt yuv420p -f yuv4mpegpipe %s/a.y4m",
             tmpdir, tmpdir);
    expect_not_y4m("a.mov", "\0\0\0\x14" "ftypqt  ", 12, "it looks like QuickTime MOV", cmd);
    /* EBML's magic, quoted because of the space; a name already ending .y4m gets another */
    snprintf(cmd, sizeof cmd,
             "ffmpeg -i '%s/my clip.y4m' -pix_fmt yuv420p -f yuv4mpegpipe '%s/my clip-yuv.y4m'",
             tmpdir, tmpdir);
    expect_not_y4m("my clip.y4m", "\x1a\x45\xdf\xa3\x01\0\0\0", 8,
                   "it looks like Matroska or WebM", cmd);
    snprintf(cmd, sizeof cmd, "ffmpeg -i %s/shot.png -pix_fmt yuv420p -f yuv4mpegpipe %s/shot.y4m",
             tmpdir, tmpdir);
    expect_not_y4m("shot.png", "\x89PNG\r\n\x1a\n\0\0\0\x0dIHDR", 16, "it looks like a PNG image", cmd);
    snprintf(cmd, sizeof cmd, "ffmpeg -i %s/v.avi -pix_fmt yuv420p -f yuv4mpegpipe %s/v.y4m",
             tmpdir, tmpdir);
    expect_not_y4m("v.avi", "RIFF\x10\0\0\0AVI LIST", 16, "it looks like AVI", cmd);
    /* unknown bytes: no guess, still the command; a name without an extension */
    snprintf(cmd, sizeof cmd, "ffmpeg -i %s/raw -pix_fmt yuv420p -f yuv4mpegpipe %s/raw.y4m",
             tmpdir, tmpdir);
    expect_not_y4m("raw", "\x10\x20\x30\x40", 4, "it does not begin with the YUV4MPEG2 magic",
                   cmd);
    /* short files: as much as there is decides */
    write_bytes(tmp_path("short.mp4"), "\0\0\0\x18" "ftyp", 8);
    sh_y4m_reader *r;
    assert_int_equal(sh_y4m_reader_open(tmp_path("short.mp4"), &r), SH_EFORMAT);
    assert_non_null(strstr(sh_error_message(), "(it looks like MP4); convert it: ffmpeg -i "));
    /* a Y4M header cut inside its magic, or that ends right after it, is still a Y4M matter */
    expect_error("YUV4MPEG2 W4", SH_EFORMAT, "not terminated");
    expect_error("YUV4MPEG2 \n", SH_EFORMAT, "lacks");
}

/* Reading "-" from a pipe: large frames arrive in pieces and nothing may seek. */
static void test_stdin_pipe(void **state)
{
    (void)state;
    const int w = 640, h = 480, frames = 4;
    size_t fb = (size_t)w * h * 3 / 2, len;
    uint8_t *data = make_stream("YUV4MPEG2 W640 H480 F25:1 C420mpeg2\n", frames, fb, &len);
    int fd[2];
    assert_int_equal(pipe(fd), 0);
    pid_t pid = fork();
    assert_true(pid >= 0);
    if (pid == 0) {
        close(fd[0]);
        size_t off = 0;
        while (off < len) { /* dribble in odd-sized pieces */
            size_t n = len - off < 7777 ? len - off : 7777;
            ssize_t k = write(fd[1], data + off, n);
            if (k <= 0) _exit(1);
            off += (size_t)k;
        }
        _exit(0);
    }
    close(fd[1]);
    int saved = dup(STDIN_FILENO);
    assert_int_equal(dup2(fd[0], STDIN_FILENO), STDIN_FILENO);
    close(fd[0]);
    clearerr(stdin);

    sh_y4m_reader *r;
    assert_int_equal(sh_y4m_reader_open("-", &r), SH_OK);
    assert_int_equal(sh_y4m_reader_header(r)->siting, SH_CHROMA_LEFT);
    sh_image img;
    assert_int_equal(sh_image_create(&img, SH_PIX_I420, w, h), SH_OK);
    for (int f = 0; f < frames; f++) {
        assert_int_equal(sh_y4m_reader_read(r, &img), SH_OK);
        assert_int_equal(img.plane[0].data[479 * img.plane[0].stride + 639],
                         expected_sample(f, 0, w, 639, 479));
        assert_int_equal(img.plane[2].data[239 * img.plane[2].stride + 319],
                         expected_sample(f, (size_t)w * h + (size_t)w * h / 4, w / 2, 319, 239));
    }
    assert_int_equal(sh_y4m_reader_read(r, &img), SH_EEOF);
    sh_y4m_reader_close(r);
    sh_image_destroy(&img);
    int status;
    waitpid(pid, &status, 0);
    assert_true(WIFEXITED(status) && WEXITSTATUS(status) == 0);
    dup2(saved, STDIN_FILENO);
    close(saved);
    clearerr(stdin);
    free(data);
}

static void test_writer_errors(void **state)
{
    (void)state;
    sh_y4m_header h = {.width = 4, .height = 2, .format = SH_PIX_GRAY8};
    sh_y4m_writer *w;
    /* A full disk is seen when the buffered frames are flushed at close. */
    if (access("/dev/full", W_OK) == 0) {
        assert_int_equal(sh_y4m_writer_open("/dev/full", &h, &w), SH_OK);
        sh_image img;
        assert_int_equal(sh_image_create(&img, SH_PIX_GRAY8, 4, 2), SH_OK);
        assert_int_equal(sh_y4m_writer_write(w, &img), SH_OK);
        assert_int_equal(sh_y4m_writer_close(w), SH_EIO);
        assert_non_null(strstr(sh_error_message(), "/dev/full"));
        sh_image_destroy(&img);
    }
    assert_int_equal(sh_y4m_writer_open("/nonexistent-dir/x.y4m", &h, &w), SH_EIO);
    assert_non_null(strstr(sh_error_message(), "/nonexistent-dir/x.y4m"));

    sh_y4m_header bad = h;
    bad.format = SH_PIX_RGB24;
    assert_int_equal(sh_y4m_writer_open(tmp_path("bad.y4m"), &bad, &w), SH_EINVAL);
    bad = h;
    strcpy(bad.extra, "XA=1\nFRAME");
    assert_int_equal(sh_y4m_writer_open(tmp_path("bad.y4m"), &bad, &w), SH_EINVAL);

    assert_int_equal(sh_y4m_writer_open(tmp_path("ok.y4m"), &h, &w), SH_OK);
    sh_image other;
    assert_int_equal(sh_image_create(&other, SH_PIX_GRAY8, 4, 3), SH_OK);
    assert_int_equal(sh_y4m_writer_write(w, &other), SH_EINVAL);
    assert_int_equal(sh_y4m_writer_close(w), SH_OK);
    sh_image_destroy(&other);

    sh_y4m_reader *r;
    assert_int_equal(sh_y4m_reader_open("/nonexistent-dir/x.y4m", &r), SH_EIO);
    assert_non_null(strstr(sh_error_message(), "/nonexistent-dir/x.y4m"));
}

/* Full range is the whole tag XCOLORRANGE=FULL among the X tags, not a prefix of another. */
static void test_full_range_tag(void **state)
{
    (void)state;
    static const struct {
        const char *extra;
        int full;
    } cases[] = {{"XCOLORRANGE=FULL", 1}, {"XLOOP=SEAMLESS XCOLORRANGE=FULL", 1}, {"XCOLORRANGE=FULL XA=1", 1},
                 {"", 0}, {"XCOLORRANGE=LIMITED", 0}, {"XCOLORRANGE=FULLY", 0}};
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        sh_y4m_header h;
        memset(&h, 0, sizeof h);
        snprintf(h.extra, sizeof h.extra, "%s", cases[i].extra);
        assert_int_equal(sh_y4m_header_full_range(&h), cases[i].full);
    }
}

/* XSTILLHEART=method:NAME set over an input's tags: the input's own one replaced (never two),
 * the others kept in order, and read back from the file a writer made. */
static void test_stillheart_tag(void **state)
{
    (void)state;
    sh_y4m_header h;
    memset(&h, 0, sizeof h);
    h.width = 4, h.height = 2, h.format = SH_PIX_GRAY8;
    strcpy(h.extra, "XCOLORRANGE=FULL XSTILLHEART=method:bspline XSTILLHEARTX=1 XSTILLHEART");
    assert_int_equal(sh_y4m_header_set_tag(&h, SH_Y4M_STILLHEART, "method:tps"), SH_OK);
    assert_string_equal(h.extra, "XCOLORRANGE=FULL XSTILLHEARTX=1 XSTILLHEART=method:tps");
    assert_int_equal(sh_y4m_header_set_tag(&h, SH_Y4M_STILLHEART, "method:gaussian-pure"), SH_OK);
    assert_string_equal(h.extra, "XCOLORRANGE=FULL XSTILLHEARTX=1 XSTILLHEART=method:gaussian-pure");

    const char *file = tmp_path("tagged.y4m");
    sh_y4m_writer *w;
    assert_int_equal(sh_y4m_writer_open(file, &h, &w), SH_OK);
    assert_int_equal(sh_y4m_writer_close(w), SH_OK);
    size_t len;
    uint8_t *bytes = slurp(file, &len);
    static const char line[] = "YUV4MPEG2 W4 H2 Cmono XCOLORRANGE=FULL XSTILLHEARTX=1 XSTILLHEART=method:gaussian-pure\n";
    assert_int_equal(len, strlen(line));
    assert_memory_equal(bytes, line, len);
    free(bytes);
    sh_y4m_reader *r;
    assert_int_equal(sh_y4m_reader_open(file, &r), SH_OK);
    char value[32];
    assert_int_equal(sh_y4m_header_tag(sh_y4m_reader_header(r), SH_Y4M_STILLHEART, value, sizeof value), 1);
    assert_string_equal(value, "method:gaussian-pure");
    assert_int_equal(sh_y4m_header_tag(sh_y4m_reader_header(r), "XSTILLHEARTX", value, 4), 1);
    assert_string_equal(value, "1");
    assert_int_equal(sh_y4m_header_tag(sh_y4m_reader_header(r), "XSTILL", value, sizeof value), 0);
    assert_int_equal(sh_y4m_header_full_range(sh_y4m_reader_header(r)), 1);
    sh_y4m_reader_close(r);

    /* a tag with nothing else; refusals leave the header as it was */
    memset(h.extra, 0, sizeof h.extra);
    assert_int_equal(sh_y4m_header_set_tag(&h, "XA", "1"), SH_OK);
    assert_string_equal(h.extra, "XA=1");
    assert_int_equal(sh_y4m_header_set_tag(&h, SH_Y4M_STILLHEART, "method:tps x"), SH_EINVAL);
    assert_int_equal(sh_y4m_header_set_tag(&h, SH_Y4M_STILLHEART, ""), SH_EINVAL);
    assert_int_equal(sh_y4m_header_set_tag(&h, "X=Y", "1"), SH_EINVAL);
    assert_int_equal(sh_y4m_header_set_tag(&h, SH_Y4M_STILLHEART, "method:tps\nFRAME"), SH_EINVAL);
    memset(h.extra, 'Z', sizeof h.extra - 20);
    h.extra[sizeof h.extra - 20] = 0;
    assert_int_equal(sh_y4m_header_set_tag(&h, SH_Y4M_STILLHEART, "method:tps"), SH_ERANGE);
    assert_int_equal(strlen(h.extra), sizeof h.extra - 20);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_round_trip_every_colour_space),
        cmocka_unit_test(test_default_and_plain_420),
        cmocka_unit_test(test_unsupported_colour_spaces),
        cmocka_unit_test(test_damaged_headers),
        cmocka_unit_test(test_truncated_and_damaged_frames),
        cmocka_unit_test(test_frame_size_against_file),
        cmocka_unit_test(test_frame_pixels_bounded),
        cmocka_unit_test(test_frame_parameters_skipped),
        cmocka_unit_test(test_wrong_image_refused),
        cmocka_unit_test(test_stdin_pipe),
        cmocka_unit_test(test_other_formats_name_ffmpeg),
        cmocka_unit_test(test_writer_errors),
        cmocka_unit_test(test_full_range_tag),
        cmocka_unit_test(test_stillheart_tag),
    };
    return cmocka_run_group_tests(tests, setup, teardown);
}
