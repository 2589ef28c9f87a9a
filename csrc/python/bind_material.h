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

/* A one-lobe Cook-Torrance material (alpha 0.1, to be set by the caller) from the keys of `params`
 * (a dict, may be NULL): diffuse, distribution, shadowing for the material, specular and ior for its
 * lobe, read as wenv.CookTorrance reads them; any other key, alpha included, is a TypeError naming
 * `caller`.  NULL with an exception set on failure; wenv_material_free the result. */
struct wenv_material *wenv_py_one_lobe_material(PyObject *params, const char *caller);

/* What the bindings of the tests' hooks (bind_internals.c) share with the material bindings. */
extern const char *const wenv_py_distribution_names[2]; /* "beckmann", "ggx" */
extern const char *const wenv_py_shadowing_names[2];    /* "smith", "vcavity" */
/* One of `names` (exact, lower case) from a str; TypeError / ValueError naming `name`. */
int wenv_py_parse_choice(PyObject *obj, const char *name, const char *const *names, int count, int *out);
/* A quadrature's `samples` (an int in [8, 4096]; None-less default 128). */
int wenv_py_parse_samples(PyObject *obj, size_t *out);
/* A float32 (n, 3) buffer as doubles, each row normalised (rows unit to float precision kept as they
 * are, so every C path sees bit-identical directions); PyMem_Free the result. */
double *wenv_py_normalised_rows(const Py_buffer *view, size_t n);

/* Material.eval(wi, wo) and its hooks: the whole f cos, or the lobes' alone through one of the C
 * paths (the double evaluation, the batch for one view, the float path the exact lights use). */
typedef enum {
    WENV_PY_EVAL_FULL,
    WENV_PY_EVAL_SPECULAR,
    WENV_PY_EVAL_SPECULAR_BATCH,
    WENV_PY_EVAL_SPECULAR_FLOAT
} wenv_py_eval_mode;
PyObject *wenv_py_material_eval(PyObject *material, PyObject *args, PyObject *kwds, wenv_py_eval_mode mode);

#endif
