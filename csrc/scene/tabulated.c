/* An isotropic BRDF tabulated over Rusinkiewicz's half and difference angles (material.h,
 * wenv_tabulated_create), measured or made from numpy.
 *
 * Layout (MERL's): the index coordinates are (sqrt(theta_h / 90) n_h, theta_d / 90 n_d,
 * phi_d / 180 n_p), theta_h's dense near the mirror direction, where measured BRDFs change fastest,
 * phi_d folded into [0, 180) by reciprocity; value (i, j, k) at 3 (k + n_p (j + n_d i)), RGB f in
 * 1/sr.  Sample (i, j, k) sits at (i, j, k) + o: o = 1/2, the centre of the bin [i, i + 1) x ...,
 * for a MERL file (its reader looks a sample up by the floor of the index coordinate, so a sample
 * stands for its bin), or o = 0 for a table sampled at the bins' starts (samples_at).  Between
 * samples the table is interpolated trilinearly, phi_d periodic (period n_p), theta_h and theta_d
 * held at their first and last sample outside them.
 *
 * The table is split into a Lambertian part, its smallest value above the horizon per channel (a
 * measured BRDF's diffuse reflection; exact, since the interpolation's weights sum to one), and one
 * glossy lobe, the rest.  The lobe's microfacet shape, which only places quadrature nodes, is a
 * Beckmann lobe whose width is the lobe's half-maximum width in theta_h at the first theta_d sample
 * (tan(theta_half) / sqrt(ln 2)), coloured to match its peak.  Integrals use two rules together:
 * cells that follow the shape (equal in its distribution's CDF, fine near the mirror direction) and
 * cells uniform over the hemisphere (for what lies away from it: a retro-reflective lobe, a broad
 * tail), each weighted by its share of the two rules' node density at the point (a partition of
 * unity), so neither counts anything twice.  The exact lights skip half vectors past the last
 * theta_h where the lobe holds 1e-7 of its peak (none for a lobe that reflects at every half vector,
 * a retro-reflective one say). */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "base/fingerprint.h"
#include "scene/material_kind.h"

#ifndef M_PI
#define M_PI 3.14159265358979323846
#endif

typedef struct {
    wenv_shared shared;
    size_t n[3];     /* theta_h, theta_d, phi_d samples */
    float *rgb;      /* n[0] n[1] n[2] x 3 */
    unsigned char *above; /* per sample: both its directions lie above the horizon */
    unsigned char *cell_above; /* per sample: so do the 8 samples of the cell it is the lowest corner of */
    wenv_sample_position samples_at;
    double offset;        /* o: where sample 0 sits on each axis of the index coordinates */
    double floor[3];      /* the smallest f above the horizon: the Lambertian part, pi floor = diffuse */
    double cos_h_min;     /* n.h below which the lobe (table - floor) holds under 1e-7 of its peak (-1: none) */
    int shape_rule;       /* the shape's cells alone integrate the lobe (see decide_rule) */
} table;

static const table *table_of(const wenv_material *mat) { return (const table *)mat->shared; }

static void table_destroy(wenv_shared *shared)
{
    table *t = (table *)shared;
    free(t->rgb);
    free(t->above);
    free(t->cell_above);
    free(t);
}

/* The index coordinates of (wi, wo), unit vectors above the horizon: sqrt(theta_h / 90) n_h,
 * theta_d / 90 n_d, phi_d / 180 n_p with Rusinkiewicz's angles (d = R_y(-theta_h) R_z(-phi_h) wi).
 * The rotations' cosines and sines come from h itself, so three arctangents are the only
 * transcendental calls; atan2, not acos: well conditioned near the normal, where theta_h's square-root
 * index is steep.  Written once for double (the reference, precomputation) and once for float (the
 * exact lights' per-vertex loop), which runs it as often as every light of every vertex. */
#define INDEX_COORDS(T, SQRT, ATAN2)                                                                               \
    static void index_coords_##T(const size_t n[3], const T wi[3], const T wo[3], double x[3])                     \
    {                                                                                                              \
        T h[3] = {wi[0] + wo[0], wi[1] + wo[1], wi[2] + wo[2]};                                                    \
        T len = SQRT(h[0] * h[0] + h[1] * h[1] + h[2] * h[2]);                                                     \
        T rxy = SQRT(h[0] * h[0] + h[1] * h[1]);                                                                   \
        T cp = rxy > 0 ? h[0] / rxy : 1, sp = rxy > 0 ? h[1] / rxy : 0, ct = h[2] / len, st = rxy / len;           \
        T a = cp * wi[0] + sp * wi[1], b = -sp * wi[0] + cp * wi[1];                                               \
        T dx = ct * a - st * wi[2], dz = st * a + ct * wi[2];                                                      \
        T theta_h = ATAN2(rxy, h[2]), theta_d = ATAN2(SQRT(dx * dx + b * b), dz), phi_d = ATAN2(b, dx);           \
        x[0] = sqrt((double)theta_h / (0.5 * M_PI)) * (double)n[0];                                                \
        x[1] = (double)theta_d / (0.5 * M_PI) * (double)n[1];                                                      \
        x[2] = ((double)phi_d < 0.0 ? (double)phi_d + M_PI : (double)phi_d) / M_PI * (double)n[2];                 \
    }
/* atan2 in float without a library call: atan on [0, 1] as a * P(a^2), P fitted by least squares
 * on Chebyshev nodes (largest error 8e-8 rad, float's own rounding), then the octant by symmetry. */
static inline float atan2_fast(float y, float x)
{
    float ax = x < 0.0f ? -x : x, ay = y < 0.0f ? -y : y;
    float hi = ax > ay ? ax : ay, lo = ax > ay ? ay : ax;
    if (!(hi > 0.0f))
        return 0.0f;
    float a = lo / hi, q = a * a;
    float r = a * (0.99999995f +
                   q * (-0.33332198f +
                        q * (0.19971951f +
                             q * (-0.14029598f + q * (0.09937584f + q * (-0.05977245f + q * (0.02443129f + q * -0.00473808f)))))));
    if (ay > ax)
        r = 1.57079633f - r;
    if (x < 0.0f)
        r = 3.14159265f - r;
    return y < 0.0f ? -r : r;
}

INDEX_COORDS(double, sqrt, atan2)
INDEX_COORDS(float, sqrtf, atan2_fast)

/* Interpolation weights along one axis: samples a and b with weight 1 - f and f. */
static void axis_taps(double x, size_t n, int periodic, size_t *a, size_t *b, double *f)
{
    double fl = floor(x);
    *f = x - fl;
    if (periodic) {
        long i = (long)fl % (long)n;
        *a = (size_t)(i < 0 ? i + (long)n : i);
        *b = (*a + 1) % n;
        return;
    }
    if (!(fl >= 0.0)) {
        *a = *b = 0;
        *f = 0.0;
    } else if (fl >= (double)(n - 1)) {
        *a = *b = n - 1;
        *f = 0.0;
    } else {
        *a = (size_t)fl;
        *b = *a + 1;
    }
}

static inline double lerp(double a, double b, double f) { return a + f * (b - a); }

/* The table at index coordinates x, trilinear; minus the floor (the glossy lobe alone), never < 0. */
static void lobe_at(const table *t, const double x[3], double rgb[3])
{
    size_t i[2], j[2], k[2];
    double fi, fj, fk;
    /* in units of samples from sample 0, which sits at o */
    axis_taps(x[0] - t->offset, t->n[0], 0, &i[0], &i[1], &fi);
    axis_taps(x[1] - t->offset, t->n[1], 0, &j[0], &j[1], &fj);
    axis_taps(x[2] - t->offset, t->n[2], 1, &k[0], &k[1], &fk);
    size_t s[8];
    for (int a = 0; a < 8; a++)
        s[a] = k[a & 1] + t->n[2] * (j[(a >> 1) & 1] + t->n[1] * i[a >> 2]);
    double v[3];
    if (t->cell_above[s[0]]) { /* the usual case, away from the horizon */
        for (int ch = 0; ch < 3; ch++) {
            const float *r = t->rgb + ch;
            double c00 = lerp(r[3 * s[0]], r[3 * s[1]], fk), c01 = lerp(r[3 * s[2]], r[3 * s[3]], fk);
            double c10 = lerp(r[3 * s[4]], r[3 * s[5]], fk), c11 = lerp(r[3 * s[6]], r[3 * s[7]], fk);
            v[ch] = lerp(lerp(c00, c01, fj), lerp(c10, c11, fj), fi);
        }
    } else {
        /* Samples whose own directions lie below the horizon hold no reflection (or a filled
         * guess): only the others are interpolated, their weights renormalised; plain trilinear
         * when every neighbour lies below. */
        double all[3] = {0.0, 0.0, 0.0}, kept_rgb[3] = {0.0, 0.0, 0.0}, total = 0.0, kept = 0.0;
        for (int a = 0; a < 8; a++) {
            double w = (a & 4 ? fi : 1.0 - fi) * (a & 2 ? fj : 1.0 - fj) * (a & 1 ? fk : 1.0 - fk);
            double wk = t->above[s[a]] ? w : 0.0;
            const float *r = t->rgb + 3 * s[a];
            total += w;
            kept += wk;
            for (int ch = 0; ch < 3; ch++) {
                all[ch] += w * r[ch];
                kept_rgb[ch] += wk * r[ch];
            }
        }
        double scale = kept > 0.0 ? total / kept : 1.0;
        for (int ch = 0; ch < 3; ch++)
            v[ch] = (kept > 0.0 ? kept_rgb[ch] : all[ch]) * scale;
    }
    for (int ch = 0; ch < 3; ch++) {
        double d = v[ch] - t->floor[ch];
        rgb[ch] = d > 0.0 ? d : 0.0;
    }
}

/* The glossy lobe (the table less its Lambertian floor), 0 below either horizon. */
static void lobe_f(const table *t, const double wi[3], const double wo[3], double rgb[3])
{
    rgb[0] = rgb[1] = rgb[2] = 0.0;
    if (!(wi[2] > 0.0) || !(wo[2] > 0.0))
        return;
    double x[3];
    index_coords_double(t->n, wi, wo, x);
    lobe_at(t, x, rgb);
}

/* ---------------------------------------------------------------- evaluation */

static void tab_lobe_value(const wenv_material *mat, size_t i, const double wi[3], const double wo[3], double rgb[3])
{
    (void)i;
    lobe_f(table_of(mat), wi, wo, rgb);
}

/* The float path: the angles in float (the per-vertex loops' cost), the interpolation in double. */
static void tab_specular_cos_f_many(const wenv_material *mat, const float wo[3], const float *terms, size_t n,
                                    const float *x, const float *y, const float *z, float *r, float *g, float *b)
{
    (void)terms;
    const table *t = table_of(mat);
    for (size_t k = 0; k < n; k++) {
        float wi[3] = {x[k], y[k], z[k]};
        double c[3], v[3] = {0.0, 0.0, 0.0};
        if (wi[2] > 0.0f && wo[2] > 0.0f) {
            index_coords_float(t->n, wi, wo, c);
            lobe_at(t, c, v);
        }
        r[k] = (float)(v[0] * wi[2]);
        g[k] = (float)(v[1] * wi[2]);
        b[k] = (float)(v[2] * wi[2]);
    }
}

/* A lobe its fitted shape covers lies about the mirror direction (decide_rule); one it does not
 * (retro-reflective, say) may lie anywhere, most likely about the view. */
static int tab_mirror_centred(const wenv_material *mat) { return table_of(mat)->shape_rule; }

static double tab_lobe_cos_h_min(const wenv_material *mat, size_t i)
{
    (void)i;
    return table_of(mat)->cos_h_min;
}

/* ---------------------------------------------------------------- integrals */

/* Nodes of the shape's cells (n_theta x n_phi, mirrored: 2 n_theta n_phi) and of cells uniform in
 * (cos theta, phi) over the hemisphere (n_rings x n_az), with RGB weights f cos Omega times each
 * rule's share of the node density (see the top comment), and each cell's solid angle. */
static wenv_status mixed_rule(const wenv_material *mat, size_t lobe, const double wo[3], size_t n_theta, size_t n_phi,
                              size_t n_rings, size_t n_az, double *wi, double *weight, double *solid_angle,
                              size_t *count, wenv_error *err)
{
    *count = 0;
    const wenv_lobe *shape = &mat->lobes[lobe];
    size_t n_shape = 2 * n_theta * n_phi, n_uniform = n_rings * n_az;
    double *omega = solid_angle ? solid_angle : malloc((n_shape + n_uniform) * sizeof *omega);
    if (!omega)
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for a table's quadrature");
    size_t got = 0;
    /* the shape's cells; their weights come back colourless (F D G...), replaced below */
    if (wenv_lobe_cells(shape, mat->shadowing, wo, n_theta, n_phi, wi, weight, omega, &got, err)) {
        if (!solid_angle)
            free(omega);
        return err->status;
    }
    for (size_t r = 0; r < n_rings; r++)
        for (size_t a = 0; a < n_az; a++) {
            double z = ((double)r + 0.5) / (double)n_rings, s = sqrt(fmax(0.0, 1.0 - z * z));
            double phi = 2.0 * M_PI * ((double)a + 0.5) / (double)n_az;
            double *w = wi + 3 * (got + r * n_az + a);
            w[0] = s * cos(phi);
            w[1] = s * sin(phi);
            w[2] = z;
            omega[got + r * n_az + a] = 2.0 * M_PI / (double)n_uniform;
        }
    /* node densities: the shape's rule follows its half-vector pdf D cos_h / (4 wo.h), the uniform
     * one 1 / 2 pi per steradian */
    double uniform_density = (double)n_uniform / (2.0 * M_PI);
    for (size_t k = 0; k < n_shape + n_uniform; k++) {
        const double *w = wi + 3 * k;
        double h[3] = {w[0] + wo[0], w[1] + wo[1], w[2] + wo[2]};
        double len = sqrt(h[0] * h[0] + h[1] * h[1] + h[2] * h[2]), shape_density = 0.0;
        if (len > 0.0 && w[2] > 0.0 && wo[2] > 0.0) {
            double ch = h[2] / len, oh = (wo[0] * h[0] + wo[1] * h[1] + wo[2] * h[2]) / len;
            if (ch > 0.0 && oh > 0.0)
                shape_density = (double)n_shape * wenv_ndf(shape->distribution, shape->alpha, ch) * ch /
                                (4.0 * oh);
        }
        double total = shape_density + uniform_density;
        double share = total > 0.0 ? (k < n_shape ? shape_density : uniform_density) / total : (k < n_shape);
        double f[3];
        lobe_f(table_of(mat), w, wo, f);
        double m = share * omega[k] * (w[2] > 0.0 ? w[2] : 0.0);
        for (int c = 0; c < 3; c++)
            weight[3 * k + (size_t)c] = f[c] * m;
    }
    *count = n_shape + n_uniform;
    if (!solid_angle)
        free(omega);
    return WENV_OK;
}

static wenv_status tab_lobe_nodes(const wenv_material *mat, size_t i, const double wo[3], size_t samples,
                                  double *wi, double *weight, size_t *count, wenv_error *err)
{
    /* 2 samples^2 nodes: all the shape's, or half the shape's and half uniform */
    if (table_of(mat)->shape_rule)
        return mixed_rule(mat, i, wo, samples, samples, 0, 0, wi, weight, NULL, count, err);
    size_t half = samples / 2 > 0 ? samples / 2 : 1;
    return mixed_rule(mat, i, wo, samples, half, samples, samples, wi, weight, NULL, count, err);
}

/* The weights' sum of a rule with these divisions (see mixed_rule). */
static wenv_status rule_albedo(const wenv_material *mat, const double wo[3], size_t n_theta, size_t n_phi,
                               size_t n_rings, size_t n_az, double rgb[3], wenv_error *err)
{
    rgb[0] = rgb[1] = rgb[2] = 0.0;
    size_t max = 2 * n_theta * n_phi + n_rings * n_az;
    double *wi = malloc(max * 6 * sizeof *wi);
    if (!wi)
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for a table's albedo");
    size_t count = 0;
    wenv_status st = mixed_rule(mat, 0, wo, n_theta, n_phi, n_rings, n_az, wi, wi + 3 * max, NULL, &count, err);
    for (size_t k = 0; !st && k < count; k++)
        for (int c = 0; c < 3; c++)
            rgb[c] += wi[3 * max + 3 * k + (size_t)c];
    free(wi);
    return st;
}

static wenv_status tab_lobe_albedo(const wenv_material *mat, size_t i, const double wo[3], size_t samples,
                                   double rgb[3], wenv_error *err)
{
    (void)i;
    if (table_of(mat)->shape_rule)
        return rule_albedo(mat, wo, samples, samples, 0, 0, rgb, err);
    /* Mixed, the rules' shares vary where neither rule's nodes are dense (a retro-reflective peak at
     * a normal view: 32 divisions read 3 % low there, 64 0.8 %): twice the divisions, since the
     * wavelet shader multiplies every vertex's radiance by this albedo. */
    size_t fine = samples <= 2048 ? 2 * samples : samples;
    return rule_albedo(mat, wo, fine, fine / 2, fine, fine, rgb, err);
}

/* 2 n_theta n_phi nodes: all the shape's cells, or the shape's for half the theta divisions and
 * uniform rings for the rest. */
static wenv_status tab_lobe_cells(const wenv_material *mat, size_t i, const double wo[3], size_t n_theta,
                                  size_t n_phi, double *wi, double *weight, double *solid_angle, size_t *count,
                                  wenv_error *err)
{
    if (table_of(mat)->shape_rule)
        return mixed_rule(mat, i, wo, n_theta, n_phi, 0, 0, wi, weight, solid_angle, count, err);
    size_t shape_theta = (n_theta + 1) / 2;
    return mixed_rule(mat, i, wo, shape_theta, n_phi, n_theta - shape_theta, 2 * n_phi, wi, weight, solid_angle,
                      count, err);
}

/* Whether the shape's cells alone integrate the lobe: its albedo by 64 x 64 of them within 0.2 % of
 * the lobe's peak albedo by a fine mixed rule, at views of 0 to 80 degrees (tables of Cook-Torrance
 * lobes, m = 0.05 to 1, differ by at most 0.07 %; a retro-reflective lobe by 2 %, one beside a glossy
 * lobe by 4-7 %).  A lobe about the mirror
 * direction passes, and then every node of the methods' fixed-size rules lies on it (as for a
 * microfacet lobe: under a detailed environment half of them spent on uniform cells alias visibly
 * at grazing views); a lobe that reflects far from the mirror direction (retro-reflective) keeps
 * the uniform cells. */
static wenv_status decide_rule(const wenv_material *mat, table *t, wenv_error *err)
{
    static const double degrees[] = {0.0, 30.0, 60.0, 80.0};
    double fine[4][3], shape[4][3], peak = 0.0;
    t->shape_rule = 0;
    for (int v = 0; v < 4; v++) {
        double a = degrees[v] * M_PI / 180.0, wo[3] = {sin(a), 0.0, cos(a)};
        if (rule_albedo(mat, wo, 256, 128, 256, 256, fine[v], err) ||
            rule_albedo(mat, wo, 64, 64, 0, 0, shape[v], err))
            return err->status;
        for (int c = 0; c < 3; c++)
            peak = fmax(peak, fine[v][c]);
    }
    int covers = 1;
    for (int v = 0; v < 4; v++)
        for (int c = 0; c < 3; c++)
            covers &= fabs(shape[v][c] - fine[v][c]) <= 2e-3 * peak;
    t->shape_rule = covers;
    return WENV_OK;
}

/* ---------------------------------------------------------------- making one */

static const wenv_material_kind TABULATED = {
    .name = "tabulated",
    .no_colour = 1,
    .mirror_symmetric = 0, /* phi_d folds into [0, 180) by reciprocity: a mirror reads 180 - phi_d */
    .smooth_limit = 0,
    .lobe_value = tab_lobe_value,
    /* accelerators: the float path's angles in float; rules that mix the shape's cells with uniform
     * ones (a measured lobe may lie away from its fitted shape) */
    .specular_cos_f_many = tab_specular_cos_f_many,
    .lobe_cos_h_min = tab_lobe_cos_h_min,
    .lobe_albedo = tab_lobe_albedo,
    .lobe_nodes = tab_lobe_nodes,
    .lobe_cells = tab_lobe_cells,
    .mirror_centred = tab_mirror_centred,
    .with_roughness = NULL, /* a measurement has no roughness to set */
};

/* Luminance of the lobe (table less floor) at sample s. */
static double lobe_luma(const table *t, size_t s)
{
    const float *v = t->rgb + 3 * s;
    return 0.2126 * fmax(0.0, v[0] - t->floor[0]) + 0.7152 * fmax(0.0, v[1] - t->floor[1]) +
           0.0722 * fmax(0.0, v[2] - t->floor[2]);
}

/* The shape: Beckmann, as wide as the lobe's half maximum in theta_h along the first theta_d and
 * phi_d samples (theta_d = 0, or half a bin from it), coloured so that it matches the lobe's peak
 * (see the top comment). */
static wenv_lobe fit_shape(const table *t)
{
    wenv_lobe shape = {.specular = {1.0, 1.0, 1.0}, .alpha = 1.0, .ior = 1.5, .distribution = WENV_NDF_BECKMANN};
    double luma0 = lobe_luma(t, 0);
    if (!(luma0 > 0.0))
        return shape;
    size_t slab = t->n[2] * t->n[1];
    for (size_t i = 1; i < t->n[0]; i++) {
        double luma = lobe_luma(t, slab * i);
        if (luma < 0.5 * luma0) {
            double prev = lobe_luma(t, slab * (i - 1));
            double x = (double)(i - 1) + (prev - 0.5 * luma0) / fmax(prev - luma, 1e-300);
            double q = (x + t->offset) / (double)t->n[0], theta = q * q * 0.5 * M_PI;
            shape.alpha = fmin(1.0, fmax(1e-3, tan(theta) / sqrt(log(2.0))));
            break;
        }
    }
    /* a unit-coloured shape's f at the mirror of a normal view: F(1) D(0) / 4 (G = 1 there) */
    double unit = wenv_fresnel_dielectric(1.0, shape.ior) / (M_PI * shape.alpha * shape.alpha * 4.0);
    for (int c = 0; c < 3; c++)
        shape.specular[c] = fmax(0.0, t->rgb[c] - t->floor[c]) / unit;
    return shape;
}

wenv_status wenv_tabulated_create(wenv_material **out, const float *rgb, const size_t dims[3],
                                  wenv_sample_position samples_at, wenv_error *err)
{
    *out = NULL;
    if (samples_at != WENV_SAMPLES_AT_CENTRES && samples_at != WENV_SAMPLES_AT_STARTS)
        return wenv_error_set(err, WENV_ERR_VALUE, "samples_at must be the bins' centres or starts, got %d",
                              (int)samples_at);
    size_t n = 1;
    for (int d = 0; d < 3; d++) {
        if (dims[d] < 2 || dims[d] > 4096)
            return wenv_error_set(err, WENV_ERR_VALUE, "table dimensions must be in [2, 4096], got %zu x %zu x %zu",
                                  dims[0], dims[1], dims[2]);
        n *= dims[d];
    }
    for (size_t s = 0; s < 3 * n; s++)
        if (!isfinite(rgb[s]) || rgb[s] < 0.0f)
            return wenv_error_set(err, WENV_ERR_VALUE, "table value %zu is %g: values must be finite and >= 0", s,
                                  (double)rgb[s]);
    table *t = calloc(1, sizeof *t);
    float *copy = malloc(3 * n * sizeof *copy);
    if (!t || !copy) {
        free(t);
        free(copy);
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for a %zu x %zu x %zu table", dims[0], dims[1],
                              dims[2]);
    }
    memcpy(copy, rgb, 3 * n * sizeof *copy);
    memcpy(t->n, dims, sizeof t->n);
    t->rgb = copy;
    t->samples_at = samples_at;
    t->offset = samples_at == WENV_SAMPLES_AT_CENTRES ? 0.5 : 0.0;
    t->above = malloc(n);
    if (!t->above) {
        table_destroy(&t->shared);
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for a table");
    }
    /* at each sample's position, with phi_h = 0: wi.z = cos th cos td - sin th sin td cos pd,
     * wo.z = 2 cos td cos th - wi.z */
    const double o = t->offset;
    for (size_t i = 0; i < dims[0]; i++)
        for (size_t j = 0; j < dims[1]; j++)
            for (size_t k = 0; k < dims[2]; k++) {
                double q = ((double)i + o) / (double)dims[0], th = q * q * 0.5 * M_PI;
                double td = ((double)j + o) / (double)dims[1] * 0.5 * M_PI;
                double pd = ((double)k + o) / (double)dims[2] * M_PI;
                double zi = cos(th) * cos(td) - sin(th) * sin(td) * cos(pd), zo = 2.0 * cos(td) * cos(th) - zi;
                t->above[k + dims[2] * (j + dims[1] * i)] = zi > 0.0 && zo > 0.0;
            }
    t->cell_above = malloc(n);
    if (!t->cell_above) {
        table_destroy(&t->shared);
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for a table");
    }
    for (size_t i = 0; i < dims[0]; i++)
        for (size_t j = 0; j < dims[1]; j++)
            for (size_t k = 0; k < dims[2]; k++) {
                /* the corners lobe_at reads from this one: the next sample, held at the last */
                size_t i1 = i + 1 < dims[0] ? i + 1 : i, j1 = j + 1 < dims[1] ? j + 1 : j, k1 = (k + 1) % dims[2];
                unsigned char all = 1;
                for (int a = 0; a < 8; a++)
                    all &= t->above[(a & 1 ? k1 : k) + dims[2] * ((a & 2 ? j1 : j) + dims[1] * (a & 4 ? i1 : i))];
                t->cell_above[k + dims[2] * (j + dims[1] * i)] = all;
            }
    atomic_init(&t->shared.refs, 1);
    t->shared.destroy = table_destroy;
    /* where the samples sit is part of what the table is: the same values elsewhere reflect otherwise */
    uint64_t h = WENV_FINGERPRINT_START;
    for (int d = 0; d < 3; d++)
        h = wenv_fingerprint_word(h, dims[d]);
    h = wenv_fingerprint_word(h, (uint64_t)samples_at);
    t->shared.fingerprint = wenv_fingerprint_floats(h, copy, 3 * n);
    /* The Lambertian floor: the smallest value above the horizon per channel (a measured BRDF's
     * diffuse reflection, a tabulated diffuse + glossy material's diffuse term), capped at albedo 1.
     * Shading it as a Lambertian part is exact (the interpolation's weights sum to one) and lets the
     * exact lights cull the lobe left over as they cull a microfacet lobe. */
    double diffuse[3] = {INFINITY, INFINITY, INFINITY};
    for (size_t s = 0; s < n; s++)
        for (int c = 0; t->above[s] && c < 3; c++)
            diffuse[c] = fmin(diffuse[c], copy[3 * s + (size_t)c]);
    for (int c = 0; c < 3; c++) {
        t->floor[c] = isfinite(diffuse[c]) ? fmin(diffuse[c], 1.0 / M_PI) : 0.0;
        diffuse[c] = M_PI * t->floor[c];
    }
    /* the exact lights' cone: past the position of the sample after the last theta_h slab where the
     * lobe holds 1e-7 of its peak anywhere (beyond it every tap the interpolation reads holds less),
     * or none */
    double peak = 0.0;
    for (size_t s = 0; s < n; s++)
        if (t->above[s])
            for (int c = 0; c < 3; c++)
                peak = fmax(peak, copy[3 * s + (size_t)c] - t->floor[c]);
    size_t last = 0, slab = dims[1] * dims[2];
    for (size_t s = 0; s < n; s++)
        for (int c = 0; t->above[s] && c < 3; c++)
            if (copy[3 * s + (size_t)c] - t->floor[c] >= 1e-7 * peak && s / slab > last)
                last = s / slab;
    double q = ((double)(last + 1) + o) / (double)dims[0];
    t->cos_h_min = last + 1 < dims[0] ? cos(q * q * 0.5 * M_PI) : -1.0;
    wenv_lobe shape = fit_shape(t);
    if (wenv_material_alloc(out, &TABULATED, diffuse, &shape, 1, WENV_SHADOW_SMITH, err)) {
        table_destroy(&t->shared);
        return err->status;
    }
    (*out)->shared = &t->shared;
    if (decide_rule(*out, t, err)) {
        wenv_material_free(*out);
        *out = NULL;
        return err->status;
    }
    return WENV_OK;
}

const float *wenv_tabulated_table(const wenv_material *mat, size_t dims[3])
{
    if (mat->kind != &TABULATED)
        return NULL;
    memcpy(dims, table_of(mat)->n, 3 * sizeof *dims);
    return table_of(mat)->rgb;
}

wenv_sample_position wenv_tabulated_samples_at(const wenv_material *mat)
{
    return mat->kind == &TABULATED ? table_of(mat)->samples_at : WENV_SAMPLES_AT_CENTRES;
}
