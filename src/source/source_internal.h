/* Private to src/source: the backend interface behind sh_source. */
#ifndef STILLHEART_SOURCE_INTERNAL_H
#define STILLHEART_SOURCE_INTERNAL_H

#include "stillheart/source.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct {
    sh_status (*start)(sh_source *src);
    int (*fd)(const sh_source *src);
    sh_status (*dequeue)(sh_source *src, int timeout_ms, sh_source_frame *frame, int *got);
    sh_status (*release)(sh_source *src, sh_source_frame *frame);
    sh_status (*stop)(sh_source *src);
    void (*close)(sh_source *src);
    /* sh_source_dequeue_into where the backend can read into dst (*direct 1); NULL: never */
    sh_status (*dequeue_into)(sh_source *src, int timeout_ms, sh_image *dst, sh_source_frame *frame, int *got,
                              int *direct);
} sh_source_ops;

/* The first member of every backend's state. */
struct sh_source {
    const sh_source_ops *ops;
    char name[288];          /* the spec, for messages */
    sh_source_options opts;
    sh_source_stats stats;
    sh_rawfmt format;
    int width, height, stride;
    int fps_num, fps_den;
    int started;
    int64_t start_ns;        /* sh_source_start_at's clock: where a replay's schedule begins */
    char damage[640];        /* sh_source_damage */
};

sh_status sh_source_open_y4m(const char *path, const sh_source_options *opts, sh_source **out);
sh_status sh_source_open_v4l2(const char *path, const sh_source_options *opts, sh_source **out);
sh_status sh_source_open_rec(const char *dir, const sh_source_options *opts, sh_source **out);
sh_status sh_source_open_libcamera(const char *name, const sh_source_options *opts, sh_source **out);

/* What the two replays (y4m:, rec:) share, as the first member of their state: a timerfd that is
 * readable when the next frame is due (the source's fd), and two frame slots that the caller
 * holds from dequeue to release. */
#define SH_REPLAY_SLOTS 2
typedef struct {
    sh_source base;
    int tfd;
    int held[SH_REPLAY_SLOTS];
} sh_replay;

/* Sets the base's ops and options; no timer yet (tfd -1, which sh_replay_close skips). */
void sh_replay_init(sh_replay *rp, const sh_source_ops *ops, const sh_source_options *opts);
/* Creates the timer: -1 with errno when it cannot be. */
int sh_replay_timer_create(sh_replay *rp);
/* Arms the timer at the absolute time due, or readable at once when not in real time (or due <= 0). */
void sh_replay_arm(sh_replay *rp, int64_t due);
/* The start of a dequeue: a slot the caller does not hold (an error when it holds both). */
sh_status sh_replay_slot(sh_replay *rp, int *slot);
/* In real time, waits for due up to timeout_ms (< 0: as long as it takes); 0 when it is not due
 * yet (nothing to hand out). Once due, the timer's expirations are cleared and 1 returned. */
int sh_replay_wait(sh_replay *rp, int64_t due, int timeout_ms);
/* Hands out the frame in slot (held from now on, counted): the source's format, data and bytes,
 * its sequence number and timestamp, and whether the scene jumps before it. */
void sh_replay_hand_out(sh_replay *rp, int slot, uint8_t *data, size_t bytes, uint64_t sequence,
                        int64_t timestamp_ns, int discontinuity, sh_source_frame *f);
/* The ops both replays use as they are. */
int sh_replay_fd(const sh_source *s);
sh_status sh_replay_release(sh_source *s, sh_source_frame *frame);
sh_status sh_replay_stop(sh_source *s);
/* Closes the timer (the backend frees the rest). */
void sh_replay_close(sh_replay *rp);

/* opts->max_frame_pixels, or the default where it is 0. */
long long sh_source_max_pixels(const sh_source_options *opts);
/* A stream's size against that bound, where the backend learns it and before it
 * allocates or maps a frame: SH_ERANGE naming kind:path, the size and the bound. */
sh_status sh_source_check_pixels(const sh_source_options *opts, const char *kind, const char *path, int width,
                                 int height);

/* t0 + k frames at num/den frames per second, exact in integers (no overflow for any k). */
int64_t sh_source_schedule_ns(int64_t t0, uint64_t k, int fps_num, int fps_den);
/* Sleeps until the absolute CLOCK_MONOTONIC time (ns). */
void sh_source_sleep_until(int64_t t_ns);

#ifdef __cplusplus
}
#endif
#endif
