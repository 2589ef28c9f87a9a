/* A material whose inputs vary per vertex (material_family.h). */
#include "methods/material_family.h"
#include "methods/vertex_colour.h"

#include <math.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "base/fingerprint.h"
#include "math/unit_pair.h"
#include "methods/emission.h"

/* What a member is on the metallic axis: the material at a Metallic, or a metal in black or in white
 * (a metal whose colour varies per vertex: wenv_material_metal_colour). */
typedef enum { SIDE_AS_IS, SIDE_BLACK, SIDE_WHITE } side_kind;
#define SIDES 3
_Static_assert(SIDES == WENV_VERTEX_LIGHTS_PICKS, "a vertex's lights are read through each of its sides");

/* A coordinate of the members' grid: one channel of a per-vertex input that changes the lobes
 * (every input of WENV_VERTEX_INPUTS but Metallic, the sides, and Alpha, a scale). */
#define COORDS (WENV_VERTEX_INPUT_CHANNELS - 2)
typedef struct {
    int input, channel;
} coord;

struct wenv_material_family {
    wenv_material *base;
    size_t n;
    int colour; /* made for a colour per vertex */
    /* members: point p (COORDS values) on side m at p n_m + m (NULL where no vertex reads it) */
    size_t n_points, n_m, made;
    double *point;
    double m_level[SIDES];
    side_kind side[SIDES];
    wenv_material **member;
    wenv_diffuse_table *diffuse;    /* per member: its Lambertian part over pi */
    wenv_diffuse_table *per_colour; /* ... per unit of colour, where the colour varies alone */
    wenv_emission_table *emission;  /* per member (only if the material emits): its own, and per unit of colour */
    wenv_error colour_why;          /* why a colour per vertex cannot be shaded (status 0: it can) */
    size_t entries;                 /* per vertex: the corners of its grid cell times the sides */
    uint32_t *member_of;            /* entries per vertex */
    float *weight;                  /* entries per vertex, 0 for an entry not read */
    float *alpha;                   /* per vertex, or NULL: scales all it reflects and emits */
    /* the lights' materials (grid interpolated only): each vertex's own values, per side */
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
    for (size_t j = 0; f->member && j < f->n_points * f->n_m; j++)
        wenv_material_free(f->member[j]);
    for (size_t p = 0; f->palette && p < f->n_palette; p++)
        wenv_material_free(f->palette[p]);
    free(f->point);
    free(f->member);
    free(f->diffuse);
    free(f->per_colour);
    free(f->emission);
    free(f->member_of);
    free(f->weight);
    free(f->alpha);
    free(f->palette);
    free(f->pick);
    free(f->side_w);
    free(f);
}

static double clamp01(double x) { return x < 0.0 ? 0.0 : (x > 1.0 ? 1.0 : x); }

/* What the family is made from: the material, the per-vertex values and the coordinates they vary. */
typedef struct {
    const wenv_principled_inputs *in;
    const wenv_vertex_inputs *vi;
    size_t n;
    coord coords[COORDS];
    double lo[COORDS], hi[COORDS]; /* the values' range */
    size_t axis[COORDS], n_axes;   /* the coordinates that vary */
} build;

/* Vertex i's value of coordinate c, clamped as Cycles clamps it (the material's own where not given). */
static double value_at(const build *b, size_t i, size_t c)
{
    const coord *k = &b->coords[c];
    const wenv_vertex_input *in = &wenv_vertex_input_list[k->input];
    const float *v = b->vi ? b->vi->value[k->input] : NULL;
    if (v)
        return wenv_vertex_input_clamp(in, v[(size_t)in->n * i + (size_t)k->channel]);
    return wenv_principled_field_c(b->in, in->row)[k->channel];
}

/* A vertex's Metallic and Alpha. */
static double scalar_at(const build *b, size_t i, int input)
{
    const wenv_vertex_input *in = &wenv_vertex_input_list[input];
    const float *v = b->vi ? b->vi->value[input] : NULL;
    return v ? wenv_vertex_input_clamp(in, v[i]) : wenv_principled_field_c(b->in, in->row)[0];
}

static void set_coords(build *b)
{
    size_t c = 0;
    for (int k = 0; k < WENV_VERTEX_INPUT_COUNT; k++) {
        if (k == WENV_VERTEX_metallic || k == WENV_VERTEX_alpha)
            continue;
        for (int ch = 0; ch < wenv_vertex_input_list[k].n; ch++)
            b->coords[c++] = (coord){k, ch};
    }
    b->n_axes = 0;
    for (c = 0; c < COORDS; c++) {
        b->lo[c] = b->hi[c] = value_at(b, 0, c);
        for (size_t i = 1; i < b->n; i++) {
            double x = value_at(b, i, c);
            b->lo[c] = fmin(b->lo[c], x);
            b->hi[c] = fmax(b->hi[c], x);
        }
        if (b->hi[c] > b->lo[c])
            b->axis[b->n_axes++] = c;
    }
}

static int is_roughness(const build *b, size_t c) { return b->coords[c].input == WENV_VERTEX_roughness; }

/* The distinct points (the varying coordinates' values) of the vertices, into point[] (COORDS each)
 * with each vertex's in which[], when there are at most WENV_FAMILY_EXACT_LEVELS: their count, else 0. */
static size_t distinct_points(const build *b, double *point, uint32_t *which)
{
    size_t count = 0;
    double here[COORDS];
    for (size_t i = 0; i < b->n; i++) {
        for (size_t c = 0; c < COORDS; c++)
            here[c] = value_at(b, i, c);
        size_t p = 0;
        while (p < count && memcmp(point + COORDS * p, here, sizeof here) != 0)
            p++;
        if (p == count) {
            if (count == WENV_FAMILY_EXACT_LEVELS)
                return 0;
            memcpy(point + COORDS * count++, here, sizeof here);
        }
        which[i] = (uint32_t)p;
    }
    return count;
}

/* The grid's levels: Roughness at k / step (0 to 1), every other axis at lo + k (hi - lo) / step. */
typedef struct {
    size_t levels[WENV_FAMILY_MAX_AXES], step[WENV_FAMILY_MAX_AXES]; /* per axis */
} grid;

/* Specular IOR Level's levels are even in its square root: the index it sets rises from 1 as the
 * root of the level, and the reflection with it, fast near 0. */
static int warped(const build *b, size_t c) { return b->coords[c].input == WENV_VERTEX_specular_ior_level; }
static double warp(const build *b, size_t c, double x) { return warped(b, c) ? sqrt(x) : x; }

static double level_value(const build *b, const grid *g, size_t a, size_t k)
{
    size_t c = b->axis[a];
    if (is_roughness(b, c))
        return (double)k / (double)g->step[a];
    double lo = warp(b, c, b->lo[c]), hi = warp(b, c, b->hi[c]);
    double x = lo + (hi - lo) * (double)k / (double)g->step[a];
    return warped(b, c) ? x * x : x;
}

/* Where vertex value x falls on axis a: the level below it and the share of the one above. */
static size_t cell_of(const build *b, const grid *g, size_t a, double x, float *t)
{
    size_t c = b->axis[a], top = g->levels[a] - 1;
    double lo = warp(b, c, b->lo[c]), hi = warp(b, c, b->hi[c]);
    double at = is_roughness(b, c) ? x * (double)g->step[a] : (warp(b, c, x) - lo) / (hi - lo) * (double)g->step[a];
    size_t k = at <= 0.0 ? 0 : ((size_t)at < top ? (size_t)at : top - 1);
    *t = (float)fmin(fmax(at - (double)k, 0.0), 1.0);
    return k;
}

/* How finely each input's axis may be cut, finest last: Roughness's spacings over [0, 1] and the
 * others' steps over their range.  The weights and tints enter linearly (exactly: their two ends
 * suffice), Specular IOR Level nearly so, the roughnesses change the lobes' shape.  A weight enters
 * linearly only while a Coat Tint is 1 and Sheen Weight at most 1 (Cycles' layering clamps above). */
static const size_t SHAPE_OPTIONS[] = {1, 2, 4, 8, 12, 16, WENV_FAMILY_FINEST};
static const size_t LEVEL_OPTIONS[] = {1, 2, 4};
static const size_t WEIGHT_OPTIONS[] = {1, 2, 4};
static const size_t LINEAR_OPTIONS[] = {1};

/* Each axis is first cut no finer than this (Roughness to 1/16, Specular IOR Level to 2 steps), so
 * that two axes share the members fairly; then as fine as the rest leaves room for. */
#define FIRST_ROUGHNESS 16
#define FIRST_OTHER 2

static size_t axis_options(const build *b, size_t c, const size_t **options)
{
    int input = b->coords[c].input;
#define OPTIONS(list) (*options = list, sizeof list / sizeof list[0])
    if (input == WENV_VERTEX_roughness || input == WENV_VERTEX_coat_roughness || input == WENV_VERTEX_sheen_roughness)
        return OPTIONS(SHAPE_OPTIONS);
    if (input == WENV_VERTEX_specular_ior_level)
        return OPTIONS(LEVEL_OPTIONS);
    if ((input == WENV_VERTEX_coat_weight && (b->in->coat_tint[0] != 1.0 || b->in->coat_tint[1] != 1.0 ||
                                              b->in->coat_tint[2] != 1.0)) ||
        (input == WENV_VERTEX_sheen_weight && b->hi[c] > 1.0))
        return OPTIONS(WEIGHT_OPTIONS);
    return OPTIONS(LINEAR_OPTIONS);
#undef OPTIONS
}

/* The levels axis a spans at option value x (Roughness: those its values span). */
static size_t spanned(const build *b, size_t a, size_t x)
{
    size_t c = b->axis[a];
    if (!is_roughness(b, c))
        return x + 1;
    return (size_t)ceil(b->hi[c] * (double)x) - (size_t)floor(b->lo[c] * (double)x) + 1;
}

/* The grid whose members fit max_members: every axis at its coarsest, then each in turn (the
 * roughnesses first) cut finer while the members, counted over the levels the values span, fit.
 * 0 when even the coarsest does not fit. */
static int choose_grid(const build *b, size_t sides, size_t max_members, grid *g)
{
    size_t at[WENV_FAMILY_MAX_AXES] = {0}, count[WENV_FAMILY_MAX_AXES];
    const size_t *options[WENV_FAMILY_MAX_AXES];
    for (size_t a = 0; a < b->n_axes; a++)
        count[a] = axis_options(b, b->axis[a], &options[a]);
    for (int pass = 0; pass < 2; pass++)
        for (int changed = 1; changed;) {
            changed = 0;
            for (size_t a = 0; a < b->n_axes; a++)
                for (size_t next = at[a] + 1; next < count[a]; next++) {
                    size_t first = is_roughness(b, b->axis[a]) ? FIRST_ROUGHNESS : FIRST_OTHER;
                    if (pass == 0 && options[a][next] > first)
                        break;
                    size_t members = sides;
                    for (size_t x = 0; x < b->n_axes; x++)
                        members *= spanned(b, x, options[x][x == a ? next : at[x]]);
                    if (members <= max_members) {
                        at[a] = next;
                        changed = 1;
                        break;
                    }
                }
        }
    size_t members = sides;
    for (size_t a = 0; a < b->n_axes; a++) {
        size_t x = options[a][at[a]];
        members *= spanned(b, a, x);
        g->step[a] = x;
        g->levels[a] = x + 1;
    }
    return members <= max_members;
}

static wenv_status principled_at(wenv_material **out, const build *b, const double *point, double metallic,
                                 side_kind side, wenv_error *err)
{
    wenv_principled_inputs at = *b->in;
    for (size_t c = 0; c < COORDS; c++)
        wenv_principled_field(&at, wenv_vertex_input_list[b->coords[c].input].row)[b->coords[c].channel] = point[c];
    at.metallic = metallic;
    at.alpha = 1.0; /* a vertex's Alpha scales what it reflects and emits (f->alpha) */
    if (side != SIDE_AS_IS)
        for (int c = 0; c < 3; c++)
            at.base_color[c] = side == SIDE_WHITE ? 1.0 : 0.0;
    return wenv_principled_create(out, &at, err);
}

/* The members the vertices read, with their tables. */
static wenv_status make_members(wenv_material_family *f, const build *b, wenv_error *err)
{
    size_t nm = f->n_points * f->n_m;
    int emits = b->in->emission_strength != 0.0;
    unsigned char *read = calloc(nm, 1);
    f->member = calloc(nm, sizeof *f->member);
    f->diffuse = calloc(nm, sizeof *f->diffuse);
    f->per_colour = calloc(nm, sizeof *f->per_colour);
    f->emission = emits ? calloc(2 * nm, sizeof *f->emission) : NULL;
    if (!read || !f->member || !f->diffuse || !f->per_colour || (emits && !f->emission)) {
        free(read);
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for a material per vertex");
    }
    for (size_t e = 0; e < f->entries * f->n; e++)
        read[f->member_of[e]] |= f->weight[e] > 0.0f;
    for (size_t j = 0; j < nm; j++) {
        if (!read[j])
            continue;
        if (principled_at(&f->member[j], b, f->point + COORDS * (j / f->n_m), f->m_level[j % f->n_m],
                          f->side[j % f->n_m], err))
            break;
        f->made++;
        wenv_material_diffuse_table(f->member[j], &f->diffuse[j]);
        if (emits && (wenv_emission_table_make(f->member[j], 0, &f->emission[2 * j], err) ||
                      wenv_emission_table_make(f->member[j], 1, &f->emission[2 * j + 1], err)))
            break;
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
    return err->status;
}

/* A vertex's own values quantized for the lights' palette: Roughness to 1 / (WENV_FAMILY_LIGHT_STEPS >>
 * coarse), the other axes to 1 / (1024 >> coarse) of their range. */
#define PALETTE_FINEST_OTHER 1024
typedef struct {
    uint32_t q[WENV_FAMILY_MAX_AXES];
    uint32_t i;
} quantized;

static int compare_quantized(const void *x, const void *y)
{
    const quantized *a = x, *b = y;
    int d = memcmp(a->q, b->q, sizeof a->q);
    return d ? d : (a->i > b->i) - (a->i < b->i);
}

static size_t quantize(const build *b, int coarse, quantized *qv, uint32_t *steps)
{
    for (size_t a = 0; a < b->n_axes; a++)
        steps[a] = (is_roughness(b, b->axis[a]) ? WENV_FAMILY_LIGHT_STEPS : PALETTE_FINEST_OTHER) >> coarse;
    for (size_t i = 0; i < b->n; i++) {
        memset(qv[i].q, 0, sizeof qv[i].q);
        for (size_t a = 0; a < b->n_axes; a++) {
            size_t c = b->axis[a];
            double x = value_at(b, i, c), t = is_roughness(b, c) ? x : (x - b->lo[c]) / (b->hi[c] - b->lo[c]);
            qv[i].q[a] = (uint32_t)lround(clamp01(t) * (double)(steps[a] ? steps[a] : 1));
        }
        qv[i].i = (uint32_t)i;
    }
    qsort(qv, b->n, sizeof *qv, compare_quantized);
    size_t distinct = 0;
    for (size_t k = 0; k < b->n; k++)
        distinct += k == 0 || memcmp(qv[k].q, qv[k - 1].q, sizeof qv[k].q) != 0;
    return distinct;
}

/* Each vertex's light materials: its own values (quantized: at most WENV_FAMILY_LIGHT_STEPS + 1
 * points) on each side it reads. */
static wenv_status make_palette(wenv_material_family *f, const build *b, wenv_error *err)
{
    quantized *qv = malloc((b->n ? b->n : 1) * sizeof *qv);
    uint32_t steps[WENV_FAMILY_MAX_AXES];
    if (!qv)
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for a material per vertex");
    size_t distinct;
    for (int coarse = 0;; coarse++)
        if ((distinct = quantize(b, coarse, qv, steps)) <= WENV_FAMILY_LIGHT_STEPS + 1 || coarse == 13)
            break;
    size_t slots = distinct * f->n_m;
    int32_t *index = malloc((slots ? slots : 1) * sizeof *index);
    double *points = malloc((distinct ? distinct : 1) * COORDS * sizeof *points);
    uint32_t *slot_of = malloc((slots ? slots : 1) * sizeof *slot_of);
    f->pick = calloc(SIDES * (b->n ? b->n : 1), sizeof *f->pick);
    f->side_w = calloc(SIDES * (b->n ? b->n : 1), sizeof *f->side_w);
    f->palette = calloc(slots ? slots : 1, sizeof *f->palette);
    if (!index || !points || !slot_of || !f->pick || !f->side_w || !f->palette) {
        free(qv);
        free(index);
        free(points);
        free(slot_of);
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for a material per vertex");
    }
    for (size_t s = 0; s < slots; s++)
        index[s] = -1;
    size_t p = 0;
    for (size_t k = 0; k < b->n; k++) {
        int first = k == 0 || memcmp(qv[k].q, qv[k - 1].q, sizeof qv[k].q) != 0;
        p += first && k > 0;
        size_t i = qv[k].i;
        if (first) {
            double *pt = points + COORDS * p;
            for (size_t c = 0; c < COORDS; c++)
                pt[c] = value_at(b, 0, c); /* the coordinates that do not vary */
            for (size_t a = 0; a < b->n_axes; a++) {
                size_t c = b->axis[a];
                double t = (double)qv[k].q[a] / (double)(steps[a] ? steps[a] : 1);
                pt[c] = is_roughness(b, c) ? t : b->lo[c] + (b->hi[c] - b->lo[c]) * t;
            }
        }
        /* the sides' weights are the entries' summed over the grid's corners */
        float *side = f->side_w + SIDES * i;
        for (size_t e = 0; e < f->entries; e++)
            side[f->member_of[f->entries * i + e] % f->n_m] += f->weight[f->entries * i + e];
        for (size_t m = 0; m < f->n_m; m++) {
            size_t s = p * f->n_m + m;
            if (side[m] > 0.0f && index[s] < 0) {
                index[s] = (int32_t)f->n_palette;
                slot_of[f->n_palette++] = (uint32_t)s;
            }
            /* a side not read picks the first made, with weight 0 */
            f->pick[SIDES * i + m] = (uint32_t)(index[s] >= 0 ? index[s] : 0);
        }
    }
    free(qv);
    free(index);
    atomic_int failed = 0;
    long long np = (long long)f->n_palette;
    wenv_error first = {0};
#pragma omp parallel for schedule(dynamic, 16)
    for (long long q = 0; q < np; q++) {
        size_t s = slot_of[q];
        wenv_error one = {0};
        if (principled_at(&f->palette[q], b, points + COORDS * (s / f->n_m), f->m_level[s % f->n_m],
                          f->side[s % f->n_m], &one)) {
#pragma omp critical(wenv_family_palette)
            if (!atomic_load(&failed))
                first = one;
            atomic_store(&failed, 1);
        }
    }
    free(slot_of);
    free(points);
    if (failed) {
        *err = first;
        return err->status;
    }
    return WENV_OK;
}

static uint64_t family_key(const wenv_principled_inputs *in, const wenv_vertex_inputs *vi, size_t n, int colour,
                           size_t max_members)
{
    uint64_t key = wenv_fingerprint_word(wenv_fingerprint_word(WENV_FINGERPRINT_START, n), (uint64_t)colour);
    key = wenv_fingerprint_word(key, max_members);
    for (size_t r = 0; r < wenv_principled_input_count; r++) {
        const wenv_principled_input *row = &wenv_principled_input_list[r];
        key = wenv_fingerprint_doubles(key, wenv_principled_field_c(in, row), (size_t)row->n);
    }
    key = wenv_fingerprint_word(key, (uint64_t)in->multiscatter);
    key = wenv_fingerprint_word(key, (uint64_t)in->oren_nayar_classic);
    for (int k = 0; vi && k < WENV_VERTEX_INPUT_COUNT; k++)
        if (vi->value[k])
            key = wenv_fingerprint_floats(wenv_fingerprint_word(key, (uint64_t)k + 1), vi->value[k],
                                          (size_t)wenv_vertex_input_list[k].n * n);
    return key;
}

int wenv_material_family_needed_for_colour(const wenv_material *base)
{
    const wenv_principled_inputs *in = wenv_principled_inputs_of(base);
    return in && in->metallic > 0.0;
}

/* The sides: the material at its one Metallic, or mixed from 0 and 1 (exactly); with a colour per
 * vertex, the metal in black and in white. */
static void set_sides(wenv_material_family *f, const build *b)
{
    int varies = 0;
    double m0 = scalar_at(b, 0, WENV_VERTEX_metallic);
    for (size_t i = 1; i < b->n && !varies; i++)
        varies = scalar_at(b, i, WENV_VERTEX_metallic) != m0;
    if (!(f->colour && (varies || m0 > 0.0))) {
        f->n_m = varies ? 2 : 1;
        f->m_level[0] = varies ? 0.0 : m0;
        f->m_level[1] = 1.0;
        return;
    }
    if (varies || m0 < 1.0)
        f->m_level[f->n_m++] = 0.0;
    f->side[f->n_m] = SIDE_BLACK;
    f->m_level[f->n_m++] = 1.0;
    f->side[f->n_m] = SIDE_WHITE;
    f->m_level[f->n_m++] = 1.0;
}

/* Vertex i's entries for its corners (point index and weight each) times the sides: a side at
 * Metallic 0 weighs 1 - m, one at 1 m (a metal in black and in white each: their colour splits it
 * per channel when shaded). */
static void set_entries(wenv_material_family *f, const build *b, size_t i, const size_t *corner_point,
                        const float *corner_w, size_t corners)
{
    float mv = (float)scalar_at(b, i, WENV_VERTEX_metallic);
    for (size_t k = 0; k < corners; k++)
        for (size_t m = 0; m < f->n_m; m++) {
            size_t e = f->entries * i + SIDES * k + m;
            float side_w = f->n_m == 1 ? 1.0f : (f->m_level[m] == 0.0 ? 1.0f - mv : mv);
            f->member_of[e] = (uint32_t)(corner_point[k] * f->n_m + m);
            f->weight[e] = corner_w[k] * side_w;
        }
}

wenv_status wenv_material_family_create(wenv_material_family **out, const wenv_material *base,
                                        const wenv_vertex_inputs *vi, size_t n, int colour, size_t max_members,
                                        wenv_error *err)
{
    *out = NULL;
    const wenv_principled_inputs *in = wenv_principled_inputs_of(base);
    if (!in)
        return wenv_error_set(err, WENV_ERR_VALUE,
                              "inputs per vertex (Roughness, Metallic...) need a Principled material (wenv.Principled), "
                              "not %s",
                              wenv_material_kind_name(base));
    if (wenv_vertex_inputs_check(vi, n, err))
        return err->status;
    build b = {in, vi, n, {{0}}, {0}, {0}, {0}, 0};
    wenv_material_family *f = calloc(1, sizeof *f);
    if (!f)
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for a material per vertex");
    f->n = n;
    f->colour = colour != 0;
    if (wenv_material_copy(&f->base, base, err)) {
        wenv_material_family_free(f);
        return err->status;
    }
    if (n > 0)
        set_coords(&b);
    set_sides(f, &b);
    /* values of a few distinct points are those points, exactly; of more, a grid interpolated */
    uint32_t *which = malloc((n ? n : 1) * sizeof *which);
    f->point = malloc((WENV_FAMILY_EXACT_LEVELS > 1 ? WENV_FAMILY_EXACT_LEVELS : 1) * COORDS * sizeof *f->point);
    if (!which || !f->point) {
        free(which);
        wenv_material_family_free(f);
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for a material per vertex");
    }
    size_t exact = n ? distinct_points(&b, f->point, which) : 1;
    if (n == 0)
        for (size_t c = 0; c < COORDS; c++)
            f->point[c] = 0.0;
    grid g = {{0}, {0}};
    if (!exact) {
        free(which);
        which = NULL;
        if (b.n_axes > WENV_FAMILY_MAX_AXES || !choose_grid(&b, f->n_m, max_members, &g)) {
            char names[256] = "";
            for (size_t a = 0; a < b.n_axes; a++) {
                const coord *k = &b.coords[b.axis[a]];
                size_t len = strlen(names);
                if (a == 0 || strcmp(wenv_vertex_input_list[k->input].name,
                                     wenv_vertex_input_list[b.coords[b.axis[a - 1]].input].name) != 0)
                    snprintf(names + len, sizeof names - len, "%s%s", len ? ", " : "", wenv_vertex_input_list[k->input].name);
            }
            wenv_material_family_free(f);
            return wenv_error_set(err, WENV_ERR_VALUE,
                                  "too many inputs vary smoothly per vertex (%s: %zu values a vertex, at most %d, in "
                                  "at most %zu materials): give fewer, or values of at most %d distinct materials",
                                  names, b.n_axes, WENV_FAMILY_MAX_AXES, max_members, WENV_FAMILY_EXACT_LEVELS);
        }
    }
    size_t corners = exact ? 1 : (size_t)1 << b.n_axes;
    f->entries = corners * SIDES;
    if (exact) {
        f->n_points = exact;
    } else {
        f->n_points = 1;
        for (size_t a = 0; a < b.n_axes; a++)
            f->n_points *= g.levels[a];
        free(f->point);
        f->point = malloc(f->n_points * COORDS * sizeof *f->point);
    }
    f->member_of = calloc(f->entries * (n ? n : 1), sizeof *f->member_of);
    f->weight = calloc(f->entries * (n ? n : 1), sizeof *f->weight);
    int scaled = (vi && vi->value[WENV_VERTEX_alpha]) || in->alpha != 1.0;
    f->alpha = scaled ? malloc((n ? n : 1) * sizeof *f->alpha) : NULL;
    if (!f->point || !f->member_of || !f->weight || (scaled && !f->alpha)) {
        free(which);
        wenv_material_family_free(f);
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for a material per vertex");
    }
    if (!exact) /* the grid's points: mixed radix over the axes, the first fastest */
        for (size_t p = 0; p < f->n_points; p++) {
            double *pt = f->point + COORDS * p;
            for (size_t c = 0; c < COORDS; c++)
                pt[c] = value_at(&b, 0, c);
            for (size_t a = 0, rest = p; a < b.n_axes; rest /= g.levels[a], a++)
                pt[b.axis[a]] = level_value(&b, &g, a, rest % g.levels[a]);
        }
    for (size_t i = 0; i < n; i++) {
        size_t corner_point[1u << WENV_FAMILY_MAX_AXES] = {0};
        float corner_w[1u << WENV_FAMILY_MAX_AXES] = {1.0f};
        if (!exact) {
            size_t k[WENV_FAMILY_MAX_AXES], stride[WENV_FAMILY_MAX_AXES];
            float t[WENV_FAMILY_MAX_AXES];
            for (size_t a = 0, st = 1; a < b.n_axes; st *= g.levels[a], a++) {
                k[a] = cell_of(&b, &g, a, value_at(&b, i, b.axis[a]), &t[a]);
                stride[a] = st;
            }
            for (size_t m = 0; m < corners; m++) {
                size_t p = 0;
                float w = 1.0f;
                for (size_t a = 0; a < b.n_axes; a++) {
                    size_t up = (m >> a) & 1u;
                    p += (k[a] + up) * stride[a];
                    w *= up ? t[a] : 1.0f - t[a];
                }
                corner_point[m] = p;
                corner_w[m] = w;
            }
        } else {
            corner_point[0] = which[i];
        }
        set_entries(f, &b, i, corner_point, corner_w, corners);
        if (f->alpha)
            f->alpha[i] = (float)scalar_at(&b, i, WENV_VERTEX_alpha);
    }
    free(which);
    f->lights_apart = !exact;
    if (make_members(f, &b, err) || (f->lights_apart && make_palette(f, &b, err))) {
        wenv_material_family_free(f);
        return err->status;
    }
    f->key = family_key(in, vi, n, f->colour, max_members);
    *out = f;
    return WENV_OK;
}

wenv_status wenv_material_family_ensure(wenv_material_family **family, const wenv_material *base,
                                        const wenv_vertex_inputs *vi, size_t n, int colour, size_t max_members,
                                        wenv_error *err)
{
    const wenv_principled_inputs *in = wenv_principled_inputs_of(base);
    if (*family && in && (*family)->key == family_key(in, vi, n, colour != 0, max_members))
        return WENV_OK;
    wenv_material_family *made;
    if (wenv_material_family_create(&made, base, vi, n, colour, max_members, err))
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
                          size_t n, const float *rgb, const float *share, const float *horizon_light,
                          const float *irradiance, int with_alpha, float *out)
{
    const wenv_diffuse_table *tables = rgb ? f->per_colour : f->diffuse;
    long long nn = (long long)n;
#pragma omp parallel for schedule(static)
    for (long long i = 0; i < nn; i++) {
        float cos_v = wenv_view_cosine(normals + 3 * i, views ? views + 3 * i : NULL);
        float t[3] = {0.0f, 0.0f, 0.0f};
        for (size_t e = 0; e < f->entries; e++) {
            float w = f->weight[f->entries * fv[i] + e], d[3];
            if (!(w > 0.0f))
                continue;
            wenv_diffuse_table_at(&tables[f->member_of[f->entries * fv[i] + e]], cos_v, d);
            for (int c = 0; c < 3; c++)
                t[c] += w * d[c];
        }
        float alpha = with_alpha && f->alpha ? f->alpha[fv[i]] : 1.0f;
        for (int c = 0; c < 3; c++) {
            float colour = rgb ? rgb[3 * i + c] : 1.0f;
            float light = wenv_bent_light(irradiance[3 * i + c], share, horizon_light, (size_t)i, c);
            float v = out[3 * i + c] + alpha * colour * t[c] * light;
            out[3 * i + c] = v > 0.0f ? v : 0.0f;
        }
    }
}

/* The call's vertices by member: member j's in at[start[j] .. start[j + 1]) with their weights. */
static int group_by_member(const wenv_material_family *f, const size_t *fv, size_t n, size_t *start, size_t *at,
                           float *w)
{
    size_t nm = f->n_points * f->n_m;
    size_t *fill = malloc(nm * sizeof *fill);
    if (!fill)
        return -1;
    memset(start, 0, (nm + 1) * sizeof *start);
    for (size_t k = 0; k < n; k++)
        for (size_t e = 0; e < f->entries; e++)
            if (f->weight[f->entries * fv[k] + e] > 0.0f)
                start[f->member_of[f->entries * fv[k] + e] + 1]++;
    for (size_t j = 0; j < nm; j++)
        start[j + 1] += start[j];
    memcpy(fill, start, nm * sizeof *fill);
    for (size_t k = 0; k < n; k++)
        for (size_t e = 0; e < f->entries; e++) {
            float x = f->weight[f->entries * fv[k] + e];
            if (x > 0.0f) {
                size_t c = fill[f->member_of[f->entries * fv[k] + e]]++;
                at[c] = k;
                w[c] = x;
            }
        }
    free(fill);
    return 0;
}

wenv_status wenv_material_family_shade(const wenv_family_rows *fr, const wenv_method *method, void *state,
                                       const float *normals, const float *views, size_t n,
                                       const wenv_shadow_scene *scene, const float *rgb, const float *share,
                                       const float *horizon_light, float *out, wenv_error *err)
{
    const wenv_material_family *f = fr->family;
    if (scene && scene->bounce_self)
        return wenv_error_set(err, WENV_ERR_VALUE,
                              "a mesh's own bounce with a material per vertex is its diffuse light with those "
                              "materials: give it as the bounce");
    if (!method->materials_kept)
        return wenv_error_set(err, WENV_ERR_VALUE,
                              "method '%s' does not shade inputs per vertex (Roughness, Metallic...: it would make "
                              "its tables again for each member at every view): use a wavelet method",
                              method->name);
    if (rgb && f->colour_why.status) {
        *err = f->colour_why;
        return err->status;
    }
    if (!rgb != !f->colour)
        return wenv_error_set(err, WENV_ERR_VALUE, "the material per vertex was made %s a colour per vertex",
                              f->colour ? "for" : "without");
    size_t nm = f->n_points * f->n_m, total = f->entries * (n ? n : 1);
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
        apply_diffuse(f, fv, normals, views, n, rgb, share, horizon_light, irradiance, 0, out);
    for (size_t k = 0; !st && f->alpha && k < n; k++)
        for (int c = 0; c < 3; c++)
            out[3 * k + (size_t)c] *= f->alpha[fv[k]];
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

/* The lights' weights (wenv_vertex_lights) times each vertex's Alpha. */
static void scale_by_alpha(const wenv_material_family *f, const size_t *fv, size_t n, float *weight)
{
    for (size_t k = 0; f->alpha && k < n; k++)
        for (size_t j = 0; j < 3 * WENV_VERTEX_LIGHTS_PICKS; j++)
            weight[3 * WENV_VERTEX_LIGHTS_PICKS * k + j] *= f->alpha[fv[k]];
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
        scale_by_alpha(f, fv, n, weight);
        *out = (wenv_vertex_lights){(const wenv_material *const *)f->palette, f->n_palette, f->key, pick, weight};
        free(fv);
        return WENV_OK;
    }
    /* exact levels: one level a vertex, so its entries with weight are its sides */
    for (size_t k = 0; k < n; k++) {
        float cos_v = wenv_view_cosine(normals + 3 * k, views ? views + 3 * k : NULL);
        size_t m = 0;
        for (size_t e = 0; e < f->entries && m < WENV_VERTEX_LIGHTS_PICKS; e++) {
            float w = f->weight[f->entries * fv[k] + e];
            if (!(w > 0.0f))
                continue;
            size_t at = WENV_VERTEX_LIGHTS_PICKS * k + m++, j = f->member_of[f->entries * fv[k] + e];
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
    scale_by_alpha(f, fv, n, weight);
    *out = (wenv_vertex_lights){(const wenv_material *const *)f->member, f->n_points * f->n_m, f->key, pick, weight};
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
    apply_diffuse(fr->family, fv, normals, views, n, rgb, NULL, NULL, irradiance, 1, out);
    free(fv);
    return WENV_OK;
}

wenv_status wenv_material_family_add_emission(const wenv_family_rows *fr, const float *normals, const float *views,
                                              size_t n, const float *colours, float *out, wenv_error *err)
{
    const wenv_material_family *f = fr->family;
    if (!f->emission)
        return WENV_OK;
    size_t *fv;
    if (family_vertices(fr, n, &fv, err))
        return err->status;
    long long nn = (long long)n;
#pragma omp parallel for schedule(static)
    for (long long i = 0; i < nn; i++) {
        float cos_v = wenv_view_cosine(normals + 3 * i, views ? views + 3 * i : NULL);
        if (!(cos_v > 0.0f))
            continue; /* seen from behind: black, as the reflection */
        float t[3] = {0.0f, 0.0f, 0.0f};
        for (size_t e = 0; e < f->entries; e++) {
            float w = f->weight[f->entries * fv[i] + e], rgb[3];
            size_t j = f->member_of[f->entries * fv[i] + e];
            /* the metal in white shares the light of the metal in black (their weights are both m) */
            if (!(w > 0.0f) || f->side[j % f->n_m] == SIDE_WHITE || !f->emission[2 * j].emits)
                continue;
            wenv_emission_table_at(&f->emission[2 * j + (colours != NULL)], cos_v, rgb);
            for (int c = 0; c < 3; c++)
                t[c] += w * rgb[c];
        }
        float alpha = f->alpha ? f->alpha[fv[i]] : 1.0f;
        for (int c = 0; c < 3; c++) {
            float v = out[3 * i + c] + alpha * t[c] * (colours ? colours[3 * i + c] : 1.0f);
            out[3 * i + c] = v > 0.0f ? v : 0.0f;
        }
    }
    free(fv);
    return WENV_OK;
}
