/* gen_degenerate.h — seeded point generators for the mesh tests (the
 * degenerate corpus of DESIGN.md section 6.7) and the test helpers they
 * share.
 *
 * Every generator returns a malloc'ed array of tile-local points (all
 * coordinates in [0, GDT_COORD_MAX]) and its length in *n; the caller frees
 * it.  NULL means out of memory (or an empty request).  Unless a generator
 * says otherwise the points are distinct; gen_dedup removes duplicates.
 */
#ifndef GEN_DEGENERATE_H
#define GEN_DEGENERATE_H

#include <stddef.h>
#include <stdint.h>
#include <stdio.h>

#include "gdt_check.h"
#include "gdt_mesh.h"
#include "gdt_predicates.h"

/* ---- seeded random numbers (xorshift64*) ---- */
typedef struct gen_rng {
    uint64_t s;
} gen_rng;

void gen_seed(gen_rng *r, uint64_t seed);
uint64_t gen_next(gen_rng *r);
/* Uniform in [0, n), n > 0. */
uint64_t gen_below(gen_rng *r, uint64_t n);
/* Uniform in [lo, hi]. */
int64_t gen_range(gen_rng *r, int64_t lo, int64_t hi);

/* ---- generators ---- */

/* n points uniform in [lo, hi]^2, duplicates removed (so maybe fewer). */
gdt_ipt *gen_uniform(gen_rng *r, size_t n, int64_t lo, int64_t hi, size_t *out_n);
/* nx * ny axis-aligned grid: (x0 + i*step, y0 + j*step). */
gdt_ipt *gen_grid(size_t nx, size_t ny, int64_t x0, int64_t y0, int64_t step, size_t *out_n);
/* Integer lattice spanned by (a, b) and (-b, a) (a rotated square grid),
 * points i*(a,b) + j*(-b,a) + (cx, cy) for |i|, |j| <= k that fall in
 * [0, GDT_COORD_MAX]^2. */
gdt_ipt *gen_rotated_grid(int64_t k, int64_t a, int64_t b, int64_t cx, int64_t cy, size_t *out_n);
/* Every lattice point on the circle x^2 + y^2 = r^2 around (cx, cy);
 * r = 5^k 13 ... has many. */
gdt_ipt *gen_circle(int64_t cx, int64_t cy, int64_t r, size_t *out_n);
/* n points within +-width of the circle of radius r around (cx, cy),
 * duplicates removed. */
gdt_ipt *gen_thin_circle(gen_rng *r, size_t n, int64_t cx, int64_t cy, int64_t radius,
                         int64_t width, size_t *out_n);
/* n distinct points (x0 + t*dx, y0 + t*dy), t in [0, span) random, shuffled. */
gdt_ipt *gen_collinear(gen_rng *r, size_t n, int64_t x0, int64_t y0, int64_t dx, int64_t dy,
                       int64_t span, size_t *out_n);
/* nc clusters of per points each, cluster centres uniform in the tile,
 * points within +-spread of them; duplicates removed. */
gdt_ipt *gen_clusters(gen_rng *r, size_t nc, size_t per, int64_t spread, size_t *out_n);
/* Points at and near the extremes of the range: the four corners, small
 * grids hugging them, and random points on the four borders. */
gdt_ipt *gen_extremes(gen_rng *r, size_t *out_n);
/* n copies of (x, y) mixed with m random others: NOT distinct. */
gdt_ipt *gen_with_duplicates(gen_rng *r, size_t n, size_t m, int64_t x, int64_t y, size_t *out_n);

/* Removes duplicates (keeps the first occurrence, preserves the order). */
void gen_dedup(gdt_ipt *pts, size_t *n);
/* Fisher-Yates shuffle; perm (may be NULL) receives the original index of
 * each output position when not NULL (perm[i] = old index of pts[i]). */
void gen_shuffle(gen_rng *r, gdt_ipt *pts, size_t n, int64_t *perm);

/* ---- test helpers ---- */

/* The counts of a mesh test; CHECK(t, cond, fmt, ...) records one check. */
typedef gdt_checks tctx;

#define CHECK(t, cond, ...) GDT_CHECK(t, cond, __VA_ARGS__)

/* Brute force: no point lies strictly inside the circumcircle of any
 * triangle (O(F n)).  Returns 0, or -1 after describing the first fault. */
int gen_brute_empty_circles(const gdt_mesh *m, char *why, size_t why_len);

/* Canonical triangle list of m (gdt_mesh_canonical), malloc'ed. */
int64_t *gen_canonical(const gdt_mesh *m);

/* Equal as canonical triangle sets; describes the first difference. */
int gen_same_triangles(const gdt_mesh *a, const gdt_mesh *b, char *why, size_t why_len);

/* Runs gdt_check_mesh and gdt_check_delaunay; records failures in t with
 * the label. Returns 0 when both pass. */
int gen_check_all(tctx *t, const gdt_mesh *m, const char *label);

/* Report and exit status of a test program. */
int gen_finish(const tctx *t, const char *name);

#endif
