/* A material's own light (a Principled BSDF's Emission), added to what a method shades.
 *
 * Why apart from the methods: emission does not depend on the lighting, so no method's tables hold it,
 * and a World's strength, which scales what is reflected, leaves it as it is.  It depends on the view
 * only through the layers it shines through (wenv_material_emission_at). */
#ifndef WENV_EMISSION_H
#define WENV_EMISSION_H

#include <stddef.h>

#include "base/error.h"
#include "scene/material.h"

/* out[i] = max(0, out[i] + emission of mat towards view i) for n vertices (views NULL: head-on, the
 * light sent to what the vertex blocks); nothing when mat emits nothing.  colours (n x 3, or NULL:
 * the material's own): each vertex's Emission Color in place of a Principled BSDF's (a texture's),
 * its Strength and the layers it shines through the material's.  WENV_ERR_NOMEM only. */
wenv_status wenv_emission_add(const wenv_material *mat, const float *colours, const float *normals,
                              const float *views, size_t n, float *out, wenv_error *err);

#endif
