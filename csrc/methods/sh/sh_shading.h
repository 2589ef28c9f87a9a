/* Spherical-harmonic environment shading (Kautz, Sloan and Snyder 2002, "Fast, arbitrary BRDF
 * shading for low-frequency lighting using spherical harmonics"), a peer of the wavelet method for
 * comparison.
 *
 * Lighting: the environment projected onto real SH up to band `order` (math/spherical_harmonics.h,
 * in pixel blocks as coarse as the order allows).  Material: each lobe's f(w, v) cos(w), projected
 * onto SH in the surface's local frame for `views` view elevations theta_v from 0 to 89.9 degrees
 * with the view in the local xz plane (isotropic BRDFs need no view azimuth: it is absorbed by the
 * frame), each by the lobe's own rule (wenv_material_lobe_nodes), so narrow lobes are projected
 * without aliasing.  Per vertex: the frame whose z is the normal and whose x points along the
 * view's tangential part; the lighting rotated into it exactly (zyz Euler angles); the radiance is
 * the dot product with the slice interpolated linearly in theta_v.  Diffuse: irradiance
 * sum_l A_l L_l0 sqrt((2l+1)/4pi) from the same rotated lighting, bands 0..order (at order 2,
 * Ramamoorthi and Hanrahan's 9 coefficients).  Cost per vertex: O(order^3) for the rotation.  A
 * material without lobes needs no rotation: bands 0 - 2 of its irradiance are evaluated per vertex
 * in closed form and bands 3 - order read from a table over an octahedral grid of normals (a few
 * ns per vertex at any order).  Assumes an isotropic material.  Registered as WENV_METHOD_SH
 * (methods/method.h). */
#ifndef WENV_SH_SHADING_H
#define WENV_SH_SHADING_H

#include <stddef.h>

typedef struct {
    size_t order; /* highest SH band, [2, WENV_SH_ORDER_MAX]: (order + 1)^2 coefficients */
    size_t views; /* view elevations with a BRDF slice, [2, 1024] */
} wenv_sh_shading_quality;

#endif
