/* Virtual glossmeter: specular gloss of a wenv material as an ISO 2813 / ASTM D523 instrument reads
 * it (docs/ARCHITECTURE.md §3.6, §3.7; thesis §1.5.1, §2.5 after Westlund & Meyer 2001), and ASTM E430 method B
 * haze.
 *
 * Instrument frame.  The instrument's axis is +Z (the nominal specimen normal) and the plane of
 * incidence is XZ.  The source centre direction (from the specimen towards the source) is
 * c_s = (-sin A, 0, cos A) for the specular angle A; its mirror direction is c_m = (sin A, 0, cos A).
 * The receptor centre c_d is c_m turned in the plane of incidence to polar angle A + o1 and then
 * tilted out of the plane by o2, where (o1, o2) = receptor_offset (both 0 for a glossmeter; haze
 * uses o1 = -1.9 and +1.9 degrees, i.e. receptors at 18.1 and 21.9 degrees).
 *
 * Angular rectangles.  An aperture of full angular size w (in plane) x h (perpendicular) centred on
 * direction c is the set of directions
 *
 *     d(X, Y) = (c + X u + Y v) / |c + X u + Y v|,   |X| <= tan(w/2),  |Y| <= tan(h/2),
 *
 * where u is the in-plane unit vector perpendicular to c pointing to larger polar angle and v the
 * unit vector perpendicular to the plane of incidence (turned with c by the out-of-plane offset).
 * (X, Y) are gnomonic coordinates: the directions through a rectangular field stop of half-sides
 * tan(w/2), tan(h/2) in the focal plane of a collimating lens of unit focal length, which is how a
 * glossmeter's source image and receptor field stop are built.  Along the centre lines the angular
 * half-extents are exactly w/2 and h/2, the edges are great-circle arcs, and the solid angle is
 *
 *     d omega = dX dY / (1 + X^2 + Y^2)^(3/2).
 *
 * The same definition holds for source and receptor.  The mirror image of the source (reflection
 * about +Z is a rotation by 180 degrees about Z) is again such a rectangle, centred on c_m with the
 * source's size, so with the receptor larger in both extents it always falls inside it.
 *
 * Flux and gloss.  With the specimen normal n (the `normal` of the configuration, normalised; +Z
 * unless the specimen is tilted in the instrument),
 *
 *     Phi = integral_source integral_receptor f(s, d) (s.n) (d.n) d omega_d d omega_s,
 *
 * f the BRDF's luminance Y = 0.2126 R + 0.7152 G + 0.0722 B.  A smooth (mirror) lobe of reflectance
 * R(theta) contributes integral over the part of the source whose mirror image about n falls in the
 * receptor of R(s.n) (s.n) d omega_s.  The standard is a smooth Fresnel reflector of index
 * standard_ior read by the same apertures at the calibrated orientation n = +Z; gloss
 * G = 100 Phi / Phi_standard in gloss units (GU).  Every part of either aperture must stay above the
 * horizon of both +Z and n (checked at the corners, which is exact: the horizon is a straight line in
 * gnomonic coordinates).
 *
 * Numerics.  hcubature (Steven G. Johnson's cubature, h-adaptive Genz-Malik rules; Debian
 * libcubature-dev) integrates
 *   - the specular lobes over the 4-D product of source and receptor ("aperture" form); in the
 *     receptor each lobe is integrated in warped gnomonic coordinates centred on the mirror image of
 *     the current source point with the lobe's own width (a Gaussian warp for Beckmann, a Cauchy and
 *     a conditional Cauchy warp for GGX; see glossmeter.c), so lobe / warp is nearly constant and a
 *     lobe far narrower than the aperture is as easy as a wide one;
 *   - a narrow lobe whose mirror image of the source straddles a receptor edge (tilted specimen,
 *     receptor smaller than the source image) in the "half-vector" form instead: microfacet slopes
 *     outside (warped by the slope distribution, cut at the kinks), and inside, for each half
 *     vector, the source region that it reflects into the receptor (a clipped polygon, Gauss rule);
 *     the aperture form would face a step of the lobe's width on the source there;
 *   - the smooth limit and the standard over the source region whose mirror image lies in the
 *     receptor (a convex polygon in gnomonic coordinates, integrated triangle by triangle);
 *   - the diffuse term as (albedo_Y / pi) times the product of the two apertures' projected solid
 *     angles (each integrated once per glossmeter).
 *
 * Error.  hcubature's error estimate is a heuristic (difference of embedded rules).  The lobes'
 * integral is asked for tol / WENV_GLOSS_SAFETY and the reported error is WENV_GLOSS_SAFETY times the
 * estimates, so a converged reading reports error <= tol.  Against references computed with
 * tol = 1e-4 GU, the true error at the default tol = 0.05 GU was at most 0.011 GU over 96 cases
 * (20/60/85 degrees, Beckmann and GGX, roughness 1e-5..2; benchmarks/validate_gloss.py), above the
 * stated error in 2 of them; tests/test_glossmeter.py keeps a small version of that check.
 * Results are deterministic: no sampling, and threads only ever split whole measurements. */
#ifndef WENV_GLOSSMETER_H
#define WENV_GLOSSMETER_H

#include <stddef.h>

#include "base/error.h"
#include "scene/material.h"

/* Default requested error bound on a reading (GU), safety factor between it and the integrator's
 * own tolerance, and cap on integrand evaluations per integral. */
#define WENV_GLOSS_DEFAULT_TOL 0.05
#define WENV_GLOSS_SAFETY 5.0
#define WENV_GLOSS_DEFAULT_MAX_EVALS ((size_t)4000000)

typedef struct {
    double angle;              /* specular angle A, degrees, in (0, 90) */
    double source[2];          /* source image: full angular size in plane, perpendicular (deg) */
    double receptor[2];        /* receptor field: full angular size in plane, perpendicular (deg) */
    double receptor_offset[2]; /* receptor centre from the mirror direction: in plane (+ = towards
                                  grazing), perpendicular (deg) */
    double standard_ior;       /* refractive index of the smooth black-glass standard, > 1 */
    double normal[3];          /* specimen normal in the instrument frame (need not be unit) */
} wenv_glossmeter_config;

/* Fills cfg with the ISO 2813 / ASTM D523 instrument for geometry 20, 60 or 85 (docs/ARCHITECTURE.md §3.7),
 * standard index 1.567, normal +Z.  WENV_ERR_VALUE naming "geometry" otherwise. */
wenv_status wenv_glossmeter_standard_config(wenv_glossmeter_config *cfg, double geometry,
                                            wenv_error *err);

typedef struct wenv_glossmeter wenv_glossmeter;

/* Validates cfg (WENV_ERR_VALUE naming "angle", "source", "receptor", "receptor_offset",
 * "standard_ior" or "normal"), builds the frames and integrates the material-independent parts
 * (the standard's flux, the apertures' projected solid angles). */
wenv_status wenv_glossmeter_create(wenv_glossmeter **out, const wenv_glossmeter_config *cfg,
                                   wenv_error *err);
void wenv_glossmeter_free(wenv_glossmeter *gm);
const wenv_glossmeter_config *wenv_glossmeter_config_of(const wenv_glossmeter *gm);

/* Flux of the standard and its error estimate; > 0 unless the receptor misses the standard's
 * mirror image of the source entirely (as the haze receptors do). */
double wenv_glossmeter_standard_flux(const wenv_glossmeter *gm, double *error);

/* Projected solid angles (integral of cos about the specimen normal, sr) of source and receptor:
 * a Lambertian albedo rho reads 100 (rho / pi) source * receptor / standard flux. */
void wenv_glossmeter_projected_solid_angles(const wenv_glossmeter *gm, double *source, double *receptor);

typedef struct {
    double tol;       /* requested error bound on the reading, GU (> 0) */
    size_t max_evals; /* cap on integrand evaluations per adaptive integral (> 0) */
    int smooth;       /* 1: read every lobe as its smooth limit (a Fresnel mirror of its colour) */
    int method;       /* lobe formulation: WENV_GLOSS_AUTO, or force one (for validation) */
} wenv_gloss_options;

enum { WENV_GLOSS_AUTO = 0, WENV_GLOSS_APERTURE = 1, WENV_GLOSS_HALF_VECTOR = 2 };

void wenv_gloss_options_default(wenv_gloss_options *opt);

typedef struct {
    double value;         /* gloss (GU) or haze (HU) */
    double error;         /* error bound on value from the integrators' estimates */
    double flux;          /* specimen flux Phi (sr^2-weighted reflectance, luminance) */
    double flux_standard; /* Phi of the standard, the denominator */
    size_t evaluations;   /* integrand evaluations of the material-dependent integrals */
    int converged;        /* 0 if max_evals was reached before tol: value and error still hold the
                             integrator's best result and estimate */
} wenv_gloss_result;

/* Reads `mat` (diffuse + any Cook-Torrance lobes).  WENV_ERR_VALUE for a zero standard flux or bad
 * options; WENV_ERR_NOMEM if the integrator could not allocate. */
wenv_status wenv_glossmeter_measure(const wenv_glossmeter *gm, const wenv_material *mat,
                                    const wenv_gloss_options *opt, wenv_gloss_result *out,
                                    wenv_error *err);

/* Reads `mat` with each of n glossmeters (OpenMP threads over the meters; each reading is the same
 * as wenv_glossmeter_measure's).  On error the first failing meter's error is reported. */
wenv_status wenv_glossmeter_measure_many(wenv_glossmeter *const *gms, size_t n, const wenv_material *mat,
                                         const wenv_gloss_options *opt, wenv_gloss_result *out,
                                         wenv_error *err);

/* Haze after ASTM E430 method B: the flux into two receptors of size `aperture` (deg) whose centres
 * are turned in the plane of incidence by offsets[0] and offsets[1] (deg) from the mirror direction
 * of `specular` (the 20 degree glossmeter: -1.9 and +1.9 give 18.1 and 21.9 degrees), summed and
 * given as 100 x (their flux) / (the standard's flux in `specular`), haze units (HU).
 * WENV_ERR_VALUE naming "offsets" or "aperture" for bad values or receptors past the horizon. */
wenv_status wenv_glossmeter_haze(const wenv_glossmeter *specular, const wenv_material *mat,
                                 const double offsets[2], const double aperture[2],
                                 const wenv_gloss_options *opt, wenv_gloss_result *out,
                                 wenv_error *err);

/* What the inverse varies: every lobe's alpha (Cook-Torrance, wenv_material_with_alpha), or Blender's
 * roughness r (a Principled BSDF's Roughness, wenv_material_with_roughness). */
typedef enum { WENV_FIT_ALPHA = 0, WENV_FIT_ROUGHNESS = 1 } wenv_fit_param;

/* The value of `param` for `tmpl` (other fields kept) that makes the reading `target` (GU), searched
 * in its logarithm over [lo, hi] by bracketed Illinois-secant iteration (the reading falls
 * monotonically as lobes widen).  Brackets: alpha within WENV_ALPHA_MIN..WENV_ALPHA_MAX, roughness
 * within (0, 1].  WENV_ERR_VALUE naming "target_gu" when the target lies outside the readings at hi
 * and lo (the message gives both and the smooth-limit value), or if tmpl has no lobe or does not
 * take the parameter. */
wenv_status wenv_glossmeter_fit(const wenv_glossmeter *gm, const wenv_material *tmpl, wenv_fit_param param,
                                double target, double lo, double hi, const wenv_gloss_options *opt,
                                double *value, wenv_gloss_result *at_root, wenv_error *err);

#endif
