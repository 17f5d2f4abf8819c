/* The quality bars for the tracker on the phantom's analytic truth, detections simulated
 * from the model (0.2 px noise, 1% dropouts): see tools/track/sim.h. Figures in docs/tracking.md. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <cmocka.h>

#include "sim.h"

/* The tracker with its default options on the simulation c. */
static track_sim_result simulate(const track_sim_config *c)
{
    sh_track_options o;
    sh_track_options_default(&o);
    track_sim_result r;
    sh_status st = track_sim_run(c, &o, &r);
    if (st) fprintf(stderr, "%s\n", sh_error_message());
    assert_int_equal(st, SH_OK);
    return r;
}

static track_sim_result run(const char *preset, int cameras, double hide, double dur, int occl,
                            double partial, double dup, int auto_ids)
{
    track_sim_config c;
    track_sim_default(&c);
    c.preset = preset;
    c.cameras = cameras;
    c.hide_fraction = hide;
    c.hide_duration = dur;
    c.occlusions = occl;
    c.partial_shift = partial;
    c.duplicate_rate = dup;
    c.auto_ids = auto_ids;
    track_sim_result r = simulate(&c);
    fprintf(stderr, "  %s cams=%d hide=%.1f/%.1fs: visible %.3f px (%.3f mm), hidden mean %.3f max %.3f px, "
                    "lost %ld, false %ld, f_h %.4f/%.4f\n",
            preset, cameras, hide, dur, r.vis_mean_px, r.vis_mean_mm, r.hid_mean_px, r.hid_max_px,
            r.hid_lost, r.false_corr, r.heart_hz, r.true_heart_hz);
    return r;
}

static const char *presets[] = {"invivo", "exvivo"};

static void test_unoccluded(void **state)
{
    (void)state;
    for (int p = 0; p < 2; p++) {
        track_sim_result r = run(presets[p], 1, 0, 0, 0, 4, 0, 0);
        assert_true(r.lock_frame >= 0);
        assert_true(fabs(r.heart_hz - r.true_heart_hz) < 0.01 * r.true_heart_hz);
        assert_true(r.vis_count > 1000);
        assert_true(r.vis_mean_px < 0.3);
        r = run(presets[p], 3, 0, 0, 0, 4, 0, 0);
        assert_true(r.vis_mean_px < 0.3);
        assert_true(r.vis_mean_mm < 0.5);
    }
}

static void test_thirty_percent_hidden_one_second(void **state)
{
    (void)state;
    for (int p = 0; p < 2; p++)
        for (int cams = 1; cams <= 3; cams += 2) {
            track_sim_result r = run(presets[p], cams, 0.3, 1.0, 0, 4, 0, 0);
            assert_true(r.hid_count > 50);
            assert_int_equal(r.hid_lost, 0);
            assert_true(r.hid_mean_px < 2.0);
            assert_true(r.hid_max_px < 5.0);
        }
}

static void test_all_hidden_half_second(void **state)
{
    (void)state;
    for (int p = 0; p < 2; p++)
        for (int cams = 1; cams <= 3; cams += 2) {
            track_sim_result r = run(presets[p], cams, 1.0, 0.5, 0, 4, 0, 0);
            assert_true(r.hid_count > 100);
            assert_int_equal(r.hid_lost, 0);
            assert_true(r.hid_mean_px < 4.0);
        }
}

/* The decoy (a real tag off the heart) and duplicated ids: never reported, never used. Ids learnt
 * from the detections (no list), so the decoy is refused because it stays still while its
 * neighbours move (sh_tracker_judge_ids). */
static void test_decoy_and_duplicates(void **state)
{
    (void)state;
    for (int p = 0; p < 2; p++)
        for (int cams = 1; cams <= 3; cams += 2) {
            track_sim_result r = run(presets[p], cams, 0, 0, 1, 0, 0.2, 1);
            assert_true(r.stats.duplicates > 0);
            assert_int_equal(r.decoy_reported, 0);
            assert_int_equal(r.false_corr, 0);
        }
}

/* Partial occlusions (the phantom's shaft and blood over tags, decoded anyway with the hidden
 * corners or a side off by 8 px: sim.h): no measured estimate may end off the truth by more than
 * 1.5 px (3D: 1 mm) after one was fed, over every marker and frame after the rates lock. */
static void test_partial_occlusions(void **state)
{
    (void)state;
    for (int p = 0; p < 2; p++)
        for (int cams = 1; cams <= 3; cams += 2) {
            track_sim_result r = run(presets[p], cams, 0, 0, 1, 8, 0, 0);
            fprintf(stderr, "    corrupted fed %ld, refused for shape %ld, gated %ld, held %ld\n",
                    r.corrupted_fed, r.stats.misshapen, r.stats.gated, r.stats.held);
            assert_true(r.corrupted_fed > 80);
            assert_true(r.stats.misshapen > 0);
            assert_int_equal(r.false_corr, 0);
            assert_true(r.vis_mean_px < 0.3);
        }
}

/* Motions the phantom's rhythm never makes (issue 13): a sudden first beat, a panned and a bumped
 * endoscope, before the rates lock (short) and after it (long), 2D and 3D. Counted over every
 * frame from the first: every marker found (detected and used) in >= 98 % of the frames it is
 * visible in (1 % of the detections are dropped at random), mean error <= 0.3 px, max <= 2 px. */
static void test_sudden_motions(void **state)
{
    (void)state;
    struct {
        int motion, first_beat, frames;
        double at;
    } cases[] = {
        {0, 1, 70, 0}, {1, 0, 70, 1.3}, {2, 0, 70, 1.3}, {1, 0, 280, 7.5}, {2, 0, 280, 7.5},
    };
    static const char *names[] = {"first beat", "pan", "bump"};
    /* under qemu-aarch64 (SH_TEST_EMULATED, tools/cross/run-lanes.sh) a run costs ten times as
     * long: the exvivo preset's first beat and bump after the lock, 2D and 3D, there; the host
     * suite runs every case */
    int emulated = getenv("SH_TEST_EMULATED") != NULL;
    for (int p = emulated; p < 2; p++)
        for (int cams = 1; cams <= 3; cams += 2)
            for (int k = 0; k < (int)(sizeof cases / sizeof cases[0]); k++) {
                if (emulated && k != 0 && k != 4) continue;
                track_sim_config c;
                track_sim_default(&c);
                c.preset = presets[p];
                c.cameras = cams;
                c.frames = cases[k].frames;
                c.camera_motion = cases[k].motion;
                c.camera_motion_at = cases[k].at;
                c.first_beat = cases[k].first_beat;
                c.all_frames = 1;
                track_sim_result r = simulate(&c);
                double found = (double)r.found / (double)r.visible;
                fprintf(stderr, "  %s cams=%d %s at %.1f s (%d frames, lock frame %d): found %.1f %%, error "
                        "mean %.3f max %.3f px, camera moved in %ld frames, taken on agreement %ld, gated %ld\n",
                        presets[p], cams, names[cases[k].first_beat ? 0 : cases[k].motion], cases[k].first_beat ? 0.5 : cases[k].at,
                        c.frames, r.lock_frame, 100 * found, r.vis_mean_px, r.vis_max_px, r.stats.camera_moves,
                        r.stats.jumped, r.stats.gated);
                assert_true(r.visible > 500);
                assert_true(found >= 0.98);
                assert_true(r.vis_mean_px <= 0.3);
                assert_true(r.vis_max_px <= 2.0);
                assert_int_equal(r.stats.camera_moves > 0, cases[k].motion > 0);
            }
}

/* The calibration check (issue 16; src/track/calcheck.c): on the phantom's detections (0.2 px
 * noise, partly hidden tags) a right calibration, with lens distortion, stays far below the
 * daemon's default [gating] max_calibration_px of 0.5 px; the wrong ones an integrator can make
 * (two cameras swapped, one camera's translation 5 % off) come out far above it. Margins printed. */
static void test_calibration_check(void **state)
{
    (void)state;
    static const double dist[5] = {-0.25, 0.1, 0.001, -0.001, 0};
    const double limit = 0.5; /* sh_config_default's max_calibration_px */
    struct {
        int cams, a, b;
        double t1;
        const char *what;
    } cases[] = {
        {2, 0, 0, 0, "right"}, {3, 0, 0, 0, "right"}, {2, 0, 1, 0, "cameras 0 and 1 swapped"},
        {3, 0, 1, 0, "cameras 0 and 1 swapped"}, {3, 1, 2, 0, "cameras 1 and 2 swapped"},
        {2, 0, 0, 1.05, "camera 1's t x 1.05"}, {3, 0, 0, 1.05, "camera 1's t x 1.05"},
    };
    /* under qemu-aarch64 (SH_TEST_EMULATED) the exvivo preset only */
    for (int p = getenv("SH_TEST_EMULATED") != NULL; p < 2; p++)
        for (int k = 0; k < (int)(sizeof cases / sizeof cases[0]); k++) {
            track_sim_config c;
            track_sim_default(&c);
            c.preset = presets[p];
            c.cameras = cases[k].cams;
            c.frames = 40;
            c.occlusions = 1;
            c.distortion = dist;
            c.swap_a = cases[k].a;
            c.swap_b = cases[k].b;
            c.t1_scale = cases[k].t1;
            track_sim_result r = simulate(&c);
            const sh_track_calibration *cc = &r.calibration;
            int right = !strcmp(cases[k].what, "right");
            fprintf(stderr, "  %s cams=%d %s: reprojection median %.3f px over %d markers (%.1fx %s the 0.5 px "
                    "limit), camera %d %.3f px\n", presets[p], cases[k].cams, cases[k].what, cc->median_px,
                    cc->samples, right ? limit / cc->median_px : cc->median_px / limit, right ? "under" : "over",
                    cc->worst_camera, cc->worst_px);
            assert_true(cc->samples >= 200);
            if (right)
                assert_true(cc->median_px < limit / 2.5);
            else
                assert_true(cc->median_px > 2 * limit);
        }
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_unoccluded),
        cmocka_unit_test(test_thirty_percent_hidden_one_second),
        cmocka_unit_test(test_all_hidden_half_second),
        cmocka_unit_test(test_decoy_and_duplicates),
        cmocka_unit_test(test_partial_occlusions),
        cmocka_unit_test(test_sudden_motions),
        cmocka_unit_test(test_calibration_check),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
