/* PNG files through libpng (built when libpng is found; otherwise SH_EUNSUPPORTED). */
#ifndef STILLHEART_PNG_H
#define STILLHEART_PNG_H

#include <stdio.h>

#include "stillheart/image.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Writes GRAY8 as 8-bit grey, RGB24 as RGB, I420 / YUV444 converted to RGB (BT.601, range
 * given by full_range). */
sh_status sh_png_write(const char *path, const sh_image *img, int full_range);

/* Reads a PNG from f (at its signature) into img (created here; the caller destroys it; zeroed
 * on error): grey and grey with alpha as GRAY8, the rest as RGB24, or everything as GRAY8 with
 * gray (colour with BT.601 luma, Y = (77 R + 150 G + 29 B + 128) >> 8). path names the file in
 * messages. Callers read files through sh_imageio_read, which also takes JPEG. */
sh_status sh_png_read(FILE *f, const char *path, int gray, sh_image *img);

#ifdef __cplusplus
}
#endif
#endif
