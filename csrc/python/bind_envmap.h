/* wenv.Environment (bind_envmap.c), as the other binding files take it. */
#ifndef WENV_BIND_ENVMAP_H
#define WENV_BIND_ENVMAP_H

#include "python/convert.h"

struct wenv_envmap;
struct wenv_auto_analysis;

/* NULL + TypeError naming `name` if obj is not a wenv.Environment. */
const struct wenv_envmap *wenv_py_envmap(PyObject *obj, const char *name);

/* quality="auto"'s analysis of an environment (a wenv.Environment, checked by the caller), kept
 * with it: empty when new, its parts made by the choices that need them (wenv_auto_choose, without
 * the GIL); NULL + exception on failure. */
struct wenv_auto_analysis *wenv_py_envmap_auto_analysis(PyObject *obj);

#endif
