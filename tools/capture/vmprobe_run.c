/* stillheart-vmprobe run: the daemon itself (`stillheart run`, as systemd starts it, with a
 * NOTIFY_SOCKET and WATCHDOG_USEC of the unit's WatchdogSec) on two vivid cameras, YUYV 640x360 at
 * 30 fps, sets made by the trigger pulses it drives on a gpio-sim line, publishing to a display
 * segment that stillheart-cat -v reads all along. vivid's two instances are one platform device,
 * so one camera alone cannot be unbound: camera 1 first falls silent for 2.5 s (vivid's
 * "Percentage of Dropped Buffers" at 100: no buffer comes back, the source times out and reopens),
 * then the driver is unbound for 1.5 s and bound again, taking both nodes, the output camera's
 * among them (ENODEV, reopened once the nodes return). Judged:
 *   run-camera-lost   camera 1 reported lost and delivering again (STATUS back at 2/2 cameras),
 *                     STATUS naming it meanwhile, incomplete sets counted beside complete ones;
 *   run-output-lost   camera 0 lost: black raw frames with the reason "output camera lost" in
 *                     the display's header, STATUS "camera 0 lost, reopening", WATCHDOG=1 never
 *                     further apart than WATCHDOG_USEC, the camera's frames shown again by
 *                     themselves;
 *   run-exit          --max-frames N camera frames published, exit 0, and stillheart-cat (giving
 *                     up after 2 s without a frame) read throughout and ended with the segment.
 * vivid's test pattern has no AprilTags: camera frames are shown raw ("no reference yet"). */
#include <errno.h>
#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <sys/wait.h>
#include <sys/ioctl.h>
#include <time.h>
#include <unistd.h>

#include <linux/videodev2.h>

#include "vmprobe.h"

#define WATCHDOG_USEC 2000000 /* firmware-config/stillheart.service: WatchdogSec=2 */
#define MAXMSG 2048

static struct {
    int fd;
    int n;
    double t[MAXMSG];
    char msg[MAXMSG][200];
} nl;

static double now_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + ts.tv_nsec / 1e9;
}

/* Collects notifications for ms milliseconds. */
static void pump(int ms)
{
    double end = now_s() + ms / 1e3;
    for (double left; (left = end - now_s()) > 0;) {
        struct pollfd p = {nl.fd, POLLIN, 0};
        if (poll(&p, 1, (int)(left * 1e3) + 1) <= 0) continue;
        char m[256];
        ssize_t k = recv(nl.fd, m, sizeof m - 1, MSG_DONTWAIT);
        if (k <= 0 || nl.n == MAXMSG) continue;
        m[k] = 0;
        nl.t[nl.n] = now_s();
        snprintf(nl.msg[nl.n++], sizeof nl.msg[0], "%.199s", m);
    }
}

static int seen(const char *what)
{
    for (int i = 0; i < nl.n; i++)
        if (strstr(nl.msg[i], what)) return 1;
    return 0;
}

pid_t spawn(char *const argv[], const char *out, const char *err)
{
    pid_t pid = fork();
    if (pid) return pid;
    int o = open(out, O_WRONLY | O_CREAT | O_TRUNC, 0644), e = open(err, O_WRONLY | O_CREAT | O_TRUNC, 0644);
    dup2(o, 1);
    dup2(e, 2);
    execv(argv[0], argv);
    _exit(127);
}

char *slurp(const char *path)
{
    static char buf[4][1 << 18];
    static int next;
    char *b = buf[next++ & 3];
    FILE *f = fopen(path, "r");
    size_t n = f ? fread(b, 1, sizeof buf[0] - 1, f) : 0;
    b[n] = 0;
    if (f) fclose(f);
    return b;
}

static int lines(const char *path)
{
    int n = 0;
    for (const char *p = slurp(path); *p; p++) n += *p == '\n';
    return n;
}

/* Pumps until cond holds, the daemon exits or seconds pass; 1 when cond held. */
static int wait_for(int (*cond)(const void *), const void *arg, double seconds, pid_t daemon, int *status)
{
    double end = now_s() + seconds;
    while (now_s() < end) {
        if (cond(arg)) return 1;
        if (waitpid(daemon, status, WNOHANG) == daemon) return cond(arg);
        pump(100);
    }
    return cond(arg);
}

static int log_has(const void *what) { return strstr(slurp("/tmp/run.log"), what) != NULL; }
/* STATUS with every camera delivering, sent after notification number *from */
static int all_back(const void *from)
{
    for (int i = *(const int *)from; i < nl.n; i++)
        if (!strncmp(nl.msg[i], "STATUS=", 7) && strstr(nl.msg[i], "2/2 cameras")) return 1;
    return 0;
}
static int cat_lines_at_least(const void *n) { return lines("/tmp/cat.log") >= *(const int *)n; }
static int notified(const void *what) { return seen(what); }

/* Camera dev falls silent for 2.5 s: vivid drops every buffer. Lost after camera_timeout_ms,
 * so STATUS (once a second, after a frame) names it for 2 s. */
static int silence(const char *dev, char *why, size_t cap)
{
    int fd = open(dev, O_RDWR);
    uint32_t id = fd >= 0 ? find_ctrl(fd, "Percentage of Dropped Buffers") : 0;
    struct v4l2_control c = {.id = id, .value = 100};
    if (!id || ioctl(fd, VIDIOC_S_CTRL, &c)) {
        snprintf(why, cap, "%s: cannot set vivid's Percentage of Dropped Buffers: %s", dev, strerror(errno));
        if (fd >= 0) close(fd);
        return 0;
    }
    pump(2500);
    c.value = 0;
    int ok = ioctl(fd, VIDIOC_S_CTRL, &c) == 0;
    if (!ok) snprintf(why, cap, "%s: cannot reset the dropped buffers: %s", dev, strerror(errno));
    close(fd);
    return ok;
}

/* The vivid driver unbound from platform device plat for 1.5 s, then bound again. */
static int unplug(const char *plat, char *why, size_t cap)
{
    if (write_sys("/sys/bus/platform/drivers/vivid/unbind", plat) < 0) {
        snprintf(why, cap, "unbind %s: %s", plat, strerror(errno));
        return 0;
    }
    pump(1500);
    if (write_sys("/sys/bus/platform/drivers/vivid/bind", plat) < 0) {
        snprintf(why, cap, "bind %s: %s", plat, strerror(errno));
        return 0;
    }
    return 1;
}

/* Over 80 lines: one daemon run in the VM guest, scripted as it happens (start, camera 1 silenced
 * and back, camera 0 unbound and rebound, max-frames), then its three results judged from the same
 * logs, notify messages and the times taken during the run. Kept whole also because only vmtest
 * (tests/vm/run.sh) runs it: a split could not be checked outside the guest. */
void run_daemon_check(const char *dev0, const char *dev1, const char *plat, const char *chip, const char *line,
                      int max_frames)
{
    FILE *f = fopen("/tmp/run.ini", "w");
    if (!f) return result(0, "run-exit", "/tmp/run.ini: %s", strerror(errno));
    fprintf(f,
            "[source]\ncamera_timeout_ms = 500\nsync_tolerance_ms = 16\n"
            "[camera0]\nspec = v4l2:%s\nformat = yuyv\nsize = 640x360\nfps = 30\n"
            "[camera1]\nspec = v4l2:%s\nformat = yuyv\nsize = 640x360\nfps = 30\n"
            "[trigger]\nmode = out\nchip = %s\nline = %s\n",
            dev0, dev1, chip, line);
    fclose(f);
    struct sockaddr_un a = {.sun_family = AF_UNIX};
    snprintf(a.sun_path, sizeof a.sun_path, "/tmp/notify");
    unlink(a.sun_path);
    nl.fd = socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0);
    if (nl.fd < 0 || bind(nl.fd, (struct sockaddr *)&a, sizeof a))
        return result(0, "run-exit", "notify socket: %s", strerror(errno));
    setenv("NOTIFY_SOCKET", a.sun_path, 1);
    char wd[32], nmax[16];
    snprintf(wd, sizeof wd, "%d", WATCHDOG_USEC);
    setenv("WATCHDOG_USEC", wd, 1);
    snprintf(nmax, sizeof nmax, "%d", max_frames);
    char *run[] = {"/bin/stillheart", "run", "--config", "/tmp/run.ini", "--group=", "--sink", "shm:/vmt",
                   "--max-frames", nmax, "--stats", NULL};
    double t0 = now_s();
    pid_t d = spawn(run, "/tmp/run.out", "/tmp/run.log");
    unsetenv("NOTIFY_SOCKET");
    int st = -1, cst = -1;
    char why[256] = "";
    /* the reader starts once frames are published (STATUS comes after the first) */
    if (!wait_for(notified, "fps", 30, d, &st)) {
        kill(d, SIGKILL);
        waitpid(d, &st, 0);
        return result(0, "run-exit", "no STATUS with fps within 30 s: %s", slurp("/tmp/run.log"));
    }
    char *cat[] = {"/bin/stillheart-cat", "--name", "/vmt", "-v", "--timeout", "2", NULL};
    pid_t c = spawn(cat, "/dev/null", "/tmp/cat.log");
    int want = 5, ok = 1;
    char back1[64], back0[64];
    snprintf(back1, sizeof back1, "camera 1 (v4l2:%s) is back", dev1);
    snprintf(back0, sizeof back0, "camera 0 (v4l2:%s) is back", dev0);
    double t_lost0 = 0, t_back0 = 0;
    if (!wait_for(cat_lines_at_least, &want, 20, d, &st))
        ok = 0, snprintf(why, sizeof why, "stillheart-cat read < 5 frames");
    int from = nl.n;
    if (ok && !silence(dev1, why, sizeof why)) ok = 0;
    if (ok && !wait_for(all_back, &from, 15, d, &st))
        ok = 0, snprintf(why, sizeof why, "camera 1 not delivering again within 15 s");
    want = lines("/tmp/cat.log") + 5;
    if (ok && !wait_for(cat_lines_at_least, &want, 20, d, &st))
        ok = 0, snprintf(why, sizeof why, "no frames after camera 1 came back");
    if (ok) {
        t_lost0 = now_s();
        ok = unplug(plat, why, sizeof why);
        from = nl.n;
        if (ok && !wait_for(log_has, back0, 15, d, &st))
            ok = 0, snprintf(why, sizeof why, "no '%s' within 15 s of the bind", back0);
        if (ok && !wait_for(all_back, &from, 15, d, &st))
            ok = 0, snprintf(why, sizeof why, "not 2/2 cameras within 15 s of the bind");
        t_back0 = now_s();
    }
    /* then on to max-frames by itself */
    for (double end = now_s() + 120; ok && now_s() < end && waitpid(d, &st, WNOHANG) == 0;) pump(100);
    if (waitpid(d, &st, WNOHANG) == 0) { /* max-frames not reached */
        ok = 0;
        snprintf(why + strlen(why), sizeof why - strlen(why), "%sstill running: stopped", why[0] ? "; " : "");
        kill(d, SIGTERM);
        waitpid(d, &st, 0);
    }
    pump(100);
    double end = now_s() + 5;
    while (waitpid(c, &cst, WNOHANG) == 0 && now_s() < end) usleep(50000);
    if (now_s() >= end) kill(c, SIGKILL), waitpid(c, &cst, 0);
    const char *log = slurp("/tmp/run.log"), *out = slurp("/tmp/run.out"), *cl = slurp("/tmp/cat.log");
    printf("VMTEST INFO run: %.1f s, camera 0 unbound at %.1f s, back at %.1f s; %s", now_s() - t0, t_lost0 - t0,
           t_back0 - t0, out);
    fflush(stdout);

    /* camera 1 */
    char lost1[64];
    snprintf(lost1, sizeof lost1, "camera 1 (v4l2:%s) lost", dev1);
    unsigned long long sets = 0, incomplete = 0;
    const char *sl = strstr(log, "sets: ");
    if (sl) sscanf(sl, "sets: %llu (%llu incomplete)", &sets, &incomplete);
    result(strstr(log, lost1) && strstr(log, back1) && seen("(camera 1 lost)") && incomplete > 0 && sets > incomplete,
           "run-camera-lost", "%s; %s; STATUS %s camera 1 lost; sets: %llu (%llu incomplete)",
           strstr(log, lost1) ? "lost" : "loss not logged", strstr(log, back1) ? "reopened" : "reopen not logged",
           seen("(camera 1 lost)") ? "named" : "never named", sets, incomplete);

    /* camera 0, the output camera */
    int blacks = 0, after = 0;
    const char *last_black = NULL;
    for (const char *q = strstr(cl, "raw: output camera lost"); q; q = strstr(q + 1, "raw: output camera lost"))
        last_black = q, blacks++;
    for (const char *q = last_black ? strchr(last_black, '\n') : NULL; q && q[1]; q = strchr(q + 1, '\n')) {
        const char *e = strchr(q + 1, '\n');
        const char *hit = strstr(q + 1, "output camera lost");
        after += !hit || (e && hit > e); /* a camera frame's line (raw: no reference yet, ...) */
    }
    double prev = -1, gap = 0;
    int pings = 0, pings_lost = 0;
    for (int i = 0; i < nl.n; i++) {
        if (strcmp(nl.msg[i], "WATCHDOG=1")) continue;
        if (prev >= 0 && nl.t[i] - prev > gap) gap = nl.t[i] - prev;
        prev = nl.t[i];
        pings++;
        pings_lost += nl.t[i] > t_lost0 && nl.t[i] < t_back0;
    }
    int status0 = seen("STATUS=camera 0 lost, reopening");
    result(blacks > 0 && after > 0 && status0 && pings_lost > 0 && gap < WATCHDOG_USEC / 1e6 &&
               strstr(log, "frames are back after"),
           "run-output-lost",
           "%d black raw frames 'output camera lost' read, %d camera frames after them; STATUS %s; %d WATCHDOG=1 "
           "(%d while camera 0 was away), largest gap %.2f s (limit %.1f)",
           blacks, after, status0 ? "'camera 0 lost, reopening'" : "never said camera 0 lost", pings, pings_lost,
           gap, WATCHDOG_USEC / 1e6);

    char want_pub[48];
    snprintf(want_pub, sizeof want_pub, "stats: %d published", max_frames);
    result(ok && WIFEXITED(st) && !WEXITSTATUS(st) && strstr(out, want_pub) && WIFEXITED(cst) && !WEXITSTATUS(cst),
           "run-exit", "%s%sdaemon %s %d, '%s' %s; stillheart-cat exit %d after %d frames read", why,
           why[0] ? "; " : "", WIFEXITED(st) ? "exit" : "signal", WIFEXITED(st) ? WEXITSTATUS(st) : WTERMSIG(st),
           want_pub, strstr(out, want_pub) ? "printed" : "not printed", WIFEXITED(cst) ? WEXITSTATUS(cst) : -1,
           lines("/tmp/cat.log"));
    if (!ok || !strstr(out, want_pub)) printf("VMTEST INFO run log: %s\n", log);
    close(nl.fd);
}
