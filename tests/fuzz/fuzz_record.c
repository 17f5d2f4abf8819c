/* libFuzzer: arbitrary bytes as a recording (record.h), versions 1 and 2, damaged anywhere.
 * Reads every record (resyncing past damage) and checks what the reader promises: frames pass
 * sh_raw_check against their stream, sets count their members, the bytes reported lost are
 * within the file; small frames are converted to I420 and GRAY8 as the replay path would. */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "stillheart/pixconv.h"
#include "stillheart/record.h"

static void check(int ok)
{
    if (!ok) abort();
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    if (size == 0) return 0; /* fmemopen refuses an empty buffer */
    FILE *in = fmemopen((void *)data, size, "rb");
    if (!in) return 0;
    sh_rec_reader *r;
    if (sh_rec_reader_open_file(in, "fuzz.shrec", &r) != SH_OK) {
        fclose(in);
        return 0;
    }
    sh_pixconv *conv = NULL;
    sh_pixconv_create(256, 256, &conv);
    sh_rec_record rec;
    int n = 0;
    while (n++ < 10000 && sh_rec_reader_next(r, &rec) == SH_OK) {
        if (rec.type == SH_REC_FRAME) {
            const sh_rec_stream *s = sh_rec_reader_stream(r, rec.camera);
            check(s != NULL);
            check(rec.raw.width == s->width && rec.raw.height == s->height && rec.raw.format == s->format);
            check(sh_raw_check(&rec.raw) == SH_OK);
            if (rec.raw.width <= 256 && rec.raw.height <= 256 && !((rec.raw.width | rec.raw.height) & 1)) {
                sh_image img;
                if (sh_image_create(&img, SH_PIX_I420, rec.raw.width, rec.raw.height) == SH_OK) {
                    sh_pixconv_convert(conv, &rec.raw, &img);
                    sh_image_destroy(&img);
                }
            }
        } else if (rec.type == SH_REC_SET) {
            check(rec.set.count == __builtin_popcount(rec.set.present));
        }
    }
    /* what was lost is within the file, and a torn tail is at most one record's worth */
    check(sh_rec_reader_lost_bytes(r) <= size);
    check(sh_rec_reader_version(r) == 1 || sh_rec_reader_version(r) == 2);
    sh_pixconv_destroy(conv);
    sh_rec_reader_close(r);
    fclose(in);
    return 0;
}
