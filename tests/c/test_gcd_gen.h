/* test_gcd_gen.h — point generators of the gCD core tests and tools (on top
 * of gen_degenerate.h). */
#ifndef TEST_GCD_GEN_H
#define TEST_GCD_GEN_H

#include <stddef.h>
#include <stdint.h>

#include "gen_degenerate.h"

/* LiDAR-like tile of about n distinct points in [0, extent)^2: zig-zag scan
 * lines of a sweeping sensor (dense along a line, sparse across) in three
 * overlapping strip directions, a lake without returns, and small gridded
 * DEM patches.  malloc'ed; *out_n receives the count. */
gdt_ipt *gcd_gen_lidar(gen_rng *rng, size_t n, int64_t extent, size_t *out_n);

#endif
