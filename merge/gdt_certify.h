/* gdt_certify.h — which triangles of a tile are final.
 *
 * A tile knows completely the points inside the closed box K (its own box
 * grown by the halo width): every cloud point of K is one of its own points
 * or one of its halo points.  A triangle t of DT(own points) is certified
 * when
 *   1. its closed circumdisk lies inside K, except on the sides of K beyond
 *      which the cloud has no point at all (the cloud's bounding box ends
 *      there), and
 *   2. no halo point lies inside or on its circumcircle.
 * Then no cloud point lies in the closed disk except t's co-circular own
 * points, which the tile's triangulation already ordered with the tie-break,
 * so t is a triangle of T_{d1,d2} of the whole cloud.  The disk test uses the
 * conservative outer box of gdt_circumdisk_bounds and the halo test the
 * exact in-circle: a triangle may be refused needlessly (it then goes to the
 * merge), never accepted wrongly.
 *
 * Triangles whose disk lies inside the open band around the tile's own box
 * ((x0 - 1, x1 + 1) x (y0 - 1, y1 + 1), lattice points being integers) cannot
 * hold a halo point: they skip the halo search.
 */
#ifndef GDT_CERTIFY_H
#define GDT_CERTIFY_H

#include <stddef.h>
#include <stdint.h>

#include "gdt_error.h"
#include "gdt_mesh.h"
#include "gdt_predicates.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Sides, in the order of the box arrays below. */
enum { GDT_SIDE_WEST = 0, GDT_SIDE_SOUTH = 1, GDT_SIDE_EAST = 2, GDT_SIDE_NORTH = 3 };

/* The region of one tile, in its tile-local lattice coordinates.  Boxes are
 * closed: {xmin, ymin, xmax, ymax}. */
typedef struct gdt_cert_region {
    int64_t own[4];   /* the tile's own box (every own point inside, no halo point) */
    int64_t known[4]; /* K: every cloud point inside is an own or a halo point */
    int open[4];      /* side k of K is open: no cloud point lies beyond known[k] */
} gdt_cert_region;

typedef struct gdt_cert_stats {
    uint64_t triangles;     /* triangles examined */
    uint64_t certified;     /* of those, certified */
    uint64_t inner;         /* certified without a halo search */
    uint64_t outside_known; /* refused: the disk may leave K */
    uint64_t halo_hit;      /* refused: a halo point on or in the circle */
    uint64_t halo_tests;    /* in-circle tests against halo points */
    gdt_pred_stats pred;
} gdt_cert_stats;

/* Reusable state (the halo's bucket grid).  Not thread-safe per instance. */
typedef struct gdt_certifier gdt_certifier;

/* threads: how many threads gdt_certify_tile may use (clamped to 1..64; a
 * tile gets one per 4096 triangles at most).  The flags do not depend on
 * it.  Ownership: *out is new; free with gdt_certifier_destroy.
 * Errors: 7001. */
gdt_status gdt_certifier_create(gdt_certifier **out, int threads, gdt_error *err);
void gdt_certifier_destroy(gdt_certifier *c);

/* Certifies the triangles of m (T_{d1,d2} of the tile's own points, in
 * tile-local coordinates) against the halo points halo[0..nhalo) (tile-local,
 * inside r->known, outside r->own).  cert receives m->ntris flags: 1 =
 * certified.  Counters in cs are accumulated (cs may be NULL).
 * Errors: GDT_EINTERNAL 7801 (a halo point outside K or inside the own box:
 * the caller's region is wrong), 7001 out of memory. */
gdt_status gdt_certify_tile(gdt_certifier *c, const gdt_mesh *m, const gdt_ipt *halo,
                            size_t nhalo, const gdt_cert_region *r, uint8_t *cert,
                            gdt_cert_stats *cs, gdt_error *err);

#ifdef __cplusplus
}
#endif
#endif
