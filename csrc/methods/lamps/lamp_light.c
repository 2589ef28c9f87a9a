#include "methods/lamps/lamp_light.h"

#include <math.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>

#include "base/fingerprint.h"
#include "methods/lamps/lamp_patch.h"
#include "math/frame.h"
#include "math/unit_pair.h"

/* Glossy points summed at once, per thread: the finest grid's. */
#define GLOSSY_POINTS (WENV_LAMP_GLOSSY_GRID * WENV_LAMP_GLOSSY_GRID)

struct wenv_lamp_light {
    size_t n, n_lamps, made;
    wenv_lamp *lamps;
    float *positions, *normals; /* the vertices', normals made unit */
    float *share;               /* n x n_lamps: the Lambertian part's light per unit of the lamp's radiance */
    uint16_t *seen;             /* n x n_lamps: which cells of the lamp the vertex sees (bit j k + i) */
    const wenv_occluders *occ;  /* what it was cast against: only its fingerprint is read later */
    float lift;
    uint64_t key;               /* of the vertices and what blocks the lamps */
    uint64_t *lamp_keys;        /* of each lamp's placement and shape: a lamp moved alone is made alone */
};

void wenv_lamp_light_free(wenv_lamp_light *l)
{
    if (!l)
        return;
    free(l->lamps);
    free(l->positions);
    free(l->normals);
    free(l->share);
    free(l->seen);
    free(l->lamp_keys);
    free(l);
}

size_t wenv_lamp_light_vertices(const wenv_lamp_light *l) { return l->n; }
size_t wenv_lamp_light_lamps(const wenv_lamp_light *l) { return l->n_lamps; }
size_t wenv_lamp_light_made(const wenv_lamp_light *l) { return l->made; }

static double dot3(const double a[3], const double b[3]) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }

static uint64_t mesh_key(const float *positions, const float *normals, size_t n, const wenv_occluders *occ)
{
    uint64_t h = wenv_fingerprint_word(WENV_FINGERPRINT_START, n);
    h = wenv_fingerprint_floats(h, positions, 3 * n);
    h = wenv_fingerprint_floats(h, normals, 3 * n);
    return wenv_fingerprint_word(h, occ ? wenv_occluders_fingerprint(occ) : 0);
}

/* How many cells a side the lamp's patch is read in from a point. */
static size_t cells_of(const wenv_lamp_patch *pa)
{
    return wenv_lamp_patch_angle(pa) > WENV_LAMP_WIDE ? WENV_LAMP_CELLS : 1;
}

/* The direction and distance to a delta lamp from p (0: none). */
static int delta_direction(const wenv_lamp *lamp, const double p[3], double w[3], double *dist)
{
    if (lamp->settings.kind == WENV_LAMP_SUN) {
        for (int c = 0; c < 3; c++)
            w[c] = -lamp->emit_dir[c];
        *dist = INFINITY;
        return 1;
    }
    double x[3] = {lamp->position[0] - p[0], lamp->position[1] - p[1], lamp->position[2] - p[2]};
    double d = sqrt(dot3(x, x));
    if (!(d > 0.0))
        return 0;
    for (int c = 0; c < 3; c++)
        w[c] = x[c] / d;
    *dist = d;
    return 1;
}

/* A delta lamp's weight along w (what multiplies its radiance and the BRDF times the cosine). */
static double delta_weight(const wenv_lamp *lamp, const double w[3], double dist)
{
    if (lamp->settings.kind == WENV_LAMP_SUN)
        return 1.0;
    double back[3] = {-w[0], -w[1], -w[2]};
    return wenv_lamp_factor(lamp, back, 0) / (dist * dist);
}

/* Whether the lamp's factor is one value over the whole patch, and that value (at its centre). */
static int factor_even(const wenv_lamp *lamp, const wenv_lamp_patch *pa, double *value)
{
    double d = sqrt(dot3(pa->centre, pa->centre));
    double back[3] = {-pa->centre[0] / d, -pa->centre[1] / d, -pa->centre[2] / d};
    *value = wenv_lamp_factor_varies(lamp) ? wenv_lamp_factor(lamp, back, pa->within_sphere) : 1.0;
    return !wenv_lamp_factor_varies(lamp) ||
           wenv_lamp_factor_even(lamp, back, wenv_lamp_patch_angle(pa), pa->within_sphere);
}

/* The lamps as later shades read them (their light, not what blocked it): their blockers were
 * borrowed for the call that made the shadows. */
static void keep_settings(wenv_lamp *kept, const wenv_lamp *lamps, size_t n_lamps)
{
    memcpy(kept, lamps, n_lamps * sizeof *lamps);
    for (size_t j = 0; j < n_lamps; j++)
        kept[j].blockers = NULL;
}

/* Vertices whose rays to a lamp are cast as one stream (neighbours in the mesh's order: their rays
 * start near each other and run towards the same lamp). */
#define RAY_BLOCK 16
#define CELLS2 (WENV_LAMP_CELLS * WENV_LAMP_CELLS)

/* One vertex's view of a lamp while its rays are cast: what finish_one reads. */
typedef struct {
    wenv_lamp_patch pa;
    double nrm[3], whole, even, weight;
    double factor[CELLS2];
    size_t k;     /* cells a side of the patch (0: a delta lamp) */
    size_t first; /* its rays among the block's */
    size_t rays;  /* how many (0: nothing to test, every cell seen) */
    int varies, lit;
} lamp_view;

/* Vertex i's view of the lamp and its rays (towards the cells' centres, or the delta lamp) written
 * at origins, dirs and fars; returns how many (none where no light reaches it or nothing blocks). */
static size_t prepare_rays(const wenv_lamp_light *L, const wenv_lamp *lamp, int blocked_at_all, size_t i,
                           lamp_view *v, float *origins, float *dirs, float *fars)
{
    double p[3];
    float origin[3];
    for (int c = 0; c < 3; c++) {
        p[c] = L->positions[3 * i + (size_t)c];
        v->nrm[c] = L->normals[3 * i + (size_t)c];
        origin[c] = L->positions[3 * i + (size_t)c] + L->lift * L->normals[3 * i + (size_t)c];
    }
    v->lit = 0;
    v->rays = 0;
    v->k = 0;
    if (lamp->delta) {
        double w[3], dist;
        if (!delta_direction(lamp, p, w, &dist))
            return 0;
        double cos_i = dot3(v->nrm, w), weight = delta_weight(lamp, w, dist);
        if (!(cos_i > 0.0) || !(weight > 0.0))
            return 0;
        v->lit = 1;
        v->weight = cos_i * weight;
        if (!blocked_at_all)
            return 0;
        memcpy(origins, origin, sizeof origin);
        for (int c = 0; c < 3; c++)
            dirs[c] = (float)w[c];
        fars[0] = isinf(dist) ? INFINITY : (float)(dist * (1.0 - 1e-4));
        return v->rays = 1;
    }
    if (!wenv_lamp_patch_at(lamp, p, &v->pa))
        return 0;
    v->whole = wenv_lamp_patch_psa(&v->pa, v->nrm);
    if (!(v->whole > 0.0))
        return 0;
    size_t k = cells_of(&v->pa);
    v->varies = !factor_even(lamp, &v->pa, &v->even);
    if (!v->varies && !(v->even > 0.0))
        return 0; /* outside a spot's cone */
    v->lit = 1;
    v->k = k;
    double h = 2.0 / (double)k;
    for (size_t c = 0; c < k * k; c++) {
        double x[3];
        wenv_lamp_patch_point(&v->pa, -1.0 + h * ((double)(c % k) + 0.5), -1.0 + h * ((double)(c / k) + 0.5), x);
        double t = sqrt(dot3(x, x)), back[3] = {-x[0] / t, -x[1] / t, -x[2] / t};
        v->factor[c] = v->varies ? wenv_lamp_factor(lamp, back, v->pa.within_sphere) : v->even;
        memcpy(origins + 3 * c, origin, sizeof origin);
        for (int a = 0; a < 3; a++)
            dirs[3 * c + (size_t)a] = (float)(x[a] / t);
        fars[c] = v->pa.infinite ? INFINITY : (float)(t * (1.0 - 1e-4));
    }
    return v->rays = blocked_at_all ? k * k : 0;
}

/* The vertex's share of the lamp and the cells it sees, its rays' answers at blocked (NULL: none
 * cast, every cell seen). */
static void finish_one(const lamp_view *v, const wenv_lamp *lamp, const unsigned char *blocked, float *share,
                       uint16_t *seen)
{
    *share = 0.0f;
    *seen = 0;
    if (!v->lit)
        return;
    if (v->k == 0) { /* a delta lamp */
        if (!(v->rays && blocked[0])) {
            *share = (float)v->weight;
            *seen = 1;
        }
        return;
    }
    size_t k = v->k;
    int alike = !v->varies;
    for (size_t c = 0; c < k * k; c++) {
        if (!(v->rays && blocked[c]))
            *seen |= (uint16_t)(1u << c);
        else
            alike = 0;
    }
    if (alike) { /* all of it seen, equally bright: the closed form alone */
        *share = (float)(v->whole * v->even);
        return;
    }
    if (*seen == 0) /* none of it seen: no light, whatever the cells' shares */
        return;
    if (k == 1) {
        *share = (float)(v->whole * v->factor[0] * (double)(*seen & 1u));
        return;
    }
    /* the cells' own shares weigh what is seen, read twice as finely where the factor varies */
    size_t kf = v->varies ? 2 * k : k;
    double hf = 2.0 / (double)kf, sum = 0.0, lit = 0.0;
    for (size_t c = 0; c < kf * kf; c++) {
        size_t a = c % kf, b = c / kf, cell = (b * k / kf) * k + a * k / kf;
        if (!((*seen >> cell) & 1u)) {
            sum += wenv_lamp_patch_cell_psa(&v->pa, kf, a, b, v->nrm);
            continue;
        }
        double f = v->factor[cell];
        if (v->varies) {
            double x[3];
            wenv_lamp_patch_point(&v->pa, -1.0 + hf * ((double)a + 0.5), -1.0 + hf * ((double)b + 0.5), x);
            double t = sqrt(dot3(x, x)), back[3] = {-x[0] / t, -x[1] / t, -x[2] / t};
            f = wenv_lamp_factor(lamp, back, v->pa.within_sphere);
        }
        double psa = wenv_lamp_patch_cell_psa(&v->pa, kf, a, b, v->nrm);
        sum += psa;
        lit += psa * f;
    }
    *share = sum > 0.0 ? (float)(v->whole * lit / sum) : 0.0f;
}

/* Vertices [first, end)'s shares of lamp j and the cells they see, their rays cast as one stream. */
static void prepare_block(wenv_lamp_light *L, const wenv_lamp *lamp, const wenv_occluders *occ, size_t j,
                          size_t first, size_t end)
{
    lamp_view views[RAY_BLOCK];
    float origins[3 * RAY_BLOCK * CELLS2], dirs[3 * RAY_BLOCK * CELLS2], fars[RAY_BLOCK * CELLS2];
    unsigned char blocked[RAY_BLOCK * CELLS2];
    const wenv_occluders *blockers = wenv_lamp_blockers(lamp, occ);
    size_t rays = 0;
    for (size_t i = first; i < end; i++) {
        lamp_view *v = &views[i - first];
        v->first = rays;
        rays += prepare_rays(L, lamp, blockers != NULL, i, v, origins + 3 * rays, dirs + 3 * rays, fars + rays);
    }
    if (rays)
        wenv_occluders_test_each(blockers, origins, dirs, fars, rays, blocked);
    for (size_t i = first; i < end; i++) {
        const lamp_view *v = &views[i - first];
        finish_one(v, lamp, blocked + v->first, &L->share[i * L->n_lamps + j], &L->seen[i * L->n_lamps + j]);
    }
}

wenv_status wenv_lamp_light_ensure(wenv_lamp_light **light, const wenv_lamp *lamps, size_t n_lamps,
                                   const float *positions, const float *normals, size_t n, const wenv_occluders *occ,
                                   const wenv_progress *progress, wenv_error *err)
{
    if (n_lamps > 0 && !lamps)
        return wenv_error_set(err, WENV_ERR_VALUE, "no lamps given");
    for (size_t i = 0; i < n; i++) {
        const float *p = positions + 3 * i, *m = normals + 3 * i;
        if (!isfinite(p[0]) || !isfinite(p[1]) || !isfinite(p[2]))
            return wenv_error_set(err, WENV_ERR_VALUE, "positions[%zu] is not finite", i);
        if (!isfinite(m[0]) || !isfinite(m[1]) || !isfinite(m[2]) || m[0] * m[0] + m[1] * m[1] + m[2] * m[2] <= 0.0f)
            return wenv_error_set(err, WENV_ERR_VALUE, "normals[%zu] is zero or not finite", i);
    }
    uint64_t key = mesh_key(positions, normals, n, occ);
    wenv_lamp_light *before = *light;
    /* the same vertices and blockers with as many lamps: only the lamps moved or reshaped are made */
    int keep = before && before->key == key && before->n == n && before->n_lamps == n_lamps;
    unsigned char *redo = malloc(n_lamps ? n_lamps : 1);
    size_t cells = (n ? n : 1) * (n_lamps ? n_lamps : 1), n_redo = 0;
    wenv_lamp_light *l = redo ? calloc(1, sizeof *l) : NULL;
    if (l) {
        l->lamps = malloc((n_lamps ? n_lamps : 1) * sizeof *lamps);
        l->lamp_keys = malloc((n_lamps ? n_lamps : 1) * sizeof *l->lamp_keys);
        l->positions = malloc((n ? n : 1) * 3 * sizeof(float));
        l->normals = malloc((n ? n : 1) * 3 * sizeof(float));
        l->share = malloc(cells * sizeof(float));
        l->seen = malloc(cells * sizeof(uint16_t));
    }
    if (!l || !l->lamps || !l->lamp_keys || !l->positions || !l->normals || !l->share || !l->seen) {
        free(redo);
        wenv_lamp_light_free(l);
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for the lamps' light at %zu vertices", n);
    }
    for (size_t j = 0; j < n_lamps; j++) {
        l->lamp_keys[j] = wenv_lamp_geometry_key(&lamps[j], WENV_FINGERPRINT_START);
        redo[j] = !keep || l->lamp_keys[j] != before->lamp_keys[j];
        n_redo += redo[j];
    }
    if (keep && n_redo == 0) { /* colours, powers, flags: read at each shade */
        keep_settings(before->lamps, lamps, n_lamps);
        free(redo);
        wenv_lamp_light_free(l);
        return WENV_OK;
    }
    if (keep) {
        memcpy(l->share, before->share, n * n_lamps * sizeof(float));
        memcpy(l->seen, before->seen, n * n_lamps * sizeof(uint16_t));
    }
    l->n = n;
    l->n_lamps = n_lamps;
    l->key = key;
    l->made = (before ? before->made : 0) + 1;
    l->lift = occ ? wenv_occluders_offset(occ) : 0.0f;
    memcpy(l->positions, positions, 3 * n * sizeof(float));
    for (size_t i = 0; i < n; i++) {
        const float *m = normals + 3 * i;
        float len = sqrtf(m[0] * m[0] + m[1] * m[1] + m[2] * m[2]);
        for (int c = 0; c < 3; c++)
            l->normals[3 * i + (size_t)c] = m[c] / len;
    }
    atomic_size_t done = 0;
    atomic_int cancelled = 0;
    size_t blocks = (n + RAY_BLOCK - 1) / RAY_BLOCK;
    keep_settings(l->lamps, lamps, n_lamps);
#pragma omp parallel for schedule(dynamic, 4)
    for (long long b = 0; b < (long long)blocks; b++) {
        if (atomic_load(&cancelled))
            continue;
        size_t first = (size_t)b * RAY_BLOCK, end = first + RAY_BLOCK < n ? first + RAY_BLOCK : n;
        for (size_t j = 0; j < n_lamps; j++)
            if (redo[j])
                prepare_block(l, &lamps[j], occ, j, first, end);
        if ((b & 15) == 15)
            wenv_progress_item(progress, &done, (blocks + 15) / 16, &cancelled);
    }
    free(redo);
    if (atomic_load(&cancelled) || wenv_progress_finish(progress)) {
        wenv_lamp_light_free(l);
        return wenv_error_set(err, WENV_ERR_CANCELLED, "the lamps' shadows were cancelled");
    }
    wenv_lamp_light_free(before);
    *light = l;
    return WENV_OK;
}

/* ---- at a view ---- */

typedef struct {
    float x[GLOSSY_POINTS], y[GLOSSY_POINTS], z[GLOSSY_POINTS], w[GLOSSY_POINTS];
    float r[GLOSSY_POINTS], g[GLOSSY_POINTS], b[GLOSSY_POINTS];
    float *terms;
} glossy_work;

/* The glossy light of `count` points (local directions and weights) through material m, times rgb
 * weights mw, added to acc. */
static void glossy_sum(glossy_work *gw, const wenv_material *m, const float wo[3], const float *terms, size_t count,
                       const float mw[3], double acc[3])
{
    wenv_material_specular_cos_f_many(m, wo, terms, count, gw->x, gw->y, gw->z, gw->r, gw->g, gw->b);
    double s[3] = {0.0, 0.0, 0.0};
    for (size_t q = 0; q < count; q++) {
        s[0] += (double)(gw->w[q] * gw->r[q]);
        s[1] += (double)(gw->w[q] * gw->g[q]);
        s[2] += (double)(gw->w[q] * gw->b[q]);
    }
    for (int c = 0; c < 3; c++)
        acc[c] += mw[c] * s[c];
}

/* The cosine of the widest angle from the mirror direction at which a vertex's materials reflect
 * anything visible (method.h's exact lights skip the same): -1 where a lobe may reflect anywhere. */
static double lobe_cone_cos(const wenv_material *const *mats, size_t count)
{
    double widest = 0.0;
    for (size_t m = 0; m < count; m++) {
        if (!wenv_material_mirror_centred(mats[m]))
            return -1.0;
        for (size_t i = 0; i < wenv_material_lobe_count(mats[m]); i++) {
            double c = wenv_material_lobe_cos_h_min(mats[m], i);
            if (!(c > 0.0))
                return -1.0;
            /* a reflection about h strays from the mirror direction by at most twice h's angle */
            widest = fmax(widest, 2.0 * acos(fmin(1.0, c)));
        }
    }
    return widest >= M_PI ? -1.0 : cos(widest);
}

/* The narrowest lobe among a vertex's materials (INFINITY: none reflects). */
static double narrowest(const wenv_material *const *mats, size_t count)
{
    double a = INFINITY;
    for (size_t m = 0; m < count; m++)
        a = fmin(a, wenv_material_lobe_width(mats[m]));
    return a;
}

/* Whether a part of a lamp `half` radians across whose centre is `off` radians from the mirror
 * direction sees only the lobes' tails, which fall as a power of the angle: well away from the peak
 * and small against its distance from it, so that a few points read it. */
static int tail_only(double off, double half, double alpha)
{
    return off - half > WENV_LAMP_PEAK * alpha && off > 6.0 * half;
}

/* A patch's glossy points being gathered into a glossy_work. */
typedef struct {
    const wenv_lamp *lamp;
    const wenv_lamp_patch *pa;
    size_t cells;
    uint16_t seen;
    int varies;
    double even; /* the factor where it does not vary */
    const double *frame, *mirror;
    double cone_cos;
    glossy_work *gw;
    size_t count;
} glossy_points;

/* The midpoints of a k x k grid over the square [s0, s0 + side] x [t0, t0 + side] of the patch's
 * domain that the vertex sees and the lobes may reach: local direction and weight (solid angle
 * times the lamp's factor). */
static void add_points(glossy_points *g, double s0, double t0, double side, size_t k)
{
    double h = side / (double)k, da = g->pa->area * h * h / 4.0;
    for (size_t b = 0; b < k; b++)
        for (size_t a = 0; a < k; a++) {
            double s = s0 + h * ((double)a + 0.5), t = t0 + h * ((double)b + 0.5), x[3];
            size_t cx = (size_t)((s + 1.0) * 0.5 * (double)g->cells), cy = (size_t)((t + 1.0) * 0.5 * (double)g->cells);
            cx = cx < g->cells ? cx : g->cells - 1;
            cy = cy < g->cells ? cy : g->cells - 1;
            if (!((g->seen >> (cy * g->cells + cx)) & 1u) || g->count >= GLOSSY_POINTS)
                continue;
            wenv_lamp_patch_point(g->pa, s, t, x);
            double dist = sqrt(dot3(x, x)), w[3] = {x[0] / dist, x[1] / dist, x[2] / dist};
            double cos_l = -dot3(g->pa->normal, w);
            if (!(cos_l > 0.0) || dot3(w, g->mirror) < g->cone_cos)
                continue;
            double back[3] = {-w[0], -w[1], -w[2]};
            double fac = g->varies ? wenv_lamp_factor(g->lamp, back, g->pa->within_sphere) : g->even;
            if (!(fac > 0.0))
                continue;
            size_t q = g->count++;
            g->gw->x[q] = (float)dot3(g->frame, w);
            g->gw->y[q] = (float)dot3(g->frame + 3, w);
            g->gw->z[q] = (float)dot3(g->frame + 6, w);
            g->gw->w[q] = (float)(da * cos_l / (dist * dist) * fac);
        }
}

wenv_status wenv_lamp_light_shade(const wenv_lamp_rows *rows, const wenv_material *mat, const wenv_vertex_lights *own,
                                  const float *normals, const float *views, size_t n, const wenv_bump_normals *bump,
                                  float *out, float *irradiance, wenv_error *err)
{
    const wenv_lamp_light *L = rows->light;
    for (size_t k = 0; k < n; k++) {
        size_t i = rows->rows ? rows->rows[k] : rows->offset + k;
        if (i >= L->n)
            return wenv_error_set(err, WENV_ERR_VALUE, "the lamps' light was made for %zu vertices, not %zu", L->n,
                                  i + 1);
    }
    size_t terms = mat ? wenv_material_view_terms(mat) : 0;
    for (size_t p = 0; own && p < own->n_palette; p++)
        if (own->palette[p] && wenv_material_view_terms(own->palette[p]) > terms)
            terms = wenv_material_view_terms(own->palette[p]);
    double mat_cone_cos = mat && views ? lobe_cone_cos(&mat, 1) : -1.0;
    atomic_int failed = 0;
    long long nn = (long long)n;
#pragma omp parallel
    {
        glossy_work *gw = malloc(sizeof *gw);
        if (gw && !(gw->terms = malloc(WENV_VERTEX_LIGHTS_PICKS * (terms ? terms : 1) * sizeof(float)))) {
            free(gw);
            gw = NULL;
        }
        if (!gw)
            atomic_store(&failed, 1);
#pragma omp for schedule(dynamic, 256)
        for (long long kk = 0; kk < nn; kk++) {
            if (!gw)
                continue;
            size_t k = (size_t)kk, i = rows->rows ? rows->rows[k] : rows->offset + k;
            double p[3], nrm[3], v[3] = {0.0, 0.0, 1.0};
            for (int c = 0; c < 3; c++)
                p[c] = L->positions[3 * i + (size_t)c];
            if (views) {
                wenv_unit_pair(normals, views, k, nrm, v);
            } else {
                double len = sqrt((double)normals[3 * k] * normals[3 * k] + (double)normals[3 * k + 1] * normals[3 * k + 1] +
                                  (double)normals[3 * k + 2] * normals[3 * k + 2]);
                for (int c = 0; c < 3; c++)
                    nrm[c] = normals[3 * k + (size_t)c] / len;
            }
            /* the vertex's materials and their weights */
            const wenv_material *mats[WENV_VERTEX_LIGHTS_PICKS];
            float mw[WENV_VERTEX_LIGHTS_PICKS][3];
            size_t n_mats = 0;
            if (own) {
                for (size_t m = 0; m < WENV_VERTEX_LIGHTS_PICKS; m++) {
                    const float *w = own->weight + 3 * (WENV_VERTEX_LIGHTS_PICKS * k + m);
                    if (w[0] > 0.0f || w[1] > 0.0f || w[2] > 0.0f) {
                        mats[n_mats] = own->palette[own->pick[WENV_VERTEX_LIGHTS_PICKS * k + m]];
                        memcpy(mw[n_mats++], w, 3 * sizeof(float));
                    }
                }
            } else {
                mats[n_mats] = mat;
                mw[n_mats][0] = mw[n_mats][1] = mw[n_mats][2] = 1.0f;
                n_mats++;
            }
            double alpha = views ? narrowest(mats, n_mats) : INFINITY;
            double f[9];
            wenv_frame(nrm, f);
            float wo[3] = {(float)dot3(f, v), (float)dot3(f + 3, v), (float)dot3(f + 6, v)};
            if (views && !(wo[2] > 0.0f))
                continue; /* seen from behind: nothing of the lamps, as nothing of the sky */
            int glossy_view = views && isfinite(alpha);
            /* (a vertex's own materials are not culled: their cones would cost more than they save) */
            for (size_t m = 0; glossy_view && m < n_mats; m++) /* what the view alone sets, once a vertex */
                wenv_material_prepare_view_f(mats[m], wo, gw->terms + m * (terms ? terms : 1));
            double cone_cos = glossy_view && !own ? mat_cone_cos : -1.0, mirror[3];
            for (int c = 0; c < 3; c++)
                mirror[c] = 2.0 * dot3(nrm, v) * nrm[c] - v[c];
            double spec[3] = {0.0, 0.0, 0.0}, irr[3] = {0.0, 0.0, 0.0}, ns[3];
            int bent = bump && bump->smooth;
            if (bent) {
                const float *b = bump->smooth + 3 * k;
                double len = sqrt((double)b[0] * b[0] + (double)b[1] * b[1] + (double)b[2] * b[2]);
                for (int c = 0; c < 3; c++)
                    ns[c] = b[c] / len;
            }
            for (size_t j = 0; j < L->n_lamps; j++) {
                const wenv_lamp *lamp = &L->lamps[j];
                float share = L->share[i * L->n_lamps + j];
                uint16_t seen = L->seen[i * L->n_lamps + j];
                if (!(share > 0.0f))
                    continue;
                double through = 1.0, towards[3], dist;
                if (bent && delta_direction(lamp, p, towards, &dist)) /* at the lamp's centre */
                    through = wenv_bump_diffuse_weight(nrm, ns, towards, bump->correction);
                if (lamp->settings.diffuse)
                    for (int c = 0; c < 3; c++)
                        irr[c] += (double)share * through * lamp->radiance[c];
                if (!glossy_view || !lamp->settings.glossy)
                    continue;
                double lamp_spec[3] = {0.0, 0.0, 0.0};
                size_t count = 0;
                if (lamp->delta) {
                    double w[3], dist;
                    delta_direction(lamp, p, w, &dist);
                    gw->x[0] = (float)dot3(f, w);
                    gw->y[0] = (float)dot3(f + 3, w);
                    gw->z[0] = (float)dot3(f + 6, w);
                    gw->w[0] = (float)delta_weight(lamp, w, dist);
                    count = 1;
                } else {
                    wenv_lamp_patch pa;
                    if (!wenv_lamp_patch_at(lamp, p, &pa))
                        continue;
                    size_t cells = cells_of(&pa);
                    double angle = wenv_lamp_patch_angle(&pa);
                    double dc = sqrt(dot3(pa.centre, pa.centre));
                    double off = acos(fmax(-1.0, fmin(1.0, dot3(pa.centre, mirror) / dc)));
                    if (cone_cos > -1.0 && off - angle > acos(cone_cos))
                        continue; /* the whole lamp outside the lobes' cone: no highlight */
                    size_t grid = (size_t)ceil(fmin(2.0 * angle / (WENV_LAMP_GLOSSY_SPACING * alpha),
                                                    (double)WENV_LAMP_GLOSSY_GRID));
                    double even;
                    int varies = !factor_even(lamp, &pa, &even);
                    if (!varies && !(even > 0.0))
                        continue;
                    if (tail_only(off, angle, alpha) && grid > 2 && !varies)
                        grid = 2; /* only the lobes' tails reach it: smooth across it */
                    if (grid < 1)
                        grid = 1;
                    /* a cone's or a spread's edge across a wide lamp is read on the coarse grid at least */
                    if (varies && angle > WENV_LAMP_WIDE && grid < WENV_LAMP_GLOSSY_COARSE)
                        grid = WENV_LAMP_GLOSSY_COARSE;
                    /* a lamp partly hidden is read at least as finely as its cells */
                    if (seen != (uint16_t)((1u << (cells * cells)) - 1u) && grid < cells)
                        grid = cells;
                    glossy_points pts = {lamp, &pa, cells, seen, varies, even, f, mirror, cone_cos, gw, 0};
                    if (grid <= WENV_LAMP_GLOSSY_COARSE) {
                        add_points(&pts, -1.0, -1.0, 2.0, grid);
                    } else {
                        /* coarse cells, each split where the lobes' peak may fall on it: the tails
                         * are smooth at the coarse spacing */
                        size_t coarse = WENV_LAMP_GLOSSY_COARSE, split = (grid + coarse - 1) / coarse;
                        double h = 2.0 / (double)coarse, half_angle = angle / (double)coarse;
                        for (size_t b = 0; b < coarse; b++)
                            for (size_t a = 0; a < coarse; a++) {
                                double s0 = -1.0 + h * (double)a, t0 = -1.0 + h * (double)b, x[3];
                                wenv_lamp_patch_point(&pa, s0 + 0.5 * h, t0 + 0.5 * h, x);
                                double cell_off = acos(fmax(-1.0, fmin(1.0, dot3(x, mirror) / sqrt(dot3(x, x)))));
                                add_points(&pts, s0, t0, h, tail_only(cell_off, half_angle, alpha) ? 1 : split);
                            }
                    }
                    count = pts.count;
                }
                for (size_t m = 0; count && m < n_mats; m++)
                    glossy_sum(gw, mats[m], wo, gw->terms + m * (terms ? terms : 1), count, mw[m], lamp_spec);
                for (int c = 0; c < 3; c++)
                    spec[c] += lamp_spec[c] * lamp->radiance[c];
            }
            for (int c = 0; c < 3; c++) {
                irradiance[3 * k + (size_t)c] += (float)irr[c];
                if (out)
                    out[3 * k + (size_t)c] += (float)spec[c];
            }
        }
        if (gw)
            free(gw->terms);
        free(gw);
    }
    if (failed)
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for the lamps' light");
    return WENV_OK;
}
