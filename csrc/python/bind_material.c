/* Python types wenv.Material (abstract base), wenv.Lambert and wenv.CookTorrance, plus private
 * helpers (_fresnel, _ndf, _smith_lambda, _lobe_albedo) that the tests use to check the core terms. */
#include "python/bind_material.h"
#include "python/module.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "scene/brdf_readers.h"
#include "scene/material.h"

#define ALBEDO_DEFAULT_SAMPLES 128
#define PARALLEL_MIN_ROWS 16384 /* below this, thread start-up costs more than it saves */

static PyTypeObject MaterialType;
static PyTypeObject LambertType;
static PyTypeObject CookTorranceType;
static PyTypeObject TabulatedType;

/* A macro's value as a string literal, for docstrings that state the core's ranges. */
#define WENV_STR_(x) #x
#define WENV_STR(x) WENV_STR_(x)

const char *const wenv_py_distribution_names[2] = {"beckmann", "ggx"};
const char *const wenv_py_shadowing_names[2] = {"smith", "vcavity"};
static const char *const sample_position_names[] = {"centres", "starts"}; /* by wenv_sample_position */

/* ---------------------------------------------------------------- small helpers */

/* Reads one of `names` (exact, lower case) from a str; TypeError / ValueError naming `name`. */
int wenv_py_parse_choice(PyObject *obj, const char *name, const char *const *names, int count, int *out)
{
    if (!PyUnicode_Check(obj)) {
        PyErr_Format(PyExc_TypeError, "%s must be a str, got %.100s", name, Py_TYPE(obj)->tp_name);
        return -1;
    }
    const char *s = PyUnicode_AsUTF8(obj);
    if (!s)
        return -1;
    for (int i = 0; i < count; i++) {
        if (strcmp(s, names[i]) == 0) {
            *out = i;
            return 0;
        }
    }
    PyErr_Format(PyExc_ValueError, "%s must be '%s' or '%s', got %R", name, names[0], names[1], obj);
    return -1;
}

static PyObject *rgb_tuple(const double rgb[3]) { return Py_BuildValue("(ddd)", rgb[0], rgb[1], rgb[2]); }

static PyObject *new_double_array(int ndim, const Py_ssize_t *shape, double **data)
{
    void *d = NULL;
    PyObject *array = wenv_py_new_array(ndim, shape, "float64", &d);
    *data = d;
    return array;
}

/* Copies a float32 (n, 3) buffer to doubles, normalising each row (rows are nonzero: checked).  Rows
 * already unit to float precision are kept as they are, so every C path (scalar or the float batch)
 * sees bit-identical directions. */
double *wenv_py_normalised_rows(const Py_buffer *view, size_t n)
{
    double *out = PyMem_Malloc(n * 3 * sizeof *out + 1);
    if (!out) {
        PyErr_NoMemory();
        return NULL;
    }
    const float *v = view->buf;
    for (size_t i = 0; i < n; i++) {
        double x = v[3 * i], y = v[3 * i + 1], z = v[3 * i + 2];
        double len2 = x * x + y * y + z * z;
        double inv = fabs(len2 - 1.0) <= 1e-6 ? 1.0 : 1.0 / sqrt(len2);
        out[3 * i] = x * inv;
        out[3 * i + 1] = y * inv;
        out[3 * i + 2] = z * inv;
    }
    return out;
}

/* ---------------------------------------------------------------- C access for other bindings */

const struct wenv_material *wenv_py_material(PyObject *obj, const char *name)
{
    if (!PyObject_TypeCheck(obj, &MaterialType) || !((MaterialObject *)obj)->mat) {
        PyErr_Format(PyExc_TypeError, "%s must be a wenv.Material (wenv.Lambert or wenv.CookTorrance), got %.100s",
                     name, Py_TYPE(obj)->tp_name);
        return NULL;
    }
    return ((MaterialObject *)obj)->mat;
}

/* ---------------------------------------------------------------- wenv.Material (base) */

static void material_dealloc(PyObject *self)
{
    wenv_material_free(((MaterialObject *)self)->mat);
    Py_TYPE(self)->tp_free(self);
}

static PyObject *wrap_material(PyTypeObject *type, wenv_material *mat, wenv_distribution distribution)
{
    MaterialObject *obj = (MaterialObject *)type->tp_alloc(type, 0);
    if (!obj) {
        wenv_material_free(mat);
        return NULL;
    }
    obj->mat = mat;
    obj->distribution = distribution;
    return (PyObject *)obj;
}

/* Room for a model's per-view float terms in _specular_float (the exact lights allow 32). */
#define WENV_PY_VIEW_TERMS_MAX 32

PyObject *wenv_py_material_eval(PyObject *self, PyObject *args, PyObject *kwds, wenv_py_eval_mode mode)
{
    static char *kwlist[] = {"wi", "wo", NULL};
    PyObject *wi_obj, *wo_obj;
    if (!PyArg_ParseTupleAndKeywords(args, kwds, "OO", kwlist, &wi_obj, &wo_obj))
        return NULL;
    const wenv_material *mat = wenv_py_material(self, "self");
    if (!mat)
        return NULL;
    Py_buffer wi_view, wo_view;
    size_t ni, no;
    int wi_single, wo_single;
    if (wenv_py_get_vec3_array(wi_obj, "wi", 1, &wi_view, &ni, &wi_single) < 0)
        return NULL;
    if (wenv_py_get_vec3_array(wo_obj, "wo", 1, &wo_view, &no, &wo_single) < 0) {
        PyBuffer_Release(&wi_view);
        return NULL;
    }
    PyObject *result = NULL;
    double *wi = NULL, *wo = NULL;
    float *fwi = NULL;
    if (mode == WENV_PY_EVAL_SPECULAR_BATCH && no != 1) {
        PyErr_SetString(PyExc_ValueError, "wo must be a single direction for the batch path");
        goto done;
    }
    if (ni != no && ni != 1 && no != 1) {
        PyErr_Format(PyExc_ValueError,
                     "wi and wo must have the same number of rows (or one of them a single direction), got %zu and %zu",
                     ni, no);
        goto done;
    }
    size_t n = ni > no ? ni : no;
    if (ni == 0 || no == 0)
        n = 0;
    wi = wenv_py_normalised_rows(&wi_view, ni);
    wo = wenv_py_normalised_rows(&wo_view, no);
    if (!wi || !wo)
        goto done;
    float *out;
    Py_ssize_t shape[2] = {(Py_ssize_t)n, 3};
    int single = wi_single && wo_single;
    result = single ? wenv_py_new_float_array(1, shape + 1, &out) : wenv_py_new_float_array(2, shape, &out);
    if (!result)
        goto done;
    if (mode == WENV_PY_EVAL_SPECULAR_BATCH) {
        fwi = PyMem_Malloc(ni * 3 * sizeof *fwi + 1);
        if (!fwi) {
            Py_CLEAR(result);
            PyErr_NoMemory();
            goto done;
        }
        for (size_t k = 0; k < 3 * ni; k++)
            fwi[k] = (float)wi[k];
        WENV_BEGIN_WORK
        wenv_material_specular_cos_batch(mat, wo, fwi, n, out);
        WENV_END_WORK
        goto done;
    }
    size_t si = ni == 1 ? 0 : 3, so = no == 1 ? 0 : 3; /* stride 0 broadcasts a single direction */
    WENV_BEGIN_WORK
    ptrdiff_t count = (ptrdiff_t)n;
#pragma omp parallel for schedule(static) if (count > PARALLEL_MIN_ROWS)
    for (ptrdiff_t k = 0; k < count; k++) {
        double rgb[3];
        const double *a = wi + (size_t)k * si, *b = wo + (size_t)k * so;
        if (mode == WENV_PY_EVAL_SPECULAR_FLOAT) {
            float af[3] = {(float)a[0], (float)a[1], (float)a[2]}, bf[3] = {(float)b[0], (float)b[1], (float)b[2]};
            float terms[WENV_PY_VIEW_TERMS_MAX], rgbf[3] = {0.0f, 0.0f, 0.0f};
            if (wenv_material_view_terms(mat) <= WENV_PY_VIEW_TERMS_MAX) {
                wenv_material_prepare_view_f(mat, bf, terms);
                wenv_material_specular_cos_f_many(mat, bf, terms, 1, &af[0], &af[1], &af[2], &rgbf[0], &rgbf[1],
                                                  &rgbf[2]);
            }
            out[3 * k] = rgbf[0];
            out[3 * k + 1] = rgbf[1];
            out[3 * k + 2] = rgbf[2];
            continue;
        }
        if (mode == WENV_PY_EVAL_FULL)
            wenv_material_eval_cos(mat, a, b, rgb);
        else
            wenv_material_specular_cos(mat, a, b, rgb);
        out[3 * k] = (float)rgb[0];
        out[3 * k + 1] = (float)rgb[1];
        out[3 * k + 2] = (float)rgb[2];
    }
    WENV_END_WORK
done:
    PyMem_Free(fwi);
    PyMem_Free(wi);
    PyMem_Free(wo);
    PyBuffer_Release(&wi_view);
    PyBuffer_Release(&wo_view);
    return result;
}

static PyObject *material_eval(PyObject *self, PyObject *args, PyObject *kwds)
{
    return wenv_py_material_eval(self, args, kwds, WENV_PY_EVAL_FULL);
}

int wenv_py_parse_samples(PyObject *obj, size_t *out)
{
    if (!obj) {
        *out = ALBEDO_DEFAULT_SAMPLES;
        return 0;
    }
    if (!PyLong_Check(obj) || PyBool_Check(obj)) {
        PyErr_Format(PyExc_TypeError, "samples must be an int, got %.100s", Py_TYPE(obj)->tp_name);
        return -1;
    }
    int overflow = 0;
    long long v = PyLong_AsLongLongAndOverflow(obj, &overflow);
    if (v == -1 && PyErr_Occurred())
        return -1;
    if (overflow || v < 8 || v > 4096) {
        PyErr_Format(PyExc_ValueError, "samples must be in [8, 4096], got %R", obj);
        return -1;
    }
    *out = (size_t)v;
    return 0;
}

static PyObject *material_albedo(PyObject *self, PyObject *args, PyObject *kwds)
{
    static char *kwlist[] = {"wo", "samples", NULL};
    PyObject *wo_obj, *samples_obj = NULL;
    if (!PyArg_ParseTupleAndKeywords(args, kwds, "O|O", kwlist, &wo_obj, &samples_obj))
        return NULL;
    const wenv_material *mat = wenv_py_material(self, "self");
    size_t samples;
    if (!mat || wenv_py_parse_samples(samples_obj, &samples) < 0)
        return NULL;
    Py_buffer view;
    size_t n;
    int single;
    if (wenv_py_get_vec3_array(wo_obj, "wo", 1, &view, &n, &single) < 0)
        return NULL;
    PyObject *result = NULL;
    double *wo = wenv_py_normalised_rows(&view, n);
    if (!wo)
        goto done;
    double *out;
    Py_ssize_t shape[2] = {(Py_ssize_t)n, 3};
    result = single ? new_double_array(1, shape + 1, &out) : new_double_array(2, shape, &out);
    if (!result)
        goto done;
    wenv_error err = {0};
    WENV_BEGIN_WORK
    for (size_t k = 0; k < n && err.status == WENV_OK; k++)
        wenv_material_albedo(mat, wo + 3 * k, samples, out + 3 * k, &err);
    WENV_END_WORK
    if (err.status != WENV_OK) {
        Py_CLEAR(result);
        wenv_py_raise(&err);
    }
done:
    PyMem_Free(wo);
    PyBuffer_Release(&view);
    return result;
}

static PyObject *material_richcompare(PyObject *a, PyObject *b, int op)
{
    if ((op != Py_EQ && op != Py_NE) || Py_TYPE(a) != Py_TYPE(b))
        Py_RETURN_NOTIMPLEMENTED;
    const MaterialObject *x = (const MaterialObject *)a, *y = (const MaterialObject *)b;
    size_t xd[3], yd[3];
    const float *xt = x->mat ? wenv_tabulated_table(x->mat, xd) : NULL, *yt = y->mat ? wenv_tabulated_table(y->mat, yd) : NULL;
    const wenv_principled_inputs *xp = x->mat ? wenv_principled_inputs_of(x->mat) : NULL,
                                 *yp = y->mat ? wenv_principled_inputs_of(y->mat) : NULL;
    if (xp || yp) { /* Principled: equal when their (clamped) inputs are */
        int same = xp && yp && memcmp(xp, yp, sizeof *xp) == 0;
        return PyBool_FromLong(op == Py_EQ ? same : !same);
    }
    if (xt || yt) { /* tables: equal when their samples and where they sit are */
        int same = xt && yt && memcmp(xd, yd, sizeof xd) == 0 &&
                   wenv_tabulated_samples_at(x->mat) == wenv_tabulated_samples_at(y->mat) &&
                   memcmp(xt, yt, 3 * xd[0] * xd[1] * xd[2] * sizeof *xt) == 0;
        return PyBool_FromLong(op == Py_EQ ? same : !same);
    }
    int equal = x->mat && y->mat && x->distribution == y->distribution &&
                wenv_material_shadowing(x->mat) == wenv_material_shadowing(y->mat) &&
                wenv_material_lobe_count(x->mat) == wenv_material_lobe_count(y->mat) &&
                memcmp(wenv_material_diffuse(x->mat), wenv_material_diffuse(y->mat), 3 * sizeof(double)) == 0;
    for (size_t i = 0; equal && i < wenv_material_lobe_count(x->mat); i++) {
        const wenv_lobe *p = wenv_material_lobe(x->mat, i), *q = wenv_material_lobe(y->mat, i);
        equal = p->alpha == q->alpha && p->ior == q->ior && p->distribution == q->distribution &&
                p->specular[0] == q->specular[0] && p->specular[1] == q->specular[1] &&
                p->specular[2] == q->specular[2];
    }
    if (op == Py_NE)
        equal = !equal;
    return PyBool_FromLong(equal);
}

static Py_hash_t material_hash(PyObject *self)
{
    /* Immutable, so hashing the (exact, round-tripping) repr is consistent with __eq__. */
    PyObject *r = PyObject_Repr(self);
    if (!r)
        return -1;
    Py_hash_t h = PyObject_Hash(r);
    Py_DECREF(r);
    return h;
}

static PyMethodDef material_methods[] = {
    {"eval", (PyCFunction)(void (*)(void))material_eval, METH_VARARGS | METH_KEYWORDS,
     "eval(wi, wo)\n--\n\nf(wi, wo) * cos_i as float32 RGB for local-frame directions (normal = +Z): wi, wo "
     "float32 arrays of shape (n, 3) or (3,), normalised here; a single direction broadcasts against n. "
     "Returns shape (n, 3), or (3,) when both are single.  0 when either direction is at or below the "
     "horizon."},
    {"albedo", (PyCFunction)(void (*)(void))material_albedo, METH_VARARGS | METH_KEYWORDS,
     "albedo(wo, samples=128)\n--\n\nDirectional albedo, integral of f(wi, wo) cos_i over wi, as float64 RGB "
     "for view(s) wo (float32 (n, 3) or (3,)).  Deterministic quadrature following the microfacet "
     "distribution (samples x 2*samples nodes per lobe, samples in [8, 4096]); the diffuse part is exact."},
    {NULL, NULL, 0, NULL},
};

static PyTypeObject MaterialType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "wenv.Material",
    .tp_basicsize = sizeof(MaterialObject),
    .tp_dealloc = material_dealloc,
    .tp_flags = Py_TPFLAGS_DEFAULT,
    .tp_doc = "Base type of reflectance models (wenv.Lambert, wenv.CookTorrance); not instantiable.",
    .tp_methods = material_methods,
    .tp_richcompare = material_richcompare,
    .tp_hash = material_hash,
};

PyTypeObject *wenv_py_material_type(void) { return &MaterialType; }

/* ---------------------------------------------------------------- wenv.Lambert */

static PyObject *lambert_new(PyTypeObject *type, PyObject *args, PyObject *kwds)
{
    static char *kwlist[] = {"color", NULL};
    PyObject *color_obj;
    if (!PyArg_ParseTupleAndKeywords(args, kwds, "O:Lambert", kwlist, &color_obj))
        return NULL;
    double color[3];
    if (wenv_py_get_rgb(color_obj, "color", color) < 0)
        return NULL;
    for (int c = 0; c < 3; c++) {
        if (color[c] > 1.0) {
            PyErr_Format(PyExc_ValueError, "color must be <= 1 in every channel (energy conservation), got %R",
                         color_obj);
            return NULL;
        }
    }
    wenv_material *mat;
    wenv_error err = {0};
    if (wenv_lambert_create(&mat, color, &err) != WENV_OK)
        return wenv_py_raise(&err);
    return wrap_material(type, mat, WENV_NDF_BECKMANN);
}

static PyObject *lambert_color(PyObject *self, void *closure)
{
    (void)closure;
    return rgb_tuple(wenv_material_diffuse(((MaterialObject *)self)->mat));
}

static PyObject *lambert_repr(PyObject *self)
{
    PyObject *color = lambert_color(self, NULL);
    if (!color)
        return NULL;
    PyObject *r = PyUnicode_FromFormat("wenv.Lambert(color=%R)", color);
    Py_DECREF(color);
    return r;
}

static PyObject *lambert_reduce(PyObject *self, PyObject *unused)
{
    (void)unused;
    PyObject *color = lambert_color(self, NULL);
    if (!color)
        return NULL;
    PyObject *r = Py_BuildValue("(O(N))", (PyObject *)Py_TYPE(self), color);
    return r;
}

static PyGetSetDef lambert_getset[] = {
    {"color", lambert_color, NULL, "Albedo (r, g, b), each in [0, 1]; f = color / pi.", NULL},
    {NULL, NULL, NULL, NULL, NULL},
};

static PyMethodDef lambert_methods[] = {
    {"__reduce__", lambert_reduce, METH_NOARGS, NULL},
    {NULL, NULL, 0, NULL},
};

static PyTypeObject LambertType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "wenv.Lambert",
    .tp_basicsize = sizeof(MaterialObject),
    .tp_flags = Py_TPFLAGS_DEFAULT,
    .tp_doc = "Lambert(color)\n--\n\nIdeal diffuse reflector, f = color / pi.  color is a grey number or (r, g, b), "
              "each in [0, 1].  Immutable.",
    .tp_base = &MaterialType,
    .tp_new = lambert_new,
    .tp_repr = lambert_repr,
    .tp_getset = lambert_getset,
    .tp_methods = lambert_methods,
};

/* ---------------------------------------------------------------- wenv.CookTorrance */

static const char *const lobe_keys[] = {"specular", "alpha", "ior", "distribution"};
#define N_LOBE_KEYS 4
#define LOBE_DEFAULT_IOR 1.5

/* Fills *lobe from dict `d` (lobes[index]); default distribution `dist`. */
static int parse_lobe(PyObject *d, Py_ssize_t index, wenv_distribution dist, wenv_lobe *lobe)
{
    char name[64];
    if (!PyDict_Check(d)) {
        PyErr_Format(PyExc_TypeError, "lobes[%zd] must be a dict, got %.100s", index, Py_TYPE(d)->tp_name);
        return -1;
    }
    Py_ssize_t pos = 0;
    PyObject *key, *value;
    while (PyDict_Next(d, &pos, &key, &value)) {
        int known = 0;
        const char *k = PyUnicode_Check(key) ? PyUnicode_AsUTF8(key) : NULL;
        if (PyUnicode_Check(key) && !k)
            return -1;
        for (int i = 0; k && i < N_LOBE_KEYS; i++)
            known |= strcmp(k, lobe_keys[i]) == 0;
        if (k && strcmp(k, "roughness") == 0) { /* the key until the lobe's parameter took its own name */
            PyErr_Format(PyExc_ValueError,
                         "lobes[%zd]: a lobe takes 'alpha' (Beckmann's RMS slope or GGX's alpha), not 'roughness', "
                         "which is Blender's roughness r (alpha = r**2: wenv.alpha_from_roughness(r))",
                         index);
            return -1;
        }
        if (!known) {
            PyErr_Format(PyExc_ValueError,
                         "lobes[%zd] has unknown key %R (known: 'specular', 'alpha', 'ior', 'distribution')",
                         index, key);
            return -1;
        }
    }

    PyObject *v;
    snprintf(name, sizeof name, "lobes[%zd].specular", index);
    lobe->specular[0] = lobe->specular[1] = lobe->specular[2] = 1.0;
    if ((v = PyDict_GetItemString(d, "specular")) && wenv_py_get_rgb(v, name, lobe->specular) < 0)
        return -1;

    snprintf(name, sizeof name, "lobes[%zd].alpha", index);
    if (!(v = PyDict_GetItemString(d, "alpha"))) {
        PyErr_Format(PyExc_ValueError, "%s is required", name);
        return -1;
    }
    if (wenv_py_get_finite(v, name, &lobe->alpha) < 0)
        return -1;

    snprintf(name, sizeof name, "lobes[%zd].ior", index);
    lobe->ior = LOBE_DEFAULT_IOR;
    if ((v = PyDict_GetItemString(d, "ior")) && wenv_py_get_finite(v, name, &lobe->ior) < 0)
        return -1;

    snprintf(name, sizeof name, "lobes[%zd].distribution", index);
    int choice = (int)dist;
    if ((v = PyDict_GetItemString(d, "distribution")) && wenv_py_parse_choice(v, name, wenv_py_distribution_names, 2, &choice) < 0)
        return -1;
    lobe->distribution = (wenv_distribution)choice;
    return 0;
}

wenv_material *wenv_py_one_lobe_material(PyObject *params, const char *caller)
{
    static const char *const keys[] = {"diffuse", "distribution", "shadowing", "specular", "ior"};
    PyObject *key, *value;
    Py_ssize_t pos = 0;
    while (params && PyDict_Next(params, &pos, &key, &value)) {
        const char *k = PyUnicode_Check(key) ? PyUnicode_AsUTF8(key) : NULL;
        if (!k) {
            PyErr_Clear();
            PyErr_Format(PyExc_TypeError, "%s keyword names must be strings", caller);
            return NULL;
        }
        if (strcmp(k, "alpha") == 0 || strcmp(k, "roughness") == 0) {
            PyErr_Format(PyExc_TypeError, "%s solves for the lobe's alpha: do not pass %s", caller, k);
            return NULL;
        }
        int known = 0;
        for (size_t i = 0; i < sizeof keys / sizeof keys[0]; i++)
            known |= strcmp(k, keys[i]) == 0;
        if (!known) {
            PyErr_Format(PyExc_TypeError,
                         "%s got an unexpected keyword argument '%s' (material parameters: diffuse, specular, ior, "
                         "distribution, shadowing)",
                         caller, k);
            return NULL;
        }
    }
    PyObject *v;
    double diffuse[3] = {0.0, 0.0, 0.0};
    int dist = WENV_NDF_BECKMANN, shadowing = WENV_SHADOW_SMITH;
    if (params && (v = PyDict_GetItemString(params, "diffuse")) && wenv_py_get_rgb(v, "diffuse", diffuse) < 0)
        return NULL;
    if (params && (v = PyDict_GetItemString(params, "distribution")) &&
        wenv_py_parse_choice(v, "distribution", wenv_py_distribution_names, 2, &dist) < 0)
        return NULL;
    if (params && (v = PyDict_GetItemString(params, "shadowing")) &&
        wenv_py_parse_choice(v, "shadowing", wenv_py_shadowing_names, 2, &shadowing) < 0)
        return NULL;
    wenv_lobe lobe = {.specular = {1.0, 1.0, 1.0}, .alpha = 0.1, .ior = LOBE_DEFAULT_IOR,
                      .distribution = (wenv_distribution)dist};
    if (params && (v = PyDict_GetItemString(params, "specular")) && wenv_py_get_rgb(v, "specular", lobe.specular) < 0)
        return NULL;
    if (params && (v = PyDict_GetItemString(params, "ior")) && wenv_py_get_finite(v, "ior", &lobe.ior) < 0)
        return NULL;
    wenv_material *mat = NULL;
    wenv_error err = {0};
    if (wenv_cook_torrance_create(&mat, diffuse, &lobe, 1, (wenv_shadowing)shadowing, &err) != WENV_OK) {
        wenv_py_raise(&err);
        return NULL;
    }
    return mat;
}

static PyObject *cook_torrance_new(PyTypeObject *type, PyObject *args, PyObject *kwds)
{
    static char *kwlist[] = {"diffuse", "lobes", "distribution", "shadowing", NULL};
    PyObject *diffuse_obj = NULL, *lobes_obj = NULL, *dist_obj = NULL, *shadow_obj = NULL;
    if (!PyArg_ParseTupleAndKeywords(args, kwds, "|OOOO:CookTorrance", kwlist, &diffuse_obj, &lobes_obj, &dist_obj,
                                     &shadow_obj))
        return NULL;
    double diffuse[3] = {0.0, 0.0, 0.0};
    if (diffuse_obj && wenv_py_get_rgb(diffuse_obj, "diffuse", diffuse) < 0)
        return NULL;
    int dist = WENV_NDF_BECKMANN, shadowing = WENV_SHADOW_SMITH;
    if (dist_obj && wenv_py_parse_choice(dist_obj, "distribution", wenv_py_distribution_names, 2, &dist) < 0)
        return NULL;
    if (shadow_obj && wenv_py_parse_choice(shadow_obj, "shadowing", wenv_py_shadowing_names, 2, &shadowing) < 0)
        return NULL;

    PyObject *seq = NULL;
    Py_ssize_t n = 0;
    if (lobes_obj) {
        if (PyDict_Check(lobes_obj) || PyUnicode_Check(lobes_obj)) {
            PyErr_Format(PyExc_TypeError, "lobes must be a list of dicts, got a %.100s (wrap one lobe in a list)",
                         Py_TYPE(lobes_obj)->tp_name);
            return NULL;
        }
        seq = PySequence_Fast(lobes_obj, "lobes must be a list of dicts");
        if (!seq) {
            PyErr_Clear();
            PyErr_Format(PyExc_TypeError, "lobes must be a list of dicts, got %.100s", Py_TYPE(lobes_obj)->tp_name);
            return NULL;
        }
        n = PySequence_Fast_GET_SIZE(seq);
    }
    wenv_lobe *lobes = NULL;
    if (n > 0) {
        lobes = PyMem_Calloc((size_t)n, sizeof *lobes);
        if (!lobes) {
            Py_DECREF(seq);
            return PyErr_NoMemory();
        }
    }
    for (Py_ssize_t i = 0; i < n; i++) {
        if (parse_lobe(PySequence_Fast_GET_ITEM(seq, i), i, (wenv_distribution)dist, &lobes[i]) < 0) {
            PyMem_Free(lobes);
            Py_DECREF(seq);
            return NULL;
        }
    }
    Py_XDECREF(seq);
    wenv_material *mat;
    wenv_error err = {0};
    wenv_status st = wenv_cook_torrance_create(&mat, diffuse, lobes, (size_t)n, (wenv_shadowing)shadowing, &err);
    PyMem_Free(lobes);
    if (st != WENV_OK)
        return wenv_py_raise(&err);
    return wrap_material(type, mat, (wenv_distribution)dist);
}

static PyObject *ct_diffuse(PyObject *self, void *closure)
{
    (void)closure;
    return rgb_tuple(wenv_material_diffuse(((MaterialObject *)self)->mat));
}

static PyObject *ct_lobes(PyObject *self, void *closure)
{
    (void)closure;
    const wenv_material *mat = ((MaterialObject *)self)->mat;
    PyObject *list = PyList_New((Py_ssize_t)wenv_material_lobe_count(mat));
    if (!list)
        return NULL;
    for (size_t i = 0; i < wenv_material_lobe_count(mat); i++) {
        const wenv_lobe *l = wenv_material_lobe(mat, i);
        PyObject *d = Py_BuildValue("{s:(ddd),s:d,s:d,s:s}", "specular", l->specular[0], l->specular[1],
                                    l->specular[2], "alpha", l->alpha, "ior", l->ior, "distribution",
                                    wenv_py_distribution_names[l->distribution]);
        if (!d) {
            Py_DECREF(list);
            return NULL;
        }
        PyList_SET_ITEM(list, (Py_ssize_t)i, d);
    }
    return list;
}

static PyObject *ct_distribution(PyObject *self, void *closure)
{
    (void)closure;
    return PyUnicode_FromString(wenv_py_distribution_names[((MaterialObject *)self)->distribution]);
}

static PyObject *ct_shadowing(PyObject *self, void *closure)
{
    (void)closure;
    return PyUnicode_FromString(wenv_py_shadowing_names[wenv_material_shadowing(((MaterialObject *)self)->mat)]);
}

/* (diffuse, lobes, distribution, shadowing): the constructor's arguments, for repr and pickling. */
static PyObject *ct_args(PyObject *self)
{
    return Py_BuildValue("(NNNN)", ct_diffuse(self, NULL), ct_lobes(self, NULL), ct_distribution(self, NULL),
                         ct_shadowing(self, NULL));
}

static PyObject *ct_repr(PyObject *self)
{
    PyObject *a = ct_args(self);
    if (!a)
        return NULL;
    PyObject *r = PyUnicode_FromFormat("wenv.CookTorrance(diffuse=%R, lobes=%R, distribution=%R, shadowing=%R)",
                                       PyTuple_GET_ITEM(a, 0), PyTuple_GET_ITEM(a, 1), PyTuple_GET_ITEM(a, 2),
                                       PyTuple_GET_ITEM(a, 3));
    Py_DECREF(a);
    return r;
}

static PyObject *ct_reduce(PyObject *self, PyObject *unused)
{
    (void)unused;
    PyObject *a = ct_args(self);
    if (!a)
        return NULL;
    return Py_BuildValue("(ON)", (PyObject *)Py_TYPE(self), a);
}

static PyObject *ct_with_alpha(PyObject *self, PyObject *arg)
{
    double alpha;
    if (wenv_py_get_finite(arg, "alpha", &alpha) < 0)
        return NULL;
    const MaterialObject *obj = (const MaterialObject *)self;
    wenv_material *mat;
    wenv_error err = {0};
    if (wenv_material_with_alpha(&mat, obj->mat, alpha, &err) != WENV_OK)
        return wenv_py_raise(&err);
    return wrap_material(Py_TYPE(self), mat, obj->distribution);
}

/* The method's old name, which took alpha: an error that names the new one, never a silent change. */
static PyObject *ct_with_roughness(PyObject *self, PyObject *arg)
{
    (void)self, (void)arg;
    PyErr_SetString(PyExc_TypeError, "CookTorrance.with_roughness() is now with_alpha(alpha): a lobe's parameter is "
                                     "alpha; for Blender's roughness r, with_alpha(wenv.alpha_from_roughness(r))");
    return NULL;
}

static PyGetSetDef ct_getset[] = {
    {"diffuse", ct_diffuse, NULL, "Lambertian albedo (r, g, b).", NULL},
    {"lobes", ct_lobes, NULL,
     "Specular lobes: a new list of dicts with every key filled in (specular, alpha, ior, distribution).", NULL},
    {"distribution", ct_distribution, NULL, "Default microfacet distribution of the lobes: 'beckmann' or 'ggx'.",
     NULL},
    {"shadowing", ct_shadowing, NULL, "Shadowing-masking term: 'smith' (height-correlated) or 'vcavity'.", NULL},
    {NULL, NULL, NULL, NULL, NULL},
};

static PyMethodDef ct_methods[] = {
    {"__reduce__", ct_reduce, METH_NOARGS, NULL},
    {"with_alpha", ct_with_alpha, METH_O,
     "with_alpha(alpha)\n--\n\nA new CookTorrance equal to this one with every lobe's alpha set to alpha."},
    {"with_roughness", ct_with_roughness, METH_O,
     "with_roughness(r)\n--\n\nRenamed: with_alpha(alpha) (a TypeError that says so)."},
    {NULL, NULL, 0, NULL},
};

static PyTypeObject CookTorranceType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "wenv.CookTorrance",
    .tp_basicsize = sizeof(MaterialObject),
    .tp_flags = Py_TPFLAGS_DEFAULT,
    .tp_doc =
        "CookTorrance(diffuse=0.0, lobes=(), distribution='beckmann', shadowing='smith')\n--\n\n"
        "Lambertian diffuse plus specular microfacet lobes, f = diffuse/pi + sum specular F D G / (4 cos_i cos_o).\n"
        "diffuse: grey or (r, g, b) in [0, 1].  lobes: list of dicts with keys 'alpha' (required, "
        "in [" WENV_STR(WENV_ALPHA_MIN) ", " WENV_STR(WENV_ALPHA_MAX) "]: Beckmann RMS slope or GGX alpha; Blender's "
        "roughness r gives alpha = r**2, wenv.alpha_from_roughness), 'specular' (grey or RGB >= 0, default 1), "
        "'ior' (in (1, 10], default 1.5) and 'distribution' (default: the material's).  distribution: "
        "'beckmann' or 'ggx'.  shadowing: 'smith' (exact Lambda, height-correlated) or 'vcavity'.  Immutable.",
    .tp_base = &MaterialType,
    .tp_new = cook_torrance_new,
    .tp_repr = ct_repr,
    .tp_getset = ct_getset,
    .tp_methods = ct_methods,
};

/* ---------------------------------------------------------------- wenv.Tabulated, wenv.load_brdf */

/* Warns (RuntimeWarning) when the material reflects more than it receives at some view: a table
 * made or measured wrong.  Views at 0, 30, 60 and 80 degrees; -1 with the warning raised as an error. */
static int warn_if_gaining(const wenv_material *mat, const char *what)
{
    static const double degrees[4] = {0.0, 30.0, 60.0, 80.0};
    double worst = 0.0, at = 0.0;
    for (int v = 0; v < 4; v++) {
        double t = degrees[v] * M_PI / 180.0, wo[3] = {sin(t), 0.0, cos(t)}, rgb[3];
        wenv_error err = {0};
        if (wenv_material_albedo(mat, wo, 32, rgb, &err)) {
            wenv_py_raise(&err);
            return -1;
        }
        for (int c = 0; c < 3; c++)
            if (rgb[c] > worst) {
                worst = rgb[c];
                at = degrees[v];
            }
    }
    if (!(worst > 1.01))
        return 0;
    char message[800];
    snprintf(message, sizeof message,
             "%s reflects %.3g of the light it receives at a view %.0f degrees from the normal (more than 1: not "
             "energy conserving)",
             what, worst, at);
    return PyErr_WarnEx(PyExc_RuntimeWarning, message, 1);
}

static PyObject *wrap_tabulated(PyTypeObject *type, wenv_material *mat, const char *what)
{
    PyObject *obj = wrap_material(type, mat, WENV_NDF_BECKMANN);
    if (obj && warn_if_gaining(mat, what) < 0)
        Py_CLEAR(obj);
    return obj;
}

static PyObject *tabulated_new(PyTypeObject *type, PyObject *args, PyObject *kwds)
{
    static char *kwlist[] = {"table", "samples_at", NULL};
    PyObject *table_obj, *at_obj = NULL;
    if (!PyArg_ParseTupleAndKeywords(args, kwds, "O|O:Tabulated", kwlist, &table_obj, &at_obj))
        return NULL;
    int at = WENV_SAMPLES_AT_CENTRES;
    if (at_obj && wenv_py_parse_choice(at_obj, "samples_at", sample_position_names, 2, &at) < 0)
        return NULL;
    /* float32 C-contiguous, converted by numpy from any real array */
    PyObject *numpy = PyImport_ImportModule("numpy");
    PyObject *array = numpy ? PyObject_CallMethod(numpy, "ascontiguousarray", "Os", table_obj, "float32") : NULL;
    Py_XDECREF(numpy);
    if (!array) {
        if (PyErr_ExceptionMatches(PyExc_ValueError) || PyErr_ExceptionMatches(PyExc_TypeError)) {
            PyErr_Clear();
            PyErr_Format(PyExc_TypeError, "table must be an array of real numbers, got %.100s",
                         Py_TYPE(table_obj)->tp_name);
        }
        return NULL;
    }
    Py_buffer b;
    if (PyObject_GetBuffer(array, &b, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) < 0) {
        Py_DECREF(array);
        return NULL;
    }
    PyObject *result = NULL;
    if (b.ndim != 4 || b.shape[3] != 3 || b.shape[0] < 2 || b.shape[1] < 2 || b.shape[2] < 2) {
        PyErr_SetString(PyExc_ValueError, "table must have shape (n_theta_h, n_theta_d, n_phi_d, 3), each n >= 2");
        goto done;
    }
    size_t dims[3] = {(size_t)b.shape[0], (size_t)b.shape[1], (size_t)b.shape[2]};
    const float *v = b.buf;
    for (size_t i = 0; i < 3 * dims[0] * dims[1] * dims[2]; i++)
        if (!isfinite(v[i]) || v[i] < 0.0f) {
            char value[32];
            snprintf(value, sizeof value, "%g", (double)v[i]);
            PyErr_Format(PyExc_ValueError, "table entries must be finite and >= 0, entry %zu is %s", i, value);
            goto done;
        }
    wenv_material *mat;
    wenv_error err = {0};
    if (wenv_tabulated_create(&mat, v, dims, (wenv_sample_position)at, &err) != WENV_OK) {
        wenv_py_raise(&err);
        goto done;
    }
    result = wrap_tabulated(type, mat, "the table");
done:
    PyBuffer_Release(&b);
    Py_DECREF(array);
    return result;
}

static PyObject *tabulated_shape(PyObject *self, void *closure)
{
    (void)closure;
    size_t d[3];
    wenv_tabulated_table(((MaterialObject *)self)->mat, d);
    return Py_BuildValue("(nnn)", (Py_ssize_t)d[0], (Py_ssize_t)d[1], (Py_ssize_t)d[2]);
}

static PyObject *tabulated_table(PyObject *self, void *closure)
{
    (void)closure;
    size_t d[3];
    const float *t = wenv_tabulated_table(((MaterialObject *)self)->mat, d);
    Py_ssize_t shape[4] = {(Py_ssize_t)d[0], (Py_ssize_t)d[1], (Py_ssize_t)d[2], 3};
    float *out;
    PyObject *array = wenv_py_new_float_array(4, shape, &out);
    if (array)
        memcpy(out, t, 3 * d[0] * d[1] * d[2] * sizeof *out);
    return array;
}

static PyObject *tabulated_samples_at(PyObject *self, void *closure)
{
    (void)closure;
    return PyUnicode_FromString(sample_position_names[wenv_tabulated_samples_at(((MaterialObject *)self)->mat)]);
}

static PyObject *tabulated_repr(PyObject *self)
{
    size_t d[3];
    const wenv_material *mat = ((MaterialObject *)self)->mat;
    wenv_tabulated_table(mat, d);
    return PyUnicode_FromFormat("wenv.Tabulated(<%zu x %zu x %zu x 3 table>, samples_at='%s')", d[0], d[1], d[2],
                                sample_position_names[wenv_tabulated_samples_at(mat)]);
}

static PyObject *tabulated_reduce(PyObject *self, PyObject *unused)
{
    (void)unused;
    PyObject *table = tabulated_table(self, NULL);
    const char *at = sample_position_names[wenv_tabulated_samples_at(((MaterialObject *)self)->mat)];
    return table ? Py_BuildValue("(O(Ns))", (PyObject *)Py_TYPE(self), table, at) : NULL;
}

static PyGetSetDef tabulated_getset[] = {
    {"shape", tabulated_shape, NULL, "(n_theta_h, n_theta_d, n_phi_d): the table's samples.", NULL},
    {"table", tabulated_table, NULL, "A float32 copy of the table, (n_theta_h, n_theta_d, n_phi_d, 3).", NULL},
    {"samples_at", tabulated_samples_at, NULL,
     "Where the samples sit: 'centres' of their bins (MERL files) or 'starts' (see the class docstring).", NULL},
    {"diffuse", ct_diffuse, NULL,
     "The Lambertian part split off the table: pi times its smallest value above the horizon, per channel "
     "(shaded as a Lambertian reflector; the rest is the glossy lobe).", NULL},
    {NULL, NULL, NULL, NULL, NULL},
};

static PyMethodDef tabulated_methods[] = {
    {"__reduce__", tabulated_reduce, METH_NOARGS, NULL},
    {NULL, NULL, 0, NULL},
};

static PyTypeObject TabulatedType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "wenv.Tabulated",
    .tp_basicsize = sizeof(MaterialObject),
    .tp_flags = Py_TPFLAGS_DEFAULT,
    .tp_doc = "Tabulated(table, samples_at='centres')\n--\n\nAn isotropic BRDF given as a table of f (RGB, 1/sr) "
              "over Rusinkiewicz's half and difference angles, in MERL's layout: table[i, j, k] stands for the bin "
              "[i, i + 1) x [j, j + 1) x [k, k + 1) of the index coordinates (sqrt(theta_h / 90 degrees) * n_theta_h, "
              "theta_d / 90 degrees * n_theta_d, phi_d / 180 degrees * n_phi_d), phi_d folded into [0, 180) degrees "
              "by reciprocity.  samples_at says where in its bin the sample was taken: 'centres' (the default, as "
              "in a MERL file, whose reader looks a sample up by the floor of the index coordinate): at "
              "(i + 0.5, j + 0.5, k + 0.5), so theta_h = ((i + 0.5) / n_theta_h)**2 * 90 degrees, theta_d = "
              "(j + 0.5) / n_theta_d * 90 degrees, phi_d = (k + 0.5) / n_phi_d * 180 degrees; 'starts': at (i, j, k), "
              "theta_h = (i / n_theta_h)**2 * 90 degrees and so on.  Interpolated trilinearly between the samples' "
              "positions, phi_d periodic, theta_h and theta_d held at their first and last samples outside them.  "
              "Entries finite and >= 0; a RuntimeWarning when the table reflects more than it receives.  The table "
              "is copied once and shared by every shader that uses the material.  Immutable.",
    .tp_base = &MaterialType,
    .tp_new = tabulated_new,
    .tp_repr = tabulated_repr,
    .tp_getset = tabulated_getset,
    .tp_methods = tabulated_methods,
};

static PyObject *py_load_brdf(PyObject *self, PyObject *arg)
{
    (void)self;
    PyObject *bytes = NULL;
    if (!PyUnicode_FSConverter(arg, &bytes))
        return NULL;
    const char *path = PyBytes_AS_STRING(bytes);
    float *rgb = NULL;
    size_t dims[3];
    wenv_material *mat = NULL;
    wenv_error err = {0};
    wenv_status st;
    WENV_BEGIN_WORK
    st = wenv_read_merl(path, &rgb, dims, &err);
    if (!st)
        st = wenv_tabulated_create(&mat, rgb, dims, WENV_SAMPLES_AT_CENTRES, &err);
    WENV_END_WORK
    free(rgb);
    PyObject *result = NULL;
    if (st)
        wenv_py_raise(&err);
    else {
        char what[600];
        snprintf(what, sizeof what, "BRDF file '%s'", path);
        result = wrap_tabulated(&TabulatedType, mat, what);
    }
    Py_DECREF(bytes);
    return result;
}

static PyObject *py_alpha_from_roughness(PyObject *self, PyObject *arg)
{
    (void)self;
    double r;
    if (wenv_py_get_finite(arg, "roughness", &r) < 0)
        return NULL;
    if (r < 0.0) {
        wenv_py_errorf(PyExc_ValueError, "roughness must be >= 0, got %g", r);
        return NULL;
    }
    return PyFloat_FromDouble(wenv_alpha_from_roughness(r));
}

static PyMethodDef material_functions[] = {
    {"load_brdf", py_load_brdf, METH_O,
     "load_brdf(path)\n--\n\nA measured BRDF from a MERL .binary file, as a wenv.Tabulated: three int32 dimensions "
     "(90, 90, 180), then the doubles channel after channel, scaled by 1/1500, 1.15/1500 and 1.66/1500 (R, G, B).  "
     "Each sample is read at the centre of its bin (samples_at='centres'), as MERL's own reader looks it up.  "
     "Samples stored negative (not measured) take the nearest measured theta_d at the same theta_h and phi_d.  "
     "OSError naming the file when it is missing, truncated, the wrong size for its dimensions, or holds NaN."},
    {"alpha_from_roughness", py_alpha_from_roughness, METH_O,
     "alpha_from_roughness(roughness)\n--\n\nThe distribution's alpha (a CookTorrance lobe's 'alpha') for Blender's "
     "perceptual roughness r, as Cycles converts it: r**2, floored at " WENV_STR(WENV_ALPHA_FROM_ROUGHNESS_MIN)
     " (a perfect mirror has no lobe width to shade).  The one conversion: wenv's 'roughness' is always r."},
    {NULL, NULL, 0, NULL},
};

/* ---------------------------------------------------------------- registration */

int wenv_register_material(PyObject *module)
{
    if (PyType_Ready(&MaterialType) < 0 || PyType_Ready(&LambertType) < 0 || PyType_Ready(&CookTorranceType) < 0 ||
        PyType_Ready(&TabulatedType) < 0)
        return -1;
    PyTypeObject *types[] = {&MaterialType, &LambertType, &CookTorranceType, &TabulatedType};
    const char *names[] = {"Material", "Lambert", "CookTorrance", "Tabulated"};
    for (int i = 0; i < 4; i++) {
        Py_INCREF(types[i]);
        if (PyModule_AddObject(module, names[i], (PyObject *)types[i]) < 0) {
            Py_DECREF(types[i]);
            return -1;
        }
    }
    if (PyModule_AddFunctions(module, material_functions) < 0)
        return -1;
    /* The accepted ranges, for callers that offer them to a user (the add-on's properties). */
    PyObject *alpha = Py_BuildValue("(dd)", WENV_ALPHA_MIN, WENV_ALPHA_MAX);
    if (PyModule_AddObject(module, "ALPHA_RANGE", alpha) < 0) {
        Py_XDECREF(alpha);
        return -1;
    }
    PyObject *ior = Py_BuildValue("(dd)", 1.0, WENV_IOR_MAX);
    if (PyModule_AddObject(module, "IOR_RANGE", ior) < 0) {
        Py_XDECREF(ior);
        return -1;
    }
    return 0;
}
