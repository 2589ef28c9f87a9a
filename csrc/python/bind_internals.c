/* Private hooks (wenv._name), every one of them, that let the tests reach the numerical building
 * blocks directly: the octahedral maps, the Haar transform, the spherical harmonics, the microfacet
 * lobe's terms and a material's C evaluation paths.  Not part of the API. */
#include "python/module.h"

#include <omp.h>
#include <string.h>

#include "math/haar.h"
#include "math/maps.h"
#include "math/sparse.h"
#include "math/vector_math.h"
#include "math/spherical_harmonics.h"
#include "python/bind_envmap.h"
#include "python/bind_material.h"
#include "scene/material.h"
#include "scene/envmap_octahedral.h"


static PyObject *map_convert(PyObject *args, int hemi, int encode)
{
    PyObject *obj;
    if (!PyArg_ParseTuple(args, "O", &obj))
        return NULL;
    Py_buffer b;
    if (PyObject_GetBuffer(obj, &b, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) < 0)
        return NULL;
    size_t in_dim = encode ? 3 : 2, out_dim = encode ? 2 : 3;
    if (b.itemsize != 8 || b.ndim != 2 || (size_t)b.shape[1] != in_dim) {
        PyBuffer_Release(&b);
        PyErr_Format(PyExc_ValueError, "expected float64 (n, %zu)", in_dim);
        return NULL;
    }
    size_t n = (size_t)b.shape[0];
    Py_ssize_t shape[2] = {(Py_ssize_t)n, (Py_ssize_t)out_dim};
    float *out;
    PyObject *result = wenv_py_new_float_array(2, shape, &out);
    const double *in = b.buf;
    for (size_t i = 0; result && i < n; i++) {
        double r[3];
        if (encode) {
            if (hemi)
                wenv_hemi_encode(in + 3 * i, &r[0], &r[1]);
            else
                wenv_oct_encode(in + 3 * i, &r[0], &r[1]);
        } else if (hemi)
            wenv_hemi_decode(in[2 * i], in[2 * i + 1], r);
        else
            wenv_oct_decode(in[2 * i], in[2 * i + 1], r);
        for (size_t c = 0; c < out_dim; c++)
            out[out_dim * i + c] = (float)r[c];
    }
    PyBuffer_Release(&b);
    return result;
}

static PyObject *py_oct_encode(PyObject *s, PyObject *a) { (void)s; return map_convert(a, 0, 1); }
static PyObject *py_oct_decode(PyObject *s, PyObject *a) { (void)s; return map_convert(a, 0, 0); }
static PyObject *py_hemi_encode(PyObject *s, PyObject *a) { (void)s; return map_convert(a, 1, 1); }
static PyObject *py_hemi_decode(PyObject *s, PyObject *a) { (void)s; return map_convert(a, 1, 0); }

static PyObject *py_texel_solid_angles(PyObject *self, PyObject *args)
{
    (void)self;
    Py_ssize_t n;
    int hemi;
    if (!PyArg_ParseTuple(args, "np", &n, &hemi))
        return NULL;
    if (n < 2 || n > 4096 || n % 2) {
        PyErr_SetString(PyExc_ValueError, "n must be even in [2, 4096]");
        return NULL;
    }
    PyObject *list = PyList_New(n * n);
    for (Py_ssize_t t = 0; list && t < n * n; t++) {
        double w = hemi ? wenv_hemi_texel_solid_angle((size_t)n, (size_t)(t % n), (size_t)(t / n))
                        : wenv_oct_texel_solid_angle((size_t)n, (size_t)(t % n), (size_t)(t / n));
        PyList_SET_ITEM(list, t, PyFloat_FromDouble(w));
    }
    return list;
}

/* wenv_oct_texel_solid_angles: every texel at once, by the map's symmetries. */
static PyObject *py_oct_texel_solid_angles_all(PyObject *self, PyObject *args)
{
    (void)self;
    Py_ssize_t n;
    if (!PyArg_ParseTuple(args, "n", &n))
        return NULL;
    if (n < 2 || n > 4096 || n % 2) {
        PyErr_SetString(PyExc_ValueError, "n must be even in [2, 4096]");
        return NULL;
    }
    double *omega = PyMem_Malloc((size_t)(n * n) * sizeof(double));
    if (!omega)
        return PyErr_NoMemory();
    wenv_oct_texel_solid_angles((size_t)n, omega);
    PyObject *list = PyList_New(n * n);
    for (Py_ssize_t t = 0; list && t < n * n; t++)
        PyList_SET_ITEM(list, t, PyFloat_FromDouble(omega[t]));
    PyMem_Free(omega);
    return list;
}

static PyObject *py_haar2d(PyObject *self, PyObject *args, PyObject *kwargs)
{
    (void)self;
    static char *kwlist[] = {"image", "inverse", NULL};
    PyObject *obj;
    int inverse = 0;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "O|p", kwlist, &obj, &inverse))
        return NULL;
    Py_buffer b;
    if (PyObject_GetBuffer(obj, &b, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) < 0)
        return NULL;
    if (b.itemsize != 4 || b.ndim != 3 || b.shape[0] != b.shape[1] || !wenv_is_power_of_two((size_t)b.shape[0])) {
        PyBuffer_Release(&b);
        PyErr_SetString(PyExc_ValueError, "image must be float32 (n, n, channels) with n a power of two");
        return NULL;
    }
    size_t n = (size_t)b.shape[0], ch = (size_t)b.shape[2];
    Py_ssize_t shape[3] = {b.shape[0], b.shape[1], b.shape[2]};
    float *out;
    PyObject *result = wenv_py_new_float_array(3, shape, &out);
    float *scratch = PyMem_Malloc(wenv_haar2d_scratch_floats(n, ch) * sizeof(float) + 1);
    if (result && scratch) {
        memcpy(out, b.buf, n * n * ch * sizeof(float));
        if (inverse)
            wenv_haar2d_inverse(out, n, ch, scratch);
        else
            wenv_haar2d_forward(out, n, ch, scratch);
    } else if (!scratch) {
        Py_CLEAR(result);
        PyErr_NoMemory();
    }
    PyMem_Free(scratch);
    PyBuffer_Release(&b);
    return result;
}


static int get_doubles(PyObject *obj, const char *name, Py_buffer *b)
{
    if (PyObject_GetBuffer(obj, b, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) < 0)
        return -1;
    if (b->itemsize != 8 || !b->format || strchr(b->format, 'd') == NULL) {
        PyBuffer_Release(b);
        PyErr_Format(PyExc_TypeError, "%s must be a C-contiguous float64 array", name);
        return -1;
    }
    return 0;
}

static int get_order(Py_ssize_t order)
{
    if (order < 0 || order > WENV_SH_ORDER_MAX) {
        PyErr_Format(PyExc_ValueError, "order must be in [0, %d]", WENV_SH_ORDER_MAX);
        return -1;
    }
    return 0;
}

/* _sh_basis(dirs float64 (n, 3) unit, order) -> float64 (n, (order + 1)^2) */
static PyObject *py_sh_basis(PyObject *self, PyObject *args)
{
    (void)self;
    PyObject *obj;
    Py_ssize_t order;
    if (!PyArg_ParseTuple(args, "On", &obj, &order) || get_order(order) < 0)
        return NULL;
    Py_buffer b;
    if (get_doubles(obj, "dirs", &b) < 0)
        return NULL;
    if (b.ndim != 2 || b.shape[1] != 3) {
        PyBuffer_Release(&b);
        PyErr_SetString(PyExc_ValueError, "dirs must have shape (n, 3)");
        return NULL;
    }
    size_t n = (size_t)b.shape[0], count = wenv_sh_count((size_t)order);
    Py_ssize_t shape[2] = {(Py_ssize_t)n, (Py_ssize_t)count};
    void *data;
    PyObject *result = wenv_py_new_array(2, shape, "float64", &data);
    for (size_t i = 0; result && i < n; i++)
        wenv_sh_eval((size_t)order, (const double *)b.buf + 3 * i, (double *)data + i * count);
    PyBuffer_Release(&b);
    return result;
}

/* _sh_rotate(coeffs float64 ((order + 1)^2,), frame float64 (3, 3) rows t, b, n) -> coefficients of
 * the function seen in the frame, f(F^T w) */
static PyObject *py_sh_rotate(PyObject *self, PyObject *args)
{
    (void)self;
    PyObject *cobj, *fobj;
    if (!PyArg_ParseTuple(args, "OO", &cobj, &fobj))
        return NULL;
    Py_buffer cb, fb;
    if (get_doubles(cobj, "coeffs", &cb) < 0)
        return NULL;
    if (get_doubles(fobj, "frame", &fb) < 0) {
        PyBuffer_Release(&cb);
        return NULL;
    }
    PyObject *result = NULL;
    size_t count = (size_t)(cb.len / 8), order = 0;
    while (wenv_sh_count(order) < count)
        order++;
    if (wenv_sh_count(order) != count || order > WENV_SH_ORDER_MAX || fb.len != 9 * 8) {
        PyErr_SetString(PyExc_ValueError, "coeffs must hold (order + 1)**2 values and frame 3 x 3");
        goto done;
    }
    wenv_sh_rotation *rot = NULL;
    wenv_error err = {0};
    if (wenv_sh_rotation_create(&rot, order, &err)) {
        wenv_py_raise(&err);
        goto done;
    }
    double *work = PyMem_Malloc(count * sizeof(double));
    Py_ssize_t shape[1] = {(Py_ssize_t)count};
    void *data;
    result = work ? wenv_py_new_array(1, shape, "float64", &data) : PyErr_NoMemory();
    if (result) {
        double a, b, g;
        wenv_sh_frame_angles(fb.buf, &a, &b, &g);
        wenv_sh_rotate_zyz(rot, a, b, g, cb.buf, data, 1, work);
    }
    PyMem_Free(work);
    wenv_sh_rotation_free(rot);
done:
    PyBuffer_Release(&cb);
    PyBuffer_Release(&fb);
    return result;
}

/* wenv_oct_from_envmap_sides: the octahedral maps of an Environment at the given sides, made in one
 * pass over its image (a list of (side, side, 3) arrays). */
static PyObject *py_oct_maps(PyObject *self, PyObject *args)
{
    (void)self;
    PyObject *env_obj, *sides_obj;
    if (!PyArg_ParseTuple(args, "OO", &env_obj, &sides_obj))
        return NULL;
    const struct wenv_envmap *env = wenv_py_envmap(env_obj, "env");
    if (!env)
        return NULL;
    PyObject *seq = PySequence_Fast(sides_obj, "sides must be a sequence of even sides");
    if (!seq)
        return NULL;
    Py_ssize_t count = PySequence_Fast_GET_SIZE(seq);
    if (count < 1 || count > WENV_OCT_SIDES_MAX) {
        Py_DECREF(seq);
        return PyErr_Format(PyExc_ValueError, "sides must hold 1 to %d sides", WENV_OCT_SIDES_MAX);
    }
    size_t sides[WENV_OCT_SIDES_MAX];
    float *maps[WENV_OCT_SIDES_MAX];
    PyObject *list = PyList_New(count);
    for (Py_ssize_t k = 0; list && k < count; k++) {
        Py_ssize_t n = PyNumber_AsSsize_t(PySequence_Fast_GET_ITEM(seq, k), PyExc_OverflowError);
        if (n == -1 && PyErr_Occurred()) {
            Py_CLEAR(list);
            break;
        }
        if (n < 2 || n > 1024 || n % 2) {
            PyErr_SetString(PyExc_ValueError, "sides must be even, in [2, 1024]");
            Py_CLEAR(list);
            break;
        }
        Py_ssize_t shape[3] = {n, n, 3};
        PyObject *arr = wenv_py_new_float_array(3, shape, &maps[k]);
        if (!arr) {
            Py_CLEAR(list);
            break;
        }
        sides[k] = (size_t)n;
        PyList_SET_ITEM(list, k, arr);
    }
    Py_DECREF(seq);
    if (!list)
        return NULL;
    wenv_error err = {0};
    wenv_status st;
    WENV_BEGIN_WORK
    st = wenv_oct_from_envmap_sides(env, (size_t)count, sides, maps, NULL, 0, &err);
    WENV_END_WORK
    if (st) {
        Py_DECREF(list);
        return wenv_py_raise(&err);
    }
    return list;
}

/* The number of threads an OpenMP region of wenv's work gets when started from the calling thread. */
static PyObject *py_work_threads(PyObject *self, PyObject *unused)
{
    (void)self;
    (void)unused;
    int threads = 0;
    WENV_BEGIN_WORK
#pragma omp parallel
    {
#pragma omp single
        threads = omp_get_num_threads();
    }
    WENV_END_WORK
    return PyLong_FromLong(threads);
}

/* ---------------------------------------------------------------- the microfacet lobe's terms */

typedef double (*unary_fn)(double x, const void *ctx);

/* Applies fn to a number (returns float) or to anything numpy turns into a float64 array (returns
 * an array of the same shape). */
static PyObject *map_unary(PyObject *obj, const char *name, unary_fn fn, const void *ctx)
{
    if (PyFloat_Check(obj) || PyLong_Check(obj)) {
        double x;
        if (wenv_py_get_finite(obj, name, &x) < 0)
            return NULL;
        return PyFloat_FromDouble(fn(x, ctx));
    }
    PyObject *numpy = PyImport_ImportModule("numpy");
    if (!numpy)
        return NULL;
    PyObject *arr = PyObject_CallMethod(numpy, "ascontiguousarray", "Os", obj, "float64");
    Py_DECREF(numpy);
    if (!arr)
        return NULL;
    Py_buffer in;
    if (PyObject_GetBuffer(arr, &in, PyBUF_C_CONTIGUOUS | PyBUF_ND) < 0) {
        Py_DECREF(arr);
        return NULL;
    }
    double *out;
    PyObject *result = wenv_py_new_array(in.ndim, in.shape ? in.shape : (Py_ssize_t[]){1}, "float64", (void **)&out);
    if (result) {
        const double *x = in.buf;
        size_t count = (size_t)(in.len / (Py_ssize_t)sizeof(double));
        for (size_t i = 0; i < count; i++) {
            if (!isfinite(x[i])) {
                Py_CLEAR(result);
                PyErr_Format(PyExc_ValueError, "%s must be finite", name);
                break;
            }
            out[i] = fn(x[i], ctx);
        }
    }
    PyBuffer_Release(&in);
    Py_DECREF(arr);
    return result;
}

typedef struct {
    wenv_distribution dist;
    double param; /* alpha or ior */
} unary_ctx;

static double fresnel_fn(double x, const void *ctx) { return wenv_fresnel_dielectric(x, ((const unary_ctx *)ctx)->param); }

static double ndf_fn(double x, const void *ctx)
{
    const unary_ctx *c = ctx;
    return wenv_ndf(c->dist, c->param, x);
}

static double lambda_fn(double x, const void *ctx)
{
    const unary_ctx *c = ctx;
    return wenv_smith_lambda(c->dist, c->param, x);
}

static int check_range(double v, const char *name, double lo, int lo_open, double hi)
{
    if ((lo_open ? !(v > lo) : !(v >= lo)) || v > hi) {
        wenv_py_errorf(PyExc_ValueError, "%s must be in %s%g, %g], got %g", name, lo_open ? "(" : "[", lo, hi, v);
        return -1;
    }
    return 0;
}

static PyObject *py_fresnel(PyObject *self, PyObject *args)
{
    (void)self;
    PyObject *x, *ior_obj;
    unary_ctx c = {WENV_NDF_BECKMANN, 0.0};
    if (!PyArg_ParseTuple(args, "OO:_fresnel", &x, &ior_obj) || wenv_py_get_finite(ior_obj, "ior", &c.param) < 0 ||
        check_range(c.param, "ior", 1.0, 1, WENV_IOR_MAX) < 0)
        return NULL;
    return map_unary(x, "cos_i", fresnel_fn, &c);
}

static PyObject *dist_helper(PyObject *args, const char *fmt, const char *xname, unary_fn fn)
{
    PyObject *dist_obj, *m_obj, *x;
    if (!PyArg_ParseTuple(args, fmt, &dist_obj, &m_obj, &x))
        return NULL;
    int dist;
    unary_ctx c;
    if (wenv_py_parse_choice(dist_obj, "distribution", wenv_py_distribution_names, 2, &dist) < 0 ||
        wenv_py_get_finite(m_obj, "alpha", &c.param) < 0 ||
        check_range(c.param, "alpha", WENV_ALPHA_MIN, 0, WENV_ALPHA_MAX) < 0)
        return NULL;
    c.dist = (wenv_distribution)dist;
    return map_unary(x, xname, fn, &c);
}

static PyObject *py_ndf(PyObject *self, PyObject *args)
{
    (void)self;
    return dist_helper(args, "OOO:_ndf", "cos_h", ndf_fn);
}

static PyObject *py_smith_lambda(PyObject *self, PyObject *args)
{
    (void)self;
    return dist_helper(args, "OOO:_smith_lambda", "cos_theta", lambda_fn);
}

static PyObject *py_lobe_albedo(PyObject *self, PyObject *args, PyObject *kwds)
{
    (void)self;
    static char *kwlist[] = {"wo", "alpha", "distribution", "shadowing", "ior", "fresnel", "samples", NULL};
    PyObject *wo_obj, *m_obj, *dist_obj = NULL, *shadow_obj = NULL, *ior_obj = NULL, *samples_obj = NULL;
    int fresnel = 0;
    if (!PyArg_ParseTupleAndKeywords(args, kwds, "OO|OOOpO:_lobe_albedo", kwlist, &wo_obj, &m_obj, &dist_obj,
                                     &shadow_obj, &ior_obj, &fresnel, &samples_obj))
        return NULL;
    wenv_lobe lobe = {{1.0, 1.0, 1.0}, 0.0, 1.5, WENV_NDF_BECKMANN};
    int dist = WENV_NDF_BECKMANN, shadowing = WENV_SHADOW_SMITH;
    size_t samples;
    if (wenv_py_get_finite(m_obj, "alpha", &lobe.alpha) < 0 ||
        (dist_obj && wenv_py_parse_choice(dist_obj, "distribution", wenv_py_distribution_names, 2, &dist) < 0) ||
        (shadow_obj && wenv_py_parse_choice(shadow_obj, "shadowing", wenv_py_shadowing_names, 2, &shadowing) < 0) ||
        (ior_obj && wenv_py_get_finite(ior_obj, "ior", &lobe.ior) < 0) || wenv_py_parse_samples(samples_obj, &samples) < 0)
        return NULL;
    lobe.distribution = (wenv_distribution)dist;
    /* Validate the lobe through the core's own rules. */
    wenv_material *probe;
    wenv_error err = {0};
    double zero[3] = {0.0, 0.0, 0.0};
    if (wenv_cook_torrance_create(&probe, zero, &lobe, 1, (wenv_shadowing)shadowing, &err) != WENV_OK)
        return wenv_py_raise(&err);
    wenv_material_free(probe);
    Py_buffer view;
    size_t n;
    if (wenv_py_get_vec3_array(wo_obj, "wo", 1, &view, &n, NULL) < 0)
        return NULL;
    if (n != 1) {
        PyBuffer_Release(&view);
        PyErr_SetString(PyExc_ValueError, "wo must be a single direction");
        return NULL;
    }
    double *wo = wenv_py_normalised_rows(&view, 1);
    PyBuffer_Release(&view);
    if (!wo)
        return NULL;
    double albedo = 0.0;
    wenv_status st;
    WENV_BEGIN_WORK
    st = wenv_lobe_albedo(&lobe, (wenv_shadowing)shadowing, wo, samples, fresnel, &albedo, &err);
    WENV_END_WORK
    PyMem_Free(wo);
    if (st != WENV_OK)
        return wenv_py_raise(&err);
    return PyFloat_FromDouble(albedo);
}

/* ---------------------------------------------------------------- a material's C paths */

static PyObject *py_specular(PyObject *self, PyObject *args, PyObject *kwds, wenv_py_eval_mode mode)
{
    (void)self;
    Py_ssize_t n = PyTuple_GET_SIZE(args);
    if (n < 1) {
        PyErr_SetString(PyExc_TypeError, "expected (material, wi, wo)");
        return NULL;
    }
    PyObject *rest = PyTuple_GetSlice(args, 1, n);
    if (!rest)
        return NULL;
    PyObject *r = wenv_py_material_eval(PyTuple_GET_ITEM(args, 0), rest, kwds, mode);
    Py_DECREF(rest);
    return r;
}

static PyObject *py_specular_double(PyObject *self, PyObject *args, PyObject *kwds)
{
    return py_specular(self, args, kwds, WENV_PY_EVAL_SPECULAR);
}
static PyObject *py_specular_batch(PyObject *self, PyObject *args, PyObject *kwds)
{
    return py_specular(self, args, kwds, WENV_PY_EVAL_SPECULAR_BATCH);
}
static PyObject *py_specular_float(PyObject *self, PyObject *args, PyObject *kwds)
{
    return py_specular(self, args, kwds, WENV_PY_EVAL_SPECULAR_FLOAT);
}

/* _sparse_rows_dot(index (n, k) uint16, weight (n, k) float32, rgb (m, 3) float32) -> (n, 3) float32:
 * wenv_sparse_rows_dot, the floor benchmarks measure a view's shading against. */
static PyObject *py_sparse_rows_dot(PyObject *self, PyObject *args)
{
    (void)self;
    PyObject *i_obj, *w_obj, *rgb_obj, *i_held = NULL, *w_held = NULL, *rgb_held = NULL, *out = NULL;
    Py_buffer ib, wb, rb;
    if (!PyArg_ParseTuple(args, "OOO", &i_obj, &w_obj, &rgb_obj))
        return NULL;
    if (wenv_py_get_typed_array(i_obj, "index", "uint16", 0, &ib, &i_held) < 0)
        return NULL;
    if (wenv_py_get_typed_array(w_obj, "weight", "float32", 0, &wb, &w_held) < 0) {
        wenv_py_release_array(&ib, &i_held);
        return NULL;
    }
    if (wenv_py_get_typed_array(rgb_obj, "rgb", "float32", 0, &rb, &rgb_held) < 0) {
        wenv_py_release_array(&ib, &i_held);
        wenv_py_release_array(&wb, &w_held);
        return NULL;
    }
    if (ib.ndim != 2 || wb.ndim != 2 || ib.shape[0] != wb.shape[0] || ib.shape[1] != wb.shape[1]) {
        PyErr_SetString(PyExc_ValueError, "index and weight must be (n, k) arrays of the same shape");
    } else if (rb.ndim != 2 || rb.shape[1] != 3 || rb.shape[0] < 1) {
        PyErr_SetString(PyExc_ValueError, "rgb must be an (m, 3) array, m >= 1");
    } else {
        const uint16_t *index = ib.buf;
        size_t n = (size_t)ib.shape[0], k = (size_t)ib.shape[1], m = (size_t)rb.shape[0], top = 0;
        for (size_t t = 0; t < n * k; t++)
            top = index[t] > top ? index[t] : top;
        float *data;
        Py_ssize_t shape[2] = {(Py_ssize_t)n, 3};
        if (n > 0 && k > 0 && top >= m)
            wenv_py_errorf(PyExc_ValueError, "index holds %zu, past rgb's %zu rows", top, m);
        else if ((out = wenv_py_new_float_array(2, shape, &data))) {
            float *rgbx = wenv_rgbx_from_rgb(rb.buf, m);
            if (!rgbx) {
                Py_CLEAR(out);
                PyErr_NoMemory();
            } else {
                Py_BEGIN_ALLOW_THREADS
                wenv_sparse_rows_dot(index, wb.buf, n, k, rgbx, data);
                Py_END_ALLOW_THREADS
                free(rgbx);
            }
        }
    }
    wenv_py_release_array(&ib, &i_held);
    wenv_py_release_array(&wb, &w_held);
    wenv_py_release_array(&rb, &rgb_held);
    return out;
}

static PyMethodDef internal_functions[] = {
    {"_sparse_rows_dot", py_sparse_rows_dot, METH_VARARGS,
     "_sparse_rows_dot(index, weight, rgb)\n--\n\nEach row's (index, weight) terms against rgb's rows: the "
     "per-vertex sparse dot product, a view's floor."},
    {"_work_threads", py_work_threads, METH_NOARGS, NULL},
    {"_oct_encode", py_oct_encode, METH_VARARGS, NULL},
    {"_oct_decode", py_oct_decode, METH_VARARGS, NULL},
    {"_hemi_encode", py_hemi_encode, METH_VARARGS, NULL},
    {"_hemi_decode", py_hemi_decode, METH_VARARGS, NULL},
    {"_texel_solid_angles", py_texel_solid_angles, METH_VARARGS, NULL},
    {"_oct_texel_solid_angles_all", py_oct_texel_solid_angles_all, METH_VARARGS, NULL},
    {"_oct_maps", py_oct_maps, METH_VARARGS, NULL},
    {"_haar2d", (PyCFunction)(void (*)(void))py_haar2d, METH_VARARGS | METH_KEYWORDS, NULL},
    {"_sh_basis", py_sh_basis, METH_VARARGS, NULL},
    {"_sh_rotate", py_sh_rotate, METH_VARARGS, NULL},
    {"_fresnel", py_fresnel, METH_VARARGS, "_fresnel(cos_i, ior)\n--\n\nUnpolarised dielectric Fresnel."},
    {"_ndf", py_ndf, METH_VARARGS, "_ndf(distribution, alpha, cos_h)\n--\n\nMicrofacet distribution D."},
    {"_smith_lambda", py_smith_lambda, METH_VARARGS, "_smith_lambda(distribution, alpha, cos_theta)\n--\n\nSmith Lambda."},
    {"_lobe_albedo", (PyCFunction)(void (*)(void))py_lobe_albedo, METH_VARARGS | METH_KEYWORDS,
     "_lobe_albedo(wo, alpha, distribution='beckmann', shadowing='smith', ior=1.5, fresnel=False, "
     "samples=128)\n--\n\nAlbedo of one white lobe; fresnel=False sets F = 1 (white-furnace test)."},
    {"_specular", (PyCFunction)(void (*)(void))py_specular_double, METH_VARARGS | METH_KEYWORDS,
     "_specular(material, wi, wo)\n--\n\nThe lobes only, times cos_i, through the double evaluation."},
    {"_specular_batch", (PyCFunction)(void (*)(void))py_specular_batch, METH_VARARGS | METH_KEYWORDS,
     "_specular_batch(material, wi, wo)\n--\n\nAs _specular through the one-view batch; wo must be single."},
    {"_specular_float", (PyCFunction)(void (*)(void))py_specular_float, METH_VARARGS | METH_KEYWORDS,
     "_specular_float(material, wi, wo)\n--\n\nAs _specular through the float path the exact lights use "
     "(0 if the model's view terms do not fit)."},
    {NULL, NULL, 0, NULL},
};

int wenv_register_internals(PyObject *module) { return PyModule_AddFunctions(module, internal_functions); }
