/* The material interface (material.h): the parts every model shares, and dispatch to its kind. */
#include "scene/material_kind.h"

#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#ifndef M_PI
#define M_PI 3.14159265358979323846
#endif

#define ALBEDO_SAMPLES_MIN 8
#define ALBEDO_SAMPLES_MAX 4096

wenv_status wenv_material_alloc(wenv_material **out, const wenv_material_kind *kind, const double diffuse[3],
                                const wenv_lobe *lobes, size_t n_lobes, wenv_shadowing shadowing, wenv_error *err)
{
    *out = NULL;
    for (int c = 0; c < 3; c++) {
        if (!isfinite(diffuse[c]) || diffuse[c] < 0.0 || diffuse[c] > 1.0)
            return wenv_error_set(err, WENV_ERR_VALUE,
                                  "diffuse must be finite in [0, 1] in every channel (energy conservation), got %g",
                                  diffuse[c]);
    }
    if (shadowing != WENV_SHADOW_SMITH && shadowing != WENV_SHADOW_VCAVITY)
        return wenv_error_set(err, WENV_ERR_VALUE, "shadowing must be smith or vcavity");
    if (n_lobes > 0 && !lobes)
        return wenv_error_set(err, WENV_ERR_VALUE, "lobes is NULL but n_lobes is %zu", n_lobes);
    if (n_lobes > SIZE_MAX / sizeof(wenv_lobe))
        return wenv_error_set(err, WENV_ERR_VALUE, "too many lobes (%zu)", n_lobes);
    for (size_t i = 0; i < n_lobes; i++) {
        if (wenv_lobe_check(&lobes[i], i, err) != WENV_OK)
            return err ? err->status : WENV_ERR_VALUE;
    }
    wenv_material *mat = calloc(1, sizeof *mat);
    if (!mat)
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory allocating a material");
    if (n_lobes > 0) {
        mat->lobes = malloc(n_lobes * sizeof *mat->lobes);
        if (!mat->lobes) {
            free(mat);
            return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory allocating %zu lobes", n_lobes);
        }
        memcpy(mat->lobes, lobes, n_lobes * sizeof *mat->lobes);
    }
    mat->kind = kind;
    memcpy(mat->diffuse, diffuse, sizeof mat->diffuse);
    mat->n_lobes = n_lobes;
    mat->shadowing = shadowing;
    *out = mat;
    return WENV_OK;
}

wenv_status wenv_material_copy(wenv_material **out, const wenv_material *src, wenv_error *err)
{
    if (wenv_material_alloc(out, src->kind, src->diffuse, src->lobes, src->n_lobes, src->shadowing, err))
        return err->status;
    if (src->shared) {
        atomic_fetch_add(&src->shared->refs, 1);
        (*out)->shared = src->shared;
    }
    return WENV_OK;
}

int wenv_material_same(const wenv_material *a, const wenv_material *b)
{
    if (a->kind != b->kind || a->n_lobes != b->n_lobes || a->shadowing != b->shadowing ||
        memcmp(a->diffuse, b->diffuse, sizeof a->diffuse) != 0 || !a->shared != !b->shared)
        return 0;
    for (size_t i = 0; i < a->n_lobes; i++) {
        const wenv_lobe *x = &a->lobes[i], *y = &b->lobes[i];
        if (memcmp(x->specular, y->specular, sizeof x->specular) != 0 || x->alpha != y->alpha ||
            x->ior != y->ior || x->distribution != y->distribution)
            return 0;
    }
    return !a->shared || a->shared == b->shared || a->shared->fingerprint == b->shared->fingerprint;
}

void wenv_material_free(wenv_material *mat)
{
    if (!mat)
        return;
    if (mat->shared && atomic_fetch_sub(&mat->shared->refs, 1) == 1)
        mat->shared->destroy(mat->shared);
    free(mat->lobes);
    free(mat);
}

wenv_status wenv_material_with_alpha(wenv_material **out, const wenv_material *src, double alpha, wenv_error *err)
{
    *out = NULL;
    if (!isfinite(alpha) || alpha < WENV_ALPHA_MIN || alpha > WENV_ALPHA_MAX)
        return wenv_error_set(err, WENV_ERR_VALUE, "alpha must be finite in [%g, %g], got %g", WENV_ALPHA_MIN,
                              WENV_ALPHA_MAX, alpha);
    if (src->n_lobes > 0 && !src->kind->lobes_are_shapes)
        return wenv_error_set(err, WENV_ERR_VALUE, "a %s material's lobes are not set by alpha%s", src->kind->name,
                              src->kind->with_roughness ? ": set its roughness (Blender's)" : "");
    if (wenv_material_copy(out, src, err))
        return err->status;
    for (size_t i = 0; i < (*out)->n_lobes; i++)
        (*out)->lobes[i].alpha = alpha;
    return WENV_OK;
}

wenv_status wenv_material_with_roughness(wenv_material **out, const wenv_material *src, double roughness,
                                         wenv_error *err)
{
    *out = NULL;
    if (!isfinite(roughness) || roughness < 0.0)
        return wenv_error_set(err, WENV_ERR_VALUE, "roughness must be finite and >= 0, got %g", roughness);
    if (src->kind->with_roughness)
        return src->kind->with_roughness(out, src, roughness, err);
    if (src->n_lobes == 0) /* nothing to set: the same material */
        return wenv_material_copy(out, src, err);
    return wenv_error_set(err, WENV_ERR_VALUE, "a %s material has no roughness to set%s", src->kind->name,
                          src->kind->lobes_are_shapes ? ": its lobes are set by alpha" : "");
}

const char *wenv_material_kind_name(const wenv_material *mat) { return mat->kind->name; }
const double *wenv_material_diffuse(const wenv_material *mat) { return mat->diffuse; }
size_t wenv_material_lobe_count(const wenv_material *mat) { return mat->n_lobes; }
const wenv_lobe *wenv_material_lobe(const wenv_material *mat, size_t i) { return i < mat->n_lobes ? &mat->lobes[i] : NULL; }
int wenv_material_has_smooth_limit(const wenv_material *mat) { return mat->kind->smooth_limit; }
int wenv_material_mirror_symmetric(const wenv_material *mat) { return mat->kind->mirror_symmetric; }

int wenv_material_lobes_follow_shapes(const wenv_material *mat)
{
    return mat->kind->lobes_follow_shapes ? mat->kind->lobes_follow_shapes(mat) : mat->kind->lobes_are_shapes;
}

void wenv_material_diffuse_at(const wenv_material *mat, double cos_v, double rgb[3])
{
    if (mat->kind->diffuse_at)
        mat->kind->diffuse_at(mat, cos_v, rgb);
    else
        memcpy(rgb, mat->diffuse, 3 * sizeof *rgb);
}

void wenv_material_diffuse_table(const wenv_material *mat, wenv_diffuse_table *table)
{
    table->n = mat->kind->diffuse_at ? WENV_DIFFUSE_TABLE_N : 1;
    for (size_t i = 0; i < table->n; i++) {
        double rgb[3];
        wenv_material_diffuse_at(mat, table->n > 1 ? (double)i / (double)(table->n - 1) : 1.0, rgb);
        for (int c = 0; c < 3; c++)
            table->over_pi[3 * i + (size_t)c] = (float)(rgb[c] / M_PI);
    }
}

wenv_status wenv_material_diffuse_per_colour_at(const wenv_material *mat, double cos_v, double rgb[3],
                                                wenv_error *err)
{
    if (mat->kind->no_colour)
        return wenv_error_set(err, WENV_ERR_VALUE, "a %s material has no colour to vary per vertex",
                              mat->kind->name);
    rgb[0] = rgb[1] = rgb[2] = 1.0;
    const char *why = mat->kind->diffuse_per_colour ? mat->kind->diffuse_per_colour(mat, cos_v, rgb) : NULL;
    if (why)
        return wenv_error_set(err, WENV_ERR_VALUE, "the colour cannot vary per vertex: %s", why);
    return WENV_OK;
}

wenv_status wenv_material_diffuse_per_colour_table(const wenv_material *mat, wenv_diffuse_table *table,
                                                   wenv_error *err)
{
    table->n = mat->kind->diffuse_per_colour ? WENV_DIFFUSE_TABLE_N : 1;
    for (size_t i = 0; i < table->n; i++) {
        double rgb[3];
        if (wenv_material_diffuse_per_colour_at(mat, table->n > 1 ? (double)i / (double)(table->n - 1) : 1.0, rgb,
                                                err))
            return err->status;
        for (int c = 0; c < 3; c++)
            table->over_pi[3 * i + (size_t)c] = (float)(rgb[c] / M_PI);
    }
    return WENV_OK;
}

int wenv_diffuse_table_any(const wenv_diffuse_table *t)
{
    for (size_t k = 0; k < 3 * t->n; k++)
        if (t->over_pi[k] != 0.0f)
            return 1;
    return 0;
}

int wenv_material_mirror_centred(const wenv_material *mat)
{
    return mat->kind->mirror_centred ? mat->kind->mirror_centred(mat) : 1;
}
wenv_shadowing wenv_material_shadowing(const wenv_material *mat) { return mat->shadowing; }

int wenv_material_emits(const wenv_material *mat) { return mat->kind->emits && mat->kind->emits(mat); }

void wenv_material_emission_at(const wenv_material *mat, double cos_v, double rgb[3])
{
    rgb[0] = rgb[1] = rgb[2] = 0.0;
    if (wenv_material_emits(mat))
        mat->kind->emission_at(mat, cos_v, rgb);
}

const wenv_lobe *wenv_material_narrowest_lobe(const wenv_material *mat)
{
    const wenv_lobe *narrowest = NULL;
    for (size_t k = 0; k < mat->n_lobes; k++) {
        const wenv_lobe *lobe = &mat->lobes[k];
        if ((lobe->specular[0] > 0.0 || lobe->specular[1] > 0.0 || lobe->specular[2] > 0.0) &&
            (!narrowest || lobe->alpha < narrowest->alpha))
            narrowest = lobe;
    }
    return narrowest;
}

double wenv_material_lobe_width(const wenv_material *mat)
{
    const wenv_lobe *lobe = wenv_material_narrowest_lobe(mat);
    return lobe ? lobe->alpha : INFINITY;
}

/* ---------------------------------------------------------------- evaluation */

void wenv_material_specular_cos(const wenv_material *mat, const double wi[3], const double wo[3], double rgb[3])
{
    rgb[0] = rgb[1] = rgb[2] = 0.0;
    if (!(wi[2] > 0.0) || !(wo[2] > 0.0))
        return;
    for (size_t i = 0; i < mat->n_lobes; i++) {
        double v[3];
        mat->kind->lobe_value(mat, i, wi, wo, v);
        for (int c = 0; c < 3; c++)
            rgb[c] += v[c] * wi[2];
    }
}

void wenv_material_eval_cos(const wenv_material *mat, const double wi[3], const double wo[3], double rgb[3])
{
    wenv_material_specular_cos(mat, wi, wo, rgb);
    if (!(wi[2] > 0.0) || !(wo[2] > 0.0))
        return;
    double k = wi[2] * WENV_INV_PI;
    for (int c = 0; c < 3; c++)
        rgb[c] += mat->diffuse[c] * k;
}

void wenv_material_derived_specular_cos_batch(const wenv_material *mat, const double wo[3], const float *wi,
                                              size_t n, float *rgb)
{
    for (size_t k = 0; k < n; k++) {
        double d[3] = {wi[3 * k], wi[3 * k + 1], wi[3 * k + 2]}, v[3];
        wenv_material_specular_cos(mat, d, wo, v);
        for (int c = 0; c < 3; c++)
            rgb[3 * k + (size_t)c] = (float)v[c];
    }
}

void wenv_material_specular_cos_batch(const wenv_material *mat, const double wo[3], const float *wi, size_t n,
                                      float *rgb_out)
{
    if (mat->kind->specular_cos_batch)
        mat->kind->specular_cos_batch(mat, wo, wi, n, rgb_out);
    else
        wenv_material_derived_specular_cos_batch(mat, wo, wi, n, rgb_out);
}

size_t wenv_material_view_terms(const wenv_material *mat)
{
    return mat->kind->view_terms ? mat->kind->view_terms(mat) : 0;
}

void wenv_material_prepare_view_f(const wenv_material *mat, const float wo[3], float *terms)
{
    if (mat->kind->prepare_view_f)
        mat->kind->prepare_view_f(mat, wo, terms);
}

void wenv_material_derived_specular_cos_f_many(const wenv_material *mat, const float wo[3], size_t n,
                                               const float *x, const float *y, const float *z, float *r, float *g,
                                               float *b)
{
    double wod[3] = {wo[0], wo[1], wo[2]};
    for (size_t k = 0; k < n; k++) {
        double wi[3] = {x[k], y[k], z[k]}, v[3];
        wenv_material_specular_cos(mat, wi, wod, v);
        r[k] = (float)v[0];
        g[k] = (float)v[1];
        b[k] = (float)v[2];
    }
}

void wenv_material_specular_cos_f_many(const wenv_material *mat, const float wo[3], const float *terms, size_t n,
                                       const float *x, const float *y, const float *z, float *r, float *g, float *b)
{
    if (mat->kind->specular_cos_f_many)
        mat->kind->specular_cos_f_many(mat, wo, terms, n, x, y, z, r, g, b);
    else
        wenv_material_derived_specular_cos_f_many(mat, wo, n, x, y, z, r, g, b);
}

double wenv_material_derived_lobe_cos_h_min(const wenv_material *mat, size_t i)
{
    return wenv_material_lobes_follow_shapes(mat) ? wenv_lobe_cos_h_min(&mat->lobes[i]) : -1.0;
}

double wenv_material_lobe_cos_h_min(const wenv_material *mat, size_t i)
{
    if (i >= mat->n_lobes)
        return -1.0;
    return mat->kind->lobe_cos_h_min ? mat->kind->lobe_cos_h_min(mat, i) : wenv_material_derived_lobe_cos_h_min(mat, i);
}

void wenv_material_lobe_value(const wenv_material *mat, size_t i, const double wi[3], const double wo[3],
                              double rgb[3])
{
    rgb[0] = rgb[1] = rgb[2] = 0.0;
    if (i < mat->n_lobes)
        mat->kind->lobe_value(mat, i, wi, wo, rgb);
}

void wenv_material_derived_lobe_over_ndf(const wenv_material *mat, size_t i, const double wi[3], const double wo[3],
                                         double rgb[3])
{
    rgb[0] = rgb[1] = rgb[2] = 0.0;
    if (!(wi[2] > 0.0) || !(wo[2] > 0.0))
        return;
    double h[3] = {wi[0] + wo[0], wi[1] + wo[1], wi[2] + wo[2]};
    double len = sqrt(h[0] * h[0] + h[1] * h[1] + h[2] * h[2]);
    const wenv_lobe *shape = &mat->lobes[i];
    double d = len > 0.0 ? wenv_ndf(shape->distribution, shape->alpha, h[2] / len) : 0.0;
    if (!(d > 0.0))
        return;
    mat->kind->lobe_value(mat, i, wi, wo, rgb);
    double k = 4.0 * wi[2] * wo[2] / d;
    for (int c = 0; c < 3; c++)
        rgb[c] *= k;
}

void wenv_material_lobe_over_ndf(const wenv_material *mat, size_t i, const double wi[3], const double wo[3],
                                 double rgb[3])
{
    rgb[0] = rgb[1] = rgb[2] = 0.0;
    if (i < mat->n_lobes)
        wenv_material_lobe_over_ndf_fn(mat)(mat, i, wi, wo, rgb);
}

wenv_lobe_rgb_fn wenv_material_lobe_value_fn(const wenv_material *mat) { return mat->kind->lobe_value; }
wenv_lobe_rgb_fn wenv_material_lobe_over_ndf_fn(const wenv_material *mat)
{
    return mat->kind->lobe_over_ndf ? mat->kind->lobe_over_ndf : wenv_material_derived_lobe_over_ndf;
}

/* ---------------------------------------------------------------- rules */

void wenv_material_reweight_nodes(const wenv_material *mat, size_t i, const double wo[3], const double *wi,
                                  double *weight, size_t count, wenv_lobe_value_at_fn value, const void *ctx)
{
    const wenv_lobe *shape = &mat->lobes[i];
    double k_o = wenv_lobe_view_k(shape, mat->shadowing, wo);
    for (size_t q = count; q-- > 0;) { /* from the back: weight[q] becomes weight[3q..3q+2] */
        const double *d = wi + 3 * q;
        double f[3], w = weight[q];
        double fs = d[2] > 0.0 && wo[2] > 0.0 ? wenv_lobe_value(shape, mat->shadowing, d, wo, k_o) : 0.0;
        if (fs > 0.0)
            value(ctx, d, f);
        for (int k = 2; k >= 0; k--)
            weight[3 * q + (size_t)k] = fs > 0.0 ? w * f[k] / fs : 0.0;
    }
}

typedef struct {
    const wenv_material *mat;
    size_t i;
    const double *wo;
} lobe_at_view;

static void value_at(const void *ctx, const double wi[3], double rgb[3])
{
    const lobe_at_view *c = ctx;
    c->mat->kind->lobe_value(c->mat, c->i, wi, c->wo, rgb);
}

wenv_status wenv_material_derived_lobe_nodes(const wenv_material *mat, size_t i, const double wo[3], size_t samples,
                                             double *wi, double *weight, size_t *count, wenv_error *err)
{
    if (wenv_lobe_nodes(&mat->lobes[i], mat->shadowing, wo, samples, wi, weight, count, err))
        return err->status;
    lobe_at_view ctx = {mat, i, wo};
    wenv_material_reweight_nodes(mat, i, wo, wi, weight, *count, value_at, &ctx);
    return WENV_OK;
}

wenv_status wenv_material_derived_lobe_cells(const wenv_material *mat, size_t i, const double wo[3], size_t n_theta,
                                             size_t n_phi, double *wi, double *weight, double *solid_angle,
                                             size_t *count, wenv_error *err)
{
    if (wenv_lobe_cells(&mat->lobes[i], mat->shadowing, wo, n_theta, n_phi, wi, weight, solid_angle, count, err))
        return err->status;
    lobe_at_view ctx = {mat, i, wo};
    wenv_material_reweight_nodes(mat, i, wo, wi, weight, *count, value_at, &ctx);
    return WENV_OK;
}

wenv_status wenv_material_derived_lobe_albedo(const wenv_material *mat, size_t i, const double wo[3], size_t samples,
                                              double rgb[3], wenv_error *err)
{
    rgb[0] = rgb[1] = rgb[2] = 0.0;
    if (samples < ALBEDO_SAMPLES_MIN || samples > ALBEDO_SAMPLES_MAX)
        return wenv_error_set(err, WENV_ERR_VALUE, "samples must be in [%d, %d], got %zu", ALBEDO_SAMPLES_MIN,
                              ALBEDO_SAMPLES_MAX, samples);
    size_t max = 2 * samples * samples;
    double *wi = malloc(max * 6 * sizeof *wi);
    if (!wi)
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for a lobe's albedo");
    size_t count = 0;
    wenv_status st = mat->kind->lobe_nodes ? mat->kind->lobe_nodes(mat, i, wo, samples, wi, wi + 3 * max, &count, err)
                                           : wenv_material_derived_lobe_nodes(mat, i, wo, samples, wi, wi + 3 * max,
                                                                              &count, err);
    for (size_t q = 0; !st && q < count; q++)
        for (int k = 0; k < 3; k++)
            rgb[k] += wi[3 * max + 3 * q + (size_t)k];
    free(wi);
    return st;
}

static wenv_status check_lobe_index(const wenv_material *mat, size_t i, wenv_error *err)
{
    if (i >= mat->n_lobes)
        return wenv_error_set(err, WENV_ERR_VALUE, "lobe %zu of a material with %zu lobes", i, mat->n_lobes);
    return WENV_OK;
}

wenv_status wenv_material_lobe_albedo(const wenv_material *mat, size_t i, const double wo[3], size_t samples,
                                      double rgb[3], wenv_error *err)
{
    rgb[0] = rgb[1] = rgb[2] = 0.0;
    if (check_lobe_index(mat, i, err))
        return err->status;
    return mat->kind->lobe_albedo ? mat->kind->lobe_albedo(mat, i, wo, samples, rgb, err)
                                  : wenv_material_derived_lobe_albedo(mat, i, wo, samples, rgb, err);
}

wenv_status wenv_material_lobe_nodes(const wenv_material *mat, size_t i, const double wo[3], size_t samples,
                                     double *wi, double *weight, size_t *count, wenv_error *err)
{
    *count = 0;
    if (check_lobe_index(mat, i, err))
        return err->status;
    return mat->kind->lobe_nodes ? mat->kind->lobe_nodes(mat, i, wo, samples, wi, weight, count, err)
                                 : wenv_material_derived_lobe_nodes(mat, i, wo, samples, wi, weight, count, err);
}

wenv_status wenv_material_lobe_cells(const wenv_material *mat, size_t i, const double wo[3], size_t n_theta,
                                     size_t n_phi, double *wi, double *weight, double *solid_angle, size_t *count,
                                     wenv_error *err)
{
    *count = 0;
    if (check_lobe_index(mat, i, err))
        return err->status;
    return mat->kind->lobe_cells
               ? mat->kind->lobe_cells(mat, i, wo, n_theta, n_phi, wi, weight, solid_angle, count, err)
               : wenv_material_derived_lobe_cells(mat, i, wo, n_theta, n_phi, wi, weight, solid_angle, count, err);
}

wenv_status wenv_material_albedo(const wenv_material *mat, const double wo[3], size_t samples, double rgb[3],
                                 wenv_error *err)
{
    rgb[0] = rgb[1] = rgb[2] = 0.0;
    if (samples < ALBEDO_SAMPLES_MIN || samples > ALBEDO_SAMPLES_MAX)
        return wenv_error_set(err, WENV_ERR_VALUE, "samples must be in [%d, %d], got %zu", ALBEDO_SAMPLES_MIN,
                              ALBEDO_SAMPLES_MAX, samples);
    if (!(wo[2] > 0.0))
        return WENV_OK;
    wenv_material_diffuse_at(mat, wo[2], rgb); /* Int diffuse / pi cos_i d wi = diffuse exactly */
    for (size_t l = 0; l < mat->n_lobes; l++) {
        double a[3];
        if (wenv_material_lobe_albedo(mat, l, wo, samples, a, err))
            return err->status;
        for (int c = 0; c < 3; c++)
            rgb[c] += a[c];
    }
    return WENV_OK;
}

/* Each cell's weight is integrated on SLOPE_SUBCELLS x SLOPE_SUBCELLS cells of the same grid, finer,
 * so that the weights sum to the lobe's albedo within 0.1 % to 80 degrees (one point per cell: 0.3 %). */
#define SLOPE_SUBCELLS 4

/* A lobe part's slope grid: the material and the part, and the rows of its cells and of their
 * SLOPE_SUBCELLS finer cells, made once for the lobe's every view. */
struct wenv_lobe_slope_grid {
    const wenv_material *mat;
    size_t i;
    wenv_slope_part part;
    size_t n_y;
    wenv_lobe grid; /* the shape's, its core's, or for the tail the GGX lobe as wide as the tail's narrowest */
    wenv_slope_rows *coarse, *fine;
};

void wenv_lobe_slope_grid_free(wenv_lobe_slope_grid *g)
{
    if (!g)
        return;
    wenv_slope_rows_free(g->coarse);
    wenv_slope_rows_free(g->fine);
    free(g);
}

wenv_status wenv_lobe_slope_grid_make(const wenv_material *mat, size_t i, size_t n_y, wenv_slope_part part,
                                      wenv_lobe_slope_grid **out, wenv_error *err)
{
    *out = NULL;
    if (i >= mat->n_lobes)
        return wenv_error_set(err, WENV_ERR_VALUE, "lobe %zu of %zu", i, mat->n_lobes);
    const wenv_lobe *lobe = &mat->lobes[i];
    if (!(part.cut >= 0.0 && part.cut <= 1.0) || (part.cut > 0.0 && lobe->distribution != WENV_NDF_GGX) ||
        (part.tail && !(part.cut > 0.0)))
        return wenv_error_set(err, WENV_ERR_VALUE, "a lobe's part must cut a GGX lobe at a scale in (0, 1], got %g",
                              part.cut);
    wenv_lobe_slope_grid *g = calloc(1, sizeof *g);
    if (!g)
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for a lobe's cells");
    *g = (wenv_lobe_slope_grid){.mat = mat, .i = i, .part = part, .n_y = n_y, .grid = *lobe};
    double grid_cut = part.tail ? 0.0 : part.cut;
    if (part.tail)
        g->grid.alpha = lobe->alpha / sqrt(part.cut);
    if (wenv_slope_rows_make(&g->grid, grid_cut, n_y, &g->coarse, err) ||
        wenv_slope_rows_make(&g->grid, grid_cut, n_y * SLOPE_SUBCELLS, &g->fine, err)) {
        wenv_lobe_slope_grid_free(g);
        return err->status;
    }
    *out = g;
    return WENV_OK;
}

wenv_status wenv_lobe_slope_grid_cells(const wenv_lobe_slope_grid *g, const double wo[3], size_t n_x, double *wi,
                                       double *weight, double *size, size_t *count, wenv_error *err)
{
    const wenv_material *mat = g->mat;
    size_t i = g->i;
    wenv_slope_part part = g->part;
    const wenv_lobe *lobe = &mat->lobes[i];
    *count = 0;
    if (wenv_slope_rows_cells(g->coarse, wo, n_x, wi, weight, size, count, err))
        return err->status;
    size_t K = SLOPE_SUBCELLS, fx = n_x * K, fy = g->n_y * K, nf = fx * fy;
    double *fine = malloc(nf * 5 * sizeof *fine);
    if (!fine)
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for a lobe's cells");
    double *fwi = fine, *fmass = fine + 3 * nf, *fsize = fine + 4 * nf;
    size_t got;
    if (wenv_slope_rows_cells(g->fine, wo, fx, fwi, fmass, fsize, &got, err)) {
        free(fine);
        return err->status;
    }
    memset(weight, 0, *count * 3 * sizeof *weight);
    wenv_lobe_rgb_fn over_ndf = wenv_material_lobe_over_ndf_fn(mat);
    /* the core's grid is e^cut times its share of D: its value over that is the lobe's over D, e^-cut */
    double core_scale = part.cut > 0.0 && !part.tail ? exp(-part.cut) : 1.0;
    double a2 = lobe->alpha * lobe->alpha, t2 = g->grid.alpha * g->grid.alpha;
    /* fine row r, column c lies in coarse row r / K, column c / K: each fine row splits its own
     * range of columns into fx, so K of them make one coarse column */
    for (size_t r = 0; r < fy; r++)
        for (size_t c = 0; c < fx; c++) {
            size_t f = r * fx + c, k = (r / K) * n_x + c / K;
            if (!(fmass[f] > 0.0))
                continue;
            double rgb[3], scale = core_scale;
            over_ndf(mat, i, fwi + 3 * f, wo, rgb);
            if (part.tail) {
                /* the tail's share of the lobe, and the lobe's D over the grid's */
                double h[3];
                for (int q = 0; q < 3; q++)
                    h[q] = fwi[3 * f + (size_t)q] + wo[q];
                double tan2 = (h[0] * h[0] + h[1] * h[1]) / fmax(h[2] * h[2], DBL_MIN);
                double grid_q = t2 + tan2, lobe_q = a2 + tan2; /* GGX's D is alpha^2 / (pi cos^4 q^2) */
                scale = (1.0 - wenv_ggx_core_share(lobe->alpha, part.cut, tan2)) * (a2 * grid_q * grid_q) /
                        (t2 * lobe_q * lobe_q);
            }
            for (int q = 0; q < 3; q++)
                weight[3 * k + (size_t)q] += rgb[q] * fmass[f] * scale;
        }
    free(fine);
    return WENV_OK;
}

wenv_status wenv_material_lobe_slope_cells(const wenv_material *mat, size_t i, const double wo[3], size_t n_x,
                                           size_t n_y, wenv_slope_part part, double *wi, double *weight,
                                           double *size, size_t *count, wenv_error *err)
{
    *count = 0;
    wenv_lobe_slope_grid *g;
    if (wenv_lobe_slope_grid_make(mat, i, n_y, part, &g, err))
        return err->status;
    wenv_status st = wenv_lobe_slope_grid_cells(g, wo, n_x, wi, weight, size, count, err);
    wenv_lobe_slope_grid_free(g);
    return st;
}
