/* Reflectance models shared by shading, the reference integrator and the glossmeter.
 *
 * Directions are unit vectors in a local frame whose +Z is the surface normal.  Cook-Torrance uses
 * the modern microfacet form f = F D G / (4 cos_i cos_o) (REFERENCE.md §2), D normalised so that
 * the projected microfacet area integrates to one, roughness m the RMS slope (Beckmann) or alpha
 * (GGX), exact unpolarised dielectric Fresnel at the lobe's index of refraction, and either
 * Smith's shadowing-masking with the distribution's exact Lambda (height-correlated form
 * G2 = 1 / (1 + Lambda(wi) + Lambda(wo))) or the original Cook-Torrance V-cavity term. */
#ifndef WENV_BRDF_H
#define WENV_BRDF_H

#include <stddef.h>

#include "error.h"

typedef enum { WENV_NDF_BECKMANN = 0, WENV_NDF_GGX = 1 } wenv_distribution;
typedef enum { WENV_SHADOW_SMITH = 0, WENV_SHADOW_VCAVITY = 1 } wenv_shadowing;

typedef struct {
    double specular[3];   /* RGB scale of the lobe, each >= 0 */
    double roughness;     /* m > 0 */
    double ior;           /* n > 1 */
    wenv_distribution distribution;
} wenv_lobe;

typedef struct {
    double diffuse[3]; /* Lambertian albedo: f_d = diffuse / pi */
    size_t n_lobes;
    wenv_lobe *lobes;  /* owned */
    wenv_shadowing shadowing;
} wenv_material;

/* Validates and copies; WENV_ERR_VALUE naming the offending field ("diffuse", "lobes[1].roughness"...). */
wenv_status wenv_material_create(wenv_material **out, const double diffuse[3], const wenv_lobe *lobes,
                                 size_t n_lobes, wenv_shadowing shadowing, wenv_error *err);
wenv_status wenv_material_copy(wenv_material **out, const wenv_material *src, wenv_error *err);
void wenv_material_free(wenv_material *mat);

/* Unpolarised Fresnel reflectance of a dielectric of index `ior` (outside index 1), cos_i in [0, 1]. */
double wenv_fresnel_dielectric(double cos_i, double ior);

/* Microfacet distribution D(h) for cos_h = n . h; 0 for cos_h <= 0. */
double wenv_ndf(wenv_distribution dist, double m, double cos_h);

/* Smith's Lambda for a direction at cos_theta to the normal. */
double wenv_smith_lambda(wenv_distribution dist, double m, double cos_theta);

/* One lobe's F D G / (4 cos_i cos_o), without its colour; 0 if either direction is below the
 * horizon. */
double wenv_lobe_eval(const wenv_lobe *lobe, wenv_shadowing shadowing, const double wi[3],
                      const double wo[3]);

/* Whole material times the incident cosine: f(wi, wo) * cos_i, RGB; 0 below the horizon. */
void wenv_material_eval_cos(const wenv_material *mat, const double wi[3], const double wo[3],
                            double rgb[3]);

/* Specular lobes only (no diffuse term), times the incident cosine, RGB. */
void wenv_material_specular_cos(const wenv_material *mat, const double wi[3], const double wo[3],
                                double rgb[3]);

/* Specular part times the incident cosine for many incident directions wi (n x 3 floats, local
 * frame) and one view wo: rgb_out is n x 3.  Per-view terms are computed once. */
void wenv_material_specular_cos_batch(const wenv_material *mat, const double wo[3], const float *wi, size_t n,
                                      float *rgb_out);

#endif
