/* IEEE 754 half precision (binary16) in portable C: what the grazing path's lighting pyramid is
 * stored in, so that a node's bilinear tap gathers one 64-bit word (r g b and a pad) instead of
 * three floats.  Half holds 11 significant bits (a relative rounding of at most 2^-11) over
 * 6e-5 to 65504 in normal numbers; callers scale their values into that range.  The conversion to
 * float is exact, so a loop that converts with the CPU's instructions (F16C, AVX-512) reads the same
 * floats as one that calls wenv_float_from_half. */
#ifndef WENV_HALF_H
#define WENV_HALF_H

#include <stdint.h>
#include <string.h>

/* The nearest half to f (ties to even); infinity past 65520, NaN kept a (quiet) NaN. */
static inline uint16_t wenv_half_from_float(float f)
{
    uint32_t x, sign;
    memcpy(&x, &f, sizeof x);
    sign = (x >> 16) & 0x8000u;
    x &= 0x7fffffffu;
    if (x >= 0x47800000u) /* 65536 and up, infinity, NaN */
        return (uint16_t)(sign | (x > 0x7f800000u ? 0x7e00u : 0x7c00u));
    if (x < 0x38800000u) {
        /* below half's smallest normal, 2^-14: adding 0.5 puts the 24-bit subnormal unit (2^-24) at
         * float's last mantissa bit, so the float addition rounds it (to even) */
        float v, magic = 0.5f;
        uint32_t y, m;
        memcpy(&v, &x, sizeof v);
        v += magic;
        memcpy(&y, &v, sizeof y);
        memcpy(&m, &magic, sizeof m);
        return (uint16_t)(sign | (y - m));
    }
    /* rebias the exponent, round the 13 dropped bits to nearest even (a carry may reach infinity) */
    uint32_t odd = (x >> 13) & 1u;
    x += ((uint32_t)(15 - 127) << 23) + 0xfffu + odd;
    return (uint16_t)(sign | (x >> 13));
}

/* h as a float, exactly. */
static inline float wenv_float_from_half(uint16_t h)
{
    uint32_t sign = (uint32_t)(h & 0x8000u) << 16, e = (h >> 10) & 0x1fu, m = h & 0x3ffu, x;
    if (e == 0) { /* zero or subnormal: m units of 2^-24 */
        float v = (float)m * 5.9604644775390625e-8f;
        return sign ? -v : v;
    }
    x = e == 31 ? (sign | 0x7f800000u | (m << 13)) : (sign | ((e + 112u) << 23) | (m << 13));
    float v;
    memcpy(&v, &x, sizeof v);
    return v;
}

#endif
