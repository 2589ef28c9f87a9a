#include "math/maps.h"

#include <math.h>

static double sgn(double x) { return x < 0.0 ? -1.0 : 1.0; }

static void normalize3(double d[3])
{
    double len = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
    d[0] /= len;
    d[1] /= len;
    d[2] /= len;
}

void wenv_oct_encode(const double d[3], double *u, double *v)
{
    double l1 = fabs(d[0]) + fabs(d[1]) + fabs(d[2]);
    double px = d[0] / l1, py = d[1] / l1;
    if (d[2] < 0.0) {
        double qx = (1.0 - fabs(py)) * sgn(px);
        double qy = (1.0 - fabs(px)) * sgn(py);
        px = qx;
        py = qy;
    }
    *u = px;
    *v = py;
}

void wenv_oct_decode(double u, double v, double d[3])
{
    d[0] = u;
    d[1] = v;
    d[2] = 1.0 - (fabs(u) + fabs(v)); /* the same for (v, u): the square's symmetries stay exact */
    if (d[2] < 0.0) {
        double x = (1.0 - fabs(v)) * sgn(u);
        double y = (1.0 - fabs(u)) * sgn(v);
        d[0] = x;
        d[1] = y;
    }
    normalize3(d);
}

void wenv_hemi_encode(const double d[3], double *u, double *v)
{
    double z = d[2] > 0.0 ? d[2] : 0.0;
    double l1 = fabs(d[0]) + fabs(d[1]) + z;
    if (l1 <= 0.0) {
        *u = *v = 0.0;
        return;
    }
    double px = d[0] / l1, py = d[1] / l1;
    *u = px + py;
    *v = px - py;
}

void wenv_hemi_decode(double u, double v, double d[3])
{
    d[0] = 0.5 * (u + v);
    d[1] = 0.5 * (u - v);
    d[2] = 1.0 - (fabs(d[0]) + fabs(d[1]));
    if (d[2] < 0.0)
        d[2] = 0.0;
    normalize3(d);
}

/* One rounding of an exact numerator: texel i's centre is exactly minus texel n - 1 - i's, so the
 * square's symmetries take centres onto centres bit for bit (slice_operators.h relies on it). */
double wenv_map_texel_center(size_t n, size_t i) { return (2.0 * (double)i + 1.0 - (double)n) / (double)n; }

double wenv_spherical_triangle(const double a[3], const double b[3], const double c[3])
{
    /* Van Oosterom & Strackee: stable for small and large triangles. */
    double bc[3] = {b[1] * c[2] - b[2] * c[1], b[2] * c[0] - b[0] * c[2], b[0] * c[1] - b[1] * c[0]};
    double det = fabs(a[0] * bc[0] + a[1] * bc[1] + a[2] * bc[2]);
    double ab = a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    double bcd = b[0] * c[0] + b[1] * c[1] + b[2] * c[2];
    double ca = c[0] * a[0] + c[1] * a[1] + c[2] * a[2];
    return 2.0 * atan2(det, 1.0 + ab + bcd + ca);
}

/* A texel split along the diagonal that the map's fold follows inside it: each half lies on one
 * face of the (hemi-)octahedron, where the map is affine, so it projects to a geodesic triangle. */
static double texel_solid_angle(size_t n, size_t i, size_t j, int hemi)
{
    double h = 2.0 / (double)n;
    double u0 = -1.0 + h * (double)i, v0 = -1.0 + h * (double)j, u1 = u0 + h, v1 = v0 + h;
    double uc = 0.5 * (u0 + u1), vc = 0.5 * (v0 + v1);
    void (*decode)(double, double, double *) = hemi ? wenv_hemi_decode : wenv_oct_decode;
    double c00[3], c10[3], c01[3], c11[3];
    decode(u0, v0, c00);
    decode(u1, v0, c10);
    decode(u0, v1, c01);
    decode(u1, v1, c11);
    int main_diagonal = (uc * vc > 0.0) == (hemi != 0);
    if (main_diagonal)
        return wenv_spherical_triangle(c00, c10, c11) + wenv_spherical_triangle(c00, c11, c01);
    return wenv_spherical_triangle(c10, c11, c01) + wenv_spherical_triangle(c10, c01, c00);
}

double wenv_oct_texel_solid_angle(size_t n, size_t i, size_t j) { return texel_solid_angle(n, i, j, 0); }
double wenv_hemi_texel_solid_angle(size_t n, size_t i, size_t j) { return texel_solid_angle(n, i, j, 1); }

void wenv_oct_texel_solid_angles(size_t n, double *out)
{
    size_t half = (n + 1) / 2;
    for (size_t b = 0; b < half; b++)
        for (size_t a = 0; a <= b; a++) {
            double omega = wenv_oct_texel_solid_angle(n, a, b);
            size_t xs[2] = {a, n - 1 - a}, ys[2] = {b, n - 1 - b};
            for (int p = 0; p < 2; p++)
                for (int q = 0; q < 2; q++) {
                    out[ys[q] * n + xs[p]] = omega;
                    out[xs[p] * n + ys[q]] = omega;
                }
        }
}

/* Texel coordinate of map coordinate u: texel centres sit at integers. */
static double texel_coord(size_t n, double u) { return (u + 1.0) * 0.5 * (double)n - 0.5; }

void wenv_oct_bilinear(size_t n, double u, double v, size_t idx[4], double w[4])
{
    double x = texel_coord(n, u), y = texel_coord(n, v);
    double fx0 = floor(x), fy0 = floor(y);
    double fx = x - fx0, fy = y - fy0;
    long ix = (long)fx0, iy = (long)fy0, nn = (long)n;
    for (int k = 0; k < 4; k++) {
        long i = ix + (k & 1), j = iy + (k >> 1);
        /* Crossing an edge of the octahedral square lands on the same edge, mirrored. */
        if (i < 0 || i >= nn) {
            i = i < 0 ? 0 : nn - 1;
            j = nn - 1 - j;
        }
        if (j < 0 || j >= nn) {
            j = j < 0 ? 0 : nn - 1;
            i = nn - 1 - i;
        }
        idx[k] = (size_t)j * n + (size_t)i;
    }
    w[0] = (1.0 - fx) * (1.0 - fy);
    w[1] = fx * (1.0 - fy);
    w[2] = (1.0 - fx) * fy;
    w[3] = fx * fy;
}

void wenv_hemi_bilinear(size_t n, double u, double v, size_t idx[4], double w[4])
{
    double hi = (double)n - 1.0;
    double x = texel_coord(n, u), y = texel_coord(n, v);
    x = x < 0.0 ? 0.0 : (x > hi ? hi : x);
    y = y < 0.0 ? 0.0 : (y > hi ? hi : y);
    double fx0 = floor(x), fy0 = floor(y);
    if (fx0 >= hi)
        fx0 = hi - 1.0;
    if (fy0 >= hi)
        fy0 = hi - 1.0;
    if (fx0 < 0.0)
        fx0 = 0.0;
    if (fy0 < 0.0)
        fy0 = 0.0;
    double fx = x - fx0, fy = y - fy0;
    size_t i = (size_t)fx0, j = (size_t)fy0;
    size_t i1 = n > 1 ? i + 1 : i, j1 = n > 1 ? j + 1 : j;
    idx[0] = j * n + i;
    idx[1] = j * n + i1;
    idx[2] = j1 * n + i;
    idx[3] = j1 * n + i1;
    w[0] = (1.0 - fx) * (1.0 - fy);
    w[1] = fx * (1.0 - fy);
    w[2] = (1.0 - fx) * fy;
    w[3] = fx * fy;
}
