/* Blender's Gabor Texture node (gabor_texture.h).  Float arithmetic in Cycles' order. */
#include "scene/gabor_texture.h"

#include <math.h>

#include "math/lookup3.h"

/* Points per progress report and cancel check. */
#define BLOCK 4096
/* Impulses a cell: Cycles' stratified count. */
#define IMPULSES 8

static const float PI_F = 3.14159265358979323846f;

/* The windowed Gaussian times the phasor of a kernel at `position` (its squared length d2) whose
 * phase advances along the frequency vector: (cosine part, sine part) added times weight to sum. */
static void add_kernel(float d2, float angle, float weight, float sum[2])
{
    float hann = 0.5f + 0.5f * cosf(PI_F * d2);
    float envelope = expf(-PI_F * d2) * hann;
    sum[0] += weight * (envelope * cosf(angle));
    sum[1] += weight * (envelope * sinf(angle));
}

static void noise_2d(const float co[2], float frequency, float isotropy, float base, float sum[2])
{
    float cell[2] = {floorf(co[0]), floorf(co[1])}, local[2] = {co[0] - cell[0], co[1] - cell[1]};
    sum[0] = sum[1] = 0.0f;
    for (int j = -1; j <= 1; j++)
        for (int i = -1; i <= 1; i++) {
            float c[2] = {cell[0] + (float)i, cell[1] + (float)j}, p[2] = {local[0] - (float)i, local[1] - (float)j};
            float part[2] = {0.0f, 0.0f};
            for (int k = 0; k < IMPULSES; k++) {
                float so[3] = {c[0], c[1], (float)(k * 3)}, sc[3] = {c[0], c[1], (float)(k * 3 + 1)};
                float sw[3] = {c[0], c[1], (float)(k * 3 + 2)}, sc2[3] = {sc[2], sc[0], sc[1]};
                float orientation = base + (wenv_lookup3_unit(so, 3) - 0.5f) * PI_F * isotropy;
                float q[2] = {p[0] - wenv_lookup3_unit(sc, 3), p[1] - wenv_lookup3_unit(sc2, 3)};
                float d2 = q[0] * q[0] + q[1] * q[1];
                if (d2 >= 1.0f)
                    continue;
                float weight = wenv_lookup3_unit(sw, 3) < 0.5f ? -1.0f : 1.0f;
                float fv[2] = {frequency * cosf(orientation), frequency * sinf(orientation)};
                add_kernel(d2, 2.0f * PI_F * (q[0] * fv[0] + q[1] * fv[1]), weight, part);
            }
            sum[0] += part[0];
            sum[1] += part[1];
        }
}

/* The kernel's direction: the base one, turned at random in spherical coordinates by isotropy. */
static void orientation_3d(const float base[3], float isotropy, const float seed[4], float out[3])
{
    if (isotropy == 0.0f) {
        out[0] = base[0], out[1] = base[1], out[2] = base[2];
        return;
    }
    float inclination = acosf(base[2]);
    float azimuth = (base[1] < 0.0f ? -1.0f : 1.0f) * acosf(base[0] / sqrtf(base[0] * base[0] + base[1] * base[1]));
    float s2[4] = {seed[2], seed[0], seed[3], seed[1]};
    inclination += wenv_lookup3_unit(seed, 4) * PI_F * isotropy;
    azimuth += wenv_lookup3_unit(s2, 4) * PI_F * isotropy;
    out[0] = sinf(inclination) * cosf(azimuth);
    out[1] = sinf(inclination) * sinf(azimuth);
    out[2] = cosf(inclination);
}

static void noise_3d(const float co[3], float frequency, float isotropy, const float base[3], float sum[2])
{
    float cell[3], local[3];
    for (int a = 0; a < 3; a++)
        cell[a] = floorf(co[a]), local[a] = co[a] - cell[a];
    sum[0] = sum[1] = 0.0f;
    for (int l = -1; l <= 1; l++)
        for (int j = -1; j <= 1; j++)
            for (int i = -1; i <= 1; i++) {
                float c[3] = {cell[0] + (float)i, cell[1] + (float)j, cell[2] + (float)l};
                float p[3] = {local[0] - (float)i, local[1] - (float)j, local[2] - (float)l};
                float part[2] = {0.0f, 0.0f};
                for (int k = 0; k < IMPULSES; k++) {
                    float so[4] = {c[0], c[1], c[2], (float)(k * 3)}, sc[4] = {c[0], c[1], c[2], (float)(k * 3 + 1)};
                    float sw[4] = {c[0], c[1], c[2], (float)(k * 3 + 2)};
                    float o[3];
                    orientation_3d(base, isotropy, so, o);
                    /* hash_float4_to_float3: the seed, then turned twice */
                    float t1[4] = {sc[2], sc[0], sc[3], sc[1]}, t2[4] = {sc[3], sc[2], sc[1], sc[0]};
                    float q[3] = {p[0] - wenv_lookup3_unit(sc, 4), p[1] - wenv_lookup3_unit(t1, 4),
                                  p[2] - wenv_lookup3_unit(t2, 4)};
                    float d2 = q[0] * q[0] + q[1] * q[1] + q[2] * q[2];
                    if (d2 >= 1.0f)
                        continue;
                    float weight = wenv_lookup3_unit(sw, 4) < 0.5f ? -1.0f : 1.0f;
                    float fv[3] = {frequency * o[0], frequency * o[1], frequency * o[2]};
                    add_kernel(d2, 2.0f * PI_F * (q[0] * fv[0] + q[1] * fv[1] + q[2] * fv[2]), weight, part);
                }
                sum[0] += part[0];
                sum[1] += part[1];
            }
}

typedef struct {
    const wenv_gabor_settings *s;
    float base3[3], frequency, isotropy, normalization;
    const float *vectors;
    float *value, *phase, *intensity;
} gabor_job;

static void gabor_block(const void *ctx, size_t first, size_t end)
{
    const gabor_job *job = ctx;
    const wenv_gabor_settings *s = job->s;
    for (size_t i = first; i < end; i++) {
        const float *v = job->vectors + 3 * i;
        float co[3] = {v[0] * s->scale, v[1] * s->scale, v[2] * s->scale}, ph[2];
        if (s->dimensions == 2)
            noise_2d(co, job->frequency, job->isotropy, s->orientation_2d, ph);
        else
            noise_3d(co, job->frequency, job->isotropy, job->base3, ph);
        if (job->value)
            job->value[i] = (ph[1] / job->normalization) * 0.5f + 0.5f;
        if (job->phase)
            job->phase[i] = (atan2f(ph[1], ph[0]) + PI_F) / (2.0f * PI_F);
        if (job->intensity)
            job->intensity[i] = sqrtf(ph[0] * ph[0] + ph[1] * ph[1]) / job->normalization;
    }
}

wenv_status wenv_gabor_texture(const wenv_gabor_settings *settings, const float *vectors, size_t n, float *value,
                               float *phase, float *intensity, const wenv_progress *progress, wenv_error *err)
{
    const wenv_gabor_settings *s = settings;
    if (s->dimensions != 2 && s->dimensions != 3)
        return wenv_error_set(err, WENV_ERR_VALUE, "dimensions must be 2 or 3, got %d", s->dimensions);
    const float given[] = {s->scale, s->frequency, s->anisotropy, s->orientation_2d, s->orientation_3d[0],
                           s->orientation_3d[1], s->orientation_3d[2]};
    const char *names[] = {"scale", "frequency", "anisotropy", "orientation_2d", "orientation_3d", "orientation_3d",
                           "orientation_3d"};
    for (size_t k = 0; k < sizeof given / sizeof given[0]; k++)
        if (!isfinite(given[k]))
            return wenv_error_set(err, WENV_ERR_VALUE, "%s must be finite, got %g", names[k], (double)given[k]);
    gabor_job job = {.s = s, .vectors = vectors, .value = value, .phase = phase, .intensity = intensity};
    const float *o = s->orientation_3d;
    float length = sqrtf(o[0] * o[0] + o[1] * o[1] + o[2] * o[2]);
    if (s->dimensions == 3 && !(length > 0.0f))
        return wenv_error_set(err, WENV_ERR_VALUE, "orientation_3d must not be zero");
    for (int a = 0; a < 3; a++)
        job.base3[a] = length > 0.0f ? o[a] / length : 0.0f;
    job.isotropy = 1.0f - fminf(fmaxf(s->anisotropy, 0.0f), 1.0f);
    job.frequency = fmaxf(0.001f, s->frequency);
    /* six standard deviations of the sum: sqrt(impulses x second moment x the kernel's squared integral) */
    float integral = s->dimensions == 2 ? 0.25f : 1.0f / (4.0f * 1.41421356237309504880f);
    job.normalization = 6.0f * sqrtf((float)IMPULSES * 0.5f * integral);
    if (wenv_progress_blocks(n, BLOCK, gabor_block, &job, progress))
        return wenv_error_set(err, WENV_ERR_CANCELLED, "the gabor texture was cancelled");
    return WENV_OK;
}
