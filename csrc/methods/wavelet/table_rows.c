/* The (normal sample, view sample) radiance table, made a row at a time: one normal sample's
 * lighting slice against every view's BRDF slice.
 *
 * Why rows: a view of a mesh never seen before reads table entries at views it has not read, and
 * making them one by one (a sparse dot product each, scattered reads of the lighting slice) cost a
 * new view of 126k vertices at `high` 0.1-0.3 s.  Made a row at a time, every view is ready once
 * a normal sample is, so a new view costs only the vertices' own work.  Rows are made in blocks of
 * 16 (or 8) normal samples whose slices are laid side by side, so that each BRDF term multiplies
 * as many lighting values at once (one vector instruction per channel): the table of `high`'s
 * 4096 x 1089 entries takes well under a second of one core. */
#include "methods/wavelet/wavelet_state.h"

#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "math/vector_math.h"

#define ROW_BLOCK 16

/* rows[s] += the BRDF slices of every view against the block's lighting, lit[(t * 3 + c) * W + s] =
 * slice s's coefficient t of channel c, W the block's width; out[s] is row s of the table (nv x 3),
 * each entry divided by its view's albedo (inv_albedo).  W floats are one vector: 16 one AVX-512
 * register, two AVX2 ones, four SSE ones; 8 half of those.  Each lane sums its own terms in the same
 * order whatever W, so both widths give the same table to the bit. */
#define DEFINE_BLOCK_ROWS(name, W)                                                                              \
    typedef float name##_vec __attribute__((vector_size((W) * sizeof(float))));                                \
    WENV_VECTOR_CLONES                                                                                         \
    static void name(const float *lit, const size_t *start, const uint32_t *idx, const float *rgb, size_t nv,  \
                     const float *inv_albedo, float *const *out, size_t n_out)                                 \
    {                                                                                                          \
        const name##_vec *lv = (const name##_vec *)lit;                                                        \
        for (size_t j = 0; j < nv; j++) {                                                                      \
            name##_vec a0 = {0}, a1 = {0}, a2 = {0};                                                           \
            for (size_t q = start[j]; q < start[j + 1]; q++) {                                                 \
                const name##_vec *l = lv + (size_t)idx[q] * 3;                                                 \
                const float *b = rgb + 3 * q;                                                                  \
                a0 += b[0] * l[0];                                                                             \
                a1 += b[1] * l[1];                                                                             \
                a2 += b[2] * l[2];                                                                             \
            }                                                                                                  \
            const float *inv = inv_albedo + 3 * j;                                                             \
            for (size_t s = 0; s < n_out; s++) {                                                               \
                float *o = out[s] + 3 * j;                                                                     \
                o[0] = a0[s] * inv[0];                                                                         \
                o[1] = a1[s] * inv[1];                                                                         \
                o[2] = a2[s] * inv[2];                                                                         \
            }                                                                                                  \
        }                                                                                                      \
    }
DEFINE_BLOCK_ROWS(block_rows16, 16)
DEFINE_BLOCK_ROWS(block_rows8, 8)

/* The block's width: 16 rows where their lighting (nl x 3 floats a row) fits in a core's L2 cache,
 * else 8.  Every BRDF term reads the lighting at a scattered coefficient: `high`'s 4096
 * coefficients take 786 KB at 16 rows, past a 512 KB L2 (AMD Zen 2 and 3), where the block's
 * table took 2.9 times as long as at 8 rows. */
static size_t block_width(size_t nl)
{
#ifdef _SC_LEVEL2_CACHE_SIZE
    long l2 = sysconf(_SC_LEVEL2_CACHE_SIZE);
#else
    long l2 = 0; /* unknown: the wider block */
#endif
    return l2 > 0 && nl * 3 * ROW_BLOCK * sizeof(float) > (size_t)l2 ? ROW_BLOCK / 2 : ROW_BLOCK;
}

wenv_status wenv_wavelet_fill_rows(wenv_wavelet *wavelet, const size_t *rows, size_t n, wenv_error *err)
{
    size_t nl = wavelet->nl, nv = wavelet->nv, width = block_width(nl), blocks = (n + width - 1) / width;
    atomic_int failed = 0;
#pragma omp parallel if (blocks > 1)
    {
        /* 64-byte aligned, the size a multiple of it (aligned_alloc's rule) */
        size_t bytes = (nl * 3 * width * sizeof(float) + 63) / 64 * 64;
        float *lit = aligned_alloc(64, bytes);
        if (!lit)
            atomic_store(&failed, 1);
#pragma omp for schedule(dynamic, 1)
        for (size_t blk = 0; blk < blocks; blk++) {
            if (atomic_load(&failed))
                continue;
            size_t first = blk * width, count = n - first < width ? n - first : width;
            float *out[ROW_BLOCK];
            const float *slice[ROW_BLOCK];
            for (size_t s = 0; s < count; s++) {
                slice[s] = wavelet->slices[rows[first + s]];
                out[s] = wavelet->m->table + rows[first + s] * nv * 3;
            }
            /* laid side by side: each slice read in order, the block written in order */
            for (size_t e = 0; e < nl * 3; e++) {
                float *to = lit + e * width;
                for (size_t s = 0; s < count; s++)
                    to[s] = slice[s][e];
                for (size_t s = count; s < width; s++)
                    to[s] = 0.0f;
            }
            (width == ROW_BLOCK ? block_rows16 : block_rows8)(lit, wavelet->m->brdf_start, wavelet->m->brdf_idx,
                                                              wavelet->m->brdf_rgb, nv, wavelet->m->view_inv_albedo,
                                                              out, count);
        }
        free(lit);
    }
    if (failed)
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory filling the shading table");
    return WENV_OK;
}

/* Lane s of block_rows alone: the same terms in the same order (C11 contracts no multiply-add), so the
 * same value to the bit as the row's entry. */
void wenv_wavelet_table_entry(const wenv_wavelet *wavelet, size_t s, size_t j, float rgb[3])
{
    const wenv_wavelet_material *m = wavelet->m;
    const float *slice = wavelet->slices[s];
    float a0 = 0.0f, a1 = 0.0f, a2 = 0.0f;
    for (size_t q = m->brdf_start[j]; q < m->brdf_start[j + 1]; q++) {
        const float *l = slice + (size_t)m->brdf_idx[q] * 3;
        const float *b = m->brdf_rgb + 3 * q;
        a0 += b[0] * l[0];
        a1 += b[1] * l[1];
        a2 += b[2] * l[2];
    }
    const float *inv = m->view_inv_albedo + 3 * j;
    rgb[0] = a0 * inv[0];
    rgb[1] = a1 * inv[1];
    rgb[2] = a2 * inv[2];
}
