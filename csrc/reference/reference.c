#include "reference/reference.h"
#include "reference/lamps_reference.h"

#include <math.h>
#include <omp.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>

#include "math/frame.h"
#include "math/unit_pair.h"

#define BLOCK 2048
/* A lobe narrower than WENV_NARROW_LOBE_PIXELS pixels (2 alpha against twice the pixel's angle) is
 * integrated by its own node rule instead of the pixel sum: at pixel centres alone a lobe of alpha 0.001 (Principled's
 * default coat) falls between them and reads whichever pixel it happens to hit, while from about a
 * pixel wide the centres sample it well (a Gaussian of one pixel's deviation aliases by ~e^-20).  The
 * rule reads the pixel under each node: the same lighting the pixel sum integrates, each pixel's
 * radiance over its area (Cycles' "Closest" interpolation; its default "Linear" blurs the lighting by
 * about a pixel, which a lobe a few pixels wide reflecting a sun of a few pixels tells apart). */
#define NODE_RAYS 256     /* a narrow lobe's node rays handed to Embree at once */
#define NARROW_SAMPLES 192 /* the rule's divisions: 2 x 192^2 nodes over a lobe a few pixels wide */

/* What blocks the lighting, if anything: the scene and the ray's start (the vertex, lifted). */
typedef struct {
    const wenv_occluders *occ;
    const float *bounce; /* per occluder vertex, the light it sends (NULL: none) */
    float origin[3];
} blocker;

/* The blocker's light where the ray along d from the vertex meets it (black without a bounce). */
static void blocker_light(const blocker *b, uint32_t tri, const float *uv, float rgb[3])
{
    rgb[0] = rgb[1] = rgb[2] = 0.0f;
    if (!b->bounce)
        return;
    const uint32_t *v = wenv_occluders_triangles(b->occ) + 3 * (size_t)tri;
    float w[3] = {1.0f - uv[0] - uv[1], uv[0], uv[1]};
    for (int k = 0; k < 3; k++)
        for (int c = 0; c < 3; c++)
            rgb[c] += w[k] * b->bounce[3 * (size_t)v[k] + (size_t)c];
}

/* Whether the direction d (world, unit) is blocked; if so, what the blocker sends back into rgb. */
static int blocked_one(const blocker *b, const double d[3], float rgb[3])
{
    if (!b->occ)
        return 0;
    float fd[3] = {(float)d[0], (float)d[1], (float)d[2]}, uv[2];
    uint32_t tri;
    wenv_occluders_hit(b->occ, b->origin, fd, 1, &tri, uv);
    if (tri == UINT32_MAX)
        return 0;
    blocker_light(b, tri, uv, rgb);
    return 1;
}

/* Lobe i's reflected radiance at view wo (frame f) by its node rule over the lighting, minus
 * what the pixel sum gave it (the pixels whose half vector lies inside its cone, cos_h >= cut), into acc.  With
 * occluders, a blocked node or pixel brings the blocker's light, in both. */
static wenv_status narrow_lobe(const wenv_envmap *env, const wenv_material *mat, size_t i, double cut,
                               const double f[9], const double wo[3], const float *dirs, const float *flux,
                               const float *omega, size_t count, double *nodes, const blocker *b, double acc[3],
                               wenv_error *err)
{
    size_t max = 2 * NARROW_SAMPLES * NARROW_SAMPLES, n = 0;
    double *weights = nodes + 3 * max;
    if (wenv_material_lobe_nodes(mat, i, wo, NARROW_SAMPLES, nodes, weights, &n, err))
        return err->status;
    /* the nodes' rays a batch at a time: Embree traces rays from one origin together far faster */
    double d[3 * NODE_RAYS];
    float fd[3 * NODE_RAYS], uv[2 * NODE_RAYS];
    uint32_t tri[NODE_RAYS];
    for (size_t start = 0; start < n; start += NODE_RAYS) {
        size_t m = n - start < NODE_RAYS ? n - start : NODE_RAYS;
        for (size_t k = 0; k < m; k++) {
            const double *l = nodes + 3 * (start + k);
            for (size_t c = 0; c < 3; c++) {
                d[3 * k + c] = f[c] * l[0] + f[3 + c] * l[1] + f[6 + c] * l[2];
                fd[3 * k + c] = (float)d[3 * k + c];
            }
        }
        if (b->occ)
            wenv_occluders_hit(b->occ, b->origin, fd, m, tri, uv);
        for (size_t k = 0; k < m; k++) {
            float L[3];
            if (b->occ && tri[k] != UINT32_MAX)
                blocker_light(b, tri[k], uv + 2 * k, L);
            else
                wenv_envmap_lookup_nearest(env, d + 3 * k, L);
            for (int c = 0; c < 3; c++)
                acc[c] += weights[3 * (start + k) + (size_t)c] * L[c];
        }
    }
    wenv_lobe_rgb_fn value = wenv_material_lobe_value_fn(mat);
    for (size_t p = 0; p < count; p++) {
        const float *d = dirs + 3 * p;
        double wi[3] = {f[0] * d[0] + f[1] * d[1] + f[2] * d[2], f[3] * d[0] + f[4] * d[1] + f[5] * d[2],
                        f[6] * d[0] + f[7] * d[1] + f[8] * d[2]};
        if (!(wi[2] > 0.0))
            continue;
        double h[3] = {wi[0] + wo[0], wi[1] + wo[1], wi[2] + wo[2]};
        double len = sqrt(h[0] * h[0] + h[1] * h[1] + h[2] * h[2]);
        if (!(len > 0.0) || h[2] / len < cut)
            continue;
        double dw[3] = {d[0], d[1], d[2]}, v[3];
        float back[3];
        int blocked = blocked_one(b, dw, back);
        value(mat, i, wi, wo, v);
        for (int c = 0; c < 3; c++)
            acc[c] -= v[c] * wi[2] * (blocked ? back[c] * omega[p] : flux[3 * p + (size_t)c]);
    }
    return WENV_OK;
}

static wenv_status reference_one(const wenv_envmap *env, const wenv_material *mat, const wenv_material *emitter,
                                 const float *normals, const float *views, size_t n, const wenv_occluders *occ,
                                 const float *positions, const float *bounce, const float *base_color,
                                 const wenv_lamp *lamps, size_t n_lamps, const float *emission,
                                 const wenv_bump_normals *bump, float *out, const wenv_progress *progress,
                                 wenv_error *err);

wenv_status wenv_reference(const wenv_envmap *env, const wenv_material *mat, const float *normals,
                           const float *views, size_t n, const wenv_occluders *occ, const float *positions,
                           const float *bounce, const float *base_color, const wenv_lamp *lamps, size_t n_lamps,
                           const float *emission, const wenv_bump_normals *bump, float *out,
                           const wenv_progress *progress, wenv_error *err)
{
    /* each vertex's Emission Color: the material emitting white, times it */
    const wenv_material *emitter = mat;
    wenv_material *white = NULL;
    if (emission) {
        const wenv_principled_inputs *in = wenv_principled_inputs_of(mat);
        if (!in)
            return wenv_error_set(err, WENV_ERR_VALUE, "an Emission Color per vertex needs a Principled material");
        wenv_principled_inputs own = *in;
        own.emission_color[0] = own.emission_color[1] = own.emission_color[2] = 1.0;
        if (wenv_principled_create(&white, &own, err))
            return err->status;
        emitter = white;
    }
    wenv_status st = reference_one(env, mat, emitter, normals, views, n, occ, positions, bounce, base_color, lamps,
                                   n_lamps, emission, bump, out, progress, err);
    wenv_material_free(white);
    return st;
}

static wenv_status reference_one(const wenv_envmap *env, const wenv_material *mat, const wenv_material *emitter,
                                 const float *normals, const float *views, size_t n, const wenv_occluders *occ,
                                 const float *positions, const float *bounce, const float *base_color,
                                 const wenv_lamp *lamps, size_t n_lamps, const float *emission,
                                 const wenv_bump_normals *bump, float *out, const wenv_progress *progress,
                                 wenv_error *err)
{
    if (occ && !positions)
        return wenv_error_set(err, WENV_ERR_VALUE, "occluders need the vertices' positions");
    if (n_lamps && !positions)
        return wenv_error_set(err, WENV_ERR_VALUE, "lamps need the vertices' positions");
    double per_colour[3];
    if (base_color && wenv_material_diffuse_per_colour_at(mat, 1.0, per_colour, err))
        return err->status;
    for (size_t i = 0; (occ || n_lamps) && i < n; i++)
        if (!isfinite(positions[3 * i]) || !isfinite(positions[3 * i + 1]) || !isfinite(positions[3 * i + 2]))
            return wenv_error_set(err, WENV_ERR_VALUE, "positions[%zu] is not finite", i);
    int has_lobes = wenv_material_lobe_count(mat) > 0;
    size_t npix = wenv_envmap_width(env) * wenv_envmap_height(env);
    float *dirs = malloc(npix * 3 * sizeof(float));
    float *flux = malloc(npix * 3 * sizeof(float));
    float *omega = malloc(npix * sizeof(float));
    if (!dirs || !flux || !omega) {
        free(dirs);
        free(flux);
        free(omega);
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for the reference");
    }
    size_t count = wenv_envmap_samples(env, dirs, flux, omega);
    /* A black pixel sends nothing, and without a bounce neither does what blocks it: the sums leave it
     * out (a softbox and a sun in a black World are a few hundred of 10^5 pixels).  A World black
     * throughout skips the lobe rules too (scenes lit by lamps alone, where a lobe is "narrow" against
     * a tiny image and its rule would cost ~10^5 reads a vertex to add zero). */
    int world_dark = 0;
    if (!(occ && bounce)) {
        size_t kept = 0;
        for (size_t p = 0; p < count; p++) {
            if (flux[3 * p] == 0.0f && flux[3 * p + 1] == 0.0f && flux[3 * p + 2] == 0.0f)
                continue;
            memmove(dirs + 3 * kept, dirs + 3 * p, 3 * sizeof(float));
            memmove(flux + 3 * kept, flux + 3 * p, 3 * sizeof(float));
            omega[kept++] = omega[p];
        }
        count = kept;
        world_dark = count == 0;
    }
    size_t n_lobes = wenv_material_lobe_count(mat), n_narrow = 0;
    double narrow_alpha = WENV_NARROW_LOBE_PIXELS * wenv_envmap_pixel_angle(env);
    for (size_t l = 0; l < n_lobes; l++)
        n_narrow += !world_dark && wenv_material_lobe(mat, l)->alpha < narrow_alpha;
    /* each narrow lobe's cone, found once (thousands of NDF values) rather than at every vertex */
    double *cut = n_narrow ? malloc(n_lobes * sizeof(double)) : NULL;
    if (n_narrow && !cut) {
        free(dirs);
        free(flux);
        free(omega);
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for the reference");
    }
    for (size_t l = 0; n_narrow && l < n_lobes; l++)
        cut[l] = wenv_material_lobe(mat, l)->alpha < narrow_alpha ? wenv_material_lobe_cos_h_min(mat, l) : 1.0;
    atomic_int failed = 0, cancelled = 0;
    atomic_size_t done = 0;
#pragma omp parallel
    {
        float *wi = malloc(BLOCK * 3 * sizeof(float));
        float *fl = malloc(BLOCK * 3 * sizeof(float));
        float *fcos = malloc(BLOCK * 3 * sizeof(float));
        float *through = bump ? malloc(BLOCK * sizeof(float)) : NULL; /* the bent Lambertian part's */
        float *wd = occ ? malloc(BLOCK * 3 * sizeof(float)) : NULL, *om = occ ? malloc(BLOCK * sizeof(float)) : NULL;
        float *uv = occ ? malloc(BLOCK * 2 * sizeof(float)) : NULL;
        uint32_t *tri = occ ? malloc(BLOCK * sizeof(uint32_t)) : NULL;
        double *nodes = n_narrow ? malloc(2 * NARROW_SAMPLES * NARROW_SAMPLES * 6 * sizeof(double)) : NULL;
        if (!wi || !fl || !fcos || (n_narrow && !nodes) || (occ && (!wd || !om || !uv || !tri)) || (bump && !through))
            atomic_store(&failed, 1);
        wenv_error lobe_err = {0};
#pragma omp for schedule(dynamic, 1)
        for (size_t i = 0; i < n; i++) {
            if (atomic_load(&failed) || atomic_load(&cancelled))
                continue;
            double nn[3], vv[3];
            wenv_unit_pair(normals, views, i, nn, vv);
            double f[9], ns[3];
            wenv_frame(nn, f);
            if (bump) {
                const float *b = bump->smooth + 3 * i;
                double len = sqrt((double)b[0] * b[0] + (double)b[1] * b[1] + (double)b[2] * b[2]);
                for (int c = 0; c < 3; c++)
                    ns[c] = b[c] / len;
            }
            double wo[3] = {f[0] * vv[0] + f[1] * vv[1] + f[2] * vv[2], f[3] * vv[0] + f[4] * vv[1] + f[5] * vv[2],
                            f[6] * vv[0] + f[7] * vv[1] + f[8] * vv[2]};
            double spec[3] = {0, 0, 0}, irr[3] = {0, 0, 0};
            blocker b = {.occ = occ, .bounce = bounce};
            if (occ || n_lamps) {
                float lift = occ ? wenv_occluders_offset(occ) : 0.0f;
                for (int c = 0; c < 3; c++)
                    b.origin[c] = positions[3 * i + (size_t)c] + lift * (float)nn[c];
            }
            if (wo[2] > 0.0 && !world_dark) {
                size_t fill = 0;
                for (size_t p = 0; p <= count; p++) {
                    if (p < count) {
                        const float *d = dirs + 3 * p;
                        float z = (float)f[6] * d[0] + (float)f[7] * d[1] + (float)f[8] * d[2];
                        if (z <= 0.0f)
                            continue;
                        float *w = wi + 3 * fill;
                        w[0] = (float)f[0] * d[0] + (float)f[1] * d[1] + (float)f[2] * d[2];
                        w[1] = (float)f[3] * d[0] + (float)f[4] * d[1] + (float)f[5] * d[2];
                        w[2] = z;
                        memcpy(fl + 3 * fill, flux + 3 * p, 3 * sizeof(float));
                        if (bump) {
                            double dd[3] = {d[0], d[1], d[2]};
                            through[fill] = (float)wenv_bump_diffuse_weight(nn, ns, dd, bump->correction);
                        }
                        if (occ) {
                            memcpy(wd + 3 * fill, d, 3 * sizeof(float));
                            om[fill] = omega[p];
                        }
                        if (++fill < BLOCK)
                            continue;
                    }
                    if (fill && occ) { /* what the scene blocks brings the blocker's light instead */
                        wenv_occluders_hit(occ, b.origin, wd, fill, tri, uv);
                        for (size_t q = 0; q < fill; q++)
                            if (tri[q] != UINT32_MAX) {
                                float back[3];
                                blocker_light(&b, tri[q], uv + 2 * q, back);
                                for (int c = 0; c < 3; c++)
                                    fl[3 * q + (size_t)c] = back[c] * om[q];
                            }
                    }
                    for (size_t q = 0; q < fill; q++)
                        for (int c = 0; c < 3; c++)
                            irr[c] += (double)wi[3 * q + 2] * fl[3 * q + (size_t)c] * (bump ? through[q] : 1.0f);
                    if (fill && has_lobes) {
                        wenv_material_specular_cos_batch(mat, wo, wi, fill, fcos);
                        for (size_t q = 0; q < fill; q++)
                            for (int c = 0; c < 3; c++)
                                spec[c] += (double)fcos[3 * q + c] * fl[3 * q + c];
                    }
                    fill = 0;
                }
            }
            double diffuse[3];
            if (base_color) { /* checked above: it cannot fail */
                wenv_material_diffuse_per_colour_at(mat, wo[2], diffuse, NULL);
                for (int c = 0; c < 3; c++)
                    diffuse[c] *= base_color[3 * i + (size_t)c];
            } else {
                wenv_material_diffuse_at(mat, wo[2], diffuse);
            }
            for (size_t l = 0; n_narrow && wo[2] > 0.0 && l < n_lobes; l++)
                if (wenv_material_lobe(mat, l)->alpha < narrow_alpha &&
                    narrow_lobe(env, mat, l, cut[l], f, wo, dirs, flux, omega, count, nodes, &b, spec, &lobe_err))
                    atomic_store(&failed, 1);
            if (n_lamps && wo[2] > 0.0) {
                double p[3] = {positions[3 * i], positions[3 * i + 1], positions[3 * i + 2]};
                wenv_reference_lamps_at(lamps, n_lamps, mat, p, nn, f, wo, occ, b.origin, bump ? ns : NULL,
                                        bump ? bump->correction : 0, spec, irr);
            }
            double emitted[3] = {0.0, 0.0, 0.0};
            if (wo[2] > 0.0)
                wenv_material_emission_at(emitter, wo[2], emitted);
            for (int c = 0; emission && c < 3; c++)
                emitted[c] *= emission[3 * i + (size_t)c];
            for (int c = 0; c < 3; c++)
                out[3 * i + c] = (float)fmax(0.0, spec[c] + irr[c] * diffuse[c] / M_PI + emitted[c]);
            wenv_progress_item(progress, &done, n, &cancelled);
        }
        free(wi);
        free(fl);
        free(fcos);
        free(through);
        free(wd);
        free(om);
        free(uv);
        free(tri);
        free(nodes);
    }
    free(dirs);
    free(flux);
    free(omega);
    free(cut);
    if (failed)
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for the reference");
    if (cancelled || wenv_progress_finish(progress))
        return wenv_error_set(err, WENV_ERR_CANCELLED, "reference cancelled");
    return WENV_OK;
}

/* ---- a material per vertex ---- */

/* A vertex's material: its inputs per vertex (WENV_VERTEX_INPUTS, channel by channel) and, where the
 * colour enters its metal, its colour. */
#define KEY_VALUES (WENV_VERTEX_INPUT_CHANNELS + 3)
typedef struct {
    float v[KEY_VALUES];
    size_t i;
} vertex_key;

static int compare_keys(const void *a, const void *b)
{
    const vertex_key *x = a, *y = b;
    for (int k = 0; k < KEY_VALUES; k++)
        if (x->v[k] != y->v[k])
            return x->v[k] < y->v[k] ? -1 : 1;
    return (x->i > y->i) - (x->i < y->i);
}

static int same_material(const vertex_key *a, const vertex_key *b) { return memcmp(a->v, b->v, sizeof a->v) == 0; }

/* One group's progress as a share of the whole. */
typedef struct {
    const wenv_progress *outer;
    double before, share;
} group_progress;

static int report_group(void *ctx, double fraction)
{
    const group_progress *g = ctx;
    return g->outer->report(g->outer->ctx, g->before + g->share * fraction);
}

static float clamp01f(float x) { return x < 0.0f ? 0.0f : (x > 1.0f ? 1.0f : x); }

/* Vertex i's key: each input's value clamped as Cycles clamps it (the material's own where not given),
 * then its colour where the colour enters its metal. */
static void key_of(const wenv_principled_inputs *in, const wenv_vertex_inputs *vi, const float *base_color,
                   int colour_in_metal, size_t i, vertex_key *key)
{
    size_t at = 0;
    memset(key, 0, sizeof *key);
    for (int k = 0; k < WENV_VERTEX_INPUT_COUNT; k++) {
        const wenv_vertex_input *row = &wenv_vertex_input_list[k];
        for (int c = 0; c < row->n; c++, at++)
            key->v[at] = vi && vi->value[k]
                             ? (float)wenv_vertex_input_clamp(row, vi->value[k][(size_t)row->n * i + (size_t)c])
                             : (float)wenv_principled_field_c(in, row->row)[c];
    }
    for (int c = 0; colour_in_metal && c < 3; c++)
        key->v[at + (size_t)c] = clamp01f(base_color[3 * i + (size_t)c]);
    key->i = i;
}

/* The material of a key (key_of). */
static wenv_status key_material(const wenv_principled_inputs *in, const vertex_key *key, int colour_in_metal,
                                wenv_material **out, wenv_error *err)
{
    wenv_principled_inputs at = *in;
    size_t j = 0;
    for (int k = 0; k < WENV_VERTEX_INPUT_COUNT; k++) {
        const wenv_vertex_input *row = &wenv_vertex_input_list[k];
        for (int c = 0; c < row->n; c++)
            wenv_principled_field(&at, row->row)[c] = key->v[j++];
    }
    for (int c = 0; colour_in_metal && c < 3; c++)
        at.base_color[c] = key->v[j + (size_t)c];
    return wenv_principled_create(out, &at, err);
}

wenv_status wenv_reference_per_vertex(const wenv_envmap *env, const wenv_material *mat, const float *normals,
                                      const float *views, size_t n, const wenv_occluders *occ, const float *positions,
                                      const float *bounce, const float *base_color, const wenv_vertex_inputs *vi,
                                      const wenv_lamp *lamps, size_t n_lamps, const float *emission,
                                      const wenv_bump_normals *bump, float *out, const wenv_progress *progress,
                                      wenv_error *err)
{
    const wenv_principled_inputs *in = wenv_principled_inputs_of(mat);
    int any = wenv_vertex_inputs_any(vi);
    /* a metal's colour is its Fresnel's: each colour its own material */
    int colour_in_metal = base_color && in && (in->metallic > 0.0 || (vi && vi->value[WENV_VERTEX_metallic]));
    if (!any && !colour_in_metal)
        return wenv_reference(env, mat, normals, views, n, occ, positions, bounce, base_color, lamps, n_lamps,
                              emission, bump, out, progress, err);
    if (!in)
        return wenv_error_set(err, WENV_ERR_VALUE,
                              "inputs per vertex (Roughness, Metallic...) need a Principled material (wenv.Principled), "
                              "not %s",
                              wenv_material_kind_name(mat));
    if (wenv_vertex_inputs_check(vi, n, err))
        return err->status;
    vertex_key *key = malloc((n ? n : 1) * sizeof *key);
    /* a group's normals, views, positions, colours, emission colours, radiance and smooth normals */
    float *work = malloc((n ? n : 1) * 21 * sizeof(float));
    if (!key || !work) {
        free(key);
        free(work);
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for the reference");
    }
    for (size_t i = 0; i < n; i++)
        key_of(in, vi, base_color, colour_in_metal, i, &key[i]);
    qsort(key, n, sizeof *key, compare_keys);
    wenv_status st = WENV_OK;
    for (size_t a = 0, b; a < n && !st; a = b) {
        for (b = a + 1; b < n && same_material(&key[a], &key[b]);)
            b++;
        size_t count = b - a;
        float *nrm = work, *vw = work + 3 * count, *pos = work + 6 * count, *rgb = work + 9 * count;
        float *o = work + 12 * count, *em = work + 15 * count, *smooth = work + 18 * count;
        for (size_t k = 0; k < count; k++) {
            size_t i = key[a + k].i;
            memcpy(nrm + 3 * k, normals + 3 * i, 3 * sizeof(float));
            memcpy(vw + 3 * k, views + 3 * i, 3 * sizeof(float));
            if (positions)
                memcpy(pos + 3 * k, positions + 3 * i, 3 * sizeof(float));
            if (base_color)
                memcpy(rgb + 3 * k, base_color + 3 * i, 3 * sizeof(float));
            if (emission)
                memcpy(em + 3 * k, emission + 3 * i, 3 * sizeof(float));
            if (bump)
                memcpy(smooth + 3 * k, bump->smooth + 3 * i, 3 * sizeof(float));
        }
        wenv_material *group_mat;
        if ((st = key_material(in, &key[a], colour_in_metal, &group_mat, err)))
            break;
        group_progress gp = {progress, (double)a / (double)n, (double)count / (double)n};
        wenv_progress inner = {progress && progress->report ? report_group : NULL, &gp};
        wenv_bump_normals group_bump = {smooth, bump ? bump->correction : 0};
        st = wenv_reference(env, group_mat, nrm, vw, count, occ, positions ? pos : NULL, bounce,
                            base_color && !colour_in_metal ? rgb : NULL, lamps, n_lamps, emission ? em : NULL,
                            bump ? &group_bump : NULL, o, &inner, err);
        wenv_material_free(group_mat);
        for (size_t k = 0; !st && k < count; k++)
            memcpy(out + 3 * key[a + k].i, o + 3 * k, 3 * sizeof(float));
    }
    free(key);
    free(work);
    return st;
}
