/* sh_source: spec parsing and dispatch to the backends. */
#include "source_internal.h"

#include <errno.h>
#include <stdio.h>
#include <string.h>
#include <time.h>

void sh_source_options_default(sh_source_options *o)
{
    memset(o, 0, sizeof *o);
    o->format = -1;
    o->exposure = o->gain = o->white_balance = SH_SOURCE_CTRL_UNSET;
    o->realtime = 1;
    o->max_frame_pixels = SH_FRAME_PIXELS_DEFAULT;
}

long long sh_source_max_pixels(const sh_source_options *o)
{
    return o->max_frame_pixels > 0 ? o->max_frame_pixels : SH_FRAME_PIXELS_DEFAULT;
}

sh_status sh_source_check_pixels(const sh_source_options *o, const char *kind, const char *path, int width,
                                 int height)
{
    char name[300];
    snprintf(name, sizeof name, "%s:%s", kind, path);
    return sh_image_check_pixels(name, width, height, sh_source_max_pixels(o));
}

void sh_source_sleep_until(int64_t t)
{
    struct timespec ts = {(time_t)(t / 1000000000), (long)(t % 1000000000)};
    while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, NULL) == EINTR) {
    }
}

int64_t sh_source_schedule_ns(int64_t t0, uint64_t k, int num, int den)
{
    /* k/num = q + r/num: q whole periods of num frames (den seconds each), r frames left */
    uint64_t q = k / (uint64_t)num, r = k % (uint64_t)num;
    return t0 + (int64_t)(q * (uint64_t)den * 1000000000u) +
           (int64_t)(r * (uint64_t)den * 1000000000u / (uint64_t)num);
}

sh_status sh_source_open(const char *spec, const sh_source_options *opts, sh_source **out)
{
    if (!spec || !out) return sh_error_set(SH_EINVAL, "source: no spec");
    *out = NULL;
    sh_source_options def;
    if (!opts) {
        sh_source_options_default(&def);
        opts = &def;
    }
    if (strlen(spec) >= sizeof(((sh_source *)0)->name))
        return sh_error_set(SH_EINVAL, "source '%.40s...': spec too long", spec);
    sh_status st;
    if (!strncmp(spec, "y4m:", 4)) st = sh_source_open_y4m(spec + 4, opts, out);
    else if (!strncmp(spec, "v4l2:", 5)) st = sh_source_open_v4l2(spec + 5, opts, out);
    else if (!strncmp(spec, "rec:", 4)) st = sh_source_open_rec(spec + 4, opts, out);
    else if (!strncmp(spec, "libcamera:", 10)) st = sh_source_open_libcamera(spec + 10, opts, out);
    else
        return sh_error_set(SH_EINVAL, "source '%s': unknown kind (v4l2:DEVICE, libcamera:NAME, y4m:FILE, rec:DIR)", spec);
    if (st != SH_OK) return st;
    snprintf((*out)->name, sizeof (*out)->name, "%s", spec);
    return SH_OK;
}

sh_status sh_source_format(const sh_source *s, sh_rawfmt *format, int *width, int *height, int *fps_num,
                           int *fps_den)
{
    if (!s) return sh_error_set(SH_EINVAL, "source: NULL");
    if (format) *format = s->format;
    if (width) *width = s->width;
    if (height) *height = s->height;
    if (fps_num) *fps_num = s->fps_num;
    if (fps_den) *fps_den = s->fps_den;
    return SH_OK;
}

int sh_source_stride(const sh_source *s) { return s ? s->stride : 0; }

sh_status sh_source_start(sh_source *s) { return sh_source_start_at(s, sh_monotonic_ns()); }

sh_status sh_source_start_at(sh_source *s, int64_t clock_ns)
{
    if (!s) return sh_error_set(SH_EINVAL, "source: NULL");
    if (s->started) return SH_OK;
    s->start_ns = clock_ns;
    sh_status st = s->ops->start(s);
    if (st == SH_OK) s->started = 1;
    return st;
}

int sh_source_fd(const sh_source *s) { return s && s->started ? s->ops->fd(s) : -1; }

sh_status sh_source_dequeue(sh_source *s, int timeout_ms, sh_source_frame *frame, int *got)
{
    if (got) *got = 0;
    if (!s || !frame || !got) return sh_error_set(SH_EINVAL, "source: NULL argument");
    if (!s->started) return sh_error_set(SH_EINVAL, "%s: dequeue before start", s->name);
    return s->ops->dequeue(s, timeout_ms, frame, got);
}

sh_status sh_source_dequeue_into(sh_source *s, int timeout_ms, sh_image *dst, sh_source_frame *frame, int *got,
                                 int *direct)
{
    if (direct) *direct = 0;
    if (!dst || !direct) {
        if (got) *got = 0;
        return sh_error_set(SH_EINVAL, "source: NULL argument");
    }
    if (!s || !s->started || !s->ops->dequeue_into) return sh_source_dequeue(s, timeout_ms, frame, got);
    if (got) *got = 0;
    if (!frame || !got) return sh_error_set(SH_EINVAL, "source: NULL argument");
    return s->ops->dequeue_into(s, timeout_ms, dst, frame, got, direct);
}

sh_status sh_source_release(sh_source *s, sh_source_frame *frame)
{
    if (!s || !frame) return sh_error_set(SH_EINVAL, "source: NULL argument");
    return s->ops->release(s, frame);
}

sh_status sh_source_stop(sh_source *s)
{
    if (!s) return sh_error_set(SH_EINVAL, "source: NULL");
    if (!s->started) return SH_OK;
    s->started = 0;
    return s->ops->stop(s);
}

void sh_source_close(sh_source *s)
{
    if (!s) return;
    if (s->started) sh_source_stop(s);
    s->ops->close(s);
}

void sh_source_get_stats(const sh_source *s, sh_source_stats *st)
{
    if (!s || !st) return;
    *st = s->stats;
}

const char *sh_source_name(const sh_source *s) { return s ? s->name : ""; }

const char *sh_source_damage(const sh_source *s) { return s ? s->damage : ""; }
