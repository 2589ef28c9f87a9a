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

/* The emission's view dependence is smooth (the layers' albedo over the view's cosine): a table of
 * WENV_EMISSION_TABLE_N cosines, linear between them, serves every vertex. */
#define WENV_EMISSION_TABLE_N 257
typedef struct {
    int emits; /* 0: the table is black */
    float rgb[3 * WENV_EMISSION_TABLE_N];
} wenv_emission_table;

/* mat's emission over the view's cosine; per_colour: per unit of Emission Color (the material
 * emitting white), for a colour per vertex.  WENV_ERR_NOMEM only. */
wenv_status wenv_emission_table_make(const wenv_material *mat, int per_colour, wenv_emission_table *table,
                                     wenv_error *err);
/* The table at cos_v (clamped to [0, 1]). */
void wenv_emission_table_at(const wenv_emission_table *table, float cos_v, float rgb[3]);

#endif
