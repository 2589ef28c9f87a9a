/* Distant HDR environments: images in equirect, mirror-ball or cube-cross projection, read from
 * OpenEXR (OpenEXRCore) or Radiance RGBE files, looked up by world direction.
 *
 * Conventions (REFERENCE.md §5): world is right-handed, Z up.  Equirect: direction (x, y, z) maps to
 * u = 0.5 - atan2(y, x) / (2 pi), v = 0.5 + asin(z) / pi with v = 0 the bottom row.  `rotation` r
 * turns the environment about +Z as a Z rotation of Blender's World Mapping node does: world
 * direction d reads the image where R_z(r) d reads the unrotated image.  `strength` multiplies the
 * radiance.  Pixel rows are stored top row first. */
#ifndef WENV_ENVMAP_H
#define WENV_ENVMAP_H

#include <stddef.h>

#include "error.h"

typedef enum {
    WENV_PROJ_EQUIRECT = 0,
    WENV_PROJ_MIRROR_BALL = 1,
    WENV_PROJ_CUBE_CROSS = 2
} wenv_projection;

typedef struct wenv_envmap wenv_envmap;

/* Copies an H x W x C float image (C = 3 or 4, alpha ignored, row 0 the top).  Non-finite pixels
 * are rejected (WENV_ERR_VALUE naming "pixels"); negative values are clamped to 0.  Cube crosses
 * must be 3:4 (vertical) or 4:3 (horizontal). */
wenv_status wenv_envmap_create(wenv_envmap **out, const float *pixels, size_t height, size_t width,
                               size_t channels, wenv_projection projection, double rotation,
                               double strength, wenv_error *err);

/* Reads an OpenEXR or Radiance .hdr file (format from its magic bytes); WENV_ERR_IO naming the
 * file when it is missing, unreadable or corrupt. */
wenv_status wenv_envmap_load(wenv_envmap **out, const char *path, wenv_projection projection,
                             double rotation, double strength, wenv_error *err);

/* A copy with another rotation and strength, sharing nothing with the original. */
wenv_status wenv_envmap_with_transform(wenv_envmap **out, const wenv_envmap *env, double rotation,
                                       double strength, wenv_error *err);

void wenv_envmap_free(wenv_envmap *env);

size_t wenv_envmap_width(const wenv_envmap *env);
size_t wenv_envmap_height(const wenv_envmap *env);
wenv_projection wenv_envmap_projection(const wenv_envmap *env);
double wenv_envmap_rotation(const wenv_envmap *env);
double wenv_envmap_strength(const wenv_envmap *env);
/* The stored image, H x W x 3 floats, row 0 the top, before strength. */
const float *wenv_envmap_pixels(const wenv_envmap *env);

/* Radiance (strength applied) seen in world direction `dir` (unit), bilinear in the image. */
void wenv_envmap_lookup(const wenv_envmap *env, const double dir[3], float rgb[3]);

/* Every pixel that covers part of the sphere, as a point sample: world direction of its centre
 * (rotation applied), flux = radiance * strength * exact solid angle of the pixel, and (if omega
 * is not NULL) that solid angle.  `dirs` and `flux` hold room for 3 * width * height floats each,
 * `omega` for width * height; pixels outside the projection's domain (outside the mirror-ball
 * disk, the empty cells of a cube cross) are skipped, black pixels are not.  Returns the number
 * written.  The solid angles of all pixels sum to 4 pi. */
size_t wenv_envmap_samples(const wenv_envmap *env, float *dirs, float *flux, float *omega);

/* Exact solid angle of pixel (row, col) (0 outside the domain). */
double wenv_envmap_pixel_solid_angle(const wenv_envmap *env, size_t row, size_t col);

#endif
