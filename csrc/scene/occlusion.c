/* Per-vertex masks of the directions the scene blocks (occlusion.h). */
#include "scene/occlusion.h"

#include <math.h>
#include <omp.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>

#include "math/frame.h"
#include "math/maps.h"

void wenv_occlusion_texel_direction(size_t resolution, size_t t, double d[3])
{
    wenv_hemi_decode(wenv_map_texel_center(resolution, t % resolution), wenv_map_texel_center(resolution, t / resolution),
                     d);
}

void wenv_occlusion_free(wenv_occlusion *o)
{
    free(o->slot);
    free(o->masks);
    memset(o, 0, sizeof *o);
}

static int finite3(const float *v) { return isfinite(v[0]) && isfinite(v[1]) && isfinite(v[2]); }

wenv_status wenv_occlusion_make(wenv_occlusion *out, const wenv_occluders *occ, const float *positions,
                                const float *normals, size_t n, size_t resolution, const wenv_progress *progress,
                                wenv_error *err)
{
    memset(out, 0, sizeof *out);
    if (resolution < WENV_OCCLUSION_RESOLUTION_MIN || resolution > WENV_OCCLUSION_RESOLUTION_MAX)
        return wenv_error_set(err, WENV_ERR_VALUE, "resolution must be in [%d, %d], got %zu",
                              WENV_OCCLUSION_RESOLUTION_MIN, WENV_OCCLUSION_RESOLUTION_MAX, resolution);
    for (size_t i = 0; i < n; i++) {
        const float *p = positions + 3 * i, *m = normals + 3 * i;
        if (!finite3(p))
            return wenv_error_set(err, WENV_ERR_VALUE, "positions[%zu] is not finite", i);
        if (!finite3(m) || !(m[0] * m[0] + m[1] * m[1] + m[2] * m[2] > 0.0f))
            return wenv_error_set(err, WENV_ERR_VALUE, "normals[%zu] must be finite and non-zero", i);
    }
    size_t texels = resolution * resolution, words = (texels + 63) / 64;
    /* each vertex's mask where its own slot would be, compacted to the vertices that need one after */
    uint64_t *all = n ? calloc(n * words, sizeof *all) : NULL;
    int32_t *slot = malloc((n ? n : 1) * sizeof *slot);
    float *local = malloc(texels * 3 * sizeof *local);
    if ((n && !all) || !slot || !local || n > (size_t)INT32_MAX) {
        free(all);
        free(slot);
        free(local);
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for the occlusion of %zu vertices", n);
    }
    for (size_t t = 0; t < texels; t++) {
        double d[3];
        wenv_occlusion_texel_direction(resolution, t, d);
        for (int k = 0; k < 3; k++)
            local[3 * t + (size_t)k] = (float)d[k];
    }
    float lift = wenv_occluders_offset(occ);
    atomic_int failed = 0, cancelled = 0;
    atomic_size_t done = 0;
#pragma omp parallel
    {
        float *dirs = malloc(texels * 3 * sizeof *dirs);
        unsigned char *blocked = malloc(texels);
        if (!dirs || !blocked)
            atomic_store(&failed, 1);
#pragma omp for schedule(dynamic, 64)
        for (size_t i = 0; i < n; i++) {
            if (atomic_load(&failed) || atomic_load(&cancelled))
                continue;
            const float *p = positions + 3 * i, *m = normals + 3 * i;
            float len = sqrtf(m[0] * m[0] + m[1] * m[1] + m[2] * m[2]);
            double nn[3] = {m[0] / len, m[1] / len, m[2] / len}, f[9];
            wenv_frame(nn, f);
            for (size_t t = 0; t < texels; t++) { /* local (x, y, z) -> world: rows of f are the axes */
                const float *l = local + 3 * t;
                for (int k = 0; k < 3; k++)
                    dirs[3 * t + (size_t)k] = (float)(f[k] * l[0] + f[3 + k] * l[1] + f[6 + k] * l[2]);
            }
            float origin[3] = {p[0] + lift * (float)nn[0], p[1] + lift * (float)nn[1], p[2] + lift * (float)nn[2]};
            wenv_occluders_test(occ, origin, dirs, texels, INFINITY, blocked);
            int any = 0;
            uint64_t *mask = all + i * words;
            for (size_t t = 0; t < texels; t++) {
                any |= blocked[t];
                if (!blocked[t])
                    mask[t / 64] |= (uint64_t)1 << (t % 64);
            }
            slot[i] = any ? 0 : -1; /* numbered below */
            wenv_progress_item(progress, &done, n, &cancelled);
        }
        free(dirs);
        free(blocked);
    }
    free(local);
    if (failed || cancelled || wenv_progress_finish(progress)) {
        free(all);
        free(slot);
        return failed ? wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for the occlusion")
                      : wenv_error_set(err, WENV_ERR_CANCELLED, "occlusion cancelled");
    }
    size_t kept = 0;
    for (size_t i = 0; i < n; i++)
        if (slot[i] >= 0) {
            if (kept != i)
                memmove(all + kept * words, all + i * words, words * sizeof *all);
            slot[i] = (int32_t)kept++;
        }
    uint64_t *masks = kept ? realloc(all, kept * words * sizeof *all) : NULL;
    if (kept && !masks)
        masks = all; /* shrinking failed: keep the larger block */
    else if (!kept)
        free(all);
    *out = (wenv_occlusion){.resolution = resolution, .n_vertices = n, .words = words, .slot = slot,
                            .masks = masks, .n_masks = kept};
    return WENV_OK;
}
