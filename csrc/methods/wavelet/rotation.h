/* Normal samples, their frames, and the wavelet rotation matrices (docs/ARCHITECTURE.md §3.3).
 *
 * Normal samples sit at the texel centres of a normal_n x normal_n octahedral map.  Each has the
 * orthonormal frame of Duff et al. 2017 / Frisvad 2012 without the sign flip, so frames vary
 * continuously over the sphere except at n = (0, 0, -1) (docs/ARCHITECTURE.md §3.1).
 *
 * The resampling operator S_s takes the global octahedral lighting texels to the local
 * hemi-octahedral texels of sample s: every global texel is split into k x k sub-samples whose
 * flux is splatted with bilinear (tent) weights onto the local texel centres, and each local row
 * is normalised to sum to one.  Tent weights keep the centroid of a small bright source (a sun)
 * where it is, so a source smaller than a texel moves no highlight; normalising keeps a constant
 * environment exactly constant.  The rotation matrix is R_s = H_local S_s H_global^T, stored by
 * columns with entries below epsilon * sqrt(N_local / N_global) dropped (that scale is the size of
 * the constant term, the largest entry). */
#ifndef WENV_ROTATION_H
#define WENV_ROTATION_H

#include <stddef.h>
#include <stdint.h>

#include "base/error.h"
#include "base/progress.h"
#include "math/frame.h"
#include "math/sparse.h"

/* The unit normal of sample s (an octahedral texel centre); its frame is wenv_frame(n). */
void wenv_normal_sample(size_t normal_n, size_t s, double n[3]);

typedef struct {
    size_t global_n, local_n, normal_n;
    double epsilon;
    wenv_csc *matrices; /* normal_n^2 of them */
} wenv_rotation;

/* What S_s needs for every frame: the world directions of the sub-samples of each global texel
 * and their solid angles. */
typedef struct wenv_resampler wenv_resampler;
wenv_status wenv_resampler_create(wenv_resampler **out, size_t global_n, size_t local_n, wenv_error *err);
void wenv_resampler_free(wenv_resampler *rs);

/* The maps rs resamples between, and the most taps one global texel gives (4 k^2). */
size_t wenv_resampler_global_n(const wenv_resampler *rs);
size_t wenv_resampler_local_n(const wenv_resampler *rs);
size_t wenv_resampler_max_taps(const wenv_resampler *rs);

/* S_s's taps of global texel u in the local map of `frame` (tent weight x the sub-sample's solid
 * angle, before each local row's normalisation): at most wenv_resampler_max_taps pairs of local
 * texel and weight; returns how many.  Applied to an image: slice_operators.h. */
size_t wenv_resampler_texel_taps(const wenv_resampler *rs, const double frame[9], size_t u, uint32_t *tap_t,
                                 double *tap_w);

/* WENV_ERR_VALUE unless the sizes are ones the matrices can be built for. */
wenv_status wenv_rotation_check_sizes(size_t global_n, size_t local_n, size_t normal_n, wenv_error *err);

wenv_status wenv_rotation_build(wenv_rotation **out, size_t global_n, size_t local_n, size_t normal_n,
                                double epsilon, const wenv_progress *progress, wenv_error *err);
void wenv_rotation_free(wenv_rotation *rot);
size_t wenv_rotation_nnz(const wenv_rotation *rot);
/* Memory the matrices take: values, row indices and column pointers. */
size_t wenv_rotation_bytes(size_t global_n, size_t normal_n, size_t nnz);

/* What wenv_rotation_build would take in memory, in bytes, estimated from a few of its matrices
 * built at normal samples spread over the grid (a fraction of a second where the whole build takes
 * minutes); a matrix's fill varies little from one normal to the next (within ~10 %). */
wenv_status wenv_rotation_estimate_bytes(size_t global_n, size_t local_n, size_t normal_n, double epsilon,
                                         size_t *bytes, wenv_error *err);

/* local (N_local x 3, Haar domain) = R_s applied to the sparse global lighting: `count` Haar
 * coefficients with indices idx (ascending) and RGB values rgb (count x 3). */
void wenv_rotation_apply(const wenv_rotation *rot, size_t s, const uint32_t *idx, const float *rgb,
                         size_t count, float *local);

/* Cache file with a header (magic, version, sizes, epsilon) and per-sample zlib blocks each with
 * its CRC-32.  Save writes a temporary file and renames it, so readers never see a partial file.
 * Load returns WENV_ERR_IO for a missing, truncated, corrupt or mismatched file. */
wenv_status wenv_rotation_save(const wenv_rotation *rot, const char *path, wenv_error *err);
wenv_status wenv_rotation_load(wenv_rotation **out, const char *path, size_t global_n, size_t local_n,
                               size_t normal_n, double epsilon, wenv_error *err);

#endif
