#include "methods/shade_budget.h"

#include <math.h>

#include "base/clock.h"

/* The first block is small, so that a step whose lighting slices and table rows are not made yet
 * (each vertex may need new ones) returns close to its budget; later blocks grow while they take
 * well under what is left of it. */
#define FIRST_BLOCK 256
#define LARGEST_BLOCK 65536

/* Rows of a larger call (rows, or offset + k when rows is NULL) from its at-th on. */
static void advance_rows(const uint32_t **rows, size_t *offset, size_t at)
{
    if (*rows)
        *rows += at;
    else
        *offset += at;
}

wenv_status wenv_shade_for(const wenv_lighting_frame *frame, const wenv_method *method, void *state,
                           const float *normals, const float *views, size_t n, const wenv_shadow_scene *scene,
                           const wenv_vertex_colour *colour, const wenv_family_rows *family,
                           const wenv_material *material, const float *emission, const wenv_lamp_rows *lamps,
                           size_t first, double budget, float *out, size_t *next, wenv_error *err)
{
    *next = first < n ? first : n;
    if (!(budget >= 0.0))
        return wenv_error_set(err, WENV_ERR_VALUE, "budget must be >= 0 seconds, got %g", budget);
    double start = wenv_now_seconds();
    /* without a budget, one block: one call reads every slice and row it needs (what a new lighting
     * remakes at once, wenv_wavelet_remake_ready), and makes those missing in one parallel pass */
    size_t at = *next, block = isinf(budget) ? n - at : FIRST_BLOCK;
    while (at < n) {
        size_t count = n - at < block ? n - at : block;
        double t0 = wenv_now_seconds();
        wenv_shadow_scene block_scene;
        if (scene) { /* the block's rows are the scene's from `at` on */
            block_scene = *scene;
            advance_rows(&block_scene.rows, &block_scene.offset, at);
        }
        wenv_vertex_colour block_colour;
        if (colour) {
            block_colour = *colour;
            block_colour.rgb = colour->rgb ? colour->rgb + 3 * at : NULL;
            block_colour.bump.smooth = colour->bump.smooth ? colour->bump.smooth + 3 * at : NULL;
        }
        wenv_family_rows block_family;
        if (family) {
            block_family = *family;
            advance_rows(&block_family.rows, &block_family.offset, at);
        }
        wenv_lamp_rows block_lamps;
        if (lamps) {
            block_lamps = *lamps;
            advance_rows(&block_lamps.rows, &block_lamps.offset, at);
        }
        if (wenv_lighting_frame_shade_scene(frame, method, state, normals + 3 * at, views + 3 * at, count,
                                            scene ? &block_scene : NULL, colour ? &block_colour : NULL,
                                            family ? &block_family : NULL, material,
                                            emission ? emission + 3 * at : NULL, lamps ? &block_lamps : NULL,
                                            out + 3 * at, err))
            return err->status;
        at += count;
        *next = at;
        double now = wenv_now_seconds(), left = budget - (now - start);
        if (!(left > 0.0))
            break;
        /* at the rate this block ran, a block twice its size would still leave half the budget */
        if (4.0 * (now - t0) < left && block < LARGEST_BLOCK)
            block *= 2;
    }
    return WENV_OK;
}
