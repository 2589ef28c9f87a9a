/* The reference's lamps: each lamp's light at a point summed over a fine grid of its own surface
 * (or, for a sun and a sphere, of its cone of directions), every point with the exact BRDF and, with
 * occluders, its own ray.  Independent of what shading does with lamps (lamps/lamp_light.h): no
 * closed form, no cells, no patch; only the lamp's emission (scene/lamp.h) is shared. */
#ifndef WENV_LAMPS_REFERENCE_H
#define WENV_LAMPS_REFERENCE_H

#include <stddef.h>

#include "scene/lamp.h"
#include "scene/material.h"
#include "scene/occluders.h"

/* The grid's side: at least this many points across a lamp, more for a lobe narrower than it. */
#define WENV_REFERENCE_LAMP_GRID 48
#define WENV_REFERENCE_LAMP_GRID_MAX 192

/* Adds to spec the lamps' light on mat's glossy part and to irr what they bring its Lambertian part
 * (cosine-weighted radiance) at point p with unit normal nrm (frame f: wenv_frame of it), seen from
 * wo (local, unit); rays from `origin` (p lifted off the surface) when occ is set.  smooth (unit, or
 * NULL): the normal nrm was bent from, the Lambertian part's light then let through as Cycles' bump
 * terminator lets it (bump_terminator.h, with or without correction). */
void wenv_reference_lamps_at(const wenv_lamp *lamps, size_t n_lamps, const wenv_material *mat, const double p[3],
                             const double nrm[3], const double f[9], const double wo[3], const wenv_occluders *occ,
                             const float origin[3], const double *smooth, int correction, double spec[3],
                             double irr[3]);

#endif
