/* Maps of what each vertex sends, and their reading at hits (sending_map.h). */
#include "scene/sending_map.h"

#include <stdint.h>

#include "math/frame.h"
#include "math/maps.h"

/* The frame rows (tangent, bitangent, normal) of a unit normal, as floats. */
static void frame_of(const float *normal, float f[9])
{
    double n[3] = {normal[0], normal[1], normal[2]}, d[9];
    wenv_frame(n, d);
    for (int k = 0; k < 9; k++)
        f[k] = (float)d[k];
}

void wenv_sending_directions(const float *normals, size_t n, size_t side, float *out)
{
    size_t texels = side * side;
    long long nn = (long long)n;
#pragma omp parallel for schedule(static, 1024)
    for (long long i = 0; i < nn; i++) {
        float f[9];
        frame_of(normals + 3 * (size_t)i, f);
        for (size_t t = 0; t < texels; t++) {
            double d[3];
            wenv_hemi_decode(wenv_map_texel_center(side, t % side), wenv_map_texel_center(side, t / side), d);
            float *o = out + 3 * (t * n + (size_t)i);
            for (int k = 0; k < 3; k++) /* local (x, y, z) -> world: rows of f are the axes */
                o[k] = (float)(f[k] * d[0] + f[3 + k] * d[1] + f[6 + k] * d[2]);
        }
    }
}

void wenv_sending_read(const wenv_occlusion *o, const wenv_occluders *occ, const float *normals, const float *sent,
                       size_t side, float *out)
{
    size_t r = o->resolution, texels = r * r, per = side * side;
    const uint32_t *triangles = wenv_occluders_triangles(occ);
    long long nm = (long long)o->n_masks;
#pragma omp parallel for schedule(dynamic, 64)
    for (long long s = 0; s < nm; s++) {
        size_t i = o->owner[s], h = o->hit_start[s];
        float f[9];
        frame_of(o->normals + 3 * (size_t)i, f);
        for (size_t t = 0; t < texels; t++) {
            if (wenv_occlusion_visible(o, (size_t)i, t))
                continue;
            double d[3];
            wenv_occlusion_texel_direction(r, t, d);
            float back[3]; /* from the hit towards the ray's start */
            for (int k = 0; k < 3; k++)
                back[k] = -(float)(f[k] * d[0] + f[3 + k] * d[1] + f[6 + k] * d[2]);
            const wenv_occlusion_hit *hit = &o->hits[h];
            const uint32_t *tri = triangles + 3 * (size_t)hit->triangle;
            float w[3], sum[3] = {0.0f, 0.0f, 0.0f};
            wenv_occlusion_hit_weights(hit, w);
            for (int c = 0; c < 3; c++) {
                float g[9];
                frame_of(normals + 3 * (size_t)tri[c], g);
                float local[3] = {g[0] * back[0] + g[1] * back[1] + g[2] * back[2],
                                  g[3] * back[0] + g[4] * back[1] + g[5] * back[2],
                                  g[6] * back[0] + g[7] * back[1] + g[8] * back[2]};
                float u, v, tw[4];
                uint32_t idx[4];
                wenv_hemi_encode_f(local, &u, &v); /* a back face's side reads its horizon */
                wenv_hemi_bilinear_f((long)side, u, v, idx, tw);
                const float *m = sent + 3 * (size_t)tri[c] * per;
                for (int q = 0; q < 4; q++)
                    for (int k = 0; k < 3; k++)
                        sum[k] += w[c] * tw[q] * m[3 * idx[q] + (size_t)k];
            }
            for (int k = 0; k < 3; k++)
                out[3 * h + (size_t)k] = sum[k] > 0.0f ? sum[k] : 0.0f;
            h++;
        }
    }
}
