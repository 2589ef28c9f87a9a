#include "math/projected_solid_angle.h"

#include <math.h>

/* The polygon's part on the positive side of the plane through the origin with normal `normal`
 * (Sutherland-Hodgman against one plane): at most n + 1 corners into out. */
static size_t clip_to_horizon(const double *in, size_t n, const double normal[3], double *out)
{
    size_t m = 0;
    for (size_t i = 0; i < n; i++) {
        const double *a = in + 3 * i, *b = in + 3 * ((i + 1) % n);
        double da = normal[0] * a[0] + normal[1] * a[1] + normal[2] * a[2];
        double db = normal[0] * b[0] + normal[1] * b[1] + normal[2] * b[2];
        if (da >= 0.0) {
            for (int c = 0; c < 3; c++)
                out[3 * m + (size_t)c] = a[c];
            m++;
        }
        if ((da >= 0.0) != (db >= 0.0)) {
            double t = da / (da - db);
            for (int c = 0; c < 3; c++)
                out[3 * m + (size_t)c] = a[c] + t * (b[c] - a[c]);
            m++;
        }
    }
    return m;
}

double wenv_projected_solid_angle(const double *corners, size_t n, const double normal[3])
{
    double clipped[3 * WENV_POLYGON_MAX];
    size_t m = clip_to_horizon(corners, n, normal, clipped);
    if (m < 3)
        return 0.0;
    double sum = 0.0;
    for (size_t i = 0; i < m; i++) {
        const double *a = clipped + 3 * i, *b = clipped + 3 * ((i + 1) % m);
        double cr[3] = {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
        double len = sqrt(cr[0] * cr[0] + cr[1] * cr[1] + cr[2] * cr[2]);
        if (len <= 0.0)
            continue; /* an edge through the point itself, or of no length: it spans no angle */
        /* the angle the edge spans, by atan2: acos loses it for the short edges of a far lamp */
        double angle = atan2(len, a[0] * b[0] + a[1] * b[1] + a[2] * b[2]);
        sum += angle * (normal[0] * cr[0] + normal[1] * cr[1] + normal[2] * cr[2]) / len;
    }
    return fabs(0.5 * sum);
}
