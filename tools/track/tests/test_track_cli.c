/* `stillheart track` from the outside: its options and refusals, its points file against the
 * phantom's ground truth (2D and, with the calibration, 3D), standard input, and the end
 * to end bar: stabilizing a rendered phantom from `stillheart track`'s points comes within 10 % of
 * stabilizing it from the ground-truth points, in the paper's metric e and in the geometric error
 * of the warp against the truth (stillheart-eval). And the motions the phantom's rhythm never
 * makes (issue 13): a sudden first beat, a panned and a bumped endoscope, before and after the
 * rates lock, through `stillheart track` and through the daemon. And without --ids (issue 18):
 * every heart marker kept, the decoy never, what was left out said. The binaries are this build's. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <cmocka.h>

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>
#include <unistd.h>

#if !defined(APP_BIN) || !defined(RENDER_BIN) || !defined(EVAL_BIN)
#error "APP_BIN, RENDER_BIN and EVAL_BIN must name this build's binaries"
#endif

static char tmp[64];
#define SH_TEST_MAX_IDS 1024 /* ids of the renders' family looked at */
static int rendered; /* 1: tmp/one (1 camera) and tmp/three (3 cameras) hold phantom renders */

/* The motion sequences: exvivo (23 frames/s, rates lock after about 4.2 s), one camera, 640x360
 * (the figures in docs/tracking.md are the same cases at 960x540, the size the issue measured:
 * the warps of the e check take 2.25 times as long there, for the same verdicts); short ones
 * move before the lock, long ones after it. */
typedef struct {
    const char *name, *render; /* tmp/NAME, stillheart-render's motion options */
    int frames;
    double start, end;         /* the motion, seconds (the renderer's definitions) */
} motion_case;
static const motion_case motions[] = {
    {"first", "--first-beat --first-beat-at 0.5", 60, 0.5, 0.5 + 0.5 / 0.7 / 4},
    /* (rendered in setup even when emulated: with the host's renderer, a second each) */
    {"pan", "--camera-motion pan --camera-motion-at 1.3", 60, 1.3, 1.3 + 0.25},
    {"bump", "--camera-motion bump --camera-motion-at 1.3", 60, 1.3, 1.3},
    {"panlong", "--camera-motion pan --camera-motion-at 5.3", 150, 5.3, 5.3 + 0.25},
    {"bumplong", "--camera-motion bump --camera-motion-at 5.3", 150, 5.3, 5.3},
};
#define NMOTIONS (int)(sizeof motions / sizeof motions[0])
#define MOTION_FPS 23.0

static void path(char *out, size_t size, const char *name)
{
    snprintf(out, size, "%s/%s", tmp, name);
}

static char *slurp(const char *file, size_t *len)
{
    FILE *f = fopen(file, "rb");
    if (!f) return NULL;
    fseek(f, 0, SEEK_END);
    long n = ftell(f);
    fseek(f, 0, SEEK_SET);
    char *buf = malloc((size_t)n + 1);
    size_t got = buf ? fread(buf, 1, (size_t)n, f) : 0;
    fclose(f);
    if (!buf) return NULL;
    buf[got] = 0;
    if (len) *len = got;
    return buf;
}

/* Runs `stillheart ARGS` (a shell fragment), stdout to tmp/NAME.out (unless redirected in args),
 * stderr to tmp/err; returns the exit status. */
static int app(const char *args, const char *name)
{
    char cmd[4096], out[512], err[512];
    path(out, sizeof out, name);
    strcat(out, ".out");
    path(err, sizeof err, "err");
    snprintf(cmd, sizeof cmd, "'%s' %s > '%s' 2> '%s'", APP_BIN, args, out, err);
    int rc = system(cmd);
    return WIFEXITED(rc) ? WEXITSTATUS(rc) : -1;
}

static int stderr_has(const char *text)
{
    char p[512];
    path(p, sizeof p, "err");
    char *e = slurp(p, NULL);
    int has = e && strstr(e, text);
    if (!has) fprintf(stderr, "stderr lacks \"%s\":\n%s\n", text, e ? e : "(none)");
    free(e);
    return has;
}

static int setup_tmp(void **state)
{
    (void)state;
    snprintf(tmp, sizeof tmp, "/tmp/sh_test_track_cli_XXXXXX");
    return mkdtemp(tmp) ? 0 : -1;
}

static int setup(void **state)
{
    if (setup_tmp(state) != 0) return -1;
    if (access(RENDER_BIN, X_OK) != 0) return 0; /* no OSMesa: the phantom tests skip */
    char cmd[2048];
    /* in-vivo (respiration, stabilizer pads), half resolution: 60 frames of one camera, 20 of three */
    snprintf(cmd, sizeof cmd,
             "'%s' --preset invivo --cameras 1 --frames 60 --width 960 --height 540 --quiet --out '%s/one' "
             "&& '%s' --preset invivo --cameras 3 --frames 20 --width 960 --height 540 --quiet --out '%s/three' "
             "&& '%s' --truth '%s/one' --export-points '%s/one/truth.csv'",
             RENDER_BIN, tmp, RENDER_BIN, tmp, EVAL_BIN, tmp, tmp);
    rendered = system(cmd) == 0;
    for (int k = 0; k < NMOTIONS && rendered; k++) {
        snprintf(cmd, sizeof cmd,
                 "'%s' --preset exvivo --cameras 1 --frames %d --width 640 --height 360 %s --quiet --out '%s/%s' "
                 "&& '%s' --truth '%s/%s' --export-points '%s/%s/truth.csv'",
                 RENDER_BIN, motions[k].frames, motions[k].render, tmp, motions[k].name, EVAL_BIN, tmp,
                 motions[k].name, tmp, motions[k].name);
        rendered = system(cmd) == 0;
    }
    return rendered ? 0 : -1;
}

static int teardown(void **state)
{
    (void)state;
    char cmd[512];
    snprintf(cmd, sizeof cmd, "rm -rf '%s'", tmp);
    return system(cmd) == 0 ? 0 : -1;
}

static void test_options_and_refusals(void **state)
{
    (void)state;
    assert_int_equal(app("track --help", "help"), 0);
    char p[512];
    path(p, sizeof p, "help.out");
    char *help = slurp(p, NULL);
    assert_non_null(help);
    assert_non_null(strstr(help, "usage: stillheart track"));
    free(help);
    assert_int_equal(app("track", "none"), 2);
    assert_true(stderr_has("need one to") && stderr_has("try 'stillheart track --help'")); /* one line, not the usage */
    assert_int_equal(app("track --ids 5-2 x.y4m", "ids"), 2);
    assert_true(stderr_has("--ids: '5-2'"));
    assert_int_equal(app("track --ids 0-64 x.y4m", "ids"), 2); /* 65 ids: more than the tracker holds */
    assert_int_equal(app("track --spatial sideways x.y4m", "spatial"), 2);
    assert_true(stderr_has("--spatial: off or fuse"));
    assert_int_equal(app("track --noise 0 x.y4m", "noise"), 2);
    assert_int_equal(app("track --lost-after 0 x.y4m", "lost"), 2);
    assert_int_equal(app("track --bogus x.y4m", "bogus"), 2);
    assert_int_equal(app("track a.y4m b.y4m", "two"), 2);
    assert_true(stderr_has("need --cameras"));
    assert_int_equal(app("track --ids 0-3 - < /dev/null", "stdin"), 1);
    assert_int_equal(app("track - < /dev/null", "stdin"), 2);
    assert_true(stderr_has("standard input needs --ids"));
    assert_int_equal(app("track --ids 0-3 /nonexistent/in.y4m", "missing"), 1);
    assert_true(stderr_has("/nonexistent/in.y4m"));
    assert_int_equal(app("track --ids 0-3 --family tag99h99 /nonexistent/in.y4m", "family"), 1);
    assert_int_equal(app("track --cameras /nonexistent/calib.yaml x.y4m", "calib"), 1);
    if (!rendered) return;
    char args[1024];
    snprintf(args, sizeof args, "track --cameras '%s/three/calibration.yaml' '%s/three/cam0.y4m'", tmp, tmp);
    assert_int_equal(app(args, "calib"), 2);
    assert_true(stderr_has("has 3 cameras, 1 videos given"));
}

typedef struct {
    int frame, id;
    double x, y, X, Y, Z;
} row;

/* Parses a points file with the given header; returns the rows (malloc'd), n. */
static row *read_points(const char *file, const char *header, int *n)
{
    size_t len;
    char *text = slurp(file, &len);
    assert_non_null(text);
    size_t hl = strlen(header);
    assert_true(len > hl && !strncmp(text, header, hl) && text[hl] == '\n');
    int cap = 1024, cnt = 0;
    row *r = malloc(sizeof *r * (size_t)cap);
    int xyz = strstr(header, ",X,Y,Z") != NULL;
    for (char *line = strtok(text + hl + 1, "\n"); line; line = strtok(NULL, "\n")) {
        if (cnt == cap) r = realloc(r, sizeof *r * (size_t)(cap *= 2));
        row *q = &r[cnt];
        int got = sscanf(line, "%d,%d,%lf,%lf,%lf,%lf,%lf", &q->frame, &q->id, &q->x, &q->y, &q->X, &q->Y, &q->Z);
        assert_int_equal(got, xyz ? 7 : 4);
        cnt++;
    }
    free(text);
    *n = cnt;
    return r;
}

static const row *find_row(const row *r, int n, int frame, int id)
{
    for (int i = 0; i < n; i++)
        if (r[i].frame == frame && r[i].id == id) return &r[i];
    return NULL;
}

/* The points file: header, frames in order from 0, ids of the phantom once per frame, positions
 * on the truth; standard input gives the same bytes; --measured-only a subset. */
static void test_points_2d(void **state)
{
    (void)state;
    if (!rendered) skip();
    char args[1024], p[512], q[512];
    snprintf(args, sizeof args, "track --ids 0-13 '%s/one/cam0.y4m'", tmp);
    assert_int_equal(app(args, "track"), 0);
    path(p, sizeof p, "track.out");
    int n, nt;
    row *r = read_points(p, "frame,id,x,y", &n);
    path(q, sizeof q, "one/truth.csv");
    row *t = read_points(q, "frame,id,x,y,X,Y,Z", &nt);
    double sum = 0, mx = 0;
    int matched = 0;
    for (int i = 0; i < n; i++) {
        assert_true(r[i].id >= 0 && r[i].id <= 13 && r[i].frame >= 0 && r[i].frame < 60);
        if (i) assert_true(r[i].frame >= r[i - 1].frame);
        if (i && r[i].frame == r[i - 1].frame) assert_true(r[i].id > r[i - 1].id);
        const row *g = find_row(t, nt, r[i].frame, r[i].id);
        if (!g) continue;
        double e = hypot(r[i].x - g->x, r[i].y - g->y);
        sum += e;
        mx = fmax(mx, e);
        matched++;
    }
    fprintf(stderr, "  2D: %d rows, %d on visible truth: mean %.3f px, max %.3f px\n", n, matched, sum / matched, mx);
    assert_int_equal(r[0].frame, 0);
    assert_true(matched >= nt * 95 / 100);
    assert_true(sum / matched < 0.15);
    assert_true(mx < 1.0);
    /* standard input: the same bytes */
    snprintf(args, sizeof args, "track --ids 0-13 - < '%s/one/cam0.y4m'", tmp);
    assert_int_equal(app(args, "stdin"), 0);
    path(q, sizeof q, "stdin.out");
    char *a = slurp(p, NULL), *b = slurp(q, NULL);
    assert_string_equal(a, b);
    free(a);
    free(b);
    /* measured only: a subset of the rows */
    snprintf(args, sizeof args, "track --ids 0-13 --measured-only '%s/one/cam0.y4m'", tmp);
    assert_int_equal(app(args, "measured"), 0);
    path(q, sizeof q, "measured.out");
    int nm;
    row *m = read_points(q, "frame,id,x,y", &nm);
    assert_true(nm > 0 && nm <= n);
    for (int i = 0; i < nm; i++) assert_non_null(find_row(r, n, m[i].frame, m[i].id));
    free(m);
    free(r);
    free(t);
}

/* Three calibrated cameras: X,Y,Z columns in the calibration's millimetres, on the truth. */
static void test_points_3d(void **state)
{
    (void)state;
    if (!rendered) skip();
    char args[1024], p[512], q[512];
    snprintf(args, sizeof args,
             "track --ids 0-13 --cameras '%s/three/calibration.yaml' '%s/three/cam0.y4m' '%s/three/cam1.y4m' "
             "'%s/three/cam2.y4m'",
             tmp, tmp, tmp, tmp);
    assert_int_equal(app(args, "track3"), 0);
    snprintf(args, sizeof args, "--truth '%s/three' --export-points '%s/three/truth.csv'", tmp, tmp);
    char cmd[2048];
    snprintf(cmd, sizeof cmd, "'%s' %s", EVAL_BIN, args);
    assert_int_equal(system(cmd), 0);
    path(p, sizeof p, "track3.out");
    path(q, sizeof q, "three/truth.csv");
    int n, nt;
    row *r = read_points(p, "frame,id,x,y,X,Y,Z", &n);
    row *t = read_points(q, "frame,id,x,y,X,Y,Z", &nt);
    double sum = 0;
    int matched = 0;
    for (int i = 0; i < n; i++) {
        const row *g = find_row(t, nt, r[i].frame, r[i].id);
        if (!g) continue;
        sum += sqrt((r[i].X - g->X) * (r[i].X - g->X) + (r[i].Y - g->Y) * (r[i].Y - g->Y) +
                    (r[i].Z - g->Z) * (r[i].Z - g->Z));
        matched++;
    }
    fprintf(stderr, "  3D: %d rows, %d on visible truth: mean %.3f mm\n", n, matched, sum / matched);
    assert_true(matched > nt / 2);
    assert_true(sum / matched < 0.5);
    free(r);
    free(t);
}

/* One JSON number of stillheart-eval's output: the first "key": value. */
static double json_num(const char *json, const char *key)
{
    char pat[64];
    snprintf(pat, sizeof pat, "\"%s\": ", key);
    const char *p = strstr(json, pat);
    return p ? strtod(p + strlen(pat), NULL) : NAN;
}

/* warp tmp/DIR/cam0.y4m with points file P (tmp/DIR/truth.csv or tmp/track.out), then
 * stillheart-eval: e and the geometric mean error */
static void stabilize(const char *dir, const char *method, const char *points, double *e, double *geo)
{
    char args[2048], cmd[4096], out[512];
    snprintf(args, sizeof args, "warp --quiet --method %s --points '%s' '%s/%s/cam0.y4m' '%s/stab.y4m'",
             method, points, tmp, dir, tmp);
    assert_int_equal(app(args, "warp"), 0);
    path(out, sizeof out, "eval.json");
    snprintf(cmd, sizeof cmd, "'%s' --quiet --json --points '%s' --truth '%s/%s' --method %s '%s/stab.y4m' > '%s'",
             EVAL_BIN, points, tmp, dir, method, tmp, out);
    assert_int_equal(system(cmd), 0);
    char *json = slurp(out, NULL);
    assert_non_null(json);
    *e = json_num(json, "e_stabilized");
    const char *g = strstr(json, "\"geometric\"");
    assert_non_null(g);
    *geo = json_num(g, "mean");
    free(json);
    assert_true(isfinite(*e) && isfinite(*geo));
}

static void test_stabilize_within_ten_percent(void **state)
{
    (void)state;
    if (!rendered) skip();
    char args[1024], tracked[512], truth[512];
    snprintf(args, sizeof args, "track --ids 0-13 '%s/one/cam0.y4m'", tmp);
    assert_int_equal(app(args, "e2e"), 0);
    path(tracked, sizeof tracked, "e2e.out");
    path(truth, sizeof truth, "one/truth.csv");
    const char *methods[] = {"bspline", "tps"};
    for (int k = 0; k < 2; k++) {
        double e_tr, g_tr, e_gt, g_gt;
        stabilize("one", methods[k], tracked, &e_tr, &g_tr);
        stabilize("one", methods[k], truth, &e_gt, &g_gt);
        fprintf(stderr, "  %s: e %.5f (truth %.5f, %+.1f %%), geometric mean %.4f px (truth %.4f, %+.1f %%)\n",
                methods[k], e_tr, e_gt, 100 * (e_tr / e_gt - 1), g_tr, g_gt, 100 * (g_tr / g_gt - 1));
        assert_true(e_tr <= 1.10 * e_gt);
        assert_true(g_tr <= 1.10 * g_gt);
    }
}

/* Issue 13's bars on one motion sequence through `stillheart track`: every marker found in
 * >= 98 % of the frames it is visible in, mean error <= 0.3 px, max <= 2 px against the truth; the
 * warp from the tracked points within 10 % (e) of the warp from the true ones. */
static void track_case(const motion_case *mc)
{
    char args[1024], p[512], q[512];
    snprintf(args, sizeof args, "track --stats --ids 0-15 '%s/%s/cam0.y4m'", tmp, mc->name);
    assert_int_equal(app(args, "motion"), 0);
    path(p, sizeof p, "motion.out");
    int n, nt;
    row *r = read_points(p, "frame,id,x,y", &n);
    snprintf(q, sizeof q, "%s/%s/truth.csv", tmp, mc->name);
    row *t = read_points(q, "frame,id,x,y,X,Y,Z", &nt);
    double sum = 0, mx = 0;
    int found = 0, worst_id = -1, worst_frame = -1;
    for (int i = 0; i < nt; i++) {
        const row *g = find_row(r, n, t[i].frame, t[i].id);
        if (!g) continue;
        double e = hypot(g->x - t[i].x, g->y - t[i].y);
        sum += e;
        if (e > mx) mx = e, worst_id = t[i].id, worst_frame = t[i].frame;
        found++;
    }
    char err[512];
    path(err, sizeof err, "err");
    char *stats = slurp(err, NULL);
    fprintf(stderr, "  %-8s track: found %d of %d (%.1f %%), error mean %.3f / max %.3f px (marker %d, frame %d)\n"
            "           %s", mc->name, found, nt, 100.0 * found / nt, sum / found, mx, worst_id, worst_frame,
            stats ? stats : "\n");
    free(stats);
    assert_true(found >= nt * 98 / 100);
    assert_true(sum / found <= 0.3);
    assert_true(mx <= 2.0);
    free(r);
    free(t);
    /* the e check runs this build's stillheart warp and stillheart-eval, whose arithmetic has
     * tests of its own on arm64 and under ASan; here their minutes would say nothing more */
#if defined(__SANITIZE_ADDRESS__)
    return;
#endif
    if (getenv("SH_TEST_EMULATED")) return;
    double e_tr, g_tr, e_gt, g_gt;
    stabilize(mc->name, "tps", p, &e_tr, &g_tr);
    stabilize(mc->name, "tps", q, &e_gt, &g_gt);
    fprintf(stderr, "           tps: e %.5f (truth %.5f, %+.1f %%), geometric mean %.4f px (truth %.4f)\n", e_tr,
            e_gt, 100 * (e_tr / e_gt - 1), g_tr, g_gt);
    assert_true(e_tr <= 1.10 * e_gt);
}

/* The same sequence through the daemon: no frame shown stabilized or degraded from a marker more
 * than 2 px off the truth, raw while the camera moves, stabilized again within 5 frames of the
 * motion's end. */
static void daemon_case(const motion_case *mc, const char *on_motion)
{
    char args[2048], tr[512], tp[512], q[512];
    path(tr, sizeof tr, "trace.csv");
    path(tp, sizeof tp, "trace_points.csv");
    snprintf(args, sizeof args,
             "run --quiet --source 'y4m:%s/%s/cam0.y4m' --realtime=0 --loop=0 --sink none --method tps "
             "--ids 0-15 --on-camera-motion %s --trace '%s' --trace-points '%s'",
             tmp, mc->name, on_motion, tr, tp);
    assert_int_equal(app(args, "daemon"), 0);
    int n, nt;
    row *r = read_points(tp, "frame,id,x,y", &n);
    snprintf(q, sizeof q, "%s/%s/truth.csv", tmp, mc->name);
    row *t = read_points(q, "frame,id,x,y,X,Y,Z", &nt);
    int bad = 0;
    double mx = 0;
    for (int i = 0; i < n; i++) {
        const row *g = find_row(t, nt, r[i].frame, r[i].id);
        if (!g) continue; /* out of view: the map still needs it, nothing to compare */
        double e = hypot(r[i].x - g->x, r[i].y - g->y);
        mx = fmax(mx, e);
        if (e > 2.0) {
            if (bad++ < 5) fprintf(stderr, "  frame %d shown warped from marker %d %.2f px off the truth\n",
                                   r[i].frame, r[i].id, e);
        }
    }
    /* the statuses, frame by frame */
    char *text = slurp(tr, NULL);
    assert_non_null(text);
    /* 1 stabilized, 2 degraded, 3 raw; building[f]: raw while the helper thread built the model
     * its markers need, which takes as many frames as the machine is slow (under load, under
     * qemu-aarch64; a new reference after the camera moved is one): the time to stabilize again
     * is counted without those frames */
    int status[400] = {0}, building[400] = {0}, frames = 0, moving = 0, raw = 0;
    int end = (int)ceil(mc->end * MOTION_FPS - 1e-9), back = -1, waited = 0;
    for (char *line = strtok(strchr(text, '\n') + 1, "\n"); line; line = strtok(NULL, "\n")) {
        int idx;
        char st[16];
        if (sscanf(line, "%d,%15[a-z]", &idx, st) != 2 || idx < 0 || idx >= 400) continue;
        status[idx] = !strcmp(st, "stabilized") ? 1 : !strcmp(st, "degraded") ? 2 : 3;
        building[idx] = status[idx] == 3 && (strstr(line, " building\"") || strstr(line, "building the reference") ||
                                                strstr(line, "new reference ("));
        moving += strstr(line, "camera moving") != NULL;
        raw += status[idx] == 3;
        if (idx >= end && status[idx] != 1)
            fprintf(stderr, "    after the motion: %s\n", line); /* what kept it from stabilizing, should it fail */
        frames = idx + 1 > frames ? idx + 1 : frames;
    }
    free(text);
    for (int f = end; f < frames && back < 0; f++) {
        if (status[f] == 1) back = f - end - waited;
        waited += building[f];
    }
    fprintf(stderr, "  %-8s daemon (%s): %d frames, %d raw (%d 'camera moving'), warped from markers at most "
            "%.2f px off the truth, stabilized again %d frames after the motion's end (frame %d; %d more while a "
            "model was building)\n", mc->name, on_motion, frames, raw, moving, mx, back, end, waited);
    assert_int_equal(frames, mc->frames);
    assert_int_equal(bad, 0);
    assert_true(back >= 0 && back <= 5);
    free(r);
    free(t);
}

/* Under qemu-aarch64 (SH_TEST_EMULATED, tools/cross/run-lanes.sh) every case costs ten times as
 * long: the bump after the lock alone (the consensus, the camera flag, the history moved, a new
 * reference), without the warps of the e check, keeps this lane within the others' time; the
 * host suite runs them all. */
static int motion_first(void)
{
    return getenv("SH_TEST_EMULATED") ? NMOTIONS - 1 : 0;
}

static void test_motion_tracked(void **state)
{
    (void)state;
    if (!rendered) skip();
    for (int k = motion_first(); k < NMOTIONS; k++) track_case(&motions[k]);
}

static void test_motion_daemon(void **state)
{
    (void)state;
    if (!rendered) skip();
    for (int k = motion_first(); k < NMOTIONS; k++) daemon_case(&motions[k], "new");
    daemon_case(&motions[getenv("SH_TEST_EMULATED") ? NMOTIONS - 1 : 2], "keep");
}

/* Without --ids (issue 18): every heart marker of the render kept, its decoy (a tag on a card
 * beside the heart, not in markers.csv) never, a points file, and stderr naming what was left
 * out and why; on both presets with --occlusions, short (30 frames: before the rates lock) to
 * long (400). Seeds 1..SH_AUTO_IDS_SEEDS (default 1; `make check-auto-ids` runs 1-8). */
static int auto_ids_case(const char *preset, int frames, int seed)
{
    char dir[400], cmd[2048], p[512];
    snprintf(dir, sizeof dir, "%s/auto_%s_%d_%d", tmp, preset, frames, seed);
    snprintf(cmd, sizeof cmd, "'%s' --preset %s --frames %d --seed %d --occlusions --quiet --out '%s'",
             RENDER_BIN, preset, frames, seed, dir);
    assert_int_equal(system(cmd), 0);
    /* the truth: the heart markers' ids (markers.csv) and the decoy's (phantom.txt) */
    int heart[SH_TEST_MAX_IDS] = {0}, decoy = -1, kept[SH_TEST_MAX_IDS] = {0};
    snprintf(p, sizeof p, "%s/markers.csv", dir);
    FILE *f = fopen(p, "r");
    assert_non_null(f);
    char line[512];
    while (fgets(line, sizeof line, f)) {
        int fr, cam, id;
        if (sscanf(line, "%d,%d,%d", &fr, &cam, &id) == 3 && id >= 0 && id < SH_TEST_MAX_IDS) heart[id] = 1;
    }
    fclose(f);
    snprintf(p, sizeof p, "%s/phantom.txt", dir);
    f = fopen(p, "r");
    assert_non_null(f);
    while (fgets(line, sizeof line, f)) sscanf(line, "decoy_id %d", &decoy);
    fclose(f);
    assert_true(decoy >= 0 && decoy < SH_TEST_MAX_IDS && !heart[decoy]);
    snprintf(cmd, sizeof cmd, "track '%s/cam0.y4m'", dir);
    assert_int_equal(app(cmd, "auto"), 0);
    path(p, sizeof p, "auto.out");
    int n;
    row *r = read_points(p, "frame,id,x,y", &n);
    assert_true(n > 0);
    for (int i = 0; i < n; i++)
        if (r[i].id >= 0 && r[i].id < SH_TEST_MAX_IDS) kept[r[i].id] = 1;
    free(r);
    int missing = 0, nheart = 0, nkept = 0;
    for (int id = 0; id < SH_TEST_MAX_IDS; id++) {
        nheart += heart[id];
        nkept += kept[id];
        if (heart[id] && !kept[id]) {
            fprintf(stderr, "  %s %d frames seed %d: heart marker %d left out\n", preset, frames, seed, id);
            missing++;
        }
    }
    fprintf(stderr, "  %s %3d frames seed %d: kept %d of %d heart markers, decoy %d %s\n", preset, frames, seed,
            nkept - kept[decoy], nheart, decoy, kept[decoy] ? "KEPT" : "left out");
    char why[64];
    snprintf(why, sizeof why, "tag %d left out", decoy);
    int said = stderr_has(why) && stderr_has("not on the heart") && stderr_has("markers found in");
    return !missing && !kept[decoy] && said;
}

static void test_auto_ids(void **state)
{
    (void)state;
    if (access(RENDER_BIN, X_OK) != 0) skip();
    static const char *presets[] = {"exvivo", "invivo"};
    static const int lengths[] = {30, 120, 400};
    const char *env = getenv("SH_AUTO_IDS_SEEDS");
    int seeds = env ? atoi(env) : 1, failed = 0;
    if (seeds < 1) seeds = 1;
    for (int s = 1; s <= seeds; s++)
        for (int p = 0; p < 2; p++)
            for (int l = 0; l < 3; l++) {
                /* emulated (SH_TEST_EMULATED): the 120-frame case only, on one preset */
                if (getenv("SH_TEST_EMULATED") && (p != 0 || lengths[l] != 120)) continue;
#ifdef __SANITIZE_ADDRESS__
                /* the ASan+UBSan build: the 400-frame renders and tracks reach no code the
                 * 30- and 120-frame ones do not, at several times their cost there */
                if (lengths[l] == 400 && !env) continue;
#endif
                failed += !auto_ids_case(presets[p], lengths[l], s);
                /* the renders are 10-140 MB: one at a time */
                char cmd[600];
                snprintf(cmd, sizeof cmd, "rm -rf '%s'/auto_*", tmp);
                assert_int_equal(system(cmd), 0);
            }
    assert_int_equal(failed, 0);
}

int main(void)
{
    /* the sweep alone (make check-auto-ids) */
    const struct CMUnitTest sweep[] = {cmocka_unit_test(test_auto_ids)};
    if (getenv("SH_AUTO_IDS_SEEDS")) return cmocka_run_group_tests(sweep, setup_tmp, teardown);
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_options_and_refusals),
        cmocka_unit_test(test_points_2d),
        cmocka_unit_test(test_points_3d),
        cmocka_unit_test(test_stabilize_within_ten_percent),
        cmocka_unit_test(test_motion_tracked),
        cmocka_unit_test(test_motion_daemon),
        cmocka_unit_test(test_auto_ids),
    };
    return cmocka_run_group_tests(tests, setup, teardown);
}
