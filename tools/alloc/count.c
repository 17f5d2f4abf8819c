/* LD_PRELOAD counter of heap allocations (malloc, calloc, realloc, posix_memalign, aligned_alloc)
 * by the shared object that asked for them: the first caller outside libc and this file, found
 * with backtrace() and dladdr(). At exit it writes "count object" lines to $ALLOC_COUNT_OUT.
 * tools/alloc/per-frame.sh runs the daemon for N and 2N frames under it: what grows with the
 * frames is what the hot loop allocates (DESIGN.md: nothing). A measuring tool, not linked into
 * anything; glibc only (__libc_malloc and friends). */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <execinfo.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

extern void *__libc_malloc(size_t);
extern void *__libc_calloc(size_t, size_t);
extern void *__libc_realloc(void *, size_t);
extern void *__libc_memalign(size_t, size_t);

#define OBJECTS 64
static char names[OBJECTS][64];
static long counts[OBJECTS];
static int nobj;
static pthread_mutex_t lock = PTHREAD_MUTEX_INITIALIZER;
static __thread int inside; /* backtrace() and dladdr() may allocate themselves */

static const char *base(const char *path)
{
    const char *s = strrchr(path, '/');
    return s ? s + 1 : path;
}

static void note(void)
{
    if (inside) return;
    inside = 1;
    void *bt[12];
    int n = backtrace(bt, 12);
    const char *who = "?";
    Dl_info self, d;
    dladdr((void *)note, &self);
    for (int i = 1; i < n; i++) {
        if (!dladdr(bt[i], &d) || !d.dli_fname) continue;
        if (d.dli_fbase == self.dli_fbase || strstr(base(d.dli_fname), "libc.so")) continue;
        who = base(d.dli_fname);
        break;
    }
    pthread_mutex_lock(&lock);
    int k = 0;
    while (k < nobj && strcmp(names[k], who)) k++;
    if (k == nobj && nobj < OBJECTS) snprintf(names[nobj++], sizeof names[0], "%s", who);
    if (k < nobj) counts[k]++;
    pthread_mutex_unlock(&lock);
    inside = 0;
}

void *malloc(size_t n) { note(); return __libc_malloc(n); }
void *calloc(size_t a, size_t b) { note(); return __libc_calloc(a, b); }
void *realloc(void *p, size_t n) { note(); return __libc_realloc(p, n); }
void *aligned_alloc(size_t a, size_t n) { note(); return __libc_memalign(a, n); }
int posix_memalign(void **p, size_t a, size_t n)
{
    note();
    *p = __libc_memalign(a, n);
    return *p ? 0 : 12; /* ENOMEM */
}

__attribute__((destructor)) static void report(void)
{
    const char *path = getenv("ALLOC_COUNT_OUT");
    FILE *f = path ? fopen(path, "w") : NULL;
    if (!f) return;
    for (int k = 0; k < nobj; k++) fprintf(f, "%ld %s\n", counts[k], names[k]);
    fclose(f);
}
