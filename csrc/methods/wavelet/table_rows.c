/* The (normal sample, view sample) radiance table, made a row at a time: one normal sample's
 * lighting slice against every view's BRDF slice.
 *
 * Why rows: a view of a mesh never seen before reads table entries at views it has not read, and
 * making them one by one (a sparse dot product each, scattered reads of the lighting slice) cost a
 * new view of 126k vertices at `high` 0.1-0.3 s.  Made a row at a time, every view is ready once
 * a normal sample is, so a new view costs only the vertices' own work.  Rows are made in blocks of
 * ROW_BLOCK normal samples whose slices are laid side by side, so that each BRDF term multiplies
 * ROW_BLOCK lighting values at once (one vector instruction per channel): the table of `high`'s
 * 4096 x 1089 entries takes well under a second of one core. */
#include "methods/wavelet/wavelet_state.h"

#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>

#include "math/vector_math.h"

#define ROW_BLOCK 16

/* rows[s] += the BRDF slices of every view against the block's lighting, lit[(t * 3 + c) *
 * ROW_BLOCK + s] = slice s's coefficient t of channel c; out[s] is row s of the table (nv x 3),
 * each entry divided by its view's albedo (inv_albedo). */
/* ROW_BLOCK floats: one AVX-512 register, two AVX2 ones, four SSE ones */
typedef float row_vec __attribute__((vector_size(ROW_BLOCK * sizeof(float))));

WENV_VECTOR_CLONES
static void block_rows(const float *lit, const size_t *start, const uint32_t *idx, const float *rgb, size_t nv,
                       const float *inv_albedo, float *const *out, size_t n_out)
{
    const row_vec *lv = (const row_vec *)lit;
    for (size_t j = 0; j < nv; j++) {
        row_vec a0 = {0}, a1 = {0}, a2 = {0};
        for (size_t q = start[j]; q < start[j + 1]; q++) {
            const row_vec *l = lv + (size_t)idx[q] * 3;
            const float *b = rgb + 3 * q;
            a0 += b[0] * l[0];
            a1 += b[1] * l[1];
            a2 += b[2] * l[2];
        }
        const float *inv = inv_albedo + 3 * j;
        for (size_t s = 0; s < n_out; s++) {
            float *o = out[s] + 3 * j;
            o[0] = a0[s] * inv[0];
            o[1] = a1[s] * inv[1];
            o[2] = a2[s] * inv[2];
        }
    }
}

wenv_status wenv_wavelet_fill_rows(wenv_wavelet *wavelet, const size_t *rows, size_t n, wenv_error *err)
{
    size_t nl = wavelet->nl, nv = wavelet->nv, blocks = (n + ROW_BLOCK - 1) / ROW_BLOCK;
    atomic_int failed = 0;
#pragma omp parallel if (blocks > 1)
    {
        /* 64-byte aligned, the size a multiple of it (aligned_alloc's rule) */
        size_t bytes = (nl * 3 * ROW_BLOCK * sizeof(float) + 63) / 64 * 64;
        float *lit = aligned_alloc(64, bytes);
        if (!lit)
            atomic_store(&failed, 1);
#pragma omp for schedule(dynamic, 1)
        for (size_t blk = 0; blk < blocks; blk++) {
            if (atomic_load(&failed))
                continue;
            size_t first = blk * ROW_BLOCK, count = n - first < ROW_BLOCK ? n - first : ROW_BLOCK;
            float *out[ROW_BLOCK];
            const float *slice[ROW_BLOCK];
            for (size_t s = 0; s < count; s++) {
                slice[s] = wavelet->slices[rows[first + s]];
                out[s] = wavelet->m->table + rows[first + s] * nv * 3;
            }
            /* laid side by side: each slice read in order, the block written in order */
            for (size_t e = 0; e < nl * 3; e++) {
                float *to = lit + e * ROW_BLOCK;
                for (size_t s = 0; s < count; s++)
                    to[s] = slice[s][e];
                for (size_t s = count; s < ROW_BLOCK; s++)
                    to[s] = 0.0f;
            }
            block_rows(lit, wavelet->m->brdf_start, wavelet->m->brdf_idx, wavelet->m->brdf_rgb, nv, wavelet->m->view_inv_albedo,
                       out, count);
        }
        free(lit);
    }
    if (failed)
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory filling the shading table");
    return WENV_OK;
}
