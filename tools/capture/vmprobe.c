/* stillheart-vmprobe: stillheart's capture code against real kernel drivers, run inside the
 * QEMU guest of tests/vm/run.sh (vivid). Prints one line per check, "VMTEST PASS name ..." or
 * "VMTEST FAIL name: why", which the host script parses from the serial console.
 *
 *   stillheart-vmprobe formats DEV           each of GREY YUYV NV12 RGB24 BGR24 MJPEG the driver
 *                                            offers: frames, geometry, timestamps, conversion
 *   stillheart-vmprobe controls DEV          exposure, gain, white balance: set and read back
 *                                            where listed, else refused naming them
 *   stillheart-vmprobe errors DEV            buffers flagged erroneous skipped and counted
 *   stillheart-vmprobe sets DEV0 DEV1        frame sets from two devices
 *   stillheart-vmprobe loss DEV PLATDEV      unbind the driver mid-stream, rebind: reported,
 *                                            running on, resumed
 *   stillheart-vmprobe libcamera NAME WxH    libcamera (vimc): frames, geometry, timestamps
 *   stillheart-vmprobe libcamera-controls NAME WxH   controls the camera does not list refused
 *   stillheart-vmprobe libcamera-loss NAME WxH PLATDEV   vimc unbound and bound again: reported,
 *                                            running on, found again
 *   stillheart-vmprobe gpio CHIP SYSDIR      gpio-sim: output pulses read back from the
 *                                            simulator, a busy line refused, input edges made
 *                                            by the simulator's pull and timestamped
 *   stillheart-vmprobe loopback OUT CAP DIR  the daemon's [sink] v4l2 on v4l2loopback's OUT, read
 *                                            back; CAP (capture only) refused (vmprobe_loop.c)
 *   stillheart-vmprobe run DEV0 DEV1 PLATDEV CHIP LINE N   stillheart run on the two, trigger
 *                                            out on CHIP:LINE, camera 1 silenced, then both
 *                                            unbound and bound again (vmprobe_run.c)
 *
 * Over 600 lines: one program for the guest, one function per check family named above, all sharing
 * result() and the sysfs helpers; the daemon run is already apart (vmprobe_run.c). Only vmtest runs
 * it, so it is not split further where a split could not be checked. */
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

#include "stillheart/cli.h"
#include "stillheart/pixconv.h"
#include "stillheart/source.h"
#include "stillheart/sync.h"
#include "vmprobe.h"

enum { W = 320, H = 180, FRAMES = 8 };

static int failures;

void result(int ok, const char *name, const char *fmt, ...)
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
                ok = 0, snprintf(why, sizeof why, "frame %d: timestamp %lld after %lld, sequence %llu after %llu", n,
                                 (long long)f.timestamp_ns, (long long)last_ts, (unsigned long long)f.sequence,
                                 (unsigned long long)last_seq);
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

/* Controls: each of exposure, gain and white balance that the driver lists is set through the
 * source (its automatic control switched off) and read back with VIDIOC_G_CTRL; each it does not
 * list is refused naming it (vivid 6.12: gain listed, exposure and white balance not). */
static void controls(const char *dev)
{
    static const struct {
        const char *name;
        uint32_t id, automatic;
        int32_t manual; /* the automatic control's "off" */
    } list[] = {
        {"exposure", V4L2_CID_EXPOSURE_ABSOLUTE, V4L2_CID_EXPOSURE_AUTO, V4L2_EXPOSURE_MANUAL},
        {"gain", V4L2_CID_GAIN, V4L2_CID_AUTOGAIN, 0},
        {"white balance", V4L2_CID_WHITE_BALANCE_TEMPERATURE, V4L2_CID_AUTO_WHITE_BALANCE, 0},
    };
    char spec[128];
    snprintf(spec, sizeof spec, "v4l2:%s", dev);
    for (size_t k = 0; k < sizeof list / sizeof list[0]; k++) {
        char name[64];
        snprintf(name, sizeof name, "controls-%s", list[k].name);
        for (char *c = name; *c; c++)
            if (*c == ' ') *c = '-';
        int fd = open(dev, O_RDWR);
        if (fd < 0) return result(0, name, "open %s: %s", dev, strerror(errno));
        struct v4l2_queryctrl q;
        memset(&q, 0, sizeof q);
        q.id = list[k].id;
        int listed = ioctl(fd, VIDIOC_QUERYCTRL, &q) == 0 && !(q.flags & V4L2_CTRL_FLAG_DISABLED);
        struct v4l2_queryctrl qa;
        memset(&qa, 0, sizeof qa);
        qa.id = list[k].automatic;
        int has_auto = ioctl(fd, VIDIOC_QUERYCTRL, &qa) == 0 && !(qa.flags & V4L2_CTRL_FLAG_DISABLED);
        close(fd);
        /* a value the driver would not pick by itself: three quarters of the range, on its step */
        int32_t step = q.step > 0 ? q.step : 1;
        int32_t value = listed ? q.minimum + (int32_t)((int64_t)(q.maximum - q.minimum) * 3 / 4 / step) * step : 100;
        if (listed && value == q.default_value) value = q.minimum;
        sh_source_options o;
        sh_source_options_default(&o);
        o.format = SH_RAW_YUYV;
        o.width = W;
        o.height = H;
        int32_t *field = k == 0 ? &o.exposure : k == 1 ? &o.gain : &o.white_balance;
        *field = value;
        sh_source *s;
        sh_status st = sh_source_open(spec, &o, &s);
        if (st == SH_OK) sh_source_close(s);
        if (!listed) {
            result(st != SH_OK && strstr(sh_error_message(), list[k].name) != NULL, name,
                   "not listed by the driver, refused: %s", st != SH_OK ? sh_error_message() : "accepted");
            continue;
        }
        if (st != SH_OK) {
            result(0, name, "listed (%d..%d) but refused: %s", (int)q.minimum, (int)q.maximum, sh_error_message());
            continue;
        }
        int got = -1, got_auto = -1;
        fd = open(dev, O_RDWR);
        struct v4l2_control c = {.id = list[k].id};
        if (fd >= 0 && ioctl(fd, VIDIOC_G_CTRL, &c) == 0) got = c.value;
        struct v4l2_control ca = {.id = list[k].automatic};
        if (fd >= 0 && has_auto && ioctl(fd, VIDIOC_G_CTRL, &ca) == 0) got_auto = ca.value;
        /* out of range: refused naming it, before the driver can clamp it */
        *field = q.maximum + 1;
        sh_status range = q.maximum < INT32_MAX ? sh_source_open(spec, &o, &s) : SH_EUNSUPPORTED;
        if (range == SH_OK) sh_source_close(s);
        int range_ok = range != SH_OK && strstr(sh_error_message(), list[k].name) != NULL;
        if (fd >= 0) close(fd);
        result(got == value && (!has_auto || got_auto == list[k].manual) && range_ok, name,
               "set to %d (range %d..%d), driver reads %d; automatic %s; %d refused: %s", (int)value, (int)q.minimum,
               (int)q.maximum, got, has_auto ? (got_auto == list[k].manual ? "off" : "still on") : "none",
               (int)q.maximum + 1, range_ok ? sh_error_message() : "accepted");
    }
}

uint32_t find_ctrl(int fd, const char *name)
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
    /* both cameras are served in one pass, so the count may end one past the target; a frame the
     * loaded emulator delivered after its set had gone is refused as late (counted), every other
     * one is in a set of at most two */
    uint64_t refused = st.late + st.duplicates;
    result(frames >= 2 * 3 * FRAMES && 2 * (uint64_t)nsets >= (uint64_t)frames - refused &&
               refused <= (uint64_t)frames / 8 && complete > 0,
           "sets",
           "%d frames of 2 cameras, %d sets, %d complete, %llu late, %llu duplicates", frames, nsets, complete,
           (unsigned long long)st.late, (unsigned long long)st.duplicates);
    sh_sync_destroy(sync);
    sh_source_close(s[0]);
    sh_source_close(s[1]);
}

int write_sys(const char *path, const char *value)
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

/* Over 80 lines: the gpio-sim chip's checks in one sequence on its sysfs folder: a second request
 * refused as busy, 400 ms of output pulses and their spacing, the input's edges, a missing chip.
 * Kept whole also because only vmtest (tests/vm/run.sh) runs it: a split could not be checked
 * outside the guest. */
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
    int64_t end = sh_monotonic_ns() + 400000000, last_edge = 0, gap[64], last_pass = sh_monotonic_ns(), stall = 0;
    int edges = 0, seen[2] = {0, 0};
    while (sh_monotonic_ns() < end) {
        struct pollfd p = {sh_gpio_trigger_fd(t), POLLIN, 0};
        poll(&p, 1, 2);
        int64_t pass = sh_monotonic_ns();
        if (pass - last_pass > stall) stall = pass - last_pass; /* the guest's own hold-ups */
        last_pass = pass;
        int64_t e;
        int got;
        if (sh_gpio_trigger_service(t, &e, &got) != SH_OK) return result(0, "gpio-output", "%s", sh_error_message());
        if (got) {
            if (edges && edges <= 64) gap[edges - 1] = e - last_edge;
            last_edge = e;
            edges++;
        }
        int v = read_sys_int(vpath);
        if (v == 0 || v == 1) seen[v]++;
    }
    sh_gpio_trigger_close(t);
    /* An edge is stamped when the line was driven, which a loaded emulator delays now and then:
     * the schedule shows in the median spacing; never more pulses than the schedule has
     * (missed ones are skipped, not bunched). */
    int ngap = edges - 1 < 64 ? edges - 1 : 64;
    for (int i = 1; i < ngap; i++)
        for (int j = i; j > 0 && gap[j - 1] > gap[j]; j--) {
            int64_t x = gap[j];
            gap[j] = gap[j - 1];
            gap[j - 1] = x;
        }
    double median_ms = ngap > 0 ? gap[ngap / 2] / 1e6 : 0;
    /* A loop that polls every 2 ms but was held up for more than half a period (an emulator
     * starved by its host) shows the host's load, not the schedule: then only what no delay can
     * change is judged (never more pulses than the schedule, both levels seen), and said so. */
    if (stall > 10000000)
        result(edges >= 1 && edges <= 21 && seen[0] && seen[1], "gpio-output",
               "%d pulses in 400 ms (at most 21), line read back high %d and low %d times; spacing not judged: "
               "the guest was held up %.1f ms (median spacing %.2f ms)",
               edges, seen[1], seen[0], stall / 1e6, median_ms);
    else
        result(edges >= 15 && edges <= 21 && seen[0] && seen[1] && median_ms > 18 && median_ms < 22, "gpio-output",
               "%d pulses in 400 ms (at most 21), line read back high %d and low %d times, median spacing %.2f ms",
               edges, seen[1], seen[0], median_ms);
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

/* libcamera controls: each of exposure, gain and white balance the camera lists is accepted, each
 * it does not list refused naming the libcamera control (vimc lists Brightness, Contrast and
 * Saturation only, so all three are refused there). */
static void libcamera_controls(const char *name, const char *size)
{
    static const char *const what[3] = {"exposure", "gain", "white balance"};
    static const char *const control[3] = {"ExposureTime", "AnalogueGain", "ColourTemperature"};
    char spec[128];
    snprintf(spec, sizeof spec, "libcamera:%s", name);
    for (int k = 0; k < 3; k++) {
        sh_source_options o;
        sh_source_options_default(&o);
        o.format = SH_RAW_RGB24;
        if (sscanf(size, "%dx%d", &o.width, &o.height) != 2) return result(0, "libcamera-controls", "bad size %s", size);
        int32_t *field = k == 0 ? &o.exposure : k == 1 ? &o.gain : &o.white_balance;
        *field = k == 2 ? 5000 : 100;
        char check[64];
        snprintf(check, sizeof check, "libcamera-controls-%s", k == 2 ? "white-balance" : what[k]);
        sh_source *s;
        sh_status st = sh_source_open(spec, &o, &s);
        if (st == SH_OK) {
            sh_source_close(s);
            result(1, check, "%s (%s) listed and accepted", what[k], control[k]);
            continue;
        }
        if (strstr(sh_error_message(), "built without")) {
            printf("VMTEST SKIP %s: %s\n", check, sh_error_message());
            return;
        }
        result(strstr(sh_error_message(), control[k]) && strstr(sh_error_message(), "not offered"), check,
               "refused: %s", sh_error_message());
    }
}

/* Writes the udev database entries libcamera's enumerator wants for every video, subdev and
 * media node (the guest has no udevd; a rebound driver's nodes are new). */
static void udev_entries(void)
{
    const char *dirs[2] = {"/sys/class/video4linux", "/sys/bus/media/devices"};
    for (int d = 0; d < 2; d++) {
        char cmd[256];
        snprintf(cmd, sizeof cmd, "for n in %s/*; do [ -f $n/dev ] && echo I:1 > /run/udev/data/c$(cat $n/dev); done",
                 dirs[d]);
        if (system(cmd) != 0) printf("VMTEST INFO udev entries for %s: not all written\n", dirs[d]);
    }
}

/* libcamera loss: vimc unbound mid-stream is reported (a loss), dequeue keeps returning without
 * frames, and when vimc is bound again the source finds the camera again and frames resume. */
static void libcamera_loss(const char *name, const char *size, const char *platdev)
{
    sh_source_options o;
    sh_source_options_default(&o);
    o.format = SH_RAW_RGB24;
    if (sscanf(size, "%dx%d", &o.width, &o.height) != 2) return result(0, "libcamera-loss", "bad size %s", size);
    o.timeout_ms = 3000;
    o.backoff_min_ms = 200;
    o.backoff_max_ms = 800;
    char spec[128];
    snprintf(spec, sizeof spec, "libcamera:%s", name);
    sh_source *s;
    if (sh_source_open(spec, &o, &s) != SH_OK || sh_source_start(s) != SH_OK) {
        if (strstr(sh_error_message(), "built without")) {
            printf("VMTEST SKIP libcamera-loss: %s\n", sh_error_message());
            return;
        }
        return result(0, "libcamera-loss", "%s", sh_error_message());
    }
    int before = 0, during = 0, after = 0, phase = 0, fd_down = 0;
    int64_t phase_end = 0, end = sh_monotonic_ns() + 60 * 1000000000LL;
    uint64_t last_seq = 0;
    int seq_ok = 1;
    while (phase < 3 && sh_monotonic_ns() < end) {
        sh_source_frame f;
        int got;
        if (sh_source_dequeue(s, 50, &f, &got) != SH_OK) {
            sh_source_close(s);
            return result(0, "libcamera-loss", "dequeue gave up: %s", sh_error_message());
        }
        if (got) {
            if (before + during + after && f.sequence <= last_seq) seq_ok = 0;
            last_seq = f.sequence;
            if (phase == 0) before++;
            else if (phase == 1) during++;
            else after++;
            sh_source_release(s, &f);
        }
        int64_t now = sh_monotonic_ns();
        if (phase == 0 && before >= 3) {
            if (write_sys("/sys/bus/platform/drivers/vimc/unbind", platdev) < 0) {
                sh_source_close(s);
                return result(0, "libcamera-loss", "unbind %s: %s", platdev, strerror(errno));
            }
            printf("VMTEST INFO libcamera-loss: %s unbound after %d frames\n", platdev, before);
            phase = 1;
            phase_end = now + 5000000000LL; /* longer than timeout_ms: the loss must be seen */
        } else if (phase == 1) {
            fd_down |= sh_source_fd(s) < 0;
            if (now >= phase_end) {
                if (write_sys("/sys/bus/platform/drivers/vimc/bind", platdev) < 0) {
                    sh_source_close(s);
                    return result(0, "libcamera-loss", "bind %s: %s", platdev, strerror(errno));
                }
                udev_entries();
                printf("VMTEST INFO libcamera-loss: %s bound again\n", platdev);
                phase = 2;
            }
        } else if (phase == 2 && after >= 3) {
            phase = 3;
        }
    }
    sh_source_stats st;
    sh_source_get_stats(s, &st);
    sh_source_close(s);
    result(phase == 3 && st.losses >= 1 && st.reopens >= 1 && during <= 1 && fd_down && seq_ok, "libcamera-loss",
           "%d frames before, %d while unbound (fd %s), %d after; %llu losses, %llu reopens, sequence %s", before,
           during, fd_down ? "-1" : "kept", after, (unsigned long long)st.losses, (unsigned long long)st.reopens,
           seq_ok ? "rising" : "not rising");
}

static void usage(FILE *out)
{
    fprintf(out, "usage: stillheart-vmprobe formats|controls|errors DEV | sets DEV0 DEV1 | loss DEV PLATDEV | "
                 "gpio CHIP SYSDIR | libcamera|libcamera-controls NAME WxH | libcamera-loss NAME WxH PLATDEV | "
                 "run DEV0 DEV1 PLATDEV CHIP LINE N | loopback OUT CAP DIR\n"
                 "The capture checks inside the QEMU guest of tests/vm/run.sh (tools/capture/vmprobe.c).\n");
}

int main(int argc, char **argv)
{
    if (argc == 2 && (!strcmp(argv[1], "-h") || !strcmp(argv[1], "--help"))) {
        usage(stdout);
        return 0;
    }
    if (argc == 2 && !strcmp(argv[1], "--version")) {
        printf("stillheart-vmprobe %s\n", SH_VERSION);
        return 0;
    }
    if (argc >= 3 && !strcmp(argv[1], "formats")) formats(argv[2]);
    else if (argc >= 3 && !strcmp(argv[1], "controls")) controls(argv[2]);
    else if (argc >= 3 && !strcmp(argv[1], "errors")) errors(argv[2]);
    else if (argc >= 4 && !strcmp(argv[1], "sets")) sets(argv[2], argv[3]);
    else if (argc >= 4 && !strcmp(argv[1], "loss")) loss(argv[2], argv[3]);
    else if (argc >= 4 && !strcmp(argv[1], "gpio")) gpio(argv[2], argv[3]);
    else if (argc >= 4 && !strcmp(argv[1], "libcamera")) libcamera(argv[2], argv[3]);
    else if (argc >= 4 && !strcmp(argv[1], "libcamera-controls")) libcamera_controls(argv[2], argv[3]);
    else if (argc >= 5 && !strcmp(argv[1], "libcamera-loss")) libcamera_loss(argv[2], argv[3], argv[4]);
    else if (argc >= 5 && !strcmp(argv[1], "loopback")) loopback_check(argv[2], argv[3], argv[4]);
    else if (argc >= 8 && !strcmp(argv[1], "run"))
        run_daemon_check(argv[2], argv[3], argv[4], argv[5], argv[6], atoi(argv[7]));
    else {
        fprintf(stderr, "stillheart-vmprobe: %s%s%s; try 'stillheart-vmprobe --help'\n", argc < 2 ? "no check named" : "'",
                argc < 2 ? "" : argv[1], argc < 2 ? "" : "': unknown check or too few arguments");
        return 2;
    }
    return failures ? 1 : 0;
}
