#include "math/haar.h"

#include <math.h>
#include <string.h>

#define INV_SQRT2 0.70710678118654752440f

int wenv_is_power_of_two(size_t n) { return n > 0 && (n & (n - 1)) == 0; }

/* One Haar step along a line of `len` pixels whose k-th pixel starts at base + k * step. */
static void forward_line(float *base, size_t len, size_t step, size_t ch, float *scratch)
{
    size_t half = len / 2;
    for (size_t k = 0; k < half; k++) {
        const float *a = base + (2 * k) * step, *b = base + (2 * k + 1) * step;
        float *lo = scratch + k * ch, *hi = scratch + (half + k) * ch;
        for (size_t c = 0; c < ch; c++) {
            lo[c] = (a[c] + b[c]) * INV_SQRT2;
            hi[c] = (a[c] - b[c]) * INV_SQRT2;
        }
    }
    for (size_t k = 0; k < len; k++)
        memcpy(base + k * step, scratch + k * ch, ch * sizeof(float));
}

static void inverse_line(float *base, size_t len, size_t step, size_t ch, float *scratch)
{
    size_t half = len / 2;
    for (size_t k = 0; k < half; k++) {
        const float *lo = base + k * step, *hi = base + (half + k) * step;
        float *a = scratch + (2 * k) * ch, *b = scratch + (2 * k + 1) * ch;
        for (size_t c = 0; c < ch; c++) {
            a[c] = (lo[c] + hi[c]) * INV_SQRT2;
            b[c] = (lo[c] - hi[c]) * INV_SQRT2;
        }
    }
    for (size_t k = 0; k < len; k++)
        memcpy(base + k * step, scratch + k * ch, ch * sizeof(float));
}

void wenv_haar2d_forward(float *data, size_t n, size_t channels, float *scratch)
{
    size_t row_step = n * channels;
    for (size_t s = n; s > 1; s /= 2) {
        for (size_t r = 0; r < s; r++)
            forward_line(data + r * row_step, s, channels, channels, scratch);
        for (size_t c = 0; c < s; c++)
            forward_line(data + c * channels, s, row_step, channels, scratch);
    }
}

void wenv_haar2d_inverse(float *data, size_t n, size_t channels, float *scratch)
{
    size_t row_step = n * channels;
    for (size_t s = 2; s <= n; s *= 2) {
        for (size_t c = 0; c < s; c++)
            inverse_line(data + c * channels, s, row_step, channels, scratch);
        for (size_t r = 0; r < s; r++)
            inverse_line(data + r * row_step, s, channels, channels, scratch);
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
