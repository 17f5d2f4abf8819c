/* The daemon's configuration keys: their table (with when a change takes effect), setting one,
 * comparing configs key by key, the command-line names, the checks across keys and writing back.
 * The kinds of value (text to value and back) are in value.c, reading INI text and files in ini.c. */
#include "stillheart/config.h"
#include "stillheart/image.h"
#include "stillheart/landmarks.h"
#include "stillheart/track.h"

#include "config_internal.h"

#include <math.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>

#define F(m) offsetof(sh_config, m)
#define S(m) sizeof(((sh_config *)0)->m)
#define SRC SH_CONFIG_SOURCE
#define PROC SH_CONFIG_PROCESSING
#define CAMERA_KEYS(i)                                                                                         \
    {"camera" #i, "spec", "camera" #i "-spec", K_SPEC, SRC, F(camera[i].spec), S(camera[i].spec), 0, 0,         \
     "v4l2:/dev/videoN | libcamera:NAME | y4m:FILE | rec:DIR (\"\": no camera)", NULL, i + 1, 0},                \
    {"camera" #i, "format", "camera" #i "-format", K_RAWFMT, SRC, F(camera[i].format), S(camera[i].format), 0, 0, \
     "yuyv nv12 grey rgb24 bgr24 mjpeg (auto: the device's)", NULL, i + 1, 0},                                   \
    {"camera" #i, "size", "camera" #i "-size", K_SIZE, SRC, F(camera[i].width), 0, 1, 16384,                     \
     "WIDTHxHEIGHT (auto: the device's)", NULL, i + 1, 0},                                                       \
    {"camera" #i, "fps", "camera" #i "-fps", K_FPS, SRC, F(camera[i].fps_num), 0, 0, 1000,                       \
     "frames per second, 30 or 30000/1001 (auto: the device's)", NULL, i + 1, 0},                                \
    {"camera" #i, "exposure", "camera" #i "-exposure", K_CTRL, SRC, F(camera[i].exposure), 0, 1, 10000000,       \
     "manual exposure in 100 us units (auto: the camera's)", NULL, i + 1, 0},                                    \
    {"camera" #i, "gain", "camera" #i "-gain", K_CTRL, SRC, F(camera[i].gain), 0, 0, 1000000,                    \
     "gain, the driver's units (auto: the camera's)", NULL, i + 1, 0},                                           \
    {"camera" #i, "white_balance", "camera" #i "-white-balance", K_CTRL, SRC, F(camera[i].white_balance), 0,     \
     1000, 20000, "manual white balance in K (auto: the camera's)", NULL, i + 1, 0}
/* Most rows leave choices, cam and alias out (zero): the table reads better without them. The
 * effect column is the fifth, before the offset, so a row cannot leave it out and still compile
 * quietly (test_config also checks every row's against docs/daemon.md). */
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmissing-field-initializers"
static const keydef keys[] = {
    {"source", "spec", "source", K_SPEC, SRC, F(camera[0].spec), S(camera[0].spec), 0, 0, "camera 0's spec ([camera0] spec)", NULL, 1, 1},
    {"source", "realtime", "realtime", K_BOOL, SRC, F(realtime), 0, 0, 1, "replay at the stream's frame rate (0: as fast as possible)"},
    {"source", "loop", "loop", K_BOOL, SRC, F(loop), 0, 0, 1, "replay: start over at the end"},
    {"source", "output", "output-camera", K_INT, SRC, F(output_camera), 0, 0, SH_CONFIG_MAX_CAMERAS - 1, "the camera whose frames are warped and shown"},
    {"source", "sync_tolerance_ms", "sync-tolerance-ms", K_DOUBLE, SRC, F(sync_tolerance_ms), 0, 0, 1000, "frames this close form a set (0: a quarter frame period)"},
    {"source", "sync_wait_ms", "sync-wait-ms", K_DOUBLE, SRC, F(sync_wait_ms), 0, 0, 10000, "a set waits this long for a missing frame (0: two frame periods)"},
    {"source", "camera_timeout_ms", "camera-timeout-ms", K_INT, SRC, F(camera_timeout_ms), 0, 10, 60000, "no frame for this long: the camera is reopened"},
    {"source", "max_frame_pixels", "max-frame-pixels", K_INT, SRC, F(max_frame_pixels), 0, 1, SH_IMAGE_MAX_SIZE * SH_IMAGE_MAX_SIZE,
     "a camera's frames of more pixels (width x height) are refused at open, before any is allocated (default: 3840x2160)"},
    {"source", "queue_ms", "queue-ms", K_INT, SRC, F(queue_ms), 0, 0, 1000,
     "real time: sets wait for processing in order while at most this many ms old (at most 8 sets) and processing keeps up with the camera; 0: only the newest waits, a set replaced is dropped (default: 100)"},
    CAMERA_KEYS(0),
    CAMERA_KEYS(1),
    CAMERA_KEYS(2),
    CAMERA_KEYS(3),
    {"trigger", "mode", "trigger", K_ENUM, SRC, F(trigger), 0, 0, 0, "off | out (drive the line) | in (timestamp its edges)", "off|out|in"},
    {"trigger", "chip", "trigger-chip", K_STR, SRC, F(trigger_chip), S(trigger_chip), 0, 0, "GPIO chip: gpiochip0, /dev/gpiochip0, a label or a number"},
    {"trigger", "line", "trigger-line", K_INT, SRC, F(trigger_line), 0, 0, 1023, "line offset on the chip"},
    {"trigger", "polarity", "trigger-polarity", K_ENUM, SRC, F(trigger_active_low), 0, 0, 0, "high | low (active edge falling)", "high|low"},
    {"trigger", "fps", "trigger-fps", K_DOUBLE, SRC, F(trigger_fps), 0, 0, 1000, "out: pulses per second (0: camera 0's frame rate)"},
    {"trigger", "pulse_us", "trigger-pulse-us", K_INT, SRC, F(trigger_pulse_us), 0, 1, 1000000, "out: pulse width in us"},
    {"trigger", "offset_us", "trigger-offset-us", K_INT, SRC, F(trigger_offset_us), 0, -1000000, 1000000, "frame timestamp minus trigger edge, expected"},
    {"detect", "family", "family", K_STR, PROC, F(family), S(family), 0, 0, "AprilTag family (tag36h11, ...)"},
    {"detect", "ids", "ids", K_IDS, PROC, F(ids_text), S(ids_text), 0, 0, "marker ids: 0-15 or 1,3,5-9"},
    {"track", "landmarks", "landmarks", K_INT, PROC, F(landmarks), 0, 0, 2000,
     "natural landmarks of the tissue besides the markers (0: none; tps, bspline, pwlinear (2D), affine; in 3D found in every camera)"},
    {"track", "landmarks_sparse", "landmarks-sparse", K_BOOL, PROC, F(landmarks_sparse), 0, 0, 1,
     "landmarks for markers too sparse for their map (four at the corners): the disagreement bound follows the map's measured error, the choice balanced over the field"},
    {"track", "landmarks_affine", "landmarks-affine", K_BOOL, PROC, F(landmarks_affine), 0, 0, 1,
     "landmarks searched through the markers' map's local affine: a third as many over 1 px off where the tissue deforms as with square windows (0)"},
    {"track", "landmarks_refine", "landmarks-refine", K_INT, PROC, F(landmarks_refine), 0, 0, 1000,
     "the reference's windows averaged with the landmarks' matches in the first N frames after it (0: the reference frame's own): half as many over 1 px off"},
    {"track", "landmarks_confirm", "landmarks-confirm", K_INT, PROC, F(landmarks_confirm), 0, 0, 1000,
     "a landmark used from its N-th pass of every test after the reference on (0: 4, and 1 with landmarks_sparse): a window on a cover's edge passes a few times"},
    {"track", "landmarks_smoothing", "landmarks-smoothing", K_DOUBLE, PROC, F(landmarks_smoothing), 0, 0, 1e9,
     "the landmarks' own smoothing in a tps map (the RBFs), the markers exact (0: interpolated too); at 1080p, 4 times it at 4K"},
    {"method", "name", "method", K_METHOD, PROC, F(method_name), S(method_name), 0, 0, "affine pwlinear bspline rbf-local[-pure] tps[-pure] gaussian[-pure]"},
    {"method", "sigma", "sigma", K_DOUBLE, PROC, F(sigma), 0, -1, 1e6, "RBF scale in px (-1: the method's default)"},
    {"method", "levels", "levels", K_INT, PROC, F(levels), 0, 0, 16, "B-spline levels (0: automatic)"},
    {"method", "smoothing", "smoothing", K_DOUBLE, PROC, F(smoothing), 0, 0, 1e9, "RBF smoothing lambda (0: interpolate)"},
    {"method", "grid", "grid", K_DOUBLE, PROC, F(grid), 0, 0, 256, "warp grid spacing in px, the first and the coarsest (0: 16, refined by the error bound)"},
    {"method", "calibration", "calibration", K_STR, PROC, F(calibration), S(calibration), 0, 0, "cameras' calibration YAML: 3D tracking and warp (\"\": 2D)"},
    {"method", "view", "view", K_ENUM, PROC, F(view), 0, 0, 0,
     "3D: reference (the output camera's view) | stereo (the pair of virtual eyes of a 3D monitor)", "reference|stereo"},
    {"method", "baseline", "baseline", K_DOUBLE, PROC, F(baseline), 0, 0.001, 1e4, "stereo: mm between the two eyes"},
    {"method", "layout", "layout", K_ENUM, PROC, F(layout), 0, 0, 0,
     "stereo: sbs (2W x H) | tb (W x 2H) | sbs-half | tb-half (each eye halved into W x H)", "sbs|tb|sbs-half|tb-half"},
    {"reference", "frame", "reference", K_INT, PROC, F(reference_frame), 0, 0, 1e9, "0: first good frame; N: the N-th frame"},
    {"reference", "on_camera_motion", "on-camera-motion", K_ENUM, SH_CONFIG_GATING, F(on_camera_motion), 0, 0, 0,
     "a moved camera, once settled: new (a new reference) | keep (the old one)", "new|keep"},
    {"gating", "min_markers", "min-markers", K_INT, SH_CONFIG_GATING, F(min_markers), 0, 1, SH_CONFIG_MAX_IDS, "fewer markers -> raw"},
    {"gating", "max_residual_px", "max-residual", K_DOUBLE, SH_CONFIG_GATING, F(max_residual_px), 0, 0, 1e4, "residual over this -> raw"},
    {"gating", "landmarks_carry", "landmarks-carry", K_BOOL, SH_CONFIG_GATING, F(landmarks_carry), 0, 0, 1,
     "a frame raw for its markers (too few, one uncertain, no model yet) with two detected there and in the last frame stabilized with its landmarks (no landmark search between them) is carried by the landmarks when they move as those markers do: degraded, over their hull ([track] landmarks, 2D)"},
    {"gating", "max_sigma_px", "max-sigma", K_DOUBLE, SH_CONFIG_GATING, F(max_sigma_px), 0, 0, 1e4, "position uncertainty (1 sigma) over this -> raw"},
    {"gating", "dropout_ms", "dropout-ms", K_INT, SH_CONFIG_GATING, F(dropout_ms), 0, 0, 60000, "stale estimates up to this -> degraded, longer -> raw"},
    {"gating", "max_calibration_px", "max-calibration", K_DOUBLE, SH_CONFIG_GATING, F(max_calibration_px), 0, 0.01, 100,
     "3D: median reprojection error of the markers seen by two or more cameras over this -> raw (the calibration does not fit)"},
    {"run", "threads", "threads", K_INT, PROC, F(threads), 0, 1, 64, "warp and detection threads"},
    {"run", "control", "control", K_STR, SH_CONFIG_CONTROL, F(control), S(control), 0, 0, "control socket path (\"\": none)"},
    {"run", "control_group", "control-group", K_STR, SH_CONFIG_LIVE, F(control_group), S(control_group), 0, 0,
     "group that may request a new reference on the control socket (\"\": the service's user and root only)"},
    {"run", "points", "points", K_STR, PROC, F(points), S(points), 0, 0, "test mode: markers from a points file instead of detection"},
    {"sink", "display", "sink", K_STR, SH_CONFIG_DISPLAY, F(sink), S(sink), 0, 0, "shm:NAME | none"},
    {"sink", "slots", "slots", K_INT, SH_CONFIG_DISPLAY, F(slots), 0, 3, 16, "frame slots of the segment"},
    {"sink", "group", "group", K_STR, SH_CONFIG_DISPLAY, F(group), S(group), 0, 0, "owner group of the segment (\"\": the process's)"},
    {"sink", "outside", "outside", K_ENUM, SH_CONFIG_GATING, F(outside), 0, 0, 0,
     "outside the markers' hull, in every sink: black | dimmed-raw (the unstabilized frame dimmed, a cyan boundary line)",
     "black|dimmed-raw"},
    {"sink", "record", "record", K_STR, SH_CONFIG_RECORD, F(record), S(record), 0, 0,
     "also write what is shown: FILE.y4m or png:DIR (\"\": no); taken: FILE-2.y4m, DIR-2, ..."},
    {"sink", "record_sync_ms", "record-sync-ms", K_INT, SH_CONFIG_RECORD, F(record_sync_ms), 0, 0, 60000,
     "Y4M record: handed to the kernel and synced to disk this often (a kill or power loss loses about this much)"},
    {"sink", "v4l2", "v4l2", K_STR, SH_CONFIG_V4L2, F(v4l2), S(v4l2), 0, 0,
     "also publish what is shown to a V4L2 output device, a v4l2loopback /dev/videoN (\"\": no)"},
    {"sink", "watchdog", "watchdog", K_BOOL, SH_CONFIG_LIVE, F(watchdog), 0, 0, 1, "send WATCHDOG=1 when systemd asks"},
};
#pragma GCC diagnostic pop
#undef SRC
#undef PROC
#define NKEYS ((int)(sizeof keys / sizeof keys[0]))

void sh_config_default(sh_config *cfg)
{
    memset(cfg, 0, sizeof *cfg);
    snprintf(cfg->camera[0].spec, sizeof cfg->camera[0].spec, "y4m:out/run-demo/cam0.y4m");
    for (int i = 0; i < SH_CONFIG_MAX_CAMERAS; i++)
        cfg->camera[i].exposure = cfg->camera[i].gain = cfg->camera[i].white_balance = SH_CONFIG_CTRL_UNSET;
    cfg->realtime = 1;
    cfg->loop = 1;
    cfg->camera_timeout_ms = 1000;
    cfg->queue_ms = 100;
    cfg->max_frame_pixels = SH_FRAME_PIXELS_DEFAULT;
    snprintf(cfg->trigger_chip, sizeof cfg->trigger_chip, "gpiochip0");
    cfg->trigger_pulse_us = 1000;
    snprintf(cfg->family, sizeof cfg->family, "tag36h11");
    snprintf(cfg->ids_text, sizeof cfg->ids_text, "0-15");
    for (int i = 0; i < 16; i++)
        cfg->ids[i] = 1;
    /* the default of `warp` and `warp3d` too: the least geometric error on the phantom (docs/warp.md) */
    snprintf(cfg->method_name, sizeof cfg->method_name, "tps");
    cfg->sigma = -1;
    cfg->levels = 0;
    cfg->smoothing = 0;
    cfg->landmarks_smoothing = SH_LANDMARK_SMOOTHING;
    sh_landmarks_params lp; /* the landmarks' own defaults */
    sh_landmarks_params_default(&lp);
    cfg->landmarks_affine = lp.affine;
    cfg->landmarks_refine = lp.refine;
    cfg->grid = 0;
    cfg->view = SH_VIEW_REFERENCE;
    cfg->baseline = SH_CONFIG_BASELINE_DEFAULT;
    cfg->layout = 0; /* sbs */
    cfg->reference_frame = 0;
    cfg->min_markers = 6;
    cfg->max_residual_px = 3.0;
    cfg->max_sigma_px = 4.0;
    cfg->dropout_ms = 200;
    cfg->max_calibration_px = 0.5;
    cfg->threads = 2;
    snprintf(cfg->sink, sizeof cfg->sink, "shm:/stillheart");
    cfg->slots = 4;
    cfg->record_sync_ms = 1000;
    snprintf(cfg->group, sizeof cfg->group, "video");
    cfg->watchdog = 1;
}

void sh_config_method(const sh_config *cfg, sh_interp_params *params)
{
    sh_interp_params_parse(cfg->method_name, params); /* a name sh_config_set accepted */
    if (cfg->sigma >= 0)
        params->sigma = cfg->sigma;
    params->levels = cfg->levels;
    params->smoothing = cfg->smoothing;
}

/* The bytes a key's value occupies; K_IDS: the id set, not its spelling ("1,2" is "1-2"). */
static void key_span(const keydef *k, size_t *offset, size_t *size)
{
    static const size_t scalar[] = {[K_BOOL] = sizeof(int),     [K_INT] = sizeof(int),    [K_DOUBLE] = sizeof(double),
                                    [K_SIZE] = 2 * sizeof(int), [K_FPS] = 2 * sizeof(int), [K_CTRL] = sizeof(int32_t),
                                    [K_ENUM] = sizeof(int)};
    *offset = k->type == K_IDS ? F(ids) : k->offset;
    *size = k->type == K_IDS ? S(ids) : k->size ? k->size : scalar[k->type];
}

/* Strings up to their end (what follows the NUL is no part of the value), the rest as bytes:
 * numbers as stored, which a parsed value never makes -0.0 or NaN. */
static int key_differs(const sh_config *a, const sh_config *b, const keydef *k)
{
    size_t off, size;
    key_span(k, &off, &size);
    const char *x = (const char *)a + off, *y = (const char *)b + off;
    if (k->size && k->type != K_IDS)
        return strncmp(x, y, size) != 0;
    return memcmp(x, y, size) != 0;
}

unsigned sh_config_changes(const sh_config *a, const sh_config *b)
{
    unsigned effects = 0;
    for (int i = 0; i < NKEYS; i++)
        if (key_differs(a, b, &keys[i]))
            effects |= keys[i].effect;
    return effects;
}

void sh_config_copy_keys(sh_config *dst, const sh_config *src, unsigned effects)
{
    for (int i = 0; i < NKEYS; i++) {
        if (!(keys[i].effect & effects))
            continue;
        size_t off, size;
        key_span(&keys[i], &off, &size);
        memcpy((char *)dst + off, (const char *)src + off, size);
        if (keys[i].type == K_IDS) /* and the spelling with the set */
            memcpy((char *)dst + keys[i].offset, (const char *)src + keys[i].offset, keys[i].size);
    }
}

void sh_config_describe(const sh_config *a, const sh_config *b, unsigned effects, char *out, size_t cap)
{
    for (int i = 0; i < NKEYS; i++) {
        const keydef *k = &keys[i];
        if (k->alias || !(k->effect & effects) || !key_differs(a, b, k))
            continue;
        char x[SH_CONFIG_STR], y[SH_CONFIG_STR];
        sh_config_format_value(a, k, 0, x, sizeof x);
        sh_config_format_value(b, k, 0, y, sizeof y);
        size_t len = strlen(out);
        if (len + 1 < cap)
            snprintf(out + len, cap - len, "%s%s %s -> %s", len ? ", " : "", k->option, x[0] ? x : "none",
                     y[0] ? y : "none");
    }
}

int sh_config_key(int i, const char **section, const char **key, sh_config_effect *effect)
{
    if (i < 0 || i >= NKEYS)
        return 0;
    *section = keys[i].section;
    *key = keys[i].key;
    *effect = keys[i].effect;
    return 1;
}

_Static_assert(NKEYS <= SH_CONFIG_KEYS, "sh_config_origin holds SH_CONFIG_KEYS rows: raise it");

/* The row of [section] key, -1 when there is none; *section_known says whether the section is. */
static int find_key(const char *section, const char *key, int *section_known)
{
    *section_known = 0;
    for (int i = 0; i < NKEYS; i++)
        if (strcmp(keys[i].section, section) == 0) {
            *section_known = 1;
            if (strcmp(keys[i].key, key) == 0)
                return i;
        }
    return -1;
}

/* The row whose origin a key's value is recorded under: another name of a key ([source] spec)
 * is its key's. */
static int canonical(int i)
{
    for (int j = 0; keys[i].alias && j < NKEYS; j++)
        if (!keys[j].alias && keys[j].offset == keys[i].offset && keys[j].type == keys[i].type)
            return j;
    return i;
}

static void record_origin(sh_config *cfg, int row, const char *origin, int line)
{
    sh_config_origin *o = &cfg->origin;
    int i = 0;
    while (i < SH_CONFIG_ORIGINS && o->name[i][0] && strncmp(o->name[i], origin, SH_CONFIG_STR - 1))
        i++;
    if (i == SH_CONFIG_ORIGINS || !origin[0]) { /* more places than the table holds: said as a default's */
        o->from[row] = 0;
        o->line[row] = 0;
        return;
    }
    if (!o->name[i][0])
        snprintf(o->name[i], sizeof o->name[i], "%s", origin);
    o->from[row] = (unsigned char)(i + 1);
    o->line[row] = line > 0 ? line : 0;
}

/* Sets [section] key; its row in *row. why gets "[section] key: reason" on a refusal. */
static sh_status set_key(sh_config *cfg, const char *section, const char *key, const char *value, char *why, int *row)
{
    int section_known;
    *row = find_key(section, key, &section_known);
    char reason[WHY];
    if (!section_known)
        snprintf(reason, sizeof reason, "unknown section [%s]", section);
    else if (*row < 0)
        snprintf(reason, sizeof reason, "unknown key");
    else if (sh_config_parse_value(cfg, &keys[*row], value, reason))
        return SH_OK;
    snprintf(why, SH_CONFIG_ERR, "[%s] %s: %s", section, key, reason);
    return SH_EINVAL;
}

sh_status sh_config_set(sh_config *cfg, const char *section, const char *key, const char *value,
                        const char *origin, int line, char *err)
{
    char why[SH_CONFIG_ERR];
    int row;
    if (set_key(cfg, section, key, value, why, &row) == SH_OK) {
        record_origin(cfg, canonical(row), origin, line);
        return SH_OK;
    }
    /* the place first, the reason cut at the message's end */
    int n = line > 0 ? snprintf(err, SH_CONFIG_ERR, "%s:%d: ", origin, line) : snprintf(err, SH_CONFIG_ERR, "%s: ", origin);
    size_t at = n < 0 ? 0 : n < SH_CONFIG_ERR ? (size_t)n : SH_CONFIG_ERR - 1;
    snprintf(err + at, SH_CONFIG_ERR - at, "%s", why);
    return SH_EINVAL;
}

void sh_config_where(const sh_config *cfg, const char *section, const char *key, char *out, size_t cap)
{
    int known, row = find_key(section, key, &known);
    const sh_config_origin *o = &cfg->origin;
    if (row >= 0)
        row = canonical(row);
    if (row < 0 || !o->from[row]) {
        snprintf(out, cap, "[%s] %s", section, key);
        return;
    }
    const char *name = o->name[o->from[row] - 1];
    if (o->line[row] > 0) {
        snprintf(out, cap, "%s:%d: [%s] %s", name, o->line[row], section, key);
        return;
    }
    char v[SH_CONFIG_STR];
    sh_config_format_value(cfg, &keys[row], 0, v, sizeof v);
    snprintf(out, cap, "%s: --%s %s", name, keys[row].option, v[0] ? v : "''");
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

/* The fewest markers a model is made from: the daemon's processing makes none from fewer than 3
 * (src/daemon/run_proc.c), which every method's own minimum is at most (sh_interp_create). */
static int method_min_markers(sh_method m)
{
    (void)m;
    return 3;
}

/* A refusal of [section] key, begun with where its value came from (sh_config_where). */
static __attribute__((format(printf, 5, 6))) sh_status refuse(const sh_config *cfg, const char *section, const char *key,
                                                              char *err, const char *fmt, ...)
{
    sh_config_where(cfg, section, key, err, SH_CONFIG_ERR);
    size_t at = strlen(err);
    if (at + 2 < SH_CONFIG_ERR) {
        memcpy(err + at, ": ", 3);
        va_list ap;
        va_start(ap, fmt);
        vsnprintf(err + at + 2, SH_CONFIG_ERR - at - 2, fmt, ap);
        va_end(ap);
    }
    return SH_EINVAL;
}

/* [method]: what the interpolation and the warp refuse whatever the points and the frames
 * (docs/daemon.md). sigma, levels and smoothing are checked one at a time over the method's
 * defaults (sh_interp_params_check's rules), so that a refusal names the key at fault. */
static sh_status check_method(const sh_config *cfg, char *err)
{
    static const char *const names[] = {"sigma", "levels", "smoothing"};
    for (int i = 0; i < 3; i++) {
        sh_interp_params p;
        sh_interp_params_parse(cfg->method_name, &p); /* a name sh_config_set accepted */
        if (i == 0 && cfg->sigma >= 0)
            p.sigma = cfg->sigma;
        if (i == 1)
            p.levels = cfg->levels;
        if (i == 2)
            p.smoothing = cfg->smoothing;
        if (sh_interp_params_check(&p) != SH_OK) {
            const char *m = sh_error_message();
            return refuse(cfg, "method", names[i], err, "%s", strncmp(m, "interp ", 7) ? m : m + 7);
        }
    }
    /* sh_warp_model_create takes a power of two; run_proc hands it the whole pixels */
    double g = cfg->grid;
    if (g != 0 && (g != floor(g) || g < 1 || ((long)g & ((long)g - 1))))
        return refuse(cfg, "method", "grid", err, "%g px is not a power of two (the warp's grid spacing: 1, 2, 4, "
                      "... 256; 0: from the error bound)", g);
    /* the stereo pair is a view of the reconstructed surface: only a calibrated rig has one */
    if (cfg->view == SH_VIEW_STEREO && !cfg->calibration[0])
        return refuse(cfg, "method", "view", err, "stereo needs a calibrated rig ([method] calibration): the two eyes "
                      "see the surface reconstructed in 3D");
    if (cfg->view != SH_VIEW_STEREO && cfg->baseline != SH_CONFIG_BASELINE_DEFAULT)
        return refuse(cfg, "method", "baseline", err, "%g mm, but only the stereo view has eyes ([method] view = stereo)",
                      cfg->baseline);
    if (cfg->view != SH_VIEW_STEREO && cfg->layout != 0)
        return refuse(cfg, "method", "layout", err, "only the stereo view has a layout ([method] view = stereo)");
    sh_interp_params method;
    sh_config_method(cfg, &method);
    /* a method that is better with landmarks (its model follows a set that changes every frame:
     * sh_warp_model_update_subset) */
    if (cfg->landmarks && !sh_landmarks_method_uses(method.method))
        return refuse(cfg, "track", "landmarks", err, "%d, but %s is worse with landmarks (tps, pwlinear, bspline and "
                      "affine follow them; docs/landmarks.md)", cfg->landmarks, cfg->method_name);
    /* in 3D the displacement's interpolant leaves points out by its fit (sh_interp_fit_subset),
     * which pwlinear has not: its triangles are the 2D warp model's */
    if (cfg->landmarks && cfg->calibration[0] && method.method == SH_METHOD_PWLINEAR)
        return refuse(cfg, "track", "landmarks", err, "%d, but in 3D ([method] calibration) pwlinear would need a new "
                      "model for every frame's landmarks (tps, bspline and affine follow them; docs/landmarks.md)",
                      cfg->landmarks);
    /* the landmarks' smoothing is a term of their rows in an RBF map, 2D or 3D's surface and
     * displacement (sh_interp_create_smoothed): changed where it does nothing, it is refused, as
     * the stereo view's keys are without it */
    if (cfg->landmarks_smoothing != SH_LANDMARK_SMOOTHING && !cfg->landmarks)
        return refuse(cfg, "track", "landmarks_smoothing", err, "%g, but there are no landmarks ([track] landmarks = 0)",
                      cfg->landmarks_smoothing);
    if (cfg->landmarks_smoothing != SH_LANDMARK_SMOOTHING && !sh_interp_method_smooths(method.method))
        return refuse(cfg, "track", "landmarks_smoothing", err, "%g, but %s interpolates the landmarks (a tps map "
                      "approximates them)", cfg->landmarks_smoothing, cfg->method_name);
    /* the refinement of the landmarks' reference, changed where there are none, is refused too */
    sh_landmarks_params lp;
    sh_landmarks_params_default(&lp);
    if (cfg->landmarks_refine != lp.refine && !cfg->landmarks)
        return refuse(cfg, "track", "landmarks_refine", err, "%d, but there are no landmarks ([track] landmarks = 0)",
                      cfg->landmarks_refine);
    if (cfg->landmarks_confirm && !cfg->landmarks)
        return refuse(cfg, "track", "landmarks_confirm", err, "%d, but there are no landmarks ([track] landmarks = 0)",
                      cfg->landmarks_confirm);
    /* carried frames rest on the landmarks found in 2D (landmarks.h, "Carried frames") */
    if (cfg->landmarks_carry && !cfg->landmarks)
        return refuse(cfg, "gating", "landmarks_carry", err, "yes, but there are no landmarks ([track] landmarks = 0)");
    if (cfg->landmarks_carry && cfg->calibration[0])
        return refuse(cfg, "gating", "landmarks_carry", err, "yes, but in 3D ([method] calibration) every camera's "
                      "landmarks are predicted through the markers' map, which too few markers do not give");
    int need = method_min_markers(method.method);
    if (cfg->min_markers < need)
        return refuse(cfg, "gating", "min_markers", err, "%d is fewer than %s needs (%d)", cfg->min_markers,
                      cfg->method_name, need);
    return SH_OK;
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
    if (check_method(cfg, err) != SH_OK)
        return SH_EINVAL;
    int nids = 0;
    for (int i = 0; i < SH_CONFIG_MAX_IDS; i++)
        nids += cfg->ids[i];
    if (!cfg->points[0] && nids < cfg->min_markers) {
        snprintf(err, SH_CONFIG_ERR, "[detect] ids: %d ids, fewer than [gating] min_markers = %d", nids,
                 cfg->min_markers);
        return SH_EINVAL;
    }
    if (!cfg->points[0] && nids > SH_TRACK_MAX_MARKERS) {
        snprintf(err, SH_CONFIG_ERR, "[detect] ids: %d ids, the tracker follows at most %d", nids, SH_TRACK_MAX_MARKERS);
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
    if (cfg->v4l2[0] && cfg->v4l2[0] != '/') {
        snprintf(err, SH_CONFIG_ERR, "[sink] v4l2: '%s': want a device path, /dev/videoN", cfg->v4l2);
        return SH_EINVAL;
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
    for (int i = 0; i < NKEYS; i++) {
        const keydef *k = &keys[i];
        if (k->alias || (k->cam > 1 && !cfg->camera[k->cam - 1].spec[0]))
            continue; /* a camera that is not there: its section would only add noise */
        if (strcmp(last, k->section)) {
            fprintf(out, "%s[%s]\n", last[0] ? "\n" : "", k->section);
            last = k->section;
        }
        char v[SH_CONFIG_STR];
        sh_config_format_value(cfg, k, 1, v, sizeof v);
        fprintf(out, "%s = %s\n", k->key, v);
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
