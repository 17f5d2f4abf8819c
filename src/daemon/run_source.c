/* stillheart run's cameras: a thread per camera, sets grouped under one lock, the sets waiting for
 * processing (run_source.h: the newest only, or a short queue with [source] queue_ms). Frame
 * buffers live in a small pool per camera; a buffer is free, being filled by its camera's thread,
 * in a pending set (sync.h holds its index as `user`), in a waiting set or in the set processing
 * holds.
 * About 700 lines, on purpose: the pool, the grouping, the waiting sets and the camera threads share
 * one lock and one buffer life cycle, and split across files each would have to know the
 * others' invariants (the options that are not, source_options.c, already went). */
#include "run_source.h"
#include "stillheart/daemon.h"

#include <errno.h>
#include <math.h>
#include <poll.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>

#include "stillheart/log.h"

#define POOL 8 /* per camera: filling + pending sets (a few frame periods) + waiting + held */
/* Sets that may wait with queue_ms. Each beyond the first holds a buffer more of every camera's
 * pool (12.4 MB a 4K camera), allocated and touched at open so that RSS does not step up at the
 * first stall; 8 sets are 133 ms at 60 frames/s, longer than any stall measured (docs/daemon.md). */
#define QUEUE_MAX 8
#define POOL_MAX (POOL + QUEUE_MAX - 1)
/* Processing times of the last sets, whose median says whether processing keeps up with the
 * camera: odd, so that the median is one of them; long enough that a few slow sets (a model
 * built, a stall) do not switch it, short enough to follow a change of load soon (8 sets switch
 * it: 133 ms at 60 frames/s, 320 ms at 25). */
#define BUSY_WINDOW 15
#define BUSY_MIN 5
/* Behind for this long before it is logged: every start is behind for a few sets (the first
 * detections search the whole frame, the reference's models are built), which is no news. */
#define BEHIND_LOG_NS 1000000000LL
#define DEQUEUE_MS 100

enum { FREE = 0, FILLING, PENDING, IN_SET };

typedef struct {
    run_source *rs;
    int index;
    char name[SH_CONFIG_STR + 8];
    char thread_name[16];
    sh_source *src;
    sh_pixconv *conv;
    sh_rawfmt format;
    int width, height, fps_num, fps_den;
    int replay;            /* y4m: or rec: */
    int nframes;           /* y4m: frames in the file (points test mode), 0 = unknown */
    sh_image pool[POOL_MAX];
    int npool;             /* buffers allocated: POOL + the queue's */
    uint64_t seq[POOL_MAX];
    unsigned epoch[POOL_MAX]; /* the source's discontinuities up to the buffer's frame */
    unsigned discontinuities;
    int state[POOL_MAX];
    int inflight;          /* buffers PENDING */
    run_camera_stats st;
    int64_t beat_ns;       /* the thread last went round its loop (run_source_alive) */
    int64_t frame_ns;      /* the source last gave a frame (or the start) */
    int64_t timeout_ns;    /* no frame for this long: lost (camera_timeout_ms, two periods at least) */
    pthread_t thread;
    int started;
} camera;

struct run_source {
    pthread_mutex_t mu;
    pthread_cond_t cv;
    int ncam, out;
    camera cam[SH_CONFIG_MAX_CAMERAS];
    sh_sync *sync;
    sh_gpio_trigger *trig;
    pthread_t trig_thread;
    int trig_started;
    int64_t trig_beat_ns;
    int64_t output_ns;     /* a set with the output camera's frame was last delivered (or the start) */
    run_frame queue[QUEUE_MAX]; /* the sets waiting, oldest first from qhead (a ring) */
    int qhead, nwaiting, qcap;
    int64_t queue_ns;      /* queue_ms: a waiting set older than this (since capture) is dropped
                            * unless it is the newest */
    int64_t period_ns;     /* the output camera's frame period */
    int64_t taken_ns;      /* the held set was taken (its processing began) */
    int64_t busy_ns[BUSY_WINDOW]; /* processing times of the last sets (a ring), with queue_ms */
    int nbusy, busy_next;
    int behind;            /* their median is over the period: only the newest set is taken */
    int64_t behind_ns;     /* since when */
    int behind_logged;     /* and said so */
    sh_log_limit behind_log, caught_up_log; /* a load that comes and goes: once a minute */
    run_frame held;
    int have_held;
    int paced;             /* as fast as possible, nothing dropped: every camera a replay */
    int nended, eof, stop;
    int failed;            /* the output camera ended in an error (run_source_failed) */
    uint64_t dropped;      /* sets dropped while waiting (the queue full, or too old): processing
                            * was behind */
    uint64_t no_output;    /* sets without the output camera's frame */
    sh_y4m_header hdr;
    double fps;
};

/* ---- under rs->mu ---- */
static void free_buffers(run_source *rs, const run_frame *f)
{
    for (int c = 0; c < rs->ncam; c++)
        if (f->cam[c]) rs->cam[c].state[f->cam[c] - rs->cam[c].pool] = FREE;
}

/* The oldest waiting set is dropped: processing is behind. */
static void drop_oldest(run_source *rs)
{
    free_buffers(rs, &rs->queue[rs->qhead]);
    rs->qhead = (rs->qhead + 1) % QUEUE_MAX;
    rs->nwaiting--;
    rs->dropped++;
}

/* A set popped from the grouping joins the waiting sets; when they are as many as may wait, the
 * oldest is dropped (with one, the newest replaces it). */
static void deliver(run_source *rs, const sh_frame_set *set)
{
    run_frame f;
    memset(&f, 0, sizeof f);
    f.cameras = rs->ncam;
    for (int c = 0; c < rs->ncam; c++) {
        if (!(set->present & (1u << c))) continue;
        camera *k = &rs->cam[c];
        int b = (int)(intptr_t)set->member[c].user;
        k->state[b] = IN_SET;
        k->inflight--;
        f.cam[c] = &k->pool[b];
    }
    if (!f.cam[rs->out]) { /* nothing to show */
        free_buffers(rs, &f);
        rs->no_output++;
        return;
    }
    camera *o = &rs->cam[rs->out];
    uint64_t seq = set->member[rs->out].sequence;
    f.img = *f.cam[rs->out];
    f.index = o->nframes > 0 ? (int)(seq % (uint64_t)o->nframes) : (int)seq;
    f.epoch = o->epoch[(int)(intptr_t)set->member[rs->out].user];
    f.capture_ns = set->time_ns;
    f.set = set->index;
    f.complete = set->complete;
    f.avail_ns = sh_monotonic_ns();
    rs->output_ns = f.avail_ns;
    if (rs->nwaiting == rs->qcap) drop_oldest(rs);
    rs->queue[(rs->qhead + rs->nwaiting) % QUEUE_MAX] = f;
    rs->nwaiting++;
    pthread_cond_broadcast(&rs->cv);
}

static void drain(run_source *rs)
{
    sh_frame_set set;
    while (sh_sync_pop(rs->sync, &set)) deliver(rs, &set);
}

static void flush(run_source *rs)
{
    sh_sync_flush(rs->sync);
    drain(rs);
}

/* The camera's replay ended or failed for good: the others go on (their sets incomplete, each
 * out once the cameras still going have their frames in it); when every camera, or the output
 * camera, is gone the source has ended. */
static void camera_ended(run_source *rs, camera *k, int failed)
{
    pthread_mutex_lock(&rs->mu);
    k->st.ended = 1;
    rs->failed |= failed && k->index == rs->out;
    rs->nended++;
    sh_sync_camera_gone(rs->sync, k->index);
    if (rs->nended == rs->ncam || k->index == rs->out) rs->eof = 1;
    if (rs->eof)
        flush(rs);
    else
        drain(rs);
    pthread_cond_broadcast(&rs->cv);
    pthread_mutex_unlock(&rs->mu);
}

/* Paced replay: wait while a set waits for processing or this camera's last frame has not yet
 * left the grouping, so the cameras go in step with processing and nothing is dropped. When every
 * camera still going has a frame in the grouping and no set is ready, no camera can add the frame
 * that completes one (stamps too far apart for one set): the pending sets are flushed, incomplete,
 * rather than stall. However slow a machine, a camera that is merely late is never flushed past. */
static void pace(run_source *rs, camera *k)
{
    pthread_mutex_lock(&rs->mu);
    while (rs->paced && !rs->stop && (rs->nwaiting || k->inflight)) {
        int stuck = !rs->nwaiting;
        for (int c = 0; c < rs->ncam; c++) stuck &= rs->cam[c].st.ended || rs->cam[c].inflight > 0;
        if (stuck) {
            flush(rs);
            continue;
        }
        k->beat_ns = sh_monotonic_ns(); /* waiting for processing is not hanging */
        struct timespec ts;
        clock_gettime(CLOCK_REALTIME, &ts);
        ts.tv_nsec += 50000000;
        ts.tv_sec += ts.tv_nsec / 1000000000;
        ts.tv_nsec %= 1000000000;
        pthread_cond_timedwait(&rs->cv, &rs->mu, &ts);
    }
    pthread_mutex_unlock(&rs->mu);
}

static int stopping(run_source *rs)
{
    pthread_mutex_lock(&rs->mu);
    int s = rs->stop;
    pthread_mutex_unlock(&rs->mu);
    return s;
}

/* Buffer b, filled (cst: how its conversion went), goes to the grouping, or back to the pool when
 * it is bad, late or a duplicate. */
static void settle(run_source *rs, camera *k, int b, sh_status cst, uint64_t seq, int64_t ts)
{
    pthread_mutex_lock(&rs->mu);
    if (cst != SH_OK) {
        k->st.bad++;
        k->state[b] = FREE;
    } else {
        k->st.converted++;
        k->seq[b] = seq;
        k->epoch[b] = k->discontinuities;
        sh_sync_disposition d = SH_SYNC_LATE;
        k->state[b] = PENDING;
        k->inflight++;
        sh_sync_push(rs->sync, k->index, seq, ts, (void *)(intptr_t)b, &d);
        if (d != SH_SYNC_ADDED) {
            if (d == SH_SYNC_LATE) k->st.late++;
            else k->st.duplicates++;
            k->state[b] = FREE;
            k->inflight--;
        }
        drain(rs);
    }
    pthread_mutex_unlock(&rs->mu);
}

/* A free buffer of the camera's pool, now FILLING; -1 when none is free. */
static int take_buffer(run_source *rs, camera *k)
{
    pthread_mutex_lock(&rs->mu);
    int b = -1;
    for (int i = 0; i < k->npool && b < 0; i++)
        if (k->state[i] == FREE) b = i;
    if (b >= 0) k->state[b] = FILLING;
    pthread_mutex_unlock(&rs->mu);
    return b;
}

static void give_back(run_source *rs, camera *k, int b)
{
    pthread_mutex_lock(&rs->mu);
    k->state[b] = FREE;
    pthread_mutex_unlock(&rs->mu);
}

static void *camera_thread(void *arg)
{
    camera *k = arg;
    run_source *rs = k->rs;
    sh_log_limit bad = {0};
    uint64_t losses = 0, reopens = 0, damaged = 0;
    sh_log_set_thread(k->thread_name);
    while (!stopping(rs)) {
        pace(rs, k);
        /* a free buffer first: a replay in the working format reads into it, no copy after */
        int b = take_buffer(rs, k);
        sh_source_frame f;
        int got = 0, direct = 0;
        sh_status st = b >= 0 ? sh_source_dequeue_into(k->src, DEQUEUE_MS, &k->pool[b], &f, &got, &direct)
                              : sh_source_dequeue(k->src, DEQUEUE_MS, &f, &got);
        if (b >= 0 && !got) give_back(rs, k, b);
        sh_source_stats ss;
        sh_source_get_stats(k->src, &ss);
        if (ss.losses != losses)
            sh_log_warn("%s lost (%llu times so far), reopening with back-off; the other cameras go on",
                    k->name, (unsigned long long)ss.losses);
        if (ss.reopens != reopens) sh_log_info("%s is back", k->name);
        /* a replay met damage in its file and goes on (or ends) past it: said once, where it is
         * (damage that stops it comes back as the error below) */
        if (ss.damaged != damaged && (st == SH_OK || st == SH_EEOF))
            sh_log_warn("%s: %s", k->name, sh_source_damage(k->src));
        damaged = ss.damaged;
        losses = ss.losses;
        reopens = ss.reopens;
        pthread_mutex_lock(&rs->mu);
        k->st.source = ss; /* also while the camera is down: online says so */
        k->beat_ns = sh_monotonic_ns();
        if (got) k->frame_ns = k->beat_ns;
        pthread_mutex_unlock(&rs->mu);
        if (st == SH_EEOF) {
            sh_log_info("%s: end of stream", k->name);
            camera_ended(rs, k, 0);
            break;
        }
        if (st != SH_OK) {
            sh_log_error("%s: %s", k->name, sh_error_message());
            camera_ended(rs, k, 1);
            break;
        }
        if (!got) continue;
        if (b < 0) {
            pthread_mutex_lock(&rs->mu);
            k->st.no_buffer++;
            pthread_mutex_unlock(&rs->mu);
        }
        sh_status cst = b >= 0 && !direct ? sh_pixconv_convert(k->conv, &f.raw, &k->pool[b]) : SH_OK;
        if (cst != SH_OK)
            sh_log_limited(&bad, SH_LOG_ERROR, "%s: frame %llu: %s (further bad frames counted only)", k->name,
                           (unsigned long long)f.sequence, sh_error_message());
        uint64_t seq = f.sequence;
        int64_t ts = f.timestamp_ns;
        k->discontinuities += f.discontinuity != 0; /* counted even for a frame not kept */
        sh_source_release(k->src, &f);
        if (b >= 0) settle(rs, k, b, cst, seq, ts);
    }
    return NULL;
}

static void *trigger_thread(void *arg)
{
    run_source *rs = arg;
    sh_log_limit err = {0};
    sh_log_set_thread("trigger");
    while (!stopping(rs)) {
        struct pollfd p = {sh_gpio_trigger_fd(rs->trig), POLLIN, 0};
        poll(&p, 1, DEQUEUE_MS);
        int64_t edge;
        int got = 0;
        if (sh_gpio_trigger_service(rs->trig, &edge, &got) != SH_OK) {
            sh_log_limited(&err, SH_LOG_ERROR, "%s", sh_error_message());
            continue;
        }
        sh_log_limit_clear(&err);
        pthread_mutex_lock(&rs->mu);
        rs->trig_beat_ns = sh_monotonic_ns();
        if (got) {
            sh_sync_trigger(rs->sync, edge);
            drain(rs);
        }
        pthread_mutex_unlock(&rs->mu);
    }
    return NULL;
}

/* A y4m: camera's file opened a second time (its header, its frame count) is read from the
 * start only when it is a regular file: a FIFO or stdin would block for a writer that has gone,
 * or take bytes from the stream the camera reads. */
static int regular_file(const char *path)
{
    struct stat sb;
    return stat(path, &sb) == 0 && S_ISREG(sb.st_mode);
}

/* Frames in a Y4M file (for the points test mode, whose frame numbers restart with each loop):
 * from its size when every frame header is a bare "FRAME" (so a long 1080p file is not read
 * through at start), else by reading it; 0 (unknown) for a pipe. */
static int count_y4m_frames(const char *path, int max_pixels)
{
    sh_y4m_reader *r;
    if (!regular_file(path)) return 0;
    if (sh_y4m_reader_open_max(path, max_pixels, &r) != SH_OK) return 0;
    const sh_y4m_header *h = sh_y4m_reader_header(r);
    size_t frame = sh_image_packed_size(h->format, h->width, h->height) + 6; /* "FRAME\n" */
    int n = 0;
    FILE *f = fopen(path, "rb");
    long hlen = 0, size = -1;
    if (f) {
        int c;
        while ((c = fgetc(f)) != EOF && c != '\n') hlen++;
        if (c == '\n' && !fseek(f, 0, SEEK_END)) size = ftell(f);
        fclose(f);
    }
    long body = size - hlen - 1;
    if (size > 0 && body >= 0 && (size_t)body % frame == 0) {
        n = (int)((size_t)body / frame);
    } else {
        sh_image img;
        if (sh_image_create(&img, h->format, h->width, h->height) == SH_OK) {
            while (sh_y4m_reader_read(r, &img) == SH_OK) n++;
            sh_image_destroy(&img);
        }
    }
    sh_y4m_reader_close(r);
    return n;
}

/* The camera's pool up to n buffers in its working format (sh_image_create touches every page). */
static sh_status grow_pool(camera *k, int n)
{
    sh_pixfmt pf = k->format == SH_RAW_GREY ? SH_PIX_GRAY8 : SH_PIX_I420;
    for (; k->npool < n; k->npool++) {
        sh_status st = sh_image_create(&k->pool[k->npool], pf, k->width, k->height);
        if (st != SH_OK) return st;
    }
    return SH_OK;
}

static sh_status open_camera(run_source *rs, const sh_config *cfg, int i)
{
    camera *k = &rs->cam[i];
    const char *spec = cfg->camera[i].spec;
    k->rs = rs;
    k->index = i;
    snprintf(k->name, sizeof k->name, "camera %d (%s)", i, spec);
    snprintf(k->thread_name, sizeof k->thread_name, "cam%d", i);
    k->replay = run_is_replay(spec);
    sh_source_options o;
    sh_daemon_camera_options(cfg, i, &o);
    sh_status st = sh_source_open(spec, &o, &k->src);
    char what[32];
    snprintf(what, sizeof what, "[camera%d] spec", i);
    if (st == SH_ERANGE) /* the bound, not the camera, may be what is wrong: name it */
        return sh_error_set(st, "%s: %s ([source] max_frame_pixels = %d)", what, sh_error_message(),
                            cfg->max_frame_pixels);
    if (st != SH_OK) return sh_error_set(st, "%s: %s", what, sh_error_message());
    sh_source_format(k->src, &k->format, &k->width, &k->height, &k->fps_num, &k->fps_den);
    if (k->format == SH_RAW_MJPEG && (st = sh_pixconv_create(k->width, k->height, &k->conv)) != SH_OK) return st;
    if ((st = grow_pool(k, POOL)) != SH_OK) return st;
    if (cfg->points[0] && !strncmp(spec, "y4m:", 4))
        k->nframes = count_y4m_frames(spec + 4, cfg->max_frame_pixels);
    return SH_OK;
}

sh_status run_source_open(const sh_config *cfg, run_source **out)
{
    *out = NULL;
    run_source *rs = calloc(1, sizeof *rs);
    if (!rs) return sh_error_set(SH_ENOMEM, "source: out of memory");
    pthread_mutex_init(&rs->mu, NULL);
    pthread_cond_init(&rs->cv, NULL);
    rs->out = cfg->output_camera;
    int n = sh_config_cameras(cfg);
    int all_replay = 1;
    sh_status st = SH_OK;
    for (int i = 0; i < n && st == SH_OK; i++) {
        rs->ncam = i + 1;
        st = open_camera(rs, cfg, i);
        all_replay &= rs->cam[i].replay;
    }
    if (st == SH_OK && rs->out >= n)
        st = sh_error_set(SH_EINVAL, "[source] output: camera %d, but %d configured", rs->out, n);
    if (st != SH_OK) {
        run_source_destroy(rs);
        return st;
    }
    rs->paced = all_replay && !cfg->realtime;
    /* the sets a stall of queue_ms spans, and the newest; as fast as possible one waits at most */
    double period = run_period_ns(rs->cam[rs->out].fps_num, rs->cam[rs->out].fps_den);
    rs->qcap = 1;
    rs->queue_ns = (int64_t)cfg->queue_ms * 1000000;
    rs->period_ns = (int64_t)period;
    rs->behind_log.period_s = rs->caught_up_log.period_s = 60;
    if (!rs->paced && cfg->queue_ms > 0) {
        double spans = ceil(rs->queue_ns / period);
        rs->qcap = spans + 1 >= QUEUE_MAX ? QUEUE_MAX : 1 + (int)spans;
    }
    for (int i = 0; i < n && st == SH_OK; i++) st = grow_pool(&rs->cam[i], POOL + rs->qcap - 1);
    if (st != SH_OK) {
        run_source_destroy(rs);
        return st;
    }
    for (int i = 0; i < n; i++) { /* a slow replay's frames are further apart than a camera's timeout */
        camera *k = &rs->cam[i];
        double t = 1e6 * (cfg->camera_timeout_ms > 0 ? cfg->camera_timeout_ms : 1000);
        double p2 = 2 * run_period_ns(k->fps_num, k->fps_den);
        k->timeout_ns = (int64_t)(t > p2 ? t : p2);
    }
    camera *k0 = &rs->cam[0], *ko = &rs->cam[rs->out];
    sh_sync_options so;
    sh_daemon_sync_options(cfg, n, k0->fps_num, k0->fps_den, &so);
    sh_gpio_options go;
    if ((st = sh_sync_create(&so, &rs->sync)) != SH_OK ||
        (sh_daemon_gpio_options(cfg, k0->fps_num, k0->fps_den, &go) && (st = sh_gpio_trigger_open(&go, &rs->trig)) != SH_OK)) {
        if (rs->sync && !rs->trig) st = sh_error_set(st, "[trigger]: %s", sh_error_message());
        run_source_destroy(rs);
        return st;
    }
    /* a replayed file keeps its own header (extras, siting), so a record of it is a Y4M like
     * the input; cameras get one from their format */
    sh_y4m_reader *r = NULL;
    const char *ospec = cfg->camera[rs->out].spec;
    if (!strncmp(ospec, "y4m:", 4) && regular_file(ospec + 4) &&
        sh_y4m_reader_open_max(ospec + 4, cfg->max_frame_pixels, &r) == SH_OK) {
        rs->hdr = *sh_y4m_reader_header(r);
        rs->hdr.format = ko->pool[0].format;
        sh_y4m_reader_close(r);
    } else {
        sh_daemon_y4m_header(ko->format, ko->width, ko->height, ko->fps_num, ko->fps_den, &rs->hdr);
    }
    rs->fps = ko->fps_num > 0 && ko->fps_den > 0 ? (double)ko->fps_num / ko->fps_den : 0;
    *out = rs;
    return SH_OK;
}

const sh_y4m_header *run_source_header(const run_source *rs) { return &rs->hdr; }

double run_source_fps(const run_source *rs) { return rs->fps; }

int run_source_cameras(const run_source *rs) { return rs->ncam; }

sh_status run_source_start(run_source *rs)
{
    /* Every replay's schedule starts at the same instant, so frame k of each has the same stamp
     * and they form sets. Started back to back on the time of each start, they did not always:
     * under qemu-aarch64 beside other jobs the three starts of a rig spread over more than the
     * quarter period sets allow, and no set of the run had two cameras (issue 21's loop at
     * bb21afd, run 2: 120 frames "checking the calibration (0 markers)"). */
    int64_t now = sh_monotonic_ns();
    for (int i = 0; i < rs->ncam; i++)
        if (sh_source_start_at(rs->cam[i].src, now) != SH_OK)
            return sh_error_set(SH_EIO, "%s: %s", rs->cam[i].name, sh_error_message());
    pthread_mutex_lock(&rs->mu);
    rs->output_ns = rs->trig_beat_ns = now;
    for (int i = 0; i < rs->ncam; i++) {
        camera *k = &rs->cam[i];
        k->beat_ns = k->frame_ns = now;
        sh_source_get_stats(k->src, &k->st.source); /* online as started, before the first dequeue */
    }
    pthread_mutex_unlock(&rs->mu);
    if (rs->trig) {
        if (sh_gpio_trigger_start(rs->trig) != SH_OK)
            return sh_error_set(SH_EIO, "[trigger]: %s", sh_error_message());
        if (pthread_create(&rs->trig_thread, NULL, trigger_thread, rs))
            return sh_error_set(SH_ENOMEM, "trigger: cannot start its thread");
        rs->trig_started = 1;
    }
    if (rs->qcap > 1)
        sh_log_info("sets wait for processing in order while captured at most %lld ms ago (%d at most)",
                (long long)(rs->queue_ns / 1000000), rs->qcap);
    for (int i = 0; i < rs->ncam; i++) {
        camera *k = &rs->cam[i];
        sh_log_info("%s: %dx%d %s at %d/%d fps%s%s", k->name, k->width, k->height,
                sh_rawfmt_name(k->format), k->fps_num, k->fps_den, i == rs->out ? ", shown" : "",
                k->replay ? (rs->paced ? ", replayed as fast as processing goes" : ", replayed in real time") : "");
        if (pthread_create(&rs->cam[i].thread, NULL, camera_thread, &rs->cam[i]))
            return sh_error_set(SH_ENOMEM, "%s: cannot start its thread", rs->cam[i].name);
        rs->cam[i].started = 1;
    }
    return SH_OK;
}

/* Under rs->mu, with queue_ms: the held set's processing took busy_ns. A queue helps only while
 * processing keeps up with the camera: after a stall it catches up, showing the sets late for a
 * moment. When processing is slower than the camera for good (a busy machine, a camera faster than
 * the pipeline), waiting sets would only show every frame queue_ms late for as long as that
 * lasts; while the median of the last sets' processing times is over the frame period, only the
 * newest set is taken, as with the mailbox. Returns +1 when that has lasted BEHIND_LOG_NS (to be
 * logged), -1 when such a spell ends, else 0. */
static int note_busy(run_source *rs, int64_t busy_ns, int64_t now)
{
    rs->busy_ns[rs->busy_next] = busy_ns;
    rs->busy_next = (rs->busy_next + 1) % BUSY_WINDOW;
    if (rs->nbusy < BUSY_WINDOW) rs->nbusy++;
    if (rs->nbusy < BUSY_MIN) return 0;
    int64_t v[BUSY_WINDOW];
    int n = rs->nbusy;
    for (int i = 0; i < n; i++) { /* insertion sort: 15 values */
        int64_t x = rs->busy_ns[i];
        int j = i;
        for (; j > 0 && v[j - 1] > x; j--) v[j] = v[j - 1];
        v[j] = x;
    }
    int behind = v[n / 2] > rs->period_ns, say = 0;
    if (behind && !rs->behind) {
        rs->behind_ns = now;
        rs->behind_logged = 0;
    } else if (behind && !rs->behind_logged && now - rs->behind_ns >= BEHIND_LOG_NS) {
        rs->behind_logged = 1;
        say = 1;
    } else if (!behind && rs->behind && rs->behind_logged) {
        say = -1;
    }
    rs->behind = behind;
    return say;
}

const run_frame *run_source_take(run_source *rs, int timeout_ms)
{
    int64_t entry = sh_monotonic_ns();
    int change = 0;
    pthread_mutex_lock(&rs->mu);
    if (rs->have_held && rs->qcap > 1) change = note_busy(rs, entry - rs->taken_ns, entry);
    if (rs->have_held) {
        free_buffers(rs, &rs->held);
        rs->have_held = 0;
        pthread_cond_broadcast(&rs->cv);
    }
    struct timespec ts;
    clock_gettime(CLOCK_REALTIME, &ts);
    ts.tv_nsec += (long)timeout_ms * 1000000;
    ts.tv_sec += ts.tv_nsec / 1000000000;
    ts.tv_nsec %= 1000000000;
    while (!rs->nwaiting && !rs->eof && !rs->stop)
        if (pthread_cond_timedwait(&rs->cv, &rs->mu, &ts) == ETIMEDOUT) break;
    /* sets captured more than queue_ms ago are dropped, the newest never: after a stall the
     * queue shows what is still recent in order and skips what is too late to show; while
     * processing is behind for good, only the newest is shown (note_busy) */
    if (rs->queue_ns > 0) {
        int64_t now = sh_monotonic_ns();
        while (rs->nwaiting > 1) {
            const run_frame *f = &rs->queue[rs->qhead];
            if (!rs->behind && now - (f->capture_ns > 0 ? f->capture_ns : f->avail_ns) <= rs->queue_ns) break;
            drop_oldest(rs);
        }
    }
    if (rs->nwaiting) {
        rs->held = rs->queue[rs->qhead];
        rs->qhead = (rs->qhead + 1) % QUEUE_MAX;
        rs->nwaiting--;
        rs->have_held = 1;
        rs->taken_ns = sh_monotonic_ns();
        pthread_cond_broadcast(&rs->cv);
    }
    int got = rs->have_held;
    pthread_mutex_unlock(&rs->mu);
    /* logged outside the lock: the cameras' threads wait on it */
    if (change > 0)
        sh_log_limited(&rs->behind_log, SH_LOG_WARN,
                       "processing has been slower than the camera for a second (a set takes longer than its "
                       "%.1f ms period, median of the last %d): only the newest set is shown until it keeps up",
                       (double)rs->period_ns / 1e6, BUSY_WINDOW);
    else if (change < 0)
        sh_log_limited(&rs->caught_up_log, SH_LOG_INFO,
                       "processing keeps up with the camera again: sets wait in order (queue_ms)");
    return got ? &rs->held : NULL;
}

int run_source_ended(run_source *rs)
{
    pthread_mutex_lock(&rs->mu);
    int e = rs->eof && !rs->nwaiting;
    pthread_mutex_unlock(&rs->mu);
    return e;
}

int run_source_failed(run_source *rs)
{
    pthread_mutex_lock(&rs->mu);
    int f = rs->failed;
    pthread_mutex_unlock(&rs->mu);
    return f;
}

uint64_t run_source_dropped(run_source *rs)
{
    pthread_mutex_lock(&rs->mu);
    uint64_t d = rs->dropped;
    pthread_mutex_unlock(&rs->mu);
    return d;
}

void run_source_camera_stats(run_source *rs, int c, run_camera_stats *out)
{
    memset(out, 0, sizeof *out);
    if (c < 0 || c >= rs->ncam) return;
    pthread_mutex_lock(&rs->mu);
    *out = rs->cam[c].st;
    pthread_mutex_unlock(&rs->mu);
}

/* Under rs->mu: "ended", "lost" or NULL (delivering). A camera is lost while source.h reopens
 * it, and any camera, a replay too, that gave no frame for camera_timeout_ms; as fast as
 * possible the cameras wait for processing, so silence there is not a loss. */
static const char *camera_down(const run_source *rs, const camera *k, int64_t now)
{
    if (k->st.ended) return "ended";
    if (!k->replay && !k->st.source.online) return "lost";
    return !rs->paced && now - k->frame_ns > k->timeout_ns ? "lost" : NULL;
}

int run_source_online(run_source *rs, char *text, size_t cap)
{
    int n = 0;
    char down[96] = "";
    int64_t now = sh_monotonic_ns();
    pthread_mutex_lock(&rs->mu);
    for (int c = 0; c < rs->ncam; c++) {
        const char *why = camera_down(rs, &rs->cam[c], now);
        if (!why) {
            n++;
            continue;
        }
        size_t used = strlen(down);
        snprintf(down + used, sizeof down - used, "%scamera %d %s", used ? ", " : "", c, why);
    }
    int total = rs->ncam;
    pthread_mutex_unlock(&rs->mu);
    snprintf(text, cap, "%d/%d cameras%s%s%s", n, total, down[0] ? " (" : "", down, down[0] ? ")" : "");
    return n;
}

int run_source_output_lost(run_source *rs, char *text, size_t cap)
{
    int64_t now = sh_monotonic_ns();
    pthread_mutex_lock(&rs->mu);
    const camera *k = &rs->cam[rs->out];
    const char *why = camera_down(rs, k, now);
    int lost = 0;
    if (!rs->eof && !rs->nwaiting && !rs->have_held) {
        if (why && !strcmp(why, "lost")) lost = 1;
        else if (!rs->paced && now - rs->output_ns > k->timeout_ns) lost = 2;
    }
    if (lost == 1)
        snprintf(text, cap, "camera %d lost, %s", k->index, k->replay ? "waiting for its frames" : "reopening");
    else if (lost == 2)
        snprintf(text, cap, "camera %d delivers, but no set with its frame for %lld ms", k->index,
                 (long long)((now - rs->output_ns) / 1000000));
    pthread_mutex_unlock(&rs->mu);
    return lost;
}

int run_source_alive(run_source *rs, int64_t max_age_ns, char *who, size_t cap)
{
    int64_t now = sh_monotonic_ns();
    int alive = 1;
    pthread_mutex_lock(&rs->mu);
    for (int c = 0; c < rs->ncam && alive; c++) {
        const camera *k = &rs->cam[c];
        if (k->started && !k->st.ended && now - k->beat_ns > max_age_ns) {
            snprintf(who, cap, "%s: its thread has not come round for %lld ms", k->name,
                     (long long)((now - k->beat_ns) / 1000000));
            alive = 0;
        }
    }
    if (alive && rs->trig_started && now - rs->trig_beat_ns > max_age_ns) {
        snprintf(who, cap, "the trigger thread has not come round for %lld ms",
                 (long long)((now - rs->trig_beat_ns) / 1000000));
        alive = 0;
    }
    pthread_mutex_unlock(&rs->mu);
    return alive;
}

void run_source_sync_stats(run_source *rs, sh_sync_stats *out)
{
    pthread_mutex_lock(&rs->mu);
    sh_sync_get_stats(rs->sync, out);
    pthread_mutex_unlock(&rs->mu);
}

static void log_stats(run_source *rs)
{
    for (int c = 0; c < rs->ncam; c++) {
        run_camera_stats st;
        run_source_camera_stats(rs, c, &st);
        sh_log_info(
                "%s: %llu frames, %llu damaged, %llu dropped by the driver, %llu without a buffer, %llu bad, %llu late, "
                "%llu duplicate, %llu losses, %llu reopens",
                rs->cam[c].name, (unsigned long long)st.converted, (unsigned long long)st.source.errors,
                (unsigned long long)st.source.drops, (unsigned long long)st.no_buffer, (unsigned long long)st.bad,
                (unsigned long long)st.late, (unsigned long long)st.duplicates, (unsigned long long)st.source.losses,
                (unsigned long long)st.source.reopens);
    }
    sh_sync_stats ss;
    run_source_sync_stats(rs, &ss);
    pthread_mutex_lock(&rs->mu);
    uint64_t no_output = rs->no_output;
    pthread_mutex_unlock(&rs->mu);
    sh_log_info("sets: %llu (%llu incomplete), %llu dropped while processing was behind, %llu without "
            "the output camera's frame", (unsigned long long)ss.sets, (unsigned long long)ss.incomplete,
            (unsigned long long)run_source_dropped(rs), (unsigned long long)no_output);
}

void run_source_destroy(run_source *rs)
{
    if (!rs) return;
    pthread_mutex_lock(&rs->mu);
    rs->stop = 1;
    pthread_cond_broadcast(&rs->cv);
    pthread_mutex_unlock(&rs->mu);
    int ran = 0;
    for (int i = 0; i < rs->ncam; i++)
        if (rs->cam[i].started) pthread_join(rs->cam[i].thread, NULL), ran = 1;
    if (ran) log_stats(rs);
    if (rs->trig_started) pthread_join(rs->trig_thread, NULL);
    for (int i = 0; i < rs->ncam; i++) {
        camera *k = &rs->cam[i];
        sh_source_close(k->src);
        sh_pixconv_destroy(k->conv);
        for (int b = 0; b < k->npool; b++) sh_image_destroy(&k->pool[b]);
    }
    sh_gpio_trigger_close(rs->trig);
    sh_sync_destroy(rs->sync);
    pthread_mutex_destroy(&rs->mu);
    pthread_cond_destroy(&rs->cv);
    free(rs);
}
