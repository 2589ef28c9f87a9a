/* Blender's Voronoi Texture node (voronoi_texture.h).  One body serves the four dimensions: a point
 * is float[4] of which the first `d` count, and a cell's neighbours are visited x fastest, then y, z
 * and w, in Cycles' order (which a tie and Smooth F1's running blend depend on).  Cells of 2 to 4
 * dimensions are hashed by their integer coordinates with Cycles' signed PCG hashes (from "Hash
 * Functions for GPU Rendering", JCGT 2020, kept to signed integers for OSL); a 1D cell by lookup3 of
 * its float. */
#include "scene/voronoi_texture.h"

#include <float.h>
#include <math.h>
#include <stdint.h>
#include <string.h>

#include "math/lookup3.h"

/* Points per progress report and cancel check. */
#define BLOCK 4096

typedef struct {
    float distance;
    float colour[3];
    float position[4]; /* Cycles' float4: (x, y, z, W), 0 where the dimension has none */
} octave_out;

static inline float lerp(float a, float b, float t) { return a + t * (b - a); }

static float smoothstep01(float x)
{
    if (x < 0.0f)
        return 0.0f;
    if (x >= 1.0f)
        return 1.0f;
    return (3.0f - 2.0f * x) * (x * x);
}

/* The distance between a and b by the node's metric (1D: always |b - a|). */
static float metric_distance(const float *a, const float *b, int d, const wenv_voronoi_settings *s)
{
    if (d == 1)
        return fabsf(b[0] - a[0]);
    float sum = 0.0f, most = 0.0f;
    for (int k = 0; k < d; k++) {
        float e = fabsf(a[k] - b[k]);
        switch (s->metric) {
        case WENV_VORONOI_EUCLIDEAN:
            sum += e * e;
            break;
        case WENV_VORONOI_MANHATTAN:
            sum += e;
            break;
        case WENV_VORONOI_CHEBYCHEV:
            most = fmaxf(most, e);
            break;
        default:
            sum += powf(e, s->exponent);
        }
    }
    switch (s->metric) {
    case WENV_VORONOI_EUCLIDEAN:
        return sqrtf(sum);
    case WENV_VORONOI_MANHATTAN:
        return sum;
    case WENV_VORONOI_CHEBYCHEV:
        return most;
    default:
        return powf(sum, 1.0f / s->exponent);
    }
}

static float euclidean(const float *a, const float *b, int d)
{
    float sum = 0.0f;
    for (int k = 0; k < d; k++)
        sum += (a[k] - b[k]) * (a[k] - b[k]);
    return d == 1 ? fabsf(a[0] - b[0]) : sqrtf(sum);
}

/* A signed 32-bit shift right by 16, as the hash's int arithmetic does it, on unsigned words. */
static inline uint32_t shift16(uint32_t v) { return (v >> 16) | ((v & 0x80000000u) ? 0xFFFF0000u : 0u); }

/* Cycles' hash_pcg{2,3,4}d_i of d integers (their two's complement bits in v), each in [0, 2^31). */
static void pcg(uint32_t *v, int d)
{
    for (int k = 0; k < d; k++)
        v[k] = v[k] * 1664525u + 1013904223u;
    for (int round = 0; round < 2; round++) {
        if (d == 2) {
            v[0] += v[1] * 1664525u;
            v[1] += v[0] * 1664525u;
        } else if (d == 3) {
            v[0] += v[1] * v[2];
            v[1] += v[2] * v[0];
            v[2] += v[0] * v[1];
        } else {
            v[0] += v[1] * v[3];
            v[1] += v[2] * v[0];
            v[2] += v[0] * v[1];
            v[3] += v[1] * v[2];
        }
        if (round == 0)
            for (int k = 0; k < d; k++)
                v[k] ^= shift16(v[k]);
    }
    for (int k = 0; k < d; k++)
        v[k] &= 0x7FFFFFFFu;
}

/* The integer cell c (d of 2 to 4; held as whole floats) hashed into dims floats in [0, 1]
 * (Cycles' hash_intN_to_floatN; a 2D cell's colour hashes (x, y, 0)). */
static void pcg_unit(const float *c, int d, int dims, float *out)
{
    uint32_t v[4] = {0, 0, 0, 0};
    int n = d == 2 && dims == 3 ? 3 : d;
    for (int k = 0; k < d; k++)
        v[k] = (uint32_t)(int32_t)c[k];
    pcg(v, n);
    for (int k = 0; k < dims; k++)
        out[k] = (float)v[k] * (1.0f / (float)0x7FFFFFFFu);
}

/* lookup3 of the cell's d coordinates followed by `extra` (the hashes' counter), or of them in the
 * order `order` gives (NULL: as they are), into [0, 1]: Cycles' hash_floatN_to_float, by which
 * Blender hashed every cell before 5.0 and still hashes a 1D one. */
static float lookup3_of(const float *c, int d, float extra, const int *order)
{
    float k[4];
    for (int i = 0; i < d; i++)
        k[i] = c[order ? order[i] : i];
    if (extra >= 0.0f)
        k[d] = extra;
    return wenv_lookup3_unit(k, extra >= 0.0f ? d + 1 : d);
}

/* The jitter of cell c's point, each component in [0, 1]: Cycles' hash_floatN_to_floatN before
 * Blender 5.0 (`lookup3`), its signed PCG since (and lookup3 in 1D). */
static void cell_jitter(const float *c, int d, int lookup3, float *out)
{
    static const int ROTATED[3][4] = {{3, 0, 1, 2}, {2, 3, 0, 1}, {1, 2, 3, 0}};
    if (d == 1) {
        out[0] = wenv_lookup3_unit(c, 1);
    } else if (!lookup3) {
        pcg_unit(c, d, d, out);
    } else {
        out[0] = lookup3_of(c, d, -1.0f, NULL);
        for (int k = 1; k < d; k++) /* 2D: (x, y, 1); 3D: (x, y, z, 1), (x, y, z, 2); 4D: the rotations */
            out[k] = d == 4 ? lookup3_of(c, 4, -1.0f, ROTATED[k - 1]) : lookup3_of(c, d, (float)k, NULL);
    }
}

/* Cell c's colour. */
static void cell_colour(const float *c, int d, int lookup3, float *rgb)
{
    static const int SHUFFLED[2][4] = {{2, 0, 3, 1}, {3, 2, 1, 0}};
    if (d == 1 || (lookup3 && d < 4)) { /* hash_floatN_to_float3: (c), (c, 1), (c, 2) */
        rgb[0] = lookup3_of(c, d, -1.0f, NULL);
        for (int i = 1; i < 3; i++)
            rgb[i] = lookup3_of(c, d, (float)i, NULL);
    } else if (lookup3) { /* hash_float4_to_float3: c, (z, x, w, y), (w, z, y, x) */
        rgb[0] = lookup3_of(c, 4, -1.0f, NULL);
        for (int i = 1; i < 3; i++)
            rgb[i] = lookup3_of(c, 4, -1.0f, SHUFFLED[i - 1]);
    } else {
        pcg_unit(c, d, 3, rgb);
    }
}

/* The neighbour `index` of 3^d (reach 1) or 5^d (reach 2) cells: its offset, x fastest. */
static void neighbour(int index, int reach, int d, float *offset)
{
    int side = 2 * reach + 1;
    for (int k = 0; k < d; k++, index /= side)
        offset[k] = (float)(index % side - reach);
}

static int cells_within(int reach, int d)
{
    int count = 1;
    for (int k = 0; k < d; k++)
        count *= 2 * reach + 1;
    return count;
}

/* The point of the cell at `offset` from `cell`, in the cell's local frame, the cell itself and its
 * jitter (jitter NULL: not wanted). */
static void cell_point(const float *cell, const float *offset, int d, const wenv_voronoi_settings *s, float *point,
                       float *at, float *jitter_out)
{
    float mine[4], *jitter = jitter_out ? jitter_out : mine;
    for (int k = 0; k < d; k++)
        at[k] = cell[k] + offset[k];
    cell_jitter(at, d, s->lookup3_cells, jitter);
    for (int k = 0; k < d; k++)
        point[k] = offset[k] + jitter[k] * s->randomness;
}

static void split(const float *coord, int d, float *cell, float *local)
{
    for (int k = 0; k < d; k++) {
        float f = floorf(coord[k]);
        local[k] = coord[k] - f;
        cell[k] = fminf(fmaxf(f, -1e9f), 1e9f); /* an int's range, where the hash reads it */
    }
}

/* A point of d dimensions as Cycles' voronoi_position places it in (x, y, z, W). */
static void as_position(const float *cell, const float *point, int d, float *out)
{
    float v[4] = {0.0f, 0.0f, 0.0f, 0.0f};
    for (int k = 0; k < d; k++)
        v[k] = cell[k] + point[k];
    if (d == 1) {
        out[0] = out[1] = out[2] = 0.0f;
        out[3] = v[0];
    } else {
        memcpy(out, v, sizeof v);
    }
}

/* F1 or F2 of one octave. */
static octave_out nearest(const float *coord, int d, const wenv_voronoi_settings *s, int second)
{
    float cell[4], local[4], offset[4], point[4], at[4], best_at[4] = {0}, next_at[4] = {0};
    float best_point[4] = {0}, next_point[4] = {0};
    float d1 = FLT_MAX, d2 = FLT_MAX;
    split(coord, d, cell, local);
    for (int i = 0, count = cells_within(1, d); i < count; i++) {
        neighbour(i, 1, d, offset);
        cell_point(cell, offset, d, s, point, at, NULL);
        float dist = metric_distance(point, local, d, s);
        if (dist < d1) {
            d2 = d1;
            memcpy(next_at, best_at, sizeof next_at);
            memcpy(next_point, best_point, sizeof next_point);
            d1 = dist;
            memcpy(best_at, at, sizeof best_at);
            memcpy(best_point, point, sizeof best_point);
        } else if (second && dist < d2) {
            d2 = dist;
            memcpy(next_at, at, sizeof next_at);
            memcpy(next_point, point, sizeof next_point);
        }
    }
    octave_out out = {second ? d2 : d1, {0}, {0}};
    cell_colour(second ? next_at : best_at, d, s->lookup3_cells, out.colour);
    as_position(cell, second ? next_point : best_point, d, out.position);
    return out;
}

static octave_out smooth_f1(const float *coord, int d, const wenv_voronoi_settings *s, int want_colour)
{
    float cell[4], local[4], offset[4], point[4], at[4], rgb[4];
    float dist_sum = 0.0f, colour[3] = {0.0f, 0.0f, 0.0f}, smooth_point[4] = {0.0f, 0.0f, 0.0f, 0.0f}, h = -1.0f;
    split(coord, d, cell, local);
    for (int i = 0, count = cells_within(2, d); i < count; i++) {
        neighbour(i, 2, d, offset);
        cell_point(cell, offset, d, s, point, at, rgb);
        float dist = metric_distance(point, local, d, s);
        h = h == -1.0f ? 1.0f : smoothstep01(0.5f + 0.5f * (dist_sum - dist) / s->smoothness);
        float correction = s->smoothness * h * (1.0f - h);
        dist_sum = lerp(dist_sum, dist, h) - correction;
        correction /= 1.0f + 3.0f * s->smoothness;
        for (int k = 0; k < d; k++)
            smooth_point[k] = lerp(smooth_point[k], point[k], h) - correction;
        if (!want_colour)
            continue;
        if (d < 3 || (d == 4 && s->lookup3_cells)) /* else a cell's colour is its jitter's first three */
            cell_colour(at, d, s->lookup3_cells, rgb);
        for (int c = 0; c < 3; c++)
            colour[c] = lerp(colour[c], rgb[c], h) - correction;
    }
    octave_out out = {dist_sum, {colour[0], colour[1], colour[2]}, {0}};
    as_position(cell, smooth_point, d, out.position);
    return out;
}

static float distance_to_edge(const float *coord, int d, const wenv_voronoi_settings *s)
{
    float cell[4], local[4], offset[4], point[4], at[4];
    split(coord, d, cell, local);
    if (d == 1) {
        float left[1] = {cell[0] - 1.0f}, right[1] = {cell[0] + 1.0f};
        float mid = wenv_lookup3_unit(cell, 1) * s->randomness;
        float lp = -1.0f + wenv_lookup3_unit(left, 1) * s->randomness;
        float rp = 1.0f + wenv_lookup3_unit(right, 1) * s->randomness;
        return fminf(fabsf((mid + lp) / 2.0f - local[0]), fabsf((mid + rp) / 2.0f - local[0]));
    }
    float to_closest[4] = {0}, least = FLT_MAX;
    int count = cells_within(1, d);
    for (int i = 0; i < count; i++) {
        neighbour(i, 1, d, offset);
        cell_point(cell, offset, d, s, point, at, NULL);
        float v[4], dd = 0.0f;
        for (int k = 0; k < d; k++) {
            v[k] = point[k] - local[k];
            dd += v[k] * v[k];
        }
        if (dd < least) {
            least = dd;
            memcpy(to_closest, v, sizeof v);
        }
    }
    least = FLT_MAX;
    for (int i = 0; i < count; i++) {
        neighbour(i, 1, d, offset);
        cell_point(cell, offset, d, s, point, at, NULL);
        float v[4], perp[4], pp = 0.0f;
        for (int k = 0; k < d; k++) {
            v[k] = point[k] - local[k];
            perp[k] = v[k] - to_closest[k];
            pp += perp[k] * perp[k];
        }
        if (pp > 0.0001f) {
            float len = sqrtf(pp), along = 0.0f;
            for (int k = 0; k < d; k++)
                along += (to_closest[k] + v[k]) / 2.0f * (perp[k] / len);
            least = fminf(least, along);
        }
    }
    return least;
}

static float n_sphere_radius(const float *coord, int d, const wenv_voronoi_settings *s)
{
    float cell[4], local[4], offset[4], point[4], at[4];
    float closest[4] = {0}, closest_offset[4] = {0}, other[4] = {0}, least = FLT_MAX;
    split(coord, d, cell, local);
    int count = cells_within(1, d);
    for (int i = 0; i < count; i++) {
        neighbour(i, 1, d, offset);
        cell_point(cell, offset, d, s, point, at, NULL);
        float dist = euclidean(point, local, d);
        if (dist < least) {
            least = dist;
            memcpy(closest, point, sizeof closest);
            memcpy(closest_offset, offset, sizeof closest_offset);
        }
    }
    least = FLT_MAX;
    for (int i = 0; i < count; i++) {
        if (i == count / 2)
            continue; /* the closest point's own cell */
        neighbour(i, 1, d, offset);
        for (int k = 0; k < d; k++)
            offset[k] += closest_offset[k];
        cell_point(cell, offset, d, s, point, at, NULL);
        float dist = euclidean(closest, point, d);
        if (dist < least) {
            least = dist;
            memcpy(other, point, sizeof other);
        }
    }
    return euclidean(other, closest, d) / 2.0f;
}

static octave_out octave(const float *coord, int d, const wenv_voronoi_settings *s, int want_colour)
{
    if (s->feature == WENV_VORONOI_F2)
        return nearest(coord, d, s, 1);
    if (s->feature == WENV_VORONOI_SMOOTH_F1 && s->smoothness != 0.0f)
        return smooth_f1(coord, d, s, want_colour);
    return nearest(coord, d, s, 0);
}

static void scaled(const float *p, float k, int d, float *out)
{
    for (int i = 0; i < d; i++)
        out[i] = p[i] * k;
}

/* Cycles' fractal Voronoi: octaves summed as fBM sums them, max_distance normalising. */
static octave_out fractal(const float *coord, int d, const wenv_voronoi_settings *s, float max_distance,
                          int want_colour)
{
    float amplitude = 1.0f, max_amplitude = 0.0f, scale = 1.0f, q[4];
    octave_out out = {0.0f, {0.0f, 0.0f, 0.0f}, {0.0f, 0.0f, 0.0f, 0.0f}};
    int zero_input = s->detail == 0.0f || s->roughness == 0.0f;
    for (int i = 0; i <= (int)ceilf(s->detail); i++) {
        scaled(coord, scale, d, q);
        octave_out o = octave(q, d, s, want_colour);
        if (zero_input) {
            max_amplitude = 1.0f;
            out = o;
            break;
        }
        if ((float)i <= s->detail) {
            max_amplitude += amplitude;
            out.distance += o.distance * amplitude;
            for (int c = 0; c < 3; c++)
                out.colour[c] += o.colour[c] * amplitude;
            for (int k = 0; k < 4; k++)
                out.position[k] = lerp(out.position[k], o.position[k] / scale, amplitude);
            scale *= s->lacunarity;
            amplitude *= s->roughness;
        } else {
            float remainder = s->detail - floorf(s->detail);
            if (remainder != 0.0f) {
                max_amplitude = lerp(max_amplitude, max_amplitude + amplitude, remainder);
                out.distance = lerp(out.distance, out.distance + o.distance * amplitude, remainder);
                for (int c = 0; c < 3; c++)
                    out.colour[c] = lerp(out.colour[c], out.colour[c] + o.colour[c] * amplitude, remainder);
                for (int k = 0; k < 4; k++)
                    out.position[k] =
                        lerp(out.position[k], lerp(out.position[k], o.position[k] / scale, amplitude), remainder);
            }
        }
    }
    if (s->normalize) {
        out.distance /= max_amplitude * max_distance;
        for (int c = 0; c < 3; c++)
            out.colour[c] /= max_amplitude;
    }
    for (int k = 0; k < 4; k++) /* back from the node's Scale (Cycles' safe_divide) */
        out.position[k] = s->scale != 0.0f ? out.position[k] / s->scale : 0.0f;
    return out;
}

static float fractal_distance_to_edge(const float *coord, int d, const wenv_voronoi_settings *s, float max_distance)
{
    float amplitude = 1.0f, max_amplitude = max_distance, scale = 1.0f, distance = 8.0f, q[4];
    int zero_input = s->detail == 0.0f || s->roughness == 0.0f;
    for (int i = 0; i <= (int)ceilf(s->detail); i++) {
        scaled(coord, scale, d, q);
        float o = distance_to_edge(q, d, s);
        if (zero_input) {
            distance = o;
            break;
        }
        if ((float)i <= s->detail) {
            max_amplitude = lerp(max_amplitude, max_distance / scale, amplitude);
            distance = lerp(distance, fminf(distance, o / scale), amplitude);
            scale *= s->lacunarity;
            amplitude *= s->roughness;
        } else {
            float remainder = s->detail - floorf(s->detail);
            if (remainder != 0.0f) {
                float lerp_amplitude = lerp(max_amplitude, max_distance / scale, amplitude);
                max_amplitude = lerp(max_amplitude, lerp_amplitude, remainder);
                float lerp_distance = lerp(distance, fminf(distance, o / scale), amplitude);
                distance = lerp(distance, fminf(distance, lerp_distance), remainder);
            }
        }
    }
    return s->normalize ? distance / max_amplitude : distance;
}

typedef struct {
    const wenv_voronoi_settings *s;
    const float *vectors, *w;
    float w0;
    float *distance, *colour, *position;
} voronoi_job;

/* One point's outputs, d a constant where this is inlined (the cell loops then unroll). */
static inline void voronoi_point(const voronoi_job *job, size_t i, const int d, float max_distance)
{
    const wenv_voronoi_settings *s = job->s;
    float p[4] = {0.0f, 0.0f, 0.0f, 0.0f}, wi = (job->w ? job->w[i] : job->w0) * s->scale;
    if (d == 1) {
        p[0] = wi;
    } else {
        for (int k = 0; k < (d == 4 ? 3 : d); k++)
            p[k] = job->vectors[3 * i + (size_t)k] * s->scale;
        if (d == 4)
            p[3] = wi;
    }
    octave_out out = {0.0f, {0.0f, 0.0f, 0.0f}, {0.0f, 0.0f, 0.0f, 0.0f}};
    if (s->feature == WENV_VORONOI_DISTANCE_TO_EDGE)
        out.distance = fractal_distance_to_edge(p, d, s, max_distance);
    else if (s->feature == WENV_VORONOI_N_SPHERE_RADIUS)
        out.distance = n_sphere_radius(p, d, s);
    else
        out = fractal(p, d, s, max_distance, job->colour != NULL);
    job->distance[i] = out.distance;
    if (job->colour)
        memcpy(job->colour + 3 * i, out.colour, sizeof out.colour);
    if (job->position)
        memcpy(job->position + 4 * i, out.position, sizeof out.position);
}

/* A block of points at a constant dimension: GCC inlines the whole chain into each (flatten). */
#if defined(__GNUC__)
#define FLATTEN __attribute__((flatten))
#else
#define FLATTEN
#endif
#define BLOCK_OF(D)                                                                                                \
    FLATTEN static void block_##D(const voronoi_job *job, size_t first, size_t end, float max_distance)           \
    {                                                                                                              \
        for (size_t i = first; i < end; i++)                                                                       \
            voronoi_point(job, i, D, max_distance);                                                                \
    }
BLOCK_OF(1)
BLOCK_OF(2)
BLOCK_OF(3)
BLOCK_OF(4)

static void voronoi_block(const void *ctx, size_t first, size_t end)
{
    const voronoi_job *job = ctx;
    const wenv_voronoi_settings *s = job->s;
    int d = s->dimensions;
    float corner[4], origin[4] = {0.0f, 0.0f, 0.0f, 0.0f}, half = 0.5f + 0.5f * s->randomness;
    for (int k = 0; k < 4; k++)
        corner[k] = half;
    float max_distance = half;
    if (s->feature != WENV_VORONOI_DISTANCE_TO_EDGE)
        max_distance = (d == 1 ? half : metric_distance(origin, corner, d, s)) *
                       (s->feature == WENV_VORONOI_F2 ? 2.0f : 1.0f);
    switch (d) {
    case 1:
        block_1(job, first, end, max_distance);
        break;
    case 2:
        block_2(job, first, end, max_distance);
        break;
    case 3:
        block_3(job, first, end, max_distance);
        break;
    default:
        block_4(job, first, end, max_distance);
    }
}

wenv_status wenv_voronoi_texture(const wenv_voronoi_settings *settings, const float *vectors, const float *w,
                                 float w0, size_t n, float *distance, float *colour, float *position,
                                 const wenv_progress *progress, wenv_error *err)
{
    wenv_voronoi_settings s = *settings;
    if (s.dimensions < 1 || s.dimensions > 4)
        return wenv_error_set(err, WENV_ERR_VALUE, "dimensions must be 1, 2, 3 or 4, got %d", s.dimensions);
    if ((int)s.feature < 0 || s.feature > WENV_VORONOI_N_SPHERE_RADIUS || (int)s.metric < 0 ||
        s.metric > WENV_VORONOI_MINKOWSKI)
        return wenv_error_set(err, WENV_ERR_VALUE, "unknown Voronoi feature or distance metric");
    const float given[] = {s.scale, s.detail, s.roughness, s.lacunarity, s.smoothness, s.exponent, s.randomness, w0};
    const char *names[] = {"scale", "detail", "roughness", "lacunarity", "smoothness", "exponent", "randomness", "w"};
    for (size_t k = 0; k < sizeof given / sizeof given[0]; k++)
        if (!isfinite(given[k]))
            return wenv_error_set(err, WENV_ERR_VALUE, "%s must be finite, got %g", names[k], (double)given[k]);
    if (s.dimensions > 1 && !vectors)
        return wenv_error_set(err, WENV_ERR_VALUE, "%dD Voronoi needs the vectors", s.dimensions);
    /* as Cycles clamps them */
    s.detail = fminf(fmaxf(s.detail, 0.0f), 15.0f);
    s.roughness = fminf(fmaxf(s.roughness, 0.0f), 1.0f);
    s.randomness = fminf(fmaxf(s.randomness, 0.0f), 1.0f);
    s.smoothness = fminf(fmaxf(s.smoothness / 2.0f, 0.0f), 0.5f);
    voronoi_job job = {&s, vectors, w, w0, distance, colour, position};
    if (wenv_progress_blocks(n, BLOCK, voronoi_block, &job, progress))
        return wenv_error_set(err, WENV_ERR_CANCELLED, "the Voronoi texture was cancelled");
    return WENV_OK;
}
