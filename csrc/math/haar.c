#include "math/haar.h"

#include <math.h>
#include <string.h>

#define INV_SQRT2 0.70710678118654752440f

int wenv_is_power_of_two(size_t n) { return n > 0 && (n & (n - 1)) == 0; }

/* One Haar step over `len` elements of `width` floats, element k at base + k * stride: averages to
 * elements 0 .. len/2 - 1, details after them.  Averages go in place (element k was read by pair
 * k/2 <= k, already done; pair 0 reads before it writes); details wait in scratch, as elements from
 * len/2 on are still to be read.  A row step has elements of one pixel, a column step of a whole
 * row: the latter's inner loop runs over contiguous floats. */
static inline __attribute__((always_inline)) void forward_step(float *base, size_t len, size_t stride, size_t width,
                                                               float *scratch)
{
    size_t half = len / 2;
    for (size_t k = 0; k < half; k++) {
        const float *a = base + 2 * k * stride, *b = a + stride;
        float *lo = base + k * stride, *hi = scratch + k * width;
        for (size_t c = 0; c < width; c++) {
            float x = a[c], y = b[c];
            lo[c] = (x + y) * INV_SQRT2;
            hi[c] = (x - y) * INV_SQRT2;
        }
    }
    for (size_t k = 0; k < half; k++)
        memcpy(base + (half + k) * stride, scratch + k * width, width * sizeof(float));
}

/* The step undone: details to scratch first, then pairs from the last down (pair k writes elements
 * 2k and 2k + 1, whose averages were read already; pair 0 reads before it writes). */
static inline __attribute__((always_inline)) void inverse_step(float *base, size_t len, size_t stride, size_t width,
                                                               float *scratch)
{
    size_t half = len / 2;
    for (size_t k = 0; k < half; k++)
        memcpy(scratch + k * width, base + (half + k) * stride, width * sizeof(float));
    for (size_t k = half; k-- > 0;) {
        const float *lo = base + k * stride, *hi = scratch + k * width;
        float *a = base + 2 * k * stride, *b = a + stride;
        for (size_t c = 0; c < width; c++) {
            float x = lo[c], y = hi[c];
            a[c] = (x + y) * INV_SQRT2;
            b[c] = (x - y) * INV_SQRT2;
        }
    }
}

/* Rows of pixels: the channel counts wenv uses get loops of constant width. */
static void forward_row(float *row, size_t len, size_t ch, float *scratch)
{
    if (ch == 3)
        forward_step(row, len, 3, 3, scratch);
    else if (ch == 1)
        forward_step(row, len, 1, 1, scratch);
    else
        forward_step(row, len, ch, ch, scratch);
}

static void inverse_row(float *row, size_t len, size_t ch, float *scratch)
{
    if (ch == 3)
        inverse_step(row, len, 3, 3, scratch);
    else if (ch == 1)
        inverse_step(row, len, 1, 1, scratch);
    else
        inverse_step(row, len, ch, ch, scratch);
}

size_t wenv_haar2d_scratch_floats(size_t n, size_t channels) { return (n / 2 > 0 ? n / 2 : 1) * n * channels; }

void wenv_haar2d_forward(float *data, size_t n, size_t channels, float *scratch)
{
    size_t row_step = n * channels;
    for (size_t s = n; s > 1; s /= 2) {
        for (size_t r = 0; r < s; r++)
            forward_row(data + r * row_step, s, channels, scratch);
        forward_step(data, s, row_step, s * channels, scratch);
    }
}

void wenv_haar2d_inverse(float *data, size_t n, size_t channels, float *scratch)
{
    size_t row_step = n * channels;
    for (size_t s = 2; s <= n; s *= 2) {
        inverse_step(data, s, row_step, s * channels, scratch);
        for (size_t r = 0; r < s; r++)
            inverse_row(data + r * row_step, s, channels, scratch);
    }
}

size_t wenv_haar2d_impulse(size_t n, size_t col, size_t row, size_t *idx, float *val)
{
    /* Follow the impulse up the levels: at each level it is one pixel of the current average
     * block, and the row step then the column step each split it into an average and a detail. */
    size_t count = 0;
    float amp = 1.0f;
    for (size_t s = n; s > 1; s /= 2) {
        size_t half = s / 2;
        size_t c2 = col / 2, r2 = row / 2;
        float sc = (col & 1) ? -INV_SQRT2 : INV_SQRT2; /* row step: detail sign */
        float sr = (row & 1) ? -INV_SQRT2 : INV_SQRT2; /* column step: detail sign */
        /* after the row step: avg at (c2, row) with amp/sqrt2, detail at (half + c2, row) */
        float a_row = amp * INV_SQRT2, d_row = amp * sc;
        /* column step on both columns */
        idx[count] = (half + r2) * n + (half + c2); /* detail-detail */
        val[count++] = d_row * sr;
        idx[count] = r2 * n + (half + c2); /* detail (row) averaged over rows */
        val[count++] = d_row * INV_SQRT2;
        idx[count] = (half + r2) * n + c2; /* average (row) detail (column) */
        val[count++] = a_row * sr;
        amp = a_row * INV_SQRT2;
        col = c2;
        row = r2;
    }
    idx[count] = 0;
    val[count++] = amp;
    return count;
}
