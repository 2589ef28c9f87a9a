#include "methods/wavelet/irradiance.h"

#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "math/maps.h"
#include "math/vector_math.h"

/* A finer map is summed in blocks onto this side: a 64 x 64 texel spans about 3 degrees, over which
 * the cosine's own change is second order (~1e-4 of the irradiance). */
#define SIDE_MAX 64

/* 16 texels at a time: one AVX-512 register, two AVX2 ones (the map's side is a power of two of
 * at least 4, so its texels come in whole vectors) */
typedef float texel_vec __attribute__((vector_size(16 * sizeof(float))));
typedef int32_t texel_mask __attribute__((vector_size(16 * sizeof(int32_t))));

struct wenv_irradiance_rule {
    size_t global_n, side, factor; /* factor x factor global texels make one summed texel */
    float *x, *y, *z;              /* side^2 each: the summed texels' centre directions */
    float *omega;                  /* side^2: their solid angles */
    float *fine_omega;             /* global_n^2: the global texels' solid angles */
};

void wenv_irradiance_rule_free(wenv_irradiance_rule *rule)
{
    if (!rule)
        return;
    free(rule->x);
    free(rule->omega);
    free(rule->fine_omega);
    free(rule);
}

wenv_status wenv_irradiance_rule_create(wenv_irradiance_rule **out, size_t global_n, wenv_error *err)
{
    *out = NULL;
    wenv_irradiance_rule *rule = calloc(1, sizeof *rule);
    size_t side = global_n < SIDE_MAX ? global_n : SIDE_MAX, n = side * side, ng = global_n * global_n;
    double *fine = malloc(ng * sizeof(double));
    if (rule) {
        /* aligned as the vector type (a multiple of 16 floats each) */
        rule->x = aligned_alloc(sizeof(texel_vec), n * 3 * sizeof(float));
        rule->omega = aligned_alloc(sizeof(texel_vec), n * sizeof(float));
        rule->fine_omega = malloc(ng * sizeof(float));
    }
    if (!rule || !fine || !rule->x || !rule->omega || !rule->fine_omega) {
        free(fine);
        wenv_irradiance_rule_free(rule);
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for the irradiance rule");
    }
    memset(rule->omega, 0, n * sizeof(float));
    rule->global_n = global_n;
    rule->side = side;
    rule->factor = global_n / side;
    rule->y = rule->x + n;
    rule->z = rule->y + n;
    wenv_oct_texel_solid_angles(global_n, fine);
    for (size_t t = 0; t < ng; t++) {
        size_t coarse = (t / global_n / rule->factor) * side + (t % global_n) / rule->factor;
        rule->fine_omega[t] = (float)fine[t];
        rule->omega[coarse] += (float)fine[t];
    }
    free(fine);
    for (size_t t = 0; t < n; t++) {
        double d[3];
        wenv_oct_decode(wenv_map_texel_center(side, t % side), wenv_map_texel_center(side, t / side), d);
        rule->x[t] = (float)d[0];
        rule->y[t] = (float)d[1];
        rule->z[t] = (float)d[2];
    }
    *out = rule;
    return WENV_OK;
}

/* pi x the cosine-weighted mean of the map's radiance over the hemisphere about n; flux holds the
 * summed texels' solid angle x radiance, channel after channel. */
WENV_VECTOR_CLONES
static void irradiance_at(const wenv_irradiance_rule *rule, const float *flux, const float *n, float out[3])
{
    size_t vecs = rule->side * rule->side / 16;
    const texel_vec *x = (const texel_vec *)rule->x, *y = (const texel_vec *)rule->y, *z = (const texel_vec *)rule->z;
    const texel_vec *omega = (const texel_vec *)rule->omega, *fr = (const texel_vec *)flux, *fg = fr + vecs,
                    *fb = fg + vecs;
    float nx = n[0], ny = n[1], nz = n[2];
    texel_vec er = {0}, eg = {0}, eb = {0}, w = {0}, zero = {0};
    for (size_t t = 0; t < vecs; t++) {
        texel_vec c = nx * x[t] + ny * y[t] + nz * z[t];
        c = (texel_vec)((texel_mask)c & (c > zero)); /* below the horizon: 0 */
        er += c * fr[t];
        eg += c * fg[t];
        eb += c * fb[t];
        w += c * omega[t];
    }
    float sum[4] = {0.0f, 0.0f, 0.0f, 0.0f};
    for (int k = 0; k < 16; k++) {
        sum[0] += er[k];
        sum[1] += eg[k];
        sum[2] += eb[k];
        sum[3] += w[k];
    }
    float scale = sum[3] > 0.0f ? (float)M_PI / sum[3] : 0.0f;
    for (int c = 0; c < 3; c++)
        out[c] = sum[c] * scale;
}

wenv_status wenv_irradiance_compute(const wenv_irradiance_rule *rule, const float *texels, const float *normals,
                                    size_t stride, size_t n, float *out, wenv_error *err)
{
    size_t side = rule->side, count = side * side, G = rule->global_n, f = rule->factor;
    float *flux = aligned_alloc(sizeof(texel_vec), 3 * count * sizeof(float));
    if (!flux)
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for the irradiance");
    memset(flux, 0, 3 * count * sizeof(float));
    for (size_t t = 0; t < G * G; t++) {
        size_t coarse = (t / G / f) * side + (t % G) / f;
        for (int c = 0; c < 3; c++)
            flux[c * count + coarse] += rule->fine_omega[t] * texels[3 * t + c];
    }
    long long nn = (long long)n;
#pragma omp parallel for schedule(static) if (n > 16)
    for (long long s = 0; s < nn; s++)
        irradiance_at(rule, flux, normals + (size_t)s * stride, out + 3 * (size_t)s);
    free(flux);
    return WENV_OK;
}
