/* Python glue for shading: wenv.Shader, wenv.reference, the quality presets, and private hooks
 * that let the tests reach the maps and the Haar transform. */
#include "bindings.h"

#include <errno.h>
#include <string.h>
#include <sys/stat.h>

#include "autoquality.h"
#include "haar.h"
#include "maps.h"
#include "reference.h"
#include "shade.h"

typedef struct {
    const char *name;
    wenv_quality q;
} preset;

static const preset PRESETS[] = {
    {"draft", {32, 16, 16, 8, 32, 256, 1e-3, 64, 256, 0}},
    {"default", {64, 32, 32, 16, 128, 1024, 1e-3, 128, 256, 0}},
    /* high: every pixel above 8x the mean radiance (up to 4096) exact, and narrow lobes at grazing
     * per vertex -- what brings m >= 0.1 within 1 % on the bundled HDRIs (README, accuracy) */
    {"high", {128, 64, 64, 32, 512, 0, 1e-4, 4096, 8, 6}},
};
#define N_PRESETS (sizeof PRESETS / sizeof PRESETS[0])

static PyObject *quality_to_dict(const wenv_quality *q)
{
    return Py_BuildValue("{s:n,s:n,s:n,s:n,s:n,s:n,s:d,s:n,s:d,s:d}", "global", (Py_ssize_t)q->global_n, "local",
                         (Py_ssize_t)q->local_n, "normals", (Py_ssize_t)q->normal_n, "views", (Py_ssize_t)q->view_n,
                         "coefficients", (Py_ssize_t)q->coefficients, "light_coefficients",
                         (Py_ssize_t)q->light_coefficients, "matrix_epsilon", q->matrix_epsilon, "lights",
                         (Py_ssize_t)q->lights, "light_threshold", q->light_threshold, "grazing", q->grazing);
}

static int get_size(PyObject *v, const char *key, size_t *out)
{
    char name[64];
    snprintf(name, sizeof name, "quality['%s']", key);
    return wenv_py_get_size(v, name, out);
}

static int parse_quality(PyObject *obj, wenv_quality *q)
{
    *q = PRESETS[1].q;
    if (PyUnicode_Check(obj)) {
        const char *name = PyUnicode_AsUTF8(obj);
        if (!name)
            return -1;
        for (size_t i = 0; i < N_PRESETS; i++)
            if (strcmp(name, PRESETS[i].name) == 0) {
                *q = PRESETS[i].q;
                return 0;
            }
        PyErr_Format(PyExc_ValueError, "quality must be 'draft', 'default', 'high', 'auto' or a dict, got '%s'", name);
        return -1;
    }
    if (!PyDict_Check(obj)) {
        PyErr_Format(PyExc_TypeError, "quality must be a preset name or a dict, got %.100s", Py_TYPE(obj)->tp_name);
        return -1;
    }
    PyObject *key, *value;
    Py_ssize_t pos = 0;
    while (PyDict_Next(obj, &pos, &key, &value)) {
        const char *k = PyUnicode_Check(key) ? PyUnicode_AsUTF8(key) : NULL;
        if (!k) {
            PyErr_Clear();
            PyErr_SetString(PyExc_TypeError, "quality keys must be strings");
            return -1;
        }
        int r;
        if (strcmp(k, "global") == 0)
            r = get_size(value, k, &q->global_n);
        else if (strcmp(k, "local") == 0)
            r = get_size(value, k, &q->local_n);
        else if (strcmp(k, "normals") == 0)
            r = get_size(value, k, &q->normal_n);
        else if (strcmp(k, "views") == 0)
            r = get_size(value, k, &q->view_n);
        else if (strcmp(k, "coefficients") == 0)
            r = get_size(value, k, &q->coefficients);
        else if (strcmp(k, "light_coefficients") == 0)
            r = get_size(value, k, &q->light_coefficients);
        else if (strcmp(k, "matrix_epsilon") == 0)
            r = wenv_py_get_finite(value, "quality['matrix_epsilon']", &q->matrix_epsilon);
        else if (strcmp(k, "lights") == 0)
            r = get_size(value, k, &q->lights);
        else if (strcmp(k, "light_threshold") == 0)
            r = wenv_py_get_finite(value, "quality['light_threshold']", &q->light_threshold);
        else if (strcmp(k, "grazing") == 0)
            r = wenv_py_get_finite(value, "quality['grazing']", &q->grazing);
        else {
            PyErr_Format(PyExc_ValueError,
                         "unknown quality key '%s' (use global, local, normals, views, coefficients, "
                         "light_coefficients, matrix_epsilon, lights, light_threshold, grazing)", k);
            return -1;
        }
        if (r < 0)
            return -1;
    }
    wenv_error err = {0};
    if (wenv_quality_check(q, &err)) {
        wenv_py_raise(&err);
        return -1;
    }
    return 0;
}

/* The rotation-matrix cache folder: WENV_CACHE_DIR, else $XDG_CACHE_HOME/wenv, else ~/.cache/wenv. */
static int default_cache_dir(char *buf, size_t size)
{
    const char *env = getenv("WENV_CACHE_DIR");
    if (env && env[0])
        snprintf(buf, size, "%s", env);
    else if ((env = getenv("XDG_CACHE_HOME")) && env[0])
        snprintf(buf, size, "%s/wenv", env);
    else if ((env = getenv("HOME")) && env[0])
        snprintf(buf, size, "%s/.cache/wenv", env);
    else
        return -1;
    /* create the folder and its parents */
    for (char *p = buf + 1; *p; p++) {
        if (*p == '/') {
            *p = '\0';
            mkdir(buf, 0755);
            *p = '/';
        }
    }
    if (mkdir(buf, 0755) != 0 && errno != EEXIST)
        return -1;
    return 0;
}

typedef struct {
    PyObject_HEAD
    wenv_shader *shader;
    wenv_quality quality;
    wenv_method method;
    PyObject *environment, *material;
    int busy;
    wenv_py_peer *peer; /* set for the peer methods ("split_sum", "sh"), which bind_peers.c runs */
    int is_auto;
    wenv_auto_choice auto_choice;
    double target_error, memory_budget_mb;
} ShaderObject;

static int claim(ShaderObject *self)
{
    if (!self->shader && !self->peer) {
        PyErr_SetString(PyExc_RuntimeError, "Shader is not initialised");
        return -1;
    }
    if (self->busy) {
        PyErr_SetString(PyExc_RuntimeError, "Shader is busy in another thread");
        return -1;
    }
    self->busy = 1;
    return 0;
}

static int do_set_environment(ShaderObject *self, PyObject *env_obj)
{
    const struct wenv_envmap *env = wenv_py_envmap(env_obj, "env");
    if (!env)
        return -1;
    if (self->peer) {
        if (wenv_py_peer_set_environment(self->peer, env) < 0)
            return -1;
        Py_INCREF(env_obj);
        Py_XSETREF(self->environment, env_obj);
        return 0;
    }
    wenv_error err = {0};
    wenv_status st;
    Py_BEGIN_ALLOW_THREADS
    st = wenv_shader_set_environment(self->shader, env, &err);
    Py_END_ALLOW_THREADS
    if (st) {
        wenv_py_raise(&err);
        return -1;
    }
    Py_INCREF(env_obj);
    Py_XSETREF(self->environment, env_obj);
    return 0;
}

static int do_set_material(ShaderObject *self, PyObject *mat_obj)
{
    const struct wenv_material *mat = wenv_py_material(mat_obj, "material");
    if (!mat)
        return -1;
    if (self->peer) {
        if (wenv_py_peer_set_material(self->peer, mat) < 0)
            return -1;
        Py_INCREF(mat_obj);
        Py_XSETREF(self->material, mat_obj);
        return 0;
    }
    wenv_error err = {0};
    wenv_status st;
    Py_BEGIN_ALLOW_THREADS
    st = wenv_shader_set_material(self->shader, mat, &err);
    Py_END_ALLOW_THREADS
    if (st) {
        wenv_py_raise(&err);
        return -1;
    }
    Py_INCREF(mat_obj);
    Py_XSETREF(self->material, mat_obj);
    return 0;
}

/* quality="auto": the cheapest ladder level predicted to meet target_error (autoquality.h). */
static int choose_auto(ShaderObject *self, PyObject *env_obj, PyObject *mat_obj, PyObject *normals_obj)
{
    if (!(self->target_error > 0.0 && self->target_error <= 1.0)) {
        PyErr_Format(PyExc_ValueError, "target_error must be in (0, 1], got %g", self->target_error);
        return -1;
    }
    if (!(self->memory_budget_mb > 0.0 && self->memory_budget_mb < 1e9)) {
        PyErr_Format(PyExc_ValueError, "memory_budget_mb must be positive, got %g", self->memory_budget_mb);
        return -1;
    }
    const struct wenv_envmap *env = wenv_py_envmap(env_obj, "env");
    const struct wenv_material *mat = wenv_py_material(mat_obj, "material");
    if (!env || !mat)
        return -1;
    struct wenv_auto_analysis *analysis = wenv_py_envmap_auto_analysis(env_obj);
    if (!analysis)
        return -1;
    Py_buffer nb = {0};
    size_t n = 0;
    const float *normals = NULL;
    if (normals_obj != Py_None) {
        if (wenv_py_get_vec3_array(normals_obj, "normals", 1, &nb, &n, NULL) < 0)
            return -1;
        normals = nb.buf;
    }
    wenv_error err = {0};
    wenv_status st;
    size_t budget = (size_t)(self->memory_budget_mb * 1048576.0);
    Py_BEGIN_ALLOW_THREADS
    st = wenv_auto_choose(env, analysis, mat, self->target_error, budget, normals, n, &self->auto_choice, &err);
    Py_END_ALLOW_THREADS
    if (normals)
        PyBuffer_Release(&nb);
    if (st) {
        wenv_py_raise(&err);
        return -1;
    }
    self->is_auto = 1;
    self->quality = self->auto_choice.quality;
    self->method = WENV_METHOD_SLICING;
    return 0;
}

static int Shader_init(ShaderObject *self, PyObject *args, PyObject *kwargs)
{
    static char *kwlist[] = {"env", "material", "quality", "method", "cache_dir", "progress", "target_error",
                             "memory_budget_mb", "normals", NULL};
    PyObject *env_obj, *mat_obj, *quality_obj = NULL, *cache_obj = Py_None, *progress_obj = Py_None;
    PyObject *normals_obj = Py_None;
    const char *method = NULL;
    self->target_error = 0.01;
    self->memory_budget_mb = 1024.0;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "OO|OzOOddO:Shader", kwlist, &env_obj, &mat_obj, &quality_obj,
                                     &method, &cache_obj, &progress_obj, &self->target_error,
                                     &self->memory_budget_mb, &normals_obj))
        return -1;
    if (self->shader || self->peer) {
        PyErr_SetString(PyExc_RuntimeError, "Shader is already initialised");
        return -1;
    }
    if (!wenv_py_envmap(env_obj, "env") || !wenv_py_material(mat_obj, "material"))
        return -1;
    int is_auto = quality_obj && PyUnicode_Check(quality_obj) && PyUnicode_CompareWithASCIIString(quality_obj, "auto") == 0;
    if (is_auto && method && strcmp(method, "slicing") != 0) {
        PyErr_Format(PyExc_ValueError, "quality='auto' chooses the method itself; leave method unset (got '%s')", method);
        return -1;
    }
    if (normals_obj != Py_None && !is_auto) {
        PyErr_SetString(PyExc_ValueError, "normals are only used by quality='auto' (to count the normal samples a "
                                          "mesh needs)");
        return -1;
    }
    if (!method)
        method = is_auto ? "slicing" : "rotation";
    int peer = wenv_py_is_peer_method(method);
    if (peer)
        ;
    else if (strcmp(method, "rotation") == 0)
        self->method = WENV_METHOD_ROTATION;
    else if (strcmp(method, "slicing") == 0)
        self->method = WENV_METHOD_SLICING;
    else {
        PyErr_Format(PyExc_ValueError, "method must be 'rotation', 'slicing', 'split_sum' or 'sh', got '%s'", method);
        return -1;
    }
    PyObject *auto_sh_quality = NULL; /* quality="auto" chose method "sh" (a material without lobes) */
    if (is_auto) {
        if (choose_auto(self, env_obj, mat_obj, normals_obj) < 0)
            return -1;
        if (self->auto_choice.sh_order) {
            /* views: the lobe-less path has no BRDF slices to sample */
            auto_sh_quality = Py_BuildValue("{s:n,s:n}", "order", (Py_ssize_t)self->auto_choice.sh_order, "views",
                                            (Py_ssize_t)2);
            if (!auto_sh_quality)
                return -1;
            quality_obj = auto_sh_quality;
            method = "sh";
            peer = 1;
        }
    } else if (!peer) {
        PyObject *q = quality_obj ? Py_NewRef(quality_obj) : PyUnicode_FromString("default");
        int r = q ? parse_quality(q, &self->quality) : -1;
        Py_XDECREF(q);
        if (r < 0)
            return -1;
    }
    if (progress_obj != Py_None && !PyCallable_Check(progress_obj)) {
        PyErr_SetString(PyExc_TypeError, "progress must be callable or None");
        Py_XDECREF(auto_sh_quality);
        return -1;
    }
    if (peer) {
        /* no matrices, so no cache: the precomputation is the lighting's and the material's */
        self->peer = wenv_py_peer_create(method, quality_obj, progress_obj);
        Py_XDECREF(auto_sh_quality);
        if (!self->peer)
            return -1;
        return do_set_environment(self, env_obj) < 0 || do_set_material(self, mat_obj) < 0 ? -1 : 0;
    }
    char dir[4096];
    const char *cache_dir = NULL;
    if (cache_obj == Py_None) {
        if (default_cache_dir(dir, sizeof dir) == 0)
            cache_dir = dir;
    } else if (cache_obj == Py_False) {
        cache_dir = NULL;
    } else {
        PyObject *bytes = NULL;
        if (!PyUnicode_FSConverter(cache_obj, &bytes))
            return -1;
        snprintf(dir, sizeof dir, "%s", PyBytes_AS_STRING(bytes));
        Py_DECREF(bytes);
        struct stat sb;
        if (stat(dir, &sb) != 0 || !S_ISDIR(sb.st_mode)) {
            PyErr_Format(PyExc_OSError, "cache_dir '%s' is not a folder", dir);
            return -1;
        }
        cache_dir = dir;
    }
    wenv_py_progress_bridge bridge = {progress_obj, 0};
    wenv_progress progress = wenv_py_progress(&bridge);
    wenv_error err = {0};
    wenv_status st;
    wenv_shader *sh = NULL;
    Py_BEGIN_ALLOW_THREADS
    st = wenv_shader_create(&sh, &self->quality, self->method, cache_dir, &progress, &err);
    Py_END_ALLOW_THREADS
    if (st) {
        if (bridge.raised && PyErr_Occurred())
            return -1;
        wenv_py_raise(&err);
        return -1;
    }
    self->shader = sh;
    if (do_set_environment(self, env_obj) < 0 || do_set_material(self, mat_obj) < 0)
        return -1;
    return 0;
}

static void Shader_dealloc(ShaderObject *self)
{
    wenv_shader_free(self->shader);
    wenv_py_peer_free(self->peer);
    Py_XDECREF(self->environment);
    Py_XDECREF(self->material);
    Py_TYPE(self)->tp_free((PyObject *)self);
}

static PyObject *shade_arrays(ShaderObject *self, const float *normals, const float *views, size_t n)
{
    Py_ssize_t shape[2] = {(Py_ssize_t)n, 3};
    float *out;
    PyObject *result = wenv_py_new_float_array(2, shape, &out);
    if (!result)
        return NULL;
    if (n == 0)
        return result;
    if (self->peer) {
        if (wenv_py_peer_shade(self->peer, normals, views, n, out) < 0)
            Py_CLEAR(result);
        return result;
    }
    wenv_error err = {0};
    wenv_status st;
    Py_BEGIN_ALLOW_THREADS
    st = wenv_shader_shade(self->shader, normals, views, n, out, &err);
    Py_END_ALLOW_THREADS
    if (st) {
        Py_DECREF(result);
        return wenv_py_raise(&err);
    }
    return result;
}

static PyObject *Shader_shade(ShaderObject *self, PyObject *args, PyObject *kwargs)
{
    static char *kwlist[] = {"normals", "view_dirs", NULL};
    PyObject *nobj, *vobj;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "OO:shade", kwlist, &nobj, &vobj))
        return NULL;
    Py_buffer nb, vb;
    size_t n, nvw;
    int single_n, single_v;
    if (wenv_py_get_vec3_array(nobj, "normals", 1, &nb, &n, &single_n) < 0)
        return NULL;
    if (wenv_py_get_vec3_array(vobj, "view_dirs", 1, &vb, &nvw, &single_v) < 0) {
        PyBuffer_Release(&nb);
        return NULL;
    }
    PyObject *result = NULL;
    float *expanded = NULL;
    const float *views = vb.buf;
    if (single_v && !single_n) {
        /* one view direction for all (orthographic camera) */
        expanded = PyMem_Malloc((n ? n : 1) * 3 * sizeof(float));
        if (!expanded) {
            PyErr_NoMemory();
            goto done;
        }
        for (size_t i = 0; i < n; i++)
            memcpy(expanded + 3 * i, vb.buf, 3 * sizeof(float));
        views = expanded;
    } else if (nvw != n) {
        PyErr_Format(PyExc_ValueError, "view_dirs has %zu rows but normals has %zu", nvw, n);
        goto done;
    }
    if (claim(self) < 0)
        goto done;
    result = shade_arrays(self, nb.buf, views, n);
    self->busy = 0;
done:
    PyMem_Free(expanded);
    PyBuffer_Release(&nb);
    PyBuffer_Release(&vb);
    return result;
}

static PyObject *Shader_shade_mesh(ShaderObject *self, PyObject *args, PyObject *kwargs)
{
    static char *kwlist[] = {"positions", "normals", "eye", NULL};
    PyObject *pobj, *nobj, *eobj;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "OOO:shade_mesh", kwlist, &pobj, &nobj, &eobj))
        return NULL;
    double eye[3];
    PyObject *seq = PySequence_Fast(eobj, "eye must be a sequence of 3 numbers");
    if (!seq)
        return NULL;
    if (PySequence_Fast_GET_SIZE(seq) != 3) {
        Py_DECREF(seq);
        PyErr_SetString(PyExc_ValueError, "eye must have 3 components");
        return NULL;
    }
    for (int c = 0; c < 3; c++)
        if (wenv_py_get_finite(PySequence_Fast_GET_ITEM(seq, c), "eye", &eye[c]) < 0) {
            Py_DECREF(seq);
            return NULL;
        }
    Py_DECREF(seq);
    Py_buffer pb, nb;
    size_t np, nn;
    if (wenv_py_get_vec3_array(pobj, "positions", 0, &pb, &np, NULL) < 0)
        return NULL;
    if (wenv_py_get_vec3_array(nobj, "normals", 1, &nb, &nn, NULL) < 0) {
        PyBuffer_Release(&pb);
        return NULL;
    }
    PyObject *result = NULL;
    float *views = NULL;
    if (np != nn) {
        PyErr_Format(PyExc_ValueError, "positions has %zu rows but normals has %zu", np, nn);
        goto done;
    }
    views = PyMem_Malloc((np ? np : 1) * 3 * sizeof(float));
    if (!views) {
        PyErr_NoMemory();
        goto done;
    }
    const float *p = pb.buf;
    for (size_t i = 0; i < np; i++) {
        double d[3] = {eye[0] - p[3 * i], eye[1] - p[3 * i + 1], eye[2] - p[3 * i + 2]};
        if (d[0] * d[0] + d[1] * d[1] + d[2] * d[2] < 1e-24) {
            PyErr_Format(PyExc_ValueError, "eye coincides with positions[%zu]", i);
            goto done;
        }
        for (int c = 0; c < 3; c++)
            views[3 * i + c] = (float)d[c];
    }
    if (claim(self) < 0)
        goto done;
    result = shade_arrays(self, nb.buf, views, np);
    self->busy = 0;
done:
    PyMem_Free(views);
    PyBuffer_Release(&pb);
    PyBuffer_Release(&nb);
    return result;
}

static PyObject *Shader_set_environment(ShaderObject *self, PyObject *env)
{
    if (claim(self) < 0)
        return NULL;
    int r = do_set_environment(self, env);
    self->busy = 0;
    if (r < 0)
        return NULL;
    Py_RETURN_NONE;
}

static PyObject *Shader_set_material(ShaderObject *self, PyObject *mat)
{
    if (claim(self) < 0)
        return NULL;
    int r = do_set_material(self, mat);
    self->busy = 0;
    if (r < 0)
        return NULL;
    Py_RETURN_NONE;
}

static PyObject *Shader_get_quality(ShaderObject *self, void *closure)
{
    (void)closure;
    if (self->peer)
        return wenv_py_peer_quality(self->peer);
    return quality_to_dict(&self->quality);
}

static PyObject *Shader_get_method(ShaderObject *self, void *closure)
{
    (void)closure;
    if (self->peer)
        return PyUnicode_FromString(wenv_py_peer_method(self->peer));
    return PyUnicode_FromString(self->method == WENV_METHOD_ROTATION ? "rotation" : "slicing");
}

static PyObject *Shader_get_environment(ShaderObject *self, void *closure)
{
    (void)closure;
    return Py_NewRef(self->environment ? self->environment : Py_None);
}

static PyObject *Shader_get_material(ShaderObject *self, void *closure)
{
    (void)closure;
    return Py_NewRef(self->material ? self->material : Py_None);
}

static PyObject *Shader_get_stats(ShaderObject *self, void *closure)
{
    (void)closure;
    PyObject *d;
    if (self->peer) {
        d = wenv_py_peer_stats(self->peer);
    } else {
        if (!self->shader)
            Py_RETURN_NONE;
        wenv_shader_stats s;
        wenv_shader_get_stats(self->shader, &s);
        static const char *cache_names[] = {"none", "loaded", "built", "built (save failed)"};
        d = Py_BuildValue("{s:n,s:n,s:s,s:d,s:n,s:n,s:n,s:n,s:n,s:n,s:n,s:n,s:n}", "rotation_nnz", (Py_ssize_t)s.rotation_nnz,
                         "rotation_bytes", (Py_ssize_t)s.rotation_bytes, "cache", cache_names[s.cache],
                         "rotation_seconds", s.rotation_seconds, "slices_ready", (Py_ssize_t)s.slices_ready,
                         "pairs_ready", (Py_ssize_t)s.pairs_ready, "light_terms", (Py_ssize_t)s.light_terms,
                         "brdf_terms", (Py_ssize_t)s.brdf_terms_total, "slice_bytes", (Py_ssize_t)s.slice_bytes,
                         "table_bytes", (Py_ssize_t)s.table_bytes, "brdf_bytes", (Py_ssize_t)s.brdf_bytes,
                         "direct_lights", (Py_ssize_t)s.direct_lights, "grazing_bytes", (Py_ssize_t)s.grazing_bytes);
    }
    if (d && self->is_auto) {
        const wenv_auto_choice *a = &self->auto_choice;
        PyObject *used = a->used_normals == (size_t)-1 || a->sh_order ? Py_NewRef(Py_None) : PyLong_FromSize_t(a->used_normals);
        PyObject *level = a->sh_order ? Py_NewRef(Py_None) : PyLong_FromSize_t(a->level);
        PyObject *order = a->sh_order ? PyLong_FromSize_t(a->sh_order) : Py_NewRef(Py_None);
        const wenv_auto_level_estimate *chosen = &a->levels[a->level];
        PyObject *levels = a->sh_order ? Py_NewRef(Py_None) : PyList_New(WENV_AUTO_LEVELS);
        for (size_t i = 0; levels && !a->sh_order && i < WENV_AUTO_LEVELS; i++) {
            const wenv_auto_level_estimate *e = &a->levels[i];
            PyObject *li = Py_BuildValue("{s:d,s:d,s:d,s:d,s:d}", "predicted_error", e->predicted_error, "lights_share",
                                         e->lights_share, "contrast", e->contrast, "light_dominance", e->light_dominance,
                                         "env_factor", e->env_factor);
            if (!li)
                Py_CLEAR(levels);
            else
                PyList_SET_ITEM(levels, (Py_ssize_t)i, li);
        }
        PyObject *info = !used || !level || !order || !levels ? NULL : Py_BuildValue("{s:O,s:O,s:s,s:d,s:d,s:d,s:d,s:d,s:d,s:O,s:d,s:d,s:O,s:O,s:d,s:d}", "level", level, "sh_order", order,
                                       "method", a->sh_order ? "sh" : "slicing", "predicted_error", a->predicted_error, "target_error",
                                       self->target_error, "contrast", chosen->contrast, "lights_share", chosen->lights_share,
                                       "light_dominance", chosen->light_dominance, "env_factor", chosen->env_factor,
                                       "met", a->met ? Py_True : Py_False, "memory_budget_mb", self->memory_budget_mb,
                                       "level_mb", (double)a->level_bytes / 1048576.0, "used_normal_samples", used,
                                       "levels", levels, "seconds", a->seconds,
                                       "analysis_seconds", a->analysis_seconds);
        Py_XDECREF(levels);
        Py_XDECREF(used);
        Py_XDECREF(level);
        Py_XDECREF(order);
        if (!info || PyDict_SetItemString(d, "auto", info) < 0)
            Py_CLEAR(d);
        Py_XDECREF(info);
    }
    return d;
}

static PyMethodDef Shader_methods[] = {
    {"shade", (PyCFunction)(void (*)(void))Shader_shade, METH_VARARGS | METH_KEYWORDS,
     "shade(normals, view_dirs)\n--\n\nLinear RGB radiance (float32, n x 3) for world-space normals and "
     "view directions (surface towards eye), float32 (n, 3); view_dirs may be one (3,) vector for all."},
    {"shade_mesh", (PyCFunction)(void (*)(void))Shader_shade_mesh, METH_VARARGS | METH_KEYWORDS,
     "shade_mesh(positions, normals, eye)\n--\n\nShade vertices seen from a perspective eye position."},
    {"set_environment", (PyCFunction)Shader_set_environment, METH_O,
     "set_environment(env)\n--\n\nNew lighting; rotation matrices are kept."},
    {"set_material", (PyCFunction)Shader_set_material, METH_O,
     "set_material(material)\n--\n\nNew BRDF; rotation matrices and lighting slices are kept."},
    {NULL, NULL, 0, NULL},
};

static PyGetSetDef Shader_getset[] = {
    {"quality", (getter)Shader_get_quality, NULL, "resolutions in use (dict)", NULL},
    {"method", (getter)Shader_get_method, NULL, "'rotation', 'slicing', 'split_sum' or 'sh'", NULL},
    {"environment", (getter)Shader_get_environment, NULL, "the current wenv.Environment", NULL},
    {"material", (getter)Shader_get_material, NULL, "the current material", NULL},
    {"stats", (getter)Shader_get_stats, NULL, "sizes, cache use and timings (dict)", NULL},
    {NULL, NULL, NULL, NULL, NULL},
};

static PyTypeObject ShaderType = {
    PyVarObject_HEAD_INIT(NULL, 0).tp_name = "wenv.Shader",
    .tp_basicsize = sizeof(ShaderObject),
    .tp_flags = Py_TPFLAGS_DEFAULT,
    .tp_doc = "Shader(env, material, quality='default', method='rotation', cache_dir=None, progress=None, "
              "target_error=0.01, memory_budget_mb=1024, normals=None)\n--\n\n"
              "Environment shading by wavelet rotation.  quality: 'draft', 'default', 'high', 'auto' or a dict of "
              "global, local, normals, views, coefficients, light_coefficients, matrix_epsilon, lights, light_threshold, grazing.  method: "
              "'rotation' (precomputed sparse matrices, cached on disk in cache_dir; None: WENV_CACHE_DIR or "
              "~/.cache/wenv; False: no cache) or 'slicing' (no matrices).  progress(fraction) is called "
              "during precomputation; returning True cancels it (wenv.CancelledError).\n\n"
              "Peer methods for comparison: 'split_sum' (prefiltered environment maps and an environment-BRDF "
              "table, Karis 2013; quality keys prefilter, samples, lut) and 'sh' (spherical harmonics, Kautz, "
              "Sloan and Snyder 2002; quality keys order, views); presets in wenv.PEER_QUALITY_PRESETS.  Their "
              "precomputation runs in set_environment and set_material, which then also report to progress.\n\n"
              "quality='auto' picks the cheapest setting of wenv.AUTO_LADDER (method 'slicing'; its last level is "
              "'high') whose error is predicted, from the narrowest lobe's roughness, the share of the flux the "
              "level's exact lights take, the bright features they leave and how far their reflections dominate, to be at "
              "most target_error (relative RMSE) within memory_budget_mb, counting lighting slices only for the "
              "normal samples the mesh's normals (if given) fall near.  A material without lobes gets method "
              "'sh' at the lowest order of wenv.AUTO_SH_ORDERS whose irradiance error, known from the lighting's "
              "SH power spectrum, meets the target.  stats['auto'] tells what it chose and why.  The choice is "
              "made once, for the environment and material given here: make a new Shader to choose again.  What "
              "it reads of the environment alone is made on first need and kept with the wenv.Environment, so "
              "later choices on it cost a fraction of a millisecond, plus about 2 ms for 126k normals "
              "(stats['auto']['analysis_seconds']: what this choice spent analysing).",
    .tp_new = PyType_GenericNew,
    .tp_init = (initproc)Shader_init,
    .tp_dealloc = (destructor)Shader_dealloc,
    .tp_methods = Shader_methods,
    .tp_getset = Shader_getset,
};

static PyObject *py_reference(PyObject *self, PyObject *args, PyObject *kwargs)
{
    (void)self;
    static char *kwlist[] = {"env", "material", "normals", "view_dirs", "progress", NULL};
    PyObject *env_obj, *mat_obj, *nobj, *vobj, *progress_obj = Py_None;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "OOOO|O:reference", kwlist, &env_obj, &mat_obj, &nobj, &vobj,
                                     &progress_obj))
        return NULL;
    const struct wenv_envmap *env = wenv_py_envmap(env_obj, "env");
    if (!env)
        return NULL;
    const struct wenv_material *mat = wenv_py_material(mat_obj, "material");
    if (!mat)
        return NULL;
    if (progress_obj != Py_None && !PyCallable_Check(progress_obj)) {
        PyErr_SetString(PyExc_TypeError, "progress must be callable or None");
        return NULL;
    }
    Py_buffer nb, vb;
    size_t n, nv;
    if (wenv_py_get_vec3_array(nobj, "normals", 1, &nb, &n, NULL) < 0)
        return NULL;
    if (wenv_py_get_vec3_array(vobj, "view_dirs", 1, &vb, &nv, NULL) < 0) {
        PyBuffer_Release(&nb);
        return NULL;
    }
    PyObject *result = NULL;
    if (nv != n) {
        PyErr_Format(PyExc_ValueError, "view_dirs has %zu rows but normals has %zu", nv, n);
        goto done;
    }
    Py_ssize_t shape[2] = {(Py_ssize_t)n, 3};
    float *out;
    result = wenv_py_new_float_array(2, shape, &out);
    if (!result || n == 0)
        goto done;
    wenv_py_progress_bridge bridge = {progress_obj, 0};
    wenv_progress progress = wenv_py_progress(&bridge);
    wenv_error err = {0};
    wenv_status st;
    Py_BEGIN_ALLOW_THREADS
    st = wenv_reference(env, mat, nb.buf, vb.buf, n, out, &progress, &err);
    Py_END_ALLOW_THREADS
    if (st) {
        Py_CLEAR(result);
        if (!(bridge.raised && PyErr_Occurred()))
            wenv_py_raise(&err);
    }
done:
    PyBuffer_Release(&nb);
    PyBuffer_Release(&vb);
    return result;
}

/* ---- private hooks for the tests ---- */

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
    float *scratch = PyMem_Malloc(n * ch * sizeof(float) + 1);
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

static PyMethodDef shade_functions[] = {
    {"reference", (PyCFunction)(void (*)(void))py_reference, METH_VARARGS | METH_KEYWORDS,
     "reference(env, material, normals, view_dirs, progress=None)\n--\n\nGround truth: the reflection "
     "equation summed over every environment pixel (exact solid angles), in the units of Shader.shade."},
    {"_oct_encode", py_oct_encode, METH_VARARGS, NULL},
    {"_oct_decode", py_oct_decode, METH_VARARGS, NULL},
    {"_hemi_encode", py_hemi_encode, METH_VARARGS, NULL},
    {"_hemi_decode", py_hemi_decode, METH_VARARGS, NULL},
    {"_texel_solid_angles", py_texel_solid_angles, METH_VARARGS, NULL},
    {"_haar2d", (PyCFunction)(void (*)(void))py_haar2d, METH_VARARGS | METH_KEYWORDS, NULL},
    {NULL, NULL, 0, NULL},
};

int wenv_register_shade(PyObject *module)
{
    if (PyType_Ready(&ShaderType) < 0)
        return -1;
    Py_INCREF(&ShaderType);
    if (PyModule_AddObject(module, "Shader", (PyObject *)&ShaderType) < 0) {
        Py_DECREF(&ShaderType);
        return -1;
    }
    if (PyModule_AddFunctions(module, shade_functions) < 0)
        return -1;
    PyObject *presets = PyDict_New();
    if (!presets)
        return -1;
    for (size_t i = 0; i < N_PRESETS; i++) {
        PyObject *d = quality_to_dict(&PRESETS[i].q);
        if (!d || PyDict_SetItemString(presets, PRESETS[i].name, d) < 0) {
            Py_XDECREF(d);
            Py_DECREF(presets);
            return -1;
        }
        Py_DECREF(d);
    }
    if (PyModule_AddObject(module, "QUALITY_PRESETS", presets) < 0) {
        Py_DECREF(presets);
        return -1;
    }
    PyObject *ladder = PyList_New(WENV_AUTO_LEVELS);
    if (!ladder)
        return -1;
    for (size_t i = 0; i < WENV_AUTO_LEVELS; i++) {
        PyObject *d = quality_to_dict(wenv_auto_level(i));
        if (!d) {
            Py_DECREF(ladder);
            return -1;
        }
        PyList_SET_ITEM(ladder, (Py_ssize_t)i, d);
    }
    if (PyModule_AddObject(module, "AUTO_LADDER", ladder) < 0) {
        Py_DECREF(ladder);
        return -1;
    }
    PyObject *orders = PyTuple_New(WENV_AUTO_SH_ORDER_COUNT);
    if (!orders)
        return -1;
    for (size_t i = 0; i < WENV_AUTO_SH_ORDER_COUNT; i++) {
        PyObject *o = PyLong_FromSize_t(WENV_AUTO_SH_ORDERS[i]);
        if (!o) {
            Py_DECREF(orders);
            return -1;
        }
        PyTuple_SET_ITEM(orders, (Py_ssize_t)i, o);
    }
    if (PyModule_AddObject(module, "AUTO_SH_ORDERS", orders) < 0) {
        Py_DECREF(orders);
        return -1;
    }
    return 0;
}
