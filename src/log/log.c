/* Log lines of the programs: include/stillheart/log.h. */
#include <pthread.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include "stillheart/log.h"
#include "stillheart/source.h"

static pthread_mutex_t log_mu = PTHREAD_MUTEX_INITIALIZER;
static sh_log_style log_style = SH_LOG_TOOL;
static sh_log_level log_level = SH_LOG_INFO;
static char log_program[64] = "stillheart";
static int log_journal;
static _Thread_local char log_thread[16];

static const char *const level_name[] = {"ERROR", "WARN", "INFO", "DEBUG"};
/* syslog's LOG_ERR, LOG_WARNING, LOG_INFO, LOG_DEBUG */
static const int level_priority[] = {3, 4, 6, 7};

/* systemd sets JOURNAL_STREAM to "DEV:INODE" of the stream it connected; a program whose stderr
 * is still that stream (not redirected by a wrapper) may prefix priorities. */
static int stderr_is_journal(void)
{
    const char *js = getenv("JOURNAL_STREAM");
    unsigned long long dev, ino;
    char end;
    if (!js || sscanf(js, "%llu:%llu%c", &dev, &ino, &end) != 2) return 0;
    struct stat st;
    if (fstat(STDERR_FILENO, &st)) return 0;
    return (unsigned long long)st.st_dev == dev && (unsigned long long)st.st_ino == ino;
}

void sh_log_setup(sh_log_style style, const char *program, sh_log_level level)
{
    int journal = stderr_is_journal();
    pthread_mutex_lock(&log_mu);
    log_style = style;
    log_level = level;
    snprintf(log_program, sizeof log_program, "%s", program ? program : "");
    log_journal = journal;
    pthread_mutex_unlock(&log_mu);
}

void sh_log_set_level(sh_log_level level)
{
    pthread_mutex_lock(&log_mu);
    log_level = level;
    pthread_mutex_unlock(&log_mu);
}

sh_log_level sh_log_get_level(void)
{
    pthread_mutex_lock(&log_mu);
    sh_log_level l = log_level;
    pthread_mutex_unlock(&log_mu);
    return l;
}

void sh_log_set_thread(const char *name)
{
    snprintf(log_thread, sizeof log_thread, "%s", name ? name : "");
}

/* Called with log_mu held. The message is cut at 767 bytes, as the daemon's lines always were. */
static void emit(sh_log_level level, const char *suffix, const char *fmt, va_list ap)
{
    char msg[768], line[1024];
    vsnprintf(msg, sizeof msg, fmt, ap);
    int n = 0;
    if (log_journal) n = snprintf(line, sizeof line, "<%d>", level_priority[level]);
    if (log_style == SH_LOG_DAEMON) {
        /* the journal stamps every entry itself; elsewhere a reader compares the line with a
         * clock on the wall (an incident report, a recording's file time), never with the
         * seconds since boot */
        char when[40] = "";
        if (!log_journal) {
            struct timespec ts;
            struct tm tm;
            clock_gettime(CLOCK_REALTIME, &ts);
            localtime_r(&ts.tv_sec, &tm);
            size_t k = strftime(when, sizeof when, "%Y-%m-%d %H:%M:%S", &tm);
            snprintf(when + k, sizeof when - k, ".%03ld ", ts.tv_nsec / 1000000);
        }
        snprintf(line + n, sizeof line - (size_t)n, "-- %-5s [%s%-7s] -- %s%s\n", level_name[level], when,
                 log_thread[0] ? log_thread : "-", msg, suffix);
    } else
        snprintf(line + n, sizeof line - (size_t)n, "%s: %s%s\n", log_program, msg, suffix);
    fputs(line, stderr);
}

static void vlog(sh_log_level level, const char *fmt, va_list ap)
{
    if ((unsigned)level > SH_LOG_DEBUG) level = SH_LOG_ERROR;
    pthread_mutex_lock(&log_mu);
    if (level <= log_level) emit(level, "", fmt, ap);
    pthread_mutex_unlock(&log_mu);
}

void sh_log_msg(sh_log_level level, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    vlog(level, fmt, ap);
    va_end(ap);
}

#define LEVEL_FN(fn, level)                                                                        \
    void fn(const char *fmt, ...)                                                                  \
    {                                                                                              \
        va_list ap;                                                                                \
        va_start(ap, fmt);                                                                         \
        vlog(level, fmt, ap);                                                                      \
        va_end(ap);                                                                                \
    }
LEVEL_FN(sh_log_error, SH_LOG_ERROR)
LEVEL_FN(sh_log_warn, SH_LOG_WARN)
LEVEL_FN(sh_log_info, SH_LOG_INFO)
LEVEL_FN(sh_log_debug, SH_LOG_DEBUG)

void sh_log_limited(sh_log_limit *lim, sh_log_level level, const char *fmt, ...)
{
    if ((unsigned)level > SH_LOG_DEBUG) level = SH_LOG_ERROR;
    pthread_mutex_lock(&log_mu);
    if (level <= log_level) {
        int64_t now = sh_monotonic_ns();
        int due = lim->period_s > 0 ? !lim->armed || (double)(now - lim->last_ns) >= lim->period_s * 1e9
                                    : !lim->armed;
        if (due) {
            char suffix[64] = "";
            if (lim->period_s > 0 && lim->suppressed)
                snprintf(suffix, sizeof suffix, " (%llu more since the last)", lim->suppressed);
            va_list ap;
            va_start(ap, fmt);
            emit(level, suffix, fmt, ap);
            va_end(ap);
            lim->armed = 1;
            lim->last_ns = now;
            lim->suppressed = 0;
        } else {
            lim->suppressed++;
        }
    }
    pthread_mutex_unlock(&log_mu);
}

unsigned long long sh_log_limit_clear(sh_log_limit *lim)
{
    pthread_mutex_lock(&log_mu);
    unsigned long long n = lim->suppressed;
    lim->armed = 0;
    lim->suppressed = 0;
    pthread_mutex_unlock(&log_mu);
    return n;
}
