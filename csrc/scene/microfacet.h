/* One microfacet lobe: the mathematics Cook-Torrance materials are made of, and the shape every
 * material describes its glossy lobes by (scene/material.h).
 *
 * Directions are unit vectors in a local frame whose +Z is the surface normal.  Cook-Torrance uses
 * the modern microfacet form f = F D G / (4 cos_i cos_o) (docs/ARCHITECTURE.md §3.6), D normalised so that
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
 * the normal or the horizon, cos_h -> 0 and roughness from WENV_ALPHA_MIN to WENV_ALPHA_MAX.
 * Evaluation never skips work for negligible D (exactness first). */
#ifndef WENV_MICROFACET_H
#define WENV_MICROFACET_H

#include <float.h>
#include <math.h>
#include <stddef.h>

#include "base/error.h"
#include "math/vector_math.h"

typedef enum { WENV_NDF_BECKMANN = 0, WENV_NDF_GGX = 1 } wenv_distribution;
typedef enum { WENV_SHADOW_SMITH = 0, WENV_SHADOW_VCAVITY = 1 } wenv_shadowing;

typedef struct {
    double specular[3];   /* RGB scale of the lobe, each >= 0 */
    double alpha;         /* Beckmann's RMS slope m or GGX's alpha, > 0 (not Blender's roughness r: alpha = r^2) */
    double ior;           /* n > 1 */
    wenv_distribution distribution;
} wenv_lobe;

/* The accepted ranges, here and nowhere else (the bindings and the add-on read them from here).
 * Roughness has a tiny positive floor rather than 0: below it the lobe is a mirror whose peak value
 * overflows float32 (D(n) = 1/(pi m^2)), and no quadrature or float32 direction resolves it anyway. */
#define WENV_ALPHA_MIN 1e-6
#define WENV_ALPHA_MAX 10.0
#define WENV_IOR_MAX 10.0

/* The one roughness conversion: Blender's (the Principled BSDF's) perceptual roughness r to a
 * distribution's alpha, alpha = r^2 as Cycles squares it, floored at WENV_ALPHA_FROM_ROUGHNESS_MIN
 * (a perfect mirror has no lobe width to shade). */
#define WENV_ALPHA_FROM_ROUGHNESS_MIN 1e-4
double wenv_alpha_from_roughness(double roughness);

/* cos(89.9 deg): the lowest view that shading tabulates a lobe for; views beyond read its limit. */
#define WENV_GRAZING_Z 0.0017453283658983088

/* WENV_ERR_VALUE naming the field ("lobes[1].alpha") unless the lobe is within the ranges. */
wenv_status wenv_lobe_check(const wenv_lobe *lobe, size_t index, wenv_error *err);

/* Microfacet distribution D(h) for cos_h = n . h; 0 for cos_h <= 0. */
double wenv_ndf(wenv_distribution dist, double m, double cos_h);

/* The distribution's CDF over tan^2(theta_h), the share xi of D cos_h d omega_h within theta_h, as
 * xi and 1 - xi (*rest), each without cancellation; and its inverse, tan^2 at (xi, 1 - xi).  What
 * the lobe's rules and split-sum's importance samples are graded by. */
void wenv_ndf_cdf(wenv_distribution dist, double m, double tan2, double *xi, double *rest);
double wenv_ndf_tan2_at(wenv_distribution dist, double m, double xi, double rest);

/* The slope distribution D cos^4(theta_h) at tan^2(theta_h) = p^2 + q^2: D cos_h d omega_h = P dp dq
 * over the half vector's slopes (p, q) (the glossmeter integrates over slopes). */
double wenv_slope_density(wenv_distribution dist, double m, double tan2);

/* Smith's Lambda for a direction at cos_theta to the normal.  0 at the normal; towards the horizon it
 * grows like 1/cos_theta and is clamped to a large finite value for cos_theta <= 1e-150. */
double wenv_smith_lambda(wenv_distribution dist, double m, double cos_theta);

/* The n.h below which the lobe's D stays under 1e-7 of its largest value (a scan over theta_h in
 * 4096 steps from the horizon in, stopping one step past the first value above the cut); -1 when no
 * such cut exists. */
double wenv_lobe_cos_h_min(const wenv_lobe *lobe);

/* One lobe's F D G / (4 cos_i cos_o), without its colour; 0 if either direction is at or below the
 * horizon (z <= 0).  Directions are unit vectors. */
double wenv_lobe_eval(const wenv_lobe *lobe, wenv_shadowing shadowing, const double wi[3], const double wo[3]);

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

/* The lobe's cells on a grid of half-vector slopes: n_y rows across the plane of wo and the normal
 * times n_x columns along it, each graded in the distribution's CDF (rows in the marginal, columns
 * in the conditional one, over the slopes whose reflection lies above the horizon).  Towards grazing
 * the reflected lobe is squeezed across that plane by about cos(theta_o) + alpha, so a few rows and
 * many columns keep the cells about as wide as long in wi, where a rule in theta_h and phi_h makes
 * long thin cells that a pre-filtered lookup cannot read well (under Blender's forest and courtyard
 * 24 x 4 of these cells read as accurately as 1024 polar ones).  Writes n_x n_y nodes, in the same
 * order for every wo: wi (3 doubles each, unit), mass (what turns the lobe's value over its D,
 * wenv_material_lobe_over_ndf, into the node's weight) and size (the cell's footprint in wi,
 * radians); nodes below the horizon have mass 0. */
wenv_status wenv_lobe_slope_cells(const wenv_lobe *lobe, double cut, const double wo[3], size_t n_x, size_t n_y,
                                  double *wi, double *mass, double *size, size_t *count, wenv_error *err);
/* cut > 0 (in (0, 1], a GGX lobe only): the grid of the lobe's core instead.  A GGX lobe of alpha a
 * is Beckmann lobes of RMS slope a / sqrt(t) mixed over t ~ Exp(1); its core, those of t >= cut,
 * has Gaussian tails, and holds the share wenv_ggx_core_share of GGX's D at each half vector (the
 * rest, the tail, is the mixture's lobes wider than a / sqrt(cut)).  The grid is graded in the
 * core's D normalised, e^cut share D. */
double wenv_ggx_core_share(double alpha, double cut, double tan2);

/* A slope grid's rows, which no view changes (each row's slope, its share and its conditional table,
 * half the rule's work for a cut lobe): made once, then read for every view by wenv_slope_rows_cells,
 * which writes what wenv_lobe_slope_cells writes, to the bit. */
typedef struct wenv_slope_rows wenv_slope_rows;
wenv_status wenv_slope_rows_make(const wenv_lobe *lobe, double cut, size_t n_y, wenv_slope_rows **out,
                                 wenv_error *err);
wenv_status wenv_slope_rows_cells(const wenv_slope_rows *rows, const double wo[3], size_t n_x, double *wi,
                                  double *mass, double *size, size_t *count, wenv_error *err);
void wenv_slope_rows_free(wenv_slope_rows *rows);

/* ---- the lobe's terms, inline for the hot loops (~1e9 calls): written once (microfacet_terms.inc),
 * compiled in double (wenv_fresnel_dielectric, wenv_ndf_tan2, wenv_smith_k, wenv_half_vector_of,
 * wenv_vis_smith, wenv_vis_vcavity) and in float (the same names with _f) ---- */

#define WENV_INV_PI (1.0 / 3.14159265358979323846)
#define WENV_INV_SQRT_PI 0.56418958354775628695
#define WENV_BECKMANN_A_CAP 30.0 /* erf(30) = 1 and exp(-900) = 0 in double: Lambda is exactly 0 */

#define WENV_MF_T double
#define WENV_MF(name) wenv_##name
#define WENV_MF_C(x) x
#define WENV_MF_SQRT sqrt
#define WENV_MF_EXP exp
#define WENV_MF_ERF(a, e) erf(a)
#define WENV_MF_OVER(x, y) ((x) / (y))
#define WENV_MF_TINY DBL_MIN
#define WENV_MF_TAN2_CAP 1e150 /* tan^2 beyond this: Beckmann D is exactly 0, GGX D its limit */
#define WENV_MF_A_CAP WENV_BECKMANN_A_CAP
#include "scene/microfacet_terms.inc"

/* float: exp and erf without library calls (math/vector_math.h), so loops over directions run
 * several lanes per instruction; caps at float's range */
#define WENV_MF_T float
#define WENV_MF(name) wenv_##name##_f
#define WENV_MF_C(x) x##f
#define WENV_MF_SQRT sqrtf
#define WENV_MF_EXP wenv_exp_vf
#define WENV_MF_ERF(a, e) wenv_erf_vf(a, e)
#define WENV_MF_OVER(x, y) ((x) * (1.0f / (y)))
#define WENV_MF_TINY FLT_MIN
#define WENV_MF_TAN2_CAP 1e30f
#define WENV_MF_A_CAP 10.0f /* erff(10) = 1, expf(-100) ~ 4e-44: Lambda is 0 in float */
#include "scene/microfacet_terms.inc"

/* ---- one lobe of a material, from those terms (double) ---- */

/* The view's part of the visibility term: K(wo) for Smith (unused by V-cavity). */
static inline double wenv_lobe_view_k(const wenv_lobe *lobe, wenv_shadowing shadowing, const double wo[3])
{
    if (shadowing != WENV_SHADOW_SMITH)
        return 0.0;
    double s = sqrt(wo[0] * wo[0] + wo[1] * wo[1]);
    return wenv_smith_k(lobe->distribution == WENV_NDF_GGX, lobe->alpha, wo[2], s);
}

/* V = G / (4 cos_i cos_o) for cos_i, cos_o > 0 (the caller checks), k_o = wenv_lobe_view_k(wo). */
static inline double wenv_lobe_vis(const wenv_lobe *lobe, wenv_shadowing shadowing, const double wi[3],
                                   const double wo[3], double k_o, wenv_half_vector h)
{
    if (shadowing == WENV_SHADOW_SMITH) {
        double si = sqrt(wi[0] * wi[0] + wi[1] * wi[1]);
        double k_i = wenv_smith_k(lobe->distribution == WENV_NDF_GGX, lobe->alpha, wi[2], si);
        return wenv_vis_smith(wi[2], wo[2], k_i, k_o);
    }
    return wenv_vis_vcavity(wi[2], wo[2], h);
}

/* F D G / (4 cos_i cos_o) under the same conditions. */
static inline double wenv_lobe_value(const wenv_lobe *lobe, wenv_shadowing shadowing, const double wi[3],
                                     const double wo[3], double k_o)
{
    wenv_half_vector h = wenv_half_vector_of(wi, wo);
    double v = wenv_lobe_vis(lobe, shadowing, wi, wo, k_o, h);
    return wenv_fresnel_dielectric(h.cos_d, lobe->ior) * wenv_ndf_tan2(lobe->distribution == WENV_NDF_GGX,
                                                                        lobe->alpha, h.tan2) * v;
}

#endif
