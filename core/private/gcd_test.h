/* gcd_test.h — entry points into single phases of the gCD core, for the
 * tests that compare each phase with its CPU reference.  Not part of the
 * public API; the same code paths as gdt_core_triangulate. */
#ifndef GCD_TEST_H
#define GCD_TEST_H

#include <stddef.h>
#include <stdint.h>

#include "gdt_core.h"
#include "gdt_error.h"
#include "gdt_mesh.h"

/* Phase 1 alone on a W x H grid: sites[i] is a texel index (repeats: the
 * lowest i wins).  colour[y*W + x] receives the texel index of the site of
 * every texel (standard flooding).  colour holds W*H values (caller-owned). */
gdt_status gcd_test_voronoi(gdt_core *c, const uint32_t *sites, size_t nsites, uint32_t W,
                            uint32_t H, uint32_t *colour, gdt_error *err);

/* Row bands of the column pass (1 = none). */
void gcd_test_set_bands(gdt_core *c, unsigned bands);

/* Phase 5's block-local flipping: about `blocks` blocks of at least
 * min_block triangle slots, queues of at most `queue` edges (a power of
 * two, at least 8); blocks = 0: the parallel rounds alone; SIZE_MAX, 0, 0:
 * the defaults of the device. */
void gcd_test_set_flip_blocks(gdt_core *c, size_t blocks, size_t min_block, size_t queue);


/* Phases 1 and 2 on real input (grid_n may be as small as 2): all receives
 * the triangulation after Phase 2 — vertices n + 12 (positions: texel
 * corner of every kept point, true position of every missing one; the 12
 * fakes at (0, 0)), every triangle slot with its links.  centre receives
 * the centre of the fake boundary. */
gdt_status gcd_test_phase2(gdt_core *c, const gdt_ipt *pts, size_t n, int grid_n, gdt_mesh *all,
                           int64_t centre[2], gdt_core_stats *st, gdt_error *err);

/* Phase 5 alone on a valid triangulation m of its points (all real, hull
 * edges without neighbour): m's triangles and links are replaced by the
 * flipped ones. */
gdt_status gcd_test_flip(gdt_core *c, gdt_mesh *m, gdt_core_stats *st, gdt_error *err);

/* The scan kernels on in[0..n): out receives the exclusive prefix sums and
 * *total the sum; flagged[0..*nflagged) the indices of the nonzero entries
 * in increasing order (the compaction kernel).  Caller-owned arrays of n. */
gdt_status gcd_test_scan(gdt_core *c, const uint32_t *in, size_t n, uint32_t *out,
                         uint32_t *total, size_t *nflagged, uint32_t *flagged, gdt_error *err);

/* The radix sort kernels: keys/vals[0..n) sorted in place, stably, by the
 * low `bits` bits of the keys (rounded up to whole bytes). */
gdt_status gcd_test_radix(gdt_core *c, uint32_t *keys, uint32_t *vals, size_t n, unsigned bits,
                          gdt_error *err);

#endif
