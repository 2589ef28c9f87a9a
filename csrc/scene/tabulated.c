/* An isotropic BRDF tabulated over Rusinkiewicz's half and difference angles (material.h,
 * wenv_tabulated_create), measured or made from numpy.
 *
 * Layout (MERL's): theta_h sample i at (i / n_h)^2 90 degrees (dense near the mirror direction,
 * where measured BRDFs change fastest), theta_d sample j at j / n_d 90 degrees, phi_d sample k at
 * k / n_p 180 degrees (phi_d folded into [0, 180) by reciprocity); value (i, j, k) at
 * 3 (k + n_p (j + n_d i)), RGB f in 1/sr.  Between samples the table is interpolated trilinearly in
 * the index coordinates (sqrt(theta_h / 90) n_h, theta_d / 90 n_d, phi_d / 180 n_p), phi_d
 * periodic, theta_h and theta_d held at their last sample beyond it.
 *
 * The whole table is one glossy lobe (no Lambertian part).  Its microfacet shape, which only places
 * quadrature nodes, is a Beckmann lobe whose width is the table's half-maximum width in theta_h at
 * theta_d = 0 (tan(theta_half) / sqrt(ln 2)), coloured to match the table's peak.  Integrals use
 * two rules together: cells that follow the shape (equal in its distribution's CDF, fine near the
 * mirror direction) and cells uniform over the hemisphere (for what lies away from it: a diffuse
 * floor, a retro-reflective lobe), each weighted by its share of the two rules' node density at the
 * point (a partition of unity), so neither counts anything twice.  The exact lights skip half
 * vectors past the last theta_h where the table holds 1e-7 of its peak (none, for a table with a
 * diffuse floor or a retro-reflective lobe: it reflects at every half vector). */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "scene/material_kind.h"

#ifndef M_PI
#define M_PI 3.14159265358979323846
#endif

typedef struct {
    wenv_shared shared;
    size_t n[3];     /* theta_h, theta_d, phi_d samples */
    float *rgb;      /* n[0] n[1] n[2] x 3 */
    unsigned char *above; /* per sample: both its directions lie above the horizon */
    double cos_h_min;     /* n.h below which the table holds under 1e-7 of its peak (-1: none) */
} table;

static const table *table_of(const wenv_material *mat) { return (const table *)mat->shared; }

static void table_destroy(wenv_shared *shared)
{
    table *t = (table *)shared;
    free(t->rgb);
    free(t->above);
    free(t);
}

/* Rusinkiewicz's angles of (wi, wo), unit vectors above the horizon. */
static void half_diff(const double wi[3], const double wo[3], double *theta_h, double *theta_d, double *phi_d)
{
    double h[3] = {wi[0] + wo[0], wi[1] + wo[1], wi[2] + wo[2]};
    double len = sqrt(h[0] * h[0] + h[1] * h[1] + h[2] * h[2]);
    for (int c = 0; c < 3; c++)
        h[c] /= len;
    /* atan2, not acos: well conditioned near the normal, where theta_h's square-root index is steep */
    *theta_h = atan2(sqrt(h[0] * h[0] + h[1] * h[1]), h[2]);
    double phi_h = atan2(h[1], h[0]);
    /* d = R_y(-theta_h) R_z(-phi_h) wi */
    double cp = cos(phi_h), sp = sin(phi_h), ct = cos(*theta_h), st = sin(*theta_h);
    double x = cp * wi[0] + sp * wi[1], y = -sp * wi[0] + cp * wi[1], z = wi[2];
    double dx = ct * x - st * z, dz = st * x + ct * z;
    *theta_d = atan2(sqrt(dx * dx + y * y), dz);
    double p = atan2(y, dx);
    *phi_d = p < 0.0 ? p + M_PI : p;
}

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

static void table_f(const table *t, const double wi[3], const double wo[3], double rgb[3])
{
    rgb[0] = rgb[1] = rgb[2] = 0.0;
    if (!(wi[2] > 0.0) || !(wo[2] > 0.0))
        return;
    double th, td, pd;
    half_diff(wi, wo, &th, &td, &pd);
    size_t i[2], j[2], k[2];
    double fi, fj, fk;
    axis_taps(sqrt(th / (0.5 * M_PI)) * (double)t->n[0], t->n[0], 0, &i[0], &i[1], &fi);
    axis_taps(td / (0.5 * M_PI) * (double)t->n[1], t->n[1], 0, &j[0], &j[1], &fj);
    axis_taps(pd / M_PI * (double)t->n[2], t->n[2], 1, &k[0], &k[1], &fk);
    /* Samples whose own directions lie below the horizon hold no reflection (or a filled guess):
     * near the horizon only the others are interpolated, their weights renormalised; plain
     * trilinear when every neighbour lies below. */
    double kept_rgb[3] = {0.0, 0.0, 0.0}, total = 0.0, kept = 0.0;
    for (int a = 0; a < 2; a++)
        for (int b = 0; b < 2; b++)
            for (int c = 0; c < 2; c++) {
                double w = (a ? fi : 1.0 - fi) * (b ? fj : 1.0 - fj) * (c ? fk : 1.0 - fk);
                size_t s = k[c] + t->n[2] * (j[b] + t->n[1] * i[a]);
                const float *v = t->rgb + 3 * s;
                total += w;
                kept += t->above[s] ? w : 0.0;
                for (int ch = 0; ch < 3; ch++) {
                    rgb[ch] += w * v[ch];
                    kept_rgb[ch] += t->above[s] ? w * v[ch] : 0.0;
                }
            }
    if (kept > 0.0)
        for (int ch = 0; ch < 3; ch++)
            rgb[ch] = kept_rgb[ch] * (total / kept);
}

/* ---------------------------------------------------------------- evaluation */

static void tab_lobe_value(const wenv_material *mat, size_t i, const double wi[3], const double wo[3], double rgb[3])
{
    (void)i;
    table_f(table_of(mat), wi, wo, rgb);
}

static void tab_specular_cos(const wenv_material *mat, const double wi[3], const double wo[3], double rgb[3])
{
    table_f(table_of(mat), wi, wo, rgb);
    for (int c = 0; c < 3; c++)
        rgb[c] *= wi[2] > 0.0 ? wi[2] : 0.0;
}

static void tab_specular_cos_batch(const wenv_material *mat, const double wo[3], const float *wi, size_t n,
                                   float *rgb)
{
    for (size_t k = 0; k < n; k++) {
        double d[3] = {wi[3 * k], wi[3 * k + 1], wi[3 * k + 2]}, v[3];
        tab_specular_cos(mat, d, wo, v);
        for (int c = 0; c < 3; c++)
            rgb[3 * k + (size_t)c] = (float)v[c];
    }
}

static size_t tab_view_terms(const wenv_material *mat)
{
    (void)mat;
    return 0;
}

static void tab_prepare_view_f(const wenv_material *mat, const float wo[3], float *terms)
{
    (void)mat, (void)wo, (void)terms;
}

/* The table is float already: the double path, rounded. */
static void tab_specular_cos_f(const wenv_material *mat, const float wi[3], const float wo[3], const float *terms,
                               float rgb[3])
{
    (void)terms;
    double a[3] = {wi[0], wi[1], wi[2]}, b[3] = {wo[0], wo[1], wo[2]}, v[3];
    tab_specular_cos(mat, a, b, v);
    for (int c = 0; c < 3; c++)
        rgb[c] = (float)v[c];
}

static double tab_lobe_cos_h_min(const wenv_material *mat, size_t i)
{
    (void)i;
    return table_of(mat)->cos_h_min;
}

/* f 4 cos_i cos_o / D(h) with D the shape's: 0 where D is (the shape places no node there). */
static void tab_lobe_over_ndf(const wenv_material *mat, size_t i, const double wi[3], const double wo[3],
                              double rgb[3])
{
    table_f(table_of(mat), wi, wo, rgb);
    double h[3] = {wi[0] + wo[0], wi[1] + wo[1], wi[2] + wo[2]};
    double len = sqrt(h[0] * h[0] + h[1] * h[1] + h[2] * h[2]);
    const wenv_lobe *shape = &mat->lobes[i];
    double d = len > 0.0 ? wenv_ndf(shape->distribution, shape->roughness, h[2] / len) : 0.0;
    double k = d > 0.0 ? 4.0 * wi[2] * wo[2] / d : 0.0;
    for (int c = 0; c < 3; c++)
        rgb[c] *= k;
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
                shape_density = (double)n_shape * wenv_ndf(shape->distribution, shape->roughness, ch) * ch /
                                (4.0 * oh);
        }
        double total = shape_density + uniform_density;
        double share = total > 0.0 ? (k < n_shape ? shape_density : uniform_density) / total : (k < n_shape);
        double f[3];
        table_f(table_of(mat), w, wo, f);
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
    /* 2 samples^2 nodes, half the shape's and half uniform */
    size_t half = samples / 2 > 0 ? samples / 2 : 1;
    return mixed_rule(mat, i, wo, samples, half, samples, samples, wi, weight, NULL, count, err);
}

static wenv_status tab_lobe_albedo(const wenv_material *mat, size_t i, const double wo[3], size_t samples,
                                   double rgb[3], wenv_error *err)
{
    rgb[0] = rgb[1] = rgb[2] = 0.0;
    size_t max = 2 * samples * samples;
    double *wi = malloc(max * 6 * sizeof *wi);
    if (!wi)
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for a table's albedo");
    size_t count = 0;
    wenv_status st = tab_lobe_nodes(mat, i, wo, samples, wi, wi + 3 * max, &count, err);
    for (size_t k = 0; !st && k < count; k++)
        for (int c = 0; c < 3; c++)
            rgb[c] += wi[3 * max + 3 * k + (size_t)c];
    free(wi);
    return st;
}

/* 2 n_theta n_phi nodes: the shape's cells for half the theta divisions, uniform rings for the rest. */
static wenv_status tab_lobe_cells(const wenv_material *mat, size_t i, const double wo[3], size_t n_theta,
                                  size_t n_phi, double *wi, double *weight, double *solid_angle, size_t *count,
                                  wenv_error *err)
{
    size_t shape_theta = (n_theta + 1) / 2;
    return mixed_rule(mat, i, wo, shape_theta, n_phi, n_theta - shape_theta, 2 * n_phi, wi, weight, solid_angle,
                      count, err);
}

/* ---------------------------------------------------------------- making one */

static const wenv_material_kind TABULATED = {
    .name = "tabulated",
    .smooth_limit = 0,
    .specular_cos = tab_specular_cos,
    .specular_cos_batch = tab_specular_cos_batch,
    .view_terms = tab_view_terms,
    .prepare_view_f = tab_prepare_view_f,
    .specular_cos_f = tab_specular_cos_f,
    .lobe_cos_h_min = tab_lobe_cos_h_min,
    .lobe_value = tab_lobe_value,
    .lobe_over_ndf = tab_lobe_over_ndf,
    .lobe_albedo = tab_lobe_albedo,
    .lobe_nodes = tab_lobe_nodes,
    .lobe_cells = tab_lobe_cells,
    .with_roughness = NULL, /* a measurement has no roughness to set */
};

/* The shape: Beckmann, as wide as the table's half maximum in theta_h at theta_d = 0, phi_d = 0,
 * coloured so that it matches the table's peak (see the top comment). */
static wenv_lobe fit_shape(const table *t)
{
    wenv_lobe shape = {.specular = {1.0, 1.0, 1.0}, .roughness = 1.0, .ior = 1.5, .distribution = WENV_NDF_BECKMANN};
    const float *peak = t->rgb;
    double luma0 = 0.2126 * peak[0] + 0.7152 * peak[1] + 0.0722 * peak[2];
    if (!(luma0 > 0.0))
        return shape;
    for (size_t i = 1; i < t->n[0]; i++) {
        const float *v = t->rgb + 3 * t->n[2] * t->n[1] * i;
        double luma = 0.2126 * v[0] + 0.7152 * v[1] + 0.0722 * v[2];
        if (luma < 0.5 * luma0) {
            const float *u = t->rgb + 3 * t->n[2] * t->n[1] * (i - 1);
            double prev = 0.2126 * u[0] + 0.7152 * u[1] + 0.0722 * u[2];
            double x = (double)(i - 1) + (prev - 0.5 * luma0) / fmax(prev - luma, 1e-300);
            double q = x / (double)t->n[0], theta = q * q * 0.5 * M_PI;
            shape.roughness = fmin(1.0, fmax(1e-3, tan(theta) / sqrt(log(2.0))));
            break;
        }
    }
    /* a unit-coloured shape's f at the mirror of a normal view: F(1) D(0) / 4 (G = 1 there) */
    double unit = wenv_fresnel_dielectric(1.0, shape.ior) / (M_PI * shape.roughness * shape.roughness * 4.0);
    for (int c = 0; c < 3; c++)
        shape.specular[c] = peak[c] / unit;
    return shape;
}

wenv_status wenv_tabulated_create(wenv_material **out, const float *rgb, const size_t dims[3], wenv_error *err)
{
    *out = NULL;
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
    t->above = malloc(n);
    if (!t->above) {
        table_destroy(&t->shared);
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for a table");
    }
    /* with phi_h = 0: wi.z = cos th cos td - sin th sin td cos pd, wo.z = 2 cos td cos th - wi.z */
    for (size_t i = 0; i < dims[0]; i++)
        for (size_t j = 0; j < dims[1]; j++)
            for (size_t k = 0; k < dims[2]; k++) {
                double q = (double)i / (double)dims[0], th = q * q * 0.5 * M_PI;
                double td = (double)j / (double)dims[1] * 0.5 * M_PI, pd = (double)k / (double)dims[2] * M_PI;
                double zi = cos(th) * cos(td) - sin(th) * sin(td) * cos(pd), zo = 2.0 * cos(td) * cos(th) - zi;
                t->above[k + dims[2] * (j + dims[1] * i)] = zi > 0.0 && zo > 0.0;
            }
    atomic_init(&t->shared.refs, 1);
    t->shared.destroy = table_destroy;
    /* the exact lights' cone: past the last theta_h slab holding 1e-7 of the peak anywhere (the next
     * sample, as interpolation reaches it), or none */
    double peak = 0.0;
    for (size_t s = 0; s < n; s++)
        if (t->above[s])
            peak = fmax(peak, fmax(copy[3 * s], fmax(copy[3 * s + 1], copy[3 * s + 2])));
    size_t last = 0, slab = dims[1] * dims[2];
    for (size_t s = 0; s < n; s++)
        if (t->above[s] && fmax(copy[3 * s], fmax(copy[3 * s + 1], copy[3 * s + 2])) >= 1e-7 * peak)
            last = s / slab > last ? s / slab : last;
    double q = (double)(last + 2) / (double)dims[0];
    t->cos_h_min = last + 2 < dims[0] ? cos(q * q * 0.5 * M_PI) : -1.0;
    wenv_lobe shape = fit_shape(t);
    const double black[3] = {0.0, 0.0, 0.0};
    if (wenv_material_alloc(out, &TABULATED, black, &shape, 1, WENV_SHADOW_SMITH, err)) {
        table_destroy(&t->shared);
        return err->status;
    }
    (*out)->shared = &t->shared;
    return WENV_OK;
}

const float *wenv_tabulated_table(const wenv_material *mat, size_t dims[3])
{
    if (mat->kind != &TABULATED)
        return NULL;
    memcpy(dims, table_of(mat)->n, 3 * sizeof *dims);
    return table_of(mat)->rgb;
}
