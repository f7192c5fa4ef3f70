/* gdt_predicates.h — the one module of exact geometric predicates.
 *
 * Coordinates are tile-local lattice integers.  Precondition for every
 * predicate: each coordinate lies in [0, 2^31 - 1] (so every difference fits
 * in 32 bits signed); callers subtract the tile origin first.  Under that
 * precondition:
 *   - orient2d is exact in int64 (|det| < 2^63);
 *   - incircle is exact in 128-bit integers built from 64-bit halves
 *     (|det| <= 6 L^4 < 2^127 with L = 2^31), no __int128 required, so the
 *     same arithmetic compiles as OpenCL C;
 *   - a double-precision filter with a proven error bound decides almost all
 *     cases; only undecided ones take the exact integer path.
 * Results are signs: +1, 0, -1.  No other code in gdt-tile evaluates a
 * geometric determinant; everything goes through here.  The arithmetic is
 * kernels/gdt_exact.clh, the same source the OpenCL kernels include.
 * The predicates are pure and thread-safe (each thread passes its own
 * counters); debug builds assert the coordinate precondition.
 *
 * The unique-Delaunay tie-break (Dyken & Floater, preferred directions
 * d1 = (1,0), d2 = (1,1)): among the two diagonals e, f of a convex
 * co-circular quad, e wins iff
 *   (e.d1)^2 |f|^2 > (f.d1)^2 |e|^2, or equal and (e.d2)^2 |f|^2 > (f.d2)^2 |e|^2.
 * For non-parallel e, f exactly one of them wins.
 */
#ifndef GDT_PREDICATES_H
#define GDT_PREDICATES_H

#include <assert.h>
#include <stdint.h>

#include "gdt_error.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Largest legal tile-local coordinate. */
#define GDT_COORD_MAX INT64_C(2147483647)

typedef struct gdt_ipt {
    int64_t x, y; /* tile-local lattice coordinates, 0 <= x, y <= GDT_COORD_MAX */
} gdt_ipt;

/* Call counters (shown with -v).  One per thread or per context: the
 * predicates update them without synchronisation.  Every predicate accepts
 * st == NULL (nothing is counted).  Start from a zeroed struct. */
typedef struct gdt_pred_stats {
    uint64_t orient_calls;     /* orient2d, including the convexity tests of edge_needs_flip */
    uint64_t incircle_calls;   /* incircle, including the one inside edge_needs_flip */
    uint64_t incircle_exact;   /* incircle calls the filter could not decide */
    uint64_t tiebreak_calls;   /* prefer_diagonal calls and co-circular convex quads
                                  decided by the tie-break in edge_needs_flip */
} gdt_pred_stats;

/* dst += src, field by field (merging per-thread counters). */
void gdt_pred_stats_add(gdt_pred_stats *dst, const gdt_pred_stats *src);

/* +1 if a, b, c turn counter-clockwise, -1 clockwise, 0 collinear. */
int gdt_orient2d(gdt_pred_stats *st, gdt_ipt a, gdt_ipt b, gdt_ipt c);

/* For a, b, c counter-clockwise: +1 if d lies strictly inside their
 * circumcircle, 0 on it, -1 outside.  (For clockwise a, b, c the sign flips.) */
int gdt_incircle(gdt_pred_stats *st, gdt_ipt a, gdt_ipt b, gdt_ipt c, gdt_ipt d);

/* Tie-break between the diagonals e = e1 - e0 and f = f1 - f0 (given as
 * integer vectors with components in [-GDT_COORD_MAX, GDT_COORD_MAX]):
 * returns +1 if e wins, -1 if f wins, 0 only if e and f are parallel. */
int gdt_prefer_diagonal(gdt_pred_stats *st, gdt_ipt e, gdt_ipt f);

/* The Lawson test with the tie-break, for the edge a-b shared by the
 * counter-clockwise triangles (a, b, c) and (b, a, d):
 * returns 1 if the edge must be flipped to c-d, i.e. d is strictly inside
 * circle(a, b, c), or d is on it and the quad a-d-b-c is strictly convex and
 * the diagonal c-d wins the tie-break over a-b.  Returns 0 if a-b is locally
 * optimal. */
int gdt_edge_needs_flip(gdt_pred_stats *st, gdt_ipt a, gdt_ipt b, gdt_ipt c, gdt_ipt d);

/* A certified outer box of the closed circumdisk of the triangle (a, b, c):
 * on return 1, bounds = {xmin, ymin, xmax, ymax} (tile-local units) with
 * xmin <= every x of the closed disk <= xmax, and the same in y.  The box is
 * computed in double with a proven error bound added outwards, so it may be
 * a little larger than the disk but never smaller: tests built on it are
 * conservative (they may refuse a disk that fits, never accept one that does
 * not).  Returns 0 (bounds untouched) when a, b, c are not strictly
 * counter-clockwise: such a triangle has no disk to certify.
 * Error analysis (u = 2^-53): with b' = b - a, c' = c - a, D = b' x c' and
 * M_x = |c'_y| |b'|^2 + |b'_y| |c'|^2 (M_y alike), the computed centre
 * offset is within 7u M_x / (2D) of the true one per axis and the radius
 * within the sum of both plus 3u r; the slack added is 32u (M_x + M_y) / (2D)
 * + 8u (|a| + |centre offset| + r) per side, several times that bound. */
int gdt_circumdisk_bounds(gdt_pred_stats *st, gdt_ipt a, gdt_ipt b, gdt_ipt c, double bounds[4]);

/* Whether the circumcircle of the strictly counter-clockwise triangle
 * (a, b, c) has a diameter below m (> 0): returns 1 only if it is proven
 * that 2R < m, so that every point of the closed disk lies at a distance
 * below m from a (and from b and c); 0 otherwise, and when (a, b, c) is
 * not strictly counter-clockwise.  Division- and root-free: with b' = b - a,
 * c' = c - a and D = b' x c' > 0, (2R)^2 = |b'|^2 |c'|^2 |b' - c'|^2 / D^2,
 * so 2R < m iff m^2 D^2 > |b'|^2 |c'|^2 |b' - c'|^2.  Both sides are
 * evaluated in double, within a relative (1 + u)^5 and (1 + u)^8 of the
 * true values (u = 2^-53: the differences and D are exact integers, every
 * operand positive); the right side is raised by 64u before the strict
 * comparison, more than covers both, so the answer 1 is exact.  m must be
 * below 2^53. */
int gdt_circumdiameter_below(gdt_pred_stats *st, gdt_ipt a, gdt_ipt b, gdt_ipt c, int64_t m);

/* Whether the closed circumdisk of the triangle (a, b, c) (either
 * orientation) misses the closed quadrant strip
 *   Q = [x0, x1] x [y, +inf):
 * returns 1 only if it is proven that no real point (px, py) with
 * x0 <= px <= x1 and py >= y lies in the closed disk (a point on the circle
 * counts as inside); 0 when the disk meets Q, when a, b, c are collinear, when
 * the arguments break 0 <= x0 <= x1 <= GDT_COORD_MAX, 0 <= y <= GDT_COORD_MAX,
 * or when the filter cannot decide.  Conservative like gdt_circumdisk_bounds:
 * it may answer 0 for a disk that misses Q, never 1 for one that meets it.
 * Decided by the certified box of gdt_circumdisk_bounds when the box misses
 * Q, and otherwise, for a centre certified west of x0 (east of x1) and south
 * of y, by the exact in-circle test of the corner (x0, y) (resp. (x1, y)),
 * the point of Q nearest to the centre.  Counts one orient2d call, plus one
 * incircle call when a corner is tested. */
int gdt_circumdisk_misses_strip(gdt_pred_stats *st, gdt_ipt a, gdt_ipt b, gdt_ipt c, int64_t x0,
                                int64_t x1, int64_t y);

/* ---- Half-lattice points (rasterisation of the TIN) --------------------
 *
 * Cell centres of a DEM grid lie on the half lattice: lattice coordinates
 * that are integers or halves.  They are given in doubled coordinates
 * (2x, 2y), lattice vertices too (2 ix, 2 iy), so that everything stays an
 * integer.  These predicates take global (not tile-local) coordinates:
 * precondition |x|, |y| <= GDT_HALF_MAX for every gdt_hpt, so that every
 * difference fits in 62 bits, every cross product in 124 and their
 * difference in 125: the arithmetic is exact in __int128 (GCC and Clang on
 * 64-bit hosts; host code only, never in a kernel). */
#define GDT_HALF_MAX (INT64_C(1) << 60)

typedef struct gdt_hpt {
    int64_t x, y; /* doubled lattice coordinates, |x|, |y| <= GDT_HALF_MAX */
} gdt_hpt;

__extension__ typedef __int128 gdt_i128;

/* The exact orientation determinant (b - a) x (p - a) (positive when a, b,
 * p turn counter-clockwise).  Counts one orient2d call.  Inline: the
 * rasteriser evaluates it for every cell centre. */
static inline gdt_i128 gdt_orient2d_half_det(gdt_pred_stats *st, gdt_hpt a, gdt_hpt b, gdt_hpt p)
{
    assert(a.x >= -GDT_HALF_MAX && a.x <= GDT_HALF_MAX && a.y >= -GDT_HALF_MAX &&
           a.y <= GDT_HALF_MAX && b.x >= -GDT_HALF_MAX && b.x <= GDT_HALF_MAX &&
           b.y >= -GDT_HALF_MAX && b.y <= GDT_HALF_MAX && p.x >= -GDT_HALF_MAX &&
           p.x <= GDT_HALF_MAX && p.y >= -GDT_HALF_MAX && p.y <= GDT_HALF_MAX);
    if (st != NULL)
        st->orient_calls++;
    return (gdt_i128)(b.x - a.x) * (gdt_i128)(p.y - a.y) -
           (gdt_i128)(b.y - a.y) * (gdt_i128)(p.x - a.x);
}

/* The same determinant for small relative coordinates: the cross product
 * (ux, uy) x (vx, vy) = ux vy - uy vx, exact in 64 bits when every
 * |component| <= GDT_SMALL_DET_MAX (products up to 2^60, their difference
 * up to 2^61).  An orientation determinant does not change under
 * translation, so gdt_orient2d_half_det(a, b, p) equals this of b - a and
 * p - a whenever those are that small.  Counts one orient2d call. */
#define GDT_SMALL_DET_MAX (INT64_C(1) << 30)

static inline int64_t gdt_orient2d_small_det(gdt_pred_stats *st, int64_t ux, int64_t uy,
                                             int64_t vx, int64_t vy)
{
    assert(ux >= -GDT_SMALL_DET_MAX && ux <= GDT_SMALL_DET_MAX && uy >= -GDT_SMALL_DET_MAX &&
           uy <= GDT_SMALL_DET_MAX && vx >= -GDT_SMALL_DET_MAX && vx <= GDT_SMALL_DET_MAX &&
           vy >= -GDT_SMALL_DET_MAX && vy <= GDT_SMALL_DET_MAX);
    if (st != NULL)
        st->orient_calls++;
    return ux * vy - uy * vx;
}

/* The half-open ownership rule of an edge u -> v of a counter-clockwise
 * triangle (its interior on the left): returns 1 if p lies strictly left of
 * the directed line u -> v, or on it and the edge is *owned*:
 *     v.y < u.y, or v.y == u.y and v.x > u.x
 * (in a counter-clockwise triangle: its west edges, going south, and its
 * south edges, going east).  Equivalently, p is moved by (eps, eps^2) for
 * an infinitesimal eps > 0 (east, then a much smaller step north) and then
 * tested strictly.  For u != v exactly one of (u -> v) and (v -> u) owns a
 * point on the line, so a point of the interior of a triangulated region
 * belongs to exactly one triangle whose three edges own it (the moved point
 * lies in the interior of exactly one triangle); points of the region's
 * boundary belong to one triangle or to none.  Counts one orient2d call. */
int gdt_edge_owns_half(gdt_pred_stats *st, gdt_hpt u, gdt_hpt v, gdt_hpt p);

/* The same rule for the points p_k = (x0 + k dx, y) of a row, dx > 0:
 * narrows [*lo, *hi] to the k of it whose point the edge u -> v owns, which
 * is an interval (empty: *lo > *hi on return).  Exact (floor and ceiling
 * divisions in 128 bits).  Precondition: every p_k with k in the given
 * [*lo, *hi] obeys the half-lattice range.  Counts one orient2d call. */
void gdt_edge_owned_range(gdt_pred_stats *st, gdt_hpt u, gdt_hpt v, int64_t x0, int64_t dx,
                          int64_t y, int64_t *lo, int64_t *hi);

/* Faults found by gdt_predicates_selftest (bit mask). */
#define GDT_FPENV_CONTRACTION 0x1u /* a*b - c was fused into one rounding (FMA) */
#define GDT_FPENV_REASSOC 0x2u     /* (a + b) - a was simplified, or extended precision */
#define GDT_FPENV_ROUNDING 0x4u    /* rounding mode is not round-to-nearest */
#define GDT_FPENV_FILTER 0x8u      /* the filter contradicted the integer path */
#define GDT_FPENV_INT128 0x10u     /* the integer path gave a wrong known answer */

/* Checks that the floating-point environment this module was compiled and
 * runs with matches the assumptions of the filter's error analysis (binary64,
 * round to nearest, no contraction, no reassociation, no extended
 * intermediates), and that the filter and the integer path agree on a set of
 * near-degenerate cases at extreme coordinates.  Call once at start-up,
 * before trusting any predicate.
 * returns: GDT_OK, or GDT_EINTERNAL (message GDT-7601) naming the faults.
 * faults (may be NULL) receives the GDT_FPENV_* mask, 0 when all is well.
 * notes: the checks use volatile operands so the compiler cannot fold them;
 *   they detect what the build actually did (e.g. fast-math or contraction
 *   options), whatever the flags claim. */
gdt_status gdt_predicates_selftest(unsigned *faults, gdt_error *err);

#ifdef __cplusplus
}
#endif
#endif
