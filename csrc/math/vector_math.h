/* What loops the compiler vectorises share: their CPU clones, texels padded to one vector, and
 * exp and erf in float: no library calls (a call stops a loop
 * from running several lanes per instruction), no branches, only arithmetic, selects and a bit
 * cast.  Relative error about 2e-7 for exp, absolute 1.5e-7 for erf (Abramowitz and Stegun 7.1.26),
 * against float's own 6e-8: well inside what the float evaluators promise (~1e-5). */
#ifndef WENV_VECTOR_MATH_H
#define WENV_VECTOR_MATH_H

#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

/* Loops written for the vectoriser are compiled for AVX-512, AVX2 and baseline x86-64, the best
 * chosen when the library loads (what ships is never built for one machine's CPU).  Sanitizer
 * builds and other compilers keep one baseline version. */
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__) && !defined(__SANITIZE_ADDRESS__)
#define WENV_VECTOR_CLONES __attribute__((target_clones("arch=x86-64-v4", "arch=x86-64-v3", "default")))
#else
#define WENV_VECTOR_CLONES
#endif

/* n r g b texels as r g b and a pad (4 floats, 16-byte aligned), so that a loop reads a texel as
 * one vector; NULL when out of memory.  The caller frees it. */
static inline float *wenv_rgbx_from_rgb(const float *rgb, size_t n)
{
    float *rgbx = aligned_alloc(4 * sizeof(float), (n ? n : 1) * 4 * sizeof(float));
    if (!rgbx)
        return NULL;
#pragma omp parallel for schedule(static) if (n > 65536)
    for (size_t t = 0; t < n; t++) {
        memcpy(rgbx + 4 * t, rgb + 3 * t, 3 * sizeof(float));
        rgbx[4 * t + 3] = 0.0f;
    }
    return rgbx;
}

/* e^x; 0 below -87 (e^-87 is near float's smallest normal), capped above 88. */
static inline float wenv_exp_vf(float x)
{
    float xc = x < -87.0f ? -87.0f : (x > 88.0f ? 88.0f : x);
    /* round to nearest by adding and taking away 1.5 x 2^23 (floorf is a call without SSE4.1) */
    float nf = (xc * 1.44269504088896341f + 12582912.0f) - 12582912.0f;
    /* x - n ln 2 in two parts (Cody and Waite), so the reduction loses nothing */
    float rr = xc - nf * 0.693359375f + nf * 2.12194440e-4f;
    float p = 1.0f + rr * (1.0f + rr * (0.5f + rr * (1.0f / 6.0f + rr * (1.0f / 24.0f + rr * (1.0f / 120.0f + rr * (1.0f / 720.0f))))));
    int32_t bits = ((int32_t)nf + 127) << 23;
    float scale;
    memcpy(&scale, &bits, sizeof scale);
    float y = p * scale;
    return x < -87.0f ? 0.0f : y;
}

/* erf(a) for a >= 0, given e = e^(-a^2) (callers need that too). */
static inline float wenv_erf_vf(float a, float e)
{
    float t = 1.0f / (1.0f + 0.3275911f * a);
    float poly = t * (0.254829592f + t * (-0.284496736f + t * (1.421413741f + t * (-1.453152027f + t * 1.061405429f))));
    return 1.0f - poly * e;
}

#endif
