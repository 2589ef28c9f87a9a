/* A material's reading: its flux into the receptor (diffuse, smooth limits, lobes) over the
 * standard's, haze, and the alpha or roughness that reads a target (glossmeter.h). */
#include "glossmeter/glossmeter_internal.h"

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
    wenv_status st = wenv_gm_material_flux(gm, mat, opt->smooth, opt->method, tol_flux, opt->max_evals, &flux, &ferr, &out->evaluations,
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
    if ((bad = wenv_gm_check_size(aperture, "aperture", err)))
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
        wenv_status st = wenv_gm_material_flux(gm, mat, opt->smooth, opt->method, tol_flux, opt->max_evals, &flux, &ferr, &ev, &conv, err);
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

/* ---------------------------------------------------------------- inverse: alpha or roughness for a reading */

static const char *const FIT_NAMES[] = {"alpha", "roughness"};

/* Reading of `tmpl` with its alpha or roughness set to x. */
static wenv_status reading_at(const wenv_glossmeter *gm, const wenv_material *tmpl, wenv_fit_param param, double x,
                              const wenv_gloss_options *opt, wenv_gloss_result *r, wenv_error *err)
{
    wenv_material *mat;
    wenv_status st = param == WENV_FIT_ALPHA ? wenv_material_with_alpha(&mat, tmpl, x, err)
                                             : wenv_material_with_roughness(&mat, tmpl, x, err);
    if (st)
        return st;
    st = wenv_glossmeter_measure(gm, mat, opt, r, err);
    wenv_material_free(mat);
    return st;
}

wenv_status wenv_glossmeter_fit(const wenv_glossmeter *gm, const wenv_material *tmpl, wenv_fit_param param,
                                double target, double m_lo, double m_hi, const wenv_gloss_options *opt,
                                double *value, wenv_gloss_result *at_root, wenv_error *err)
{
    if (!isfinite(target))
        return wenv_error_set(err, WENV_ERR_VALUE, "target_gu must be finite");
    if (param != WENV_FIT_ALPHA && param != WENV_FIT_ROUGHNESS)
        return wenv_error_set(err, WENV_ERR_VALUE, "param must be alpha or roughness");
    const char *name = FIT_NAMES[param];
    double lo_min = param == WENV_FIT_ALPHA ? WENV_ALPHA_MIN : 0.0, hi_max = param == WENV_FIT_ALPHA ? WENV_ALPHA_MAX : 1.0;
    if (!(m_lo >= lo_min && m_lo > 0.0) || !(m_hi > m_lo) || !(m_hi <= hi_max))
        return wenv_error_set(err, WENV_ERR_VALUE, "bracket must satisfy %g %s lo < hi <= %g for %s, got (%g, %g)",
                              lo_min, lo_min > 0.0 ? "<=" : "<", hi_max, name, m_lo, m_hi);
    if (wenv_material_lobe_count(tmpl) < 1)
        return wenv_error_set(err, WENV_ERR_VALUE, "fitting %s needs a material with a specular lobe", name);
    wenv_gloss_options o = *opt;
    o.smooth = 0;
    wenv_gloss_result ra, rb, r;
    wenv_status st;
    if ((st = reading_at(gm, tmpl, param, m_lo, &o, &ra, err)) || (st = reading_at(gm, tmpl, param, m_hi, &o, &rb, err)))
        return st;
    if (!(target <= ra.value && target >= rb.value)) {
        wenv_gloss_result smooth;
        o.smooth = 1;
        double smooth_value = NAN;
        wenv_error ignore = {0};
        if (wenv_glossmeter_measure(gm, tmpl, &o, &smooth, &ignore) == WENV_OK)
            smooth_value = smooth.value;
        if (isnan(smooth_value)) /* a material without a smooth limit (a Principled BSDF, a table) */
            return wenv_error_set(err, WENV_ERR_VALUE,
                                  "target_gu %g is out of reach at %g degrees: %s %g..%g reads %.3f..%.3f GU",
                                  target, gm->cfg.angle, name, m_lo, m_hi, ra.value, rb.value);
        return wenv_error_set(err, WENV_ERR_VALUE,
                              "target_gu %g is out of reach at %g degrees: %s %g..%g reads %.3f..%.3f GU "
                              "(smooth-surface limit %.3f GU)",
                              target, gm->cfg.angle, name, m_lo, m_hi, ra.value, rb.value, smooth_value);
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
            if ((st = reading_at(gm, tmpl, param, exp(xn), &o, &r, err)))
                return st;
            double gn = r.value - target;
            x = xn;
            if (fabs(gn) <= half_tol || xb - xa < 1e-9 || it >= 100)
                break;
            if (gn > 0.0) { /* reading still too high: the root lies at wider lobes */
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
    *value = exp(x);
    if (at_root)
        *at_root = r;
    return WENV_OK;
}

