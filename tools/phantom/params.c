/* phantom.txt: the model's parameters, one `key value...` line each, doubles printed with 17
 * significant digits so that reading them back gives the very same bits and the truth library
 * reproduces the renderer's surface exactly. */
#include <errno.h>
#include <math.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "phantom.h"

#define MAGIC "stillheart-phantom 1"

typedef struct {
    const char *key;
    size_t offset;
    int count;
    char type;  /* 'd' double, 'i' int, 'u' uint64 */
    char group; /* 0: always there; 'c' camera motion, 'f' first beat, 't' texture contrast, 'm' trilinear
                 * texture, 'b' blood spread: written only when the feature is on, so files from
                 * before it (and without it) read as without */
} field;

#define D(name, n) {#name, offsetof(phantom_model, name), n, 'd', 0}
#define I(name) {#name, offsetof(phantom_model, name), 1, 'i', 0}
#define OD(name, n, g) {#name, offsetof(phantom_model, name), n, 'd', g}
#define OI(name, g) {#name, offsetof(phantom_model, name), 1, 'i', g}

static const field fields[] = {
    D(fps, 1), I(frames), I(width), I(height), {"seed", offsetof(phantom_model, seed), 1, 'u', 0},
    D(size_u, 1), D(size_v, 1), D(dome_height, 1), D(dome_su, 1), D(dome_sv, 1), D(dome_u, 1),
    D(dome_v, 1), D(heart_hz, 1), D(heart_phase, 1), D(delay, 1), D(contraction, 1), D(twist, 1),
    D(twist_radius, 1), D(lift, 1), D(lift_u, 1), D(lift_v, 1), D(lift_sigma, 1), D(push, 1),
    D(push_u, 1), D(push_v, 1), D(push_sigma, 1), D(push_phase, 1), D(resp_hz, 1),
    D(resp_shift, 3), D(resp_tilt, 1), I(num_pads), D(pad_falloff, 1), D(pad_radius, 1),
    D(tag_size, 1), I(num_markers), I(num_cameras), I(shaft), D(shaft_p0, 3), D(shaft_p1, 3),
    D(shaft_dir, 3), D(shaft_length, 1), D(shaft_radius, 1), D(shaft_period, 1), I(num_blobs),
    I(decoy), I(decoy_id), D(decoy_center, 3), D(decoy_yaw, 1), D(noise, 1), D(exposure, 1),
    OI(cam_motion, 'c'), OD(cam_motion_t0, 1, 'c'), OD(cam_motion_dur, 1, 'c'),
    OD(cam_motion_shift, 3, 'c'), OI(first_beat, 'f'), OD(first_beat_at, 1, 'f'),
    OD(texture_contrast, 1, 't'), OI(texture_trilinear, 'm'), OD(blood_spread, 1, 'b'),
};
#define NFIELDS (sizeof fields / sizeof fields[0])

static int group_on(const phantom_model *m, char group)
{
    return group == 0 || (group == 'c' && m->cam_motion != 0) || (group == 'f' && m->first_beat != 0) ||
           (group == 't' && m->texture_contrast != 0) || (group == 'm' && m->texture_trilinear != 0) ||
           (group == 'b' && m->blood_spread != 0);
}

static void put_doubles(FILE *f, const double *d, int n)
{
    for (int i = 0; i < n; i++) fprintf(f, " %.17g", d[i]);
    fputc('\n', f);
}

sh_status phantom_model_write(const phantom_model *m, const char *path)
{
    FILE *f = fopen(path, "w");
    if (!f) return sh_error_set(SH_EIO, "%s: cannot create: %s", path, strerror(errno));
    fprintf(f, "%s\n# the analytic model of tools/phantom/phantom.h; see phantom_surface()\n", MAGIC);
    fprintf(f, "family %s\n", m->family);
    for (size_t k = 0; k < NFIELDS; k++) {
        const field *fd = &fields[k];
        if (!group_on(m, fd->group)) continue;
        const char *p = (const char *)m + fd->offset;
        fprintf(f, "%s", fd->key);
        if (fd->type == 'd') put_doubles(f, (const double *)(const void *)p, fd->count);
        else if (fd->type == 'i') fprintf(f, " %d\n", *(const int *)(const void *)p);
        else fprintf(f, " %llu\n", (unsigned long long)*(const uint64_t *)(const void *)p);
    }
    for (int i = 0; i < m->num_pads; i++) {
        fprintf(f, "pad %d", i);
        put_doubles(f, &m->pad[i].u0, 4);
    }
    for (int i = 0; i < m->num_markers; i++) {
        fprintf(f, "marker %d %d", i, m->marker[i].id);
        put_doubles(f, &m->marker[i].u, 2);
    }
    for (int i = 0; i < m->num_blobs; i++) {
        fprintf(f, "blob %d", i);
        put_doubles(f, &m->blob[i].u, 5);
    }
    for (int i = 0; i < m->num_cameras; i++) {
        const phantom_camera *c = &m->cam[i];
        double v[21] = {c->fx, c->fy, c->cx, c->cy};
        memcpy(v + 4, c->dist, sizeof c->dist);
        memcpy(v + 9, c->R, sizeof c->R);
        memcpy(v + 18, c->t, sizeof c->t);
        fprintf(f, "camera %d", i);
        put_doubles(f, v, 21);
    }
    if (ferror(f) | fclose(f)) return sh_error_set(SH_EIO, "%s: write failed", path);
    return SH_OK;
}

/* Reads exactly n numbers from s; anything else on the line is an error. */
static int get_doubles(const char *s, double *out, int n)
{
    for (int i = 0; i < n; i++) {
        char *end;
        errno = 0;
        out[i] = strtod(s, &end);
        if (end == s || errno == ERANGE || !isfinite(out[i])) return 0;
        s = end;
    }
    while (*s == ' ' || *s == '\t' || *s == '\r') s++;
    return *s == '\0';
}

static sh_status validate(const phantom_model *m, const char *name, unsigned seen_pad,
                          uint64_t seen_marker, unsigned seen_blob, unsigned seen_cam)
{
#define BAD(...) sh_error_set(SH_EFORMAT, __VA_ARGS__)
    if (!(m->fps > 0 && m->fps <= 1000) || m->frames < 0 || m->frames > 10000000)
        return BAD("%s: fps/frames out of range", name);
    if (m->width < 16 || m->height < 16 || m->width > 8192 || m->height > 8192)
        return BAD("%s: image size %dx%d out of range", name, m->width, m->height);
    if (!(m->size_u > 0 && m->size_v > 0 && m->dome_su > 0 && m->dome_sv > 0 && m->twist_radius > 0 &&
          m->lift_sigma > 0 && m->push_sigma > 0 && m->tag_size > 0))
        return BAD("%s: sizes and widths must be positive", name);
    if (m->num_pads < 0 || m->num_pads > PHANTOM_MAX_PADS || m->num_markers < 0 ||
        m->num_markers > PHANTOM_MAX_MARKERS || m->num_blobs < 0 || m->num_blobs > PHANTOM_MAX_BLOBS ||
        m->num_cameras < 1 || m->num_cameras > PHANTOM_MAX_CAMERAS)
        return BAD("%s: a count is out of range", name);
    if (m->num_pads > 0 && !(m->pad_falloff > 0 && m->pad_radius > 0))
        return BAD("%s: pad_falloff and pad_radius must be positive", name);
    if (m->shaft && !(m->shaft_period > 0 && m->shaft_radius > 0 && m->shaft_length > 0 &&
                      fabs(m->shaft_dir[0]) + fabs(m->shaft_dir[1]) + fabs(m->shaft_dir[2]) > 0))
        return BAD("%s: shaft needs a positive period, radius, length and a direction", name);
    if (seen_pad != (1u << m->num_pads) - 1 || seen_blob != (1u << m->num_blobs) - 1 ||
        seen_cam != (1u << m->num_cameras) - 1 ||
        seen_marker != (m->num_markers == 64 ? ~0ull : (1ull << m->num_markers) - 1))
        return BAD("%s: pad/marker/blob/camera lines do not match their counts", name);
    for (int i = 0; i < m->num_cameras; i++)
        if (!(m->cam[i].fx > 0 && m->cam[i].fy > 0)) return BAD("%s: camera %d focal <= 0", name, i);
    if (m->family[0] == '\0') return BAD("%s: no family line", name);
    if (m->cam_motion < 0 || m->cam_motion > 2) return BAD("%s: cam_motion %d: 0, 1 or 2", name, m->cam_motion);
    if (m->cam_motion == 1 && !(m->cam_motion_dur > 0))
        return BAD("%s: a pan (cam_motion 1) needs cam_motion_dur > 0", name);
    if (!(m->texture_contrast >= 0 && m->texture_contrast <= 16))
        return BAD("%s: texture_contrast out of range (0 to 16)", name);
    if (!(m->blood_spread >= 0 && m->blood_spread <= 60))
        return BAD("%s: blood_spread out of range (0 to 60 s)", name);
    if (m->first_beat < 0 || m->first_beat > 1) return BAD("%s: first_beat %d: 0 or 1", name, m->first_beat);
    if (m->texture_trilinear < 0 || m->texture_trilinear > 1)
        return BAD("%s: texture_trilinear %d: 0 or 1", name, m->texture_trilinear);
    /* the first beat's warp divides by the heart rate */
    if (m->first_beat && !(m->heart_hz > 0 && m->first_beat_at >= 0))
        return BAD("%s: first_beat needs heart_hz > 0 and first_beat_at >= 0", name);
    return SH_OK;
#undef BAD
}

/* Which indexed lines and fields a file has given, to refuse repeats and find missing ones. */
typedef struct {
    unsigned field[NFIELDS];
    unsigned pad, blob, cam;
    uint64_t marker;
} seen_set;

/* A "pad|marker|blob|camera INDEX values" line; *ok says whether the values are good. */
static sh_status parse_indexed(const char *key, const char *rest, const char *name, int lineno, phantom_model *m,
                               seen_set *seen, int *ok)
{
    int idx = -1, used = 0;
    if (sscanf(rest, " %d%n", &idx, &used) != 1 || idx < 0)
        return sh_error_set(SH_EFORMAT, "%s:%d: bad %s index", name, lineno, key);
    rest += used;
    if (key[0] == 'p' && idx < PHANTOM_MAX_PADS && !(seen->pad >> idx & 1)) {
        seen->pad |= 1u << idx;
        *ok = get_doubles(rest, &m->pad[idx].u0, 4);
    } else if (key[0] == 'm' && idx < PHANTOM_MAX_MARKERS && !(seen->marker >> idx & 1)) {
        seen->marker |= 1ull << idx;
        double v[3];
        *ok = get_doubles(rest, v, 3) && v[0] >= 0 && v[0] < 1e6 && v[0] == floor(v[0]);
        m->marker[idx].id = *ok ? (int)v[0] : 0;
        m->marker[idx].u = v[1];
        m->marker[idx].v = v[2];
    } else if (key[0] == 'b' && idx < PHANTOM_MAX_BLOBS && !(seen->blob >> idx & 1)) {
        seen->blob |= 1u << idx;
        *ok = get_doubles(rest, &m->blob[idx].u, 5);
    } else if (key[0] == 'c' && idx < PHANTOM_MAX_CAMERAS && !(seen->cam >> idx & 1)) {
        seen->cam |= 1u << idx;
        double v[21];
        *ok = get_doubles(rest, v, 21);
        phantom_camera *c = &m->cam[idx];
        c->fx = v[0];
        c->fy = v[1];
        c->cx = v[2];
        c->cy = v[3];
        memcpy(c->dist, v + 4, sizeof c->dist);
        memcpy(c->R, v + 9, sizeof c->R);
        memcpy(c->t, v + 18, sizeof c->t);
    } else {
        return sh_error_set(SH_EFORMAT, "%s:%d: %s %d out of range or repeated", name, lineno, key, idx);
    }
    return SH_OK;
}

/* A "key values" line of the fields table; *ok says whether the values are good. */
static sh_status parse_field(const char *key, const char *rest, const char *name, int lineno, phantom_model *m,
                             seen_set *seen, int *ok)
{
    size_t k = 0;
    while (k < NFIELDS && strcmp(fields[k].key, key) != 0) k++;
    if (k == NFIELDS) return sh_error_set(SH_EFORMAT, "%s:%d: unknown key '%s'", name, lineno, key);
    if (seen->field[k]++) return sh_error_set(SH_EFORMAT, "%s:%d: %s repeated", name, lineno, key);
    char *p = (char *)m + fields[k].offset;
    double v[3];
    *ok = get_doubles(rest, v, fields[k].count);
    if (*ok && fields[k].type == 'd') {
        memcpy(p, v, sizeof(double) * (size_t)fields[k].count);
    } else if (*ok && fields[k].type == 'i') {
        *ok = v[0] == floor(v[0]) && fabs(v[0]) < 1e9;
        *(int *)(void *)p = *ok ? (int)v[0] : 0;
    } else if (*ok) {
        /* the seed may exceed 2^53: read it as an integer, not through a double */
        char *end;
        errno = 0;
        unsigned long long s = strtoull(rest, &end, 10);
        while (*end == ' ' || *end == '\r') end++;
        *ok = errno == 0 && *end == '\0' && strchr(rest, '-') == NULL;
        *(uint64_t *)(void *)p = s;
    }
    return SH_OK;
}

sh_status phantom_model_parse(const char *text, size_t len, const char *name, phantom_model *m)
{
    memset(m, 0, sizeof *m);
    seen_set seen;
    memset(&seen, 0, sizeof seen);
    char line[1024];
    sh_lines it;
    sh_lines_init(&it, text, len, name);
    sh_status st;
    while ((st = sh_lines_next(&it, line, sizeof line)) == SH_OK) {
        int lineno = it.lineno;
        if (lineno == 1) {
            if (strncmp(line, MAGIC, strlen(MAGIC)) != 0)
                return sh_error_set(SH_EFORMAT, "%s:1: not a phantom file (want '%s')", name, MAGIC);
            continue;
        }
        if (line[0] == '#' || line[0] == '\0' || line[0] == '\r') continue;
        char key[32];
        int kl = 0;
        while (line[kl] && line[kl] != ' ' && kl < 31) {
            key[kl] = line[kl];
            kl++;
        }
        key[kl] = '\0';
        const char *rest = line + kl;
        int ok = 0, used = 0;
        sh_status lst = SH_OK;
        if (strcmp(key, "family") == 0) {
            ok = sscanf(rest, " %31s %n", m->family, &used) == 1 && rest[used] == '\0';
        } else if (!strcmp(key, "pad") || !strcmp(key, "marker") || !strcmp(key, "blob") ||
                   !strcmp(key, "camera")) {
            lst = parse_indexed(key, rest, name, lineno, m, &seen, &ok);
        } else {
            lst = parse_field(key, rest, name, lineno, m, &seen, &ok);
        }
        if (lst != SH_OK) return lst;
        if (!ok) return sh_error_set(SH_EFORMAT, "%s:%d: bad values for '%s'", name, lineno, key);
    }
    if (st != SH_EEOF) return st;
    if (it.lineno == 0) return sh_error_set(SH_EFORMAT, "%s: empty", name);
    for (size_t k = 0; k < NFIELDS; k++)
        if (!seen.field[k] && group_on(m, fields[k].group))
            return sh_error_set(SH_EFORMAT, "%s: missing '%s'", name, fields[k].key);
    return validate(m, name, seen.pad, seen.marker, seen.blob, seen.cam);
}

sh_status phantom_model_read(const char *path, phantom_model *m)
{
    FILE *f = fopen(path, "rb");
    if (!f) return sh_error_set(SH_EIO, "%s: cannot open: %s", path, strerror(errno));
    char *buf = NULL;
    size_t len = 0, cap = 0;
    for (;;) {
        if (len == cap) {
            cap = cap ? 2 * cap : 16384;
            if (cap > (64u << 20)) {
                free(buf);
                fclose(f);
                return sh_error_set(SH_EFORMAT, "%s: too large for a phantom file", path);
            }
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
    if (err) {
        free(buf);
        return sh_error_set(SH_EIO, "%s: read error", path);
    }
    sh_status st = phantom_model_parse(buf, len, path, m);
    free(buf);
    return st;
}
