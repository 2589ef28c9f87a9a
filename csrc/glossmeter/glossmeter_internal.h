/* What the glossmeter's files share (instrument.c, flux.c, reading.c): the instrument's
 * geometry, its polygons, and the integrals one file makes for another.  Private to glossmeter/. */
#ifndef WENV_GLOSSMETER_INTERNAL_H
#define WENV_GLOSSMETER_INTERNAL_H

#include "glossmeter/glossmeter.h"

#include <cubature.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#ifndef M_PI
#define M_PI 3.14159265358979323846
#endif
#ifndef M_SQRT2
#define M_SQRT2 1.41421356237309504880
#endif
#ifndef M_SQRT1_2
#define M_SQRT1_2 0.70710678118654752440
#endif

#define DEG (M_PI / 180.0)
#define MAX_POLY 16 /* rectangle clipped by four half-planes: at most 8 vertices */
#define MAX_KINKS 32

typedef struct {
    size_t n;
    double xy[2 * MAX_POLY];
} polygon;

struct wenv_glossmeter {
    wenv_glossmeter_config cfg;
    double n[3], t1[3], t2[3];        /* unit specimen normal and a tangent frame for the BRDF */
    double cs[3], us[3], vs[3];       /* source centre and its in-plane / perpendicular axes */
    double cs_local[3], us_local[3], vs_local[3]; /* the same in the specimen frame (t1, t2, n) */
    double cd[3], ud[3], vd[3];       /* receptor centre and axes */
    double hs[2], hd[2];              /* gnomonic half-sides tan(w/2), tan(h/2) */
    double proj_source, proj_receptor; /* projected solid angles about n */
    double proj_error;                /* error estimate of proj_source * proj_receptor */
    polygon mirror_in;                /* source region whose mirror about n falls in the receptor */
    double flux_std, flux_std_error;
    /* For the choice of the lobe formulation (see lobe_needs_half_vector()): extent of the mirror
     * image of the source in receptor gnomonic coordinates, and the incidence cosine at its centre. */
    double image_lo[2], image_hi[2];
    int image_far;                    /* part of the image is >= 87 degrees from the receptor centre */
    double cos_i0;
    /* Half-vector slope frame about n (e1 in the plane of incidence) and the box of slopes (p, q)
     * that can reflect some source direction into the receptor, padded. */
    double e1[3], e2[3];
    double hbox[4];
    /* Slopes where the clipped source polygon of the half-vector form changes shape (kinks of its
     * integrand), along p (at q = 0) and along q (at p = 0), ascending. */
    size_t n_kinks[2];
    double kinks[2][MAX_KINKS];
};

/* ---------------------------------------------------------------- small vector helpers */

static inline double dot3(const double a[3], const double b[3]) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }

static inline void cross3(const double a[3], const double b[3], double out[3])
{
    out[0] = a[1] * b[2] - a[2] * b[1];
    out[1] = a[2] * b[0] - a[0] * b[2];
    out[2] = a[0] * b[1] - a[1] * b[0];
}

/* Gnomonic point of an aperture: unit direction and the solid-angle density 1/(1+X^2+Y^2)^(3/2). */
static inline double aperture_dir(const double c[3], const double u[3], const double v[3], double X, double Y,
                           double out[3])
{
    double r2 = 1.0 + X * X + Y * Y;
    double inv = 1.0 / sqrt(r2);
    for (int k = 0; k < 3; k++)
        out[k] = (c[k] + X * u[k] + Y * v[k]) * inv;
    return inv * inv * inv;
}

static inline void to_local(const wenv_glossmeter *gm, const double w[3], double out[3])
{
    out[0] = dot3(w, gm->t1);
    out[1] = dot3(w, gm->t2);
    out[2] = dot3(w, gm->n);
}

/* ---------------------------------------------------------------- across the files */

/* instrument.c: the source region (gnomonic coordinates) whose mirror image about unit `normal` falls
 * in the receptor, whether a polygon is the whole source rectangle, the smooth-limit flux over such
 * a region (sum over components k of weight_k * integral F_k(s.n) (s.n) d omega), and the check of
 * an aperture's size. */
void wenv_gm_mirror_region(const wenv_glossmeter *gm, const double normal[3], polygon *p);
int wenv_gm_polygon_is_rect(const polygon *p, const double half[2]);
wenv_status wenv_gm_mirror_flux(const wenv_glossmeter *gm, const double normal[3], const polygon *region,
                                unsigned fdim, const double *ior, const double *weight, size_t max_evals,
                                double *val, double *errv, size_t *evals, int *converged, wenv_error *err);
wenv_status wenv_gm_check_size(const double size[2], const char *name, wenv_error *err);

/* flux.c: the flux of `mat` into the receptor and its error bound: tol_flux / WENV_GLOSS_SAFETY is
 * asked of the lobes' integral and the error returned is WENV_GLOSS_SAFETY times the integrators'
 * estimates (see glossmeter.h). */
wenv_status wenv_gm_material_flux(const wenv_glossmeter *gm, const wenv_material *mat, int smooth, int method,
                                  double tol_flux, size_t max_evals, double *flux, double *flux_err, size_t *evals,
                                  int *converged, wenv_error *err);

#endif
