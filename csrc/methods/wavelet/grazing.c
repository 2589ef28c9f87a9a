#include "methods/wavelet/grazing.h"

#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "math/maps.h"
#include "scene/envmap_octahedral.h"

/* ---- the lighting as an octahedral mip pyramid ------------------------------------------------ */

struct wenv_grazing_light {
    wenv_oct_pyramid pyramid;
    float lod_offset; /* level = half log2 of a cell's solid angle + this */
};

void wenv_grazing_light_free(wenv_grazing_light *light)
{
    if (!light)
        return;
    wenv_oct_pyramid_free(&light->pyramid);
    free(light);
}

size_t wenv_grazing_light_bytes(const wenv_grazing_light *light)
{
    return light ? wenv_oct_pyramid_bytes(&light->pyramid) : 0;
}

wenv_status wenv_grazing_light_create(wenv_grazing_light **out, const wenv_envmap *env, const size_t *excluded,
                                      size_t n_excluded, wenv_error *err)
{
    *out = NULL;
    wenv_grazing_light *light = calloc(1, sizeof *light);
    if (!light)
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for the grazing lighting");
    if (wenv_oct_pyramid_build(&light->pyramid, env, excluded, n_excluded, 512, err)) {
        free(light);
        return err->status;
    }
    /* a base texel covers about 4 pi / base^2 */
    light->lod_offset = (float)(log2((double)light->pyramid.side[0]) - 0.5 * log2(4.0 * M_PI));
    *out = light;
    return WENV_OK;
}

static inline void level_bilinear(const wenv_grazing_light *light, size_t l, float u, float v, float w_level,
                                  const float wn[3], float acc[3])
{
    uint32_t idx[4];
    float w[4];
    wenv_oct_bilinear_f((long)light->pyramid.side[l], u, v, idx, w);
    const float *t = light->pyramid.texels[l];
    for (int k = 0; k < 4; k++) {
        const float *p = t + 3 * (size_t)idx[k];
        float s = w_level * w[k];
        acc[0] += s * wn[0] * p[0];
        acc[1] += s * wn[1] * p[1];
        acc[2] += s * wn[2] * p[2];
    }
}

/* ---- the lobes' rules over the view angle ----------------------------------------------------- */

/* Cells per lobe: N_THETA in the distribution's CDF times N_PHI on the half circle (mirrored). */
#define N_THETA 32
#define N_PHI 16
#define NODE_FLOATS 7 /* local x y z, weight r g b, half log2 of the cell's solid angle */
/* Rules tabulated at this many view angles, uniform in log cos(theta) over the range the blend
 * reaches: near the horizon the rule's azimuth map follows tan(theta), which changes by its own size
 * within a step of cos(theta). */
#define ENTRIES 128

struct wenv_grazing_rule {
    size_t n_nodes;
    float log_c_hi, dlog_c; /* entry e at log cos = log_c_hi - e dlog_c */
    float rho_scale, m_min, threshold; /* rho = rho_scale (cos_v + m_min) */
    float *nodes; /* ENTRIES x n_nodes x NODE_FLOATS */
};

void wenv_grazing_rule_free(wenv_grazing_rule *rule)
{
    if (!rule)
        return;
    free(rule->nodes);
    free(rule);
}

size_t wenv_grazing_rule_bytes(const wenv_grazing_rule *rule)
{
    return rule ? ENTRIES * rule->n_nodes * NODE_FLOATS * sizeof(float) : 0;
}

static int lobe_is_black(const wenv_lobe *lobe)
{
    return !(lobe->specular[0] > 0.0 || lobe->specular[1] > 0.0 || lobe->specular[2] > 0.0);
}

wenv_status wenv_grazing_rule_create(wenv_grazing_rule **out, const wenv_material *mat, size_t local_n,
                                     double threshold, wenv_error *err)
{
    *out = NULL;
    double m_min = wenv_material_lobe_width(mat);
    size_t lobes = 0, n_lobes = wenv_material_lobe_count(mat);
    for (size_t k = 0; k < n_lobes; k++)
        lobes += !lobe_is_black(wenv_material_lobe(mat, k));
    if (!lobes || !(threshold > 0.0))
        return WENV_OK;
    size_t per_lobe = 2 * N_THETA * N_PHI;
    wenv_grazing_rule *rule = calloc(1, sizeof *rule);
    double *wi = malloc(per_lobe * 7 * sizeof(double));
    if (!rule || !wi) {
        free(rule);
        free(wi);
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for the grazing rules");
    }
    double *weight = wi + 3 * per_lobe, *omega = weight + 3 * per_lobe;
    rule->n_nodes = lobes * per_lobe;
    rule->rho_scale = (float)(4.0 * (double)local_n * m_min / M_PI);
    rule->m_min = (float)m_min;
    rule->threshold = (float)threshold;
    /* the blend is 0 from rho = 2 threshold up */
    double c_hi = 2.0 * threshold / (double)rule->rho_scale - m_min;
    if (!(c_hi > WENV_GRAZING_Z)) { /* the local map resolves this material's lobes at every view */
        free(wi);
        wenv_grazing_rule_free(rule);
        return WENV_OK;
    }
    double log_hi = log(fmin(c_hi, 1.0)), log_lo = log(WENV_GRAZING_Z);
    rule->log_c_hi = (float)log_hi;
    rule->dlog_c = (float)((log_hi - log_lo) / (ENTRIES - 1));
    rule->nodes = malloc(ENTRIES * rule->n_nodes * NODE_FLOATS * sizeof(float));
    if (!rule->nodes) {
        free(wi);
        wenv_grazing_rule_free(rule);
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for the grazing rules");
    }
    for (size_t e = 0; e < ENTRIES; e++) {
        double c = exp(log_hi - (log_hi - log_lo) * (double)e / (ENTRIES - 1));
        double wo[3] = {sqrt(fmax(0.0, 1.0 - c * c)), 0.0, c};
        float *node = rule->nodes + e * rule->n_nodes * NODE_FLOATS;
        for (size_t k = 0; k < n_lobes; k++) {
            if (lobe_is_black(wenv_material_lobe(mat, k)))
                continue;
            size_t count;
            if (wenv_material_lobe_cells(mat, k, wo, N_THETA, N_PHI, wi, weight, omega, &count, err)) {
                free(wi);
                wenv_grazing_rule_free(rule);
                return err->status;
            }
            for (size_t i = 0; i < count; i++, node += NODE_FLOATS) {
                for (int c = 0; c < 3; c++) {
                    node[c] = (float)wi[3 * i + c];
                    node[3 + c] = (float)weight[3 * i + c];
                }
                node[6] = omega[i] > 0.0 ? (float)(0.5 * log2(omega[i])) : -64.0f;
            }
        }
    }
    free(wi);
    *out = rule;
    return WENV_OK;
}

float wenv_grazing_blend(const wenv_grazing_rule *rule, float cos_v)
{
    if (!rule)
        return 0.0f;
    float t = (2.0f * rule->threshold - rule->rho_scale * (cos_v + rule->m_min)) / rule->threshold;
    t = t < 0.0f ? 0.0f : (t > 1.0f ? 1.0f : t);
    return t * t * (3.0f - 2.0f * t);
}

void wenv_grazing_shade(const wenv_grazing_rule *rule, const wenv_grazing_light *light, const float n[3],
                        const float v[3], float cos_v, float rgb[3])
{
    rgb[0] = rgb[1] = rgb[2] = 0.0f;
    /* frame: Z the normal, X the view's direction along the surface */
    float x[3] = {v[0] - cos_v * n[0], v[1] - cos_v * n[1], v[2] - cos_v * n[2]};
    float len = sqrtf(x[0] * x[0] + x[1] * x[1] + x[2] * x[2]);
    if (len > 1e-6f) {
        for (int c = 0; c < 3; c++)
            x[c] /= len;
    } else { /* view along the normal: the lobes are isotropic, any tangent will do */
        float a[3] = {fabsf(n[0]) < 0.9f ? 1.0f : 0.0f, fabsf(n[0]) < 0.9f ? 0.0f : 1.0f, 0.0f};
        float d = a[0] * n[0] + a[1] * n[1];
        for (int c = 0; c < 3; c++)
            x[c] = a[c] - d * n[c];
        len = sqrtf(x[0] * x[0] + x[1] * x[1] + x[2] * x[2]);
        for (int c = 0; c < 3; c++)
            x[c] /= len;
    }
    float y[3] = {n[1] * x[2] - n[2] * x[1], n[2] * x[0] - n[0] * x[2], n[0] * x[1] - n[1] * x[0]};
    float pos = (rule->log_c_hi - logf(cos_v)) / rule->dlog_c;
    pos = pos < 0.0f ? 0.0f : (pos > (float)(ENTRIES - 1) ? (float)(ENTRIES - 1) : pos);
    size_t e = (size_t)pos;
    if (e > ENTRIES - 2)
        e = ENTRIES - 2;
    float f = pos - (float)e, g = 1.0f - f;
    const float *a = rule->nodes + e * rule->n_nodes * NODE_FLOATS, *b = a + rule->n_nodes * NODE_FLOATS;
    float top = (float)(light->pyramid.levels - 1), acc[3] = {0.0f, 0.0f, 0.0f};
    for (size_t k = 0; k < rule->n_nodes; k++, a += NODE_FLOATS, b += NODE_FLOATS) {
        float w[3] = {g * a[3] + f * b[3], g * a[4] + f * b[4], g * a[5] + f * b[5]};
        if (!(w[0] + w[1] + w[2] > 0.0f))
            continue;
        float lx = g * a[0] + f * b[0], ly = g * a[1] + f * b[1], lz = g * a[2] + f * b[2];
        float d[3] = {lx * x[0] + ly * y[0] + lz * n[0], lx * x[1] + ly * y[1] + lz * n[1],
                      lx * x[2] + ly * y[2] + lz * n[2]};
        float u, vv;
        wenv_oct_encode_f(d, &u, &vv);
        float lod = g * a[6] + f * b[6] + light->lod_offset;
        lod = lod < 0.0f ? 0.0f : (lod > top ? top : lod);
        size_t l0 = (size_t)lod;
        float fl = lod - (float)l0;
        level_bilinear(light, l0, u, vv, 1.0f - fl, w, acc);
        if (fl > 0.0f)
            level_bilinear(light, l0 + 1, u, vv, fl, w, acc);
    }
    memcpy(rgb, acc, sizeof acc);
}
