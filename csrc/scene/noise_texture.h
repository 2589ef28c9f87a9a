/* Blender's Noise Texture node, evaluated at points as Cycles' SVM evaluates it
 * (intern/cycles/kernel/svm/noisetex.h): Perlin noise of 1 to 4 dimensions hashed by Jenkins'
 * lookup3, summed over octaves as fBM, multifractal, hybrid or ridged multifractal, or
 * heterogeneous terrain, the coordinates optionally distorted by noise of their own.  A material
 * textured by noise is then shaded with the values Cycles renders, to float rounding. */
#ifndef WENV_NOISE_TEXTURE_H
#define WENV_NOISE_TEXTURE_H

#include <stddef.h>

#include "base/error.h"
#include "base/progress.h"

/* node.noise_type, in Cycles' NodeNoiseType order */
typedef enum {
    WENV_NOISE_MULTIFRACTAL = 0,
    WENV_NOISE_FBM,
    WENV_NOISE_HYBRID_MULTIFRACTAL,
    WENV_NOISE_RIDGED_MULTIFRACTAL,
    WENV_NOISE_HETERO_TERRAIN,
} wenv_noise_type;

/* The node's settings and unlinked inputs, under Blender's names. */
typedef struct {
    int dimensions; /* 1 (W alone), 2 (x, y), 3 (x, y, z) or 4 (x, y, z, W) */
    wenv_noise_type type;
    int normalize;  /* fBM: the sum mapped to [0, 1] */
    float scale, detail, roughness, lacunarity, offset, gain, distortion;
} wenv_noise_settings;

/* The node's Fac (value[i]) and, where colour is not NULL, its Color (colour[3 i ..]) at n points:
 * `vectors` (n x 3, the Vector input; NULL for 1D) and W (w[i], or w0 for all where w is NULL).
 * Reports to `progress` (NULL: none), which may cancel.  ValueError for dimensions outside 1 to 4,
 * an unknown type or a setting that is not finite. */
wenv_status wenv_noise_texture(const wenv_noise_settings *settings, const float *vectors, const float *w, float w0,
                               size_t n, float *value, float *colour, const wenv_progress *progress,
                               wenv_error *err);

/* Cycles' fBM of 3D noise at p (noise_fbm): what other textures distort with (the Wave Texture). */
float wenv_noise_fbm3(const float p[3], float detail, float roughness, float lacunarity, int normalize);

#endif
