/* The daemon's control socket: a local UNIX stream socket, one command line per connection and
 * one reply line. It is served by a thread of its own (poll over the listening socket and every
 * client), so an answer never waits for a frame and a client never holds up the processing loop.
 *
 * Who may do what is decided from the peer's credentials (SO_PEERCRED, SO_PEERGROUPS, taken by
 * the kernel at connect time), not from the socket file's mode: the file is 0666 so that every
 * group given a right can reach it, and everyone else is answered "not permitted" and logged with
 * uid and pid (docs/daemon.md, "Control socket"). Root and the service's own uid may do anything;
 * `reference` also the control group; `status` also the control and the display group.
 *
 * No client can lock others out: a connection must send its line within CTL_TIMEOUT_MS or is
 * dropped; one uid holds at most PER_UID connections (its oldest is dropped for a new one), and
 * when the table is full the oldest connection of the uid holding the most goes. A hostile user
 * can so crowd out only its own connections. */
#ifndef _GNU_SOURCE
#define _GNU_SOURCE /* struct ucred, SO_PEERGROUPS, accept4, pipe2 */
#endif
#include <errno.h>
#include <fcntl.h>
#include <grp.h>
#include <poll.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <time.h>
#include <unistd.h>

#include "run_ctl.h"
#include "stillheart/log.h"

#define CLIENTS 64
#define PER_UID 8
#define CTL_TIMEOUT_MS 1000
#define MAX_GROUPS 256

typedef struct {
    int fd;
    size_t len;
    char line[256]; /* longer than any command: a full buffer is refused as too long, not cut */
    int64_t since;  /* ms, monotonic: accepted */
    uid_t uid;
    pid_t pid;
    int rights;     /* RUN_CTL_* the peer has */
} client;

struct run_ctl {
    int fd, wake[2];
    char path[sizeof(((struct sockaddr_un *)0)->sun_path)];
    dev_t dev;
    ino_t ino;
    pthread_t thread;
    int started;
    client c[CLIENTS];
    pthread_mutex_t mu; /* status, the groups */
    char status[192], status_json[RUN_CTL_STATUS_MAX];
    gid_t control_gid, display_gid;
    int has_control;    /* a control group is configured */
    atomic_int refs;
    /* idle drops are summed, logged at most once a second: a flood must not flood the log */
    unsigned dropped;
    uid_t dropped_uid;
    pid_t dropped_pid;
    int64_t dropped_logged;
};

static int64_t now_ms(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (int64_t)ts.tv_sec * 1000 + ts.tv_nsec / 1000000;
}

static sh_status group_id(const char *name, const char *key, gid_t *out)
{
    char buf[4096];
    struct group g, *r = NULL;
    int e = getgrnam_r(name, &g, buf, sizeof buf, &r);
    if (!r) return sh_error_set(SH_EINVAL, "%s: no group '%s'%s%s", key, name, e ? ": " : "", e ? strerror(e) : "");
    *out = g.gr_gid;
    return SH_OK;
}

sh_status run_ctl_groups(run_ctl *c, const char *control_group, const char *display_group)
{
    gid_t cg = 0, dg = getegid();
    sh_status st = SH_OK;
    if (control_group[0]) st = group_id(control_group, "[run] control_group", &cg);
    if (st == SH_OK && display_group[0]) st = group_id(display_group, "[sink] group", &dg);
    if (st != SH_OK) return st;
    pthread_mutex_lock(&c->mu);
    c->has_control = control_group[0] != 0;
    c->control_gid = cg;
    c->display_gid = dg;
    pthread_mutex_unlock(&c->mu);
    return SH_OK;
}

/* The rights of the peer on fd, from its credentials at connect time. */
static int peer_rights(run_ctl *c, int fd, uid_t *uid, pid_t *pid)
{
    struct ucred cr;
    socklen_t n = sizeof cr;
    if (getsockopt(fd, SOL_SOCKET, SO_PEERCRED, &cr, &n) != 0) return *uid = (uid_t)-1, *pid = 0, 0;
    *uid = cr.uid;
    *pid = cr.pid;
    if (cr.uid == 0 || cr.uid == geteuid()) return RUN_CTL_STATUS | RUN_CTL_REFERENCE;
    gid_t g[MAX_GROUPS];
    socklen_t gn = sizeof g;
    int ng = getsockopt(fd, SOL_SOCKET, SO_PEERGROUPS, g, &gn) == 0 ? (int)(gn / sizeof g[0]) : 0;
    pthread_mutex_lock(&c->mu);
    int in_control = 0, in_display = cr.gid == c->display_gid;
    if (c->has_control && cr.gid == c->control_gid) in_control = 1;
    for (int i = 0; i < ng; i++) {
        if (c->has_control && g[i] == c->control_gid) in_control = 1;
        if (g[i] == c->display_gid) in_display = 1;
    }
    pthread_mutex_unlock(&c->mu);
    /* a peer in more groups than we asked for is judged on the first MAX_GROUPS: never a right
     * it lacks, at worst a refusal it can fix by dropping groups */
    return in_control ? RUN_CTL_STATUS | RUN_CTL_REFERENCE : in_display ? RUN_CTL_STATUS : 0;
}

static void drop(client *k)
{
    close(k->fd);
    k->fd = -1;
}

static void reply(client *k, const char *text)
{
    /* best effort: a client that does not read its reply loses it, the daemon goes on */
    size_t n = strlen(text);
    if (send(k->fd, text, n, MSG_NOSIGNAL | MSG_DONTWAIT) == (ssize_t)n)
        send(k->fd, "\n", 1, MSG_NOSIGNAL | MSG_DONTWAIT);
    drop(k);
}

static void count_drop(run_ctl *c, client *k)
{
    c->dropped++;
    c->dropped_uid = k->uid;
    c->dropped_pid = k->pid;
    drop(k);
}

static void log_drops(run_ctl *c, int64_t now)
{
    if (!c->dropped || now - c->dropped_logged < 1000) return;
    sh_log_warn("control: dropped %u connection%s that sent no command within %d ms or crowded their uid's "
           "share (the last: uid %u pid %d)", c->dropped, c->dropped == 1 ? "" : "s", CTL_TIMEOUT_MS,
           (unsigned)c->dropped_uid, (int)c->dropped_pid);
    c->dropped = 0;
    c->dropped_logged = now;
}

int run_ctl_command(const char *data, size_t len, int rights, const char *status_line, const char *status_json,
                    char *reply, size_t cap)
{
    char line[128];
    size_t n = 0;
    while (n < len && data[n] != '\n') n++;
    if (n > sizeof line - 1) { /* never read a cut command as a shorter one */
        snprintf(reply, cap, "error: command longer than %zu bytes", sizeof line - 1);
        return RUN_CTL_BAD;
    }
    memcpy(line, data, n);
    while (n && (line[n - 1] == '\r' || line[n - 1] == ' ')) n--;
    line[n] = 0;
    if (n == strlen("reference") && !memcmp(line, "reference", n)) {
        if (!(rights & RUN_CTL_REFERENCE)) {
            snprintf(reply, cap, "error: reference: not permitted (the service's user, root and [run] control_group only)");
            return RUN_CTL_REFUSED;
        }
        snprintf(reply, cap, "ok: new reference requested");
        return RUN_CTL_REFERENCE;
    }
    int json = n == strlen("status-json") && !memcmp(line, "status-json", n);
    if (json || (n == strlen("status") && !memcmp(line, "status", n))) {
        if (!(rights & RUN_CTL_STATUS)) {
            snprintf(reply, cap, "error: %s: not permitted (the service's user, root, [run] control_group and "
                     "[sink] group only)", line);
            return RUN_CTL_REFUSED;
        }
        snprintf(reply, cap, "%s", json ? status_json : status_line);
        return RUN_CTL_STATUS;
    }
    /* echoed back on one line: anything but printable ASCII shows as '?' */
    for (size_t i = 0; i < n; i++)
        if (line[i] < 0x20 || line[i] > 0x7e) line[i] = '?';
    snprintf(reply, cap, "error: '%.64s': unknown command (reference, status, status-json)", line);
    return RUN_CTL_BAD;
}

/* One client that sent its line (or closed, or filled its buffer): answered, logged, closed. */
static void answer(run_ctl *c, client *k)
{
    char status[sizeof c->status], json[sizeof c->status_json], text[RUN_CTL_STATUS_MAX + 64];
    pthread_mutex_lock(&c->mu);
    memcpy(status, c->status, sizeof status);
    memcpy(json, c->status_json, sizeof json);
    pthread_mutex_unlock(&c->mu);
    int r = run_ctl_command(k->line, k->len, k->rights, status, json, text, sizeof text);
    if (r == RUN_CTL_REFERENCE) {
        atomic_fetch_add(&c->refs, 1);
        sh_log_info("control: reference from uid %u pid %d: accepted", (unsigned)k->uid, (int)k->pid);
    } else if (r == RUN_CTL_STATUS) {
        sh_log_info("control: status from uid %u pid %d: answered", (unsigned)k->uid, (int)k->pid);
    } else {
        sh_log_warn("control: uid %u pid %d refused: %s", (unsigned)k->uid, (int)k->pid, text + 7);
    }
    reply(k, text);
}

/* A new connection from uid: makes room for it (its uid's oldest beyond PER_UID, or, the table
 * full, the oldest of the uid holding the most) and returns its slot. */
static client *make_room(run_ctl *c, uid_t uid)
{
    int mine = 0, oldest_mine = -1, free_slot = -1;
    for (int i = 0; i < CLIENTS; i++) {
        if (c->c[i].fd < 0) { if (free_slot < 0) free_slot = i; continue; }
        if (c->c[i].uid != uid) continue;
        mine++;
        if (oldest_mine < 0 || c->c[i].since < c->c[oldest_mine].since) oldest_mine = i;
    }
    if (mine >= PER_UID) {
        count_drop(c, &c->c[oldest_mine]);
        return &c->c[oldest_mine];
    }
    if (free_slot >= 0) return &c->c[free_slot];
    int most = 0, victim = 0;
    for (int i = 0; i < CLIENTS; i++) {
        int same = 0;
        for (int j = 0; j < CLIENTS; j++) same += c->c[j].uid == c->c[i].uid;
        if (same > most || (same == most && c->c[i].since < c->c[victim].since)) most = same, victim = i;
    }
    count_drop(c, &c->c[victim]);
    return &c->c[victim];
}

/* At most CLIENTS a round: a flood of connections cannot keep the thread from answering. */
static void accept_some(run_ctl *c, int64_t now)
{
    for (int i = 0; i < CLIENTS; i++) {
        int fd = accept4(c->fd, NULL, NULL, SOCK_NONBLOCK | SOCK_CLOEXEC);
        if (fd < 0) return; /* EAGAIN, or a connection gone before we took it */
        uid_t uid;
        pid_t pid;
        int rights = peer_rights(c, fd, &uid, &pid);
        client *k = make_room(c, uid);
        k->fd = fd;
        k->len = 0;
        k->since = now;
        k->uid = uid;
        k->pid = pid;
        k->rights = rights;
    }
}

static void *serve(void *arg)
{
    run_ctl *c = arg;
    sh_log_set_thread("ctl");
    struct pollfd p[CLIENTS + 2];
    int at[CLIENTS + 2];
    for (;;) {
        int64_t now = now_ms(), wait = -1;
        int n = 0;
        p[n++] = (struct pollfd){.fd = c->wake[0], .events = POLLIN};
        p[n++] = (struct pollfd){.fd = c->fd, .events = POLLIN};
        for (int i = 0; i < CLIENTS; i++) {
            if (c->c[i].fd < 0) continue;
            int64_t left = c->c[i].since + CTL_TIMEOUT_MS - now;
            if (wait < 0 || left < wait) wait = left < 0 ? 0 : left;
            at[n] = i;
            p[n++] = (struct pollfd){.fd = c->c[i].fd, .events = POLLIN};
        }
        if (c->dropped && (wait < 0 || wait > 1000)) wait = 1000;
        if (poll(p, (nfds_t)n, (int)wait) < 0 && errno != EINTR) {
            sh_log_error("control: poll: %s; the control socket answers no more until a restart",
                   strerror(errno));
            break;
        }
        if (p[0].revents) break; /* run_ctl_close */
        now = now_ms();
        /* those who sent their line first: a flood of new connections cannot push them out */
        for (int j = 2; j < n; j++) {
            client *k = &c->c[at[j]];
            if (!p[j].revents || k->fd != p[j].fd) continue;
            ssize_t got = recv(k->fd, k->line + k->len, sizeof k->line - 1 - k->len, MSG_DONTWAIT);
            if (got > 0) k->len += (size_t)got;
            if (got == 0 || (got < 0 && errno != EAGAIN && errno != EINTR) || memchr(k->line, '\n', k->len) ||
                k->len == sizeof k->line - 1)
                answer(c, k);
        }
        for (int i = 0; i < CLIENTS; i++)
            if (c->c[i].fd >= 0 && now - c->c[i].since >= CTL_TIMEOUT_MS) count_drop(c, &c->c[i]);
        if (p[1].revents) accept_some(c, now);
        log_drops(c, now);
    }
    return NULL;
}

sh_status run_ctl_open(const char *path, const char *control_group, const char *display_group,
                       run_ctl **out)
{
    struct sockaddr_un a;
    memset(&a, 0, sizeof a);
    a.sun_family = AF_UNIX;
    if (strlen(path) >= sizeof a.sun_path) return sh_error_set(SH_EINVAL, "%s: socket path too long", path);
    run_ctl *c = calloc(1, sizeof *c);
    if (!c) return sh_error_set(SH_ENOMEM, "control: out of memory");
    for (int i = 0; i < CLIENTS; i++) c->c[i].fd = -1;
    c->wake[0] = c->wake[1] = -1;
    pthread_mutex_init(&c->mu, NULL);
    snprintf(c->status, sizeof c->status, "starting: no frame yet");
    snprintf(c->status_json, sizeof c->status_json, "{\"state\": \"starting\"}");
    snprintf(c->path, sizeof c->path, "%s", path);
    memcpy(a.sun_path, path, strlen(path));
    sh_status st = run_ctl_groups(c, control_group, display_group);
    if (st != SH_OK) {
        pthread_mutex_destroy(&c->mu);
        free(c);
        return st;
    }
    c->fd = socket(AF_UNIX, SOCK_STREAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
    /* a socket left by a crashed daemon is replaced; one a running daemon serves, or anything
     * else at that path, is not */
    struct stat sb;
    if (c->fd >= 0 && lstat(path, &sb) == 0 && S_ISSOCK(sb.st_mode)) {
        int probe = socket(AF_UNIX, SOCK_STREAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
        int live = probe >= 0 && (connect(probe, (struct sockaddr *)&a, sizeof a) == 0 || errno == EAGAIN);
        if (probe >= 0) close(probe);
        if (live) {
            close(c->fd);
            pthread_mutex_destroy(&c->mu);
            free(c);
            return sh_error_set(SH_EIO, "%s: in use by a running daemon", path);
        }
        unlink(path);
    }
    /* 0666: rights come from the peer's credentials (above), and every group given one must
     * reach the socket; the directory around it decides who can reach it at all. chmod after
     * bind, not umask around it: the umask is the whole process's, and other threads create
     * files (recordings) meanwhile. */
    int ok = c->fd >= 0 && bind(c->fd, (struct sockaddr *)&a, sizeof a) == 0 && chmod(path, 0666) == 0 &&
             listen(c->fd, SOMAXCONN) == 0 && lstat(path, &sb) == 0 && pipe2(c->wake, O_CLOEXEC | O_NONBLOCK) == 0;
    if (ok) {
        c->dev = sb.st_dev;
        c->ino = sb.st_ino;
        errno = pthread_create(&c->thread, NULL, serve, c);
        ok = c->started = errno == 0;
    }
    if (!ok) {
        st = sh_error_set(SH_EIO, "%s: %s", path, strerror(errno));
        run_ctl_close(c);
        return st;
    }
    *out = c;
    return SH_OK;
}

void run_ctl_close(run_ctl *c)
{
    if (!c) return;
    if (c->started) {
        (void)!write(c->wake[1], "x", 1);
        pthread_join(c->thread, NULL);
    }
    for (int i = 0; i < CLIENTS; i++)
        if (c->c[i].fd >= 0) close(c->c[i].fd);
    if (c->fd >= 0) {
        close(c->fd);
        /* only our own socket: a daemon started since may have bound the path anew */
        struct stat sb;
        if (c->ino && lstat(c->path, &sb) == 0 && sb.st_dev == c->dev && sb.st_ino == c->ino) unlink(c->path);
    }
    if (c->wake[0] >= 0) close(c->wake[0]);
    if (c->wake[1] >= 0) close(c->wake[1]);
    pthread_mutex_destroy(&c->mu);
    free(c);
}

void run_ctl_set_status(run_ctl *c, const char *status_line, const char *status_json)
{
    pthread_mutex_lock(&c->mu);
    snprintf(c->status, sizeof c->status, "%s", status_line);
    snprintf(c->status_json, sizeof c->status_json, "%s", status_json);
    pthread_mutex_unlock(&c->mu);
}

int run_ctl_references(run_ctl *c) { return atomic_exchange(&c->refs, 0); }
