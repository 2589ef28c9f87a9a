#include "autoquality.h"

#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "maps.h"
#include "sh.h"


/* global, local, normals, views, coefficients, light_coefficients (0: all, slicing keeps every
 * term anyway), matrix_epsilon (unused by slicing), lights, light_threshold, grazing */
static const wenv_quality LADDER[WENV_AUTO_LEVELS] = {
    {32, 16, 16, 8, 64, 0, 1e-3, 64, 256, 0},
    {64, 32, 32, 16, 128, 0, 1e-3, 128, 256, 0},
    {128, 64, 32, 16, 256, 0, 1e-4, 512, 256, 0},
    {128, 64, 64, 32, 512, 0, 1e-4, 1024, 256, 0},
};

/* Median relative RMSE over the bundled HDRIs per level (rows) at roughness 0.05, 0.1, 0.2, 0.5
 * and for Lambert (last column), from examples/auto_quality.py --calibrate. */
static const double ROUGHNESS[4] = {0.05, 0.1, 0.2, 0.5};
static const double MEDIAN_ERROR[WENV_AUTO_LEVELS][5] = {
    {0.33261, 0.17655, 0.11943, 0.07144, 0.01686},
    {0.15948, 0.08371, 0.04078, 0.02345, 0.00470},
    {0.12508, 0.04692, 0.02797, 0.01540, 0.00339},
    {0.07568, 0.02614, 0.01426, 0.00728, 0.00136},
};
/* Error factor of an environment: MARGIN ((1 - l) + SLOPE c) with l the share of its flux shaded
 * as exact lights (no error of their own, so the relative error of the rest shrinks by 1 - l) and c
 * its contrast; fitted to the eight bundled HDRIs' errors relative to their median
 * (examples/auto_quality.py), MARGIN so that few are underestimated. */
#define CONTRAST_SLOPE 4.0
#define CONTRAST_MARGIN 1.2

const wenv_quality *wenv_auto_level(size_t i)
{
    return i < WENV_AUTO_LEVELS ? &LADDER[i] : NULL;
}

size_t wenv_auto_level_bytes(size_t i, size_t used_normals)
{
    const wenv_quality *q = &LADDER[i];
    size_t ns = q->normal_n * q->normal_n, nv = (q->view_n + 1) * (q->view_n + 1), nl = q->local_n * q->local_n;
    size_t ng = q->global_n * q->global_n, made = used_normals < ns ? used_normals : ns;
    size_t table = ns * nv * (3 * sizeof(float) + 2);         /* radiance and two flags per pair */
    size_t slices = made * nl * 3 * sizeof(float) + ns * (3 + 12) * sizeof(float); /* + irradiance, frames */
    size_t brdf = nv * q->coefficients * 4 * sizeof(float);  /* index and RGB per kept term */
    return table + slices + brdf + ng * 3 * sizeof(float);
}

/* Fraction of the environment's flux held by pixels brighter than CONTRAST_FACTOR times its mean
 * radiance, once the brightest pixels (those a shader takes out as exact lights) are out: bright,
 * extended, hard-edged features -- softboxes, sunlit walls, sky through leaves -- that neither the
 * lights nor a wavelet map of a few degrees per texel resolve.  On the bundled HDRIs: studio 0.70,
 * courtyard 0.33, forest 0.16 (2 - 5 times the median error at every level), interior 0.09, night,
 * sunrise, city and sunset 0.002 - 0.03 (0.3 - 1 times). */
#define CONTRAST_FACTOR 16.0
static wenv_status contrast(const wenv_envmap *env, double *out, double *lights_share, wenv_error *err)
{
    const size_t k = LADDER[1].lights;
    size_t w = wenv_envmap_width(env), h = wenv_envmap_height(env);
    wenv_bright_pixel *bright = malloc(k * sizeof *bright);
    if (!bright)
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory estimating the environment");
    size_t nb = wenv_envmap_brightest(env, k, LADDER[1].light_threshold, bright);
    /* flux with strength applied throughout, as the lights' own fluxes are */
    double total = wenv_envmap_flux(env), strength = wenv_envmap_strength(env);
    if (!(total > 0.0)) { /* black (or zero strength): nothing is hard */
        free(bright);
        *out = *lights_share = 0.0;
        return WENV_OK;
    }
    double cut = CONTRAST_FACTOR * total / (4.0 * M_PI) / strength;
    const float *px = wenv_envmap_pixels(env);
    double bright_flux = 0.0;
    for (size_t row = 0; row < h; row++)
        for (size_t col = 0; col < w; col++) {
            const float *p = px + 3 * (row * w + col);
            if (p[0] > cut || p[1] > cut || p[2] > cut)
                bright_flux += wenv_envmap_pixel_solid_angle(env, row, col) * ((double)p[0] + p[1] + p[2]) / 3.0;
        }
    bright_flux *= strength;
    double light_flux = 0.0; /* the lights are shaded exactly */
    for (size_t i = 0; i < nb; i++)
        light_flux += ((double)bright[i].flux[0] + bright[i].flux[1] + bright[i].flux[2]) / 3.0;
    free(bright);
    *out = total > 0.0 ? fmin(1.0, fmax(0.0, (bright_flux - light_flux) / total)) : 0.0;
    *lights_share = total > 0.0 ? fmin(1.0, fmax(0.0, light_flux / total)) : 0.0;
    return WENV_OK;
}

/* Measured error of a level for a material: Lambert's column without lobes, else the narrowest
 * lobe's roughness, interpolated linearly in log roughness and clamped to the measured range. */
static double level_error(size_t level, const wenv_material *mat)
{
    const double *e = MEDIAN_ERROR[level];
    if (!mat->n_lobes)
        return e[4];
    double m = mat->lobes[0].roughness;
    for (size_t l = 1; l < mat->n_lobes; l++)
        m = fmin(m, mat->lobes[l].roughness);
    if (m <= ROUGHNESS[0])
        return e[0];
    if (m >= ROUGHNESS[3])
        return e[3];
    size_t i = 0;
    while (m > ROUGHNESS[i + 1])
        i++;
    double t = log(m / ROUGHNESS[i]) / log(ROUGHNESS[i + 1] / ROUGHNESS[i]);
    return exp((1.0 - t) * log(e[i]) + t * log(e[i + 1]));
}

/* Memory of method "sh" for a material without lobes: lighting coefficients and the irradiance table. */
static size_t sh_bytes(size_t order)
{
    return wenv_sh_count(order) * 3 * sizeof(double) + 128 * 128 * 3 * sizeof(float);
}

/* Normal samples of an n_side grid that the normals' bilinear taps reach ((size_t)-1 without
 * normals or memory to count them). */
static size_t used_normal_samples(size_t n_side, const float *normals, size_t n)
{
    if (!normals)
        return (size_t)-1;
    unsigned char *hit = calloc(n_side * n_side, 1);
    if (!hit)
        return (size_t)-1;
    size_t used = 0;
    for (size_t i = 0; i < n; i++) {
        const float *d = normals + 3 * i;
        float len = sqrtf(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]), u, v, w[4];
        if (!(len > 0.0f))
            continue;
        float unit[3] = {d[0] / len, d[1] / len, d[2] / len};
        uint32_t idx[4];
        wenv_oct_encode_f(unit, &u, &v);
        wenv_oct_bilinear_f((long)n_side, u, v, idx, w);
        for (int k = 0; k < 4; k++)
            if (w[k] > 0.0f && !hit[idx[k]]) {
                hit[idx[k]] = 1;
                used++;
            }
    }
    free(hit);
    return used;
}

const size_t WENV_AUTO_SH_ORDERS[WENV_AUTO_SH_ORDER_COUNT] = {2, 4, 6, 8, 10, 12, 14, 16};

/* Band of the spectrum estimate; beyond it the power A_l^2 P_l is taken to fall as l^-4, as a lone
 * sun's does (A_l^2 ~ l^-5, P_l ~ 2l + 1), which bounds every non-negative lighting. */
#define SH_ESTIMATE_ORDER 20
#define SH_TAIL_FACTOR 2.9 /* sum over even l > 20 of (20 / l)^4 */
/* Measured errors on the bundled HDRIs (examples/auto_quality.py) are 0.75 - 0.95 times the
 * estimate down to 0.3 %; below, a floor of a few 0.01 % (the irradiance table, the reference's own
 * pixel sums) shows. */
#define SH_ERROR_MARGIN 1.0
#define SH_ERROR_FLOOR 5e-4

static int sh_band_power(const wenv_envmap *env, const double albedo[3], double *power)
{
    size_t count = wenv_sh_count(SH_ESTIMATE_ORDER);
    double *c = malloc(count * 3 * sizeof(double));
    if (!c)
        return -1;
    wenv_error err = {0};
    /* a coarse projection: the estimate needs each band's power, not its coefficients exactly */
    if (wenv_sh_project_envmap_blocks(env, SH_ESTIMATE_ORDER, wenv_sh_projection_block(env, SH_ESTIMATE_ORDER / 2),
                                      c, NULL, &err)) {
        free(c);
        return -1;
    }
    for (size_t l = 0; l <= SH_ESTIMATE_ORDER; l++) {
        double a = wenv_sh_lambert_factor(l), p = 0.0;
        for (size_t i = l * l; i < (l + 1) * (l + 1); i++)
            for (int ch = 0; ch < 3; ch++)
                p += albedo[ch] * albedo[ch] * c[3 * i + ch] * c[3 * i + ch];
        power[l] = a * a * p;
    }
    free(c);
    return 0;
}

static double sh_error_from_power(const double *power, size_t order)
{
    double beyond = SH_TAIL_FACTOR * power[SH_ESTIMATE_ORDER], total = beyond, tail = beyond;
    for (size_t l = 0; l <= SH_ESTIMATE_ORDER; l++) {
        total += power[l];
        if (l > order)
            tail += power[l];
    }
    return total > 0.0 ? SH_ERROR_MARGIN * sqrt(tail / total) + SH_ERROR_FLOOR : 0.0;
}

wenv_status wenv_auto_choose(const wenv_envmap *env, const wenv_material *mat, double target, size_t memory_budget,
                             const float *normals, size_t n, wenv_auto_choice *out, wenv_error *err)
{
    memset(out, 0, sizeof *out);
    if (!(target > 0.0 && target <= 1.0))
        return wenv_error_set(err, WENV_ERR_VALUE, "target_error must be in (0, 1], got %g", target);
    if (!mat->n_lobes) {
        double power[SH_ESTIMATE_ORDER + 1];
        if (sh_band_power(env, mat->diffuse, power) < 0)
            return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory estimating the environment");
        for (size_t i = 0; i < WENV_AUTO_SH_ORDER_COUNT; i++) {
            double e = sh_error_from_power(power, WENV_AUTO_SH_ORDERS[i]);
            if (e <= target && sh_bytes(WENV_AUTO_SH_ORDERS[i]) <= memory_budget) {
                out->sh_order = WENV_AUTO_SH_ORDERS[i];
                out->predicted_error = e;
                out->met = 1;
                out->level_bytes = sh_bytes(out->sh_order);
                return WENV_OK;
            }
        }
    }
    size_t used[WENV_AUTO_LEVELS];
    for (size_t i = 0; i < WENV_AUTO_LEVELS; i++)
        used[i] = used_normal_samples(LADDER[i].normal_n, normals, n);
    if (wenv_auto_level_bytes(0, used[0]) > memory_budget)
        return wenv_error_set(err, WENV_ERR_VALUE, "memory_budget of %zu bytes is below the cheapest setting's %zu",
                              memory_budget, wenv_auto_level_bytes(0, used[0]));
    if (contrast(env, &out->contrast, &out->lights_share, err))
        return err->status;
    out->env_factor = fmin(8.0, CONTRAST_MARGIN * ((1.0 - out->lights_share) + CONTRAST_SLOPE * out->contrast));
    size_t best = 0;
    for (size_t i = 0; i < WENV_AUTO_LEVELS && wenv_auto_level_bytes(i, used[i]) <= memory_budget; i++) {
        best = i;
        if (level_error(i, mat) * out->env_factor <= target) {
            out->met = 1;
            break;
        }
    }
    out->level = best;
    out->quality = LADDER[best];
    out->used_normals = used[best];
    out->level_bytes = wenv_auto_level_bytes(best, used[best]);
    out->predicted_error = level_error(best, mat) * out->env_factor;
    return WENV_OK;
}
