#include "methods/wavelet/lights.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "math/maps.h"

/* Octahedral direction bins per side: 64 bins of about 0.2 sr, so a narrow lobe's cone meets a few. */
#define BIN_SIDE 8
#define BINS (BIN_SIDE * BIN_SIDE)
/* Levels with fewer lights than this skip the bin tests: testing every light is as cheap. */
#define FEW_LIGHTS 32
#define MAX_VIEW_TERMS 32 /* a layered material: 4 a lobe, 5 of its own */
/* A pixel seen through a lobe narrower than itself is integrated over its area on a grid of points
 * this many per lobe width (about: the lobe's width against the pixel's), up to MAX_SUBPIXELS a side. */
#define SUBPIXELS_PER_WIDTH 4.0f
#define MAX_SUBPIXELS 16

typedef struct {
    size_t count;
    float *dir;  /* count x 3, unit, grouped by bin */
    float *flux; /* count x 3: radiance x solid angle */
    float *span; /* count: |flux-weighted mean direction| of its pixels (1 for a pixel), so that
                  * irradiance, linear in the direction above the horizon, stays exact */
    float *extent; /* level 0 only, count x 6: each pixel's du, dv (wenv_bright_pixel) */
    float reach;   /* level 0: the largest |du| + |dv|, radians about: how far a pixel reaches */
    size_t offset[BINS + 1];
    float axis[BINS * 3];               /* each bin's bounding cone ... */
    float cos_radius[BINS], sin_radius[BINS]; /* ... and its half-angle */
} light_level;

struct wenv_lights {
    light_level level[WENV_LIGHT_LEVELS];
};

/* Plain comparisons: fminf/fmaxf are library calls on x86-64 (their NaN rules have no single
 * instruction), and these run per vertex and light. */
static inline float min_f(float a, float b) { return a < b ? a : b; }
static inline float max_f(float a, float b) { return a > b ? a : b; }

void wenv_lights_free(wenv_lights *lights)
{
    if (!lights)
        return;
    for (int k = 0; k < WENV_LIGHT_LEVELS; k++) {
        free(lights->level[k].dir);
        free(lights->level[k].flux);
        free(lights->level[k].span);
        free(lights->level[k].extent);
    }
    free(lights);
}

size_t wenv_lights_count(const wenv_lights *lights, int level)
{
    return lights && level >= 0 && level < WENV_LIGHT_LEVELS ? lights->level[level].count : 0;
}

int wenv_lights_level(double width)
{
    for (int k = WENV_LIGHT_LEVELS - 1; k > 0; k--)
        if (WENV_LIGHT_RADIUS(k) <= WENV_LIGHT_WIDTH_FRACTION * width)
            return k;
    return 0;
}

static size_t bin_of(const float d[3])
{
    return wenv_oct_texel_f(d, BIN_SIDE);
}

/* Fills a level from n lights (directions, fluxes, spans and, for the pixels, extents), sorting
 * them into bins. */
static int fill_level(light_level *lv, const float *dir, const float *flux, const float *span, const float *extent,
                      size_t n)
{
    lv->count = n;
    lv->dir = malloc((n ? n : 1) * 3 * sizeof(float));
    lv->flux = malloc((n ? n : 1) * 3 * sizeof(float));
    lv->span = malloc((n ? n : 1) * sizeof(float));
    lv->extent = extent ? malloc((n ? n : 1) * 6 * sizeof(float)) : NULL;
    size_t *bin = malloc((n ? n : 1) * sizeof(size_t));
    if (!lv->dir || !lv->flux || !lv->span || (extent && !lv->extent) || !bin) {
        free(bin);
        return -1;
    }
    size_t next[BINS];
    memset(lv->offset, 0, sizeof lv->offset);
    for (size_t i = 0; i < n; i++) {
        bin[i] = bin_of(dir + 3 * i);
        lv->offset[bin[i] + 1]++;
    }
    for (size_t b = 0; b < BINS; b++)
        lv->offset[b + 1] += lv->offset[b];
    memcpy(next, lv->offset, sizeof next);
    for (size_t i = 0; i < n; i++) {
        size_t j = next[bin[i]]++;
        memcpy(lv->dir + 3 * j, dir + 3 * i, 3 * sizeof(float));
        memcpy(lv->flux + 3 * j, flux + 3 * i, 3 * sizeof(float));
        lv->span[j] = span[i];
        if (extent) {
            memcpy(lv->extent + 6 * j, extent + 6 * i, 6 * sizeof(float));
            const float *e = extent + 6 * i;
            float reach = sqrtf(e[0] * e[0] + e[1] * e[1] + e[2] * e[2]) + sqrtf(e[3] * e[3] + e[4] * e[4] + e[5] * e[5]);
            lv->reach = max_f(lv->reach, reach);
        }
    }
    free(bin);
    for (size_t b = 0; b < BINS; b++) {
        double a[3] = {0.0, 0.0, 0.0};
        for (size_t j = lv->offset[b]; j < lv->offset[b + 1]; j++)
            for (int c = 0; c < 3; c++)
                a[c] += lv->dir[3 * j + c];
        double len = sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]);
        double cr = 1.0;
        if (len > 0.0) {
            for (int c = 0; c < 3; c++)
                lv->axis[3 * b + c] = (float)(a[c] / len);
            for (size_t j = lv->offset[b]; j < lv->offset[b + 1]; j++) {
                const float *d = lv->dir + 3 * j, *x = lv->axis + 3 * b;
                double dot = (double)d[0] * x[0] + (double)d[1] * x[1] + (double)d[2] * x[2];
                cr = dot < cr ? dot : cr;
            }
        } else { /* empty, or lights cancelling out: a cone that takes in everything */
            lv->axis[3 * b] = lv->axis[3 * b + 1] = 0.0f;
            lv->axis[3 * b + 2] = 1.0f;
            cr = lv->offset[b + 1] > lv->offset[b] ? -1.0 : 1.0;
        }
        /* a hair wider than measured, so float rounding in the test never drops a light */
        double r = fmin(M_PI, acos(fmax(-1.0, fmin(1.0, cr))) + 1e-4);
        lv->cos_radius[b] = (float)cos(r);
        lv->sin_radius[b] = (float)sin(r);
    }
    return 0;
}

/* Greedy clustering, brightest first: each light joins the first cluster whose seed lies within
 * `radius` of it, or seeds a new one.  Writes the clusters' flux-weighted unit directions, spans
 * and summed fluxes (room for n) and returns their number; (size_t)-1 when out of memory. */
static size_t cluster(const float *dir, const float *flux, const float *span, size_t n, double radius, float *cdir,
                      float *cflux, float *cspan)
{
    size_t *seed = malloc((n ? n : 1) * sizeof *seed);
    double *acc = calloc((n ? n : 1) * 6, sizeof *acc); /* weighted direction, flux */
    if (!seed || !acc) {
        free(seed);
        free(acc);
        return (size_t)-1;
    }
    double cos_r = cos(radius);
    size_t nc = 0;
    for (size_t i = 0; i < n; i++) {
        const float *d = dir + 3 * i;
        size_t c = 0;
        while (c < nc) {
            const float *o = dir + 3 * seed[c];
            if ((double)d[0] * o[0] + (double)d[1] * o[1] + (double)d[2] * o[2] >= cos_r)
                break;
            c++;
        }
        if (c == nc)
            seed[nc++] = i;
        const float *f = flux + 3 * i;
        double w = ((double)f[0] + f[1] + f[2]) / 3.0;
        for (int k = 0; k < 3; k++) {
            acc[6 * c + k] += w * span[i] * d[k];
            acc[6 * c + 3 + k] += f[k];
        }
    }
    for (size_t c = 0; c < nc; c++) {
        double *a = acc + 6 * c, len = sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]);
        double w = (a[3] + a[4] + a[5]) / 3.0;
        cspan[c] = len > 0.0 && w > 0.0 ? (float)fmin(1.0, len / w) : 1.0f;
        for (int k = 0; k < 3; k++) {
            /* a black cluster (all weights 0) keeps its seed's direction */
            cdir[3 * c + k] = len > 0.0 ? (float)(a[k] / len) : dir[3 * seed[c] + k];
            cflux[3 * c + k] = (float)a[3 + k];
        }
    }
    free(seed);
    free(acc);
    return nc;
}

wenv_status wenv_lights_create(wenv_lights **out, const wenv_bright_pixel *px, size_t n, wenv_error *err)
{
    *out = NULL;
    size_t room = n ? n : 1;
    wenv_lights *lights = calloc(1, sizeof *lights);
    /* two sets of (direction, flux, span): the level below, and the one being clustered from it;
     * then the pixels' extents */
    float *buf = malloc(room * 20 * sizeof(float));
    if (!lights || !buf)
        goto nomem;
    float *dir = buf, *flux = buf + 3 * room, *span = buf + 6 * room;
    float *cdir = buf + 7 * room, *cflux = buf + 10 * room, *cspan = buf + 13 * room, *extent = buf + 14 * room;
    for (size_t i = 0; i < n; i++) {
        memcpy(dir + 3 * i, px[i].dir, 3 * sizeof(float));
        memcpy(flux + 3 * i, px[i].flux, 3 * sizeof(float));
        memcpy(extent + 6 * i, px[i].du, 3 * sizeof(float));
        memcpy(extent + 6 * i + 3, px[i].dv, 3 * sizeof(float));
        span[i] = 1.0f;
    }
    if (fill_level(&lights->level[0], dir, flux, span, extent, n))
        goto nomem;
    /* each level clusters the one below it, in the order its seeds were made (brightest first) */
    size_t m = n;
    for (int k = 1; k < WENV_LIGHT_LEVELS; k++) {
        size_t nc = cluster(dir, flux, span, m, WENV_LIGHT_RADIUS(k), cdir, cflux, cspan);
        if (nc == (size_t)-1 || fill_level(&lights->level[k], cdir, cflux, cspan, NULL, nc))
            goto nomem;
        float *t;
        t = dir, dir = cdir, cdir = t;
        t = flux, flux = cflux, cflux = t;
        t = span, span = cspan, cspan = t;
        m = nc;
    }
    free(buf);
    *out = lights;
    return WENV_OK;
nomem:
    wenv_lights_free(lights);
    free(buf);
    return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for the exact lights");
}

/* Whether bin b's cone meets the cone of half-angle alpha (cos_a, sin_a) about axis x. */
static inline int bin_meets(const light_level *lv, size_t b, const float x[3], float cos_a, float sin_a)
{
    float cr = lv->cos_radius[b], sr = lv->sin_radius[b];
    if (cos_a <= -cr) /* alpha + radius >= pi */
        return 1;
    const float *a = lv->axis + 3 * b;
    return a[0] * x[0] + a[1] * x[1] + a[2] * x[2] >= cos_a * cr - sin_a * sr;
}

static inline void irradiance_range(const light_level *lv, size_t begin, size_t end, const float n[3], float e[3])
{
    for (size_t i = begin; i < end; i++) {
        const float *l = lv->dir + 3 * i, *flux = lv->flux + 3 * i;
        float ci = n[0] * l[0] + n[1] * l[1] + n[2] * l[2];
        if (!(ci > 0.0f))
            continue;
        ci *= lv->span[i];
        e[0] += ci * flux[0];
        e[1] += ci * flux[1];
        e[2] += ci * flux[2];
    }
}

void wenv_lights_irradiance(const wenv_lights *lights, int level, const float n[3], float e[3])
{
    const light_level *lv = &lights->level[level];
    if (lv->count < FEW_LIGHTS) {
        irradiance_range(lv, 0, lv->count, n, e);
        return;
    }
    for (size_t b = 0; b < BINS; b++)
        if (lv->offset[b] < lv->offset[b + 1] && bin_meets(lv, b, n, 0.0f, 1.0f))
            irradiance_range(lv, lv->offset[b], lv->offset[b + 1], n, e);
}

/* The view's terms, computed once per vertex (and only if a light is near a lobe). */
typedef struct {
    const wenv_material *mat;
    size_t n_lobes;
    const float *cos_h_min;
    float n[3], v[3], wo[3], co, so;
    float subpixel_scale; /* points per radian of a pixel's extent (0: pixels are points) */
    float reach;          /* how far a pixel may reach from its centre (0: pixels are points) */
    float slack;          /* how far a pixel's centre may lie outside a lobe's n.h cut and still meet it */
    float terms[MAX_VIEW_TERMS]; /* the material's, for this view */
    int have_terms;              /* terms and the two below are set */
    int use_float;               /* the terms fit: the float path (else the double one, rare) */
    wenv_specular_cos_f_fn specular_cos_f;
} specular_view;

static inline int near_a_lobe(const specular_view *sv, float ch, float slack)
{
    int near = 0;
    for (size_t k = 0; k < sv->n_lobes; k++)
        near |= ch >= sv->cos_h_min[k] - slack;
    return near;
}

/* n.h for light direction l, with l.v into *lv_dot; -2 when l and v are opposite (no half vector). */
static inline float cos_half(const specular_view *sv, const float l[3], float ci, float *lv_dot)
{
    const float *v = sv->v;
    *lv_dot = l[0] * v[0] + l[1] * v[1] + l[2] * v[2];
    float h2 = 2.0f + 2.0f * *lv_dot;
    return h2 > 1e-12f ? (ci + sv->co) / sqrtf(h2) : -2.0f;
}

/* The lobes' f cos for light direction l (n.l = ci > 0, l.v = lv_dot) times `flux` x weight, added to s. */
static inline void add_light(specular_view *sv, float ci, float lv_dot, const float flux[3], float weight, float s[3])
{
    const wenv_material *mat = sv->mat;
    float co = sv->co, so = sv->so;
    float si = sqrtf(max_f(0.0f, 1.0f - ci * ci));
    float cphi = si * so > 1e-6f ? (lv_dot - ci * co) / (si * so) : 1.0f;
    cphi = min_f(1.0f, max_f(-1.0f, cphi));
    float wi[3] = {si * cphi, si * sqrtf(1.0f - cphi * cphi), ci}, rgb[3];
    if (!sv->have_terms) {
        sv->use_float = wenv_material_view_terms(mat) <= MAX_VIEW_TERMS;
        if (sv->use_float)
            wenv_material_prepare_view_f(mat, sv->wo, sv->terms);
        sv->specular_cos_f = wenv_material_specular_cos_f_fn(mat);
        sv->have_terms = 1;
    }
    if (sv->use_float) {
        sv->specular_cos_f(mat, wi, sv->wo, sv->terms, rgb);
    } else {
        double wid[3] = {wi[0], wi[1], wi[2]}, wod[3] = {sv->wo[0], sv->wo[1], sv->wo[2]}, rgbd[3];
        wenv_material_specular_cos(mat, wid, wod, rgbd);
        for (int c = 0; c < 3; c++)
            rgb[c] = (float)rgbd[c];
    }
    s[0] += weight * rgb[0] * flux[0];
    s[1] += weight * rgb[1] * flux[1];
    s[2] += weight * rgb[2] * flux[2];
}

/* A pixel wider than the lobe: its point at the centre would alias (a lobe narrower than a pixel
 * reflects it where its centre happens to fall), so its area is integrated on a grid of points as
 * the reference integrates narrow lobes over the pixels' areas.  Returns 0 if a point suffices. */
static inline int add_pixel_area(specular_view *sv, const float l[3], const float e[6], const float flux[3], float s[3])
{
    float lu = sqrtf(e[0] * e[0] + e[1] * e[1] + e[2] * e[2]), lv = sqrtf(e[3] * e[3] + e[4] * e[4] + e[5] * e[5]);
    int nu = (int)min_f((float)MAX_SUBPIXELS, ceilf(sv->subpixel_scale * lu));
    int nv = (int)min_f((float)MAX_SUBPIXELS, ceilf(sv->subpixel_scale * lv));
    nu = nu < 1 ? 1 : nu;
    nv = nv < 1 ? 1 : nv;
    if (nu * nv == 1)
        return 0;
    const float *n = sv->n;
    float weight = 1.0f / (float)(nu * nv);
    for (int b = 0; b < nv; b++) {
        float fb = (2.0f * (float)b + 1.0f) / (float)nv - 1.0f;
        for (int a = 0; a < nu; a++) {
            float fa = (2.0f * (float)a + 1.0f) / (float)nu - 1.0f, p[3];
            for (int c = 0; c < 3; c++)
                p[c] = l[c] + fa * e[c] + fb * e[3 + c];
            float inv = 1.0f / sqrtf(p[0] * p[0] + p[1] * p[1] + p[2] * p[2]);
            p[0] *= inv;
            p[1] *= inv;
            p[2] *= inv;
            float ci = n[0] * p[0] + n[1] * p[1] + n[2] * p[2], lv_dot;
            if (!(ci > 0.0f) || !near_a_lobe(sv, cos_half(sv, p, ci, &lv_dot), 0.0f))
                continue;
            add_light(sv, ci, lv_dot, flux, weight, s);
        }
    }
    return 1;
}

/* A light off every lobe (n.h below the lobe's cut) costs a few dot products; one inside is
 * evaluated exactly in float. */
static inline void specular_range(const light_level *lv, size_t begin, size_t end, specular_view *sv, float s[3])
{
    const float *n = sv->n;
    float slack = sv->slack;
    for (size_t i = begin; i < end; i++) {
        const float *l = lv->dir + 3 * i, *flux = lv->flux + 3 * i;
        float ci = n[0] * l[0] + n[1] * l[1] + n[2] * l[2], lv_dot;
        if (!(ci > -sv->reach))
            continue;
        float ch = cos_half(sv, l, ci, &lv_dot);
        if (!near_a_lobe(sv, ch, slack))
            continue;
        if (sv->reach > 0.0f && add_pixel_area(sv, l, lv->extent + 6 * i, flux, s))
            continue;
        if (!(ci > 0.0f) || !near_a_lobe(sv, ch, 0.0f))
            continue;
        add_light(sv, ci, lv_dot, flux, 1.0f, s);
    }
}

void wenv_lights_specular(const wenv_lights *lights, int level, const wenv_material *mat, const float *cos_h_min,
                          double cone_cos, double narrow_width, const float n[3], const float v[3], float cos_v,
                          float s[3])
{
    const light_level *lv = &lights->level[level];
    specular_view sv = {.mat = mat, .n_lobes = wenv_material_lobe_count(mat), .cos_h_min = cos_h_min, .co = cos_v};
    memcpy(sv.n, n, sizeof sv.n);
    memcpy(sv.v, v, sizeof sv.v);
    /* any frame with +Z the normal will do: the lobes are isotropic */
    sv.so = sqrtf(max_f(0.0f, 1.0f - cos_v * cos_v));
    sv.wo[0] = sv.so;
    sv.wo[1] = 0.0f;
    sv.wo[2] = cos_v;
    if (lv->extent && narrow_width > 0.0 && 2.0 * SUBPIXELS_PER_WIDTH * lv->reach > narrow_width) {
        /* pixels wider than the lobe: their extents are read, and a pixel whose centre is off the
         * lobe by less than its reach may still meet it.  Near the mirror direction n.h moves by
         * up to the light's displacement over 2 n.v; the cone about it widens by the reach. */
        sv.subpixel_scale = (float)(2.0 * SUBPIXELS_PER_WIDTH / narrow_width);
        sv.reach = lv->reach;
        sv.slack = (float)fmin(2.0, lv->reach / (2.0 * fmax(cos_v, 1e-3)) + 1e-6);
        if (cone_cos > -1.0) {
            double cone = acos(fmin(1.0, cone_cos)) + lv->reach;
            cone_cos = cone >= M_PI ? -1.0 : cos(cone);
        }
    }
    if (lv->count < FEW_LIGHTS || cone_cos <= -1.0) {
        specular_range(lv, 0, lv->count, &sv, s);
        return;
    }
    float r[3] = {2.0f * cos_v * n[0] - v[0], 2.0f * cos_v * n[1] - v[1], 2.0f * cos_v * n[2] - v[2]};
    float cos_a = (float)cone_cos, sin_a = (float)sqrt(fmax(0.0, 1.0 - cone_cos * cone_cos));
    for (size_t b = 0; b < BINS; b++)
        if (lv->offset[b] < lv->offset[b + 1] && bin_meets(lv, b, r, cos_a, sin_a))
            specular_range(lv, lv->offset[b], lv->offset[b + 1], &sv, s);
}
