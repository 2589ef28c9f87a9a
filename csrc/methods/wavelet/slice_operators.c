#include "methods/wavelet/slice_operators.h"

#include <math.h>
#include <omp.h>
#include <stdatomic.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "math/maps.h"

/* The symmetries of the square about z: g = 4 swap + 2 (x mirrored) + (y mirrored), applied as
 * x' = sx (swap ? y : x), y' = sy (swap ? x : y), z' = z.  g = 0 is the identity. */
#define SYMMETRIES 8

static void symmetry_matrix(int g, double m[9])
{
    int swap = g >> 2;
    memset(m, 0, 9 * sizeof(double));
    m[swap ? 1 : 0] = (g & 2) ? -1.0 : 1.0;
    m[swap ? 3 : 4] = (g & 1) ? -1.0 : 1.0;
    m[8] = 1.0;
}

static void times(const double m[9], const double d[3], double o[3])
{
    for (int r = 0; r < 3; r++)
        o[r] = m[3 * r] * d[0] + m[3 * r + 1] * d[1] + m[3 * r + 2] * d[2];
}

static void transpose_times(const double m[9], const double d[3], double o[3])
{
    for (int r = 0; r < 3; r++)
        o[r] = m[r] * d[0] + m[3 + r] * d[1] + m[6 + r] * d[2];
}

/* The texel of an n x n map centred at (u, v); SIZE_MAX when (u, v) is no texel's centre. */
static size_t centre_texel(size_t n, double u, double v)
{
    double x = (u + 1.0) * 0.5 * (double)n - 0.5, y = (v + 1.0) * 0.5 * (double)n - 0.5;
    double i = nearbyint(x), j = nearbyint(y);
    if (fabs(x - i) > 1e-6 || fabs(y - j) > 1e-6 || i < 0.0 || j < 0.0 || i >= (double)n || j >= (double)n)
        return SIZE_MAX;
    return (size_t)j * n + (size_t)i;
}

/* An operator by local texel (a gather): each local texel's sum is made in registers and stored
 * once, where splatting by global texel stored every tap (twice as slow). */
typedef struct {
    uint32_t *start;    /* nl + 1: local texel t's taps are start[t] .. start[t + 1] - 1 */
    uint32_t *texel;    /* each tap's global texel, ascending within a local texel; or NULL and */
    uint16_t *texel16;  /* the same in 16 bits, kept so when the global map has at most 2^16 texels */
    float *weight;      /* each tap's weight, a local texel's summing to one */
    size_t n_taps;
} slice_operator;

static inline size_t tap_texel(const slice_operator *op, size_t q) { return op->texel16 ? op->texel16[q] : op->texel[q]; }

/* The resampler's taps as they are made, by global texel (the scatter the gather is sorted from). */
typedef struct {
    uint32_t *texel;  /* global texels with taps, ascending */
    uint32_t *count;  /* how many taps each has */
    uint16_t *local;  /* each tap's local texel */
    double *raw;      /* each tap's weight, before its local texel's row is normalised */
    size_t n_texels, n_taps;
} scatter_taps;

struct wenv_slice_operators {
    const wenv_resampler *rs;
    size_t normal_n, ns, ng, nl, max_taps, budget;
    size_t *orbit;                     /* ns: the sample whose operator serves s (s itself for those) */
    unsigned char *global_of, *local_of; /* ns: the symmetry each map is read through */
    uint32_t *global_perm[SYMMETRIES]; /* ng each: the texel of G read as texel u (identity at 0) */
    uint16_t *local_perm[SYMMETRIES];  /* nl each: where the operator's local texel t goes */
    slice_operator **kept;             /* ns, set at orbit representatives once made */
    atomic_size_t bytes;
};

typedef float rgbx __attribute__((vector_size(4 * sizeof(float))));

struct wenv_slice_work {
    uint32_t *tap_t;  /* max_taps */
    double *tap_w;
    double *rowsum;   /* nl */
    int32_t *slot;    /* nl: a local texel's tap among the current global texel's, or -1 */
    scatter_taps scatter;
    slice_operator op; /* an operator made here: kept ones are copied out of it */
    size_t room_texels, room_taps;
};

static void operator_free(slice_operator *op)
{
    if (!op)
        return;
    free(op->start);
    free(op->texel);
    free(op->texel16);
    free(op->weight);
}

static size_t operator_bytes(const slice_operator *op, size_t nl)
{
    size_t index = op->texel16 ? sizeof(uint16_t) : sizeof(uint32_t);
    return sizeof *op + (nl + 1) * sizeof(uint32_t) + op->n_taps * (index + sizeof(float));
}

void wenv_slice_operators_free(wenv_slice_operators *ops)
{
    if (!ops)
        return;
    if (ops->kept)
        for (size_t s = 0; s < ops->ns; s++)
            if (ops->kept[s]) {
                operator_free(ops->kept[s]);
                free(ops->kept[s]);
            }
    free(ops->kept);
    free(ops->orbit);
    free(ops->global_of);
    free(ops->local_of);
    for (int g = 0; g < SYMMETRIES; g++) {
        free(ops->global_perm[g]);
        free(ops->local_perm[g]);
    }
    free(ops);
}

/* The texel of an n x n octahedral (or hemi-octahedral) map whose centre is m (or m^T) times texel
 * t's centre direction; SIZE_MAX when that is no texel's centre. */
static size_t texel_image(size_t n, int hemi, const double m[9], int transpose, size_t t)
{
    double d[3], e[3], u = wenv_map_texel_center(n, t % n), v = wenv_map_texel_center(n, t / n);
    if (hemi)
        wenv_hemi_decode(u, v, d);
    else
        wenv_oct_decode(u, v, d);
    if (transpose)
        transpose_times(m, d, e);
    else
        times(m, d, e);
    if (hemi)
        wenv_hemi_encode(e, &u, &v);
    else
        wenv_oct_encode(e, &u, &v);
    return centre_texel(n, u, v);
}

/* Texel permutations of symmetry g on both maps; 0 when g does not map texel centres onto texel
 * centres (then no sample uses it). */
static int make_permutations(wenv_slice_operators *ops, int g)
{
    double m[9];
    symmetry_matrix(g, m);
    size_t gn = wenv_resampler_global_n(ops->rs), ln = wenv_resampler_local_n(ops->rs);
    for (size_t t = 0; t < ops->ng; t++) {
        size_t to = texel_image(gn, 0, m, 1, t);
        if (to == SIZE_MAX)
            return 0;
        ops->global_perm[g][t] = (uint32_t)to;
    }
    for (size_t t = 0; t < ops->nl; t++) {
        size_t to = texel_image(ln, 1, m, 0, t);
        if (to == SIZE_MAX)
            return 0;
        ops->local_perm[g][t] = (uint16_t)to;
    }
    return 1;
}

/* Sample s's orbit representative (the least index M n_s takes), the symmetry M that takes s there,
 * and P = F_s M^T F_c^T, the signed permutation of tangents that relates the two frames. */
static void find_orbit(wenv_slice_operators *ops, const int usable[SYMMETRIES], size_t s)
{
    double m[9];
    size_t best = s;
    int best_g = 0;
    for (int g = 0; g < SYMMETRIES; g++) {
        if (!usable[g])
            continue;
        symmetry_matrix(g, m);
        size_t to = texel_image(ops->normal_n, 0, m, 0, s); /* normal samples are texel centres */
        if (to < best) {
            best = to;
            best_g = g;
        }
    }
    ops->orbit[s] = s;
    ops->global_of[s] = ops->local_of[s] = 0;
    if (best == s)
        return;
    double n[3], e[3], fs[9], fc[9], nc[3], p[9];
    symmetry_matrix(best_g, m);
    wenv_normal_sample(ops->normal_n, s, n);
    wenv_frame(n, fs);
    wenv_normal_sample(ops->normal_n, best, nc);
    wenv_frame(nc, fc);
    /* p = fs m^T fc^T, column by column: p e_k = fs m^T (row k of fc) */
    for (int k = 0; k < 3; k++) {
        double a[3];
        transpose_times(m, fc + 3 * k, a);
        times(fs, a, e);
        for (int r = 0; r < 3; r++)
            p[3 * r + k] = e[r];
    }
    for (int g = 0; g < SYMMETRIES; g++) {
        double q[9];
        symmetry_matrix(g, q);
        double off = 0.0;
        for (int k = 0; k < 9; k++)
            off = fmax(off, fabs(p[k] - q[k]));
        if (usable[g] && off < 1e-9) {
            ops->orbit[s] = best;
            ops->global_of[s] = (unsigned char)best_g;
            ops->local_of[s] = (unsigned char)g;
            return;
        }
    }
}

wenv_status wenv_slice_operators_create(wenv_slice_operators **out, const wenv_resampler *rs, size_t normal_n,
                                        size_t byte_budget, wenv_error *err)
{
    *out = NULL;
    wenv_slice_operators *ops = calloc(1, sizeof *ops);
    if (!ops)
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for the slices' operators");
    size_t gn = wenv_resampler_global_n(rs), ln = wenv_resampler_local_n(rs);
    ops->rs = rs;
    ops->normal_n = normal_n;
    ops->ns = normal_n * normal_n;
    ops->ng = gn * gn;
    ops->nl = ln * ln;
    ops->max_taps = wenv_resampler_max_taps(rs);
    ops->budget = byte_budget;
    atomic_init(&ops->bytes, 0);
    ops->orbit = malloc(ops->ns * sizeof(size_t));
    ops->global_of = malloc(ops->ns);
    ops->local_of = malloc(ops->ns);
    ops->kept = calloc(ops->ns, sizeof(slice_operator *));
    int ok = ops->orbit && ops->global_of && ops->local_of && ops->kept;
    for (int g = 0; g < SYMMETRIES && ok; g++) {
        ops->global_perm[g] = malloc(ops->ng * sizeof(uint32_t));
        ops->local_perm[g] = malloc(ops->nl * sizeof(uint16_t));
        ok = ops->global_perm[g] && ops->local_perm[g];
    }
    if (!ok) {
        wenv_slice_operators_free(ops);
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for the slices' operators");
    }
    int usable[SYMMETRIES] = {1};
    for (size_t t = 0; t < ops->ng; t++)
        ops->global_perm[0][t] = (uint32_t)t;
    for (size_t t = 0; t < ops->nl; t++)
        ops->local_perm[0][t] = (uint16_t)t;
    for (int g = 1; g < SYMMETRIES; g++)
        usable[g] = make_permutations(ops, g);
    for (size_t s = 0; s < ops->ns; s++)
        find_orbit(ops, usable, s);
    *out = ops;
    return WENV_OK;
}

wenv_slice_work *wenv_slice_work_new(const wenv_slice_operators *ops)
{
    wenv_slice_work *w = calloc(1, sizeof *w);
    if (!w)
        return NULL;
    w->tap_t = malloc(ops->max_taps * sizeof(uint32_t));
    w->tap_w = malloc(ops->max_taps * sizeof(double));
    w->rowsum = malloc(ops->nl * sizeof(double));
    w->slot = malloc(ops->nl * sizeof(int32_t));
    w->op.start = malloc((ops->nl + 1) * sizeof(uint32_t));
    if (!w->tap_t || !w->tap_w || !w->rowsum || !w->slot || !w->op.start) {
        wenv_slice_work_free(w);
        return NULL;
    }
    for (size_t t = 0; t < ops->nl; t++)
        w->slot[t] = -1;
    return w;
}

void wenv_slice_work_free(wenv_slice_work *w)
{
    if (!w)
        return;
    free(w->tap_t);
    free(w->tap_w);
    free(w->rowsum);
    free(w->slot);
    free(w->scatter.texel);
    free(w->scatter.count);
    free(w->scatter.local);
    free(w->scatter.raw);
    operator_free(&w->op);
    free(w);
}

static int grow(void **p, size_t size)
{
    void *q = realloc(*p, size);
    if (!q)
        return -1;
    *p = q;
    return 0;
}

/* Room in w->scatter and w->op for `texels` global texels and `taps` taps. */
static int reserve(wenv_slice_work *w, size_t texels, size_t taps)
{
    scatter_taps *sc = &w->scatter;
    if (texels > w->room_texels) {
        size_t room = texels > 2 * w->room_texels ? texels : 2 * w->room_texels;
        if (grow((void **)&sc->texel, room * sizeof(uint32_t)) || grow((void **)&sc->count, room * sizeof(uint32_t)))
            return -1;
        w->room_texels = room;
    }
    if (taps > w->room_taps) {
        size_t room = taps > 2 * w->room_taps ? taps : 2 * w->room_taps;
        if (grow((void **)&sc->local, room * sizeof(uint16_t)) || grow((void **)&sc->raw, room * sizeof(double)) ||
            grow((void **)&w->op.texel, room * sizeof(uint32_t)) || grow((void **)&w->op.weight, room * sizeof(float)))
            return -1;
        w->room_taps = room;
    }
    return 0;
}

/* Sample c's operator into w->op: the resampler's taps with each global texel's taps on one local
 * texel summed, then every local row normalised.  Its frame is the double-precision one rotation's
 * matrices are built with, so that directions on a frame's horizon fall on the same side in both
 * methods. */
static int build_operator(const wenv_slice_operators *ops, size_t c, wenv_slice_work *w)
{
    double n[3], f[9];
    wenv_normal_sample(ops->normal_n, c, n);
    wenv_frame(n, f);
    scatter_taps *sc = &w->scatter;
    sc->n_texels = sc->n_taps = 0;
    memset(w->rowsum, 0, ops->nl * sizeof(double));
    for (size_t u = 0; u < ops->ng; u++) {
        size_t count = wenv_resampler_texel_taps(ops->rs, f, u, w->tap_t, w->tap_w);
        if (!count)
            continue;
        if (reserve(w, sc->n_texels + 1, sc->n_taps + count) < 0)
            return -1;
        size_t first = sc->n_taps;
        for (size_t q = 0; q < count; q++) {
            uint32_t t = w->tap_t[q];
            if (w->slot[t] < 0) {
                w->slot[t] = (int32_t)(sc->n_taps - first);
                sc->local[sc->n_taps] = (uint16_t)t;
                sc->raw[sc->n_taps++] = 0.0;
            }
            sc->raw[first + (size_t)w->slot[t]] += w->tap_w[q];
            w->rowsum[t] += w->tap_w[q];
        }
        for (size_t e = first; e < sc->n_taps; e++)
            w->slot[sc->local[e]] = -1;
        sc->texel[sc->n_texels] = (uint32_t)u;
        sc->count[sc->n_texels++] = (uint32_t)(sc->n_taps - first);
    }
    /* sorted by local texel (counting sort; global texels stay ascending within each) */
    slice_operator *op = &w->op;
    memset(op->start, 0, (ops->nl + 1) * sizeof(uint32_t));
    for (size_t e = 0; e < sc->n_taps; e++)
        op->start[sc->local[e] + 1]++;
    for (size_t t = 0; t < ops->nl; t++)
        op->start[t + 1] += op->start[t];
    for (size_t t = 0; t < ops->nl; t++)
        w->slot[t] = (int32_t)op->start[t]; /* the next free tap of each local texel */
    for (size_t k = 0, e = 0; k < sc->n_texels; k++)
        for (size_t end = e + sc->count[k]; e < end; e++) {
            size_t t = sc->local[e], q = (size_t)w->slot[t]++;
            op->texel[q] = sc->texel[k];
            op->weight[q] = (float)(sc->raw[e] / w->rowsum[t]);
        }
    for (size_t t = 0; t < ops->nl; t++)
        w->slot[t] = -1;
    op->n_taps = sc->n_taps;
    return 0;
}

/* A copy of op in memory of its own size, its global texels in 16 bits where they fit. */
static slice_operator *operator_copy(const slice_operator *op, size_t nl, size_t ng)
{
    slice_operator *k = calloc(1, sizeof *k);
    if (!k)
        return NULL;
    size_t taps = op->n_taps ? op->n_taps : 1;
    int narrow = ng <= (size_t)UINT16_MAX + 1;
    k->start = malloc((nl + 1) * sizeof(uint32_t));
    if (narrow)
        k->texel16 = malloc(taps * sizeof(uint16_t));
    else
        k->texel = malloc(taps * sizeof(uint32_t));
    k->weight = malloc(taps * sizeof(float));
    if (!k->start || !(k->texel || k->texel16) || !k->weight) {
        operator_free(k);
        free(k);
        return NULL;
    }
    memcpy(k->start, op->start, (nl + 1) * sizeof(uint32_t));
    if (narrow)
        for (size_t q = 0; q < op->n_taps; q++)
            k->texel16[q] = (uint16_t)op->texel[q];
    else
        memcpy(k->texel, op->texel, op->n_taps * sizeof(uint32_t));
    memcpy(k->weight, op->weight, op->n_taps * sizeof(float));
    k->n_taps = op->n_taps;
    return k;
}

int wenv_slice_operators_prepare(wenv_slice_operators *ops, const size_t *slices, size_t n)
{
    if (atomic_load(&ops->bytes) >= ops->budget)
        return 0;
    size_t *todo = malloc((n ? n : 1) * sizeof(size_t));
    unsigned char *listed = calloc(ops->ns, 1);
    if (!todo || !listed) {
        free(todo);
        free(listed);
        return -1;
    }
    size_t ntodo = 0;
    for (size_t e = 0; e < n; e++) {
        size_t c = ops->orbit[slices[e]];
        if (!ops->kept[c] && !listed[c]) {
            listed[c] = 1;
            todo[ntodo++] = c;
        }
    }
    free(listed);
    atomic_int failed = 0;
#pragma omp parallel if (ntodo > 1)
    {
        wenv_slice_work *w = wenv_slice_work_new(ops);
        if (!w)
            atomic_store(&failed, 1);
#pragma omp for schedule(dynamic, 1)
        for (size_t e = 0; e < ntodo; e++) {
            if (atomic_load(&failed) || atomic_load(&ops->bytes) >= ops->budget)
                continue;
            slice_operator *k = NULL;
            if (build_operator(ops, todo[e], w) < 0 || !(k = operator_copy(&w->op, ops->nl, ops->ng))) {
                atomic_store(&failed, 1);
                continue;
            }
            size_t bytes = operator_bytes(k, ops->nl);
            if (atomic_fetch_add(&ops->bytes, bytes) + bytes > ops->budget) {
                /* past the budget: made again whenever a slice needs it */
                atomic_fetch_sub(&ops->bytes, bytes);
                operator_free(k);
                free(k);
            } else {
                ops->kept[todo[e]] = k;
            }
        }
        wenv_slice_work_free(w);
    }
    free(todo);
    return atomic_load(&failed) ? -1 : 0;
}

size_t wenv_slice_operators_orbit(const wenv_slice_operators *ops, size_t s) { return ops->orbit[s]; }

/* k samples' slices through one read of their operator.  Each sample's taps are summed exactly as
 * for one sample alone, so a slice does not depend on which of its orbit were made with it: two
 * sums, even and odd taps, so that a tap does not wait for the last one's addition.  Inlined for
 * each constant k, so that the sums stay in registers. */
static inline __attribute__((always_inline)) void resample_orbit(const slice_operator *op, size_t nl,
                                                                 const uint32_t *const *from,
                                                                 const uint16_t *const *to, const rgbx *g,
                                                                 float *const *locals, const size_t k)
{
    const float *weight = op->weight;
    for (size_t t = 0; t < nl; t++) {
        rgbx a[WENV_ORBIT_MAX] = {{0.0f}}, b[WENV_ORBIT_MAX] = {{0.0f}};
        size_t q = op->start[t], end = op->start[t + 1];
        for (; q + 1 < end; q += 2) {
            float w0 = weight[q], w1 = weight[q + 1];
            size_t u0 = tap_texel(op, q), u1 = tap_texel(op, q + 1);
            for (size_t i = 0; i < k; i++) {
                a[i] += w0 * g[from[i][u0]];
                b[i] += w1 * g[from[i][u1]];
            }
        }
        if (q < end)
            for (size_t i = 0; i < k; i++)
                a[i] += weight[q] * g[from[i][tap_texel(op, q)]];
        for (size_t i = 0; i < k; i++) {
            rgbx sum = a[i] + b[i];
            float *l = locals[i] + 3 * (size_t)to[i][t];
            l[0] = sum[0];
            l[1] = sum[1];
            l[2] = sum[2];
        }
    }
}

int wenv_slice_operators_resample(const wenv_slice_operators *ops, const size_t *samples, size_t k,
                                  const float *global_rgbx, float *const *locals, wenv_slice_work *w)
{
    if (k < 1 || k > WENV_ORBIT_MAX)
        return -1;
    size_t c = ops->orbit[samples[0]];
    const slice_operator *op = ops->kept[c];
    if (!op) {
        if (build_operator(ops, c, w) < 0)
            return -1;
        op = &w->op;
    }
    const uint32_t *from[WENV_ORBIT_MAX];
    const uint16_t *to[WENV_ORBIT_MAX];
    for (size_t i = 0; i < k; i++) {
        from[i] = ops->global_perm[ops->global_of[samples[i]]];
        to[i] = ops->local_perm[ops->local_of[samples[i]]];
    }
    const rgbx *g = (const rgbx *)global_rgbx;
    switch (k) {
    case 1: resample_orbit(op, ops->nl, from, to, g, locals, 1); break;
    case 2: resample_orbit(op, ops->nl, from, to, g, locals, 2); break;
    case 3: resample_orbit(op, ops->nl, from, to, g, locals, 3); break;
    case 4: resample_orbit(op, ops->nl, from, to, g, locals, 4); break;
    case 5: resample_orbit(op, ops->nl, from, to, g, locals, 5); break;
    case 6: resample_orbit(op, ops->nl, from, to, g, locals, 6); break;
    case 7: resample_orbit(op, ops->nl, from, to, g, locals, 7); break;
    default: resample_orbit(op, ops->nl, from, to, g, locals, 8); break;
    }
    return 0;
}

size_t wenv_slice_operators_estimate_bytes(size_t global_n, size_t local_n, size_t normal_n, size_t used_normals)
{
    /* orbits: 8 samples each, 4 on the diagonals u = +-v */
    size_t ns = normal_n * normal_n, orbits = ns / 8 + normal_n / 2;
    size_t used = used_normals < orbits ? used_normals : orbits;
    /* taps of a global texel above the horizon: the local texels its footprint (up to sqrt 2 times
     * wider than local/global texels) and their tents reach */
    double ratio = (double)local_n / (double)global_n, k = fmax(2.0, ceil(2.83 * ratio));
    double taps = fmin(4.0 * k * k, (M_SQRT2 * ratio + 1.8) * (M_SQRT2 * ratio + 1.8));
    size_t index = global_n * global_n <= (size_t)UINT16_MAX + 1 ? sizeof(uint16_t) : sizeof(uint32_t);
    double per_orbit = (double)((local_n * local_n + 1) * sizeof(uint32_t)) +
                       0.5 * (double)(global_n * global_n) * taps * (double)(index + sizeof(float));
    return (size_t)((double)used * per_orbit);
}

size_t wenv_slice_operators_bytes(const wenv_slice_operators *ops)
{
    return atomic_load(&ops->bytes);
}
