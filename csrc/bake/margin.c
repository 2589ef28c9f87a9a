/* The "Extend" margin (margin.h): one ring at a time, each ring reading only the texels filled
 * before it and marking its own filled after, so its texels can be done by any thread in any order.
 * Only the rings' texels are visited: the first ring is found by one pass over the image, each next
 * one among the unfilled neighbours of the last (a texel that touched a filled one before would
 * have been in an earlier ring), so a margin costs its rings, not a pass over the image a ring. */
#include "bake/margin.h"

#include <stdlib.h>

typedef struct {
    size_t *at;
    size_t count, capacity;
} texel_list;

static int list_push(texel_list *list, size_t texel)
{
    if (list->count == list->capacity) {
        size_t capacity = list->capacity ? 2 * list->capacity : 1024;
        size_t *grown = realloc(list->at, capacity * sizeof *grown);
        if (!grown)
            return -1;
        list->at = grown;
        list->capacity = capacity;
    }
    list->at[list->count++] = texel;
    return 0;
}

/* Texel `at`'s 3 x 3 neighbourhood, itself included, clipped to the image: rows y0..y1, columns
 * x0..x1. */
typedef struct {
    size_t x0, x1, y0, y1;
} neighbourhood;

static neighbourhood around(size_t at, size_t width, size_t height)
{
    size_t x = at % width, y = at / width;
    return (neighbourhood){.x0 = x ? x - 1 : 0, .x1 = x + 1 < width ? x + 1 : x,
                           .y0 = y ? y - 1 : 0, .y1 = y + 1 < height ? y + 1 : y};
}

static int touches_filled(const uint8_t *filled, size_t width, size_t height, size_t at)
{
    neighbourhood a = around(at, width, height);
    for (size_t yy = a.y0; yy <= a.y1; yy++)
        for (size_t xx = a.x0; xx <= a.x1; xx++)
            if (filled[yy * width + xx])
                return 1;
    return 0;
}

/* The mean of the filled 8-neighbours of texel `at` into its pixel (it has at least one). */
static void take_mean(float *pixels, const uint8_t *filled, size_t width, size_t height, size_t channels, size_t at)
{
    neighbourhood a = around(at, width, height);
    float sum[4] = {0.0f, 0.0f, 0.0f, 0.0f};
    int n = 0;
    for (size_t yy = a.y0; yy <= a.y1; yy++)
        for (size_t xx = a.x0; xx <= a.x1; xx++) {
            size_t from = yy * width + xx;
            if (!filled[from])
                continue;
            for (size_t c = 0; c < channels; c++)
                sum[c] += pixels[from * channels + c];
            n++;
        }
    for (size_t c = 0; c < channels; c++)
        pixels[at * channels + c] = sum[c] / (float)n;
}

wenv_status wenv_extend_margin(float *pixels, uint8_t *filled, size_t width, size_t height, size_t channels,
                               size_t margin, size_t *added, wenv_error *err)
{
    if (channels == 0 || channels > 4)
        return wenv_error_set(err, WENV_ERR_VALUE, "pixels must have 1 to 4 channels, got %zu", channels);
    *added = 0;
    if (margin == 0 || width == 0 || height == 0)
        return WENV_OK;
    uint8_t *queued = malloc(width * height); /* in this ring or the next */
    texel_list ring = {0}, next = {0};
    int failed = !queued;
    if (!failed) {
        long long rows = (long long)height;
#pragma omp parallel for schedule(static)
        for (long long y = 0; y < rows; y++)
            for (size_t at = (size_t)y * width; at < ((size_t)y + 1) * width; at++)
                queued[at] = !filled[at] && touches_filled(filled, width, height, at);
    }
    for (size_t at = 0; at < width * height && !failed; at++)
        if (queued[at])
            failed = list_push(&ring, at) < 0;
    size_t count = 0;
    for (size_t r = 0; r < margin && ring.count && !failed; r++) {
        long long n = (long long)ring.count;
#pragma omp parallel for schedule(static)
        for (long long k = 0; k < n; k++)
            take_mean(pixels, filled, width, height, channels, ring.at[k]);
        for (size_t k = 0; k < ring.count; k++)
            filled[ring.at[k]] = 1;
        count += ring.count;
        next.count = 0;
        for (size_t k = 0; k < ring.count && r + 1 < margin && !failed; k++) {
            neighbourhood a = around(ring.at[k], width, height);
            for (size_t yy = a.y0; yy <= a.y1 && !failed; yy++)
                for (size_t xx = a.x0; xx <= a.x1 && !failed; xx++) {
                    size_t at = yy * width + xx;
                    if (filled[at] || queued[at])
                        continue;
                    queued[at] = 1;
                    failed = list_push(&next, at) < 0;
                }
        }
        texel_list swap = ring;
        ring = next;
        next = swap;
    }
    free(queued);
    free(ring.at);
    free(next.at);
    if (failed)
        return wenv_error_set(err, WENV_ERR_NOMEM, "no memory for a %zu x %zu margin", width, height);
    *added = count;
    return WENV_OK;
}
