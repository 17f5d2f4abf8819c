/* Frames: planar or interleaved 8-bit images with explicit stride.
 *
 * An sh_image either owns its pixel memory (sh_image_create / sh_image_destroy) or borrows it
 * (sh_image_wrap: the caller keeps ownership and must outlive the image). */
#ifndef STILLHEART_IMAGE_H
#define STILLHEART_IMAGE_H

#include <stdint.h>

#include "stillheart/core.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef enum {
    SH_PIX_GRAY8 = 0, /* one plane */
    SH_PIX_RGB24,     /* one plane, R G B interleaved */
    SH_PIX_I420,      /* Y, then U and V at half width and height (rounded up) */
    SH_PIX_YUV444     /* Y, U, V planes at full resolution */
} sh_pixfmt;

/* Where 4:2:0 chroma samples sit relative to luma, as Y4M's C420* tags name it. */
typedef enum {
    SH_CHROMA_CENTER = 0, /* 420jpeg: between the four luma samples */
    SH_CHROMA_LEFT,       /* 420mpeg2: horizontally with the left luma, vertically between */
    SH_CHROMA_PALDV       /* 420paldv: Cr with the top-left luma, Cb with the bottom-left */
} sh_chroma_siting;

#define SH_IMAGE_MAX_PLANES 3
/* Largest width or height: the warp's 16.16 fixed-point positions cover +-16384 px. */
#define SH_IMAGE_MAX_SIZE 16384
/* The most pixels (width x height) one stream's frame may have unless a caller sets its own
 * bound (the daemon's [source] max_frame_pixels): the largest camera stillheart supports, a 4K
 * UHD endoscope tower's 3840x2160 (issue 20). SH_IMAGE_MAX_SIZE alone would let a header ask
 * for 16384x16384, 768 MiB a 4:4:4 frame. */
#define SH_FRAME_PIXELS_DEFAULT (3840 * 2160)

typedef struct {
    uint8_t *data;
    int width;      /* samples per row (pixels, not bytes) */
    int height;
    int stride;     /* bytes from one row to the next */
} sh_plane;

typedef struct {
    sh_pixfmt format;
    sh_chroma_siting siting;
    int width, height; /* of the full-resolution (luma / RGB) plane */
    int num_planes;
    sh_plane plane[SH_IMAGE_MAX_PLANES];
    void *owned;       /* allocation freed by sh_image_destroy; NULL when wrapping */
} sh_image;

/* Bytes per sample in plane 0 (3 for RGB24, 1 otherwise). */
int sh_pixfmt_channels(sh_pixfmt format);
const char *sh_pixfmt_name(sh_pixfmt format);

/* Bytes one frame of this format occupies when its planes are packed without padding. */
size_t sh_image_packed_size(sh_pixfmt format, int width, int height);

/* SH_OK when width x height is at most max_pixels; else SH_ERANGE with a message naming `name`,
 * the size and the bound. Called where a stream's size becomes known, before its frames are
 * allocated. */
sh_status sh_image_check_pixels(const char *name, int width, int height, long long max_pixels);

/* Allocates an image (rows 32-byte aligned, contents zeroed). */
sh_status sh_image_create(sh_image *img, sh_pixfmt format, int width, int height);

/* Describes caller-owned memory holding packed planes (as in a Y4M frame). */
sh_status sh_image_wrap(sh_image *img, sh_pixfmt format, int width, int height, uint8_t *packed);

void sh_image_destroy(sh_image *img);

/* A view of the width x height window of img at (x, y): the same memory and strides, nothing
 * allocated (view->owned is NULL: sh_image_destroy leaves img's pixels alone). I420 windows
 * start at even offsets. SH_EINVAL when the window does not lie inside img. */
sh_status sh_image_window(const sh_image *img, int x, int y, int width, int height, sh_image *view);

/* Copies pixels between two images of the same format and size (strides may differ). */
sh_status sh_image_copy(sh_image *dst, const sh_image *src);

/* Converts any format to RGB24 (dst created by the caller at the same size). YUV uses BT.601
 * coefficients, full range (0..255) when full_range, else limited (16..235 / 16..240); chroma
 * is upsampled bilinearly honouring the siting. GRAY8 replicates the grey. */
sh_status sh_image_to_rgb(const sh_image *src, sh_image *dst, int full_range);

/* Sets every pixel to black (Y=16 for limited-range YUV is not assumed: Y=0, U=V=128). */
void sh_image_clear(sh_image *img);

#ifdef __cplusplus
}
#endif
#endif
