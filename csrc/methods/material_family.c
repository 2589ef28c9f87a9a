/* A material whose Roughness and Metallic vary per vertex (material_family.h). */
#include "methods/material_family.h"

#include <math.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>

#include "base/fingerprint.h"
#include "math/unit_pair.h"

/* What a member is on the metallic axis: the material at a Metallic, or a metal in black or in white
 * (a metal whose colour varies per vertex: wenv_material_metal_colour). */
typedef enum { SIDE_AS_IS, SIDE_BLACK, SIDE_WHITE } side_kind;
#define SIDES 3
_Static_assert(SIDES == WENV_VERTEX_LIGHTS_PICKS, "a vertex's lights are read through each of its sides");
/* Per vertex: at most two roughness levels times the sides. */
#define ENTRIES (2 * SIDES)

struct wenv_material_family {
    wenv_material *base;
    size_t n;
    int colour; /* made for a colour per vertex */
    /* members: n_r roughness levels x n_m sides, member (ir, im) at ir n_m + im (NULL where no vertex
     * reads it) */
    size_t n_r, n_m, made;
    size_t spacing; /* interpolated roughness: levels k / spacing */
    double r_level[WENV_FAMILY_FINEST + 1], m_level[SIDES];
    side_kind side[SIDES];
    wenv_material **member;
    wenv_diffuse_table *diffuse;    /* per member: its Lambertian part over pi */
    wenv_diffuse_table *per_colour; /* ... per unit of colour, where the colour varies alone */
    wenv_error colour_why;          /* why a colour per vertex cannot be shaded (status 0: it can) */
    uint32_t *member_of;            /* ENTRIES per vertex */
    float *weight;                  /* ENTRIES per vertex, 0 for an entry not read */
    /* the lights' materials (roughness interpolated only): each vertex's own roughness, per side */
    int lights_apart;
    wenv_material **palette;
    size_t n_palette;
    uint32_t *pick;   /* SIDES per vertex */
    float *side_w;    /* SIDES per vertex: each side's weight */
    uint64_t key;
};

void wenv_material_family_free(wenv_material_family *f)
{
    if (!f)
        return;
    wenv_material_free(f->base);
    for (size_t j = 0; f->member && j < f->n_r * f->n_m; j++)
        wenv_material_free(f->member[j]);
    for (size_t p = 0; f->palette && p < f->n_palette; p++)
        wenv_material_free(f->palette[p]);
    free(f->member);
    free(f->diffuse);
    free(f->per_colour);
    free(f->member_of);
    free(f->weight);
    free(f->palette);
    free(f->pick);
    free(f->side_w);
    free(f);
}

static double clamp01(double x) { return x < 0.0 ? 0.0 : (x > 1.0 ? 1.0 : x); }

/* Finite values (the name and vertex of the first that is not), and whether they are all one value. */
static wenv_status check_values(const float *x, size_t n, const char *name, int *uniform, wenv_error *err)
{
    *uniform = 1;
    for (size_t i = 0; i < n; i++) {
        if (!isfinite(x[i]))
            return wenv_error_set(err, WENV_ERR_VALUE, "%s[%zu] is %g: a vertex's %s must be finite", name, i,
                                  (double)x[i], name);
        *uniform &= clamp01(x[i]) == clamp01(x[0]);
    }
    return WENV_OK;
}

static int compare_double(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

/* The distinct values of x (clamped) into level[], ascending, when there are at most
 * WENV_FAMILY_EXACT_LEVELS of them: their count, else 0 (-1 out of memory). */
static long distinct_levels(const float *x, size_t n, double *level)
{
    double *v = malloc((n ? n : 1) * sizeof *v);
    if (!v)
        return -1;
    for (size_t i = 0; i < n; i++)
        v[i] = clamp01(x[i]);
    qsort(v, n, sizeof *v, compare_double);
    long count = 0;
    for (size_t i = 0; i < n; i++)
        if (i == 0 || v[i] != v[i - 1]) {
            if (count == WENV_FAMILY_EXACT_LEVELS) {
                free(v);
                return 0;
            }
            level[count++] = v[i];
        }
    free(v);
    return count;
}

/* The level equal to x in level[0 .. count). */
static size_t level_of(const double *level, size_t count, double x)
{
    size_t lo = 0, hi = count - 1;
    while (lo < hi) {
        size_t mid = (lo + hi) / 2;
        if (level[mid] < x)
            lo = mid + 1;
        else
            hi = mid;
    }
    return lo;
}

/* The finest of the levels' spacings (WENV_FAMILY_FINEST, then coarser) at which the levels the
 * roughness spans, times the sides, make at most max_members members. */
static size_t level_spacing(const float *roughness, size_t n, size_t sides, size_t max_members)
{
    static const size_t SPACINGS[] = {WENV_FAMILY_FINEST, 16, 12, 8, 4, 2, 1};
    double lo = 1.0, hi = 0.0;
    for (size_t i = 0; i < n; i++) {
        lo = fmin(lo, clamp01(roughness[i]));
        hi = fmax(hi, clamp01(roughness[i]));
    }
    size_t k = 0;
    while (k + 1 < sizeof SPACINGS / sizeof SPACINGS[0] &&
           ((size_t)ceil(hi * (double)SPACINGS[k]) - (size_t)floor(lo * (double)SPACINGS[k]) + 1) * sides >
               max_members)
        k++;
    return SPACINGS[k];
}

static wenv_status principled_at(wenv_material **out, const wenv_principled_inputs *in, double roughness,
                                 double metallic, side_kind side, wenv_error *err)
{
    wenv_principled_inputs at = *in;
    at.roughness = roughness;
    at.metallic = metallic;
    if (side != SIDE_AS_IS)
        for (int c = 0; c < 3; c++)
            at.base_color[c] = side == SIDE_WHITE ? 1.0 : 0.0;
    return wenv_principled_create(out, &at, err);
}

/* The members the vertices read, with their tables. */
static wenv_status make_members(wenv_material_family *f, const wenv_principled_inputs *in, wenv_error *err)
{
    size_t nm = f->n_r * f->n_m;
    unsigned char *read = calloc(nm, 1);
    f->member = calloc(nm, sizeof *f->member);
    f->diffuse = calloc(nm, sizeof *f->diffuse);
    f->per_colour = calloc(nm, sizeof *f->per_colour);
    if (!read || !f->member || !f->diffuse || !f->per_colour) {
        free(read);
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for a material per vertex");
    }
    for (size_t e = 0; e < ENTRIES * f->n; e++)
        read[f->member_of[e]] |= f->weight[e] > 0.0f;
    for (size_t j = 0; j < nm; j++) {
        if (!read[j])
            continue;
        if (principled_at(&f->member[j], in, f->r_level[j / f->n_m], f->m_level[j % f->n_m], f->side[j % f->n_m],
                          err)) {
            free(read);
            return err->status;
        }
        f->made++;
        wenv_material_diffuse_table(f->member[j], &f->diffuse[j]);
        if (f->side[j % f->n_m] != SIDE_AS_IS) { /* a metal: no Lambertian part, its colour mixed in */
            double w[3];
            f->per_colour[j] = f->diffuse[j];
            if (!wenv_material_metal_colour(f->member[j], 1.0, (double[3]){0.5, 0.5, 0.5}, w, w) &&
                !f->colour_why.status)
                wenv_error_set(&f->colour_why, WENV_ERR_VALUE,
                               "the colour cannot vary per vertex: a Principled BSDF's Base Color is also its metal's "
                               "Fresnel colour, and a coat or sheen over a metal whose colour varies is not shaded");
            continue;
        }
        wenv_error why = {0};
        if (f->colour && wenv_material_diffuse_per_colour_table(f->member[j], &f->per_colour[j], &why) &&
            !f->colour_why.status)
            f->colour_why = why;
    }
    free(read);
    return WENV_OK;
}

/* Each vertex's light materials: its own roughness (to 1 / WENV_FAMILY_LIGHT_STEPS) on each side it
 * reads. */
static wenv_status make_palette(wenv_material_family *f, const wenv_principled_inputs *in, const float *roughness,
                                wenv_error *err)
{
    size_t slots = (WENV_FAMILY_LIGHT_STEPS + 1) * f->n_m;
    int32_t *index = malloc(slots * sizeof *index);
    f->pick = calloc(SIDES * f->n, sizeof *f->pick);
    f->side_w = calloc(SIDES * f->n, sizeof *f->side_w);
    f->palette = calloc(slots, sizeof *f->palette);
    uint32_t *slot_of = malloc(slots * sizeof *slot_of);
    if (!index || !f->pick || !f->side_w || !f->palette || !slot_of) {
        free(index);
        free(slot_of);
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for a material per vertex");
    }
    for (size_t s = 0; s < slots; s++)
        index[s] = -1;
    for (size_t i = 0; i < f->n; i++) {
        size_t q = (size_t)lround(clamp01(roughness[i]) * WENV_FAMILY_LIGHT_STEPS);
        /* the sides' weights are the entries' summed over the roughness levels */
        float *side = f->side_w + SIDES * i;
        for (size_t e = 0; e < ENTRIES; e++)
            side[f->member_of[ENTRIES * i + e] % f->n_m] += f->weight[ENTRIES * i + e];
        for (size_t m = 0; m < f->n_m; m++) {
            size_t s = q * f->n_m + m;
            if (side[m] > 0.0f && index[s] < 0) {
                index[s] = (int32_t)f->n_palette;
                slot_of[f->n_palette++] = (uint32_t)s;
            }
            /* a side not read picks the first made, with weight 0 */
            f->pick[SIDES * i + m] = (uint32_t)(index[s] >= 0 ? index[s] : 0);
        }
    }
    free(index);
    atomic_int failed = 0;
    long long np = (long long)f->n_palette;
    wenv_error first = {0};
#pragma omp parallel for schedule(dynamic, 16)
    for (long long p = 0; p < np; p++) {
        size_t s = slot_of[p];
        wenv_error one = {0};
        if (principled_at(&f->palette[p], in, (double)(s / f->n_m) / WENV_FAMILY_LIGHT_STEPS, f->m_level[s % f->n_m],
                          f->side[s % f->n_m], &one)) {
#pragma omp critical(wenv_family_palette)
            if (!atomic_load(&failed))
                first = one;
            atomic_store(&failed, 1);
        }
    }
    free(slot_of);
    if (failed) {
        *err = first;
        return err->status;
    }
    return WENV_OK;
}

static uint64_t family_key(const wenv_principled_inputs *in, const float *roughness, const float *metallic, size_t n,
                           int colour, size_t max_members)
{
    uint64_t key = wenv_fingerprint_word(wenv_fingerprint_word(WENV_FINGERPRINT_START, n), (uint64_t)colour);
    key = wenv_fingerprint_word(key, max_members);
    for (size_t r = 0; r < wenv_principled_input_count; r++) {
        const wenv_principled_input *row = &wenv_principled_input_list[r];
        key = wenv_fingerprint_doubles(key, wenv_principled_field_c(in, row), (size_t)row->n);
    }
    key = wenv_fingerprint_word(key, (uint64_t)in->multiscatter);
    if (roughness)
        key = wenv_fingerprint_floats(wenv_fingerprint_word(key, 1), roughness, n);
    if (metallic)
        key = wenv_fingerprint_floats(wenv_fingerprint_word(key, 2), metallic, n);
    return key;
}

int wenv_material_family_needed_for_colour(const wenv_material *base)
{
    const wenv_principled_inputs *in = wenv_principled_inputs_of(base);
    return in && in->metallic > 0.0;
}

wenv_status wenv_material_family_create(wenv_material_family **out, const wenv_material *base, const float *roughness,
                                        const float *metallic, size_t n, int colour, size_t max_members,
                                        wenv_error *err)
{
    *out = NULL;
    const wenv_principled_inputs *in = wenv_principled_inputs_of(base);
    if (!in)
        return wenv_error_set(err, WENV_ERR_VALUE,
                              "a Roughness or Metallic per vertex needs a Principled material (wenv.Principled), not "
                              "%s",
                              wenv_material_kind_name(base));
    int r_uniform = 1, m_uniform = 1; /* a roughness's distinct values are counted below */
    if ((roughness && check_values(roughness, n, "roughness", &r_uniform, err)) ||
        (metallic && check_values(metallic, n, "metallic", &m_uniform, err)))
        return err->status;
    wenv_material_family *f = calloc(1, sizeof *f);
    if (!f)
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for a material per vertex");
    f->n = n;
    f->colour = colour != 0;
    /* a roughness of a few values is those values, exactly; of more, the levels interpolated */
    long exact = roughness ? distinct_levels(roughness, n, f->r_level) : 0;
    if (exact < 0) {
        free(f);
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for a material per vertex");
    }
    int interpolated = roughness && !exact;
    /* the metallic axis: the material at its one Metallic, or mixed from 0 and 1 (exactly); with a
     * colour per vertex, the metal in black and in white */
    int varies = metallic && !m_uniform;
    double m0 = metallic && n ? clamp01(metallic[0]) : in->metallic;
    if (!(f->colour && (varies || m0 > 0.0))) {
        f->n_m = varies ? 2 : 1;
        f->m_level[0] = varies ? 0.0 : m0;
        f->m_level[1] = 1.0;
    } else {
        if (varies || m0 < 1.0)
            f->m_level[f->n_m++] = 0.0;
        f->side[f->n_m] = SIDE_BLACK;
        f->m_level[f->n_m++] = 1.0;
        f->side[f->n_m] = SIDE_WHITE;
        f->m_level[f->n_m++] = 1.0;
    }
    f->n_r = exact ? (size_t)exact : 1;
    if (interpolated) {
        f->spacing = level_spacing(roughness, n, f->n_m, max_members);
        f->n_r = f->spacing + 1;
    }
    for (size_t k = 0; !exact && k < f->n_r; k++)
        f->r_level[k] = interpolated ? (double)k / (double)f->spacing : in->roughness;
    f->lights_apart = interpolated;
    f->member_of = calloc(ENTRIES * (n ? n : 1), sizeof *f->member_of);
    f->weight = calloc(ENTRIES * (n ? n : 1), sizeof *f->weight);
    if (wenv_material_copy(&f->base, base, err) || !f->member_of || !f->weight) {
        wenv_material_family_free(f);
        return err->status ? err->status : wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for a material per vertex");
    }
    for (size_t i = 0; i < n; i++) {
        size_t ir[2] = {0, 0};
        float wr[2] = {1.0f, 0.0f};
        if (exact) {
            ir[0] = level_of(f->r_level, f->n_r, clamp01(roughness[i]));
        } else if (interpolated) {
            double x = clamp01(roughness[i]) * (double)f->spacing;
            size_t k = (size_t)x < f->spacing ? (size_t)x : f->spacing - 1;
            ir[0] = k;
            ir[1] = k + 1;
            wr[1] = (float)(x - (double)k);
            wr[0] = 1.0f - wr[1];
        }
        /* a side at Metallic 0 weighs 1 - m, one at 1 m (a metal in black and in white each: their
         * colour splits it per channel when shaded) */
        float mv = (float)(varies ? clamp01(metallic[i]) : m0);
        for (size_t a = 0; a < 2; a++)
            for (size_t b = 0; b < f->n_m; b++) {
                size_t e = ENTRIES * i + SIDES * a + b;
                float side_w = f->n_m == 1 ? 1.0f : (f->m_level[b] == 0.0 ? 1.0f - mv : mv);
                f->member_of[e] = (uint32_t)(ir[a] * f->n_m + b);
                f->weight[e] = wr[a] * side_w;
            }
    }
    if (make_members(f, in, err) || (f->lights_apart && make_palette(f, in, roughness, err))) {
        wenv_material_family_free(f);
        return err->status;
    }
    f->key = family_key(in, roughness, metallic, n, f->colour, max_members);
    *out = f;
    return WENV_OK;
}

wenv_status wenv_material_family_ensure(wenv_material_family **family, const wenv_material *base,
                                        const float *roughness, const float *metallic, size_t n, int colour,
                                        size_t max_members, wenv_error *err)
{
    const wenv_principled_inputs *in = wenv_principled_inputs_of(base);
    if (*family && in && (*family)->key == family_key(in, roughness, metallic, n, colour != 0, max_members))
        return WENV_OK;
    wenv_material_family *made;
    if (wenv_material_family_create(&made, base, roughness, metallic, n, colour, max_members, err))
        return err->status;
    wenv_material_family_free(*family);
    *family = made;
    return WENV_OK;
}

size_t wenv_material_family_vertices(const wenv_material_family *f) { return f->n; }
uint64_t wenv_material_family_key(const wenv_material_family *f) { return f->key; }
size_t wenv_material_family_members(const wenv_material_family *f) { return f->made; }
size_t wenv_material_family_light_materials(const wenv_material_family *f) { return f->n_palette; }
const wenv_material *wenv_material_family_base(const wenv_material_family *f) { return f->base; }

/* ---- shading ---- */

typedef struct {
    const wenv_method *method;
    void *state;
    const float *normals, *views;
    const wenv_shadow_scene *scene;
    const float *rgb; /* a colour per call vertex, or NULL */
} call;

/* What of a metal in black (or white) a vertex of colour rgb seen at cos_v takes, per channel. */
static void metal_share(const wenv_material *metal, side_kind side, float cos_v, const float *rgb, float share[3])
{
    double colour[3] = {rgb[0], rgb[1], rgb[2]}, black[3], white[3];
    wenv_material_metal_colour(metal, cos_v, colour, black, white); /* checked when the family was made */
    for (int c = 0; c < 3; c++)
        share[c] = (float)(side == SIDE_WHITE ? white[c] : black[c]);
}

/* A member's shading of the count call vertices at[] (normals and views gathered into work), added
 * to out with their weights w[] (for a metal in black or white, times its share of their colour) and
 * to irradiance with w[] (once per vertex and level: not for the metal in white, whose light the
 * metal in black counts). */
static wenv_status shade_member(const call *c, const wenv_material *member, side_kind side, const size_t *at,
                                const float *w, size_t count, float *work, uint32_t *rows, float *out,
                                float *irradiance, wenv_error *err)
{
    float *nrm = work, *vw = work + 3 * count, *o = work + 6 * count, *e = work + 9 * count;
    long long nc = (long long)count;
#pragma omp parallel for schedule(static) if (count > 4096)
    for (long long k = 0; k < nc; k++) {
        memcpy(nrm + 3 * k, c->normals + 3 * at[k], 3 * sizeof(float));
        if (c->views)
            memcpy(vw + 3 * k, c->views + 3 * at[k], 3 * sizeof(float));
    }
    wenv_shadow_scene sub;
    if (c->scene) {
        sub = *c->scene;
        for (size_t k = 0; k < count; k++)
            rows[k] = c->scene->rows ? c->scene->rows[at[k]] : (uint32_t)(c->scene->offset + at[k]);
        sub.rows = rows;
        sub.offset = 0;
    }
    if (c->method->set_material(c->state, member, NULL, err))
        return err->status;
    wenv_status st;
    if (!c->views)
        st = c->method->diffuse_light(c->state, nrm, count, c->scene ? &sub : NULL, o, e, err);
    else if (c->scene)
        st = c->method->shade_shadowed(c->state, nrm, vw, count, &sub, o, e, err);
    else
        st = c->method->shade(c->state, nrm, vw, count, o, e, err);
    if (st)
        return st;
    /* a member reads each vertex once, so no two iterations write one row */
#pragma omp parallel for schedule(static) if (count > 4096)
    for (long long k = 0; k < nc; k++) {
        float share[3] = {1.0f, 1.0f, 1.0f};
        if (side != SIDE_AS_IS)
            metal_share(member, side, wenv_view_cosine(nrm + 3 * k, c->views ? vw + 3 * k : NULL), c->rgb + 3 * at[k],
                        share);
        for (int ch = 0; ch < 3; ch++) {
            out[3 * at[k] + ch] += w[k] * share[ch] * o[3 * k + ch];
            if (side != SIDE_WHITE)
                irradiance[3 * at[k] + ch] += w[k] * e[3 * k + ch];
        }
    }
    return WENV_OK;
}

/* Each call vertex's light materials and their weights per channel (wenv_vertex_lights). */
static void lights_of(const wenv_material_family *f, const size_t *fv, const float *normals, const float *views,
                      size_t n, const float *rgb, uint32_t *pick, float *weight)
{
    long long nn = (long long)n;
#pragma omp parallel for schedule(static)
    for (long long k = 0; k < nn; k++) {
        float cos_v = wenv_view_cosine(normals + 3 * k, views + 3 * k);
        for (size_t m = 0; m < WENV_VERTEX_LIGHTS_PICKS; m++) {
            size_t at = WENV_VERTEX_LIGHTS_PICKS * (size_t)k + m;
            float *w = weight + 3 * at, share[3] = {1.0f, 1.0f, 1.0f};
            pick[at] = m < f->n_m ? f->pick[SIDES * fv[k] + m] : 0;
            float side_w = m < f->n_m ? f->side_w[SIDES * fv[k] + m] : 0.0f;
            if (side_w > 0.0f && f->side[m] != SIDE_AS_IS)
                metal_share(f->palette[pick[at]], f->side[m], cos_v, rgb + 3 * k, share);
            for (int c = 0; c < 3; c++)
                w[c] = side_w * share[c];
        }
    }
}

/* The vertices' Lambertian part, their members' mixed, times their colour (1 without) and light. */
static void apply_diffuse(const wenv_material_family *f, const size_t *fv, const float *normals, const float *views,
                          size_t n, const float *rgb, const float *irradiance, float *out)
{
    const wenv_diffuse_table *tables = rgb ? f->per_colour : f->diffuse;
    long long nn = (long long)n;
#pragma omp parallel for schedule(static)
    for (long long i = 0; i < nn; i++) {
        float cos_v = wenv_view_cosine(normals + 3 * i, views ? views + 3 * i : NULL);
        float t[3] = {0.0f, 0.0f, 0.0f};
        for (size_t e = 0; e < ENTRIES; e++) {
            float w = f->weight[ENTRIES * fv[i] + e], d[3];
            if (!(w > 0.0f))
                continue;
            wenv_diffuse_table_at(&tables[f->member_of[ENTRIES * fv[i] + e]], cos_v, d);
            for (int c = 0; c < 3; c++)
                t[c] += w * d[c];
        }
        for (int c = 0; c < 3; c++) {
            float colour = rgb ? rgb[3 * i + c] : 1.0f;
            float v = out[3 * i + c] + colour * t[c] * irradiance[3 * i + c];
            out[3 * i + c] = v > 0.0f ? v : 0.0f;
        }
    }
}

/* The call's vertices by member: member j's in at[start[j] .. start[j + 1]) with their weights. */
static int group_by_member(const wenv_material_family *f, const size_t *fv, size_t n, size_t *start, size_t *at,
                           float *w)
{
    size_t nm = f->n_r * f->n_m;
    size_t *fill = malloc(nm * sizeof *fill);
    if (!fill)
        return -1;
    memset(start, 0, (nm + 1) * sizeof *start);
    for (size_t k = 0; k < n; k++)
        for (size_t e = 0; e < ENTRIES; e++)
            if (f->weight[ENTRIES * fv[k] + e] > 0.0f)
                start[f->member_of[ENTRIES * fv[k] + e] + 1]++;
    for (size_t j = 0; j < nm; j++)
        start[j + 1] += start[j];
    memcpy(fill, start, nm * sizeof *fill);
    for (size_t k = 0; k < n; k++)
        for (size_t e = 0; e < ENTRIES; e++) {
            float x = f->weight[ENTRIES * fv[k] + e];
            if (x > 0.0f) {
                size_t c = fill[f->member_of[ENTRIES * fv[k] + e]]++;
                at[c] = k;
                w[c] = x;
            }
        }
    free(fill);
    return 0;
}

wenv_status wenv_material_family_shade(const wenv_family_rows *fr, const wenv_method *method, void *state,
                                       const float *normals, const float *views, size_t n,
                                       const wenv_shadow_scene *scene, const float *rgb, float *out, wenv_error *err)
{
    const wenv_material_family *f = fr->family;
    if (scene && scene->bounce_self)
        return wenv_error_set(err, WENV_ERR_VALUE,
                              "a mesh's own bounce with a material per vertex is its diffuse light with those "
                              "materials: give it as the bounce");
    if (!method->materials_kept)
        return wenv_error_set(err, WENV_ERR_VALUE,
                              "method '%s' does not shade a Roughness or Metallic per vertex (it would make its "
                              "tables again for each member at every view): use a wavelet method",
                              method->name);
    if (rgb && f->colour_why.status) {
        *err = f->colour_why;
        return err->status;
    }
    if (!rgb != !f->colour)
        return wenv_error_set(err, WENV_ERR_VALUE, "the material per vertex was made %s a colour per vertex",
                              f->colour ? "for" : "without");
    size_t nm = f->n_r * f->n_m, total = ENTRIES * (n ? n : 1);
    size_t *fv = malloc((n ? n : 1) * sizeof *fv), *start = malloc((nm + 1) * sizeof *start);
    size_t *at = malloc(total * sizeof *at);
    float *w = malloc(total * sizeof *w), *irradiance = calloc(3 * (n ? n : 1), sizeof(float));
    float *work = malloc(12 * (n ? n : 1) * sizeof(float));
    uint32_t *rows = scene ? malloc((n ? n : 1) * sizeof *rows) : NULL;
    uint32_t *pick = NULL;
    float *light_w = NULL;
    wenv_status st = WENV_OK;
    if (!fv || !start || !at || !w || !irradiance || !work || (scene && !rows)) {
        st = wenv_error_set(err, WENV_ERR_NOMEM, "out of memory shading %zu vertices", n);
        goto done;
    }
    for (size_t k = 0; k < n; k++) {
        fv[k] = fr->rows ? fr->rows[k] : fr->offset + k;
        if (fv[k] >= f->n) {
            st = wenv_error_set(err, WENV_ERR_VALUE, "the material per vertex was made for %zu vertices, not %zu",
                                f->n, fv[k] + 1);
            goto done;
        }
    }
    if (group_by_member(f, fv, n, start, at, w) < 0) {
        st = wenv_error_set(err, WENV_ERR_NOMEM, "out of memory shading %zu vertices", n);
        goto done;
    }
    memset(out, 0, 3 * n * sizeof(float));
    call c = {method, state, normals, views, scene, rgb};
    int apart = f->lights_apart && views && method->set_lights_apart && method->shade_lights;
    if (apart)
        method->set_lights_apart(state, 1);
    for (size_t j = 0; j < nm && !st; j++)
        if (start[j + 1] > start[j])
            st = shade_member(&c, f->member[j], f->side[j % f->n_m], at + start[j], w + start[j],
                              start[j + 1] - start[j], work, rows, out, irradiance, err);
    if (apart)
        method->set_lights_apart(state, 0);
    if (!st && apart) {
        pick = malloc(WENV_VERTEX_LIGHTS_PICKS * (n ? n : 1) * sizeof *pick);
        light_w = malloc(3 * WENV_VERTEX_LIGHTS_PICKS * (n ? n : 1) * sizeof *light_w);
        if (!pick || !light_w) {
            st = wenv_error_set(err, WENV_ERR_NOMEM, "out of memory shading %zu vertices", n);
        } else {
            lights_of(f, fv, normals, views, n, rgb, pick, light_w);
            wenv_vertex_lights vl = {(const wenv_material *const *)f->palette, f->n_palette, f->key, pick, light_w};
            st = method->shade_lights(state, normals, views, n, scene, &vl, out, irradiance, err);
        }
    }
    if (!st)
        apply_diffuse(f, fv, normals, views, n, rgb, irradiance, out);
    /* the shader's material again, whatever happened */
    wenv_error restore = {0};
    if (method->set_material(state, f->base, NULL, &restore) && !st)
        st = (*err = restore).status;
done:
    free(fv);
    free(start);
    free(at);
    free(w);
    free(irradiance);
    free(work);
    free(rows);
    free(pick);
    free(light_w);
    return st;
}

/* The call's vertices' rows of the family, checked. */
static wenv_status family_vertices(const wenv_family_rows *fr, size_t n, size_t **fv, wenv_error *err)
{
    if (!(*fv = malloc((n ? n : 1) * sizeof **fv)))
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory shading %zu vertices", n);
    for (size_t k = 0; k < n; k++) {
        (*fv)[k] = fr->rows ? fr->rows[k] : fr->offset + k;
        if ((*fv)[k] >= fr->family->n) {
            wenv_status st = wenv_error_set(err, WENV_ERR_VALUE, "the material per vertex was made for %zu vertices, "
                                            "not %zu", fr->family->n, (*fv)[k] + 1);
            free(*fv);
            *fv = NULL;
            return st;
        }
    }
    return WENV_OK;
}

wenv_status wenv_material_family_own(const wenv_family_rows *fr, const float *normals, const float *views, size_t n,
                                     const float *rgb, uint32_t *pick, float *weight, wenv_vertex_lights *out,
                                     wenv_error *err)
{
    const wenv_material_family *f = fr->family;
    size_t *fv;
    if (family_vertices(fr, n, &fv, err))
        return err->status;
    if (f->lights_apart) {
        if (views) {
            lights_of(f, fv, normals, views, n, rgb, pick, weight);
        } else { /* head-on */
            for (size_t k = 0; k < n; k++)
                for (size_t m = 0; m < WENV_VERTEX_LIGHTS_PICKS; m++) {
                    size_t at = WENV_VERTEX_LIGHTS_PICKS * k + m;
                    float side_w = m < f->n_m ? f->side_w[SIDES * fv[k] + m] : 0.0f, share[3] = {1.0f, 1.0f, 1.0f};
                    pick[at] = m < f->n_m ? f->pick[SIDES * fv[k] + m] : 0;
                    if (side_w > 0.0f && f->side[m] != SIDE_AS_IS)
                        metal_share(f->palette[pick[at]], f->side[m], 1.0f, rgb + 3 * k, share);
                    for (int c = 0; c < 3; c++)
                        weight[3 * at + (size_t)c] = side_w * share[c];
                }
        }
        *out = (wenv_vertex_lights){(const wenv_material *const *)f->palette, f->n_palette, f->key, pick, weight};
        free(fv);
        return WENV_OK;
    }
    /* exact levels: one level a vertex, so its entries with weight are its sides */
    for (size_t k = 0; k < n; k++) {
        float cos_v = wenv_view_cosine(normals + 3 * k, views ? views + 3 * k : NULL);
        size_t m = 0;
        for (size_t e = 0; e < ENTRIES && m < WENV_VERTEX_LIGHTS_PICKS; e++) {
            float w = f->weight[ENTRIES * fv[k] + e];
            if (!(w > 0.0f))
                continue;
            size_t at = WENV_VERTEX_LIGHTS_PICKS * k + m++, j = f->member_of[ENTRIES * fv[k] + e];
            float share[3] = {1.0f, 1.0f, 1.0f};
            if (f->side[j % f->n_m] != SIDE_AS_IS)
                metal_share(f->member[j], f->side[j % f->n_m], cos_v, rgb + 3 * k, share);
            pick[at] = (uint32_t)j;
            for (int c = 0; c < 3; c++)
                weight[3 * at + (size_t)c] = w * share[c];
        }
        for (; m < WENV_VERTEX_LIGHTS_PICKS; m++) {
            size_t at = WENV_VERTEX_LIGHTS_PICKS * k + m;
            pick[at] = 0;
            weight[3 * at] = weight[3 * at + 1] = weight[3 * at + 2] = 0.0f;
        }
    }
    *out = (wenv_vertex_lights){(const wenv_material *const *)f->member, f->n_r * f->n_m, f->key, pick, weight};
    free(fv);
    return WENV_OK;
}

wenv_status wenv_material_family_add_diffuse(const wenv_family_rows *fr, const float *normals, const float *views,
                                             size_t n, const float *rgb, const float *irradiance, float *out,
                                             wenv_error *err)
{
    size_t *fv;
    if (family_vertices(fr, n, &fv, err))
        return err->status;
    apply_diffuse(fr->family, fv, normals, views, n, rgb, irradiance, out);
    free(fv);
    return WENV_OK;
}
