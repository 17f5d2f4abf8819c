/* The one clock every module and program times with (core.h). */
#include "stillheart/core.h"

#include <time.h>

int64_t sh_monotonic_ns(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (int64_t)ts.tv_sec * 1000000000 + ts.tv_nsec;
}
