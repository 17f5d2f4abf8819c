/* PNG output through libpng. libpng reports errors by longjmp; its messages are caught here and
 * turned into a status (library code never prints), and a half-written file is removed. */
#include "stillheart/png.h"

#ifdef SH_HAVE_PNG

#include <errno.h>
#include <png.h>
#include <stdio.h>
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

sh_status sh_png_write(const char *path, const sh_image *img, int full_range)
{
    (void)img;
    (void)full_range;
    return sh_error_set(SH_EUNSUPPORTED, "%s: built without libpng, PNG output unavailable",
                        path ? path : "png");
}

#endif
