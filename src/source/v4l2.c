/* v4l2:DEVICE — memory-mapped streaming capture.
 *
 * open: QUERYCAP (capture + streaming), S_FMT (size, format) and the re-read of bytesperline and
 * sizeimage the driver chose, S_PARM (frame rate), controls when asked, REQBUFS (MMAP, ask
 * options.buffers, accept >= 2), QUERYBUF + mmap. start: QBUF all, STREAMON. dequeue: poll with a
 * timeout, DQBUF; buffers flagged V4L2_BUF_FLAG_ERROR are requeued, skipped and counted; gaps in
 * the driver's sequence are counted as drops.
 * Loss (ENODEV, EIO, any other DQBUF/QBUF error, POLLERR, no frame within timeout_ms): full
 * teardown (STREAMOFF, munmap, close) once the caller has released the frames it holds, then
 * reopen from scratch with a back-off doubling from backoff_min_ms to backoff_max_ms. The device
 * must come back with the same size and format. */
#include "source_internal.h"

#include <errno.h>
#include <fcntl.h>
#include <poll.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/ioctl.h>
#include <sys/mman.h>
#include <unistd.h>

#include <linux/videodev2.h>

#define MAX_BUFFERS 32

typedef struct {
    sh_source base;
    char path[256];
    int fd;
    int nbuf;
    void *start[MAX_BUFFERS];
    size_t length[MAX_BUFFERS];
    int held[MAX_BUFFERS];
    int nheld;
    unsigned generation;  /* bumped at each teardown; a frame of an old one is not requeued */
    uint32_t sizeimage;
    int streaming;
    int down;             /* lost: waiting for releases, then for the back-off */
    int mapped;
    int64_t last_frame;   /* monotonic ns of the last frame (or of STREAMON) */
    int64_t retry_at;
    int backoff_ms;
    uint64_t seq_base;    /* added to the driver's sequence (it restarts at each reopen) */
    uint64_t next_seq;
    int have_seq;
    uint32_t last_driver_seq;
    int64_t last_stamp;   /* timestamp of the last frame delivered */
} v4l2_source;

static int xioctl(int fd, unsigned long req, void *arg)
{
    int r;
    do r = ioctl(fd, req, arg);
    while (r < 0 && errno == EINTR);
    return r;
}

static sh_status fail(v4l2_source *v, const char *what, int err)
{
    return sh_error_set(err == ENODEV || err == ENOENT || err == EIO ? SH_EIO : SH_EUNSUPPORTED,
                        "v4l2:%s: %s: %s", v->path, what, strerror(err));
}

static void unmap_close(v4l2_source *v)
{
    if (v->fd >= 0 && v->streaming) {
        int type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
        xioctl(v->fd, VIDIOC_STREAMOFF, &type);
    }
    v->streaming = 0;
    for (int i = 0; i < v->nbuf; i++)
        if (v->start[i] && v->start[i] != MAP_FAILED) munmap(v->start[i], v->length[i]);
    memset(v->start, 0, sizeof v->start);
    if (v->fd >= 0) {
        struct v4l2_requestbuffers rb = {.count = 0, .type = V4L2_BUF_TYPE_VIDEO_CAPTURE, .memory = V4L2_MEMORY_MMAP};
        xioctl(v->fd, VIDIOC_REQBUFS, &rb);
        close(v->fd);
    }
    v->fd = -1;
    v->nbuf = 0;
    v->mapped = 0;
}

/* A control the driver does not list, or a value outside its range, is refused by name rather
 * than left to the driver (some clamp silently). */
static sh_status set_ctrl(v4l2_source *v, uint32_t id, int32_t value, const char *name, const char *cid)
{
    struct v4l2_queryctrl q;
    memset(&q, 0, sizeof q);
    q.id = id;
    if (xioctl(v->fd, VIDIOC_QUERYCTRL, &q) < 0 || (q.flags & V4L2_CTRL_FLAG_DISABLED))
        return sh_error_set(SH_EUNSUPPORTED, "v4l2:%s: control %s (%s) not offered by the driver", v->path, name, cid);
    if (value < q.minimum || value > q.maximum)
        return sh_error_set(SH_EUNSUPPORTED, "v4l2:%s: control %s (%s) = %d outside %d..%d", v->path, name, cid,
                            (int)value, (int)q.minimum, (int)q.maximum);
    struct v4l2_control c = {.id = id, .value = value};
    if (xioctl(v->fd, VIDIOC_S_CTRL, &c) < 0)
        return sh_error_set(SH_EUNSUPPORTED, "v4l2:%s: control %s (%s) = %d: %s", v->path, name, cid, (int)value,
                            strerror(errno));
    return SH_OK;
}

/* QUERYCAP: a single-planar capture device that streams. */
static sh_status check_caps(v4l2_source *v)
{
    struct v4l2_capability cap;
    memset(&cap, 0, sizeof cap);
    if (xioctl(v->fd, VIDIOC_QUERYCAP, &cap) < 0)
        return sh_error_set(SH_EUNSUPPORTED, "v4l2:%s: not a V4L2 device (%s)", v->path, strerror(errno));
    uint32_t caps = cap.capabilities & V4L2_CAP_DEVICE_CAPS ? cap.device_caps : cap.capabilities;
    if (!(caps & V4L2_CAP_VIDEO_CAPTURE) || !(caps & V4L2_CAP_STREAMING))
        return sh_error_set(SH_EUNSUPPORTED, "v4l2:%s (%s): not a streaming single-planar capture device",
                            v->path, (const char *)cap.card);
    return SH_OK;
}

/* S_FMT and the re-read of what the driver chose, which must be what was asked (first: the
 * options; after a loss: what was negotiated before); sets the source's geometry and sizeimage. */
static sh_status negotiate_format(v4l2_source *v, int first)
{
    const sh_source_options *o = &v->base.opts;
    sh_status st;
    struct v4l2_format fmt;
    memset(&fmt, 0, sizeof fmt);
    fmt.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    if (xioctl(v->fd, VIDIOC_G_FMT, &fmt) < 0) return fail(v, "VIDIOC_G_FMT", errno);
    int want_w = first ? o->width : v->base.width, want_h = first ? o->height : v->base.height;
    int want_f = first ? o->format : (int)v->base.format;
    if (want_w > 0) fmt.fmt.pix.width = (uint32_t)want_w;
    if (want_h > 0) fmt.fmt.pix.height = (uint32_t)want_h;
    if (want_f >= 0) fmt.fmt.pix.pixelformat = sh_rawfmt_fourcc((sh_rawfmt)want_f);
    fmt.fmt.pix.field = V4L2_FIELD_NONE;
    fmt.fmt.pix.bytesperline = 0; /* the driver's choice */
    if (xioctl(v->fd, VIDIOC_S_FMT, &fmt) < 0) return fail(v, "VIDIOC_S_FMT", errno);
    /* the driver may change everything: read it back */
    if (xioctl(v->fd, VIDIOC_G_FMT, &fmt) < 0) return fail(v, "VIDIOC_G_FMT", errno);
    sh_rawfmt got;
    if (sh_rawfmt_from_fourcc(fmt.fmt.pix.pixelformat, &got) != SH_OK)
        return sh_error_set(SH_EUNSUPPORTED, "v4l2:%s: %s", v->path, sh_error_message());
    if ((want_f >= 0 && (int)got != want_f) || (want_w > 0 && (int)fmt.fmt.pix.width != want_w) ||
        (want_h > 0 && (int)fmt.fmt.pix.height != want_h))
        return sh_error_set(SH_EUNSUPPORTED, "v4l2:%s: asked %dx%d %s, the driver gives %ux%u %s", v->path, want_w,
                            want_h, want_f >= 0 ? sh_rawfmt_name((sh_rawfmt)want_f) : "any", fmt.fmt.pix.width,
                            fmt.fmt.pix.height, sh_rawfmt_name(got));
    if ((st = sh_source_check_pixels(o, "v4l2", v->path, (int)fmt.fmt.pix.width, (int)fmt.fmt.pix.height)) != SH_OK)
        return st; /* before REQBUFS: the driver allocates the buffers we would map */
    if (fmt.fmt.pix.field != V4L2_FIELD_NONE && fmt.fmt.pix.field != V4L2_FIELD_ANY)
        return sh_error_set(SH_EUNSUPPORTED, "v4l2:%s: interlaced field order %u not supported", v->path,
                            fmt.fmt.pix.field);
    int w = (int)fmt.fmt.pix.width, h = (int)fmt.fmt.pix.height, stride = (int)fmt.fmt.pix.bytesperline;
    if (got != SH_RAW_MJPEG) {
        if (stride < sh_rawfmt_min_stride(got, w)) stride = sh_rawfmt_min_stride(got, w);
        size_t need = sh_raw_frame_size(got, w, h, stride);
        if (!need || fmt.fmt.pix.sizeimage < need)
            return sh_error_set(SH_EUNSUPPORTED, "v4l2:%s: %dx%d %s with bytesperline %d, sizeimage %u: inconsistent",
                                v->path, w, h, sh_rawfmt_name(got), stride, fmt.fmt.pix.sizeimage);
    }
    v->base.format = got;
    v->base.width = w;
    v->base.height = h;
    v->base.stride = stride;
    v->sizeimage = fmt.fmt.pix.sizeimage;
    return SH_OK;
}

/* S_PARM when a rate is asked, then the rate the driver runs at (0/0 when it does not say). */
static sh_status set_rate(v4l2_source *v)
{
    const sh_source_options *o = &v->base.opts;
    struct v4l2_streamparm parm;
    memset(&parm, 0, sizeof parm);
    parm.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    if (o->fps_num > 0 && o->fps_den > 0) {
        if (xioctl(v->fd, VIDIOC_G_PARM, &parm) < 0 || !(parm.parm.capture.capability & V4L2_CAP_TIMEPERFRAME))
            return sh_error_set(SH_EUNSUPPORTED, "v4l2:%s: the frame rate cannot be set", v->path);
        parm.parm.capture.timeperframe.numerator = (uint32_t)o->fps_den;
        parm.parm.capture.timeperframe.denominator = (uint32_t)o->fps_num;
        if (xioctl(v->fd, VIDIOC_S_PARM, &parm) < 0) return fail(v, "VIDIOC_S_PARM", errno);
    }
    memset(&parm, 0, sizeof parm);
    parm.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    v->base.fps_num = v->base.fps_den = 0;
    if (xioctl(v->fd, VIDIOC_G_PARM, &parm) == 0 && parm.parm.capture.timeperframe.numerator) {
        v->base.fps_num = (int)parm.parm.capture.timeperframe.denominator;
        v->base.fps_den = (int)parm.parm.capture.timeperframe.numerator;
    }
    return SH_OK;
}

/* The controls asked for: switch the automatic one off first where there is one (absent is fine). */
static sh_status set_controls(v4l2_source *v)
{
    const sh_source_options *o = &v->base.opts;
    sh_status st;
    if (o->exposure != SH_SOURCE_CTRL_UNSET) {
        struct v4l2_control c = {.id = V4L2_CID_EXPOSURE_AUTO, .value = V4L2_EXPOSURE_MANUAL};
        xioctl(v->fd, VIDIOC_S_CTRL, &c);
        if ((st = set_ctrl(v, V4L2_CID_EXPOSURE_ABSOLUTE, o->exposure, "exposure", "V4L2_CID_EXPOSURE_ABSOLUTE")) !=
            SH_OK)
            return st;
    }
    if (o->gain != SH_SOURCE_CTRL_UNSET) {
        struct v4l2_control c = {.id = V4L2_CID_AUTOGAIN, .value = 0};
        xioctl(v->fd, VIDIOC_S_CTRL, &c);
        if ((st = set_ctrl(v, V4L2_CID_GAIN, o->gain, "gain", "V4L2_CID_GAIN")) != SH_OK) return st;
    }
    if (o->white_balance != SH_SOURCE_CTRL_UNSET) {
        struct v4l2_control c = {.id = V4L2_CID_AUTO_WHITE_BALANCE, .value = 0};
        xioctl(v->fd, VIDIOC_S_CTRL, &c);
        if ((st = set_ctrl(v, V4L2_CID_WHITE_BALANCE_TEMPERATURE, o->white_balance, "white balance",
                           "V4L2_CID_WHITE_BALANCE_TEMPERATURE")) != SH_OK)
            return st;
    }
    return SH_OK;
}

/* REQBUFS (mmap, options.buffers, at least 2), then QUERYBUF and mmap each; each buffer must hold
 * a frame of the negotiated geometry. What is mapped so far stays for unmap_close. */
static sh_status map_buffers(v4l2_source *v)
{
    const sh_source_options *o = &v->base.opts;
    sh_rawfmt got = v->base.format;
    int w = v->base.width, h = v->base.height, stride = v->base.stride;
    struct v4l2_requestbuffers rb;
    memset(&rb, 0, sizeof rb);
    rb.count = (uint32_t)(o->buffers > 0 ? o->buffers : 4);
    if (rb.count > MAX_BUFFERS) rb.count = MAX_BUFFERS;
    rb.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    rb.memory = V4L2_MEMORY_MMAP;
    if (xioctl(v->fd, VIDIOC_REQBUFS, &rb) < 0) return fail(v, "VIDIOC_REQBUFS (mmap)", errno);
    if (rb.count < 2)
        return sh_error_set(SH_EUNSUPPORTED, "v4l2:%s: the driver gives %u buffer(s), 2 needed", v->path, rb.count);
    v->nbuf = (int)(rb.count > MAX_BUFFERS ? MAX_BUFFERS : rb.count);
    for (int i = 0; i < v->nbuf; i++) {
        struct v4l2_buffer b;
        memset(&b, 0, sizeof b);
        b.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
        b.memory = V4L2_MEMORY_MMAP;
        b.index = (uint32_t)i;
        if (xioctl(v->fd, VIDIOC_QUERYBUF, &b) < 0) return fail(v, "VIDIOC_QUERYBUF", errno);
        v->length[i] = b.length;
        v->start[i] = mmap(NULL, b.length, PROT_READ | PROT_WRITE, MAP_SHARED, v->fd, b.m.offset);
        if (v->start[i] == MAP_FAILED) {
            v->start[i] = NULL;
            return fail(v, "mmap", errno);
        }
        if (got != SH_RAW_MJPEG && b.length < sh_raw_frame_size(got, w, h, stride))
            return sh_error_set(SH_EUNSUPPORTED, "v4l2:%s: buffer of %u bytes holds no frame", v->path, b.length);
    }
    return SH_OK;
}

/* Opens, configures and maps, in that order (the header's open sequence); on failure everything
 * is closed again. first: the geometry is negotiated (else it must match what was negotiated
 * before). */
static sh_status open_device(v4l2_source *v, int first)
{
    v->fd = open(v->path, O_RDWR | O_NONBLOCK | O_CLOEXEC);
    if (v->fd < 0) return fail(v, "open", errno);
    sh_status st;
    if ((st = check_caps(v)) == SH_OK && (st = negotiate_format(v, first)) == SH_OK && (st = set_rate(v)) == SH_OK &&
        (st = set_controls(v)) == SH_OK && (st = map_buffers(v)) == SH_OK) {
        v->mapped = 1;
        return SH_OK;
    }
    unmap_close(v);
    return st;
}

static sh_status stream_on(v4l2_source *v)
{
    for (int i = 0; i < v->nbuf; i++) {
        struct v4l2_buffer b;
        memset(&b, 0, sizeof b);
        b.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
        b.memory = V4L2_MEMORY_MMAP;
        b.index = (uint32_t)i;
        if (xioctl(v->fd, VIDIOC_QBUF, &b) < 0) return fail(v, "VIDIOC_QBUF", errno);
    }
    int type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    if (xioctl(v->fd, VIDIOC_STREAMON, &type) < 0) return fail(v, "VIDIOC_STREAMON", errno);
    v->streaming = 1;
    v->last_frame = sh_monotonic_ns();
    v->have_seq = 0;
    v->seq_base = v->next_seq;
    v->base.stats.online = 1;
    return SH_OK;
}

static sh_status v_start(sh_source *s)
{
    v4l2_source *v = (v4l2_source *)s;
    if (!v->mapped) {
        sh_status st = open_device(v, 0);
        if (st != SH_OK) return st;
    }
    sh_status st = stream_on(v);
    if (st != SH_OK) unmap_close(v);
    return st;
}

static int v_fd(const sh_source *s)
{
    const v4l2_source *v = (const v4l2_source *)s;
    return v->down ? -1 : v->fd;
}

static int backoff_min(const v4l2_source *v) { return v->base.opts.backoff_min_ms > 0 ? v->base.opts.backoff_min_ms : 100; }
static int backoff_max(const v4l2_source *v) { return v->base.opts.backoff_max_ms > 0 ? v->base.opts.backoff_max_ms : 5000; }
static int timeout_of(const v4l2_source *v) { return v->base.opts.timeout_ms > 0 ? v->base.opts.timeout_ms : 1000; }

/* The camera is lost: what can go now goes; the mappings stay until the caller's frames are back. */
static void lose(v4l2_source *v)
{
    v->down = 1;
    v->base.stats.losses++;
    v->base.stats.online = 0;
    v->generation++;
    v->backoff_ms = backoff_min(v);
    v->retry_at = sh_monotonic_ns() + (int64_t)v->backoff_ms * 1000000;
    if (v->fd >= 0 && v->streaming) {
        int type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
        xioctl(v->fd, VIDIOC_STREAMOFF, &type);
        v->streaming = 0;
    }
    if (!v->nheld) unmap_close(v);
}

static void try_reopen(v4l2_source *v, int64_t now)
{
    if (v->nheld || now < v->retry_at) return;
    if (v->mapped || v->fd >= 0) unmap_close(v);
    if (open_device(v, 0) == SH_OK && stream_on(v) == SH_OK) {
        v->down = 0;
        v->base.stats.reopens++;
        return;
    }
    unmap_close(v);
    v->backoff_ms = v->backoff_ms * 2 > backoff_max(v) ? backoff_max(v) : v->backoff_ms * 2;
    v->retry_at = now + (int64_t)v->backoff_ms * 1000000;
}

/* Drops are the gaps in the driver's sequence. */
static void count_sequence(v4l2_source *v, uint32_t sequence)
{
    sh_source *s = &v->base;
    if (v->have_seq && sequence > v->last_driver_seq + 1)
        s->stats.drops += sequence - v->last_driver_seq - 1;
    /* A driver sequence that does not rise (vivid under load ticks twice on one count) moves
     * the base so that ours still does. */
    if (v->have_seq && sequence <= v->last_driver_seq) v->seq_base += v->last_driver_seq - sequence + 1;
    v->have_seq = 1;
    v->last_driver_seq = sequence;
}

/* The dequeued buffer b, of which bytes are a frame, becomes f and is held until released. */
static void hand_out(v4l2_source *v, const struct v4l2_buffer *b, size_t bytes, int64_t now, sh_source_frame *f)
{
    sh_source *s = &v->base;
    memset(f, 0, sizeof *f);
    f->camera = s->opts.camera;
    f->sequence = v->seq_base + b->sequence;
    v->next_seq = f->sequence + 1;
    if ((b->flags & V4L2_BUF_FLAG_TIMESTAMP_MASK) == V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC)
        f->timestamp_ns = (int64_t)b->timestamp.tv_sec * 1000000000 + (int64_t)b->timestamp.tv_usec * 1000;
    else
        f->timestamp_ns = now;
    /* A driver stamp that is not after the last one is stale: vivid (6.12) completes a
     * buffer before it writes its timestamp, so a prompt DQBUF can see the stamp of the
     * buffer's previous use. The dequeue time replaces it: sets need rising times. */
    if (f->timestamp_ns <= v->last_stamp && v->last_stamp) f->timestamp_ns = now;
    v->last_stamp = f->timestamp_ns;
    f->raw.format = s->format;
    f->raw.width = s->width;
    f->raw.height = s->height;
    f->raw.stride = s->stride;
    f->raw.data = v->start[b->index];
    f->raw.bytes = bytes;
    f->slot = (int)((v->generation & 0xffffff) << 6 | b->index);
    v->held[b->index] = 1;
    v->nheld++;
    s->stats.frames++;
}

static sh_status v_dequeue(sh_source *s, int timeout_ms, sh_source_frame *f, int *got)
{
    v4l2_source *v = (v4l2_source *)s;
    int64_t start = sh_monotonic_ns();
    int64_t deadline = timeout_ms < 0 ? INT64_MAX : start + (int64_t)timeout_ms * 1000000;
    for (;;) {
        int64_t now = sh_monotonic_ns();
        if (v->down) {
            try_reopen(v, now);
            if (v->down) {
                if (now >= deadline) return SH_OK;
                int64_t until = v->retry_at < deadline ? v->retry_at : deadline;
                if (v->nheld) return SH_OK; /* nothing can change until the caller releases */
                sh_source_sleep_until(until);
                continue;
            }
        }
        if (v->nheld >= v->nbuf - 1 && v->nbuf > 1)
            return sh_error_set(SH_EINVAL, "%s: %d of %d buffers held (release frames)", s->name, v->nheld, v->nbuf);
        int64_t lost_at = v->last_frame + (int64_t)timeout_of(v) * 1000000;
        int64_t wake = lost_at < deadline ? lost_at : deadline;
        int wait_ms = wake <= now ? 0 : (int)((wake - now + 999999) / 1000000);
        struct pollfd p = {.fd = v->fd, .events = POLLIN};
        int r = poll(&p, 1, wait_ms);
        if (r < 0 && errno != EINTR) {
            lose(v);
            continue;
        }
        now = sh_monotonic_ns();
        if (r <= 0) {
            if (now >= lost_at) {
                sh_error_set(SH_EIO, "%s: no frame for %d ms", s->name, timeout_of(v));
                lose(v);
                continue;
            }
            if (now >= deadline) return SH_OK;
            continue;
        }
        struct v4l2_buffer b;
        memset(&b, 0, sizeof b);
        b.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
        b.memory = V4L2_MEMORY_MMAP;
        if (xioctl(v->fd, VIDIOC_DQBUF, &b) < 0) {
            if (errno == EAGAIN && !(p.revents & (POLLERR | POLLHUP))) continue;
            sh_error_set(SH_EIO, "%s: VIDIOC_DQBUF: %s", s->name, strerror(errno));
            lose(v);
            continue;
        }
        if (b.index >= (uint32_t)v->nbuf) {
            lose(v);
            continue;
        }
        v->last_frame = now;
        count_sequence(v, b.sequence);
        size_t bytes = b.bytesused ? b.bytesused : v->length[b.index];
        if (bytes > v->length[b.index]) bytes = v->length[b.index];
        int bad = (b.flags & V4L2_BUF_FLAG_ERROR) != 0;
        if (!bad && s->format != SH_RAW_MJPEG && bytes < sh_raw_frame_size(s->format, s->width, s->height, s->stride))
            bad = 1;
        if (bad) {
            s->stats.errors++;
            if (xioctl(v->fd, VIDIOC_QBUF, &b) < 0) lose(v);
            continue;
        }
        hand_out(v, &b, bytes, now, f);
        *got = 1;
        return SH_OK;
    }
}

static sh_status v_release(sh_source *s, sh_source_frame *f)
{
    v4l2_source *v = (v4l2_source *)s;
    int index = f->slot & 63;
    unsigned gen = (unsigned)f->slot >> 6;
    if (f->slot < 0 || index >= MAX_BUFFERS || !v->held[index])
        return sh_error_set(SH_EINVAL, "%s: release of a frame not held", s->name);
    v->held[index] = 0;
    v->nheld--;
    f->slot = -1;
    if (gen != (v->generation & 0xffffff) || v->down) {
        if (v->down && !v->nheld && v->mapped) unmap_close(v);
        return SH_OK;
    }
    struct v4l2_buffer b;
    memset(&b, 0, sizeof b);
    b.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    b.memory = V4L2_MEMORY_MMAP;
    b.index = (uint32_t)index;
    if (xioctl(v->fd, VIDIOC_QBUF, &b) < 0) {
        sh_error_set(SH_EIO, "%s: VIDIOC_QBUF: %s", s->name, strerror(errno));
        lose(v);
    }
    return SH_OK;
}

static sh_status v_stop(sh_source *s)
{
    v4l2_source *v = (v4l2_source *)s;
    if (v->fd >= 0 && v->streaming) {
        int type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
        xioctl(v->fd, VIDIOC_STREAMOFF, &type);
    }
    v->streaming = 0;
    memset(v->held, 0, sizeof v->held);
    v->nheld = 0;
    v->down = 0;
    v->base.stats.online = 0;
    unmap_close(v); /* start reopens */
    return SH_OK;
}

static void v_close(sh_source *s)
{
    v4l2_source *v = (v4l2_source *)s;
    unmap_close(v);
    free(v);
}

static const sh_source_ops ops = {v_start, v_fd, v_dequeue, v_release, v_stop, v_close, NULL};

sh_status sh_source_open_v4l2(const char *path, const sh_source_options *opts, sh_source **out)
{
    if (!*path) return sh_error_set(SH_EINVAL, "v4l2: no device named");
    if (strlen(path) >= sizeof(((v4l2_source *)0)->path))
        return sh_error_set(SH_EINVAL, "v4l2:%.40s...: path too long", path);
    if (opts->format >= SH_RAW_COUNT || opts->format == SH_RAW_I420 || opts->format == SH_RAW_YUV444)
        return sh_error_set(SH_EUNSUPPORTED, "v4l2:%s: format %s not supported for capture", path,
                            sh_rawfmt_name((sh_rawfmt)opts->format));
    v4l2_source *v = calloc(1, sizeof *v);
    if (!v) return sh_error_set(SH_ENOMEM, "v4l2:%s: out of memory", path);
    v->base.ops = &ops;
    v->base.opts = *opts;
    v->fd = -1;
    snprintf(v->path, sizeof v->path, "%s", path);
    sh_status st = open_device(v, 1);
    if (st != SH_OK) {
        free(v);
        return st;
    }
    *out = &v->base;
    return SH_OK;
}
