/* stillheart-vmprobe loopback OUT CAP DIR: the daemon's [sink] v4l2 against the real v4l2loopback
 * driver (tests/vm/run.sh loads it with exclusive_caps=1 max_width=320 max_height=180
 * max_buffers=8, the node OUT), a capture client of our own reading the frames back as OBS or
 * GStreamer's v4l2src would (mmap streaming, VIDIOC_DQBUF). DIR (made on the host) holds in.y4m,
 * a 320x180 23 fps phantom render, its points file points.csv, warp.y4m (`stillheart warp
 * --method tps` of it, on the host), slow.y4m and gst.y4m (in.y4m at 10 and 2 fps). Judged:
 *   loop-not-output  CAP (vivid, capture only) refused at start, saying it has no video output;
 *   loop-no-reader   nobody reading: every frame written, none refused, the record byte for byte
 *                    warp.y4m (as test_daemon compares): an absent consumer holds nothing up;
 *   loop-capture     the daemon in real time on slow.y4m and a client that reads the first frames
 *                    at once, then one every 250 ms (slower than the 10 fps written): each frame
 *                    read back is byte for byte the record's (what the segment was given) frame
 *                    of the buffer's sequence number (v4l2loopback numbers the frames written from
 *                    0 once every opener has closed), the slow part sees gaps (the driver drops
 *                    for the reader, not the daemon for the driver), and the daemon wrote every
 *                    frame it showed, none refused;
 *   loop-gstreamer   GStreamer's v4l2src (gst-launch-1.0, when the host had it for the initramfs)
 *                    on the device while the daemon writes: every frame it hands its filesink is
 *                    byte for byte one the daemon recorded, in order (the README's pipeline);
 *   loop-reload      a SIGHUP that brings a camera of 160x96 frames: the device closed and opened
 *                    again with the new format (a reader gets 160x96), frames counted for each;
 *   loop-format      640x360 frames, over the device's max_width: refused, naming what it set. */
#include <errno.h>
#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/ioctl.h>
#include <sys/mman.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include <linux/videodev2.h>

#include "stillheart/y4m.h"
#include "vmprobe.h"

#define FW 320
#define FH 180
#define FSIZE (FW * FH * 3 / 2)
#define MAXCAP 64
#define NBUF 4

/* The frames of a Y4M file the daemon wrote (320x180 I420, "FRAME\n" headers); their count. */
static int read_frames(const char *path, uint8_t **out)
{
    FILE *f = fopen(path, "rb");
    if (!f) return -1;
    char line[256];
    if (!fgets(line, sizeof line, f) || !strstr(line, "W320 H180")) {
        fclose(f);
        return -1;
    }
    uint8_t *buf = NULL;
    int n = 0;
    for (;;) {
        if (!fgets(line, sizeof line, f) || strncmp(line, "FRAME", 5)) break;
        uint8_t *grown = realloc(buf, (size_t)(n + 1) * FSIZE);
        if (!grown) break;
        buf = grown;
        if (fread(buf + (size_t)n * FSIZE, 1, FSIZE, f) != FSIZE) break;
        n++;
    }
    fclose(f);
    *out = buf;
    return n;
}

static int run_wait(char *const argv[], const char *log)
{
    pid_t pid = spawn(argv, "/dev/null", log);
    int status = 0;
    if (waitpid(pid, &status, 0) != pid) return -1;
    return WIFEXITED(status) ? WEXITSTATUS(status) : 128;
}

static int same_file(const char *a, const char *b)
{
    uint8_t *fa = NULL, *fb = NULL;
    int na = read_frames(a, &fa), nb = read_frames(b, &fb);
    int same = na > 0 && na == nb && !memcmp(fa, fb, (size_t)na * FSIZE);
    free(fa);
    free(fb);
    return same ? na : -1;
}

/* A capture client: STREAMON on OUT once a writer has written (EIO before), then DQBUF until
 * nothing comes for 1.5 s after the daemon ended. The first `fast` frames are read at once, the
 * others 250 ms apart. Sequence numbers and bytes into seq/frames; the count, or -1 with why. */
static int capture(const char *out, pid_t daemon, int *status, int fast, uint32_t *seq, uint8_t *frames, char *why,
                   size_t cap)
{
    int fd = -1, n = 0, ended = 0;
    void *map[NBUF] = {0};
    size_t len[NBUF] = {0};
    struct timespec nap = {0, 50000000};
    for (int tries = 0; fd < 0 && tries < 400; tries++) {
        if (!ended && waitpid(daemon, status, WNOHANG) == daemon) ended = 1;
        fd = open(out, O_RDWR | O_NONBLOCK);
        struct v4l2_format f = {.type = V4L2_BUF_TYPE_VIDEO_CAPTURE};
        struct v4l2_requestbuffers rb = {.count = NBUF, .type = V4L2_BUF_TYPE_VIDEO_CAPTURE, .memory = V4L2_MEMORY_MMAP};
        int type = V4L2_BUF_TYPE_VIDEO_CAPTURE, ok = fd >= 0 && ioctl(fd, VIDIOC_G_FMT, &f) == 0 &&
            f.fmt.pix.width == FW && f.fmt.pix.height == FH && f.fmt.pix.pixelformat == V4L2_PIX_FMT_YUV420 &&
            ioctl(fd, VIDIOC_REQBUFS, &rb) == 0 && rb.count >= 2;
        for (unsigned i = 0; ok && i < rb.count && i < NBUF; i++) {
            struct v4l2_buffer b = {.index = i, .type = V4L2_BUF_TYPE_VIDEO_CAPTURE, .memory = V4L2_MEMORY_MMAP};
            ok = ioctl(fd, VIDIOC_QUERYBUF, &b) == 0 &&
                 (map[i] = mmap(NULL, b.length, PROT_READ, MAP_SHARED, fd, b.m.offset)) != MAP_FAILED &&
                 ioctl(fd, VIDIOC_QBUF, &b) == 0;
            len[i] = b.length;
            if (map[i] == MAP_FAILED) map[i] = NULL;
        }
        if (ok && ioctl(fd, VIDIOC_STREAMON, &type) == 0) break;
        for (int i = 0; i < NBUF; i++)
            if (map[i]) munmap(map[i], len[i]), map[i] = NULL;
        if (fd >= 0) close(fd);
        fd = -1;
        if (ended) break;
        nanosleep(&nap, NULL);
    }
    if (fd < 0) {
        snprintf(why, cap, "no capture stream from %s (daemon %s)", out, ended ? "ended" : "running");
        return -1;
    }
    while (n < MAXCAP) {
        if (!ended && waitpid(daemon, status, WNOHANG) == daemon) ended = 1;
        struct pollfd p = {fd, POLLIN, 0};
        if (poll(&p, 1, ended ? 1500 : 3000) <= 0) {
            if (ended) break;
            continue;
        }
        struct v4l2_buffer b = {.type = V4L2_BUF_TYPE_VIDEO_CAPTURE, .memory = V4L2_MEMORY_MMAP};
        if (ioctl(fd, VIDIOC_DQBUF, &b) != 0) {
            if (errno == EAGAIN) continue;
            snprintf(why, cap, "DQBUF: %s", strerror(errno));
            n = -1;
            break;
        }
        /* a frame read again (the driver repeats the newest when asked before a new one) is skipped */
        if (b.index < NBUF && map[b.index] && b.bytesused >= FSIZE && (!n || b.sequence != seq[n - 1])) {
            seq[n] = b.sequence;
            memcpy(frames + (size_t)n * FSIZE, map[b.index], FSIZE);
            n++;
        } else if (b.bytesused < FSIZE) {
            snprintf(why, cap, "a buffer of %u bytes, not %d", b.bytesused, FSIZE);
            n = -1;
            break;
        }
        ioctl(fd, VIDIOC_QBUF, &b);
        if (n > fast) {
            struct timespec slow = {0, 250000000};
            nanosleep(&slow, NULL);
        }
    }
    int type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    ioctl(fd, VIDIOC_STREAMOFF, &type);
    for (int i = 0; i < NBUF; i++)
        if (map[i]) munmap(map[i], len[i]);
    close(fd);
    if (!ended) waitpid(daemon, status, 0);
    return n;
}

/* The line of log where what starts, for the report. */
static const char *line_of(const char *log, const char *what, char *out, size_t cap)
{
    const char *at = strstr(log, what);
    if (!at) return log;
    while (at > log && at[-1] != '\n') at--;
    size_t n = strcspn(at, "\n");
    snprintf(out, cap, "%.*s", (int)(n < cap ? n : cap - 1), at);
    return out;
}

/* The width of the frames the device gives a reader once a writer wrote, 0 before: with
 * exclusive_caps=1 it announces a capture side only then (G_FMT answers with the last format
 * even when nobody writes). */
static int capture_width(const char *out)
{
    int fd = open(out, O_RDWR | O_NONBLOCK);
    struct v4l2_capability cap = {0};
    struct v4l2_format f = {.type = V4L2_BUF_TYPE_VIDEO_CAPTURE};
    int w = fd >= 0 && ioctl(fd, VIDIOC_QUERYCAP, &cap) == 0 && (cap.device_caps & V4L2_CAP_VIDEO_CAPTURE) &&
                    ioctl(fd, VIDIOC_G_FMT, &f) == 0 ? (int)f.fmt.pix.width : 0;
    if (fd >= 0) close(fd);
    return w;
}

static int capture_ready(const char *out) { return capture_width(out) == FW; }

/* gst-launch-1.0 v4l2src ! filesink while the daemon writes; the frames matched to the record. */
static void gstreamer_check(const char *out, const char *dir)
{
    if (access("/bin/gst-launch-1.0", X_OK)) {
        printf("VMTEST INFO loop-gstreamer: no gst-launch-1.0 in the initramfs (the host has none): not run\n");
        return;
    }
    char src[200], pts[200], dev[200];
    /* 2 frames/s: v4l2loopback lets the writer overwrite a buffer a reader still holds once it is
     * max_buffers (8) frames behind, which a gst-launch starting under emulation can be at 10 */
    snprintf(src, sizeof src, "y4m:%s/gst.y4m", dir);
    snprintf(pts, sizeof pts, "%s/points.csv", dir);
    snprintf(dev, sizeof dev, "device=%s", out);
    /* looping, stopped once gst-launch is done: its start under emulation takes seconds */
    char *argv[] = {"/bin/stillheart", "run", "--group=", "--source", src, "--loop", "--realtime", "--sink", "none",
                    "--points", pts, "--method", "tps", "--threads", "2", "--min-markers", "3", "--record",
                    "/tmp/loop-g.y4m", "--v4l2", (char *)out, NULL};
    char *gst[] = {"/bin/gst-launch-1.0", "-q", "v4l2src", dev, "num-buffers=6", "!",
                   "video/x-raw,format=I420,width=320,height=180", "!", "filesink", "location=/tmp/gst.yuv", NULL};
    /* the plugins in the initramfs only, scanned in this process (no gst-plugin-scanner) */
    setenv("GST_PLUGIN_SYSTEM_PATH_1_0", "/gst", 1);
    setenv("GST_REGISTRY_1_0", "/tmp/gst-registry.bin", 1);
    setenv("GST_REGISTRY_FORK", "no", 1);
    int status = 0, gst_status = 0;
    pid_t pid = spawn(argv, "/dev/null", "/tmp/loop-g.log");
    struct timespec nap = {0, 50000000};
    for (int i = 0; i < 400 && !capture_ready(out) && waitpid(pid, &status, WNOHANG) != pid; i++) nanosleep(&nap, NULL);
    pid_t g = spawn(gst, "/tmp/gst.out", "/tmp/gst.err");
    waitpid(g, &gst_status, 0);
    kill(pid, SIGTERM);
    waitpid(pid, &status, 0);
    uint8_t *rec = NULL, *got = NULL;
    int nrec = read_frames("/tmp/loop-g.y4m", &rec), n = 0, matched = 0, k = 0, distinct = 0;
    char which[96] = "";
    FILE *f = fopen("/tmp/gst.yuv", "rb");
    /* in order; the same frame twice is allowed (v4l2loopback gives a reader that asks before the
     * next write the newest frame again) */
    if (f && (got = malloc(FSIZE)))
        for (int last = -1; fread(got, 1, FSIZE, f) == FSIZE; n++) {
            int from = k;
            while (k < nrec && memcmp(got, rec + (size_t)k * FSIZE, FSIZE)) k++;
            if (k < nrec) matched++, distinct += k != last, last = k;
            else k = from;
            size_t at = strlen(which);
            snprintf(which + at, sizeof which - at, "%s%d", at ? "," : "", k < nrec ? k : -1);
        }
    if (f) fclose(f);
    free(rec);
    free(got);
    int gst_ok = WIFEXITED(gst_status) && WEXITSTATUS(gst_status) == 0;
    result(gst_ok && n == 6 && matched == n && distinct >= 2 && WIFEXITED(status) && WEXITSTATUS(status) == 0,
           "loop-gstreamer", "gst-launch-1.0 v4l2src %s ! filesink: %d frames, %d byte for byte recorded frames in order "
           "(record frames %s: %d different; %d recorded); gst-launch %s%.200s", out, n, matched, which, distinct, nrec,
           gst_ok ? "exit 0" : "failed: ", gst_ok ? "" : slurp("/tmp/gst.err"));
}

/* Two grey frames of w x h in path. */
static int grey_input(const char *path, int width, int height)
{
    sh_y4m_header h = {.width = width, .height = height, .format = SH_PIX_I420, .fps_num = 10, .fps_den = 1};
    sh_y4m_writer *wr;
    sh_image img;
    if (sh_y4m_writer_open(path, &h, &wr) != SH_OK) return -1;
    int ok = sh_image_create(&img, SH_PIX_I420, width, height) == SH_OK;
    if (ok) {
        sh_image_clear(&img);
        ok = sh_y4m_writer_write(wr, &img) == SH_OK && sh_y4m_writer_write(wr, &img) == SH_OK;
        sh_image_destroy(&img);
    }
    return sh_y4m_writer_close(wr) == SH_OK && ok ? 0 : -1;
}

static int write_ini(const char *path, const char *spec)
{
    FILE *f = fopen(path, "w");
    if (!f) return -1;
    fprintf(f, "[camera0]\nspec = %s\n[source]\nrealtime = 1\nloop = 1\n[sink]\ndisplay = none\n"
               "v4l2 = /dev/video10\n[gating]\nmin_markers = 3\n", spec);
    return fclose(f);
}

static int log_says(const char *path, const char *what, int seconds)
{
    struct timespec nap = {0, 100000000};
    for (int i = 0; i < seconds * 10; i++, nanosleep(&nap, NULL))
        if (strstr(slurp(path), what)) return 1;
    return 0;
}

/* SIGHUP to a config whose camera gives other frames: the same device reopened with them. */
static void reload_check(const char *out, const char *dir)
{
    char spec[200], line[400];
    snprintf(spec, sizeof spec, "y4m:%s/slow.y4m", dir);
    if (strcmp(out, "/dev/video10") || grey_input("/tmp/small.y4m", 160, 96) || write_ini("/tmp/loop.ini", spec))
        return result(0, "loop-reload", "cannot write its input (or the device is not /dev/video10)");
    char *argv[] = {"/bin/stillheart", "run", "--group=", "--config", "/tmp/loop.ini", NULL};
    pid_t pid = spawn(argv, "/dev/null", "/tmp/loop-h.log");
    struct timespec nap = {0, 50000000};
    int status = 0, before = 0, after = 0, i;
    for (i = 0; i < 400 && (before = capture_width(out)) != FW; i++) nanosleep(&nap, NULL);
    log_says("/tmp/loop-h.log", "[sink] v4l2: publishing", 20); /* its signal handlers are in place */
    write_ini("/tmp/loop.ini", "y4m:/tmp/small.y4m");
    kill(pid, SIGHUP);
    int applied = log_says("/tmp/loop-h.log", "config reloaded:", 20);
    for (i = 0; applied && i < 200 && (after = capture_width(out)) != 160; i++) nanosleep(&nap, NULL);
    kill(pid, SIGTERM);
    waitpid(pid, &status, 0);
    const char *log = slurp("/tmp/loop-h.log");
    int closes = 0;
    for (const char *p = log; (p = strstr(p, "frames written, 0 not taken")); p++) closes++;
    const char *want = "cameras reopened (320x180 i420 -> 160x96 i420)";
    result(before == FW && after == 160 && strstr(log, want) && strstr(log, "v4l2 /dev/video10 opened again") &&
           closes == 2 && WIFEXITED(status) && WEXITSTATUS(status) == 0, "loop-reload",
           "a reader got %d px wide frames before, %d after; %d closes counted; exit %d; %s", before, after, closes,
           WIFEXITED(status) ? WEXITSTATUS(status) : -1,
           line_of(log, applied ? "config reloaded:" : "reload refused", line, sizeof line));
}

static void captured_check(const char *out, const char *dir)
{
    char src[200], pts[200], want[200];
    snprintf(src, sizeof src, "y4m:%s/slow.y4m", dir);
    snprintf(pts, sizeof pts, "%s/points.csv", dir);
    char *argv[] = {"/bin/stillheart", "run", "--group=", "--source", src, "--no-loop", "--realtime", "--sink", "none",
                    "--points", pts, "--method", "tps", "--threads", "2", "--min-markers", "3", "--record",
                    "/tmp/loop-b.y4m", "--v4l2", (char *)out, "--stats", NULL};
    static uint8_t frames[(size_t)MAXCAP * FSIZE];
    uint32_t seq[MAXCAP];
    char why[200] = "";
    int status = 0;
    pid_t pid = spawn(argv, "/dev/null", "/tmp/loop-b.log");
    int n = capture(out, pid, &status, 8, seq, frames, why, sizeof why);
    uint8_t *rec = NULL;
    int nrec = read_frames("/tmp/loop-b.y4m", &rec), equal = 0, rising = 1, gaps = 0, late_gaps = 0;
    for (int i = 0; i < n; i++) {
        if (i && seq[i] <= seq[i - 1]) rising = 0;
        if (i && seq[i] > seq[i - 1] + 1) gaps++, late_gaps += i > 8;
        if ((int)seq[i] < nrec && !memcmp(frames + (size_t)i * FSIZE, rec + (size_t)seq[i] * FSIZE, FSIZE)) equal++;
    }
    free(rec);
    snprintf(want, sizeof want, "[sink] v4l2: %s: %d frames written, 0 not taken by the device", out, nrec);
    const char *log = slurp("/tmp/loop-b.log");
    int exited = WIFEXITED(status) && WEXITSTATUS(status) == 0;
    if (n < 0) return result(0, "loop-capture", "%s", why);
    result(exited && n >= 10 && equal == n && rising && late_gaps > 0 && strstr(log, want), "loop-capture",
           "%d frames read back (sequence %u..%u, %d gaps, %d of them while reading slowly), %d byte for byte the "
           "record's frame of their sequence number, of %d recorded; daemon %s; %s", n, n ? seq[0] : 0,
           n ? seq[n - 1] : 0, gaps, late_gaps, equal, nrec, exited ? "exit 0" : "failed",
           strstr(log, want) ? want : log);
}

void loopback_check(const char *out, const char *cap_dev, const char *dir)
{
    char src[200], pts[200], warp[200], want[300], line[400];
    snprintf(src, sizeof src, "y4m:%s/in.y4m", dir);
    snprintf(pts, sizeof pts, "%s/points.csv", dir);
    snprintf(warp, sizeof warp, "%s/warp.y4m", dir);

    char *refuse[] = {"/bin/stillheart", "run", "--group=", "--source", src, "--no-loop", "--no-realtime", "--sink", "none",
                      "--points", pts, "--min-markers", "3", "--v4l2", (char *)cap_dev, NULL};
    int rc = run_wait(refuse, "/tmp/loop-r.log");
    snprintf(want, sizeof want, "[sink] v4l2: %s: not a V4L2 output device (", cap_dev);
    const char *log = slurp("/tmp/loop-r.log");
    result(rc != 0 && strstr(log, want) && strstr(log, "has no video output"), "loop-not-output", "exit %d: %s", rc,
           line_of(log, want, line, sizeof line));

    char *quiet[] = {"/bin/stillheart", "run", "--group=", "--source", src, "--no-loop", "--no-realtime", "--sink", "none",
                     "--points", pts, "--method", "tps", "--threads", "2", "--min-markers", "3", "--record",
                     "/tmp/loop-a.y4m", "--v4l2", (char *)out, NULL};
    rc = run_wait(quiet, "/tmp/loop-a.log");
    int same = same_file("/tmp/loop-a.y4m", warp);
    snprintf(want, sizeof want, "[sink] v4l2: %s: %d frames written, 0 not taken by the device", out, same);
    log = slurp("/tmp/loop-a.log");
    result(rc == 0 && same > 0 && strstr(log, want), "loop-no-reader",
           "exit %d, record %s stillheart warp's (%d frames), %s", rc, same > 0 ? "byte for byte" : "differs from", same,
           strstr(log, want) ? want : log);

    captured_check(out, dir);
    gstreamer_check(out, dir);
    reload_check(out, dir);

    if (grey_input("/tmp/big.y4m", 640, 360) != 0) return result(0, "loop-format", "cannot write /tmp/big.y4m");
    char *big[] = {"/bin/stillheart", "run", "--group=", "--source", "y4m:/tmp/big.y4m", "--no-loop", "--no-realtime",
                   "--sink", "none", "--v4l2", (char *)out, NULL};
    rc = run_wait(big, "/tmp/loop-f.log");
    snprintf(want, sizeof want, "[sink] v4l2: %s: format 640x360 YU12 refused: the device sets 320x180 YU12", out);
    log = slurp("/tmp/loop-f.log");
    result(rc != 0 && strstr(log, want), "loop-format", "exit %d: %s", rc, line_of(log, want, line, sizeof line));
}
