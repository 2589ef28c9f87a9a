#include "math/sparse.h"

#include <stdlib.h>
#include <string.h>

/* Hoare-style quickselect: after it, work[k] holds the k-th largest value. */
static float kth_largest(float *work, size_t n, size_t k)
{
    size_t lo = 0, hi = n - 1;
    while (lo < hi) {
        float pivot = work[lo + (hi - lo) / 2];
        size_t i = lo, j = hi;
        while (i <= j) {
            while (work[i] > pivot)
                i++;
            while (work[j] < pivot)
                j--;
            if (i <= j) {
                float t = work[i];
                work[i] = work[j];
                work[j] = t;
                i++;
                if (j == 0)
                    break;
                j--;
            }
        }
        if (k <= j)
            hi = j;
        else if (k >= i)
            lo = i;
        else
            break;
    }
    return work[k];
}

size_t wenv_select_largest(const float *mag, size_t n, size_t k, uint32_t *idx, float *work)
{
    size_t nonzero = 0;
    for (size_t i = 0; i < n; i++)
        nonzero += mag[i] > 0.0f;
    if (k >= nonzero) {
        size_t c = 0;
        for (size_t i = 0; i < n; i++)
            if (mag[i] > 0.0f)
                idx[c++] = (uint32_t)i;
        return c;
    }
    if (k == 0)
        return 0;
    memcpy(work, mag, n * sizeof(float));
    float thr = kth_largest(work, n, k - 1);
    size_t c = 0;
    for (size_t i = 0; i < n && c < k; i++)
        if (mag[i] > thr)
            idx[c++] = (uint32_t)i;
    /* ties at the threshold fill the remaining places, in index order */
    size_t above = c;
    if (c < k) {
        /* merge in the ties while keeping indices ascending */
        size_t ties = 0;
        for (size_t i = 0; i < n && above + ties < k; i++)
            if (mag[i] == thr && thr > 0.0f)
                work[ties++] = (float)i; /* work is free again; indices < 2^24 are exact */
        size_t a = 0, b = 0, out = 0;
        /* backwards merge into idx[0..above+ties) */
        a = above;
        b = ties;
        out = above + ties;
        while (b > 0) {
            uint32_t tb = (uint32_t)work[b - 1];
            if (a > 0 && idx[a - 1] > tb)
                idx[--out] = idx[--a];
            else {
                idx[--out] = tb;
                b--;
            }
        }
        c = above + ties;
    }
    return c;
}

void wenv_csc_free(wenv_csc *m)
{
    if (!m)
        return;
    free(m->colptr);
    free(m->rowidx);
    free(m->val);
    memset(m, 0, sizeof *m);
}

size_t wenv_csc_nnz(const wenv_csc *m) { return m->colptr ? m->colptr[m->cols] : 0; }

typedef float rgbx4 __attribute__((vector_size(4 * sizeof(float))));

void wenv_sparse_rows_dot(const uint16_t *index, const float *weight, size_t n, size_t k, const float *rgbx,
                          float *out)
{
    const rgbx4 *light = (const rgbx4 *)(const void *)rgbx;
#pragma omp parallel for schedule(static)
    for (size_t r = 0; r < n; r++) {
        const uint16_t *ix = index + r * k;
        const float *w = weight + r * k;
        /* four sums in turn: one would wait on each multiply-add's latency */
        rgbx4 part[4] = {{0.0f}};
        size_t j = 0;
        for (; j + 4 <= k; j += 4)
            for (size_t q = 0; q < 4; q++)
                part[q] += w[j + q] * light[ix[j + q]];
        for (; j < k; j++)
            part[0] += w[j] * light[ix[j]];
        rgbx4 sum = (part[0] + part[1]) + (part[2] + part[3]);
        out[3 * r] = sum[0];
        out[3 * r + 1] = sum[1];
        out[3 * r + 2] = sum[2];
    }
}
