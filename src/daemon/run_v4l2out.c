/* [sink] v4l2: what is shown, also to a V4L2 output device (a v4l2loopback node), so OBS,
 * GStreamer's v4l2src, ffmpeg and video-conferencing tools take it as a camera.
 *
 * Read/write I/O, not mmap buffers: one write() is one frame to v4l2loopback, and a write never
 * waits for a reader (the driver overwrites its ring; a reader that falls behind sees gaps in the
 * buffers' sequence numbers). The descriptor is still non-blocking, so a driver that would wait
 * cannot hold up the display: a write it refuses (EAGAIN) or takes only in part is counted as a
 * frame not taken and the next frame is tried. The format is set once at open, VIDIOC_S_FMT on
 * the output queue with the frames' size and layout, and read back: a driver that changes any of
 * it (v4l2loopback keeps the format another writer or a reader holds, and clamps sizes to its
 * max_width/max_height) is refused, naming what it offered, since a consumer would read the bytes
 * with the wrong geometry. The frame's status (stabilized, degraded, raw) is not in V4L2: it is in
 * the display segment's header (docs/daemon.md). */
#include <errno.h>
#include <fcntl.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/ioctl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <linux/videodev2.h>

#include "run_sink.h"
#include "stillheart/config.h"

struct run_v4l2out {
    char path[SH_CONFIG_STR];
    int fd;
    uint8_t *buf;   /* one frame, planes packed as V4L2 lays them out */
    size_t size;
    sh_pixfmt format;
    int width, height;
    uint64_t written, not_taken;
};

static void fourcc_text(uint32_t f, char out[5])
{
    for (int i = 0; i < 4; i++) {
        char c = (char)((f >> (8 * i)) & 0xff);
        out[i] = c > 32 && c < 127 ? c : '?';
    }
    out[4] = 0;
}

static int xioctl(int fd, unsigned long req, void *arg)
{
    int r;
    do r = ioctl(fd, req, arg);
    while (r < 0 && errno == EINTR);
    return r;
}

/* The device opened and asked: a character device, V4L2, with an output queue. */
static sh_status open_output(run_v4l2out *o)
{
    struct stat sb;
    if (stat(o->path, &sb) != 0) return sh_error_set(SH_EIO, "%s: %s", o->path, strerror(errno));
    if (!S_ISCHR(sb.st_mode))
        return sh_error_set(SH_EINVAL, "%s: not a device (a V4L2 output device such as a v4l2loopback /dev/videoN)",
                            o->path);
    o->fd = open(o->path, O_RDWR | O_NONBLOCK | O_CLOEXEC);
    if (o->fd < 0) return sh_error_set(SH_EIO, "%s: %s", o->path, strerror(errno));
    struct v4l2_capability cap;
    memset(&cap, 0, sizeof cap);
    if (xioctl(o->fd, VIDIOC_QUERYCAP, &cap) != 0)
        return sh_error_set(SH_EINVAL, "%s: not a V4L2 device (VIDIOC_QUERYCAP: %s)", o->path, strerror(errno));
    uint32_t caps = cap.capabilities & V4L2_CAP_DEVICE_CAPS ? cap.device_caps : cap.capabilities;
    if (!(caps & V4L2_CAP_VIDEO_OUTPUT))
        return sh_error_set(SH_EINVAL, "%s: not a V4L2 output device (%s, driver %s, has no video output; "
                            "a v4l2loopback device is one)", o->path, (const char *)cap.card, (const char *)cap.driver);
    if (!(caps & V4L2_CAP_READWRITE))
        return sh_error_set(SH_EINVAL, "%s: the output device (%s) takes no write() of frames", o->path,
                            (const char *)cap.card);
    return SH_OK;
}

/* VIDIOC_S_FMT on the output queue with the frames' geometry, refused unless taken as asked. */
static sh_status set_format(run_v4l2out *o, uint32_t fourcc, int channels, int fps_num, int fps_den)
{
    struct v4l2_format f;
    memset(&f, 0, sizeof f);
    f.type = V4L2_BUF_TYPE_VIDEO_OUTPUT;
    f.fmt.pix.width = (uint32_t)o->width;
    f.fmt.pix.height = (uint32_t)o->height;
    f.fmt.pix.pixelformat = fourcc;
    f.fmt.pix.field = V4L2_FIELD_NONE;
    f.fmt.pix.bytesperline = (uint32_t)(o->width * channels);
    f.fmt.pix.sizeimage = (uint32_t)o->size;
    char want[5], got[5];
    fourcc_text(fourcc, want);
    if (xioctl(o->fd, VIDIOC_S_FMT, &f) != 0)
        return sh_error_set(SH_EINVAL, "%s: format %dx%d %s refused (VIDIOC_S_FMT: %s)", o->path, o->width,
                            o->height, want, strerror(errno));
    fourcc_text(f.fmt.pix.pixelformat, got);
    if (f.fmt.pix.width != (uint32_t)o->width || f.fmt.pix.height != (uint32_t)o->height ||
        f.fmt.pix.pixelformat != fourcc)
        return sh_error_set(SH_EINVAL, "%s: format %dx%d %s refused: the device sets %ux%u %s (its size limits, or "
                            "the format another writer or a reader holds)", o->path, o->width, o->height, want,
                            f.fmt.pix.width, f.fmt.pix.height, got);
    /* rows as the frames are packed; v4l2loopback rounds sizeimage up to whole pages */
    if (f.fmt.pix.bytesperline != (uint32_t)(o->width * channels) || f.fmt.pix.sizeimage < o->size)
        return sh_error_set(SH_EINVAL, "%s: format %dx%d %s refused: the device wants %u bytes a row and %u a "
                            "frame, the frames have %d and %zu", o->path, o->width, o->height, want,
                            f.fmt.pix.bytesperline, f.fmt.pix.sizeimage, o->width * channels, o->size);
    /* the frame rate consumers see (a hint: a driver without it still takes the frames) */
    struct v4l2_streamparm parm;
    memset(&parm, 0, sizeof parm);
    parm.type = V4L2_BUF_TYPE_VIDEO_OUTPUT;
    if (fps_num > 0 && fps_den > 0) {
        parm.parm.output.timeperframe.numerator = (uint32_t)fps_den;
        parm.parm.output.timeperframe.denominator = (uint32_t)fps_num;
        (void)xioctl(o->fd, VIDIOC_S_PARM, &parm);
    }
    return SH_OK;
}

sh_status run_v4l2out_open(const char *path, const sh_y4m_header *hdr, run_v4l2out **out)
{
    *out = NULL;
    uint32_t fourcc;
    switch (hdr->format) {
    case SH_PIX_GRAY8: fourcc = V4L2_PIX_FMT_GREY; break;
    case SH_PIX_RGB24: fourcc = V4L2_PIX_FMT_RGB24; break;
    case SH_PIX_I420: fourcc = V4L2_PIX_FMT_YUV420; break;
    default:
        /* V4L2's planar 4:4:4 is multi-planar only (YUV444M), which write() cannot carry */
        return sh_error_set(SH_EINVAL, "%s: %s frames have no single-buffer V4L2 format (GRAY8, RGB24 and I420 do)",
                            path, sh_pixfmt_name(hdr->format));
    }
    run_v4l2out *o = calloc(1, sizeof *o);
    if (!o) return sh_error_set(SH_ENOMEM, "v4l2: out of memory");
    snprintf(o->path, sizeof o->path, "%s", path);
    o->fd = -1;
    o->format = hdr->format;
    o->width = hdr->width;
    o->height = hdr->height;
    o->size = sh_image_packed_size(hdr->format, hdr->width, hdr->height);
    sh_status st = (o->buf = malloc(o->size)) ? SH_OK : sh_error_set(SH_ENOMEM, "v4l2: out of memory");
    if (st == SH_OK) st = open_output(o);
    if (st == SH_OK) st = set_format(o, fourcc, sh_pixfmt_channels(hdr->format), hdr->fps_num, hdr->fps_den);
    if (st != SH_OK) {
        run_v4l2out_close(o);
        return st;
    }
    *out = o;
    return SH_OK;
}

const char *run_v4l2out_path(const run_v4l2out *o) { return o->path; }

sh_status run_v4l2out_write(run_v4l2out *o, const sh_image *shown)
{
    if (shown->format != o->format || shown->width != o->width || shown->height != o->height)
        return sh_error_set(SH_EINVAL, "%s: a %dx%d frame for a %dx%d output", o->path, shown->width, shown->height,
                            o->width, o->height);
    uint8_t *at = o->buf;
    for (int p = 0; p < shown->num_planes; p++) {
        const sh_plane *pl = &shown->plane[p];
        size_t row = (size_t)pl->width * (size_t)(p ? 1 : sh_pixfmt_channels(o->format));
        for (int y = 0; y < pl->height; y++, at += row) memcpy(at, pl->data + (size_t)y * (size_t)pl->stride, row);
    }
    ssize_t n;
    do n = write(o->fd, o->buf, o->size);
    while (n < 0 && errno == EINTR);
    if (n == (ssize_t)o->size) {
        o->written++;
        return SH_OK;
    }
    if (n >= 0 || errno == EAGAIN || errno == EBUSY || errno == ENOBUFS) {
        o->not_taken++;
        return SH_OK;
    }
    return sh_error_set(SH_EIO, "%s: write: %s", o->path, strerror(errno));
}

uint64_t run_v4l2out_written(const run_v4l2out *o) { return o->written; }

uint64_t run_v4l2out_not_taken(const run_v4l2out *o) { return o->not_taken; }

void run_v4l2out_close(run_v4l2out *o)
{
    if (!o) return;
    if (o->fd >= 0) close(o->fd);
    free(o->buf);
    free(o);
}
