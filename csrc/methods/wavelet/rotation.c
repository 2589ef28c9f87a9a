#include "methods/wavelet/rotation.h"

#include <math.h>
#include <omp.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>

#include "math/haar.h"
#include "math/maps.h"

void wenv_normal_sample(size_t normal_n, size_t s, double n[3])
{
    wenv_oct_decode(wenv_map_texel_center(normal_n, s % normal_n), wenv_map_texel_center(normal_n, s / normal_n), n);
}

struct wenv_resampler {
    size_t global_n, local_n, k;
    float *sub_dirs;    /* N_global * k * k * 3 */
    double *sub_omega;  /* N_global: solid angle of one sub-sample of each texel */
    float *cone;        /* N_global * 4: a unit axis and the sine of the angle holding its sub-samples */
};

wenv_status wenv_resampler_create(wenv_resampler **out, size_t global_n, size_t local_n, wenv_error *err)
{
    *out = NULL;
    wenv_resampler *rs = calloc(1, sizeof *rs);
    if (!rs)
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for the resampler");
    /* Sub-samples no farther apart than half a local texel, so every local tent sees many. */
    double ratio = 2.83 * (double)local_n / (double)global_n;
    size_t k = (size_t)ceil(ratio);
    rs->k = k < 2 ? 2 : k;
    rs->global_n = global_n;
    rs->local_n = local_n;
    size_t ng = global_n * global_n, kk = rs->k * rs->k;
    rs->sub_dirs = malloc(ng * kk * 3 * sizeof(float));
    rs->sub_omega = malloc(ng * sizeof(double));
    rs->cone = malloc(ng * 4 * sizeof(float));
    if (!rs->sub_dirs || !rs->sub_omega || !rs->cone) {
        wenv_resampler_free(rs);
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for the resampler");
    }
    double kn = (double)(rs->k * global_n);
    for (size_t u = 0; u < ng; u++) {
        size_t i = u % global_n, j = u / global_n;
        rs->sub_omega[u] = wenv_oct_texel_solid_angle(global_n, i, j) / (double)kk;
        for (size_t q = 0; q < kk; q++) {
            /* as texel centres (maps.c): mirrored sub-samples mirror exactly */
            double su = (2.0 * (double)(i * rs->k + q % rs->k) + 1.0 - kn) / kn;
            double sv = (2.0 * (double)(j * rs->k + q / rs->k) + 1.0 - kn) / kn;
            double d[3];
            wenv_oct_decode(su, sv, d);
            float *o = rs->sub_dirs + (u * kk + q) * 3;
            o[0] = (float)d[0];
            o[1] = (float)d[1];
            o[2] = (float)d[2];
        }
        /* the texel's cone: its centre, and the widest angle to a sub-sample (a hair more) */
        double c[3], r = 0.0;
        wenv_oct_decode(wenv_map_texel_center(global_n, i), wenv_map_texel_center(global_n, j), c);
        for (size_t q = 0; q < kk; q++) {
            const float *o = rs->sub_dirs + (u * kk + q) * 3;
            double dot = c[0] * o[0] + c[1] * o[1] + c[2] * o[2];
            r = fmax(r, acos(fmax(-1.0, fmin(1.0, dot))));
        }
        float *cone = rs->cone + 4 * u;
        for (int q = 0; q < 3; q++)
            cone[q] = (float)c[q];
        cone[3] = (float)sin(fmin(0.5 * M_PI, r + 1e-4));
    }
    *out = rs;
    return WENV_OK;
}

void wenv_resampler_free(wenv_resampler *rs)
{
    if (!rs)
        return;
    free(rs->sub_dirs);
    free(rs->sub_omega);
    free(rs->cone);
    free(rs);
}

size_t wenv_resampler_global_n(const wenv_resampler *rs) { return rs->global_n; }
size_t wenv_resampler_local_n(const wenv_resampler *rs) { return rs->local_n; }
size_t wenv_resampler_max_taps(const wenv_resampler *rs) { return 4 * rs->k * rs->k; }

size_t wenv_resampler_texel_taps(const wenv_resampler *rs, const double f[9], size_t u, uint32_t *tap_t,
                                 double *tap_w)
{
    size_t kk = rs->k * rs->k, count = 0;
    const float *d = rs->sub_dirs + u * kk * 3, *cone = rs->cone + 4 * u;
    float ff[9];
    for (int c = 0; c < 9; c++)
        ff[c] = (float)f[c];
    /* a texel wholly below the frame's horizon gives nothing: half of them, skipped whole */
    if (ff[6] * cone[0] + ff[7] * cone[1] + ff[8] * cone[2] < -cone[3])
        return 0;
    for (size_t q = 0; q < kk; q++, d += 3) {
        float loc[3] = {ff[0] * d[0] + ff[1] * d[1] + ff[2] * d[2], ff[3] * d[0] + ff[4] * d[1] + ff[5] * d[2],
                        ff[6] * d[0] + ff[7] * d[1] + ff[8] * d[2]};
        if (loc[2] < 0.0f)
            continue;
        float lu, lv, w[4];
        uint32_t idx[4];
        wenv_hemi_encode_f(loc, &lu, &lv);
        wenv_hemi_bilinear_f((long)rs->local_n, lu, lv, idx, w);
        for (int c = 0; c < 4; c++) {
            if (w[c] <= 0.0f)
                continue;
            tap_t[count] = idx[c];
            tap_w[count++] = (double)w[c] * rs->sub_omega[u];
        }
    }
    return count;
}

/* ---- building R_s ---------------------------------------------------------------------------- */

typedef struct {
    uint32_t *u, *j;
    float *v;
    size_t count, cap;
} triplets;

/* `p` reallocated to n items of `size` bytes; on failure `p` unchanged (still owned) and *failed set,
 * so that several arrays grow together and a failure frees nothing twice. */
static void *grown(void *p, size_t n, size_t size, int *failed)
{
    void *q = realloc(p, n * size);
    if (!q)
        *failed = 1;
    return q ? q : p;
}

static int triplets_push(triplets *tr, uint32_t u, uint32_t j, float v)
{
    if (tr->count == tr->cap) {
        size_t cap = tr->cap ? 2 * tr->cap : 4096;
        int failed = 0;
        tr->u = grown(tr->u, cap, sizeof *tr->u, &failed);
        tr->j = grown(tr->j, cap, sizeof *tr->j, &failed);
        tr->v = grown(tr->v, cap, sizeof *tr->v, &failed);
        if (failed)
            return -1;
        tr->cap = cap;
    }
    tr->u[tr->count] = u;
    tr->j[tr->count] = j;
    tr->v[tr->count++] = v;
    return 0;
}

static void triplets_free(triplets *tr)
{
    free(tr->u);
    free(tr->j);
    free(tr->v);
    memset(tr, 0, sizeof *tr);
}

typedef struct {
    double *rowsum;     /* N_local */
    uint32_t *tap_t;    /* N_global * 4k^2 */
    double *tap_w;
    size_t *tap_start;  /* N_global + 1 */
    float *acc;         /* N_local, then N_global: a column's sums */
    uint32_t *touched;  /* N_local, then N_global: where acc is non-zero */
    unsigned char *mark;/* N_local, then N_global */
    triplets p, out;
    size_t *col_start;  /* N_local + 1: P's entries of each local coefficient */
    uint32_t *col_u;    /* P's entries grouped by local coefficient: global texel, value */
    float *col_v;
    size_t col_room;
    /* the Haar transform of a unit impulse at each texel of the local and of the global map (3 log2 n
     * + 1 terms each), made once: the build reads them a few hundred million times */
    size_t local_per, global_per;
    uint32_t *local_idx, *global_idx;
    float *local_val, *global_val;
} build_ws;

static void ws_free(build_ws *ws)
{
    free(ws->rowsum);
    free(ws->tap_t);
    free(ws->tap_w);
    free(ws->tap_start);
    free(ws->acc);
    free(ws->touched);
    free(ws->mark);
    triplets_free(&ws->p);
    triplets_free(&ws->out);
    free(ws->col_start);
    free(ws->col_u);
    free(ws->col_v);
    free(ws->local_idx);
    free(ws->local_val);
    free(ws->global_idx);
    free(ws->global_val);
}

/* Every texel's impulse response on an n x n map: per terms each, into *idx and *val. */
static int make_impulses(size_t n, size_t *per, uint32_t **idx, float **val)
{
    size_t idx_one[64];
    float val_one[64];
    *per = wenv_haar2d_impulse(n, 0, 0, idx_one, val_one);
    *idx = malloc(n * n * *per * sizeof **idx);
    *val = malloc(n * n * *per * sizeof **val);
    if (!*idx || !*val)
        return -1;
    for (size_t t = 0; t < n * n; t++) {
        wenv_haar2d_impulse(n, t % n, t / n, idx_one, val_one);
        for (size_t e = 0; e < *per; e++) {
            (*idx)[t * *per + e] = (uint32_t)idx_one[e];
            (*val)[t * *per + e] = val_one[e];
        }
    }
    return 0;
}

static int ws_alloc(build_ws *ws, const wenv_resampler *rs)
{
    size_t nl = rs->local_n * rs->local_n, ng = rs->global_n * rs->global_n, kk4 = 4 * rs->k * rs->k;
    size_t most = nl > ng ? nl : ng;
    memset(ws, 0, sizeof *ws);
    ws->rowsum = malloc(nl * sizeof(double));
    ws->tap_t = malloc(ng * kk4 * sizeof(uint32_t));
    ws->tap_w = malloc(ng * kk4 * sizeof(double));
    ws->tap_start = malloc((ng + 1) * sizeof(size_t));
    ws->acc = calloc(most, sizeof(float));
    ws->touched = malloc(most * sizeof(uint32_t));
    ws->mark = calloc(most, 1);
    ws->col_start = malloc((nl + 1) * sizeof(size_t));
    if (make_impulses(rs->local_n, &ws->local_per, &ws->local_idx, &ws->local_val) ||
        make_impulses(rs->global_n, &ws->global_per, &ws->global_idx, &ws->global_val))
        return -1;
    return ws->rowsum && ws->tap_t && ws->tap_w && ws->tap_start && ws->acc && ws->touched && ws->mark &&
                   ws->col_start
               ? 0
               : -1;
}

/* Adds w x the impulse response `per` terms at idx, val into ws->acc, noting the coefficients it
 * reaches first in ws->touched; returns the new count of those. */
static size_t add_impulse(build_ws *ws, const uint32_t *idx, const float *val, size_t per, float w, size_t ntouched)
{
    for (size_t e = 0; e < per; e++) {
        uint32_t jj = idx[e];
        if (!ws->mark[jj]) {
            ws->mark[jj] = 1;
            ws->touched[ntouched++] = jj;
        }
        ws->acc[jj] += w * val[e];
    }
    return ntouched;
}

/* P's entries (global texel u, local coefficient j, value) grouped by j, in u order within each. */
static int group_by_local(build_ws *ws, size_t nl)
{
    size_t np = ws->p.count;
    if (np > ws->col_room) {
        int failed = 0;
        ws->col_u = grown(ws->col_u, np, sizeof *ws->col_u, &failed);
        ws->col_v = grown(ws->col_v, np, sizeof *ws->col_v, &failed);
        if (failed)
            return -1;
        ws->col_room = np;
    }
    memset(ws->col_start, 0, (nl + 1) * sizeof(size_t));
    for (size_t e = 0; e < np; e++)
        ws->col_start[ws->p.j[e] + 1]++;
    for (size_t j = 0; j < nl; j++)
        ws->col_start[j + 1] += ws->col_start[j];
    for (size_t e = 0; e < np; e++) {
        size_t at = ws->col_start[ws->p.j[e]]++;
        ws->col_u[at] = ws->p.u[e];
        ws->col_v[at] = ws->p.v[e];
    }
    /* filling moved each start to where the next one begins: shift back */
    for (size_t j = nl; j > 0; j--)
        ws->col_start[j] = ws->col_start[j - 1];
    ws->col_start[0] = 0;
    return 0;
}

/* R_s = H_local S_s H_global^T, computed as (H_local S_s) first (sparse: each global texel touches
 * a few local texels, whose Haar transforms are impulse responses), then the global transform of
 * each of its columns the same way: a column holds the few global texels that reach one local
 * coefficient, and their impulse responses (3 log2 G + 1 terms each) cost far less than
 * transforming the dense N_global x N_local block (the thesis's largest set: 45 s -> X s). */
static int build_matrix(const wenv_resampler *rs, const double f[9], double threshold, build_ws *ws, wenv_csc *m)
{
    size_t nl = rs->local_n * rs->local_n, ng = rs->global_n * rs->global_n;
    size_t kk4 = 4 * rs->k * rs->k;
    memset(ws->rowsum, 0, nl * sizeof(double));
    for (size_t u = 0; u < ng; u++) {
        size_t c = wenv_resampler_texel_taps(rs, f, u, ws->tap_t + u * kk4, ws->tap_w + u * kk4);
        ws->tap_start[u] = c; /* count for now */
        for (size_t q = 0; q < c; q++)
            ws->rowsum[ws->tap_t[u * kk4 + q]] += ws->tap_w[u * kk4 + q];
    }
    ws->p.count = 0;
    for (size_t u = 0; u < ng; u++) {
        size_t ntouched = 0;
        for (size_t q = 0; q < ws->tap_start[u]; q++) {
            uint32_t t = ws->tap_t[u * kk4 + q];
            ntouched = add_impulse(ws, ws->local_idx + t * ws->local_per, ws->local_val + t * ws->local_per,
                                   ws->local_per, (float)(ws->tap_w[u * kk4 + q] / ws->rowsum[t]), ntouched);
        }
        for (size_t e = 0; e < ntouched; e++) {
            uint32_t jj = ws->touched[e];
            if (triplets_push(&ws->p, (uint32_t)u, jj, ws->acc[jj]) < 0)
                return -1;
            ws->acc[jj] = 0.0f;
            ws->mark[jj] = 0;
        }
    }
    if (group_by_local(ws, nl) < 0)
        return -1;
    ws->out.count = 0;
    for (size_t jj = 0; jj < nl; jj++) {
        size_t ntouched = 0;
        for (size_t e = ws->col_start[jj]; e < ws->col_start[jj + 1]; e++)
            ntouched = add_impulse(ws, ws->global_idx + (size_t)ws->col_u[e] * ws->global_per,
                                   ws->global_val + (size_t)ws->col_u[e] * ws->global_per, ws->global_per,
                                   ws->col_v[e], ntouched);
        for (size_t e = 0; e < ntouched; e++) {
            uint32_t g = ws->touched[e];
            if (fabsf(ws->acc[g]) > threshold && triplets_push(&ws->out, g, (uint32_t)jj, ws->acc[g]) < 0)
                return -1;
            ws->acc[g] = 0.0f;
            ws->mark[g] = 0;
        }
    }
    /* counting sort by global coefficient: within a column, rows stay ascending */
    size_t nnz = ws->out.count;
    m->rows = nl;
    m->cols = ng;
    m->colptr = calloc(ng + 1, sizeof(size_t));
    m->rowidx = malloc((nnz ? nnz : 1) * sizeof(uint16_t));
    m->val = malloc((nnz ? nnz : 1) * sizeof(float));
    if (!m->colptr || !m->rowidx || !m->val)
        return -1;
    for (size_t e = 0; e < nnz; e++)
        m->colptr[ws->out.u[e] + 1]++;
    for (size_t u = 0; u < ng; u++)
        m->colptr[u + 1] += m->colptr[u];
    size_t *fill = ws->tap_start; /* reuse: N_global + 1 entries */
    memcpy(fill, m->colptr, (ng + 1) * sizeof(size_t));
    for (size_t e = 0; e < nnz; e++) {
        size_t pos = fill[ws->out.u[e]]++;
        m->rowidx[pos] = (uint16_t)ws->out.j[e];
        m->val[pos] = ws->out.v[e];
    }
    return 0;
}

wenv_status wenv_rotation_check_sizes(size_t global_n, size_t local_n, size_t normal_n, wenv_error *err)
{
    if (!wenv_is_power_of_two(global_n) || global_n < 4 || global_n > 512)
        return wenv_error_set(err, WENV_ERR_VALUE, "global map size must be a power of two in [4, 512], got %zu", global_n);
    if (!wenv_is_power_of_two(local_n) || local_n < 4 || local_n > 256)
        return wenv_error_set(err, WENV_ERR_VALUE, "local map size must be a power of two in [4, 256], got %zu", local_n);
    if (normal_n < 2 || normal_n > 512 || normal_n % 2)
        return wenv_error_set(err, WENV_ERR_VALUE, "normal sample grid must be even in [2, 512], got %zu", normal_n);
    return WENV_OK;
}

static double build_threshold(size_t global_n, size_t local_n, double epsilon)
{
    return epsilon * sqrt((double)(local_n * local_n) / (double)(global_n * global_n));
}

size_t wenv_rotation_bytes(size_t global_n, size_t normal_n, size_t nnz)
{
    size_t ns = normal_n * normal_n;
    return nnz * (sizeof(uint16_t) + sizeof(float)) + ns * (global_n * global_n + 1) * sizeof(size_t) +
           ns * sizeof(wenv_csc);
}

#define ESTIMATE_SAMPLES 4

/* The sizes and epsilon checked, and the resampler both the build and its estimate use. */
static wenv_status check_and_resample(size_t global_n, size_t local_n, size_t normal_n, double epsilon,
                                      wenv_resampler **rs, wenv_error *err)
{
    if (wenv_rotation_check_sizes(global_n, local_n, normal_n, err))
        return err->status;
    if (!(epsilon >= 0.0 && epsilon < 1.0))
        return wenv_error_set(err, WENV_ERR_VALUE, "matrix epsilon must be in [0, 1), got %g", epsilon);
    return wenv_resampler_create(rs, global_n, local_n, err);
}

wenv_status wenv_rotation_estimate_bytes(size_t global_n, size_t local_n, size_t normal_n, double epsilon,
                                         size_t *bytes, wenv_error *err)
{
    *bytes = 0;
    wenv_resampler *rs = NULL;
    if (check_and_resample(global_n, local_n, normal_n, epsilon, &rs, err))
        return err->status;
    size_t ns = normal_n * normal_n, samples = 0, nnz = 0;
    size_t want = ns < ESTIMATE_SAMPLES ? ns : ESTIMATE_SAMPLES;
    build_ws ws;
    int failed = ws_alloc(&ws, rs) < 0;
    for (size_t k = 0; k < want && !failed; k++) {
        double n[3], f[9];
        wenv_csc m = {0};
        wenv_normal_sample(normal_n, (2 * k + 1) * ns / (2 * want), n);
        wenv_frame(n, f);
        failed = build_matrix(rs, f, build_threshold(global_n, local_n, epsilon), &ws, &m) < 0;
        nnz += wenv_csc_nnz(&m);
        samples++;
        wenv_csc_free(&m);
    }
    ws_free(&ws);
    wenv_resampler_free(rs);
    if (failed)
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory estimating the rotation matrices' size");
    *bytes = wenv_rotation_bytes(global_n, normal_n, (size_t)((double)nnz / (double)samples * (double)ns));
    return WENV_OK;
}

wenv_status wenv_rotation_build(wenv_rotation **out, size_t global_n, size_t local_n, size_t normal_n,
                                double epsilon, const wenv_progress *progress, wenv_error *err)
{
    *out = NULL;
    wenv_resampler *rs = NULL;
    if (check_and_resample(global_n, local_n, normal_n, epsilon, &rs, err))
        return err->status;
    size_t ns = normal_n * normal_n;
    wenv_rotation *rot = calloc(1, sizeof *rot);
    wenv_csc *mats = rot ? calloc(ns, sizeof *mats) : NULL;
    if (!rot || !mats) {
        free(rot);
        wenv_resampler_free(rs);
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for %zu rotation matrices", ns);
    }
    rot->global_n = global_n;
    rot->local_n = local_n;
    rot->normal_n = normal_n;
    rot->epsilon = epsilon;
    rot->matrices = mats;
    double threshold = build_threshold(global_n, local_n, epsilon);

    atomic_int failed = 0, cancelled = 0;
    atomic_size_t done = 0;
#pragma omp parallel
    {
        build_ws ws;
        if (ws_alloc(&ws, rs) < 0)
            atomic_store(&failed, 1);
#pragma omp for schedule(dynamic, 1)
        for (size_t s = 0; s < ns; s++) {
            if (atomic_load(&failed) || atomic_load(&cancelled))
                continue;
            double n[3], f[9];
            wenv_normal_sample(normal_n, s, n);
            wenv_frame(n, f);
            if (build_matrix(rs, f, threshold, &ws, &mats[s]) < 0)
                atomic_store(&failed, 1);
            wenv_progress_item(progress, &done, ns, &cancelled);
        }
        ws_free(&ws);
    }
    wenv_resampler_free(rs);
    if (!failed && !cancelled && wenv_progress_finish(progress))
        cancelled = 1;
    if (failed || cancelled) {
        wenv_rotation_free(rot);
        if (cancelled)
            return wenv_error_set(err, WENV_ERR_CANCELLED, "rotation matrix precomputation cancelled");
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory building rotation matrices");
    }
    *out = rot;
    return WENV_OK;
}

void wenv_rotation_free(wenv_rotation *rot)
{
    if (!rot)
        return;
    if (rot->matrices) {
        size_t ns = rot->normal_n * rot->normal_n;
        for (size_t s = 0; s < ns; s++)
            wenv_csc_free(&rot->matrices[s]);
        free(rot->matrices);
    }
    free(rot);
}

size_t wenv_rotation_nnz(const wenv_rotation *rot)
{
    size_t total = 0, ns = rot->normal_n * rot->normal_n;
    for (size_t s = 0; s < ns; s++)
        total += wenv_csc_nnz(&rot->matrices[s]);
    return total;
}

void wenv_rotation_apply(const wenv_rotation *rot, size_t s, const uint32_t *idx, const float *rgb,
                         size_t count, float *local)
{
    const wenv_csc *m = &rot->matrices[s];
    memset(local, 0, m->rows * 3 * sizeof(float));
    for (size_t e = 0; e < count; e++) {
        size_t col = idx[e];
        float r = rgb[3 * e], g = rgb[3 * e + 1], b = rgb[3 * e + 2];
        for (size_t p = m->colptr[col]; p < m->colptr[col + 1]; p++) {
            float v = m->val[p];
            float *l = local + 3 * (size_t)m->rowidx[p];
            l[0] += v * r;
            l[1] += v * g;
            l[2] += v * b;
        }
    }
}
