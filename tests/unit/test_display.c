/* The shared-memory display buffer: round trip, no torn frame under a racing reader, a stalled
 * or late reader, closing, and hostile segments. */
#include <libgen.h>
#include <pthread.h>
#include <time.h>
#include <setjmp.h>
#include <signal.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <fcntl.h>
#include <sys/mman.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cmocka.h>

#include "stillheart/display.h"
#include "stillheart/y4m.h"

enum { W = 320, H = 240 };

static char name[64];

/* Frame n: every byte a function of n and its position, so any mix of two frames shows. */
static void paint(sh_image *img, uint32_t n)
{
    for (int p = 0; p < img->num_planes; p++)
        for (int y = 0; y < img->plane[p].height; y++)
            for (int x = 0; x < img->plane[p].width; x++)
                img->plane[p].data[(size_t)y * img->plane[p].stride + x] =
                    (uint8_t)(n * 31u + (uint32_t)(x * 7 + y * 13 + p * 101));
}

static int painted_as(const sh_image *img, uint32_t n)
{
    for (int p = 0; p < img->num_planes; p++)
        for (int y = 0; y < img->plane[p].height; y++)
            for (int x = 0; x < img->plane[p].width; x++)
                if (img->plane[p].data[(size_t)y * img->plane[p].stride + x] !=
                    (uint8_t)(n * 31u + (uint32_t)(x * 7 + y * 13 + p * 101)))
                    return 0;
    return 1;
}

static int setup(void **state)
{
    (void)state;
    snprintf(name, sizeof name, "/stillheart-test-%d", (int)getpid());
    return 0;
}

static void test_round_trip(void **state)
{
    (void)state;
    sh_display_writer *w;
    assert_int_equal(sh_display_writer_create(name, SH_PIX_I420, W, H, 3, 1, NULL, &w), SH_OK);
    sh_image img, got;
    assert_int_equal(sh_image_create(&img, SH_PIX_I420, W, H), SH_OK);
    assert_int_equal(sh_image_create(&got, SH_PIX_I420, W, H), SH_OK);
    paint(&img, 7);
    sh_display_frame_info info = {.capture_ns = 12345, .status = SH_DISPLAY_DEGRADED,
                                  .markers_used = 11, .residual_px = 0.25f};
    strcpy(info.reason, "marker 4 hidden");
    assert_int_equal(sh_display_writer_publish(w, &img, &info), SH_OK);
    sh_display_reader *r;
    assert_int_equal(sh_display_reader_open(name, &r), SH_OK);
    const sh_display_header *h = sh_display_reader_header(r);
    assert_int_equal(h->width, W);
    assert_int_equal(h->format, SH_PIX_I420);
    assert_int_equal(h->full_range, 1);
    sh_display_frame_info back;
    assert_int_equal(sh_display_reader_next(r, &got, &back, 100), SH_OK);
    assert_true(painted_as(&got, 7));
    assert_int_equal(back.sequence, 1);
    assert_int_equal(back.capture_ns, 12345);
    assert_int_equal(back.status, SH_DISPLAY_DEGRADED);
    assert_int_equal(back.markers_used, 11);
    assert_string_equal(back.reason, "marker 4 hidden");
    assert_true(back.publish_ns > 0);
    /* nothing newer yet: a timeout, not the same frame again */
    assert_int_equal(sh_display_reader_next(r, &got, &back, 20), SH_EIO);
    sh_display_writer_destroy(w, 0);
    assert_int_equal(sh_display_reader_next(r, &got, &back, 100), SH_EEOF);
    sh_display_reader_close(r);
    shm_unlink(name);
    sh_image_destroy(&img);
    sh_image_destroy(&got);
}

typedef struct {
    sh_display_writer *w;
    int frames;
} writer_job;

static void *writer_main(void *arg)
{
    writer_job *job = arg;
    sh_image img;
    sh_image_create(&img, SH_PIX_GRAY8, W, H);
    for (int n = 1; n <= job->frames; n++) {
        paint(&img, (uint32_t)n);
        sh_display_frame_info info = {.capture_ns = n};
        sh_display_writer_publish(job->w, &img, &info);
    }
    sh_image_destroy(&img);
    return NULL;
}

/* 10,000 frames written as fast as possible while a reader takes frames as fast as it can:
 * every frame it returns is whole (its pixels are all of one frame, the one its info names). */
static void test_racing_reader_sees_no_torn_frame(void **state)
{
    (void)state;
    sh_display_writer *w;
    assert_int_equal(sh_display_writer_create(name, SH_PIX_GRAY8, W, H, 3, 0, NULL, &w), SH_OK);
    sh_display_reader *r;
    assert_int_equal(sh_display_reader_open(name, &r), SH_OK);
    writer_job job = {w, 10000};
    pthread_t t;
    assert_int_equal(pthread_create(&t, NULL, writer_main, &job), 0);
    sh_image got;
    assert_int_equal(sh_image_create(&got, SH_PIX_GRAY8, W, H), SH_OK);
    int reads = 0;
    uint64_t last = 0;
    sh_display_frame_info info;
    int64_t polls = 0;
    for (; last < 10000 && polls < 100000000; polls++) {
        /* timeout 0: spin, so reads overlap the writer's copies as often as they can */
        sh_status st = sh_display_reader_next(r, &got, &info, 0);
        if (st == SH_EIO) continue;
        assert_int_equal(st, SH_OK);
        if (!painted_as(&got, (uint32_t)info.sequence)) fail_msg("frame %llu torn", (unsigned long long)info.sequence);
        assert_int_equal(info.capture_ns, (int64_t)info.sequence);
        assert_true(info.sequence > last);
        last = info.sequence;
        reads++;
    }
    pthread_join(t, NULL);
    printf("  %d whole frames read while 10000 were written (%lld polls)\n", reads, (long long)polls);
    assert_true(reads > 1);
    assert_int_equal(last, 10000);
    sh_display_reader_close(r);
    sh_display_writer_destroy(w, 1);
    sh_image_destroy(&got);
}

/* A reader process stopped in the middle of its work holds nothing: the writer publishes all
 * its frames, and a reader started afterwards gets the newest one. */
static void test_stalled_and_late_readers(void **state)
{
    (void)state;
    sh_display_writer *w;
    assert_int_equal(sh_display_writer_create(name, SH_PIX_GRAY8, W, H, 4, 0, NULL, &w), SH_OK);
    pid_t child = fork();
    assert_true(child >= 0);
    if (child == 0) { /* a reader that reads forever until it is stopped and killed */
        sh_display_reader *r;
        sh_image img;
        if (sh_display_reader_open(name, &r) != SH_OK) _exit(1);
        sh_image_create(&img, SH_PIX_GRAY8, W, H);
        for (;;) sh_display_reader_next(r, &img, NULL, 100);
    }
    writer_job job = {w, 200};
    writer_main(&job);
    kill(child, SIGSTOP); /* stalled wherever it was, possibly mid-copy */
    job.frames = 2000;
    writer_main(&job);    /* would hang here if the writer ever waited for a reader */
    kill(child, SIGKILL);
    waitpid(child, NULL, 0);

    sh_display_reader *late;
    assert_int_equal(sh_display_reader_open(name, &late), SH_OK);
    sh_image got;
    assert_int_equal(sh_image_create(&got, SH_PIX_GRAY8, W, H), SH_OK);
    sh_display_frame_info info;
    assert_int_equal(sh_display_reader_next(late, &got, &info, 100), SH_OK);
    assert_int_equal(info.sequence, 2200); /* the newest, not the oldest */
    assert_true(painted_as(&got, 2000));   /* painted with the second run's last number */
    sh_display_reader_close(late);
    sh_display_writer_destroy(w, 1);
    sh_image_destroy(&got);
}

static void test_hostile_segments(void **state)
{
    (void)state;
    sh_display_writer *w;
    assert_int_equal(sh_display_writer_create(name, SH_PIX_RGB24, 32, 16, 3, 0, NULL, &w), SH_OK);
    sh_image img;
    assert_int_equal(sh_image_create(&img, SH_PIX_RGB24, 32, 16), SH_OK);
    assert_int_equal(sh_display_writer_publish(w, &img, NULL), SH_OK);
    sh_display_reader *r;
    assert_int_equal(sh_display_reader_open(name, &r), SH_OK);
    const sh_display_header *h = sh_display_reader_header(r);
    size_t size = sizeof *h + (size_t)h->slot_bytes * h->slot_count;
    uint8_t *copy = malloc(size);
    sh_display_reader_close(r);
    FILE *f = NULL;
    (void)f;
    /* a private copy of the segment to damage */
    sh_display_reader *rr;
    {
        int fd = shm_open(name, O_RDONLY, 0);
        assert_true(fd >= 0);
        assert_int_equal(read(fd, copy, size), (ssize_t)size);
        close(fd);
    }
    assert_int_equal(sh_display_reader_attach(copy, size, &rr), SH_OK);
    sh_display_reader_close(rr);
    sh_display_header *hh = (sh_display_header *)copy;
    const struct { size_t offset; uint32_t value; } damage[] = {
        {offsetof(sh_display_header, version), 99},
        {offsetof(sh_display_header, width), 33},
        {offsetof(sh_display_header, format), 77},
        {offsetof(sh_display_header, slot_count), 2},
        {offsetof(sh_display_header, slot_count), 4}, /* more slots than the size holds */
        {offsetof(sh_display_header, stride), 1},
        {offsetof(sh_display_header, frame_bytes), 1u << 31},
    };
    for (size_t k = 0; k < sizeof damage / sizeof damage[0]; k++) {
        uint32_t saved;
        memcpy(&saved, copy + damage[k].offset, 4);
        memcpy(copy + damage[k].offset, &damage[k].value, 4);
        assert_int_equal(sh_display_reader_attach(copy, size, &rr), SH_EFORMAT);
        memcpy(copy + damage[k].offset, &saved, 4);
    }
    assert_int_equal(sh_display_reader_attach(copy, size - 1, &rr), SH_EFORMAT);
    /* a slot index past the end in `latest` is ignored, not followed */
    assert_int_equal(sh_display_reader_attach(copy, size, &rr), SH_OK);
    hh->latest = (5ull << 8) | 200;
    hh->closed = 1;
    assert_int_equal(sh_display_reader_next(rr, &img, NULL, 10), SH_EIO);
    sh_display_reader_close(rr);
    free(copy);
    sh_display_writer_destroy(w, 1);
    sh_image_destroy(&img);
}

static char cat_binary[4096];

/* stillheart-cat turns what the writer publishes into a Y4M stream, frame for frame. */
static void test_cat_writes_y4m(void **state)
{
    (void)state;
    sh_display_writer *w;
    assert_int_equal(sh_display_writer_create(name, SH_PIX_I420, W, H, 3, 0, NULL, &w), SH_OK);
    sh_image img;
    assert_int_equal(sh_image_create(&img, SH_PIX_I420, W, H), SH_OK);
    paint(&img, 1);
    assert_int_equal(sh_display_writer_publish(w, &img, NULL), SH_OK);
    char out[] = "/tmp/stillheart-cat-XXXXXX";
    int fd = mkstemp(out);
    assert_true(fd >= 0);
    pid_t child = fork();
    if (child == 0) {
        dup2(fd, 1);
        execl(cat_binary, cat_binary, "--name", name, "--count", "3", "--timeout", "5", (char *)NULL);
        _exit(127);
    }
    close(fd);
    for (uint32_t n = 2; n <= 6; n++) { /* published slowly enough for a 0.5 ms poll */
        struct timespec pause = {0, 100 * 1000000};
        nanosleep(&pause, NULL);
        paint(&img, n);
        assert_int_equal(sh_display_writer_publish(w, &img, NULL), SH_OK);
    }
    int status;
    waitpid(child, &status, 0);
    assert_true(WIFEXITED(status) && WEXITSTATUS(status) == 0);
    sh_y4m_reader *r;
    assert_int_equal(sh_y4m_reader_open(out, &r), SH_OK);
    assert_int_equal(sh_y4m_reader_header(r)->format, SH_PIX_I420);
    sh_image got;
    assert_int_equal(sh_image_create(&got, SH_PIX_I420, W, H), SH_OK);
    uint32_t previous = 0;
    int frames = 0;
    while (sh_y4m_reader_read(r, &got) == SH_OK) {
        uint32_t n = 0;
        for (uint32_t k = 1; k <= 6 && !n; k++)
            if (painted_as(&got, k)) n = k;
        assert_true(n > previous); /* whole frames, in order, none twice */
        previous = n;
        frames++;
    }
    assert_int_equal(frames, 3);
    sh_y4m_reader_close(r);
    unlink(out);
    sh_display_writer_destroy(w, 1);
    sh_image_destroy(&img);
    sh_image_destroy(&got);
}

static void test_bad_arguments(void **state)
{
    (void)state;
    sh_display_writer *w;
    assert_int_equal(sh_display_writer_create("no-slash", SH_PIX_GRAY8, W, H, 3, 0, NULL, &w), SH_EINVAL);
    assert_int_equal(sh_display_writer_create(name, SH_PIX_GRAY8, W, H, 2, 0, NULL, &w), SH_EINVAL);
    assert_int_equal(sh_display_writer_create(name, SH_PIX_GRAY8, W, H, 3, 0, "no-such-group-xyz", &w), SH_EIO);
    shm_unlink(name);
    sh_display_reader *r;
    assert_int_equal(sh_display_reader_open("/stillheart-none-such", &r), SH_EIO);
}

int main(int argc, char **argv)
{
    (void)argc;
    /* build/tests/test_display -> build/stillheart-cat */
    char self[4096];
    snprintf(self, sizeof self, "%s", argv[0]);
    snprintf(cat_binary, sizeof cat_binary, "%s/../stillheart-cat", dirname(self));
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_round_trip),
        cmocka_unit_test(test_racing_reader_sees_no_torn_frame),
        cmocka_unit_test(test_stalled_and_late_readers),
        cmocka_unit_test(test_hostile_segments),
        cmocka_unit_test(test_cat_writes_y4m),
        cmocka_unit_test(test_bad_arguments),
    };
    return cmocka_run_group_tests(tests, setup, NULL);
}
