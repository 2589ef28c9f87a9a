/* Argument checking and conversions shared by the binding files. */
#include "python/convert.h"

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <string.h>

#include "scene/bump_terminator.h"

static void set_message(PyObject *type, const char *text)
{
    PyObject *message = PyUnicode_DecodeUTF8(text, (Py_ssize_t)strlen(text), "backslashreplace");
    if (message) {
        PyErr_SetObject(type, message);
        Py_DECREF(message);
    }
}

PyObject *wenv_py_errorf(PyObject *type, const char *fmt, ...)
{
    char text[1024];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(text, sizeof text, fmt, ap);
    va_end(ap);
    set_message(type, text);
    return NULL;
}

PyObject *wenv_py_raise(const wenv_error *err)
{
    if (PyErr_Occurred())
        return NULL;
    PyObject *type = PyExc_RuntimeError;
    switch (err->status) {
    case WENV_ERR_VALUE: type = PyExc_ValueError; break;
    case WENV_ERR_TYPE: type = PyExc_TypeError; break;
    case WENV_ERR_IO: type = PyExc_OSError; break;
    case WENV_ERR_NOMEM: type = PyExc_MemoryError; break;
    case WENV_ERR_CANCELLED: type = wenv_py_cancelled_error(); break;
    case WENV_OK: break;
    }
    /* messages quote paths and file headers, whose bytes need not be UTF-8: undecodable ones are
     * shown as \x escapes rather than turning the error into a UnicodeDecodeError */
    set_message(type, err->message[0] ? err->message : "wenv: unknown error");
    return NULL;
}

/* A C-contiguous float32 buffer of `obj` into *view (released by the caller), or -1 with a TypeError
 * naming `name` and the shape it should have. */
static int get_float32_buffer(PyObject *obj, const char *name, const char *shape, Py_buffer *view)
{
    if (PyObject_GetBuffer(obj, view, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) < 0) {
        PyErr_Clear();
        PyErr_Format(PyExc_TypeError, "%s must be a C-contiguous float32 array of shape %s, got %.100s", name, shape,
                     Py_TYPE(obj)->tp_name);
        return -1;
    }
    const char *fmt = view->format ? view->format : "B";
    if ((fmt[0] == '<' || fmt[0] == '=' || fmt[0] == '@') && fmt[1])
        fmt++;
    if (view->itemsize != 4 || fmt[0] != 'f' || fmt[1] != '\0') {
        PyErr_Format(PyExc_TypeError, "%s must have dtype float32, got format '%s'", name,
                     view->format ? view->format : "B");
        PyBuffer_Release(view);
        return -1;
    }
    return 0;
}

int wenv_py_get_vec3_array(PyObject *obj, const char *name, int require_nonzero, Py_buffer *view,
                           size_t *n, int *single)
{
    if (get_float32_buffer(obj, name, "(n, 3)", view) < 0)
        return -1;
    int is_single = view->ndim == 1 && view->shape[0] == 3;
    if (!is_single && !(view->ndim == 2 && view->shape[1] == 3)) {
        PyErr_Format(PyExc_ValueError, "%s must have shape (n, 3)", name);
        PyBuffer_Release(view);
        return -1;
    }
    size_t count = is_single ? 1 : (size_t)view->shape[0];
    const float *v = view->buf;
    for (size_t i = 0; i < count; i++) {
        float x = v[3 * i], y = v[3 * i + 1], z = v[3 * i + 2];
        if (!isfinite(x) || !isfinite(y) || !isfinite(z)) {
            PyErr_Format(PyExc_ValueError, "%s[%zu] is not finite", name, i);
            PyBuffer_Release(view);
            return -1;
        }
        if (require_nonzero && x * x + y * y + z * z < 1e-24f) {
            PyErr_Format(PyExc_ValueError, "%s[%zu] has zero length", name, i);
            PyBuffer_Release(view);
            return -1;
        }
    }
    *n = count;
    if (single)
        *single = is_single;
    return 0;
}

int wenv_py_get_vec3_pair(PyObject *a, const char *a_name, PyObject *b, const char *b_name, int b_nonzero,
                          Py_buffer *a_view, Py_buffer *b_view, size_t *n)
{
    size_t na, nb;
    if (wenv_py_get_vec3_array(a, a_name, 0, a_view, &na, NULL) < 0)
        return -1;
    if (wenv_py_get_vec3_array(b, b_name, b_nonzero, b_view, &nb, NULL) < 0) {
        PyBuffer_Release(a_view);
        return -1;
    }
    if (na != nb) {
        PyErr_Format(PyExc_ValueError, "%s has %zu rows but %s has %zu", a_name, na, b_name, nb);
        PyBuffer_Release(a_view);
        PyBuffer_Release(b_view);
        return -1;
    }
    *n = na;
    return 0;
}

int wenv_py_get_writable_vec3_array(PyObject *obj, const char *name, size_t n, Py_buffer *view)
{
    if (PyObject_GetBuffer(obj, view, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT | PyBUF_WRITABLE) < 0) {
        PyErr_Clear();
        PyErr_Format(PyExc_TypeError, "%s must be a writable C-contiguous float32 array of shape (%zu, 3), got %.100s",
                     name, n, Py_TYPE(obj)->tp_name);
        return -1;
    }
    const char *fmt = view->format ? view->format : "B";
    if ((fmt[0] == '<' || fmt[0] == '=' || fmt[0] == '@') && fmt[1])
        fmt++;
    if (view->itemsize != 4 || fmt[0] != 'f' || fmt[1] != '\0' || view->ndim != 2 || (size_t)view->shape[0] != n ||
        view->shape[1] != 3) {
        PyErr_Format(PyExc_ValueError, "%s must be a float32 array of shape (%zu, 3)", name, n);
        PyBuffer_Release(view);
        return -1;
    }
    return 0;
}

int wenv_py_get_matrix(PyObject *obj, const char *name, size_t rows, size_t count, double *out)
{
    size_t cols = count / rows;
    PyObject *outer = PySequence_Fast(obj, "");
    if (!outer || (size_t)PySequence_Fast_GET_SIZE(outer) != rows) {
        Py_XDECREF(outer);
        PyErr_Clear();
        PyErr_Format(PyExc_TypeError, "%s must be a %zu x %zu matrix (rows of numbers), got %.100s", name, rows, cols,
                     Py_TYPE(obj)->tp_name);
        return -1;
    }
    for (size_t r = 0; r < rows; r++) {
        PyObject *row = PySequence_Fast(PySequence_Fast_GET_ITEM(outer, (Py_ssize_t)r), "");
        if (!row || (size_t)PySequence_Fast_GET_SIZE(row) != cols) {
            Py_XDECREF(row);
            Py_DECREF(outer);
            PyErr_Clear();
            PyErr_Format(PyExc_TypeError, "%s must be a %zu x %zu matrix (rows of numbers)", name, rows, cols);
            return -1;
        }
        for (size_t c = 0; c < cols; c++)
            if (wenv_py_get_finite(PySequence_Fast_GET_ITEM(row, (Py_ssize_t)c), name, &out[r * cols + c]) < 0) {
                Py_DECREF(row);
                Py_DECREF(outer);
                return -1;
            }
        Py_DECREF(row);
    }
    Py_DECREF(outer);
    return 0;
}

int wenv_py_get_size(PyObject *obj, const char *name, size_t *out)
{
    if (!PyLong_Check(obj) || PyBool_Check(obj)) {
        PyErr_Format(PyExc_TypeError, "%s must be an int, got %.100s", name, Py_TYPE(obj)->tp_name);
        return -1;
    }
    long long x = PyLong_AsLongLong(obj);
    if (x == -1 && PyErr_Occurred()) {
        PyErr_Clear();
        PyErr_Format(PyExc_ValueError, "%s is out of range", name);
        return -1;
    }
    if (x < 0) {
        PyErr_Format(PyExc_ValueError, "%s must not be negative, got %lld", name, x);
        return -1;
    }
    *out = (size_t)x;
    return 0;
}

int wenv_py_get_finite(PyObject *obj, const char *name, double *out)
{
    if (!PyNumber_Check(obj) || PyBool_Check(obj)) {
        PyErr_Format(PyExc_TypeError, "%s must be a number, got %.100s", name, Py_TYPE(obj)->tp_name);
        return -1;
    }
    double v = PyFloat_AsDouble(obj);
    if (v == -1.0 && PyErr_Occurred())
        return -1;
    if (!isfinite(v)) {
        PyErr_Format(PyExc_ValueError, "%s must be finite", name);
        return -1;
    }
    *out = v;
    return 0;
}

int wenv_py_get_rgb(PyObject *obj, const char *name, double rgb[3])
{
    if (PyNumber_Check(obj) && !PySequence_Check(obj)) {
        double g;
        if (wenv_py_get_finite(obj, name, &g) < 0)
            return -1;
        rgb[0] = rgb[1] = rgb[2] = g;
    } else {
        PyObject *seq = PySequence_Fast(obj, "");
        if (!seq) {
            PyErr_Clear();
            PyErr_Format(PyExc_TypeError, "%s must be a number or an (r, g, b) sequence", name);
            return -1;
        }
        if (PySequence_Fast_GET_SIZE(seq) != 3) {
            Py_DECREF(seq);
            PyErr_Format(PyExc_ValueError, "%s must have 3 components (r, g, b)", name);
            return -1;
        }
        for (int c = 0; c < 3; c++) {
            if (wenv_py_get_finite(PySequence_Fast_GET_ITEM(seq, c), name, &rgb[c]) < 0) {
                Py_DECREF(seq);
                return -1;
            }
        }
        Py_DECREF(seq);
    }
    for (int c = 0; c < 3; c++) {
        if (rgb[c] < 0.0) {
            PyErr_Format(PyExc_ValueError, "%s must be >= 0 in every channel", name);
            return -1;
        }
    }
    return 0;
}

PyObject *wenv_py_new_array(int ndim, const Py_ssize_t *shape, const char *dtype, void **data)
{
    PyObject *numpy = PyImport_ImportModule("numpy");
    if (!numpy)
        return NULL;
    PyObject *shape_tuple = PyTuple_New(ndim);
    if (!shape_tuple) {
        Py_DECREF(numpy);
        return NULL;
    }
    for (int i = 0; i < ndim; i++) {
        PyObject *dim = PyLong_FromSsize_t(shape[i]);
        if (!dim) {
            Py_DECREF(shape_tuple);
            Py_DECREF(numpy);
            return NULL;
        }
        PyTuple_SET_ITEM(shape_tuple, i, dim);
    }
    PyObject *array = PyObject_CallMethod(numpy, "empty", "Os", shape_tuple, dtype);
    Py_DECREF(shape_tuple);
    Py_DECREF(numpy);
    if (!array)
        return NULL;
    Py_buffer view;
    if (PyObject_GetBuffer(array, &view, PyBUF_C_CONTIGUOUS | PyBUF_WRITABLE) < 0) {
        Py_DECREF(array);
        return NULL;
    }
    *data = view.buf; /* numpy keeps the storage alive as long as the array lives */
    PyBuffer_Release(&view);
    return array;
}

PyObject *wenv_py_new_float_array(int ndim, const Py_ssize_t *shape, float **data)
{
    void *d = NULL;
    PyObject *array = wenv_py_new_array(ndim, shape, "float32", &d);
    *data = d;
    return array;
}

static int progress_trampoline(void *ctx, double fraction)
{
    wenv_py_progress_bridge *bridge = ctx;
    if (!bridge->callback || bridge->callback == Py_None)
        return 0;
    if (bridge->raised)
        return 1;
    if (fraction < 1.0 && fraction - bridge->reported < WENV_PY_PROGRESS_STEP)
        return 0;
    bridge->reported = fraction;
    PyGILState_STATE gil = PyGILState_Ensure();
    int stop = 0;
    PyObject *result = PyObject_CallFunction(bridge->callback, "d", fraction);
    if (!result) {
        bridge->raised = 1;
        stop = 1;
    } else {
        int truth = PyObject_IsTrue(result);
        Py_DECREF(result);
        if (truth < 0) { /* a value that cannot be tested for truth: its exception stops the work */
            bridge->raised = 1;
            truth = 1;
        }
        stop = truth;
    }
    PyGILState_Release(gil);
    return stop;
}

float *wenv_py_vertex_colours(PyObject *obj, const char *name, size_t n, int up_to_one)
{
    Py_buffer cb;
    size_t rows;
    if (wenv_py_get_vec3_array(obj, name, 0, &cb, &rows, NULL) < 0)
        return NULL;
    float *rgb = NULL;
    const float *c = cb.buf;
    if (rows != n) {
        PyErr_Format(PyExc_ValueError, "%s has %zu rows, one per vertex (%zu)", name, rows, n);
        goto done;
    }
    for (size_t i = 0; i < 3 * n; i++)
        if (!(c[i] >= 0.0f) || !isfinite(c[i])) {
            PyErr_Format(PyExc_ValueError, "%s[%zu] must be finite and non-negative (linear RGB)", name, i / 3);
            goto done;
        }
    if (!(rgb = PyMem_Malloc((n ? n : 1) * 3 * sizeof(float)))) {
        PyErr_NoMemory();
        goto done;
    }
    for (size_t i = 0; i < 3 * n; i++)
        rgb[i] = up_to_one && c[i] > 1.0f ? 1.0f : c[i];
done:
    PyBuffer_Release(&cb);
    return rgb;
}

float *wenv_py_base_colours(PyObject *obj, size_t n) { return wenv_py_vertex_colours(obj, "base_color", n, 1); }

int wenv_py_get_vertex_values(PyObject *obj, const char *name, size_t n, Py_buffer *view)
{
    if (get_float32_buffer(obj, name, "(n,)", view) < 0)
        return -1;
    if (view->ndim != 1 || (size_t)view->shape[0] != n) {
        PyErr_Format(PyExc_ValueError, "%s must have shape (%zu,): one value per vertex", name, n);
        PyBuffer_Release(view);
        return -1;
    }
    return 0;
}

int wenv_py_bump_correction(PyObject *obj, void *mode)
{
    int *out = mode;
    if (PyUnicode_Check(obj)) {
        const char *name = PyUnicode_AsUTF8(obj);
        if (!name)
            return 0;
        if (strcmp(name, "MICROFACET") == 0 || strcmp(name, "CHIANG") == 0) {
            *out = name[0] == 'M' ? WENV_BUMP_MICROFACET : WENV_BUMP_CHIANG;
            return 1;
        }
        PyErr_Format(PyExc_ValueError, "bump_map_correction must be True, False, 'MICROFACET' or 'CHIANG', got '%s'",
                     name);
        return 0;
    }
    int truth = PyObject_IsTrue(obj);
    if (truth < 0)
        return 0;
    *out = truth ? WENV_BUMP_MICROFACET : WENV_BUMP_NONE;
    return 1;
}

wenv_progress wenv_py_progress(wenv_py_progress_bridge *bridge)
{
    wenv_progress p = {NULL, NULL};
    if (bridge->callback && bridge->callback != Py_None) {
        p.report = progress_trampoline;
        p.ctx = bridge;
    }
    return p;
}

int wenv_py_run_released(wenv_status (*work)(void *ctx, const wenv_progress *p, wenv_error *err), void *ctx,
                         PyObject *progress_obj)
{
    wenv_py_progress_bridge bridge = {.callback = progress_obj};
    wenv_progress progress = wenv_py_progress(&bridge);
    wenv_error err = {0};
    wenv_status st;
    WENV_BEGIN_WORK
    st = work(ctx, &progress, &err);
    WENV_END_WORK
    if (!st)
        return 0;
    if (!(bridge.raised && PyErr_Occurred()))
        wenv_py_raise(&err);
    return -1;
}

int wenv_py_check_progress(PyObject *progress)
{
    if (progress != Py_None && !PyCallable_Check(progress)) {
        PyErr_SetString(PyExc_TypeError, "progress must be callable or None");
        return -1;
    }
    return 0;
}

int wenv_py_take_vertex_inputs(PyObject *kwargs, wenv_py_vertex_inputs *v)
{
    memset(v, 0, sizeof *v);
    if (!kwargs)
        return 0;
    if (!(v->rest = PyDict_Copy(kwargs)))
        return -1;
    for (int k = 0; k < WENV_VERTEX_INPUT_COUNT; k++) {
        PyObject *item = PyDict_GetItemString(v->rest, wenv_vertex_input_list[k].name);
        if (!item)
            continue;
        Py_INCREF(item);
        v->obj[k] = item;
        if (PyDict_DelItemString(v->rest, wenv_vertex_input_list[k].name) < 0)
            return -1;
    }
    return 0;
}

int wenv_py_vertex_inputs_given(const wenv_py_vertex_inputs *v)
{
    for (int k = 0; k < WENV_VERTEX_INPUT_COUNT; k++)
        if (v->obj[k] && v->obj[k] != Py_None)
            return 1;
    return 0;
}

int wenv_py_vertex_inputs_read(wenv_py_vertex_inputs *v, size_t n, wenv_vertex_inputs *out)
{
    memset(out, 0, sizeof *out);
    for (int k = 0; k < WENV_VERTEX_INPUT_COUNT; k++) {
        const char *name = wenv_vertex_input_list[k].name;
        size_t width = (size_t)wenv_vertex_input_list[k].n, rows = n;
        if (!v->obj[k] || v->obj[k] == Py_None)
            continue;
        if (!v->values[k]) {
            Py_buffer view;
            if (width == 1 ? wenv_py_get_vertex_values(v->obj[k], name, n, &view)
                           : wenv_py_get_vec3_array(v->obj[k], name, 0, &view, &rows, NULL))
                return -1;
            if (rows != n) {
                PyErr_Format(PyExc_ValueError, "%s has %zu rows, one per vertex (%zu)", name, rows, n);
                PyBuffer_Release(&view);
                return -1;
            }
            v->values[k] = PyMem_Malloc((n ? n : 1) * width * sizeof(float));
            if (v->values[k])
                memcpy(v->values[k], view.buf, n * width * sizeof(float));
            PyBuffer_Release(&view);
            if (!v->values[k]) {
                PyErr_NoMemory();
                return -1;
            }
        }
        out->value[k] = v->values[k];
    }
    return 0;
}

void wenv_py_vertex_inputs_release(wenv_py_vertex_inputs *v)
{
    for (int k = 0; k < WENV_VERTEX_INPUT_COUNT; k++) {
        Py_XDECREF(v->obj[k]);
        PyMem_Free(v->values[k]);
    }
    Py_XDECREF(v->rest);
    memset(v, 0, sizeof *v);
}

int wenv_py_get_typed_array(PyObject *obj, const char *name, const char *dtype, int writable, Py_buffer *view,
                            PyObject **held)
{
    PyObject *numpy = PyImport_ImportModule("numpy");
    *held = numpy ? PyObject_CallMethod(numpy, "ascontiguousarray", "Os", obj, dtype) : NULL;
    Py_XDECREF(numpy);
    if (!*held) {
        if (PyErr_ExceptionMatches(PyExc_ValueError) || PyErr_ExceptionMatches(PyExc_TypeError)) {
            PyErr_Clear();
            PyErr_Format(PyExc_TypeError, "%s must be an array convertible to %s", name, dtype);
        }
        return -1;
    }
    if (writable && *held != obj) {
        PyErr_Format(PyExc_TypeError, "%s must be a C-contiguous %s numpy array (it is written in place)", name,
                     dtype);
        Py_CLEAR(*held);
        return -1;
    }
    if (PyObject_GetBuffer(*held, view, PyBUF_ND | PyBUF_C_CONTIGUOUS | (writable ? PyBUF_WRITABLE : 0)) < 0) {
        Py_CLEAR(*held);
        return -1;
    }
    return 0;
}

void wenv_py_release_array(Py_buffer *view, PyObject **held)
{
    PyBuffer_Release(view);
    Py_CLEAR(*held);
}
