/* wenv.Shader: one shading method (methods/method.h) held through the method interface, with its
 * environment and material.  This file checks arguments, converts arrays and dicts, and releases
 * the GIL around the work; which method, its presets, its cache and quality="auto"'s choice are the
 * core's. */
#include "python/module.h"

#include <math.h>
#include <string.h>

#include "auto/autoquality.h"
#include "base/fingerprint.h"
#include "methods/material_family.h"
#include "methods/method.h"
#include "methods/presets.h"
#include "methods/lighting_frame.h"
#include "methods/shade_budget.h"
#include "methods/visibility.h"
#include "python/bind_envmap.h"
#include "python/bind_material.h"
#include "python/bind_lamp.h"
#include "python/bind_occlusion.h"

typedef struct {
    PyObject_HEAD
    const wenv_method *method;
    void *state;   /* the method's, once made */
    void *quality; /* method->quality_size bytes */
    PyObject *environment, *material;
    wenv_lighting_frame frame; /* the latest environment against the one the method holds */
    PyObject *progress; /* owned, or NULL: reported to by precomputation, here and in set_* */
    int busy;
    int is_auto;
    wenv_auto_choice auto_choice;
    double target_error, memory_budget_mb;
    Py_ssize_t visible; /* vertices the last shade_mesh(cull=True) shaded; -1 if it shaded all */
    Py_ssize_t next_vertex; /* the first of them the last shade_mesh left unshaded (its budget); -1 before one */
    wenv_material_family *family; /* the latest Roughness and Metallic per vertex, kept for the next view */
    wenv_lamp_light *lamp_light;  /* the latest lamps' light at the latest vertices, kept for the next view */
} ShaderObject;

/* ---- quality dicts, read and written through the method's parameter table ---- */

static PyObject *quality_to_dict(const wenv_method *method, const void *quality)
{
    PyObject *d = PyDict_New();
    for (size_t k = 0; d && k < method->n_params; k++) {
        const wenv_param *p = &method->params[k];
        const char *field = (const char *)quality + p->offset;
        PyObject *v = p->type == WENV_PARAM_SIZE ? PyLong_FromSize_t(*(const size_t *)field)
                                                 : PyFloat_FromDouble(*(const double *)field);
        if (!v || PyDict_SetItemString(d, p->key, v) < 0)
            Py_CLEAR(d);
        Py_XDECREF(v);
    }
    return d;
}

static void preset_names_text(char *buf, size_t size, int with_auto)
{
    size_t used = 0;
    for (size_t i = 0; i < WENV_PRESET_COUNT && used < size; i++)
        used += (size_t)snprintf(buf + used, size - used, "'%s', ", WENV_PRESET_NAMES[i]);
    if (used < size)
        snprintf(buf + used, size - used, "%sor a dict", with_auto ? "'auto' " : "");
}

/* quality: a preset name, a dict of the method's keys (missing keys from "default") or NULL. */
static int parse_quality(const wenv_method *method, PyObject *obj, void *quality)
{
    memcpy(quality, method->presets[WENV_PRESET_DEFAULT], method->quality_size);
    if (obj && PyUnicode_Check(obj)) {
        const char *name = PyUnicode_AsUTF8(obj);
        if (!name)
            return -1;
        const void *preset = wenv_method_preset(method, name);
        if (!preset) {
            char names[128];
            preset_names_text(names, sizeof names, 1);
            PyErr_Format(PyExc_ValueError, "quality must be %s, got '%s'", names, name);
            return -1;
        }
        memcpy(quality, preset, method->quality_size);
    } else if (obj && !PyDict_Check(obj)) {
        PyErr_Format(PyExc_TypeError, "quality must be a preset name or a dict, got %.100s", Py_TYPE(obj)->tp_name);
        return -1;
    }
    PyObject *key, *value;
    Py_ssize_t pos = 0;
    while (obj && PyDict_Check(obj) && PyDict_Next(obj, &pos, &key, &value)) {
        const char *k = PyUnicode_Check(key) ? PyUnicode_AsUTF8(key) : NULL;
        if (!k) {
            PyErr_Clear();
            PyErr_SetString(PyExc_TypeError, "quality keys must be strings");
            return -1;
        }
        const wenv_param *p = NULL;
        for (size_t e = 0; !p && e < method->n_params; e++)
            if (strcmp(k, method->params[e].key) == 0)
                p = &method->params[e];
        if (!p) {
            char keys[256];
            size_t used = 0;
            for (size_t e = 0; e < method->n_params && used < sizeof keys; e++)
                used += (size_t)snprintf(keys + used, sizeof keys - used, "%s%s", e ? ", " : "", method->params[e].key);
            PyErr_Format(PyExc_ValueError, "quality key '%s' does not apply to method '%s' (use %s)", k, method->name,
                         keys);
            return -1;
        }
        char name[64];
        snprintf(name, sizeof name, "quality['%s']", k);
        char *field = (char *)quality + p->offset;
        int r = p->type == WENV_PARAM_SIZE ? wenv_py_get_size(value, name, (size_t *)field)
                                           : wenv_py_get_finite(value, name, (double *)field);
        if (r < 0)
            return -1;
    }
    wenv_error err = {0};
    if (method->check_quality(quality, &err)) {
        wenv_py_raise(&err);
        return -1;
    }
    return 0;
}

static const wenv_method *parse_method(const char *name)
{
    const wenv_method *method = wenv_method_named(name);
    if (!method) {
        char names[256];
        size_t used = 0, count = wenv_method_count();
        for (size_t i = 0; i < count && used < sizeof names; i++)
            used += (size_t)snprintf(names + used, sizeof names - used, "%s'%s'",
                                     i == 0 ? "" : i + 1 == count ? " or " : ", ", wenv_method_at(i)->name);
        PyErr_Format(PyExc_ValueError, "method must be %s, got '%s'", names, name);
    }
    return method;
}

/* cache_dir: None (the default folder), False (no cache) or a path. */
static int parse_cache(PyObject *obj, wenv_method_setup *setup, PyObject **bytes)
{
    *bytes = NULL;
    if (obj == Py_None) {
        setup->cache = WENV_CACHE_DEFAULT;
        return 0;
    }
    if (obj == Py_False) {
        setup->cache = WENV_CACHE_NONE;
        return 0;
    }
    if (!PyUnicode_FSConverter(obj, bytes))
        return -1;
    setup->cache = WENV_CACHE_FOLDER;
    setup->cache_dir = PyBytes_AS_STRING(*bytes);
    return 0;
}

/* ---- the shader ---- */

static int claim(ShaderObject *self)
{
    if (!self->state) {
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

/* set_environment (material = 0) or set_material (material = 1), GIL released, progress reported. */
static int do_set(ShaderObject *self, PyObject *obj, int material)
{
    const void *arg = material ? (const void *)wenv_py_material(obj, "material") : (const void *)wenv_py_envmap(obj, "env");
    if (!arg)
        return -1;
    wenv_py_progress_bridge bridge = {.callback = self->progress};
    wenv_progress progress = wenv_py_progress(&bridge);
    wenv_error err = {0};
    wenv_status st;
    WENV_BEGIN_WORK
    st = material ? self->method->set_material(self->state, arg, &progress, &err)
                  : wenv_lighting_frame_set(&self->frame, self->method, self->state, arg, &progress, &err);
    WENV_END_WORK
    if (st) {
        if (!(bridge.raised && PyErr_Occurred()))
            wenv_py_raise(&err);
        return -1;
    }
    Py_INCREF(obj);
    if (material)
        Py_XSETREF(self->material, obj);
    else
        Py_XSETREF(self->environment, obj);
    return 0;
}

/* quality="auto": the core chooses the method and its quality (auto/autoquality.h). */
static int choose_auto(ShaderObject *self, PyObject *env_obj, PyObject *mat_obj, PyObject *normals_obj)
{
    if (!(self->target_error > 0.0 && self->target_error <= 1.0)) {
        wenv_py_errorf(PyExc_ValueError, "target_error must be in (0, 1], got %g", self->target_error);
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
    WENV_BEGIN_WORK
    st = wenv_auto_choose(env, analysis, mat, self->target_error, budget, normals, n, &self->auto_choice, &err);
    WENV_END_WORK
    if (normals)
        PyBuffer_Release(&nb);
    if (st) {
        wenv_py_raise(&err);
        return -1;
    }
    self->is_auto = 1;
    return 0;
}

static int Shader_init(ShaderObject *self, PyObject *args, PyObject *kwargs)
{
    static char *kwlist[] = {"env", "material", "quality", "method", "cache_dir", "progress", "target_error",
                             "memory_budget_mb", "normals", NULL};
    PyObject *env_obj, *mat_obj, *quality_obj = NULL, *cache_obj = Py_None, *progress_obj = Py_None;
    PyObject *normals_obj = Py_None;
    const char *method_name = NULL;
    self->target_error = 0.01;
    self->memory_budget_mb = 1024.0;
    self->visible = -1;
    self->next_vertex = -1;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "OO|OzOOddO:Shader", kwlist, &env_obj, &mat_obj, &quality_obj,
                                     &method_name, &cache_obj, &progress_obj, &self->target_error,
                                     &self->memory_budget_mb, &normals_obj))
        return -1;
    if (self->state) {
        PyErr_SetString(PyExc_RuntimeError, "Shader is already initialised");
        return -1;
    }
    if (!(self->memory_budget_mb > 0.0 && self->memory_budget_mb < 1e9)) {
        wenv_py_errorf(PyExc_ValueError, "memory_budget_mb must be positive, got %g", self->memory_budget_mb);
        return -1;
    }
    if (!wenv_py_envmap(env_obj, "env") || !wenv_py_material(mat_obj, "material"))
        return -1;
    int is_auto = quality_obj && PyUnicode_Check(quality_obj) && PyUnicode_CompareWithASCIIString(quality_obj, "auto") == 0;
    if (is_auto && method_name && strcmp(method_name, WENV_METHOD_SLICING.name) != 0) {
        PyErr_Format(PyExc_ValueError, "quality='auto' chooses the method itself; leave method unset (got '%s')",
                     method_name);
        return -1;
    }
    if (normals_obj != Py_None && !is_auto) {
        PyErr_SetString(PyExc_ValueError, "normals are only used by quality='auto' (to count the normal samples a "
                                          "mesh needs)");
        return -1;
    }
    const wenv_method *method = method_name ? parse_method(method_name) : wenv_method_default();
    if (!method)
        return -1;
    if (is_auto) {
        if (choose_auto(self, env_obj, mat_obj, normals_obj) < 0)
            return -1;
        method = self->auto_choice.method;
    }
    PyMem_Free(self->quality);
    self->quality = PyMem_Malloc(method->quality_size);
    if (!self->quality) {
        PyErr_NoMemory();
        return -1;
    }
    self->method = method;
    if (is_auto)
        memcpy(self->quality, wenv_auto_choice_quality(&self->auto_choice), method->quality_size);
    else if (parse_quality(method, quality_obj, self->quality) < 0)
        return -1;
    if (wenv_py_check_progress(progress_obj) < 0)
        return -1;
    Py_XSETREF(self->progress, progress_obj == Py_None ? NULL : Py_NewRef(progress_obj));
    wenv_method_setup setup = {0};
    PyObject *cache_bytes;
    if (parse_cache(cache_obj, &setup, &cache_bytes) < 0)
        return -1;
    wenv_py_progress_bridge bridge = {.callback = self->progress};
    wenv_progress progress = wenv_py_progress(&bridge);
    setup.progress = &progress;
    setup.memory_budget = (size_t)(self->memory_budget_mb * 1048576.0);
    wenv_error err = {0};
    wenv_status st;
    void *state = NULL;
    WENV_BEGIN_WORK
    if (!method_name && !is_auto) /* reads the cache folder, may build a few sample matrices */
        self->method = method = wenv_method_choose_default(self->quality, &setup);
    st = method->create(&state, self->quality, &setup, &err);
    WENV_END_WORK
    Py_XDECREF(cache_bytes);
    if (st) {
        if (!(bridge.raised && PyErr_Occurred()))
            wenv_py_raise(&err);
        return -1;
    }
    self->state = state;
    memset(&self->frame, 0, sizeof self->frame);
    return do_set(self, env_obj, 0) < 0 || do_set(self, mat_obj, 1) < 0 ? -1 : 0;
}

static void Shader_dealloc(ShaderObject *self)
{
    if (self->state)
        self->method->destroy(self->state);
    wenv_material_family_free(self->family);
    wenv_lamp_light_free(self->lamp_light);
    PyMem_Free(self->quality);
    Py_XDECREF(self->environment);
    Py_XDECREF(self->material);
    Py_XDECREF(self->progress);
    Py_TYPE(self)->tp_free((PyObject *)self);
}

/* The light given as reaching the blocked texels: per hit of the occlusion (n_hits rows, hit order),
 * not negative, into hb.  -1 with the error set. */
static int parse_bounce_hits(PyObject *obj, const wenv_occlusion *o, Py_buffer *hb)
{
    size_t rows, hits = o->n_masks ? o->hit_start[o->n_masks] : 0;
    if (wenv_py_get_vec3_array(obj, "bounce_hits", 0, hb, &rows, NULL) < 0)
        return -1;
    if (rows != hits) {
        PyErr_Format(PyExc_ValueError, "bounce_hits has %zu rows, one per hit of the occlusion (%zu: Occlusion.hits)",
                     rows, hits);
        return -1;
    }
    const float *b = hb->buf;
    for (size_t i = 0; i < 3 * rows; i++)
        if (!(b[i] >= 0.0f) || isinf(b[i])) {
            PyErr_Format(PyExc_ValueError, "bounce_hits[%zu] is negative or not finite: it is light (radiance)", i / 3);
            return -1;
        }
    return 0;
}

/* The scene of `occlusion` and `bounce` (NULL: not given, 'self') or `bounce_hits` (NULL or None: not
 * given) for n shaded vertices into *scene (their buffers in *bb, released by the caller when
 * bb->obj is set, and bb[1]).  -1 with the error set. */
static int parse_scene(ShaderObject *self, PyObject *occlusion, PyObject *bounce, PyObject *bounce_hits, size_t n,
                       wenv_shadow_scene *scene, Py_buffer bb[2])
{
    memset(scene, 0, sizeof *scene);
    if (!self->method->shade_shadowed) {
        PyErr_Format(PyExc_ValueError,
                     "method '%s' shades without shadows: occlusion is for the wavelet methods (rotation, slicing)",
                     self->method->name);
        return -1;
    }
    if (wenv_py_occlusion(occlusion, "occlusion", &scene->occlusion, &scene->occluders) < 0)
        return -1;
    if (scene->occlusion->n_vertices != n) {
        PyErr_Format(PyExc_ValueError, "occlusion was made for %zu vertices, shading %zu", scene->occlusion->n_vertices,
                     n);
        return -1;
    }
    uint64_t key = wenv_fingerprint_word(WENV_FINGERPRINT_START, scene->occlusion->fingerprint);
    size_t nv = wenv_occluders_vertex_count(scene->occluders);
    if (bounce_hits && bounce_hits != Py_None) {
        if (bounce && bounce != Py_None) {
            PyErr_SetString(PyExc_ValueError, "give bounce (per occluder vertex) or bounce_hits (per hit), not both");
            return -1;
        }
        if (parse_bounce_hits(bounce_hits, scene->occlusion, &bb[1]) < 0)
            return -1;
        scene->bounce_hits = bb[1].buf;
        size_t hits = scene->occlusion->n_masks ? scene->occlusion->hit_start[scene->occlusion->n_masks] : 0;
        key = wenv_fingerprint_floats(wenv_fingerprint_word(key, 4), scene->bounce_hits, 3 * hits);
    } else if (!bounce || (PyUnicode_Check(bounce) && PyUnicode_CompareWithASCIIString(bounce, "self") == 0)) {
        if (nv != n) {
            PyErr_Format(PyExc_ValueError,
                         "bounce='self' reads the shaded mesh's own light, but the occluders have %zu vertices and "
                         "%zu are shaded: give bounce as each occluder vertex's light (Shader.diffuse_light), or "
                         "None",
                         nv, n);
            return -1;
        }
        scene->bounce_self = 1;
        key = wenv_fingerprint_word(key, 1);
    } else if (bounce != Py_None) {
        size_t rows;
        if (wenv_py_get_vec3_array(bounce, "bounce", 0, &bb[0], &rows, NULL) < 0)
            return -1;
        if (rows != nv) {
            PyErr_Format(PyExc_ValueError, "bounce has %zu rows, one per occluder vertex (%zu)", rows, nv);
            return -1;
        }
        const float *b = bb[0].buf;
        for (size_t i = 0; i < 3 * rows; i++)
            if (b[i] < 0.0f) {
                PyErr_Format(PyExc_ValueError, "bounce[%zu] is negative: it is light (radiance)", i / 3);
                return -1;
            }
        scene->bounce = b;
        key = wenv_fingerprint_floats(wenv_fingerprint_word(key, 2), b, 3 * rows);
    }
    scene->key = key;
    return 0;
}

/* The smooth normals (n rows; None: sb->obj NULL) the normals were bent from, into sb (released by
 * the caller).  -1 with the error set. */
static int parse_smooth(PyObject *smooth_obj, size_t n, Py_buffer *sb)
{
    sb->obj = NULL;
    if (!smooth_obj || smooth_obj == Py_None)
        return 0;
    size_t ns;
    if (wenv_py_get_vec3_array(smooth_obj, "smooth_normals", 1, sb, &ns, NULL) < 0) {
        sb->obj = NULL;
        return -1;
    }
    if (ns == n)
        return 0;
    PyErr_Format(PyExc_ValueError, "smooth_normals has %zu rows but normals has %zu", ns, n);
    PyBuffer_Release(sb);
    sb->obj = NULL;
    return -1;
}

/* A colour per vertex (base_color, n rows) for the shader's material, and the smooth normals the
 * normals were bent from (sb: parse_smooth's; correction: their Bump Map Correction), into *colour
 * (its table in *table, its rows in *rgb: wenv_py_base_colours, PyMem_Free'd by the caller).
 * Neither given: *rgb NULL and *colour unused (colour_of).  -1 with the error set. */
static int parse_colour(ShaderObject *self, PyObject *obj, size_t n, int per_vertex_material, const Py_buffer *sb,
                        int correction, wenv_diffuse_table *table, wenv_vertex_colour *colour, float **rgb)
{
    *rgb = NULL;
    *colour = (wenv_vertex_colour){table, NULL, {sb->obj ? sb->buf : NULL, correction}, NULL, NULL};
    int have_rgb = obj && obj != Py_None;
    if (!have_rgb && !sb->obj)
        return 0;
    wenv_error err = {0};
    /* with a material per vertex, its members' tables are read (material_family.h); without a colour
     * the part is the material's own, its colour in */
    if (per_vertex_material || !have_rgb)
        wenv_material_diffuse_table(wenv_py_material(self->material, "material"), table);
    else if (wenv_material_diffuse_per_colour_table(wenv_py_material(self->material, "material"), table, &err)) {
        wenv_py_raise(&err);
        return -1;
    }
    if (have_rgb && !(*rgb = wenv_py_base_colours(obj, n)))
        return -1;
    colour->rgb = *rgb;
    return 0;
}

/* The colour parse_colour read, or NULL when neither a colour nor smooth normals were given. */
static const wenv_vertex_colour *colour_of(const wenv_vertex_colour *colour)
{
    return colour->rgb || colour->bump.smooth ? colour : NULL;
}

/* Whether the shader's material shades as a family (material_family.h) with these per-vertex
 * inputs: any of WENV_VERTEX_INPUTS per vertex, or a colour per vertex on a metal. */
static int per_vertex_material(ShaderObject *self, PyObject *colour, const wenv_py_vertex_inputs *vin)
{
    return wenv_py_vertex_inputs_given(vin) ||
           (colour && colour != Py_None &&
            wenv_material_family_needed_for_colour(wenv_py_material(self->material, "material")));
}

/* The inputs per vertex for n vertices, and whether a colour per vertex is given: the shader's family
 * made for them, unless it was, into *rows (NULL when no family is needed: per_vertex_material).
 * Called with the shader claimed.  -1 with the error set. */
static int ensure_family(ShaderObject *self, PyObject *colour, wenv_py_vertex_inputs *vin, size_t n,
                         wenv_family_rows *rows, const wenv_family_rows **out)
{
    *out = NULL;
    if (!per_vertex_material(self, colour, vin))
        return 0;
    wenv_vertex_inputs vi;
    if (wenv_py_vertex_inputs_read(vin, n, &vi) < 0)
        return -1;
    wenv_error err = {0};
    wenv_status st;
    const struct wenv_material *base = wenv_py_material(self->material, "material");
    WENV_BEGIN_WORK
    /* the members must fit among the materials the method keeps (it refuses the family if it keeps none) */
    size_t kept = self->method->materials_kept ? self->method->materials_kept(self->state) : 0;
    size_t room = kept > WENV_FAMILY_SPARE_KEPT ? kept - WENV_FAMILY_SPARE_KEPT : 1;
    st = wenv_material_family_ensure(&self->family, base, &vi, n, colour && colour != Py_None, room, &err);
    WENV_END_WORK
    if (st) {
        wenv_py_raise(&err);
        return -1;
    }
    *rows = (wenv_family_rows){self->family, NULL, 0};
    *out = rows;
    return 0;
}

/* The lamps (a sequence of wenv.Lamp; NULL or None: none) at n vertices (positions: NULL when not
 * given): the shader's lamps' light made for them, unless it was, shadowed by the scene's occluders
 * when scene is set, into *rows (*out NULL without lamps).  Called with the shader claimed; the
 * shadows' rays report to the shader's progress.  -1 with the error set. */
static int ensure_lamps(ShaderObject *self, PyObject *lamps_obj, const float *positions, const float *normals,
                        size_t n, const wenv_shadow_scene *scene, wenv_lamp_rows *rows, const wenv_lamp_rows **out)
{
    *out = NULL;
    wenv_lamp *lamps;
    size_t n_lamps;
    if (wenv_py_lamps(lamps_obj, "lamps", &lamps, &n_lamps) < 0)
        return -1;
    if (!lamps_obj || lamps_obj == Py_None)
        return 0;
    if (!positions) {
        PyMem_Free(lamps);
        PyErr_SetString(PyExc_ValueError, "lamps need the vertices' positions (positions=)");
        return -1;
    }
    wenv_py_progress_bridge bridge = {.callback = self->progress};
    wenv_progress progress = wenv_py_progress(&bridge);
    wenv_error err = {0};
    wenv_status st;
    WENV_BEGIN_WORK
    st = wenv_lamp_light_ensure(&self->lamp_light, lamps, n_lamps, positions, normals, n,
                                scene ? scene->occluders : NULL, &progress, &err);
    WENV_END_WORK
    PyMem_Free(lamps);
    if (st) {
        if (!(bridge.raised && PyErr_Occurred()))
            wenv_py_raise(&err);
        return -1;
    }
    *rows = (wenv_lamp_rows){self->lamp_light, NULL, 0};
    *out = rows;
    return 0;
}

/* With a colour or material per vertex, or a material that emits, a mesh's own bounce
 * (bounce='self') is its light with those colours and materials, its emission included: it is made
 * here, for every vertex of the occlusion (normals: all n of them), and given as the scene's
 * bounce (*light, PyMem_Free'd by the caller).  -1 with the error set. */
static int own_bounce(ShaderObject *self, const float *normals, size_t n, wenv_shadow_scene *scene,
                      const wenv_vertex_colour *colour, const wenv_family_rows *family, const float *emission,
                      const wenv_lamp_rows *lamps, float **light)
{
    *light = NULL;
    /* a material that emits sends its own light too, and lamps theirs, which the method's own bounce
     * leaves out */
    if ((!colour && !family && !lamps && !emission &&
         !wenv_material_emits(wenv_py_material(self->material, "material"))) ||
        !scene->bounce_self)
        return 0;
    if (!(*light = PyMem_Malloc((n ? n : 1) * 3 * sizeof(float)))) {
        PyErr_NoMemory();
        return -1;
    }
    wenv_shadow_scene sending = *scene;
    sending.bounce_self = 0;
    wenv_error err = {0};
    wenv_status st;
    WENV_BEGIN_WORK
    st = wenv_lighting_frame_shade_scene(&self->frame, self->method, self->state, normals, NULL, n, &sending, colour,
                                         family, wenv_py_material(self->material, "material"), emission, lamps, *light,
                                         &err);
    WENV_END_WORK
    if (st) {
        wenv_py_raise(&err);
        return -1;
    }
    scene->bounce_self = 0;
    scene->bounce = *light;
    scene->key = wenv_fingerprint_floats(wenv_fingerprint_word(scene->key, 3), *light, 3 * n);
    return 0;
}

/* views NULL: the diffuse light leaving each vertex; scene NULL: unshadowed; colour NULL: the
 * material's own. */
static PyObject *shade_arrays(ShaderObject *self, const float *normals, const float *views, size_t n,
                              const wenv_shadow_scene *scene, const wenv_vertex_colour *colour,
                              const wenv_family_rows *family, const float *emission, const wenv_lamp_rows *lamps)
{
    Py_ssize_t shape[2] = {(Py_ssize_t)n, 3};
    float *out;
    PyObject *result = wenv_py_new_float_array(2, shape, &out);
    if (!result || n == 0)
        return result;
    wenv_error err = {0};
    wenv_status st;
    WENV_BEGIN_WORK
    st = wenv_lighting_frame_shade_scene(&self->frame, self->method, self->state, normals, views, n, scene, colour,
                                         family, wenv_py_material(self->material, "material"), emission, lamps, out,
                                         &err);
    WENV_END_WORK
    if (st) {
        Py_DECREF(result);
        return wenv_py_raise(&err);
    }
    return result;
}

/* positions (n rows of xyz floats) for the lamps, into pb (released by the caller).  -1 with the
 * error set. */
static int positions_for(PyObject *obj, size_t n, Py_buffer *pb)
{
    size_t np;
    if (wenv_py_get_vec3_array(obj, "positions", 0, pb, &np, NULL) < 0)
        return -1;
    if (np != n) {
        PyErr_Format(PyExc_ValueError, "positions has %zu rows but normals has %zu", np, n);
        PyBuffer_Release(pb);
        pb->obj = NULL;
        return -1;
    }
    return 0;
}

static PyObject *shade_with(ShaderObject *self, PyObject *args, PyObject *kwargs, wenv_py_vertex_inputs *vin)
{
    static char *kwlist[] = {"normals",   "view_dirs", "occlusion",      "bounce",         "base_color",
                             "positions", "lamps",     "emission_color", "smooth_normals", "bump_map_correction",
                             "bounce_hits", NULL};
    PyObject *nobj, *vobj, *occ_obj = Py_None, *bounce_obj = NULL, *colour_obj = NULL, *hits_obj = NULL;
    PyObject *pos_obj = Py_None, *lamps_obj = Py_None, *emit_obj = Py_None, *smooth_obj = Py_None;
    int correction = 1;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "OO|$OOOOOOOO&O:shade", kwlist, &nobj, &vobj, &occ_obj, &bounce_obj,
                                     &colour_obj, &pos_obj, &lamps_obj, &emit_obj, &smooth_obj,
                                     wenv_py_bump_correction, &correction, &hits_obj))
        return NULL;
    Py_buffer nb, vb, bb[2] = {{0}, {0}}, pb = {0};
    size_t n, nvw;
    int single_n, single_v;
    if (wenv_py_get_vec3_array(nobj, "normals", 1, &nb, &n, &single_n) < 0)
        return NULL;
    if (wenv_py_get_vec3_array(vobj, "view_dirs", 1, &vb, &nvw, &single_v) < 0) {
        PyBuffer_Release(&nb);
        return NULL;
    }
    PyObject *result = NULL;
    float *expanded = NULL, *rgb = NULL, *light = NULL, *emission = NULL;
    Py_buffer sb = {0};
    const float *views = vb.buf;
    wenv_shadow_scene scene;
    wenv_diffuse_table table;
    wenv_vertex_colour colour;
    wenv_family_rows family_rows;
    const wenv_family_rows *family = NULL;
    wenv_lamp_rows lamp_rows;
    const wenv_lamp_rows *lamps = NULL;
    int claimed = 0;
    if (pos_obj != Py_None && positions_for(pos_obj, n, &pb) < 0)
        goto done;
    if (emit_obj != Py_None && !(emission = wenv_py_vertex_colours(emit_obj, "emission_color", n, 0)))
        goto done;
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
    if (occ_obj == Py_None && (bounce_obj || (hits_obj && hits_obj != Py_None))) {
        PyErr_SetString(PyExc_ValueError, "bounce is read only with occlusion (what blocks the light it fills in)");
        goto done;
    }
    if (occ_obj != Py_None && parse_scene(self, occ_obj, bounce_obj, hits_obj, n, &scene, bb) < 0)
        goto done;
    if (parse_smooth(smooth_obj, n, &sb) < 0 ||
        parse_colour(self, colour_obj, n, per_vertex_material(self, colour_obj, vin), &sb, correction, &table,
                     &colour, &rgb) < 0 ||
        claim(self) < 0)
        goto done;
    claimed = 1;
    if (ensure_family(self, colour_obj, vin, n, &family_rows, &family) < 0 ||
        ensure_lamps(self, lamps_obj, pb.obj ? pb.buf : NULL, nb.buf, n, occ_obj != Py_None ? &scene : NULL,
                     &lamp_rows, &lamps) < 0)
        goto done;
    if (occ_obj == Py_None ||
        own_bounce(self, nb.buf, n, &scene, colour_of(&colour), family, emission, lamps, &light) == 0)
        result = shade_arrays(self, nb.buf, views, n, occ_obj != Py_None ? &scene : NULL, colour_of(&colour), family,
                              emission, lamps);
done:
    if (claimed)
        self->busy = 0;
    if (pb.obj)
        PyBuffer_Release(&pb);
    PyMem_Free(emission);
    PyMem_Free(expanded);
    PyMem_Free(rgb);
    if (sb.obj)
        PyBuffer_Release(&sb);
    PyMem_Free(light);
    for (int k = 0; k < 2; k++)
        if (bb[k].obj)
            PyBuffer_Release(&bb[k]);
    PyBuffer_Release(&nb);
    PyBuffer_Release(&vb);
    return result;
}

static PyObject *diffuse_light_with(ShaderObject *self, PyObject *args, PyObject *kwargs,
                                    wenv_py_vertex_inputs *vin)
{
    static char *kwlist[] = {"normals", "occlusion",      "base_color",          "positions", "lamps",
                             "emission_color", "smooth_normals", "bump_map_correction", NULL};
    PyObject *nobj, *occ_obj = Py_None, *colour_obj = NULL;
    PyObject *pos_obj = Py_None, *lamps_obj = Py_None, *emit_obj = Py_None, *smooth_obj = Py_None;
    int correction = 1;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "O|$OOOOOOO&:diffuse_light", kwlist, &nobj, &occ_obj, &colour_obj,
                                     &pos_obj, &lamps_obj, &emit_obj, &smooth_obj, wenv_py_bump_correction,
                                     &correction))
        return NULL;
    if (!self->method->diffuse_light) {
        PyErr_Format(PyExc_ValueError, "method '%s' does not give the diffuse light: use a wavelet method",
                     self->method->name);
        return NULL;
    }
    Py_buffer nb, bb[2] = {{0}, {0}}, pb = {0};
    size_t n;
    if (wenv_py_get_vec3_array(nobj, "normals", 1, &nb, &n, NULL) < 0)
        return NULL;
    PyObject *result = NULL;
    wenv_shadow_scene scene;
    wenv_diffuse_table table;
    wenv_vertex_colour colour;
    float *rgb = NULL, *emission = NULL;
    Py_buffer sb = {0};
    wenv_family_rows family_rows;
    const wenv_family_rows *family = NULL;
    wenv_lamp_rows lamp_rows;
    const wenv_lamp_rows *lamps = NULL;
    int claimed = 0;
    if (pos_obj != Py_None && positions_for(pos_obj, n, &pb) < 0)
        goto done;
    if (emit_obj != Py_None && !(emission = wenv_py_vertex_colours(emit_obj, "emission_color", n, 0)))
        goto done;
    if (occ_obj != Py_None && parse_scene(self, occ_obj, Py_None, NULL, n, &scene, bb) < 0)
        goto done;
    if (parse_smooth(smooth_obj, n, &sb) < 0 ||
        parse_colour(self, colour_obj, n, per_vertex_material(self, colour_obj, vin), &sb, correction, &table,
                     &colour, &rgb) < 0 ||
        claim(self) < 0)
        goto done;
    claimed = 1;
    if (ensure_family(self, colour_obj, vin, n, &family_rows, &family) == 0 &&
        ensure_lamps(self, lamps_obj, pb.obj ? pb.buf : NULL, nb.buf, n, occ_obj != Py_None ? &scene : NULL,
                     &lamp_rows, &lamps) == 0)
        result = shade_arrays(self, nb.buf, NULL, n, occ_obj != Py_None ? &scene : NULL, colour_of(&colour), family,
                              emission, lamps);
done:
    if (claimed)
        self->busy = 0;
    if (pb.obj)
        PyBuffer_Release(&pb);
    PyMem_Free(emission);
    PyMem_Free(rgb);
    if (sb.obj)
        PyBuffer_Release(&sb);
    PyBuffer_Release(&nb);
    return result;
}

/* eye: a sequence of 3 finite numbers. */
static int parse_eye(PyObject *obj, double eye[3])
{
    PyObject *seq = PySequence_Fast(obj, "eye must be a sequence of 3 numbers");
    if (!seq)
        return -1;
    if (PySequence_Fast_GET_SIZE(seq) != 3) {
        Py_DECREF(seq);
        PyErr_SetString(PyExc_ValueError, "eye must have 3 components");
        return -1;
    }
    for (int c = 0; c < 3; c++)
        if (wenv_py_get_finite(PySequence_Fast_GET_ITEM(seq, c), "eye", &eye[c]) < 0) {
            Py_DECREF(seq);
            return -1;
        }
    Py_DECREF(seq);
    return 0;
}

/* Shades the `count` vertices whose visible[i] is set (all if visible is NULL) into their rows of
 * out (n x 3); the other rows are left as they are. */
/* Shades the vertices to shade (the `count` visible ones, or all n) from the first-th of them on, within
 * `budget` seconds (wenv_shade_for); *next gets the first left. */
static int shade_visible(ShaderObject *self, const float *normals, const float *views, size_t n,
                         const unsigned char *visible, size_t count, const wenv_shadow_scene *scene,
                         const wenv_vertex_colour *colour, const wenv_family_rows *family, const float *emission,
                         const wenv_lamp_rows *lamps, size_t first, double budget, float *out, size_t *next)
{
    float *gathered = NULL, *shaded = out;
    uint32_t *rows = NULL;
    wenv_shadow_scene culled;
    wenv_vertex_colour culled_colour;
    wenv_family_rows culled_family;
    wenv_lamp_rows culled_lamps;
    if (visible) {
        /* normals, views, radiance, colours, emission colours and smooth normals */
        gathered = PyMem_Malloc((count ? count : 1) * 18 * sizeof(float));
        rows = scene || family || lamps ? PyMem_Malloc((count ? count : 1) * sizeof *rows) : NULL;
        if (!gathered || ((scene || family || lamps) && !rows)) {
            PyMem_Free(gathered);
            PyMem_Free(rows);
            PyErr_NoMemory();
            return -1;
        }
        for (size_t i = 0, k = 0; i < n; i++)
            if (visible[i]) {
                memcpy(gathered + 3 * k, normals + 3 * i, 3 * sizeof(float));
                memcpy(gathered + 3 * (count + k), views + 3 * i, 3 * sizeof(float));
                if (colour && colour->rgb)
                    memcpy(gathered + 3 * (3 * count + k), colour->rgb + 3 * i, 3 * sizeof(float));
                if (colour && colour->bump.smooth)
                    memcpy(gathered + 3 * (5 * count + k), colour->bump.smooth + 3 * i, 3 * sizeof(float));
                if (emission)
                    memcpy(gathered + 3 * (4 * count + k), emission + 3 * i, 3 * sizeof(float));
                if (rows)
                    rows[k] = (uint32_t)i;
                k++;
            }
        if (scene) { /* the gathered rows are these vertices of the occlusion */
            culled = *scene;
            culled.rows = rows;
            scene = &culled;
        }
        if (colour) {
            culled_colour = *colour;
            culled_colour.rgb = colour->rgb ? gathered + 9 * count : NULL;
            culled_colour.bump.smooth = colour->bump.smooth ? gathered + 15 * count : NULL;
            colour = &culled_colour;
        }
        if (family) { /* and of the family */
            culled_family = (wenv_family_rows){family->family, rows, 0};
            family = &culled_family;
        }
        if (lamps) { /* and of the lamps' light */
            culled_lamps = (wenv_lamp_rows){lamps->light, rows, 0};
            lamps = &culled_lamps;
        }
        normals = gathered;
        views = gathered + 3 * count;
        shaded = gathered + 6 * count;
        if (emission)
            emission = gathered + 12 * count;
    }
    wenv_error err = {0};
    wenv_status st = WENV_OK;
    *next = first;
    if (first < count) {
        WENV_BEGIN_WORK
        st = wenv_shade_for(&self->frame, self->method, self->state, normals, views, count, scene, colour, family,
                            wenv_py_material(self->material, "material"), emission, lamps, first, budget, shaded,
                            next, &err);
        WENV_END_WORK
    }
    if (!st && visible)
        for (size_t i = 0, k = 0; i < n && k < *next; i++)
            if (visible[i]) {
                if (k >= first)
                    memcpy(out + 3 * i, shaded + 3 * k, 3 * sizeof(float));
                k++;
            }
    PyMem_Free(gathered);
    PyMem_Free(rows);
    if (st) {
        wenv_py_raise(&err);
        return -1;
    }
    return 0;
}

/* wenv.EyeAtVertexError for the `count` positions (n of them) at the eye, with their indices as
 * `vertices` (int64), so a caller can leave them black and shade the rest. */
static void raise_eye_at_vertex(const float *p, const double eye[3], size_t n, size_t count)
{
    Py_ssize_t shape[1] = {(Py_ssize_t)count};
    void *data;
    PyObject *index = wenv_py_new_array(1, shape, "int64", &data);
    if (!index)
        return;
    int64_t *ix = data;
    size_t k = 0;
    for (size_t i = 0; i < n && k < count; i++) {
        double d[3] = {eye[0] - p[3 * i], eye[1] - p[3 * i + 1], eye[2] - p[3 * i + 2]};
        if (d[0] * d[0] + d[1] * d[1] + d[2] * d[2] < 1e-24)
            ix[k++] = (int64_t)i;
    }
    PyObject *type = wenv_py_eye_at_vertex_error();
    PyObject *exc = PyObject_CallFunction(type, "N",
                                          PyUnicode_FromFormat("eye coincides with positions[%zd]%s: a vertex at the "
                                                               "eye has no view direction (the exception's "
                                                               "`vertices` lists all %zu)",
                                                               (Py_ssize_t)ix[0], count > 1 ? " and others" : "",
                                                               count));
    if (exc && PyObject_SetAttrString(exc, "vertices", index) == 0)
        PyErr_SetObject(type, exc);
    Py_XDECREF(exc);
    Py_DECREF(index);
}

static PyObject *shade_mesh_with(ShaderObject *self, PyObject *args, PyObject *kwargs, wenv_py_vertex_inputs *vin)
{
    static char *kwlist[] = {"positions", "normals",   "eye",    "cull",       "view_projection", "out",
                             "first",     "budget",    "occlusion", "bounce", "base_color",      "lamps",
                             "emission_color", "smooth_normals", "bump_map_correction", "bounce_hits", NULL};
    PyObject *pobj, *nobj, *eobj, *vp_obj = Py_None, *out_obj = Py_None, *budget_obj = Py_None, *first_obj = NULL;
    PyObject *occ_obj = Py_None, *bounce_obj = NULL, *colour_obj = NULL, *hits_obj = NULL;
    PyObject *lamps_obj = Py_None, *emit_obj = Py_None, *smooth_obj = Py_None;
    int cull = 0, correction = 1;
    size_t first = 0;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "OOO|$pOOOOOOOOOOO&O:shade_mesh", kwlist, &pobj, &nobj, &eobj, &cull,
                                     &vp_obj, &out_obj, &first_obj, &budget_obj, &occ_obj, &bounce_obj, &colour_obj,
                                     &lamps_obj, &emit_obj, &smooth_obj, wenv_py_bump_correction, &correction,
                                     &hits_obj))
        return NULL;
    if (occ_obj == Py_None && (bounce_obj || (hits_obj && hits_obj != Py_None))) {
        PyErr_SetString(PyExc_ValueError, "bounce is read only with occlusion (what blocks the light it fills in)");
        return NULL;
    }
    if (first_obj && wenv_py_get_size(first_obj, "first", &first) < 0)
        return NULL;
    double budget = INFINITY;
    if (budget_obj != Py_None) {
        if (!PyFloat_Check(budget_obj) && !PyLong_Check(budget_obj)) {
            PyErr_Format(PyExc_TypeError, "budget must be a number of seconds or None, got %.100s",
                         Py_TYPE(budget_obj)->tp_name);
            return NULL;
        }
        budget = PyFloat_AsDouble(budget_obj);
        if (budget == -1.0 && PyErr_Occurred())
            return NULL;
        if (!(budget >= 0.0)) {
            PyErr_Format(PyExc_ValueError, "budget must be >= 0 seconds, got %R", budget_obj);
            return NULL;
        }
    }
    double eye[3], vp[16];
    if (parse_eye(eobj, eye) < 0)
        return NULL;
    if (vp_obj != Py_None && !cull) {
        PyErr_SetString(PyExc_ValueError, "view_projection is only read with cull=True (it sets which vertices are "
                                          "off screen)");
        return NULL;
    }
    if (vp_obj != Py_None && wenv_py_get_matrix(vp_obj, "view_projection", 4, 16, vp) < 0)
        return NULL;
    Py_buffer pb, nb, ob = {0}, bb[2] = {{0}, {0}};
    size_t np, nn;
    wenv_shadow_scene scene;
    if (wenv_py_get_vec3_array(pobj, "positions", 0, &pb, &np, NULL) < 0)
        return NULL;
    if (wenv_py_get_vec3_array(nobj, "normals", 1, &nb, &nn, NULL) < 0) {
        PyBuffer_Release(&pb);
        return NULL;
    }
    PyObject *result = NULL;
    float *views = NULL, *rgb = NULL, *light = NULL, *emission = NULL;
    Py_buffer sb = {0};
    unsigned char *visible = NULL;
    int claimed = 0;
    wenv_diffuse_table table;
    wenv_vertex_colour colour;
    if (np != nn) {
        PyErr_Format(PyExc_ValueError, "positions has %zu rows but normals has %zu", np, nn);
        goto done;
    }
    if (occ_obj != Py_None && parse_scene(self, occ_obj, bounce_obj, hits_obj, np, &scene, bb) < 0)
        goto done;
    if (parse_smooth(smooth_obj, np, &sb) < 0 ||
        parse_colour(self, colour_obj, np, per_vertex_material(self, colour_obj, vin), &sb, correction, &table,
                     &colour, &rgb) < 0)
        goto done;
    if (emit_obj != Py_None && !(emission = wenv_py_vertex_colours(emit_obj, "emission_color", np, 0)))
        goto done;
    float *out;
    if (out_obj == Py_None) {
        Py_ssize_t shape[2] = {(Py_ssize_t)np, 3};
        if (!(result = wenv_py_new_float_array(2, shape, &out)))
            goto done;
        memset(out, 0, np * 3 * sizeof(float)); /* rows of vertices not seen stay black */
    } else {
        if (wenv_py_get_writable_vec3_array(out_obj, "out", np, &ob) < 0)
            goto done;
        out = ob.buf;
        result = Py_NewRef(out_obj);
    }
    views = PyMem_Malloc((np ? np : 1) * 3 * sizeof(float));
    visible = cull ? PyMem_Malloc(np ? np : 1) : NULL;
    if (!views || (cull && !visible)) {
        PyErr_NoMemory();
        goto fail;
    }
    const float *p = pb.buf;
    size_t at_eye = 0;
    for (size_t i = 0; i < np; i++) {
        double d[3] = {eye[0] - p[3 * i], eye[1] - p[3 * i + 1], eye[2] - p[3 * i + 2]};
        at_eye += d[0] * d[0] + d[1] * d[1] + d[2] * d[2] < 1e-24;
        for (int c = 0; c < 3; c++)
            views[3 * i + c] = (float)d[c];
    }
    if (at_eye) {
        raise_eye_at_vertex(pb.buf, eye, np, at_eye);
        goto fail;
    }
    size_t count = np, next;
    if (cull)
        count = wenv_visible_vertices(pb.buf, nb.buf, np, eye, vp_obj != Py_None ? vp : NULL, visible);
    if (first > count) {
        PyErr_Format(PyExc_ValueError, "first (%zu) is past the %zu vertices to shade", first, count);
        goto fail;
    }
    if (claim(self) < 0)
        goto fail;
    claimed = 1;
    wenv_family_rows family_rows;
    const wenv_family_rows *family;
    wenv_lamp_rows lamp_rows;
    const wenv_lamp_rows *lamps;
    if (ensure_family(self, colour_obj, vin, np, &family_rows, &family) < 0 ||
        ensure_lamps(self, lamps_obj, pb.buf, nb.buf, np, occ_obj != Py_None ? &scene : NULL, &lamp_rows, &lamps) < 0)
        goto fail;
    if (occ_obj != Py_None &&
        own_bounce(self, nb.buf, np, &scene, colour_of(&colour), family, emission, lamps, &light) < 0)
        goto fail;
    if (shade_visible(self, nb.buf, views, np, visible, count, occ_obj != Py_None ? &scene : NULL,
                      colour_of(&colour), family, emission, lamps, first, budget, out, &next) < 0)
        goto fail;
    self->visible = cull ? (Py_ssize_t)count : -1;
    self->next_vertex = (Py_ssize_t)next;
    goto done;
fail:
    Py_CLEAR(result);
done:
    if (claimed)
        self->busy = 0;
    PyMem_Free(views);
    PyMem_Free(rgb);
    if (sb.obj)
        PyBuffer_Release(&sb);
    PyMem_Free(emission);
    PyMem_Free(light);
    PyMem_Free(visible);
    if (ob.obj)
        PyBuffer_Release(&ob);
    for (int k = 0; k < 2; k++)
        if (bb[k].obj)
            PyBuffer_Release(&bb[k]);
    PyBuffer_Release(&pb);
    PyBuffer_Release(&nb);
    return result;
}

static PyObject *Shader_set_environment(ShaderObject *self, PyObject *env)
{
    if (claim(self) < 0)
        return NULL;
    int r = do_set(self, env, 0);
    self->busy = 0;
    if (r < 0)
        return NULL;
    Py_RETURN_NONE;
}

static PyObject *Shader_set_material(ShaderObject *self, PyObject *mat)
{
    if (claim(self) < 0)
        return NULL;
    int r = do_set(self, mat, 1);
    self->busy = 0;
    if (r < 0)
        return NULL;
    Py_RETURN_NONE;
}

static PyObject *Shader_get_quality(ShaderObject *self, void *closure)
{
    (void)closure;
    if (!self->quality)
        Py_RETURN_NONE;
    return quality_to_dict(self->method, self->quality);
}

static PyObject *Shader_get_method(ShaderObject *self, void *closure)
{
    (void)closure;
    if (!self->method)
        Py_RETURN_NONE;
    return PyUnicode_FromString(self->method->name);
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
    if (!self->state)
        Py_RETURN_NONE;
    wenv_stat stats[WENV_STATS_MAX];
    size_t count = self->method->stats(self->state, stats);
    PyObject *d = PyDict_New();
    for (size_t k = 0; d && k < count; k++) {
        const wenv_stat *s = &stats[k];
        PyObject *v = s->type == WENV_STAT_COUNT ? PyLong_FromSize_t(s->count)
                      : s->type == WENV_STAT_REAL ? PyFloat_FromDouble(s->real)
                                                  : PyUnicode_FromString(s->text);
        if (!v || PyDict_SetItemString(d, s->key, v) < 0)
            Py_CLEAR(d);
        Py_XDECREF(v);
    }
    if (d && self->visible >= 0) {
        PyObject *v = PyLong_FromSsize_t(self->visible);
        if (!v || PyDict_SetItemString(d, "visible_vertices", v) < 0)
            Py_CLEAR(d);
        Py_XDECREF(v);
    }
    if (d && self->lamp_light) {
        PyObject *v = PyLong_FromSize_t(wenv_lamp_light_made(self->lamp_light));
        if (!v || PyDict_SetItemString(d, "lamp_light_made", v) < 0)
            Py_CLEAR(d);
        Py_XDECREF(v);
    }
    if (d && self->next_vertex >= 0) {
        PyObject *v = PyLong_FromSsize_t(self->next_vertex);
        if (!v || PyDict_SetItemString(d, "next_vertex", v) < 0)
            Py_CLEAR(d);
        Py_XDECREF(v);
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
            PyObject *li = Py_BuildValue("{s:d,s:d,s:d,s:d,s:d,s:d}", "predicted_error", e->predicted_error,
                                         "lights_share", e->lights_share, "contrast", e->contrast, "sun_contrast",
                                         e->sun_contrast, "light_dominance", e->light_dominance, "env_factor",
                                         e->env_factor);
            if (!li)
                Py_CLEAR(levels);
            else
                PyList_SET_ITEM(levels, (Py_ssize_t)i, li);
        }
        PyObject *info = !used || !level || !order || !levels ? NULL : Py_BuildValue("{s:O,s:O,s:s,s:d,s:d,s:d,s:d,s:d,s:d,s:O,s:d,s:d,s:O,s:O,s:d,s:d,s:d}", "level", level, "sh_order", order,
                                       "method", a->method->name, "predicted_error", a->predicted_error, "target_error",
                                       self->target_error, "contrast", chosen->contrast, "lights_share", chosen->lights_share,
                                       "light_dominance", chosen->light_dominance, "env_factor", chosen->env_factor,
                                       "met", a->met ? Py_True : Py_False, "memory_budget_mb", self->memory_budget_mb,
                                       "level_mb", (double)a->level_bytes / 1048576.0, "used_normal_samples", used,
                                       "levels", levels, "seconds", a->seconds,
                                       "analysis_seconds", a->analysis_seconds, "head_on", a->head_on);
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

/* Shader.shade, diffuse_light and shade_mesh take the inputs per vertex (WENV_VERTEX_INPUTS) as
 * keywords by the one list, the rest as each declares them. */
#define WITH_VERTEX_INPUTS(name, with)                                                                             \
    static PyObject *name(ShaderObject *self, PyObject *args, PyObject *kwargs)                                    \
    {                                                                                                              \
        wenv_py_vertex_inputs vin;                                                                                 \
        PyObject *result =                                                                                         \
            wenv_py_take_vertex_inputs(kwargs, &vin) < 0 ? NULL : with(self, args, vin.rest, &vin);                \
        wenv_py_vertex_inputs_release(&vin);                                                                       \
        return result;                                                                                             \
    }
WITH_VERTEX_INPUTS(Shader_shade, shade_with)
WITH_VERTEX_INPUTS(Shader_diffuse_light, diffuse_light_with)
WITH_VERTEX_INPUTS(Shader_shade_mesh, shade_mesh_with)

static PyMethodDef Shader_methods[] = {
    {"shade", (PyCFunction)(void (*)(void))Shader_shade, METH_VARARGS | METH_KEYWORDS,
     "shade(normals, view_dirs, *, occlusion=None, bounce='self', base_color=None, positions=None, lamps=None, "
     "emission_color=None, roughness=None, metallic=None, specular_ior_level=None, specular_tint=None, "
     "coat_weight=None, coat_roughness=None, sheen_weight=None, sheen_roughness=None, sheen_tint=None, alpha=None, "
     "smooth_normals=None, bump_map_correction=True, bounce_hits=None)"
     "\n--\n\nLinear RGB radiance (float32, n x 3) for "
     "world-space normals and view directions (surface towards eye), float32 (n, 3); view_dirs may be one (3,) "
     "vector for all.  occlusion (a wenv.Occlusion made for these vertices) shades with the scene in the way: "
     "its blocked directions hide the environment, the exact lights are tested along their own rays, and the "
     "blockers send their light back -- bounce='self' (the occluders are this mesh: its own light, as "
     "diffuse_light gives it), an "
     "array (occluder vertices, 3) of each occluder vertex's light (Shader.diffuse_light), or None (black).  "
     "bounce_hits, in place of bounce, gives the light reaching each blocked texel itself: float32 (h, 3), one row "
     "per ray of Occlusion.hits, in its order (what the blocker sends towards this vertex, its glossy light "
     "included).  Wavelet methods only.\n\nbase_color (float32 (n, 3), linear RGB, clamped to [0, 1] as the material's own "
     "is): each vertex's colour in place of the material's -- a Principled BSDF's Base Color, a Lambert's or "
     "Cook-Torrance's diffuse albedo -- at the cost of a multiply-add a vertex (it scales the Lambertian part "
     "alone); a ValueError says why for a material whose colour also enters its lobes (a metal, a rough "
     "diffuse) or that has none (a measured table).  Every method.  emission_color (float32 (n, 3), linear, >= "
     "0): each vertex's Emission Color in place of a Principled material's, its Strength and layers the "
     "material's (every method).\n\nroughness, metallic, specular_ior_level, coat_weight, coat_roughness, "
     "sheen_weight, sheen_roughness, alpha (float32 (n,)) and specular_tint, sheen_tint (float32 (n, 3)), "
     "clamped as Cycles clamps them: each vertex's input in place of a Principled material's (a texture's "
     "values; wenv.Principled.INPUTS marks them per_vertex).  Metallic, Alpha and the weights and tints are "
     "exact (they enter linearly); values of at most 8 distinct materials are exact; inputs varying more "
     "smoothly are the axes of a grid of materials a vertex mixes, Roughness 1/24 apart (1/16 beside another "
     "axis), the exact lights read at each vertex's own values (within 1 % of each vertex's own material for "
     "one input, 1.1 % for two: docs/python.md); at most 4 channels may vary smoothly at once "
     "(wenv.Principled.PER_VERTEX).  The members are made once and kept: a new view costs each vertex its "
     "cell's members' reads.  Wavelet methods only.\n\n"
     "positions (float32 (n, 3), world) and lamps (a sequence of wenv.Lamp): the scene's lamps added as Cycles "
     "emits them, with the shadows of occlusion's scene (docs/lamps.md).  Every method.\n\n"
     "smooth_normals (float32 (n, 3)): the normals before a normal map or Bump node bent `normals`; the "
     "Lambertian part then loses what Cycles' bump terminator takes (the light from below the smooth horizon, "
     "and with bump_map_correction, the material's Bump Map Correction, grazing light masked by GGX's G1 of "
     "the bend): each lamp weighed in its own direction, the sky's light by its share, the horizon's read "
     "where it is lost (docs/python.md).  Every method."},
    {"diffuse_light", (PyCFunction)(void (*)(void))Shader_diffuse_light, METH_VARARGS | METH_KEYWORDS,
     "diffuse_light(normals, *, occlusion=None, base_color=None, positions=None, lamps=None, emission_color=None, "
     "roughness=None, metallic=None, ...)\n--\n\nThe light (radiance, float32 n x 3) each vertex sends "
     "back to the surfaces it blocks (shade's bounce), as if diffuse: its albedo head-on (the Lambertian "
     "part's and the lobes') over pi times its irradiance, with its shadows when occlusion is given.  "
     "Wavelet methods only; base_color, the inputs per vertex, emission_color, positions, lamps and "
     "smooth_normals as shade's."},
    {"shade_mesh", (PyCFunction)(void (*)(void))Shader_shade_mesh, METH_VARARGS | METH_KEYWORDS,
     "shade_mesh(positions, normals, eye, *, cull=False, view_projection=None, out=None, first=0, budget=None, "
     "occlusion=None, bounce='self', bounce_hits=None, base_color=None, lamps=None, emission_color=None, "
     "roughness=None, metallic=None, ...)\n--\n\nShade vertices seen from a perspective eye position.  cull=True shades only what the eye sees: "
     "vertices whose normal faces it and, given view_projection (the viewport's 4 x 4 world-to-clip "
     "matrix, row-major: Blender's region_3d.perspective_matrix), those inside its frustum; the rows of "
     "the others are left as they were in `out` (a float32 (n, 3) array written in place and returned) "
     "or black in a new array.  stats['visible_vertices'] tells how many were shaded; wenv.visible_vertices "
     "gives which.  Renders and bakes from other views keep cull=False.\n\n"
     "first and budget shade in steps: the vertices to shade (the visible ones, in order, with cull=True) "
     "from the first-th on, in blocks until budget seconds have passed (at least one block); "
     "stats['next_vertex'] is where the next step starts (the number to shade once all are done), and "
     "rows not reached keep what `out` held.  So a view that rests is refined by an accurate Shader "
     "over a fast one's result: out = fast.shade_mesh(...); then accurate.shade_mesh(..., out=out, "
     "first=k, budget=0.05) until k reaches the count.\n\n"
     "occlusion and bounce (or bounce_hits) shade with the scene in the way, as shade's (the occlusion made for these "
     "positions and normals); base_color, emission_color, smooth_normals and the inputs per vertex as shade's; "
     "lamps (a "
     "sequence of wenv.Lamp) add the scene's lamps, as Cycles emits them (docs/lamps.md)."},
    {"set_environment", (PyCFunction)Shader_set_environment, METH_O,
     "set_environment(env)\n--\n\nNew lighting; rotation matrices are kept."},
    {"set_material", (PyCFunction)Shader_set_material, METH_O,
     "set_material(material)\n--\n\nNew BRDF; rotation matrices and lighting slices are kept.  The wavelet methods "
     "keep the last materials set (up to 40 within 768 MB): one of them set again (equal in every value) makes "
     "nothing anew."},
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
    .tp_doc = "Shader(env, material, quality='default', method=None, cache_dir=None, progress=None, "
              "target_error=0.01, memory_budget_mb=1024, normals=None)\n--\n\n"
              "Environment shading by wavelet rotation.  quality: 'draft', 'default', 'high', 'auto' or a dict of "
              "global, local, normals, views, coefficients, light_coefficients, matrix_epsilon, lights, light_threshold, "
              "light_tolerance, grazing, grazing_slopes, lobe_rings.  method: "
              "'rotation' (precomputed sparse matrices, cached on disk in cache_dir; None: WENV_CACHE_DIR or "
              "~/.cache/wenv; False: no cache) or 'slicing' (the same shading without matrices); None picks "
              "'rotation' where the matrices are in the cache or take at most 768 MB (and memory_budget_mb), "
              "else 'slicing' (`draft` rotates; `default` and `high` slice unless their matrices are cached).  "
              "Matrices not in the cache that would take more than memory_budget_mb are a ValueError, estimated "
              "from a few of them before anything large is built; 'slicing' keeps its resampling operators within "
              "an eighth of memory_budget_mb (at most 128 MB; stats['resampling_bytes']).  progress(fraction) is called "
              "during precomputation; returning True cancels it (wenv.CancelledError).\n\n"
              "Peer methods for comparison: 'split_sum' (prefiltered environment maps and an environment-BRDF "
              "table, Karis 2013; quality keys prefilter, samples, lut) and 'sh' (spherical harmonics, Kautz, "
              "Sloan and Snyder 2002; quality keys order, views); presets in wenv.PEER_QUALITY_PRESETS.  Their "
              "precomputation runs in set_environment and set_material, which then also report to progress.\n\n"
              "quality='auto' picks the cheapest setting of wenv.AUTO_LADDER (method 'slicing'; level 3 is 'default', the last "
              "'high') whose error is predicted, from the narrowest lobe's roughness and distribution, the share "
              "of the flux the "
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


/* wenv.METHODS, wenv.QUALITY_PRESETS (the wavelet methods'), wenv.PEER_QUALITY_PRESETS (the others',
 * by method), wenv.AUTO_LADDER and wenv.AUTO_SH_ORDERS, all read from the core's tables. */
static PyObject *presets_of(const wenv_method *method)
{
    PyObject *d = PyDict_New();
    for (size_t p = 0; d && p < WENV_PRESET_COUNT; p++) {
        PyObject *q = quality_to_dict(method, method->presets[p]);
        if (!q || PyDict_SetItemString(d, WENV_PRESET_NAMES[p], q) < 0)
            Py_CLEAR(d);
        Py_XDECREF(q);
    }
    return d;
}

static int add_object(PyObject *module, const char *name, PyObject *value)
{
    if (!value || PyModule_AddObject(module, name, value) < 0) {
        Py_XDECREF(value);
        return -1;
    }
    return 0;
}

static PyObject *py_visible_vertices(PyObject *module, PyObject *args, PyObject *kwargs)
{
    (void)module;
    static char *kwlist[] = {"positions", "normals", "eye", "view_projection", NULL};
    PyObject *pobj, *nobj, *eobj, *vp_obj = Py_None;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "OOO|O:visible_vertices", kwlist, &pobj, &nobj, &eobj, &vp_obj))
        return NULL;
    double eye[3], vp[16];
    if (parse_eye(eobj, eye) < 0 || (vp_obj != Py_None && wenv_py_get_matrix(vp_obj, "view_projection", 4, 16, vp) < 0))
        return NULL;
    Py_buffer pb, nb;
    size_t np;
    if (wenv_py_get_vec3_pair(pobj, "positions", nobj, "normals", 0, &pb, &nb, &np) < 0)
        return NULL;
    PyObject *result = NULL;
    {
        Py_ssize_t shape[1] = {(Py_ssize_t)np};
        void *data;
        if ((result = wenv_py_new_array(1, shape, "bool", &data))) {
            WENV_BEGIN_WORK
            wenv_visible_vertices(pb.buf, nb.buf, np, eye, vp_obj != Py_None ? vp : NULL, data);
            WENV_END_WORK
        }
    }
    PyBuffer_Release(&pb);
    PyBuffer_Release(&nb);
    return result;
}

/* The method wenv.Shader runs a wavelet quality with when none is named (the core's choice). */
static PyObject *py_method_for(PyObject *self, PyObject *args, PyObject *kwargs)
{
    (void)self;
    static char *kwlist[] = {"quality", "cache_dir", "memory_budget_mb", NULL};
    PyObject *quality_obj, *cache_obj = Py_None;
    double budget_mb = 1024.0;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "O|Od:method_for", kwlist, &quality_obj, &cache_obj, &budget_mb))
        return NULL;
    if (!(budget_mb > 0.0 && budget_mb < 1e9)) {
        wenv_py_errorf(PyExc_ValueError, "memory_budget_mb must be positive, got %g", budget_mb);
        return NULL;
    }
    if (PyUnicode_Check(quality_obj) && PyUnicode_CompareWithASCIIString(quality_obj, "auto") == 0)
        return PyUnicode_FromString(WENV_METHOD_SLICING.name); /* auto's ladder slices */
    const wenv_method *method = wenv_method_default();
    void *quality = PyMem_Malloc(method->quality_size);
    if (!quality)
        return PyErr_NoMemory();
    PyObject *cache_bytes = NULL, *result = NULL;
    wenv_method_setup setup = {0};
    if (parse_quality(method, quality_obj, quality) == 0 && parse_cache(cache_obj, &setup, &cache_bytes) == 0) {
        setup.memory_budget = (size_t)(budget_mb * 1048576.0);
        const wenv_method *chosen;
        WENV_BEGIN_WORK
        chosen = wenv_method_choose_default(quality, &setup);
        WENV_END_WORK
        result = PyUnicode_FromString(chosen->name);
    }
    Py_XDECREF(cache_bytes);
    PyMem_Free(quality);
    return result;
}

static PyMethodDef shader_functions[] = {
    {"method_for", (PyCFunction)(void (*)(void))py_method_for, METH_VARARGS | METH_KEYWORDS,
     "method_for(quality, cache_dir=None, memory_budget_mb=1024)\n--\n\nThe method wenv.Shader runs `quality` "
     "with when no method is named: 'rotation' (precomputed matrices: built on first use, or read from the cache) "
     "or 'slicing' (nothing to precompute; the lighting is resampled for each new environment).  'auto' slices."},
    {"visible_vertices", (PyCFunction)(void (*)(void))py_visible_vertices, METH_VARARGS | METH_KEYWORDS,
     "visible_vertices(positions, normals, eye, view_projection=None)\n--\n\nWhich vertices an eye sees "
     "(bool, n): those whose normal faces it and, given view_projection (4 x 4 world-to-clip, row-major), "
     "inside its frustum -- the ones Shader.shade_mesh(cull=True) shades."},
    {NULL, NULL, 0, NULL},
};

int wenv_register_shader(PyObject *module)
{
    if (PyType_Ready(&ShaderType) < 0 || PyModule_AddFunctions(module, shader_functions) < 0)
        return -1;
    Py_INCREF(&ShaderType);
    if (add_object(module, "Shader", (PyObject *)&ShaderType) < 0)
        return -1;
    size_t count = wenv_method_count();
    PyObject *names = PyTuple_New((Py_ssize_t)count), *peers = PyDict_New();
    for (size_t i = 0; names && i < count; i++) {
        PyObject *name = PyUnicode_FromString(wenv_method_at(i)->name);
        if (!name)
            Py_CLEAR(names);
        else
            PyTuple_SET_ITEM(names, (Py_ssize_t)i, name);
    }
    /* the wavelet methods share QUALITY_PRESETS; each other method's are under its name */
    for (size_t i = 0; peers && i < count; i++) {
        const wenv_method *m = wenv_method_at(i);
        if (m->presets[0] == WENV_METHOD_ROTATION.presets[0])
            continue;
        PyObject *p = presets_of(m);
        if (!p || PyDict_SetItemString(peers, m->name, p) < 0)
            Py_CLEAR(peers);
        Py_XDECREF(p);
    }
    PyObject *ladder = PyList_New(WENV_AUTO_LEVELS);
    for (size_t i = 0; ladder && i < WENV_AUTO_LEVELS; i++) {
        PyObject *d = quality_to_dict(&WENV_METHOD_SLICING, &WENV_AUTO_LADDER[i]);
        if (!d)
            Py_CLEAR(ladder);
        else
            PyList_SET_ITEM(ladder, (Py_ssize_t)i, d);
    }
    PyObject *orders = PyTuple_New(WENV_AUTO_SH_ORDER_COUNT);
    for (size_t i = 0; orders && i < WENV_AUTO_SH_ORDER_COUNT; i++) {
        PyObject *o = PyLong_FromSize_t(WENV_AUTO_SH_ORDERS[i]);
        if (!o)
            Py_CLEAR(orders);
        else
            PyTuple_SET_ITEM(orders, (Py_ssize_t)i, o);
    }
    if (add_object(module, "METHODS", names) < 0 || add_object(module, "QUALITY_PRESETS", presets_of(&WENV_METHOD_ROTATION)) < 0 ||
        add_object(module, "PEER_QUALITY_PRESETS", peers) < 0 || add_object(module, "AUTO_LADDER", ladder) < 0 ||
        add_object(module, "AUTO_SH_ORDERS", orders) < 0)
        return -1;
    return 0;
}
