/* What stands between a surface and its sky: triangle meshes in an Embree scene (the ray tracer
 * Cycles uses on CPUs), tested ray by ray.  Built once per mesh state; immutable afterwards, so any
 * number of threads may test rays at once. */
#ifndef WENV_OCCLUDERS_H
#define WENV_OCCLUDERS_H

#include <stddef.h>
#include <stdint.h>

#include "base/error.h"

typedef struct wenv_occluders wenv_occluders;

/* The scene of n_triangles triangles (three indices each into n_positions xyz float positions).
 * WENV_ERR_VALUE naming the first bad entry: a position not finite ("positions[i]"), an index past
 * the positions ("triangles[i]"), a triangle of zero area ("triangles[i] is degenerate"); or when the
 * scene would take more than memory_budget bytes (estimated before anything is built).  The data is
 * copied. */
wenv_status wenv_occluders_create(wenv_occluders **out, const float *positions, size_t n_positions,
                                  const uint32_t *triangles, size_t n_triangles, size_t memory_budget,
                                  wenv_error *err);
void wenv_occluders_free(wenv_occluders *occ);
/* About how many bytes occluders of that many positions and triangles take (what the memory budget
 * is held to). */
double wenv_occluders_bytes_needed(size_t n_positions, size_t n_triangles);

size_t wenv_occluders_triangle_count(const wenv_occluders *occ);
/* The positions the triangles index, and the triangles (3 indices each) as the scene holds them. */
size_t wenv_occluders_vertex_count(const wenv_occluders *occ);
const uint32_t *wenv_occluders_triangles(const wenv_occluders *occ);
const float *wenv_occluders_positions(const wenv_occluders *occ);
/* The memory budget it was made with, which each occlusion cast against it keeps to as well. */
size_t wenv_occluders_memory_budget(const wenv_occluders *occ);
/* Of its content (positions and triangles): what tells one scene from another. */
uint64_t wenv_occluders_fingerprint(const wenv_occluders *occ);
/* The diagonal of the scene's bounding box: what a ray's start is lifted off a surface by a
 * fraction of (wenv_occluders_offset), so that it does not hit the face it starts on. */
double wenv_occluders_size(const wenv_occluders *occ);
/* The lift: WENV_OCCLUDER_OFFSET times the size rounded up to a power of two, so that an object
 * moved within about the same bounds leaves every ray's start where it was (an occlusion made from
 * the one before then equals a new cast: occlusion.h). */
#define WENV_OCCLUDER_OFFSET 1e-4
float wenv_occluders_offset(const wenv_occluders *occ);

/* Whether anything blocks each of n rays from `origin` along the unit directions `dirs` (xyz floats)
 * before distance tfar (INFINITY: anywhere): blocked[k] = 1 or 0.  Thread-safe, no allocation. */
void wenv_occluders_test(const wenv_occluders *occ, const float origin[3], const float *dirs, size_t n, float tfar,
                         unsigned char *blocked);

/* The same with ray k ending at fars[k] (INFINITY: anywhere): the points of a lamp, tested at once. */
void wenv_occluders_test_until(const wenv_occluders *occ, const float origin[3], const float *dirs, const float *fars,
                               size_t n, unsigned char *blocked);
/* The same with ray k from its own origin (origins + 3 k): neighbouring points' rays to a lamp, one
 * stream.  On the calling thread, no allocation. */
void wenv_occluders_test_each(const wenv_occluders *occ, const float *origins, const float *dirs, const float *fars,
                              size_t n, unsigned char *blocked);

/* The nearest surface along each of n rays from `origin` (directions as wenv_occluders_test, no far
 * limit): tri[k] its triangle, or UINT32_MAX where the ray reaches the sky, and uv[2k], uv[2k + 1]
 * the hit's barycentric weights of the triangle's second and third vertices.  Thread-safe. */
void wenv_occluders_hit(const wenv_occluders *occ, const float origin[3], const float *dirs, size_t n, uint32_t *tri,
                        float *uv);
/* The same for n rays of their own origins (xyz floats each), on the calling thread: rays that run
 * side by side (neighbouring origins, the same direction) next to each other are traced together. */
void wenv_occluders_hit_rays(const wenv_occluders *occ, const float *origins, const float *dirs, size_t n,
                             uint32_t *tri, float *uv);

/* The same for n rays of their own origins (xyz floats each) that scatter (a hemisphere's from each
 * point), on the calling thread, in streams Embree sorts into packets.  No allocation. */
void wenv_occluders_test_scattered(const wenv_occluders *occ, const float *origins, const float *dirs, size_t n,
                                   float tfar, unsigned char *blocked);

/* The same for n rays of their own origins (xyz floats each), on every thread. */
void wenv_occluders_test_rays(const wenv_occluders *occ, const float *origins, const float *dirs, size_t n, float tfar,
                              unsigned char *blocked);

/* Calls visit(user, triangle) for each triangle whose bounds come within `radius` of `point` (some
 * farther ones too: visit decides), through Embree's point query.  Thread-safe. */
void wenv_occluders_near(const wenv_occluders *occ, const float point[3], float radius,
                         void (*visit)(void *user, size_t triangle), void *user);

#endif
