/* libFuzzer: arbitrary bytes as one command on the daemon's control socket (src/daemon/run_ctl.c,
 * linked from the library). The first byte is
 * the peer's rights (bit 0: status, bit 1: reference, as the daemon derives them from
 * SO_PEERCRED), the rest the command. The reply is one printable line that never overflows;
 * only "reference" with the reference right asks for a new reference, "status" without the
 * status right is refused and never shows the status line. */
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "../../src/daemon/run_ctl.h"

static void check(int ok)
{
    if (!ok) abort();
}

int LLVMFuzzerTestOneInput(const uint8_t *in, size_t insize)
{
    static const char status[] = "frame 7: stabilized, 16 markers, residual 0.21 px, 8 published, 0 dropped";
    static const char status_json[] = "{\"state\": \"running\", \"frame\": 7, \"markers\": 16}";
    if (insize < 1) return 0;
    int rights = (in[0] & 1 ? RUN_CTL_STATUS : 0) | (in[0] & 2 ? RUN_CTL_REFERENCE : 0);
    const uint8_t *data = in + 1;
    size_t size = insize - 1;
    char reply[192];
    memset(reply, 'x', sizeof reply);
    int r = run_ctl_command((const char *)data, size, rights, status, status_json, reply, sizeof reply);
    check(memchr(reply, 0, sizeof reply) != NULL);
    check(strchr(reply, '\n') == NULL);
    for (const char *p = reply; *p; p++) check(*p >= 0x20 && *p <= 0x7e);
    size_t n = 0;
    while (n < size && data[n] != '\n') n++;
    if (n > 127) {
        check(r == RUN_CTL_BAD && !strncmp(reply, "error: command longer", 21));
        return 0;
    }
    while (n && (data[n - 1] == '\r' || data[n - 1] == ' ')) n--;
    int is_ref = n == 9 && !memcmp(data, "reference", 9), is_status = n == 6 && !memcmp(data, "status", 6);
    int is_json = n == 11 && !memcmp(data, "status-json", 11);
    if (is_ref && (rights & RUN_CTL_REFERENCE)) check(r == RUN_CTL_REFERENCE && !strcmp(reply, "ok: new reference requested"));
    else if (is_status && (rights & RUN_CTL_STATUS)) check(r == RUN_CTL_STATUS && !strcmp(reply, status));
    else if (is_json && (rights & RUN_CTL_STATUS)) check(r == RUN_CTL_STATUS && !strcmp(reply, status_json));
    else if (is_ref || is_status || is_json)
        check(r == RUN_CTL_REFUSED && strstr(reply, "not permitted") && !strstr(reply, "frame 7") && !strstr(reply, "\"frame\""));
    else check(r == RUN_CTL_BAD && !strncmp(reply, "error: '", 8));
    return 0;
}
