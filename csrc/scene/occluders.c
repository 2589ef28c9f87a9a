/* Triangle meshes as an Embree scene, tested ray by ray (occluders.h). */
#include "scene/occluders.h"

#include <embree3/rtcore.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "base/fingerprint.h"

struct wenv_occluders {
    RTCDevice device;
    RTCScene scene;
    size_t n_triangles, n_positions;
    const uint32_t *triangles; /* Embree's index buffer, alive with the scene */
    const float *positions;    /* and its vertex buffer */
    double size;
    size_t memory_budget;      /* also what each occlusion cast against it may take */
    uint64_t fingerprint;      /* of the positions and triangles */
};

/* Embree's bytes per triangle for a static scene (the BVH and its triangle data, measured: about
 * 100 with the build's temporary memory), and the copies made here. */
#define BYTES_PER_TRIANGLE 160
#define BYTES_PER_POSITION 16

/* Embree reports errors through a callback: the first is kept for the caller. */
static void on_error(void *user, enum RTCError code, const char *str)
{
    wenv_error *err = user;
    if (err && err->status == WENV_OK)
        wenv_error_set(err, code == RTC_ERROR_OUT_OF_MEMORY ? WENV_ERR_NOMEM : WENV_ERR_VALUE, "Embree: %s",
                       str ? str : "unknown error");
}

static wenv_status check(const float *p, size_t np, const uint32_t *t, size_t nt, wenv_error *err)
{
    for (size_t i = 0; i < np; i++)
        if (!isfinite(p[3 * i]) || !isfinite(p[3 * i + 1]) || !isfinite(p[3 * i + 2]))
            return wenv_error_set(err, WENV_ERR_VALUE, "positions[%zu] is not finite", i);
    for (size_t i = 0; i < nt; i++) {
        const uint32_t *f = t + 3 * i;
        for (int k = 0; k < 3; k++)
            if (f[k] >= np)
                return wenv_error_set(err, WENV_ERR_VALUE, "triangles[%zu] refers to vertex %u of %zu", i,
                                      (unsigned)f[k], np);
        const float *a = p + 3 * (size_t)f[0], *b = p + 3 * (size_t)f[1], *c = p + 3 * (size_t)f[2];
        double e1[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]}, e2[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
        double x = e1[1] * e2[2] - e1[2] * e2[1], y = e1[2] * e2[0] - e1[0] * e2[2], z = e1[0] * e2[1] - e1[1] * e2[0];
        if (!(x * x + y * y + z * z > 0.0))
            return wenv_error_set(err, WENV_ERR_VALUE, "triangles[%zu] is degenerate (zero area): remove it", i);
    }
    return WENV_OK;
}

double wenv_occluders_bytes_needed(size_t n_positions, size_t n_triangles)
{
    return (double)n_triangles * BYTES_PER_TRIANGLE + (double)n_positions * BYTES_PER_POSITION;
}

wenv_status wenv_occluders_create(wenv_occluders **out, const float *positions, size_t n_positions,
                                  const uint32_t *triangles, size_t n_triangles, size_t memory_budget,
                                  wenv_error *err)
{
    *out = NULL;
    if (n_triangles == 0)
        return wenv_error_set(err, WENV_ERR_VALUE, "triangles: an occluder needs at least one triangle");
    if (n_triangles > UINT32_MAX / 3 || n_positions > UINT32_MAX)
        return wenv_error_set(err, WENV_ERR_VALUE, "too many triangles (%zu) or positions (%zu)", n_triangles,
                              n_positions);
    double need = wenv_occluders_bytes_needed(n_positions, n_triangles);
    if (need > (double)memory_budget)
        return wenv_error_set(err, WENV_ERR_VALUE,
                              "occluders of %zu triangles need about %.0f MB, over the memory budget of %.0f MB",
                              n_triangles, need / 1048576.0, (double)memory_budget / 1048576.0);
    if (check(positions, n_positions, triangles, n_triangles, err))
        return err->status;
    wenv_occluders *occ = calloc(1, sizeof *occ);
    if (!occ)
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for occluders");
    occ->n_triangles = n_triangles;
    occ->n_positions = n_positions;
    occ->memory_budget = memory_budget;
    occ->fingerprint = wenv_fingerprint_floats(wenv_fingerprint_word(WENV_FINGERPRINT_START, n_positions), positions,
                                               3 * n_positions);
    for (size_t i = 0; i < 3 * n_triangles; i++)
        occ->fingerprint = wenv_fingerprint_word(occ->fingerprint, triangles[i]);
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (size_t i = 0; i < n_positions; i++)
        for (int k = 0; k < 3; k++) {
            lo[k] = fmin(lo[k], positions[3 * i + (size_t)k]);
            hi[k] = fmax(hi[k], positions[3 * i + (size_t)k]);
        }
    occ->size = sqrt((hi[0] - lo[0]) * (hi[0] - lo[0]) + (hi[1] - lo[1]) * (hi[1] - lo[1]) +
                     (hi[2] - lo[2]) * (hi[2] - lo[2]));
    wenv_error local = {0};
    occ->device = rtcNewDevice(NULL);
    if (!occ->device) {
        free(occ);
        return wenv_error_set(err, WENV_ERR_NOMEM, "Embree could not start (error %d)", (int)rtcGetDeviceError(NULL));
    }
    rtcSetDeviceErrorFunction(occ->device, on_error, &local);
    occ->scene = rtcNewScene(occ->device);
    RTCGeometry geom = occ->scene ? rtcNewGeometry(occ->device, RTC_GEOMETRY_TYPE_TRIANGLE) : NULL;
    float *vb = geom ? rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float),
                                               n_positions)
                     : NULL;
    uint32_t *ib = geom ? rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                                                  3 * sizeof(uint32_t), n_triangles)
                        : NULL;
    if (vb && ib) {
        memcpy(vb, positions, n_positions * 3 * sizeof(float));
        memcpy(ib, triangles, n_triangles * 3 * sizeof(uint32_t));
        occ->triangles = ib;
        occ->positions = vb;
        rtcCommitGeometry(geom);
        rtcAttachGeometry(occ->scene, geom);
        rtcSetSceneBuildQuality(occ->scene, RTC_BUILD_QUALITY_HIGH); /* built once, tested millions of times */
        /* conservative box tests: what a ray meets does not depend on how the tree was built, so
         * an occlusion made from the one before (another scene's tree) is a new cast's to the bit */
        rtcSetSceneFlags(occ->scene, RTC_SCENE_FLAG_ROBUST);
        rtcCommitScene(occ->scene);
    }
    if (geom)
        rtcReleaseGeometry(geom);
    rtcSetDeviceErrorFunction(occ->device, NULL, NULL); /* `local` is about to go */
    if (!vb || !ib || local.status != WENV_OK) {
        wenv_occluders_free(occ);
        if (local.status == WENV_OK)
            wenv_error_set(&local, WENV_ERR_NOMEM, "out of memory for occluders");
        return wenv_error_set(err, local.status, "%s", local.message);
    }
    *out = occ;
    return WENV_OK;
}

void wenv_occluders_free(wenv_occluders *occ)
{
    if (!occ)
        return;
    if (occ->scene)
        rtcReleaseScene(occ->scene);
    if (occ->device)
        rtcReleaseDevice(occ->device);
    free(occ);
}

size_t wenv_occluders_triangle_count(const wenv_occluders *occ) { return occ->n_triangles; }
size_t wenv_occluders_vertex_count(const wenv_occluders *occ) { return occ->n_positions; }
size_t wenv_occluders_memory_budget(const wenv_occluders *occ) { return occ->memory_budget; }
uint64_t wenv_occluders_fingerprint(const wenv_occluders *occ) { return occ->fingerprint; }
const uint32_t *wenv_occluders_triangles(const wenv_occluders *occ) { return occ->triangles; }
const float *wenv_occluders_positions(const wenv_occluders *occ) { return occ->positions; }
double wenv_occluders_size(const wenv_occluders *occ) { return occ->size; }
float wenv_occluders_offset(const wenv_occluders *occ)
{
    return (float)(WENV_OCCLUDER_OFFSET * (occ->size > 0.0 ? exp2(ceil(log2(occ->size))) : 1.0));
}

/* Rays handed to Embree at once: its stream interface sorts them into packets. */
#define STREAM 256

/* Rays from origins + k * origin_stride (0: all from one origin), each ending at fars[k] (NULL: all
 * at far); `coherent` when neighbouring rays run from near one another in near directions. */
static void test_from(const wenv_occluders *occ, const float *origins, size_t origin_stride, const float *dirs,
                      size_t n, float far, const float *fars, int coherent, unsigned char *blocked)
{
    struct RTCRay rays[STREAM];
    struct RTCIntersectContext context;
    for (size_t start = 0; start < n; start += STREAM) {
        size_t m = n - start < STREAM ? n - start : STREAM;
        for (size_t k = 0; k < m; k++) {
            const float *d = dirs + 3 * (start + k), *origin = origins + origin_stride * (start + k);
            rays[k] = (struct RTCRay){.org_x = origin[0], .org_y = origin[1], .org_z = origin[2], .tnear = 0.0f,
                                      .dir_x = d[0], .dir_y = d[1], .dir_z = d[2], .time = 0.0f,
                                      .tfar = fars ? fars[start + k] : far, .mask = UINT32_MAX, .id = (unsigned)k,
                                      .flags = 0};
        }
        rtcInitIntersectContext(&context);
        context.flags = coherent ? RTC_INTERSECT_CONTEXT_FLAG_COHERENT : RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT;
        rtcOccluded1M(occ->scene, &context, rays, (unsigned)m, sizeof rays[0]);
        for (size_t k = 0; k < m; k++)
            blocked[start + k] = rays[k].tfar < 0.0f; /* Embree marks an occluded ray with tfar = -inf */
    }
}

void wenv_occluders_test_rays(const wenv_occluders *occ, const float *origins, const float *dirs, size_t n, float tfar,
                              unsigned char *blocked)
{
    /* Whole streams per thread, marked incoherent (a hemisphere's rays from each point): Embree then
     * sorts them into packets, 1.4x the rays a second of one call per ray. */
    size_t streams = (n + STREAM - 1) / STREAM;
#pragma omp parallel for schedule(dynamic, 4)
    for (size_t s = 0; s < streams; s++) {
        size_t start = s * STREAM, m = n - start < STREAM ? n - start : STREAM;
        wenv_occluders_test_scattered(occ, origins + 3 * start, dirs + 3 * start, m, tfar, blocked + start);
    }
}

void wenv_occluders_test_scattered(const wenv_occluders *occ, const float *origins, const float *dirs, size_t n,
                                   float tfar, unsigned char *blocked)
{
    test_from(occ, origins, 3, dirs, n, tfar, NULL, 0, blocked);
}

void wenv_occluders_test(const wenv_occluders *occ, const float origin[3], const float *dirs, size_t n, float tfar,
                         unsigned char *blocked)
{
    test_from(occ, origin, 0, dirs, n, tfar, NULL, 1, blocked);
}

void wenv_occluders_test_until(const wenv_occluders *occ, const float origin[3], const float *dirs, const float *fars,
                               size_t n, unsigned char *blocked)
{
    test_from(occ, origin, 0, dirs, n, 0.0f, fars, 1, blocked);
}

void wenv_occluders_test_each(const wenv_occluders *occ, const float *origins, const float *dirs, const float *fars,
                              size_t n, unsigned char *blocked)
{
    test_from(occ, origins, 3, dirs, n, 0.0f, fars, 1, blocked);
}

/* The nearest hits of n rays, ray k from origins + k * origin_stride (0: all from one origin). */
static void hit_from(const wenv_occluders *occ, const float *origins, size_t origin_stride, const float *dirs,
                     size_t n, uint32_t *tri, float *uv)
{
    struct RTCRayHit rays[STREAM];
    struct RTCIntersectContext context;
    for (size_t start = 0; start < n; start += STREAM) {
        size_t m = n - start < STREAM ? n - start : STREAM;
        for (size_t k = 0; k < m; k++) {
            const float *d = dirs + 3 * (start + k), *o = origins + origin_stride * (start + k);
            rays[k].ray = (struct RTCRay){.org_x = o[0], .org_y = o[1], .org_z = o[2], .tnear = 0.0f,
                                          .dir_x = d[0], .dir_y = d[1], .dir_z = d[2], .time = 0.0f, .tfar = INFINITY,
                                          .mask = UINT32_MAX, .id = (unsigned)k, .flags = 0};
            rays[k].hit.geomID = RTC_INVALID_GEOMETRY_ID;
            rays[k].hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
        }
        rtcInitIntersectContext(&context);
        context.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
        rtcIntersect1M(occ->scene, &context, rays, (unsigned)m, sizeof rays[0]);
        for (size_t k = 0; k < m; k++) {
            int hit = rays[k].hit.geomID != RTC_INVALID_GEOMETRY_ID;
            tri[start + k] = hit ? rays[k].hit.primID : UINT32_MAX;
            uv[2 * (start + k)] = hit ? rays[k].hit.u : 0.0f;
            uv[2 * (start + k) + 1] = hit ? rays[k].hit.v : 0.0f;
        }
    }
}

void wenv_occluders_hit(const wenv_occluders *occ, const float origin[3], const float *dirs, size_t n, uint32_t *tri,
                        float *uv)
{
    hit_from(occ, origin, 0, dirs, n, tri, uv);
}

void wenv_occluders_hit_rays(const wenv_occluders *occ, const float *origins, const float *dirs, size_t n,
                             uint32_t *tri, float *uv)
{
    hit_from(occ, origins, 3, dirs, n, tri, uv);
}

typedef struct {
    void (*visit)(void *user, size_t triangle);
    void *user;
} near_visit;

static bool visit_near(struct RTCPointQueryFunctionArguments *args)
{
    const near_visit *v = args->userPtr;
    v->visit(v->user, args->primID);
    return false; /* the query's radius is left as it was */
}

void wenv_occluders_near(const wenv_occluders *occ, const float point[3], float radius,
                         void (*visit)(void *user, size_t triangle), void *user)
{
    struct RTCPointQuery query = {.x = point[0], .y = point[1], .z = point[2], .time = 0.0f, .radius = radius};
    struct RTCPointQueryContext context;
    rtcInitPointQueryContext(&context);
    near_visit v = {visit, user};
    rtcPointQuery(occ->scene, &query, &context, visit_near, &v);
}
