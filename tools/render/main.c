/* stillheart-render: renders the beating-heart phantom with its exact ground truth.
 *
 * The main thread draws (OSMesa's llvmpipe spreads each draw over LP_NUM_THREADS threads); one
 * worker converts finished frames to I420 with sensor noise and writes them, so drawing and
 * writing overlap. Frames go through a two-slot ring: the drawing never waits on the disk for
 * more than one frame. */
#include <errno.h>
#include <getopt.h>
#include <limits.h>
#include <math.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include "render.h"
#include "stillheart/calib.h"
#include "stillheart/cli.h"
#include "stillheart/log.h"
#include "stillheart/y4m.h"

static const sh_cli cli = {"stillheart-render"};

static void usage(FILE *f)
{
    fprintf(f,
"usage: stillheart-render --preset exvivo|invivo --out DIR [options]\n"
"Renders a beating-heart phantom seen by 1-3 calibrated cameras, with exact ground truth.\n"
"\n"
"  --preset NAME      exvivo: artificial heart, 16 markers, 0.7 Hz, 23 fps, 400 frames;\n"
"                     invivo: porcine heart, 14 markers, 80 bpm + respiration, stabilizer\n"
"                     pads pressing part of the surface still, 31 fps, 337 frames\n"
"  --out DIR          output folder (created if missing)\n"
"  --frames N         number of frames (default: the preset's)\n"
"  --fps F            frame rate (default: the preset's)\n"
"  --rig small|paper  small: 1 camera, 640x360, a render a laptop makes in seconds (the\n"
"                     heart's default); paper: the paper's trinocular rig, 3 cameras at\n"
"                     1920x1080 (the default with --calib-target: a rig is calibrated);\n"
"                     --cameras, --width and --height change one of them\n"
"  --cameras K        1, 2 or 3 cameras of the trinocular rig (default: the rig's)\n"
"  --width W          image width, even (default: the rig's)\n"
"  --height H         image height, even (default: the rig's); the focal length scales with W\n"
"  --seed S           seed of everything random: texture, marker jitter, occlusions, noise\n"
"                     (default 1); the same seed gives the same bytes\n"
"  --occlusions       an instrument shaft crossing the view, blood blobs covering markers for\n"
"                     a while, and a decoy tag on a card beside the heart (not in markers.csv)\n"
"  --blood-spread SECONDS\n"
"                     how long each blood blob takes to spread to its size, and to shrink\n"
"                     back (default 0.4; up to 60); it stays at full size as long whatever\n"
"                     this is: a slow ooze creeps over the tissue. In phantom.txt\n"
"  --bpm B            heart rate in beats per minute (default 42 exvivo, 80 invivo)\n"
"  --periodic         a sequence that loops without a jump: the heart and respiration rates\n"
"                     are rounded to whole cycles over it (refused beyond 10 %% of the asked\n"
"                     rate) and the Y4M headers carry XLOOP=SEAMLESS, which tells a looping\n"
"                     replay (stillheart run --loop) that the motion goes on across the loop\n"
"  --camera-motion pan|bump\n"
"                     the endoscope moves: the whole scene (heart, pads, shaft, decoy) slides\n"
"                     along camera 0's image x axis, parallel to its image plane, so that the\n"
"                     patch centre's image moves right by 6 %% of the width over 0.25 s on a\n"
"                     smooth (1-cos)/2 ramp (pan), or by 3 %% of the width between two frames\n"
"                     (bump: the first frame at or after the start is moved); the view stays\n"
"                     moved afterwards. In phantom.txt, so the truth follows it\n"
"  --camera-motion-at SECONDS\n"
"                     when the motion starts (default: 40 %% into the sequence)\n"
"  --first-beat       the heart rests (activation 0) from frame 0, then its first contraction\n"
"                     (phase 0 to pi) runs 4 times faster than the beats after it, which\n"
"                     follow at the normal rate; respiration is not affected\n"
"  --first-beat-at SECONDS\n"
"                     how long the heart rests first (default 0.5)\n"
"                     (--camera-motion and --first-beat happen once: not with --periodic)\n"
"  --markers N        number of markers (default 16 exvivo, 14 invivo)\n"
"  --tag-size MM      edge of a tag's black border in mm (default 10 exvivo, 8 invivo)\n"
"  --family NAME      tag36h11 (default), tag25h9, tag16h5 or tagStandard41h12\n"
"  --ids A,B,...      marker ids (default 0..N-1); sets N when --markers is absent\n"
"  --only-markers A,B,...\n"
"                     the markers laid out as without it, then only those with these ids\n"
"                     drawn and in markers.csv, the others' tissue bare (e.g. the four at\n"
"                     the corners of the field, without the stickers between them); the\n"
"                     same texture, motion, instrument and blood as without it\n"
"  --distortion K1,K2,P1,P2,K3\n"
"                     OpenCV lens distortion of every camera (default none)\n"
"  --noise SIGMA      read noise in DN (default 1.5; shot noise grows with the signal; 0: none)\n"
"  --exposure GAIN    exposure gain on the rendered radiance (default 1; highlights clip)\n"
"  --texture-contrast F\n"
"                     the tissue texture's colours about their mean scaled by F (default 1;\n"
"                     0.5 halves its contrast: landmarks must not find the phantom easier\n"
"                     than tissue); in phantom.txt\n"
"  --texture-filter nearest-mip|trilinear\n"
"                     how the tissue texture is minified: from the nearest mip level (the\n"
"                     default, as every measured table was rendered), or trilinear (the two\n"
"                     nearest levels blended), which has no seam sweeping over the tissue\n"
"                     where the level changes as the heart scales; tissue has none. The tags\n"
"                     keep the nearest level. In phantom.txt\n"
"  --calib-target checkerboard:COLSxROWS:SQUARE_MM\n"
"                     instead of the heart: a planar checkerboard (COLS x ROWS inner corners,\n"
"                     one count odd and one even; squares SQUARE_MM) in --frames poses\n"
"                     (default 20), each seen whole by every camera, tilted 15-40 degrees in\n"
"                     directions spread round the circle (every fifth nearly frontal); lens\n"
"                     distortion, noise and exposure as for the heart. Writes cam*.y4m,\n"
"                     calibration.yaml (the truth) and board.csv (frame,camera,corner,x,y,X,Y,Z:\n"
"                     inner corner r * COLS + c at board (c, r) * SQUARE_MM, its pixel and world\n"
"                     position), no markers.csv or phantom.txt\n"
SH_CLI_USAGE
"\n"
"Writes DIR/cam0.y4m (cam1, cam2: Y4M 4:2:0, BT.601 limited range), DIR/markers.csv\n"
"(frame,camera,id,point,x,y,visible,X,Y,Z: point c = tag centre, 0-3 its corners in\n"
"libapriltag's order; x,y OpenCV pixels of the distorted image, pixel centres at integers;\n"
"X,Y,Z world mm), DIR/calibration.yaml (OpenCV FileStorage: K_i, dist_i, R_i, t_i, P_i) and\n"
"DIR/phantom.txt (the analytic motion, reloaded by tools/phantom's truth library).\n"
"Environment: LP_NUM_THREADS (llvmpipe threads, default: the number of CPUs).\n");
}

typedef struct {
    uint8_t *rgba;
    int camera, frame, full;
} slot;

typedef struct {
    pthread_mutex_t mu;
    pthread_cond_t cv;
    slot slots[2];
    int quit;
    sh_status status;
    char error[512];
    const phantom_model *m;
    rd_sensor sensor;
    sh_y4m_writer *writers[PHANTOM_MAX_CAMERAS];
    uint8_t *i420, *scratch;
} pipeline;

static void *writer_main(void *arg)
{
    pipeline *p = arg;
    int next = 0;
    for (;;) {
        pthread_mutex_lock(&p->mu);
        while (!p->slots[next].full && !p->quit) pthread_cond_wait(&p->cv, &p->mu);
        if (!p->slots[next].full) {
            pthread_mutex_unlock(&p->mu);
            return NULL;
        }
        slot *s = &p->slots[next];
        int failed = p->status != SH_OK;
        pthread_mutex_unlock(&p->mu);
        sh_status st = SH_OK;
        if (!failed) {
            const phantom_model *m = p->m;
            rd_sensor_to_i420(&p->sensor, s->camera, s->frame, s->rgba, m->width, m->height, p->i420,
                              p->scratch);
            sh_image img;
            st = sh_image_wrap(&img, SH_PIX_I420, m->width, m->height, p->i420);
            if (st == SH_OK) st = sh_y4m_writer_write(p->writers[s->camera], &img);
        }
        pthread_mutex_lock(&p->mu);
        if (st != SH_OK) {
            snprintf(p->error, sizeof p->error, "%s", sh_error_message());
            p->status = st;
        }
        s->full = 0;
        pthread_cond_broadcast(&p->cv);
        pthread_mutex_unlock(&p->mu);
        next ^= 1;
    }
}

static int parse_list(const char *s, double *out, int max)
{
    int n = 0;
    while (*s && n < max) {
        char *end;
        errno = 0;
        out[n++] = strtod(s, &end);
        if (end == s || errno) return -1;
        s = end;
        if (*s == ',') s++;
        else if (*s) return -1;
    }
    return *s ? -1 : n;
}

/* A comma-separated list of at most PHANTOM_MAX_MARKERS whole numbers from lo to INT_MAX (--ids,
 * --only-markers) into out: their count, or 0 with the reason logged. Each is compared as a
 * double before it is converted: a value beyond int's range would not convert. */
static int parse_ids(const char *name, const char *s, double lo, const char *what, int *out)
{
    double v[PHANTOM_MAX_MARKERS];
    int n = parse_list(s, v, PHANTOM_MAX_MARKERS);
    if (n <= 0) {
        sh_log_error("%s '%s': comma-separated ids, at most %d", name, s, PHANTOM_MAX_MARKERS);
        return 0;
    }
    for (int i = 0; i < n; i++) {
        if (!(v[i] >= lo && v[i] <= INT_MAX) || v[i] != floor(v[i])) {
            sh_log_error("%s: '%g' is not %s", name, v[i], what);
            return 0;
        }
        out[i] = (int)v[i];
    }
    return n;
}

static int parse_int(const char *s, long lo, long hi, long *out)
{
    char *end;
    errno = 0;
    long v = strtol(s, &end, 10);
    if (end == s || *end || errno || v < lo || v > hi) return 0;
    *out = v;
    return 1;
}

static int parse_double(const char *s, double *out)
{
    char *end;
    errno = 0;
    *out = strtod(s, &end);
    return end != s && !*end && !errno;
}

static int make_dir(const char *path)
{
    char tmp[4096];
    if (snprintf(tmp, sizeof tmp, "%s", path) >= (int)sizeof tmp) return -1;
    for (char *p = tmp + 1; *p; p++)
        if (*p == '/') {
            *p = '\0';
            if (mkdir(tmp, 0777) != 0 && errno != EEXIST) return -1;
            *p = '/';
        }
    if (mkdir(tmp, 0777) != 0 && errno != EEXIST) return -1;
    struct stat st;
    return stat(tmp, &st) == 0 && S_ISDIR(st.st_mode) ? 0 : -1;
}

static double now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec + ts.tv_nsec * 1e-9;
}

static sh_status write_calibration(const phantom_model *m, const char *path)
{
    sh_calib cal;
    phantom_calibration(m, &cal);
    return sh_calib_write(path, &cal);
}

static void fmt_num(char *buf, size_t n, double v)
{
    if (v != v) snprintf(buf, n, "nan");
    else snprintf(buf, n, "%.6f", v);
}

static int write_markers(FILE *f, const phantom_model *m, int frame)
{
    static const char names[PHANTOM_POINTS] = {'0', '1', '2', '3', 'c'};
    double t = frame / m->fps;
    for (int c = 0; c < m->num_cameras; c++)
        for (int i = 0; i < m->num_markers; i++)
            for (int k = 0; k < PHANTOM_POINTS; k++) {
                double X[3], x = NAN, y = NAN;
                phantom_marker_point(m, i, k, t, X);
                int front = phantom_project(&m->cam[c], X, &x, &y);
                int vis = front && phantom_marker_visible(m, c, t, i, k);
                char xs[32], ys[32];
                fmt_num(xs, sizeof xs, front ? x : NAN);
                fmt_num(ys, sizeof ys, front ? y : NAN);
                if (fprintf(f, "%d,%d,%d,%c,%s,%s,%d,%.6f,%.6f,%.6f\n", frame, c, m->marker[i].id,
                            names[k], xs, ys, vis, X[0], X[1], X[2]) < 0)
                    return -1;
            }
    return 0;
}

/* The board's inner corners: their true pixels in every camera (the calibration's truth). */
static int write_board_corners(FILE *f, const phantom_model *m, const rd_board *b, const rd_board_pose *p,
                               int frame)
{
    for (int c = 0; c < m->num_cameras; c++)
        for (int r = 0; r < b->rows; r++)
            for (int k = 0; k < b->cols; k++) {
                double X[3], x = NAN, y = NAN;
                rd_board_point(p, k * b->square, r * b->square, X);
                phantom_project(&m->cam[c], X, &x, &y);
                if (fprintf(f, "%d,%d,%d,%.6f,%.6f,%.6f,%.6f,%.6f\n", frame, c, r * b->cols + k, x, y, X[0],
                            X[1], X[2]) < 0)
                    return -1;
            }
    return 0;
}

/* llvmpipe and LLVM keep caches for the life of the process; under LeakSanitizer (the ASan test
 * build) they are not our leaks. */
const char *__lsan_default_suppressions(void);
const char *__lsan_default_suppressions(void)
{
    return "leak:libOSMesa\nleak:libLLVM\nleak:libgallium\nleak:libglapi\n";
}
const char *__lsan_default_options(void);
const char *__lsan_default_options(void)
{
    return "print_suppressions=0";
}

/* What the command line asks for; o.dist and o.ids point into it. */
typedef struct {
    phantom_options o;
    const char *out;
    double dist[5];
    int ids[PHANTOM_MAX_MARKERS], only[PHANTOM_MAX_MARKERS];
    rd_board board;
    int board_mode;
} render_args;

/* Fills *a from the command line; returns -1 to go on, or the exit status (0 after --help, 2 for
 * a usage error). Over 80 lines because it is one case a line for each of its options, read as a
 * table beside the option list: split, each option's check would sit away from its name. */
static int parse_args(int argc, char **argv, render_args *a)
{
    phantom_options *o = &a->o;
    phantom_options_default(o);
    a->out = NULL;
    a->board_mode = 0;
    enum { O_PRESET = 256, O_FRAMES, O_CAMERAS, O_WIDTH, O_HEIGHT, O_SEED, O_OCC, O_BPM, O_MARKERS,
           O_TAG, O_FAMILY, O_IDS, O_ONLY, O_FPS, O_DIST, O_NOISE, O_EXPOSURE, O_TEXTURE_CONTRAST, O_TEXTURE_FILTER, O_OUT,
           O_TARGET, O_PERIODIC, O_CAM_MOTION, O_CAM_MOTION_AT, O_FIRST_BEAT, O_FIRST_BEAT_AT, O_RIG, O_BLOOD_SPREAD };
    static const struct option opts[] = {
        {"preset", 1, 0, O_PRESET}, {"frames", 1, 0, O_FRAMES}, {"cameras", 1, 0, O_CAMERAS},
        {"width", 1, 0, O_WIDTH}, {"height", 1, 0, O_HEIGHT}, {"seed", 1, 0, O_SEED},
        {"occlusions", 0, 0, O_OCC}, {"bpm", 1, 0, O_BPM}, {"markers", 1, 0, O_MARKERS},
        {"tag-size", 1, 0, O_TAG}, {"family", 1, 0, O_FAMILY}, {"ids", 1, 0, O_IDS}, {"only-markers", 1, 0, O_ONLY},
        {"fps", 1, 0, O_FPS}, {"distortion", 1, 0, O_DIST}, {"noise", 1, 0, O_NOISE},
        {"exposure", 1, 0, O_EXPOSURE}, {"texture-contrast", 1, 0, O_TEXTURE_CONTRAST},
        {"texture-filter", 1, 0, O_TEXTURE_FILTER}, {"out", 1, 0, O_OUT},
        SH_CLI_OPTIONS,
        {"calib-target", 1, 0, O_TARGET},
        {"periodic", 0, 0, O_PERIODIC}, {"camera-motion", 1, 0, O_CAM_MOTION},
        {"camera-motion-at", 1, 0, O_CAM_MOTION_AT}, {"first-beat", 0, 0, O_FIRST_BEAT},
        {"first-beat-at", 1, 0, O_FIRST_BEAT_AT}, {"rig", 1, 0, O_RIG}, {"blood-spread", 1, 0, O_BLOOD_SPREAD}, {0, 0, 0, 0}};
    int rig = -1, set_cameras = 0, set_width = 0, set_height = 0; /* rig: 0 small, 1 paper */
    const char *heart_option = NULL; /* the last option that only the heart uses */
    int ch;
    long lv;
    double dv;
#define BAD(...) do { sh_log_error(__VA_ARGS__); return 2; } while (0)
    int idx;
    opterr = 0;
    while ((ch = getopt_long(argc, argv, ":h", opts, &idx)) != -1) {
        if (ch == O_PRESET || ch == O_OCC || ch == O_BPM || ch == O_MARKERS || ch == O_TAG || ch == O_FAMILY ||
            ch == O_IDS || ch == O_ONLY || ch == O_PERIODIC || ch == O_CAM_MOTION || ch == O_CAM_MOTION_AT || ch == O_FIRST_BEAT ||
            ch == O_FIRST_BEAT_AT || ch == O_TEXTURE_CONTRAST || ch == O_TEXTURE_FILTER || ch == O_BLOOD_SPREAD)
            heart_option = opts[idx].name;
        switch (ch) {
        case O_PRESET: o->preset = optarg; break;
        case O_FRAMES: if (!parse_int(optarg, 1, 1000000, &lv)) BAD("--frames '%s': a count from 1", optarg); o->frames = (int)lv; break;
        case O_CAMERAS: if (!parse_int(optarg, 1, 3, &lv)) BAD("--cameras '%s': 1, 2 or 3", optarg); o->cameras = (int)lv; set_cameras = 1; break;
        case O_WIDTH: if (!parse_int(optarg, 16, 8192, &lv)) BAD("--width '%s': 16 to 8192", optarg); o->width = (int)lv; set_width = 1; break;
        case O_HEIGHT: if (!parse_int(optarg, 16, 8192, &lv)) BAD("--height '%s': 16 to 8192", optarg); o->height = (int)lv; set_height = 1; break;
        case O_RIG:
            if (!strcmp(optarg, "small")) rig = 0;
            else if (!strcmp(optarg, "paper")) rig = 1;
            else BAD("--rig '%s': small or paper", optarg);
            break;
        case O_SEED: {
            char *end;
            errno = 0;
            unsigned long long s = strtoull(optarg, &end, 10);
            if (end == optarg || *end || errno || optarg[0] == '-') BAD("--seed '%s': a non-negative integer", optarg);
            o->seed = s;
            break;
        }
        case O_OCC: o->occlusions = 1; break;
        case O_BPM: if (!parse_double(optarg, &dv) || !(dv > 0 && dv <= 300)) BAD("--bpm '%s': 0 to 300", optarg); o->bpm = dv; break;
        case O_MARKERS: if (!parse_int(optarg, 1, PHANTOM_MAX_MARKERS, &lv)) BAD("--markers '%s': 1 to %d", optarg, PHANTOM_MAX_MARKERS); o->markers = (int)lv; break;
        case O_TAG: if (!parse_double(optarg, &dv) || !(dv > 0)) BAD("--tag-size '%s': millimetres > 0", optarg); o->tag_size = dv; break;
        case O_FAMILY: o->family = optarg; break;
        case O_IDS:
            if (!(o->num_ids = parse_ids("--ids", optarg, INT_MIN, "an integer", a->ids))) return 2;
            o->ids = a->ids;
            break;
        case O_ONLY:
            if (!(o->num_only = parse_ids("--only-markers", optarg, 0, "an id", a->only))) return 2;
            o->only = a->only;
            break;
        case O_FPS: if (!parse_double(optarg, &dv) || !(dv > 0 && dv <= 1000)) BAD("--fps '%s': 0 to 1000", optarg); o->fps = dv; break;
        case O_DIST: if (parse_list(optarg, a->dist, 5) != 5) BAD("--distortion '%s': five numbers k1,k2,p1,p2,k3", optarg); o->dist = a->dist; break;
        case O_NOISE: if (!parse_double(optarg, &dv) || !(dv >= 0 && dv <= 100)) BAD("--noise '%s': 0 to 100 DN", optarg); o->noise = dv; break;
        case O_EXPOSURE: if (!parse_double(optarg, &dv) || !(dv > 0 && dv <= 16)) BAD("--exposure '%s': a gain in (0, 16]", optarg); o->exposure = dv; break;
        case O_TEXTURE_FILTER:
            if (strcmp(optarg, "nearest-mip") == 0) o->texture_trilinear = 0;
            else if (strcmp(optarg, "trilinear") == 0) o->texture_trilinear = 1;
            else BAD("--texture-filter '%s': nearest-mip or trilinear", optarg);
            break;
        case O_TEXTURE_CONTRAST: if (!parse_double(optarg, &dv) || !(dv > 0 && dv <= 16)) BAD("--texture-contrast '%s': a factor in (0, 16]", optarg); o->texture_contrast = dv; break;
        case O_OUT: a->out = optarg; break;
        case O_PERIODIC: o->periodic = 1; break;
        case O_CAM_MOTION:
            if (!strcmp(optarg, "pan")) o->camera_motion = PHANTOM_CAM_PAN;
            else if (!strcmp(optarg, "bump")) o->camera_motion = PHANTOM_CAM_BUMP;
            else BAD("--camera-motion '%s': pan or bump", optarg);
            break;
        case O_CAM_MOTION_AT: if (!parse_double(optarg, &dv) || !(dv > 0 && dv < 1e6)) BAD("--camera-motion-at '%s': seconds > 0", optarg); o->camera_motion_at = dv; break;
        case O_FIRST_BEAT: o->first_beat = 1; break;
        case O_FIRST_BEAT_AT: if (!parse_double(optarg, &dv) || !(dv > 0 && dv < 1e6)) BAD("--first-beat-at '%s': seconds > 0", optarg); o->first_beat_at = dv; break;
        case O_BLOOD_SPREAD: if (!parse_double(optarg, &dv) || !(dv > 0 && dv <= 60)) BAD("--blood-spread '%s': seconds in (0, 60]", optarg); o->blood_spread = dv; break;
        case O_TARGET:
            if (rd_board_parse(optarg, &a->board) != SH_OK) BAD("%s", sh_error_message());
            a->board_mode = 1;
            break;
        case 'h': usage(stdout); return 0;
        default: { int rc = sh_cli_option(&cli, ch, argv); if (rc >= 0) return rc; } break;
        }
    }
    if (optind < argc) return sh_cli_usage_error(&cli, "unexpected argument '%s'", argv[optind]);
    if (!a->out) return sh_cli_usage_error(&cli, "--out DIR is required");
    if (a->board_mode && heart_option) BAD("--%s: the heart's option, not the board's (--calib-target)", heart_option);
    if (o->camera_motion_at > 0 && !o->camera_motion) BAD("--camera-motion-at: with --camera-motion pan|bump only");
    if (o->first_beat_at > 0 && !o->first_beat) BAD("--first-beat-at: with --first-beat only");
    if (o->blood_spread > 0 && !o->occlusions) BAD("--blood-spread: with --occlusions only");
#undef BAD
    if (a->board_mode && o->frames <= 0) o->frames = 20;
    if (rig < 0) rig = a->board_mode;
    if (!set_cameras) o->cameras = rig ? 3 : 1;
    if (!set_width) o->width = rig ? 1920 : 640;
    if (!set_height) o->height = rig ? 1080 : 360;
    return -1;
}

/* One render's resources: everything that done() releases, zeroed before the first is taken. */
typedef struct {
    const render_args *a;
    const phantom_model *m;
    rd_board_pose *poses;
    pipeline p;
    FILE *csv;
    rd_scene *scene;
    rd_board_raster *raster[PHANTOM_MAX_CAMERAS];
    rd_texture drape[PHANTOM_MAX_CAMERAS];
    pthread_t thread;
    int thread_ok;
} render_run;

#define FAIL() do { sh_log_error("%s", sh_error_message()); return -1; } while (0)

/* The buffers, the files that do not depend on the frames, the Y4M writers, the backgrounds and
 * the scene (or the board's rasterizers); 0, or -1 after logging why. */
static int open_outputs(render_run *r)
{
    const phantom_model *m = r->m;
    const char *out = r->a->out;
    int board_mode = r->a->board_mode;
    pipeline *p = &r->p;
    char path[4200];
    size_t frame_bytes = (size_t)m->width * m->height * 4;
    p->slots[0].rgba = malloc(frame_bytes);
    p->slots[1].rgba = malloc(frame_bytes);
    p->i420 = malloc(sh_image_packed_size(SH_PIX_I420, m->width, m->height));
    p->scratch = malloc((size_t)m->width * m->height);
    if (!p->slots[0].rgba || !p->slots[1].rgba || !p->i420 || !p->scratch) {
        sh_log_error("out of memory for %dx%d frames", m->width, m->height);
        return -1;
    }
    snprintf(path, sizeof path, "%s/%s", out, PHANTOM_PARAMS_FILE);
    if (!board_mode && phantom_model_write(m, path) != SH_OK) FAIL();
    snprintf(path, sizeof path, "%s/calibration.yaml", out);
    if (write_calibration(m, path) != SH_OK) FAIL();
    snprintf(path, sizeof path, "%s/%s", out, board_mode ? "board.csv" : "markers.csv");
    r->csv = fopen(path, "w");
    if (!r->csv) {
        sh_log_error("%s: %s", path, strerror(errno));
        return -1;
    }
    fprintf(r->csv, "%s\n", board_mode ? "frame,camera,corner,x,y,X,Y,Z" : PHANTOM_CSV_HEADER);
    sh_y4m_header hdr;
    memset(&hdr, 0, sizeof hdr);
    hdr.width = m->width;
    hdr.height = m->height;
    hdr.format = SH_PIX_I420;
    hdr.siting = SH_CHROMA_CENTER;
    hdr.fps_num = m->fps == (int)m->fps ? (int)m->fps : (int)(m->fps * 1000 + 0.5);
    hdr.fps_den = m->fps == (int)m->fps ? 1 : 1000;
    hdr.aspect_num = hdr.aspect_den = 1;
    hdr.interlace = 'p';
    if (r->a->o.periodic) snprintf(hdr.extra, sizeof hdr.extra, "%s", SH_Y4M_LOOP_SEAMLESS);
    for (int c = 0; c < m->num_cameras; c++) {
        snprintf(path, sizeof path, "%s/cam%d.y4m", out, c);
        if (sh_y4m_writer_open(path, &hdr, &p->writers[c]) != SH_OK) FAIL();
    }
    for (int c = 0; c < m->num_cameras; c++) {
        if (rd_texture_drape(m->seed, c, m->width, m->height, &r->drape[c]) != SH_OK) FAIL();
        p->sensor.background[c] = r->drape[c].rgb;
    }
    if (board_mode) {
        for (int c = 0; c < m->num_cameras; c++)
            if (rd_board_raster_create(m, c, &r->raster[c]) != SH_OK) FAIL();
    } else if (rd_scene_create(m, &r->scene) != SH_OK) {
        FAIL();
    }
    return 0;
}

/* Draws frame f of every camera into the ring and writes its truth rows; 0, or -1 after logging. */
static int render_frame(render_run *r, int f, int *cur)
{
    const phantom_model *m = r->m;
    const render_args *a = r->a;
    pipeline *p = &r->p;
    if (!a->board_mode) rd_scene_update(r->scene, f / m->fps);
    for (int c = 0; c < m->num_cameras; c++) {
        pthread_mutex_lock(&p->mu);
        while (p->slots[*cur].full) pthread_cond_wait(&p->cv, &p->mu);
        sh_status wst = p->status;
        pthread_mutex_unlock(&p->mu);
        if (wst != SH_OK) {
            sh_log_error("%s", p->error);
            return -1;
        }
        sh_status dst = a->board_mode ? rd_board_draw(r->raster[c], &m->cam[c], &a->board, &r->poses[f],
                                                      r->drape[c].rgb, p->slots[*cur].rgba)
                                      : rd_scene_draw(r->scene, c, p->slots[*cur].rgba);
        if (dst != SH_OK) FAIL();
        pthread_mutex_lock(&p->mu);
        p->slots[*cur].camera = c;
        p->slots[*cur].frame = f;
        p->slots[*cur].full = 1;
        pthread_cond_broadcast(&p->cv);
        pthread_mutex_unlock(&p->mu);
        *cur ^= 1;
    }
    if ((a->board_mode ? write_board_corners(r->csv, m, &a->board, &r->poses[f], f) : write_markers(r->csv, m, f)) !=
        0) {
        sh_log_error("%s: write error: %s", a->board_mode ? "board.csv" : "markers.csv", strerror(errno));
        return -1;
    }
    return 0;
}

#undef FAIL

/* Stops the writer, closes the outputs and frees everything; returns rc, or 1 where a late write
 * failed. */
static int finish(render_run *r, int rc, int quiet, double t_start)
{
    const phantom_model *m = r->m;
    pipeline *p = &r->p;
    if (r->thread_ok) {
        pthread_mutex_lock(&p->mu);
        p->quit = 1;
        pthread_cond_broadcast(&p->cv);
        pthread_mutex_unlock(&p->mu);
        pthread_join(r->thread, NULL);
        if (rc == 0 && p->status != SH_OK) {
            sh_log_error("%s", p->error);
            rc = 1;
        }
    }
    if (rc == 0 && !quiet) {
        double el = now() - t_start;
        sh_log_info("%d frames x %d cameras, %dx%d, in %.1f s (%.1f frames/s, %.1f "
                    "images/s, setup included)", m->frames, m->num_cameras, m->width, m->height, el,
                    m->frames / el, m->frames * m->num_cameras / el);
    }
    for (int c = 0; c < m->num_cameras; c++)
        if (p->writers[c] && sh_y4m_writer_close(p->writers[c]) != SH_OK && rc == 0) {
            sh_log_error("%s", sh_error_message());
            rc = 1;
        }
    if (r->csv && (ferror(r->csv) | fclose(r->csv)) && rc == 0) {
        sh_log_error("%s: write error", r->a->board_mode ? "board.csv" : "markers.csv");
        rc = 1;
    }
    rd_scene_destroy(r->scene);
    for (int c = 0; c < PHANTOM_MAX_CAMERAS; c++) rd_board_raster_destroy(r->raster[c]);
    free(r->poses);
    for (int c = 0; c < PHANTOM_MAX_CAMERAS; c++) rd_texture_free(&r->drape[c]);
    free(p->slots[0].rgba);
    free(p->slots[1].rgba);
    free(p->i420);
    free(p->scratch);
    pthread_mutex_destroy(&p->mu);
    pthread_cond_destroy(&p->cv);
    return rc;
}

int main(int argc, char **argv)
{
    sh_log_setup(SH_LOG_TOOL, "stillheart-render", SH_LOG_INFO);
    static render_args a;
    int prc = parse_args(argc, argv, &a);
    if (prc >= 0) return prc;
    int quiet = sh_log_get_level() < SH_LOG_INFO;

    static phantom_model m;
    if (phantom_model_build(&a.o, &m) != SH_OK) {
        sh_log_error("%s", sh_error_message());
        return 2;
    }
    /* the board's poses before anything is written: a board too large for the view is refused */
    rd_board_pose *poses = NULL;
    if (a.board_mode) {
        poses = malloc(sizeof *poses * (size_t)m.frames);
        if (!poses) {
            sh_log_error("out of memory for %d poses", m.frames);
            return 1;
        }
        if (rd_board_poses(&m, &a.board, m.frames, m.seed, poses) != SH_OK) {
            sh_log_error("%s", sh_error_message());
            free(poses);
            return 2;
        }
    }
    if (make_dir(a.out) != 0) {
        sh_log_error("%s: cannot create the folder: %s", a.out, strerror(errno));
        free(poses);
        return 1;
    }
    if (!getenv("LP_NUM_THREADS")) {
        long n = sysconf(_SC_NPROCESSORS_ONLN);
        char buf[24];
        snprintf(buf, sizeof buf, "%ld", n > 0 && n < 1000 ? n : 1);
        setenv("LP_NUM_THREADS", buf, 0);
    }
    rd_sensor_init();
    double t_start = now();

    static render_run r;
    r.a = &a;
    r.m = &m;
    r.poses = poses;
    pthread_mutex_init(&r.p.mu, NULL);
    pthread_cond_init(&r.p.cv, NULL);
    r.p.m = &m;
    r.p.sensor.gain = m.exposure;
    r.p.sensor.read_noise = m.noise;
    r.p.sensor.seed = m.seed;
    if (open_outputs(&r) != 0) return finish(&r, 1, quiet, t_start);
    if (pthread_create(&r.thread, NULL, writer_main, &r.p) != 0) {
        sh_log_error("cannot start the writer thread");
        return finish(&r, 1, quiet, t_start);
    }
    r.thread_ok = 1;
    sh_cli_progress bar;
    sh_cli_progress_start(&bar, "render", m.frames, "frames");
    int cur = 0;
    for (int f = 0; f < m.frames; f++) {
        if (render_frame(&r, f, &cur) != 0) return finish(&r, 1, quiet, t_start);
        sh_cli_progress_update(&bar, f + 1);
    }
    sh_cli_progress_end(&bar);
    return finish(&r, 0, quiet, t_start);
}
