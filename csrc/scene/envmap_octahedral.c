#include "scene/envmap_octahedral.h"

#include <math.h>
#include <omp.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "math/maps.h"
#include "math/vector_math.h"

static void supersample_texel(const wenv_envmap *env, size_t side, size_t t, float *rgb)
{
    const size_t k = 4;
    double h = 2.0 / (double)side, acc[3] = {0, 0, 0};
    for (size_t q = 0; q < k * k; q++) {
        double d[3];
        float c[3];
        wenv_oct_decode(-1.0 + h * ((double)(t % side) + ((double)(q % k) + 0.5) / (double)k),
                        -1.0 + h * ((double)(t / side) + ((double)(q / k) + 0.5) / (double)k), d);
        wenv_envmap_lookup(env, d, c);
        for (int i = 0; i < 3; i++)
            acc[i] += c[i];
    }
    for (int i = 0; i < 3; i++)
        rgb[i] = (float)(acc[i] / (double)(k * k));
}

static int splats(const wenv_envmap *env, size_t side)
{
    return wenv_envmap_width(env) * wenv_envmap_height(env) >= 2 * side * side;
}

/* First index in the ascending list a[0..n) whose value is at least x. */
static size_t lower_bound(const size_t *a, size_t n, size_t x)
{
    size_t lo = 0, hi = n;
    while (lo < hi) {
        size_t mid = lo + (hi - lo) / 2;
        if (a[mid] < x)
            lo = mid + 1;
        else
            hi = mid;
    }
    return lo;
}

/* A map the image is too coarse to splat onto: 4 x 4 lookups per texel, excluded pixels black. */
static wenv_status supersample_map(const wenv_envmap *env, size_t side, float *texels, const size_t *excluded,
                                   size_t n_excluded, wenv_error *err)
{
    /* a coarse image is looked up, so excluded pixels are blacked out in a copy */
    wenv_envmap *residual = NULL;
    if (n_excluded) {
        size_t npix = wenv_envmap_width(env) * wenv_envmap_height(env);
        float *px = malloc(npix * 3 * sizeof(float));
        if (!px)
            return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory filtering the environment");
        memcpy(px, wenv_envmap_pixels(env), npix * 3 * sizeof(float));
        for (size_t e = 0; e < n_excluded; e++)
            px[3 * excluded[e]] = px[3 * excluded[e] + 1] = px[3 * excluded[e] + 2] = 0.0f;
        wenv_status st = wenv_envmap_create(&residual, px, wenv_envmap_height(env), wenv_envmap_width(env), 3,
                                            wenv_envmap_projection(env), wenv_envmap_rotation(env),
                                            wenv_envmap_strength(env), err);
        free(px);
        if (st)
            return st;
    }
    const wenv_envmap *src = residual ? residual : env;
    size_t nt = side * side;
#pragma omp parallel for schedule(dynamic, 64)
    for (size_t t = 0; t < nt; t++)
        supersample_texel(src, side, t, texels + 3 * t);
    wenv_envmap_free(residual);
    return WENV_OK;
}

/* flux r g b and solid angle of a texel, summed in one vector; in double, so that the sums (then
 * rounded to float) do not depend on how the rows were split between threads */
typedef double flux4 __attribute__((vector_size(4 * sizeof(double))));

/* One row's samples splatted onto every map (accumulators one after another), the pixel's flux
 * and solid angle as one vector: a single AVX instruction per tap where the CPU has it. */
WENV_VECTOR_CLONES
static void splat_row(const float *dirs, const float *flux, const float *omega, size_t n, const size_t *sides,
                      size_t n_sides, flux4 *acc)
{
    for (size_t p = 0; p < n; p++) {
        float u, v, wt[4];
        uint32_t idx[4];
        flux4 f = {(double)flux[3 * p], (double)flux[3 * p + 1], (double)flux[3 * p + 2], (double)omega[p]};
        wenv_oct_encode_f(dirs + 3 * p, &u, &v);
        flux4 *a = acc;
        for (size_t k = 0; k < n_sides; k++) {
            wenv_oct_bilinear_f((long)sides[k], u, v, idx, wt);
            for (int c = 0; c < 4; c++)
                a[idx[c]] += (double)wt[c] * f;
            a += sides[k] * sides[k];
        }
    }
}

wenv_status wenv_oct_from_envmap_sides(const wenv_envmap *env, size_t count, const size_t *sides, float *const *texels,
                                       const size_t *excluded, size_t n_excluded, wenv_error *err)
{
    /* maps of sides the image is too coarse to splat onto are looked up */
    if (count > WENV_OCT_SIDES_MAX)
        return wenv_error_set(err, WENV_ERR_VALUE, "at most %d octahedral maps in one pass, not %zu", WENV_OCT_SIDES_MAX,
                              count);
    size_t splat_sides[WENV_OCT_SIDES_MAX], splat_of[WENV_OCT_SIDES_MAX], n_splat = 0, acc_texels = 0;
    for (size_t k = 0; k < count; k++) {
        if (!splats(env, sides[k])) {
            wenv_status st = supersample_map(env, sides[k], texels[k], excluded, n_excluded, err);
            if (st)
                return st;
            continue;
        }
        splat_of[n_splat] = k;
        splat_sides[n_splat++] = sides[k];
        acc_texels += sides[k] * sides[k];
    }
    if (!n_splat)
        return WENV_OK;
    int threads = omp_get_max_threads();
    size_t w = wenv_envmap_width(env), h = wenv_envmap_height(env);
    /* One accumulator per thread, and each image row sampled into a small per-thread buffer and
     * splatted at once: this runs over every pixel at each lighting change, and materialising
     * every pixel's sample would stream tens of megabytes through memory.  Aligned as the vector
     * type (AVX loads it whole). */
    flux4 *acc = aligned_alloc(sizeof(flux4), (size_t)threads * acc_texels * sizeof(flux4));
    if (!acc)
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory filtering the environment");
    int failed = 0, used = 1;
#pragma omp parallel num_threads(threads) reduction(| : failed)
    {
        /* each thread clears its own accumulator (and so first touches its pages); the region may
         * get fewer threads than asked, and only theirs are summed */
        if (omp_get_thread_num() == 0)
            used = omp_get_num_threads();
        flux4 *mine = acc + (size_t)omp_get_thread_num() * acc_texels;
        memset(mine, 0, acc_texels * sizeof(flux4));
        float *dirs = malloc(w * 7 * sizeof(float)), *flux = NULL, *omega = NULL;
        uint32_t *cols = malloc(w * sizeof(uint32_t));
        failed = !dirs || !cols;
        if (dirs) {
            flux = dirs + 3 * w;
            omega = dirs + 6 * w;
        }
#pragma omp for schedule(static)
        for (size_t row = 0; row < h; row++) {
            if (!dirs || !cols)
                continue;
            size_t n = wenv_envmap_row_samples(env, row, dirs, flux, omega, cols);
            /* excluded pixels: black, solid angle kept (both lists ascend, so one walk) */
            size_t e = lower_bound(excluded, n_excluded, row * w), end = lower_bound(excluded, n_excluded, (row + 1) * w);
            for (size_t p = 0; p < n && e < end; p++) {
                while (e < end && excluded[e] < row * w + cols[p])
                    e++;
                if (e < end && excluded[e] == row * w + cols[p])
                    flux[3 * p] = flux[3 * p + 1] = flux[3 * p + 2] = 0.0f;
            }
            splat_row(dirs, flux, omega, n, splat_sides, n_splat, mine);
        }
        free(dirs);
        free(cols);
    }
    if (failed) {
        free(acc);
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory filtering the environment");
    }
#pragma omp parallel for schedule(static)
    for (size_t e = 0; e < acc_texels; e++)
        for (int t = 1; t < used; t++)
            acc[e] += acc[(size_t)t * acc_texels + e];
    const flux4 *a = acc;
    for (size_t k = 0; k < n_splat; k++) {
        size_t side = splat_sides[k], nt = side * side;
        float *out = texels[splat_of[k]];
#pragma omp parallel for schedule(dynamic, 64)
        for (size_t t = 0; t < nt; t++) {
            if (a[t][3] > 0.0) {
                for (int c = 0; c < 3; c++)
                    out[3 * t + c] = (float)(a[t][c] / a[t][3]);
            } else {
                supersample_texel(env, side, t, out + 3 * t);
            }
        }
        a += nt;
    }
    free(acc);
    return WENV_OK;
}

wenv_status wenv_oct_from_envmap(const wenv_envmap *env, size_t side, float *texels, const size_t *excluded,
                                 size_t n_excluded, wenv_error *err)
{
    return wenv_oct_from_envmap_sides(env, 1, &side, &texels, excluded, n_excluded, err);
}

void wenv_oct_pyramid_free(wenv_oct_pyramid *p)
{
    free(p->texels[0]); /* every level lives in level 0's block */
    memset(p, 0, sizeof *p);
}

size_t wenv_oct_pyramid_bytes(const wenv_oct_pyramid *p)
{
    size_t b = 0;
    for (size_t k = 0; k < p->levels; k++)
        b += p->side[k] * p->side[k] * 3 * sizeof(float);
    return b;
}

wenv_status wenv_oct_pyramid_build(wenv_oct_pyramid *p, const wenv_envmap *env, const size_t *excluded, size_t n_excluded,
                                   size_t max_side, size_t also_side, float *also_texels, wenv_error *err)
{
    memset(p, 0, sizeof *p);
    double npix = (double)(wenv_envmap_width(env) * wenv_envmap_height(env));
    size_t base = 64;
    while (base < max_side && (double)(base * base) < npix)
        base *= 2;
    while (base > 2 && base > max_side)
        base /= 2;
    /* one block, level after level, so a lookup can address any level from one base */
    size_t total = 0;
    for (size_t s = base; s >= 2; s /= 2) {
        p->side[p->levels++] = s;
        total += s * s * 3;
    }
    float *block = malloc(total * sizeof(float));
    if (!block) {
        memset(p, 0, sizeof *p);
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for the environment pyramid");
    }
    for (size_t k = 0, at = 0; k < p->levels; k++) {
        p->texels[k] = block + at;
        at += p->side[k] * p->side[k] * 3;
    }
    size_t sides[2] = {base, also_side};
    float *maps[2] = {p->texels[0], also_texels};
    if (wenv_oct_from_envmap_sides(env, also_texels ? 2 : 1, sides, maps, excluded, n_excluded, err)) {
        wenv_oct_pyramid_free(p);
        return err->status;
    }
    /* each level averages the one below over solid angle; a coarse texel's is the sum of its four */
    double *omega = malloc((base * base + (base / 2) * (base / 2)) * sizeof(double));
    if (!omega) {
        wenv_oct_pyramid_free(p);
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for the environment pyramid");
    }
    double *fine_omega = omega, *coarse_omega = omega + base * base;
    wenv_oct_texel_solid_angles(base, fine_omega);
    for (size_t k = 1; k < p->levels; k++) {
        size_t s = p->side[k], fs = p->side[k - 1];
        const float *fine = p->texels[k - 1];
        float *coarse = p->texels[k];
#pragma omp parallel for schedule(static)
        for (size_t t = 0; t < s * s; t++) {
            size_t i = t % s, j = t / s;
            double acc[3] = {0, 0, 0}, wsum = 0.0;
            for (size_t c = 0; c < 4; c++) {
                size_t f = (2 * j + (c >> 1)) * fs + 2 * i + (c & 1);
                for (int ch = 0; ch < 3; ch++)
                    acc[ch] += fine_omega[f] * fine[3 * f + ch];
                wsum += fine_omega[f];
            }
            for (int ch = 0; ch < 3; ch++)
                coarse[3 * t + ch] = (float)(acc[ch] / wsum);
            coarse_omega[t] = wsum;
        }
        /* the next level reads this one's: its sums move to the front of the scratch */
        memmove(fine_omega, coarse_omega, s * s * sizeof(double));
    }
    free(omega);
    return WENV_OK;
}
