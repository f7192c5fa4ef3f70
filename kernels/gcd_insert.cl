/* gcd_insert.cl — Phase 4 of the gCD core: parallel insertion of the
 * missing points (Algorithm 3 of Qi, Cao & Tan), also the whole insertion
 * path for tiles the grid fits badly.
 *
 * One round:
 *   p4_locate  every uninserted point walks from its hint to its container:
 *              the triangle holding it strictly inside, or the edge it lies
 *              on (remembering stochastic walk with a deterministic hash, so
 *              it ends on any valid triangulation); a point on a vertex is a
 *              duplicate;
 *   p4_mark    atomic_min of the point's priority on its container (both
 *              triangles for an edge);
 *   p4_win     a point holding all its marks inserts this round, into
 *              the two dead slots reserved for it (d_rslot, core/private/
 *              gcd_ctx.h);
 *   p4_apply   1 -> 3 (inside) or 2 -> 4 (on an edge) split, phase A of the
 *              two-phase rewrite (kernels/gcd_tri.clh);
 *   p4_link    phase B; losers keep their container as the next hint.
 * CPU reference: the reference triangulator (the final result) and the
 * validity checks of tests/c/test_gcd_core.c. */
#include "gcd_tri.clh"

#define P4_MAX_STEPS (1 << 24)
#define P4_ERR 0
#define P4_ERRV 1
#define P4_DUP 2
#define P4_DUPA 3
#define P4_DUPB 4
#define P4_STEPS 5

/* Rotation around vertex w (at slot k of t) to the triangle whose wedge at
 * w holds q, returned; *steps counts the moves.  Gives up (returning the
 * last triangle) after 64 moves or at a boundary: the walk that follows
 * finds the container anyway. */
inline int p4_wedge(__global const int *tri, __global const int *opp, __global const int *pos,
                    int nreal, long cx, long cy, gcd_spt q, int t, int k, uint *steps)
{
    int w = tri[3 * t + k];
    gcd_spt sw = gcd_vpt(pos, w, nreal, cx, cy);
    for (int turn = 0; turn < 64; turn++) {
        int a = tri[3 * t + (k + 1) % 3], b = tri[3 * t + (k + 2) % 3];
        int nx;
        if (gcd_orient(sw, gcd_vpt(pos, a, nreal, cx, cy), q) < 0)
            nx = opp[3 * t + (k + 2) % 3]; /* clockwise: across w-a */
        else if (gcd_orient(sw, gcd_vpt(pos, b, nreal, cx, cy), q) > 0)
            nx = opp[3 * t + (k + 1) % 3]; /* counter-clockwise: across w-b */
        else
            break;
        if (nx < 0)
            break;
        t = nx >> 2;
        k = gcd_slot_of(tri, t, w);
        (*steps)++;
    }
    return t;
}

/* The walk of one point (work-item g of p4_locate); returns its steps. */
inline uint p4_walk(__global const int *tri, __global const int *opp, __global const int *pos,
                    __global const int *pts, int nreal, long cx, long cy,
                    __global const int *list, uint g, __global int *hint,
                    __global const int *piv, __global int *cont, __global uint *locep,
                    uint epoch, __global uint *stat)
{
    int p = list[g];
    long qx = pts[2 * p], qy = pts[2 * p + 1];
    gcd_spt q = gcd_spt_real(qx, qy, cx, cy);
    int t = hint[g];
    uint steps = 0;
    if (locep[g] == 0 && piv[g] >= 0) {
        int k = gcd_slot_of(tri, t, piv[g]);
        if (k >= 0)
            t = p4_wedge(tri, opp, pos, nreal, cx, cy, q, t, k, &steps);
    }
    locep[g] = epoch;
    int came = -1; /* slot of t through which the walk entered (q inside it) */
    for (;;) {
        int v0 = tri[3 * t], v1 = tri[3 * t + 1], v2 = tri[3 * t + 2];
        int o[3];
        if (!gcd_is_fake(v0, nreal) && !gcd_is_fake(v1, nreal) && !gcd_is_fake(v2, nreal)) {
            long x0 = pos[2 * v0], y0 = pos[2 * v0 + 1], x1 = pos[2 * v1], y1 = pos[2 * v1 + 1];
            long x2 = pos[2 * v2], y2 = pos[2 * v2 + 1];
            o[0] = came == 0 ? 1 : gdt_x_orient2d(x1, y1, x2, y2, qx, qy);
            o[1] = came == 1 ? 1 : gdt_x_orient2d(x2, y2, x0, y0, qx, qy);
            o[2] = came == 2 ? 1 : gdt_x_orient2d(x0, y0, x1, y1, qx, qy);
        } else {
            gcd_spt s0 = gcd_vpt(pos, v0, nreal, cx, cy), s1 = gcd_vpt(pos, v1, nreal, cx, cy);
            gcd_spt s2 = gcd_vpt(pos, v2, nreal, cx, cy);
            o[0] = came == 0 ? 1 : gcd_orient(s1, s2, q);
            o[1] = came == 1 ? 1 : gcd_orient(s2, s0, q);
            o[2] = came == 2 ? 1 : gcd_orient(s0, s1, q);
        }
        /* leave through an edge that has q strictly outside (never the one
         * just crossed: q is strictly inside it, o = 1 without a test); the
         * first edge tried is random */
        int r = (int)(gcd_hash2((uint)p, steps) % 3u), moved = 0;
        for (int k = 0; k < 3 && !moved; k++) {
            int i = (r + k) % 3;
            int nb = opp[3 * t + i];
            if (o[i] < 0 && nb >= 0) {
                t = nb >> 2;
                came = nb & 3;
                moved = 1;
            }
        }
        if (!moved && (o[0] < 0 || o[1] < 0 || o[2] < 0)) {
            /* outside a boundary edge: impossible inside the fake polygon */
            stat[P4_ERRV] = (uint)p;
            atomic_inc(&stat[P4_ERR]);
            cont[g] = -1;
            return steps;
        }
        if (!moved) {
            int zeros = (o[0] == 0) + (o[1] == 0) + (o[2] == 0);
            if (zeros >= 2) {
                /* on a vertex: the vertex where the two zero edges meet */
                int v = o[0] != 0 ? v0 : o[1] != 0 ? v1 : v2;
                if (atomic_inc(&stat[P4_DUP]) == 0) {
                    stat[P4_DUPA] = (uint)p;
                    stat[P4_DUPB] = (uint)v;
                }
                cont[g] = -1;
            } else {
                int e = o[0] == 0 ? 0 : o[1] == 0 ? 1 : o[2] == 0 ? 2 : 3;
                cont[g] = (t << 2) | e;
            }
            hint[g] = t;
            return steps;
        }
        if (++steps > P4_MAX_STEPS) {
            stat[P4_ERRV] = (uint)p;
            atomic_inc(&stat[P4_ERR]);
            cont[g] = -1;
            return steps;
        }
    }
}

/* cont[g] = container: (t << 2 | e), e = 3 inside, else the slot of the
 * edge p lies on.  hint[g]: start triangle in, container out; the first
 * location first turns around piv[g] (a vertex of the hint, or -1) to the
 * wedge holding the point.  locep[g]: the round that located the point (0:
 * never); a point whose container was not rewritten since (modified[]
 * holds each slot's last rewrite round) keeps it without walking. */
__kernel void p4_locate(__global const int *tri, __global const int *opp,
                        __global const int *pos, __global const int *pts, int nreal, long cx,
                        long cy, __global const int *list, uint nl, __global int *hint,
                        __global const int *piv, __global int *cont, __global uint *locep,
                        __global const uint *modified, uint epoch, __global uint *stat)
{
    __local uint l_steps;
    uint g = get_global_id(0), lid = get_local_id(0);
    uint steps = 0;
    if (lid == 0)
        l_steps = 0;
    barrier(CLK_LOCAL_MEM_FENCE);
    /* a container untouched since the point found it is still its container */
    if (g < nl && !(locep[g] != 0 && cont[g] >= 0 && modified[cont[g] >> 2] < locep[g]))
        steps = p4_walk(tri, opp, pos, pts, nreal, cx, cy, list, g, hint, piv, cont, locep,
                        epoch, stat);
    if (steps)
        atomic_add(&l_steps, steps);
    barrier(CLK_LOCAL_MEM_FENCE);
    if (lid == 0 && l_steps)
        atomic_add(&stat[P4_STEPS], l_steps);
}

__kernel void p4_mark(__global const int *opp, __global const int *list, uint nl,
                      __global const int *cont, __global uint *mark)
{
    uint g = get_global_id(0);
    if (g >= nl || cont[g] < 0)
        return;
    uint pp = gcd_prio((uint)list[g]);
    int t = cont[g] >> 2, e = cont[g] & 3;
    atomic_min(&mark[t], pp);
    if (e < 3)
        atomic_min(&mark[opp[3 * t + e] >> 2], pp);
}

/* win[g] = 1 for a winner (and its container is recorded in cont). */
__kernel void p4_win(__global const int *opp, __global const int *list, uint nl,
                     __global const int *cont, __global const uint *mark, __global uint *win)
{
    uint g = get_global_id(0);
    if (g >= nl)
        return;
    uint w = 0;
    if (cont[g] >= 0) {
        uint pp = gcd_prio((uint)list[g]);
        int t = cont[g] >> 2, e = cont[g] & 3;
        w = mark[t] == pp && (e == 3 || mark[opp[3 * t + e] >> 2] == pp);
    }
    win[g] = w;
}

/* Phase A.  The new slots are the point's reserved dead slots rslot[2p],
 * rslot[2p+1].  fix[4g..4g+3]: the new slots holding old outer
 * references. */
__kernel void p4_apply(__global int *tri, __global int *opp, __global int *pos,
                       __global const int *pts, __global const int *list, uint nl,
                       __global const int *cont, __global const uint *win,
                       __global const int *rslot, __global int *exch,
                       __global uint *modified, uint round, __global int *vt, __global int *fix,
                       __global int *newl, __global uint *nnew)
{
    uint g = get_global_id(0);
    if (g >= nl || !win[g])
        return;
    int p = list[g], t = cont[g] >> 2, e = cont[g] & 3;
    int s1 = rslot[2 * p], s2 = rslot[2 * p + 1];
    /* a deleted bad case still has its texel corner there */
    pos[2 * p] = pts[2 * p];
    pos[2 * p + 1] = pts[2 * p + 1];
    if (e == 3) {
        int v0 = tri[3 * t], v1 = tri[3 * t + 1], v2 = tri[3 * t + 2];
        int o0 = opp[3 * t], o1 = opp[3 * t + 1], o2 = opp[3 * t + 2];
        tri[3 * t] = p, tri[3 * t + 1] = v1, tri[3 * t + 2] = v2;
        tri[3 * s1] = p, tri[3 * s1 + 1] = v2, tri[3 * s1 + 2] = v0;
        tri[3 * s2] = p, tri[3 * s2 + 1] = v0, tri[3 * s2 + 2] = v1;
        opp[3 * t] = o0, opp[3 * t + 1] = (s1 << 2) | 2, opp[3 * t + 2] = (s2 << 2) | 1;
        opp[3 * s1] = o1, opp[3 * s1 + 1] = (s2 << 2) | 2, opp[3 * s1 + 2] = (t << 2) | 1;
        opp[3 * s2] = o2, opp[3 * s2 + 1] = (t << 2) | 2, opp[3 * s2 + 2] = (s1 << 2) | 1;
        exch[3 * t] = (t << 2) | 0;
        exch[3 * t + 1] = (s1 << 2) | 0;
        exch[3 * t + 2] = (s2 << 2) | 0;
        modified[t] = round;
        fix[4 * g] = (t << 2) | 0;
        fix[4 * g + 1] = (s1 << 2) | 0;
        fix[4 * g + 2] = (s2 << 2) | 0;
        fix[4 * g + 3] = -1;
        uint k = atomic_add(nnew, 3u);
        newl[k] = t, newl[k + 1] = s1, newl[k + 2] = s2;
    } else {
        int ou = opp[3 * t + e], u = ou >> 2, f = ou & 3;
        int e1 = (e + 1) % 3, e2 = (e + 2) % 3, f1 = (f + 1) % 3, f2 = (f + 2) % 3;
        int c = tri[3 * t + e], a = tri[3 * t + e1], b = tri[3 * t + e2], w = tri[3 * u + f];
        int tb = opp[3 * t + e1], ta = opp[3 * t + e2]; /* across b-c and c-a */
        int ua = opp[3 * u + f1], ub = opp[3 * u + f2]; /* across a-w and w-b */
        tri[3 * t] = p, tri[3 * t + 1] = b, tri[3 * t + 2] = c;
        tri[3 * s1] = p, tri[3 * s1 + 1] = c, tri[3 * s1 + 2] = a;
        tri[3 * u] = p, tri[3 * u + 1] = a, tri[3 * u + 2] = w;
        tri[3 * s2] = p, tri[3 * s2 + 1] = w, tri[3 * s2 + 2] = b;
        opp[3 * t] = tb, opp[3 * t + 1] = (s1 << 2) | 2, opp[3 * t + 2] = (s2 << 2) | 1;
        opp[3 * s1] = ta, opp[3 * s1 + 1] = (u << 2) | 2, opp[3 * s1 + 2] = (t << 2) | 1;
        opp[3 * u] = ua, opp[3 * u + 1] = (s2 << 2) | 2, opp[3 * u + 2] = (s1 << 2) | 1;
        opp[3 * s2] = ub, opp[3 * s2 + 1] = (t << 2) | 2, opp[3 * s2 + 2] = (u << 2) | 1;
        exch[3 * t + e1] = (t << 2) | 0;
        exch[3 * t + e2] = (s1 << 2) | 0;
        exch[3 * u + f1] = (u << 2) | 0;
        exch[3 * u + f2] = (s2 << 2) | 0;
        modified[t] = round;
        modified[u] = round;
        fix[4 * g] = (t << 2) | 0;
        fix[4 * g + 1] = (s1 << 2) | 0;
        fix[4 * g + 2] = (u << 2) | 0;
        fix[4 * g + 3] = (s2 << 2) | 0;
        uint k = atomic_add(nnew, 4u);
        newl[k] = t, newl[k + 1] = s1, newl[k + 2] = u, newl[k + 3] = s2;
    }
    vt[p] = t;
}

/* Phase B, and the marks of every candidate are cleared; lose[g] = 1 for a
 * point still to insert. */
__kernel void p4_link(__global int *opp, __global const int *exch,
                      __global const uint *modified, uint round, uint nl,
                      __global const uint *win, __global const int *fix)
{
    uint g = get_global_id(0);
    if (g >= nl || !win[g])
        return;
    for (int k = 0; k < 4; k++) {
        int f = fix[4 * g + k];
        if (f >= 0)
            gcd_link_fix(opp, exch, modified, round, f >> 2, f & 3);
    }
}

/* Clears the marks set by p4_mark (containers read before the round). */
__kernel void p4_unmark(__global const int *list, uint nl, __global const int *cont,
                        __global const int *oldnb, __global uint *mark, __global const uint *win,
                        __global uint *lose)
{
    uint g = get_global_id(0);
    if (g >= nl)
        return;
    if (cont[g] >= 0) {
        mark[cont[g] >> 2] = GCD_EMPTY;
        if (oldnb[g] >= 0)
            mark[oldnb[g]] = GCD_EMPTY;
    }
    lose[g] = win[g] ? 0u : 1u;
}

/* The neighbour across the container edge, read before any rewrite. */
__kernel void p4_nb(__global const int *opp, uint nl, __global const int *cont,
                    __global int *oldnb)
{
    uint g = get_global_id(0);
    if (g >= nl)
        return;
    int c = cont[g];
    oldnb[g] = (c >= 0 && (c & 3) < 3) ? opp[3 * (c >> 2) + (c & 3)] >> 2 : -1;
}

/* Start hints of the missing points: a triangle of the vertex that owns the
 * point's texel, or of the point's former neighbour when it was deleted as a
 * bad case (following deleted neighbours), and that vertex as the pivot of
 * the first walk.  Triangle 0 (no pivot) if all else fails. */
__kernel void p4_hints(__global const int *list, uint nl, __global const uint *texel,
                       __global const uint *seed, __global const int *vt,
                       __global const int *tri, uint T, uint all_missing, __global int *hint,
                       __global int *piv)
{
    uint g = get_global_id(0);
    if (g >= nl)
        return;
    if (all_missing) {
        hint[g] = 0;
        piv[g] = -1;
        return;
    }
    int p = list[g];
    uint owner = seed[texel[p]];
    int v = owner == (uint)p ? p : (int)owner;
    /* a deleted vertex names a former neighbour (vt = -2 - q): follow */
    for (int k = 0; k < 1024 && vt[v] <= -2; k++)
        v = -2 - vt[v];
    int h = vt[v];
    if (h < 0 || (uint)h >= T || tri[3 * h] < 0) {
        h = 0;
        v = -1;
    }
    hint[g] = h;
    piv[g] = v;
}

/* Compaction of the losers: their point, hint, container and location
 * round move to rank[g] (scan of lose[]). */
__kernel void p4_compact(__global const int *list, __global const int *hint,
                         __global const int *cont, __global const uint *locep, uint nl,
                         __global const uint *rank, uint total, __global int *out,
                         __global int *outh, __global int *outc, __global uint *oute)
{
    uint g = get_global_id(0);
    if (g >= nl)
        return;
    uint next = g + 1 < nl ? rank[g + 1] : total;
    if (next != rank[g]) {
        out[rank[g]] = list[g];
        outh[rank[g]] = hint[g];
        outc[rank[g]] = cont[g];
        oute[rank[g]] = locep[g];
    }
}

/* flag[i] = 1 for a real point not in the triangulation: it lost its texel
 * (to a lower index or to the frame), it was deleted as a bad case, or the
 * insertion path inserts everything. */
__kernel void p4_absent_flags(__global const uint *texel, __global const uint *seed, uint n,
                              __global const uint *bad, uint all_missing, __global uint *flag)
{
    uint i = get_global_id(0);
    if (i < n)
        flag[i] = (all_missing || seed[texel[i]] != i || bad[i]) ? 1u : 0u;
}
