/* Shared between the Y4M reader and writer; not part of the public API. */
#ifndef STILLHEART_Y4M_INTERNAL_H
#define STILLHEART_Y4M_INTERNAL_H

#include "stillheart/y4m.h"

/* Longest header or FRAME line accepted: the fixed tags plus the whole extra buffer, with room
 * to spare. It only bounds what a damaged stream can make us scan. */
#define Y4M_MAX_HEADER (SH_Y4M_MAX_EXTRA + 256)

/* sh_y4m_header_parse with the file name to put in messages. */
sh_status y4m_header_parse_named(const char *line, size_t len, const char *name,
                                 sh_y4m_header *header);

/* The refusal of a stream whose first n bytes (head) lack the magic: what it looks like (MP4,
 * Matroska, PNG...) and the ffmpeg command that converts it, for name ("<stdin>": a pipe). */
sh_status y4m_refuse_not_y4m(const unsigned char *head, size_t n, const char *name);

/* Writes the header line (with its newline) for header into out; returns its length, or -1 when
 * the header cannot be written (bad size or format, extra with a newline). */
int y4m_header_format(const sh_y4m_header *header, char *out, size_t cap);

#endif
