/* Blender's Principled BSDF as Cycles evaluates it ("Principled v2", Blender 4.x and 5.x), reflection
 * only (material.h, wenv_principled_create).
 *
 * Cycles builds the node as closures from the top layer down, each taking from those below what it
 * reflects (svm_node_closure_bsdf, CLOSURE_BSDF_PRINCIPLED_ID): with W the weight left for the
 * layers below, starting at Alpha,
 *   sheen    Zeltner et al.'s linearly transformed cosine (A, B, albedo R from a table over n.v and Sheen
 *            Roughness), weight Sheen Weight x Sheen Tint W R; then W *= 1 - its albedo;
 *   coat     GGX (alpha = Coat Roughness^2), exact dielectric Fresnel of Coat IOR, weight Coat Weight W,
 *            always energy-compensated; then W *= 1 - its albedo, and the coat's absorption
 *            W *= mix(1, Coat Tint^(1 / cos_t), Coat Weight), cos_t the view refracted into the coat;
 *   metal    GGX (alpha = Roughness^2), F82-tint Fresnel (F0 = Base Color, F82 tint = Specular Tint),
 *            weight Metallic W; then W *= (1 - Metallic) (1 - Transmission Weight);
 *   specular GGX, the dielectric Fresnel of the IOR remapped from its F0 to F0' = F0 2 Level x
 *            Specular Tint (the "generalised Schlick" real-Fresnel mode), weight W; then
 *            W *= 1 - its albedo;
 *   diffuse  Lambert, Base Color W; with Diffuse Roughness (Blender 4.3+) the energy-preserving
 *            Oren-Nayar of OpenPBR ("EON": Fujii's improved Oren-Nayar and a multiple-scattering term),
 *            which depends on the light as well, so it is one more lobe; with oren_nayar_classic,
 *            Fujii's term alone, as Cycles shades a rough Diffuse BSDF before 4.3.
 * "Multiscatter GGX" (the default) compensates the metal and specular lobes for the energy single
 * scattering loses (Kulla & Conty): the lobe is divided by its albedo E(mu) with F = 1 and darkened
 * to 1 + Fms (1 - E) / E, Fms = Fss Eavg / (1 - Fss (1 - Eavg)) with Fss the Fresnel's cosine-weighted
 * mean.  A layer's albedo is Cycles' estimate: its weight (darkening included) times
 * mix(F0, 1, s(rough, mu, F0)), s read from a table.  "1 - albedo" is 1 - its largest channel,
 * clamped to [0, 1].  Every weight depends on the view only (mu = n.v), so the diffuse part is
 * Lambertian for each view with an albedo that changes with it (wenv_material_diffuse_at).  The
 * tables (E, Eavg, s) are principled_tables.c, computed from their definitions; a lookup is linear
 * between nodes at i / (n - 1), clamped, as Cycles reads them.
 *
 * Emission (Emission Color x Strength) is emitted through the layers above the metal, as Cycles sets it
 * up after the coat: its weight is W there, so a coat or sheen dims it towards grazing
 * (wenv_material_emission_at).
 * What Cycles adds that reflection does not have -- transmission, subsurface scattering, the
 * see-through part of Alpha, thin film, anisotropy -- is not shaded, nor a Coat Tint above 1
 * (read as 1); wenv_principled_unhonoured names each input set to something that needs it.
 * Subsurface scattering is shaded as the diffuse reflection it turns into on a smooth convex surface
 * (Base Color as albedo). */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "base/fingerprint.h"
#include "scene/material_kind.h"
#include "scene/principled_tables.h"
#include "scene/sheen_table.h"


typedef enum { LOBE_SHEEN, LOBE_COAT, LOBE_METAL, LOBE_SPECULAR, LOBE_DIFFUSE } lobe_role;

#define MAX_LOBES 5

typedef struct {
    lobe_role role;
    double alpha, rough; /* GGX alpha and Cycles' table coordinate (alpha^(1/2)) */
    int compensate;      /* energy compensation */
    double fss[3];       /* the Fresnel's cosine-weighted mean (compensation) */
    double z;            /* the s table's third coordinate for the albedo estimate */
    int ior_table;       /* which s table: 1 gen_schlick_ior_s, 0 gen_schlick_s */
    double f0_est[3];    /* the albedo estimate's mix(f0_est, 1, s) */
} lobe_model;

typedef struct {
    wenv_shared shared;
    wenv_principled_inputs in; /* as given, clamped as Cycles clamps */
    double base[3];            /* Base Color clamped to [0, 1] */
    double eta, f0_col[3];     /* the specular lobe's (adjusted) index and tinted F0 */
    double f0_metal[3], b_metal[3];
    double eon_a, eon_b, eon_ems[3]; /* the Oren-Nayar diffuse's constants (Diffuse Roughness > 0) */
    size_t n;
    lobe_model lobe[MAX_LOBES];
} principled;

static const principled *model_of(const wenv_material *mat) { return (const principled *)mat->shared; }

static void model_destroy(wenv_shared *shared) { free(shared); }

static inline double clamp01(double x) { return x < 0.0 ? 0.0 : (x > 1.0 ? 1.0 : x); }

/* ---------------------------------------------------------------- tables, as Cycles reads them */

static double read1(const float *t, size_t n, double x, size_t stride)
{
    x = clamp01(x) * (double)(n - 1);
    size_t i = (size_t)x < n - 1 ? (size_t)x : n - 1, j = i + 1 < n ? i + 1 : n - 1;
    double f = x - (double)i;
    return (1.0 - f) * t[i * stride] + f * t[j * stride];
}

static double read2(const float *t, size_t nx, size_t ny, double x, double y)
{
    y = clamp01(y) * (double)(ny - 1);
    size_t i = (size_t)y < ny - 1 ? (size_t)y : ny - 1, j = i + 1 < ny ? i + 1 : ny - 1;
    double f = y - (double)i;
    return (1.0 - f) * read1(t + i * nx, nx, x, 1) + f * read1(t + j * nx, nx, x, 1);
}

static double read3(const float *t, size_t n, double x, double y, double z)
{
    z = clamp01(z) * (double)(n - 1);
    size_t i = (size_t)z < n - 1 ? (size_t)z : n - 1, j = i + 1 < n ? i + 1 : n - 1;
    double f = z - (double)i;
    return (1.0 - f) * read2(t + i * n * n, n, n, x, y) + f * read2(t + j * n * n, n, n, x, y);
}

/* ---------------------------------------------------------------- Fresnel */

static inline double f0_from_ior(double eta) { return ((eta - 1.0) / (eta + 1.0)) * ((eta - 1.0) / (eta + 1.0)); }

static double ior_from_f0(double f0)
{
    double s = sqrt(fmin(fmax(f0, 0.0), 0.99));
    return (1.0 + s) / (1.0 - s);
}

/* Kulla and Conty's fit of the cosine-weighted mean of the dielectric Fresnel. */
static double fresnel_dielectric_fss(double eta)
{
    return eta >= 1.0 ? (eta - 1.0) / (4.08567 + 1.00071 * eta)
                      : 0.997118 + eta * (0.1014 - eta * (0.965241 + eta * 0.130607));
}

/* Each role's Fresnel at c = wi.h, RGB: inline, so that the float path's per-lobe loops, which pass
 * the role as a constant, run it in vector lanes. */
static inline void role_fresnel(const principled *p, lobe_role role, double c, double f[3])
{
    if (role == LOBE_COAT) {
        f[0] = f[1] = f[2] = wenv_fresnel_dielectric(c, p->in.coat_ior);
    } else if (role == LOBE_METAL) {
        /* F82-tint (Kutz et al., "Novel aspects of the Adobe Standard Material") */
        double s = clamp01(1.0 - c), s5 = s * s * s * s * s;
        for (int k = 0; k < 3; k++)
            f[k] = clamp01(p->f0_metal[k] + (1.0 - p->f0_metal[k]) * s5 - p->b_metal[k] * c * s5 * s);
    } else {
        double f0 = f0_from_ior(p->eta);
        double s = clamp01((wenv_fresnel_dielectric(c, p->eta) - f0) / (1.0 - f0));
        for (int k = 0; k < 3; k++)
            f[k] = p->f0_col[k] + (1.0 - p->f0_col[k]) * s;
    }
}

static void lobe_fresnel(const principled *p, const lobe_model *l, double c, double f[3]) { role_fresnel(p, l->role, c, f); }

/* ---------------------------------------------------------------- the layers' weights for a view */

typedef struct {
    double lobe[MAX_LOBES][3]; /* each lobe's RGB weight: layer weight x darkening x 1 / E (compensation) */
    double sheen_a, sheen_b;   /* the sheen's transformed cosine for this view */
    double eon_ms[3];          /* the Oren-Nayar diffuse's multiple scattering for this view */
    double diffuse[3]; /* the Lambertian albedo */
    double emission[3]; /* the radiance emitted: Emission Color x Strength x W after sheen and coat */
    double diffuse_per_colour[3]; /* the same per unit of Base Color: what the layers above leave */
} view_weights;

/* The Oren-Nayar diffuse's G and directional albedo E at cos mu (OpenPBR's EON). */
static double eon_g(double mu)
{
    if (mu < 1e-6)
        return (0.5 * M_PI - 2.0 / 3.0) - mu;
    double s = sqrt(fmax(0.0, 1.0 - mu * mu)), theta = acos(fmin(mu, 1.0));
    return s * (theta - 2.0 / 3.0 - s * mu) + (2.0 / 3.0) * (s / mu) * (1.0 - s * s * s);
}

static double eon_e(const principled *p, double mu) { return p->eon_a * M_PI + p->eon_b * eon_g(mu); }

static void weights_for_view(const principled *p, double mu, view_weights *vw)
{
    mu = clamp01(mu);
    double w[3] = {p->in.alpha, p->in.alpha, p->in.alpha};
    vw->sheen_a = 1.0;
    vw->sheen_b = 0.0;
    int emitted = 0;
    for (size_t i = 0; i <= p->n; i++) {
        /* the layers above the metal are done: emission goes out through them */
        if (!emitted && (i == p->n || (p->lobe[i].role != LOBE_SHEEN && p->lobe[i].role != LOBE_COAT))) {
            for (int k = 0; k < 3; k++)
                vw->emission[k] = p->in.emission_color[k] * p->in.emission_strength * w[k];
            emitted = 1;
        }
        if (i == p->n)
            break;
        const lobe_model *l = &p->lobe[i];
        if (l->role == LOBE_DIFFUSE) { /* the last: what the layers above leave, Base Color W */
            double loss = 1.0 - eon_e(p, mu);
            for (int k = 0; k < 3; k++) {
                vw->lobe[i][k] = p->base[k] * w[k];
                vw->eon_ms[k] = p->eon_ems[k] * loss;
                w[k] = 0.0; /* no Lambertian part left */
            }
            continue;
        }
        if (l->role == LOBE_SHEEN) {
            double a = read2(wenv_sheen_ltc, 32, 32, mu, l->rough);
            double b = read2(wenv_sheen_ltc + 32 * 32, 32, 32, mu, l->rough);
            double r = read2(wenv_sheen_ltc + 2 * 32 * 32, 32, 32, mu, l->rough);
            int kept = fabs(a) >= WENV_PRINCIPLED_WEIGHT_CUTOFF && r >= WENV_PRINCIPLED_WEIGHT_CUTOFF; /* Cycles drops it otherwise */
            double largest = 0.0;
            for (int k = 0; k < 3; k++) {
                vw->lobe[i][k] = kept ? p->in.sheen_weight * p->in.sheen_tint[k] * w[k] * r : 0.0;
                largest = fmax(largest, kept ? p->in.sheen_weight * p->in.sheen_tint[k] * r : 0.0);
            }
            vw->sheen_a = a;
            vw->sheen_b = b;
            for (int k = 0; k < 3; k++)
                w[k] *= clamp01(1.0 - largest);
            continue;
        }
        double scale = l->role == LOBE_COAT ? p->in.coat_weight : (l->role == LOBE_METAL ? p->in.metallic : 1.0);
        double dark[3] = {1.0, 1.0, 1.0}, es = 1.0;
        if (l->compensate) {
            double e = read2(wenv_ggx_E, 32, 32, l->rough, mu), eavg = read1(wenv_ggx_Eavg, 32, l->rough, 1);
            e = fmax(e, 1e-6);
            double missing = (1.0 - e) / e;
            es = 1.0 + missing;
            for (int k = 0; k < 3; k++) {
                double fms = l->fss[k] * eavg / (1.0 - l->fss[k] * (1.0 - eavg));
                dark[k] = (1.0 + fms * missing) / es;
            }
        }
        for (int k = 0; k < 3; k++)
            vw->lobe[i][k] = scale * w[k] * dark[k] * es;
        if (l->role == LOBE_METAL) {
            double below = (1.0 - p->in.metallic) * (1.0 - p->in.transmission_weight);
            for (int k = 0; k < 3; k++)
                w[k] *= below;
            continue;
        }
        /* albedo layering: W *= clamp(1 - max_ch(albedo / W)), the albedo Cycles' estimate */
        double s = l->ior_table ? read3(wenv_ggx_gen_schlick_ior_s, 16, l->rough, mu, l->z)
                                : read3(wenv_ggx_gen_schlick_s, 16, l->rough, mu, l->z);
        double largest = 0.0;
        for (int k = 0; k < 3; k++)
            largest = fmax(largest, scale * dark[k] * (l->f0_est[k] + (1.0 - l->f0_est[k]) * s));
        double keep = clamp01(1.0 - largest);
        for (int k = 0; k < 3; k++)
            w[k] *= keep;
        if (l->role == LOBE_COAT) {
            /* absorption along the view refracted into the coat */
            double inv = 1.0 / p->in.coat_ior, cos_t = sqrt(fmax(0.0, 1.0 - inv * inv * (1.0 - mu * mu)));
            for (int k = 0; k < 3; k++) {
                /* a tint above 1 (a coat that adds light) grows without bound towards grazing in
                 * Cycles, to infinity in float: read as 1 (wenv_principled_unhonoured names it) */
                double c = fmin(p->in.coat_tint[k], 1.0);
                double tint = c == 1.0 ? 1.0 : pow(c, 1.0 / fmax(cos_t, 1e-6));
                w[k] *= 1.0 + (tint - 1.0) * p->in.coat_weight;
            }
        }
    }
    for (int k = 0; k < 3; k++) {
        vw->diffuse[k] = p->base[k] * w[k];
        vw->diffuse_per_colour[k] = w[k];
    }
}

/* ---------------------------------------------------------------- evaluation */

/* The sheen's f (no cosine) at wi: its transformed cosine in the frame whose x axis is the view's
 * tangential direction, over cos_i. */
static double sheen_f(const view_weights *vw, const double wi[3], const double wo[3])
{
    double t = sqrt(wo[0] * wo[0] + wo[1] * wo[1]);
    double tx = t > 1e-12 ? wo[0] / t : 1.0, ty = t > 1e-12 ? wo[1] / t : 0.0; /* head-on: any frame */
    double ox = tx * wi[0] + ty * wi[1], oy = -ty * wi[0] + tx * wi[1], oz = wi[2];
    double a = vw->sheen_a, b = vw->sheen_b;
    double len2 = (a * ox + b * oz) * (a * ox + b * oz) + (a * oy) * (a * oy) + oz * oz;
    double q = a / len2;
    return q * q / M_PI;
}

/* One lobe's f (no cosine) for unit directions above the horizon: weight x F D G2 / (4 ci co), or
 * weight x the sheen's. */
static void lobe_f(const principled *p, const wenv_lobe *shape, size_t i, const view_weights *vw, const double wi[3],
                   const double wo[3], double rgb[3])
{
    if (p->lobe[i].role == LOBE_SHEEN) {
        double s = sheen_f(vw, wi, wo);
        for (int k = 0; k < 3; k++)
            rgb[k] = vw->lobe[i][k] * s;
        return;
    }
    if (p->lobe[i].role == LOBE_DIFFUSE) {
        /* (a + b t) + ms (1 - E(cos_i)), t the cosine of the azimuth between them, over the larger cosine */
        double t = wi[0] * wo[0] + wi[1] * wo[1] + wi[2] * wo[2] - wi[2] * wo[2];
        if (t > 0.0)
            t /= fmax(wi[2], wo[2]) + DBL_MIN;
        double single = p->eon_a + p->eon_b * t, loss = 1.0 - eon_e(p, wi[2]);
        for (int k = 0; k < 3; k++)
            rgb[k] = vw->lobe[i][k] * (single + vw->eon_ms[k] * loss);
        return;
    }
    wenv_half_vector h = wenv_half_vector_of(wi, wo);
    double k_o = wenv_lobe_view_k(shape, WENV_SHADOW_SMITH, wo);
    double v = wenv_lobe_vis(shape, WENV_SHADOW_SMITH, wi, wo, k_o, h) * wenv_ndf_tan2(1, shape->alpha, h.tan2);
    double f[3];
    lobe_fresnel(p, &p->lobe[i], h.cos_d, f);
    for (int k = 0; k < 3; k++)
        rgb[k] = vw->lobe[i][k] * f[k] * v;
}

static void pr_lobe_value(const wenv_material *mat, size_t i, const double wi[3], const double wo[3], double rgb[3])
{
    rgb[0] = rgb[1] = rgb[2] = 0.0;
    if (!(wi[2] > 0.0) || !(wo[2] > 0.0))
        return;
    view_weights vw;
    weights_for_view(model_of(mat), wo[2], &vw);
    lobe_f(model_of(mat), &mat->lobes[i], i, &vw, wi, wo, rgb);
}

static void pr_specular_cos_batch(const wenv_material *mat, const double wo[3], const float *wi, size_t n,
                                  float *rgb_out)
{
    memset(rgb_out, 0, n * 3 * sizeof *rgb_out);
    const principled *p = model_of(mat);
    if (!(wo[2] > 0.0) || p->n == 0)
        return;
    view_weights vw;
    weights_for_view(p, wo[2], &vw);
    for (size_t q = 0; q < n; q++) {
        double d[3] = {wi[3 * q], wi[3 * q + 1], wi[3 * q + 2]}, acc[3] = {0.0, 0.0, 0.0};
        if (!(d[2] > 0.0))
            continue;
        for (size_t i = 0; i < p->n; i++) {
            double v[3];
            lobe_f(p, &mat->lobes[i], i, &vw, d, wo, v);
            for (int k = 0; k < 3; k++)
                acc[k] += v[k] * d[2];
        }
        for (int k = 0; k < 3; k++)
            rgb_out[3 * q + (size_t)k] = (float)acc[k];
    }
}

/* The float path: the view's weights and Smith K per lobe are its terms (4 a lobe), then the sheen's
A and B and the Oren-Nayar diffuse's multiple scattering (3); the rest in float. */
static size_t pr_view_terms(const wenv_material *mat) { return 4 * model_of(mat)->n + 5; }

static void pr_prepare_view_f(const wenv_material *mat, const float wo[3], float *terms)
{
    const principled *p = model_of(mat);
    view_weights vw;
    weights_for_view(p, wo[2], &vw);
    double wod[3] = {wo[0], wo[1], wo[2]};
    for (size_t i = 0; i < p->n; i++) {
        for (int k = 0; k < 3; k++)
            terms[4 * i + (size_t)k] = (float)vw.lobe[i][k];
        terms[4 * i + 3] = (float)wenv_lobe_view_k(&mat->lobes[i], WENV_SHADOW_SMITH, wod);
    }
    terms[4 * p->n] = (float)vw.sheen_a;
    terms[4 * p->n + 1] = (float)vw.sheen_b;
    for (int k = 0; k < 3; k++)
        terms[4 * p->n + 2 + (size_t)k] = (float)vw.eon_ms[k];
}

/* The float path, a lobe at a time over arrays of directions (each adds to r, g, b, lobes in the
 * model's order, so every sum is the one a direction at a time would make).  The microfacet and sheen
 * loops are written for the vectoriser: always inlined with the role constant, arrays restrict, the
 * view copied (as cook_torrance.c's), a light below the horizon computed at a stand-in and its value
 * selected away. */
typedef struct {
    const principled *p;
    const float *terms; /* pr_prepare_view_f's */
    float wo[3], co;
    size_t n;
} pr_lanes;

/* The Oren-Nayar diffuse lobe i, as lobe_f in float but for E (a library acos: left scalar). */
static void diffuse_lanes(const pr_lanes *a, size_t i, const float *x, const float *y, const float *z, float *r,
                          float *g, float *b)
{
    const principled *p = a->p;
    const float *terms = a->terms, *wo = a->wo;
    float co = a->co, *out[3] = {r, g, b};
    for (size_t k = 0; k < a->n; k++) {
        float ci = z[k];
        if (!(ci > 0.0f))
            continue;
        float t = x[k] * wo[0] + y[k] * wo[1];
        if (t > 0.0f)
            t /= (ci > co ? ci : co) + FLT_MIN;
        float single = (float)p->eon_a + (float)p->eon_b * t, loss = (float)(1.0 - eon_e(p, ci));
        for (int c = 0; c < 3; c++)
            out[c][k] += terms[4 * i + (size_t)c] * (single + terms[4 * p->n + 2 + (size_t)c] * loss) * ci;
    }
}

static inline __attribute__((always_inline)) void sheen_lanes(const pr_lanes *a, size_t i, const float *restrict x,
                                                              const float *restrict y, const float *restrict z,
                                                              float *restrict r, float *restrict g, float *restrict b)
{
    const principled *p = a->p;
    const float *terms = a->terms;
    float so = sqrtf(a->wo[0] * a->wo[0] + a->wo[1] * a->wo[1]);
    float tx = so > 1e-6f ? a->wo[0] / so : 1.0f, ty = so > 1e-6f ? a->wo[1] / so : 0.0f;
    float sa = terms[4 * p->n], sb = terms[4 * p->n + 1];
    float w0 = terms[4 * i], w1 = terms[4 * i + 1], w2 = terms[4 * i + 2];
    for (size_t k = 0; k < a->n; k++) {
        float ci = z[k] > 0.0f ? z[k] : 1.0f;
        float ox = tx * x[k] + ty * y[k], oy = -ty * x[k] + tx * y[k];
        float len2s = (sa * ox + sb * ci) * (sa * ox + sb * ci) + (sa * oy) * (sa * oy) + ci * ci, q = sa / len2s;
        float v0 = w0 * q * q * (float)WENV_INV_PI * ci, v1 = w1 * q * q * (float)WENV_INV_PI * ci;
        float v2 = w2 * q * q * (float)WENV_INV_PI * ci;
        int above = z[k] > 0.0f;
        r[k] += above ? v0 : 0.0f;
        g[k] += above ? v1 : 0.0f;
        b[k] += above ? v2 : 0.0f;
    }
}

/* A GGX lobe with Smith's visibility and the role's Fresnel (role constant where inlined). */
static inline __attribute__((always_inline)) void ggx_lanes(const pr_lanes *a, size_t i, const lobe_role role, float m,
                                                            const float *restrict x, const float *restrict y,
                                                            const float *restrict z, float *restrict r,
                                                            float *restrict g, float *restrict b)
{
    const principled *p = a->p;
    const float wo[3] = {a->wo[0], a->wo[1], a->wo[2]};
    float co = a->co, ko = a->terms[4 * i + 3];
    float w0 = a->terms[4 * i], w1 = a->terms[4 * i + 1], w2 = a->terms[4 * i + 2];
    for (size_t k = 0; k < a->n; k++) {
        float wi[3] = {x[k], y[k], z[k] > 0.0f ? z[k] : 1.0f}, ci = wi[2];
        wenv_half_vector_f h = wenv_half_vector_of_f(wi, wo);
        float si = sqrtf(wi[0] * wi[0] + wi[1] * wi[1]);
        float vis = wenv_vis_smith_f(ci, co, wenv_smith_k_f(1, m, ci, si), ko);
        float d = wenv_ndf_tan2_f(1, m, h.tan2);
        double f[3];
        role_fresnel(p, role, h.cos_d, f);
        int above = z[k] > 0.0f;
        r[k] += above ? w0 * (float)f[0] * d * vis * ci : 0.0f;
        g[k] += above ? w1 * (float)f[1] * d * vis * ci : 0.0f;
        b[k] += above ? w2 * (float)f[2] * d * vis * ci : 0.0f;
    }
}

WENV_VECTOR_CLONES
static void pr_specular_cos_f_many(const wenv_material *mat, const float wo[3], const float *terms, size_t n,
                                   const float *x, const float *y, const float *z, float *r, float *g, float *b)
{
    for (size_t k = 0; k < n; k++)
        r[k] = g[k] = b[k] = 0.0f;
    if (!(wo[2] > 0.0f))
        return;
    pr_lanes a = {.p = model_of(mat), .terms = terms, .wo = {wo[0], wo[1], wo[2]}, .co = wo[2], .n = n};
    for (size_t i = 0; i < a.p->n; i++) {
        /* a lobe of no weight at this view (the metal lobe of a dielectric, the dielectric one of a
         * metal) would add zeros */
        if (terms[4 * i] == 0.0f && terms[4 * i + 1] == 0.0f && terms[4 * i + 2] == 0.0f)
            continue;
        float m = (float)mat->lobes[i].alpha;
        switch (a.p->lobe[i].role) {
        case LOBE_DIFFUSE:
            diffuse_lanes(&a, i, x, y, z, r, g, b);
            break;
        case LOBE_SHEEN:
            sheen_lanes(&a, i, x, y, z, r, g, b);
            break;
        case LOBE_COAT:
            ggx_lanes(&a, i, LOBE_COAT, m, x, y, z, r, g, b);
            break;
        case LOBE_METAL:
            ggx_lanes(&a, i, LOBE_METAL, m, x, y, z, r, g, b);
            break;
        default:
            ggx_lanes(&a, i, LOBE_SPECULAR, m, x, y, z, r, g, b);
            break;
        }
    }
}

static double pr_lobe_cos_h_min(const wenv_material *mat, size_t i)
{
    /* the sheen (towards grazing most) and the Oren-Nayar diffuse reflect at every half vector */
    lobe_role role = model_of(mat)->lobe[i].role;
    return role == LOBE_SHEEN || role == LOBE_DIFFUSE ? -1.0 : wenv_lobe_cos_h_min(&mat->lobes[i]);
}

/* f 4 ci co / D: weight x F G2. */
static void pr_lobe_over_ndf(const wenv_material *mat, size_t i, const double wi[3], const double wo[3],
                             double rgb[3])
{
    rgb[0] = rgb[1] = rgb[2] = 0.0;
    double ci = wi[2], co = wo[2];
    double s[3] = {wi[0] + wo[0], wi[1] + wo[1], ci + co}, len = sqrt(s[0] * s[0] + s[1] * s[1] + s[2] * s[2]);
    if (!(ci > 0.0) || !(co > 0.0) || !(len > 0.0))
        return;
    const principled *p = model_of(mat);
    const wenv_lobe *shape = &mat->lobes[i];
    view_weights vw;
    weights_for_view(p, co, &vw);
    if (p->lobe[i].role == LOBE_SHEEN || p->lobe[i].role == LOBE_DIFFUSE) { /* f 4 ci co over the shape's D */
        double f[3], d = wenv_ndf(shape->distribution, shape->alpha, s[2] / len);
        lobe_f(p, shape, i, &vw, wi, wo, f);
        for (int k = 0; k < 3; k++)
            rgb[k] = d > 0.0 ? f[k] * 4.0 * ci * co / d : 0.0;
        return;
    }
    wenv_half_vector h = wenv_half_vector_of(wi, wo);
    double g = 4.0 * ci * co * wenv_lobe_vis(shape, WENV_SHADOW_SMITH, wi, wo, wenv_lobe_view_k(shape, WENV_SHADOW_SMITH, wo), h);
    double f[3];
    lobe_fresnel(p, &p->lobe[i], h.cos_d, f);
    for (int k = 0; k < 3; k++)
        rgb[k] = vw.lobe[i][k] * f[k] * g;
}

/* ---------------------------------------------------------------- integrals */

/* The shape's rules (GGX, Smith, dielectric Fresnel of the shape's index) re-weighted node by node to
 * the lobe (wenv_material_reweight_nodes), with the view's weights made once rather than per node:
 * for a GGX lobe D and G2 are the same and the ratio is its weight and Fresnel over the shape's
 * Fresnel, smooth across the rule; the sheen's broad GGX shape (alpha 1) is positive everywhere its
 * lobe is. */
typedef struct {
    const principled *p;
    const wenv_lobe *shape;
    size_t i;
    const double *wo;
    view_weights vw;
} lobe_at_view;

static void value_at(const void *ctx, const double wi[3], double rgb[3])
{
    const lobe_at_view *c = ctx;
    lobe_f(c->p, c->shape, c->i, &c->vw, wi, c->wo, rgb);
}

static void reweight(const wenv_material *mat, size_t i, const double wo[3], const double *wi, double *weight,
                     size_t count)
{
    lobe_at_view ctx = {.p = model_of(mat), .shape = &mat->lobes[i], .i = i, .wo = wo};
    weights_for_view(ctx.p, wo[2], &ctx.vw);
    lobe_role role = ctx.p->lobe[i].role;
    if (role == LOBE_SHEEN || role == LOBE_DIFFUSE || mat->shadowing != WENV_SHADOW_SMITH ||
        ctx.shape->distribution != WENV_NDF_GGX) {
        wenv_material_reweight_nodes(mat, i, wo, wi, weight, count, value_at, &ctx);
        return;
    }
    /* the ratio with D and G2 cancelled, which the generic path evaluates twice at every node */
    for (size_t q = count; q-- > 0;) { /* from the back: weight[q] becomes weight[3q..3q+2] */
        const double *d = wi + 3 * q;
        double w = weight[q], f[3] = {0.0, 0.0, 0.0}, fs = 0.0;
        if (d[2] > 0.0 && wo[2] > 0.0) {
            wenv_half_vector h = wenv_half_vector_of(d, wo);
            if (wenv_ndf_tan2(1, ctx.shape->alpha, h.tan2) > 0.0)
                fs = wenv_fresnel_dielectric(h.cos_d, ctx.shape->ior);
            if (fs > 0.0)
                role_fresnel(ctx.p, role, h.cos_d, f);
        }
        for (int k = 2; k >= 0; k--)
            weight[3 * q + (size_t)k] = fs > 0.0 ? w * ctx.vw.lobe[i][k] * f[k] / fs : 0.0;
    }
}

static wenv_status pr_lobe_nodes(const wenv_material *mat, size_t i, const double wo[3], size_t samples, double *wi,
                                 double *weight, size_t *count, wenv_error *err)
{
    if (wenv_lobe_nodes(&mat->lobes[i], WENV_SHADOW_SMITH, wo, samples, wi, weight, count, err))
        return err->status;
    reweight(mat, i, wo, wi, weight, *count);
    return WENV_OK;
}

static wenv_status pr_lobe_cells(const wenv_material *mat, size_t i, const double wo[3], size_t n_theta,
                                 size_t n_phi, double *wi, double *weight, double *solid_angle, size_t *count,
                                 wenv_error *err)
{
    if (wenv_lobe_cells(&mat->lobes[i], WENV_SHADOW_SMITH, wo, n_theta, n_phi, wi, weight, solid_angle, count, err))
        return err->status;
    reweight(mat, i, wo, wi, weight, *count);
    return WENV_OK;
}

static void pr_diffuse_at(const wenv_material *mat, double cos_v, double rgb[3])
{
    view_weights vw;
    weights_for_view(model_of(mat), cos_v, &vw);
    memcpy(rgb, vw.diffuse, 3 * sizeof *rgb);
}

/* Base Color is in the Lambertian part alone (W(mu) of it) unless a metal's Fresnel or the rough
 * diffuse lobe holds it too. */
static void pr_emission_at(const wenv_material *mat, double cos_v, double rgb[3])
{
    view_weights vw;
    weights_for_view(model_of(mat), cos_v, &vw);
    for (int k = 0; k < 3; k++)
        rgb[k] = vw.emission[k];
}

static int pr_emits(const wenv_material *mat)
{
    const wenv_principled_inputs *in = &model_of(mat)->in;
    return in->emission_strength != 0.0 &&
           (in->emission_color[0] != 0.0 || in->emission_color[1] != 0.0 || in->emission_color[2] != 0.0);
}

static const char *pr_diffuse_per_colour(const wenv_material *mat, double cos_v, double rgb[3])
{
    const principled *p = model_of(mat);
    for (size_t i = 0; i < p->n; i++) {
        if (p->lobe[i].role == LOBE_METAL)
            return "a Principled BSDF's Base Color is also a metal's Fresnel colour (Metallic > 0)";
        if (p->lobe[i].role == LOBE_DIFFUSE)
            return "a Principled BSDF's Base Color is also its rough diffuse lobe's (Diffuse Roughness > 0)";
    }
    view_weights vw;
    weights_for_view(p, cos_v, &vw);
    memcpy(rgb, vw.diffuse_per_colour, 3 * sizeof *rgb);
    return NULL;
}

/* The node's Roughness (Blender's, alpha = roughness^2) set to `roughness`, clamped to [0, 1] as Cycles
 * clamps it; the coat keeps its own.  What the glossmeter's fit varies. */
static wenv_status pr_with_roughness(wenv_material **out, const wenv_material *src, double roughness, wenv_error *err)
{
    wenv_principled_inputs in = model_of(src)->in;
    in.roughness = roughness;
    return wenv_principled_create(out, &in, err);
}

/* The sheen and the rough diffuse borrow a GGX shape they do not follow. */
static int pr_lobes_follow_shapes(const wenv_material *mat)
{
    const principled *p = model_of(mat);
    for (size_t i = 0; i < p->n; i++)
        if (p->lobe[i].role == LOBE_SHEEN || p->lobe[i].role == LOBE_DIFFUSE)
            return 0;
    return 1;
}

static const wenv_material_kind PRINCIPLED = {
    .name = "principled",
    .mirror_symmetric = 1, /* shaded isotropic (anisotropy is unhonoured): functions of dot products */
    .smooth_limit = 0, /* an F82 metal or a remapped dielectric is no Fresnel mirror of one index */
    .lobe_value = pr_lobe_value,
    /* accelerators: the layers' weights for a view made once per batch or rule, not per direction */
    .specular_cos_batch = pr_specular_cos_batch,
    .view_terms = pr_view_terms,
    .prepare_view_f = pr_prepare_view_f,
    .specular_cos_f_many = pr_specular_cos_f_many,
    .lobe_over_ndf = pr_lobe_over_ndf,
    .lobe_nodes = pr_lobe_nodes,
    .lobe_cells = pr_lobe_cells,
    .lobe_cos_h_min = pr_lobe_cos_h_min,
    .diffuse_at = pr_diffuse_at,
    .diffuse_per_colour = pr_diffuse_per_colour,
    .emits = pr_emits,
    .emission_at = pr_emission_at,
    .with_roughness = pr_with_roughness,
    .lobes_follow_shapes = pr_lobes_follow_shapes,
};

/* ---------------------------------------------------------------- making one */

void wenv_principled_defaults(wenv_principled_inputs *in)
{
    memset(in, 0, sizeof *in);
    for (size_t r = 0; r < wenv_principled_input_count; r++) {
        const wenv_principled_input *row = &wenv_principled_input_list[r];
        memcpy(wenv_principled_field(in, row), row->fallback, (size_t)row->n * sizeof(double));
    }
    in->multiscatter = 1; /* the node's default distribution, Multiscatter GGX */
}

/* Every input finite, and those that scale the reflection at most WENV_PRINCIPLED_SCALE_MAX; the
 * error names the first that is not. */
static wenv_status check_inputs(const wenv_principled_inputs *in, wenv_error *err)
{
    for (size_t r = 0; r < wenv_principled_input_count; r++) {
        const wenv_principled_input *row = &wenv_principled_input_list[r];
        const double *v = wenv_principled_field_c(in, row);
        for (int k = 0; k < row->n; k++) {
            if (!isfinite(v[k]))
                return wenv_error_set(err, WENV_ERR_VALUE, "%s must be finite, got %g", row->name, v[k]);
            if (row->scales && v[k] > WENV_PRINCIPLED_SCALE_MAX)
                return wenv_error_set(err, WENV_ERR_VALUE, "%s must be at most %g, got %g", row->name,
                                      WENV_PRINCIPLED_SCALE_MAX, v[k]);
        }
    }
    return WENV_OK;
}

/* The inputs clamped as Cycles' kernel clamps them (svm/closure.h). */
static void clamp_inputs(wenv_principled_inputs *in)
{
    for (size_t r = 0; r < wenv_principled_input_count; r++) {
        const wenv_principled_input *row = &wenv_principled_input_list[r];
        double *v = wenv_principled_field(in, row);
        for (int k = 0; k < row->n; k++)
            v[k] = fmin(fmax(v[k], row->lo), row->hi);
    }
}

/* A GGX lobe's model and shape; the shape's index only places the rules' Fresnel, the lobe's own
 * Fresnel comes from the model. */
static void add_lobe(principled *p, wenv_lobe *shapes, lobe_role role, double roughness, int compensate,
                     const double colour[3])
{
    lobe_model *l = &p->lobe[p->n];
    l->role = role;
    l->alpha = wenv_alpha_from_roughness(roughness);
    l->rough = sqrt(l->alpha);
    l->compensate = compensate;
    shapes[p->n] = (wenv_lobe){.specular = {colour[0], colour[1], colour[2]}, .alpha = l->alpha,
                               .ior = 1.5, .distribution = WENV_NDF_GGX};
    p->n++;
}

/* The inputs field by field (the struct's padding is not data). */
static uint64_t inputs_fingerprint(const wenv_principled_inputs *in)
{
    uint64_t h = WENV_FINGERPRINT_START;
    for (size_t r = 0; r < wenv_principled_input_count; r++) {
        const wenv_principled_input *row = &wenv_principled_input_list[r];
        h = wenv_fingerprint_doubles(h, wenv_principled_field_c(in, row), (size_t)row->n);
    }
    return wenv_fingerprint_word(wenv_fingerprint_word(h, (uint64_t)in->multiscatter), (uint64_t)in->oren_nayar_classic);
}

wenv_status wenv_principled_create(wenv_material **out, const wenv_principled_inputs *inputs, wenv_error *err)
{
    *out = NULL;
    if (check_inputs(inputs, err))
        return err->status;
    principled *p = calloc(1, sizeof *p);
    if (!p)
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for a Principled material");
    atomic_init(&p->shared.refs, 1);
    p->shared.destroy = model_destroy;
    p->in = *inputs;
    clamp_inputs(&p->in);
    const wenv_principled_inputs *in = &p->in;
    p->shared.fingerprint = inputs_fingerprint(in);
    for (int k = 0; k < 3; k++)
        p->base[k] = fmin(in->base_color[k], 1.0);
    wenv_lobe shapes[MAX_LOBES];

    if (in->sheen_weight > WENV_PRINCIPLED_WEIGHT_CUTOFF) {
        /* the table is read at the Sheen Roughness (clamped as Cycles does); the shape only places
         * the rules' nodes: a broad GGX */
        lobe_model *l = &p->lobe[p->n];
        l->role = LOBE_SHEEN;
        l->rough = fmin(fmax(in->sheen_roughness, 1e-3), 1.0);
        l->alpha = 1.0;
        shapes[p->n] = (wenv_lobe){.specular = {in->sheen_tint[0], in->sheen_tint[1], in->sheen_tint[2]},
                                   .alpha = 1.0, .ior = 1.5, .distribution = WENV_NDF_GGX};
        p->n++;
    }

    if (in->coat_weight > WENV_PRINCIPLED_WEIGHT_CUTOFF) {
        lobe_model *l = &p->lobe[p->n];
        double one[3] = {1.0, 1.0, 1.0};
        add_lobe(p, shapes, LOBE_COAT, in->coat_roughness, 1, one);
        double fss = fresnel_dielectric_fss(in->coat_ior), f0 = f0_from_ior(in->coat_ior);
        for (int k = 0; k < 3; k++) {
            l->fss[k] = fss;
            l->f0_est[k] = f0;
        }
        l->ior_table = 1;
        l->z = sqrt(fabs((in->coat_ior - 1.0) / (in->coat_ior + 1.0)));
        shapes[p->n - 1].ior = fmin(fmax(in->coat_ior, 1.0 + 1e-4), WENV_IOR_MAX);
    }
    if (in->metallic > WENV_PRINCIPLED_WEIGHT_CUTOFF) {
        lobe_model *l = &p->lobe[p->n];
        const double f6_7 = 6.0 / 7.0, f5 = pow(f6_7, 5.0);
        int white = 1;
        for (int k = 0; k < 3; k++) {
            double tint = fmin(in->specular_tint[k], 1.0);
            white &= tint == 1.0;
            p->f0_metal[k] = p->base[k];
            p->b_metal[k] = (p->base[k] + (1.0 - p->base[k]) * f5) * (7.0 / (f5 * f6_7)) * (1.0 - tint);
        }
        for (int k = 0; k < 3; k++) {
            if (white)
                p->b_metal[k] = 0.0;
            /* the mean of F82: Int 2 mu (1 - mu)^5 = 1/21, Int 2 mu mu (1 - mu)^6 = 1/126 */
            l->fss[k] = p->f0_metal[k] + (1.0 - p->f0_metal[k]) / 21.0 - p->b_metal[k] / 126.0;
            l->f0_est[k] = p->f0_metal[k];
        }
        /* the shape's colour says what the lobe reflects: a black metal still reflects its Fresnel's
         * rim (its mean, Fss), so that what sizes and keeps lobes by it does not drop it */
        double shape_colour[3];
        for (int k = 0; k < 3; k++)
            shape_colour[k] = fmax(p->base[k], l->fss[k]);
        add_lobe(p, shapes, LOBE_METAL, in->roughness, in->multiscatter, shape_colour);
        l->ior_table = 0;
        l->z = 0.5; /* Cycles' estimate reads the Schlick table there (exponent about 5) */
    }
    /* the specular lobe's index: Specular IOR Level scales F0 by 2 level */
    p->eta = in->ior;
    double f0 = f0_from_ior(in->ior);
    if (in->specular_ior_level != 0.5) {
        f0 *= 2.0 * in->specular_ior_level;
        p->eta = ior_from_f0(f0);
        if (in->ior < 1.0)
            p->eta = 1.0 / p->eta;
    }
    if (p->eta != 1.0) {
        lobe_model *l = &p->lobe[p->n];
        for (int k = 0; k < 3; k++)
            p->f0_col[k] = clamp01(f0 * in->specular_tint[k]);
        add_lobe(p, shapes, LOBE_SPECULAR, in->roughness, in->multiscatter, p->f0_col);
        double f0_real = f0_from_ior(p->eta);
        double s = clamp01((fresnel_dielectric_fss(p->eta) - f0_real) / (1.0 - f0_real));
        for (int k = 0; k < 3; k++) {
            l->fss[k] = p->f0_col[k] + (1.0 - p->f0_col[k]) * s;
            l->f0_est[k] = p->f0_col[k];
        }
        l->ior_table = 1;
        l->z = sqrt(fabs((p->eta - 1.0) / (p->eta + 1.0)));
        shapes[p->n - 1].ior = fmin(fmax(p->eta > 1.0 ? p->eta : 1.0 / p->eta, 1.0 + 1e-4), WENV_IOR_MAX);
    }
    if (in->diffuse_roughness >= 1e-5) {
        /* Oren-Nayar instead of Lambert: its constants (the colour for its multiple scattering is Base
         * Color clamped to [0, 1]); the lobe's shape, a broad GGX, only places the rules' nodes */
        double sigma = in->diffuse_roughness;
        p->eon_a = 1.0 / (M_PI + sigma * (0.5 * M_PI - 2.0 / 3.0));
        p->eon_b = sigma * p->eon_a;
        double eavg = p->eon_a * M_PI + ((2.0 * M_PI - 5.6) / 3.0) * p->eon_b;
        for (int k = 0; k < 3; k++) {
            double rho = p->base[k];
            /* Cycles before 4.3 (bsdf_oren_nayar) has the same single scattering and no more */
            p->eon_ems[k] = in->oren_nayar_classic
                                ? 0.0
                                : rho * rho / M_PI * (eavg / (1.0 - eavg)) / (1.0 - rho * (1.0 - eavg));
        }
        lobe_model *l = &p->lobe[p->n];
        l->role = LOBE_DIFFUSE;
        l->alpha = 1.0;
        l->rough = 1.0;
        shapes[p->n] = (wenv_lobe){.specular = {p->base[0], p->base[1], p->base[2]}, .alpha = 1.0, .ior = 1.5,
                                   .distribution = WENV_NDF_GGX};
        p->n++;
    }
    /* the Lambertian part as seen head-on, for what reads one number (the view-dependent albedo is
     * wenv_material_diffuse_at); subsurface scattering shaded as diffuse */
    view_weights vw;
    weights_for_view(p, 1.0, &vw);
    double diffuse[3];
    for (int k = 0; k < 3; k++)
        diffuse[k] = fmin(vw.diffuse[k], 1.0);
    if (wenv_material_alloc(out, &PRINCIPLED, diffuse, shapes, p->n, WENV_SHADOW_SMITH, err)) {
        free(p);
        return err->status;
    }
    (*out)->shared = &p->shared;
    return WENV_OK;
}

/* The metal's Fresnel mean (Kulla & Conty's Fss) at F0 = f0 with F82 tint `tint`. */
static double metal_fss(double f0, double tint)
{
    /* per vertex and channel: (6/7)^5 multiplied out rather than a pow() call */
    const double f6_7 = 6.0 / 7.0, f5 = f6_7 * f6_7 * f6_7 * f6_7 * f6_7;
    double b = tint >= 1.0 ? 0.0 : (f0 + (1.0 - f0) * f5) * (7.0 / (f5 * f6_7)) * (1.0 - tint);
    return f0 + (1.0 - f0) / 21.0 - b / 126.0;
}

int wenv_material_metal_colour(const wenv_material *mat, double cos_v, const double colour[3], double w_black[3],
                               double w_white[3])
{
    if (mat->kind != &PRINCIPLED)
        return 0;
    const principled *p = model_of(mat);
    const lobe_model *metal = NULL;
    for (size_t i = 0; i < p->n; i++) {
        if (p->lobe[i].role == LOBE_METAL)
            metal = &p->lobe[i];
        else if (p->lobe[i].role == LOBE_SHEEN || p->lobe[i].role == LOBE_COAT)
            return 0; /* a layer over the metal takes no part in its colour */
    }
    if (!metal || p->in.metallic < 1.0)
        return 0;
    double mu = clamp01(cos_v), missing = 0.0, eavg = 1.0;
    if (metal->compensate) {
        double e = fmax(read2(wenv_ggx_E, 32, 32, metal->rough, mu), 1e-6);
        missing = (1.0 - e) / e;
        eavg = read1(wenv_ggx_Eavg, 32, metal->rough, 1);
    }
    for (int k = 0; k < 3; k++) {
        double tint = fmin(p->in.specular_tint[k], 1.0), f0 = clamp01(colour[k]);
        double c[3], at[3] = {0.0, 1.0, f0};
        for (int j = 0; j < 3; j++) { /* the compensation at F0 = 0, 1 and the colour */
            double fss = metal_fss(at[j], tint);
            c[j] = 1.0 + fss * eavg / (1.0 - fss * (1.0 - eavg)) * missing;
        }
        w_black[k] = (1.0 - f0) * c[2] / c[0];
        w_white[k] = f0 * c[2] / c[1];
    }
    return 1;
}

const wenv_principled_inputs *wenv_principled_inputs_of(const wenv_material *mat)
{
    return mat->kind == &PRINCIPLED ? &model_of(mat)->in : NULL;
}

/* Whether some channel of the row's value meets its rule. */
static int breaks_rule(const wenv_principled_input *row, const double *v)
{
    for (int k = 0; k < row->n; k++)
        if ((row->rule == WENV_ABOVE && v[k] > row->threshold) || (row->rule == WENV_BELOW && v[k] < row->threshold) ||
            (row->rule == WENV_NONZERO && fabs(v[k]) > row->threshold))
            return 1;
    return 0;
}

static const wenv_principled_input *row_named(const char *name)
{
    for (size_t r = 0; r < wenv_principled_input_count; r++)
        if (strcmp(wenv_principled_input_list[r].name, name) == 0)
            return &wenv_principled_input_list[r];
    return NULL;
}

size_t wenv_principled_unhonoured(const wenv_principled_inputs *in, const char **names, size_t max)
{
    size_t n = 0;
    for (size_t r = 0; r < wenv_principled_input_count; r++) {
        const wenv_principled_input *row = &wenv_principled_input_list[r];
        if (row->rule == WENV_NEVER || !breaks_rule(row, wenv_principled_field_c(in, row)))
            continue;
        const wenv_principled_input *partner = row->partner[0] ? row_named(row->partner) : NULL;
        if (partner) {
            const double *p = wenv_principled_field_c(in, partner);
            int present = 0;
            for (int k = 0; k < partner->n; k++)
                present |= p[k] > WENV_PRINCIPLED_WEIGHT_CUTOFF;
            if (!present)
                continue;
        }
        if (n < max)
            names[n] = row->name;
        n++;
    }
    return n;
}
