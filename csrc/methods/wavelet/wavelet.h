/* Environment shading by wavelet rotation (Wang et al. 2006, as the 2007 thesis built it).
 *
 * Lighting: the environment is tent-filtered onto a global octahedral map, Haar transformed and
 * cut to its largest coefficients.  For each normal sample the local lighting slice (a
 * hemi-octahedral map in the sample's frame, Haar domain) comes from the rotation matrix
 * ("rotation") or from resampling the global map directly ("slicing"); the two agree exactly when
 * nothing is truncated.  Slices are made only for normal samples that some vertex needs.
 *
 * Material: for each view sample (a hemi-octahedral grid of local view directions) the BRDF
 * slice f(w, v) cos(w) is integrated against each local texel's tent, Haar transformed and cut to
 * its largest coefficients (RGB share their indices).  The diffuse part is view-independent: it
 * uses the irradiance of each normal sample, summed over the global map with the lighting
 * (irradiance.h).
 *
 * Per vertex: the normal is interpolated bilinearly between the 4 nearest normal samples.  Each
 * sample is shaded with the view that has the same mirror direction about the sample's normal as
 * the vertex view has about the vertex normal, so a highlight stays where it belongs instead of
 * moving with the sample spacing; that view is interpolated bilinearly between the 4 nearest
 * view samples.  The 16 (normal sample, view sample) radiances are sparse dot products computed
 * once per lighting and material and kept in a table, so a new view costs 16 table reads per
 * vertex plus the dot products of pairs not seen before.
 *
 * Lights: a sun or a lamp holds most of a scene's flux in a few pixels, and wavelet truncation and
 * interpolation between samples spread its highlight over neighbouring views and normals.  The
 * brightest pixels (at most quality.lights of them, each brighter than light_threshold times the
 * mean radiance) are therefore taken out of the lighting before the transform and shaded per vertex
 * as exact directional lights with the material's own BRDF, in clusters as coarse as the lobe
 * allows (lights.h).
 *
 * Grazing: near grazing a narrow lobe is squeezed below the local map's resolution; with
 * quality.grazing > 0 such lobes are integrated per vertex over a mip pyramid of the same lighting
 * (grazing.h) and blended with the wavelet result. */
#ifndef WENV_WAVELET_H
#define WENV_WAVELET_H

#include <stddef.h>

#include "base/error.h"
#include "base/progress.h"
#include "scene/envmap.h"
#include "scene/material.h"
#include "methods/method.h"

typedef enum { WENV_WAVELET_ROTATION = 0, WENV_WAVELET_SLICING = 1 } wenv_wavelet_variant;

typedef struct {
    size_t global_n;           /* octahedral lighting map side (power of two) */
    size_t local_n;            /* hemi-octahedral slice side (power of two) */
    size_t normal_n;           /* octahedral normal-sample grid side (even) */
    size_t view_n;             /* hemi-octahedral view-sample grid side */
    size_t coefficients;       /* Haar terms kept per BRDF slice (0: all) */
    size_t light_coefficients; /* Haar terms kept of the global lighting (0: all) */
    double matrix_epsilon;     /* rotation-matrix entries dropped below this (relative) */
    size_t lights;             /* brightest pixels shaded as exact directional lights (0: none) */
    double light_threshold;    /* ... when brighter than this many times the mean radiance */
    double light_tolerance;    /* a cluster of lights is read whole when its error is within this
                                * fraction of what the vertex reflects otherwise (lights.h) */
    double grazing;            /* lobes narrower than this many local texels are integrated per vertex
                                * (grazing.h; 0: never) */
    size_t grazing_slopes;     /* 1: GGX lobes too on the grazing path's 96 slope cells (else 1024
                                * polar nodes: exact for GGX's tails, 10x the cost) */
    size_t lobe_rings;         /* a narrow lobe that its nine shadow rays find partly blocked is cast
                                * again on this many rings of rays (shadows.h; 0: the nine alone) */
} wenv_wavelet_quality;

/* Materials a shader keeps besides the current one's, most recently set first, while they hold at
 * most WENV_WAVELET_KEPT_BYTES between them: setting one of them again (meshes of a few materials
 * shaded in turn) costs nothing while the lighting holds, and its table rows as they are needed
 * after a new lighting. */
#define WENV_WAVELET_KEPT_MATERIALS 40
#define WENV_WAVELET_KEPT_BYTES ((size_t)768 << 20)

/* Slicing keeps its resampling operators (slice_operators.h) while they take at most this and an
 * eighth of the shader's memory budget: all of `default`'s (47 MB), 70 % of `high`'s (~185 MB). */
#define WENV_WAVELET_OPERATOR_BYTES ((size_t)128 << 20)

typedef struct {
    size_t rotation_nnz, rotation_bytes;
    int cache; /* 0 no cache used, 1 loaded, 2 built and saved, 3 built, save failed */
    size_t slices_ready, pairs_ready, light_terms, brdf_terms_total, direct_lights;
    size_t slice_bytes, table_bytes, brdf_bytes, grazing_bytes;
    size_t materials_kept, materials_reused; /* kept now (the current one included); set again and found */
    size_t resampling_bytes; /* slicing: the resampling operators kept (slice_operators.h) */
    double rotation_seconds;
} wenv_wavelet_stats;

typedef struct wenv_wavelet wenv_wavelet;

wenv_status wenv_wavelet_quality_check(const wenv_wavelet_quality *q, wenv_error *err);

/* cache_dir may be NULL (no disk cache).  Builds or loads the rotation matrices for
 * WENV_WAVELET_ROTATION, reporting progress. */
/* memory_budget: the most the rotation matrices may take, in bytes (0: no limit); matrices not in
 * the cache that would take more (wenv_rotation_estimate_bytes) are a WENV_ERR_VALUE, not built. */
wenv_status wenv_wavelet_create(wenv_wavelet **out, const wenv_wavelet_quality *q, wenv_wavelet_variant method,
                               const char *cache_dir, size_t memory_budget, const wenv_progress *progress,
                               wenv_error *err);

/* wenv_method_choose_default for the wavelet quality q (method.h). */
const wenv_method *wenv_wavelet_default_method(const void *q, const wenv_method_setup *setup);

/* The rotation matrices' cache file for q in cache_dir, into path (room for size bytes): named by
 * every setting that changes the matrices, epsilon to its last bit.  0 on success. */
int wenv_wavelet_rotation_cache_path(const wenv_wavelet_quality *q, const char *cache_dir, char *path, size_t size);
void wenv_wavelet_free(wenv_wavelet *sh);

wenv_status wenv_wavelet_set_environment(wenv_wavelet *sh, const wenv_envmap *env, wenv_error *err);
/* Reports to `progress` (may be NULL) as the BRDF slices are made; a cancel keeps the current material. */
wenv_status wenv_wavelet_set_material(wenv_wavelet *sh, const wenv_material *mat, const wenv_progress *progress,
                                      wenv_error *err);

/* normals and views (surface towards eye) are n x 3; need not be unit length but must be
 * non-zero and finite (the bindings check).  out is n x 3 linear RGB radiance; with irradiance
 * (n x 3, else NULL), all but the Lambertian part, which irradiance gets the light of (method.h). */
wenv_status wenv_wavelet_shade(wenv_wavelet *sh, const float *normals, const float *views, size_t n,
                              float *out, float *irradiance, wenv_error *err);
/* The same with the scene in the way (methods/wavelet/shadows.h; method.h's shade_shadowed). */
wenv_status wenv_wavelet_shade_shadowed(wenv_wavelet *sh, const float *normals, const float *views, size_t n,
                                        const wenv_shadow_scene *scene, float *out, float *irradiance,
                                        wenv_error *err);
/* method.h's materials_kept: WENV_WAVELET_KEPT_MATERIALS, or fewer where materials of the current
 * one's size pass WENV_WAVELET_KEPT_BYTES (1 before a material is set). */
size_t wenv_wavelet_materials_kept(const wenv_wavelet *sh);
/* method.h's set_lights_apart and shade_lights. */
void wenv_wavelet_set_lights_apart(wenv_wavelet *sh, int apart);
wenv_status wenv_wavelet_shade_lights(wenv_wavelet *sh, const float *normals, const float *views, size_t n,
                                      const wenv_shadow_scene *scene, const wenv_vertex_lights *lights, float *out,
                                      float *irradiance, wenv_error *err);
/* The diffuse light leaving each vertex (method.h's diffuse_light). */
wenv_status wenv_wavelet_diffuse_light(wenv_wavelet *sh, const float *normals, size_t n,
                                       const wenv_shadow_scene *scene, float *out, float *irradiance,
                                       wenv_error *err);

void wenv_wavelet_get_stats(const wenv_wavelet *sh, wenv_wavelet_stats *stats);

#endif
