/* Blender's Noise Texture node (noise_texture.h).  One body serves the four dimensions: a point is
 * float[4] of which the first `d` count.  Lerps run along x, then y, z and w, as Cycles' SSE
 * kernels run them on x86 CPUs; the hashes and gradients are exact, so values agree with Cycles'
 * to float rounding. */
#include "scene/noise_texture.h"

#include <math.h>
#include <stdint.h>
#include <string.h>

#include "math/lookup3.h"

/* Points per progress report and cancel check. */
#define BLOCK 4096

/* Cycles' random offsets of a seed, component k: the seeds of distortion and of Color's channels. */
static float seed_offset(float seed, int k, int d)
{
    float key[2] = {seed, (float)k};
    return 100.0f + wenv_lookup3_unit(key, d == 1 ? 1 : 2) * 100.0f;
}

/* ---- Perlin noise ---- */

static inline float fade(float t) { return t * t * t * (t * (t * 6.0f - 15.0f) + 10.0f); }
static inline float lerp(float a, float b, float t) { return a + t * (b - a); }
static inline float negate_if(float v, uint32_t condition) { return condition ? -v : v; }

/* The gradient at a lattice corner of hash h, dotted with the offset f from it. */
static float gradient(uint32_t hash, const float *f, int d)
{
    switch (d) {
    case 1: {
        uint32_t h = hash & 15u;
        return negate_if(1.0f + (float)(h & 7u), h & 8u) * f[0];
    }
    case 2: {
        uint32_t h = hash & 7u;
        float u = h < 4 ? f[0] : f[1], v = 2.0f * (h < 4 ? f[1] : f[0]);
        return negate_if(u, h & 1u) + negate_if(v, h & 2u);
    }
    case 3: {
        uint32_t h = hash & 15u;
        float u = h < 8 ? f[0] : f[1], vt = (h == 12 || h == 14) ? f[0] : f[2], v = h < 4 ? f[1] : vt;
        return negate_if(u, h & 1u) + negate_if(v, h & 2u);
    }
    default: {
        uint32_t h = hash & 31u;
        float u = h < 24 ? f[0] : f[1], v = h < 16 ? f[1] : f[2], s = h < 8 ? f[2] : f[3];
        return negate_if(u, h & 1u) + negate_if(v, h & 2u) + negate_if(s, h & 4u);
    }
    }
}

/* Perlin noise at p, of d dimensions: the 2^d corners' gradients blended by the faded fractions.
 * Inlined where d is a constant, so that its loops unroll. */
static inline float perlin(const float *p, const int d)
{
    int cell[4];
    float frac[4], t[4], values[16];
    for (int k = 0; k < d; k++) {
        float f = floorf(p[k]);
        cell[k] = (int)f;
        frac[k] = p[k] - f;
        t[k] = fade(frac[k]);
    }
    for (int corner = 0; corner < (1 << d); corner++) {
        uint32_t key[4];
        float off[4];
        for (int k = 0; k < d; k++) {
            int up = (corner >> k) & 1;
            key[k] = (uint32_t)(cell[k] + up);
            off[k] = up ? frac[k] - 1.0f : frac[k];
        }
        values[corner] = gradient(wenv_lookup3(key, d), off, d);
    }
    /* along x first: corner bit 0 */
    for (int k = 0; k < d; k++)
        for (int c = 0; c < (1 << (d - 1 - k)); c++)
            values[c] = lerp(values[2 * c], values[2 * c + 1], t[k]);
    return values[0];
}

/* Signed noise in about [-1, 1] (the OSL scales), repeating every 100,000 along each axis. */
static float snoise(const float *p, int d)
{
    float q[4];
    for (int k = 0; k < d; k++) /* fmodf leaves a smaller value as it is, and costs more than a test */
        q[k] = fabsf(p[k]) < 100000.0f ? p[k] : fmodf(p[k], 100000.0f);
    switch (d) {
    case 1:
        return 0.2500f * perlin(q, 1);
    case 2:
        return 0.6616f * perlin(q, 2);
    case 3:
        return 0.9820f * perlin(q, 3);
    default:
        return 0.8344f * perlin(q, 4);
    }
}

static void scaled(const float *p, float s, int d, float *out)
{
    for (int k = 0; k < d; k++)
        out[k] = s * p[k];
}

/* ---- octaves ---- */

static float fbm(const float *p, int d, const wenv_noise_settings *s)
{
    float fscale = 1.0f, amp = 1.0f, maxamp = 0.0f, sum = 0.0f, q[4];
    for (int i = 0; i <= (int)s->detail; i++) {
        scaled(p, fscale, d, q);
        sum += snoise(q, d) * amp;
        maxamp += amp;
        amp *= s->roughness;
        fscale *= s->lacunarity;
    }
    float rmd = s->detail - floorf(s->detail);
    if (rmd == 0.0f)
        return s->normalize ? 0.5f * sum / maxamp + 0.5f : sum;
    scaled(p, fscale, d, q);
    float sum2 = sum + snoise(q, d) * amp;
    return s->normalize ? lerp(0.5f * sum / maxamp + 0.5f, 0.5f * sum2 / (maxamp + amp) + 0.5f, rmd)
                        : lerp(sum, sum2, rmd);
}

float wenv_noise_fbm3(const float p[3], float detail, float roughness, float lacunarity, int normalize)
{
    wenv_noise_settings s = {.dimensions = 3, .type = WENV_NOISE_FBM, .normalize = normalize,
                             .detail = fminf(fmaxf(detail, 0.0f), 15.0f), .roughness = roughness,
                             .lacunarity = lacunarity};
    float q[4] = {p[0], p[1], p[2], 0.0f};
    return fbm(q, 3, &s);
}

static float multifractal(const float *p0, int d, const wenv_noise_settings *s)
{
    float value = 1.0f, pwr = 1.0f, p[4];
    memcpy(p, p0, sizeof p);
    for (int i = 0; i <= (int)s->detail; i++) {
        value *= pwr * snoise(p, d) + 1.0f;
        pwr *= s->roughness;
        scaled(p, s->lacunarity, d, p);
    }
    float rmd = s->detail - floorf(s->detail);
    if (rmd != 0.0f)
        value *= rmd * pwr * snoise(p, d) + 1.0f;
    return value;
}

static float hetero_terrain(const float *p0, int d, const wenv_noise_settings *s)
{
    float pwr = s->roughness, p[4];
    memcpy(p, p0, sizeof p);
    float value = s->offset + snoise(p, d); /* the first octave unscaled */
    scaled(p, s->lacunarity, d, p);
    for (int i = 1; i <= (int)s->detail; i++) {
        value += (snoise(p, d) + s->offset) * pwr * value;
        pwr *= s->roughness;
        scaled(p, s->lacunarity, d, p);
    }
    float rmd = s->detail - floorf(s->detail);
    if (rmd != 0.0f)
        value += rmd * ((snoise(p, d) + s->offset) * pwr * value);
    return value;
}

static float hybrid_multifractal(const float *p0, int d, const wenv_noise_settings *s)
{
    float pwr = 1.0f, value = 0.0f, weight = 1.0f, p[4];
    memcpy(p, p0, sizeof p);
    for (int i = 0; weight > 0.001f && i <= (int)s->detail; i++) {
        weight = fminf(weight, 1.0f);
        float signal = (snoise(p, d) + s->offset) * pwr;
        pwr *= s->roughness;
        value += weight * signal;
        weight *= s->gain * signal;
        scaled(p, s->lacunarity, d, p);
    }
    float rmd = s->detail - floorf(s->detail);
    if (rmd != 0.0f && weight > 0.001f)
        value += rmd * fminf(weight, 1.0f) * ((snoise(p, d) + s->offset) * pwr);
    return value;
}

static float ridged_multifractal(const float *p0, int d, const wenv_noise_settings *s)
{
    float pwr = s->roughness, p[4];
    memcpy(p, p0, sizeof p);
    float signal = s->offset - fabsf(snoise(p, d));
    signal *= signal;
    float value = signal;
    for (int i = 1; i <= (int)s->detail; i++) {
        scaled(p, s->lacunarity, d, p);
        float weight = fminf(fmaxf(signal * s->gain, 0.0f), 1.0f);
        signal = s->offset - fabsf(snoise(p, d));
        signal *= signal;
        signal *= weight;
        value += signal * pwr;
        pwr *= s->roughness;
    }
    return value;
}

static float octaves(const float *p, int d, const wenv_noise_settings *s)
{
    switch (s->type) {
    case WENV_NOISE_MULTIFRACTAL:
        return multifractal(p, d, s);
    case WENV_NOISE_FBM:
        return fbm(p, d, s);
    case WENV_NOISE_HYBRID_MULTIFRACTAL:
        return hybrid_multifractal(p, d, s);
    case WENV_NOISE_RIDGED_MULTIFRACTAL:
        return ridged_multifractal(p, d, s);
    default:
        return hetero_terrain(p, d, s);
    }
}

/* The point seen from seed `seed`'s random offset. */
static void offset_by(const float *p, float seed, int d, float *out)
{
    for (int k = 0; k < d; k++)
        out[k] = p[k] + seed_offset(seed, k, d);
}

/* Point i's value and colour. */
static void noise_at(const wenv_noise_settings *s, const float *vectors, const float *w, float w0, size_t i,
                     float *value, float *colour)
{
    int d = s->dimensions;
    float p[4] = {0.0f, 0.0f, 0.0f, 0.0f}, wi = w ? w[i] : w0;
    if (d == 1) {
        p[0] = wi * s->scale;
    } else {
        for (int k = 0; k < (d == 4 ? 3 : d); k++)
            p[k] = vectors[3 * i + (size_t)k] * s->scale;
        if (d == 4)
            p[3] = wi * s->scale;
    }
    if (s->distortion != 0.0f) {
        float moved[4], q[4];
        for (int k = 0; k < d; k++) {
            offset_by(p, (float)k, d, q);
            moved[k] = p[k] + snoise(q, d) * s->distortion;
        }
        memcpy(p, moved, sizeof p);
    }
    float v = octaves(p, d, s);
    value[i] = v;
    if (!colour)
        return;
    float q[4];
    colour[3 * i] = v;
    for (int c = 1; c < 3; c++) {
        offset_by(p, (float)(d + c - 1), d, q);
        colour[3 * i + (size_t)c] = octaves(q, d, s);
    }
}

typedef struct {
    const wenv_noise_settings *s;
    const float *vectors, *w;
    float w0;
    float *value, *colour;
} noise_job;

static void noise_block(const void *ctx, size_t first, size_t end)
{
    const noise_job *job = ctx;
    for (size_t i = first; i < end; i++)
        noise_at(job->s, job->vectors, job->w, job->w0, i, job->value, job->colour);
}

wenv_status wenv_noise_texture(const wenv_noise_settings *settings, const float *vectors, const float *w, float w0,
                               size_t n, float *value, float *colour, const wenv_progress *progress, wenv_error *err)
{
    wenv_noise_settings s = *settings;
    int d = s.dimensions;
    if (d < 1 || d > 4)
        return wenv_error_set(err, WENV_ERR_VALUE, "dimensions must be 1, 2, 3 or 4, got %d", d);
    if ((int)s.type < 0 || s.type > WENV_NOISE_HETERO_TERRAIN)
        return wenv_error_set(err, WENV_ERR_VALUE, "unknown noise type %d", (int)s.type);
    const float given[] = {s.scale, s.detail, s.roughness, s.lacunarity, s.offset, s.gain, s.distortion, w0};
    const char *names[] = {"scale", "detail", "roughness", "lacunarity", "offset", "gain", "distortion", "w"};
    for (size_t k = 0; k < sizeof given / sizeof given[0]; k++)
        if (!isfinite(given[k]))
            return wenv_error_set(err, WENV_ERR_VALUE, "%s must be finite, got %g", names[k], (double)given[k]);
    if (d > 1 && !vectors)
        return wenv_error_set(err, WENV_ERR_VALUE, "%dD noise needs the vectors", d);
    /* as Cycles clamps them */
    s.detail = fminf(fmaxf(s.detail, 0.0f), 15.0f);
    s.roughness = fmaxf(s.roughness, 0.0f);
    noise_job job = {&s, vectors, w, w0, value, colour};
    if (wenv_progress_blocks(n, BLOCK, noise_block, &job, progress))
        return wenv_error_set(err, WENV_ERR_CANCELLED, "the noise texture was cancelled");
    return WENV_OK;
}
