/* The grazing path's node loop (grazing_nodes.h) in three versions: AVX-512, AVX2 and a portable
 * one.  GCC did not vectorise the portable loop (the octahedral edge folds and the two levels'
 * selects stayed branches), which left the path at about 4 ns a node; the versions below find 16 or
 * 8 nodes' taps per instruction.  AVX-512 reads the taps with gathers.  AVX2 reads each node's two
 * rows of taps as two 128-bit loads: on AMD's Zen 3 (no AVX-512) the gathers took 68 % of a view
 * at m = 0.1, and the loads take 1.8x less time.  All three compute the same thing per node from
 * the same halves (their conversion to float is exact); AVX2 as lerps, so the sums differ in their
 * last bits. */
#include "methods/wavelet/grazing_nodes.h"

#include <math.h>
#include <stdlib.h>

#include "math/half.h"

#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#define WENV_HAVE_X86_NODES 1
#endif

/* ---- portable ---------------------------------------------------------------------------------- */

/* Where one level's bilinear read of (u, v) starts: its first tap (the next is 4 halves on, the row
 * below *row taps on) and the weights across (*tx) and down (*ty). */
static inline const uint16_t *level_taps1(const wenv_node_pyramid *p, int32_t level, float u, float v, float *tx,
                                          float *ty, int32_t *row)
{
    int32_t side = p->side[level];
    *row = side + 2;
    float fx = (u + 1.0f) * 0.5f * (float)side - 0.5f, fy = (v + 1.0f) * 0.5f * (float)side - 0.5f;
    int32_t ix = (int32_t)(fx + 1.0f) - 1, iy = (int32_t)(fy + 1.0f) - 1; /* floor for x >= -1 */
    *tx = fx - (float)ix;
    *ty = fy - (float)iy;
    /* the border holds what lies past the edges: -1 and side are its columns and rows */
    ix = ix < -1 ? -1 : (ix > side - 1 ? side - 1 : ix);
    iy = iy < -1 ? -1 : (iy > side - 1 ? side - 1 : iy);
    return p->texels + 4 * (size_t)(p->offset[level] + (iy + 1) * *row + ix + 1);
}

/* Tap c (0 to 3: across, then down) of a read starting at t0, and its weight in it. */
static inline const uint16_t *level_tap(const uint16_t *t0, int32_t row, int32_t c, float wl, float tx, float ty,
                                        float *wt)
{
    *wt = wl * ((c & 1) ? tx : 1.0f - tx) * ((c >> 1) ? ty : 1.0f - ty);
    return t0 + 4 * ((c & 1) + (c >> 1) * row);
}

static inline void level_read(const wenv_node_pyramid *p, int32_t level, float u, float v, float wl, float sum[3])
{
    float tx, ty, wt;
    int32_t row;
    const uint16_t *t0 = level_taps1(p, level, u, v, &tx, &ty, &row);
    for (int32_t c = 0; c < 4; c++) {
        const uint16_t *t = level_tap(t0, row, c, wl, tx, ty, &wt);
        sum[0] += wt * wenv_float_from_half(t[0]);
        sum[1] += wt * wenv_float_from_half(t[1]);
        sum[2] += wt * wenv_float_from_half(t[2]);
    }
}

/* Direction (d0, d1, d2)'s octahedral (u, v), and the two levels read at lod (clamped) with the
 * coarser one's weight. */
static inline void direction_levels(const wenv_node_pyramid *p, float d0, float d1, float d2, float lod, float *u,
                                    float *v, int32_t *l0, int32_t *l1, float *fl)
{
    float top = (float)p->top;
    /* octahedral encoding (wenv_oct_encode_f) */
    float inv = 1.0f / (fabsf(d0) + fabsf(d1) + fabsf(d2) + 1e-30f);
    float pu = d0 * inv, pv = d1 * inv;
    *u = d2 < 0.0f ? copysignf(1.0f - fabsf(pv), pu) : pu;
    *v = d2 < 0.0f ? copysignf(1.0f - fabsf(pu), pv) : pv;
    lod = lod < 0.0f ? 0.0f : (lod > top ? top : lod);
    *l0 = (int32_t)lod;
    *l1 = *l0 + 1 < p->top ? *l0 + 1 : p->top;
    *fl = lod - (float)*l0;
}

/* The lighting in world direction (d0, d1, d2) at level lod (before clamping), into sum. */
static inline void read_direction(const wenv_node_pyramid *p, float d0, float d1, float d2, float lod, float sum[3])
{
    float u, v, fl;
    int32_t l0, l1;
    direction_levels(p, d0, d1, d2, lod, &u, &v, &l0, &l1, &fl);
    level_read(p, l0, u, v, 1.0f - fl, sum);
    level_read(p, l1, u, v, fl, sum);
}

#ifdef WENV_HAVE_X86_NODES
#define F16C __attribute__((target("f16c")))

/* read_direction with each tap's four halves converted at once by the CPU: every channel's products
 * and sums are the portable read's, in its order, and the conversion is exact, so the values are
 * the same to the bit.  Shadows read a blocked texel's lighting so, a few times per vertex. */
F16C static void read_direction_f16c(const wenv_node_pyramid *p, const float d[3], float lod, float sum[3])
{
    float u, v, fl, tx, ty, wt;
    int32_t levels[2], row;
    direction_levels(p, d[0], d[1], d[2], lod, &u, &v, &levels[0], &levels[1], &fl);
    __m128 acc = _mm_setzero_ps();
    for (int k = 0; k < 2; k++) {
        const uint16_t *t0 = level_taps1(p, levels[k], u, v, &tx, &ty, &row);
        for (int32_t c = 0; c < 4; c++) {
            const uint16_t *t = level_tap(t0, row, c, k ? fl : 1.0f - fl, tx, ty, &wt);
            __m128 h = _mm_cvtph_ps(_mm_loadl_epi64((const __m128i *)(const void *)t));
            acc = _mm_add_ps(acc, _mm_mul_ps(_mm_set1_ps(wt), h));
        }
    }
    float out[4];
    _mm_storeu_ps(out, acc);
    for (int c = 0; c < 3; c++)
        sum[c] = out[c];
}
#endif

void wenv_node_pyramid_read(const wenv_node_pyramid *p, const float d[3], float log2_footprint, float rgb[3])
{
    rgb[0] = rgb[1] = rgb[2] = 0.0f;
#ifdef WENV_HAVE_X86_NODES
    if (p->halves_by_cpu)
        read_direction_f16c(p, d, log2_footprint + p->lod_offset, rgb);
    else
#endif
        read_direction(p, d[0], d[1], d[2], log2_footprint + p->lod_offset, rgb);
    for (int c = 0; c < 3; c++)
        rgb[c] *= p->scale;
}

uint16_t *wenv_node_pyramid_make(wenv_node_pyramid *p, const float *const *rgb, const size_t *sides, size_t levels)
{
    size_t total = 0;
    float top = 0.0f;
    for (size_t k = 0; k < levels; k++) {
        total += (sides[k] + 2) * (sides[k] + 2);
        for (size_t i = 0; i < 3 * sides[k] * sides[k]; i++)
            top = rgb[k][i] > top ? rgb[k][i] : top;
    }
    uint16_t *halves = aligned_alloc(8, (total ? total : 1) * 4 * sizeof(uint16_t));
    if (!halves)
        return NULL;
    /* top / scale in (2^13, 2^14] */
    int e;
    frexpf(top > 0.0f ? top : 1.0f, &e);
    p->scale = ldexpf(1.0f, e - 14);
    float inv = 1.0f / p->scale;
    size_t at = 0;
    for (size_t k = 0; k < levels; k++) {
        int32_t side = (int32_t)sides[k], row = side + 2;
        p->side[k] = side;
        p->offset[k] = (int32_t)at;
#pragma omp parallel for schedule(static) if (side > 128)
        for (int32_t pj = 0; pj < row; pj++)
            for (int32_t pi = 0; pi < row; pi++) {
                /* crossing an edge of the octahedral square lands on the same edge, mirrored; at a
                 * corner, twice */
                int32_t i = pi - 1, j = pj - 1;
                int32_t out_i = i < 0 || i >= side;
                int32_t i1 = out_i ? (i < 0 ? 0 : side - 1) : i, j1 = out_i ? side - 1 - j : j;
                int32_t out_j = j1 < 0 || j1 >= side;
                int32_t j2 = out_j ? (j1 < 0 ? 0 : side - 1) : j1, i2 = out_j ? side - 1 - i1 : i1;
                const float *src = rgb[k] + 3 * ((size_t)j2 * (size_t)side + (size_t)i2);
                uint16_t *dst = halves + 4 * (at + (size_t)pj * (size_t)row + (size_t)pi);
                for (int c = 0; c < 3; c++)
                    dst[c] = wenv_half_from_float(src[c] * inv);
                dst[3] = 0;
            }
        at += (size_t)row * (size_t)row;
    }
    p->top = (int32_t)levels - 1;
    p->texels = halves;
    p->halves_by_cpu = 0;
#ifdef WENV_HAVE_X86_NODES
    __builtin_cpu_init();
    p->halves_by_cpu = __builtin_cpu_supports("avx2"); /* every AVX2 CPU has F16C (see below) */
#endif
    return halves;
}

void wenv_grazing_nodes_portable(const float *a, const float *b, size_t stride, size_t n, float g, float f,
                                 const float x[3], const float y[3], const float z[3], const wenv_node_pyramid *p,
                                 float rgb[3])
{
    float acc[3] = {0.0f, 0.0f, 0.0f};
    for (size_t k = 0; k < n; k++) {
        float lx = g * a[k] + f * b[k], ly = g * a[stride + k] + f * b[stride + k];
        float lz = g * a[2 * stride + k] + f * b[2 * stride + k];
        float d0 = lx * x[0] + ly * y[0] + lz * z[0], d1 = lx * x[1] + ly * y[1] + lz * z[1];
        float d2 = lx * x[2] + ly * y[2] + lz * z[2];
        float sum[3] = {0.0f, 0.0f, 0.0f};
        read_direction(p, d0, d1, d2, g * a[6 * stride + k] + f * b[6 * stride + k] + p->lod_offset, sum);
        for (int c = 0; c < 3; c++)
            acc[c] += (g * a[(3 + (size_t)c) * stride + k] + f * b[(3 + (size_t)c) * stride + k]) * sum[c];
    }
    for (int c = 0; c < 3; c++)
        rgb[c] = acc[c] * p->scale;
}

#ifdef WENV_HAVE_X86_NODES

/* ---- AVX-512: 16 nodes at a time --------------------------------------------------------------- */

#define AVX512 __attribute__((target("avx512f")))

AVX512 static inline __m512 mix16(const float *a, const float *b, size_t k, __m512 g, __m512 f)
{
    return _mm512_fmadd_ps(g, _mm512_loadu_ps(a + k), _mm512_mul_ps(f, _mm512_loadu_ps(b + k)));
}

AVX512 static inline void level_read16(const uint16_t *texels, __m512i side, __m512i base, __m512 u, __m512 v,
                                       __m512 wl, __m512 sum[3])
{
    const __m512 one = _mm512_set1_ps(1.0f), half = _mm512_set1_ps(0.5f);
    const __m512i ione = _mm512_set1_epi32(1);
    /* a texel's word holds r g (low 32 bits) and b pad: lanes 0-7 from the first 8-lane gather, 8-15
     * from the second */
    const __m512i evens = _mm512_setr_epi32(0, 2, 4, 6, 8, 10, 12, 14, 16, 18, 20, 22, 24, 26, 28, 30);
    const __m512i odds = _mm512_add_epi32(evens, ione);
    __m512 sf = _mm512_cvtepi32_ps(side);
    __m512 fx = _mm512_fmsub_ps(_mm512_mul_ps(_mm512_add_ps(u, one), half), sf, half);
    __m512 fy = _mm512_fmsub_ps(_mm512_mul_ps(_mm512_add_ps(v, one), half), sf, half);
    __m512i ix = _mm512_sub_epi32(_mm512_cvttps_epi32(_mm512_add_ps(fx, one)), ione);
    __m512i iy = _mm512_sub_epi32(_mm512_cvttps_epi32(_mm512_add_ps(fy, one)), ione);
    __m512 tx = _mm512_sub_ps(fx, _mm512_cvtepi32_ps(ix)), ty = _mm512_sub_ps(fy, _mm512_cvtepi32_ps(iy));
    __m512 wx[2] = {_mm512_sub_ps(one, tx), tx}, wy[2] = {_mm512_sub_ps(one, ty), ty};
    /* the border's columns and rows are -1 and side; +1 puts them at 0 and side + 1 */
    __m512i row = _mm512_add_epi32(side, _mm512_set1_epi32(2));
    ix = _mm512_min_epi32(_mm512_max_epi32(_mm512_add_epi32(ix, ione), _mm512_setzero_si512()), side);
    iy = _mm512_min_epi32(_mm512_max_epi32(_mm512_add_epi32(iy, ione), _mm512_setzero_si512()), side);
    __m512i at0 = _mm512_add_epi32(base, _mm512_add_epi32(_mm512_mullo_epi32(iy, row), ix));
    for (int c = 0; c < 4; c++) {
        __m512i at = (c & 1) ? _mm512_add_epi32(at0, ione) : at0;
        if (c >> 1)
            at = _mm512_add_epi32(at, row);
        __m512i lo = _mm512_i32gather_epi64(_mm512_castsi512_si256(at), texels, 8);
        __m512i hi = _mm512_i32gather_epi64(_mm512_extracti64x4_epi64(at, 1), texels, 8);
        __m512i rg = _mm512_permutex2var_epi32(lo, evens, hi), bx = _mm512_permutex2var_epi32(lo, odds, hi);
        __m512 wt = _mm512_mul_ps(wl, _mm512_mul_ps(wx[c & 1], wy[c >> 1]));
        sum[0] = _mm512_fmadd_ps(wt, _mm512_cvtph_ps(_mm512_cvtepi32_epi16(rg)), sum[0]);
        sum[1] = _mm512_fmadd_ps(wt, _mm512_cvtph_ps(_mm512_cvtepi32_epi16(_mm512_srli_epi32(rg, 16))), sum[1]);
        sum[2] = _mm512_fmadd_ps(wt, _mm512_cvtph_ps(_mm512_cvtepi32_epi16(bx)), sum[2]);
    }
}

AVX512 static void nodes_avx512(const float *a, const float *b, size_t stride, size_t n, float g, float f,
                                const float x[3], const float y[3], const float z[3], const wenv_node_pyramid *p,
                                float rgb[3])
{
    const __m512 G = _mm512_set1_ps(g), F = _mm512_set1_ps(f), one = _mm512_set1_ps(1.0f), zero = _mm512_setzero_ps();
    const __m512 top = _mm512_set1_ps((float)p->top), lod_offset = _mm512_set1_ps(p->lod_offset);
    const __m512 tiny = _mm512_set1_ps(1e-30f);
    const __m512i sides = _mm512_loadu_si512(p->side), offsets = _mm512_loadu_si512(p->offset);
    const __m512i itop = _mm512_set1_epi32(p->top), ione = _mm512_set1_epi32(1), sign = _mm512_set1_epi32(INT32_MIN);
    __m512 acc[3] = {zero, zero, zero};
    for (size_t k = 0; k < n; k += 16) {
        __m512 lx = mix16(a, b, k, G, F), ly = mix16(a + stride, b + stride, k, G, F);
        __m512 lz = mix16(a + 2 * stride, b + 2 * stride, k, G, F);
        __m512 d0 = _mm512_fmadd_ps(lx, _mm512_set1_ps(x[0]), _mm512_fmadd_ps(ly, _mm512_set1_ps(y[0]), _mm512_mul_ps(lz, _mm512_set1_ps(z[0]))));
        __m512 d1 = _mm512_fmadd_ps(lx, _mm512_set1_ps(x[1]), _mm512_fmadd_ps(ly, _mm512_set1_ps(y[1]), _mm512_mul_ps(lz, _mm512_set1_ps(z[1]))));
        __m512 d2 = _mm512_fmadd_ps(lx, _mm512_set1_ps(x[2]), _mm512_fmadd_ps(ly, _mm512_set1_ps(y[2]), _mm512_mul_ps(lz, _mm512_set1_ps(z[2]))));
        __m512 l1 = _mm512_div_ps(one, _mm512_add_ps(_mm512_add_ps(_mm512_abs_ps(d0), _mm512_abs_ps(d1)),
                                                     _mm512_add_ps(_mm512_abs_ps(d2), tiny)));
        __m512 pu = _mm512_mul_ps(d0, l1), pv = _mm512_mul_ps(d1, l1);
        /* copysign(1 - |p|, q): 1 - |p| >= 0, so q's sign bit is or-ed in */
        __m512 qu = _mm512_castsi512_ps(_mm512_or_si512(_mm512_castps_si512(_mm512_sub_ps(one, _mm512_abs_ps(pv))),
                                                        _mm512_and_si512(_mm512_castps_si512(pu), sign)));
        __m512 qv = _mm512_castsi512_ps(_mm512_or_si512(_mm512_castps_si512(_mm512_sub_ps(one, _mm512_abs_ps(pu))),
                                                        _mm512_and_si512(_mm512_castps_si512(pv), sign)));
        __mmask16 below = _mm512_cmp_ps_mask(d2, zero, _CMP_LT_OQ);
        __m512 u = _mm512_mask_blend_ps(below, pu, qu), v = _mm512_mask_blend_ps(below, pv, qv);
        __m512 lod = _mm512_add_ps(mix16(a + 6 * stride, b + 6 * stride, k, G, F), lod_offset);
        lod = _mm512_min_ps(_mm512_max_ps(lod, zero), top);
        __m512i l0 = _mm512_cvttps_epi32(lod), l1v = _mm512_min_epi32(_mm512_add_epi32(l0, ione), itop);
        __m512 fl = _mm512_sub_ps(lod, _mm512_cvtepi32_ps(l0));
        __m512 sum[3] = {zero, zero, zero};
        level_read16(p->texels, _mm512_permutexvar_epi32(l0, sides), _mm512_permutexvar_epi32(l0, offsets), u, v,
                     _mm512_sub_ps(one, fl), sum);
        level_read16(p->texels, _mm512_permutexvar_epi32(l1v, sides), _mm512_permutexvar_epi32(l1v, offsets), u, v, fl,
                     sum);
        for (int c = 0; c < 3; c++)
            acc[c] = _mm512_fmadd_ps(mix16(a + (3 + (size_t)c) * stride, b + (3 + (size_t)c) * stride, k, G, F), sum[c],
                                     acc[c]);
    }
    for (int c = 0; c < 3; c++)
        rgb[c] = _mm512_reduce_add_ps(acc[c]) * p->scale;
}

/* ---- AVX2: 8 nodes' taps at a time, then each node's reads --------------------------------------- */

#define AVX2 __attribute__((target("avx2,fma,f16c")))

AVX2 static inline __m256 mix8(const float *a, const float *b, size_t k, __m256 g, __m256 f)
{
    return _mm256_fmadd_ps(g, _mm256_loadu_ps(a + k), _mm256_mul_ps(f, _mm256_loadu_ps(b + k)));
}

AVX2 static inline __m256 abs8(__m256 x) { return _mm256_andnot_ps(_mm256_set1_ps(-0.0f), x); }

/* What one level's bilinear read needs, per node of a block of 8: its first tap's texel, the row's
 * length in texels, and the weights across (tx) and down (ty). */
typedef struct {
    int32_t at[8], row[8];
    float tx[8], ty[8];
} level_taps8;

AVX2 static inline void level_taps(__m256i side, __m256i base, __m256 u, __m256 v, level_taps8 *out)
{
    const __m256 one = _mm256_set1_ps(1.0f), half = _mm256_set1_ps(0.5f);
    const __m256i ione = _mm256_set1_epi32(1), zero = _mm256_setzero_si256();
    __m256 sf = _mm256_cvtepi32_ps(side);
    __m256 fx = _mm256_fmsub_ps(_mm256_mul_ps(_mm256_add_ps(u, one), half), sf, half);
    __m256 fy = _mm256_fmsub_ps(_mm256_mul_ps(_mm256_add_ps(v, one), half), sf, half);
    __m256i ix = _mm256_sub_epi32(_mm256_cvttps_epi32(_mm256_add_ps(fx, one)), ione);
    __m256i iy = _mm256_sub_epi32(_mm256_cvttps_epi32(_mm256_add_ps(fy, one)), ione);
    _mm256_storeu_ps(out->tx, _mm256_sub_ps(fx, _mm256_cvtepi32_ps(ix)));
    _mm256_storeu_ps(out->ty, _mm256_sub_ps(fy, _mm256_cvtepi32_ps(iy)));
    /* the border's columns and rows are -1 and side; +1 puts them at 0 and side + 1 */
    __m256i row = _mm256_add_epi32(side, _mm256_set1_epi32(2));
    ix = _mm256_min_epi32(_mm256_max_epi32(_mm256_add_epi32(ix, ione), zero), side);
    iy = _mm256_min_epi32(_mm256_max_epi32(_mm256_add_epi32(iy, ione), zero), side);
    __m256i at = _mm256_add_epi32(base, _mm256_add_epi32(_mm256_mullo_epi32(iy, row), ix));
    _mm256_storeu_si256((__m256i *)(void *)out->at, at);
    _mm256_storeu_si256((__m256i *)(void *)out->row, row);
}

/* Node k's bilinear read of one level as r g b pad: a tap and its right-hand neighbour are one
 * 128-bit load of 8 halves, so a read is two loads, lerped down then across. */
AVX2 static inline __m128 level_read1(const uint16_t *texels, const level_taps8 *t, int k)
{
    const uint16_t *t0 = texels + 4 * (size_t)t->at[k], *t1 = t0 + 4 * (size_t)t->row[k];
    __m256 top = _mm256_cvtph_ps(_mm_loadu_si128((const __m128i *)(const void *)t0));
    __m256 bottom = _mm256_cvtph_ps(_mm_loadu_si128((const __m128i *)(const void *)t1));
    __m256 down = _mm256_fmadd_ps(_mm256_set1_ps(t->ty[k]), _mm256_sub_ps(bottom, top), top);
    __m128 left = _mm256_castps256_ps128(down), right = _mm256_extractf128_ps(down, 1);
    return _mm_fmadd_ps(_mm_set1_ps(t->tx[k]), _mm_sub_ps(right, left), left);
}

/* Node k's lighting, trilinear: its two levels' reads mixed by `between` (the finer one's weight is 1
 * less it). */
AVX2 static inline __m128 node_light(const uint16_t *texels, const level_taps8 taps[2], const float *between, int k)
{
    __m128 near = level_read1(texels, &taps[0], k), far = level_read1(texels, &taps[1], k);
    return _mm_fmadd_ps(_mm_set1_ps(between[k]), _mm_sub_ps(far, near), near);
}

/* A level's side or first texel for each node's level l (0 <= l < 16): two 8-entry permutes. */
AVX2 static inline __m256i level_lookup(const int32_t *table, __m256i l)
{
    __m256i lo = _mm256_permutevar8x32_epi32(_mm256_loadu_si256((const __m256i *)(const void *)table), l);
    __m256i hi = _mm256_permutevar8x32_epi32(_mm256_loadu_si256((const __m256i *)(const void *)(table + 8)), l);
    return _mm256_blendv_epi8(lo, hi, _mm256_cmpgt_epi32(l, _mm256_set1_epi32(7)));
}

AVX2 static void nodes_avx2(const float *a, const float *b, size_t stride, size_t n, float g, float f, const float x[3],
                            const float y[3], const float z[3], const wenv_node_pyramid *p, float rgb[3])
{
    const __m256 G = _mm256_set1_ps(g), F = _mm256_set1_ps(f), one = _mm256_set1_ps(1.0f), zero = _mm256_setzero_ps();
    const __m256 top = _mm256_set1_ps((float)p->top), lod_offset = _mm256_set1_ps(p->lod_offset);
    const __m256 tiny = _mm256_set1_ps(1e-30f), sign = _mm256_set1_ps(-0.0f);
    const __m256i itop = _mm256_set1_epi32(p->top), ione = _mm256_set1_epi32(1);
    /* two sums, even and odd nodes, so that a node's fma need not wait for the one before it */
    __m128 even = _mm_setzero_ps(), odd = _mm_setzero_ps();
    for (size_t k = 0; k < n; k += 8) {
        __m256 lx = mix8(a, b, k, G, F), ly = mix8(a + stride, b + stride, k, G, F);
        __m256 lz = mix8(a + 2 * stride, b + 2 * stride, k, G, F);
        __m256 d0 = _mm256_fmadd_ps(lx, _mm256_set1_ps(x[0]), _mm256_fmadd_ps(ly, _mm256_set1_ps(y[0]), _mm256_mul_ps(lz, _mm256_set1_ps(z[0]))));
        __m256 d1 = _mm256_fmadd_ps(lx, _mm256_set1_ps(x[1]), _mm256_fmadd_ps(ly, _mm256_set1_ps(y[1]), _mm256_mul_ps(lz, _mm256_set1_ps(z[1]))));
        __m256 d2 = _mm256_fmadd_ps(lx, _mm256_set1_ps(x[2]), _mm256_fmadd_ps(ly, _mm256_set1_ps(y[2]), _mm256_mul_ps(lz, _mm256_set1_ps(z[2]))));
        __m256 l1 = _mm256_div_ps(one, _mm256_add_ps(_mm256_add_ps(abs8(d0), abs8(d1)), _mm256_add_ps(abs8(d2), tiny)));
        __m256 pu = _mm256_mul_ps(d0, l1), pv = _mm256_mul_ps(d1, l1);
        __m256 qu = _mm256_or_ps(_mm256_sub_ps(one, abs8(pv)), _mm256_and_ps(pu, sign));
        __m256 qv = _mm256_or_ps(_mm256_sub_ps(one, abs8(pu)), _mm256_and_ps(pv, sign));
        __m256 below = _mm256_cmp_ps(d2, zero, _CMP_LT_OQ);
        __m256 u = _mm256_blendv_ps(pu, qu, below), v = _mm256_blendv_ps(pv, qv, below);
        __m256 lod = _mm256_add_ps(mix8(a + 6 * stride, b + 6 * stride, k, G, F), lod_offset);
        lod = _mm256_min_ps(_mm256_max_ps(lod, zero), top);
        __m256i l0 = _mm256_cvttps_epi32(lod), l1v = _mm256_min_epi32(_mm256_add_epi32(l0, ione), itop);
        __m256 fl = _mm256_sub_ps(lod, _mm256_cvtepi32_ps(l0));
        level_taps8 taps[2];
        level_taps(level_lookup(p->side, l0), level_lookup(p->offset, l0), u, v, &taps[0]);
        level_taps(level_lookup(p->side, l1v), level_lookup(p->offset, l1v), u, v, &taps[1]);
        float between[8], weight[8][4];
        _mm256_storeu_ps(between, fl);
        /* each node's r g b weights side by side, its pad's weight 0 */
        __m256 wr = mix8(a + 3 * stride, b + 3 * stride, k, G, F), wg = mix8(a + 4 * stride, b + 4 * stride, k, G, F);
        __m256 wb = mix8(a + 5 * stride, b + 5 * stride, k, G, F);
        __m256 rg_lo = _mm256_unpacklo_ps(wr, wg), rg_hi = _mm256_unpackhi_ps(wr, wg);
        __m256 b0_lo = _mm256_unpacklo_ps(wb, zero), b0_hi = _mm256_unpackhi_ps(wb, zero);
        __m256 n0 = _mm256_shuffle_ps(rg_lo, b0_lo, _MM_SHUFFLE(1, 0, 1, 0)); /* nodes 0 | 4 */
        __m256 n1 = _mm256_shuffle_ps(rg_lo, b0_lo, _MM_SHUFFLE(3, 2, 3, 2)); /* nodes 1 | 5 */
        __m256 n2 = _mm256_shuffle_ps(rg_hi, b0_hi, _MM_SHUFFLE(1, 0, 1, 0)); /* nodes 2 | 6 */
        __m256 n3 = _mm256_shuffle_ps(rg_hi, b0_hi, _MM_SHUFFLE(3, 2, 3, 2)); /* nodes 3 | 7 */
        _mm_storeu_ps(weight[0], _mm256_castps256_ps128(n0));
        _mm_storeu_ps(weight[4], _mm256_extractf128_ps(n0, 1));
        _mm_storeu_ps(weight[1], _mm256_castps256_ps128(n1));
        _mm_storeu_ps(weight[5], _mm256_extractf128_ps(n1, 1));
        _mm_storeu_ps(weight[2], _mm256_castps256_ps128(n2));
        _mm_storeu_ps(weight[6], _mm256_extractf128_ps(n2, 1));
        _mm_storeu_ps(weight[3], _mm256_castps256_ps128(n3));
        _mm_storeu_ps(weight[7], _mm256_extractf128_ps(n3, 1));
        for (int j = 0; j < 8; j += 2) {
            even = _mm_fmadd_ps(_mm_loadu_ps(weight[j]), node_light(p->texels, taps, between, j), even);
            odd = _mm_fmadd_ps(_mm_loadu_ps(weight[j + 1]), node_light(p->texels, taps, between, j + 1), odd);
        }
    }
    float out[4];
    _mm_storeu_ps(out, _mm_add_ps(even, odd));
    for (int c = 0; c < 3; c++)
        rgb[c] = out[c] * p->scale;
}

#endif /* WENV_HAVE_X86_NODES */

wenv_grazing_nodes_fn wenv_grazing_nodes_version(int which)
{
#ifdef WENV_HAVE_X86_NODES
    __builtin_cpu_init();
    if (which == 2)
        return __builtin_cpu_supports("avx512f") ? nodes_avx512 : NULL;
    if (which == 1)
        /* F16C came before AVX2 (Ivy Bridge, Piledriver): every AVX2 CPU has it, and clang's
         * __builtin_cpu_supports does not know its name */
        return __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma") ? nodes_avx2 : NULL;
#endif
    return which == 0 ? wenv_grazing_nodes_portable : NULL;
}

wenv_grazing_nodes_fn wenv_grazing_nodes_for_cpu(void)
{
    for (int which = 2; which > 0; which--) {
        wenv_grazing_nodes_fn fn = wenv_grazing_nodes_version(which);
        if (fn)
            return fn;
    }
    return wenv_grazing_nodes_portable;
}
