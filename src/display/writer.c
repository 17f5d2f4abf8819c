/* The display segment's writer (display.h has the protocol; docs/daemon.md the security model).
 *
 * The writer trusts nothing in shared memory. Its layout (slot count, strides, offsets, sizes)
 * and each slot's lock count live in this struct; the segment is written, never read back.
 * Before each publish one fstat of its own descriptor checks that the object is still whole and
 * still its own: the size it made, owner, mode and group as it set them, and one link (a name
 * unlinked, or replaced by a rename, leaves 0). A segment that fails the check, or that faults
 * during the copy (truncated between the check and the copy: display_guard), is marked retired
 * for its readers and a new one is made under the name, with a new generation. */
#include <errno.h>
#include <fcntl.h>
#include <grp.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/file.h>
#include <sys/mman.h>
#include <sys/random.h>
#include <sys/stat.h>
#include <unistd.h>
#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#include "display_internal.h"

#define SEGMENT_MODE 0640

struct sh_display_writer {
    char name[256];
    char group[64];
    int has_group;
    gid_t gid;
    int fd;
    uint8_t *base;
    size_t size;
    dev_t dev;
    ino_t ino;
    sh_display_header geometry; /* what publish relies on and writes out, kept privately */
    uint64_t lock[SH_DISPLAY_MAX_SLOTS]; /* each slot's lock count, as last stored */
    uint64_t sequence;
    uint32_t next_slot;
    uint64_t remade;
};

/* A random generation, never 0 (0: a segment of a writer before generations). */
static uint64_t new_generation(void)
{
    uint64_t g = 0;
    while (g == 0)
        if (getrandom(&g, sizeof g, 0) != (ssize_t)sizeof g) g = (uint64_t)sh_monotonic_ns() ^ ((uint64_t)getpid() << 40);
    return g;
}

/* Marks a mapped header retired (magic 0) or closed, under the guard: the object may have been
 * cut short, and then there is nothing left to mark. */
static void mark(void *header, size_t mapped, int closed)
{
    sh_display_header *h = header;
    display_guard g;
    if (sigsetjmp(g.jump, 1) == 0) {
        display_guard_enter(&g, header, mapped);
        if (closed)
            __atomic_store_n(&h->closed, 1, __ATOMIC_RELEASE);
        else
            __atomic_store_n(&h->magic, 0, __ATOMIC_RELEASE);
    }
    display_guard_leave();
}

/* Whether the name stands for the object dev/ino. */
static int name_is(const char *name, dev_t dev, ino_t ino)
{
    struct stat sb;
    int fd = shm_open(name, O_RDONLY | O_NOFOLLOW, 0);
    if (fd < 0) return 0;
    int same = fstat(fd, &sb) == 0 && sb.st_dev == dev && sb.st_ino == ino;
    close(fd);
    return same;
}

/* The object under the name is not a live writer's (its lock is free) and belongs to this uid:
 * it is marked retired for the readers still mapping it and unlinked, never rewritten in place:
 * its slots' lock counts would start again from zero under a reader in the middle of a copy,
 * which then finds the same even count after the copy and keeps a frame made of two writers'
 * pixels, and a smaller new segment would cut pages off under it (SIGBUS). Another uid's object
 * is refused with its owner named: a segment of someone else's must never be taken for ours. */
static sh_status retire_existing(const char *name)
{
    int fd = shm_open(name, O_RDWR | O_NOFOLLOW, 0);
    if (fd < 0 && errno == EACCES) fd = shm_open(name, O_RDONLY | O_NOFOLLOW, 0);
    if (fd < 0)
        return errno == ENOENT ? SH_OK : sh_error_set(SH_EIO, "display: open the existing %s: %s", name, strerror(errno));
    struct stat sb;
    if (fstat(fd, &sb) != 0) {
        close(fd);
        return sh_error_set(SH_EIO, "display: stat the existing %s: %s", name, strerror(errno));
    }
    if (sb.st_uid != geteuid()) {
        char owner[160], self[160];
        display_describe_uid(sb.st_uid, owner, sizeof owner);
        display_describe_uid(geteuid(), self, sizeof self);
        close(fd);
        return sh_error_set(SH_EINVAL, "display: %s belongs to %s, not to this service (%s): refused (someone "
                            "else made the name first; remove /dev/shm%s as root, or choose another [sink] display)",
                            name, owner, self, name);
    }
    if (flock(fd, LOCK_EX | LOCK_NB) != 0) {
        close(fd);
        return sh_error_set(SH_EIO, "display: %s is in use by another writer that is still running "
                            "(another stillheart on the same [sink] display name?)", name);
    }
    if (sb.st_size >= (off_t)sizeof(sh_display_header)) {
        sh_display_header *old = mmap(NULL, sizeof *old, PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0);
        if (old != MAP_FAILED) {
            mark(old, sizeof *old, 0);
            munmap(old, sizeof *old);
        }
    }
    close(fd);
    if (shm_unlink(name) != 0 && errno != ENOENT)
        return sh_error_set(SH_EIO, "display: remove the existing %s: %s", name, strerror(errno));
    return SH_OK;
}

static void unmap(sh_display_writer *w)
{
    if (w->base) munmap(w->base, w->size);
    if (w->fd >= 0) close(w->fd); /* and its lock with it */
    w->base = NULL;
    w->fd = -1;
}

/* A new object under the name, exclusively: O_EXCL, after retiring what was there. */
static sh_status make_segment(sh_display_writer *w)
{
    const char *name = w->name;
    sh_status st = SH_OK;
    for (int attempt = 0; w->fd < 0; attempt++) {
        /* 0: nothing but this process may touch it before its mode is set */
        w->fd = shm_open(name, O_RDWR | O_CREAT | O_EXCL | O_NOFOLLOW, 0);
        if (w->fd >= 0) break;
        if (errno != EEXIST || attempt == 3)
            return sh_error_set(SH_EIO, "display: shm_open %s: %s", name, strerror(errno));
        if ((st = retire_existing(name)) != SH_OK) return st;
    }
    struct stat sb;
    if (flock(w->fd, LOCK_EX | LOCK_NB) != 0) {
        st = sh_error_set(SH_EIO, "display: lock %s: %s", name, strerror(errno));
    } else if (fchmod(w->fd, SEGMENT_MODE) != 0) { /* 0640 regardless of the umask */
        st = sh_error_set(SH_EIO, "display: chmod %s: %s", name, strerror(errno));
    } else if (w->has_group && fchown(w->fd, (uid_t)-1, w->gid) != 0) {
        st = sh_error_set(SH_EIO, "display: %s: cannot give the segment to group '%s': %s (the service must "
                          "be a member of it)", name, w->group, strerror(errno));
    } else if (ftruncate(w->fd, (off_t)w->size) != 0) {
        st = sh_error_set(SH_EIO, "display: resize %s to %zu bytes: %s", name, w->size, strerror(errno));
    } else if (fstat(w->fd, &sb) != 0) {
        st = sh_error_set(SH_EIO, "display: stat %s: %s", name, strerror(errno));
    } else if ((w->base = mmap(NULL, w->size, PROT_READ | PROT_WRITE, MAP_SHARED, w->fd, 0)) == MAP_FAILED) {
        w->base = NULL;
        st = sh_error_set(SH_EIO, "display: mmap %s: %s", name, strerror(errno));
    }
    if (st != SH_OK) {
        unmap(w);
        shm_unlink(name); /* ours (O_EXCL), and never valid */
        return st;
    }
    w->dev = sb.st_dev;
    w->ino = sb.st_ino;
    memset(w->lock, 0, sizeof w->lock); /* a new object is zero filled */
    w->next_slot = 0;
    w->geometry.generation = new_generation();
    w->geometry.writer_pid = getpid();
    /* Nobody else can have written into a new object yet (mode 0 until the fchmod above, and
     * the fd is the only way in): no guard needed. magic still 0: a reader opening now refuses
     * it; release: a reader that loads the magic with acquire sees every field before it. */
    sh_display_header h = w->geometry;
    h.magic = 0;
    memcpy(w->base, &h, sizeof h);
    __atomic_store_n(&((sh_display_header *)w->base)->magic, SH_DISPLAY_MAGIC, __ATOMIC_RELEASE);
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
    if (display_layout(&h, format, width, height) != SH_OK)
        return sh_error_set(SH_EINVAL, "display: cannot hold %dx%d %s frames", width, height,
                            sh_pixfmt_name(format));
    sh_status st = display_guard_install();
    if (st != SH_OK) return st;
    sh_display_writer *w = calloc(1, sizeof *w);
    if (!w) return sh_error_set(SH_ENOMEM, "display: out of memory");
    snprintf(w->name, sizeof w->name, "%s", name);
    w->fd = -1;
    if (group && *group) {
        /* looked up once: a segment made again later (below) does not depend on NSS */
        struct group *g = getgrnam(group);
        if (!g) {
            free(w);
            return sh_error_set(SH_EINVAL, "display: %s: no group '%s' to give the segment to (create it, e.g. "
                                "groupadd --system %s, or set [sink] group to an existing group, or empty "
                                "for the service's own)", name, group, group);
        }
        w->has_group = 1;
        w->gid = g->gr_gid;
        snprintf(w->group, sizeof w->group, "%s", group);
    }
    w->size = sizeof h + (size_t)h.slot_bytes * (size_t)slots;
    h.magic = SH_DISPLAY_MAGIC;
    h.version = SH_DISPLAY_VERSION;
    h.header_size = sizeof h;
    h.width = (uint32_t)width;
    h.height = (uint32_t)height;
    h.format = (uint32_t)format;
    h.siting = 0;
    h.slot_count = (uint32_t)slots;
    h.full_range = full_range ? 1 : 0;
    w->geometry = h;
    if ((st = make_segment(w)) != SH_OK) {
        free(w);
        return st;
    }
    *out = w;
    return SH_OK;
}

/* Whether the object is still the one this writer made, whole: one fstat, every publish. */
static int intact(const sh_display_writer *w)
{
    struct stat sb;
    return fstat(w->fd, &sb) == 0 && sb.st_dev == w->dev && sb.st_ino == w->ino && sb.st_nlink == 1 &&
           sb.st_size == (off_t)w->size && sb.st_uid == geteuid() && (sb.st_mode & 07777) == SEGMENT_MODE &&
           (!w->has_group || sb.st_gid == w->gid);
}

/* Gives up the current object (marked retired for its readers, if it can still be written) and
 * makes a new one under the name. */
static sh_status remake(sh_display_writer *w)
{
    if (w->base) {
        mark(w->base, w->size, 0);
        /* the name still ours (shrunk or re-moded in place): it goes with the object */
        if (name_is(w->name, w->dev, w->ino)) shm_unlink(w->name);
    }
    unmap(w);
    sh_status st = make_segment(w);
    if (st == SH_OK) w->remade++;
    return st;
}

/* One row into a slot. The writer never reads the segment back and a frame is 12 MB at 4K, so on
 * x86 the row goes with streaming stores (MOVNTDQ): ordinary stores would first read every
 * destination line into the cache (read for ownership) and then push the frame's copy out of
 * it again, both on the processing thread's time; measured 1.77 -> 1.14 ms a 4K I420 frame
 * after 64 MB of other writes (docs/daemon.md, "At 4K"). Streaming stores are weakly ordered
 * against every other store: copy_in fences them on both sides (stream_fence). dst is
 * 16-byte aligned (the slot's pixels are 64-aligned, strides a multiple of 16); the row's tail
 * under 16 bytes is copied plainly. */
static void copy_row(uint8_t *dst, const uint8_t *src, size_t n)
{
#if defined(__SSE2__)
    size_t i = 0;
    for (; i + 64 <= n; i += 64) {
        __m128i a = _mm_loadu_si128((const __m128i *)(src + i));
        __m128i b = _mm_loadu_si128((const __m128i *)(src + i + 16));
        __m128i c = _mm_loadu_si128((const __m128i *)(src + i + 32));
        __m128i d = _mm_loadu_si128((const __m128i *)(src + i + 48));
        _mm_stream_si128((__m128i *)(dst + i), a);
        _mm_stream_si128((__m128i *)(dst + i + 16), b);
        _mm_stream_si128((__m128i *)(dst + i + 32), c);
        _mm_stream_si128((__m128i *)(dst + i + 48), d);
    }
    for (; i + 16 <= n; i += 16) _mm_stream_si128((__m128i *)(dst + i), _mm_loadu_si128((const __m128i *)(src + i)));
    memcpy(dst + i, src + i, n - i);
#else
    memcpy(dst, src, n);
#endif
}

/* Orders copy_row's streaming stores against the lock's ordinary stores: x86 lets a streaming
 * store become visible before an earlier store or after a later one (Intel SDM 8.2.2), which a
 * C11 fence does not prevent (on x86 it only stops the compiler). */
static void stream_fence(void)
{
#if defined(__SSE2__)
    _mm_sfence();
#endif
}

/* The publish proper, under the guard: 0 done, 1 the mapping faulted (cut short under us). */
static int copy_in(sh_display_writer *w, const sh_image *frame, const sh_display_frame_info *info, uint32_t slot)
{
    const sh_display_header *h = &w->geometry;
    uint8_t *base = w->base + sizeof *h + (size_t)slot * h->slot_bytes;
    display_slot_header *sh = (display_slot_header *)base;
    uint64_t lock = w->lock[slot]; /* even; this writer is the slot's only writer (O_EXCL) */
    display_guard g;
    if (sigsetjmp(g.jump, 1)) return 1;
    display_guard_enter(&g, w->base, w->size);
    /* The writer's half of the sequence lock (Boehm, "Can seqlocks get along with programming
     * language memory models?", 2012). The odd count is stored first, then a release fence:
     * every store after the fence (the pixels) becomes visible no earlier than the odd count,
     * so a reader that copied any new byte finds the count changed when it looks again. On
     * aarch64 the fence is a DMB ISH, which orders the odd store before the later stores; on
     * x86 stores are not reordered with each other and the fence only stops the compiler. */
    __atomic_store_n(&sh->lock, lock + 1, __ATOMIC_RELAXED);
    __atomic_thread_fence(__ATOMIC_RELEASE);
    stream_fence(); /* the odd count before any streamed pixel */
    memcpy(&sh->info, info, sizeof *info);
    uint8_t *pixels = base + SLOT_HEADER_BYTES;
    for (uint32_t p = 0; p < h->num_planes; p++) {
        size_t row = (size_t)frame->plane[p].width * (size_t)sh_pixfmt_channels(frame->format);
        for (int y = 0; y < frame->plane[p].height; y++)
            copy_row(pixels + h->plane_offset[p] + (size_t)y * h->stride[p],
                     frame->plane[p].data + (size_t)y * frame->plane[p].stride, row);
    }
    stream_fence(); /* every streamed pixel before the even count below */
    /* publish_ns: the moment the frame is whole in the slot, still inside the odd count (a
     * reader sees it with the frame or not at all). The copy above is the writer's cost, part
     * of capture-to-publish; a reader's publish-to-flip starts when it could have the frame. */
    const int64_t published = sh_monotonic_ns();
    memcpy((uint8_t *)&sh->info + offsetof(sh_display_frame_info, publish_ns), &published, sizeof published);
    /* Release (STLR on aarch64): all of the frame is visible before the even count, and the
     * count before `latest` names the slot. */
    __atomic_store_n(&sh->lock, lock + 2, __ATOMIC_RELEASE);
    /* The header again from the private copy, magic included: whatever another process with
     * write access scribbled there is undone for readers that open the segment from now on
     * (the writer's own values are rewritten, so a reader validating meanwhile sees them). */
    sh_display_header *shared = (sh_display_header *)w->base;
    memcpy((uint8_t *)shared + 8, (const uint8_t *)h + 8, offsetof(sh_display_header, latest) - 8);
    memcpy(&shared->writer_pid, &h->writer_pid, sizeof *h - offsetof(sh_display_header, writer_pid));
    __atomic_store_n(&shared->magic, SH_DISPLAY_MAGIC, __ATOMIC_RELAXED);
    __atomic_store_n(&shared->latest, (info->sequence << 8) | slot, __ATOMIC_RELEASE);
    display_guard_leave();
    w->lock[slot] = lock + 2;
    /* readers asleep on `latest` take the frame now rather than at their next poll (one system
     * call, about a microsecond, against the frame's copy above) */
    display_wake_latest(shared);
    return 0;
}

sh_status sh_display_writer_publish(sh_display_writer *w, const sh_image *frame,
                                    const sh_display_frame_info *info)
{
    const sh_display_header *h = &w->geometry;
    if (!frame || frame->format != (sh_pixfmt)h->format || frame->width != (int)h->width ||
        frame->height != (int)h->height)
        return sh_error_set(SH_EINVAL, "display: frame does not match the segment's %ux%u %s",
                            h->width, h->height, sh_pixfmt_name((sh_pixfmt)h->format));
    sh_display_frame_info copy = info ? *info : (sh_display_frame_info){0};
    copy.sequence = ++w->sequence;
    copy.reason[sizeof copy.reason - 1] = 0;
    /* twice at most: a segment cut short during the copy is made again and the frame goes there */
    int cut_short = 0;
    for (int attempt = 0; attempt < 2; attempt++) {
        if (!w->base || cut_short || !intact(w)) {
            sh_status st = remake(w);
            if (st != SH_OK) return st;
        }
        uint32_t slot = w->next_slot;
        w->next_slot = (slot + 1) % h->slot_count;
        if (copy_in(w, frame, &copy, slot) == 0) return SH_OK;
        cut_short = 1;
    }
    return sh_error_set(SH_EIO, "display: %s was cut short under the writer twice in one frame", w->name);
}

uint64_t sh_display_writer_remade(const sh_display_writer *w) { return w->remade; }
uint64_t sh_display_writer_generation(const sh_display_writer *w) { return w->geometry.generation; }

void sh_display_writer_destroy(sh_display_writer *w, int unlink_segment)
{
    if (!w) return;
    if (w->base) mark(w->base, w->size, 1);
    /* the name only while it still stands for this object: another writer may have made its
     * own under it, which this one must not unlink */
    if (unlink_segment && w->fd >= 0 && name_is(w->name, w->dev, w->ino)) shm_unlink(w->name);
    unmap(w);
    free(w);
}
