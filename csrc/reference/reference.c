#include "reference/reference.h"

#include <math.h>
#include <omp.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>

#include "math/frame.h"
#include "math/unit_pair.h"

#define BLOCK 2048
/* A lobe narrower than WENV_NARROW_LOBE_PIXELS pixels (2 alpha against twice the pixel's angle) is
 * integrated by its own node rule instead of the pixel sum: at pixel centres alone a lobe of alpha 0.001 (Principled's
 * default coat) falls between them and reads whichever pixel it happens to hit, while from about a
 * pixel wide the centres sample it well (a Gaussian of one pixel's deviation aliases by ~e^-20).  The
 * rule reads the pixel under each node: the same lighting the pixel sum integrates, each pixel's
 * radiance over its area (Cycles' "Closest" interpolation; its default "Linear" blurs the lighting by
 * about a pixel, which a lobe a few pixels wide reflecting a sun of a few pixels tells apart). */
#define NARROW_SAMPLES 192 /* the rule's divisions: 2 x 192^2 nodes over a lobe a few pixels wide */

/* What blocks the lighting, if anything: the scene and the ray's start (the vertex, lifted). */
typedef struct {
    const wenv_occluders *occ;
    float origin[3];
} blocker;

/* Whether the direction d (world, unit) is blocked. */
static int blocked_one(const blocker *b, const double d[3])
{
    if (!b->occ)
        return 0;
    float fd[3] = {(float)d[0], (float)d[1], (float)d[2]};
    unsigned char hit;
    wenv_occluders_test(b->occ, b->origin, fd, 1, INFINITY, &hit);
    return hit;
}

/* Lobe i's reflected radiance at view wo (frame f) by its node rule over the lighting, minus
 * what the pixel sum gave it (the pixels whose half vector lies inside its cone), into acc.  With
 * occluders, a blocked node or pixel brings nothing, in both. */
static wenv_status narrow_lobe(const wenv_envmap *env, const wenv_material *mat, size_t i, const double f[9],
                               const double wo[3], const float *dirs, const float *flux, size_t count, double *nodes,
                               const blocker *b, double acc[3], wenv_error *err)
{
    size_t max = 2 * NARROW_SAMPLES * NARROW_SAMPLES, n = 0;
    double *weights = nodes + 3 * max;
    if (wenv_material_lobe_nodes(mat, i, wo, NARROW_SAMPLES, nodes, weights, &n, err))
        return err->status;
    for (size_t k = 0; k < n; k++) {
        const double *l = nodes + 3 * k;
        double d[3] = {f[0] * l[0] + f[3] * l[1] + f[6] * l[2], f[1] * l[0] + f[4] * l[1] + f[7] * l[2],
                       f[2] * l[0] + f[5] * l[1] + f[8] * l[2]};
        if (blocked_one(b, d))
            continue;
        float L[3];
        wenv_envmap_lookup_nearest(env, d, L);
        for (int c = 0; c < 3; c++)
            acc[c] += weights[3 * k + (size_t)c] * L[c];
    }
    double cut = wenv_material_lobe_cos_h_min(mat, i);
    wenv_lobe_rgb_fn value = wenv_material_lobe_value_fn(mat);
    for (size_t p = 0; p < count; p++) {
        const float *d = dirs + 3 * p;
        double wi[3] = {f[0] * d[0] + f[1] * d[1] + f[2] * d[2], f[3] * d[0] + f[4] * d[1] + f[5] * d[2],
                        f[6] * d[0] + f[7] * d[1] + f[8] * d[2]};
        if (!(wi[2] > 0.0))
            continue;
        double h[3] = {wi[0] + wo[0], wi[1] + wo[1], wi[2] + wo[2]};
        double len = sqrt(h[0] * h[0] + h[1] * h[1] + h[2] * h[2]);
        if (!(len > 0.0) || h[2] / len < cut)
            continue;
        double dw[3] = {d[0], d[1], d[2]};
        if (blocked_one(b, dw))
            continue;
        double v[3];
        value(mat, i, wi, wo, v);
        for (int c = 0; c < 3; c++)
            acc[c] -= v[c] * wi[2] * flux[3 * p + (size_t)c];
    }
    return WENV_OK;
}

wenv_status wenv_reference(const wenv_envmap *env, const wenv_material *mat, const float *normals,
                           const float *views, size_t n, const wenv_occluders *occ, const float *positions,
                           float *out, const wenv_progress *progress, wenv_error *err)
{
    if (occ && !positions)
        return wenv_error_set(err, WENV_ERR_VALUE, "occluders need the vertices' positions");
    for (size_t i = 0; occ && i < n; i++)
        if (!isfinite(positions[3 * i]) || !isfinite(positions[3 * i + 1]) || !isfinite(positions[3 * i + 2]))
            return wenv_error_set(err, WENV_ERR_VALUE, "positions[%zu] is not finite", i);
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
    size_t n_lobes = wenv_material_lobe_count(mat), n_narrow = 0;
    double narrow_alpha = WENV_NARROW_LOBE_PIXELS * wenv_envmap_pixel_angle(env);
    for (size_t l = 0; l < n_lobes; l++)
        n_narrow += wenv_material_lobe(mat, l)->alpha < narrow_alpha;
    atomic_int failed = 0, cancelled = 0;
    atomic_size_t done = 0;
#pragma omp parallel
    {
        float *wi = malloc(BLOCK * 3 * sizeof(float));
        float *fl = malloc(BLOCK * 3 * sizeof(float));
        float *fcos = malloc(BLOCK * 3 * sizeof(float));
        float *wd = occ ? malloc(BLOCK * 3 * sizeof(float)) : NULL;
        unsigned char *hit = occ ? malloc(BLOCK) : NULL;
        double *nodes = n_narrow ? malloc(2 * NARROW_SAMPLES * NARROW_SAMPLES * 6 * sizeof(double)) : NULL;
        if (!wi || !fl || !fcos || (n_narrow && !nodes) || (occ && (!wd || !hit)))
            atomic_store(&failed, 1);
        wenv_error lobe_err = {0};
#pragma omp for schedule(dynamic, 1)
        for (size_t i = 0; i < n; i++) {
            if (atomic_load(&failed) || atomic_load(&cancelled))
                continue;
            double nn[3], vv[3];
            wenv_unit_pair(normals, views, i, nn, vv);
            double f[9];
            wenv_frame(nn, f);
            double wo[3] = {f[0] * vv[0] + f[1] * vv[1] + f[2] * vv[2], f[3] * vv[0] + f[4] * vv[1] + f[5] * vv[2],
                            f[6] * vv[0] + f[7] * vv[1] + f[8] * vv[2]};
            double spec[3] = {0, 0, 0}, irr[3] = {0, 0, 0};
            blocker b = {.occ = occ};
            if (occ) {
                float lift = wenv_occluders_offset(occ);
                for (int c = 0; c < 3; c++)
                    b.origin[c] = positions[3 * i + (size_t)c] + lift * (float)nn[c];
            }
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
                        if (occ)
                            memcpy(wd + 3 * fill, d, 3 * sizeof(float));
                        if (++fill < BLOCK)
                            continue;
                    }
                    if (fill && occ) { /* direct light only: what the scene blocks brings nothing */
                        wenv_occluders_test(occ, b.origin, wd, fill, INFINITY, hit);
                        for (size_t q = 0; q < fill; q++)
                            if (hit[q])
                                memset(fl + 3 * q, 0, 3 * sizeof(float));
                    }
                    for (size_t q = 0; q < fill; q++)
                        for (int c = 0; c < 3; c++)
                            irr[c] += (double)wi[3 * q + 2] * fl[3 * q + (size_t)c];
                    if (fill && has_lobes) {
                        wenv_material_specular_cos_batch(mat, wo, wi, fill, fcos);
                        for (size_t q = 0; q < fill; q++)
                            for (int c = 0; c < 3; c++)
                                spec[c] += (double)fcos[3 * q + c] * fl[3 * q + c];
                    }
                    fill = 0;
                }
            }
            double diffuse[3];
            wenv_material_diffuse_at(mat, wo[2], diffuse);
            for (size_t l = 0; n_narrow && wo[2] > 0.0 && l < n_lobes; l++)
                if (wenv_material_lobe(mat, l)->alpha < narrow_alpha &&
                    narrow_lobe(env, mat, l, f, wo, dirs, flux, count, nodes, &b, spec, &lobe_err))
                    atomic_store(&failed, 1);
            for (int c = 0; c < 3; c++)
                out[3 * i + c] = (float)(spec[c] + irr[c] * diffuse[c] / M_PI);
            wenv_progress_item(progress, &done, n, &cancelled);
        }
        free(wi);
        free(fl);
        free(fcos);
        free(wd);
        free(hit);
        free(nodes);
    }
    free(dirs);
    free(flux);
    if (failed)
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for the reference");
    if (cancelled || wenv_progress_finish(progress))
        return wenv_error_set(err, WENV_ERR_CANCELLED, "reference cancelled");
    return WENV_OK;
}
