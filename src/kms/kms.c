/* The DRM/KMS output (kms.h): libdrm's legacy mode-setting calls, which every KMS driver takes
 * (the atomic helpers implement them), and dumb buffers, which need no GPU API. */
#include <ctype.h>
#include <dirent.h>
#include <errno.h>
#include <fcntl.h>
#include <limits.h>
#include <math.h>
#include <poll.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/mman.h>
#include <time.h>
#include <unistd.h>

#include "stillheart/kms.h"

sh_status sh_kms_parse_mode(const char *text, int *width, int *height, double *refresh)
{
    char *end;
    const char *s = text ? text : "";
    long w = isdigit((unsigned char)*s) ? strtol(s, &end, 10) : -1;
    if (w < 1 || w > 16384 || (*end != 'x' && *end != 'X')) goto bad;
    s = end + 1;
    long h = isdigit((unsigned char)*s) ? strtol(s, &end, 10) : -1;
    if (h < 1 || h > 16384) goto bad;
    double r = 0;
    if (*end == '@') {
        s = end + 1;
        r = isdigit((unsigned char)*s) ? strtod(s, &end) : -1;
        if (!(r > 0 && r <= 1000)) goto bad;
    }
    if (*end) goto bad;
    *width = (int)w;
    *height = (int)h;
    *refresh = r;
    return SH_OK;
bad:
    return sh_error_set(SH_EINVAL, "mode '%s': not WxH or WxH@R (e.g. 1920x1080@60)", text ? text : "");
}

#ifndef SH_HAVE_DRM

sh_status sh_kms_create(const sh_kms_options *options, sh_kms **out)
{
    (void)options;
    *out = NULL;
    return sh_error_set(SH_EUNSUPPORTED, "built without libdrm: no KMS output (install libdrm-dev and rebuild)");
}
void sh_kms_destroy(sh_kms *kms) { (void)kms; }
void sh_kms_get_info(const sh_kms *kms, sh_kms_info *info) { (void)kms; memset(info, 0, sizeof *info); }
void sh_kms_back(sh_kms *kms, uint32_t **pixels, int *stride) { (void)kms; *pixels = NULL; *stride = 0; }
sh_status sh_kms_present(sh_kms *kms) { (void)kms; return sh_error_set(SH_EUNSUPPORTED, "built without libdrm"); }
sh_status sh_kms_wait(sh_kms *kms, int timeout_ms, int64_t *flip_ns)
{
    (void)kms, (void)timeout_ms, (void)flip_ns;
    return sh_error_set(SH_EUNSUPPORTED, "built without libdrm");
}

#else

#include <drm_fourcc.h>
#include <xf86drm.h>
#include <xf86drmMode.h>

typedef struct {
    uint32_t handle, fb_id, pitch;
    uint64_t size;
    uint32_t *map;
} kms_buffer;

struct sh_kms {
    int fd;
    uint32_t connector_id, crtc_id;
    drmModeModeInfo mode;
    kms_buffer buf[2];
    int back;
    int modeset_done;
    int pending; /* 0 none, 1 a page flip in flight, 2 the first mode set (no event) */
    int64_t flip_ns;
    drmModeCrtc *saved;
    sh_kms_info info;
};

static int64_t now_ns(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (int64_t)ts.tv_sec * 1000000000 + ts.tv_nsec;
}

static void connector_name(const drmModeConnector *c, char *out, size_t cap)
{
    const char *t = drmModeGetConnectorTypeName(c->connector_type);
    snprintf(out, cap, "%s-%u", t ? t : "Unknown", c->connector_type_id);
}

static double mode_refresh(const drmModeModeInfo *m)
{
    if (!m->htotal || !m->vtotal) return m->vrefresh;
    double r = m->clock * 1000.0 / ((double)m->htotal * m->vtotal);
    if (m->flags & DRM_MODE_FLAG_INTERLACE) r *= 2;
    if (m->flags & DRM_MODE_FLAG_DBLSCAN) r /= 2;
    if (m->vscan > 1) r /= m->vscan;
    return r;
}

/* Who has the device open besides this process (the likely master): "123 (Xorg), 456 (weston)",
 * from /proc, as far as it shows other processes (hidepid, ProtectProc= hide them). */
static void device_holders(const char *device, char *out, size_t cap)
{
    char want[PATH_MAX];
    out[0] = 0;
    if (!realpath(device, want)) return;
    DIR *proc = opendir("/proc");
    if (!proc) return;
    size_t used = 0;
    for (struct dirent *e; (e = readdir(proc));) {
        char *end;
        long pid = strtol(e->d_name, &end, 10);
        if (*end || pid <= 0 || pid == (long)getpid()) continue;
        char path[64], link[PATH_MAX];
        snprintf(path, sizeof path, "/proc/%ld/fd", pid);
        DIR *fds = opendir(path);
        if (!fds) continue;
        int found = 0;
        for (struct dirent *f; !found && (f = readdir(fds));) {
            char fp[96];
            snprintf(fp, sizeof fp, "/proc/%ld/fd/%.20s", pid, f->d_name);
            ssize_t n = readlink(fp, link, sizeof link - 1);
            if (n > 0) {
                link[n] = 0;
                found = !strcmp(link, want);
            }
        }
        closedir(fds);
        if (!found) continue;
        char comm[64] = "?";
        snprintf(path, sizeof path, "/proc/%ld/comm", pid);
        FILE *cf = fopen(path, "r");
        if (cf) {
            if (fgets(comm, sizeof comm, cf)) comm[strcspn(comm, "\n")] = 0;
            fclose(cf);
        }
        int k = snprintf(out + used, cap - used, "%s%ld (%s)", used ? ", " : "", pid, comm);
        if (k < 0 || (size_t)k >= cap - used) break;
        used += (size_t)k;
    }
    closedir(proc);
}

static sh_status become_master(int fd, const char *device)
{
    if (drmIsMaster(fd) || drmSetMaster(fd) == 0) return SH_OK;
    char who[256];
    device_holders(device, who, sizeof who);
    if (who[0])
        return sh_error_set(SH_EIO, "%s: DRM master is held by another process: %s has it open "
                            "(stop it, or switch it away from this output)", device, who);
    return sh_error_set(SH_EIO, "%s: DRM master is held by another process (not visible in /proc here: "
                        "a display server or another stillheart-show?)", device);
}

/* The connector asked for (or the first with a monitor); a refusal lists what there is. */
static sh_status pick_connector(int fd, const drmModeRes *res, const char *device, const char *want,
                                drmModeConnector **out)
{
    char list[512] = "";
    size_t used = 0;
    *out = NULL;
    for (int i = 0; i < res->count_connectors; i++) {
        drmModeConnector *c = drmModeGetConnector(fd, res->connectors[i]);
        if (!c) continue;
        char name[32];
        connector_name(c, name, sizeof name);
        const char *state = c->connection == DRM_MODE_CONNECTED ? "connected"
                            : c->connection == DRM_MODE_DISCONNECTED ? "disconnected" : "unknown";
        int k = snprintf(list + used, sizeof list - used, "%s%s (%s)", used ? ", " : "", name, state);
        if (k > 0 && (size_t)k < sizeof list - used) used += (size_t)k;
        if (want ? !strcasecmp(want, name) : c->connection == DRM_MODE_CONNECTED && c->count_modes > 0) {
            if (c->connection == DRM_MODE_DISCONNECTED || c->count_modes == 0) {
                int modes = c->count_modes;
                drmModeFreeConnector(c);
                return sh_error_set(SH_EINVAL, "%s: connector %s has no monitor (%s, %d modes)", device, name,
                                    state, modes);
            }
            *out = c;
            return SH_OK;
        }
        drmModeFreeConnector(c);
    }
    if (want) return sh_error_set(SH_EINVAL, "%s: no connector '%s' (there are: %s)", device, want, used ? list : "none");
    return sh_error_set(SH_EINVAL, "%s: no connector with a monitor (there are: %s)", device, used ? list : "none");
}

static sh_status pick_mode(const drmModeConnector *c, const sh_kms_options *o, const char *cname,
                           drmModeModeInfo *out)
{
    int best = -1;
    for (int i = 0; i < c->count_modes; i++) {
        const drmModeModeInfo *m = &c->modes[i];
        int fits = o->width == 0 ? 1
                   : m->hdisplay == o->width && m->vdisplay == o->height &&
                         (o->refresh == 0 || fabs(mode_refresh(m) - o->refresh) < 0.5);
        if (!fits) continue;
        if (best < 0 || (m->type & DRM_MODE_TYPE_PREFERRED)) best = i;
        if (o->width == 0 && (m->type & DRM_MODE_TYPE_PREFERRED)) break;
    }
    if (best >= 0) {
        *out = c->modes[best];
        return SH_OK;
    }
    char list[1024] = "";
    size_t used = 0;
    for (int i = 0; i < c->count_modes; i++) {
        int k = snprintf(list + used, sizeof list - used, "%s%dx%d@%.2f", i ? " " : "", c->modes[i].hdisplay,
                         c->modes[i].vdisplay, mode_refresh(&c->modes[i]));
        if (k < 0 || (size_t)k >= sizeof list - used) break;
        used += (size_t)k;
    }
    char want[64];
    if (o->refresh > 0) snprintf(want, sizeof want, "%dx%d@%g", o->width, o->height, o->refresh);
    else snprintf(want, sizeof want, "%dx%d", o->width, o->height);
    return sh_error_set(SH_EINVAL, "connector %s does not offer the mode %s (it offers: %s)", cname, want, list);
}

/* The CRTC already driving the connector, else the first one its encoders can drive. */
static uint32_t pick_crtc(int fd, const drmModeRes *res, const drmModeConnector *c)
{
    if (c->encoder_id) {
        drmModeEncoder *e = drmModeGetEncoder(fd, c->encoder_id);
        uint32_t id = e ? e->crtc_id : 0;
        drmModeFreeEncoder(e);
        if (id) return id;
    }
    for (int i = 0; i < c->count_encoders; i++) {
        drmModeEncoder *e = drmModeGetEncoder(fd, c->encoders[i]);
        if (!e) continue;
        for (int j = 0; j < res->count_crtcs; j++)
            if (e->possible_crtcs & (1u << j)) {
                drmModeFreeEncoder(e);
                return res->crtcs[j];
            }
        drmModeFreeEncoder(e);
    }
    return 0;
}

static sh_status make_buffer(sh_kms *k, kms_buffer *b, const char *device)
{
    uint32_t w = k->mode.hdisplay, h = k->mode.vdisplay;
    uint64_t offset;
    if (drmModeCreateDumbBuffer(k->fd, w, h, 32, 0, &b->handle, &b->pitch, &b->size) != 0)
        return sh_error_set(SH_EIO, "%s: cannot make a %ux%u buffer: %s", device, w, h, strerror(errno));
    uint32_t handles[4] = {b->handle}, pitches[4] = {b->pitch}, offsets[4] = {0};
    if (drmModeAddFB2(k->fd, w, h, DRM_FORMAT_XRGB8888, handles, pitches, offsets, &b->fb_id, 0) != 0)
        return sh_error_set(SH_EIO, "%s: the driver takes no XRGB8888 framebuffer: %s", device, strerror(errno));
    if (drmModeMapDumbBuffer(k->fd, b->handle, &offset) != 0)
        return sh_error_set(SH_EIO, "%s: cannot map a buffer: %s", device, strerror(errno));
    void *m = mmap(NULL, b->size, PROT_READ | PROT_WRITE, MAP_SHARED, k->fd, (off_t)offset);
    if (m == MAP_FAILED) return sh_error_set(SH_EIO, "%s: cannot map a buffer: %s", device, strerror(errno));
    b->map = m;
    memset(b->map, 0, b->size);
    return SH_OK;
}

/* Opens, checks and sets up in order; each step's refusal names what it found. ~90 lines: one
 * linear sequence with one cleanup, easier to follow whole than split. */
sh_status sh_kms_create(const sh_kms_options *o, sh_kms **out)
{
    *out = NULL;
    const char *device = o->device ? o->device : "/dev/dri/card0";
    sh_kms *k = calloc(1, sizeof *k);
    if (!k) return sh_error_set(SH_ENOMEM, "out of memory");
    k->fd = -1;
    drmModeRes *res = NULL;
    drmModeConnector *c = NULL;
    sh_status st;
    k->fd = open(device, O_RDWR | O_CLOEXEC);
    if (k->fd < 0) {
        st = sh_error_set(SH_EIO, "%s: %s%s", device, strerror(errno),
                          errno == ENOENT ? " (no such device: ls /dev/dri; is the display driver loaded?)"
                          : errno == EACCES ? " (the user needs the group of the device, video)" : "");
        goto fail;
    }
    res = drmModeGetResources(k->fd);
    if (!res) {
        st = sh_error_set(SH_EINVAL, "%s: not a KMS display device (%s)", device, strerror(errno));
        goto fail;
    }
    drmVersion *v = drmGetVersion(k->fd);
    snprintf(k->info.driver, sizeof k->info.driver, "%s", v && v->name ? v->name : "?");
    drmFreeVersion(v);
    if ((st = pick_connector(k->fd, res, device, o->connector, &c)) != SH_OK) goto fail;
    connector_name(c, k->info.connector, sizeof k->info.connector);
    if ((st = pick_mode(c, o, k->info.connector, &k->mode)) != SH_OK) goto fail;
    k->connector_id = c->connector_id;
    k->crtc_id = pick_crtc(k->fd, res, c);
    if (!k->crtc_id) {
        st = sh_error_set(SH_EINVAL, "%s: no display controller (CRTC) can drive %s", device, k->info.connector);
        goto fail;
    }
    /* before anything is changed: a refusal here leaves the screen as it was */
    if ((st = become_master(k->fd, device)) != SH_OK) goto fail;
    for (int i = 0; i < 2; i++)
        if ((st = make_buffer(k, &k->buf[i], device)) != SH_OK) goto fail;
    k->saved = drmModeGetCrtc(k->fd, k->crtc_id);
    k->info.width = k->mode.hdisplay;
    k->info.height = k->mode.vdisplay;
    k->info.refresh = mode_refresh(&k->mode);
    drmModeFreeConnector(c);
    drmModeFreeResources(res);
    *out = k;
    return SH_OK;
fail:
    drmModeFreeConnector(c);
    drmModeFreeResources(res);
    sh_kms_destroy(k);
    return st;
}

static void on_flip(int fd, unsigned int frame, unsigned int sec, unsigned int usec, void *data)
{
    (void)fd, (void)frame;
    sh_kms *k = data;
    k->flip_ns = (int64_t)sec * 1000000000 + (int64_t)usec * 1000;
    k->pending = 0;
}

sh_status sh_kms_wait(sh_kms *k, int timeout_ms, int64_t *flip_ns)
{
    if (k->pending == 2) {
        k->pending = 0;
    } else if (k->pending == 1) {
        int64_t end = now_ns() + (int64_t)timeout_ms * 1000000;
        drmEventContext ev = {.version = 2, .page_flip_handler = on_flip};
        while (k->pending == 1) {
            int left = timeout_ms < 0 ? -1 : (int)((end - now_ns()) / 1000000);
            if (timeout_ms >= 0 && left < 0) return sh_error_set(SH_EIO, "no page flip within %d ms", timeout_ms);
            struct pollfd p = {k->fd, POLLIN, 0};
            int n = poll(&p, 1, left);
            if (n < 0 && errno == EINTR) continue;
            if (n < 0) return sh_error_set(SH_EIO, "waiting for the page flip: %s", strerror(errno));
            if (n > 0 && drmHandleEvent(k->fd, &ev) != 0)
                return sh_error_set(SH_EIO, "reading the page flip event: %s", strerror(errno));
        }
    } else {
        return sh_error_set(SH_EINVAL, "no page flip asked for");
    }
    k->back ^= 1;
    if (flip_ns) *flip_ns = k->flip_ns;
    return SH_OK;
}

sh_status sh_kms_present(sh_kms *k)
{
    if (k->pending) return sh_error_set(SH_EINVAL, "a page flip is still in flight");
    const kms_buffer *b = &k->buf[k->back];
    if (!k->modeset_done) {
        if (drmModeSetCrtc(k->fd, k->crtc_id, b->fb_id, 0, 0, &k->connector_id, 1, &k->mode) != 0)
            return sh_error_set(SH_EIO, "setting the mode %dx%d on %s: %s", k->info.width, k->info.height,
                                k->info.connector, strerror(errno));
        k->modeset_done = 1;
        k->flip_ns = now_ns();
        k->pending = 2;
        return SH_OK;
    }
    if (drmModePageFlip(k->fd, k->crtc_id, b->fb_id, DRM_MODE_PAGE_FLIP_EVENT, k) != 0)
        return sh_error_set(SH_EIO, "page flip on %s: %s", k->info.connector, strerror(errno));
    k->pending = 1;
    return SH_OK;
}

void sh_kms_back(sh_kms *k, uint32_t **pixels, int *stride)
{
    *pixels = k->buf[k->back].map;
    *stride = (int)k->buf[k->back].pitch;
}

void sh_kms_get_info(const sh_kms *k, sh_kms_info *info) { *info = k->info; }

void sh_kms_destroy(sh_kms *k)
{
    if (!k) return;
    if (k->pending == 1) sh_kms_wait(k, 200, NULL); /* a buffer in a flip must not go away under it */
    if (k->saved) {
        if (k->modeset_done && k->saved->mode_valid)
            drmModeSetCrtc(k->fd, k->saved->crtc_id, k->saved->buffer_id, k->saved->x, k->saved->y,
                           &k->connector_id, 1, &k->saved->mode);
        drmModeFreeCrtc(k->saved);
    }
    for (int i = 0; i < 2; i++) {
        kms_buffer *b = &k->buf[i];
        if (b->map) munmap(b->map, b->size);
        if (b->fb_id) drmModeRmFB(k->fd, b->fb_id);
        if (b->handle) drmModeDestroyDumbBuffer(k->fd, b->handle);
    }
    if (k->fd >= 0) close(k->fd);
    free(k);
}

#endif
