/* Nonstandard 2D Haar transform (docs/ARCHITECTURE.md §3.3), orthonormal (1/sqrt 2 per step), so the
 * inverse is the transpose and dot products are preserved (Parseval).
 *
 * The image is n x n "pixels" (n a power of two), each a vector of `channels` floats stored
 * contiguously (index (row * n + col) * channels + c); every channel is transformed alike.  One
 * level transforms the rows of the top-left s x s block (averages to the left half, details to
 * the right half), then its columns (averages on top), and recurses on the s/2 x s/2 average
 * block.  `scratch` holds wenv_haar2d_scratch_floats(n, channels) floats (half the image). */
#ifndef WENV_HAAR_H
#define WENV_HAAR_H

#include <stddef.h>

int wenv_is_power_of_two(size_t n);

size_t wenv_haar2d_scratch_floats(size_t n, size_t channels);
void wenv_haar2d_forward(float *data, size_t n, size_t channels, float *scratch);
void wenv_haar2d_inverse(float *data, size_t n, size_t channels, float *scratch);

/* Coefficients of the transform of a unit impulse at pixel (col, row): 3 log2(n) + 1 of them.
 * Writes indices and values; returns their count. */
size_t wenv_haar2d_impulse(size_t n, size_t col, size_t row, size_t *idx, float *val);

#endif
