/* libFuzzer: arbitrary bytes as a Y4M stream. Reads every frame, and checks that whatever was
 * read writes back and reads again to the same header and pixels (a round-trip oracle, so the
 * fuzzer finds wrong answers as well as crashes). The same bytes as a regular file (a memfd)
 * take the path that measures the header's frame size against the file and the damage, and,
 * opened by name with a bound on a frame's pixels taken from the input's length, the bound's
 * refusal: every accepted header is within its bound, every refused one over it. */
#define _GNU_SOURCE
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <unistd.h>

#include "stillheart/y4m.h"

/* Frames above this are not allocated: libFuzzer's malloc limit, not the reader, would fail. */
#define MAX_FRAME_BYTES (4u << 20)

static void check(int ok)
{
    if (!ok) abort();
}

static int same_pixels(const sh_image *a, const sh_image *b)
{
    for (int p = 0; p < a->num_planes; p++)
        for (int y = 0; y < a->plane[p].height; y++)
            if (memcmp(a->plane[p].data + (size_t)y * a->plane[p].stride,
                       b->plane[p].data + (size_t)y * b->plane[p].stride,
                       (size_t)a->plane[p].width * (size_t)sh_pixfmt_channels(a->format)))
                return 0;
    return 1;
}

/* As a regular file: an accepted header leaves room for at least one whole frame (or none at
 * all), the frames read are at most the whole frames counted, and damage is located at the
 * frame that failed, with what lies behind it. */
static void as_file(const uint8_t *data, size_t size)
{
    int fd = memfd_create("fuzz.y4m", 0);
    if (fd < 0) return;
    FILE *f = fdopen(fd, "w+b");
    check(f && fwrite(data, 1, size, f) == size && fseek(f, 0, SEEK_SET) == 0);
    sh_y4m_reader *r;
    if (sh_y4m_reader_open_file(f, "fuzz.y4m", &r) != SH_OK) {
        check(strstr(sh_error_message(), "fuzz.y4m") != NULL);
        fclose(f);
        return;
    }
    const sh_y4m_header *h = sh_y4m_reader_header(r);
    size_t bytes = sh_image_packed_size(h->format, h->width, h->height);
    long long whole = sh_y4m_reader_whole_frames(r);
    check(whole >= 0 && whole <= (long long)size / (long long)(bytes + 6));
    sh_image img;
    if (bytes <= MAX_FRAME_BYTES && sh_image_create(&img, h->format, h->width, h->height) == SH_OK) {
        sh_status st;
        int frames = 0;
        while ((st = sh_y4m_reader_read(r, &img)) == SH_OK) frames++;
        check(frames <= whole);
        sh_y4m_damage d;
        check(sh_y4m_reader_damage(r, &d) == (st == SH_EFORMAT));
        if (st == SH_EFORMAT)
            check(d.frame == frames && d.offset > 0 && d.lost >= 0 && d.offset + d.lost == (long long)size &&
                  d.frames_lost >= (d.lost > 0));
        sh_image_destroy(&img);
    }
    sh_y4m_reader_close(r);
    fclose(f);
}

/* The header's pixels when its first line parses, else -1. */
static long long header_pixels(const uint8_t *data, size_t size)
{
    const char *nl = memchr(data, '\n', size);
    sh_y4m_header h;
    if (!nl || sh_y4m_header_parse((const char *)data, (size_t)(nl - (const char *)data), &h) != SH_OK) return -1;
    return (long long)h.width * h.height;
}

/* Opened by name with a caller's bound (the input's length: as often over as under it): an
 * accepted stream is within it, a refusal for it (SH_ERANGE) names the file and comes from a
 * header that parsed and is over it. Streams of unknown size take the default bound. */
static void bounded(const uint8_t *data, size_t size)
{
    int fd = memfd_create("fuzz.y4m", 0);
    if (fd < 0) return;
    if (write(fd, data, size) != (ssize_t)size) {
        close(fd);
        return;
    }
    char path[64];
    snprintf(path, sizeof path, "/proc/self/fd/%d", fd);
    long long bound = (long long)size, px = header_pixels(data, size);
    sh_y4m_reader *r = NULL;
    sh_status st = sh_y4m_reader_open_max(path, bound, &r);
    if (st == SH_OK) {
        const sh_y4m_header *h = sh_y4m_reader_header(r);
        check((long long)h->width * h->height <= bound && (long long)h->width * h->height == px);
        sh_y4m_reader_close(r);
    } else {
        check(r == NULL && strstr(sh_error_message(), path) != NULL);
        if (st == SH_ERANGE) check(px > bound);
    }
    close(fd);
}

/* Our tag set over whatever tags a parsed header has: read back as set, the only one of its key
 * (sh_y4m_header_tag finds the first), the header still writable. */
static void stillheart_tag(const sh_y4m_header *parsed)
{
    sh_y4m_header h = *parsed;
    char value[32], line[SH_Y4M_MAX_EXTRA + 256];
    if (sh_y4m_header_set_tag(&h, SH_Y4M_STILLHEART, "method:tps") != SH_OK) {
        check(!memcmp(&h, parsed, sizeof h));
        return;
    }
    check(sh_y4m_header_tag(&h, SH_Y4M_STILLHEART, value, sizeof value) && !strcmp(value, "method:tps"));
    static const char ours[] = SH_Y4M_STILLHEART "=method:tps"; /* the last tag, a whole word */
    size_t n = strlen(h.extra), k = sizeof ours - 1;
    check(n >= k && !strcmp(h.extra + n - k, ours) && (n == k || h.extra[n - k - 1] == ' '));
    FILE *mem = fmemopen(line, sizeof line, "wb");
    sh_y4m_writer *w;
    if (mem && sh_y4m_writer_open_file(mem, "mem", &h, &w) == SH_OK) sh_y4m_writer_close(w);
    if (mem) fclose(mem);
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    as_file(data, size);
    bounded(data, size);
    if (size == 0) return 0; /* fmemopen refuses an empty buffer */
    const char *nl = memchr(data, '\n', size);
    sh_y4m_header parsed;
    if (sh_y4m_header_parse((const char *)data, nl ? (size_t)(nl - (const char *)data) : size, &parsed) == SH_OK)
        stillheart_tag(&parsed);

    FILE *in = fmemopen((void *)data, size, "rb");
    if (!in) return 0;
    sh_y4m_reader *r;
    if (sh_y4m_reader_open_file(in, "fuzz.y4m", &r) != SH_OK) {
        check(sh_error_message()[0] != '\0');
        fclose(in);
        return 0;
    }
    const sh_y4m_header *h = sh_y4m_reader_header(r);
    size_t bytes = sh_image_packed_size(h->format, h->width, h->height);
    check(bytes > 0 && (long long)h->width * h->height <= SH_FRAME_PIXELS_DEFAULT);
    sh_image img, back;
    if (bytes > MAX_FRAME_BYTES || sh_image_create(&img, h->format, h->width, h->height) != SH_OK) {
        sh_y4m_reader_close(r);
        fclose(in);
        return 0;
    }
    check(sh_image_create(&back, h->format, h->width, h->height) == SH_OK);

    char *buf = NULL;
    size_t len = 0;
    FILE *mem = open_memstream(&buf, &len);
    sh_y4m_writer *w;
    check(mem && sh_y4m_writer_open_file(mem, "mem", h, &w) == SH_OK);
    sh_status st;
    int frames = 0;
    while ((st = sh_y4m_reader_read(r, &img)) == SH_OK) {
        check(sh_y4m_writer_write(w, &img) == SH_OK);
        frames++;
    }
    check(st == SH_EEOF || st == SH_EFORMAT);
    check(sh_y4m_reader_frame_index(r) == frames);
    check(sh_y4m_writer_close(w) == SH_OK);
    fclose(mem);

    /* What was written reads back to the same header and frames. */
    FILE *again = fmemopen(buf, len, "rb");
    sh_y4m_reader *r2;
    check(again && sh_y4m_reader_open_file(again, "again", &r2) == SH_OK);
    const sh_y4m_header *h2 = sh_y4m_reader_header(r2);
    check(h2->width == h->width && h2->height == h->height && h2->format == h->format &&
          h2->fps_num == h->fps_num && h2->fps_den == h->fps_den &&
          h2->aspect_num == h->aspect_num && h2->aspect_den == h->aspect_den &&
          h2->interlace == h->interlace && strcmp(h2->extra, h->extra) == 0 &&
          (h->format != SH_PIX_I420 || h2->siting == h->siting));
    FILE *again_src = fmemopen((void *)data, size, "rb");
    sh_y4m_reader *r3;
    check(again_src && sh_y4m_reader_open_file(again_src, "src", &r3) == SH_OK);
    for (int f = 0; f < frames; f++) {
        check(sh_y4m_reader_read(r2, &back) == SH_OK);
        check(sh_y4m_reader_read(r3, &img) == SH_OK);
        check(same_pixels(&img, &back));
    }
    check(sh_y4m_reader_read(r2, &back) == SH_EEOF);
    sh_y4m_reader_close(r3);
    sh_y4m_reader_close(r2);
    fclose(again_src);
    fclose(again);
    free(buf);
    sh_image_destroy(&back);
    sh_image_destroy(&img);
    sh_y4m_reader_close(r);
    fclose(in);
    return 0;
}
