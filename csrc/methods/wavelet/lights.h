/* Exact directional lights: the environment's brightest pixels, shaded per vertex.
 *
 * Why: a sun, a lamp or a softbox holds much of a scene's flux in few pixels, and wavelet
 * truncation and interpolation between samples smear their highlights.  Taken out of the lighting
 * and shaded as point lights at their pixel centres, they are exact in the reference's own sense
 * (wenv_reference sums the same pixels at the same centres; a lobe narrower than a pixel integrates
 * its area on a grid of points, where the reference integrates the lobe by its own rule).
 *
 * Cost is kept down two ways:
 *  - a tree of clusters: level 0 holds every pixel; level k merges the lights of level k - 1 whose
 *    directions lie within WENV_LIGHT_RADIUS(k) of a seed into one light at their flux-weighted
 *    centre, with the radius that holds them all;
 *  - a walk per vertex from the coarsest level down that reads a cluster whole where its error is
 *    small against the vertex's radiance: a cluster of radius r seen through a lobe w radians wide
 *    is off by about (r / w)^2 of its contribution near the lobe's peak, and by far less of the
 *    vertex's radiance out in the lobe's tail, so a sun under a narrow lobe is read pixel by pixel
 *    while a softbox in the tail is a few lights, and clusters wholly outside the lobe's cone or
 *    below the horizon are skipped whole. */
#ifndef WENV_LIGHTS_H
#define WENV_LIGHTS_H

#include <stddef.h>

#include "base/error.h"
#include "scene/envmap.h"
#include "scene/material.h"

#define WENV_LIGHT_LEVELS 9
/* Cluster radius of level k >= 1, radians: 0.25 degrees doubling per level, to 32 degrees. */
#define WENV_LIGHT_RADIUS(k) ((k) ? 0.25 * 0.017453292519943295 * (double)(1u << ((k) - 1)) : 0.0)

typedef struct wenv_lights wenv_lights;

/* px: the pixels taken out (wenv_envmap_brightest), brightest first.  n may be 0. */
wenv_status wenv_lights_create(wenv_lights **out, const wenv_bright_pixel *px, size_t n, wenv_error *err);
void wenv_lights_free(wenv_lights *lights);
/* Lights at a level (level 0: the pixels). */
size_t wenv_lights_count(const wenv_lights *lights, int level);

/* What the scene lets through to a vertex (methods/wavelet/shadows.c): `visible` says how much of a
 * light in direction l reaches it (0 or 1), and `at_edge` whether a shadow's edge may pass near l, so
 * that a cluster there is read by its parts down to sin_radius_edge, each with its own answer (a
 * shadow's edge as sharp as that: a sun's disk is one ray, a softbox's pixels a few); a cluster
 * whose radius's sine exceeds sin_radius_max is read by its parts anywhere, so that no edge hides
 * inside it.  NULL everywhere: nothing blocks. */
typedef struct wenv_light_visibility {
    float (*visible)(const struct wenv_light_visibility *vis, const float l[3]);
    int (*at_edge)(const struct wenv_light_visibility *vis, const float l[3]);
    float sin_radius_max;
    float sin_radius_edge; /* at an edge, clusters down to this radius are read by their parts */
} wenv_light_visibility;

/* Irradiance at unit normal n, added to e.  Clusters wholly above the horizon are exact as their
 * flux vectors (the cosine is linear in the direction); one across it is read whole when what its
 * lights below the horizon could add, its flux x its radius, is within `tolerance` (RGB summed),
 * else from its parts, down to the pixels' centres as the reference reads them. */
void wenv_lights_irradiance(const wenv_lights *lights, const float n[3], float tolerance,
                            const wenv_light_visibility *vis, float e[3]);

/* What the walk over the clusters needs to know of a material's lobes. */
typedef struct {
    double alpha;       /* the narrowest lobe's alpha (its width: wenv_material_lobe_width) */
    double cone_cos;    /* cosine of the half-angle about the mirror direction outside which every
                         * lobe is negligible (-1: none) */
    int modelled;       /* the lobes lie about the mirror direction and follow their shapes
                         * (wenv_material_lobes_follow_shapes): their width and tails bound a
                         * cluster's error */
    int narrow;         /* the lobe is narrower than WENV_NARROW_LOBE_PIXELS pixels: level 0 integrates
                         * pixels wider than it over their areas, as wenv_reference does */
    const float *peak;  /* modelled lobes: wenv_lights_peak_table's */
    const float *envelope; /* lobes not modelled: wenv_lights_envelope_table's (NULL: every pixel read) */
} wenv_lights_lobe;

/* The lobes' largest f cos (RGB summed) about the mirror direction, with a margin, at
 * WENV_LIGHT_PEAK_SAMPLES + 1 views uniform in sqrt(cos(theta_v)) from 0 to 1: it bounds what a
 * cluster can add, and depends on the view's angle alone (isotropic lobes), so it is made once per
 * material rather than per vertex.  alpha: wenv_lights_lobe's. */
#define WENV_LIGHT_PEAK_SAMPLES 64
void wenv_lights_peak_table(const wenv_material *mat, double alpha, float peak[WENV_LIGHT_PEAK_SAMPLES + 1]);

/* For lobes not modelled (tables), what bounds a cluster instead of the shape: the lobes' largest
 * f cos (RGB summed) over light directions at least WENV_LIGHT_ENVELOPE_ANGLE(j) from the mirror
 * direction, with a margin, sampled at the peak table's views (row i) and nearer deviations, so a
 * cluster far out in a measured lobe's tail is read whole as a modelled lobe's is.  Rows of
 * WENV_LIGHT_ENVELOPE_BINS, each non-increasing. */
#define WENV_LIGHT_ENVELOPE_BINS 32
#define WENV_LIGHT_ENVELOPE_ANGLE(j) \
    (3.14159265358979323846 * ((double)(j) / (WENV_LIGHT_ENVELOPE_BINS - 1)) * ((double)(j) / (WENV_LIGHT_ENVELOPE_BINS - 1)))
void wenv_lights_envelope_table(const wenv_material *mat,
                                float envelope[(WENV_LIGHT_PEAK_SAMPLES + 1) * WENV_LIGHT_ENVELOPE_BINS]);

/* The lobes' reflected radiance at unit normal n and view v (n . v = cos_v > 0), added to s.
 * cos_h_min[k]: lobe k's n.h below which it is negligible.  Clusters are read whole where their
 * estimated error (RGB summed) is within `tolerance`, else their parts, down to the pixels. */
void wenv_lights_specular(const wenv_lights *lights, const wenv_material *mat, const float *cos_h_min,
                          const wenv_lights_lobe *lobe, const float n[3], const float v[3], float cos_v,
                          float tolerance, const wenv_light_visibility *vis, float s[3]);

#endif
