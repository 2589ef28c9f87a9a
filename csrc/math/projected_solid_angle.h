/* The projected solid angle of a planar polygon seen from a point on a surface: Int cos(theta) d omega
 * over the directions through the polygon, above the surface's horizon (Lambert's formula, as
 * Arvo 1995 writes it).  A Lambertian emitter of radiance L so gives an irradiance of L times it.
 *
 * Why a closed form: the Lambertian part of a lamp's light is most of what a matte surface shows, and
 * a quadrature over a large lamp close to the surface would need hundreds of points for what four
 * edges give exactly. */
#ifndef WENV_PROJECTED_SOLID_ANGLE_H
#define WENV_PROJECTED_SOLID_ANGLE_H

#include <stddef.h>

/* The most corners a polygon may have (a clip adds one). */
#define WENV_POLYGON_MAX 32

/* corners: n points (xyz doubles) relative to the surface point, in order around a convex polygon;
 * normal: the surface's unit normal.  The part below the horizon (normal . x < 0) is cut away; the
 * result is >= 0 whichever way the corners turn.  n in [3, WENV_POLYGON_MAX - 1]. */
double wenv_projected_solid_angle(const double *corners, size_t n, const double normal[3]);

#endif
