/* markers.csv: the renderer's per-frame marker truth. The reader is strict (exact header, ten
 * fields a row, numbers that parse whole) because the evaluator's numbers come from it. */
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "phantom.h"

void phantom_csv_free(phantom_csv *csv)
{
    free(csv->rows);
    csv->rows = NULL;
    csv->count = 0;
}

static int parse_int(const char *s, const char *e, int *out)
{
    if (s == e || e - s > 9) return 0;
    int v = 0;
    for (const char *p = s; p < e; p++) {
        if (*p < '0' || *p > '9') return 0;
        v = v * 10 + (*p - '0');
    }
    *out = v;
    return 1;
}

static int parse_double(const char *s, const char *e, double *out)
{
    char tmp[64];
    size_t n = (size_t)(e - s);
    if (n == 0 || n >= sizeof tmp) return 0;
    memcpy(tmp, s, n);
    tmp[n] = '\0';
    char *end;
    errno = 0;
    *out = strtod(tmp, &end);
    if (*end != '\0' || errno == ERANGE) return 0;
    /* nan stands for "not projectable" (behind the camera); inf is never written */
    return !isinf(*out);
}

sh_status phantom_csv_parse(const char *text, size_t len, const char *name, phantom_csv *csv)
{
    csv->rows = NULL;
    csv->count = 0;
    size_t hl = strlen(PHANTOM_CSV_HEADER), pos = 0;
    if (len < hl || memcmp(text, PHANTOM_CSV_HEADER, hl) != 0 ||
        (len > hl && text[hl] != '\n' && text[hl] != '\r'))
        return sh_error_set(SH_EFORMAT, "%s:1: header is not '%s'", name, PHANTOM_CSV_HEADER);
    pos = hl;
    int cap = 0, lineno = 1;
    while (pos < len) {
        if (text[pos] == '\r') pos++;
        if (pos < len && text[pos] == '\n') pos++;
        if (pos >= len) break;
        lineno++;
        size_t e = pos;
        while (e < len && text[e] != '\n' && text[e] != '\r') e++;
        const char *f[11];
        int nf = 0;
        f[nf++] = text + pos;
        for (size_t i = pos; i < e && nf < 11; i++)
            if (text[i] == ',') f[nf++] = text + i + 1;
        if (nf != 10) {
            phantom_csv_free(csv);
            return sh_error_set(SH_EFORMAT, "%s:%d: want 10 fields", name, lineno);
        }
        const char *end[10];
        for (int i = 0; i < 9; i++) end[i] = f[i + 1] - 1;
        end[9] = text + e;
        phantom_csv_row r;
        int ok = parse_int(f[0], end[0], &r.frame) && parse_int(f[1], end[1], &r.camera) &&
                 parse_int(f[2], end[2], &r.id) && parse_double(f[4], end[4], &r.x) &&
                 parse_double(f[5], end[5], &r.y) && parse_int(f[6], end[6], &r.visible) &&
                 r.visible <= 1 && parse_double(f[7], end[7], &r.X) &&
                 parse_double(f[8], end[8], &r.Y) && parse_double(f[9], end[9], &r.Z);
        if (ok && end[3] - f[3] == 1 && *f[3] == 'c') r.point = 4;
        else if (ok && end[3] - f[3] == 1 && *f[3] >= '0' && *f[3] <= '3') r.point = *f[3] - '0';
        else ok = 0;
        if (!ok) {
            phantom_csv_free(csv);
            return sh_error_set(SH_EFORMAT, "%s:%d: bad row", name, lineno);
        }
        if (csv->count == cap) {
            int nc = cap ? 2 * cap : 1024;
            phantom_csv_row *nr = nc > cap ? realloc(csv->rows, sizeof *nr * (size_t)nc) : NULL;
            if (!nr) {
                phantom_csv_free(csv);
                return sh_error_set(SH_ENOMEM, "%s: out of memory", name);
            }
            csv->rows = nr;
            cap = nc;
        }
        csv->rows[csv->count++] = r;
        pos = e;
    }
    return SH_OK;
}

sh_status phantom_csv_read(const char *path, phantom_csv *csv)
{
    csv->rows = NULL;
    csv->count = 0;
    FILE *f = fopen(path, "rb");
    if (!f) return sh_error_set(SH_EIO, "%s: cannot open: %s", path, strerror(errno));
    char *buf = NULL;
    size_t len = 0, cap = 0;
    for (;;) {
        if (len == cap) {
            cap = cap ? 2 * cap : 1 << 20;
            char *nb = realloc(buf, cap);
            if (!nb) {
                free(buf);
                fclose(f);
                return sh_error_set(SH_ENOMEM, "%s: out of memory", path);
            }
            buf = nb;
        }
        size_t r = fread(buf + len, 1, cap - len, f);
        len += r;
        if (r == 0) break;
    }
    int err = ferror(f);
    fclose(f);
    sh_status st = err ? sh_error_set(SH_EIO, "%s: read error", path)
                       : phantom_csv_parse(buf, len, path, csv);
    free(buf);
    return st;
}

static int cmp_key(const phantom_csv_row *r, int frame, int camera, int id, int point)
{
    int a[4] = {r->frame, r->camera, r->id, r->point}, b[4] = {frame, camera, id, point};
    for (int i = 0; i < 4; i++)
        if (a[i] != b[i]) return a[i] < b[i] ? -1 : 1;
    return 0;
}

const phantom_csv_row *phantom_csv_find(const phantom_csv *csv, int frame, int camera, int id,
                                        int point)
{
    /* The renderer writes rows sorted by (frame, camera, marker index, point): binary search on
     * (frame, camera), then scan that block for (id, point). */
    int lo = 0, hi = csv->count;
    while (lo < hi) {
        int mid = lo + (hi - lo) / 2;
        const phantom_csv_row *r = &csv->rows[mid];
        if (r->frame < frame || (r->frame == frame && r->camera < camera)) lo = mid + 1;
        else hi = mid;
    }
    for (int i = lo; i < csv->count && csv->rows[i].frame == frame && csv->rows[i].camera == camera; i++)
        if (cmp_key(&csv->rows[i], frame, camera, id, point) == 0) return &csv->rows[i];
    for (int i = 0; i < csv->count; i++) /* unsorted files still answer */
        if (cmp_key(&csv->rows[i], frame, camera, id, point) == 0) return &csv->rows[i];
    return NULL;
}
