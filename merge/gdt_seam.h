/* gdt_seam.h — the seam merge: everything the tiles could not certify.
 *
 * Notation: P is the cloud, T = T_{d1,d2}(P) and, for any point set A,
 * T(A) = T_{d1,d2}(A); C is the set of certified triangles of all tiles
 * (each in T, see gdt_certify.h), R the part of the hull of P that C does
 * not cover, E* the triangles of T in R: what the merge must emit.
 *
 * Per tile (gdt_seam_extract), the seam vertices U_T are the vertices of the
 * tile's uncertified triangles, the vertices of its hull edges, and every
 * point of a tile with no triangle (< 3 points, or all collinear).  The
 * barrier edges are the edges of certified triangles whose other side is an
 * uncertified triangle or the tile's hull, directed with the certified
 * triangle on their left.
 *
 * Why triangulating seam vertices is enough:
 *   a. every triangle of T not in C has its three vertices in U, the union
 *      of the U_T: a vertex outside U is interior to its tile's hull with
 *      only certified triangles around it, and those form its whole star
 *      in T;
 *   b. for point sets A within X, a triangle (or an edge) of T(X) with its
 *      vertices in A is one of T(A): the tie-break is a consistent symbolic
 *      perturbation of the lifting, and a lower face of the lifted X stays
 *      one for any subset holding its vertices.  Conversely a triangle of
 *      T(A) whose closed circumdisk holds no point of X \ A is a triangle of
 *      T(X): those points lift strictly above its plane;
 *   c. the border between C and the rest of the plane consists of barrier
 *      edges with C on their left (an edge of a certified triangle whose
 *      neighbour in T is not certified: that neighbour is also its tile
 *      neighbour, or has a vertex in another tile, or the edge is on the
 *      hull), each an edge of T(U) by (a, b).  Two certified triangles of
 *      different tiles never share an edge (a triangle's vertices are own
 *      points of its tile), so C never lies on the right of a barrier edge.
 *      Hence E* is exactly the set of triangles of T(U) that do not overlap
 *      C.
 *
 * The merge by rows (gdt_merger_round).  Tiles are ordered by (j, i); a row
 * is the tiles of one j, rows without tiles are skipped.  For the rows
 * r = 0, 1, ... in that order: S_r is the seam of row r's tiles, A_r = S_0
 * u ... u S_r, C_r the certified triangles of rows <= r, [X0, X1] the
 * cloud's x range in the merge frame (every seam vertex has X0 <= x <= X1),
 * Y_{r+1} the merge-frame y of the south edge of the next row, and
 *   Q_{r+1} = [X0, X1] x [Y_{r+1}, +inf):
 * every point of a later row lies in Q_{r+1}, and so does every triangle
 * with its vertices in later rows (Q_{r+1} is convex).  Round r holds a band
 * W_r within A_r and a list of walls (directed edges), triangulates W_r
 * (DT(W_r) = T(W_r), the reference triangulator) and classifies its
 * triangles:
 *   covered: reached by a flood from the triangle left of every wall that
 *            never crosses a wall;
 *   emitted: not covered, and final: its closed circumdisk provably misses
 *            Q_{r+1} (gdt_circumdisk_misses_strip, conservative: it may
 *            leave a final triangle pending, never the reverse); in the
 *            last round every triangle that is not covered;
 *   pending: the others.
 * It hands on to round r + 1:
 *   W'_r: the vertices of pending triangles and the vertices on the hull of
 *         DT(W_r) (all of W_r when DT(W_r) has no triangle); the band of
 *         round r + 1 is W_{r+1} = W'_r u S_{r+1};
 *   walls: those walls of round r, and those edges of triangles emitted
 *         in round r (directed with the triangle on their left), whose
 *         right side in DT(W_r) is a pending triangle or the outside of the
 *         hull; then the barrier edges of row r + 1 join them.
 * The walls of round 0 are row 0's barrier edges.  A handed-on wall has
 * both ends in W'_r (they are vertices of the pending triangle, or hull
 * vertices).  A wall whose right side was emitted is dropped even when both
 * its ends are kept: a region emitted in round r and enclosed by certified
 * triangles would otherwise be walled off from every seed in round r + 1
 * and emitted again.
 *
 * Let E_r be the triangles emitted in rounds <= r (E_{-1} empty) and
 * Z_r = hull(A_r) \ (C_r u E_{r-1}): what round r has to find.  We show,
 * by induction over the rounds:
 *   I1. hull(W_r) = hull(A_r) and every point of A_r on the boundary of
 *       hull(A_r) is in W_r;
 *   I2. Z_r is the union of a set Z*_r of triangles of T(A_r), and Z*_r is
 *       in DT(W_r);
 *   I3. every wall is an edge of DT(W_r) with C_r or E_{r-1} on its left,
 *       and on its right Z_r or the outside of hull(A_r), unless the
 *       reverse edge is a wall as well;
 *   I4. every edge of DT(W_r) between Z_r and C_r u E_{r-1} is a wall;
 *   L.  a barrier edge of a row q <= r, or an edge of a triangle emitted in
 *       a round q <= r directed with it on its left, whose right side
 *       (next to it) avoids C_r u E_r, is handed on to round r + 1 (it is a
 *       wall in every round after q up to r + 1, and in round q too for a
 *       barrier edge).
 * The covered triangles are then exactly those outside Z_r.  The flood
 * starts outside Z_r (I3) and never enters it (I4; no wall runs inside Z_r,
 * its left side being outside).  Conversely let K be a maximal set of
 * triangles outside Z_r connected across edges that are not walls.  An
 * edge of K's border is a wall or a hull edge h of DT(W_r), which by I1 is a
 * hull edge of T(A_r).  Inside h lies C_r (then h is a barrier edge, C's
 * border consisting of edges of T(A_r) by (c, b)) or a triangle of E_{r-1}
 * with edge h; in both cases h is a wall with K on its left (a barrier
 * edge of row r, or by L for round r - 1: its right side is outside
 * hull(A_r)).  A wall with K on its right has its reverse as a wall (I3:
 * K is neither Z_r nor outside the hull), with K on the left.  So K holds a seed, every
 * triangle outside Z_r is covered, and the uncovered triangles are Z*_r.
 * What is emitted is right: a final triangle t of Z*_r has a closed disk
 * that misses Q_{r+1}, which holds every point of U \ A_r, so the disk holds
 * no point of U \ A_r and t is in T(U) (b); only that is asked of the disk.
 * t lies in its disk, so it does not overlap C_r, nor a certified triangle
 * of a later row (that lies in Q_{r+1}), so t is in E* (c); it is not in
 * E_{r-1} (Z_r excludes it).  In the last round A_r = U and C_r = C, so Z*_r = E* \ E_{r-1}, all
 * emitted.  Every face of E* is emitted once, and the hull of the last
 * DT(W_r) is the hull of U (I1), i.e. of P.
 * Round 0: W_0 = A_0, DT(W_0) = T(A_0); Z_0 is bounded by barrier edges
 * (c), which are edges of T(A_0) (b): I1, I2, I4 hold, and I3 since the
 * right side of a barrier edge is a triangle of R or outside hull(P) (c)
 * and E_{-1} is empty.
 * Round r + 1 from round r:
 *   L: in each round i from q to r, such an edge is a wall (a barrier
 *      edge of row i, or by L for i - 1) and an edge of DT(W_i) (I3), or,
 *      for i = q, an edge of a triangle emitted in round i.  Its right side
 *      avoids C_i u E_i, so it is the outside of hull(A_i) or, the
 *      uncovered triangles being Z*_i, a triangle of Z*_i that is not
 *      emitted, i.e. pending: the edge is handed on.
 *   I1: a point of A_r on the boundary of hull(A_{r+1}) is on the boundary
 *      of hull(A_r), so in W_r (I1) and a hull vertex of DT(W_r) (the
 *      triangulator keeps points on hull sides as hull vertices): kept.
 *   I2: C_{r+1}'s border consists of barrier edges, edges of T(A_{r+1})
 *      (b), and the triangles of E_r are triangles of T(U), hence of
 *      T(A_{r+1}) (b): Z_{r+1} is a union of triangles of T(A_{r+1}).  A
 *      vertex v in A_r of such a triangle d is kept: on the boundary of
 *      hull(A_r) by I1; otherwise, next to v, d lies inside hull(A_r) and
 *      avoids C_r and E_r, so it overlaps a triangle of Z*_r at v (I2) that
 *      is not emitted: pending.  So d's vertices are in W_{r+1} and d is in
 *      DT(W_{r+1}) (b).
 *   I3: a wall is a barrier edge or an edge of a triangle of E_r, an edge of
 *      T(U) with both ends in W_{r+1}, hence an edge of DT(W_{r+1}) (b).  A
 *      handed-on wall had on its right a pending triangle (avoiding C_r and
 *      E_r) or the outside of hull(A_r) (which holds neither); now its right
 *      side is Z_{r+1}, the outside of hull(A_{r+1}), or a certified
 *      triangle of row r + 1.  That cannot happen to a barrier edge (c);
 *      for an edge of t in E_r it makes the reverse a barrier edge of row
 *      r + 1 (the certified triangle's tile neighbour across it is not
 *      certified, or it would be t).  A barrier edge of row r + 1 has on its
 *      right the outside of hull(P), a triangle of E_r (whose edge there is
 *      a wall by L, the certified triangle avoiding C_r u E_r), or a
 *      triangle of R not in E_r: Z_{r+1} or the outside of hull(A_{r+1}).
 *   I4: an edge of DT(W_{r+1}) between Z_{r+1} and C_{r+1} is a barrier edge
 *      (c; two edges of T(A_{r+1}) on one segment coincide); one between
 *      Z_{r+1} and a triangle of E_r is that triangle's edge.  Its right
 *      side lies in Z_{r+1}, avoiding C_r u E_r: it is a wall (a barrier
 *      edge of row r + 1, or by L).
 * Self-checks: a wall that is not an edge of DT(W_r) contradicts (a, b) and
 * I3; a covered triangle on the right of a wall whose reverse is not a wall
 * contradicts I3.  Both are reported as internal errors (7811) instead of
 * writing a wrong mesh.
 *
 * Deferred rows.  Nothing above needs a row to be the tiles of one j:
 * only that rows are runs of consecutive tiles in tile order (so Q_{r+1}
 * holds every later point, and a tile neighbour of a certified triangle
 * across a barrier edge of the row is a tile of that row or a later one),
 * and the argument for I3 uses only that.  So a round may join its row to
 * the next round's, which then triangulates W'_{r-1} u S_r u S_{r+1} with
 * the walls of both rows: that is the proof run on rows r and r + 1 taken
 * as one.  The merger defers a row (not the last) that brings fewer than
 * half as many vertices as the previous triangulated round kept; such a
 * round triangulates nothing and emits nothing, and its y_next is not
 * used (the floor of later vertices stays the one of the last
 * triangulated round, which is lower).  Each triangulated band but the
 * last then holds at most three times the vertices that joined it since
 * the previous one, so all triangulations together take at most 4 |U|
 * vertices, even when the band keeps nearly all it holds (a strip
 * a few lattice steps wide, every point of which is a hull point); rows
 * that bring at least half the carried band are merged one by one as
 * before.
 *
 * Memory: a round holds W_r, DT(W_r) and the walls (about 200 bytes per
 * band vertex).  W'_r is the pending triangles' vertices (those whose disk
 * reaches into Q_{r+1}: about the northern seam of one row, more where
 * empty space lets disks grow) plus the hull of A_r, never all seams.  Flat
 * slivers along the cloud's west and east sides have disks reaching far
 * north, but outside [X0, X1]: only a thin lens of such a disk lies in the
 * cloud's x range, and it ends near the sliver.  Testing the disk against
 * Q_{r+1} rather than against the half-plane y >= Y_{r+1} emits them: they
 * do not make the band grow with the number of rows.  The hull of A_r stays whole (I1): where the cloud's west
 * or east side is a straight lattice line holding many points (gridded
 * data), every one of them stays in the band.  The emitted faces of a round
 * are handed to the caller and dropped.
 */
#ifndef GDT_SEAM_H
#define GDT_SEAM_H

#include <stddef.h>
#include <stdint.h>

#include "gdt_error.h"
#include "gdt_mesh.h"
#include "gdt_reference.h"

#ifdef __cplusplus
extern "C" {
#endif

/* A seam vertex: its output vertex index, its coordinates in the merge
 * frame (lattice minus the cloud's lattice minimum, so in [0, 2^31 - 1])
 * and its z (carried for the outputs that interpolate the merge's faces;
 * the merge itself never reads it). */
typedef struct gdt_seam_vertex {
    uint64_t id;
    int64_t x, y;
    double z;
} gdt_seam_vertex;

/* A barrier edge a -> b (output vertex indices), certified side on the left. */
typedef struct gdt_seam_edge {
    uint64_t a, b;
} gdt_seam_edge;

/* A growable list of both, reused across tiles. */
typedef struct gdt_seam {
    gdt_seam_vertex *v;
    size_t nv, cap_v;
    gdt_seam_edge *e;
    size_t ne, cap_e;
} gdt_seam;

/* Frees the arrays and zeroes s; s may be NULL. */
void gdt_seam_free(gdt_seam *s);

/* Appends the seam of one tile to s: m is T_{d1,d2} of the tile's points in
 * tile-local coordinates, vertex i has output index id_base + i, merge
 * frame coordinates pts[i] + (dx, dy) and z[i] (0 when z is NULL); cert
 * holds m->ntris certification flags.  Vertices are appended in increasing
 * index, edges sorted.
 * Errors: GDT_EINPUT 3811 (a merge-frame coordinate outside
 * [0, 2^31 - 1]), 7001 out of memory. */
gdt_status gdt_seam_extract(gdt_seam *s, const gdt_mesh *m, const uint8_t *cert,
                            const double *z, uint64_t id_base, int64_t dx, int64_t dy,
                            gdt_error *err);

/* Counters of a merge; the sums run over all rounds. */
typedef struct gdt_merge_stats {
    uint64_t seam_vertices, barrier_edges; /* of all rows: |U| and all barrier edges */
    uint64_t seam_triangles;    /* triangles of DT(W_r), summed over the rounds */
    uint64_t covered;           /* of those, covered, summed over the rounds */
    uint64_t faces;             /* emitted */
    uint64_t hull_vertices;     /* vertices on the hull of the last round's band
                                   (= the hull of U = the hull of P) */
    uint64_t rounds;            /* rounds run (one per row) */
    uint64_t deferred;          /* of those, rounds whose row joined the next
                                   round's band untriangulated */
    uint64_t max_band_vertices; /* largest |W_r| */
    uint64_t max_walls;         /* largest number of walls of a round */
    uint64_t peak_bytes;        /* largest memory held by the merger's own arrays at
                                   the end of a round (the triangulator's scratch
                                   during DT(W_r) is not counted) */
    double t_triangulate, t_classify;
    gdt_reference_stats ref;
} gdt_merge_stats;

/* The merger: the band and the walls between rounds.  Not thread-safe per
 * instance. */
typedef struct gdt_merger gdt_merger;

/* x0, x1: the cloud's x range in the merge frame, [X0, X1] of the proof:
 * every seam vertex of every round has x0 <= x <= x1, with
 * 0 <= x0 <= x1 <= 2^31 - 1.  A wider range is safe (only fewer triangles
 * become final before the last round); a narrower one is refused by
 * gdt_merger_round.
 * Ownership: *out is new; free with gdt_merger_destroy.  Errors:
 * GDT_EINTERNAL 7814 (x0, x1 out of order or out of range), 7001. */
gdt_status gdt_merger_create(gdt_merger **out, int64_t x0, int64_t x1, gdt_error *err);
void gdt_merger_destroy(gdt_merger *m);

/* One round: row holds the seam of the tiles of the next row in tile order
 * (vertices by strictly increasing id, every id above those of earlier
 * rounds; the barrier edges name vertices of this row).  y_next: every seam
 * vertex of every later row has merge-frame y >= y_next (ignored when last
 * is nonzero: no later row); a y_next outside [0, 2^31 - 1] keeps every
 * uncovered triangle pending.  row is only read during the call.
 * On success *faces (owned by m, valid until the next call on m) holds
 * 3 * *nfaces output indices: the faces final in this round,
 * counter-clockwise, each rotated to start at its smallest index, sorted.
 * Over all rounds the faces are those of gdt_merge_seams on the union of
 * the rows, each once.
 * Errors: GDT_EINTERNAL 7810 (ids not increasing), 7811 (a wall missing from
 * DT(W_r), or covered on its uncovered side: a certification fault), 7812
 * (an edge names no vertex of the band), 7813 (a round after the last), 7814
 * (a vertex with x outside [x0, x1], or with y below an earlier round's
 * y_next: the finality test of earlier rounds assumed otherwise), the
 * reference triangulator's 734x, 7001.  After an error m can only be
 * destroyed. */
gdt_status gdt_merger_round(gdt_merger *m, const gdt_seam *row, int64_t y_next, int last,
                            const uint64_t **faces, size_t *nfaces, gdt_error *err);

/* After a successful gdt_merger_round: the merge-frame coordinates of the
 * vertices of its *faces, 3 per face in the same order, and their z (each
 * owned by m, valid until the next call on m). */
const gdt_ipt *gdt_merger_face_points(const gdt_merger *m);
const double *gdt_merger_face_z(const gdt_merger *m);

/* The counters so far (owned by m). */
const gdt_merge_stats *gdt_merger_stats(const gdt_merger *m);


/* The whole merge in one round (all seams at once, memory growing with
 * them): s->v sorted by strictly increasing id.  On success *faces
 * (malloc'ed, caller frees) holds 3 * *nfaces output indices: the triangles
 * of T in R, counter-clockwise, each rotated to start at its smallest index,
 * sorted.  Errors: as gdt_merger_round. */
gdt_status gdt_merge_seams(const gdt_seam *s, uint64_t **faces, size_t *nfaces,
                           gdt_merge_stats *ms, gdt_error *err);

#ifdef __cplusplus
}
#endif
#endif
