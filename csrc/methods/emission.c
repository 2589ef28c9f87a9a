/* A material's own light, added (emission.h). */
#include "methods/emission.h"

#include <math.h>

#include "math/unit_pair.h"

/* The emission's view dependence is smooth (the layers' albedo over the view's cosine): a table
 * of 257 cosines, linear between them, serves every vertex. */
#define TABLE_N 257

wenv_status wenv_emission_add(const wenv_material *mat, const float *colours, const float *normals,
                              const float *views, size_t n, float *out, wenv_error *err)
{
    wenv_material *white = NULL;
    if (colours) { /* the emission per unit of Emission Color: the material emitting white */
        const wenv_principled_inputs *in = wenv_principled_inputs_of(mat);
        if (!in || in->emission_strength == 0.0)
            return WENV_OK;
        wenv_principled_inputs own = *in;
        own.emission_color[0] = own.emission_color[1] = own.emission_color[2] = 1.0;
        if (wenv_principled_create(&white, &own, err))
            return err->status;
        mat = white;
    }
    if (!wenv_material_emits(mat)) {
        wenv_material_free(white);
        return WENV_OK;
    }
    float table[3 * TABLE_N];
    for (size_t i = 0; i < TABLE_N; i++) {
        double rgb[3];
        wenv_material_emission_at(mat, (double)i / (TABLE_N - 1), rgb);
        for (int c = 0; c < 3; c++)
            table[3 * i + (size_t)c] = (float)rgb[c];
    }
    wenv_material_free(white);
    long long nn = (long long)n;
#pragma omp parallel for schedule(static)
    for (long long i = 0; i < nn; i++) {
        float cos_v = wenv_view_cosine(normals + 3 * i, views ? views + 3 * i : NULL);
        if (!(cos_v > 0.0f))
            continue; /* seen from behind: black, as the reflection */
        float x = (cos_v > 1.0f ? 1.0f : cos_v) * (float)(TABLE_N - 1);
        size_t k = (size_t)x < TABLE_N - 1 ? (size_t)x : TABLE_N - 2;
        float f = x - (float)k;
        for (int c = 0; c < 3; c++) {
            float e = (1.0f - f) * table[3 * k + (size_t)c] + f * table[3 * (k + 1) + (size_t)c];
            float v = out[3 * i + c] + e * (colours ? colours[3 * i + c] : 1.0f);
            out[3 * i + c] = v > 0.0f ? v : 0.0f;
        }
    }
    return WENV_OK;
}
