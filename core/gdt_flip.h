/* gdt_flip.h — the Lawson flip engine with the preferred-direction
 * tie-break.
 *
 * Turns any valid triangulation of a point set (gdt_check_mesh passes) into
 * the unique Delaunay triangulation T_{d1,d2} of Dyken & Floater: edges are
 * tested with gdt_edge_needs_flip and flipped until none needs it.  By
 * Thm 4.1 of the paper the result does not depend on the starting
 * triangulation nor on the order of the flips.
 *
 * Frozen triangles: an optional mask marks triangles that must survive
 * unchanged (the merge stage freezes certified triangles).  An edge with a
 * frozen triangle on either side is never tested nor flipped, so frozen
 * triangles keep their index, vertices and slot order; only their opposite
 * pointers are updated when a neighbour is rebuilt.  Every other interior
 * edge is locally optimal on return.
 */
#ifndef GDT_FLIP_H
#define GDT_FLIP_H

#include <stddef.h>
#include <stdint.h>

#include "gdt_error.h"
#include "gdt_mesh.h"
#include "gdt_predicates.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct gdt_flip_stats {
    uint64_t edges_tested; /* Lawson tests evaluated */
    uint64_t flips;        /* edges flipped */
} gdt_flip_stats;

/* Flips m in place to local optimality (see above).
 *   st:     predicate counters, may be NULL (accumulated).
 *   fs:     flip counters, may be NULL (accumulated, not reset).
 *   frozen: NULL, or m->ntris flags; nonzero = frozen triangle.
 * Precondition (not checked, O(n log n) to verify): m is a valid mesh in
 * the sense of gdt_check_mesh.  Triangles are rewritten in place (no
 * triangle is added or removed); m->pts and m->ids are untouched.
 * Temporary memory: 13 bytes per triangle, freed before return.
 * Errors: 7350 (mesh over the limits), 7001 (out of memory; m unchanged). */
gdt_status gdt_flip_to_delaunay(gdt_pred_stats *st, gdt_flip_stats *fs, gdt_mesh *m,
                                const uint8_t *frozen, gdt_error *err);

#ifdef __cplusplus
}
#endif
#endif
