/* A material's flux from the source into the receptor: its diffuse part in closed form, its smooth
 * limit over the mirror region, and its lobes by adaptive cubature (glossmeter.h).
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
#include "glossmeter/glossmeter_internal.h"

/* Luminance weights (Rec. 709 / sRGB primaries), docs/ARCHITECTURE.md §3.7. */
static const double LUMA[3] = {0.2126, 0.7152, 0.0722};

static double luminance(const double rgb[3]) { return LUMA[0] * rgb[0] + LUMA[1] * rgb[1] + LUMA[2] * rgb[2]; }

/* ---------------------------------------------------------------- the specular lobes (4-D) */

typedef enum { WARP_GAUSS, WARP_CAUCHY } warp_kind;

typedef struct {
    const wenv_material *mat;
    size_t index;   /* the lobe's, in mat: its values come from the material */
    wenv_lobe_rgb_fn value, over_ndf; /* the material's, resolved once */
    const wenv_lobe *lobe; /* its shape: widths and warps */
    double weight;  /* luminance of the shape's colour, for error budgets */
    warp_kind warp; /* the lobe's change of variables, see lobe_warp() */
    double scale;   /* warp scale per unit roughness along the plane of incidence */
} active_lobe;

typedef struct {
    const wenv_glossmeter *gm;
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
            double w = L->scale * L->lobe->alpha;
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
            double f[3];
            L->value(L->mat, L->index, sl, dl, f);
            sum += luminance(f) * cos_s * cos_d * dens_s * dens_d * jx * jy;
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

typedef struct {
    const wenv_glossmeter *gm;
    const active_lobe *lobe;
    double cell[4]; /* slope box p0, p1, q0, q1 integrated by this call */
    size_t evals;
} half_ctx;

/* F G (s.h) d omega_s at gnomonic source point (x, y) for half vector h, given in the specimen's
 * local frame (F G: the lobe over its shape's D, from the material, which works in that frame). */
static double half_point(const half_ctx *ctx, const double h_local[3], double x, double y)
{
    const wenv_glossmeter *gm = ctx->gm;
    double sl[3], dl[3], fg[3];
    double dens = aperture_dir(gm->cs_local, gm->us_local, gm->vs_local, x, y, sl);
    double sh = dot3(sl, h_local);
    if (!(sh > 0.0))
        return 0.0;
    for (int k = 0; k < 3; k++)
        dl[k] = 2.0 * sh * h_local[k] - sl[k];
    if (!(sl[2] > 0.0) || !(dl[2] > 0.0))
        return 0.0;
    ctx->lobe->over_ndf(ctx->lobe->mat, ctx->lobe->index, sl, dl, fg);
    return luminance(fg) * sh * dens;
}

/* Inner integral over the source region that h reflects into the receptor. */
static double half_inner(half_ctx *ctx, const double h[3])
{
    const wenv_glossmeter *gm = ctx->gm;
    polygon p;
    wenv_gm_mirror_region(gm, h, &p);
    if (p.n < 3)
        return 0.0;
    double h_local[3];
    to_local(gm, h, h_local);
    double sum = 0.0;
    if (wenv_gm_polygon_is_rect(&p, gm->hs)) {
        for (int i = 0; i < 5; i++)
            for (int j = 0; j < 5; j++)
                sum += GL5_W[i] * GL5_W[j] *
                       half_point(ctx, h_local, gm->hs[0] * (2.0 * GL5_X[i] - 1.0),
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
                row += GL5_W[j] * half_point(ctx, h_local, x, y);
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
    return wenv_slope_density(lobe->distribution, lobe->alpha, p * p + q * q);
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
    double a = L->warp == WARP_GAUSS ? lobe->alpha * M_SQRT1_2 : lobe->alpha;
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
        fval[i] = w / inv * half_inner(ctx, h);
    }
    return 0;
}

/* Probability that one slope coordinate of the lobe lies in [a, b] (marginals: Gaussian of sigma
 * m/sqrt(2) for Beckmann; (1 + x/sqrt(1 + x^2))/2 in x = slope/m for GGX). */
static double slope_marginal_mass(const active_lobe *L, double a, double b)
{
    double m = L->lobe->alpha;
    if (L->warp == WARP_GAUSS)
        return 0.5 * fabs(erfc(-b / m) - erfc(-a / m)); /* slope / (sigma sqrt 2) = slope / m */
    double xa = a / m, xb = b / m;
    return 0.5 * fabs(xb / sqrt(1.0 + xb * xb) - xa / sqrt(1.0 + xa * xa));
}

/* Integrates one narrow lobe in the half-vector form: the slope box is cut at the kinks of the
 * inner integral (so every cell's integrand is smooth and no kink hides between a rule's points),
 * skipping Beckmann cuts beyond 12 sigma where the lobe weighs nothing; each cell gets an equal share
 * of the tolerance. */
static wenv_status half_vector_flux(const wenv_glossmeter *gm, const active_lobe *L,
                                    double req, size_t max_evals, double *val, double *errv, size_t *evals,
                                    int *converged, wenv_error *err)
{
    double cuts[2][MAX_KINKS + 2];
    size_t nc[2];
    double reach = L->warp == WARP_GAUSS ? 12.0 * L->lobe->alpha * M_SQRT1_2 : INFINITY;
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
            half_ctx ctx = {.gm = gm, .lobe = L,
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
    width[0] = L->scale * L->lobe->alpha;
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


/* Flux of `mat` and its error bound: tol_flux / WENV_GLOSS_SAFETY is asked of the lobes' integral and
 * the error returned is WENV_GLOSS_SAFETY times the integrators' estimates (see glossmeter.h). */
wenv_status wenv_gm_material_flux(const wenv_glossmeter *gm, const wenv_material *mat, int smooth, int method,
                                  double tol_flux, size_t max_evals, double *flux, double *flux_err, size_t *evals,
                                  int *converged, wenv_error *err)
{
    *flux = *flux_err = 0.0;
    *evals = 0;
    *converged = 1;
    size_t n_lobes = wenv_material_lobe_count(mat);
    if (smooth && !wenv_material_has_smooth_limit(mat))
        return wenv_error_set(err, WENV_ERR_VALUE, "smooth=True reads the smooth limit of a material's lobes, and a %s "
                              "material has none", wenv_material_kind_name(mat));
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
            active_lobe a = {.mat = mat, .index = k, .value = wenv_material_lobe_value_fn(mat),
                             .over_ndf = wenv_material_lobe_over_ndf_fn(mat), .lobe = L, .weight = w};
            lobe_warp(L->distribution, &a.warp, &a.scale);
            if (method == WENV_GLOSS_HALF_VECTOR || (method == WENV_GLOSS_AUTO && lobe_needs_half_vector(gm, &a)))
                narrow[n_narrow++] = a;
            else
                rough[n_rough++] = a;
        }
    }

    /* Diffuse: f = albedo/pi is constant over the apertures, so the 4-D integral is the product of
     * their projected solid angles (precomputed).  A layered material's albedo changes with the view:
     * it is read at the receptor's centre, the view of a few degrees' aperture whose first-order
     * change cancels across it. */
    double diffuse_rgb[3];
    wenv_material_diffuse_at(mat, dot3(gm->cd, gm->n), diffuse_rgb);
    double albedo = luminance(diffuse_rgb);
    *flux += albedo / M_PI * gm->proj_source * gm->proj_receptor;
    *flux_err += WENV_GLOSS_SAFETY * albedo / M_PI * gm->proj_error;

    if (n_mirror > 0) {
        double v[64], e[64];
        wenv_status st = wenv_gm_mirror_flux(gm, gm->n, &gm->mirror_in, (unsigned)n_mirror, mirror_ior, mirror_w,
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
        wenv_status st = half_vector_flux(gm, &narrow[k], req / (double)n_narrow, max_evals, &v, &e,
                                          evals, converged, err);
        if (st)
            return st;
        *flux += v;
        *flux_err += WENV_GLOSS_SAFETY * e;
    }
    if (n_rough > 0) {
        lobe_ctx ctx = {.gm = gm, .lobes = rough, .n_lobes = n_rough};
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
