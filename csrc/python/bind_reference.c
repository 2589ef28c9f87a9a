/* wenv.reference: the brute-force ground truth. */
#include "python/module.h"

#include "python/bind_envmap.h"
#include "python/bind_lamp.h"
#include "python/bind_material.h"
#include "python/bind_occlusion.h"
#include "reference/reference.h"

static PyObject *reference_with(PyObject *args, PyObject *kwargs, wenv_py_vertex_inputs *vin)
{
    static char *kwlist[] = {"env",       "material",       "normals",        "view_dirs",           "progress",
                             "positions", "occluders",      "bounce",         "base_color",          "lamps",
                             "emission_color", "smooth_normals", "bump_map_correction", NULL};
    PyObject *env_obj, *mat_obj, *nobj, *vobj, *progress_obj = Py_None, *pobj = Py_None, *occ_obj = Py_None;
    PyObject *bounce_obj = Py_None, *colour_obj = Py_None;
    PyObject *lamps_obj = Py_None, *emit_obj = Py_None, *smooth_obj = Py_None;
    int correction = 1;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "OOOO|OOOOO$OOOO&:reference", kwlist, &env_obj, &mat_obj, &nobj,
                                     &vobj, &progress_obj, &pobj, &occ_obj, &bounce_obj, &colour_obj, &lamps_obj,
                                     &emit_obj, &smooth_obj, wenv_py_bump_correction, &correction))
        return NULL;
    if (bounce_obj != Py_None && occ_obj == Py_None) {
        PyErr_SetString(PyExc_ValueError, "bounce is read only with occluders (what blocks the light it fills in)");
        return NULL;
    }
    const struct wenv_occluders *occ = NULL;
    if (occ_obj != Py_None && !(occ = wenv_py_occluders(occ_obj, "occluders")))
        return NULL;
    if (occ_obj != Py_None && pobj == Py_None) {
        PyErr_SetString(PyExc_ValueError, "occluders need positions: the rays start at the positions");
        return NULL;
    }
    if (lamps_obj != Py_None && pobj == Py_None) {
        PyErr_SetString(PyExc_ValueError, "lamps need the vertices' positions (positions=)");
        return NULL;
    }
    if (pobj != Py_None && occ_obj == Py_None && lamps_obj == Py_None) {
        PyErr_SetString(PyExc_ValueError, "positions are read only with occluders or lamps");
        return NULL;
    }
    const struct wenv_envmap *env = wenv_py_envmap(env_obj, "env");
    if (!env)
        return NULL;
    const struct wenv_material *mat = wenv_py_material(mat_obj, "material");
    if (!mat)
        return NULL;
    if (wenv_py_check_progress(progress_obj) < 0)
        return NULL;
    Py_buffer nb, vb;
    size_t n, nv;
    if (wenv_py_get_vec3_array(nobj, "normals", 1, &nb, &n, NULL) < 0)
        return NULL;
    if (wenv_py_get_vec3_array(vobj, "view_dirs", 1, &vb, &nv, NULL) < 0) {
        PyBuffer_Release(&nb);
        return NULL;
    }
    PyObject *result = NULL;
    Py_buffer pb = {0}, bb = {0}, sb = {0};
    wenv_vertex_inputs vi;
    float *rgb = NULL, *emission = NULL;
    wenv_lamp *lamps = NULL;
    size_t np = n, nb_rows, n_lamps = 0;
    if (pobj != Py_None && wenv_py_get_vec3_array(pobj, "positions", 0, &pb, &np, NULL) < 0)
        goto done;
    if (wenv_py_lamps(lamps_obj, "lamps", &lamps, &n_lamps) < 0)
        goto done;
    if (bounce_obj != Py_None) {
        if (wenv_py_get_vec3_array(bounce_obj, "bounce", 0, &bb, &nb_rows, NULL) < 0)
            goto done;
        if (nb_rows != wenv_occluders_vertex_count(occ)) {
            PyErr_Format(PyExc_ValueError, "bounce has %zu rows, one per occluder vertex (%zu)", nb_rows,
                         wenv_occluders_vertex_count(occ));
            goto done;
        }
    }
    if (nv != n || np != n) {
        PyErr_Format(PyExc_ValueError, "view_dirs has %zu rows and positions %zu, but normals has %zu", nv,
                     np, n);
        goto done;
    }
    size_t ns = n;
    if (smooth_obj != Py_None && wenv_py_get_vec3_array(smooth_obj, "smooth_normals", 1, &sb, &ns, NULL) < 0)
        goto done;
    if (ns != n) {
        PyErr_Format(PyExc_ValueError, "smooth_normals has %zu rows but normals has %zu", ns, n);
        goto done;
    }
    wenv_bump_normals bump = {sb.obj ? sb.buf : NULL, correction};
    if (colour_obj != Py_None && !(rgb = wenv_py_base_colours(colour_obj, n)))
        goto done;
    if (emit_obj != Py_None && !(emission = wenv_py_vertex_colours(emit_obj, "emission_color", n, 0)))
        goto done;
    if (wenv_py_vertex_inputs_read(vin, n, &vi) < 0)
        goto done;
    Py_ssize_t shape[2] = {(Py_ssize_t)n, 3};
    float *out;
    result = wenv_py_new_float_array(2, shape, &out);
    if (!result || n == 0)
        goto done;
    wenv_py_progress_bridge bridge = {.callback = progress_obj};
    wenv_progress progress = wenv_py_progress(&bridge);
    wenv_error err = {0};
    wenv_status st;
    WENV_BEGIN_WORK
    st = wenv_reference_per_vertex(env, mat, nb.buf, vb.buf, n, occ, pb.obj ? pb.buf : NULL, bb.obj ? bb.buf : NULL, rgb,
                                   &vi, lamps, n_lamps, emission, sb.obj ? &bump : NULL, out, &progress, &err);
    WENV_END_WORK
    if (st) {
        Py_CLEAR(result);
        if (!(bridge.raised && PyErr_Occurred()))
            wenv_py_raise(&err);
    }
done:
    PyMem_Free(rgb);
    PyMem_Free(emission);
    PyMem_Free(lamps);
    if (pb.obj)
        PyBuffer_Release(&pb);
    if (bb.obj)
        PyBuffer_Release(&bb);
    if (sb.obj)
        PyBuffer_Release(&sb);
    PyBuffer_Release(&nb);
    PyBuffer_Release(&vb);
    return result;
}

/* The inputs per vertex (WENV_VERTEX_INPUTS) are keywords by the one list. */
static PyObject *py_reference(PyObject *self, PyObject *args, PyObject *kwargs)
{
    (void)self;
    wenv_py_vertex_inputs vin;
    PyObject *result = wenv_py_take_vertex_inputs(kwargs, &vin) < 0 ? NULL : reference_with(args, vin.rest, &vin);
    wenv_py_vertex_inputs_release(&vin);
    return result;
}

static PyMethodDef reference_functions[] = {
    {"reference", (PyCFunction)(void (*)(void))py_reference, METH_VARARGS | METH_KEYWORDS,
     "reference(env, material, normals, view_dirs, progress=None, positions=None, occluders=None, bounce=None, "
     "base_color=None, *, lamps=None, emission_color=None, roughness=None, metallic=None, specular_ior_level=None, "
     "specular_tint=None, coat_weight=None, coat_roughness=None, sheen_weight=None, sheen_roughness=None, "
     "sheen_tint=None, alpha=None, smooth_normals=None, bump_map_correction=True)\n--\n\n"
     "Ground truth: the reflection equation summed over every environment pixel (exact solid angles), in the "
     "units of Shader.shade.  With occluders (a wenv.Occluders) and the vertices' positions, each pixel's ray "
     "from the vertex is cast exactly, and a blocked one brings the blocker's light where it is hit: bounce "
     "(occluder vertices, 3), each occluder vertex's radiance interpolated over the hit triangle, or nothing "
     "when bounce is None (direct light only).  base_color (n, 3): each vertex's colour in place of the "
     "material's, as Shader.shade takes it.  roughness, metallic, specular_ior_level, coat_weight, coat_roughness, "
     "sheen_weight, sheen_roughness, alpha (n,) and specular_tint, sheen_tint (n, 3) float32: each vertex's "
     "input in place of a Principled material's, each distinct set of values shaded with its own material, "
     "exactly.  "
     "lamps (a sequence of wenv.Lamp, with positions): each lamp's light summed over a fine grid of its surface "
     "(or its cone of directions), each point with the exact BRDF and, with occluders, its own ray.  "
     "emission_color (n, 3): each vertex's Emission Color in place of a Principled material's.  "
     "smooth_normals (n, 3): the normals before a normal map or Bump node bent `normals`, the Lambertian part "
     "receiving each direction's light as Cycles' bump terminator lets it through (bump_map_correction: the "
     "material's Bump Map Correction)."},
    {NULL, NULL, 0, NULL},
};

int wenv_register_reference(PyObject *module) { return PyModule_AddFunctions(module, reference_functions); }
