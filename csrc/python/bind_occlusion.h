/* wenv.Occluders and wenv.Occlusion (bind_occlusion.c), as the other binding files take them. */
#ifndef WENV_BIND_OCCLUSION_H
#define WENV_BIND_OCCLUSION_H

#include "python/convert.h"

struct wenv_occluders;

/* NULL + TypeError naming `name` if obj is not a wenv.Occluders. */
const struct wenv_occluders *wenv_py_occluders(PyObject *obj, const char *name);

#endif
