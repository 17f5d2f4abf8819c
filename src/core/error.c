#include "stillheart/core.h"

#include <stdarg.h>
#include <stdio.h>
#include <string.h>

static _Thread_local char last_message[512];

sh_status sh_error_set(sh_status code, const char *fmt, ...)
{
    /* formatted aside first: callers prefix the current message with its own text
     * (sh_error_set(st, "context: %s", sh_error_message())), which vsnprintf into the same
     * buffer would overwrite while reading it */
    char text[sizeof last_message];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(text, sizeof text, fmt, ap);
    va_end(ap);
    memcpy(last_message, text, sizeof last_message);
    return code;
}

const char *sh_error_message(void)
{
    return last_message;
}

const char *sh_status_name(sh_status code)
{
    switch (code) {
    case SH_OK: return "ok";
    case SH_EINVAL: return "invalid argument";
    case SH_ENOMEM: return "out of memory";
    case SH_EIO: return "i/o error";
    case SH_EFORMAT: return "malformed input";
    case SH_EDEGENERATE: return "degenerate geometry";
    case SH_EEOF: return "end of stream";
    case SH_EUNSUPPORTED: return "unsupported";
    case SH_ERANGE: return "out of range";
    }
    return "unknown status";
}
