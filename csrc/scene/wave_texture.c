/* Blender's Wave Texture node (wave_texture.h). */
#include "scene/wave_texture.h"

#include <math.h>

#include "scene/noise_texture.h"

/* Points per progress report and cancel check. */
#define BLOCK 4096

static float wave_at(const wenv_wave_settings *s, const float *v)
{
    float p[3];
    for (int k = 0; k < 3; k++) /* Cycles' nudge off unit coordinates, where bands would flip */
        p[k] = (v[k] * s->scale + 0.000001f) * 0.999999f;
    float n;
    if (s->type == WENV_WAVE_BANDS) {
        n = s->direction == WENV_WAVE_ALONG_ALL ? (p[0] + p[1] + p[2]) * 10.0f : p[s->direction] * 20.0f;
    } else {
        float r[3] = {p[0], p[1], p[2]};
        if (s->direction != WENV_WAVE_ALONG_ALL)
            r[s->direction] = 0.0f; /* rings about that axis */
        n = sqrtf(r[0] * r[0] + r[1] * r[1] + r[2] * r[2]) * 20.0f;
    }
    n += s->phase;
    if (s->distortion != 0.0f) {
        float q[3] = {p[0] * s->detail_scale, p[1] * s->detail_scale, p[2] * s->detail_scale};
        n += s->distortion * (wenv_noise_fbm3(q, s->detail, s->detail_roughness, 2.0f, 1) * 2.0f - 1.0f);
    }
    const float two_pi = 6.2831853071795864f, half_pi = 1.5707963267948966f;
    switch (s->profile) {
    case WENV_WAVE_SIN:
        return 0.5f + 0.5f * sinf(n - half_pi);
    case WENV_WAVE_SAW:
        n /= two_pi;
        return n - floorf(n);
    default:
        n /= two_pi;
        return fabsf(n - floorf(n + 0.5f)) * 2.0f;
    }
}

typedef struct {
    const wenv_wave_settings *s;
    const float *vectors;
    float *value;
} wave_job;

static void wave_block(const void *ctx, size_t first, size_t end)
{
    const wave_job *job = ctx;
    for (size_t i = first; i < end; i++)
        job->value[i] = wave_at(job->s, job->vectors + 3 * i);
}

wenv_status wenv_wave_texture(const wenv_wave_settings *settings, const float *vectors, size_t n, float *value,
                              const wenv_progress *progress, wenv_error *err)
{
    const wenv_wave_settings *s = settings;
    const float given[] = {s->scale, s->distortion, s->detail, s->detail_scale, s->detail_roughness, s->phase};
    const char *names[] = {"scale", "distortion", "detail", "detail_scale", "detail_roughness", "phase"};
    for (size_t k = 0; k < sizeof given / sizeof given[0]; k++)
        if (!isfinite(given[k]))
            return wenv_error_set(err, WENV_ERR_VALUE, "%s must be finite, got %g", names[k], (double)given[k]);
    if ((int)s->type < 0 || s->type > WENV_WAVE_RINGS || (int)s->direction < 0 ||
        s->direction > WENV_WAVE_ALONG_ALL || (int)s->profile < 0 || s->profile > WENV_WAVE_TRI)
        return wenv_error_set(err, WENV_ERR_VALUE, "unknown wave type, direction or profile");
    wave_job job = {s, vectors, value};
    if (wenv_progress_blocks(n, BLOCK, wave_block, &job, progress))
        return wenv_error_set(err, WENV_ERR_CANCELLED, "the wave texture was cancelled");
    return WENV_OK;
}
