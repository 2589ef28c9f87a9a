/* The slicing method's resampling S_s (rotation.h) of the global lighting texels into each normal
 * sample's local texels, kept as a sparse operator per orbit of normal samples.
 *
 * Why: S_s does not depend on the image, but splatting every global texel's sub-samples (a rotation,
 * a hemi-octahedral encoding and four tents each) cost ~0.7 ms per slice at `default`, two thirds of
 * a new image's time.  Kept, a slice is one streaming pass over its taps (and the samples of an orbit
 * that are needed together share that pass).
 *
 * Why orbits: the octahedral maps and the tangent frames (math/frame.h) share the symmetries of the
 * square about the z axis, the mirrors x -> -x, y -> -y and the swap x <-> y (8 in all): the frame
 * of M n is M's image of the frame of n up to a signed permutation P of its tangents.  So
 * S_{M^T c} G = P(S_c (G o M^T)): one operator serves the up to 8 samples of an orbit, read through a
 * permutation of the global texels and one of the local texels, and the kept operators take an
 * eighth of the memory.  A sample whose frame does not follow (none on the maps of wenv today; the
 * check stays) keeps its own operator. */
#ifndef WENV_SLICE_OPERATORS_H
#define WENV_SLICE_OPERATORS_H

#include <stddef.h>

#include "base/error.h"
#include "methods/wavelet/rotation.h"

typedef struct wenv_slice_operators wenv_slice_operators;

/* The operators of `rs` for a normal_n x normal_n grid of normal samples: orbits found now,
 * operators made as slices need them and kept while they take at most byte_budget bytes (past it a
 * slice's operator is made, applied and dropped: the same result, at the splat's cost). */
wenv_status wenv_slice_operators_create(wenv_slice_operators **out, const wenv_resampler *rs, size_t normal_n,
                                        size_t byte_budget, wenv_error *err);
void wenv_slice_operators_free(wenv_slice_operators *ops);

/* Makes (in parallel) and keeps the operators that slices[0..n) read and that are not made yet,
 * while the budget holds.  -1 when out of memory. */
int wenv_slice_operators_prepare(wenv_slice_operators *ops, const size_t *slices, size_t n);

/* One thread's scratch for wenv_slice_operators_resample. */
typedef struct wenv_slice_work wenv_slice_work;
wenv_slice_work *wenv_slice_work_new(const wenv_slice_operators *ops);
void wenv_slice_work_free(wenv_slice_work *work);

/* The samples of an orbit share its representative's operator: at most this many. */
#define WENV_ORBIT_MAX 8

/* The representative of s's orbit (samples with the same one share an operator). */
size_t wenv_slice_operators_orbit(const wenv_slice_operators *ops, size_t s);

/* locals[i] (N_local x 3, pixel domain) = S_{samples[i]} applied to the global lighting texels,
 * given as r g b and a pad (N_global x 4 floats, 16-byte aligned), for 1 <= k <= WENV_ORBIT_MAX
 * samples of one orbit: their operator is read once for all of them (a slice of a new image is
 * bound by streaming its operator from memory).  Reads only the operators, so threads may resample
 * at once.  -1 when out of memory or k is out of range. */
int wenv_slice_operators_resample(const wenv_slice_operators *ops, const size_t *samples, size_t k,
                                  const float *global_rgbx, float *const *locals, wenv_slice_work *work);

/* What the operators of `used_normals` of the normal samples would take, at most (no budget):
 * within ~10 % above what they take for the maps of AUTO_LADDER, without building one. */
size_t wenv_slice_operators_estimate_bytes(size_t global_n, size_t local_n, size_t normal_n, size_t used_normals);

/* Memory the kept operators take. */
size_t wenv_slice_operators_bytes(const wenv_slice_operators *ops);

#endif
