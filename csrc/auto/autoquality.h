/* quality="auto": the cheapest shading setting whose error is predicted to meet a target.
 *
 * Settings form a ladder, cheapest first (each level costs more time per view and more memory than
 * the one below).  The error of each level was measured (benchmarks/auto_quality.py --calibrate) on
 * Blender's eight bundled HDRIs against the brute-force reference: a Lambertian material and
 * specular lobes of roughness 0.05, 0.1, 0.2 and 0.5, over random (normal, view) pairs with views
 * uniform on the hemisphere.  The prediction for a material and an environment is cheap:
 *
 *   - the lobe width: the measured error of the level, interpolated in log roughness at the
 *     narrowest lobe (clamped to the measured range; a material without lobes reads the Lambert
 *     column);
 *   - the environment, per level: the share of its flux the level's lights take (exact, so the
 *     relative error of the rest shrinks), the share in bright extended features the level leaves
 *     in the lighting (pixels above 16 times the mean radiance that are not its lights), which a
 *     wavelet map of a few degrees per texel resolves worst, and how far its lights' reflections
 *     dominate the reflected signal under the narrowest lobe (mean squares of the lights and of
 *     the rest over octahedral texels as wide as the lobe), which is what relative RMSE divides by.
 *
 * Level 3 is the "default" preset and the last level the "high" preset, so auto reaches high's
 * accuracy where the scene needs it.
 *
 * For glossy materials the chosen method is "slicing": at equal resolutions it shades a view
 * exactly as fast as "rotation" (both read the same table), it has no matrices to build or hold,
 * and it makes lighting slices only for the normal samples the mesh's vertices fall near.
 *
 * A material without lobes reflects the irradiance alone, which spherical harmonics of order L
 * give with an error known in advance: over normals uniform on the sphere, the relative RMSE is
 * sqrt(sum_{l > L} A_l^2 P_l / sum_l A_l^2 P_l), with A_l Lambert's clamped-cosine factors and P_l
 * the lighting's power in band l (Parseval).  One coarse projection of the lighting to band 20
 * gives every P_l; auto takes the lowest order in WENV_AUTO_SH_ORDERS meeting the target (method
 * "sh", whose lobe-less path reads a tabulated irradiance), and the slicing ladder only when even
 * the highest order cannot.
 *
 * Everything auto reads of the environment alone is made once per environment and kept
 * (wenv_auto_analysis: 8-14 ms for the slicing ladder, 9-10 ms for SH, on Blender's 1024 x 512
 * HDRIs); a choice then costs a fraction of a millisecond plus a pass over the mesh's normals when
 * given.  SH order 2 makes a first view in a few milliseconds, so choosing must cost far less for
 * auto to match it. */
#ifndef WENV_AUTOQUALITY_H
#define WENV_AUTOQUALITY_H

#include <stddef.h>

#include "base/error.h"
#include "methods/method.h"
#include "methods/presets.h"
#include "scene/envmap.h"
#include "scene/material.h"


/* Level `i` of the ladder (0 <= i < WENV_AUTO_LEVELS). */
const wenv_wavelet_quality *wenv_auto_level(size_t i);

/* Memory a level holds at most for shading (tables, BRDF slices, and lighting slices for
 * `used_normals` normal samples, or for all of them when used_normals is (size_t)-1), in bytes. */
size_t wenv_auto_level_bytes(size_t i, size_t used_normals);


/* How a level is predicted to fare under the environment and material (autoquality.c). */
typedef struct {
    double lights_share;    /* flux share of the pixels it shades as exact lights */
    double contrast;        /* flux share of the bright extended features it leaves in the lighting */
    double sun_contrast;    /* the same, left by the suns alone (its lights above 256x the mean) */
    double light_dominance; /* its lights' mean square over the rest's, under the narrowest lobe */
    double env_factor;      /* its error relative to its median over the bundled HDRIs */
    double predicted_error; /* relative RMSE */
} wenv_auto_level_estimate;

typedef struct {
    size_t sh_order;        /* > 0: method "sh" at this order (a material without lobes) */
    size_t level;           /* else the chosen ladder level (method "slicing") */
    const wenv_method *method;           /* what to shade with: WENV_METHOD_SH or WENV_METHOD_SLICING */
    wenv_wavelet_quality quality;        /* its quality (wenv_auto_choice_quality gives the right one) */
    wenv_sh_shading_quality sh_quality;
    double predicted_error; /* relative RMSE predicted at that level */
    double head_on;         /* the lobes' albedo head-on over theirs at 80 degrees (autoquality.c) */
    wenv_auto_level_estimate levels[WENV_AUTO_LEVELS]; /* every level's (not filled for "sh") */
    int met;                /* whether some level within the budget is predicted to meet the target */
    size_t level_bytes;     /* the chosen level's memory, as counted against the budget */
    size_t used_normals;    /* its normal samples the mesh's normals fall near ((size_t)-1: all) */
    double seconds;         /* what choosing took (with analysing the environment, when it did) */
    double analysis_seconds; /* what analysing the environment took in this choice (0: all it needed was made) */
} wenv_auto_choice;

/* What auto reads of an environment whatever the material (its brightest pixels, the lighting
 * without them as a small octahedral pyramid, its bright extended features, its power per SH band),
 * made part by part as choices on it first need them and kept, so that choosing again for another
 * material or target costs well under a millisecond.  Safe to share between threads choosing on
 * the same environment, which must outlive it. */
typedef struct wenv_auto_analysis wenv_auto_analysis;

wenv_status wenv_auto_analysis_create(wenv_auto_analysis **out, const wenv_envmap *env, wenv_error *err);
void wenv_auto_analysis_free(wenv_auto_analysis *an);

/* The cheapest level whose predicted error is at most `target` and whose memory is at most
 * `memory_budget` bytes; when none is predicted to meet the target, the most accurate level within
 * the budget (met = 0).  `normals` (n x 3 floats, may be NULL) are the mesh's: a level's lighting
 * slices are then counted only for the normal samples they fall near, as shading makes only those
 * (a flat floor needs a handful, a sphere all).  target in (0, 1]; WENV_ERR_VALUE when even the
 * cheapest level exceeds the budget.  `analysis` is `env`'s, its parts made here as needed (NULL: a
 * new one, freed here). */
wenv_status wenv_auto_choose(const wenv_envmap *env, wenv_auto_analysis *analysis, const wenv_material *mat,
                             double target, size_t memory_budget, const float *normals, size_t n,
                             wenv_auto_choice *out, wenv_error *err);

/* The chosen method's quality struct (choice->method's). */
const void *wenv_auto_choice_quality(const wenv_auto_choice *choice);

#endif
