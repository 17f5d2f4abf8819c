/* Frame sets: the frames of 2-3 (up to SH_SYNC_MAX_CAMERAS) cameras that belong to one exposure,
 * grouped by trigger edge and timestamp.
 *
 * Each pending set has a reference time: its trigger edge (sh_sync_trigger, plus
 * trigger_offset_ns, the expected delay from the edge to a frame's timestamp) or, without
 * triggers, the timestamp of its first frame. A frame joins the pending set whose reference is
 * within tolerance_ns of its timestamp, else it opens a new one (sets are kept in time order, so
 * frames may come in any order across cameras). An edge that comes after its frames still gives
 * the set its time if the set has not been popped yet. The tolerance must be under half the frame
 * period.
 *
 * A set is emitted (sh_sync_pop) in time order:
 * - as soon as every camera has a frame in it;
 * - incomplete, when a later set is complete (a camera's missing frame never stalls the sets
 *   after it), when frames max_wait_ns newer than its reference have arrived, when more than
 *   SH_SYNC_MAX_PENDING sets are open, or at sh_sync_flush;
 * - once every camera not gone (sh_sync_camera_gone) has a frame in it (incomplete).
 * A frame whose set was already emitted is refused as late; a second frame of one camera in one
 * set is refused as a duplicate (the first stays). The caller owns the frames: `user` is carried
 * along for it, and a refused frame is the caller's to release. Nothing is allocated after
 * sh_sync_create. Not thread-safe: one thread pushes and pops. */
#ifndef STILLHEART_SYNC_H
#define STILLHEART_SYNC_H

#include <stdint.h>

#include "stillheart/core.h"

#ifdef __cplusplus
extern "C" {
#endif

#define SH_SYNC_MAX_CAMERAS 8
#define SH_SYNC_MAX_PENDING 16

typedef struct {
    int cameras;              /* 1..SH_SYNC_MAX_CAMERAS */
    int64_t tolerance_ns;     /* > 0 */
    int64_t max_wait_ns;      /* > 0: how long a set waits for its missing frames */
    int64_t trigger_offset_ns;/* frame timestamp - trigger edge, expected */
} sh_sync_options;

typedef enum {
    SH_SYNC_ADDED = 0,
    SH_SYNC_LATE,             /* its set was emitted already (or it is older than that) */
    SH_SYNC_DUPLICATE         /* the set has this camera's frame already */
} sh_sync_disposition;

typedef struct {
    uint64_t sequence;
    int64_t timestamp_ns;
    void *user;
} sh_sync_member;

typedef struct {
    uint64_t index;           /* 0, 1, ... in emission (= time) order */
    int64_t time_ns;          /* the reference: trigger edge (+ offset) or first frame */
    int triggered;            /* 1 when a trigger edge made or confirmed it */
    int complete;
    int count;                /* frames in it */
    uint32_t present;         /* bit c set: member[c] holds camera c's frame */
    sh_sync_member member[SH_SYNC_MAX_CAMERAS];
} sh_frame_set;

typedef struct {
    uint64_t sets, complete, incomplete; /* emitted */
    uint64_t late, duplicates;           /* frames refused */
    uint64_t late_edges;                 /* trigger edges older than the last emitted set */
} sh_sync_stats;

typedef struct sh_sync sh_sync;

sh_status sh_sync_create(const sh_sync_options *opts, sh_sync **out);
void sh_sync_destroy(sh_sync *sync);
/* A trigger edge at edge_ns (CLOCK_MONOTONIC, e.g. a GPIO event). */
sh_status sh_sync_trigger(sh_sync *sync, int64_t edge_ns);
sh_status sh_sync_push(sh_sync *sync, int camera, uint64_t sequence, int64_t timestamp_ns, void *user,
                       sh_sync_disposition *disposition);
/* 1 and *out filled when a set is ready, 0 when none is. */
int sh_sync_pop(sh_sync *sync, sh_frame_set *out);
/* Marks every pending set ready (they come out of sh_sync_pop, incomplete or not). */
void sh_sync_flush(sh_sync *sync);
/* Camera `camera` sends no more frames (its stream ended or failed for good): no set waits for it
 * any longer, so the sets the other cameras are still filling come out as soon as they have all
 * their frames (incomplete, without this camera's), not before: a frame of theirs is never made
 * late by the gone camera. Flushing instead would emit the sets the others have not yet filled
 * and refuse their frames as late when they come. */
sh_status sh_sync_camera_gone(sh_sync *sync, int camera);
void sh_sync_get_stats(const sh_sync *sync, sh_sync_stats *stats);

/* ---- GPIO trigger (libgpiod 1.6, the v1 API; built when pkg-config finds libgpiod) ----
 * Output: stillheart drives the line: a pulse of pulse_ns every period_ns, the cameras expose on
 * it. Input: stillheart timestamps the active edges of a camera strobe or a master trigger.
 * Either way sh_gpio_trigger_service gives the active edge's CLOCK_MONOTONIC time, for
 * sh_sync_trigger. The fd goes into the caller's poll loop beside the cameras'. */
typedef struct {
    const char *chip;      /* "gpiochip0", "/dev/gpiochip0", a label or a number */
    unsigned line;
    int active_low;        /* polarity: the active edge is the falling one on the wire */
    int output;            /* 1: drive pulses; 0: read edges */
    int64_t period_ns;     /* output: pulse period (> pulse_ns) */
    int64_t pulse_ns;      /* output: pulse width (> 0) */
} sh_gpio_options;

typedef struct sh_gpio_trigger sh_gpio_trigger;

/* A missing chip, a line out of range or a line another consumer holds is refused here with
 * a message naming chip and line. */
sh_status sh_gpio_trigger_open(const sh_gpio_options *opts, sh_gpio_trigger **out);
/* Output: starts the pulses (first at once). Input: nothing to do. */
sh_status sh_gpio_trigger_start(sh_gpio_trigger *t);
int sh_gpio_trigger_fd(const sh_gpio_trigger *t);
/* Call when the fd is readable (or any time): *got = 1 with *edge_ns when an active edge was
 * produced (output) or received (input); 0 otherwise. Never blocks. */
sh_status sh_gpio_trigger_service(sh_gpio_trigger *t, int64_t *edge_ns, int *got);
uint64_t sh_gpio_trigger_edges(const sh_gpio_trigger *t);
void sh_gpio_trigger_close(sh_gpio_trigger *t);

#ifdef __cplusplus
}
#endif
#endif
