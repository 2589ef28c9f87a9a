#include "scene/lamp.h"

#include <math.h>
#include <string.h>

#include "base/fingerprint.h"

void wenv_lamp_settings_defaults(wenv_lamp_settings *s, wenv_lamp_kind kind)
{
    memset(s, 0, sizeof *s);
    s->kind = kind;
    for (int k = 0; k < 4; k++)
        s->matrix[5 * k] = 1.0;
    s->color[0] = s->color[1] = s->color[2] = 1.0;
    s->energy = 10.0;
    s->normalize = 1;
    s->soft_falloff = 1;
    s->angle = 0.009180432185530663; /* Blender's: the Sun's 0.526 degrees */
    s->spot_size = M_PI / 4.0;
    s->spot_blend = 0.15;
    s->shape = WENV_LAMP_SQUARE;
    s->size = s->size_y = 0.25;
    s->spread = M_PI;
    s->cast_shadow = s->diffuse = s->glossy = 1;
}

static void column(const double *m, int c, double out[3])
{
    for (int r = 0; r < 3; r++)
        out[r] = m[4 * r + c];
}

static double length(const double v[3]) { return sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]); }

static wenv_status out_of_range(wenv_error *err, const char *index, const char *name, double value, const char *range)
{
    return wenv_error_set(err, WENV_ERR_VALUE, "%s.%s must be %s, got %g", index, name, range, value);
}

/* The 3 x 3 inverse of the matrix's linear part, row-major; 0 when it is singular. */
static int invert3(const double *m4, double inv[9])
{
    double a[9];
    for (int r = 0; r < 3; r++)
        for (int c = 0; c < 3; c++)
            a[3 * r + c] = m4[4 * r + c];
    double c0 = a[4] * a[8] - a[5] * a[7], c1 = a[5] * a[6] - a[3] * a[8], c2 = a[3] * a[7] - a[4] * a[6];
    double det = a[0] * c0 + a[1] * c1 + a[2] * c2;
    if (!(fabs(det) > 1e-30) || !isfinite(det))
        return 0;
    double d = 1.0 / det;
    inv[0] = c0 * d;
    inv[1] = (a[2] * a[7] - a[1] * a[8]) * d;
    inv[2] = (a[1] * a[5] - a[2] * a[4]) * d;
    inv[3] = c1 * d;
    inv[4] = (a[0] * a[8] - a[2] * a[6]) * d;
    inv[5] = (a[2] * a[3] - a[0] * a[5]) * d;
    inv[6] = c2 * d;
    inv[7] = (a[1] * a[6] - a[0] * a[7]) * d;
    inv[8] = (a[0] * a[4] - a[1] * a[3]) * d;
    return 1;
}

/* An angle Blender holds in float, up to pi: pi rounded up to float is pi. */
static double to_pi(double angle) { return angle > M_PI && angle <= (double)(float)M_PI ? M_PI : angle; }

wenv_status wenv_lamp_make(wenv_lamp *out, const wenv_lamp_settings *given, const char *index, wenv_error *err)
{
    memset(out, 0, sizeof *out);
    out->settings = *given;
    wenv_lamp_settings *s = &out->settings;
    s->angle = to_pi(s->angle);
    s->spot_size = to_pi(s->spot_size);
    s->spread = to_pi(s->spread);
    if (s->kind < WENV_LAMP_SUN || s->kind > WENV_LAMP_AREA)
        return wenv_error_set(err, WENV_ERR_VALUE, "%s is of no known kind", index);
    for (int k = 0; k < 16; k++)
        if (!isfinite(s->matrix[k]))
            return out_of_range(err, index, "matrix", s->matrix[k], "finite");
    for (int c = 0; c < 3; c++)
        if (!(isfinite(s->color[c]) && s->color[c] >= 0.0))
            return out_of_range(err, index, "color", s->color[c], "finite and >= 0");
    if (!(isfinite(s->energy) && s->energy >= 0.0))
        return out_of_range(err, index, "energy", s->energy, "finite and >= 0");
    if (!(isfinite(s->exposure) && fabs(s->exposure) <= 32.0))
        return out_of_range(err, index, "exposure", s->exposure, "in [-32, 32] (Blender's range)");
    double strength = s->energy * exp2(s->exposure);
    for (int k = 0; k < 3; k++)
        out->position[k] = s->matrix[4 * k + 3];
    double z[3];
    column(s->matrix, 2, z);
    double zl = length(z);
    if (zl > 0.0)
        for (int k = 0; k < 3; k++)
            out->emit_dir[k] = -z[k] / zl;
    double scale = 0.0; /* what strength becomes as radiance (or intensity, irradiance) */
    switch (s->kind) {
    case WENV_LAMP_SUN: {
        if (!(isfinite(s->angle) && s->angle >= 0.0 && s->angle <= M_PI))
            return out_of_range(err, index, "angle", s->angle, "in [0, pi]");
        if (!(zl > 0.0))
            return wenv_error_set(err, WENV_ERR_VALUE, "%s.matrix has no Z axis to shine along", index);
        double half = 0.5 * s->angle;
        out->delta = half <= 0.0;
        out->sun_tan = tan(half);
        scale = out->delta || !s->normalize ? 1.0 : 1.0 / (M_PI * sin(half) * sin(half));
        break;
    }
    case WENV_LAMP_POINT:
    case WENV_LAMP_SPOT: {
        if (!(isfinite(s->radius) && s->radius >= 0.0))
            return out_of_range(err, index, "radius", s->radius, "finite and >= 0");
        out->delta = s->radius == 0.0;
        out->sphere = !out->delta && !s->soft_falloff;
        double area = out->delta ? 4.0 : 4.0 * M_PI * s->radius * s->radius;
        scale = (s->normalize ? 1.0 / area : 1.0) / M_PI;
        if (s->kind == WENV_LAMP_SPOT) {
            if (!(isfinite(s->spot_size) && s->spot_size >= 0.0 && s->spot_size <= M_PI))
                return out_of_range(err, index, "spot_size", s->spot_size, "in [0, pi]");
            if (!(isfinite(s->spot_blend) && s->spot_blend >= 0.0 && s->spot_blend <= 1.0))
                return out_of_range(err, index, "spot_blend", s->spot_blend, "in [0, 1]");
            if (!invert3(s->matrix, out->spot_local))
                return wenv_error_set(err, WENV_ERR_VALUE,
                                      "%s.matrix is singular: a spot's cone is shaped by its scale", index);
            out->spot_cos = cos(0.5 * s->spot_size);
            out->spot_band = (1.0 - out->spot_cos) * s->spot_blend;
            double longest = 0.0, shortest = INFINITY;
            for (int c = 0; c < 3; c++) {
                double axis[3];
                column(s->matrix, c, axis);
                longest = fmax(longest, length(axis));
                shortest = fmin(shortest, length(axis));
            }
            out->spot_stretch = longest / shortest;
        }
        break;
    }
    case WENV_LAMP_AREA: {
        if (s->shape < WENV_LAMP_SQUARE || s->shape > WENV_LAMP_ELLIPSE)
            return wenv_error_set(err, WENV_ERR_VALUE, "%s.shape is of no known shape", index);
        if (!(isfinite(s->size) && s->size >= 0.0))
            return out_of_range(err, index, "size", s->size, "finite and >= 0");
        int own_y = s->shape == WENV_LAMP_RECTANGLE || s->shape == WENV_LAMP_ELLIPSE;
        if (own_y && !(isfinite(s->size_y) && s->size_y >= 0.0))
            return out_of_range(err, index, "size_y", s->size_y, "finite and >= 0");
        /* a spread of 0 is a beam, each point lit from one direction: not a lamp shaded here */
        if (!(isfinite(s->spread) && s->spread >= WENV_LAMP_SPREAD_MIN && s->spread <= M_PI))
            return out_of_range(err, index, "spread", s->spread, "in [0.001, pi] (a beam of spread 0 is not shaded)");
        double x[3], y[3];
        column(s->matrix, 0, x);
        column(s->matrix, 1, y);
        double su = 0.5 * s->size, sv = 0.5 * (own_y ? s->size_y : s->size);
        for (int k = 0; k < 3; k++) {
            out->half_u[k] = su * x[k];
            out->half_v[k] = sv * y[k];
        }
        out->ellipse = s->shape == WENV_LAMP_DISK || s->shape == WENV_LAMP_ELLIPSE;
        out->area = 4.0 * length(out->half_u) * length(out->half_v) * (out->ellipse ? M_PI / 4.0 : 1.0);
        if (!(zl > 0.0) || !(out->area > 0.0)) { /* no area emits nothing, as in Cycles; it emits along -Z */
            out->area = 0.0;
            break;
        }
        if (s->spread < M_PI) {
            double h = 0.5 * s->spread;
            out->spread_tan = h > 0.0 ? tan(h) : 0.0;
            out->spread_norm = h > 0.05 ? 1.0 / (tan(h) - h) : (h > 0.0 ? 3.0 / (h * h * h) : INFINITY);
        }
        scale = (s->normalize ? 1.0 / out->area : 1.0) / M_PI;
        break;
    }
    }
    for (int c = 0; c < 3; c++)
        out->radiance[c] = s->color[c] * strength * scale;
    if (!(isfinite(out->radiance[0]) && isfinite(out->radiance[1]) && isfinite(out->radiance[2])))
        return wenv_error_set(err, WENV_ERR_VALUE, "%s is too bright: its radiance is not finite", index);
    return WENV_OK;
}

static double smoothstep(double x) { return x <= 0.0 ? 0.0 : (x >= 1.0 ? 1.0 : x * x * (3.0 - 2.0 * x)); }

double wenv_lamp_factor(const wenv_lamp *l, const double w[3], int within_sphere)
{
    if (l->settings.kind == WENV_LAMP_SPOT && !within_sphere) {
        const double *m = l->spot_local;
        double local[3] = {m[0] * w[0] + m[1] * w[1] + m[2] * w[2], m[3] * w[0] + m[4] * w[1] + m[5] * w[2],
                           m[6] * w[0] + m[7] * w[1] + m[8] * w[2]};
        double len = length(local);
        double z = len > 0.0 ? -local[2] / len : -1.0;
        if (l->spot_band <= 0.0)
            return z > l->spot_cos ? 1.0 : 0.0;
        return smoothstep((z - l->spot_cos) / l->spot_band);
    }
    if (l->settings.kind == WENV_LAMP_AREA) {
        double c = l->emit_dir[0] * w[0] + l->emit_dir[1] * w[1] + l->emit_dir[2] * w[2];
        if (!(c > 0.0))
            return 0.0; /* behind it: it emits from one side */
        if (l->settings.spread >= M_PI)
            return 1.0;
        double tan_theta = sqrt(fmax(0.0, 1.0 - c * c)) / c;
        if (l->spread_tan == 0.0) /* a beam: Cycles' pi over its collimated sample */
            return tan_theta > 1e-5 ? 0.0 : M_PI;
        return fmax(0.0, (l->spread_tan - tan_theta) * l->spread_norm);
    }
    return 1.0;
}

int wenv_lamp_factor_varies(const wenv_lamp *l)
{
    return l->settings.kind == WENV_LAMP_SPOT || (l->settings.kind == WENV_LAMP_AREA && l->settings.spread < M_PI);
}

int wenv_lamp_factor_even(const wenv_lamp *l, const double w[3], double angle, int within_sphere)
{
    if (l->settings.kind == WENV_LAMP_AREA)
        return l->settings.spread >= M_PI;
    if (l->settings.kind != WENV_LAMP_SPOT || within_sphere)
        return 1;
    const double *m = l->spot_local;
    double local[3] = {m[0] * w[0] + m[1] * w[1] + m[2] * w[2], m[3] * w[0] + m[4] * w[1] + m[5] * w[2],
                       m[6] * w[0] + m[7] * w[1] + m[8] * w[2]};
    double len = length(local);
    double at = acos(fmax(-1.0, fmin(1.0, len > 0.0 ? -local[2] / len : -1.0)));
    double reach = l->spot_stretch * angle, outer = acos(l->spot_cos);
    double inner = acos(fmin(1.0, l->spot_cos + l->spot_band));
    return at + reach < inner || at - reach > outer;
}

uint64_t wenv_lamp_geometry_key(const wenv_lamp *l, uint64_t h)
{
    const wenv_lamp_settings *s = &l->settings;
    h = wenv_fingerprint_word(h, (uint64_t)s->kind);
    h = wenv_fingerprint_doubles(h, s->matrix, 16);
    double shape[8] = {s->radius, s->angle, s->spot_size, s->spot_blend, s->size, s->size_y, s->spread, (double)s->shape};
    h = wenv_fingerprint_doubles(h, shape, 8);
    h = wenv_fingerprint_word(h, l->blockers ? wenv_occluders_fingerprint(l->blockers) : 0);
    return wenv_fingerprint_word(h, (uint64_t)(s->soft_falloff * 2 + s->cast_shadow));
}

const wenv_occluders *wenv_lamp_blockers(const wenv_lamp *l, const wenv_occluders *scene)
{
    if (!scene || !l->settings.cast_shadow)
        return NULL;
    return l->blockers ? l->blockers : scene;
}
