#include "octfilter.h"

#include <omp.h>
#include <stdint.h>
#include <stdlib.h>

#include "maps.h"

static void supersample_texel(const wenv_envmap *env, size_t side, size_t t, float *rgb)
{
    const size_t k = 4;
    double h = 2.0 / (double)side, acc[3] = {0, 0, 0};
    for (size_t q = 0; q < k * k; q++) {
        double d[3];
        float c[3];
        wenv_oct_decode(-1.0 + h * ((double)(t % side) + ((double)(q % k) + 0.5) / (double)k),
                        -1.0 + h * ((double)(t / side) + ((double)(q / k) + 0.5) / (double)k), d);
        wenv_envmap_lookup(env, d, c);
        for (int i = 0; i < 3; i++)
            acc[i] += c[i];
    }
    for (int i = 0; i < 3; i++)
        rgb[i] = (float)(acc[i] / (double)(k * k));
}

wenv_status wenv_oct_from_envmap(const wenv_envmap *env, size_t side, float *texels, wenv_error *err)
{
    size_t nt = side * side, npix = wenv_envmap_width(env) * wenv_envmap_height(env);
    if (npix < 2 * nt) {
#pragma omp parallel for schedule(dynamic, 64)
        for (size_t t = 0; t < nt; t++)
            supersample_texel(env, side, t, texels + 3 * t);
        return WENV_OK;
    }
    int threads = omp_get_max_threads();
    size_t w = wenv_envmap_width(env), h = wenv_envmap_height(env);
    /* One accumulator per thread, and each image row sampled into a small per-thread buffer and
     * splatted at once: this runs over every pixel at each lighting change, and materialising
     * every pixel's sample would stream tens of megabytes through memory. */
    double *acc = calloc((size_t)threads * nt * 4, sizeof(double));
    if (!acc)
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory filtering the environment");
    int failed = 0;
#pragma omp parallel num_threads(threads) reduction(| : failed)
    {
        double *mine = acc + (size_t)omp_get_thread_num() * nt * 4;
        float *dirs = malloc(w * 7 * sizeof(float)), *flux = dirs + 3 * w, *omega = dirs + 6 * w;
        failed = dirs == NULL;
#pragma omp for schedule(static)
        for (size_t row = 0; row < h; row++) {
            if (!dirs)
                continue;
            size_t count = wenv_envmap_row_samples(env, row, dirs, flux, omega);
            for (size_t p = 0; p < count; p++) {
                float u, v, wt[4];
                uint32_t idx[4];
                wenv_oct_encode_f(dirs + 3 * p, &u, &v);
                wenv_oct_bilinear_f((long)side, u, v, idx, wt);
                for (int c = 0; c < 4; c++) {
                    double *a = mine + 4 * (size_t)idx[c];
                    a[0] += (double)wt[c] * flux[3 * p];
                    a[1] += (double)wt[c] * flux[3 * p + 1];
                    a[2] += (double)wt[c] * flux[3 * p + 2];
                    a[3] += (double)wt[c] * omega[p];
                }
            }
        }
        free(dirs);
    }
    if (failed) {
        free(acc);
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory filtering the environment");
    }
    for (int t = 1; t < threads; t++)
        for (size_t e = 0; e < nt * 4; e++)
            acc[e] += acc[(size_t)t * nt * 4 + e];
#pragma omp parallel for schedule(dynamic, 64)
    for (size_t t = 0; t < nt; t++) {
        if (acc[4 * t + 3] > 0.0) {
            for (int c = 0; c < 3; c++)
                texels[3 * t + c] = (float)(acc[4 * t + c] / acc[4 * t + 3]);
        } else {
            supersample_texel(env, side, t, texels + 3 * t);
        }
    }
    free(acc);
    return WENV_OK;
}
