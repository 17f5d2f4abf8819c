/* The daemon's pipeline pieces, opened from one config, and their swap when SIGHUP brings a new
 * config.
 *
 * A reload opens the new pieces beside the running ones and swaps them in only once every one of
 * them opened, so a config that cannot run leaves the running pipeline as it was. Two pieces
 * cannot be opened beside their predecessor: the cameras (a V4L2 device opens once, so the old
 * ones close first and are reopened when the new ones fail) and a display segment that keeps its
 * name with another geometry (the name is the segment: it is replaced last, when nothing else can
 * fail). */
#include <stdarg.h>
#include <stdio.h>
#include <string.h>
#include <sys/stat.h>

#include "run_pipeline.h"
#include "stillheart/log.h"

static const char *shm_name(const sh_config *c) { return strncmp(c->sink, "shm:", 4) ? NULL : c->sink + 4; }

static sh_status display_create(const sh_config *cfg, const sh_y4m_header *h, sh_display_writer **out)
{
    sh_status st = sh_display_writer_create(shm_name(cfg), h->format, h->width, h->height, cfg->slots,
                                            sh_y4m_header_full_range(h), cfg->group[0] ? cfg->group : NULL, out);
    return st == SH_OK ? SH_OK : sh_error_set(st, "[sink] display: %s", sh_error_message());
}

/* The record's XSTILLHEART tag (y4m.h): the method that stabilizes what it holds, spelled as
 * `stillheart warp` and `warp3d` tag theirs, so stillheart-eval measures the right map. */
static void record_tag(const sh_config *cfg, char *value, size_t cap)
{
    sh_interp_params method;
    char name[32];
    sh_config_method(cfg, &method);
    sh_interp_params_name(&method, name, sizeof name);
    snprintf(value, cap, "%s:%s", cfg->calibration[0] ? "method3d" : "method", name);
}

/* [sink] record opened with the frames' header and its tag; the error says which key. */
static sh_status record_open(const sh_config *cfg, const sh_y4m_header *hdr, run_record **out)
{
    sh_y4m_header tagged = *hdr;
    char value[64];
    record_tag(cfg, value, sizeof value);
    sh_status st = sh_y4m_header_set_tag(&tagged, SH_Y4M_STILLHEART, value);
    if (st == SH_OK) st = run_record_open(cfg->record, &tagged, cfg->record_sync_ms, out);
    return st == SH_OK ? SH_OK : sh_error_set(st, "[sink] record: %s", sh_error_message());
}

/* [sink] v4l2 opened for the frames; the error says which key. */
static sh_status v4l2_open(const sh_config *cfg, const sh_y4m_header *hdr, run_v4l2out **out)
{
    sh_status st = run_v4l2out_open(cfg->v4l2, hdr, out);
    if (st != SH_OK) return sh_error_set(st, "[sink] v4l2: %s", sh_error_message());
    sh_log_info("[sink] v4l2: publishing %dx%d %s frames to %s", hdr->width, hdr->height, sh_pixfmt_name(hdr->format),
                cfg->v4l2);
    return SH_OK;
}

/* Closes the V4L2 output, saying how many frames it took and did not. */
void run_pipeline_v4l2_close(run_v4l2out *o)
{
    if (!o) return;
    unsigned long long taken = run_v4l2out_written(o), missed = run_v4l2out_not_taken(o);
    sh_log_msg(missed ? SH_LOG_WARN : SH_LOG_INFO, "[sink] v4l2: %s: %llu frames written, %llu not taken by the device",
               run_v4l2out_path(o), taken, missed);
    run_v4l2out_close(o);
}

/* The frame shown while the output camera is lost: black in the display's format and range. */
static sh_status black_frame(const sh_y4m_header *hdr, sh_image *img)
{
    sh_status st = sh_image_create(img, hdr->format, hdr->width, hdr->height);
    if (st != SH_OK) return st;
    uint8_t luma = sh_y4m_header_full_range(hdr) || hdr->format == SH_PIX_RGB24 ? 0 : 16;
    for (int p = 0; p < img->num_planes; p++)
        for (int y = 0; y < img->plane[p].height; y++)
            memset(img->plane[p].data + (size_t)y * img->plane[p].stride, p ? 128 : luma,
                   (size_t)img->plane[p].width * (size_t)sh_pixfmt_channels(hdr->format));
    return SH_OK;
}

/* Opens the cameras and, with start, starts them; nothing stays open on error. */
static sh_status source_open(const sh_config *cfg, int start, run_source **out)
{
    sh_status st = run_source_open(cfg, out);
    if (st != SH_OK || !start || (st = run_source_start(*out)) == SH_OK) return st;
    char m[512];
    snprintf(m, sizeof m, "%s", sh_error_message()); /* destroying logs, and may set errors */
    run_source_destroy(*out);
    *out = NULL;
    return sh_error_set(st, "%s", m);
}

/* Which file this start records to: another than the configured one when that was taken. */
static void log_record(const sh_config *cfg, const run_record *rec)
{
    const char *path = run_record_path(rec), *want = strncmp(cfg->record, "png:", 4) ? cfg->record : cfg->record + 4;
    if (strcmp(path, want))
        sh_log_info("[sink] record: %s holds an earlier recording (never written over): recording to %s", want, path);
    else
        sh_log_info("[sink] record: recording to %s", path);
}

static sh_status record_close(run_record *rec)
{
    if (!rec) return SH_OK;
    if (run_record_skipped(rec))
        sh_log_warn("[sink] record: %llu frames not recorded (the PNG writer fell behind)",
            (unsigned long long)run_record_skipped(rec));
    if (run_record_close(rec) == SH_OK) return SH_OK;
    sh_log_error("[sink] record: %s", sh_error_message());
    return SH_EIO;
}

/* The files processing reads at start, as stat sees them: an operator who rewrites the
 * calibration or the points file in place and reloads means the new one. */
static void stamp(const char *path, run_file_stamp *s)
{
    struct stat sb;
    memset(s, 0, sizeof *s);
    if (path[0] && stat(path, &sb) == 0) {
        s->ino = (int64_t)sb.st_ino;
        s->size = (int64_t)sb.st_size;
        s->mtime_ns = (int64_t)sb.st_mtim.tv_sec * 1000000000 + sb.st_mtim.tv_nsec;
    }
}

static void stamps(run_pipeline *p)
{
    stamp(p->cfg.calibration, &p->calib_file);
    stamp(p->cfg.points, &p->points_file);
}

/* Every configured camera a replayed file. */
static int all_replays(const sh_config *cfg)
{
    int n = sh_config_cameras(cfg);
    for (int i = 0; i < n; i++)
        if (strncmp(cfg->camera[i].spec, "y4m:", 4) && strncmp(cfg->camera[i].spec, "rec:", 4)) return 0;
    return n > 0;
}

sh_status run_pipeline_open(run_pipeline *p, const sh_config *cfg)
{
    memset(p, 0, sizeof *p);
    p->cfg = *cfg;
    stamps(p); /* before the files are read: one rewritten meanwhile is read again at a reload */
    sh_status st = run_source_open(cfg, &p->src);
    /* input a restart cannot mend: replayed files (every camera a y4m: or rec: file), a camera
     * whose frames are over [source] max_frame_pixels, and what processing reads (points,
     * calibration) */
    int input = st != SH_OK && (all_replays(cfg) || st == SH_ERANGE);
    if (st == SH_OK) {
        p->hdr = *run_source_header(p->src);
        st = run_proc_create(cfg, &p->hdr, run_source_fps(p->src), run_source_cameras(p->src), &p->proc);
        input = st != SH_OK;
        if (st == SH_OK) p->out_hdr = *run_proc_header(p->proc);
    }
    if (st == SH_OK && shm_name(cfg)) st = display_create(cfg, &p->out_hdr, &p->disp);
    if (st == SH_OK) st = black_frame(&p->out_hdr, &p->black);
    if (st == SH_OK && cfg->record[0]) st = record_open(cfg, &p->out_hdr, &p->rec);
    if (st == SH_OK && p->rec) log_record(cfg, p->rec);
    if (st == SH_OK && cfg->v4l2[0]) st = v4l2_open(cfg, &p->out_hdr, &p->v4l2);
    if (st == SH_OK && cfg->control[0] &&
        (st = run_ctl_open(cfg->control, cfg->control_group, cfg->group, &p->ctl)) != SH_OK)
        st = sh_error_set(st, "[run] control: %s", sh_error_message());
    if (st != SH_OK) {
        char m[512];
        snprintf(m, sizeof m, "%s", sh_error_message());
        run_pipeline_close(p);
        return sh_error_set(input ? SH_EINVAL : st == SH_EINVAL ? SH_EIO : st, "%s", m);
    }
    return SH_OK;
}

sh_status run_pipeline_start(run_pipeline *p) { return run_source_start(p->src); }

uint64_t run_pipeline_dropped(run_pipeline *p) { return p->dropped_before + (p->src ? run_source_dropped(p->src) : 0); }

int run_pipeline_builds(const run_pipeline *p) { return p->builds_before + (p->proc ? run_proc_builds(p->proc) : 0); }
int run_pipeline_refined(const run_pipeline *p) { return p->refined_before + (p->proc ? run_proc_refined(p->proc) : 0); }

/* Appends ", text" (the first without the comma) to out. */
static __attribute__((format(printf, 3, 4))) void add(char *out, size_t cap, const char *fmt, ...)
{
    size_t len = strlen(out);
    if (len && len + 2 < cap) {
        memcpy(out + len, ", ", 3);
        len += 2;
    }
    va_list ap;
    va_start(ap, fmt);
    if (len < cap) vsnprintf(out + len, cap - len, fmt, ap);
    va_end(ap);
}

static int same_stamp(const run_file_stamp *a, const run_file_stamp *b)
{
    return a->ino == b->ino && a->size == b->size && a->mtime_ns == b->mtime_ns;
}

/* The processing keys that differ between p's config and n's (the key table's
 * SH_CONFIG_PROCESSING), and the files processing reads rewritten under the same name, as text
 * for the log; 0 when nothing did. */
static int proc_changes(const run_pipeline *p, const run_pipeline *n, char *out, size_t cap)
{
    const sh_config *a = &p->cfg, *b = &n->cfg;
    out[0] = 0;
    sh_config_describe(a, b, SH_CONFIG_PROCESSING, out, cap);
    if (!strcmp(a->points, b->points) && !same_stamp(&p->points_file, &n->points_file))
        add(out, cap, "points file rewritten");
    if (!strcmp(a->calibration, b->calibration) && !same_stamp(&p->calib_file, &n->calib_file))
        add(out, cap, "calibration rewritten");
    return out[0] != 0;
}

static int same_frames(const sh_y4m_header *a, const sh_y4m_header *b)
{
    return a->width == b->width && a->height == b->height && a->format == b->format && sh_y4m_header_full_range(a) == sh_y4m_header_full_range(b);
}

/* What a reload changes, decided before anything is opened: from the effects of the keys that
 * changed (the key table's column, sh_config_changes), the files and the frames. */
typedef struct {
    unsigned effects;    /* sh_config_effect bits of the keys that changed */
    int cameras;         /* SH_CONFIG_SOURCE: the cameras are closed and opened */
    int processing;      /* a new run_proc (processing keys or files, or new cameras: a new stream) */
    char proc_text[384]; /* the processing keys that changed, for the log */
    int record, control; /* SH_CONFIG_RECORD, SH_CONFIG_CONTROL */
    int v4l2;            /* SH_CONFIG_V4L2, or new frames: the V4L2 output opened again ... */
    int v4l2_closed;     /* ... and the running one closed first (the same device takes one format) */
    int ctl_groups;      /* the control socket is kept with other groups (SH_CONFIG_LIVE) */
    int same_name;       /* the display segment keeps its name ... */
    int keep_disp;       /* ... its geometry and format and every SH_CONFIG_DISPLAY key: kept as it is */
    int new_frames;      /* the output camera's geometry or format changed */
    int new_shown;       /* the shown frames' (the sinks'): the camera's, or the stereo layout's */
    int black_made;      /* n's black frame is new */
    char again[512];     /* why the previous display could not be made again ("" when it could) */
} changes;

/* A piece of n failed to open: closes what n opened and puts back what was closed (the
 * previous cameras; the previous display; the previous V4L2 output). what says why. */
static run_reload refuse(run_pipeline *p, run_pipeline *n, const changes *c, char *what, size_t cap)
{
    char why[512], back[640] = "";
    snprintf(why, sizeof why, "%s", sh_error_message());
    if (n->proc != p->proc) run_proc_destroy(n->proc);
    if (n->rec != p->rec) run_record_close(n->rec); /* nothing was written to it */
    if (n->ctl != p->ctl) run_ctl_close(n->ctl);
    else if (c->ctl_groups) run_ctl_groups(p->ctl, p->cfg.control_group, p->cfg.group); /* they resolved before */
    if (n->v4l2 != p->v4l2) run_v4l2out_close(n->v4l2); /* nothing was written to it */
    if (c->v4l2_closed && v4l2_open(&p->cfg, &p->out_hdr, &p->v4l2) != SH_OK) {
        sh_log_error("the previous %s; publishing there stopped", sh_error_message());
        p->v4l2 = NULL;
    }
    if (n->disp != p->disp && n->disp) sh_display_writer_destroy(n->disp, 1); /* it never showed a frame */
    if (c->black_made) sh_image_destroy(&n->black);
    if (c->cameras) {
        run_source_destroy(n->src);
        sh_status st = source_open(&p->cfg, 1, &p->src);
        if (st == SH_OK && !same_frames(run_source_header(p->src), &p->hdr)) {
            /* processing and display are sized for the frames the cameras gave before */
            run_source_destroy(p->src);
            p->src = NULL;
            st = sh_error_set(SH_EIO, "they came back with other frames than before");
        }
        snprintf(back, sizeof back, "; the previous cameras %s%s", st == SH_OK ? "are back" : "cannot be reopened either: ",
                 st == SH_OK ? "" : sh_error_message());
    }
    int fatal = !p->src || c->again[0];
    size_t len = strlen(back);
    if (c->again[0]) snprintf(back + len, sizeof back - len, "; the previous display cannot be made again: %s", c->again);
    snprintf(what, cap, "reload refused%s: %s%s", fatal ? "" : ", keeping the running config", why, back);
    return fatal ? RUN_RELOAD_FATAL : RUN_RELOAD_REFUSED;
}

/* What an applied reload changed, for the log; "" when only gating did (or nothing at all). */
static void describe(const run_pipeline *p, const run_pipeline *n, const changes *c, char *what, size_t cap)
{
    const sh_config *old = &p->cfg, *fresh = &n->cfg;
    what[0] = 0;
    if (c->cameras && c->new_frames)
        add(what, cap, "cameras reopened (%dx%d %s -> %dx%d %s)", p->hdr.width, p->hdr.height,
            sh_pixfmt_name(p->hdr.format), n->hdr.width, n->hdr.height, sh_pixfmt_name(n->hdr.format));
    else if (c->cameras)
        add(what, cap, "cameras reopened");
    if (c->proc_text[0]) add(what, cap, "%s", c->proc_text);
    if (c->same_name && !c->keep_disp)
        add(what, cap, "sink %s made again for %dx%d frames", fresh->sink, n->out_hdr.width, n->out_hdr.height);
    else
        sh_config_describe(old, fresh, SH_CONFIG_DISPLAY, what, cap);
    sh_config_describe(old, fresh, SH_CONFIG_RECORD | SH_CONFIG_V4L2 | SH_CONFIG_CONTROL | SH_CONFIG_LIVE, what, cap);
    if (c->v4l2 && !(c->effects & SH_CONFIG_V4L2) && fresh->v4l2[0]) add(what, cap, "v4l2 %s opened again", fresh->v4l2);
    if (what[0] && c->keep_disp) add(what, cap, "sink kept");
    if (what[0] && (c->effects & SH_CONFIG_GATING)) add(what, cap, "gating");
}

/* A reload's record, V4L2 output and control socket: opened anew when their keys changed (n's
 * then; the same V4L2 device is closed first: it takes one format), else the running socket takes
 * the fresh groups. */
static sh_status reload_record_control(run_pipeline *p, run_pipeline *n, changes *c)
{
    const sh_config *old = &p->cfg, *fresh = &n->cfg;
    sh_status st = SH_OK;
    if (c->record) {
        n->rec = NULL;
        if (fresh->record[0] && (st = record_open(fresh, &n->out_hdr, &n->rec)) != SH_OK) return st;
        if (n->rec) log_record(fresh, n->rec);
    }
    if (c->v4l2) {
        if (p->v4l2 && !strcmp(old->v4l2, fresh->v4l2)) {
            run_pipeline_v4l2_close(p->v4l2);
            p->v4l2 = NULL;
            c->v4l2_closed = 1;
        }
        n->v4l2 = NULL;
        if (fresh->v4l2[0] && (st = v4l2_open(fresh, &n->out_hdr, &n->v4l2)) != SH_OK) return st;
    }
    if (c->control) {
        n->ctl = NULL;
        if (fresh->control[0] &&
            (st = run_ctl_open(fresh->control, fresh->control_group, fresh->group, &n->ctl)) != SH_OK)
            st = sh_error_set(st, "[run] control: %s", sh_error_message());
    } else if (p->ctl && (strcmp(fresh->control_group, old->control_group) || strcmp(fresh->group, old->group))) {
        if ((st = run_ctl_groups(p->ctl, fresh->control_group, fresh->group)) == SH_OK) c->ctl_groups = 1;
    }
    return st;
}

/* Every piece of n opened: closes the ones of p it replaced and makes n the running pipeline. */
static void swap_in(run_pipeline *p, run_pipeline *n, const changes *c)
{
    if (n->proc != p->proc) {
        p->builds_before += run_proc_builds(p->proc);
        p->refined_before += run_proc_refined(p->proc);
        run_proc_destroy(p->proc);
    } else {
        run_proc_set_gating(p->proc, &n->cfg);
    }
    if (n->rec != p->rec) record_close(p->rec);
    if (n->ctl != p->ctl) run_ctl_close(p->ctl);
    if (n->v4l2 != p->v4l2) run_pipeline_v4l2_close(p->v4l2);
    if (n->disp != p->disp && p->disp) sh_display_writer_destroy(p->disp, 0); /* marked closed, as at exit */
    if (c->black_made) sh_image_destroy(&p->black);
    n->dropped_before = p->dropped_before;
    n->builds_before = p->builds_before;
    n->refined_before = p->refined_before;
    *p = *n;
}

run_reload run_pipeline_reload(run_pipeline *p, const sh_config *fresh, char *what, size_t cap)
{
    const sh_config *old = &p->cfg;
    run_pipeline n = *p; /* the pieces to run with: p's until replaced */
    n.cfg = *fresh;
    stamps(&n);
    changes c;
    memset(&c, 0, sizeof c);
    c.effects = sh_config_changes(old, fresh);
    c.cameras = (c.effects & SH_CONFIG_SOURCE) != 0;
    c.processing = proc_changes(p, &n, c.proc_text, sizeof c.proc_text) || c.cameras;
    c.record = (c.effects & SH_CONFIG_RECORD) != 0;
    c.control = (c.effects & SH_CONFIG_CONTROL) != 0;
    const char *oname = shm_name(old), *nname = shm_name(fresh);
    c.same_name = oname && nname && !strcmp(oname, nname);
    sh_status st = SH_OK;

    if (c.cameras) {
        p->dropped_before += run_source_dropped(p->src);
        run_source_destroy(p->src); /* before the new cameras open: a V4L2 device opens once */
        p->src = n.src = NULL;
        st = run_source_open(fresh, &n.src);
        if (st == SH_OK) n.hdr = *run_source_header(n.src);
    }
    c.new_frames = !same_frames(&n.hdr, &p->hdr);
    if (st == SH_OK && c.processing) {
        st = run_proc_create(fresh, &n.hdr, run_source_fps(n.src), run_source_cameras(n.src), &n.proc);
        if (st == SH_OK) n.out_hdr = *run_proc_header(n.proc);
    } else if (st == SH_OK && (c.effects & SH_CONFIG_GATING)) {
        st = run_proc_check(fresh, &n.hdr); /* min_markers: the model the frames allow (run_proc_create's check) */
    }
    /* the sinks follow the shown frames: a new camera size, or a stereo view or layout turned on,
     * off or changed */
    c.new_shown = st == SH_OK && !same_frames(&n.out_hdr, &p->out_hdr);
    c.v4l2 = (c.effects & SH_CONFIG_V4L2) || (c.new_shown && fresh->v4l2[0]);
    c.keep_disp = c.same_name && !c.new_shown && !(c.effects & SH_CONFIG_DISPLAY);
    if (st == SH_OK && (c.cameras || c.new_shown) && (st = black_frame(&n.out_hdr, &n.black)) == SH_OK) c.black_made = 1;
    if (st == SH_OK && !c.record && p->rec && c.new_shown)
        /* reopening the file or folder would write over what it holds */
        st = sh_error_set(SH_EINVAL, "[sink] record %s: the frames change from %dx%d to %dx%d and a record keeps "
                          "one size (give [sink] record a new name)", fresh->record, p->out_hdr.width, p->out_hdr.height,
                          n.out_hdr.width, n.out_hdr.height);
    char was[64], now[64];
    record_tag(old, was, sizeof was);
    record_tag(fresh, now, sizeof now);
    if (st == SH_OK && !c.record && p->rec && strncmp(fresh->record, "png:", 4) && strcmp(was, now))
        /* the header says how its frames were made and cannot be rewritten */
        st = sh_error_set(SH_EINVAL, "[sink] record %s: its header says %s=%s, the frames from now on would be "
                          "%s, and a record keeps one method (give [sink] record a new name)", run_record_path(p->rec),
                          SH_Y4M_STILLHEART, was, now);
    if (st == SH_OK) st = reload_record_control(p, &n, &c);
    if (st == SH_OK && !c.same_name) {
        n.disp = NULL;
        if (nname) st = display_create(fresh, &n.out_hdr, &n.disp);
    }
    if (st == SH_OK && c.cameras) st = run_source_start(n.src);
    if (st == SH_OK && c.same_name && !c.keep_disp) {
        /* Unlinked, not only marked closed: the new segment is a new object, so a reader still
         * mapping the old one never touches pages a smaller segment would have cut off. */
        sh_display_writer_destroy(p->disp, 1);
        p->disp = n.disp = NULL;
        if ((st = display_create(fresh, &n.out_hdr, &n.disp)) != SH_OK) {
            char m[512];
            snprintf(m, sizeof m, "%s", sh_error_message());
            if (display_create(old, &p->out_hdr, &p->disp) != SH_OK) snprintf(c.again, sizeof c.again, "%s", sh_error_message());
            st = sh_error_set(st, "%s", m);
        }
    }
    if (st != SH_OK) return refuse(p, &n, &c, what, cap);

    describe(p, &n, &c, what, cap);
    swap_in(p, &n, &c);
    return RUN_RELOAD_APPLIED;
}

sh_status run_pipeline_close(run_pipeline *p)
{
    run_source_destroy(p->src);
    sh_status st = record_close(p->rec);
    run_pipeline_v4l2_close(p->v4l2);
    run_ctl_close(p->ctl);
    if (p->disp) sh_display_writer_destroy(p->disp, 0); /* marked closed; readers see the end */
    run_proc_destroy(p->proc);
    sh_image_destroy(&p->black);
    memset(p, 0, sizeof *p);
    return st;
}
