/* Which directions of each vertex's hemisphere the scene blocks: one bit per texel of an r x r
 * hemi-octahedral map in the vertex's frame (math/frame.h, math/maps.h), set where a ray from the
 * vertex through the texel's centre reaches the sky.  A vertex that sees its whole hemisphere holds
 * no mask at all, so a scene that blocks nothing (a convex mesh alone) costs one index a vertex --
 * unless it is made with point rays: then every vertex holds a mask, and the directions shading
 * reads as points (the exact lights, a narrow lobe's rays about its mirror direction) are always
 * cast as rays, never taken from the mask, which at a coarse side misses what stands between its
 * rays (a bake's texels, 4 x 4 rays each).
 * Depends on the mesh state only: a new World, view or material needs none made again. */
#ifndef WENV_OCCLUSION_H
#define WENV_OCCLUSION_H

#include <stddef.h>
#include <stdint.h>

#include "base/error.h"
#include "base/progress.h"
#include "scene/occluders.h"

/* The map's side r: 4 (16 directions, about 22 degrees a texel) to 16 (256, about 6 degrees). */
#define WENV_OCCLUSION_RESOLUTION_MIN 4
#define WENV_OCCLUSION_RESOLUTION_MAX 16

/* The resolution Auto picks for n vertices: the finest whose rays (n r^2) stay within
 * WENV_OCCLUSION_AUTO_RAYS, so that casting (or casting again after an edit) takes about the same
 * time whatever the mesh's size: 1.2 s on 2 cores for Suzanne's 126,290 vertices at 8 x 8, where
 * 16 x 16 took 4.2 s; 16 x 16 up to 32,768 vertices. */
#define WENV_OCCLUSION_AUTO_RAYS ((size_t)1 << 23)
size_t wenv_occlusion_auto_resolution(size_t n);

/* Where a blocked texel's ray meets the scene: the occluders' triangle and the hit's barycentric
 * weights of its second and third vertices in units of 1/65535, so that the light the blocker sends
 * (its vertices' bounce light) can be read there. */
typedef struct {
    uint32_t triangle;
    uint16_t u, v;
} wenv_occlusion_hit;

typedef struct {
    size_t resolution;  /* r */
    size_t n_vertices;
    size_t words;       /* 64-bit words per mask: ceil(r^2 / 64) */
    int32_t *slot;      /* per vertex: its mask's index, or -1 when it sees its whole hemisphere */
    uint64_t *masks;    /* n_masks x words; bit t (row-major texel) set: visible */
    size_t n_masks;
    size_t *hit_start;  /* n_masks + 1: mask k's blocked texels' hits are hits[hit_start[k] ..), texel order */
    wenv_occlusion_hit *hits;
    float *positions;   /* n x 3: the vertices the masks are for, as given */
    float *normals;     /* n x 3: their unit normals (the masks' frames) */
    uint64_t fingerprint; /* of all the above: what tells one occlusion from another */
    size_t cast_vertices; /* how many vertices' rays were cast to make it (all of them, unless refreshed) */
    int point_rays;       /* every vertex holds a mask; point-like directions are cast, not read from it */
    uint32_t *owner;      /* n_masks: the vertex whose rays made mask k, in whose frame it lies */
    int shared;           /* some vertices read another's mask (wenv_occlusion_make's masks_from) */
} wenv_occlusion;

/* The masks of n vertices (positions and normals as xyz floats; normals non-zero) against `occ`,
 * within the memory budget `occ` was made with (WENV_ERR_VALUE saying so when it would not fit);
 * `point_rays` as wenv_occlusion's.  masks_from (NULL: each vertex its own): vertex i reads the mask
 * of vertex masks_from[i], which reads its own, so that only those cast their masks' rays: the
 * neighbouring texels of a bake share one, each keeping its own position and normal, so its point
 * rays and frame (needs point_rays; WENV_ERR_VALUE naming "masks_from[i]" otherwise).
 * Rays start wenv_occluders_offset off the surface along the normal.  Progress
 * and cancel as base/progress.h.  WENV_ERR_VALUE for a resolution out of range or a normal that is
 * zero or not finite (naming "normals[i]"), or a position not finite ("positions[i]"). */
wenv_status wenv_occlusion_make(wenv_occlusion *out, const wenv_occluders *occ, const float *positions,
                                const float *normals, size_t n, size_t resolution, int point_rays,
                                const uint32_t *masks_from, const wenv_progress *progress, wenv_error *err);

/* The same after some triangles changed (an object moved, deformed, edited or removed), casting only
 * what the change can reach: `before` is the occlusion of these positions and normals against
 * `occluders_before`, whose triangles [first, first + count) changed; `occ` holds every other one of
 * them, in the same order with the same corners, and in their place those that are there now (any
 * number).  A vertex is cast again when one of its hits was on a changed triangle or one of its rays
 * meets a changed triangle as it is now before what it met (the changed triangles' bounds decide
 * most without a ray); the others keep their masks and hits.  The result is what
 * wenv_occlusion_make would give, with `cast_vertices` telling how many were cast (all of them when
 * the scene's lift changed, which moves every ray's start: wenv_occluders_offset).  WENV_ERR_VALUE
 * when `before` is of other positions or normals, shares masks, or a triangle outside the changed
 * ones differs. */
wenv_status wenv_occlusion_refresh(wenv_occlusion *out, const wenv_occlusion *before,
                                   const wenv_occluders *occluders_before, const wenv_occluders *occ,
                                   const float *positions, const float *normals, size_t n, size_t first,
                                   size_t count, const wenv_progress *progress, wenv_error *err);
/* `o` as if made with point rays: the same masks and hits, every vertex holding a mask (an open one
 * where `o` held none), so that shading casts its point-like directions; no ray is cast.  Its
 * fingerprint is o's marked as such.  WENV_ERR_VALUE when `o` shares masks (made with point rays). */
wenv_status wenv_occlusion_with_point_rays(wenv_occlusion *out, const wenv_occlusion *o, wenv_error *err);
void wenv_occlusion_free(wenv_occlusion *o);
/* The bytes it holds. */
size_t wenv_occlusion_bytes(const wenv_occlusion *o);

/* The triangle vertices' weights of a hit. */
static inline void wenv_occlusion_hit_weights(const wenv_occlusion_hit *h, float w[3])
{
    w[1] = (float)h->u * (1.0f / 65535.0f);
    w[2] = (float)h->v * (1.0f / 65535.0f);
    w[0] = 1.0f - w[1] - w[2];
}

/* Whether texel t (row-major, 0 .. r^2 - 1) of vertex i's map is visible. */
static inline int wenv_occlusion_visible(const wenv_occlusion *o, size_t i, size_t t)
{
    int32_t s = o->slot[i];
    return s < 0 || (int)((o->masks[(size_t)s * o->words + t / 64] >> (t % 64)) & 1u);
}

/* How many hits it holds: every blocked texel of every vertex. */
size_t wenv_occlusion_hit_count(const wenv_occlusion *o);

/* For each hit, in hit order (mask by mask, blocked texels in texel order): the vertex whose texel
 * it is (the mask's owner), and its ray's unit direction in the world (as it was cast), 3 floats. */
void wenv_occlusion_hit_rays(const wenv_occlusion *o, uint32_t *vertex, float *direction);

/* The unit direction, in the vertex's local frame (+Z the normal), through texel t's centre. */
void wenv_occlusion_texel_direction(size_t resolution, size_t t, double d[3]);

#endif
