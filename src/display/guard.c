/* The SIGBUS guard of the display segment's mappings (display_internal.h, display.h says so to
 * the applications).
 *
 * Why a handler at all: a shared-memory object can be truncated by anyone allowed to write it
 * (the service's own uid, root) while it is mapped; a load or store to a page past the new end
 * raises SIGBUS, whose default action kills the process. Neither end can prevent it for a POSIX
 * shm object (only a memfd can be sealed against shrinking, and a memfd has no name to open), and
 * checking the size first leaves a window between the check and the copy. So the copies into and
 * out of the mapping run under a guard: a thread-local pointer names the range being copied, and
 * the handler jumps back to the guard's sigsetjmp only for a fault in that range on that thread.
 * Every other SIGBUS goes to the handler that was there before (or the default action: the
 * handler puts it back and returns, the faulting instruction runs again and the process dies as
 * it would have). sigsetjmp saves the signal mask (one sigprocmask per guarded copy, a few
 * hundred ns against a frame's copy) so that SIGBUS, blocked while the handler runs, is
 * unblocked again after the jump. */
#include <pthread.h>
#include <signal.h>
#include <string.h>

#include "display_internal.h"

static _Thread_local display_guard *volatile current;
static struct sigaction previous;
static pthread_mutex_t install_lock = PTHREAD_MUTEX_INITIALIZER;

static void on_sigbus(int sig, siginfo_t *si, void *ctx)
{
    display_guard *g = current;
    const volatile uint8_t *a = si ? (const volatile uint8_t *)si->si_addr : NULL;
    if (g && a >= g->lo && a < g->lo + g->len) {
        current = NULL;
        siglongjmp(g->jump, 1);
    }
    if (previous.sa_flags & SA_SIGINFO) {
        if (previous.sa_sigaction) previous.sa_sigaction(sig, si, ctx);
        return;
    }
    if (previous.sa_handler == SIG_DFL || previous.sa_handler == SIG_IGN) {
        /* the default action on the fault's second coming (an ignored fault would loop) */
        signal(sig, SIG_DFL);
        return;
    }
    previous.sa_handler(sig);
}

/* Checked at every create, open and attach, not once per process: code that replaced the handler
 * without chaining to it (a test framework that puts back SIG_DFL after each test does) would
 * leave every later guard without its handler, and the first fault in a segment would kill the
 * process. Put back, it chains to whatever replaced it. */
sh_status display_guard_install(void)
{
    pthread_mutex_lock(&install_lock);
    struct sigaction now, was;
    int ok = sigaction(SIGBUS, NULL, &now) == 0;
    if (ok && !((now.sa_flags & SA_SIGINFO) && now.sa_sigaction == on_sigbus)) {
        struct sigaction sa;
        memset(&sa, 0, sizeof sa);
        sa.sa_sigaction = on_sigbus;
        sa.sa_flags = SA_SIGINFO | SA_ONSTACK;
        sigemptyset(&sa.sa_mask);
        /* `previous` is set before the handler can run with it */
        previous = now;
        ok = sigaction(SIGBUS, &sa, &was) == 0;
    }
    pthread_mutex_unlock(&install_lock);
    return ok ? SH_OK : sh_error_set(SH_EIO, "display: cannot install the SIGBUS guard");
}

void display_guard_enter(display_guard *g, const volatile void *lo, size_t len)
{
    g->lo = lo;
    g->len = len;
    /* the pointer is stored after the range it names: the handler of this thread sees both */
    __atomic_signal_fence(__ATOMIC_SEQ_CST);
    current = g;
    __atomic_signal_fence(__ATOMIC_SEQ_CST);
}

void display_guard_leave(void)
{
    __atomic_signal_fence(__ATOMIC_SEQ_CST);
    current = NULL;
}
