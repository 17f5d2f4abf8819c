/* rec:DIR — one camera of a stillheart recording replayed as a source. Frames come with the
 * recorded spacing: frame i is due at start + (t_i - t_0) in real time (or at once), and is
 * timestamped so, on today's monotonic clock. Looping starts again one mean frame interval after
 * the last frame. The frames are copied out of the reader into two slots allocated at open.
 * Damage: the reader resyncs past it, so the replay (and a loop) covers every good record; the
 * damage is counted and described (note_damage) and, without loop, the end is an error. */
#include "source_internal.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "stillheart/record.h"

typedef struct {
    sh_replay rp; /* first: the base source, the timer and the slots */
    char path[256];
    sh_rec_reader *reader;
    sh_rec_stream stream;
    uint8_t *mem[SH_REPLAY_SLOTS];
    size_t cap;
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
    sh_source *s = &r->rp.base;
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
            if (!r->rp.base.opts.loop || !r->count_in_pass) {
                r->have_next = 0;
                r->at_end = 1;
                r->end_damaged = r->rp.base.stats.damaged != 0;
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
            r->rp.base.stats.errors++;
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

/* At the end (nothing read ahead) the timer is readable at once: the next dequeue says so. */
static void arm(rec_source *r) { sh_replay_arm(&r->rp, r->have_next ? due_of(r) : 0); }

static sh_status r_start(sh_source *s)
{
    rec_source *r = (rec_source *)s;
    r->start = s->start_ns;
    arm(r);
    return SH_OK;
}

static sh_status r_dequeue(sh_source *s, int timeout_ms, sh_source_frame *f, int *got)
{
    rec_source *r = (rec_source *)s;
    int slot;
    sh_status st = sh_replay_slot(&r->rp, &slot);
    if (st != SH_OK) return st;
    if (!r->have_next && r->end_damaged) { /* the end of a damaged recording is an error: a caller's exit says so */
        r->end_damaged = 0;
        return sh_error_set(SH_EFORMAT, "%s", r->rp.base.damage);
    }
    if (!r->have_next) return SH_EEOF;
    int64_t due = due_of(r);
    if (!sh_replay_wait(&r->rp, due, timeout_ms)) return SH_OK;
    /* hand out the read-ahead buffer; the slot's buffer becomes the next read-ahead one */
    uint8_t *out = r->next_mem;
    r->next_mem = r->mem[slot];
    r->mem[slot] = out;
    /* restarted: read ahead at the previous frame, this one opens a pass */
    sh_replay_hand_out(&r->rp, slot, out, r->next_bytes, r->sequence_out++, due, r->restarted, f);
    r->restarted = 0;
    st = read_ahead(r);
    if (st != SH_OK) {
        r->rp.held[slot] = 0;
        return st;
    }
    arm(r);
    *got = 1;
    return SH_OK;
}

static void r_close(sh_source *s)
{
    rec_source *r = (rec_source *)s;
    sh_rec_reader_close(r->reader);
    for (int i = 0; i < SH_REPLAY_SLOTS; i++) free(r->mem[i]);
    free(r->next_mem);
    sh_replay_close(&r->rp);
    free(r);
}

static const sh_source_ops ops = {r_start, sh_replay_fd, r_dequeue, sh_replay_release, sh_replay_stop, r_close, NULL};

sh_status sh_source_open_rec(const char *path, const sh_source_options *opts, sh_source **out)
{
    if (!*path) return sh_error_set(SH_EINVAL, "rec: no recording named");
    if (strlen(path) >= sizeof(((rec_source *)0)->path))
        return sh_error_set(SH_EINVAL, "rec:%.40s...: path too long", path);
    rec_source *r = calloc(1, sizeof *r);
    if (!r) return sh_error_set(SH_ENOMEM, "rec:%s: out of memory", path);
    sh_replay_init(&r->rp, &ops, opts);
    snprintf(r->path, sizeof r->path, "%s", path);
    sh_status st = sh_rec_reader_open(path, &r->reader);
    if (st != SH_OK) {
        r_close(&r->rp.base);
        return st;
    }
    const sh_rec_stream *s = sh_rec_reader_stream(r->reader, opts->camera);
    if (!s) {
        r_close(&r->rp.base);
        return sh_error_set(SH_EINVAL, "rec:%s: no camera %d in the recording", path, opts->camera);
    }
    if ((st = sh_source_check_pixels(opts, "rec", path, s->width, s->height)) != SH_OK) {
        r_close(&r->rp.base);
        return st;
    }
    r->stream = *s;
    r->rp.base.format = s->format;
    r->rp.base.width = s->width;
    r->rp.base.height = s->height;
    r->rp.base.stride = s->stride;
    r->rp.base.fps_num = s->fps_num;
    r->rp.base.fps_den = s->fps_den;
    r->cap = s->format == SH_RAW_MJPEG ? (size_t)s->width * s->height * 3 + (1u << 20)
                                       : sh_raw_frame_size(s->format, s->width, s->height, s->stride) + (1u << 20);
    for (int i = 0; i < SH_REPLAY_SLOTS; i++) r->mem[i] = malloc(r->cap);
    r->next_mem = malloc(r->cap);
    if (!r->mem[0] || !r->mem[1] || !r->next_mem || sh_replay_timer_create(&r->rp) < 0) {
        r_close(&r->rp.base);
        return sh_error_set(SH_ENOMEM, "rec:%s: out of memory", path);
    }
    if ((st = read_ahead(r)) != SH_OK) {
        r_close(&r->rp.base);
        return st;
    }
    *out = &r->rp.base;
    return SH_OK;
}
