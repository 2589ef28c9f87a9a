/* Fuzz target: OpenEXR environment files, through wenv_envmap_load as wenv.load_environment calls
 * it (magic bytes, OpenEXRCore, the C++ library's fallback for DWAA/DWAB, the pixel checks).
 * Built and run by tests/fuzz/run.py. */
#include "fuzz_input.h"

#include <float.h>

#include "scene/envmap.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    char path[64];
    int fd = fuzz_input_file(data, size, path, sizeof path);
    wenv_envmap *env = NULL;
    wenv_error err = {0};
    wenv_status st = wenv_envmap_load(&env, path, WENV_PROJ_EQUIRECT, 0.0, 1.0, &err);
    if (st == WENV_OK) {
        /* what every method reads first: the pixels must all be finite and non-negative */
        const float *px = wenv_envmap_pixels(env);
        size_t n = wenv_envmap_height(env) * wenv_envmap_width(env) * 3;
        for (size_t i = 0; i < n; i++)
            if (!(px[i] >= 0.0f && px[i] <= FLT_MAX))
                abort();
        wenv_envmap_free(env);
    } else {
        fuzz_check_refusal(st, &err, path);
    }
    close(fd);
    return 0;
}
