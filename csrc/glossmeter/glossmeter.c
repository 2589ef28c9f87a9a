/* Virtual glossmeter: geometry, the adaptive integrals and the roughness fit (see glossmeter.h).
 *
 * Why the specular lobes need care.  A lobe of roughness m is a peak of width ~2m around the mirror
 * image of each source point; the receptor is 30-200 times wider than that for m = 1e-4.  Sampled
 * on plain aperture coordinates, hcubature's first rules would straddle the peak and report a
 * confident wrong answer, then oscillate as m changes.  We therefore change variables per lobe and
 * per source point: in the receptor's gnomonic coordinates (X, Y) we substitute X = X0 + a_x z(t_x)
 * (likewise Y), with (X0, Y0) the mirror image of the source point, a_x, a_y the lobe's widths
 * there, and z(t) the inverse CDF of a warp density restricted to the receptor (t in [0, 1]).  With
 * the warp matched to the lobe (Gaussian for Beckmann, Cauchy and conditional Cauchy for GGX, see
 * lobe_warp()) the new integrand lobe / warp is nearly constant for every m: as m -> 0 it tends to
 * F(theta_i) times the fraction of the lobe inside the receptor, so the reading converges to the
 * smooth value without oscillation; a rough lobe gets a width larger than the receptor and the
 * substitution becomes nearly linear.  The domain stays a rectangle, so no corner or edge of the
 * receptor cuts through a rule.  (Plain half-vector coordinates would not help by themselves: the
 * peak is as narrow there, and the receptor's image is curved.)  Where the mirror image of the
 * source straddles a receptor edge, a narrow lobe puts a step of its own width on the source
 * coordinates; those lobes use the half-vector form further down.
 *
 * The smooth limit is a 2-D integral over the source region whose mirror image lies in the
 * receptor: the receptor's four edge planes pulled back by the mirror map are straight lines in the
 * source's gnomonic plane, so that region is the source rectangle clipped by four half-planes. */
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

/* Luminance weights (Rec. 709 / sRGB primaries), docs/ARCHITECTURE.md §3.7. */
static const double LUMA[3] = {0.2126, 0.7152, 0.0722};

typedef struct {
    size_t n;
    double xy[2 * MAX_POLY];
} polygon;

struct wenv_glossmeter {
    wenv_glossmeter_config cfg;
    double n[3], t1[3], t2[3];        /* unit specimen normal and a tangent frame for the BRDF */
    double cs[3], us[3], vs[3];       /* source centre and its in-plane / perpendicular axes */
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

static double dot3(const double a[3], const double b[3]) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }

static void cross3(const double a[3], const double b[3], double out[3])
{
    out[0] = a[1] * b[2] - a[2] * b[1];
    out[1] = a[2] * b[0] - a[0] * b[2];
    out[2] = a[0] * b[1] - a[1] * b[0];
}

/* Gnomonic point of an aperture: unit direction and the solid-angle density 1/(1+X^2+Y^2)^(3/2). */
static double aperture_dir(const double c[3], const double u[3], const double v[3], double X, double Y,
                           double out[3])
{
    double r2 = 1.0 + X * X + Y * Y;
    double inv = 1.0 / sqrt(r2);
    for (int k = 0; k < 3; k++)
        out[k] = (c[k] + X * u[k] + Y * v[k]) * inv;
    return inv * inv * inv;
}

/* Orthonormal frame around unit n (Duff et al. 2017, docs/ARCHITECTURE.md §3.1).  Any frame serves
 * isotropic lobes; this one is deterministic. */
static void tangent_frame(const double n[3], double t1[3], double t2[3])
{
    double sign = copysign(1.0, n[2]);
    double a = -1.0 / (sign + n[2]);
    double b = n[0] * n[1] * a;
    t1[0] = 1.0 + sign * n[0] * n[0] * a;
    t1[1] = sign * b;
    t1[2] = -sign * n[0];
    t2[0] = b;
    t2[1] = sign + n[1] * n[1] * a;
    t2[2] = -n[1];
}

static void to_local(const wenv_glossmeter *gm, const double w[3], double out[3])
{
    out[0] = dot3(w, gm->t1);
    out[1] = dot3(w, gm->t2);
    out[2] = dot3(w, gm->n);
}

/* ---------------------------------------------------------------- configuration */

wenv_status wenv_glossmeter_standard_config(wenv_glossmeter_config *cfg, double geometry, wenv_error *err)
{
    static const double table[3][5] = {
        /* angle, source in plane x perpendicular, receptor in plane x perpendicular (docs/ARCHITECTURE.md §3.7) */
        {20.0, 0.75, 2.5, 1.80, 3.6},
        {60.0, 0.75, 2.5, 4.4, 11.7},
        {85.0, 0.75, 2.5, 4.0, 6.0},
    };
    for (size_t i = 0; i < 3; i++) {
        if (geometry == table[i][0]) {
            memset(cfg, 0, sizeof *cfg);
            cfg->angle = table[i][0];
            cfg->source[0] = table[i][1];
            cfg->source[1] = table[i][2];
            cfg->receptor[0] = table[i][3];
            cfg->receptor[1] = table[i][4];
            cfg->standard_ior = 1.567;
            cfg->normal[2] = 1.0;
            return WENV_OK;
        }
    }
    return wenv_error_set(err, WENV_ERR_VALUE, "geometry must be 20, 60 or 85 (degrees), got %g", geometry);
}

void wenv_gloss_options_default(wenv_gloss_options *opt)
{
    opt->tol = WENV_GLOSS_DEFAULT_TOL;
    opt->max_evals = WENV_GLOSS_DEFAULT_MAX_EVALS;
    opt->smooth = 0;
    opt->method = WENV_GLOSS_AUTO;
}

/* Smallest cosine to `normal` over the four corners of an aperture; the minimum over the whole
 * rectangle is at a corner because {d . n > 0} is a half-plane in gnomonic coordinates. */
static double min_corner_cos(const double c[3], const double u[3], const double v[3], const double h[2],
                             const double normal[3])
{
    double lo = INFINITY;
    for (int i = 0; i < 4; i++) {
        double d[3];
        aperture_dir(c, u, v, (i & 1) ? h[0] : -h[0], (i & 2) ? h[1] : -h[1], d);
        double cs = dot3(d, normal);
        if (cs < lo)
            lo = cs;
    }
    return lo;
}

/* Clips a convex polygon by a + b x + c y >= 0 (Sutherland-Hodgman, one edge). */
static void clip_halfplane(polygon *p, double a, double b, double c)
{
    polygon out;
    out.n = 0;
    for (size_t i = 0; i < p->n; i++) {
        const double *P = p->xy + 2 * i, *Q = p->xy + 2 * ((i + 1) % p->n);
        double fp = a + b * P[0] + c * P[1], fq = a + b * Q[0] + c * Q[1];
        if (fp >= 0.0 && out.n < MAX_POLY) {
            out.xy[2 * out.n] = P[0];
            out.xy[2 * out.n + 1] = P[1];
            out.n++;
        }
        if ((fp >= 0.0) != (fq >= 0.0) && out.n < MAX_POLY) {
            double t = fp / (fp - fq);
            out.xy[2 * out.n] = P[0] + t * (Q[0] - P[0]);
            out.xy[2 * out.n + 1] = P[1] + t * (Q[1] - P[1]);
            out.n++;
        }
    }
    *p = out;
}

/* Source region (gnomonic coordinates) whose mirror image about unit `normal` falls in the
 * receptor.  The mirror map M = 2 n n^T - I is a symmetric rotation, so M s . e >= 0 is s . (M e) >= 0,
 * linear in (x, y) for s ~ c_s + x u_s + y v_s.  The four receptor edge planes imply d . c_d >= 0. */
static void mirror_region(const wenv_glossmeter *gm, const double normal[3], polygon *p)
{
    p->n = 4;
    const double hx = gm->hs[0], hy = gm->hs[1];
    const double rect[8] = {-hx, -hy, hx, -hy, hx, hy, -hx, hy};
    memcpy(p->xy, rect, sizeof rect);
    for (int j = 0; j < 4; j++) {
        const double *axis = j < 2 ? gm->ud : gm->vd;
        double half = j < 2 ? gm->hd[0] : gm->hd[1];
        double sign = (j & 1) ? -1.0 : 1.0;
        double e[3], g[3];
        for (int k = 0; k < 3; k++)
            e[k] = half * gm->cd[k] + sign * axis[k];
        double en = dot3(e, normal);
        for (int k = 0; k < 3; k++)
            g[k] = 2.0 * en * normal[k] - e[k];
        clip_halfplane(p, dot3(g, gm->cs), dot3(g, gm->us), dot3(g, gm->vs));
        if (p->n < 3) {
            p->n = 0;
            return;
        }
    }
}

/* ---------------------------------------------------------------- 2-D integrals over the source */

/* Integrand kinds over a source region: Fresnel mirrors (one component per index) or plain cosine. */
typedef struct {
    const wenv_glossmeter *gm;
    const double *normal;   /* cosines and Fresnel angles are taken about this normal */
    const double *ior;      /* NULL: integrate the projected solid angle (cosine only) */
    const double *weight;   /* per-component weight (luminance of the lobe colour), or NULL */
    const double *c, *u, *v; /* aperture frame */
    double tri[6];          /* triangle A, B, C when mapping from the unit square, else unused */
    int use_tri;
    size_t evals;
} area_ctx;

static int area_integrand(unsigned ndim, size_t npt, const double *x, void *data, unsigned fdim,
                          double *fval)
{
    (void)ndim;
    area_ctx *ctx = data;
    for (size_t i = 0; i < npt; i++) {
        double X = x[2 * i], Y = x[2 * i + 1], jac = 1.0;
        if (ctx->use_tri) {
            /* Collapsed (Duffy) map of the unit square onto triangle ABC: p = A + u(B-A) + uv(C-B). */
            const double *T = ctx->tri;
            double uu = X, vv = Y;
            X = T[0] + uu * (T[2] - T[0]) + uu * vv * (T[4] - T[2]);
            Y = T[1] + uu * (T[3] - T[1]) + uu * vv * (T[5] - T[3]);
            jac = uu * fabs((T[2] - T[0]) * (T[5] - T[3]) - (T[3] - T[1]) * (T[4] - T[2]));
        }
        double d[3];
        double dens = aperture_dir(ctx->c, ctx->u, ctx->v, X, Y, d) * jac;
        double cs = dot3(d, ctx->normal);
        if (cs < 0.0)
            cs = 0.0;
        for (unsigned k = 0; k < fdim; k++) {
            double f = ctx->ior ? wenv_fresnel_dielectric(cs, ctx->ior[k]) : 1.0;
            if (ctx->weight)
                f *= ctx->weight[k];
            fval[i * fdim + k] = f * cs * dens;
        }
    }
    ctx->evals += npt;
    return 0;
}

/* Integrates area_ctx over a polygon of the aperture's gnomonic plane (fan of Duffy triangles, or
 * the whole rectangle in one piece when the polygon is it).  val/err have fdim entries. */
static wenv_status integrate_area(area_ctx *ctx, const polygon *p, int whole_rect, const double half[2],
                                  unsigned fdim, double rel_tol, size_t max_evals, double *val,
                                  double *errv, int *converged, wenv_error *err)
{
    double v[64], e[64];
    if (fdim > 64)
        return wenv_error_set(err, WENV_ERR_VALUE, "too many lobes for the glossmeter (at most 64)");
    for (unsigned k = 0; k < fdim; k++)
        val[k] = errv[k] = 0.0;
    if (whole_rect) {
        ctx->use_tri = 0;
        double lo[2] = {-half[0], -half[1]}, hi[2] = {half[0], half[1]};
        if (hcubature_v(fdim, area_integrand, ctx, 2, lo, hi, max_evals, 0.0, rel_tol, ERROR_INDIVIDUAL, val,
                        errv) != 0)
            return wenv_error_set(err, WENV_ERR_NOMEM, "glossmeter: out of memory in the cubature");
    } else {
        if (p->n < 3)
            return WENV_OK; /* empty region */
        ctx->use_tri = 1;
        const double lo[2] = {0.0, 0.0}, hi[2] = {1.0, 1.0};
        for (size_t t = 1; t + 1 < p->n; t++) {
            memcpy(ctx->tri, p->xy, 2 * sizeof(double));
            memcpy(ctx->tri + 2, p->xy + 2 * t, 4 * sizeof(double));
            if (hcubature_v(fdim, area_integrand, ctx, 2, lo, hi, max_evals, 0.0, rel_tol, ERROR_INDIVIDUAL, v,
                            e) != 0)
                return wenv_error_set(err, WENV_ERR_NOMEM, "glossmeter: out of memory in the cubature");
            for (unsigned k = 0; k < fdim; k++) {
                val[k] += v[k];
                errv[k] += e[k];
            }
        }
    }
    for (unsigned k = 0; k < fdim; k++)
        if (errv[k] > rel_tol * fabs(val[k]) * 10.0 + 1e-300 && converged)
            *converged = 0;
    return WENV_OK;
}

static int polygon_is_rect(const polygon *p, const double half[2])
{
    if (p->n != 4)
        return 0;
    for (size_t i = 0; i < 4; i++)
        if (fabs(fabs(p->xy[2 * i]) - half[0]) > 1e-15 || fabs(fabs(p->xy[2 * i + 1]) - half[1]) > 1e-15)
            return 0;
    return 1;
}

/* Smooth-limit flux: sum over components k of weight_k * integral F_k(s.n) (s.n) d omega over the
 * source region whose mirror image lies in the receptor. */
static wenv_status mirror_flux(const wenv_glossmeter *gm, const double normal[3], const polygon *region,
                               unsigned fdim, const double *ior, const double *weight, size_t max_evals,
                               double *val, double *errv, size_t *evals, int *converged, wenv_error *err)
{
    area_ctx ctx = {.gm = gm, .normal = normal, .ior = ior, .weight = weight, .c = gm->cs, .u = gm->us,
                    .v = gm->vs};
    wenv_status st = integrate_area(&ctx, region, polygon_is_rect(region, gm->hs), gm->hs, fdim, 1e-11,
                                    max_evals, val, errv, converged, err);
    if (evals)
        *evals += ctx.evals;
    return st;
}

/* ---------------------------------------------------------------- creation and validation */

static wenv_status check_size(const double size[2], const char *name, wenv_error *err)
{
    for (int i = 0; i < 2; i++)
        if (!isfinite(size[i]) || size[i] <= 0.0 || size[i] >= 90.0)
            return wenv_error_set(err, WENV_ERR_VALUE,
                                  "%s must be two angular sizes in (0, 90) degrees (in plane, perpendicular), "
                                  "got (%g, %g)",
                                  name, size[0], size[1]);
    return WENV_OK;
}

/* Slopes (p, q) of the half vector h ~ s + d about n in the frame (e1, e2). */
static void half_slopes(const wenv_glossmeter *gm, const double s[3], const double d[3], double *p, double *q)
{
    double h[3] = {s[0] + d[0], s[1] + d[1], s[2] + d[2]};
    double hn = dot3(h, gm->n);
    *p = dot3(h, gm->e1) / hn;
    *q = dot3(h, gm->e2) / hn;
}

/* Edge planes of an aperture: d is inside iff d . e_j >= 0 for j = 0..3. */
static void edge_planes(const double c[3], const double u[3], const double v[3], const double h[2], double e[4][3])
{
    for (int j = 0; j < 4; j++) {
        const double *axis = j < 2 ? u : v;
        double half = j < 2 ? h[0] : h[1], sign = (j & 1) ? -1.0 : 1.0;
        for (int k = 0; k < 3; k++)
            e[j][k] = half * c[k] + sign * axis[k];
    }
}

/* e . (h reflection of w) for the half vector of slopes (t, 0) (axis 0) or (0, t) (axis 1). */
static double reflected_side(const wenv_glossmeter *gm, int axis, double t, const double w[3], const double e[3])
{
    double h[3], p = axis == 0 ? t : 0.0, q = axis == 0 ? 0.0 : t;
    double inv = 1.0 / sqrt(1.0 + p * p + q * q), r[3];
    for (int k = 0; k < 3; k++)
        h[k] = (gm->n[k] + p * gm->e1[k] + q * gm->e2[k]) * inv;
    double wh = dot3(w, h);
    for (int k = 0; k < 3; k++)
        r[k] = 2.0 * wh * h[k] - w[k];
    return dot3(r, e);
}

/* Kinks of the half-vector form's inner integral along one slope axis: slopes at which a reflected
 * source corner crosses a receptor edge plane or a reflected receptor corner crosses a source edge
 * plane (the clipped polygon gains or loses a vertex there).  Found by sign changes on a 256-point
 * grid over the slope box, refined by bisection.  Kinks closer than 1e-3 of the box (the corners of
 * one edge, split by a slight tilt) are merged: a cell boundary that close to a kink leaves the
 * kink's effect below the rules' resolution, and thin cells would only cost evaluations. */
static void find_kinks(wenv_glossmeter *gm, int axis)
{
    double es[4][3], ed[4][3];
    edge_planes(gm->cs, gm->us, gm->vs, gm->hs, es);
    edge_planes(gm->cd, gm->ud, gm->vd, gm->hd, ed);
    double lo = gm->hbox[2 * axis], hi = gm->hbox[2 * axis + 1], found[64];
    size_t n = 0;
    enum { GRID = 256 };
    for (int family = 0; family < 2; family++) {
        for (int c = 0; c < 4; c++) {
            double w[3];
            if (family == 0)
                aperture_dir(gm->cs, gm->us, gm->vs, (c & 1) ? gm->hs[0] : -gm->hs[0], (c & 2) ? gm->hs[1] : -gm->hs[1], w);
            else
                aperture_dir(gm->cd, gm->ud, gm->vd, (c & 1) ? gm->hd[0] : -gm->hd[0], (c & 2) ? gm->hd[1] : -gm->hd[1], w);
            for (int j = 0; j < 4; j++) {
                const double *e = family == 0 ? ed[j] : es[j];
                double t0 = lo, f0 = reflected_side(gm, axis, t0, w, e);
                for (int g = 1; g <= GRID && n < 64; g++) {
                    double t1 = lo + (hi - lo) * g / GRID, f1 = reflected_side(gm, axis, t1, w, e);
                    if ((f0 < 0.0) != (f1 < 0.0)) {
                        double a = t0, b = t1, fa = f0;
                        for (int it = 0; it < 60; it++) {
                            double mid = 0.5 * (a + b), fm = reflected_side(gm, axis, mid, w, e);
                            if ((fm < 0.0) == (fa < 0.0)) {
                                a = mid;
                                fa = fm;
                            } else {
                                b = mid;
                            }
                        }
                        found[n++] = 0.5 * (a + b);
                    }
                    t0 = t1;
                    f0 = f1;
                }
            }
        }
    }
    /* Sort (insertion: n <= 64) and merge kinks closer than 1e-9 of the box. */
    for (size_t i = 1; i < n; i++) {
        double v = found[i];
        size_t k = i;
        while (k > 0 && found[k - 1] > v) {
            found[k] = found[k - 1];
            k--;
        }
        found[k] = v;
    }
    size_t m = 0;
    for (size_t i = 0; i < n && m < MAX_KINKS; i++)
        if (m == 0 || found[i] - gm->kinks[axis][m - 1] > 1e-3 * (hi - lo))
            gm->kinks[axis][m++] = found[i];
    gm->n_kinks[axis] = m;
}

/* Mirror image of the source in the receptor, and the half-vector slope box, from the apertures'
 * corners and edge midpoints (gnomonic maps are nearly linear over a few degrees, so extremes sit on
 * the boundary; the box is padded by 25% on each side to be safe: outside the true support the
 * integrand is exactly zero, so padding costs only evaluations). */
static void image_and_slopes(wenv_glossmeter *gm)
{
    const double ex[3] = {1.0, 0.0, 0.0};
    double xn = dot3(ex, gm->n);
    for (int k = 0; k < 3; k++)
        gm->e1[k] = ex[k] - xn * gm->n[k];
    double len = sqrt(dot3(gm->e1, gm->e1));
    for (int k = 0; k < 3; k++)
        gm->e1[k] /= len;
    cross3(gm->n, gm->e1, gm->e2);
    double c0[3];
    aperture_dir(gm->cs, gm->us, gm->vs, 0.0, 0.0, c0);
    gm->cos_i0 = dot3(c0, gm->n);

    gm->image_lo[0] = gm->image_lo[1] = INFINITY;
    gm->image_hi[0] = gm->image_hi[1] = -INFINITY;
    gm->image_far = 0;
    gm->hbox[0] = gm->hbox[2] = INFINITY;
    gm->hbox[1] = gm->hbox[3] = -INFINITY;
    static const double grid[8][2] = {{-1, -1}, {0, -1}, {1, -1}, {1, 0}, {1, 1}, {0, 1}, {-1, 1}, {-1, 0}};
    for (int i = 0; i < 8; i++) {
        double s[3], r[3];
        aperture_dir(gm->cs, gm->us, gm->vs, grid[i][0] * gm->hs[0], grid[i][1] * gm->hs[1], s);
        double cs = dot3(s, gm->n);
        for (int k = 0; k < 3; k++)
            r[k] = 2.0 * cs * gm->n[k] - s[k];
        double rc = dot3(r, gm->cd);
        if (rc > 0.05) {
            double X = dot3(r, gm->ud) / rc, Y = dot3(r, gm->vd) / rc;
            gm->image_lo[0] = fmin(gm->image_lo[0], X);
            gm->image_hi[0] = fmax(gm->image_hi[0], X);
            gm->image_lo[1] = fmin(gm->image_lo[1], Y);
            gm->image_hi[1] = fmax(gm->image_hi[1], Y);
        } else {
            gm->image_far = 1;
        }
        for (int j = 0; j < 8; j++) {
            double d[3], p, q;
            aperture_dir(gm->cd, gm->ud, gm->vd, grid[j][0] * gm->hd[0], grid[j][1] * gm->hd[1], d);
            half_slopes(gm, s, d, &p, &q);
            gm->hbox[0] = fmin(gm->hbox[0], p);
            gm->hbox[1] = fmax(gm->hbox[1], p);
            gm->hbox[2] = fmin(gm->hbox[2], q);
            gm->hbox[3] = fmax(gm->hbox[3], q);
        }
    }
    for (int a = 0; a < 2; a++) {
        double pad = 0.25 * (gm->hbox[2 * a + 1] - gm->hbox[2 * a]);
        gm->hbox[2 * a] -= pad;
        gm->hbox[2 * a + 1] += pad;
        find_kinks(gm, a);
    }
}

wenv_status wenv_glossmeter_create(wenv_glossmeter **out, const wenv_glossmeter_config *cfg, wenv_error *err)
{
    *out = NULL;
    if (!isfinite(cfg->angle) || cfg->angle <= 0.0 || cfg->angle >= 90.0)
        return wenv_error_set(err, WENV_ERR_VALUE, "angle must be in (0, 90) degrees, got %g", cfg->angle);
    wenv_status bad;
    if ((bad = check_size(cfg->source, "source", err)) || (bad = check_size(cfg->receptor, "receptor", err)))
        return bad;
    for (int i = 0; i < 2; i++)
        if (!isfinite(cfg->receptor_offset[i]) || fabs(cfg->receptor_offset[i]) >= 90.0)
            return wenv_error_set(err, WENV_ERR_VALUE, "receptor_offset must be two finite angles in (-90, 90) "
                                                       "degrees");
    if (!isfinite(cfg->standard_ior) || cfg->standard_ior <= 1.0 || cfg->standard_ior > 10.0)
        return wenv_error_set(err, WENV_ERR_VALUE, "standard_ior must be in (1, 10], got %g", cfg->standard_ior);
    double nlen = sqrt(dot3(cfg->normal, cfg->normal));
    if (!isfinite(nlen) || nlen < 1e-12)
        return wenv_error_set(err, WENV_ERR_VALUE, "normal must be a finite non-zero 3-vector");

    wenv_glossmeter *gm = calloc(1, sizeof *gm);
    if (!gm)
        return wenv_error_set(err, WENV_ERR_NOMEM, "glossmeter: out of memory");
    gm->cfg = *cfg;
    for (int k = 0; k < 3; k++)
        gm->n[k] = cfg->normal[k] / nlen;
    tangent_frame(gm->n, gm->t1, gm->t2);

    /* Source: polar angle A on the -X side; u = d c / d(polar angle), v = +Y. */
    double A = cfg->angle * DEG;
    const double cs[3] = {-sin(A), 0.0, cos(A)}, us[3] = {-cos(A), 0.0, -sin(A)}, ey[3] = {0.0, 1.0, 0.0};
    memcpy(gm->cs, cs, sizeof cs);
    memcpy(gm->us, us, sizeof us);
    memcpy(gm->vs, ey, sizeof ey);
    /* Receptor: mirror direction turned in plane to A + o1, then tilted out of plane by o2 about u. */
    double Ar = A + cfg->receptor_offset[0] * DEG, o2 = cfg->receptor_offset[1] * DEG;
    const double cr[3] = {sin(Ar), 0.0, cos(Ar)}, ur[3] = {cos(Ar), 0.0, -sin(Ar)};
    for (int k = 0; k < 3; k++) {
        gm->cd[k] = cos(o2) * cr[k] + sin(o2) * ey[k];
        gm->ud[k] = ur[k];
    }
    cross3(gm->cd, gm->ud, gm->vd);
    for (int i = 0; i < 2; i++) {
        gm->hs[i] = tan(0.5 * cfg->source[i] * DEG);
        gm->hd[i] = tan(0.5 * cfg->receptor[i] * DEG);
    }

    /* Horizon: every part of both apertures above the calibrated (+Z) and the specimen horizon. */
    const double ez[3] = {0.0, 0.0, 1.0};
    wenv_status st = WENV_OK;
    if (min_corner_cos(gm->cs, gm->us, gm->vs, gm->hs, ez) <= 0.0)
        st = wenv_error_set(err, WENV_ERR_VALUE, "source extends past the horizon at angle %g degrees", cfg->angle);
    else if (min_corner_cos(gm->cd, gm->ud, gm->vd, gm->hd, ez) <= 0.0)
        st = wenv_error_set(err, WENV_ERR_VALUE,
                            "receptor extends past the horizon (angle %g, receptor (%g, %g), offset (%g, %g) degrees)",
                            cfg->angle, cfg->receptor[0], cfg->receptor[1], cfg->receptor_offset[0],
                            cfg->receptor_offset[1]);
    else if (min_corner_cos(gm->cs, gm->us, gm->vs, gm->hs, gm->n) <= 0.0 ||
             min_corner_cos(gm->cd, gm->ud, gm->vd, gm->hd, gm->n) <= 0.0)
        st = wenv_error_set(err, WENV_ERR_VALUE,
                            "normal (%g, %g, %g) tilts the specimen so far that an aperture is past its horizon",
                            cfg->normal[0], cfg->normal[1], cfg->normal[2]);
    if (st != WENV_OK) {
        free(gm);
        return st;
    }

    image_and_slopes(gm);

    /* Material-independent integrals, to ~1e-11 relative: they cost ~100 evaluations each. */
    int conv = 1;
    double val[1], ev[1];
    area_ctx ctx = {.gm = gm, .normal = gm->n, .c = gm->cs, .u = gm->us, .v = gm->vs};
    polygon none = {0};
    if ((st = integrate_area(&ctx, &none, 1, gm->hs, 1, 1e-11, WENV_GLOSS_DEFAULT_MAX_EVALS, val, ev, &conv, err)))
        goto fail;
    gm->proj_source = val[0];
    double e_s = ev[0];
    ctx.c = gm->cd;
    ctx.u = gm->ud;
    ctx.v = gm->vd;
    if ((st = integrate_area(&ctx, &none, 1, gm->hd, 1, 1e-11, WENV_GLOSS_DEFAULT_MAX_EVALS, val, ev, &conv, err)))
        goto fail;
    gm->proj_receptor = val[0];
    gm->proj_error = e_s * gm->proj_receptor + ev[0] * gm->proj_source;

    polygon std_region;
    mirror_region(gm, ez, &std_region);
    mirror_region(gm, gm->n, &gm->mirror_in);
    if ((st = mirror_flux(gm, ez, &std_region, 1, &cfg->standard_ior, NULL, WENV_GLOSS_DEFAULT_MAX_EVALS, val, ev,
                          NULL, &conv, err)))
        goto fail;
    gm->flux_std = val[0];
    gm->flux_std_error = ev[0];
    *out = gm;
    return WENV_OK;
fail:
    free(gm);
    return st;
}

void wenv_glossmeter_free(wenv_glossmeter *gm) { free(gm); }

const wenv_glossmeter_config *wenv_glossmeter_config_of(const wenv_glossmeter *gm) { return &gm->cfg; }

double wenv_glossmeter_standard_flux(const wenv_glossmeter *gm, double *error)
{
    if (error)
        *error = gm->flux_std_error;
    return gm->flux_std;
}

void wenv_glossmeter_projected_solid_angles(const wenv_glossmeter *gm, double *source, double *receptor)
{
    *source = gm->proj_source;
    *receptor = gm->proj_receptor;
}

/* ---------------------------------------------------------------- the specular lobes (4-D) */

typedef enum { WARP_GAUSS, WARP_CAUCHY } warp_kind;

typedef struct {
    const wenv_lobe *lobe;
    double weight;  /* luminance of the lobe colour */
    warp_kind warp; /* the lobe's change of variables, see lobe_warp() */
    double scale;   /* warp scale per unit roughness along the plane of incidence */
} active_lobe;

typedef struct {
    const wenv_glossmeter *gm;
    wenv_shadowing shadowing;
    const active_lobe *lobes;
    size_t n_lobes;
    size_t evals;
} lobe_ctx;

/* Near the mirror direction a half-vector slope (p, q) moves the reflected direction by ~2p in the
 * plane of incidence and ~2q cos(theta_i) across it (in the receptor's gnomonic units).  Beckmann
 * slopes are independent Gaussians of standard deviation m/sqrt(2), so a narrow Beckmann lobe is a
 * separable Gaussian of sigma = sqrt(2) m (times cos(theta_i) across): a Gaussian warp of that width
 * leaves lobe / warp = 1 + O(m), a nearly constant integrand.  When the lobe is wider, the receptor
 * cuts the warp at a few sigma and the ratio stays smooth.  GGX slopes (x, y) in units of m have
 * the density 1 / (pi (1 + x^2 + y^2)^2), whose r^-4 tails no light-tailed warp bounds.  We warp x by
 * a Cauchy density and then y, given x, by a Cauchy density of scale rho = sqrt(1 + x^2), the
 * width of the conditional density of y: the ratio is then pi cos(phi_x) cos^2(phi_y) in the
 * Cauchy angles phi (x = tan phi_x, y = rho tan phi_y), an entire function of the cube
 * coordinates, with no corner singularity (a plain product of Cauchy warps leaves one). */
static void lobe_warp(wenv_distribution dist, warp_kind *kind, double *scale)
{
    *kind = dist == WENV_NDF_BECKMANN ? WARP_GAUSS : WARP_CAUCHY;
    *scale = dist == WENV_NDF_BECKMANN ? M_SQRT2 : 2.0;
}

/* Inverse of the standard normal CDF for p in (0, 1/2]: Acklam's rational approximation, relative
 * error below 1.2e-9 in the quantile.  Not refined further: the warp only has to be a smooth
 * bijection whose Jacobian we know, and using 1/phi(z) as that Jacobian is off by the (smooth,
 * ~1e-9) derivative of the approximation error, far below any tolerance here. */
static double normal_quantile_lower(double p)
{
    static const double a[6] = {-3.969683028665376e+01, 2.209460984245205e+02, -2.759285104469687e+02,
                                1.383577518672690e+02,  -3.066479806614716e+01, 2.506628277459239e+00};
    static const double b[5] = {-5.447609879822406e+01, 1.615858368580409e+02, -1.556989798598866e+02,
                                6.680131188771972e+01, -1.328068155288572e+01};
    static const double c[6] = {-7.784894002430293e-03, -3.223964580411365e-01, -2.400758277161838e+00,
                                -2.549732539343734e+00, 4.374664141464968e+00,  2.938163982698783e+00};
    static const double d[4] = {7.784695709041462e-03, 3.224671290700398e-01, 2.445134137142996e+00,
                                3.754408661907416e+00};
    double x;
    if (p < 0.02425) {
        double q = sqrt(-2.0 * log(p));
        x = (((((c[0] * q + c[1]) * q + c[2]) * q + c[3]) * q + c[4]) * q + c[5]) /
            ((((d[0] * q + d[1]) * q + d[2]) * q + d[3]) * q + 1.0);
    } else {
        double q = p - 0.5, r = q * q;
        x = (((((a[0] * r + a[1]) * r + a[2]) * r + a[3]) * r + a[4]) * r + a[5]) * q /
            (((((b[0] * r + b[1]) * r + b[2]) * r + b[3]) * r + b[4]) * r + 1.0);
    }
    return x;
}

/* Maps t in [0, 1] onto [lo, hi] by the inverse CDF of the warp density centred at c with scale a,
 * restricted to [lo, hi]; returns X and sets *jac = dX/dt (0 in tails too far out to matter). */
static double warp_map(warp_kind kind, double t, double c, double a, double lo, double hi, double *jac)
{
    double X;
    if (kind == WARP_CAUCHY) {
        double pa = atan((lo - c) / a), pb = atan((hi - c) / a);
        double xi = tan(pa + t * (pb - pa));
        X = c + a * xi;
        *jac = a * (1.0 + xi * xi) * (pb - pa);
    } else {
        /* Work in whichever tail is small, so ranges far out in either tail keep full precision:
         * P(z) = Phi(z) for a range below the centre, 1 - Phi(z) (mirrored) above it. */
        double za = (lo - c) / a, zb = (hi - c) / a;
        int upper = za > 0.0; /* whole range above the centre: mirror it */
        if (upper) {
            double tmp = -zb;
            zb = -za;
            za = tmp;
            t = 1.0 - t;
        }
        double pa = 0.5 * erfc(-za * M_SQRT1_2), pb = 0.5 * erfc(-zb * M_SQRT1_2);
        double width = pb - pa;
        double p = pa + t * width;
        if (!(p > 0.0) || !(width > 0.0)) {
            *jac = 0.0;
            return c;
        }
        double z = p <= 0.5 ? normal_quantile_lower(p) : -normal_quantile_lower(1.0 - p);
        if (!(fabs(z) < 37.0)) { /* the Gaussian density underflows: nothing to integrate there */
            *jac = 0.0;
            return c;
        }
        if (upper)
            z = -z;
        X = c + a * z;
        *jac = a * width * 2.5066282746310002 * exp(0.5 * z * z);
    }
    if (X < lo)
        X = lo;
    if (X > hi)
        X = hi;
    return X;
}

static int lobe_integrand(unsigned ndim, size_t npt, const double *x, void *data, unsigned fdim, double *fval)
{
    (void)ndim;
    (void)fdim;
    lobe_ctx *ctx = data;
    const wenv_glossmeter *gm = ctx->gm;
    for (size_t i = 0; i < npt; i++) {
        const double *p = x + 4 * i;
        double s[3], sl[3];
        double dens_s = aperture_dir(gm->cs, gm->us, gm->vs, p[0], p[1], s);
        double cos_s = dot3(s, gm->n);
        to_local(gm, s, sl);
        /* Mirror image of s about n in the receptor's gnomonic plane: the lobes' peak. */
        double r[3], X0 = 0.0, Y0 = 0.0, far = 0.0;
        for (int k = 0; k < 3; k++)
            r[k] = 2.0 * cos_s * gm->n[k] - s[k];
        double rc = dot3(r, gm->cd);
        if (rc > 0.05) {
            X0 = dot3(r, gm->ud) / rc;
            Y0 = dot3(r, gm->vd) / rc;
        } else {
            far = 1.0; /* peak > 87 degrees from the receptor (absurd tilts): plain widths suffice */
        }
        double sum = 0.0;
        for (size_t k = 0; k < ctx->n_lobes; k++) {
            const active_lobe *L = ctx->lobes + k;
            double w = L->scale * L->lobe->roughness;
            double ax = far ? 1.0 : fmin(w, 1.0), ay = far ? 1.0 : fmin(w * cos_s, 1.0);
            double jx, jy;
            double X = warp_map(L->warp, p[2], X0, ax, -gm->hd[0], gm->hd[0], &jx);
            if (L->warp == WARP_CAUCHY) {
                /* Conditional scale: given x = (X - X0)/ax, GGX's slope density across is Cauchy-like of
                 * width sqrt(1 + x^2), see lobe_warp(). */
                double xi = (X - X0) / ax;
                ay *= sqrt(1.0 + xi * xi);
            }
            double Y = warp_map(L->warp, p[3], Y0, ay, -gm->hd[1], gm->hd[1], &jy);
            if (jx == 0.0 || jy == 0.0)
                continue;
            double d[3], dl[3];
            double dens_d = aperture_dir(gm->cd, gm->ud, gm->vd, X, Y, d);
            double cos_d = dot3(d, gm->n);
            to_local(gm, d, dl);
            double f = wenv_lobe_eval(L->lobe, ctx->shadowing, sl, dl);
            sum += L->weight * f * cos_s * cos_d * dens_s * dens_d * jx * jy;
        }
        fval[i] = sum;
    }
    ctx->evals += npt;
    return 0;
}

/* ---------------------------------------------------------------- narrow lobes across a receptor edge
 *
 * When the mirror image of the source straddles a receptor edge (tilted specimen, a receptor smaller
 * than the source image, offset receptors) and the lobe is much narrower than the image, the
 * reading's integrand over the source has a step of the lobe's width along the pulled-back edge,
 * which no rule on source coordinates resolves for m -> 0.  There we swap the order: for a fixed
 * half vector h the directions s that reflect into the receptor form the source rectangle clipped by
 * the four receptor edge planes reflected about h (straight lines in gnomonic coordinates), so
 *
 *     Phi_lobe = integral dP(p, q) / cos(theta_h) integral_{source clipped for h} F(s.h) G(s, d) (s.h) d omega_s
 *
 * with d = 2 (s.h) h - s and dP = D(h) cos(theta_h) d omega_h the microfacet slope distribution
 * (Beckmann: independent Gaussians of sigma m/sqrt(2); GGX: 1/(pi m^2 (1 + r^2/m^2)^2)).  The step
 * becomes the clipping of a polygon, exact for every h; the outer integral over slopes is warped as
 * in the 4-D form, but centred on the normal.  The inner integral of a smooth, slowly varying
 * function over a polygon a few degrees wide takes a fixed product Gauss rule per triangle (error
 * < 1e-10 relative, checked against an 8x8 rule during development). */

static const double GL5_X[5] = {0.04691007703066800, 0.23076534494715845, 0.5, 0.76923465505284155,
                                0.95308992296933200};
static const double GL5_W[5] = {0.11846344252809454, 0.23931433524968324, 0.28444444444444444,
                                0.23931433524968324, 0.11846344252809454};

/* Shadowing-masking G of a lobe for unit s, d about n (scene/microfacet.h: Smith height-correlated from the
 * exported Lambda, or the V-cavity term), and cos_h = h . n. */
static double lobe_shadowing(const wenv_lobe *lobe, wenv_shadowing shadowing, double cos_s, double cos_d,
                             double cos_h, double sh)
{
    if (shadowing == WENV_SHADOW_SMITH)
        return 1.0 / (1.0 + wenv_smith_lambda(lobe->distribution, lobe->roughness, cos_s) +
                      wenv_smith_lambda(lobe->distribution, lobe->roughness, cos_d));
    return fmin(1.0, 2.0 * cos_h * fmin(cos_s, cos_d) / sh);
}

typedef struct {
    const wenv_glossmeter *gm;
    wenv_shadowing shadowing;
    const active_lobe *lobe;
    double cell[4]; /* slope box p0, p1, q0, q1 integrated by this call */
    size_t evals;
} half_ctx;

/* F G (s.h) d omega_s at gnomonic source point (x, y) for half vector h. */
static double half_point(const half_ctx *ctx, const wenv_lobe *lobe, const double h[3], double cos_h, double x,
                         double y)
{
    const wenv_glossmeter *gm = ctx->gm;
    double s[3], d[3];
    double dens = aperture_dir(gm->cs, gm->us, gm->vs, x, y, s);
    double sh = dot3(s, h);
    if (!(sh > 0.0))
        return 0.0;
    for (int k = 0; k < 3; k++)
        d[k] = 2.0 * sh * h[k] - s[k];
    double cos_s = dot3(s, gm->n), cos_d = dot3(d, gm->n);
    if (!(cos_s > 0.0) || !(cos_d > 0.0))
        return 0.0;
    return wenv_fresnel_dielectric(sh, lobe->ior) * lobe_shadowing(lobe, ctx->shadowing, cos_s, cos_d, cos_h, sh) *
           sh * dens;
}

/* Inner integral over the source region that h reflects into the receptor. */
static double half_inner(half_ctx *ctx, const wenv_lobe *lobe, const double h[3], double cos_h)
{
    const wenv_glossmeter *gm = ctx->gm;
    polygon p;
    mirror_region(gm, h, &p);
    if (p.n < 3)
        return 0.0;
    double sum = 0.0;
    if (polygon_is_rect(&p, gm->hs)) {
        for (int i = 0; i < 5; i++)
            for (int j = 0; j < 5; j++)
                sum += GL5_W[i] * GL5_W[j] *
                       half_point(ctx, lobe, h, cos_h, gm->hs[0] * (2.0 * GL5_X[i] - 1.0),
                                  gm->hs[1] * (2.0 * GL5_X[j] - 1.0));
        ctx->evals += 25;
        return sum * 4.0 * gm->hs[0] * gm->hs[1];
    }
    const double *A = p.xy;
    for (size_t t = 1; t + 1 < p.n; t++) {
        const double *B = p.xy + 2 * t, *C = p.xy + 2 * t + 2;
        double det = fabs((B[0] - A[0]) * (C[1] - B[1]) - (B[1] - A[1]) * (C[0] - B[0]));
        double tri = 0.0;
        for (int i = 0; i < 5; i++) {
            double u = GL5_X[i], row = 0.0;
            for (int j = 0; j < 5; j++) {
                double v = GL5_X[j];
                double x = A[0] + u * (B[0] - A[0]) + u * v * (C[0] - B[0]);
                double y = A[1] + u * (B[1] - A[1]) + u * v * (C[1] - B[1]);
                row += GL5_W[j] * half_point(ctx, lobe, h, cos_h, x, y);
            }
            tri += GL5_W[i] * u * row;
        }
        sum += tri * det;
        ctx->evals += 25;
    }
    return sum;
}

/* Slope density of the lobe (scene/microfacet.h's D written on slopes: D cos(theta_h) d omega_h = P dp dq). */
static double slope_density(const wenv_lobe *lobe, double p, double q)
{
    double m2 = lobe->roughness * lobe->roughness, r2 = (p * p + q * q) / m2;
    if (lobe->distribution == WENV_NDF_GGX)
        return 1.0 / (M_PI * m2 * (1.0 + r2) * (1.0 + r2));
    return exp(-r2) / (M_PI * m2);
}

static int half_integrand(unsigned ndim, size_t npt, const double *x, void *data, unsigned fdim, double *fval)
{
    (void)ndim;
    (void)fdim;
    half_ctx *ctx = data;
    const wenv_glossmeter *gm = ctx->gm;
    const active_lobe *L = ctx->lobe;
    const wenv_lobe *lobe = L->lobe;
    /* Slope warps centred on the normal: Gaussian of sigma m/sqrt(2) per axis (Beckmann: exactly the
     * slope density), Cauchy of scale m then, given p, Cauchy of scale m sqrt(1 + (p/m)^2) (GGX, as in
     * lobe_warp()); restricted to the cell, which keeps the domain a rectangle for every p. */
    double a = L->warp == WARP_GAUSS ? lobe->roughness * M_SQRT1_2 : lobe->roughness;
    for (size_t i = 0; i < npt; i++) {
        double jp, jq;
        double pp = warp_map(L->warp, x[2 * i], 0.0, a, ctx->cell[0], ctx->cell[1], &jp);
        double aq = L->warp == WARP_CAUCHY ? a * sqrt(1.0 + (pp / a) * (pp / a)) : a;
        double qq = warp_map(L->warp, x[2 * i + 1], 0.0, aq, ctx->cell[2], ctx->cell[3], &jq);
        double w = slope_density(lobe, pp, qq) * jp * jq;
        fval[i] = 0.0;
        if (!(w > 0.0))
            continue;
        double h[3], inv = 1.0 / sqrt(1.0 + pp * pp + qq * qq);
        for (int c = 0; c < 3; c++)
            h[c] = (gm->n[c] + pp * gm->e1[c] + qq * gm->e2[c]) * inv;
        /* 1 / cos(theta_h) turns the slope measure back into D d omega_h. */
        fval[i] = L->weight * w / inv * half_inner(ctx, lobe, h, inv);
    }
    return 0;
}

/* Probability that one slope coordinate of the lobe lies in [a, b] (marginals: Gaussian of sigma
 * m/sqrt(2) for Beckmann; (1 + x/sqrt(1 + x^2))/2 in x = slope/m for GGX). */
static double slope_marginal_mass(const active_lobe *L, double a, double b)
{
    double m = L->lobe->roughness;
    if (L->warp == WARP_GAUSS)
        return 0.5 * fabs(erfc(-b / m) - erfc(-a / m)); /* slope / (sigma sqrt 2) = slope / m */
    double xa = a / m, xb = b / m;
    return 0.5 * fabs(xb / sqrt(1.0 + xb * xb) - xa / sqrt(1.0 + xa * xa));
}

/* Integrates one narrow lobe in the half-vector form: the slope box is cut at the kinks of the
 * inner integral (so every cell's integrand is smooth and no kink hides between a rule's points),
 * skipping Beckmann cuts beyond 12 sigma where the lobe weighs nothing; each cell gets an equal share
 * of the tolerance. */
static wenv_status half_vector_flux(const wenv_glossmeter *gm, wenv_shadowing shadowing, const active_lobe *L,
                                    double req, size_t max_evals, double *val, double *errv, size_t *evals,
                                    int *converged, wenv_error *err)
{
    double cuts[2][MAX_KINKS + 2];
    size_t nc[2];
    double reach = L->warp == WARP_GAUSS ? 12.0 * L->lobe->roughness * M_SQRT1_2 : INFINITY;
    for (int axis = 0; axis < 2; axis++) {
        size_t n = 0;
        cuts[axis][n++] = gm->hbox[2 * axis];
        for (size_t k = 0; k < gm->n_kinks[axis]; k++)
            if (fabs(gm->kinks[axis][k]) < reach)
                cuts[axis][n++] = gm->kinks[axis][k];
        cuts[axis][n++] = gm->hbox[2 * axis + 1];
        nc[axis] = n - 1;
    }
    double share = req / (double)(nc[0] * nc[1]);
    /* inner(h) / cos(theta_h) <= (source solid angle) * sqrt(1 + p^2 + q^2): F, G, s.h <= 1. */
    double pm = fmax(fabs(gm->hbox[0]), fabs(gm->hbox[1])), qm = fmax(fabs(gm->hbox[2]), fabs(gm->hbox[3]));
    double inner_max = 4.0 * gm->hs[0] * gm->hs[1] * sqrt(1.0 + pm * pm + qm * qm) * L->weight;
    *val = *errv = 0.0;
    for (size_t i = 0; i < nc[0]; i++) {
        for (size_t j = 0; j < nc[1]; j++) {
            /* A cell whose slope probability (bounded by either marginal's) times the largest inner
             * value is below a tenth of its share is skipped, the bound booked as error. */
            double bound = inner_max * fmin(slope_marginal_mass(L, cuts[0][i], cuts[0][i + 1]),
                                            slope_marginal_mass(L, cuts[1][j], cuts[1][j + 1]));
            if (bound < 0.1 * share) {
                *errv += bound;
                continue;
            }
            half_ctx ctx = {.gm = gm, .shadowing = shadowing, .lobe = L,
                            .cell = {cuts[0][i], cuts[0][i + 1], cuts[1][j], cuts[1][j + 1]}};
            const double lo[2] = {0.0, 0.0}, hi[2] = {1.0, 1.0};
            size_t budget = max_evals > *evals ? (max_evals - *evals) / 25 : 0;
            double v = 0.0, e = 0.0;
            if (budget < 17) {
                *converged = 0;
                return WENV_OK;
            }
            if (hcubature_v(1, half_integrand, &ctx, 2, lo, hi, budget, share, 0.0, ERROR_INDIVIDUAL, &v, &e) != 0)
                return wenv_error_set(err, WENV_ERR_NOMEM, "glossmeter: out of memory in the cubature");
            *evals += ctx.evals;
            if (!(e <= share))
                *converged = 0;
            *val += v;
            *errv += e;
        }
    }
    return WENV_OK;
}

/* Whether a lobe needs the half-vector form: some receptor edge passes within one lobe width of
 * the mirror image of the source, across which the lobe is narrower than a tenth of the image.
 * Otherwise the 4-D form's integrand is smooth on the source (the image well inside or outside
 * the receptor, or a lobe wide enough to blur the edge over the image). */
static int lobe_needs_half_vector(const wenv_glossmeter *gm, const active_lobe *L)
{
    if (gm->image_far)
        return 0;
    double width[2];
    width[0] = L->scale * L->lobe->roughness;
    width[1] = width[0] * gm->cos_i0;
    for (int k = 0; k < 2; k++) {
        double lo = gm->image_lo[k], hi = gm->image_hi[k];
        int near_edge = (-gm->hd[k] >= lo - width[k] && -gm->hd[k] <= hi + width[k]) ||
                        (gm->hd[k] >= lo - width[k] && gm->hd[k] <= hi + width[k]);
        if (near_edge && width[k] < 0.1 * (hi - lo))
            return 1;
    }
    return 0;
}

static double luminance(const double rgb[3]) { return LUMA[0] * rgb[0] + LUMA[1] * rgb[1] + LUMA[2] * rgb[2]; }

/* Flux of `mat` and its error bound: tol_flux / WENV_GLOSS_SAFETY is asked of the lobes' integral and
 * the error returned is WENV_GLOSS_SAFETY times the integrators' estimates (see glossmeter.h). */
static wenv_status material_flux(const wenv_glossmeter *gm, const wenv_material *mat, int smooth, int method,
                                 double tol_flux,
                                 size_t max_evals, double *flux, double *flux_err, size_t *evals, int *converged,
                                 wenv_error *err)
{
    *flux = *flux_err = 0.0;
    *evals = 0;
    *converged = 1;
    size_t n_lobes = wenv_material_lobe_count(mat);
    wenv_shadowing shadowing = wenv_material_shadowing(mat);
    if (n_lobes > 64)
        return wenv_error_set(err, WENV_ERR_VALUE, "material has %zu lobes; the glossmeter handles at most 64",
                              n_lobes);
    active_lobe rough[64], narrow[64];
    double mirror_ior[64], mirror_w[64];
    size_t n_rough = 0, n_narrow = 0, n_mirror = 0;
    for (size_t k = 0; k < n_lobes; k++) {
        const wenv_lobe *L = wenv_material_lobe(mat, k);
        double w = luminance(L->specular);
        if (w <= 0.0)
            continue;
        if (smooth) {
            mirror_ior[n_mirror] = L->ior;
            mirror_w[n_mirror++] = w;
        } else {
            active_lobe a = {.lobe = L, .weight = w};
            lobe_warp(L->distribution, &a.warp, &a.scale);
            if (method == WENV_GLOSS_HALF_VECTOR || (method == WENV_GLOSS_AUTO && lobe_needs_half_vector(gm, &a)))
                narrow[n_narrow++] = a;
            else
                rough[n_rough++] = a;
        }
    }

    /* Diffuse: f = albedo/pi is constant, so the 4-D integral is the product of the apertures'
     * projected solid angles (precomputed). */
    double albedo = luminance(wenv_material_diffuse(mat));
    *flux += albedo / M_PI * gm->proj_source * gm->proj_receptor;
    *flux_err += WENV_GLOSS_SAFETY * albedo / M_PI * gm->proj_error;

    if (n_mirror > 0) {
        double v[64], e[64];
        wenv_status st = mirror_flux(gm, gm->n, &gm->mirror_in, (unsigned)n_mirror, mirror_ior, mirror_w,
                                     max_evals, v, e, evals, converged, err);
        if (st)
            return st;
        for (size_t k = 0; k < n_mirror; k++) {
            *flux += v[k];
            *flux_err += WENV_GLOSS_SAFETY * e[k];
        }
    }

    /* Split the lobes' budget between the two forms when both are needed. */
    double req = tol_flux / WENV_GLOSS_SAFETY / ((n_rough > 0) + (n_narrow > 0) > 1 ? 2.0 : 1.0);
    for (size_t k = 0; k < n_narrow; k++) {
        double v, e;
        wenv_status st = half_vector_flux(gm, shadowing, &narrow[k], req / (double)n_narrow, max_evals, &v, &e,
                                          evals, converged, err);
        if (st)
            return st;
        *flux += v;
        *flux_err += WENV_GLOSS_SAFETY * e;
    }
    if (n_rough > 0) {
        lobe_ctx ctx = {.gm = gm, .shadowing = shadowing, .lobes = rough, .n_lobes = n_rough};
        const double lo[4] = {-gm->hs[0], -gm->hs[1], 0.0, 0.0}, hi[4] = {gm->hs[0], gm->hs[1], 1.0, 1.0};
        double v, e;
        if (hcubature_v(1, lobe_integrand, &ctx, 4, lo, hi, max_evals, req, 0.0, ERROR_INDIVIDUAL, &v, &e) != 0)
            return wenv_error_set(err, WENV_ERR_NOMEM, "glossmeter: out of memory in the cubature");
        *evals += ctx.evals;
        if (!(e <= req))
            *converged = 0;
        *flux += v;
        *flux_err += WENV_GLOSS_SAFETY * e;
    }
    return WENV_OK;
}

static wenv_status check_options(const wenv_gloss_options *opt, wenv_error *err)
{
    if (!isfinite(opt->tol) || opt->tol <= 0.0)
        return wenv_error_set(err, WENV_ERR_VALUE, "tol must be a positive number of gloss units, got %g", opt->tol);
    if (opt->method < WENV_GLOSS_AUTO || opt->method > WENV_GLOSS_HALF_VECTOR)
        return wenv_error_set(err, WENV_ERR_VALUE, "method must be 'auto', 'aperture' or 'half_vector'");
    if (opt->max_evals < 1000)
        return wenv_error_set(err, WENV_ERR_VALUE, "max_evals must be at least 1000, got %zu", opt->max_evals);
    return WENV_OK;
}

wenv_status wenv_glossmeter_measure(const wenv_glossmeter *gm, const wenv_material *mat,
                                    const wenv_gloss_options *opt, wenv_gloss_result *out, wenv_error *err)
{
    memset(out, 0, sizeof *out);
    wenv_status bad = check_options(opt, err);
    if (bad)
        return bad;
    if (!(gm->flux_std > 0.0))
        return wenv_error_set(err, WENV_ERR_VALUE,
                              "the receptor does not see the mirror image of the source (receptor_offset too "
                              "large), so the standard reads zero and gloss is undefined");
    /* 90% of the budget to the lobes; the 2-D parts are computed to ~1e-11 relative. */
    double tol_flux = 0.9 * opt->tol * gm->flux_std / 100.0;
    double flux, ferr;
    wenv_status st = material_flux(gm, mat, opt->smooth, opt->method, tol_flux, opt->max_evals, &flux, &ferr, &out->evaluations,
                                   &out->converged, err);
    if (st)
        return st;
    out->flux = flux;
    out->flux_standard = gm->flux_std;
    out->value = 100.0 * flux / gm->flux_std;
    out->error = 100.0 * ferr / gm->flux_std + WENV_GLOSS_SAFETY * fabs(out->value) * gm->flux_std_error / gm->flux_std;
    return WENV_OK;
}

wenv_status wenv_glossmeter_measure_many(wenv_glossmeter *const *gms, size_t n, const wenv_material *mat,
                                         const wenv_gloss_options *opt, wenv_gloss_result *out, wenv_error *err)
{
    wenv_error errs[16];
    if (n > 16)
        return wenv_error_set(err, WENV_ERR_VALUE, "at most 16 glossmeters at once, got %zu", n);
    memset(errs, 0, sizeof errs);
    /* One thread per meter: readings differ in cost (20 degrees is usually the dearest), so hand them
     * out one at a time. */
#pragma omp parallel for schedule(dynamic, 1) if (n > 1)
    for (size_t i = 0; i < n; i++)
        wenv_glossmeter_measure(gms[i], mat, opt, &out[i], &errs[i]);
    for (size_t i = 0; i < n; i++)
        if (errs[i].status != WENV_OK)
            return wenv_error_set(err, errs[i].status, "%s", errs[i].message);
    return WENV_OK;
}

/* ---------------------------------------------------------------- haze */

wenv_status wenv_glossmeter_haze(const wenv_glossmeter *specular, const wenv_material *mat, const double offsets[2],
                                 const double aperture[2], const wenv_gloss_options *opt, wenv_gloss_result *out,
                                 wenv_error *err)
{
    memset(out, 0, sizeof *out);
    wenv_status bad = check_options(opt, err);
    if (bad)
        return bad;
    for (int i = 0; i < 2; i++)
        if (!isfinite(offsets[i]) || fabs(offsets[i]) >= 90.0)
            return wenv_error_set(err, WENV_ERR_VALUE, "offsets must be two finite angles in (-90, 90) degrees");
    if ((bad = check_size(aperture, "aperture", err)))
        return bad;
    if (!(specular->flux_std > 0.0))
        return wenv_error_set(err, WENV_ERR_VALUE, "the specular glossmeter does not see the standard");
    out->converged = 1;
    double tol_flux = 0.45 * opt->tol * specular->flux_std / 100.0; /* split over the two receptors */
    for (int i = 0; i < 2; i++) {
        wenv_glossmeter_config cfg = specular->cfg;
        cfg.receptor[0] = aperture[0];
        cfg.receptor[1] = aperture[1];
        cfg.receptor_offset[0] += offsets[i];
        wenv_glossmeter *gm;
        wenv_error local = {0};
        if (wenv_glossmeter_create(&gm, &cfg, &local) != WENV_OK) {
            if (local.status == WENV_ERR_NOMEM)
                return wenv_error_set(err, local.status, "%s", local.message);
            return wenv_error_set(err, WENV_ERR_VALUE, "offsets/aperture: haze receptor %d at %g degrees: %s", i,
                                  cfg.angle + cfg.receptor_offset[0], local.message);
        }
        double flux, ferr;
        size_t ev;
        int conv;
        wenv_status st = material_flux(gm, mat, opt->smooth, opt->method, tol_flux, opt->max_evals, &flux, &ferr, &ev, &conv, err);
        wenv_glossmeter_free(gm);
        if (st)
            return st;
        out->flux += flux;
        out->error += ferr;
        out->evaluations += ev;
        out->converged &= conv;
    }
    out->flux_standard = specular->flux_std;
    out->value = 100.0 * out->flux / specular->flux_std;
    out->error = 100.0 * out->error / specular->flux_std +
                 WENV_GLOSS_SAFETY * fabs(out->value) * specular->flux_std_error / specular->flux_std;
    return WENV_OK;
}

/* ---------------------------------------------------------------- inverse: roughness for a reading */

/* Reading of `tmpl` with every lobe's roughness set to m. */
static wenv_status reading_at(const wenv_glossmeter *gm, const wenv_material *tmpl, double m,
                              const wenv_gloss_options *opt, wenv_gloss_result *r, wenv_error *err)
{
    wenv_material *mat;
    wenv_status st = wenv_material_with_roughness(&mat, tmpl, m, err);
    if (st)
        return st;
    st = wenv_glossmeter_measure(gm, mat, opt, r, err);
    wenv_material_free(mat);
    return st;
}

wenv_status wenv_glossmeter_fit_roughness(const wenv_glossmeter *gm, const wenv_material *tmpl, double target,
                                          double m_lo, double m_hi, const wenv_gloss_options *opt,
                                          double *roughness, wenv_gloss_result *at_root, wenv_error *err)
{
    if (!isfinite(target))
        return wenv_error_set(err, WENV_ERR_VALUE, "target_gu must be finite");
    if (!(m_lo >= WENV_ROUGHNESS_MIN) || !(m_hi > m_lo) || !(m_hi <= WENV_ROUGHNESS_MAX))
        return wenv_error_set(err, WENV_ERR_VALUE, "bracket must satisfy %g <= lo < hi <= %g, got (%g, %g)",
                              WENV_ROUGHNESS_MIN, WENV_ROUGHNESS_MAX, m_lo, m_hi);
    if (wenv_material_lobe_count(tmpl) < 1)
        return wenv_error_set(err, WENV_ERR_VALUE, "fit_roughness needs a material with a specular lobe");
    wenv_gloss_options o = *opt;
    o.smooth = 0;
    wenv_gloss_result ra, rb, r;
    wenv_status st;
    if ((st = reading_at(gm, tmpl, m_lo, &o, &ra, err)) || (st = reading_at(gm, tmpl, m_hi, &o, &rb, err)))
        return st;
    if (!(target <= ra.value && target >= rb.value)) {
        wenv_gloss_result smooth;
        o.smooth = 1;
        double smooth_value = NAN;
        wenv_error ignore = {0};
        if (wenv_glossmeter_measure(gm, tmpl, &o, &smooth, &ignore) == WENV_OK)
            smooth_value = smooth.value;
        return wenv_error_set(err, WENV_ERR_VALUE,
                              "target_gu %g is out of reach at %g degrees: roughness %g..%g reads %.3f..%.3f GU "
                              "(smooth-surface limit %.3f GU)",
                              target, gm->cfg.angle, m_lo, m_hi, ra.value, rb.value, smooth_value);
    }
    /* Illinois (modified regula falsi) on x = ln m with g(x) = reading - target decreasing in x.  The
     * bracket [xa, xb] always holds the root, so the search cannot leave [m_lo, m_hi]; it stops when
     * the reading is within tol / WENV_GLOSS_SAFETY of the target (the integrals' own accuracy) or
     * the bracket is ~1e-9 wide in ln m. */
    double xa = log(m_lo), xb = log(m_hi), ga = ra.value - target, gb = rb.value - target;
    double half_tol = opt->tol / WENV_GLOSS_SAFETY; /* the readings' own accuracy */
    int side = 0;
    double x;
    if (fabs(ga) <= half_tol) {
        x = xa;
        r = ra;
    } else if (fabs(gb) <= half_tol) {
        x = xb;
        r = rb;
    } else {
        for (int it = 0;; it++) {
            double xn = xb - gb * (xb - xa) / (gb - ga);
            if (!(xn > xa && xn < xb) || it % 8 == 7) /* degenerate step, or slow: bisect */
                xn = 0.5 * (xa + xb);
            if ((st = reading_at(gm, tmpl, exp(xn), &o, &r, err)))
                return st;
            double gn = r.value - target;
            x = xn;
            if (fabs(gn) <= half_tol || xb - xa < 1e-9 || it >= 100)
                break;
            if (gn > 0.0) { /* reading still too high: the root lies at larger roughness */
                xa = xn;
                ga = gn;
                if (side == -1)
                    gb *= 0.5;
                side = -1;
            } else {
                xb = xn;
                gb = gn;
                if (side == 1)
                    ga *= 0.5;
                side = 1;
            }
        }
    }
    *roughness = exp(x);
    if (at_root)
        *at_root = r;
    return WENV_OK;
}
