/* Square maps of directions (REFERENCE.md §3).
 *
 * Octahedral map: the whole sphere on [-1,1]^2.  Hemi-octahedral ("pyramidal") map: the upper
 * hemisphere z >= 0 on [-1,1]^2, the square's edges being the horizon.  An n x n texel grid covers
 * the square; texel (i, j) is column i, row j, stored at index j * n + i, with its centre at
 * u = -1 + (2 i + 1) / n, v = -1 + (2 j + 1) / n.  n must be even so that every fold of the maps
 * runs along texel edges or texel diagonals: then each texel is one or two spherical triangles with
 * great-circle edges and its solid angle is exact. */
#ifndef WENV_MAPS_H
#define WENV_MAPS_H

#include <stddef.h>

void wenv_oct_encode(const double d[3], double *u, double *v);
void wenv_oct_decode(double u, double v, double d[3]);
/* Directions below the horizon are treated as on it. */
void wenv_hemi_encode(const double d[3], double *u, double *v);
void wenv_hemi_decode(double u, double v, double d[3]);

double wenv_map_texel_center(size_t n, size_t i);

/* Exact solid angle of a texel; they sum to 4 pi (octahedral) and 2 pi (hemi-octahedral). */
double wenv_oct_texel_solid_angle(size_t n, size_t i, size_t j);
double wenv_hemi_texel_solid_angle(size_t n, size_t i, size_t j);

/* Bilinear interpolation taps between texel centres for map point (u, v): four texel indices and
 * weights summing to one.  The octahedral map continues across its edges, which fold onto
 * themselves mirrored (so interpolation is continuous on the whole sphere); the hemi-octahedral
 * map clamps at the horizon. */
void wenv_oct_bilinear(size_t n, double u, double v, size_t idx[4], double w[4]);
void wenv_hemi_bilinear(size_t n, double u, double v, size_t idx[4], double w[4]);

/* The same for samples on the (n + 1) x (n + 1) texel corners (index j * (n + 1) + i at
 * u = -1 + 2 i / n): the outermost samples lie on the horizon, so nothing is extrapolated. */
void wenv_hemi_bilinear_corners(size_t n, double u, double v, size_t idx[4], double w[4]);

/* Solid angle of the spherical triangle with unit-vector corners a, b, c. */
double wenv_spherical_triangle(const double a[3], const double b[3], const double c[3]);

#endif
