/* What the wavelet shader's files share (wavelet.c: the shader and its lighting; brdf_slices.c: the
 * material's slices; vertex_shading.c: the table and the vertices).  Private to methods/wavelet/. */
#ifndef WENV_WAVELET_STATE_H
#define WENV_WAVELET_STATE_H

#include <stddef.h>
#include <stdint.h>

#include "methods/wavelet/grazing.h"
#include "methods/wavelet/irradiance.h"
#include "methods/wavelet/light_lobes.h"
#include "methods/wavelet/lights.h"
#include "methods/wavelet/rotation.h"
#include "methods/wavelet/shadows.h"
#include "methods/wavelet/slice_operators.h"
#include "methods/wavelet/wavelet.h"

/* One material's part of the shader (brdf_slices.c): its BRDF slices, what the exact lights and the
 * grazing path read of it, and its (normal sample, view sample) radiance table, made a row (a normal
 * sample, every view) at a time.  The shader keeps the last few, so that meshes of a few materials
 * shaded in turn each make their slices once while the lighting holds. */
typedef struct {
    wenv_material *mat;      /* for the direct lights, and to recognise the material set again */
    size_t serial;           /* the shader's count of materials made, at this one's making */
    int mirror_centred;      /* normal samples keep the vertex's mirror direction (else its view) */
    wenv_light_lobes light;  /* what the exact lights read of it */
    float *albedo;           /* ALBEDO_N x 3: specular albedo at cos(view) = WENV_GRAZING_Z .. 1 */
    float *view_inv_albedo;  /* nv x 3: 1 / albedo of each view sample (0 where the albedo is 0) */
    wenv_diffuse_table diffuse; /* the Lambertian part's albedo / pi over the view's cosine */
    int has_diffuse, has_lobes; /* what the exact lights shade per vertex */
    wenv_grazing_rule *grazing_rule; /* NULL: no lobe is integrated per vertex */
    size_t *brdf_start;      /* nv + 1 */
    uint32_t *brdf_idx;
    float *brdf_rgb;
    size_t brdf_terms;
    float *table;            /* ns x nv x 3 */
    wenv_texel_reflection texel_reflection; /* shading with shadows: made for the masks' resolution */
    wenv_texel_reflection texel_reflection_before; /* the one of the resolution before: a bake's texels
                                                     * and vertices take turns at two */
    int lobes_narrow;        /* ... and whether its lobes are narrow against the masks' texels */
    float lobe_alpha;        /* the widest lobe's alpha (a narrow lobe's rays, shadows.h) */
    unsigned char *row_ready, *row_need; /* per normal sample, as slice_ready and slice_need */
    unsigned char *row_asked; /* per normal sample: read as entries since the row went stale (vertex_shading.c) */
} wenv_wavelet_material;

/* Sub-samples of the local map's texels, k x k per texel in texel order, with their tent taps. */
typedef struct {
    size_t k, count;
    float *dirs;    /* count x 3 */
    uint32_t *taps; /* count x 4 */
    float *w;       /* count x 4: tent weight x solid angle x normalisation */
} wenv_texel_rule;

struct wenv_wavelet {
    wenv_wavelet_quality q;
    wenv_wavelet_variant method;
    size_t ng, nl, ns, nv;
    wenv_rotation *rot;      /* rotation method only */
    wenv_resampler *resampler; /* slicing method only */
    wenv_slice_operators *slice_ops; /* slicing method only: S_s of each orbit of samples, kept */
    float *frames;           /* ns x 9 */
    wenv_wavelet_stats stats;

    /* lighting */
    int have_env;
    uint32_t *light_idx;     /* kept global Haar coefficients */
    float *light_rgb;
    size_t light_count;
    float *global_rgbx;      /* slicing: the kept lighting back in the pixel domain, r g b and a pad */
    float **slices;          /* ns pointers to nl x 3 Haar coefficients, NULL until needed */
    float *irradiance;       /* ns x 3, every normal sample's, made with the lighting */
    wenv_irradiance_rule *irradiance_rule;
    float radiance_max[3];   /* brightest texel of the lighting the slices see (lights out) */
    wenv_lights *lights;     /* pixels taken out as exact directional lights (lights.h) */
    float mean_radiance;     /* the environment's, lights included (channels averaged) */
    double narrow_alpha; /* lobes narrower than this integrate the lights' pixel areas (envmap.h) */
    unsigned char *slice_ready, *slice_need; /* ready: 0 stale, READY, or USED (see READY) */
    wenv_grazing_light *grazing_light; /* made while the current material reads it (NULL otherwise) */
    wenv_envmap *image;      /* the lighting's image (shared with the caller's, not copied) and the */
    size_t *excluded;        /* pixels the lights took out (ascending), for a pyramid made later */
    size_t n_excluded;

    /* local quadrature: 2 x 2 sub-samples per texel, and for a lobe too narrow for them a finer
     * rule, read near the lobe, with a 2 x 2 rule weighted like it per texel for the rest
     * (brdf_slices.c) */
    wenv_texel_rule quad, fine, fine_coarse;
    float *texel_centre;     /* nl x 3: each local texel's centre direction */

    /* shading with shadows (shadows.h): per blocked texel the hidden lighting, and per mask its
     * cosine-weighted sum, kept while the lighting and the occlusion hold; the same less the
     * blocker's light, kept while the scene's key holds too (and, when a mesh's own diffuse light is
     * its bounce, the material) */
    int shadowing;            /* shaded with shadows since made: a new lighting makes the pyramid too */
    int shadow_env_valid;
    uint64_t shadow_env_key;
    float *shadow_lbar;       /* hits x 3 */
    float *shadow_e_env;      /* masks x 3 */
    wenv_light_memo *shadow_lights; /* the lights' rays' answers (written while shading), kept with the
                                     * hidden lighting */
    int shadow_valid;
    uint64_t shadow_key;
    size_t shadow_material;   /* the serial of the material whose diffuse light the bounce is (0: none) */
    size_t material_serial;
    float *shadow_hidden;     /* hits x 3 */
    float *shadow_e_hidden;   /* masks x 3 */

    /* a material that varies per vertex (method.h's shade_lights): whether shade leaves the lights
     * out, and what the lights read of each vertex's materials, kept while the palette's key holds */
    int lights_apart;
    wenv_material **palette_mat; /* copies */
    wenv_light_lobes *palette;
    unsigned char *palette_made;
    size_t n_palette;
    uint64_t palette_key;

    /* materials: the current one first, then those set before it, most recent first */
    wenv_wavelet_material *kept[WENV_WAVELET_KEPT_MATERIALS];
    size_t n_kept;
    wenv_wavelet_material *m; /* kept[0], the current material; NULL before the first */
};

/* States of a lighting slice or table row: made (READY), and made and read by the latest shade
 * call (USED), which a new lighting or material remakes at once.  Marking use on the read that
 * checks readiness costs nothing extra per vertex. */
#define READY 1
#define USED 2

/* Entries of the specular albedo table, uniform in cos(view): 1/256 apart is 0.22 degrees at the
 * horizon, where the albedo changes fastest. */
#define ALBEDO_N 257
#define ALBEDO_SAMPLES 32


/* Specular albedo at cos(view) = c, linear in the table. */
static inline void wenv_wavelet_albedo_at(const float *table, float c, float a[3])
{
    float x = (c - (float)WENV_GRAZING_Z) * (float)(ALBEDO_N - 1) / (1.0f - (float)WENV_GRAZING_Z);
    x = x < 0.0f ? 0.0f : (x > (float)(ALBEDO_N - 1) ? (float)(ALBEDO_N - 1) : x);
    long i = (long)x;
    if (i > ALBEDO_N - 2)
        i = ALBEDO_N - 2;
    float f = x - (float)i;
    for (int k = 0; k < 3; k++)
        a[k] = (1.0f - f) * table[3 * i + k] + f * table[3 * (i + 1) + k];
}

/* brdf_slices.c: the local map's sub-sample quadrature (k x k per texel), and freeing it and a
 * material's part; the bytes a material's part holds. */
wenv_status wenv_wavelet_build_quadrature(wenv_wavelet *wavelet, wenv_error *err);
void wenv_wavelet_free_quadrature(wenv_wavelet *wavelet);
void wenv_wavelet_material_free(wenv_wavelet_material *m);
size_t wenv_wavelet_material_bytes(const wenv_wavelet *wavelet, const wenv_wavelet_material *m);

/* A material's table and its rows' three states (ready, needed, asked). */
static inline size_t wenv_wavelet_table_bytes(const wenv_wavelet *wavelet)
{
    return wavelet->ns * (wavelet->nv * 3 * sizeof(float) + 3);
}

/* vertex_shading.c: after a new lighting (lighting = 1) or a material made current, remakes at once
 * what the latest shade call read; a new lighting marks the rest stale. */
/* table_rows.c: the table rows of the n normal samples rows[] (their lighting slices made); one entry,
 * (normal sample s, view sample j), on its own: the row's value to the bit. */
wenv_status wenv_wavelet_fill_rows(wenv_wavelet *wavelet, const size_t *rows, size_t n, wenv_error *err);
void wenv_wavelet_table_entry(const wenv_wavelet *wavelet, size_t s, size_t j, float rgb[3]);
wenv_status wenv_wavelet_remake_ready(wenv_wavelet *wavelet, int lighting, wenv_error *err);

/* vertex_shading.c: frees what the lights keep of a palette. */
void wenv_wavelet_palette_free(wenv_wavelet *wavelet);

/* wavelet.c: makes the grazing path's pyramid of the lighting if the current material reads it and
 * it is not made: a diffuse material never pays for it, and one with lobes made current later
 * does. */
wenv_status wenv_wavelet_ensure_grazing(wenv_wavelet *wavelet, wenv_error *err);
/* ... and whatever the material, for the shadows' hidden lighting. */
wenv_status wenv_wavelet_ensure_pyramid(wenv_wavelet *wavelet, wenv_error *err);

#endif
