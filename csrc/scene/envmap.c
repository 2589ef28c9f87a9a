/* Distant HDR environments: storage, the three projections, exact pixel solid angles, bilinear
 * lookup, and loading a file (the readers are exr_reader.c and rgbe_reader.c). */
#define _POSIX_C_SOURCE 200809L /* pread, fstat, strerror_r */

#include "scene/envmap.h"
#include "scene/image_readers.h"

#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "base/fingerprint.h"

#define PI 3.14159265358979323846

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
    atomic_size_t *image_users; /* environments sharing pixels, row_flux and row_peak (never changed
                                   once made): copies with another transform share them */
    uint64_t fingerprint; /* of the pixels (wenv_envmap_fingerprint) */
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
    if (height > WENV_IMAGE_MAX_SIDE || width > WENV_IMAGE_MAX_SIDE || height * width > WENV_IMAGE_MAX_PIXELS)
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

/* Where pixels come from: an argument (a bad one is a WENV_ERR_VALUE) or a file (WENV_ERR_IO, as for
 * every other fault of a file). */
typedef enum { PIXELS_FROM_ARGUMENT, PIXELS_FROM_FILE } pixel_source;

/* Whether pixels x strength stay within WENV_RADIANCE_MAX (the rows' peaks must be set). */
static wenv_status check_radiance_range(const wenv_envmap *env, const char *what, pixel_source source,
                                        wenv_error *err)
{
    double peak = 0.0;
    for (size_t row = 0; row < env->height; row++)
        peak = env->row_peak[row] > peak ? env->row_peak[row] : peak;
    if (!(peak * env->strength <= WENV_RADIANCE_MAX))
        return wenv_error_set(err, source == PIXELS_FROM_FILE ? WENV_ERR_IO : WENV_ERR_VALUE,
                              "%s: the brightest pixel times strength is %g, more than %g: wenv shades in float32, "
                              "which cannot hold what such lighting reflects (scale the image or strength down)",
                              what, peak * env->strength, WENV_RADIANCE_MAX);
    return WENV_OK;
}

/* Equirect: world (x, y) of each column's azimuth under the rotation, so that sampling every pixel
 * at a lighting change needs no sincos.  -1 when out of memory. */
static int column_azimuths(wenv_envmap *env)
{
    if (env->projection != WENV_PROJ_EQUIRECT)
        return 0;
    env->column_xy = malloc(2 * env->width * sizeof(double));
    if (!env->column_xy)
        return -1;
    for (size_t col = 0; col < env->width; col++) {
        double phi = PI * (1.0 - 2.0 * (((double)col + 0.5) / (double)env->width));
        double x = cos(phi), y = sin(phi);
        /* world direction w = R_z(-r) d */
        env->column_xy[2 * col] = env->cos_r * x + env->sin_r * y;
        env->column_xy[2 * col + 1] = -env->sin_r * x + env->cos_r * y;
    }
    return 0;
}

/* Takes ownership of rgb (height x width x 3). */
static wenv_status envmap_adopt_checked(wenv_envmap **out, float *rgb, size_t height, size_t width,
                                        wenv_projection projection, double rotation, double strength,
                                        const char *what, pixel_source source, wenv_error *err)
{
    *out = NULL;
    if (check_transform(rotation, strength, err) || check_shape(height, width, projection, what, err)) {
        free(rgb);
        return err->status;
    }
    size_t count = height * width * 3;
    for (size_t i = 0; i < count; i++) {
        if (!isfinite(rgb[i])) {
            size_t px = i / 3;
            wenv_error_set(err, source == PIXELS_FROM_FILE ? WENV_ERR_IO : WENV_ERR_VALUE,
                           "%s: pixel [row %zu, column %zu, channel %zu] is not finite", what, px / width, px % width,
                           i % 3);
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
    env->image_users = malloc(sizeof *env->image_users);
    if (env->image_users)
        atomic_init(env->image_users, 1);
    if (!env->image_users || column_azimuths(env) < 0) {
        wenv_envmap_free(env);
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for an environment");
    }
    if (projection == WENV_PROJ_CUBE_CROSS) {
        int vertical = width * 4 == height * 3;
        env->face_size = vertical ? width / 3 : width / 4;
        memcpy(env->faces, horizontal_cross, sizeof horizontal_cross);
        if (vertical)
            env->faces[1] = vertical_cross_minus_x;
    }
    if (row_stats(env) < 0) {
        wenv_envmap_free(env);
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for an environment");
    }
    if (check_radiance_range(env, what, source, err)) {
        wenv_envmap_free(env);
        return err->status;
    }
    *out = env;
    return WENV_OK;
}

static wenv_status envmap_adopt(wenv_envmap **out, float *rgb, size_t height, size_t width,
                                wenv_projection projection, double rotation, double strength, const char *what,
                                pixel_source source, wenv_error *err)
{
    return envmap_adopt_checked(out, rgb, height, width, projection, rotation, strength, what, source, err);
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
    return envmap_adopt(out, rgb, height, width, projection, rotation, strength, "pixels", PIXELS_FROM_ARGUMENT, err);
}

wenv_status wenv_envmap_with_transform(wenv_envmap **out, const wenv_envmap *env, double rotation,
                                       double strength, wenv_error *err)
{
    /* the image is shared, not copied: a lighting change makes one of these per new image */
    *out = NULL;
    if (check_transform(rotation, strength, err))
        return err->status;
    wenv_envmap *copy = malloc(sizeof *copy);
    if (!copy)
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for an environment");
    *copy = *env;
    copy->rotation = rotation;
    copy->strength = strength;
    copy->cos_r = cos(rotation);
    copy->sin_r = sin(rotation);
    copy->column_xy = NULL;
    atomic_fetch_add(copy->image_users, 1);
    if (column_azimuths(copy) < 0) {
        wenv_envmap_free(copy);
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for an environment");
    }
    if (check_radiance_range(copy, "strength", PIXELS_FROM_ARGUMENT, err)) {
        wenv_envmap_free(copy);
        return err->status;
    }
    *out = copy;
    return WENV_OK;
}

void wenv_envmap_free(wenv_envmap *env)
{
    if (!env)
        return;
    /* the last of the environments sharing the image frees it */
    if (!env->image_users || atomic_fetch_sub(env->image_users, 1) == 1) {
        free(env->pixels);
        free(env->row_flux);
        free(env->row_peak);
        free(env->image_users);
    }
    free(env->column_xy);
    free(env);
}

size_t wenv_envmap_width(const wenv_envmap *env) { return env->width; }
size_t wenv_envmap_height(const wenv_envmap *env) { return env->height; }
wenv_projection wenv_envmap_projection(const wenv_envmap *env) { return env->projection; }
double wenv_envmap_rotation(const wenv_envmap *env) { return env->rotation; }
double wenv_envmap_strength(const wenv_envmap *env) { return env->strength; }

double wenv_envmap_pixel_angle(const wenv_envmap *env)
{
    switch (env->projection) {
    case WENV_PROJ_EQUIRECT: return PI / (double)env->height;
    case WENV_PROJ_MIRROR_BALL: return 4.0 / (double)env->width; /* the disk's pi (w/2)^2 pixels over 4 pi sr */
    case WENV_PROJ_CUBE_CROSS: break;
    }
    return sqrt(4.0 * PI / 6.0) / (double)env->face_size;
}
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

/* Image-space direction (unrotated) of the point (fx, fy) of pixel (row, col), fx and fy in [0, 1]
 * across it (0.5, 0.5: its centre); 0 if outside the domain. */
static int pixel_point_direction(const wenv_envmap *env, size_t row, size_t col, double fx, double fy, double d[3])
{
    double w = (double)env->width, h = (double)env->height;
    switch (env->projection) {
    case WENV_PROJ_EQUIRECT: {
        double u = ((double)col + fx) / w, v = 1.0 - ((double)row + fy) / h;
        double phi = PI * (1.0 - 2.0 * u), lat = PI * (v - 0.5);
        d[0] = cos(lat) * cos(phi);
        d[1] = cos(lat) * sin(phi);
        d[2] = sin(lat);
        return 1;
    }
    case WENV_PROJ_MIRROR_BALL: {
        double x = (2.0 * ((double)col + fx) - w) / w, z = (h - 2.0 * ((double)row + fy)) / h;
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
        double s = (2.0 * ((double)(col % n) + fx) - nn) / nn, t = (2.0 * ((double)(row % n) + fy) - nn) / nn;
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

static int pixel_direction(const wenv_envmap *env, size_t row, size_t col, double d[3])
{
    return pixel_point_direction(env, row, col, 0.5, 0.5, d);
}

/* World direction w with R_z(r) w = d, i.e. w = R_z(-r) d. */
static inline void image_to_world(const wenv_envmap *env, const double d[3], double w[3])
{
    w[0] = env->cos_r * d[0] + env->sin_r * d[1];
    w[1] = -env->sin_r * d[0] + env->cos_r * d[1];
    w[2] = d[2];
}

/* Half the vector across pixel (row, col) from its left edge to its right (du) and from its top
 * to its bottom (dv), through its centre, in world space: centre + a du + b dv, a and b in [-1, 1],
 * spans the pixel to first order. */
static void pixel_footprint(const wenv_envmap *env, size_t row, size_t col, float du[3], float dv[3])
{
    double a[3], b[3], wa[3], wb[3];
    const double edge[4][2] = {{0.0, 0.5}, {1.0, 0.5}, {0.5, 0.0}, {0.5, 1.0}};
    for (int k = 0; k < 2; k++) {
        float *out = k ? dv : du;
        if (!pixel_point_direction(env, row, col, edge[2 * k][0], edge[2 * k][1], a) ||
            !pixel_point_direction(env, row, col, edge[2 * k + 1][0], edge[2 * k + 1][1], b)) {
            out[0] = out[1] = out[2] = 0.0f;
            continue;
        }
        image_to_world(env, a, wa);
        image_to_world(env, b, wb);
        for (int c = 0; c < 3; c++)
            out[c] = (float)(0.5 * (wb[c] - wa[c]));
    }
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
    size_t m = 0;
    for (size_t col = 0; col < env->width; col++) {
        const float *p = pixel_at(env, row, col);
        double omega = wenv_envmap_pixel_solid_angle(env, row, col), d[3];
        if (!(omega > 0.0) || !pixel_direction(env, row, col, d))
            continue;
        if (dirs) {
            double wd[3];
            image_to_world(env, d, wd);
            for (int k = 0; k < 3; k++)
                dirs[3 * m + k] = (float)wd[k];
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

/* Per-row flux, peak and fingerprint, once per image (they do not change with rotation or
 * strength): the search for the brightest pixels at each lighting change then reads only rows that
 * can hold one, and a lighting change tells a new image from a turned one at no cost. */
static int row_stats(wenv_envmap *env)
{
    size_t w = env->width, h = env->height;
    env->row_flux = malloc((h ? h : 1) * sizeof(double));
    env->row_peak = malloc((h ? h : 1) * sizeof(float));
    uint64_t *row_hash = malloc((h ? h : 1) * sizeof(uint64_t));
    if (!env->row_flux || !env->row_peak || !row_hash) {
        free(row_hash);
        return -1;
    }
#pragma omp parallel for schedule(static)
    for (size_t row = 0; row < h; row++) {
        const float *p = pixel_at(env, row, 0);
        row_hash[row] = wenv_fingerprint_floats(WENV_FINGERPRINT_START, p, 3 * w);
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
    uint64_t fp = WENV_FINGERPRINT_START;
    for (size_t row = 0; row < h; row++)
        fp = wenv_fingerprint_word(fp, row_hash[row]);
    env->fingerprint = fp ^ (uint64_t)(w * h);
    free(row_hash);
    return 0;
}

uint64_t wenv_envmap_fingerprint(const wenv_envmap *env)
{
    return env->fingerprint;
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
                pixel_footprint(env, row, cols[e], out[j].du, out[j].dv);
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

/* `nearest`: the pixel whose area holds d instead of the bilinear blend (weights snapped to 0 or 1). */
static void lookup_equirect(const wenv_envmap *env, const double d[3], int nearest, double acc[3])
{
    size_t w = env->width, h = env->height;
    double z = fmin(fmax(d[2], -1.0), 1.0);
    double u = 0.5 - atan2(d[1], d[0]) / (2.0 * PI), v = 0.5 + asin(z) / PI;
    double fx = u * (double)w - 0.5, fy = (1.0 - v) * (double)h - 0.5;
    fy = fmin(fmax(fy, 0.0), (double)(h - 1)); /* the poles clamp to the first and last rows */
    double x0f = floor(fx), y0f = floor(fy);
    double wx = fx - x0f, wy = fy - y0f;
    if (nearest) { /* the one pixel the bilinear blend's snapped weights pick, read alone */
        long long x = (long long)x0f + (wx >= 0.5), n = (long long)w;
        x = x < 0 ? x + n : (x >= n ? x - n : x); /* fx lies in [-0.5, w - 0.5]: one wrap at most */
        size_t y = (size_t)y0f + (wy >= 0.5 && (size_t)y0f + 1 < h);
        const float *p = pixel_at(env, y, (size_t)x);
        for (int c = 0; c < 3; c++)
            acc[c] = p[c];
        return;
    }
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

static void lookup_mirror_ball(const wenv_envmap *env, const double d[3], int nearest, double acc[3])
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
    if (nearest) {
        wx = wx >= 0.5;
        wy = wy >= 0.5;
    }
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

static void lookup_cube(const wenv_envmap *env, const double d[3], int nearest, double acc[3])
{
    int f = cube_face_of(d);
    const cube_face *fc = &env->faces[f];
    double dc = dot3(d, fc->c); /* >= 1/sqrt(3) for the selected face */
    double s = dot3(d, fc->r) / dc, t = dot3(d, fc->d) / dc;
    double n = (double)env->face_size;
    double fx = fmin(fmax(0.5 * (s + 1.0) * n - 0.5, -0.5), n - 0.5);
    double fy = fmin(fmax(0.5 * (t + 1.0) * n - 0.5, -0.5), n - 0.5);
    double x0f = floor(fx), y0f = floor(fy), wx = fx - x0f, wy = fy - y0f;
    if (nearest) {
        wx = wx >= 0.5;
        wy = wy >= 0.5;
    }
    long long x0 = (long long)x0f, y0 = (long long)y0f;
    const float *p00 = cube_texel(env, f, x0, y0), *p01 = cube_texel(env, f, x0 + 1, y0);
    const float *p10 = cube_texel(env, f, x0, y0 + 1), *p11 = cube_texel(env, f, x0 + 1, y0 + 1);
    for (int c = 0; c < 3; c++)
        acc[c] = (1.0 - wy) * ((1.0 - wx) * p00[c] + wx * p01[c]) + wy * ((1.0 - wx) * p10[c] + wx * p11[c]);
}

static void lookup(const wenv_envmap *env, const double dir[3], int nearest, float rgb[3])
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
    case WENV_PROJ_EQUIRECT: lookup_equirect(env, d, nearest, acc); break;
    case WENV_PROJ_MIRROR_BALL: lookup_mirror_ball(env, d, nearest, acc); break;
    case WENV_PROJ_CUBE_CROSS: lookup_cube(env, d, nearest, acc); break;
    }
    for (int c = 0; c < 3; c++)
        rgb[c] = (float)(acc[c] * env->strength);
}

void wenv_envmap_lookup(const wenv_envmap *env, const double dir[3], float rgb[3]) { lookup(env, dir, 0, rgb); }

void wenv_envmap_lookup_nearest(const wenv_envmap *env, const double dir[3], float rgb[3])
{
    lookup(env, dir, 1, rgb);
}

void wenv_envmap_lookup_many(const wenv_envmap *env, const float *dirs, size_t n, float *rgb)
{
#pragma omp parallel for schedule(static) if (n > 8192)
    for (size_t i = 0; i < n; i++) {
        double d[3] = {dirs[3 * i], dirs[3 * i + 1], dirs[3 * i + 2]};
        wenv_envmap_lookup(env, d, rgb + 3 * i);
    }
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
        status = wenv_read_exr(fd, size, path, &rgb, &h, &w, err);
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
        status = wenv_read_rgbe(buf, done, path, &rgb, &h, &w, err);
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
    return envmap_adopt(out, rgb, h, w, projection, rotation, strength, what, PIXELS_FROM_FILE, err);
}
