/* Tangent frames of normals: the frame of Duff et al. 2017 / Frisvad 2012 without the sign flip, so
 * frames vary continuously over the sphere except at n = (0, 0, -1), where the formula's limit
 * along -X is taken (docs/ARCHITECTURE.md §3.1). */
#ifndef WENV_FRAME_H
#define WENV_FRAME_H

/* Frame rows: tangent, bitangent, normal (frame[0..2], frame[3..5], frame[6..8]); n unit length. */
void wenv_frame(const double n[3], double frame[9]);

#endif
