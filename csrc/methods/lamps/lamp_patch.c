#include "methods/lamps/lamp_patch.h"

#include <math.h>

#include "math/projected_solid_angle.h"

/* An ellipse's outline as a polygon of this many corners, its radius scaled so that the areas
 * agree (the projected solid angle then agrees to about 1e-4). */
#define ELLIPSE_CORNERS 32

static double dot3(const double a[3], const double b[3]) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
static double len3(const double a[3]) { return sqrt(dot3(a, a)); }

/* Two half axes of length r across the unit direction d. */
static void across(const double d[3], double r, double u[3], double v[3])
{
    double a[3] = {0.0, 0.0, 0.0};
    a[fabs(d[0]) < 0.6 ? 0 : (fabs(d[1]) < 0.6 ? 1 : 2)] = 1.0;
    double x[3] = {a[1] * d[2] - a[2] * d[1], a[2] * d[0] - a[0] * d[2], a[0] * d[1] - a[1] * d[0]};
    double lx = len3(x);
    for (int c = 0; c < 3; c++)
        x[c] /= lx;
    double y[3] = {d[1] * x[2] - d[2] * x[1], d[2] * x[0] - d[0] * x[2], d[0] * x[1] - d[1] * x[0]};
    for (int c = 0; c < 3; c++) {
        u[c] = r * x[c];
        v[c] = r * y[c];
    }
}

int wenv_lamp_patch_at(const wenv_lamp *l, const double p[3], wenv_lamp_patch *pa)
{
    pa->infinite = 0;
    pa->within_sphere = 0;
    pa->ellipse = 1;
    pa->facing = 1;
    switch (l->settings.kind) {
    case WENV_LAMP_SUN:
        for (int c = 0; c < 3; c++) {
            pa->centre[c] = -l->emit_dir[c];
            pa->normal[c] = l->emit_dir[c];
        }
        across(l->emit_dir, l->sun_tan, pa->u, pa->v);
        pa->infinite = 1;
        break;
    case WENV_LAMP_POINT:
    case WENV_LAMP_SPOT: {
        double x[3] = {l->position[0] - p[0], l->position[1] - p[1], l->position[2] - p[2]};
        double d = len3(x), r = l->settings.radius;
        if (!(d > 1e-9 * (1.0 + r)))
            return 0;
        double dir[3] = {x[0] / d, x[1] / d, x[2] / d};
        pa->within_sphere = d <= r;
        double radius = r, at = d;
        if (l->sphere) { /* the circle where the silhouette's cone touches the sphere */
            double s = fmin(r / d, 0.999);
            at = d * (1.0 - s * s);
            radius = d * s * sqrt(1.0 - s * s);
        }
        for (int c = 0; c < 3; c++) {
            pa->centre[c] = at * dir[c];
            pa->normal[c] = -dir[c];
        }
        across(dir, radius, pa->u, pa->v);
        break;
    }
    case WENV_LAMP_AREA: {
        if (!(l->area > 0.0))
            return 0;
        double x[3] = {l->position[0] - p[0], l->position[1] - p[1], l->position[2] - p[2]};
        if (!(dot3(x, l->emit_dir) < 0.0)) /* on its dark side, or in its plane */
            return 0;
        for (int c = 0; c < 3; c++) {
            pa->centre[c] = x[c];
            pa->u[c] = l->half_u[c];
            pa->v[c] = l->half_v[c];
            pa->normal[c] = l->emit_dir[c];
        }
        pa->ellipse = l->ellipse;
        pa->facing = 0;
        break;
    }
    }
    pa->area = 4.0 * len3(pa->u) * len3(pa->v) * (pa->ellipse ? M_PI / 4.0 : 1.0);
    return pa->area > 0.0;
}

void wenv_lamp_patch_point(const wenv_lamp_patch *pa, double s, double t, double x[3])
{
    double a = s, b = t;
    if (pa->ellipse) {
        if (s == 0.0 && t == 0.0) {
            a = b = 0.0;
        } else if (fabs(s) > fabs(t)) {
            double phi = M_PI / 4.0 * (t / s);
            a = s * cos(phi);
            b = s * sin(phi);
        } else {
            double phi = M_PI / 2.0 - M_PI / 4.0 * (s / t);
            a = t * cos(phi);
            b = t * sin(phi);
        }
    }
    for (int c = 0; c < 3; c++)
        x[c] = pa->centre[c] + a * pa->u[c] + b * pa->v[c];
}

double wenv_lamp_patch_angle(const wenv_lamp_patch *pa)
{
    double d = len3(pa->centre), r = sqrt(dot3(pa->u, pa->u) + dot3(pa->v, pa->v));
    return atan2(r, d);
}

double wenv_lamp_patch_psa(const wenv_lamp_patch *pa, const double normal[3])
{
    if (pa->facing) { /* a cap wholly above the horizon: pi sin^2 of its radius times the cosine */
        double d2 = dot3(pa->centre, pa->centre), r2 = dot3(pa->u, pa->u);
        double sin2 = r2 / (r2 + d2), cos_c = dot3(pa->centre, normal) / sqrt(d2);
        if (cos_c > 0.0 && cos_c * cos_c > sin2)
            return M_PI * sin2 * cos_c;
    }
    double corners[3 * ELLIPSE_CORNERS];
    size_t n;
    if (pa->ellipse) {
        double step = 2.0 * M_PI / ELLIPSE_CORNERS, k = sqrt(step / sin(step));
        for (size_t i = 0; i < ELLIPSE_CORNERS; i++) {
            double a = k * cos(step * (double)i), b = k * sin(step * (double)i);
            for (int c = 0; c < 3; c++)
                corners[3 * i + (size_t)c] = pa->centre[c] + a * pa->u[c] + b * pa->v[c];
        }
        n = ELLIPSE_CORNERS;
    } else {
        static const double s[4] = {-1, 1, 1, -1}, t[4] = {-1, -1, 1, 1};
        for (size_t i = 0; i < 4; i++)
            for (int c = 0; c < 3; c++)
                corners[3 * i + (size_t)c] = pa->centre[c] + s[i] * pa->u[c] + t[i] * pa->v[c];
        n = 4;
    }
    return wenv_projected_solid_angle(corners, n, normal);
}

double wenv_lamp_patch_cell_psa(const wenv_lamp_patch *pa, size_t k, size_t i, size_t j, const double normal[3])
{
    double h = 2.0 / (double)k, s0 = -1.0 + h * (double)i, t0 = -1.0 + h * (double)j;
    double corners[12];
    wenv_lamp_patch_point(pa, s0, t0, corners);
    wenv_lamp_patch_point(pa, s0 + h, t0, corners + 3);
    wenv_lamp_patch_point(pa, s0 + h, t0 + h, corners + 6);
    wenv_lamp_patch_point(pa, s0, t0 + h, corners + 9);
    return wenv_projected_solid_angle(corners, 4, normal);
}
