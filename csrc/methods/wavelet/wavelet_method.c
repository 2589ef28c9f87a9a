/* Wavelet rotation (wavelet.h) behind the shading-method interface, in its two variants: "rotation"
 * (precomputed sparse rotation matrices, cached on disk) and "slicing" (the resampling applied
 * directly, no matrices). */
#include <stddef.h>
#include <sys/stat.h>

#include "methods/cache_dir.h"
#include "methods/method.h"
#include "methods/presets.h"
#include "methods/wavelet/rotation.h"
#include "methods/wavelet/wavelet.h"

#define PARAM(key, type, field) {key, type, offsetof(wenv_wavelet_quality, field)}
static const wenv_param PARAMS[] = {
    PARAM("global", WENV_PARAM_SIZE, global_n),
    PARAM("local", WENV_PARAM_SIZE, local_n),
    PARAM("normals", WENV_PARAM_SIZE, normal_n),
    PARAM("views", WENV_PARAM_SIZE, view_n),
    PARAM("coefficients", WENV_PARAM_SIZE, coefficients),
    PARAM("light_coefficients", WENV_PARAM_SIZE, light_coefficients),
    PARAM("matrix_epsilon", WENV_PARAM_REAL, matrix_epsilon),
    PARAM("lights", WENV_PARAM_SIZE, lights),
    PARAM("light_threshold", WENV_PARAM_REAL, light_threshold),
    PARAM("light_tolerance", WENV_PARAM_REAL, light_tolerance),
    PARAM("grazing", WENV_PARAM_REAL, grazing),
    PARAM("grazing_slopes", WENV_PARAM_SIZE, grazing_slopes),
    PARAM("lobe_rings", WENV_PARAM_SIZE, lobe_rings),
};
#undef PARAM

static wenv_status check_quality(const void *quality, wenv_error *err)
{
    return wenv_wavelet_quality_check(quality, err);
}

static wenv_status create(void **state, const void *quality, const wenv_method_setup *setup,
                          wenv_wavelet_variant variant, wenv_error *err)
{
    char buf[4096];
    const char *cache_dir = NULL;
    /* only rotation has matrices to cache */
    if (variant == WENV_WAVELET_ROTATION && wenv_cache_dir_resolve(setup, buf, sizeof buf, &cache_dir, err))
        return err->status;
    return wenv_wavelet_create((wenv_wavelet **)state, quality, variant, cache_dir, setup ? setup->memory_budget : 0,
                               setup ? setup->progress : NULL, err);
}

/* Matrices at most this large are built when no method is named: the `default` preset's take
 * ~510 MB in memory and ~5 s on two cores; `high`'s would take ~9.5 GB and many minutes. */
#define AFFORDABLE_ROTATION_BYTES ((size_t)768 << 20)

const wenv_method *wenv_wavelet_default_method(const void *quality, const wenv_method_setup *setup)
{
    const wenv_wavelet_quality *q = quality;
    char buf[4096], path[4096];
    const char *cache_dir = NULL;
    wenv_error ignored = {0};
    struct stat st;
    if (wenv_cache_dir_resolve(setup, buf, sizeof buf, &cache_dir, &ignored) == WENV_OK && cache_dir &&
        wenv_wavelet_rotation_cache_path(q, cache_dir, path, sizeof path) == 0 && stat(path, &st) == 0)
        return &WENV_METHOD_ROTATION;
    size_t limit = AFFORDABLE_ROTATION_BYTES, need;
    if (setup && setup->memory_budget && setup->memory_budget < limit)
        limit = setup->memory_budget;
    if (wenv_rotation_estimate_bytes(q->global_n, q->local_n, q->normal_n, q->matrix_epsilon, &need, &ignored) ==
            WENV_OK &&
        need <= limit)
        return &WENV_METHOD_ROTATION;
    return &WENV_METHOD_SLICING;
}

static wenv_status create_rotation(void **state, const void *quality, const wenv_method_setup *setup,
                                   wenv_error *err)
{
    return create(state, quality, setup, WENV_WAVELET_ROTATION, err);
}

static wenv_status create_slicing(void **state, const void *quality, const wenv_method_setup *setup,
                                  wenv_error *err)
{
    return create(state, quality, setup, WENV_WAVELET_SLICING, err);
}

static void destroy(void *state) { wenv_wavelet_free(state); }

/* A new lighting reports no progress: it takes milliseconds per slice, spread over the views that
 * need them.  A new material's BRDF slices cost its lobes' evaluations (seconds for dozens of
 * lobes): they report, and can be cancelled. */
static wenv_status set_environment(void *state, const wenv_envmap *env, const wenv_progress *progress,
                                   wenv_error *err)
{
    (void)progress;
    return wenv_wavelet_set_environment(state, env, err);
}

static wenv_status set_material(void *state, const wenv_material *mat, const wenv_progress *progress,
                                wenv_error *err)
{
    return wenv_wavelet_set_material(state, mat, progress, err);
}

static wenv_status shade(void *state, const float *normals, const float *views, size_t n, float *out,
                         float *irradiance, wenv_error *err)
{
    return wenv_wavelet_shade(state, normals, views, n, out, irradiance, err);
}

static wenv_status shade_shadowed(void *state, const float *normals, const float *views, size_t n,
                                  const wenv_shadow_scene *scene, float *out, float *irradiance, wenv_error *err)
{
    return wenv_wavelet_shade_shadowed(state, normals, views, n, scene, out, irradiance, err);
}

static wenv_status diffuse_light(void *state, const float *normals, size_t n, const wenv_shadow_scene *scene,
                                 float *out, float *irradiance, wenv_error *err)
{
    return wenv_wavelet_diffuse_light(state, normals, n, scene, out, irradiance, err);
}

static void set_lights_apart(void *state, int apart) { wenv_wavelet_set_lights_apart(state, apart); }

static size_t materials_kept(const void *state) { return wenv_wavelet_materials_kept(state); }

static wenv_status shade_lights(void *state, const float *normals, const float *views, size_t n,
                                const wenv_shadow_scene *scene, const wenv_vertex_lights *lights, float *out,
                                float *irradiance, wenv_error *err)
{
    return wenv_wavelet_shade_lights(state, normals, views, n, scene, lights, out, irradiance, err);
}

static size_t stats(const void *state, wenv_stat *out)
{
    static const char *const CACHE_USE[] = {"none", "loaded", "built", "built (save failed)"};
    wenv_wavelet_stats s;
    wenv_wavelet_get_stats(state, &s);
    size_t k = 0;
    out[k++] = wenv_stat_count("rotation_nnz", s.rotation_nnz);
    out[k++] = wenv_stat_count("rotation_bytes", s.rotation_bytes);
    out[k++] = wenv_stat_text("cache", CACHE_USE[s.cache]);
    out[k++] = wenv_stat_real("rotation_seconds", s.rotation_seconds);
    out[k++] = wenv_stat_count("slices_ready", s.slices_ready);
    out[k++] = wenv_stat_count("pairs_ready", s.pairs_ready);
    out[k++] = wenv_stat_count("light_terms", s.light_terms);
    out[k++] = wenv_stat_count("brdf_terms", s.brdf_terms_total);
    out[k++] = wenv_stat_count("slice_bytes", s.slice_bytes);
    out[k++] = wenv_stat_count("table_bytes", s.table_bytes);
    out[k++] = wenv_stat_count("brdf_bytes", s.brdf_bytes);
    out[k++] = wenv_stat_count("direct_lights", s.direct_lights);
    out[k++] = wenv_stat_count("grazing_bytes", s.grazing_bytes);
    out[k++] = wenv_stat_count("materials_kept", s.materials_kept);
    out[k++] = wenv_stat_count("materials_reused", s.materials_reused);
    out[k++] = wenv_stat_count("resampling_bytes", s.resampling_bytes);
    return k;
}

#define WAVELET_METHOD(method_name, method_summary, create_fn)                                                  \
    {                                                                                                          \
        .name = method_name, .summary = method_summary, .quality_size = sizeof(wenv_wavelet_quality),          \
        .params = PARAMS, .n_params = sizeof PARAMS / sizeof PARAMS[0],                                        \
        .presets = {&WENV_WAVELET_PRESETS[0], &WENV_WAVELET_PRESETS[1], &WENV_WAVELET_PRESETS[2]},              \
        .check_quality = check_quality, .create = create_fn, .destroy = destroy,                               \
        .set_environment = set_environment, .set_material = set_material, .shade = shade,                      \
        .shade_shadowed = shade_shadowed, .diffuse_light = diffuse_light, .set_lights_apart = set_lights_apart,     \
        .materials_kept = materials_kept,                                                                      \
        .shade_lights = shade_lights, .stats = stats,                                                          \
    }

const wenv_method WENV_METHOD_ROTATION = WAVELET_METHOD(
    "rotation", "wavelet rotation with precomputed sparse matrices (Wang et al. 2006), cached on disk",
    create_rotation);
const wenv_method WENV_METHOD_SLICING = WAVELET_METHOD(
    "slicing", "wavelet rotation with the resampling applied directly: no matrices to build or hold",
    create_slicing);
