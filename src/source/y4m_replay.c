/* y4m:FILE — a Y4M file replayed as a camera: frame k is due at start + k/fps (real time) or at
 * once (as fast as asked); its timestamp is always the schedule's, start + k/fps, so a replay
 * feeds the pipeline the same times however fast it runs. Looping starts the file again with
 * the sequence and the schedule going on; the first frame of the new pass is flagged a
 * discontinuity unless the header says the end joins the start (XLOOP=SEAMLESS). The pollable
 * fd is a timerfd armed at the next due time. Two frame slots, allocated at open, after the
 * reader checked the header's frame size against the file's and against the options' bound on
 * a frame's pixels (a pipe's size cannot be known). Damage: met_damage. */
#include "source_internal.h"

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "stillheart/y4m.h"

typedef struct {
    sh_replay rp; /* first: the base source, the timer and the slots */
    char path[256];
    sh_y4m_reader *reader;
    sh_pixfmt pixfmt;
    uint8_t *mem[SH_REPLAY_SLOTS];
    sh_image img[SH_REPLAY_SLOTS];
    size_t frame_bytes;
    int64_t t0;
    uint64_t k;
    int at_end;
    int seamless;  /* the file's end joins its start (XLOOP=SEAMLESS) */
    int restarted; /* the file started again and the scene jumps there */
    int damage_seen; /* met once: counted once, not on every pass */
} y4m_source;

static sh_status y_start(sh_source *s)
{
    y4m_source *y = (y4m_source *)s;
    y->t0 = s->start_ns;
    y->k = 0;
    sh_replay_arm(&y->rp, y->t0);
    return SH_OK;
}

static sh_status rewind_reader(y4m_source *y)
{
    sh_y4m_reader_close(y->reader);
    y->reader = NULL;
    sh_status st = sh_y4m_reader_open_max(y->path, sh_source_max_pixels(&y->rp.base.opts), &y->reader);
    if (st != SH_OK) return st;
    const sh_y4m_header *h = sh_y4m_reader_header(y->reader);
    if (h->width != y->rp.base.width || h->height != y->rp.base.height || h->format != y->pixfmt)
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
    sh_source *s = &y->rp.base;
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

/* The next frame into the slot's image, or into dst (a caller's image of the file's format and
 * size: sh_source_dequeue_into), the slot then held without its memory. */
static sh_status y_read(sh_source *s, int timeout_ms, sh_image *dst, sh_source_frame *f, int *got)
{
    y4m_source *y = (y4m_source *)s;
    int slot;
    sh_status st = sh_replay_slot(&y->rp, &slot);
    if (st != SH_OK) return st;
    if (y->at_end) return SH_EEOF;
    int64_t due = sh_source_schedule_ns(y->t0, y->k, s->fps_num, s->fps_den);
    if (!sh_replay_wait(&y->rp, due, timeout_ms)) return SH_OK;
    sh_image *img = dst ? dst : &y->img[slot];
    sh_chroma_siting kept = img->siting;
    st = sh_y4m_reader_read(y->reader, img);
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
        st = sh_y4m_reader_read(y->reader, img);
    }
    if (st != SH_OK) return st == SH_EEOF ? sh_error_set(SH_EFORMAT, "%s: no frame to loop over", s->name) : st;
    /* dst as pixconv would have left it: a raw I420 frame's chroma centred (a raw frame carries no
     * siting), a GRAY8 image's siting untouched */
    if (dst) dst->siting = dst->format == SH_PIX_I420 ? SH_CHROMA_CENTER : kept;
    sh_replay_hand_out(&y->rp, slot, dst ? NULL : y->mem[slot], dst ? 0 : y->frame_bytes, y->k, due, y->restarted, f);
    y->restarted = 0;
    y->k++;
    sh_replay_arm(&y->rp, sh_source_schedule_ns(y->t0, y->k, s->fps_num, s->fps_den));
    *got = 1;
    return SH_OK;
}

static sh_status y_dequeue(sh_source *s, int timeout_ms, sh_source_frame *f, int *got)
{
    return y_read(s, timeout_ms, NULL, f, got);
}

/* Straight into dst when it is what pixconv would make of the file's frames: the same format
 * (I420 or GRAY8; 4:4:4 files are converted to I420) and size. */
static sh_status y_dequeue_into(sh_source *s, int timeout_ms, sh_image *dst, sh_source_frame *f, int *got,
                                int *direct)
{
    y4m_source *y = (y4m_source *)s;
    *direct = dst->format == y->pixfmt && (dst->format == SH_PIX_I420 || dst->format == SH_PIX_GRAY8) &&
              dst->width == s->width && dst->height == s->height;
    return y_read(s, timeout_ms, *direct ? dst : NULL, f, got);
}

static void y_close(sh_source *s)
{
    y4m_source *y = (y4m_source *)s;
    sh_y4m_reader_close(y->reader);
    for (int i = 0; i < SH_REPLAY_SLOTS; i++) free(y->mem[i]);
    sh_replay_close(&y->rp);
    free(y);
}

static const sh_source_ops ops = {y_start, sh_replay_fd, y_dequeue, sh_replay_release, sh_replay_stop, y_close,
                                   y_dequeue_into};

sh_status sh_source_open_y4m(const char *path, const sh_source_options *opts, sh_source **out)
{
    if (!*path) return sh_error_set(SH_EINVAL, "y4m: no file named");
    if (strlen(path) >= sizeof(((y4m_source *)0)->path))
        return sh_error_set(SH_EINVAL, "y4m:%.40s...: path too long", path);
    y4m_source *y = calloc(1, sizeof *y);
    if (!y) return sh_error_set(SH_ENOMEM, "y4m:%s: out of memory", path);
    sh_replay_init(&y->rp, &ops, opts);
    snprintf(y->path, sizeof y->path, "%s", path);
    sh_status st = sh_y4m_reader_open_max(path, sh_source_max_pixels(opts), &y->reader);
    if (st != SH_OK) {
        y_close(&y->rp.base);
        return st;
    }
    const sh_y4m_header *h = sh_y4m_reader_header(y->reader);
    y->pixfmt = h->format;
    y->seamless = sh_y4m_header_has_tag(h, SH_Y4M_LOOP_SEAMLESS);
    y->rp.base.format = h->format == SH_PIX_GRAY8 ? SH_RAW_GREY : h->format == SH_PIX_I420 ? SH_RAW_I420
                                                                                       : SH_RAW_YUV444;
    y->rp.base.width = h->width;
    y->rp.base.height = h->height;
    y->rp.base.stride = h->width;
    y->rp.base.fps_num = h->fps_num > 0 && h->fps_den > 0 ? h->fps_num : opts->fps_num;
    y->rp.base.fps_den = h->fps_num > 0 && h->fps_den > 0 ? h->fps_den : opts->fps_den;
    if (y->rp.base.fps_num <= 0 || y->rp.base.fps_den <= 0) y->rp.base.fps_num = 25, y->rp.base.fps_den = 1;
    y->frame_bytes = sh_image_packed_size(h->format, h->width, h->height);
    if (h->format == SH_PIX_I420 && ((h->width | h->height) & 1)) {
        y_close(&y->rp.base);
        return sh_error_set(SH_EUNSUPPORTED, "y4m:%s: odd size %dx%d", path, h->width, h->height);
    }
    if (sh_y4m_reader_whole_frames(y->reader) == 0) { /* before its frame size is allocated */
        y_close(&y->rp.base);
        return sh_error_set(SH_EFORMAT, "y4m:%s: no frame in the file", path);
    }
    for (int i = 0; i < SH_REPLAY_SLOTS; i++) {
        y->mem[i] = malloc(y->frame_bytes);
        if (!y->mem[i] || sh_image_wrap(&y->img[i], h->format, h->width, h->height, y->mem[i]) != SH_OK) {
            y_close(&y->rp.base);
            return sh_error_set(SH_ENOMEM, "y4m:%s: out of memory", path);
        }
    }
    if (sh_replay_timer_create(&y->rp) < 0) {
        int e = errno;
        y_close(&y->rp.base);
        return sh_error_set(SH_EIO, "y4m:%s: timerfd: %s", path, strerror(e));
    }
    *out = &y->rp.base;
    return SH_OK;
}
