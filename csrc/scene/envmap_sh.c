#include "scene/envmap_sh.h"

#include <math.h>
#include <omp.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>

size_t wenv_sh_projection_block(const wenv_envmap *env, size_t order)
{
    /* pixel side from the mean solid angle; a block spans at most pi / (8 order), an eighth of
     * band `order`'s half wavelength: the point rule then errs by about (pi / 8)^2 / 12 = 1.3 % in
     * the top band's coefficients and by (l / order)^2 of that in band l */
    double pixel = sqrt(4.0 * M_PI / (double)(wenv_envmap_width(env) * wenv_envmap_height(env)));
    double side = M_PI / (8.0 * (double)(order ? order : 1)) / pixel;
    if (side < 1.0)
        return 1;
    return side > (double)WENV_SH_BLOCK_MAX ? WENV_SH_BLOCK_MAX : (size_t)side;
}

wenv_status wenv_sh_project_envmap_blocks(const wenv_envmap *env, size_t order, size_t block, double *coeffs,
                                          const wenv_progress *progress, wenv_error *err)
{
    size_t count = wenv_sh_count(order), w = wenv_envmap_width(env), h = wenv_envmap_height(env);
    if (block < 1)
        block = 1;
    size_t strips = (h + block - 1) / block, cells = (w + block - 1) / block;
    memset(coeffs, 0, count * 3 * sizeof(double));
    atomic_int failed = 0, cancelled = 0;
    atomic_size_t done = 0;
#pragma omp parallel
    {
        double *acc = calloc(count * 3, sizeof(double));
        double *y = malloc(count * sizeof(double));
        float *dirs = malloc(w * 3 * sizeof(float)), *flux = malloc(w * 3 * sizeof(float));
        uint32_t *cols = malloc(w * sizeof(uint32_t));
        double *cell = malloc(cells * 9 * sizeof(double)); /* per block: flux RGB, flux-weighted dir, area-weighted dir */
        float *omega = malloc(w * sizeof(float));
        if (!acc || !y || !dirs || !flux || !cols || !cell || !omega)
            atomic_store(&failed, 1);
#pragma omp for schedule(dynamic, 1)
        for (size_t s = 0; s < strips; s++) {
            if (atomic_load(&failed) || atomic_load(&cancelled))
                continue;
            memset(cell, 0, cells * 9 * sizeof(double));
            size_t end = (s + 1) * block < h ? (s + 1) * block : h;
            for (size_t row = s * block; row < end; row++) {
                size_t n = wenv_envmap_row_samples(env, row, dirs, flux, omega, cols);
                for (size_t p = 0; p < n; p++) {
                    const float *f = flux + 3 * p, *d = dirs + 3 * p;
                    double *c = cell + 9 * (cols[p] / block);
                    double wgt = fabs((double)f[0]) + fabs((double)f[1]) + fabs((double)f[2]);
                    for (int k = 0; k < 3; k++) {
                        c[k] += f[k];
                        c[3 + k] += wgt * d[k];
                        c[6 + k] += omega[p] * d[k];
                    }
                }
            }
            /* A block's flux at its flux-weighted mean direction: exact for a lone bright pixel (a
             * sun keeps its place), second order in the spread of the flux otherwise. */
            for (size_t b = 0; b < cells; b++) {
                const double *c = cell + 9 * b;
                if (c[0] == 0.0 && c[1] == 0.0 && c[2] == 0.0)
                    continue;
                const double *m = (c[3] != 0.0 || c[4] != 0.0 || c[5] != 0.0) ? c + 3 : c + 6;
                double len = sqrt(m[0] * m[0] + m[1] * m[1] + m[2] * m[2]);
                if (!(len > 0.0))
                    continue;
                double d[3] = {m[0] / len, m[1] / len, m[2] / len};
                wenv_sh_eval(order, d, y);
                for (size_t i = 0; i < count; i++) {
                    acc[3 * i] += y[i] * c[0];
                    acc[3 * i + 1] += y[i] * c[1];
                    acc[3 * i + 2] += y[i] * c[2];
                }
            }
            size_t dn = atomic_fetch_add(&done, 1) + 1;
            if (wenv_progress_step(progress, dn, strips))
                atomic_store(&cancelled, 1);
        }
        if (!atomic_load(&failed)) {
#pragma omp critical(wenv_sh_project)
            for (size_t i = 0; i < 3 * count; i++)
                coeffs[i] += acc[i];
        }
        free(acc);
        free(y);
        free(dirs);
        free(flux);
        free(cols);
        free(cell);
        free(omega);
    }
    if (failed)
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory projecting the environment");
    /* the last strip may have been another thread's: report completion (and honour a stop) here */
    if (cancelled || wenv_progress_finish(progress))
        return wenv_error_set(err, WENV_ERR_CANCELLED, "projection of the environment cancelled");
    return WENV_OK;
}

wenv_status wenv_sh_project_envmap(const wenv_envmap *env, size_t order, double *coeffs,
                                   const wenv_progress *progress, wenv_error *err)
{
    return wenv_sh_project_envmap_blocks(env, order, wenv_sh_projection_block(env, order), coeffs, progress, err);
}
