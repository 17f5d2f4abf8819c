// Helpers shared by the detection benchmarks (bench_detect, bench_detect_track), bench_outside and
// bench_screen:
// thread CPU time, medians, and stopping on an error.
#ifndef STILLHEART_BENCH_DETECT_UTIL_H
#define STILLHEART_BENCH_DETECT_UTIL_H

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <vector>

extern "C" {
#include "stillheart/core.h"
}

// Thread CPU time in ms: the machines here are shared, wall time swings with the load.
static inline double bench_now_ms()
{
    timespec ts;
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return ts.tv_sec * 1e3 + ts.tv_nsec * 1e-6;
}

static inline double bench_median(std::vector<double> v)
{
    std::sort(v.begin(), v.end());
    return v.empty() ? 0 : v[v.size() / 2];
}

static inline void bench_check(const char *bench, sh_status st, const char *what)
{
    if (st != SH_OK) {
        std::fprintf(stderr, "%s: %s: %s\n", bench, what, sh_error_message());
        std::exit(1);
    }
}

#endif
