/* Exact directional lights: the environment's brightest pixels, shaded per vertex.
 *
 * Why: a sun, a lamp or a softbox holds much of a scene's flux in few pixels, and wavelet
 * truncation and interpolation between samples smear their highlights.  Taken out of the lighting
 * and shaded as point lights at their pixel centres, they are exact in the reference's own sense
 * (wenv_reference sums the same pixels at the same centres; a lobe narrower than a pixel integrates
 * its area on a grid of points, where the reference integrates the lobe by its own rule).
 *
 * Cost is kept down two ways:
 *  - levels of clusters: level 0 holds every pixel; level k merges the lights of level k - 1 whose
 *    directions lie within WENV_LIGHT_RADIUS(k) of a seed into one light at their flux-weighted
 *    centre.  A cluster of radius r seen through a lobe w radians wide is off by about (r / w)^2 / 2
 *    of its contribution, so a vertex reads the coarsest level with r <= WENV_LIGHT_WIDTH_FRACTION w:
 *    a wide lobe sees a sun as one light, a lobe squeezed at grazing sees every pixel;
 *  - direction bins: each level's lights are sorted into octahedral bins with a bounding cone; a
 *    vertex visits only the bins that meet its lobe's cone about the mirror direction. */
#ifndef WENV_LIGHTS_H
#define WENV_LIGHTS_H

#include <stddef.h>

#include "base/error.h"
#include "scene/envmap.h"
#include "scene/material.h"

#define WENV_LIGHT_LEVELS 7
/* Cluster radius of level k >= 1, radians: 0.25 degrees doubling per level, to 8 degrees. */
#define WENV_LIGHT_RADIUS(k) ((k) ? 0.25 * 0.017453292519943295 * (double)(1u << ((k) - 1)) : 0.0)
/* Largest cluster radius per radian of lobe width (0.5 % off per light at worst). */
#define WENV_LIGHT_WIDTH_FRACTION 0.1
/* The width irradiance reads at: the cosine is linear above the horizon (a cluster's span keeps
 * that exact), but a cluster straddling the horizon is cut, so clusters stay within 1 degree. */
#define WENV_LIGHT_IRRADIANCE_WIDTH 0.18

typedef struct wenv_lights wenv_lights;

/* px: the pixels taken out (wenv_envmap_brightest), brightest first.  n may be 0. */
wenv_status wenv_lights_create(wenv_lights **out, const wenv_bright_pixel *px, size_t n, wenv_error *err);
void wenv_lights_free(wenv_lights *lights);
/* Lights at a level (level 0: the pixels). */
size_t wenv_lights_count(const wenv_lights *lights, int level);

/* The coarsest level whose cluster radius is at most WENV_LIGHT_WIDTH_FRACTION of a lobe
 * `width` radians wide. */
int wenv_lights_level(double width);

/* Irradiance at unit normal n, added to e. */
void wenv_lights_irradiance(const wenv_lights *lights, int level, const float n[3], float e[3]);

/* The lobes' reflected radiance at unit normal n and view v (n . v = cos_v > 0), added to s.
 * cos_h_min[k]: lobe k's n.h below which it is negligible; cone_cos: cosine of the half-angle
 * about the mirror direction outside which every lobe is negligible (-1: none); narrow_width: for
 * a lobe narrower than WENV_NARROW_LOBE_PIXELS pixels, its width about there in radians (level 0
 * then integrates the pixels wider than it over their areas, as wenv_reference does), else 0. */
void wenv_lights_specular(const wenv_lights *lights, int level, const wenv_material *mat, const float *cos_h_min,
                          double cone_cos, double narrow_width, const float n[3], const float v[3], float cos_v,
                          float s[3]);

#endif
