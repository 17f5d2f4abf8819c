/* y4m:FILE — a Y4M file replayed as a camera: frame k is due at start + k/fps (real time) or at
 * once (as fast as asked); its timestamp is always the schedule's, start + k/fps, so a replay
 * feeds the pipeline the same times however fast it runs. Looping starts the file again with
 * the sequence and the schedule going on; the first frame of the new pass is flagged a
 * discontinuity unless the header says the end joins the start (XLOOP=SEAMLESS). The pollable
 * fd is a timerfd armed at the next due time. Two frame slots, allocated at open, after the
 * reader checked the header's frame size against the file's. Damage: met_damage. */
#include "source_internal.h"

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/timerfd.h>
#include <unistd.h>

#include "stillheart/y4m.h"

#define SLOTS 2

typedef struct {
    sh_source base;
    char path[256];
    sh_y4m_reader *reader;
    sh_pixfmt pixfmt;
    uint8_t *mem[SLOTS];
    sh_image img[SLOTS];
    int held[SLOTS];
    size_t frame_bytes;
    int tfd;
    int64_t t0;
    uint64_t k;
    int at_end;
    int seamless;  /* the file's end joins its start (XLOOP=SEAMLESS) */
    int restarted; /* the file started again and the scene jumps there */
    int damage_seen; /* met once: counted once, not on every pass */
} y4m_source;

static void arm(y4m_source *y, int64_t due)
{
    struct itimerspec it;
    memset(&it, 0, sizeof it);
    if (!y->base.opts.realtime || due <= 0) {
        it.it_value.tv_nsec = 1; /* relative: readable at once */
        timerfd_settime(y->tfd, 0, &it, NULL);
        return;
    }
    it.it_value.tv_sec = (time_t)(due / 1000000000);
    it.it_value.tv_nsec = (long)(due % 1000000000);
    if (!it.it_value.tv_sec && !it.it_value.tv_nsec) it.it_value.tv_nsec = 1;
    timerfd_settime(y->tfd, TFD_TIMER_ABSTIME, &it, NULL);
}

static sh_status y_start(sh_source *s)
{
    y4m_source *y = (y4m_source *)s;
    y->t0 = sh_monotonic_ns();
    y->k = 0;
    arm(y, y->t0);
    return SH_OK;
}

static int y_fd(const sh_source *s) { return ((const y4m_source *)s)->tfd; }

static sh_status rewind_reader(y4m_source *y)
{
    sh_y4m_reader_close(y->reader);
    y->reader = NULL;
    sh_status st = sh_y4m_reader_open(y->path, &y->reader);
    if (st != SH_OK) return st;
    const sh_y4m_header *h = sh_y4m_reader_header(y->reader);
    if (h->width != y->base.width || h->height != y->base.height || h->format != y->pixfmt)
        return sh_error_set(SH_EFORMAT, "y4m:%s: the file changed while looping", y->path);
    return SH_OK;
}

/* The reader stopped at damage. Where nothing good lies behind it (a torn last frame: the
 * recorder was killed) the good part is everything before it, so the replay ends or loops
 * there, counted and described once for a WARNING; where frames lie behind it, looping would
 * show a prefix as if it were the file, so the replay stops with the error. Returns SH_EEOF to
 * end the pass, or the error. */
static sh_status met_damage(y4m_source *y)
{
    sh_source *s = &y->base;
    sh_y4m_damage d;
    if (!sh_y4m_reader_damage(y->reader, &d)) return SH_EFORMAT;
    int tail = d.frames_lost >= 0 && d.frames_lost <= 1 && d.frame > 0;
    if (!y->damage_seen) {
        y->damage_seen = 1;
        s->stats.errors++;
        s->stats.damaged++;
        if (d.lost > 0) s->stats.lost_bytes += (uint64_t)d.lost;
        snprintf(s->damage, sizeof s->damage, "%s%s", sh_error_message(),
                 !tail ? " (the replay stops there)" : s->opts.loop ? " (the frames before it are looped)" : "");
    }
    if (!tail) {
        y->at_end = 1;
        return sh_error_set(SH_EFORMAT, "%s", s->damage);
    }
    return SH_EEOF;
}

static sh_status y_dequeue(sh_source *s, int timeout_ms, sh_source_frame *f, int *got)
{
    y4m_source *y = (y4m_source *)s;
    int slot = -1;
    for (int i = 0; i < SLOTS; i++)
        if (!y->held[i]) {
            slot = i;
            break;
        }
    if (slot < 0) return sh_error_set(SH_EINVAL, "%s: every frame slot is held (release frames)", s->name);
    if (y->at_end) return SH_EEOF;
    int64_t due = sh_source_schedule_ns(y->t0, y->k, s->fps_num, s->fps_den);
    if (s->opts.realtime) {
        int64_t now = sh_monotonic_ns();
        if (now < due) {
            if (timeout_ms == 0) return SH_OK;
            if (timeout_ms > 0 && now + (int64_t)timeout_ms * 1000000 < due) {
                sh_source_sleep_until(now + (int64_t)timeout_ms * 1000000);
                return SH_OK;
            }
            sh_source_sleep_until(due);
        }
    }
    uint64_t expirations;
    if (read(y->tfd, &expirations, sizeof expirations) < 0 && errno != EAGAIN) {
        /* nothing to clear */
    }
    sh_status st = sh_y4m_reader_read(y->reader, &y->img[slot]);
    for (int attempt = 0; st != SH_OK && attempt < 2; attempt++) {
        if (st == SH_EFORMAT) st = met_damage(y);
        if (st != SH_EEOF) return st;
        if (!s->opts.loop) {
            y->at_end = 1;
            if (y->damage_seen) /* the end came early: a caller's exit says so, not only a log line */
                return sh_error_set(SH_EFORMAT, "%s", s->damage);
            return SH_EEOF;
        }
        if ((st = rewind_reader(y)) != SH_OK) return st;
        y->restarted = !y->seamless;
        st = sh_y4m_reader_read(y->reader, &y->img[slot]);
    }
    if (st != SH_OK) return st == SH_EEOF ? sh_error_set(SH_EFORMAT, "%s: no frame to loop over", s->name) : st;
    y->held[slot] = 1;
    memset(f, 0, sizeof *f);
    f->camera = s->opts.camera;
    f->sequence = y->k;
    f->discontinuity = y->restarted;
    y->restarted = 0;
    f->timestamp_ns = due;
    f->raw.format = s->format;
    f->raw.width = s->width;
    f->raw.height = s->height;
    f->raw.stride = s->stride;
    f->raw.data = y->mem[slot];
    f->raw.bytes = y->frame_bytes;
    f->slot = slot;
    y->k++;
    s->stats.frames++;
    arm(y, sh_source_schedule_ns(y->t0, y->k, s->fps_num, s->fps_den));
    *got = 1;
    return SH_OK;
}

static sh_status y_release(sh_source *s, sh_source_frame *f)
{
    y4m_source *y = (y4m_source *)s;
    if (f->slot < 0 || f->slot >= SLOTS || !y->held[f->slot])
        return sh_error_set(SH_EINVAL, "%s: release of a frame not held", s->name);
    y->held[f->slot] = 0;
    f->slot = -1;
    return SH_OK;
}

static sh_status y_stop(sh_source *s)
{
    (void)s;
    return SH_OK;
}

static void y_close(sh_source *s)
{
    y4m_source *y = (y4m_source *)s;
    sh_y4m_reader_close(y->reader);
    for (int i = 0; i < SLOTS; i++) free(y->mem[i]);
    if (y->tfd >= 0) close(y->tfd);
    free(y);
}

static const sh_source_ops ops = {y_start, y_fd, y_dequeue, y_release, y_stop, y_close};

sh_status sh_source_open_y4m(const char *path, const sh_source_options *opts, sh_source **out)
{
    if (!*path) return sh_error_set(SH_EINVAL, "y4m: no file named");
    if (strlen(path) >= sizeof(((y4m_source *)0)->path))
        return sh_error_set(SH_EINVAL, "y4m:%.40s...: path too long", path);
    y4m_source *y = calloc(1, sizeof *y);
    if (!y) return sh_error_set(SH_ENOMEM, "y4m:%s: out of memory", path);
    y->base.ops = &ops;
    y->base.opts = *opts;
    y->tfd = -1;
    snprintf(y->path, sizeof y->path, "%s", path);
    sh_status st = sh_y4m_reader_open(path, &y->reader);
    if (st != SH_OK) {
        y_close(&y->base);
        return st;
    }
    const sh_y4m_header *h = sh_y4m_reader_header(y->reader);
    y->pixfmt = h->format;
    y->seamless = sh_y4m_header_has_tag(h, SH_Y4M_LOOP_SEAMLESS);
    y->base.format = h->format == SH_PIX_GRAY8 ? SH_RAW_GREY : h->format == SH_PIX_I420 ? SH_RAW_I420
                                                                                       : SH_RAW_YUV444;
    y->base.width = h->width;
    y->base.height = h->height;
    y->base.stride = h->width;
    y->base.fps_num = h->fps_num > 0 && h->fps_den > 0 ? h->fps_num : opts->fps_num;
    y->base.fps_den = h->fps_num > 0 && h->fps_den > 0 ? h->fps_den : opts->fps_den;
    if (y->base.fps_num <= 0 || y->base.fps_den <= 0) y->base.fps_num = 25, y->base.fps_den = 1;
    if (sh_y4m_reader_whole_frames(y->reader) == 0) { /* before its frame size is allocated */
        y_close(&y->base);
        return sh_error_set(SH_EFORMAT, "y4m:%s: no frame in the file", path);
    }
    y->frame_bytes = sh_image_packed_size(h->format, h->width, h->height);
    if (h->format == SH_PIX_I420 && ((h->width | h->height) & 1)) {
        y_close(&y->base);
        return sh_error_set(SH_EUNSUPPORTED, "y4m:%s: odd size %dx%d", path, h->width, h->height);
    }
    for (int i = 0; i < SLOTS; i++) {
        y->mem[i] = malloc(y->frame_bytes);
        if (!y->mem[i] || sh_image_wrap(&y->img[i], h->format, h->width, h->height, y->mem[i]) != SH_OK) {
            y_close(&y->base);
            return sh_error_set(SH_ENOMEM, "y4m:%s: out of memory", path);
        }
    }
    y->tfd = timerfd_create(CLOCK_MONOTONIC, TFD_NONBLOCK | TFD_CLOEXEC);
    if (y->tfd < 0) {
        int e = errno;
        y_close(&y->base);
        return sh_error_set(SH_EIO, "y4m:%s: timerfd: %s", path, strerror(e));
    }
    *out = &y->base;
    return SH_OK;
}
