/* The daemon's control socket: a local UNIX stream socket (mode 0660, the segment's group may
 * use it), one command line per connection and one reply line. It is polled from the processing
 * loop between frames and never blocks it: connections are non-blocking, a client that has not
 * sent its line yet is kept (a few, for a second at most) and looked at again next time. */
#include <errno.h>
#include <fcntl.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <time.h>
#include <unistd.h>

#include "run.h"

#define CLIENTS 8

typedef struct {
    int fd;
    size_t len;
    char line[256]; /* longer than any command: a full buffer is refused as too long, not cut */
    struct timespec since;
} client;

struct run_ctl {
    int fd;
    char path[sizeof(((struct sockaddr_un *)0)->sun_path)];
    client c[CLIENTS];
};

sh_status run_ctl_open(const char *path, run_ctl **out)
{
    struct sockaddr_un a;
    memset(&a, 0, sizeof a);
    a.sun_family = AF_UNIX;
    if (strlen(path) >= sizeof a.sun_path) return sh_error_set(SH_EINVAL, "%s: socket path too long", path);
    run_ctl *c = calloc(1, sizeof *c);
    if (!c) return sh_error_set(SH_ENOMEM, "control: out of memory");
    for (int i = 0; i < CLIENTS; i++) c->c[i].fd = -1;
    snprintf(c->path, sizeof c->path, "%s", path);
    memcpy(a.sun_path, path, strlen(path));
    c->fd = socket(AF_UNIX, SOCK_STREAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
    /* a socket left by a crashed daemon is replaced; anything else at that path is not */
    struct stat sb;
    if (c->fd >= 0 && lstat(path, &sb) == 0 && S_ISSOCK(sb.st_mode)) unlink(path);
    mode_t old = umask(0117);
    int ok = c->fd >= 0 && bind(c->fd, (struct sockaddr *)&a, sizeof a) == 0 && listen(c->fd, CLIENTS) == 0;
    umask(old);
    if (!ok) {
        sh_status st = sh_error_set(SH_EIO, "%s: %s", path, strerror(errno));
        if (c->fd >= 0) close(c->fd);
        free(c);
        return st;
    }
    *out = c;
    return SH_OK;
}

void run_ctl_close(run_ctl *c)
{
    if (!c) return;
    for (int i = 0; i < CLIENTS; i++)
        if (c->c[i].fd >= 0) close(c->c[i].fd);
    close(c->fd);
    unlink(c->path);
    free(c);
}

static void reply(client *k, const char *text)
{
    /* best effort: a client that does not read its reply loses it, the daemon goes on */
    size_t n = strlen(text);
    if (send(k->fd, text, n, MSG_NOSIGNAL | MSG_DONTWAIT) == (ssize_t)n)
        send(k->fd, "\n", 1, MSG_NOSIGNAL | MSG_DONTWAIT);
    close(k->fd);
    k->fd = -1;
}

int run_ctl_command(const char *data, size_t len, const char *status_line, char *reply, size_t cap)
{
    char line[128];
    size_t n = 0;
    while (n < len && data[n] != '\n') n++;
    if (n > sizeof line - 1) { /* never read a cut command as a shorter one */
        snprintf(reply, cap, "error: command longer than %zu bytes", sizeof line - 1);
        return 0;
    }
    memcpy(line, data, n);
    while (n && (line[n - 1] == '\r' || line[n - 1] == ' ')) n--;
    line[n] = 0;
    if (n == strlen("reference") && !memcmp(line, "reference", n)) {
        snprintf(reply, cap, "ok: new reference requested");
        return 1;
    }
    if (n == strlen("status") && !memcmp(line, "status", n)) {
        snprintf(reply, cap, "%s", status_line);
        return 0;
    }
    /* echoed back on one line: anything but printable ASCII shows as '?' */
    for (size_t i = 0; i < n; i++)
        if (line[i] < 0x20 || line[i] > 0x7e) line[i] = '?';
    snprintf(reply, cap, "error: '%.64s': unknown command (reference, status)", line);
    return 0;
}

int run_ctl_poll(run_ctl *c, const char *status_line)
{
    struct timespec now;
    clock_gettime(CLOCK_MONOTONIC, &now);
    for (int i = 0; i < CLIENTS; i++) {
        if (c->c[i].fd >= 0) continue;
        int fd = accept(c->fd, NULL, NULL);
        if (fd < 0) break;
        fcntl(fd, F_SETFL, O_NONBLOCK);
        fcntl(fd, F_SETFD, FD_CLOEXEC);
        c->c[i].fd = fd;
        c->c[i].len = 0;
        c->c[i].since = now;
    }
    int refs = 0;
    for (int i = 0; i < CLIENTS; i++) {
        client *k = &c->c[i];
        if (k->fd < 0) continue;
        ssize_t got = recv(k->fd, k->line + k->len, sizeof k->line - 1 - k->len, MSG_DONTWAIT);
        if (got > 0) k->len += (size_t)got;
        int done = memchr(k->line, '\n', k->len) || got == 0 || k->len == sizeof k->line - 1;
        if (!done) {
            if (now.tv_sec - k->since.tv_sec > 1) reply(k, "error: no command within a second");
            continue;
        }
        char text[192];
        refs += run_ctl_command(k->line, k->len, status_line, text, sizeof text);
        reply(k, text);
    }
    return refs;
}
