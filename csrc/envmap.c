/* Distant HDR environments: storage, the three projections, exact pixel solid angles, bilinear
 * lookup, and the file readers (OpenEXR through OpenEXRCore, Radiance RGBE by hand). */
#define _POSIX_C_SOURCE 200809L /* pread, fstat, strerror_r */

#include "envmap.h"

#include <dlfcn.h>
#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <omp.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include <ImfCRgbaFile.h>
#include <OpenEXRConfig.h>
#include <openexr.h>

#define PI 3.14159265358979323846

/* Largest image accepted from a file or an array (far beyond real panoramas): keeps every size
 * product far from overflow and OpenEXRCore's int32 line strides in range. */
#define MAX_SIDE ((size_t)1 << 20)
#define MAX_PIXELS ((size_t)1 << 30)

typedef struct {
    double c[3], r[3], d[3]; /* face centre, image-right and image-down directions */
    size_t cell_col, cell_row; /* cell of the cross holding the face */
} cube_face;

struct wenv_envmap {
    size_t width, height;
    wenv_projection projection;
    double rotation, strength;
    double cos_r, sin_r;
    size_t face_size;    /* cube cross: face edge in pixels */
    cube_face faces[6];  /* cube cross: +X, -X, +Y, -Y, +Z, -Z */
    float *pixels;       /* height x width x 3, row 0 the top */
    double *column_xy;   /* equirect: world (x, y) of each column's azimuth, rotation applied */
    double *row_flux;    /* per row: sum of solid angle x channel mean over its pixels (no strength) */
    float *row_peak;     /* per row: its brightest channel value (no strength) */
};

/* Face frames as documented in envmap.h (order +X, -X, +Y, -Y, +Z, -Z). */
static const cube_face horizontal_cross[6] = {
    {{1, 0, 0}, {0, -1, 0}, {0, 0, -1}, 1, 1},
    {{-1, 0, 0}, {0, 1, 0}, {0, 0, -1}, 3, 1},
    {{0, 1, 0}, {1, 0, 0}, {0, 0, -1}, 0, 1},
    {{0, -1, 0}, {-1, 0, 0}, {0, 0, -1}, 2, 1},
    {{0, 0, 1}, {0, -1, 0}, {1, 0, 0}, 1, 0},
    {{0, 0, -1}, {0, -1, 0}, {-1, 0, 0}, 1, 2},
};
static const cube_face vertical_cross_minus_x = {{-1, 0, 0}, {0, -1, 0}, {0, 0, 1}, 1, 3};

/* ---------------------------------------------------------------------------------------------
 * Parameters and construction */

int wenv_envmap_parse_projection(const char *name, wenv_projection *out)
{
    static const char *const names[] = {"equirect", "mirror_ball", "cube_cross"};
    for (int i = 0; i < 3; i++) {
        if (name && strcmp(name, names[i]) == 0) {
            *out = (wenv_projection)i;
            return 0;
        }
    }
    return -1;
}

const char *wenv_envmap_projection_name(wenv_projection projection)
{
    switch (projection) {
    case WENV_PROJ_EQUIRECT: return "equirect";
    case WENV_PROJ_MIRROR_BALL: return "mirror_ball";
    case WENV_PROJ_CUBE_CROSS: return "cube_cross";
    }
    return "?";
}

static wenv_status check_transform(double rotation, double strength, wenv_error *err)
{
    if (!isfinite(rotation))
        return wenv_error_set(err, WENV_ERR_VALUE, "rotation must be finite, got %g", rotation);
    if (!isfinite(strength) || strength < 0.0)
        return wenv_error_set(err, WENV_ERR_VALUE, "strength must be finite and >= 0, got %g", strength);
    return WENV_OK;
}

static wenv_status check_projection(wenv_projection projection, wenv_error *err)
{
    if (projection != WENV_PROJ_EQUIRECT && projection != WENV_PROJ_MIRROR_BALL &&
        projection != WENV_PROJ_CUBE_CROSS)
        return wenv_error_set(err, WENV_ERR_VALUE, "projection must be one of " WENV_ENVMAP_PROJECTION_NAMES);
    return WENV_OK;
}

static wenv_status check_shape(size_t height, size_t width, wenv_projection projection, const char *what,
                               wenv_error *err)
{
    if (check_projection(projection, err))
        return err->status;
    if (height == 0 || width == 0)
        return wenv_error_set(err, WENV_ERR_VALUE, "%s: image is empty (%zu x %zu pixels)", what, width, height);
    if (height > MAX_SIDE || width > MAX_SIDE || height * width > MAX_PIXELS)
        return wenv_error_set(err, WENV_ERR_VALUE, "%s: image of %zu x %zu pixels is too large", what, width,
                              height);
    if (projection == WENV_PROJ_CUBE_CROSS) {
        int horizontal = width % 4 == 0 && height % 3 == 0 && width / 4 == height / 3;
        int vertical = width % 3 == 0 && height % 4 == 0 && width / 3 == height / 4;
        if (!horizontal && !vertical)
            return wenv_error_set(err, WENV_ERR_VALUE,
                                  "%s: a cube cross must be 4:3 (horizontal) or 3:4 (vertical) with square "
                                  "faces, got %zu x %zu pixels (width x height)",
                                  what, width, height);
    }
    return WENV_OK;
}

/* Takes ownership of `rgb` (height x width x 3): validates it, clamps negatives, and wraps it. */
static int row_stats(wenv_envmap *env);

/* Takes ownership of rgb (height x width x 3).  `checked`: the pixels come from another environment,
 * already finite and non-negative. */
static wenv_status envmap_adopt_checked(wenv_envmap **out, float *rgb, size_t height, size_t width,
                                        wenv_projection projection, double rotation, double strength,
                                        const char *what, int checked, wenv_error *err)
{
    *out = NULL;
    if (check_transform(rotation, strength, err) || check_shape(height, width, projection, what, err)) {
        free(rgb);
        return err->status;
    }
    size_t count = checked ? 0 : height * width * 3;
    for (size_t i = 0; i < count; i++) {
        if (!isfinite(rgb[i])) {
            size_t px = i / 3;
            wenv_error_set(err, WENV_ERR_VALUE, "%s: pixel [row %zu, column %zu, channel %zu] is not finite", what,
                           px / width, px % width, i % 3);
            free(rgb);
            return err->status;
        }
        if (!(rgb[i] > 0.0f)) /* negative radiance is meaningless; also turns -0 into +0 */
            rgb[i] = 0.0f;
    }
    wenv_envmap *env = calloc(1, sizeof *env);
    if (!env) {
        free(rgb);
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for an environment");
    }
    env->width = width;
    env->height = height;
    env->projection = projection;
    env->rotation = rotation;
    env->strength = strength;
    env->cos_r = cos(rotation);
    env->sin_r = sin(rotation);
    env->pixels = rgb;
    if (projection == WENV_PROJ_EQUIRECT) {
        /* per-column azimuths, so that sampling every pixel at a lighting change needs no sincos */
        env->column_xy = malloc(2 * width * sizeof(double));
        if (!env->column_xy) {
            free(rgb);
            free(env);
            return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for an environment");
        }
        for (size_t col = 0; col < width; col++) {
            double phi = PI * (1.0 - 2.0 * (((double)col + 0.5) / (double)width));
            double x = cos(phi), y = sin(phi);
            /* world direction w = R_z(-r) d */
            env->column_xy[2 * col] = env->cos_r * x + env->sin_r * y;
            env->column_xy[2 * col + 1] = -env->sin_r * x + env->cos_r * y;
        }
    }
    if (projection == WENV_PROJ_CUBE_CROSS) {
        int vertical = width * 4 == height * 3;
        env->face_size = vertical ? width / 3 : width / 4;
        memcpy(env->faces, horizontal_cross, sizeof horizontal_cross);
        if (vertical)
            env->faces[1] = vertical_cross_minus_x;
    }
    if (!checked && row_stats(env) < 0) {
        wenv_envmap_free(env);
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for an environment");
    }
    *out = env;
    return WENV_OK;
}

static wenv_status envmap_adopt(wenv_envmap **out, float *rgb, size_t height, size_t width,
                                wenv_projection projection, double rotation, double strength, const char *what,
                                wenv_error *err)
{
    return envmap_adopt_checked(out, rgb, height, width, projection, rotation, strength, what, 0, err);
}

wenv_status wenv_envmap_create(wenv_envmap **out, const float *pixels, size_t height, size_t width,
                               size_t channels, wenv_projection projection, double rotation, double strength,
                               wenv_error *err)
{
    *out = NULL;
    if (!pixels && height && width)
        return wenv_error_set(err, WENV_ERR_VALUE, "pixels is NULL");
    if (channels != 3 && channels != 4)
        return wenv_error_set(err, WENV_ERR_VALUE, "pixels must have 3 or 4 channels, got %zu", channels);
    if (check_transform(rotation, strength, err) || check_shape(height, width, projection, "pixels", err))
        return err->status;
    float *rgb = malloc(height * width * 3 * sizeof *rgb);
    if (!rgb)
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for a %zu x %zu environment", width, height);
    for (size_t i = 0; i < height * width; i++)
        for (size_t c = 0; c < 3; c++)
            rgb[3 * i + c] = pixels[channels * i + c];
    return envmap_adopt(out, rgb, height, width, projection, rotation, strength, "pixels", err);
}

wenv_status wenv_envmap_with_transform(wenv_envmap **out, const wenv_envmap *env, double rotation,
                                       double strength, wenv_error *err)
{
    /* a plain copy: the pixels were checked when the original was made (a lighting change) */
    size_t bytes = env->height * env->width * 3 * sizeof(float);
    float *rgb = malloc(bytes ? bytes : 1);
    if (!rgb)
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for a %zu x %zu environment", env->width,
                              env->height);
    memcpy(rgb, env->pixels, bytes);
    wenv_status st = envmap_adopt_checked(out, rgb, env->height, env->width, env->projection, rotation, strength,
                                          "pixels", 1, err);
    if (st)
        return st;
    /* the rows' statistics do not depend on rotation or strength */
    (*out)->row_flux = malloc((env->height ? env->height : 1) * sizeof(double));
    (*out)->row_peak = malloc((env->height ? env->height : 1) * sizeof(float));
    if (!(*out)->row_flux || !(*out)->row_peak) {
        wenv_envmap_free(*out);
        *out = NULL;
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for an environment");
    }
    memcpy((*out)->row_flux, env->row_flux, env->height * sizeof(double));
    memcpy((*out)->row_peak, env->row_peak, env->height * sizeof(float));
    return WENV_OK;
}

void wenv_envmap_free(wenv_envmap *env)
{
    if (env) {
        free(env->pixels);
        free(env->column_xy);
        free(env->row_flux);
        free(env->row_peak);
        free(env);
    }
}

size_t wenv_envmap_width(const wenv_envmap *env) { return env->width; }
size_t wenv_envmap_height(const wenv_envmap *env) { return env->height; }
wenv_projection wenv_envmap_projection(const wenv_envmap *env) { return env->projection; }
double wenv_envmap_rotation(const wenv_envmap *env) { return env->rotation; }
double wenv_envmap_strength(const wenv_envmap *env) { return env->strength; }
const float *wenv_envmap_pixels(const wenv_envmap *env) { return env->pixels; }

/* ---------------------------------------------------------------------------------------------
 * Geometry */

static inline double dot3(const double a[3], const double b[3]) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }

static inline const float *pixel_at(const wenv_envmap *env, size_t row, size_t col)
{
    return env->pixels + (row * env->width + col) * 3;
}

/* Cube face holding direction d (largest component), in the faces[] order. */
static inline int cube_face_of(const double d[3])
{
    double ax = fabs(d[0]), ay = fabs(d[1]), az = fabs(d[2]);
    if (ax >= ay && ax >= az)
        return d[0] >= 0 ? 0 : 1;
    if (ay >= az)
        return d[1] >= 0 ? 2 : 3;
    return d[2] >= 0 ? 4 : 5;
}

static int cube_face_of_cell(const wenv_envmap *env, size_t cell_col, size_t cell_row)
{
    for (int f = 0; f < 6; f++)
        if (env->faces[f].cell_col == cell_col && env->faces[f].cell_row == cell_row)
            return f;
    return -1;
}

/* Signed area of the unit disk within [0, x] x [0, y] (the disk is symmetric, so signs factor). */
static double disk_quadrant_area(double x, double y)
{
    double sx = x < 0 ? -1.0 : 1.0, sy = y < 0 ? -1.0 : 1.0;
    x = fmin(fabs(x), 1.0);
    y = fmin(fabs(y), 1.0);
    double a;
    if (x * x + y * y <= 1.0) {
        a = x * y;
    } else {
        /* full height y up to where the circle drops below y, then the circle itself */
        double xa = sqrt(1.0 - y * y);
        a = xa * y + 0.5 * (x * sqrt(fmax(1.0 - x * x, 0.0)) + asin(x)) - 0.5 * (xa * y + asin(xa));
    }
    return sx * sy * a;
}

/* Exact area of [x0, x1] x [y0, y1] inside the unit disk. */
static double disk_rect_area(double x0, double x1, double y0, double y1)
{
    double fx = fmax(fabs(x0), fabs(x1)), fy = fmax(fabs(y0), fabs(y1));
    if (fx * fx + fy * fy <= 1.0)
        return (x1 - x0) * (y1 - y0); /* wholly inside: avoid cancellation */
    double nx = x0 > 0 ? x0 : (x1 < 0 ? -x1 : 0.0), ny = y0 > 0 ? y0 : (y1 < 0 ? -y1 : 0.0);
    if (nx * nx + ny * ny >= 1.0)
        return 0.0;
    double a = disk_quadrant_area(x1, y1) - disk_quadrant_area(x0, y1) - disk_quadrant_area(x1, y0) +
               disk_quadrant_area(x0, y0);
    return fmax(a, 0.0);
}

/* Mirror-ball disk coordinates of pixel (row, col): x to the right, z up, the disk is x^2+z^2 <= 1. */
static inline void ball_pixel_rect(const wenv_envmap *env, size_t row, size_t col, double *x0, double *x1,
                                   double *z0, double *z1)
{
    double w = (double)env->width, h = (double)env->height;
    *x0 = (2.0 * (double)col - w) / w;
    *x1 = (2.0 * (double)(col + 1) - w) / w;
    *z1 = (h - 2.0 * (double)row) / h;
    *z0 = (h - 2.0 * (double)(row + 1)) / h;
}

static inline int ball_pixel_in_disk(const wenv_envmap *env, size_t row, size_t col)
{
    double x0, x1, z0, z1;
    ball_pixel_rect(env, row, col, &x0, &x1, &z0, &z1);
    double nx = x0 > 0 ? x0 : (x1 < 0 ? -x1 : 0.0), nz = z0 > 0 ? z0 : (z1 < 0 ? -z1 : 0.0);
    return nx * nx + nz * nz < 1.0;
}

/* Solid angle of the rectangle [0, x] x [0, y] on the face plane at unit distance (signed). */
static inline double cube_corner(double x, double y) { return atan2(x * y, sqrt(x * x + y * y + 1.0)); }

double wenv_envmap_pixel_solid_angle(const wenv_envmap *env, size_t row, size_t col)
{
    if (row >= env->height || col >= env->width)
        return 0.0;
    switch (env->projection) {
    case WENV_PROJ_EQUIRECT: {
        /* dphi (sin lat_top - sin lat_bottom), written as a product to stay exact near the poles */
        double h = (double)env->height;
        return (2.0 * PI / (double)env->width) * 2.0 * sin(((double)row + 0.5) * PI / h) * sin(0.5 * PI / h);
    }
    case WENV_PROJ_MIRROR_BALL: {
        double x0, x1, z0, z1;
        ball_pixel_rect(env, row, col, &x0, &x1, &z0, &z1);
        return 4.0 * disk_rect_area(x0, x1, z0, z1); /* the mirror ball is equal-area: dw = 4 dA */
    }
    case WENV_PROJ_CUBE_CROSS: {
        size_t n = env->face_size;
        if (cube_face_of_cell(env, col / n, row / n) < 0)
            return 0.0;
        double nn = (double)n, i = (double)(col % n), j = (double)(row % n);
        double s0 = (2.0 * i - nn) / nn, s1 = (2.0 * i + 2.0 - nn) / nn;
        double t0 = (2.0 * j - nn) / nn, t1 = (2.0 * j + 2.0 - nn) / nn;
        return cube_corner(s1, t1) - cube_corner(s0, t1) - cube_corner(s1, t0) + cube_corner(s0, t0);
    }
    }
    return 0.0;
}

/* Image-space direction (unrotated) of the centre of pixel (row, col); 0 if outside the domain. */
static int pixel_direction(const wenv_envmap *env, size_t row, size_t col, double d[3])
{
    double w = (double)env->width, h = (double)env->height;
    switch (env->projection) {
    case WENV_PROJ_EQUIRECT: {
        double u = ((double)col + 0.5) / w, v = 1.0 - ((double)row + 0.5) / h;
        double phi = PI * (1.0 - 2.0 * u), lat = PI * (v - 0.5);
        d[0] = cos(lat) * cos(phi);
        d[1] = cos(lat) * sin(phi);
        d[2] = sin(lat);
        return 1;
    }
    case WENV_PROJ_MIRROR_BALL: {
        double x = (2.0 * (double)col + 1.0 - w) / w, z = (h - 2.0 * (double)row - 1.0) / h;
        double r2 = x * x + z * z;
        if (r2 > 1.0) { /* rim pixel whose centre lies outside: use the nearest point of the disk */
            double s = 1.0 / sqrt(r2);
            x *= s;
            z *= s;
            r2 = 1.0;
        }
        /* Cycles' mirrorball_to_direction: reflect I = (0, -1, 0) about the ball normal */
        double k = sqrt(fmax(1.0 - r2, 0.0));
        d[0] = 2.0 * k * x;
        d[1] = 1.0 - 2.0 * k * k;
        d[2] = 2.0 * k * z;
        return 1;
    }
    case WENV_PROJ_CUBE_CROSS: {
        size_t n = env->face_size;
        int f = cube_face_of_cell(env, col / n, row / n);
        if (f < 0)
            return 0;
        double nn = (double)n;
        double s = (2.0 * (double)(col % n) + 1.0 - nn) / nn, t = (2.0 * (double)(row % n) + 1.0 - nn) / nn;
        const cube_face *fc = &env->faces[f];
        double len2 = 0.0;
        for (int k = 0; k < 3; k++) {
            d[k] = fc->c[k] + s * fc->r[k] + t * fc->d[k];
            len2 += d[k] * d[k];
        }
        double inv = 1.0 / sqrt(len2);
        for (int k = 0; k < 3; k++)
            d[k] *= inv;
        return 1;
    }
    }
    return 0;
}

/* One row's valid pixels written from position m on; returns how many. */
/* Equirect rows read the per-column azimuth table: the same directions and solid angles as
 * pixel_direction / wenv_envmap_pixel_solid_angle, without a sincos per pixel. */
static size_t equirect_row_samples(const wenv_envmap *env, size_t row, float *dirs, float *flux, float *omega_out,
                                   uint32_t *cols)
{
    size_t w = env->width, h = env->height;
    double lat = PI * ((1.0 - ((double)row + 0.5) / (double)h) - 0.5), cl = cos(lat), sl = sin(lat);
    double omega = wenv_envmap_pixel_solid_angle(env, row, 0), k = omega * env->strength;
    const double *xy = env->column_xy;
    const float *p = pixel_at(env, row, 0);
    for (size_t col = 0; col < w; col++) {
        dirs[3 * col] = (float)(cl * xy[2 * col]);
        dirs[3 * col + 1] = (float)(cl * xy[2 * col + 1]);
        dirs[3 * col + 2] = (float)sl;
        for (int ch = 0; ch < 3; ch++)
            flux[3 * col + ch] = (float)(p[3 * col + ch] * k);
        if (omega_out)
            omega_out[col] = (float)omega;
        if (cols)
            cols[col] = (uint32_t)col;
    }
    return w;
}

size_t wenv_envmap_row_samples(const wenv_envmap *env, size_t row, float *dirs, float *flux, float *omega_out,
                               uint32_t *cols)
{
    if (env->projection == WENV_PROJ_EQUIRECT)
        return dirs ? equirect_row_samples(env, row, dirs, flux, omega_out, cols) : env->width;
    double c = env->cos_r, s = env->sin_r;
    size_t m = 0;
    for (size_t col = 0; col < env->width; col++) {
        const float *p = pixel_at(env, row, col);
        double omega = wenv_envmap_pixel_solid_angle(env, row, col), d[3];
        if (!(omega > 0.0) || !pixel_direction(env, row, col, d))
            continue;
        if (dirs) {
            /* world direction w with R_z(r) w = d, i.e. w = R_z(-r) d */
            dirs[3 * m] = (float)(c * d[0] + s * d[1]);
            dirs[3 * m + 1] = (float)(-s * d[0] + c * d[1]);
            dirs[3 * m + 2] = (float)d[2];
            double k = omega * env->strength;
            for (int ch = 0; ch < 3; ch++)
                flux[3 * m + ch] = (float)(p[ch] * k);
            if (omega_out)
                omega_out[m] = (float)omega;
            if (cols)
                cols[m] = (uint32_t)col;
        }
        m++;
    }
    return m;
}

size_t wenv_envmap_samples(const wenv_envmap *env, float *dirs, float *flux, float *omega_out)
{
    /* Rows in parallel: count each row's valid pixels, then fill from the prefix sums, so the
     * order is the serial one. */
    size_t h = env->height;
    size_t *start = malloc((h + 1) * sizeof(size_t));
    if (!start) {
        size_t m = 0;
        for (size_t row = 0; row < h; row++)
            m += wenv_envmap_row_samples(env, row, dirs + 3 * m, flux + 3 * m, omega_out ? omega_out + m : NULL, NULL);
        return m;
    }
    start[0] = 0;
#pragma omp parallel for schedule(dynamic, 8)
    for (size_t row = 0; row < h; row++)
        start[row + 1] = wenv_envmap_row_samples(env, row, NULL, NULL, NULL, NULL);
    for (size_t row = 0; row < h; row++)
        start[row + 1] += start[row];
#pragma omp parallel for schedule(dynamic, 8)
    for (size_t row = 0; row < h; row++) {
        size_t m = start[row];
        wenv_envmap_row_samples(env, row, dirs + 3 * m, flux + 3 * m, omega_out ? omega_out + m : NULL, NULL);
    }
    size_t m = start[h];
    free(start);
    return m;
}

/* Whether a ranks before b: brighter, then earlier in the image (a total order, so the result does
 * not depend on how rows were split between threads). */
static int brighter(const wenv_bright_pixel *a, const wenv_bright_pixel *b)
{
    return a->radiance > b->radiance || (a->radiance == b->radiance && a->pixel < b->pixel);
}

/* The k brightest seen so far as a heap whose root is the dimmest of them (n of capacity k):
 * O(log k) per candidate, where a sorted list costs O(k) and a sun-lit scene has tens of
 * thousands of candidates. */
static void sift_down(wenv_bright_pixel *heap, size_t n, size_t i)
{
    for (;;) {
        size_t l = 2 * i + 1, r = l + 1, dim = i;
        if (l < n && brighter(&heap[dim], &heap[l]))
            dim = l;
        if (r < n && brighter(&heap[dim], &heap[r]))
            dim = r;
        if (dim == i)
            return;
        wenv_bright_pixel t = heap[i];
        heap[i] = heap[dim];
        heap[dim] = t;
        i = dim;
    }
}

static void keep_brightest(wenv_bright_pixel *heap, size_t *n, size_t k, const wenv_bright_pixel *p)
{
    if (*n < k) {
        size_t i = (*n)++;
        heap[i] = *p;
        while (i > 0 && brighter(&heap[(i - 1) / 2], &heap[i])) {
            wenv_bright_pixel t = heap[i];
            heap[i] = heap[(i - 1) / 2];
            heap[(i - 1) / 2] = t;
            i = (i - 1) / 2;
        }
    } else if (brighter(p, &heap[0])) {
        heap[0] = *p;
        sift_down(heap, k, 0);
    }
}

static int cmp_brighter(const void *a, const void *b)
{
    return brighter(a, b) ? -1 : brighter(b, a) ? 1 : 0;
}

static int cmp_pixel(const void *a, const void *b)
{
    size_t x = ((const wenv_bright_pixel *)a)->pixel, y = ((const wenv_bright_pixel *)b)->pixel;
    return (x > y) - (x < y);
}

/* Per-row flux and peak, once per image (they do not change with rotation or strength): the search
 * for the brightest pixels at each lighting change then reads only rows that can hold one. */
static int row_stats(wenv_envmap *env)
{
    size_t w = env->width, h = env->height;
    env->row_flux = malloc((h ? h : 1) * sizeof(double));
    env->row_peak = malloc((h ? h : 1) * sizeof(float));
    if (!env->row_flux || !env->row_peak)
        return -1;
#pragma omp parallel for schedule(static)
    for (size_t row = 0; row < h; row++) {
        const float *p = pixel_at(env, row, 0);
        double flux = 0.0, row_omega = env->projection == WENV_PROJ_EQUIRECT ? wenv_envmap_pixel_solid_angle(env, row, 0)
                                                                               : -1.0;
        float peak = 0.0f;
        for (size_t col = 0; col < w; col++, p += 3) {
            double omega = row_omega >= 0.0 ? row_omega : wenv_envmap_pixel_solid_angle(env, row, col);
            if (!(omega > 0.0))
                continue;
            flux += omega * ((double)p[0] + p[1] + p[2]) / 3.0;
            float big = p[0] > p[1] ? p[0] : p[1];
            big = big > p[2] ? big : p[2];
            peak = big > peak ? big : peak;
        }
        env->row_flux[row] = flux;
        env->row_peak[row] = peak;
    }
    return 0;
}

double wenv_envmap_flux(const wenv_envmap *env)
{
    double total = 0.0;
    for (size_t row = 0; row < env->height; row++)
        total += env->row_flux[row];
    return total * env->strength;
}

size_t wenv_envmap_brightest(const wenv_envmap *env, size_t k, double relative, wenv_bright_pixel *out)
{
    size_t w = env->width, h = env->height;
    if (!k || !w || !h)
        return 0;
    double threshold = relative * wenv_envmap_flux(env) / (4.0 * PI);
    size_t n = 0;
    float strength = (float)env->strength;
    /* only rows whose peak passes the threshold can hold a light: a sun touches a handful */
    for (size_t row = 0; row < h; row++) {
        if (!((double)env->row_peak[row] * env->strength > threshold))
            continue;
        const float *p = pixel_at(env, row, 0);
        for (size_t col = 0; col < w; col++, p += 3) {
            float big = p[0] > p[1] ? p[0] : p[1];
            big = (big > p[2] ? big : p[2]) * strength;
            if (!((double)big > threshold) || (n == k && big < out[0].radiance))
                continue;
            if (env->projection != WENV_PROJ_EQUIRECT && !(wenv_envmap_pixel_solid_angle(env, row, col) > 0.0))
                continue;
            wenv_bright_pixel b = {.pixel = row * w + col, .radiance = big};
            keep_brightest(out, &n, k, &b);
        }
    }
    /* direction and flux exactly as wenv_envmap_samples gives them, so that whoever takes these
     * pixels out of a sum of samples takes out precisely what was put in; one pass per row */
    float *dirs = n ? malloc(w * 7 * sizeof(float)) : NULL;
    uint32_t *cols = n ? malloc(w * sizeof(uint32_t)) : NULL;
    if (n && (!dirs || !cols))
        n = 0;
    qsort(out, n, sizeof *out, cmp_pixel);
    for (size_t i = 0; i < n;) {
        size_t row = out[i].pixel / w, end = i;
        while (end < n && out[end].pixel / w == row)
            end++;
        size_t m = wenv_envmap_row_samples(env, row, dirs, dirs + 3 * w, dirs + 6 * w, cols);
        for (size_t e = 0, j = i; e < m && j < end; e++) { /* both ascending in column */
            while (j < end && out[j].pixel % w < cols[e])
                j++; /* not a sample (cannot happen: checked above); its flux stays 0 */
            if (j < end && out[j].pixel % w == cols[e]) {
                memcpy(out[j].dir, dirs + 3 * e, sizeof out[j].dir);
                memcpy(out[j].flux, dirs + 3 * w + 3 * e, sizeof out[j].flux);
                j++;
            }
        }
        i = end;
    }
    qsort(out, n, sizeof *out, cmp_brighter);
    free(dirs);
    free(cols);
    return n;
}

/* ---------------------------------------------------------------------------------------------
 * Lookup */

static void lookup_equirect(const wenv_envmap *env, const double d[3], double acc[3])
{
    size_t w = env->width, h = env->height;
    double z = fmin(fmax(d[2], -1.0), 1.0);
    double u = 0.5 - atan2(d[1], d[0]) / (2.0 * PI), v = 0.5 + asin(z) / PI;
    double fx = u * (double)w - 0.5, fy = (1.0 - v) * (double)h - 0.5;
    fy = fmin(fmax(fy, 0.0), (double)(h - 1)); /* the poles clamp to the first and last rows */
    double x0f = floor(fx), y0f = floor(fy);
    double wx = fx - x0f, wy = fy - y0f;
    long long xi = (long long)x0f % (long long)w; /* wraps horizontally across the seam */
    if (xi < 0)
        xi += (long long)w;
    size_t x0 = (size_t)xi, x1 = (x0 + 1) % w;
    size_t y0 = (size_t)y0f, y1 = y0 + 1 < h ? y0 + 1 : y0;
    const float *p00 = pixel_at(env, y0, x0), *p01 = pixel_at(env, y0, x1);
    const float *p10 = pixel_at(env, y1, x0), *p11 = pixel_at(env, y1, x1);
    for (int c = 0; c < 3; c++)
        acc[c] = (1.0 - wy) * ((1.0 - wx) * p00[c] + wx * p01[c]) + wy * ((1.0 - wx) * p10[c] + wx * p11[c]);
}

static void lookup_mirror_ball(const wenv_envmap *env, const double d[3], double acc[3])
{
    /* Cycles' direction_to_mirrorball */
    double x = d[0], y = d[1] - 1.0, z = d[2];
    double div = 2.0 * sqrt(fmax(-0.5 * y, 0.0));
    if (div > 1e-150) {
        x /= div;
        z /= div;
    } else { /* exactly +Y: every rim point sees it; pick one instead of Cycles' centre */
        x = 1.0;
        z = 0.0;
    }
    size_t w = env->width, h = env->height;
    double fx = 0.5 * (x + 1.0) * (double)w - 0.5, fy = (1.0 - 0.5 * (z + 1.0)) * (double)h - 0.5;
    fx = fmin(fmax(fx, 0.0), (double)(w - 1));
    fy = fmin(fmax(fy, 0.0), (double)(h - 1));
    size_t x0 = (size_t)floor(fx), y0 = (size_t)floor(fy);
    double wx = fx - (double)x0, wy = fy - (double)y0;
    size_t xs[2] = {x0, x0 + 1 < w ? x0 + 1 : x0}, ys[2] = {y0, y0 + 1 < h ? y0 + 1 : y0};
    double wxs[2] = {1.0 - wx, wx}, wys[2] = {1.0 - wy, wy};
    /* bilinear over the taps that touch the disk only, so the rim does not fade into the
     * (arbitrary) outside of the ball */
    double total = 0.0, sum[3] = {0, 0, 0}, plain[3] = {0, 0, 0};
    for (int j = 0; j < 2; j++) {
        for (int i = 0; i < 2; i++) {
            double wt = wys[j] * wxs[i];
            const float *p = pixel_at(env, ys[j], xs[i]);
            for (int c = 0; c < 3; c++)
                plain[c] += wt * p[c];
            if (wt > 0.0 && ball_pixel_in_disk(env, ys[j], xs[i])) {
                total += wt;
                for (int c = 0; c < 3; c++)
                    sum[c] += wt * p[c];
            }
        }
    }
    for (int c = 0; c < 3; c++)
        acc[c] = total > 0.0 ? sum[c] / total : plain[c];
}

/* Pixel of face texel (x, y); texels just beyond the face edge are read from the neighbouring face. */
static const float *cube_texel(const wenv_envmap *env, int f, long long x, long long y)
{
    long long n = (long long)env->face_size;
    if (x < 0 || y < 0 || x >= n || y >= n) {
        const cube_face *fc = &env->faces[f];
        double s = (2.0 * (double)x + 1.0 - (double)n) / (double)n, t = (2.0 * (double)y + 1.0 - (double)n) / (double)n;
        double d[3];
        for (int k = 0; k < 3; k++)
            d[k] = fc->c[k] + s * fc->r[k] + t * fc->d[k];
        f = cube_face_of(d);
        fc = &env->faces[f];
        double dc = dot3(d, fc->c);
        double s2 = dot3(d, fc->r) / dc, t2 = dot3(d, fc->d) / dc;
        x = (long long)floor(0.5 * (s2 + 1.0) * (double)n);
        y = (long long)floor(0.5 * (t2 + 1.0) * (double)n);
        x = x < 0 ? 0 : (x >= n ? n - 1 : x);
        y = y < 0 ? 0 : (y >= n ? n - 1 : y);
    }
    const cube_face *fc = &env->faces[f];
    return pixel_at(env, fc->cell_row * env->face_size + (size_t)y, fc->cell_col * env->face_size + (size_t)x);
}

static void lookup_cube(const wenv_envmap *env, const double d[3], double acc[3])
{
    int f = cube_face_of(d);
    const cube_face *fc = &env->faces[f];
    double dc = dot3(d, fc->c); /* >= 1/sqrt(3) for the selected face */
    double s = dot3(d, fc->r) / dc, t = dot3(d, fc->d) / dc;
    double n = (double)env->face_size;
    double fx = fmin(fmax(0.5 * (s + 1.0) * n - 0.5, -0.5), n - 0.5);
    double fy = fmin(fmax(0.5 * (t + 1.0) * n - 0.5, -0.5), n - 0.5);
    double x0f = floor(fx), y0f = floor(fy), wx = fx - x0f, wy = fy - y0f;
    long long x0 = (long long)x0f, y0 = (long long)y0f;
    const float *p00 = cube_texel(env, f, x0, y0), *p01 = cube_texel(env, f, x0 + 1, y0);
    const float *p10 = cube_texel(env, f, x0, y0 + 1), *p11 = cube_texel(env, f, x0 + 1, y0 + 1);
    for (int c = 0; c < 3; c++)
        acc[c] = (1.0 - wy) * ((1.0 - wx) * p00[c] + wx * p01[c]) + wy * ((1.0 - wx) * p10[c] + wx * p11[c]);
}

void wenv_envmap_lookup(const wenv_envmap *env, const double dir[3], float rgb[3])
{
    double len = sqrt(dir[0] * dir[0] + dir[1] * dir[1] + dir[2] * dir[2]);
    double w[3] = {0.0, 0.0, 1.0};
    if (len > 0.0 && isfinite(len)) {
        w[0] = dir[0] / len;
        w[1] = dir[1] / len;
        w[2] = dir[2] / len;
    }
    /* image direction R_z(r) w: the Mapping node's Z rotation */
    double d[3] = {env->cos_r * w[0] - env->sin_r * w[1], env->sin_r * w[0] + env->cos_r * w[1], w[2]};
    double acc[3] = {0, 0, 0};
    switch (env->projection) {
    case WENV_PROJ_EQUIRECT: lookup_equirect(env, d, acc); break;
    case WENV_PROJ_MIRROR_BALL: lookup_mirror_ball(env, d, acc); break;
    case WENV_PROJ_CUBE_CROSS: lookup_cube(env, d, acc); break;
    }
    for (int c = 0; c < 3; c++)
        rgb[c] = (float)(acc[c] * env->strength);
}

void wenv_envmap_lookup_many(const wenv_envmap *env, const float *dirs, size_t n, float *rgb)
{
#pragma omp parallel for schedule(static) if (n > 8192)
    for (size_t i = 0; i < n; i++) {
        double d[3] = {dirs[3 * i], dirs[3 * i + 1], dirs[3 * i + 2]};
        wenv_envmap_lookup(env, d, rgb + 3 * i);
    }
}

/* ---------------------------------------------------------------------------------------------
 * Files */

typedef struct {
    int fd;
    int64_t size;
    char message[200]; /* first detailed message from OpenEXRCore */
} exr_stream;

static int64_t exr_read_cb(exr_const_context_t ctxt, void *user, void *buffer, uint64_t sz, uint64_t offset,
                           exr_stream_error_func_ptr_t error_cb)
{
    exr_stream *s = user;
    uint8_t *dst = buffer;
    uint64_t done = 0;
    if (offset > (uint64_t)s->size)
        return 0; /* past the end: OpenEXRCore reports the short read */
    while (done < sz) {
        size_t want = sz - done > ((size_t)1 << 30) ? ((size_t)1 << 30) : (size_t)(sz - done);
        ssize_t got = pread(s->fd, dst + done, want, (off_t)(offset + done));
        if (got < 0) {
            if (errno == EINTR)
                continue;
            if (error_cb)
                error_cb(ctxt, EXR_ERR_READ_IO, "read error at offset %llu", (unsigned long long)(offset + done));
            return -1;
        }
        if (got == 0)
            break;
        done += (uint64_t)got;
    }
    return (int64_t)done;
}

static int64_t exr_size_cb(exr_const_context_t ctxt, void *user)
{
    (void)ctxt;
    return ((exr_stream *)user)->size;
}

static void exr_error_cb(exr_const_context_t ctxt, exr_result_t code, const char *msg)
{
    void *user = NULL;
    /* silence OpenEXRCore's default printing to stderr; keep the first message for the exception */
    if (ctxt && exr_get_user_data(ctxt, &user) == EXR_ERR_SUCCESS && user) {
        exr_stream *s = user;
        if (!s->message[0])
            snprintf(s->message, sizeof s->message, "%s", msg ? msg : exr_get_error_code_as_string(code));
    }
}

static wenv_status exr_fail(wenv_error *err, const char *path, const exr_stream *s, exr_result_t rv)
{
    return wenv_error_set(err, WENV_ERR_IO, "cannot read OpenEXR file '%s': %s", path,
                          s->message[0] ? s->message : exr_get_error_code_as_string(rv));
}

/* Colour slot of an EXR channel: 0..2 for R, G, B; 3 for Y (grey); -1 otherwise. */
static int exr_channel_slot(const char *name)
{
    if (!name)
        return -1;
    if (strcmp(name, "R") == 0)
        return 0;
    if (strcmp(name, "G") == 0)
        return 1;
    if (strcmp(name, "B") == 0)
        return 2;
    if (strcmp(name, "Y") == 0)
        return 3;
    return -1;
}

/* Decodes one chunk whose top-left pixel is (x_off, y_off) in the data window into rgb. */
static exr_result_t exr_decode_chunk(exr_context_t ctx, const exr_chunk_info_t *cinfo, exr_decode_pipeline_t *dec,
                                     int *initialised, float *rgb, size_t width, size_t height, int64_t x_off,
                                     int64_t y_off, int grey)
{
    if (x_off < 0 || y_off < 0 || cinfo->width <= 0 || cinfo->height <= 0 ||
        (uint64_t)x_off + (uint64_t)cinfo->width > width || (uint64_t)y_off + (uint64_t)cinfo->height > height)
        return EXR_ERR_BAD_CHUNK_LEADER; /* a chunk outside the data window: corrupt file */
    exr_result_t rv = *initialised ? exr_decoding_update(ctx, 0, cinfo, dec)
                                   : exr_decoding_initialize(ctx, 0, cinfo, dec);
    if (rv != EXR_ERR_SUCCESS)
        return rv;
    *initialised = 1;
    for (int16_t c = 0; c < dec->channel_count; c++) {
        exr_coding_channel_info_t *ch = &dec->channels[c];
        int slot = exr_channel_slot(ch->channel_name);
        if (grey ? slot != 3 : (slot < 0 || slot > 2)) {
            ch->decode_to_ptr = NULL; /* not wanted: the pipeline skips it */
            continue;
        }
        ch->decode_to_ptr = (uint8_t *)(rgb + ((size_t)y_off * width + (size_t)x_off) * 3 + (grey ? 0 : slot));
        ch->user_bytes_per_element = 4;
        ch->user_data_type = EXR_PIXEL_FLOAT;
        ch->user_pixel_stride = 3 * (int32_t)sizeof(float);
        ch->user_line_stride = (int32_t)(3 * sizeof(float) * width);
    }
    rv = exr_decoding_choose_default_routines(ctx, 0, dec);
    if (rv != EXR_ERR_SUCCESS)
        return rv;
    return exr_decoding_run(ctx, 0, dec);
}

/* OpenEXRCore 3.1 cannot decompress DWAA/DWAB ("not yet implemented in C"), and Blender's bundled
 * HDRIs are DWAB.  For those files only, wenv falls back to OpenEXR's own C interface to its C++
 * library (ImfCRgbaFile.h, shipped in the same Debian package as OpenEXRCore).  It is loaded with
 * dlopen on demand so the build keeps linking OpenEXRCore alone; the handle is never closed, as a
 * linked library would never be unloaded either. */
typedef struct {
    ImfInputFile *(*open)(const char name[]);
    int (*close)(ImfInputFile *in);
    int (*set_frame_buffer)(ImfInputFile *in, ImfRgba *base, size_t x_stride, size_t y_stride);
    int (*read_pixels)(ImfInputFile *in, int scan_line1, int scan_line2);
    const ImfHeader *(*header)(const ImfInputFile *in);
    int (*channels)(const ImfInputFile *in);
    void (*data_window)(const ImfHeader *hdr, int *x_min, int *y_min, int *x_max, int *y_max);
    void (*half_to_float)(int n, const ImfHalf h[], float f[]);
    const char *(*error_message)(void);
} imf_api;

#define STR_(x) #x
#define STR(x) STR_(x)

static int imf_api_load(imf_api *api, char *why, size_t why_size)
{
    /* the soname of the C++ library that ships with the OpenEXRCore we were built against */
    char soname[64];
    const char *lib_version = OPENEXR_LIB_VERSION_STRING;
    size_t major_len = strcspn(lib_version, ".");
    snprintf(soname, sizeof soname, "libOpenEXR-%d_%d.so.%.*s", OPENEXR_VERSION_MAJOR, OPENEXR_VERSION_MINOR,
             (int)major_len, lib_version);
    const char *candidates[] = {soname, "libOpenEXR-" STR(OPENEXR_VERSION_MAJOR) "_" STR(OPENEXR_VERSION_MINOR) ".so",
                                "libOpenEXR.so"};
    void *lib = NULL;
    for (size_t i = 0; i < sizeof candidates / sizeof *candidates && !lib; i++)
        lib = dlopen(candidates[i], RTLD_NOW | RTLD_LOCAL);
    if (!lib) {
        const char *e = dlerror();
        snprintf(why, why_size, "%s", e ? e : soname);
        return -1;
    }
    struct {
        void **slot;
        const char *name;
    } symbols[] = {
        {(void **)&api->open, "ImfOpenInputFile"},
        {(void **)&api->close, "ImfCloseInputFile"},
        {(void **)&api->set_frame_buffer, "ImfInputSetFrameBuffer"},
        {(void **)&api->read_pixels, "ImfInputReadPixels"},
        {(void **)&api->header, "ImfInputHeader"},
        {(void **)&api->channels, "ImfInputChannels"},
        {(void **)&api->data_window, "ImfHeaderDataWindow"},
        {(void **)&api->half_to_float, "ImfHalfToFloatArray"},
        {(void **)&api->error_message, "ImfErrorMessage"},
    };
    for (size_t i = 0; i < sizeof symbols / sizeof *symbols; i++) {
        /* POSIX's way to store a function address obtained from dlsym */
        *symbols[i].slot = dlsym(lib, symbols[i].name);
        if (!*symbols[i].slot) {
            snprintf(why, why_size, "symbol %s missing from %s", symbols[i].name, soname);
            return -1;
        }
    }
    return 0;
}

static wenv_status load_exr_rgba(const char *path, float **out, size_t *out_h, size_t *out_w, wenv_error *err)
{
    imf_api api;
    char why[256];
    if (imf_api_load(&api, why, sizeof why) < 0)
        return wenv_error_set(err, WENV_ERR_IO,
                              "cannot read OpenEXR file '%s': its compression (DWAA/DWAB) needs OpenEXR's library "
                              "libOpenEXR, which could not be loaded (%s)",
                              path, why);
    ImfInputFile *in = api.open(path);
    if (!in) {
        const char *m = api.error_message();
        return wenv_error_set(err, WENV_ERR_IO, "cannot read OpenEXR file '%s': %s", path, m ? m : "unknown error");
    }
    float *rgb = NULL, *row_f = NULL;
    ImfRgba *buf = NULL;
    int x_min, y_min, x_max, y_max;
    api.data_window(api.header(in), &x_min, &y_min, &x_max, &y_max);
    int64_t w64 = (int64_t)x_max - x_min + 1, h64 = (int64_t)y_max - y_min + 1;
    if (!(api.channels(in) & (IMF_WRITE_RGB | IMF_WRITE_Y))) {
        wenv_error_set(err, WENV_ERR_IO, "cannot read OpenEXR file '%s': it has no R, G, B (or Y) channels", path);
        goto done;
    }
    if (w64 <= 0 || h64 <= 0 || (uint64_t)w64 > MAX_SIDE || (uint64_t)h64 > MAX_SIDE ||
        (uint64_t)w64 * (uint64_t)h64 > MAX_PIXELS) {
        wenv_error_set(err, WENV_ERR_IO, "cannot read OpenEXR file '%s': unusable data window %lld x %lld", path,
                       (long long)w64, (long long)h64);
        goto done;
    }
    size_t width = (size_t)w64, height = (size_t)h64;
    buf = malloc(width * height * sizeof *buf);
    rgb = malloc(width * height * 3 * sizeof *rgb);
    row_f = malloc(width * 4 * sizeof *row_f);
    if (!buf || !rgb || !row_f) {
        wenv_error_set(err, WENV_ERR_NOMEM, "out of memory reading '%s' (%zu x %zu)", path, width, height);
        goto done;
    }
    /* the RGBA interface addresses pixels by absolute (x, y): shift the base by the window's corner */
    uintptr_t base = (uintptr_t)buf - ((uintptr_t)(intptr_t)x_min + (uintptr_t)(intptr_t)y_min * width) * sizeof *buf;
    if (!api.set_frame_buffer(in, (ImfRgba *)base, 1, width) || !api.read_pixels(in, y_min, y_max)) {
        const char *m = api.error_message();
        wenv_error_set(err, WENV_ERR_IO, "cannot read OpenEXR file '%s': %s", path, m ? m : "unknown error");
        goto done;
    }
    for (size_t r = 0; r < height; r++) {
        api.half_to_float((int)(4 * width), &buf[r * width].r, row_f);
        for (size_t x = 0; x < width; x++)
            for (size_t c = 0; c < 3; c++)
                rgb[(r * width + x) * 3 + c] = row_f[4 * x + c];
    }
    *out = rgb;
    *out_h = height;
    *out_w = width;
    rgb = NULL;
done:
    api.close(in);
    free(buf);
    free(rgb);
    free(row_f);
    return err->status;
}

static wenv_status load_exr(int fd, int64_t size, const char *path, float **out, size_t *out_h, size_t *out_w,
                            wenv_error *err)
{
    exr_stream stream = {fd, size, ""};
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    init.error_handler_fn = exr_error_cb;
    init.user_data = &stream;
    init.read_fn = exr_read_cb;
    init.size_fn = exr_size_cb;
    exr_context_t ctx = NULL;
    exr_result_t rv = exr_start_read(&ctx, path, &init);
    if (rv != EXR_ERR_SUCCESS) {
        exr_fail(err, path, &stream, rv);
        exr_finish(&ctx);
        return err->status;
    }
    float *rgb = NULL;
    exr_decode_pipeline_t dec = EXR_DECODE_PIPELINE_INITIALIZER;
    int initialised = 0, use_rgba = 0;
    exr_storage_t storage;
    exr_attr_box2i_t dw;
    const exr_attr_chlist_t *chl = NULL;
    if ((rv = exr_get_storage(ctx, 0, &storage)) != EXR_ERR_SUCCESS ||
        (rv = exr_get_data_window(ctx, 0, &dw)) != EXR_ERR_SUCCESS ||
        (rv = exr_get_channels(ctx, 0, &chl)) != EXR_ERR_SUCCESS || !chl) {
        exr_fail(err, path, &stream, rv);
        goto done;
    }
    if (storage != EXR_STORAGE_SCANLINE && storage != EXR_STORAGE_TILED) {
        wenv_error_set(err, WENV_ERR_IO, "cannot read OpenEXR file '%s': deep images are not supported", path);
        goto done;
    }
    int64_t w64 = (int64_t)dw.max.x - dw.min.x + 1, h64 = (int64_t)dw.max.y - dw.min.y + 1;
    if (w64 <= 0 || h64 <= 0 || (uint64_t)w64 > MAX_SIDE || (uint64_t)h64 > MAX_SIDE ||
        (uint64_t)w64 * (uint64_t)h64 > MAX_PIXELS) {
        wenv_error_set(err, WENV_ERR_IO, "cannot read OpenEXR file '%s': unusable data window %lld x %lld", path,
                       (long long)w64, (long long)h64);
        goto done;
    }
    size_t width = (size_t)w64, height = (size_t)h64;
    int have[4] = {0, 0, 0, 0};
    for (int i = 0; i < chl->num_channels; i++) {
        const exr_attr_chlist_entry_t *e = &chl->entries[i];
        int slot = exr_channel_slot(e->name.str);
        if (slot < 0)
            continue;
        if (e->pixel_type != EXR_PIXEL_HALF && e->pixel_type != EXR_PIXEL_FLOAT) {
            wenv_error_set(err, WENV_ERR_IO, "cannot read OpenEXR file '%s': channel %s is not half or float", path,
                           e->name.str);
            goto done;
        }
        if (e->x_sampling != 1 || e->y_sampling != 1) {
            wenv_error_set(err, WENV_ERR_IO, "cannot read OpenEXR file '%s': channel %s is subsampled", path,
                           e->name.str);
            goto done;
        }
        have[slot] = 1;
    }
    int grey = !(have[0] && have[1] && have[2]);
    if (grey && !have[3]) {
        char names[160] = "";
        size_t len = 0;
        for (int i = 0; i < chl->num_channels && len + 1 < sizeof names; i++)
            len += (size_t)snprintf(names + len, sizeof names - len, "%s%s", i ? ", " : "",
                                    chl->entries[i].name.str ? chl->entries[i].name.str : "?");
        wenv_error_set(err, WENV_ERR_IO,
                       "cannot read OpenEXR file '%s': it needs R, G and B (or Y) channels, found: %s", path,
                       names[0] ? names : "none");
        goto done;
    }
    rgb = calloc(width * height * 3, sizeof *rgb);
    if (!rgb) {
        wenv_error_set(err, WENV_ERR_NOMEM, "out of memory reading '%s' (%zu x %zu)", path, width, height);
        goto done;
    }
    exr_chunk_info_t cinfo;
    if (storage == EXR_STORAGE_SCANLINE) {
        int32_t lines = 0;
        if ((rv = exr_get_scanlines_per_chunk(ctx, 0, &lines)) != EXR_ERR_SUCCESS || lines <= 0) {
            exr_fail(err, path, &stream, rv != EXR_ERR_SUCCESS ? rv : EXR_ERR_INVALID_ATTR);
            goto done;
        }
        for (int64_t y = dw.min.y; y <= dw.max.y; y += lines) {
            rv = exr_read_scanline_chunk_info(ctx, 0, (int)y, &cinfo);
            if (rv == EXR_ERR_SUCCESS)
                rv = exr_decode_chunk(ctx, &cinfo, &dec, &initialised, rgb, width, height,
                                      (int64_t)cinfo.start_x - dw.min.x, (int64_t)cinfo.start_y - dw.min.y, grey);
            if (rv == EXR_ERR_FEATURE_NOT_IMPLEMENTED) {
                use_rgba = 1;
                goto done;
            }
            if (rv != EXR_ERR_SUCCESS) {
                exr_fail(err, path, &stream, rv);
                goto done;
            }
        }
    } else {
        int32_t tw = 0, th = 0;
        if ((rv = exr_get_tile_sizes(ctx, 0, 0, 0, &tw, &th)) != EXR_ERR_SUCCESS || tw <= 0 || th <= 0) {
            exr_fail(err, path, &stream, rv != EXR_ERR_SUCCESS ? rv : EXR_ERR_INVALID_ATTR);
            goto done;
        }
        size_t ntx = (width + (size_t)tw - 1) / (size_t)tw, nty = (height + (size_t)th - 1) / (size_t)th;
        for (size_t ty = 0; ty < nty; ty++) {
            for (size_t tx = 0; tx < ntx; tx++) {
                /* tile positions count from the data window's corner */
                rv = exr_read_tile_chunk_info(ctx, 0, (int)tx, (int)ty, 0, 0, &cinfo);
                if (rv == EXR_ERR_SUCCESS)
                    rv = exr_decode_chunk(ctx, &cinfo, &dec, &initialised, rgb, width, height,
                                          (int64_t)(tx * (size_t)tw), (int64_t)(ty * (size_t)th), grey);
                if (rv == EXR_ERR_FEATURE_NOT_IMPLEMENTED) {
                    use_rgba = 1;
                    goto done;
                }
                if (rv != EXR_ERR_SUCCESS) {
                    exr_fail(err, path, &stream, rv);
                    goto done;
                }
            }
        }
    }
    if (grey)
        for (size_t i = 0; i < width * height; i++)
            rgb[3 * i + 1] = rgb[3 * i + 2] = rgb[3 * i];
    *out = rgb;
    *out_h = height;
    *out_w = width;
    rgb = NULL;
done:
    if (initialised)
        exr_decoding_destroy(ctx, &dec);
    exr_finish(&ctx);
    free(rgb);
    if (use_rgba) /* OpenEXRCore lacks this compression: OpenEXR's C++ library decodes the file */
        return load_exr_rgba(path, out, out_h, out_w, err);
    return err->status;
}

/* Radiance RGBE: header lines up to a blank line, a resolution line, then scanlines that are flat,
 * old-style run-length (1,1,1,n repeats) or new-style RLE (2,2,hi,lo then four RLE channels). */

static wenv_status hdr_corrupt(wenv_error *err, const char *path, const char *what, size_t row)
{
    return wenv_error_set(err, WENV_ERR_IO, "cannot read Radiance HDR file '%s': %s in scanline %zu", path, what,
                          row);
}

static wenv_status hdr_scanline(const uint8_t **pp, const uint8_t *end, uint8_t *scan, size_t w, const char *path,
                                size_t row, wenv_error *err)
{
    const uint8_t *p = *pp;
    if (w >= 8 && w < 32768 && end - p >= 4 && p[0] == 2 && p[1] == 2 && !(p[2] & 0x80)) {
        if (((size_t)p[2] << 8 | p[3]) != w)
            return hdr_corrupt(err, path, "run-length scanline of the wrong width", row);
        p += 4;
        for (size_t ch = 0; ch < 4; ch++) {
            size_t x = 0;
            while (x < w) {
                if (p >= end)
                    return hdr_corrupt(err, path, "file is truncated", row);
                size_t count = *p++;
                if (count > 128) {
                    count -= 128;
                    if (count > w - x)
                        return hdr_corrupt(err, path, "run past the end of the line", row);
                    if (p >= end)
                        return hdr_corrupt(err, path, "file is truncated", row);
                    for (size_t i = 0; i < count; i++)
                        scan[4 * (x + i) + ch] = *p;
                    p++;
                } else {
                    if (count == 0 || count > w - x)
                        return hdr_corrupt(err, path, "bad literal run length", row);
                    if ((size_t)(end - p) < count)
                        return hdr_corrupt(err, path, "file is truncated", row);
                    for (size_t i = 0; i < count; i++)
                        scan[4 * (x + i) + ch] = p[i];
                    p += count;
                }
                x += count;
            }
        }
    } else {
        size_t x = 0;
        unsigned shift = 0;
        while (x < w) {
            if (end - p < 4)
                return hdr_corrupt(err, path, "file is truncated", row);
            if (p[0] == 1 && p[1] == 1 && p[2] == 1) { /* old-style run: repeat the previous pixel */
                if (x == 0 || shift > 24)
                    return hdr_corrupt(err, path, "bad old-style run", row);
                size_t count = (size_t)p[3] << shift;
                if (count > w - x)
                    return hdr_corrupt(err, path, "run past the end of the line", row);
                for (size_t i = 0; i < count; i++)
                    memcpy(scan + 4 * (x + i), scan + 4 * (x - 1), 4);
                x += count;
                shift += 8;
            } else {
                memcpy(scan + 4 * x, p, 4);
                x++;
                shift = 0;
            }
            p += 4;
        }
    }
    *pp = p;
    return WENV_OK;
}

static wenv_status load_hdr(const uint8_t *buf, size_t size, const char *path, float **out, size_t *out_h,
                            size_t *out_w, wenv_error *err)
{
    const uint8_t *p = buf, *end = buf + size;
    int first = 1, rgbe = 1;
    /* header: "#?PROGRAM" line, variable lines, blank line (EXPOSURE and the like are ignored,
     * as Blender and most readers do) */
    for (;;) {
        const uint8_t *nl = memchr(p, '\n', (size_t)(end - p));
        if (!nl)
            return wenv_error_set(err, WENV_ERR_IO, "cannot read Radiance HDR file '%s': header does not end",
                                  path);
        size_t len = (size_t)(nl - p);
        if (first) {
            first = 0;
        } else if (len == 0 || (len == 1 && p[0] == '\r')) {
            p = nl + 1;
            break;
        } else if (len >= 7 && memcmp(p, "FORMAT=", 7) == 0) {
            const char *fmt = (const char *)p + 7;
            size_t flen = len - 7;
            while (flen && (fmt[flen - 1] == '\r' || fmt[flen - 1] == ' '))
                flen--;
            if (flen == 15 && memcmp(fmt, "32-bit_rle_rgbe", 15) == 0)
                rgbe = 1;
            else
                rgbe = 0;
        }
        p = nl + 1;
    }
    if (!rgbe)
        return wenv_error_set(err, WENV_ERR_IO,
                              "cannot read Radiance HDR file '%s': only FORMAT=32-bit_rle_rgbe is supported (XYZE "
                              "and others are not)",
                              path);
    const uint8_t *nl = memchr(p, '\n', (size_t)(end - p));
    char line[80];
    size_t len = nl ? (size_t)(nl - p) : 0;
    if (!nl || len >= sizeof line)
        return wenv_error_set(err, WENV_ERR_IO, "cannot read Radiance HDR file '%s': missing resolution line", path);
    memcpy(line, p, len);
    line[len] = '\0';
    p = nl + 1;
    char a1[3], a2[3];
    unsigned long long h = 0, w = 0;
    int consumed = 0;
    if (sscanf(line, "%2s %llu %2s %llu %n", a1, &h, a2, &w, &consumed) != 4 || line[consumed] != '\0')
        return wenv_error_set(err, WENV_ERR_IO, "cannot read Radiance HDR file '%s': bad resolution line '%s'", path,
                              line);
    if (strcmp(a1, "-Y") != 0 || strcmp(a2, "+X") != 0)
        return wenv_error_set(err, WENV_ERR_IO,
                              "cannot read Radiance HDR file '%s': orientation '%s' is not supported, only the "
                              "standard '-Y height +X width'",
                              path, line);
    if (h == 0 || w == 0 || h > MAX_SIDE || w > MAX_SIDE || h * w > MAX_PIXELS)
        return wenv_error_set(err, WENV_ERR_IO, "cannot read Radiance HDR file '%s': unusable size %llu x %llu",
                              path, w, h);
    size_t width = (size_t)w, height = (size_t)h;
    float *rgb = malloc(width * height * 3 * sizeof *rgb);
    uint8_t *scan = malloc(width * 4);
    if (!rgb || !scan) {
        free(rgb);
        free(scan);
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory reading '%s' (%zu x %zu)", path, width, height);
    }
    for (size_t row = 0; row < height; row++) {
        if (hdr_scanline(&p, end, scan, width, path, row, err) != WENV_OK) {
            free(rgb);
            free(scan);
            return err->status;
        }
        float *dst = rgb + row * width * 3;
        for (size_t x = 0; x < width; x++) {
            const uint8_t *q = scan + 4 * x;
            /* mantissa * 2^(e - 136), e = 0 black: the same numbers Blender (OpenImageIO) and
             * stb_image read.  Radiance's own colr_color adds half a step to the mantissa; matching
             * Blender matters more here than that sub-1% bias. */
            double f = q[3] ? ldexp(1.0, (int)q[3] - 136) : 0.0;
            for (int c = 0; c < 3; c++)
                dst[3 * x + c] = (float)((double)q[c] * f);
        }
    }
    free(scan);
    *out = rgb;
    *out_h = height;
    *out_w = width;
    return WENV_OK;
}

static void describe_errno(int code, char *buf, size_t size)
{
    if (strerror_r(code, buf, size) != 0)
        snprintf(buf, size, "error %d", code);
}

wenv_status wenv_envmap_load(wenv_envmap **out, const char *path, wenv_projection projection, double rotation,
                             double strength, wenv_error *err)
{
    *out = NULL;
    if (!path)
        return wenv_error_set(err, WENV_ERR_VALUE, "path is NULL");
    if (check_transform(rotation, strength, err) || check_projection(projection, err))
        return err->status;
    char why[128];
    /* O_NONBLOCK: opening a FIFO must not wait for a writer (it is rejected below) */
    int fd = open(path, O_RDONLY | O_NONBLOCK | O_CLOEXEC);
    if (fd < 0) {
        int code = errno;
        describe_errno(code, why, sizeof why);
        return wenv_error_set(err, WENV_ERR_IO, "cannot open environment file '%s': %s", path, why);
    }
    struct stat st;
    if (fstat(fd, &st) != 0) {
        describe_errno(errno, why, sizeof why);
        close(fd);
        return wenv_error_set(err, WENV_ERR_IO, "cannot open environment file '%s': %s", path, why);
    }
    if (S_ISDIR(st.st_mode)) {
        close(fd);
        return wenv_error_set(err, WENV_ERR_IO, "environment file '%s' is a directory", path);
    }
    if (!S_ISREG(st.st_mode)) {
        close(fd);
        return wenv_error_set(err, WENV_ERR_IO, "environment file '%s' is not a regular file", path);
    }
    int64_t size = (int64_t)st.st_size;
    uint8_t magic[4] = {0, 0, 0, 0};
    ssize_t got = size >= 4 ? pread(fd, magic, 4, 0) : 0;
    float *rgb = NULL;
    size_t h = 0, w = 0;
    wenv_status status;
    if (got == 4 && magic[0] == 0x76 && magic[1] == 0x2f && magic[2] == 0x31 && magic[3] == 0x01) {
        status = load_exr(fd, size, path, &rgb, &h, &w, err);
    } else if (got == 4 && magic[0] == '#' && magic[1] == '?') {
        uint8_t *buf = (uint64_t)size < SIZE_MAX ? malloc((size_t)size) : NULL;
        if (!buf) {
            close(fd);
            return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory reading '%s'", path);
        }
        size_t done = 0;
        while (done < (size_t)size) {
            ssize_t n = pread(fd, buf + done, (size_t)size - done, (off_t)done);
            if (n < 0 && errno == EINTR)
                continue;
            if (n <= 0)
                break;
            done += (size_t)n;
        }
        if (done != (size_t)size) {
            free(buf);
            close(fd);
            return wenv_error_set(err, WENV_ERR_IO, "cannot read environment file '%s': read error", path);
        }
        status = load_hdr(buf, done, path, &rgb, &h, &w, err);
        free(buf);
    } else {
        close(fd);
        return wenv_error_set(err, WENV_ERR_IO,
                              "environment file '%s' is neither OpenEXR nor Radiance HDR (unknown magic bytes)",
                              path);
    }
    close(fd);
    if (status != WENV_OK)
        return status;
    char what[600];
    snprintf(what, sizeof what, "file '%s'", path);
    return envmap_adopt(out, rgb, h, w, projection, rotation, strength, what, err);
}
