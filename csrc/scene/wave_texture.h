/* Blender's Wave Texture node, evaluated at points as Cycles' SVM evaluates it
 * (intern/cycles/kernel/svm/wave.h): bands or rings along an axis, a sine, saw or triangle profile,
 * the phase distorted by fBM noise. */
#ifndef WENV_WAVE_TEXTURE_H
#define WENV_WAVE_TEXTURE_H

#include <stddef.h>

#include "base/error.h"
#include "base/progress.h"

typedef enum { WENV_WAVE_BANDS = 0, WENV_WAVE_RINGS } wenv_wave_type;
/* bands: X, Y, Z, diagonal; rings: X, Y, Z, spherical */
typedef enum { WENV_WAVE_X = 0, WENV_WAVE_Y, WENV_WAVE_Z, WENV_WAVE_ALONG_ALL } wenv_wave_direction;
typedef enum { WENV_WAVE_SIN = 0, WENV_WAVE_SAW, WENV_WAVE_TRI } wenv_wave_profile;

/* The node's settings and unlinked inputs, under Blender's names. */
typedef struct {
    wenv_wave_type type;
    wenv_wave_direction direction;
    wenv_wave_profile profile;
    float scale, distortion, detail, detail_scale, detail_roughness, phase;
} wenv_wave_settings;

/* The node's Fac at n points (`vectors`, n x 3); its Color is Fac in every channel.  Reports to
 * `progress` (NULL: none), which may cancel.  ValueError for a setting that is not finite. */
wenv_status wenv_wave_texture(const wenv_wave_settings *settings, const float *vectors, size_t n, float *value,
                              const wenv_progress *progress, wenv_error *err);

#endif
