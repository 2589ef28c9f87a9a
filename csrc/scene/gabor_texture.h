/* Blender's Gabor Texture node, evaluated at points as Cycles' SVM evaluates it
 * (intern/cycles/kernel/svm/gabor.h): sparse Gabor convolution noise (Lagae et al. 2009), eight
 * impulses a lattice cell of Bernoulli weights hashed by lookup3, each a Hann-windowed Gaussian
 * phasor; its value, phase and intensity (Tricard et al. 2019). */
#ifndef WENV_GABOR_TEXTURE_H
#define WENV_GABOR_TEXTURE_H

#include <stddef.h>

#include "base/error.h"
#include "base/progress.h"

/* The node's settings and unlinked inputs, under Blender's names. */
typedef struct {
    int dimensions; /* 2 or 3 (node.gabor_type) */
    float scale, frequency, anisotropy;
    float orientation_2d;    /* radians (2D) */
    float orientation_3d[3]; /* a direction, made unit (3D) */
} wenv_gabor_settings;

/* At n points (`vectors`, n x 3): the node's Value, Phase and Intensity (any of them NULL: not
 * wanted).  Reports to `progress` (NULL: none), which may cancel.  ValueError for a setting that is
 * not finite, dimensions other than 2 or 3, or a zero 3D orientation. */
wenv_status wenv_gabor_texture(const wenv_gabor_settings *settings, const float *vectors, size_t n, float *value,
                               float *phase, float *intensity, const wenv_progress *progress, wenv_error *err);

#endif
