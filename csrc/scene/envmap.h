/* Distant HDR environments: images in equirect, mirror-ball or cube-cross projection, read from
 * OpenEXR (OpenEXRCore) or Radiance RGBE files, looked up by world direction.
 *
 * Conventions (docs/ARCHITECTURE.md §3.4): world is right-handed, Z up.  Equirect: direction (x, y, z) maps to
 * u = 0.5 - atan2(y, x) / (2 pi), v = 0.5 + asin(z) / pi with v = 0 the bottom row.  `rotation` r
 * turns the environment about +Z as a Z rotation of Blender's World Mapping node does: world
 * direction d reads the image where R_z(r) d reads the unrotated image.  `strength` multiplies the
 * radiance.  Pixel rows are stored top row first.
 *
 * Mirror ball: Cycles' Mirror Ball projection.  The disk inscribed in the image holds a mirrored
 * sphere photographed from -Y looking along +Y: the disk centre sees -Y (back at the camera), the
 * rim sees +Y, the top of the disk +Z and its right-hand side +X.  It is equal-area (solid angle =
 * 4 x area in disk coordinates [-1, 1]^2); rim pixels count the exact part inside the disk.
 *
 * Cube cross: the cube unfolded as seen from inside, in the usual cross layout, with the horizontal
 * strip a continuous, unmirrored panorama that agrees with the equirect convention (+Y, +X, -Y, -X
 * from left to right, like u = 0.125 .. 1.125 of an equirect image), +Z above and -Z below +X:
 *
 *     horizontal (4:3)          vertical (3:4)
 *         [+Z]                      [+Z]
 *     [+Y][+X][-Y][-X]          [+Y][+X][-Y]
 *         [-Z]                      [-Z]
 *                                   [-X]   (upside down: it continues the column past -Z)
 *
 * In each face the image's right and down directions (R, D) are, with face centre C:
 *   +X: R = -Y, D = -Z    +Y: R = +X, D = -Z    -Y: R = -X, D = -Z    -X: R = +Y, D = -Z
 *   +Z: R = -Y, D = +X    -Z: R = -Y, D = -X    -X of the vertical cross: R = -Y, D = +Z
 * so face coordinates (s, t) in [-1, 1]^2 (s right, t down) look along C + s R + t D.  Empty cells
 * of the cross are outside the domain. */
#ifndef WENV_ENVMAP_H
#define WENV_ENVMAP_H

#include <stddef.h>
#include <stdint.h>

#include "base/error.h"

typedef enum {
    WENV_PROJ_EQUIRECT = 0,
    WENV_PROJ_MIRROR_BALL = 1,
    WENV_PROJ_CUBE_CROSS = 2
} wenv_projection;

typedef struct wenv_envmap wenv_envmap;

/* The largest radiance (a pixel times strength) an environment may hold.  Shading works in float32
 * (up to 3.4e38) and squares Haar coefficients to rank them, so 1e18 leaves room for sums over
 * thousands of pixels and lobe peaks of 1e6; a sun in physical units is below 1e10.  More is a
 * WENV_ERR_VALUE (an argument) or WENV_ERR_IO (a file). */
#define WENV_RADIANCE_MAX 1e18

/* Copies an H x W x C float image (C = 3 or 4, alpha ignored, row 0 the top).  Non-finite pixels
 * are rejected (WENV_ERR_VALUE naming "pixels"); negative values are clamped to 0.  Cube crosses
 * must be 3:4 (vertical) or 4:3 (horizontal). */
wenv_status wenv_envmap_create(wenv_envmap **out, const float *pixels, size_t height, size_t width,
                               size_t channels, wenv_projection projection, double rotation,
                               double strength, wenv_error *err);

/* Reads an OpenEXR or Radiance .hdr file (format from its magic bytes); WENV_ERR_IO naming the
 * file when it is missing, unreadable or corrupt, non-finite pixels included (WENV_ERR_VALUE for a
 * cube cross of the wrong aspect).  OpenEXR: first part, scanline or tiled (level 0), half or float
 * R, G, B (or Y) channels, decoded by OpenEXRCore; DWAA/DWAB, which OpenEXRCore 3.1 cannot
 * decompress, go through OpenEXR's C interface to its C++ library (ImfCRgbaFile.h, loaded with
 * dlopen).  Radiance: FORMAT=32-bit_rle_rgbe, '-Y H +X W', flat, old-style or new-style RLE
 * scanlines, decoded as mantissa * 2^(e - 136) like Blender; EXPOSURE is ignored, as Blender does. */
wenv_status wenv_envmap_load(wenv_envmap **out, const char *path, wenv_projection projection,
                             double rotation, double strength, wenv_error *err);

/* A copy with another rotation and strength.  It shares the image with the original (an image is
 * never changed once made; the last environment freed frees it), so it costs no pixels. */
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

/* Radiance (strength applied) seen in world direction `dir` (unit; normalised here anyway, a zero
 * vector reads +Z), bilinear in the image.  Equirect wraps horizontally and clamps at the poles; a
 * cube cross reads across face edges from the neighbouring face; a mirror ball ignores pixels
 * outside the disk. */
void wenv_envmap_lookup(const wenv_envmap *env, const double dir[3], float rgb[3]);

/* The same without interpolation: the radiance of the pixel whose area holds `dir` -- the lighting
 * as wenv_envmap_samples' pixels carry it, piecewise constant (Cycles' "Closest" interpolation). */
void wenv_envmap_lookup_nearest(const wenv_envmap *env, const double dir[3], float rgb[3]);

/* A lobe of roughness (alpha) below this many pixel angles is narrower than about two pixels: its
 * reflection of a pixel depends on where in the pixel it falls, so wenv_reference integrates it by
 * its own rule over the pixels' areas and the exact lights integrate those areas too. */
#define WENV_NARROW_LOBE_PIXELS 2.0

/* A pixel's angular size in radians, about (the equirect row height; for other projections the
 * side of a square of the mean pixel solid angle). */
double wenv_envmap_pixel_angle(const wenv_envmap *env);

/* Every pixel that covers part of the sphere, as a point sample: world direction of its centre
 * (rotation applied), flux = radiance * strength * exact solid angle of the pixel, and (if omega
 * is not NULL) that solid angle.  `dirs` and `flux` hold room for 3 * width * height floats each,
 * `omega` for width * height; pixels outside the projection's domain (outside the mirror-ball
 * disk, the empty cells of a cube cross) are skipped, black pixels are not.  Returns the number
 * written.  The solid angles of all pixels sum to 4 pi. */
size_t wenv_envmap_samples(const wenv_envmap *env, float *dirs, float *flux, float *omega);

/* wenv_envmap_samples for one image row, into room for `width` samples (dirs and flux 3 floats
 * each; omega one and cols, each sample's column, may be NULL); with dirs NULL, only counts.
 * Thread-safe.  Returns the number of samples of the row. */
size_t wenv_envmap_row_samples(const wenv_envmap *env, size_t row, float *dirs, float *flux, float *omega,
                               uint32_t *cols);

/* A pixel taken out of the environment to be shaded as an exact directional light. */
typedef struct {
    size_t pixel;   /* row * width + col */
    float dir[3];   /* world direction of its centre, rotation applied */
    float flux[3];  /* radiance * strength * solid angle */
    float radiance; /* its largest channel, strength applied */
    float du[3], dv[3]; /* its extent: dir + a du + b dv, a and b in [-1, 1], spans it (to first order) */
} wenv_bright_pixel;

/* The up to k brightest pixels (by largest channel) whose radiance exceeds `relative` times the
 * environment's mean radiance (total flux / 4 pi, channels averaged), brightest first, ties by
 * pixel order.  `out` holds room for k.  Returns the number written; 0 on allocation failure (then
 * nothing is taken out, which is always a valid answer). */
size_t wenv_envmap_brightest(const wenv_envmap *env, size_t k, double relative, wenv_bright_pixel *out);

/* The image's fingerprint (64-bit FNV-1a over each row's pixels, the rows' combined in order):
 * made with the image, kept by its copies under another rotation or strength, so telling whether
 * two environments hold the same image costs nothing at a lighting change. */
uint64_t wenv_envmap_fingerprint(const wenv_envmap *env);

/* Total flux: the sum over pixels of solid angle x radiance (channels averaged, strength applied);
 * kept per row with the image, so this costs one pass over the rows. */
double wenv_envmap_flux(const wenv_envmap *env);

/* Exact solid angle of pixel (row, col) (0 outside the domain). */
double wenv_envmap_pixel_solid_angle(const wenv_envmap *env, size_t row, size_t col);

/* Added: wenv_envmap_lookup for n directions (n x 3 floats, need not be unit; zero vectors read
 * +Z) into n x 3 floats, in parallel (OpenMP) for large n.  Thread-safe: `env` is only read. */
void wenv_envmap_lookup_many(const wenv_envmap *env, const float *dirs, size_t n, float *rgb);

/* Added: parses a projection name ("equirect", "mirror_ball", "cube_cross"); 0 on success, -1 if
 * unknown.  wenv_envmap_projection_name returns the name ("?" for an invalid value). */
int wenv_envmap_parse_projection(const char *name, wenv_projection *out);
const char *wenv_envmap_projection_name(wenv_projection projection);
#define WENV_ENVMAP_PROJECTION_NAMES "'equirect', 'mirror_ball', 'cube_cross'"

#endif
