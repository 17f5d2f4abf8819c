/* rec:DIR — one camera of a stillheart recording replayed as a source. Frames come with the
 * recorded spacing: frame i is due at start + (t_i - t_0) in real time (or at once), and is
 * timestamped so, on today's monotonic clock. Looping starts again one mean frame interval after
 * the last frame. The frames are copied out of the reader into two slots allocated at open.
 * Damage: the reader resyncs past it, so the replay (and a loop) covers every good record; the
 * damage is counted and described (note_damage) and, without loop, the end is an error. */
#include "source_internal.h"

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/timerfd.h>
#include <unistd.h>

#include "stillheart/record.h"

#define SLOTS 2

typedef struct {
    sh_source base;
    char path[256];
    sh_rec_reader *reader;
    sh_rec_stream stream;
    uint8_t *mem[SLOTS];
    size_t cap;
    int held[SLOTS];
    int tfd;
    int64_t start, first_ts, last_ts, offset;
    uint64_t count_in_pass;
    int have_first;
    /* the next frame, read ahead so that its due time is known */
    int have_next;
    uint64_t next_seq;
    int64_t next_ts;
    size_t next_bytes;
    uint8_t *next_mem; /* one of the slots' twin: a third buffer */
    uint64_t sequence_out;
    int at_end;
    int restarted; /* the recording started again: a camera's recording never joins its start */
    int passes;    /* completed: damage is counted in the first pass only */
    uint64_t seen_skipped, seen_lost; /* the reader's damage counters already reported */
    int end_damaged; /* a replay without loop that met damage ends in the error, once */
} rec_source;

/* Reports new damage the reader skipped (resync goes on past it, so the replay does too):
 * counted in the stats and described for the caller's WARNING, in the first pass only. */
static void note_damage(rec_source *r)
{
    uint64_t sk = sh_rec_reader_skipped(r->reader), lost = sh_rec_reader_lost_bytes(r->reader);
    if (r->passes || lost == r->seen_lost) return;
    sh_source *s = &r->base;
    s->stats.damaged++;
    s->stats.errors += sk - r->seen_skipped;
    s->stats.lost_bytes = lost;
    snprintf(s->damage, sizeof s->damage,
             "rec:%s: damaged recording: %llu record(s) skipped%s, %llu bytes lost so far; the replay goes on "
             "with the good records",
             r->path, (unsigned long long)sk, sh_rec_reader_truncated(r->reader) ? " and a torn last record" : "",
             (unsigned long long)lost);
    r->seen_skipped = sk;
    r->seen_lost = lost;
}

static sh_status read_ahead(rec_source *r)
{
    sh_rec_record rec;
    for (;;) {
        sh_status st = sh_rec_reader_next(r->reader, &rec);
        note_damage(r);
        if (st == SH_EEOF) {
            if (!r->base.opts.loop || !r->count_in_pass) {
                r->have_next = 0;
                r->at_end = 1;
                r->end_damaged = r->base.stats.damaged != 0;
                return SH_OK;
            }
            r->passes++;
            sh_rec_reader_close(r->reader);
            r->reader = NULL;
            if ((st = sh_rec_reader_open(r->path, &r->reader)) != SH_OK) return st;
            int64_t span = r->last_ts - r->first_ts;
            int64_t step = r->count_in_pass > 1 ? span / (int64_t)(r->count_in_pass - 1) : 40000000;
            r->offset += span + step;
            r->count_in_pass = 0;
            r->restarted = 1;
            continue;
        }
        if (st != SH_OK) return st;
        if (rec.type != SH_REC_FRAME || rec.camera != r->stream.camera) continue;
        if (rec.raw.bytes > r->cap) {
            r->base.stats.errors++;
            continue;
        }
        if (!r->have_first) r->first_ts = rec.timestamp_ns, r->have_first = 1;
        r->last_ts = rec.timestamp_ns;
        r->count_in_pass++;
        memcpy(r->next_mem, rec.raw.data, rec.raw.bytes);
        r->next_bytes = rec.raw.bytes;
        r->next_seq = rec.sequence;
        r->next_ts = rec.timestamp_ns;
        r->have_next = 1;
        return SH_OK;
    }
}

static int64_t due_of(const rec_source *r) { return r->start + (r->next_ts - r->first_ts) + r->offset; }

static void arm(rec_source *r)
{
    struct itimerspec it;
    memset(&it, 0, sizeof it);
    int64_t due = due_of(r);
    if (!r->base.opts.realtime || !r->have_next || due <= 0) {
        it.it_value.tv_nsec = 1;
        timerfd_settime(r->tfd, 0, &it, NULL);
        return;
    }
    it.it_value.tv_sec = (time_t)(due / 1000000000);
    it.it_value.tv_nsec = (long)(due % 1000000000);
    if (!it.it_value.tv_sec && !it.it_value.tv_nsec) it.it_value.tv_nsec = 1;
    timerfd_settime(r->tfd, TFD_TIMER_ABSTIME, &it, NULL);
}

static sh_status r_start(sh_source *s)
{
    rec_source *r = (rec_source *)s;
    r->start = sh_monotonic_ns();
    arm(r);
    return SH_OK;
}

static int r_fd(const sh_source *s) { return ((const rec_source *)s)->tfd; }

static sh_status r_dequeue(sh_source *s, int timeout_ms, sh_source_frame *f, int *got)
{
    rec_source *r = (rec_source *)s;
    int slot = -1;
    for (int i = 0; i < SLOTS; i++)
        if (!r->held[i]) {
            slot = i;
            break;
        }
    if (slot < 0) return sh_error_set(SH_EINVAL, "%s: every frame slot is held (release frames)", s->name);
    if (!r->have_next && r->end_damaged) { /* the end of a damaged recording is an error: a caller's exit says so */
        r->end_damaged = 0;
        return sh_error_set(SH_EFORMAT, "%s", s->damage);
    }
    if (!r->have_next) return SH_EEOF;
    int64_t due = due_of(r);
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
    if (read(r->tfd, &expirations, sizeof expirations) < 0 && errno != EAGAIN) {
        /* nothing to clear */
    }
    /* hand out the read-ahead buffer; the slot's buffer becomes the next read-ahead one */
    uint8_t *out = r->next_mem;
    r->next_mem = r->mem[slot];
    r->mem[slot] = out;
    memset(f, 0, sizeof *f);
    f->camera = s->opts.camera;
    f->sequence = r->sequence_out++;
    f->discontinuity = r->restarted; /* read ahead at the previous frame: this one opens a pass */
    r->restarted = 0;
    f->timestamp_ns = due;
    f->raw.format = s->format;
    f->raw.width = s->width;
    f->raw.height = s->height;
    f->raw.stride = s->stride;
    f->raw.data = out;
    f->raw.bytes = r->next_bytes;
    f->slot = slot;
    r->held[slot] = 1;
    s->stats.frames++;
    sh_status st = read_ahead(r);
    if (st != SH_OK) {
        r->held[slot] = 0;
        return st;
    }
    arm(r);
    *got = 1;
    return SH_OK;
}

static sh_status r_release(sh_source *s, sh_source_frame *f)
{
    rec_source *r = (rec_source *)s;
    if (f->slot < 0 || f->slot >= SLOTS || !r->held[f->slot])
        return sh_error_set(SH_EINVAL, "%s: release of a frame not held", s->name);
    r->held[f->slot] = 0;
    f->slot = -1;
    return SH_OK;
}

static sh_status r_stop(sh_source *s)
{
    (void)s;
    return SH_OK;
}

static void r_close(sh_source *s)
{
    rec_source *r = (rec_source *)s;
    sh_rec_reader_close(r->reader);
    for (int i = 0; i < SLOTS; i++) free(r->mem[i]);
    free(r->next_mem);
    if (r->tfd >= 0) close(r->tfd);
    free(r);
}

static const sh_source_ops ops = {r_start, r_fd, r_dequeue, r_release, r_stop, r_close};

sh_status sh_source_open_rec(const char *path, const sh_source_options *opts, sh_source **out)
{
    if (!*path) return sh_error_set(SH_EINVAL, "rec: no recording named");
    if (strlen(path) >= sizeof(((rec_source *)0)->path))
        return sh_error_set(SH_EINVAL, "rec:%.40s...: path too long", path);
    rec_source *r = calloc(1, sizeof *r);
    if (!r) return sh_error_set(SH_ENOMEM, "rec:%s: out of memory", path);
    r->base.ops = &ops;
    r->base.opts = *opts;
    r->tfd = -1;
    snprintf(r->path, sizeof r->path, "%s", path);
    sh_status st = sh_rec_reader_open(path, &r->reader);
    if (st != SH_OK) {
        r_close(&r->base);
        return st;
    }
    const sh_rec_stream *s = sh_rec_reader_stream(r->reader, opts->camera);
    if (!s) {
        r_close(&r->base);
        return sh_error_set(SH_EINVAL, "rec:%s: no camera %d in the recording", path, opts->camera);
    }
    r->stream = *s;
    r->base.format = s->format;
    r->base.width = s->width;
    r->base.height = s->height;
    r->base.stride = s->stride;
    r->base.fps_num = s->fps_num;
    r->base.fps_den = s->fps_den;
    r->cap = s->format == SH_RAW_MJPEG ? (size_t)s->width * s->height * 3 + (1u << 20)
                                       : sh_raw_frame_size(s->format, s->width, s->height, s->stride) + (1u << 20);
    for (int i = 0; i < SLOTS; i++) r->mem[i] = malloc(r->cap);
    r->next_mem = malloc(r->cap);
    r->tfd = timerfd_create(CLOCK_MONOTONIC, TFD_NONBLOCK | TFD_CLOEXEC);
    if (!r->mem[0] || !r->mem[1] || !r->next_mem || r->tfd < 0) {
        r_close(&r->base);
        return sh_error_set(SH_ENOMEM, "rec:%s: out of memory", path);
    }
    if ((st = read_ahead(r)) != SH_OK) {
        r_close(&r->base);
        return st;
    }
    *out = &r->base;
    return SH_OK;
}
