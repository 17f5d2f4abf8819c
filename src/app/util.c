#include <errno.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "app.h"
#include "stillheart/y4m.h"

int app_parse_int(const char *option, const char *text, int min, int max, int *out)
{
    char *end;
    errno = 0;
    long v = strtol(text, &end, 10);
    if (errno || end == text || *end || v < min || v > max) {
        fprintf(stderr, "stillheart: %s: '%s' is not a whole number in %d..%d\n", option, text,
                min, max);
        return 0;
    }
    *out = (int)v;
    return 1;
}

int app_parse_double(const char *option, const char *text, double min, double max, double *out)
{
    char *end;
    errno = 0;
    double v = strtod(text, &end);
    if (errno || end == text || *end || !isfinite(v) || v < min || v > max) {
        fprintf(stderr, "stillheart: %s: '%s' is not a number in %g..%g\n", option, text, min,
                max);
        return 0;
    }
    *out = v;
    return 1;
}

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

void app_progress_start(app_progress *p)
{
    p->enabled = isatty(STDERR_FILENO);
    p->start = p->last = app_now();
}

void app_progress_update(app_progress *p, const char *label, int done, int total)
{
    if (!p->enabled) return;
    double now = app_now();
    if (now - p->last < 0.1 && done != total) return;
    p->last = now;
    double rate = done / fmax(now - p->start, 1e-9);
    if (total > 0) {
        int width = 30, fill = (int)((long)width * done / total);
        fprintf(stderr, "\r%s [%.*s%*s] %d/%d  %.1f frames/s ", label, fill,
                "##############################", width - fill, "", done, total, rate);
    } else {
        fprintf(stderr, "\r%s %d frames  %.1f frames/s ", label, done, rate);
    }
}

void app_progress_end(app_progress *p)
{
    if (p->enabled) fputc('\n', stderr);
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
