/* The material interface: what shading, the reference, the exact lights, the grazing path, auto
 * and the glossmeter know of a material.  Lambert (lambert.c) and multi-lobe Cook-Torrance
 * (cook_torrance.c) implement it; a new reflectance model implements material_kind.h and is used
 * by all of them without edits.
 *
 * A material is a Lambertian part (its albedo, f_d = diffuse / pi) plus a glossy part described by
 * lobes.  Each lobe has a microfacet shape (scene/microfacet.h: distribution, alpha,
 * index, colour): for Cook-Torrance it is the lobe itself; for other models it is the microfacet
 * lobe closest to it, which places quadrature nodes, warps the glossmeter's integrals, sizes the
 * maps and prefilters (split-sum's assumption), while every value -- and where a lobe can reflect
 * (the exact lights' cones) -- comes from the model's own evaluation and rules below.
 *
 * Directions are unit vectors in the local frame whose +Z is the surface normal; wi towards the
 * light, wo towards the eye (docs/ARCHITECTURE.md §3.1).  Everything returns
 * finite values for valid input, directions exactly at the normal or the horizon included, and 0
 * below either horizon.  Materials are immutable after creation, so one may be evaluated from many
 * threads at once. */
#ifndef WENV_MATERIAL_H
#define WENV_MATERIAL_H

#include <stddef.h>

#include "base/error.h"
#include "scene/microfacet.h"
#include "scene/principled_inputs.h"

/* The struct tag lets the bindings forward-declare `struct wenv_material`. */
typedef struct wenv_material wenv_material;

/* ---- making one ---- */

/* Lambertian: f = albedo / pi.  albedo finite in [0, 1] per channel (energy conservation). */
wenv_status wenv_lambert_create(wenv_material **out, const double albedo[3], wenv_error *err);

/* Lambertian diffuse plus n_lobes Cook-Torrance lobes sharing one shadowing form.  Validates and
 * copies; WENV_ERR_VALUE naming the offending field ("diffuse", "lobes[1].alpha"...): diffuse as
 * Lambert's albedo, each lobe as wenv_lobe_check, known shadowing.  n_lobes = 0 (lobes may be NULL)
 * gives a Cook-Torrance material without lobes, which reflects as Lambert does. */
wenv_status wenv_cook_torrance_create(wenv_material **out, const double diffuse[3], const wenv_lobe *lobes,
                                      size_t n_lobes, wenv_shadowing shadowing, wenv_error *err);

/* Where a table's sample (i, j, k) sits in the index coordinates (sqrt(theta_h / 90) n_h,
 * theta_d / 90 n_d, phi_d / 180 n_p): at the centre of its bin, (i + 1/2, j + 1/2, k + 1/2), as in a
 * MERL file (MERL's reader, like pbrt's, looks a sample up by the floor of the index coordinate), or
 * at the start of its bin, (i, j, k). */
typedef enum { WENV_SAMPLES_AT_CENTRES = 0, WENV_SAMPLES_AT_STARTS = 1 } wenv_sample_position;

/* An isotropic BRDF tabulated over Rusinkiewicz's half and difference angles in MERL's layout
 * (scene/tabulated.c: sample positions and trilinear interpolation): rgb is n_h x n_d x n_p x 3
 * floats of f (1/sr), finite and >= 0; dims in [2, 4096]; samples_at says where the samples sit
 * (WENV_ERR_VALUE naming "samples_at" for another value).  Copied once and shared by the
 * material's copies (a shader's copy costs no copy of the table).  Its smallest value above the
 * horizon is the Lambertian part (diffuse = pi x that, per channel), the rest one glossy lobe. */
wenv_status wenv_tabulated_create(wenv_material **out, const float *rgb, const size_t dims[3],
                                  wenv_sample_position samples_at, wenv_error *err);

/* Blender's Principled BSDF node's inputs (scene/principled_inputs.h: the one list of them);
 * wenv_principled_defaults gives the node's defaults. */
void wenv_principled_defaults(wenv_principled_inputs *in);

/* The Principled BSDF's reflection as Cycles evaluates it (scene/principled.c): every input finite
 * (WENV_ERR_VALUE naming the first that is not), clamped as Cycles' kernel clamps them.  Its lobes
 * are GGX (coat, metal, dielectric specular, as present); its Lambertian part changes with the view
 * (wenv_material_diffuse_at). */
wenv_status wenv_principled_create(wenv_material **out, const wenv_principled_inputs *in, wenv_error *err);

/* A Principled material's inputs (clamped), NULL for other models. */
const wenv_principled_inputs *wenv_principled_inputs_of(const wenv_material *mat);

/* The names of the inputs set to something wenv does not shade (the list's rule column, in its
 * order): up to max of them into names; returns how many there are. */
size_t wenv_principled_unhonoured(const wenv_principled_inputs *in, const char **names, size_t max);

/* A tabulated material's table, dims filled; NULL for other models. */
const float *wenv_tabulated_table(const wenv_material *mat, size_t dims[3]);

/* Where a tabulated material's samples sit (WENV_SAMPLES_AT_CENTRES for other models). */
wenv_sample_position wenv_tabulated_samples_at(const wenv_material *mat);

wenv_status wenv_material_copy(wenv_material **out, const wenv_material *src, wenv_error *err);
void wenv_material_free(wenv_material *mat);

/* Whether a and b reflect alike: the same model made from the same values (a copy, or one made
 * again from them), so that what was computed for one serves the other.  A measured table or a
 * Principled BSDF's inputs compare by a 64-bit fingerprint. */
int wenv_material_same(const wenv_material *a, const wenv_material *b);

/* A new material equal to `src` but for how wide its lobes are, as the glossmeter's one-parameter
 * inverse varies it; a copy for a material without lobes.  with_alpha sets every lobe's alpha (for
 * a model whose lobes are their shapes: Cook-Torrance), validated against WENV_ALPHA_MIN..MAX;
 * with_roughness sets Blender's roughness r (for a model that takes it: the Principled BSDF's
 * Roughness, clamped to [0, 1] as Cycles clamps it), finite and >= 0.  WENV_ERR_VALUE, naming the
 * other, for a model that takes the other, and for a model that takes neither (a measured table). */
wenv_status wenv_material_with_alpha(wenv_material **out, const wenv_material *src, double alpha, wenv_error *err);
wenv_status wenv_material_with_roughness(wenv_material **out, const wenv_material *src, double roughness,
                                         wenv_error *err);

/* "lambert", "cook_torrance", ... */
const char *wenv_material_kind_name(const wenv_material *mat);

/* ---- what it is made of ---- */

/* The Lambertian part's albedo (RGB); for a material whose Lambertian part changes with the view,
 * its value head-on (see wenv_material_diffuse_at). */
const double *wenv_material_diffuse(const wenv_material *mat);

/* The Lambertian part's albedo for a view at cos_v to the normal (f_d = albedo / pi for every wi):
 * constant for most models; a layered one (Principled) lets through what its upper layers leave. */
void wenv_material_diffuse_at(const wenv_material *mat, double cos_v, double rgb[3]);

/* The same over cos_v in [0, 1], tabulated for per-vertex loops: albedo / pi at WENV_DIFFUSE_TABLE_N
 * cosines i / (n - 1), linear between them (n = 1 when it does not change with the view). */
#define WENV_DIFFUSE_TABLE_N 257
typedef struct {
    size_t n;
    float over_pi[3 * WENV_DIFFUSE_TABLE_N];
} wenv_diffuse_table;
void wenv_material_diffuse_table(const wenv_material *mat, wenv_diffuse_table *table);
static inline void wenv_diffuse_table_at(const wenv_diffuse_table *t, float cos_v, float out[3])
{
    float x = (cos_v < 0.0f ? 0.0f : (cos_v > 1.0f ? 1.0f : cos_v)) * (float)(t->n - 1);
    size_t i = (size_t)x < t->n - 1 ? (size_t)x : t->n - 1, j = i + 1 < t->n ? i + 1 : i;
    float f = x - (float)i;
    for (int c = 0; c < 3; c++)
        out[c] = (1.0f - f) * t->over_pi[3 * i + (size_t)c] + f * t->over_pi[3 * j + (size_t)c];
}
/* Whether any entry is non-zero. */
int wenv_diffuse_table_any(const wenv_diffuse_table *t);

/* The Lambertian part per unit of the material's colour -- a Principled BSDF's Base Color, a
 * Lambert's or Cook-Torrance's diffuse albedo -- tabulated as above: what a colour that varies per
 * vertex multiplies, the rest of the material being free of it.  WENV_ERR_VALUE saying why when the
 * colour enters elsewhere too (a metal's Fresnel, a rough diffuse lobe) or the material has no
 * colour (a measured table). */
wenv_status wenv_material_diffuse_per_colour_table(const wenv_material *mat, wenv_diffuse_table *table,
                                                   wenv_error *err);
/* The same for one view (the albedo, not over pi). */
wenv_status wenv_material_diffuse_per_colour_at(const wenv_material *mat, double cos_v, double rgb[3],
                                                wenv_error *err);

/* A metal's colour as a mix of itself in black and in white: for a Principled BSDF at Metallic 1 with no
 * coat or sheen over it, the weights per channel (w_black, w_white) that make it at Base Color
 * `colour` (clamped to [0, 1]) from the same material at Base Color 0 and at 1, for a view at cos_v.
 * Exact (to the Fresnel's clamp at 0): its F82-tint Fresnel is linear in the colour, and its energy
 * compensation a factor of the colour and the view alone.  0 (nothing written) for other materials. */
int wenv_material_metal_colour(const wenv_material *mat, double cos_v, const double colour[3], double w_black[3],
                               double w_white[3]);

/* Light a material emits of its own (a Principled BSDF's Emission), added to what it reflects:
 * whether it emits any, and its radiance towards a view at cos_v to the normal (RGB; 0 for a model
 * without emission). */
int wenv_material_emits(const wenv_material *mat);
void wenv_material_emission_at(const wenv_material *mat, double cos_v, double rgb[3]);

/* The glossy lobes: how many, and each one's microfacet shape (see above). */
size_t wenv_material_lobe_count(const wenv_material *mat);
const wenv_lobe *wenv_material_lobe(const wenv_material *mat, size_t i);

/* Whether the lobes have a smooth limit: Fresnel mirrors of their shapes' colour and index (the
 * glossmeter's smooth=True), as microfacet lobes do and a measured table does not. */
int wenv_material_has_smooth_limit(const wenv_material *mat);
/* Whether f(M wi, M wo) = f(wi, wo) for every reflection M about a plane through the normal (and so
 * every turn about it): the wavelet shader then makes one BRDF slice per orbit of the view samples
 * under the square's symmetries and permutes it for the rest.  Isotropic models; not a table, whose
 * phi_d is folded by reciprocity only. */
int wenv_material_mirror_symmetric(const wenv_material *mat);
/* Whether each lobe is its shape's D (wenv_material_lobe) times factors that vary slowly across it
 * (Fresnel, masking, constant weights), so that the shape's width and tails bound it: Cook-Torrance's
 * and Principled's microfacet lobes; not a table's (its shape is only a fit) nor Principled's sheen
 * and rough diffuse, which only borrow a shape. */
int wenv_material_lobes_follow_shapes(const wenv_material *mat);

/* Whether the glossy part reflects about the mirror direction, as microfacet lobes do (and a table
 * whose fitted shape carries its lobe), rather than elsewhere (a retro-reflective lobe, about the
 * view).  The wavelet shader interpolates between normal samples keeping what the lobe is centred
 * on: the vertex's mirror direction, or its view. */
int wenv_material_mirror_centred(const wenv_material *mat);

/* The masking-shadowing form the lobes' shapes assume (Smith for models that do not say). */
wenv_shadowing wenv_material_shadowing(const wenv_material *mat);

/* The width of the narrowest lobe that reflects anything, as a microfacet alpha (its
 * reflected lobe is about 2 alpha radians wide at normal incidence, narrower in azimuth towards
 * grazing); INFINITY when no lobe reflects.  Every consumer that sizes something by the lobes
 * (sub-sampling, the grazing path, the lights' cluster levels, auto) reads this one number. */
double wenv_material_lobe_width(const wenv_material *mat);
/* That narrowest lobe reflecting anything (its alpha is the width above), or NULL when none does. */
const wenv_lobe *wenv_material_narrowest_lobe(const wenv_material *mat);

/* ---- evaluation ---- */

/* The whole material times the incident cosine: f(wi, wo) cos_i, RGB. */
void wenv_material_eval_cos(const wenv_material *mat, const double wi[3], const double wo[3], double rgb[3]);

/* The glossy part only (no Lambertian term), times the incident cosine, RGB. */
void wenv_material_specular_cos(const wenv_material *mat, const double wi[3], const double wo[3], double rgb[3]);

/* Batch form for one view and n incident unit directions (float xyz triples): rgb_out[3k..3k+2] =
 * specular_cos(wi[k], wo) rounded to float.  Reentrant, no allocation. */
void wenv_material_specular_cos_batch(const wenv_material *mat, const double wo[3], const float *wi, size_t n,
                                      float *rgb_out);

/* Float form for the hot per-vertex loops (the exact lights): the same model in float precision
 * (relative error ~1e-5 against the double path where the value is not negligible).  Terms that
 * depend on the view only are made once per view into `terms` (wenv_material_view_terms(mat)
 * floats), then n directions at once, structure of arrays: wi = (x[k], y[k], z[k]) unit; f cos into
 * r, g, b.  Models with a vectorised evaluator run it on the widest instructions the CPU has. */
size_t wenv_material_view_terms(const wenv_material *mat);
void wenv_material_prepare_view_f(const wenv_material *mat, const float wo[3], float *terms);
void wenv_material_specular_cos_f_many(const wenv_material *mat, const float wo[3], const float *terms, size_t n,
                                       const float *x, const float *y, const float *z, float *r, float *g, float *b);

/* The n.h (h the half vector) below which lobe i reflects nothing visible (under 1e-7 of its peak),
 * or -1 when it may reflect at any half vector (a retro-reflective lobe, say): what the exact lights
 * skip without evaluating. */
double wenv_material_lobe_cos_h_min(const wenv_material *mat, size_t i);

/* Lobe i alone: f_i(wi, wo), no cosine, RGB. */
void wenv_material_lobe_value(const wenv_material *mat, size_t i, const double wi[3], const double wo[3],
                              double rgb[3]);

/* Lobe i over its shape's distribution: f_i(wi, wo) 4 cos_i cos_o / D(h), h the half vector, RGB (for
 * a microfacet lobe, F(wi.h) G(wi, wo) times its colour).  Integrals over half vectors weighted by
 * the shape's D (the glossmeter's narrow lobes) read the lobe through this. */
void wenv_material_lobe_over_ndf(const wenv_material *mat, size_t i, const double wi[3], const double wo[3],
                                 double rgb[3]);

/* The functions behind the two above (i < lobe count), for integrands that call them millions of
 * times to call without the dispatch. */
typedef void (*wenv_lobe_rgb_fn)(const wenv_material *mat, size_t i, const double wi[3], const double wo[3],
                                 double rgb[3]);
wenv_lobe_rgb_fn wenv_material_lobe_value_fn(const wenv_material *mat);
wenv_lobe_rgb_fn wenv_material_lobe_over_ndf_fn(const wenv_material *mat);

/* ---- integrals ---- */

/* Directional albedo rho(wo) = Int f(wi, wo) cos_i d wi, RGB: the Lambertian part exactly, each lobe
 * by wenv_material_lobe_albedo.  samples in [8, 4096]; 0 for wo at or below the horizon. */
wenv_status wenv_material_albedo(const wenv_material *mat, const double wo[3], size_t samples, double rgb[3],
                                 wenv_error *err);

/* Lobe i's albedo, RGB, by a deterministic rule with `samples` nodes per dimension following the
 * lobe (for Cook-Torrance, wenv_lobe_albedo times its colour). */
wenv_status wenv_material_lobe_albedo(const wenv_material *mat, size_t i, const double wo[3], size_t samples,
                                      double rgb[3], wenv_error *err);

/* Lobe i's quadrature rule for smooth integrands: unit directions wi and RGB weights with
 * sum_k weight[k] g(wi[k]) ~ Int g(wi) f_i(wi, wo) cos_i d wi (the weights sum to its albedo).  wi and
 * weight need room for 2 samples^2 nodes (3 doubles each); *count gets the number written. */
wenv_status wenv_material_lobe_nodes(const wenv_material *mat, size_t i, const double wo[3], size_t samples,
                                     double *wi, double *weight, size_t *count, wenv_error *err);

/* Lobe i's rule as midpoints of equal cells, for integrands that are not smooth (an environment's
 * radiance), with the solid angle each cell covers so the radiance can be read pre-filtered over it.
 * Always 2 n_theta n_phi nodes (wi 3 doubles, weight 3 doubles each) in the same order for every wo,
 * so rules of neighbouring views interpolate node by node; weight 0 below the horizon. */
wenv_status wenv_material_lobe_cells(const wenv_material *mat, size_t i, const double wo[3], size_t n_theta,
                                     size_t n_phi, double *wi, double *weight, double *solid_angle, size_t *count,
                                     wenv_error *err);

/* Which part of a lobe a slope rule integrates: the whole lobe on its shape's grid (cut 0), or of a
 * lobe whose shape is GGX the core, f_i times wenv_ggx_core_share at cut, on the core's grid (tail 0),
 * or the rest, its tail, on the grid of GGX of alpha / sqrt(cut) (tail 1).  Core and tail sum to the
 * lobe. */
typedef struct {
    double cut;
    int tail;
} wenv_slope_part;

/* Lobe i's rule on a slope grid (wenv_lobe_slope_cells), of the part `part` says: n_x n_y nodes, wi
 * and RGB weight (3 doubles each) with sum_k weight[k] E(wi[k]) ~ Int E(wi) f_part(wi, wo) cos_i d wi,
 * and each cell's footprint `size` in radians, for a lobe about the mirror direction
 * (wenv_material_mirror_centred).  WENV_ERR_VALUE for a cut outside [0, 1] or on a lobe not GGX. */
wenv_status wenv_material_lobe_slope_cells(const wenv_material *mat, size_t i, const double wo[3], size_t n_x,
                                           size_t n_y, wenv_slope_part part, double *wi, double *weight,
                                           double *size, size_t *count, wenv_error *err);

/* The same rule for many views: what no view changes (the grid's rows, coarse and fine: half of a
 * core's work) made once by wenv_lobe_slope_grid_make, then each view's nodes, to the bit those of
 * wenv_material_lobe_slope_cells.  The grid holds mat, which must outlive it. */
typedef struct wenv_lobe_slope_grid wenv_lobe_slope_grid;
wenv_status wenv_lobe_slope_grid_make(const wenv_material *mat, size_t i, size_t n_y, wenv_slope_part part,
                                      wenv_lobe_slope_grid **out, wenv_error *err);
wenv_status wenv_lobe_slope_grid_cells(const wenv_lobe_slope_grid *g, const double wo[3], size_t n_x, double *wi,
                                       double *weight, double *size, size_t *count, wenv_error *err);
void wenv_lobe_slope_grid_free(wenv_lobe_slope_grid *g);

#endif
