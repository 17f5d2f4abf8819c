/* libFuzzer: arbitrary bytes as one command on the daemon's control socket (src/app/run_ctl.c,
 * compiled in here: it lives in the stillheart command, not in the library). The reply is one
 * printable line that never overflows; only "reference" asks for a new reference. */
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "../../src/app/run_ctl.c"

static void check(int ok)
{
    if (!ok) abort();
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    static const char status[] = "frame 7: stabilized, 16 markers, residual 0.21 px, 8 published, 0 dropped";
    char reply[192];
    memset(reply, 'x', sizeof reply);
    int ref = run_ctl_command((const char *)data, size, status, reply, sizeof reply);
    check(memchr(reply, 0, sizeof reply) != NULL);
    check(strchr(reply, '\n') == NULL);
    for (const char *p = reply; *p; p++) check(*p >= 0x20 && *p <= 0x7e);
    size_t n = 0;
    while (n < size && data[n] != '\n') n++;
    if (n > 127) {
        check(ref == 0 && !strncmp(reply, "error: command longer", 21));
        return 0;
    }
    while (n && (data[n - 1] == '\r' || data[n - 1] == ' ')) n--;
    int is_ref = n == 9 && !memcmp(data, "reference", 9);
    check(ref == is_ref);
    check(is_ref ? !strcmp(reply, "ok: new reference requested")
                 : (n == 6 && !memcmp(data, "status", 6)) ? !strcmp(reply, status) : !strncmp(reply, "error: '", 8));
    return 0;
}
