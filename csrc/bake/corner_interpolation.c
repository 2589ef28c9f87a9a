/* Values per face corner at barycentric points (corner_interpolation.h): one pass, where numpy's
 * three gathers, products and sums made nine over a million points' arrays. */
#include "bake/corner_interpolation.h"

wenv_status wenv_corner_interpolate(const double *values, size_t n_values, size_t k, const int64_t *corners,
                                    const float *weights, size_t n, float *out, wenv_error *err)
{
    long long count = (long long)n, bad = -1;
#pragma omp parallel for schedule(static) reduction(max : bad)
    for (long long i = 0; i < count; i++) {
        const int64_t *c = corners + 3 * i;
        const float *w = weights + 3 * i;
        int inside = 1;
        for (int j = 0; j < 3; j++)
            inside &= c[j] >= 0 && (uint64_t)c[j] < n_values;
        if (!inside) {
            bad = i > bad ? i : bad;
            continue;
        }
        const double *a = values + (size_t)c[0] * k, *b = values + (size_t)c[1] * k, *d = values + (size_t)c[2] * k;
        for (size_t m = 0; m < k; m++)
            out[(size_t)i * k + m] = (float)((double)w[0] * a[m] + (double)w[1] * b[m] + (double)w[2] * d[m]);
    }
    if (bad >= 0)
        return wenv_error_set(err, WENV_ERR_VALUE, "corners[%lld] names a row past the %zu values", bad, n_values);
    return WENV_OK;
}
