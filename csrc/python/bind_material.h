/* wenv.Material and its kinds (bind_material.c), as the other binding files take them. */
#ifndef WENV_BIND_MATERIAL_H
#define WENV_BIND_MATERIAL_H

#include "python/convert.h"

struct wenv_material;

/* NULL + TypeError naming `name` if obj is not a wenv.Material. */
const struct wenv_material *wenv_py_material(PyObject *obj, const char *name);

/* A one-lobe Cook-Torrance material (roughness 0.1, to be set by the caller) from the keys of
 * `params` (a dict, may be NULL): diffuse, distribution, shadowing for the material, specular and ior
 * for its lobe, read as wenv.CookTorrance reads them; any other key, roughness included, is a
 * TypeError naming `caller`.  NULL with an exception set on failure; wenv_material_free the result. */
struct wenv_material *wenv_py_one_lobe_material(PyObject *params, const char *caller);

#endif
