/* The `wenv` extension module: module object, thread control and registration of the bindings. */
#include "python/module.h"

#include <omp.h>
#include <stdatomic.h>
#include <string.h>


static PyObject *cancelled_error_type; /* set once at import; read-only afterwards */
static PyObject *eye_at_vertex_error_type; /* likewise */
/* wenv.set_num_threads's choice, for every thread of the process (0: none made) -- the one setting a
 * script changes at run time, as OMP_NUM_THREADS is set for the process. */
static atomic_int num_threads;

void wenv_py_use_num_threads(void)
{
    int n = atomic_load(&num_threads);
    if (n > 0 && omp_get_max_threads() != n)
        omp_set_num_threads(n);
}

PyObject *wenv_py_cancelled_error(void) { return cancelled_error_type ? cancelled_error_type : PyExc_RuntimeError; }
PyObject *wenv_py_eye_at_vertex_error(void)
{
    return eye_at_vertex_error_type ? eye_at_vertex_error_type : PyExc_ValueError;
}

static PyObject *set_num_threads(PyObject *self, PyObject *arg)
{
    (void)self;
    long n = PyLong_AsLong(arg);
    if (n == -1 && PyErr_Occurred())
        return NULL;
    if (n < 1 || n > 4096) {
        PyErr_SetString(PyExc_ValueError, "n must be between 1 and 4096 threads");
        return NULL;
    }
    atomic_store(&num_threads, (int)n);
    omp_set_num_threads((int)n);
    Py_RETURN_NONE;
}

static PyObject *get_num_threads(PyObject *self, PyObject *unused)
{
    (void)self;
    (void)unused;
    int n = atomic_load(&num_threads);
    return PyLong_FromLong(n > 0 ? n : omp_get_max_threads());
}

/* Names the API gave up, each with what replaced it: an AttributeError that says where to go rather
 * than a bare one (PEP 562's module __getattr__, called only for names the module does not have). */
static const char *const RENAMED[][2] = {
    {"ROUGHNESS_RANGE", "ALPHA_RANGE (a lobe's alpha; 'roughness' is Blender's r, alpha = r**2)"},
};

static PyObject *module_getattr(PyObject *self, PyObject *name)
{
    (void)self;
    const char *n = PyUnicode_Check(name) ? PyUnicode_AsUTF8(name) : NULL;
    for (size_t i = 0; n && i < sizeof RENAMED / sizeof RENAMED[0]; i++)
        if (strcmp(n, RENAMED[i][0]) == 0)
            return PyErr_Format(PyExc_AttributeError, "wenv.%s is now wenv.%s", RENAMED[i][0], RENAMED[i][1]);
    return PyErr_Format(PyExc_AttributeError, "module 'wenv' has no attribute %R", name);
}

static PyMethodDef module_methods[] = {
    {"__getattr__", module_getattr, METH_O, NULL},
    {"set_num_threads", set_num_threads, METH_O,
     "set_num_threads(n)\n--\n\nUse n OpenMP threads for shading and precomputation, whichever thread "
     "calls wenv afterwards (the default comes from OMP_NUM_THREADS or the number of cores)."},
    {"get_num_threads", get_num_threads, METH_NOARGS,
     "get_num_threads()\n--\n\nNumber of OpenMP threads wenv uses."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef wenv_module = {
    PyModuleDef_HEAD_INIT, "wenv",
    "Wavelet-rotation environment shading with view-dependent BRDFs, and a virtual glossmeter.",
    -1, module_methods, NULL, NULL, NULL, NULL,
};

PyMODINIT_FUNC PyInit_wenv(void)
{
    PyObject *m = PyModule_Create(&wenv_module);
    if (!m)
        return NULL;
    if (!cancelled_error_type) {
        cancelled_error_type = PyErr_NewExceptionWithDoc(
            "wenv.CancelledError", "Long work was stopped by its progress callback.", PyExc_Exception, NULL);
        if (!cancelled_error_type)
            goto fail;
    }
    Py_INCREF(cancelled_error_type);
    if (PyModule_AddObject(m, "CancelledError", cancelled_error_type) < 0) {
        Py_DECREF(cancelled_error_type);
        goto fail;
    }
    if (!eye_at_vertex_error_type) {
        eye_at_vertex_error_type = PyErr_NewExceptionWithDoc(
            "wenv.EyeAtVertexError",
            "A vertex lies exactly at the eye, so it has no view direction (a ValueError).  `vertices` holds the "
            "indices of every such vertex, for a caller that leaves them black and shades the rest.",
            PyExc_ValueError, NULL);
        if (!eye_at_vertex_error_type)
            goto fail;
    }
    Py_INCREF(eye_at_vertex_error_type);
    if (PyModule_AddObject(m, "EyeAtVertexError", eye_at_vertex_error_type) < 0) {
        Py_DECREF(eye_at_vertex_error_type);
        goto fail;
    }
    if (PyModule_AddStringConstant(m, "__version__", "0.1.0") < 0 || wenv_register_envmap(m) < 0 ||
        wenv_register_material(m) < 0 || wenv_register_principled(m) < 0 || wenv_register_shader(m) < 0 || wenv_register_reference(m) < 0 ||
        wenv_register_glossmeter(m) < 0 || wenv_register_occlusion(m) < 0 || wenv_register_lamp(m) < 0 ||
        wenv_register_bake(m) < 0 || wenv_register_textures(m) < 0 || wenv_register_internals(m) < 0)
        goto fail;
    return m;
fail:
    Py_DECREF(m);
    return NULL;
}
