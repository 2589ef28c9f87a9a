#include "methods/lighting_frame.h"

#include "methods/lamps/lamp_shading.h"
#include "methods/emission.h"

#include "base/fingerprint.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* The frame of env's rotation and strength about the held image. */
static void follow(wenv_lighting_frame *frame, const wenv_envmap *env)
{
    /* measured against the unrotated image: R_z(rotation) takes a world direction to it */
    double r = wenv_envmap_rotation(env), c = cos(r), s = sin(r);
    float turn[9] = {(float)c, (float)-s, 0.0f, (float)s, (float)c, 0.0f, 0.0f, 0.0f, 1.0f};
    memcpy(frame->turn, turn, sizeof turn);
    frame->scale = frame->held_strength > 0.0 ? (float)(wenv_envmap_strength(env) / frame->held_strength) : 0.0f;
    frame->identity = r == 0.0 && frame->scale == 1.0f;
}

static int holds(const wenv_lighting_frame *frame, const wenv_envmap *env, uint64_t hash)
{
    return frame->have && hash == frame->image_hash && wenv_envmap_width(env) == frame->width &&
           wenv_envmap_height(env) == frame->height && wenv_envmap_projection(env) == frame->projection;
}

wenv_status wenv_lighting_frame_set(wenv_lighting_frame *frame, const wenv_method *method, void *state,
                                    const wenv_envmap *env, const wenv_progress *progress, wenv_error *err)
{
    uint64_t hash = wenv_envmap_fingerprint(env);
    if (holds(frame, env, hash) && (frame->held_strength == 1.0 || wenv_envmap_strength(env) == frame->held_strength)) {
        follow(frame, env);
        return WENV_OK;
    }
    /* an image too bright for strength 1 is held at the World's own strength (and given anew
     * when that changes) */
    wenv_envmap *canonical = NULL;
    wenv_error ignored = {0};
    double held = 1.0;
    if (wenv_envmap_with_transform(&canonical, env, 0.0, 1.0, &ignored) != WENV_OK) {
        held = wenv_envmap_strength(env);
        if (wenv_envmap_with_transform(&canonical, env, 0.0, held, err) != WENV_OK)
            return err->status;
    }
    wenv_status st = method->set_environment(state, canonical, progress, err);
    wenv_envmap_free(canonical);
    if (st)
        return st;
    frame->have = 1;
    frame->image_hash = hash;
    frame->width = wenv_envmap_width(env);
    frame->height = wenv_envmap_height(env);
    frame->projection = wenv_envmap_projection(env);
    frame->held_strength = held;
    follow(frame, env);
    return WENV_OK;
}

static void turn_all(const float t[9], const float *in, size_t n, float *out)
{
    for (size_t i = 0; i < n; i++) {
        const float *a = in + 3 * i;
        float *b = out + 3 * i;
        b[0] = t[0] * a[0] + t[1] * a[1] + t[2] * a[2];
        b[1] = t[3] * a[0] + t[4] * a[1] + t[5] * a[2];
        b[2] = t[6] * a[0] + t[7] * a[1] + t[8] * a[2];
    }
}

/* method->shade, or method->shade_shadowed with `scene`, or with views NULL method->diffuse_light,
 * under the frame. */
static wenv_status run_split(const wenv_method *method, void *state, const float *normals, const float *views,
                             size_t n, const wenv_shadow_scene *scene, float *out, float *irradiance,
                             wenv_error *err)
{
    if (views && !scene)
        return method->shade(state, normals, views, n, out, irradiance, err);
    if (!views)
        return method->diffuse_light(state, normals, n, scene, out, irradiance, err);
    return method->shade_shadowed(state, normals, views, n, scene, out, irradiance, err);
}

/* The same, each vertex given its colour when `colour` is set, its material when `family` is. */
static wenv_status run(const wenv_method *method, void *state, const float *normals, const float *views, size_t n,
                       const wenv_shadow_scene *scene, const wenv_vertex_colour *colour,
                       const wenv_family_rows *family, float *out, wenv_error *err)
{
    if (family)
        return wenv_material_family_shade(family, method, state, normals, views, n, scene, colour ? colour->rgb : NULL,
                                          colour ? colour->share : NULL, colour ? colour->horizon_light : NULL, out,
                                          err);
    if (!colour)
        return run_split(method, state, normals, views, n, scene, out, NULL, err);
    float *irradiance = malloc(n * 3 * sizeof(float));
    if (!irradiance)
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for the irradiance of %zu vertices", n);
    wenv_status st = run_split(method, state, normals, views, n, scene, out, irradiance, err);
    if (!st)
        wenv_vertex_colour_apply(colour, normals, views, n, irradiance, out);
    free(irradiance);
    return st;
}

wenv_status wenv_lighting_frame_shade_scene(const wenv_lighting_frame *frame, const wenv_method *method, void *state,
                                            const float *normals, const float *views, size_t n,
                                            const wenv_shadow_scene *scene, const wenv_vertex_colour *colour,
                                            const wenv_family_rows *family, const wenv_material *material,
                                            const float *emission, const wenv_lamp_rows *lamps, float *out,
                                            wenv_error *err)
{
    wenv_shadow_scene held;
    if (scene) {
        /* the masks and rays stay in the world: the method turns between them and its frame */
        held = *scene;
        for (int k = 0; k < 9; k++)
            held.turn[k] = frame->identity ? (float)(k % 4 == 0) : frame->turn[k];
        held.bounce_scale = frame->identity ? 1.0f : (frame->scale > 0.0f ? 1.0f / frame->scale : 0.0f);
        held.key = wenv_fingerprint_floats(wenv_fingerprint_word(scene->key, 0x7475726eu), held.turn, 9);
        held.key = wenv_fingerprint_floats(held.key, &held.bounce_scale, 1);
        scene = &held;
    }
    wenv_status st = WENV_OK;
    /* a bent Lambertian part keeps its share of a uniform sky and loses that share of the light at
     * the smooth horizon towards its bend, read as the irradiance at that horizon (vertex_colour.h;
     * a method without diffuse light loses the share of the part's own light) */
    int turn = !frame->identity && n > 0;
    int bent = colour && colour->bump.smooth && n > 0, horizon = bent && method->diffuse_light;
    float *turned = turn ? malloc(n * (horizon ? 9 : 6) * sizeof(float)) : NULL;
    /* the shares, then the horizons, their light, and the diffuse pass's other output */
    float *bump_rows = bent ? malloc(n * (horizon ? 10 : 1) * sizeof(float)) : NULL;
    if ((turn && !turned) || (bent && !bump_rows)) {
        free(turned);
        free(bump_rows);
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory turning %zu normals and views", n);
    }
    float *horizons = horizon ? bump_rows + n : NULL, *horizon_light = horizon ? bump_rows + 4 * n : NULL;
    wenv_vertex_colour with_bump;
    if (bent) {
        wenv_bump_share_rows(normals, colour->bump.smooth, n, colour->bump.correction, bump_rows);
        if (horizon)
            wenv_bump_horizons(normals, colour->bump.smooth, n, horizons);
        with_bump = *colour;
        with_bump.share = bump_rows;
        with_bump.horizon_light = horizon_light;
    }
    const float *at_normals = normals, *at_views = views, *at_horizons = horizons;
    if (turn) {
        turn_all(frame->turn, normals, n, turned);
        at_normals = turned;
        if (views)
            turn_all(frame->turn, views, n, turned + 3 * n);
        at_views = views ? turned + 3 * n : NULL;
        if (horizon)
            turn_all(frame->turn, horizons, n, turned + 6 * n);
        at_horizons = horizon ? turned + 6 * n : NULL;
    }
    if (horizon)
        st = run_split(method, state, at_horizons, NULL, n, scene, bump_rows + 7 * n, horizon_light, err);
    if (!st)
        st = run(method, state, at_normals, at_views, n, scene, bent ? &with_bump : colour, family, out, err);
    if (!st && turn && frame->scale != 1.0f)
        for (size_t i = 0; i < 3 * n; i++)
            out[i] *= frame->scale;
    free(turned);
    free(bump_rows);
    /* lamps and emission in the world: the frame turns both normal and view, but not the lamps */
    if (!st && lamps && material)
        st = wenv_lamps_add(lamps, material, colour, family, normals, views, n, out, err);
    /* a material per vertex emits through each vertex's own layers */
    if (!st && family)
        st = wenv_material_family_add_emission(family, normals, views, n, emission, out, err);
    else if (!st && material)
        st = wenv_emission_add(material, emission, normals, views, n, out, err);
    return st;
}

wenv_status wenv_lighting_frame_shade(const wenv_lighting_frame *frame, const wenv_method *method, void *state,
                                      const float *normals, const float *views, size_t n, float *out,
                                      wenv_error *err)
{
    return wenv_lighting_frame_shade_scene(frame, method, state, normals, views, n, NULL, NULL, NULL, NULL, NULL, NULL,
                                           out, err);
}
