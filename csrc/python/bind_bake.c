/* wenv.uv_texels, wenv.corner_values_at and wenv.extend_margin: the image side of a bake
 * (bake/texel_raster.h, bake/corner_interpolation.h, bake/margin.h). */
#include <stdint.h>
#include <string.h>

#include "bake/corner_interpolation.h"
#include "bake/margin.h"
#include "bake/texel_raster.h"
#include "python/module.h"

/* numpy.ascontiguousarray(obj, dtype) as a buffer (writable if asked: then obj itself must be
 * that array, so the caller sees what is written).  -1 with TypeError naming `name`. */
/* uv_texels(uv, triangles, width, height, memory_budget_mb=1024, progress=None, border=False)
 *   -> (triangle (height, width) int32, weights (height, width, 2) float32, covered, overlapped) */
static PyObject *uv_texels(PyObject *self, PyObject *args, PyObject *kwargs)
{
    (void)self;
    static char *kwlist[] = {"uv", "triangles", "width", "height", "memory_budget_mb", "progress", "border", NULL};
    PyObject *uv_obj, *tri_obj, *w_obj, *h_obj, *progress_obj = Py_None;
    double budget_mb = 1024.0;
    int border = 0;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "OOOO|dOp:uv_texels", kwlist, &uv_obj, &tri_obj, &w_obj, &h_obj,
                                     &budget_mb, &progress_obj, &border))
        return NULL;
    size_t width, height;
    if (wenv_py_get_size(w_obj, "width", &width) < 0 || wenv_py_get_size(h_obj, "height", &height) < 0)
        return NULL;
    if (width == 0 || height == 0)
        return wenv_py_errorf(PyExc_ValueError, "the image is %zu x %zu texels: it must have at least one", width,
                              height);
    if (!(budget_mb > 0.0 && budget_mb < 1e9))
        return wenv_py_errorf(PyExc_ValueError, "memory_budget_mb must be positive, got %g", budget_mb);
    /* what is made here (a triangle and two weights a texel) and what a bake holds per texel beside it
     * (RGBA floats): both must fit */
    double need_mb = (double)width * (double)height * (12.0 + 16.0) / 1048576.0;
    if (need_mb > budget_mb)
        return wenv_py_errorf(PyExc_ValueError,
                              "a %zu x %zu image needs %.0f MB to bake, over the memory budget of %.0f MB", width,
                              height, need_mb, budget_mb);
    if (wenv_py_check_progress(progress_obj) < 0)
        return NULL;
    Py_buffer ub, tb;
    PyObject *uv_held, *tri_held;
    if (wenv_py_get_typed_array(uv_obj, "uv", "float32", 0, &ub, &uv_held) < 0)
        return NULL;
    if (ub.ndim != 2 || ub.shape[1] != 2) {
        wenv_py_release_array(&ub, &uv_held);
        PyErr_SetString(PyExc_ValueError, "uv must have shape (n, 2)");
        return NULL;
    }
    if (wenv_py_get_typed_array(tri_obj, "triangles", "int64", 0, &tb, &tri_held) < 0) {
        wenv_py_release_array(&ub, &uv_held);
        return NULL;
    }
    PyObject *result = NULL, *tri_out = NULL, *weights_out = NULL;
    uint32_t *tri = NULL;
    size_t n_uv = (size_t)ub.shape[0], n_tri = tb.ndim == 2 ? (size_t)tb.shape[0] : 0;
    if (!(tb.ndim == 2 && tb.shape[1] == 3) && !(tb.ndim == 1 && tb.shape[0] == 0)) {
        PyErr_SetString(PyExc_ValueError, "triangles must have shape (m, 3)");
        goto done;
    }
    if (!(tri = PyMem_Malloc((n_tri > 0 ? 3 * n_tri : 1) * sizeof *tri))) {
        PyErr_NoMemory();
        goto done;
    }
    const int64_t *t64 = tb.buf;
    for (size_t i = 0; i < 3 * n_tri; i++) {
        if (t64[i] < 0 || (uint64_t)t64[i] >= n_uv) {
            wenv_py_errorf(PyExc_ValueError, "triangles[%zu] indexes uv row %lld of %zu", i / 3, (long long)t64[i],
                           n_uv);
            goto done;
        }
        tri[i] = (uint32_t)t64[i];
    }
    Py_ssize_t shape[3] = {(Py_ssize_t)height, (Py_ssize_t)width, 2};
    void *tri_data, *weight_data;
    if (!(tri_out = wenv_py_new_array(2, shape, "int32", &tri_data)) ||
        !(weights_out = wenv_py_new_array(3, shape, "float32", &weight_data)))
        goto done;
    wenv_py_progress_bridge bridge = {.callback = progress_obj};
    wenv_progress progress = wenv_py_progress(&bridge);
    wenv_error err = {0};
    wenv_status st;
    size_t covered = 0, overlapped = 0;
    WENV_BEGIN_WORK
    st = wenv_texel_raster(ub.buf, n_uv, tri, n_tri, width, height, border, tri_data, weight_data, &covered,
                           &overlapped, &progress, &err);
    WENV_END_WORK
    if (st) {
        if (!(bridge.raised && PyErr_Occurred()))
            wenv_py_raise(&err);
        goto done;
    }
    result = Py_BuildValue("(OOnn)", tri_out, weights_out, (Py_ssize_t)covered, (Py_ssize_t)overlapped);
done:
    Py_XDECREF(tri_out);
    Py_XDECREF(weights_out);
    PyMem_Free(tri);
    wenv_py_release_array(&ub, &uv_held);
    wenv_py_release_array(&tb, &tri_held);
    return result;
}

/* corner_values_at(values, corners, weights) -> (n, k) float32 */
static PyObject *corner_values_at(PyObject *self, PyObject *args, PyObject *kwargs)
{
    (void)self;
    static char *kwlist[] = {"values", "corners", "weights", NULL};
    PyObject *v_obj, *c_obj, *w_obj;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "OOO:corner_values_at", kwlist, &v_obj, &c_obj, &w_obj))
        return NULL;
    /* float32 rows are summed in float32, as numpy sums them; any other numbers in float64 */
    int single = 0;
    Py_buffer probe;
    if (PyObject_CheckBuffer(v_obj) && PyObject_GetBuffer(v_obj, &probe, PyBUF_FORMAT | PyBUF_STRIDES) == 0) {
        single = probe.format && (strcmp(probe.format, "f") == 0 || strcmp(probe.format, "<f") == 0);
        PyBuffer_Release(&probe);
    } else {
        PyErr_Clear();
    }
    Py_buffer vb, cb, wb;
    PyObject *v_held, *c_held, *w_held, *result = NULL;
    if (wenv_py_get_typed_array(v_obj, "values", single ? "float32" : "float64", 0, &vb, &v_held) < 0)
        return NULL;
    if (wenv_py_get_typed_array(c_obj, "corners", "int64", 0, &cb, &c_held) < 0) {
        wenv_py_release_array(&vb, &v_held);
        return NULL;
    }
    if (wenv_py_get_typed_array(w_obj, "weights", "float32", 0, &wb, &w_held) < 0) {
        wenv_py_release_array(&vb, &v_held);
        wenv_py_release_array(&cb, &c_held);
        return NULL;
    }
    if (vb.ndim != 2 || cb.ndim != 2 || cb.shape[1] != 3 || wb.ndim != 2 || wb.shape[1] != 3 ||
        wb.shape[0] != cb.shape[0]) {
        PyErr_SetString(PyExc_ValueError, "values must have shape (m, k), corners and weights (n, 3)");
        goto done;
    }
    Py_ssize_t shape[2] = {cb.shape[0], vb.shape[1]};
    void *out;
    if (!(result = wenv_py_new_array(2, shape, "float32", &out)))
        goto done;
    wenv_error err = {0};
    wenv_status st;
    WENV_BEGIN_WORK
    st = single ? wenv_corner_interpolate_f(vb.buf, (size_t)vb.shape[0], (size_t)vb.shape[1], cb.buf, wb.buf,
                                            (size_t)cb.shape[0], out, &err)
                : wenv_corner_interpolate(vb.buf, (size_t)vb.shape[0], (size_t)vb.shape[1], cb.buf, wb.buf,
                                          (size_t)cb.shape[0], out, &err);
    WENV_END_WORK
    if (st) {
        Py_CLEAR(result);
        wenv_py_raise(&err);
    }
done:
    wenv_py_release_array(&vb, &v_held);
    wenv_py_release_array(&cb, &c_held);
    wenv_py_release_array(&wb, &w_held);
    return result;
}

/* extend_margin(pixels, filled, margin) -> texels filled; both arrays written in place */
static PyObject *extend_margin(PyObject *self, PyObject *args, PyObject *kwargs)
{
    (void)self;
    static char *kwlist[] = {"pixels", "filled", "margin", NULL};
    PyObject *p_obj, *f_obj, *m_obj;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "OOO:extend_margin", kwlist, &p_obj, &f_obj, &m_obj))
        return NULL;
    size_t margin;
    if (wenv_py_get_size(m_obj, "margin", &margin) < 0)
        return NULL;
    Py_buffer pb, fb;
    PyObject *p_held, *f_held;
    if (wenv_py_get_typed_array(p_obj, "pixels", "float32", 1, &pb, &p_held) < 0)
        return NULL;
    if (wenv_py_get_typed_array(f_obj, "filled", "bool", 1, &fb, &f_held) < 0) {
        wenv_py_release_array(&pb, &p_held);
        return NULL;
    }
    PyObject *result = NULL;
    if (pb.ndim != 3 || fb.ndim != 2 || pb.shape[0] != fb.shape[0] || pb.shape[1] != fb.shape[1]) {
        PyErr_SetString(PyExc_ValueError, "pixels must have shape (height, width, channels) and filled (height, width)");
        goto done;
    }
    wenv_error err = {0};
    wenv_status st;
    size_t added = 0;
    WENV_BEGIN_WORK
    st = wenv_extend_margin(pb.buf, fb.buf, (size_t)pb.shape[1], (size_t)pb.shape[0], (size_t)pb.shape[2], margin,
                            &added, &err);
    WENV_END_WORK
    result = st ? wenv_py_raise(&err) : PyLong_FromSize_t(added);
done:
    wenv_py_release_array(&pb, &p_held);
    wenv_py_release_array(&fb, &f_held);
    return result;
}

static PyMethodDef bake_functions[] = {
    {"uv_texels", (PyCFunction)(void (*)(void))uv_texels, METH_VARARGS | METH_KEYWORDS,
     "uv_texels(uv, triangles, width, height, memory_budget_mb=1024, progress=None, border=False)\n--\n\n"
     "Which texel of a width x height image lies in which UV triangle: uv (n, 2) points, triangles (m, 3)\n"
     "indices into them.  Texel (x, y) has its centre at ((x + 0.5) / width, (y + 0.5) / height), row 0\n"
     "at v = 0 (Blender's order of Image.pixels).  Returns (triangle, weights, covered, overlapped):\n"
     "triangle (height, width) int32, the triangle holding each centre or -1; weights (height, width, 2)\n"
     "float32, the barycentric weights of its second and third corners (the first's is 1 minus both);\n"
     "covered, the texels in some triangle; overlapped, the texels a second triangle also holds (where\n"
     "islands overlap the first keeps them).  A centre on an edge two triangles share goes to one.\n"
     "border=True: each texel outside every triangle that touches one inside (8-neighbours) holds that\n"
     "neighbour's triangle t as -2 - t, with its centre's (extrapolated) weights in it.\n"
     "ValueError for an image of no texels or one whose bake would pass memory_budget_mb."},
    {"corner_values_at", (PyCFunction)(void (*)(void))corner_values_at, METH_VARARGS | METH_KEYWORDS,
     "corner_values_at(values, corners, weights)\n--\n\n"
     "Values given per face corner read at points by their barycentric weights: values (m, k), corners\n"
     "(n, 3) rows of it, weights (n, 3).  Returns (n, k) float32, each point's w0 v0 + w1 v1 + w2 v2 summed\n"
     "in that order as numpy sums it: in float32 for float32 values, else in float64.  ValueError for a\n"
     "corner that is not a row of values."},
    {"extend_margin", (PyCFunction)(void (*)(void))extend_margin, METH_VARARGS | METH_KEYWORDS,
     "extend_margin(pixels, filled, margin)\n--\n\n"
     "Carries the colours of the texels `filled` marks outwards by `margin` rings, in place (Blender's\n"
     "'Extend' margin): each ring's texels take the mean of the filled 8-neighbours they touch.  pixels:\n"
     "(height, width, channels) float32; filled: (height, width) bool, updated.  Returns the texels filled."},
    {NULL, NULL, 0, NULL},
};

int wenv_register_bake(PyObject *module) { return PyModule_AddFunctions(module, bake_functions); }
