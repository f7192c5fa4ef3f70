/* gdt_seam.h — the seam merge: everything the tiles could not certify.
 *
 * Notation: P is the cloud, C the certified triangles of all tiles (each in
 * T = T_{d1,d2}(P), see gdt_certify.h), R the part of the hull of P that C
 * does not cover.
 *
 * Per tile (gdt_seam_extract), the seam vertices U_T are the vertices of the
 * tile's uncertified triangles, the vertices of its hull edges, and every
 * point of a tile with no triangle (< 3 points, or all collinear).  The
 * barrier edges are the edges of certified triangles whose other side is an
 * uncertified triangle or the tile's hull, directed with the certified
 * triangle on their left.
 *
 * Why re-triangulating U = union of the U_T is enough (gdt_merge_seams):
 *   a. every triangle of T not in C has its three vertices in U: a vertex
 *      outside U is interior to its tile's hull with only certified
 *      triangles around it, and those form its whole star in T;
 *   b. a triangle of T with its vertices in U is a triangle of
 *      T_{d1,d2}(U): the tie-break is a consistent symbolic perturbation of
 *      the lifting, and a lower face of the lifted P stays one for any subset
 *      holding its vertices;
 *   c. so the triangles of T in R are exactly the triangles of DT(U) that do
 *      not overlap C.  The border between C and R consists of barrier edges
 *      (an edge of a certified triangle whose neighbour in T is not
 *      certified: that neighbour is also its tile neighbour, or has a vertex
 *      in another tile, or the edge is on the hull), each an edge of DT(U)
 *      by (a, b).  Flooding DT(U) from the left side of every barrier edge
 *      without crossing one marks exactly the triangles over C; the others
 *      are emitted.
 * A barrier edge that is not an edge of DT(U) contradicts (a, b): the merge
 * reports it as an internal error (7811) instead of writing a wrong mesh.
 *
 * Memory: the merge holds U and DT(U) (about 200 bytes per seam vertex).
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

/* A seam vertex: its output vertex index and its coordinates in the merge
 * frame (lattice minus the cloud's lattice minimum, so in [0, 2^31 - 1]). */
typedef struct gdt_seam_vertex {
    uint64_t id;
    int64_t x, y;
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
 * tile-local coordinates, vertex i has output index id_base + i and merge
 * frame coordinates pts[i] + (dx, dy); cert holds m->ntris certification
 * flags.  Vertices are appended in increasing index, edges sorted.
 * Errors: GDT_EINPUT 3811 (a merge-frame coordinate outside
 * [0, 2^31 - 1]), 7001 out of memory. */
gdt_status gdt_seam_extract(gdt_seam *s, const gdt_mesh *m, const uint8_t *cert,
                            uint64_t id_base, int64_t dx, int64_t dy, gdt_error *err);

typedef struct gdt_merge_stats {
    uint64_t seam_vertices, barrier_edges;
    uint64_t seam_triangles;   /* triangles of DT(U) */
    uint64_t covered;          /* of those, over certified triangles */
    uint64_t faces;            /* emitted */
    uint64_t hull_vertices;    /* vertices on the hull of U (= the hull of P) */
    double t_triangulate, t_classify;
    gdt_reference_stats ref;
} gdt_merge_stats;

/* The merge.  s->v must be sorted by strictly increasing id (tiles appended
 * in index order give that).  On success *faces (malloc'ed, caller frees)
 * holds 3 * *nfaces output indices: the triangles of T in R, counter-clockwise,
 * each rotated to start at its smallest index, sorted.
 * Errors: GDT_EINTERNAL 7810 (ids not increasing), 7811 (a barrier edge
 * missing from DT(U): a certification fault), 7812 (a barrier edge names
 * no seam vertex), the reference triangulator's 734x, 7001. */
gdt_status gdt_merge_seams(const gdt_seam *s, uint64_t **faces, size_t *nfaces,
                           gdt_merge_stats *ms, gdt_error *err);

#ifdef __cplusplus
}
#endif
#endif
