/* Recording what was shown: FILE.y4m (written on the processing thread: a Y4M frame is a copy),
 * or png:DIR, numbered PNGs. A recording is evidence, so a start never writes over one: each start
 * takes the configured name when it is free (for png:DIR, an empty or new folder), else NAME-2,
 * NAME-3, ... (docs/daemon.md, "Recording what was shown"). The Y4M file is handed to the kernel
 * every sync_ms (a kill loses at most that much) and made durable by a thread of its own
 * (fdatasync can take tens of ms on an SD card: never on the processing thread), so power loss
 * loses at most about sync_ms more. Compressing a 1080p PNG takes tens of ms, more than a frame, so PNGs
 * are written by their own thread from a small ring of copies; when it falls behind a frame is
 * not recorded (counted and logged at the end), never is the display held up for it. A PNG is
 * named by the frame's display sequence number (DIR/000001.png is the first published frame,
 * as stillheart-cat -v numbers them). */
#include <dirent.h>
#include <errno.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include "run_sink.h"
#include "stillheart/config.h"
#include "stillheart/core.h"
#include "stillheart/png.h"

#define RING 4

struct run_record {
    char path[SH_CONFIG_STR + 8]; /* the file or folder this start writes */
    sh_y4m_writer *y4m;
    int sync_ms;
    int stream;             /* a FIFO or device (an encoder reading it): written as it is, not synced */
    int64_t last_flush;
    int flushed, synced;    /* flushes handed to the sync thread, and done by it */
    /* png */
    char dir[SH_CONFIG_STR + 8];
    int full_range;
    pthread_t thread;
    int started, stop;
    pthread_mutex_t mu;
    pthread_cond_t cv;
    sh_image ring[RING];
    uint64_t seq[RING];
    int head, count;        /* frames waiting: ring[head .. head + count) */
    uint64_t next_seq, skipped, failed;
    char err[SH_CONFIG_STR + 160];
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

/* Makes every flush durable: fdatasync on the file's descriptor, off the processing thread. */
static void *sync_thread(void *arg)
{
    run_record *r = arg;
    int fd = sh_y4m_writer_fd(r->y4m);
    pthread_mutex_lock(&r->mu);
    for (;;) {
        while (r->synced == r->flushed && !r->stop) pthread_cond_wait(&r->cv, &r->mu);
        if (r->synced == r->flushed) break;
        int upto = r->flushed;
        pthread_mutex_unlock(&r->mu);
        int rc = fdatasync(fd);
        pthread_mutex_lock(&r->mu);
        if (rc != 0 && !r->failed++) snprintf(r->err, sizeof r->err, "%s: fdatasync: %s", r->path, strerror(errno));
        r->synced = upto;
    }
    pthread_mutex_unlock(&r->mu);
    return NULL;
}

/* A folder that may take this start's PNGs: new, or there and empty. */
static int dir_free(const char *dir)
{
    DIR *d = opendir(dir);
    if (!d) return errno == ENOENT;
    struct dirent *e;
    int empty = 1;
    while (empty && (e = readdir(d)))
        if (strcmp(e->d_name, ".") && strcmp(e->d_name, "..")) empty = 0;
    closedir(d);
    return empty;
}

/* spec's name, else NAME-2(.y4m), NAME-3, ...: the first that is free. A FIFO or device under
 * spec's name holds no recording to keep: it is written (an encoder or recorder reading it). */
static sh_status free_name(run_record *r, const char *spec)
{
    int png = !strncmp(spec, "png:", 4);
    const char *name = png ? spec + 4 : spec;
    struct stat sb;
    if (!png && stat(name, &sb) == 0 && (S_ISFIFO(sb.st_mode) || S_ISCHR(sb.st_mode))) {
        snprintf(r->path, sizeof r->path, "%s", name);
        r->stream = 1;
        return SH_OK;
    }
    size_t stem = strlen(name) - (png ? 0 : 4); /* config.c made sure a file ends in .y4m */
    for (int k = 1; k < 10000; k++) {
        if (k == 1)
            snprintf(r->path, sizeof r->path, "%s", name);
        else
            snprintf(r->path, sizeof r->path, "%.*s-%d%s", (int)stem, name, k, png ? "" : ".y4m");
        if (png ? dir_free(r->path) : access(r->path, F_OK) != 0 && errno == ENOENT) return SH_OK;
    }
    return sh_error_set(SH_EIO, "%s: and 9999 numbered names after it are taken", name);
}

sh_status run_record_open(const char *spec, const sh_y4m_header *hdr, int sync_ms, run_record **out)
{
    run_record *r = calloc(1, sizeof *r);
    if (!r) return sh_error_set(SH_ENOMEM, "record: out of memory");
    pthread_mutex_init(&r->mu, NULL);
    pthread_cond_init(&r->cv, NULL);
    r->next_seq = 1;
    r->sync_ms = sync_ms;
    r->last_flush = sh_monotonic_ns();
    sh_status st = free_name(r, spec);
    if (st == SH_OK && strncmp(spec, "png:", 4)) {
        st = r->stream ? sh_y4m_writer_open(r->path, hdr, &r->y4m) : sh_y4m_writer_open_new(r->path, hdr, &r->y4m);
        if (st == SH_OK && !r->stream) st = sh_y4m_writer_flush(r->y4m); /* a valid, empty recording from the start */
        if (st == SH_OK && !r->stream && pthread_create(&r->thread, NULL, sync_thread, r))
            st = sh_error_set(SH_ENOMEM, "record: cannot start the thread that syncs %s", r->path);
        if (st != SH_OK) {
            run_record_close(r);
            return st;
        }
        r->started = !r->stream;
        *out = r;
        return SH_OK;
    }
    snprintf(r->dir, sizeof r->dir, "%s", r->path);
    r->full_range = sh_y4m_header_full_range(hdr);
    if (st != SH_OK || (mkdir(r->dir, 0775) && errno != EEXIST)) {
        if (st == SH_OK) st = sh_error_set(SH_EIO, "%s: %s", r->dir, strerror(errno));
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
    if (r->y4m) {
        sh_status st = sh_y4m_writer_write(r->y4m, shown);
        int64_t now = sh_monotonic_ns();
        if (st != SH_OK || r->stream || now - r->last_flush < (int64_t)r->sync_ms * 1000000) return st;
        r->last_flush = now;
        if ((st = sh_y4m_writer_flush(r->y4m)) != SH_OK) return st;
        pthread_mutex_lock(&r->mu);
        r->flushed++;
        pthread_cond_signal(&r->cv);
        if (r->failed) st = sh_error_set(SH_EIO, "%s", r->err);
        pthread_mutex_unlock(&r->mu);
        return st;
    }
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

const char *run_record_path(const run_record *r) { return r->path; }

sh_status run_record_close(run_record *r)
{
    if (!r) return SH_OK;
    sh_status st = SH_OK;
    if (r->y4m && r->started) { /* a clean stop: everything flushed and made durable */
        st = sh_y4m_writer_flush(r->y4m);
        pthread_mutex_lock(&r->mu);
        r->flushed++;
        r->stop = 1;
        pthread_cond_signal(&r->cv);
        pthread_mutex_unlock(&r->mu);
        pthread_join(r->thread, NULL);
        r->started = 0;
        if (r->failed && st == SH_OK) st = sh_error_set(SH_EIO, "%s", r->err);
    }
    if (r->y4m) {
        sh_status cst = sh_y4m_writer_close(r->y4m);
        if (st == SH_OK) st = cst;
    }
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
