/* Reflectance models shared by shading, the reference integrator and the glossmeter.
 *
 * Directions are unit vectors in a local frame whose +Z is the surface normal.  Cook-Torrance uses
 * the modern microfacet form f = F D G / (4 cos_i cos_o) (REFERENCE.md §2), D normalised so that
 * the projected microfacet area integrates to one, roughness m the RMS slope (Beckmann) or alpha
 * (GGX), exact unpolarised dielectric Fresnel at the lobe's index of refraction, and either
 * Smith's shadowing-masking with the distribution's exact Lambda (height-correlated form
 * G2 = 1 / (1 + Lambda(wi) + Lambda(wo))) or the original Cook-Torrance V-cavity term.
 *
 * Why height-correlated Smith: it is the form Heitz (2014, "Understanding the Masking-Shadowing
 * Function in Microfacet-Based BRDFs") recommends; unlike the separable G1(wi) G1(wo) it accounts
 * for the correlation between masking and shadowing by the same microsurface heights, is exact for
 * the Smith microsurface profile, and is reciprocal.  Lambda is the exact one of the distribution:
 * Beckmann Lambda(a) = (erf(a) - 1) / 2 + exp(-a^2) / (2 a sqrt(pi)), GGX
 * Lambda = (-1 + sqrt(1 + m^2 tan^2)) / 2, with a = 1 / (m tan theta).
 * V-cavity: G = min(1, 2 cos_h cos_o / (wo.h), 2 cos_h cos_i / (wi.h)) (Cook & Torrance 1982).
 *
 * Numerics: every function returns finite values for valid inputs, including directions exactly at
 * the normal or the horizon, cos_h -> 0 and roughness from WENV_ROUGHNESS_MIN to WENV_ROUGHNESS_MAX.
 * Evaluation never skips work for negligible D (exactness first).  Materials are immutable after
 * creation, so one material may be evaluated from many threads at once. */
#ifndef WENV_BRDF_H
#define WENV_BRDF_H

#include <stddef.h>

#include "base/error.h"

typedef enum { WENV_NDF_BECKMANN = 0, WENV_NDF_GGX = 1 } wenv_distribution;
typedef enum { WENV_SHADOW_SMITH = 0, WENV_SHADOW_VCAVITY = 1 } wenv_shadowing;

typedef struct {
    double specular[3];   /* RGB scale of the lobe, each >= 0 */
    double roughness;     /* m > 0 */
    double ior;           /* n > 1 */
    wenv_distribution distribution;
} wenv_lobe;

/* Accepted parameter ranges (checked by wenv_material_create).  Roughness has a tiny positive floor
 * rather than 0: below it the lobe is a mirror whose peak value overflows float32 (D(n) = 1/(pi m^2)),
 * and no quadrature or float32 direction resolves it anyway. */
#define WENV_ROUGHNESS_MIN 1e-6
#define WENV_ROUGHNESS_MAX 10.0
#define WENV_IOR_MAX 10.0

/* cos(89.9 deg): the lowest view that shading tabulates a lobe for; views beyond read its limit. */
#define WENV_GRAZING_Z 0.0017453283658983088

/* The struct tag lets bindings.h forward-declare `struct wenv_material` without including this file. */
typedef struct wenv_material {
    double diffuse[3]; /* Lambertian albedo: f_d = diffuse / pi */
    size_t n_lobes;
    wenv_lobe *lobes;  /* owned */
    wenv_shadowing shadowing;
} wenv_material;

/* Validates and copies; WENV_ERR_VALUE naming the offending field ("diffuse", "lobes[1].roughness"...).
 * Rules: diffuse finite in [0, 1] per channel (energy conservation); specular finite >= 0; roughness
 * finite in [WENV_ROUGHNESS_MIN, WENV_ROUGHNESS_MAX]; ior finite in (1, WENV_IOR_MAX]; known
 * distribution and shadowing enums.  n_lobes = 0 (lobes may be NULL) gives a Lambertian material. */
wenv_status wenv_material_create(wenv_material **out, const double diffuse[3], const wenv_lobe *lobes,
                                 size_t n_lobes, wenv_shadowing shadowing, wenv_error *err);
wenv_status wenv_material_copy(wenv_material **out, const wenv_material *src, wenv_error *err);
void wenv_material_free(wenv_material *mat);

/* A new material equal to `src` except that every lobe's roughness is set to `roughness` (validated
 * like wenv_material_create, error names "roughness").  Setting one value rather than scaling keeps
 * the glossmeter's one-parameter inverse (find m giving a target gloss) direct for the common
 * single-lobe case; for a material without lobes it is a plain copy. */
wenv_status wenv_material_with_roughness(wenv_material **out, const wenv_material *src, double roughness,
                                         wenv_error *err);

/* Unpolarised Fresnel reflectance of a dielectric of index `ior` (outside index 1), cos_i in [0, 1]. */
double wenv_fresnel_dielectric(double cos_i, double ior);

/* Microfacet distribution D(h) for cos_h = n . h; 0 for cos_h <= 0. */
double wenv_ndf(wenv_distribution dist, double m, double cos_h);

/* Smith's Lambda for a direction at cos_theta to the normal.  0 at the normal; towards the horizon it
 * grows like 1/cos_theta and is clamped to a large finite value for cos_theta <= 1e-150. */
double wenv_smith_lambda(wenv_distribution dist, double m, double cos_theta);

/* One lobe's F D G / (4 cos_i cos_o), without its colour; 0 if either direction is at or below the
 * horizon (z <= 0).  Directions are unit vectors. */
double wenv_lobe_eval(const wenv_lobe *lobe, wenv_shadowing shadowing, const double wi[3],
                      const double wo[3]);

/* Whole material times the incident cosine: f(wi, wo) * cos_i, RGB; 0 below the horizon. */
void wenv_material_eval_cos(const wenv_material *mat, const double wi[3], const double wo[3],
                            double rgb[3]);

/* Specular lobes only (no diffuse term), times the incident cosine, RGB. */
void wenv_material_specular_cos(const wenv_material *mat, const double wi[3], const double wo[3],
                                double rgb[3]);

/* Batch form of wenv_material_specular_cos for one view and n incident unit directions (float xyz
 * triples): rgb_out[3k..3k+2] = specular_cos(wi[k], wo).  Terms that depend on the view only (Smith
 * Lambda(wo) per lobe, via K(wo)) are computed once per block of directions; the per-pair code and
 * the order of the double sums are the scalar path's, so for the same (float) directions the results
 * are identical to wenv_material_specular_cos rounded to float.  wo at or below the horizon gives 0.
 * Reentrant, no allocation. */
void wenv_material_specular_cos_batch(const wenv_material *mat, const double wo[3], const float *wi,
                                      size_t n, float *rgb_out);

/* Float forms of wenv_material_specular_cos for hot per-vertex loops (the shading's direct lights):
 * same formulation, float precision (relative error ~1e-5 against the double path where the value
 * is not negligible).  wenv_material_view_k_f fills k_o[n_lobes] with the terms that depend on the
 * view only; pass them to every wenv_material_specular_cos_f call with that view. */
void wenv_material_view_k_f(const wenv_material *mat, const float wo[3], float *k_o);
void wenv_material_specular_cos_f(const wenv_material *mat, const float wi[3], const float wo[3], const float *k_o,
                                  float rgb[3]);

/* Directional albedo rho(wo) = integral over the hemisphere of f(wi, wo) cos_i d wi, RGB, by a
 * deterministic product quadrature per lobe in half-vector space: Gauss-Legendre over the part of
 * the distribution's CDF of theta_h whose mirror direction is above the horizon (`samples` nodes,
 * graded towards the horizon) times `samples` azimuth nodes on the mirror-symmetric half circle; the
 * diffuse part is exact.  samples in [8, 4096].  With 128, Smith lobes are accurate to ~2e-5 for
 * roughness 0.01..3 and views up to 89.9 degrees; V-cavity lobes (whose min() has kinks) to ~1e-4
 * up to 89 degrees, while beyond ~89.5 degrees they need samples >= 512 for 1e-3.  0 for wo at or
 * below the horizon.  Cost: samples^2 lobe evaluations per lobe. */
wenv_status wenv_material_albedo(const wenv_material *mat, const double wo[3], size_t samples,
                                 double rgb[3], wenv_error *err);

/* One lobe's albedo (no colour) by the same quadrature.  include_fresnel = 0 replaces F by 1: the
 * white-furnace check of the microfacet part D G alone, which must not exceed 1. */
wenv_status wenv_lobe_albedo(const wenv_lobe *lobe, wenv_shadowing shadowing, const double wo[3],
                             size_t samples, int include_fresnel, double *albedo, wenv_error *err);

/* The nodes of that rule for one lobe (with Fresnel, without colour), for integrals of other
 * functions against the lobe: directions wi (unit, above the horizon) and weights with
 * sum_k weight[k] g(wi[k]) ~ Int g(wi) f(wi, wo) cos_i d wi for smooth g; the weights sum to the
 * albedo.  The half-circle rule is mirrored about the plane of wo and the normal, so wi and weight
 * need room for 2 samples^2 nodes (3 doubles per direction); *count gets the number written. */
wenv_status wenv_lobe_nodes(const wenv_lobe *lobe, wenv_shadowing shadowing, const double wo[3], size_t samples,
                            double *wi, double *weight, size_t *count, wenv_error *err);

/* The same rule as midpoints of equal cells -- n_theta in the distribution's graded CDF times n_phi
 * in the azimuth map over the half circle, mirrored -- for integrands that are not smooth, such as
 * an environment's radiance: with each node also the solid angle in wi its cell covers
 * (solid_angle), the radiance can be read pre-filtered over that footprint.  Always writes
 * 2 n_theta n_phi nodes (wi 3 doubles each), in the same order for every wo, so that rules for
 * neighbouring views can be interpolated node by node; nodes that rounding puts below the horizon,
 * and all nodes of a view at or below it, have weight 0.  n_theta, n_phi in [1, 4096]. */
wenv_status wenv_lobe_cells(const wenv_lobe *lobe, wenv_shadowing shadowing, const double wo[3], size_t n_theta,
                            size_t n_phi, double *wi, double *weight, double *solid_angle, size_t *count,
                            wenv_error *err);

#endif
