/* The irradiance of the wavelet shader's normal samples, summed directly over the global lighting
 * map (the lighting the slices see, exact lights taken out).
 *
 * Why not from the lighting slices, as the thesis did (the cosine's Haar coefficients against each
 * slice): a diffuse material then needed every slice its normals read, made and Haar transformed,
 * though it reads one number per sample of each; at `default` that was two thirds of a new image's
 * time for Lambert.  Summed over the map (at most 64 x 64 texels, a texel's cosine at its centre),
 * the irradiance of every normal sample costs about a millisecond, is as close to the lighting as
 * the slices' (which resample the same map), and a diffuse-only material makes no slice at all. */
#ifndef WENV_WAVELET_IRRADIANCE_H
#define WENV_WAVELET_IRRADIANCE_H

#include <stddef.h>

#include "base/error.h"

typedef struct wenv_irradiance_rule wenv_irradiance_rule;

/* The rule for a global octahedral map of global_n x global_n texels. */
wenv_status wenv_irradiance_rule_create(wenv_irradiance_rule **out, size_t global_n, wenv_error *err);
void wenv_irradiance_rule_free(wenv_irradiance_rule *rule);

/* out[3 s .. 3 s + 2] = the irradiance at unit normal normals + s * stride (s < n) under the global
 * map `texels` (global_n^2 x 3 radiance, pixel domain), scaled so that a constant radiance L gives
 * exactly pi L.  Normals in parallel; each sum in a fixed order, so the result does not depend on
 * the number of threads. */
wenv_status wenv_irradiance_compute(const wenv_irradiance_rule *rule, const float *texels, const float *normals,
                                    size_t stride, size_t n, float *out, wenv_error *err);

#endif
