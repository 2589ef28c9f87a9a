/* wenv.Principled: Blender's Principled BSDF as Cycles evaluates it (scene/principled.c). */
#include "python/bind_material.h"
#include "python/module.h"

#include <math.h>
#include <stddef.h>
#include <string.h>

#include "methods/material_family.h"
#include "scene/material.h"

static const char *const DISTRIBUTIONS[] = {"ggx", "multiscatter_ggx"}; /* index = multiscatter */
/* index = oren_nayar_classic: Cycles' Diffuse Roughness from Blender 4.3 on, and before it */
static const char *const OREN_NAYAR[] = {"energy_preserving", "classic"};

/* One of two names into *index; a ValueError naming both otherwise. */
static int set_choice(int *index, const char *keyword, const char *const names[2], PyObject *value)
{
    const char *d = PyUnicode_Check(value) ? PyUnicode_AsUTF8(value) : NULL;
    for (int i = 0; d && i < 2; i++)
        if (strcmp(d, names[i]) == 0) {
            *index = i;
            return 0;
        }
    PyErr_Format(PyExc_ValueError, "%s must be '%s' or '%s', got %R", keyword, names[1], names[0], value);
    return -1;
}

static PyTypeObject PrincipledType;

/* A colour: a grey number, (r, g, b), or Blender's (r, g, b, a) with a ignored (Cycles ignores it). */
static int get_colour(PyObject *obj, const char *name, double rgb[3])
{
    if (PySequence_Check(obj) && !PyUnicode_Check(obj) && PySequence_Size(obj) == 4) {
        PyObject *three = PySequence_GetSlice(obj, 0, 3);
        int r = three ? wenv_py_get_rgb(three, name, rgb) : -1;
        Py_XDECREF(three);
        return r;
    }
    return wenv_py_get_rgb(obj, name, rgb);
}

static int set_input(wenv_principled_inputs *in, PyObject *key, PyObject *value)
{
    const char *name = PyUnicode_Check(key) ? PyUnicode_AsUTF8(key) : NULL;
    if (!name) {
        if (!PyErr_Occurred())
            PyErr_SetString(PyExc_TypeError, "Principled keywords must be strings");
        return -1;
    }
    if (strcmp(name, "distribution") == 0)
        return set_choice(&in->multiscatter, name, DISTRIBUTIONS, value);
    if (strcmp(name, "oren_nayar") == 0)
        return set_choice(&in->oren_nayar_classic, name, OREN_NAYAR, value);
    for (size_t r = 0; r < wenv_principled_input_count; r++) {
        const wenv_principled_input *row = &wenv_principled_input_list[r];
        if (strcmp(name, row->name) != 0)
            continue;
        double *v = wenv_principled_field(in, row);
        return row->n == 3 ? get_colour(value, name, v) : wenv_py_get_finite(value, name, v);
    }
    PyErr_Format(PyExc_TypeError,
                 "Principled got an unexpected keyword argument '%s' (the Principled BSDF node's inputs in snake "
                 "case, as wenv.Principled.INPUTS lists them, distribution or oren_nayar)",
                 name);
    return -1;
}

/* {name: value} of every input (clamped as evaluated), colours as tuples, and the distribution. */
static PyObject *inputs_dict(const wenv_principled_inputs *in, int only_changed)
{
    wenv_principled_inputs defaults;
    wenv_principled_defaults(&defaults);
    PyObject *d = PyDict_New();
    for (size_t r = 0; d && r < wenv_principled_input_count; r++) {
        const wenv_principled_input *row = &wenv_principled_input_list[r];
        const double *v = wenv_principled_field_c(in, row), *w = wenv_principled_field_c(&defaults, row);
        if (only_changed && memcmp(v, w, (size_t)row->n * sizeof *v) == 0)
            continue;
        PyObject *value = row->n == 3 ? Py_BuildValue("(ddd)", v[0], v[1], v[2]) : PyFloat_FromDouble(v[0]);
        if (!value || PyDict_SetItemString(d, row->name, value) < 0)
            Py_CLEAR(d);
        Py_XDECREF(value);
    }
    const struct {
        const char *keyword;
        int value, fallback;
        const char *const *names;
    } choices[] = {{"distribution", in->multiscatter, defaults.multiscatter, DISTRIBUTIONS},
                   {"oren_nayar", in->oren_nayar_classic, defaults.oren_nayar_classic, OREN_NAYAR}};
    for (size_t c = 0; d && c < sizeof choices / sizeof *choices; c++) {
        if (only_changed && choices[c].value == choices[c].fallback)
            continue;
        PyObject *name = PyUnicode_FromString(choices[c].names[choices[c].value ? 1 : 0]);
        if (!name || PyDict_SetItemString(d, choices[c].keyword, name) < 0)
            Py_CLEAR(d);
        Py_XDECREF(name);
    }
    return d;
}

static PyObject *unhonoured_tuple(const wenv_principled_inputs *in)
{
    const char *names[64];
    size_t n = wenv_principled_unhonoured(in, names, 64);
    n = n < 64 ? n : 64;
    PyObject *t = PyTuple_New((Py_ssize_t)n);
    for (size_t i = 0; t && i < n; i++) {
        PyObject *s = PyUnicode_FromString(names[i]);
        if (!s) {
            Py_CLEAR(t);
            break;
        }
        PyTuple_SET_ITEM(t, (Py_ssize_t)i, s);
    }
    return t;
}

static PyObject *principled_new(PyTypeObject *type, PyObject *args, PyObject *kwds)
{
    if (PyTuple_GET_SIZE(args) != 0) {
        PyErr_SetString(PyExc_TypeError, "Principled takes keyword arguments only (the node's inputs by name)");
        return NULL;
    }
    wenv_principled_inputs in;
    wenv_principled_defaults(&in);
    PyObject *key, *value;
    Py_ssize_t pos = 0;
    while (kwds && PyDict_Next(kwds, &pos, &key, &value))
        if (set_input(&in, key, value) < 0)
            return NULL;
    wenv_material *mat = NULL;
    wenv_error err = {0};
    if (wenv_principled_create(&mat, &in, &err))
        return wenv_py_raise(&err);
    MaterialObject *obj = (MaterialObject *)type->tp_alloc(type, 0);
    if (!obj) {
        wenv_material_free(mat);
        return NULL;
    }
    obj->mat = mat;
    obj->distribution = WENV_NDF_GGX;
    PyObject *skipped = unhonoured_tuple(wenv_principled_inputs_of(mat));
    if (!skipped) {
        Py_DECREF(obj);
        return NULL;
    }
    if (PyTuple_GET_SIZE(skipped) > 0) {
        PyObject *sep = PyUnicode_FromString(", ");
        PyObject *joined = sep ? PyUnicode_Join(sep, skipped) : NULL;
        Py_XDECREF(sep);
        int failed = !joined || PyErr_WarnFormat(PyExc_UserWarning, 1,
                                                 "wenv.Principled does not shade %U (reflection only; subsurface "
                                                 "scattering is shaded as diffuse, a coat tint above 1 as 1): "
                                                 "see .unhonoured",
                                                 joined) < 0;
        Py_XDECREF(joined);
        if (failed) {
            Py_DECREF(skipped);
            Py_DECREF(obj);
            return NULL;
        }
    }
    Py_DECREF(skipped);
    return (PyObject *)obj;
}

static const wenv_principled_inputs *inputs_of(PyObject *self)
{
    return wenv_principled_inputs_of(((MaterialObject *)self)->mat);
}

static PyObject *principled_inputs(PyObject *self, void *closure)
{
    (void)closure;
    return inputs_dict(inputs_of(self), 0);
}

static PyObject *principled_unhonoured(PyObject *self, void *closure)
{
    (void)closure;
    return unhonoured_tuple(inputs_of(self));
}

static PyObject *principled_repr(PyObject *self)
{
    PyObject *d = inputs_dict(inputs_of(self), 1);
    if (!d)
        return NULL;
    PyObject *r = PyDict_Size(d) ? PyUnicode_FromFormat("wenv.Principled(**%R)", d)
                                 : PyUnicode_FromString("wenv.Principled()");
    Py_DECREF(d);
    return r;
}

/* Pickled as Principled(**inputs). */
static PyObject *principled_reduce(PyObject *self, PyObject *unused)
{
    (void)unused;
    PyObject *copyreg = PyImport_ImportModule("copyreg");
    PyObject *newobj = copyreg ? PyObject_GetAttrString(copyreg, "__newobj_ex__") : NULL;
    PyObject *kwargs = inputs_dict(inputs_of(self), 1);
    PyObject *result = newobj && kwargs ? Py_BuildValue("(O(O()O))", newobj, (PyObject *)Py_TYPE(self), kwargs) : NULL;
    Py_XDECREF(copyreg);
    Py_XDECREF(newobj);
    Py_XDECREF(kwargs);
    return result;
}

/* The Lambertian part for views at cos_v (an array), RGB float64 (n, 3). */
static PyObject *principled_diffuse_at(PyObject *self, PyObject *arg)
{
    PyObject *numpy = PyImport_ImportModule("numpy");
    PyObject *array = numpy ? PyObject_CallMethod(numpy, "asarray", "Os", arg, "float64") : NULL;
    Py_XDECREF(numpy);
    if (!array)
        return NULL;
    Py_buffer b;
    if (PyObject_GetBuffer(array, &b, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) < 0) {
        Py_DECREF(array);
        return NULL;
    }
    size_t n = (size_t)(b.len / (Py_ssize_t)sizeof(double));
    const double *c = b.buf;
    PyObject *out = PyList_New((Py_ssize_t)n);
    for (size_t i = 0; out && i < n; i++) {
        if (!isfinite(c[i])) {
            wenv_py_errorf(PyExc_ValueError, "cos_v must be finite, got %g", c[i]);
            Py_CLEAR(out);
            break;
        }
        double rgb[3];
        wenv_material_diffuse_at(((MaterialObject *)self)->mat, c[i], rgb);
        PyObject *t = Py_BuildValue("(ddd)", rgb[0], rgb[1], rgb[2]);
        if (!t)
            Py_CLEAR(out);
        else
            PyList_SET_ITEM(out, (Py_ssize_t)i, t);
    }
    PyBuffer_Release(&b);
    Py_DECREF(array);
    return out;
}

static PyObject *principled_diffuse(PyObject *self, void *closure)
{
    (void)closure;
    const double *d = wenv_material_diffuse(((MaterialObject *)self)->mat);
    return Py_BuildValue("(ddd)", d[0], d[1], d[2]);
}

static PyGetSetDef principled_getset[] = {
    {"diffuse", principled_diffuse, NULL,
     "The Lambertian part's albedo seen head-on (the upper layers let through less towards grazing: "
     "diffuse_at).", NULL},
    {"inputs", principled_inputs, NULL,
     "{name: value} of every input as evaluated (clamped as Cycles clamps them), 'distribution' and "
     "'oren_nayar'.", NULL},
    {"unhonoured", principled_unhonoured, NULL,
     "Names of the inputs set to something wenv does not shade, or shades in part (subsurface scattering as "
     "diffuse, Alpha's see-through part left out, a Coat Tint above 1 as 1); wenv.Principled.INPUTS gives each "
     "one's note.",
     NULL},
    {NULL, NULL, NULL, NULL, NULL},
};

static PyMethodDef principled_methods[] = {
    {"__reduce__", principled_reduce, METH_NOARGS, NULL},
    {"diffuse_at", principled_diffuse_at, METH_O,
     "diffuse_at(cos_v)\n--\n\nThe Lambertian part's albedo (RGB) for views at cos_v to the normal (a number or "
     "a sequence): Base Color times what the coat, metal and specular layers let through, as Cycles layers them."},
    {NULL, NULL, 0, NULL},
};

static PyTypeObject PrincipledType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "wenv.Principled",
    .tp_basicsize = sizeof(MaterialObject),
    .tp_flags = Py_TPFLAGS_DEFAULT,
    .tp_doc = "Principled(**inputs)\n--\n\nBlender's Principled BSDF, evaluated as Cycles (Blender 4.x/5.x) "
              "evaluates it: the node's inputs by name in snake case (wenv.Principled.INPUTS lists each with its "
              "socket, size, default and whether wenv shades it) with Blender's defaults for the rest, and "
              "distribution='multiscatter_ggx' (Blender's "
              "default) or 'ggx'.  oren_nayar='energy_preserving' (Cycles from Blender 4.3 on) or 'classic' (before "
              "it: a Diffuse BSDF's Roughness) is the model of Diffuse Roughness.  Colours are a grey number, (r, g, b) or Blender's (r, g, b, a).  Roughness is "
              "Blender's (alpha = roughness^2).  Values are clamped as Cycles' kernel clamps them; non-finite ones, "
              "and inputs that scale the reflection past 1e6, are a ValueError.  Reflection only: `unhonoured` "
              "names what is set but not shaded.  Immutable.",
    .tp_new = principled_new,
    .tp_repr = principled_repr,
    .tp_getset = principled_getset,
    .tp_methods = principled_methods,
};

/* Principled.INPUTS: the list of inputs (scene/principled_inputs.h) as a tuple of dicts, from which
 * callers such as the add-on map sockets and draw panels. */
static PyObject *inputs_table(void)
{
    static const char *const SHADING[] = {"yes", "partly", "no"};
    PyObject *t = PyTuple_New((Py_ssize_t)wenv_principled_input_count);
    for (size_t r = 0; t && r < wenv_principled_input_count; r++) {
        const wenv_principled_input *row = &wenv_principled_input_list[r];
        PyObject *fallback = row->n == 3 ? Py_BuildValue("(ddd)", row->fallback[0], row->fallback[1], row->fallback[2])
                                         : PyFloat_FromDouble(row->fallback[0]);
        /* what Shader.shade takes per vertex: the list's inputs, and the colours it takes on their own */
        int per_vertex = strcmp(row->name, "base_color") == 0 || strcmp(row->name, "emission_color") == 0;
        for (int k = 0; k < WENV_VERTEX_INPUT_COUNT; k++)
            per_vertex |= wenv_vertex_input_list[k].row == row;
        PyObject *d = fallback ? Py_BuildValue("{s:s,s:s,s:i,s:N,s:s,s:s,s:O}", "name", row->name, "socket",
                                               row->socket, "size", row->n, "default", fallback, "shaded",
                                               SHADING[row->shading], "note", row->note, "per_vertex",
                                               per_vertex ? Py_True : Py_False)
                               : NULL;
        if (!d) {
            Py_CLEAR(t);
            break;
        }
        PyTuple_SET_ITEM(t, (Py_ssize_t)r, d);
    }
    return t;
}

int wenv_register_principled(PyObject *module)
{
    PrincipledType.tp_base = wenv_py_material_type();
    if (PyType_Ready(&PrincipledType) < 0)
        return -1;
    PyObject *table = inputs_table();
    if (!table || PyDict_SetItemString(PrincipledType.tp_dict, "INPUTS", table) < 0) {
        Py_XDECREF(table);
        return -1;
    }
    Py_DECREF(table);
    /* how much may vary per vertex (material_family.h): any values of at most `exact_materials`
     * distinct materials, or at most `smooth_channels` input channels varying smoothly */
    PyObject *limits = Py_BuildValue("{s:i,s:i}", "exact_materials", WENV_FAMILY_EXACT_LEVELS, "smooth_channels",
                                     WENV_FAMILY_MAX_AXES);
    if (!limits || PyDict_SetItemString(PrincipledType.tp_dict, "PER_VERTEX", limits) < 0) {
        Py_XDECREF(limits);
        return -1;
    }
    Py_DECREF(limits);
    PyType_Modified(&PrincipledType);
    Py_INCREF(&PrincipledType);
    if (PyModule_AddObject(module, "Principled", (PyObject *)&PrincipledType) < 0) {
        Py_DECREF(&PrincipledType);
        return -1;
    }
    return 0;
}
