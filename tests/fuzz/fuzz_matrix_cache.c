/* Fuzz target: the rotation matrices' cache file (methods/wavelet/matrix_cache.c), loaded with the
 * sizes its own header names, as a Shader whose settings match would load it.  Built and run by
 * tests/fuzz/run.py.
 *
 * Every block is zlib-compressed and every part carries a CRC-32, so random bytes almost never get
 * past the checksums to the matrices behind them.  A custom mutator therefore mostly mutates the
 * file's content -- the header's fields or a block's uncompressed matrix -- and writes it back
 * compressed, with sizes and CRCs made right (libFuzzer's documented way for compressed inputs); a
 * quarter of the mutations stay plain byte mutations, which reach the checks themselves. */
#include "fuzz_input.h"

#include <zlib.h>

#include "methods/wavelet/matrix_cache_format.h"
#include "methods/wavelet/rotation.h"

/* More than any input libFuzzer is given here (-max_len), so a parsed file is always small. */
#define MAX_FILE ((size_t)1 << 22)

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    wenv_matrix_cache_header h = {{0}, 0, 0, 4, 4, 2, 1e-3};
    if (size)
        memcpy(&h, data, size < sizeof h ? size : sizeof h);
    char path[64];
    int fd = fuzz_input_file(data, size, path, sizeof path);
    wenv_rotation *rot = NULL;
    wenv_error err = {0};
    wenv_status st = wenv_rotation_load(&rot, path, (size_t)h.global_n, (size_t)h.local_n, (size_t)h.normal_n,
                                        h.epsilon, &err);
    if (st == WENV_OK) {
        /* the loader's promise: matrices of the header's sizes */
        if (rot->normal_n != h.normal_n || !rot->matrices)
            abort();
        for (size_t s = 0; s < rot->normal_n * rot->normal_n; s++)
            if (rot->matrices[s].rows != h.local_n * h.local_n || rot->matrices[s].cols != h.global_n * h.global_n)
                abort();
        wenv_rotation_free(rot);
    } else if (st != WENV_ERR_VALUE) { /* VALUE: header sizes no Shader asks for, refused before opening */
        fuzz_check_refusal(st, &err, path);
    }
    close(fd);
    return 0;
}

/* ---------------------------------------------------------------- the structure-aware mutator */

size_t LLVMFuzzerMutate(uint8_t *data, size_t size, size_t max_size);

typedef struct {
    wenv_matrix_cache_header h;
    size_t ns;
    wenv_matrix_cache_entry *entries;
    unsigned char **raw; /* each block uncompressed */
} parsed_cache;

static void parsed_free(parsed_cache *p)
{
    for (size_t s = 0; p->raw && s < p->ns; s++)
        free(p->raw[s]);
    free(p->raw);
    free(p->entries);
}

/* 0 if `data` is a well-formed cache file of plausible sizes (CRCs need not be right). */
static int parse(const uint8_t *data, size_t size, parsed_cache *p)
{
    memset(p, 0, sizeof *p);
    if (size < sizeof p->h || size > MAX_FILE)
        return -1;
    memcpy(&p->h, data, sizeof p->h);
    if (p->h.normal_n < 1 || p->h.normal_n > 512)
        return -1;
    p->ns = (size_t)(p->h.normal_n * p->h.normal_n);
    size_t pos = sizeof p->h;
    if (p->ns > (size - pos) / sizeof(wenv_matrix_cache_entry))
        return -1;
    p->entries = malloc(p->ns * sizeof *p->entries);
    p->raw = calloc(p->ns, sizeof *p->raw);
    if (!p->entries || !p->raw)
        return -1;
    memcpy(p->entries, data + pos, p->ns * sizeof *p->entries);
    pos += p->ns * sizeof *p->entries;
    for (size_t s = 0; s < p->ns; s++) {
        wenv_matrix_cache_entry *e = &p->entries[s];
        if (e->comp_size > size - pos || e->raw_size > MAX_FILE)
            return -1;
        p->raw[s] = malloc(e->raw_size ? e->raw_size : 1);
        uLongf len = (uLongf)e->raw_size;
        if (!p->raw[s] || uncompress(p->raw[s], &len, data + pos, (uLong)e->comp_size) != Z_OK ||
            len != e->raw_size)
            return -1;
        pos += e->comp_size;
    }
    return 0;
}

/* Writes `p` to out (at most max_size bytes) with every size and CRC made right; 0 if it fits. */
static size_t serialise(parsed_cache *p, uint8_t *out, size_t max_size)
{
    size_t pos = sizeof p->h + p->ns * sizeof *p->entries;
    if (pos > max_size)
        return 0;
    for (size_t s = 0; s < p->ns; s++) {
        wenv_matrix_cache_entry *e = &p->entries[s];
        uLongf comp = compressBound((uLong)e->raw_size);
        if (comp > max_size - pos)
            return 0;
        if (compress2(out + pos, &comp, p->raw[s], (uLong)e->raw_size, 1) != Z_OK)
            return 0;
        e->comp_size = comp;
        e->crc = (uint32_t)crc32(0L, p->raw[s], (uInt)e->raw_size);
        pos += comp;
    }
    p->h.header_crc = wenv_matrix_cache_header_crc(&p->h, p->entries, p->ns);
    memcpy(out, &p->h, sizeof p->h);
    memcpy(out + sizeof p->h, p->entries, p->ns * sizeof *p->entries);
    return pos;
}

size_t LLVMFuzzerCustomMutator(uint8_t *data, size_t size, size_t max_size, unsigned int seed)
{
    if (seed % 4 == 0)
        return LLVMFuzzerMutate(data, size, max_size);
    parsed_cache p;
    if (parse(data, size, &p) != 0) {
        parsed_free(&p);
        return LLVMFuzzerMutate(data, size, max_size);
    }
    if (seed % 8 == 1) { /* the header's fields (magic, version, sizes, epsilon), its size fixed */
        LLVMFuzzerMutate((uint8_t *)&p.h, sizeof p.h, sizeof p.h);
    } else if (p.ns) { /* one block's matrix (nnz, column pointers, row indices, values), its length too */
        size_t s = (seed / 8) % p.ns, raw = (size_t)p.entries[s].raw_size, room = 2 * raw + 64;
        unsigned char *buf = malloc(room);
        if (buf) {
            memcpy(buf, p.raw[s], raw);
            p.entries[s].raw_size = LLVMFuzzerMutate(buf, raw, room);
            free(p.raw[s]);
            p.raw[s] = buf;
        }
    }
    size_t out = 0;
    uint8_t *tmp = malloc(max_size);
    if (tmp) {
        out = serialise(&p, tmp, max_size);
        if (out)
            memcpy(data, tmp, out);
        free(tmp);
    }
    parsed_free(&p);
    return out ? out : LLVMFuzzerMutate(data, size, max_size);
}
