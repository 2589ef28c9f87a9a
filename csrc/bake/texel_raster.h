/* Which texel centres of an image each triangle of a UV map covers, and where in it: what a bake
 * shades per texel (the add-on's bake.py). */
#ifndef WENV_TEXEL_RASTER_H
#define WENV_TEXEL_RASTER_H

#include <stddef.h>
#include <stdint.h>

#include "base/error.h"
#include "base/progress.h"

/* For each texel of a width x height image (row 0 at v = 0, texel (x, y)'s centre at
 * ((x + 0.5) / width, (y + 0.5) / height)), the triangle of `triangles` (n_triangles x 3 indices
 * into uv, n_uv points of 2 floats) whose UV triangle holds the centre, or -1: into triangle_out
 * (width * height), with the barycentric weights of the triangle's second and third corners into
 * weights_out (2 per texel; the first corner's is 1 minus both; 0 where no triangle).
 * A centre on an edge two triangles share belongs to one of them (the top-left rule, whichever way
 * each is wound); a triangle of no UV area covers nothing.  Where islands overlap, the first
 * triangle keeps the texel and *overlapped counts it; *covered counts the texels with a triangle.
 * With `border`, each texel outside every triangle that touches one inside (8-neighbours) gets that
 * neighbour's triangle t as -2 - t, and its centre's weights in it, extrapolated: a bake shades the
 * islands' first ring as the surface continued, so that filtering across a seam reads it.
 * ValueError for an index past n_uv or a coordinate that is not finite. */
wenv_status wenv_texel_raster(const float *uv, size_t n_uv, const uint32_t *triangles, size_t n_triangles,
                              size_t width, size_t height, int border, int32_t *triangle_out, float *weights_out,
                              size_t *covered, size_t *overlapped, const wenv_progress *progress, wenv_error *err);

#endif
