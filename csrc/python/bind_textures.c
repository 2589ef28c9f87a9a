/* wenv.noise_texture: Blender's Noise Texture node at points (scene/noise_texture.h). */
#include <string.h>

#include "python/module.h"
#include "scene/noise_texture.h"

static const char *const TYPE_NAMES[] = {"MULTIFRACTAL", "FBM", "HYBRID_MULTIFRACTAL", "RIDGED_MULTIFRACTAL",
                                         "HETERO_TERRAIN"};

/* noise_texture(vectors, w=0, *, dimensions=3, type='FBM', normalize=True, scale=5, detail=2,
 * roughness=0.5, lacunarity=2, offset=0, gain=1, distortion=0, color=True, progress=None)
 * -> (fac (n,), color (n, 3) or None) */
static PyObject *noise_texture(PyObject *self, PyObject *args, PyObject *kwargs)
{
    (void)self;
    static char *kwlist[] = {"vectors", "w", "dimensions", "type", "normalize", "scale", "detail", "roughness",
                             "lacunarity", "offset", "gain", "distortion", "color", "progress", NULL};
    PyObject *v_obj, *w_obj = NULL, *progress_obj = Py_None;
    int want_colour = 1;
    const char *type = "FBM";
    int dimensions = 3, normalize = 1;
    double scale = 5.0, detail = 2.0, roughness = 0.5, lacunarity = 2.0, offset = 0.0, gain = 1.0, distortion = 0.0;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "O|O$isidddddddpO:noise_texture", kwlist, &v_obj, &w_obj,
                                     &dimensions, &type, &normalize, &scale, &detail, &roughness, &lacunarity,
                                     &offset, &gain, &distortion, &want_colour, &progress_obj))
        return NULL;
    if (progress_obj != Py_None && !PyCallable_Check(progress_obj)) {
        PyErr_SetString(PyExc_TypeError, "progress must be callable or None");
        return NULL;
    }
    wenv_noise_settings s = {.dimensions = dimensions, .normalize = normalize, .scale = (float)scale,
                             .detail = (float)detail, .roughness = (float)roughness, .lacunarity = (float)lacunarity,
                             .offset = (float)offset, .gain = (float)gain, .distortion = (float)distortion};
    int found = -1;
    for (int k = 0; k < 5; k++)
        if (strcmp(type, TYPE_NAMES[k]) == 0)
            found = k;
    if (found < 0)
        return PyErr_Format(PyExc_ValueError, "type must be 'FBM', 'MULTIFRACTAL', 'HYBRID_MULTIFRACTAL', "
                            "'RIDGED_MULTIFRACTAL' or 'HETERO_TERRAIN', got '%s'", type);
    s.type = (wenv_noise_type)found;
    Py_buffer vb, wb = {0};
    PyObject *v_held, *w_held = NULL, *fac = NULL, *colour = NULL;
    if (wenv_py_get_typed_array(v_obj, "vectors", "float32", 0, &vb, &v_held) < 0)
        return NULL;
    double w0 = 0.0;
    int w_array = w_obj && w_obj != Py_None && !PyFloat_Check(w_obj) && !PyLong_Check(w_obj);
    if (vb.ndim != 2 || vb.shape[1] != 3) {
        PyErr_SetString(PyExc_ValueError, "vectors must have shape (n, 3)");
        goto done;
    }
    if (w_array) {
        if (wenv_py_get_typed_array(w_obj, "w", "float32", 0, &wb, &w_held) < 0)
            goto done;
        if (wb.ndim != 1 || wb.shape[0] != vb.shape[0]) {
            PyErr_SetString(PyExc_ValueError, "w must be a number or have shape (n,), one per vector");
            goto done;
        }
    } else if (w_obj && w_obj != Py_None && wenv_py_get_finite(w_obj, "w", &w0) < 0) {
        goto done;
    }
    Py_ssize_t n = vb.shape[0], shape[2] = {vb.shape[0], 3};
    float *fac_out, *colour_out = NULL;
    if (!(fac = wenv_py_new_float_array(1, &n, &fac_out)))
        goto done;
    if (want_colour && !(colour = wenv_py_new_float_array(2, shape, &colour_out)))
        goto done;
    wenv_py_progress_bridge bridge = {.callback = progress_obj};
    wenv_progress progress = wenv_py_progress(&bridge);
    wenv_error err = {0};
    wenv_status st;
    WENV_BEGIN_WORK
    st = wenv_noise_texture(&s, vb.buf, w_array ? wb.buf : NULL, (float)w0, (size_t)n, fac_out, colour_out,
                            &progress, &err);
    WENV_END_WORK
    if (st) {
        if (!(bridge.raised && PyErr_Occurred()))
            wenv_py_raise(&err);
        goto done;
    }
    if (!colour)
        colour = Py_NewRef(Py_None);
    wenv_py_release_array(&vb, &v_held);
    if (w_held)
        wenv_py_release_array(&wb, &w_held);
    return Py_BuildValue("(NN)", fac, colour);
done:
    Py_XDECREF(fac);
    Py_XDECREF(colour);
    wenv_py_release_array(&vb, &v_held);
    if (w_held)
        wenv_py_release_array(&wb, &w_held);
    return NULL;
}

static PyMethodDef texture_functions[] = {
    {"noise_texture", (PyCFunction)(void (*)(void))noise_texture, METH_VARARGS | METH_KEYWORDS,
     "noise_texture(vectors, w=0, *, dimensions=3, type='FBM', normalize=True, scale=5, detail=2, roughness=0.5, "
     "lacunarity=2, offset=0, gain=1, distortion=0, color=True, progress=None)\n--\n\n"
     "Blender's Noise Texture node at points, as Cycles evaluates it: `vectors` (n, 3) float32 is its Vector "
     "input, `w` its W (a number, or (n,) float32; read in 1D and 4D), the rest its settings and unlinked "
     "inputs under Blender's names (type: node.noise_type).  Returns (fac (n,), color (n, 3)) float32, the "
     "node's Fac and Color outputs (color None with color=False, a third of the work).  Detail is clamped to "
     "[0, 15] and roughness to >= 0, as Cycles clamps them.  progress(fraction) is called as blocks of points "
     "finish; returning True cancels (wenv.CancelledError).",
    },
    {NULL, NULL, 0, NULL},
};

int wenv_register_textures(PyObject *module) { return PyModule_AddFunctions(module, texture_functions); }
