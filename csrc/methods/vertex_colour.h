/* A colour per vertex in place of the material's: a texture's Base Color, read at each vertex.
 *
 * Why: a material's colour is, where it can vary alone, a factor on its Lambertian part and on
 * nothing else (wenv_material_diffuse_per_colour_table), so a method shades the rest and the light
 * that part reflects once (method.h's irradiance), and each vertex's colour costs a multiply-add:
 * no BRDF slices, tables or rotation made per colour. */
#ifndef WENV_VERTEX_COLOUR_H
#define WENV_VERTEX_COLOUR_H

#include <stddef.h>

#include "scene/material.h"

typedef struct {
    const wenv_diffuse_table *per_colour; /* the material's Lambertian part per unit colour, over pi */
    const float *rgb;                     /* one linear RGB colour per shaded vertex, in [0, 1] */
} wenv_vertex_colour;

/* out[i] = max(0, out[i] + rgb[i] x per_colour(cos_v) x irradiance[i]) for n vertices, cos_v the
 * cosine between normal i and view i (views NULL: 1, the light sent out head-on). */
void wenv_vertex_colour_apply(const wenv_vertex_colour *colour, const float *normals, const float *views, size_t n,
                              const float *irradiance, float *out);

#endif
