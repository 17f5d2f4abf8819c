/* The daemon's configuration keys: their table, values from text, the command-line names, the
 * checks across keys and writing back. Reading INI text and files is in ini.c. */
#include "stillheart/config.h"
#include "stillheart/pixconv.h"

#include <errno.h>
#include <math.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>

typedef enum { K_STR, K_BOOL, K_INT, K_DOUBLE, K_METHOD, K_IDS, K_SPEC, K_RAWFMT, K_SIZE, K_FPS, K_CTRL, K_ENUM } ktype;

typedef struct {
    const char *section, *key, *option;
    ktype type;
    size_t offset, size; /* K_STR: buffer size */
    double min, max;
    const char *help;
    const char *choices; /* K_ENUM: the names of 0, 1, ... separated by '|' */
    int cam;             /* per-camera keys: camera index + 1 */
    int alias;           /* another name of a key listed too: not written back */
} keydef;

#define F(m) offsetof(sh_config, m)
#define S(m) sizeof(((sh_config *)0)->m)
#define CAMERA_KEYS(i)                                                                                      \
    {"camera" #i, "spec", "camera" #i "-spec", K_SPEC, F(camera[i].spec), S(camera[i].spec), 0, 0,           \
     "v4l2:/dev/videoN | libcamera:NAME | y4m:FILE | rec:DIR (\"\": no camera)", NULL, i + 1, 0},             \
    {"camera" #i, "format", "camera" #i "-format", K_RAWFMT, F(camera[i].format), S(camera[i].format), 0, 0,   \
     "yuyv nv12 grey rgb24 bgr24 mjpeg (auto: the device's)", NULL, i + 1, 0},                                \
    {"camera" #i, "size", "camera" #i "-size", K_SIZE, F(camera[i].width), 0, 1, 16384,                       \
     "WIDTHxHEIGHT (auto: the device's)", NULL, i + 1, 0},                                                    \
    {"camera" #i, "fps", "camera" #i "-fps", K_FPS, F(camera[i].fps_num), 0, 0, 1000,                         \
     "frames per second, 30 or 30000/1001 (auto: the device's)", NULL, i + 1, 0},                             \
    {"camera" #i, "exposure", "camera" #i "-exposure", K_CTRL, F(camera[i].exposure), 0, 1, 10000000,         \
     "manual exposure in 100 us units (auto: the camera's)", NULL, i + 1, 0},                                 \
    {"camera" #i, "gain", "camera" #i "-gain", K_CTRL, F(camera[i].gain), 0, 0, 1000000,                      \
     "gain, the driver's units (auto: the camera's)", NULL, i + 1, 0},                                        \
    {"camera" #i, "white_balance", "camera" #i "-white-balance", K_CTRL, F(camera[i].white_balance), 0, 1000, \
     20000, "manual white balance in K (auto: the camera's)", NULL, i + 1, 0}
/* Most rows leave choices, cam and alias out (zero): the table reads better without them. */
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmissing-field-initializers"
static const keydef keys[] = {
    {"source", "spec", "source", K_SPEC, F(source), S(source), 0, 0, "camera 0's spec ([camera0] spec)", NULL, 1, 1},
    {"source", "realtime", "realtime", K_BOOL, F(realtime), 0, 0, 1, "replay at the stream's frame rate (0: as fast as possible)"},
    {"source", "loop", "loop", K_BOOL, F(loop), 0, 0, 1, "replay: start over at the end"},
    {"source", "output", "output-camera", K_INT, F(output_camera), 0, 0, SH_CONFIG_MAX_CAMERAS - 1, "the camera whose frames are warped and shown"},
    {"source", "sync_tolerance_ms", "sync-tolerance-ms", K_DOUBLE, F(sync_tolerance_ms), 0, 0, 1000, "frames this close form a set (0: a quarter frame period)"},
    {"source", "sync_wait_ms", "sync-wait-ms", K_DOUBLE, F(sync_wait_ms), 0, 0, 10000, "a set waits this long for a missing frame (0: two frame periods)"},
    {"source", "camera_timeout_ms", "camera-timeout-ms", K_INT, F(camera_timeout_ms), 0, 10, 60000, "no frame for this long: the camera is reopened"},
    CAMERA_KEYS(0),
    CAMERA_KEYS(1),
    CAMERA_KEYS(2),
    CAMERA_KEYS(3),
    {"trigger", "mode", "trigger", K_ENUM, F(trigger), 0, 0, 0, "off | out (drive the line) | in (timestamp its edges)", "off|out|in"},
    {"trigger", "chip", "trigger-chip", K_STR, F(trigger_chip), S(trigger_chip), 0, 0, "GPIO chip: gpiochip0, /dev/gpiochip0, a label or a number"},
    {"trigger", "line", "trigger-line", K_INT, F(trigger_line), 0, 0, 1023, "line offset on the chip"},
    {"trigger", "polarity", "trigger-polarity", K_ENUM, F(trigger_active_low), 0, 0, 0, "high | low (active edge falling)", "high|low"},
    {"trigger", "fps", "trigger-fps", K_DOUBLE, F(trigger_fps), 0, 0, 1000, "out: pulses per second (0: camera 0's frame rate)"},
    {"trigger", "pulse_us", "trigger-pulse-us", K_INT, F(trigger_pulse_us), 0, 1, 1000000, "out: pulse width in us"},
    {"trigger", "offset_us", "trigger-offset-us", K_INT, F(trigger_offset_us), 0, -1000000, 1000000, "frame timestamp minus trigger edge, expected"},
    {"detect", "family", "family", K_STR, F(family), S(family), 0, 0, "AprilTag family (tag36h11, ...)"},
    {"detect", "ids", "ids", K_IDS, F(ids_text), S(ids_text), 0, 0, "marker ids: 0-15 or 1,3,5-9"},
    {"method", "name", "method", K_METHOD, F(method_name), S(method_name), 0, 0, "affine pwlinear bspline rbf-local[-pure] tps[-pure] gaussian[-pure]"},
    {"method", "sigma", "sigma", K_DOUBLE, F(sigma), 0, -1, 1e6, "RBF scale in px (-1: the method's default)"},
    {"method", "levels", "levels", K_INT, F(levels), 0, 0, 16, "B-spline levels (0: automatic)"},
    {"method", "smoothing", "smoothing", K_DOUBLE, F(smoothing), 0, 0, 1e9, "RBF smoothing lambda (0: interpolate)"},
    {"method", "grid", "grid", K_DOUBLE, F(grid), 0, 0, 256, "warp grid spacing in px (0: from the error bound)"},
    {"method", "calibration", "calibration", K_STR, F(calibration), S(calibration), 0, 0, "cameras' calibration YAML: 3D tracking and warp (\"\": 2D)"},
    {"reference", "frame", "reference", K_INT, F(reference_frame), 0, 0, 1e9, "0: first good frame; N: the N-th frame"},
    {"reference", "on_camera_motion", "on-camera-motion", K_ENUM, F(on_camera_motion), 0, 0, 0,
     "a moved camera, once settled: new (a new reference) | keep (the old one)", "new|keep"},
    {"gating", "min_markers", "min-markers", K_INT, F(min_markers), 0, 1, SH_CONFIG_MAX_IDS, "fewer markers -> raw"},
    {"gating", "max_residual_px", "max-residual", K_DOUBLE, F(max_residual_px), 0, 0, 1e4, "residual over this -> raw"},
    {"gating", "max_sigma_px", "max-sigma", K_DOUBLE, F(max_sigma_px), 0, 0, 1e4, "position uncertainty (1 sigma) over this -> raw"},
    {"gating", "dropout_ms", "dropout-ms", K_INT, F(dropout_ms), 0, 0, 60000, "stale estimates up to this -> degraded, longer -> raw"},
    {"gating", "max_calibration_px", "max-calibration", K_DOUBLE, F(max_calibration_px), 0, 0.01, 100,
     "3D: median reprojection error of the markers every camera sees over this -> raw (the calibration does not fit)"},
    {"run", "threads", "threads", K_INT, F(threads), 0, 1, 64, "warp threads"},
    {"run", "control", "control", K_STR, F(control), S(control), 0, 0, "control socket path (\"\": none)"},
    {"run", "control_group", "control-group", K_STR, F(control_group), S(control_group), 0, 0,
     "group that may request a new reference on the control socket (\"\": the service's user and root only)"},
    {"run", "points", "points", K_STR, F(points), S(points), 0, 0, "test mode: markers from a points file instead of detection"},
    {"sink", "display", "sink", K_STR, F(sink), S(sink), 0, 0, "shm:NAME | none"},
    {"sink", "slots", "slots", K_INT, F(slots), 0, 3, 16, "frame slots of the segment"},
    {"sink", "group", "group", K_STR, F(group), S(group), 0, 0, "owner group of the segment (\"\": the process's)"},
    {"sink", "record", "record", K_STR, F(record), S(record), 0, 0, "also write what is shown: FILE.y4m or png:DIR (\"\": no)"},
    {"sink", "watchdog", "watchdog", K_BOOL, F(watchdog), 0, 0, 1, "send WATCHDOG=1 when systemd asks"},
};
#pragma GCC diagnostic pop
#define NKEYS ((int)(sizeof keys / sizeof keys[0]))

void sh_config_default(sh_config *cfg)
{
    memset(cfg, 0, sizeof *cfg);
    snprintf(cfg->source, sizeof cfg->source, "y4m:out/run-demo/cam0.y4m");
    for (int i = 0; i < SH_CONFIG_MAX_CAMERAS; i++)
        cfg->camera[i].exposure = cfg->camera[i].gain = cfg->camera[i].white_balance = SH_CONFIG_CTRL_UNSET;
    cfg->realtime = 1;
    cfg->loop = 1;
    cfg->camera_timeout_ms = 1000;
    snprintf(cfg->trigger_chip, sizeof cfg->trigger_chip, "gpiochip0");
    cfg->trigger_pulse_us = 1000;
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
    cfg->max_calibration_px = 0.5;
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
    case K_SPEC: {
        static const char *const kinds[] = {"v4l2:", "libcamera:", "y4m:", "rec:"};
        int ok = !*value;
        for (int i = 0; i < 4 && !ok; i++)
            ok = !strncmp(value, kinds[i], strlen(kinds[i])) && value[strlen(kinds[i])];
        if (!ok)
            return fail(err, origin, line, section, key,
                        "'%s' is not v4l2:/dev/videoN, libcamera:NAME, y4m:FILE or rec:DIR", value);
        if (strlen(value) >= k->size)
            return fail(err, origin, line, section, key, "value longer than %s characters", "255");
        memset(base + k->offset, 0, k->size); /* configs compare with memcmp (reload, tests) */
        snprintf(base + k->offset, k->size, "%s", value);
        return SH_OK;
    }
    case K_RAWFMT: {
        sh_rawfmt f;
        int any = !*value || !strcasecmp(value, "auto");
        if (!any && (strlen(value) >= k->size || sh_rawfmt_parse(value, &f) != SH_OK))
            return fail(err, origin, line, section, key,
                        "unknown pixel format '%s' (yuyv, nv12, grey, rgb24, bgr24, mjpeg, i420, or auto)", value);
        memset(base + k->offset, 0, k->size);
        snprintf(base + k->offset, k->size, "%s", any ? "" : value);
        return SH_OK;
    }
    case K_SIZE: {
        int *wh = (int *)(base + k->offset), w = 0, h = 0;
        if (*value && strcasecmp(value, "auto")) {
            long a, b = 0;
            errno = 0;
            a = strtol(value, &end, 10);
            int ok = end != value && (*end == 'x' || *end == 'X') && !errno;
            if (ok) {
                const char *p = end + 1;
                b = strtol(p, &end, 10);
                ok = end != p && !*end && !errno && a >= k->min && a <= k->max && b >= k->min && b <= k->max;
            }
            if (!ok)
                return fail(err, origin, line, section, key,
                            "'%s' is not WIDTHxHEIGHT (1..16384 each, e.g. 1920x1080) or auto", value);
            w = (int)a;
            h = (int)b;
        }
        wh[0] = w;
        wh[1] = h;
        return SH_OK;
    }
    case K_FPS: {
        int *nd = (int *)(base + k->offset);
        long num = 0, den = 0;
        if (*value && strcasecmp(value, "auto")) {
            errno = 0;
            double v = strtod(value, &end);
            int ok = end != value && !errno && isfinite(v);
            if (ok && *end == '/') { /* an exact ratio: 30000/1001 */
                const char *p = end + 1;
                double d = strtod(p, &end);
                ok = end != p && !*end && v == floor(v) && d == floor(d) && d >= 1 && d <= 1e6 && v >= 1 &&
                     v <= 1e9 && v / d <= k->max;
                num = ok ? (long)v : 0;
                den = ok ? (long)d : 0;
            } else if (ok) { /* decimal: kept to a thousandth */
                ok = !*end && v > 0 && v <= k->max;
                num = ok ? lround(v * 1000) : 0;
                den = 1000;
                while (ok && num % 10 == 0 && den > 1)
                    num /= 10, den /= 10;
            }
            if (!ok || num <= 0)
                return fail(err, origin, line, section, key,
                            "'%s' is not a frame rate (30, 29.97, 30000/1001 up to 1000; or auto)", value);
        }
        nd[0] = (int)num;
        nd[1] = (int)den;
        return SH_OK;
    }
    case K_CTRL: {
        int32_t v = SH_CONFIG_CTRL_UNSET;
        if (*value && strcasecmp(value, "auto")) {
            errno = 0;
            long l = strtol(value, &end, 10);
            if (end == value || *end || errno || l < k->min || l > k->max) {
                char msg[128];
                snprintf(msg, sizeof msg, "'%%s' is not auto or a whole number in %.0f..%.0f", k->min, k->max);
                return fail(err, origin, line, section, key, msg, value);
            }
            v = (int32_t)l;
        }
        *(int32_t *)(base + k->offset) = v;
        return SH_OK;
    }
    case K_ENUM: {
        int idx = 0;
        for (const char *c = k->choices; *c; idx++) {
            size_t n = strcspn(c, "|");
            if (strlen(value) == n && !strncasecmp(value, c, n)) {
                *(int *)(base + k->offset) = idx;
                return SH_OK;
            }
            c += n + (c[n] == '|');
        }
        char msg[128];
        snprintf(msg, sizeof msg, "'%%s' is not one of %s", k->choices);
        return fail(err, origin, line, section, key, msg, value);
    }
    }
    return SH_EINVAL;
}

int sh_config_cameras(const sh_config *cfg)
{
    int n = 0;
    while (n < SH_CONFIG_MAX_CAMERAS && cfg->camera[n].spec[0])
        n++;
    return n;
}

int sh_config_option(const char *name, const char **section, const char **key, int *is_flag)
{
    *is_flag = 0; /* callers read it for run-only options too */
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
    if (!sh_config_cameras(cfg)) {
        snprintf(err, SH_CONFIG_ERR, "[camera0] spec: empty, no camera configured (v4l2:/dev/videoN, "
                 "libcamera:NAME, y4m:FILE or rec:DIR)");
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
    for (int i = 1; i < SH_CONFIG_MAX_CAMERAS; i++)
        if (cfg->camera[i].spec[0] && !cfg->camera[i - 1].spec[0]) {
            snprintf(err, SH_CONFIG_ERR, "[camera%d] spec: set while [camera%d] spec is empty (cameras count from 0 "
                     "without gaps)", i, i - 1);
            return SH_EINVAL;
        }
    int ncam = sh_config_cameras(cfg);
    if (cfg->output_camera >= ncam) {
        snprintf(err, SH_CONFIG_ERR, "[source] output: camera %d, but %d camera%s configured", cfg->output_camera,
                 ncam, ncam == 1 ? " is" : "s are");
        return SH_EINVAL;
    }
    if (cfg->trigger != SH_TRIGGER_OFF && !cfg->trigger_chip[0]) {
        snprintf(err, SH_CONFIG_ERR, "[trigger] chip: empty, but mode %s needs a GPIO chip",
                 cfg->trigger == SH_TRIGGER_OUT ? "out" : "in");
        return SH_EINVAL;
    }
    if (cfg->trigger == SH_TRIGGER_OUT && cfg->trigger_fps > 0 && cfg->trigger_pulse_us * 1e-6 * cfg->trigger_fps >= 1) {
        snprintf(err, SH_CONFIG_ERR, "[trigger] pulse_us: %d us is not shorter than the period at %g pulses/s",
                 cfg->trigger_pulse_us, cfg->trigger_fps);
        return SH_EINVAL;
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
        if (k->alias || (k->cam > 1 && !cfg->camera[k->cam - 1].spec[0]))
            continue; /* a camera that is not there: its section would only add noise */
        if (strcmp(last, k->section)) {
            fprintf(out, "%s[%s]\n", last[0] ? "\n" : "", k->section);
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
        case K_SPEC:
            fprintf(out, "%s\n", base + k->offset);
            break;
        case K_RAWFMT:
            fprintf(out, "%s\n", base[k->offset] ? base + k->offset : "auto");
            break;
        case K_SIZE:
        case K_FPS: {
            const int *v = (const int *)(base + k->offset);
            if (v[0]) fprintf(out, "%d%s%d\n", v[0], k->type == K_SIZE ? "x" : "/", v[1]);
            else fprintf(out, "auto\n");
            break;
        }
        case K_CTRL: {
            int32_t v = *(const int32_t *)(base + k->offset);
            if (v == SH_CONFIG_CTRL_UNSET) fprintf(out, "auto\n");
            else fprintf(out, "%d\n", (int)v);
            break;
        }
        case K_ENUM: {
            const char *c = k->choices;
            for (int idx = *(const int *)(base + k->offset); idx > 0 && strchr(c, '|'); idx--)
                c = strchr(c, '|') + 1;
            fprintf(out, "%.*s\n", (int)strcspn(c, "|"), c);
            break;
        }
        }
    }
}

void sh_config_usage(FILE *out)
{
    for (int i = 0; i < NKEYS; i++) {
        if (keys[i].cam > 1)
            continue; /* cameras 1.. have camera 0's keys: one line says so */
        fprintf(out, "  --%-21s %s  [%s] %s: %s\n", keys[i].option, keys[i].type == K_BOOL ? "0|1" : "V  ",
                keys[i].section, keys[i].key, keys[i].help);
        if (i + 1 < NKEYS && keys[i].cam == 1 && !keys[i].alias && keys[i + 1].cam != 1)
            fprintf(out, "  --cameraN-KEY           V    [cameraN] KEY: the same keys for cameras 1..%d\n",
                    SH_CONFIG_MAX_CAMERAS - 1);
    }
}
