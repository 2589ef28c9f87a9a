#include "scene/envmap_sh.h"

#include <math.h>
#include <omp.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>

/* groups of strips summed apart (see below): enough to share among many threads */
#define SUM_GROUPS 64

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

/* One thread's buffers for a strip of image rows. */
typedef struct {
    double *y;     /* count */
    float *dirs;   /* w x 3 */
    float *flux;   /* w x 3 */
    float *omega;  /* w */
    uint32_t *cols;
    double *cell;  /* per block: flux RGB, flux-weighted direction, area-weighted direction */
} strip_scratch;

/* acc += strip s's blocks, each block's flux at its direction. */
static void project_strip(const wenv_envmap *env, size_t order, size_t block, size_t s, size_t cells,
                          strip_scratch *t, double *acc)
{
    size_t count = wenv_sh_count(order), h = wenv_envmap_height(env);
    memset(t->cell, 0, cells * 9 * sizeof(double));
    size_t end = (s + 1) * block < h ? (s + 1) * block : h;
    for (size_t row = s * block; row < end; row++) {
        size_t n = wenv_envmap_row_samples(env, row, t->dirs, t->flux, t->omega, t->cols);
        for (size_t p = 0; p < n; p++) {
            const float *f = t->flux + 3 * p, *d = t->dirs + 3 * p;
            double *c = t->cell + 9 * (t->cols[p] / block);
            double wgt = fabs((double)f[0]) + fabs((double)f[1]) + fabs((double)f[2]);
            for (int k = 0; k < 3; k++) {
                c[k] += f[k];
                c[3 + k] += wgt * d[k];
                c[6 + k] += t->omega[p] * d[k];
            }
        }
    }
    /* A block's flux at its flux-weighted mean direction: exact for a lone bright pixel (a sun
     * keeps its place), second order in the spread of the flux otherwise. */
    for (size_t b = 0; b < cells; b++) {
        const double *c = t->cell + 9 * b;
        if (c[0] == 0.0 && c[1] == 0.0 && c[2] == 0.0)
            continue;
        const double *m = (c[3] != 0.0 || c[4] != 0.0 || c[5] != 0.0) ? c + 3 : c + 6;
        double len = sqrt(m[0] * m[0] + m[1] * m[1] + m[2] * m[2]);
        if (!(len > 0.0))
            continue;
        double d[3] = {m[0] / len, m[1] / len, m[2] / len};
        wenv_sh_eval(order, d, t->y);
        for (size_t i = 0; i < count; i++) {
            acc[3 * i] += t->y[i] * c[0];
            acc[3 * i + 1] += t->y[i] * c[1];
            acc[3 * i + 2] += t->y[i] * c[2];
        }
    }
}

wenv_status wenv_sh_project_envmap_blocks(const wenv_envmap *env, size_t order, size_t block, double *coeffs,
                                          const wenv_progress *progress, wenv_error *err)
{
    size_t count = wenv_sh_count(order), w = wenv_envmap_width(env), h = wenv_envmap_height(env);
    if (block < 1)
        block = 1;
    size_t strips = (h + block - 1) / block, cells = (w + block - 1) / block;
    /* Strips are summed in a fixed number of groups of consecutive strips, each in strip order,
     * and the groups in order: the coefficients do not depend on how many threads ran or which
     * finished first. */
    size_t groups = strips < SUM_GROUPS ? strips : SUM_GROUPS;
    double *partial = calloc(groups * count * 3, sizeof(double));
    memset(coeffs, 0, count * 3 * sizeof(double));
    if (!partial)
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory projecting the environment");
    atomic_int failed = 0, cancelled = 0;
    atomic_size_t done = 0;
#pragma omp parallel
    {
        strip_scratch t = {.y = malloc(count * sizeof(double)), .dirs = malloc(w * 3 * sizeof(float)),
                           .flux = malloc(w * 3 * sizeof(float)), .omega = malloc(w * sizeof(float)),
                           .cols = malloc(w * sizeof(uint32_t)), .cell = malloc(cells * 9 * sizeof(double))};
        if (!t.y || !t.dirs || !t.flux || !t.omega || !t.cols || !t.cell)
            atomic_store(&failed, 1);
#pragma omp for schedule(dynamic, 1)
        for (size_t g = 0; g < groups; g++) {
            for (size_t s = g * strips / groups; s < (g + 1) * strips / groups; s++) {
                if (atomic_load(&failed) || atomic_load(&cancelled))
                    break;
                project_strip(env, order, block, s, cells, &t, partial + g * count * 3);
                wenv_progress_item(progress, &done, strips, &cancelled);
            }
        }
        free(t.y);
        free(t.dirs);
        free(t.flux);
        free(t.omega);
        free(t.cols);
        free(t.cell);
    }
    for (size_t g = 0; g < groups; g++)
        for (size_t i = 0; i < 3 * count; i++)
            coeffs[i] += partial[g * count * 3 + i];
    free(partial);
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
