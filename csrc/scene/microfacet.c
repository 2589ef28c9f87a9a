/* One microfacet lobe (microfacet.h): what is not inline there -- D by cos_h, Lambda, the CDF, the
 * checks -- and the lobe's quadrature rules. */
#include "scene/microfacet.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "math/quadrature.h"

#ifndef M_PI
#define M_PI 3.14159265358979323846
#endif

#define ALBEDO_SAMPLES_MIN 8
#define ALBEDO_SAMPLES_MAX 4096

double wenv_alpha_from_roughness(double roughness)
{
    return fmax(roughness * roughness, WENV_ALPHA_FROM_ROUGHNESS_MIN);
}

double wenv_ndf(wenv_distribution dist, double m, double cos_h)
{
    if (!(cos_h > 0.0))
        return 0.0;
    double c = fmin(cos_h, 1.0);
    double s2 = (1.0 - c) * (1.0 + c); /* sin^2 without cancellation near c = 1 */
    return wenv_ndf_tan2(dist == WENV_NDF_GGX, m, s2 / fmax(c * c, DBL_MIN));
}

void wenv_ndf_cdf(wenv_distribution dist, double m, double tan2, double *xi, double *rest)
{
    double m2 = m * m;
    if (dist == WENV_NDF_GGX) {
        *xi = tan2 / (m2 + tan2);
        *rest = m2 / (m2 + tan2);
    } else {
        *xi = -expm1(-tan2 / m2);
        *rest = exp(-tan2 / m2);
    }
}

double wenv_ndf_tan2_at(wenv_distribution dist, double m, double xi, double rest)
{
    double m2 = m * m;
    return dist == WENV_NDF_GGX ? m2 * xi / rest : -m2 * log(rest);
}

double wenv_slope_density(wenv_distribution dist, double m, double tan2)
{
    double q = 1.0 + tan2;
    return wenv_ndf_tan2(dist == WENV_NDF_GGX, m, tan2) / (q * q);
}

double wenv_smith_lambda(wenv_distribution dist, double m, double cos_theta)
{
    double c = fmin(fmax(cos_theta, 0.0), 1.0);
    double s = sqrt((1.0 - c) * (1.0 + c));
    double cc = fmax(c, 1e-150); /* horizon: large finite instead of inf (and no overflow of m^2 tan^2) */
    if (dist == WENV_NDF_GGX) {
        /* (sqrt(1 + x) - 1) / 2 rewritten as x / (2 (1 + sqrt(1 + x))): no cancellation for small x. */
        double mt = m * s / cc;
        double x = mt * mt;
        return x / (2.0 * (1.0 + sqrt(1.0 + x)));
    }
    double a = fmin(cc / fmax(m * s, DBL_MIN), WENV_BECKMANN_A_CAP);
    /* (erf(a) - 1) / 2 = -erfc(a) / 2: erfc keeps the small difference accurate for large a. */
    double lambda = 0.5 * (exp(-a * a) * WENV_INV_SQRT_PI / a - erfc(a));
    return fmax(lambda, 0.0);
}

double wenv_lobe_cos_h_min(const wenv_lobe *lobe)
{
    enum { STEPS = 4096 };
    double peak = 0.0;
    for (int i = 0; i <= STEPS; i++)
        peak = fmax(peak, wenv_ndf(lobe->distribution, lobe->alpha, cos(0.5 * M_PI * i / STEPS)));
    int i = STEPS;
    while (i > 0 && wenv_ndf(lobe->distribution, lobe->alpha, cos(0.5 * M_PI * i / STEPS)) < 1e-7 * peak)
        i--;
    i = i < STEPS ? i + 1 : STEPS;
    return i >= STEPS ? -1.0 : cos(0.5 * M_PI * i / STEPS);
}

double wenv_lobe_eval(const wenv_lobe *lobe, wenv_shadowing shadowing, const double wi[3], const double wo[3])
{
    if (!(wi[2] > 0.0) || !(wo[2] > 0.0))
        return 0.0;
    return wenv_lobe_value(lobe, shadowing, wi, wo, wenv_lobe_view_k(lobe, shadowing, wo));
}

wenv_status wenv_lobe_check(const wenv_lobe *lobe, size_t i, wenv_error *err)
{
    for (int c = 0; c < 3; c++) {
        if (!isfinite(lobe->specular[c]) || lobe->specular[c] < 0.0)
            return wenv_error_set(err, WENV_ERR_VALUE, "lobes[%zu].specular must be finite and >= 0, got %g", i,
                                  lobe->specular[c]);
    }
    if (!isfinite(lobe->alpha) || lobe->alpha < WENV_ALPHA_MIN || lobe->alpha > WENV_ALPHA_MAX)
        return wenv_error_set(err, WENV_ERR_VALUE, "lobes[%zu].alpha must be finite in [%g, %g], got %g", i,
                              WENV_ALPHA_MIN, WENV_ALPHA_MAX, lobe->alpha);
    if (!isfinite(lobe->ior) || !(lobe->ior > 1.0) || lobe->ior > WENV_IOR_MAX)
        return wenv_error_set(err, WENV_ERR_VALUE, "lobes[%zu].ior must be finite in (1, %g], got %g", i, WENV_IOR_MAX,
                              lobe->ior);
    if (lobe->distribution != WENV_NDF_BECKMANN && lobe->distribution != WENV_NDF_GGX)
        return wenv_error_set(err, WENV_ERR_VALUE, "lobes[%zu].distribution must be beckmann or ggx", i);
    return WENV_OK;
}

/* ---------------------------------------------------------------- albedo quadrature */

/* Integral of F D G / (4 ci co) * ci over wi, substituted to the half vector (d wi = 4 (wo.h) d wh)
 * and then to the distribution's CDF xi(theta_h), for which D cos_h d wh = d xi d phi / (2 pi):
 *   albedo = (1 / 2 pi) Int d phi Int_0^xi_max(phi) F G (wo.h) / (co cos_h) d xi.
 * Nodes follow D, so peaks of any width are resolved.  Three details keep it accurate for grazing
 * views and tiny roughness with a modest node count:
 *  - Range: for azimuth phi' (relative to wo's) the reflected wi is above the horizon exactly for
 *    theta_h < theta_max = pi/4 + beta/2, beta = atan(tan(theta_o) cos phi') (there cos_i =
 *    A sin(2 (theta_max - theta_h)) and wo.h > 0 holds), so the rule never straddles that kink.
 *  - Grading: Smith G changes quickly where cos_i ~ m, just below theta_max, and in xi that band can
 *    be far narrower than the node spacing; xi = xi_max (1 - (1 - u)^4) crowds nodes there.
 *  - Azimuth: for grazing views beta swings from +theta_o to -theta_o within ~cos(theta_o) of
 *    phi' = 90 deg; half of the map phi'(v) follows beta (phi' = acos(tan(theta_o cos(pi v)) /
 *    tan(theta_o))), half is linear, over the mirror-symmetric half circle [0, pi]. */
typedef struct {
    size_t n;            /* nodes on [0, 1] */
    const double *x, *w; /* positions and weights */
} unit_rule;

/* The rule's nodes are recorded when node_wi is not NULL (node_weight too; node_omega, the solid
 * angle in wi each node stands for, may be NULL).  Every (theta, phi) node is recorded, with weight
 * 0 where rounding puts wi below the horizon, so the count is always 2 nt np. */
static double lobe_rule_nodes(const wenv_lobe *lobe, wenv_shadowing shadowing, const double wo[3], unit_rule rt,
                              unit_rule rp, int include_fresnel, double *node_wi, double *node_weight,
                              double *node_omega, size_t *node_count)
{
    size_t recorded = 0;
    if (node_count)
        *node_count = 0;
    if (!(wo[2] > 0.0))
        return 0.0;
    double k_o = wenv_lobe_view_k(lobe, shadowing, wo);
    double co = wo[2], so = sqrt(wo[0] * wo[0] + wo[1] * wo[1]);
    double phi_o = atan2(wo[1], wo[0]);
    double theta_o = atan2(so, co), tan_o = so / co;
    double lambda = theta_o > 1e-6 ? 0.5 : 0.0; /* near the normal beta is ~0 and the linear map suffices */
    double total = 0.0;
    for (size_t j = 0; j < rp.n; j++) {
        double v = rp.x[j];
        /* phi' and d phi' / dv of the mixed map (see above). */
        double phi = M_PI * v, dphi = M_PI;
        if (lambda > 0.0) {
            double b = theta_o * cos(M_PI * v), tb = tan(b);
            /* 1 - y^2 with y = tan(b) / tan_o, from tan_o - tan(b) = sin(theta_o - b) / (cos theta_o cos b)
             * and theta_o - b = 2 theta_o sin^2(pi v / 2): no cancellation near the ends. */
            double sv = sin(0.5 * M_PI * v);
            double diff = sin(2.0 * theta_o * sv * sv) / (cos(theta_o) * cos(b));
            double sin_phi = sqrt(fmax(diff * (tan_o + tb), 0.0)) / tan_o;
            double phi_b = atan2(sin_phi, tb / tan_o);
            double cb = cos(b);
            double dphi_b = sin_phi > 0.0 ? theta_o * M_PI * sin(M_PI * v) / (cb * cb * tan_o * sin_phi) : 0.0;
            phi = (1.0 - lambda) * phi + lambda * phi_b;
            dphi = (1.0 - lambda) * dphi + lambda * dphi_b;
        }
        double cp = cos(phi_o + phi), sp = sin(phi_o + phi);
        double p = so * cos(phi), amp = sqrt(co * co + p * p);
        double tan_max = p >= 0.0 ? (amp + p) / co : co / (amp - p); /* tan(pi/4 + beta/2), stable */
        double t_max = tan_max * tan_max;
        /* xi_max and 1 - xi_max, each without cancellation. */
        double xi_max, rest;
        wenv_ndf_cdf(lobe->distribution, lobe->alpha, t_max, &xi_max, &rest);
        double ring = 0.0;
        for (size_t i = 0; i < rt.n; i++) {
            double r = 1.0 - rt.x[i], r3 = r * r * r;
            double xi = xi_max * (1.0 - r3 * r);
            double one_minus_xi = rest + xi_max * r3 * r;
            double t = wenv_ndf_tan2_at(lobe->distribution, lobe->alpha, xi, one_minus_xi);
            double ch = 1.0 / sqrt(1.0 + t), sh = sqrt(t) * ch;
            double h[3] = {sh * cp, sh * sp, ch};
            double oh = wo[0] * h[0] + wo[1] * h[1] + wo[2] * h[2];
            double wi[3] = {2.0 * oh * h[0] - wo[0], 2.0 * oh * h[1] - wo[1], 2.0 * oh * h[2] - wo[2]};
            double term = 0.0;
            if (oh > 0.0 && wi[2] > 0.0) { /* fails only by rounding at the range's end */
                /* vis = G / (4 ci co); the integrand F G (wo.h) / (co ch) = F vis 4 ci (wo.h) / ch. */
                double vis = wenv_lobe_vis(lobe, shadowing, wi, wo, k_o, wenv_half_vector_of(wi, wo));
                double f = include_fresnel ? wenv_fresnel_dielectric(oh, lobe->ior) : 1.0;
                term = rt.w[i] * 4.0 * r3 * f * vis * 4.0 * wi[2] * oh / ch;
            }
            ring += term;
            if (node_wi) {
                memcpy(node_wi + 3 * recorded, wi, sizeof wi);
                if (node_omega) {
                    /* d wi = 4 (wo.h) d wh and D cos_h d wh = d xi d phi / (2 pi), per unit of the
                     * rule's variables (the ring's factors follow below) */
                    double d = wenv_ndf(lobe->distribution, lobe->alpha, ch);
                    node_omega[recorded] = d > 0.0 ? rt.w[i] * 4.0 * r3 * 4.0 * fabs(oh) / (d * ch) : 0.0;
                }
                node_weight[recorded++] = term;
            }
        }
        total += rp.w[j] * dphi * xi_max * ring;
        if (node_wi) {
            /* this ring's nodes and their mirror images about the plane of wo and the normal (the
             * rule covers one half circle), each with half the weight */
            double scale = rp.w[j] * dphi * xi_max / (2.0 * M_PI), px = -sin(phi_o), py = cos(phi_o);
            size_t first = *node_count, len = recorded - first;
            for (size_t k = first; k < recorded; k++) {
                node_weight[k] *= scale;
                if (node_omega) {
                    node_omega[k] *= scale;
                    node_omega[k + len] = node_omega[k];
                }
                double *a = node_wi + 3 * k, *b = node_wi + 3 * (k + len), dp = a[0] * px + a[1] * py;
                b[0] = a[0] - 2.0 * dp * px;
                b[1] = a[1] - 2.0 * dp * py;
                b[2] = a[2];
                node_weight[k + len] = node_weight[k];
            }
            recorded += len;
            *node_count = recorded;
        }
    }
    return total / M_PI; /* (1 / 2 pi) * 2 halves */
}

static wenv_status albedo_nodes(size_t samples, double **x, double **w, wenv_error *err)
{
    *x = *w = NULL;
    if (samples < ALBEDO_SAMPLES_MIN || samples > ALBEDO_SAMPLES_MAX)
        return wenv_error_set(err, WENV_ERR_VALUE, "samples must be in [%d, %d], got %zu", ALBEDO_SAMPLES_MIN,
                              ALBEDO_SAMPLES_MAX, samples);
    *x = malloc(2 * samples * sizeof **x);
    if (!*x)
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for %zu quadrature nodes", samples);
    *w = *x + samples;
    wenv_gauss_legendre_01(samples, *x, *w);
    return WENV_OK;
}

wenv_status wenv_lobe_albedo(const wenv_lobe *lobe, wenv_shadowing shadowing, const double wo[3], size_t samples,
                             int include_fresnel, double *albedo, wenv_error *err)
{
    *albedo = 0.0;
    double *x, *w;
    wenv_status st = albedo_nodes(samples, &x, &w, err);
    if (st != WENV_OK)
        return st;
    unit_rule r = {samples, x, w};
    *albedo = lobe_rule_nodes(lobe, shadowing, wo, r, r, include_fresnel, NULL, NULL, NULL, NULL);
    free(x);
    return WENV_OK;
}

wenv_status wenv_lobe_nodes(const wenv_lobe *lobe, wenv_shadowing shadowing, const double wo[3], size_t samples,
                            double *wi, double *weight, size_t *count, wenv_error *err)
{
    *count = 0;
    double *x, *w;
    wenv_status st = albedo_nodes(samples, &x, &w, err);
    if (st != WENV_OK)
        return st;
    unit_rule r = {samples, x, w};
    lobe_rule_nodes(lobe, shadowing, wo, r, r, 1, wi, weight, NULL, count);
    free(x);
    return WENV_OK;
}

wenv_status wenv_lobe_cells(const wenv_lobe *lobe, wenv_shadowing shadowing, const double wo[3], size_t n_theta,
                            size_t n_phi, double *wi, double *weight, double *solid_angle, size_t *count,
                            wenv_error *err)
{
    *count = 0;
    if (n_theta < 1 || n_phi < 1 || n_theta > ALBEDO_SAMPLES_MAX || n_phi > ALBEDO_SAMPLES_MAX)
        return wenv_error_set(err, WENV_ERR_VALUE, "cell counts must be in [1, %d], got %zu x %zu",
                              ALBEDO_SAMPLES_MAX, n_theta, n_phi);
    double *x = malloc(2 * (n_theta + n_phi) * sizeof *x);
    if (!x)
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for %zu x %zu cells", n_theta, n_phi);
    double *w = x + n_theta, *xp = w + n_theta, *wp = xp + n_phi;
    for (size_t i = 0; i < n_theta; i++) {
        x[i] = ((double)i + 0.5) / (double)n_theta;
        w[i] = 1.0 / (double)n_theta;
    }
    wenv_gauss_legendre_01(n_phi, xp, wp);
    unit_rule rt = {n_theta, x, w}, rp = {n_phi, xp, wp};
    if (!(wo[2] > 0.0)) {
        /* nothing is reflected; the cells still exist, with weight 0 */
        size_t n = 2 * n_theta * n_phi;
        for (size_t k = 0; k < n; k++) {
            wi[3 * k] = wi[3 * k + 1] = 0.0;
            wi[3 * k + 2] = 1.0;
            weight[k] = solid_angle[k] = 0.0;
        }
        *count = n;
    } else {
        lobe_rule_nodes(lobe, shadowing, wo, rt, rp, 1, wi, weight, solid_angle, count);
    }
    free(x);
    return WENV_OK;
}

/* ---- the rule on a grid in slope space ---------------------------------------------------------- */

/* A half vector's slopes (x, y) = tan(theta_h) (cos phi_h, sin phi_h).  The distribution's slope
 * density P22 (D cos_h per unit slope area) is Beckmann's Gaussian exp(-(x^2 + y^2) / a^2) / (pi a^2)
 * or GGX's a^2 / (pi (a^2 + x^2 + y^2)^2); the cells below are graded in y's marginal CDF and in x's
 * CDF given y, so each holds the mass of D it is credited with.
 *
 * GGX is a mixture of Beckmann lobes: P22 = Int_0^inf e^-t B(a / sqrt(t)) dt, B(m) Beckmann's of RMS
 * slope m (its slopes are Gaussian over a scale that is Exp(1)).  Its part of scales t >= cut
 * (normalised; the grid `cut` > 0 gives) has Gaussian tails, 1 - P(cut q) of GGX's far out, with
 * q = 1 + (x^2 + y^2) / a^2 and P(u) = (1 + u) e^-u: P22 = e^cut P(cut q) GGX's.  Its marginal is in
 * closed form (the incomplete gamma function of order 3/2); its CDF given y is, over
 * v = atan(x / (a sqrt(B))) with B = 1 + y^2 / a^2, the integral of g(v) = (cos^2 v + cut B)
 * exp(-cut B tan^2 v), smooth and negligible past tan^2 v = 64 / (cut B): each row tabulates it on
 * CUT_PANELS panels of 4 Gauss-Legendre nodes, which a CDF value then completes within its panel. */
#define CUT_PANELS 128
typedef struct {
    int ggx;
    double a, cut;
} slope_grid;

typedef struct {
    double y, b;                   /* the row's slope y and a sqrt(B) = sqrt(a^2 + y^2) */
    double cb, v_max, dv;          /* cut B; the panels cover [-v_max, v_max] in steps of dv */
    double sum[CUT_PANELS + 1];    /* the integral of g up to each panel's start */
} slope_row;

static const double GL4_X[4] = {0.0694318442029737, 0.3300094782075719, 0.6699905217924281, 0.9305681557970263};
static const double GL4_W[4] = {0.1739274225687269, 0.3260725774312731, 0.3260725774312731, 0.1739274225687269};

static double cut_g(double cb, double v)
{
    double c2 = cos(v) * cos(v);
    return c2 > 0.0 ? (c2 + cb) * exp(-cb * (1.0 - c2) / c2) : 0.0;
}

static double cut_panel(double cb, double from, double to)
{
    double sum = 0.0, len = to - from;
    for (int k = 0; k < 4; k++)
        sum += GL4_W[k] * cut_g(cb, from + len * GL4_X[k]);
    return sum * len;
}

/* The row's integral of g from -v_max to v (clamped to the panels). */
static double cut_integral(const slope_row *row, double v)
{
    double at = (v + row->v_max) / row->dv;
    if (!(at > 0.0))
        return 0.0;
    if (at >= CUT_PANELS)
        return row->sum[CUT_PANELS];
    size_t k = (size_t)at;
    double start = -row->v_max + (double)k * row->dv;
    return row->sum[k] + cut_panel(row->cb, start, v);
}

static double slope_marginal_cdf(const slope_grid *g, double y)
{
    double a = g->a;
    if (!g->ggx)
        return 0.5 * erfc(-y / a);
    if (!(g->cut > 0.0))
        return 0.5 + 0.5 * y / sqrt(a * a + y * y);
    double b = fabs(y) / a, r = sqrt(1.0 + b * b), c = g->cut;
    double v = erf(b * sqrt(c)) + b * exp(c) * erfc(sqrt(c) * r) / r;
    return 0.5 + copysign(0.5 * v, y);
}

static double slope_marginal_pdf(const slope_grid *g, double y)
{
    double a = g->a;
    if (!g->ggx)
        return exp(-y * y / (a * a)) / (a * sqrt(M_PI));
    if (!(g->cut > 0.0)) {
        double q = a * a + y * y;
        return a * a / (2.0 * q * sqrt(q));
    }
    double s = 1.0 + y * y / (a * a), z = g->cut * s;
    double gamma = sqrt(z) * exp(-z) + 0.5 * sqrt(M_PI) * erfc(sqrt(z)); /* Gamma(3/2, z) */
    return exp(g->cut) * gamma / (a * sqrt(M_PI) * s * sqrt(s));
}

static void make_row(const slope_grid *g, double y, slope_row *row)
{
    row->y = y;
    row->b = sqrt(g->a * g->a + y * y);
    row->cb = row->v_max = row->dv = 0.0;
    if (!(g->ggx && g->cut > 0.0))
        return;
    row->cb = g->cut * (1.0 + y * y / (g->a * g->a));
    row->v_max = atan(8.0 / sqrt(row->cb));
    row->dv = 2.0 * row->v_max / CUT_PANELS;
    row->sum[0] = 0.0;
    for (size_t k = 0; k < CUT_PANELS; k++) {
        double from = -row->v_max + (double)k * row->dv;
        row->sum[k + 1] = row->sum[k] + cut_panel(row->cb, from, from + row->dv);
    }
}

static double slope_conditional_cdf(const slope_grid *g, const slope_row *row, double x)
{
    double a = g->a;
    if (!g->ggx)
        return 0.5 * erfc(-x / a);
    double b = row->b;
    if (!(g->cut > 0.0))
        return 0.5 + (b * x / (b * b + x * x) + atan(x / b)) / M_PI;
    return fmin(1.0, cut_integral(row, atan(x / b)) / row->sum[CUT_PANELS]);
}

static double slope_conditional_pdf(const slope_grid *g, const slope_row *row, double x)
{
    double a = g->a;
    if (!g->ggx)
        return exp(-x * x / (a * a)) / (a * sqrt(M_PI));
    double b = row->b;
    if (!(g->cut > 0.0)) {
        double q = b * b + x * x;
        return 2.0 * b * b * b / (M_PI * q * q);
    }
    double v = atan(x / b), c = cos(v);
    if (!(fabs(v) < row->v_max))
        return 0.0;
    return cut_g(row->cb, v) * c * c / (b * row->sum[CUT_PANELS]);
}

/* A cut row's v at CDF value u: its panel from the table, then Newton's steps on the integral
 * within it (g is its derivative), one or two from the panel's linear estimate. */
static double cut_inverse(const slope_row *row, double u)
{
    double target = u * row->sum[CUT_PANELS];
    size_t k0 = 0, k1 = CUT_PANELS;
    while (k1 - k0 > 1) {
        size_t mid = (k0 + k1) / 2;
        if (row->sum[mid] <= target)
            k0 = mid;
        else
            k1 = mid;
    }
    double lo = -row->v_max + (double)k0 * row->dv, hi = lo + row->dv, span = row->sum[k1] - row->sum[k0];
    double v = lo + (span > 0.0 ? (target - row->sum[k0]) / span : 0.5) * row->dv;
    for (int it = 0; it < 50; it++) {
        double gv = cut_g(row->cb, v);
        if (!(gv > 0.0))
            break;
        double next = v - (row->sum[k0] + cut_panel(row->cb, lo, v) - target) / gv;
        next = next < lo ? lo : (next > hi ? hi : next);
        int done = fabs(next - v) <= 1e-15 * (1.0 + fabs(v));
        v = next;
        if (done)
            break;
    }
    return v;
}

/* The slope at CDF value u (the marginal's if row is NULL, else the row's conditional): Newton's
 * steps on the CDF from the median, inside a bracket that each step narrows, bisecting where a step
 * would leave it.  A material's grazing rules take tens of thousands of these; bisection alone took
 * 100 CDF evaluations each (half of a material change's time), Newton takes about six. */
static double slope_inverse(const slope_grid *g, const slope_row *row, double u)
{
    double a = g->a, lo = -1e4 * a - 1.0, hi = 1e4 * a + 1.0, x = 0.0;
    for (int it = 0; it < 200; it++) {
        double f = (row ? slope_conditional_cdf(g, row, x) : slope_marginal_cdf(g, x)) - u;
        if (f == 0.0)
            return x;
        if (f < 0.0)
            lo = x;
        else
            hi = x;
        double p = row ? slope_conditional_pdf(g, row, x) : slope_marginal_pdf(g, x);
        double next = p > 0.0 ? x - f / p : 0.5 * (lo + hi);
        if (!(next > lo && next < hi))
            next = 0.5 * (lo + hi);
        if (fabs(next - x) <= 1e-14 * (a + fabs(x)) || hi - lo <= 1e-14 * (a + fabs(x)))
            return next;
        x = next;
    }
    return x;
}

double wenv_ggx_core_share(double alpha, double cut, double tan2)
{
    double u = cut * (1.0 + tan2 / (alpha * alpha));
    return (1.0 + u) * exp(-u);
}

/* wi for half-vector slopes (x, y) and wo = (s, 0, c); v.h and cos_h into *vh, *ch. */
static void slope_reflect(double x, double y, const double wo[3], double wi[3], double *vh, double *ch)
{
    double inv = 1.0 / sqrt(1.0 + x * x + y * y), h[3] = {x * inv, y * inv, inv};
    *vh = wo[0] * h[0] + wo[2] * h[2];
    *ch = inv;
    for (int c = 0; c < 3; c++)
        wi[c] = 2.0 * *vh * h[c] - wo[c];
}

static double angle_between(const double a[3], const double b[3])
{
    double cx = a[1] * b[2] - a[2] * b[1], cy = a[2] * b[0] - a[0] * b[2], cz = a[0] * b[1] - a[1] * b[0];
    return atan2(sqrt(cx * cx + cy * cy + cz * cz), a[0] * b[0] + a[1] * b[1] + a[2] * b[2]);
}

/* A grid's rows: each row's slope y, its share of the marginal (dy) and its conditional table. */
struct wenv_slope_rows {
    slope_grid g;
    size_t n_y;
    double *y, *dy;
    slope_row *row;
};

void wenv_slope_rows_free(wenv_slope_rows *rows)
{
    if (!rows)
        return;
    free(rows->y);
    free(rows->row);
    free(rows);
}

wenv_status wenv_slope_rows_make(const wenv_lobe *lobe, double cut, size_t n_y, wenv_slope_rows **out,
                                 wenv_error *err)
{
    *out = NULL;
    if (n_y < 1 || n_y > ALBEDO_SAMPLES_MAX)
        return wenv_error_set(err, WENV_ERR_VALUE, "row counts must be in [1, %d], got %zu", ALBEDO_SAMPLES_MAX, n_y);
    if (!(cut >= 0.0 && cut <= 1.0) || (cut > 0.0 && lobe->distribution != WENV_NDF_GGX))
        return wenv_error_set(err, WENV_ERR_VALUE, "a slope grid's cut must be in [0, 1], and 0 but for GGX, got %g", cut);
    wenv_slope_rows *rows = calloc(1, sizeof *rows);
    if (rows) {
        rows->y = malloc(2 * n_y * sizeof *rows->y);
        rows->row = malloc(n_y * sizeof *rows->row);
    }
    if (!rows || !rows->y || !rows->row) {
        wenv_slope_rows_free(rows);
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for a slope grid's %zu rows", n_y);
    }
    rows->g = (slope_grid){lobe->distribution == WENV_NDF_GGX, lobe->alpha, cut};
    rows->n_y = n_y;
    rows->dy = rows->y + n_y;
    for (size_t j = 0; j < n_y; j++) {
        rows->y[j] = slope_inverse(&rows->g, NULL, ((double)j + 0.5) / (double)n_y);
        rows->dy[j] = 1.0 / (double)n_y / slope_marginal_pdf(&rows->g, rows->y[j]);
        make_row(&rows->g, rows->y[j], &rows->row[j]);
    }
    *out = rows;
    return WENV_OK;
}

wenv_status wenv_slope_rows_cells(const wenv_slope_rows *rows, const double wo[3], size_t n_x, double *wi,
                                  double *mass, double *size, size_t *count, wenv_error *err)
{
    *count = 0;
    if (n_x < 1 || n_x > ALBEDO_SAMPLES_MAX)
        return wenv_error_set(err, WENV_ERR_VALUE, "cell counts must be in [1, %d], got %zu x %zu",
                              ALBEDO_SAMPLES_MAX, n_x, rows->n_y);
    const slope_grid *g = &rows->g;
    double so = sqrt(wo[0] * wo[0] + wo[1] * wo[1]), co = wo[2];
    /* work with the view in the xz plane, turn the nodes back at the end */
    double cp = so > 0.0 ? wo[0] / so : 1.0, sp = so > 0.0 ? wo[1] / so : 0.0, w[3] = {so, 0.0, co};
    size_t n = 0;
    for (size_t j = 0; j < rows->n_y; j++) {
        double y = rows->y[j], dy = rows->dy[j];
        const slope_row *row = &rows->row[j];
        /* the slopes x whose reflection lies above the horizon: c x^2 - 2 s x + c (y^2 - 1) < 0 */
        double r = sqrt(fmax(0.0, 1.0 - co * co * y * y));
        double x1 = co * (y * y - 1.0) / (so + r), x2 = co > 0.0 ? (so + r) / co : INFINITY;
        double f_lo = slope_conditional_cdf(g, row, x1), f_hi = isinf(x2) ? 1.0 : slope_conditional_cdf(g, row, x2);
        double df = (f_hi - f_lo) / (double)n_x;
        for (size_t i = 0; i < n_x; i++, n++) {
            double *d = wi + 3 * n;
            double u = f_lo + ((double)i + 0.5) * df;
            double x = g->ggx && g->cut > 0.0 ? row->b * tan(cut_inverse(row, u)) : slope_inverse(g, row, u);
            double dx = df / slope_conditional_pdf(g, row, x);
            double vh, ch;
            slope_reflect(x, y, w, d, &vh, &ch);
            mass[n] = size[n] = 0.0;
            if (co > 0.0 && d[2] > 0.0 && vh > 0.0 && df > 0.0) {
                /* Int f cos E d wi = Int (f 4 cos_i cos_o / D) (v.h) / (cos_o cos_h) E dP(slopes):
                 * the cell's share of P times the factor that turns the lobe's value over D into it */
                mass[n] = df / (double)rows->n_y * vh / (co * ch);
                /* the cell's extent in wi along each axis; its footprint is their geometric mean */
                double e[2], p[3], q[3], t1, t2;
                slope_reflect(x - 0.5 * dx, y, w, p, &t1, &t2);
                slope_reflect(x + 0.5 * dx, y, w, q, &t1, &t2);
                e[0] = angle_between(p, q);
                slope_reflect(x, y - 0.5 * dy, w, p, &t1, &t2);
                slope_reflect(x, y + 0.5 * dy, w, q, &t1, &t2);
                e[1] = angle_between(p, q);
                size[n] = sqrt(e[0] * e[1]);
            }
            double rx = cp * d[0] - sp * d[1], ry = sp * d[0] + cp * d[1];
            d[0] = rx;
            d[1] = ry;
        }
    }
    *count = n;
    return WENV_OK;
}

wenv_status wenv_lobe_slope_cells(const wenv_lobe *lobe, double cut, const double wo[3], size_t n_x, size_t n_y,
                                  double *wi, double *mass, double *size, size_t *count, wenv_error *err)
{
    *count = 0;
    wenv_slope_rows *rows;
    if (wenv_slope_rows_make(lobe, cut, n_y, &rows, err))
        return err->status;
    wenv_status st = wenv_slope_rows_cells(rows, wo, n_x, wi, mass, size, count, err);
    wenv_slope_rows_free(rows);
    return st;
}
