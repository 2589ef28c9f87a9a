/* Blender's Principled BSDF node's inputs, defined once.  Every row below is one socket; from this
 * list follow the C struct (wenv_principled_inputs), the node's defaults, what is checked and how
 * Cycles clamps it, the material's fingerprint, what wenv does not shade (with the words a user
 * reads), the Python keywords of wenv.Principled and wenv.Principled.INPUTS, from which the add-on
 * maps sockets and draws its panel.  A new Blender input is one new row (docs/ARCHITECTURE.md §2).
 *
 * Columns: X(name, n, socket, default r, g, b (n = 1: the first), lo, hi, scales, shading, rule,
 * threshold, partner, note)
 *   name      the Python keyword: the socket's name in snake case
 *   n         1 for a value, 3 for a colour
 *   socket    the node's socket name (Blender 4.x/5.x)
 *   default   the node's default (node_shader_bsdf_principled.cc)
 *   lo, hi    the range Cycles' kernel clamps it to (svm/closure.h; -INF/INF: none)
 *   scales    1 when it multiplies what is reflected: at most WENV_PRINCIPLED_SCALE_MAX (a value near
 *             float's largest, which Blender's sockets hold, would overflow the lighting)
 *   shading   WENV_SHADED, WENV_SHADED_PARTLY (shaded in part: the note says how), WENV_NOT_SHADED
 *   rule      when a value is named by wenv_principled_unhonoured: WENV_NEVER, WENV_ABOVE or
 *   threshold WENV_BELOW the threshold, or WENV_NONZERO (|value| above it), in any channel of a colour,
 *   partner   and only while `partner` (an input's name, or "") is above WENV_PRINCIPLED_WEIGHT_CUTOFF in
 *             some channel
 *   note      what a user reads when it is named */
#ifndef WENV_PRINCIPLED_INPUTS_H
#define WENV_PRINCIPLED_INPUTS_H

#include <math.h>
#include <stddef.h>

#include "base/error.h"

#define WENV_PRINCIPLED_INPUTS(X)                                                                                  \
    X(base_color, 3, "Base Color", 0.8, 0.8, 0.8, 0.0, INFINITY, 1, WENV_SHADED, WENV_NEVER, 0.0, "", "")          \
    X(metallic, 1, "Metallic", 0.0, 0.0, 0.0, 0.0, 1.0, 0, WENV_SHADED, WENV_NEVER, 0.0, "", "")                    \
    X(roughness, 1, "Roughness", 0.5, 0.0, 0.0, 0.0, 1.0, 0, WENV_SHADED, WENV_NEVER, 0.0, "", "")                  \
    X(ior, 1, "IOR", 1.5, 0.0, 0.0, 1e-5, INFINITY, 0, WENV_SHADED, WENV_NEVER, 0.0, "", "")                        \
    X(alpha, 1, "Alpha", 1.0, 0.0, 0.0, 0.0, 1.0, 0, WENV_SHADED_PARTLY, WENV_BELOW, 1.0, "",                        \
      "Alpha below 1: the see-through part is not shaded (the reflection is scaled by Alpha)")                     \
    X(specular_ior_level, 1, "Specular IOR Level", 0.5, 0.0, 0.0, 0.0, INFINITY, 1, WENV_SHADED, WENV_NEVER, 0.0,  \
      "", "")                                                                                                      \
    X(specular_tint, 3, "Specular Tint", 1.0, 1.0, 1.0, 0.0, INFINITY, 1, WENV_SHADED, WENV_NEVER, 0.0, "", "")    \
    X(anisotropic, 1, "Anisotropic", 0.0, 0.0, 0.0, 0.0, 1.0, 0, WENV_NOT_SHADED, WENV_ABOVE, 0.0, "",               \
      "Anisotropy is not shaded (the lobes are isotropic)")                                                        \
    X(anisotropic_rotation, 1, "Anisotropic Rotation", 0.0, 0.0, 0.0, -INFINITY, INFINITY, 0, WENV_NOT_SHADED,     \
      WENV_NEVER, 0.0, "", "")                                                                                     \
    X(coat_weight, 1, "Coat Weight", 0.0, 0.0, 0.0, 0.0, INFINITY, 1, WENV_SHADED, WENV_NEVER, 0.0, "", "")        \
    X(coat_roughness, 1, "Coat Roughness", 0.03, 0.0, 0.0, 0.0, 1.0, 0, WENV_SHADED, WENV_NEVER, 0.0, "", "")      \
    X(coat_ior, 1, "Coat IOR", 1.5, 0.0, 0.0, 1.0, INFINITY, 0, WENV_SHADED, WENV_NEVER, 0.0, "", "")              \
    X(coat_tint, 3, "Coat Tint", 1.0, 1.0, 1.0, 0.0, INFINITY, 0, WENV_SHADED_PARTLY, WENV_ABOVE, 1.0,              \
      "coat_weight",                                                                                               \
      "Coat Tint above 1 is shaded as 1 (a coat that adds light grows without bound towards grazing)")             \
    X(sheen_weight, 1, "Sheen Weight", 0.0, 0.0, 0.0, 0.0, INFINITY, 1, WENV_SHADED, WENV_NEVER, 0.0, "", "")      \
    X(sheen_roughness, 1, "Sheen Roughness", 0.5, 0.0, 0.0, 0.0, 1.0, 0, WENV_SHADED, WENV_NEVER, 0.0, "", "")     \
    X(sheen_tint, 3, "Sheen Tint", 1.0, 1.0, 1.0, 0.0, INFINITY, 1, WENV_SHADED, WENV_NEVER, 0.0, "", "")          \
    X(subsurface_weight, 1, "Subsurface Weight", 0.0, 0.0, 0.0, 0.0, 1.0, 0, WENV_SHADED_PARTLY, WENV_ABOVE,        \
      WENV_PRINCIPLED_WEIGHT_CUTOFF, "", "Subsurface scattering is shaded as diffuse reflection")                  \
    X(subsurface_radius, 3, "Subsurface Radius", 1.0, 0.2, 0.1, -INFINITY, INFINITY, 0, WENV_NOT_SHADED,            \
      WENV_NEVER, 0.0, "", "")                                                                                     \
    X(subsurface_scale, 1, "Subsurface Scale", 0.05, 0.0, 0.0, -INFINITY, INFINITY, 0, WENV_NOT_SHADED, WENV_NEVER, \
      0.0, "", "")                                                                                                 \
    X(subsurface_ior, 1, "Subsurface IOR", 1.4, 0.0, 0.0, -INFINITY, INFINITY, 0, WENV_NOT_SHADED, WENV_NEVER, 0.0,  \
      "", "")                                                                                                      \
    X(subsurface_anisotropy, 1, "Subsurface Anisotropy", 0.0, 0.0, 0.0, -INFINITY, INFINITY, 0, WENV_NOT_SHADED,   \
      WENV_NEVER, 0.0, "", "")                                                                                     \
    X(transmission_weight, 1, "Transmission Weight", 0.0, 0.0, 0.0, 0.0, 1.0, 0, WENV_NOT_SHADED, WENV_ABOVE,       \
      WENV_PRINCIPLED_WEIGHT_CUTOFF, "",                                                                           \
      "Transmission is not shaded (wenv shades reflection: the light through the object is left out)")             \
    X(diffuse_roughness, 1, "Diffuse Roughness", 0.0, 0.0, 0.0, 0.0, 1.0, 0, WENV_SHADED, WENV_NEVER, 0.0, "", "") \
    X(emission_color, 3, "Emission Color", 1.0, 1.0, 1.0, -INFINITY, INFINITY, 1, WENV_SHADED, WENV_NEVER, 0.0, "", \
      "")                                                                                                          \
    X(emission_strength, 1, "Emission Strength", 0.0, 0.0, 0.0, -INFINITY, INFINITY, 1, WENV_SHADED, WENV_NEVER,    \
      0.0, "", "")                                                                                                 \
    X(thin_film_thickness, 1, "Thin Film Thickness", 0.0, 0.0, 0.0, -INFINITY, INFINITY, 0, WENV_NOT_SHADED,       \
      WENV_ABOVE, 0.1, "", "Thin film is not shaded")                                                              \
    X(thin_film_ior, 1, "Thin Film IOR", 1.33, 0.0, 0.0, -INFINITY, INFINITY, 0, WENV_NOT_SHADED, WENV_NEVER, 0.0, \
      "", "")

/* Cycles drops a closure whose mean weight is below this; an input that only weighs something
 * counts from here. */
#define WENV_PRINCIPLED_WEIGHT_CUTOFF 1e-5
/* The most an input that scales the reflection may be: a million keeps every product finite under
 * the brightest lighting a World may give. */
#define WENV_PRINCIPLED_SCALE_MAX 1e6

typedef enum { WENV_SHADED, WENV_SHADED_PARTLY, WENV_NOT_SHADED } wenv_principled_shading;
typedef enum { WENV_NEVER, WENV_ABOVE, WENV_BELOW, WENV_NONZERO } wenv_principled_rule;

#define WENV_PRINCIPLED_FIELD_1(name) double name;
#define WENV_PRINCIPLED_FIELD_3(name) double name[3];
#define WENV_PRINCIPLED_FIELD(name, n, ...) WENV_PRINCIPLED_FIELD_##n(name)

/* The node's inputs (Blender 4.x/5.x names in snake case), as Cycles reads them; the node's
 * distribution, "Multiscatter GGX" (multiscatter 1, Blender's default) or "GGX", is a property of
 * the node rather than a socket.  oren_nayar_classic picks the Diffuse Roughness model of Cycles
 * before Blender 4.3 (a Diffuse BSDF's Roughness there): Fujii's Oren-Nayar alone, without the
 * multiple scattering that the energy-preserving model of 4.3 on adds. */
typedef struct {
    WENV_PRINCIPLED_INPUTS(WENV_PRINCIPLED_FIELD)
    int multiscatter;
    int oren_nayar_classic;
} wenv_principled_inputs;

/* One row of the list, for loops over the inputs. */
typedef struct {
    const char *name, *socket;
    size_t offset; /* of the field in wenv_principled_inputs */
    int n;
    double fallback[3]; /* the node's default */
    double lo, hi;
    int scales;
    wenv_principled_shading shading;
    wenv_principled_rule rule;
    double threshold;
    const char *partner, *note;
} wenv_principled_input;

extern const wenv_principled_input wenv_principled_input_list[];
extern const size_t wenv_principled_input_count;

/* The field of `in` a row describes (n doubles). */
static inline double *wenv_principled_field(wenv_principled_inputs *in, const wenv_principled_input *row)
{
    return (double *)((char *)in + row->offset);
}
static inline const double *wenv_principled_field_c(const wenv_principled_inputs *in, const wenv_principled_input *row)
{
    return (const double *)((const char *)in + row->offset);
}

/* The inputs that may vary per vertex (Shader.shade's keywords, methods/material_family.h, the
 * reference), each n float32 values or n x 3 for a colour: X(name, n).  Base Color and Emission
 * Color vary per vertex on their own, more cheaply (vertex_colour.h, emission.h). */
#define WENV_VERTEX_INPUTS(X)                                                                                      \
    X(roughness, 1)                                                                                                \
    X(metallic, 1)                                                                                                 \
    X(specular_ior_level, 1)                                                                                       \
    X(specular_tint, 3)                                                                                            \
    X(coat_weight, 1)                                                                                              \
    X(coat_roughness, 1)                                                                                           \
    X(sheen_weight, 1)                                                                                             \
    X(sheen_roughness, 1)                                                                                          \
    X(sheen_tint, 3)                                                                                               \
    X(alpha, 1)

#define WENV_VERTEX_INPUT_INDEX(name, n) WENV_VERTEX_##name,
enum { WENV_VERTEX_INPUTS(WENV_VERTEX_INPUT_INDEX) WENV_VERTEX_INPUT_COUNT };
/* Their values a vertex, channel by channel. */
#define WENV_VERTEX_INPUT_ADD_CHANNELS(name, n) +n
enum { WENV_VERTEX_INPUT_CHANNELS = 0 WENV_VERTEX_INPUTS(WENV_VERTEX_INPUT_ADD_CHANNELS) };

/* Each per-vertex input's values (NULL: the material's own), n x its channels. */
typedef struct {
    const float *value[WENV_VERTEX_INPUT_COUNT];
} wenv_vertex_inputs;

/* One per-vertex input: its keyword, channels and the row of wenv_principled_input_list it sets. */
typedef struct {
    const char *name;
    int n;
    const wenv_principled_input *row;
} wenv_vertex_input;

extern const wenv_vertex_input wenv_vertex_input_list[WENV_VERTEX_INPUT_COUNT];

/* Whether any of vi's inputs is given. */
static inline int wenv_vertex_inputs_any(const wenv_vertex_inputs *vi)
{
    for (int k = 0; vi && k < WENV_VERTEX_INPUT_COUNT; k++)
        if (vi->value[k])
            return 1;
    return 0;
}

/* Every given value finite: else WENV_ERR_VALUE naming the input and the vertex. */
wenv_status wenv_vertex_inputs_check(const wenv_vertex_inputs *vi, size_t n, wenv_error *err);

/* A per-vertex value clamped as Cycles clamps the input (and at WENV_PRINCIPLED_SCALE_MAX), as a double. */
static inline double wenv_vertex_input_clamp(const wenv_vertex_input *in, float x)
{
    double v = (double)x, hi = in->row->hi < WENV_PRINCIPLED_SCALE_MAX ? in->row->hi : WENV_PRINCIPLED_SCALE_MAX;
    return v < in->row->lo ? in->row->lo : (v > hi ? hi : v);
}

#endif
