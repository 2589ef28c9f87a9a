/* Texel centres in UV triangles (texel_raster.h): each band of rows tests the triangles whose
 * bounding boxes reach it (listed per band, in the triangles' order), so threads never write the
 * same texel and the result does not depend on their number. */
#include "bake/texel_raster.h"

#include <math.h>
#include <stdatomic.h>
#include <stdlib.h>

/* Rows per band: enough to keep a thread busy, few enough that bands balance on 2 to 64 threads. */
#define BAND_ROWS 8

typedef struct {
    double x[3], y[3]; /* corners in texel units, wound counter-clockwise */
    double area2;      /* twice the signed area of the triangle as given (either sign) */
    double ax, ay, bx, by, cx, cy; /* corners in the given order, for the weights */
    int y0, y1;        /* rows whose centres the box may hold */
    int x0, x1;
} uv_triangle;

/* A point on the edge (x0, y0) -> (x1, y1) of a counter-clockwise triangle belongs to it when the
 * edge is a top edge (horizontal, the triangle below it: y grows upwards here) or a left edge. */
static int top_left(double x0, double y0, double x1, double y1)
{
    return (y0 == y1 && x1 < x0) || y1 < y0;
}

static double edge(double x0, double y0, double x1, double y1, double px, double py)
{
    return (x1 - x0) * (py - y0) - (y1 - y0) * (px - x0);
}

static int inside(const uv_triangle *t, double px, double py)
{
    for (int k = 0; k < 3; k++) {
        int j = (k + 1) % 3;
        double e = edge(t->x[k], t->y[k], t->x[j], t->y[j], px, py);
        if (e < 0.0 || (e == 0.0 && !top_left(t->x[k], t->y[k], t->x[j], t->y[j])))
            return 0;
    }
    return 1;
}

static int clamp_int(double v, int lo, int hi)
{
    return v < lo ? lo : v > hi ? hi : (int)v;
}

/* The triangle in texel units; 0 when it covers no texel centre (no area, or off the image). */
static int prepare(const float *uv, const uint32_t *tri, size_t width, size_t height, uv_triangle *t)
{
    double px[3], py[3];
    for (int k = 0; k < 3; k++) {
        px[k] = (double)uv[2 * (size_t)tri[k]] * (double)width;
        py[k] = (double)uv[2 * (size_t)tri[k] + 1] * (double)height;
    }
    t->area2 = (px[1] - px[0]) * (py[2] - py[0]) - (px[2] - px[0]) * (py[1] - py[0]);
    if (!(fabs(t->area2) > 0.0))
        return 0;
    int order[3] = {0, t->area2 > 0.0 ? 1 : 2, t->area2 > 0.0 ? 2 : 1};
    for (int k = 0; k < 3; k++) {
        t->x[k] = px[order[k]];
        t->y[k] = py[order[k]];
    }
    t->ax = px[0], t->ay = py[0], t->bx = px[1], t->by = py[1], t->cx = px[2], t->cy = py[2];
    double lo_x = fmin(px[0], fmin(px[1], px[2])), hi_x = fmax(px[0], fmax(px[1], px[2]));
    double lo_y = fmin(py[0], fmin(py[1], py[2])), hi_y = fmax(py[0], fmax(py[1], py[2]));
    /* centres at i + 0.5: the first at or above lo - 0.5, the last at or below hi - 0.5 */
    t->x0 = clamp_int(ceil(lo_x - 0.5), 0, (int)width);
    t->x1 = clamp_int(floor(hi_x - 0.5), -1, (int)width - 1);
    t->y0 = clamp_int(ceil(lo_y - 0.5), 0, (int)height);
    t->y1 = clamp_int(floor(hi_y - 0.5), -1, (int)height - 1);
    return t->x0 <= t->x1 && t->y0 <= t->y1;
}

/* The texels outside every triangle that touch one inside (8-neighbours, the first in NEIGHBOURS'
 * order): each takes that neighbour's triangle, marked -2 - t, with its centre's weights in it
 * (outside it, so one is negative).  Read from a copy of which texels are inside, so that no thread
 * reads what another writes. */
static const int NEIGHBOURS[8][2] = {{-1, 0}, {1, 0}, {0, -1}, {0, 1}, {-1, -1}, {1, -1}, {-1, 1}, {1, 1}};

static wenv_status border_ring(const float *uv, const uint32_t *triangles, size_t width, size_t height,
                               int32_t *triangle_out, float *weights_out, wenv_error *err)
{
    uint8_t *inside = malloc(width * height);
    if (!inside)
        return wenv_error_set(err, WENV_ERR_NOMEM, "no memory for the border of a %zu x %zu image", width, height);
    for (size_t i = 0; i < width * height; i++)
        inside[i] = triangle_out[i] >= 0;
#pragma omp parallel for schedule(static)
    for (size_t y = 0; y < height; y++)
        for (size_t x = 0; x < width; x++) {
            size_t at = y * width + x;
            if (inside[at])
                continue;
            for (int k = 0; k < 8; k++) {
                long nx = (long)x + NEIGHBOURS[k][0], ny = (long)y + NEIGHBOURS[k][1];
                if (nx < 0 || ny < 0 || nx >= (long)width || ny >= (long)height || !inside[(size_t)ny * width + (size_t)nx])
                    continue;
                int32_t t = triangle_out[(size_t)ny * width + (size_t)nx];
                const uint32_t *c = triangles + 3 * (size_t)t;
                double ax = uv[2 * c[0]] * (double)width, ay = uv[2 * c[0] + 1] * (double)height;
                double bx = uv[2 * c[1]] * (double)width, by = uv[2 * c[1] + 1] * (double)height;
                double cx = uv[2 * c[2]] * (double)width, cy = uv[2 * c[2] + 1] * (double)height;
                double px = (double)x + 0.5, py = (double)y + 0.5;
                double area2 = (bx - ax) * (cy - ay) - (cx - ax) * (by - ay);
                triangle_out[at] = -2 - t;
                weights_out[2 * at] = (float)(((px - ax) * (cy - ay) - (cx - ax) * (py - ay)) / area2);
                weights_out[2 * at + 1] = (float)(((bx - ax) * (py - ay) - (px - ax) * (by - ay)) / area2);
                break;
            }
        }
    free(inside);
    return WENV_OK;
}

wenv_status wenv_texel_raster(const float *uv, size_t n_uv, const uint32_t *triangles, size_t n_triangles,
                              size_t width, size_t height, int border, int32_t *triangle_out, float *weights_out,
                              size_t *covered, size_t *overlapped, const wenv_progress *progress, wenv_error *err)
{
    if (width == 0 || height == 0 || width > INT32_MAX / 2 || height > INT32_MAX / 2)
        return wenv_error_set(err, WENV_ERR_VALUE, "the image must be between 1 and 2^30 texels a side, got %zu x %zu",
                              width, height);
    if (n_triangles > INT32_MAX)
        return wenv_error_set(err, WENV_ERR_VALUE, "at most 2^31 - 1 triangles, got %zu", n_triangles);
    for (size_t i = 0; i < n_uv; i++)
        if (!isfinite(uv[2 * i]) || !isfinite(uv[2 * i + 1]))
            return wenv_error_set(err, WENV_ERR_VALUE, "uv has a coordinate that is not finite at row %zu", i);
    for (size_t i = 0; i < 3 * n_triangles; i++)
        if (triangles[i] >= n_uv)
            return wenv_error_set(err, WENV_ERR_VALUE, "triangles index uv row %u of %zu (triangle %zu)",
                                  (unsigned)triangles[i], n_uv, i / 3);
    for (size_t i = 0; i < width * height; i++) {
        triangle_out[i] = -1;
        weights_out[2 * i] = weights_out[2 * i + 1] = 0.0f;
    }
    uv_triangle *tris = malloc((n_triangles ? n_triangles : 1) * sizeof *tris);
    size_t *kept = malloc((n_triangles ? n_triangles : 1) * sizeof *kept);
    if (!tris || !kept) {
        free(tris);
        free(kept);
        return wenv_error_set(err, WENV_ERR_NOMEM, "no memory for %zu UV triangles", n_triangles);
    }
    size_t n_kept = 0;
    for (size_t i = 0; i < n_triangles; i++)
        if (prepare(uv, triangles + 3 * i, width, height, &tris[n_kept]))
            kept[n_kept++] = i;

    size_t bands = (height + BAND_ROWS - 1) / BAND_ROWS;
    /* each band's triangles: a counting sort of every (band, triangle) pair a box spans */
    size_t *first = calloc(bands + 1, sizeof *first), *listed = NULL, pairs = 0;
    if (first) {
        for (size_t k = 0; k < n_kept; k++)
            for (size_t b = (size_t)tris[k].y0 / BAND_ROWS; b <= (size_t)tris[k].y1 / BAND_ROWS; b++)
                first[b + 1]++;
        for (size_t b = 0; b < bands; b++)
            first[b + 1] += first[b];
        pairs = first[bands];
        listed = malloc((pairs ? pairs : 1) * sizeof *listed);
    }
    if (!first || !listed) {
        free(tris);
        free(kept);
        free(first);
        return wenv_error_set(err, WENV_ERR_NOMEM, "no memory for the bands of %zu UV triangles", n_triangles);
    }
    for (size_t k = 0; k < n_kept; k++)
        for (size_t b = (size_t)tris[k].y0 / BAND_ROWS; b <= (size_t)tris[k].y1 / BAND_ROWS; b++)
            listed[first[b]++] = k;
    for (size_t b = bands; b > 0; b--) /* the fill moved each start to the next band's */
        first[b] = first[b - 1];
    first[0] = 0;

    size_t total_covered = 0, total_overlapped = 0;
    atomic_size_t done = 0;
    atomic_int cancelled = 0;
#pragma omp parallel for schedule(dynamic, 1) reduction(+ : total_covered, total_overlapped)
    for (size_t band = 0; band < bands; band++) {
        if (atomic_load(&cancelled))
            continue;
        int row0 = (int)(band * BAND_ROWS), row1 = (int)fmin((double)(row0 + BAND_ROWS), (double)height) - 1;
        for (size_t at_list = first[band]; at_list < first[band + 1]; at_list++) {
            size_t k = listed[at_list];
            const uv_triangle *t = &tris[k];
            int ya = t->y0 > row0 ? t->y0 : row0, yb = t->y1 < row1 ? t->y1 : row1;
            for (int y = ya; y <= yb; y++) {
                double py = y + 0.5;
                for (int x = t->x0; x <= t->x1; x++) {
                    double px = x + 0.5;
                    if (!inside(t, px, py))
                        continue;
                    size_t at = (size_t)y * width + (size_t)x;
                    if (triangle_out[at] >= 0) {
                        total_overlapped++;
                        continue;
                    }
                    triangle_out[at] = (int32_t)kept[k];
                    total_covered++;
                    double wb = ((px - t->ax) * (t->cy - t->ay) - (t->cx - t->ax) * (py - t->ay)) / t->area2;
                    double wc = ((t->bx - t->ax) * (py - t->ay) - (px - t->ax) * (t->by - t->ay)) / t->area2;
                    weights_out[2 * at] = (float)wb;
                    weights_out[2 * at + 1] = (float)wc;
                }
            }
        }
        wenv_progress_item(progress, &done, bands, &cancelled);
    }
    free(tris);
    free(kept);
    free(first);
    free(listed);
    if (atomic_load(&cancelled) || wenv_progress_finish(progress))
        return wenv_error_set(err, WENV_ERR_CANCELLED, "cancelled");
    *covered = total_covered;
    *overlapped = total_overlapped;
    return border ? border_ring(uv, triangles, width, height, triangle_out, weights_out, err) : WENV_OK;
}
