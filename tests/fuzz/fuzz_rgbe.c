/* Fuzz target: Radiance RGBE (.hdr) files, read in memory by wenv_read_rgbe as wenv_envmap_load
 * hands it the whole file.  Built and run by tests/fuzz/run.py. */
#include "fuzz_input.h"

#include <float.h>

#include "scene/image_readers.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    static const char path[] = "fuzz-input.hdr";
    float *rgb = NULL;
    size_t h = 0, w = 0;
    wenv_error err = {0};
    wenv_status st = wenv_read_rgbe(data, size, path, &rgb, &h, &w, &err);
    if (st == WENV_OK) {
        /* decoded RGBE is a byte mantissa times a power of two: finite and non-negative */
        if (h == 0 || w == 0 || h > WENV_IMAGE_MAX_SIDE || w > WENV_IMAGE_MAX_SIDE)
            abort();
        for (size_t i = 0; i < h * w * 3; i++)
            if (!(rgb[i] >= 0.0f && rgb[i] <= FLT_MAX))
                abort();
        free(rgb);
    } else {
        fuzz_check_refusal(st, &err, path);
    }
    return 0;
}
