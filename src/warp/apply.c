/* The executor: cuts the output frame into horizontal stripes, one per thread, and fills each
 * plane row from the model's spans. Threads are started once and wait on a condition variable
 * between frames, so a frame costs no thread creation and no allocation. */
#include <pthread.h>
#include <sched.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "warp_internal.h"

/* What the warp last wrote into an output buffer: each plane row's inside, pixels [first, last]
 * (first > last: none), the rest black. sh_warp_apply_again writes black only where a row's
 * inside was and no longer is: at 4K the whole outside is about 0.5 ms of memset a frame (both
 * threads), and the hull of one model does not move. Kept for the last KEPT buffers. */
#define KEPT 4
typedef struct {
    const uint8_t *data[SH_IMAGE_MAX_PLANES]; /* which buffer; NULL: the entry is free */
    int width, height, format;
    int row0[SH_IMAGE_MAX_PLANES];  /* plane p's rows in first[] and last[] from row0[p] */
    int rows, capacity;
    int32_t *first, *last;
    unsigned stamp;           /* last used: the oldest goes first */
} kept_output;

typedef struct {
    const sh_warp_model *model;
    const sh_image *current;
    sh_image *out;
    kept_output *kept;    /* where the rows' insides are noted (NULL: out of memory, not noted) */
    int again;            /* kept describes out as it is: only the changed outside is written */
    const int *split;     /* stripe k: full-resolution rows split[k] .. split[k + 1] - 1 */
    sh_warp_model *grid;  /* not NULL: the job is this model's grid map instead, */
    int grid_rows;        /*   its node rows cut in equal parts (warp_model_grid_rows) */
} warp_job;

struct sh_warp {
    int threads;
    pthread_t *workers;
    pthread_mutex_t lock;
    pthread_cond_t start, done;
    atomic_uint generation; /* bumped per job (under lock): workers run when it changes */
    atomic_int pending;   /* workers still busy with the current job (changed under lock) */
    int quit;
    warp_job job;
    int row_capacity;     /* pixels per thread in row_coords */
    int32_t *row_coords;  /* per thread: fx[row_capacity], fy[row_capacity] */
    kept_output kept[KEPT];
    unsigned clock;
    int *split;           /* threads + 1 stripe bounds (warp_job) */
};

void warp_plane_offsets(const sh_image *img, int p, plane_geometry *g)
{
    g->scale = 1;
    g->ox = g->oy = 0;
    if (img->format != SH_PIX_I420 || p == 0) return;
    g->scale = 2;
    switch (img->siting) {
    case SH_CHROMA_CENTER: g->ox = 0.5; g->oy = 0.5; break;
    case SH_CHROMA_LEFT: g->ox = 0; g->oy = 0.5; break;
    case SH_CHROMA_PALDV: g->ox = 0; g->oy = p == 1 ? 1 : 0; break; /* Cb below, Cr on the line */
    }
}

static int same_geometry(const plane_geometry *a, const plane_geometry *b)
{
    return a->scale == b->scale && a->ox == b->ox && a->oy == b->oy && a->width == b->width &&
           a->height == b->height;
}

/* Black on the row's pixels [a, b] (nothing when b < a). */
static void black_span(uint8_t *row, int channels, uint8_t black, int a, int b)
{
    if (b >= a) memset(row + (size_t)a * channels, black, (size_t)(b - a + 1) * channels);
}

/* The row's outside made black: all of it, or with `was` (the inside the buffer's row had, the
 * rest of it black already) only what was inside and is not now. */
static void black_outside(uint8_t *row, int channels, uint8_t black, int width, int first, int last, const int32_t *was)
{
    if (!was) {
        if (first > last) {
            black_span(row, channels, black, 0, width - 1);
            return;
        }
        black_span(row, channels, black, 0, first - 1);
        black_span(row, channels, black, last + 1, width - 1);
        return;
    }
    int f0 = was[0], l0 = was[1];
    if (first > last) {
        black_span(row, channels, black, f0, l0);
        return;
    }
    black_span(row, channels, black, f0, l0 < first - 1 ? l0 : first - 1);
    black_span(row, channels, black, f0 > last + 1 ? f0 : last + 1, l0);
}

/* The stripe's rows of every plane. Planes that sit alike (4:2:0's U and V at every siting but
 * PAL DV's, all three of 4:4:4) are done together, row by row: the row's extent and source
 * positions are made once and sampled from each (the same positions each would have made). */
static void run_stripe(const warp_job *job, int stripe, int32_t *fx, int32_t *fy)
{
    const sh_image *cur = job->current;
    sh_image *out = job->out;
    int channels = sh_pixfmt_channels(cur->format);
    for (int p = 0, q; p < cur->num_planes; p = q) {
        plane_geometry g;
        warp_plane_offsets(cur, p, &g);
        g.width = out->plane[p].width;
        g.height = out->plane[p].height;
        for (q = p + 1; q < cur->num_planes; q++) {
            plane_geometry h;
            warp_plane_offsets(cur, q, &h);
            h.width = out->plane[q].width;
            h.height = out->plane[q].height;
            if (!same_geometry(&g, &h)) break;
        }
        const int full = cur->plane[0].height;
        int y0 = (int)((long)g.height * job->split[stripe] / full);
        int y1 = (int)((long)g.height * job->split[stripe + 1] / full);
        for (int y = y0; y < y1; y++) {
            int first, last;
            int inside = warp_model_row_extent(job->model, &g, y, &first, &last);
            if (inside) warp_model_row_fill(job->model, &g, y, first, last, fx, fy);
            else first = g.width, last = -1;
            for (int k = p; k < q; k++) {
                uint8_t *row = out->plane[k].data + (size_t)y * out->plane[k].stride;
                uint8_t black = (k > 0 && cur->format != SH_PIX_RGB24) ? 128 : 0;
                int32_t was[2] = {0, -1};
                if (job->kept) {
                    int32_t *nf = job->kept->first + job->kept->row0[k] + y, *nl = job->kept->last + job->kept->row0[k] + y;
                    was[0] = *nf;
                    was[1] = *nl;
                    *nf = first;
                    *nl = last;
                }
                black_outside(row, channels, black, g.width, first, last, job->again ? was : NULL);
                if (inside)
                    warp_sample_row(&cur->plane[k], channels, black, row + (size_t)first * channels, fx, fy,
                                    last - first + 1);
            }
        }
    }
}

/* Thread index's part of a job: its stripe of the frame, or its rows of the grid's nodes. */
static void run_part(sh_warp *w, const warp_job *job, int index)
{
    if (job->grid) {
        warp_model_grid_rows(job->grid, (int)((long)job->grid_rows * index / w->threads),
                             (int)((long)job->grid_rows * (index + 1) / w->threads), index);
        return;
    }
    run_stripe(job, index, w->row_coords + 2 * (size_t)index * w->row_capacity,
               w->row_coords + (2 * (size_t)index + 1) * w->row_capacity);
}

/* Waking a sleeping thread costs 50-150 us on the 2-core VMs measured (the idle core halts),
 * about as much as the map update it would share. So a thread that is out of work looks for
 * the next job, or for the others' end, this long before it sleeps: the update's job and the
 * warp's follow each other within it, and stripes of equal work end within it. At 60 frames/s
 * that is at most 1.2 % of a core per thread for each job a frame brings (2.4 % with the
 * update's); it yields between looks, so that a thread of the daemon's that has work
 * (detection, capture) gets the core first. */
#define SPIN_NS 200000L

static long long now_ns(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (long long)t.tv_sec * 1000000000LL + t.tv_nsec;
}

static inline void relax(void)
{
#if defined(__x86_64__) || defined(__i386__)
    __builtin_ia32_pause();
#elif defined(__aarch64__)
    __asm__ volatile("yield");
#endif
}

/* Returns once *v differs from `was`, or after SPIN_NS. */
static void spin_while_uint(atomic_uint *v, unsigned was)
{
    long long end = now_ns() + SPIN_NS;
    for (;;) {
        for (int i = 0; i < 64; i++) {
            if (atomic_load_explicit(v, memory_order_acquire) != was) return;
            relax();
        }
        if (now_ns() > end) return;
        sched_yield();
    }
}

static void spin_while_positive(atomic_int *v)
{
    long long end = now_ns() + SPIN_NS;
    for (;;) {
        for (int i = 0; i < 64; i++) {
            if (atomic_load_explicit(v, memory_order_acquire) <= 0) return;
            relax();
        }
        if (now_ns() > end) return;
        sched_yield();
    }
}

/* The job on every thread, this one taking part 0; returns when all are done. */
static void run_all(sh_warp *w, const warp_job *job)
{
    if (w->threads == 1) {
        run_part(w, job, 0);
        return;
    }
    pthread_mutex_lock(&w->lock);
    w->job = *job;
    w->pending = w->threads - 1;
    w->generation++;
    pthread_cond_broadcast(&w->start);
    pthread_mutex_unlock(&w->lock);
    run_part(w, job, 0);
    spin_while_positive(&w->pending);
    pthread_mutex_lock(&w->lock);
    while (w->pending > 0) pthread_cond_wait(&w->done, &w->lock);
    pthread_mutex_unlock(&w->lock);
}

typedef struct {
    sh_warp *warp;
    int index;
} worker_arg;

static void *worker_main(void *arg)
{
    worker_arg *wa = arg;
    sh_warp *w = wa->warp;
    int index = wa->index;
    free(wa);
    unsigned seen = 0;
    for (;;) {
        spin_while_uint(&w->generation, seen);
        pthread_mutex_lock(&w->lock);
        while (!w->quit && w->generation == seen) pthread_cond_wait(&w->start, &w->lock);
        if (w->quit) break;
        seen = w->generation;
        warp_job job = w->job;
        pthread_mutex_unlock(&w->lock);
        run_part(w, &job, index);
        pthread_mutex_lock(&w->lock);
        if (--w->pending == 0) pthread_cond_signal(&w->done);
        pthread_mutex_unlock(&w->lock);
    }
    pthread_mutex_unlock(&w->lock);
    return NULL;
}

sh_status sh_warp_create(int threads, sh_warp **out)
{
    if (!out || threads < 1 || threads > 256)
        return sh_error_set(SH_EINVAL, "warp: threads must be 1..256, got %d", threads);
    warp_sample_init();
    sh_warp *w = calloc(1, sizeof *w);
    if (!w) return sh_error_set(SH_ENOMEM, "warp: out of memory");
    w->threads = threads;
    w->split = malloc(sizeof(int) * ((size_t)threads + 1));
    if (!w->split) {
        free(w);
        return sh_error_set(SH_ENOMEM, "warp: out of memory");
    }
    pthread_mutex_init(&w->lock, NULL);
    pthread_cond_init(&w->start, NULL);
    pthread_cond_init(&w->done, NULL);
    if (threads > 1) {
        w->workers = calloc((size_t)threads - 1, sizeof(pthread_t));
        if (!w->workers) {
            sh_warp_destroy(w);
            return sh_error_set(SH_ENOMEM, "warp: out of memory");
        }
        for (int i = 1; i < threads; i++) {
            worker_arg *wa = malloc(sizeof *wa);
            if (!wa || (*wa = (worker_arg){w, i}, pthread_create(&w->workers[i - 1], NULL,
                                                                 worker_main, wa)) != 0) {
                free(wa);
                w->threads = i; /* destroy joins only the ones started */
                sh_warp_destroy(w);
                return sh_error_set(SH_ENOMEM, "warp: cannot start thread %d", i);
            }
        }
    }
    *out = w;
    return SH_OK;
}

void sh_warp_destroy(sh_warp *w)
{
    if (!w) return;
    pthread_mutex_lock(&w->lock);
    w->quit = 1;
    pthread_cond_broadcast(&w->start);
    pthread_mutex_unlock(&w->lock);
    for (int i = 1; i < w->threads && w->workers; i++) pthread_join(w->workers[i - 1], NULL);
    free(w->workers);
    free(w->row_coords);
    free(w->split);
    for (int i = 0; i < KEPT; i++) {
        free(w->kept[i].first);
        free(w->kept[i].last);
    }
    pthread_mutex_destroy(&w->lock);
    pthread_cond_destroy(&w->start);
    pthread_cond_destroy(&w->done);
    free(w);
}

static int same_buffer(const kept_output *k, const sh_image *out)
{
    if (k->width != out->width || k->height != out->height || k->format != (int)out->format) return 0;
    for (int p = 0; p < out->num_planes; p++)
        if (k->data[p] != out->plane[p].data) return 0;
    return k->data[0] != NULL;
}

/* out's entry, with *known 1 when it was noted before; a new one takes the oldest entry's place.
 * NULL when the rows cannot be allocated: the output is then written whole and not noted. */
static kept_output *kept_for(sh_warp *w, const sh_image *out, int *known)
{
    kept_output *k = NULL;
    *known = 0;
    for (int i = 0; i < KEPT && !k; i++)
        if (same_buffer(&w->kept[i], out)) k = &w->kept[i], *known = 1;
    for (int i = 0; i < KEPT && !k; i++)
        if (!w->kept[i].data[0]) k = &w->kept[i];
    if (!k) {
        k = &w->kept[0];
        for (int i = 1; i < KEPT; i++)
            if (w->kept[i].stamp < k->stamp) k = &w->kept[i];
    }
    k->stamp = ++w->clock;
    if (*known) return k;
    int rows = 0;
    for (int p = 0; p < out->num_planes; p++) {
        k->row0[p] = rows;
        rows += out->plane[p].height;
    }
    k->data[0] = NULL; /* not this buffer's until it is whole */
    if (rows > k->capacity) {
        int32_t *f = realloc(k->first, sizeof(int32_t) * (size_t)rows);
        if (f) k->first = f;
        int32_t *l = f ? realloc(k->last, sizeof(int32_t) * (size_t)rows) : NULL;
        if (l) k->last = l;
        if (!f || !l) return NULL;
        k->capacity = rows;
    }
    k->rows = rows;
    k->width = out->width;
    k->height = out->height;
    k->format = (int)out->format;
    for (int p = 0; p < SH_IMAGE_MAX_PLANES; p++) k->data[p] = p < out->num_planes ? out->plane[p].data : NULL;
    return k;
}

static sh_status apply(sh_warp *w, const sh_warp_model *model, const sh_image *current, sh_image *out, int again);

/* Stripes of equal work rather than equal rows: the hull seldom sits in the frame's middle
 * (the bench's 4K frames: up to 1.2x the inside pixels in one half). A row costs its inside
 * pixels (the sampling and the row fill, every plane in proportion) and an eighth of its width
 * (the black fill, the row's setup); estimated on every 8th full-resolution row, bounds even so
 * that 4:2:0 chroma rows split at half of them. */
#define BALANCE_STEP 8

static void balance_stripes(const sh_warp_model *model, const sh_image *cur, int stripes, int *split)
{
    plane_geometry g;
    warp_plane_offsets(cur, 0, &g);
    g.width = cur->plane[0].width;
    g.height = cur->plane[0].height;
    double total = 0;
    for (int y = 0; y < g.height; y += BALANCE_STEP) {
        int first, last;
        total += g.width / 8.0 + (warp_model_row_extent(model, &g, y, &first, &last) ? last - first + 1 : 0);
    }
    split[0] = 0;
    double done = 0;
    int k = 1;
    for (int y = 0; y < g.height && k < stripes; y += BALANCE_STEP) {
        int first, last;
        done += g.width / 8.0 + (warp_model_row_extent(model, &g, y, &first, &last) ? last - first + 1 : 0);
        while (k < stripes && done >= total * k / stripes) split[k++] = y + BALANCE_STEP;
    }
    for (; k < stripes; k++) split[k] = g.height;
    for (k = 1; k < stripes; k++) {
        split[k] &= ~1;
        if (split[k] > g.height) split[k] = g.height & ~1;
        if (split[k] < split[k - 1]) split[k] = split[k - 1];
    }
    split[stripes] = g.height;
}

sh_status sh_warp_apply(sh_warp *w, const sh_warp_model *model, const sh_image *current, sh_image *out)
{
    return apply(w, model, current, out, 0);
}

sh_status sh_warp_apply_again(sh_warp *w, const sh_warp_model *model, const sh_image *current, sh_image *out)
{
    return apply(w, model, current, out, 1);
}

static sh_status apply(sh_warp *w, const sh_warp_model *model, const sh_image *current, sh_image *out, int again)
{
    if (!w || !model || !current || !out)
        return sh_error_set(SH_EINVAL, "warp: missing argument");
    if (current->format != out->format || current->width != out->width ||
        current->height != out->height || current->width != model->width ||
        current->height != model->height)
        return sh_error_set(SH_EINVAL, "warp: frame %dx%d %s, output %dx%d %s, model %dx%d",
                            current->width, current->height, sh_pixfmt_name(current->format),
                            out->width, out->height, sh_pixfmt_name(out->format), model->width,
                            model->height);
    out->siting = current->siting;
    if (current->width > w->row_capacity) {
        /* Sized once for the frame geometry: later frames of the same size allocate nothing. */
        int32_t *coords = malloc(sizeof(int32_t) * 2 * (size_t)w->threads * current->width);
        if (!coords) return sh_error_set(SH_ENOMEM, "warp: out of memory");
        free(w->row_coords);
        w->row_coords = coords;
        w->row_capacity = current->width;
    }
    int known;
    kept_output *kept = kept_for(w, out, &known);
    if (w->threads == 1) {
        w->split[0] = 0;
        w->split[1] = current->height;
    } else {
        balance_stripes(model, current, w->threads, w->split);
    }
    warp_job job = {model, current, out, kept, again && known, w->split, NULL, 0};
    run_all(w, &job);
    return SH_OK;
}

/* A grid too small to be worth a wake-up per thread is made here: at 4K with 16 px cells
 * (33 000 nodes, 0.3 ms) the threads pay; a few hundred nodes cost less than waking one. */
#define GRID_SHARED_NODES 4096

static void grid_on_threads(void *ctx, sh_warp_model *m, int rows)
{
    sh_warp *w = ctx;
    if (w->threads == 1 || (long)rows * m->nx < GRID_SHARED_NODES || rows < w->threads) {
        warp_model_grid_rows(m, 0, rows, 0);
        return;
    }
    warp_job job = {.grid = m, .grid_rows = rows};
    run_all(w, &job);
}

sh_status sh_warp_update(sh_warp *w, sh_warp_model *model, const double *cur_xy, const unsigned char *use)
{
    if (!w || !model) return sh_error_set(SH_EINVAL, "warp: missing argument");
    return warp_model_update_with(model, cur_xy, use, grid_on_threads, w, w->threads);
}
