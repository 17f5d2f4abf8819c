/* sh_display_reader_view: a frame drawn where it lies in the segment. What the viewer did stands
 * only for a whole frame: never for one the writer came into meanwhile (a racing writer, and a
 * lap forced in the middle of the viewer), a segment cut short under the viewer abandons it
 * without a crash and the reader follows the writer's new segment, and a viewer's own failure
 * leaves the frame to be taken again. The truth is the frame each sequence number was painted
 * as, by the test. */
#include <fcntl.h>
#include <pthread.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>
#include <sys/mman.h>
#include <unistd.h>

#include <cmocka.h>

#include "stillheart/display.h"
#include "display_paint.h"

enum { W = 160, H = 120 };

static char name[64];

static int setup(void **state)
{
    (void)state;
    snprintf(name, sizeof name, "/stillheart-view-%d", (int)getpid());
    return 0;
}

/* The viewer of most tests: the view copied row by row into `out` (its own strides), and the
 * sequence its info named. */
typedef struct {
    sh_image out;
    uint64_t sequence;
    int calls;
    void (*during)(void *); /* called in the middle of the copy (a lap, a truncation) */
    void *during_arg;
    int finished;           /* calls that got to the end */
    sh_status fail;         /* returned instead of SH_OK when set */
} copier;

static sh_status copy_view(void *ctx, const sh_image *view, const sh_display_frame_info *info)
{
    copier *c = ctx;
    c->calls++;
    c->sequence = info->sequence;
    for (int p = 0; p < view->num_planes; p++) {
        if (p == 1 && c->during) c->during(c->during_arg);
        for (int y = 0; y < view->plane[p].height; y++)
            memcpy(c->out.plane[p].data + (size_t)y * c->out.plane[p].stride,
                   view->plane[p].data + (size_t)y * view->plane[p].stride, (size_t)view->plane[p].width);
    }
    c->finished++;
    if (c->fail != SH_OK) return sh_error_set(c->fail, "viewer: told to fail");
    return SH_OK;
}

static void publish(sh_display_writer *w, sh_image *img, uint32_t n)
{
    paint(img, n);
    assert_int_equal(sh_display_writer_publish(w, img, &(sh_display_frame_info){.capture_ns = n}), SH_OK);
}

/* Frames in I420 (three planes at the segment's padded strides): each view holds the frame its
 * info names, and after it the next is waited for (the writer's wake) or the call times out. */
static void test_view_round_trip(void **state)
{
    (void)state;
    enum { VW = 158, VH = 118 }; /* rows padded in the segment: strides differ from widths */
    sh_display_writer *w;
    assert_int_equal(sh_display_writer_create(name, SH_PIX_I420, VW, VH, 3, 0, NULL, &w), SH_OK);
    sh_image img;
    assert_int_equal(sh_image_create(&img, SH_PIX_I420, VW, VH), SH_OK);
    copier c = {0};
    assert_int_equal(sh_image_create(&c.out, SH_PIX_I420, VW, VH), SH_OK);
    sh_display_reader *r;
    publish(w, &img, 1);
    assert_int_equal(sh_display_reader_open(name, NULL, 0, &r), SH_OK);
    sh_display_frame_info info;
    assert_int_equal(sh_display_reader_view(r, copy_view, &c, &info, 100), SH_OK);
    assert_int_equal(info.sequence, 1);
    assert_int_equal(info.capture_ns, 1);
    assert_true(painted_as(&c.out, 1));
    /* nothing newer: a timeout, the viewer not called */
    int calls = c.calls;
    assert_int_equal(sh_display_reader_view(r, copy_view, &c, &info, 20), SH_EIO);
    assert_int_equal(c.calls, calls);
    for (uint32_t n = 2; n <= 5; n++) {
        publish(w, &img, n);
        assert_int_equal(sh_display_reader_view(r, copy_view, &c, &info, 100), SH_OK);
        assert_int_equal(info.sequence, n);
        assert_true(painted_as(&c.out, n));
    }
    assert_int_equal(sh_display_reader_view(r, NULL, &c, &info, 0), SH_EINVAL);
    sh_display_reader_close(r);
    sh_display_writer_destroy(w, 1);
    sh_image_destroy(&img);
    sh_image_destroy(&c.out);
}

/* A writer thread publishing as fast as it can against a viewer as fast as it can: every frame
 * the viewer is left with is whole, and laps (viewer calls whose work was thrown away) are
 * counted. */
static void test_racing_viewer_keeps_no_torn_frame(void **state)
{
    (void)state;
    sh_display_writer *w;
    assert_int_equal(sh_display_writer_create(name, SH_PIX_GRAY8, W, H, 3, 0, NULL, &w), SH_OK);
    sh_display_reader *r;
    assert_int_equal(sh_display_reader_open(name, NULL, 0, &r), SH_OK);
    copier c = {0};
    assert_int_equal(sh_image_create(&c.out, SH_PIX_GRAY8, W, H), SH_OK);
    writer_job job = {w, 5000, W, H};
    pthread_t t;
    assert_int_equal(pthread_create(&t, NULL, writer_main, &job), 0);
    int reads = 0;
    uint64_t last = 0;
    sh_display_frame_info info;
    for (long polls = 0; last < 5000 && polls < 100000000; polls++) {
        sh_status st = sh_display_reader_view(r, copy_view, &c, &info, 0);
        if (st == SH_EIO) continue;
        assert_int_equal(st, SH_OK);
        if (!painted_as(&c.out, (uint32_t)info.sequence)) fail_msg("frame %llu torn", (unsigned long long)info.sequence);
        assert_int_equal(c.sequence, info.sequence);
        assert_true(info.sequence > last);
        last = info.sequence;
        reads++;
    }
    pthread_join(t, NULL);
    printf("  %d whole frames viewed while 5000 were written (%d viewer calls, %d thrown away)\n", reads, c.calls,
           c.calls - reads);
    assert_int_equal(last, 5000);
    sh_display_reader_close(r);
    sh_display_writer_destroy(w, 1);
    sh_image_destroy(&c.out);
}

/* A lap forced in the middle of the viewer: while it copies, three newer frames go into the
 * three slots (one of them the slot it is reading). Its work on that frame is thrown away and it
 * is called again, on the newest; it is left with frame 4, whole. */
typedef struct {
    sh_display_writer *w;
    sh_image *img;
    uint32_t next;
    int laps_left;
} lapper;

static void lap(void *arg)
{
    lapper *l = arg;
    if (l->laps_left-- <= 0) return;
    for (int k = 0; k < 3; k++) {
        paint(l->img, l->next);
        sh_display_frame_info info = {.capture_ns = l->next++};
        /* from another thread would be the real case; here the publish runs inside the viewer, which
         * display.h forbids for applications only because its guard would end the reader's: no
         * fault is provoked before the viewer returns */
        assert_int_equal(sh_display_writer_publish(l->w, l->img, &info), SH_OK);
    }
}

static void test_lapped_viewer_is_called_again(void **state)
{
    (void)state;
    sh_display_writer *w;
    assert_int_equal(sh_display_writer_create(name, SH_PIX_I420, W, H, 3, 0, NULL, &w), SH_OK);
    sh_image img, pub;
    assert_int_equal(sh_image_create(&img, SH_PIX_I420, W, H), SH_OK);
    assert_int_equal(sh_image_create(&pub, SH_PIX_I420, W, H), SH_OK);
    publish(w, &img, 1);
    sh_display_reader *r;
    assert_int_equal(sh_display_reader_open(name, NULL, 0, &r), SH_OK);
    lapper l = {w, &pub, 2, 1};
    copier c = {.during = lap, .during_arg = &l};
    assert_int_equal(sh_image_create(&c.out, SH_PIX_I420, W, H), SH_OK);
    sh_display_frame_info info;
    assert_int_equal(sh_display_reader_view(r, copy_view, &c, &info, 100), SH_OK);
    assert_int_equal(c.calls, 2);
    assert_int_equal(info.sequence, 4);
    assert_int_equal(info.capture_ns, 4);
    assert_true(painted_as(&c.out, 4));
    sh_display_reader_close(r);
    sh_display_writer_destroy(w, 1);
    sh_image_destroy(&img);
    sh_image_destroy(&pub);
    sh_image_destroy(&c.out);
}

/* The segment cut short while the viewer reads it: the viewer is abandoned at the fault (it
 * never finishes), no crash, no frame; the writer's next publish makes a new segment and the
 * viewer gets that frame, of the new generation. */
static void truncate_segment(void *arg)
{
    int *once = arg;
    if (!*once) return;
    *once = 0;
    int fd = shm_open(name, O_RDWR, 0);
    assert_true(fd >= 0);
    assert_int_equal(ftruncate(fd, 4096), 0);
    close(fd);
}

static void test_viewer_abandoned_when_cut_short(void **state)
{
    (void)state;
    sh_display_writer *w;
    assert_int_equal(sh_display_writer_create(name, SH_PIX_I420, W, H, 3, 0, NULL, &w), SH_OK);
    uint64_t first = sh_display_writer_generation(w);
    sh_image img;
    assert_int_equal(sh_image_create(&img, SH_PIX_I420, W, H), SH_OK);
    publish(w, &img, 1);
    sh_display_reader *r;
    assert_int_equal(sh_display_reader_open(name, NULL, 0, &r), SH_OK);
    int once = 1;
    copier c = {.during = truncate_segment, .during_arg = &once};
    assert_int_equal(sh_image_create(&c.out, SH_PIX_I420, W, H), SH_OK);
    sh_display_frame_info info;
    assert_int_equal(sh_display_reader_view(r, copy_view, &c, &info, 50), SH_EIO);
    assert_int_equal(c.calls, 1);
    assert_int_equal(c.finished, 0);
    publish(w, &img, 2);
    assert_int_equal(sh_display_writer_remade(w), 1);
    assert_int_equal(sh_display_reader_view(r, copy_view, &c, &info, 1000), SH_OK);
    assert_int_equal(info.capture_ns, 2);
    assert_true(painted_as(&c.out, 2));
    assert_int_equal(c.finished, 1);
    assert_true(sh_display_reader_header(r)->generation != first);
    assert_int_equal(sh_display_reader_header(r)->generation, sh_display_writer_generation(w));
    sh_display_reader_close(r);
    sh_display_writer_destroy(w, 1);
    sh_image_destroy(&img);
    sh_image_destroy(&c.out);
}

/* The viewer's own failure is returned with its message and the frame is not taken: the next
 * call hands the same frame again. */
static void test_viewer_failure_leaves_the_frame(void **state)
{
    (void)state;
    sh_display_writer *w;
    assert_int_equal(sh_display_writer_create(name, SH_PIX_GRAY8, W, H, 3, 0, NULL, &w), SH_OK);
    sh_image img;
    assert_int_equal(sh_image_create(&img, SH_PIX_GRAY8, W, H), SH_OK);
    publish(w, &img, 1);
    sh_display_reader *r;
    assert_int_equal(sh_display_reader_open(name, NULL, 0, &r), SH_OK);
    copier c = {.fail = SH_ENOMEM};
    assert_int_equal(sh_image_create(&c.out, SH_PIX_GRAY8, W, H), SH_OK);
    sh_display_frame_info info = {.sequence = 99};
    assert_int_equal(sh_display_reader_view(r, copy_view, &c, &info, 100), SH_ENOMEM);
    assert_string_equal(sh_error_message(), "viewer: told to fail");
    assert_int_equal(info.sequence, 99); /* untouched */
    c.fail = SH_OK;
    assert_int_equal(sh_display_reader_view(r, copy_view, &c, &info, 100), SH_OK);
    assert_int_equal(info.sequence, 1);
    assert_true(painted_as(&c.out, 1));
    sh_display_reader_close(r);
    sh_display_writer_destroy(w, 1);
    sh_image_destroy(&img);
    sh_image_destroy(&c.out);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test_setup(test_view_round_trip, setup),
        cmocka_unit_test_setup(test_racing_viewer_keeps_no_torn_frame, setup),
        cmocka_unit_test_setup(test_lapped_viewer_is_called_again, setup),
        cmocka_unit_test_setup(test_viewer_abandoned_when_cut_short, setup),
        cmocka_unit_test_setup(test_viewer_failure_leaves_the_frame, setup),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
