/* What the exact lights read of a material (light_lobes.h). */
#include "methods/wavelet/light_lobes.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* nodes per dimension of the albedo's rule: a scale for a tolerance needs a few per cent */
#define ALBEDO_SAMPLES 8

void wenv_light_lobes_free(wenv_light_lobes *lobes)
{
    free(lobes->cos_h_min);
    free(lobes->envelope);
    memset(lobes, 0, sizeof *lobes);
}

wenv_status wenv_light_lobes_make(wenv_light_lobes *lobes, const wenv_material *mat, wenv_error *err)
{
    memset(lobes, 0, sizeof *lobes);
    lobes->mat = mat;
    size_t n_lobes = wenv_material_lobe_count(mat);
    lobes->has_lobes = n_lobes > 0;
    lobes->cos_h_min = malloc((n_lobes ? n_lobes : 1) * sizeof(float));
    if (!lobes->cos_h_min)
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for the material's lights");
    for (size_t k = 0; k < n_lobes; k++)
        lobes->cos_h_min[k] = (float)wenv_material_lobe_cos_h_min(mat, k);
    /* A half-vector theta_h from the normal turns the mirror direction by at most 2 theta_h. */
    double theta_h = 0.0;
    for (size_t k = 0; k < n_lobes; k++)
        theta_h = fmax(theta_h, acos(fmax(-1.0, fmin(1.0, (double)lobes->cos_h_min[k]))));
    lobes->alpha = fmin(1.0, wenv_material_lobe_width(mat));
    lobes->modelled = wenv_material_mirror_centred(mat) && wenv_material_lobes_follow_shapes(mat);
    lobes->cone_cos = 2.0 * theta_h >= M_PI ? -1.0 : cos(2.0 * theta_h);
    if (lobes->modelled) {
        wenv_lights_peak_table(mat, lobes->alpha, lobes->peak);
    } else if (n_lobes) {
        lobes->envelope = malloc((WENV_LIGHT_PEAK_SAMPLES + 1) * WENV_LIGHT_ENVELOPE_BINS * sizeof(float));
        if (!lobes->envelope) {
            wenv_light_lobes_free(lobes);
            return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for the material's lights");
        }
        wenv_lights_envelope_table(mat, lobes->envelope);
    }
    for (size_t i = 0; i < WENV_LIGHT_LOBES_ALBEDO_N; i++) {
        double c = fmax(1e-3, (double)i / (WENV_LIGHT_LOBES_ALBEDO_N - 1));
        double wo[3] = {sqrt(fmax(0.0, 1.0 - c * c)), 0.0, c};
        for (size_t k = 0; k < n_lobes; k++) {
            double a[3];
            if (wenv_material_lobe_albedo(mat, k, wo, ALBEDO_SAMPLES, a, err)) {
                wenv_light_lobes_free(lobes);
                return err->status;
            }
            for (int c3 = 0; c3 < 3; c3++)
                lobes->albedo[3 * i + (size_t)c3] += (float)a[c3];
        }
    }
    return WENV_OK;
}

wenv_lights_lobe wenv_light_lobes_walk(const wenv_light_lobes *lobes, double narrow_alpha)
{
    return (wenv_lights_lobe){.alpha = lobes->alpha,
                              .cone_cos = lobes->cone_cos,
                              .modelled = lobes->modelled,
                              .narrow = lobes->alpha < narrow_alpha,
                              .peak = lobes->peak,
                              .envelope = lobes->modelled ? NULL : lobes->envelope};
}

float wenv_light_lobes_albedo_sum(const wenv_light_lobes *lobes, float c)
{
    float x = (c < 0.0f ? 0.0f : (c > 1.0f ? 1.0f : c)) * (float)(WENV_LIGHT_LOBES_ALBEDO_N - 1);
    size_t i = (size_t)x < WENV_LIGHT_LOBES_ALBEDO_N - 1 ? (size_t)x : WENV_LIGHT_LOBES_ALBEDO_N - 2;
    float f = x - (float)i;
    const float *a = lobes->albedo + 3 * i, *b = a + 3;
    return (1.0f - f) * (a[0] + a[1] + a[2]) + f * (b[0] + b[1] + b[2]);
}
