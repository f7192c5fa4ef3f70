/* gdt_plycheck.h — exact, streaming, bounded-memory checker of an output PLY.
 *
 * gdt_ply_check reads a mesh file in the layout of io/gdt_ply.h and proves,
 * in exact integer arithmetic on the lattice integers, that it is the unique
 * Delaunay triangulation T_{d1,d2} of its vertices (the invariants of
 * gdt_check_mesh and gdt_check_delaunay in gdt_mesh.h, for a mesh that does
 * not fit in memory).  Checks, in this order (the first violation stops the
 * check and is reported):
 *   lattice     every x = ox + sx * i, y = oy + sy * j ("comment lattice sx
 *               sy ox oy"): i = rint((x - ox) / sx) within 1e-6 lattice
 *               units, or x equal to the double ox + sx * i; |i| < 2^53
 *   extent      max i - min i and max j - min j at most 2^31 - 1 (the
 *               predicates' tile-local range; the origin is (min i, min j))
 *   points      no two vertices on the same lattice point
 *   faces       count byte 3; indices in [0, V) and distinct; strictly
 *               counter-clockwise (orient2d > 0)
 *   vertices    every vertex is in a face (when F > 0)
 *   edges       every undirected edge in one face (boundary) or two faces
 *               that traverse it in opposite directions
 *   Delaunay    every interior edge is locally optimal under the Lawson test
 *               with the Dyken-Floater tie-break seen from both sides
 *               (gdt_edge_needs_flip is 0 both ways)
 *   boundary    every boundary vertex starts exactly one and ends exactly one
 *               boundary edge; every turn is left or straight on (never
 *               back); the edge directions wind once in total
 *   Euler       F = 2V - h - 2, h = boundary (hull) vertices
 *   F = 0       legal only for V < 3 or all vertices collinear
 * design: the boundary is checked locally, vertex by vertex, so it never has
 * to be held as one chain.  Each closed cycle of boundary edges that turns
 * only left or straight on has turning number >= 1; a total of exactly one
 * turn therefore means exactly one cycle, and that cycle is a convex polygon
 * P.  With all faces counter-clockwise and every interior edge shared by two
 * faces in opposite directions, the number of faces covering a point is the
 * winding number of the boundary around it: 1 inside P, 0 outside.  So the
 * faces tile P; with distinct points all used, no vertex lies inside a face
 * or on an edge it does not belong to, and P is the convex hull.  Local
 * optimality with the tie-break on every interior edge then makes the mesh
 * T_{d1,d2} (Lawson; Dyken & Floater Thm 4.1).  Euler's relation follows
 * from the above and is still verified as a stated property.
 *
 * Memory: the vertex section is memory-mapped (read-only, file-backed pages
 * that the kernel can drop) and read by index; the face section is read in
 * chunks.  Everything else lives in opts->mem_budget bytes of heap whatever
 * the mesh size: the half-edge records (16 bytes each, 3F of them), the
 * point records (16 bytes per vertex) and the boundary records are
 * distributed over temporary files by key range and each range is sorted in
 * memory (a range too large for the budget is split again); the vertex-use
 * bitmap is checked in windows of the budget.  Temporary files are created
 * in opts->temp_dir and unlinked at once, so none is left behind whatever
 * happens, not even after a crash.  Temporary disk: about 48 F + 16 V bytes.
 *
 * Header accepted: "ply", "format binary_little_endian 1.0", comments
 * (exactly one "comment lattice sx sy ox oy": four finite numbers, sx, sy >
 * 0, parsed with strtod, so the process must run in the "C" numeric locale,
 * as gdt-tile does), obj_info lines, "element vertex V" with exactly the
 * properties double x, double y, double z, then optionally "element face F"
 * with exactly "property list uchar int vertex_indices" (uint8 / int32 and
 * vertex_index are accepted as synonyms), "end_header".  Counts may be
 * space-padded.  The file size must be header + 24 V + 13 F bytes.  A face
 * record is always 13 bytes: a count byte other than 3 is a violation.
 *
 * Message numbers.
 *   Violations (GDT_EINTERNAL; the message names the file and the face,
 *   edge or vertex at fault, with lattice coordinates):
 *     7360 vertex off the lattice (or lattice integer out of range)
 *     7361 two vertices on the same lattice point
 *     7362 no faces, but the vertices are not collinear
 *     7363 face count byte is not 3
 *     7364 face index outside [0, V)
 *     7365 face repeats a vertex
 *     7366 face not strictly counter-clockwise (clockwise or degenerate)
 *     7367 vertex in no face
 *     7368 edge in more than two faces
 *     7369 edge traversed twice in the same direction
 *     7370 interior edge not locally Delaunay (a vertex strictly inside the
 *          circumcircle of the other face)
 *     7371 co-circular convex quad whose diagonal loses the tie-break
 *     7372 boundary chain broken (a vertex starts or ends two boundary
 *          edges, or is entered but not left, or left but not entered)
 *     7373 boundary not convex (reflex or backward turn)
 *     7374 boundary edges do not wind exactly once (several loops)
 *     7375 Euler's relation fails
 *   Bad file (GDT_EINPUT): 3360 not a PLY file (no "ply" magic), 3361
 *     malformed or overlong header, 3362 layout other than the one above
 *     (format, elements, properties), 3363 lattice comment missing,
 *     repeated or malformed, 3364 file size differs from the header's
 *     (truncated or trailing bytes), 3365 counts too large (V > 2^31 - 1 or
 *     F > 2^32 - 1), 3366 lattice extent above 2^31 - 1 (cannot be checked
 *     with tile-local predicates).
 *   I/O (GDT_EIO): 4360 cannot open or stat the file, 4361 read or map
 *     failure, 4362 temporary file cannot be created, 4363 temporary file
 *     write failure (disk full), 4364 temporary file read failure.
 *   Other: 7001 out of memory; 7376 bad arguments (NULL path or result);
 *     7379 internal inconsistency of the spill files (a bug).
 *
 * Reentrant: no global state; separate calls are independent.  The mesh
 * file must not change during the call.
 */
#ifndef GDT_PLYCHECK_H
#define GDT_PLYCHECK_H

#include <stddef.h>
#include <stdint.h>

#include "gdt_cloud.h"
#include "gdt_error.h"
#include "gdt_predicates.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Default heap budget. */
#define GDT_PLYCHECK_DEFAULT_BUDGET ((size_t)256 << 20)
/* Smallest budget; smaller requests are raised to it.  Tiny budgets are
 * legal (tests use them to force every spill path), only slower. */
#define GDT_PLYCHECK_MIN_BUDGET ((size_t)64 << 10)

typedef struct gdt_plycheck_opts {
    size_t mem_budget;    /* heap bytes the check may hold at once; 0: default */
    const char *temp_dir; /* temporary files; NULL or "": the PLY's directory */
} gdt_plycheck_opts;

/* Defaults: mem_budget = GDT_PLYCHECK_DEFAULT_BUDGET, temp_dir = NULL. */
void gdt_plycheck_opts_init(gdt_plycheck_opts *opts);

typedef struct gdt_plycheck_result {
    uint64_t vertices;       /* V from the header */
    uint64_t faces;          /* F from the header */
    uint64_t hull_vertices;  /* h (0 when F = 0) */
    uint64_t interior_edges; /* edges given the Lawson test from both sides */
    uint64_t boundary_edges; /* edges in one face */
    gdt_lattice lattice;     /* from the "comment lattice" line */
    int64_t origin_x;        /* lattice integers of the tile-local origin */
    int64_t origin_y;        /*   (the smallest i and j) */
    int64_t extent_x;        /* largest i - origin_x */
    int64_t extent_y;        /* largest j - origin_y */
    int collinear;           /* F = 0 and 3 or more vertices, all collinear */
    gdt_pred_stats pred;     /* predicate counters */
    uint64_t spill_bytes;    /* bytes written to temporary files (0: all in memory) */
    uint64_t spill_files;    /* temporary files created */
    uint64_t spill_splits;   /* spilled buckets split again before sorting */
    size_t peak_heap;        /* most heap bytes held at once (the mapped file excluded) */
    size_t mem_budget;       /* the budget actually used */
} gdt_plycheck_result;

/* Checks the mesh file path as described at the top of this file.
 * opts may be NULL (defaults).  res (required) is zeroed, then filled with
 * the counts; on a violation it holds those reached so far.
 * returns: GDT_OK when the mesh is valid and T_{d1,d2}; GDT_EINTERNAL with
 *   a 736x/737x message for a violation; GDT_EINPUT 336x / GDT_EIO 436x for
 *   a file that cannot be read as a gdt-tile mesh or temporary files that
 *   cannot be written; 7001 out of memory.
 * Ownership: nothing is allocated for the caller; every temporary file and
 *   buffer is released before return, on every path. */
gdt_status gdt_ply_check(const gdt_plycheck_opts *opts, const char *path, gdt_plycheck_result *res,
                         gdt_error *err);

#ifdef __cplusplus
}
#endif
#endif
