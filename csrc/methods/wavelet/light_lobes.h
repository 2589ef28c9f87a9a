/* What the exact lights (lights.h) read of a material: each lobe's cut, the cone about the mirror
 * direction that holds them, and the bound a cluster's error is read against.
 *
 * Why a home of its own: the shader's current material reads it for its lights, and a material that
 * varies per vertex (methods/material_family.h) reads it for each vertex's own roughness, where
 * interpolating between two materials' highlights would blur a sun's.  It is cheap to make (a few
 * hundred evaluations), so a family's hundreds of roughness values each have one. */
#ifndef WENV_LIGHT_LOBES_H
#define WENV_LIGHT_LOBES_H

#include "base/error.h"
#include "methods/wavelet/lights.h"
#include "scene/material.h"

/* The specular albedo's samples, uniform in cos(view) from 0 to 1: what the lights' tolerance is
 * scaled by (a bound's scale, not a value shaded). */
#define WENV_LIGHT_LOBES_ALBEDO_N 17

typedef struct {
    const wenv_material *mat; /* not owned: it outlives this */
    int has_lobes;
    float *cos_h_min;         /* per lobe: below this n.h its D is negligible (< 1e-7 of its peak) */
    double cone_cos;          /* lights farther than this from the mirror direction miss every lobe */
    double alpha;             /* the narrowest lobe's width (how finely the lights are read) */
    int modelled;             /* mirror-centred lobes that follow their shapes (lights.h) */
    float peak[WENV_LIGHT_PEAK_SAMPLES + 1];                               /* modelled lobes */
    float *envelope; /* the others' bound: (WENV_LIGHT_PEAK_SAMPLES + 1) x WENV_LIGHT_ENVELOPE_BINS */
    float albedo[3 * WENV_LIGHT_LOBES_ALBEDO_N];
} wenv_light_lobes;

/* Made for mat (kept by the caller while this is used); on failure *lobes is freed. */
wenv_status wenv_light_lobes_make(wenv_light_lobes *lobes, const wenv_material *mat, wenv_error *err);
void wenv_light_lobes_free(wenv_light_lobes *lobes);

/* The walk's view of them (lights.h); narrow_alpha: the lighting's (wavelet.h). */
wenv_lights_lobe wenv_light_lobes_walk(const wenv_light_lobes *lobes, double narrow_alpha);

/* The specular albedo at cos(view) c, RGB summed, linear between samples. */
float wenv_light_lobes_albedo_sum(const wenv_light_lobes *lobes, float c);

#endif
