/* Python glue for the virtual glossmeter: wenv.Glossmeter, wenv.gloss, wenv.haze, wenv.fit_alpha,
 * wenv.fit_roughness.
 * The numerics live in glossmeter.c; this file parses arguments, releases the GIL around the
 * integrals and turns results into Python values. */
#include "python/bind_material.h"
#include "python/module.h"

#include <math.h>
#include <stdint.h>
#include <string.h>

#ifndef M_PI
#define M_PI 3.14159265358979323846
#endif
#ifndef M_SQRT1_2
#define M_SQRT1_2 0.70710678118654752440
#endif

#include "glossmeter/glossmeter.h"
#include "scene/material.h"

#define HAZE_OFFSET 1.9       /* ASTM E430 method B: receptors at 20 -/+ 1.9 = 18.1 and 21.9 degrees */
#define HAZE_APERTURE_W 0.4   /* assumed haze slit size, in plane x perpendicular (degrees) */
#define HAZE_APERTURE_H 3.6
#define FIT_ALPHA_LO 1e-4
#define FIT_ALPHA_HI 2.0
#define FIT_ROUGHNESS_LO 1e-3 /* Blender's roughness r: alpha 1e-6, below the core's floor of 1e-4 alpha anyway */
#define FIT_ROUGHNESS_HI 1.0

typedef struct {
    PyObject_HEAD
    wenv_glossmeter *gm;
} GlossmeterObject;

static PyTypeObject GlossmeterType;

/* ---------------------------------------------------------------- argument helpers */

/* A sequence of `n` finite numbers; errors name `name`. */
static int get_vec(PyObject *obj, const char *name, double *out, Py_ssize_t n)
{
    PyObject *seq = PySequence_Check(obj) && !PyUnicode_Check(obj) ? PySequence_Fast(obj, "") : NULL;
    if (!seq) {
        PyErr_Clear();
        PyErr_Format(PyExc_TypeError, "%s must be a sequence of %zd numbers, got %.100s", name, n,
                     Py_TYPE(obj)->tp_name);
        return -1;
    }
    if (PySequence_Fast_GET_SIZE(seq) != n) {
        PyErr_Format(PyExc_ValueError, "%s must have %zd components, got %zd", name, n, PySequence_Fast_GET_SIZE(seq));
        Py_DECREF(seq);
        return -1;
    }
    for (Py_ssize_t i = 0; i < n; i++) {
        if (wenv_py_get_finite(PySequence_Fast_GET_ITEM(seq, i), name, &out[i]) < 0) {
            Py_DECREF(seq);
            return -1;
        }
    }
    Py_DECREF(seq);
    return 0;
}

static int get_opt_vec(PyObject *obj, const char *name, double *out, Py_ssize_t n)
{
    return (obj && obj != Py_None) ? get_vec(obj, name, out, n) : 0;
}

static int get_method(PyObject *obj, wenv_gloss_options *opt)
{
    static const char *const names[] = {"auto", "aperture", "half_vector"};
    if (!obj || obj == Py_None)
        return 0;
    const char *s = PyUnicode_Check(obj) ? PyUnicode_AsUTF8(obj) : NULL;
    if (!s) {
        if (!PyErr_Occurred())
            PyErr_Format(PyExc_TypeError, "method must be a str, got %.100s", Py_TYPE(obj)->tp_name);
        return -1;
    }
    for (int i = 0; i < 3; i++) {
        if (strcmp(s, names[i]) == 0) {
            opt->method = i;
            return 0;
        }
    }
    PyErr_Format(PyExc_ValueError, "method must be 'auto', 'aperture' or 'half_vector', got %R", obj);
    return -1;
}

/* Keyword options shared by every measurement: tol, max_evals, smooth. */
static int get_options(PyObject *tol, PyObject *max_evals, PyObject *smooth, wenv_gloss_options *opt)
{
    wenv_gloss_options_default(opt);
    if (tol && tol != Py_None) {
        if (wenv_py_get_finite(tol, "tol", &opt->tol) < 0)
            return -1;
        if (opt->tol <= 0.0) {
            wenv_py_errorf(PyExc_ValueError, "tol must be > 0 gloss units, got %g", opt->tol);
            return -1;
        }
    }
    if (max_evals && max_evals != Py_None) {
        size_t v;
        if (wenv_py_get_size(max_evals, "max_evals", &v) < 0)
            return -1;
        if (v < 1000) {
            PyErr_Format(PyExc_ValueError, "max_evals must be at least 1000, got %zu", v);
            return -1;
        }
        opt->max_evals = v;
    }
    if (smooth) {
        int b = PyObject_IsTrue(smooth);
        if (b < 0)
            return -1;
        opt->smooth = b;
    }
    return 0;
}

static PyObject *not_converged(const wenv_gloss_result *r, const wenv_gloss_options *opt)
{
    wenv_py_errorf(PyExc_RuntimeError,
                 "glossmeter: the integral did not reach tol=%g within max_evals=%zu evaluations "
                 "(reading %.4f, estimated error %.3g); raise max_evals or tol",
                 opt->tol, opt->max_evals, r->value, r->error);
    return NULL;
}

static PyObject *result_value(const wenv_gloss_result *r, const wenv_gloss_options *opt, int return_error)
{
    if (!r->converged)
        return not_converged(r, opt);
    if (return_error)
        return Py_BuildValue("(dd)", r->value, r->error);
    return PyFloat_FromDouble(r->value);
}

/* A reading (offsets NULL) or haze, with the GIL released.  The material object is kept alive by a
 * reference of our own; materials and glossmeters are immutable, so other threads may use them. */
static int run_reading(const wenv_glossmeter *gm, PyObject *material, const double *offsets,
                       const double *aperture, const wenv_gloss_options *opt, wenv_gloss_result *r)
{
    const wenv_material *mat = wenv_py_material(material, "material");
    if (!mat)
        return -1;
    wenv_error err = {0};
    wenv_status st;
    Py_INCREF(material);
    WENV_BEGIN_WORK
    st = offsets ? wenv_glossmeter_haze(gm, mat, offsets, aperture, opt, r, &err)
                 : wenv_glossmeter_measure(gm, mat, opt, r, &err);
    WENV_END_WORK
    Py_DECREF(material);
    if (st != WENV_OK) {
        wenv_py_raise(&err);
        return -1;
    }
    return 0;
}

static int run_measure(const wenv_glossmeter *gm, PyObject *material, const wenv_gloss_options *opt,
                       wenv_gloss_result *r)
{
    return run_reading(gm, material, NULL, NULL, opt, r);
}

static int run_haze(const wenv_glossmeter *gm, PyObject *material, PyObject *offsets_obj, PyObject *aperture_obj,
                    const wenv_gloss_options *opt, wenv_gloss_result *r)
{
    double offsets[2] = {-HAZE_OFFSET, HAZE_OFFSET}, aperture[2] = {HAZE_APERTURE_W, HAZE_APERTURE_H};
    if (get_opt_vec(offsets_obj, "offsets", offsets, 2) < 0 || get_opt_vec(aperture_obj, "aperture", aperture, 2) < 0)
        return -1;
    return run_reading(gm, material, offsets, aperture, opt, r);
}


static wenv_glossmeter *standard_meter(double geometry)
{
    wenv_glossmeter_config cfg;
    wenv_error err = {0};
    wenv_glossmeter *gm = NULL;
    if (wenv_glossmeter_standard_config(&cfg, geometry, &err) != WENV_OK ||
        wenv_glossmeter_create(&gm, &cfg, &err) != WENV_OK) {
        wenv_py_raise(&err);
        return NULL;
    }
    return gm;
}

/* ---------------------------------------------------------------- fit_roughness */

/* Pops the fit's own keyword options from a copy of kwds, leaving the material parameters. */
static PyObject *pop_kw(PyObject *kw, const char *name)
{
    if (!kw)
        return NULL;
    PyObject *v = PyDict_GetItemString(kw, name);
    if (v) {
        Py_INCREF(v);
        PyDict_DelItemString(kw, name);
    }
    return v;
}

static const char *const FIT_CALLERS[] = {"fit_alpha()", "fit_roughness()"};

/* The fit of `param`: of a given material, or (alpha only) of a one-lobe Cook-Torrance made from the
 * remaining keyword parameters. */
static PyObject *do_fit(const wenv_glossmeter *gm, wenv_fit_param param, PyObject *target_obj, PyObject *params)
{
    const char *caller = FIT_CALLERS[param];
    double target;
    if (wenv_py_get_finite(target_obj, "target_gu", &target) < 0)
        return NULL;
    PyObject *bracket_obj = pop_kw(params, "bracket"), *tol_obj = pop_kw(params, "tol"),
             *evals_obj = pop_kw(params, "max_evals"), *material_obj = pop_kw(params, "material");
    PyObject *result = NULL;
    wenv_material *tmpl = NULL;
    const wenv_material *mat = NULL;
    double bracket[2] = {param == WENV_FIT_ALPHA ? FIT_ALPHA_LO : FIT_ROUGHNESS_LO,
                         param == WENV_FIT_ALPHA ? FIT_ALPHA_HI : FIT_ROUGHNESS_HI};
    wenv_gloss_options opt;
    if (get_opt_vec(bracket_obj, "bracket", bracket, 2) < 0 || get_options(tol_obj, evals_obj, NULL, &opt) < 0)
        goto done;
    if (material_obj) {
        if (PyDict_Size(params) > 0) {
            PyErr_Format(PyExc_TypeError, "%s takes either material= or the parameters of a Cook-Torrance lobe, not both",
                         caller);
            goto done;
        }
        mat = wenv_py_material(material_obj, "material");
    } else if (param == WENV_FIT_ROUGHNESS) {
        PyErr_SetString(PyExc_TypeError,
                        "fit_roughness() fits Blender's roughness r of material=... (a wenv.Principled); a Cook-Torrance "
                        "lobe's parameter is alpha: fit_alpha(target_gu, geometry, **lobe_params)");
        goto done;
    } else {
        mat = tmpl = wenv_py_one_lobe_material(params, caller);
    }
    if (!mat)
        goto done;
    double value = NAN;
    wenv_gloss_result r = {0};
    wenv_error err = {0};
    wenv_status st;
    WENV_BEGIN_WORK
    st = wenv_glossmeter_fit(gm, mat, param, target, bracket[0], bracket[1], &opt, &value, &r, &err);
    WENV_END_WORK
    if (st != WENV_OK)
        wenv_py_raise(&err);
    else if (!r.converged)
        not_converged(&r, &opt);
    else
        result = PyFloat_FromDouble(value);
done:
    Py_XDECREF(bracket_obj);
    Py_XDECREF(tol_obj);
    Py_XDECREF(evals_obj);
    Py_XDECREF(material_obj);
    wenv_material_free(tmpl);
    return result;
}

/* ---------------------------------------------------------------- wenv.Glossmeter */

static void glossmeter_dealloc(PyObject *self)
{
    wenv_glossmeter_free(((GlossmeterObject *)self)->gm);
    Py_TYPE(self)->tp_free(self);
}

static PyObject *glossmeter_new(PyTypeObject *type, PyObject *args, PyObject *kwds)
{
    static char *kwlist[] = {"angle", "source", "receptor", "standard_ior", "normal", "receptor_offset", NULL};
    PyObject *angle_obj = NULL, *source_obj = NULL, *receptor_obj = NULL, *ior_obj = NULL, *normal_obj = NULL,
             *offset_obj = NULL;
    if (!PyArg_ParseTupleAndKeywords(args, kwds, "|OOOOOO:Glossmeter", kwlist, &angle_obj, &source_obj,
                                     &receptor_obj, &ior_obj, &normal_obj, &offset_obj))
        return NULL;
    double angle = 60.0;
    if (angle_obj && wenv_py_get_finite(angle_obj, "angle", &angle) < 0)
        return NULL;
    /* Apertures default to the ISO 2813 ones of the angle (the 60 degree ones off 20/60/85). */
    wenv_glossmeter_config cfg;
    wenv_error err = {0};
    if (wenv_glossmeter_standard_config(&cfg, (angle == 20.0 || angle == 85.0) ? angle : 60.0, &err) != WENV_OK)
        return wenv_py_raise(&err);
    cfg.angle = angle;
    if (get_opt_vec(source_obj, "source", cfg.source, 2) < 0 || get_opt_vec(receptor_obj, "receptor", cfg.receptor, 2) < 0 ||
        get_opt_vec(normal_obj, "normal", cfg.normal, 3) < 0 ||
        get_opt_vec(offset_obj, "receptor_offset", cfg.receptor_offset, 2) < 0)
        return NULL;
    if (ior_obj && ior_obj != Py_None && wenv_py_get_finite(ior_obj, "standard_ior", &cfg.standard_ior) < 0)
        return NULL;
    wenv_glossmeter *gm;
    wenv_status st;
    WENV_BEGIN_WORK
    st = wenv_glossmeter_create(&gm, &cfg, &err);
    WENV_END_WORK
    if (st != WENV_OK)
        return wenv_py_raise(&err);
    if (!(wenv_glossmeter_standard_flux(gm, NULL) > 0.0)) {
        wenv_glossmeter_free(gm);
        PyErr_SetString(PyExc_ValueError, "receptor_offset: the receptor does not see the mirror image of the source, "
                                          "so the standard would read zero");
        return NULL;
    }
    GlossmeterObject *self = (GlossmeterObject *)type->tp_alloc(type, 0);
    if (!self) {
        wenv_glossmeter_free(gm);
        return NULL;
    }
    self->gm = gm;
    return (PyObject *)self;
}

static const wenv_glossmeter *meter_of(PyObject *self) { return ((GlossmeterObject *)self)->gm; }

static PyObject *glossmeter_measure(PyObject *self, PyObject *args, PyObject *kwds)
{
    static char *kwlist[] = {"material", "tol", "smooth", "return_error", "max_evals", NULL};
    PyObject *material, *tol = NULL, *smooth = NULL, *max_evals = NULL;
    int return_error = 0;
    if (!PyArg_ParseTupleAndKeywords(args, kwds, "O|$OOpO:measure", kwlist, &material, &tol, &smooth, &return_error,
                                     &max_evals))
        return NULL;
    wenv_gloss_options opt;
    wenv_gloss_result r;
    if (get_options(tol, max_evals, smooth, &opt) < 0 || run_measure(meter_of(self), material, &opt, &r) < 0)
        return NULL;
    return result_value(&r, &opt, return_error);
}

static PyObject *result_dict(const wenv_gloss_result *r, const char *value_key)
{
    return Py_BuildValue("{s:d,s:d,s:d,s:d,s:n,s:O}", value_key, r->value, "error", r->error, "flux", r->flux,
                         "flux_standard", r->flux_standard, "evaluations", (Py_ssize_t)r->evaluations, "converged",
                         r->converged ? Py_True : Py_False);
}

static PyObject *glossmeter_reading(PyObject *self, PyObject *args, PyObject *kwds)
{
    static char *kwlist[] = {"material", "tol", "smooth", "max_evals", "method", NULL};
    PyObject *material, *tol = NULL, *smooth = NULL, *max_evals = NULL, *method = NULL;
    if (!PyArg_ParseTupleAndKeywords(args, kwds, "O|$OOOO:reading", kwlist, &material, &tol, &smooth, &max_evals,
                                     &method))
        return NULL;
    wenv_gloss_options opt;
    wenv_gloss_result r;
    if (get_options(tol, max_evals, smooth, &opt) < 0 || get_method(method, &opt) < 0 ||
        run_measure(meter_of(self), material, &opt, &r) < 0)
        return NULL;
    return result_dict(&r, "gloss");
}

static PyObject *haze_impl(const wenv_glossmeter *gm, PyObject *args, PyObject *kwds)
{
    static char *kwlist[] = {"material", "offsets", "aperture", "tol", "smooth", "return_error", "max_evals", NULL};
    PyObject *material, *offsets = NULL, *aperture = NULL, *tol = NULL, *smooth = NULL, *max_evals = NULL;
    int return_error = 0;
    if (!PyArg_ParseTupleAndKeywords(args, kwds, "O|$OOOOpO:haze", kwlist, &material, &offsets, &aperture, &tol,
                                     &smooth, &return_error, &max_evals))
        return NULL;
    wenv_gloss_options opt;
    wenv_gloss_result r;
    if (get_options(tol, max_evals, smooth, &opt) < 0 || run_haze(gm, material, offsets, aperture, &opt, &r) < 0)
        return NULL;
    return result_value(&r, &opt, return_error);
}

static PyObject *glossmeter_haze(PyObject *self, PyObject *args, PyObject *kwds)
{
    return haze_impl(meter_of(self), args, kwds);
}

static PyObject *glossmeter_fit(PyObject *self, PyObject *args, PyObject *kwds, wenv_fit_param param)
{
    PyObject *target;
    if (!PyArg_ParseTuple(args, param == WENV_FIT_ALPHA ? "O:fit_alpha" : "O:fit_roughness", &target))
        return NULL;
    PyObject *params = kwds ? PyDict_Copy(kwds) : PyDict_New();
    if (!params)
        return NULL;
    PyObject *r = do_fit(meter_of(self), param, target, params);
    Py_DECREF(params);
    return r;
}

static PyObject *glossmeter_fit_alpha(PyObject *self, PyObject *args, PyObject *kwds)
{
    return glossmeter_fit(self, args, kwds, WENV_FIT_ALPHA);
}

static PyObject *glossmeter_fit_roughness(PyObject *self, PyObject *args, PyObject *kwds)
{
    return glossmeter_fit(self, args, kwds, WENV_FIT_ROUGHNESS);
}

static PyObject *glossmeter_repr(PyObject *self)
{
    const wenv_glossmeter_config *c = wenv_glossmeter_config_of(meter_of(self));
    char buf[400];
    snprintf(buf, sizeof buf,
             "wenv.Glossmeter(angle=%g, source=(%g, %g), receptor=(%g, %g), standard_ior=%g, normal=(%g, %g, %g), "
             "receptor_offset=(%g, %g))",
             c->angle, c->source[0], c->source[1], c->receptor[0], c->receptor[1], c->standard_ior, c->normal[0],
             c->normal[1], c->normal[2], c->receptor_offset[0], c->receptor_offset[1]);
    return PyUnicode_FromString(buf);
}

enum { G_ANGLE, G_SOURCE, G_RECEPTOR, G_IOR, G_NORMAL, G_OFFSET, G_STD_FLUX, G_STD_REFL, G_PROJ_S, G_PROJ_D };

static PyObject *glossmeter_get(PyObject *self, void *closure)
{
    const wenv_glossmeter *gm = meter_of(self);
    const wenv_glossmeter_config *c = wenv_glossmeter_config_of(gm);
    double ps, pd;
    switch ((int)(intptr_t)closure) {
    case G_ANGLE: return PyFloat_FromDouble(c->angle);
    case G_SOURCE: return Py_BuildValue("(dd)", c->source[0], c->source[1]);
    case G_RECEPTOR: return Py_BuildValue("(dd)", c->receptor[0], c->receptor[1]);
    case G_IOR: return PyFloat_FromDouble(c->standard_ior);
    case G_NORMAL: return Py_BuildValue("(ddd)", c->normal[0], c->normal[1], c->normal[2]);
    case G_OFFSET: return Py_BuildValue("(dd)", c->receptor_offset[0], c->receptor_offset[1]);
    case G_STD_FLUX: return PyFloat_FromDouble(wenv_glossmeter_standard_flux(gm, NULL));
    case G_STD_REFL: return PyFloat_FromDouble(wenv_fresnel_dielectric(cos(c->angle * M_PI / 180.0), c->standard_ior));
    case G_PROJ_S:
    case G_PROJ_D:
        wenv_glossmeter_projected_solid_angles(gm, &ps, &pd);
        return PyFloat_FromDouble((int)(intptr_t)closure == G_PROJ_S ? ps : pd);
    }
    Py_RETURN_NONE;
}

#define GETTER(name, id, doc) {name, glossmeter_get, NULL, doc, (void *)(intptr_t)(id)}
static PyGetSetDef glossmeter_getset[] = {
    GETTER("angle", G_ANGLE, "Specular angle (degrees) of source and receptor from the instrument axis."),
    GETTER("source", G_SOURCE, "Source image size (in plane, perpendicular), degrees."),
    GETTER("receptor", G_RECEPTOR, "Receptor field size (in plane, perpendicular), degrees."),
    GETTER("standard_ior", G_IOR, "Refractive index of the smooth black-glass standard (reads 100 GU)."),
    GETTER("normal", G_NORMAL, "Specimen normal in the instrument frame (axis +Z), as given."),
    GETTER("receptor_offset", G_OFFSET,
           "Receptor centre relative to the mirror direction (in plane towards grazing, perpendicular), degrees."),
    GETTER("standard_flux", G_STD_FLUX, "Flux of the standard (sr^2): the denominator of every reading."),
    GETTER("standard_reflectance", G_STD_REFL,
           "Fresnel reflectance of the standard at the specular angle (0.04908 / 0.10006 / 0.61915 at 20/60/85)."),
    GETTER("source_projected_solid_angle", G_PROJ_S, "Integral of cos over the source aperture about the normal (sr)."),
    GETTER("receptor_projected_solid_angle", G_PROJ_D,
           "Integral of cos over the receptor aperture about the normal (sr)."),
    {NULL, NULL, NULL, NULL, NULL},
};

static PyMethodDef glossmeter_methods[] = {
    {"measure", (PyCFunction)(void (*)(void))glossmeter_measure, METH_VARARGS | METH_KEYWORDS,
     "measure($self, material, *, tol=0.05, smooth=False, return_error=False, max_evals=4000000)\n--\n\n"
     "Specular gloss of `material` in gloss units: 100 x its flux / the standard's flux.  The integrals are\n"
     "adaptive (hcubature) with an estimated error of at most `tol` GU; return_error=True returns\n"
     "(gloss, error_estimate).  smooth=True reads every lobe as its smooth limit (a Fresnel mirror of the\n"
     "lobe's colour; the diffuse part stays).  RuntimeError if max_evals is reached before tol."},
    {"reading", (PyCFunction)(void (*)(void))glossmeter_reading, METH_VARARGS | METH_KEYWORDS,
     "reading($self, material, *, tol=0.05, smooth=False, max_evals=4000000, method='auto')\n--\n\n"
     "Like measure(), as a dict: gloss, error, flux, flux_standard, evaluations, converged (no exception\n"
     "when the cap is hit).  method forces the lobes' formulation for validation: 'aperture' (4-D over\n"
     "source x receptor) or 'half_vector' (slopes outside, clipped source inside); 'auto' picks per lobe."},
    {"haze", (PyCFunction)(void (*)(void))glossmeter_haze, METH_VARARGS | METH_KEYWORDS,
     "haze($self, material, *, offsets=(-1.9, 1.9), aperture=(0.4, 3.6), tol=0.05, smooth=False, "
     "return_error=False, max_evals=4000000)\n--\n\n"
     "Haze (ASTM E430 method B style) in haze units: 100 x the flux into two receptors of size `aperture`\n"
     "whose centres are turned in the plane of incidence by `offsets` (degrees) from the mirror direction,\n"
     "summed, over this glossmeter's standard flux."},
    {"fit_alpha", (PyCFunction)(void (*)(void))glossmeter_fit_alpha, METH_VARARGS | METH_KEYWORDS,
     "fit_alpha($self, target_gu, /, **material_params)\n--\n\n"
     "Keyword options: bracket=(1e-4, 2.0), tol=0.05, max_evals=4000000.\n"
     "The lobes' alpha of a one-lobe wenv.CookTorrance(**material_params), or of material=wenv.CookTorrance(...),\n"
     "that this glossmeter reads as target_gu; see wenv.fit_alpha."},
    {"fit_roughness", (PyCFunction)(void (*)(void))glossmeter_fit_roughness, METH_VARARGS | METH_KEYWORDS,
     "fit_roughness($self, target_gu, /, *, material, bracket=(1e-3, 1.0), tol=0.05, max_evals=4000000)\n--\n\n"
     "Blender's roughness r of material (a wenv.Principled) that this glossmeter reads as target_gu; see\n"
     "wenv.fit_roughness."},
    {NULL, NULL, 0, NULL},
};

static PyTypeObject GlossmeterType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "wenv.Glossmeter",
    .tp_basicsize = sizeof(GlossmeterObject),
    .tp_flags = Py_TPFLAGS_DEFAULT,
    .tp_doc =
        "Glossmeter(angle=60, source=None, receptor=None, standard_ior=1.567, normal=(0, 0, 1), "
        "receptor_offset=(0, 0))\n--\n\n"
        "A virtual ISO 2813 / ASTM D523 specular glossmeter.  angle: specular angle in (0, 90) degrees.\n"
        "source, receptor: full angular sizes (in plane of incidence, perpendicular) in degrees of the source\n"
        "image and the receptor field; when omitted they are the ISO ones of angle 20, 60 or 85 (the 60 degree\n"
        "ones for other angles).  The receptor is centred on the mirror direction of the source, moved by\n"
        "receptor_offset (degrees; in plane + = towards grazing).  standard_ior: index of the smooth black\n"
        "glass that reads 100 GU.  normal: the specimen's normal in the instrument frame (instrument axis +Z,\n"
        "source on the -X side); tilting it misaligns the specimen, the standard stays calibrated at +Z.\n"
        "Every part of both apertures must lie above the horizon (ValueError naming the argument).  Immutable.",
    .tp_new = glossmeter_new,
    .tp_dealloc = glossmeter_dealloc,
    .tp_repr = glossmeter_repr,
    .tp_getset = glossmeter_getset,
    .tp_methods = glossmeter_methods,
};

/* ---------------------------------------------------------------- module functions */

/* geometry: 20, 60, 85 or a sequence of them. */
static PyObject *module_gloss(PyObject *module, PyObject *args, PyObject *kwds)
{
    (void)module;
    static char *kwlist[] = {"material", "geometry", "tol", "smooth", "return_error", "max_evals", NULL};
    PyObject *material, *geometry = NULL, *tol = NULL, *smooth = NULL, *max_evals = NULL;
    int return_error = 0;
    if (!PyArg_ParseTupleAndKeywords(args, kwds, "O|O$OOpO:gloss", kwlist, &material, &geometry, &tol, &smooth,
                                     &return_error, &max_evals))
        return NULL;
    wenv_gloss_options opt;
    if (get_options(tol, max_evals, smooth, &opt) < 0 || !wenv_py_material(material, "material"))
        return NULL;
    int single = !geometry || PyNumber_Check(geometry);
    double geoms[8];
    Py_ssize_t n = 1;
    geoms[0] = 60.0;
    if (geometry && single) {
        if (wenv_py_get_finite(geometry, "geometry", &geoms[0]) < 0)
            return NULL;
    } else if (geometry) {
        PyObject *seq = PySequence_Fast(geometry, "");
        if (!seq) {
            PyErr_Clear();
            return PyErr_Format(PyExc_TypeError, "geometry must be 20, 60, 85 or a sequence of them, got %.100s",
                                Py_TYPE(geometry)->tp_name);
        }
        n = PySequence_Fast_GET_SIZE(seq);
        if (n < 1 || n > 8) {
            Py_DECREF(seq);
            return PyErr_Format(PyExc_ValueError, "geometry must list 1 to 8 angles, got %zd", n);
        }
        for (Py_ssize_t i = 0; i < n; i++) {
            if (wenv_py_get_finite(PySequence_Fast_GET_ITEM(seq, i), "geometry", &geoms[i]) < 0) {
                Py_DECREF(seq);
                return NULL;
            }
        }
        Py_DECREF(seq);
    }
    wenv_glossmeter *gms[8] = {NULL};
    wenv_gloss_result res[8];
    PyObject *out = NULL;
    for (Py_ssize_t i = 0; i < n; i++)
        if (!(gms[i] = standard_meter(geoms[i])))
            goto done;
    const wenv_material *mat = wenv_py_material(material, "material");
    wenv_error err = {0};
    wenv_status st;
    Py_INCREF(material);
    WENV_BEGIN_WORK
    st = wenv_glossmeter_measure_many(gms, (size_t)n, mat, &opt, res, &err);
    WENV_END_WORK
    Py_DECREF(material);
    if (st != WENV_OK) {
        wenv_py_raise(&err);
        goto done;
    }
    if (single) {
        out = result_value(&res[0], &opt, return_error);
        goto done;
    }
    if (!(out = PyTuple_New(n)))
        goto done;
    for (Py_ssize_t i = 0; i < n; i++) {
        PyObject *v = result_value(&res[i], &opt, return_error);
        if (!v) {
            Py_CLEAR(out);
            goto done;
        }
        PyTuple_SET_ITEM(out, i, v);
    }
done:
    for (Py_ssize_t i = 0; i < n; i++)
        wenv_glossmeter_free(gms[i]);
    return out;
}

static PyObject *module_haze(PyObject *module, PyObject *args, PyObject *kwds)
{
    (void)module;
    wenv_glossmeter *gm = standard_meter(20.0);
    if (!gm)
        return NULL;
    PyObject *r = haze_impl(gm, args, kwds);
    wenv_glossmeter_free(gm);
    return r;
}

static PyObject *module_fit(PyObject *args, PyObject *kwds, wenv_fit_param param)
{
    const char *caller = FIT_CALLERS[param];
    PyObject *target, *geometry = NULL;
    if (!PyArg_ParseTuple(args, param == WENV_FIT_ALPHA ? "O|O:fit_alpha" : "O|O:fit_roughness", &target, &geometry))
        return NULL;
    PyObject *params = kwds ? PyDict_Copy(kwds) : PyDict_New();
    if (!params)
        return NULL;
    PyObject *geom_kw = pop_kw(params, "geometry");
    PyObject *result = NULL;
    double g = 60.0;
    if (geometry && geom_kw) {
        PyErr_Format(PyExc_TypeError, "%s got multiple values for argument 'geometry'", caller);
    } else if (!(geometry || geom_kw) || wenv_py_get_finite(geometry ? geometry : geom_kw, "geometry", &g) == 0) {
        wenv_glossmeter *gm = PyErr_Occurred() ? NULL : standard_meter(g);
        if (gm) {
            result = do_fit(gm, param, target, params);
            wenv_glossmeter_free(gm);
        }
    }
    Py_XDECREF(geom_kw);
    Py_DECREF(params);
    return result;
}

static PyObject *module_fit_alpha(PyObject *module, PyObject *args, PyObject *kwds)
{
    (void)module;
    return module_fit(args, kwds, WENV_FIT_ALPHA);
}

static PyObject *module_fit_roughness(PyObject *module, PyObject *args, PyObject *kwds)
{
    (void)module;
    return module_fit(args, kwds, WENV_FIT_ROUGHNESS);
}

static PyMethodDef glossmeter_functions[] = {
    {"gloss", (PyCFunction)(void (*)(void))module_gloss, METH_VARARGS | METH_KEYWORDS,
     "gloss(material, geometry=60, *, tol=0.05, smooth=False, return_error=False, max_evals=4000000)\n--\n\n"
     "Specular gloss (GU) of `material` as an ISO 2813 / ASTM D523 glossmeter reads it at geometry 20, 60\n"
     "or 85 degrees; a sequence of geometries gives a tuple.  Coloured materials are read on luminance\n"
     "Y = 0.2126 R + 0.7152 G + 0.0722 B.  See wenv.Glossmeter.measure for the options."},
    {"haze", (PyCFunction)(void (*)(void))module_haze, METH_VARARGS | METH_KEYWORDS,
     "haze(material, *, offsets=(-1.9, 1.9), aperture=(0.4, 3.6), tol=0.05, smooth=False, return_error=False, "
     "max_evals=4000000)\n--\n\n"
     "Reflection haze after ASTM E430 method B with the 20 degree glossmeter: flux into two receptors at\n"
     "18.1 and 21.9 degrees (offsets from the 20 degree mirror direction), summed, as 100 x / the\n"
     "standard's 20 degree flux (haze units).  aperture: each haze receptor's size (in plane,\n"
     "perpendicular), degrees."},
    {"fit_alpha", (PyCFunction)(void (*)(void))module_fit_alpha, METH_VARARGS | METH_KEYWORDS,
     "fit_alpha(target_gu, geometry=60, /, **material_params)\n--\n\n"
     "Keyword options: bracket=(1e-4, 2.0), tol=0.05, max_evals=4000000 (geometry may also be a keyword).\n"
     "The lobe's alpha (Beckmann's RMS slope m or GGX's alpha) of wenv.CookTorrance(diffuse=...,\n"
     "lobes=[dict(alpha=..., specular=..., ior=...)], distribution=..., shadowing=...) that reads target_gu\n"
     "at the geometry (material_params: diffuse, specular, ior, distribution, shadowing; defaults as in\n"
     "CookTorrance); or material=wenv.CookTorrance(...), every lobe set to the same alpha.  The reading falls\n"
     "monotonically with alpha; the root is bracketed in ln alpha over `bracket` and refined until the\n"
     "reading is within tol/2.  ValueError naming target_gu when it lies outside the readings at the\n"
     "bracket's ends (the message gives them and the smooth-surface limit)."},
    {"fit_roughness", (PyCFunction)(void (*)(void))module_fit_roughness, METH_VARARGS | METH_KEYWORDS,
     "fit_roughness(target_gu, geometry=60, /, *, material, bracket=(1e-3, 1.0), tol=0.05, max_evals=4000000)\n"
     "--\n\n"
     "Blender's roughness r (the Principled BSDF's Roughness, alpha = r**2) of material=wenv.Principled(...)\n"
     "that reads target_gu at the geometry, every other input kept; searched as fit_alpha searches.  A\n"
     "Cook-Torrance lobe's parameter is alpha: fit_alpha."},
    {NULL, NULL, 0, NULL},
};

int wenv_register_glossmeter(PyObject *module)
{
    if (PyType_Ready(&GlossmeterType) < 0)
        return -1;
    Py_INCREF(&GlossmeterType);
    if (PyModule_AddObject(module, "Glossmeter", (PyObject *)&GlossmeterType) < 0) {
        Py_DECREF(&GlossmeterType);
        return -1;
    }
    return PyModule_AddFunctions(module, glossmeter_functions);
}
