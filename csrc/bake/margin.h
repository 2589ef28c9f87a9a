/* A bake's margin: the colours at the edge of its UV islands carried outwards, so that filtering
 * and mip-mapping an image near an island's edge read the island's colours, not the background. */
#ifndef WENV_MARGIN_H
#define WENV_MARGIN_H

#include <stddef.h>
#include <stdint.h>

#include "base/error.h"

/* Extends `pixels` (height x width x channels floats, row-major) from the texels `filled` marks
 * (height x width, 0 or 1) by `margin` rings: in each ring, every texel not filled that touches a
 * filled one (8-neighbours) takes the mean of the filled ones it touches, and is filled -- Blender's
 * "Extend" margin.  Texels farther away are untouched.  *added counts the texels filled. */
wenv_status wenv_extend_margin(float *pixels, uint8_t *filled, size_t width, size_t height, size_t channels,
                               size_t margin, size_t *added, wenv_error *err);

#endif
