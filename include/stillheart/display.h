/* The shared-memory display buffer: the daemon publishes stabilized frames into a POSIX
 * shared-memory segment, and any number of readers (the display, stillheart-cat, recorders)
 * take the newest one.
 *
 * Layout (all fields fixed width, little endian as the host; see sh_display_header below):
 *   [ header, 256 bytes ][ slot 0: slot header 128 bytes, pixels ][ slot 1 ] ... [ slot N-1 ]
 * A slot header starts with the slot's 64-bit lock count, then 8 bytes of padding and the
 * frame's sh_display_frame_info; the pixels follow with the header's strides and offsets.
 * Each slot has a sequence lock: the writer makes its counter odd, writes, makes it even and
 * then announces the slot in header.latest. A reader copies a slot and keeps the copy only if
 * the counter was the same even value before and after; otherwise it tries the newest slot
 * again. With at least three slots the writer never waits for anyone, a reader never returns a
 * torn frame, and a reader that stalls or dies holds nothing. The memory ordering this relies
 * on (C11 acquire/release, and why it holds on aarch64) is written next to the code, display.c.
 *
 * A segment is never rebuilt in place: a writer created under a name already taken marks the old
 * segment replaced (magic 0) and unlinks it, then makes a new one. Readers still mapping the old
 * one keep whole frames from it and then get SH_EEOF; they open the name again to follow.
 *
 * The daemon (docs/daemon.md) publishes only frames it can vouch for, each with its status. While
 * its output camera is lost it publishes a black frame per frame period with status raw and the
 * reason "output camera lost" (capture_ns 0: no camera frame; markers_used 0, residual_px -1),
 * so that readers keep getting frames and a display can show its "camera lost" notice; the
 * camera's frames follow again by themselves when it returns. There is no header-only update. */
#ifndef STILLHEART_DISPLAY_H
#define STILLHEART_DISPLAY_H

#include <stdint.h>

#include "stillheart/image.h"

#ifdef __cplusplus
extern "C" {
#endif

#define SH_DISPLAY_MAGIC 0x594c505349444853ull /* "SHDISPLY" */
#define SH_DISPLAY_VERSION 1
#define SH_DISPLAY_DEFAULT_NAME "/stillheart"
#define SH_DISPLAY_MIN_SLOTS 3
#define SH_DISPLAY_MAX_SLOTS 16

typedef enum {
    SH_DISPLAY_RAW = 0,        /* the unwarped frame: tracking cannot be trusted (see reason) */
    SH_DISPLAY_STABILIZED = 1, /* warped onto the reference */
    SH_DISPLAY_DEGRADED = 2    /* stabilized through a short dropout (see reason) */
} sh_display_status;

/* Published with every frame. */
typedef struct {
    uint64_t sequence;         /* 1, 2, 3, ... per published frame */
    int64_t capture_ns;        /* CLOCK_MONOTONIC of the camera frame */
    int64_t publish_ns;        /* CLOCK_MONOTONIC when published */
    uint32_t status;           /* sh_display_status */
    uint32_t markers_used;
    float residual_px;         /* tracking residual behind the map (NaN when unknown) */
    char reason[44];           /* why raw / degraded, "" when stabilized; NUL terminated */
} sh_display_frame_info;

/* The segment's header, as it lies in shared memory. */
typedef struct {
    uint64_t magic;            /* SH_DISPLAY_MAGIC */
    uint32_t version;          /* SH_DISPLAY_VERSION */
    uint32_t header_size;      /* sizeof(sh_display_header) */
    uint32_t width, height;
    uint32_t format;           /* sh_pixfmt */
    uint32_t siting;           /* sh_chroma_siting */
    uint32_t num_planes;
    uint32_t stride[3];        /* bytes per row of each plane in a slot */
    uint32_t plane_offset[3];  /* from the start of a slot's pixels */
    uint32_t frame_bytes;      /* pixels of one slot */
    uint32_t slot_count;
    uint32_t slot_bytes;       /* slot header + pixels, a multiple of 64 */
    uint32_t closed;           /* 1 once the writer has shut down cleanly */
    uint32_t full_range;       /* YUV range of the frames */
    uint64_t latest;           /* (sequence << 8) | slot of the newest frame; 0: none yet */
    int64_t writer_pid;
    uint8_t reserved[256 - 96];
} sh_display_header;

typedef struct sh_display_writer sh_display_writer;

/* Creates (or takes over) the segment `name` ("/stillheart"), mode 0660, group `group` when
 * given and permitted (the service's group, "video"); sized for frames like `format`. */
sh_status sh_display_writer_create(const char *name, sh_pixfmt format, int width, int height,
                                   int slots, int full_range, const char *group,
                                   sh_display_writer **out);
/* Copies the frame into the next slot and announces it. Never blocks on readers. info->sequence
 * and publish_ns are filled in by the writer. One thread at a time per writer. */
sh_status sh_display_writer_publish(sh_display_writer *w, const sh_image *frame,
                                    const sh_display_frame_info *info);
/* Marks the segment closed and unmaps it; unlink removes the name as well. */
void sh_display_writer_destroy(sh_display_writer *w, int unlink_segment);

typedef struct sh_display_reader sh_display_reader;

/* SH_EIO when no segment has the name; SH_EFORMAT when it is not a valid segment, which is also
 * what a segment still being created looks like for a moment (a reader that starts beside the
 * daemon tries again). */
sh_status sh_display_reader_open(const char *name, sh_display_reader **out);
/* Reads from a buffer already in memory (the fuzz harness, tests): validates the header
 * against size like a segment. The buffer must outlive the reader. */
sh_status sh_display_reader_attach(const void *buffer, size_t size, sh_display_reader **out);
const sh_display_header *sh_display_reader_header(const sh_display_reader *r);
/* Waits up to timeout_ms (-1: forever) for a frame newer than the last one this reader
 * returned, and copies it into frame (created by the caller with the header's format and
 * size). SH_EEOF when the writer closed the segment or another writer replaced it; SH_EIO on
 * timeout. frame and info are written only with SH_OK, and then hold one whole published frame;
 * on any other status they hold what they held before the call (a display may keep showing it). */
sh_status sh_display_reader_next(sh_display_reader *r, sh_image *frame,
                                 sh_display_frame_info *info, int timeout_ms);
void sh_display_reader_close(sh_display_reader *r);

#ifdef __cplusplus
}
#endif
#endif
