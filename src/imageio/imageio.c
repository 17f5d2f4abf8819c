/* Still image reading: PNG (libpng) and JPEG (libturbojpeg), chosen by the file's signature.
 * Library errors become a status naming the file; nothing is printed. */
#include "stillheart/imageio.h"

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#ifdef SH_HAVE_PNG
#include <png.h>
#endif
#ifdef SH_HAVE_TURBOJPEG
#include <turbojpeg.h>
#endif

/* Files larger than this are refused (a 16384x16384 RGB PNG is far smaller compressed). */
#define MAX_FILE_BYTES ((long)1 << 30)

static void rgb_row_to_gray(const uint8_t *s, uint8_t *d, int w)
{
    for (int x = 0; x < w; x++, s += 3)
        d[x] = (uint8_t)((77u * s[0] + 150u * s[1] + 29u * s[2] + 128u) >> 8);
}

#ifdef SH_HAVE_PNG
typedef struct {
    char message[200];
} png_ctx;

static void on_png_error(png_structp png, png_const_charp msg)
{
    png_ctx *ctx = png_get_error_ptr(png);
    snprintf(ctx->message, sizeof ctx->message, "%s", msg ? msg : "libpng error");
    png_longjmp(png, 1);
}

static void on_png_warning(png_structp png, png_const_charp msg)
{
    (void)png;
    (void)msg;
}

/* Everything setjmp's return must see is reached through `out` and `row` (not locals changed
 * after setjmp). */
static sh_status read_png(FILE *f, const char *path, sh_image *out, int gray, uint8_t **row)
{
    png_ctx ctx = {{0}};
    png_structp png = png_create_read_struct(PNG_LIBPNG_VER_STRING, &ctx, on_png_error,
                                             on_png_warning);
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
#endif

#ifdef SH_HAVE_TURBOJPEG
static sh_status read_jpeg(const unsigned char *data, unsigned long size, const char *path,
                           sh_image *out, int gray)
{
    tjhandle tj = tjInitDecompress();
    if (!tj) return sh_error_set(SH_ENOMEM, "%s: cannot create the JPEG decoder", path);
    int w = 0, h = 0, sub = 0, cs = 0;
    if (tjDecompressHeader3(tj, data, size, &w, &h, &sub, &cs) != 0) {
        sh_status st = sh_error_set(SH_EFORMAT, "%s: bad JPEG: %s", path, tjGetErrorStr2(tj));
        tjDestroy(tj);
        return st;
    }
    if (w <= 0 || h <= 0 || w > SH_IMAGE_MAX_SIZE || h > SH_IMAGE_MAX_SIZE) {
        tjDestroy(tj);
        return sh_error_set(SH_EFORMAT, "%s: JPEG size %dx%d not supported", path, w, h);
    }
    /* TJPF_GRAY on a YCbCr JPEG is its Y component, untouched by colour conversion. */
    int to_gray = gray || cs == TJCS_GRAY;
    sh_status st = sh_image_create(out, to_gray ? SH_PIX_GRAY8 : SH_PIX_RGB24, w, h);
    if (st != SH_OK) {
        tjDestroy(tj);
        return st;
    }
    if (tjDecompress2(tj, data, size, out->plane[0].data, w, out->plane[0].stride, h,
                      to_gray ? TJPF_GRAY : TJPF_RGB, TJFLAG_ACCURATEDCT) != 0 &&
        tjGetErrorCode(tj) == TJERR_FATAL) {
        st = sh_error_set(SH_EFORMAT, "%s: bad JPEG: %s", path, tjGetErrorStr2(tj));
        sh_image_destroy(out);
    }
    tjDestroy(tj);
    return st;
}
#endif

static sh_status read_any(const char *path, sh_image *img, int gray)
{
    if (!path || !img) return sh_error_set(SH_EINVAL, "imageio: missing argument");
    memset(img, 0, sizeof *img);
    FILE *f = fopen(path, "rb");
    if (!f) return sh_error_set(SH_EIO, "%s: %s", path, strerror(errno));
    unsigned char sig[8] = {0};
    size_t got = fread(sig, 1, sizeof sig, f);
    sh_status st;
    if (got == 8 && !memcmp(sig, "\x89PNG\r\n\x1a\n", 8)) {
#ifdef SH_HAVE_PNG
        rewind(f);
        uint8_t *row = NULL;
        st = read_png(f, path, img, gray, &row);
        free(row);
        if (st != SH_OK) sh_image_destroy(img);
#else
        st = sh_error_set(SH_EUNSUPPORTED, "%s: built without libpng", path);
#endif
    } else if (got >= 3 && sig[0] == 0xFF && sig[1] == 0xD8 && sig[2] == 0xFF) {
#ifdef SH_HAVE_TURBOJPEG
        long size = -1;
        if (fseek(f, 0, SEEK_END) == 0) size = ftell(f);
        if (size <= 0 || size > MAX_FILE_BYTES || fseek(f, 0, SEEK_SET) != 0) {
            st = sh_error_set(SH_EIO, "%s: cannot size the file", path);
        } else {
            unsigned char *data = malloc((size_t)size);
            if (!data) {
                st = sh_error_set(SH_ENOMEM, "%s: cannot allocate %ld bytes", path, size);
            } else if (fread(data, 1, (size_t)size, f) != (size_t)size) {
                st = sh_error_set(SH_EIO, "%s: short read", path);
            } else {
                st = read_jpeg(data, (unsigned long)size, path, img, gray);
            }
            free(data);
        }
#else
        st = sh_error_set(SH_EUNSUPPORTED, "%s: built without libturbojpeg", path);
#endif
    } else {
        st = sh_error_set(SH_EFORMAT, "%s: neither PNG nor JPEG", path);
    }
    fclose(f);
    return st;
}

sh_status sh_imageio_read(const char *path, sh_image *img)
{
    return read_any(path, img, 0);
}

sh_status sh_imageio_read_gray(const char *path, sh_image *img)
{
    return read_any(path, img, 1);
}
