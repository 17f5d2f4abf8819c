#include <errno.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "app.h"
#include "stillheart/y4m.h"

double app_now(void) { return (double)sh_monotonic_ns() * 1e-9; }

int app_read_frame_at(const char *path, int index, sh_image *img)
{
    sh_y4m_reader *r;
    if (sh_y4m_reader_open(path, &r) != SH_OK) return 0;
    sh_status st = SH_OK;
    for (int i = 0; i <= index && st == SH_OK; i++) st = sh_y4m_reader_read(r, img);
    sh_y4m_reader_close(r);
    if (st == SH_EEOF) sh_error_set(SH_EINVAL, "%s has no frame %d", path, index);
    return st == SH_OK;
}

int app_write_npy(const char *path, const float *data, int h, int w, int depth)
{
    FILE *f = fopen(path, "wb");
    if (!f) {
        fprintf(stderr, "stillheart: %s: %s\n", path, strerror(errno));
        return 0;
    }
    char dict[128];
    int len = snprintf(dict, sizeof dict,
                       "{'descr': '<f4', 'fortran_order': False, 'shape': (%d, %d, %d), }", h, w,
                       depth);
    /* magic (6) + version (2) + header length (2) + dict + padding + '\n', multiple of 64 */
    int total = 10 + len + 1;
    int pad = (64 - total % 64) % 64;
    uint16_t hlen = (uint16_t)(len + pad + 1);
    unsigned char head[10] = {0x93, 'N', 'U', 'M', 'P', 'Y', 1, 0, (unsigned char)(hlen & 0xff),
                              (unsigned char)(hlen >> 8)};
    fwrite(head, 1, sizeof head, f);
    fwrite(dict, 1, (size_t)len, f);
    for (int i = 0; i < pad; i++) fputc(' ', f);
    fputc('\n', f);
    size_t n = (size_t)h * w * depth;
    /* .npy stores little endian; every platform we build for is little endian. */
    int ok = fwrite(data, sizeof(float), n, f) == n;
    ok &= fclose(f) == 0;
    if (!ok) fprintf(stderr, "stillheart: %s: write failed: %s\n", path, strerror(errno));
    return ok;
}
