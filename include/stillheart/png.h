/* PNG output through libpng (built when libpng is found; otherwise SH_EUNSUPPORTED). */
#ifndef STILLHEART_PNG_H
#define STILLHEART_PNG_H

#include "stillheart/image.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Writes GRAY8 as 8-bit grey, RGB24 as RGB, I420 / YUV444 converted to RGB (BT.601, range
 * given by full_range). */
sh_status sh_png_write(const char *path, const sh_image *img, int full_range);

#ifdef __cplusplus
}
#endif
#endif
