#include "methods/wavelet/grazing.h"

#include <math.h>
#include <stdatomic.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "math/maps.h"
#include "methods/wavelet/grazing_nodes.h"
#include "scene/envmap_octahedral.h"

/* ---- the lighting as an octahedral mip pyramid ------------------------------------------------ */

struct wenv_grazing_light {
    uint16_t *halves;        /* the pyramid's texels as r g b and a pad, level after level */
    size_t bytes;
    wenv_node_pyramid nodes; /* the same, as the node loop reads it */
};

void wenv_grazing_light_free(wenv_grazing_light *light)
{
    if (!light)
        return;
    free(light->halves);
    free(light);
}

const wenv_node_pyramid *wenv_grazing_light_pyramid(const wenv_grazing_light *light) { return &light->nodes; }

size_t wenv_grazing_light_bytes(const wenv_grazing_light *light)
{
    return light ? light->bytes : 0;
}

wenv_status wenv_grazing_light_create(wenv_grazing_light **out, const wenv_envmap *env, const size_t *excluded,
                                      size_t n_excluded, size_t also_side, float *also_texels, wenv_error *err)
{
    *out = NULL;
    wenv_grazing_light *light = calloc(1, sizeof *light);
    if (!light)
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for the grazing lighting");
    wenv_oct_pyramid pyramid;
    if (wenv_oct_pyramid_build(&pyramid, env, excluded, n_excluded, 512, also_side, also_texels, err)) {
        free(light);
        return err->status;
    }
    /* a 512 base halves down to 2: 9 levels */
    if (pyramid.levels > WENV_NODE_LEVELS_MAX) {
        wenv_oct_pyramid_free(&pyramid);
        free(light);
        return wenv_error_set(err, WENV_ERR_VALUE, "the grazing lighting has %zu levels, at most %d", pyramid.levels,
                              WENV_NODE_LEVELS_MAX);
    }
    light->halves = wenv_node_pyramid_make(&light->nodes, (const float *const *)pyramid.texels, pyramid.side,
                                           pyramid.levels);
    if (!light->halves) {
        wenv_oct_pyramid_free(&pyramid);
        free(light);
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for the grazing lighting");
    }
    for (size_t k = 0; k < pyramid.levels; k++)
        light->bytes += (pyramid.side[k] + 2) * (pyramid.side[k] + 2) * 4 * sizeof(uint16_t);
    /* a base texel covers about 4 pi / base^2 */
    light->nodes.lod_offset = (float)(log2((double)pyramid.side[0]) - 0.5 * log2(4.0 * M_PI));
    wenv_oct_pyramid_free(&pyramid);
    *out = light;
    return WENV_OK;
}

/* ---- the lobes' rules over the view angle ----------------------------------------------------- */

/* Cells per lobe, for a lobe about the mirror direction: N_X along the plane of the view and the
 * normal times N_Y across it, on the slope grid (wenv_lobe_slope_cells); otherwise (a
 * retro-reflective table) the polar rule's N_THETA in the distribution's CDF times N_PHI on the half
 * circle, mirrored.
 *
 * A GGX lobe from alpha GGX_ALPHA_MIN up reaches far across the plane of the view with its heavy
 * tails, which one point per cell of GGX's grid reads badly: 16 x 6 cells left a Principled metal of
 * roughness 0.3 3.2 % off at level 5 under courtyard (1024 polar nodes: 1.1 %).  So it is cut in two
 * (wenv_slope_part): its core, the Beckmann lobes it mixes up to alpha / sqrt(GGX_CUT) wide, on
 * CORE_X x CORE_Y cells of the core's own grid, and its tail, the wider ones (9.5 % of D), on
 * TAIL_X x TAIL_Y cells of a GGX grid that wide: 2.0 % (24 x 4 and 8 x 4: 2.5 %).  Up to
 * GGX_CUT_ALPHA_MAX: a wider lobe is on the path only within a few degrees of the horizon, and the
 * Principled BSDF's sheen and rough diffuse borrow a GGX shape of alpha 1 to place nodes; those keep
 * GGX_X x GGX_Y cells of GGX's grid.  A narrower lobe (a clear coat) stretches along the plane of a
 * grazing view and keeps 24 x 4 (16 x 6 took the coated paint under forest from 8.8 to 10 %). */
#define N_X 24
#define N_Y 4
#define GGX_X 16
#define GGX_Y 6
#define CORE_X 16
#define CORE_Y 6
#define TAIL_X 8
#define TAIL_Y 4
#define GGX_CUT 0.1
#define GGX_ALPHA_MIN 0.03
#define GGX_CUT_ALPHA_MAX 0.5
/* With a GGX lobe cut in two, the path's threshold falls from `grazing` texels at the horizon to
 * (1 - FACING_CUT) of it at normal incidence: the cells read a lobe as wide as long worse than the
 * wavelet maps do once it spans some 5 texels (the metal above at views within 37 degrees of the
 * normal: 1.6 % on the path, 0.55 % on the maps), while towards grazing the path stays the better.
 * The metal at level 5 then: 1.6 %. */
#define FACING_CUT (1.0 / 3.0)
#define N_THETA 32
#define N_PHI 16
/* Per node: local x y z, weight r g b, log2 of the cell's footprint (radians); each entry holds
 * them as NODE_FLOATS arrays of n_nodes (one per field), for the vectorised loop. */
#define NODE_FLOATS 7
/* Rules tabulated at this many view angles, uniform in log cos(theta) over the range the blend
 * reaches: near the horizon the rule's azimuth map follows tan(theta), which changes by its own size
 * within a step of cos(theta). */
#define ENTRIES 128

struct wenv_grazing_rule {
    size_t n_nodes;
    float log_c_hi, dlog_c; /* entry e at log cos = log_c_hi - e dlog_c */
    float rho_scale, m_min, threshold; /* rho = rho_scale (cos_v + m_min) */
    float face; /* the threshold is threshold (1 - face cos_v) */
    size_t stride; /* n_nodes rounded up to a multiple of 16: one field's array */
    float *nodes;  /* ENTRIES x NODE_FLOATS x stride */
    wenv_grazing_nodes_fn read_nodes; /* the node loop for this CPU */
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
    return rule ? ENTRIES * rule->stride * NODE_FLOATS * sizeof(float) : 0;
}

static int lobe_is_black(const wenv_lobe *lobe)
{
    return !(lobe->specular[0] > 0.0 || lobe->specular[1] > 0.0 || lobe->specular[2] > 0.0);
}

/* Takes out the lobes whose every node weighs 0 at every view: a full Principled metal's dielectric
 * lobe, which the node loop read for nothing (half the metal's grazing path).  Each lobe's nodes are a
 * block (block[k] of them, a multiple of 16), so the lanes of the node loop sum the same nodes in the
 * same order as before. */
static void drop_weightless_lobes(wenv_grazing_rule *rule, const size_t *block, size_t n_blocks)
{
    size_t entry = rule->stride * NODE_FLOATS, kept = 0, at = 0;
    for (size_t b = 0; b < n_blocks; at += block[b++]) {
        int weighs = 0;
        for (size_t e = 0; e < ENTRIES && !weighs; e++) {
            const float *w = rule->nodes + e * entry + 3 * rule->stride;
            for (size_t k = at; k < at + block[b] && !weighs; k++)
                weighs = w[k] != 0.0f || w[rule->stride + k] != 0.0f || w[2 * rule->stride + k] != 0.0f;
        }
        if (!weighs)
            continue;
        if (kept != at)
            for (size_t e = 0; e < ENTRIES; e++)
                for (size_t f = 0; f < NODE_FLOATS; f++) {
                    float *row = rule->nodes + e * entry + f * rule->stride;
                    memmove(row + kept, row + at, block[b] * sizeof *row);
                }
        kept += block[b];
    }
    if (kept == rule->n_nodes)
        return;
    /* the entries closed up to the new stride, in place (each moves to a lower address) */
    size_t stride = (kept + 15) / 16 * 16;
    for (size_t e = 0; e < ENTRIES; e++)
        for (size_t f = 0; f < NODE_FLOATS; f++) {
            float *from = rule->nodes + e * entry + f * rule->stride, *to = rule->nodes + (e * NODE_FLOATS + f) * stride;
            memmove(to, from, kept * sizeof *to);
            memset(to + kept, 0, (stride - kept) * sizeof *to);
        }
    rule->n_nodes = kept;
    rule->stride = stride;
}

static int lobe_is_ggx(const wenv_lobe *lobe)
{
    return lobe->distribution == WENV_NDF_GGX && lobe->alpha >= GGX_ALPHA_MIN;
}

/* Whether a lobe on the slope grid is cut into a core and a tail. */
static int lobe_is_cut(const wenv_lobe *lobe)
{
    return lobe_is_ggx(lobe) && lobe->alpha <= GGX_CUT_ALPHA_MAX;
}

/* A slope rule's columns and rows for a lobe's part (0: the whole lobe or a cut lobe's core, 1: its tail). */
static size_t slope_columns(const wenv_lobe *lobe, int part)
{
    return part ? TAIL_X : lobe_is_cut(lobe) ? CORE_X : lobe_is_ggx(lobe) ? GGX_X : N_X;
}

static size_t slope_rows(const wenv_lobe *lobe, int part)
{
    return part ? TAIL_Y : lobe_is_cut(lobe) ? CORE_Y : lobe_is_ggx(lobe) ? GGX_Y : N_Y;
}

static void free_grids(wenv_lobe_slope_grid **grids, size_t n_lobes)
{
    for (size_t k = 0; grids && k < 2 * n_lobes; k++)
        wenv_lobe_slope_grid_free(grids[k]);
    free(grids);
}

wenv_status wenv_grazing_rule_create(wenv_grazing_rule **out, const wenv_material *mat, size_t local_n,
                                     double threshold, int all_slopes, wenv_error *err)
{
    *out = NULL;
    double m_min = wenv_material_lobe_width(mat);
    size_t lobes = 0, n_lobes = wenv_material_lobe_count(mat);
    for (size_t k = 0; k < n_lobes; k++)
        lobes += !lobe_is_black(wenv_material_lobe(mat, k));
    if (!lobes || !(threshold > 0.0))
        return WENV_OK;
    /* The slope grid is graded in the lobe shape's D and takes one point per cell: exact enough
     * for Beckmann lobes that follow their shape; the polar rule's 10x more nodes for the rest.
     * GGX's heavy tails, which a grazing view's reflection weighs by slope, lost 1.6 % of a
     * Cook-Torrance lobe and 10 % of a Principled metal; a table's lobe over its fitted shape's D
     * varies within the cells (courtyard, t0.1: 0.76 % against 0.58 %).  all_slopes takes GGX
     * lobes on the grid anyway, for interactive rates: a Principled paint at roughness 0.3 went from
     * ~200 to ~25 ms a view of 126k vertices, its error from 1.9 to 3.0 % (a metal's 2.8 to 6.3 %;
     * before GGX lobes were cut in two, above), and a table's lobe about the mirror direction on its
     * fitted shape's grid. */
    int slope = wenv_material_mirror_centred(mat) && (wenv_material_lobes_follow_shapes(mat) || all_slopes);
    for (size_t k = 0; k < n_lobes && !all_slopes; k++)
        if (!lobe_is_black(wenv_material_lobe(mat, k)) && wenv_material_lobe(mat, k)->distribution != WENV_NDF_BECKMANN)
            slope = 0;
    wenv_grazing_rule *rule = calloc(1, sizeof *rule);
    size_t *block = rule ? malloc(lobes * sizeof *block) : NULL;
    if (!block) {
        free(rule);
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for the grazing rules");
    }
    /* each lobe's block of nodes (weightless padding to a multiple of 16) */
    size_t n_blocks = 0, per_lobe_max = 0;
    int any_cut = 0;
    for (size_t k = 0; k < n_lobes; k++) {
        const wenv_lobe *lobe = wenv_material_lobe(mat, k);
        if (lobe_is_black(lobe))
            continue;
        size_t nodes = !slope ? 2 * N_THETA * N_PHI
                              : slope_columns(lobe, 0) * slope_rows(lobe, 0) +
                                    (lobe_is_cut(lobe) ? slope_columns(lobe, 1) * slope_rows(lobe, 1) : 0);
        any_cut |= slope && lobe_is_cut(lobe);
        block[n_blocks] = (nodes + 15) / 16 * 16;
        per_lobe_max = block[n_blocks] > per_lobe_max ? block[n_blocks] : per_lobe_max;
        rule->n_nodes += block[n_blocks++];
    }
    rule->rho_scale = (float)(4.0 * (double)local_n * m_min / M_PI);
    rule->m_min = (float)m_min;
    rule->threshold = (float)threshold;
    rule->read_nodes = wenv_grazing_nodes_for_cpu();
    double kf = any_cut ? FACING_CUT : 0.0, sc = (double)rule->rho_scale;
    rule->face = (float)kf;
    /* the blend is 0 from rho = 2 threshold (1 - kf cos) up */
    double c_hi = (2.0 * threshold - sc * m_min) / (sc + 2.0 * threshold * kf);
    if (!(c_hi > WENV_GRAZING_Z)) { /* the local map resolves this material's lobes at every view */
        free(block);
        wenv_grazing_rule_free(rule);
        return WENV_OK;
    }
    double log_hi = log(fmin(c_hi, 1.0)), log_lo = log(WENV_GRAZING_Z);
    rule->log_c_hi = (float)log_hi;
    rule->dlog_c = (float)((log_hi - log_lo) / (ENTRIES - 1));
    rule->stride = (rule->n_nodes + 15) / 16 * 16;
    /* the padding's weights are 0: it reads the lighting and adds nothing */
    rule->nodes = calloc(ENTRIES * rule->stride * NODE_FLOATS, sizeof(float));
    if (!rule->nodes) {
        free(block);
        wenv_grazing_rule_free(rule);
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for the grazing rules");
    }
    /* each slope grid's rows, which no entry's view changes, made once (2 parts a lobe at most) */
    wenv_lobe_slope_grid **grids = slope ? calloc(2 * n_lobes, sizeof *grids) : NULL;
    if (slope && !grids) {
        free(block);
        wenv_grazing_rule_free(rule);
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for the grazing rules");
    }
    for (size_t k = 0; slope && k < n_lobes; k++) {
        const wenv_lobe *lobe = wenv_material_lobe(mat, k);
        int cut = lobe_is_cut(lobe);
        for (int part = 0; !lobe_is_black(lobe) && part < (cut ? 2 : 1); part++) {
            wenv_slope_part sp = {cut ? GGX_CUT : 0.0, part};
            if (wenv_lobe_slope_grid_make(mat, k, slope_rows(lobe, part), sp, &grids[2 * k + (size_t)part], err)) {
                free_grids(grids, n_lobes);
                free(block);
                wenv_grazing_rule_free(rule);
                return err->status;
            }
        }
    }
    /* the entries are independent, and a lobe's cells cost it several inverse error functions
     * each: half a material change's time on one thread */
    atomic_int failed = 0;
    wenv_error first_err = {0};
#pragma omp parallel
    {
        double *wi = malloc(per_lobe_max * 7 * sizeof(double));
        if (!wi)
            atomic_store(&failed, 1);
#pragma omp for schedule(dynamic, 4)
        for (size_t e = 0; e < ENTRIES; e++) {
            if (atomic_load(&failed))
                continue;
            double *weight = wi + 3 * per_lobe_max, *omega = weight + 3 * per_lobe_max;
            double c = exp(log_hi - (log_hi - log_lo) * (double)e / (ENTRIES - 1));
            double wo[3] = {sqrt(fmax(0.0, 1.0 - c * c)), 0.0, c};
            float *entry = rule->nodes + e * rule->stride * NODE_FLOATS;
            size_t at = 0, b = 0;
            for (size_t k = 0; k < n_lobes && !atomic_load(&failed); k++) {
                const wenv_lobe *lobe = wenv_material_lobe(mat, k);
                if (lobe_is_black(lobe))
                    continue;
                /* one lobe's parts: the whole lobe, or a GGX lobe's core and tail */
                size_t start = at;
                int cut = slope && lobe_is_cut(lobe);
                for (int part = 0; part < (cut ? 2 : 1); part++) {
                    size_t count;
                    wenv_error lobe_err = {0};
                    /* omega: each cell's footprint, radians (slope) or its solid angle (polar) */
                    const wenv_lobe_slope_grid *grid = slope ? grids[2 * k + (size_t)part] : NULL;
                    wenv_status st =
                        slope ? wenv_lobe_slope_grid_cells(grid, wo, slope_columns(lobe, part), wi, weight, omega,
                                                           &count, &lobe_err)
                              : wenv_material_lobe_cells(mat, k, wo, N_THETA, N_PHI, wi, weight, omega, &count, &lobe_err);
                    if (st) {
                        if (!atomic_exchange(&failed, 2))
                            first_err = lobe_err;
                        break;
                    }
                    for (size_t i = 0; i < count; i++, at++) {
                        for (size_t c3 = 0; c3 < 3; c3++) {
                            entry[c3 * rule->stride + at] = (float)wi[3 * i + c3];
                            entry[(3 + c3) * rule->stride + at] = (float)weight[3 * i + c3];
                        }
                        double footprint = slope ? omega[i] : sqrt(fmax(omega[i], 0.0));
                        entry[6 * rule->stride + at] = footprint > 0.0 ? (float)log2(footprint) : -64.0f;
                    }
                }
                at = start + block[b++];
            }
        }
        free(wi);
    }
    free_grids(grids, n_lobes);
    if (failed) {
        free(block);
        wenv_grazing_rule_free(rule);
        if (failed == 2) {
            *err = first_err;
            return err->status;
        }
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for the grazing rules");
    }
    drop_weightless_lobes(rule, block, n_blocks);
    free(block);
    *out = rule;
    return WENV_OK;
}

float wenv_grazing_blend(const wenv_grazing_rule *rule, float cos_v)
{
    if (!rule)
        return 0.0f;
    float th = rule->threshold * (1.0f - rule->face * cos_v);
    float t = (2.0f * th - rule->rho_scale * (cos_v + rule->m_min)) / th;
    t = t < 0.0f ? 0.0f : (t > 1.0f ? 1.0f : t);
    return t * t * (3.0f - 2.0f * t);
}

int wenv_grazing_every_view(const wenv_grazing_rule *rule)
{
    /* past normal incidence, for views a rounding above cos 1 */
    return rule && wenv_grazing_blend(rule, 1.01f) >= 1.0f;
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
    float f = pos - (float)e;
    size_t entry = rule->stride * NODE_FLOATS;
    const float *a = rule->nodes + e * entry;
    rule->read_nodes(a, a + entry, rule->stride, rule->stride, 1.0f - f, f, x, y, n, &light->nodes, rgb);
}
