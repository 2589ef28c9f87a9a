/* Shading with the scene in the way (shadows.h). */
#include "methods/wavelet/shadows.h"

#include <math.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>

#include "math/frame.h"
#include "math/maps.h"

/* Each texel's cosine integral is summed over SUBTEXELS^2 exact sub-texel solid angles; each view's
 * lobes are binned from their node rules of NODE_SAMPLES divisions (2 x 32^2 nodes a lobe). */
#define SUBTEXELS 8
#define NODE_SAMPLES 32

void wenv_texel_reflection_free(wenv_texel_reflection *t)
{
    free(t->specular);
    free(t->cosine);
    free(t->direction);
    free(t->footprint);
    memset(t, 0, sizeof *t);
}

/* The texel of an r x r hemi-octahedral map that local direction d (z > 0) falls in. */
static inline size_t texel_of(const float d[3], size_t r)
{
    float u, v;
    wenv_hemi_encode_f(d, &u, &v);
    long n = (long)r, i = (long)((u + 1.0f) * 0.5f * (float)n), j = (long)((v + 1.0f) * 0.5f * (float)n);
    i = i < 0 ? 0 : (i > n - 1 ? n - 1 : i);
    j = j < 0 ? 0 : (j > n - 1 ? n - 1 : j);
    return (size_t)(j * n + i);
}

wenv_status wenv_texel_reflection_make(wenv_texel_reflection *out, const wenv_material *mat, size_t resolution,
                                       wenv_error *err)
{
    memset(out, 0, sizeof *out);
    size_t r = resolution, texels = r * r, views = WENV_TEXEL_REFLECTION_VIEWS, n_lobes = wenv_material_lobe_count(mat);
    out->resolution = r;
    out->views = views;
    out->cosine = calloc(texels, sizeof *out->cosine);
    out->direction = malloc(texels * 3 * sizeof *out->direction);
    out->footprint = malloc(texels * sizeof *out->footprint);
    out->specular = calloc(views * views * texels * 3, sizeof *out->specular);
    if (!out->cosine || !out->direction || !out->footprint || !out->specular) {
        wenv_texel_reflection_free(out);
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for the shadows' texel reflection");
    }
    for (size_t t = 0; t < texels; t++) {
        double d[3];
        wenv_occlusion_texel_direction(r, t, d);
        for (int c = 0; c < 3; c++)
            out->direction[3 * t + (size_t)c] = (float)d[c];
        out->footprint[t] = 0.5f * log2f((float)wenv_hemi_texel_solid_angle(r, t % r, t / r));
    }
    size_t fine = r * SUBTEXELS;
    for (size_t fj = 0; fj < fine; fj++)
        for (size_t fi = 0; fi < fine; fi++) {
            double d[3];
            wenv_hemi_decode(wenv_map_texel_center(fine, fi), wenv_map_texel_center(fine, fj), d);
            out->cosine[(fj / SUBTEXELS) * r + fi / SUBTEXELS] +=
                (float)(wenv_hemi_texel_solid_angle(fine, fi, fj) * (d[2] > 0.0 ? d[2] : 0.0));
        }
    if (!n_lobes) {
        free(out->specular);
        out->specular = NULL;
        return WENV_OK;
    }
    atomic_int failed = 0;
    wenv_error first = {0};
    long long nv = (long long)(views * views);
#pragma omp parallel
    {
        size_t max = 2 * NODE_SAMPLES * NODE_SAMPLES;
        double *wi = malloc(max * 3 * sizeof *wi), *weight = malloc(max * 3 * sizeof *weight);
        wenv_error local = {0};
        if (!wi || !weight)
            atomic_store(&failed, 1);
#pragma omp for schedule(dynamic, 4)
        for (long long q = 0; q < nv; q++) {
            if (atomic_load(&failed))
                continue;
            double wo[3];
            wenv_hemi_decode(wenv_map_texel_center(views, (size_t)q % views), wenv_map_texel_center(views, (size_t)q / views),
                             wo);
            float *row = out->specular + (size_t)q * texels * 3;
            for (size_t l = 0; l < n_lobes; l++) {
                size_t count = 0;
                if (wenv_material_lobe_nodes(mat, l, wo, NODE_SAMPLES, wi, weight, &count, &local)) {
#pragma omp critical(wenv_texel_reflection_error)
                    if (first.status == WENV_OK)
                        first = local;
                    atomic_store(&failed, 1);
                    break;
                }
                for (size_t k = 0; k < count; k++) {
                    float d[3] = {(float)wi[3 * k], (float)wi[3 * k + 1], (float)wi[3 * k + 2]};
                    if (!(d[2] > 0.0f))
                        continue;
                    float *t = row + 3 * texel_of(d, r);
                    for (int c = 0; c < 3; c++)
                        t[c] += (float)weight[3 * k + (size_t)c];
                }
            }
            /* as shares of the albedo: the vertex's own albedo scales them, exact in its view where
             * the grid's is not (towards grazing the albedo climbs faster than views interpolate) */
            double sum[3] = {0.0, 0.0, 0.0};
            for (size_t t = 0; t < texels; t++)
                for (int c = 0; c < 3; c++)
                    sum[c] += row[3 * t + (size_t)c];
            for (size_t t = 0; t < texels; t++)
                for (int c = 0; c < 3; c++)
                    row[3 * t + (size_t)c] = sum[c] > 0.0 ? (float)(row[3 * t + (size_t)c] / sum[c]) : 0.0f;
        }
        free(wi);
        free(weight);
    }
    if (failed) {
        wenv_texel_reflection_free(out);
        if (first.status != WENV_OK)
            return wenv_error_set(err, first.status, "%s", first.message);
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for the shadows' texel reflection");
    }
    return WENV_OK;
}

/* ---- one vertex -------------------------------------------------------------------------------- */

/* The mask's bits of the blocked texels, word w (the last word's unused bits cleared). */
static inline uint64_t blocked_bits(const wenv_vertex_shadow *vs, size_t w, size_t texels)
{
    uint64_t bits = ~vs->mask[w];
    size_t left = texels - 64 * w;
    return left >= 64 ? bits : bits & (((uint64_t)1 << left) - 1);
}

/* Calls body(t, k) for each blocked texel t, k counting them from 0. */
#define FOR_EACH_BLOCKED(vs, texels, body)                                            \
    do {                                                                              \
        size_t k_ = 0;                                                                \
        for (size_t w_ = 0; 64 * w_ < (texels); w_++)                                 \
            for (uint64_t b_ = blocked_bits((vs), w_, (texels)); b_; b_ &= b_ - 1) {  \
                size_t t = 64 * w_ + (size_t)__builtin_ctzll(b_), k = k_++;           \
                body;                                                                 \
            }                                                                         \
    } while (0)

static inline int texel_open(const wenv_vertex_shadow *vs, size_t t)
{
    return (int)((vs->mask[t / 64] >> (t % 64)) & 1u);
}

/* Whether direction l (in the method's frame) lies above the vertex's horizon: the z that
 * texels_about computes, and its test. */
static inline int above_horizon(const wenv_vertex_shadow *vs, const float l[3])
{
    const float *f = vs->frame;
    return f[6] * l[0] + f[7] * l[1] + f[8] * l[2] > 0.0f;
}

/* How many of the mask's texels about direction l (in the method's frame) are open and blocked: its
 * texel and the eight around it.  0 and 0 below the horizon. */
static void texels_about(const wenv_vertex_shadow *vs, const float l[3], int *open, int *shut)
{
    const float *f = vs->frame;
    float d[3] = {f[0] * l[0] + f[1] * l[1] + f[2] * l[2], f[3] * l[0] + f[4] * l[1] + f[5] * l[2],
                  f[6] * l[0] + f[7] * l[1] + f[8] * l[2]};
    *open = *shut = 0;
    if (!(d[2] > 0.0f))
        return;
    long n = (long)vs->resolution;
    size_t at = texel_of(d, vs->resolution);
    long i = (long)at % n, j = (long)at / n;
    for (long b = j - 1; b <= j + 1; b++)
        for (long a = i - 1; a <= i + 1; a++) {
            if (a < 0 || b < 0 || a >= n || b >= n)
                continue;
            if (texel_open(vs, (size_t)(b * n + a)))
                (*open)++;
            else
                (*shut)++;
        }
}

static int light_at_edge(const wenv_light_visibility *vis, const float l[3])
{
    int open, shut;
    texels_about((const wenv_vertex_shadow *)vis, l, &open, &shut);
    return open && shut;
}

/* Direction l: what the mask says where its texels about l agree (unless the occlusion asks for
 * point rays), else a ray, whose answer is kept in the vertex's memo if `keep` (a light's
 * direction, the same at every view; not a mirror direction, which each view moves). */
static float visible_along(const wenv_vertex_shadow *vs, const float l[3], int keep)
{
    if (!above_horizon(vs, l))
        return 0.0f; /* below the horizon it brings nothing anyway */
    if (!vs->point_rays) { /* point rays ask no mask */
        int open, shut;
        texels_about(vs, l, &open, &shut);
        if (!shut || !open)
            return open ? 1.0f : 0.0f;
    }
    int known = keep && vs->memo_slot ? wenv_light_memo_find(vs->memo_slot, l) : -1;
    if (known >= 0)
        return (float)known;
    const float *t = vs->turn; /* the ray is cast in the world */
    float world[3] = {t[0] * l[0] + t[3] * l[1] + t[6] * l[2], t[1] * l[0] + t[4] * l[1] + t[7] * l[2],
                      t[2] * l[0] + t[5] * l[1] + t[8] * l[2]};
    unsigned char hit;
    wenv_occluders_test(vs->occluders, vs->origin, world, 1, INFINITY, &hit);
    if (keep && vs->memo_slot)
        wenv_light_memo_put(vs->memo, vs->memo_slot, l, !hit);
    return hit ? 0.0f : 1.0f;
}

/* A light in direction l (the lights' walk). */
static float light_visible(const wenv_light_visibility *vis, const float l[3])
{
    return visible_along((const wenv_vertex_shadow *)vis, l, 1);
}

int wenv_shadow_lobes_narrow(double alpha_max, size_t resolution)
{
    /* a lobe about 4 alpha across within half a texel (pi / r across) */
    return alpha_max < M_PI / (8.0 * (double)resolution);
}

/* How many blocked texels come before texel t in texel order. */
static size_t blocked_before(const wenv_vertex_shadow *vs, size_t t)
{
    size_t count = 0;
    for (size_t w = 0; w < t / 64; w++)
        count += (size_t)__builtin_popcountll(~vs->mask[w]);
    uint64_t below = t % 64 ? (((uint64_t)1 << (t % 64)) - 1) : 0;
    return count + (size_t)__builtin_popcountll(~vs->mask[t / 64] & below);
}

/* A direction's visibility for a narrow lobe: open below the mask's horizon, where the lobe's light
 * is the unshadowed shading's (as a mirror direction there always was). */
static float lobe_direction_open(const wenv_vertex_shadow *vs, const float l[3])
{
    if (!above_horizon(vs, l))
        return 1.0f;
    return visible_along(vs, l, 0);
}

/* The rings of a narrow lobe's rays: half vectors at the GGX slope quantiles xi (tan theta_h =
 * alpha sqrt(xi / (1 - xi))), each ring standing for an equal share of the lobe's microfacets.  The
 * nine first; rings of 6, 10, 14, ... rays at xi = (g + 1/2) / rings where they disagree. */
typedef struct {
    float xi;
    int count;
} lobe_ring;
static const lobe_ring NINE_RAYS[] = {{0.25f, 3}, {0.75f, 6}};
enum { NINE = 9, RING_RAYS_FIRST = 6, RING_RAYS_STEP = 4 };
#define LOBE_RAYS_MAX                                                                                          \
    (WENV_LOBE_RINGS_MAX * RING_RAYS_FIRST + RING_RAYS_STEP * WENV_LOBE_RINGS_MAX * (WENV_LOBE_RINGS_MAX - 1) / 2)

/* A lobe's rays: their directions (the method's frame), weights, and which a blocker stops. */
typedef struct {
    size_t count;
    float dir[3 * LOBE_RAYS_MAX], weight[LOBE_RAYS_MAX];
    unsigned char blocked[LOBE_RAYS_MAX];
    int any_blocked, any_open;
} lobe_rays;

static void cast_lobe_rays(const wenv_vertex_shadow *vs, const float n[3], const float v[3], float alpha,
                           const lobe_ring *ring, size_t rings, lobe_rays *out)
{
    /* a tangent frame about n (Duff et al. 2017, branchless) */
    float sign = n[2] >= 0.0f ? 1.0f : -1.0f, a = -1.0f / (sign + n[2]), b = n[0] * n[1] * a;
    float t[3] = {1.0f + sign * n[0] * n[0] * a, sign * b, -sign * n[0]}, u[3] = {b, sign + n[1] * n[1] * a, -n[1]};
    float world[3 * LOBE_RAYS_MAX];
    unsigned char above[LOBE_RAYS_MAX], hit[LOBE_RAYS_MAX];
    size_t count = 0, cast = 0;
    for (size_t g = 0; g < rings; g++) {
        float slope = alpha * sqrtf(ring[g].xi / (1.0f - ring[g].xi));
        float weight = 1.0f / ((float)rings * (float)ring[g].count);
        for (int k = 0; k < ring[g].count; k++) {
            /* every other ring turned by half a step, so that together they cover the azimuths */
            float phi = 2.0f * (float)M_PI * ((float)k + 0.5f * (float)(g % 2)) / (float)ring[g].count;
            float h[3], len = 0.0f;
            for (int c = 0; c < 3; c++) {
                h[c] = n[c] + slope * (cosf(phi) * t[c] + sinf(phi) * u[c]);
                len += h[c] * h[c];
            }
            len = sqrtf(len);
            float vh = (v[0] * h[0] + v[1] * h[1] + v[2] * h[2]) / len, *d = out->dir + 3 * count;
            for (int c = 0; c < 3; c++)
                d[c] = 2.0f * vh * h[c] / len - v[c];
            float cos_i = d[0] * n[0] + d[1] * n[1] + d[2] * n[2];
            if (!(vh > 0.0f) || !(cos_i > 0.0f))
                continue; /* facing away, or reflected below the surface: no light either way */
            /* the half vectors are drawn as D(h) cos(theta_h) is: each direction's share of f cos is
             * then G (v.h) / (n.h) up to what all share; G's light-side factor (Smith's, GGX) keeps
             * the rays near the horizon, where blockers stand, from counting as much as the rest */
            float tan2_i = (1.0f - cos_i * cos_i) / (cos_i * cos_i);
            out->weight[count] = weight * vh * len * 2.0f / (1.0f + sqrtf(1.0f + alpha * alpha * tan2_i));
            const float *f = vs->frame, *turn = vs->turn;
            above[count] = f[6] * d[0] + f[7] * d[1] + f[8] * d[2] > 0.0f; /* below the mask's horizon: open */
            if (above[count]) {
                for (int c = 0; c < 3; c++) /* the rays are cast in the world */
                    world[3 * cast + (size_t)c] = turn[c] * d[0] + turn[3 + c] * d[1] + turn[6 + c] * d[2];
                cast++;
            }
            count++;
        }
    }
    /* one call for the lobe's rays: Embree takes rays from one origin as a coherent stream */
    if (cast)
        wenv_occluders_test(vs->occluders, vs->origin, world, cast, INFINITY, hit);
    out->count = count;
    out->any_blocked = out->any_open = 0;
    for (size_t k = 0, c = 0; k < count; k++) {
        out->blocked[k] = above[k] && hit[c++];
        out->any_blocked |= out->blocked[k];
        out->any_open |= !out->blocked[k];
    }
}

/* The share of a narrow lobe (alpha, about the mirror direction r of view v at normal n) that reaches
 * the sky, in [0, 1], as wenv_shadow_narrow_specular reads it; below the mask's horizon is open.
 * With rays and a pyramid, lit[c] gets the share of what the lobe reflects of the lighting in
 * channel c that reaches it: each ray weighted by the lighting along it too, so that a blocker
 * hiding the bright part of what a lobe sees takes that part's light, not the lobe's mean share of
 * it (the uniform lighting the geometric share assumes).  Otherwise lit[c] is the geometric share. */
static float lobe_visible(const wenv_vertex_shadow *vs, const wenv_node_pyramid *pyramid, const float n[3],
                          const float v[3], const float r[3], float alpha, size_t fine_rings, float lit[3])
{
    lobe_rays rays;
    rays.count = 0;
    if (vs->point_rays && alpha >= WENV_LOBE_RAYS_ALPHA_MIN)
        cast_lobe_rays(vs, n, v, alpha, NINE_RAYS, sizeof NINE_RAYS / sizeof NINE_RAYS[0], &rays);
    if (!rays.count) {
        float open = lobe_direction_open(vs, r);
        lit[0] = lit[1] = lit[2] = open;
        return open;
    }
    if (!rays.any_blocked) {
        lit[0] = lit[1] = lit[2] = 1.0f;
        return 1.0f;
    }
    size_t used = NINE;
    if (rays.any_open && fine_rings) {
        /* a blocker's edge crosses the lobe: where it lies, and what light it hides, is read finer */
        lobe_ring ring[WENV_LOBE_RINGS_MAX];
        used = 0;
        for (size_t g = 0; g < fine_rings; g++) {
            ring[g] = (lobe_ring){((float)g + 0.5f) / (float)fine_rings, RING_RAYS_FIRST + RING_RAYS_STEP * (int)g};
            used += (size_t)ring[g].count;
        }
        cast_lobe_rays(vs, n, v, alpha, ring, fine_rings, &rays);
    }
    /* the lighting along each ray is read only for a lobe something blocks, at the ray's share of
     * the lobe's reflected cone (about 2 alpha in radius) */
    float log2_footprint = log2f(2.0f * alpha * sqrtf((float)M_PI / (float)used));
    float seen = 0.0f, total = 0.0f, light_seen[3] = {0.0f, 0.0f, 0.0f}, light_total[3] = {0.0f, 0.0f, 0.0f};
    for (size_t k = 0; k < rays.count; k++) {
        float along[3] = {1.0f, 1.0f, 1.0f}, w = rays.weight[k];
        if (pyramid)
            wenv_node_pyramid_read(pyramid, rays.dir + 3 * k, log2_footprint, along);
        total += w;
        seen += rays.blocked[k] ? 0.0f : w;
        for (int c = 0; c < 3; c++) {
            light_total[c] += w * along[c];
            light_seen[c] += rays.blocked[k] ? 0.0f : w * along[c];
        }
    }
    float open = total > 0.0f ? seen / total : lobe_direction_open(vs, r);
    for (int c = 0; c < 3; c++) /* a channel the lighting leaves black along every ray: the geometric share */
        lit[c] = light_total[c] > 0.0f ? light_seen[c] / light_total[c] : open;
    return open;
}

void wenv_shadow_narrow_specular(const wenv_vertex_shadow *vs, const wenv_node_pyramid *pyramid, const float *lbar,
                                 const float *hidden, const float n[3], const float v[3], float cos_v, float alpha,
                                 size_t fine_rings, const float albedo[3], float s[3])
{
    float r[3], lit[3];
    for (int c = 0; c < 3; c++)
        r[c] = 2.0f * cos_v * n[c] - v[c];
    float seen = lobe_visible(vs, pyramid, n, v, r, alpha, fine_rings, lit);
    if (seen >= 1.0f)
        return;
    const float *f = vs->frame;
    float d[3] = {f[0] * r[0] + f[1] * r[1] + f[2] * r[2], f[3] * r[0] + f[4] * r[1] + f[5] * r[2],
                  f[6] * r[0] + f[7] * r[1] + f[8] * r[2]};
    /* the blocker's light through the mirror direction's texel, or the mean of the blocked ones about it */
    long side = (long)vs->resolution;
    size_t at = texel_of(d, vs->resolution);
    long i = (long)at % side, j = (long)at / side;
    float back[3] = {0.0f, 0.0f, 0.0f};
    int count = 0;
    for (int ring = 0; ring <= 1 && !count; ring++)
        for (long b = j - ring; b <= j + ring; b++)
            for (long a = i - ring; a <= i + ring; a++) {
                if (a < 0 || b < 0 || a >= side || b >= side || texel_open(vs, (size_t)(b * side + a)))
                    continue;
                size_t k = blocked_before(vs, (size_t)(b * side + a));
                for (int c = 0; c < 3; c++)
                    back[c] += lbar[3 * k + (size_t)c] - hidden[3 * k + (size_t)c];
                count++;
            }
    for (int c = 0; c < 3; c++)
        s[c] = lit[c] * s[c] + (1.0f - seen) * (count ? albedo[c] * back[c] / (float)count : 0.0f);
}

void wenv_vertex_shadow_init(wenv_vertex_shadow *vs, const wenv_shadow_scene *scene, size_t i, wenv_light_memo *memo)
{
    const wenv_occlusion *o = scene->occlusion;
    const float *nf = o->normals + 3 * i, *p = o->positions + 3 * i;
    double nn[3] = {nf[0], nf[1], nf[2]}, f[9];
    wenv_frame(nn, f);
    /* local = F w for a world direction w, and w = T' h for h in the method's frame: local = F T' h */
    const float *t = scene->turn;
    for (int r = 0; r < 3; r++)
        for (int c = 0; c < 3; c++)
            vs->frame[3 * r + c] = (float)(f[3 * r] * t[3 * c] + f[3 * r + 1] * t[3 * c + 1] + f[3 * r + 2] * t[3 * c + 2]);
    vs->turn = t;
    vs->mask = o->masks + (size_t)o->slot[i] * o->words;
    vs->point_rays = o->point_rays;
    vs->memo = memo;
    vs->memo_slot = memo ? memo->slots + i : NULL; /* a vertex's own: vertices may share a mask, not rays */
    vs->resolution = o->resolution;
    vs->occluders = scene->occluders;
    float lift = wenv_occluders_offset(scene->occluders);
    for (int k = 0; k < 3; k++)
        vs->origin[k] = p[k] + lift * nf[k];
    vs->lights.visible = light_visible;
    vs->lights.at_edge = light_at_edge;
    /* a cluster wider than half a texel may straddle a shadow's edge the mask cannot place */
    vs->lights.sin_radius_max = sinf((float)M_PI / (4.0f * (float)o->resolution));
    /* at an edge, a sixteenth of a texel: 1.4 degrees at 8 x 8 */
    vs->lights.sin_radius_edge = sinf((float)M_PI / (16.0f * (float)o->resolution));
}

void wenv_shadow_specular(const wenv_vertex_shadow *vs, const wenv_texel_reflection *tr, const float *blocked,
                          const float v[3], const float albedo[3], float s[3])
{
    const float *f = vs->frame;
    float d[3] = {f[0] * v[0] + f[1] * v[1] + f[2] * v[2], f[3] * v[0] + f[4] * v[1] + f[5] * v[2],
                  f[6] * v[0] + f[7] * v[1] + f[8] * v[2]};
    float u, w;
    wenv_hemi_encode_f(d, &u, &w);
    uint32_t idx[4];
    float wt[4];
    wenv_hemi_bilinear_f((long)tr->views, u, w, idx, wt);
    size_t texels = tr->resolution * tr->resolution;
    const float *row[4];
    for (int q = 0; q < 4; q++)
        row[q] = tr->specular + (size_t)idx[q] * texels * 3;
    float acc[3] = {0.0f, 0.0f, 0.0f};
    FOR_EACH_BLOCKED(vs, texels, {
        const float *x = blocked + 3 * k;
        for (int c = 0; c < 3; c++) {
            size_t e = 3 * t + (size_t)c;
            acc[c] += x[c] * (wt[0] * row[0][e] + wt[1] * row[1][e] + wt[2] * row[2][e] + wt[3] * row[3][e]);
        }
    });
    for (int c = 0; c < 3; c++)
        s[c] -= albedo[c] * acc[c];
}

void wenv_shadow_hidden_light(const wenv_vertex_shadow *vs, const wenv_node_pyramid *pyramid,
                              const wenv_texel_reflection *tr, float *lbar, float e_hidden[3])
{
    size_t r = vs->resolution, texels = r * r;
    const float *f = vs->frame;
    e_hidden[0] = e_hidden[1] = e_hidden[2] = 0.0f;
    FOR_EACH_BLOCKED(vs, texels, {
        const float *l = tr->direction + 3 * t;
        float d[3];
        for (int c = 0; c < 3; c++)
            d[c] = f[c] * l[0] + f[3 + c] * l[1] + f[6 + c] * l[2];
        /* read over the texel: a footprint of the square root of its solid angle */
        float *x = lbar + 3 * k;
        wenv_node_pyramid_read(pyramid, d, tr->footprint[t], x);
        for (int c = 0; c < 3; c++)
            e_hidden[c] += x[c] * tr->cosine[t];
    });
}

void wenv_shadow_bounce(const wenv_shadow_scene *scene, size_t slot, const float *cosine, float *lbar,
                        float e_hidden[3])
{
    const float *bounce = scene->bounce;
    const wenv_occlusion *o = scene->occlusion;
    const wenv_occlusion_hit *hit = o->hits + o->hit_start[slot];
    const float *at_hits = scene->bounce_hits ? scene->bounce_hits + 3 * o->hit_start[slot] : NULL;
    const uint32_t *triangles = wenv_occluders_triangles(scene->occluders);
    wenv_vertex_shadow vs = {.mask = o->masks + slot * o->words, .resolution = o->resolution};
    size_t texels = o->resolution * o->resolution;
    float scale = scene->bounce_scale;
    FOR_EACH_BLOCKED(&vs, texels, {
        const uint32_t *tri = triangles + 3 * (size_t)hit[k].triangle;
        float w[3];
        wenv_occlusion_hit_weights(&hit[k], w);
        for (int c = 0; c < 3; c++) {
            float b = scale * (at_hits ? at_hits[3 * k + (size_t)c]
                                       : w[0] * bounce[3 * (size_t)tri[0] + (size_t)c] +
                                             w[1] * bounce[3 * (size_t)tri[1] + (size_t)c] +
                                             w[2] * bounce[3 * (size_t)tri[2] + (size_t)c]);
            lbar[3 * k + (size_t)c] -= b;
            e_hidden[c] -= b * cosine[t];
        }
    });
}
