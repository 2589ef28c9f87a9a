#include "reference/reference.h"

#include <math.h>
#include <omp.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>

#include "math/frame.h"

#define BLOCK 2048

wenv_status wenv_reference(const wenv_envmap *env, const wenv_material *mat, const float *normals,
                           const float *views, size_t n, float *out, const wenv_progress *progress,
                           wenv_error *err)
{
    const double *diffuse = wenv_material_diffuse(mat);
    int has_lobes = wenv_material_lobe_count(mat) > 0;
    size_t npix = wenv_envmap_width(env) * wenv_envmap_height(env);
    float *dirs = malloc(npix * 3 * sizeof(float));
    float *flux = malloc(npix * 3 * sizeof(float));
    if (!dirs || !flux) {
        free(dirs);
        free(flux);
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for the reference");
    }
    size_t count = wenv_envmap_samples(env, dirs, flux, NULL);
    atomic_int failed = 0, cancelled = 0;
    atomic_size_t done = 0;
#pragma omp parallel
    {
        float *wi = malloc(BLOCK * 3 * sizeof(float));
        float *fl = malloc(BLOCK * 3 * sizeof(float));
        float *fcos = malloc(BLOCK * 3 * sizeof(float));
        if (!wi || !fl || !fcos)
            atomic_store(&failed, 1);
#pragma omp for schedule(dynamic, 1)
        for (size_t i = 0; i < n; i++) {
            if (atomic_load(&failed) || atomic_load(&cancelled))
                continue;
            double nn[3] = {normals[3 * i], normals[3 * i + 1], normals[3 * i + 2]};
            double vv[3] = {views[3 * i], views[3 * i + 1], views[3 * i + 2]};
            double ln = sqrt(nn[0] * nn[0] + nn[1] * nn[1] + nn[2] * nn[2]);
            double lv = sqrt(vv[0] * vv[0] + vv[1] * vv[1] + vv[2] * vv[2]);
            for (int c = 0; c < 3; c++) {
                nn[c] /= ln;
                vv[c] /= lv;
            }
            double f[9];
            wenv_frame(nn, f);
            double wo[3] = {f[0] * vv[0] + f[1] * vv[1] + f[2] * vv[2], f[3] * vv[0] + f[4] * vv[1] + f[5] * vv[2],
                            f[6] * vv[0] + f[7] * vv[1] + f[8] * vv[2]};
            double spec[3] = {0, 0, 0}, irr[3] = {0, 0, 0};
            if (wo[2] > 0.0) {
                size_t fill = 0;
                for (size_t p = 0; p <= count; p++) {
                    if (p < count) {
                        const float *d = dirs + 3 * p;
                        float z = (float)f[6] * d[0] + (float)f[7] * d[1] + (float)f[8] * d[2];
                        if (z <= 0.0f)
                            continue;
                        float *w = wi + 3 * fill;
                        w[0] = (float)f[0] * d[0] + (float)f[1] * d[1] + (float)f[2] * d[2];
                        w[1] = (float)f[3] * d[0] + (float)f[4] * d[1] + (float)f[5] * d[2];
                        w[2] = z;
                        memcpy(fl + 3 * fill, flux + 3 * p, 3 * sizeof(float));
                        irr[0] += (double)z * flux[3 * p];
                        irr[1] += (double)z * flux[3 * p + 1];
                        irr[2] += (double)z * flux[3 * p + 2];
                        if (++fill < BLOCK)
                            continue;
                    }
                    if (fill && has_lobes) {
                        wenv_material_specular_cos_batch(mat, wo, wi, fill, fcos);
                        for (size_t q = 0; q < fill; q++)
                            for (int c = 0; c < 3; c++)
                                spec[c] += (double)fcos[3 * q + c] * fl[3 * q + c];
                    }
                    fill = 0;
                }
            }
            for (int c = 0; c < 3; c++)
                out[3 * i + c] = (float)(spec[c] + irr[c] * diffuse[c] / M_PI);
            size_t d = atomic_fetch_add(&done, 1) + 1;
            if (omp_get_thread_num() == 0 && progress && progress->report &&
                progress->report(progress->ctx, (double)d / (double)n))
                atomic_store(&cancelled, 1);
        }
        free(wi);
        free(fl);
        free(fcos);
    }
    free(dirs);
    free(flux);
    if (failed)
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for the reference");
    if (cancelled)
        return wenv_error_set(err, WENV_ERR_CANCELLED, "reference cancelled");
    return WENV_OK;
}
