/* Python glue for distant environments: the wenv.Environment type and wenv.load_environment. */
#include "python/bind_envmap.h"
#include "python/module.h"

#include <string.h>

#include "auto/autoquality.h"
#include "scene/envmap.h"

/* Above this many directions a lookup releases the GIL (below it the switch costs more). */
#define LOOKUP_NOGIL_MIN 1024

typedef struct {
    PyObject_HEAD
    wenv_envmap *env; /* owned, never NULL once constructed; immutable */
    wenv_auto_analysis *auto_analysis; /* owned; made on quality="auto"'s first use, filled as choices need */
} EnvironmentObject;

static PyTypeObject EnvironmentType;

const struct wenv_envmap *wenv_py_envmap(PyObject *obj, const char *name)
{
    if (!obj || !PyObject_TypeCheck(obj, &EnvironmentType)) {
        PyErr_Format(PyExc_TypeError, "%s must be a wenv.Environment, got %.100s", name,
                     obj ? Py_TYPE(obj)->tp_name : "nothing");
        return NULL;
    }
    return ((EnvironmentObject *)obj)->env;
}

struct wenv_auto_analysis *wenv_py_envmap_auto_analysis(PyObject *obj)
{
    EnvironmentObject *self = (EnvironmentObject *)obj;
    if (!self->auto_analysis) {
        wenv_error err = {0};
        if (wenv_auto_analysis_create(&self->auto_analysis, self->env, &err)) {
            wenv_py_raise(&err);
            return NULL;
        }
    }
    return self->auto_analysis;
}

/* Wraps `env` (ownership passes to the new object, or it is freed on failure). */
static PyObject *wrap_envmap(wenv_envmap *env)
{
    EnvironmentObject *self = (EnvironmentObject *)EnvironmentType.tp_alloc(&EnvironmentType, 0);
    if (!self) {
        wenv_envmap_free(env);
        return NULL;
    }
    self->env = env;
    return (PyObject *)self;
}

static int parse_projection(PyObject *obj, wenv_projection *out)
{
    *out = WENV_PROJ_EQUIRECT;
    if (!obj)
        return 0;
    if (!PyUnicode_Check(obj)) {
        PyErr_Format(PyExc_TypeError, "projection must be a str (one of " WENV_ENVMAP_PROJECTION_NAMES "), got %.100s",
                     Py_TYPE(obj)->tp_name);
        return -1;
    }
    const char *name = PyUnicode_AsUTF8(obj);
    if (!name)
        return -1;
    if (wenv_envmap_parse_projection(name, out) < 0) {
        PyErr_Format(PyExc_ValueError, "unknown projection %R: must be one of " WENV_ENVMAP_PROJECTION_NAMES, obj);
        return -1;
    }
    return 0;
}

/* rotation and strength from optional objects (NULL or None keeps *rotation / *strength). */
static int parse_transform(PyObject *rot_obj, PyObject *str_obj, double *rotation, double *strength)
{
    if (rot_obj && rot_obj != Py_None && wenv_py_get_finite(rot_obj, "rotation", rotation) < 0)
        return -1;
    if (str_obj && str_obj != Py_None) {
        if (wenv_py_get_finite(str_obj, "strength", strength) < 0)
            return -1;
        if (*strength < 0.0) {
            wenv_py_errorf(PyExc_ValueError, "strength must be >= 0, got %g", *strength);
            return -1;
        }
    }
    return 0;
}

/* Environment(pixels, projection="equirect", rotation=0.0, strength=1.0) */
static PyObject *environment_new(PyTypeObject *type, PyObject *args, PyObject *kwds)
{
    (void)type;
    static char *kwlist[] = {"pixels", "projection", "rotation", "strength", NULL};
    PyObject *pixels, *proj_obj = NULL, *rot_obj = NULL, *str_obj = NULL;
    if (!PyArg_ParseTupleAndKeywords(args, kwds, "O|OOO:Environment", kwlist, &pixels, &proj_obj, &rot_obj,
                                     &str_obj))
        return NULL;
    wenv_projection projection;
    double rotation = 0.0, strength = 1.0;
    if (parse_projection(proj_obj, &projection) < 0 || parse_transform(rot_obj, str_obj, &rotation, &strength) < 0)
        return NULL;
    if (!PyObject_CheckBuffer(pixels)) {
        PyErr_Format(PyExc_TypeError, "pixels must be a float32 array of shape (H, W, 3) or (H, W, 4), got %.100s",
                     Py_TYPE(pixels)->tp_name);
        return NULL;
    }
    Py_buffer view;
    if (PyObject_GetBuffer(pixels, &view, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) < 0) {
        PyErr_Clear();
        PyErr_SetString(PyExc_ValueError, "pixels must be C-contiguous (use numpy.ascontiguousarray)");
        return NULL;
    }
    const char *fmt = view.format ? view.format : "B";
    const char *f = fmt;
    if ((f[0] == '<' || f[0] == '=' || f[0] == '@') && f[1])
        f++;
    if (view.itemsize != 4 || f[0] != 'f' || f[1] != '\0') {
        PyErr_Format(PyExc_TypeError, "pixels must have dtype float32, got format '%s'", fmt);
        PyBuffer_Release(&view);
        return NULL;
    }
    if (view.ndim != 3 || (view.shape[2] != 3 && view.shape[2] != 4)) {
        if (view.ndim == 3)
            PyErr_Format(PyExc_ValueError, "pixels must have shape (H, W, 3) or (H, W, 4), got (%zd, %zd, %zd)",
                         view.shape[0], view.shape[1], view.shape[2]);
        else
            PyErr_Format(PyExc_ValueError, "pixels must have shape (H, W, 3) or (H, W, 4), got %d dimensions",
                         view.ndim);
        PyBuffer_Release(&view);
        return NULL;
    }
    wenv_envmap *env = NULL;
    wenv_error err = {WENV_OK, ""};
    size_t h = (size_t)view.shape[0], w = (size_t)view.shape[1], c = (size_t)view.shape[2];
    wenv_status status;
    WENV_BEGIN_WORK
    status = wenv_envmap_create(&env, view.buf, h, w, c, projection, rotation, strength, &err);
    WENV_END_WORK
    PyBuffer_Release(&view);
    if (status != WENV_OK)
        return wenv_py_raise(&err);
    return wrap_envmap(env);
}

static void environment_dealloc(PyObject *self)
{
    wenv_auto_analysis_free(((EnvironmentObject *)self)->auto_analysis);
    wenv_envmap_free(((EnvironmentObject *)self)->env);
    Py_TYPE(self)->tp_free(self);
}

static PyObject *environment_repr(PyObject *self)
{
    const wenv_envmap *env = ((EnvironmentObject *)self)->env;
    char text[200];
    /* PyUnicode_FromFormat has no %g */
    snprintf(text, sizeof text, "wenv.Environment(%zux%zu, projection='%s', rotation=%.17g, strength=%.17g)",
             wenv_envmap_width(env), wenv_envmap_height(env),
             wenv_envmap_projection_name(wenv_envmap_projection(env)), wenv_envmap_rotation(env),
             wenv_envmap_strength(env));
    return PyUnicode_FromString(text);
}

static PyObject *get_width(PyObject *self, void *closure)
{
    (void)closure;
    return PyLong_FromSize_t(wenv_envmap_width(((EnvironmentObject *)self)->env));
}

static PyObject *get_height(PyObject *self, void *closure)
{
    (void)closure;
    return PyLong_FromSize_t(wenv_envmap_height(((EnvironmentObject *)self)->env));
}

static PyObject *get_projection(PyObject *self, void *closure)
{
    (void)closure;
    return PyUnicode_FromString(wenv_envmap_projection_name(wenv_envmap_projection(((EnvironmentObject *)self)->env)));
}

static PyObject *get_rotation(PyObject *self, void *closure)
{
    (void)closure;
    return PyFloat_FromDouble(wenv_envmap_rotation(((EnvironmentObject *)self)->env));
}

static PyObject *get_strength(PyObject *self, void *closure)
{
    (void)closure;
    return PyFloat_FromDouble(wenv_envmap_strength(((EnvironmentObject *)self)->env));
}

static PyObject *get_pixels(PyObject *self, void *closure)
{
    (void)closure;
    const wenv_envmap *env = ((EnvironmentObject *)self)->env;
    Py_ssize_t shape[3] = {(Py_ssize_t)wenv_envmap_height(env), (Py_ssize_t)wenv_envmap_width(env), 3};
    float *data;
    PyObject *array = wenv_py_new_float_array(3, shape, &data);
    if (array)
        memcpy(data, wenv_envmap_pixels(env), (size_t)shape[0] * (size_t)shape[1] * 3 * sizeof(float));
    return array;
}

static PyObject *environment_lookup(PyObject *self, PyObject *dirs)
{
    const wenv_envmap *env = ((EnvironmentObject *)self)->env;
    Py_buffer view;
    size_t n;
    int single;
    if (wenv_py_get_vec3_array(dirs, "dirs", 1, &view, &n, &single) < 0)
        return NULL;
    Py_ssize_t shape[2] = {(Py_ssize_t)n, 3};
    float *out;
    PyObject *result = single ? wenv_py_new_float_array(1, shape + 1, &out) : wenv_py_new_float_array(2, shape, &out);
    if (!result) {
        PyBuffer_Release(&view);
        return NULL;
    }
    if (n >= LOOKUP_NOGIL_MIN) {
        WENV_BEGIN_WORK
        wenv_envmap_lookup_many(env, view.buf, n, out);
        WENV_END_WORK
    } else {
        wenv_envmap_lookup_many(env, view.buf, n, out);
    }
    PyBuffer_Release(&view);
    return result;
}

static PyObject *environment_with_transform(PyObject *self, PyObject *args, PyObject *kwds)
{
    static char *kwlist[] = {"rotation", "strength", NULL};
    PyObject *rot_obj = NULL, *str_obj = NULL;
    if (!PyArg_ParseTupleAndKeywords(args, kwds, "|OO:with_transform", kwlist, &rot_obj, &str_obj))
        return NULL;
    const wenv_envmap *env = ((EnvironmentObject *)self)->env;
    double rotation = wenv_envmap_rotation(env), strength = wenv_envmap_strength(env);
    if (parse_transform(rot_obj, str_obj, &rotation, &strength) < 0)
        return NULL;
    wenv_envmap *copy = NULL;
    wenv_error err = {WENV_OK, ""};
    wenv_status status;
    WENV_BEGIN_WORK
    status = wenv_envmap_with_transform(&copy, env, rotation, strength, &err);
    WENV_END_WORK
    if (status != WENV_OK)
        return wenv_py_raise(&err);
    return wrap_envmap(copy);
}

static PyObject *environment_solid_angles(PyObject *self, PyObject *unused)
{
    (void)unused;
    const wenv_envmap *env = ((EnvironmentObject *)self)->env;
    size_t h = wenv_envmap_height(env), w = wenv_envmap_width(env);
    Py_ssize_t shape[2] = {(Py_ssize_t)h, (Py_ssize_t)w};
    void *storage = NULL;
    PyObject *array = wenv_py_new_array(2, shape, "float64", &storage);
    if (!array)
        return NULL;
    double *data = storage;
    WENV_BEGIN_WORK
    for (size_t r = 0; r < h; r++)
        for (size_t c = 0; c < w; c++)
            data[r * w + c] = wenv_envmap_pixel_solid_angle(env, r, c);
    WENV_END_WORK
    return array;
}

static PyObject *environment_samples(PyObject *self, PyObject *unused)
{
    (void)unused;
    const wenv_envmap *env = ((EnvironmentObject *)self)->env;
    size_t total = wenv_envmap_height(env) * wenv_envmap_width(env) * 3;
    float *dirs = PyMem_RawMalloc(total * sizeof(float)), *flux = PyMem_RawMalloc(total * sizeof(float));
    if (!dirs || !flux) {
        PyMem_RawFree(dirs);
        PyMem_RawFree(flux);
        return PyErr_NoMemory();
    }
    size_t m;
    WENV_BEGIN_WORK
    m = wenv_envmap_samples(env, dirs, flux, NULL);
    WENV_END_WORK
    Py_ssize_t shape[2] = {(Py_ssize_t)m, 3};
    float *d_out, *f_out;
    PyObject *d_arr = wenv_py_new_float_array(2, shape, &d_out);
    PyObject *f_arr = d_arr ? wenv_py_new_float_array(2, shape, &f_out) : NULL;
    if (f_arr) {
        memcpy(d_out, dirs, m * 3 * sizeof(float));
        memcpy(f_out, flux, m * 3 * sizeof(float));
    }
    PyMem_RawFree(dirs);
    PyMem_RawFree(flux);
    if (!f_arr) {
        Py_XDECREF(d_arr);
        return NULL;
    }
    PyObject *result = PyTuple_Pack(2, d_arr, f_arr);
    Py_DECREF(d_arr);
    Py_DECREF(f_arr);
    return result;
}

static PyGetSetDef environment_getset[] = {
    {"width", get_width, NULL, "Image width in pixels.", NULL},
    {"height", get_height, NULL, "Image height in pixels.", NULL},
    {"projection", get_projection, NULL, "'equirect', 'mirror_ball' or 'cube_cross'.", NULL},
    {"rotation", get_rotation, NULL, "Rotation about world +Z in radians (as the World Mapping node's Z).", NULL},
    {"strength", get_strength, NULL, "Radiance multiplier.", NULL},
    {"pixels", get_pixels, NULL, "A copy of the image, float32 (H, W, 3), row 0 the top, before strength.", NULL},
    {NULL, NULL, NULL, NULL, NULL},
};

static PyMethodDef environment_methods[] = {
    {"lookup", environment_lookup, METH_O,
     "lookup(dirs)\n--\n\nRadiance (strength applied) seen in world directions `dirs` (float32 (n, 3) or (3,), "
     "need not be unit), bilinear in the image.  Returns float32 (n, 3) (or (3,))."},
    {"with_transform", (PyCFunction)(void (*)(void))environment_with_transform, METH_VARARGS | METH_KEYWORDS,
     "with_transform(rotation=None, strength=None)\n--\n\nA new Environment with the same image and another "
     "rotation and/or strength (None keeps the current value)."},
    {"solid_angles", environment_solid_angles, METH_NOARGS,
     "solid_angles()\n--\n\nExact solid angle of every pixel, float64 (H, W); 0 outside the projection's domain. "
     "Sums to 4 pi."},
    {"samples", environment_samples, METH_NOARGS,
     "samples()\n--\n\n(dirs, flux): float32 (m, 3) world directions of the pixel centres (rotation applied) and "
     "radiance * strength * solid angle, for every pixel of the projection's domain."},
    {NULL, NULL, 0, NULL},
};

static PyTypeObject EnvironmentType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "wenv.Environment",
    .tp_basicsize = sizeof(EnvironmentObject),
    .tp_dealloc = environment_dealloc,
    .tp_repr = environment_repr,
    .tp_flags = Py_TPFLAGS_DEFAULT,
    .tp_doc = "Environment(pixels, projection='equirect', rotation=0.0, strength=1.0)\n--\n\n"
              "A distant HDR environment.  `pixels` is a C-contiguous float32 array (H, W, 3) or (H, W, 4) "
              "(alpha ignored), row 0 the top of the image; non-finite values are rejected and negative ones "
              "clamped to 0.  `projection` is 'equirect' (Blender's convention), 'mirror_ball' (Cycles' Mirror "
              "Ball) or 'cube_cross' (4:3 horizontal or 3:4 vertical cross; layout in csrc/envmap.h).  `rotation` "
              "turns the environment about world +Z like the Z rotation of Blender's World Mapping node; "
              "`strength` multiplies the radiance.  Immutable.",
    .tp_getset = environment_getset,
    .tp_methods = environment_methods,
    .tp_new = environment_new,
};

/* load_environment(path, projection="equirect", rotation=0.0, strength=1.0) */
static PyObject *load_environment(PyObject *module, PyObject *args, PyObject *kwds)
{
    (void)module;
    static char *kwlist[] = {"path", "projection", "rotation", "strength", NULL};
    PyObject *path_obj, *proj_obj = NULL, *rot_obj = NULL, *str_obj = NULL;
    if (!PyArg_ParseTupleAndKeywords(args, kwds, "O|OOO:load_environment", kwlist, &path_obj, &proj_obj, &rot_obj,
                                     &str_obj))
        return NULL;
    wenv_projection projection;
    double rotation = 0.0, strength = 1.0;
    if (parse_projection(proj_obj, &projection) < 0 || parse_transform(rot_obj, str_obj, &rotation, &strength) < 0)
        return NULL;
    PyObject *path_bytes = NULL;
    if (!PyUnicode_FSConverter(path_obj, &path_bytes)) {
        if (PyErr_ExceptionMatches(PyExc_TypeError)) {
            PyErr_Clear();
            PyErr_Format(PyExc_TypeError, "path must be str, bytes or os.PathLike, got %.100s",
                         Py_TYPE(path_obj)->tp_name);
        }
        return NULL;
    }
    const char *path = PyBytes_AS_STRING(path_bytes);
    wenv_envmap *env = NULL;
    wenv_error err = {WENV_OK, ""};
    wenv_status status;
    WENV_BEGIN_WORK
    status = wenv_envmap_load(&env, path, projection, rotation, strength, &err);
    WENV_END_WORK
    Py_DECREF(path_bytes);
    if (status != WENV_OK)
        return wenv_py_raise(&err);
    return wrap_envmap(env);
}

static PyMethodDef envmap_functions[] = {
    {"load_environment", (PyCFunction)(void (*)(void))load_environment, METH_VARARGS | METH_KEYWORDS,
     "load_environment(path, projection='equirect', rotation=0.0, strength=1.0)\n--\n\n"
     "Reads an OpenEXR (scanline or tiled, half or float RGB(A) or Y) or Radiance .hdr (RGBE, '-Y H +X W') file "
     "into a wenv.Environment; the format comes from the file's magic bytes.  OSError naming the file when it is "
     "missing, unreadable or corrupt."},
    {NULL, NULL, 0, NULL},
};

int wenv_register_envmap(PyObject *module)
{
    if (PyType_Ready(&EnvironmentType) < 0)
        return -1;
    Py_INCREF(&EnvironmentType);
    if (PyModule_AddObject(module, "Environment", (PyObject *)&EnvironmentType) < 0) {
        Py_DECREF(&EnvironmentType);
        return -1;
    }
    return PyModule_AddFunctions(module, envmap_functions);
}
