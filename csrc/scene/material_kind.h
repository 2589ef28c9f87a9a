/* What a reflectance model implements to be a material (scene/material.h).  Only the models'
 * own files include this; everything else sees materials through material.h. */
#ifndef WENV_MATERIAL_KIND_H
#define WENV_MATERIAL_KIND_H

#include <stdatomic.h>
#include <stdint.h>

#include "scene/material.h"

/* Data a model shares between the copies of a material (a measured table): counted, freed with the
 * last copy, so a shader's copy of a material costs no copy of its table. */
typedef struct wenv_shared {
    atomic_size_t refs;
    void (*destroy)(struct wenv_shared *shared);
    uint64_t fingerprint; /* of what the model made it from (base/fingerprint.h): wenv_material_same */
} wenv_shared;

typedef struct wenv_material_kind {
    const char *name;
    int mirror_symmetric; /* f(M wi, M wo) = f(wi, wo) for every reflection M about a plane through
                           * the normal, to the model's own rounding (wenv_material_mirror_symmetric) */
    int smooth_limit; /* its lobes become Fresnel mirrors of their shape's colour and index as they
                       * narrow (a microfacet model); 0 for a measured table, which has no such limit */
    /* The glossy part (see material.h for each contract). */
    void (*specular_cos)(const wenv_material *mat, const double wi[3], const double wo[3], double rgb[3]);
    void (*specular_cos_batch)(const wenv_material *mat, const double wo[3], const float *wi, size_t n, float *rgb);
    size_t (*view_terms)(const wenv_material *mat);
    void (*prepare_view_f)(const wenv_material *mat, const float wo[3], float *terms);
    wenv_specular_cos_f_fn specular_cos_f;
    /* Optional: specular_cos_f over arrays (wenv_material_specular_cos_f_many); NULL loops over it. */
    void (*specular_cos_f_many)(const wenv_material *mat, const float wo[3], const float *terms, size_t n,
                                const float *x, const float *y, const float *z, float *r, float *g, float *b);
    double (*lobe_cos_h_min)(const wenv_material *mat, size_t i);
    wenv_lobe_rgb_fn lobe_value;
    wenv_lobe_rgb_fn lobe_over_ndf;
    wenv_status (*lobe_albedo)(const wenv_material *mat, size_t i, const double wo[3], size_t samples, double rgb[3],
                               wenv_error *err);
    wenv_status (*lobe_nodes)(const wenv_material *mat, size_t i, const double wo[3], size_t samples, double *wi,
                              double *weight, size_t *count, wenv_error *err);
    wenv_status (*lobe_cells)(const wenv_material *mat, size_t i, const double wo[3], size_t n_theta, size_t n_phi,
                              double *wi, double *weight, double *solid_angle, size_t *count, wenv_error *err);
    /* Optional: the Lambertian part's albedo for a view (wenv_material_diffuse_at); NULL when it is
     * the constant `diffuse`. */
    void (*diffuse_at)(const wenv_material *mat, double cos_v, double rgb[3]);
    /* Optional: whether the glossy part reflects about the mirror direction (material.h,
     * wenv_material_mirror_centred); NULL for always. */
    int (*mirror_centred)(const wenv_material *mat);
    /* Optional: whether each lobe is its shape's D times factors that vary slowly over it
     * (wenv_material_lobes_follow_shapes); NULL for never. */
    int (*lobes_follow_shapes)(const wenv_material *mat);
    /* Optional: a copy with every lobe at `roughness` (already validated); NULL if the model cannot. */
    wenv_status (*with_roughness)(wenv_material **out, const wenv_material *src, double roughness, wenv_error *err);
} wenv_material_kind;

struct wenv_material {
    const wenv_material_kind *kind;
    double diffuse[3];
    size_t n_lobes;
    wenv_lobe *lobes; /* owned: the lobes' shapes (Cook-Torrance: the lobes) */
    wenv_shadowing shadowing;
    wenv_shared *shared; /* the model's data, or NULL */
};

/* Checks diffuse and the lobes and makes the common part (lobes copied); the kind fills the rest. */
wenv_status wenv_material_alloc(wenv_material **out, const wenv_material_kind *kind, const double diffuse[3],
                                const wenv_lobe *lobes, size_t n_lobes, wenv_shadowing shadowing, wenv_error *err);

#endif
