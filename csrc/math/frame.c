/* Tangent frames of normals (docs/ARCHITECTURE.md §3.1). */
#include "math/frame.h"

#include <string.h>

void wenv_frame(const double n[3], double f[9])
{
    double z1 = 1.0 + n[2];
    if (z1 < 1e-12) {
        /* n = -Z: the limit of the formula along -X; the only point where frames jump. */
        const double t[9] = {0, -1, 0, -1, 0, 0, 0, 0, -1};
        memcpy(f, t, sizeof t);
        return;
    }
    double a = 1.0 / z1, b = -n[0] * n[1] * a;
    f[0] = 1.0 - n[0] * n[0] * a;
    f[1] = b;
    f[2] = -n[0];
    f[3] = b;
    f[4] = 1.0 - n[1] * n[1] * a;
    f[5] = -n[1];
    f[6] = n[0];
    f[7] = n[1];
    f[8] = n[2];
}
