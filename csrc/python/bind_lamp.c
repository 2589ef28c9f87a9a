/* wenv.Lamp: a scene's lamp as Blender sets it up (scene/lamp.h). */
#include "python/bind_lamp.h"

#include <math.h>
#include <string.h>

#include "python/bind_occlusion.h"
#include "python/module.h"

typedef struct {
    PyObject_HEAD
    wenv_lamp lamp;
    PyObject *blockers; /* the wenv.Occluders lamp.blockers points into, or NULL */
} LampObject;

static PyTypeObject LampType;

static const char *const KIND_NAMES[] = {"SUN", "POINT", "SPOT", "AREA"};
static const char *const SHAPE_NAMES[] = {"SQUARE", "RECTANGLE", "DISK", "ELLIPSE"};

/* The index of obj (a str) among names; -1 + ValueError naming `name` otherwise. */
static int name_index(PyObject *obj, const char *name, const char *const *names, int count)
{
    const char *s = PyUnicode_Check(obj) ? PyUnicode_AsUTF8(obj) : NULL;
    for (int i = 0; s && i < count; i++)
        if (strcmp(s, names[i]) == 0)
            return i;
    if (!PyErr_Occurred())
        PyErr_Format(PyExc_ValueError, "%s must be one of %s, %s, %s or %s, got %R", name, names[0], names[1],
                     names[2], names[3], obj);
    return -1;
}

static int get_flag(PyObject *obj, const char *name, int *out)
{
    if (!obj)
        return 0;
    int v = PyObject_IsTrue(obj);
    if (v < 0)
        return -1;
    (void)name;
    *out = v;
    return 0;
}

static int get_real(PyObject *obj, const char *name, double *out)
{
    return obj ? wenv_py_get_finite(obj, name, out) : 0;
}

static int lamp_init(LampObject *self, PyObject *args, PyObject *kwargs)
{
    static char *kwlist[] = {"type",         "matrix",     "color",      "energy",   "exposure", "normalize",
                             "radius",       "soft_falloff", "angle",    "spot_size", "spot_blend", "shape",
                             "size",         "size_y",     "spread",     "cast_shadow", "diffuse", "glossy", "blockers", NULL};
    PyObject *type_obj, *matrix = Py_None, *color = NULL, *energy = NULL, *exposure = NULL, *normalize = NULL;
    PyObject *radius = NULL, *soft = NULL, *angle = NULL, *spot_size = NULL, *spot_blend = NULL, *shape = NULL;
    PyObject *size = NULL, *size_y = NULL, *spread = NULL, *shadow = NULL, *diffuse = NULL, *glossy = NULL;
    PyObject *blockers = Py_None;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "O|O$OOOOOOOOOOOOOOOOO:Lamp", kwlist, &type_obj, &matrix, &color,
                                     &energy, &exposure, &normalize, &radius, &soft, &angle, &spot_size, &spot_blend,
                                     &shape, &size, &size_y, &spread, &shadow, &diffuse, &glossy, &blockers))
        return -1;
    const wenv_occluders *own = NULL;
    if (blockers != Py_None && !(own = wenv_py_occluders(blockers, "blockers")))
        return -1;
    int kind = name_index(type_obj, "type", KIND_NAMES, 4);
    if (kind < 0)
        return -1;
    wenv_lamp_settings s;
    wenv_lamp_settings_defaults(&s, (wenv_lamp_kind)kind);
    if (matrix != Py_None && wenv_py_get_matrix(matrix, "matrix", 4, 16, s.matrix) < 0)
        return -1;
    if (color && wenv_py_get_rgb(color, "color", s.color) < 0)
        return -1;
    if (get_real(energy, "energy", &s.energy) < 0 || get_real(exposure, "exposure", &s.exposure) < 0 ||
        get_flag(normalize, "normalize", &s.normalize) < 0 || get_real(radius, "radius", &s.radius) < 0 ||
        get_flag(soft, "soft_falloff", &s.soft_falloff) < 0 || get_real(angle, "angle", &s.angle) < 0 ||
        get_real(spot_size, "spot_size", &s.spot_size) < 0 || get_real(spot_blend, "spot_blend", &s.spot_blend) < 0 ||
        get_real(size, "size", &s.size) < 0 || get_real(size_y, "size_y", &s.size_y) < 0 ||
        get_real(spread, "spread", &s.spread) < 0 || get_flag(shadow, "cast_shadow", &s.cast_shadow) < 0 ||
        get_flag(diffuse, "diffuse", &s.diffuse) < 0 || get_flag(glossy, "glossy", &s.glossy) < 0)
        return -1;
    if (shape) {
        int k = name_index(shape, "shape", SHAPE_NAMES, 4);
        if (k < 0)
            return -1;
        s.shape = (wenv_lamp_shape)k;
    }
    wenv_error err = {0};
    if (wenv_lamp_make(&self->lamp, &s, "Lamp", &err)) {
        wenv_py_raise(&err);
        return -1;
    }
    self->lamp.blockers = own;
    Py_XSETREF(self->blockers, own ? Py_NewRef(blockers) : NULL);
    return 0;
}

static void lamp_dealloc(LampObject *self)
{
    Py_XDECREF(self->blockers);
    Py_TYPE(self)->tp_free((PyObject *)self);
}

static PyObject *lamp_get_blockers(LampObject *self, void *closure)
{
    (void)closure;
    return Py_NewRef(self->blockers ? self->blockers : Py_None);
}

int wenv_py_lamps(PyObject *obj, const char *name, wenv_lamp **lamps, size_t *n)
{
    *lamps = NULL;
    *n = 0;
    if (!obj || obj == Py_None)
        return 0;
    PyObject *seq = PySequence_Fast(obj, "lamps must be a sequence of wenv.Lamp");
    if (!seq)
        return -1;
    Py_ssize_t count = PySequence_Fast_GET_SIZE(seq);
    if (count && !(*lamps = PyMem_Malloc((size_t)count * sizeof **lamps))) {
        Py_DECREF(seq);
        PyErr_NoMemory();
        return -1;
    }
    for (Py_ssize_t i = 0; i < count; i++) {
        PyObject *item = PySequence_Fast_GET_ITEM(seq, i);
        if (!PyObject_TypeCheck(item, &LampType)) {
            PyErr_Format(PyExc_TypeError, "%s[%zd] must be a wenv.Lamp, got %.100s", name, i, Py_TYPE(item)->tp_name);
            PyMem_Free(*lamps);
            *lamps = NULL;
            Py_DECREF(seq);
            return -1;
        }
        (*lamps)[i] = ((LampObject *)item)->lamp;
    }
    *n = (size_t)count;
    Py_DECREF(seq);
    return 0;
}

static PyObject *lamp_get_type(LampObject *self, void *closure)
{
    (void)closure;
    return PyUnicode_FromString(KIND_NAMES[self->lamp.settings.kind]);
}

static PyObject *lamp_get_radiance(LampObject *self, void *closure)
{
    (void)closure;
    const double *r = self->lamp.radiance;
    return Py_BuildValue("(ddd)", r[0], r[1], r[2]);
}

static PyObject *lamp_get_position(LampObject *self, void *closure)
{
    (void)closure;
    const double *p = self->lamp.position;
    return Py_BuildValue("(ddd)", p[0], p[1], p[2]);
}

static PyObject *lamp_repr(LampObject *self)
{
    const wenv_lamp_settings *s = &self->lamp.settings;
    char buf[160];
    snprintf(buf, sizeof buf, "wenv.Lamp('%s', energy=%g, at=(%g, %g, %g))", KIND_NAMES[s->kind], s->energy,
             self->lamp.position[0], self->lamp.position[1], self->lamp.position[2]);
    return PyUnicode_FromString(buf);
}

static PyGetSetDef lamp_getset[] = {
    {"type", (getter)lamp_get_type, NULL, "'SUN', 'POINT', 'SPOT' or 'AREA'.", NULL},
    {"radiance", (getter)lamp_get_radiance, NULL,
     "What it emits as Cycles does (RGB): the radiance of its surface; a point lamp's (radius 0) intensity "
     "in W/sr; a sun of angle 0's irradiance in W/m^2.",
     NULL},
    {"position", (getter)lamp_get_position, NULL, "Where it is (the matrix's last column).", NULL},
    {"blockers", (getter)lamp_get_blockers, NULL,
     "The wenv.Occluders that block its light where shadows are on, in place of the scene's (a Light's shadow "
     "linking), or None: the scene's.",
     NULL},
    {NULL, NULL, NULL, NULL, NULL},
};

static PyTypeObject LampType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "wenv.Lamp",
    .tp_basicsize = sizeof(LampObject),
    .tp_flags = Py_TPFLAGS_DEFAULT,
    .tp_doc = "Lamp(type, matrix=None, *, color=(1, 1, 1), energy=10, exposure=0, normalize=True, radius=0, "
              "soft_falloff=True, angle=0.00918, spot_size=pi/4, spot_blend=0.15, shape='SQUARE', size=0.25, "
              "size_y=0.25, spread=pi, cast_shadow=True, diffuse=True, glossy=True, blockers=None)\n--\n\n"
              "A scene's lamp as a Blender Light object sets it up, shaded as Cycles emits it (docs/lamps.md).  "
              "type: 'SUN', 'POINT', 'SPOT' or 'AREA'; matrix: the object's matrix_world (4 x 4; None: at the "
              "origin, shining down -Z); the rest are the Light's settings under Blender's names (radius is "
              "shadow_soft_size, soft_falloff use_soft_falloff, cast_shadow use_shadow; color times the "
              "temperature's colour where the light uses one), and diffuse and glossy the object's ray "
              "visibility.  Energy is in W (a sun's in W/m^2).  blockers (a wenv.Occluders): what blocks its light "
              "where a call is shadowed, in place of the call's occluders (a Light's shadow linking).  A "
              "ValueError names a setting out of Blender's range: a negative or infinite energy, say.",
    .tp_new = PyType_GenericNew,
    .tp_init = (initproc)lamp_init,
    .tp_dealloc = (destructor)lamp_dealloc,
    .tp_repr = (reprfunc)lamp_repr,
    .tp_getset = lamp_getset,
};

int wenv_register_lamp(PyObject *module)
{
    if (PyType_Ready(&LampType) < 0)
        return -1;
    Py_INCREF(&LampType);
    if (PyModule_AddObject(module, "Lamp", (PyObject *)&LampType) < 0) {
        Py_DECREF(&LampType);
        return -1;
    }
    return 0;
}
