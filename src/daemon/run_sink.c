/* Recording what was shown: FILE.y4m (written on the processing thread: a Y4M frame is a copy),
 * or png:DIR, numbered PNGs. Compressing a 1080p PNG takes tens of ms, more than a frame, so PNGs
 * are written by their own thread from a small ring of copies; when it falls behind a frame is
 * not recorded (counted and logged at the end), never is the display held up for it. A PNG is
 * named by the frame's display sequence number (DIR/000001.png is the first published frame,
 * as stillheart-cat -v numbers them). */
#include <errno.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "run_sink.h"
#include "stillheart/config.h"
#include "stillheart/png.h"

#define RING 4

struct run_record {
    sh_y4m_writer *y4m;
    /* png */
    char dir[SH_CONFIG_STR];
    int full_range;
    pthread_t thread;
    int started, stop;
    pthread_mutex_t mu;
    pthread_cond_t cv;
    sh_image ring[RING];
    uint64_t seq[RING];
    int head, count;        /* frames waiting: ring[head .. head + count) */
    uint64_t next_seq, skipped, failed;
    char err[256];
};

static void *png_thread(void *arg)
{
    run_record *r = arg;
    char path[SH_CONFIG_STR + 32];
    pthread_mutex_lock(&r->mu);
    for (;;) {
        while (!r->count && !r->stop) pthread_cond_wait(&r->cv, &r->mu);
        if (!r->count) break;
        int i = r->head;
        pthread_mutex_unlock(&r->mu);
        snprintf(path, sizeof path, "%s/%06llu.png", r->dir, (unsigned long long)r->seq[i]);
        sh_status st = sh_png_write(path, &r->ring[i], r->full_range);
        pthread_mutex_lock(&r->mu);
        if (st != SH_OK && !r->failed++) snprintf(r->err, sizeof r->err, "%s", sh_error_message());
        r->head = (r->head + 1) % RING;
        r->count--;
    }
    pthread_mutex_unlock(&r->mu);
    return NULL;
}

sh_status run_record_open(const char *spec, const sh_y4m_header *hdr, run_record **out)
{
    run_record *r = calloc(1, sizeof *r);
    if (!r) return sh_error_set(SH_ENOMEM, "record: out of memory");
    pthread_mutex_init(&r->mu, NULL);
    pthread_cond_init(&r->cv, NULL);
    r->next_seq = 1;
    if (strncmp(spec, "png:", 4)) {
        sh_status st = sh_y4m_writer_open(spec, hdr, &r->y4m);
        if (st != SH_OK) {
            run_record_close(r);
            return st;
        }
        *out = r;
        return SH_OK;
    }
    snprintf(r->dir, sizeof r->dir, "%s", spec + 4);
    r->full_range = sh_y4m_header_full_range(hdr);
    if (mkdir(r->dir, 0775) && errno != EEXIST) {
        sh_status st = sh_error_set(SH_EIO, "%s: %s", r->dir, strerror(errno));
        run_record_close(r);
        return st;
    }
    for (int i = 0; i < RING; i++) {
        sh_status st = sh_image_create(&r->ring[i], hdr->format, hdr->width, hdr->height);
        if (st != SH_OK) {
            run_record_close(r);
            return st;
        }
    }
    if (pthread_create(&r->thread, NULL, png_thread, r)) {
        run_record_close(r);
        return sh_error_set(SH_ENOMEM, "record: cannot start the PNG writer");
    }
    r->started = 1;
    *out = r;
    return SH_OK;
}

sh_status run_record_write(run_record *r, const sh_image *shown)
{
    uint64_t seq = r->next_seq++;
    if (r->y4m) return sh_y4m_writer_write(r->y4m, shown);
    pthread_mutex_lock(&r->mu);
    if (r->count == RING) {
        r->skipped++;
    } else {
        int i = (r->head + r->count) % RING;
        /* the slot is the writer's only between head and head + count: this one is free */
        pthread_mutex_unlock(&r->mu);
        sh_status st = sh_image_copy(&r->ring[i], shown);
        pthread_mutex_lock(&r->mu);
        if (st == SH_OK) {
            r->seq[i] = seq;
            r->count++;
            pthread_cond_signal(&r->cv);
        }
    }
    pthread_mutex_unlock(&r->mu);
    return SH_OK;
}

uint64_t run_record_skipped(const run_record *r) { return r->skipped; }

sh_status run_record_close(run_record *r)
{
    if (!r) return SH_OK;
    sh_status st = SH_OK;
    if (r->y4m) st = sh_y4m_writer_close(r->y4m);
    if (r->started) {
        pthread_mutex_lock(&r->mu);
        r->stop = 1;
        pthread_cond_signal(&r->cv);
        pthread_mutex_unlock(&r->mu);
        pthread_join(r->thread, NULL); /* what is queued is written first */
        if (r->failed)
            st = sh_error_set(SH_EIO, "%llu PNGs not written: %s", (unsigned long long)r->failed, r->err);
    }
    for (int i = 0; i < RING; i++) sh_image_destroy(&r->ring[i]);
    pthread_mutex_destroy(&r->mu);
    pthread_cond_destroy(&r->cv);
    free(r);
    return st;
}
