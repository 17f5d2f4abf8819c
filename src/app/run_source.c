/* stillheart run's source: a replay thread feeding the three-buffer mailbox (run_source.h). */
#include "run_source.h"

#include <errno.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

typedef struct {
    run_frame f;
} slot;

struct run_source {
    pthread_mutex_t mu;
    pthread_cond_t cv;
    pthread_t thread;
    int started;
    slot buf[3];
    int w, m, p;        /* filled by the source / waiting (-1: none) / held by processing (-1) */
    int eof;            /* the source ended (no loop) or failed */
    int stop;
    int realtime, loop;
    uint64_t delivered, dropped;
    sh_y4m_reader *reader;
    sh_y4m_header hdr;
    char path[SH_CONFIG_STR];
    double fps;
    run_log_fn log;
};

static int64_t mono_ns(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (int64_t)ts.tv_sec * 1000000000 + ts.tv_nsec;
}

static int free_slot(const run_source *mb)
{
    for (int i = 0; i < 3; i++)
        if (i != mb->w && i != mb->m && i != mb->p) return i;
    return -1;
}

static int stopping(run_source *mb)
{
    pthread_mutex_lock(&mb->mu);
    int s = mb->stop;
    pthread_mutex_unlock(&mb->mu);
    return s;
}

static void *source_thread(void *arg)
{
    run_source *mb = arg;
    int index = 0;
    int64_t start = mono_ns();
    uint64_t k = 0;
    while (!stopping(mb)) {
        slot *s = &mb->buf[mb->w];
        sh_status st = sh_y4m_reader_read(mb->reader, &s->f.img);
        if (st == SH_EEOF && mb->loop) {
            sh_y4m_reader_close(mb->reader);
            mb->reader = NULL;
            if (sh_y4m_reader_open(mb->path, &mb->reader) != SH_OK) {
                mb->log("ERROR", "source", "%s: reopen: %s", mb->path, sh_error_message());
                break;
            }
            index = 0;
            continue;
        }
        if (st == SH_EEOF) { mb->log("INFO", "source", "%s: end of stream", mb->path); break; }
        if (st != SH_OK) {
            mb->log("ERROR", "source", "%s: %s", mb->path, sh_error_message());
            break;
        }
        if (mb->realtime && mb->fps > 0) { /* frame k is due at start + k / fps */
            int64_t due = start + (int64_t)((double)k * 1e9 / mb->fps);
            int64_t now = mono_ns();
            if (due > now) {
                struct timespec ts = {(time_t)((due - now) / 1000000000), (long)((due - now) % 1000000000)};
                while (nanosleep(&ts, &ts) && errno == EINTR && !stopping(mb)) {}
            }
        }
        k++;
        s->f.index = index++;
        pthread_mutex_lock(&mb->mu);
        if (!mb->realtime) /* as fast as processing takes them: wait, nothing dropped */
            while (mb->m >= 0 && !mb->stop) pthread_cond_wait(&mb->cv, &mb->mu);
        s->f.avail_ns = mono_ns(); /* available to processing from now */
        if (mb->m >= 0) { /* behind: the waiting frame is the oldest, drop it */
            int old = mb->m;
            mb->m = mb->w;
            mb->w = old;
            mb->dropped++;
        } else {
            mb->m = mb->w;
            mb->w = free_slot(mb);
        }
        mb->delivered++;
        pthread_cond_broadcast(&mb->cv);
        pthread_mutex_unlock(&mb->mu);
    }
    pthread_mutex_lock(&mb->mu);
    mb->eof = 1;
    pthread_cond_broadcast(&mb->cv);
    pthread_mutex_unlock(&mb->mu);
    return NULL;
}

sh_status run_source_open(const sh_config *cfg, run_log_fn log, run_source **out)
{
    *out = NULL;
    run_source *mb = calloc(1, sizeof *mb);
    if (!mb) return sh_error_set(SH_ENOMEM, "source: out of memory");
    pthread_mutex_init(&mb->mu, NULL);
    pthread_cond_init(&mb->cv, NULL);
    mb->w = 0; mb->m = -1; mb->p = -1;
    mb->realtime = cfg->realtime;
    mb->loop = cfg->loop;
    mb->log = log;
    snprintf(mb->path, sizeof mb->path, "%s", cfg->source + 4);
    sh_status st = sh_y4m_reader_open(mb->path, &mb->reader);
    if (st != SH_OK) {
        run_source_destroy(mb);
        return st;
    }
    const sh_y4m_header *hdr = sh_y4m_reader_header(mb->reader);
    mb->hdr = *hdr;
    mb->fps = hdr->fps_num > 0 && hdr->fps_den > 0 ? (double)hdr->fps_num / hdr->fps_den : 0;
    for (int i = 0; i < 3; i++)
        if ((st = sh_image_create(&mb->buf[i].f.img, hdr->format, hdr->width, hdr->height)) != SH_OK) {
            run_source_destroy(mb);
            return st;
        }
    *out = mb;
    return SH_OK;
}

const sh_y4m_header *run_source_header(const run_source *rs) { return &rs->hdr; }

double run_source_fps(const run_source *rs) { return rs->fps; }

sh_status run_source_start(run_source *rs)
{
    if (pthread_create(&rs->thread, NULL, source_thread, rs))
        return sh_error_set(SH_ENOMEM, "source: cannot start its thread");
    rs->started = 1;
    return SH_OK;
}

const run_frame *run_source_take(run_source *mb, int timeout_ms)
{
    pthread_mutex_lock(&mb->mu);
    mb->p = -1;
    struct timespec ts;
    clock_gettime(CLOCK_REALTIME, &ts);
    ts.tv_nsec += (long)timeout_ms * 1000000;
    ts.tv_sec += ts.tv_nsec / 1000000000;
    ts.tv_nsec %= 1000000000;
    while (mb->m < 0 && !mb->eof && !mb->stop)
        if (pthread_cond_timedwait(&mb->cv, &mb->mu, &ts) == ETIMEDOUT) break;
    int got = mb->m;
    if (got >= 0) {
        mb->p = got;
        mb->m = -1;
        pthread_cond_broadcast(&mb->cv);
    }
    pthread_mutex_unlock(&mb->mu);
    return got >= 0 ? &mb->buf[got].f : NULL;
}

int run_source_ended(run_source *mb)
{
    pthread_mutex_lock(&mb->mu);
    int eof = mb->eof && mb->m < 0;
    pthread_mutex_unlock(&mb->mu);
    return eof;
}

void run_source_set_pacing(run_source *mb, int realtime, int loop)
{
    pthread_mutex_lock(&mb->mu);
    mb->realtime = realtime;
    mb->loop = loop;
    pthread_mutex_unlock(&mb->mu);
}

uint64_t run_source_dropped(run_source *mb)
{
    pthread_mutex_lock(&mb->mu);
    uint64_t d = mb->dropped;
    pthread_mutex_unlock(&mb->mu);
    return d;
}

void run_source_destroy(run_source *mb)
{
    if (!mb) return;
    if (mb->started) {
        pthread_mutex_lock(&mb->mu);
        mb->stop = 1;
        pthread_cond_broadcast(&mb->cv);
        pthread_mutex_unlock(&mb->mu);
        pthread_join(mb->thread, NULL);
    }
    sh_y4m_reader_close(mb->reader);
    for (int i = 0; i < 3; i++) sh_image_destroy(&mb->buf[i].f.img);
    pthread_mutex_destroy(&mb->mu);
    pthread_cond_destroy(&mb->cv);
    free(mb);
}
