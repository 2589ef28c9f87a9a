/* Square maps of directions (docs/ARCHITECTURE.md §3.2).
 *
 * Octahedral map: the whole sphere on [-1,1]^2.  Hemi-octahedral ("pyramidal") map: the upper
 * hemisphere z >= 0 on [-1,1]^2, the square's edges being the horizon.  An n x n texel grid covers
 * the square; texel (i, j) is column i, row j, stored at index j * n + i, with its centre at
 * u = -1 + (2 i + 1) / n, v = -1 + (2 j + 1) / n.  n must be even so that every fold of the maps
 * runs along texel edges or texel diagonals: then each texel is one or two spherical triangles with
 * great-circle edges and its solid angle is exact. */
#ifndef WENV_MAPS_H
#define WENV_MAPS_H

#include <math.h>
#include <stddef.h>
#include <stdint.h>

void wenv_oct_encode(const double d[3], double *u, double *v);
void wenv_oct_decode(double u, double v, double d[3]);
/* Directions below the horizon are treated as on it. */
void wenv_hemi_encode(const double d[3], double *u, double *v);
void wenv_hemi_decode(double u, double v, double d[3]);

double wenv_map_texel_center(size_t n, size_t i);

/* Exact solid angle of a texel; they sum to 4 pi (octahedral) and 2 pi (hemi-octahedral). */
double wenv_oct_texel_solid_angle(size_t n, size_t i, size_t j);
double wenv_hemi_texel_solid_angle(size_t n, size_t i, size_t j);
/* Every texel's solid angle on an n x n octahedral map (out: n^2, row by row), each computed once
 * per orbit of the square's symmetries: an eighth of the calls. */
void wenv_oct_texel_solid_angles(size_t n, double *out);

/* Bilinear interpolation taps between texel centres for map point (u, v): four texel indices and
 * weights summing to one.  The octahedral map continues across its edges, which fold onto
 * themselves mirrored (so interpolation is continuous on the whole sphere); the hemi-octahedral
 * map clamps at the horizon. */
void wenv_oct_bilinear(size_t n, double u, double v, size_t idx[4], double w[4]);
void wenv_hemi_bilinear(size_t n, double u, double v, size_t idx[4], double w[4]);

/* Solid angle of the spherical triangle with unit-vector corners a, b, c. */
double wenv_spherical_triangle(const double a[3], const double b[3], const double c[3]);

/* Float forms of wenv_oct_encode and wenv_oct_bilinear for loops over every vertex or pixel: no
 * double divisions, and truncating casts instead of floor() (a libm call on baseline x86-64). */
static inline void wenv_oct_encode_f(const float d[3], float *u, float *v)
{
    float l1 = 1.0f / (fabsf(d[0]) + fabsf(d[1]) + fabsf(d[2]));
    float pu = d[0] * l1, pv = d[1] * l1;
    if (d[2] < 0.0f) {
        float qu = copysignf(1.0f - fabsf(pv), pu), qv = copysignf(1.0f - fabsf(pu), pv);
        pu = qu;
        pv = qv;
    }
    *u = pu;
    *v = pv;
}

/* Index of the texel of an n x n octahedral map that unit direction d falls in. */
static inline size_t wenv_oct_texel_f(const float d[3], size_t n)
{
    float u, v;
    wenv_oct_encode_f(d, &u, &v);
    long x = (long)((u + 1.0f) * 0.5f * (float)n), y = (long)((v + 1.0f) * 0.5f * (float)n), hi = (long)n - 1;
    x = x < 0 ? 0 : (x > hi ? hi : x);
    y = y < 0 ? 0 : (y > hi ? hi : y);
    return (size_t)y * n + (size_t)x;
}

static inline void wenv_oct_bilinear_f(long n, float u, float v, uint32_t idx[4], float w[4])
{
    float x = (u + 1.0f) * 0.5f * (float)n - 0.5f, y = (v + 1.0f) * 0.5f * (float)n - 0.5f;
    long ix = (long)(x + 1.0f) - 1, iy = (long)(y + 1.0f) - 1; /* floor for x >= -1 */
    float fx = x - (float)ix, fy = y - (float)iy;
    for (int k = 0; k < 4; k++) {
        long i = ix + (k & 1), j = iy + (k >> 1);
        /* crossing an edge of the octahedral square lands on the same edge, mirrored */
        if (i < 0 || i >= n) {
            i = i < 0 ? 0 : n - 1;
            j = n - 1 - j;
        }
        if (j < 0 || j >= n) {
            j = j < 0 ? 0 : n - 1;
            i = n - 1 - i;
        }
        idx[k] = (uint32_t)(j * n + i);
    }
    w[0] = (1.0f - fx) * (1.0f - fy);
    w[1] = fx * (1.0f - fy);
    w[2] = (1.0f - fx) * fy;
    w[3] = fx * fy;
}

/* Float forms of wenv_hemi_encode and wenv_hemi_bilinear, for the resampling loops. */
static inline void wenv_hemi_encode_f(const float d[3], float *u, float *v)
{
    float z = d[2] > 0.0f ? d[2] : 0.0f;
    float l1 = fabsf(d[0]) + fabsf(d[1]) + z;
    if (l1 <= 0.0f) {
        *u = *v = 0.0f;
        return;
    }
    float px = d[0] / l1, py = d[1] / l1;
    *u = px + py;
    *v = px - py;
}

static inline void wenv_hemi_bilinear_f(long n, float u, float v, uint32_t idx[4], float w[4])
{
    float hi = (float)(n - 1);
    float x = (u + 1.0f) * 0.5f * (float)n - 0.5f, y = (v + 1.0f) * 0.5f * (float)n - 0.5f;
    x = x < 0.0f ? 0.0f : (x > hi ? hi : x);
    y = y < 0.0f ? 0.0f : (y > hi ? hi : y);
    long i = (long)x, j = (long)y; /* x, y >= 0: truncation is floor */
    if (i > n - 2)
        i = n - 2;
    if (j > n - 2)
        j = n - 2;
    float fx = x - (float)i, fy = y - (float)j;
    idx[0] = (uint32_t)(j * n + i);
    idx[1] = idx[0] + 1;
    idx[2] = idx[0] + (uint32_t)n;
    idx[3] = idx[2] + 1;
    w[0] = (1.0f - fx) * (1.0f - fy);
    w[1] = fx * (1.0f - fy);
    w[2] = (1.0f - fx) * fy;
    w[3] = fx * fy;
}

#endif
