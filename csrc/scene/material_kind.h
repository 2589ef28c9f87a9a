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

/* A model provides one function, lobe_value: lobe i's f(wi, wo).  Every other entry is an
 * accelerator or a property with a default derived from lobe_value and the lobes' shapes (material.c,
 * the wenv_material_derived_* functions below), so a new model starts with lobe_value alone and adds
 * an accelerator only where a benchmark asks for it; tests/c/core_check.c holds each model's
 * accelerators to the defaults. */
typedef struct wenv_material_kind {
    const char *name;
    int mirror_symmetric; /* f(M wi, M wo) = f(wi, wo) for every reflection M about a plane through
                           * the normal, to the model's own rounding (wenv_material_mirror_symmetric) */
    int smooth_limit; /* its lobes become Fresnel mirrors of their shape's colour and index as they
                       * narrow (a microfacet model); 0 for a measured table, which has no such limit */
    int lobes_are_shapes; /* each lobe is exactly its microfacet shape times its colour (Cook-Torrance):
                           * wenv_material_with_alpha sets it, and it follows its shape */

    /* Required for a model with lobes: lobe i's f(wi, wo), RGB, no cosine (material.h). */
    wenv_lobe_rgb_fn lobe_value;

    /* Accelerators (NULL: the derived default). */
    /* f cos summed over the lobes for one view and many directions, in double, rounded to float
     * (wenv_material_specular_cos_batch). */
    void (*specular_cos_batch)(const wenv_material *mat, const double wo[3], const float *wi, size_t n, float *rgb);
    /* The same in float for the per-vertex loops: terms made once per view, then many directions
     * (wenv_material_specular_cos_f_many); view_terms and prepare_view_f NULL for none. */
    size_t (*view_terms)(const wenv_material *mat);
    void (*prepare_view_f)(const wenv_material *mat, const float wo[3], float *terms);
    void (*specular_cos_f_many)(const wenv_material *mat, const float wo[3], const float *terms, size_t n,
                                const float *x, const float *y, const float *z, float *r, float *g, float *b);
    wenv_lobe_rgb_fn lobe_over_ndf;
    wenv_status (*lobe_albedo)(const wenv_material *mat, size_t i, const double wo[3], size_t samples, double rgb[3],
                               wenv_error *err);
    wenv_status (*lobe_nodes)(const wenv_material *mat, size_t i, const double wo[3], size_t samples, double *wi,
                              double *weight, size_t *count, wenv_error *err);
    wenv_status (*lobe_cells)(const wenv_material *mat, size_t i, const double wo[3], size_t n_theta, size_t n_phi,
                              double *wi, double *weight, double *solid_angle, size_t *count, wenv_error *err);
    double (*lobe_cos_h_min)(const wenv_material *mat, size_t i);

    /* Properties (NULL: the default named). */
    /* The Lambertian part's albedo for a view (wenv_material_diffuse_at); default the constant
     * `diffuse`. */
    void (*diffuse_at)(const wenv_material *mat, double cos_v, double rgb[3]);
    /* The same per unit of the material's colour for a view, into rgb, returning NULL; or why the
     * colour cannot vary alone (it enters the lobes too).  NULL: the colour is the constant albedo
     * (`diffuse`), the lobes free of it. */
    const char *(*diffuse_per_colour)(const wenv_material *mat, double cos_v, double rgb[3]);
    /* Whether it emits light of its own, and the radiance it emits towards a view at cos_v (RGB, not
     * lit by anything: wenv_material_emission_at); NULL: it emits nothing. */
    int (*emits)(const wenv_material *mat);
    void (*emission_at)(const wenv_material *mat, double cos_v, double rgb[3]);
    /* Set for a model with no colour input (a measured table): no per-vertex colour. */
    int no_colour;
    /* Whether the glossy part reflects about the mirror direction (wenv_material_mirror_centred);
     * default always. */
    int (*mirror_centred)(const wenv_material *mat);
    /* Whether each lobe is its shape's D times factors that vary slowly over it
     * (wenv_material_lobes_follow_shapes); default lobes_are_shapes. */
    int (*lobes_follow_shapes)(const wenv_material *mat);
    /* A copy at Blender's roughness r (finite, >= 0), for a model that takes it
     * (wenv_material_with_roughness); default: a copy for a material without lobes, else an error. */
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

/* The defaults, derived from lobe_value and the lobes' shapes: what a model gets for an accelerator it
 * leaves NULL, and what the tests hold each accelerator to.  Same contracts as material.h's. */
void wenv_material_derived_specular_cos_batch(const wenv_material *mat, const double wo[3], const float *wi,
                                              size_t n, float *rgb);
void wenv_material_derived_specular_cos_f_many(const wenv_material *mat, const float wo[3], size_t n,
                                               const float *x, const float *y, const float *z, float *r, float *g,
                                               float *b);
/* f_i 4 cos_i cos_o / D(h), D the lobe's shape's; 0 where D is. */
void wenv_material_derived_lobe_over_ndf(const wenv_material *mat, size_t i, const double wi[3], const double wo[3],
                                         double rgb[3]);
/* The shape's rules (microfacet.h) re-weighted node by node by the lobe's value over the shape's. */
wenv_status wenv_material_derived_lobe_nodes(const wenv_material *mat, size_t i, const double wo[3], size_t samples,
                                             double *wi, double *weight, size_t *count, wenv_error *err);
wenv_status wenv_material_derived_lobe_cells(const wenv_material *mat, size_t i, const double wo[3], size_t n_theta,
                                             size_t n_phi, double *wi, double *weight, double *solid_angle,
                                             size_t *count, wenv_error *err);
/* The sum of lobe_nodes' weights. */
wenv_status wenv_material_derived_lobe_albedo(const wenv_material *mat, size_t i, const double wo[3], size_t samples,
                                              double rgb[3], wenv_error *err);
/* The shape's cut when the lobes follow their shapes, else -1. */
double wenv_material_derived_lobe_cos_h_min(const wenv_material *mat, size_t i);

/* The re-weighting behind the derived rules, for a model whose own lobe value is cheaper per view:
 * count nodes wi of lobe i's shape with their shape weights (the first count of weight) become the
 * lobe's RGB weights (3 count), value(ctx, wi, rgb) giving the lobe's f at each node. */
typedef void (*wenv_lobe_value_at_fn)(const void *ctx, const double wi[3], double rgb[3]);
void wenv_material_reweight_nodes(const wenv_material *mat, size_t i, const double wo[3], const double *wi,
                                  double *weight, size_t count, wenv_lobe_value_at_fn value, const void *ctx);

#endif
