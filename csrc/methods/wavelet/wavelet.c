/* The wavelet shader (wavelet.h): settings, creation with its rotation matrices or resampler, and
 * the lighting: global Haar coefficients, exact lights, and the lighting slices they feed. */
#include "methods/wavelet/wavelet_state.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "base/clock.h"
#include "math/haar.h"
#include "math/vector_math.h"
#include "scene/envmap_octahedral.h"

wenv_status wenv_wavelet_quality_check(const wenv_wavelet_quality *q, wenv_error *err)
{
    if (!wenv_is_power_of_two(q->global_n) || q->global_n < 4 || q->global_n > 512)
        return wenv_error_set(err, WENV_ERR_VALUE, "quality['global'] must be a power of two in [4, 512], got %zu", q->global_n);
    if (!wenv_is_power_of_two(q->local_n) || q->local_n < 4 || q->local_n > 256)
        return wenv_error_set(err, WENV_ERR_VALUE, "quality['local'] must be a power of two in [4, 256], got %zu", q->local_n);
    if (q->normal_n < 2 || q->normal_n > 512 || q->normal_n % 2)
        return wenv_error_set(err, WENV_ERR_VALUE, "quality['normals'] must be an even number in [2, 512], got %zu", q->normal_n);
    if (q->view_n < 2 || q->view_n > 256 || q->view_n % 2)
        return wenv_error_set(err, WENV_ERR_VALUE, "quality['views'] must be an even number in [2, 256], got %zu", q->view_n);
    if (q->coefficients > q->local_n * q->local_n)
        return wenv_error_set(err, WENV_ERR_VALUE, "quality['coefficients'] must be at most local**2 = %zu, got %zu",
                              q->local_n * q->local_n, q->coefficients);
    if (q->light_coefficients > ((size_t)1 << 20))
        return wenv_error_set(err, WENV_ERR_VALUE, "quality['light_coefficients'] must be at most 2**20, got %zu",
                              q->light_coefficients);
    if (q->lights > 4096)
        return wenv_error_set(err, WENV_ERR_VALUE, "quality['lights'] must be at most 4096, got %zu", q->lights);
    if (!(q->light_threshold >= 1.0 && q->light_threshold <= 1e12))
        return wenv_error_set(err, WENV_ERR_VALUE, "quality['light_threshold'] must be in [1, 1e12], got %g",
                              q->light_threshold);
    if (!(q->light_tolerance > 0.0 && q->light_tolerance <= 1.0))
        return wenv_error_set(err, WENV_ERR_VALUE, "quality['light_tolerance'] must be in (0, 1], got %g",
                              q->light_tolerance);
    if (!(q->grazing >= 0.0 && q->grazing <= 64.0))
        return wenv_error_set(err, WENV_ERR_VALUE, "quality['grazing'] must be in [0, 64], got %g", q->grazing);
    if (q->lobe_rings > WENV_LOBE_RINGS_MAX)
        return wenv_error_set(err, WENV_ERR_VALUE, "quality['lobe_rings'] must be 0 to %d, got %zu", WENV_LOBE_RINGS_MAX,
                              q->lobe_rings);
    if (q->grazing_slopes > 1)
        return wenv_error_set(err, WENV_ERR_VALUE, "quality['grazing_slopes'] must be 0 or 1, got %zu", q->grazing_slopes);
    if (!(q->matrix_epsilon >= 0.0 && q->matrix_epsilon < 1.0))
        return wenv_error_set(err, WENV_ERR_VALUE, "quality['matrix_epsilon'] must be in [0, 1), got %g", q->matrix_epsilon);
    size_t table = q->normal_n * q->normal_n * (q->view_n + 1) * (q->view_n + 1);
    if (table > ((size_t)1 << 26))
        return wenv_error_set(err, WENV_ERR_VALUE, "quality: normals**2 * (views + 1)**2 = %zu exceeds 2**26 table entries", table);
    return WENV_OK;
}

void wenv_wavelet_free(wenv_wavelet *wavelet)
{
    if (!wavelet)
        return;
    wenv_rotation_free(wavelet->rot);
    wenv_slice_operators_free(wavelet->slice_ops);
    wenv_resampler_free(wavelet->resampler);
    free(wavelet->frames);
    free(wavelet->light_idx);
    free(wavelet->light_rgb);
    free(wavelet->global_rgbx);
    if (wavelet->slices)
        for (size_t s = 0; s < wavelet->ns; s++)
            free(wavelet->slices[s]);
    free(wavelet->slices);
    free(wavelet->irradiance);
    wenv_irradiance_rule_free(wavelet->irradiance_rule);
    wenv_lights_free(wavelet->lights);
    wenv_grazing_light_free(wavelet->grazing_light);
    wenv_envmap_free(wavelet->image);
    free(wavelet->excluded);
    free(wavelet->shadow_hidden);
    free(wavelet->shadow_e_hidden);
    free(wavelet->shadow_lbar);
    free(wavelet->shadow_e_env);
    if (wavelet->shadow_lights)
        wenv_light_memo_free(wavelet->shadow_lights);
    free(wavelet->shadow_lights);
    free(wavelet->slice_ready);
    free(wavelet->slice_need);
    wenv_wavelet_palette_free(wavelet);
    wenv_wavelet_free_quadrature(wavelet);
    for (size_t i = 0; i < wavelet->n_kept; i++)
        wenv_wavelet_material_free(wavelet->kept[i]);
    free(wavelet);
}

int wenv_wavelet_rotation_cache_path(const wenv_wavelet_quality *q, const char *cache_dir, char *path, size_t size)
{
    /* %a: two epsilons that print alike to a few digits must not share (and overwrite) a file */
    int n = snprintf(path, size, "%s/wenv-rot-v2-g%zu-l%zu-n%zu-e%a.bin", cache_dir, q->global_n, q->local_n,
                     q->normal_n, q->matrix_epsilon);
    return n > 0 && (size_t)n < size ? 0 : -1;
}

/* Matrices for q not in the cache: built, unless they would take more than memory_budget. */
static wenv_status build_rotation(wenv_wavelet *wavelet, const wenv_wavelet_quality *q, size_t memory_budget,
                                  const wenv_progress *progress, wenv_error *err)
{
    if (memory_budget) {
        size_t need;
        if (wenv_rotation_estimate_bytes(q->global_n, q->local_n, q->normal_n, q->matrix_epsilon, &need, err))
            return err->status;
        if (need > memory_budget)
            return wenv_error_set(err, WENV_ERR_VALUE,
                                  "rotation matrices for global %zu, local %zu, normals %zu at matrix_epsilon %g would "
                                  "take about %.0f MB, more than memory_budget_mb (%.0f): use method='slicing' (the "
                                  "same shading without matrices) or raise memory_budget_mb",
                                  q->global_n, q->local_n, q->normal_n, q->matrix_epsilon, (double)need / 1048576.0,
                                  (double)memory_budget / 1048576.0);
    }
    return wenv_rotation_build(&wavelet->rot, q->global_n, q->local_n, q->normal_n, q->matrix_epsilon, progress, err);
}

/* What slicing may keep of its resampling operators under the shader's memory budget (wavelet.h). */
static size_t operator_budget(size_t memory_budget)
{
    size_t share = memory_budget / 8;
    return memory_budget && share < WENV_WAVELET_OPERATOR_BYTES ? share : WENV_WAVELET_OPERATOR_BYTES;
}

wenv_status wenv_wavelet_create(wenv_wavelet **out, const wenv_wavelet_quality *q, wenv_wavelet_variant method,
                               const char *cache_dir, size_t memory_budget, const wenv_progress *progress,
                               wenv_error *err)
{
    *out = NULL;
    if (wenv_wavelet_quality_check(q, err))
        return err->status;
    wenv_wavelet *wavelet = calloc(1, sizeof *wavelet);
    if (!wavelet)
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for the shader");
    wavelet->q = *q;
    wavelet->method = method;
    wavelet->ng = q->global_n * q->global_n;
    wavelet->nl = q->local_n * q->local_n;
    wavelet->ns = q->normal_n * q->normal_n;
    wavelet->nv = (q->view_n + 1) * (q->view_n + 1); /* samples on texel corners, horizon included */
    wavelet->frames = malloc(wavelet->ns * 9 * sizeof(float));
    wavelet->slices = calloc(wavelet->ns, sizeof(float *));
    wavelet->irradiance = calloc(wavelet->ns * 3, sizeof(float));
    wavelet->slice_ready = calloc(wavelet->ns, 1);
    wavelet->slice_need = calloc(wavelet->ns, 1);
    if (!wavelet->frames || !wavelet->slices || !wavelet->irradiance || !wavelet->slice_ready || !wavelet->slice_need) {
        wenv_wavelet_free(wavelet);
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for the shader tables");
    }
    for (size_t s = 0; s < wavelet->ns; s++) {
        double n[3], f[9];
        wenv_normal_sample(q->normal_n, s, n);
        wenv_frame(n, f);
        for (int c = 0; c < 9; c++)
            wavelet->frames[9 * s + c] = (float)f[c];
    }
    if (wenv_irradiance_rule_create(&wavelet->irradiance_rule, q->global_n, err) ||
        wenv_wavelet_build_quadrature(wavelet, err)) {
        wenv_wavelet_free(wavelet);
        return err->status;
    }
    double t0 = wenv_now_seconds();
    if (method == WENV_WAVELET_ROTATION) {
        char path[4096];
        if (!cache_dir || wenv_wavelet_rotation_cache_path(q, cache_dir, path, sizeof path) != 0)
            path[0] = '\0'; /* no cache, or a folder whose path leaves no room for the name */
        if (path[0]) {
            wenv_error ignored = {0};
            if (wenv_rotation_load(&wavelet->rot, path, q->global_n, q->local_n, q->normal_n, q->matrix_epsilon,
                                   &ignored) == WENV_OK)
                wavelet->stats.cache = 1;
        }
        if (!wavelet->rot) {
            if (build_rotation(wavelet, q, memory_budget, progress, err)) {
                wenv_wavelet_free(wavelet);
                return err->status;
            }
            if (path[0]) {
                wenv_error save_err = {0};
                wavelet->stats.cache = wenv_rotation_save(wavelet->rot, path, &save_err) == WENV_OK ? 2 : 3;
            }
        }
        wavelet->stats.rotation_nnz = wenv_rotation_nnz(wavelet->rot);
        wavelet->stats.rotation_bytes = wenv_rotation_bytes(q->global_n, q->normal_n, wavelet->stats.rotation_nnz);
    } else if (wenv_resampler_create(&wavelet->resampler, q->global_n, q->local_n, err) ||
               wenv_slice_operators_create(&wavelet->slice_ops, wavelet->resampler, q->normal_n,
                                           operator_budget(memory_budget), err)) {
        wenv_wavelet_free(wavelet);
        return err->status;
    }
    wavelet->stats.rotation_seconds = wenv_now_seconds() - t0;
    *out = wavelet;
    return WENV_OK;
}

static int compare_size(const void *a, const void *b)
{
    size_t x = *(const size_t *)a, y = *(const size_t *)b;
    return (x > y) - (x < y);
}

wenv_status wenv_wavelet_set_environment(wenv_wavelet *wavelet, const wenv_envmap *env, wenv_error *err)
{
    size_t G = wavelet->q.global_n, ng = wavelet->ng;
    float *texels = malloc(ng * 3 * sizeof(float));
    float *scratch = malloc(wenv_haar2d_scratch_floats(G, 3) * sizeof(float));
    float *mag = malloc(ng * sizeof(float));
    float *work = malloc(ng * sizeof(float));
    uint32_t *idx = malloc(ng * sizeof(uint32_t));
    float *rgb = NULL, *irradiance = malloc(wavelet->ns * 3 * sizeof(float));
    wenv_status st = WENV_OK;
    size_t npixels = wavelet->q.lights;
    wenv_bright_pixel *bright = malloc((npixels ? npixels : 1) * sizeof *bright);
    size_t *excluded = malloc((npixels ? npixels : 1) * sizeof *excluded);
    wenv_lights *lights = NULL;
    wenv_grazing_light *grazing = NULL;
    wenv_envmap *image = NULL;
    if (!texels || !scratch || !mag || !work || !idx || !irradiance || !bright || !excluded) {
        st = wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for the environment");
        goto done;
    }
    if ((st = wenv_envmap_with_transform(&image, env, wenv_envmap_rotation(env), wenv_envmap_strength(env), err)))
        goto done;
    npixels = wenv_envmap_brightest(env, npixels, wavelet->q.light_threshold, bright);
    if ((st = wenv_lights_create(&lights, bright, npixels, err)))
        goto done;
    wavelet->narrow_alpha = WENV_NARROW_LOBE_PIXELS * wenv_envmap_pixel_angle(env);
    wavelet->mean_radiance = (float)(wenv_envmap_flux(env) / (4.0 * M_PI));
    for (size_t i = 0; i < npixels; i++)
        excluded[i] = bright[i].pixel;
    qsort(excluded, npixels, sizeof *excluded, compare_size);
    if ((wavelet->m && wavelet->m->grazing_rule) || wavelet->shadowing) {
        /* the grazing path's (and the shadows') pyramid and the global map in one pass over the image */
        if ((st = wenv_grazing_light_create(&grazing, env, excluded, npixels, G, texels, err)))
            goto done;
    } else if ((st = wenv_oct_from_envmap(env, G, texels, excluded, npixels, err))) {
        goto done;
    }
    float peak[3] = {0.0f, 0.0f, 0.0f};
    for (size_t u = 0; u < ng; u++)
        for (int c = 0; c < 3; c++)
            peak[c] = texels[3 * u + c] > peak[c] ? texels[3 * u + c] : peak[c];
    wenv_haar2d_forward(texels, G, 3, scratch);
    for (size_t u = 0; u < ng; u++)
        mag[u] = texels[3 * u] * texels[3 * u] + texels[3 * u + 1] * texels[3 * u + 1] + texels[3 * u + 2] * texels[3 * u + 2];
    /* more terms asked for than the map has keeps them all */
    size_t keep = wavelet->q.light_coefficients && wavelet->q.light_coefficients < ng ? wavelet->q.light_coefficients : ng;
    size_t count = wenv_select_largest(mag, ng, keep, idx, work);
    rgb = malloc((count ? count : 1) * 3 * sizeof(float));
    if (!rgb) {
        st = wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for the environment");
        goto done;
    }
    for (size_t e = 0; e < count; e++)
        memcpy(rgb + 3 * e, texels + 3 * (size_t)idx[e], 3 * sizeof(float));
    /* the kept lighting back in the pixel domain: the normal samples' irradiance sums it, and
     * slicing resamples it */
    memset(texels, 0, ng * 3 * sizeof(float));
    for (size_t e = 0; e < count; e++)
        memcpy(texels + 3 * (size_t)idx[e], rgb + 3 * e, 3 * sizeof(float));
    wenv_haar2d_inverse(texels, G, 3, scratch);
    if ((st = wenv_irradiance_compute(wavelet->irradiance_rule, texels, wavelet->frames + 6, 9, wavelet->ns, irradiance,
                                      err)))
        goto done;
    if (wavelet->method == WENV_WAVELET_SLICING) {
        /* the resampling reads a texel as one vector */
        float *rgbx = wenv_rgbx_from_rgb(texels, ng);
        if (!rgbx) {
            st = wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for the environment");
            goto done;
        }
        free(wavelet->global_rgbx);
        wavelet->global_rgbx = rgbx;
    }
    free(wavelet->light_idx);
    free(wavelet->light_rgb);
    wavelet->light_idx = idx;
    wavelet->light_rgb = rgb;
    wavelet->light_count = count;
    memcpy(wavelet->radiance_max, peak, sizeof peak);
    free(wavelet->irradiance);
    wavelet->irradiance = irradiance;
    idx = NULL;
    rgb = NULL;
    irradiance = NULL;
    wenv_lights_free(wavelet->lights);
    wavelet->lights = lights;
    lights = NULL;
    wenv_grazing_light_free(wavelet->grazing_light);
    wavelet->grazing_light = grazing;
    grazing = NULL;
    wenv_envmap_free(wavelet->image);
    wavelet->image = image;
    image = NULL;
    free(wavelet->excluded);
    wavelet->excluded = excluded;
    wavelet->n_excluded = npixels;
    excluded = NULL;
    wavelet->have_env = 1;
    wavelet->shadow_valid = wavelet->shadow_env_valid = 0;
    st = wenv_wavelet_remake_ready(wavelet, 1, err);
done:
    free(texels);
    free(scratch);
    free(mag);
    free(work);
    free(idx);
    free(rgb);
    free(irradiance);
    free(bright);
    free(excluded);
    wenv_lights_free(lights);
    wenv_grazing_light_free(grazing);
    wenv_envmap_free(image);
    return st;
}

wenv_status wenv_wavelet_ensure_pyramid(wenv_wavelet *wavelet, wenv_error *err)
{
    if (!wavelet->have_env || wavelet->grazing_light)
        return WENV_OK;
    return wenv_grazing_light_create(&wavelet->grazing_light, wavelet->image, wavelet->excluded, wavelet->n_excluded,
                                     0, NULL, err);
}

wenv_status wenv_wavelet_ensure_grazing(wenv_wavelet *wavelet, wenv_error *err)
{
    if (!wavelet->have_env || wavelet->grazing_light || !wavelet->m || !wavelet->m->grazing_rule)
        return WENV_OK;
    return wenv_grazing_light_create(&wavelet->grazing_light, wavelet->image, wavelet->excluded, wavelet->n_excluded,
                                     0, NULL, err);
}

void wenv_wavelet_get_stats(const wenv_wavelet *wavelet, wenv_wavelet_stats *stats)
{
    *stats = wavelet->stats;
    size_t slices = 0, pairs = 0;
    for (size_t s = 0; s < wavelet->ns; s++)
        slices += wavelet->slices[s] != NULL;
    for (size_t p = 0; wavelet->m && p < wavelet->ns; p++)
        pairs += wavelet->m->row_ready[p] != 0 ? wavelet->nv : 0;
    stats->slices_ready = slices;
    stats->pairs_ready = pairs;
    stats->light_terms = wavelet->light_count;
    stats->direct_lights = wenv_lights_count(wavelet->lights, 0);
    stats->slice_bytes = slices * wavelet->nl * 3 * sizeof(float);
    /* every material kept, the current one's first */
    stats->brdf_terms_total = wavelet->m ? wavelet->m->brdf_terms : 0;
    stats->table_bytes = stats->brdf_bytes = 0;
    stats->grazing_bytes = wenv_grazing_light_bytes(wavelet->grazing_light);
    for (size_t i = 0; i < wavelet->n_kept; i++) {
        stats->table_bytes += wenv_wavelet_table_bytes(wavelet);
        stats->brdf_bytes += wavelet->kept[i]->brdf_terms * 4 * sizeof(float);
        stats->grazing_bytes += wenv_grazing_rule_bytes(wavelet->kept[i]->grazing_rule);
    }
    stats->materials_kept = wavelet->n_kept;
    stats->resampling_bytes = wavelet->slice_ops ? wenv_slice_operators_bytes(wavelet->slice_ops) : 0;
}
