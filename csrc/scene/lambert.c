/* Lambertian reflection, f = albedo / pi, as a material (material.h): the Lambertian part alone. */
#include "scene/material_kind.h"

/* No lobes: every entry of the interface takes its default (nothing reflected but the Lambertian
 * part, which material.c adds). */
static const wenv_material_kind LAMBERT = {
    .name = "lambert",
    .mirror_symmetric = 1,
    .smooth_limit = 1, /* no lobes: its smooth limit is itself */
};

wenv_status wenv_lambert_create(wenv_material **out, const double albedo[3], wenv_error *err)
{
    return wenv_material_alloc(out, &LAMBERT, albedo, NULL, 0, WENV_SHADOW_SMITH, err);
}
