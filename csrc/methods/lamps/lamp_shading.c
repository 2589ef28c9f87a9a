#include "methods/lamps/lamp_shading.h"

#include <math.h>
#include <stdlib.h>

#include "math/unit_pair.h"

/* The lobes' albedo head-on over pi: what the diffuse light counts of them (method.h). */
static wenv_status lobes_head_on(const wenv_material *mat, float rgb[3], wenv_error *err)
{
    const double up[3] = {0.0, 0.0, 1.0};
    double sum[3] = {0.0, 0.0, 0.0};
    for (size_t l = 0; l < wenv_material_lobe_count(mat); l++) {
        double a[3];
        if (wenv_material_lobe_albedo(mat, l, up, 32, a, err))
            return err->status;
        for (int c = 0; c < 3; c++)
            sum[c] += a[c];
    }
    for (int c = 0; c < 3; c++)
        rgb[c] = (float)(sum[c] / M_PI);
    return WENV_OK;
}

wenv_status wenv_lamps_add(const wenv_lamp_rows *lamps, const wenv_material *mat, const wenv_vertex_colour *colour,
                           const wenv_family_rows *family, const float *normals, const float *views, size_t n,
                           float *out, wenv_error *err)
{
    if (!n || !wenv_lamp_light_lamps(lamps->light))
        return WENV_OK;
    float *irradiance = calloc(3 * n, sizeof(float));
    uint32_t *pick = family && views ? malloc(WENV_VERTEX_LIGHTS_PICKS * n * sizeof *pick) : NULL;
    float *weight = family && views ? malloc(3 * WENV_VERTEX_LIGHTS_PICKS * n * sizeof *weight) : NULL;
    wenv_status st = WENV_OK;
    if (!irradiance || (family && views && (!pick || !weight))) {
        st = wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for the lamps' light at %zu vertices", n);
        goto done;
    }
    wenv_vertex_lights own;
    if (family && views &&
        (st = wenv_material_family_own(family, normals, views, n, colour ? colour->rgb : NULL, pick, weight, &own, err)))
        goto done;
    /* a bent Lambertian part's lamps are weighed each in its direction (the caller's colour holds no
     * sky's share: wenv_lighting_frame_shade_scene sets that on its own copy) */
    const wenv_bump_normals *bump = colour && colour->bump.smooth ? &colour->bump : NULL;
    if ((st = wenv_lamp_light_shade(lamps, mat, family && views ? &own : NULL, normals, views, n, bump, out,
                                    irradiance, err)))
        goto done;
    if (!views) { /* the lobes' light sent back as diffuse */
        float lobes[3];
        if ((st = lobes_head_on(mat, lobes, err)))
            goto done;
        for (size_t i = 0; i < 3 * n; i++)
            out[i] += lobes[i % 3] * irradiance[i];
    }
    if (family) {
        st = wenv_material_family_add_diffuse(family, normals, views, n, colour ? colour->rgb : NULL, irradiance, out,
                                              err);
    } else if (colour) {
        wenv_vertex_colour_apply(colour, normals, views, n, irradiance, out);
    } else {
        wenv_diffuse_table table;
        wenv_material_diffuse_table(mat, &table);
        long long nn = (long long)n;
#pragma omp parallel for schedule(static) if (n > 4096)
        for (long long i = 0; i < nn; i++) {
            float d[3];
            wenv_diffuse_table_at(&table, wenv_view_cosine(normals + 3 * i, views ? views + 3 * i : NULL), d);
            for (int c = 0; c < 3; c++) {
                float v = out[3 * i + c] + d[c] * irradiance[3 * i + c];
                out[3 * i + c] = v > 0.0f ? v : 0.0f;
            }
        }
    }
done:
    free(irradiance);
    free(pick);
    free(weight);
    return st;
}
