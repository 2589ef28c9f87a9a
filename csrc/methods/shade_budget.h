/* Shading in blocks until a time budget is spent: how a view that rests is refined in steps that a
 * caller interleaves with its own work (the add-on's live mode, a script's refine loop). */
#ifndef WENV_SHADE_BUDGET_H
#define WENV_SHADE_BUDGET_H

#include <stddef.h>

#include "methods/lighting_frame.h"
#include "methods/method.h"

/* Shades pairs first .. n - 1 of normals and views into out (as method->shade, or with `scene` as
 * method->shade_shadowed; scene may be NULL; colour and emission, one per pair, family, material and
 * lamps may be NULL) in
 * blocks, in order,
 * until `budget` seconds have passed -- at least one block, whatever the budget -- and sets *next to
 * the first pair left unshaded (n when none is), under `frame` (wenv_lighting_frame_shade).  Pairs before `first` and after *next are not
 * touched.  A budget of infinity shades them all. */
wenv_status wenv_shade_for(const wenv_lighting_frame *frame, const wenv_method *method, void *state,
                           const float *normals, const float *views, size_t n, const wenv_shadow_scene *scene,
                           const wenv_vertex_colour *colour, const wenv_family_rows *family,
                           const wenv_material *material, const float *emission, const wenv_lamp_rows *lamps,
                           size_t first, double budget, float *out, size_t *next, wenv_error *err);

#endif
