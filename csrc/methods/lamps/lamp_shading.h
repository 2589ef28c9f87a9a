/* The scene's lamps added to what a method shades: the glossy part with each vertex's own material
 * (material_family.h) and the Lambertian part with each vertex's colour (vertex_colour.h), as the
 * environment's light is, unscaled by the World's strength. */
#ifndef WENV_LAMP_SHADING_H
#define WENV_LAMP_SHADING_H

#include "methods/lamps/lamp_light.h"
#include "methods/material_family.h"
#include "methods/vertex_colour.h"

/* out[i] += lamps' light at call vertex i, clamped at 0: normals and views in the world (views NULL:
 * the diffuse light sent out head-on, as method.h's diffuse_light: the lobes' albedo head-on counted
 * as diffuse, the material's own where a family's members differ); colour and family as
 * lighting_frame.h's (NULL: the material's own). */
wenv_status wenv_lamps_add(const wenv_lamp_rows *lamps, const wenv_material *mat, const wenv_vertex_colour *colour,
                           const wenv_family_rows *family, const float *normals, const float *views, size_t n,
                           float *out, wenv_error *err);

#endif
