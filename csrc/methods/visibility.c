#include "methods/visibility.h"

static int inside_frustum(const double m[16], const float p[3])
{
    double clip[4];
    for (int r = 0; r < 4; r++)
        clip[r] = m[4 * r] * p[0] + m[4 * r + 1] * p[1] + m[4 * r + 2] * p[2] + m[4 * r + 3];
    double w = clip[3];
    return w > 0.0 && clip[0] >= -w && clip[0] <= w && clip[1] >= -w && clip[1] <= w && clip[2] >= -w &&
           clip[2] <= w;
}

size_t wenv_visible_vertices(const float *positions, const float *normals, size_t n, const double eye[3],
                             const double *view_projection, unsigned char *visible)
{
    size_t count = 0;
    long long nn = (long long)n;
#pragma omp parallel for reduction(+ : count) schedule(static) if (n > 16384)
    for (long long ii = 0; ii < nn; ii++) {
        size_t i = (size_t)ii;
        const float *p = positions + 3 * i, *nrm = normals + 3 * i;
        double facing = nrm[0] * (eye[0] - p[0]) + nrm[1] * (eye[1] - p[1]) + nrm[2] * (eye[2] - p[2]);
        int seen = facing > 0.0 && (!view_projection || inside_frustum(view_projection, p));
        visible[i] = (unsigned char)seen;
        count += (size_t)seen;
    }
    return count;
}
