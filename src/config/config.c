/* The daemon's INI configuration (inih when found, else a small built-in line parser with the
 * same rules), the command-line names of its keys, and the checks. */
#include "stillheart/config.h"

#include <errno.h>
#include <math.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>

#ifdef SH_HAVE_INIH
#include <ini.h>
#endif

typedef enum { K_STR, K_BOOL, K_INT, K_DOUBLE, K_METHOD, K_IDS } ktype;

typedef struct {
    const char *section, *key, *option;
    ktype type;
    size_t offset, size; /* K_STR: buffer size */
    double min, max;
    const char *help;
} keydef;

#define F(m) offsetof(sh_config, m)
#define S(m) sizeof(((sh_config *)0)->m)
static const keydef keys[] = {
    {"source", "spec", "source", K_STR, F(source), S(source), 0, 0, "y4m:FILE | v4l2:/dev/videoN | ... (capture spec)"},
    {"source", "realtime", "realtime", K_BOOL, F(realtime), 0, 0, 1, "replay at the stream's frame rate (0: as fast as possible)"},
    {"source", "loop", "loop", K_BOOL, F(loop), 0, 0, 1, "replay: start over at the end"},
    {"detect", "family", "family", K_STR, F(family), S(family), 0, 0, "AprilTag family (tag36h11, ...)"},
    {"detect", "ids", "ids", K_IDS, F(ids_text), S(ids_text), 0, 0, "marker ids: 0-15 or 1,3,5-9"},
    {"method", "name", "method", K_METHOD, F(method_name), S(method_name), 0, 0, "affine pwlinear bspline rbf-local[-pure] tps[-pure] gaussian[-pure]"},
    {"method", "sigma", "sigma", K_DOUBLE, F(sigma), 0, -1, 1e6, "RBF scale in px (-1: the method's default)"},
    {"method", "levels", "levels", K_INT, F(levels), 0, 0, 16, "B-spline levels (0: automatic)"},
    {"method", "smoothing", "smoothing", K_DOUBLE, F(smoothing), 0, 0, 1e9, "RBF smoothing lambda (0: interpolate)"},
    {"method", "grid", "grid", K_DOUBLE, F(grid), 0, 0, 256, "warp grid spacing in px (0: from the error bound)"},
    {"reference", "frame", "reference", K_INT, F(reference_frame), 0, 0, 1e9, "0: first good frame; N: the N-th frame"},
    {"gating", "min_markers", "min-markers", K_INT, F(min_markers), 0, 1, SH_CONFIG_MAX_IDS, "fewer markers -> raw"},
    {"gating", "max_residual_px", "max-residual", K_DOUBLE, F(max_residual_px), 0, 0, 1e4, "residual over this -> raw"},
    {"gating", "max_sigma_px", "max-sigma", K_DOUBLE, F(max_sigma_px), 0, 0, 1e4, "position uncertainty (1 sigma) over this -> raw"},
    {"gating", "dropout_ms", "dropout-ms", K_INT, F(dropout_ms), 0, 0, 60000, "stale estimates up to this -> degraded, longer -> raw"},
    {"run", "threads", "threads", K_INT, F(threads), 0, 1, 64, "warp threads"},
    {"run", "control", "control", K_STR, F(control), S(control), 0, 0, "control socket path (\"\": none)"},
    {"run", "points", "points", K_STR, F(points), S(points), 0, 0, "test mode: markers from a points file instead of detection"},
    {"sink", "display", "sink", K_STR, F(sink), S(sink), 0, 0, "shm:NAME | none"},
    {"sink", "slots", "slots", K_INT, F(slots), 0, 3, 16, "frame slots of the segment"},
    {"sink", "group", "group", K_STR, F(group), S(group), 0, 0, "owner group of the segment (\"\": the process's)"},
    {"sink", "record", "record", K_STR, F(record), S(record), 0, 0, "also write what is shown: FILE.y4m or png:DIR (\"\": no)"},
    {"sink", "watchdog", "watchdog", K_BOOL, F(watchdog), 0, 0, 1, "send WATCHDOG=1 when systemd asks"},
};
#define NKEYS ((int)(sizeof keys / sizeof keys[0]))

void sh_config_default(sh_config *cfg)
{
    memset(cfg, 0, sizeof *cfg);
    snprintf(cfg->source, sizeof cfg->source, "y4m:out/run-demo/cam0.y4m");
    cfg->realtime = 1;
    cfg->loop = 1;
    snprintf(cfg->family, sizeof cfg->family, "tag36h11");
    snprintf(cfg->ids_text, sizeof cfg->ids_text, "0-15");
    for (int i = 0; i < 16; i++)
        cfg->ids[i] = 1;
    snprintf(cfg->method_name, sizeof cfg->method_name, "tps");
    sh_interp_params_parse("tps", &cfg->method);
    cfg->sigma = -1;
    cfg->levels = 0;
    cfg->smoothing = 0;
    cfg->grid = 0;
    cfg->reference_frame = 0;
    cfg->min_markers = 6;
    cfg->max_residual_px = 3.0;
    cfg->max_sigma_px = 4.0;
    cfg->dropout_ms = 200;
    cfg->threads = 2;
    snprintf(cfg->sink, sizeof cfg->sink, "shm:/stillheart");
    cfg->slots = 4;
    snprintf(cfg->group, sizeof cfg->group, "video");
    cfg->watchdog = 1;
}

static sh_status fail(char *err, const char *origin, int line, const char *section, const char *key,
                      const char *fmt, const char *value)
{
    char why[256];
    snprintf(why, sizeof why, fmt, value);
    if (line > 0)
        snprintf(err, SH_CONFIG_ERR, "%s:%d: [%s] %s: %s", origin, line, section, key, why);
    else
        snprintf(err, SH_CONFIG_ERR, "%s: [%s] %s: %s", origin, section, key, why);
    return SH_EINVAL;
}

static int parse_ids(const char *text, uint8_t *ids)
{
    memset(ids, 0, SH_CONFIG_MAX_IDS);
    const char *p = text;
    int any = 0;
    while (*p) {
        while (*p == ' ' || *p == '\t')
            p++;
        char *end;
        errno = 0;
        long a = strtol(p, &end, 10);
        if (end == p || errno || a < 0 || a >= SH_CONFIG_MAX_IDS)
            return 0;
        long b = a;
        p = end;
        if (*p == '-') {
            p++;
            b = strtol(p, &end, 10);
            if (end == p || errno || b < a || b >= SH_CONFIG_MAX_IDS)
                return 0;
            p = end;
        }
        for (long i = a; i <= b; i++)
            ids[i] = 1;
        any = 1;
        while (*p == ' ' || *p == '\t')
            p++;
        if (*p == ',')
            p++;
        else if (*p)
            return 0;
    }
    return any;
}

static void apply_method(sh_config *cfg)
{
    sh_interp_params_parse(cfg->method_name, &cfg->method);
    if (cfg->sigma >= 0)
        cfg->method.sigma = cfg->sigma;
    cfg->method.levels = cfg->levels;
    cfg->method.smoothing = cfg->smoothing;
}

sh_status sh_config_set(sh_config *cfg, const char *section, const char *key, const char *value,
                        const char *origin, int line, char *err)
{
    const keydef *k = NULL;
    int section_known = 0;
    for (int i = 0; i < NKEYS; i++) {
        if (strcmp(keys[i].section, section) == 0) {
            section_known = 1;
            if (strcmp(keys[i].key, key) == 0) {
                k = &keys[i];
                break;
            }
        }
    }
    if (!section_known)
        return fail(err, origin, line, section, key, "unknown section [%s]", section);
    if (!k)
        return fail(err, origin, line, section, key, "unknown key%s", "");
    char *base = (char *)cfg;
    char *end;
    switch (k->type) {
    case K_STR:
        if (strlen(value) >= k->size)
            return fail(err, origin, line, section, key, "value longer than %s characters",
                        k->size >= 256 ? "255" : k->size >= 64 ? "63" : "31");
        snprintf(base + k->offset, k->size, "%s", value);
        return SH_OK;
    case K_BOOL: {
        int v;
        if (!strcasecmp(value, "1") || !strcasecmp(value, "yes") || !strcasecmp(value, "true") ||
            !strcasecmp(value, "on"))
            v = 1;
        else if (!strcasecmp(value, "0") || !strcasecmp(value, "no") || !strcasecmp(value, "false") ||
                 !strcasecmp(value, "off"))
            v = 0;
        else
            return fail(err, origin, line, section, key, "'%s' is not yes/no/1/0/true/false/on/off", value);
        *(int *)(base + k->offset) = v;
        return SH_OK;
    }
    case K_INT: {
        errno = 0;
        long v = strtol(value, &end, 10);
        if (end == value || *end || errno || v < k->min || v > k->max) {
            char msg[128];
            snprintf(msg, sizeof msg, "'%%s' is not a whole number in %.0f..%.0f", k->min, k->max);
            return fail(err, origin, line, section, key, msg, value);
        }
        *(int *)(base + k->offset) = (int)v;
        apply_method(cfg);
        return SH_OK;
    }
    case K_DOUBLE: {
        errno = 0;
        double v = strtod(value, &end);
        if (end == value || *end || errno || !isfinite(v) || v < k->min || v > k->max) {
            char msg[128];
            snprintf(msg, sizeof msg, "'%%s' is not a number in %g..%g", k->min, k->max);
            return fail(err, origin, line, section, key, msg, value);
        }
        *(double *)(base + k->offset) = v;
        apply_method(cfg);
        return SH_OK;
    }
    case K_METHOD: {
        sh_interp_params p;
        if (strlen(value) >= k->size || sh_interp_params_parse(value, &p) != SH_OK)
            return fail(err, origin, line, section, key,
                        "unknown method '%s' (affine, pwlinear, bspline, rbf-local, tps, gaussian, "
                        "or -pure variants)", value);
        snprintf(cfg->method_name, sizeof cfg->method_name, "%s", value);
        apply_method(cfg);
        return SH_OK;
    }
    case K_IDS: {
        uint8_t ids[SH_CONFIG_MAX_IDS];
        if (strlen(value) >= k->size || !parse_ids(value, ids))
            return fail(err, origin, line, section, key,
                        "'%s' is not a list of ids in 0..1023 (e.g. 0-15 or 1,3,5-9)", value);
        memcpy(cfg->ids, ids, sizeof ids);
        snprintf(cfg->ids_text, sizeof cfg->ids_text, "%s", value);
        return SH_OK;
    }
    }
    return SH_EINVAL;
}

typedef struct {
    sh_config *cfg;
    const char *origin;
    char *err;
    int failed;
} parse_ctx;

#ifdef SH_HAVE_INIH
/* Debian's inih calls the handler without a line number; a handler returning 0 makes
 * ini_parse_string return that line, which names it in the message afterwards. */
static int on_key(void *user, const char *section, const char *name, const char *value)
{
    parse_ctx *c = user;
    if (c->failed)
        return 1; /* keep the first error's line as the one returned */
    if (sh_config_set(c->cfg, section, name, value, "", 0, c->err) != SH_OK) {
        c->failed = 1;
        return 0;
    }
    return 1;
}
#endif

sh_status sh_config_parse_string(sh_config *cfg, const char *text, const char *origin, char *err)
{
    sh_config work = *cfg; /* all or nothing */
    parse_ctx c = {&work, origin, err, 0};
    err[0] = 0;
#ifdef SH_HAVE_INIH
    int r = ini_parse_string(text, on_key, &c);
    if (c.failed) {
        char why[SH_CONFIG_ERR];
        snprintf(why, sizeof why, "%s", err + 2); /* past the empty origin's ": " */
        snprintf(err, SH_CONFIG_ERR, "%.200s:%d: %.300s", origin, r, why);
        return SH_EINVAL;
    }
    if (r != 0) {
        snprintf(err, SH_CONFIG_ERR, "%s:%d: not an INI line (want [section] or key = value)",
                 origin, r > 0 ? r : 0);
        return SH_EFORMAT;
    }
#else
    /* The same rules as inih's defaults: [section], key = value or key : value, ; and # comments. */
    char section[64] = "";
    int lineno = 0;
    const char *p = text;
    while (*p) {
        char line[1024];
        size_t n = strcspn(p, "\n");
        lineno++;
        if (n >= sizeof line) {
            snprintf(err, SH_CONFIG_ERR, "%s:%d: line too long", origin, lineno);
            return SH_EFORMAT;
        }
        memcpy(line, p, n);
        line[n] = 0;
        p += n + (p[n] == '\n');
        char *s = line;
        while (*s == ' ' || *s == '\t' || *s == '\r')
            s++;
        char *e = s + strlen(s);
        while (e > s && (e[-1] == ' ' || e[-1] == '\t' || e[-1] == '\r'))
            *--e = 0;
        if (!*s || *s == ';' || *s == '#')
            continue;
        if (*s == '[') {
            char *close = strchr(s, ']');
            if (!close || close - s - 1 >= (long)sizeof section) {
                snprintf(err, SH_CONFIG_ERR, "%s:%d: not an INI line (want [section] or key = value)", origin, lineno);
                return SH_EFORMAT;
            }
            *close = 0;
            snprintf(section, sizeof section, "%s", s + 1);
            continue;
        }
        char *eq = strpbrk(s, "=:");
        if (!eq) {
            snprintf(err, SH_CONFIG_ERR, "%s:%d: not an INI line (want [section] or key = value)", origin, lineno);
            return SH_EFORMAT;
        }
        *eq = 0;
        char *k = s, *v = eq + 1;
        char *ke = eq;
        while (ke > k && (ke[-1] == ' ' || ke[-1] == '\t'))
            *--ke = 0;
        while (*v == ' ' || *v == '\t')
            v++;
        char *c2 = strstr(v, " ;");
        if (c2) {
            *c2 = 0;
            char *ve = c2;
            while (ve > v && (ve[-1] == ' ' || ve[-1] == '\t'))
                *--ve = 0;
        }
        if (sh_config_set(&work, section, k, v, origin, lineno, err) != SH_OK)
            return SH_EINVAL;
    }
#endif
    *cfg = work;
    return SH_OK;
}

sh_status sh_config_load_file(sh_config *cfg, const char *path, char *err)
{
    FILE *f = fopen(path, "rb");
    if (!f) {
        snprintf(err, SH_CONFIG_ERR, "%s: cannot open: %s", path, strerror(errno));
        return SH_EIO;
    }
    char *text = NULL;
    size_t len = 0, cap = 0;
    for (;;) {
        if (len + 4097 > cap) {
            cap = cap ? cap * 2 : 8192;
            if (cap > (1u << 20)) {
                free(text);
                fclose(f);
                snprintf(err, SH_CONFIG_ERR, "%s: larger than 1 MiB", path);
                return SH_EFORMAT;
            }
            char *t = realloc(text, cap);
            if (!t) {
                free(text);
                fclose(f);
                snprintf(err, SH_CONFIG_ERR, "%s: out of memory", path);
                return SH_ENOMEM;
            }
            text = t;
        }
        size_t got = fread(text + len, 1, 4096, f);
        len += got;
        if (got < 4096)
            break;
    }
    int bad = ferror(f);
    fclose(f);
    if (bad) {
        free(text);
        snprintf(err, SH_CONFIG_ERR, "%s: read error", path);
        return SH_EIO;
    }
    text[len] = 0;
    if (strlen(text) != len) {
        free(text);
        snprintf(err, SH_CONFIG_ERR, "%s: contains a NUL byte", path);
        return SH_EFORMAT;
    }
    sh_status st = sh_config_parse_string(cfg, text, path, err);
    free(text);
    return st;
}

int sh_config_option(const char *name, const char **section, const char **key, int *is_flag)
{
    for (int i = 0; i < NKEYS; i++)
        if (strcmp(keys[i].option, name) == 0) {
            *section = keys[i].section;
            *key = keys[i].key;
            *is_flag = keys[i].type == K_BOOL;
            return 1;
        }
    return 0;
}

static int method_min_markers(sh_method m)
{
    switch (m) {
    case SH_METHOD_AFFINE:
    case SH_METHOD_PWLINEAR:
        return 3;
    default:
        return 3;
    }
}

sh_status sh_config_check(const sh_config *cfg, char *err)
{
    if (!cfg->source[0]) {
        snprintf(err, SH_CONFIG_ERR, "[source] spec: empty");
        return SH_EINVAL;
    }
    if (strncmp(cfg->sink, "shm:", 4) != 0 && strcmp(cfg->sink, "none") != 0) {
        snprintf(err, SH_CONFIG_ERR, "[sink] display: '%s' is neither shm:NAME nor none", cfg->sink);
        return SH_EINVAL;
    }
    if (!strncmp(cfg->sink, "shm:", 4) && (!cfg->sink[4] || strchr(cfg->sink + 5, '/'))) {
        snprintf(err, SH_CONFIG_ERR, "[sink] display: '%s': want shm:NAME or shm:/NAME, one component",
                 cfg->sink);
        return SH_EINVAL;
    }
    int need = method_min_markers(cfg->method.method);
    if (cfg->min_markers < need) {
        snprintf(err, SH_CONFIG_ERR, "[gating] min_markers: %d is fewer than %s needs (%d)", cfg->min_markers,
                 cfg->method_name, need);
        return SH_EINVAL;
    }
    int nids = 0;
    for (int i = 0; i < SH_CONFIG_MAX_IDS; i++)
        nids += cfg->ids[i];
    if (!cfg->points[0] && nids < cfg->min_markers) {
        snprintf(err, SH_CONFIG_ERR, "[detect] ids: %d ids, fewer than [gating] min_markers = %d", nids,
                 cfg->min_markers);
        return SH_EINVAL;
    }
    if (!cfg->points[0] && nids > 64) { /* SH_TRACK_MAX_MARKERS */
        snprintf(err, SH_CONFIG_ERR, "[detect] ids: %d ids, the tracker follows at most 64", nids);
        return SH_EINVAL;
    }
    if (cfg->record[0]) {
        size_t n = strlen(cfg->record);
        int png = !strncmp(cfg->record, "png:", 4);
        if (png ? n == 4 : (n < 4 || strcmp(cfg->record + n - 4, ".y4m") != 0)) {
            snprintf(err, SH_CONFIG_ERR, "[sink] record: '%s': want FILE.y4m or png:DIR", cfg->record);
            return SH_EINVAL;
        }
    }
    if (cfg->control[0] && strlen(cfg->control) >= 108) { /* sizeof sockaddr_un.sun_path */
        snprintf(err, SH_CONFIG_ERR, "[run] control: '%s': a socket path has at most 107 bytes", cfg->control);
        return SH_EINVAL;
    }
    return SH_OK;
}

void sh_config_write(const sh_config *cfg, FILE *out)
{
    const char *last = "";
    const char *base = (const char *)cfg;
    for (int i = 0; i < NKEYS; i++) {
        const keydef *k = &keys[i];
        if (strcmp(last, k->section)) {
            fprintf(out, "%s[%s]\n", i ? "\n" : "", k->section);
            last = k->section;
        }
        fprintf(out, "%s = ", k->key);
        switch (k->type) {
        case K_STR:
        case K_METHOD:
        case K_IDS:
            fprintf(out, "%s\n", base + k->offset);
            break;
        case K_BOOL:
            fprintf(out, "%s\n", *(const int *)(base + k->offset) ? "yes" : "no");
            break;
        case K_INT:
            fprintf(out, "%d\n", *(const int *)(base + k->offset));
            break;
        case K_DOUBLE:
            fprintf(out, "%.17g\n", *(const double *)(base + k->offset));
            break;
        }
    }
}

void sh_config_usage(FILE *out)
{
    for (int i = 0; i < NKEYS; i++)
        fprintf(out, "  --%-14s %s  [%s] %s: %s\n", keys[i].option, keys[i].type == K_BOOL ? "0|1" : "V  ",
                keys[i].section, keys[i].key, keys[i].help);
}
