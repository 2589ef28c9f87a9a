/* Split-sum image-based lighting (splitsum.h) behind the shading-method interface. */
#include <stddef.h>

#include "methods/method.h"
#include "methods/presets.h"
#include "methods/splitsum/splitsum.h"

static const wenv_param PARAMS[] = {
    {"prefilter", WENV_PARAM_SIZE, offsetof(wenv_splitsum_quality, prefilter)},
    {"samples", WENV_PARAM_SIZE, offsetof(wenv_splitsum_quality, samples)},
    {"lut", WENV_PARAM_SIZE, offsetof(wenv_splitsum_quality, lut)},
};

static wenv_status check_quality(const void *quality, wenv_error *err)
{
    return wenv_splitsum_quality_check(quality, err);
}

/* No matrices, so no cache and nothing to report: the work is in set_environment / set_material. */
static wenv_status create(void **state, const void *quality, const wenv_method_setup *setup, wenv_error *err)
{
    (void)setup;
    return wenv_splitsum_create((wenv_splitsum **)state, quality, err);
}

static void destroy(void *state) { wenv_splitsum_free(state); }

static wenv_status set_environment(void *state, const wenv_envmap *env, const wenv_progress *progress,
                                   wenv_error *err)
{
    return wenv_splitsum_set_environment(state, env, progress, err);
}

static wenv_status set_material(void *state, const wenv_material *mat, const wenv_progress *progress,
                                wenv_error *err)
{
    return wenv_splitsum_set_material(state, mat, progress, err);
}

static wenv_status shade(void *state, const float *normals, const float *views, size_t n, float *out,
                         wenv_error *err)
{
    return wenv_splitsum_shade(state, normals, views, n, out, err);
}

static size_t stats(const void *state, wenv_stat *out)
{
    wenv_splitsum_stats s;
    wenv_splitsum_get_stats(state, &s);
    size_t k = 0;
    out[k++] = wenv_stat_count("lobes", s.lobes);
    out[k++] = wenv_stat_count("source_side", s.source_side);
    out[k++] = wenv_stat_count("source_levels", s.source_levels);
    out[k++] = wenv_stat_count("source_bytes", s.source_bytes);
    out[k++] = wenv_stat_count("prefilter_bytes", s.prefilter_bytes);
    out[k++] = wenv_stat_count("lut_bytes", s.lut_bytes);
    out[k++] = wenv_stat_real("environment_seconds", s.environment_seconds);
    out[k++] = wenv_stat_real("prefilter_seconds", s.prefilter_seconds);
    out[k++] = wenv_stat_real("lut_seconds", s.lut_seconds);
    return k;
}

const wenv_method WENV_METHOD_SPLIT_SUM = {
    .name = "split_sum",
    .summary = "prefiltered environment maps and an environment-BRDF table (Karis 2013), for comparison",
    .quality_size = sizeof(wenv_splitsum_quality),
    .params = PARAMS,
    .n_params = sizeof PARAMS / sizeof PARAMS[0],
    .presets = {&WENV_SPLIT_SUM_PRESETS[0], &WENV_SPLIT_SUM_PRESETS[1], &WENV_SPLIT_SUM_PRESETS[2]},
    .check_quality = check_quality,
    .create = create,
    .destroy = destroy,
    .set_environment = set_environment,
    .set_material = set_material,
    .shade = shade,
    .stats = stats,
};
