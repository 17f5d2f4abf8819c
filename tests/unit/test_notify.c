/* sd_notify against a NOTIFY_SOCKET the test opens (a path and an abstract name), a listener that
 * stops reading, the watchdog interval from the environment, and silence outside systemd. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <cmocka.h>

#include "stillheart/notify.h"

static int open_socket(const char *name, int abstract)
{
    int fd = socket(AF_UNIX, SOCK_DGRAM, 0);
    assert_true(fd >= 0);
    struct sockaddr_un a;
    memset(&a, 0, sizeof a);
    a.sun_family = AF_UNIX;
    size_t n = strlen(name);
    memcpy(a.sun_path + abstract, name, n);
    socklen_t len = (socklen_t)(offsetof(struct sockaddr_un, sun_path) + n + 1);
    assert_int_equal(bind(fd, (struct sockaddr *)&a, len), 0);
    struct timeval tv = {1, 0};
    setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
    return fd;
}

static void expect(int fd, const char *want)
{
    char buf[2048];
    ssize_t r = recv(fd, buf, sizeof buf - 1, 0);
    assert_true(r >= 0);
    buf[r] = 0;
    assert_string_equal(buf, want);
}

/* A listener at /tmp/NAME-PID (its path in path, for unlink), named by NOTIFY_SOCKET. */
static int listen_at(const char *name, char *path, size_t cap)
{
    snprintf(path, cap, "/tmp/%s-%d", name, (int)getpid());
    unlink(path);
    int fd = open_socket(path, 0);
    setenv("NOTIFY_SOCKET", path, 1);
    return fd;
}

static void test_path_socket(void **state)
{
    (void)state;
    char path[64];
    int fd = listen_at("sh-notify", path, sizeof path);
    assert_int_equal(sh_notify("READY=1"), SH_OK);
    expect(fd, "READY=1");
    assert_int_equal(sh_notifyf("STATUS=%.1f fps, %d markers, %s", 59.94, 16, "stabilized"), SH_OK);
    expect(fd, "STATUS=59.9 fps, 16 markers, stabilized");
    assert_int_equal(sh_notify("WATCHDOG=1"), SH_OK);
    expect(fd, "WATCHDOG=1");
    close(fd);
    unlink(path);
    /* the listener is gone: an error, not a crash */
    assert_int_not_equal(sh_notify("WATCHDOG=1"), SH_OK);
    unsetenv("NOTIFY_SOCKET");
}

/* A listener that stops reading: once its queue is full, each message waits its 200 ms and is
 * dropped with an error; none blocks for good (the daemon's loop and its exit call this). */
static void test_listener_not_reading(void **state)
{
    (void)state;
    char path[64];
    int fd = listen_at("sh-notify-full", path, sizeof path);
    int qlen = 10;
    FILE *f = fopen("/proc/sys/net/unix/max_dgram_qlen", "r");
    if (f) {
        if (fscanf(f, "%d", &qlen) != 1) qlen = 10;
        fclose(f);
    }
    if (qlen > 4096) qlen = 4096;
    int failed = 0;
    for (int i = 0; i < qlen + 3; i++) failed += sh_notify("WATCHDOG=1") != SH_OK;
    assert_true(failed >= 1 && failed <= 3); /* the queue held qlen (+1: the kernel counts > qlen) */
    expect(fd, "WATCHDOG=1");                /* one read: room for one more */
    assert_int_equal(sh_notify("STOPPING=1"), SH_OK);
    close(fd);
    unlink(path);
    unsetenv("NOTIFY_SOCKET");
}

static void test_abstract_socket(void **state)
{
    (void)state;
    char name[64], env[70];
    snprintf(name, sizeof name, "sh-notify-abs-%d", (int)getpid());
    int fd = open_socket(name, 1);
    snprintf(env, sizeof env, "@%s", name);
    setenv("NOTIFY_SOCKET", env, 1);
    assert_int_equal(sh_notify("STOPPING=1"), SH_OK);
    expect(fd, "STOPPING=1");
    close(fd);
    unsetenv("NOTIFY_SOCKET");
}

static void test_outside_systemd(void **state)
{
    (void)state;
    unsetenv("NOTIFY_SOCKET");
    assert_int_equal(sh_notify("READY=1"), SH_OK);
    setenv("NOTIFY_SOCKET", "relative", 1);
    assert_int_not_equal(sh_notify("READY=1"), SH_OK);
    unsetenv("NOTIFY_SOCKET");
}

static void test_watchdog_env(void **state)
{
    (void)state;
    unsetenv("WATCHDOG_USEC");
    unsetenv("WATCHDOG_PID");
    assert_int_equal(sh_notify_watchdog_usec(), 0);
    setenv("WATCHDOG_USEC", "2000000", 1);
    assert_int_equal(sh_notify_watchdog_usec(), 2000000);
    char pid[32];
    snprintf(pid, sizeof pid, "%d", (int)getpid());
    setenv("WATCHDOG_PID", pid, 1);
    assert_int_equal(sh_notify_watchdog_usec(), 2000000);
    setenv("WATCHDOG_PID", "1", 1);
    assert_int_equal(sh_notify_watchdog_usec(), 0);
    setenv("WATCHDOG_USEC", "12x", 1);
    unsetenv("WATCHDOG_PID");
    assert_int_equal(sh_notify_watchdog_usec(), 0);
    unsetenv("WATCHDOG_USEC");
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_path_socket),
        cmocka_unit_test(test_listener_not_reading),
        cmocka_unit_test(test_abstract_socket),
        cmocka_unit_test(test_outside_systemd),
        cmocka_unit_test(test_watchdog_env),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
