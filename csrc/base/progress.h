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

/* Runs each(ctx, first, end) over [0, n) in blocks of `block` items, in parallel, with a report after
 * each block and a last one at the end.  Nonzero: the report asked to stop (blocks not yet begun
 * are skipped). */
static inline int wenv_progress_blocks(size_t n, size_t block, void (*each)(const void *ctx, size_t first, size_t end),
                                       const void *ctx, const wenv_progress *p)
{
    size_t blocks = (n + block - 1) / block;
    atomic_size_t done = 0;
    atomic_int cancelled = 0;
#pragma omp parallel for schedule(dynamic, 1)
    for (long long b = 0; b < (long long)blocks; b++) {
        if (atomic_load(&cancelled))
            continue;
        size_t first = (size_t)b * block, end = first + block < n ? first + block : n;
        each(ctx, first, end);
        wenv_progress_item(p, &done, blocks, &cancelled);
    }
    return atomic_load(&cancelled) || wenv_progress_finish(p);
}

#endif
