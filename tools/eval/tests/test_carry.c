/* Carried frames (landmarks.h, "Carried frames"; docs/landmarks.md): four tags at the corners of
 * a rendered phantom's field, two of them gone for a stretch of frames, against the phantom's
 * truth. The daemon in test mode (its markers from a points file without those two) shows those
 * frames raw without [gating] landmarks_carry and carried with it, as near the truth as with all
 * four; when the two markers left move unlike the tissue (a detection gone wrong: the file's rows
 * 6 px off), the landmarks refuse to carry and the frames are raw. `stillheart track
 * --landmarks-carry` on the same video with the two tags painted over (a grey disk, as blood)
 * writes the landmarks of those frames, and `stillheart warp` maps every frame through them. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <cmocka.h>

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "shell.h"
#include "stillheart/y4m.h"

#if !defined(EVAL_BIN) || !defined(RENDER_BIN) || !defined(APP_BIN)
#error "EVAL_BIN, RENDER_BIN and APP_BIN must name this build's programs"
#endif

/* 960x540 (as test_eval_landmarks: at 640x360 the tags leave the tissue few corners), 40 frames;
 * the two tags at the field's left gone in frames GONE0..GONE1 */
#define FRAMES 40
#define GONE0 15
#define GONE1 24
#define ONE 19 /* a frame amid them with one marker */
#define REF 6 /* another reference than frame 0, before them */

static char dir[] = "/tmp/sh_carry_XXXXXX";

/* A number of a program's JSON output; the test fails when it has none under that key. */
static double json_num(const char *json, const char *key)
{
    double v = test_json_num(json, key);
    if (isnan(v)) fail_msg("no number under %s in %s", key, json);
    return v;
}

/* The four tags nearest the corners of a 16-tag render's frame 0 (tools/eval/corners.awk), the
 * same seed rendered with those alone, its truth's tag centres as the points file p4.csv; the two
 * left ones (the smallest x in frame 0) in `left`. */
static int setup(void **state)
{
    (void)state;
    assert_non_null(mkdtemp(dir));
    if (test_run("cd '%s' && '%s' --preset exvivo --rig paper --cameras 1 --width 960 --height 540 --seed 1 "
                 "--frames %d --quiet --out full && '%s' --truth full --export-points full.csv && "
                 "ids=$(awk -F, -f '%s/tools/eval/corners.awk' full.csv | tr '|' ,) && "
                 "'%s' --preset exvivo --rig paper --cameras 1 --width 960 --height 540 --seed 1 --frames %d "
                 "--only-markers $ids --quiet --out . && '%s' --truth . --export-points points.csv && "
                 "cut -d, -f1-4 points.csv > p4.csv && rm -rf full",
                 dir, RENDER_BIN, FRAMES, EVAL_BIN, SOURCE_DIR, RENDER_BIN, FRAMES, EVAL_BIN) != 0)
        fail_msg("%s\n%s", test_cmd, test_out);
    return 0;
}

static int teardown(void **state)
{
    (void)state;
    test_run("rm -rf '%s'", dir);
    return 0;
}

/* The two ids of p4.csv's frame 0 with the smallest x, "a|b" for awk; with third, the id with the
 * third smallest (a right one) alone. */
static void left_ids(char *out, size_t cap, int third)
{
    if (test_run("awk -F, '$1 == 0 { print $3, $2 }' '%s/p4.csv' | sort -n | %s | awk '{ print $2 }' | "
                 "paste -sd'|'", dir, third ? "sed -n 3p" : "head -2") != 0)
        fail_msg("%s", test_out);
    snprintf(out, cap, "%.*s", (int)strcspn(test_out, "\n"), test_out);
}

/* The daemon in test mode on cam0.y4m with points file PTS: landmarks with the sparse tests, three
 * markers needed, carry on or off; its trace in t.csv, what it showed in rec.y4m, its points in
 * used.csv; the geometric error of what it showed (the evaluator's JSON left in test_out). */
static double daemon(const char *pts, int carry)
{
    if (test_run("cd '%s' && rm -f rec.y4m && '%s' run --source y4m:cam0.y4m --no-realtime --no-loop --points %s "
                 "--landmarks 200 --landmarks-sparse 1 --min-markers 3 --landmarks-carry %d --method tps --sink none "
                 "--group= --threads 2 --quiet --record rec.y4m --trace t.csv --trace-points used.csv && "
                 "'%s' --quiet --json --truth . --points used.csv rec.y4m cam0.y4m",
                 dir, APP_BIN, pts, carry, EVAL_BIN) != 0)
        fail_msg("%s\n%s", test_cmd, test_out);
    const char *g = strstr(test_out, "\"geometric\"");
    assert_non_null(g);
    return json_num(g, "mean");
}

/* Frames of t.csv in [f0, f1] whose status is `status` and whose reason starts with `reason`. */
static int traced(int f0, int f1, const char *status, const char *reason)
{
    if (test_run("awk -F, -v a=%d -v b=%d -v s='%s' -v r='\"%s' 'NR > 1 && $1 >= a && $1 <= b && $2 == s && "
                 "index($5, r) == 1 { n++ } END { print n + 0 }' '%s/t.csv'", f0, f1, status, reason, dir) != 0)
        fail_msg("%s", test_out);
    return atoi(test_out);
}

static void test_daemon_carries_two_markers(void **state)
{
    (void)state;
    char left[64], right[64];
    left_ids(left, sizeof left, 0);
    left_ids(right, sizeof right, 1);
    /* the two left markers' rows gone in GONE0..GONE1; and, beside it, the two right ones' rows
     * moved 6 px there too; and one of those gone as well in ONE, a frame amid them */
    if (test_run("cd '%s' && awk -F, -v l='^(%s)$' 'NR == 1 || !($1 >= %d && $1 <= %d && $2 ~ l)' p4.csv > gone.csv && "
                 "awk -F, -v OFS=, -v a=%d -v b=%d 'NR > 1 && $1 >= a && $1 <= b { $3 += 6 } { print }' gone.csv > "
                 "moved.csv && awk -F, -v r=%s '!($1 == %d && $2 == r)' gone.csv > one.csv",
                 dir, left, GONE0, GONE1, GONE0, GONE1, right, ONE) != 0)
        fail_msg("%s\n%s", test_cmd, test_out);
    double all = daemon("p4.csv", 0);
    double raw = daemon("gone.csv", 0);
    int raw_frames = traced(GONE0, GONE1, "raw", "too few markers");
    double carried = daemon("gone.csv", 1);
    int carried_frames = traced(GONE0, GONE1, "degraded", "carried: 2 markers");
    int raw_after = traced(1, FRAMES, "raw", "");
    print_message("  geometric error: four tags %.4f px; two gone in frames %d-%d: raw %.4f px (%d raw), carried "
                  "%.4f px (%d carried, %d raw)\n", all, GONE0, GONE1, raw, raw_frames, carried, carried_frames,
                  raw_after);
    assert_int_equal(raw_frames, GONE1 - GONE0 + 1);
    assert_int_equal(carried_frames, GONE1 - GONE0 + 1);
    assert_int_equal(raw_after, 0);
    /* the carried frames are as near the truth as the four tags' (over the hull of the points
     * used: a lost tag's corner is not shown stabilized, and not counted) */
    assert_true(carried < all * 1.1);
    assert_true(carried < raw / 4);
    /* the markers left moved unlike the tissue: refused at the first such frame, which breaks
     * the chain; nothing carried, every such frame raw */
    daemon("moved.csv", 1);
    int refused = traced(GONE0, GONE0, "raw", "too few markers (2); landmarks");
    int moved_raw = traced(GONE0, GONE1, "raw", "too few markers");
    int moved_carried = traced(1, FRAMES, "degraded", "carried");
    print_message("  the two markers left 6 px off: %d refused by the landmarks, %d raw, %d carried\n", refused,
                  moved_raw, moved_carried);
    assert_int_equal(refused, 1);
    assert_int_equal(moved_raw, GONE1 - GONE0 + 1);
    assert_int_equal(moved_carried, 0);
    /* one marker in frame ONE: nothing to vouch for the landmarks there, so it is raw; the frames
     * after it are carried from the frame before it, on the two markers seen in both */
    double one = daemon("one.csv", 1);
    int one_raw = traced(1, FRAMES, "raw", "too few markers (1");
    int one_carried = traced(GONE0, GONE1, "degraded", "carried: 2 markers");
    int one_all_raw = traced(1, FRAMES, "raw", "");
    print_message("  one marker left in frame %d: %d raw, %d of the other frames carried, %.4f px\n", ONE, one_raw,
                  one_carried, one);
    assert_int_equal(one_raw, 1);
    assert_int_equal(one_all_raw, 1);
    assert_int_equal(one_carried, GONE1 - GONE0);
    assert_true(one < raw / 4);
    /* refused: without landmarks, and in 3D */
    const char *bad[][2] = {{"--landmarks-carry 1", "there are no landmarks"},
                            {"--landmarks 10 --landmarks-carry 1 --calibration x.yaml", "in 3D"}};
    for (int k = 0; k < 2; k++) {
        assert_int_equal(test_run("'%s' run --source y4m:%s/cam0.y4m %s --sink none", APP_BIN, dir, bad[k][0]), 2);
        if (!strstr(test_out, bad[k][1])) fail_msg("%s: no '%s' in:\n%s", bad[k][0], bad[k][1], test_out);
    }
}

/* covered.y4m: cam0.y4m with a grey disk of radius r (luma 110, neutral chroma: blood's flat look
 * on the band-passed frames) over each of the two left tags' centres in frames f0..f1, and over a
 * third tag's in frame one (within them; -1: none). */
static void cover(int f0, int f1, double r, int one)
{
    char left[64], right[64], path[600];
    left_ids(left, sizeof left, 0);
    left_ids(right, sizeof right, 1);
    if (test_run("awk -F, -v l='^(%s)$' -v r=%s -v o=%d 'NR > 1 && ($2 ~ l || ($1 == o && $2 == r)) "
                 "{ print $1, $3, $4 }' '%s/p4.csv'", left, right, one, dir) != 0)
        fail_msg("%s", test_out);
    double cx[2 * FRAMES + 1], cy[2 * FRAMES + 1];
    int cf[2 * FRAMES + 1], nc = 0;
    for (char *s = test_out; nc < 2 * FRAMES + 1 && sscanf(s, "%d %lf %lf", &cf[nc], &cx[nc], &cy[nc]) == 3; nc++) {
        s = strchr(s, '\n');
        if (!s) break;
        s++;
    }
    snprintf(path, sizeof path, "%s/cam0.y4m", dir);
    sh_y4m_reader *rd;
    assert_int_equal(sh_y4m_reader_open(path, &rd), SH_OK);
    const sh_y4m_header *h = sh_y4m_reader_header(rd);
    sh_image img;
    assert_int_equal(sh_image_create(&img, h->format, h->width, h->height), SH_OK);
    snprintf(path, sizeof path, "%s/covered.y4m", dir);
    sh_y4m_writer *wr;
    assert_int_equal(sh_y4m_writer_open(path, h, &wr), SH_OK);
    for (int f = 0; sh_y4m_reader_read(rd, &img) == SH_OK; f++) {
        for (int k = 0; k < nc && f >= f0 && f <= f1; k++) {
            if (cf[k] != f) continue;
            for (int p = 0; p < 3; p++) {
                sh_plane *pl = &img.plane[p];
                double s = (double)pl->width / h->width; /* the chroma planes' scale */
                for (int y = 0; y < pl->height; y++)
                    for (int x = 0; x < pl->width; x++)
                        if (hypot(x / s - cx[k], y / s - cy[k]) <= r) pl->data[(size_t)y * pl->stride + x] = p ? 128 : 110;
            }
        }
        assert_int_equal(sh_y4m_writer_write(wr, &img), SH_OK);
    }
    assert_int_equal(sh_y4m_writer_close(wr), SH_OK);
    sh_y4m_reader_close(rd);
    sh_image_destroy(&img);
}

/* `stillheart track --landmarks 200 --landmarks-sparse --reference REF` on covered.y4m (with
 * --landmarks-carry when carry) into lmK.csv, then `stillheart warp --reference REF` through it:
 * the geometric error and raw frames of what it shows into mean and raw; with carry, --stats'
 * carried and not carried frames, and its landmarks chosen and judged (the verdicts' sum) into
 * c[0..3]. */
static void track_warp(int k, int carry, int ref, double *mean, int *raw, double c[4])
{
    /* in a subshell: its standard error, the JSON, is test_out, and its output the file */
    if (test_run("cd '%s' && ('%s' track --ids $(awk -F, 'NR > 1 { print $2 }' p4.csv | sort -un | paste -sd,) "
                 "--landmarks 200 --landmarks-sparse --reference %d %s --stats --json covered.y4m > lm%d.csv)", dir,
                 APP_BIN, ref, carry ? "--landmarks-carry" : "", k) != 0)
        fail_msg("%s\n%s", test_cmd, test_out);
    if (carry) {
        const char *l = strstr(test_out, "\"landmarks\"");
        assert_non_null(l);
        c[0] = json_num(l, "carried_frames");
        c[1] = json_num(l, "not_carried_frames");
        c[2] = json_num(l, "chosen");
        static const char *const verdicts[] = {"accepted", "lost", "photometric", "backward", "disagrees", "deviates",
                                               "unconfirmed"};
        c[3] = 0;
        for (int v = 0; v < 7; v++) c[3] += json_num(l, verdicts[v]);
    }
    if (test_run("cd '%s' && '%s' warp --quiet --method tps --reference %d --points lm%d.csv covered.y4m stab.y4m && "
                 "'%s' --quiet --json --reference %d --truth . --points lm%d.csv stab.y4m",
                 dir, APP_BIN, ref, k, EVAL_BIN, ref, k) != 0)
        fail_msg("%s\n%s", test_cmd, test_out);
    const char *g = strstr(test_out, "\"geometric\"");
    assert_non_null(g);
    *mean = json_num(g, "mean");
    *raw = (int)json_num(g, "raw_frames");
}

static void test_track_carries_two_markers(void **state)
{
    (void)state;
    /* frames 12-34 covered: the tracker writes its predictions of the two for a fifth of a
     * second before it knows the heart's rate (a third of the stretch), then drops them */
    cover(12, 34, 30, -1);
    double mean[2], c[4] = {0};
    int raw[2];
    track_warp(0, 0, 0, &mean[0], &raw[0], c);
    track_warp(1, 1, 0, &mean[1], &raw[1], c);
    double carried = c[0], not_carried = c[1];
    print_message("  two tags covered in frames 12-34: without carry %.4f px (%d frames raw); with it %.4f px (%d "
                  "raw), %.0f frames carried, %.0f not vouched for\n", mean[0], raw[0], mean[1], raw[1], carried,
                  not_carried);
    assert_true(raw[0] > 0);
    assert_int_equal(raw[1], 0);
    assert_int_equal((int)carried, raw[0]);
    assert_int_equal((int)not_carried, 0);
    /* every frame searched counts each landmark's verdict once: the frames the file has landmark
     * rows for but frame 0 (their reference positions), and those searched and not carried */
    assert_int_equal(test_run("cd '%s' && awk -F, 'NR > 1 && $2 >= 1000000 { print $1 }' lm1.csv | sort -u | wc -l",
                              dir), 0);
    assert_int_equal((long long)c[3], (long long)c[2] * (atoi(test_out) - 1 + (long long)not_carried));
    assert_true(mean[1] < mean[0] / 2);
    /* a third tag covered too in frame 28, after the tracker dropped the two: one tag detected
     * there, nothing to vouch for the landmarks, so that frame is raw; the frames after it are
     * carried from the frame before it, on the two tags detected in both */
    cover(12, 34, 30, 28);
    double one;
    int one_raw;
    track_warp(2, 1, 0, &one, &one_raw, c);
    print_message("  a third tag covered in frame 28: %d raw, %.0f carried, %.4f px\n", one_raw, c[0], one);
    assert_int_equal(one_raw, 1);
    assert_int_equal((int)c[0], raw[0] - 1);
    assert_true(one < mean[0] / 2);
    /* the landmarks chosen in frame REF (--reference), before the stretch: the chain's first link
     * is REF, the same frames carried as from frame 0, none before REF written */
    cover(12, 34, 30, -1);
    double from[2];
    int from_raw[2];
    track_warp(3, 0, REF, &from[0], &from_raw[0], c);
    track_warp(4, 1, REF, &from[1], &from_raw[1], c);
    print_message("  from frame %d: without carry %.4f px (%d frames raw); with it %.4f px (%d raw), %.0f carried\n",
                  REF, from[0], from_raw[0], from[1], from_raw[1], c[0]);
    assert_int_equal(from_raw[0], raw[0]);
    assert_int_equal(from_raw[1], 0);
    assert_int_equal((int)c[0], raw[0]);
    assert_int_equal((int)c[1], 0);
    assert_int_equal(test_run("cd '%s' && awk -F, 'NR > 1 && $2 >= 1000000 { print $1 }' lm4.csv | sort -n | uniq | "
                              "awk 'NR == 1 { f = $1 } END { print f, NR }'", dir), 0);
    int first, frames;
    assert_int_equal(sscanf(test_out, "%d %d", &first, &frames), 2);
    assert_int_equal(first, REF);
    assert_int_equal((long long)c[3], (long long)c[2] * (frames - 1));
    assert_true(from[1] < from[0] / 2);
    /* refused: without --landmarks, and with --cameras (3D) */
    assert_int_equal(test_run("'%s' track --landmarks-carry %s/cam0.y4m", APP_BIN, dir), 2);
    assert_non_null(strstr(test_out, "--landmarks-carry goes with --landmarks"));
    assert_int_equal(test_run("'%s' track --landmarks 10 --landmarks-carry --cameras x.yaml %s/cam0.y4m %s/cam0.y4m",
                              APP_BIN, dir, dir), 2);
    assert_non_null(strstr(test_out, "--landmarks-carry is 2D"));
}

/* Under qemu-aarch64 (SH_TEST_EMULATED, tools/cross/run-lanes.sh) the six daemon runs and two
 * tracks of 960x540 frames would add about two minutes to a lane: the host suite and ASan run
 * them, and on aarch64 test_landmarks_carry checks sh_landmarks_carry itself, whose C has no
 * SIMD of its own (its searches are test_landmarks' and test_flow_simd's). */
int main(void)
{
    if (getenv("SH_TEST_EMULATED")) {
        printf("test_carry: skipped under emulation (the host and ASan suites run it)\n[  PASSED  ] 0 tests.\n");
        return 0;
    }
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_daemon_carries_two_markers),
        cmocka_unit_test(test_track_carries_two_markers),
    };
    return cmocka_run_group_tests(tests, setup, teardown);
}
