/* Real spherical harmonics: evaluation, projection of an environment, irradiance and rotation.
 *
 * Basis: orthonormal real SH up to band `order` ((order + 1)^2 functions), coefficient index
 * l^2 + l + m for m in [-l, l]; m > 0 holds sqrt(2) N_lm P_lm(cos theta) cos(m phi), m < 0 the same
 * with sin(|m| phi), Condon-Shortley phase included.  The associated Legendre functions come from
 * the fully normalised three-term recurrences, stable to high bands.
 *
 * Rotation: the coefficients of f o R for R = Rz(alpha) Ry(beta) Rz(gamma) (zyz Euler angles).
 * A rotation about z mixes each (m, -m) pair by cos/sin(m angle); a rotation about y is one about z
 * conjugated by the fixed quarter turn Q = Rx(-pi/2) (Q Rz(beta) Q^T = Ry(beta)), whose per-band
 * matrices are computed once by exact quadrature (the "zxzxz" decomposition Kautz, Sloan and
 * Snyder 2002 use).  Cost per rotation: two dense band-block products, sum (2l+1)^2 each. */
#ifndef WENV_SH_H
#define WENV_SH_H

#include <stddef.h>

#include "base/error.h"

#define WENV_SH_ORDER_MAX 32

static inline size_t wenv_sh_count(size_t order) { return (order + 1) * (order + 1); }

/* y[0 .. (order+1)^2) = basis functions at the unit direction d. */
void wenv_sh_eval(size_t order, const double d[3], double *y);

/* Lambert's clamped-cosine convolution factor A_l (Ramamoorthi and Hanrahan 2001): irradiance is
 * sum_lm A_l L_lm Y_lm(n).  pi, 2 pi / 3, 0 for odd l > 1, pi / 4 for l = 2, ... */
double wenv_sh_lambert_factor(size_t l);

/* Irradiance at unit normal n from lighting coefficients (count(order) x 3), bands 0..order. */
void wenv_sh_irradiance(size_t order, const double *coeffs, const double n[3], double rgb[3]);

typedef struct wenv_sh_rotation wenv_sh_rotation;

wenv_status wenv_sh_rotation_create(wenv_sh_rotation **out, size_t order, wenv_error *err);
void wenv_sh_rotation_free(wenv_sh_rotation *rot);

/* out = coefficients of f o (Rz(alpha) Ry(beta) Rz(gamma)) for f given by `in`; both count x
 * channels, interleaved.  `in` and `out` must not overlap; `work` holds count x channels doubles. */
void wenv_sh_rotate_zyz(const wenv_sh_rotation *rot, double alpha, double beta, double gamma, const double *in,
                        double *out, size_t channels, double *work);

/* In place: coefficients of f o Rz(angle). */
void wenv_sh_rotate_z(size_t order, double angle, double *c, size_t channels);

/* Euler angles with Rz(alpha) Ry(beta) Rz(gamma) = F^T for an orthonormal frame F whose rows are the
 * tangent, bitangent and normal: then f o F^T is f seen in the frame (local direction -> world). */
void wenv_sh_frame_angles(const double frame[9], double *alpha, double *beta, double *gamma);

#endif
