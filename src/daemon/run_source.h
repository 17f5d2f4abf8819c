/* Private to the daemon (src/daemon): its cameras. One thread per camera
 * ([cameraN] in the config, opened through include/stillheart/source.h: V4L2, libcamera, Y4M
 * replay, recordings) converts each frame into its working format (pixconv.h: GRAY8 for a grey
 * camera, I420 otherwise) and groups it with the other cameras' into a set (sync.h: by trigger
 * edge with [trigger], else by timestamp). The newest set that holds the output camera's frame
 * waits for the processing thread in a one-set mailbox: when processing falls behind, the waiting
 * set is the oldest and is dropped and counted. With [source] queue_ms (default 100), sets wait
 * in order instead (up to 8) while captured at most that long ago, so that a short stall of the
 * machine shows its sets late rather than dropping them; older ones are dropped and counted, the
 * newest never; and while processing is slower than the camera (the median of the last sets'
 * processing times over the frame period) only the newest is taken, as with the mailbox. Replay
 * as fast as possible (every camera a y4m: or rec:, realtime off) drops nothing: the cameras wait
 * for processing instead.
 * A camera that vanishes is reopened by source.h with back-off while the others go on (its frames
 * are missing from the sets meanwhile: incomplete sets, counted). */
#ifndef STILLHEART_RUN_SOURCE_H
#define STILLHEART_RUN_SOURCE_H

#include <stddef.h>
#include <stdint.h>

#include "stillheart/config.h"
#include "stillheart/image.h"
#include "stillheart/source.h"
#include "stillheart/sync.h"
#include "stillheart/y4m.h"

typedef struct {
    sh_image img;         /* the output camera's frame (the one warped), in the header's format */
    int index;            /* its frame index: in the file for a replay (from 0 again after a loop),
                           * else the camera's sequence number */
    unsigned epoch;       /* the output camera's discontinuities so far (source.h: a replay that
                           * started again, its end not joining its start): motion history
                           * from an earlier epoch does not apply */
    int64_t avail_ns;     /* CLOCK_MONOTONIC time the set became available to processing */
    int64_t capture_ns;   /* the set's time: trigger edge + offset, or its first frame's timestamp */
    uint64_t set;         /* the set's index (sync.h) */
    int complete;         /* every camera's frame is in it */
    int cameras;
    const sh_image *cam[SH_CONFIG_MAX_CAMERAS]; /* each camera's frame, NULL when missing (3D) */
} run_frame;

typedef struct {
    sh_source_stats source; /* delivered, damaged, driver drops, losses, reopens, online */
    uint64_t converted;     /* frames converted into the working format */
    uint64_t bad;           /* frames pixconv refused (logged once) */
    uint64_t no_buffer;     /* frames dropped for want of a free buffer */
    uint64_t late, duplicates; /* refused by the set grouping */
    int ended;              /* end of a replay, or an error reopening cannot cure */
} run_camera_stats;

typedef struct run_source run_source;

/* Opens every configured camera (a missing device or file fails here, sh_error_message naming
 * it), the trigger line when [trigger] mode is not off, and allocates all buffers. */
sh_status run_source_open(const sh_config *cfg, run_source **out);
/* The output camera's frames: geometry, working format, rate (also what a Y4M record gets). */
const sh_y4m_header *run_source_header(const run_source *rs);
/* Frames per second of the output camera (0: unknown). */
double run_source_fps(const run_source *rs);
int run_source_cameras(const run_source *rs);
sh_status run_source_start(run_source *rs);
/* The next set (the newest, or with queue_ms the oldest still recent), waiting up to timeout_ms;
 * NULL on timeout or at the end. The set (and the frames it points to) stays valid until the next
 * call. */
const run_frame *run_source_take(run_source *rs, int timeout_ms);
/* 1 once the source has ended (replays without loop, or the output camera failed for good) and
 * its last set was taken. */
int run_source_ended(run_source *rs);
/* 1 when the output camera ended in an error (a replay's file damaged where good frames lie
 * behind the damage, a device that failed for good): the stop is not a clean end. */
int run_source_failed(run_source *rs);
/* Sets dropped because processing was behind (sets without the output camera's frame are
 * counted apart, in the exit log). */
uint64_t run_source_dropped(run_source *rs);
void run_source_camera_stats(run_source *rs, int camera, run_camera_stats *out);
void run_source_sync_stats(run_source *rs, sh_sync_stats *out);
/* Cameras delivering now, as text for STATUS ("2/2 cameras", "1/2 cameras (camera 1 lost)");
 * returns their number. */
int run_source_online(run_source *rs, char *text, size_t cap);
/* Whether the output camera gives nothing to show, the source otherwise running (not ended, no
 * set waiting): 1 when the camera is lost (source.h reopening it, or no frame from it for
 * [source] camera_timeout_ms; never as fast as possible, where cameras wait for processing),
 * 2 when it delivers but no set with its frame was formed for that long; 0 otherwise. text
 * says it for STATUS ("camera 0 lost, reopening"). */
int run_source_output_lost(run_source *rs, char *text, size_t cap);
/* 1 when every camera thread still running, and the trigger's, went round its loop within
 * max_age_ns (each does at least every 100 ms unless stuck in a driver or a file); else 0 and
 * who names the first that did not. The daemon's watchdog relies on it while nothing is shown. */
int run_source_alive(run_source *rs, int64_t max_age_ns, char *who, size_t cap);
/* Stops the threads (if started; then logs each camera's counters and the sets formed, INFO)
 * and frees everything. */
void run_source_destroy(run_source *rs);

/* ---- source_options.c (the public half is in daemon.h: sh_daemon_camera_options, ...) ---- */
/* 1 for a replay's spec (y4m: or rec:). */
int run_is_replay(const char *spec);
/* A rate's frame period, ns (unknown: PAL's, 25 fps). */
double run_period_ns(int fps_num, int fps_den);

#endif
