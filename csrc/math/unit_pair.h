/* A (normal, view) pair as the shading calls take them -- float xyz triples of any length -- read
 * into unit doubles: what every per-pair loop over normals and views starts with. */
#ifndef WENV_UNIT_PAIR_H
#define WENV_UNIT_PAIR_H

#include <math.h>
#include <stddef.h>

/* Pair i of the arrays, each vector divided by its length (non-zero: the callers check). */
static inline void wenv_unit_pair(const float *normals, const float *views, size_t i, double n[3], double v[3])
{
    for (int c = 0; c < 3; c++) {
        n[c] = normals[3 * i + (size_t)c];
        v[c] = views[3 * i + (size_t)c];
    }
    double ln = sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    double lv = sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
    for (int c = 0; c < 3; c++) {
        n[c] /= ln;
        v[c] /= lv;
    }
}

/* The cosine between a normal n and a view v (float triples of any non-zero length), in float for
 * the per-vertex passes after shading; 1 (head-on) without a view. */
static inline float wenv_view_cosine(const float *n, const float *v)
{
    if (!v)
        return 1.0f;
    float len = sqrtf((n[0] * n[0] + n[1] * n[1] + n[2] * n[2]) * (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]));
    return len > 0.0f ? (n[0] * v[0] + n[1] * v[1] + n[2] * v[2]) / len : 0.0f;
}

#endif
