#include "methods/splitsum/splitsum.h"

#include <math.h>
#include <omp.h>
#include <stdatomic.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "base/clock.h"
#include "math/frame.h"
#include "math/maps.h"
#include "scene/envmap_octahedral.h"
#include "math/spherical_harmonics.h"
#include "math/unit_pair.h"
#include "scene/envmap_sh.h"
#include "methods/method.h"
#include "methods/presets.h"

typedef wenv_oct_pyramid pyramid;

typedef struct {
    size_t lobes, source_side, source_levels, source_bytes, prefilter_bytes, lut_bytes;
    double environment_seconds, prefilter_seconds, lut_seconds;
} wenv_splitsum_stats;

typedef struct wenv_splitsum wenv_splitsum;

struct wenv_splitsum {
    wenv_splitsum_quality q;
    wenv_splitsum_stats stats;
    int have_env, have_mat;
    pyramid src;
    double irradiance_sh[9 * 3];
    /* material */
    size_t n_lobes;
    wenv_lobe *lobes;  /* their shapes: what the prefilter assumes */
    wenv_diffuse_table diffuse; /* the Lambertian part's albedo / pi over the view's cosine */
    float *lut;        /* n_lobes x q.lut x 3: each lobe's albedo, its colour included */
    float *prefilter;  /* n_lobes x prefilter^2 x 3, once both are set */
};

static const wenv_param PARAMS[] = {
    {"prefilter", WENV_PARAM_SIZE, offsetof(wenv_splitsum_quality, prefilter)},
    {"samples", WENV_PARAM_SIZE, offsetof(wenv_splitsum_quality, samples)},
    {"lut", WENV_PARAM_SIZE, offsetof(wenv_splitsum_quality, lut)},
};

static wenv_status check_quality(const void *quality, wenv_error *err)
{
    const wenv_splitsum_quality *q = quality;
    if (q->prefilter < 8 || q->prefilter > 1024 || q->prefilter % 2)
        return wenv_error_set(err, WENV_ERR_VALUE, "quality['prefilter'] must be an even number in [8, 1024], got %zu",
                              q->prefilter);
    if (q->samples < 1 || q->samples > 65536)
        return wenv_error_set(err, WENV_ERR_VALUE, "quality['samples'] must be in [1, 65536], got %zu", q->samples);
    if (q->lut < 2 || q->lut > 4096)
        return wenv_error_set(err, WENV_ERR_VALUE, "quality['lut'] must be in [2, 4096], got %zu", q->lut);
    return WENV_OK;
}


static void destroy(void *state)
{
    wenv_splitsum *ss = state;
    if (!ss)
        return;
    wenv_oct_pyramid_free(&ss->src);
    free(ss->lobes);
    free(ss->lut);
    free(ss->prefilter);
    free(ss);
}

/* No matrices, so no cache and nothing to report: the work is in set_environment / set_material. */
static wenv_status create(void **state, const void *quality, const wenv_method_setup *setup, wenv_error *err)
{
    (void)setup;
    const wenv_splitsum_quality *q = quality;
    *state = NULL;
    if (check_quality(q, err))
        return err->status;
    wenv_splitsum *ss = calloc(1, sizeof *ss);
    if (!ss)
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for the split-sum shader");
    ss->q = *q;
    *state = ss;
    return WENV_OK;
}


static void bilinear_fetch(const float *texels, size_t side, double u, double v, double rgb[3])
{
    size_t idx[4];
    double w[4];
    wenv_oct_bilinear(side, u, v, idx, w);
    rgb[0] = rgb[1] = rgb[2] = 0.0;
    for (int k = 0; k < 4; k++) {
        const float *t = texels + 3 * idx[k];
        rgb[0] += w[k] * t[0];
        rgb[1] += w[k] * t[1];
        rgb[2] += w[k] * t[2];
    }
}

static void pyramid_fetch(const pyramid *p, const double d[3], double lod, double rgb[3])
{
    double u, v;
    wenv_oct_encode(d, &u, &v);
    double top = (double)(p->levels - 1);
    if (!(lod > 0.0))
        lod = 0.0;
    if (lod > top)
        lod = top;
    size_t lo = (size_t)lod;
    double f = lod - (double)lo;
    bilinear_fetch(p->texels[lo], p->side[lo], u, v, rgb);
    if (f > 0.0 && lo + 1 < p->levels) {
        double hi[3];
        bilinear_fetch(p->texels[lo + 1], p->side[lo + 1], u, v, hi);
        for (int c = 0; c < 3; c++)
            rgb[c] += f * (hi[c] - rgb[c]);
    }
}

static double radical_inverse2(uint32_t k)
{
    k = (k << 16) | (k >> 16);
    k = ((k & 0x55555555u) << 1) | ((k & 0xAAAAAAAAu) >> 1);
    k = ((k & 0x33333333u) << 2) | ((k & 0xCCCCCCCCu) >> 2);
    k = ((k & 0x0F0F0F0Fu) << 4) | ((k & 0xF0F0F0F0u) >> 4);
    k = ((k & 0x00FF00FFu) << 8) | ((k & 0xFF00FF00u) >> 8);
    return (double)k * (1.0 / 4294967296.0);
}

typedef struct {
    double h[3];   /* half vector in the texel's frame */
    double weight; /* n.l */
    double lod;    /* pyramid level matched to the sample's solid angle */
} prefilter_sample;

/* The lobe's samples, the same in every texel's frame since n = v: half vectors h by the inverse CDF
 * of D(h) cos(theta_h) at Hammersley points, l = 2 (n.h) h - n with pdf(l) = D(h) / 4. */
static size_t prefilter_samples(const wenv_lobe *lobe, size_t count, size_t base_side, prefilter_sample *out)
{
    double texel_omega = 4.0 * M_PI / (double)(base_side * base_side);
    size_t kept = 0;
    for (size_t k = 0; k < count; k++) {
        double u1 = ((double)k + 0.5) / (double)count, phi = 2.0 * M_PI * radical_inverse2((uint32_t)k);
        double t = wenv_ndf_tan2_at(lobe->distribution, lobe->alpha, u1, 1.0 - u1);
        double ch = 1.0 / sqrt(1.0 + t), sh = sqrt(t) * ch;
        double nl = 2.0 * ch * ch - 1.0;
        if (!(nl > 0.0))
            continue;
        double pdf = 0.25 * wenv_ndf(lobe->distribution, lobe->alpha, ch);
        double lod = pdf > 0.0 ? 0.5 * log2(1.0 / ((double)count * pdf * texel_omega)) + 1.0 : 1e9;
        prefilter_sample *s = out + kept++;
        s->h[0] = sh * cos(phi);
        s->h[1] = sh * sin(phi);
        s->h[2] = ch;
        s->weight = nl;
        s->lod = lod;
    }
    return kept;
}

/* prefiltered maps for every lobe (out: n_lobes x side^2 x 3) */
static wenv_status prefilter_all(const wenv_splitsum *ss, const pyramid *src, const wenv_lobe *lobes, size_t n_lobes,
                                 float *out, const wenv_progress *progress, wenv_error *err)
{
    size_t P = ss->q.prefilter, nt = P * P, S = ss->q.samples;
    prefilter_sample *samples = malloc(S * sizeof *samples);
    if (!samples)
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for prefilter samples");
    atomic_int cancelled = 0;
    atomic_size_t done = 0;
    size_t total = nt * n_lobes;
    for (size_t l = 0; l < n_lobes && !cancelled; l++) {
        float *map = out + l * nt * 3;
        size_t same = l;
        for (size_t e = 0; e < l; e++)
            if (lobes[e].distribution == lobes[l].distribution && lobes[e].alpha == lobes[l].alpha)
                same = e;
        if (same != l) {
            memcpy(map, out + same * nt * 3, nt * 3 * sizeof(float));
            atomic_fetch_add(&done, nt);
            continue;
        }
        size_t kept = prefilter_samples(&lobes[l], S, src->side[0], samples);
#pragma omp parallel for schedule(dynamic, 16)
        for (size_t t = 0; t < nt; t++) {
            if (atomic_load(&cancelled))
                continue;
            double n[3], f[9];
            wenv_oct_decode(wenv_map_texel_center(P, t % P), wenv_map_texel_center(P, t / P), n);
            wenv_frame(n, f);
            double acc[3] = {0, 0, 0}, wsum = 0.0;
            for (size_t k = 0; k < kept; k++) {
                const prefilter_sample *s = samples + k;
                double h[3], L[3], rgb[3];
                for (int c = 0; c < 3; c++)
                    h[c] = s->h[0] * f[c] + s->h[1] * f[3 + c] + s->h[2] * f[6 + c];
                for (int c = 0; c < 3; c++)
                    L[c] = 2.0 * s->h[2] * h[c] - n[c];
                pyramid_fetch(src, L, s->lod, rgb);
                for (int c = 0; c < 3; c++)
                    acc[c] += s->weight * rgb[c];
                wsum += s->weight;
            }
            for (int c = 0; c < 3; c++)
                map[3 * t + c] = wsum > 0.0 ? (float)(acc[c] / wsum) : 0.0f;
            size_t d = atomic_fetch_add(&done, 1) + 1;
            if ((d & 255) == 0 && wenv_progress_step(progress, d, total))
                atomic_store(&cancelled, 1);
        }
    }
    free(samples);
    if (cancelled)
        return wenv_error_set(err, WENV_ERR_CANCELLED, "prefiltering cancelled");
    if (wenv_progress_finish(progress))
        return wenv_error_set(err, WENV_ERR_CANCELLED, "prefiltering cancelled");
    return WENV_OK;
}

static void update_bytes(wenv_splitsum *ss)
{
    size_t P = ss->q.prefilter;
    ss->stats.lobes = ss->n_lobes;
    ss->stats.prefilter_bytes = ss->prefilter ? ss->n_lobes * P * P * 3 * sizeof(float) : 0;
    ss->stats.lut_bytes = ss->n_lobes * ss->q.lut * 3 * sizeof(float);
    size_t source = 0; /* kept to prefilter again when the material changes */
    for (size_t k = 0; k < ss->src.levels; k++)
        source += ss->src.side[k] * ss->src.side[k] * 3 * sizeof(float);
    ss->stats.source_bytes = source;
}

static wenv_status set_environment(void *state, const wenv_envmap *env, const wenv_progress *progress,
                                          wenv_error *err)
{
    wenv_splitsum *ss = state;
    double t0 = wenv_now_seconds();
    pyramid src;
    double sh9[9 * 3];
    if (wenv_oct_pyramid_build(&src, env, NULL, 0, 512, 0, NULL, err))
        return err->status;
    if (wenv_sh_project_envmap(env, 2, sh9, NULL, err)) {
        wenv_oct_pyramid_free(&src);
        return err->status;
    }
    double t1 = wenv_now_seconds();
    float *pre = NULL;
    if (ss->have_mat && ss->n_lobes) {
        size_t P = ss->q.prefilter;
        pre = malloc(ss->n_lobes * P * P * 3 * sizeof(float));
        if (!pre) {
            wenv_oct_pyramid_free(&src);
            return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for prefiltered maps");
        }
        if (prefilter_all(ss, &src, ss->lobes, ss->n_lobes, pre, progress, err)) {
            free(pre);
            wenv_oct_pyramid_free(&src);
            return err->status;
        }
        free(ss->prefilter);
        ss->prefilter = pre;
        ss->stats.prefilter_seconds = wenv_now_seconds() - t1;
    }
    wenv_oct_pyramid_free(&ss->src);
    ss->src = src;
    memcpy(ss->irradiance_sh, sh9, sizeof sh9);
    ss->stats.environment_seconds = t1 - t0;
    ss->stats.source_side = src.side[0];
    ss->stats.source_levels = src.levels;
    ss->have_env = 1;
    update_bytes(ss);
    return WENV_OK;
}

#define LUT_ALBEDO_SAMPLES 64

static wenv_status set_material(void *state, const wenv_material *mat, const wenv_progress *progress,
                                       wenv_error *err)
{
    wenv_splitsum *ss = state;
    size_t nl = wenv_material_lobe_count(mat), N = ss->q.lut, P = ss->q.prefilter;
    wenv_lobe *lobes = malloc((nl ? nl : 1) * sizeof *lobes);
    float *lut = malloc((nl ? nl : 1) * N * 3 * sizeof(float));
    float *pre = NULL;
    if (!lobes || !lut) {
        free(lobes);
        free(lut);
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for the environment-BRDF table");
    }
    for (size_t l = 0; l < nl; l++)
        lobes[l] = *wenv_material_lobe(mat, l);
    double t0 = wenv_now_seconds();
    atomic_int failed = 0;
    wenv_error lut_err = {0};
#pragma omp parallel for schedule(dynamic, 1) collapse(2)
    for (size_t l = 0; l < nl; l++)
        for (size_t i = 0; i < N; i++) {
            double mu = ((double)i + 0.5) / (double)N, wo[3] = {sqrt(1.0 - mu * mu), 0.0, mu}, a[3] = {0.0, 0.0, 0.0};
            wenv_error e = {0};
            if (wenv_material_lobe_albedo(mat, l, wo, LUT_ALBEDO_SAMPLES, a, &e) != WENV_OK) {
#pragma omp critical(wenv_splitsum_lut)
                wenv_error_set(&lut_err, e.status, "%s", e.message);
                atomic_store(&failed, 1);
            }
            for (int c = 0; c < 3; c++)
                lut[(l * N + i) * 3 + (size_t)c] = (float)a[c];
        }
    if (failed) {
        free(lobes);
        free(lut);
        return wenv_error_set(err, lut_err.status, "%s", lut_err.message);
    }
    double t1 = wenv_now_seconds();
    if (ss->have_env && nl) {
        pre = malloc(nl * P * P * 3 * sizeof(float));
        if (!pre) {
            free(lobes);
            free(lut);
            return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for prefiltered maps");
        }
        if (prefilter_all(ss, &ss->src, lobes, nl, pre, progress, err)) {
            free(pre);
            free(lobes);
            free(lut);
            return err->status;
        }
        ss->stats.prefilter_seconds = wenv_now_seconds() - t1;
    }
    free(ss->lobes);
    free(ss->lut);
    free(ss->prefilter);
    ss->lobes = lobes;
    ss->lut = lut;
    ss->prefilter = pre;
    ss->n_lobes = nl;
    wenv_material_diffuse_table(mat, &ss->diffuse);
    ss->stats.lut_seconds = t1 - t0;
    ss->have_mat = 1;
    update_bytes(ss);
    return WENV_OK;
}

/* RGB entries at n.v = (i + 0.5) / N, linear in between. */
static inline void lut_lookup(const float *table, size_t N, double mu, double rgb[3])
{
    double x = mu * (double)N - 0.5, f = 0.0;
    size_t i = 0, j = 0;
    if (x >= (double)(N - 1)) {
        i = j = N - 1;
    } else if (x > 0.0) {
        i = (size_t)x;
        j = i + 1;
        f = x - (double)i;
    }
    const float *a = table + 3 * i, *b = table + 3 * j;
    for (int c = 0; c < 3; c++)
        rgb[c] = a[c] + f * (b[c] - a[c]);
}

static wenv_status shade(void *state, const float *normals, const float *views, size_t n,
                                float *out, float *irradiance, wenv_error *err)
{
    const wenv_splitsum *ss = state;
    if (!ss->have_env || !ss->have_mat)
        return wenv_error_set(err, WENV_ERR_VALUE, "the shader needs an environment and a material");
    size_t P = ss->q.prefilter, N = ss->q.lut;
    long long nn = (long long)n;
#pragma omp parallel for schedule(dynamic, 256)
    for (long long i = 0; i < nn; i++) {
        double nv3[3], v[3];
        wenv_unit_pair(normals, views, (size_t)i, nv3, v);
        float *o = out + 3 * i, *e_out = irradiance ? irradiance + 3 * i : NULL;
        double mu = nv3[0] * v[0] + nv3[1] * v[1] + nv3[2] * v[2];
        if (!(mu > 0.0)) {
            o[0] = o[1] = o[2] = 0.0f;
            if (e_out)
                e_out[0] = e_out[1] = e_out[2] = 0.0f;
            continue;
        }
        double irr[3], rgb[3];
        float d[3] = {0.0f, 0.0f, 0.0f};
        wenv_sh_irradiance(2, ss->irradiance_sh, nv3, irr);
        if (!e_out) /* else the Lambertian part is the caller's */
            wenv_diffuse_table_at(&ss->diffuse, (float)mu, d);
        for (int c = 0; c < 3; c++) {
            rgb[c] = d[c] * fmax(irr[c], 0.0);
            if (e_out)
                e_out[c] = (float)fmax(irr[c], 0.0);
        }
        if (ss->n_lobes) {
            double r[3] = {2.0 * mu * nv3[0] - v[0], 2.0 * mu * nv3[1] - v[1], 2.0 * mu * nv3[2] - v[2]}, u, w;
            wenv_oct_encode(r, &u, &w);
            for (size_t l = 0; l < ss->n_lobes; l++) {
                double pre[3];
                bilinear_fetch(ss->prefilter + l * P * P * 3, P, u, w, pre);
                double e[3];
                lut_lookup(ss->lut + l * N * 3, N, mu, e);
                for (int c = 0; c < 3; c++)
                    rgb[c] += e[c] * pre[c];
            }
        }
        for (int c = 0; c < 3; c++)
            o[c] = rgb[c] > 0.0 || e_out ? (float)rgb[c] : 0.0f;
    }
    return WENV_OK;
}

static size_t stats(const void *state, wenv_stat *out)
{
    const wenv_splitsum_stats s = ((const wenv_splitsum *)state)->stats;
    size_t k = 0;
    out[k++] = wenv_stat_count("lobes", s.lobes);
    out[k++] = wenv_stat_count("source_side", s.source_side);
    out[k++] = wenv_stat_count("source_levels", s.source_levels);
    out[k++] = wenv_stat_count("source_bytes", s.source_bytes);
    out[k++] = wenv_stat_count("prefilter_bytes", s.prefilter_bytes);
    out[k++] = wenv_stat_count("lut_bytes", s.lut_bytes);
    out[k++] = wenv_stat_real("environment_seconds", s.environment_seconds);
    out[k++] = wenv_stat_real("prefilter_seconds", s.prefilter_seconds);
    out[k++] = wenv_stat_real("lut_seconds", s.lut_seconds);
    return k;
}

const wenv_method WENV_METHOD_SPLIT_SUM = {
    .name = "split_sum",
    .summary = "prefiltered environment maps and an environment-BRDF table (Karis 2013), for comparison",
    .quality_size = sizeof(wenv_splitsum_quality),
    .params = PARAMS,
    .n_params = sizeof PARAMS / sizeof PARAMS[0],
    .presets = {&WENV_SPLIT_SUM_PRESETS[0], &WENV_SPLIT_SUM_PRESETS[1], &WENV_SPLIT_SUM_PRESETS[2]},
    .check_quality = check_quality,
    .create = create,
    .destroy = destroy,
    .set_environment = set_environment,
    .set_material = set_material,
    .shade = shade,
    .stats = stats,
};
