/* The Ambient Occlusion node's share at each point (ambient.h). */
#include "scene/ambient.h"

#include <math.h>
#include <stdint.h>
#include <stdlib.h>

/* Rays tested at once on a thread (held on its stack); points a block between two reports. */
#define CHUNK 1024
#define BLOCK_RAYS 65536

typedef struct {
    const wenv_occluders *scene;
    const float *points, *normals;
    size_t rays;
    float pattern[WENV_AMBIENT_MAX_RAYS][3];
    float step, far;
    int inside;
    float *out;
} ambient_job;

/* A turn in [0, 2 pi) for point `index`, the same at every call (a 64-bit mix of the index). */
static double turn_of(size_t index)
{
    uint64_t h = (uint64_t)index * 0x9E3779B97F4A7C15ull;
    h ^= h >> 31;
    h *= 0xBF58476D1CE4E5B9ull;
    h ^= h >> 29;
    return (double)(h >> 11) * (2.0 * M_PI / 9007199254740992.0);
}

/* The point's rays: the pattern turned by its own angle, then set in the frame of its unit normal
 * (Duff et al.'s branchless basis). */
static void point_rays(const ambient_job *job, size_t index, float (*dirs)[3], float (*origins)[3])
{
    const float *p = job->points + 3 * index, *nrm = job->normals + 3 * index;
    double up[3] = {nrm[0], nrm[1], nrm[2]}, len = sqrt(up[0] * up[0] + up[1] * up[1] + up[2] * up[2]);
    len = len > 1e-30 ? len : 1e-30;
    for (int k = 0; k < 3; k++)
        up[k] = (job->inside ? -up[k] : up[k]) / len;
    double sign = up[2] >= 0.0 ? 1.0 : -1.0, a = -1.0 / (sign + up[2]), b = up[0] * up[1] * a;
    float t[3] = {(float)(1.0 + sign * up[0] * up[0] * a), (float)(sign * b), (float)(-sign * up[0])};
    float s[3] = {(float)b, (float)(sign + up[1] * up[1] * a), (float)(-up[1])};
    float u[3] = {(float)up[0], (float)up[1], (float)up[2]};
    double turn = turn_of(index);
    float c = (float)cos(turn), si = (float)sin(turn);
    for (size_t r = 0; r < job->rays; r++) {
        const float *q = job->pattern[r];
        float px = c * q[0] - si * q[1], py = si * q[0] + c * q[1];
        for (int k = 0; k < 3; k++) {
            dirs[r][k] = px * t[k] + py * s[k] + q[2] * u[k];
            origins[r][k] = p[k] + job->step * dirs[r][k];
        }
    }
}

static void ambient_block(const void *ctx, size_t first, size_t end)
{
    const ambient_job *job = ctx;
    float dirs[CHUNK][3], origins[CHUNK][3];
    unsigned char blocked[CHUNK];
    size_t per_chunk = CHUNK / job->rays;
    for (size_t i = first; i < end; i += per_chunk) {
        size_t m = end - i < per_chunk ? end - i : per_chunk;
        for (size_t j = 0; j < m; j++)
            point_rays(job, i + j, dirs + j * job->rays, origins + j * job->rays);
        wenv_occluders_test_scattered(job->scene, &origins[0][0], &dirs[0][0], m * job->rays, job->far, blocked);
        for (size_t j = 0; j < m; j++) {
            size_t open = 0;
            for (size_t r = 0; r < job->rays; r++)
                open += !blocked[j * job->rays + r];
            job->out[i + j] = (float)((double)open / (double)job->rays);
        }
    }
}

wenv_status wenv_ambient_shares(const wenv_occluders *scene, const float *points, const float *normals, size_t n,
                                size_t rays, double distance, int inside, float *out, const wenv_progress *progress,
                                wenv_error *err)
{
    if (rays < 1 || rays > WENV_AMBIENT_MAX_RAYS)
        return wenv_error_set(err, WENV_ERR_VALUE, "rays must be from 1 to %d, got %zu", WENV_AMBIENT_MAX_RAYS, rays);
    if (!isfinite(distance))
        return wenv_error_set(err, WENV_ERR_VALUE, "distance must be finite, got %g", distance);
    if (distance <= 0.0 || !wenv_occluders_triangle_count(scene)) { /* (Cycles: no rays at all) */
        for (size_t i = 0; i < n; i++)
            out[i] = 1.0f;
        return WENV_OK;
    }
    ambient_job *j = malloc(sizeof *j); /* (its pattern: too large for a stack) */
    if (!j)
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for the rays' pattern");
    float step = wenv_occluders_offset(scene);
    *j = (ambient_job){.scene = scene, .points = points, .normals = normals, .rays = rays, .step = step,
                       .far = (float)(distance - step), .inside = inside, .out = out};
    /* a Fibonacci spiral over the unit disk lifted onto the hemisphere, as Cycles lifts its
     * concentric disk samples: cosine-weighted */
    for (size_t r = 0; r < rays; r++) {
        double i = (double)r + 0.5, radius = sqrt(i / (double)rays), phi = i * M_PI * (3.0 - sqrt(5.0));
        j->pattern[r][0] = (float)(radius * cos(phi));
        j->pattern[r][1] = (float)(radius * sin(phi));
        j->pattern[r][2] = (float)sqrt(fmax(1.0 - radius * radius, 0.0));
    }
    size_t block = BLOCK_RAYS / rays;
    int stopped = wenv_progress_blocks(n, block, ambient_block, j, progress);
    free(j);
    return stopped ? wenv_error_set(err, WENV_ERR_CANCELLED, "cancelled") : WENV_OK;
}
