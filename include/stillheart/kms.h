/* A DRM/KMS output for the display on the box's own monitor (stillheart-show): one connector,
 * one mode, two XRGB8888 dumb buffers, page flips on vblank. No X, no Wayland: the process must
 * be (or become) the device's DRM master. Built with libdrm (SH_HAVE_DRM); without it
 * sh_kms_create refuses with SH_EUNSUPPORTED.
 *
 * The cycle: draw into sh_kms_back (the buffer not being scanned out), sh_kms_present, then
 * sh_kms_wait for the flip. The first present sets the mode (drmModeSetCrtc) on the back buffer;
 * every later one is a drmModePageFlip with DRM_MODE_PAGE_FLIP_EVENT, which the kernel applies at
 * the next vblank, so a buffer is never changed while it is scanned out and the picture never
 * tears. sh_kms_wait returns the event's timestamp (CLOCK_MONOTONIC: the vblank at which the new
 * buffer began to be scanned out) and makes the other buffer the back one. Nothing is queued:
 * one flip at a time.
 *
 * sh_kms_destroy puts back the CRTC configuration found at create (the console's), so the
 * monitor is not left on a buffer that no longer exists. */
#ifndef STILLHEART_KMS_H
#define STILLHEART_KMS_H

#include <stdint.h>

#include "stillheart/core.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct {
    const char *device;    /* "/dev/dri/card0" */
    const char *connector; /* "HDMI-A-1", "Virtual-1"; NULL: the first connected one */
    int width, height;     /* 0: the connector's preferred mode */
    double refresh;        /* Hz; 0: any refresh of that size (the preferred one first) */
} sh_kms_options;

/* "WxH" or "WxH@R" (R in Hz, may have decimals): SH_OK, or SH_EINVAL with a message. */
sh_status sh_kms_parse_mode(const char *text, int *width, int *height, double *refresh);

typedef struct sh_kms sh_kms;

/* Opens the device and sets up the output. Refusals, each with a message naming the thing:
 * SH_EIO no such device (or no permission); SH_EINVAL not a KMS device, no such connector (the
 * connectors are listed), the connector has no monitor, the mode not offered (the connector's
 * modes are listed); SH_EIO DRM master held by another process (named, as far as /proc shows
 * who has the device open); SH_EUNSUPPORTED built without libdrm. */
sh_status sh_kms_create(const sh_kms_options *options, sh_kms **out);
void sh_kms_destroy(sh_kms *kms);

typedef struct {
    char connector[32]; /* "Virtual-1" */
    int width, height;
    double refresh;     /* Hz, from the mode's pixel clock and totals */
    char driver[32];    /* the kernel driver ("bochs-drm", "vc4", ...) */
} sh_kms_info;
void sh_kms_get_info(const sh_kms *kms, sh_kms_info *info);

/* The back buffer: XRGB8888, 0x00RRGGBB per pixel. Valid until the next sh_kms_wait. */
void sh_kms_back(sh_kms *kms, uint32_t **pixels, int *stride);

/* Shows the back buffer: a mode set the first time, a page flip at the next vblank after that.
 * SH_EIO with the kernel's reason (the monitor unplugged, master lost). */
sh_status sh_kms_present(sh_kms *kms);

/* Waits up to timeout_ms (-1: forever) for the flip sh_kms_present asked for; *flip_ns its
 * vblank timestamp (CLOCK_MONOTONIC). SH_EIO on a timeout or an error; SH_OK at once with the
 * time of the mode set after the first present. */
sh_status sh_kms_wait(sh_kms *kms, int timeout_ms, int64_t *flip_ns);

#ifdef __cplusplus
}
#endif
#endif
