/* An environment's radiance projected onto real spherical harmonics (math/spherical_harmonics.h
 * for the basis and its conventions). */
#ifndef WENV_ENVMAP_SH_H
#define WENV_ENVMAP_SH_H

#include <stddef.h>

#include "base/error.h"
#include "base/progress.h"
#include "math/spherical_harmonics.h"
#include "scene/envmap.h"

/* Coefficients (count x 3, RGB interleaved) of the environment's radiance.  Pixels are summed in
 * blocks of `block` x `block` (1: every pixel a point of its exact solid angle, as wenv_reference
 * sums them), each block's flux placed at its flux-weighted mean direction.  Parallel; reports
 * progress. */
wenv_status wenv_sh_project_envmap_blocks(const wenv_envmap *env, size_t order, size_t block, double *coeffs,
                                          const wenv_progress *progress, wenv_error *err);

/* The block side wenv_sh_project_envmap uses for `order`: as coarse as keeps band `order` within
 * about 1 % (on a 1024 x 512 image: 16 pixels at order 2, 10 at order 8, 2 at order 32).  A block's
 * flux-weighted direction keeps a lone sun exact. */
#define WENV_SH_BLOCK_MAX 16
size_t wenv_sh_projection_block(const wenv_envmap *env, size_t order);
wenv_status wenv_sh_project_envmap(const wenv_envmap *env, size_t order, double *coeffs,
                                   const wenv_progress *progress, wenv_error *err);

#endif
