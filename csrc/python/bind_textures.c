/* wenv.noise_texture, wenv.wave_texture, wenv.voronoi_texture, wenv.white_noise_texture and
 * wenv.gabor_texture: Blender's procedural texture nodes at points (scene/noise_texture.h,
 * scene/wave_texture.h, scene/voronoi_texture.h, scene/white_noise_texture.h, scene/gabor_texture.h). */
#include <string.h>

#include "python/module.h"
#include "scene/gabor_texture.h"
#include "scene/noise_texture.h"
#include "scene/voronoi_texture.h"
#include "scene/wave_texture.h"
#include "scene/white_noise_texture.h"

static const char *const TYPE_NAMES[] = {"MULTIFRACTAL", "FBM", "HYBRID_MULTIFRACTAL", "RIDGED_MULTIFRACTAL",
                                         "HETERO_TERRAIN"};

/* The index of `name` among `names` (count of them); -1 + ValueError naming `what` otherwise. */
static int choice(const char *name, const char *what, const char *const *names, int count)
{
    for (int k = 0; k < count; k++)
        if (strcmp(name, names[k]) == 0)
            return k;
    PyErr_Format(PyExc_ValueError, "%s must be one of %s ... %s, got '%s'", what, names[0], names[count - 1], name);
    return -1;
}

/* The (n, 3) float32 vectors of a texture call; -1 with the error set. */
static int get_vectors(PyObject *obj, Py_buffer *view, PyObject **held)
{
    if (wenv_py_get_typed_array(obj, "vectors", "float32", 0, view, held) < 0)
        return -1;
    if (view->ndim != 2 || view->shape[1] != 3) {
        wenv_py_release_array(view, held);
        PyErr_SetString(PyExc_ValueError, "vectors must have shape (n, 3)");
        return -1;
    }
    return 0;
}

/* The W input of a texture call: *array set (and the view held) for an (n,) array, else *w0 from a
 * number; -1 with the error set. */
static int get_w(PyObject *w_obj, Py_ssize_t n, Py_buffer *view, PyObject **held, int *array, double *w0)
{
    *array = w_obj && w_obj != Py_None && !PyFloat_Check(w_obj) && !PyLong_Check(w_obj);
    *w0 = 0.0;
    if (!*array)
        return w_obj && w_obj != Py_None ? wenv_py_get_finite(w_obj, "w", w0) : 0;
    if (wenv_py_get_typed_array(w_obj, "w", "float32", 0, view, held) < 0)
        return -1;
    if (view->ndim != 1 || view->shape[0] != n) {
        wenv_py_release_array(view, held);
        PyErr_SetString(PyExc_ValueError, "w must be a number or have shape (n,), one per vector");
        return -1;
    }
    return 0;
}

/* A texture of a value and a colour per point (and a position: the Voronoi's cell), as the core
 * computes it. */
typedef wenv_status (*texture_call)(const void *settings, const float *vectors, const float *w, float w0, size_t n,
                                    float *value, float *colour, float *position, const wenv_progress *progress,
                                    wenv_error *err);

static wenv_status noise_adapter(const void *settings, const float *vectors, const float *w, float w0, size_t n,
                                 float *value, float *colour, float *position, const wenv_progress *progress,
                                 wenv_error *err)
{
    (void)position;
    return wenv_noise_texture(settings, vectors, w, w0, n, value, colour, progress, err);
}

static wenv_status voronoi_adapter(const void *settings, const float *vectors, const float *w, float w0, size_t n,
                                   float *value, float *colour, float *position, const wenv_progress *progress,
                                   wenv_error *err)
{
    return wenv_voronoi_texture(settings, vectors, w, w0, n, value, colour, position, progress, err);
}

static wenv_status white_noise_adapter(const void *settings, const float *vectors, const float *w, float w0, size_t n,
                                       float *value, float *colour, float *position, const wenv_progress *progress,
                                       wenv_error *err)
{
    (void)position;
    return wenv_white_noise_texture(*(const int *)settings, vectors, w, w0, n, value, colour, progress, err);
}

/* A texture call of a value and a colour per point, as wenv_py_run_released runs it. */
typedef struct {
    texture_call call;
    const void *settings;
    const float *vectors, *w;
    float w0;
    size_t n;
    float *value, *colour, *position;
} texture_work;

static wenv_status run_texture_work(void *ctx, const wenv_progress *p, wenv_error *err)
{
    texture_work *t = ctx;
    return t->call(t->settings, t->vectors, t->w, t->w0, t->n, t->value, t->colour, t->position, p, err);
}

/* (value (n,), colour (n, 3) or None) of `call` at the vectors and W given, the GIL released; with
 * want_position 0 or 1 a third, (n, 4) or None: the Voronoi's cell. */
static PyObject *run_texture(texture_call call, const void *settings, PyObject *v_obj, PyObject *w_obj,
                             int want_colour, int want_position, PyObject *progress_obj)
{
    if (wenv_py_check_progress(progress_obj) < 0)
        return NULL;
    Py_buffer vb, wb;
    PyObject *v_held, *w_held = NULL, *value = NULL, *colour = NULL, *position = NULL;
    int w_array;
    double w0;
    if (get_vectors(v_obj, &vb, &v_held) < 0)
        return NULL;
    Py_ssize_t n = vb.shape[0], shape[2] = {vb.shape[0], 3}, shape4[2] = {vb.shape[0], 4};
    float *value_out, *colour_out = NULL, *position_out = NULL;
    if (get_w(w_obj, n, &wb, &w_held, &w_array, &w0) < 0 || !(value = wenv_py_new_float_array(1, &n, &value_out)) ||
        (want_colour && !(colour = wenv_py_new_float_array(2, shape, &colour_out))) ||
        (want_position > 0 && !(position = wenv_py_new_float_array(2, shape4, &position_out))))
        goto fail;
    texture_work work = {call, settings, vb.buf, w_array ? wb.buf : NULL, (float)w0, (size_t)n, value_out,
                         colour_out, position_out};
    if (wenv_py_run_released(run_texture_work, &work, progress_obj) < 0)
        goto fail;
    wenv_py_release_array(&vb, &v_held);
    if (w_held)
        wenv_py_release_array(&wb, &w_held);
    if (want_position >= 0)
        return Py_BuildValue("(NNN)", value, colour ? colour : Py_NewRef(Py_None),
                             position ? position : Py_NewRef(Py_None));
    return Py_BuildValue("(NN)", value, colour ? colour : Py_NewRef(Py_None));
fail:
    Py_XDECREF(value);
    Py_XDECREF(colour);
    Py_XDECREF(position);
    wenv_py_release_array(&vb, &v_held);
    if (w_held)
        wenv_py_release_array(&wb, &w_held);
    return NULL;
}

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
    wenv_noise_settings s = {.dimensions = dimensions, .normalize = normalize, .scale = (float)scale,
                             .detail = (float)detail, .roughness = (float)roughness, .lacunarity = (float)lacunarity,
                             .offset = (float)offset, .gain = (float)gain, .distortion = (float)distortion};
    int found = choice(type, "type", TYPE_NAMES, 5);
    if (found < 0)
        return NULL;
    s.type = (wenv_noise_type)found;
    return run_texture(noise_adapter, &s, v_obj, w_obj, want_colour, -1, progress_obj);
}

typedef struct {
    const wenv_wave_settings *s;
    const float *vectors;
    size_t n;
    float *fac;
} wave_work;

static wenv_status run_wave_work(void *ctx, const wenv_progress *p, wenv_error *err)
{
    wave_work *w = ctx;
    return wenv_wave_texture(w->s, w->vectors, w->n, w->fac, p, err);
}

/* wave_texture(vectors, *, wave_type='BANDS', direction='X', profile='SIN', scale=5, distortion=0,
 * detail=2, detail_scale=1, detail_roughness=0.5, phase=0, progress=None) -> fac (n,) */
static PyObject *wave_texture(PyObject *self, PyObject *args, PyObject *kwargs)
{
    (void)self;
    static char *kwlist[] = {"vectors", "wave_type", "direction", "profile", "scale", "distortion", "detail",
                             "detail_scale", "detail_roughness", "phase", "progress", NULL};
    static const char *const TYPES[] = {"BANDS", "RINGS"};
    static const char *const BANDS[] = {"X", "Y", "Z", "DIAGONAL"}, *const RINGS[] = {"X", "Y", "Z", "SPHERICAL"};
    static const char *const PROFILES[] = {"SIN", "SAW", "TRI"};
    PyObject *v_obj, *progress_obj = Py_None;
    const char *type = "BANDS", *direction = "X", *profile = "SIN";
    double scale = 5.0, distortion = 0.0, detail = 2.0, detail_scale = 1.0, detail_roughness = 0.5, phase = 0.0;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "O|$sssddddddO:wave_texture", kwlist, &v_obj, &type, &direction,
                                     &profile, &scale, &distortion, &detail, &detail_scale, &detail_roughness, &phase,
                                     &progress_obj))
        return NULL;
    if (wenv_py_check_progress(progress_obj) < 0)
        return NULL;
    int t = choice(type, "wave_type", TYPES, 2), d = t < 0 ? -1 : choice(direction, "direction", t ? RINGS : BANDS, 4);
    int p = d < 0 ? -1 : choice(profile, "profile", PROFILES, 3);
    if (p < 0)
        return NULL;
    wenv_wave_settings s = {.type = (wenv_wave_type)t, .direction = (wenv_wave_direction)d,
                            .profile = (wenv_wave_profile)p, .scale = (float)scale, .distortion = (float)distortion,
                            .detail = (float)detail, .detail_scale = (float)detail_scale,
                            .detail_roughness = (float)detail_roughness, .phase = (float)phase};
    Py_buffer vb;
    PyObject *v_held, *fac;
    if (get_vectors(v_obj, &vb, &v_held) < 0)
        return NULL;
    Py_ssize_t n = vb.shape[0];
    float *out;
    if (!(fac = wenv_py_new_float_array(1, &n, &out))) {
        wenv_py_release_array(&vb, &v_held);
        return NULL;
    }
    wave_work work = {&s, vb.buf, (size_t)n, out};
    int failed = wenv_py_run_released(run_wave_work, &work, progress_obj) < 0;
    wenv_py_release_array(&vb, &v_held);
    if (failed) {
        Py_DECREF(fac);
        return NULL;
    }
    return fac;
}

/* voronoi_texture(vectors, w=0, *, dimensions=3, feature='F1', distance='EUCLIDEAN', normalize=False,
 * scale=5, detail=0, roughness=0.5, lacunarity=2, smoothness=1, exponent=0.5, randomness=1, color=True,
 * position=False, progress=None) -> (distance (n,), color (n, 3) or None, position (n, 4) or None) */
static PyObject *voronoi_texture(PyObject *self, PyObject *args, PyObject *kwargs)
{
    (void)self;
    static char *kwlist[] = {"vectors", "w", "dimensions", "feature", "distance", "normalize", "scale", "detail",
                             "roughness", "lacunarity", "smoothness", "exponent", "randomness", "color", "position",
                             "cell_hash", "progress", NULL};
    static const char *const CELL_HASHES[] = {"PCG", "LOOKUP3"};
    static const char *const FEATURES[] = {"F1", "F2", "SMOOTH_F1", "DISTANCE_TO_EDGE", "N_SPHERE_RADIUS"};
    static const char *const METRICS[] = {"EUCLIDEAN", "MANHATTAN", "CHEBYCHEV", "MINKOWSKI"};
    PyObject *v_obj, *w_obj = NULL, *progress_obj = Py_None;
    const char *feature = "F1", *metric = "EUCLIDEAN", *cell_hash = "PCG";
    int dimensions = 3, normalize = 0, want_colour = 1, want_position = 0;
    double scale = 5.0, detail = 0.0, roughness = 0.5, lacunarity = 2.0, smoothness = 1.0, exponent = 0.5;
    double randomness = 1.0;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "O|O$isspdddddddppsO:voronoi_texture", kwlist, &v_obj, &w_obj,
                                     &dimensions, &feature, &metric, &normalize, &scale, &detail, &roughness,
                                     &lacunarity, &smoothness, &exponent, &randomness, &want_colour, &want_position,
                                     &cell_hash, &progress_obj))
        return NULL;
    int f = choice(feature, "feature", FEATURES, 5), m = f < 0 ? -1 : choice(metric, "distance", METRICS, 4);
    int h = m < 0 ? -1 : choice(cell_hash, "cell_hash", CELL_HASHES, 2);
    if (h < 0)
        return NULL;
    wenv_voronoi_settings s = {.dimensions = dimensions, .feature = (wenv_voronoi_feature)f,
                               .metric = (wenv_voronoi_metric)m, .normalize = normalize, .scale = (float)scale,
                               .detail = (float)detail, .roughness = (float)roughness,
                               .lacunarity = (float)lacunarity, .smoothness = (float)smoothness,
                               .exponent = (float)exponent, .randomness = (float)randomness, .lookup3_cells = h};
    return run_texture(voronoi_adapter, &s, v_obj, w_obj, want_colour, want_position, progress_obj);
}

/* white_noise_texture(vectors, w=0, *, dimensions=3, color=True, progress=None)
 * -> (value (n,), color (n, 3) or None) */
static PyObject *white_noise_texture(PyObject *self, PyObject *args, PyObject *kwargs)
{
    (void)self;
    static char *kwlist[] = {"vectors", "w", "dimensions", "color", "progress", NULL};
    PyObject *v_obj, *w_obj = NULL, *progress_obj = Py_None;
    int dimensions = 3, want_colour = 1;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "O|O$ipO:white_noise_texture", kwlist, &v_obj, &w_obj,
                                     &dimensions, &want_colour, &progress_obj))
        return NULL;
    return run_texture(white_noise_adapter, &dimensions, v_obj, w_obj, want_colour, -1, progress_obj);
}

typedef struct {
    const wenv_gabor_settings *s;
    const float *vectors;
    size_t n;
    float *out[3];
} gabor_work;

static wenv_status run_gabor_work(void *ctx, const wenv_progress *p, wenv_error *err)
{
    gabor_work *g = ctx;
    return wenv_gabor_texture(g->s, g->vectors, g->n, g->out[0], g->out[1], g->out[2], p, err);
}

/* gabor_texture(vectors, *, dimensions=2, scale=5, frequency=2, anisotropy=1, orientation_2d=pi/4,
 * orientation_3d=(1.4142, 1.4142, 0), progress=None) -> (value, phase, intensity), each (n,) */
static PyObject *gabor_texture(PyObject *self, PyObject *args, PyObject *kwargs)
{
    (void)self;
    static char *kwlist[] = {"vectors", "dimensions", "scale", "frequency", "anisotropy", "orientation_2d",
                             "orientation_3d", "progress", NULL};
    PyObject *v_obj, *progress_obj = Py_None;
    int dimensions = 2;
    double scale = 5.0, frequency = 2.0, anisotropy = 1.0, orientation_2d = 0.78539816339744831;
    double o3[3] = {1.41421356237309505, 1.41421356237309505, 0.0};
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "O|$idddd(ddd)O:gabor_texture", kwlist, &v_obj, &dimensions, &scale,
                                     &frequency, &anisotropy, &orientation_2d, &o3[0], &o3[1], &o3[2], &progress_obj))
        return NULL;
    if (wenv_py_check_progress(progress_obj) < 0)
        return NULL;
    wenv_gabor_settings s = {.dimensions = dimensions, .scale = (float)scale, .frequency = (float)frequency,
                             .anisotropy = (float)anisotropy, .orientation_2d = (float)orientation_2d,
                             .orientation_3d = {(float)o3[0], (float)o3[1], (float)o3[2]}};
    Py_buffer vb;
    PyObject *v_held, *out[3] = {NULL, NULL, NULL};
    if (get_vectors(v_obj, &vb, &v_held) < 0)
        return NULL;
    Py_ssize_t n = vb.shape[0];
    float *arrays[3];
    for (int k = 0; k < 3; k++)
        if (!(out[k] = wenv_py_new_float_array(1, &n, &arrays[k])))
            goto fail;
    gabor_work work = {&s, vb.buf, (size_t)n, {arrays[0], arrays[1], arrays[2]}};
    if (wenv_py_run_released(run_gabor_work, &work, progress_obj) < 0)
        goto fail;
    wenv_py_release_array(&vb, &v_held);
    return Py_BuildValue("(NNN)", out[0], out[1], out[2]);
fail:
    for (int k = 0; k < 3; k++)
        Py_XDECREF(out[k]);
    wenv_py_release_array(&vb, &v_held);
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
    {"wave_texture", (PyCFunction)(void (*)(void))wave_texture, METH_VARARGS | METH_KEYWORDS,
     "wave_texture(vectors, *, wave_type='BANDS', direction='X', profile='SIN', scale=5, distortion=0, detail=2, "
     "detail_scale=1, detail_roughness=0.5, phase=0, progress=None)\n--\n\n"
     "Blender's Wave Texture node at points, as Cycles evaluates it: `vectors` (n, 3) float32 is its Vector "
     "input; wave_type, direction (bands: 'X', 'Y', 'Z', 'DIAGONAL'; rings: 'X', 'Y', 'Z', 'SPHERICAL') and "
     "profile ('SIN', 'SAW', 'TRI') its settings, the rest its inputs (phase: Phase Offset).  Returns its Fac "
     "(n,) float32; its Color is Fac in each channel.  progress(fraction) may cancel (wenv.CancelledError).",
    },
    {"voronoi_texture", (PyCFunction)(void (*)(void))voronoi_texture, METH_VARARGS | METH_KEYWORDS,
     "voronoi_texture(vectors, w=0, *, dimensions=3, feature='F1', distance='EUCLIDEAN', normalize=False, scale=5, "
     "detail=0, roughness=0.5, lacunarity=2, smoothness=1, exponent=0.5, randomness=1, color=True, position=False, "
     "cell_hash='PCG', progress=None)\n--\n\n"
     "Blender's Voronoi Texture node at points, as Cycles evaluates it: `vectors` (n, 3) float32 is its Vector "
     "input, `w` its W (a number or (n,) float32; read in 1D and 4D), feature and distance (the metric) its "
     "settings, the rest its inputs.  Returns (distance (n,), color (n, 3) or None with color=False, position "
     "(n, 4) or None without position=True) float32: the node's Distance (its Radius for 'N_SPHERE_RADIUS'), "
     "Color, and its Position and W as (x, y, z, W) (0 where the dimensions have none, and for the distance to "
     "edge and the radius).  cell_hash: how 2D to 4D cells are hashed, 'PCG' as Blender from 5.0, 'LOOKUP3' as "
     "before.  progress(fraction) may cancel (wenv.CancelledError).",
    },
    {"white_noise_texture", (PyCFunction)(void (*)(void))white_noise_texture, METH_VARARGS | METH_KEYWORDS,
     "white_noise_texture(vectors, w=0, *, dimensions=3, color=True, progress=None)\n--\n\n"
     "Blender's White Noise Texture node at points, as Cycles evaluates it: `vectors` (n, 3) float32 is its "
     "Vector input, `w` its W (a number or (n,) float32; read in 1D and 4D).  Returns (value (n,), color (n, 3) "
     "or None with color=False) float32, the bits of each point's coordinates hashed into [0, 1].  "
     "progress(fraction) may cancel (wenv.CancelledError).",
    },
    {"gabor_texture", (PyCFunction)(void (*)(void))gabor_texture, METH_VARARGS | METH_KEYWORDS,
     "gabor_texture(vectors, *, dimensions=2, scale=5, frequency=2, anisotropy=1, orientation_2d=pi/4, "
     "orientation_3d=(1.4142, 1.4142, 0), progress=None)\n--\n\n"
     "Blender's Gabor Texture node at points, as Cycles evaluates it: `vectors` (n, 3) float32 is its Vector "
     "input, dimensions its type (2 or 3), the rest its inputs (orientation_2d in radians, orientation_3d a "
     "direction).  Returns (value, phase, intensity), each (n,) float32: the node's three outputs.  "
     "progress(fraction) may cancel (wenv.CancelledError).",
    },
    {NULL, NULL, 0, NULL},
};

int wenv_register_textures(PyObject *module) { return PyModule_AddFunctions(module, texture_functions); }
