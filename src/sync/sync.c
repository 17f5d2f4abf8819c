/* Frame-set grouping (sync.h). Pending sets live in a small array sorted by reference time. */
#include "stillheart/sync.h"

#include <stdlib.h>
#include <string.h>

struct sh_sync {
    sh_sync_options o;
    sh_frame_set pending[SH_SYNC_MAX_PENDING + 1];
    int npending;
    int nready;            /* the first nready pending sets are ready to pop */
    uint32_t all;          /* bits of every camera */
    uint32_t expected;     /* of them, the ones not gone (sh_sync_camera_gone): a set has waited
                            * enough once it holds all of theirs */
    int64_t newest;        /* newest frame timestamp seen */
    int have_newest;
    int64_t horizon;       /* reference of the last emitted (ready) set */
    int have_horizon;
    uint64_t next_index;
    sh_sync_stats stats;
};

sh_status sh_sync_create(const sh_sync_options *o, sh_sync **out)
{
    if (!o || !out) return sh_error_set(SH_EINVAL, "sync: NULL argument");
    if (o->cameras < 1 || o->cameras > SH_SYNC_MAX_CAMERAS)
        return sh_error_set(SH_EINVAL, "sync: %d cameras (1..%d)", o->cameras, SH_SYNC_MAX_CAMERAS);
    if (o->tolerance_ns <= 0 || o->max_wait_ns <= 0)
        return sh_error_set(SH_EINVAL, "sync: tolerance and maximum wait must be positive");
    sh_sync *s = calloc(1, sizeof *s);
    if (!s) return sh_error_set(SH_ENOMEM, "sync: out of memory");
    s->o = *o;
    s->all = s->expected = o->cameras == 32 ? 0xffffffffu : (1u << o->cameras) - 1;
    *out = s;
    return SH_OK;
}

void sh_sync_destroy(sh_sync *s) { free(s); }

/* Marks pending sets [nready, upto) ready, in order. */
static void ready_upto(sh_sync *s, int upto)
{
    for (; s->nready < upto; s->nready++) {
        sh_frame_set *f = &s->pending[s->nready];
        f->complete = (f->present & s->all) == s->all;
        s->horizon = f->time_ns;
        s->have_horizon = 1;
    }
}

/* Applies the emission rules after a change. */
static void settle(sh_sync *s)
{
    /* the latest complete set (of the cameras not gone) makes every set before it ready */
    for (int i = s->npending - 1; i >= s->nready; i--)
        if ((s->pending[i].present & s->expected) == s->expected) {
            ready_upto(s, i + 1);
            break;
        }
    /* waited long enough */
    while (s->nready < s->npending && s->have_newest &&
           s->newest - s->pending[s->nready].time_ns > s->o.max_wait_ns)
        ready_upto(s, s->nready + 1);
    /* too many open */
    while (s->npending - s->nready > SH_SYNC_MAX_PENDING - 1 && s->nready < s->npending) ready_upto(s, s->nready + 1);
}

static int64_t dist(int64_t a, int64_t b) { return a > b ? a - b : b - a; }

/* The open set whose reference is within tolerance of t (the nearest), or -1. */
static int find(const sh_sync *s, int64_t t)
{
    int best = -1;
    int64_t bd = 0;
    for (int i = s->nready; i < s->npending; i++) {
        int64_t d = dist(s->pending[i].time_ns, t);
        if (d <= s->o.tolerance_ns && (best < 0 || d < bd)) best = i, bd = d;
    }
    return best;
}

/* Opens a set at reference t, in time order; returns its position or -1 when full. */
static int open_set(sh_sync *s, int64_t t, int triggered)
{
    if (s->npending >= SH_SYNC_MAX_PENDING + 1) return -1;
    int i = s->npending;
    while (i > s->nready && s->pending[i - 1].time_ns > t) i--;
    memmove(&s->pending[i + 1], &s->pending[i], (size_t)(s->npending - i) * sizeof s->pending[0]);
    s->npending++;
    sh_frame_set *f = &s->pending[i];
    memset(f, 0, sizeof *f);
    f->time_ns = t;
    f->triggered = triggered;
    return i;
}

static int is_late(const sh_sync *s, int64_t t) { return s->have_horizon && t <= s->horizon + s->o.tolerance_ns; }

sh_status sh_sync_trigger(sh_sync *s, int64_t edge)
{
    if (!s) return sh_error_set(SH_EINVAL, "sync: NULL");
    int64_t t = edge + s->o.trigger_offset_ns;
    /* a set already complete but not yet popped still takes its edge's time */
    for (int i = 0; i < s->nready; i++)
        if (dist(s->pending[i].time_ns, t) <= s->o.tolerance_ns) {
            s->pending[i].time_ns = t;
            s->pending[i].triggered = 1;
            return SH_OK;
        }
    if (is_late(s, t)) {
        s->stats.late_edges++;
        return SH_OK;
    }
    int i = find(s, t);
    if (i >= 0) {
        /* frames came first: the edge is the set's time from now on */
        s->pending[i].time_ns = t;
        s->pending[i].triggered = 1;
    } else if (open_set(s, t, 1) < 0) {
        ready_upto(s, s->nready + 1);
        if (open_set(s, t, 1) < 0) return sh_error_set(SH_ERANGE, "sync: no room for a set");
    }
    settle(s);
    return SH_OK;
}

sh_status sh_sync_push(sh_sync *s, int camera, uint64_t sequence, int64_t t, void *user, sh_sync_disposition *disp)
{
    if (!s || !disp) return sh_error_set(SH_EINVAL, "sync: NULL argument");
    if (camera < 0 || camera >= s->o.cameras)
        return sh_error_set(SH_EINVAL, "sync: camera %d out of 0..%d", camera, s->o.cameras - 1);
    if (is_late(s, t)) {
        s->stats.late++;
        *disp = SH_SYNC_LATE;
        return SH_OK;
    }
    int i = find(s, t);
    if (i < 0) {
        i = open_set(s, t, 0);
        if (i < 0) {
            /* full of ready sets the caller has not popped: refuse rather than grow */
            s->stats.late++;
            *disp = SH_SYNC_LATE;
            return sh_error_set(SH_ERANGE, "sync: %d sets waiting to be popped", s->nready);
        }
    }
    sh_frame_set *f = &s->pending[i];
    if (f->present & (1u << camera)) {
        s->stats.duplicates++;
        *disp = SH_SYNC_DUPLICATE;
        return SH_OK;
    }
    f->present |= 1u << camera;
    f->count++;
    f->member[camera].sequence = sequence;
    f->member[camera].timestamp_ns = t;
    f->member[camera].user = user;
    if (!s->have_newest || t > s->newest) s->newest = t, s->have_newest = 1;
    *disp = SH_SYNC_ADDED;
    settle(s);
    return SH_OK;
}

int sh_sync_pop(sh_sync *s, sh_frame_set *out)
{
    if (!s || !out || !s->nready) return 0;
    *out = s->pending[0];
    out->index = s->next_index++;
    s->stats.sets++;
    if (out->complete) s->stats.complete++;
    else s->stats.incomplete++;
    memmove(&s->pending[0], &s->pending[1], (size_t)(s->npending - 1) * sizeof s->pending[0]);
    s->npending--;
    s->nready--;
    return 1;
}

void sh_sync_flush(sh_sync *s)
{
    if (s) ready_upto(s, s->npending);
}

sh_status sh_sync_camera_gone(sh_sync *s, int camera)
{
    if (!s) return sh_error_set(SH_EINVAL, "sync: NULL");
    if (camera < 0 || camera >= s->o.cameras)
        return sh_error_set(SH_EINVAL, "sync: camera %d out of 0..%d", camera, s->o.cameras - 1);
    s->expected &= ~(1u << camera);
    settle(s);
    return SH_OK;
}

void sh_sync_get_stats(const sh_sync *s, sh_sync_stats *st)
{
    if (s && st) *st = s->stats;
}
