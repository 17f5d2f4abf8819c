/* The display segment's reader (display.h has the contract; docs/daemon.md the security model).
 *
 * A reader opened by name checks who owns the object before it maps it, keeps a validated copy
 * of the header and never trusts the segment's own fields again, copies a slot aside and keeps
 * the copy only when the slot's sequence lock held across it, and follows the daemon: a segment
 * retired by a new writer (magic 0), cut short (a fault under the guard), unlinked or replaced
 * under its name, or (with follow) closed, is left and the name opened again, and frames are
 * taken from the new object only, from its start. */
#include <errno.h>
#include <fcntl.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include "display_internal.h"

#define NAME_CHECK_NS 100000000 /* how often a reader with no new frame looks at the name */

struct sh_display_reader {
    char name[256];             /* "" when attached to a buffer */
    uid_t owner;
    int follow;
    int fd;
    const uint8_t *base;        /* NULL between two objects */
    size_t size;
    int mapped;
    int have_object;            /* the object last mapped (kept after it is left) */
    dev_t dev;
    ino_t ino;
    sh_display_header geometry; /* validated copy: the segment's own fields are not trusted again */
    uint64_t last_sequence;
    uint32_t seen;              /* the futex word (display_latest_word) at the last look */
    uint8_t *stage;             /* one slot's pixels: a copy is made here and kept only if whole */
    size_t stage_cap;
    int64_t next_name_check;
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
        display_layout(&expect, (sh_pixfmt)h->format, (int)h->width, (int)h->height) != SH_OK)
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

/* The header copied aside (under the guard: the object may be cut short meanwhile) and checked;
 * r->geometry changes only to a valid header (a caller may look at it between two objects). */
static sh_status reader_init(sh_display_reader *r)
{
    sh_display_header h;
    display_guard g;
    if (sigsetjmp(g.jump, 1)) return sh_error_set(SH_EFORMAT, "display: the segment was cut short while opening it");
    display_guard_enter(&g, r->base, r->size);
    /* Acquire, paired with the writer's release store of the magic: the fields copied next are
     * the ones written before it (a segment still being built shows magic 0 and is refused). */
    uint64_t magic = __atomic_load_n(&((const sh_display_header *)r->base)->magic, __ATOMIC_ACQUIRE);
    memcpy(&h, r->base, sizeof h);
    display_guard_leave();
    h.magic = magic;
    sh_status st = validate(&h, r->size);
    if (st != SH_OK) return st;
    if (h.frame_bytes > r->stage_cap) {
        free(r->stage);
        r->stage_cap = 0;
        if (!(r->stage = malloc(h.frame_bytes))) return sh_error_set(SH_ENOMEM, "display: out of memory");
        r->stage_cap = h.frame_bytes;
    }
    r->geometry = h;
    return SH_OK;
}

static void unmap(sh_display_reader *r)
{
    if (r->mapped && r->base) munmap((void *)r->base, r->size);
    if (r->fd >= 0) close(r->fd);
    r->fd = -1;
    r->mapped = 0;
    if (r->name[0]) r->base = NULL;
}

/* The object under the name, if it may be read: SH_OK mapped and valid; SH_EINVAL refused for
 * good (its owner or mode); SH_EIO / SH_EFORMAT not there or not valid yet (try again). */
static sh_status map_name(sh_display_reader *r)
{
    int fd = shm_open(r->name, O_RDONLY | O_NOFOLLOW, 0);
    if (fd < 0) return sh_error_set(SH_EIO, "display: %s: %s (is the daemon running?)", r->name, strerror(errno));
    struct stat sb;
    if (fstat(fd, &sb) != 0) {
        close(fd);
        return sh_error_set(SH_EIO, "display: stat %s: %s", r->name, strerror(errno));
    }
    if (sb.st_uid != r->owner || (sb.st_mode & 022)) {
        char owner[160], want[160];
        display_describe_uid(sb.st_uid, owner, sizeof owner);
        display_describe_uid(r->owner, want, sizeof want);
        close(fd);
        if (sb.st_uid != r->owner)
            return sh_error_set(SH_EINVAL, "display: %s belongs to %s, not to %s: refused (its frames may come from "
                                "anyone; give the daemon's user as the owner to read it)", r->name, owner, want);
        return sh_error_set(SH_EINVAL, "display: %s has mode %04o, writable by others than its owner (%s): refused",
                            r->name, (unsigned)(sb.st_mode & 07777), owner);
    }
    int same = r->have_object && sb.st_dev == r->dev && sb.st_ino == r->ino;
    if (sb.st_size < (off_t)sizeof(sh_display_header)) {
        close(fd);
        return sh_error_set(SH_EFORMAT, "display: %s: not a stillheart display segment", r->name);
    }
    r->size = (size_t)sb.st_size;
    void *base = mmap(NULL, r->size, PROT_READ, MAP_SHARED, fd, 0);
    if (base == MAP_FAILED) {
        close(fd);
        return sh_error_set(SH_EIO, "display: mmap %s: %s", r->name, strerror(errno));
    }
    r->fd = fd;
    r->base = base;
    r->mapped = 1;
    sh_status st = reader_init(r);
    if (st != SH_OK) {
        unmap(r);
        const char *m = sh_error_message();
        return sh_error_set(st, "display: %s: %s", r->name, strncmp(m, "display: ", 9) ? m : m + 9);
    }
    /* a new object: its frames are counted from its start; the same one (left after a fault or
     * a scribbled magic): only frames newer than the last one returned */
    if (!same) r->last_sequence = 0;
    r->have_object = 1;
    r->dev = sb.st_dev;
    r->ino = sb.st_ino;
    r->next_name_check = sh_monotonic_ns() + NAME_CHECK_NS;
    return SH_OK;
}

/* Whether the name still stands for the mapped object (unlinked or replaced without being
 * retired, e.g. removed by hand: left, to follow whatever comes under the name). */
static int name_holds_ours(const sh_display_reader *r)
{
    struct stat sb;
    int fd = shm_open(r->name, O_RDONLY | O_NOFOLLOW, 0);
    if (fd < 0) return 0;
    int same = fstat(fd, &sb) == 0 && sb.st_dev == r->dev && sb.st_ino == r->ino;
    close(fd);
    return same;
}

sh_status sh_display_reader_open(const char *name, const sh_display_reader_options *opt, int timeout_ms,
                                 sh_display_reader **out)
{
    if (!name || name[0] != '/' || strlen(name) >= 255)
        return sh_error_set(SH_EINVAL, "display: shared-memory name must look like /name");
    sh_status st = display_guard_install();
    if (st != SH_OK) return st;
    sh_display_reader *r = calloc(1, sizeof *r);
    if (!r) return sh_error_set(SH_ENOMEM, "display: out of memory");
    snprintf(r->name, sizeof r->name, "%s", name);
    r->fd = -1;
    r->owner = !opt || opt->owner_uid < 0 ? geteuid() : (uid_t)opt->owner_uid;
    r->follow = opt && opt->follow;
    int64_t deadline = timeout_ms < 0 ? INT64_MAX : sh_monotonic_ns() + (int64_t)timeout_ms * 1000000;
    /* the daemon may be starting: its segment appears, then becomes valid, within the timeout */
    while ((st = map_name(r)) != SH_OK && st != SH_EINVAL && sh_monotonic_ns() < deadline)
        display_sleep_us(2000);
    if (st != SH_OK) {
        sh_display_reader_close(r);
        return st;
    }
    *out = r;
    return SH_OK;
}

sh_status sh_display_reader_attach(const void *buffer, size_t size, sh_display_reader **out)
{
    if (!buffer) return sh_error_set(SH_EINVAL, "display: no buffer");
    sh_status st = display_guard_install();
    if (st != SH_OK) return st;
    sh_display_reader *r = calloc(1, sizeof *r);
    if (!r) return sh_error_set(SH_ENOMEM, "display: out of memory");
    r->fd = -1;
    r->base = buffer;
    r->size = size;
    st = size >= sizeof(sh_display_header) ? reader_init(r) : sh_error_set(SH_EFORMAT, "display: too small");
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
 * writer was in the slot before or during the copy (try again). Runs under the caller's guard.
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
 * new writer, or a writer that remakes its segment, makes a new object), so an equal count means
 * the same frame. This is the only place a slot is read: every return of a frame (the newest, the
 * last before a close, the one in hand at a timeout, a reopen) goes through it. */
/* With a viewer (sh_display_reader_view) the copy of the pixels is the viewer's own work on them
 * in place: the same fence follows it (the call is opaque to the compiler, and the fence orders
 * the processor's loads inside it), so what the viewer read is kept only under the same proof. */
typedef struct {
    sh_display_view_fn fn; /* NULL: the pixels copied into r->stage */
    void *ctx;
    sh_status status;      /* fn's, from its last call */
} viewer;

/* The pixels of a slot where they lie, with the validated header's strides (read only: the
 * mapping is PROT_READ). */
static void slot_view(const sh_display_header *g, const uint8_t *pixels, sh_image *v)
{
    sh_image_wrap(v, (sh_pixfmt)g->format, (int)g->width, (int)g->height, (uint8_t *)pixels);
    for (uint32_t p = 0; p < g->num_planes; p++) {
        v->plane[p].data = (uint8_t *)pixels + g->plane_offset[p];
        v->plane[p].stride = (int)g->stride[p];
    }
}

static sh_status copy_slot(sh_display_reader *r, uint32_t slot, sh_display_frame_info *info, viewer *vw)
{
    const sh_display_header *g = &r->geometry;
    const uint8_t *base = r->base + sizeof *g + (size_t)slot * g->slot_bytes;
    const display_slot_header *sh = (const display_slot_header *)base;
    uint64_t before = __atomic_load_n(&sh->lock, __ATOMIC_ACQUIRE);
    if (before & 1) return SH_EINVAL;
    memcpy(info, (const void *)&sh->info, sizeof *info);
    info->reason[sizeof info->reason - 1] = 0;
    if (vw && vw->fn) {
        sh_image view;
        slot_view(g, base + SLOT_HEADER_BYTES, &view);
        vw->status = vw->fn(vw->ctx, &view, info);
    } else {
        memcpy(r->stage, base + SLOT_HEADER_BYTES, g->frame_bytes);
    }
    __atomic_thread_fence(__ATOMIC_ACQUIRE);
    if (__atomic_load_n(&sh->lock, __ATOMIC_RELAXED) != before) return SH_EINVAL;
    return SH_OK;
}

enum { POLL_NOTHING, POLL_FRAME, POLL_CLOSED, POLL_RETIRED, POLL_CUT_SHORT };

/* One look at the segment, under the guard: a newer whole frame in r->stage (or seen by the
 * viewer) and *copy, or what became of the segment. */
static int poll_segment(sh_display_reader *r, sh_display_frame_info *copy, viewer *vw)
{
    const sh_display_header *live = (const sh_display_header *)r->base;
    const sh_display_header *g = &r->geometry;
    display_guard guard;
    if (sigsetjmp(guard.jump, 1)) return POLL_CUT_SHORT;
    display_guard_enter(&guard, r->base, r->size);
    int result = POLL_NOTHING;
    uint64_t latest = __atomic_load_n(&live->latest, __ATOMIC_ACQUIRE);
    uint32_t slot = (uint32_t)(latest & 0xff);
    r->seen = (uint32_t)latest;
    if (latest != 0 && (latest >> 8) > r->last_sequence && slot < g->slot_count &&
        copy_slot(r, slot, copy, vw) == SH_OK && copy->sequence > r->last_sequence)
        result = POLL_FRAME;
    else if (__atomic_load_n(&live->magic, __ATOMIC_ACQUIRE) != SH_DISPLAY_MAGIC)
        result = POLL_RETIRED;
    else if (__atomic_load_n(&live->closed, __ATOMIC_ACQUIRE) && (latest >> 8) <= r->last_sequence)
        result = POLL_CLOSED;
    display_guard_leave();
    return result;
}

/* sh_display_reader_next (a frame to copy into) and _view (a viewer) in one loop. */
static sh_status next_frame(sh_display_reader *r, sh_image *frame, viewer *vw, sh_display_frame_info *info,
                            int timeout_ms)
{
    const sh_display_header *g = &r->geometry;
    int64_t deadline = timeout_ms < 0 ? INT64_MAX : sh_monotonic_ns() + (int64_t)timeout_ms * 1000000;
    for (;;) {
        int left = 0, closed = 0;
        if (!r->base) {
            sh_status st = map_name(r);
            if (st == SH_EINVAL) return st;
        }
        if (r->base) {
            if (frame && (frame->format != (sh_pixfmt)g->format || frame->width != (int)g->width || frame->height != (int)g->height))
                return sh_error_set(SH_ERANGE, "display: %s carries %ux%u %s frames (a daemon restarted with another "
                                    "size?): the frame must be made anew from its header", r->name[0] ? r->name : "the segment",
                                    g->width, g->height, sh_pixfmt_name((sh_pixfmt)g->format));
            sh_display_frame_info copy;
            int what = poll_segment(r, &copy, vw);
            /* the caller's frame and info are written only from a whole copy of a newer frame:
             * on every other return (timeout, closed, replaced) they hold what they held */
            if (what == POLL_FRAME && vw && vw->status != SH_OK) return vw->status;
            if (what == POLL_FRAME) {
                for (uint32_t p = 0; frame && p < g->num_planes; p++) {
                    size_t row = (size_t)frame->plane[p].width * (size_t)sh_pixfmt_channels(frame->format);
                    for (int y = 0; y < frame->plane[p].height; y++)
                        memcpy(frame->plane[p].data + (size_t)y * frame->plane[p].stride,
                               r->stage + g->plane_offset[p] + (size_t)y * g->stride[p], row);
                }
                r->last_sequence = copy.sequence;
                r->next_name_check = sh_monotonic_ns() + NAME_CHECK_NS;
                if (info) *info = copy;
                return SH_OK;
            }
            if (!r->name[0] && what == POLL_RETIRED) return sh_error_set(SH_EEOF, "display: the segment was replaced");
            if (!r->name[0] && what == POLL_CLOSED) return sh_error_set(SH_EEOF, "display: the writer closed the segment");
            if (!r->name[0] && what == POLL_CUT_SHORT) return sh_error_set(SH_EIO, "display: the segment was cut short");
            if (what == POLL_CLOSED && !r->follow)
                return sh_error_set(SH_EEOF, "display: the writer closed the segment");
            /* Closed, following: the segment stays mapped (a new daemon retires it, magic 0, or
             * the name is found to stand for another object; the writer, if it was not really
             * gone, clears the flag with its next publish) and the name is looked at each time. */
            closed = what == POLL_CLOSED;
            int64_t now = sh_monotonic_ns();
            if (r->name[0] && (what == POLL_RETIRED || what == POLL_CUT_SHORT ||
                               ((closed || now >= r->next_name_check) && !name_holds_ours(r)))) {
                unmap(r);
                left = 1; /* the name again at once: a new daemon's segment may be there */
            } else if (now >= r->next_name_check) {
                r->next_name_check = now + NAME_CHECK_NS;
            }
        }
        if (sh_monotonic_ns() >= deadline)
            return sh_error_set(SH_EIO, "display: no new frame in %d ms%s", timeout_ms, r->base ? "" : " (no segment)");
        /* Until the writer's wake, at most 0.5 ms (a frame period is 16 ms or more; the bound
         * is the poll of a writer that does not wake, and the name's and the deadline's check);
         * 2 ms between two opens of the name, 5 ms between two looks at the name of a closed
         * segment. */
        if (left) continue;
        if (r->base && !closed)
            display_wait_latest((const sh_display_header *)r->base, r->seen, 500);
        else
            display_sleep_us(!r->base ? 2000 : 5000);
    }
}

sh_status sh_display_reader_next(sh_display_reader *r, sh_image *frame, sh_display_frame_info *info,
                                 int timeout_ms)
{
    if (!frame) return sh_error_set(SH_EINVAL, "display: no frame to read into");
    return next_frame(r, frame, NULL, info, timeout_ms);
}

sh_status sh_display_reader_view(sh_display_reader *r, sh_display_view_fn fn, void *ctx,
                                 sh_display_frame_info *info, int timeout_ms)
{
    if (!fn) return sh_error_set(SH_EINVAL, "display: no viewer");
    viewer vw = {fn, ctx, SH_OK};
    return next_frame(r, NULL, &vw, info, timeout_ms);
}

void sh_display_reader_close(sh_display_reader *r)
{
    if (!r) return;
    unmap(r);
    free(r->stage);
    free(r);
}
