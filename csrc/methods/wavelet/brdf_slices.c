/* The wavelet shader's material side: BRDF slices (f cos integrated against each local texel's
 * tent for every view sample, Haar transformed and cut), the specular albedo table, and the cones
 * the exact lights test against. */
#include "methods/wavelet/wavelet_state.h"

#include <math.h>
#include <omp.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>

#include "math/haar.h"
#include "math/maps.h"

/* sub-samples per texel side of the rule every texel takes */
#define COARSE_K 2
/* the fine rule's reach about the mirror direction, in lobe widths: twice (reflection doubles the
 * half-vector's angle) 12 widths, where GGX keeps 1/145 of its lobe beyond and Beckmann nothing */
#define NARROW_REACH 24.0

void wenv_wavelet_material_free(wenv_wavelet_material *m)
{
    if (!m)
        return;
    wenv_material_free(m->mat);
    wenv_light_lobes_free(&m->light);
    free(m->albedo);
    free(m->view_inv_albedo);
    wenv_grazing_rule_free(m->grazing_rule);
    free(m->brdf_start);
    free(m->brdf_idx);
    free(m->brdf_rgb);
    free(m->table);
    free(m->row_ready);
    free(m->row_need);
    free(m->row_asked);
    wenv_texel_reflection_free(&m->texel_reflection);
    wenv_texel_reflection_free(&m->texel_reflection_before);
    free(m);
}

size_t wenv_wavelet_materials_kept(const wenv_wavelet *wavelet)
{
    if (!wavelet->m)
        return 1;
    size_t bytes = wenv_wavelet_material_bytes(wavelet, wavelet->m), fit = 1 + WENV_WAVELET_KEPT_BYTES / (bytes ? bytes : 1);
    return fit < WENV_WAVELET_KEPT_MATERIALS ? fit : WENV_WAVELET_KEPT_MATERIALS;
}

size_t wenv_wavelet_material_bytes(const wenv_wavelet *wavelet, const wenv_wavelet_material *m)
{
    return wenv_wavelet_table_bytes(wavelet) + m->brdf_terms * 4 * sizeof(float) +
           wavelet->nv * 3 * sizeof(float) + wenv_grazing_rule_bytes(m->grazing_rule);
}

static void texel_rule_free(wenv_texel_rule *rule)
{
    free(rule->dirs);
    free(rule->taps);
    free(rule->w);
    memset(rule, 0, sizeof *rule);
}

void wenv_wavelet_free_quadrature(wenv_wavelet *wavelet)
{
    texel_rule_free(&wavelet->quad);
    texel_rule_free(&wavelet->fine);
    texel_rule_free(&wavelet->fine_coarse);
    free(wavelet->texel_centre);
    wavelet->texel_centre = NULL;
}

/* Each texel's share of a rule's cosine weight: its sub-samples' weights times cos theta. */
static double texel_cos_weight(const wenv_texel_rule *rule, size_t t)
{
    double sum = 0.0;
    for (size_t e = t * rule->k * rule->k; e < (t + 1) * rule->k * rule->k; e++)
        for (int c = 0; c < 4; c++)
            sum += (double)rule->w[4 * e + c] * rule->dirs[3 * e + 2];
    return sum;
}

/* Sub-samples of every local texel (k x k per texel, each carrying the texel's exact solid angle
 * over k^2) with their tent taps.  Without `like`, scaled so the cosine weights sum to exactly pi:
 * then a constant environment gives exactly albedo x radiance.  With it, each texel's weights are
 * scaled to that texel's weight in `like`, so that the rules can be mixed texel by texel. */
static wenv_status texel_rule_build(wenv_texel_rule *rule, size_t L, size_t k, const wenv_texel_rule *like,
                                    wenv_error *err)
{
    size_t nl = L * L, count = nl * k * k;
    rule->dirs = malloc(count * 3 * sizeof(float));
    rule->taps = malloc(count * 4 * sizeof(uint32_t));
    rule->w = malloc(count * 4 * sizeof(float));
    if (!rule->dirs || !rule->taps || !rule->w) {
        texel_rule_free(rule);
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for the local quadrature");
    }
    rule->k = k;
    rule->count = count;
    double h = 2.0 / (double)L, total = 0.0;
    for (size_t t = 0; t < nl; t++) {
        size_t i = t % L, j = t / L;
        double omega = wenv_hemi_texel_solid_angle(L, i, j) / (double)(k * k);
        for (size_t q = 0; q < k * k; q++) {
            size_t e = t * k * k + q;
            double u = -1.0 + h * ((double)i + ((double)(q % k) + 0.5) / (double)k);
            double v = -1.0 + h * ((double)j + ((double)(q / k) + 0.5) / (double)k);
            double d[3], w[4];
            size_t idx[4];
            wenv_hemi_decode(u, v, d);
            wenv_hemi_bilinear(L, u, v, idx, w);
            for (int c = 0; c < 3; c++)
                rule->dirs[3 * e + c] = (float)d[c];
            for (int c = 0; c < 4; c++) {
                rule->taps[4 * e + c] = (uint32_t)idx[c];
                rule->w[4 * e + c] = (float)(w[c] * omega);
                total += w[c] * omega * d[2];
            }
        }
    }
    if (!like) {
        double scale = M_PI / total;
        for (size_t e = 0; e < count * 4; e++)
            rule->w[e] = (float)(rule->w[e] * scale);
        return WENV_OK;
    }
    for (size_t t = 0; t < nl; t++) {
        double mine = texel_cos_weight(rule, t), target = texel_cos_weight(like, t);
        double scale = mine > 0.0 ? target / mine : 0.0;
        for (size_t e = t * k * k * 4; e < (t + 1) * k * k * 4; e++)
            rule->w[e] = (float)(rule->w[e] * scale);
    }
    return WENV_OK;
}

/* The 2 x 2 rule and the texels' centre directions, made once per shader. */
wenv_status wenv_wavelet_build_quadrature(wenv_wavelet *wavelet, wenv_error *err)
{
    size_t L = wavelet->q.local_n, nl = wavelet->nl;
    if (texel_rule_build(&wavelet->quad, L, COARSE_K, NULL, err))
        return err->status;
    if (!(wavelet->texel_centre = malloc(nl * 3 * sizeof(float))))
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for the local quadrature");
    for (size_t t = 0; t < nl; t++) {
        double d[3];
        wenv_hemi_decode(wenv_map_texel_center(L, t % L), wenv_map_texel_center(L, t / L), d);
        for (int c = 0; c < 3; c++)
            wavelet->texel_centre[3 * t + c] = (float)d[c];
    }
    return WENV_OK;
}

/* Sub-samples per local texel side: enough to resolve the narrowest lobe (its reflected width is
 * about 1.4 m radians) with a couple of samples. */
static size_t quadrature_k(const wenv_wavelet *wavelet, const wenv_material *mat)
{
    double m = fmin(1.0, wenv_material_lobe_width(mat));
    double spacing = 2.5 / (double)wavelet->q.local_n;
    size_t k = (size_t)ceil(2.0 * spacing / (1.41 * m));
    return k < COARSE_K ? COARSE_K : (k > 16 ? 16 : k);
}

/* The finer rule a material's narrowest lobe needs, when the 2 x 2 one is too coarse for it, and
 * the 2 x 2 rule weighted like it texel by texel (so that the two mixed still sum to pi). */
static wenv_status fine_rule_for(wenv_wavelet *wavelet, const wenv_material *mat, int *fine, wenv_error *err)
{
    size_t k = quadrature_k(wavelet, mat), L = wavelet->q.local_n;
    *fine = k > COARSE_K;
    if (!*fine || k == wavelet->fine.k)
        return WENV_OK;
    texel_rule_free(&wavelet->fine);
    texel_rule_free(&wavelet->fine_coarse);
    if (texel_rule_build(&wavelet->fine, L, k, NULL, err) ||
        texel_rule_build(&wavelet->fine_coarse, L, COARSE_K, &wavelet->fine, err)) {
        texel_rule_free(&wavelet->fine);
        return err->status;
    }
    return WENV_OK;
}

/* Adds texels [t0, t1) of a rule to the slice: f cos at their sub-samples, spread by the taps, in
 * batches of at most `cap` sub-samples (fcos holds cap x 3). */
static void integrate_texels(const wenv_material *mat, const double wo[3], const wenv_texel_rule *rule, size_t t0,
                             size_t t1, float *fcos, size_t cap, float *slice)
{
    size_t per = rule->k * rule->k, step = cap / per > 0 ? cap / per : 1;
    for (size_t t = t0; t < t1; t += step) {
        size_t first = t * per, count = ((t + step < t1 ? t + step : t1) - t) * per;
        wenv_material_specular_cos_batch(mat, wo, rule->dirs + 3 * first, count, fcos);
        for (size_t e = 0; e < count; e++) {
            const float *g = fcos + 3 * e;
            for (int c = 0; c < 4; c++) {
                float w = rule->w[4 * (first + e) + c];
                float *o = slice + 3 * (size_t)rule->taps[4 * (first + e) + c];
                o[0] += w * g[0];
                o[1] += w * g[1];
                o[2] += w * g[2];
            }
        }
    }
}

/* Whether texel t's centre lies within the reach (cos_reach) of direction r; the products in an
 * order a turn or mirror of both vectors keeps, so that a slice permuted across its orbit takes the
 * fine rule on the same texels. */
static inline int texel_near(const wenv_wavelet *wavelet, size_t t, const double r[3], double cos_reach)
{
    const float *c = wavelet->texel_centre + 3 * t;
    return (c[0] * r[0] + c[1] * r[1]) + c[2] * r[2] >= cos_reach;
}

/* A view's BRDF slice (pixel domain).  A lobe narrower than the 2 x 2 rule resolves takes the fine
 * rule only on the texels within NARROW_REACH of its widths from the mirror direction (plus two
 * texels); the rest holds its tails, which 2 x 2 sub-samples weighted like the fine rule follow.
 * Reading the fine rule everywhere cost a coat or a mirror-like table 10-20x the material's time.
 * A lobe that need not lie about the mirror direction takes the fine rule everywhere. */
static void brdf_slice(const wenv_wavelet *wavelet, const wenv_material *mat, int fine, const double wo[3],
                       float *fcos, float *slice)
{
    size_t nl = wavelet->nl, cap = wavelet->quad.count;
    memset(slice, 0, nl * 3 * sizeof(float));
    if (!fine || !wenv_material_mirror_centred(mat)) {
        integrate_texels(mat, wo, fine ? &wavelet->fine : &wavelet->quad, 0, nl, fcos, cap, slice);
        return;
    }
    double reach = NARROW_REACH * wenv_material_lobe_width(mat) + 2.0 * 2.5 / (double)wavelet->q.local_n;
    double cos_reach = reach < M_PI ? cos(reach) : -1.0;
    double r[3] = {-wo[0], -wo[1], wo[2]}; /* the mirror direction */
    /* runs of texels on the same side, each integrated in one batch */
    for (size_t t = 0, end; t < nl; t = end) {
        int near = texel_near(wavelet, t, r, cos_reach);
        for (end = t + 1; end < nl && texel_near(wavelet, end, r, cos_reach) == near; end++)
            ;
        integrate_texels(mat, wo, near ? &wavelet->fine : &wavelet->fine_coarse, t, end, fcos, cap, slice);
    }
}

/* The specular lobes' directional albedo over cos(view), and its inverse at each view sample.
 *
 * Why: a table entry is the lighting seen through one view sample's BRDF slice, and near grazing
 * the slice's overall size (Fresnel, masking, 1/cos of the view) changes faster than bilinear
 * interpolation between view samples follows.  Entries are therefore kept divided by their view's
 * albedo -- a weighted mean radiance, which varies slowly -- and a vertex multiplies the
 * interpolated mean by the albedo at its own view.  A constant environment stays exact. */
static wenv_status albedo_tables(const wenv_wavelet *wavelet, wenv_wavelet_material *m, const wenv_material *mat,
                                 wenv_error *err)
{
    size_t V = wavelet->q.view_n;
    m->albedo = calloc(ALBEDO_N * 3, sizeof(float));
    m->view_inv_albedo = calloc(wavelet->nv * 3, sizeof(float));
    if (!m->albedo || !m->view_inv_albedo)
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for the material");
    atomic_int failed = 0;
#pragma omp parallel for schedule(dynamic, 4)
    for (size_t i = 0; i < ALBEDO_N; i++) {
        double c = WENV_GRAZING_Z + (1.0 - WENV_GRAZING_Z) * (double)i / (double)(ALBEDO_N - 1);
        double wo[3] = {sqrt(fmax(0.0, 1.0 - c * c)), 0.0, c};
        for (size_t l = 0; l < wenv_material_lobe_count(mat); l++) {
            double a[3];
            wenv_error lobe_err = {0};
            if (wenv_material_lobe_albedo(mat, l, wo, ALBEDO_SAMPLES, a, &lobe_err)) {
                atomic_store(&failed, 1);
                continue;
            }
            for (int k = 0; k < 3; k++)
                m->albedo[3 * i + k] += (float)a[k];
        }
    }
    if (failed)
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for the material's albedo");
    for (size_t j = 0; j < wavelet->nv; j++) {
        double wo[3];
        wenv_hemi_decode(-1.0 + 2.0 * (double)(j % (V + 1)) / (double)V, -1.0 + 2.0 * (double)(j / (V + 1)) / (double)V,
                         wo);
        float a[3];
        wenv_wavelet_albedo_at(m->albedo, (float)wo[2], a);
        for (int k = 0; k < 3; k++)
            m->view_inv_albedo[3 * j + k] = a[k] > 1e-30f ? 1.0f / a[k] : 0.0f;
    }
    return WENV_OK;
}

/* The table rows the latest shade call read under material `before` are remade at once for `m`
 * when it becomes current (as after a new lighting: shading the same view again, the usual case
 * while a material is edited, is then one pass); the rest as vertices need them. */
static void carry_used_rows(size_t ns, const wenv_wavelet_material *before, wenv_wavelet_material *m)
{
    for (size_t s = 0; before && before != m && s < ns; s++)
        m->row_need[s] |= before->row_ready[s] == USED;
}

/* Makes kept material m the current one, at the front of the kept. */
static wenv_status install(wenv_wavelet *wavelet, wenv_wavelet_material *m, wenv_error *err)
{
    size_t at = 0;
    while (wavelet->kept[at] != m)
        at++;
    carry_used_rows(wavelet->ns, wavelet->m, m);
    memmove(wavelet->kept + 1, wavelet->kept, at * sizeof *wavelet->kept);
    wavelet->kept[0] = m;
    wavelet->m = m;
    return wenv_wavelet_remake_ready(wavelet, 0, err);
}

static int compare_u32(const void *a, const void *b)
{
    uint32_t x = *(const uint32_t *)a, y = *(const uint32_t *)b;
    return (x > y) - (x < y);
}

/* The square's symmetries on an n x n grid of the local frame's hemi-octahedral square (texels,
 * n = local_n, or view-sample corners, n = views + 1): g = 4 swap + 2 (u mirrored) + (v mirrored).
 * Each is a turn or mirror of directions about the normal (hemi_decode: u and v are x + y and
 * x - y), and acts alike on both grids. */
#define SQUARE_SYMMETRIES 8

static size_t grid_image(size_t n, size_t idx, int g)
{
    size_t a = idx % n, b = idx / n;
    if (g & 4) {
        size_t t = a;
        a = b;
        b = t;
    }
    if (g & 2)
        a = n - 1 - a;
    if (g & 1)
        b = n - 1 - b;
    return b * n + a;
}

/* The first index of idx's orbit: the view sample whose slice the orbit's are permuted from. */
static size_t orbit_first(size_t n, size_t idx)
{
    size_t first = idx;
    for (int g = 1; g < SQUARE_SYMMETRIES; g++) {
        size_t j = grid_image(n, idx, g);
        first = j < first ? j : first;
    }
    return first;
}

/* A pixel-domain slice (L x L x 3, transformed in place) cut to its `keep` largest Haar
 * coefficients (RGB sharing indices), in index order into idx / rgb; returns how many. */
static size_t truncated_slice(float *slice, size_t L, size_t keep, float *scratch, float *mag, float *work,
                              uint32_t *idx, float *rgb)
{
    size_t nl = L * L;
    wenv_haar2d_forward(slice, L, 3, scratch);
    for (size_t t = 0; t < nl; t++)
        mag[t] = slice[3 * t] * slice[3 * t] + slice[3 * t + 1] * slice[3 * t + 1] + slice[3 * t + 2] * slice[3 * t + 2];
    size_t count = wenv_select_largest(mag, nl, keep, idx, work);
    /* in index order: the table rows then read the lighting slices front to back */
    qsort(idx, count, sizeof *idx, compare_u32);
    for (size_t e = 0; e < count; e++)
        memcpy(rgb + e * 3, slice + 3 * (size_t)idx[e], 3 * sizeof(float));
    return count;
}

wenv_status wenv_wavelet_set_material(wenv_wavelet *wavelet, const wenv_material *mat, const wenv_progress *progress,
                                      wenv_error *err)
{
    for (size_t i = 0; i < wavelet->n_kept; i++)
        if (wenv_material_same(wavelet->kept[i]->mat, mat)) {
            wavelet->stats.materials_reused++;
            return install(wavelet, wavelet->kept[i], err);
        }
    size_t nv = wavelet->nv, nl = wavelet->nl, L = wavelet->q.local_n, V = wavelet->q.view_n;
    size_t keep = wavelet->q.coefficients ? wavelet->q.coefficients : nl;
    /* the slices are made beside the current material, which stays until they exist: a cancel
     * (or running out of memory here) leaves the shader as it was */
    size_t *counts = NULL, *reps = NULL, n_reps = 0;
    uint32_t *all_idx = NULL;
    float *all_rgb = NULL;
    wenv_wavelet_material *m = NULL;
    wenv_status st;
    /* the grazing path's rule first: where it takes every view, the lobes need no BRDF slice (a
     * coat, a Cook-Torrance lobe of m < 0.07 at 64^2 local maps), and a new image no lighting slice */
    wenv_grazing_rule *grazing = NULL;
    if ((st = wenv_grazing_rule_create(&grazing, mat, L, wavelet->q.grazing, wavelet->q.grazing_slopes != 0, err)))
        return st;
    int sliced = wenv_material_lobe_count(mat) && !wenv_grazing_every_view(grazing), fine = 0;
    if (sliced && (st = fine_rule_for(wavelet, mat, &fine, err)))
        goto fail;
    counts = calloc(nv, sizeof(size_t));
    all_idx = malloc(nv * keep * sizeof(uint32_t));
    all_rgb = malloc(nv * keep * 3 * sizeof(float));
    reps = malloc(nv * sizeof(size_t));
    if (!counts || !all_idx || !all_rgb || !reps) {
        st = wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for BRDF slices");
        goto fail;
    }
    /* an isotropic model's slice for a view turned or mirrored about the normal is its slice so
     * turned: one per orbit of the view samples is made, and permuted for the rest */
    int symmetric = wenv_material_mirror_symmetric(mat);
    for (size_t j = 0; j < nv; j++)
        if (!symmetric || orbit_first(V + 1, j) == j)
            reps[n_reps++] = j;
    atomic_int failed = 0, cancelled = 0;
    atomic_size_t done = 0;
    if (sliced) {
#pragma omp parallel
        {
            float *slice = malloc(nl * 3 * sizeof(float)), *turned = malloc(nl * 3 * sizeof(float));
            float *scratch = malloc(wenv_haar2d_scratch_floats(L, 3) * sizeof(float));
            float *mag = malloc(nl * sizeof(float));
            float *work = malloc(nl * sizeof(float));
            float *fcos = malloc(wavelet->quad.count * 3 * sizeof(float));
            if (!slice || !turned || !scratch || !mag || !work || !fcos)
                atomic_store(&failed, 1);
#pragma omp for schedule(dynamic, 1)
            for (size_t r = 0; r < n_reps; r++) {
                if (atomic_load(&failed) || atomic_load(&cancelled))
                    continue;
                size_t rep = reps[r];
                double wo[3];
                wenv_hemi_decode(-1.0 + 2.0 * (double)(rep % (V + 1)) / (double)V,
                                 -1.0 + 2.0 * (double)(rep / (V + 1)) / (double)V, wo);
                /* a view exactly on the horizon sees nothing; its limit is what interpolation needs */
                if (wo[2] < WENV_GRAZING_Z) {
                    double sc = sqrt((1.0 - WENV_GRAZING_Z * WENV_GRAZING_Z) / (wo[0] * wo[0] + wo[1] * wo[1]));
                    wo[0] *= sc;
                    wo[1] *= sc;
                    wo[2] = WENV_GRAZING_Z;
                }
                brdf_slice(wavelet, mat, fine, wo, fcos, slice);
                /* the orbit's views, each once: view g(rep) reads texel t of the rep's slice at g(t) */
                for (int g = 0; g < (symmetric ? SQUARE_SYMMETRIES : 1); g++) {
                    size_t j = grid_image(V + 1, rep, g);
                    int seen = 0;
                    for (int h = 0; h < g && !seen; h++)
                        seen = grid_image(V + 1, rep, h) == j;
                    if (seen)
                        continue;
                    for (size_t t = 0; t < nl; t++)
                        memcpy(turned + 3 * grid_image(L, t, g), slice + 3 * t, 3 * sizeof(float));
                    counts[j] = truncated_slice(turned, L, keep, scratch, mag, work, all_idx + j * keep,
                                                all_rgb + j * keep * 3);
                    /* a slice costs its lobes' evaluations: many lobes make this long enough to report */
                    wenv_progress_item(progress, &done, nv, &cancelled);
                }
            }
            free(slice);
            free(turned);
            free(scratch);
            free(mag);
            free(work);
            free(fcos);
        }
    }
    if (!failed && !cancelled && wenv_progress_finish(progress))
        cancelled = 1;
    if (failed || cancelled) {
        st = cancelled ? wenv_error_set(err, WENV_ERR_CANCELLED, "material precomputation cancelled")
                       : wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for BRDF slices");
        goto fail;
    }
    /* the new material's part, made whole before it replaces anything */
    m = calloc(1, sizeof *m);
    if (m)
        m->serial = ++wavelet->material_serial;
    if (m) {
        m->brdf_start = calloc(nv + 1, sizeof(size_t));
        m->table = malloc(wavelet->ns * nv * 3 * sizeof(float));
        m->row_ready = calloc(wavelet->ns, 1);
        m->row_need = calloc(wavelet->ns, 1);
        m->row_asked = calloc(wavelet->ns, 1);
    }
    if (!m || !m->brdf_start || !m->table || !m->row_ready || !m->row_need || !m->row_asked) {
        st = wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for BRDF slices");
        goto fail;
    }
    m->grazing_rule = grazing;
    grazing = NULL;
    /* touch the table now rather than page by page during the first views */
    memset(m->table, 0, wavelet->ns * nv * 3 * sizeof(float));
    for (size_t j = 0; j < nv; j++)
        m->brdf_start[j + 1] = m->brdf_start[j] + counts[j];
    size_t total = m->brdf_start[nv];
    m->brdf_terms = total;
    m->brdf_idx = malloc((total ? total : 1) * sizeof(uint32_t));
    m->brdf_rgb = malloc((total ? total : 1) * 3 * sizeof(float));
    if (!m->brdf_idx || !m->brdf_rgb) {
        st = wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for BRDF slices");
        goto fail;
    }
    for (size_t j = 0; j < nv; j++) {
        memcpy(m->brdf_idx + m->brdf_start[j], all_idx + j * keep, counts[j] * sizeof(uint32_t));
        memcpy(m->brdf_rgb + 3 * m->brdf_start[j], all_rgb + j * keep * 3, counts[j] * 3 * sizeof(float));
    }
    if (wenv_material_copy(&m->mat, mat, err) || wenv_light_lobes_make(&m->light, m->mat, err) ||
        albedo_tables(wavelet, m, mat, err)) {
        st = err->status;
        goto fail;
    }
    free(counts);
    free(all_idx);
    free(all_rgb);
    free(reps);
    wenv_material_diffuse_table(mat, &m->diffuse);
    m->has_diffuse = wenv_diffuse_table_any(&m->diffuse);
    m->has_lobes = wenv_material_lobe_count(mat) > 0;
    m->mirror_centred = wenv_material_mirror_centred(mat);
    carry_used_rows(wavelet->ns, wavelet->m, m);
    /* kept at the front, ahead of the others; the oldest go past the count or the bytes */
    if (wavelet->n_kept == WENV_WAVELET_KEPT_MATERIALS)
        wenv_wavelet_material_free(wavelet->kept[--wavelet->n_kept]);
    memmove(wavelet->kept + 1, wavelet->kept, wavelet->n_kept * sizeof *wavelet->kept);
    wavelet->kept[0] = m;
    wavelet->n_kept++;
    size_t others = 0, n = 1;
    while (n < wavelet->n_kept &&
           others + wenv_wavelet_material_bytes(wavelet, wavelet->kept[n]) <= WENV_WAVELET_KEPT_BYTES)
        others += wenv_wavelet_material_bytes(wavelet, wavelet->kept[n++]);
    while (wavelet->n_kept > n)
        wenv_wavelet_material_free(wavelet->kept[--wavelet->n_kept]);
    wavelet->m = m;
    return wenv_wavelet_remake_ready(wavelet, 0, err);
fail:
    free(counts);
    free(all_idx);
    free(all_rgb);
    free(reps);
    wenv_wavelet_material_free(m);
    wenv_grazing_rule_free(grazing);
    return st;
}
