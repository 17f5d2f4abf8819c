/* Private to stillheart-vmprobe: what its checks share (vmprobe.c, vmprobe_run.c). */
#ifndef STILLHEART_VMPROBE_H
#define STILLHEART_VMPROBE_H

#include <stdint.h>

/* Prints "VMTEST PASS|FAIL name: ..." (the line tests/vm/run.sh counts). */
void result(int ok, const char *name, const char *fmt, ...) __attribute__((format(printf, 3, 4)));
/* Writes value to a sysfs file: 0, or -1 with errno. */
int write_sys(const char *path, const char *value);
/* A vivid control by its name (its ids are private to the driver); 0 when not listed. */
uint32_t find_ctrl(int fd, const char *name);
/* Starts argv[0] with argv, its stdout and stderr to the files out and err (vmprobe_run.c). */
#include <sys/types.h>
pid_t spawn(char *const argv[], const char *out, const char *err);
/* A file's text (up to 256 KiB; one of four static buffers, reused in turn). */
char *slurp(const char *path);
/* The daemon's [sink] v4l2 on the v4l2loopback node out, read back (vmprobe_loop.c). */
void loopback_check(const char *out, const char *cap, const char *dir);
/* stillheart run on two vivid cameras with a GPIO trigger: camera 1 silenced, then the driver
 * (both cameras) unbound and bound again (vmprobe_run.c). */
void run_daemon_check(const char *dev0, const char *dev1, const char *plat, const char *chip, const char *line,
                      int max_frames);

#endif
