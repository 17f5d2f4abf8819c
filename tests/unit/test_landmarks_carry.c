/* sh_landmarks_carry (landmarks.h, "Carried frames") against answers known without it: the
 * synthetic sequence (tools/synth: a texture under a known smooth deformation) gives every
 * landmark's and marker's true position in each frame. A frame carried from the frame before's
 * landmarks finds them where the truth has them; the check refuses a marker that moved unlike the
 * truth by a known distance, and a frame before whose landmarks were all off by a known shift; too
 * few markers or no landmark before searches nothing; bad arguments are refused. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include <cmocka.h>

#include "stillheart/landmarks.h"
#include "synth.h"

enum { W = 480, H = 360 };

static const synth_motion motion = {W, H, 6.0};

/* The frame before and this one: t = 0.15 and 0.2 of the synthetic deformation. */
#define T_PREV 0.15
#define T_NOW 0.2

typedef struct {
    sh_image ref, cur;
    sh_landmarks *lm;
    int n;
    float *prev, *pred, *xy;
    uint8_t *ok, *verdict;
    double *truth; /* n pairs: where each landmark is at T_NOW */
    /* two markers, near opposite corners of the field: reference, before, now */
    double mref[4], mprev[4], mnow[4];
} scene;

static void render(sh_image *img, double t)
{
    assert_int_equal(sh_image_create(img, SH_PIX_GRAY8, W, H), SH_OK);
    synth_render(&motion, t, img);
}

/* The landmarks of the sparse tests (3 levels: the search starts where the frame before had them)
 * on raw frames, as test_landmarks' tests on this texture; the frame before's positions its
 * truth, every third landmark not accepted there (predicted from its neighbours). */
static void scene_make(scene *s)
{
    memset(s, 0, sizeof *s);
    render(&s->ref, 0);
    render(&s->cur, T_NOW);
    sh_landmarks_params p;
    sh_landmarks_params_sparse(&p);
    p.max_points = 300;
    p.min_distance = 10;
    p.band = 0;
    assert_int_equal(sh_landmarks_create(&p, &s->ref.plane[0], NULL, NULL, 0, &s->lm), SH_OK);
    s->n = sh_landmarks_count(s->lm);
    assert_true(s->n >= 100);
    const float *r = sh_landmarks_reference(s->lm);
    s->prev = malloc(2 * (size_t)s->n * sizeof *s->prev);
    s->xy = malloc(2 * (size_t)s->n * sizeof *s->xy);
    s->pred = malloc(2 * (size_t)s->n * sizeof *s->pred);
    s->ok = malloc((size_t)s->n);
    s->verdict = malloc((size_t)s->n);
    s->truth = malloc(2 * (size_t)s->n * sizeof *s->truth);
    assert_non_null(s->prev && s->pred && s->xy && s->ok && s->verdict && s->truth);
    for (int i = 0; i < s->n; i++) {
        double x, y;
        synth_forward(&motion, T_PREV, r[2 * i], r[2 * i + 1], &x, &y);
        s->prev[2 * i] = (float)x, s->prev[2 * i + 1] = (float)y;
        s->ok[i] = i % 3 != 0;
        synth_forward(&motion, T_NOW, r[2 * i], r[2 * i + 1], &s->truth[2 * i], &s->truth[2 * i + 1]);
    }
    const double m[4] = {70, 60, 410, 300};
    memcpy(s->mref, m, sizeof m);
    for (int k = 0; k < 2; k++) {
        synth_forward(&motion, T_PREV, m[2 * k], m[2 * k + 1], &s->mprev[2 * k], &s->mprev[2 * k + 1]);
        synth_forward(&motion, T_NOW, m[2 * k], m[2 * k + 1], &s->mnow[2 * k], &s->mnow[2 * k + 1]);
    }
}

static void scene_free(scene *s)
{
    free(s->prev), free(s->pred), free(s->xy), free(s->ok), free(s->verdict), free(s->truth);
    sh_landmarks_destroy(s->lm);
    sh_image_destroy(&s->ref);
    sh_image_destroy(&s->cur);
}

static void test_carried_against_truth(void **state)
{
    (void)state;
    scene s;
    scene_make(&s);
    sh_landmarks_counts c;
    sh_landmarks_carry_report r;
    assert_int_equal(sh_landmarks_carry(s.lm, &s.cur.plane[0], s.prev, s.ok, s.mref, s.mprev, s.mnow, 2, 3.0,
                                        s.pred, s.xy, s.verdict, &c, &r),
                     SH_OK);
    int acc = 0, acc_new = 0, fresh = 0;
    double worst = 0;
    for (int i = 0; i < s.n; i++) {
        fresh += !s.ok[i];
        if (s.verdict[i] != SH_LANDMARK_ACCEPTED) continue;
        acc++;
        acc_new += !s.ok[i];
        worst = fmax(worst, hypot(s.xy[2 * i] - s.truth[2 * i], s.xy[2 * i + 1] - s.truth[2 * i + 1]));
    }
    print_message("  %d of %d accepted (%d of the %d not accepted before), worst %.3f px from the truth; "
                  "support %d, the markers' motion %.3f px from their landmarks'\n",
                  acc, s.n, acc_new, fresh, worst, r.support, r.worst_px);
    assert_int_equal(c.verdicts[SH_LANDMARK_ACCEPTED], acc);
    assert_true(r.searched && r.carried);
    assert_true(acc >= s.n * 8 / 10);
    assert_true(acc_new >= fresh * 8 / 10); /* predicted from their neighbours' */
    assert_true(worst <= 1.0);
    assert_true(r.support >= SH_LANDMARKS_CARRY_SUPPORT && r.support <= SH_LANDMARKS_CARRY_NEAR);
    /* the truth moves the markers as it moves the landmarks near them: what is left is the
     * landmarks' error and the motion's change over the tens of px between them */
    assert_true(r.worst_px < 0.5);
    scene_free(&s);
}

/* A marker seen 5 px from where the truth moved it (a detector or a tracker gone wrong): its
 * landmarks' motion is the truth's, so the check finds it 5 px off (to the landmarks' error and
 * the < 0.5 px above) and refuses the frame at 3 px; at 6 px it passes. */
static void test_marker_unlike_landmarks(void **state)
{
    (void)state;
    scene s;
    scene_make(&s);
    s.mnow[2] += 3, s.mnow[3] -= 4;
    sh_landmarks_carry_report r;
    assert_int_equal(sh_landmarks_carry(s.lm, &s.cur.plane[0], s.prev, s.ok, s.mref, s.mprev, s.mnow, 2, 3.0,
                                        s.pred, s.xy, s.verdict, NULL, &r),
                     SH_OK);
    print_message("  marker %d %.3f px unlike its landmarks\n", r.worst, r.worst_px);
    assert_true(r.searched);
    assert_false(r.carried);
    assert_int_equal(r.worst, 1);
    assert_true(fabs(r.worst_px - 5) < 0.5);
    assert_int_equal(sh_landmarks_carry(s.lm, &s.cur.plane[0], s.prev, s.ok, s.mref, s.mprev, s.mnow, 2, 6.0,
                                        s.pred, s.xy, s.verdict, NULL, &r),
                     SH_OK);
    assert_true(r.carried);
    scene_free(&s);
}

/* The frame before's landmarks all 6 px off (a chain that went wrong): each is still found against
 * the reference, where the truth has it, so its motion since the frame before differs from the
 * markers' (which the detector saw) by those 6 px, and the frame is refused. */
static void test_wrong_frame_before(void **state)
{
    (void)state;
    scene s;
    scene_make(&s);
    for (int i = 0; i < s.n; i++) s.prev[2 * i] += 6;
    sh_landmarks_carry_report r;
    assert_int_equal(sh_landmarks_carry(s.lm, &s.cur.plane[0], s.prev, s.ok, s.mref, s.mprev, s.mnow, 2, 3.0,
                                        s.pred, s.xy, s.verdict, NULL, &r),
                     SH_OK);
    double worst = 0;
    int acc = 0;
    for (int i = 0; i < s.n; i++)
        if (s.verdict[i] == SH_LANDMARK_ACCEPTED) {
            acc++;
            worst = fmax(worst, hypot(s.xy[2 * i] - s.truth[2 * i], s.xy[2 * i + 1] - s.truth[2 * i + 1]));
        }
    print_message("  %d accepted, worst %.3f px from the truth; marker %d %.3f px unlike its landmarks\n", acc, worst,
                  r.worst, r.worst_px);
    assert_true(acc > 0 && worst <= 1.0);
    assert_false(r.carried);
    assert_true(fabs(r.worst_px - 6) < 0.5);
    scene_free(&s);
}

/* Nothing to vouch for the landmarks, or nothing to carry: no search, not carried; and what is
 * refused as bad arguments. */
static void test_nothing_to_carry(void **state)
{
    (void)state;
    scene s;
    scene_make(&s);
    sh_landmarks_carry_report r;
    memset(s.verdict, 0xee, (size_t)s.n);
    assert_int_equal(sh_landmarks_carry(s.lm, &s.cur.plane[0], s.prev, s.ok, s.mref, s.mprev, s.mnow, 1, 3.0,
                                        s.pred, s.xy, s.verdict, NULL, &r),
                     SH_OK);
    assert_false(r.searched || r.carried);
    assert_int_equal(r.support, 0);
    assert_int_equal(s.verdict[0], 0xee); /* not searched */
    memset(s.ok, 0, (size_t)s.n);
    assert_int_equal(sh_landmarks_carry(s.lm, &s.cur.plane[0], s.prev, s.ok, s.mref, s.mprev, s.mnow, 2, 3.0,
                                        s.pred, s.xy, s.verdict, NULL, &r),
                     SH_OK);
    assert_false(r.searched || r.carried);
    assert_int_equal(r.support, 0);
    assert_int_equal(s.verdict[0], 0xee);
    assert_int_equal(sh_landmarks_carry(s.lm, &s.cur.plane[0], s.prev, s.ok, s.mref, s.mprev, s.mnow, 2, 3.0,
                                        s.pred, s.prev, s.verdict, NULL, &r),
                     SH_EINVAL);
    assert_int_equal(sh_landmarks_carry(s.lm, &s.cur.plane[0], s.prev, s.ok, s.mref, s.mprev, s.mnow, 2, 3.0,
                                        s.xy, s.xy, s.verdict, NULL, &r),
                     SH_EINVAL);
    assert_int_equal(sh_landmarks_carry(s.lm, &s.cur.plane[0], s.prev, s.ok, s.mref, s.mprev, s.mnow, 2, 0,
                                        s.pred, s.xy, s.verdict, NULL, &r),
                     SH_EINVAL);
    assert_int_equal(sh_landmarks_carry(s.lm, &s.cur.plane[0], s.prev, s.ok, NULL, s.mprev, s.mnow, 2, 3.0,
                                        s.pred, s.xy, s.verdict, NULL, &r),
                     SH_EINVAL);
    assert_int_equal(sh_landmarks_carry(NULL, &s.cur.plane[0], s.prev, s.ok, s.mref, s.mprev, s.mnow, 2, 3.0,
                                        s.pred, s.xy, s.verdict, NULL, &r),
                     SH_EINVAL);
    scene_free(&s);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_carried_against_truth),
        cmocka_unit_test(test_marker_unlike_landmarks),
        cmocka_unit_test(test_wrong_frame_before),
        cmocka_unit_test(test_nothing_to_carry),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
