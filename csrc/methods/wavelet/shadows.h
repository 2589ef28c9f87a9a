/* Shading with the scene in the way, for the wavelet methods.
 *
 * A vertex's unshadowed radiance is what the wavelet table gives: the lighting times the BRDF over
 * its whole hemisphere.  Its blocked texels (scene/occlusion.h: an r x r hemi-octahedral map in its
 * frame) take away the lighting they hide and give back what the blocker sends through them:
 *
 *     L_o = L_o,unshadowed - sum over blocked t of (Lbar_t - B_t) R_t(v)
 *
 * with Lbar_t the environment (its exact lights taken out) read over texel t's solid angle from the
 * mip pyramid at the texel's footprint, B_t the blocker's light where texel t's ray hits it (its
 * vertices' bounce light, interpolated), and R_t(v) the material's reflection integrated over the
 * texel: the lobes' f cos by their node rules (so that a narrow lobe lands in the texel it points
 * into) at views on a grid of the vertex's frame, and the Lambertian part as its albedo / pi times
 * the texel's cosine integral.  Lbar_t - B_t does not depend on the view: it is kept per blocked
 * texel while the lighting and the scene hold, and a view change costs a few multiply-adds per
 * blocked texel of each vertex that has any.
 *
 * The exact lights (suns, lamps) are tested in their own directions: where the mask is open or
 * blocked all around a light's texel, it says; elsewhere one ray is cast, so a sun's shadow edge is
 * as sharp as the geometry.  Clusters of lights wider than half a texel are read by their parts.
 *
 * What is not exact: within a blocked texel the lighting is its mean over the texel, so a lobe
 * narrower than a texel that sees part of one reads the mean where it would read its own part; and
 * a blocker sends one bounce, read at the texel's centre ray: its Lambertian light (head-on) from
 * its vertices, or what the caller gives per hit (method.h: bounce_hits). */
#ifndef WENV_SHADOWS_H
#define WENV_SHADOWS_H

#include <stddef.h>
#include <stdint.h>

#include "base/error.h"
#include "methods/method.h"
#include "methods/wavelet/grazing_nodes.h"
#include "methods/wavelet/light_memo.h"
#include "methods/wavelet/lights.h"
#include "scene/material.h"

/* A material's reflection integrated over each texel of the r x r mask map, RGB: the lobes' f cos at
 * `views` x `views` view directions (texel centres of a hemi-octahedral map of views in the vertex's
 * frame) as shares of their albedo, and the cosine's integral (the Lambertian part's weight, the
 * same for every view); with each texel's centre direction and footprint, read for every blocked
 * texel of every mask. */
typedef struct {
    size_t resolution, views;
    float *specular;  /* views^2 x r^2 x 3; NULL for a material without lobes */
    float *cosine;    /* r^2 */
    float *direction; /* r^2 x 3: the texel's centre, local (+Z the normal) */
    float *footprint; /* r^2: log2 of the square root of its solid angle */
} wenv_texel_reflection;

#define WENV_TEXEL_REFLECTION_VIEWS 16

wenv_status wenv_texel_reflection_make(wenv_texel_reflection *out, const wenv_material *mat, size_t resolution,
                                       wenv_error *err);
void wenv_texel_reflection_free(wenv_texel_reflection *t);

/* What one vertex's shading needs of the scene: its frame (that of its mask), its mask, where its
 * lights' rays start, and the lights' visibility test. */
typedef struct {
    wenv_light_visibility lights; /* first: the lights' walk hands this back */
    float frame[9];               /* rows: the frame's x, y, z (z the normal), in the method's frame */
    const float *turn;            /* a world direction into the method's frame (the scene's) */
    const uint64_t *mask;         /* bit t set: texel t open */
    size_t resolution;
    const wenv_occluders *occluders;
    float origin[3];
    wenv_light_memo *memo;         /* where the lights' rays' answers are kept (NULL: nowhere) */
    wenv_light_memo_slot *memo_slot; /* this vertex's */
    int point_rays;                  /* point-like directions always cast (wenv_occlusion's) */
} wenv_vertex_shadow;

/* Sets vs for vertex i of scene's occlusion, which must hold a mask for it (slot >= 0); its lights'
 * rays are kept in memo's slot for it, if memo is given. */
void wenv_vertex_shadow_init(wenv_vertex_shadow *vs, const wenv_shadow_scene *scene, size_t i, wenv_light_memo *memo);

/* Subtracts from s the lobes' share of what vertex vs's blocked texels hide: sum over them of
 * blocked[k] (RGB, one per blocked texel in texel order) x R_t(v), v the unit view (in the method's
 * frame), R_t the table's share times the lobes' albedo at the vertex's view. */
void wenv_shadow_specular(const wenv_vertex_shadow *vs, const wenv_texel_reflection *tr, const float *blocked,
                          const float v[3], const float albedo[3], float s[3]);

/* Whether lobes no wider than alpha_max (their alpha) are narrow against the masks' texels at
 * `resolution`: then they are seen through their own rays (wenv_shadow_narrow_specular). */
int wenv_shadow_lobes_narrow(double alpha_max, size_t resolution);

/* Lobes narrower than this (their alpha) are seen through their mirror direction alone, even with
 * point rays: their reflected directions stay within about two degrees of it. */
#define WENV_LOBE_RAYS_ALPHA_MIN 0.02f

/* The most rings a narrow lobe's shadow rays may be cast again on (wenv_wavelet_quality.lobe_rings):
 * 6, 10, 14, ... rays a ring, 160 on 8. */
#define WENV_LOBE_RINGS_MAX 8

/* For lobes narrow against a texel (the widest's alpha; unit view v at unit normal n, cos_v = n.v,
 * in the method's frame): what the lobes reflect, s, is kept for the share of the lobe that reaches
 * the sky -- without point rays, or below WENV_LOBE_RAYS_ALPHA_MIN, its mirror direction's answer
 * (the mask where its texels about it agree, else a ray); with point rays, nine rays through half
 * vectors at the lobe's slope quantiles, since a 4 x 4 mask's texel is wider than a metal's lobe and
 * one ray would cut its blurred mirror image of a blocker as sharply as a mirror's; where the nine
 * disagree (a blocker's edge crosses the lobe), `fine_rings` rings of rays in their place (0: the
 * nine alone) -- and is the albedo times the blocker's light for the rest (lbar and hidden as the
 * vertex's blocked texels hold them: the blocker's light is their difference, read about the mirror
 * direction).  With the rays and the lighting's pyramid, s is kept for the share of its light the
 * open rays carry, each ray's weight times the lighting along it (pyramid NULL: the lobe's share,
 * the lighting taken as uniform over it). */
void wenv_shadow_narrow_specular(const wenv_vertex_shadow *vs, const wenv_node_pyramid *pyramid, const float *lbar,
                                 const float *hidden, const float n[3], const float v[3], float cos_v, float alpha,
                                 size_t fine_rings, const float albedo[3], float s[3]);

/* For each blocked texel of vertex vs (texel order), the environment read over its solid angle into
 * lbar (3 floats each); returns sum of lbar x the texel's cosine integral into e_hidden (the texels'
 * of tr, at the masks' resolution). */
void wenv_shadow_hidden_light(const wenv_vertex_shadow *vs, const wenv_node_pyramid *pyramid,
                              const wenv_texel_reflection *tr, float *lbar, float e_hidden[3]);

/* The blocker's light B through each blocked texel of mask slot k (hits in texel order): the
 * scene's bounce per hit, or its bounce per occluder vertex interpolated at the hit; subtracted from lbar (in place), and
 * sum of the change x the texels' cosine integrals added to e_hidden. */
void wenv_shadow_bounce(const wenv_shadow_scene *scene, size_t slot, const float *cosine, float *lbar,
                        float e_hidden[3]);

#endif
