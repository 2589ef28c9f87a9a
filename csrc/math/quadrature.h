/* Gauss-Legendre quadrature nodes, shared by the albedo rule, the spherical-harmonic rotation and the
 * BRDF projections. */
#ifndef WENV_QUADRATURE_H
#define WENV_QUADRATURE_H

#include <stddef.h>

/* n nodes x (ascending) and weights w on (0, 1), exact for polynomials of degree 2n - 1. */
void wenv_gauss_legendre_01(size_t n, double *x, double *w);

#endif
