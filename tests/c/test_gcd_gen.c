/* test_gcd_gen.c — see test_gcd_gen.h. */
#include "test_gcd_gen.h"

#include <math.h>
#include <stdlib.h>

gdt_ipt *gcd_gen_lidar(gen_rng *rng, size_t n, int64_t extent, size_t *out_n)
{
    gdt_ipt *p = malloc((n + 1) * sizeof *p);
    size_t k = 0;
    if (p == NULL)
        return NULL;
    double line_gap = (double)extent / sqrt((double)n / 6.0);
    while (k < n) {
        int strip = (int)gen_below(rng, 3);
        double ang = 0.15 * strip + 0.02 * ((double)gen_below(rng, 1000) / 1000.0);
        double y0 = (double)gen_below(rng, (uint64_t)extent);
        double step = line_gap / 6.0;
        double x = 0;
        for (int j = 0; j < 600 && k < n; j++) {
            x += step * (0.9 + 0.2 * (double)gen_below(rng, 1000) / 1000.0);
            double px = x * cos(ang) - 0.0 * sin(ang);
            double py = y0 + x * sin(ang) + 0.3 * line_gap * sin(x / line_gap);
            int64_t ix = (int64_t)px % extent, iy = (int64_t)py % extent;
            if (ix < 0)
                ix += extent;
            if (iy < 0)
                iy += extent;
            /* a lake without returns */
            double dx = (double)ix - 0.3 * (double)extent, dy = (double)iy - 0.6 * (double)extent;
            if (dx * dx + dy * dy < 0.02 * (double)extent * (double)extent)
                continue;
            p[k].x = ix;
            p[k].y = iy;
            k++;
        }
        if (gen_below(rng, 50) == 0) {
            /* a gridded DEM patch on the lattice */
            int64_t gx = (int64_t)gen_below(rng, (uint64_t)extent / 2);
            int64_t gy = (int64_t)gen_below(rng, (uint64_t)extent / 2);
            int64_t gs = (int64_t)(line_gap / 2) + 1;
            for (int a = 0; a < 20 && k < n; a++)
                for (int b = 0; b < 20 && k < n; b++) {
                    p[k].x = gx + a * gs;
                    p[k].y = gy + b * gs;
                    k++;
                }
        }
    }
    gen_dedup(p, &k);
    *out_n = k;
    return p;
}

