/* The shading-method interface: what every way of shading a mesh under an environment provides.
 *
 * A method shades (normal, view) pairs with one material under one environment.  It is made with
 * its own quality settings (a plain struct described by `params`, so that callers can read and
 * write it by key without knowing the method), then given an environment and a material, each of
 * which may be replaced later without remaking the rest.  wenv.Shader (python/bind_shader.c) holds
 * one method through this table and never names a method itself.
 *
 * Adding a method: a folder under csrc/methods/ with its numerical code and one `const wenv_method`
 * describing it (as methods/wavelet/wavelet_method.c does), its presets in methods/presets.c, and
 * one entry in methods/methods.c.  See docs/ARCHITECTURE.md. */
#ifndef WENV_METHOD_H
#define WENV_METHOD_H

#include <stddef.h>

#include "base/error.h"
#include "base/progress.h"
#include "scene/envmap.h"
#include "scene/material.h"
#include "scene/occlusion.h"

/* What stands in a shaded mesh's way (shading with shadows): the masks and hits of the vertices
 * shaded (rows below), the scene they were cast against (the
 * exact lights' rays), and what the blockers send back through the blocked directions: bounce,
 * one RGB radiance per occluder vertex (its diffuse light: wenv_method.diffuse_light), read at each
 * hit between the hit triangle's vertices; or bounce_hits, one RGB radiance per hit of the occlusion
 * (hit order): what the blocker sends towards the vertex there, its glossy light included; or
 * bounce_self when the occluders' vertices are the shaded vertices, whose own diffuse light is then
 * used; none: blocked directions are black.  `key` changes whenever any of it does: what a
 * method keeps for it (per-vertex sums over the blocked texels) is kept while the key and the
 * lighting hold. */
typedef struct {
    const wenv_occlusion *occlusion;
    const wenv_occluders *occluders;
    const float *bounce;
    const float *bounce_hits;
    int bounce_self;
    uint64_t key;
    /* which of the occlusion's vertices row k of the shaded arrays is: rows[k], or offset + k when
     * rows is NULL (a block of a larger call, or a culled subset) */
    const uint32_t *rows;
    size_t offset;
    /* set by the lighting's frame (lighting_frame.h): a world direction into the frame the method
     * shades in (row-major), and what the bounce's radiance is scaled by there */
    float turn[9];
    float bounce_scale;
} wenv_shadow_scene;

/* Each vertex's own materials for what a method shades per vertex with the BRDF itself (a material
 * that varies per vertex, methods/material_family.h): vertex k is lit through the materials
 * palette[pick[WENV_VERTEX_LIGHTS_PICKS k + j]], each weighted per channel by
 * weight[3 (WENV_VERTEX_LIGHTS_PICKS k + j) + c] (0: not read).  palette_key changes whenever the
 * palette does, so a method may keep what it makes of each entry. */
#define WENV_VERTEX_LIGHTS_PICKS 3
typedef struct {
    const wenv_material *const *palette;
    size_t n_palette;
    uint64_t palette_key;
    const uint32_t *pick;
    const float *weight;
} wenv_vertex_lights;

/* One quality key: its name, its type and where it sits in the method's quality struct. */
typedef enum { WENV_PARAM_SIZE, WENV_PARAM_REAL } wenv_param_type;
typedef struct {
    const char *key;
    wenv_param_type type; /* size_t or double at `offset` */
    size_t offset;
} wenv_param;

/* One statistic a method reports (sizes, timings, what its cache did). */
typedef enum { WENV_STAT_COUNT, WENV_STAT_REAL, WENV_STAT_TEXT } wenv_stat_type;
typedef struct {
    const char *key;
    wenv_stat_type type;
    size_t count;
    double real;
    const char *text; /* static storage */
} wenv_stat;
#define WENV_STATS_MAX 24

/* The named presets every method has, from cheapest to most accurate. */
#define WENV_PRESET_COUNT 3
typedef enum { WENV_PRESET_DRAFT = 0, WENV_PRESET_DEFAULT = 1, WENV_PRESET_HIGH = 2 } wenv_preset;
extern const char *const WENV_PRESET_NAMES[WENV_PRESET_COUNT];

/* Where a method that keeps precomputed data on disk (the rotation matrices) keeps it. */
typedef enum {
    WENV_CACHE_DEFAULT = 0, /* $WENV_CACHE_DIR, else $XDG_CACHE_HOME/wenv, else ~/.cache/wenv (made if missing) */
    WENV_CACHE_NONE,        /* no disk cache */
    WENV_CACHE_FOLDER       /* cache_dir, which must be an existing folder */
} wenv_cache_mode;

typedef struct {
    wenv_cache_mode cache;
    const char *cache_dir;      /* WENV_CACHE_FOLDER only */
    const wenv_progress *progress; /* for work done while creating (may be NULL) */
    size_t memory_budget;       /* bytes precomputed data may take (0: no limit) */
} wenv_method_setup;

typedef struct wenv_method {
    const char *name;    /* as passed to wenv.Shader(method=...) */
    const char *summary; /* one line: what it is and after whom */
    size_t quality_size; /* bytes of its quality struct */
    const wenv_param *params;
    size_t n_params;
    const void *presets[WENV_PRESET_COUNT]; /* quality structs, WENV_PRESET_NAMES order */

    /* WENV_ERR_VALUE naming the key ("quality['order'] ...") unless the settings are usable. */
    wenv_status (*check_quality)(const void *quality, wenv_error *err);
    /* Makes the method's state for `quality` (checked); nothing is shaded until an environment and a
     * material are set.  May build or load precomputed data, reporting to setup->progress. */
    wenv_status (*create)(void **state, const void *quality, const wenv_method_setup *setup, wenv_error *err);
    void (*destroy)(void *state);
    /* Both leave the state as it was when they fail or are cancelled.  `progress` may be NULL. */
    wenv_status (*set_environment)(void *state, const wenv_envmap *env, const wenv_progress *progress,
                                   wenv_error *err);
    wenv_status (*set_material)(void *state, const wenv_material *mat, const wenv_progress *progress,
                                wenv_error *err);
    /* normals and views (surface towards eye): n x 3 floats, non-zero and finite, not necessarily
     * unit; out: n x 3 linear RGB radiance.  Needs an environment and a material set.
     * irradiance NULL: out is all of it.  Else out is all but the material's Lambertian part (not
     * clamped at 0) and irradiance (n x 3) the light that part reflects -- what arrives, cosine
     * weighted, with the shadows and the bounce -- so that a caller multiplies it by a colour of
     * its own per vertex (wenv_material_diffuse_per_colour_table). */
    wenv_status (*shade)(void *state, const float *normals, const float *views, size_t n, float *out,
                         float *irradiance, wenv_error *err);
    /* shade with the scene in the way (NULL for methods that model no shadows: they say so). */
    wenv_status (*shade_shadowed)(void *state, const float *normals, const float *views, size_t n,
                                  const wenv_shadow_scene *scene, float *out, float *irradiance, wenv_error *err);
    /* The diffuse light leaving each of n vertices (normals as for shade; scene NULL: unshadowed), RGB:
     * what the Lambertian part sends out head-on, the blockers' bounce for other meshes; irradiance
     * as for shade (the Lambertian part head-on left out).  NULL as above. */
    wenv_status (*diffuse_light)(void *state, const float *normals, size_t n, const wenv_shadow_scene *scene,
                                 float *out, float *irradiance, wenv_error *err);
    /* What a method shades per vertex with the material's own BRDF rather than through what it made of
     * it (the wavelet methods' exact lights), for a material that varies per vertex: with
     * set_lights_apart(state, 1), shade and shade_shadowed leave it out (they are then asked for
     * irradiance), and shade_lights adds it to out and irradiance (as shade's with irradiance), each
     * vertex lit through its own materials.  NULL for a method without such a part. */
    void (*set_lights_apart)(void *state, int apart);
    /* How many materials of the current one's size set_material keeps made (the current one among
     * them), so that a material that varies per vertex, which sets each member in turn, makes
     * nothing again at a new view when its members fit.  NULL for a method that keeps none. */
    size_t (*materials_kept)(const void *state);
    wenv_status (*shade_lights)(void *state, const float *normals, const float *views, size_t n,
                                const wenv_shadow_scene *scene, const wenv_vertex_lights *lights, float *out,
                                float *irradiance, wenv_error *err);
    /* Fills at most WENV_STATS_MAX entries; returns how many. */
    size_t (*stats)(const void *state, wenv_stat *out);
} wenv_method;

/* The registry (methods.c): every method, in the order they are documented. */
extern const wenv_method WENV_METHOD_ROTATION, WENV_METHOD_SLICING, WENV_METHOD_SPLIT_SUM, WENV_METHOD_SH;
size_t wenv_method_count(void);
const wenv_method *wenv_method_at(size_t i);
const wenv_method *wenv_method_named(const char *name); /* NULL if there is none */
/* The method whose quality keys and presets wenv.Shader reads unless told (wavelet rotation) ... */
const wenv_method *wenv_method_default(void);
/* ... and the one it then runs with that quality: rotation where its matrices are in the cache or
 * cheap to build (within the memory budget and about `default`'s size), else slicing, the same
 * shading without matrices -- so no preset builds gigabytes unasked. */
const wenv_method *wenv_method_choose_default(const void *quality, const wenv_method_setup *setup);

/* A method's preset by name (NULL if `name` is not a preset). */
const void *wenv_method_preset(const wenv_method *method, const char *name);

/* Statistic helpers for the methods' `stats` functions. */
static inline wenv_stat wenv_stat_count(const char *key, size_t value)
{
    return (wenv_stat){.key = key, .type = WENV_STAT_COUNT, .count = value};
}
static inline wenv_stat wenv_stat_real(const char *key, double value)
{
    return (wenv_stat){.key = key, .type = WENV_STAT_REAL, .real = value};
}
static inline wenv_stat wenv_stat_text(const char *key, const char *value)
{
    return (wenv_stat){.key = key, .type = WENV_STAT_TEXT, .text = value};
}

#endif
