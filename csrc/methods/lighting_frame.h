/* The lighting's frame: a method holds an environment image at rotation 0 and strength 1, and a
 * World's rotation and strength are applied around it.
 *
 * Why: turning the environment by r is turning every normal and view by -r under the unturned one
 * (the reflected radiance does not depend on the frame it is written in), and strength scales the
 * result linearly.  A new World rotation or strength therefore costs what a view change costs,
 * where giving the method the transformed image would remake everything it made from the lighting
 * (slices, table rows, lights, the grazing pyramid: ~0.3 s for `default` at 126k vertices).  Holding
 * the image at one canonical frame also keeps the result a function of the inputs alone, whatever
 * the environments set before.  Only a new image goes to the method. */
#ifndef WENV_LIGHTING_FRAME_H
#define WENV_LIGHTING_FRAME_H

#include <stddef.h>
#include <stdint.h>

#include "base/error.h"
#include "base/progress.h"
#include "methods/lamps/lamp_light.h"
#include "methods/material_family.h"
#include "methods/method.h"
#include "methods/vertex_colour.h"
#include "scene/envmap.h"

typedef struct {
    int have;                  /* the method holds an image */
    uint64_t image_hash;       /* of the image it holds (wenv_envmap_fingerprint) */
    size_t width, height;
    wenv_projection projection;
    double held_strength;      /* 1, or the World's own where the image at 1 would be out of range */
    float turn[9];             /* row-major: a world direction into the held image's frame */
    float scale;               /* the World's strength over the held one */
    int identity;              /* turn is the identity and scale 1 */
} wenv_lighting_frame;

/* Makes env the lighting: the method is given env's image at rotation 0 and strength 1 unless it
 * holds that image already, and the frame takes env's rotation and strength.  On failure the frame
 * and the method are as they were. */
wenv_status wenv_lighting_frame_set(wenv_lighting_frame *frame, const wenv_method *method, void *state,
                                    const wenv_envmap *env, const wenv_progress *progress, wenv_error *err);

/* method->shade under the frame: normals and views turned into the held image's frame, the
 * radiance scaled by the strength. */
wenv_status wenv_lighting_frame_shade(const wenv_lighting_frame *frame, const wenv_method *method, void *state,
                                      const float *normals, const float *views, size_t n, float *out,
                                      wenv_error *err);

/* The same with the scene in the way (method->shade_shadowed; its turn and bounce_scale are set
 * here), or with views NULL the diffuse light leaving each vertex (method->diffuse_light; scene may
 * then be NULL).  The method must provide them.  colour (NULL: the material's own) gives each
 * vertex its colour, family (NULL: the method's material) its Roughness and Metallic
 * (material_family.h; colour's per_colour table is then the family's members').  material is the
 * shader's: its own light is added, unscaled by the World's strength (emission.h; emission, one RGB
 * per vertex or NULL: each vertex's Emission Color), and so is the light of the scene's lamps
 * (lamps: NULL for none; lamps/lamp_shading.h), in the world's frame. */
wenv_status wenv_lighting_frame_shade_scene(const wenv_lighting_frame *frame, const wenv_method *method, void *state,
                                            const float *normals, const float *views, size_t n,
                                            const wenv_shadow_scene *scene, const wenv_vertex_colour *colour,
                                            const wenv_family_rows *family, const wenv_material *material,
                                            const float *emission, const wenv_lamp_rows *lamps, float *out,
                                            wenv_error *err);

#endif
