/* mesh_ops.h — combinatorial mesh operations shared by the reference
 * triangulator, the flip engine and the verifiers (no geometry here).
 *
 * Conventions are those of gdt_mesh.h: slot i of triangle t is opposite the
 * edge tri[3t+(i+1)%3] -> tri[3t+(i+2)%3]; opp entries are packed
 * (triangle << 2 | slot) or GDT_MESH_NONE.  The reference triangulator also
 * stores "ghost" triangles that use one extra vertex index standing for the
 * point at infinity; these operations never look at coordinates, so they
 * work on ghosts unchanged.
 */
#ifndef GDT_MESH_OPS_H
#define GDT_MESH_OPS_H

#include <stddef.h>
#include <stdint.h>

#include "gdt_mesh.h"

static inline int mesh_next(int i)
{
    return i == 2 ? 0 : i + 1;
}
static inline int mesh_prev(int i)
{
    return i == 0 ? 2 : i - 1;
}

/* The opp entry a packed pointer designates. */
static inline int32_t *mesh_opp_ref(int32_t *opp, int32_t packed)
{
    return opp + 3 * (size_t)gdt_opp_tri(packed) + (size_t)gdt_opp_slot(packed);
}

/* Flips the edge opposite slot i of triangle t.
 * Preconditions (not checked): opp[3t+i] designates the neighbour u; the
 * quadrilateral of t and u is strictly convex, so both new triangles are
 * counter-clockwise; the four outer neighbours are triangles other than t
 * and u.
 * With c = t[i], a = t[i+1], b = t[i+2] and d the apex of u opposite a-b,
 * afterwards t = (c, a, d) and u = (c, d, b): slot 0 of both holds c, the
 * new diagonal c-d is opposite t's slot 1 and u's slot 2, and every outer
 * neighbour's back pointer is updated. */
static inline void mesh_flip(int32_t *tri, int32_t *opp, int32_t t, int i)
{
    int32_t *T = tri + 3 * (size_t)t;
    int32_t *O = opp + 3 * (size_t)t;
    int i1 = mesh_next(i), i2 = mesh_prev(i);
    int32_t c = T[i], a = T[i1], b = T[i2];
    int32_t ou = O[i];
    int32_t u = gdt_opp_tri(ou);
    int j = gdt_opp_slot(ou), j1 = mesh_next(j), j2 = mesh_prev(j);
    int32_t *U = tri + 3 * (size_t)u;
    int32_t *P = opp + 3 * (size_t)u;
    int32_t d = U[j];
    int32_t na = O[i1]; /* across b-c */
    int32_t nb = O[i2]; /* across c-a */
    int32_t mb = P[j1]; /* across a-d */
    int32_t ma = P[j2]; /* across d-b */

    T[0] = c, T[1] = a, T[2] = d;
    O[0] = mb, O[1] = gdt_opp_pack(u, 2), O[2] = nb;
    U[0] = c, U[1] = d, U[2] = b;
    P[0] = ma, P[1] = na, P[2] = gdt_opp_pack(t, 1);
    if (mb != GDT_MESH_NONE)
        *mesh_opp_ref(opp, mb) = gdt_opp_pack(t, 0);
    if (nb != GDT_MESH_NONE)
        *mesh_opp_ref(opp, nb) = gdt_opp_pack(t, 2);
    if (ma != GDT_MESH_NONE)
        *mesh_opp_ref(opp, ma) = gdt_opp_pack(u, 0);
    if (na != GDT_MESH_NONE)
        *mesh_opp_ref(opp, na) = gdt_opp_pack(u, 1);
}

/* Writes the fan of k triangles around vertex p into the triangle slots
 * ids[0..k): triangle ids[q] = (p, v[q], v[q+1 mod k]), whose slot 0 faces
 * the outer neighbour outer[q] (packed, or GDT_MESH_NONE) across
 * v[q]-v[q+1]; the spokes are linked around p and the outer neighbours'
 * back pointers are set.  outer[] must be read before the old triangles are
 * overwritten, i.e. passed in by the caller. */
static inline void mesh_fan(int32_t *tri, int32_t *opp, int32_t p, const int32_t *v,
                            const int32_t *outer, const int32_t *ids, int k)
{
    for (int q = 0; q < k; q++) {
        int32_t t = ids[q];
        int32_t *T = tri + 3 * (size_t)t;
        int32_t *O = opp + 3 * (size_t)t;
        T[0] = p, T[1] = v[q], T[2] = v[(q + 1) % k];
        O[0] = outer[q];
        O[1] = gdt_opp_pack(ids[(q + 1) % k], 2);
        O[2] = gdt_opp_pack(ids[(q + k - 1) % k], 1);
        if (outer[q] != GDT_MESH_NONE)
            *mesh_opp_ref(opp, outer[q]) = gdt_opp_pack(t, 0);
    }
}

/* ---- helpers implemented in mesh.c ---- */

/* Computes opp from tri alone (see gdt_mesh_link), into opp[3*ntris].
 * Errors 7302, 7303, 7001. */
gdt_status gdt_mesh_adjacency(const int32_t *tri, size_t ntris, size_t nverts, int32_t *opp,
                              gdt_error *err);

/* Sorts key[0..n) ascending, carrying val along (stable LSD radix sort over
 * the bytes that differ).  tkey/tval: caller-provided scratch of n entries. */
void gdt_mesh_radix_sort(uint64_t *key, int32_t *val, size_t n, uint64_t *tkey, int32_t *tval);

#endif
