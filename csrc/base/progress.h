/* Progress reporting for long work, and its cancel. */
#ifndef WENV_PROGRESS_H
#define WENV_PROGRESS_H

#include <omp.h>
#include <stdatomic.h>
#include <stddef.h>

/* `report` is called from one thread only with a fraction in [0, 1]; it returns nonzero to ask the
 * work to stop.  Either field may be NULL. */
typedef struct {
    int (*report)(void *ctx, double fraction);
    void *ctx;
} wenv_progress;

/* Inside a parallel loop, after an item: `done` of `total` items finished.  Only thread 0 reports
 * (the callback may wait for Python's lock, and one caller keeps the fractions in order).  Nonzero:
 * stop. */
static inline int wenv_progress_step(const wenv_progress *p, size_t done, size_t total)
{
    return omp_get_thread_num() == 0 && p && p->report && p->report(p->ctx, (double)done / (double)total);
}

/* The same for one more finished item of a parallel loop: counts it in `done` and sets `cancelled`
 * when the report asks to stop. */
static inline void wenv_progress_item(const wenv_progress *p, atomic_size_t *done, size_t total, atomic_int *cancelled)
{
    if (wenv_progress_step(p, atomic_fetch_add(done, 1) + 1, total))
        atomic_store(cancelled, 1);
}

/* After the loop, from the calling thread: the last report.  A dynamic schedule may give thread 0
 * no item of a short loop, so a stop asked for is honoured here at the latest.  Nonzero: stop. */
static inline int wenv_progress_finish(const wenv_progress *p)
{
    return p && p->report && p->report(p->ctx, 1.0);
}

#endif
