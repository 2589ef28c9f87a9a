/* Blender's White Noise Texture node, evaluated at points as Cycles' SVM evaluates it
 * (intern/cycles/kernel/svm/white_noise.h): the bits of the point's coordinates hashed by lookup3
 * into a value and a colour in [0, 1]. */
#ifndef WENV_WHITE_NOISE_TEXTURE_H
#define WENV_WHITE_NOISE_TEXTURE_H

#include <stddef.h>

#include "base/error.h"
#include "base/progress.h"

/* The node's Value and Color (NULL: not wanted) at n points: `vectors` (n x 3) its Vector input, its
 * W `w` (n; NULL: `w0` everywhere), in 1 to 4 `dimensions` (1D reads W alone, 4D the vector and W).
 * Reports to `progress` (NULL: none), which may cancel.  ValueError for other dimensions. */
wenv_status wenv_white_noise_texture(int dimensions, const float *vectors, const float *w, float w0, size_t n,
                                     float *value, float *colour, const wenv_progress *progress, wenv_error *err);

#endif
