/* Frame sources: cameras (V4L2, libcamera), Y4M replay and recordings, behind one interface.
 *
 * A source is opened from a spec:
 *   v4l2:/dev/video0     a V4L2 capture device (memory-mapped streaming)
 *   y4m:FILE             a Y4M file replayed in real time (its frame rate) or as fast as possible
 *   rec:DIR              a stillheart recording (record.h), camera chosen by options.camera
 *   libcamera:NAME       a libcamera camera (id, part of one, or index; built with libcamera)
 * Frames are delivered raw (sh_raw: the pixel format the device gave) with the camera index,
 * a sequence number and a CLOCK_MONOTONIC capture timestamp (the driver's where it gives one).
 * Convert them with pixconv.h.
 *
 * The loop: sh_source_start, then poll sh_source_fd (POLLIN) with the other sources' fds, call
 * sh_source_dequeue, use the frame, sh_source_release it. A source owns a few buffers: a frame
 * must be released before more than (buffers - 1) are held. Nothing is allocated per frame.
 *
 * A camera that fails (ENODEV, EIO, no frame within options.timeout_ms) is torn down and reopened
 * with a growing back-off; meanwhile dequeue reports no frame (got = 0) and sh_source_fd is -1,
 * so the caller keeps serving the other cameras. Call sh_source_dequeue at least every
 * timeout_ms / 2 (poll with a timeout) so that a silent camera is noticed and retried. */
#ifndef STILLHEART_SOURCE_H
#define STILLHEART_SOURCE_H

#include <stdint.h>

#include "stillheart/pixconv.h"

#ifdef __cplusplus
extern "C" {
#endif

#define SH_SOURCE_CTRL_UNSET INT32_MIN

typedef struct {
    int camera;            /* index stamped on each frame (and the camera read from a rec:) */
    int width, height;     /* requested size; 0 = the device's current one */
    int format;            /* requested sh_rawfmt, -1 = the device's current one */
    int fps_num, fps_den;  /* requested rate (frames per second = num/den); 0 = leave */
    int buffers;           /* V4L2 buffers asked for (>= 2 accepted); 0 = 4 */
    int timeout_ms;        /* no frame for this long = camera lost; 0 = 1000 */
    int max_frame_pixels;  /* a stream of larger frames (width x height) is refused at open with
                            * SH_ERANGE, before any frame is allocated; 0 = SH_FRAME_PIXELS_DEFAULT */
    int backoff_min_ms, backoff_max_ms; /* reopen back-off; 0 = 100 and 5000 */
    /* Controls, set when not SH_SOURCE_CTRL_UNSET, the automatic one switched off first where
     * the camera has it; a control the camera does not list, or a value outside its range,
     * fails the open naming it. V4L2 / libcamera: */
    int32_t exposure;      /* V4L2_CID_EXPOSURE_ABSOLUTE (100 us units) / ExposureTime = 100 us x this */
    int32_t gain;          /* V4L2_CID_GAIN (driver units) / AnalogueGain = this / 100 (100: unity) */
    int32_t white_balance; /* V4L2_CID_WHITE_BALANCE_TEMPERATURE / ColourTemperature (K) */
    /* Replay (y4m:, rec:): */
    int realtime;          /* 1: frame k is due at start + k/fps; 0: as fast as asked */
    int loop;              /* 1: start again at the end (sequence and timestamps keep rising; the
                            * first frame of each new pass is flagged a discontinuity unless the
                            * Y4M file is tagged XLOOP=SEAMLESS, y4m.h). A file damaged where
                            * good frames lie behind the damage is not looped (sh_source_damage) */
} sh_source_options;

void sh_source_options_default(sh_source_options *opts);

typedef struct {
    int camera;
    uint64_t sequence;     /* per source, from 0, counting driver drops (gaps show them) */
    int64_t timestamp_ns;  /* CLOCK_MONOTONIC */
    int discontinuity;     /* 1: the scene does not follow on from the previous frame (a replay
                            * that started again), so motion history no longer applies */
    sh_raw raw;            /* borrowed until sh_source_release */
    int slot;              /* private: the buffer to give back */
} sh_source_frame;

typedef struct {
    uint64_t frames;       /* delivered */
    uint64_t errors;       /* skipped: buffers the driver flagged erroneous, bad frames */
    uint64_t drops;        /* gaps in the driver's sequence numbers */
    uint64_t reopens;      /* successful reopens after a loss */
    uint64_t losses;       /* times the device was lost (error or timeout) */
    uint64_t damaged;      /* replays: damaged places met in the file (each once, not again on
                            * every loop pass); sh_source_damage describes the last */
    uint64_t lost_bytes;   /* replays: bytes of the file those places cost */
    int online;            /* 1 while streaming */
} sh_source_stats;

typedef struct sh_source sh_source;

/* Opens (and for cameras configures) the source; a missing device or file fails here with a
 * message naming it. */
sh_status sh_source_open(const char *spec, const sh_source_options *opts, sh_source **out);
/* The negotiated format: valid after open. fps 0/0 when unknown. */
sh_status sh_source_format(const sh_source *src, sh_rawfmt *format, int *width, int *height, int *fps_num,
                           int *fps_den);
/* Bytes per row of plane 0 of the frames (the driver's bytesperline; 0 for MJPEG). */
int sh_source_stride(const sh_source *src);
sh_status sh_source_start(sh_source *src);
/* sh_source_start with the schedule of a replay (y4m:, rec:) starting at clock_ns
 * (CLOCK_MONOTONIC, sh_monotonic_ns): replays started one after another with the same clock_ns
 * stamp their frames alike (frame k of a y4m: at clock_ns + k/fps), so a rig of replays forms
 * frame sets however long the starts between them took. Cameras ignore it: their frames carry
 * the driver's times. sh_source_start is this with the time of the call. */
sh_status sh_source_start_at(sh_source *src, int64_t clock_ns);
/* A file descriptor that becomes readable when a frame may be ready; -1 while a camera is down. */
int sh_source_fd(const sh_source *src);
/* Waits up to timeout_ms (0: no wait, -1: until a frame or an error) for the next frame. *got is
 * 1 with a frame, 0 when none came in time or the camera is being reopened. SH_EEOF when a
 * replay without loop is over. Errors are returned only for what reopening cannot cure. */
sh_status sh_source_dequeue(sh_source *src, int timeout_ms, sh_source_frame *frame, int *got);
/* sh_source_dequeue with the pixels read straight into dst where the source can give them
 * without a conversion: a y4m: replay whose frames are dst's format and size, I420 or grey
 * (GRAY8). *direct is then 1, dst holds the frame with what sh_pixconv_convert would have made
 * of it (the chroma siting of a raw I420 frame: centre) and frame->raw has no data (NULL, 0
 * bytes); the frame is released as any other. Otherwise *direct is 0 and the frame is
 * sh_source_dequeue's (dst untouched), for the caller to convert. A 4K replay spares a 12 MB copy
 * a frame this way (docs/daemon.md, "At 4K"). */
sh_status sh_source_dequeue_into(sh_source *src, int timeout_ms, sh_image *dst, sh_source_frame *frame, int *got,
                                 int *direct);
sh_status sh_source_release(sh_source *src, sh_source_frame *frame);
sh_status sh_source_stop(sh_source *src);
void sh_source_close(sh_source *src);
void sh_source_get_stats(const sh_source *src, sh_source_stats *stats);
const char *sh_source_name(const sh_source *src);
/* Replays: the last damage met in the file, one line naming the file, where, and how much was
 * lost ("" when none). A replay goes on past damage only where nothing is lost beyond the
 * damaged part (a torn last frame, a damaged record skipped); the caller logs the line at
 * WARNING when stats.damaged changes. Damage that would make a replay drop or loop over part of
 * the file is instead an error from sh_source_dequeue, with the same line: a non-looping replay
 * of a damaged file ends in that error, never in SH_EEOF. */
const char *sh_source_damage(const sh_source *src);

#ifdef __cplusplus
}
#endif
#endif
