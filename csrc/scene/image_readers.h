/* The environment file readers behind wenv_envmap_load (envmap.c), one file each.  Each returns
 * height x width x 3 linear floats (row 0 the top, malloc'd, owned by the caller) or an error naming
 * `path`; the pixels are checked (finite, negatives clamped) by the environment that adopts them. */
#ifndef WENV_IMAGE_READERS_H
#define WENV_IMAGE_READERS_H

#include <stddef.h>
#include <stdint.h>

#include "base/error.h"

/* Largest image accepted from a file or an array (far beyond real panoramas): keeps every size
 * product far from overflow and OpenEXRCore's int32 line strides in range.  The fuzz targets
 * (tests/fuzz/run.py) build with fewer pixels: a valid file may declare an image thousands of times
 * its own size (compressed or run-length rows), which is no fault but would exceed their memory
 * limit. */
#define WENV_IMAGE_MAX_SIDE ((size_t)1 << 20)
#ifndef WENV_IMAGE_MAX_PIXELS
#define WENV_IMAGE_MAX_PIXELS ((size_t)1 << 30)
#endif

/* OpenEXR (exr_reader.c): `fd` open for reading, `size` bytes long. */
wenv_status wenv_read_exr(int fd, int64_t size, const char *path, float **rgb, size_t *height, size_t *width,
                          wenv_error *err);

/* Radiance RGBE (rgbe_reader.c): the whole file in `buf`. */
wenv_status wenv_read_rgbe(const uint8_t *buf, size_t size, const char *path, float **rgb, size_t *height,
                           size_t *width, wenv_error *err);

#endif
