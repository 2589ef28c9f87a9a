/* A scene's lamp (a Blender Light object) as Cycles emits it: sun, point, spot and area, in
 * Blender's units and settings, made into what shading reads -- a uniform emitter, its radiance,
 * and a factor per direction (a spot's cone, an area lamp's spread).
 *
 * Cycles' conventions (intern/cycles/scene/light.cpp and kernel/light/, docs/lamps.md):
 *  - strength S = colour x energy x 2^exposure (the temperature's colour is the caller's, in colour);
 *  - sun: a disk of half-angle angle/2 about the object's -Z, radiance S / (pi sin^2(angle/2)) (an
 *    irradiance of S head-on); angle 0 is a direction, irradiance S;
 *  - point and spot: radius r (shadow_soft_size; object scale ignored).  With Soft Falloff, a disk
 *    of radius r at the lamp facing the shaded point; without, a sphere; either of radiance
 *    S / (4 pi^2 r^2).  Radius 0: intensity S / (4 pi).  A spot multiplies by
 *    smoothstep((z - cos(size / 2)) / ((1 - cos(size / 2)) blend)), z the direction of the light
 *    leaving the lamp in the object's scaled frame (-Z its axis), per point of the lamp;
 *  - area: square, rectangle, disk or ellipse in the object's xy (scaled), emitting from its -Z side
 *    only, radiance S / (pi A) times the spread's max(0, (tan h - tan theta) / (tan h - h)),
 *    h = spread / 2, theta the angle from the lamp's -Z;
 *  - normalize off (Blender 4.5+): the 1 / area factors are left out (S / pi for point, spot and
 *    area; S for the sun).
 * The World's strength does not scale a lamp. */
#ifndef WENV_LAMP_H
#define WENV_LAMP_H

#include <stddef.h>
#include <stdint.h>

#include "base/error.h"
#include "scene/occluders.h"

typedef enum { WENV_LAMP_SUN = 0, WENV_LAMP_POINT, WENV_LAMP_SPOT, WENV_LAMP_AREA } wenv_lamp_kind;
typedef enum { WENV_LAMP_SQUARE = 0, WENV_LAMP_RECTANGLE, WENV_LAMP_DISK, WENV_LAMP_ELLIPSE } wenv_lamp_shape;

/* The narrowest spread shaded (radians): below it an area lamp is a beam. */
#define WENV_LAMP_SPREAD_MIN 1e-3

/* A Light object's settings, named as Blender names them. */
typedef struct {
    wenv_lamp_kind kind;
    double matrix[16];   /* the object's matrix_world, row-major: location in the last column */
    double color[3];     /* linear RGB, times the temperature's colour where the light uses one */
    double energy;       /* W (sun: W/m^2) */
    double exposure;     /* stops: the energy is scaled by 2^exposure */
    int normalize;       /* power independent of the size (Blender's default) */
    double radius;       /* point, spot: shadow_soft_size (m) */
    int soft_falloff;    /* point, spot: use_soft_falloff */
    double angle;        /* sun: the disk's angular diameter (rad) */
    double spot_size;    /* spot: the cone's full angle (rad) */
    double spot_blend;   /* spot: [0, 1] */
    wenv_lamp_shape shape; /* area */
    double size, size_y; /* area: sizes along the object's x and y (m; size_y for rectangles and ellipses) */
    double spread;       /* area: (0, pi] (rad) */
    int cast_shadow;     /* use_shadow */
    int diffuse, glossy; /* the object's ray visibility: whether diffuse and glossy reflection see it */
} wenv_lamp_settings;

/* Blender's defaults for a new Light of `kind` at the origin, unrotated (energy 10; radius 0.1...). */
void wenv_lamp_settings_defaults(wenv_lamp_settings *s, wenv_lamp_kind kind);

/* What shading reads of a lamp. */
typedef struct {
    wenv_lamp_settings settings;
    double position[3];
    double emit_dir[3];      /* the way its light travels: the object's -Z, unit (sun, spot, area) */
    double half_u[3], half_v[3]; /* area: half the shape along the object's x and y, scaled */
    int ellipse;             /* area: disk or ellipse */
    double area;             /* area: of the shape */
    int delta;               /* a point (radius 0) or a direction (sun of angle 0) */
    int sphere;              /* point, spot: a sphere (Soft Falloff off) */
    double sun_tan;          /* sun: tan of the disk's half-angle */
    double spot_local[9];    /* spot: a world direction into the object's scaled frame (row-major) */
    double spot_cos, spot_band; /* spot: cos of the half-angle, and the blend's width in cos */
    double spot_stretch;     /* spot: how much its scale may widen an angle (the longest axis over the shortest) */
    double spread_tan, spread_norm; /* area: tan h and 1 / (tan h - h); spread_tan 0: no spread */
    double radiance[3];      /* of the emitting surface; a point: its intensity; a direction: irradiance */
    /* what blocks this lamp's light where a scene is shadowed, in place of the scene's occluders (a
     * Light's shadow linking; NULL: the scene's); borrowed for one call, never kept */
    const wenv_occluders *blockers;
} wenv_lamp;

/* Made from settings: WENV_ERR_VALUE naming the setting after `name` ("Lamp.energy must be finite
 * and >= 0, got -1") for a value out of Blender's range or not finite, or a matrix that cannot carry
 * the lamp (a spot's singular scale, a sun's zero Z axis). */
wenv_status wenv_lamp_make(wenv_lamp *out, const wenv_lamp_settings *settings, const char *name, wenv_error *err);

/* The factor on the radiance of light leaving the lamp towards `toward_vertex` (a unit direction
 * from the lamp's point to the shaded point): a spot's cone, an area lamp's spread and side; 1
 * otherwise.  within_sphere: the shaded point is inside a spot's sphere (no cone there). */
double wenv_lamp_factor(const wenv_lamp *lamp, const double toward_vertex[3], int within_sphere);

/* Whether the factor may vary over the lamp as one point sees it (a spot's cone, a partial spread). */
int wenv_lamp_factor_varies(const wenv_lamp *lamp);

/* Whether it is the same for every direction within `angle` radians of toward_vertex: a spot's cone
 * edge and blend well away from them (what lets a lamp that looks wide be read at its centre). */
int wenv_lamp_factor_even(const wenv_lamp *lamp, const double toward_vertex[3], double angle, int within_sphere);

/* Of what decides where its light falls and what blocks it (not its colour or power; its own
 * blockers by their fingerprint): what a cache of its shadows is kept against. */
uint64_t wenv_lamp_geometry_key(const wenv_lamp *lamp, uint64_t h);

/* What blocks the lamp's light in a scene shadowed by `scene` (NULL: unshadowed): nothing when it
 * casts no shadow, its own blockers where it has them, else the scene's. */
const wenv_occluders *wenv_lamp_blockers(const wenv_lamp *lamp, const wenv_occluders *scene);

#endif
