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

void wenv_wavelet_material_free(wenv_wavelet_material *m)
{
    if (!m)
        return;
    wenv_material_free(m->mat);
    free(m->lobe_cos_h_min);
    free(m->albedo);
    free(m->view_inv_albedo);
    wenv_grazing_rule_free(m->grazing_rule);
    free(m->brdf_start);
    free(m->brdf_idx);
    free(m->brdf_rgb);
    free(m->table);
    free(m->row_ready);
    free(m->row_need);
    free(m);
}

size_t wenv_wavelet_material_bytes(const wenv_wavelet *wavelet, const wenv_wavelet_material *m)
{
    return wenv_wavelet_table_bytes(wavelet) + m->brdf_terms * 4 * sizeof(float) +
           wavelet->nv * 3 * sizeof(float) + wenv_grazing_rule_bytes(m->grazing_rule);
}

void wenv_wavelet_free_quadrature(wenv_wavelet *wavelet)
{
    free(wavelet->quad_dirs);
    free(wavelet->quad_taps);
    free(wavelet->quad_w);
    wavelet->quad_dirs = NULL;
    wavelet->quad_taps = NULL;
    wavelet->quad_w = NULL;
    wavelet->quad_k = 0;
}

/* Sub-samples of every local texel (k x k per texel, each carrying the texel's exact solid angle
 * over k^2) with their tent taps, scaled so the cosine weights sum to exactly pi: then a constant
 * environment gives exactly albedo x radiance. */
wenv_status wenv_wavelet_build_quadrature(wenv_wavelet *wavelet, size_t k, wenv_error *err)
{
    if (wavelet->quad_k == k)
        return WENV_OK;
    wenv_wavelet_free_quadrature(wavelet);
    size_t L = wavelet->q.local_n, nl = wavelet->nl, count = nl * k * k;
    wavelet->quad_dirs = malloc(count * 3 * sizeof(float));
    wavelet->quad_taps = malloc(count * 4 * sizeof(uint32_t));
    wavelet->quad_w = malloc(count * 4 * sizeof(float));
    if (!wavelet->quad_dirs || !wavelet->quad_taps || !wavelet->quad_w) {
        wenv_wavelet_free_quadrature(wavelet);
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for the local quadrature");
    }
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
                wavelet->quad_dirs[3 * e + c] = (float)d[c];
            for (int c = 0; c < 4; c++) {
                wavelet->quad_taps[4 * e + c] = (uint32_t)idx[c];
                wavelet->quad_w[4 * e + c] = (float)(w[c] * omega);
                total += w[c] * omega * d[2];
            }
        }
    }
    double scale = M_PI / total;
    for (size_t e = 0; e < count * 4; e++)
        wavelet->quad_w[e] = (float)(wavelet->quad_w[e] * scale);
    wavelet->quad_count = count;
    wavelet->quad_k = k;
    return WENV_OK;
}

/* Sub-samples per local texel side: enough to resolve the narrowest lobe (its reflected width is
 * about 1.4 m radians) with a couple of samples. */
static size_t quadrature_k(const wenv_wavelet *wavelet, const wenv_material *mat)
{
    double m = fmin(1.0, wenv_material_lobe_width(mat));
    double spacing = 2.5 / (double)wavelet->q.local_n;
    size_t k = (size_t)ceil(2.0 * spacing / (1.41 * m));
    return k < 2 ? 2 : (k > 16 ? 16 : k);
}

/* Per lobe, the n.h below which it reflects nothing visible (wenv_material_lobe_cos_h_min): a direct
 * light there adds nothing, and skipping it keeps the lights cheap per vertex. */
static wenv_status lobe_cutoffs(wenv_wavelet_material *m, const wenv_material *mat, wenv_error *err)
{
    size_t n_lobes = wenv_material_lobe_count(mat);
    m->lobe_cos_h_min = malloc((n_lobes ? n_lobes : 1) * sizeof(float));
    if (!m->lobe_cos_h_min)
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for the material");
    for (size_t k = 0; k < n_lobes; k++)
        m->lobe_cos_h_min[k] = (float)wenv_material_lobe_cos_h_min(mat, k);
    /* A half-vector theta_h from the normal turns the mirror direction by at most 2 theta_h. */
    double theta_h = 0.0;
    for (size_t k = 0; k < n_lobes; k++)
        theta_h = fmax(theta_h, acos(fmax(-1.0, fmin(1.0, (double)m->lobe_cos_h_min[k]))));
    m->lobe_m_min = fmin(1.0, wenv_material_lobe_width(mat));
    m->mirror_centred = wenv_material_mirror_centred(mat);
    m->lobes_modelled = m->mirror_centred && wenv_material_lobes_follow_shapes(mat);
    m->light_cone_cos = 2.0 * theta_h >= M_PI ? -1.0 : cos(2.0 * theta_h);
    if (m->lobes_modelled)
        wenv_lights_peak_table(mat, m->lobe_m_min, m->lobe_peak);
    else if (n_lobes)
        wenv_lights_envelope_table(mat, m->lobe_envelope);
    return WENV_OK;
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
    if (wenv_material_lobe_count(mat) && wenv_wavelet_build_quadrature(wavelet, quadrature_k(wavelet, mat), err))
        return err->status;
    /* the slices are made beside the current material, which stays until they exist: a cancel
     * (or running out of memory here) leaves the shader as it was */
    size_t *counts = calloc(nv, sizeof(size_t));
    uint32_t *all_idx = malloc(nv * keep * sizeof(uint32_t));
    float *all_rgb = malloc(nv * keep * 3 * sizeof(float));
    if (!counts || !all_idx || !all_rgb) {
        free(counts);
        free(all_idx);
        free(all_rgb);
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for BRDF slices");
    }
    /* an isotropic model's slice for a view turned or mirrored about the normal is its slice so
     * turned: one per orbit of the view samples is made, and permuted for the rest */
    int symmetric = wenv_material_mirror_symmetric(mat);
    size_t *reps = malloc(nv * sizeof(size_t)), n_reps = 0;
    if (!reps) {
        free(counts);
        free(all_idx);
        free(all_rgb);
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for BRDF slices");
    }
    for (size_t j = 0; j < nv; j++)
        if (!symmetric || orbit_first(V + 1, j) == j)
            reps[n_reps++] = j;
    atomic_int failed = 0, cancelled = 0;
    atomic_size_t done = 0;
    if (wenv_material_lobe_count(mat)) {
#pragma omp parallel
        {
            float *slice = malloc(nl * 3 * sizeof(float)), *turned = malloc(nl * 3 * sizeof(float));
            float *scratch = malloc(wenv_haar2d_scratch_floats(L, 3) * sizeof(float));
            float *mag = malloc(nl * sizeof(float));
            float *work = malloc(nl * sizeof(float));
            float *fcos = malloc(wavelet->quad_count * 3 * sizeof(float));
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
                wenv_material_specular_cos_batch(mat, wo, wavelet->quad_dirs, wavelet->quad_count, fcos);
                memset(slice, 0, nl * 3 * sizeof(float));
                for (size_t e = 0; e < wavelet->quad_count; e++) {
                    const float *g = fcos + 3 * e;
                    for (int c = 0; c < 4; c++) {
                        float w = wavelet->quad_w[4 * e + c];
                        float *o = slice + 3 * (size_t)wavelet->quad_taps[4 * e + c];
                        o[0] += w * g[0];
                        o[1] += w * g[1];
                        o[2] += w * g[2];
                    }
                }
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
                    size_t d = atomic_fetch_add(&done, 1) + 1;
                    if (omp_get_thread_num() == 0 && progress && progress->report &&
                        progress->report(progress->ctx, (double)d / (double)nv))
                        atomic_store(&cancelled, 1);
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
    free(reps);
    if (failed || cancelled) {
        free(counts);
        free(all_idx);
        free(all_rgb);
        return cancelled ? wenv_error_set(err, WENV_ERR_CANCELLED, "material precomputation cancelled")
                         : wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for BRDF slices");
    }
    /* the new material's part, made whole before it replaces anything */
    wenv_wavelet_material *m = calloc(1, sizeof *m);
    if (m) {
        m->brdf_start = calloc(nv + 1, sizeof(size_t));
        m->table = malloc(wavelet->ns * nv * 3 * sizeof(float));
        m->row_ready = calloc(wavelet->ns, 1);
        m->row_need = calloc(wavelet->ns, 1);
    }
    if (!m || !m->brdf_start || !m->table || !m->row_ready || !m->row_need) {
        free(counts);
        free(all_idx);
        free(all_rgb);
        wenv_wavelet_material_free(m);
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for BRDF slices");
    }
    /* touch the table now rather than page by page during the first views */
    memset(m->table, 0, wavelet->ns * nv * 3 * sizeof(float));
    for (size_t j = 0; j < nv; j++)
        m->brdf_start[j + 1] = m->brdf_start[j] + counts[j];
    size_t total = m->brdf_start[nv];
    m->brdf_terms = total;
    m->brdf_idx = malloc((total ? total : 1) * sizeof(uint32_t));
    m->brdf_rgb = malloc((total ? total : 1) * 3 * sizeof(float));
    if (!m->brdf_idx || !m->brdf_rgb) {
        free(counts);
        free(all_idx);
        free(all_rgb);
        wenv_wavelet_material_free(m);
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for BRDF slices");
    }
    for (size_t j = 0; j < nv; j++) {
        memcpy(m->brdf_idx + m->brdf_start[j], all_idx + j * keep, counts[j] * sizeof(uint32_t));
        memcpy(m->brdf_rgb + 3 * m->brdf_start[j], all_rgb + j * keep * 3, counts[j] * 3 * sizeof(float));
    }
    free(counts);
    free(all_idx);
    free(all_rgb);
    if (wenv_material_copy(&m->mat, mat, err) || lobe_cutoffs(m, mat, err) || albedo_tables(wavelet, m, mat, err) ||
        wenv_grazing_rule_create(&m->grazing_rule, mat, wavelet->q.local_n, wavelet->q.grazing,
                                 wavelet->q.grazing_slopes != 0, err)) {
        wenv_wavelet_material_free(m);
        return err->status;
    }
    wenv_material_diffuse_table(mat, &m->diffuse);
    m->has_diffuse = wenv_diffuse_table_any(&m->diffuse);
    m->has_lobes = wenv_material_lobe_count(mat) > 0;
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
}
