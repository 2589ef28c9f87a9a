/* Spherical-harmonic shading (sh_shading.h) behind the shading-method interface. */
#include <stddef.h>

#include "methods/method.h"
#include "methods/presets.h"
#include "methods/sh/sh_shading.h"

static const wenv_param PARAMS[] = {
    {"order", WENV_PARAM_SIZE, offsetof(wenv_sh_shading_quality, order)},
    {"views", WENV_PARAM_SIZE, offsetof(wenv_sh_shading_quality, views)},
};

static wenv_status check_quality(const void *quality, wenv_error *err)
{
    return wenv_sh_shading_quality_check(quality, err);
}

/* No matrices, so no cache and nothing to report: the work is in set_environment / set_material. */
static wenv_status create(void **state, const void *quality, const wenv_method_setup *setup, wenv_error *err)
{
    (void)setup;
    return wenv_sh_shading_create((wenv_sh_shading **)state, quality, err);
}

static void destroy(void *state) { wenv_sh_shading_free(state); }

static wenv_status set_environment(void *state, const wenv_envmap *env, const wenv_progress *progress,
                                   wenv_error *err)
{
    return wenv_sh_shading_set_environment(state, env, progress, err);
}

static wenv_status set_material(void *state, const wenv_material *mat, const wenv_progress *progress,
                                wenv_error *err)
{
    return wenv_sh_shading_set_material(state, mat, progress, err);
}

static wenv_status shade(void *state, const float *normals, const float *views, size_t n, float *out,
                         wenv_error *err)
{
    return wenv_sh_shading_shade(state, normals, views, n, out, err);
}

static size_t stats(const void *state, wenv_stat *out)
{
    wenv_sh_shading_stats s;
    wenv_sh_shading_get_stats(state, &s);
    size_t k = 0;
    out[k++] = wenv_stat_count("coefficients", s.coefficients);
    out[k++] = wenv_stat_count("slice_bytes", s.slice_bytes);
    out[k++] = wenv_stat_count("quadrature_nodes", s.quadrature_nodes);
    out[k++] = wenv_stat_real("projection_seconds", s.projection_seconds);
    out[k++] = wenv_stat_real("slice_seconds", s.slice_seconds);
    return k;
}

const wenv_method WENV_METHOD_SH = {
    .name = "sh",
    .summary = "spherical harmonics with per-vertex rotation (Kautz, Sloan and Snyder 2002), for comparison",
    .quality_size = sizeof(wenv_sh_shading_quality),
    .params = PARAMS,
    .n_params = sizeof PARAMS / sizeof PARAMS[0],
    .presets = {&WENV_SH_PRESETS[0], &WENV_SH_PRESETS[1], &WENV_SH_PRESETS[2]},
    .check_quality = check_quality,
    .create = create,
    .destroy = destroy,
    .set_environment = set_environment,
    .set_material = set_material,
    .shade = shade,
    .stats = stats,
};
