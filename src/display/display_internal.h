/* What the display's writer and reader share beyond display.h: the slot header, the pixel
 * layout, names of owners for messages, and the guard that turns a fault on a mapping that was
 * cut short under us into an error instead of a crash. */
#ifndef STILLHEART_DISPLAY_INTERNAL_H
#define STILLHEART_DISPLAY_INTERNAL_H

#include <setjmp.h>
#include <stddef.h>
#include <stdint.h>
#include <sys/types.h>

#include "stillheart/core.h"
#include "stillheart/display.h"

#define SLOT_HEADER_BYTES 128

typedef struct {
    uint64_t lock;  /* sequence lock: odd while the writer fills the slot */
    uint64_t pad;
    sh_display_frame_info info;
    uint8_t reserved[SLOT_HEADER_BYTES - 16 - sizeof(sh_display_frame_info)];
} display_slot_header;

void display_sleep_us(long us);
/* The word of the header a reader waits on for the next publish (a futex), and the two halves:
 * a reader that saw `seen` there sleeps until the word changes, the writer wakes it, or `us`
 * microseconds pass (the bound keeps a reader of a writer that never wakes, or of a kernel
 * without the call, on its timed poll); the writer wakes every waiter after each publish. */
const volatile uint32_t *display_latest_word(const volatile sh_display_header *h);
void display_wait_latest(const volatile sh_display_header *h, uint32_t seen, long us);
void display_wake_latest(volatile sh_display_header *h);
/* The pixel layout of one slot for a format: planes packed, rows padded to 16 bytes. */
sh_status display_layout(sh_display_header *h, sh_pixfmt format, int width, int height);
/* "user NAME (uid N)" or "uid N" when the user has no name. */
void display_describe_uid(uid_t uid, char *out, size_t cap);

/* A fault guard: between display_guard_enter and display_guard_leave, a SIGBUS whose address
 * lies in [lo, lo + len) (a shared mapping whose object was truncated under it) returns to the
 * sigsetjmp of the guard with 1. Use:
 *     display_guard g;
 *     if (sigsetjmp(g.jump, 1)) { ...the mapping is cut short: give it up... }
 *     display_guard_enter(&g, base, size);
 *     ...loads and stores into the mapping...
 *     display_guard_leave();
 * Nothing assigned between enter and the fault may be read after the jump unless volatile.
 * display_guard_install (once per process, idempotent) puts in the SIGBUS handler. */
typedef struct {
    sigjmp_buf jump;
    const volatile uint8_t *lo;
    size_t len;
} display_guard;

sh_status display_guard_install(void);
void display_guard_enter(display_guard *g, const volatile void *lo, size_t len);
void display_guard_leave(void);

#endif
