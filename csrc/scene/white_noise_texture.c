/* Blender's White Noise Texture node (white_noise_texture.h). */
#include "scene/white_noise_texture.h"

#include "math/lookup3.h"

/* Points per progress report and cancel check. */
#define BLOCK 16384

typedef struct {
    int dimensions;
    const float *vectors, *w;
    float w0, *value, *colour;
} white_noise_job;

/* The point's key (Cycles' order: the vector's used axes, then W) and its colour's second and third
 * keys: the key with 1 and 2 appended (in 1D to 3D) or turned (4D), as hash_floatN_to_float3 makes
 * them. */
static int keys_at(const white_noise_job *job, size_t i, float key[4], float second[4], float third[4])
{
    const float *v = job->vectors + 3 * i, w = job->w ? job->w[i] : job->w0;
    int d = job->dimensions;
    if (d == 1) {
        key[0] = w;
    } else {
        for (int k = 0; k < (d == 4 ? 3 : d); k++)
            key[k] = v[k];
        if (d == 4)
            key[3] = w;
    }
    if (d == 4) {
        const float x = key[0], y = key[1], z = key[2], t = key[3];
        second[0] = z, second[1] = x, second[2] = t, second[3] = y;
        third[0] = t, third[1] = z, third[2] = y, third[3] = x;
        return 4;
    }
    for (int k = 0; k < d; k++)
        second[k] = third[k] = key[k];
    second[d] = 1.0f, third[d] = 2.0f;
    return d + 1;
}

static void white_noise_block(const void *ctx, size_t first, size_t end)
{
    const white_noise_job *job = ctx;
    for (size_t i = first; i < end; i++) {
        float key[4], second[4], third[4];
        int longer = keys_at(job, i, key, second, third);
        job->value[i] = wenv_lookup3_unit(key, job->dimensions);
        if (job->colour) {
            float *c = job->colour + 3 * i;
            c[0] = job->value[i];
            c[1] = wenv_lookup3_unit(second, longer);
            c[2] = wenv_lookup3_unit(third, longer);
        }
    }
}

wenv_status wenv_white_noise_texture(int dimensions, const float *vectors, const float *w, float w0, size_t n,
                                     float *value, float *colour, const wenv_progress *progress, wenv_error *err)
{
    if (dimensions < 1 || dimensions > 4)
        return wenv_error_set(err, WENV_ERR_VALUE, "dimensions must be 1, 2, 3 or 4, got %d", dimensions);
    white_noise_job job = {dimensions, vectors, w, w0, value, colour};
    if (wenv_progress_blocks(n, BLOCK, white_noise_block, &job, progress))
        return wenv_error_set(err, WENV_ERR_CANCELLED, "the white noise texture was cancelled");
    return WENV_OK;
}
