/* The shared-memory display buffer: the daemon publishes stabilized frames into a POSIX
 * shared-memory segment, and any number of readers (the display, stillheart-cat, recorders)
 * take the newest one.
 *
 * Layout (all fields fixed width, little endian as the host; see sh_display_header below):
 *   [ header, 256 bytes ][ slot 0: slot header 128 bytes, pixels ][ slot 1 ] ... [ slot N-1 ]
 * A slot header (SH_DISPLAY_SLOT_HEADER_BYTES = 128) starts with the slot's 64-bit lock count,
 * then 8 bytes of padding and the frame's sh_display_frame_info (80 bytes), then 32 reserved
 * bytes; the pixels follow with the header's strides and offsets.
 * Each slot has a sequence lock: the writer makes its counter odd, writes, makes it even and
 * then announces the slot in header.latest. A reader copies a slot and keeps the copy only if
 * the counter was the same even value before and after; otherwise it tries the newest slot
 * again. With at least three slots the writer never waits for anyone, a reader never returns a
 * torn frame, and a reader that stalls or dies holds nothing. The memory ordering this relies
 * on (C11 acquire/release, and why it holds on aarch64) is written next to the code
 * (src/display/writer.c, reader.c).
 *
 * Who may do what (docs/daemon.md, "The display segment"): the writer creates the segment
 * exclusively, mode 0640, in the group it is given: only its own uid (and root) can write or
 * truncate it, the group can read it. A segment already under the name is replaced when it
 * belongs to the writer's uid and no live writer holds it (an flock on the object), refused with
 * its owner named when it belongs to another uid. The writer never reads the segment back: its
 * layout lives in private memory; before each publish it checks its own object (one fstat: size,
 * owner, mode, group, still linked under its name) and copies under a SIGBUS guard, so a segment
 * shrunk, re-moded, unlinked or replaced under it is retired (magic 0) and made anew with a new
 * generation, never a crash.
 *
 * Generations and restarts: every segment carries a random 64-bit generation, new with every
 * object (a daemon start, or a segment made anew). A segment is never rebuilt in place: a new
 * writer marks the old one retired (magic 0) and unlinks it, then makes a new object. A reader
 * opened by name (sh_display_reader_open) follows: when its segment is retired, cut short,
 * unlinked or replaced under the name (and, with follow, closed), it opens the name again,
 * waiting for the next daemon within the caller's timeout, and returns frames of the new object
 * only, from its start; it never goes back to an object it left, so no frame of an older
 * generation follows one of a newer. Readers check the owner of what they open.
 *
 * SIGBUS: sh_display_writer_create, sh_display_reader_open and _attach install a process-wide
 * SIGBUS handler (sigaction, SA_SIGINFO | SA_ONSTACK) when it is not in place. It acts only on a
 * fault in a mapping this library is copying into or out of (or a viewer reads, see
 * sh_display_reader_view) on the faulting thread (a segment truncated under it: that copy is
 * abandoned with an error); every other SIGBUS goes to the handler that was installed before
 * it, or to the default action. An application that installs its own SIGBUS handler afterwards
 * must chain to the one it replaces (sigaction's old action); one that does not leaves the
 * readers and writers it has open unguarded, and the next create, open or attach puts the
 * handler back, chaining to the application's.
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
#define SH_DISPLAY_SLOT_HEADER_BYTES 128

typedef enum {
    SH_DISPLAY_RAW = 0,        /* the unwarped frame: tracking cannot be trusted (see reason) */
    SH_DISPLAY_STABILIZED = 1, /* warped onto the reference */
    SH_DISPLAY_DEGRADED = 2    /* stabilized through a short dropout (see reason) */
} sh_display_status;

/* Published with every frame. */
typedef struct {
    uint64_t sequence;         /* 1, 2, 3, ... per published frame */
    int64_t capture_ns;        /* CLOCK_MONOTONIC of the camera frame */
    int64_t publish_ns;        /* CLOCK_MONOTONIC when published: the frame whole in its slot */
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
    uint64_t generation;       /* random, new with every object (0: a writer before generations) */
    uint8_t reserved[256 - 104];
} sh_display_header;

typedef struct sh_display_writer sh_display_writer;

/* Creates the segment `name` ("/stillheart"), mode 0640, group `group` when given (the display
 * group, "video"; NULL or "": the process's group; SH_EINVAL when no such group exists), sized
 * for frames like `format`. A segment already under the name is replaced when it is this uid's
 * and no running writer holds it; SH_EINVAL naming its owner when it is another uid's, SH_EIO
 * when a running writer holds it. */
sh_status sh_display_writer_create(const char *name, sh_pixfmt format, int width, int height,
                                   int slots, int full_range, const char *group,
                                   sh_display_writer **out);
/* Copies the frame into the next slot and announces it. Never blocks on readers; reads nothing
 * back from the segment. info->sequence and publish_ns are filled in by the writer. A segment
 * found shrunk, re-moded, unlinked or replaced (or cut short during the copy) is made anew under
 * the name with a new generation, and the frame goes there; an error only when that cannot be
 * done (the name taken by another uid meanwhile: tried again at the next publish). One thread at
 * a time per writer. */
sh_status sh_display_writer_publish(sh_display_writer *w, const sh_image *frame,
                                    const sh_display_frame_info *info);
/* How many times publish made the segment anew, and the current segment's generation. */
uint64_t sh_display_writer_remade(const sh_display_writer *w);
uint64_t sh_display_writer_generation(const sh_display_writer *w);
/* Marks the segment closed and unmaps it; unlink removes the name as well (when it is still
 * this writer's). */
void sh_display_writer_destroy(sh_display_writer *w, int unlink_segment);

typedef struct sh_display_reader sh_display_reader;

#define SH_DISPLAY_OWNER_SELF (-1)
typedef struct {
    /* The uid the segment must belong to; SH_DISPLAY_OWNER_SELF (the default, also with NULL
     * options): the reader's effective uid. A segment of another uid, or one writable by its
     * group or others, is refused (SH_EINVAL, naming its owner): its frames could come from
     * anyone. A display running as another user than the service gives the service's uid. */
    int64_t owner_uid;
    /* 0: a segment the writer closed (the daemon stopped) ends the stream (SH_EEOF). 1: the
     * reader waits for the next daemon under the name as it does after a crash. */
    int follow;
} sh_display_reader_options;

/* Opens the segment `name`, waiting up to timeout_ms (-1: forever, 0: one try) for it to appear
 * and become valid (a reader started before the daemon). SH_EINVAL at once when it belongs to
 * another owner than the options say; otherwise, at the timeout, SH_EIO when no segment has the
 * name, SH_EFORMAT when what is there is not a valid segment. */
sh_status sh_display_reader_open(const char *name, const sh_display_reader_options *options,
                                 int timeout_ms, sh_display_reader **out);
/* Reads from a buffer already in memory (the fuzz harness, tests): validates the header
 * against size like a segment; follows nothing. The buffer must outlive the reader. */
sh_status sh_display_reader_attach(const void *buffer, size_t size, sh_display_reader **out);
/* The validated copy of the current segment's header (format, size, generation). After
 * sh_display_reader_next returned SH_ERANGE it describes the new segment. */
const sh_display_header *sh_display_reader_header(const sh_display_reader *r);
/* Waits up to timeout_ms (-1: forever) for a frame newer than the last one this reader
 * returned, and copies it into frame (created by the caller with the header's format and
 * size). A reader opened by name follows restarts meanwhile (above): a segment retired, cut
 * short, unlinked or replaced is left and the name opened again (a new daemon's next frame
 * comes within a poll of 0.5 ms once it is published); with follow, a closed one too.
 * Statuses: SH_OK a frame; SH_EIO no new frame within the timeout; SH_EEOF the writer closed the
 * segment (without follow; an attached buffer also when it was retired); SH_ERANGE the segment
 * now carries frames of another format or size than `frame` (a daemon restarted at another
 * size): make the frame anew from sh_display_reader_header and call again; SH_EINVAL the name
 * now belongs to another owner. The writer wakes waiting readers after each publish (a futex on
 * the header's `latest`), so a frame is taken within tens of microseconds of its publish. frame and info are written only with SH_OK, and then hold one
 * whole published frame; on any other status they hold what they held before the call (a
 * display may keep showing it). */
sh_status sh_display_reader_next(sh_display_reader *r, sh_image *frame,
                                 sh_display_frame_info *info, int timeout_ms);

/* What sh_display_reader_view does with a frame in place: `view` holds the frame's pixels where
 * they lie in the segment (read only; the strides are the header's), `info` its info. */
typedef sh_status (*sh_display_view_fn)(void *ctx, const sh_image *view, const sh_display_frame_info *info);
/* As sh_display_reader_next, without copying the frame: the newest frame is handed to fn where
 * it lies, and what fn did with it stands only when the writer stayed out of the slot meanwhile.
 * Then the call returns SH_OK (or fn's own error, the frame not taken) with *info the frame's.
 * If the writer came into the slot while fn ran (it laps a reader after slot_count - 1 newer
 * frames), fn is called again on the newest frame; on any return but SH_OK, what fn did is not a
 * frame. So fn must be work that may be done again, whose last run is what counts (drawing or
 * converting into a buffer), and:
 *  - it reads the view on the calling thread only, and only until it returns: the view lies
 *    under this thread's SIGBUS guard. A segment cut short while fn runs abandons fn where it is
 *    (a jump back into the reader: fn does not return) and the reader goes on as
 *    sh_display_reader_next does, so fn takes no lock and allocates nothing it frees later;
 *  - it calls no sh_display_* function but sh_display_reader_header, which describes the
 *    segment the view lies in (a daemon restarted meanwhile: the new one's).
 * There is no SH_ERANGE: the view has the segment's size and format (sh_display_reader_header
 * too). It saves both copies sh_display_reader_next makes (into the reader's stage, then into the
 * caller's frame: at 1080p I420 about 0.2 ms each). */
sh_status sh_display_reader_view(sh_display_reader *r, sh_display_view_fn fn, void *ctx,
                                 sh_display_frame_info *info, int timeout_ms);
void sh_display_reader_close(sh_display_reader *r);

#ifdef __cplusplus
}
#endif
#endif
