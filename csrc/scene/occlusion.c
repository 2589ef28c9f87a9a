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

size_t wenv_occlusion_hit_count(const wenv_occlusion *o)
{
    return o->n_masks ? o->hit_start[o->n_masks] : 0;
}

void wenv_occlusion_hit_rays(const wenv_occlusion *o, uint32_t *vertex, float *direction)
{
    size_t r = o->resolution, texels = r * r;
    for (size_t s = 0; s < o->n_masks; s++) {
        size_t i = o->owner[s], h = o->hit_start[s];
        double n[3] = {o->normals[3 * i], o->normals[3 * i + 1], o->normals[3 * i + 2]}, f[9];
        wenv_frame(n, f);
        for (size_t t = 0; t < texels; t++) {
            if (wenv_occlusion_visible(o, i, t))
                continue;
            double d[3];
            wenv_occlusion_texel_direction(r, t, d);
            vertex[h] = (uint32_t)i;
            for (int k = 0; k < 3; k++) /* local (x, y, z) -> world: rows of f are the axes, as the rays were cast */
                direction[3 * h + (size_t)k] = (float)(f[k] * d[0] + f[3 + k] * d[1] + f[6 + k] * d[2]);
            h++;
        }
    }
}

size_t wenv_occlusion_auto_resolution(size_t n)
{
    size_t r = WENV_OCCLUSION_RESOLUTION_MAX;
    while (r > WENV_OCCLUSION_RESOLUTION_MIN && n * r * r > WENV_OCCLUSION_AUTO_RAYS)
        r--;
    return r;
}

void wenv_occlusion_free(wenv_occlusion *o)
{
    free(o->slot);
    free(o->masks);
    free(o->hit_start);
    free(o->hits);
    free(o->positions);
    free(o->normals);
    free(o->owner);
    memset(o, 0, sizeof *o);
}

size_t wenv_occlusion_bytes(const wenv_occlusion *o)
{
    return o->n_vertices * (sizeof *o->slot + 6 * sizeof(float)) +
           o->n_masks * (o->words * 8 + sizeof(size_t) + sizeof *o->owner) +
           (o->n_masks ? o->hit_start[o->n_masks] : 0) * sizeof *o->hits;
}

static int finite3(const float *v) { return isfinite(v[0]) && isfinite(v[1]) && isfinite(v[2]); }

/* Vertices cast per block: their hits are gathered in a block-sized buffer, then compacted. */
#define BLOCK_VERTICES 2048
/* Vertices traced together: enough for GROUP_RAYS rays, and at least GROUP_VERTICES (measured on
 * Suzanne's 126k vertices: 8 x 8 masks cast fastest in fours, 16 x 16 in fours, a bake's 4 x 4 in
 * sixteens).  More cost a refresh, which traces a group whole when one of its vertices changed. */
#define GROUP_RAYS 256
#define GROUP_VERTICES 4

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

/* What remaking an occlusion after some triangles changed knows: the occlusion before, the changed
 * triangles' ids then, the changed triangles alone as they are now, and the bounds of both. */
typedef struct {
    const wenv_occlusion *before;
    const wenv_occluders *occluders_before;
    const wenv_occluders *changed; /* the changed triangles as they are now (NULL: none are left) */
    size_t first, end_before;      /* the changed triangles' ids before: [first, end_before) */
    long long shift;               /* added to the ids of those after them */
    float lo[3], hi[3];            /* the changed triangles' bounds, before and now */
} refresh_plan;

/* Whether any point of the box lo..hi lies above the plane through `origin` normal to n. */
static int box_above(const float lo[3], const float hi[3], const float origin[3], const double n[3])
{
    double reach = 0.0; /* the largest n.(x - origin) over the box: at the corner n points to */
    for (int k = 0; k < 3; k++)
        reach += n[k] * ((n[k] > 0.0 ? hi[k] : lo[k]) - origin[k]);
    return reach > 0.0;
}

/* How far from `origin` a hit before lies: its triangle's point at its (rounded) weights. */
static float hit_distance(const wenv_occluders *occ, const wenv_occlusion_hit *h, const float origin[3])
{
    const float *p = wenv_occluders_positions(occ);
    const uint32_t *tri = wenv_occluders_triangles(occ) + 3 * (size_t)h->triangle;
    float w[3], d2 = 0.0f;
    wenv_occlusion_hit_weights(h, w);
    for (int k = 0; k < 3; k++) {
        float x = w[0] * p[3 * (size_t)tri[0] + (size_t)k] + w[1] * p[3 * (size_t)tri[1] + (size_t)k] +
                  w[2] * p[3 * (size_t)tri[2] + (size_t)k] - origin[k];
        d2 += x * x;
    }
    return sqrtf(d2);
}

/* Whether vertex i's rays may see a change: one of its hits was on a changed triangle, or one of its
 * rays meets a changed triangle as it is now before what it met then.  Those nearly tied with their
 * hit before are counted in (a far limit 0.1 % long), so what is kept is what a new cast gives. */
static int sees_a_change(const refresh_plan *rp, size_t i, const float origin[3], const double n[3], const float *dirs,
                         size_t texels, float lift)
{
    const wenv_occlusion *b = rp->before;
    int32_t s = b->slot[i];
    const wenv_occlusion_hit *h = s >= 0 ? b->hits + b->hit_start[s] : NULL;
    size_t nh = s >= 0 ? b->hit_start[s + 1] - b->hit_start[s] : 0;
    for (size_t k = 0; k < nh; k++)
        if (h[k].triangle >= rp->first && h[k].triangle < rp->end_before)
            return 1;
    if (!rp->changed || !box_above(rp->lo, rp->hi, origin, n))
        return 0;
    const uint64_t *mask = s >= 0 ? b->masks + (size_t)s * b->words : NULL;
    size_t k = 0;
    for (size_t t = 0; t < texels; t++) {
        float tfar = INFINITY;
        if (mask && !((mask[t / 64] >> (t % 64)) & 1u))
            tfar = hit_distance(rp->occluders_before, &h[k++], origin) * 1.001f + lift;
        unsigned char blocked;
        wenv_occluders_test(rp->changed, origin, dirs + 3 * t, 1, tfar, &blocked);
        if (blocked)
            return 1;
    }
    return 0;
}

/* Vertex i's mask and hits as they were, the ids after the changed ones shifted; returns the hits. */
static unsigned short keep_vertex(const refresh_plan *rp, size_t i, uint64_t *mask, wenv_occlusion_hit *out)
{
    const wenv_occlusion *b = rp->before;
    int32_t s = b->slot[i];
    if (s < 0) {
        for (size_t w = 0; w < b->words; w++)
            mask[w] = ~(uint64_t)0;
        return 0;
    }
    memcpy(mask, b->masks + (size_t)s * b->words, b->words * sizeof *mask);
    size_t nh = b->hit_start[s + 1] - b->hit_start[s];
    for (size_t k = 0; k < nh; k++) {
        out[k] = b->hits[b->hit_start[s] + k];
        if (out[k].triangle >= rp->end_before)
            out[k].triangle = (uint32_t)((long long)out[k].triangle + rp->shift);
    }
    return (unsigned short)nh;
}

/* Casts (or, refreshing, keeps where nothing it sees changed) every vertex's mask. */
static wenv_status cast(wenv_occlusion *out, const wenv_occluders *occ, const float *positions, const float *normals,
                        size_t n, size_t resolution, int point_rays, const uint32_t *masks_from,
                        const refresh_plan *refresh, const wenv_progress *progress, wenv_error *err)
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
    for (size_t i = 0; masks_from && i < n; i++) {
        if (!point_rays)
            return wenv_error_set(err, WENV_ERR_VALUE, "masks_from needs point_rays: a vertex reading another's "
                                                       "mask casts its own point-like directions");
        if (masks_from[i] >= n || masks_from[masks_from[i]] != masks_from[i])
            return wenv_error_set(err, WENV_ERR_VALUE,
                                  "masks_from[%zu] must be a vertex (below %zu) that reads its own mask, got %u", i, n,
                                  (unsigned)masks_from[i]);
    }
    size_t texels = resolution * resolution, words = (texels + 63) / 64;
    size_t block = n < BLOCK_VERTICES ? (n ? n : 1) : BLOCK_VERTICES;
    size_t group = GROUP_RAYS / texels > GROUP_VERTICES ? GROUP_RAYS / texels : GROUP_VERTICES;
    /* what every vertex holds whatever it sees, and the hits (those of the blocked texels) the rest
     * of the budget leaves room for */
    double fixed = (double)n * (sizeof(int32_t) + 6 * sizeof(float) + sizeof(size_t) + sizeof(uint32_t) +
                                words * 8) +
                   (double)block * texels * (sizeof(wenv_occlusion_hit) + 1);
    double budget = (double)wenv_occluders_memory_budget(occ);
    if (fixed > budget)
        return wenv_error_set(err, WENV_ERR_VALUE,
                              "the occlusion of %zu vertices needs at least %.0f MB, over the memory budget of %.0f MB",
                              n, fixed / 1048576.0, budget / 1048576.0);
    size_t hit_budget = (size_t)((budget - fixed) / sizeof(wenv_occlusion_hit));
    wenv_occlusion o = {.resolution = resolution, .n_vertices = n, .words = words, .point_rays = point_rays};
    o.slot = malloc((n ? n : 1) * sizeof *o.slot);
    o.masks = malloc((n ? n : 1) * words * sizeof *o.masks); /* shrunk to the masks kept after */
    o.hit_start = malloc(((n ? n : 1) + 1) * sizeof *o.hit_start);
    o.positions = malloc((n ? n : 1) * 3 * sizeof *o.positions);
    o.normals = malloc((n ? n : 1) * 3 * sizeof *o.normals);
    o.owner = malloc((n ? n : 1) * sizeof *o.owner); /* shrunk as the masks are */
    wenv_occlusion_hit *block_hits = malloc(block * texels * sizeof *block_hits);
    unsigned short *block_count = malloc(block * sizeof *block_count);
    uint64_t *block_masks = malloc(block * words * sizeof *block_masks);
    float *local = malloc(texels * 3 * sizeof *local);
    if (!o.slot || !o.masks || !o.hit_start || !o.positions || !o.normals || !o.owner || !block_hits || !block_count ||
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
    atomic_size_t done = 0, recast = 0;
    int over = 0;
    for (size_t first = 0; first < n && !failed && !cancelled; first += block) {
        size_t count = n - first < block ? n - first : block;
#pragma omp parallel
        {
            /* a vertex's directions, and its group's rays: neighbouring vertices' rays in one
             * direction run side by side, traced together */
            float *dirs = malloc(group * texels * 3 * sizeof *dirs), *origins = malloc(group * 3 * sizeof *origins);
            float *ray_dirs = malloc(group * texels * 3 * sizeof *ray_dirs);
            float *ray_origins = malloc(group * texels * 3 * sizeof *ray_origins);
            float *uv = malloc(group * texels * 2 * sizeof *uv);
            uint32_t *tri = malloc(group * texels * sizeof *tri);
            size_t *traced = malloc(group * sizeof *traced);
            if (!dirs || !origins || !ray_dirs || !ray_origins || !uv || !tri || !traced)
                atomic_store(&failed, 1);
#pragma omp for schedule(dynamic, 4)
            for (size_t g = 0; g < (count + group - 1) / group; g++) {
                if (atomic_load(&failed) || atomic_load(&cancelled))
                    continue;
                size_t b0 = g * group, b_end = b0 + group < count ? b0 + group : count, m = 0, recasting = 0;
                for (size_t b = b0; b < b_end; b++) {
                    size_t i = first + b;
                    const float *p = positions + 3 * i, *nm = normals + 3 * i;
                    float len = sqrtf(nm[0] * nm[0] + nm[1] * nm[1] + nm[2] * nm[2]);
                    double nn[3] = {nm[0] / len, nm[1] / len, nm[2] / len}, f[9];
                    for (int k = 0; k < 3; k++)
                        o.normals[3 * i + (size_t)k] = (float)nn[k];
                    if (masks_from && masks_from[i] != i) { /* it reads another's mask */
                        wenv_progress_item(progress, &done, n, &cancelled);
                        continue;
                    }
                    wenv_frame(nn, f);
                    float *d = dirs + m * texels * 3, *origin = origins + 3 * m;
                    for (size_t t = 0; t < texels; t++) { /* local (x, y, z) -> world: rows of f are the axes */
                        const float *l = local + 3 * t;
                        for (int k = 0; k < 3; k++)
                            d[3 * t + (size_t)k] = (float)(f[k] * l[0] + f[3 + k] * l[1] + f[6 + k] * l[2]);
                    }
                    for (int k = 0; k < 3; k++)
                        origin[k] = p[k] + lift * (float)nn[k];
                    /* a ray's answer may depend on those it is traced with (which of two triangles it
                     * meets on their common edge), so a group is always traced whole, as a first cast
                     * traces it, and a refresh keeps what it need not cast again */
                    if (refresh && !sees_a_change(refresh, i, origin, nn, d, texels, lift)) {
                        block_count[b] = keep_vertex(refresh, i, block_masks + b * words, block_hits + b * texels);
                        wenv_progress_item(progress, &done, n, &cancelled);
                        traced[m++] = SIZE_MAX;
                        continue;
                    }
                    recasting++;
                    traced[m++] = b;
                }
                if (!recasting)
                    continue;
                for (size_t t = 0; t < texels; t++)
                    for (size_t j = 0; j < m; j++)
                        for (int k = 0; k < 3; k++) {
                            ray_dirs[3 * (t * m + j) + (size_t)k] = dirs[3 * (j * texels + t) + (size_t)k];
                            ray_origins[3 * (t * m + j) + (size_t)k] = origins[3 * j + (size_t)k];
                        }
                wenv_occluders_hit_rays(occ, ray_origins, ray_dirs, m * texels, tri, uv);
                atomic_fetch_add(&recast, recasting);
                for (size_t j = 0; j < m; j++) {
                    size_t b = traced[j];
                    if (b == SIZE_MAX)
                        continue;
                    uint64_t *mask = block_masks + b * words;
                    wenv_occlusion_hit *h = block_hits + b * texels;
                    memset(mask, 0, words * sizeof *mask);
                    unsigned short nh = 0;
                    for (size_t t = 0; t < texels; t++) {
                        size_t r = t * m + j;
                        if (tri[r] == UINT32_MAX) {
                            mask[t / 64] |= (uint64_t)1 << (t % 64);
                            continue;
                        }
                        float u = uv[2 * r] < 0.0f ? 0.0f : (uv[2 * r] > 1.0f ? 1.0f : uv[2 * r]);
                        float v = uv[2 * r + 1] < 0.0f ? 0.0f : (uv[2 * r + 1] > 1.0f - u ? 1.0f - u : uv[2 * r + 1]);
                        h[nh++] = (wenv_occlusion_hit){.triangle = tri[r], .u = (uint16_t)lrintf(u * 65535.0f),
                                                       .v = (uint16_t)lrintf(v * 65535.0f)};
                    }
                    block_count[b] = nh;
                    wenv_progress_item(progress, &done, n, &cancelled);
                }
            }
            free(dirs);
            free(origins);
            free(ray_dirs);
            free(ray_origins);
            free(uv);
            free(tri);
            free(traced);
        }
        /* kept in vertex order: a vertex with no blocked texel keeps no mask.  A cancel leaves the
         * block's later counts unwritten, so nothing of a cancelled block is kept. */
        for (size_t b = 0; b < count && !failed && !cancelled; b++) {
            size_t i = first + b;
            if (masks_from && masks_from[i] != i)
                continue; /* its slot is its mask's, once all are kept */
            if (!block_count[b] && !point_rays) {
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
            o.owner[o.n_masks] = (uint32_t)i;
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
    for (size_t i = 0; masks_from && i < n; i++)
        if (masks_from[i] != i) {
            o.slot[i] = o.slot[masks_from[i]];
            o.shared = 1;
        }
    /* the blocks were sized for every vertex: give back what the kept masks do not use */
    uint64_t *masks = realloc(o.masks, (o.n_masks ? o.n_masks : 1) * words * sizeof *o.masks);
    if (masks)
        o.masks = masks;
    size_t *starts = realloc(o.hit_start, (o.n_masks + 1) * sizeof *o.hit_start);
    if (starts)
        o.hit_start = starts;
    uint32_t *owners = realloc(o.owner, (o.n_masks ? o.n_masks : 1) * sizeof *o.owner);
    if (owners)
        o.owner = owners;
    uint64_t h = wenv_fingerprint_word(WENV_FINGERPRINT_START, resolution);
    h = wenv_fingerprint_word(h, (uint64_t)point_rays);
    h = wenv_fingerprint_word(wenv_fingerprint_word(h, n), wenv_occluders_triangle_count(occ));
    for (size_t k = 0; k < o.n_masks * words; k++)
        h = wenv_fingerprint_word(h, o.masks[k]);
    for (size_t k = 0; k < o.hit_start[o.n_masks]; k++)
        h = wenv_fingerprint_word(h, ((uint64_t)o.hits[k].triangle << 32) | ((uint64_t)o.hits[k].u << 16) | o.hits[k].v);
    for (size_t i = 0; o.shared && i < n; i++)
        h = wenv_fingerprint_word(h, (uint64_t)(uint32_t)o.slot[i]);
    h = wenv_fingerprint_floats(h, o.positions, 3 * n);
    o.fingerprint = wenv_fingerprint_floats(h, o.normals, 3 * n);
    o.cast_vertices = atomic_load(&recast);
    *out = o;
    return WENV_OK;
}

wenv_status wenv_occlusion_make(wenv_occlusion *out, const wenv_occluders *occ, const float *positions,
                                const float *normals, size_t n, size_t resolution, int point_rays,
                                const uint32_t *masks_from, const wenv_progress *progress, wenv_error *err)
{
    return cast(out, occ, positions, normals, n, resolution, point_rays, masks_from, NULL, progress, err);
}

wenv_status wenv_occlusion_with_point_rays(wenv_occlusion *out, const wenv_occlusion *o, wenv_error *err)
{
    memset(out, 0, sizeof *out);
    if (o->shared)
        return wenv_error_set(err, WENV_ERR_VALUE, "the occlusion shares masks: it was made with point rays");
    size_t n = o->n_vertices, words = o->words, texels = o->resolution * o->resolution;
    size_t hits = wenv_occlusion_hit_count(o), rows = n ? n : 1;
    wenv_occlusion c = {.resolution = o->resolution, .n_vertices = n, .words = words, .point_rays = 1, .n_masks = n};
    c.slot = malloc(rows * sizeof *c.slot);
    c.masks = malloc(rows * words * sizeof *c.masks);
    c.hit_start = malloc((n + 1) * sizeof *c.hit_start);
    c.hits = malloc((hits ? hits : 1) * sizeof *c.hits);
    c.positions = malloc(rows * 3 * sizeof *c.positions);
    c.normals = malloc(rows * 3 * sizeof *c.normals);
    c.owner = malloc(rows * sizeof *c.owner);
    if (!c.slot || !c.masks || !c.hit_start || !c.hits || !c.positions || !c.normals || !c.owner) {
        wenv_occlusion_free(&c);
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for the occlusion of %zu vertices", n);
    }
    memcpy(c.positions, o->positions, n * 3 * sizeof(float));
    memcpy(c.normals, o->normals, n * 3 * sizeof(float));
    if (hits) /* kept in vertex order, as the masks are */
        memcpy(c.hits, o->hits, hits * sizeof *c.hits);
    c.hit_start[0] = 0;
    for (size_t i = 0; i < n; i++) {
        uint64_t *mask = c.masks + i * words;
        int32_t s = o->slot[i];
        c.slot[i] = (int32_t)i;
        c.owner[i] = (uint32_t)i;
        if (s >= 0) {
            memcpy(mask, o->masks + (size_t)s * words, words * sizeof *mask);
            c.hit_start[i + 1] = c.hit_start[i] + (o->hit_start[s + 1] - o->hit_start[s]);
            continue;
        }
        memset(mask, 0, words * sizeof *mask); /* every texel open, as a cast sets them */
        for (size_t t = 0; t < texels; t++)
            mask[t / 64] |= (uint64_t)1 << (t % 64);
        c.hit_start[i + 1] = c.hit_start[i];
    }
    c.fingerprint = wenv_fingerprint_word(o->fingerprint, 0x706f696e74ull); /* "point" */
    *out = c;
    return WENV_OK;
}

/* Grows lo..hi to hold triangles [first, first + count) of occ. */
static void add_bounds(const wenv_occluders *occ, size_t first, size_t count, float lo[3], float hi[3])
{
    const float *p = wenv_occluders_positions(occ);
    const uint32_t *t = wenv_occluders_triangles(occ) + 3 * first;
    for (size_t k = 0; k < 3 * count; k++)
        for (int c = 0; c < 3; c++) {
            float x = p[3 * (size_t)t[k] + (size_t)c];
            lo[c] = x < lo[c] ? x : lo[c];
            hi[c] = x > hi[c] ? x : hi[c];
        }
}

/* Whether triangle a of occ_a and b of occ_b have the same corners (bit for bit). */
static int same_triangle(const wenv_occluders *occ_a, size_t a, const wenv_occluders *occ_b, size_t b)
{
    const float *pa = wenv_occluders_positions(occ_a), *pb = wenv_occluders_positions(occ_b);
    const uint32_t *ta = wenv_occluders_triangles(occ_a) + 3 * a, *tb = wenv_occluders_triangles(occ_b) + 3 * b;
    for (int k = 0; k < 3; k++)
        if (memcmp(pa + 3 * (size_t)ta[k], pb + 3 * (size_t)tb[k], 3 * sizeof(float)))
            return 0;
    return 1;
}

wenv_status wenv_occlusion_refresh(wenv_occlusion *out, const wenv_occlusion *before,
                                   const wenv_occluders *occluders_before, const wenv_occluders *occ,
                                   const float *positions, const float *normals, size_t n, size_t first,
                                   size_t count, const wenv_progress *progress, wenv_error *err)
{
    memset(out, 0, sizeof *out);
    size_t total_before = wenv_occluders_triangle_count(occluders_before), total = wenv_occluders_triangle_count(occ);
    if (first > total_before || count > total_before - first)
        return wenv_error_set(err, WENV_ERR_VALUE, "changed triangles [%zu, %zu) are not among the %zu before", first,
                              first + count, total_before);
    if (total + count < total_before)
        return wenv_error_set(err, WENV_ERR_VALUE,
                              "the occluders have %zu triangles: fewer than the %zu outside the changed ones", total,
                              total_before - count);
    if (before->shared)
        return wenv_error_set(err, WENV_ERR_VALUE, "previous shares masks between vertices: cast it anew");
    if (before->n_vertices != n || memcmp(before->positions, positions, n * 3 * sizeof(float)))
        return wenv_error_set(err, WENV_ERR_VALUE, "previous was made for other positions: cast the occlusion anew");
    for (size_t i = 0; i < n; i++) {
        const float *m = normals + 3 * i, *u = before->normals + 3 * i;
        float len = sqrtf(m[0] * m[0] + m[1] * m[1] + m[2] * m[2]);
        if (!(len > 0.0f) || (float)(m[0] / len) != u[0] || (float)(m[1] / len) != u[1] || (float)(m[2] / len) != u[2])
            return wenv_error_set(err, WENV_ERR_VALUE, "previous was made for other normals (normals[%zu]): cast the "
                                                       "occlusion anew", i);
    }
    size_t count_now = total + count - total_before, end_before = first + count;
    for (size_t k = 0; k < total_before; k++) {
        if (k == first)
            k = end_before;
        if (k >= total_before)
            break;
        size_t now = k < first ? k : k - count + count_now;
        if (!same_triangle(occluders_before, k, occ, now))
            return wenv_error_set(err, WENV_ERR_VALUE,
                                  "triangle %zu before is not triangle %zu now, and is outside the changed ones [%zu, "
                                  "%zu): cast the occlusion anew", k, now, first, end_before);
    }
    /* rays start off the surface by a fraction of the scene's size: another size moves every start,
     * and only a new cast gives what a new cast gives */
    if (wenv_occluders_offset(occ) != wenv_occluders_offset(occluders_before))
        return cast(out, occ, positions, normals, n, before->resolution, before->point_rays, NULL, NULL, progress,
                    err);
    refresh_plan plan = {.before = before, .occluders_before = occluders_before, .first = first,
                         .end_before = end_before, .shift = (long long)count_now - (long long)count,
                         .lo = {INFINITY, INFINITY, INFINITY}, .hi = {-INFINITY, -INFINITY, -INFINITY}};
    add_bounds(occluders_before, first, count, plan.lo, plan.hi);
    add_bounds(occ, first, count_now, plan.lo, plan.hi);
    wenv_occluders *changed = NULL;
    if (count_now) {
        /* the changed triangles alone, to test each ray against them only */
        if (wenv_occluders_create(&changed, wenv_occluders_positions(occ), wenv_occluders_vertex_count(occ),
                                  wenv_occluders_triangles(occ) + 3 * first, count_now,
                                  wenv_occluders_memory_budget(occ), err))
            return err->status;
        plan.changed = changed;
    }
    wenv_status st =
        cast(out, occ, positions, normals, n, before->resolution, before->point_rays, NULL, &plan, progress, err);
    wenv_occluders_free(changed);
    return st;
}
