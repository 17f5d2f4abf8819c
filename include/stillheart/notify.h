/* systemd's notification protocol without libsystemd: one datagram to $NOTIFY_SOCKET
 * ("READY=1", "STATUS=...", "WATCHDOG=1", "STOPPING=1", "RELOADING=1"). Outside systemd
 * (no NOTIFY_SOCKET) every call is a no-op returning SH_OK. */
#ifndef STILLHEART_NOTIFY_H
#define STILLHEART_NOTIFY_H

#include <stdint.h>
#include "stillheart/core.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Sends text (newline-separated assignments) to $NOTIFY_SOCKET (a path, or "@name" for the
 * abstract namespace). SH_OK also when the variable is unset. */
sh_status sh_notify(const char *text);
/* printf-style; the message is cut at 1 KiB. */
sh_status sh_notifyf(const char *fmt, ...) __attribute__((format(printf, 1, 2)));
/* The watchdog interval asked for by $WATCHDOG_USEC (checked against $WATCHDOG_PID when set),
 * in microseconds; 0 when none. Ping at half of it. */
uint64_t sh_notify_watchdog_usec(void);

#ifdef __cplusplus
}
#endif
#endif
