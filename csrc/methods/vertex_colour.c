/* A colour per vertex (vertex_colour.h). */
#include "methods/vertex_colour.h"

#include <math.h>

void wenv_vertex_colour_apply(const wenv_vertex_colour *colour, const float *normals, const float *views, size_t n,
                              const float *irradiance, float *out)
{
    long long nn = (long long)n;
#pragma omp parallel for schedule(static)
    for (long long i = 0; i < nn; i++) {
        float cos_v = 1.0f;
        if (views) {
            const float *a = normals + 3 * i, *b = views + 3 * i;
            float ab = a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
            float len = sqrtf((a[0] * a[0] + a[1] * a[1] + a[2] * a[2]) * (b[0] * b[0] + b[1] * b[1] + b[2] * b[2]));
            cos_v = len > 0.0f ? ab / len : 0.0f;
        }
        float d[3];
        wenv_diffuse_table_at(colour->per_colour, cos_v, d);
        const float *c = colour->rgb + 3 * i, *e = irradiance + 3 * i;
        float *o = out + 3 * i;
        for (int k = 0; k < 3; k++) {
            float v = o[k] + c[k] * d[k] * e[k];
            o[k] = v > 0.0f ? v : 0.0f;
        }
    }
}
