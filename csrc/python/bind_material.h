/* wenv.Material and its kinds (bind_material.c), as the other binding files take them. */
#ifndef WENV_BIND_MATERIAL_H
#define WENV_BIND_MATERIAL_H

#include "python/convert.h"

struct wenv_material;

/* NULL + TypeError naming `name` if obj is not a wenv.Material. */
const struct wenv_material *wenv_py_material(PyObject *obj, const char *name);

/* A new wenv.CookTorrance wrapping `mat` (owned by the result, freed on failure). */
PyObject *wenv_py_material_wrap(struct wenv_material *mat);

#endif
