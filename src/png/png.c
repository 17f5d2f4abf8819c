/* PNG through libpng, both ways (imageio reads PNG files through here). libpng reports errors by
 * longjmp; its messages are caught here and turned into a status (library code never prints),
 * and a half-written file is removed. */
#include "stillheart/png.h"

#ifdef SH_HAVE_PNG

#include <errno.h>
#include <png.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

typedef struct {
    char message[200];
} png_ctx;

static void on_error(png_structp png, png_const_charp msg)
{
    png_ctx *ctx = png_get_error_ptr(png);
    snprintf(ctx->message, sizeof ctx->message, "%s", msg ? msg : "libpng error");
    png_longjmp(png, 1);
}

static void on_warning(png_structp png, png_const_charp msg)
{
    (void)png;
    (void)msg;
}

static void rgb_row_to_gray(const uint8_t *s, uint8_t *d, int w)
{
    for (int x = 0; x < w; x++, s += 3)
        d[x] = (uint8_t)((77u * s[0] + 150u * s[1] + 29u * s[2] + 128u) >> 8);
}

/* Everything setjmp's return must see is reached through `out` and `row` (not locals changed
 * after setjmp). */
static sh_status read_rows(FILE *f, const char *path, sh_image *out, int gray, uint8_t **row)
{
    png_ctx ctx = {{0}};
    png_structp png = png_create_read_struct(PNG_LIBPNG_VER_STRING, &ctx, on_error, on_warning);
    png_infop info = png ? png_create_info_struct(png) : NULL;
    if (!png || !info) {
        png_destroy_read_struct(&png, &info, NULL);
        return sh_error_set(SH_ENOMEM, "%s: cannot create the PNG reader", path);
    }
    if (setjmp(png_jmpbuf(png))) {
        png_destroy_read_struct(&png, &info, NULL);
        return sh_error_set(SH_EFORMAT, "%s: bad PNG: %s", path, ctx.message);
    }
    png_init_io(png, f);
    png_set_user_limits(png, SH_IMAGE_MAX_SIZE, SH_IMAGE_MAX_SIZE);
    png_read_info(png, info);
    png_uint_32 w = png_get_image_width(png, info), h = png_get_image_height(png, info);
    int color = png_get_color_type(png, info);
    png_set_strip_16(png);
    png_set_strip_alpha(png);
    png_set_packing(png);
    if (color == PNG_COLOR_TYPE_PALETTE) png_set_palette_to_rgb(png);
    if (color == PNG_COLOR_TYPE_GRAY || color == PNG_COLOR_TYPE_GRAY_ALPHA)
        png_set_expand_gray_1_2_4_to_8(png);
    /* interlaced files: each pass rewrites the rows */
    int passes = png_set_interlace_handling(png);
    png_read_update_info(png, info);
    int channels = png_get_channels(png, info);
    if (channels != 1 && channels != 3) png_error(png, "unexpected channel count");
    sh_pixfmt fmt = (channels == 1 || gray) ? SH_PIX_GRAY8 : SH_PIX_RGB24;
    if (sh_image_create(out, fmt, (int)w, (int)h) != SH_OK) png_error(png, "out of memory");
    if (channels == 3 && fmt == SH_PIX_GRAY8) {
        *row = malloc((size_t)w * 3);
        if (!*row) png_error(png, "out of memory");
    }
    for (int pass = 0; pass < passes; pass++)
        for (png_uint_32 y = 0; y < h; y++) {
            uint8_t *dst = out->plane[0].data + (size_t)y * (size_t)out->plane[0].stride;
            if (*row) {
                /* interlaced colour to grey would need the whole RGB image: refused */
                if (passes > 1) png_error(png, "interlaced colour PNG read as grey");
                png_read_row(png, *row, NULL);
                rgb_row_to_gray(*row, dst, (int)w);
            } else {
                png_read_row(png, dst, NULL);
            }
        }
    png_read_end(png, NULL);
    png_destroy_read_struct(&png, &info, NULL);
    return SH_OK;
}
sh_status sh_png_read(FILE *f, const char *path, int gray, sh_image *img)
{
    if (!f || !path || !img) return sh_error_set(SH_EINVAL, "png: missing argument");
    memset(img, 0, sizeof *img);
    uint8_t *row = NULL;
    sh_status st = read_rows(f, path, img, gray, &row);
    free(row);
    if (st != SH_OK) sh_image_destroy(img);
    return st;
}

/* Writes an RGB24 or GRAY8 image; everything volatile that setjmp's return must see. */
static sh_status write_rows(FILE *f, const char *path, const sh_image *img)
{
    png_ctx ctx = {{0}};
    png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, &ctx, on_error, on_warning);
    png_infop info = png ? png_create_info_struct(png) : NULL;
    if (!png || !info) {
        png_destroy_write_struct(&png, NULL);
        return sh_error_set(SH_ENOMEM, "%s: cannot create the PNG writer", path);
    }
    if (setjmp(png_jmpbuf(png))) {
        png_destroy_write_struct(&png, &info);
        return sh_error_set(SH_EIO, "%s: PNG write failed: %s", path, ctx.message);
    }
    png_init_io(png, f);
    int color = img->format == SH_PIX_RGB24 ? PNG_COLOR_TYPE_RGB : PNG_COLOR_TYPE_GRAY;
    png_set_IHDR(png, info, (png_uint_32)img->width, (png_uint_32)img->height, 8, color,
                 PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
    png_write_info(png, info);
    for (int y = 0; y < img->height; y++)
        png_write_row(png, img->plane[0].data + (size_t)y * (size_t)img->plane[0].stride);
    png_write_end(png, info);
    png_destroy_write_struct(&png, &info);
    return SH_OK;
}

sh_status sh_png_write(const char *path, const sh_image *img, int full_range)
{
    if (!path || !img || !img->plane[0].data)
        return sh_error_set(SH_EINVAL, "png: missing argument");
    sh_image rgb = {0};
    const sh_image *src = img;
    if (img->format == SH_PIX_I420 || img->format == SH_PIX_YUV444) {
        sh_status st = sh_image_create(&rgb, SH_PIX_RGB24, img->width, img->height);
        if (st != SH_OK) return st;
        st = sh_image_to_rgb(img, &rgb, full_range);
        if (st != SH_OK) {
            sh_image_destroy(&rgb);
            return st;
        }
        src = &rgb;
    } else if (img->format != SH_PIX_GRAY8 && img->format != SH_PIX_RGB24) {
        return sh_error_set(SH_EINVAL, "%s: cannot write pixel format %d as PNG", path,
                            (int)img->format);
    }

    int is_stdout = strcmp(path, "-") == 0;
    FILE *f = is_stdout ? stdout : fopen(path, "wb");
    if (!f) {
        sh_image_destroy(&rgb);
        return sh_error_set(SH_EIO, "%s: %s", path, strerror(errno));
    }
    /* Only a regular file we just wrote is removed on failure: never a device (/dev/full). */
    struct stat sb;
    int regular = !is_stdout && fstat(fileno(f), &sb) == 0 && S_ISREG(sb.st_mode);
    sh_status st = write_rows(f, path, src);
    sh_image_destroy(&rgb);
    /* A full disk shows up at the flush or the close, after libpng thinks all went well. */
    if (fflush(f) != 0 && st == SH_OK)
        st = sh_error_set(SH_EIO, "%s: write error: %s", path, strerror(errno));
    if (!is_stdout) {
        if (fclose(f) != 0 && st == SH_OK)
            st = sh_error_set(SH_EIO, "%s: write error: %s", path, strerror(errno));
        if (st != SH_OK && regular) remove(path);
    }
    return st;
}

#else /* !SH_HAVE_PNG */

#include <string.h>

sh_status sh_png_read(FILE *f, const char *path, int gray, sh_image *img)
{
    (void)f;
    (void)gray;
    if (img) memset(img, 0, sizeof *img);
    return sh_error_set(SH_EUNSUPPORTED, "%s: built without libpng", path ? path : "png");
}

sh_status sh_png_write(const char *path, const sh_image *img, int full_range)
{
    (void)img;
    (void)full_range;
    return sh_error_set(SH_EUNSUPPORTED, "%s: built without libpng, PNG output unavailable",
                        path ? path : "png");
}

#endif
