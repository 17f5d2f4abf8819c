#include "stillheart/metrics.h"

#include <math.h>
#include <stdint.h>
#include <stdlib.h>

struct sh_metric {
    int width, height, channels, full_range, frames, pixels;
    sh_image ref_rgb, scratch;  /* RGB24 (or GRAY8) copies */
    uint8_t *inside;            /* hull mask */
    uint64_t *sum;              /* per pixel and channel: sum of |I_t - I_ref| in 0..255 units */
};

void sh_metric_destroy(sh_metric *m)
{
    if (!m) return;
    sh_image_destroy(&m->ref_rgb);
    sh_image_destroy(&m->scratch);
    free(m->inside);
    free(m->sum);
    free(m);
}

/* GRAY8 stays one channel (its metric is over that channel); everything else becomes RGB. */
static sh_status to_working(const sh_metric *m, const sh_image *src, sh_image *dst)
{
    if (src->format == SH_PIX_GRAY8) return sh_image_copy(dst, src);
    return sh_image_to_rgb(src, dst, m->full_range);
}

sh_status sh_metric_create(const sh_image *reference, const sh_hull *hull, int full_range,
                           sh_metric **out)
{
    if (!reference || !hull || !out) return sh_error_set(SH_EINVAL, "metric: missing argument");
    sh_metric *m = calloc(1, sizeof *m);
    if (!m) return sh_error_set(SH_ENOMEM, "metric: out of memory");
    m->width = reference->width;
    m->height = reference->height;
    m->full_range = full_range;
    sh_pixfmt work = reference->format == SH_PIX_GRAY8 ? SH_PIX_GRAY8 : SH_PIX_RGB24;
    m->channels = sh_pixfmt_channels(work);
    size_t npix = (size_t)m->width * m->height;
    sh_status st;
    if ((st = sh_image_create(&m->ref_rgb, work, m->width, m->height)) != SH_OK ||
        (st = sh_image_create(&m->scratch, work, m->width, m->height)) != SH_OK)
        goto fail;
    m->inside = calloc(npix, 1);
    m->sum = calloc(npix * m->channels, sizeof(uint64_t));
    if (!m->inside || !m->sum) {
        st = sh_error_set(SH_ENOMEM, "metric: out of memory");
        goto fail;
    }
    if ((st = to_working(m, reference, &m->ref_rgb)) != SH_OK) goto fail;
    for (int y = 0; y < m->height; y++) {
        int first, last;
        if (!sh_hull_plane_row(hull, y, m->width, 1, 0, 0, &first, &last)) continue;
        for (int x = first; x <= last; x++) m->inside[(size_t)y * m->width + x] = 1;
        m->pixels += last - first + 1;
    }
    *out = m;
    return SH_OK;
fail:
    sh_metric_destroy(m);
    return st;
}

sh_status sh_metric_add(sh_metric *m, const sh_image *frame)
{
    if (!m || !frame) return sh_error_set(SH_EINVAL, "metric: missing frame");
    if (frame->width != m->width || frame->height != m->height)
        return sh_error_set(SH_EINVAL, "metric: frame %dx%d, reference %dx%d", frame->width,
                            frame->height, m->width, m->height);
    if ((frame->format == SH_PIX_GRAY8) != (m->channels == 1))
        return sh_error_set(SH_EINVAL, "metric: grey and colour frames mixed");
    sh_status st = to_working(m, frame, &m->scratch);
    if (st != SH_OK) return st;
    const int ch = m->channels;
    for (int y = 0; y < m->height; y++) {
        const uint8_t *a = m->scratch.plane[0].data + (size_t)y * m->scratch.plane[0].stride;
        const uint8_t *r = m->ref_rgb.plane[0].data + (size_t)y * m->ref_rgb.plane[0].stride;
        const uint8_t *in = m->inside + (size_t)y * m->width;
        uint64_t *s = m->sum + (size_t)y * m->width * ch;
        for (int x = 0; x < m->width; x++) {
            if (!in[x]) continue;
            for (int c = 0; c < ch; c++) s[x * ch + c] += (uint64_t)abs(a[x * ch + c] - r[x * ch + c]);
        }
    }
    m->frames++;
    return SH_OK;
}

int sh_metric_frames(const sh_metric *m)
{
    return m->frames;
}

int sh_metric_pixels(const sh_metric *m)
{
    return m->pixels;
}

double sh_metric_e(const sh_metric *m)
{
    if (m->frames == 0 || m->pixels == 0) return 0;
    /* Sum exactly in integers, divide once: e = total / (255 k p). */
    uint64_t total = 0;
    size_t n = (size_t)m->width * m->height * m->channels;
    for (size_t i = 0; i < n; i++) total += m->sum[i];
    return (double)total / (255.0 * m->frames * m->pixels);
}

sh_status sh_metric_error_image(const sh_metric *m, float *grey)
{
    if (!m || !grey) return sh_error_set(SH_EINVAL, "metric: no output buffer");
    double scale = m->frames ? 1.0 / (255.0 * m->frames * m->channels) : 0;
    for (size_t i = 0; i < (size_t)m->width * m->height; i++) {
        if (!m->inside[i]) {
            grey[i] = NAN;
            continue;
        }
        uint64_t s = 0;
        for (int c = 0; c < m->channels; c++) s += m->sum[i * m->channels + c];
        grey[i] = (float)(s * scale);
    }
    return SH_OK;
}
