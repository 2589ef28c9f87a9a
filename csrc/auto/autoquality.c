#include "auto/autoquality.h"

#include <math.h>
#include <omp.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "math/maps.h"
#include "scene/envmap_octahedral.h"
#include "math/spherical_harmonics.h"
#include "scene/envmap_sh.h"
#include "methods/wavelet/lights.h"
#include "methods/wavelet/slice_operators.h"
#include "methods/wavelet/wavelet.h"


/* Median relative RMSE over the bundled HDRIs per level (rows) at roughness 0.05, 0.1, 0.2, 0.5
 * and for Lambert (last column), as benchmarks/auto_quality.py estimates it (high as a control variate
 * on 50000 pairs weighted toward the bright reflections, the reference on 8000), --calibrate. */
static const double ROUGHNESS[4] = {0.05, 0.1, 0.2, 0.5};
static const double MEDIAN_ERROR[WENV_AUTO_LEVELS][5] = {
    {0.13151, 0.15083, 0.13559, 0.07411, 0.01108},
    {0.07523, 0.07632, 0.05140, 0.02507, 0.00333},
    {0.06002, 0.04847, 0.03684, 0.01752, 0.00275},
    {0.00844, 0.00412, 0.00636, 0.01366, 0.00275},
    {0.05008, 0.02951, 0.01881, 0.00755, 0.00099},
    {0.00431, 0.00253, 0.00277, 0.00507, 0.00105},
    {0.00405, 0.00179, 0.00288, 0.00469, 0.00089},
};
/* A level's error under an environment is its median error times a factor of three measures
 * (estimate_levels): l, the share of the flux its lights take (exact: the rest carries the error),
 * c, the share in bright extended features it leaves in the lighting, and d, its lights' dominance
 * of the reflected signal under the narrowest lobe.  For the levels without the grazing path the
 * factor is
 *     SCALE ((1 - l) + CONTRAST_SLOPE c) / (1 + d)^DOMINANCE_POWER,
 * its constants fitted on the bundled HDRIs (benchmarks/auto_quality.py --fit): the target met
 * wherever some level meets it, and as few levels picked too high as that allows. */
#define ERROR_SCALE 0.85
#define CONTRAST_SLOPE 10.0
#define DOMINANCE_POWER 0.0625
#define ENV_FACTOR_MAX 8.0
/* Lights that take nearly all the flux drive the formula toward 0, but what they leave -- grazing
 * views, the clusters' spread -- still errs (studio's high measures 0.15-0.4 times its median). */
#define ENV_FACTOR_MIN 0.15
/* The levels with the grazing path (default, level 5, high) integrate narrow lobes at grazing views
 * per vertex, and levels 5 and 6 (high) also take the bright extended features out as clustered
 * lights, so what remains of their error sits where those features are or were.  Their factor is
 *     scale ((1 - l) + CONTRAST_SLOPE c_s)^contrast_power / (1 + d)^dominance_power
 * with l and d their own and c_s the bright extended share that suns alone (lights above
 * SUN_THRESHOLD times the mean) leave in the lighting (benchmarks/auto_quality.py --fit).  high's
 * is a least-squares fit: it is taken when nothing cheaper is predicted to meet the target, and its
 * factor only says whether it does (the levels' formula put courtyard's error under high at a
 * quarter of what it measures, and claimed 1 % there).  default's and level 5's are fitted as the
 * levels' are, one set for both, for the target met wherever some level meets it: their lights, read
 * to 5 %, do not lower their error as high's do (night's lamps just below the sun threshold err
 * 1.1 % at m = 0.05 beneath a light dominance of 48 under default), hence no dominance term. */
#define SUN_THRESHOLD 256.0
/* A level given a factor here (scale > 0) is predicted by it; the others by the levels' formula.
 * wide_contrast_power (0: contrast_power at every width) is the contrast power from the widest
 * calibrated lobe (ROUGHNESS[3]) up, reached linearly in log m from contrast_power at ROUGHNESS[2]: a
 * wide lobe averages what bright features the lights leave over more of the lighting, and one power
 * for every width over-predicted level 5's error at m = 0.5 1.4-2.5x under forest, studio and
 * courtyard while it was exact under sunset, whose lighting has almost none. */
typedef struct {
    double scale, contrast_power, dominance_power, wide_contrast_power;
} grazing_factor;
static const grazing_factor GRAZING_FACTOR[WENV_AUTO_LEVELS] = {
    [3] = {1.25, 0.75, 0.0, 0.375},
    [5] = {1.25, 0.75, 0.0, 0.375},
    [6] = {1.44, 0.75, 0.25, 0.0},
};

/* The contrast power of a level's grazing factor for a lobe m wide (see GRAZING_FACTOR). */
static double contrast_power_at(const grazing_factor *g, double m)
{
    if (!(g->wide_contrast_power > 0.0) || !(m > ROUGHNESS[2]))
        return g->contrast_power;
    double t = fmin(1.0, log(m / ROUGHNESS[2]) / log(ROUGHNESS[3] / ROUGHNESS[2]));
    return g->contrast_power + t * (g->wide_contrast_power - g->contrast_power);
}

/* MEDIAN_ERROR is Beckmann lobes', dielectric ones (index 1.5) whose reflection, and so whose
 * error, lies mostly at grazing views.  A GGX lobe (Blender's Principled BSDF, the Glossy node's
 * default) of the same width errs up to these many times as much per level, by how much of its
 * reflection it keeps head-on, where the maps and the grazing path's cells err otherwise: as a
 * dielectric (the Principled paint, GGX_DIELECTRIC) or as a metal (the Principled metal, as much
 * head-on as at grazing, GGX_METAL), linear between by the lobes' albedo head-on over theirs at 80
 * degrees (HEAD_ON_DIELECTRIC and HEAD_ON_METAL are the two's).  The largest over the bundled HDRIs
 * of the material's error (alpha 0.09) over Beckmann's at m = 0.09 on the same 2000 pairs
 * (benchmarks/auto_quality.py --calibrate-ggx), applied at every GGX width, so that a target said
 * to be met is: one factor for both, the metal's median over the HDRIs (2.45 at level 5), claimed
 * 1 % for the metal under sunset, where it errs 1.5 %; the metal's largest (4.68) predicted the
 * paint 2-4x above what it errs.  The grazing path's cells (levels 3 and 5) read GGX's heavy tails
 * worse than Beckmann's, high's polar nodes less so, the wavelet maps alone (levels 0-2 and 4) as a
 * wider lobe. */
static const double GGX_DIELECTRIC[WENV_AUTO_LEVELS] = {1.37, 1.37, 1.37, 1.58, 1.34, 1.65, 1.54};
static const double GGX_METAL[WENV_AUTO_LEVELS] = {2.59, 2.44, 2.48, 4.70, 2.30, 4.68, 3.25};
#define HEAD_ON_DIELECTRIC 0.146
#define HEAD_ON_METAL 0.869
/* A lobe narrower than the calibrated range (a clear coat) is read at its edge, m = 0.05, which
 * misjudges it: per level, the median over the HDRIs of the coated paint's error (a coat of alpha
 * 0.01) over that prediction, its GGX factor's included (same command).  The levels without the grazing path lose such a lobe
 * at every view; default and level 5 take it whole on the path, on 24 x 4 cells of GGX's grid that
 * the metal's lobe, cut in two, does not share.  Applied in full at alpha 0.01 and below, in
 * log-proportion between 0.05 and 0.01. */
#define NARROW_ALPHA 0.01
static const double NARROW_FACTOR[WENV_AUTO_LEVELS] = {1.12, 1.02, 1.16, 1.61, 1.29, 1.56, 2.44};

/* The lobes' albedo at normal incidence over theirs at 80 degrees, channels summed: 0.15 for the
 * Principled paint (Fresnel's 4 % head-on), 0.87 for the metal; 0 without lobes. */
static double head_on_share(const wenv_material *mat)
{
    double sum[2] = {0.0, 0.0}, wo[2][3] = {{0.0, 0.0, 1.0}, {sin(80.0 * M_PI / 180.0), 0.0, cos(80.0 * M_PI / 180.0)}};
    for (size_t l = 0; l < wenv_material_lobe_count(mat); l++)
        for (int v = 0; v < 2; v++) {
            double rgb[3];
            wenv_error err = {0};
            if (wenv_material_lobe_albedo(mat, l, wo[v], 32, rgb, &err) == WENV_OK)
                sum[v] += rgb[0] + rgb[1] + rgb[2];
        }
    return sum[1] > 0.0 ? sum[0] / sum[1] : 0.0;
}

const wenv_wavelet_quality *wenv_auto_level(size_t i)
{
    return i < WENV_AUTO_LEVELS ? &WENV_AUTO_LADDER[i] : NULL;
}

size_t wenv_auto_level_bytes(size_t i, size_t used_normals)
{
    const wenv_wavelet_quality *q = &WENV_AUTO_LADDER[i];
    size_t ns = q->normal_n * q->normal_n, nv = (q->view_n + 1) * (q->view_n + 1), nl = q->local_n * q->local_n;
    size_t ng = q->global_n * q->global_n, made = used_normals < ns ? used_normals : ns;
    size_t table = ns * nv * (3 * sizeof(float) + 2);         /* radiance and two flags per pair */
    size_t slices = made * nl * 3 * sizeof(float) + ns * (3 + 12) * sizeof(float); /* + irradiance, frames */
    size_t brdf = nv * q->coefficients * 4 * sizeof(float);  /* index and RGB per kept term */
    size_t lights = q->lights * WENV_LIGHT_LEVELS * 7 * sizeof(float); /* direction, flux, span per cluster level */
    size_t grazing = q->grazing > 0.0 ? 512 * 512 * 3 * sizeof(float) * 4 / 3 : 0; /* its pyramid, at most */
    size_t operators = wenv_slice_operators_estimate_bytes(q->global_n, q->local_n, q->normal_n, made);
    if (operators > WENV_WAVELET_OPERATOR_BYTES)
        operators = WENV_WAVELET_OPERATOR_BYTES;
    return table + slices + brdf + ng * 3 * sizeof(float) + lights + grazing + operators;
}

/* Pixels brighter than CONTRAST_FACTOR times the mean radiance that a level does not take out as
 * lights: bright, extended, hard-edged features -- softboxes, sunlit walls, sky through leaves --
 * that a wavelet map of a few degrees per texel resolves worst. */
#define CONTRAST_FACTOR 16.0

/* Exact lights leave no error of their own, and under a narrow lobe a light's reflection is a
 * bright spot that dominates the signal's mean square (which relative RMSE divides by) far beyond
 * its share of the flux: a lamp or a sun reflected at m = 0.1 is hundreds of times the mean.  The
 * lights' weight is the ratio of mean squares, lights alone against the rest, of the lighting
 * averaged over octahedral texels about as wide as the reflected lobe: DOMINANCE_TEXELS / m
 * texels on a side (texels of about 1.8 m radians). */
#define DOMINANCE_TEXELS 2.0
#define DOMINANCE_MAX 1e6
#define DOMINANCE_GRID_MAX 64 /* texels on a side: DOMINANCE_TEXELS / m for m >= 0.05, with room */

/* One pyramid level of the lighting with every candidate light out (black), with each texel's
 * solid angle, the texel each candidate falls in, and room to gather lights per texel. */
typedef struct {
    size_t side;
    const float *texels;
    double *solid_angle, *lit, *other;
    size_t *texel_of; /* per candidate light */
} dominance_grid;

static void grid_free(dominance_grid *g)
{
    free(g->solid_angle);
    free(g->lit);
    free(g->other);
    free(g->texel_of);
}

static int grid_init(dominance_grid *g, const wenv_oct_pyramid *p, size_t level, const wenv_bright_pixel *bright,
                     size_t nb)
{
    size_t n = p->side[level];
    g->side = n;
    g->texels = p->texels[level];
    g->solid_angle = malloc(n * n * sizeof(double));
    g->lit = malloc(n * n * sizeof(double));
    g->other = malloc(n * n * sizeof(double));
    g->texel_of = malloc((nb ? nb : 1) * sizeof(size_t));
    if (!g->solid_angle || !g->lit || !g->other || !g->texel_of)
        return -1;
    for (size_t t = 0; t < n * n; t++)
        g->solid_angle[t] = wenv_oct_texel_solid_angle(n, t % n, t / n);
    for (size_t k = 0; k < nb; k++)
        g->texel_of[k] = wenv_oct_texel_f(bright[k].dir, n);
    return 0;
}

/* Mean square of a level's lights (the first nl candidates) over that of the rest of the lighting
 * (the other candidates back in), on a grid: every candidate's flux spread over its texel. */
static double light_dominance_at(dominance_grid *g, const wenv_bright_pixel *bright, size_t nl, size_t nb)
{
    size_t nt = g->side * g->side;
    memset(g->lit, 0, nt * sizeof(double));
    memset(g->other, 0, nt * sizeof(double));
    for (size_t k = 0; k < nb; k++) {
        double flux = ((double)bright[k].flux[0] + bright[k].flux[1] + bright[k].flux[2]) / 3.0;
        (k < nl ? g->lit : g->other)[g->texel_of[k]] += flux;
    }
    double rest = 0.0, lit = 0.0;
    for (size_t t = 0; t < nt; t++) {
        const float *x = g->texels + 3 * t;
        double sa = g->solid_angle[t], r = ((double)x[0] + x[1] + x[2]) / 3.0 + g->other[t] / sa;
        rest += r * r * sa;
        lit += g->lit[t] * g->lit[t] / sa;
    }
    if (!(rest > 0.0))
        return lit > 0.0 ? DOMINANCE_MAX : 0.0;
    return fmin(DOMINANCE_MAX, lit / rest);
}

static int by_pixel(const void *a, const void *b)
{
    size_t x = *(const size_t *)a, y = *(const size_t *)b;
    return (x > y) - (x < y);
}

/* Band of the spectrum estimate; beyond it the power A_l^2 P_l is taken to fall as l^-4, as a lone
 * sun's does (A_l^2 ~ l^-5, P_l ~ 2l + 1), which bounds every non-negative lighting. */
#define SH_ESTIMATE_ORDER 20
#define SH_TAIL_FACTOR 2.9 /* sum over even l > 20 of (20 / l)^4 */

/* What auto reads of an environment whatever the material, in two parts each made on first need
 * and then kept: for the slicing ladder the brightest pixels (each level's lights are a prefix of
 * them: the brightest above its threshold, up to its budget), the lighting without any of them as
 * an octahedral pyramid and the flux in bright extended features (8-14 ms on Blender's HDRIs); for
 * SH irradiance the lighting's power per band (9-10 ms).  A material without lobes needs only the
 * second, one with lobes only the first.  The lock makes a part once however many threads choose. */
struct wenv_auto_analysis {
    const wenv_envmap *env;
    omp_lock_t lock;
    double total, mean, strength; /* flux, mean radiance (flux / 4 pi), the environment's strength */
    int lights_made, spectrum_made;
    /* the ladder's part */
    double bright_flux; /* flux of pixels above CONTRAST_FACTOR times the mean */
    size_t nb;
    wenv_bright_pixel *bright;
    wenv_oct_pyramid pyramid; /* without the nb candidates */
    /* the SH part: sum over m of the squared coefficients, per band and channel */
    double band_power[SH_ESTIMATE_ORDER + 1][3];
};

wenv_status wenv_auto_analysis_create(wenv_auto_analysis **out, const wenv_envmap *env, wenv_error *err)
{
    wenv_auto_analysis *an = calloc(1, sizeof *an);
    if (!(*out = an))
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory analysing the environment");
    an->env = env;
    an->total = wenv_envmap_flux(env);
    an->strength = wenv_envmap_strength(env);
    an->mean = an->total / (4.0 * M_PI);
    omp_init_lock(&an->lock);
    return WENV_OK;
}

void wenv_auto_analysis_free(wenv_auto_analysis *an)
{
    if (!an)
        return;
    omp_destroy_lock(&an->lock);
    wenv_oct_pyramid_free(&an->pyramid);
    free(an->bright);
    free(an);
}

static int sh_band_power(const wenv_envmap *env, double power[][3])
{
    size_t count = wenv_sh_count(SH_ESTIMATE_ORDER);
    double *c = malloc(count * 3 * sizeof(double));
    if (!c)
        return -1;
    wenv_error err = {0};
    /* a coarse projection: the estimate needs each band's power, not its coefficients exactly */
    if (wenv_sh_project_envmap_blocks(env, SH_ESTIMATE_ORDER, wenv_sh_projection_block(env, SH_ESTIMATE_ORDER / 2),
                                      c, NULL, &err)) {
        free(c);
        return -1;
    }
    for (size_t l = 0; l <= SH_ESTIMATE_ORDER; l++)
        for (int ch = 0; ch < 3; ch++) {
            double p = 0.0;
            for (size_t i = l * l; i < (l + 1) * (l + 1); i++)
                p += c[3 * i + ch] * c[3 * i + ch];
            power[l][ch] = p;
        }
    free(c);
    return 0;
}

static wenv_status make_spectrum(wenv_auto_analysis *an, wenv_error *err)
{
    if (an->total > 0.0 && sh_band_power(an->env, an->band_power) < 0) /* black: no power anywhere */
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory analysing the environment");
    return WENV_OK;
}

static wenv_status make_lights(wenv_auto_analysis *an, wenv_error *err)
{
    const wenv_envmap *env = an->env;
    if (!(an->total > 0.0)) /* black (or zero strength): nothing to resolve */
        return WENV_OK;
    size_t k = 0;
    double relative = INFINITY;
    for (size_t i = 0; i < WENV_AUTO_LEVELS; i++) {
        k = WENV_AUTO_LADDER[i].lights > k ? WENV_AUTO_LADDER[i].lights : k;
        relative = fmin(relative, WENV_AUTO_LADDER[i].light_threshold);
    }
    free(an->bright); /* from an attempt that failed, if any */
    size_t *excluded = malloc((k ? k : 1) * sizeof *excluded);
    an->bright = malloc((k ? k : 1) * sizeof *an->bright);
    if (!an->bright || !excluded) {
        free(excluded);
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory analysing the environment");
    }
    an->nb = wenv_envmap_brightest(env, k, relative, an->bright);
    for (size_t i = 0; i < an->nb; i++)
        excluded[i] = an->bright[i].pixel;
    qsort(excluded, an->nb, sizeof *excluded, by_pixel);
    wenv_status st = wenv_oct_pyramid_build(&an->pyramid, env, excluded, an->nb, DOMINANCE_GRID_MAX, 0, NULL, err);
    free(excluded);
    if (st)
        return st;
    double cut = CONTRAST_FACTOR * an->mean / an->strength, bright_flux = 0.0;
    size_t w = wenv_envmap_width(env), h = wenv_envmap_height(env);
    const float *px = wenv_envmap_pixels(env);
    for (size_t row = 0; row < h; row++)
        for (size_t col = 0; col < w; col++) {
            const float *p = px + 3 * (row * w + col);
            if (p[0] > cut || p[1] > cut || p[2] > cut)
                bright_flux += wenv_envmap_pixel_solid_angle(env, row, col) * ((double)p[0] + p[1] + p[2]) / 3.0;
        }
    an->bright_flux = bright_flux * an->strength;
    return WENV_OK;
}

/* Makes the part `made` flags with `make` unless made before; adds the time to *seconds. */
static wenv_status need_part(wenv_auto_analysis *an, int *made, wenv_status (*make)(wenv_auto_analysis *, wenv_error *),
                             double *seconds, wenv_error *err)
{
    wenv_status st = WENV_OK;
    omp_set_lock(&an->lock);
    if (!*made) {
        double start = omp_get_wtime();
        st = make(an, err);
        *made = st == WENV_OK;
        *seconds += omp_get_wtime() - start;
    }
    omp_unset_lock(&an->lock);
    return st;
}

/* Per level: the flux share of its lights, the share of the bright extended features it leaves in
 * the lighting, and (for a material with lobes, of narrowest roughness m > 0) its lights'
 * dominance, averaged over texels about DOMINANCE_TEXELS / m on a side. */
static wenv_status estimate_levels(const wenv_auto_analysis *an, double m, wenv_auto_level_estimate *est,
                                   wenv_error *err)
{
    if (!(an->total > 0.0))
        return WENV_OK;
    const wenv_bright_pixel *bright = an->bright;
    size_t nb = an->nb;
    const wenv_oct_pyramid *pyramid = &an->pyramid;
    dominance_grid grid[2] = {{0}, {0}};
    double blend = 0.0; /* between grid[0] and grid[1], in log side */
    wenv_status st = WENV_OK;
    if (m > 0.0) {
        double x = fmin(fmax(log2((double)pyramid->side[0] * m / DOMINANCE_TEXELS), 0.0), (double)(pyramid->levels - 1));
        size_t lo = (size_t)floor(x), hi = lo + 1 < pyramid->levels ? lo + 1 : lo;
        blend = x - (double)lo;
        if (grid_init(&grid[0], pyramid, lo, bright, nb) || grid_init(&grid[1], pyramid, hi, bright, nb)) {
            st = wenv_error_set(err, WENV_ERR_NOMEM, "out of memory estimating the environment");
            goto done;
        }
    }
    double mean = an->mean;
    for (size_t i = 0; i < WENV_AUTO_LEVELS; i++) {
        size_t nl = 0;
        double light_flux = 0.0, bright_lights = 0.0, bright_suns = 0.0;
        while (nl < nb && nl < WENV_AUTO_LADDER[i].lights && (double)bright[nl].radiance > WENV_AUTO_LADDER[i].light_threshold * mean) {
            double f = ((double)bright[nl].flux[0] + bright[nl].flux[1] + bright[nl].flux[2]) / 3.0;
            light_flux += f;
            if ((double)bright[nl].radiance > CONTRAST_FACTOR * mean)
                bright_lights += f;
            if ((double)bright[nl].radiance > SUN_THRESHOLD * mean)
                bright_suns += f;
            nl++;
        }
        est[i].lights_share = fmin(1.0, light_flux / an->total);
        est[i].contrast = fmin(1.0, fmax(0.0, (an->bright_flux - bright_lights) / an->total));
        est[i].sun_contrast = fmin(1.0, fmax(0.0, (an->bright_flux - bright_suns) / an->total));
        if (m > 0.0 && nl) {
            double a = log1p(light_dominance_at(&grid[0], bright, nl, nb));
            double b = log1p(light_dominance_at(&grid[1], bright, nl, nb));
            est[i].light_dominance = expm1(a + blend * (b - a));
        }
    }
done:
    grid_free(&grid[0]);
    grid_free(&grid[1]);
    return st;
}

/* Median error of a level at roughness m (0: Lambert's column), interpolated linearly in log
 * roughness and clamped to the measured range. */
static double level_error(size_t level, double m)
{
    const double *e = MEDIAN_ERROR[level];
    if (!(m > 0.0))
        return e[4];
    if (m <= ROUGHNESS[0])
        return e[0];
    if (m >= ROUGHNESS[3])
        return e[3];
    size_t i = 0;
    while (m > ROUGHNESS[i + 1])
        i++;
    double t = log(m / ROUGHNESS[i]) / log(ROUGHNESS[i + 1] / ROUGHNESS[i]);
    return exp((1.0 - t) * log(e[i]) + t * log(e[i + 1]));
}

/* Memory of method "sh" for a material without lobes: lighting coefficients and the irradiance table. */
static size_t sh_bytes(size_t order)
{
    return wenv_sh_count(order) * 3 * sizeof(double) + 128 * 128 * 3 * sizeof(float);
}

/* Normal samples of an n_side grid that the normals' bilinear taps reach ((size_t)-1 without
 * normals or memory to count them). */
static size_t used_normal_samples(size_t n_side, const float *normals, size_t n)
{
    if (!normals)
        return (size_t)-1;
    unsigned char *hit = calloc(n_side * n_side, 1);
    if (!hit)
        return (size_t)-1;
    /* a mesh's worth of normals in parallel: every writer stores the same 1, so counting after */
#pragma omp parallel for schedule(static)
    for (size_t i = 0; i < n; i++) {
        const float *d = normals + 3 * i;
        float len = sqrtf(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]), u, v, w[4];
        if (!(len > 0.0f))
            continue;
        float unit[3] = {d[0] / len, d[1] / len, d[2] / len};
        uint32_t idx[4];
        wenv_oct_encode_f(unit, &u, &v);
        wenv_oct_bilinear_f((long)n_side, u, v, idx, w);
        for (int k = 0; k < 4; k++)
            if (w[k] > 0.0f) {
#pragma omp atomic write
                hit[idx[k]] = 1;
            }
    }
    size_t used = 0;
    for (size_t t = 0; t < n_side * n_side; t++)
        used += hit[t];
    free(hit);
    return used;
}


/* The truncation error follows from the power spectrum exactly (Parseval); what the estimate gets
 * wrong is its coarse projection, blocks sized for band SH_ESTIMATE_ORDER / 2, whose point rule errs
 * by about SH_BLOCK_RULE_ERROR (l / (SH_ESTIMATE_ORDER / 2))^2 in band l's coefficients (sh.c), and
 * so by as much in an error made mostly of band order + 2.  Beside it, the irradiance table and the
 * reference's own pixel sums leave a few 0.01 % (SH_ERROR_FLOOR), independent of the truncation, so
 * added in quadrature.  On the bundled HDRIs the measured error is 0.91 - 0.999 times the
 * prediction down to 0.2 %, and 0.54 times it at 0.04 %, where the floor dominates
 * (benchmarks/auto_quality.py). */
#define SH_BLOCK_RULE_ERROR 0.013
#define SH_ERROR_FLOOR 5e-4

static double sh_error_from_power(const double *power, size_t order)
{
    double beyond = SH_TAIL_FACTOR * power[SH_ESTIMATE_ORDER], total = beyond, tail = beyond;
    for (size_t l = 0; l <= SH_ESTIMATE_ORDER; l++) {
        total += power[l];
        if (l > order)
            tail += power[l];
    }
    if (!(total > 0.0))
        return 0.0;
    double band = (double)(order + 2) / (SH_ESTIMATE_ORDER / 2);
    double truncation = (1.0 + SH_BLOCK_RULE_ERROR * band * band) * sqrt(tail / total);
    return sqrt(truncation * truncation + SH_ERROR_FLOOR * SH_ERROR_FLOOR);
}

/* Normal samples of a level's grid the mesh's normals reach, counted once per grid side. */
static size_t used_at(size_t level, const float *normals, size_t n, size_t *by_side)
{
    size_t side = WENV_AUTO_LADDER[level].normal_n, slot = side <= 16 ? 0 : side <= 32 ? 1 : 2;
    if (by_side[slot] == 0)
        by_side[slot] = used_normal_samples(side, normals, n);
    return by_side[slot];
}

/* Whether a level fits the budget: every slice, or those the mesh uses. */
static int level_fits(size_t level, size_t budget, const float *normals, size_t n, size_t *by_side)
{
    return wenv_auto_level_bytes(level, (size_t)-1) <= budget ||
           wenv_auto_level_bytes(level, used_at(level, normals, n, by_side)) <= budget;
}

wenv_status wenv_auto_choose(const wenv_envmap *env, wenv_auto_analysis *analysis, const wenv_material *mat,
                             double target, size_t memory_budget, const float *normals, size_t n,
                             wenv_auto_choice *out, wenv_error *err)
{
    memset(out, 0, sizeof *out);
    double start = omp_get_wtime();
    if (!(target > 0.0 && target <= 1.0))
        return wenv_error_set(err, WENV_ERR_VALUE, "target_error must be in (0, 1], got %g", target);
    if (analysis && analysis->env != env)
        return wenv_error_set(err, WENV_ERR_VALUE, "the analysis given is of another environment");
    wenv_auto_analysis *made = NULL;
    if (!analysis) {
        if (wenv_auto_analysis_create(&made, env, err))
            return err->status;
        analysis = made;
    }
    wenv_status st = WENV_OK;
    if (!wenv_material_lobe_count(mat)) {
        if ((st = need_part(analysis, &analysis->spectrum_made, make_spectrum, &out->analysis_seconds, err)))
            goto done;
        const double *diffuse = wenv_material_diffuse(mat);
        double power[SH_ESTIMATE_ORDER + 1];
        for (size_t l = 0; l <= SH_ESTIMATE_ORDER; l++) {
            double a = wenv_sh_lambert_factor(l);
            power[l] = 0.0;
            for (int ch = 0; ch < 3; ch++)
                power[l] += a * a * diffuse[ch] * diffuse[ch] * analysis->band_power[l][ch];
        }
        for (size_t i = 0; i < WENV_AUTO_SH_ORDER_COUNT; i++) {
            double e = sh_error_from_power(power, WENV_AUTO_SH_ORDERS[i]);
            if (e <= target && sh_bytes(WENV_AUTO_SH_ORDERS[i]) <= memory_budget) {
                out->sh_order = WENV_AUTO_SH_ORDERS[i];
                out->method = &WENV_METHOD_SH;
                out->sh_quality = (wenv_sh_shading_quality){.order = out->sh_order, .views = WENV_AUTO_SH_VIEWS};
                out->predicted_error = e;
                out->met = 1;
                out->level_bytes = sh_bytes(out->sh_order);
                goto done;
            }
        }
    }
    /* per grid side (16, 32, 64): normal samples the mesh uses, counted when a budget check or
     * the answer needs them; 0 not yet counted */
    size_t by_side[3] = {0, 0, 0};
    if (!level_fits(0, memory_budget, normals, n, by_side)) {
        st = wenv_error_set(err, WENV_ERR_VALUE, "memory_budget of %zu bytes is below the cheapest setting's %zu",
                            memory_budget, wenv_auto_level_bytes(0, used_at(0, normals, n, by_side)));
        goto done;
    }
    if ((st = need_part(analysis, &analysis->lights_made, make_lights, &out->analysis_seconds, err)))
        goto done;
    /* the narrowest lobe's width (Lambert's column, m = 0, when no lobe reflects) */
    double m = wenv_material_lobe_width(mat);
    m = isfinite(m) ? m : 0.0;
    int ggx = m > 0.0 && wenv_material_narrowest_lobe(mat)->distribution == WENV_NDF_GGX;
    out->head_on = head_on_share(mat);
    double metal_like = fmin(1.0, fmax(0.0, (out->head_on - HEAD_ON_DIELECTRIC) / (HEAD_ON_METAL - HEAD_ON_DIELECTRIC)));
    /* how far below the calibrated range, 0 to 1 at NARROW_ALPHA */
    double narrow = m > 0.0 && m < ROUGHNESS[0] ? fmin(1.0, log(ROUGHNESS[0] / m) / log(ROUGHNESS[0] / NARROW_ALPHA)) : 0.0;
    /* the lobe's width within the calibrated range decides which texels the dominance averages */
    if ((st = estimate_levels(analysis, m > 0.0 ? fmin(fmax(m, ROUGHNESS[0]), ROUGHNESS[3]) : 0.0, out->levels, err)))
        goto done;
    for (size_t i = 0; i < WENV_AUTO_LEVELS; i++) {
        wenv_auto_level_estimate *e = &out->levels[i];
        const grazing_factor *g = &GRAZING_FACTOR[i];
        if (g->scale > 0.0)
            e->env_factor = g->scale *
                            pow((1.0 - e->lights_share) + CONTRAST_SLOPE * e->sun_contrast, contrast_power_at(g, m)) /
                            pow(1.0 + e->light_dominance, g->dominance_power);
        else
            e->env_factor = ERROR_SCALE * ((1.0 - e->lights_share) + CONTRAST_SLOPE * e->contrast) /
                            pow(1.0 + e->light_dominance, DOMINANCE_POWER);
        e->env_factor = fmin(ENV_FACTOR_MAX, fmax(ENV_FACTOR_MIN, e->env_factor));
        double ggx_factor = (1.0 - metal_like) * GGX_DIELECTRIC[i] + metal_like * GGX_METAL[i];
        e->predicted_error = level_error(i, m) * e->env_factor * (ggx ? ggx_factor : 1.0) *
                             pow(NARROW_FACTOR[i], narrow);
    }
    size_t best = 0;
    for (size_t i = 0; i < WENV_AUTO_LEVELS; i++) {
        if (!level_fits(i, memory_budget, normals, n, by_side))
            break;
        best = i;
        if (out->levels[i].predicted_error <= target) {
            out->met = 1;
            break;
        }
    }
    out->level = best;
    out->quality = WENV_AUTO_LADDER[best];
    out->method = &WENV_METHOD_SLICING;
    out->used_normals = used_at(best, normals, n, by_side);
    out->level_bytes = wenv_auto_level_bytes(best, out->used_normals);
    out->predicted_error = out->levels[best].predicted_error;
done:
    wenv_auto_analysis_free(made);
    out->seconds = omp_get_wtime() - start;
    return st;
}

const void *wenv_auto_choice_quality(const wenv_auto_choice *choice)
{
    return choice->sh_order ? (const void *)&choice->sh_quality : (const void *)&choice->quality;
}
