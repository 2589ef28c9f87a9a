/* Values per face corner at barycentric points (corner_interpolation.h): one pass, where numpy's
 * three gathers, products and sums made nine over a million points' arrays.  The sums keep numpy's
 * order and precision, so a bake reads the same values to the bit. */
#include "bake/corner_interpolation.h"

/* values_d or values_f (the other NULL): the rows' type sets the arithmetic's */
static wenv_status interpolate(const double *values_d, const float *values_f, size_t n_values, size_t k,
                               const int64_t *corners, const float *weights, size_t n, float *out, wenv_error *err)
{
    long long count = (long long)n, bad = -1;
#pragma omp parallel for schedule(static) reduction(max : bad)
    for (long long i = 0; i < count; i++)
        for (int j = 0; j < 3; j++)
            if (corners[3 * i + j] < 0 || (uint64_t)corners[3 * i + j] >= n_values)
                bad = i;
    if (bad >= 0)
        return wenv_error_set(err, WENV_ERR_VALUE, "corners[%lld] names a row past the %zu values", bad, n_values);
#pragma omp parallel for schedule(static)
    for (long long i = 0; i < count; i++) {
        const int64_t *c = corners + 3 * i;
        const float *w = weights + 3 * i;
        size_t a = (size_t)c[0] * k, b = (size_t)c[1] * k, d = (size_t)c[2] * k;
        for (size_t m = 0; m < k; m++)
            out[(size_t)i * k + m] =
                values_f ? w[0] * values_f[a + m] + w[1] * values_f[b + m] + w[2] * values_f[d + m]
                         : (float)((double)w[0] * values_d[a + m] + (double)w[1] * values_d[b + m] +
                                   (double)w[2] * values_d[d + m]);
    }
    return WENV_OK;
}

wenv_status wenv_corner_interpolate(const double *values, size_t n_values, size_t k, const int64_t *corners,
                                    const float *weights, size_t n, float *out, wenv_error *err)
{
    return interpolate(values, NULL, n_values, k, corners, weights, n, out, err);
}

wenv_status wenv_corner_interpolate_f(const float *values_f, size_t n_values, size_t k, const int64_t *corners,
                                      const float *weights, size_t n, float *out, wenv_error *err)
{
    return interpolate(NULL, values_f, n_values, k, corners, weights, n, out, err);
}
