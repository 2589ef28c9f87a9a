/* Per-vertex masks of the directions the scene blocks (occlusion.h). */
#include "scene/occlusion.h"

#include <math.h>
#include <omp.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>

#include "base/fingerprint.h"
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
    free(o->hit_start);
    free(o->hits);
    free(o->positions);
    free(o->normals);
    memset(o, 0, sizeof *o);
}

size_t wenv_occlusion_bytes(const wenv_occlusion *o)
{
    return o->n_vertices * (sizeof *o->slot + 6 * sizeof(float)) + o->n_masks * (o->words * 8 + sizeof(size_t)) +
           (o->n_masks ? o->hit_start[o->n_masks] : 0) * sizeof *o->hits;
}

static int finite3(const float *v) { return isfinite(v[0]) && isfinite(v[1]) && isfinite(v[2]); }

/* Vertices cast per block: their hits are gathered in a block-sized buffer, then compacted. */
#define BLOCK_VERTICES 2048

/* Appends `count` hits to the growing array; -1 out of memory, -2 over `budget` hits. */
static int append_hits(wenv_occlusion *o, size_t *cap, const wenv_occlusion_hit *h, size_t count, size_t budget)
{
    size_t used = o->hit_start[o->n_masks];
    if (used + count > budget)
        return -2;
    if (used + count > *cap) {
        size_t grown = (used + count) * 3 / 2 + 1024;
        wenv_occlusion_hit *more = realloc(o->hits, grown * sizeof *more);
        if (!more)
            return -1;
        o->hits = more;
        *cap = grown;
    }
    memcpy(o->hits + used, h, count * sizeof *h);
    return 0;
}

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
    if (n > (size_t)INT32_MAX)
        return wenv_error_set(err, WENV_ERR_VALUE, "too many vertices (%zu)", n);
    size_t texels = resolution * resolution, words = (texels + 63) / 64;
    size_t block = n < BLOCK_VERTICES ? (n ? n : 1) : BLOCK_VERTICES;
    /* what every vertex holds whatever it sees, and the hits (those of the blocked texels) the rest
     * of the budget leaves room for */
    double fixed = (double)n * (sizeof(int32_t) + 6 * sizeof(float) + sizeof(size_t) + words * 8) +
                   (double)block * texels * (sizeof(wenv_occlusion_hit) + 1);
    double budget = (double)wenv_occluders_memory_budget(occ);
    if (fixed > budget)
        return wenv_error_set(err, WENV_ERR_VALUE,
                              "the occlusion of %zu vertices needs at least %.0f MB, over the memory budget of %.0f MB",
                              n, fixed / 1048576.0, budget / 1048576.0);
    size_t hit_budget = (size_t)((budget - fixed) / sizeof(wenv_occlusion_hit));
    wenv_occlusion o = {.resolution = resolution, .n_vertices = n, .words = words};
    o.slot = malloc((n ? n : 1) * sizeof *o.slot);
    o.masks = malloc((n ? n : 1) * words * sizeof *o.masks); /* shrunk to the masks kept after */
    o.hit_start = malloc(((n ? n : 1) + 1) * sizeof *o.hit_start);
    o.positions = malloc((n ? n : 1) * 3 * sizeof *o.positions);
    o.normals = malloc((n ? n : 1) * 3 * sizeof *o.normals);
    wenv_occlusion_hit *block_hits = malloc(block * texels * sizeof *block_hits);
    unsigned short *block_count = malloc(block * sizeof *block_count);
    uint64_t *block_masks = malloc(block * words * sizeof *block_masks);
    float *local = malloc(texels * 3 * sizeof *local);
    if (!o.slot || !o.masks || !o.hit_start || !o.positions || !o.normals || !block_hits || !block_count ||
        !block_masks || !local) {
        free(block_hits);
        free(block_count);
        free(block_masks);
        free(local);
        wenv_occlusion_free(&o);
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for the occlusion of %zu vertices", n);
    }
    if (n)
        memcpy(o.positions, positions, n * 3 * sizeof(float));
    o.hit_start[0] = 0;
    for (size_t t = 0; t < texels; t++) {
        double d[3];
        wenv_occlusion_texel_direction(resolution, t, d);
        for (int k = 0; k < 3; k++)
            local[3 * t + (size_t)k] = (float)d[k];
    }
    float lift = wenv_occluders_offset(occ);
    size_t cap = 0;
    atomic_int failed = 0, cancelled = 0;
    atomic_size_t done = 0;
    int over = 0;
    for (size_t first = 0; first < n && !failed && !cancelled; first += block) {
        size_t count = n - first < block ? n - first : block;
#pragma omp parallel
        {
            float *dirs = malloc(texels * 3 * sizeof *dirs), *uv = malloc(texels * 2 * sizeof *uv);
            uint32_t *tri = malloc(texels * sizeof *tri);
            if (!dirs || !uv || !tri)
                atomic_store(&failed, 1);
#pragma omp for schedule(dynamic, 64)
            for (size_t b = 0; b < count; b++) {
                if (atomic_load(&failed) || atomic_load(&cancelled))
                    continue;
                size_t i = first + b;
                const float *p = positions + 3 * i, *m = normals + 3 * i;
                float len = sqrtf(m[0] * m[0] + m[1] * m[1] + m[2] * m[2]);
                double nn[3] = {m[0] / len, m[1] / len, m[2] / len}, f[9];
                for (int k = 0; k < 3; k++)
                    o.normals[3 * i + (size_t)k] = (float)nn[k];
                wenv_frame(nn, f);
                for (size_t t = 0; t < texels; t++) { /* local (x, y, z) -> world: rows of f are the axes */
                    const float *l = local + 3 * t;
                    for (int k = 0; k < 3; k++)
                        dirs[3 * t + (size_t)k] = (float)(f[k] * l[0] + f[3 + k] * l[1] + f[6 + k] * l[2]);
                }
                float origin[3] = {p[0] + lift * (float)nn[0], p[1] + lift * (float)nn[1], p[2] + lift * (float)nn[2]};
                wenv_occluders_hit(occ, origin, dirs, texels, tri, uv);
                uint64_t *mask = block_masks + b * words;
                memset(mask, 0, words * sizeof *mask);
                wenv_occlusion_hit *h = block_hits + b * texels;
                unsigned short nh = 0;
                for (size_t t = 0; t < texels; t++) {
                    if (tri[t] == UINT32_MAX) {
                        mask[t / 64] |= (uint64_t)1 << (t % 64);
                        continue;
                    }
                    float u = uv[2 * t] < 0.0f ? 0.0f : (uv[2 * t] > 1.0f ? 1.0f : uv[2 * t]);
                    float v = uv[2 * t + 1] < 0.0f ? 0.0f : (uv[2 * t + 1] > 1.0f - u ? 1.0f - u : uv[2 * t + 1]);
                    h[nh++] = (wenv_occlusion_hit){.triangle = tri[t], .u = (uint16_t)lrintf(u * 65535.0f),
                                                   .v = (uint16_t)lrintf(v * 65535.0f)};
                }
                block_count[b] = nh;
                wenv_progress_item(progress, &done, n, &cancelled);
            }
            free(dirs);
            free(uv);
            free(tri);
        }
        /* kept in vertex order: a vertex with no blocked texel keeps no mask */
        for (size_t b = 0; b < count && !failed; b++) {
            size_t i = first + b;
            if (!block_count[b]) {
                o.slot[i] = -1;
                continue;
            }
            int appended = append_hits(&o, &cap, block_hits + b * texels, block_count[b], hit_budget);
            if (appended < 0) {
                over = appended == -2;
                atomic_store(&failed, 1);
                break;
            }
            memcpy(o.masks + o.n_masks * words, block_masks + b * words, words * sizeof *o.masks);
            o.slot[i] = (int32_t)o.n_masks;
            o.hit_start[o.n_masks + 1] = o.hit_start[o.n_masks] + block_count[b];
            o.n_masks++;
        }
    }
    free(block_hits);
    free(block_count);
    free(block_masks);
    free(local);
    if (failed || cancelled || wenv_progress_finish(progress)) {
        int nomem = failed;
        wenv_occlusion_free(&o);
        if (over)
            return wenv_error_set(err, WENV_ERR_VALUE,
                                  "the occlusion of %zu vertices outgrew the memory budget of %.0f MB (its blocked "
                                  "texels' hits): raise memory_budget_mb or lower the resolution",
                                  n, budget / 1048576.0);
        return nomem ? wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for the occlusion")
                     : wenv_error_set(err, WENV_ERR_CANCELLED, "occlusion cancelled");
    }
    /* the blocks were sized for every vertex: give back what the kept masks do not use */
    uint64_t *masks = realloc(o.masks, (o.n_masks ? o.n_masks : 1) * words * sizeof *o.masks);
    if (masks)
        o.masks = masks;
    size_t *starts = realloc(o.hit_start, (o.n_masks + 1) * sizeof *o.hit_start);
    if (starts)
        o.hit_start = starts;
    uint64_t h = wenv_fingerprint_word(WENV_FINGERPRINT_START, resolution);
    h = wenv_fingerprint_word(wenv_fingerprint_word(h, n), wenv_occluders_triangle_count(occ));
    for (size_t k = 0; k < o.n_masks * words; k++)
        h = wenv_fingerprint_word(h, o.masks[k]);
    for (size_t k = 0; k < o.hit_start[o.n_masks]; k++)
        h = wenv_fingerprint_word(h, ((uint64_t)o.hits[k].triangle << 32) | ((uint64_t)o.hits[k].u << 16) | o.hits[k].v);
    h = wenv_fingerprint_floats(h, o.positions, 3 * n);
    o.fingerprint = wenv_fingerprint_floats(h, o.normals, 3 * n);
    *out = o;
    return WENV_OK;
}
