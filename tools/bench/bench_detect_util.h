// Helpers shared by the detection benchmarks (bench_detect, bench_detect_track), bench_landmarks,
// bench_outside and bench_screen:
// thread CPU time, medians, stopping on an error, and the build's phantom renderer.
#ifndef STILLHEART_BENCH_DETECT_UTIL_H
#define STILLHEART_BENCH_DETECT_UTIL_H

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <string>
#include <vector>

#include <unistd.h>

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

// The renderer of this build ($STILLHEART_RENDER, else $(BUILD)/stillheart-render beside
// $(BUILD)/bench/NAME, argv0); "" after saying that NAME is skipped when there is none (it needs
// OSMesa).
static inline std::string bench_renderer(const char *name, const char *argv0)
{
    std::string rbin;
    if (const char *env = std::getenv("STILLHEART_RENDER")) rbin = env;
    else {
        std::string self = argv0;
        size_t slash = self.rfind('/');
        rbin = (slash == std::string::npos ? std::string(".") : self.substr(0, slash)) + "/../stillheart-render";
    }
    if (access(rbin.c_str(), X_OK) != 0) {
        std::printf("%s: no phantom renderer at %s (needs OSMesa), skipped\n", name, rbin.c_str());
        return "";
    }
    return rbin;
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
