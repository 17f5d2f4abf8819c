// libcamera:NAME — a libcamera camera behind the C source interface (Debian 12: libcamera
// 0.0.3, whose API changes between versions; built only when pkg-config finds it).
//
// NAME is a camera id, a substring of one, or an index in the manager's list ("0"). One stream
// (role VideoRecording), format and size as asked (the validated configuration must keep them),
// options.buffers (4) buffers from FrameBufferAllocator, mapped once; one request per buffer.
// libcamera completes requests on its own thread: the handler only records the request's index in
// a small locked ring and writes an eventfd, which is this source's pollable fd. Frames whose
// metadata says FrameError are requeued and counted. Not yet: controls, and reopening a camera
// that went away (a timeout is counted as a loss; the camera is not reopened).
#include "source_internal.h"

#ifdef SH_HAVE_LIBCAMERA

#include <errno.h>
#include <poll.h>
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
    int64_t last_frame = 0;
    sh_rawfmt format = SH_RAW_YUYV;

    void completed(Request *r)
    {
        if (r->status() == Request::RequestCancelled) return;
        {
            std::lock_guard<std::mutex> g(lock);
            done.push_back((int)r->cookie());
        }
        uint64_t one = 1;
        ssize_t w = write(efd, &one, sizeof one);
        (void)w;
    }
};

struct lc_source {
    sh_source base;
    Impl *impl;
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

sh_status lc_start(sh_source *s)
{
    Impl *m = ((lc_source *)s)->impl;
    if (m->camera->start() != 0) return sh_error_set(SH_EIO, "%s: cannot start", s->name);
    m->running = true;
    for (auto &r : m->requests)
        if (m->camera->queueRequest(r.get()) != 0) return sh_error_set(SH_EIO, "%s: cannot queue a request", s->name);
    m->last_frame = sh_monotonic_ns();
    s->stats.online = 1;
    return SH_OK;
}

int lc_fd(const sh_source *s) { return ((const lc_source *)s)->impl->efd; }

sh_status lc_dequeue(sh_source *s, int timeout_ms, sh_source_frame *f, int *got)
{
    Impl *m = ((lc_source *)s)->impl;
    int64_t deadline = timeout_ms < 0 ? INT64_MAX : sh_monotonic_ns() + (int64_t)timeout_ms * 1000000;
    int lost_ms = s->opts.timeout_ms > 0 ? s->opts.timeout_ms : 1000;
    for (;;) {
        int index = -1;
        {
            std::lock_guard<std::mutex> g(m->lock);
            if (!m->done.empty()) {
                index = m->done.front();
                m->done.erase(m->done.begin());
            }
        }
        int64_t now = sh_monotonic_ns();
        if (index < 0) {
            if (s->stats.online && now - m->last_frame > (int64_t)lost_ms * 1000000) {
                s->stats.losses++;
                s->stats.online = 0;
            }
            if (now >= deadline) return SH_OK;
            int64_t left = deadline - now;
            struct pollfd p = {m->efd, POLLIN, 0};
            poll(&p, 1, left > 100000000 ? 100 : (int)(left / 1000000) + 1);
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
        m->last_frame = now;
        s->stats.online = 1;
        size_t bytes = 0;
        for (const auto &p : md.planes()) bytes += p.bytesused;
        if (s->format != SH_RAW_MJPEG && bytes < sh_raw_frame_size(s->format, s->width, s->height, s->stride))
            bytes = sh_raw_frame_size(s->format, s->width, s->height, s->stride);
        memset(f, 0, sizeof *f);
        f->camera = s->opts.camera;
        f->sequence = md.sequence;
        f->timestamp_ns = (int64_t)md.timestamp;
        f->raw.format = s->format;
        f->raw.width = s->width;
        f->raw.height = s->height;
        f->raw.stride = s->stride;
        f->raw.data = m->data[(size_t)index];
        f->raw.bytes = bytes;
        f->slot = index;
        s->stats.frames++;
        *got = 1;
        return SH_OK;
    }
}

sh_status lc_release(sh_source *s, sh_source_frame *f)
{
    Impl *m = ((lc_source *)s)->impl;
    if (f->slot < 0 || (size_t)f->slot >= m->requests.size())
        return sh_error_set(SH_EINVAL, "%s: release of a frame not held", s->name);
    Request *req = m->requests[(size_t)f->slot].get();
    f->slot = -1;
    if (!m->running) return SH_OK;
    req->reuse(Request::ReuseBuffers);
    if (m->camera->queueRequest(req) != 0) return sh_error_set(SH_EIO, "%s: cannot requeue", s->name);
    return SH_OK;
}

sh_status lc_stop(sh_source *s)
{
    Impl *m = ((lc_source *)s)->impl;
    if (m->running) m->camera->stop();
    m->running = false;
    std::lock_guard<std::mutex> g(m->lock);
    m->done.clear();
    s->stats.online = 0;
    return SH_OK;
}

void destroy(Impl *m)
{
    if (m->running) m->camera->stop();
    if (m->camera) m->camera->requestCompleted.disconnect(m, &Impl::completed);
    for (size_t i = 0; i < m->maps.size(); i++)
        if (m->maps[i] && m->maps[i] != MAP_FAILED) munmap(m->maps[i], m->map_len[i]);
    m->requests.clear();
    m->alloc.reset();
    if (m->acquired) m->camera->release();
    m->camera.reset();
    if (m->efd >= 0) close(m->efd);
    delete m;
    manager_put();
}

void lc_close(sh_source *s)
{
    lc_source *l = (lc_source *)s;
    destroy(l->impl);
    free(l);
}

const sh_source_ops ops = {lc_start, lc_fd, lc_dequeue, lc_release, lc_stop, lc_close};

} // namespace

extern "C" sh_status sh_source_open_libcamera(const char *name, const sh_source_options *o, sh_source **out)
{
    if (o->exposure != SH_SOURCE_CTRL_UNSET || o->gain != SH_SOURCE_CTRL_UNSET ||
        o->white_balance != SH_SOURCE_CTRL_UNSET)
        return sh_error_set(SH_EUNSUPPORTED, "libcamera:%s: camera controls not supported yet", name);
    CameraManager *cm = manager_get();
    if (!cm) return sh_error_set(SH_EIO, "libcamera:%s: the camera manager does not start", name);
    Impl *m = new (std::nothrow) Impl();
    if (!m) {
        manager_put();
        return sh_error_set(SH_ENOMEM, "libcamera:%s: out of memory", name);
    }
    sh_status st = SH_OK;
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
    if (!m->camera) {
        st = sh_error_set(SH_EIO, "libcamera:%s: no such camera (found: %s)", name, ids.empty() ? "none" : ids.c_str());
        destroy(m);
        return st;
    }
    if (m->camera->acquire() != 0) {
        st = sh_error_set(SH_EIO, "libcamera:%s: camera busy", name);
        destroy(m);
        return st;
    }
    m->acquired = true;
    m->config = m->camera->generateConfiguration({StreamRole::VideoRecording});
    if (!m->config || m->config->size() < 1) {
        st = sh_error_set(SH_EUNSUPPORTED, "libcamera:%s: no video configuration", name);
        destroy(m);
        return st;
    }
    StreamConfiguration &sc = m->config->at(0);
    if (o->format >= 0) {
        PixelFormat pf = from_raw((sh_rawfmt)o->format);
        if (!pf.isValid()) {
            st = sh_error_set(SH_EUNSUPPORTED, "libcamera:%s: format %s not supported", name,
                              sh_rawfmt_name((sh_rawfmt)o->format));
            destroy(m);
            return st;
        }
        sc.pixelFormat = pf;
    }
    if (o->width > 0 && o->height > 0) sc.size = Size((unsigned)o->width, (unsigned)o->height);
    sc.bufferCount = (unsigned)(o->buffers > 0 ? o->buffers : 4);
    CameraConfiguration::Status vs = m->config->validate();
    sh_rawfmt got;
    if (vs == CameraConfiguration::Invalid || !to_raw(sc.pixelFormat, &got) ||
        (o->format >= 0 && (int)got != o->format) ||
        (o->width > 0 && (int)sc.size.width != o->width) || (o->height > 0 && (int)sc.size.height != o->height)) {
        st = sh_error_set(SH_EUNSUPPORTED, "libcamera:%s: asked %dx%d %s, the camera gives %s", name, o->width,
                          o->height, o->format >= 0 ? sh_rawfmt_name((sh_rawfmt)o->format) : "any",
                          sc.toString().c_str());
        destroy(m);
        return st;
    }
    if (m->camera->configure(m->config.get()) != 0) {
        st = sh_error_set(SH_EIO, "libcamera:%s: configure %s failed", name, sc.toString().c_str());
        destroy(m);
        return st;
    }
    m->stream = sc.stream();
    m->alloc = std::make_unique<FrameBufferAllocator>(m->camera);
    if (m->alloc->allocate(m->stream) < 2) {
        st = sh_error_set(SH_EIO, "libcamera:%s: fewer than 2 buffers", name);
        destroy(m);
        return st;
    }
    int stride = (int)sc.stride;
    if (got != SH_RAW_MJPEG && stride < sh_rawfmt_min_stride(got, (int)sc.size.width))
        stride = sh_rawfmt_min_stride(got, (int)sc.size.width);
    size_t need = got == SH_RAW_MJPEG ? 1 : sh_raw_frame_size(got, (int)sc.size.width, (int)sc.size.height, stride);
    const auto &bufs = m->alloc->buffers(m->stream);
    for (size_t i = 0; i < bufs.size(); i++) {
        const FrameBuffer *fb = bufs[i].get();
        const auto &planes = fb->planes();
        // all planes in one dmabuf, back to back: one mapping, one frame pointer
        int fd = planes[0].fd.get();
        size_t start = planes[0].offset, end = (size_t)planes[0].offset + planes[0].length;
        for (size_t p = 1; p < planes.size(); p++) {
            if (planes[p].fd.get() != fd || planes[p].offset != end) {
                st = sh_error_set(SH_EUNSUPPORTED, "libcamera:%s: planes not contiguous in one buffer", name);
                destroy(m);
                return st;
            }
            end += planes[p].length;
        }
        void *map = mmap(nullptr, end, PROT_READ, MAP_SHARED, fd, 0);
        m->maps.push_back(map);
        m->map_len.push_back(end);
        if (map == MAP_FAILED || end - start < need) {
            st = sh_error_set(SH_EIO, "libcamera:%s: cannot map buffer %zu", name, i);
            destroy(m);
            return st;
        }
        m->data.push_back((uint8_t *)map + start);
        std::unique_ptr<Request> req = m->camera->createRequest(i);
        if (!req || req->addBuffer(m->stream, bufs[i].get()) != 0) {
            st = sh_error_set(SH_EIO, "libcamera:%s: cannot create request %zu", name, i);
            destroy(m);
            return st;
        }
        m->requests.push_back(std::move(req));
    }
    m->efd = eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC);
    if (m->efd < 0) {
        st = sh_error_set(SH_EIO, "libcamera:%s: eventfd: %s", name, strerror(errno));
        destroy(m);
        return st;
    }
    m->done.reserve(m->requests.size() + 1); // the completion thread never allocates
    m->camera->requestCompleted.connect(m, &Impl::completed);
    lc_source *l = (lc_source *)calloc(1, sizeof *l);
    if (!l) {
        destroy(m);
        return sh_error_set(SH_ENOMEM, "libcamera:%s: out of memory", name);
    }
    l->impl = m;
    l->base.ops = &ops;
    l->base.opts = *o;
    l->base.format = got;
    l->base.width = (int)sc.size.width;
    l->base.height = (int)sc.size.height;
    l->base.stride = stride;
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
