/* The daemon's configuration: one INI file (firmware-config/stillheart.ini documents every key),
 * every key also settable from the command line, which wins over the file.
 *
 * A bad section, key or value, or a file that cannot be read, is refused with one line naming the
 * file, the line and the key ("stillheart.ini:12: [gating] min_markers: 'x' is not a whole number
 * in 1..1024"). Loading never touches a running configuration: parse into a fresh sh_config and
 * swap only when it succeeded (that is how SIGHUP reloads keep the running config on error). */
#ifndef STILLHEART_CONFIG_H
#define STILLHEART_CONFIG_H

#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include "stillheart/core.h"
#include "stillheart/interp.h"

#ifdef __cplusplus
extern "C" {
#endif

#define SH_CONFIG_STR 256
#define SH_CONFIG_MAX_IDS 1024 /* tag ids 0..1023 */
#define SH_CONFIG_ERR 512

#define SH_CONFIG_MAX_CAMERAS 4
#define SH_CONFIG_CTRL_UNSET INT32_MIN /* a control left as the camera has it (SH_SOURCE_CTRL_UNSET) */

/* [cameraN]: one camera of the rig (the source.h options of the same names). */
typedef struct {
    char spec[SH_CONFIG_STR];        /* v4l2:/dev/videoN, libcamera:NAME, y4m:FILE, rec:DIR; "" = none */
    char format[16];                 /* sh_rawfmt name ("yuyv", "nv12", ...); "" = the device's */
    int width, height;               /* 0 = the device's */
    int fps_num, fps_den;            /* 0/0 = the device's */
    int32_t exposure, gain, white_balance; /* SH_CONFIG_CTRL_UNSET = leave as the camera has it */
} sh_config_camera;

typedef enum { SH_TRIGGER_OFF = 0, SH_TRIGGER_OUT, SH_TRIGGER_IN } sh_trigger_mode;

#define SH_CONFIG_KEYS 128  /* room for the key table's rows (config.c asserts it) */
#define SH_CONFIG_ORIGINS 4 /* files (and "command line") a config's keys were set from */

/* Where each key was last set, for refusals that come after parsing (sh_config_check, the
 * daemon's checks against the frame size): kept in the config so that it is copied, swapped and
 * kept with it at a reload. Not a key: sh_config_changes and the effects never look at it. */
typedef struct {
    char name[SH_CONFIG_ORIGINS][SH_CONFIG_STR]; /* a file's name, or "command line" */
    unsigned char from[SH_CONFIG_KEYS]; /* per key row: 0 the default, i + 1 name[i] */
    int line[SH_CONFIG_KEYS];           /* per key row: the line in that file, 0 none (the command line) */
} sh_config_origin;

typedef struct {
    /* [cameraN]; [source] spec and --source are other names of camera[0].spec */
    sh_config_camera camera[SH_CONFIG_MAX_CAMERAS];
    /* [source] */
    int realtime;                    /* 1: the stream's frame rate; 0: as fast as possible */
    int loop;                        /* replay: start over at the end */
    int output_camera;               /* the camera whose frames are warped and shown */
    double sync_tolerance_ms;        /* frames this close form a set; 0 = a quarter frame period */
    double sync_wait_ms;             /* a set waits this long for a missing frame; 0 = 2 periods */
    int camera_timeout_ms;           /* no frame for this long: the camera is lost and reopened */
    int max_frame_pixels;            /* a camera's frames of more pixels are refused at open */
    int queue_ms;                    /* sets wait for processing in order while at most this old
                                      * (since capture) and processing keeps up; 0: only the newest
                                      * waits. Default 100 */
    /* [trigger] */
    sh_trigger_mode trigger;
    char trigger_chip[64];           /* gpiochip0, /dev/gpiochip0, a label or a number */
    int trigger_line;
    int trigger_active_low;          /* polarity low: the active edge is the falling one */
    double trigger_fps;              /* out: pulse rate; 0 = camera 0's frame rate */
    int trigger_pulse_us;            /* out: pulse width */
    int trigger_offset_us;           /* frame timestamp - trigger edge, expected */
    /* [detect] */
    char family[32];                 /* tag36h11, tagStandard41h12, ... */
    uint8_t ids[SH_CONFIG_MAX_IDS];  /* ids[i] = 1: tag i is a marker */
    char ids_text[SH_CONFIG_STR];    /* as written: "0-15", "1,3,5-9" */
    /* [track] */
    int landmarks;                   /* natural landmarks of the tissue besides the markers (0: none) */
    int landmarks_sparse;            /* their tests for sparse markers (sh_landmarks_params_sparse) */
    int landmarks_affine;            /* their forward search through the map's local affine (.affine) */
    int landmarks_refine;            /* frames whose matches refine the reference's windows (.refine) */
    int landmarks_confirm;           /* a landmark's pass from which it is used (.confirm); 0: the
                                      * tests' own (4, or 1 with landmarks_sparse) */
    double landmarks_smoothing;      /* their own smoothing in the map (SH_LANDMARK_SMOOTHING) */
    /* [method] */
    char method_name[32];            /* sh_config_method: the interpolation parameters of these four */
    double sigma;                    /* < 0: the method's default */
    int levels;
    double smoothing;
    double grid;                     /* warp grid spacing in px; 0 = from the error bound */
    char calibration[SH_CONFIG_STR]; /* the cameras' calibration YAML: 3D tracking and warp ("" = 2D) */
    int view;                        /* 3D: SH_VIEW_REFERENCE (0, the output camera's own) or SH_VIEW_STEREO */
    double baseline;                 /* stereo: mm between the virtual eyes */
    int layout;                      /* stereo: sh_warp3d_layout (sbs, tb, sbs-half, tb-half) */
    /* [reference] */
    int reference_frame;             /* 0: first good frame; N: the N-th frame (1-based) */
    int on_camera_motion;            /* SH_CAMERA_MOTION_NEW (0) or _KEEP (1) */
    /* [gating] */
    int min_markers;                 /* fewer -> raw ("too few markers") */
    double max_residual_px;          /* larger -> raw ("residual") */
    int landmarks_carry;             /* fewer than min_markers, two seen: carried by the landmarks
                                      * (sh_landmarks_carry), degraded ("carried") */
    double max_sigma_px;             /* position uncertainty (1 sigma) over this -> raw */
    int dropout_ms;                  /* stale up to this -> degraded; longer -> raw */
    double max_calibration_px;       /* 3D: the calibration's median reprojection error over this -> raw */
    /* [run] */
    int threads;
    char points[SH_CONFIG_STR];      /* test mode: markers from a points file, no detection */
    char control[SH_CONFIG_STR];     /* control socket path ("" = none): reference, status */
    char control_group[64];          /* may request a reference there ("" = the service's user and root only) */
    /* [sink] */
    char sink[SH_CONFIG_STR];        /* shm:NAME or none */
    int slots;
    char group[64];                  /* owner group of the segment ("" = the process's) */
    int outside;                     /* SH_OUTSIDE_BLACK (0) or SH_OUTSIDE_DIMMED_RAW (1) */
    char record[SH_CONFIG_STR];      /* "", FILE.y4m or png:DIR: what is shown, also to files */
    int record_sync_ms;              /* Y4M record: flushed and synced this often (0: every frame) */
    char v4l2[SH_CONFIG_STR];        /* "" or a V4L2 output device (v4l2loopback): what is shown, also there */
    int watchdog;                    /* 1: WATCHDOG=1 pings when systemd asks for them */
    sh_config_origin origin;         /* where each key was set (sh_config_set records it) */
} sh_config;

/* [reference] on_camera_motion: once a moved endoscope has settled, a new reference is taken
 * (new, the default) or the old one is kept (keep). */
enum { SH_CAMERA_MOTION_NEW = 0, SH_CAMERA_MOTION_KEEP = 1 };

/* [method] view: what a calibrated rig's stabilized surface is shown as: the output camera's own
 * view (reference) or the stereo pair of paper section IV, two virtual eyes [method] baseline
 * apart around the output camera, in the frame [method] layout arranges (warp3d.h). */
enum { SH_VIEW_REFERENCE = 0, SH_VIEW_STEREO = 1 };
#define SH_CONFIG_BASELINE_DEFAULT 10.0 /* mm, as `stillheart warp3d --baseline` */

/* [sink] outside: what a warped frame shows outside the markers' hull: black (the paper's) or
 * the current, unstabilized frame dimmed, with a boundary line (sh_warp_outside, warp.h). */
enum { SH_OUTSIDE_BLACK = 0, SH_OUTSIDE_DIMMED_RAW = 1 };

/* When a key's change takes effect in the running daemon (SIGHUP: src/daemon/run_pipeline.c). The key
 * table gives every key exactly one; the reload acts on these classes, never on key names, so a
 * new key is applied as soon as its row says how (docs/daemon.md lists them). */
typedef enum {
    SH_CONFIG_LIVE = 1 << 0,       /* read from the running config where it is used: nothing is rebuilt */
    SH_CONFIG_GATING = 1 << 1,     /* handed to the running processing (the gate), from the next frame */
    SH_CONFIG_SOURCE = 1 << 2,     /* the cameras closed and opened again (a new stream: processing too) */
    SH_CONFIG_PROCESSING = 1 << 3, /* detector, tracker, models and warp made again: a new reference */
    SH_CONFIG_DISPLAY = 1 << 4,    /* the display segment made again (or another one made) */
    SH_CONFIG_RECORD = 1 << 5,     /* the record file or folder closed and another opened */
    SH_CONFIG_CONTROL = 1 << 6,    /* the control socket closed and another opened */
    SH_CONFIG_V4L2 = 1 << 7,       /* the V4L2 output closed and opened again */
} sh_config_effect;

/* The embedded defaults (the run demo's config): y4m:out/run-demo/cam0.y4m, tps, shm:/stillheart. */
void sh_config_default(sh_config *cfg);

/* Sets one key from text. origin (a file name or "command line") and line (0: none) name the
 * place in the error message, written to err (SH_CONFIG_ERR bytes), and are recorded in
 * cfg->origin for sh_config_where (a key of another name, [source] spec, under the key it names). */
sh_status sh_config_set(sh_config *cfg, const char *section, const char *key, const char *value,
                        const char *origin, int line, char *err);

/* Parses INI text over cfg (keys not mentioned keep their value). */
sh_status sh_config_parse_string(sh_config *cfg, const char *text, const char *origin, char *err);
/* Reads and parses the file; a file that cannot be opened is an error naming it. */
sh_status sh_config_load_file(sh_config *cfg, const char *path, char *err);

/* Command line: finds the key that --NAME sets (e.g. "max-residual" -> [gating] max_residual_px).
 * Returns 1 and the section/key, or 0 when no key has that option name. */
int sh_config_option(const char *name, const char **section, const char **key, int *is_flag);
/* Where a key's value came from, as a refusal begins: "FILE:LINE: [section] key" from a file,
 * "command line: --option VALUE" from the command line, "[section] key" when it has its default
 * (or came from more files than the origin table holds). */
void sh_config_where(const sh_config *cfg, const char *section, const char *key, char *out, size_t cap);
/* Checks the whole config (consistency across keys: min_markers vs method, the [method] values
 * against what the interpolation and the warp accept whatever the frames: docs/daemon.md);
 * refusals begin with sh_config_where's place. */
sh_status sh_config_check(const sh_config *cfg, char *err);
/* Writes the config as INI (every key), e.g. for --print-config. */
void sh_config_write(const sh_config *cfg, FILE *out);
/* The number of cameras: those with a spec, from camera 0 on (sh_config_check refuses gaps). */
int sh_config_cameras(const sh_config *cfg);
/* The interpolation parameters that [method] name, sigma, levels and smoothing give. */
void sh_config_method(const sh_config *cfg, sh_interp_params *params);

/* The effects (sh_config_effect bits) of every key whose value differs between a and b, compared
 * key by key through the table; 0: the same configuration. */
unsigned sh_config_changes(const sh_config *a, const sh_config *b);
/* Copies from src into dst every key whose effect is among effects. */
void sh_config_copy_keys(sh_config *dst, const sh_config *src, unsigned effects);
/* Appends to out (", " between items) "OPTION OLD -> NEW" for every key among effects whose value
 * differs, for the daemon's log ("method tps -> bspline"); empty values read "none". */
void sh_config_describe(const sh_config *a, const sh_config *b, unsigned effects, char *out, size_t cap);
/* The table, for tests and docs: key i's section, name and effect; 0 past the last key. Other
 * names of a key ([source] spec) are listed too. */
int sh_config_key(int i, const char **section, const char **key, sh_config_effect *effect);

/* Prints the option list for --help. */
void sh_config_usage(FILE *out);

#ifdef __cplusplus
}
#endif
#endif
