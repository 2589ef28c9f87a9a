/* Which vertices a viewport sees, so that shading skips the rest.
 *
 * A vertex is seen when its normal faces the eye (n . (eye - p) > 0) and, given the viewport's
 * view-projection matrix, its position lies inside the view frustum (clip coordinates within
 * -w..w on every axis, w > 0: OpenGL's clip volume, which Blender's perspective_matrix maps to).
 * Back-facing vertices and vertices off screen are then exactly the ones skipped. */
#ifndef WENV_VISIBILITY_H
#define WENV_VISIBILITY_H

#include <stddef.h>

/* positions, normals: n x 3 floats; view_projection: 4 x 4 doubles, row-major (clip = M (p, 1)),
 * or NULL for the facing test alone.  Writes visible[i] = 1 or 0 and returns how many are 1.
 * Runs in parallel (OpenMP) for large n. */
size_t wenv_visible_vertices(const float *positions, const float *normals, size_t n, const double eye[3],
                             const double *view_projection, unsigned char *visible);

#endif
