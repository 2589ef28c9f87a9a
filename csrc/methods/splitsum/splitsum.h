/* Split-sum image-based lighting (Karis 2013, "Real Shading in Unreal Engine 4"; as Filament and
 * EEVEE do it), a peer of the wavelet method for comparison.
 *
 * Specular, per lobe: L_spec(n, v) ~ prefiltered(r) x E(n.v) x specular, r the mirror direction.
 *  - prefiltered: the environment convolved with the lobe's distribution under the n = v = r
 *    assumption, on an octahedral map (maps.h) of side `prefilter`, one map per lobe at the lobe's
 *    own roughness (the lobes are known when the material is set, so there is no interpolation
 *    between roughness levels).  Each texel is an importance-sampled estimate with `samples`
 *    Hammersley half vectors drawn from the lobe's distribution (Beckmann or GGX), weighted by n.l
 *    (Karis's estimator), each sample read from a solid-angle-matched level of a mip pyramid of the
 *    environment (filtered importance sampling, Colbert and Krivanek 2007, as Filament's cmgen).
 *  - E(n.v): the lobe's own directional albedo, colour included (wenv_material_lobe_albedo; for
 *    Cook-Torrance its exact distribution, shadowing and dielectric Fresnel at its index): the
 *    environment-BRDF table of the 2D LUT (n.v, roughness) taken at the lobe's roughness and index,
 *    so no Schlick approximation and no roughness interpolation; `lut` entries at
 *    n.v = (i + 0.5) / lut, linear in between, RGB.
 * The prefilter assumes each lobe is the microfacet lobe of its shape (scene/material.h): exact
 * for Cook-Torrance, the closest microfacet lobe for other models.
 * Diffuse: irradiance from the 9-coefficient SH projection of the environment (Ramamoorthi and
 * Hanrahan 2001), clamped at zero, times diffuse / pi.
 * Registered as WENV_METHOD_SPLIT_SUM (methods/method.h).
 * What the method cannot do (by design): the n = v = r assumption loses the stretching of
 * highlights at grazing views and the dependence of the lobe's shape on the view. */
#ifndef WENV_SPLITSUM_H
#define WENV_SPLITSUM_H

#include <stddef.h>

typedef struct {
    size_t prefilter; /* side of each lobe's octahedral prefiltered map, even, [8, 1024] */
    size_t samples;   /* importance samples per prefiltered texel, [1, 65536] */
    size_t lut;       /* environment-BRDF entries over n.v per lobe, [2, 4096] */
} wenv_splitsum_quality;

#endif
