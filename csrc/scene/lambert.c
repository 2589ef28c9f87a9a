/* Lambertian reflection, f = albedo / pi, as a material (material.h): the Lambertian part alone. */
#include "scene/material_kind.h"

#include <string.h>

static void lambert_specular_cos(const wenv_material *mat, const double wi[3], const double wo[3], double rgb[3])
{
    (void)mat, (void)wi, (void)wo;
    rgb[0] = rgb[1] = rgb[2] = 0.0;
}

static void lambert_specular_cos_batch(const wenv_material *mat, const double wo[3], const float *wi, size_t n,
                                       float *rgb)
{
    (void)mat, (void)wo, (void)wi;
    memset(rgb, 0, n * 3 * sizeof *rgb);
}

static size_t lambert_view_terms(const wenv_material *mat)
{
    (void)mat;
    return 0;
}

static void lambert_prepare_view_f(const wenv_material *mat, const float wo[3], float *terms)
{
    (void)mat, (void)wo, (void)terms;
}

static void lambert_specular_cos_f(const wenv_material *mat, const float wi[3], const float wo[3],
                                   const float *terms, float rgb[3])
{
    (void)mat, (void)wi, (void)wo, (void)terms;
    rgb[0] = rgb[1] = rgb[2] = 0.0f;
}

/* Never called: a Lambertian material has no lobes (material.c checks the index). */
static wenv_status no_lobe(wenv_error *err)
{
    return wenv_error_set(err, WENV_ERR_VALUE, "a Lambertian material has no lobes");
}

static double lambert_lobe_cos_h_min(const wenv_material *mat, size_t i)
{
    (void)mat, (void)i;
    return -1.0;
}

static void lambert_lobe_rgb(const wenv_material *mat, size_t i, const double wi[3], const double wo[3], double rgb[3])
{
    (void)mat, (void)i, (void)wi, (void)wo;
    rgb[0] = rgb[1] = rgb[2] = 0.0;
}

static wenv_status lambert_lobe_albedo(const wenv_material *mat, size_t i, const double wo[3], size_t samples,
                                       double rgb[3], wenv_error *err)
{
    (void)mat, (void)i, (void)wo, (void)samples, (void)rgb;
    return no_lobe(err);
}

static wenv_status lambert_lobe_nodes(const wenv_material *mat, size_t i, const double wo[3], size_t samples,
                                      double *wi, double *weight, size_t *count, wenv_error *err)
{
    (void)mat, (void)i, (void)wo, (void)samples, (void)wi, (void)weight, (void)count;
    return no_lobe(err);
}

static wenv_status lambert_lobe_cells(const wenv_material *mat, size_t i, const double wo[3], size_t n_theta,
                                      size_t n_phi, double *wi, double *weight, double *solid_angle, size_t *count,
                                      wenv_error *err)
{
    (void)mat, (void)i, (void)wo, (void)n_theta, (void)n_phi, (void)wi, (void)weight, (void)solid_angle, (void)count;
    return no_lobe(err);
}

/* Nothing to set: the same material. */
static wenv_status lambert_with_roughness(wenv_material **out, const wenv_material *src, double roughness,
                                          wenv_error *err)
{
    (void)roughness;
    return wenv_material_copy(out, src, err);
}

static const wenv_material_kind LAMBERT = {
    .name = "lambert",
    .mirror_symmetric = 1,
    .smooth_limit = 1, /* no lobes: its smooth limit is itself */
    .specular_cos = lambert_specular_cos,
    .specular_cos_batch = lambert_specular_cos_batch,
    .view_terms = lambert_view_terms,
    .prepare_view_f = lambert_prepare_view_f,
    .specular_cos_f = lambert_specular_cos_f,
    .lobe_cos_h_min = lambert_lobe_cos_h_min,
    .lobe_value = lambert_lobe_rgb,
    .lobe_over_ndf = lambert_lobe_rgb,
    .lobe_albedo = lambert_lobe_albedo,
    .lobe_nodes = lambert_lobe_nodes,
    .lobe_cells = lambert_lobe_cells,
    .with_roughness = lambert_with_roughness,
};

wenv_status wenv_lambert_create(wenv_material **out, const double albedo[3], wenv_error *err)
{
    return wenv_material_alloc(out, &LAMBERT, albedo, NULL, 0, WENV_SHADOW_SMITH, err);
}
