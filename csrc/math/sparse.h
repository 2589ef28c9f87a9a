/* Sparse vectors and matrices for truncated wavelet coefficients and rotation matrices. */
#ifndef WENV_SPARSE_H
#define WENV_SPARSE_H

#include <stddef.h>
#include <stdint.h>

/* Indices of the k entries of largest magnitude among mag[0..n) (zeros never chosen), written to
 * idx in ascending order so gathers walk memory forwards.  `work` holds n floats.  Returns how
 * many were written (at most k). */
size_t wenv_select_largest(const float *mag, size_t n, size_t k, uint32_t *idx, float *work);

/* Compressed sparse columns: column j holds rows[colptr[j] .. colptr[j+1]) and their values. */
typedef struct {
    size_t rows, cols;
    size_t *colptr; /* cols + 1 */
    uint16_t *rowidx; /* local maps are at most 256 x 256: u16 cuts the matrices' bandwidth by a quarter */
    float *val;
} wenv_csc;

void wenv_csc_free(wenv_csc *m);
size_t wenv_csc_nnz(const wenv_csc *m);

/* Each of n rows' k terms against an RGB vector: out[3 r + c] = sum over j of
 * weight[r k + j] * rgbx[4 index[r k + j] + c], rows over the threads.  The per-vertex sparse dot
 * product of the thesis's relighting (a vertex's kept transport terms against the lighting's
 * coefficients): what a view of n vertices costs at the least, the floor the benchmarks measure
 * the shading against.  rgbx holds each coefficient as r g b and a pad (wenv_rgbx_from_rgb), so a
 * term is one 4-wide load and multiply-add.  The caller checks every index against its length.
 * On the 2-core VM 126k rows of 128 terms (u16 index, float weight: 97 MB) take about 28 ms, the
 * rows' memory bound (37 ms on one thread; 15 ms when the rows fit in the caches). */
void wenv_sparse_rows_dot(const uint16_t *index, const float *weight, size_t n, size_t k, const float *rgbx,
                          float *out);

#endif
