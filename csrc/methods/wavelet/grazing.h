/* Per-vertex integration of narrow specular lobes at grazing views.
 *
 * Why: towards grazing, a lobe of roughness m is squeezed against the surface's horizon to about
 * 2 m cos(theta_v) radians in azimuth, while the hemi-octahedral local map's texels are pi / (2 local)
 * wide there.  Once the lobe is narrower than a few texels, the product of BRDF slice and lighting
 * slice cannot resolve it at any number of kept terms: under Blender's courtyard at m = 0.1 and
 * `high` (local 64), the pairs with views past 78 degrees carried 9.6 of 10.3 points of relative
 * RMSE.  There the lobe is integrated per vertex instead:
 *  - each lobe's half-vector rule of equal cells (wenv_lobe_cells) is tabulated over the view angle
 *    in the lobe's own frame, and interpolated node by node, so the result is continuous in the view;
 *  - a vertex turns the nodes into its frame (normal, and the view's tangent direction) and each node
 *    reads the lighting from an octahedral mip pyramid at the level whose texel matches the node's
 *    cell (filtered importance sampling, with a deterministic rule);
 *  - the shader blends this result with the wavelet one by the lobe's width in local texels,
 *    rho = 4 local m cos(theta_v) / pi: all per-vertex below `threshold`, all wavelet above twice
 *    that, smoothstep between.
 * The pyramid holds the same lighting the slices see: pixels shaded as exact lights are black. */
#ifndef WENV_GRAZING_H
#define WENV_GRAZING_H

#include <stddef.h>

#include "base/error.h"
#include "methods/wavelet/grazing_nodes.h"
#include "scene/envmap.h"
#include "scene/material.h"

/* The lighting as an octahedral mip pyramid (radiance, strength applied). */
typedef struct wenv_grazing_light wenv_grazing_light;

/* The pyramid of wenv_oct_pyramid_build; `excluded` as for wenv_oct_from_envmap, also_side and
 * also_texels (or NULL) a map made in the same pass over the image. */
wenv_status wenv_grazing_light_create(wenv_grazing_light **out, const wenv_envmap *env, const size_t *excluded,
                                      size_t n_excluded, size_t also_side, float *also_texels, wenv_error *err);
void wenv_grazing_light_free(wenv_grazing_light *light);
size_t wenv_grazing_light_bytes(const wenv_grazing_light *light);
/* Its pyramid, as the nodes read it (grazing_nodes.h). */
const wenv_node_pyramid *wenv_grazing_light_pyramid(const wenv_grazing_light *light);

/* The tabulated rules of a material's lobes. */
typedef struct wenv_grazing_rule wenv_grazing_rule;

/* threshold > 0 is rho below which a vertex is shaded by the rule alone; local_n the local map's
 * side; all_slopes puts GGX lobes on the slope grid too (wenv_wavelet_quality.grazing_slopes).  A
 * material without lobes (or with only black ones) gives *out = NULL: nothing to do. */
wenv_status wenv_grazing_rule_create(wenv_grazing_rule **out, const wenv_material *mat, size_t local_n,
                                     double threshold, int all_slopes, wenv_error *err);
void wenv_grazing_rule_free(wenv_grazing_rule *rule);
size_t wenv_grazing_rule_bytes(const wenv_grazing_rule *rule);

/* Share of the per-vertex result at cos(view) cos_v: 1 for narrow lobes near grazing, 0 where the
 * local map resolves every lobe. */
float wenv_grazing_blend(const wenv_grazing_rule *rule, float cos_v);

/* Whether the per-vertex result is the whole at every view (lobes narrower than the threshold even
 * at normal incidence), so that the material's BRDF slices would never be read. */
int wenv_grazing_every_view(const wenv_grazing_rule *rule);

/* The lobes' reflected radiance at one vertex: unit normal n, unit view v (towards the eye),
 * cos_v = n.v > 0.  Thread-safe. */
void wenv_grazing_shade(const wenv_grazing_rule *rule, const wenv_grazing_light *light, const float n[3],
                        const float v[3], float cos_v, float rgb[3]);

#endif
