/* Still image reading: PNG (the png module) and JPEG (libturbojpeg), chosen by the file's signature.
 * Library errors become a status naming the file; nothing is printed. */
#include "stillheart/imageio.h"

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "stillheart/png.h"
#ifdef SH_HAVE_TURBOJPEG
#include <turbojpeg.h>
#endif

/* Files larger than this are refused (a 16384x16384 RGB PNG is far smaller compressed). */
#define MAX_FILE_BYTES ((long)1 << 30)

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
        rewind(f);
        st = sh_png_read(f, path, gray, img);
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
