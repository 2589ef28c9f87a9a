/* The "Extend" margin (margin.h): one ring at a time, each ring reading only the texels filled
 * before it and marking its own apart, so rows can be done by any thread in any order. */
#include "bake/margin.h"

#include <stdlib.h>

wenv_status wenv_extend_margin(float *pixels, uint8_t *filled, size_t width, size_t height, size_t channels,
                               size_t margin, size_t *added, wenv_error *err)
{
    if (channels == 0 || channels > 4)
        return wenv_error_set(err, WENV_ERR_VALUE, "pixels must have 1 to 4 channels, got %zu", channels);
    uint8_t *ring_marks = calloc(width * height > 0 ? width * height : 1, 1);
    if (!ring_marks)
        return wenv_error_set(err, WENV_ERR_NOMEM, "no memory for a %zu x %zu margin", width, height);
    size_t count = 0;
    for (size_t ring = 0; ring < margin; ring++) {
        size_t ring_count = 0;
#pragma omp parallel for schedule(static) reduction(+ : ring_count)
        for (size_t y = 0; y < height; y++) {
            for (size_t x = 0; x < width; x++) {
                size_t at = y * width + x;
                if (filled[at])
                    continue;
                float sum[4] = {0.0f, 0.0f, 0.0f, 0.0f};
                int n = 0;
                for (size_t yy = y ? y - 1 : 0; yy <= y + 1 && yy < height; yy++)
                    for (size_t xx = x ? x - 1 : 0; xx <= x + 1 && xx < width; xx++) {
                        size_t from = yy * width + xx;
                        if (!filled[from])
                            continue;
                        for (size_t c = 0; c < channels; c++)
                            sum[c] += pixels[from * channels + c];
                        n++;
                    }
                if (!n)
                    continue;
                for (size_t c = 0; c < channels; c++)
                    pixels[at * channels + c] = sum[c] / (float)n;
                ring_marks[at] = 1;
                ring_count++;
            }
        }
        if (!ring_count)
            break;
        for (size_t i = 0; i < width * height; i++)
            if (ring_marks[i]) {
                filled[i] = 1;
                ring_marks[i] = 0;
            }
        count += ring_count;
    }
    free(ring_marks);
    *added = count;
    return WENV_OK;
}
