/* Private to the daemon (src/daemon): the control socket (run_ctl.c). */
#ifndef STILLHEART_RUN_CTL_H
#define STILLHEART_RUN_CTL_H

#include <stddef.h>
#include "stillheart/core.h"

/* ---- control socket (run_ctl.c) ----
 * A local UNIX stream socket served by a thread of its own: one command line per connection
 * ("reference", "status", "status-json"), one reply line. Rights come from the peer's credentials: root and the
 * service's uid may do anything, control_group members "reference" and "status", display_group
 * members "status" and "status-json" ("" control group: none; "" display group: the process's group). Every
 * answered or refused command is logged with the peer's uid and pid. */
typedef struct run_ctl run_ctl;
enum { RUN_CTL_BAD = 0, RUN_CTL_STATUS = 1, RUN_CTL_REFERENCE = 2, RUN_CTL_REFUSED = 4 };
sh_status run_ctl_open(const char *path, const char *control_group, const char *display_group, run_ctl **out);
void run_ctl_close(run_ctl *c);
/* New groups for a running socket (a reload); an unknown group is refused, the old ones kept. */
sh_status run_ctl_groups(run_ctl *c, const char *control_group, const char *display_group);
/* The lines "status" and "status-json" are answered with from now on (the same state: a line of
 * text, one JSON object). */
#define RUN_CTL_STATUS_MAX 512
void run_ctl_set_status(run_ctl *c, const char *status_line, const char *status_json);
/* "reference" requests accepted since the last call. */
int run_ctl_references(run_ctl *c);
/* One command (data: len bytes, up to the first newline) from a peer with rights (RUN_CTL_STATUS |
 * RUN_CTL_REFERENCE) -> reply (one printable line, NUL-terminated). Returns RUN_CTL_REFERENCE or
 * RUN_CTL_STATUS for a command carried out, RUN_CTL_REFUSED for one the rights do not allow,
 * RUN_CTL_BAD for anything else. */
int run_ctl_command(const char *data, size_t len, int rights, const char *status_line, const char *status_json,
                    char *reply, size_t cap);

#endif
