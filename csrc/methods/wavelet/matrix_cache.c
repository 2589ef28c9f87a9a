/* The rotation matrices' cache file: a header (magic, version, sizes, epsilon, its CRC) and one
 * zlib block per normal sample with its own CRC-32, written to a temporary file and renamed.
 *
 * A block holds its row indices as deltas within each column and every multi-byte field as byte
 * planes (all low bytes, then the next, ...), compressed with zlib's run-length strategy: the
 * values' sign-exponent planes and the small deltas compress, the mantissas' low planes do not and
 * are passed over quickly.  Level 1's string matching took 9 ms a block of 64/32/32 (60 % of the
 * thesis's largest precompute) for 55 % of the raw size; this takes 4 ms for 65 %. */
#include "methods/wavelet/rotation.h"

#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>
#include <zlib.h>

#include "methods/wavelet/matrix_cache_format.h"

/* Raw block of one matrix: nnz (u64), colptr as u32 (cols + 1), the rows' deltas within their column
 * as two byte planes of nnz, the f32 values as four. */
static size_t raw_size_of(const wenv_csc *m)
{
    size_t nnz = wenv_csc_nnz(m);
    return 8 + (m->cols + 1) * 4 + nnz * 2 + nnz * 4;
}

/* Byte k of field i (of `size` bytes, as the machine stores it: wenv builds for little-endian
 * platforms) goes to plane k at i: planes[k * n + i]. */
static void to_planes(const unsigned char *fields, size_t n, size_t size, unsigned char *planes)
{
    for (size_t i = 0; i < n; i++)
        for (size_t k = 0; k < size; k++)
            planes[k * n + i] = fields[i * size + k];
}

static void from_planes(const unsigned char *planes, size_t n, size_t size, unsigned char *fields)
{
    for (size_t i = 0; i < n; i++)
        for (size_t k = 0; k < size; k++)
            fields[i * size + k] = planes[k * n + i];
}

static void pack(const wenv_csc *m, unsigned char *buf)
{
    uint64_t nnz = wenv_csc_nnz(m);
    memcpy(buf, &nnz, 8);
    buf += 8;
    for (size_t c = 0; c <= m->cols; c++) {
        uint32_t v = (uint32_t)m->colptr[c];
        memcpy(buf, &v, 4);
        buf += 4;
    }
    /* rows ascend within a column: their deltas from the row before (the first from 0) are small */
    for (size_t c = 0; c < m->cols; c++) {
        unsigned prev = 0;
        for (size_t e = m->colptr[c]; e < m->colptr[c + 1]; e++) {
            unsigned delta = (unsigned)(m->rowidx[e] - prev) & 0xffffu;
            buf[e] = (unsigned char)(delta & 0xffu);
            buf[nnz + e] = (unsigned char)(delta >> 8);
            prev = m->rowidx[e];
        }
    }
    to_planes((const unsigned char *)m->val, nnz, 4, buf + 2 * nnz);
}

static int unpack(const unsigned char *buf, size_t size, size_t rows, size_t cols, wenv_csc *m)
{
    uint64_t nnz;
    if (size < 8)
        return -1;
    memcpy(&nnz, buf, 8);
    if (nnz > rows * cols || size != 8 + (cols + 1) * 4 + nnz * 6)
        return -1;
    buf += 8;
    m->rows = rows;
    m->cols = cols;
    m->colptr = malloc((cols + 1) * sizeof(size_t));
    m->rowidx = malloc((nnz ? nnz : 1) * sizeof(uint16_t));
    m->val = malloc((nnz ? nnz : 1) * sizeof(float));
    if (!m->colptr || !m->rowidx || !m->val)
        return -1;
    for (size_t c = 0; c <= cols; c++) {
        uint32_t v;
        memcpy(&v, buf, 4);
        buf += 4;
        m->colptr[c] = v;
        if (v > nnz || (c > 0 && m->colptr[c] < m->colptr[c - 1]) || (c == 0 && v != 0))
            return -1;
    }
    if (m->colptr[cols] != nnz)
        return -1;
    for (size_t c = 0; c < cols; c++) {
        size_t row = 0;
        for (size_t e = m->colptr[c]; e < m->colptr[c + 1]; e++) {
            row += (size_t)buf[e] | (size_t)buf[nnz + e] << 8;
            if (row >= rows)
                return -1;
            m->rowidx[e] = (uint16_t)row;
        }
    }
    from_planes(buf + 2 * nnz, nnz, 4, (unsigned char *)m->val);
    /* R = H_local S H_global^T with orthonormal Haar bases and S row-stochastic (non-negative, rows
     * summing to 1): |R_ij| <= ||S||_2 <= sqrt(||S||_1 ||S||_inf) <= sqrt(rows).  A block with valid
     * CRCs but values beyond that was not written by wenv_rotation_save. */
    float bound = sqrtf((float)rows) * 1.0001f;
    for (size_t e = 0; e < nnz; e++)
        if (!(fabsf(m->val[e]) <= bound))
            return -1;
    return 0;
}

/* zlib's run-length strategy at level 1 into out (room for compressBound(size)); *out_size set. */
static int compress_block(const unsigned char *in, size_t size, unsigned char *out, uLongf *out_size)
{
    z_stream z;
    memset(&z, 0, sizeof z);
    if (deflateInit2(&z, 1, Z_DEFLATED, 15, 8, Z_RLE) != Z_OK)
        return -1;
    z.next_in = (Bytef *)in;
    z.avail_in = (uInt)size;
    z.next_out = out;
    z.avail_out = (uInt)*out_size;
    int r = deflate(&z, Z_FINISH);
    *out_size = z.total_out;
    deflateEnd(&z);
    return r == Z_STREAM_END ? 0 : -1;
}

/* The rename itself reaches the disk only with its folder: best effort (a failure loses the
 * cache, never its content). */
static void sync_folder_of(const char *path)
{
    const char *slash = strrchr(path, '/');
    char folder[4096];
    size_t len = slash ? (size_t)(slash - path) : 0;
    if (len >= sizeof folder)
        return;
    memcpy(folder, path, len);
    folder[len] = '\0';
    int fd = open(slash == path ? "/" : len ? folder : ".", O_RDONLY | O_DIRECTORY);
    if (fd >= 0) {
        fsync(fd);
        close(fd);
    }
}

wenv_status wenv_rotation_save(const wenv_rotation *rot, const char *path, wenv_error *err)
{
    size_t ns = rot->normal_n * rot->normal_n;
    wenv_matrix_cache_entry *entries = calloc(ns, sizeof *entries);
    unsigned char **blobs = calloc(ns, sizeof *blobs);
    if (!entries || !blobs) {
        free(entries);
        free(blobs);
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory writing %s", path);
    }
    atomic_int failed = 0;
#pragma omp parallel for schedule(dynamic, 4)
    for (size_t s = 0; s < ns; s++) {
        size_t raw = raw_size_of(&rot->matrices[s]);
        unsigned char *rawbuf = malloc(raw);
        uLongf comp = compressBound((uLong)raw);
        blobs[s] = malloc(comp);
        if (!rawbuf || !blobs[s]) {
            free(rawbuf);
            atomic_store(&failed, 1);
            continue;
        }
        pack(&rot->matrices[s], rawbuf);
        if (compress_block(rawbuf, raw, blobs[s], &comp) < 0)
            atomic_store(&failed, 1);
        entries[s].comp_size = comp;
        entries[s].raw_size = raw;
        entries[s].crc = (uint32_t)crc32(0L, rawbuf, (uInt)raw);
        free(rawbuf);
    }
    wenv_status st = WENV_OK;
    char *tmp = NULL;
    FILE *fp = NULL;
    if (failed) {
        st = wenv_error_set(err, WENV_ERR_NOMEM, "out of memory compressing rotation matrices for %s", path);
        goto done;
    }
    wenv_matrix_cache_header h;
    memset(&h, 0, sizeof h);
    memcpy(h.magic, WENV_MATRIX_CACHE_MAGIC, sizeof WENV_MATRIX_CACHE_MAGIC);
    h.version = WENV_MATRIX_CACHE_VERSION;
    h.global_n = rot->global_n;
    h.local_n = rot->local_n;
    h.normal_n = rot->normal_n;
    h.epsilon = rot->epsilon;
    h.header_crc = wenv_matrix_cache_header_crc(&h, entries, ns);
    size_t plen = strlen(path) + 64;
    tmp = malloc(plen);
    if (!tmp) {
        st = wenv_error_set(err, WENV_ERR_NOMEM, "out of memory writing %s", path);
        goto done;
    }
    /* a new file of a name no one can guess (mkstemp: O_CREAT | O_EXCL, so no symlink planted at the
     * name is followed, and threads and processes writing at once each have their own), renamed over
     * the cache file once complete and on disk */
    snprintf(tmp, plen, "%s.tmp.XXXXXX", path);
    int fd = mkstemp(tmp);
    if (fd < 0 || fchmod(fd, 0644) != 0 || !(fp = fdopen(fd, "wb"))) {
        st = wenv_error_set(err, WENV_ERR_IO, "cannot write %s: %s", tmp, strerror(errno));
        if (fd >= 0) {
            close(fd);
            remove(tmp);
        }
        goto done;
    }
    int ok = fwrite(&h, sizeof h, 1, fp) == 1 && fwrite(entries, sizeof *entries, ns, fp) == ns;
    for (size_t s = 0; ok && s < ns; s++)
        ok = fwrite(blobs[s], 1, entries[s].comp_size, fp) == entries[s].comp_size;
    ok = ok && fflush(fp) == 0 && fsync(fileno(fp)) == 0;
    ok = (fclose(fp) == 0) && ok;
    fp = NULL;
    if (!ok || rename(tmp, path) != 0) {
        st = wenv_error_set(err, WENV_ERR_IO, "cannot write %s: %s", path, strerror(errno));
        remove(tmp);
    } else {
        sync_folder_of(path);
    }
done:
    for (size_t s = 0; s < ns; s++)
        free(blobs[s]);
    free(blobs);
    free(entries);
    free(tmp);
    return st;
}

wenv_status wenv_rotation_load(wenv_rotation **out, const char *path, size_t global_n, size_t local_n,
                               size_t normal_n, double epsilon, wenv_error *err)
{
    *out = NULL;
    if (wenv_rotation_check_sizes(global_n, local_n, normal_n, err))
        return err->status;
    FILE *fp = fopen(path, "rb");
    if (!fp)
        return wenv_error_set(err, WENV_ERR_IO, "cannot open %s: %s", path, strerror(errno));
    size_t ns = normal_n * normal_n, nl = local_n * local_n, ng = global_n * global_n;
    wenv_matrix_cache_header h;
    wenv_matrix_cache_entry *entries = NULL;
    wenv_rotation *rot = NULL;
    wenv_status st = WENV_OK;
    if (fread(&h, sizeof h, 1, fp) != 1 || memcmp(h.magic, WENV_MATRIX_CACHE_MAGIC, sizeof WENV_MATRIX_CACHE_MAGIC) != 0 ||
        h.version != WENV_MATRIX_CACHE_VERSION || h.global_n != global_n || h.local_n != local_n ||
        h.normal_n != normal_n || h.epsilon != epsilon) {
        st = wenv_error_set(err, WENV_ERR_IO, "%s is not a wenv rotation cache for these sizes", path);
        goto fail;
    }
    entries = malloc(ns * sizeof *entries);
    if (!entries) {
        st = wenv_error_set(err, WENV_ERR_NOMEM, "out of memory reading %s", path);
        goto fail;
    }
    if (fread(entries, sizeof *entries, ns, fp) != ns || wenv_matrix_cache_header_crc(&h, entries, ns) != h.header_crc) {
        st = wenv_error_set(err, WENV_ERR_IO, "%s: truncated or corrupt header", path);
        goto fail;
    }
    rot = calloc(1, sizeof *rot);
    if (rot)
        rot->matrices = calloc(ns, sizeof *rot->matrices);
    if (!rot || !rot->matrices) {
        st = wenv_error_set(err, WENV_ERR_NOMEM, "out of memory reading %s", path);
        goto fail;
    }
    rot->global_n = global_n;
    rot->local_n = local_n;
    rot->normal_n = normal_n;
    rot->epsilon = epsilon;
    size_t max_raw = 8 + (ng + 1) * 4 + nl * ng * 6;
    struct stat file;
    uint64_t table_end = sizeof h + ns * sizeof *entries;
    if (fstat(fileno(fp), &file) != 0 || file.st_size < 0 || (uint64_t)file.st_size < table_end) {
        st = wenv_error_set(err, WENV_ERR_IO, "%s: truncated or unreadable", path);
        goto fail;
    }
    uint64_t left = (uint64_t)file.st_size - table_end;
    for (size_t s = 0; s < ns; s++) {
        wenv_matrix_cache_entry *e = &entries[s];
        /* sizes are checked against what the file still holds before anything is allocated for
         * them: zlib never inflates more than 1032 times (a deflate match of 258 bytes takes at
         * least 2 bits), so a block table claiming more is corrupt whatever its CRC says */
        if (e->raw_size > max_raw || e->comp_size > compressBound((uLong)e->raw_size) || e->comp_size > left ||
            e->raw_size > 1032 * e->comp_size) {
            st = wenv_error_set(err, WENV_ERR_IO, "%s: corrupt block table (block %zu: %llu bytes inflating to %llu, "
                                "%llu bytes left in the file)", path, s, (unsigned long long)e->comp_size,
                                (unsigned long long)e->raw_size, (unsigned long long)left);
            goto fail;
        }
        left -= e->comp_size;
        unsigned char *comp = malloc(e->comp_size ? e->comp_size : 1);
        unsigned char *raw = malloc(e->raw_size ? e->raw_size : 1);
        int ok = comp && raw && fread(comp, 1, e->comp_size, fp) == e->comp_size;
        uLongf rawlen = (uLongf)e->raw_size;
        ok = ok && uncompress(raw, &rawlen, comp, (uLong)e->comp_size) == Z_OK && rawlen == e->raw_size;
        ok = ok && (uint32_t)crc32(0L, raw, (uInt)rawlen) == e->crc;
        ok = ok && unpack(raw, rawlen, nl, ng, &rot->matrices[s]) == 0;
        free(comp);
        free(raw);
        if (!ok) {
            st = wenv_error_set(err, WENV_ERR_IO, "%s: truncated or corrupt block %zu", path, s);
            goto fail;
        }
    }
    if (fgetc(fp) != EOF) {
        st = wenv_error_set(err, WENV_ERR_IO, "%s: trailing data", path);
        goto fail;
    }
    rot->normal_n = normal_n;
    fclose(fp);
    free(entries);
    *out = rot;
    return WENV_OK;
fail:
    fclose(fp);
    free(entries);
    if (rot)
        rot->normal_n = rot->matrices ? normal_n : 0;
    wenv_rotation_free(rot);
    return st;
}
