/* Cycles' bump terminator: what a diffuse closure receives where a normal map or a Bump node bends
 * its normal n away from the surface's smooth normal ns.
 *
 * Why: Cycles rejects light from below the smooth surface's horizon and, with the material's Bump
 * Map Correction (on by default), masks light at grazing angles to it: from Blender 4.5 by GGX's G1
 * of alpha^2 = min(1, tan^2(bend) / 8) (Conty Estevez, Lecocq and Stein 2019, "A Microfacet-Based
 * Shadowing Function to Solve the Bump Terminator Problem"), before by Chiang, Li and Burley's
 * 2019 term of g = cos(smooth, l) / (cos(bent, l) cos(bend)), -g^3 + g^2 + g below 1 ("Taming the
 * Shadow Terminator").  A bent diffuse closure then reflects less than its normal alone says: 4.7 %
 * less on average for the bumps of the textured scene under a uniform sky, 12 % at a 30-degree
 * bend (17 % by Chiang's).  Glossy closures keep their normal here. */
#ifndef WENV_BUMP_TERMINATOR_H
#define WENV_BUMP_TERMINATOR_H

#include <stddef.h>

/* The correction a material's Bump Map Correction makes: none, Blender 4.5's, or the one before. */
enum { WENV_BUMP_NONE = 0, WENV_BUMP_MICROFACET = 1, WENV_BUMP_CHIANG = 2 };

/* Normals bent by a normal map or Bump node, with the smooth normals they were bent from (n x 3, one
 * per shaded vertex) and the material's Bump Map Correction (WENV_BUMP_*). */
typedef struct {
    const float *smooth;
    int correction;
} wenv_bump_normals;

/* How much of light from unit direction l a diffuse closure of unit normal n on a surface of unit
 * smooth normal ns receives (its cosine with n aside), as Cycles' bump_shadowing_term: 0 from the
 * smooth surface's other side, else the correction's (WENV_BUMP_*; 1 without one). */
double wenv_bump_diffuse_weight(const double n[3], const double ns[3], const double l[3], int correction);

/* The share of a uniform sky's light a bent diffuse closure receives, by the cosine of the bend. */
#define WENV_BUMP_SHARES 64
typedef struct {
    float share[WENV_BUMP_SHARES + 1]; /* at cos bend = k / WENV_BUMP_SHARES */
} wenv_bump_shares;

void wenv_bump_shares_make(wenv_bump_shares *t, int correction);

/* share[i] for n vertices of normals (bent) and smooth normals (n x 3 each, non-zero, not necessarily
 * unit): under lighting that varies little over the sliver the smooth horizon cuts from the cosine
 * lobe, the factor on the Lambertian part's light (exact under a uniform sky). */
void wenv_bump_share_rows(const float *normals, const float *smooth, size_t n, int correction, float *share);

/* horizon (n x 3, unit) for the same rows: the smooth surface's horizon towards the bend, the normal
 * whose irradiance stands for the light a bent part loses (any horizon where nothing is bent). */
void wenv_bump_horizons(const float *normals, const float *smooth, size_t n, float *horizon);

#endif
