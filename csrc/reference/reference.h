/* Ground truth: the reflection equation summed over every environment pixel, each a point
 * source of flux radiance x exact pixel solid angle, with the exact BRDF, plus what the material
 * emits (wenv_material_emission_at).  Same units as shading.
 * With occluders (positions then required), each pixel's ray from the vertex (lifted off the
 * surface by wenv_occluders_offset) is cast exactly, and a blocked one brings
 * the light of the blocker where it is hit: bounce (per occluder vertex, RGB radiance, interpolated
 * over the hit triangle) times the pixel's solid angle, or nothing when bounce is NULL (direct light
 * only).  occ NULL: unshadowed.  The scene's lamps (n_lamps of them; positions then required) are
 * added as reference/lamps_reference.h sums them, shadowed by occ, unscaled by the World.  emission
 * (n x 3, or NULL: the material's own): each vertex's Emission Color (a Principled material's). */
#ifndef WENV_REFERENCE_H
#define WENV_REFERENCE_H

#include <stddef.h>

#include "base/error.h"
#include "scene/principled_inputs.h"
#include "base/progress.h"
#include "scene/bump_terminator.h"
#include "scene/envmap.h"
#include "scene/lamp.h"
#include "scene/material.h"
#include "scene/occluders.h"

/* base_color (NULL: the material's): each vertex's colour in [0, 1] in place of the material's, in
 * its Lambertian part (wenv_material_diffuse_per_colour_at; WENV_ERR_VALUE where it cannot vary).
 * bump (NULL: none): the smooth normals the normals were bent from, whose Lambertian part then
 * receives each direction's light as Cycles' bump terminator lets it through (bump_terminator.h). */
wenv_status wenv_reference(const wenv_envmap *env, const wenv_material *mat, const float *normals,
                           const float *views, size_t n, const wenv_occluders *occ, const float *positions,
                           const float *bounce, const float *base_color, const wenv_lamp *lamps, size_t n_lamps,
                           const float *emission, const wenv_bump_normals *bump, float *out,
                           const wenv_progress *progress, wenv_error *err);

/* The same with each vertex's inputs (vi: principled_inputs.h's WENV_VERTEX_INPUTS, each NULL for the
 * material's own), for a Principled material (WENV_ERR_VALUE otherwise): the vertices of one set of
 * values, clamped as Cycles clamps them, are shaded with that material, exactly.  With a colour per
 * vertex on a material with a metal (Metallic above 0, here or per vertex), each colour is its own
 * material too, the metal's Fresnel colour being the Base Color. */
wenv_status wenv_reference_per_vertex(const wenv_envmap *env, const wenv_material *mat, const float *normals,
                                      const float *views, size_t n, const wenv_occluders *occ, const float *positions,
                                      const float *bounce, const float *base_color, const wenv_vertex_inputs *vi,
                                      const wenv_lamp *lamps, size_t n_lamps, const float *emission,
                                      const wenv_bump_normals *bump, float *out, const wenv_progress *progress,
                                      wenv_error *err);

#endif
