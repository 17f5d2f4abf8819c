/* Recordings: what the cameras delivered (raw frames as delivered, their timestamps and
 * sequence numbers, the frame sets), for replay (source spec rec:DIR) and conversion to Y4M.
 *
 * A recording is a folder holding one append-only file, recording.shrec (docs/capture.md):
 *   file header (16 bytes): "SHREC\r\n\x1a" magic, u32 version (2), u32 header size (16)
 *   records, each: u32 magic "SHRR", u32 type, u32 payload length, u32 CRC-32 of the type, the
 *   length and the payload (version 1: of the payload only), then the payload. Little endian.
 *   type 1 STREAM: u32 camera, format (sh_rawfmt), width, height, stride, fps_num, fps_den,
 *                  char source[64] (NUL padded)
 *   type 2 FRAME:  u32 camera, u32 flags (0), u64 sequence, i64 timestamp_ns, then the bytes
 *   type 3 SET:    u64 index, i64 time_ns, u32 flags (1 triggered, 2 complete), u32 present,
 *                  u64 sequence[SH_SYNC_MAX_CAMERAS] (0 where absent)
 * Each record goes out in one write(2), so a killed process or a full disk loses at most the
 * record being written. The reader reads versions 1 and 2 and refuses a later one by its number.
 * Past damage (a wrong magic, length or CRC) it resyncs on the next record whose CRC holds,
 * counting the records (the damaged one and every record magic in the bytes skipped) and the
 * bytes it skipped; a record cut by the end of the file with nothing good after it is a torn
 * tail (a writer stopped mid-record), reported apart. Records whose CRC holds but whose content
 * cannot be used (a frame of a camera without its stream) are skipped and counted too. */
#ifndef STILLHEART_RECORD_H
#define STILLHEART_RECORD_H

#include <stdint.h>
#include <stdio.h>

#include "stillheart/pixconv.h"
#include "stillheart/sync.h"

#ifdef __cplusplus
extern "C" {
#endif

#define SH_REC_FILE "recording.shrec"
#define SH_REC_MAX_STREAMS SH_SYNC_MAX_CAMERAS

typedef struct {
    int camera;
    sh_rawfmt format;
    int width, height, stride;
    int fps_num, fps_den;
    char source[64];
} sh_rec_stream;

typedef enum { SH_REC_STREAM = 1, SH_REC_FRAME = 2, SH_REC_SET = 3 } sh_rec_type;

typedef struct {
    sh_rec_type type;
    /* FRAME */
    int camera;
    uint64_t sequence;
    int64_t timestamp_ns;
    sh_raw raw;               /* data borrowed from the reader until its next call */
    /* SET */
    sh_frame_set set;         /* members' user pointers are NULL */
    /* STREAM */
    sh_rec_stream stream;
} sh_rec_record;

typedef struct sh_rec_writer sh_rec_writer;

/* Creates the folder (if missing) and its recording file; an existing recording is refused. */
sh_status sh_rec_writer_create(const char *dir, sh_rec_writer **out);
/* Makes what is written durable every sync_ms (fdatasync, by a thread of the writer's own, so
 * the caller never waits for the disk): power loss then loses at most about sync_ms of records
 * (a kill loses at most the record being written, whatever the interval). 0: a sync after every
 * record. Without it the file is synced only at close. Once, before the first record. */
sh_status sh_rec_writer_set_sync(sh_rec_writer *w, int sync_ms);
/* Describes a camera; before its first frame. */
sh_status sh_rec_writer_stream(sh_rec_writer *w, const sh_rec_stream *stream);
sh_status sh_rec_writer_frame(sh_rec_writer *w, int camera, uint64_t sequence, int64_t timestamp_ns,
                              const sh_raw *raw);
sh_status sh_rec_writer_set(sh_rec_writer *w, const sh_frame_set *set);
/* Closes; reports an earlier failed write (disk full) as SH_EIO. */
sh_status sh_rec_writer_close(sh_rec_writer *w);

typedef struct sh_rec_reader sh_rec_reader;

/* path: the recording folder or the file itself. Reads the file header and the stream records
 * at its start (a recording whose header is damaged is refused naming the file). */
sh_status sh_rec_reader_open(const char *path, sh_rec_reader **out);
/* Reads from a stream the caller opened and closes after the reader (fuzzing); it must seek
 * (resync does), so a pipe is refused. */
sh_status sh_rec_reader_open_file(FILE *file, const char *name, sh_rec_reader **out);
int sh_rec_reader_streams(const sh_rec_reader *r, const sh_rec_stream **streams);
/* The stream of a camera, or NULL. */
const sh_rec_stream *sh_rec_reader_stream(const sh_rec_reader *r, int camera);
/* The next record (STREAM records after the first frame are returned too). SH_EEOF at the end
 * of the file or at a torn tail (sh_rec_reader_truncated tells which). */
sh_status sh_rec_reader_next(sh_rec_reader *r, sh_rec_record *rec);
int sh_rec_reader_truncated(const sh_rec_reader *r);    /* the file ends in a torn record */
uint64_t sh_rec_reader_skipped(const sh_rec_reader *r); /* damaged records, or bad content */
/* Every byte not read as a good record so far: damage skipped, bad content, a torn tail. */
uint64_t sh_rec_reader_lost_bytes(const sh_rec_reader *r);
int sh_rec_reader_version(const sh_rec_reader *r);
void sh_rec_reader_close(sh_rec_reader *r);

/* CRC-32 (IEEE 802.3, as zlib's crc32) of n bytes, continuing from crc (0 to start). */
uint32_t sh_crc32(uint32_t crc, const void *data, size_t n);

#ifdef __cplusplus
}
#endif
#endif
