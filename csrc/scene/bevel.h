/* The Bevel node's normal, as Cycles' svm_bevel converges to it: the mean of the smooth normals of
 * the object's own surface within the node's radius of the point, weighted over the surface's area
 * by Cycles' cubic falloff, (radius - r)^3.  Cycles estimates that integral with rays across a
 * disk about three axes (multiple importance sampled, so that every part of the surface is found
 * whatever its slope); here it is integrated over the triangles near the point, found by Embree. */
#ifndef WENV_BEVEL_H
#define WENV_BEVEL_H

#include <stddef.h>

#include "base/error.h"
#include "base/progress.h"
#include "scene/occluders.h"

/* For each of the n points (xyz floats), the unit bevelled normal into out (n x 3 floats), or
 * (0, 0, 0) where no surface lies within its radius (Cycles then keeps the point's own normal):
 * radii[i] where radii is given (a radius of 0 or less reads nothing, as Cycles'), else `radius`.
 * `surface` is the object's own triangles alone; corner_normals holds each triangle's three smooth
 * normals (9 floats a triangle, in the surface's order; a flat face's are its own normal).
 * WENV_ERR_VALUE for a radius that is not finite (or, without radii, not positive);
 * WENV_ERR_CANCELLED when progress asks to stop. */
wenv_status wenv_bevel_normals(const wenv_occluders *surface, const float *corner_normals, const float *points,
                               size_t n, double radius, const float *radii, float *out, const wenv_progress *progress,
                               wenv_error *err);

#endif
