/* gcd_hull.h — the sequential step of Phase 2 (on the CPU, like the
 * boundary walk of the gCD paper): the triangles between the boundary of
 * the dual triangulation and the fake boundary at infinity.
 *
 * The boundary is the frame: Phase 1 makes every border texel of the grid a
 * site of its own (a frame vertex at the texel corner), so no region of a
 * real point reaches the border and the dual of the standard-flooding
 * colouring is a triangulation of the frame rectangle (Cao, Edelsbrunner,
 * Tan: with the outside as one more site x0 it triangulates the sphere, and
 * x0's link is the frame).  Every hull edge then gets the fake vertex whose
 * direction is closest to its outward normal, and every hull vertex a fan
 * of the fakes in between; all these triangles are counter-clockwise for
 * R -> infinity, which is checked with the symbolic orientation of
 * kernels/gcd_geom.clh.
 */
#ifndef GCD_HULL_H
#define GCD_HULL_H

#include <stddef.h>
#include <stdint.h>

#include "gdt_error.h"
#include "gdt_predicates.h"

/* A growable list of triangles (3 vertex indices each). */
typedef struct gcd_tri_list {
    int32_t *v;
    size_t n, cap; /* triangles */
} gcd_tri_list;

void gcd_tri_list_free(gcd_tri_list *l);

/* The fake boundary: fake k is vertex nreal + k, at C + R u_k. */
typedef struct gcd_frame {
    int64_t cx, cy;
    int32_t nreal;
} gcd_frame;

/* Appends the fake ring around the convex counter-clockwise hull cycle
 * h[0..k) (positions hp; collinear hull points included; k = 1: a single
 * point; a doubled chain for collinear sets).  *nring: triangles added.
 * Errors: 7621 (a ring triangle is not counter-clockwise: the cycle was not
 * convex), 7001. */
gdt_status gcd_ring(const gcd_frame *fr, const int32_t *h, const gdt_ipt *hp, size_t k,
                    gcd_tri_list *out, size_t *nring, gdt_error *err);

/* Collinear vertex set idx/pos[0..m) (m >= 1, distinct, any order; checked
 * collinear, else 7621): appends the fake ring around the doubled chain. */
gdt_status gcd_hull_degenerate(const gcd_frame *fr, int32_t *idx, gdt_ipt *pos, size_t m,
                               gcd_tri_list *out, size_t *nring, gdt_error *err);

#endif
