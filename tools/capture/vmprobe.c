/* stillheart-vmprobe: stillheart's capture code against real kernel drivers, run inside the
 * QEMU guest of tests/vm/run.sh (vivid). Prints one line per check, "VMTEST PASS name ..." or
 * "VMTEST FAIL name: why", which the host script parses from the serial console.
 *
 *   stillheart-vmprobe formats DEV           each of GREY YUYV NV12 RGB24 BGR24 MJPEG the driver
 *                                            offers: frames, geometry, timestamps, conversion
 *   stillheart-vmprobe controls DEV          gain set and read back, exposure refused (vivid)
 *   stillheart-vmprobe errors DEV            buffers flagged erroneous skipped and counted
 *   stillheart-vmprobe sets DEV0 DEV1        frame sets from two devices
 *   stillheart-vmprobe loss DEV PLATDEV      unbind the driver mid-stream, rebind: reported,
 *                                            running on, resumed
 *   stillheart-vmprobe libcamera NAME WxH    libcamera (vimc): frames, geometry, timestamps
 *   stillheart-vmprobe gpio CHIP SYSDIR      gpio-sim: output pulses read back from the
 *                                            simulator, a busy line refused, input edges made
 *                                            by the simulator's pull and timestamped */
#include <errno.h>
#include <stdarg.h>
#include <fcntl.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/ioctl.h>
#include <poll.h>
#include <unistd.h>

#include <linux/videodev2.h>

#include "stillheart/pixconv.h"
#include "stillheart/source.h"
#include "stillheart/sync.h"

enum { W = 320, H = 180, FRAMES = 8 };

static int failures;

static void result(int ok, const char *name, const char *fmt, ...) __attribute__((format(printf, 3, 4)));
static void result(int ok, const char *name, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    printf("VMTEST %s %s: ", ok ? "PASS" : "FAIL", name);
    vprintf(fmt, ap);
    printf("\n");
    fflush(stdout);
    va_end(ap);
    if (!ok) failures++;
}

static int offered(const char *dev, uint32_t fourcc)
{
    int fd = open(dev, O_RDWR);
    if (fd < 0) return 0;
    struct v4l2_fmtdesc d;
    int found = 0;
    for (uint32_t i = 0;; i++) {
        memset(&d, 0, sizeof d);
        d.index = i;
        d.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
        if (ioctl(fd, VIDIOC_ENUM_FMT, &d) < 0) break;
        if (d.pixelformat == fourcc) found = 1;
    }
    close(fd);
    return found;
}

static void formats(const char *dev)
{
    const sh_rawfmt list[] = {SH_RAW_GREY, SH_RAW_YUYV, SH_RAW_NV12, SH_RAW_RGB24, SH_RAW_BGR24, SH_RAW_MJPEG};
    sh_pixconv *conv;
    if (sh_pixconv_create(1920, 1080, &conv) != SH_OK) return result(0, "pixconv", "%s", sh_error_message());
    sh_image i420;
    sh_image_create(&i420, SH_PIX_I420, W, H);
    for (size_t k = 0; k < sizeof list / sizeof list[0]; k++) {
        char name[64];
        snprintf(name, sizeof name, "capture-%s", sh_rawfmt_name(list[k]));
        if (!offered(dev, sh_rawfmt_fourcc(list[k]))) {
            printf("VMTEST SKIP %s: %s does not offer it\n", name, dev);
            continue;
        }
        sh_source_options o;
        sh_source_options_default(&o);
        o.format = (int)list[k];
        o.width = W;
        o.height = H;
        o.fps_num = 30;
        o.fps_den = 1;
        o.timeout_ms = 5000;
        char spec[128];
        snprintf(spec, sizeof spec, "v4l2:%s", dev);
        sh_source *s;
        if (sh_source_open(spec, &o, &s) != SH_OK || sh_source_start(s) != SH_OK) {
            result(0, name, "%s", sh_error_message());
            continue;
        }
        int n = 0, ok = 1;
        int64_t last_ts = 0;
        uint64_t last_seq = 0;
        char why[256] = "";
        for (int tries = 0; n < FRAMES && tries < 200; tries++) {
            sh_source_frame f;
            int got;
            if (sh_source_dequeue(s, 1000, &f, &got) != SH_OK) {
                snprintf(why, sizeof why, "dequeue: %s", sh_error_message());
                ok = 0;
                break;
            }
            if (!got) continue;
            if (f.raw.width != W || f.raw.height != H || f.raw.format != list[k])
                ok = 0, snprintf(why, sizeof why, "frame %dx%d %s", f.raw.width, f.raw.height,
                                 sh_rawfmt_name(f.raw.format));
            if (n && (f.timestamp_ns <= last_ts || f.sequence <= last_seq))
                ok = 0, snprintf(why, sizeof why, "timestamps or sequence not increasing");
            if (sh_raw_check(&f.raw) != SH_OK || sh_pixconv_convert(conv, &f.raw, &i420) != SH_OK)
                ok = 0, snprintf(why, sizeof why, "frame %d: %s", n, sh_error_message());
            last_ts = f.timestamp_ns;
            last_seq = f.sequence;
            sh_source_release(s, &f);
            n++;
        }
        sh_source_stats st;
        sh_source_get_stats(s, &st);
        sh_source_close(s);
        if (n < FRAMES && ok) ok = 0, snprintf(why, sizeof why, "%d of %d frames", n, FRAMES);
        if (ok)
            result(1, name, "%d frames %dx%d, timestamps increasing, %llu errors, %llu drops", n, W, H,
                   (unsigned long long)st.errors, (unsigned long long)st.drops);
        else
            result(0, name, "%s", why);
    }
    sh_image_destroy(&i420);
    sh_pixconv_destroy(conv);
}

/* Controls: vivid has gain (with autogain) but no exposure: the first is set and read back, the
 * second refused naming it. */
static void controls(const char *dev)
{
    sh_source_options o;
    sh_source_options_default(&o);
    o.format = SH_RAW_YUYV;
    o.width = W;
    o.height = H;
    o.gain = 77;
    char spec[128];
    snprintf(spec, sizeof spec, "v4l2:%s", dev);
    sh_source *s;
    if (sh_source_open(spec, &o, &s) != SH_OK) return result(0, "controls-gain", "%s", sh_error_message());
    sh_source_close(s);
    int fd = open(dev, O_RDWR), got = -1;
    struct v4l2_control c = {.id = V4L2_CID_GAIN};
    if (fd >= 0 && ioctl(fd, VIDIOC_G_CTRL, &c) == 0) got = c.value;
    if (fd >= 0) close(fd);
    result(got == 77, "controls-gain", "gain set to 77, driver reads %d", got);
    o.gain = SH_SOURCE_CTRL_UNSET;
    o.exposure = 100;
    sh_status st = sh_source_open(spec, &o, &s);
    if (st == SH_OK) sh_source_close(s);
    result(st != SH_OK && strstr(sh_error_message(), "exposure") != NULL, "controls-exposure",
           "refused: %s", st != SH_OK ? sh_error_message() : "accepted");
}

/* A vivid control by its name (its ids are private to the driver). */
static uint32_t find_ctrl(int fd, const char *name)
{
    struct v4l2_queryctrl q;
    memset(&q, 0, sizeof q);
    q.id = V4L2_CTRL_FLAG_NEXT_CTRL;
    while (ioctl(fd, VIDIOC_QUERYCTRL, &q) == 0) {
        if (!strcmp((const char *)q.name, name)) return q.id;
        q.id |= V4L2_CTRL_FLAG_NEXT_CTRL;
    }
    return 0;
}

/* Buffers the driver flags erroneous (vivid's "Inject V4L2_BUF_FLAG_ERROR") are skipped and
 * counted; capture goes on. */
static void errors(const char *dev)
{
    sh_source_options o;
    sh_source_options_default(&o);
    o.format = SH_RAW_YUYV;
    o.width = W;
    o.height = H;
    o.timeout_ms = 5000;
    char spec[128];
    snprintf(spec, sizeof spec, "v4l2:%s", dev);
    sh_source *s;
    if (sh_source_open(spec, &o, &s) != SH_OK || sh_source_start(s) != SH_OK)
        return result(0, "error-buffers", "%s", sh_error_message());
    int fd = open(dev, O_RDWR);
    uint32_t id = fd >= 0 ? find_ctrl(fd, "Inject V4L2_BUF_FLAG_ERROR") : 0;
    if (!id) {
        printf("VMTEST SKIP error-buffers: no error injection control\n");
        if (fd >= 0) close(fd);
        sh_source_close(s);
        return;
    }
    int n = 0, injected = 0;
    for (int tries = 0; n < 12 && tries < 300; tries++) {
        sh_source_frame f;
        int got;
        if (sh_source_dequeue(s, 200, &f, &got) != SH_OK) break;
        if (!got) continue;
        sh_source_release(s, &f);
        n++;
        if (n == 3 || n == 6) {
            struct v4l2_control c = {.id = id, .value = 1};
            if (ioctl(fd, VIDIOC_S_CTRL, &c) == 0) injected++;
        }
    }
    close(fd);
    sh_source_stats st;
    sh_source_get_stats(s, &st);
    sh_source_close(s);
    result(n == 12 && injected == 2 && st.errors >= 1, "error-buffers",
           "%d good frames, %d errors injected, %llu skipped and counted", n, injected, (unsigned long long)st.errors);
}

static void sets(const char *d0, const char *d1)
{
    sh_source *s[2] = {0};
    const char *devs[2] = {d0, d1};
    for (int i = 0; i < 2; i++) {
        sh_source_options o;
        sh_source_options_default(&o);
        o.camera = i;
        o.format = SH_RAW_YUYV;
        o.width = W;
        o.height = H;
        o.fps_num = 30;
        o.fps_den = 1;
        o.timeout_ms = 5000;
        char spec[128];
        snprintf(spec, sizeof spec, "v4l2:%s", devs[i]);
        if (sh_source_open(spec, &o, &s[i]) != SH_OK || sh_source_start(s[i]) != SH_OK)
            return result(0, "sets", "%s", sh_error_message());
    }
    /* free-running cameras: a frame belongs to the set within half a period */
    sh_sync_options so = {2, 16 * 1000000, 100 * 1000000, 0};
    sh_sync *sync;
    sh_sync_create(&so, &sync);
    int frames = 0;
    sh_frame_set set;
    int nsets = 0, complete = 0;
    for (int tries = 0; frames < 2 * 3 * FRAMES && tries < 1000; tries++)
        for (int i = 0; i < 2; i++) {
            sh_source_frame f;
            int got;
            if (sh_source_dequeue(s[i], 20, &f, &got) != SH_OK || !got) continue;
            sh_sync_disposition d;
            sh_sync_push(sync, i, f.sequence, f.timestamp_ns, NULL, &d);
            sh_source_release(s[i], &f);
            frames++;
            while (sh_sync_pop(sync, &set)) nsets++, complete += set.complete;
        }
    sh_sync_flush(sync);
    while (sh_sync_pop(sync, &set)) nsets++, complete += set.complete;
    sh_sync_stats st;
    sh_sync_get_stats(sync, &st);
    result(frames == 2 * 3 * FRAMES && nsets >= 3 * FRAMES && complete > 0, "sets",
           "%d frames of 2 cameras, %d sets, %d complete, %llu late, %llu duplicates", frames, nsets, complete,
           (unsigned long long)st.late, (unsigned long long)st.duplicates);
    sh_sync_destroy(sync);
    sh_source_close(s[0]);
    sh_source_close(s[1]);
}

static int write_sys(const char *path, const char *value)
{
    int fd = open(path, O_WRONLY);
    if (fd < 0) return -1;
    ssize_t r = write(fd, value, strlen(value));
    close(fd);
    return r < 0 ? -1 : 0;
}

static void loss(const char *dev, const char *platdev)
{
    sh_source_options o;
    sh_source_options_default(&o);
    o.format = SH_RAW_YUYV;
    o.width = W;
    o.height = H;
    o.fps_num = 30;
    o.fps_den = 1;
    o.timeout_ms = 2000;
    o.backoff_min_ms = 100;
    o.backoff_max_ms = 400;
    char spec[128];
    snprintf(spec, sizeof spec, "v4l2:%s", dev);
    sh_source *s;
    if (sh_source_open(spec, &o, &s) != SH_OK || sh_source_start(s) != SH_OK)
        return result(0, "loss", "%s", sh_error_message());
    int before = 0, during = 0, after = 0, phase = 0;
    int64_t phase_end = 0;
    for (int tries = 0; tries < 3000 && phase < 3; tries++) {
        sh_source_frame f;
        int got;
        sh_status st = sh_source_dequeue(s, 50, &f, &got);
        if (st != SH_OK) return result(0, "loss", "dequeue gave up: %s", sh_error_message());
        if (got) {
            if (phase == 0) before++;
            else if (phase == 1) during++;
            else after++;
            sh_source_release(s, &f);
        }
        int64_t now = sh_monotonic_ns();
        if (phase == 0 && before >= 5) {
            if (write_sys("/sys/bus/platform/drivers/vivid/unbind", platdev) < 0)
                return result(0, "loss", "unbind %s: %s", platdev, strerror(errno));
            printf("VMTEST INFO loss: %s unbound after %d frames\n", platdev, before);
            phase = 1;
            phase_end = now + 1500000000LL; /* 1.5 s without the device: keep running */
        } else if (phase == 1 && now >= phase_end) {
            if (write_sys("/sys/bus/platform/drivers/vivid/bind", platdev) < 0)
                return result(0, "loss", "bind %s: %s", platdev, strerror(errno));
            printf("VMTEST INFO loss: %s bound again\n", platdev);
            phase = 2;
        } else if (phase == 2 && after >= 5) {
            phase = 3;
        }
    }
    sh_source_stats st;
    sh_source_get_stats(s, &st);
    sh_source_close(s);
    result(phase == 3 && st.losses >= 1 && st.reopens >= 1 && during <= 1, "loss",
           "%d frames before, %d while unbound, %d after; %llu losses, %llu reopens", before, during, after,
           (unsigned long long)st.losses, (unsigned long long)st.reopens);
}

static int read_sys_int(const char *path)
{
    char b[16] = "";
    int fd = open(path, O_RDONLY);
    if (fd < 0) return -1;
    ssize_t r = read(fd, b, sizeof b - 1);
    close(fd);
    return r > 0 ? atoi(b) : -1;
}

static void gpio(const char *chip, const char *sysdir)
{
    /* output: 20 ms period, 5 ms pulses on line 0 */
    sh_gpio_options o = {chip, 0, 0, 1, 20000000, 5000000};
    sh_gpio_trigger *t;
    if (sh_gpio_trigger_open(&o, &t) != SH_OK) return result(0, "gpio-output", "%s", sh_error_message());
    sh_gpio_trigger *busy = NULL;
    sh_status bst = sh_gpio_trigger_open(&o, &busy);
    result(bst != SH_OK && strstr(sh_error_message(), "busy") != NULL, "gpio-busy", "second request: %s",
           bst != SH_OK ? sh_error_message() : "accepted");
    sh_gpio_trigger_close(busy);
    char vpath[256];
    snprintf(vpath, sizeof vpath, "%s/sim_gpio0/value", sysdir);
    sh_gpio_trigger_start(t);
    int64_t end = sh_monotonic_ns() + 400000000, last_edge = 0;
    int edges = 0, seen[2] = {0, 0}, spacing_ok = 1;
    while (sh_monotonic_ns() < end) {
        struct pollfd p = {sh_gpio_trigger_fd(t), POLLIN, 0};
        poll(&p, 1, 2);
        int64_t e;
        int got;
        if (sh_gpio_trigger_service(t, &e, &got) != SH_OK) return result(0, "gpio-output", "%s", sh_error_message());
        if (got) {
            if (edges && (e - last_edge < 15000000 || e - last_edge > 60000000)) spacing_ok = 0;
            last_edge = e;
            edges++;
        }
        int v = read_sys_int(vpath);
        if (v == 0 || v == 1) seen[v]++;
    }
    sh_gpio_trigger_close(t);
    result(edges >= 15 && edges <= 22 && seen[0] && seen[1] && spacing_ok, "gpio-output",
           "%d pulses in 400 ms, line read back high %d and low %d times, spacing %s", edges, seen[1], seen[0],
           spacing_ok ? "20 ms" : "wrong");
    /* input: rising edges of line 1, made by the simulator's pull */
    sh_gpio_options in = {chip, 1, 0, 0, 0, 0};
    if (sh_gpio_trigger_open(&in, &t) != SH_OK) return result(0, "gpio-input", "%s", sh_error_message());
    snprintf(vpath, sizeof vpath, "%s/sim_gpio1/pull", sysdir);
    int ok = 1, n = 0;
    for (int k = 0; k < 3; k++) {
        write_sys(vpath, "pull-down");
        usleep(20000);
        int64_t e, before = sh_monotonic_ns();
        int got = 0;
        sh_gpio_trigger_service(t, &e, &got); /* drain */
        if (write_sys(vpath, "pull-up") < 0) ok = 0;
        int64_t after = sh_monotonic_ns();
        struct pollfd p = {sh_gpio_trigger_fd(t), POLLIN, 0};
        poll(&p, 1, 1000);
        if (sh_gpio_trigger_service(t, &e, &got) != SH_OK || !got) {
            ok = 0;
            continue;
        }
        if (e < before || e > after + 1000000) ok = 0; /* the kernel's monotonic edge time */
        n++;
    }
    sh_gpio_trigger_close(t);
    result(ok && n == 3, "gpio-input", "%d of 3 rising edges timestamped within the pull write", n);
    sh_gpio_options missing = {"gpiochip-missing", 0, 0, 0, 0, 0};
    result(sh_gpio_trigger_open(&missing, &t) != SH_OK && strstr(sh_error_message(), "gpiochip-missing"),
           "gpio-missing-chip", "%s", sh_error_message());
}

static void libcamera(const char *name, const char *size)
{
    sh_source_options o;
    sh_source_options_default(&o);
    o.format = SH_RAW_RGB24;
    if (sscanf(size, "%dx%d", &o.width, &o.height) != 2) return result(0, "libcamera", "bad size %s", size);
    o.timeout_ms = 20000;
    char spec[128];
    snprintf(spec, sizeof spec, "libcamera:%s", name);
    sh_source *s;
    if (sh_source_open(spec, &o, &s) != SH_OK || sh_source_start(s) != SH_OK) {
        if (strstr(sh_error_message(), "built without")) {
            printf("VMTEST SKIP libcamera: %s\n", sh_error_message());
            return;
        }
        return result(0, "libcamera", "%s", sh_error_message());
    }
    sh_rawfmt f;
    int w, h;
    sh_source_format(s, &f, &w, &h, NULL, NULL);
    sh_image i420;
    sh_image_create(&i420, SH_PIX_I420, w & ~1, h & ~1);
    int n = 0, ok = 1;
    int64_t last = 0;
    char why[256] = "";
    for (int tries = 0; n < 4 && tries < 60; tries++) {
        sh_source_frame fr;
        int got;
        if (sh_source_dequeue(s, 1000, &fr, &got) != SH_OK) {
            ok = 0;
            snprintf(why, sizeof why, "%s", sh_error_message());
            break;
        }
        if (!got) continue;
        if (fr.raw.width != o.width || fr.raw.height != o.height || fr.raw.format != SH_RAW_RGB24)
            ok = 0, snprintf(why, sizeof why, "frame %dx%d %s", fr.raw.width, fr.raw.height, sh_rawfmt_name(fr.raw.format));
        if (n && fr.timestamp_ns <= last) ok = 0, snprintf(why, sizeof why, "timestamps not increasing");
        if (sh_raw_check(&fr.raw) != SH_OK || sh_pixconv_convert(NULL, &fr.raw, &i420) != SH_OK)
            ok = 0, snprintf(why, sizeof why, "%s", sh_error_message());
        last = fr.timestamp_ns;
        sh_source_release(s, &fr);
        n++;
    }
    sh_source_close(s);
    sh_image_destroy(&i420);
    if (n < 4 && ok) ok = 0, snprintf(why, sizeof why, "%d of 4 frames", n);
    if (ok) result(1, "libcamera", "%s: %d frames %dx%d %s, timestamps increasing", name, n, w, h, sh_rawfmt_name(f));
    else result(0, "libcamera", "%s", why);
}

int main(int argc, char **argv)
{
    if (argc >= 3 && !strcmp(argv[1], "formats")) formats(argv[2]);
    else if (argc >= 3 && !strcmp(argv[1], "controls")) controls(argv[2]);
    else if (argc >= 3 && !strcmp(argv[1], "errors")) errors(argv[2]);
    else if (argc >= 4 && !strcmp(argv[1], "sets")) sets(argv[2], argv[3]);
    else if (argc >= 4 && !strcmp(argv[1], "loss")) loss(argv[2], argv[3]);
    else if (argc >= 4 && !strcmp(argv[1], "gpio")) gpio(argv[2], argv[3]);
    else if (argc >= 4 && !strcmp(argv[1], "libcamera")) libcamera(argv[2], argv[3]);
    else {
        fprintf(stderr, "usage: stillheart-vmprobe formats DEV | sets DEV0 DEV1 | loss DEV PLATDEV\n");
        return 2;
    }
    return failures ? 1 : 0;
}
