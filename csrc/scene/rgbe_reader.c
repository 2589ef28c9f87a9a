/* Radiance RGBE (.hdr) files, read by hand: the format is small and has no well-kept C library.
 * Header lines up to a blank line, a resolution line, then scanlines that are flat, old-style
 * run-length (1,1,1,n repeats) or new-style RLE (2,2,hi,lo then four RLE channels). */
#include "scene/image_readers.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static wenv_status hdr_corrupt(wenv_error *err, const char *path, const char *what, size_t row)
{
    return wenv_error_set(err, WENV_ERR_IO, "cannot read Radiance HDR file '%s': %s in scanline %zu", path, what,
                          row);
}

static wenv_status hdr_scanline(const uint8_t **pp, const uint8_t *end, uint8_t *scan, size_t w, const char *path,
                                size_t row, wenv_error *err)
{
    const uint8_t *p = *pp;
    if (w >= 8 && w < 32768 && end - p >= 4 && p[0] == 2 && p[1] == 2 && !(p[2] & 0x80)) {
        if (((size_t)p[2] << 8 | p[3]) != w)
            return hdr_corrupt(err, path, "run-length scanline of the wrong width", row);
        p += 4;
        for (size_t ch = 0; ch < 4; ch++) {
            size_t x = 0;
            while (x < w) {
                if (p >= end)
                    return hdr_corrupt(err, path, "file is truncated", row);
                size_t count = *p++;
                if (count > 128) {
                    count -= 128;
                    if (count > w - x)
                        return hdr_corrupt(err, path, "run past the end of the line", row);
                    if (p >= end)
                        return hdr_corrupt(err, path, "file is truncated", row);
                    for (size_t i = 0; i < count; i++)
                        scan[4 * (x + i) + ch] = *p;
                    p++;
                } else {
                    if (count == 0 || count > w - x)
                        return hdr_corrupt(err, path, "bad literal run length", row);
                    if ((size_t)(end - p) < count)
                        return hdr_corrupt(err, path, "file is truncated", row);
                    for (size_t i = 0; i < count; i++)
                        scan[4 * (x + i) + ch] = p[i];
                    p += count;
                }
                x += count;
            }
        }
    } else {
        size_t x = 0;
        unsigned shift = 0;
        while (x < w) {
            if (end - p < 4)
                return hdr_corrupt(err, path, "file is truncated", row);
            if (p[0] == 1 && p[1] == 1 && p[2] == 1) { /* old-style run: repeat the previous pixel */
                if (x == 0 || shift > 24)
                    return hdr_corrupt(err, path, "bad old-style run", row);
                size_t count = (size_t)p[3] << shift;
                if (count > w - x)
                    return hdr_corrupt(err, path, "run past the end of the line", row);
                for (size_t i = 0; i < count; i++)
                    memcpy(scan + 4 * (x + i), scan + 4 * (x - 1), 4);
                x += count;
                shift += 8;
            } else {
                memcpy(scan + 4 * x, p, 4);
                x++;
                shift = 0;
            }
            p += 4;
        }
    }
    *pp = p;
    return WENV_OK;
}

wenv_status wenv_read_rgbe(const uint8_t *buf, size_t size, const char *path, float **out, size_t *out_h,
                            size_t *out_w, wenv_error *err)
{
    const uint8_t *p = buf, *end = buf + size;
    int first = 1, rgbe = 1;
    /* header: "#?PROGRAM" line, variable lines, blank line (EXPOSURE and the like are ignored,
     * as Blender and most readers do) */
    for (;;) {
        const uint8_t *nl = memchr(p, '\n', (size_t)(end - p));
        if (!nl)
            return wenv_error_set(err, WENV_ERR_IO, "cannot read Radiance HDR file '%s': header does not end",
                                  path);
        size_t len = (size_t)(nl - p);
        if (first) {
            first = 0;
        } else if (len == 0 || (len == 1 && p[0] == '\r')) {
            p = nl + 1;
            break;
        } else if (len >= 7 && memcmp(p, "FORMAT=", 7) == 0) {
            const char *fmt = (const char *)p + 7;
            size_t flen = len - 7;
            while (flen && (fmt[flen - 1] == '\r' || fmt[flen - 1] == ' '))
                flen--;
            if (flen == 15 && memcmp(fmt, "32-bit_rle_rgbe", 15) == 0)
                rgbe = 1;
            else
                rgbe = 0;
        }
        p = nl + 1;
    }
    if (!rgbe)
        return wenv_error_set(err, WENV_ERR_IO,
                              "cannot read Radiance HDR file '%s': only FORMAT=32-bit_rle_rgbe is supported (XYZE "
                              "and others are not)",
                              path);
    const uint8_t *nl = memchr(p, '\n', (size_t)(end - p));
    char line[80];
    size_t len = nl ? (size_t)(nl - p) : 0;
    if (!nl || len >= sizeof line)
        return wenv_error_set(err, WENV_ERR_IO, "cannot read Radiance HDR file '%s': missing resolution line", path);
    memcpy(line, p, len);
    line[len] = '\0';
    p = nl + 1;
    char a1[3], a2[3];
    unsigned long long h = 0, w = 0;
    int consumed = 0;
    if (sscanf(line, "%2s %llu %2s %llu %n", a1, &h, a2, &w, &consumed) != 4 || line[consumed] != '\0')
        return wenv_error_set(err, WENV_ERR_IO, "cannot read Radiance HDR file '%s': bad resolution line '%s'", path,
                              line);
    if (strcmp(a1, "-Y") != 0 || strcmp(a2, "+X") != 0)
        return wenv_error_set(err, WENV_ERR_IO,
                              "cannot read Radiance HDR file '%s': orientation '%s' is not supported, only the "
                              "standard '-Y height +X width'",
                              path, line);
    if (h == 0 || w == 0 || h > WENV_IMAGE_MAX_SIDE || w > WENV_IMAGE_MAX_SIDE || h * w > WENV_IMAGE_MAX_PIXELS)
        return wenv_error_set(err, WENV_ERR_IO, "cannot read Radiance HDR file '%s': unusable size %llu x %llu",
                              path, w, h);
    size_t width = (size_t)w, height = (size_t)h;
    /* rows are held as they are decoded, the room doubling: a header claiming a huge image over a
     * few bytes is a truncated file, not an allocation of the size it claims */
    float *rgb = NULL;
    size_t room = 0;
    uint8_t *scan = malloc(width * 4);
    if (!scan)
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory reading '%s' (%zu x %zu)", path, width, height);
    for (size_t row = 0; row < height; row++) {
        if (hdr_scanline(&p, end, scan, width, path, row, err) != WENV_OK) {
            free(rgb);
            free(scan);
            return err->status;
        }
        if (row == room) {
            size_t more = room ? 2 * room : 16;
            room = more < height ? more : height;
            float *grown = realloc(rgb, room * width * 3 * sizeof *rgb);
            if (!grown) {
                free(rgb);
                free(scan);
                return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory reading '%s' (%zu x %zu)", path, width,
                                      height);
            }
            rgb = grown;
        }
        float *dst = rgb + row * width * 3;
        for (size_t x = 0; x < width; x++) {
            const uint8_t *q = scan + 4 * x;
            /* mantissa * 2^(e - 136), e = 0 black: the same numbers Blender (OpenImageIO) and
             * stb_image read.  Radiance's own colr_color adds half a step to the mantissa; matching
             * Blender matters more here than that sub-1% bias. */
            double f = q[3] ? ldexp(1.0, (int)q[3] - 136) : 0.0;
            for (int c = 0; c < 3; c++)
                dst[3 * x + c] = (float)((double)q[c] * f);
        }
    }
    free(scan);
    *out = rgb;
    *out_h = height;
    *out_w = width;
    return WENV_OK;
}

