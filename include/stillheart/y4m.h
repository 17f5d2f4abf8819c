/* YUV4MPEG2 (Y4M) streams: the reader and writer of every stillheart video.
 *
 * Supported colour spaces: Cmono (GRAY8), C420jpeg / C420 / C420mpeg2 / C420paldv (I420 with the
 * siting recorded in the image), C444 (YUV444). Frame-rate (F), aspect (A), interlacing (I) tags
 * are parsed; X tags (XCOLORRANGE=FULL, ...) and unknown tags are kept verbatim and written back
 * by a writer created from the reader's header. */
#ifndef STILLHEART_Y4M_H
#define STILLHEART_Y4M_H

#include <stdio.h>

#include "stillheart/image.h"

#ifdef __cplusplus
extern "C" {
#endif

#define SH_Y4M_MAX_EXTRA 1024

/* Our X tag for a stream whose last frame is followed by its first without a jump in the scene
 * (a periodic phantom, stillheart-render --periodic): a looping replay (source.h) goes on across
 * the loop instead of flagging a discontinuity. */
#define SH_Y4M_LOOP_SEAMLESS "XLOOP=SEAMLESS"
/* The X tag of full-range samples (0..255, as JPEG and our renderers make them); without it a
 * stream is limited range (16..235), as Y4M has it. */
#define SH_Y4M_FULL_RANGE "XCOLORRANGE=FULL"

/* Our X tag saying which stillheart model stabilized a video, so that stillheart-eval measures
 * the map that made it: XSTILLHEART=method:NAME (`stillheart warp`, `run`: the 2D interpolant,
 * spelled as --method and [method] name take it, e.g. tps or gaussian-pure) or
 * XSTILLHEART=method3d:NAME (`warp3d`, `run` with a calibration: the interpolant of the surface,
 * then "/" and the displacement's when they differ). The method's sigma, levels and smoothing
 * are not in it. */
#define SH_Y4M_STILLHEART "XSTILLHEART"

typedef struct {
    int width, height;
    sh_pixfmt format;          /* GRAY8, I420 or YUV444 */
    sh_chroma_siting siting;   /* for I420 */
    int fps_num, fps_den;      /* 0/0 when the stream gave none */
    int aspect_num, aspect_den;/* 0:0 = unknown */
    char interlace;            /* 'p', 't', 'b', 'm' or 0 when absent */
    char extra[SH_Y4M_MAX_EXTRA]; /* X tags and unknown tags, space separated, verbatim */
} sh_y4m_header;

/* 1 when the header's X tags hold `tag` (e.g. SH_Y4M_LOOP_SEAMLESS) as a whole word. */
int sh_y4m_header_has_tag(const sh_y4m_header *header, const char *tag);
/* 1 when the header says its samples are full range (SH_Y4M_FULL_RANGE). */
int sh_y4m_header_full_range(const sh_y4m_header *header);

/* Sets the X tag KEY=VALUE (key e.g. SH_Y4M_STILLHEART), after removing every tag KEY or
 * KEY=... the header had: a header copied from an input keeps one, the new one. SH_EINVAL for
 * an empty key or value or one with a space or a control character, SH_ERANGE when the tags
 * would no longer fit. */
sh_status sh_y4m_header_set_tag(sh_y4m_header *header, const char *key, const char *value);
/* 1 and the value of the first tag KEY=VALUE in out (NUL-terminated; cap bytes, longer values
 * truncated), or 0 when the header has none. */
int sh_y4m_header_tag(const sh_y4m_header *header, const char *key, char *out, size_t cap);

typedef struct sh_y4m_reader sh_y4m_reader;

/* path "-" reads stdin. A bad header fails here with a message naming the file, and so does,
 * for a regular file, a header whose frame size is more than the file holds after it (a header
 * only, no frame, is a clean empty stream). Width and height are at most SH_IMAGE_MAX_SIZE, so
 * a frame's byte count never overflows, and a frame of more than SH_FRAME_PIXELS_DEFAULT pixels
 * (width x height, image.h) is refused (SH_ERANGE, naming the size and the bound), on a pipe
 * too, before anyone allocates one. */
sh_status sh_y4m_reader_open(const char *path, sh_y4m_reader **out);
/* sh_y4m_reader_open with the caller's bound on a frame's pixels instead of the default (the
 * daemon's [source] max_frame_pixels). */
sh_status sh_y4m_reader_open_max(const char *path, long long max_pixels, sh_y4m_reader **out);
const sh_y4m_header *sh_y4m_reader_header(const sh_y4m_reader *reader);
/* Reads the next frame into img (created by the caller with the header's format and size).
 * Returns SH_EEOF at a clean end; a damaged FRAME line or a truncated frame returns SH_EFORMAT
 * naming the file and the 0-based frame index; frames before it were already delivered. */
sh_status sh_y4m_reader_read(sh_y4m_reader *reader, sh_image *img);
int sh_y4m_reader_frame_index(const sh_y4m_reader *reader); /* frames delivered so far */
/* Whole frames (of "FRAME\n" plus the planes) the rest of a regular file can hold; -1 for a
 * pipe or another stream of unknown size. */
long long sh_y4m_reader_whole_frames(const sh_y4m_reader *reader);

/* Where a stream is damaged, after sh_y4m_reader_read returned SH_EFORMAT. */
typedef struct {
    int frame;              /* 0-based index of the frame that could not be read */
    long long offset;       /* byte offset of its FRAME line */
    long long lost;         /* bytes from there to the end of the file (-1: not a regular file) */
    long long frames_lost;  /* lost in frames, rounded up (1 for a torn last frame); -1 unknown */
} sh_y4m_damage;
/* 1 and *damage filled when the stream stopped at damage (SH_EFORMAT), else 0. */
int sh_y4m_reader_damage(const sh_y4m_reader *reader, sh_y4m_damage *damage);
void sh_y4m_reader_close(sh_y4m_reader *reader);
/* Reads from a stream the caller opened (a pipe, fmemopen); name is used in messages. The
 * caller keeps the FILE and closes it after sh_y4m_reader_close. Frames are bounded as by
 * sh_y4m_reader_open. */
sh_status sh_y4m_reader_open_file(FILE *file, const char *name, sh_y4m_reader **out);

typedef struct sh_y4m_writer sh_y4m_writer;

/* path "-" writes stdout. The header is written at once. */
sh_status sh_y4m_writer_open(const char *path, const sh_y4m_header *header, sh_y4m_writer **out);
sh_status sh_y4m_writer_write(sh_y4m_writer *writer, const sh_image *img);
/* A file that does not exist yet (O_EXCL, mode 0640 before the umask): an existing one is never
 * written over (SH_EIO naming it). */
sh_status sh_y4m_writer_open_new(const char *path, const sh_y4m_header *header, sh_y4m_writer **out);
/* Hands what is buffered to the kernel (fflush): a process killed after this loses none of it,
 * power loss only what the kernel has not written yet (fdatasync the descriptor for that, from
 * any thread: sh_y4m_writer_fd). SH_EIO on a write error (disk full). */
sh_status sh_y4m_writer_flush(sh_y4m_writer *writer);
/* The file's descriptor (-1 for none). */
int sh_y4m_writer_fd(const sh_y4m_writer *writer);
/* Flushes and closes; reports a failed flush (disk full) as SH_EIO. */
sh_status sh_y4m_writer_close(sh_y4m_writer *writer);
/* Writes to a stream the caller opened; close flushes it but leaves it open. */
sh_status sh_y4m_writer_open_file(FILE *file, const char *name, const sh_y4m_header *header,
                                  sh_y4m_writer **out);

/* Parses a header line (without "YUV4MPEG2 " magic check done by the caller: the full line,
 * starting with "YUV4MPEG2", without the newline). Exposed for fuzzing and tests. */
sh_status sh_y4m_header_parse(const char *line, size_t len, sh_y4m_header *header);

#ifdef __cplusplus
}
#endif
#endif
