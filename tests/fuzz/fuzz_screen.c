/* libFuzzer: what the display segment hands stillheart-show, drawn on the screen. A frame's
 * size, format and pixels, its status (any 32-bit value, not only the three known) and its
 * reason (bytes from shared memory, with or without a NUL) on a screen of any size: the drawing
 * stays inside the buffer (ASan) and refuses only what screen.h says it refuses.
 *   fw fh sw sh format status(4, little endian) overlay full_range reason(44) pixels... */
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "stillheart/screen.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    if (size < 13 + 44) return 0;
    int fw = data[0] % 64 + 1, fh = data[1] % 64 + 1, sw = data[2] % 200 + 1, sh = data[3] % 200 + 1;
    static const sh_pixfmt formats[] = {SH_PIX_GRAY8, SH_PIX_RGB24, SH_PIX_I420, SH_PIX_YUV444};
    sh_pixfmt fmt = formats[data[4] % 4];
    uint32_t status = (uint32_t)data[5] | (uint32_t)data[6] << 8 | (uint32_t)data[7] << 16 | (uint32_t)data[8] << 24;
    sh_screen_overlay ov = (sh_screen_overlay)(data[9] % 3);
    int full = data[10] & 1;
    char reason[44];
    memcpy(reason, data + 13, sizeof reason);
    const uint8_t *px = data + 13 + 44;
    size_t npx = size - 13 - 44;
    sh_image f;
    if (sh_image_create(&f, fmt, fw, fh) != SH_OK) return 0;
    for (int p = 0; npx && p < f.num_planes; p++)
        for (int y = 0; y < f.plane[p].height; y++)
            for (int x = 0; x < f.plane[p].width * sh_pixfmt_channels(fmt); x++)
                f.plane[p].data[y * f.plane[p].stride + x] = px[(size_t)(p * 7919 + y * 131 + x) % npx];
    /* exactly the screen's bytes, so that ASan sees a write past it */
    sh_screen_buffer b = {malloc((size_t)sw * (size_t)sh * 4), sw, sh, sw * 4};
    if (b.pixels) {
        sh_screen_layout l = sh_screen_layout_for(fw, fh, sw, sh);
        if (sh_screen_draw_frame(&b, &l, &f, full) != SH_OK) abort(); /* a layout for this screen always fits */
        sh_screen_draw_status(&b, &l, ov, status, reason, (int)sizeof reason);
        sh_screen_draw_no_signal(&b, (double)data[11] * 1000.0 - 1.0);
        free(b.pixels);
    }
    sh_image_destroy(&f);
    return 0;
}
