#include "methods/sh/sh_shading.h"

#include <math.h>
#include <omp.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "base/clock.h"
#include "math/maps.h"
#include "math/spherical_harmonics.h"
#include "math/unit_pair.h"
#include "scene/envmap_sh.h"
#include "methods/method.h"
#include "methods/presets.h"


typedef struct {
    size_t coefficients, slice_bytes, quadrature_nodes;
    double projection_seconds, slice_seconds;
} wenv_sh_shading_stats;

typedef struct wenv_sh_shading wenv_sh_shading;

struct wenv_sh_shading {
    wenv_sh_shading_quality q;
    wenv_sh_shading_stats stats;
    size_t count;
    wenv_sh_rotation *rot;
    int have_env, have_mat;
    double *light;   /* count x 3, world frame */
    double *slices;  /* views x count x 3, local frame, view in the xz plane */
    wenv_diffuse_table diffuse; /* the Lambertian part's albedo / pi over the view's cosine */
    size_t n_lobes;
    /* Without lobes the radiance depends on the normal alone and needs no rotation: bands 0 - 2 of
     * the irradiance (nearly all of it) are evaluated per vertex in closed form, bands 3 - order,
     * small and smooth, read bilinearly from an octahedral grid of IRR_SIDE^2 normals. */
    int lambert;          /* a lighting and a lobe-less material are set */
    float low[9 * 3];     /* A_l L_lm for l <= 2, RGB */
    float *irr_map;       /* IRR_SIDE^2 x 3 (bands 3 - order), NULL at order 2 */
};

/* 128^2 texels are 1.6 degrees or less apart: bilinear reads err by under 0.3 % of band 4's share,
 * itself under a sixth of band 2's (A_4 / A_2 = 1 / 6). */
#define IRR_SIDE 128

static double max_view_theta(void) { return acos(WENV_GRAZING_Z); }

static const wenv_param PARAMS[] = {
    {"order", WENV_PARAM_SIZE, offsetof(wenv_sh_shading_quality, order)},
    {"views", WENV_PARAM_SIZE, offsetof(wenv_sh_shading_quality, views)},
};

static wenv_status check_quality(const void *quality, wenv_error *err)
{
    const wenv_sh_shading_quality *q = quality;
    if (q->order < 2 || q->order > WENV_SH_ORDER_MAX)
        return wenv_error_set(err, WENV_ERR_VALUE, "quality['order'] must be in [2, %d], got %zu", WENV_SH_ORDER_MAX,
                              q->order);
    if (q->views < 2 || q->views > 1024)
        return wenv_error_set(err, WENV_ERR_VALUE, "quality['views'] must be in [2, 1024], got %zu", q->views);
    return WENV_OK;
}

static void destroy(void *state)
{
    wenv_sh_shading *sr = state;
    if (!sr)
        return;
    wenv_sh_rotation_free(sr->rot);
    free(sr->light);
    free(sr->slices);
    free(sr->irr_map);
    free(sr);
}

/* No matrices, so no cache and nothing to report: the work is in set_environment / set_material. */
static wenv_status create(void **state, const void *quality, const wenv_method_setup *setup, wenv_error *err)
{
    (void)setup;
    const wenv_sh_shading_quality *q = quality;
    *state = NULL;
    if (check_quality(q, err))
        return err->status;
    wenv_sh_shading *sr = calloc(1, sizeof *sr);
    if (!sr)
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for the SH shader");
    sr->q = *q;
    sr->count = wenv_sh_count(q->order);
    sr->stats.coefficients = sr->count;
    *state = sr;
    return WENV_OK;
}

/* Makes (or drops) the lobe-less path's irradiance: when the lighting is set and the material has no
 * lobes. */
static wenv_status update_irradiance_map(wenv_sh_shading *sr, wenv_error *err)
{
    sr->lambert = sr->have_env && sr->have_mat && !sr->n_lobes;
    if (!sr->lambert || sr->q.order <= 2) {
        free(sr->irr_map);
        sr->irr_map = NULL;
    }
    if (!sr->lambert)
        return WENV_OK;
    for (size_t l = 0; l <= 2; l++)
        for (size_t i = l * l; i < (l + 1) * (l + 1); i++)
            for (int c = 0; c < 3; c++)
                sr->low[3 * i + c] = (float)(wenv_sh_lambert_factor(l) * sr->light[3 * i + c]);
    if (sr->q.order <= 2)
        return WENV_OK;
    size_t n = IRR_SIDE;
    if (!sr->irr_map && !(sr->irr_map = malloc(n * n * 3 * sizeof(float))))
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for the irradiance map");
    float *map = sr->irr_map;
    const double *light = sr->light;
    size_t order = sr->q.order;
    long long total = (long long)(n * n);
#pragma omp parallel for schedule(static)
    for (long long t = 0; t < total; t++) {
        double d[3], all[3], low[3];
        wenv_oct_decode(wenv_map_texel_center(n, (size_t)t % n), wenv_map_texel_center(n, (size_t)t / n), d);
        wenv_sh_irradiance(order, light, d, all);
        wenv_sh_irradiance(2, light, d, low);
        for (int c = 0; c < 3; c++)
            map[3 * t + c] = (float)(all[c] - low[c]);
    }
    return WENV_OK;
}

static wenv_status set_environment(void *state, const wenv_envmap *env, const wenv_progress *progress,
                                          wenv_error *err)
{
    wenv_sh_shading *sr = state;
    double t0 = wenv_now_seconds();
    double *light = malloc(sr->count * 3 * sizeof(double));
    if (!light)
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for SH lighting");
    if (wenv_sh_project_envmap(env, sr->q.order, light, progress, err)) {
        free(light);
        return err->status;
    }
    free(sr->light);
    sr->light = light;
    sr->have_env = 1;
    sr->stats.projection_seconds = wenv_now_seconds() - t0;
    return update_irradiance_map(sr, err);
}

/* Nodes per dimension of each lobe's rule: enough for the lobe (the rule follows it) and for the
 * oscillation of the highest band. */
static size_t lobe_samples(size_t order)
{
    size_t s = 4 * order + 16;
    return s < 48 ? 48 : s;
}

static wenv_status set_material(void *state, const wenv_material *mat, const wenv_progress *progress,
                                       wenv_error *err)
{
    wenv_sh_shading *sr = state;
    double t0 = wenv_now_seconds();
    size_t V = sr->q.views, count = sr->count, S = lobe_samples(sr->q.order), nodes_max = 2 * S * S;
    size_t n_lobes = wenv_material_lobe_count(mat);
    double *slices = calloc(V * count * 3, sizeof(double));
    if (!slices)
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for SH BRDF slices");
    atomic_int failed = 0, cancelled = 0;
    atomic_size_t done = 0;
    size_t nodes_total = 0;
    if (n_lobes && !sr->rot && wenv_sh_rotation_create(&sr->rot, sr->q.order, err)) {
        free(slices);
        return err->status;
    }
    if (n_lobes) {
#pragma omp parallel reduction(+ : nodes_total)
        {
            double *wi = malloc(nodes_max * 3 * sizeof(double));
            double *weight = malloc(nodes_max * 3 * sizeof(double));
            double *y = malloc(count * sizeof(double));
            if (!wi || !weight || !y)
                atomic_store(&failed, 1);
#pragma omp for schedule(dynamic, 1)
            for (size_t j = 0; j < V; j++) {
                if (atomic_load(&failed) || atomic_load(&cancelled))
                    continue;
                double th = max_view_theta() * (double)j / (double)(V - 1);
                double wo[3] = {sin(th), 0.0, cos(th)};
                double *slice = slices + j * count * 3;
                for (size_t l = 0; l < n_lobes; l++) {
                    size_t nodes = 0;
                    wenv_error e = {0};
                    if (wenv_material_lobe_nodes(mat, l, wo, S, wi, weight, &nodes, &e)) {
                        atomic_store(&failed, 1);
                        break;
                    }
                    nodes_total += nodes;
                    for (size_t k = 0; k < nodes; k++) {
                        wenv_sh_eval(sr->q.order, wi + 3 * k, y);
                        for (size_t i = 0; i < count; i++) {
                            slice[3 * i] += weight[3 * k] * y[i];
                            slice[3 * i + 1] += weight[3 * k + 1] * y[i];
                            slice[3 * i + 2] += weight[3 * k + 2] * y[i];
                        }
                    }
                }
                wenv_progress_item(progress, &done, V, &cancelled);
            }
            free(wi);
            free(weight);
            free(y);
        }
    }
    if (!failed && !cancelled && wenv_progress_finish(progress))
        cancelled = 1;
    if (failed || cancelled) {
        free(slices);
        return failed ? wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for SH BRDF slices")
                      : wenv_error_set(err, WENV_ERR_CANCELLED, "SH projection of the BRDF cancelled");
    }
    free(sr->slices);
    sr->slices = slices;
    sr->n_lobes = n_lobes;
    wenv_material_diffuse_table(mat, &sr->diffuse);
    sr->have_mat = 1;
    sr->stats.slice_seconds = wenv_now_seconds() - t0;
    sr->stats.slice_bytes = V * count * 3 * sizeof(double);
    sr->stats.quadrature_nodes = nodes_total;
    return update_irradiance_map(sr, err);
}

/* A material without lobes: irradiance times albedo / pi. */
static wenv_status shade_lambert(const wenv_sh_shading *sr, const float *normals, const float *views, size_t n,
                                 float *out, float *irradiance)
{
    const float *low = sr->low, *map = sr->irr_map;
    long long nn = (long long)n;
#pragma omp parallel for schedule(dynamic, 256)
    for (long long i = 0; i < nn; i++) {
        const float *nr = normals + 3 * i, *v = views + 3 * i;
        float *o = out + 3 * i, *e_out = irradiance ? irradiance + 3 * i : NULL;
        float len = sqrtf(nr[0] * nr[0] + nr[1] * nr[1] + nr[2] * nr[2]);
        float d[3] = {nr[0] / len, nr[1] / len, nr[2] / len};
        float lv = sqrtf(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]), mu = (d[0] * v[0] + d[1] * v[1] + d[2] * v[2]) / lv;
        if (!(mu > 0.0f)) {
            o[0] = o[1] = o[2] = 0.0f;
            if (e_out)
                e_out[0] = e_out[1] = e_out[2] = 0.0f;
            continue;
        }
        float k[3];
        wenv_diffuse_table_at(&sr->diffuse, mu, k);
        float x = d[0], y = d[1], z = d[2];
        /* the real SH of bands 0 - 2 as wenv_sh_eval makes them (Condon-Shortley phase) */
        const float yb[9] = {0.28209479f, -0.48860251f * y, 0.48860251f * z, -0.48860251f * x, 1.09254843f * x * y,
                             -1.09254843f * y * z, 0.31539157f * (3.0f * z * z - 1.0f), -1.09254843f * x * z,
                             0.54627422f * (x * x - y * y)};
        float e[3] = {0.0f, 0.0f, 0.0f};
        for (int b = 0; b < 9; b++)
            for (int c = 0; c < 3; c++)
                e[c] += low[3 * b + c] * yb[b];
        if (map) {
            uint32_t idx[4];
            float u, w, wt[4];
            wenv_oct_encode_f(d, &u, &w);
            wenv_oct_bilinear_f(IRR_SIDE, u, w, idx, wt);
            for (int c = 0; c < 3; c++)
                e[c] += wt[0] * map[3 * idx[0] + c] + wt[1] * map[3 * idx[1] + c] + wt[2] * map[3 * idx[2] + c] +
                        wt[3] * map[3 * idx[3] + c];
        }
        for (int c = 0; c < 3; c++) {
            o[c] = e[c] > 0.0f && !e_out ? k[c] * e[c] : 0.0f;
            if (e_out)
                e_out[c] = e[c] > 0.0f ? e[c] : 0.0f;
        }
    }
    return WENV_OK;
}

static wenv_status shade(void *state, const float *normals, const float *views, size_t n,
                                float *out, float *irradiance, wenv_error *err)
{
    const wenv_sh_shading *sr = state;
    if (!sr->have_env || !sr->have_mat)
        return wenv_error_set(err, WENV_ERR_VALUE, "the shader needs an environment and a material");
    if (sr->lambert)
        return shade_lambert(sr, normals, views, n, out, irradiance);
    size_t L = sr->q.order, count = sr->count, V = sr->q.views;
    double view_scale = (double)(V - 1) / max_view_theta();
    atomic_int failed = 0;
    long long nn = (long long)n;
#pragma omp parallel
    {
        double *local = malloc(count * 3 * sizeof(double));
        double *work = malloc(count * 3 * sizeof(double));
        if (!local || !work)
            atomic_store(&failed, 1);
#pragma omp for schedule(dynamic, 256)
        for (long long i = 0; i < nn; i++) {
            float *o = out + 3 * i, *e_out = irradiance ? irradiance + 3 * i : NULL;
            if (atomic_load(&failed))
                continue;
            double nr[3], v[3];
            wenv_unit_pair(normals, views, (size_t)i, nr, v);
            double mu = nr[0] * v[0] + nr[1] * v[1] + nr[2] * v[2];
            if (!(mu > 0.0)) {
                o[0] = o[1] = o[2] = 0.0f;
                if (e_out)
                    e_out[0] = e_out[1] = e_out[2] = 0.0f;
                continue;
            }
            /* frame: Rz(alpha) Ry(beta) takes z to the normal; gamma turns x towards the view */
            double alpha = atan2(nr[1], nr[0]), beta = acos(fmax(-1.0, fmin(1.0, nr[2])));
            double ca = cos(alpha), sa = sin(alpha), cb = cos(beta), sb = sin(beta);
            double vx = ca * v[0] + sa * v[1], vy = -sa * v[0] + ca * v[1];
            double gamma = atan2(vy, cb * vx - sb * v[2]);
            wenv_sh_rotate_zyz(sr->rot, alpha, beta, gamma, sr->light, local, 3, work);
            double rgb[3] = {0, 0, 0}, irr[3] = {0, 0, 0};
            for (size_t l = 0; l <= L; l++) {
                double a = wenv_sh_lambert_factor(l) * sqrt((2.0 * (double)l + 1.0) / (4.0 * M_PI));
                const double *c = local + 3 * (l * l + l);
                for (int k = 0; k < 3; k++)
                    irr[k] += a * c[k];
            }
            float dk[3] = {0.0f, 0.0f, 0.0f};
            if (!e_out) /* else the Lambertian part is the caller's */
                wenv_diffuse_table_at(&sr->diffuse, (float)mu, dk);
            for (int k = 0; k < 3; k++) {
                rgb[k] = dk[k] * fmax(irr[k], 0.0);
                if (e_out)
                    e_out[k] = (float)fmax(irr[k], 0.0);
            }
            if (sr->n_lobes) {
                double x = acos(fmin(1.0, mu)) * view_scale;
                size_t j = x >= (double)(V - 1) ? V - 2 : (size_t)x;
                double f = x - (double)j;
                if (f > 1.0)
                    f = 1.0;
                const double *b0 = sr->slices + j * count * 3, *b1 = b0 + count * 3;
                /* the slices are even in y: only the m >= 0 (cosine) terms are non-zero */
                for (size_t l = 0; l <= L; l++)
                    for (size_t m = 0; m <= l; m++) {
                        size_t e = 3 * (l * l + l + m);
                        for (int k = 0; k < 3; k++)
                            rgb[k] += local[e + k] * (b0[e + k] + f * (b1[e + k] - b0[e + k]));
                    }
            }
            for (int k = 0; k < 3; k++)
                o[k] = rgb[k] > 0.0 || e_out ? (float)rgb[k] : 0.0f;
        }
        free(local);
        free(work);
    }
    if (failed)
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory shading");
    return WENV_OK;
}

static size_t stats(const void *state, wenv_stat *out)
{
    const wenv_sh_shading_stats s = ((const wenv_sh_shading *)state)->stats;
    size_t k = 0;
    out[k++] = wenv_stat_count("coefficients", s.coefficients);
    out[k++] = wenv_stat_count("slice_bytes", s.slice_bytes);
    out[k++] = wenv_stat_count("quadrature_nodes", s.quadrature_nodes);
    out[k++] = wenv_stat_real("projection_seconds", s.projection_seconds);
    out[k++] = wenv_stat_real("slice_seconds", s.slice_seconds);
    return k;
}

const wenv_method WENV_METHOD_SH = {
    .name = "sh",
    .summary = "spherical harmonics with per-vertex rotation (Kautz, Sloan and Snyder 2002), for comparison",
    .quality_size = sizeof(wenv_sh_shading_quality),
    .params = PARAMS,
    .n_params = sizeof PARAMS / sizeof PARAMS[0],
    .presets = {&WENV_SH_PRESETS[0], &WENV_SH_PRESETS[1], &WENV_SH_PRESETS[2]},
    .check_quality = check_quality,
    .create = create,
    .destroy = destroy,
    .set_environment = set_environment,
    .set_material = set_material,
    .shade = shade,
    .stats = stats,
};
