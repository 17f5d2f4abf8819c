/* What src/screen's files share beyond screen.h. */
#ifndef STILLHEART_SCREEN_INTERNAL_H
#define STILLHEART_SCREEN_INTERNAL_H

#include "stillheart/screen.h"

/* sh_screen_draw_frame_band with the row a scaled frame is converted through given by the
 * caller (frame->width pixels; NULL when the frame is as wide as the picture), so that a caller
 * drawing frame after frame (sh_screen_painter) allocates nothing per frame. */
sh_status screen_draw_band(const sh_screen_buffer *dst, const sh_screen_layout *layout, const sh_image *frame,
                           int full_range, int y0, int y1, uint32_t *row);

#endif
