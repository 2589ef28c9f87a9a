#include "reference/lamps_reference.h"

#include "scene/bump_terminator.h"

#include <math.h>

static double dot3(const double a[3], const double b[3]) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }

/* A unit frame about unit d: x, y across it. */
static void basis(const double d[3], double x[3], double y[3])
{
    double a[3] = {0.0, 0.0, 0.0};
    a[fabs(d[0]) < 0.6 ? 0 : (fabs(d[1]) < 0.6 ? 1 : 2)] = 1.0;
    double c[3] = {a[1] * d[2] - a[2] * d[1], a[2] * d[0] - a[0] * d[2], a[0] * d[1] - a[1] * d[0]};
    double l = sqrt(dot3(c, c));
    for (int k = 0; k < 3; k++)
        x[k] = c[k] / l;
    y[0] = d[1] * x[2] - d[2] * x[1];
    y[1] = d[2] * x[0] - d[0] * x[2];
    y[2] = d[0] * x[1] - d[1] * x[0];
}

typedef struct {
    const wenv_material *mat;
    const double *nrm, *f, *wo;
    const wenv_occluders *occ;
    const float *origin;
    const double *smooth;
    int correction;
    int diffuse, glossy;
    double spec[3], irr[3]; /* per unit radiance of the lamp, before its colour */
} sum;

/* One point of the lamp: direction w (unit, world), weight (solid angle, or what a delta lamp gives
 * instead), ray length t (INFINITY: the sky). */
static void add(sum *s, const double w[3], double weight, double t)
{
    double cos_i = dot3(s->nrm, w);
    if (!(cos_i > 0.0) || !(weight > 0.0))
        return;
    if (s->occ) {
        float dir[3] = {(float)w[0], (float)w[1], (float)w[2]};
        unsigned char blocked = 0;
        wenv_occluders_test(s->occ, s->origin, dir, 1, isinf(t) ? INFINITY : (float)(t * (1.0 - 1e-4)), &blocked);
        if (blocked)
            return;
    }
    if (s->diffuse) {
        double through = s->smooth ? wenv_bump_diffuse_weight(s->nrm, s->smooth, w, s->correction) : 1.0;
        for (int c = 0; c < 3; c++)
            s->irr[c] += weight * cos_i * through;
    }
    if (s->glossy) {
        double wi[3] = {dot3(s->f, w), dot3(s->f + 3, w), dot3(s->f + 6, w)}, rgb[3];
        wenv_material_specular_cos(s->mat, wi, s->wo, rgb);
        for (int c = 0; c < 3; c++)
            s->spec[c] += weight * rgb[c];
    }
}

/* The directions of a cone of half-angle with cosine cos_a about unit d, on a grid uniform in
 * (cos theta, phi): equal solid angles. */
static void cone(sum *s, const wenv_lamp *l, const double d[3], double cos_a, size_t grid, int within, double radius,
                 const double centre_rel[3], int infinite)
{
    double x[3], y[3];
    basis(d, x, y);
    double d_omega = (1.0 - cos_a) * 2.0 * M_PI / (double)(grid * grid);
    for (size_t i = 0; i < grid; i++) {
        double c = 1.0 - (1.0 - cos_a) * ((double)i + 0.5) / (double)grid, sn = sqrt(fmax(0.0, 1.0 - c * c));
        for (size_t j = 0; j < grid; j++) {
            double phi = 2.0 * M_PI * ((double)j + 0.5) / (double)grid;
            double w[3];
            for (int k = 0; k < 3; k++)
                w[k] = c * d[k] + sn * (cos(phi) * x[k] + sin(phi) * y[k]);
            double t = INFINITY;
            if (!infinite) { /* to the sphere's near side along w */
                double b = dot3(w, centre_rel), cc = dot3(centre_rel, centre_rel) - radius * radius;
                double disc = b * b - cc;
                t = within ? b + sqrt(fmax(0.0, disc)) : b - sqrt(fmax(0.0, disc));
            }
            double back[3] = {-w[0], -w[1], -w[2]};
            add(s, w, d_omega * (l ? wenv_lamp_factor(l, back, within) : 1.0), t);
        }
    }
}

/* Points of a flat shape (centre c relative to p, half axes u and v, an ellipse or a rectangle), on
 * a grid of equal areas: a rectangle's cells, an ellipse's rings and sectors. */
static void flat(sum *s, const wenv_lamp *l, const double c[3], const double u[3], const double v[3], int ellipse,
                 double area, const double normal[3], size_t grid, int within)
{
    double da = area / (double)(grid * grid);
    for (size_t i = 0; i < grid; i++)
        for (size_t j = 0; j < grid; j++) {
            double a, b;
            if (ellipse) {
                double r = sqrt(((double)i + 0.5) / (double)grid), phi = 2.0 * M_PI * ((double)j + 0.5) / (double)grid;
                a = r * cos(phi);
                b = r * sin(phi);
            } else {
                a = -1.0 + 2.0 * ((double)i + 0.5) / (double)grid;
                b = -1.0 + 2.0 * ((double)j + 0.5) / (double)grid;
            }
            double x[3];
            for (int k = 0; k < 3; k++)
                x[k] = c[k] + a * u[k] + b * v[k];
            double t = sqrt(dot3(x, x)), w[3] = {x[0] / t, x[1] / t, x[2] / t};
            double cos_l = -dot3(normal, w);
            if (!(cos_l > 0.0))
                continue;
            double back[3] = {-w[0], -w[1], -w[2]};
            add(s, w, da * cos_l / (t * t) * wenv_lamp_factor(l, back, within), t);
        }
}

void wenv_reference_lamps_at(const wenv_lamp *lamps, size_t n_lamps, const wenv_material *mat, const double p[3],
                             const double nrm[3], const double f[9], const double wo[3], const wenv_occluders *occ,
                             const float origin[3], const double *smooth, int correction, double spec[3],
                             double irr[3])
{
    double alpha = wenv_material_lobe_width(mat);
    for (size_t j = 0; j < n_lamps; j++) {
        const wenv_lamp *l = &lamps[j];
        const wenv_lamp_settings *st = &l->settings;
        sum s = {.mat = mat,         .nrm = nrm,
                 .f = f,             .wo = wo,
                 .occ = wenv_lamp_blockers(l, occ),
                 .origin = origin,   .smooth = smooth,
                 .correction = correction,
                 .diffuse = st->diffuse,
                 .glossy = st->glossy && wo[2] > 0.0};
        double rel[3] = {l->position[0] - p[0], l->position[1] - p[1], l->position[2] - p[2]};
        double d = sqrt(dot3(rel, rel)), to[3] = {rel[0] / d, rel[1] / d, rel[2] / d};
        /* the lamp's angular size against the lobe sets the grid */
        double across = 0.0;
        if (st->kind == WENV_LAMP_SUN)
            across = 0.5 * st->angle;
        else if (st->kind == WENV_LAMP_AREA)
            across = atan2(sqrt(dot3(l->half_u, l->half_u) + dot3(l->half_v, l->half_v)), d);
        else
            across = atan2(st->radius, d);
        double want = isfinite(alpha) ? 12.0 * across / alpha : 0.0;
        size_t grid = want > WENV_REFERENCE_LAMP_GRID ? (size_t)ceil(fmin(want, WENV_REFERENCE_LAMP_GRID_MAX))
                                                      : WENV_REFERENCE_LAMP_GRID;
        if (st->kind == WENV_LAMP_SUN) {
            double towards[3] = {-l->emit_dir[0], -l->emit_dir[1], -l->emit_dir[2]};
            if (l->delta)
                add(&s, towards, 1.0, INFINITY);
            else
                cone(&s, NULL, towards, cos(0.5 * st->angle), grid, 0, 0.0, NULL, 1);
        } else if (st->kind == WENV_LAMP_AREA) {
            if (l->area > 0.0 && dot3(rel, l->emit_dir) < 0.0)
                flat(&s, l, rel, l->half_u, l->half_v, l->ellipse, l->area, l->emit_dir, grid, 0);
        } else if (d > 0.0) {
            int within = d <= st->radius;
            double back[3] = {-to[0], -to[1], -to[2]};
            if (l->delta) {
                add(&s, to, wenv_lamp_factor(l, back, 0) / (d * d), d);
            } else if (l->sphere) {
                double cos_a = within ? -1.0 : sqrt(fmax(0.0, 1.0 - st->radius * st->radius / (d * d)));
                cone(&s, l, to, cos_a, grid, within, st->radius, rel, 0);
            } else { /* soft falloff: a disk at the lamp facing p */
                double x[3], y[3];
                basis(to, x, y);
                for (int k = 0; k < 3; k++) {
                    x[k] *= st->radius;
                    y[k] *= st->radius;
                }
                flat(&s, l, rel, x, y, 1, M_PI * st->radius * st->radius, back, grid, within);
            }
        }
        for (int c = 0; c < 3; c++) {
            spec[c] += s.spec[c] * l->radiance[c];
            irr[c] += s.irr[c] * l->radiance[c];
        }
    }
}
