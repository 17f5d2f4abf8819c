/* stillheart ctl: one command to the daemon's control socket ([run] control), its reply printed.
 * The daemon decides who may do what from this process's credentials (docs/daemon.md). */
#include <errno.h>
#include <getopt.h>
#include <stdio.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/time.h>
#include <sys/un.h>
#include <unistd.h>

#include "app.h"
#include "stillheart/log.h"

#define CTL_DEFAULT_SOCKET "/run/stillheart/control"
#define CTL_WAIT_S 3

enum { CTL_OK = 0, CTL_REFUSED = 1, CTL_USAGE = 2, CTL_UNREACHABLE = 3 };

static const sh_cli cli = {"stillheart ctl"};

static void usage(FILE *out)
{
    fprintf(out,
        "usage: stillheart ctl [--socket PATH] [--json] status|reference\n\n"
        "Sends one command to the control socket of a running `stillheart run` and prints its reply.\n"
        "  status      one line: the last frame's status, markers, residual, published and dropped\n"
        "  reference   take a new reference frame (as SIGUSR1 to the daemon)\n"
        "options:\n"
        "  --socket PATH      the daemon's [run] control socket (default " CTL_DEFAULT_SOCKET ")\n"
        "  --json             status as one JSON object (the socket's command status-json): state\n"
        "                     (starting, running, camera lost), lost (why, while lost), frame,\n"
        "                     status, reason (null when none), markers, residual_px (null when not\n"
        "                     measured) of the last published frame; published, black_frames,\n"
        "                     dropped\n"
        SH_CLI_USAGE
        "Who may: root and the service's user anything; [run] control_group members both commands;\n"
        "[sink] group members status. The daemon logs every command with the caller's uid and pid.\n"
        "exit status: 0 done (the reply on stdout), 1 the daemon refused or answered an error (on\n"
        "stderr), 2 usage, 3 no daemon at PATH or no reply within %d s.\n", CTL_WAIT_S);
}

int cmd_ctl(int argc, char **argv)
{
    static const struct option options[] = {
        {"socket", required_argument, 0, 's'}, {"json", no_argument, 0, 'j'}, SH_CLI_OPTIONS, {0, 0, 0, 0}};
    const char *path = CTL_DEFAULT_SOCKET, *cmd = NULL;
    int json = 0, opt;
    sh_log_setup(SH_LOG_TOOL, "stillheart ctl", SH_LOG_INFO);
    optind = 1;
    opterr = 0;
    while ((opt = getopt_long(argc, argv, ":h", options, NULL)) != -1) {
        switch (opt) {
        case 's': path = optarg; break;
        case 'j': json = 1; break;
        case 'h': usage(stdout); return CTL_OK;
        default: { int rc = sh_cli_option(&cli, opt, argv); if (rc >= 0) return rc; } break;
        }
    }
    for (int i = optind; i < argc; i++) {
        const char *a = argv[i];
        if (cmd) return sh_cli_usage_error(&cli, "one command at a time ('%s', then '%s')", cmd, a);
        if (strcmp(a, "status") && strcmp(a, "reference"))
            return sh_cli_usage_error(&cli, "'%s': unknown command (status, reference)", a);
        cmd = a;
    }
    if (!cmd) return sh_cli_usage_error(&cli, "no command (status, reference)");
    if (json && strcmp(cmd, "status")) return sh_cli_usage_error(&cli, "--json goes with status");
    if (json) cmd = "status-json";
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
    char line[64], reply[1024];
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
