/* Python glue for the peer shading methods behind wenv.Shader: "split_sum" (splitsum.h) and "sh"
 * (shrender.h), their quality presets, and private hooks that let the tests reach the spherical
 * harmonics (sh.h).  bind_shade.c dispatches to these when the method is a peer's. */
#include "bindings.h"

#include <stddef.h>
#include <string.h>

#include "sh.h"
#include "shrender.h"
#include "splitsum.h"

typedef enum { PEER_SPLIT_SUM = 0, PEER_SH = 1 } peer_kind;

typedef struct {
    const char *key;
    size_t offset; /* of a size_t in the method's quality struct */
} quality_key;

static const quality_key SPLIT_SUM_KEYS[] = {
    {"prefilter", offsetof(wenv_splitsum_quality, prefilter)},
    {"samples", offsetof(wenv_splitsum_quality, samples)},
    {"lut", offsetof(wenv_splitsum_quality, lut)},
};
static const quality_key SH_KEYS[] = {
    {"order", offsetof(wenv_shrender_quality, order)},
    {"views", offsetof(wenv_shrender_quality, views)},
};

static const char *PRESET_NAMES[3] = {"draft", "default", "high"};
static const wenv_splitsum_quality SPLIT_SUM_PRESETS[3] = {{64, 64, 32}, {128, 256, 64}, {256, 512, 128}};
static const wenv_shrender_quality SH_PRESETS[3] = {{4, 16}, {8, 32}, {16, 64}};

typedef struct {
    const char *name, *keys_text;
    const quality_key *keys;
    size_t n_keys;
} peer_info;

static const peer_info PEERS[2] = {
    {"split_sum", "prefilter, samples, lut", SPLIT_SUM_KEYS, sizeof SPLIT_SUM_KEYS / sizeof SPLIT_SUM_KEYS[0]},
    {"sh", "order, views", SH_KEYS, sizeof SH_KEYS / sizeof SH_KEYS[0]},
};

struct wenv_py_peer {
    peer_kind kind;
    wenv_splitsum_quality split_sum_q;
    wenv_shrender_quality sh_q;
    wenv_splitsum *split_sum;
    wenv_shrender *sh;
    PyObject *progress; /* owned, or NULL */
};

int wenv_py_is_peer_method(const char *method)
{
    return strcmp(method, PEERS[PEER_SPLIT_SUM].name) == 0 || strcmp(method, PEERS[PEER_SH].name) == 0;
}

const char *wenv_py_peer_method(const wenv_py_peer *peer) { return PEERS[peer->kind].name; }

static void *quality_struct(wenv_py_peer *peer)
{
    return peer->kind == PEER_SPLIT_SUM ? (void *)&peer->split_sum_q : (void *)&peer->sh_q;
}

static PyObject *quality_dict(peer_kind kind, const void *q)
{
    const peer_info *info = &PEERS[kind];
    PyObject *d = PyDict_New();
    for (size_t k = 0; d && k < info->n_keys; k++) {
        PyObject *v = PyLong_FromSize_t(*(const size_t *)((const char *)q + info->keys[k].offset));
        if (!v || PyDict_SetItemString(d, info->keys[k].key, v) < 0)
            Py_CLEAR(d);
        Py_XDECREF(v);
    }
    return d;
}

static int parse_peer_quality(wenv_py_peer *peer, PyObject *obj)
{
    const peer_info *info = &PEERS[peer->kind];
    size_t preset = 1;
    if (obj && PyUnicode_Check(obj)) {
        const char *name = PyUnicode_AsUTF8(obj);
        if (!name)
            return -1;
        for (preset = 0; preset < 3 && strcmp(name, PRESET_NAMES[preset]) != 0; preset++)
            ;
        if (preset == 3) {
            PyErr_Format(PyExc_ValueError, "quality must be 'draft', 'default', 'high' or a dict, got '%s'", name);
            return -1;
        }
    } else if (obj && !PyDict_Check(obj)) {
        PyErr_Format(PyExc_TypeError, "quality must be a preset name or a dict, got %.100s", Py_TYPE(obj)->tp_name);
        return -1;
    }
    peer->split_sum_q = SPLIT_SUM_PRESETS[preset];
    peer->sh_q = SH_PRESETS[preset];
    if (obj && PyDict_Check(obj)) {
        PyObject *key, *value;
        Py_ssize_t pos = 0;
        while (PyDict_Next(obj, &pos, &key, &value)) {
            const char *k = PyUnicode_Check(key) ? PyUnicode_AsUTF8(key) : NULL;
            if (!k) {
                PyErr_Clear();
                PyErr_SetString(PyExc_TypeError, "quality keys must be strings");
                return -1;
            }
            size_t e = 0;
            while (e < info->n_keys && strcmp(k, info->keys[e].key) != 0)
                e++;
            if (e == info->n_keys) {
                PyErr_Format(PyExc_ValueError, "quality key '%s' does not apply to method '%s' (use %s)", k,
                             info->name, info->keys_text);
                return -1;
            }
            char name[64];
            snprintf(name, sizeof name, "quality['%s']", k);
            if (wenv_py_get_size(value, name, (size_t *)((char *)quality_struct(peer) + info->keys[e].offset)) < 0)
                return -1;
        }
    }
    wenv_error err = {0};
    wenv_status st = peer->kind == PEER_SPLIT_SUM ? wenv_splitsum_quality_check(&peer->split_sum_q, &err)
                                                  : wenv_shrender_quality_check(&peer->sh_q, &err);
    if (st) {
        wenv_py_raise(&err);
        return -1;
    }
    return 0;
}

void wenv_py_peer_free(wenv_py_peer *peer)
{
    if (!peer)
        return;
    wenv_splitsum_free(peer->split_sum);
    wenv_shrender_free(peer->sh);
    Py_XDECREF(peer->progress);
    PyMem_Free(peer);
}

wenv_py_peer *wenv_py_peer_create(const char *method, PyObject *quality, PyObject *progress)
{
    wenv_py_peer *peer = PyMem_Calloc(1, sizeof *peer);
    if (!peer)
        return (wenv_py_peer *)PyErr_NoMemory();
    peer->kind = strcmp(method, PEERS[PEER_SH].name) == 0 ? PEER_SH : PEER_SPLIT_SUM;
    if (parse_peer_quality(peer, quality) < 0) {
        wenv_py_peer_free(peer);
        return NULL;
    }
    if (progress && progress != Py_None)
        peer->progress = Py_NewRef(progress);
    wenv_error err = {0};
    wenv_status st;
    Py_BEGIN_ALLOW_THREADS
    st = peer->kind == PEER_SPLIT_SUM ? wenv_splitsum_create(&peer->split_sum, &peer->split_sum_q, &err)
                                      : wenv_shrender_create(&peer->sh, &peer->sh_q, &err);
    Py_END_ALLOW_THREADS
    if (st) {
        wenv_py_peer_free(peer);
        wenv_py_raise(&err);
        return NULL;
    }
    return peer;
}

/* set_environment (what = 0) or set_material (what = 1), GIL released, progress reported */
static int peer_set(wenv_py_peer *peer, int what, const void *arg)
{
    wenv_py_progress_bridge bridge = {peer->progress, 0};
    wenv_progress progress = wenv_py_progress(&bridge);
    wenv_error err = {0};
    wenv_status st;
    Py_BEGIN_ALLOW_THREADS
    if (peer->kind == PEER_SPLIT_SUM)
        st = what ? wenv_splitsum_set_material(peer->split_sum, arg, &progress, &err)
                  : wenv_splitsum_set_environment(peer->split_sum, arg, &progress, &err);
    else
        st = what ? wenv_shrender_set_material(peer->sh, arg, &progress, &err)
                  : wenv_shrender_set_environment(peer->sh, arg, &progress, &err);
    Py_END_ALLOW_THREADS
    if (st) {
        if (!(bridge.raised && PyErr_Occurred()))
            wenv_py_raise(&err);
        return -1;
    }
    return 0;
}

int wenv_py_peer_set_environment(wenv_py_peer *peer, const struct wenv_envmap *env) { return peer_set(peer, 0, env); }

int wenv_py_peer_set_material(wenv_py_peer *peer, const struct wenv_material *mat) { return peer_set(peer, 1, mat); }

int wenv_py_peer_shade(wenv_py_peer *peer, const float *normals, const float *views, size_t n, float *out)
{
    wenv_error err = {0};
    wenv_status st;
    Py_BEGIN_ALLOW_THREADS
    st = peer->kind == PEER_SPLIT_SUM ? wenv_splitsum_shade(peer->split_sum, normals, views, n, out, &err)
                                      : wenv_shrender_shade(peer->sh, normals, views, n, out, &err);
    Py_END_ALLOW_THREADS
    if (st) {
        wenv_py_raise(&err);
        return -1;
    }
    return 0;
}

PyObject *wenv_py_peer_quality(wenv_py_peer *peer) { return quality_dict(peer->kind, quality_struct(peer)); }

PyObject *wenv_py_peer_stats(const wenv_py_peer *peer)
{
    if (peer->kind == PEER_SPLIT_SUM) {
        wenv_splitsum_stats s;
        wenv_splitsum_get_stats(peer->split_sum, &s);
        return Py_BuildValue("{s:n,s:n,s:n,s:n,s:n,s:n,s:d,s:d,s:d}", "lobes", (Py_ssize_t)s.lobes, "source_side",
                             (Py_ssize_t)s.source_side, "source_levels", (Py_ssize_t)s.source_levels,
                             "source_bytes", (Py_ssize_t)s.source_bytes, "prefilter_bytes", (Py_ssize_t)s.prefilter_bytes, "lut_bytes", (Py_ssize_t)s.lut_bytes,
                             "environment_seconds", s.environment_seconds, "prefilter_seconds", s.prefilter_seconds,
                             "lut_seconds", s.lut_seconds);
    }
    wenv_shrender_stats s;
    wenv_shrender_get_stats(peer->sh, &s);
    return Py_BuildValue("{s:n,s:n,s:n,s:d,s:d}", "coefficients", (Py_ssize_t)s.coefficients, "slice_bytes",
                         (Py_ssize_t)s.slice_bytes, "quadrature_nodes", (Py_ssize_t)s.quadrature_nodes,
                         "projection_seconds", s.projection_seconds, "slice_seconds", s.slice_seconds);
}

/* ---- private hooks for the tests ---- */

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

static PyMethodDef peer_functions[] = {
    {"_sh_basis", py_sh_basis, METH_VARARGS, NULL},
    {"_sh_rotate", py_sh_rotate, METH_VARARGS, NULL},
    {NULL, NULL, 0, NULL},
};

int wenv_register_peers(PyObject *module)
{
    if (PyModule_AddFunctions(module, peer_functions) < 0)
        return -1;
    PyObject *presets = PyDict_New();
    if (!presets)
        return -1;
    for (size_t kind = 0; kind < 2; kind++) {
        PyObject *per = PyDict_New();
        if (!per || PyDict_SetItemString(presets, PEERS[kind].name, per) < 0) {
            Py_XDECREF(per);
            Py_DECREF(presets);
            return -1;
        }
        Py_DECREF(per);
        for (size_t p = 0; p < 3; p++) {
            PyObject *d = kind == PEER_SPLIT_SUM ? quality_dict(PEER_SPLIT_SUM, &SPLIT_SUM_PRESETS[p])
                                                 : quality_dict(PEER_SH, &SH_PRESETS[p]);
            if (!d || PyDict_SetItemString(per, PRESET_NAMES[p], d) < 0) {
                Py_XDECREF(d);
                Py_DECREF(presets);
                return -1;
            }
            Py_DECREF(d);
        }
    }
    return PyModule_AddObject(module, "PEER_QUALITY_PRESETS", presets);
}
