#include "math/quadrature.h"

#include <math.h>

/* Newton on P_n from the Abramowitz & Stegun 25.4.29 start. */
void wenv_gauss_legendre_01(size_t n, double *x, double *w)
{
    for (size_t i = 0; i < (n + 1) / 2; i++) {
        double z = cos(M_PI * ((double)i + 0.75) / ((double)n + 0.5));
        double dp = 1.0;
        for (int it = 0; it < 100; it++) {
            double p0 = 1.0, p1 = 0.0;
            for (size_t j = 1; j <= n; j++) {
                double p2 = p1;
                p1 = p0;
                p0 = ((2.0 * (double)j - 1.0) * z * p1 - ((double)j - 1.0) * p2) / (double)j;
            }
            dp = (double)n * (z * p0 - p1) / (z * z - 1.0);
            double dz = p0 / dp;
            z -= dz;
            if (fabs(dz) < 1e-15)
                break;
        }
        double wt = 2.0 / ((1.0 - z * z) * dp * dp);
        /* map [-1, 1] -> [0, 1] */
        x[i] = 0.5 * (1.0 - z);
        x[n - 1 - i] = 0.5 * (1.0 + z);
        w[i] = w[n - 1 - i] = 0.5 * wt;
    }
}
