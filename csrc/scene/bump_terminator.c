/* Cycles' bump terminator for a diffuse closure (bump_terminator.h). */
#include "scene/bump_terminator.h"

#include <math.h>

#include "math/quadrature.h"

#define QUAD_NODES 48

/* GGX's Smith G1 at cosine c of a lobe of alpha^2 a2, as Cycles' bsdf_G. */
static double ggx_g1(double a2, double c)
{
    double t2 = (1.0 - c * c) / (c * c);
    return 2.0 / (1.0 + sqrt(1.0 + a2 * t2));
}

static double bend_alpha2(double cos_bend)
{
    double c2 = cos_bend * cos_bend;
    double a2 = c2 > 0.0 ? 0.125 * (1.0 / c2 - 1.0) : 1.0;
    return a2 < 1.0 ? a2 : 1.0;
}

/* Chiang, Li and Burley's term of g = cos(smooth, l) / (cos(bent, l) cos(bend)). */
static double chiang(double ci, double cn, double cd)
{
    double g = cn * cd > 0.0 ? ci / (cn * cd) : 0.0;
    if (g >= 1.0)
        return 1.0;
    return g > 0.0 ? (-g + 1.0) * g * g + g : 0.0;
}

double wenv_bump_diffuse_weight(const double n[3], const double ns[3], const double l[3], int correction)
{
    double cos_sl = ns[0] * l[0] + ns[1] * l[1] + ns[2] * l[2];
    double cos_sn = ns[0] * n[0] + ns[1] * n[1] + ns[2] * n[2];
    double cos_nl = n[0] * l[0] + n[1] * l[1] + n[2] * l[2];
    if (cos_sl * cos_sn * cos_nl < 0.0)
        return 0.0;
    double ci = fabs(cos_sl), cd = fabs(cos_sn);
    if (correction == WENV_BUMP_NONE || cd >= 1.0 || ci >= 1.0)
        return 1.0;
    if (correction == WENV_BUMP_CHIANG)
        return chiang(ci, fabs(cos_nl), cd);
    if (ci < 1e-6)
        return 0.0;
    return ggx_g1(bend_alpha2(cd), ci);
}

/* The share at bend cosine cd: (1/pi) times the integral over the smooth hemisphere of G1 x the
 * bent cosine, whose azimuthal integral is closed: for a = cd cos t, b = sd sin t, the integral of
 * max(0, a + b cos phi) over phi is 2 pi a where a >= b, else 2 (a phi0 + b sin phi0), cos phi0 = -a/b. */
static double share_at(double cd, int correction, const double *x, const double *w)
{
    double sd = sqrt(fmax(0.0, 1.0 - cd * cd)), a2 = bend_alpha2(cd), sum = 0.0;
    for (int k = 0; k < QUAD_NODES; k++) {
        double t = 0.5 * M_PI * x[k], ct = cos(t), st = sin(t);
        double a = cd * ct, b = sd * st, ring, phi0 = a >= b ? M_PI : acos(-a / b);
        if (correction == WENV_BUMP_CHIANG && cd < 1.0) { /* the term turns with the azimuth too */
            ring = 0.0;
            for (int j = 0; j < QUAD_NODES; j++) {
                double cn = a + b * cos(phi0 * x[j]);
                ring += 2.0 * phi0 * w[j] * cn * chiang(ct, cn, cd);
            }
        } else {
            ring = a >= b ? 2.0 * M_PI * a : 2.0 * (a * phi0 + b * sin(phi0));
            ring *= correction == WENV_BUMP_MICROFACET && cd < 1.0 ? ggx_g1(a2, ct) : 1.0;
        }
        sum += w[k] * 0.5 * M_PI * ring * st;
    }
    return sum / M_PI;
}

void wenv_bump_shares_make(wenv_bump_shares *t, int correction)
{
    double x[QUAD_NODES], w[QUAD_NODES];
    wenv_gauss_legendre_01(QUAD_NODES, x, w);
    for (int k = 0; k <= WENV_BUMP_SHARES; k++)
        t->share[k] = (float)share_at((double)k / WENV_BUMP_SHARES, correction, x, w);
    t->share[WENV_BUMP_SHARES] = 1.0f;
}

void wenv_bump_share_rows(const float *normals, const float *smooth, size_t n, int correction, float *share)
{
    wenv_bump_shares t;
    wenv_bump_shares_make(&t, correction);
    for (size_t i = 0; i < n; i++) {
        const float *a = normals + 3 * i, *b = smooth + 3 * i;
        float la = sqrtf(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]), lb = sqrtf(b[0] * b[0] + b[1] * b[1] + b[2] * b[2]);
        float c = (a[0] * b[0] + a[1] * b[1] + a[2] * b[2]) / (la * lb);
        c = fabsf(c); /* a closure bent past the smooth horizon takes the other side's light alike */
        c = c < 1.0f ? c : 1.0f;
        float at = c * WENV_BUMP_SHARES;
        int k = (int)at;
        k = k < WENV_BUMP_SHARES - 1 ? k : WENV_BUMP_SHARES - 1;
        float f = at - (float)k;
        share[i] = c >= 1.0f ? 1.0f : t.share[k] + f * (t.share[k + 1] - t.share[k]);
    }
}

void wenv_bump_horizons(const float *normals, const float *smooth, size_t n, float *horizon)
{
    for (size_t i = 0; i < n; i++) {
        const float *a = normals + 3 * i, *b = smooth + 3 * i;
        float lb = sqrtf(b[0] * b[0] + b[1] * b[1] + b[2] * b[2]), s[3] = {b[0] / lb, b[1] / lb, b[2] / lb};
        float along = a[0] * s[0] + a[1] * s[1] + a[2] * s[2], t[3];
        for (int c = 0; c < 3; c++)
            t[c] = a[c] - along * s[c];
        float lt = sqrtf(t[0] * t[0] + t[1] * t[1] + t[2] * t[2]);
        if (!(lt > 1e-6f * sqrtf(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]))) {
            /* unbent: a horizon across the smooth normal, which loses nothing */
            float pick[3] = {fabsf(s[0]) < 0.9f ? 1.0f : 0.0f, fabsf(s[0]) < 0.9f ? 0.0f : 1.0f, 0.0f};
            along = pick[0] * s[0] + pick[1] * s[1];
            for (int c = 0; c < 3; c++)
                t[c] = pick[c] - along * s[c];
            lt = sqrtf(t[0] * t[0] + t[1] * t[1] + t[2] * t[2]);
        }
        for (int c = 0; c < 3; c++)
            horizon[3 * i + (size_t)c] = t[c] / lt;
    }
}
