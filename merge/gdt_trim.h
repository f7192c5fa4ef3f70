/* gdt_trim.h — trimming the TIN: --max-edge and --concavity.
 *
 * Edge length is horizontal, in CRS units: the edge of lattice vector
 * (dx, dy) is longer than L when (dx sx)^2 + (dy sy)^2 > L^2, evaluated in
 * double in exactly this order (gdt_trim_longer; dx and dy are exact as
 * doubles below 2^53).  It depends on the two end points alone.
 *
 * The rules, applied to the whole triangulation T:
 *   --max-edge L: a face is dropped when one of its edges is longer than L.
 *   --concavity L: a face is dropped when it can be reached from outside
 *     the convex hull by crossing edges longer than L only.  This is the
 *     peel "drop triangles from the outside in, across boundary edges longer
 *     than L, until no boundary edge is longer": the peel drops f across e
 *     only when the far side of e is outside or already dropped, which makes
 *     a path; and along a path each face becomes peelable once the one
 *     before it is gone.  So the result does not depend on the peel's order.
 * The two rules are independent (the concavity peel starts from the convex
 * hull, not from holes that --max-edge cuts); a face is kept when neither
 * drops it.  Both depend on T alone, so not on the tiling; vertices are
 * never dropped.
 *
 * The tiled run computes --concavity out of core:
 *   - per tile (gdt_trim_tile_run, on its certified faces): faces that share
 *     an edge longer than L are joined into components (union-find).  A long
 *     edge of a certified face that no other certified face of the tile has
 *     is an *open* edge: its far side is a merge face or outside the hull
 *     (a certified face has all its vertices in its tile, so certified faces
 *     of two tiles never share an edge).  Only the components with an open
 *     edge can be reached from outside: their faces are the tile's
 *     *candidates*, listed with the component's label (its smallest face
 *     index); their open edges are listed with the label too.
 *   - the merge faces' long edges and the tiles' open edges meet in one
 *     graph (gdt_trim_graph): an edge (by its two output indices) seen twice
 *     joins its two sides, an edge seen once is a hull edge, and the side
 *     that has it is reached from outside.
 * The graph holds the tiles' open edges and the merge faces' long edges
 * (about 64 bytes each with its hash slot), never the faces: the seams, not
 * the cloud.  A whole mesh in memory is one tile with no merge faces: every
 * open edge is then a hull edge (gdt_trim_mesh).
 */
#ifndef GDT_TRIM_H
#define GDT_TRIM_H

#include <stddef.h>
#include <stdint.h>

#include "gdt_error.h"
#include "gdt_predicates.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct gdt_trim_rule {
    double max_edge;  /* > 0: --max-edge L; 0: off */
    double concavity; /* > 0: --concavity L; 0: off */
    double sx, sy;    /* the lattice steps (finite, > 0) */
} gdt_trim_rule;

/* 1 when either rule is on. */
static inline int gdt_trim_on(const gdt_trim_rule *r)
{
    return r != NULL && (r->max_edge > 0 || r->concavity > 0);
}

/* 1 when the edge of lattice vector (dx, dy) is longer than L (see above). */
static inline int gdt_trim_longer(const gdt_trim_rule *r, double L, int64_t dx, int64_t dy)
{
    double x = (double)dx * r->sx, y = (double)dy * r->sy;
    return x * x + y * y > L * L;
}

/* 1 when --max-edge drops the face of lattice points a, b, c. */
int gdt_trim_cut(const gdt_trim_rule *r, gdt_ipt a, gdt_ipt b, gdt_ipt c);

/* An open edge of a tile: output indices a < b, and the label of the
 * component of the certified face that has it. */
typedef struct gdt_trim_open {
    uint64_t a, b;
    uint32_t label;
} gdt_trim_open;

/* What a tile's certified faces carry for trimming.  Reused across tiles;
 * zero it before the first use. */
typedef struct gdt_trim_tile {
    uint32_t *cut;        /* faces --max-edge drops, increasing */
    size_t ncut, cap_cut;
    uint32_t *cand;       /* candidates: 2 per face (face, label), by increasing face */
    size_t ncand, cap_cand;
    gdt_trim_open *open;  /* open edges, by (a, b) */
    size_t nopen, cap_open;
    /* scratch */
    uint32_t *parent;
    size_t cap_parent;
    uint64_t *rec;        /* long-edge records */
    size_t cap_rec;
} gdt_trim_tile;

void gdt_trim_tile_free(gdt_trim_tile *t);

/* Fills t for nf faces (3 nf vertex indices into pts, counter-clockwise;
 * face f of the list is face number f of the tile) whose vertex i has
 * output index base + i.  Faces are numbered below 2^32 and vertices below
 * 2^32.  Output of the rule that is off stays empty.
 * returns: GDT_OK; GDT_EINTERNAL 7001 (out of memory), 7891 (more than
 * 2^32 - 1 faces). */
gdt_status gdt_trim_tile_run(gdt_trim_tile *t, const gdt_trim_rule *r, const uint32_t *faces,
                             size_t nf, const gdt_ipt *pts, uint64_t base, gdt_error *err);

/* The graph of the whole run's long edges (see above). */
typedef struct gdt_trim_graph gdt_trim_graph;

/* Ownership: *out is new; free with gdt_trim_graph_destroy.
 * returns: GDT_OK; GDT_EINTERNAL 7001. */
gdt_status gdt_trim_graph_create(gdt_trim_graph **out, const gdt_trim_rule *r, gdt_error *err);
void gdt_trim_graph_destroy(gdt_trim_graph *g);

/* Adds tile `tile`'s n open edges.  Tiles are added in increasing order,
 * each once, before gdt_trim_graph_resolve.
 * returns: GDT_OK; GDT_EINTERNAL 7001, 7892 (tiles out of order, an edge
 * met a third time: the inputs are no triangulation). */
gdt_status gdt_trim_graph_add_tile(gdt_trim_graph *g, uint64_t tile, const gdt_trim_open *e,
                                   size_t n, gdt_error *err);

/* Adds n merge faces: 3 n output indices and their 3 n vertices' lattice
 * coordinates in any common frame; they are numbered on from the faces
 * added before (the first is number 0).  Records --max-edge's verdict of
 * each and their long edges.
 * returns: GDT_OK; GDT_EINTERNAL 7001, 7892. */
gdt_status gdt_trim_graph_add_faces(gdt_trim_graph *g, const uint64_t *faces,
                                    const gdt_ipt *xy, size_t n, gdt_error *err);

/* Finds what is reached from outside.  After it only the queries below.
 * returns: GDT_OK; GDT_EINTERNAL 7001. */
gdt_status gdt_trim_graph_resolve(gdt_trim_graph *g, gdt_error *err);

/* 1 when --concavity drops the candidates of label `label` of tile `tile`. */
int gdt_trim_graph_tile_dropped(const gdt_trim_graph *g, uint64_t tile, uint32_t label);

/* 1 when merge face i (numbered as added) is dropped by either rule. */
int gdt_trim_graph_face_dropped(const gdt_trim_graph *g, uint64_t i);

/* Merge faces added, and of those dropped by --max-edge, by --concavity
 * and by either. */
typedef struct gdt_trim_counts {
    uint64_t faces, cut, peeled, dropped;
} gdt_trim_counts;
gdt_trim_counts gdt_trim_graph_merge_counts(const gdt_trim_graph *g);

/* A whole mesh in memory: keep[f] = 0 for every face either rule drops,
 * 1 otherwise (faces as for gdt_trim_tile_run, base 0).  *counts gets the
 * faces and the drops by rule (may be NULL).
 * returns: GDT_OK; GDT_EINTERNAL 7001, 7891, 7892. */
gdt_status gdt_trim_mesh(const gdt_trim_rule *r, const uint32_t *faces, size_t nf,
                         const gdt_ipt *pts, uint8_t *keep, gdt_trim_counts *counts,
                         gdt_error *err);

#ifdef __cplusplus
}
#endif
#endif
