#include "methods/wavelet/wavelet.h"

#include <math.h>
#include <omp.h>
#include <stdatomic.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "methods/wavelet/grazing.h"
#include "math/haar.h"
#include "methods/wavelet/lights.h"
#include "math/maps.h"
#include "math/octfilter.h"
#include "methods/wavelet/rotation.h"
#include "math/sparse.h"

struct wenv_wavelet {
    wenv_wavelet_quality q;
    wenv_wavelet_variant method;
    size_t ng, nl, ns, nv;
    wenv_rotation *rot;      /* rotation method only */
    wenv_resampler *resampler; /* slicing method only */
    float *frames;           /* ns x 9 */
    wenv_wavelet_stats stats;

    /* lighting */
    int have_env;
    uint32_t *light_idx;     /* kept global Haar coefficients */
    float *light_rgb;
    size_t light_count;
    float *global_texels;    /* slicing: the kept lighting back in the pixel domain */
    float **slices;          /* ns pointers to nl x 3 Haar coefficients, NULL until needed */
    float *irradiance;       /* ns x 3 */
    float radiance_max[3];   /* brightest texel of the lighting the slices see (lights out) */
    wenv_lights *lights;     /* pixels taken out as exact directional lights (lights.h) */
    unsigned char *slice_ready, *slice_need; /* ready: 0 stale, READY, or USED (see READY) */
    wenv_grazing_light *grazing_light; /* quality.grazing > 0 only */

    /* local quadrature: sub-samples of the local map with their tent taps */
    size_t quad_k, quad_count;
    float *quad_dirs;        /* quad_count x 3 */
    uint32_t *quad_taps;     /* quad_count x 4 */
    float *quad_w;           /* quad_count x 4: tent weight x solid angle x normalisation */
    float *cosine_haar;      /* nl: Haar transform of the cosine weights (sum pi) */

    /* material */
    int have_mat;
    wenv_material *mat;      /* for the direct lights */
    float *lobe_cos_h_min;   /* per lobe: below this n.h its D is negligible (< 1e-7 of its peak) */
    double light_cone_cos;   /* lights farther than this from the mirror direction miss every lobe */
    double lobe_m_min;       /* the narrowest lobe's roughness (picks the lights' cluster level) */
    float *albedo;           /* ALBEDO_N x 3: specular albedo at cos(view) = WENV_GRAZING_Z .. 1 */
    float *view_inv_albedo;  /* nv x 3: 1 / albedo of each view sample (0 where the albedo is 0) */
    float diffuse_over_pi[3];
    wenv_grazing_rule *grazing_rule; /* NULL: no lobe is integrated per vertex */
    size_t *brdf_start;      /* nv + 1 */
    uint32_t *brdf_idx;
    float *brdf_rgb;

    /* (normal sample, view sample) radiance table */
    float *table;            /* ns x nv x 3 */
    unsigned char *pair_ready, *pair_need;
};

/* States of a lighting slice or table entry: made (READY), and made and read by the latest shade
 * call (USED), which a new lighting or material remakes at once.  Marking use on the read that
 * checks readiness costs nothing extra per vertex. */
#define READY 1
#define USED 2

/* Entries of the specular albedo table, uniform in cos(view): 1/256 apart is 0.22 degrees at the
 * horizon, where the albedo changes fastest. */
#define ALBEDO_N 257
#define ALBEDO_SAMPLES 32

static double now_seconds(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

wenv_status wenv_wavelet_quality_check(const wenv_wavelet_quality *q, wenv_error *err)
{
    if (!wenv_is_power_of_two(q->global_n) || q->global_n < 4 || q->global_n > 512)
        return wenv_error_set(err, WENV_ERR_VALUE, "quality['global'] must be a power of two in [4, 512], got %zu", q->global_n);
    if (!wenv_is_power_of_two(q->local_n) || q->local_n < 4 || q->local_n > 256)
        return wenv_error_set(err, WENV_ERR_VALUE, "quality['local'] must be a power of two in [4, 256], got %zu", q->local_n);
    if (q->normal_n < 2 || q->normal_n > 512 || q->normal_n % 2)
        return wenv_error_set(err, WENV_ERR_VALUE, "quality['normals'] must be an even number in [2, 512], got %zu", q->normal_n);
    if (q->view_n < 2 || q->view_n > 256 || q->view_n % 2)
        return wenv_error_set(err, WENV_ERR_VALUE, "quality['views'] must be an even number in [2, 256], got %zu", q->view_n);
    if (q->coefficients > q->local_n * q->local_n)
        return wenv_error_set(err, WENV_ERR_VALUE, "quality['coefficients'] must be at most local**2 = %zu, got %zu",
                              q->local_n * q->local_n, q->coefficients);
    if (q->light_coefficients > ((size_t)1 << 20))
        return wenv_error_set(err, WENV_ERR_VALUE, "quality['light_coefficients'] must be at most 2**20, got %zu",
                              q->light_coefficients);
    if (q->lights > 4096)
        return wenv_error_set(err, WENV_ERR_VALUE, "quality['lights'] must be at most 4096, got %zu", q->lights);
    if (!(q->light_threshold >= 1.0 && q->light_threshold <= 1e12))
        return wenv_error_set(err, WENV_ERR_VALUE, "quality['light_threshold'] must be in [1, 1e12], got %g",
                              q->light_threshold);
    if (!(q->grazing >= 0.0 && q->grazing <= 64.0))
        return wenv_error_set(err, WENV_ERR_VALUE, "quality['grazing'] must be in [0, 64], got %g", q->grazing);
    if (!(q->matrix_epsilon >= 0.0 && q->matrix_epsilon < 1.0))
        return wenv_error_set(err, WENV_ERR_VALUE, "quality['matrix_epsilon'] must be in [0, 1), got %g", q->matrix_epsilon);
    size_t table = q->normal_n * q->normal_n * (q->view_n + 1) * (q->view_n + 1);
    if (table > ((size_t)1 << 26))
        return wenv_error_set(err, WENV_ERR_VALUE, "quality: normals**2 * (views + 1)**2 = %zu exceeds 2**26 table entries", table);
    return WENV_OK;
}

static void free_material(wenv_wavelet *wavelet)
{
    wenv_material_free(wavelet->mat);
    free(wavelet->lobe_cos_h_min);
    free(wavelet->albedo);
    free(wavelet->view_inv_albedo);
    wavelet->mat = NULL;
    wavelet->lobe_cos_h_min = NULL;
    wavelet->albedo = NULL;
    wavelet->view_inv_albedo = NULL;
    wenv_grazing_rule_free(wavelet->grazing_rule);
    wavelet->grazing_rule = NULL;
    free(wavelet->brdf_start);
    free(wavelet->brdf_idx);
    free(wavelet->brdf_rgb);
    wavelet->brdf_start = NULL;
    wavelet->brdf_idx = NULL;
    wavelet->brdf_rgb = NULL;
    wavelet->have_mat = 0;
}

static void free_quadrature(wenv_wavelet *wavelet)
{
    free(wavelet->quad_dirs);
    free(wavelet->quad_taps);
    free(wavelet->quad_w);
    wavelet->quad_dirs = NULL;
    wavelet->quad_taps = NULL;
    wavelet->quad_w = NULL;
    wavelet->quad_k = 0;
}

void wenv_wavelet_free(wenv_wavelet *wavelet)
{
    if (!wavelet)
        return;
    wenv_rotation_free(wavelet->rot);
    wenv_resampler_free(wavelet->resampler);
    free(wavelet->frames);
    free(wavelet->light_idx);
    free(wavelet->light_rgb);
    free(wavelet->global_texels);
    if (wavelet->slices)
        for (size_t s = 0; s < wavelet->ns; s++)
            free(wavelet->slices[s]);
    free(wavelet->slices);
    free(wavelet->irradiance);
    wenv_lights_free(wavelet->lights);
    wenv_grazing_light_free(wavelet->grazing_light);
    free(wavelet->slice_ready);
    free(wavelet->slice_need);
    free_quadrature(wavelet);
    free(wavelet->cosine_haar);
    free_material(wavelet);
    free(wavelet->table);
    free(wavelet->pair_ready);
    free(wavelet->pair_need);
    free(wavelet);
}

/* Sub-samples of every local texel (k x k per texel, each carrying the texel's exact solid angle
 * over k^2) with their tent taps, scaled so the cosine weights sum to exactly pi: then a constant
 * environment gives exactly albedo x radiance. */
static wenv_status build_quadrature(wenv_wavelet *wavelet, size_t k, wenv_error *err)
{
    if (wavelet->quad_k == k)
        return WENV_OK;
    free_quadrature(wavelet);
    size_t L = wavelet->q.local_n, nl = wavelet->nl, count = nl * k * k;
    wavelet->quad_dirs = malloc(count * 3 * sizeof(float));
    wavelet->quad_taps = malloc(count * 4 * sizeof(uint32_t));
    wavelet->quad_w = malloc(count * 4 * sizeof(float));
    double *cosw = calloc(nl, sizeof(double));
    float *cos_f = malloc(nl * sizeof(float));
    float *scratch = malloc(L * sizeof(float));
    if (!wavelet->quad_dirs || !wavelet->quad_taps || !wavelet->quad_w || !cosw || !cos_f || !scratch) {
        free(cosw);
        free(cos_f);
        free(scratch);
        free_quadrature(wavelet);
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
                cosw[idx[c]] += w[c] * omega * d[2];
                total += w[c] * omega * d[2];
            }
        }
    }
    double scale = M_PI / total;
    for (size_t e = 0; e < count * 4; e++)
        wavelet->quad_w[e] = (float)(wavelet->quad_w[e] * scale);
    for (size_t t = 0; t < nl; t++)
        cos_f[t] = (float)(cosw[t] * scale);
    wenv_haar2d_forward(cos_f, L, 1, scratch);
    free(cosw);
    free(scratch);
    /* The irradiance weights stay those of the first quadrature: the lighting slices (and their
     * irradiance) outlive materials, so a slice must not depend on which material was current. */
    if (wavelet->cosine_haar)
        free(cos_f);
    else
        wavelet->cosine_haar = cos_f;
    wavelet->quad_count = count;
    wavelet->quad_k = k;
    return WENV_OK;
}

wenv_status wenv_wavelet_create(wenv_wavelet **out, const wenv_wavelet_quality *q, wenv_wavelet_variant method,
                               const char *cache_dir, const wenv_progress *progress, wenv_error *err)
{
    *out = NULL;
    if (wenv_wavelet_quality_check(q, err))
        return err->status;
    wenv_wavelet *wavelet = calloc(1, sizeof *wavelet);
    if (!wavelet)
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for the shader");
    wavelet->q = *q;
    wavelet->method = method;
    wavelet->ng = q->global_n * q->global_n;
    wavelet->nl = q->local_n * q->local_n;
    wavelet->ns = q->normal_n * q->normal_n;
    wavelet->nv = (q->view_n + 1) * (q->view_n + 1); /* samples on texel corners, horizon included */
    wavelet->frames = malloc(wavelet->ns * 9 * sizeof(float));
    wavelet->slices = calloc(wavelet->ns, sizeof(float *));
    wavelet->irradiance = calloc(wavelet->ns * 3, sizeof(float));
    wavelet->slice_ready = calloc(wavelet->ns, 1);
    wavelet->slice_need = calloc(wavelet->ns, 1);
    wavelet->table = malloc(wavelet->ns * wavelet->nv * 3 * sizeof(float));
    wavelet->pair_ready = calloc(wavelet->ns * wavelet->nv, 1);
    wavelet->pair_need = calloc(wavelet->ns * wavelet->nv, 1);
    if (!wavelet->frames || !wavelet->slices || !wavelet->irradiance || !wavelet->slice_ready || !wavelet->slice_need || !wavelet->table ||
        !wavelet->pair_ready || !wavelet->pair_need) {
        wenv_wavelet_free(wavelet);
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for the shader tables");
    }
    /* touch the table now rather than page by page during the first views */
    memset(wavelet->table, 0, wavelet->ns * wavelet->nv * 3 * sizeof(float));
    for (size_t s = 0; s < wavelet->ns; s++) {
        double n[3], f[9];
        wenv_normal_sample(q->normal_n, s, n);
        wenv_frame(n, f);
        for (int c = 0; c < 9; c++)
            wavelet->frames[9 * s + c] = (float)f[c];
    }
    if (build_quadrature(wavelet, 2, err)) {
        wenv_wavelet_free(wavelet);
        return err->status;
    }
    double t0 = now_seconds();
    if (method == WENV_WAVELET_ROTATION) {
        char path[4096];
        path[0] = '\0';
        if (cache_dir) {
            snprintf(path, sizeof path, "%s/wenv-rot-v2-g%zu-l%zu-n%zu-e%.3g.bin", cache_dir, q->global_n,
                     q->local_n, q->normal_n, q->matrix_epsilon);
            wenv_error ignored = {0};
            if (wenv_rotation_load(&wavelet->rot, path, q->global_n, q->local_n, q->normal_n, q->matrix_epsilon,
                                   &ignored) == WENV_OK)
                wavelet->stats.cache = 1;
        }
        if (!wavelet->rot) {
            if (wenv_rotation_build(&wavelet->rot, q->global_n, q->local_n, q->normal_n, q->matrix_epsilon, progress, err)) {
                wenv_wavelet_free(wavelet);
                return err->status;
            }
            if (path[0]) {
                wenv_error save_err = {0};
                wavelet->stats.cache = wenv_rotation_save(wavelet->rot, path, &save_err) == WENV_OK ? 2 : 3;
            }
        }
        wavelet->stats.rotation_nnz = wenv_rotation_nnz(wavelet->rot);
        wavelet->stats.rotation_bytes = wavelet->stats.rotation_nnz * (sizeof(uint16_t) + sizeof(float)) +
                                   wavelet->ns * (wavelet->ng + 1) * sizeof(size_t);
    } else if (wenv_resampler_create(&wavelet->resampler, q->global_n, q->local_n, err)) {
        wenv_wavelet_free(wavelet);
        return err->status;
    }
    wavelet->stats.rotation_seconds = now_seconds() - t0;
    *out = wavelet;
    return WENV_OK;
}

/* Bilinear taps on the normal samples' octahedral grid and on a slice's view-sample corners, in
 * float with truncating casts: this runs 5 times per vertex per frame, and libm's floor() (a call
 * on baseline x86-64) and double divisions dominated it.  Same conventions as maps.c. */
static inline void corner_taps_f(long n, float u, float v, uint32_t idx[4], float w[4])
{
    float hi = (float)n, x = (u + 1.0f) * 0.5f * hi, y = (v + 1.0f) * 0.5f * hi;
    x = x < 0.0f ? 0.0f : (x > hi ? hi : x);
    y = y < 0.0f ? 0.0f : (y > hi ? hi : y);
    long i = (long)x, j = (long)y;
    if (i > n - 1)
        i = n - 1;
    if (j > n - 1)
        j = n - 1;
    float fx = x - (float)i, fy = y - (float)j;
    long row = n + 1;
    idx[0] = (uint32_t)(j * row + i);
    idx[1] = idx[0] + 1;
    idx[2] = idx[0] + (uint32_t)row;
    idx[3] = idx[2] + 1;
    w[0] = (1.0f - fx) * (1.0f - fy);
    w[1] = fx * (1.0f - fy);
    w[2] = (1.0f - fx) * fy;
    w[3] = fx * fy;
}

static wenv_status fill_needed(wenv_wavelet *wavelet, wenv_error *err);

/* A new lighting (slices too) or material remakes at once what the latest shade call read -- so
 * that shading the same view again, the usual case while lighting or material is edited, is a single
 * pass over the vertices -- and marks everything else stale, to be made when a vertex needs it. */
static wenv_status remake_ready(wenv_wavelet *wavelet, int slices, wenv_error *err)
{
    size_t npairs = wavelet->ns * wavelet->nv;
    if (slices) {
        for (size_t s = 0; s < wavelet->ns; s++)
            wavelet->slice_need[s] |= wavelet->slice_ready[s] == USED;
        memset(wavelet->slice_ready, 0, wavelet->ns);
    }
    for (size_t p = 0; p < npairs; p++)
        wavelet->pair_need[p] |= wavelet->pair_ready[p] == USED;
    memset(wavelet->pair_ready, 0, npairs);
    if (!wavelet->have_env || !wavelet->have_mat)
        return WENV_OK;
    return fill_needed(wavelet, err);
}

static int compare_size(const void *a, const void *b)
{
    size_t x = *(const size_t *)a, y = *(const size_t *)b;
    return (x > y) - (x < y);
}

wenv_status wenv_wavelet_set_environment(wenv_wavelet *wavelet, const wenv_envmap *env, wenv_error *err)
{
    size_t G = wavelet->q.global_n, ng = wavelet->ng;
    float *texels = malloc(ng * 3 * sizeof(float));
    float *scratch = malloc(G * 3 * sizeof(float));
    float *mag = malloc(ng * sizeof(float));
    float *work = malloc(ng * sizeof(float));
    uint32_t *idx = malloc(ng * sizeof(uint32_t));
    float *rgb = NULL;
    wenv_status st = WENV_OK;
    size_t npixels = wavelet->q.lights;
    wenv_bright_pixel *bright = malloc((npixels ? npixels : 1) * sizeof *bright);
    size_t *excluded = malloc((npixels ? npixels : 1) * sizeof *excluded);
    wenv_lights *lights = NULL;
    if (!texels || !scratch || !mag || !work || !idx || !bright || !excluded) {
        st = wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for the environment");
        goto done;
    }
    npixels = wenv_envmap_brightest(env, npixels, wavelet->q.light_threshold, bright);
    if ((st = wenv_lights_create(&lights, bright, npixels, err)))
        goto done;
    for (size_t i = 0; i < npixels; i++)
        excluded[i] = bright[i].pixel;
    qsort(excluded, npixels, sizeof *excluded, compare_size);
    if ((st = wenv_oct_from_envmap(env, G, texels, excluded, npixels, err)))
        goto done;
    if (wavelet->q.grazing > 0.0) {
        wenv_grazing_light *gl;
        if ((st = wenv_grazing_light_create(&gl, env, excluded, npixels, err)))
            goto done;
        wenv_grazing_light_free(wavelet->grazing_light);
        wavelet->grazing_light = gl;
    }
    float peak[3] = {0.0f, 0.0f, 0.0f};
    for (size_t u = 0; u < ng; u++)
        for (int c = 0; c < 3; c++)
            peak[c] = texels[3 * u + c] > peak[c] ? texels[3 * u + c] : peak[c];
    wenv_haar2d_forward(texels, G, 3, scratch);
    for (size_t u = 0; u < ng; u++)
        mag[u] = texels[3 * u] * texels[3 * u] + texels[3 * u + 1] * texels[3 * u + 1] + texels[3 * u + 2] * texels[3 * u + 2];
    /* more terms asked for than the map has keeps them all */
    size_t keep = wavelet->q.light_coefficients && wavelet->q.light_coefficients < ng ? wavelet->q.light_coefficients : ng;
    size_t count = wenv_select_largest(mag, ng, keep, idx, work);
    rgb = malloc((count ? count : 1) * 3 * sizeof(float));
    if (!rgb) {
        st = wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for the environment");
        goto done;
    }
    for (size_t e = 0; e < count; e++)
        memcpy(rgb + 3 * e, texels + 3 * (size_t)idx[e], 3 * sizeof(float));
    if (wavelet->method == WENV_WAVELET_SLICING) {
        /* slicing reads the kept lighting back in the pixel domain */
        memset(texels, 0, ng * 3 * sizeof(float));
        for (size_t e = 0; e < count; e++)
            memcpy(texels + 3 * (size_t)idx[e], rgb + 3 * e, 3 * sizeof(float));
        wenv_haar2d_inverse(texels, G, 3, scratch);
        free(wavelet->global_texels);
        wavelet->global_texels = texels;
        texels = NULL;
    }
    free(wavelet->light_idx);
    free(wavelet->light_rgb);
    wavelet->light_idx = idx;
    wavelet->light_rgb = rgb;
    wavelet->light_count = count;
    memcpy(wavelet->radiance_max, peak, sizeof peak);
    idx = NULL;
    rgb = NULL;
    wenv_lights_free(wavelet->lights);
    wavelet->lights = lights;
    lights = NULL;
    wavelet->have_env = 1;
    st = remake_ready(wavelet, 1, err);
done:
    free(texels);
    free(scratch);
    free(mag);
    free(work);
    free(idx);
    free(rgb);
    free(bright);
    free(excluded);
    wenv_lights_free(lights);
    return st;
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

/* Per lobe, the n.h below which its distribution stays under 1e-7 of its largest value (a scan over
 * theta_h from the horizon in, stopping one step past the first value above the cut): a direct
 * light there adds nothing visible, and skipping it keeps the lights cheap per vertex. */
static wenv_status lobe_cutoffs(wenv_wavelet *wavelet, const wenv_material *mat, wenv_error *err)
{
    enum { STEPS = 4096 };
    size_t n_lobes = wenv_material_lobe_count(mat);
    wavelet->lobe_cos_h_min = malloc((n_lobes ? n_lobes : 1) * sizeof(float));
    if (!wavelet->lobe_cos_h_min)
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for the material");
    for (size_t k = 0; k < n_lobes; k++) {
        const wenv_lobe *lobe = wenv_material_lobe(mat, k);
        double peak = 0.0;
        for (int i = 0; i <= STEPS; i++)
            peak = fmax(peak, wenv_ndf(lobe->distribution, lobe->roughness, cos(0.5 * M_PI * i / STEPS)));
        int i = STEPS;
        while (i > 0 && wenv_ndf(lobe->distribution, lobe->roughness, cos(0.5 * M_PI * i / STEPS)) < 1e-7 * peak)
            i--;
        i = i < STEPS ? i + 1 : STEPS;
        wavelet->lobe_cos_h_min[k] = i >= STEPS ? -1.0f : (float)cos(0.5 * M_PI * i / STEPS);
    }
    /* A half-vector theta_h from the normal turns the mirror direction by at most 2 theta_h. */
    double theta_h = 0.0;
    for (size_t k = 0; k < n_lobes; k++)
        theta_h = fmax(theta_h, acos(fmax(-1.0, fmin(1.0, (double)wavelet->lobe_cos_h_min[k]))));
    wavelet->lobe_m_min = fmin(1.0, wenv_material_lobe_width(mat));
    wavelet->light_cone_cos = 2.0 * theta_h >= M_PI ? -1.0 : cos(2.0 * theta_h);
    return WENV_OK;
}

/* Specular albedo at cos(view) = c, linear in the table. */
static inline void albedo_at(const float *table, float c, float a[3])
{
    float x = (c - (float)WENV_GRAZING_Z) * (float)(ALBEDO_N - 1) / (1.0f - (float)WENV_GRAZING_Z);
    x = x < 0.0f ? 0.0f : (x > (float)(ALBEDO_N - 1) ? (float)(ALBEDO_N - 1) : x);
    long i = (long)x;
    if (i > ALBEDO_N - 2)
        i = ALBEDO_N - 2;
    float f = x - (float)i;
    for (int k = 0; k < 3; k++)
        a[k] = (1.0f - f) * table[3 * i + k] + f * table[3 * (i + 1) + k];
}

/* The specular lobes' directional albedo over cos(view), and its inverse at each view sample.
 *
 * Why: a table entry is the lighting seen through one view sample's BRDF slice, and near grazing
 * the slice's overall size (Fresnel, masking, 1/cos of the view) changes faster than bilinear
 * interpolation between view samples follows.  Entries are therefore kept divided by their view's
 * albedo -- a weighted mean radiance, which varies slowly -- and a vertex multiplies the
 * interpolated mean by the albedo at its own view.  A constant environment stays exact. */
static wenv_status albedo_tables(wenv_wavelet *wavelet, const wenv_material *mat, wenv_error *err)
{
    size_t V = wavelet->q.view_n;
    wavelet->albedo = calloc(ALBEDO_N * 3, sizeof(float));
    wavelet->view_inv_albedo = calloc(wavelet->nv * 3, sizeof(float));
    if (!wavelet->albedo || !wavelet->view_inv_albedo)
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
                wavelet->albedo[3 * i + k] += (float)a[k];
        }
    }
    if (failed)
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for the material's albedo");
    for (size_t j = 0; j < wavelet->nv; j++) {
        double wo[3];
        wenv_hemi_decode(-1.0 + 2.0 * (double)(j % (V + 1)) / (double)V, -1.0 + 2.0 * (double)(j / (V + 1)) / (double)V,
                         wo);
        float a[3];
        albedo_at(wavelet->albedo, (float)wo[2], a);
        for (int k = 0; k < 3; k++)
            wavelet->view_inv_albedo[3 * j + k] = a[k] > 1e-30f ? 1.0f / a[k] : 0.0f;
    }
    return WENV_OK;
}

wenv_status wenv_wavelet_set_material(wenv_wavelet *wavelet, const wenv_material *mat, wenv_error *err)
{
    size_t nv = wavelet->nv, nl = wavelet->nl, L = wavelet->q.local_n, V = wavelet->q.view_n;
    size_t keep = wavelet->q.coefficients ? wavelet->q.coefficients : nl;
    if (wenv_material_lobe_count(mat) && build_quadrature(wavelet, quadrature_k(wavelet, mat), err))
        return err->status;
    free_material(wavelet);
    wavelet->brdf_start = calloc(nv + 1, sizeof(size_t));
    size_t *counts = calloc(nv, sizeof(size_t));
    uint32_t *all_idx = malloc(nv * keep * sizeof(uint32_t));
    float *all_rgb = malloc(nv * keep * 3 * sizeof(float));
    if (!wavelet->brdf_start || !counts || !all_idx || !all_rgb) {
        free(counts);
        free(all_idx);
        free(all_rgb);
        free_material(wavelet);
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for BRDF slices");
    }
    atomic_int failed = 0;
    if (wenv_material_lobe_count(mat)) {
#pragma omp parallel
        {
            float *slice = malloc(nl * 3 * sizeof(float));
            float *scratch = malloc(L * 3 * sizeof(float));
            float *mag = malloc(nl * sizeof(float));
            float *work = malloc(nl * sizeof(float));
            float *fcos = malloc(wavelet->quad_count * 3 * sizeof(float));
            if (!slice || !scratch || !mag || !work || !fcos)
                atomic_store(&failed, 1);
#pragma omp for schedule(dynamic, 1)
            for (size_t j = 0; j < nv; j++) {
                if (atomic_load(&failed))
                    continue;
                double wo[3];
                wenv_hemi_decode(-1.0 + 2.0 * (double)(j % (V + 1)) / (double)V,
                                 -1.0 + 2.0 * (double)(j / (V + 1)) / (double)V, wo);
                /* a view exactly on the horizon sees nothing; its limit is what interpolation needs */
                if (wo[2] < WENV_GRAZING_Z) {
                    double s = sqrt((1.0 - WENV_GRAZING_Z * WENV_GRAZING_Z) / (wo[0] * wo[0] + wo[1] * wo[1]));
                    wo[0] *= s;
                    wo[1] *= s;
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
                wenv_haar2d_forward(slice, L, 3, scratch);
                for (size_t t = 0; t < nl; t++)
                    mag[t] = slice[3 * t] * slice[3 * t] + slice[3 * t + 1] * slice[3 * t + 1] + slice[3 * t + 2] * slice[3 * t + 2];
                uint32_t *idx = all_idx + j * keep;
                size_t count = wenv_select_largest(mag, nl, keep, idx, work);
                for (size_t e = 0; e < count; e++)
                    memcpy(all_rgb + (j * keep + e) * 3, slice + 3 * (size_t)idx[e], 3 * sizeof(float));
                counts[j] = count;
            }
            free(slice);
            free(scratch);
            free(mag);
            free(work);
            free(fcos);
        }
    }
    if (failed) {
        free(counts);
        free(all_idx);
        free(all_rgb);
        free_material(wavelet);
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for BRDF slices");
    }
    for (size_t j = 0; j < nv; j++)
        wavelet->brdf_start[j + 1] = wavelet->brdf_start[j] + counts[j];
    size_t total = wavelet->brdf_start[nv];
    wavelet->brdf_idx = malloc((total ? total : 1) * sizeof(uint32_t));
    wavelet->brdf_rgb = malloc((total ? total : 1) * 3 * sizeof(float));
    if (!wavelet->brdf_idx || !wavelet->brdf_rgb) {
        free(counts);
        free(all_idx);
        free(all_rgb);
        free_material(wavelet);
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for BRDF slices");
    }
    for (size_t j = 0; j < nv; j++) {
        memcpy(wavelet->brdf_idx + wavelet->brdf_start[j], all_idx + j * keep, counts[j] * sizeof(uint32_t));
        memcpy(wavelet->brdf_rgb + 3 * wavelet->brdf_start[j], all_rgb + j * keep * 3, counts[j] * 3 * sizeof(float));
    }
    free(counts);
    free(all_idx);
    free(all_rgb);
    if (wenv_material_copy(&wavelet->mat, mat, err) || lobe_cutoffs(wavelet, mat, err) || albedo_tables(wavelet, mat, err) ||
        wenv_grazing_rule_create(&wavelet->grazing_rule, mat, wavelet->q.local_n, wavelet->q.grazing, err)) {
        free_material(wavelet);
        return err->status;
    }
    for (int c = 0; c < 3; c++)
        wavelet->diffuse_over_pi[c] = (float)(wenv_material_diffuse(mat)[c] / M_PI);
    wavelet->stats.brdf_terms_total = total;
    wavelet->have_mat = 1;
    return remake_ready(wavelet, 0, err);
}

/* ---- per vertex -------------------------------------------------------------------------------- */

typedef struct {
    uint32_t sample[4];
    float sample_w[4];
    uint32_t pair[16];
    float pair_w[16];
    float n[3], v[3]; /* unit vertex normal and view, for the direct lights */
    float cos_v;      /* n . v, > 0 */
} vertex_taps;

/* Returns 0 when the view is below the surface (the vertex is black). */
static int compute_taps(const wenv_wavelet *wavelet, const float *nrm, const float *view, vertex_taps *tp)
{
    float n[3] = {nrm[0], nrm[1], nrm[2]}, v[3] = {view[0], view[1], view[2]};
    float in = 1.0f / sqrtf(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    float iv = 1.0f / sqrtf(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
    for (int c = 0; c < 3; c++) {
        n[c] *= in;
        v[c] *= iv;
    }
    float nv = n[0] * v[0] + n[1] * v[1] + n[2] * v[2];
    if (!(nv > 0.0f))
        return 0;
    memcpy(tp->n, n, sizeof n);
    memcpy(tp->v, v, sizeof v);
    tp->cos_v = nv;
    float r[3] = {2.0f * nv * n[0] - v[0], 2.0f * nv * n[1] - v[1], 2.0f * nv * n[2] - v[2]};
    /* octahedral encoding of the normal */
    float ou, ov;
    wenv_oct_encode_f(n, &ou, &ov);
    wenv_oct_bilinear_f((long)wavelet->q.normal_n, ou, ov, tp->sample, tp->sample_w);
    for (int k = 0; k < 4; k++) {
        const float *f = wavelet->frames + 9 * (size_t)tp->sample[k];
        /* mirror of r about the sample normal, in the sample's frame: (-r.t, -r.b, r.n) */
        float lx = -(f[0] * r[0] + f[1] * r[1] + f[2] * r[2]), ly = -(f[3] * r[0] + f[4] * r[1] + f[5] * r[2]);
        float lz = f[6] * r[0] + f[7] * r[1] + f[8] * r[2];
        /* hemi-octahedral encoding; views below the sample's horizon are read on it */
        float hl = fabsf(lx) + fabsf(ly) + (lz > 0.0f ? lz : 0.0f);
        float ih = hl > 0.0f ? 1.0f / hl : 0.0f, px = lx * ih, py = ly * ih;
        uint32_t vidx[4];
        float vw[4];
        corner_taps_f((long)wavelet->q.view_n, px + py, px - py, vidx, vw);
        uint32_t base = tp->sample[k] * (uint32_t)wavelet->nv;
        for (int j = 0; j < 4; j++) {
            tp->pair[4 * k + j] = base + vidx[j];
            tp->pair_w[4 * k + j] = tp->sample_w[k] * vw[j];
        }
    }
    return 1;
}

static int compute_slice(wenv_wavelet *wavelet, size_t s, float *pixel_work, double *rowsum, float *scratch)
{
    if (!wavelet->slices[s]) {
        wavelet->slices[s] = malloc(wavelet->nl * 3 * sizeof(float));
        if (!wavelet->slices[s])
            return -1;
    }
    float *slice = wavelet->slices[s];
    if (wavelet->method == WENV_WAVELET_ROTATION) {
        wenv_rotation_apply(wavelet->rot, s, wavelet->light_idx, wavelet->light_rgb, wavelet->light_count, slice);
    } else {
        /* the double-precision frame the rotation matrices were built with, so that directions on
         * a frame's horizon fall on the same side in both methods */
        double n[3], f[9];
        wenv_normal_sample(wavelet->q.normal_n, s, n);
        wenv_frame(n, f);
        wenv_resample_slice(wavelet->resampler, f, wavelet->global_texels, pixel_work, rowsum);
        wenv_haar2d_forward(pixel_work, wavelet->q.local_n, 3, scratch);
        memcpy(slice, pixel_work, wavelet->nl * 3 * sizeof(float));
    }
    double e[3] = {0, 0, 0};
    for (size_t t = 0; t < wavelet->nl; t++) {
        float c = wavelet->cosine_haar[t];
        e[0] += c * slice[3 * t];
        e[1] += c * slice[3 * t + 1];
        e[2] += c * slice[3 * t + 2];
    }
    for (int c = 0; c < 3; c++)
        wavelet->irradiance[3 * s + c] = (float)e[c];
    return 0;
}


/* The exact lights at one vertex: irradiance into e (the diffuse term scales it) and the specular
 * lobes' reflected radiance into s, each from the coarsest cluster level its lobe allows.  Towards
 * grazing a lobe narrows to about 2 m cos(theta_v) in azimuth, so there the pixels are read. */
static void shade_direct(const wenv_wavelet *wavelet, const float n[3], const float v[3], float co, float e[3],
                         float s[3])
{
    const wenv_material *mat = wavelet->mat;
    const double *diffuse = wenv_material_diffuse(mat);
    if (diffuse[0] != 0.0 || diffuse[1] != 0.0 || diffuse[2] != 0.0)
        wenv_lights_irradiance(wavelet->lights, wenv_lights_level(WENV_LIGHT_IRRADIANCE_WIDTH), n, e);
    if (wenv_material_lobe_count(mat))
        wenv_lights_specular(wavelet->lights, wenv_lights_level(2.0 * wavelet->lobe_m_min * co), mat, wavelet->lobe_cos_h_min,
                             wavelet->light_cone_cos, n, v, co, s);
}

static void shade_vertex(const wenv_wavelet *wavelet, const vertex_taps *tp, float *o)
{
    float e[3] = {0, 0, 0}, m[3] = {0, 0, 0}, s[3] = {0, 0, 0};
    if (wenv_lights_count(wavelet->lights, 0))
        shade_direct(wavelet, tp->n, tp->v, tp->cos_v, e, s);
    for (int k = 0; k < 4; k++) {
        const float *ir = wavelet->irradiance + 3 * (size_t)tp->sample[k];
        e[0] += tp->sample_w[k] * ir[0];
        e[1] += tp->sample_w[k] * ir[1];
        e[2] += tp->sample_w[k] * ir[2];
    }
    /* table entries are mean radiances under the lobe (see albedo_tables) */
    for (int k = 0; k < 16; k++) {
        const float *t = wavelet->table + 3 * (size_t)tp->pair[k];
        float w = tp->pair_w[k];
        if (w > 0.0f) {
            m[0] += w * t[0];
            m[1] += w * t[1];
            m[2] += w * t[2];
        }
    }
    float blend = wenv_grazing_blend(wavelet->grazing_rule, tp->cos_v);
    if (wavelet->albedo && blend < 1.0f) {
        /* A mean radiance under the lobe lies between the lighting's darkest and brightest
         * texels; wavelet truncation and interpolation can ring past either, most at narrow
         * lobes near grazing, where they overshot the brightest pixel several-fold. */
        float a[3];
        albedo_at(wavelet->albedo, tp->cos_v, a);
        for (int c = 0; c < 3; c++) {
            float mc = m[c] < 0.0f ? 0.0f : (m[c] > wavelet->radiance_max[c] ? wavelet->radiance_max[c] : m[c]);
            s[c] += (1.0f - blend) * a[c] * mc;
        }
    }
    if (blend > 0.0f) {
        float g[3];
        wenv_grazing_shade(wavelet->grazing_rule, wavelet->grazing_light, tp->n, tp->v, tp->cos_v, g);
        for (int c = 0; c < 3; c++)
            s[c] += blend * g[c];
    }
    for (int c = 0; c < 3; c++) {
        float val = wavelet->diffuse_over_pi[c] * e[c] + s[c];
        o[c] = val > 0.0f ? val : 0.0f;
    }
}

/* Whether the n states state[idx[k]] read with weight w[k] > 0 are all made; marks those made as
 * USED. */
static inline int read_states(unsigned char *state, const uint32_t *idx, const float *w, int n)
{
    int all = 1;
    for (int k = 0; k < n; k++) {
        unsigned char f;
#pragma omp atomic read
        f = state[idx[k]];
        if (w[k] > 0.0f) {
            if (!f)
                all = 0;
            else if (f == READY) {
#pragma omp atomic write
                state[idx[k]] = USED;
            }
        }
    }
    return all;
}

/* Whether every slice and table entry the vertex reads is ready; marks those ready as USED. */
static int read_taps(const wenv_wavelet *wavelet, const vertex_taps *tp)
{
    int slices = read_states(wavelet->slice_ready, tp->sample, tp->sample_w, 4);
    return read_states(wavelet->pair_ready, tp->pair, tp->pair_w, 16) && slices;
}

/* Flags in the need flags what the vertex reads.  Checked before written so that cache lines
 * shared between threads stay clean; every writer stores 1. */
static inline void flag_taps(const vertex_taps *tp, unsigned char *slice_flags, unsigned char *pair_flags)
{
    for (int k = 0; k < 4; k++) {
        unsigned char f;
#pragma omp atomic read
        f = slice_flags[tp->sample[k]];
        if (tp->sample_w[k] > 0.0f && !f) {
#pragma omp atomic write
            slice_flags[tp->sample[k]] = 1;
        }
    }
    for (int k = 0; k < 16; k++) {
        unsigned char f;
#pragma omp atomic read
        f = pair_flags[tp->pair[k]];
        if (tp->pair_w[k] > 0.0f && !f) {
#pragma omp atomic write
            pair_flags[tp->pair[k]] = 1;
        }
    }
}

/* Makes the lighting slices and table entries flagged in slice_need / pair_need. */
static wenv_status fill_needed(wenv_wavelet *wavelet, wenv_error *err)
{
    size_t npairs = wavelet->ns * wavelet->nv;
    size_t *todo = malloc((wavelet->ns > npairs ? wavelet->ns : npairs) * sizeof(size_t));
    if (!todo)
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory shading");
    size_t ntodo = 0;
    for (size_t s = 0; s < wavelet->ns; s++) {
        if (wavelet->slice_need[s] && !wavelet->slice_ready[s])
            todo[ntodo++] = s;
        wavelet->slice_need[s] = 0;
    }
    atomic_int failed = 0;
#pragma omp parallel if (ntodo > 1)
    {
        float *pixel_work = malloc(wavelet->nl * 3 * sizeof(float));
        double *rowsum = malloc(wavelet->nl * sizeof(double));
        float *scratch = malloc(wavelet->q.local_n * 3 * sizeof(float));
        if (!pixel_work || !rowsum || !scratch)
            atomic_store(&failed, 1);
#pragma omp for schedule(dynamic, 4)
        for (size_t e = 0; e < ntodo; e++) {
            if (atomic_load(&failed))
                continue;
            if (compute_slice(wavelet, todo[e], pixel_work, rowsum, scratch) < 0)
                atomic_store(&failed, 1);
            else
                wavelet->slice_ready[todo[e]] = USED; /* made for the latest shade call */
        }
        free(pixel_work);
        free(rowsum);
        free(scratch);
    }
    if (failed) {
        free(todo);
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory computing lighting slices");
    }
    /* table entries: sparse BRDF slice . dense lighting slice, per RGB channel */
    ntodo = 0;
    for (size_t p = 0; p < npairs; p++) {
        if (wavelet->pair_need[p] && !wavelet->pair_ready[p])
            todo[ntodo++] = p;
        wavelet->pair_need[p] = 0;
    }
#pragma omp parallel for schedule(dynamic, 64) if (ntodo > 256)
    for (size_t e = 0; e < ntodo; e++) {
        size_t p = todo[e], s = p / wavelet->nv, j = p % wavelet->nv;
        const float *slice = wavelet->slices[s];
        float acc[3] = {0, 0, 0};
        for (size_t q = wavelet->brdf_start[j]; q < wavelet->brdf_start[j + 1]; q++) {
            const float *l = slice + 3 * (size_t)wavelet->brdf_idx[q], *b = wavelet->brdf_rgb + 3 * q;
            acc[0] += l[0] * b[0];
            acc[1] += l[1] * b[1];
            acc[2] += l[2] * b[2];
        }
        const float *inv = wavelet->view_inv_albedo + 3 * j;
        for (int c = 0; c < 3; c++)
            wavelet->table[3 * p + c] = acc[c] * inv[c];
        wavelet->pair_ready[p] = USED;
    }
    free(todo);
    return WENV_OK;
}

wenv_status wenv_wavelet_shade(wenv_wavelet *wavelet, const float *normals, const float *views, size_t n,
                              float *out, wenv_error *err)
{
    if (!wavelet->have_env || !wavelet->have_mat)
        return wenv_error_set(err, WENV_ERR_VALUE, "the shader needs an environment and a material");
    /* One pass shades every vertex whose table entries exist (all of them for a view seen before)
     * and flags what the others need; those are shaded after the missing entries are made. */
    size_t *pending = malloc((n ? n : 1) * sizeof(size_t));
    if (!pending)
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory shading");
    /* what the previous call read is no longer the latest */
    for (size_t q = 0; q < wavelet->ns; q++)
        wavelet->slice_ready[q] = wavelet->slice_ready[q] != 0;
    for (size_t q = 0; q < wavelet->ns * wavelet->nv; q++)
        wavelet->pair_ready[q] = wavelet->pair_ready[q] != 0;
    atomic_size_t npending = 0;
    long long nn = (long long)n;
#pragma omp parallel for schedule(static)
    for (long long i = 0; i < nn; i++) {
        vertex_taps tp;
        float *o = out + 3 * i;
        if (!compute_taps(wavelet, normals + 3 * i, views + 3 * i, &tp)) {
            o[0] = o[1] = o[2] = 0.0f;
            continue;
        }
        if (read_taps(wavelet, &tp)) {
            shade_vertex(wavelet, &tp, o);
            continue;
        }
        flag_taps(&tp, wavelet->slice_need, wavelet->pair_need);
        pending[atomic_fetch_add(&npending, 1)] = (size_t)i;
    }
    size_t np = atomic_load(&npending);
    if (np) {
        if (fill_needed(wavelet, err)) {
            free(pending);
            return err->status;
        }
#pragma omp parallel for schedule(static)
        for (size_t e = 0; e < np; e++) {
            vertex_taps tp;
            size_t i = pending[e];
            compute_taps(wavelet, normals + 3 * i, views + 3 * i, &tp);
            shade_vertex(wavelet, &tp, out + 3 * i);
        }
    }
    free(pending);
    return WENV_OK;
}

void wenv_wavelet_get_stats(const wenv_wavelet *wavelet, wenv_wavelet_stats *stats)
{
    *stats = wavelet->stats;
    size_t slices = 0, pairs = 0;
    for (size_t s = 0; s < wavelet->ns; s++)
        slices += wavelet->slices[s] != NULL;
    for (size_t p = 0; p < wavelet->ns * wavelet->nv; p++)
        pairs += wavelet->pair_ready[p] != 0;
    stats->slices_ready = slices;
    stats->pairs_ready = pairs;
    stats->light_terms = wavelet->light_count;
    stats->direct_lights = wenv_lights_count(wavelet->lights, 0);
    stats->slice_bytes = slices * wavelet->nl * 3 * sizeof(float);
    stats->table_bytes = wavelet->ns * wavelet->nv * (3 * sizeof(float) + 2);
    stats->brdf_bytes = wavelet->stats.brdf_terms_total * 4 * sizeof(float);
    stats->grazing_bytes = wenv_grazing_light_bytes(wavelet->grazing_light) + wenv_grazing_rule_bytes(wavelet->grazing_rule);
}
