/* Jenkins' lookup3 hash (burtleburtle.net/bob/c/lookup3.c, public domain) on 1 to 4 words, as
 * Cycles hashes lattice points and seeds (its util/hash.h): the procedural textures' randomness. */
#ifndef WENV_LOOKUP3_H
#define WENV_LOOKUP3_H

#include <stdint.h>
#include <string.h>

static inline uint32_t wenv_lookup3_rot(uint32_t x, int k) { return (x << k) | (x >> (32 - k)); }

static inline void wenv_lookup3_mix(uint32_t *a, uint32_t *b, uint32_t *c)
{
    *a -= *c, *a ^= wenv_lookup3_rot(*c, 4), *c += *b;
    *b -= *a, *b ^= wenv_lookup3_rot(*a, 6), *a += *c;
    *c -= *b, *c ^= wenv_lookup3_rot(*b, 8), *b += *a;
    *a -= *c, *a ^= wenv_lookup3_rot(*c, 16), *c += *b;
    *b -= *a, *b ^= wenv_lookup3_rot(*a, 19), *a += *c;
    *c -= *b, *c ^= wenv_lookup3_rot(*b, 4), *b += *a;
}

static inline uint32_t wenv_lookup3_final(uint32_t a, uint32_t b, uint32_t c)
{
    c ^= b, c -= wenv_lookup3_rot(b, 14);
    a ^= c, a -= wenv_lookup3_rot(c, 11);
    b ^= a, b -= wenv_lookup3_rot(a, 25);
    c ^= b, c -= wenv_lookup3_rot(b, 16);
    a ^= c, a -= wenv_lookup3_rot(c, 4);
    b ^= a, b -= wenv_lookup3_rot(a, 14);
    c ^= b, c -= wenv_lookup3_rot(b, 24);
    return c;
}

/* The hash of d words k[0..d): lookup3's hashword of a d-word key, seed 13. */
static inline uint32_t wenv_lookup3(const uint32_t *k, int d)
{
    uint32_t a, b, c;
    a = b = c = 0xdeadbeefu + ((uint32_t)d << 2) + 13u;
    if (d == 4) {
        a += k[0], b += k[1], c += k[2];
        wenv_lookup3_mix(&a, &b, &c);
        a += k[3];
        return wenv_lookup3_final(a, b, c);
    }
    if (d >= 3)
        c += k[2];
    if (d >= 2)
        b += k[1];
    a += k[0];
    return wenv_lookup3_final(a, b, c);
}

static inline uint32_t wenv_float_bits(float f)
{
    uint32_t u;
    memcpy(&u, &f, sizeof u);
    return u;
}

/* The hash of d floats' bits as a float in [0, 1] (Cycles' hash_floatN_to_float). */
static inline float wenv_lookup3_unit(const float *k, int d)
{
    uint32_t w[4];
    for (int i = 0; i < d; i++)
        w[i] = wenv_float_bits(k[i]);
    return (float)wenv_lookup3(w, d) * (1.0f / (float)0xFFFFFFFFu);
}

#endif
