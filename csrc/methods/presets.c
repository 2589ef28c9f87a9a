#include "methods/presets.h"

const char *const WENV_PRESET_NAMES[WENV_PRESET_COUNT] = {"draft", "default", "high"};

/* draft and default take out suns and lamps (pixels above 256x the mean radiance); high also takes
 * out every bright extended feature (above 8x the mean, up to 4096) -- what brings m >= 0.1 within
 * 1 % on the bundled HDRIs (docs/performance.md, "Speed against accuracy").  default and high integrate narrow
 * lobes at grazing views per vertex.  default is built for a view change within 30 ms at 126k
 * vertices and 3 % at m >= 0.2: high's local resolution (the per-view cost does not grow with it),
 * half its normal samples, its lights read to 5 % instead of 0.3 %, GGX lobes (Principled) on the
 * grazing path's slope cells; through slicing (its rotation matrices would take ~2.4 GB). */
#define DEFAULT_QUALITY                                                                                        \
    {.global_n = 128, .local_n = 64, .normal_n = 32, .view_n = 24, .coefficients = 512, .light_coefficients = 0, \
     .matrix_epsilon = 1e-4, .lights = 4096, .light_threshold = 256, .light_tolerance = 0.05, .grazing = 6,     \
     .grazing_slopes = 1, .lobe_rings = 4}
#define HIGH_QUALITY                                                                                           \
    {.global_n = 128, .local_n = 64, .normal_n = 64, .view_n = 32, .coefficients = 512, .light_coefficients = 0, \
     .matrix_epsilon = 1e-4, .lights = 4096, .light_threshold = 8, .light_tolerance = 0.003, .grazing = 6,      \
     .lobe_rings = 8}

const wenv_wavelet_quality WENV_WAVELET_PRESETS[WENV_PRESET_COUNT] = {
    [WENV_PRESET_DRAFT] = {.global_n = 32, .local_n = 16, .normal_n = 16, .view_n = 8, .coefficients = 32,
                           .light_coefficients = 256, .matrix_epsilon = 1e-3, .lights = 64,
                           .light_threshold = 256, .light_tolerance = 0.003, .grazing = 0},
    [WENV_PRESET_DEFAULT] = DEFAULT_QUALITY,
    [WENV_PRESET_HIGH] = HIGH_QUALITY,
};

const wenv_splitsum_quality WENV_SPLIT_SUM_PRESETS[WENV_PRESET_COUNT] = {
    [WENV_PRESET_DRAFT] = {.prefilter = 64, .samples = 64, .lut = 32},
    [WENV_PRESET_DEFAULT] = {.prefilter = 128, .samples = 256, .lut = 64},
    [WENV_PRESET_HIGH] = {.prefilter = 256, .samples = 512, .lut = 128},
};

const wenv_sh_shading_quality WENV_SH_PRESETS[WENV_PRESET_COUNT] = {
    [WENV_PRESET_DRAFT] = {.order = 4, .views = 16},
    [WENV_PRESET_DEFAULT] = {.order = 8, .views = 32},
    [WENV_PRESET_HIGH] = {.order = 16, .views = 64},
};

/* light_coefficients 0 (slicing keeps every term anyway); matrix_epsilon unused by slicing.  The
 * errors auto predicts for these levels are calibrated on exactly these settings
 * (auto/autoquality.c): change one and recalibrate.  Level 3 is the "default" preset: a first view
 * in about 60 % of level 4's time, a median error of 0.4-0.8 % at m = 0.05-0.2 where level 4's is
 * 1.9-5 %, but coarser for broad lobes and Lambert (half level 4's normal samples).  Level 5 is
 * default's per-vertex path with high's tables (64 normal samples, 32 views) and the bright extended
 * features taken out as exact lights (pixels above 16x the mean, read to 5 %): Lambert and
 * Cook-Torrance lobes from m = 0.1 up within 1 % under every bundled HDRI (benchmarks/accuracy.py:
 * 0.16 / 0.85 / 0.95 / 0.97 % worst at Lambert, m = 0.1, 0.2, 0.5) at 3-5x less time per view than
 * high, which reads its lights to 0.3 % and integrates lobes on 10x more grazing nodes.  Its lights'
 * walk is most of its cost where the bright features are large (courtyard's sunlit walls, studio's
 * softboxes).  The last level is "high". */
const wenv_wavelet_quality WENV_AUTO_LADDER[WENV_AUTO_LEVELS] = {
    {.global_n = 32, .local_n = 16, .normal_n = 16, .view_n = 8, .coefficients = 64, .light_coefficients = 0,
     .matrix_epsilon = 1e-3, .lights = 64, .light_threshold = 256, .light_tolerance = 0.003, .grazing = 0},
    {.global_n = 64, .local_n = 32, .normal_n = 32, .view_n = 16, .coefficients = 128, .light_coefficients = 0,
     .matrix_epsilon = 1e-3, .lights = 128, .light_threshold = 256, .light_tolerance = 0.003, .grazing = 0},
    {.global_n = 128, .local_n = 64, .normal_n = 32, .view_n = 16, .coefficients = 256, .light_coefficients = 0,
     .matrix_epsilon = 1e-4, .lights = 512, .light_threshold = 256, .light_tolerance = 0.003, .grazing = 0},
    DEFAULT_QUALITY,
    {.global_n = 128, .local_n = 64, .normal_n = 64, .view_n = 32, .coefficients = 512, .light_coefficients = 0,
     .matrix_epsilon = 1e-4, .lights = 1024, .light_threshold = 256, .light_tolerance = 0.003, .grazing = 0},
    {.global_n = 128, .local_n = 64, .normal_n = 64, .view_n = 32, .coefficients = 512, .light_coefficients = 0,
     .matrix_epsilon = 1e-4, .lights = 4096, .light_threshold = 16, .light_tolerance = 0.05, .grazing = 6,
     .grazing_slopes = 1, .lobe_rings = 4},
    HIGH_QUALITY,
};

const size_t WENV_AUTO_SH_ORDERS[WENV_AUTO_SH_ORDER_COUNT] = {2, 4, 6, 8, 10, 12, 14, 16};
