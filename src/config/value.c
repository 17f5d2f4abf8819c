/* The kinds of value a config key has (config.c's table): text to value, with the reason for a
 * refusal, and value to text, as --print-config and the reload's log write it. */
#include "config_internal.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>

#include "stillheart/pixconv.h"

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

static int parse_str(sh_config *cfg, const keydef *k, const char *value, char *why)
{
    if (strlen(value) >= k->size) {
        snprintf(why, WHY, "value longer than %zu characters", k->size - 1);
        return 0;
    }
    snprintf((char *)cfg + k->offset, k->size, "%s", value);
    return 1;
}

static int parse_bool(sh_config *cfg, const keydef *k, const char *value, char *why)
{
    static const char *const yes[] = {"1", "yes", "true", "on"}, *const no[] = {"0", "no", "false", "off"};
    for (int i = 0; i < 4; i++)
        if (!strcasecmp(value, yes[i]) || !strcasecmp(value, no[i])) {
            *(int *)((char *)cfg + k->offset) = !strcasecmp(value, yes[i]);
            return 1;
        }
    snprintf(why, WHY, "'%s' is not yes/no/1/0/true/false/on/off", value);
    return 0;
}

/* A whole number in k's range; what says what else the key takes, for the reason. */
static int whole(const keydef *k, const char *value, const char *what, long *v, char *why)
{
    char *end;
    errno = 0;
    *v = strtol(value, &end, 10);
    if (end != value && !*end && !errno && *v >= k->min && *v <= k->max)
        return 1;
    snprintf(why, WHY, "'%s' is not %sa whole number in %.0f..%.0f", value, what, k->min, k->max);
    return 0;
}

static int parse_int(sh_config *cfg, const keydef *k, const char *value, char *why)
{
    long v;
    if (!whole(k, value, "", &v, why))
        return 0;
    *(int *)((char *)cfg + k->offset) = (int)v;
    return 1;
}

static int parse_double(sh_config *cfg, const keydef *k, const char *value, char *why)
{
    char *end;
    errno = 0;
    double v = strtod(value, &end);
    if (end == value || *end || errno || !isfinite(v) || v < k->min || v > k->max) {
        snprintf(why, WHY, "'%s' is not a number in %g..%g", value, k->min, k->max);
        return 0;
    }
    *(double *)((char *)cfg + k->offset) = v;
    return 1;
}

static int parse_method(sh_config *cfg, const keydef *k, const char *value, char *why)
{
    sh_interp_params p;
    if (strlen(value) >= k->size || sh_interp_params_parse(value, &p) != SH_OK) {
        snprintf(why, WHY, "unknown method '%s' (affine, pwlinear, bspline, rbf-local, tps, gaussian, "
                 "or -pure variants)", value);
        return 0;
    }
    snprintf(cfg->method_name, sizeof cfg->method_name, "%s", value);
    return 1;
}

static int parse_ids_key(sh_config *cfg, const keydef *k, const char *value, char *why)
{
    uint8_t ids[SH_CONFIG_MAX_IDS];
    if (strlen(value) >= k->size || !parse_ids(value, ids)) {
        snprintf(why, WHY, "'%s' is not a list of ids in 0..%d (e.g. 0-15 or 1,3,5-9)", value, SH_CONFIG_MAX_IDS - 1);
        return 0;
    }
    memcpy(cfg->ids, ids, sizeof ids);
    snprintf(cfg->ids_text, sizeof cfg->ids_text, "%s", value);
    return 1;
}

static int parse_spec(sh_config *cfg, const keydef *k, const char *value, char *why)
{
    static const char *const kinds[] = {"v4l2:", "libcamera:", "y4m:", "rec:"};
    int ok = !*value;
    for (int i = 0; i < 4 && !ok; i++)
        ok = !strncmp(value, kinds[i], strlen(kinds[i])) && value[strlen(kinds[i])];
    if (!ok) {
        snprintf(why, WHY, "'%s' is not v4l2:/dev/videoN, libcamera:NAME, y4m:FILE or rec:DIR", value);
        return 0;
    }
    return parse_str(cfg, k, value, why);
}

static int parse_rawfmt(sh_config *cfg, const keydef *k, const char *value, char *why)
{
    sh_rawfmt f;
    int any = !*value || !strcasecmp(value, "auto");
    if (!any && (strlen(value) >= k->size || sh_rawfmt_parse(value, &f) != SH_OK)) {
        snprintf(why, WHY, "unknown pixel format '%s' (yuyv, nv12, grey, rgb24, bgr24, mjpeg, i420, or auto)", value);
        return 0;
    }
    snprintf((char *)cfg + k->offset, k->size, "%s", any ? "" : value);
    return 1;
}

static int parse_size(sh_config *cfg, const keydef *k, const char *value, char *why)
{
    int *wh = (int *)((char *)cfg + k->offset), w = 0, h = 0;
    if (*value && strcasecmp(value, "auto")) {
        char *end;
        long a, b = 0;
        errno = 0;
        a = strtol(value, &end, 10);
        int ok = end != value && (*end == 'x' || *end == 'X') && !errno;
        if (ok) {
            const char *p = end + 1;
            b = strtol(p, &end, 10);
            ok = end != p && !*end && !errno && a >= k->min && a <= k->max && b >= k->min && b <= k->max;
        }
        if (!ok) {
            snprintf(why, WHY, "'%s' is not WIDTHxHEIGHT (%.0f..%.0f each, e.g. 1920x1080) or auto", value, k->min,
                     k->max);
            return 0;
        }
        w = (int)a;
        h = (int)b;
    }
    wh[0] = w;
    wh[1] = h;
    return 1;
}

static int parse_fps(sh_config *cfg, const keydef *k, const char *value, char *why)
{
    int *nd = (int *)((char *)cfg + k->offset);
    long num = 0, den = 0;
    if (*value && strcasecmp(value, "auto")) {
        char *end;
        errno = 0;
        double v = strtod(value, &end);
        int ok = end != value && !errno && isfinite(v);
        if (ok && *end == '/') { /* an exact ratio: 30000/1001 */
            const char *p = end + 1;
            double d = strtod(p, &end);
            ok = end != p && !*end && v == floor(v) && d == floor(d) && d >= 1 && d <= 1e6 && v >= 1 && v <= 1e9 &&
                 v / d <= k->max;
            num = ok ? (long)v : 0;
            den = ok ? (long)d : 0;
        } else if (ok) { /* decimal: kept to a thousandth */
            ok = !*end && v > 0 && v <= k->max;
            num = ok ? lround(v * 1000) : 0;
            den = 1000;
            while (ok && num % 10 == 0 && den > 1)
                num /= 10, den /= 10;
        }
        if (!ok || num <= 0) {
            snprintf(why, WHY, "'%s' is not a frame rate (30, 29.97, 30000/1001 up to %.0f; or auto)", value, k->max);
            return 0;
        }
    }
    nd[0] = (int)num;
    nd[1] = (int)den;
    return 1;
}

static int parse_ctrl(sh_config *cfg, const keydef *k, const char *value, char *why)
{
    long v = SH_CONFIG_CTRL_UNSET;
    if (*value && strcasecmp(value, "auto") && !whole(k, value, "auto or ", &v, why))
        return 0;
    *(int32_t *)((char *)cfg + k->offset) = (int32_t)v;
    return 1;
}

static int parse_enum(sh_config *cfg, const keydef *k, const char *value, char *why)
{
    int idx = 0;
    for (const char *c = k->choices; *c; idx++) {
        size_t n = strcspn(c, "|");
        if (strlen(value) == n && !strncasecmp(value, c, n)) {
            *(int *)((char *)cfg + k->offset) = idx;
            return 1;
        }
        c += n + (c[n] == '|');
    }
    snprintf(why, WHY, "'%s' is not one of %s", value, k->choices);
    return 0;
}

/* Indexed by ktype. */
static int (*const parsers[])(sh_config *, const keydef *, const char *, char *) = {
    [K_STR] = parse_str,       [K_BOOL] = parse_bool,     [K_INT] = parse_int,   [K_DOUBLE] = parse_double,
    [K_METHOD] = parse_method, [K_IDS] = parse_ids_key,   [K_SPEC] = parse_spec, [K_RAWFMT] = parse_rawfmt,
    [K_SIZE] = parse_size,     [K_FPS] = parse_fps,       [K_CTRL] = parse_ctrl, [K_ENUM] = parse_enum,
};

void sh_config_format_value(const sh_config *cfg, const keydef *k, int exact, char *out, size_t cap)
{
    const char *v = (const char *)cfg + k->offset;
    switch (k->type) {
    case K_STR:
    case K_METHOD:
    case K_IDS:
    case K_SPEC:
        snprintf(out, cap, "%s", v);
        return;
    case K_RAWFMT:
        snprintf(out, cap, "%s", v[0] ? v : "auto");
        return;
    case K_BOOL:
        snprintf(out, cap, "%s", *(const int *)v ? "yes" : "no");
        return;
    case K_INT:
        snprintf(out, cap, "%d", *(const int *)v);
        return;
    case K_DOUBLE:
        snprintf(out, cap, exact ? "%.17g" : "%g", *(const double *)v);
        return;
    case K_SIZE:
    case K_FPS: {
        const int *p = (const int *)v;
        if (p[0]) snprintf(out, cap, "%d%s%d", p[0], k->type == K_SIZE ? "x" : "/", p[1]);
        else snprintf(out, cap, "auto");
        return;
    }
    case K_CTRL: {
        int32_t c = *(const int32_t *)v;
        if (c == SH_CONFIG_CTRL_UNSET) snprintf(out, cap, "auto");
        else snprintf(out, cap, "%d", (int)c);
        return;
    }
    case K_ENUM: {
        const char *c = k->choices;
        for (int idx = *(const int *)v; idx > 0 && strchr(c, '|'); idx--)
            c = strchr(c, '|') + 1;
        snprintf(out, cap, "%.*s", (int)strcspn(c, "|"), c);
        return;
    }
    }
}

int sh_config_parse_value(sh_config *cfg, const keydef *k, const char *value, char *why)
{
    return parsers[k->type](cfg, k, value, why);
}
