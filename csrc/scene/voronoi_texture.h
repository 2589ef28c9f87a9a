/* Blender's Voronoi Texture node, evaluated at points as Cycles' SVM evaluates it
 * (intern/cycles/kernel/svm/voronoi.h): a jittered point per lattice cell, hashed by lookup3; the
 * distance to the nearest (F1), second nearest (F2) or a smooth blend of them (Smooth F1), the
 * distance to the cells' edges, or the radius of the sphere a point's cell holds; summed over
 * octaves as Cycles' fractal Voronoi sums them. */
#ifndef WENV_VORONOI_TEXTURE_H
#define WENV_VORONOI_TEXTURE_H

#include <stddef.h>

#include "base/error.h"
#include "base/progress.h"

/* node.feature and node.distance, in Cycles' order */
typedef enum {
    WENV_VORONOI_F1 = 0,
    WENV_VORONOI_F2,
    WENV_VORONOI_SMOOTH_F1,
    WENV_VORONOI_DISTANCE_TO_EDGE,
    WENV_VORONOI_N_SPHERE_RADIUS,
} wenv_voronoi_feature;
typedef enum {
    WENV_VORONOI_EUCLIDEAN = 0,
    WENV_VORONOI_MANHATTAN,
    WENV_VORONOI_CHEBYCHEV,
    WENV_VORONOI_MINKOWSKI,
} wenv_voronoi_metric;

/* The node's settings and unlinked inputs, under Blender's names. */
typedef struct {
    int dimensions; /* 1 (W alone) to 4 (x, y, z, W) */
    wenv_voronoi_feature feature;
    wenv_voronoi_metric metric;
    int normalize;
    float scale, detail, roughness, lacunarity, smoothness, exponent, randomness;
    int lookup3_cells; /* hash 2D to 4D cells as Blender did before 5.0 (lookup3), not by PCG */
} wenv_voronoi_settings;

/* At n points (`vectors`, n x 3; NULL for 1D; W w[i], or w0 where w is NULL): the node's Distance
 * (distance[i]; its Radius for N-Sphere Radius) and, where colour is not NULL, its Color
 * (colour[3 i ..]; black for the distance to edge and the radius, as Cycles gives them) and, where
 * position is not NULL, the cell's point (position[4 i ..]: x, y, z and W, 0 where the dimensions
 * have none, as are they for the distance to edge and the radius; its Position and W outputs).
 * Reports to `progress` (NULL: none), which may cancel.  ValueError for a setting out of range. */
wenv_status wenv_voronoi_texture(const wenv_voronoi_settings *settings, const float *vectors, const float *w,
                                 float w0, size_t n, float *distance, float *colour, float *position,
                                 const wenv_progress *progress, wenv_error *err);

#endif
