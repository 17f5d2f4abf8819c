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
    char damage[640];        /* sh_source_damage */
};

sh_status sh_source_open_y4m(const char *path, const sh_source_options *opts, sh_source **out);
sh_status sh_source_open_v4l2(const char *path, const sh_source_options *opts, sh_source **out);
sh_status sh_source_open_rec(const char *dir, const sh_source_options *opts, sh_source **out);
sh_status sh_source_open_libcamera(const char *name, const sh_source_options *opts, sh_source **out);

/* t0 + k frames at num/den frames per second, exact in integers (no overflow for any k). */
int64_t sh_source_schedule_ns(int64_t t0, uint64_t k, int fps_num, int fps_den);
/* Sleeps until the absolute CLOCK_MONOTONIC time (ns). */
void sh_source_sleep_until(int64_t t_ns);

#ifdef __cplusplus
}
#endif
#endif
