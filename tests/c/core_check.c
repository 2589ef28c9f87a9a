/* The core without Python: materials through the material interface and every registered method
 * through the shading-method interface, checked against closed forms.  Built and run by
 * tests/test_core_c.py from csrc/ minus csrc/python/, which shows the layers below the bindings
 * stand on their own.  Prints one line per check and "N passed, N failed"; exits non-zero on a
 * failure. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "bake/margin.h"
#include "bake/texel_raster.h"
#include "methods/lamps/lamp_shading.h"
#include "methods/method.h"
#include "math/half.h"
#include "methods/wavelet/grazing_nodes.h"
#include "reference/reference.h"
#include "scene/bump_terminator.h"
#include "scene/envmap.h"
#include "scene/material_kind.h"

static int passed, failed;

static void check(int ok, const char *what, double got, double want)
{
    printf("%s %s: got %.9g, against %.9g\n", ok ? "ok  " : "FAIL", what, got, want);
    if (ok)
        passed++;
    else
        failed++;
}

static int near(double got, double want, double rel) { return fabs(got - want) <= rel * fabs(want) + 1e-12; }

/* A constant environment of radiance 1 (equirect 64 x 32). */
static wenv_envmap *white_environment(void)
{
    size_t w = 64, h = 32;
    float *px = malloc(w * h * 3 * sizeof(float));
    if (!px)
        return NULL;
    for (size_t i = 0; i < w * h * 3; i++)
        px[i] = 1.0f;
    wenv_envmap *env = NULL;
    wenv_error err = {0};
    if (wenv_envmap_create(&env, px, h, w, 3, WENV_PROJ_EQUIRECT, 0.0, 1.0, &err))
        fprintf(stderr, "environment: %s\n", err.message);
    free(px);
    return env;
}

static void check_materials(void)
{
    wenv_error err = {0};
    const double grey[3] = {0.5, 0.25, 1.0}, black[3] = {0.0, 0.0, 0.0};
    wenv_material *lambert = NULL, *ct = NULL;
    wenv_lobe lobes[2] = {{.specular = {1, 1, 1}, .alpha = 0.3, .ior = 1.5, .distribution = WENV_NDF_GGX},
                          {.specular = {0.5, 0.5, 0.5}, .alpha = 0.05, .ior = 1.5, .distribution = WENV_NDF_BECKMANN}};
    if (wenv_lambert_create(&lambert, grey, &err) || wenv_cook_torrance_create(&ct, black, lobes, 2, WENV_SHADOW_SMITH, &err)) {
        check(0, err.message, 0, 0);
        return;
    }
    double wi[3] = {0.6, 0.0, 0.8}, wo[3] = {-0.6, 0.0, 0.8}, rgb[3], albedo[3];
    wenv_material_eval_cos(lambert, wi, wo, rgb);
    check(near(rgb[0], 0.5 * 0.8 / M_PI, 1e-12), "Lambert f cos = albedo cos / pi", rgb[0], 0.5 * 0.8 / M_PI);
    check(wenv_material_lobe_count(lambert) == 0 && isinf(wenv_material_lobe_width(lambert)),
          "Lambert has no lobe and no width", (double)wenv_material_lobe_count(lambert), 0);
    check(wenv_material_lobe_width(ct) == 0.05, "Cook-Torrance width is its narrowest lobe", wenv_material_lobe_width(ct),
          0.05);
    /* a lobe's node rule integrates 1 to its albedo, RGB */
    size_t samples = 64, count = 0;
    double *nodes = malloc(2 * samples * samples * 3 * sizeof(double)), *weights = malloc(2 * samples * samples * 3 * sizeof(double));
    double lobe_albedo[3], sum[3] = {0, 0, 0};
    if (!nodes || !weights || wenv_material_lobe_nodes(ct, 1, wo, samples, nodes, weights, &count, &err) ||
        wenv_material_lobe_albedo(ct, 1, wo, samples, lobe_albedo, &err)) {
        check(0, "lobe rules", 0, 0);
    } else {
        for (size_t k = 0; k < count; k++)
            for (int c = 0; c < 3; c++)
                sum[c] += weights[3 * k + c];
        check(near(sum[0], lobe_albedo[0], 1e-9), "lobe nodes' weights sum to its albedo", sum[0], lobe_albedo[0]);
    }
    free(nodes);
    free(weights);
    /* the float path agrees with the double one */
    float terms[8], wif[3] = {0.6f, 0.0f, 0.8f}, wof[3] = {-0.6f, 0.0f, 0.8f}, rgbf[3];
    wenv_material_prepare_view_f(ct, wof, terms);
    wenv_material_specular_cos_f_many(ct, wof, terms, 1, &wif[0], &wif[1], &wif[2], &rgbf[0], &rgbf[1], &rgbf[2]);
    wenv_material_specular_cos(ct, wi, wo, rgb);
    check(near(rgbf[0], rgb[0], 1e-4), "float and double evaluation agree", rgbf[0], rgb[0]);
    /* the lobes add up to the glossy part; a lobe over its shape's D, times D / (4 cos cos), is the lobe */
    double lobe0[3], lobe1[3], over[3];
    wenv_material_lobe_value(ct, 0, wi, wo, lobe0);
    wenv_material_lobe_value(ct, 1, wi, wo, lobe1);
    check(near((lobe0[0] + lobe1[0]) * wi[2], rgb[0], 1e-12), "lobe values add up to the glossy part",
          (lobe0[0] + lobe1[0]) * wi[2], rgb[0]);
    double h[3] = {0.0, 0.0, 1.0}; /* the half vector of this mirror pair */
    const wenv_lobe *shape = wenv_material_lobe(ct, 0);
    wenv_material_lobe_over_ndf(ct, 0, wi, wo, over);
    double back = over[0] * wenv_ndf(shape->distribution, shape->alpha, h[2]) / (4.0 * wi[2] * wo[2]);
    check(near(back, lobe0[0], 1e-12), "a lobe over its shape's D gives the lobe back", back, lobe0[0]);
    double cut = wenv_material_lobe_cos_h_min(ct, 1);
    check(cut > 0.0 && cut < 1.0, "a narrow lobe has a cone for the exact lights", cut, 1.0);
    if (wenv_material_albedo(ct, wo, 128, albedo, &err) == WENV_OK)
        check(albedo[0] > 0.0 && albedo[0] < 1.0, "Cook-Torrance albedo in (0, 1)", albedo[0], 1.0);
    wenv_material_free(lambert);
    wenv_material_free(ct);
}

/* The largest relative difference of a and b over n values, against the largest of them. */
static double worst_difference(const double *a, const double *b, size_t n)
{
    double diff = 0.0, scale = 0.0;
    for (size_t k = 0; k < n; k++) {
        diff = fmax(diff, fabs(a[k] - b[k]));
        scale = fmax(scale, fmax(fabs(a[k]), fabs(b[k])));
    }
    return scale > 0.0 ? diff / scale : diff;
}

/* A model's accelerators against the defaults derived from its lobe_value (material_kind.h): the
 * interface's promise that an accelerator only makes faster what lobe_value defines. */
static void check_accelerators(const char *name, const wenv_material *mat)
{
    enum { N = 64, S = 16 };
    const double wo[3] = {0.6, 0.1, sqrt(1.0 - 0.37)};
    const float wof[3] = {(float)wo[0], (float)wo[1], (float)wo[2]};
    float wi[3 * N], x[N], y[N], z[N], fast[3 * N], slow[3 * N], r[N], g[N], b[N], r2[N], g2[N], b2[N];
    for (size_t k = 0; k < N; k++) { /* directions over the hemisphere and a few below it */
        double u = ((double)k + 0.5) / N, phi = 2.39996322972865332 * (double)k, c = 1.1 * u - 0.1;
        double s = sqrt(fmax(0.0, 1.0 - c * c));
        x[k] = wi[3 * k] = (float)(s * cos(phi));
        y[k] = wi[3 * k + 1] = (float)(s * sin(phi));
        z[k] = wi[3 * k + 2] = (float)c;
    }
    double a[3 * N], d[3 * N];
    char what[200];
    const wenv_material_kind *kind = mat->kind;
    if (kind->specular_cos_batch) {
        wenv_material_specular_cos_batch(mat, wo, wi, N, fast);
        wenv_material_derived_specular_cos_batch(mat, wo, wi, N, slow);
        for (size_t k = 0; k < 3 * N; k++) {
            a[k] = fast[k];
            d[k] = slow[k];
        }
        snprintf(what, sizeof what, "%s: the batched evaluation is lobe_value's", name);
        check(worst_difference(a, d, 3 * N) < 1e-6, what, worst_difference(a, d, 3 * N), 0.0);
    }
    float terms[64];
    if (kind->specular_cos_f_many && wenv_material_view_terms(mat) <= 64) {
        wenv_material_prepare_view_f(mat, wof, terms);
        wenv_material_specular_cos_f_many(mat, wof, terms, N, x, y, z, r, g, b);
        wenv_material_derived_specular_cos_f_many(mat, wof, N, x, y, z, r2, g2, b2);
        for (size_t k = 0; k < N; k++) {
            a[3 * k] = r[k], a[3 * k + 1] = g[k], a[3 * k + 2] = b[k];
            d[3 * k] = r2[k], d[3 * k + 1] = g2[k], d[3 * k + 2] = b2[k];
        }
        snprintf(what, sizeof what, "%s: the float evaluation is lobe_value's to float's accuracy", name);
        check(worst_difference(a, d, 3 * N) < 1e-4, what, worst_difference(a, d, 3 * N), 0.0);
    }
    wenv_error err = {0};
    double *nodes = malloc(4 * 2 * S * S * 3 * sizeof *nodes);
    if (!nodes) {
        check(0, "out of memory", 0, 0);
        return;
    }
    double *w_fast = nodes + 2 * S * S * 3, *w_slow = w_fast + 2 * S * S * 3, *omega = w_slow + 2 * S * S * 3;
    for (size_t i = 0; i < wenv_material_lobe_count(mat); i++) {
        double dir[3] = {wi[3 * 40], wi[3 * 40 + 1], wi[3 * 40 + 2]};
        if (kind->lobe_over_ndf) {
            double fo[3], so[3];
            wenv_material_lobe_over_ndf(mat, i, dir, wo, fo);
            wenv_material_derived_lobe_over_ndf(mat, i, dir, wo, so);
            snprintf(what, sizeof what, "%s lobe %zu: over its shape's D as lobe_value gives it", name, i);
            check(worst_difference(fo, so, 3) < 1e-9, what, worst_difference(fo, so, 3), 0.0);
        }
        if (kind->lobe_cells) {
            size_t n_fast = 0, n_slow = 0;
            double sum_fast[3] = {0, 0, 0}, sum_slow[3] = {0, 0, 0};
            if (wenv_material_lobe_cells(mat, i, wo, S, S, nodes, w_fast, omega, &n_fast, &err) ||
                wenv_material_derived_lobe_cells(mat, i, wo, S, S, nodes, w_slow, omega, &n_slow, &err)) {
                check(0, err.message, 0, 0);
                continue;
            }
            for (size_t k = 0; k < n_fast; k++)
                for (int c = 0; c < 3; c++)
                    sum_fast[c] += w_fast[3 * k + (size_t)c];
            for (size_t k = 0; k < n_slow; k++)
                for (int c = 0; c < 3; c++)
                    sum_slow[c] += w_slow[3 * k + (size_t)c];
            /* different rules may integrate the same lobe: they agree to the rules' accuracy */
            snprintf(what, sizeof what, "%s lobe %zu: its cells hold the mass the derived cells hold", name, i);
            check(worst_difference(sum_fast, sum_slow, 3) < 0.02, what, worst_difference(sum_fast, sum_slow, 3), 0.0);
        }
        if (kind->lobe_albedo) {
            double alb_fast[3], alb_slow[3];
            if (wenv_material_lobe_albedo(mat, i, wo, S, alb_fast, &err) ||
                wenv_material_derived_lobe_albedo(mat, i, wo, S, alb_slow, &err)) {
                check(0, err.message, 0, 0);
                continue;
            }
            snprintf(what, sizeof what, "%s lobe %zu: its albedo is the derived one", name, i);
            check(worst_difference(alb_fast, alb_slow, 3) < 0.02, what, worst_difference(alb_fast, alb_slow, 3), 0.0);
        }
        if (kind->lobe_cos_h_min && wenv_material_lobes_follow_shapes(mat)) {
            double cut = wenv_material_lobe_cos_h_min(mat, i), derived = wenv_material_derived_lobe_cos_h_min(mat, i);
            snprintf(what, sizeof what, "%s lobe %zu: its cone for the exact lights is its shape's", name, i);
            check(cut == derived, what, cut, derived);
        }
    }
    free(nodes);
}

static void check_models(void)
{
    wenv_error err = {0};
    const double black[3] = {0.0, 0.0, 0.0};
    wenv_lobe lobes[2] = {{.specular = {1, 0.8, 0.6}, .alpha = 0.3, .ior = 1.5, .distribution = WENV_NDF_GGX},
                          {.specular = {0.5, 0.5, 0.5}, .alpha = 0.1, .ior = 1.7, .distribution = WENV_NDF_BECKMANN}};
    wenv_material *ct = NULL, *cavity = NULL, *coated = NULL, *sheen = NULL, *table = NULL;
    wenv_principled_inputs in;
    wenv_principled_defaults(&in);
    in.metallic = 0.5;
    in.coat_weight = 1.0;
    in.coat_roughness = 0.02; /* narrow enough for a cone */
    in.roughness = 0.4;
    wenv_principled_inputs soft;
    wenv_principled_defaults(&soft);
    soft.sheen_weight = 1.0;
    soft.diffuse_roughness = 0.7;
    /* a small table of a smooth lobe */
    size_t dims[3] = {16, 16, 32}, n = dims[0] * dims[1] * dims[2];
    float *rgb = malloc(3 * n * sizeof *rgb);
    for (size_t k = 0; rgb && k < n; k++) {
        double th = pow((double)(k / (dims[1] * dims[2])) / (double)dims[0], 2.0) * 0.5 * M_PI;
        for (int c = 0; c < 3; c++)
            rgb[3 * k + (size_t)c] = (float)(0.05 + 2.0 * exp(-th * th / 0.02));
    }
    if (!rgb || wenv_cook_torrance_create(&ct, black, lobes, 2, WENV_SHADOW_SMITH, &err) ||
        wenv_cook_torrance_create(&cavity, black, lobes, 1, WENV_SHADOW_VCAVITY, &err) ||
        wenv_principled_create(&coated, &in, &err) || wenv_principled_create(&sheen, &soft, &err) ||
        wenv_tabulated_create(&table, rgb, dims, WENV_SAMPLES_AT_CENTRES, &err)) {
        check(0, err.message[0] ? err.message : "out of memory", 0, 0);
    } else {
        check_accelerators("Cook-Torrance", ct);
        check_accelerators("Cook-Torrance (V-cavity)", cavity);
        check_accelerators("Principled (coated metal)", coated);
        check_accelerators("Principled (sheen, rough diffuse)", sheen);
        check_accelerators("tabulated", table);
    }
    free(rgb);
    wenv_material_free(ct);
    wenv_material_free(cavity);
    wenv_material_free(coated);
    wenv_material_free(sheen);
    wenv_material_free(table);
}

/* Every method, with its default preset, shades a Lambertian material under a white environment to
 * its albedo (what each promises for a constant environment, to its own accuracy). */
static void check_methods(const wenv_envmap *env)
{
    wenv_error err = {0};
    const double albedo[3] = {0.8, 0.5, 0.2};
    wenv_material *mat = NULL;
    if (wenv_lambert_create(&mat, albedo, &err)) {
        check(0, err.message, 0, 0);
        return;
    }
    float normals[4 * 3] = {0, 0, 1, 1, 0, 0, 0, -1, 0, 0.6f, 0, -0.8f};
    float views[4 * 3] = {0, 0.6f, 0.8f, 0.8f, 0, 0.6f, 0, -1, 0, 1, 0, 0};
    for (size_t i = 0; i < wenv_method_count(); i++) {
        const wenv_method *m = wenv_method_at(i);
        const void *quality = wenv_method_preset(m, "draft");
        wenv_method_setup setup = {.cache = WENV_CACHE_NONE};
        void *state = NULL;
        float out[4 * 3];
        char what[160];
        snprintf(what, sizeof what, "%s: a white environment reflects the albedo", m->name);
        if (!quality || m->check_quality(quality, &err) || m->create(&state, quality, &setup, &err) ||
            m->set_environment(state, env, NULL, &err) || m->set_material(state, mat, NULL, &err) ||
            m->shade(state, normals, views, 4, out, NULL, &err)) {
            check(0, err.message[0] ? err.message : what, 0, 0);
        } else {
            double worst = 0.0;
            for (int k = 0; k < 4; k++)
                for (int c = 0; c < 3; c++)
                    worst = fmax(worst, fabs(out[3 * k + c] - albedo[c]) / albedo[c]);
            check(worst < 0.02, what, worst, 0.0);
            /* the Lambertian part's light given apart, times the colour per unit, is the whole */
            float rest[4 * 3], irradiance[4 * 3];
            wenv_diffuse_table per_colour;
            snprintf(what, sizeof what, "%s: the Lambertian part's light apart, coloured, is the whole", m->name);
            if (m->shade(state, normals, views, 4, rest, irradiance, &err) ||
                wenv_material_diffuse_per_colour_table(mat, &per_colour, &err)) {
                check(0, err.message, 0, 0);
            } else {
                double apart = 0.0;
                for (int k = 0; k < 4; k++)
                    for (int c = 0; c < 3; c++) {
                        double whole = rest[3 * k + c] + albedo[c] * per_colour.over_pi[c] * irradiance[3 * k + c];
                        apart = fmax(apart, fabs(whole - out[3 * k + c]) / albedo[c]);
                    }
                check(apart < 1e-5, what, apart, 0.0);
            }
            wenv_stat stats[WENV_STATS_MAX];
            size_t n = m->stats(state, stats);
            snprintf(what, sizeof what, "%s: reports stats", m->name);
            check(n > 0 && n <= WENV_STATS_MAX, what, (double)n, 1);
        }
        if (state)
            m->destroy(state);
        err = (wenv_error){0};
    }
    check(wenv_method_named("no such method") == NULL, "unknown methods are not found", 0, 0);
    float ref[4 * 3];
    if (wenv_reference(env, mat, normals, views, 4, NULL, NULL, NULL, NULL, NULL, 0, NULL, NULL, ref, NULL, &err) == WENV_OK)
        check(near(ref[0], albedo[0], 2e-3), "the reference reflects the albedo (pixel sums, 64 x 32)", ref[0], albedo[0]);
    wenv_material_free(mat);
}

/* The grazing path's node loop chosen for this CPU (AVX-512, AVX2 or portable) against the portable
 * one, on random nodes over a random pyramid, edges of the octahedral square and every level
 * included. */
static void check_grazing_nodes(void)
{
    enum { LEVELS = 6, NODES = 64, STRIDE = 64 };
    size_t sides[LEVELS], total = 0;
    for (int k = 0; k < LEVELS; k++) {
        sides[k] = (size_t)32 >> k;
        total += sides[k] * sides[k];
    }
    wenv_node_pyramid p = {.lod_offset = 3.5f};
    float *rgb = malloc(total * 3 * sizeof(float)), *a = malloc(2 * 7 * STRIDE * sizeof(float));
    const float *levels[LEVELS];
    uint16_t *texels = NULL;
    unsigned state = 12345u;
#define NEXT_UNIFORM() ((state = state * 1664525u + 1013904223u), (float)(state >> 8) / 16777216.0f)
    if (rgb) {
        for (size_t i = 0; i < total * 3; i++) /* over six decades: halves' range, and their subnormals */
            rgb[i] = 3.0f * powf(10.0f, -6.0f * NEXT_UNIFORM());
        for (size_t k = 0, at = 0; k < LEVELS; at += 3 * sides[k] * sides[k], k++)
            levels[k] = rgb + at;
        texels = wenv_node_pyramid_make(&p, levels, sides, LEVELS);
    }
    if (!rgb || !texels || !a) {
        check(0, "memory for the node check", 0, 0);
        free(rgb);
        free(texels);
        free(a);
        return;
    }
    /* each padded texel holds its own texel, or across an edge the one mirrored on that edge, within
     * half's rounding (2^-11, or 2^-25 of the scale below its normal numbers) */
    int exact = p.top == LEVELS - 1;
    for (int k = 0; k < LEVELS && exact; k++) {
        int32_t side = p.side[k], row = side + 2;
        for (int32_t pj = 0; pj < row && exact; pj++)
            for (int32_t pi = 0; pi < row && exact; pi++) {
                int32_t i = pi - 1, j = pj - 1;
                if (i < 0 || i >= side) { /* fold across the left or right edge */
                    i = i < 0 ? 0 : side - 1;
                    j = side - 1 - j;
                }
                if (j < 0 || j >= side) {
                    j = j < 0 ? 0 : side - 1;
                    i = side - 1 - i;
                }
                const uint16_t *t = texels + 4 * ((size_t)p.offset[k] + (size_t)(pj * row + pi));
                const float *want = levels[k] + 3 * (size_t)(j * side + i);
                exact = t[3] == 0;
                for (int c = 0; c < 3; c++)
                    exact = exact && fabsf(wenv_float_from_half(t[c]) * p.scale - want[c]) <=
                                         fmaxf(want[c] * 4.9e-4f, p.scale * 3e-8f);
            }
    }
    check(exact, "the pyramid's halves hold each texel and its folds within half's rounding", exact, 1);
    /* pads that must not be read: infinity */
    for (int k = 0; k < LEVELS; k++)
        for (int32_t t = 0; t < (p.side[k] + 2) * (p.side[k] + 2); t++)
            texels[4 * ((size_t)p.offset[k] + (size_t)t) + 3] = 0x7c00;
    for (int e = 0; e < 2; e++)
        for (int k = 0; k < NODES; k++) {
            float *entry = a + e * 7 * STRIDE;
            float th = 3.14159265f * NEXT_UNIFORM(), ph = 6.2831853f * NEXT_UNIFORM();
            entry[k] = sinf(th) * cosf(ph);
            entry[STRIDE + k] = sinf(th) * sinf(ph);
            entry[2 * STRIDE + k] = cosf(th);
            for (int c = 3; c < 6; c++)
                entry[c * STRIDE + k] = NEXT_UNIFORM();
            entry[6 * STRIDE + k] = -10.0f + 12.0f * NEXT_UNIFORM(); /* below level 0 to past the top */
        }
#undef NEXT_UNIFORM
    float x[3] = {0.6f, 0.8f, 0.0f}, y[3] = {0.0f, 0.0f, 1.0f}, z[3] = {0.8f, -0.6f, 0.0f}, want[3], got[3];
    wenv_grazing_nodes_portable(a, a + 7 * STRIDE, STRIDE, NODES, 0.3f, 0.7f, x, y, z, &p, want);
    /* every vector version this CPU runs (AVX2 on an AVX-512 machine too), each colour */
    double worst = 0.0;
    int versions = 0;
    for (int which = 1; which <= 2; which++) {
        wenv_grazing_nodes_fn fn = wenv_grazing_nodes_version(which);
        if (!fn)
            continue;
        versions++;
        fn(a, a + 7 * STRIDE, STRIDE, NODES, 0.3f, 0.7f, x, y, z, &p, got);
        for (int c = 0; c < 3; c++)
            worst = fmax(worst, fabs((double)got[c] - want[c]) / fmax(1e-30, fabs((double)want[c])));
    }
    check(worst <= 1e-5, "every grazing node loop this CPU runs equals the portable one", worst, 1e-5);
    check(want[0] > 0.0f && want[1] > 0.0f && want[2] > 0.0f, "the node loop reads the lighting", want[0], 0);
    wenv_grazing_nodes_fn best = wenv_grazing_nodes_version(2) ? wenv_grazing_nodes_version(2)
                                 : wenv_grazing_nodes_version(1) ? wenv_grazing_nodes_version(1)
                                                                 : wenv_grazing_nodes_version(0);
    check(wenv_grazing_nodes_for_cpu() == best && best, "the shading runs the best node loop this CPU has", versions,
          versions);
    /* single reads (a shadow's blocked texels): the CPU's conversion of a tap's halves, where it has
     * one, reads what the portable read does, to the bit */
    int same = 1, by_cpu = p.halves_by_cpu;
    for (int k = 0; k < NODES && same; k++) {
        float d[3] = {a[k], a[STRIDE + k], a[2 * STRIDE + k]}, portable[3], fast[3];
        p.halves_by_cpu = 0;
        wenv_node_pyramid_read(&p, d, a[6 * STRIDE + k], portable);
        p.halves_by_cpu = by_cpu;
        wenv_node_pyramid_read(&p, d, a[6 * STRIDE + k], fast);
        same = memcmp(portable, fast, sizeof fast) == 0 && portable[0] > 0.0f;
    }
    check(same, "a single pyramid read is the portable one's to the bit", same, 1);
    free(rgb);
    free(texels);
    free(a);
}

/* A point lamp of radius 0 over a Lambertian floor: P / (4 pi d^2) cos, times albedo / pi. */
static void check_lamps(void)
{
    wenv_lamp_settings settings;
    wenv_lamp_settings_defaults(&settings, WENV_LAMP_POINT);
    settings.energy = 100.0;
    settings.matrix[3] = 1.0; /* at (1, 0, 2) */
    settings.matrix[11] = 2.0;
    wenv_lamp lamp;
    wenv_error err = {0};
    wenv_material *mat = NULL;
    wenv_lamp_light *light = NULL;
    const float position[3] = {0.0f, 0.0f, 0.0f}, normal[3] = {0.0f, 0.0f, 1.0f};
    float out[3] = {0.0f, 0.0f, 0.0f};
    if (wenv_lamp_make(&lamp, &settings, "lamp", &err) || wenv_lambert_create(&mat, (double[3]){0.5, 0.5, 0.5}, &err) ||
        wenv_lamp_light_ensure(&light, &lamp, 1, position, normal, 1, NULL, NULL, &err)) {
        check(0, err.message, 0.0, 0.0);
    } else {
        wenv_lamp_rows rows = {light, NULL, 0};
        wenv_lamps_add(&rows, mat, NULL, NULL, normal, normal, 1, out, &err);
        double d2 = 5.0, want = 100.0 / (4.0 * M_PI * d2) * (2.0 / sqrt(d2)) * 0.5 / M_PI;
        check(near(out[0], want, 1e-5), "a point lamp over a Lambertian floor", out[0], want);
    }
    wenv_lamp_light_free(light);
    wenv_material_free(mat);
}

/* A 5 x 5 grid of quads over the square, each split one way or the other and every other triangle
 * wound backwards, on 40 x 30 texels (edges through centres): every centre in exactly one triangle;
 * then the margin of one texel about a 2 x 2 island reaches its 12 neighbours and no further. */
static void check_bake(void)
{
    enum { Q = 5, W = 40, H = 30 };
    float uv[2 * (Q + 1) * (Q + 1)];
    uint32_t tris[3 * 2 * Q * Q];
    for (int j = 0; j <= Q; j++)
        for (int i = 0; i <= Q; i++) {
            uv[2 * (j * (Q + 1) + i)] = (float)i / Q;
            uv[2 * (j * (Q + 1) + i) + 1] = (float)j / Q;
        }
    size_t t = 0;
    for (int j = 0; j < Q; j++)
        for (int i = 0; i < Q; i++) {
            uint32_t a = (uint32_t)(j * (Q + 1) + i), b = a + 1, c = a + Q + 2, d = a + Q + 1;
            uint32_t quad[2][3] = {{a, b, c}, {a, c, d}};
            if ((i + j) % 2) {
                uint32_t other[2][3] = {{a, b, d}, {b, c, d}};
                memcpy(quad, other, sizeof quad);
            }
            for (int k = 0; k < 2; k++, t++)
                for (int v = 0; v < 3; v++)
                    tris[3 * t + v] = quad[k][(t % 2) ? 2 - v : v];
        }
    int32_t *triangle = malloc(W * H * sizeof *triangle);
    float *weights = malloc(2 * W * H * sizeof *weights);
    size_t covered = 0, overlapped = 0;
    wenv_error err = {0};
    if (!triangle || !weights || wenv_texel_raster(uv, (Q + 1) * (Q + 1), tris, t, W, H, 0, triangle, weights,
                                                   &covered, &overlapped, NULL, &err)) {
        check(0, err.message[0] ? err.message : "texel raster", 0, 0);
    } else {
        double worst = 0.0;
        for (int y = 0; y < H; y++)
            for (int x = 0; x < W; x++) {
                size_t at = (size_t)(y * W + x);
                const uint32_t *c = tris + 3 * (size_t)triangle[at];
                double wb = weights[2 * at], wc = weights[2 * at + 1], wa = 1.0 - wb - wc;
                for (int k = 0; k < 2; k++) {
                    double p = wa * uv[2 * c[0] + k] + wb * uv[2 * c[1] + k] + wc * uv[2 * c[2] + k];
                    double want = k ? (y + 0.5) / H : (x + 0.5) / W;
                    worst = fmax(worst, fabs(p - want));
                }
            }
        check(covered == W * H && overlapped == 0, "a tiling covers each texel once", (double)covered, W * H);
        check(worst < 1e-6, "the weights give each texel centre back", worst, 0.0);
    }
    free(triangle);
    free(weights);
    float pixels[8 * 8];
    uint8_t filled[8 * 8] = {0};
    for (int i = 0; i < 64; i++)
        pixels[i] = -1.0f;
    for (int y = 3; y < 5; y++)
        for (int x = 3; x < 5; x++) {
            pixels[y * 8 + x] = 2.0f;
            filled[y * 8 + x] = 1;
        }
    size_t added = 0;
    int ring_ok = !wenv_extend_margin(pixels, filled, 8, 8, 1, 1, &added, &err);
    for (int y = 0; y < 8; y++)
        for (int x = 0; x < 8; x++) {
            int near_island = x >= 2 && x <= 5 && y >= 2 && y <= 5;
            ring_ok &= near_island ? (filled[y * 8 + x] && pixels[y * 8 + x] == 2.0f)
                                   : (!filled[y * 8 + x] && pixels[y * 8 + x] == -1.0f);
        }
    check(ring_ok && added == 12, "a margin of one texel fills the island's ring and no more", (double)added, 12);
}

/* A GGX lobe cut in two (wenv_slope_part): on their slope grids its core's weights sum to the
 * integral of the lobe times the core's share of D, its tail's to the rest, and the two to the
 * lobe's albedo -- for a Cook-Torrance lobe and a Principled metal, views from the normal to 88
 * degrees.  The core's reference is the lobe's own fine rule weighted by the share node by node. */
static void check_ggx_cut(void)
{
    wenv_error err = {0};
    const double black[3] = {0.0, 0.0, 0.0};
    wenv_lobe lobe = {.specular = {0.9, 0.6, 0.3}, .alpha = 0.09, .ior = 1.5, .distribution = WENV_NDF_GGX};
    wenv_principled_inputs in;
    wenv_principled_defaults(&in);
    in.base_color[0] = 0.9, in.base_color[1] = 0.6, in.base_color[2] = 0.3;
    in.metallic = 1.0;
    in.roughness = 0.3;
    wenv_material *mats[2] = {NULL, NULL};
    double *buf = malloc(2 * 1024 * 1024 * 6 * sizeof *buf);
    if (!buf || wenv_cook_torrance_create(&mats[0], black, &lobe, 1, WENV_SHADOW_SMITH, &err) ||
        wenv_principled_create(&mats[1], &in, &err)) {
        check(0, buf ? err.message : "out of memory", 0, 0);
        free(buf);
        wenv_material_free(mats[0]);
        return;
    }
    const double cut = 0.1, degrees[5] = {0.0, 30.0, 60.0, 80.0, 88.0};
    double worst_sum = 0.0, worst_core = 0.0, worst_grazing = 0.0, worst_core_grazing = 0.0, metal_ratio = 0.0;
    for (int m = 0; m < 2; m++)
        for (int d = 0; d < 5; d++) {
            double th = degrees[d] * M_PI / 180.0, wo[3] = {sin(th), 0.0, cos(th)};
            double whole[3] = {0, 0, 0}, core[3] = {0, 0, 0}, got[2][3] = {{0, 0, 0}, {0, 0, 0}};
            double wi[3 * 96], weight[3 * 96], size[96];
            size_t count = 0;
            /* the reference: the lobe's own rule of 2 x 1024^2 nodes, the core's share node by node */
            if (wenv_material_lobe_nodes(mats[m], 0, wo, 1024, buf, buf + 3 * 2 * 1024 * 1024, &count, &err)) {
                check(0, err.message, 0, 0);
                continue;
            }
            for (size_t k = 0; k < count; k++) {
                const double *wi = buf + 3 * k, *w = buf + 3 * 2 * 1024 * 1024 + 3 * k;
                double h[3] = {wi[0] + wo[0], wi[1] + wo[1], wi[2] + wo[2]};
                double share = wenv_ggx_core_share(0.09, cut, (h[0] * h[0] + h[1] * h[1]) / (h[2] * h[2]));
                for (int c = 0; c < 3; c++) {
                    whole[c] += w[c];
                    core[c] += w[c] * share;
                }
            }
            for (int part = 0; part < 2; part++) {
                wenv_slope_part sp = {cut, part};
                size_t n = part ? 8 : 16, rows = part ? 4 : 6;
                if (wenv_material_lobe_slope_cells(mats[m], 0, wo, n, rows, sp, wi, weight, size, &count, &err)) {
                    check(0, err.message, 0, 0);
                    continue;
                }
                for (size_t k = 0; k < count; k++)
                    for (int c = 0; c < 3; c++)
                        got[part][c] += weight[3 * k + (size_t)c];
            }
            /* the rule the cut replaced: one GGX grid of 16 x 6 */
            double one[3] = {0, 0, 0};
            wenv_slope_part whole_lobe = {0.0, 0};
            if (wenv_material_lobe_slope_cells(mats[m], 0, wo, 16, 6, whole_lobe, wi, weight, size, &count, &err))
                check(0, err.message, 0, 0);
            for (size_t k = 0; k < count; k++)
                for (int c = 0; c < 3; c++)
                    one[c] += weight[3 * k + (size_t)c];
            for (int c = 0; c < 3; c++) {
                double sum_err = fabs(got[0][c] + got[1][c] - whole[c]) / whole[c];
                double core_err = fabs(got[0][c] - core[c]) / core[c];
                if (degrees[d] <= 60.0) {
                    worst_sum = fmax(worst_sum, sum_err);
                    worst_core = fmax(worst_core, core_err);
                } else { /* towards grazing: within 0.8 % at 80 degrees, 3 % at 88 */
                    worst_grazing = fmax(worst_grazing, sum_err / (degrees[d] <= 80.0 ? 0.008 : 0.03));
                    worst_core_grazing = fmax(worst_core_grazing, core_err);
                    if (m == 1) /* the metal: against the one grid's error there */
                        metal_ratio = fmax(metal_ratio, sum_err / (fabs(one[c] - whole[c]) / whole[c]));
                }
            }
        }
    check(worst_sum <= 0.004, "a GGX lobe's core and tail cells sum to its albedo, views to 60 degrees", worst_sum, 0.004);
    check(worst_core <= 0.003, "a GGX lobe's core cells hold its core's share, views to 60 degrees", worst_core, 0.003);
    check(worst_grazing <= 1.0, "... within 0.8 % at 80 degrees and 3 % at 88 (as a share of those bounds)",
          worst_grazing, 1.0);
    check(worst_core_grazing <= 0.01, "... and the core's share within 1 % there", worst_core_grazing, 0.01);
    /* the metal's at 80 and 88 degrees: 0.6 and 2.7 % under its albedo, one GGX grid's 2.0 and 6.4 % */
    check(metal_ratio <= 0.5, "a Principled metal's cut cells are at most half as far off there as one GGX grid's",
          metal_ratio, 0.5);
    wenv_slope_part bad = {0.1, 0};
    wenv_lobe beckmann = lobe;
    beckmann.distribution = WENV_NDF_BECKMANN;
    wenv_material *b = NULL;
    double wi[3], weight[3], size[1], wo[3] = {0.0, 0.0, 1.0};
    size_t count;
    int refused = !wenv_cook_torrance_create(&b, black, &beckmann, 1, WENV_SHADOW_SMITH, &err) &&
                  wenv_material_lobe_slope_cells(b, 0, wo, 1, 1, bad, wi, weight, size, &count, &err) == WENV_ERR_VALUE;
    check(refused, "a cut of a lobe that is not GGX is refused", refused, 1);
    wenv_material_free(b);
    wenv_material_free(mats[0]);
    wenv_material_free(mats[1]);
    free(buf);
}

/* Cycles' bump terminator (scene/bump_terminator.h): without correction a bent Lambertian part keeps
 * (1 + cos bend) / 2 of a uniform sky (the part of its cosine lobe above the smooth horizon); with it,
 * what Cycles 5.0 renders of a white plane bent by a normal map under a white sky (512 samples). */
static void check_bump_terminator(void)
{
    const double bends[] = {30.0, 45.0, 60.0}, cycles[] = {0.8787, 0.7432, 0.5654};
    double worst_off = 0.0, worst_on = 0.0;
    for (int k = 0; k < 3; k++) {
        double d = bends[k] * M_PI / 180.0;
        float n[3] = {(float)sin(d), 0.0f, (float)cos(d)}, up[3] = {0.0f, 0.0f, 1.0f}, off, on;
        wenv_bump_share_rows(n, up, 1, 0, &off);
        wenv_bump_share_rows(n, up, 1, 1, &on);
        worst_off = fmax(worst_off, fabs(off - 0.5 * (1.0 + cos(d))));
        worst_on = fmax(worst_on, fabs(on - cycles[k]));
    }
    check(worst_off < 1e-4, "a bent part keeps (1 + cos bend) / 2 of a uniform sky without correction", worst_off,
          1e-4);
    check(worst_on < 2e-3, "with correction, what Cycles renders of a bent white plane", worst_on, 2e-3);
}

int main(void)
{
    check_bump_terminator();
    check_ggx_cut();
    check_lamps();
    check_bake();
    check_grazing_nodes();
    check_materials();
    check_models();
    wenv_envmap *env = white_environment();
    if (env) {
        check_methods(env);
        wenv_envmap_free(env);
    } else {
        check(0, "white environment", 0, 0);
    }
    printf("%d passed, %d failed\n", passed, failed);
    return failed ? 1 : 0;
}
