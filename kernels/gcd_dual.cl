/* gcd_dual.cl — Phase 2 of the gCD core: the triangles dual to the digital
 * Voronoi vertices of the standard-flooding colouring.
 *
 * Corner (x, y), 0 <= x < W-1, 0 <= y < H-1, is shared by the texels
 * a = (x, y), b = (x+1, y), c = (x+1, y+1), d = (x, y+1), counter-clockwise.
 * It is a digital Voronoi vertex when it sees four colours, or three with
 * the repeated colour on two side-adjacent texels (Cao, Edelsbrunner, Tan,
 * Fig. 2); a repeated colour on a diagonal is a neck.  The sites in the
 * counter-clockwise order of their texels form counter-clockwise triangles
 * (Consistent Orientation Lemma); four colours give (a, b, c) and (a, c, d).
 * Counting and writing are two passes over chunks of corners in row-major
 * order, so the triangle order is deterministic; each chunk's triangles
 * are followed by the slots it reserves for Phase 4 (gcd_geom.clh).
 * CPU reference: dual_reference in tests/c/test_gcd_phase2.c. */
#include "gcd_geom.clh"

/* Number of triangles of one corner; the vertices (colours) in *t. */
inline int p2_corner(__global const uint *colour, uint W, uint x, uint y, uint *t)
{
    uint a = colour[y * W + x], b = colour[y * W + x + 1];
    uint c = colour[(y + 1) * W + x + 1], d = colour[(y + 1) * W + x];
    if (a == c || b == d)
        return 0;
    int eq = (a == b) + (b == c) + (c == d) + (d == a);
    if (eq == 0) {
        t[0] = a, t[1] = b, t[2] = c;
        t[3] = a, t[4] = c, t[5] = d;
        return 2;
    }
    if (eq > 1)
        return 0;
    if (a == b)
        t[0] = a, t[1] = c, t[2] = d;
    else if (b == c)
        t[0] = a, t[1] = b, t[2] = d;
    else
        t[0] = a, t[1] = b, t[2] = c;
    return 1;
}

/* Slots per chunk: its dual triangles, then two reserved slots per
 * missing point at home in it (range: p1_missing_range). */
__kernel void p2_count(__global const uint *colour, uint W, uint H, __global const uint *range,
                       __global uint *counts)
{
    size_t g = get_global_id(0);
    size_t ncorner = (size_t)(W - 1) * (H - 1);
    size_t lo = g * GCD_CORNER_CHUNK;
    if (lo >= ncorner)
        return;
    size_t hi = lo + GCD_CORNER_CHUNK < ncorner ? lo + GCD_CORNER_CHUNK : ncorner;
    uint s = 0, t[6];
    uint x = (uint)(lo % (W - 1)), y = (uint)(lo / (W - 1));
    for (size_t i = lo; i < hi; i++) {
        s += (uint)p2_corner(colour, W, x, y, t);
        if (++x == W - 1)
            x = 0, y++;
    }
    counts[g] = s + 2 * (range[2 * g + 1] - range[2 * g]);
}

/* Vertices are point indices: seed[site texel].  The reserved slots are
 * written dead (tri[3s] = -1) and handed to their points: internal missing
 * point kept + j gets rslot[2p], rslot[2p+1].  The vertex counts of
 * m_vcount are done here for these slots (cnt preset to 0). */
__kernel void p2_write(__global const uint *colour, __global const uint *seed, uint W, uint H,
                       __global const uint *offsets, __global const uint *range, uint kept,
                       __global int *tri, __global int *rslot, __global uint *cnt)
{
    size_t g = get_global_id(0);
    size_t ncorner = (size_t)(W - 1) * (H - 1);
    size_t lo = g * GCD_CORNER_CHUNK;
    if (lo >= ncorner)
        return;
    size_t hi = lo + GCD_CORNER_CHUNK < ncorner ? lo + GCD_CORNER_CHUNK : ncorner;
    size_t o = offsets[g];
    uint t[6];
    uint x = (uint)(lo % (W - 1)), y = (uint)(lo / (W - 1));
    for (size_t i = lo; i < hi; i++) {
        int k = p2_corner(colour, W, x, y, t);
        for (int j = 0; j < 3 * k; j++) {
            uint v = seed[t[j]];
            tri[3 * o + j] = (int)v;
            atomic_inc(&cnt[v]);
        }
        o += (size_t)k;
        if (++x == W - 1)
            x = 0, y++;
    }
    for (uint j = range[2 * g]; j < range[2 * g + 1]; j++, o += 2) {
        size_t p = (size_t)kept + j;
        for (int q = 0; q < 6; q++)
            tri[3 * o + q] = GCD_NONE;
        rslot[2 * p] = (int)o;
        rslot[2 * p + 1] = (int)o + 1;
    }
}

/* flag[i] = 1 for a point that owns its texel (a kept point). */
__kernel void p2_kept_flags(__global const uint *texel, __global const uint *seed, uint n,
                            __global uint *flag)
{
    uint i = get_global_id(0);
    if (i < n)
        flag[i] = seed[texel[i]] == i ? 1u : 0u;
}
