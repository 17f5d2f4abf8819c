/* Drawing a frame in bands on several threads (screen.h, sh_screen_painter): the conversion is
 * most of stillheart-show's own part of publish-to-flip, and it divides. Each frame is one round:
 * the caller posts it, every helper draws its band and counts itself done, the caller draws band
 * 0 and waits for the count. Nothing is queued: a round ends before the call returns. Each band
 * has its own row for scaled frames, kept from frame to frame and grown only when a wider frame
 * comes (a daemon restarted at another size): no allocation per frame. */
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "screen_internal.h"

#define MAX_THREADS 8

typedef struct {
    sh_screen_painter *p;
    int band;
    pthread_t th;
    uint32_t *row;  /* the band's row for a scaled frame */
} helper;

struct sh_screen_painter {
    helper h[MAX_THREADS];
    int n, started;              /* bands (the caller's included); helpers started */
    pthread_mutex_t mu;
    pthread_cond_t go, done;
    unsigned long long round;
    int pending, quit;
    const sh_screen_buffer *dst; /* the round's job */
    const sh_screen_layout *layout;
    const sh_image *frame;
    int full_range;
    sh_status status;            /* the first helper failure of the round, and its message */
    char message[256];
    int row_cap;                 /* pixels each band's row holds */
};

static sh_status draw_band(const sh_screen_painter *p, int band)
{
    long long h = p->dst->height;
    return screen_draw_band(p->dst, p->layout, p->frame, p->full_range, (int)(h * band / p->n),
                            (int)(h * (band + 1) / p->n), p->h[band].row);
}

/* Every band's row as wide as the frame (before a round: no helper is drawing). */
static sh_status grow_rows(sh_screen_painter *p, int width)
{
    if (width <= p->row_cap) return SH_OK;
    for (int i = 0; i < p->n; i++) {
        uint32_t *r = realloc(p->h[i].row, (size_t)width * sizeof *r);
        if (!r) return sh_error_set(SH_ENOMEM, "screen: out of memory for a %d-pixel row", width);
        p->h[i].row = r;
    }
    p->row_cap = width;
    return SH_OK;
}

static void *helper_main(void *arg)
{
    helper *me = arg;
    sh_screen_painter *p = me->p;
    unsigned long long seen = 0;
    pthread_mutex_lock(&p->mu);
    for (;;) {
        while (!p->quit && p->round == seen) pthread_cond_wait(&p->go, &p->mu);
        if (p->quit) break;
        seen = p->round;
        pthread_mutex_unlock(&p->mu);
        sh_status st = draw_band(p, me->band);
        pthread_mutex_lock(&p->mu);
        if (st != SH_OK && p->status == SH_OK) {
            /* the message is this thread's: copied for the caller's */
            p->status = st;
            snprintf(p->message, sizeof p->message, "%s", sh_error_message());
        }
        if (--p->pending == 0) pthread_cond_signal(&p->done);
    }
    pthread_mutex_unlock(&p->mu);
    return NULL;
}

sh_status sh_screen_painter_create(int threads, sh_screen_painter **out)
{
    if (threads < 1 || threads > MAX_THREADS)
        return sh_error_set(SH_EINVAL, "screen: %d drawing threads, not 1 to %d", threads, MAX_THREADS);
    sh_screen_painter *p = calloc(1, sizeof *p);
    if (!p) return sh_error_set(SH_ENOMEM, "screen: out of memory");
    p->n = threads;
    pthread_mutex_init(&p->mu, NULL);
    pthread_cond_init(&p->go, NULL);
    pthread_cond_init(&p->done, NULL);
    for (int i = 1; i < threads; i++) {
        p->h[i] = (helper){p, i, 0, NULL};
        int e = pthread_create(&p->h[i].th, NULL, helper_main, &p->h[i]);
        if (e) {
            sh_screen_painter_destroy(p);
            return sh_error_set(SH_EIO, "screen: cannot start a drawing thread: %s", strerror(e));
        }
        p->started = i;
    }
    *out = p;
    return SH_OK;
}

sh_status sh_screen_painter_draw(sh_screen_painter *p, const sh_screen_buffer *dst, const sh_screen_layout *layout,
                                 const sh_image *frame, int full_range)
{
    if (frame->width != layout->picture.width) {
        sh_status st = grow_rows(p, frame->width);
        if (st != SH_OK) return st;
    }
    p->dst = dst;
    p->layout = layout;
    p->frame = frame;
    p->full_range = full_range;
    /* one thread: no round, no lock; the frame is read with nothing held (screen.h promises it
     * to a caller that may abandon the draw by a jump, as sh_display_reader_view does) */
    if (p->n == 1) return draw_band(p, 0);
    pthread_mutex_lock(&p->mu);
    p->status = SH_OK;
    p->pending = p->n - 1;
    p->round++;
    pthread_cond_broadcast(&p->go);
    pthread_mutex_unlock(&p->mu);
    sh_status st = draw_band(p, 0);
    pthread_mutex_lock(&p->mu);
    while (p->pending > 0) pthread_cond_wait(&p->done, &p->mu);
    if (st == SH_OK && p->status != SH_OK) st = sh_error_set(p->status, "%s", p->message);
    pthread_mutex_unlock(&p->mu);
    return st;
}

void sh_screen_painter_destroy(sh_screen_painter *p)
{
    if (!p) return;
    pthread_mutex_lock(&p->mu);
    p->quit = 1;
    pthread_cond_broadcast(&p->go);
    pthread_mutex_unlock(&p->mu);
    for (int i = 1; i <= p->started; i++) pthread_join(p->h[i].th, NULL);
    pthread_cond_destroy(&p->go);
    pthread_cond_destroy(&p->done);
    pthread_mutex_destroy(&p->mu);
    for (int i = 0; i < MAX_THREADS; i++) free(p->h[i].row);
    free(p);
}
