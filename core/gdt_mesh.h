/* gdt_mesh.h — the triangle mesh of gdt-tile and its exact verifiers.
 *
 * Storage (Shewchuk / gDel2D style): flat arrays, no per-triangle
 * allocation.  Triangle t has the vertices tri[3t], tri[3t+1], tri[3t+2]
 * ("slots" 0, 1, 2) and the packed opposite pointers opp[3t+0..2].
 *
 * Invariants of a valid mesh (what gdt_check_mesh verifies):
 *   - every vertex index is in [0, nverts); the three are distinct;
 *   - every triangle is strictly counter-clockwise (orient2d > 0);
 *   - neighbour i is across the edge OPPOSITE vertex i: the edge of slot i
 *     runs from tri[3t + (i+1)%3] to tri[3t + (i+2)%3];
 *   - opp[3t+i] = (u << 2) | j when triangle u shares that edge and the edge
 *     is opposite u's slot j; then opp[3u+j] = (t << 2) | i and u traverses
 *     the edge in the other direction.  opp = GDT_MESH_NONE (-1) on the hull;
 *   - every edge belongs to one (hull) or two (interior) triangles;
 *   - the hull edges form one closed convex counter-clockwise chain: the
 *     boundary of the triangulated region is the convex hull of the points,
 *     and points lying on a hull side are hull vertices (h counts them);
 *   - every vertex is used, the points are distinct, and with V >= 3 points
 *     not all collinear F = 2V - h - 2.  Fewer than 3 points, or all points
 *     collinear: F = 0 (no triangle has positive area).
 *
 * Limits: V <= GDT_MESH_MAX_VERTS, so that F <= 2V - 5 fits the packed
 * pointers (triangle index < 2^29).
 *
 * Coordinates are tile-local lattice integers in [0, GDT_COORD_MAX]
 * (gdt_predicates.h); all geometry goes through the predicates module.
 *
 * Not thread-safe per instance; distinct meshes are independent.
 */
#ifndef GDT_MESH_H
#define GDT_MESH_H

#include <stddef.h>
#include <stdint.h>

#include "gdt_error.h"
#include "gdt_predicates.h"

#ifdef __cplusplus
extern "C" {
#endif

#define GDT_MESH_NONE (-1)
/* Largest vertex count (2^28): 2V triangles stay below 2^29. */
#define GDT_MESH_MAX_VERTS ((size_t)1 << 28)
/* Largest triangle count: triangle indices must fit 29 bits. */
#define GDT_MESH_MAX_TRIS ((size_t)1 << 29)

static inline int32_t gdt_opp_pack(int32_t t, int slot)
{
    return (int32_t)(((uint32_t)t << 2) | (uint32_t)slot);
}
static inline int32_t gdt_opp_tri(int32_t o)
{
    return o >> 2;
}
static inline int gdt_opp_slot(int32_t o)
{
    return (int)(o & 3);
}

typedef struct gdt_mesh {
    size_t nverts;    /* vertices in use: pts[0 .. nverts) */
    size_t ntris;     /* triangles in use */
    size_t cap_verts; /* allocated entries of pts (and ids) */
    size_t cap_tris;  /* allocated triangles of tri and opp */
    gdt_ipt *pts;     /* vertex coordinates; owned by the mesh */
    int64_t *ids;     /* optional caller-defined vertex ids (e.g. global
                       * point index), owned by the mesh; NULL means vertex i
                       * is point i of whatever array the mesh was built from */
    int32_t *tri;     /* 3 * cap_tris vertex indices, owned */
    int32_t *opp;     /* 3 * cap_tris packed opposite pointers, owned */
} gdt_mesh;

/* Empty mesh, no allocation.  Every mesh must be initialised before use. */
void gdt_mesh_init(gdt_mesh *m);

/* Frees every array of m and leaves it empty (as gdt_mesh_init).  m may be
 * NULL. */
void gdt_mesh_free(gdt_mesh *m);

/* Grows the capacity to at least nverts vertices and ntris triangles (ids
 * too when with_ids, or when m->ids already exists), keeping the content.
 * Never shrinks.  Errors: 7301 (over the limits), 7001 (out of memory; m
 * then keeps its content and stays valid, possibly with a larger capacity). */
gdt_status gdt_mesh_reserve(gdt_mesh *m, size_t nverts, size_t ntris, int with_ids, gdt_error *err);

/* Makes m the point set pts[0..n) with no triangles (ids, if present, are
 * set to 0..n-1).  Copies the points; the caller keeps ownership of pts. */
gdt_status gdt_mesh_set_points(gdt_mesh *m, const gdt_ipt *pts, size_t n, gdt_error *err);

/* Computes every opp pointer from the triangles alone (combinatorics, no
 * geometry), in O(V + F) time plus the sort of each vertex's edge list.
 * Errors (GDT_EINTERNAL): 7302 index out of range or repeated in a triangle,
 * 7303 an edge in more than two triangles, or traversed twice in the same
 * direction (non-manifold or inconsistently oriented); 7001 out of memory.
 * On error, opp is left unspecified. */
gdt_status gdt_mesh_link(gdt_mesh *m, gdt_error *err);

/* Canonical form for comparisons: every triangle rotated so that its
 * smallest vertex key comes first (orientation kept), then the triangles
 * sorted lexicographically.  The key of vertex v is ids[v] when ids exists,
 * else v.  out must hold 3 * ntris values (caller-owned). */
void gdt_mesh_canonical(const gdt_mesh *m, int64_t *out);

/* ---- Verifiers (exact; GDT_OK or GDT_EINTERNAL with the first fault) ----
 *
 * Messages name the triangle, slot, edge and vertices at fault.  st receives
 * the predicate counters and may be NULL. */

/* Verifies every invariant listed at the top of this file: limits (7310),
 * coordinate range (7311), distinct points (7312), indices (7313), strict
 * counter-clockwise orientation (7314), opposite pointers (7315), edges in
 * one or two triangles and shared edges linked (7316), every vertex used
 * (7317), hull edges form one closed chain (7318) that is convex and winds
 * once (7319), every point inside or on the hull (7320), Euler's relation
 * (7321), connectivity (7322), no triangle only for < 3 or collinear
 * points (7323).  7001: out of memory.  O((V + F) log V) time, O(V + F)
 * temporary memory. */
gdt_status gdt_check_mesh(gdt_pred_stats *st, const gdt_mesh *m, gdt_error *err);

/* Verifies that every interior edge is locally optimal under the Lawson
 * test with the preferred-direction tie-break, seen from both sides
 * (gdt_edge_needs_flip is 0 both ways), i.e. the mesh is T_{d1,d2}
 * (Dyken & Floater, Thm 4.1) once gdt_check_mesh also passes.
 * Fault: 7330 (edge that must flip).  Precondition: gdt_check_mesh passed;
 * out-of-range pointers are still reported (7315) rather than followed. */
gdt_status gdt_check_delaunay(gdt_pred_stats *st, const gdt_mesh *m, gdt_error *err);

#ifdef __cplusplus
}
#endif
#endif
