/* The programs' log lines (stillheart/log.h), read back from a file that stands in for stderr:
 * the level filter, both styles, the thread name, once / rate-limited messages and their counts,
 * and journald's priority prefix. */
#include <pthread.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include <cmocka.h>

#include "stillheart/log.h"
#include "stillheart/source.h"

static char path[] = "/tmp/sh-test-log.XXXXXX";
static int saved_err = -1;

/* stderr onto a fresh temporary file; the log set up afresh (it checks stderr's identity). */
static void capture(sh_log_style style, sh_log_level level)
{
    int fd = mkstemp(path);
    assert_true(fd >= 0);
    fflush(stderr);
    if (saved_err < 0) saved_err = dup(STDERR_FILENO);
    assert_true(dup2(fd, STDERR_FILENO) >= 0);
    close(fd);
    sh_log_setup(style, "prog", level);
}

/* Everything written since capture(); stderr back to the terminal. */
static char *captured(void)
{
    fflush(stderr);
    dup2(saved_err, STDERR_FILENO);
    FILE *f = fopen(path, "rb");
    assert_non_null(f);
    static char buf[8192];
    size_t n = fread(buf, 1, sizeof buf - 1, f);
    buf[n] = 0;
    fclose(f);
    unlink(path);
    strcpy(path, "/tmp/sh-test-log.XXXXXX");
    return buf;
}

static void tool_style_and_level_filter(void **state)
{
    (void)state;
    capture(SH_LOG_TOOL, SH_LOG_WARN);
    sh_log_error("%s: %d", "bad.ini", 2);
    sh_log_warn("warning: %s", "odd");
    sh_log_info("not shown");
    sh_log_debug("not shown");
    assert_int_equal(sh_log_get_level(), SH_LOG_WARN);
    sh_log_set_level(SH_LOG_DEBUG);
    sh_log_debug("shown");
    sh_log_set_level(SH_LOG_ERROR);
    sh_log_warn("not shown");
    sh_log_msg(SH_LOG_ERROR, "last");
    assert_string_equal(captured(), "prog: bad.ini: 2\nprog: warning: odd\nprog: shown\nprog: last\n");
}

/* "-- LEVEL [YYYY-MM-DD HH:MM:SS.mmm thread ] -- message": local wall-clock time at the call. */
static double wall_now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_REALTIME, &ts);
    return (double)ts.tv_sec + ts.tv_nsec / 1e9;
}

static void check_daemon_line(const char *line, const char *level, const char *thread, const char *msg,
                              double t0, double t1)
{
    char want_head[32];
    snprintf(want_head, sizeof want_head, "-- %-5s [", level);
    assert_memory_equal(line, want_head, strlen(want_head));
    struct tm tm;
    memset(&tm, 0, sizeof tm);
    int ms = -1, used = 0;
    assert_int_equal(sscanf(line + strlen(want_head), "%4d-%2d-%2d %2d:%2d:%2d.%3d%n", &tm.tm_year, &tm.tm_mon,
                            &tm.tm_mday, &tm.tm_hour, &tm.tm_min, &tm.tm_sec, &ms, &used), 7);
    assert_int_equal(used, 23);
    tm.tm_year -= 1900;
    tm.tm_mon -= 1;
    tm.tm_isdst = -1;
    double t = (double)mktime(&tm) + ms / 1000.0; /* the line's time, read back as local time */
    assert_true(t >= t0 - 0.002 && t <= t1 + 0.002);
    const char *end = line + strlen(want_head) + used;
    char want_tail[256];
    snprintf(want_tail, sizeof want_tail, " %-7s] -- %s", thread, msg);
    assert_memory_equal(end, want_tail, strlen(want_tail));
    assert_int_equal(end[strlen(want_tail)], '\n');
}

static void *named_thread(void *arg)
{
    (void)arg;
    sh_log_set_thread("cam1");
    sh_log_warn("cam1 lost");
    return NULL;
}

static void daemon_style_and_thread_names(void **state)
{
    (void)state;
    capture(SH_LOG_DAEMON, SH_LOG_INFO);
    double t0 = wall_now();
    sh_log_set_thread("main");
    sh_log_info("reference: frame %d, %d markers", 0, 16);
    pthread_t th;
    assert_int_equal(pthread_create(&th, NULL, named_thread, NULL), 0);
    pthread_join(th, NULL);
    sh_log_error("publish: %s", "gone");
    sh_log_set_thread("a-name-longer-than-fifteen");
    sh_log_info("cut");
    double t1 = wall_now();
    char *out = captured();
    char *l2 = strchr(out, '\n') + 1, *l3 = strchr(l2, '\n') + 1, *l4 = strchr(l3, '\n') + 1;
    check_daemon_line(out, "INFO", "main", "reference: frame 0, 16 markers", t0, t1);
    check_daemon_line(l2, "WARN", "cam1", "cam1 lost", t0, t1);   /* the other thread's own name */
    check_daemon_line(l3, "ERROR", "main", "publish: gone", t0, t1); /* this one's unchanged */
    check_daemon_line(l4, "INFO", "a-name-longer-t", "cut", t0, t1);
    assert_string_equal(strchr(l4, '\n'), "\n");
}

static void *unnamed_thread(void *arg)
{
    (void)arg;
    sh_log_info("who");
    return NULL;
}

static void unnamed_thread_shows_dash(void **state)
{
    (void)state;
    capture(SH_LOG_DAEMON, SH_LOG_INFO);
    double t0 = wall_now();
    pthread_t th;
    assert_int_equal(pthread_create(&th, NULL, unnamed_thread, NULL), 0);
    pthread_join(th, NULL);
    check_daemon_line(captured(), "INFO", "-", "who", t0, wall_now());
}

static void once_until_cleared(void **state)
{
    (void)state;
    capture(SH_LOG_TOOL, SH_LOG_INFO);
    sh_log_limit lim = {0};
    for (int i = 0; i < 5; i++) sh_log_limited(&lim, SH_LOG_ERROR, "tracker: %d", i);
    assert_int_equal(lim.suppressed, 4);
    assert_int_equal(sh_log_limit_clear(&lim), 4);
    sh_log_limited(&lim, SH_LOG_ERROR, "tracker: again");
    sh_log_limited(&lim, SH_LOG_ERROR, "tracker: not shown");
    /* filtered by level: neither logged nor counted, and the limit stays as it was */
    sh_log_limit quiet = {0};
    sh_log_limited(&quiet, SH_LOG_DEBUG, "debug");
    assert_int_equal(quiet.armed, 0);
    assert_int_equal(quiet.suppressed, 0);
    assert_string_equal(captured(), "prog: tracker: 0\nprog: tracker: again\n");
    assert_int_equal(sh_log_limit_clear(&lim), 1);
}

static void at_most_once_a_period(void **state)
{
    (void)state;
    capture(SH_LOG_TOOL, SH_LOG_INFO);
    /* The period is measured from the line. A sleep outlasts it for sure; calls back to back stay
     * within it unless the machine stalls this thread for a whole second. */
    sh_log_limit lim = {.period_s = 1.0};
    for (int i = 0; i < 3; i++) sh_log_limited(&lim, SH_LOG_WARN, "late %d", i);
    struct timespec ts = {1, 50 * 1000 * 1000};
    nanosleep(&ts, NULL);
    sh_log_limited(&lim, SH_LOG_WARN, "late %d", 3);
    sh_log_limited(&lim, SH_LOG_WARN, "late %d", 4);
    nanosleep(&ts, NULL);
    sh_log_limited(&lim, SH_LOG_WARN, "late %d", 5);
    sh_log_limited(&lim, SH_LOG_WARN, "late %d", 6);
    assert_int_equal(sh_log_limit_clear(&lim), 1);
    sh_log_limited(&lim, SH_LOG_WARN, "late %d", 7); /* cleared: due at once, nothing to count */
    assert_string_equal(captured(), "prog: late 0\n"
                                    "prog: late 3 (2 more since the last)\n"
                                    "prog: late 5 (1 more since the last)\n"
                                    "prog: late 7\n");
}

/* $JOURNAL_STREAM naming the captured stderr with its inode + ino_offset (0: it is the journal),
 * and the log set up again to read it. */
static void journal_stream(sh_log_style style, sh_log_level level, unsigned ino_offset)
{
    struct stat st;
    assert_int_equal(fstat(STDERR_FILENO, &st), 0);
    char js[64];
    snprintf(js, sizeof js, "%llu:%llu", (unsigned long long)st.st_dev, (unsigned long long)st.st_ino + ino_offset);
    setenv("JOURNAL_STREAM", js, 1);
    sh_log_setup(style, "prog", level);
}

static void journal_priorities(void **state)
{
    (void)state;
    capture(SH_LOG_TOOL, SH_LOG_DEBUG);
    journal_stream(SH_LOG_TOOL, SH_LOG_DEBUG, 0);
    sh_log_error("e");
    sh_log_warn("w");
    sh_log_info("i");
    sh_log_debug("d");
    /* another stream's identity (stderr redirected by a wrapper): no prefix */
    journal_stream(SH_LOG_TOOL, SH_LOG_DEBUG, 1);
    sh_log_info("plain");
    setenv("JOURNAL_STREAM", "garbage", 1);
    sh_log_setup(SH_LOG_TOOL, "prog", SH_LOG_DEBUG);
    sh_log_info("plain too");
    unsetenv("JOURNAL_STREAM");
    assert_string_equal(captured(), "<3>prog: e\n<4>prog: w\n<6>prog: i\n<7>prog: d\nprog: plain\nprog: plain too\n");
}

/* The daemon's lines in the journal: the priority, no time (journald stamps each entry). */
static void journal_daemon_lines_carry_no_time(void **state)
{
    (void)state;
    capture(SH_LOG_DAEMON, SH_LOG_INFO);
    journal_stream(SH_LOG_DAEMON, SH_LOG_INFO, 0);
    sh_log_set_thread("main");
    sh_log_warn("camera 0 lost");
    unsetenv("JOURNAL_STREAM");
    assert_string_equal(captured(), "<4>-- WARN  [main   ] -- camera 0 lost\n");
}

static void long_message_cut(void **state)
{
    (void)state;
    capture(SH_LOG_TOOL, SH_LOG_INFO);
    char big[2000];
    memset(big, 'x', sizeof big - 1);
    big[sizeof big - 1] = 0;
    sh_log_error("%s", big);
    char *out = captured();
    assert_int_equal(strlen(out), strlen("prog: ") + 767 + 1);
    assert_int_equal(out[strlen(out) - 1], '\n');
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(tool_style_and_level_filter),
        cmocka_unit_test(daemon_style_and_thread_names),
        cmocka_unit_test(unnamed_thread_shows_dash),
        cmocka_unit_test(once_until_cleared),
        cmocka_unit_test(at_most_once_a_period),
        cmocka_unit_test(journal_priorities),
        cmocka_unit_test(journal_daemon_lines_carry_no_time),
        cmocka_unit_test(long_message_cut),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
