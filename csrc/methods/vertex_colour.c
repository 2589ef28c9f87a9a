/* A colour per vertex (vertex_colour.h). */
#include "methods/vertex_colour.h"

#include <math.h>

#include "math/unit_pair.h"

void wenv_vertex_colour_apply(const wenv_vertex_colour *colour, const float *normals, const float *views, size_t n,
                              const float *irradiance, float *out)
{
    long long nn = (long long)n;
#pragma omp parallel for schedule(static)
    for (long long i = 0; i < nn; i++) {
        float cos_v = wenv_view_cosine(normals + 3 * i, views ? views + 3 * i : NULL);
        float d[3];
        wenv_diffuse_table_at(colour->per_colour, cos_v, d);
        const float *e = irradiance + 3 * i;
        float *o = out + 3 * i;
        for (int k = 0; k < 3; k++) {
            float c = colour->rgb ? colour->rgb[3 * i + k] : 1.0f;
            float light = wenv_bent_light(e[k], colour->share, colour->horizon_light, (size_t)i, k);
            float v = o[k] + c * d[k] * light;
            o[k] = v > 0.0f ? v : 0.0f;
        }
    }
}
