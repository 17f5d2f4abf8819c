/* The points CSV: `frame,id,x,y[,X,Y,Z]` or `frame,id,X,Y,Z`. Parsing is strict about content (every bad row is
 * refused with its line number: a wrong marker position would give a wrong picture) and lenient
 * about layout (CRLF, blank lines, spaces around fields, a UTF-8 BOM). The last line must end in
 * a newline: a file cut inside "24.31" reads "2", a number that parses and is wrong, so a
 * missing final newline is taken for a cut file, not for a careless editor. */
#include "stillheart/points.h"

#include <errno.h>
#include <limits.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#define MAX_FIELDS 7
#define MAX_FIELD_CHARS 127

typedef struct {
    sh_point p;
    int line;
} row_in;

typedef struct {
    const char *s;
    size_t len;
} span;

static span trim(const char *s, size_t len)
{
    while (len && (*s == ' ' || *s == '\t')) s++, len--;
    while (len && (s[len - 1] == ' ' || s[len - 1] == '\t')) len--;
    return (span){s, len};
}

/* Splits [s, s+len) at commas into at most MAX_FIELDS + 1 trimmed fields; returns the count
 * (MAX_FIELDS + 1 means "too many"). */
static int split(const char *s, size_t len, span *fields)
{
    int n = 0;
    size_t start = 0;
    for (size_t i = 0; i <= len; i++) {
        if (i == len || s[i] == ',') {
            if (n == MAX_FIELDS + 1) return n;
            fields[n++] = trim(s + start, i - start);
            start = i + 1;
        }
    }
    return n;
}

static int span_is(span f, const char *word)
{
    return f.len == strlen(word) && memcmp(f.s, word, f.len) == 0;
}

/* Returns 0 ok, 1 not an integer, 2 negative, 3 above max. */
static int parse_int(span f, long max, int *out)
{
    size_t i = 0;
    int neg = 0;
    if (f.len && (f.s[0] == '+' || f.s[0] == '-')) neg = f.s[0] == '-', i = 1;
    if (i == f.len) return 1;
    long v = 0;
    int big = 0;
    for (; i < f.len; i++) {
        if (f.s[i] < '0' || f.s[i] > '9') return 1;
        if (!big) v = v * 10 + (f.s[i] - '0');
        if (v > max) big = 1;
    }
    if (neg && (v != 0 || big)) return 2;
    if (big) return 3;
    *out = (int)v;
    return 0;
}

/* Returns 0 ok, 1 not a number, 2 not finite. */
static int parse_real(span f, double *out)
{
    char buf[MAX_FIELD_CHARS + 1];
    if (f.len == 0 || f.len > MAX_FIELD_CHARS) return 1;
    memcpy(buf, f.s, f.len);
    buf[f.len] = '\0';
    char *end;
    double v = strtod(buf, &end);
    if (end != buf + f.len) return 1;
    if (!isfinite(v)) return 2;
    *out = v;
    return 0;
}

static int cmp_rows(const void *a, const void *b)
{
    const row_in *ra = a, *rb = b;
    if (ra->p.frame != rb->p.frame) return ra->p.frame < rb->p.frame ? -1 : 1;
    if (ra->p.id != rb->p.id) return ra->p.id < rb->p.id ? -1 : 1;
    return (ra->line > rb->line) - (ra->line < rb->line); /* first occurrence first */
}

static const char *const column_names[MAX_FIELDS] = {"frame", "id", "x", "y", "X", "Y", "Z"};

/* The headers a file may have: its columns as indices into column_names. */
static const struct {
    int count, has_3d;
    int col[MAX_FIELDS];
} layouts[] = {{4, 0, {0, 1, 2, 3}}, {7, 1, {0, 1, 2, 3, 4, 5, 6}}, {5, SH_POINTS_XYZ_ONLY, {0, 1, 4, 5, 6}}};
#define NUM_LAYOUTS (int)(sizeof layouts / sizeof layouts[0])

/* The layout whose header the n fields are, or -1. */
static int header_layout(const span *fields, int n)
{
    for (int k = 0; k < NUM_LAYOUTS; k++) {
        int ok = n == layouts[k].count;
        for (int c = 0; ok && c < n; c++) ok = span_is(fields[c], column_names[layouts[k].col[c]]);
        if (ok) return k;
    }
    return -1;
}

/* Parses one data row into r (the columns of layouts[k]); on failure records "name:line:
 * reason". */
static sh_status parse_row(const span *fields, int nfields, int k, const char *name,
                           int line, row_in *r)
{
    int expect = layouts[k].count;
    if (nfields != expect)
        return sh_error_set(SH_EFORMAT, "%s:%d: %s%d columns, the header has %d", name, line,
                            nfields > MAX_FIELDS ? "more than " : "",
                            nfields > MAX_FIELDS ? MAX_FIELDS : nfields, expect);
    int ints[2];
    for (int c = 0; c < 2; c++) {
        long max = c == 0 ? SH_POINTS_MAX_FRAME : INT_MAX;
        int e = parse_int(fields[c], max, &ints[c]);
        int flen = fields[c].len > 32 ? 32 : (int)fields[c].len;
        if (e == 1)
            return sh_error_set(SH_EFORMAT, "%s:%d: %s '%.*s' is not an integer", name, line,
                                column_names[c], flen, fields[c].s);
        if (e == 2)
            return sh_error_set(SH_EFORMAT, "%s:%d: negative %s '%.*s'", name, line,
                                column_names[c], flen, fields[c].s);
        if (e == 3)
            return sh_error_set(SH_EFORMAT, "%s:%d: %s '%.*s' out of range (max %ld)", name,
                                line, column_names[c], flen, fields[c].s, max);
    }
    double v[5] = {NAN, NAN, NAN, NAN, NAN};
    for (int c = 2; c < expect; c++) {
        int col = layouts[k].col[c];
        int e = parse_real(fields[c], &v[col - 2]);
        int flen = fields[c].len > 32 ? 32 : (int)fields[c].len;
        if (e)
            return sh_error_set(SH_EFORMAT, "%s:%d: %s '%.*s' is %s", name, line,
                                column_names[col], flen, fields[c].s,
                                e == 1 ? "not a number" : "not finite");
    }
    r->p = (sh_point){ints[0], ints[1], v[0], v[1], v[2], v[3], v[4]};
    r->line = line;
    return SH_OK;
}

/* Sorts, refuses duplicates, builds the frame index. Takes ownership of rows. */
static sh_status finish(row_in *rows, int count, int has_3d, const char *name,
                        sh_points *points)
{
    if (count > 1) qsort(rows, (size_t)count, sizeof *rows, cmp_rows);
    for (int i = 1; i < count; i++) {
        if (rows[i].p.frame == rows[i - 1].p.frame && rows[i].p.id == rows[i - 1].p.id) {
            sh_status st = sh_error_set(SH_EFORMAT,
                                        "%s:%d: duplicate marker: frame %d id %d (first at "
                                        "line %d)",
                                        name, rows[i].line, rows[i].p.frame, rows[i].p.id,
                                        rows[i - 1].line);
            free(rows);
            return st;
        }
    }
    int max_frame = count ? rows[count - 1].p.frame : -1;
    sh_point *out = malloc((size_t)(count ? count : 1) * sizeof *out);
    int *start = malloc((size_t)(max_frame + 2) * sizeof *start);
    if (!out || !start) {
        free(out);
        free(start);
        free(rows);
        return sh_error_set(SH_ENOMEM, "%s: out of memory", name);
    }
    for (int i = 0; i < count; i++) out[i] = rows[i].p;
    free(rows);
    int i = 0;
    for (int f = 0; f <= max_frame + 1; f++) {
        while (i < count && out[i].frame < f) i++;
        start[f] = i;
    }
    points->rows = out;
    points->count = count;
    points->has_3d = has_3d;
    points->max_frame = max_frame;
    points->frame_start = start;
    return SH_OK;
}

sh_status sh_points_parse(const char *text, size_t len, const char *name, sh_points *points)
{
    if (!points || (!text && len)) return sh_error_set(SH_EINVAL, "points: missing argument");
    if (!name) name = "points";
    memset(points, 0, sizeof *points);
    points->max_frame = -1;

    if (len >= 3 && memcmp(text, "\xEF\xBB\xBF", 3) == 0) text += 3, len -= 3;

    row_in *rows = NULL;
    size_t count = 0, cap = 0;
    int layout = -1; /* layouts[], -1 until the header was read */
    int line = 0;
    span fields[MAX_FIELDS + 1];
    size_t pos = 0;
    while (pos < len) {
        const char *s = text + pos;
        const char *nl = memchr(s, '\n', len - pos);
        size_t llen = nl ? (size_t)(nl - s) : len - pos;
        pos += llen + (nl ? 1 : 0);
        line++;
        if (llen && s[llen - 1] == '\r') llen--;
        span whole = trim(s, llen);
        if (whole.len == 0) continue;
        if (!nl) {
            free(rows);
            return sh_error_set(SH_EFORMAT, "%s:%d: the last line does not end in a newline (is the file cut?)",
                                name, line);
        }
        int n = split(whole.s, whole.len, fields);

        if (layout < 0) {
            if ((layout = header_layout(fields, n)) < 0) {
                free(rows);
                return sh_error_set(SH_EFORMAT,
                                    "%s:%d: bad header, expected 'frame,id,x,y', "
                                    "'frame,id,x,y,X,Y,Z' or 'frame,id,X,Y,Z'",
                                    name, line);
            }
            continue;
        }
        if (count == (size_t)INT_MAX) {
            free(rows);
            return sh_error_set(SH_EFORMAT, "%s:%d: too many rows", name, line);
        }
        if (count == cap) {
            size_t ncap = cap ? cap * 2 : 256;
            row_in *grown = realloc(rows, ncap * sizeof *rows);
            if (!grown) {
                free(rows);
                return sh_error_set(SH_ENOMEM, "%s:%d: out of memory", name, line);
            }
            rows = grown;
            cap = ncap;
        }
        sh_status st = parse_row(fields, n, layout, name, line, &rows[count]);
        if (st != SH_OK) {
            free(rows);
            return st;
        }
        count++;
    }
    if (layout < 0) {
        free(rows);
        return sh_error_set(SH_EFORMAT, "%s:%d: no header, expected 'frame,id,x,y'", name,
                            line ? line : 1);
    }
    return finish(rows, (int)count, layouts[layout].has_3d, name, points);
}

sh_status sh_points_need_2d(const sh_points *points, const char *name)
{
    if (points->has_3d != SH_POINTS_XYZ_ONLY) return SH_OK;
    return sh_error_set(SH_EFORMAT, "%s: 'frame,id,X,Y,Z' has 3D positions only; this needs the image "
                        "positions x,y too ('frame,id,x,y' or 'frame,id,x,y,X,Y,Z')", name);
}

sh_status sh_points_read(const char *path, sh_points *points)
{
    if (!path || !points) return sh_error_set(SH_EINVAL, "points: missing argument");
    int is_stdin = strcmp(path, "-") == 0;
    const char *name = is_stdin ? "<stdin>" : path;
    FILE *f = is_stdin ? stdin : fopen(path, "rb");
    if (!f) return sh_error_set(SH_EIO, "%s: %s", path, strerror(errno));
    /* Read whole (works on pipes: no size known in advance). */
    char *buf = NULL;
    size_t len = 0, cap = 0;
    sh_status st = SH_OK;
    for (;;) {
        if (len == cap) {
            size_t ncap = cap ? cap * 2 : 65536;
            char *grown = realloc(buf, ncap);
            if (!grown) {
                st = sh_error_set(SH_ENOMEM, "%s: out of memory", name);
                break;
            }
            buf = grown;
            cap = ncap;
        }
        size_t n = fread(buf + len, 1, cap - len, f);
        len += n;
        if (n == 0) {
            if (ferror(f)) st = sh_error_set(SH_EIO, "%s: read error: %s", name, strerror(errno));
            break;
        }
    }
    if (!is_stdin) fclose(f);
    if (st == SH_OK) st = sh_points_parse(buf, len, name, points);
    free(buf);
    return st;
}

void sh_points_destroy(sh_points *points)
{
    if (!points) return;
    free(points->rows);
    free(points->frame_start);
    memset(points, 0, sizeof *points);
    points->max_frame = -1;
}

int sh_points_drop_ids(sh_points *points, int min_id)
{
    int w = 0;
    for (int i = 0; i < points->count; i++)
        if (points->rows[i].id < min_id) points->rows[w++] = points->rows[i];
    int dropped = points->count - w;
    points->count = w;
    /* the frames stay (a frame may now have no row); their starts move down */
    for (int f = 0, i = 0; f <= points->max_frame + 1; f++) {
        while (i < w && points->rows[i].frame < f) i++;
        points->frame_start[f] = i;
    }
    return dropped;
}

const sh_point *sh_points_frame(const sh_points *points, int frame, int *count)
{
    if (!points || !points->frame_start || frame < 0 || frame > points->max_frame) {
        if (count) *count = 0;
        return NULL;
    }
    int a = points->frame_start[frame], b = points->frame_start[frame + 1];
    if (count) *count = b - a;
    return points->rows + a;
}

/* The shortest of %.15g / %.17g that reads back to the same double: exact round trips, and
 * 0.1 still prints as 0.1. */
static int put_real(FILE *out, double v)
{
    char buf[40];
    snprintf(buf, sizeof buf, "%.15g", v);
    if (strtod(buf, NULL) != v) snprintf(buf, sizeof buf, "%.17g", v);
    return fputs(buf, out) >= 0;
}

int sh_points_match(const sh_point *ref, int nref, const sh_point *cur, int ncur, int *ids,
                    double *ref_xy, double *cur_xy)
{
    int n = 0;
    for (int i = 0, j = 0; i < nref && j < ncur;) {
        if (ref[i].id < cur[j].id) {
            i++;
        } else if (ref[i].id > cur[j].id) {
            j++;
        } else {
            ids[n] = cur[j].id;
            if (ref_xy) ref_xy[2 * n] = ref[i].x, ref_xy[2 * n + 1] = ref[i].y;
            cur_xy[2 * n] = cur[j].x;
            cur_xy[2 * n + 1] = cur[j].y;
            n++, i++, j++;
        }
    }
    return n;
}

static int has_xyz(const sh_point *p)
{
    return isfinite(p->X) && isfinite(p->Y) && isfinite(p->Z);
}

/* The keeping walk with no landmark id: only the points both frames have. */
int sh_points_match_xyz(const sh_point *ref, int nref, const sh_point *cur, int ncur, int *ids,
                        double *cur_xyz)
{
    int used;
    return sh_points_match_xyz_keep(ref, nref, cur, ncur, INT_MAX, ids, cur_xyz, NULL, &used);
}

int sh_points_match_xyz_keep(const sh_point *ref, int nref, const sh_point *cur, int ncur, int min_id, int *ids,
                             double *cur_xyz, unsigned char *use, int *used)
{
    int n = 0;
    *used = 0;
    for (int i = 0, j = 0; i < nref; i++) {
        while (j < ncur && cur[j].id < ref[i].id) j++;
        int here = j < ncur && cur[j].id == ref[i].id && has_xyz(&cur[j]);
        if (!has_xyz(&ref[i]) || (ref[i].id < min_id && !here)) continue;
        const sh_point *p = here ? &cur[j] : &ref[i];
        ids[n] = ref[i].id;
        cur_xyz[3 * n] = p->X, cur_xyz[3 * n + 1] = p->Y, cur_xyz[3 * n + 2] = p->Z;
        if (use) use[n] = (unsigned char)here;
        *used += here;
        n++;
    }
    return n;
}

sh_status sh_points_write(FILE *out, const sh_point *rows, int count, int has_3d)
{
    if (!out || (count > 0 && !rows) || count < 0)
        return sh_error_set(SH_EINVAL, "points: missing argument");
    for (int i = 0; i < count; i++) {
        const sh_point *p = &rows[i];
        int finite = (has_3d == SH_POINTS_XYZ_ONLY || (isfinite(p->x) && isfinite(p->y))) &&
                     (!has_3d || (isfinite(p->X) && isfinite(p->Y) && isfinite(p->Z)));
        if (p->frame < 0 || p->id < 0 || !finite)
            return sh_error_set(SH_EINVAL, "points: row %d (frame %d id %d) cannot be written: "
                                "negative index or non-finite coordinate", i, p->frame, p->id);
    }
    int xy = has_3d != SH_POINTS_XYZ_ONLY;
    int ok = fputs(!has_3d ? "frame,id,x,y\n" : xy ? "frame,id,x,y,X,Y,Z\n" : "frame,id,X,Y,Z\n", out) >= 0;
    for (int i = 0; ok && i < count; i++) {
        const sh_point *p = &rows[i];
        ok = fprintf(out, "%d,%d", p->frame, p->id) > 0;
        if (ok && xy)
            ok = fputc(',', out) != EOF && put_real(out, p->x) && fputc(',', out) != EOF && put_real(out, p->y);
        if (ok && has_3d)
            ok = fputc(',', out) != EOF && put_real(out, p->X) && fputc(',', out) != EOF &&
                 put_real(out, p->Y) && fputc(',', out) != EOF && put_real(out, p->Z);
        if (ok) ok = fputc('\n', out) != EOF;
    }
    if (!ok || fflush(out) != 0)
        return sh_error_set(SH_EIO, "points: write error: %s", strerror(errno));
    return SH_OK;
}
