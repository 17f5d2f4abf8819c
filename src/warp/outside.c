/* Outside the hull: the current frame dimmed, with a boundary line (warp.h, docs/warp.md).
 *
 * The hull is convex, so each plane row holds its inside pixels as one interval, and the
 * boundary of a row is the union of the neighbouring rows' intervals widened by the line's
 * width. Both depend on the hull alone, so they are kept per plane row as runs (dimmed or
 * boundary, the inside left out) and made again only when the hull changes: a frame then costs
 * one pass over the outside pixels, reading the current frame and writing the output. */
#include <stdlib.h>
#include <string.h>

#include "warp_internal.h"

enum { RUN_DIM, RUN_LINE };

typedef struct {
    int32_t x0, x1, kind; /* pixels x0..x1 of the row */
} run;

typedef struct {
    int width, height, d;   /* the plane's size; the line's width in its pixels */
    int channels;
    uint8_t black;          /* what dimming goes halfway to */
    uint8_t colour[3];      /* the line's: one sample, or R G B */
    int *first, *last;      /* the row's inside pixels, first > last when none */
    int *row_start;         /* row y: runs[row_start[y] .. row_start[y + 1]) */
    run *runs;
} plane_runs;

struct sh_warp_outside {
    sh_pixfmt format;
    int width, height, planes;
    plane_runs plane[SH_IMAGE_MAX_PLANES];
    int valid;                 /* the runs below were made for hull and siting */
    sh_chroma_siting siting;
    int hull_count;
    double *hull_xy;           /* the hull's vertices, x then y: SH_HULL_MAX_VERTICES each */
};

/* Runs of one row at most: the 2d + 1 widened intervals merge into m <= 2d + 1, each with a
 * dimmed run before it and at most two boundary runs (split by the inside), and one dimmed run
 * after the last. */
static int max_runs(int d) { return 3 * (2 * d + 1) + 1; }

void sh_warp_outside_destroy(sh_warp_outside *o)
{
    if (!o) return;
    for (int p = 0; p < SH_IMAGE_MAX_PLANES; p++) {
        free(o->plane[p].first);
        free(o->plane[p].last);
        free(o->plane[p].row_start);
        free(o->plane[p].runs);
    }
    free(o->hull_xy);
    free(o);
}

sh_status sh_warp_outside_create(sh_pixfmt format, int width, int height, int full_range,
                                 sh_warp_outside **out)
{
    if (!out) return sh_error_set(SH_EINVAL, "warp outside: missing argument");
    if (format < SH_PIX_GRAY8 || format > SH_PIX_YUV444 || width < 1 || height < 1 || width > SH_IMAGE_MAX_SIZE ||
        height > SH_IMAGE_MAX_SIZE)
        return sh_error_set(SH_EINVAL, "warp outside: invalid frames %dx%d", width, height);
    sh_warp_outside *o = calloc(1, sizeof *o);
    if (!o) return sh_error_set(SH_ENOMEM, "warp outside: out of memory");
    o->format = format;
    o->width = width;
    o->height = height;
    o->planes = format == SH_PIX_I420 || format == SH_PIX_YUV444 ? 3 : 1;
    o->hull_xy = malloc(sizeof(double) * 2 * SH_HULL_MAX_VERTICES);
    int ok = o->hull_xy != NULL;
    /* BT.601 cyan, RGB (0, 255, 255), rounded to the nearest code value (warp.h) */
    static const uint8_t cyan_limited[3] = {170, 166, 16}, cyan_full[3] = {179, 171, 1};
    for (int p = 0; p < o->planes && ok; p++) {
        plane_runs *pr = &o->plane[p];
        int chroma = p > 0 && format != SH_PIX_RGB24;
        int scale = format == SH_PIX_I420 && p > 0 ? 2 : 1;
        pr->width = (width + scale - 1) / scale; /* 4:2:0 chroma rounded up (image.h) */
        pr->height = (height + scale - 1) / scale;
        pr->d = SH_WARP_OUTSIDE_LINE / scale > 0 ? SH_WARP_OUTSIDE_LINE / scale : 1;
        pr->channels = format == SH_PIX_RGB24 ? 3 : 1;
        pr->black = chroma ? 128 : format == SH_PIX_RGB24 || full_range ? 0 : 16;
        if (format == SH_PIX_RGB24) {
            pr->colour[0] = 0;
            pr->colour[1] = pr->colour[2] = 255;
        } else {
            pr->colour[0] = (full_range ? cyan_full : cyan_limited)[p];
        }
        pr->first = malloc(sizeof(int) * (size_t)pr->height);
        pr->last = malloc(sizeof(int) * (size_t)pr->height);
        pr->row_start = malloc(sizeof(int) * ((size_t)pr->height + 1));
        pr->runs = malloc(sizeof(run) * (size_t)pr->height * (size_t)max_runs(pr->d));
        ok = pr->first && pr->last && pr->row_start && pr->runs;
    }
    if (!ok) {
        sh_warp_outside_destroy(o);
        return sh_error_set(SH_ENOMEM, "warp outside: out of memory");
    }
    *out = o;
    return SH_OK;
}

static int same_hull(const sh_warp_outside *o, const sh_hull *h, sh_chroma_siting siting)
{
    return o->valid && o->siting == siting && o->hull_count == h->count &&
           !memcmp(o->hull_xy, h->x, sizeof(double) * (size_t)h->count) &&
           !memcmp(o->hull_xy + SH_HULL_MAX_VERTICES, h->y, sizeof(double) * (size_t)h->count);
}

static void emit(run *r, int *n, int x0, int x1, int kind)
{
    if (x0 > x1) return;
    r[*n] = (run){x0, x1, kind};
    (*n)++;
}

/* Row y's runs into r (returns how many): the inside [first[y], last[y]] left out, the
 * boundary the union of [first[k] - d, last[k] + d] over the rows k within d of y. */
static int row_runs(const plane_runs *pr, int y, run *r)
{
    int s[16], e[16], m = 0; /* 2d + 1 <= 5 intervals: d <= SH_WARP_OUTSIDE_LINE */
    for (int k = y - pr->d; k <= y + pr->d; k++) {
        if (k < 0 || k >= pr->height || pr->first[k] > pr->last[k]) continue;
        int a = pr->first[k] - pr->d, b = pr->last[k] + pr->d;
        a = a < 0 ? 0 : a;
        b = b >= pr->width ? pr->width - 1 : b;
        int i = m++;
        while (i > 0 && s[i - 1] > a) { /* insertion by start */
            s[i] = s[i - 1];
            e[i] = e[i - 1];
            i--;
        }
        s[i] = a;
        e[i] = b;
    }
    int merged = 0;
    for (int i = 0; i < m; i++) {
        if (merged && s[i] <= e[merged - 1] + 1) {
            if (e[i] > e[merged - 1]) e[merged - 1] = e[i];
            continue;
        }
        s[merged] = s[i];
        e[merged] = e[i];
        merged++;
    }
    int n = 0, cursor = 0, f = pr->first[y], l = pr->last[y];
    for (int i = 0; i < merged; i++) {
        emit(r, &n, cursor, s[i] - 1, RUN_DIM);
        if (f <= l) {
            emit(r, &n, s[i], e[i] < f - 1 ? e[i] : f - 1, RUN_LINE);
            emit(r, &n, s[i] > l + 1 ? s[i] : l + 1, e[i], RUN_LINE);
        } else {
            emit(r, &n, s[i], e[i], RUN_LINE);
        }
        cursor = e[i] + 1;
    }
    emit(r, &n, cursor, pr->width - 1, RUN_DIM);
    return n;
}

static void make_runs(sh_warp_outside *o, const sh_warp_model *model, const sh_image *frame)
{
    for (int p = 0; p < o->planes; p++) {
        plane_runs *pr = &o->plane[p];
        plane_geometry g;
        warp_plane_offsets(frame, p, &g);
        g.width = pr->width;
        g.height = pr->height;
        for (int y = 0; y < pr->height; y++)
            if (!warp_model_row_extent(model, &g, y, &pr->first[y], &pr->last[y])) pr->first[y] = 1, pr->last[y] = 0;
        int used = 0;
        for (int y = 0; y < pr->height; y++) {
            pr->row_start[y] = used;
            used += row_runs(pr, y, pr->runs + used);
        }
        pr->row_start[pr->height] = used;
    }
    const sh_hull *h = &model->hull;
    memcpy(o->hull_xy, h->x, sizeof(double) * (size_t)h->count);
    memcpy(o->hull_xy + SH_HULL_MAX_VERTICES, h->y, sizeof(double) * (size_t)h->count);
    o->hull_count = h->count;
    o->siting = frame->siting;
    o->valid = 1;
}

/* (v + b + 1) >> 1 over whole rows: the form compilers turn into a rounding average (pavgb,
 * urhadd) of 16 or more bytes a step. */
static void dim(uint8_t *restrict dst, const uint8_t *restrict src, size_t n, uint8_t black)
{
    for (size_t i = 0; i < n; i++) dst[i] = (uint8_t)((src[i] + black + 1) >> 1);
}

static void line(uint8_t *dst, size_t pixels, int channels, const uint8_t *colour)
{
    if (channels == 1) {
        memset(dst, colour[0], pixels);
        return;
    }
    for (size_t i = 0; i < pixels; i++, dst += 3) memcpy(dst, colour, 3);
}

sh_status sh_warp_outside_apply(sh_warp_outside *o, const sh_warp_model *model,
                                const sh_image *current, sh_image *out)
{
    if (!o || !model || !current || !out)
        return sh_error_set(SH_EINVAL, "warp outside: missing argument");
    if (current->format != o->format || out->format != o->format || current->width != o->width ||
        current->height != o->height || out->width != o->width || out->height != o->height ||
        model->width != o->width || model->height != o->height)
        return sh_error_set(SH_EINVAL, "warp outside: made for %dx%d %s, frame %dx%d %s, output %dx%d %s, "
                            "model %dx%d", o->width, o->height, sh_pixfmt_name(o->format), current->width,
                            current->height, sh_pixfmt_name(current->format), out->width, out->height,
                            sh_pixfmt_name(out->format), model->width, model->height);
    if (!same_hull(o, &model->hull, current->siting)) make_runs(o, model, current);
    for (int p = 0; p < o->planes; p++) {
        const plane_runs *pr = &o->plane[p];
        const sh_plane *sp = &current->plane[p];
        sh_plane *dp = &out->plane[p];
        size_t ch = (size_t)pr->channels;
        for (int y = 0; y < pr->height; y++) {
            const uint8_t *src = sp->data + (size_t)y * sp->stride;
            uint8_t *dst = dp->data + (size_t)y * dp->stride;
            for (int k = pr->row_start[y]; k < pr->row_start[y + 1]; k++) {
                const run *r = &pr->runs[k];
                size_t at = (size_t)r->x0 * ch, len = (size_t)(r->x1 - r->x0 + 1);
                if (r->kind == RUN_DIM) dim(dst + at, src + at, len * ch, pr->black);
                else line(dst + at, len, pr->channels, pr->colour);
            }
        }
    }
    return SH_OK;
}
