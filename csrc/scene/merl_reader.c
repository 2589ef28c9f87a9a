#define _POSIX_C_SOURCE 200809L /* fileno, fstat */

#include "scene/brdf_readers.h"

#include <errno.h>
#include <float.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

/* Far beyond any measured table (MERL's is 90 x 90 x 180): keeps sizes far from overflow. */
#define MAX_DIM 4096
#define MAX_SAMPLES ((size_t)1 << 28)

static const double SCALE[3] = {1.0 / 1500.0, 1.15 / 1500.0, 1.66 / 1500.0};

static wenv_status io_error(wenv_error *err, const char *path, const char *why)
{
    return wenv_error_set(err, WENV_ERR_IO, "cannot read MERL BRDF file '%s': %s", path, why);
}

/* Fills the unmeasured (negative) entries of one channel, stride 3 (see brdf_readers.h).  Returns 0
 * when nothing at all was measured.  column_measured: dims[0] x dims[2] flags; nearest: dims[0]
 * indices of scratch. */
static int fill_unmeasured(float *rgb, const size_t dims[3], int *column_measured, size_t *nearest)
{
    size_t nh = dims[0], nd = dims[1], np = dims[2];
    int any = 0;
    for (size_t i = 0; i < nh; i++)
        for (size_t k = 0; k < np; k++) {
            float *col = rgb + 3 * (k + np * nd * i);
            size_t stride = 3 * np, first = nd;
            for (size_t j = 0; j < nd; j++)
                if (col[j * stride] >= 0.0f) {
                    first = j;
                    break;
                }
            column_measured[i * np + k] = first < nd;
            if (first == nd)
                continue;
            any = 1;
            for (size_t j = 0; j < first; j++) /* leading: the first measured */
                col[j * stride] = col[first * stride];
            for (size_t j = first + 1; j < nd; j++) /* forward: the last measured */
                if (col[j * stride] < 0.0f)
                    col[j * stride] = col[(j - 1) * stride];
        }
    if (!any)
        return 0;
    /* columns with nothing measured: the nearest theta_h at the same phi_d that has one (the smaller
     * on a tie), found in one pass up and one down per phi_d (a search outwards from each column
     * took 76 s on a 4096 x 2 x 512 table measured at one theta_h) */
    for (size_t k = 0; k < np; k++) {
        size_t below = SIZE_MAX;
        for (size_t i = 0; i < nh; i++) {
            if (column_measured[i * np + k])
                below = i;
            nearest[i] = below;
        }
        size_t above = SIZE_MAX;
        for (size_t i = nh; i-- > 0;) {
            if (column_measured[i * np + k]) {
                above = i;
                continue;
            }
            size_t src = nearest[i];
            if (above != SIZE_MAX && (src == SIZE_MAX || above - i < i - src))
                src = above;
            float *col = rgb + 3 * (k + np * nd * i);
            const float *from = src == SIZE_MAX ? NULL : rgb + 3 * (k + np * nd * src);
            for (size_t j = 0; j < nd; j++) /* no column at this phi_d measured: black, not negative */
                col[j * 3 * np] = from ? from[j * 3 * np] : 0.0f;
        }
    }
    return 1;
}

wenv_status wenv_read_merl(const char *path, float **rgb_out, size_t dims[3], wenv_error *err)
{
    *rgb_out = NULL;
    FILE *fp = fopen(path, "rb");
    if (!fp) {
        char why[128];
        snprintf(why, sizeof why, "%s", strerror(errno));
        return io_error(err, path, why);
    }
    struct stat st;
    int32_t header[3];
    wenv_status status = WENV_OK;
    double *block = NULL;
    float *rgb = NULL;
    int *measured = NULL;
    size_t *nearest = NULL;
    if (fstat(fileno(fp), &st) != 0 || !S_ISREG(st.st_mode)) {
        status = io_error(err, path, "not a regular file");
        goto done;
    }
    if (fread(header, sizeof header[0], 3, fp) != 3) {
        status = io_error(err, path, "too short for the three int32 dimensions of a MERL table");
        goto done;
    }
    for (int d = 0; d < 3; d++) {
        if (header[d] < 2 || header[d] > MAX_DIM) {
            status = wenv_error_set(err, WENV_ERR_IO,
                                    "cannot read MERL BRDF file '%s': dimensions %d x %d x %d are not a MERL table's",
                                    path, (int)header[0], (int)header[1], (int)header[2]);
            goto done;
        }
        dims[d] = (size_t)header[d];
    }
    size_t n = dims[0] * dims[1] * dims[2];
    uint64_t want = 12 + (uint64_t)n * 3 * sizeof(double);
    if (n > MAX_SAMPLES || (uint64_t)st.st_size != want) {
        status = wenv_error_set(err, WENV_ERR_IO,
                                "cannot read MERL BRDF file '%s': %zu x %zu x %zu samples need %llu bytes, the file "
                                "has %lld (truncated, or not a MERL table)",
                                path, dims[0], dims[1], dims[2], (unsigned long long)want, (long long)st.st_size);
        goto done;
    }
    block = malloc(n * sizeof *block);
    rgb = malloc(n * 3 * sizeof *rgb);
    measured = malloc(dims[0] * dims[2] * sizeof *measured);
    nearest = malloc(dims[0] * sizeof *nearest);
    if (!block || !rgb || !measured || !nearest) {
        status = wenv_error_set(err, WENV_ERR_NOMEM, "out of memory reading '%s'", path);
        goto done;
    }
    for (int c = 0; c < 3 && !status; c++) {
        if (fread(block, sizeof *block, n, fp) != n) {
            status = io_error(err, path, "truncated");
            break;
        }
        for (size_t s = 0; s < n; s++) {
            double v = block[s] * SCALE[c];
            if (!isfinite(block[s])) {
                status = wenv_error_set(err, WENV_ERR_IO, "cannot read MERL BRDF file '%s': sample %zu of channel %d "
                                        "is not finite", path, s, c);
                break;
            }
            /* a finite double past a float's range would become an infinite table value */
            if (v > FLT_MAX) {
                status = wenv_error_set(err, WENV_ERR_IO, "cannot read MERL BRDF file '%s': sample %zu of channel %d "
                                        "is %g, too large for a float", path, s, c, v);
                break;
            }
            /* negative: not measured, kept negative until filled below */
            rgb[3 * s + (size_t)c] = block[s] < 0.0 ? -1.0f : (float)v;
        }
    }
    for (int c = 0; c < 3 && !status; c++)
        if (!fill_unmeasured(rgb + c, dims, measured, nearest))
            status = io_error(err, path, "no sample was measured");
done:
    fclose(fp);
    free(block);
    free(measured);
    free(nearest);
    if (status) {
        free(rgb);
        return status;
    }
    *rgb_out = rgb;
    return WENV_OK;
}
