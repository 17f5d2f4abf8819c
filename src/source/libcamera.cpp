// libcamera:NAME — a libcamera camera behind the C source interface (Debian 12: libcamera
// 0.0.3, whose API changes between versions; built only when pkg-config finds it).
//
// NAME is a camera id, a substring of one, or an index in the manager's list ("0"). One stream
// (role VideoRecording), format and size as asked (the validated configuration must keep them),
// options.buffers (4) buffers from FrameBufferAllocator, mapped once; one request per buffer.
// libcamera completes requests on its own thread: the handler only records the request's index in
// a small locked ring and writes an eventfd, which is this source's pollable fd. Frames whose
// metadata says FrameError are requeued and counted.
//
// Controls: exposure, gain and white balance become ExposureTime, AnalogueGain and
// ColourTemperature (with AeEnable / AwbEnable off where listed), set on the first requests; a
// control the camera does not list, or a value outside its range, is refused naming it.
//
// Loss (the camera's disconnected signal, or no frame for timeout_ms): the camera is stopped and
// released, its buffers unmapped once the caller has released the frames it holds, and it is
// looked up again by NAME with a back-off doubling from backoff_min_ms to backoff_max_ms. The
// manager's list follows hotplug only through udev; when this source is the manager's only user
// the manager is restarted for each attempt, so that a camera that returns is found without udev
// (the vmtest guest) too. The camera must come back with the same format and size.
//
// Over 600 lines: the only file that includes libcamera, whose C++ API changes between versions;
// split, its types would have to travel in a C++ header and a version change would touch several
// files.
#include "source_internal.h"

#ifdef SH_HAVE_LIBCAMERA

#include <algorithm>
#include <atomic>
#include <dirent.h>
#include <errno.h>
#include <poll.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/eventfd.h>
#include <sys/mman.h>
#include <unistd.h>

#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include <libcamera/libcamera.h>

using namespace libcamera;

namespace {

// One CameraManager per process (libcamera allows no second one), shared by the sources.
std::mutex manager_lock;
CameraManager *manager;
int manager_users;

CameraManager *manager_get()
{
    std::lock_guard<std::mutex> g(manager_lock);
    if (!manager) {
        manager = new CameraManager();
        if (manager->start() != 0) {
            delete manager;
            manager = nullptr;
            return nullptr;
        }
    }
    manager_users++;
    return manager;
}

void manager_put()
{
    std::lock_guard<std::mutex> g(manager_lock);
    if (--manager_users == 0) {
        manager->stop();
        delete manager;
        manager = nullptr;
    }
}

struct Impl {
    std::shared_ptr<Camera> camera;
    std::unique_ptr<CameraConfiguration> config;
    std::unique_ptr<FrameBufferAllocator> alloc;
    std::vector<std::unique_ptr<Request>> requests;
    std::vector<uint8_t *> data;   // frame start of each buffer
    std::vector<void *> maps;
    std::vector<size_t> map_len;
    Stream *stream = nullptr;
    int efd = -1;
    bool acquired = false, running = false;
    std::mutex lock;
    std::vector<int> done; // completed request indices, oldest first
    std::vector<char> held; // per request: a frame the caller has not released
    int nheld = 0;
    std::atomic<bool> gone{false}; // the camera's disconnected signal (udev hotplug)
    bool vanished = false;         // lost with its device nodes gone: cannot be stopped
    std::vector<int> removed_before; // device fds already removed at open (not this camera's)
    ControlList initial;   // the controls asked for, set on the first requests

    void completed(Request *r)
    {
        if (r->status() == Request::RequestCancelled) return;
        {
            std::lock_guard<std::mutex> g(lock);
            done.push_back((int)r->cookie());
        }
        wake();
    }

    void disconnected()
    {
        gone = true;
        wake();
    }

    void wake()
    {
        uint64_t one = 1;
        ssize_t w = write(efd, &one, sizeof one);
        (void)w;
    }
};

struct lc_source {
    sh_source base;
    Impl *impl;            // null while the camera is down and its buffers are gone
    std::string name;
    bool down;
    int64_t last_frame, retry_at;
    int backoff_ms;
    uint64_t seq_base, next_seq; // the camera's sequence restarts at each reopen; ours keeps rising
};

bool to_raw(const PixelFormat &f, sh_rawfmt *out)
{
    if (f == formats::YUYV) *out = SH_RAW_YUYV;
    else if (f == formats::NV12) *out = SH_RAW_NV12;
    else if (f == formats::R8) *out = SH_RAW_GREY;
    else if (f == formats::BGR888) *out = SH_RAW_RGB24; // DRM order: bytes R, G, B
    else if (f == formats::RGB888) *out = SH_RAW_BGR24; // bytes B, G, R
    else if (f == formats::MJPEG) *out = SH_RAW_MJPEG;
    else return false;
    return true;
}

PixelFormat from_raw(sh_rawfmt f)
{
    switch (f) {
    case SH_RAW_YUYV: return formats::YUYV;
    case SH_RAW_NV12: return formats::NV12;
    case SH_RAW_GREY: return formats::R8;
    case SH_RAW_RGB24: return formats::BGR888;
    case SH_RAW_BGR24: return formats::RGB888;
    case SH_RAW_MJPEG: return formats::MJPEG;
    default: return PixelFormat();
    }
}

int backoff_min(const sh_source *s) { return s->opts.backoff_min_ms > 0 ? s->opts.backoff_min_ms : 100; }
int backoff_max(const sh_source *s) { return s->opts.backoff_max_ms > 0 ? s->opts.backoff_max_ms : 5000; }
int timeout_of(const sh_source *s) { return s->opts.timeout_ms > 0 ? s->opts.timeout_ms : 1000; }

void removed_device_fds(std::vector<int> *out);

// Stops a running camera where that is possible; otherwise it stays marked running. libcamera
// 0.0.3 asserts in Camera::stop() when the requests queued to a device that has gone never come
// back (streamOff fails before it cancels them), so a camera whose device vanished unnoticed by
// udev is not stopped; a disconnected one (udev told libcamera) refuses to stop (-ENODEV).
void stop_camera(Impl *m)
{
    if (!m->running) return;
    if (!m->gone) {
        std::vector<int> now;
        removed_device_fds(&now);
        for (int fd : now)
            if (std::find(m->removed_before.begin(), m->removed_before.end(), fd) == m->removed_before.end())
                m->vanished = true;
    }
    if (!m->vanished && m->camera->stop() == 0) m->running = false;
}

void destroy(Impl *m)
{
    stop_camera(m);
    if (m->camera) {
        m->camera->requestCompleted.disconnect(m, &Impl::completed);
        m->camera->disconnected.disconnect(m, &Impl::disconnected);
    }
    for (size_t i = 0; i < m->maps.size(); i++)
        if (m->maps[i] && m->maps[i] != MAP_FAILED) munmap(m->maps[i], m->map_len[i]);
    m->requests.clear();
    m->alloc.reset();
    if (m->acquired && !m->running) m->camera->release();
    if (m->running) {
        // A camera that could not be stopped cannot be destroyed either: its pipeline's IPA
        // thread may still run, and a running std::thread destroyed terminates the process. It
        // is kept, never freed (so not destroyed at exit either): one camera object per loss.
        static std::vector<std::shared_ptr<Camera>> *kept = new std::vector<std::shared_ptr<Camera>>();
        std::lock_guard<std::mutex> g(manager_lock);
        kept->push_back(m->camera);
    }
    m->camera.reset();
    if (m->efd >= 0) close(m->efd);
    delete m;
    manager_put();
}

// The fds of V4L2 and media device nodes this process holds open that have been removed (their
// link ends in " (deleted)"). Without udev hotplug (no disconnected signal) a new one is how a
// camera whose device went away is told apart from one that only stalled; those already there
// at open belong to cameras lost before.
void removed_device_fds(std::vector<int> *out)
{
    out->clear();
    DIR *d = opendir("/proc/self/fd");
    if (!d) return;
    while (struct dirent *e = readdir(d)) {
        char path[300], target[256];
        snprintf(path, sizeof path, "/proc/self/fd/%s", e->d_name);
        ssize_t n = readlink(path, target, sizeof target - 1);
        if (n <= 0) continue;
        target[n] = 0;
        if ((!strncmp(target, "/dev/video", 10) || !strncmp(target, "/dev/v4l-subdev", 15) ||
             !strncmp(target, "/dev/media", 10)) &&
            strstr(target, " (deleted)"))
            out->push_back(atoi(e->d_name));
    }
    closedir(d);
}

// Starts the camera and queues every request, the asked controls on each of these first ones.
sh_status start_impl(Impl *m, const char *name)
{
    if (m->camera->start() != 0) return sh_error_set(SH_EIO, "%s: cannot start", name);
    m->running = true;
    for (auto &r : m->requests) {
        r->reuse(Request::ReuseBuffers); // requests cancelled by an earlier stop are pending again
        for (const auto &c : m->initial) r->controls().set(c.first, c.second);
        if (m->camera->queueRequest(r.get()) != 0) return sh_error_set(SH_EIO, "%s: cannot queue a request", name);
    }
    return SH_OK;
}

// The camera is lost: stopped now where it can be; released, unmapped and dropped once the
// caller's frames are back.
void lose(lc_source *l, int64_t now)
{
    Impl *m = l->impl;
    l->down = true;
    l->base.stats.losses++;
    l->base.stats.online = 0;
    l->backoff_ms = backoff_min(&l->base);
    l->retry_at = now + (int64_t)l->backoff_ms * 1000000;
    stop_camera(m); // cancels the queued requests where it can
    {
        std::lock_guard<std::mutex> g(m->lock);
        m->done.clear();
    }
    if (!m->nheld) {
        destroy(m);
        l->impl = nullptr;
    }
}

sh_status open_camera(const char *name, const sh_source_options *o, Impl **out, sh_rawfmt *format, int *width,
                      int *height, int *stride);

void try_reopen(lc_source *l, int64_t now)
{
    if (now < l->retry_at || (l->impl && l->impl->nheld)) return;
    if (l->impl) {
        destroy(l->impl);
        l->impl = nullptr;
    }
    // the same geometry as negotiated at the first open
    sh_source_options o = l->base.opts;
    o.format = (int)l->base.format;
    o.width = l->base.width;
    o.height = l->base.height;
    sh_rawfmt f;
    int w, h, stride;
    Impl *m = nullptr;
    if (open_camera(l->name.c_str(), &o, &m, &f, &w, &h, &stride) == SH_OK && stride == l->base.stride &&
        start_impl(m, l->base.name) == SH_OK) {
        l->impl = m;
        l->down = false;
        l->base.stats.reopens++;
        l->base.stats.online = 1;
        l->last_frame = now;
        l->seq_base = l->next_seq;
        return;
    }
    if (m) destroy(m);
    l->backoff_ms = l->backoff_ms * 2 > backoff_max(&l->base) ? backoff_max(&l->base) : l->backoff_ms * 2;
    l->retry_at = now + (int64_t)l->backoff_ms * 1000000;
}

sh_status lc_start(sh_source *s)
{
    lc_source *l = (lc_source *)s;
    if (!l->impl) { // stopped while down: a fresh attempt at once
        l->down = true;
        l->retry_at = 0;
        l->backoff_ms = backoff_min(s);
        return SH_OK;
    }
    sh_status st = start_impl(l->impl, s->name);
    if (st != SH_OK) return st;
    l->last_frame = sh_monotonic_ns();
    s->stats.online = 1;
    return SH_OK;
}

int lc_fd(const sh_source *s)
{
    const lc_source *l = (const lc_source *)s;
    return l->down || !l->impl ? -1 : l->impl->efd;
}

sh_status lc_dequeue(sh_source *s, int timeout_ms, sh_source_frame *f, int *got)
{
    lc_source *l = (lc_source *)s;
    int64_t deadline = timeout_ms < 0 ? INT64_MAX : sh_monotonic_ns() + (int64_t)timeout_ms * 1000000;
    for (;;) {
        int64_t now = sh_monotonic_ns();
        if (l->down) {
            try_reopen(l, now);
            if (l->down) {
                if (now >= deadline || (l->impl && l->impl->nheld)) return SH_OK;
                sh_source_sleep_until(l->retry_at < deadline ? l->retry_at : deadline);
                continue;
            }
        }
        Impl *m = l->impl;
        if (m->gone) {
            sh_error_set(SH_EIO, "%s: the camera was disconnected", s->name);
            lose(l, now);
            continue;
        }
        int index = -1;
        {
            std::lock_guard<std::mutex> g(m->lock);
            if (!m->done.empty()) {
                index = m->done.front();
                m->done.erase(m->done.begin());
            }
        }
        if (index < 0) {
            int64_t lost_at = l->last_frame + (int64_t)timeout_of(s) * 1000000;
            if (now >= lost_at) {
                sh_error_set(SH_EIO, "%s: no frame for %d ms", s->name, timeout_of(s));
                lose(l, now);
                continue;
            }
            if (now >= deadline) return SH_OK;
            int64_t wake = lost_at < deadline ? lost_at : deadline;
            struct pollfd p = {m->efd, POLLIN, 0};
            poll(&p, 1, (int)((wake - now + 999999) / 1000000));
            uint64_t n;
            ssize_t r = read(m->efd, &n, sizeof n);
            (void)r;
            continue;
        }
        Request *req = m->requests[(size_t)index].get();
        FrameBuffer *fb = req->buffers().begin()->second;
        const FrameMetadata &md = fb->metadata();
        if (md.status != FrameMetadata::FrameSuccess) {
            s->stats.errors++;
            req->reuse(Request::ReuseBuffers);
            m->camera->queueRequest(req);
            continue;
        }
        l->last_frame = now;
        size_t bytes = 0;
        for (const auto &p : md.planes()) bytes += p.bytesused;
        if (s->format != SH_RAW_MJPEG && bytes < sh_raw_frame_size(s->format, s->width, s->height, s->stride))
            bytes = sh_raw_frame_size(s->format, s->width, s->height, s->stride);
        memset(f, 0, sizeof *f);
        f->camera = s->opts.camera;
        f->sequence = l->seq_base + md.sequence;
        if (f->sequence > l->next_seq && l->next_seq > l->seq_base) s->stats.drops += f->sequence - l->next_seq;
        l->next_seq = f->sequence + 1;
        f->timestamp_ns = (int64_t)md.timestamp;
        f->raw.format = s->format;
        f->raw.width = s->width;
        f->raw.height = s->height;
        f->raw.stride = s->stride;
        f->raw.data = m->data[(size_t)index];
        f->raw.bytes = bytes;
        f->slot = index;
        m->held[(size_t)index] = 1;
        m->nheld++;
        s->stats.frames++;
        *got = 1;
        return SH_OK;
    }
}

sh_status lc_release(sh_source *s, sh_source_frame *f)
{
    lc_source *l = (lc_source *)s;
    Impl *m = l->impl;
    if (!m || f->slot < 0 || (size_t)f->slot >= m->requests.size() || !m->held[(size_t)f->slot])
        return sh_error_set(SH_EINVAL, "%s: release of a frame not held", s->name);
    Request *req = m->requests[(size_t)f->slot].get();
    m->held[(size_t)f->slot] = 0;
    m->nheld--;
    f->slot = -1;
    if (l->down || !m->running) {
        if (l->down && !m->nheld) { // the last frame of a lost camera: its buffers can go
            destroy(m);
            l->impl = nullptr;
        }
        return SH_OK;
    }
    req->reuse(Request::ReuseBuffers);
    if (m->camera->queueRequest(req) != 0) {
        sh_error_set(SH_EIO, "%s: cannot requeue", s->name);
        lose(l, sh_monotonic_ns());
    }
    return SH_OK;
}

sh_status lc_stop(sh_source *s)
{
    lc_source *l = (lc_source *)s;
    Impl *m = l->impl;
    s->stats.online = 0;
    bool was_down = l->down;
    l->down = false;
    if (!m) return SH_OK;
    std::fill(m->held.begin(), m->held.end(), 0);
    m->nheld = 0;
    if (was_down) { // what is left of a lost camera goes; start looks it up again
        destroy(m);
        l->impl = nullptr;
        return SH_OK;
    }
    stop_camera(m);
    if (m->running) { // its device has gone: what is left goes, start looks it up again
        destroy(m);
        l->impl = nullptr;
        return SH_OK;
    }
    std::lock_guard<std::mutex> g(m->lock);
    m->done.clear();
    return SH_OK;
}

void lc_close(sh_source *s)
{
    lc_source *l = (lc_source *)s;
    if (l->impl) destroy(l->impl);
    delete l;
}

const sh_source_ops ops = {lc_start, lc_fd, lc_dequeue, lc_release, lc_stop, lc_close, nullptr};

// A control's limit as a double, whatever its type.
double as_double(const ControlValue &v)
{
    switch (v.type()) {
    case ControlTypeInteger32: return v.get<int32_t>();
    case ControlTypeInteger64: return (double)v.get<int64_t>();
    case ControlTypeFloat: return v.get<float>();
    default: return 0;
    }
}

// The controls asked for, as libcamera controls the camera lists; anything else refused by name.
sh_status camera_controls(Camera *cam, const char *name, const sh_source_options *o, ControlList *out)
{
    const ControlInfoMap &info = cam->controls();
    std::string listed;
    for (const auto &kv : info) listed += (listed.empty() ? "" : ", ") + kv.first->name();
    struct {
        int32_t value;
        const char *what;
        const ControlId *id;
        const ControlId *automatic; // switched off first where listed
        double scale;               // libcamera value = option * scale
    } want[] = {
        {o->exposure, "exposure", &controls::ExposureTime, &controls::AeEnable, 100.0}, // 100 us units -> us
        {o->gain, "gain", &controls::AnalogueGain, &controls::AeEnable, 0.01},          // 100 = unity
        {o->white_balance, "white balance", &controls::ColourTemperature, &controls::AwbEnable, 1.0}, // K
    };
    for (const auto &c : want) {
        if (c.value == SH_SOURCE_CTRL_UNSET) continue;
        auto it = info.find(c.id);
        if (it == info.end())
            return sh_error_set(SH_EUNSUPPORTED, "libcamera:%s: control %s (%s) not offered by the camera (it lists: %s)",
                                name, c.what, c.id->name().c_str(), listed.empty() ? "none" : listed.c_str());
        double v = c.value * c.scale, lo = as_double(it->second.min()), hi = as_double(it->second.max());
        if (lo < hi && (v < lo || v > hi))
            return sh_error_set(SH_EUNSUPPORTED, "libcamera:%s: control %s (%s) = %g outside %g..%g", name, c.what,
                                c.id->name().c_str(), v, lo, hi);
        if (info.find(c.automatic) != info.end()) out->set(c.automatic->id(), ControlValue(false));
        if (c.id->type() == ControlTypeFloat) out->set(c.id->id(), ControlValue((float)v));
        else out->set(c.id->id(), ControlValue((int32_t)v));
    }
    return SH_OK;
}

// The camera NAME names (an id, a substring of one or an index) into m->camera.
sh_status find_camera(CameraManager *cm, const char *name, Impl *m)
{
    std::string want(name), ids;
    {
        // the list holds every camera: it must be gone before the manager can go
        auto cams = cm->cameras();
        for (size_t i = 0; i < cams.size(); i++) {
            const std::string &id = cams[i]->id();
            ids += (ids.empty() ? "" : ", ") + id;
            if (!m->camera &&
                (id == want || want == std::to_string(i) || (!want.empty() && id.find(want) != std::string::npos)))
                m->camera = cams[i];
        }
    }
    if (!m->camera)
        return sh_error_set(SH_EIO, "libcamera:%s: no such camera (found: %s)", name, ids.empty() ? "none" : ids.c_str());
    return SH_OK;
}

// Acquires and configures m's camera: one stream, the format and size asked kept by validation;
// *got its format.
sh_status configure_stream(Impl *m, const char *name, const sh_source_options *o, sh_rawfmt *got)
{
    if (m->camera->acquire() != 0) return sh_error_set(SH_EIO, "libcamera:%s: camera busy", name);
    m->acquired = true;
    m->config = m->camera->generateConfiguration({StreamRole::VideoRecording});
    if (!m->config || m->config->size() < 1)
        return sh_error_set(SH_EUNSUPPORTED, "libcamera:%s: no video configuration", name);
    StreamConfiguration &sc = m->config->at(0);
    if (o->format >= 0) {
        PixelFormat pf = from_raw((sh_rawfmt)o->format);
        if (!pf.isValid())
            return sh_error_set(SH_EUNSUPPORTED, "libcamera:%s: format %s not supported", name,
                                sh_rawfmt_name((sh_rawfmt)o->format));
        sc.pixelFormat = pf;
    }
    if (o->width > 0 && o->height > 0) sc.size = Size((unsigned)o->width, (unsigned)o->height);
    sc.bufferCount = (unsigned)(o->buffers > 0 ? o->buffers : 4);
    CameraConfiguration::Status vs = m->config->validate();
    if (vs == CameraConfiguration::Invalid || !to_raw(sc.pixelFormat, got) ||
        (o->format >= 0 && (int)*got != o->format) ||
        (o->width > 0 && (int)sc.size.width != o->width) || (o->height > 0 && (int)sc.size.height != o->height))
        return sh_error_set(SH_EUNSUPPORTED, "libcamera:%s: asked %dx%d %s, the camera gives %s", name, o->width,
                            o->height, o->format >= 0 ? sh_rawfmt_name((sh_rawfmt)o->format) : "any",
                            sc.toString().c_str());
    sh_status st;
    // before the allocator: the buffers would be this size
    if ((st = sh_source_check_pixels(o, "libcamera", name, (int)sc.size.width, (int)sc.size.height)) != SH_OK)
        return st;
    if (m->camera->configure(m->config.get()) != 0)
        return sh_error_set(SH_EIO, "libcamera:%s: configure %s failed", name, sc.toString().c_str());
    m->stream = sc.stream();
    return SH_OK;
}

// Allocates m's buffers, maps each once (need: the bytes a frame takes at least) and makes one
// request per buffer.
sh_status map_buffers(Impl *m, const char *name, size_t need)
{
    m->alloc = std::make_unique<FrameBufferAllocator>(m->camera);
    if (m->alloc->allocate(m->stream) < 2) return sh_error_set(SH_EIO, "libcamera:%s: fewer than 2 buffers", name);
    const auto &bufs = m->alloc->buffers(m->stream);
    for (size_t i = 0; i < bufs.size(); i++) {
        const FrameBuffer *fb = bufs[i].get();
        const auto &planes = fb->planes();
        // all planes in one dmabuf, back to back: one mapping, one frame pointer
        int fd = planes[0].fd.get();
        size_t start = planes[0].offset, end = (size_t)planes[0].offset + planes[0].length;
        for (size_t p = 1; p < planes.size(); p++) {
            if (planes[p].fd.get() != fd || planes[p].offset != end)
                return sh_error_set(SH_EUNSUPPORTED, "libcamera:%s: planes not contiguous in one buffer", name);
            end += planes[p].length;
        }
        void *map = mmap(nullptr, end, PROT_READ, MAP_SHARED, fd, 0);
        m->maps.push_back(map);
        m->map_len.push_back(end);
        if (map == MAP_FAILED || end - start < need)
            return sh_error_set(SH_EIO, "libcamera:%s: cannot map buffer %zu", name, i);
        m->data.push_back((uint8_t *)map + start);
        std::unique_ptr<Request> req = m->camera->createRequest(i);
        if (!req || req->addBuffer(m->stream, bufs[i].get()) != 0)
            return sh_error_set(SH_EIO, "libcamera:%s: cannot create request %zu", name, i);
        m->requests.push_back(std::move(req));
    }
    return SH_OK;
}

// Looks the camera up, configures, allocates and maps; *out is left null on failure.
sh_status open_camera(const char *name, const sh_source_options *o, Impl **out, sh_rawfmt *format, int *width,
                      int *height, int *stride_out)
{
    *out = nullptr;
    CameraManager *cm = manager_get();
    if (!cm) return sh_error_set(SH_EIO, "libcamera:%s: the camera manager does not start", name);
    Impl *m = new (std::nothrow) Impl();
    if (!m) {
        manager_put();
        return sh_error_set(SH_ENOMEM, "libcamera:%s: out of memory", name);
    }
    removed_device_fds(&m->removed_before);
    sh_status st;
    sh_rawfmt got = SH_RAW_MJPEG; // set by configure_stream
    if ((st = find_camera(cm, name, m)) != SH_OK ||
        (st = camera_controls(m->camera.get(), name, o, &m->initial)) != SH_OK ||
        (st = configure_stream(m, name, o, &got)) != SH_OK) {
        destroy(m);
        return st;
    }
    const StreamConfiguration &sc = m->config->at(0);
    int stride = (int)sc.stride;
    if (got != SH_RAW_MJPEG && stride < sh_rawfmt_min_stride(got, (int)sc.size.width))
        stride = sh_rawfmt_min_stride(got, (int)sc.size.width);
    size_t need = got == SH_RAW_MJPEG ? 1 : sh_raw_frame_size(got, (int)sc.size.width, (int)sc.size.height, stride);
    if ((st = map_buffers(m, name, need)) != SH_OK) {
        destroy(m);
        return st;
    }
    m->efd = eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC);
    if (m->efd < 0) {
        st = sh_error_set(SH_EIO, "libcamera:%s: eventfd: %s", name, strerror(errno));
        destroy(m);
        return st;
    }
    m->done.reserve(m->requests.size() + 1); // the completion thread never allocates
    m->held.assign(m->requests.size(), 0);
    m->camera->requestCompleted.connect(m, &Impl::completed);
    m->camera->disconnected.connect(m, &Impl::disconnected);
    *out = m;
    *format = got;
    *width = (int)sc.size.width;
    *height = (int)sc.size.height;
    *stride_out = stride;
    return SH_OK;
}

} // namespace

extern "C" sh_status sh_source_open_libcamera(const char *name, const sh_source_options *o, sh_source **out)
{
    lc_source *l = new (std::nothrow) lc_source();
    if (!l) return sh_error_set(SH_ENOMEM, "libcamera:%s: out of memory", name);
    sh_status st = open_camera(name, o, &l->impl, &l->base.format, &l->base.width, &l->base.height, &l->base.stride);
    if (st != SH_OK) {
        delete l;
        return st;
    }
    l->name = name;
    l->base.ops = &ops;
    l->base.opts = *o;
    *out = &l->base;
    return SH_OK;
}

#else

extern "C" sh_status sh_source_open_libcamera(const char *name, const sh_source_options *opts, sh_source **out)
{
    (void)opts;
    (void)out;
    return sh_error_set(SH_EUNSUPPORTED, "libcamera:%s: built without libcamera", name);
}

#endif
