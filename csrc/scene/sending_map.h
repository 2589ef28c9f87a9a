/* What a vertex sends towards each direction of its hemisphere, read where another vertex's ray
 * meets it: a blocker's light with its glossy part in the direction it leaves (the bounce per hit,
 * methods/method.h).  A vertex's map is side x side texels of a hemi-octahedral map (math/maps.h)
 * in its frame (math/frame.h), each the radiance it sends along the texel centre's direction; a
 * hit reads the maps of its triangle's corners towards the ray's start, bilinearly between texel
 * centres, weighed by the hit's barycentric weights. */
#ifndef WENV_SENDING_MAP_H
#define WENV_SENDING_MAP_H

#include <stddef.h>

#include "scene/occluders.h"
#include "scene/occlusion.h"

/* Maps of side 2 .. 64 (even, as math/maps.h's). */
#define WENV_SENDING_SIDE_MAX 64

/* The unit world direction of each texel centre of the maps of n vertices (normals: unit), texel by
 * texel: out[3 (t n + i) ..] for texel t of vertex i. */
void wenv_sending_directions(const float *normals, size_t n, size_t side, float *out);

/* What reaches each hit of o (hit order, 3 floats each) from the maps `sent` of the occluders'
 * vertices (`occ`, which o was cast against): sent[3 (v side^2 + t) ..] the radiance vertex v sends
 * along its texel t, in the frame of normals[v] (unit). */
void wenv_sending_read(const wenv_occlusion *o, const wenv_occluders *occ, const float *normals, const float *sent,
                       size_t side, float *out);

#endif
