/* sd_notify in a few lines: an AF_UNIX datagram to $NOTIFY_SOCKET. */
#include "stillheart/notify.h"

#include <errno.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/time.h>
#include <sys/un.h>
#include <unistd.h>

sh_status sh_notify(const char *text)
{
    const char *path = getenv("NOTIFY_SOCKET");
    if (!path || !*path)
        return SH_OK;
    struct sockaddr_un addr;
    memset(&addr, 0, sizeof addr);
    addr.sun_family = AF_UNIX;
    size_t n = strlen(path);
    if ((path[0] != '/' && path[0] != '@') || n >= sizeof addr.sun_path)
        return sh_error_set(SH_EINVAL, "NOTIFY_SOCKET '%s': not a socket path", path);
    memcpy(addr.sun_path, path, n);
    if (path[0] == '@')
        addr.sun_path[0] = 0;
    socklen_t len = (socklen_t)(offsetof(struct sockaddr_un, sun_path) + n + (path[0] == '/'));
    int fd = socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0);
    if (fd < 0)
        return sh_error_set(SH_EIO, "NOTIFY_SOCKET: socket: %s", strerror(errno));
    /* A datagram to a listener whose queue is full (net.unix.max_dgram_qlen, 10 by the kernel's
     * default) blocks the sender: a manager that stops reading would hold the processing loop,
     * and after a signal has broken the wait, the loop's exit too. So a message waits at most
     * 200 ms and is then dropped with an error (STATUS and WATCHDOG come again anyway). */
    struct timeval limit = {0, 200000};
    setsockopt(fd, SOL_SOCKET, SO_SNDTIMEO, &limit, sizeof limit);
    ssize_t r = sendto(fd, text, strlen(text), MSG_NOSIGNAL, (struct sockaddr *)&addr, len);
    int e = errno;
    close(fd);
    if (r < 0)
        return sh_error_set(SH_EIO, "NOTIFY_SOCKET %s: %s", path, strerror(e));
    return SH_OK;
}

sh_status sh_notifyf(const char *fmt, ...)
{
    char buf[1024];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(buf, sizeof buf, fmt, ap);
    va_end(ap);
    return sh_notify(buf);
}

uint64_t sh_notify_watchdog_usec(void)
{
    const char *usec = getenv("WATCHDOG_USEC");
    if (!usec || !*usec)
        return 0;
    const char *pid = getenv("WATCHDOG_PID");
    if (pid && *pid && strtol(pid, NULL, 10) != (long)getpid())
        return 0;
    char *end;
    errno = 0;
    unsigned long long v = strtoull(usec, &end, 10);
    if (errno || *end || end == usec)
        return 0;
    return v;
}
