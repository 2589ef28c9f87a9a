/* An environment resampled onto octahedral texels (maps.h layout), as the average radiance over
 * each texel's neighbourhood.  With enough pixels (at least two per texel) each pixel's flux is
 * split between the four nearest texel centres and every texel divided by the solid angle it
 * received: a constant environment stays constant (to float rounding) and a sun keeps
 * its centroid.  Coarser environments are read by 4 x 4 bilinear lookups per texel, as is any
 * texel no pixel reached. */
#ifndef WENV_ENVMAP_OCTAHEDRAL_H
#define WENV_ENVMAP_OCTAHEDRAL_H

#include <stddef.h>

#include "base/error.h"
#include "scene/envmap.h"

/* texels: side x side x 3 floats (side even).  Radiance includes the environment's strength.
 * `excluded` (ascending pixel indices row * width + col, n_excluded of them, may be NULL) are pixels
 * shaded elsewhere: they count as black, their solid angle kept. */
wenv_status wenv_oct_from_envmap(const wenv_envmap *env, size_t side, float *texels, const size_t *excluded,
                                 size_t n_excluded, wenv_error *err);

/* The same for `count` (at most WENV_OCT_SIDES_MAX) maps of sides[k] into texels[k], in one pass over
 * the image: a new lighting makes both the wavelet methods' map and the grazing path's pyramid. */
#define WENV_OCT_SIDES_MAX 4
wenv_status wenv_oct_from_envmap_sides(const wenv_envmap *env, size_t count, const size_t *sides, float *const *texels,
                                       const size_t *excluded, size_t n_excluded, wenv_error *err);


/* Mip pyramid of the environment on octahedral maps, level k of side base >> k down to 2: level 0
 * as fine as the environment up to max_side (a power of two in [64, max_side] with about a pixel
 * per texel, or max_side itself when that is below 64; made by wenv_oct_from_envmap with `excluded`
 * black), each coarser texel the solid-angle-weighted mean of its four children (the octahedral
 * square nests).  The levels lie one after another in texels[0]'s block.  With also_texels (else
 * NULL) an also_side map is made in the same pass over the image. */
typedef struct {
    size_t levels;
    size_t side[16];
    float *texels[16];
} wenv_oct_pyramid;

wenv_status wenv_oct_pyramid_build(wenv_oct_pyramid *p, const wenv_envmap *env, const size_t *excluded, size_t n_excluded,
                                   size_t max_side, size_t also_side, float *also_texels, wenv_error *err);
void wenv_oct_pyramid_free(wenv_oct_pyramid *p);
size_t wenv_oct_pyramid_bytes(const wenv_oct_pyramid *p);

#endif
