/* A material whose inputs vary per vertex: a Principled BSDF read through textures (its Roughness,
 * Metallic, Specular IOR Level and Tint, Coat Weight and Roughness, Sheen Weight, Roughness and Tint,
 * Alpha: principled_inputs.h's WENV_VERTEX_INPUTS).
 *
 * How (docs/python.md, "Roughness and Metallic per vertex"):
 *  - Metallic enters a Principled BSDF linearly (Cycles weighs the metal by Metallic and what lies
 *    under it by 1 - Metallic), so a vertex is exactly its mix of the material at Metallic 0 and at 1.
 *  - Alpha scales everything the vertex reflects and emits: it multiplies the vertex's weights.
 *  - The others change the lobes.  Where the vertices take a few distinct sets of values, each set
 *    has its own member, exactly.  Otherwise the inputs that vary are the axes of a grid: Roughness
 *    at levels 1 / WENV_FAMILY_FINEST apart (or coarser, below), each other input at 8, 4, 2 or 1
 *    steps over the range its values span; a vertex mixes the members at the corners of its cell,
 *    multilinearly.  A sun's highlight would blur that way (two highlights
 *    of other widths are not one of the width between), so the part a method shades per vertex with
 *    the BRDF itself (the wavelet methods' exact lights) is shaded apart, each vertex with a material
 *    at its own values (Roughness to 1 / WENV_FAMILY_LIGHT_STEPS, the others to 1/1024 of their range,
 *    coarser where that would make more than WENV_FAMILY_LIGHT_STEPS + 1 materials): only the rest of
 *    the lighting, smooth against the levels' spacing, is interpolated.
 *  - Emission shines through each member's layers (its coat and sheen), mixed as the rest.
 *  - The Lambertian part is the members' mixed, applied once per vertex with a colour per vertex when
 *    there is one (vertex_colour.h's irradiance).  A metal's colour is its Fresnel colour: a metal of a
 *    colour per vertex is its mix, per channel and view, of the metal in black and in white
 *    (wenv_material_metal_colour), exactly.
 * Each member is an ordinary material the method keeps made (its slices and table rows), so a new view
 * costs each vertex its two members' reads and one set of lights. */
#ifndef WENV_MATERIAL_FAMILY_H
#define WENV_MATERIAL_FAMILY_H

#include <stddef.h>
#include <stdint.h>

#include "base/error.h"
#include "methods/method.h"
#include "scene/material.h"
#include "scene/principled_inputs.h"

/* Roughness levels 0, 1/24, ..., 1: the interpolation stays within 1 % of each vertex's own material
 * (0.05-0.88 % over the bundled HDRIs: docs/performance.md, "Roughness and Metallic per vertex")... */
#define WENV_FAMILY_FINEST 24
/* ... unless the levels a roughness spans, times the metallic sides, would be more members than the
 * method keeps (less a few: method.h's materials_kept, WENV_FAMILY_SPARE_KEPT), for a family must fit
 * whole or be made again at every view: the levels are then 1/16, 1/12, 1/8, 1/4, 1/2 or 1 apart. */
#define WENV_FAMILY_SPARE_KEPT 4
/* A Roughness of at most this many distinct values (a texture of a few flat regions) has a member at
 * each, exactly, and no interpolation. */
#define WENV_FAMILY_EXACT_LEVELS 8
/* The lights' materials: Roughness to 1/8192 (a GGX peak at roughness 0.05 moves by 0.5 %). */
#define WENV_FAMILY_LIGHT_STEPS 8192
/* At most this many input channels may vary smoothly at once (a vertex mixes 2^4 corners per side: 48
 * entries of 8 bytes, 48 MB at 126k vertices); more need values of a few distinct materials. */
#define WENV_FAMILY_MAX_AXES 4

typedef struct wenv_material_family wenv_material_family;

/* base: a Principled material (WENV_ERR_VALUE otherwise); vi: the values per vertex (n each, x 3 for
 * a colour; NULL, or a NULL input: the material's own), finite (WENV_ERR_VALUE naming the first
 * vertex that is not), clamped as Cycles clamps them; more than WENV_FAMILY_MAX_AXES varying smoothly,
 * or a grid past max_members, is WENV_ERR_VALUE naming them.  colour: whether the calls give a colour per vertex too (a metal then
 * has members in black and in white).  max_members: the most members the levels may make (the
 * method's materials_kept less WENV_FAMILY_SPARE_KEPT).  Makes every member and light material the
 * vertices read. */
wenv_status wenv_material_family_create(wenv_material_family **out, const wenv_material *base,
                                        const wenv_vertex_inputs *vi, size_t n, int colour, size_t max_members,
                                        wenv_error *err);
/* Whether a colour per vertex on `base` needs a family even with its own Roughness and Metallic: a
 * Principled BSDF with Metallic above 0. */
int wenv_material_family_needed_for_colour(const wenv_material *base);
void wenv_material_family_free(wenv_material_family *family);
/* *family made for these values, unless it was made for them already (wenv_material_family_key):
 * what a caller keeps between views, so that a new view makes nothing.  The one it replaces is freed;
 * on failure *family is kept. */
wenv_status wenv_material_family_ensure(wenv_material_family **family, const wenv_material *base,
                                        const wenv_vertex_inputs *vi, size_t n, int colour, size_t max_members,
                                        wenv_error *err);

size_t wenv_material_family_vertices(const wenv_material_family *family);
/* Of the values it was made from (the material and every vertex's), for recognising them again. */
uint64_t wenv_material_family_key(const wenv_material_family *family);
/* Members made (materials the method shades), and the lights' materials. */
size_t wenv_material_family_members(const wenv_material_family *family);
size_t wenv_material_family_light_materials(const wenv_material_family *family);
/* The material the family was made from. */
const wenv_material *wenv_material_family_base(const wenv_material_family *family);

/* Which of the family's vertices a call shades: vertex k of the call is rows[k], or offset + k when
 * rows is NULL (as wenv_shadow_scene's rows). */
typedef struct {
    const wenv_material_family *family;
    const uint32_t *rows;
    size_t offset;
} wenv_family_rows;

/* Each call vertex's own materials, for what is shaded per vertex with the BRDF itself (the scene's
 * lamps, lamps/lamp_light.h): its Roughness exactly (the lights' palette where the levels are
 * interpolated, else its members) on each metallic side, weighted per channel as method.h's
 * wenv_vertex_lights (a metal's by its share of the vertex's colour, rgb; NULL without).  pick and
 * weight: room for WENV_VERTEX_LIGHTS_PICKS (x 3) per vertex; *out points into them and the family.
 * WENV_ERR_VALUE for a row past the family's vertices. */
wenv_status wenv_material_family_own(const wenv_family_rows *rows, const float *normals, const float *views, size_t n,
                                     const float *rgb, uint32_t *pick, float *weight, wenv_vertex_lights *out,
                                     wenv_error *err);

/* out[i] += each call vertex's Lambertian part (its members' mixed, times its colour rgb where given)
 * times irradiance[i], clamped at 0, for a view at normal i . view i (views NULL: head-on). */
wenv_status wenv_material_family_add_diffuse(const wenv_family_rows *rows, const float *normals, const float *views,
                                             size_t n, const float *rgb, const float *irradiance, float *out,
                                             wenv_error *err);

/* out[i] = max(0, out[i] + each call vertex's emission towards view i through its members' layers)
 * (views NULL: head-on); colours (n x 3, or NULL: the material's own) each vertex's Emission Color, as
 * emission.h's. */
wenv_status wenv_material_family_add_emission(const wenv_family_rows *rows, const float *normals, const float *views,
                                              size_t n, const float *colours, float *out, wenv_error *err);

/* Shades n (normal, view) pairs in the method's frame as method->shade / shade_shadowed (scene set)
 * would with each vertex's own material, or with views NULL its diffuse light (method.h), into out;
 * rgb (n x 3, or NULL; given only to a family made for a colour) a colour per vertex, and share
 * (n, or NULL) and horizon_light (n x 3, or NULL) what a bent Lambertian part loses, as
 * vertex_colour.h's.  The scene's own bounce must be given
 * (bounce_self 0: a mesh's light with its materials is this function's with views NULL).  Sets the
 * members as the method's material in turn and the family's base material last. */
wenv_status wenv_material_family_shade(const wenv_family_rows *rows, const wenv_method *method, void *state,
                                       const float *normals, const float *views, size_t n,
                                       const wenv_shadow_scene *scene, const float *rgb, const float *share,
                                       const float *horizon_light, float *out, wenv_error *err);

#endif
