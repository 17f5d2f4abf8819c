/* The replays' shared part (source_internal.h): the timer that makes a replay pollable like a
 * camera, the frame slots and the wait for a frame's due time. y4m_replay.c and rec.c differ only
 * in where frames and their times come from. */
#include "source_internal.h"

#include <errno.h>
#include <string.h>
#include <sys/timerfd.h>
#include <unistd.h>

void sh_replay_init(sh_replay *rp, const sh_source_ops *ops, const sh_source_options *opts)
{
    rp->base.ops = ops;
    rp->base.opts = *opts;
    rp->tfd = -1;
}

int sh_replay_timer_create(sh_replay *rp)
{
    rp->tfd = timerfd_create(CLOCK_MONOTONIC, TFD_NONBLOCK | TFD_CLOEXEC);
    return rp->tfd < 0 ? -1 : 0;
}

void sh_replay_arm(sh_replay *rp, int64_t due)
{
    struct itimerspec it;
    memset(&it, 0, sizeof it);
    if (!rp->base.opts.realtime || due <= 0) {
        it.it_value.tv_nsec = 1; /* relative: readable at once */
        timerfd_settime(rp->tfd, 0, &it, NULL);
        return;
    }
    it.it_value.tv_sec = (time_t)(due / 1000000000);
    it.it_value.tv_nsec = (long)(due % 1000000000);
    if (!it.it_value.tv_sec && !it.it_value.tv_nsec) it.it_value.tv_nsec = 1;
    timerfd_settime(rp->tfd, TFD_TIMER_ABSTIME, &it, NULL);
}

sh_status sh_replay_slot(sh_replay *rp, int *slot)
{
    for (int i = 0; i < SH_REPLAY_SLOTS; i++)
        if (!rp->held[i]) {
            *slot = i;
            return SH_OK;
        }
    return sh_error_set(SH_EINVAL, "%s: every frame slot is held (release frames)", rp->base.name);
}

int sh_replay_wait(sh_replay *rp, int64_t due, int timeout_ms)
{
    if (rp->base.opts.realtime) {
        int64_t now = sh_monotonic_ns();
        if (now < due) {
            if (timeout_ms == 0) return 0;
            if (timeout_ms > 0 && now + (int64_t)timeout_ms * 1000000 < due) {
                sh_source_sleep_until(now + (int64_t)timeout_ms * 1000000);
                return 0;
            }
            sh_source_sleep_until(due);
        }
    }
    uint64_t expirations;
    if (read(rp->tfd, &expirations, sizeof expirations) < 0 && errno != EAGAIN) {
        /* nothing to clear */
    }
    return 1;
}

void sh_replay_hand_out(sh_replay *rp, int slot, uint8_t *data, size_t bytes, uint64_t sequence,
                        int64_t timestamp_ns, int discontinuity, sh_source_frame *f)
{
    const sh_source *s = &rp->base;
    memset(f, 0, sizeof *f);
    f->camera = s->opts.camera;
    f->sequence = sequence;
    f->discontinuity = discontinuity;
    f->timestamp_ns = timestamp_ns;
    f->raw.format = s->format;
    f->raw.width = s->width;
    f->raw.height = s->height;
    f->raw.stride = s->stride;
    f->raw.data = data;
    f->raw.bytes = bytes;
    f->slot = slot;
    rp->held[slot] = 1;
    rp->base.stats.frames++;
}

int sh_replay_fd(const sh_source *s) { return ((const sh_replay *)s)->tfd; }

sh_status sh_replay_release(sh_source *s, sh_source_frame *f)
{
    sh_replay *rp = (sh_replay *)s;
    if (f->slot < 0 || f->slot >= SH_REPLAY_SLOTS || !rp->held[f->slot])
        return sh_error_set(SH_EINVAL, "%s: release of a frame not held", s->name);
    rp->held[f->slot] = 0;
    f->slot = -1;
    return SH_OK;
}

sh_status sh_replay_stop(sh_source *s)
{
    (void)s; /* a replay stops between dequeues: nothing runs on its own */
    return SH_OK;
}

void sh_replay_close(sh_replay *rp)
{
    if (rp->tfd >= 0) close(rp->tfd);
    rp->tfd = -1;
}
