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

#endif
