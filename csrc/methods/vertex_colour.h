/* A colour per vertex in place of the material's: a texture's Base Color, read at each vertex (and
 * the share of its light a bent Lambertian part receives, which scales the same part).
 *
 * Why: a material's colour is, where it can vary alone, a factor on its Lambertian part and on
 * nothing else (wenv_material_diffuse_per_colour_table), so a method shades the rest and the light
 * that part reflects once (method.h's irradiance), and each vertex's colour costs a multiply-add:
 * no BRDF slices, tables or rotation made per colour. */
#ifndef WENV_VERTEX_COLOUR_H
#define WENV_VERTEX_COLOUR_H

#include <stddef.h>

#include "scene/bump_terminator.h"
#include "scene/material.h"

typedef struct {
    const wenv_diffuse_table *per_colour; /* the material's Lambertian part per unit colour, over pi
                                           * (with rgb NULL: the part itself) */
    const float *rgb;                     /* one linear RGB colour per shaded vertex, in [0, 1]; NULL: 1 */
    wenv_bump_normals bump; /* the smooth normals (n x 3, world) the normals were bent from, whose
                             * Lambertian part loses what Cycles' bump terminator takes; smooth NULL
                             * where nothing is bent */
    /* set by wenv_lighting_frame_shade_scene from bump, not by its callers: per vertex the share of
     * a uniform sky the bent part keeps, and the irradiance at the smooth horizon towards its bend
     * (in the method's frame), whose lost share it loses (NULL: the share of its own light) */
    const float *share;
    const float *horizon_light;
} wenv_vertex_colour;

/* The light vertex i's Lambertian part receives in channel c, from the irradiance e at its normal:
 * where it is bent, less what the smooth surface's horizon takes -- the lost share of the horizon's
 * light where that is known (exact for a uniform sky, and where the light is linear in the
 * direction across the horizon), else of e. */
static inline float wenv_bent_light(float e, const float *share, const float *horizon_light, size_t i, int c)
{
    if (!share)
        return e;
    if (!horizon_light)
        return share[i] * e;
    float kept = e - (1.0f - share[i]) * horizon_light[3 * i + (size_t)c];
    return kept > 0.0f ? kept : 0.0f;
}

/* out[i] = max(0, out[i] + rgb[i] x per_colour(cos_v) x the light of irradiance[i] the part receives
 * (wenv_bent_light)) for n vertices, cos_v the cosine between normal i and view i (views NULL: 1, the
 * light sent out head-on). */
void wenv_vertex_colour_apply(const wenv_vertex_colour *colour, const float *normals, const float *views, size_t n,
                              const float *irradiance, float *out);

#endif
