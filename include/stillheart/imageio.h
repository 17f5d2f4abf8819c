/* Reading still images: PNG through libpng (SH_HAVE_PNG), JPEG through libturbojpeg
 * (SH_HAVE_TURBOJPEG). The format comes from the file's signature, not its name. Built without
 * the library, the format's read returns SH_EUNSUPPORTED. */
#ifndef STILLHEART_IMAGEIO_H
#define STILLHEART_IMAGEIO_H

#include "stillheart/image.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Reads the file into img (created here; the caller destroys it): grey images (and grey with
 * alpha) as GRAY8, everything else as RGB24. Alpha is dropped, 16-bit samples keep their high
 * byte, palettes are expanded. */
sh_status sh_imageio_read(const char *path, sh_image *img);

/* Reads the file as GRAY8: a colour JPEG's own luma plane (Y of its YCbCr, as libapriltag's
 * test decoder takes it), a colour PNG converted with BT.601 luma
 * Y = (77 R + 150 G + 29 B + 128) >> 8. */
sh_status sh_imageio_read_gray(const char *path, sh_image *img);

#ifdef __cplusplus
}
#endif
#endif
