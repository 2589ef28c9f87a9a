/* 64-bit FNV-1a fingerprints: what tells one input (an image, a material's data) from another
 * without keeping a copy of it to compare. */
#ifndef WENV_FINGERPRINT_H
#define WENV_FINGERPRINT_H

#include <stddef.h>
#include <stdint.h>
#include <string.h>

#define WENV_FINGERPRINT_START 0xcbf29ce484222325ull

/* h with the 64-bit word v folded in. */
static inline uint64_t wenv_fingerprint_word(uint64_t h, uint64_t v) { return (h ^ v) * 0x100000001b3ull; }

/* h with n floats folded in, a 32-bit word each (their bits: -0 and 0 differ). */
static inline uint64_t wenv_fingerprint_floats(uint64_t h, const float *x, size_t n)
{
    for (size_t i = 0; i < n; i++) {
        uint32_t w;
        memcpy(&w, x + i, sizeof w);
        h = wenv_fingerprint_word(h, w);
    }
    return h;
}

/* h with n doubles folded in, by their bits. */
static inline uint64_t wenv_fingerprint_doubles(uint64_t h, const double *x, size_t n)
{
    for (size_t i = 0; i < n; i++) {
        uint64_t w;
        memcpy(&w, x + i, sizeof w);
        h = wenv_fingerprint_word(h, w);
    }
    return h;
}

#endif
