/* Ground truth: the reflection equation summed over every environment pixel, each a point
 * source of flux radiance x exact pixel solid angle, with the exact BRDF.  Same units as shading. */
#ifndef WENV_REFERENCE_H
#define WENV_REFERENCE_H

#include <stddef.h>

#include "base/error.h"
#include "base/progress.h"
#include "scene/envmap.h"
#include "scene/material.h"

wenv_status wenv_reference(const wenv_envmap *env, const wenv_material *mat, const float *normals,
                           const float *views, size_t n, float *out, const wenv_progress *progress,
                           wenv_error *err);

#endif
