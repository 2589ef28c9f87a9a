/* A material's own light, added (emission.h). */
#include "methods/emission.h"

#include <math.h>
#include <stdlib.h>

#include "math/unit_pair.h"

wenv_status wenv_emission_table_make(const wenv_material *mat, int per_colour, wenv_emission_table *table,
                                     wenv_error *err)
{
    wenv_material *white = NULL;
    table->emits = 0;
    if (per_colour) { /* the emission per unit of Emission Color: the material emitting white */
        const wenv_principled_inputs *in = wenv_principled_inputs_of(mat);
        if (!in || in->emission_strength == 0.0)
            return WENV_OK;
        wenv_principled_inputs own = *in;
        own.emission_color[0] = own.emission_color[1] = own.emission_color[2] = 1.0;
        if (wenv_principled_create(&white, &own, err))
            return err->status;
        mat = white;
    }
    if (wenv_material_emits(mat)) {
        table->emits = 1;
        for (size_t i = 0; i < WENV_EMISSION_TABLE_N; i++) {
            double rgb[3];
            wenv_material_emission_at(mat, (double)i / (WENV_EMISSION_TABLE_N - 1), rgb);
            for (int c = 0; c < 3; c++)
                table->rgb[3 * i + (size_t)c] = (float)rgb[c];
        }
    }
    wenv_material_free(white);
    return WENV_OK;
}

void wenv_emission_table_at(const wenv_emission_table *table, float cos_v, float rgb[3])
{
    float x = (cos_v > 1.0f ? 1.0f : (cos_v > 0.0f ? cos_v : 0.0f)) * (float)(WENV_EMISSION_TABLE_N - 1);
    size_t k = (size_t)x < WENV_EMISSION_TABLE_N - 1 ? (size_t)x : WENV_EMISSION_TABLE_N - 2;
    float f = x - (float)k;
    for (int c = 0; c < 3; c++)
        rgb[c] = (1.0f - f) * table->rgb[3 * k + (size_t)c] + f * table->rgb[3 * (k + 1) + (size_t)c];
}

wenv_status wenv_emission_add(const wenv_material *mat, const float *colours, const float *normals,
                              const float *views, size_t n, float *out, wenv_error *err)
{
    wenv_emission_table *table = malloc(sizeof *table);
    if (!table)
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for a material's emission");
    if (wenv_emission_table_make(mat, colours != NULL, table, err)) {
        free(table);
        return err->status;
    }
    long long nn = table->emits ? (long long)n : 0;
#pragma omp parallel for schedule(static)
    for (long long i = 0; i < nn; i++) {
        float cos_v = wenv_view_cosine(normals + 3 * i, views ? views + 3 * i : NULL);
        if (!(cos_v > 0.0f))
            continue; /* seen from behind: black, as the reflection */
        float e[3];
        wenv_emission_table_at(table, cos_v, e);
        for (int c = 0; c < 3; c++) {
            float v = out[3 * i + c] + e[c] * (colours ? colours[3 * i + c] : 1.0f);
            out[3 * i + c] = v > 0.0f ? v : 0.0f;
        }
    }
    free(table);
    return WENV_OK;
}
