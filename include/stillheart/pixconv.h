/* Camera pixel formats ("raw" frames as a driver delivers them) to the pipeline's working
 * formats: GRAY8 (luma, for detection), I420 (the Y4M / warp format) and RGB24.
 *
 * Conventions (the ones OpenCV's cvtColor and V4L2's defaults use):
 * - YUYV, NV12, I420, YUV444 are BT.601 limited range (Y 16..235, U/V 16..240). To RGB24 each
 *   pixel takes the chroma sample of its own 2x1 (YUYV) or 2x2 (NV12) block (no interpolation),
 *   as cvtColor's COLOR_YUV2RGB_YUYV / _NV12 do.
 * - RGB24 / BGR24 to GRAY8 and I420 give limited-range BT.601 luma (the Y plane cvtColor's
 *   COLOR_RGB2YUV_I420 gives), chroma from the mean of each 2x2 block. GRAY8 is always the Y
 *   plane the I420 conversion would give, so detection sees the same numbers either way.
 * - YUYV to I420: chroma of two rows averaged (rounding half up); siting SH_CHROMA_LEFT (the
 *   MPEG-2 convention of 4:2:2 and NV12 sources). NV12 to I420 only de-interleaves. I420 input
 *   (from Y4M replay) is copied and taken as SH_CHROMA_CENTER, Y4M's default.
 * - MJPEG (JFIF) is full range: decoded by libturbojpeg, its samples are kept as they are
 *   (GRAY8/I420 full range, siting SH_CHROMA_CENTER); RGB24 is libturbojpeg's own conversion.
 *   4:2:2 and 4:4:4 JPEGs are decoded to their native planes and averaged down to 4:2:0.
 * - GREY to I420 sets U = V = 128; to RGB24 replicates the grey.
 * Odd widths or heights are refused for the 4:2:x inputs (YUYV, NV12, I420): the drivers never
 * deliver them. The conversions allocate nothing (libjpeg's own decoder state aside). */
#ifndef STILLHEART_PIXCONV_H
#define STILLHEART_PIXCONV_H

#include <stddef.h>
#include <stdint.h>

#include "stillheart/image.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef enum {
    SH_RAW_GREY = 0, /* 8-bit luma */
    SH_RAW_YUYV,     /* 4:2:2 packed Y0 U Y1 V */
    SH_RAW_NV12,     /* Y plane, then interleaved U V at half width and height */
    SH_RAW_RGB24,
    SH_RAW_BGR24,
    SH_RAW_MJPEG,    /* one JPEG per frame, variable size */
    SH_RAW_I420,     /* planar 4:2:0, as Y4M stores it */
    SH_RAW_YUV444,   /* planar 4:4:4 */
    SH_RAW_COUNT
} sh_rawfmt;

/* One frame as delivered: stride is the bytes from one row of plane 0 to the next (the driver's
 * bytesperline); later planes follow plane 0 at stride * height with the same stride for NV12
 * (V4L2's single-planar NV12), stride / 2 for I420. Unused for MJPEG, whose size is bytes. */
typedef struct {
    sh_rawfmt format;
    int width, height;
    int stride;
    const uint8_t *data;
    size_t bytes;
} sh_raw;

const char *sh_rawfmt_name(sh_rawfmt format);      /* "YUYV", "NV12", ... */
/* Accepts the names above in any case ("grey"/"gray8", "rgb", "bgr", "mjpg"/"jpeg" too). */
sh_status sh_rawfmt_parse(const char *name, sh_rawfmt *out);
/* The V4L2 fourcc of a format and back (SH_EUNSUPPORTED for other fourccs). */
uint32_t sh_rawfmt_fourcc(sh_rawfmt format);
sh_status sh_rawfmt_from_fourcc(uint32_t fourcc, sh_rawfmt *out);
/* Smallest stride and frame size of a tightly packed frame (0 for MJPEG or bad geometry). */
int sh_rawfmt_min_stride(sh_rawfmt format, int width);
size_t sh_raw_frame_size(sh_rawfmt format, int width, int height, int stride);
/* Checks geometry, stride and size of a frame; SH_EFORMAT with the reason. */
sh_status sh_raw_check(const sh_raw *src);

typedef struct sh_pixconv sh_pixconv;

/* State for MJPEG (a decoder and a scratch buffer for frames up to max_width x max_height).
 * The other formats need none: pass NULL to sh_pixconv_convert. */
sh_status sh_pixconv_create(int max_width, int max_height, sh_pixconv **out);
void sh_pixconv_destroy(sh_pixconv *conv);

/* Converts src into dst (created by the caller: GRAY8, I420 or RGB24, src's size). For I420 the
 * siting of dst is set as described above. */
sh_status sh_pixconv_convert(sh_pixconv *conv, const sh_raw *src, sh_image *dst);

#ifdef __cplusplus
}
#endif
#endif
