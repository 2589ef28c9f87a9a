/* Multi-lobe Cook-Torrance as a material (material.h): each lobe is scene/microfacet.h's lobe, F D G /
 * (4 cos_i cos_o) times its colour; the terms and their formulation are microfacet_terms.inc's. */
#include "math/vector_math.h"
#include "scene/material_kind.h"

#include <math.h>
#include <string.h>

/* The lobes' colours times each lobe's colourless weights, expanded in place from the back
 * (weight holds 3 count doubles; the first count are the colourless ones). */
static void colour_weights(const wenv_lobe *lobe, double *weight, size_t count)
{
    for (size_t k = count; k-- > 0;) {
        double w = weight[k];
        for (int c = 2; c >= 0; c--)
            weight[3 * k + (size_t)c] = w * lobe->specular[c];
    }
}

/* Block size of the batch path: the view term is recomputed once per block and lobe (< 1% of the
 * work at 128), which keeps the function allocation-free for any number of lobes. */
#define BATCH_BLOCK 128

static void ct_specular_cos_batch(const wenv_material *mat, const double wo[3], const float *wi, size_t n,
                                 float *rgb_out)
{
    if (!(wo[2] > 0.0) || mat->n_lobes == 0) {
        memset(rgb_out, 0, n * 3 * sizeof *rgb_out);
        return;
    }
    double acc[BATCH_BLOCK * 3];
    for (size_t start = 0; start < n; start += BATCH_BLOCK) {
        size_t count = n - start < BATCH_BLOCK ? n - start : BATCH_BLOCK;
        const float *w = wi + 3 * start;
        memset(acc, 0, count * 3 * sizeof acc[0]);
        for (size_t l = 0; l < mat->n_lobes; l++) {
            const wenv_lobe *lobe = &mat->lobes[l];
            double k_o = wenv_lobe_view_k(lobe, mat->shadowing, wo);
            double s0 = lobe->specular[0], s1 = lobe->specular[1], s2 = lobe->specular[2];
            for (size_t k = 0; k < count; k++) {
                double d[3] = {w[3 * k], w[3 * k + 1], w[3 * k + 2]};
                if (!(d[2] > 0.0))
                    continue;
                double v = wenv_lobe_value(lobe, mat->shadowing, d, wo, k_o) * d[2];
                acc[3 * k] += s0 * v;
                acc[3 * k + 1] += s1 * v;
                acc[3 * k + 2] += s2 * v;
            }
        }
        float *out = rgb_out + 3 * start;
        for (size_t k = 0; k < 3 * count; k++)
            out[k] = (float)acc[k];
    }
}

/* One lobe's f cos over arrays of directions, added to r, g, b.  Always inlined with ggx and smith
 * constant, so that the terms' branches on them fold away (GCC vectorises no loop with control flow
 * in it), and the arrays restrict rather than `omp simd`, under which GCC 12 left the loop scalar
 * (its per-lane copy of wi has no vector type). */
static inline __attribute__((always_inline)) void
ct_lobe_lanes(const wenv_lobe *lobe, const int ggx, const int smith, const float wo[3], float ko, size_t n,
              const float *restrict x, const float *restrict y, const float *restrict z, float *restrict r,
              float *restrict g, float *restrict b)
{
    /* a copy: reads through wo, which might alias the outputs, also kept the loop scalar */
    const float w_o[3] = {wo[0], wo[1], wo[2]};
    float co = w_o[2], m = (float)lobe->alpha, ior = (float)lobe->ior;
    float s0 = (float)lobe->specular[0], s1 = (float)lobe->specular[1], s2 = (float)lobe->specular[2];
    for (size_t k = 0; k < n; k++) {
        float ci = z[k];
        /* a safe stand-in where the light is below: its value is 0 */
        float wi[3] = {x[k], y[k], ci > 0.0f ? ci : 1.0f};
        wenv_half_vector_f h = wenv_half_vector_of_f(wi, w_o);
        float si = sqrtf(wi[0] * wi[0] + wi[1] * wi[1]);
        float vis = smith ? wenv_vis_smith_f(wi[2], co, wenv_smith_k_f(ggx, m, wi[2], si), ko)
                          : wenv_vis_vcavity_f(wi[2], co, h);
        float v = wenv_fresnel_dielectric_f(h.cos_d, ior) * wenv_ndf_tan2_f(ggx, m, h.tan2) * vis * ci;
        v = ci > 0.0f ? v : 0.0f;
        r[k] += s0 * v;
        g[k] += s1 * v;
        b[k] += s2 * v;
    }
}

/* The float path over arrays of directions, the lobes' parameters hoisted and every per-direction
 * step branch-free, so the loop runs 8 or 16 lanes per instruction on CPUs that have AVX2 or
 * AVX-512 (WENV_VECTOR_CLONES).  The same formulas as above, with exp and erf from
 * math/vector_math.h. */
WENV_VECTOR_CLONES
static void ct_specular_cos_f_many(const wenv_material *mat, const float wo[3], const float *k_o, size_t n,
                                   const float *x, const float *y, const float *z, float *r, float *g, float *b)
{
    for (size_t k = 0; k < n; k++)
        r[k] = g[k] = b[k] = 0.0f;
    if (!(wo[2] > 0.0f))
        return;
    int smith = mat->shadowing == WENV_SHADOW_SMITH;
    for (size_t l = 0; l < mat->n_lobes; l++) {
        const wenv_lobe *lobe = &mat->lobes[l];
        if (lobe->distribution == WENV_NDF_GGX) {
            if (smith)
                ct_lobe_lanes(lobe, 1, 1, wo, k_o[l], n, x, y, z, r, g, b);
            else
                ct_lobe_lanes(lobe, 1, 0, wo, k_o[l], n, x, y, z, r, g, b);
        } else if (smith) {
            ct_lobe_lanes(lobe, 0, 1, wo, k_o[l], n, x, y, z, r, g, b);
        } else {
            ct_lobe_lanes(lobe, 0, 0, wo, k_o[l], n, x, y, z, r, g, b);
        }
    }
}

static size_t ct_view_terms(const wenv_material *mat) { return mat->n_lobes; }

/* Per lobe, Smith's K(wo) (unused by V-cavity). */
static void ct_prepare_view_f(const wenv_material *mat, const float wo[3], float *k_o)
{
    float s = sqrtf(wo[0] * wo[0] + wo[1] * wo[1]);
    for (size_t l = 0; l < mat->n_lobes; l++)
        k_o[l] = mat->shadowing == WENV_SHADOW_SMITH
                     ? wenv_smith_k_f(mat->lobes[l].distribution == WENV_NDF_GGX, (float)mat->lobes[l].alpha,
                                      wo[2], s)
                     : 0.0f;
}

/* ---------------------------------------------------------------- one lobe */

static void ct_lobe_value(const wenv_material *mat, size_t i, const double wi[3], const double wo[3], double rgb[3])
{
    const wenv_lobe *lobe = &mat->lobes[i];
    /* wenv_lobe_eval, inline: the glossmeter calls this millions of times per reading */
    double f = wi[2] > 0.0 && wo[2] > 0.0
                   ? wenv_lobe_value(lobe, mat->shadowing, wi, wo, wenv_lobe_view_k(lobe, mat->shadowing, wo))
                   : 0.0;
    for (int c = 0; c < 3; c++)
        rgb[c] = lobe->specular[c] * f;
}

/* F G, G = 4 cos_i cos_o V from the one visibility term. */
static void ct_lobe_over_ndf(const wenv_material *mat, size_t i, const double wi[3], const double wo[3],
                             double rgb[3])
{
    rgb[0] = rgb[1] = rgb[2] = 0.0;
    if (!(wi[2] > 0.0) || !(wo[2] > 0.0))
        return;
    const wenv_lobe *lobe = &mat->lobes[i];
    wenv_half_vector h = wenv_half_vector_of(wi, wo);
    double g = 4.0 * wi[2] * wo[2] * wenv_lobe_vis(lobe, mat->shadowing, wi, wo, wenv_lobe_view_k(lobe, mat->shadowing, wo), h);
    double fg = wenv_fresnel_dielectric(h.cos_d, lobe->ior) * g;
    for (int c = 0; c < 3; c++)
        rgb[c] = lobe->specular[c] * fg;
}

/* ---------------------------------------------------------------- integrals */

static wenv_status ct_lobe_albedo(const wenv_material *mat, size_t i, const double wo[3], size_t samples,
                                  double rgb[3], wenv_error *err)
{
    double a;
    if (wenv_lobe_albedo(&mat->lobes[i], mat->shadowing, wo, samples, 1, &a, err))
        return err->status;
    for (int c = 0; c < 3; c++)
        rgb[c] = mat->lobes[i].specular[c] * a;
    return WENV_OK;
}

static wenv_status ct_lobe_nodes(const wenv_material *mat, size_t i, const double wo[3], size_t samples,
                                 double *wi, double *weight, size_t *count, wenv_error *err)
{
    if (wenv_lobe_nodes(&mat->lobes[i], mat->shadowing, wo, samples, wi, weight, count, err))
        return err->status;
    colour_weights(&mat->lobes[i], weight, *count);
    return WENV_OK;
}

static wenv_status ct_lobe_cells(const wenv_material *mat, size_t i, const double wo[3], size_t n_theta,
                                 size_t n_phi, double *wi, double *weight, double *solid_angle, size_t *count,
                                 wenv_error *err)
{
    if (wenv_lobe_cells(&mat->lobes[i], mat->shadowing, wo, n_theta, n_phi, wi, weight, solid_angle, count, err))
        return err->status;
    colour_weights(&mat->lobes[i], weight, *count);
    return WENV_OK;
}

static const wenv_material_kind COOK_TORRANCE = {
    .name = "cook_torrance",
    .mirror_symmetric = 1, /* isotropic microfacet lobes: dot products with the normal and each other */
    .smooth_limit = 1,
    .lobes_are_shapes = 1,
    .lobe_value = ct_lobe_value,
    /* accelerators: the view's terms once per batch and lobe, a vectorised float loop, and the
     * lobe's own rules (exact colour weights, no re-weighting) */
    .specular_cos_batch = ct_specular_cos_batch,
    .view_terms = ct_view_terms,
    .prepare_view_f = ct_prepare_view_f,
    .specular_cos_f_many = ct_specular_cos_f_many,
    .lobe_over_ndf = ct_lobe_over_ndf,
    .lobe_albedo = ct_lobe_albedo,
    .lobe_nodes = ct_lobe_nodes,
    .lobe_cells = ct_lobe_cells,
};

/* Mixtures fitted to measurements use a handful of lobes; each costs every method per vertex and per
 * BRDF-slice texel, and ten thousand built for minutes. */
#define LOBES_MAX 64
/* The lobes' summed albedo is checked at these view cosines, 0 to 75 degrees, by a 32 x 32 rule that
 * is within about 0.3 % of it; past ENERGY_LIMIT the lobes reflect more than they receive.  Towards
 * grazing, where Fresnel takes every lobe towards 1, lobes added rather than layered (a clear coat over
 * a paint's own gloss, as classic multi-lobe fits do) commonly pass 1; that rim is left as the model
 * gives it. */
static const double ENERGY_COS[] = {1.0, 0.8, 0.6, 0.4, 0.26};
#define ENERGY_SAMPLES 32
#define ENERGY_LIMIT 1.01

/* The Lambertian part is checked on its own (diffuse <= 1): this model adds it to the lobes, as the
 * classic Cook-Torrance does, rather than layering it under them. */
static wenv_status check_energy(const wenv_lobe *lobes, size_t n_lobes, wenv_shadowing shadowing, wenv_error *err)
{
    for (size_t v = 0; v < sizeof ENERGY_COS / sizeof *ENERGY_COS; v++) {
        double c = ENERGY_COS[v], wo[3] = {sqrt(1.0 - c * c), 0.0, c}, sum[3] = {0.0, 0.0, 0.0};
        for (size_t l = 0; l < n_lobes; l++) {
            double a;
            if (wenv_lobe_albedo(&lobes[l], shadowing, wo, ENERGY_SAMPLES, 1, &a, err))
                return err->status;
            for (int k = 0; k < 3; k++)
                sum[k] += lobes[l].specular[k] * a;
        }
        for (int k = 0; k < 3; k++)
            if (sum[k] > ENERGY_LIMIT)
                return wenv_error_set(err, WENV_ERR_VALUE,
                                      "lobes reflect %.3g times the light they receive (%s channel, view %.0f degrees "
                                      "from the normal): a material reflects at most what it receives; lower the "
                                      "lobes' specular colours",
                                      sum[k], k == 0 ? "red" : (k == 1 ? "green" : "blue"), acos(c) * 180.0 / M_PI);
    }
    return WENV_OK;
}

wenv_status wenv_cook_torrance_create(wenv_material **out, const double diffuse[3], const wenv_lobe *lobes,
                                      size_t n_lobes, wenv_shadowing shadowing, wenv_error *err)
{
    *out = NULL;
    if (n_lobes > LOBES_MAX)
        return wenv_error_set(err, WENV_ERR_VALUE, "lobes: at most %d, got %zu", LOBES_MAX, n_lobes);
    if (wenv_material_alloc(out, &COOK_TORRANCE, diffuse, lobes, n_lobes, shadowing, err))
        return err->status;
    if (check_energy(lobes, n_lobes, shadowing, err)) {
        wenv_material_free(*out);
        *out = NULL;
        return err->status;
    }
    return WENV_OK;
}
