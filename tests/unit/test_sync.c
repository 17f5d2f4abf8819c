/* Frame-set grouping on synthetic timestamp streams: steady, jittered, missing, late, duplicate
 * and out-of-order frames, triggers before and after their frames, stalls, flush, a camera gone. Expected sets
 * follow from the streams' construction (frame k of every camera belongs to set k). */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include <cmocka.h>

#include "stillheart/sync.h"

#define MS 1000000LL
static const int64_t T0 = 1000 * MS, P = 20 * MS; /* 50 fps */

static sh_sync *make(int cameras, int64_t max_wait, int64_t offset)
{
    sh_sync_options o = {cameras, 4 * MS, max_wait, offset};
    sh_sync *s;
    assert_int_equal(sh_sync_create(&o, &s), SH_OK);
    return s;
}

/* Deterministic jitter within +-3 ms. */
static int64_t jitter(int cam, int k) { return ((cam * 7 + k * 13) % 7 - 3) * MS; }

static sh_sync_disposition push(sh_sync *s, int cam, int k, int64_t t)
{
    sh_sync_disposition d;
    assert_int_equal(sh_sync_push(s, cam, (uint64_t)k, t, (void *)(intptr_t)(cam * 1000 + k + 1), &d), SH_OK);
    return d;
}

static void test_steady(void **state)
{
    (void)state;
    sh_sync *s = make(3, 3 * P, 0);
    int popped = 0;
    for (int k = 0; k < 50; k++) {
        for (int c = 0; c < 3; c++) assert_int_equal(push(s, c, k, T0 + k * P + jitter(c, k)), SH_SYNC_ADDED);
        sh_frame_set f;
        assert_int_equal(sh_sync_pop(s, &f), 1); /* out at once: complete */
        assert_int_equal(sh_sync_pop(s, &(sh_frame_set){0}), 0);
        assert_int_equal(f.index, (uint64_t)popped++);
        assert_true(f.complete);
        assert_int_equal(f.count, 3);
        assert_int_equal(f.present, 7);
        assert_int_equal(f.time_ns, T0 + k * P + jitter(0, k)); /* the first frame's time */
        for (int c = 0; c < 3; c++) {
            assert_int_equal(f.member[c].sequence, (uint64_t)k);
            assert_ptr_equal(f.member[c].user, (void *)(intptr_t)(c * 1000 + k + 1));
        }
    }
    sh_sync_stats st;
    sh_sync_get_stats(s, &st);
    assert_int_equal(st.sets, 50);
    assert_int_equal(st.complete, 50);
    assert_int_equal(st.incomplete, 0);
    sh_sync_destroy(s);
}

/* Camera 1 loses frame 5: set 5 comes out incomplete as soon as set 6 is complete, not after
 * the (long) maximum wait; the lost frame arriving afterwards is refused as late. */
static void test_missing_and_late(void **state)
{
    (void)state;
    sh_sync *s = make(2, 100 * P, 0);
    sh_frame_set f;
    for (int k = 0; k < 10; k++) {
        push(s, 0, k, T0 + k * P);
        if (k != 5) push(s, 1, k, T0 + k * P + MS);
        if (k == 5) {
            assert_int_equal(sh_sync_pop(s, &f), 0); /* set 5 waits for camera 1 */
            continue;
        }
        if (k == 6) {
            assert_int_equal(sh_sync_pop(s, &f), 1);
            assert_false(f.complete);
            assert_int_equal(f.present, 1);
            assert_int_equal(f.member[0].sequence, 5);
            /* the lost frame turns up late */
            assert_int_equal(push(s, 1, 5, T0 + 5 * P + MS), SH_SYNC_LATE);
        }
        assert_int_equal(sh_sync_pop(s, &f), 1);
        assert_true(f.complete);
        assert_int_equal(f.member[1].sequence, (uint64_t)k);
    }
    sh_sync_stats st;
    sh_sync_get_stats(s, &st);
    assert_int_equal(st.incomplete, 1);
    assert_int_equal(st.complete, 9);
    assert_int_equal(st.late, 1);
    sh_sync_destroy(s);
}

static void test_duplicate(void **state)
{
    (void)state;
    sh_sync *s = make(2, 3 * P, 0);
    assert_int_equal(push(s, 0, 0, T0), SH_SYNC_ADDED);
    assert_int_equal(push(s, 0, 0, T0 + MS), SH_SYNC_DUPLICATE);
    assert_int_equal(push(s, 1, 0, T0 + 2 * MS), SH_SYNC_ADDED);
    sh_frame_set f;
    assert_int_equal(sh_sync_pop(s, &f), 1);
    assert_true(f.complete);
    assert_int_equal(f.member[0].timestamp_ns, T0); /* the first stays */
    sh_sync_stats st;
    sh_sync_get_stats(s, &st);
    assert_int_equal(st.duplicates, 1);
    sh_sync_destroy(s);
}

/* Camera 2's frames arrive three periods behind the others', camera 1's in reverse pairs: every
 * set still complete, in time order. */
static void test_out_of_order(void **state)
{
    (void)state;
    sh_sync *s = make(3, 5 * P, 0);
    int next = 0;
    sh_frame_set f;
    for (int k = 0; k < 40 + 3; k++) {
        if (k < 40) push(s, 0, k, T0 + k * P + jitter(0, k));
        if (k < 40 && k % 2 == 1) {
            push(s, 1, k, T0 + k * P + jitter(1, k));
            push(s, 1, k - 1, T0 + (k - 1) * P + jitter(1, k - 1));
        }
        if (k >= 3) push(s, 2, k - 3, T0 + (k - 3) * P + jitter(2, k - 3));
        while (sh_sync_pop(s, &f)) {
            assert_true(f.complete);
            assert_int_equal(f.index, (uint64_t)next);
            for (int c = 0; c < 3; c++) assert_int_equal(f.member[c].sequence, (uint64_t)next);
            next++;
        }
    }
    assert_int_equal(next, 40);
    sh_sync_destroy(s);
}

/* Only camera 0 delivers: its sets come out incomplete once frames max_wait newer arrive. */
static void test_stall_and_flush(void **state)
{
    (void)state;
    sh_sync *s = make(2, 2 * P + P / 2, 0);
    sh_frame_set f;
    int popped = 0;
    for (int k = 0; k < 10; k++) {
        push(s, 0, k, T0 + k * P);
        while (sh_sync_pop(s, &f)) {
            assert_false(f.complete);
            assert_int_equal(f.member[0].sequence, (uint64_t)popped);
            popped++;
        }
        /* set j is out once frame j + 3 (60 ms > 50 ms later) has come */
        assert_int_equal(popped, k >= 3 ? k - 2 : 0);
    }
    sh_sync_flush(s);
    while (sh_sync_pop(s, &f)) popped++;
    assert_int_equal(popped, 10);
    sh_sync_destroy(s);
}

/* Camera 1 of three stops after frame 4 (its stream ended): the set it left half filled comes out
 * as soon as camera 1 is gone, and every later set once cameras 0 and 2 are both in it, whichever
 * comes first: no frame of theirs is refused as late (a flush at every frame after the loss
 * emitted the sets camera 2 opened before camera 0's frame came, and refused that frame). */
static void test_camera_gone(void **state)
{
    (void)state;
    sh_sync *s = make(3, 10 * P, 0);
    sh_frame_set f;
    int popped = 0;
    for (int k = 0; k < 5; k++) {
        for (int c = 0; c < 3; c++) assert_int_equal(push(s, c, k, T0 + k * P + jitter(c, k)), SH_SYNC_ADDED);
        while (sh_sync_pop(s, &f)) assert_true(f.complete), popped++;
    }
    /* frame 5 of cameras 0 and 2 in, camera 1's never: waiting, until camera 1 is gone */
    push(s, 0, 5, T0 + 5 * P + jitter(0, 5));
    push(s, 2, 5, T0 + 5 * P + jitter(2, 5));
    assert_int_equal(sh_sync_pop(s, &f), 0);
    assert_int_equal(sh_sync_camera_gone(s, 1), SH_OK);
    assert_int_equal(sh_sync_pop(s, &f), 1);
    assert_false(f.complete);
    assert_int_equal(f.present, 5);
    popped++;
    for (int k = 6; k < 20; k++) {
        int first = k % 2 ? 2 : 0; /* either camera may be first */
        assert_int_equal(push(s, first, k, T0 + k * P + jitter(first, k)), SH_SYNC_ADDED);
        assert_int_equal(sh_sync_pop(s, &f), 0); /* the other's frame is still to come */
        assert_int_equal(push(s, 2 - first, k, T0 + k * P + jitter(2 - first, k)), SH_SYNC_ADDED);
        assert_int_equal(sh_sync_pop(s, &f), 1);
        assert_int_equal(f.present, 5);
        assert_int_equal(f.member[0].sequence, (uint64_t)k);
        popped++;
    }
    sh_sync_stats st;
    sh_sync_get_stats(s, &st);
    assert_int_equal(popped, 20);
    assert_int_equal(st.late, 0);
    assert_int_equal(st.complete, 5);
    assert_int_equal(st.incomplete, 15);
    assert_int_equal(sh_sync_camera_gone(s, 3), SH_EINVAL);
    /* every camera gone: nothing waits */
    push(s, 0, 20, T0 + 20 * P);
    assert_int_equal(sh_sync_pop(s, &f), 0);
    assert_int_equal(sh_sync_camera_gone(s, 0), SH_OK);
    assert_int_equal(sh_sync_camera_gone(s, 2), SH_OK);
    assert_int_equal(sh_sync_pop(s, &f), 1);
    sh_sync_destroy(s);
}

/* Trigger edges: frames 5 ms after the edge. The set's time is the edge (+ offset), whether the
 * edge event comes before or after the frames; an edge with no frames is an incomplete set. */
static void test_trigger(void **state)
{
    (void)state;
    const int64_t off = 5 * MS;
    sh_sync *s = make(2, 3 * P, off);
    sh_frame_set f;
    for (int k = 0; k < 12; k++) {
        int64_t edge = T0 + k * P;
        if (k == 7) { /* the cameras missed this pulse */
            assert_int_equal(sh_sync_trigger(s, edge), SH_OK);
            continue;
        }
        if (k % 2) assert_int_equal(sh_sync_trigger(s, edge), SH_OK);
        push(s, 0, k, edge + off + jitter(0, k));
        push(s, 1, k, edge + off + jitter(1, k));
        if (!(k % 2)) assert_int_equal(sh_sync_trigger(s, edge), SH_OK);
        if (k == 8) {
            assert_int_equal(sh_sync_pop(s, &f), 1);
            assert_false(f.complete);
            assert_int_equal(f.count, 0);
            assert_true(f.triggered);
            assert_int_equal(f.time_ns, T0 + 7 * P + off);
        }
        assert_int_equal(sh_sync_pop(s, &f), 1);
        assert_true(f.complete);
        assert_true(f.triggered);
        assert_int_equal(f.time_ns, edge + off);
        assert_int_equal(f.member[1].sequence, (uint64_t)k);
    }
    /* an edge older than what was emitted */
    assert_int_equal(sh_sync_trigger(s, T0), SH_OK);
    sh_sync_stats st;
    sh_sync_get_stats(s, &st);
    assert_int_equal(st.late_edges, 1);
    assert_int_equal(st.incomplete, 1);
    sh_sync_destroy(s);
}

static void test_bad_args(void **state)
{
    (void)state;
    sh_sync *s;
    sh_sync_options o = {0, MS, MS, 0};
    assert_int_equal(sh_sync_create(&o, &s), SH_EINVAL);
    o.cameras = 2;
    o.tolerance_ns = 0;
    assert_int_equal(sh_sync_create(&o, &s), SH_EINVAL);
    s = make(2, P, 0);
    sh_sync_disposition d;
    assert_int_equal(sh_sync_push(s, 2, 0, T0, NULL, &d), SH_EINVAL);
    assert_int_equal(sh_sync_push(s, -1, 0, T0, NULL, &d), SH_EINVAL);
    /* many sets never popped: refused with an error, nothing grows */
    sh_status st = SH_OK;
    for (int k = 0; k < 100 && st == SH_OK; k++) st = sh_sync_push(s, 0, (uint64_t)k, T0 + k * P, NULL, &d);
    assert_int_equal(st, SH_ERANGE);
    sh_sync_destroy(s);
}

/* A missing GPIO chip is refused naming it (with or without libgpiod in the build); the lines
 * themselves are tested against gpio-sim in tests/vm/. */
static void test_gpio_refusals(void **state)
{
    (void)state;
    sh_gpio_options o = {"gpiochip-stillheart-missing", 3, 0, 1, 20 * MS, 1 * MS};
    sh_gpio_trigger *t = NULL;
    assert_int_not_equal(sh_gpio_trigger_open(&o, &t), SH_OK);
    assert_non_null(strstr(sh_error_message(), "gpiochip-stillheart-missing"));
    o.pulse_ns = 30 * MS; /* wider than the period */
    assert_int_not_equal(sh_gpio_trigger_open(&o, &t), SH_OK);
    assert_null(t);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_steady),          cmocka_unit_test(test_missing_and_late),
        cmocka_unit_test(test_duplicate),       cmocka_unit_test(test_out_of_order),
        cmocka_unit_test(test_stall_and_flush), cmocka_unit_test(test_camera_gone),
        cmocka_unit_test(test_trigger),         cmocka_unit_test(test_bad_args),
        cmocka_unit_test(test_gpio_refusals),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
