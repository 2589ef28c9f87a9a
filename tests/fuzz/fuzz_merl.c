/* Fuzz target: MERL .binary BRDF files (wenv_read_merl, as wenv.load_brdf calls it).  Built and run
 * by tests/fuzz/run.py. */
#include "fuzz_input.h"

#include <float.h>

#include "scene/brdf_readers.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    char path[64];
    int fd = fuzz_input_file(data, size, path, sizeof path);
    float *rgb = NULL;
    size_t dims[3];
    wenv_error err = {0};
    wenv_status st = wenv_read_merl(path, &rgb, dims, &err);
    if (st == WENV_OK) {
        /* the reader's promise (brdf_readers.h): a table wenv_tabulated_create accepts (which
         * refuses a bad one as a value error that would not name the file), whatever the file */
        size_t n = 3;
        for (int d = 0; d < 3; d++) {
            if (dims[d] < 2 || dims[d] > 4096)
                abort();
            n *= dims[d];
        }
        for (size_t i = 0; i < n; i++)
            if (!(rgb[i] >= 0.0f && rgb[i] <= FLT_MAX)) {
                fprintf(stderr, "table value %zu is %g\n", i, (double)rgb[i]);
                abort();
            }
        free(rgb);
    } else {
        fuzz_check_refusal(st, &err, path);
    }
    close(fd);
    return 0;
}
