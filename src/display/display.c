/* The shared-memory display buffer: writer and reader (see display.h for the protocol). */
#include "stillheart/display.h"

#include <errno.h>
#include <fcntl.h>
#include <grp.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#define SLOT_HEADER_BYTES 128

typedef struct {
    uint64_t lock;  /* sequence lock: odd while the writer fills the slot */
    uint64_t pad;
    sh_display_frame_info info;
    uint8_t reserved[SLOT_HEADER_BYTES - 16 - sizeof(sh_display_frame_info)];
} slot_header;

_Static_assert(sizeof(sh_display_header) == 256, "the header's size is part of the format");
_Static_assert(sizeof(sh_display_frame_info) == 80, "frame info is part of the format");
_Static_assert(sizeof(slot_header) == SLOT_HEADER_BYTES, "slot header is part of the format");

/* The pixel layout of one slot for a format: planes packed, rows padded to 16 bytes. */
static sh_status layout(sh_display_header *h, sh_pixfmt format, int width, int height)
{
    sh_image probe;
    uint8_t dummy;
    if (sh_image_wrap(&probe, format, width, height, &dummy) != SH_OK) return SH_EINVAL;
    uint32_t offset = 0;
    h->num_planes = (uint32_t)probe.num_planes;
    for (int p = 0; p < probe.num_planes; p++) {
        uint32_t row = (uint32_t)probe.plane[p].width * (uint32_t)sh_pixfmt_channels(format);
        h->stride[p] = (row + 15u) & ~15u;
        h->plane_offset[p] = offset;
        offset += h->stride[p] * (uint32_t)probe.plane[p].height;
    }
    h->frame_bytes = offset;
    h->slot_bytes = (SLOT_HEADER_BYTES + offset + 63u) & ~63u;
    return SH_OK;
}

struct sh_display_writer {
    char name[256];
    int fd;
    uint8_t *base;
    size_t size;
    sh_display_header *header;  /* in shared memory: written, never read back */
    sh_display_header geometry; /* the layout publish relies on, kept privately */
    uint64_t lock[SH_DISPLAY_MAX_SLOTS]; /* each slot's lock count, as last stored */
    uint64_t sequence;
    uint32_t next_slot;
};

/* A segment already under this name (a daemon that stopped, or one being replaced) is marked
 * invalid for the readers still mapping it and then unlinked, never rewritten in place: its
 * slots' lock counts would start again from zero under a reader in the middle of a copy, which
 * then finds the same even count after the copy and keeps a frame made of two writers' pixels,
 * and a smaller new segment would cut pages off under it (SIGBUS). Readers of the old object
 * keep a whole frame or see "replaced". */
static sh_status retire_previous(const char *name)
{
    int fd = shm_open(name, O_RDWR, 0);
    if (fd < 0) return errno == ENOENT ? SH_OK : sh_error_set(SH_EIO, "display: open the existing %s: %s", name, strerror(errno));
    struct stat sb;
    if (fstat(fd, &sb) == 0 && sb.st_size >= (off_t)sizeof(sh_display_header)) {
        sh_display_header *old = mmap(NULL, sizeof *old, PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0);
        if (old != MAP_FAILED) {
            __atomic_store_n(&old->magic, 0, __ATOMIC_RELEASE);
            munmap(old, sizeof *old);
        }
    }
    close(fd);
    if (shm_unlink(name) != 0 && errno != ENOENT)
        return sh_error_set(SH_EIO, "display: remove the existing %s: %s", name, strerror(errno));
    return SH_OK;
}

sh_status sh_display_writer_create(const char *name, sh_pixfmt format, int width, int height,
                                   int slots, int full_range, const char *group,
                                   sh_display_writer **out)
{
    if (!name || name[0] != '/' || strlen(name) >= 255 || strchr(name + 1, '/'))
        return sh_error_set(SH_EINVAL, "display: shared-memory name must look like /name");
    if (slots < SH_DISPLAY_MIN_SLOTS || slots > SH_DISPLAY_MAX_SLOTS)
        return sh_error_set(SH_EINVAL, "display: %d slots, need %d..%d", slots,
                            SH_DISPLAY_MIN_SLOTS, SH_DISPLAY_MAX_SLOTS);
    sh_display_header h = {0};
    if (layout(&h, format, width, height) != SH_OK)
        return sh_error_set(SH_EINVAL, "display: cannot hold %dx%d %s frames", width, height,
                            sh_pixfmt_name(format));
    sh_display_writer *w = calloc(1, sizeof *w);
    if (!w) return sh_error_set(SH_ENOMEM, "display: out of memory");
    snprintf(w->name, sizeof w->name, "%s", name);
    w->size = sizeof h + (size_t)h.slot_bytes * (size_t)slots;
    w->fd = -1;
    sh_status st = retire_previous(name);
    if (st != SH_OK) goto fail;
    /* O_EXCL: a new object, zero filled by ftruncate; a second writer creating the same name
     * at the same moment fails here rather than sharing the slots */
    w->fd = shm_open(name, O_RDWR | O_CREAT | O_EXCL, 0660);
    if (w->fd < 0) {
        st = sh_error_set(SH_EIO, "display: shm_open %s: %s", name, strerror(errno));
        goto fail;
    }
    /* 0660 regardless of the umask, for the readers of the service's group */
    if (fchmod(w->fd, 0660) != 0) {
        st = sh_error_set(SH_EIO, "display: chmod %s: %s", name, strerror(errno));
        goto fail;
    }
    if (group && *group) {
        struct group *g = getgrnam(group);
        if (!g || fchown(w->fd, (uid_t)-1, g->gr_gid) != 0) {
            st = sh_error_set(SH_EIO, "display: %s: cannot give the segment to group '%s': %s",
                              name, group, g ? strerror(errno) : "no such group");
            goto fail;
        }
    }
    if (ftruncate(w->fd, (off_t)w->size) != 0) {
        st = sh_error_set(SH_EIO, "display: resize %s to %zu bytes: %s", name, w->size, strerror(errno));
        goto fail;
    }
    w->base = mmap(NULL, w->size, PROT_READ | PROT_WRITE, MAP_SHARED, w->fd, 0);
    if (w->base == MAP_FAILED) {
        w->base = NULL;
        st = sh_error_set(SH_EIO, "display: mmap %s: %s", name, strerror(errno));
        goto fail;
    }
    w->header = (sh_display_header *)w->base;
    h.version = SH_DISPLAY_VERSION;
    h.header_size = sizeof h;
    h.width = (uint32_t)width;
    h.height = (uint32_t)height;
    h.format = (uint32_t)format;
    h.siting = 0;
    h.slot_count = (uint32_t)slots;
    h.full_range = full_range ? 1 : 0;
    h.writer_pid = getpid();
    w->geometry = h;
    w->geometry.magic = SH_DISPLAY_MAGIC;
    memcpy(w->base, &h, sizeof h); /* magic still 0: a reader opening now refuses the segment */
    /* Release: a reader that loads the magic with acquire (reader_init) sees every field above. */
    __atomic_store_n(&w->header->magic, SH_DISPLAY_MAGIC, __ATOMIC_RELEASE);
    *out = w;
    return SH_OK;
fail:
    if (w->fd >= 0) {
        close(w->fd);
        shm_unlink(name); /* ours (O_EXCL), and never valid */
    }
    free(w);
    return st;
}

sh_status sh_display_writer_publish(sh_display_writer *w, const sh_image *frame,
                                    const sh_display_frame_info *info)
{
    const sh_display_header *h = &w->geometry;
    if (!frame || frame->format != (sh_pixfmt)h->format || frame->width != (int)h->width ||
        frame->height != (int)h->height)
        return sh_error_set(SH_EINVAL, "display: frame does not match the segment's %ux%u %s",
                            h->width, h->height, sh_pixfmt_name((sh_pixfmt)h->format));
    uint32_t slot = w->next_slot;
    w->next_slot = (slot + 1) % h->slot_count;
    uint8_t *base = w->base + sizeof *h + (size_t)slot * h->slot_bytes;
    slot_header *sh = (slot_header *)base;
    uint64_t lock = w->lock[slot]; /* even; this writer is the slot's only writer (O_EXCL) */
    w->lock[slot] = lock + 2;
    /* The writer's half of the sequence lock (Boehm, "Can seqlocks get along with programming
     * language memory models?", 2012). The odd count is stored first, then a release fence:
     * every store after the fence (the pixels) becomes visible no earlier than the odd count,
     * so a reader that copied any new byte finds the count changed when it looks again. On
     * aarch64 the fence is a DMB ISH, which orders the odd store before the later stores; on
     * x86 stores are not reordered with each other and the fence only stops the compiler. */
    __atomic_store_n(&sh->lock, lock + 1, __ATOMIC_RELAXED);
    __atomic_thread_fence(__ATOMIC_RELEASE);
    sh_display_frame_info copy = info ? *info : (sh_display_frame_info){0};
    copy.sequence = ++w->sequence;
    copy.publish_ns = sh_monotonic_ns();
    copy.reason[sizeof copy.reason - 1] = 0;
    memcpy(&sh->info, &copy, sizeof copy);
    uint8_t *pixels = base + SLOT_HEADER_BYTES;
    for (uint32_t p = 0; p < h->num_planes; p++) {
        size_t row = (size_t)frame->plane[p].width * (size_t)sh_pixfmt_channels(frame->format);
        for (int y = 0; y < frame->plane[p].height; y++)
            memcpy(pixels + h->plane_offset[p] + (size_t)y * h->stride[p],
                   frame->plane[p].data + (size_t)y * frame->plane[p].stride, row);
    }
    /* Release (STLR on aarch64): all of the frame is visible before the even count, and the
     * count before `latest` names the slot. */
    __atomic_store_n(&sh->lock, lock + 2, __ATOMIC_RELEASE);
    __atomic_store_n(&w->header->latest, (copy.sequence << 8) | slot, __ATOMIC_RELEASE);
    return SH_OK;
}

/* Whether the name still stands for this writer's object: another writer may have retired it
 * and made its own under the name, which this one must not unlink. */
static int name_is_ours(const sh_display_writer *w)
{
    struct stat mine, named;
    int fd = shm_open(w->name, O_RDONLY, 0);
    if (fd < 0) return 0;
    int same = fstat(w->fd, &mine) == 0 && fstat(fd, &named) == 0 && mine.st_dev == named.st_dev &&
               mine.st_ino == named.st_ino;
    close(fd);
    return same;
}

void sh_display_writer_destroy(sh_display_writer *w, int unlink_segment)
{
    if (!w) return;
    if (w->base) {
        __atomic_store_n(&w->header->closed, 1, __ATOMIC_RELEASE);
        munmap(w->base, w->size);
    }
    if (unlink_segment && name_is_ours(w)) shm_unlink(w->name);
    close(w->fd);
    free(w);
}

struct sh_display_reader {
    int fd;
    const uint8_t *base;
    size_t size;
    int mapped;
    sh_display_header geometry; /* validated copy: the segment's own fields are not trusted again */
    uint64_t last_sequence;
    uint8_t *stage;             /* one slot's pixels: a copy is made here and kept only if whole */
};

/* Everything a reader relies on, checked against the segment's size. */
static sh_status validate(const sh_display_header *h, size_t size)
{
    if (size < sizeof *h || h->magic != SH_DISPLAY_MAGIC)
        return sh_error_set(SH_EFORMAT, "display: not a stillheart display segment");
    if (h->version != SH_DISPLAY_VERSION || h->header_size != sizeof *h)
        return sh_error_set(SH_EFORMAT, "display: segment version %u, this reader knows %u",
                            h->version, SH_DISPLAY_VERSION);
    if (h->format > SH_PIX_YUV444 || h->slot_count < SH_DISPLAY_MIN_SLOTS ||
        h->slot_count > SH_DISPLAY_MAX_SLOTS)
        return sh_error_set(SH_EFORMAT, "display: bad format %u or slot count %u", h->format,
                            h->slot_count);
    sh_display_header expect = {0};
    if (h->width > SH_IMAGE_MAX_SIZE || h->height > SH_IMAGE_MAX_SIZE ||
        layout(&expect, (sh_pixfmt)h->format, (int)h->width, (int)h->height) != SH_OK)
        return sh_error_set(SH_EFORMAT, "display: bad geometry %ux%u", h->width, h->height);
    if (h->num_planes != expect.num_planes || h->frame_bytes != expect.frame_bytes ||
        h->slot_bytes != expect.slot_bytes ||
        memcmp(h->stride, expect.stride, sizeof expect.stride) ||
        memcmp(h->plane_offset, expect.plane_offset, sizeof expect.plane_offset))
        return sh_error_set(SH_EFORMAT, "display: plane layout does not match %ux%u %s", h->width,
                            h->height, sh_pixfmt_name((sh_pixfmt)h->format));
    if ((size - sizeof *h) / h->slot_bytes < h->slot_count)
        return sh_error_set(SH_EFORMAT, "display: segment of %zu bytes too small for %u slots",
                            size, h->slot_count);
    return SH_OK;
}

static sh_status reader_init(sh_display_reader *r)
{
    /* Acquire, paired with the writer's release store of the magic: the fields copied next are
     * the ones written before it (a segment still being built shows magic 0 and is refused). */
    uint64_t magic = __atomic_load_n(&((const sh_display_header *)r->base)->magic, __ATOMIC_ACQUIRE);
    memcpy(&r->geometry, r->base, sizeof r->geometry);
    r->geometry.magic = magic;
    sh_status st = validate(&r->geometry, r->size);
    if (st != SH_OK) return st;
    r->stage = malloc(r->geometry.frame_bytes ? r->geometry.frame_bytes : 1);
    return r->stage ? SH_OK : sh_error_set(SH_ENOMEM, "display: out of memory");
}

sh_status sh_display_reader_open(const char *name, sh_display_reader **out)
{
    sh_display_reader *r = calloc(1, sizeof *r);
    if (!r) return sh_error_set(SH_ENOMEM, "display: out of memory");
    sh_status st;
    struct stat sb;
    r->fd = shm_open(name, O_RDONLY, 0);
    if (r->fd < 0) {
        st = sh_error_set(SH_EIO, "display: %s: %s (is the daemon running?)", name, strerror(errno));
        goto fail;
    }
    if (fstat(r->fd, &sb) != 0 || sb.st_size < (off_t)sizeof(sh_display_header)) {
        st = sh_error_set(SH_EFORMAT, "display: %s: not a stillheart display segment", name);
        goto fail;
    }
    r->size = (size_t)sb.st_size;
    void *base = mmap(NULL, r->size, PROT_READ, MAP_SHARED, r->fd, 0);
    if (base == MAP_FAILED) {
        st = sh_error_set(SH_EIO, "display: mmap %s: %s", name, strerror(errno));
        goto fail;
    }
    r->base = base;
    r->mapped = 1;
    if ((st = reader_init(r)) != SH_OK) goto fail;
    *out = r;
    return SH_OK;
fail:
    sh_display_reader_close(r);
    return st;
}

sh_status sh_display_reader_attach(const void *buffer, size_t size, sh_display_reader **out)
{
    if (!buffer) return sh_error_set(SH_EINVAL, "display: no buffer");
    sh_display_reader *r = calloc(1, sizeof *r);
    if (!r) return sh_error_set(SH_ENOMEM, "display: out of memory");
    r->fd = -1;
    r->base = buffer;
    r->size = size;
    sh_status st = size >= sizeof(sh_display_header) ? reader_init(r)
                                                     : sh_error_set(SH_EFORMAT, "display: too small");
    if (st != SH_OK) {
        sh_display_reader_close(r);
        return st;
    }
    *out = r;
    return SH_OK;
}

const sh_display_header *sh_display_reader_header(const sh_display_reader *r)
{
    return &r->geometry;
}

/* One attempt at a slot: SH_OK with a whole frame in r->stage and *info, SH_EINVAL when the
 * writer was in the slot before or during the copy (try again).
 *
 * The reader's half of the sequence lock. The count is loaded with acquire (LDAR on aarch64):
 * no load of the copy is performed before it. After the copy, an acquire fence (DMB ISHLD on
 * aarch64) keeps every load of the copy before the second load of the count; without it the
 * processor may satisfy some pixel loads after that load, from a frame the check never saw.
 * So if both loads return the same even count, no store of a publish (odd count first, release
 * fence, pixels, release store of the next even count) fell inside the copy: a store made
 * after the odd count and read by the copy would make the second load see that odd count or a
 * later one. The copies themselves are plain memcpy (a relaxed atomic per byte would cost a
 * frame's time); GCC and Clang do not move memory accesses across these fences, and a copy that
 * raced a writer is thrown away unread. On x86 (TSO) loads are not reordered with each other and
 * the fence only stops the compiler. The count is 64 bits and only ever grows in one object (a
 * new writer makes a new object: retire_previous), so an equal count means the same frame. */
static sh_status copy_slot(sh_display_reader *r, uint32_t slot, sh_display_frame_info *info)
{
    const sh_display_header *g = &r->geometry;
    const uint8_t *base = r->base + sizeof *g + (size_t)slot * g->slot_bytes;
    const slot_header *sh = (const slot_header *)base;
    uint64_t before = __atomic_load_n(&sh->lock, __ATOMIC_ACQUIRE);
    if (before & 1) return SH_EINVAL;
    memcpy(info, (const void *)&sh->info, sizeof *info);
    memcpy(r->stage, base + SLOT_HEADER_BYTES, g->frame_bytes);
    __atomic_thread_fence(__ATOMIC_ACQUIRE);
    if (__atomic_load_n(&sh->lock, __ATOMIC_RELAXED) != before) return SH_EINVAL;
    info->reason[sizeof info->reason - 1] = 0;
    return SH_OK;
}

sh_status sh_display_reader_next(sh_display_reader *r, sh_image *frame,
                                 sh_display_frame_info *info, int timeout_ms)
{
    const sh_display_header *g = &r->geometry;
    const sh_display_header *live = (const sh_display_header *)r->base;
    if (!frame || frame->format != (sh_pixfmt)g->format || frame->width != (int)g->width ||
        frame->height != (int)g->height)
        return sh_error_set(SH_EINVAL, "display: reader frame must be %ux%u %s", g->width,
                            g->height, sh_pixfmt_name((sh_pixfmt)g->format));
    int64_t deadline = timeout_ms < 0 ? INT64_MAX : sh_monotonic_ns() + (int64_t)timeout_ms * 1000000;
    for (;;) {
        uint64_t latest = __atomic_load_n(&live->latest, __ATOMIC_ACQUIRE);
        uint32_t slot = (uint32_t)(latest & 0xff);
        sh_display_frame_info copy;
        /* the caller's frame and info are written only from a whole copy of a newer frame: on
         * every other return (timeout, closed, replaced) they hold what they held */
        if (latest != 0 && (latest >> 8) > r->last_sequence && slot < g->slot_count &&
            copy_slot(r, slot, &copy) == SH_OK && copy.sequence > r->last_sequence) {
            for (uint32_t p = 0; p < g->num_planes; p++) {
                size_t row = (size_t)frame->plane[p].width * (size_t)sh_pixfmt_channels(frame->format);
                for (int y = 0; y < frame->plane[p].height; y++)
                    memcpy(frame->plane[p].data + (size_t)y * frame->plane[p].stride,
                           r->stage + g->plane_offset[p] + (size_t)y * g->stride[p], row);
            }
            r->last_sequence = copy.sequence;
            if (info) *info = copy;
            return SH_OK;
        }
        if (__atomic_load_n(&live->magic, __ATOMIC_ACQUIRE) != SH_DISPLAY_MAGIC)
            return sh_error_set(SH_EEOF, "display: the segment was replaced");
        if (__atomic_load_n(&live->closed, __ATOMIC_ACQUIRE) && (latest >> 8) <= r->last_sequence)
            return sh_error_set(SH_EEOF, "display: the writer closed the segment");
        if (sh_monotonic_ns() >= deadline) return sh_error_set(SH_EIO, "display: no new frame in %d ms", timeout_ms);
        struct timespec pause = {0, 500000}; /* 0.5 ms: a frame period is 16 ms or more */
        nanosleep(&pause, NULL);
    }
}

void sh_display_reader_close(sh_display_reader *r)
{
    if (!r) return;
    if (r->mapped) munmap((void *)r->base, r->size);
    if (r->fd >= 0) close(r->fd);
    free(r->stage);
    free(r);
}
