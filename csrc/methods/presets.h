/* Every shading setting wenv names, in one place (presets.c): each method's draft / default /
 * high presets, the ladder quality="auto" climbs, and the SH orders it may pick. */
#ifndef WENV_PRESETS_H
#define WENV_PRESETS_H

#include <stddef.h>

#include "methods/method.h"
#include "methods/sh/sh_shading.h"
#include "methods/splitsum/splitsum.h"
#include "methods/wavelet/wavelet.h"

extern const wenv_wavelet_quality WENV_WAVELET_PRESETS[WENV_PRESET_COUNT];
extern const wenv_splitsum_quality WENV_SPLIT_SUM_PRESETS[WENV_PRESET_COUNT];
extern const wenv_sh_shading_quality WENV_SH_PRESETS[WENV_PRESET_COUNT];

/* quality="auto" with lobes: method "slicing" at one of these, cheapest first (auto/autoquality.h). */
#define WENV_AUTO_LEVELS 7
extern const wenv_wavelet_quality WENV_AUTO_LADDER[WENV_AUTO_LEVELS];

/* quality="auto" without lobes: method "sh" at one of these orders (odd bands above 1 carry no
 * irradiance), with this many views (the lobe-less path has no BRDF slices to sample). */
#define WENV_AUTO_SH_ORDER_COUNT 8
extern const size_t WENV_AUTO_SH_ORDERS[WENV_AUTO_SH_ORDER_COUNT];
#define WENV_AUTO_SH_VIEWS 2

#endif
