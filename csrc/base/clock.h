/* A monotonic clock for the timings the core reports in its stats. */
#ifndef WENV_CLOCK_H
#define WENV_CLOCK_H

#include <time.h>

static inline double wenv_now_seconds(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

#endif
