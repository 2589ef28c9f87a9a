/* wenv.Occluders and wenv.Occlusion: what stands between the vertices and their sky (scene/occluders.h,
 * scene/occlusion.h). */
#include "python/bind_occlusion.h"

#include <math.h>
#include <string.h>

#include "math/maps.h"
#include "python/module.h"
#include "scene/ambient.h"
#include "scene/bevel.h"
#include "scene/occlusion.h"
#include "scene/sending_map.h"

typedef struct {
    PyObject_HEAD
    wenv_occluders *occ;
} OccludersObject;

typedef struct {
    PyObject_HEAD
    wenv_occlusion o;
    PyObject *occluders; /* what it was cast against: the lights' rays and the bounce's triangles */
} OcclusionObject;

static PyTypeObject OccludersType, OcclusionType;

int wenv_py_occlusion(PyObject *obj, const char *name, const wenv_occlusion **occlusion,
                      const wenv_occluders **occluders)
{
    if (!PyObject_TypeCheck(obj, &OcclusionType)) {
        PyErr_Format(PyExc_TypeError, "%s must be a wenv.Occlusion (Occluders.occlusion), got %.100s", name,
                     Py_TYPE(obj)->tp_name);
        return -1;
    }
    OcclusionObject *o = (OcclusionObject *)obj;
    *occlusion = &o->o;
    *occluders = ((OccludersObject *)o->occluders)->occ;
    return 0;
}

const struct wenv_occluders *wenv_py_occluders(PyObject *obj, const char *name)
{
    if (!PyObject_TypeCheck(obj, &OccludersType) || !((OccludersObject *)obj)->occ) {
        PyErr_Format(PyExc_TypeError, "%s must be a wenv.Occluders, got %.100s", name, Py_TYPE(obj)->tp_name);
        return NULL;
    }
    return ((OccludersObject *)obj)->occ;
}

/* A C-contiguous uint32 copy of an integer array of shape (m, 3), every entry in [0, 2^32); *m rows. */
static PyObject *triangle_array(PyObject *obj, size_t *m)
{
    PyObject *numpy = PyImport_ImportModule("numpy");
    PyObject *arr = numpy ? PyObject_CallMethod(numpy, "asarray", "O", obj) : NULL;
    PyObject *result = NULL;
    if (!arr)
        goto done;
    PyObject *kind = PyObject_GetAttrString(arr, "dtype");
    PyObject *k = kind ? PyObject_GetAttrString(kind, "kind") : NULL;
    int integer = k && PyUnicode_Check(k) &&
                  (PyUnicode_CompareWithASCIIString(k, "i") == 0 || PyUnicode_CompareWithASCIIString(k, "u") == 0);
    Py_XDECREF(kind);
    Py_XDECREF(k);
    PyObject *shape = PyObject_GetAttrString(arr, "shape");
    int ok = shape && PyTuple_Check(shape) && PyTuple_GET_SIZE(shape) == 2 &&
             PyLong_AsSsize_t(PyTuple_GET_ITEM(shape, 1)) == 3;
    Py_ssize_t rows = ok ? PyLong_AsSsize_t(PyTuple_GET_ITEM(shape, 0)) : 0;
    Py_XDECREF(shape);
    if (PyErr_Occurred())
        goto done;
    if (!integer || !ok) {
        PyErr_SetString(PyExc_TypeError, "triangles must be an integer array of shape (m, 3)");
        goto done;
    }
    if (rows > 0) {
        PyObject *lo = PyObject_CallMethod(arr, "min", NULL), *hi = PyObject_CallMethod(arr, "max", NULL);
        PyObject *zero = PyLong_FromLong(0), *limit = PyLong_FromUnsignedLongLong(UINT32_MAX);
        int neg = lo && zero ? PyObject_RichCompareBool(lo, zero, Py_LT) : -1;
        int big = hi && limit ? PyObject_RichCompareBool(hi, limit, Py_GT) : -1;
        Py_XDECREF(lo);
        Py_XDECREF(hi);
        Py_XDECREF(zero);
        Py_XDECREF(limit);
        if (neg < 0 || big < 0)
            goto done;
        if (neg || big) {
            PyErr_SetString(PyExc_ValueError, "triangles must index positions: every entry in [0, 2^32)");
            goto done;
        }
    }
    result = PyObject_CallMethod(numpy, "ascontiguousarray", "Os", arr, "uint32");
    *m = (size_t)rows;
done:
    Py_XDECREF(numpy);
    Py_XDECREF(arr);
    return result;
}

/* ---------------------------------------------------------------- wenv.Occluders */

static int occluders_init(OccludersObject *self, PyObject *args, PyObject *kwargs)
{
    static char *kwlist[] = {"positions", "triangles", "memory_budget_mb", NULL};
    PyObject *pobj, *tobj;
    double budget_mb = 1024.0;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "OO|d:Occluders", kwlist, &pobj, &tobj, &budget_mb))
        return -1;
    if (self->occ) {
        PyErr_SetString(PyExc_RuntimeError, "Occluders is already initialised");
        return -1;
    }
    if (!(budget_mb > 0.0 && budget_mb < 1e9)) {
        wenv_py_errorf(PyExc_ValueError, "memory_budget_mb must be positive, got %g", budget_mb);
        return -1;
    }
    Py_buffer pb, tb;
    size_t np, nt = 0;
    if (wenv_py_get_vec3_array(pobj, "positions", 0, &pb, &np, NULL) < 0)
        return -1;
    PyObject *tri = triangle_array(tobj, &nt);
    if (!tri || PyObject_GetBuffer(tri, &tb, PyBUF_C_CONTIGUOUS) < 0) {
        Py_XDECREF(tri);
        PyBuffer_Release(&pb);
        return -1;
    }
    wenv_error err = {0};
    wenv_status st;
    wenv_occluders *occ = NULL;
    WENV_BEGIN_WORK
    st = wenv_occluders_create(&occ, pb.buf, np, tb.buf, nt, (size_t)(budget_mb * 1048576.0), &err);
    WENV_END_WORK
    PyBuffer_Release(&tb);
    Py_DECREF(tri);
    PyBuffer_Release(&pb);
    if (st) {
        wenv_py_raise(&err);
        return -1;
    }
    self->occ = occ;
    return 0;
}

static void occluders_dealloc(OccludersObject *self)
{
    wenv_occluders_free(self->occ);
    Py_TYPE(self)->tp_free((PyObject *)self);
}

static int ready(OccludersObject *self)
{
    if (!self->occ) {
        PyErr_SetString(PyExc_RuntimeError, "Occluders is not initialised");
        return -1;
    }
    return 0;
}

/* occluded(origins, directions, tfar=inf): bool per ray. */
static PyObject *occluders_occluded(OccludersObject *self, PyObject *args, PyObject *kwargs)
{
    static char *kwlist[] = {"origins", "directions", "tfar", NULL};
    PyObject *oobj, *dobj;
    double tfar = INFINITY;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "OO|d:occluded", kwlist, &oobj, &dobj, &tfar) || ready(self) < 0)
        return NULL;
    if (!(tfar > 0.0)) {
        wenv_py_errorf(PyExc_ValueError, "tfar must be positive, got %g", tfar);
        return NULL;
    }
    Py_buffer ob, db;
    size_t no, nd;
    if (wenv_py_get_vec3_array(oobj, "origins", 0, &ob, &no, NULL) < 0)
        return NULL;
    if (wenv_py_get_vec3_array(dobj, "directions", 1, &db, &nd, NULL) < 0) {
        PyBuffer_Release(&ob);
        return NULL;
    }
    PyObject *result = NULL;
    if (no != nd && no != 1) {
        PyErr_Format(PyExc_ValueError, "origins has %zu rows but directions has %zu (or give one origin)", no, nd);
        goto done;
    }
    Py_ssize_t shape[1] = {(Py_ssize_t)nd};
    void *data;
    float *unit = PyMem_Malloc(nd * 3 * sizeof(float) + 1);
    if (!unit) {
        PyErr_NoMemory();
        goto done;
    }
    const float *d = db.buf;
    for (size_t k = 0; k < nd; k++) {
        float len = sqrtf(d[3 * k] * d[3 * k] + d[3 * k + 1] * d[3 * k + 1] + d[3 * k + 2] * d[3 * k + 2]);
        for (int c = 0; c < 3; c++)
            unit[3 * k + (size_t)c] = d[3 * k + (size_t)c] / len;
    }
    if ((result = wenv_py_new_array(1, shape, "bool", &data))) {
        const float *o = ob.buf;
        WENV_BEGIN_WORK
        if (no == 1)
            wenv_occluders_test(self->occ, o, unit, nd, (float)tfar, data);
        else
            wenv_occluders_test_rays(self->occ, o, unit, nd, (float)tfar, data);
        WENV_END_WORK
    }
    PyMem_Free(unit);
done:
    PyBuffer_Release(&ob);
    PyBuffer_Release(&db);
    return result;
}

/* The core's ambient shares or bevelled normals, as wenv_py_run_released runs them. */
typedef struct {
    const wenv_occluders *occ;
    const float *points, *normals, *radii;
    size_t n, rays;
    double distance_or_radius;
    int inside;
    float *out;
} surface_work;

static wenv_status run_ambient(void *ctx, const wenv_progress *p, wenv_error *err)
{
    const surface_work *w = ctx;
    return wenv_ambient_shares(w->occ, w->points, w->normals, w->n, w->rays, w->distance_or_radius, w->inside, w->out,
                               p, err);
}

static wenv_status run_bevel(void *ctx, const wenv_progress *p, wenv_error *err)
{
    const surface_work *w = ctx;
    return wenv_bevel_normals(w->occ, w->normals, w->points, w->n, w->distance_or_radius, w->radii, w->out, p, err);
}

/* ambient(points, normals, distance, rays, inside=False, progress=None): the Ambient Occlusion
 * node's unoccluded share per point. */
static PyObject *occluders_ambient(OccludersObject *self, PyObject *args, PyObject *kwargs)
{
    static char *kwlist[] = {"points", "normals", "distance", "rays", "inside", "progress", NULL};
    PyObject *pobj, *nobj, *progress_obj = Py_None;
    double distance;
    Py_ssize_t rays;
    int inside = 0;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "OOdn|pO:ambient", kwlist, &pobj, &nobj, &distance, &rays,
                                     &inside, &progress_obj) ||
        ready(self) < 0 || wenv_py_check_progress(progress_obj) < 0)
        return NULL;
    if (rays < 1) {
        wenv_py_errorf(PyExc_ValueError, "rays must be from 1 to %d, got %zd", WENV_AMBIENT_MAX_RAYS, rays);
        return NULL;
    }
    Py_buffer pb, nb;
    size_t np;
    if (wenv_py_get_vec3_pair(pobj, "points", nobj, "normals", 0, &pb, &nb, &np) < 0)
        return NULL;
    PyObject *result = NULL;
    Py_ssize_t shape[1] = {(Py_ssize_t)np};
    float *out;
    if (!(result = wenv_py_new_float_array(1, shape, &out)))
        goto done;
    surface_work work = {self->occ, pb.buf, nb.buf, NULL, np, (size_t)rays, distance, inside, out};
    if (wenv_py_run_released(run_ambient, &work, progress_obj) < 0)
        Py_CLEAR(result);
done:
    PyBuffer_Release(&pb);
    PyBuffer_Release(&nb);
    return result;
}

/* bevel(points, corner_normals, radius, progress=None): the Bevel node's unit normal per point;
 * radius one for all, or float32 (n,), each point's. */
static PyObject *occluders_bevel(OccludersObject *self, PyObject *args, PyObject *kwargs)
{
    static char *kwlist[] = {"points", "corner_normals", "radius", "progress", NULL};
    PyObject *pobj, *nobj, *robj, *progress_obj = Py_None;
    double radius = 0.0;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "OOO|O:bevel", kwlist, &pobj, &nobj, &robj, &progress_obj) ||
        ready(self) < 0)
        return NULL;
    if (wenv_py_check_progress(progress_obj) < 0)
        return NULL;
    int per_point = PyObject_CheckBuffer(robj);
    if (!per_point) {
        if (wenv_py_get_finite(robj, "radius", &radius) < 0)
            return NULL;
        if (!(radius > 0.0)) {
            wenv_py_errorf(PyExc_ValueError, "radius must be positive and finite, got %g", radius);
            return NULL;
        }
    }
    Py_buffer pb, nb, rb = {0};
    size_t np, nn;
    if (wenv_py_get_vec3_array(pobj, "points", 0, &pb, &np, NULL) < 0)
        return NULL;
    if (wenv_py_get_vec3_array(nobj, "corner_normals", 0, &nb, &nn, NULL) < 0) {
        PyBuffer_Release(&pb);
        return NULL;
    }
    if (per_point && wenv_py_get_vertex_values(robj, "radius", np, &rb) < 0) {
        PyBuffer_Release(&pb);
        PyBuffer_Release(&nb);
        return NULL;
    }
    PyObject *result = NULL;
    size_t triangles = wenv_occluders_triangle_count(self->occ);
    if (nn != 3 * triangles) {
        PyErr_Format(PyExc_ValueError, "corner_normals has %zu rows: it needs 3 per triangle (%zu)", nn,
                     3 * triangles);
        goto done;
    }
    Py_ssize_t shape[2] = {(Py_ssize_t)np, 3};
    float *out;
    if (!(result = wenv_py_new_float_array(2, shape, &out)))
        goto done;
    surface_work work = {self->occ, pb.buf, nb.buf, per_point ? rb.buf : NULL, np, 0, radius, 0, out};
    if (wenv_py_run_released(run_bevel, &work, progress_obj) < 0)
        Py_CLEAR(result);
done:
    PyBuffer_Release(&pb);
    PyBuffer_Release(&nb);
    if (per_point)
        PyBuffer_Release(&rb);
    return result;
}

/* The previous occlusion and the changed triangles of a refresh: previous None (and changed None)
 * for a new cast.  -1 + an exception naming the argument. */
static int refresh_args(PyObject *previous, PyObject *changed, size_t *resolution, int resolution_given,
                        const OcclusionObject **before, size_t *first, size_t *count)
{
    *before = NULL;
    if (previous == Py_None) {
        if (changed != Py_None) {
            PyErr_SetString(PyExc_ValueError, "changed needs previous: the occlusion cast before the change");
            return -1;
        }
        return 0;
    }
    if (!PyObject_TypeCheck(previous, &OcclusionType)) {
        PyErr_Format(PyExc_TypeError, "previous must be a wenv.Occlusion, got %.80s", Py_TYPE(previous)->tp_name);
        return -1;
    }
    const OcclusionObject *b = (const OcclusionObject *)previous;
    if (resolution_given && *resolution != b->o.resolution) {
        PyErr_Format(PyExc_ValueError, "resolution %zu is not previous's (%zu)", *resolution, b->o.resolution);
        return -1;
    }
    *resolution = b->o.resolution;
    if (!PyTuple_Check(changed) || PyTuple_GET_SIZE(changed) != 2 ||
        wenv_py_get_size(PyTuple_GET_ITEM(changed, 0), "changed[0]", first) < 0 ||
        wenv_py_get_size(PyTuple_GET_ITEM(changed, 1), "changed[1]", count) < 0) {
        if (!PyErr_Occurred())
            PyErr_SetString(PyExc_TypeError,
                            "changed must be (first, count): the triangles of previous's occluders that changed");
        return -1;
    }
    *before = b;
    return 0;
}

/* masks_from as the core takes it: n vertex indices (PyMem_Malloc'ed into *out); NULL for None. */
static int masks_from_arg(PyObject *obj, size_t n, uint32_t **out)
{
    *out = NULL;
    if (obj == Py_None)
        return 0;
    Py_buffer view;
    PyObject *held = NULL;
    if (wenv_py_get_typed_array(obj, "masks_from", "int64", 0, &view, &held) < 0)
        return -1;
    int ok = view.ndim == 1 && (size_t)view.shape[0] == n;
    if (!ok)
        PyErr_Format(PyExc_ValueError, "masks_from must hold one vertex index per vertex (%zu)", n);
    const int64_t *from = view.buf;
    *out = ok ? PyMem_Malloc((n ? n : 1) * sizeof **out) : NULL;
    if (ok && !*out)
        PyErr_NoMemory();
    for (size_t i = 0; *out && i < n; i++) {
        if (from[i] < 0 || (uint64_t)from[i] >= n) {
            PyErr_Format(PyExc_ValueError, "masks_from[%zu] must be a vertex index in [0, %zu), got %lld", i, n,
                         (long long)from[i]);
            PyMem_Free(*out);
            *out = NULL;
            break;
        }
        (*out)[i] = (uint32_t)from[i];
    }
    wenv_py_release_array(&view, &held);
    return *out ? 0 : -1;
}

/* occlusion(positions, normals, resolution=8, progress=None, previous=None, changed=None, *, point_rays=False,
 *           masks_from=None) -> wenv.Occlusion */
static PyObject *occluders_occlusion(OccludersObject *self, PyObject *args, PyObject *kwargs)
{
    static char *kwlist[] = {"positions", "normals", "resolution", "progress", "previous", "changed", "point_rays",
                             "masks_from", NULL};
    PyObject *pobj, *nobj, *res_obj = NULL, *progress_obj = Py_None, *previous = Py_None, *changed = Py_None;
    PyObject *masks_obj = Py_None;
    int point_rays = -1;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "OO|OOOO$pO:occlusion", kwlist, &pobj, &nobj, &res_obj,
                                     &progress_obj, &previous, &changed, &point_rays, &masks_obj) ||
        ready(self) < 0)
        return NULL;
    size_t resolution = 8, first = 0, count = 0;
    int automatic = res_obj && PyUnicode_Check(res_obj);
    if (automatic && PyUnicode_CompareWithASCIIString(res_obj, "auto")) {
        PyErr_Format(PyExc_ValueError, "resolution must be 4 to 16 or 'auto', got %R", res_obj);
        return NULL;
    }
    if (res_obj && !automatic && wenv_py_get_size(res_obj, "resolution", &resolution) < 0)
        return NULL;
    if (wenv_py_check_progress(progress_obj) < 0)
        return NULL;
    const OcclusionObject *before;
    if (refresh_args(previous, changed, &resolution, res_obj != NULL && !automatic, &before, &first, &count) < 0)
        return NULL;
    if (masks_obj != Py_None && before) {
        PyErr_SetString(PyExc_ValueError, "masks_from is not taken with previous: a refresh keeps previous's masks");
        return NULL;
    }
    if (before && point_rays >= 0 && point_rays != before->o.point_rays) {
        PyErr_Format(PyExc_ValueError, "point_rays=%s is not previous's: a refresh keeps what previous was made as",
                     point_rays ? "True" : "False");
        return NULL;
    }
    Py_buffer pb, nb;
    size_t np;
    if (wenv_py_get_vec3_pair(pobj, "positions", nobj, "normals", 1, &pb, &nb, &np) < 0)
        return NULL;
    if (automatic && !before)
        resolution = wenv_occlusion_auto_resolution(np);
    uint32_t *masks_from = NULL;
    OcclusionObject *out = NULL;
    if (masks_from_arg(masks_obj, np, &masks_from) < 0)
        goto done;
    out = PyObject_New(OcclusionObject, &OcclusionType);
    if (!out)
        goto done;
    memset(&out->o, 0, sizeof out->o);
    out->occluders = Py_NewRef((PyObject *)self);
    wenv_py_progress_bridge bridge = {.callback = progress_obj};
    wenv_progress progress = wenv_py_progress(&bridge);
    wenv_error err = {0};
    wenv_status st;
    WENV_BEGIN_WORK
    if (before)
        st = wenv_occlusion_refresh(&out->o, &before->o, ((OccludersObject *)before->occluders)->occ, self->occ,
                                    pb.buf, nb.buf, np, first, count, &progress, &err);
    else
        st = wenv_occlusion_make(&out->o, self->occ, pb.buf, nb.buf, np, resolution, point_rays > 0, masks_from,
                                 &progress, &err);
    WENV_END_WORK
    if (st) {
        Py_CLEAR(out);
        if (!(bridge.raised && PyErr_Occurred()))
            wenv_py_raise(&err);
    }
done:
    PyMem_Free(masks_from);
    PyBuffer_Release(&pb);
    PyBuffer_Release(&nb);
    return (PyObject *)out;
}

static PyObject *occluders_triangles(OccludersObject *self, void *closure)
{
    (void)closure;
    return ready(self) < 0 ? NULL : PyLong_FromSize_t(wenv_occluders_triangle_count(self->occ));
}

static PyObject *occluders_size(OccludersObject *self, void *closure)
{
    (void)closure;
    return ready(self) < 0 ? NULL : PyFloat_FromDouble(wenv_occluders_size(self->occ));
}

static PyObject *occluders_offset(OccludersObject *self, void *closure)
{
    (void)closure;
    return ready(self) < 0 ? NULL : PyFloat_FromDouble(wenv_occluders_offset(self->occ));
}

/* auto_resolution(count) -> int */
static PyObject *occluders_bytes_needed(PyObject *cls, PyObject *args)
{
    (void)cls;
    Py_ssize_t positions, triangles;
    if (!PyArg_ParseTuple(args, "nn:bytes_needed", &positions, &triangles))
        return NULL;
    if (positions < 0 || triangles < 0) {
        PyErr_SetString(PyExc_ValueError, "positions and triangles must be counts (0 or more)");
        return NULL;
    }
    return PyFloat_FromDouble(wenv_occluders_bytes_needed((size_t)positions, (size_t)triangles));
}

static PyObject *occluders_auto_resolution(PyObject *cls, PyObject *count_obj)
{
    (void)cls;
    size_t count;
    if (wenv_py_get_size(count_obj, "count", &count) < 0)
        return NULL;
    return PyLong_FromSize_t(wenv_occlusion_auto_resolution(count));
}

static PyMethodDef occluders_methods[] = {
    {"bytes_needed", (PyCFunction)occluders_bytes_needed, METH_VARARGS | METH_STATIC,
     "bytes_needed(positions, triangles)\n--\n\nAbout how many bytes Occluders of that many positions and "
     "triangles take: what memory_budget_mb holds them to."},
    {"auto_resolution", (PyCFunction)occluders_auto_resolution, METH_O | METH_STATIC,
     "auto_resolution(count)\n--\n\nThe resolution occlusion(..., resolution='auto') casts `count` vertices at: the "
     "finest whose rays stay within 2^23."},
    {"ambient", (PyCFunction)(void (*)(void))occluders_ambient, METH_VARARGS | METH_KEYWORDS,
     "ambient(points, normals, distance, rays, inside=False, progress=None)\n--\n\nThe Ambient Occlusion node's "
     "share at each point (float32 (n,)), as Cycles' converges to it: of `rays` cosine-weighted rays about its "
     "normal (the opposite one with `inside`), a stratified set turned by a hash of the point's index, those that "
     "run `distance` without meeting these triangles; 1 everywhere for a distance of 0 or less.  points, normals: "
     "float32 (n, 3).  rays: 1 to 1024.  progress(fraction) may return True to cancel."},
    {"bevel", (PyCFunction)(void (*)(void))occluders_bevel, METH_VARARGS | METH_KEYWORDS,
     "bevel(points, corner_normals, radius, progress=None)\n--\n\nThe Bevel node's normal at each point (float32 "
     "(n, 3)), as Cycles' converges to it: the mean of the smooth normals of these triangles (an object's own) "
     "within `radius` of the point, weighted over their area by Cycles' falloff (radius - r)^3; (0, 0, 0) where "
     "none lies within it.  radius: one for every point (positive), or float32 (n,), each point's (0 or less "
     "reads nothing, as Cycles').  corner_normals: float32 (3 m, 3), each triangle's three smooth normals in the "
     "Occluders' order.  progress(fraction) may return True to cancel."},
    {"occluded", (PyCFunction)(void (*)(void))occluders_occluded, METH_VARARGS | METH_KEYWORDS,
     "occluded(origins, directions, tfar=inf)\n--\n\nWhether anything blocks each ray (bool, n): origins float32 "
     "(n, 3) or one (3,), directions float32 (n, 3) (normalised here), up to distance tfar."},
    {"occlusion", (PyCFunction)(void (*)(void))occluders_occlusion, METH_VARARGS | METH_KEYWORDS,
     "occlusion(positions, normals, resolution=8, progress=None, previous=None, changed=None, *, point_rays=False, "
     "masks_from=None)"
     "\n--\n\nWhich directions of each vertex's hemisphere the scene blocks, as a wenv.Occlusion: a ray from the "
     "vertex (lifted off the surface by Occluders.offset) through the centre of each texel of a resolution x "
     "resolution hemi-octahedral map in the vertex's frame (resolution 4 to 16, or 'auto': the finest whose rays, "
     "vertices x resolution^2, stay within 2^23, about 1.2 s on 2 cores).  point_rays=True: shading casts a ray "
     "along every point-like direction it reads (an exact light's, nine about a narrow lobe's mirror direction) "
     "at every vertex, rather than trusting the mask where its texels about the direction agree (what coarse masks miss "
     "between their rays).  masks_from (with point_rays; integer array, one per vertex): vertex i reads the mask of "
     "vertex masks_from[i] (one that reads its own), whose rays alone are cast, keeping its own position and normal "
     "for its point rays (a bake's neighbouring texels).  progress(fraction) may return True to cancel.\n\n"
     "After a change (an object moved, "
     "deformed, edited or removed), previous (the occlusion of the same positions and normals before) and "
     "changed=(first, count) (the triangles of previous's occluders that changed, every other one here in the same order, the new ones in their place) cast only the vertices whose "
     "rays met the changed triangles or meet them now; the result is what a new cast gives, and cast_vertices "
     "says how many were cast."},
    {NULL, NULL, 0, NULL},
};

static PyGetSetDef occluders_getset[] = {
    {"triangles", (getter)occluders_triangles, NULL, "Number of triangles.", NULL},
    {"size", (getter)occluders_size, NULL, "Diagonal of the scene's bounding box.", NULL},
    {"offset", (getter)occluders_offset, NULL,
     "How far rays start off a surface, along its normal: 1e-4 of the size rounded up to a power of two.", NULL},
    {NULL, NULL, NULL, NULL, NULL},
};

static PyTypeObject OccludersType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "wenv.Occluders",
    .tp_basicsize = sizeof(OccludersObject),
    .tp_dealloc = (destructor)occluders_dealloc,
    .tp_flags = Py_TPFLAGS_DEFAULT,
    .tp_doc = "Occluders(positions, triangles, memory_budget_mb=1024)\n--\n\nWhat stands between surfaces and "
              "their sky: triangles (an integer array (m, 3) indexing positions, float32 (n, 3), world space) in "
              "an Embree scene.  A position not finite, an index past the positions or a triangle of zero area is "
              "a ValueError naming it; so is a scene estimated to need more than memory_budget_mb.  Immutable.",
    .tp_new = PyType_GenericNew,
    .tp_init = (initproc)occluders_init,
    .tp_methods = occluders_methods,
    .tp_getset = occluders_getset,
};

/* ---------------------------------------------------------------- wenv.Occlusion */

static void occlusion_dealloc(OcclusionObject *self)
{
    wenv_occlusion_free(&self->o);
    Py_XDECREF(self->occluders);
    Py_TYPE(self)->tp_free((PyObject *)self);
}

static PyObject *occlusion_visible(OcclusionObject *self, void *closure)
{
    (void)closure;
    size_t r = self->o.resolution, n = self->o.n_vertices;
    Py_ssize_t shape[3] = {(Py_ssize_t)n, (Py_ssize_t)r, (Py_ssize_t)r};
    void *data;
    PyObject *a = wenv_py_new_array(3, shape, "bool", &data);
    unsigned char *v = data;
    for (size_t i = 0; a && i < n; i++)
        for (size_t t = 0; t < r * r; t++)
            v[i * r * r + t] = (unsigned char)wenv_occlusion_visible(&self->o, i, t);
    return a;
}

/* Which triangle each texel's ray meets first: -1 where it reaches the sky. */
static PyObject *occlusion_triangles(OcclusionObject *self, void *closure)
{
    (void)closure;
    const wenv_occlusion *o = &self->o;
    size_t r = o->resolution, n = o->n_vertices, texels = r * r;
    Py_ssize_t shape[3] = {(Py_ssize_t)n, (Py_ssize_t)r, (Py_ssize_t)r};
    void *data;
    PyObject *a = wenv_py_new_array(3, shape, "int64", &data);
    int64_t *tri = data;
    for (size_t i = 0; a && i < n; i++) {
        const wenv_occlusion_hit *h = o->slot[i] >= 0 ? o->hits + o->hit_start[o->slot[i]] : NULL;
        for (size_t t = 0; t < texels; t++)
            tri[i * texels + t] = wenv_occlusion_visible(o, i, t) ? -1 : (int64_t)(h++)->triangle;
    }
    return a;
}

/* Every hit, in the order bounce_hits takes them: whose, where to, and what it meets. */
static PyObject *occlusion_hits(OcclusionObject *self, void *closure)
{
    (void)closure;
    const wenv_occlusion *o = &self->o;
    size_t h = wenv_occlusion_hit_count(o);
    Py_ssize_t one[1] = {(Py_ssize_t)h}, three[2] = {(Py_ssize_t)h, 3};
    void *vertex_data, *direction_data, *triangle_data, *weights_data;
    PyObject *vertex = wenv_py_new_array(1, one, "int64", &vertex_data);
    PyObject *direction = vertex ? wenv_py_new_array(2, three, "float32", &direction_data) : NULL;
    PyObject *triangle = direction ? wenv_py_new_array(1, one, "int64", &triangle_data) : NULL;
    PyObject *weights = triangle ? wenv_py_new_array(2, three, "float32", &weights_data) : NULL;
    uint32_t *whose = weights ? PyMem_Malloc((h ? h : 1) * sizeof *whose) : NULL;
    PyObject *out = whose ? PyDict_New() : NULL;
    if (weights && !whose)
        PyErr_NoMemory();
    if (out) {
        wenv_occlusion_hit_rays(o, whose, direction_data);
        for (size_t k = 0; k < h; k++) {
            ((int64_t *)vertex_data)[k] = whose[k];
            ((int64_t *)triangle_data)[k] = o->hits[k].triangle;
            wenv_occlusion_hit_weights(&o->hits[k], (float *)weights_data + 3 * k);
        }
        if (PyDict_SetItemString(out, "vertex", vertex) < 0 || PyDict_SetItemString(out, "direction", direction) < 0 ||
            PyDict_SetItemString(out, "triangle", triangle) < 0 || PyDict_SetItemString(out, "weights", weights) < 0)
            Py_CLEAR(out);
    }
    PyMem_Free(whose);
    Py_XDECREF(vertex);
    Py_XDECREF(direction);
    Py_XDECREF(triangle);
    Py_XDECREF(weights);
    return out;
}

/* Each vertex's visible share of its hemisphere, by solid angle. */
static PyObject *occlusion_open(OcclusionObject *self, void *closure)
{
    (void)closure;
    size_t r = self->o.resolution, n = self->o.n_vertices;
    Py_ssize_t shape[1] = {(Py_ssize_t)n};
    void *data;
    PyObject *a = wenv_py_new_array(1, shape, "float64", &data);
    if (!a)
        return NULL;
    double *open = data;
    for (size_t i = 0; i < n; i++) {
        double s = 0.0;
        for (size_t t = 0; t < r * r; t++)
            if (wenv_occlusion_visible(&self->o, i, t))
                s += wenv_hemi_texel_solid_angle(r, t % r, t / r);
        open[i] = s / (2.0 * M_PI);
    }
    return a;
}

static PyObject *occlusion_directions(OcclusionObject *self, void *closure)
{
    (void)closure;
    size_t r = self->o.resolution;
    Py_ssize_t shape[3] = {(Py_ssize_t)r, (Py_ssize_t)r, 3};
    void *data;
    PyObject *a = wenv_py_new_array(3, shape, "float64", &data);
    for (size_t t = 0; a && t < r * r; t++)
        wenv_occlusion_texel_direction(r, t, (double *)data + 3 * t);
    return a;
}

static PyObject *occlusion_size(OcclusionObject *self, void *closure)
{
    size_t which = (size_t)(uintptr_t)closure;
    const wenv_occlusion *o = &self->o;
    if (which == 5)
        return PyBool_FromLong(o->point_rays);
    size_t v = which == 0 ? o->resolution
                          : which == 1 ? o->n_vertices
                                       : which == 2 ? o->n_masks
                                                    : which == 3 ? wenv_occlusion_bytes(o)
                                                                 : o->cast_vertices;
    return PyLong_FromSize_t(v);
}

static PyGetSetDef occlusion_getset[] = {
    {"resolution", (getter)occlusion_size, NULL, "The maps' side.", (void *)0},
    {"vertices", (getter)occlusion_size, NULL, "Number of vertices.", (void *)1},
    {"blocked_vertices", (getter)occlusion_size, NULL,
     "Masks held: one per vertex some direction of whose hemisphere is blocked (with point_rays, one per vertex, or "
     "per vertex reading its own with masks_from).",
     (void *)2},
    {"nbytes", (getter)occlusion_size, NULL, "Bytes held.", (void *)3},
    {"cast_vertices", (getter)occlusion_size, NULL,
     "How many vertices' rays were cast to make it: all of them, unless made from a previous occlusion.", (void *)4},
    {"point_rays", (getter)occlusion_size, NULL,
     "Whether shading casts a ray along every point-like direction (exact lights, mirror directions) rather than "
     "reading the mask where it agrees; every vertex then holds a mask.", (void *)5},
    {"visible", (getter)occlusion_visible, NULL,
     "bool (n, resolution, resolution): texel (row, column) of a vertex's map reaches the sky.", NULL},
    {"triangles", (getter)occlusion_triangles, NULL,
     "int64 (n, resolution, resolution): the occluders' triangle each texel's ray meets first, -1 where it reaches "
     "the sky.", NULL},
    {"open_fraction", (getter)occlusion_open, NULL,
     "float64 (n,): each vertex's visible share of its hemisphere, by solid angle.", NULL},
    {"hits", (getter)occlusion_hits, NULL,
     "dict of every blocked texel's ray, in the order Shader.shade's bounce_hits takes them (vertex by vertex, "
     "texels in row-major order): 'vertex' int64 (h,) whose texel it is, 'direction' float32 (h, 3) its unit world "
     "direction, 'triangle' int64 (h,) the occluders' triangle it meets first, 'weights' float32 (h, 3) the hit's "
     "barycentric weights of that triangle's corners.", NULL},
    {"directions", (getter)occlusion_directions, NULL,
     "float64 (resolution, resolution, 3): each texel's direction in a vertex's frame (+Z the normal; the "
     "tangents of wenv's one frame).", NULL},
    {NULL, NULL, NULL, NULL, NULL},
};

/* A side of the sending maps: even, 2 .. WENV_SENDING_SIDE_MAX.  -1 with the error set. */
static int sending_side(size_t side)
{
    if (side < 2 || side > WENV_SENDING_SIDE_MAX || side % 2) {
        PyErr_Format(PyExc_ValueError, "a sending map's side must be even, 2 to %d, got %zu", WENV_SENDING_SIDE_MAX,
                     side);
        return -1;
    }
    return 0;
}

static PyObject *occlusion_sending_directions(OcclusionObject *self, PyObject *args, PyObject *kwargs)
{
    static char *kwlist[] = {"side", NULL};
    PyObject *side_obj;
    size_t side, n = self->o.n_vertices;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "O:sending_directions", kwlist, &side_obj) ||
        wenv_py_get_size(side_obj, "side", &side) < 0 || sending_side(side) < 0)
        return NULL;
    Py_ssize_t shape[3] = {(Py_ssize_t)(side * side), (Py_ssize_t)n, 3};
    float *out;
    PyObject *a = wenv_py_new_float_array(3, shape, &out);
    if (!a)
        return NULL;
    WENV_BEGIN_WORK
    wenv_sending_directions(self->o.normals, n, side, out);
    WENV_END_WORK
    return a;
}

static PyObject *occlusion_read_sent(OcclusionObject *self, PyObject *args, PyObject *kwargs)
{
    static char *kwlist[] = {"normals", "sent", NULL};
    PyObject *nobj, *sobj, *held = NULL;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "OO:read_sent", kwlist, &nobj, &sobj))
        return NULL;
    const wenv_occluders *occ = ((OccludersObject *)self->occluders)->occ;
    size_t nv = wenv_occluders_vertex_count(occ), rows;
    Py_buffer nb, sb;
    if (wenv_py_get_vec3_array(nobj, "normals", 1, &nb, &rows, NULL) < 0)
        return NULL;
    PyObject *result = NULL;
    float *unit = NULL;
    if (rows != nv) {
        PyErr_Format(PyExc_ValueError, "normals has %zu rows, one per occluder vertex (%zu)", rows, nv);
        PyBuffer_Release(&nb);
        return NULL;
    }
    if (wenv_py_get_typed_array(sobj, "sent", "float32", 0, &sb, &held) < 0) {
        PyBuffer_Release(&nb);
        return NULL;
    }
    size_t side = sb.ndim == 3 ? (size_t)lround(sqrt((double)sb.shape[1])) : 0;
    if (sb.ndim != 3 || (size_t)sb.shape[0] != nv || sb.shape[2] != 3 || side * side != (size_t)sb.shape[1]) {
        PyErr_Format(PyExc_ValueError, "sent must be (occluder vertices (%zu), side^2, 3): each vertex's map", nv);
        goto done;
    }
    if (sending_side(side) < 0)
        goto done;
    const float *s = sb.buf;
    for (size_t i = 0; i < nv * side * side * 3; i++)
        if (!(s[i] >= 0.0f) || isinf(s[i])) {
            PyErr_Format(PyExc_ValueError, "sent[%zu] is negative or not finite: it is light (radiance)",
                         i / (side * side * 3));
            goto done;
        }
    if (!(unit = PyMem_Malloc((nv ? nv : 1) * 3 * sizeof(float)))) {
        PyErr_NoMemory();
        goto done;
    }
    const float *m = nb.buf;
    for (size_t i = 0; i < nv; i++) { /* the frames of unit normals, as the maps were made in */
        float len = sqrtf(m[3 * i] * m[3 * i] + m[3 * i + 1] * m[3 * i + 1] + m[3 * i + 2] * m[3 * i + 2]);
        for (int k = 0; k < 3; k++)
            unit[3 * i + (size_t)k] = m[3 * i + (size_t)k] / len;
    }
    Py_ssize_t shape[2] = {(Py_ssize_t)wenv_occlusion_hit_count(&self->o), 3};
    float *out;
    if ((result = wenv_py_new_float_array(2, shape, &out))) {
        WENV_BEGIN_WORK
        wenv_sending_read(&self->o, occ, unit, s, side, out);
        WENV_END_WORK
    }
done:
    PyMem_Free(unit);
    wenv_py_release_array(&sb, &held);
    PyBuffer_Release(&nb);
    return result;
}

/* with_point_rays() -> wenv.Occlusion */
static PyObject *occlusion_with_point_rays(OcclusionObject *self, PyObject *unused)
{
    (void)unused;
    OcclusionObject *out = PyObject_New(OcclusionObject, &OcclusionType);
    if (!out)
        return NULL;
    memset(&out->o, 0, sizeof out->o);
    out->occluders = Py_NewRef(self->occluders);
    wenv_error err = {0};
    wenv_status st;
    WENV_BEGIN_WORK
    st = wenv_occlusion_with_point_rays(&out->o, &self->o, &err);
    WENV_END_WORK
    if (st) {
        Py_CLEAR(out);
        wenv_py_raise(&err);
    }
    return (PyObject *)out;
}

static PyMethodDef occlusion_methods[] = {
    {"with_point_rays", (PyCFunction)occlusion_with_point_rays, METH_NOARGS,
     "with_point_rays()\n--\n\nThis occlusion as if cast with point_rays=True (its masks and hits, every vertex "
     "holding a mask), casting no ray: cast_vertices is 0."},
    {"sending_directions", (PyCFunction)(void (*)(void))occlusion_sending_directions, METH_VARARGS | METH_KEYWORDS,
     "sending_directions(side)\n--\n\nfloat32 (side^2, n, 3): the unit world direction of each texel centre of a "
     "side x side hemi-octahedral map in each vertex's frame (its normal as the occlusion holds it), texel by texel "
     "(row-major): the views at which to shade the vertices for the maps read_sent reads."},
    {"read_sent", (PyCFunction)(void (*)(void))occlusion_read_sent, METH_VARARGS | METH_KEYWORDS,
     "read_sent(normals, sent)\n--\n\nfloat32 (h, 3), Shader.shade's bounce_hits: what reaches each hit (in the "
     "order of `hits`) from what it meets.  `sent` (occluder vertices, side^2, 3) holds the radiance each occluder "
     "vertex sends towards each texel of its map (sending_directions of an occlusion made for it: texel t of "
     "vertex v at sent[v, t]), `normals` (occluder vertices, 3) their normals (the maps' frames); each hit reads "
     "its triangle's corners' maps towards the ray's start, bilinearly, weighed by the hit's barycentric "
     "weights."},
    {NULL, NULL, 0, NULL},
};

static PyTypeObject OcclusionType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "wenv.Occlusion",
    .tp_basicsize = sizeof(OcclusionObject),
    .tp_dealloc = (destructor)occlusion_dealloc,
    .tp_flags = Py_TPFLAGS_DEFAULT,
    .tp_doc = "Which directions of each vertex's hemisphere a scene blocks (Occluders.occlusion makes it): one bit "
              "per texel of a hemi-octahedral map in the vertex's frame; a vertex that sees its whole hemisphere "
              "holds none.  Immutable.",
    .tp_getset = occlusion_getset,
    .tp_methods = occlusion_methods,
};

int wenv_register_occlusion(PyObject *module)
{
    if (PyType_Ready(&OccludersType) < 0 || PyType_Ready(&OcclusionType) < 0)
        return -1;
    PyTypeObject *types[] = {&OccludersType, &OcclusionType};
    const char *names[] = {"Occluders", "Occlusion"};
    for (int i = 0; i < 2; i++) {
        Py_INCREF(types[i]);
        if (PyModule_AddObject(module, names[i], (PyObject *)types[i]) < 0) {
            Py_DECREF(types[i]);
            return -1;
        }
    }
    return 0;
}
