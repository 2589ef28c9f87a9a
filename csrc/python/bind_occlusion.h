/* wenv.Occluders and wenv.Occlusion (bind_occlusion.c), as the other binding files take them. */
#ifndef WENV_BIND_OCCLUSION_H
#define WENV_BIND_OCCLUSION_H

#include "python/convert.h"
#include "scene/occlusion.h"

/* NULL + TypeError naming `name` if obj is not a wenv.Occluders. */
const struct wenv_occluders *wenv_py_occluders(PyObject *obj, const char *name);

/* The occlusion obj holds and the occluders it was cast against; -1 + TypeError naming `name` if obj
 * is not a wenv.Occlusion. */
int wenv_py_occlusion(PyObject *obj, const char *name, const wenv_occlusion **occlusion,
                      const wenv_occluders **occluders);

#endif
