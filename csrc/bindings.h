/* Python C-API glue shared by the binding files (bind_*.c).  Numerical code never includes this. */
#ifndef WENV_BINDINGS_H
#define WENV_BINDINGS_H

#define PY_SSIZE_T_CLEAN
#include <Python.h>

#include "error.h"

/* Each binding file adds its types and functions to the module; 0 on success, -1 with an exception. */
int wenv_register_envmap(PyObject *module);
int wenv_register_brdf(PyObject *module);
int wenv_register_shade(PyObject *module);
int wenv_register_glossmeter(PyObject *module);
int wenv_register_peers(PyObject *module);

/* Raises the Python exception that matches err->status (ValueError, TypeError, OSError,
 * MemoryError, wenv.CancelledError).  Always returns NULL for convenient `return`. */
PyObject *wenv_py_raise(const wenv_error *err);

/* wenv.CancelledError (set up by module.c). */
PyObject *wenv_py_cancelled_error(void);

/* Gets a read-only float32, C-contiguous buffer of shape (n, 3) from `obj`; `name` is used in the
 * exception.  Also accepts a single 3-vector (shape (3,)), reported as n = 1 with *single = 1.
 * Rejects non-finite entries and (if require_nonzero) zero-length rows.  On success the caller
 * must PyBuffer_Release(view). */
int wenv_py_get_vec3_array(PyObject *obj, const char *name, int require_nonzero, Py_buffer *view,
                           size_t *n, int *single);

/* Reads an RGB triple from a number (grey) or a length-3 sequence of finite numbers >= 0. */
int wenv_py_get_rgb(PyObject *obj, const char *name, double rgb[3]);

/* Reads a non-negative int into a size_t; TypeError / ValueError naming `name` otherwise. */
int wenv_py_get_size(PyObject *obj, const char *name, size_t *out);

/* Reads a finite float; ValueError naming `name` otherwise. */
int wenv_py_get_finite(PyObject *obj, const char *name, double *out);

/* New numpy array of the given shape and dtype ("float32", "float64"); *data points at its storage. */
PyObject *wenv_py_new_array(int ndim, const Py_ssize_t *shape, const char *dtype, void **data);

/* New numpy float32 array of the given shape (numpy.empty); *data points at its storage. */
PyObject *wenv_py_new_float_array(int ndim, const Py_ssize_t *shape, float **data);

/* Bridges a Python progress callback to wenv_progress.  The callback is called as
 * callback(fraction) with the GIL held; a true return value (or an exception) stops the work. */
typedef struct {
    PyObject *callback; /* borrowed; may be NULL or None */
    int raised;         /* set when the callback raised: the exception is pending */
} wenv_py_progress_bridge;

wenv_progress wenv_py_progress(wenv_py_progress_bridge *bridge);

struct wenv_envmap;
const struct wenv_envmap *wenv_py_envmap(PyObject *obj, const char *name); /* NULL + TypeError naming `name` if obj is not a wenv.Environment */
struct wenv_auto_analysis;
/* quality="auto"'s analysis of an environment (a wenv.Environment, checked by the caller), kept
 * with it: empty when new, its parts made by the choices that need them (wenv_auto_choose, without
 * the GIL); NULL + exception on failure. */
struct wenv_auto_analysis *wenv_py_envmap_auto_analysis(PyObject *obj);
struct wenv_material;
const struct wenv_material *wenv_py_material(PyObject *obj, const char *name); /* NULL + TypeError naming `name` if obj is not a wenv.Material */

/* The peer shading methods behind wenv.Shader ("split_sum", "sh"; bind_peers.c).  Every function
 * that can fail returns NULL / -1 with a Python exception set; long work runs without the GIL and
 * reports to the progress callback given at creation. */
typedef struct wenv_py_peer wenv_py_peer;
int wenv_py_is_peer_method(const char *method);
wenv_py_peer *wenv_py_peer_create(const char *method, PyObject *quality, PyObject *progress);
void wenv_py_peer_free(wenv_py_peer *peer);
const char *wenv_py_peer_method(const wenv_py_peer *peer);
int wenv_py_peer_set_environment(wenv_py_peer *peer, const struct wenv_envmap *env);
int wenv_py_peer_set_material(wenv_py_peer *peer, const struct wenv_material *mat);
int wenv_py_peer_shade(wenv_py_peer *peer, const float *normals, const float *views, size_t n, float *out);
PyObject *wenv_py_peer_quality(wenv_py_peer *peer);
PyObject *wenv_py_peer_stats(const wenv_py_peer *peer);

#endif
