#include "math/spherical_harmonics.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "math/quadrature.h"

void wenv_sh_eval(size_t order, const double d[3], double *y)
{
    const double x = d[0], yy = d[1], z = d[2];
    double c = 1.0, s = 0.0;                 /* Re, Im of (x + i y)^m: sin^m(theta) cos/sin(m phi) */
    double pmm = 0.28209479177387814;        /* N_mm without sin^m: 1 / sqrt(4 pi) at m = 0 */
    for (size_t m = 0; m <= order; m++) {
        if (m > 0) {
            double cn = x * c - yy * s;
            s = x * s + yy * c;
            c = cn;
            pmm *= -sqrt((2.0 * (double)m + 1.0) / (2.0 * (double)m));
        }
        double p2 = 0.0, p1 = pmm;
        for (size_t l = m; l <= order; l++) {
            double p;
            if (l == m)
                p = pmm;
            else if (l == m + 1)
                p = sqrt(2.0 * (double)m + 3.0) * z * pmm;
            else {
                double L = (double)l, M = (double)m;
                double a = sqrt((4.0 * L * L - 1.0) / (L * L - M * M));
                double b = sqrt(((L - 1.0) * (L - 1.0) - M * M) / (4.0 * (L - 1.0) * (L - 1.0) - 1.0));
                p = a * (z * p1 - b * p2);
            }
            if (l > m) {
                p2 = p1;
                p1 = p;
            }
            size_t base = l * l + l;
            if (m == 0)
                y[base] = p;
            else {
                y[base + m] = M_SQRT2 * p * c;
                y[base - m] = M_SQRT2 * p * s;
            }
        }
    }
}

double wenv_sh_lambert_factor(size_t l)
{
    if (l == 0)
        return M_PI;
    if (l == 1)
        return 2.0 * M_PI / 3.0;
    if (l % 2)
        return 0.0;
    /* 2 pi (-1)^(l/2 - 1) / ((l + 2)(l - 1)) * binomial(l, l/2) / 2^l */
    double central = 1.0;
    for (size_t k = 1; k <= l / 2; k++)
        central *= (double)(l / 2 + k) / (double)k / 4.0;
    double sign = (l / 2) % 2 ? 1.0 : -1.0;
    return 2.0 * M_PI * sign * central / ((double)(l + 2) * (double)(l - 1));
}

void wenv_sh_irradiance(size_t order, const double *coeffs, const double n[3], double rgb[3])
{
    double y[(WENV_SH_ORDER_MAX + 1) * (WENV_SH_ORDER_MAX + 1)];
    wenv_sh_eval(order, n, y);
    rgb[0] = rgb[1] = rgb[2] = 0.0;
    for (size_t l = 0; l <= order; l++) {
        double a = wenv_sh_lambert_factor(l);
        if (a == 0.0)
            continue;
        for (size_t i = l * l; i < (l + 1) * (l + 1); i++)
            for (int c = 0; c < 3; c++)
                rgb[c] += a * coeffs[3 * i + c] * y[i];
    }
}

/* ---- rotation ---------------------------------------------------------------------------------- */

struct wenv_sh_rotation {
    size_t order;
    double *quarter; /* per band l, the (2l+1)^2 matrix of f -> f o Q, row-major, at band_offset(l) */
};

static size_t band_offset(size_t l) { return l * (2 * l - 1) * (2 * l + 1) / 3; } /* sum_{k<l} (2k+1)^2 */

void wenv_sh_rotation_free(wenv_sh_rotation *rot)
{
    if (!rot)
        return;
    free(rot->quarter);
    free(rot);
}

/* C(Q)_ij = Int Y_i(w) Y_j(Q w) dw over each band by a product rule (Gauss-Legendre in z, uniform
 * in phi) that is exact for the band-2L polynomials involved. */
wenv_status wenv_sh_rotation_create(wenv_sh_rotation **out, size_t order, wenv_error *err)
{
    *out = NULL;
    if (order > WENV_SH_ORDER_MAX)
        return wenv_error_set(err, WENV_ERR_VALUE, "order must be at most %d, got %zu", WENV_SH_ORDER_MAX, order);
    size_t count = wenv_sh_count(order), nz = order + 2, nphi = 2 * order + 3;
    wenv_sh_rotation *rot = calloc(1, sizeof *rot);
    double *zx = malloc(2 * nz * sizeof(double));
    double *ya = malloc(2 * count * sizeof(double));
    if (rot)
        rot->quarter = calloc(band_offset(order + 1), sizeof(double));
    if (!rot || !rot->quarter || !zx || !ya) {
        wenv_sh_rotation_free(rot);
        free(zx);
        free(ya);
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for SH rotation");
    }
    rot->order = order;
    double *zw = zx + nz, *yb = ya + count;
    wenv_gauss_legendre_01(nz, zx, zw);
    for (size_t a = 0; a < nz; a++) {
        double z = 2.0 * zx[a] - 1.0, r = sqrt(fmax(0.0, 1.0 - z * z));
        double w = 2.0 * zw[a] * 2.0 * M_PI / (double)nphi;
        for (size_t b = 0; b < nphi; b++) {
            double phi = 2.0 * M_PI * (double)b / (double)nphi;
            double d[3] = {r * cos(phi), r * sin(phi), z};
            double qd[3] = {d[0], d[2], -d[1]}; /* Q = Rx(-pi/2) */
            wenv_sh_eval(order, d, ya);
            wenv_sh_eval(order, qd, yb);
            for (size_t l = 0; l <= order; l++) {
                size_t n = 2 * l + 1, base = l * l;
                double *blk = rot->quarter + band_offset(l);
                for (size_t i = 0; i < n; i++)
                    for (size_t j = 0; j < n; j++)
                        blk[i * n + j] += w * ya[base + i] * yb[base + j];
            }
        }
    }
    /* the exact entries are 0 or of size ~1 / sqrt(2l+1); drop quadrature rounding */
    for (size_t e = 0; e < band_offset(order + 1); e++)
        if (fabs(rot->quarter[e]) < 1e-13)
            rot->quarter[e] = 0.0;
    free(zx);
    free(ya);
    *out = rot;
    return WENV_OK;
}

void wenv_sh_rotate_z(size_t order, double angle, double *c, size_t channels)
{
    double c1 = cos(angle), s1 = sin(angle), cm = 1.0, sm = 0.0;
    for (size_t m = 1; m <= order; m++) {
        double t = cm * c1 - sm * s1;
        sm = sm * c1 + cm * s1;
        cm = t;
        for (size_t l = m; l <= order; l++) {
            double *a = c + (l * l + l + m) * channels, *b = c + (l * l + l - m) * channels;
            for (size_t k = 0; k < channels; k++) {
                double av = a[k], bv = b[k];
                a[k] = av * cm + bv * sm;
                b[k] = bv * cm - av * sm;
            }
        }
    }
}

/* out = C(Q) in (transpose = 0) or C(Q)^T in (transpose = 1), band by band */
static void apply_quarter(const wenv_sh_rotation *rot, int transpose, const double *in, double *out, size_t channels)
{
    for (size_t l = 0; l <= rot->order; l++) {
        size_t n = 2 * l + 1, base = l * l;
        const double *blk = rot->quarter + band_offset(l);
        double *o = out + base * channels;
        const double *x = in + base * channels;
        memset(o, 0, n * channels * sizeof(double));
        for (size_t i = 0; i < n; i++)
            for (size_t j = 0; j < n; j++) {
                double q = transpose ? blk[j * n + i] : blk[i * n + j];
                if (q == 0.0)
                    continue;
                for (size_t k = 0; k < channels; k++)
                    o[i * channels + k] += q * x[j * channels + k];
            }
    }
}

/* C(Rz(a) Q Rz(b) Q^T Rz(g)) = Cz(g) C(Q)^T Cz(b) C(Q) Cz(a) */
void wenv_sh_rotate_zyz(const wenv_sh_rotation *rot, double alpha, double beta, double gamma, const double *in,
                        double *out, size_t channels, double *work)
{
    size_t count = wenv_sh_count(rot->order);
    memcpy(out, in, count * channels * sizeof(double));
    wenv_sh_rotate_z(rot->order, alpha, out, channels);
    apply_quarter(rot, 0, out, work, channels);
    wenv_sh_rotate_z(rot->order, beta, work, channels);
    apply_quarter(rot, 1, work, out, channels);
    wenv_sh_rotate_z(rot->order, gamma, out, channels);
}

void wenv_sh_frame_angles(const double frame[9], double *alpha, double *beta, double *gamma)
{
    const double *t = frame, *n = frame + 6;
    double a = atan2(n[1], n[0]), b = acos(fmax(-1.0, fmin(1.0, n[2])));
    double ca = cos(a), sa = sin(a), cb = cos(b), sb = sin(b);
    /* t in the frame Rz(a) Ry(b): Ry(b)^T Rz(a)^T t */
    double tx = ca * t[0] + sa * t[1], ty = -sa * t[0] + ca * t[1], tz = t[2];
    double x0 = cb * tx - sb * tz;
    *alpha = a;
    *beta = b;
    *gamma = atan2(ty, x0);
}
