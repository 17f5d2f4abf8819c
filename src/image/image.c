#include "stillheart/image.h"

#include <stdlib.h>
#include <string.h>

int sh_pixfmt_channels(sh_pixfmt format)
{
    return format == SH_PIX_RGB24 ? 3 : 1;
}

const char *sh_pixfmt_name(sh_pixfmt format)
{
    switch (format) {
    case SH_PIX_GRAY8: return "gray8";
    case SH_PIX_RGB24: return "rgb24";
    case SH_PIX_I420: return "i420";
    case SH_PIX_YUV444: return "yuv444";
    }
    return "unknown";
}

static int plane_geometry(sh_pixfmt format, int width, int height, int p, int *w, int *h)
{
    switch (format) {
    case SH_PIX_GRAY8:
    case SH_PIX_RGB24:
        if (p > 0) return 0;
        *w = width;
        *h = height;
        return 1;
    case SH_PIX_I420:
        if (p > 2) return 0;
        *w = p ? (width + 1) / 2 : width;
        *h = p ? (height + 1) / 2 : height;
        return 1;
    case SH_PIX_YUV444:
        if (p > 2) return 0;
        *w = width;
        *h = height;
        return 1;
    }
    return 0;
}

static int valid_geometry(sh_pixfmt format, int width, int height)
{
    return width > 0 && height > 0 && width <= SH_IMAGE_MAX_SIZE && height <= SH_IMAGE_MAX_SIZE &&
           format >= SH_PIX_GRAY8 && format <= SH_PIX_YUV444;
}

size_t sh_image_packed_size(sh_pixfmt format, int width, int height)
{
    size_t total = 0;
    int w, h;
    if (!valid_geometry(format, width, height)) return 0;
    for (int p = 0; plane_geometry(format, width, height, p, &w, &h); p++)
        total += (size_t)w * (size_t)h * (size_t)sh_pixfmt_channels(format);
    return total;
}

sh_status sh_image_check_pixels(const char *name, int width, int height, long long max_pixels)
{
    long long px = (long long)width * (long long)height;
    if (px <= max_pixels) return SH_OK;
    return sh_error_set(SH_ERANGE, "%s: %dx%d frames (%lld pixels) are more than the %lld pixels a stream may have",
                        name, width, height, px, max_pixels);
}

static void describe(sh_image *img, sh_pixfmt format, int width, int height)
{
    memset(img, 0, sizeof *img);
    img->format = format;
    img->width = width;
    img->height = height;
    int w, h;
    for (int p = 0; plane_geometry(format, width, height, p, &w, &h); p++) {
        img->plane[p].width = w;
        img->plane[p].height = h;
        img->num_planes = p + 1;
    }
}

sh_status sh_image_create(sh_image *img, sh_pixfmt format, int width, int height)
{
    if (!img || !valid_geometry(format, width, height))
        return sh_error_set(SH_EINVAL, "image: invalid geometry %dx%d", width, height);
    describe(img, format, width, height);
    size_t offsets[SH_IMAGE_MAX_PLANES], total = 0;
    for (int p = 0; p < img->num_planes; p++) {
        size_t row = (size_t)img->plane[p].width * (size_t)sh_pixfmt_channels(format);
        /* 16 bytes of slack per row let vector loads read past the last pixel safely. */
        img->plane[p].stride = (int)((row + 16 + 31) & ~(size_t)31);
        offsets[p] = total;
        total += (size_t)img->plane[p].stride * (size_t)img->plane[p].height;
    }
    uint8_t *mem = aligned_alloc(32, total);
    if (!mem) return sh_error_set(SH_ENOMEM, "image: cannot allocate %zu bytes", total);
    memset(mem, 0, total);
    for (int p = 0; p < img->num_planes; p++) img->plane[p].data = mem + offsets[p];
    img->owned = mem;
    sh_image_clear(img);
    return SH_OK;
}

sh_status sh_image_wrap(sh_image *img, sh_pixfmt format, int width, int height, uint8_t *packed)
{
    if (!img || !packed || !valid_geometry(format, width, height))
        return sh_error_set(SH_EINVAL, "image: invalid geometry %dx%d", width, height);
    describe(img, format, width, height);
    size_t offset = 0;
    for (int p = 0; p < img->num_planes; p++) {
        img->plane[p].stride = img->plane[p].width * sh_pixfmt_channels(format);
        img->plane[p].data = packed + offset;
        offset += (size_t)img->plane[p].stride * (size_t)img->plane[p].height;
    }
    return SH_OK;
}

void sh_image_destroy(sh_image *img)
{
    if (!img) return;
    free(img->owned);
    memset(img, 0, sizeof *img);
}

sh_status sh_image_window(const sh_image *img, int x, int y, int width, int height, sh_image *view)
{
    /* 4:2:0 chroma is shared by 2x2 luma pixels: a window must start on a pair, or its chroma
     * plane would belong half to its neighbour */
    int sub = img && img->format == SH_PIX_I420;
    if (!img || !view || width < 1 || height < 1 || x < 0 || y < 0 || x > img->width - width ||
        y > img->height - height || (sub && ((x | y) & 1)))
        return sh_error_set(SH_EINVAL, "image: no %dx%d window at (%d, %d) of a %dx%d frame%s", width, height, x, y,
                            img ? img->width : 0, img ? img->height : 0, sub ? " (I420: even offsets)" : "");
    sh_image v;
    describe(&v, img->format, width, height);
    v.siting = img->siting;
    int channels = sh_pixfmt_channels(img->format);
    for (int p = 0; p < v.num_planes; p++) {
        int px = sub && p > 0 ? x / 2 : x, py = sub && p > 0 ? y / 2 : y;
        if (px + v.plane[p].width > img->plane[p].width || py + v.plane[p].height > img->plane[p].height)
            return sh_error_set(SH_EINVAL, "image: the %dx%d window at (%d, %d) cuts a chroma sample of the %dx%d frame",
                                width, height, x, y, img->width, img->height);
        v.plane[p].stride = img->plane[p].stride;
        v.plane[p].data = img->plane[p].data + (size_t)py * (size_t)img->plane[p].stride + (size_t)px * (size_t)(p ? 1 : channels);
    }
    *view = v;
    return SH_OK;
}

sh_status sh_image_copy(sh_image *dst, const sh_image *src)
{
    if (!dst || !src || dst->format != src->format || dst->width != src->width ||
        dst->height != src->height)
        return sh_error_set(SH_EINVAL, "image: copy between different formats or sizes");
    dst->siting = src->siting;
    for (int p = 0; p < src->num_planes; p++) {
        size_t row = (size_t)src->plane[p].width * (size_t)sh_pixfmt_channels(src->format);
        for (int y = 0; y < src->plane[p].height; y++)
            memcpy(dst->plane[p].data + (size_t)y * dst->plane[p].stride,
                   src->plane[p].data + (size_t)y * src->plane[p].stride, row);
    }
    return SH_OK;
}

void sh_image_clear(sh_image *img)
{
    for (int p = 0; p < img->num_planes; p++) {
        uint8_t value = (p > 0 && img->format != SH_PIX_RGB24) ? 128 : 0;
        size_t row = (size_t)img->plane[p].width * (size_t)sh_pixfmt_channels(img->format);
        for (int y = 0; y < img->plane[p].height; y++)
            memset(img->plane[p].data + (size_t)y * img->plane[p].stride, value, row);
    }
}
