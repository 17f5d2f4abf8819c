/* The publisher thread (run_publish.h). A mailbox of one frame under a mutex: submit fills it and
 * wakes the thread, the thread runs fn and stamps the time, wait sleeps until it is done. The
 * mutex hands everything fn wrote (the pipeline's sinks, counters) back to the processing thread
 * with the wait, so the two threads never touch the sinks at the same time. */
#include <pthread.h>
#include <stdlib.h>

#include "run_publish.h"
#include "stillheart/log.h"

struct run_publisher {
    run_publish_fn fn;
    void *ctx;
    pthread_t thread;
    pthread_mutex_t mu;
    pthread_cond_t cv;
    const sh_image *shown;     /* the frame in flight; NULL: none */
    const sh_display_frame_info *info;
    int busy;                  /* handed and not yet waited for */
    int done;                  /* fn returned for it */
    int64_t done_ns;
    int quit;
};

static void *publisher_main(void *arg)
{
    run_publisher *p = arg;
    sh_log_set_thread("publish");
    pthread_mutex_lock(&p->mu);
    for (;;) {
        while (!p->quit && !(p->busy && !p->done)) pthread_cond_wait(&p->cv, &p->mu);
        if (p->busy && !p->done) {
            const sh_image *shown = p->shown;
            const sh_display_frame_info *info = p->info;
            pthread_mutex_unlock(&p->mu);
            p->fn(p->ctx, shown, info);
            int64_t t = sh_monotonic_ns();
            pthread_mutex_lock(&p->mu);
            p->done_ns = t;
            p->done = 1;
            pthread_cond_broadcast(&p->cv);
            continue;
        }
        if (p->quit) break;
    }
    pthread_mutex_unlock(&p->mu);
    return NULL;
}

sh_status run_publisher_create(run_publish_fn fn, void *ctx, run_publisher **out)
{
    *out = NULL;
    run_publisher *p = calloc(1, sizeof *p);
    if (!p) return sh_error_set(SH_ENOMEM, "publisher: out of memory");
    p->fn = fn;
    p->ctx = ctx;
    pthread_mutex_init(&p->mu, NULL);
    pthread_cond_init(&p->cv, NULL);
    if (pthread_create(&p->thread, NULL, publisher_main, p)) {
        pthread_mutex_destroy(&p->mu);
        pthread_cond_destroy(&p->cv);
        free(p);
        return sh_error_set(SH_ENOMEM, "publisher: cannot start its thread");
    }
    *out = p;
    return SH_OK;
}

void run_publisher_destroy(run_publisher *p)
{
    if (!p) return;
    int64_t t;
    run_publisher_wait(p, &t);
    pthread_mutex_lock(&p->mu);
    p->quit = 1;
    pthread_cond_broadcast(&p->cv);
    pthread_mutex_unlock(&p->mu);
    pthread_join(p->thread, NULL);
    pthread_mutex_destroy(&p->mu);
    pthread_cond_destroy(&p->cv);
    free(p);
}

void run_publisher_submit(run_publisher *p, const sh_image *shown, const sh_display_frame_info *info)
{
    pthread_mutex_lock(&p->mu);
    p->shown = shown;
    p->info = info;
    p->busy = 1;
    p->done = 0;
    pthread_cond_broadcast(&p->cv);
    pthread_mutex_unlock(&p->mu);
}

int run_publisher_wait(run_publisher *p, int64_t *done_ns)
{
    pthread_mutex_lock(&p->mu);
    int had = p->busy;
    while (p->busy && !p->done) pthread_cond_wait(&p->cv, &p->mu);
    if (had) *done_ns = p->done_ns;
    p->busy = 0;
    p->shown = NULL;
    p->info = NULL;
    pthread_mutex_unlock(&p->mu);
    return had;
}
