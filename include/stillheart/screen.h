/* The picture a monitor shows: a published frame scaled into an XRGB8888 scanout buffer with
 * letterboxing, and the status overlay drawn over it (stillheart-show; docs/display.md).
 *
 * Pure pixel work on memory the caller owns (a KMS dumb buffer, or a test's array): no device,
 * nothing printed, so that the host tests check every pixel. Each frame row is converted once
 * (into the picture directly when the frame is as wide as the picture, else into one row
 * allocated per call) and a row repeated by upscaling is copied.
 *
 * Scaling keeps the frame's aspect ratio (square pixels) and centres it: the picture rectangle is
 * the whole height or the whole width of the screen, the rest is black bars. Each screen pixel of
 * the picture takes the frame pixel under its centre (nearest neighbour:
 * sx = floor((x + 0.5) * frame_width / picture_width), the same in y), so a picture at an
 * integer scale repeats each frame pixel exactly and none is ever blended with its neighbour.
 * YUV is converted with BT.601 coefficients, full or limited range as the segment says; I420
 * chroma is the sample of the 2x2 block the luma sample lies in.
 *
 * The overlay (sh_screen_overlay):
 *   off      nothing is drawn over the picture: its pixels are exactly the frame's;
 *   minimal  a thin frame in the status colour along the inside edge of the picture;
 *   full     that frame, a badge in the picture's top-left corner naming the status in black on
 *            the status colour, and the reason (the segment's text) in white on black along the
 *            picture's bottom edge when there is one.
 * Colours: stabilized green, degraded amber, raw red (SH_SCREEN_*). "NO SIGNAL" (with the time
 * since the last frame) replaces the whole picture in every mode: a frame that is no longer
 * coming is never left on the screen as if it were live.
 *
 * Text is a 5x7 bitmap font of its own (src/screen/font.c: upper-case letters, digits and the
 * punctuation of the daemon's reasons; lower case is shown in upper case, any other byte as '?'),
 * drawn in cells of 6x8 pixels times an integer scale. */
#ifndef STILLHEART_SCREEN_H
#define STILLHEART_SCREEN_H

#include <stdint.h>

#include "stillheart/image.h"

#ifdef __cplusplus
extern "C" {
#endif

#define SH_SCREEN_BLACK 0x00000000u
#define SH_SCREEN_WHITE 0x00ffffffu
#define SH_SCREEN_STABILIZED 0x0000c800u /* green */
#define SH_SCREEN_DEGRADED 0x00ffb000u   /* amber */
#define SH_SCREEN_RAW 0x00e00000u        /* red */

/* One glyph cell: 5x7 pixels and a column and a row of space, times the text scale. */
#define SH_SCREEN_CELL_W 6
#define SH_SCREEN_CELL_H 8

typedef enum { SH_SCREEN_OVERLAY_OFF = 0, SH_SCREEN_OVERLAY_MINIMAL, SH_SCREEN_OVERLAY_FULL } sh_screen_overlay;

/* An XRGB8888 buffer (0x00RRGGBB per pixel, little endian as DRM_FORMAT_XRGB8888). */
typedef struct {
    uint32_t *pixels;
    int width, height;
    int stride; /* bytes from one row to the next, a multiple of 4 */
} sh_screen_buffer;

typedef struct {
    int x, y, width, height;
} sh_screen_rect;

/* Where everything goes for a frame of frame_w x frame_h on a screen_w x screen_h screen. */
typedef struct {
    sh_screen_rect picture; /* the scaled frame; the rest of the screen is black */
    int border;             /* the status frame's thickness: max(2, screen_h / 160) */
    int scale;              /* text scale: max(1, screen_h / 240) */
    sh_screen_rect badge;   /* full mode's status badge (the longest word's size, "STABILIZED") */
} sh_screen_layout;

/* The layout; a frame or screen without pixels gives an empty picture rectangle. */
sh_screen_layout sh_screen_layout_for(int frame_w, int frame_h, int screen_w, int screen_h);

/* Accepts "off", "minimal", "full"; 0 for anything else. */
int sh_screen_overlay_parse(const char *text, sh_screen_overlay *out);
const char *sh_screen_overlay_name(sh_screen_overlay overlay);

/* The colour and the badge's word for a status (sh_display_status's values: 0 raw, 1
 * stabilized, 2 degraded); an unknown value is raw's. */
uint32_t sh_screen_status_colour(uint32_t status);
const char *sh_screen_status_word(uint32_t status);

/* The frame (GRAY8, I420, YUV444 or RGB24) scaled into the picture rectangle of `layout`, the
 * bars black. SH_EINVAL for a format it does not know or a layout that does not fit dst. */
sh_status sh_screen_draw_frame(const sh_screen_buffer *dst, const sh_screen_layout *layout,
                               const sh_image *frame, int full_range);

/* The same for the screen rows [y0, y1) only (clipped to the buffer), bars included: bands that
 * tile the screen, drawn by as many threads, make the picture sh_screen_draw_frame makes, byte
 * for byte (stillheart-show --threads). */
sh_status sh_screen_draw_frame_band(const sh_screen_buffer *dst, const sh_screen_layout *layout,
                                    const sh_image *frame, int full_range, int y0, int y1);

/* A frame drawn by `threads` threads (1 to 8: the caller and threads - 1 helpers started at
 * create), each a band of the screen: the same bytes as sh_screen_draw_frame. _draw returns once
 * every band is drawn; SH_OK or the first band's failure with its message. One caller at a time.
 * With one thread, the frame is read on the calling thread with no lock held and nothing
 * allocated meanwhile (rows for a wider frame are grown before it is read): a draw from a view
 * that sh_display_reader_view may abandon by a jump leaves the painter as it was. */
typedef struct sh_screen_painter sh_screen_painter;
sh_status sh_screen_painter_create(int threads, sh_screen_painter **out);
sh_status sh_screen_painter_draw(sh_screen_painter *p, const sh_screen_buffer *dst, const sh_screen_layout *layout,
                                 const sh_image *frame, int full_range);
void sh_screen_painter_destroy(sh_screen_painter *p);

/* The overlay for a frame of this status and reason (NUL terminated, at most reason_cap bytes
 * read: it comes from shared memory) drawn over the picture; nothing in SH_SCREEN_OVERLAY_OFF. */
void sh_screen_draw_status(const sh_screen_buffer *dst, const sh_screen_layout *layout,
                           sh_screen_overlay overlay, uint32_t status, const char *reason,
                           int reason_cap);

/* The whole screen black with "NO SIGNAL" in the middle (white, twice the text scale) and
 * below it "LAST FRAME N S AGO" (whole seconds, from since_s >= 0) or "NO FRAME YET" (since_s
 * < 0), at the text scale. */
void sh_screen_draw_no_signal(const sh_screen_buffer *dst, double since_s);

/* Text at (x, y) (its top-left corner), glyphs only (the space between them is left as it
 * was), clipped to the buffer; at most `cap` bytes or up to a NUL. Returns its width in pixels
 * (cells x SH_SCREEN_CELL_W x scale). */
int sh_screen_draw_text(const sh_screen_buffer *dst, int x, int y, int scale, uint32_t colour,
                        const char *text, int cap);
/* The 7 rows of a character's glyph, bit 4 the leftmost of 5 columns ('?' for what the font
 * does not have; lower case as upper case). */
const uint8_t *sh_screen_glyph(unsigned char c);

/* A filled rectangle, clipped to the buffer. */
void sh_screen_fill(const sh_screen_buffer *dst, sh_screen_rect r, uint32_t colour);

#ifdef __cplusplus
}
#endif
#endif
