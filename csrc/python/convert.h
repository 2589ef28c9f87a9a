/* Argument checks and conversions shared by the binding files (bind_*.c): errors to exceptions,
 * arrays, numbers, progress callbacks.  Numerical code never includes this. */
#ifndef WENV_CONVERT_H
#define WENV_CONVERT_H

#define PY_SSIZE_T_CLEAN
#include <Python.h>

#include "base/error.h"
#include "base/progress.h"
#include "scene/principled_inputs.h"

/* Raises the Python exception that matches err->status (ValueError, TypeError, OSError,
 * MemoryError, wenv.CancelledError).  Always returns NULL for convenient `return`. */
PyObject *wenv_py_raise(const wenv_error *err);

/* Sets an exception of `type` whose message is formatted by C's vsnprintf: PyErr_Format has no
 * %g, %f or %e (it printed them literally); bytes that are not UTF-8 come out as \x escapes.
 * Always returns NULL. */
PyObject *wenv_py_errorf(PyObject *type, const char *fmt, ...);

/* wenv.CancelledError (set up by module.c). */
PyObject *wenv_py_cancelled_error(void);
/* wenv.EyeAtVertexError: a ValueError whose `vertices` lists the vertices at the eye (module.c). */
PyObject *wenv_py_eye_at_vertex_error(void);

/* Gets a read-only float32, C-contiguous buffer of shape (n, 3) from `obj`; `name` is used in the
 * exception.  Also accepts a single 3-vector (shape (3,)), reported as n = 1 with *single = 1.
 * Rejects non-finite entries and (if require_nonzero) zero-length rows.  On success the caller
 * must PyBuffer_Release(view). */
int wenv_py_get_vec3_array(PyObject *obj, const char *name, int require_nonzero, Py_buffer *view,
                           size_t *n, int *single);

/* Two such arrays of as many rows (names a_name, b_name; zero rows refused in b when b_nonzero):
 * ValueError naming both when their rows differ.  On success the caller releases both views. */
int wenv_py_get_vec3_pair(PyObject *a, const char *a_name, PyObject *b, const char *b_name, int b_nonzero,
                          Py_buffer *a_view, Py_buffer *b_view, size_t *n);

/* Gets a writable float32, C-contiguous buffer of shape (n, 3) -- exactly n rows -- from `obj`,
 * for results written in place.  On success the caller must PyBuffer_Release(view). */
int wenv_py_get_writable_vec3_array(PyObject *obj, const char *name, size_t n, Py_buffer *view);

/* Reads `count` finite numbers from a sequence of `rows` sequences of count / rows numbers (a 4 x 4
 * numpy array or mathutils.Matrix, for one), row-major into out. */
int wenv_py_get_matrix(PyObject *obj, const char *name, size_t rows, size_t count, double *out);

/* Reads an RGB triple from a number (grey) or a length-3 sequence of finite numbers >= 0. */
int wenv_py_get_rgb(PyObject *obj, const char *name, double rgb[3]);

/* Reads a non-negative int into a size_t; TypeError / ValueError naming `name` otherwise. */
int wenv_py_get_size(PyObject *obj, const char *name, size_t *out);

/* Reads a finite float; ValueError naming `name` otherwise. */
int wenv_py_get_finite(PyObject *obj, const char *name, double *out);

/* Gets a C-contiguous buffer of numpy dtype `dtype` ("float32", "int64", "uint16", "bool"...) from
 * `obj`, converting it when it is not one already (TypeError naming `name` when it cannot be); with
 * `writable`, `obj` itself must be such an array, as results are written into it.  *held keeps
 * the array alive: on success the caller ends with wenv_py_release_array(view, held). */
int wenv_py_get_typed_array(PyObject *obj, const char *name, const char *dtype, int writable, Py_buffer *view,
                            PyObject **held);
void wenv_py_release_array(Py_buffer *view, PyObject **held);

/* New numpy array of the given shape and dtype ("float32", "float64", "int64", "bool"); *data points at its storage. */
PyObject *wenv_py_new_array(int ndim, const Py_ssize_t *shape, const char *dtype, void **data);

/* New numpy float32 array of the given shape (numpy.empty); *data points at its storage. */
PyObject *wenv_py_new_float_array(int ndim, const Py_ssize_t *shape, float **data);

/* WENV_BEGIN_WORK applies the thread count wenv.set_num_threads chose (if any) to the calling thread
 * before releasing the GIL: OpenMP keeps its thread count per calling thread, and the add-on (or any
 * script) shades from worker threads. */
void wenv_py_use_num_threads(void);
#define WENV_BEGIN_WORK                                                                                          \
    wenv_py_use_num_threads();                                                                                   \
    Py_BEGIN_ALLOW_THREADS
#define WENV_END_WORK Py_END_ALLOW_THREADS

/* Bridges a Python progress callback to wenv_progress.  The callback is called as
 * callback(fraction) with the GIL held, at most every WENV_PY_PROGRESS_STEP of the work (a loop
 * over vertices reports each one, and a callback that updates Blender's indicator is not free) and
 * at the end; a true return value (or an exception) stops the work. */
#define WENV_PY_PROGRESS_STEP 0.002
typedef struct {
    PyObject *callback; /* borrowed; may be NULL or None */
    int raised;         /* set when the callback raised: the exception is pending */
    double reported;    /* the last fraction passed on (0 to start) */
} wenv_py_progress_bridge;

wenv_progress wenv_py_progress(wenv_py_progress_bridge *bridge);
/* 0 when `progress` is None or callable; else -1 with TypeError naming the argument. */
int wenv_py_check_progress(PyObject *progress);
/* Runs work(ctx, progress, err) with the GIL released, `progress_obj` (None or a callable, checked
 * by the caller) told the fractions; -1 with the Python error set when it fails or is cancelled. */
int wenv_py_run_released(wenv_status (*work)(void *ctx, const wenv_progress *p, wenv_error *err), void *ctx,
                         PyObject *progress_obj);

/* base_color: one linear RGB colour per vertex (n rows), finite and non-negative, copied clamped to
 * [0, 1] as a material clamps its own (PyMem_Free it).  NULL with a ValueError or TypeError naming
 * base_color. */
/* Colours per vertex (n rows of RGB, finite and >= 0, float32-convertible) named `name`, copied (clamped
 * to 1 where up_to_one), PyMem_Free'd by the caller; NULL with the error set. */
float *wenv_py_vertex_colours(PyObject *obj, const char *name, size_t n, int up_to_one);
float *wenv_py_base_colours(PyObject *obj, size_t n);
/* One float32 value per vertex (1-D, n of them) from `obj` named `name`: a view of its buffer into
 * *view (released by the caller), or -1 with TypeError/ValueError set. */
int wenv_py_get_vertex_values(PyObject *obj, const char *name, size_t n, Py_buffer *view);
/* An "O&" converter of bump_map_correction into a WENV_BUMP_* mode (int): True or 'MICROFACET'
 * (Blender 4.5 on), 'CHIANG' (before), False or None; 0 with ValueError otherwise. */
int wenv_py_bump_correction(PyObject *obj, void *mode);

/* The inputs per vertex (principled_inputs.h's WENV_VERTEX_INPUTS) a call takes as keywords:
 * wenv_py_take_vertex_inputs takes them out of kwargs (the rest in `rest`, for PyArg_Parse...),
 * wenv_py_vertex_inputs_read checks and copies them for n vertices (n values each, n x 3 for a
 * colour), wenv_py_vertex_inputs_release frees what either made. */
typedef struct {
    PyObject *obj[WENV_VERTEX_INPUT_COUNT];
    float *values[WENV_VERTEX_INPUT_COUNT];
    PyObject *rest;
} wenv_py_vertex_inputs;
int wenv_py_take_vertex_inputs(PyObject *kwargs, wenv_py_vertex_inputs *v);
int wenv_py_vertex_inputs_given(const wenv_py_vertex_inputs *v);
int wenv_py_vertex_inputs_read(wenv_py_vertex_inputs *v, size_t n, wenv_vertex_inputs *out);
void wenv_py_vertex_inputs_release(wenv_py_vertex_inputs *v);

#endif
