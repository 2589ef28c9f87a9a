/* wenv.Material and its kinds (bind_material.c), as the other binding files take them. */
#ifndef WENV_BIND_MATERIAL_H
#define WENV_BIND_MATERIAL_H

#include "python/convert.h"

#include "scene/microfacet.h"

struct wenv_material;

/* Every wenv material object: the base type's layout, which every kind's type shares. */
typedef struct {
    PyObject_HEAD
    struct wenv_material *mat;       /* owned, immutable after construction */
    wenv_distribution distribution;  /* CookTorrance's material-level default, kept for .distribution */
} MaterialObject;

/* wenv.Material, the base type of every kind (bind_principled.c's among them). */
PyTypeObject *wenv_py_material_type(void);

/* NULL + TypeError naming `name` if obj is not a wenv.Material. */
const struct wenv_material *wenv_py_material(PyObject *obj, const char *name);

/* A one-lobe Cook-Torrance material (roughness 0.1, to be set by the caller) from the keys of
 * `params` (a dict, may be NULL): diffuse, distribution, shadowing for the material, specular and ior
 * for its lobe, read as wenv.CookTorrance reads them; any other key, roughness included, is a
 * TypeError naming `caller`.  NULL with an exception set on failure; wenv_material_free the result. */
struct wenv_material *wenv_py_one_lobe_material(PyObject *params, const char *caller);

#endif
