/* The scene's lamps' light at each vertex of a mesh, with the material's own BRDF, shadows and all:
 * what every method adds to its environment's light (docs/lamps.md).
 *
 * How:
 *  - What no view changes is made once per mesh state and lamp placement (wenv_lamp_light_ensure):
 *    for each vertex and lamp, the light its Lambertian part receives per unit of the lamp's
 *    radiance -- the projected solid angle of the lamp's patch (lamp_patch.h), in closed form,
 *    times the lamp's factor -- and which of k x k cells of the lamp it sees (a ray each; k = 4
 *    for a lamp wider than WENV_LAMP_WIDE, else 1).  A lamp's new colour or power makes nothing
 *    again.
 *  - The glossy part, which turns with the view, is summed at each view over a grid of the lamp's
 *    points fine enough for the narrowest lobe where its peak falls, coarser in its tails, each
 *    vertex through its own materials.
 * A lamp of radius 0 (or a sun of angle 0) is one direction, exactly. */
#ifndef WENV_LAMP_LIGHT_H
#define WENV_LAMP_LIGHT_H

#include <stddef.h>
#include <stdint.h>

#include "base/error.h"
#include "base/progress.h"
#include "methods/method.h"
#include "scene/bump_terminator.h"
#include "scene/lamp.h"
#include "scene/material.h"
#include "scene/occluders.h"

/* A lamp wider than this (radians across, as seen) has its shadows read over 4 x 4 cells. */
#define WENV_LAMP_WIDE 0.02
#define WENV_LAMP_CELLS 4
/* The glossy grid: points WENV_LAMP_GLOSSY_SPACING x the narrowest lobe's alpha apart across the
 * lamp, at most WENV_LAMP_GLOSSY_GRID a side.  Where the lobes' peak (WENV_LAMP_PEAK alphas about
 * the mirror direction) misses the lamp, 2 a side read the smooth tails; otherwise a finer grid
 * than WENV_LAMP_GLOSSY_COARSE is made only in the coarse cells the peak may fall on. */
#define WENV_LAMP_GLOSSY_SPACING 0.5
#define WENV_LAMP_GLOSSY_GRID 32
#define WENV_LAMP_GLOSSY_COARSE 4
#define WENV_LAMP_PEAK 6.0

typedef struct wenv_lamp_light wenv_lamp_light;

/* *light made for these lamps at these n vertices (positions, normals: xyz floats; normals non-zero),
 * shadowed by occ (NULL: no shadows), unless it was made for them already -- only the lamps'
 * colours, powers and ray visibility differ, which are then taken as they are.  On failure *light
 * is kept.  WENV_ERR_VALUE naming positions[i] or normals[i] that are not finite (or zero).
 * Progress and cancel as base/progress.h. */
wenv_status wenv_lamp_light_ensure(wenv_lamp_light **light, const wenv_lamp *lamps, size_t n_lamps,
                                   const float *positions, const float *normals, size_t n, const wenv_occluders *occ,
                                   const wenv_progress *progress, wenv_error *err);
void wenv_lamp_light_free(wenv_lamp_light *light);
size_t wenv_lamp_light_vertices(const wenv_lamp_light *light);
size_t wenv_lamp_light_lamps(const wenv_lamp_light *light);
/* How many times its per-vertex part was made (what a test of "a new power makes nothing" reads). */
size_t wenv_lamp_light_made(const wenv_lamp_light *light);

/* Which of the light's vertices a call shades: vertex k is rows[k], or offset + k when rows is NULL. */
typedef struct {
    const wenv_lamp_light *light;
    const uint32_t *rows;
    size_t offset;
} wenv_lamp_rows;

/* For n call vertices (normals and views as the shading calls take them; views NULL: the diffuse
 * light sent out head-on, no glossy part): adds the lamps' light on the glossy part to out, each
 * vertex through its own materials (own; NULL: mat for all), and what they bring the Lambertian part
 * (cosine-weighted radiance, as method.h's irradiance) to irradiance -- where bump is set (NULL:
 * nothing bent), each lamp's as Cycles' bump terminator lets it through in the lamp's direction. */
wenv_status wenv_lamp_light_shade(const wenv_lamp_rows *rows, const wenv_material *mat, const wenv_vertex_lights *own,
                                  const float *normals, const float *views, size_t n, const wenv_bump_normals *bump,
                                  float *out, float *irradiance, wenv_error *err);

#endif
