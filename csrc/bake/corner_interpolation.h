/* Values given per face corner, read at points inside (or just outside) a triangle by their
 * barycentric weights: what a bake reads at each texel (positions, normals, UVs, tangents). */
#ifndef WENV_CORNER_INTERPOLATION_H
#define WENV_CORNER_INTERPOLATION_H

#include <stddef.h>
#include <stdint.h>

#include "base/error.h"

/* out[i * k + c] = w0 v[c0][c] + w1 v[c1][c] + w2 v[c2][c] for each of n points, summed in that
 * order as numpy sums its arrays' terms: `values` is n_values rows of k doubles, each term and sum
 * in double and the point's value rounded to float; `values_f` of floats, every term and sum in
 * float.  `corners` holds the 3 rows of each point, `weights` its 3 weights.  ValueError for a
 * corner that is not a row of the values. */
wenv_status wenv_corner_interpolate(const double *values, size_t n_values, size_t k, const int64_t *corners,
                                    const float *weights, size_t n, float *out, wenv_error *err);
wenv_status wenv_corner_interpolate_f(const float *values_f, size_t n_values, size_t k, const int64_t *corners,
                                      const float *weights, size_t n, float *out, wenv_error *err);

#endif
