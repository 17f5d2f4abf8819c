/* libFuzzer: a hostile shared-memory segment. Whatever the bytes say, the reader either
 * refuses the header or reads frames without leaving the buffer. */
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "stillheart/display.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    /* the segment is page aligned in real life; the reader's atomic loads need 8 */
    uint8_t *segment = aligned_alloc(64, (size + 63) & ~(size_t)63);
    if (!segment) return 0;
    memcpy(segment, data, size);
    sh_display_reader *r;
    if (sh_display_reader_attach(segment, size, &r) == SH_OK) {
        const sh_display_header *h = sh_display_reader_header(r);
        sh_image frame;
        if ((size_t)h->width * h->height <= (1u << 20) &&
            sh_image_create(&frame, (sh_pixfmt)h->format, (int)h->width, (int)h->height) == SH_OK) {
            sh_display_frame_info info;
            for (int k = 0; k < 3; k++)
                if (sh_display_reader_next(r, &frame, &info, 0) != SH_OK) break;
            sh_image_destroy(&frame);
        }
        sh_display_reader_close(r);
    }
    free(segment);
    return 0;
}
