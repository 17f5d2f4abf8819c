/* The daemon as a module (daemon.h), driven in-process as `stillheart run` drives it: a refused
 * trace file names itself and leaves nothing open; a replay of frames without markers publishes
 * max_frames raw frames; a stop flag set before the loop publishes nothing; a reload whose config
 * cannot be read is refused and the loop goes on; a [method] no model can come from on these
 * frames is refused at start and at a reload, naming its file and line; a Y4M record names its
 * method in its header and keeps it across reloads; [sink] v4l2 refuses what is not a V4L2 output; [source] queue_ms
 * keeps the sets a processing stall spans in order while they are recent (the cameras alone,
 * run_source.h). The counts come from the input (N frames, no markers in them, max_frames), read
 * back through the stats line. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <errno.h>
#include <fcntl.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include <cmocka.h>

#include "stillheart/daemon.h"
#include "stillheart/image.h"
#include "stillheart/log.h"
#include "stillheart/y4m.h"
#include "../../src/daemon/run_sink.h"
#include "../../src/daemon/run_source.h"

#define W 64
#define H 48
#define N 8

static char tmp[64], video[128];

static int cmp_double(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

/* n grey gradient frames at fps: nothing a detector could take for a marker. */
static int write_video(const char *path, int fps, int n)
{
    sh_y4m_header h;
    memset(&h, 0, sizeof h);
    h.width = W;
    h.height = H;
    h.format = SH_PIX_I420;
    h.fps_num = fps;
    h.fps_den = 1;
    sh_y4m_writer *wr;
    if (sh_y4m_writer_open(path, &h, &wr) != SH_OK) return -1;
    sh_image img;
    if (sh_image_create(&img, SH_PIX_I420, W, H) != SH_OK) return -1;
    for (int k = 0; k < n; k++) {
        for (int p = 0; p < 3; p++)
            for (int y = 0; y < img.plane[p].height; y++)
                memset(img.plane[p].data + y * img.plane[p].stride, (k * 9 + y) & 255, (size_t)img.plane[p].width);
        if (sh_y4m_writer_write(wr, &img) != SH_OK) return -1;
    }
    sh_image_destroy(&img);
    return sh_y4m_writer_close(wr) == SH_OK ? 0 : -1;
}

static int setup(void **state)
{
    (void)state;
    snprintf(tmp, sizeof tmp, "/tmp/sh-test-dmod-%d", (int)getpid());
    if (mkdir(tmp, 0700)) return -1;
    snprintf(video, sizeof video, "%s/cam0.y4m", tmp);
    sh_log_setup(SH_LOG_DAEMON, "test_daemon_module", SH_LOG_WARN);
    return write_video(video, 25, N);
}

static int teardown(void **state)
{
    (void)state;
    unlink(video);
    char plain[160]; /* test_v4l2_refusals' file, left when it failed: one failure, not two */
    snprintf(plain, sizeof plain, "%s/plain", tmp);
    unlink(plain);
    return rmdir(tmp);
}

/* The replay's config, then extra (INI text, "hup.ini") over it. */
static sh_status config_with(sh_config *cfg, const char *extra, char *err)
{
    char ini[512];
    snprintf(ini, sizeof ini, "[camera0]\nspec = y4m:%s\n[source]\nrealtime = 0\nloop = 0\n[sink]\ndisplay = none\n"
             "[run]\ncontrol =\n", video);
    sh_config_default(cfg);
    assert_int_equal(sh_config_parse_string(cfg, ini, "test", err), SH_OK);
    sh_status st = sh_config_parse_string(cfg, extra, "hup.ini", err);
    return st == SH_OK ? sh_config_check(cfg, err) : st;
}

static void config(sh_config *cfg)
{
    char err[SH_CONFIG_ERR];
    assert_int_equal(config_with(cfg, "", err), SH_OK);
}

static int loads;
static sh_status refuse_load(void *ctx, sh_config *fresh, char *err)
{
    (void)fresh;
    assert_ptr_equal(ctx, &loads);
    loads++;
    snprintf(err, SH_CONFIG_ERR, "test: no config today");
    return SH_EINVAL;
}

/* Runs a daemon over the replay; returns the stats line. */
static void run(const sh_daemon_options *o, sh_daemon_signals *sig, char *stats, size_t cap)
{
    sh_config cfg;
    config(&cfg);
    sh_daemon *d = NULL;
    assert_int_equal(sh_daemon_create(&cfg, o, &d), SH_OK);
    assert_int_equal(sh_daemon_start(d), SH_OK);
    assert_int_equal(sh_daemon_run(d, sig), SH_OK);
    sh_daemon_stats(d, stats, cap);
    assert_int_equal(sh_daemon_destroy(d), SH_OK);
}

static void test_trace_refused(void **state)
{
    (void)state;
    sh_config cfg;
    config(&cfg);
    sh_daemon_options o = {.trace_path = "/nonexistent-dir/trace.csv"};
    sh_daemon *d = (sh_daemon *)&o; /* must be reset */
    assert_int_equal(sh_daemon_create(&cfg, &o, &d), SH_EIO);
    assert_null(d);
    assert_string_equal(sh_error_message(), "--trace: /nonexistent-dir/trace.csv: No such file or directory");
}

static void test_max_frames(void **state)
{
    (void)state;
    char stats[512];
    sh_daemon_signals sig = {0};
    sh_daemon_options o = {.max_frames = 3};
    run(&o, &sig, stats, sizeof stats);
    assert_memory_equal(stats, "stats: 3 published (3 raw, 0 degraded), 0 dropped,", 50);
    /* grey frames without markers: nothing to lock the rates on */
    const char *tail = ", the tracker's rates not locked";
    assert_string_equal(stats + strlen(stats) - strlen(tail), tail);
}

static void test_stop_before(void **state)
{
    (void)state;
    char stats[512];
    sh_daemon_signals sig = {.stop = 1};
    sh_daemon_options o = {0};
    run(&o, &sig, stats, sizeof stats);
    assert_memory_equal(stats, "stats: 0 published (0 raw, 0 degraded)", 38);
}

static void test_reload_refused(void **state)
{
    (void)state;
    char stats[512];
    loads = 0;
    sh_daemon_signals sig = {.reload = 1};
    sh_daemon_options o = {.max_frames = 2, .load = refuse_load, .load_ctx = &loads};
    run(&o, &sig, stats, sizeof stats);
    assert_int_equal(loads, 1);
    assert_int_equal(sig.reload, 0);
    assert_memory_equal(stats, "stats: 2 published (2 raw, 0 degraded)", 38);
}

/* SIGHUP's config: the replay's with this text over it. */
static const char *hup_text;
static sh_status load_hup(void *ctx, sh_config *fresh, char *err)
{
    (void)ctx;
    return config_with(fresh, hup_text, err);
}

/* Runs a daemon started on start_text (over the replay's config) that reloads hup_text at its
 * first frame and publishes 2; returns its log (stderr) in log. */
static void run_reload(const char *start_text, const char *hup, char *log, size_t cap)
{
    char path[160], err[SH_CONFIG_ERR], stats[512];
    snprintf(path, sizeof path, "%s/log", tmp);
    hup_text = hup;
    fflush(stderr);
    int saved = dup(2), fd = open(path, O_WRONLY | O_CREAT | O_TRUNC, 0600);
    assert_true(saved >= 0 && fd >= 0);
    dup2(fd, 2);
    close(fd);
    sh_log_set_level(SH_LOG_INFO); /* "config reloaded" */
    sh_config cfg;
    assert_int_equal(config_with(&cfg, start_text, err), SH_OK);
    sh_daemon_signals sig = {.reload = 1};
    sh_daemon_options o = {.max_frames = 2, .load = load_hup};
    sh_daemon *d = NULL;
    assert_int_equal(sh_daemon_create(&cfg, &o, &d), SH_OK);
    assert_int_equal(sh_daemon_start(d), SH_OK);
    assert_int_equal(sh_daemon_run(d, &sig), SH_OK);
    sh_daemon_stats(d, stats, sizeof stats);
    assert_int_equal(sh_daemon_destroy(d), SH_OK);
    sh_log_set_level(SH_LOG_WARN);
    fflush(stderr);
    dup2(saved, 2);
    close(saved);
    assert_memory_equal(stats, "stats: 2 published (2 raw, 0 degraded)", 38);
    FILE *f = fopen(path, "r");
    assert_non_null(f);
    size_t n = fread(log, 1, cap - 1, f);
    log[n] = 0;
    fclose(f);
    unlink(path);
}

/* Issue 16: a [method] that no model can come from on these 64x48 frames, even with [gating]
 * min_markers markers spread evenly over them, is refused at start (SH_EINVAL: `stillheart run`
 * exits 2) and at a reload (the running config kept), naming the file and line. The Gaussian's
 * bounds here: with 6 markers its system is singular from sigma 1e4 (rcond < 1e-15), not at 3000;
 * with 16 from 316, not at 100 (measured with sh_interp_create on that layout). A reload that
 * changes only min_markers is checked as well. */
static void test_model_the_frames_cannot_give(void **state)
{
    (void)state;
    char err[SH_CONFIG_ERR], log[8192];
    sh_config cfg;
    assert_int_equal(config_with(&cfg, "[method]\nname = gaussian\nsigma = 1e4\n", err), SH_OK);
    sh_daemon_options o = {0};
    sh_daemon *d = NULL;
    assert_int_equal(sh_daemon_create(&cfg, &o, &d), SH_EINVAL);
    assert_null(d);
    const char *want = "hup.ini:3: [method] sigma: no model on 64x48 frames, not even from [gating] min_markers = 6 "
                       "markers spread evenly over the frame: gaussian: the interpolation system is singular";
    if (strncmp(sh_error_message(), want, strlen(want))) fail_msg("got '%s'", sh_error_message());

    run_reload("", "[method]\nname = gaussian\nsigma = 1e6\n", log, sizeof log);
    if (!strstr(log, "reload refused, keeping the running config: hup.ini:3: [method] sigma: no model on 64x48 frames"))
        fail_msg("sigma 1e6 reload: %s", log);
    run_reload("[method]\nname = gaussian\nsigma = 1000\n",
               "[method]\nname = gaussian\nsigma = 1000\n[gating]\nmin_markers = 16\n", log, sizeof log);
    if (!strstr(log, "reload refused, keeping the running config: hup.ini:3: [method] sigma: no model on 64x48 "
                     "frames, not even from [gating] min_markers = 16 markers"))
        fail_msg("min_markers 16 reload: %s", log);
    /* the nearest valid values: applied */
    run_reload("", "[method]\nname = gaussian\nsigma = 3000\n", log, sizeof log);
    if (strstr(log, "refused") || !strstr(log, "config reloaded: method tps -> gaussian, sigma -1 -> 3000"))
        fail_msg("sigma 3000 reload: %s", log);
    run_reload("[method]\nname = gaussian\nsigma = 100\n",
               "[method]\nname = gaussian\nsigma = 100\n[gating]\nmin_markers = 16\n", log, sizeof log);
    if (strstr(log, "refused") || !strstr(log, "config reloaded"))
        fail_msg("min_markers 16 at sigma 100 reload: %s", log);
}

/* The first line of a file, in line (cap bytes). */
static void first_line(const char *path, char *line, size_t cap)
{
    FILE *f = fopen(path, "rb");
    assert_non_null(f);
    assert_non_null(fgets(line, (int)cap, f));
    fclose(f);
}

/* Issue 18: a Y4M record names the method its frames are stabilized with (XSTILLHEART, as
 * `stillheart warp` tags its output) and keeps it: a reload to another method with the same
 * record is refused, the running config kept; with a new record name it is applied, the new
 * record naming the new method. */
static void test_record_names_its_method(void **state)
{
    (void)state;
    char start[256], hup[256], log[8192], line[256], rec[160];
    snprintf(rec, sizeof rec, "%s/rec.y4m", tmp);
    snprintf(start, sizeof start, "[method]\nname = tps\n[sink]\nrecord = %s\n", rec);
    snprintf(hup, sizeof hup, "[method]\nname = gaussian-pure\n[sink]\nrecord = %s\n", rec);
    run_reload(start, hup, log, sizeof log);
    if (!strstr(log, "reload refused, keeping the running config: [sink] record ") ||
        !strstr(log, "rec.y4m: its header says XSTILLHEART=method:tps, the frames from now on would be "
                     "method:gaussian-pure, and a record keeps one method"))
        fail_msg("same record, another method: %s", log);
    first_line(rec, line, sizeof line);
    assert_non_null(strstr(line, " XSTILLHEART=method:tps\n"));

    snprintf(hup, sizeof hup, "[method]\nname = gaussian-pure\n[sink]\nrecord = %s/rec-b.y4m\n", tmp);
    run_reload(start, hup, log, sizeof log);
    if (strstr(log, "refused") || !strstr(log, "config reloaded")) fail_msg("new record, another method: %s", log);
    snprintf(rec, sizeof rec, "%s/rec-b.y4m", tmp);
    first_line(rec, line, sizeof line);
    assert_non_null(strstr(line, " XSTILLHEART=method:gaussian-pure\n"));
    static const char *const made[] = {"rec.y4m", "rec-2.y4m", "rec-b.y4m"}; /* the second start: rec-2 */
    for (int i = 0; i < 3; i++) {
        snprintf(rec, sizeof rec, "%s/%s", tmp, made[i]);
        assert_int_equal(unlink(rec), 0);
    }
}

/* The refusal of a device that is not V4L2: the kernel answers VIDIOC_QUERYCAP on /dev/null with
 * ENOTTY; qemu-aarch64 (the aarch64 suite) passes no ioctl it does not know and answers ENOSYS.
 * Either is the refusal, said with the system's own words for it. */
static int not_v4l2(const char *msg, const char *prefix)
{
    char a[256], b[256];
    snprintf(a, sizeof a, "%s%s)", prefix, strerror(ENOTTY));
    snprintf(b, sizeof b, "%s%s)", prefix, strerror(ENOSYS));
    if (!strcmp(msg, a) || !strcmp(msg, b)) return 1;
    printf("  got: %s\n", msg);
    return 0;
}

/* Issue 17: [sink] v4l2 refuses, naming the key and saying which, what is not a V4L2 output
 * device: a missing path, a plain file, a device that is not V4L2 (/dev/null), frames V4L2 has no
 * single-buffer format for; at start (SH_EIO: a restart can mend a device that appears later,
 * v4l2loopback loaded after the daemon) and at a reload (the running config kept). A device
 * without a video output and a format the device changes need a V4L2 driver: make vmtest has
 * them (tools/capture/vmprobe_loop.c). */
static void test_v4l2_refusals(void **state)
{
    (void)state;
    char path[160], err[SH_CONFIG_ERR], log[8192];
    snprintf(path, sizeof path, "%s/plain", tmp);
    FILE *f = fopen(path, "w");
    assert_non_null(f);
    fclose(f);
    sh_y4m_header h;
    memset(&h, 0, sizeof h);
    h.width = W;
    h.height = H;
    h.format = SH_PIX_I420;
    run_v4l2out *o = (run_v4l2out *)&h; /* must be reset */
    assert_int_equal(run_v4l2out_open(path, &h, &o), SH_EINVAL);
    assert_null(o);
    if (!strstr(sh_error_message(), "/plain: not a device (a V4L2 output device such as a v4l2loopback /dev/videoN)"))
        fail_msg("plain file: %s", sh_error_message());
    assert_int_equal(run_v4l2out_open("/dev/null", &h, &o), SH_EINVAL);
    assert_true(not_v4l2(sh_error_message(), "/dev/null: not a V4L2 device (VIDIOC_QUERYCAP: "));
    assert_int_equal(run_v4l2out_open("/nonexistent/video9", &h, &o), SH_EIO);
    assert_string_equal(sh_error_message(), "/nonexistent/video9: No such file or directory");
    h.format = SH_PIX_YUV444;
    assert_int_equal(run_v4l2out_open("/dev/null", &h, &o), SH_EINVAL);
    assert_string_equal(sh_error_message(),
                        "/dev/null: yuv444 frames have no single-buffer V4L2 format (GRAY8, RGB24 and I420 do)");

    sh_config cfg;
    assert_int_equal(config_with(&cfg, "[sink]\nv4l2 = video0\n", err), SH_EINVAL);
    assert_string_equal(err, "[sink] v4l2: 'video0': want a device path, /dev/videoN");
    assert_int_equal(config_with(&cfg, "[sink]\nv4l2 = /dev/null\n", err), SH_OK);
    sh_daemon_options opt = {0};
    sh_daemon *d = NULL;
    assert_int_equal(sh_daemon_create(&cfg, &opt, &d), SH_EIO);
    assert_null(d);
    assert_true(not_v4l2(sh_error_message(), "[sink] v4l2: /dev/null: not a V4L2 device (VIDIOC_QUERYCAP: "));
    char hup[256];
    snprintf(hup, sizeof hup, "[sink]\nv4l2 = %s\n", path);
    run_reload("", hup, log, sizeof log);
    if (!strstr(log, "reload refused, keeping the running config: [sink] v4l2: ") || !strstr(log, "/plain: not a device"))
        fail_msg("reload to a plain file: %s", log);
    assert_int_equal(unlink(path), 0);
}

/* The cameras alone on a new 50 frames/s replay of n frames at path, in real time, started. */
static run_source *start_replay(const char *path, int n, int queue_ms)
{
    char ini[512], err[SH_CONFIG_ERR];
    assert_int_equal(write_video(path, 50, n), 0);
    snprintf(ini, sizeof ini, "[camera0]\nspec = y4m:%s\n[source]\nrealtime = 1\nloop = 0\nqueue_ms = %d\n",
             path, queue_ms);
    sh_config cfg;
    sh_config_default(&cfg);
    assert_int_equal(sh_config_parse_string(&cfg, ini, "test", err), SH_OK);
    run_source *rs;
    assert_int_equal(run_source_open(&cfg, &rs), SH_OK);
    assert_int_equal(run_source_start(rs), SH_OK);
    return rs;
}

/* [source] queue_ms, on the cameras alone: processing stalls 410 ms while a 50 frames/s replay
 * goes on in real time. With queue_ms = 100 the sets it then takes, back to back, are in capture
 * order without a gap, at most 1 + 100 / 20 = 6 of them, each but the newest captured at most
 * 100 ms before it was taken (the age is taken before the call: no later than the rule's); every
 * set before the first is counted dropped. With queue_ms = 0 it takes the newest set alone. The
 * bounds come from the replay's schedule (frame k at start + 20 k ms), not from the code. *taken
 * counts the sets already queued when the burst began (avail_ns): one queued during it was not
 * waiting. The capture time cannot say so: a replay's is its schedule, and under qemu-aarch64 a
 * loaded capture thread queues a set due before the burst after it began (two CI runs took 2
 * with queue_ms = 0, the second while the count still went by capture time). */
static void stall_and_take(int queue_ms, int *taken, int *first)
{
    char path[160];
    snprintf(path, sizeof path, "%s/fifty.y4m", tmp);
    run_source *rs = start_replay(path, 60, queue_ms);
    struct timespec pause = {0, 410000000}; /* frame 20 due 10 ms before: the ages are 10 ms off the bound */
    nanosleep(&pause, NULL);
    int index[64];
    double age_ms[64];
    int n = 0, waiting = 0;
    const int64_t burst = sh_monotonic_ns();
    for (; n < 64; n++) { /* the burst: every set waiting, back to back */
        int64_t before = sh_monotonic_ns();
        const run_frame *f = run_source_take(rs, 0);
        if (!f) break;
        index[n] = f->index;
        age_ms[n] = (double)(before - f->capture_ns) / 1e6;
        waiting += f->avail_ns < burst;
    }
    assert_true(n >= 1);
    for (int i = 1; i < n; i++) {
        if (index[i] != index[i - 1] + 1) fail_msg("set %d after set %d", index[i], index[i - 1]);
        /* another set waited when set i - 1 was taken: it was recent */
        if (queue_ms && age_ms[i - 1] > queue_ms)
            fail_msg("frame %d taken %.1f ms after its capture, another waiting", index[i - 1], age_ms[i - 1]);
    }
    *taken = waiting;
    *first = index[0];
    assert_int_equal(run_source_dropped(rs), (uint64_t)*first);
    run_source_destroy(rs);
    unlink(path);
}

static void test_queue_after_a_stall(void **state)
{
    (void)state;
    int taken, first;
    stall_and_take(100, &taken, &first);
    if (taken < 2 || taken > 6) fail_msg("%d sets taken after the stall, from frame %d", taken, first);
    assert_true(first >= 10); /* 410 ms: frame 20 is due, the queue holds 6 sets at most */
    stall_and_take(0, &taken, &first);
    assert_int_equal(taken, 1);
    assert_true(first >= 15);
}

/* [source] queue_ms while processing is slower than the camera for good: a queue would show every
 * set as late as queue_ms allows, so only the newest is taken until processing keeps up again.
 * A 50 frames/s replay (frame k due at start + 20 k ms), queue_ms = 300 (8 sets may wait):
 * processing takes 30 ms a set for 40 sets, then next to nothing for 25, then stalls 150 ms.
 * While slow, once the last sets' median says so (15 sets at most), each set taken is the newest:
 * the median age at take of sets 20-39 is under 60 ms (the period, and 40 ms for a loaded
 * machine; a queue that kept waiting sets would hold 8 and show them about 150 ms late). Once fast
 * again, a stall's sets wait in order as before: the burst after it is several consecutive sets. */
static void test_queue_not_while_behind(void **state)
{
    (void)state;
    char path[160];
    snprintf(path, sizeof path, "%s/behind.y4m", tmp);
    run_source *rs = start_replay(path, 150, 300);
    double age_ms[40];
    struct timespec slow = {0, 30000000};
    for (int i = 0; i < 40; i++) {
        const run_frame *f = run_source_take(rs, 1000);
        assert_non_null(f);
        age_ms[i] = (double)(sh_monotonic_ns() - f->capture_ns) / 1e6;
        nanosleep(&slow, NULL);
    }
    double late[20];
    memcpy(late, age_ms + 20, sizeof late);
    qsort(late, 20, sizeof *late, cmp_double);
    printf("  processing 30 ms a set at 20 ms a frame: sets 20-39 shown %.1f ms after capture (median), "
           "sets 0-4 %.1f %.1f %.1f %.1f %.1f\n", late[10], age_ms[0], age_ms[1], age_ms[2], age_ms[3], age_ms[4]);
    if (late[10] >= 60) fail_msg("processing behind: sets shown %.1f ms after capture (median)", late[10]);
    for (int i = 0; i < 25; i++) assert_non_null(run_source_take(rs, 1000));
    struct timespec stall = {0, 150000000};
    nanosleep(&stall, NULL);
    int index[16], n = 0;
    for (; n < 16; n++) {
        const run_frame *f = run_source_take(rs, 0);
        if (!f) break;
        index[n] = f->index;
    }
    for (int i = 1; i < n; i++)
        if (index[i] != index[i - 1] + 1) fail_msg("after the stall: set %d after set %d", index[i], index[i - 1]);
    if (n < 5) fail_msg("keeping up again, a 150 ms stall: %d sets waited in order", n);
    run_source_destroy(rs);
    unlink(path);
}

/* A replay without loop ends: the loop stops after its last frame, every frame published. */
static void test_replay_ends(void **state)
{
    (void)state;
    char stats[512], want[64];
    sh_daemon_signals sig = {0};
    sh_daemon_options o = {0};
    run(&o, &sig, stats, sizeof stats);
    int n = snprintf(want, sizeof want, "stats: %d published (%d raw, 0 degraded)", N, N);
    assert_memory_equal(stats, want, (size_t)n);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_trace_refused),
        cmocka_unit_test(test_max_frames),
        cmocka_unit_test(test_stop_before),
        cmocka_unit_test(test_reload_refused),
        cmocka_unit_test(test_replay_ends),
        cmocka_unit_test(test_queue_after_a_stall),
        cmocka_unit_test(test_queue_not_while_behind),
        cmocka_unit_test(test_model_the_frames_cannot_give),
        cmocka_unit_test(test_record_names_its_method),
        cmocka_unit_test(test_v4l2_refusals),
    };
    return cmocka_run_group_tests(tests, setup, teardown);
}
