/* flip.c — Lawson flip engine with the preferred-direction tie-break. */
#include "gdt_flip.h"

#include <stdlib.h>

#include "private/mesh_ops.h"

/* design: a stack of half-edges (triangle << 2 | slot) and one "queued" bit
 * per half-edge, so each (triangle, slot) is on the stack at most once.
 * Initially every interior edge is queued once.  A popped entry tests
 * whatever edge that slot holds now; a flip rewrites both triangles and
 * queues their four outer edges.  Invariant: every edge that may fail the
 * test has a queued half-edge or is adjacent to a frozen triangle, so the
 * loop ends with every unfrozen interior edge locally optimal.  Termination:
 * each flip lowers (lifted volume, sorted diagonal scores) lexicographically,
 * and a point set has finitely many triangulations. */
gdt_status gdt_flip_to_delaunay(gdt_pred_stats *st, gdt_flip_stats *fs, gdt_mesh *m,
                                const uint8_t *frozen, gdt_error *err)
{
    gdt_status s = GDT_OK;
    size_t nt = m->ntris;
    int32_t *tri = m->tri, *opp = m->opp;
    const gdt_ipt *pts = m->pts;
    int32_t *stack = NULL;
    uint8_t *queued = NULL;
    size_t top = 0;
    uint64_t tested = 0, flips = 0;

    if (nt > GDT_MESH_MAX_TRIS || m->nverts > GDT_MESH_MAX_VERTS)
        return gdt_error_set(err, GDT_EINTERNAL, 7350,
                             "flip engine: mesh of %zu vertices and %zu triangles exceeds the "
                             "limits",
                             m->nverts, nt);
    if (nt < 2)
        return GDT_OK;
    stack = malloc(3 * nt * sizeof *stack);
    queued = calloc(nt, 1);
    if (stack == NULL || queued == NULL) {
        s = gdt_error_set(err, GDT_EINTERNAL, 7001,
                          "out of memory for the flip queue of %zu triangles", nt);
        goto fail;
    }
    for (size_t k = nt; k-- > 0;) {
        int32_t t = (int32_t)k;
        if (frozen != NULL && frozen[t])
            continue;
        for (int i = 2; i >= 0; i--) {
            int32_t o = opp[3 * (size_t)t + (size_t)i];
            if (o == GDT_MESH_NONE || gdt_opp_tri(o) < t)
                continue;
            stack[top++] = gdt_opp_pack(t, i);
            queued[t] |= (uint8_t)(1u << i);
        }
    }
    while (top > 0) {
        int32_t e = stack[--top];
        int32_t t = gdt_opp_tri(e);
        int i = gdt_opp_slot(e);
        queued[t] &= (uint8_t) ~(1u << i);
        int32_t o = opp[3 * (size_t)t + (size_t)i];
        if (o == GDT_MESH_NONE)
            continue;
        int32_t u = gdt_opp_tri(o);
        if (frozen != NULL && (frozen[t] || frozen[u]))
            continue;
        const int32_t *T = tri + 3 * (size_t)t;
        int32_t d = tri[3 * (size_t)u + (size_t)gdt_opp_slot(o)];
        tested++;
        if (!gdt_edge_needs_flip(st, pts[T[mesh_next(i)]], pts[T[mesh_prev(i)]], pts[T[i]], pts[d]))
            continue;
        mesh_flip(tri, opp, t, i);
        flips++;
        /* t = (c, a, d), u = (c, d, b): outer edges are t slots 0, 2 and
         * u slots 0, 1. */
        static const int outer_slot[4] = {0, 2, 0, 1};
        for (int q = 0; q < 4; q++) {
            int32_t w = q < 2 ? t : u;
            int sl = outer_slot[q];
            if (!(queued[w] & (1u << sl))) {
                queued[w] |= (uint8_t)(1u << sl);
                stack[top++] = gdt_opp_pack(w, sl);
            }
        }
    }
    if (fs != NULL) {
        fs->edges_tested += tested;
        fs->flips += flips;
    }

fail:
    free(stack);
    free(queued);
    return s;
}
