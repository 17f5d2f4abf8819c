/* libFuzzer: a hostile shared-memory segment. Whatever the bytes say, the reader either
 * refuses the header or reads frames without leaving the buffer.
 *
 * Two kinds of input. Plain bytes: a segment in memory (sh_display_reader_attach). Bytes that
 * begin with "SHFZ": a real shared-memory object under a name, opened by name as the display
 * opens it, and then changed under the reader between its reads:
 *   "SHFZ" op(1) split(4, little endian) A(split bytes) B(the rest)
 * A is the segment the reader opens; then op & 3 says what happens to it: 0 nothing, 1 it is
 * truncated to (op >> 2) / 63 of its size (a fault under the reader's copy: the SIGBUS guard),
 * 2 it is retired (magic 0) and replaced by B under the name, 3 it is unlinked and B made
 * under the name without retiring A (a reader finds it by the name). The reader reads on. */
#include <fcntl.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <unistd.h>

#include "stillheart/display.h"

/* A viewer that touches every byte a view says it has (ASan sees a view reaching past an
 * attached buffer; a fault past a mapping is the guard's). */
static sh_status touch_view(void *ctx, const sh_image *view, const sh_display_frame_info *info)
{
    unsigned sum = info->status;
    for (int p = 0; p < view->num_planes; p++)
        for (int y = 0; y < view->plane[p].height; y++)
            for (int x = 0; x < view->plane[p].width * sh_pixfmt_channels(view->format); x++)
                sum += view->plane[p].data[(size_t)y * view->plane[p].stride + x];
    *(volatile unsigned *)ctx = sum;
    return SH_OK;
}

/* reads alternate between a copy (sh_display_reader_next) and a view (_view) */
static void read_some(sh_display_reader *r, int reads)
{
    sh_image frame = {0};
    for (int k = 0; k < reads; k++) {
        if (k & 1) {
            volatile unsigned sum = 0;
            sh_display_frame_info info;
            sh_status st = sh_display_reader_view(r, touch_view, (void *)&sum, &info, 0);
            if (st != SH_OK && st != SH_EIO) break;
            continue;
        }
        const sh_display_header *h = sh_display_reader_header(r);
        if (frame.width != (int)h->width || frame.height != (int)h->height || frame.format != (sh_pixfmt)h->format) {
            sh_image_destroy(&frame);
            if ((size_t)h->width * h->height > (1u << 20) ||
                sh_image_create(&frame, (sh_pixfmt)h->format, (int)h->width, (int)h->height) != SH_OK)
                return;
        }
        sh_display_frame_info info;
        sh_status st = sh_display_reader_next(r, &frame, &info, 0);
        if (st != SH_OK && st != SH_ERANGE && st != SH_EIO) break;
    }
    sh_image_destroy(&frame);
}

static int make_object(const char *name, const uint8_t *data, size_t size)
{
    shm_unlink(name);
    int fd = shm_open(name, O_RDWR | O_CREAT | O_EXCL, 0600);
    if (fd < 0) return -1;
    if (size && write(fd, data, size) != (ssize_t)size) {
        close(fd);
        return -1;
    }
    return fd;
}

static void named(const uint8_t *data, size_t size)
{
    if (size < 9) return;
    uint8_t op = data[4];
    uint32_t split;
    memcpy(&split, data + 5, 4);
    data += 9;
    size -= 9;
    size_t a = split < size ? split : size;
    char name[64];
    snprintf(name, sizeof name, "/sh-fuzz-display-%d", (int)getpid());
    int fd = make_object(name, data, a);
    if (fd < 0) return;
    sh_display_reader *r;
    if (sh_display_reader_open(name, NULL, 0, &r) == SH_OK) {
        read_some(r, 2);
        if ((op & 3) == 1 && ftruncate(fd, (off_t)(a * (op >> 2) / 63)) != 0) op = 0;
        if ((op & 3) >= 2) {
            uint64_t zero = 0;
            if ((op & 3) == 2 && a >= 8 && pwrite(fd, &zero, 8, 0) != 8) op = 0;
            int fd2 = make_object(name, data + a, size - a);
            if (fd2 >= 0) close(fd2);
        }
        read_some(r, 3);
        sh_display_reader_close(r);
    }
    close(fd);
    shm_unlink(name);
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    if (size >= 4 && !memcmp(data, "SHFZ", 4)) {
        named(data, size);
        return 0;
    }
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
    /* the same bytes through views, from a reader of its own (each frame is returned once) */
    if (sh_display_reader_attach(segment, size, &r) == SH_OK) {
        const sh_display_header *h = sh_display_reader_header(r);
        volatile unsigned sum = 0;
        sh_display_frame_info info;
        for (int k = 0; k < 3 && (size_t)h->width * h->height <= (1u << 20); k++)
            if (sh_display_reader_view(r, touch_view, (void *)&sum, &info, 0) != SH_OK) break;
        sh_display_reader_close(r);
    }
    free(segment);
    return 0;
}
