#include "methods/wavelet/lights.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "math/maps.h"

#define MAX_VIEW_TERMS 32 /* a layered material: 4 a lobe, 5 of its own */
/* A pixel seen through a lobe narrower than itself is integrated over its area on a grid of points
 * this many per lobe width (about: the lobe's width against the pixel's), up to MAX_SUBPIXELS a side. */
#define SUBPIXELS_PER_WIDTH 4.0f
#define MAX_SUBPIXELS 16

typedef struct {
    size_t count;
    float *dir;    /* count x 3, unit: the flux-weighted centre */
    float *flux;   /* count x 3: radiance x solid angle */
    float *vec;    /* count x 9: per channel, the sum of its pixels' flux x direction, so that
                    * irradiance, linear in the direction above the horizon, is exact for a cluster */
    float *sin_radius; /* count: sine of the angle about dir that holds every pixel centre in it */
    uint32_t *child;   /* count + 1 (levels >= 1): children are child[i] .. child[i + 1] - 1 below */
    float *extent; /* level 0 only, count x 6: each pixel's du, dv (wenv_bright_pixel) */
    float reach;   /* level 0: the largest |du| + |dv|, radians about: how far a pixel reaches */
} light_level;

struct wenv_lights {
    light_level level[WENV_LIGHT_LEVELS];
};

/* Plain comparisons: fminf/fmaxf are library calls on x86-64 (their NaN rules have no single
 * instruction), and these run per vertex and light. */
static inline float min_f(float a, float b) { return a < b ? a : b; }
static inline float max_f(float a, float b) { return a > b ? a : b; }
static inline float dot3(const float a[3], const float b[3]) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }

void wenv_lights_free(wenv_lights *lights)
{
    if (!lights)
        return;
    for (int k = 0; k < WENV_LIGHT_LEVELS; k++) {
        light_level *lv = &lights->level[k];
        free(lv->dir);
        free(lv->flux);
        free(lv->vec);
        free(lv->sin_radius);
        free(lv->child);
        free(lv->extent);
    }
    free(lights);
}

size_t wenv_lights_count(const wenv_lights *lights, int level)
{
    return lights && level >= 0 && level < WENV_LIGHT_LEVELS ? lights->level[level].count : 0;
}

static int alloc_level(light_level *lv, size_t n, int pixels)
{
    size_t room = n ? n : 1;
    lv->count = n;
    lv->dir = malloc(room * 3 * sizeof(float));
    lv->flux = malloc(room * 3 * sizeof(float));
    lv->vec = malloc(room * 9 * sizeof(float));
    lv->sin_radius = malloc(room * sizeof(float));
    lv->child = pixels ? NULL : malloc((n + 1) * sizeof(uint32_t));
    lv->extent = pixels ? malloc(room * 6 * sizeof(float)) : NULL;
    return lv->dir && lv->flux && lv->vec && lv->sin_radius && (pixels ? lv->extent != NULL : lv->child != NULL)
               ? 0
               : -1;
}

/* Greedy clustering, brightest first: each light of `below` joins the first cluster whose seed
 * lies within `radius` of it, or seeds a new one.  parent[i] gets light i's cluster; the clusters'
 * flux-weighted unit directions, summed fluxes and flux vectors go to cdir, cflux, cvec (room for
 * below->count).  Returns their number; (size_t)-1 when out of memory. */
static size_t cluster(const light_level *below, double radius, uint32_t *parent, float *cdir, float *cflux,
                      float *cvec)
{
    size_t n = below->count;
    size_t *seed = malloc((n ? n : 1) * sizeof *seed);
    double *acc = calloc((n ? n : 1) * 15, sizeof *acc); /* weighted direction, flux, flux vectors */
    if (!seed || !acc) {
        free(seed);
        free(acc);
        return (size_t)-1;
    }
    double cos_r = cos(radius);
    size_t nc = 0;
    for (size_t i = 0; i < n; i++) {
        const float *d = below->dir + 3 * i;
        size_t c = 0;
        while (c < nc) {
            const float *o = below->dir + 3 * seed[c];
            if ((double)d[0] * o[0] + (double)d[1] * o[1] + (double)d[2] * o[2] >= cos_r)
                break;
            c++;
        }
        if (c == nc)
            seed[nc++] = i;
        parent[i] = (uint32_t)c;
        const float *f = below->flux + 3 * i, *vec = below->vec + 9 * i;
        double *a = acc + 15 * c;
        for (int k = 0; k < 3; k++) {
            /* channels averaged: the flux-weighted direction */
            a[k] += ((double)vec[k] + vec[3 + k] + vec[6 + k]) / 3.0;
            a[3 + k] += f[k];
        }
        for (int k = 0; k < 9; k++)
            a[6 + k] += vec[k];
    }
    for (size_t c = 0; c < nc; c++) {
        double *a = acc + 15 * c, len = sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]);
        for (int k = 0; k < 3; k++) {
            /* a black cluster (all weights 0) keeps its seed's direction */
            cdir[3 * c + k] = len > 0.0 ? (float)(a[k] / len) : below->dir[3 * seed[c] + k];
            cflux[3 * c + k] = (float)a[3 + k];
        }
        for (int k = 0; k < 9; k++)
            cvec[9 * c + k] = (float)a[6 + k];
    }
    free(seed);
    free(acc);
    return nc;
}

/* Puts level k's lights in the order `order` gives (order[new] = old), carrying their children
 * ranges' old order along in `key` (the position each old light's parent now has). */
static int permute_level(light_level *lv, const size_t *order)
{
    size_t n = lv->count;
    light_level t = {0};
    if (alloc_level(&t, n, lv->extent != NULL))
        goto fail;
    for (size_t j = 0; j < n; j++) {
        size_t i = order[j];
        memcpy(t.dir + 3 * j, lv->dir + 3 * i, 3 * sizeof(float));
        memcpy(t.flux + 3 * j, lv->flux + 3 * i, 3 * sizeof(float));
        memcpy(t.vec + 9 * j, lv->vec + 9 * i, 9 * sizeof(float));
        t.sin_radius[j] = lv->sin_radius[i];
        if (lv->extent)
            memcpy(t.extent + 6 * j, lv->extent + 6 * i, 6 * sizeof(float));
    }
    free(lv->dir);
    free(lv->flux);
    free(lv->vec);
    free(lv->sin_radius);
    free(lv->extent);
    lv->dir = t.dir;
    lv->flux = t.flux;
    lv->vec = t.vec;
    lv->sin_radius = t.sin_radius;
    lv->extent = t.extent;
    free(t.child); /* the children ranges are filled by the caller */
    return 0;
fail:
    free(t.dir);
    free(t.flux);
    free(t.vec);
    free(t.sin_radius);
    free(t.child);
    free(t.extent);
    return -1;
}

wenv_status wenv_lights_create(wenv_lights **out, const wenv_bright_pixel *px, size_t n, wenv_error *err)
{
    *out = NULL;
    size_t room = n ? n : 1;
    wenv_lights *lights = calloc(1, sizeof *lights);
    /* per level above the pixels, each light's parent; a scratch for orders and positions */
    uint32_t *parent = malloc(room * WENV_LIGHT_LEVELS * sizeof *parent);
    size_t *order = malloc(room * sizeof *order), *pos = malloc(room * sizeof *pos), *next = malloc((room + 1) * sizeof *next);
    if (!lights || !parent || !order || !pos || !next)
        goto nomem;
    light_level *pixels = &lights->level[0];
    if (alloc_level(pixels, n, 1))
        goto nomem;
    for (size_t i = 0; i < n; i++) {
        memcpy(pixels->dir + 3 * i, px[i].dir, 3 * sizeof(float));
        memcpy(pixels->flux + 3 * i, px[i].flux, 3 * sizeof(float));
        memcpy(pixels->extent + 6 * i, px[i].du, 3 * sizeof(float));
        memcpy(pixels->extent + 6 * i + 3, px[i].dv, 3 * sizeof(float));
        const float *e = pixels->extent + 6 * i;
        float reach = sqrtf(dot3(e, e)) + sqrtf(dot3(e + 3, e + 3));
        pixels->reach = max_f(pixels->reach, reach);
        for (int c = 0; c < 3; c++)
            for (int k = 0; k < 3; k++)
                pixels->vec[9 * i + 3 * c + k] = px[i].flux[c] * px[i].dir[k];
        pixels->sin_radius[i] = 0.0f;
    }
    /* each level clusters the one below it, seeds brightest first */
    for (int k = 1; k < WENV_LIGHT_LEVELS; k++) {
        light_level *below = &lights->level[k - 1], *lv = &lights->level[k];
        if (alloc_level(lv, below->count, 0))
            goto nomem;
        uint32_t *par = parent + (size_t)(k - 1) * room;
        size_t nc = cluster(below, WENV_LIGHT_RADIUS(k), par, lv->dir, lv->flux, lv->vec);
        if (nc == (size_t)-1)
            goto nomem;
        lv->count = nc;
    }
    /* top down: order each level so that every cluster's children are consecutive below it */
    for (int k = WENV_LIGHT_LEVELS - 1; k >= 1; k--) {
        light_level *lv = &lights->level[k], *below = &lights->level[k - 1];
        const uint32_t *par = parent + (size_t)(k - 1) * room;
        /* pos[c]: where cluster c (in cluster order) now sits in level k; identity at the top */
        if (k == WENV_LIGHT_LEVELS - 1)
            for (size_t c = 0; c < lv->count; c++)
                pos[c] = c;
        /* counting sort of the lights below by their parent's position */
        memset(next, 0, (lv->count + 1) * sizeof *next);
        for (size_t i = 0; i < below->count; i++)
            next[pos[par[i]] + 1]++;
        for (size_t c = 0; c < lv->count; c++)
            next[c + 1] += next[c];
        for (size_t c = 0; c <= lv->count; c++)
            lv->child[c] = (uint32_t)next[c];
        for (size_t i = 0; i < below->count; i++)
            order[next[pos[par[i]]]++] = i;
        if (permute_level(below, order))
            goto nomem;
        /* the next level down finds its parents (lights of this one below) by their new places */
        for (size_t j = 0; j < below->count; j++)
            pos[order[j]] = j;
    }
    /* radii, bottom up: every pixel centre of a cluster lies within its sin_radius of its direction */
    for (int k = 1; k < WENV_LIGHT_LEVELS; k++) {
        light_level *lv = &lights->level[k], *below = &lights->level[k - 1];
        for (size_t c = 0; c < lv->count; c++) {
            double r = 0.0;
            for (uint32_t j = lv->child[c]; j < lv->child[c + 1]; j++) {
                const float *a = lv->dir + 3 * c, *b = below->dir + 3 * j;
                double d = fmax(-1.0, fmin(1.0, (double)a[0] * b[0] + (double)a[1] * b[1] + (double)a[2] * b[2]));
                r = fmax(r, acos(d) + asin(fmin(1.0, (double)below->sin_radius[j])));
            }
            /* a hair wider than measured, so float rounding in the tests never misjudges a light */
            r += 1e-4;
            lv->sin_radius[c] = r >= 0.5 * M_PI ? 1.0f : (float)sin(r);
        }
    }
    free(parent);
    free(order);
    free(pos);
    free(next);
    *out = lights;
    return WENV_OK;
nomem:
    wenv_lights_free(lights);
    free(parent);
    free(order);
    free(pos);
    free(next);
    return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for the exact lights");
}

/* Depth-first walk over the cluster tree: a stack of ranges of lights, one per level at most. */
typedef struct {
    int level;
    uint32_t next, end;
} tree_range;

void wenv_lights_irradiance(const wenv_lights *lights, const float n[3], float tolerance,
                            const wenv_light_visibility *vis, float e[3])
{
    const int top = WENV_LIGHT_LEVELS - 1;
    tree_range stack[WENV_LIGHT_LEVELS];
    int depth = 0;
    stack[depth++] = (tree_range){top, 0, (uint32_t)lights->level[top].count};
    while (depth) {
        tree_range *r = &stack[depth - 1];
        if (r->next == r->end) {
            depth--;
            continue;
        }
        const light_level *lv = &lights->level[r->level];
        uint32_t i = r->next++;
        const float *l = lv->dir + 3 * i, *vec = lv->vec + 9 * i, *flux = lv->flux + 3 * i;
        float ci = dot3(n, l), sr = lv->sin_radius[i];
        if (ci <= -sr)
            continue;
        /* across the horizon (|n.centre| < sin radius) a light's n.l is within 2 sin radius of 0:
         * those below subtract, or those above are missed, at most that x their flux */
        int whole = ci >= sr || r->level == 0 || 2.0f * (flux[0] + flux[1] + flux[2]) * sr <= tolerance;
        if (whole && (!vis || r->level == 0 ||
                      (sr <= vis->sin_radius_max && (sr <= vis->sin_radius_edge || !(ci > -sr && vis->at_edge(vis, l)))))) {
            float seen = ci > 0.0f && vis ? vis->visible(vis, l) : 1.0f;
            if (ci > 0.0f && seen > 0.0f) {
                e[0] += seen * max_f(0.0f, dot3(n, vec));
                e[1] += seen * max_f(0.0f, dot3(n, vec + 3));
                e[2] += seen * max_f(0.0f, dot3(n, vec + 6));
            }
            continue;
        }
        stack[depth++] = (tree_range){r->level - 1, lv->child[i], lv->child[i + 1]};
    }
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
    int have_terms;              /* terms and the one below are set */
    int use_float;               /* the terms fit: the float path (else the double one, rare) */
    const wenv_light_visibility *vis; /* what the scene lets through (NULL: everything) */
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

/* Light direction l (n.l = ci > 0, l.v = lv_dot) in the view's frame (+Z the normal, wo in xz). */
static inline void view_frame_dir(const specular_view *sv, float ci, float lv_dot, float wi[3])
{
    float co = sv->co, so = sv->so;
    float si = sqrtf(max_f(0.0f, 1.0f - ci * ci));
    float cphi = si * so > 1e-6f ? (lv_dot - ci * co) / (si * so) : 1.0f;
    cphi = min_f(1.0f, max_f(-1.0f, cphi));
    wi[0] = si * cphi;
    wi[1] = si * sqrtf(1.0f - cphi * cphi);
    wi[2] = ci;
}

static inline void prepare_terms(specular_view *sv)
{
    if (sv->have_terms)
        return;
    sv->use_float = wenv_material_view_terms(sv->mat) <= MAX_VIEW_TERMS;
    if (sv->use_float)
        wenv_material_prepare_view_f(sv->mat, sv->wo, sv->terms);
    sv->have_terms = 1;
}

/* The lobes' f cos for light direction l (n.l = ci > 0, l.v = lv_dot), into rgb. */
static inline void eval_light(specular_view *sv, float ci, float lv_dot, float rgb[3])
{
    float wi[3];
    view_frame_dir(sv, ci, lv_dot, wi);
    prepare_terms(sv);
    if (sv->use_float) {
        wenv_material_specular_cos_f_many(sv->mat, sv->wo, sv->terms, 1, &wi[0], &wi[1], &wi[2], &rgb[0], &rgb[1],
                                          &rgb[2]);
    } else {
        double wid[3] = {wi[0], wi[1], wi[2]}, wod[3] = {sv->wo[0], sv->wo[1], sv->wo[2]}, rgbd[3];
        wenv_material_specular_cos(sv->mat, wid, wod, rgbd);
        for (int c = 0; c < 3; c++)
            rgb[c] = (float)rgbd[c];
    }
}

/* Lights accepted by a vertex's walk, evaluated together (the model's batched float evaluator
 * runs several directions per instruction where the CPU allows). */
#define BATCH 64
typedef struct {
    size_t n;
    float x[BATCH], y[BATCH], z[BATCH];    /* wi in the view's frame */
    float fr[BATCH], fg[BATCH], fb[BATCH]; /* flux x weight */
    float r[BATCH], g[BATCH], b[BATCH];    /* f cos, filled by the evaluator */
} light_batch;

static void flush_batch(specular_view *sv, light_batch *lb, float s[3])
{
    size_t n = lb->n;
    if (!n)
        return;
    prepare_terms(sv);
    if (sv->use_float) {
        wenv_material_specular_cos_f_many(sv->mat, sv->wo, sv->terms, n, lb->x, lb->y, lb->z, lb->r, lb->g, lb->b);
    } else {
        double wod[3] = {sv->wo[0], sv->wo[1], sv->wo[2]};
        for (size_t k = 0; k < n; k++) {
            double wid[3] = {lb->x[k], lb->y[k], lb->z[k]}, rgbd[3];
            wenv_material_specular_cos(sv->mat, wid, wod, rgbd);
            lb->r[k] = (float)rgbd[0];
            lb->g[k] = (float)rgbd[1];
            lb->b[k] = (float)rgbd[2];
        }
    }
    float a0 = 0.0f, a1 = 0.0f, a2 = 0.0f;
    for (size_t k = 0; k < n; k++) {
        a0 += lb->r[k] * lb->fr[k];
        a1 += lb->g[k] * lb->fg[k];
        a2 += lb->b[k] * lb->fb[k];
    }
    s[0] += a0;
    s[1] += a1;
    s[2] += a2;
    lb->n = 0;
}

/* Queues light direction l (world; n.l = ci > 0, l.v = lv_dot) with `flux` x weight x how much of
 * it the scene lets through. */
static inline void push_light(specular_view *sv, light_batch *lb, const float l[3], float ci, float lv_dot,
                              const float flux[3], float weight, float s[3])
{
    if (sv->vis && !((weight *= sv->vis->visible(sv->vis, l)) > 0.0f))
        return;
    float wi[3];
    view_frame_dir(sv, ci, lv_dot, wi);
    size_t k = lb->n++;
    lb->x[k] = wi[0];
    lb->y[k] = wi[1];
    lb->z[k] = wi[2];
    lb->fr[k] = weight * flux[0];
    lb->fg[k] = weight * flux[1];
    lb->fb[k] = weight * flux[2];
    if (lb->n == BATCH)
        flush_batch(sv, lb, s);
}

/* A pixel wider than the lobe: its point at the centre would alias (a lobe narrower than a pixel
 * reflects it where its centre happens to fall), so its area is integrated on a grid of points as
 * the reference integrates narrow lobes over the pixels' areas.  Returns 0 if a point suffices. */
static inline int add_pixel_area(specular_view *sv, light_batch *lb, const float l[3], const float e[6],
                                  const float flux[3], float s[3])
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
            push_light(sv, lb, p, ci, lv_dot, flux, weight, s);
        }
    }
    return 1;
}

/* One pixel: a light off every lobe (n.h below the lobe's cut) costs a few dot products; one inside
 * is evaluated exactly in float, or over its area when the lobe is narrower than it. */
static inline void specular_pixel(const light_level *lv, size_t i, specular_view *sv, light_batch *lb, float s[3])
{
    const float *l = lv->dir + 3 * i, *flux = lv->flux + 3 * i;
    float ci = dot3(sv->n, l), lv_dot;
    if (!(ci > -sv->reach))
        return;
    float ch = cos_half(sv, l, ci, &lv_dot);
    if (!near_a_lobe(sv, ch, sv->slack))
        return;
    if (sv->reach > 0.0f && add_pixel_area(sv, lb, l, lv->extent + 6 * i, flux, s))
        return;
    if (!(ci > 0.0f) || !near_a_lobe(sv, ch, 0.0f))
        return;
    push_light(sv, lb, l, ci, lv_dot, flux, 1.0f, s);
}

/* A cluster is read at its flux-weighted centre, which is exact to first order; the second-order
 * error is about its flux x f cos x (radius / w)^2 (1 + 2 q) for a lobe w wide across (Gaussian
 * about the mirror direction, q its exponent at the centre).  The walk reads a cluster whole when
 * that is within the tolerance and its radius a fraction of the lobe's width, or when all of it lies
 * so far out in the lobe's tail that the whole cluster is within the tolerance; otherwise its
 * children. */
#define CLUSTER_WIDTH_FRACTION 0.5f

/* What the walk needs of the lobes about this vertex's mirror direction r. */
typedef struct {
    float r[3], across[3], along[3]; /* axes about r: across the plane of n and r, and along it */
    float w_across, inv_across, inv_along;
    float cone; /* cos of the cone about r outside which the lobes are negligible (-2: none) */
    float peak; /* about the lobes' largest f cos, RGB summed, with a margin */
    int centred; /* the lobes' width and tails bound a cluster's error */
    const float *envelope_lo, *envelope_hi; /* else, when given: the envelope's rows about cos_v */
} lobe_axes;

/* What a cluster whose nearest point lies `deviation` radians from the mirror direction can add per
 * unit flux, for lobes not modelled: the envelope's bin at or below it, the larger of the two views'. */
static inline float envelope_at(const lobe_axes *ax, float deviation)
{
    float pos = sqrtf(max_f(0.0f, deviation) * (float)(1.0 / M_PI)) * (float)(WENV_LIGHT_ENVELOPE_BINS - 1);
    size_t j = pos < (float)(WENV_LIGHT_ENVELOPE_BINS - 1) ? (size_t)pos : WENV_LIGHT_ENVELOPE_BINS - 1;
    return max_f(ax->envelope_lo[j], ax->envelope_hi[j]);
}

/* One walk over the cluster tree at absolute tolerance `tolerance`, adding to s. */
static void walk_clusters(const wenv_lights *lights, specular_view *sv, const lobe_axes *ax, float tolerance,
                          float s[3])
{
    light_batch lb;
    lb.n = 0;
    const int top = WENV_LIGHT_LEVELS - 1;
    tree_range stack[WENV_LIGHT_LEVELS];
    int depth = 0;
    stack[depth++] = (tree_range){top, 0, (uint32_t)lights->level[top].count};
    while (depth) {
        tree_range *rg = &stack[depth - 1];
        if (rg->next == rg->end) {
            depth--;
            continue;
        }
        int k = rg->level;
        const light_level *lv = &lights->level[k];
        uint32_t i = rg->next++;
        if (k == 0) {
            specular_pixel(lv, i, sv, &lb, s);
            continue;
        }
        const float *l = lv->dir + 3 * i, *flux = lv->flux + 3 * i;
        float sr = lv->sin_radius[i] + sv->reach, cr = sqrtf(max_f(0.0f, 1.0f - sr * sr));
        float ci = dot3(sv->n, l);
        if (ci <= -sr) /* wholly below the horizon */
            continue;
        float cd = dot3(ax->r, l), sd = sqrtf(max_f(0.0f, 1.0f - cd * cd));
        /* cos of the nearest angle to r: wholly outside every lobe's cone is skipped */
        float c_near = sd <= sr ? 1.0f : cd * cr + sd * sr;
        if (c_near < ax->cone)
            continue;
        float flux_sum = flux[0] + flux[1] + flux[2];
        int bounded = ax->centred || ax->envelope_lo;
        float bound = INFINITY, q = 0.0f, a = 0.0f, b = 0.0f;
        if (bounded) {
            /* the Gaussian exponent at the centre, in the lobe's widths along each axis */
            a = dot3(l, ax->across) * ax->inv_across;
            b = dot3(l, ax->along) * ax->inv_along;
            q = a * a + b * b;
        }
        if (ax->centred) {
            /* ... and at the cluster's point nearest the peak (each axis on its own); a Gaussian or
             * GGX tail falls at least as 1 / (1 + q)^2 */
            float an = max_f(0.0f, fabsf(a) - sr * ax->inv_across), bn = max_f(0.0f, fabsf(b) - sr * ax->inv_along);
            float t = 1.0f / (1.0f + an * an + bn * bn);
            /* behind the mirror direction (cd < 0) the lobe holds nothing of note */
            bound = cd > 0.0f ? flux_sum * ax->peak * t * t : 0.0f;
        } else if (ax->envelope_lo) {
            float deviation = acosf(min_f(1.0f, max_f(-1.0f, cd))) - asinf(min_f(1.0f, sr));
            bound = flux_sum * envelope_at(ax, deviation);
        }
        if (bound <= tolerance) {
            /* all of it is within the tolerance: its centre stands for it */
            float lv_dot;
            float ch = cos_half(sv, l, ci, &lv_dot);
            if (ci > 0.0f && near_a_lobe(sv, ch, 0.0f))
                push_light(sv, &lb, l, ci, lv_dot, flux, 1.0f, s);
            continue;
        }
        if (sv->vis && (lv->sin_radius[i] > sv->vis->sin_radius_max ||
                        (lv->sin_radius[i] > sv->vis->sin_radius_edge && sv->vis->at_edge(sv->vis, l)))) {
            /* one that matters, wider than the masks resolve or where a shadow's edge may cross it */
            stack[depth++] = (tree_range){k - 1, lv->child[i], lv->child[i + 1]};
            continue;
        }
        /* A cluster a fraction of the lobe's width across is read whole where its second-order
         * error is within the tolerance.  A table's lobe is bounded by its envelope, not by its
         * fitted shape's tail, which it only resembles (bounded by the shape: sunset, t0.1, 0.72 %
         * against 0.36 %); its width is the shape's, which holds for a retro-reflective lobe too:
         * every table's error within 0.1 point of reading every pixel (benchmarks/accuracy.py
         * --tables) at 5-15x fewer evaluations. */
        if (bounded && ci >= sr && sr <= CLUSTER_WIDTH_FRACTION * ax->w_across) {
            float x = sr * ax->inv_across;
            if (bound * x * x * (1.0f + 2.0f * q) <= tolerance) {
                push_light(sv, &lb, l, ci, dot3(l, sv->v), flux, 1.0f, s);
                continue;
            }
        }
        stack[depth++] = (tree_range){k - 1, lv->child[i], lv->child[i + 1]};
    }
    flush_batch(sv, &lb, s);
}

/* The peak and envelope tables' view i (cos_v uniform in sqrt from 0 to 1) in the normal's frame, its
 * mirror direction r and up, towards the normal in the plane of r and n (not normalised: its
 * length is returned). */
static float table_view(const wenv_material *mat, size_t i, specular_view *sv, float r[3], float up[3])
{
    float t = (float)i / (float)WENV_LIGHT_PEAK_SAMPLES, cos_v = max_f(1e-4f, t * t);
    *sv = (specular_view){.mat = mat, .n_lobes = wenv_material_lobe_count(mat), .co = cos_v};
    sv->so = sqrtf(max_f(0.0f, 1.0f - cos_v * cos_v));
    sv->n[2] = 1.0f;
    sv->v[0] = sv->wo[0] = sv->so;
    sv->v[2] = sv->wo[2] = cos_v;
    r[0] = -sv->so;
    r[1] = 0.0f;
    r[2] = cos_v;
    up[0] = sv->so * cos_v;
    up[1] = 0.0f;
    up[2] = 1.0f - cos_v * cos_v;
    return sqrtf(dot3(up, up));
}

void wenv_lights_peak_table(const wenv_material *mat, double alpha, float peak[WENV_LIGHT_PEAK_SAMPLES + 1])
{
    float m = (float)alpha;
    for (size_t i = 0; i <= WENV_LIGHT_PEAK_SAMPLES; i++) {
        specular_view sv;
        float r[3], up[3];
        /* at the mirror direction r and, towards grazing, where the cosine has grown before D falls
         * (about m above it) */
        float ul = table_view(mat, i, &sv, r, up), best = 0.0f;
        for (int k = 0; k < 3; k++) {
            float ang = 0.5f * (float)k * m, ca = cosf(ang), sa = ul > 1e-6f ? sinf(ang) / ul : 0.0f;
            float d[3] = {ca * r[0] + sa * up[0], ca * r[1] + sa * up[1], ca * r[2] + sa * up[2]};
            float rgb[3];
            if (!(d[2] > 0.0f))
                continue;
            eval_light(&sv, d[2], dot3(d, sv.v), rgb);
            best = max_f(best, rgb[0] + rgb[1] + rgb[2]);
        }
        peak[i] = 1.5f * best;
    }
}

/* Deviations sampled per bin, and azimuths about the mirror direction over half a turn (a light's
 * direction enters the lobes through n.l and l.v alone, view_frame_dir, so the other half repeats). */
#define ENVELOPE_STEPS 3
#define ENVELOPE_AZIMUTHS 16

void wenv_lights_envelope_table(const wenv_material *mat,
                                float envelope[(WENV_LIGHT_PEAK_SAMPLES + 1) * WENV_LIGHT_ENVELOPE_BINS])
{
#pragma omp parallel for schedule(dynamic, 1)
    for (size_t i = 0; i <= WENV_LIGHT_PEAK_SAMPLES; i++) {
        specular_view sv;
        float r[3], up[3];
        /* axes about the mirror direction r: up (normalised here) and across, +Y */
        float ul = table_view(mat, i, &sv, r, up);
        if (ul > 1e-6f) {
            for (int c = 0; c < 3; c++)
                up[c] /= ul;
        } else {
            up[0] = 1.0f;
            up[2] = 0.0f;
        }
        float *row = envelope + i * WENV_LIGHT_ENVELOPE_BINS;
        for (size_t j = 0; j < WENV_LIGHT_ENVELOPE_BINS; j++) {
            double lo = WENV_LIGHT_ENVELOPE_ANGLE(j);
            double hi = j + 1 < WENV_LIGHT_ENVELOPE_BINS ? WENV_LIGHT_ENVELOPE_ANGLE(j + 1) : lo;
            float best = 0.0f;
            for (int a = 0; a < ENVELOPE_STEPS; a++) {
                double dev = lo + (hi - lo) * (double)a / ENVELOPE_STEPS;
                float cd = (float)cos(dev), sd = (float)sin(dev);
                for (int k = 0; k <= ENVELOPE_AZIMUTHS; k++) {
                    double psi = M_PI * (double)k / ENVELOPE_AZIMUTHS;
                    float cp = (float)cos(psi), sp = (float)sin(psi), d[3], rgb[3];
                    d[0] = cd * r[0] + sd * cp * up[0];
                    d[1] = sd * sp;
                    d[2] = cd * r[2] + sd * cp * up[2];
                    if (!(d[2] > 0.0f))
                        continue;
                    eval_light(&sv, d[2], dot3(d, sv.v), rgb);
                    best = max_f(best, rgb[0] + rgb[1] + rgb[2]);
                }
            }
            row[j] = best;
        }
        /* a bin bounds every deviation from its own on */
        for (size_t j = WENV_LIGHT_ENVELOPE_BINS - 1; j-- > 0;)
            row[j] = max_f(row[j], row[j + 1]);
        for (size_t j = 0; j < WENV_LIGHT_ENVELOPE_BINS; j++)
            row[j] *= 1.5f;
    }
}

void wenv_lights_specular(const wenv_lights *lights, const wenv_material *mat, const float *cos_h_min,
                          const wenv_lights_lobe *lobe, const float n[3], const float v[3], float cos_v,
                          float tolerance, const wenv_light_visibility *vis, float s[3])
{
    specular_view sv = {.mat = mat, .n_lobes = wenv_material_lobe_count(mat), .cos_h_min = cos_h_min, .co = cos_v,
                        .vis = vis};
    memcpy(sv.n, n, sizeof sv.n);
    memcpy(sv.v, v, sizeof sv.v);
    /* any frame with +Z the normal will do: the lobes are isotropic */
    sv.so = sqrtf(max_f(0.0f, 1.0f - cos_v * cos_v));
    sv.wo[0] = sv.so;
    sv.wo[1] = 0.0f;
    sv.wo[2] = cos_v;
    const light_level *pixels = &lights->level[0];
    double cone_cos = lobe->cone_cos;
    lobe_axes ax = {.centred = lobe->modelled};
    /* across the mirror direction a lobe of roughness m is about 2 m cos(theta_v) wide, squeezed
     * against the horizon (to about m^2 / 4 at it), and 2 m along it */
    float m = (float)lobe->alpha, w_across = 2.0f * m * cos_v + 0.25f * m * m, w_along = 2.0f * m;
    if (lobe->narrow && 2.0f * SUBPIXELS_PER_WIDTH * pixels->reach > w_across) {
        /* pixels wider than the lobe: their extents are read, and a pixel whose centre is off the
         * lobe by less than its reach may still meet it.  Near the mirror direction n.h moves by
         * up to the light's displacement over 2 n.v; the cone about it widens by the reach. */
        sv.subpixel_scale = 2.0f * SUBPIXELS_PER_WIDTH / w_across;
        sv.reach = pixels->reach;
        sv.slack = (float)fmin(2.0, pixels->reach / (2.0 * fmax(cos_v, 1e-3)) + 1e-6);
        if (cone_cos > -1.0) {
            double cone = acos(fmin(1.0, cone_cos)) + pixels->reach;
            cone_cos = cone >= M_PI ? -1.0 : cos(cone);
        }
    }
    float *r = ax.r, *across = ax.across, *along = ax.along;
    for (int c = 0; c < 3; c++)
        r[c] = 2.0f * cos_v * n[c] - v[c];
    across[0] = n[1] * r[2] - n[2] * r[1];
    across[1] = n[2] * r[0] - n[0] * r[2];
    across[2] = n[0] * r[1] - n[1] * r[0];
    float len = sqrtf(dot3(across, across));
    if (len > 1e-6f) {
        for (int c = 0; c < 3; c++)
            across[c] /= len;
    } else { /* the view along the normal: the lobe is round */
        w_across = w_along = min_f(w_across, w_along);
        float a[3] = {fabsf(r[0]) < 0.9f ? 1.0f : 0.0f, fabsf(r[0]) < 0.9f ? 0.0f : 1.0f, 0.0f};
        float d = dot3(a, r);
        for (int c = 0; c < 3; c++)
            across[c] = a[c] - d * r[c];
        len = sqrtf(dot3(across, across));
        for (int c = 0; c < 3; c++)
            across[c] /= len;
    }
    along[0] = r[1] * across[2] - r[2] * across[1];
    along[1] = r[2] * across[0] - r[0] * across[2];
    along[2] = r[0] * across[1] - r[1] * across[0];
    ax.w_across = w_across;
    ax.inv_across = 1.0f / w_across;
    ax.inv_along = 1.0f / w_along;
    ax.cone = cone_cos > -1.0 ? (float)cone_cos : -2.0f;
    if (ax.centred) {
        /* between two samples the larger, the table's margin covering the change within a step */
        float pos = sqrtf(max_f(0.0f, min_f(1.0f, cos_v))) * (float)WENV_LIGHT_PEAK_SAMPLES;
        size_t at = (size_t)pos;
        at = at < WENV_LIGHT_PEAK_SAMPLES ? at : WENV_LIGHT_PEAK_SAMPLES - 1;
        ax.peak = max_f(lobe->peak[at], lobe->peak[at + 1]);
    } else if (lobe->envelope) {
        float pos = sqrtf(max_f(0.0f, min_f(1.0f, cos_v))) * (float)WENV_LIGHT_PEAK_SAMPLES;
        size_t at = (size_t)pos;
        at = at < WENV_LIGHT_PEAK_SAMPLES ? at : WENV_LIGHT_PEAK_SAMPLES - 1;
        ax.envelope_lo = lobe->envelope + at * WENV_LIGHT_ENVELOPE_BINS;
        ax.envelope_hi = ax.envelope_lo + WENV_LIGHT_ENVELOPE_BINS;
    }
    walk_clusters(lights, &sv, &ax, tolerance, s);
}
