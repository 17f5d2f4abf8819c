/* Recordings: CRC-32 against its published check value, a round trip of streams, frames and
 * sets, a torn tail at every byte of the last record, a damaged record in the middle, every
 * byte flipped in turn, version 1 files, a writer killed mid-stream, the refusals, and replay
 * through the source interface (rec:DIR), damaged too. */
#include <setjmp.h>
#include <signal.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cmocka.h>

#include "stillheart/record.h"
#include "stillheart/source.h"

enum { W = 8, H = 4, NF = 10 };
static char dir[64], file[96];

static void fill(uint8_t *b, size_t n, int k)
{
    for (size_t i = 0; i < n; i++) b[i] = (uint8_t)(k * 17 + i * 3);
}

static void rm_rec(void)
{
    unlink(file);
    rmdir(dir);
}

static int setup(void **state)
{
    (void)state;
    snprintf(dir, sizeof dir, "/tmp/sh-test-rec-%d", (int)getpid());
    snprintf(file, sizeof file, "%s/%s", dir, SH_REC_FILE);
    rm_rec();
    return 0;
}

static int teardown(void **state)
{
    (void)state;
    rm_rec();
    return 0;
}

/* Camera 0: YUYV 8x4, camera 1: GREY 8x4; frame k of camera c at 1 s + k * 40 ms + c ms; a set
 * after each pair. */
static void write_rec(void)
{
    sh_rec_writer *w;
    assert_int_equal(sh_rec_writer_create(dir, &w), SH_OK);
    sh_rec_stream s0 = {0, SH_RAW_YUYV, W, H, 2 * W, 25, 1, "v4l2:/dev/video0"};
    sh_rec_stream s1 = {1, SH_RAW_GREY, W, H, W, 25, 1, "v4l2:/dev/video1"};
    assert_int_equal(sh_rec_writer_stream(w, &s0), SH_OK);
    assert_int_equal(sh_rec_writer_stream(w, &s1), SH_OK);
    uint8_t b[2 * W * H];
    for (int k = 0; k < NF; k++) {
        for (int c = 0; c < 2; c++) {
            size_t n = c ? W * H : 2 * W * H;
            fill(b, n, k + 100 * c);
            sh_raw raw = {c ? SH_RAW_GREY : SH_RAW_YUYV, W, H, c ? W : 2 * W, b, n};
            assert_int_equal(sh_rec_writer_frame(w, c, (uint64_t)k, 1000000000LL + k * 40000000LL + c * 1000000, &raw),
                             SH_OK);
        }
        sh_frame_set set;
        memset(&set, 0, sizeof set);
        set.index = (uint64_t)k;
        set.time_ns = 1000000000LL + k * 40000000LL;
        set.complete = 1;
        set.present = 3;
        set.member[0].sequence = set.member[1].sequence = (uint64_t)k;
        assert_int_equal(sh_rec_writer_set(w, &set), SH_OK);
    }
    assert_int_equal(sh_rec_writer_close(w), SH_OK);
}

/* Reads everything back; returns the number of whole frames, checking each. */
static int read_all(const char *path, int *sets, int *truncated, uint64_t *skipped)
{
    sh_rec_reader *r;
    assert_int_equal(sh_rec_reader_open(path, &r), SH_OK);
    assert_int_equal(sh_rec_reader_streams(r, NULL), 2);
    sh_rec_record rec;
    int frames = 0;
    *sets = 0;
    sh_status st;
    uint8_t b[2 * W * H];
    while ((st = sh_rec_reader_next(r, &rec)) == SH_OK) {
        if (rec.type == SH_REC_FRAME) {
            int k = (int)rec.sequence, c = rec.camera;
            assert_int_equal(rec.timestamp_ns, 1000000000LL + k * 40000000LL + c * 1000000);
            fill(b, rec.raw.bytes, k + 100 * c);
            assert_int_equal(rec.raw.bytes, c ? W * H : 2 * W * H);
            assert_memory_equal(b, rec.raw.data, rec.raw.bytes);
            assert_int_equal(rec.raw.format, c ? SH_RAW_GREY : SH_RAW_YUYV);
            frames++;
        } else if (rec.type == SH_REC_SET) {
            assert_int_equal(rec.set.index, (uint64_t)*sets);
            assert_true(rec.set.complete);
            assert_int_equal(rec.set.count, 2);
            assert_int_equal(rec.set.member[1].sequence, (uint64_t)*sets);
            (*sets)++;
        }
    }
    assert_int_equal(st, SH_EEOF);
    *truncated = sh_rec_reader_truncated(r);
    *skipped = sh_rec_reader_skipped(r);
    sh_rec_reader_close(r);
    return frames;
}

static void test_crc(void **state)
{
    (void)state;
    assert_int_equal(sh_crc32(0, "123456789", 9), 0xcbf43926u);
    assert_int_equal(sh_crc32(sh_crc32(0, "1234", 4), "56789", 5), 0xcbf43926u);
}

static void test_round_trip(void **state)
{
    (void)state;
    rm_rec();
    write_rec();
    int sets, trunc;
    uint64_t skipped;
    assert_int_equal(read_all(dir, &sets, &trunc, &skipped), 2 * NF);
    assert_int_equal(sets, NF);
    assert_false(trunc);
    assert_int_equal(skipped, 0);
    sh_rec_reader *r;
    assert_int_equal(sh_rec_reader_open(file, &r), SH_OK); /* the file itself too */
    const sh_rec_stream *s = sh_rec_reader_stream(r, 0);
    assert_non_null(s);
    assert_string_equal(s->source, "v4l2:/dev/video0");
    assert_int_equal(s->stride, 2 * W);
    assert_null(sh_rec_reader_stream(r, 2));
    sh_rec_reader_close(r);
    /* a second recording into the same folder is refused */
    sh_rec_writer *w;
    assert_int_equal(sh_rec_writer_create(dir, &w), SH_EIO);
    assert_non_null(strstr(sh_error_message(), "already"));
}

static long file_size(void)
{
    struct stat st;
    assert_int_equal(stat(file, &st), 0);
    return (long)st.st_size;
}

/* Cut the file at every byte of its last two records: the rest reads, the tail is reported. */
static void test_torn_tail(void **state)
{
    (void)state;
    rm_rec();
    write_rec();
    long full = file_size();
    long set_rec = 16 + 8 + 8 + 4 + 4 + 8 * SH_SYNC_MAX_CAMERAS, frame_rec = 16 + 24 + W * H;
    FILE *f = fopen(file, "rb");
    char *all = malloc((size_t)full);
    assert_int_equal(fread(all, 1, (size_t)full, f), (size_t)full);
    fclose(f);
    for (long cut = full - set_rec - frame_rec + 1; cut < full; cut++) {
        f = fopen(file, "wb");
        assert_int_equal(fwrite(all, 1, (size_t)cut, f), (size_t)cut);
        fclose(f);
        int sets, trunc;
        uint64_t skipped;
        int frames = read_all(dir, &sets, &trunc, &skipped);
        int last_frame_whole = cut >= full - set_rec;
        assert_int_equal(frames, 2 * NF - 1 + last_frame_whole);
        assert_int_equal(sets, NF - 1);
        assert_int_equal(trunc, cut != full - set_rec); /* a cut between records is a clean end */
    }
    free(all);
}

/* Record sizes in write_rec's file, from the layout in record.h, and where frame k of camera c
 * begins. */
enum { STREAM_REC = 16 + 7 * 4 + 64, FRAME0_REC = 16 + 24 + 2 * W * H, FRAME1_REC = 16 + 24 + W * H,
       SET_REC = 16 + 24 + 8 * SH_SYNC_MAX_CAMERAS };
static long frame_at(int k, int c) { return 16 + 2 * STREAM_REC + k * (FRAME0_REC + FRAME1_REC + SET_REC) + c * FRAME0_REC; }

/* XORs the byte at `at` of the recording with mask. */
static void flip_at(long at, int mask)
{
    FILE *f = fopen(file, "r+b");
    assert_non_null(f);
    fseek(f, at, SEEK_SET);
    int c = fgetc(f);
    fseek(f, at, SEEK_SET);
    fputc(c ^ mask, f);
    fclose(f);
}

/* One flipped byte in frame 3 of camera 0: that frame is skipped and counted, the rest reads. */
static void test_damaged_middle(void **state)
{
    (void)state;
    rm_rec();
    write_rec();
    flip_at(frame_at(3, 0) + 16 + 24 + 5, 0x40);
    int sets, trunc;
    uint64_t skipped;
    assert_int_equal(read_all(dir, &sets, &trunc, &skipped), 2 * NF - 1);
    assert_int_equal(sets, NF);
    assert_false(trunc);
    assert_int_equal(skipped, 1);
    sh_rec_reader *r;
    assert_int_equal(sh_rec_reader_open(dir, &r), SH_OK);
    sh_rec_record rec;
    while (sh_rec_reader_next(r, &rec) == SH_OK) {
    }
    assert_int_equal(sh_rec_reader_lost_bytes(r), FRAME0_REC); /* the damaged record, no more */
    sh_rec_reader_close(r);
}

/* The records of write_rec in file order: kind (0 stream, 1 frame, 2 set), camera, index, and
 * their byte sizes, from the layout in record.h. */
enum { NREC = 2 + 3 * NF };
static void layout(int kind[NREC], int cam[NREC], int idx[NREC], long size[NREC])
{
    for (int c = 0; c < 2; c++) kind[c] = 0, cam[c] = c, idx[c] = 0, size[c] = STREAM_REC;
    for (int k = 0; k < NF; k++)
        for (int j = 0; j < 3; j++) {
            int i = 2 + 3 * k + j;
            kind[i] = j < 2 ? 1 : 2;
            cam[i] = j < 2 ? j : -1;
            idx[i] = k;
            size[i] = j == 2 ? SET_REC : j ? FRAME1_REC : FRAME0_REC;
        }
}

/* Every byte of a small recording flipped in turn (one bit, a different one as the offset goes):
 * the reader never crashes, refuses a damaged file header by name, and otherwise reads every
 * record but the one the flip is in, in order and intact, counting that one record (skipped or
 * a torn tail) and exactly its bytes. A damaged STREAM record costs its camera's frames too
 * (they cannot be read without it): those are counted as skipped. */
static void test_bit_flips(void **state)
{
    (void)state;
    rm_rec();
    write_rec();
    int kind[NREC], cam[NREC], idx[NREC];
    long size[NREC], start[NREC + 1];
    layout(kind, cam, idx, size);
    start[0] = 16;
    for (int i = 0; i < NREC; i++) start[i + 1] = start[i] + size[i];
    long full = file_size();
    assert_int_equal(full, start[NREC]);
    FILE *f = fopen(file, "rb");
    uint8_t *all = malloc((size_t)full);
    assert_int_equal(fread(all, 1, (size_t)full, f), (size_t)full);
    fclose(f);
    uint8_t b[2 * W * H];
    int refused = 0, torn = 0;
    for (long at = 0; at < full; at++) {
        all[at] ^= (uint8_t)(1u << (at % 8));
        f = fopen(file, "wb");
        assert_int_equal(fwrite(all, 1, (size_t)full, f), (size_t)full);
        fclose(f);
        all[at] ^= (uint8_t)(1u << (at % 8));
        sh_rec_reader *r;
        sh_status st = sh_rec_reader_open(dir, &r);
        if (at < 16) {
            assert_int_equal(st, SH_EFORMAT);
            assert_non_null(strstr(sh_error_message(), file));
            refused++;
            continue;
        }
        assert_int_equal(st, SH_OK);
        int hit = 0;
        while (start[hit + 1] <= at) hit++;
        int lost_cam = kind[hit] == 0 ? cam[hit] : -1;
        uint64_t want_skipped = 1, want_lost = (uint64_t)size[hit];
        if (lost_cam >= 0) want_skipped += NF, want_lost += (uint64_t)NF * (uint64_t)size[2 + lost_cam];
        sh_rec_record rec;
        int i = 2; /* the next record expected after the streams */
        assert_int_equal(sh_rec_reader_streams(r, NULL), lost_cam >= 0 ? 1 : 2);
        while ((st = sh_rec_reader_next(r, &rec)) == SH_OK) {
            while (i == hit || (kind[i] == 1 && cam[i] == lost_cam)) i++;
            assert_true(i < NREC);
            if (kind[i] == 1) {
                assert_int_equal(rec.type, SH_REC_FRAME);
                assert_int_equal(rec.camera, cam[i]);
                assert_int_equal(rec.sequence, (uint64_t)idx[i]);
                fill(b, rec.raw.bytes, idx[i] + 100 * cam[i]);
                assert_int_equal((long)rec.raw.bytes, size[i] - 40);
                assert_memory_equal(b, rec.raw.data, rec.raw.bytes);
            } else {
                assert_int_equal(rec.type, SH_REC_SET);
                assert_int_equal(rec.set.index, (uint64_t)idx[i]);
            }
            i++;
        }
        assert_int_equal(st, SH_EEOF);
        while (i < NREC && (i == hit || (kind[i] == 1 && cam[i] == lost_cam))) i++;
        assert_int_equal(i, NREC); /* nothing else lost */
        uint64_t sk = sh_rec_reader_skipped(r);
        int tr = sh_rec_reader_truncated(r);
        torn += tr;
        assert_int_equal(sk + (uint64_t)tr, want_skipped);
        assert_int_equal(sh_rec_reader_lost_bytes(r), want_lost);
        sh_rec_reader_close(r);
    }
    print_message("%ld bytes flipped in turn: %d in the file header refused by name, %ld in records each cost that "
                  "record alone (%d of them read as a torn tail)\n", full, refused, full - 16, torn);
    free(all);
}

/* Version 1 (the CRC of the payload alone) still reads; a version this reader does not know is
 * refused by its number. */
static void test_versions(void **state)
{
    (void)state;
    rm_rec();
    write_rec();
    long full = file_size();
    FILE *f = fopen(file, "rb");
    uint8_t *all = malloc((size_t)full);
    assert_int_equal(fread(all, 1, (size_t)full, f), (size_t)full);
    fclose(f);
    assert_int_equal(all[8], 2);
    all[8] = 1;
    for (long at = 16; at < full;) { /* rewrite every record's CRC as version 1 had it */
        uint32_t len = (uint32_t)all[at + 8] | (uint32_t)all[at + 9] << 8 | (uint32_t)all[at + 10] << 16 |
                       (uint32_t)all[at + 11] << 24;
        uint32_t crc = sh_crc32(0, all + at + 16, len);
        for (int k = 0; k < 4; k++) all[at + 12 + k] = (uint8_t)(crc >> (8 * k));
        at += 16 + (long)len;
    }
    f = fopen(file, "wb");
    assert_int_equal(fwrite(all, 1, (size_t)full, f), (size_t)full);
    fclose(f);
    int sets, trunc;
    uint64_t skipped;
    assert_int_equal(read_all(dir, &sets, &trunc, &skipped), 2 * NF);
    assert_int_equal(sets, NF);
    assert_int_equal(skipped, 0);
    all[8] = 3;
    f = fopen(file, "wb");
    assert_int_equal(fwrite(all, 1, (size_t)full, f), (size_t)full);
    fclose(f);
    sh_rec_reader *r;
    assert_int_equal(sh_rec_reader_open(dir, &r), SH_EFORMAT);
    assert_non_null(strstr(sh_error_message(), "recording version 3, this reader knows 1 to 2"));
    assert_non_null(strstr(sh_error_message(), file));
    free(all);
}

/* A replay meets damage: it goes on past it (camera 1's frame 3 skipped), counts it once and
 * describes it; without loop the end is an error saying how much was lost, with loop every
 * good frame comes round again. */
static void test_replay_damage(void **state)
{
    (void)state;
    rm_rec();
    write_rec();
    flip_at(frame_at(3, 1) + 30, 0x01);
    char spec[96], want[200];
    snprintf(spec, sizeof spec, "rec:%s", dir);
    snprintf(want, sizeof want, "rec:%s: damaged recording: 1 record(s) skipped, %d bytes lost so far", dir, FRAME1_REC);
    for (int loop = 0; loop < 2; loop++) {
        sh_source_options o;
        sh_source_options_default(&o);
        o.camera = 1;
        o.realtime = 0;
        o.loop = loop;
        sh_source *s;
        assert_int_equal(sh_source_open(spec, &o, &s), SH_OK);
        assert_int_equal(sh_source_start(s), SH_OK);
        uint8_t b[W * H];
        int n = 0;
        sh_status st = SH_OK;
        for (; n < 2 * (NF - 1); n++) {
            sh_source_frame fr;
            int got;
            if ((st = sh_source_dequeue(s, 0, &fr, &got)) != SH_OK) break;
            int k = n % (NF - 1);
            fill(b, W * H, (k < 3 ? k : k + 1) + 100); /* frame 3 is the damaged one */
            assert_memory_equal(b, fr.raw.data, W * H);
            assert_int_equal(sh_source_release(s, &fr), SH_OK);
        }
        sh_source_stats ss;
        sh_source_get_stats(s, &ss);
        assert_int_equal(ss.damaged, 1);
        assert_int_equal(ss.lost_bytes, (uint64_t)FRAME1_REC);
        assert_non_null(strstr(sh_source_damage(s), want));
        if (loop) {
            assert_int_equal(n, 2 * (NF - 1));
        } else {
            assert_int_equal(n, NF - 1);
            assert_int_equal(st, SH_EFORMAT);
            assert_non_null(strstr(sh_error_message(), want));
        }
        sh_source_close(s);
    }
}

/* A writer killed mid-stream: every frame it finished reads back. */
static void test_killed_writer(void **state)
{
    (void)state;
    rm_rec();
    pid_t pid = fork();
    assert_true(pid >= 0);
    if (pid == 0) {
        sh_rec_writer *w;
        if (sh_rec_writer_create(dir, &w) != SH_OK) _exit(1);
        sh_rec_stream s0 = {0, SH_RAW_GREY, 640, 480, 640, 25, 1, "test"};
        sh_rec_writer_stream(w, &s0);
        static uint8_t b[640 * 480];
        sh_raw raw = {SH_RAW_GREY, 640, 480, 640, b, sizeof b};
        for (uint64_t k = 0;; k++) {
            memset(b, (int)(k & 0xff), sizeof b);
            sh_rec_writer_frame(w, 0, k, (int64_t)k, &raw);
        }
    }
    /* let it write a few frames (slow machines and emulators included), then kill it */
    struct stat stt;
    for (int i = 0; i < 500; i++) {
        if (stat(file, &stt) == 0 && stt.st_size > 3 * 640 * 480) break;
        usleep(10000);
    }
    usleep(20000);
    kill(pid, SIGKILL);
    int status;
    waitpid(pid, &status, 0);
    sh_rec_reader *r;
    assert_int_equal(sh_rec_reader_open(dir, &r), SH_OK);
    sh_rec_record rec;
    uint64_t n = 0;
    while (sh_rec_reader_next(r, &rec) == SH_OK) {
        assert_int_equal(rec.sequence, n);
        assert_int_equal(rec.raw.bytes, 640 * 480);
        assert_int_equal(rec.raw.data[640 * 480 - 1], (uint8_t)(n & 0xff));
        n++;
    }
    assert_true(n > 0);
    assert_int_equal(sh_rec_reader_skipped(r), 0);
    sh_rec_reader_close(r);
}

static void test_refusals(void **state)
{
    (void)state;
    sh_rec_reader *r;
    assert_int_equal(sh_rec_reader_open("/nonexistent/rec", &r), SH_EIO);
    assert_non_null(strstr(sh_error_message(), "/nonexistent/rec"));
    FILE *f = fmemopen((void *)"YUV4MPEG2 W8 H4\n", 16, "rb");
    assert_int_equal(sh_rec_reader_open_file(f, "x.y4m", &r), SH_EFORMAT);
    assert_non_null(strstr(sh_error_message(), "x.y4m"));
    fclose(f);
    /* a pipe: resync seeks, so it is refused by name */
    int fds[2];
    assert_int_equal(pipe(fds), 0);
    assert_int_equal(write(fds[1], "SHREC\r\n\x1a\x02\0\0\0\x10\0\0\0", 16), 16);
    close(fds[1]);
    f = fdopen(fds[0], "rb");
    assert_int_equal(sh_rec_reader_open_file(f, "pipe.shrec", &r), SH_EINVAL);
    assert_non_null(strstr(sh_error_message(), "pipe.shrec: a recording is read from a file that can seek"));
    fclose(f);
    sh_rec_writer *w;
    rm_rec();
    assert_int_equal(sh_rec_writer_create(dir, &w), SH_OK);
    uint8_t b[4] = {0};
    sh_raw raw = {SH_RAW_GREY, 2, 2, 2, b, 4};
    assert_int_equal(sh_rec_writer_frame(w, 0, 0, 0, &raw), SH_EINVAL); /* no stream yet */
    assert_int_equal(sh_rec_writer_close(w), SH_OK);
}

/* rec: replay, as fast as asked: camera 1's frames with the recorded spacing. */
static void test_replay(void **state)
{
    (void)state;
    rm_rec();
    write_rec();
    char spec[96];
    snprintf(spec, sizeof spec, "rec:%s", dir);
    sh_source_options o;
    sh_source_options_default(&o);
    o.camera = 1;
    o.realtime = 0;
    o.loop = 1;
    sh_source *s;
    assert_int_equal(sh_source_open(spec, &o, &s), SH_OK);
    sh_rawfmt fmt;
    int w, h;
    assert_int_equal(sh_source_format(s, &fmt, &w, &h, NULL, NULL), SH_OK);
    assert_int_equal(fmt, SH_RAW_GREY);
    assert_int_equal(sh_source_start(s), SH_OK);
    int64_t t0 = 0;
    uint8_t b[W * H];
    for (int i = 0; i < NF + 3; i++) {
        sh_source_frame f;
        int got;
        assert_int_equal(sh_source_dequeue(s, 0, &f, &got), SH_OK);
        assert_int_equal(got, 1);
        if (!i) t0 = f.timestamp_ns;
        /* 40 ms apart, and the loop goes on 40 ms after the last one */
        assert_int_equal(f.timestamp_ns - t0, (int64_t)i * 40000000);
        assert_int_equal(f.camera, 1);
        fill(b, W * H, i % NF + 100);
        assert_memory_equal(b, f.raw.data, W * H);
        assert_int_equal(sh_source_release(s, &f), SH_OK);
    }
    sh_source_close(s);
    o.camera = 5;
    assert_int_equal(sh_source_open(spec, &o, &s), SH_EINVAL);
    assert_non_null(strstr(sh_error_message(), "camera 5"));
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_crc),           cmocka_unit_test(test_round_trip),
        cmocka_unit_test(test_torn_tail),     cmocka_unit_test(test_damaged_middle),
        cmocka_unit_test(test_killed_writer), cmocka_unit_test(test_refusals),
        cmocka_unit_test(test_replay),        cmocka_unit_test(test_bit_flips),
        cmocka_unit_test(test_versions),      cmocka_unit_test(test_replay_damage),
    };
    return cmocka_run_group_tests(tests, setup, teardown);
}
