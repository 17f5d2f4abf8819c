/* The OpenCV FileStorage YAML subset of include/stillheart/calib.h: top-level `key: scalar` and
 * `key: !!opencv-matrix` maps with rows, cols, dt and a bracketed data list that may span lines;
 * and the physical checks a calibration passes before it is used (check.c). */
#include "stillheart/calib.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define MAX_DATA 16

void sh_calib_compute_p(sh_calib *calib)
{
    for (int c = 0; c < calib->num_cameras && c < SH_CALIB_MAX_CAMERAS; c++) {
        sh_calib_camera *k = &calib->cam[c];
        for (int i = 0; i < 3; i++)
            for (int j = 0; j < 4; j++) {
                double s = 0;
                for (int l = 0; l < 3; l++) s += k->K[3 * i + l] * (j < 3 ? k->R[3 * l + j] : k->t[l]);
                k->P[4 * i + j] = s;
            }
    }
}

static void put_matrix(FILE *f, const char *key, int idx, int rows, int cols, const double *d)
{
    fprintf(f, "%s_%d: !!opencv-matrix\n   rows: %d\n   cols: %d\n   dt: d\n   data: [", key, idx,
            rows, cols);
    for (int i = 0; i < rows * cols; i++)
        fprintf(f, "%s%s%.17g", i ? "," : " ", i && i % 3 == 0 ? "\n       " : "", d[i]);
    fprintf(f, " ]\n");
}

sh_status sh_calib_write(const char *path, const sh_calib *calib)
{
    if (calib->num_cameras < 1 || calib->num_cameras > SH_CALIB_MAX_CAMERAS)
        return sh_error_set(SH_EINVAL, "%s: %d cameras", path, calib->num_cameras);
    FILE *f = fopen(path, "w");
    if (!f) return sh_error_set(SH_EIO, "%s: cannot create: %s", path, strerror(errno));
    fprintf(f, "%%YAML:1.0\n---\nnum_cameras: %d\nimage_width: %d\nimage_height: %d\n",
            calib->num_cameras, calib->width, calib->height);
    for (int c = 0; c < calib->num_cameras; c++) {
        const sh_calib_camera *k = &calib->cam[c];
        int nd = k->num_dist > 0 ? k->num_dist : 5;
        put_matrix(f, "K", c, 3, 3, k->K);
        put_matrix(f, "dist", c, 1, nd, k->dist);
        put_matrix(f, "R", c, 3, 3, k->R);
        put_matrix(f, "t", c, 3, 1, k->t);
        put_matrix(f, "P", c, 3, 4, k->P);
    }
    if (ferror(f) | fclose(f)) return sh_error_set(SH_EIO, "%s: write failed", path);
    return SH_OK;
}

typedef struct {
    char key[64];
    int line;
    int rows, cols, have_dt, in_data, closed;
    int n;
    double d[MAX_DATA];
} matrix;

enum { HAVE_K = 1, HAVE_R = 2, HAVE_T = 4, HAVE_P = 8, HAVE_DIST = 16 };

static sh_status finish_matrix(matrix *mx, const char *name, sh_calib *calib, int *have)
{
    if (!mx->key[0]) return SH_OK;
    if (!mx->closed || mx->rows <= 0 || mx->cols <= 0 || mx->rows * mx->cols != mx->n)
        return sh_error_set(SH_EFORMAT, "%s:%d: matrix '%s' is incomplete or its data does not "
                            "match rows x cols", name, mx->line, mx->key);
    const char *us = strrchr(mx->key, '_');
    char *end;
    long idx = us ? strtol(us + 1, &end, 10) : -1;
    if (!us || us[1] < '0' || us[1] > '9' || *end != '\0' || idx < 0 || idx >= SH_CALIB_MAX_CAMERAS) {
        mx->key[0] = '\0';
        return SH_OK; /* some other matrix: not ours to judge */
    }
    size_t base = (size_t)(us - mx->key);
    sh_calib_camera *k = &calib->cam[idx];
    int *h = &have[idx];
#define IS(s) (base == strlen(s) && strncmp(mx->key, s, base) == 0)
#define SHAPE(r, c) (mx->rows == (r) && mx->cols == (c))
    if (IS("K") && SHAPE(3, 3)) {
        memcpy(k->K, mx->d, sizeof k->K);
        *h |= HAVE_K;
    } else if (IS("R") && SHAPE(3, 3)) {
        memcpy(k->R, mx->d, sizeof k->R);
        *h |= HAVE_R;
    } else if (IS("t") && (SHAPE(3, 1) || SHAPE(1, 3))) {
        memcpy(k->t, mx->d, sizeof k->t);
        *h |= HAVE_T;
    } else if (IS("P") && SHAPE(3, 4)) {
        memcpy(k->P, mx->d, sizeof k->P);
        *h |= HAVE_P;
    } else if (IS("dist") && (mx->rows == 1 || mx->cols == 1) &&
               (mx->n == 4 || mx->n == 5 || mx->n == 8 || mx->n == 12 || mx->n == 14)) {
        memset(k->dist, 0, sizeof k->dist);
        memcpy(k->dist, mx->d, sizeof(double) * (size_t)mx->n);
        k->num_dist = mx->n;
        *h |= HAVE_DIST;
    } else if (IS("K") || IS("R") || IS("t") || IS("P") || IS("dist")) {
        return sh_error_set(SH_EFORMAT, "%s:%d: '%s' has the wrong shape %dx%d", name, mx->line,
                            mx->key, mx->rows, mx->cols);
    }
#undef IS
#undef SHAPE
    mx->key[0] = '\0';
    return SH_OK;
}

/* Consumes numbers from s into the matrix until ']' or the end of the line. */
static int scan_data(matrix *mx, const char *s)
{
    for (;;) {
        while (*s == ' ' || *s == '\t' || *s == ',' || *s == '\r') s++;
        if (*s == '\0') return 1;
        if (*s == ']') {
            mx->closed = 1;
            mx->in_data = 0;
            s++;
            while (*s == ' ' || *s == '\t' || *s == '\r') s++;
            return *s == '\0';
        }
        char *end;
        errno = 0;
        double v = strtod(s, &end);
        if (end == s || errno == ERANGE || !isfinite(v) || mx->n >= MAX_DATA) return 0;
        mx->d[mx->n++] = v;
        s = end;
    }
}

static int parse_int(const char *s, int *out)
{
    char *end;
    errno = 0;
    long v = strtol(s, &end, 10);
    while (*end == ' ' || *end == '\t' || *end == '\r') end++;
    if (end == s || *end != '\0' || errno || v < 0 || v > 1000000) return 0;
    *out = (int)v;
    return 1;
}

/* rows, cols, dt or data (whose numbers may go on over the next lines) of the matrix being read;
 * another key is ignored. 0: a bad value. */
static int matrix_field(matrix *mx, const char *key, const char *val)
{
    int ok = 1;
    if (!strcmp(key, "rows")) ok = parse_int(val, &mx->rows) && mx->rows <= MAX_DATA;
    else if (!strcmp(key, "cols")) ok = parse_int(val, &mx->cols) && mx->cols <= MAX_DATA;
    else if (!strcmp(key, "dt")) ok = (val[0] == 'd' || val[0] == 'f') && (mx->have_dt = 1);
    else if (!strcmp(key, "data")) {
        ok = val[0] == '[' && !mx->closed;
        mx->in_data = ok;
        ok = ok && scan_data(mx, val + 1);
    }
    return ok;
}

/* The whole file read: the sizes and each camera's K, R and t must be there; P is computed
 * where the file has none. */
static sh_status complete(sh_calib *calib, const int *have, const char *name)
{
    if (calib->num_cameras < 1 || calib->num_cameras > SH_CALIB_MAX_CAMERAS)
        return sh_error_set(SH_EFORMAT, "%s: num_cameras missing or not 1..%d", name, SH_CALIB_MAX_CAMERAS);
    if (calib->width < 1 || calib->height < 1)
        return sh_error_set(SH_EFORMAT, "%s: image_width/image_height missing", name);
    for (int c = 0; c < calib->num_cameras; c++) {
        if ((have[c] & (HAVE_K | HAVE_R | HAVE_T)) != (HAVE_K | HAVE_R | HAVE_T))
            return sh_error_set(SH_EFORMAT, "%s: camera %d lacks K_%d, R_%d or t_%d", name, c, c, c, c);
        if (!(have[c] & HAVE_DIST)) calib->cam[c].num_dist = 0;
    }
    double P[SH_CALIB_MAX_CAMERAS][12];
    for (int c = 0; c < calib->num_cameras; c++) memcpy(P[c], calib->cam[c].P, sizeof P[c]);
    sh_calib_compute_p(calib);
    for (int c = 0; c < calib->num_cameras; c++) /* a P from the file wins: it may be rectified */
        if (have[c] & HAVE_P) memcpy(calib->cam[c].P, P[c], sizeof P[c]);
    return SH_OK;
}

sh_status sh_calib_parse(const char *text, size_t len, const char *name, sh_calib *calib)
{
    memset(calib, 0, sizeof *calib);
    calib->num_cameras = -1;
    calib->width = calib->height = -1;
    int have[SH_CALIB_MAX_CAMERAS] = {0};
    matrix mx;
    memset(&mx, 0, sizeof mx);
    char line[512];
    sh_lines it;
    sh_lines_init(&it, text, len, name);
    sh_status st;
    while ((st = sh_lines_next(&it, line, sizeof line)) == SH_OK) {
        int lineno = it.lineno;
        if (lineno == 1) {
            if (strncmp(line, "%YAML", 5) != 0)
                return sh_error_set(SH_EFORMAT, "%s:1: not an OpenCV YAML file (no %%YAML)", name);
            continue;
        }
        if (mx.in_data) {
            if (!scan_data(&mx, line))
                return sh_error_set(SH_EFORMAT, "%s:%d: bad matrix data", name, lineno);
            continue;
        }
        const char *s = line;
        while (*s == ' ') s++;
        if (*s == '\0' || *s == '#' || *s == '\r' || strncmp(line, "---", 3) == 0) continue;
        const char *colon = strchr(s, ':');
        if (!colon) return sh_error_set(SH_EFORMAT, "%s:%d: expected 'key: value'", name, lineno);
        char key[64];
        size_t kl = (size_t)(colon - s);
        if (kl == 0 || kl >= sizeof key) return sh_error_set(SH_EFORMAT, "%s:%d: bad key", name, lineno);
        memcpy(key, s, kl);
        key[kl] = '\0';
        const char *val = colon + 1;
        while (*val == ' ' || *val == '\t') val++;
        if (s == line) { /* top level: a new key ends any matrix */
            if ((st = finish_matrix(&mx, name, calib, have)) != SH_OK) return st;
            if (strncmp(val, "!!opencv-matrix", 15) == 0) {
                memset(&mx, 0, sizeof mx);
                memcpy(mx.key, key, kl + 1);
                mx.line = lineno;
                continue;
            }
            int *target = !strcmp(key, "num_cameras")    ? &calib->num_cameras
                          : !strcmp(key, "image_width")  ? &calib->width
                          : !strcmp(key, "image_height") ? &calib->height
                                                         : NULL;
            if (target && !parse_int(val, target))
                return sh_error_set(SH_EFORMAT, "%s:%d: bad value for %s", name, lineno, key);
            continue;
        }
        if (!mx.key[0]) continue; /* inside some other structure */
        if (!matrix_field(&mx, key, val))
            return sh_error_set(SH_EFORMAT, "%s:%d: bad matrix field '%s'", name, lineno, key);
    }
    if (st != SH_EEOF) return st;
    if (mx.in_data) return sh_error_set(SH_EFORMAT, "%s: matrix '%s' not closed", name, mx.key);
    if ((st = finish_matrix(&mx, name, calib, have)) != SH_OK) return st;
    return complete(calib, have, name);
}

sh_status sh_calib_read(const char *path, sh_calib *calib) { return sh_calib_load(path, NULL, calib); }

sh_status sh_calib_load(const char *path, const sh_calib_limits *limits, sh_calib *calib)
{
    FILE *f = fopen(path, "rb");
    if (!f) return sh_error_set(SH_EIO, "%s: cannot open: %s", path, strerror(errno));
    size_t cap = 1 << 16, len = 0;
    char *buf = malloc(cap);
    if (!buf) {
        fclose(f);
        return sh_error_set(SH_ENOMEM, "%s: out of memory", path);
    }
    size_t r;
    while ((r = fread(buf + len, 1, cap - len, f)) > 0) {
        len += r;
        if (len == cap) {
            char *nb = cap < (16u << 20) ? realloc(buf, cap * 2) : NULL;
            if (!nb) {
                free(buf);
                fclose(f);
                return sh_error_set(SH_EFORMAT, "%s: too large for a calibration file", path);
            }
            buf = nb;
            cap *= 2;
        }
    }
    int err = ferror(f);
    fclose(f);
    sh_status st = err ? sh_error_set(SH_EIO, "%s: read error", path) : sh_calib_parse(buf, len, path, calib);
    free(buf);
    if (st == SH_OK) st = sh_calib_check(calib, path, limits, NULL);
    return st;
}
