/* The instrument: apertures, the specimen frame, the mirror region of the source, the standard's
 * flux and the 2-D integrals over the source (glossmeter.h). */
#include "glossmeter/glossmeter_internal.h"
#include "math/frame.h"

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
void wenv_gm_mirror_region(const wenv_glossmeter *gm, const double normal[3], polygon *p)
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

int wenv_gm_polygon_is_rect(const polygon *p, const double half[2])
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
wenv_status wenv_gm_mirror_flux(const wenv_glossmeter *gm, const double normal[3], const polygon *region,
                                unsigned fdim, const double *ior, const double *weight, size_t max_evals,
                               double *val, double *errv, size_t *evals, int *converged, wenv_error *err)
{
    area_ctx ctx = {.gm = gm, .normal = normal, .ior = ior, .weight = weight, .c = gm->cs, .u = gm->us,
                    .v = gm->vs};
    wenv_status st = integrate_area(&ctx, region, wenv_gm_polygon_is_rect(region, gm->hs), gm->hs, fdim, 1e-11,
                                    max_evals, val, errv, converged, err);
    if (evals)
        *evals += ctx.evals;
    return st;
}

/* ---------------------------------------------------------------- creation and validation */

wenv_status wenv_gm_check_size(const double size[2], const char *name, wenv_error *err)
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
    if ((bad = wenv_gm_check_size(cfg->source, "source", err)) || (bad = wenv_gm_check_size(cfg->receptor, "receptor", err)))
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
    double frame[9]; /* the one tangent frame (docs/ARCHITECTURE.md §3.1); any serves isotropic lobes */
    wenv_frame(gm->n, frame);
    memcpy(gm->t1, frame, sizeof gm->t1);
    memcpy(gm->t2, frame + 3, sizeof gm->t2);

    /* Source: polar angle A on the -X side; u = d c / d(polar angle), v = +Y. */
    double A = cfg->angle * DEG;
    const double cs[3] = {-sin(A), 0.0, cos(A)}, us[3] = {-cos(A), 0.0, -sin(A)}, ey[3] = {0.0, 1.0, 0.0};
    memcpy(gm->cs, cs, sizeof cs);
    memcpy(gm->us, us, sizeof us);
    memcpy(gm->vs, ey, sizeof ey);
    to_local(gm, gm->cs, gm->cs_local); /* for the lobes' values, which the material gives in that frame */
    to_local(gm, gm->us, gm->us_local);
    to_local(gm, gm->vs, gm->vs_local);
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
    wenv_gm_mirror_region(gm, ez, &std_region);
    wenv_gm_mirror_region(gm, gm->n, &gm->mirror_in);
    if ((st = wenv_gm_mirror_flux(gm, ez, &std_region, 1, &cfg->standard_ior, NULL, WENV_GLOSS_DEFAULT_MAX_EVALS, val, ev,
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

