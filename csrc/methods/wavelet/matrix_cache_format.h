/* The rotation matrices' cache file as it lies on disk (matrix_cache.c writes and reads it; the
 * fuzz target builds inputs from it): a header, a table of one entry per normal sample's zlib
 * block, then the blocks.  Little-endian x86-64 layout, no padding. */
#ifndef WENV_MATRIX_CACHE_FORMAT_H
#define WENV_MATRIX_CACHE_FORMAT_H

#include <stddef.h>
#include <stdint.h>
#include <zlib.h>

#define WENV_MATRIX_CACHE_MAGIC "WENVROT"
#define WENV_MATRIX_CACHE_VERSION 3u /* 2: float resampling splat; 3: byte planes, run-length zlib */

typedef struct {
    char magic[8];
    uint32_t version, header_crc;
    uint64_t global_n, local_n, normal_n;
    double epsilon;
} wenv_matrix_cache_header;

typedef struct {
    uint64_t comp_size, raw_size;
    uint32_t crc, pad;
} wenv_matrix_cache_entry;

_Static_assert(sizeof(wenv_matrix_cache_header) == 48 && sizeof(wenv_matrix_cache_entry) == 24,
               "the cache file's layout");

/* The header's CRC covers the header (its CRC field zero) and the block table. */
static inline uint32_t wenv_matrix_cache_header_crc(const wenv_matrix_cache_header *h,
                                                    const wenv_matrix_cache_entry *entries, size_t ns)
{
    wenv_matrix_cache_header copy = *h;
    copy.header_crc = 0;
    uLong crc = crc32(0L, (const Bytef *)&copy, sizeof copy);
    return (uint32_t)crc32(crc, (const Bytef *)entries, (uInt)(ns * sizeof *entries));
}

#endif
