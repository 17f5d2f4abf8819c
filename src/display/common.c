/* Helpers of the display's writer and reader (display_internal.h). */
#include <errno.h>
#include <limits.h>
#include <linux/futex.h>
#include <pwd.h>
#include <stdio.h>
#include <sys/syscall.h>
#include <time.h>
#include <unistd.h>

#include "display_internal.h"

_Static_assert(sizeof(sh_display_header) == 256, "the header's size is part of the format");
_Static_assert(sizeof(sh_display_frame_info) == 80, "frame info is part of the format");
_Static_assert(sizeof(display_slot_header) == SLOT_HEADER_BYTES, "slot header is part of the format");
_Static_assert(SH_DISPLAY_SLOT_HEADER_BYTES == SLOT_HEADER_BYTES, "display.h says the slot header's size");

void display_sleep_us(long us)
{
    struct timespec t = {us / 1000000, (us % 1000000) * 1000};
    nanosleep(&t, NULL);
}

/* The low 32 bits of `latest` change with every publish, which is all a futex needs: no field of
 * its own in the header, and a writer older than the wake (it never wakes anyone) leaves its
 * readers on their old timed poll. Shared futexes (not FUTEX_PRIVATE: two processes) are keyed
 * by the object and offset, so each process's own mapping of the segment meets the others'. */
const volatile uint32_t *display_latest_word(const volatile sh_display_header *h)
{
#if __BYTE_ORDER__ == __ORDER_BIG_ENDIAN__
    return (const volatile uint32_t *)&h->latest + 1;
#else
    return (const volatile uint32_t *)&h->latest;
#endif
}

void display_wait_latest(const volatile sh_display_header *h, uint32_t seen, long us)
{
    struct timespec t = {us / 1000000, (us % 1000000) * 1000};
    /* FUTEX_WAIT only reads the word, so a read-only mapping may wait on it (Linux 4.5 on). The
     * kernel's own load of a word cut short under us is EFAULT, never a SIGBUS. Any failure
     * other than a timeout, a changed word or a signal (no futex, EFAULT) is the plain sleep. */
    int saved = errno;
    if (syscall(SYS_futex, display_latest_word(h), FUTEX_WAIT, seen, &t, NULL, 0) != 0 && errno != ETIMEDOUT &&
        errno != EAGAIN && errno != EINTR)
        nanosleep(&t, NULL);
    errno = saved;
}

void display_wake_latest(volatile sh_display_header *h)
{
    int saved = errno;
    syscall(SYS_futex, display_latest_word(h), FUTEX_WAKE, INT_MAX, NULL, NULL, 0);
    errno = saved;
}

sh_status display_layout(sh_display_header *h, sh_pixfmt format, int width, int height)
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

void display_describe_uid(uid_t uid, char *out, size_t cap)
{
    struct passwd pw, *found = NULL;
    char buf[1024];
    if (getpwuid_r(uid, &pw, buf, sizeof buf, &found) == 0 && found)
        snprintf(out, cap, "user %s (uid %u)", found->pw_name, (unsigned)uid);
    else
        snprintf(out, cap, "uid %u", (unsigned)uid);
}
