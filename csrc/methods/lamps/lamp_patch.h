/* A lamp as one shaded point sees it: a flat, uniformly bright patch -- a rectangle or an ellipse --
 * whose directions are the lamp's, with a factor per direction (lamp.h's wenv_lamp_factor).
 *
 * Why one form: an area lamp is one; a soft-falloff point or spot is a disk facing the point; a
 * sphere is seen through the circle where the cone of its silhouette touches it, a disk of the
 * same directions; a sun is a disk of its directions one unit away.  So one closed form gives the
 * Lambertian part (math/projected_solid_angle.h) and one grid of points the rest, for every lamp. */
#ifndef WENV_LAMP_PATCH_H
#define WENV_LAMP_PATCH_H

#include "scene/lamp.h"

typedef struct {
    double centre[3];   /* relative to the shaded point */
    double u[3], v[3];  /* half axes */
    double normal[3];   /* unit, facing the shaded point's side */
    int ellipse;
    int facing;         /* a circle square to the line from the point: its directions are a cap */
    int infinite;       /* a sun's: rays to it have no end */
    int within_sphere;  /* the point is within a point or spot lamp's radius (a spot's cone is not applied) */
    double area;
} wenv_lamp_patch;

/* The patch of a lamp that is not a delta (lamp->delta 0) seen from p; 0 when none of its light
 * can reach p (behind an area lamp, at a lamp's centre, a lamp of no area). */
int wenv_lamp_patch_at(const wenv_lamp *lamp, const double p[3], wenv_lamp_patch *patch);

/* The point of the patch at (s, t) in [-1, 1]^2 (an ellipse's by Shirley and Chiu's concentric map,
 * which keeps areas: equal squares are equal parts of it), relative to the shaded point. */
void wenv_lamp_patch_point(const wenv_lamp_patch *patch, double s, double t, double x[3]);

/* How far across it looks from the shaded point, in radians (about). */
double wenv_lamp_patch_angle(const wenv_lamp_patch *patch);

/* The projected solid angle of the whole patch (above the horizon of `normal`), or of its cell
 * (i, j) of a k x k grid over [-1, 1]^2. */
double wenv_lamp_patch_psa(const wenv_lamp_patch *patch, const double normal[3]);
double wenv_lamp_patch_cell_psa(const wenv_lamp_patch *patch, size_t k, size_t i, size_t j, const double normal[3]);

#endif
