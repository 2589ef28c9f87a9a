/* The Ambient Occlusion node's share, as Cycles' svm_ao casts it: of a cosine-weighted hemisphere
 * about each point's normal, the rays that run the node's Distance without meeting the scene.
 * Cycles casts the node's Samples at each of a pixel's samples, and the pixel converges to that
 * share; here one stratified set is cast at each point (a Fibonacci spiral over the unit disk, each
 * point an equal area, lifted onto the hemisphere), turned about the normal by a hash of the
 * point's index so that neighbouring points' errors differ rather than band. */
#ifndef WENV_AMBIENT_H
#define WENV_AMBIENT_H

#include <stddef.h>

#include "base/error.h"
#include "base/progress.h"
#include "scene/occluders.h"

/* The most rays a point (Cycles' node takes at most 128 Samples). */
#define WENV_AMBIENT_MAX_RAYS 1024

/* For each of the n points (xyz floats) with its normal (xyz floats, made unit here; negated with
 * `inside`), the share of `rays` rays that run `distance` without meeting `scene`, into out (n
 * floats).  Each ray starts a little along itself (the scene's offset), passing the point's own
 * triangle as Cycles' rays skip it.  A distance of 0 or less casts nothing: every share 1.
 * WENV_ERR_VALUE for rays outside [1, WENV_AMBIENT_MAX_RAYS] or a distance that is not finite;
 * WENV_ERR_CANCELLED when progress asks to stop. */
wenv_status wenv_ambient_shares(const wenv_occluders *scene, const float *points, const float *normals, size_t n,
                                size_t rays, double distance, int inside, float *out, const wenv_progress *progress,
                                wenv_error *err);

#endif
