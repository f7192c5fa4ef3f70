/* gdt_reference.h — the plain CPU reference triangulator.
 *
 * Computes T_{d1,d2}, the unique Delaunay triangulation with the
 * preferred-direction tie-break (gdt_predicates.h), of a set of distinct
 * tile-local lattice points.  Simple, exact and deterministic; it exists to
 * check the production paths (OpenCL core, tiling, merge), which must give
 * exactly the same triangle set.
 *
 * design: randomized incremental insertion in BRIO order (fixed-seed
 * shuffle into rounds of doubling size, each round sorted along a Hilbert
 * curve), point location by a remembering stochastic walk from the last
 * inserted point, Lawson flips with the tie-break after each insertion.  The
 * outside of the hull is covered by "ghost" triangles sharing one symbolic
 * vertex at infinity, so no coordinate ever leaves [0, 2^31-1] and points on
 * a hull side stay hull vertices.  Ghosts are removed at the end and one
 * pass of the flip engine (gdt_flip.h) over all edges makes the result
 * locally optimal with the tie-break everywhere, hence T_{d1,d2} (Thm 4.1).
 * Expected O(n log n) time; peak memory about 100 bytes per point.
 */
#ifndef GDT_REFERENCE_H
#define GDT_REFERENCE_H

#include <stddef.h>
#include <stdint.h>

#include "gdt_error.h"
#include "gdt_flip.h"
#include "gdt_mesh.h"
#include "gdt_predicates.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct gdt_reference_stats {
    gdt_pred_stats pred;   /* predicate counters */
    uint64_t walk_steps;   /* triangles visited by point location */
    uint64_t insert_flips; /* flips while inserting points */
    gdt_flip_stats final;  /* the closing pass of the flip engine */
} gdt_reference_stats;

/* Triangulates pts[0..n).  Counters in st are accumulated; st may be NULL.
 *
 * On success out holds vertex i = pts[i] (out->ids, if already allocated,
 * is set to 0..n-1) and the triangles of T_{d1,d2} with their opposite
 * pointers; fewer than 3 points or all points collinear give 0 triangles.
 * out must have been initialised (gdt_mesh_init); its previous content is
 * replaced and its capacity reused.  The caller keeps ownership of pts and
 * frees out with gdt_mesh_free.
 *
 * Preconditions, checked: n <= GDT_MESH_MAX_VERTS and every coordinate in
 * [0, GDT_COORD_MAX] (7340); the points are distinct (7341: duplicates must
 * be removed by the caller, the message names two equal input indices).
 * 7342: internal inconsistency (a bug).  7001: out of memory.  On error,
 * out is valid but its content unspecified.
 * Reentrant: no global state; the shuffle uses a fixed seed. */
gdt_status gdt_reference_triangulate(gdt_reference_stats *st, const gdt_ipt *pts, size_t n,
                                     gdt_mesh *out, gdt_error *err);

#ifdef __cplusplus
}
#endif
#endif
