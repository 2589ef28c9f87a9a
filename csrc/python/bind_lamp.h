/* wenv.Lamp (bind_lamp.c), as the other binding files take lamps. */
#ifndef WENV_BIND_LAMP_H
#define WENV_BIND_LAMP_H

#include "python/convert.h"
#include "scene/lamp.h"

/* The lamps of obj, a sequence of wenv.Lamp (None: none), copied into *lamps (PyMem_Free'd by the
 * caller; NULL when there are none) and their count into *n.  -1 + TypeError naming `name`. */
int wenv_py_lamps(PyObject *obj, const char *name, wenv_lamp **lamps, size_t *n);

#endif
