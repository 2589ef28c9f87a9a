/* The wavelet shader per vertex: taps on the normal and view samples, the (normal sample, view
 * sample) radiance table made as vertices need it, the exact lights and the grazing path. */
#include "methods/wavelet/wavelet_state.h"

#include "base/fingerprint.h"

#include <math.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>

#include "math/haar.h"
#include "math/maps.h"

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

/* A new lighting remakes at once what the latest shade call read -- so that shading the same view
 * again, the usual case while lighting or material is edited, is a single pass over the vertices --
 * and marks everything else stale (every kept material's table rows too), to be made when a vertex
 * needs it.  A material made current (lighting = 0) keeps its rows; those flagged are made. */
wenv_status wenv_wavelet_remake_ready(wenv_wavelet *wavelet, int lighting, wenv_error *err)
{
    if (lighting) {
        for (size_t s = 0; s < wavelet->ns; s++)
            wavelet->slice_need[s] |= wavelet->slice_ready[s] == USED;
        memset(wavelet->slice_ready, 0, wavelet->ns);
        for (size_t i = 0; i < wavelet->n_kept; i++) {
            wenv_wavelet_material *k = wavelet->kept[i];
            for (size_t s = 0; s < wavelet->ns; s++)
                k->row_need[s] = k == wavelet->m && (k->row_need[s] || k->row_ready[s] == USED);
            memset(k->row_ready, 0, wavelet->ns);
            memset(k->row_asked, 0, wavelet->ns);
        }
    }
    if (!wavelet->have_env || !wavelet->m)
        return WENV_OK;
    if (wenv_wavelet_ensure_grazing(wavelet, err))
        return err->status;
    return fill_needed(wavelet, err);
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
    /* What each normal sample's view keeps from the vertex: a lobe about the mirror direction sees
     * the same lighting from every sample when the mirror direction r is kept (the view about the
     * sample normal is then the mirror of r); a lobe about the view (retro-reflective) when the
     * view itself is.  The samples' bilinear weights do not reproduce the vertex normal where the
     * octahedral map folds (x = 0, y = 0: up to half a texel), so keeping the other direction moves
     * the lobe by twice that. */
    float r[3] = {2.0f * nv * n[0] - v[0], 2.0f * nv * n[1] - v[1], 2.0f * nv * n[2] - v[2]};
    int keep_mirror = wavelet->m->mirror_centred;
    /* octahedral encoding of the normal */
    float ou, ov;
    wenv_oct_encode_f(n, &ou, &ov);
    wenv_oct_bilinear_f((long)wavelet->q.normal_n, ou, ov, tp->sample, tp->sample_w);
    for (int k = 0; k < 4; k++) {
        const float *f = wavelet->frames + 9 * (size_t)tp->sample[k];
        /* in the sample's frame: the mirror of r about the sample normal, (-r.t, -r.b, r.n), or v */
        const float *d = keep_mirror ? r : v;
        float sign = keep_mirror ? -1.0f : 1.0f;
        float lx = sign * (f[0] * d[0] + f[1] * d[1] + f[2] * d[2]), ly = sign * (f[3] * d[0] + f[4] * d[1] + f[5] * d[2]);
        float lz = f[6] * d[0] + f[7] * d[1] + f[8] * d[2];
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

/* The lighting slices of samples[0..k): one sample (rotation), or up to WENV_ORBIT_MAX samples of
 * one orbit (slicing), resampled through one read of their operator. */
static int compute_slices(wenv_wavelet *wavelet, const size_t *samples, size_t k, wenv_slice_work *work,
                          float *scratch)
{
    float *slice[WENV_ORBIT_MAX];
    for (size_t i = 0; i < k; i++) {
        size_t s = samples[i];
        if (!wavelet->slices[s] && !(wavelet->slices[s] = malloc(wavelet->nl * 3 * sizeof(float))))
            return -1;
        slice[i] = wavelet->slices[s];
    }
    if (wavelet->method == WENV_WAVELET_ROTATION) {
        wenv_rotation_apply(wavelet->rot, samples[0], wavelet->light_idx, wavelet->light_rgb, wavelet->light_count,
                            slice[0]);
        return 0;
    }
    /* resampled, then transformed in place */
    if (wenv_slice_operators_resample(wavelet->slice_ops, samples, k, wavelet->global_rgbx, slice, work) < 0)
        return -1;
    for (size_t i = 0; i < k; i++)
        wenv_haar2d_forward(slice[i], wavelet->q.local_n, 3, scratch);
    return 0;
}

/* What a vertex with blocked texels shades with (NULL for one that sees its whole hemisphere). */
typedef struct {
    wenv_vertex_shadow vs;
    const float *hidden;   /* its blocked texels' hidden lighting less the blocker's light */
    const float *e_hidden; /* their cosine-weighted sum */
    const float *lbar;     /* its blocked texels' hidden lighting alone */
} vertex_shadow;

/* The irradiance the normal samples interpolate at the vertex, less what its blocked texels hide. */
static void sampled_irradiance(const wenv_wavelet *wavelet, const uint32_t sample[4], const float sample_w[4],
                               const vertex_shadow *sh, float e[3])
{
    e[0] = e[1] = e[2] = 0.0f;
    for (int k = 0; k < 4; k++) {
        const float *ir = wavelet->irradiance + 3 * (size_t)sample[k];
        e[0] += sample_w[k] * ir[0];
        e[1] += sample_w[k] * ir[1];
        e[2] += sample_w[k] * ir[2];
    }
    if (sh)
        for (int c = 0; c < 3; c++)
            e[c] = e[c] - sh->e_hidden[c] > 0.0f ? e[c] - sh->e_hidden[c] : 0.0f;
}

/* The exact lights' irradiance at unit normal n, added to e. */
static void lights_irradiance(const wenv_wavelet *wavelet, const float n[3], const vertex_shadow *sh, float e[3])
{
    /* as for the lobes below: against the rest's irradiance plus a uniform mean's */
    float scale = e[0] + e[1] + e[2] + 3.0f * (float)M_PI * wavelet->mean_radiance;
    wenv_lights_irradiance(wavelet->lights, n, (float)wavelet->q.light_tolerance * scale, sh ? &sh->vs.lights : NULL,
                           e);
}

/* o: the radiance; with irr, o all but the Lambertian part and irr the light it reflects (method.h).
 * entries: the vertex's 16 table entries made for it (NULL: read from the table). */
static void shade_vertex(const wenv_wavelet *wavelet, const vertex_taps *tp, const vertex_shadow *sh,
                         const float *entries, float *o, float *irr)
{
    float e[3], m[3] = {0, 0, 0}, s[3] = {0, 0, 0};
    sampled_irradiance(wavelet, tp->sample, tp->sample_w, sh, e);
    /* table entries are mean radiances under the lobe (see albedo_tables) */
    for (int k = 0; k < 16 && wavelet->m->brdf_terms; k++) {
        const float *t = entries ? entries + 3 * k : wavelet->m->table + 3 * (size_t)tp->pair[k];
        float w = tp->pair_w[k];
        if (w > 0.0f) {
            m[0] += w * t[0];
            m[1] += w * t[1];
            m[2] += w * t[2];
        }
    }
    float blend = wenv_grazing_blend(wavelet->m->grazing_rule, tp->cos_v);
    float a[3] = {0.0f, 0.0f, 0.0f};
    if (wavelet->m->albedo)
        wenv_wavelet_albedo_at(wavelet->m->albedo, tp->cos_v, a);
    if (wavelet->m->albedo && blend < 1.0f) {
        /* A mean radiance under the lobe lies between the lighting's darkest and brightest
         * texels; wavelet truncation and interpolation can ring past either, most at narrow
         * lobes near grazing, where they overshot the brightest pixel several-fold. */
        for (int c = 0; c < 3; c++) {
            float mc = m[c] < 0.0f ? 0.0f : (m[c] > wavelet->radiance_max[c] ? wavelet->radiance_max[c] : m[c]);
            s[c] += (1.0f - blend) * a[c] * mc;
        }
    }
    if (blend > 0.0f) {
        float g[3];
        wenv_grazing_shade(wavelet->m->grazing_rule, wavelet->grazing_light, tp->n, tp->v, tp->cos_v, g);
        for (int c = 0; c < 3; c++)
            s[c] += blend * g[c];
    }
    if (sh && wavelet->m->texel_reflection.specular && wavelet->m->albedo) {
        if (wavelet->m->lobes_narrow) {
            wenv_shadow_narrow_specular(&sh->vs, wenv_grazing_light_pyramid(wavelet->grazing_light), sh->lbar,
                                        sh->hidden, tp->n, tp->v, tp->cos_v, wavelet->m->lobe_alpha,
                                        wavelet->q.lobe_rings, a, s);
        } else {
            wenv_shadow_specular(&sh->vs, &wavelet->m->texel_reflection, sh->hidden, tp->v, a, s);
        }
    }
    if (wenv_lights_count(wavelet->lights, 0) && !wavelet->lights_apart) {
        /* the irradiance asked for is the light arriving, whatever this material reflects of it */
        if (wavelet->m->has_diffuse || irr)
            lights_irradiance(wavelet, tp->n, sh, e);
        if (wavelet->m->has_lobes) {
            wenv_lights_lobe lobe = wenv_light_lobes_walk(&wavelet->m->light, wavelet->narrow_alpha);
            /* the error allowed per cluster is against the vertex's radiance without the lights plus
             * what a uniform environment of the mean radiance would reflect (so that a vertex that
             * sees little of the rest still reads its lights to a tolerance the image notices) */
            float scale = s[0] + s[1] + s[2] + wavelet->mean_radiance * (a[0] + a[1] + a[2]);
            wenv_lights_specular(wavelet->lights, wavelet->m->mat, wavelet->m->light.cos_h_min, &lobe, tp->n, tp->v,
                                 tp->cos_v, (float)wavelet->q.light_tolerance * scale, sh ? &sh->vs.lights : NULL, s);
        }
    }
    if (irr) {
        for (int c = 0; c < 3; c++) {
            o[c] = s[c];
            irr[c] = e[c] > 0.0f ? e[c] : 0.0f;
        }
        return;
    }
    float d[3];
    wenv_diffuse_table_at(&wavelet->m->diffuse, tp->cos_v, d);
    for (int c = 0; c < 3; c++) {
        float val = d[c] * e[c] + s[c];
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

/* Whether every slice and table row the vertex reads is ready; marks those ready as USED.  A
 * material without BRDF slices (diffuse only) reads neither: its table is zero, and the irradiance
 * is made with the lighting. */
static int read_taps(const wenv_wavelet *wavelet, const vertex_taps *tp)
{
    if (!wavelet->m->brdf_terms)
        return 1;
    int slices = read_states(wavelet->slice_ready, tp->sample, tp->sample_w, 4);
    return read_states(wavelet->m->row_ready, tp->sample, tp->sample_w, 4) && slices;
}

/* Flags in `flags` the entries a vertex reads with weight.  Checked before written so that cache
 * lines shared between threads stay clean; every writer stores 1. */
static inline void flag_needed(unsigned char *flags, const uint32_t *idx, const float *w, int n)
{
    for (int k = 0; k < n; k++) {
        unsigned char f;
#pragma omp atomic read
        f = flags[idx[k]];
        if (w[k] > 0.0f && !f) {
#pragma omp atomic write
            flags[idx[k]] = 1;
        }
    }
}

static inline void flag_taps(const vertex_taps *tp, unsigned char *slice_flags, unsigned char *row_flags)
{
    flag_needed(slice_flags, tp->sample, tp->sample_w, 4);
    flag_needed(row_flags, tp->sample, tp->sample_w, 4);
}

static int compare_u64(const void *a, const void *b)
{
    uint64_t x = *(const uint64_t *)a, y = *(const uint64_t *)b;
    return (x > y) - (x < y);
}

/* samples[0..n) ordered by their orbit, then by sample: an orbit's samples next to each other. */
static void order_by_orbit(const wenv_slice_operators *ops, size_t *samples, size_t n)
{
    uint64_t *key = malloc((n ? n : 1) * sizeof(uint64_t));
    if (!key)
        return; /* unordered: the same slices, each orbit's operator read more often */
    for (size_t e = 0; e < n; e++)
        key[e] = ((uint64_t)wenv_slice_operators_orbit(ops, samples[e]) << 32) | (uint64_t)samples[e];
    qsort(key, n, sizeof *key, compare_u64);
    for (size_t e = 0; e < n; e++)
        samples[e] = (size_t)(key[e] & 0xffffffffu);
    free(key);
}

/* Makes the lighting slices flagged in slice_need. */
static wenv_status fill_slices(wenv_wavelet *wavelet, wenv_error *err)
{
    size_t *todo = malloc(wavelet->ns * sizeof(size_t));
    if (!todo)
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory shading");
    size_t ntodo = 0;
    for (size_t s = 0; s < wavelet->ns; s++) {
        if (wavelet->slice_need[s] && !wavelet->slice_ready[s])
            todo[ntodo++] = s;
        wavelet->slice_need[s] = 0;
    }
    /* slicing: the samples of an orbit in one group, which reads their operator once */
    size_t *group = malloc((ntodo + 1) * sizeof(size_t)), ngroups = 0;
    atomic_int failed = !group || (wavelet->slice_ops && wenv_slice_operators_prepare(wavelet->slice_ops, todo, ntodo) < 0);
    if (!failed && wavelet->slice_ops)
        order_by_orbit(wavelet->slice_ops, todo, ntodo);
    for (size_t e = 0; !failed && e < ntodo; e++)
        if (e == 0 || !wavelet->slice_ops || e - group[ngroups - 1] == WENV_ORBIT_MAX ||
            wenv_slice_operators_orbit(wavelet->slice_ops, todo[e]) !=
                wenv_slice_operators_orbit(wavelet->slice_ops, todo[e - 1]))
            group[ngroups++] = e;
    if (group)
        group[ngroups] = ntodo;
#pragma omp parallel if (ngroups > 1)
    {
        wenv_slice_work *work = wavelet->slice_ops ? wenv_slice_work_new(wavelet->slice_ops) : NULL;
        float *scratch = malloc(wenv_haar2d_scratch_floats(wavelet->q.local_n, 3) * sizeof(float));
        if ((wavelet->slice_ops && !work) || !scratch)
            atomic_store(&failed, 1);
#pragma omp for schedule(dynamic, 1)
        for (size_t gi = 0; gi < ngroups; gi++) {
            if (atomic_load(&failed))
                continue;
            size_t first = group[gi], k = group[gi + 1] - first;
            if (compute_slices(wavelet, todo + first, k, work, scratch) < 0) {
                atomic_store(&failed, 1);
                continue;
            }
            for (size_t i = 0; i < k; i++)
                wavelet->slice_ready[todo[first + i]] = USED; /* made for the latest shade call */
        }
        wenv_slice_work_free(work);
        free(scratch);
    }
    free(group);
    free(todo);
    if (failed)
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory computing lighting slices");
    return WENV_OK;
}

/* Makes the lighting slices and table rows flagged in slice_need / row_need. */
static wenv_status fill_needed(wenv_wavelet *wavelet, wenv_error *err)
{
    if (fill_slices(wavelet, err))
        return err->status;
    size_t *todo = malloc(wavelet->ns * sizeof(size_t));
    if (!todo)
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory shading");
    size_t ntodo = 0;
    for (size_t s = 0; s < wavelet->ns; s++) {
        if (wavelet->m->row_need[s] && !wavelet->m->row_ready[s])
            todo[ntodo++] = s;
        wavelet->m->row_need[s] = 0;
    }
    wenv_status st = ntodo ? wenv_wavelet_fill_rows(wavelet, todo, ntodo, err) : WENV_OK;
    if (!st)
        for (size_t e = 0; e < ntodo; e++)
            wavelet->m->row_ready[todo[e]] = USED;
    free(todo);
    return st;
}

/* Vertex i's part of the scene: NULL when it sees its whole hemisphere. */
/* env_only: the hidden lighting alone, before any bounce. */
static const vertex_shadow *vertex_shadow_at(const wenv_wavelet *wavelet, const wenv_shadow_scene *scene, size_t row,
                                             int env_only, vertex_shadow *sh)
{
    if (!scene)
        return NULL;
    size_t i = scene->rows ? scene->rows[row] : scene->offset + row;
    if (scene->occlusion->slot[i] < 0)
        return NULL;
    size_t slot = (size_t)scene->occlusion->slot[i];
    wenv_vertex_shadow_init(&sh->vs, scene, i, wavelet->shadow_lights);
    sh->hidden = (env_only ? wavelet->shadow_lbar : wavelet->shadow_hidden) + 3 * scene->occlusion->hit_start[slot];
    sh->lbar = wavelet->shadow_lbar + 3 * scene->occlusion->hit_start[slot];
    sh->e_hidden = (env_only ? wavelet->shadow_e_env : wavelet->shadow_e_hidden) + 3 * slot;
    return sh;
}

/* Whether the np vertices whose table rows are missing read entries made for them alone rather than
 * whole rows; if so marks those rows asked and unflags them.  A row holds every view's entry, made
 * in vector lanes that share each read of a BRDF term, and serves later views until the lighting or
 * the material changes; an entry is one view's terms for one tap of one vertex, at about 16 times a
 * row entry's cost.  So entries only when a vertex's 16, each counted as ENTRY_AGAINST_ROW row
 * entries, come to fewer than the missing rows' entries: a few thousand scattered vertices (a
 * test's random pairs) against rows of a thousand views, at a quarter of the rows' cost or less,
 * while a mesh's vertices, which share their normal samples, make rows; and rows once one of them
 * is asked for again (the same vertices' next view). */
#define ENTRY_AGAINST_ROW 64
static int by_entries(wenv_wavelet *wavelet, size_t np)
{
    wenv_wavelet_material *m = wavelet->m;
    size_t rows = 0;
    for (size_t s = 0; s < wavelet->ns; s++) {
        if (!m->row_need[s] || m->row_ready[s])
            continue;
        if (m->row_asked[s])
            return 0;
        rows++;
    }
    if (!(np * 16 * ENTRY_AGAINST_ROW < rows * wavelet->nv))
        return 0;
    for (size_t s = 0; s < wavelet->ns; s++) {
        m->row_asked[s] |= m->row_need[s] && !m->row_ready[s];
        m->row_need[s] = 0;
    }
    return 1;
}

static wenv_status shade_all(wenv_wavelet *wavelet, const float *normals, const float *views, size_t n,
                             const wenv_shadow_scene *scene, float *out, float *irradiance, wenv_error *err)
{
    /* One pass shades every vertex whose table rows exist (all of them once its normals were seen,
     * whatever the view) and flags what the others need; those are shaded after the missing rows
     * are made. */
    size_t *pending = malloc((n ? n : 1) * sizeof(size_t));
    if (!pending)
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory shading");
    /* what the previous call read is no longer the latest */
    for (size_t q = 0; q < wavelet->ns; q++)
        wavelet->slice_ready[q] = wavelet->slice_ready[q] != 0;
    for (size_t q = 0; q < wavelet->ns; q++)
        wavelet->m->row_ready[q] = wavelet->m->row_ready[q] != 0;
    atomic_size_t npending = 0;
    long long nn = (long long)n;
    /* Dynamic: a vertex facing the eye costs 10-100x one facing away, and the facing ones gather in
     * a part of the mesh's order, so equal halves left a thread idle for a third of a view. */
#pragma omp parallel for schedule(dynamic, 256)
    for (long long i = 0; i < nn; i++) {
        vertex_taps tp;
        float *o = out + 3 * i, *irr = irradiance ? irradiance + 3 * i : NULL;
        if (!compute_taps(wavelet, normals + 3 * i, views + 3 * i, &tp)) {
            o[0] = o[1] = o[2] = 0.0f;
            if (irr)
                irr[0] = irr[1] = irr[2] = 0.0f;
            continue;
        }
        if (read_taps(wavelet, &tp)) {
            vertex_shadow sh;
            shade_vertex(wavelet, &tp, vertex_shadow_at(wavelet, scene, (size_t)i, 0, &sh), NULL, o, irr);
            continue;
        }
        flag_taps(&tp, wavelet->slice_need, wavelet->m->row_need);
        pending[atomic_fetch_add(&npending, 1)] = (size_t)i;
    }
    size_t np = atomic_load(&npending);
    if (np) {
        int entries = by_entries(wavelet, np);
        if (entries ? fill_slices(wavelet, err) : fill_needed(wavelet, err)) {
            free(pending);
            return err->status;
        }
#pragma omp parallel for schedule(dynamic, 256)
        for (size_t e = 0; e < np; e++) {
            vertex_taps tp;
            vertex_shadow sh;
            float made[48];
            size_t i = pending[e];
            compute_taps(wavelet, normals + 3 * i, views + 3 * i, &tp);
            for (int k = 0; entries && k < 16; k++)
                if (tp.pair_w[k] > 0.0f)
                    wenv_wavelet_table_entry(wavelet, tp.pair[k] / wavelet->nv, tp.pair[k] % wavelet->nv,
                                             made + 3 * k);
            shade_vertex(wavelet, &tp, vertex_shadow_at(wavelet, scene, i, 0, &sh), entries ? made : NULL,
                         out + 3 * i, irradiance ? irradiance + 3 * i : NULL);
        }
    }
    free(pending);
    return WENV_OK;
}

wenv_status wenv_wavelet_shade(wenv_wavelet *wavelet, const float *normals, const float *views, size_t n,
                              float *out, float *irradiance, wenv_error *err)
{
    if (!wavelet->have_env || !wavelet->m)
        return wenv_error_set(err, WENV_ERR_VALUE, "the shader needs an environment and a material");
    if (wenv_wavelet_ensure_grazing(wavelet, err)) /* not made when memory ran out before */
        return err->status;
    return shade_all(wavelet, normals, views, n, NULL, out, irradiance, err);
}

/* ---- with the scene in the way ------------------------------------------------------------------ */

/* The light each of n vertices sends back to what it blocks, as if diffuse: its albedo head-on (the
 * Lambertian part's and the lobes', so that a metal returns what it reflects rather than nothing)
 * over pi, times the irradiance (less what the blocked texels hide: the hidden lighting alone,
 * before any bounce, with the lights tested). */
static void diffuse_light(const wenv_wavelet *wavelet, const float *normals, size_t n, const wenv_shadow_scene *scene,
                          float *out, float *irradiance)
{
    float head_on[3] = {0.0f, 0.0f, 0.0f}, lobes[3] = {0.0f, 0.0f, 0.0f};
    if (!irradiance) /* else the Lambertian part is the caller's */
        wenv_diffuse_table_at(&wavelet->m->diffuse, 1.0f, head_on);
    if (wavelet->m->albedo)
        wenv_wavelet_albedo_at(wavelet->m->albedo, 1.0f, lobes);
    for (int c = 0; c < 3; c++)
        head_on[c] += lobes[c] * (float)(1.0 / M_PI);
    long long nn = (long long)n;
#pragma omp parallel for schedule(static)
    for (long long i = 0; i < nn; i++) {
        const float *m = normals + 3 * i;
        float inv = 1.0f / sqrtf(m[0] * m[0] + m[1] * m[1] + m[2] * m[2]), nrm[3] = {m[0] * inv, m[1] * inv, m[2] * inv};
        float ou, ov, w[4], e[3];
        uint32_t sample[4];
        wenv_oct_encode_f(nrm, &ou, &ov);
        wenv_oct_bilinear_f((long)wavelet->q.normal_n, ou, ov, sample, w);
        vertex_shadow sh;
        const vertex_shadow *shp = vertex_shadow_at(wavelet, scene, (size_t)i, 1, &sh);
        sampled_irradiance(wavelet, sample, w, shp, e);
        if (wenv_lights_count(wavelet->lights, 0))
            lights_irradiance(wavelet, nrm, shp, e);
        for (int c = 0; c < 3; c++) {
            out[3 * i + c] = head_on[c] * e[c];
            if (irradiance)
                irradiance[3 * i + c] = e[c];
        }
    }
}

static wenv_status check_scene(const wenv_shadow_scene *scene, size_t n, wenv_error *err)
{
    size_t nv = scene->occlusion->n_vertices;
    if (!scene->rows && scene->offset + n > nv)
        return wenv_error_set(err, WENV_ERR_VALUE, "occlusion was made for %zu vertices, shading %zu from %zu", nv, n,
                              scene->offset);
    for (size_t k = 0; scene->rows && k < n; k++)
        if (scene->rows[k] >= nv)
            return wenv_error_set(err, WENV_ERR_VALUE, "row %zu is vertex %u of an occlusion of %zu", k,
                                  (unsigned)scene->rows[k], nv);
    if (scene->bounce_self && wenv_occluders_vertex_count(scene->occluders) != nv)
        return wenv_error_set(err, WENV_ERR_VALUE,
                              "a mesh's own bounce needs its vertices to be the occluders' (%zu), the occlusion's %zu",
                              wenv_occluders_vertex_count(scene->occluders), nv);
    return WENV_OK;
}

/* The occlusion's unit normals turned into the method's frame, every vertex in order. */
static float *occlusion_normals(const wenv_shadow_scene *scene)
{
    const wenv_occlusion *o = scene->occlusion;
    float *out = malloc((o->n_vertices ? o->n_vertices : 1) * 3 * sizeof(float));
    const float *t = scene->turn;
    for (size_t i = 0; out && i < o->n_vertices; i++) {
        const float *a = o->normals + 3 * i;
        for (int r = 0; r < 3; r++)
            out[3 * i + (size_t)r] = t[3 * r] * a[0] + t[3 * r + 1] * a[1] + t[3 * r + 2] * a[2];
    }
    return out;
}

/* Replaces *a and *b by blocks of na and nb RGB triples (at least one each); -1 when out of memory,
 * with both kept. */
static int renew_pair(float **a, size_t na, float **b, size_t nb)
{
    float *x = malloc((na ? na : 1) * 3 * sizeof(float)), *y = malloc((nb ? nb : 1) * 3 * sizeof(float));
    if (!x || !y) {
        free(x);
        free(y);
        return -1;
    }
    free(*a);
    free(*b);
    *a = x;
    *b = y;
    return 0;
}

/* The hidden lighting of every blocked texel and its sums, unless kept for this occlusion under this
 * lighting and frame. */
static wenv_status ensure_hidden_light(wenv_wavelet *wavelet, const wenv_shadow_scene *scene, wenv_error *err)
{
    const wenv_occlusion *o = scene->occlusion;
    uint64_t key = wenv_fingerprint_word(wenv_fingerprint_word(WENV_FINGERPRINT_START, o->fingerprint),
                                         wenv_occluders_fingerprint(scene->occluders));
    key = wenv_fingerprint_floats(key, scene->turn, 9);
    if (wavelet->shadow_env_valid && wavelet->shadow_env_key == key)
        return WENV_OK;
    wavelet->shadow_env_valid = wavelet->shadow_valid = 0;
    size_t hits = o->n_masks ? o->hit_start[o->n_masks] : 0;
    /* the lights' rays are kept for a quarter of what the occluders may take */
    if (!wavelet->shadow_lights && !(wavelet->shadow_lights = calloc(1, sizeof *wavelet->shadow_lights)))
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for the shadows of %zu vertices", o->n_vertices);
    if (wenv_light_memo_reset(wavelet->shadow_lights, o->n_vertices, wenv_occluders_memory_budget(scene->occluders) / 4,
                              err))
        return err->status;
    if (renew_pair(&wavelet->shadow_lbar, hits, &wavelet->shadow_e_env, o->n_masks) < 0)
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for the shadows of %zu vertices", o->n_vertices);
    const wenv_node_pyramid *pyramid = wenv_grazing_light_pyramid(wavelet->grazing_light);
    const wenv_texel_reflection *tr = &wavelet->m->texel_reflection;
    float *lbar = wavelet->shadow_lbar, *e_env = wavelet->shadow_e_env;
    long long nm = (long long)o->n_masks;
#pragma omp parallel for schedule(dynamic, 256)
    for (long long k = 0; k < nm; k++) {
        wenv_vertex_shadow vs; /* in the frame of the vertex whose rays made the mask */
        wenv_vertex_shadow_init(&vs, scene, o->owner[k], NULL);
        wenv_shadow_hidden_light(&vs, pyramid, tr, lbar + 3 * o->hit_start[k], e_env + 3 * k);
    }
    wavelet->shadow_env_key = key;
    wavelet->shadow_env_valid = 1;
    return WENV_OK;
}

/* Makes what shading with `scene` keeps, unless it holds: the pyramid, the material's texel
 * reflection at the masks' resolution, the hidden lighting, and the same less the blocker's light.
 * with_bounce 0: the hidden lighting alone. */
static wenv_status ensure_shadows(wenv_wavelet *wavelet, const wenv_shadow_scene *scene, int with_bounce,
                                  wenv_error *err)
{
    wavelet->shadowing = 1;
    if (wenv_wavelet_ensure_grazing(wavelet, err) || wenv_wavelet_ensure_pyramid(wavelet, err))
        return err->status;
    const wenv_occlusion *o = scene->occlusion;
    wenv_wavelet_material *m = wavelet->m;
    if (m->texel_reflection.resolution != o->resolution) {
        wenv_texel_reflection kept = m->texel_reflection;
        m->texel_reflection = m->texel_reflection_before;
        m->texel_reflection_before = kept;
        if (m->texel_reflection.resolution != o->resolution) {
            wenv_texel_reflection_free(&m->texel_reflection);
            if (wenv_texel_reflection_make(&m->texel_reflection, m->mat, o->resolution, err))
                return err->status;
        }
    }
    double alpha_max = 0.0;
    for (size_t k = 0; k < wenv_material_lobe_count(m->mat); k++)
        alpha_max = fmax(alpha_max, wenv_material_lobe(m->mat, k)->alpha);
    /* with point rays, a lobe narrow against the coarsest masks is seen through its own rays at every
     * side: a bake's texels and its vertices' two passes (shadows.h) then see it alike */
    size_t side = o->point_rays ? WENV_OCCLUSION_RESOLUTION_MIN : o->resolution;
    m->lobes_narrow = wenv_material_mirror_centred(m->mat) && wenv_shadow_lobes_narrow(alpha_max, side);
    m->lobe_alpha = (float)alpha_max;
    if (ensure_hidden_light(wavelet, scene, err) || !with_bounce)
        return err->status;
    size_t own = scene->bounce_self ? m->serial : 0;
    if (wavelet->shadow_valid && wavelet->shadow_key == scene->key && wavelet->shadow_material == own)
        return WENV_OK;
    wavelet->shadow_valid = 0;
    size_t n = o->n_vertices, hits = o->n_masks ? o->hit_start[o->n_masks] : 0;
    float *own_light = scene->bounce_self ? malloc((n ? n : 1) * 3 * sizeof(float)) : NULL;
    float *normals = scene->bounce_self ? occlusion_normals(scene) : NULL;
    if ((scene->bounce_self && (!own_light || !normals)) ||
        renew_pair(&wavelet->shadow_hidden, hits, &wavelet->shadow_e_hidden, o->n_masks) < 0) {
        free(own_light);
        free(normals);
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for the shadows of %zu vertices", n);
    }
    memcpy(wavelet->shadow_hidden, wavelet->shadow_lbar, hits * 3 * sizeof(float));
    memcpy(wavelet->shadow_e_hidden, wavelet->shadow_e_env, o->n_masks * 3 * sizeof(float));
    /* a given bounce is in the world's units; a mesh's own light is in the method's already */
    wenv_shadow_scene sending = *scene;
    sending.rows = NULL; /* every vertex of the occlusion, in order */
    sending.offset = 0;
    if (scene->bounce_self) {
        diffuse_light(wavelet, normals, n, &sending, own_light, NULL);
        sending.bounce = own_light;
        sending.bounce_scale = 1.0f;
    }
    if (sending.bounce || sending.bounce_hits) {
        const float *cosine = m->texel_reflection.cosine;
        float *hidden = wavelet->shadow_hidden, *e_hidden = wavelet->shadow_e_hidden;
        long long nm = (long long)o->n_masks;
#pragma omp parallel for schedule(dynamic, 256)
        for (long long k = 0; k < nm; k++)
            wenv_shadow_bounce(&sending, (size_t)k, cosine, hidden + 3 * o->hit_start[k], e_hidden + 3 * k);
    }
    free(own_light);
    free(normals);
    wavelet->shadow_key = scene->key;
    wavelet->shadow_material = own;
    wavelet->shadow_valid = 1;
    return WENV_OK;
}

wenv_status wenv_wavelet_shade_shadowed(wenv_wavelet *wavelet, const float *normals, const float *views, size_t n,
                                        const wenv_shadow_scene *scene, float *out, float *irradiance,
                                        wenv_error *err)
{
    if (!wavelet->have_env || !wavelet->m)
        return wenv_error_set(err, WENV_ERR_VALUE, "the shader needs an environment and a material");
    if (check_scene(scene, n, err) || ensure_shadows(wavelet, scene, 1, err))
        return err->status;
    return shade_all(wavelet, normals, views, n, scene, out, irradiance, err);
}

wenv_status wenv_wavelet_diffuse_light(wenv_wavelet *wavelet, const float *normals, size_t n,
                                       const wenv_shadow_scene *scene, float *out, float *irradiance,
                                       wenv_error *err)
{
    if (!wavelet->have_env || !wavelet->m)
        return wenv_error_set(err, WENV_ERR_VALUE, "the shader needs an environment and a material");
    if (scene) {
        if (check_scene(scene, n, err))
            return err->status;
        /* the hidden lighting alone: a bounce asked of this mesh is what it sends, not what it gets */
        if (ensure_shadows(wavelet, scene, 0, err))
            return err->status;
    }
    diffuse_light(wavelet, normals, n, scene, out, irradiance);
    return WENV_OK;
}

/* ---- each vertex lit through its own materials (method.h's shade_lights) ---------------------- */

void wenv_wavelet_set_lights_apart(wenv_wavelet *wavelet, int apart) { wavelet->lights_apart = apart != 0; }

void wenv_wavelet_palette_free(wenv_wavelet *wavelet)
{
    for (size_t i = 0; i < wavelet->n_palette; i++) {
        if (wavelet->palette_made && wavelet->palette_made[i])
            wenv_light_lobes_free(&wavelet->palette[i]);
        if (wavelet->palette_mat)
            wenv_material_free(wavelet->palette_mat[i]);
    }
    free(wavelet->palette_mat);
    free(wavelet->palette);
    free(wavelet->palette_made);
    wavelet->palette_mat = NULL;
    wavelet->palette = NULL;
    wavelet->palette_made = NULL;
    wavelet->n_palette = 0;
}

/* What the lights read of every palette entry a vertex reads (copies of the materials, kept while
 * the palette's key holds). */
static wenv_status ensure_palette(wenv_wavelet *wavelet, const wenv_vertex_lights *vl, size_t n, wenv_error *err)
{
    if (wavelet->palette && wavelet->palette_key != vl->palette_key)
        wenv_wavelet_palette_free(wavelet);
    if (!wavelet->palette) {
        size_t np = vl->n_palette ? vl->n_palette : 1;
        wavelet->palette_mat = calloc(np, sizeof *wavelet->palette_mat);
        wavelet->palette = calloc(np, sizeof *wavelet->palette);
        wavelet->palette_made = calloc(np, 1);
        wavelet->n_palette = vl->n_palette;
        wavelet->palette_key = vl->palette_key;
        if (!wavelet->palette_mat || !wavelet->palette || !wavelet->palette_made) {
            wenv_wavelet_palette_free(wavelet);
            return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for %zu light materials", vl->n_palette);
        }
    }
    size_t *todo = malloc((wavelet->n_palette ? wavelet->n_palette : 1) * sizeof *todo), ntodo = 0;
    unsigned char *wanted = calloc(wavelet->n_palette ? wavelet->n_palette : 1, 1);
    if (!todo || !wanted) {
        free(todo);
        free(wanted);
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for %zu light materials", vl->n_palette);
    }
    for (size_t k = 0; k < WENV_VERTEX_LIGHTS_PICKS * n; k++) {
        uint32_t p = vl->pick[k];
        const float *w = vl->weight + 3 * k;
        if ((w[0] != 0.0f || w[1] != 0.0f || w[2] != 0.0f) && !wavelet->palette_made[p] && !wanted[p]) {
            wanted[p] = 1;
            todo[ntodo++] = p;
        }
    }
    free(wanted);
    atomic_int failed = 0;
    long long nt = (long long)ntodo;
#pragma omp parallel for schedule(dynamic, 8)
    for (long long e = 0; e < nt; e++) {
        size_t p = todo[e];
        wenv_error one = {0};
        if (wenv_material_copy(&wavelet->palette_mat[p], vl->palette[p], &one) ||
            wenv_light_lobes_make(&wavelet->palette[p], wavelet->palette_mat[p], &one)) {
            atomic_store(&failed, 1);
            continue;
        }
        wavelet->palette_made[p] = 1;
    }
    free(todo);
    if (failed)
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for %zu light materials", vl->n_palette);
    return WENV_OK;
}

static wenv_status check_lights(const wenv_vertex_lights *vl, size_t n, wenv_error *err)
{
    for (size_t k = 0; k < WENV_VERTEX_LIGHTS_PICKS * n; k++) {
        if (vl->pick[k] >= vl->n_palette)
            return wenv_error_set(err, WENV_ERR_VALUE, "vertex %zu picks a light material past the %zu made",
                                  k / WENV_VERTEX_LIGHTS_PICKS, vl->n_palette);
        for (int c = 0; c < 3; c++)
            if (!isfinite(vl->weight[3 * k + (size_t)c]))
                return wenv_error_set(err, WENV_ERR_VALUE, "vertex %zu weighs a light material by %g",
                                      k / WENV_VERTEX_LIGHTS_PICKS, (double)vl->weight[3 * k + (size_t)c]);
    }
    return WENV_OK;
}

wenv_status wenv_wavelet_shade_lights(wenv_wavelet *wavelet, const float *normals, const float *views, size_t n,
                                      const wenv_shadow_scene *scene, const wenv_vertex_lights *vl, float *out,
                                      float *irradiance, wenv_error *err)
{
    if (!wavelet->have_env || !wavelet->m)
        return wenv_error_set(err, WENV_ERR_VALUE, "the shader needs an environment and a material");
    if (!wenv_lights_count(wavelet->lights, 0) || n == 0)
        return WENV_OK;
    if (check_lights(vl, n, err) || (scene && (check_scene(scene, n, err) || ensure_shadows(wavelet, scene, 1, err))) ||
        ensure_palette(wavelet, vl, n, err))
        return err->status;
    float tolerance = (float)wavelet->q.light_tolerance;
    long long nn = (long long)n;
#pragma omp parallel for schedule(dynamic, 256)
    for (long long i = 0; i < nn; i++) {
        const float *a = normals + 3 * i, *b = views + 3 * i;
        float in = 1.0f / sqrtf(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]);
        float iv = 1.0f / sqrtf(b[0] * b[0] + b[1] * b[1] + b[2] * b[2]);
        float nrm[3] = {a[0] * in, a[1] * in, a[2] * in}, v[3] = {b[0] * iv, b[1] * iv, b[2] * iv};
        float cos_v = nrm[0] * v[0] + nrm[1] * v[1] + nrm[2] * v[2];
        if (!(cos_v > 0.0f))
            continue; /* black, as shade left it */
        vertex_shadow sh;
        const vertex_shadow *shp = vertex_shadow_at(wavelet, scene, (size_t)i, 0, &sh);
        float *e = irradiance + 3 * i, *o = out + 3 * i;
        lights_irradiance(wavelet, nrm, shp, e);
        float rest = o[0] + o[1] + o[2];
        for (int j = 0; j < WENV_VERTEX_LIGHTS_PICKS; j++) {
            size_t at = WENV_VERTEX_LIGHTS_PICKS * (size_t)i + (size_t)j;
            const float *w = vl->weight + 3 * at;
            const wenv_light_lobes *lobes = &wavelet->palette[vl->pick[at]];
            if ((w[0] == 0.0f && w[1] == 0.0f && w[2] == 0.0f) || !lobes->has_lobes)
                continue;
            wenv_lights_lobe walk = wenv_light_lobes_walk(lobes, wavelet->narrow_alpha);
            /* against the rest and a uniform mean's reflection, as shade_vertex reads them */
            float scale = rest + wavelet->mean_radiance * wenv_light_lobes_albedo_sum(lobes, cos_v), s[3] = {0, 0, 0};
            wenv_lights_specular(wavelet->lights, lobes->mat, lobes->cos_h_min, &walk, nrm, v, cos_v, tolerance * scale,
                                 shp ? &shp->vs.lights : NULL, s);
            for (int c = 0; c < 3; c++)
                o[c] += w[c] * s[c];
        }
    }
    return WENV_OK;
}
