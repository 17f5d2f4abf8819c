/* stillheart ctl: one command to the daemon's control socket ([run] control), its reply printed.
 * The daemon decides who may do what from this process's credentials (docs/daemon.md). */
#include <errno.h>
#include <stdio.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/time.h>
#include <sys/un.h>
#include <unistd.h>

#include "app.h"

#define CTL_DEFAULT_SOCKET "/run/stillheart/control"
#define CTL_WAIT_S 3

enum { CTL_OK = 0, CTL_REFUSED = 1, CTL_USAGE = 2, CTL_UNREACHABLE = 3 };

static void usage(FILE *out)
{
    fprintf(out,
        "usage: stillheart ctl [--socket PATH] status|reference\n\n"
        "Sends one command to the control socket of a running `stillheart run` and prints its reply.\n"
        "  status      one line: the last frame's status, markers, residual, published and dropped\n"
        "  reference   take a new reference frame (as SIGUSR1 to the daemon)\n"
        "options:\n"
        "  --socket PATH   the daemon's [run] control socket (default " CTL_DEFAULT_SOCKET ")\n"
        "  --help          this text\n"
        "Who may: root and the service's user anything; [run] control_group members both commands;\n"
        "[sink] group members status. The daemon logs every command with the caller's uid and pid.\n"
        "exit status: 0 done (the reply on stdout), 1 the daemon refused or answered an error (on\n"
        "stderr), 2 usage, 3 no daemon at PATH or no reply within %d s.\n", CTL_WAIT_S);
}

int cmd_ctl(int argc, char **argv)
{
    const char *path = CTL_DEFAULT_SOCKET, *cmd = NULL;
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i];
        if (!strcmp(a, "--help") || !strcmp(a, "-h")) { usage(stdout); return CTL_OK; }
        if (!strcmp(a, "--socket") && i + 1 < argc) { path = argv[++i]; continue; }
        if (!strncmp(a, "--socket=", 9)) { path = a + 9; continue; }
        if (a[0] == '-') {
            fprintf(stderr, "stillheart ctl: %s: %s (stillheart ctl --help)\n", a,
                    !strcmp(a, "--socket") ? "needs a path" : "unknown option");
            return CTL_USAGE;
        }
        if (cmd) { fprintf(stderr, "stillheart ctl: one command at a time ('%s', then '%s')\n", cmd, a); return CTL_USAGE; }
        if (strcmp(a, "status") && strcmp(a, "reference")) {
            fprintf(stderr, "stillheart ctl: '%s': unknown command (status, reference)\n", a);
            return CTL_USAGE;
        }
        cmd = a;
    }
    if (!cmd) { usage(stderr); return CTL_USAGE; }
    struct sockaddr_un sa;
    memset(&sa, 0, sizeof sa);
    sa.sun_family = AF_UNIX;
    if (strlen(path) >= sizeof sa.sun_path) {
        fprintf(stderr, "stillheart ctl: %s: a socket path has at most %zu bytes\n", path, sizeof sa.sun_path - 1);
        return CTL_USAGE;
    }
    memcpy(sa.sun_path, path, strlen(path));
    int fd = socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
    /* the send timeout also bounds connect on a UNIX socket whose backlog is full */
    struct timeval tv = {CTL_WAIT_S, 0};
    if (fd < 0 || setsockopt(fd, SOL_SOCKET, SO_SNDTIMEO, &tv, sizeof tv) ||
        setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv) || connect(fd, (struct sockaddr *)&sa, sizeof sa)) {
        int e = errno;
        fprintf(stderr, "stillheart ctl: %s: %s%s\n", path, e == EAGAIN || e == EINPROGRESS ? "no room (timed out)" : strerror(e),
                e == ENOENT || e == ECONNREFUSED ? " (is stillheart run running with [run] control set to it?)" : "");
        if (fd >= 0) close(fd);
        return e == EACCES ? CTL_REFUSED : CTL_UNREACHABLE;
    }
    char line[64], reply[512];
    int n = snprintf(line, sizeof line, "%s\n", cmd);
    size_t got = 0;
    if (send(fd, line, (size_t)n, MSG_NOSIGNAL) != n) {
        fprintf(stderr, "stillheart ctl: %s: sending: %s\n", path, strerror(errno));
        close(fd);
        return CTL_UNREACHABLE;
    }
    for (;;) {
        ssize_t r = recv(fd, reply + got, sizeof reply - 1 - got, 0);
        if (r > 0 && (got += (size_t)r) < sizeof reply - 1) continue;
        if (r < 0 && errno == EINTR) continue;
        if (r < 0) {
            if (errno == EAGAIN) fprintf(stderr, "stillheart ctl: %s: no reply within %d s\n", path, CTL_WAIT_S);
            else fprintf(stderr, "stillheart ctl: %s: %s\n", path, strerror(errno));
            close(fd);
            return CTL_UNREACHABLE;
        }
        break;
    }
    close(fd);
    reply[got] = 0;
    while (got && (reply[got - 1] == '\n' || reply[got - 1] == '\r')) reply[--got] = 0;
    if (!got) {
        fprintf(stderr, "stillheart ctl: %s: the daemon closed the connection without a reply\n", path);
        return CTL_UNREACHABLE;
    }
    if (!strncmp(reply, "error: ", 7)) {
        fprintf(stderr, "stillheart ctl: %s\n", reply + 7);
        return CTL_REFUSED;
    }
    printf("%s\n", reply);
    return CTL_OK;
}
