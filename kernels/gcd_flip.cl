/* gcd_flip.cl — Phase 5 of the gCD core: parallel Lawson flipping to
 * T_{d1,d2} (and the shared flip machinery of the insertion path).
 *
 * One round:
 *   p5_check  over the active triangles: every edge is tested once (by the
 *             triangle of smaller index, or by the active side when the
 *             other is inactive) with the double-precision filter; a quad
 *             the filter certifies is decided at once (co-circular ones by
 *             the integer tie-break), the others are appended to the exact
 *             list (quads with a fake vertex always are);
 *   p5_exact  decides the listed quads exactly (128-bit in-circle, symbolic
 *             predicates for fakes, Dyken-Floater tie-break);
 *             every edge to flip votes with its priority on both triangles
 *             (atomic_min; priorities are distinct) and joins the candidates;
 *   p5_flip   a candidate that holds both votes flips: its two triangle
 *             slots are rewritten (mesh_flip of core/private/mesh_ops.h) and
 *             each of its four outer edges records where it went (exch);
 *   p5_link   the flipped pairs fix their outer links: across an edge whose
 *             neighbour also flipped, the neighbour's exch entry names the
 *             new triangle; otherwise the neighbour's back pointer is set
 *             (no other pair touches that slot) — a race-free two-phase flip;
 *   p5_next   flipped and outvoted triangles form the next active list.
 * Candidates are (t << 2 | i, u << 2 | j) pairs, read before any rewrite.
 * Decisions depend only on the mesh, never on list order, so the result is
 * deterministic; Lawson's algorithm with the tie-break ends at T_{d1,d2}.
 * CPU reference: the flip engine gdt_flip_to_delaunay (core/flip.c). */
#include "gcd_tri.clh"

/* Counters in stat[]: */
#define P5_TESTED 0
#define P5_EXACT 1
#define P5_TIEBREAK 2
#define P5_FLIPS 3

inline gcd_spt p5_pt(__global const int *pos, int v, int nreal, long cx, long cy)
{
    if (v >= nreal && v < nreal + GCD_NFAKE)
        return gcd_spt_fake(v - nreal);
    return gcd_spt_real((long)pos[2 * v], (long)pos[2 * v + 1], cx, cy);
}

inline void p5_vote(__global uint *vote, int t, int u, uint prio)
{
    atomic_min(&vote[t], prio);
    atomic_min(&vote[u], prio);
}

inline void p5_candidate(__global uint *vote, __global int *cand, __global uint *ncand, int t,
                         int i, int u, int j)
{
    int e = (t << 2) | i, f = (u << 2) | j;
    uint prio = gcd_prio((uint)(e < f ? e : f));
    p5_vote(vote, t, u, prio);
    uint k = atomic_inc(ncand);
    cand[2 * k] = e;
    cand[2 * k + 1] = f;
}

/* active[0..na): triangles to check; inact[t] == round marks them.
 * List appends and counters are aggregated per work-group in local memory
 * (one global atomic per group and list), so the lists' order depends on
 * scheduling but their content does not. */
__kernel void p5_check(__global const int *tri, __global const int *opp,
                       __global const int *pos, int nreal, long cx, long cy,
                       __global const int *active, uint na, __global const uint *inact,
                       uint round, uint all_active, __global uint *vote, __global int *cand,
                       __global uint *ncand, __global int *exact, __global uint *nexact,
                       __global uint *stat)
{
    __local uint l_tested, l_tie, l_nc, l_nx, l_bc, l_bx;
    uint g = get_global_id(0), lid = get_local_id(0);
    int ce[3], cf[3], xe[3];
    uint nc = 0, nx = 0, tested = 0, tie = 0;
    if (lid == 0)
        l_tested = l_tie = l_nc = l_nx = 0;
    barrier(CLK_LOCAL_MEM_FENCE);
    int t = g < na ? active[g] : -1;
    int v[3] = {-1, -1, -1};
    if (t >= 0) {
        v[0] = tri[3 * t];
        v[1] = tri[3 * t + 1];
        v[2] = tri[3 * t + 2];
    }
    if (v[0] >= 0) {
        int tfake = gcd_is_fake(v[0], nreal) || gcd_is_fake(v[1], nreal) || gcd_is_fake(v[2], nreal);
        long px[3], py[3];
        for (int k = 0; k < 3; k++) {
            px[k] = tfake ? 0 : pos[2 * v[k]];
            py[k] = tfake ? 0 : pos[2 * v[k] + 1];
        }
        for (int i = 0; i < 3; i++) {
            int o = opp[3 * t + i];
            if (o < 0)
                continue;
            int u = o >> 2, j = o & 3;
            if (u < t && (all_active || inact[u] == round))
                continue; /* the other side tests it */
            tested++;
            int i1 = i == 2 ? 0 : i + 1, i2 = i == 0 ? 2 : i - 1;
            int d = tri[3 * u + j];
            int flip = 0, undecided = 1;
#if defined(GDT_X_HAVE_F64)
            if (!tfake && !gcd_is_fake(d, nreal)) {
                /* edge a-b of the counter-clockwise (a, b, c) and (b, a, d) */
                long ax = px[i1], ay = py[i1], bx = px[i2], by = py[i2];
                long cx2 = px[i], cy2 = py[i], dx = pos[2 * d], dy = pos[2 * d + 1];
                int s = gdt_x_incircle_filter_d(ax - dx, ay - dy, bx - dx, by - dy, cx2 - dx,
                                                cy2 - dy);
                if (s != GDT_X_UNDECIDED) {
                    undecided = 0;
                    if (s > 0) {
                        flip = 1;
                    } else if (s == 0 && gdt_x_orient2d(dx, dy, bx, by, cx2, cy2) > 0 &&
                               gdt_x_orient2d(cx2, cy2, ax, ay, dx, dy) > 0) {
                        tie++;
                        flip = gdt_x_prefer_diagonal(dx - cx2, dy - cy2, bx - ax, by - ay) > 0;
                    }
                }
            }
#endif
            if (undecided) {
                xe[nx++] = (t << 2) | i;
            } else if (flip) {
                int e = (t << 2) | i, f = (u << 2) | j;
                p5_vote(vote, t, u, gcd_prio((uint)(e < f ? e : f)));
                ce[nc] = e;
                cf[nc++] = f;
            }
        }
    }
    uint myc = nc ? atomic_add(&l_nc, nc) : 0;
    uint myx = nx ? atomic_add(&l_nx, nx) : 0;
    if (tested)
        atomic_add(&l_tested, tested);
    if (tie)
        atomic_add(&l_tie, tie);
    barrier(CLK_LOCAL_MEM_FENCE);
    if (lid == 0) {
        l_bc = l_nc ? atomic_add(ncand, l_nc) : 0;
        l_bx = l_nx ? atomic_add(nexact, l_nx) : 0;
        if (l_tested)
            atomic_add(&stat[P5_TESTED], l_tested);
        if (l_tie)
            atomic_add(&stat[P5_TIEBREAK], l_tie);
    }
    barrier(CLK_LOCAL_MEM_FENCE);
    for (uint k = 0; k < nc; k++) {
        cand[2 * (l_bc + myc + k)] = ce[k];
        cand[2 * (l_bc + myc + k) + 1] = cf[k];
    }
    for (uint k = 0; k < nx; k++)
        exact[l_bx + myx + k] = xe[k];
}

/* The quads the filter left undecided (or that hold a fake). */
__kernel void p5_exact(__global const int *tri, __global const int *opp,
                       __global const int *pos, int nreal, long cx, long cy,
                       __global const int *exact, uint nx, __global uint *vote,
                       __global int *cand, __global uint *ncand, __global uint *stat)
{
    uint g = get_global_id(0);
    if (g >= nx)
        return;
    int e = exact[g], t = e >> 2, i = e & 3;
    int o = opp[3 * t + i], u = o >> 2, j = o & 3;
    int c = tri[3 * t + i], a = tri[3 * t + (i + 1) % 3], b = tri[3 * t + (i + 2) % 3];
    int d = tri[3 * u + j];
    unsigned code = gcd_flip_code(p5_pt(pos, a, nreal, cx, cy), p5_pt(pos, b, nreal, cx, cy),
                                  p5_pt(pos, c, nreal, cx, cy), p5_pt(pos, d, nreal, cx, cy), a,
                                  b, c, d);
    if (code & GDT_X_USED_EXACT)
        atomic_inc(&stat[P5_EXACT]);
    if (code & GDT_X_USED_TIEBREAK)
        atomic_inc(&stat[P5_TIEBREAK]);
    if (code & GDT_X_FLIP)
        p5_candidate(vote, cand, ncand, t, i, u, j);
}

/* Phase A of the two-phase flip: winners rewrite their two slots; the new
 * outer slots hold the old outer references until p5_link; exch[old slot]
 * names the new slot of each outer edge; flipped[] marks the round. */
__kernel void p5_flip(__global int *tri, __global int *opp, __global const int *cand, uint nc,
                      __global const uint *vote, __global int *exch, __global uint *flipped,
                      uint round, __global uint *win, __global uint *stat)
{
    uint g = get_global_id(0);
    if (g >= nc)
        return;
    int e = cand[2 * g], t = e >> 2, i = e & 3;
    int f = cand[2 * g + 1], u = f >> 2, j = f & 3;
    uint prio = gcd_prio((uint)(e < f ? e : f));
    if (vote[t] != prio || vote[u] != prio) {
        win[g] = 0;
        return;
    }
    win[g] = 1;
    int i1 = (i + 1) % 3, i2 = (i + 2) % 3, j1 = (j + 1) % 3, j2 = (j + 2) % 3;
    int c = tri[3 * t + i], a = tri[3 * t + i1], b = tri[3 * t + i2], d = tri[3 * u + j];
    int na = opp[3 * t + i1], nb = opp[3 * t + i2], mb = opp[3 * u + j1], ma = opp[3 * u + j2];
    tri[3 * t] = c, tri[3 * t + 1] = a, tri[3 * t + 2] = d;
    tri[3 * u] = c, tri[3 * u + 1] = d, tri[3 * u + 2] = b;
    opp[3 * t] = mb, opp[3 * t + 1] = (u << 2) | 2, opp[3 * t + 2] = nb;
    opp[3 * u] = ma, opp[3 * u + 1] = na, opp[3 * u + 2] = (t << 2) | 1;
    exch[3 * t + i2] = (t << 2) | 2;
    exch[3 * u + j1] = (t << 2) | 0;
    exch[3 * u + j2] = (u << 2) | 0;
    exch[3 * t + i1] = (u << 2) | 1;
    flipped[t] = round;
    flipped[u] = round;
    atomic_inc(&stat[P5_FLIPS]);
}

/* Phase B: outer links of the flipped pairs. */
inline void p5_fix(__global int *opp, __global const int *exch, __global const uint *flipped,
                   uint round, int y, int ys)
{
    int o = opp[3 * y + ys];
    if (o < 0)
        return;
    int n = o >> 2, ns = o & 3;
    if (flipped[n] == round)
        opp[3 * y + ys] = exch[3 * n + ns];
    else
        opp[3 * n + ns] = (y << 2) | ys;
}

__kernel void p5_link(__global int *opp, __global const int *cand, uint nc,
                      __global const uint *win, __global const int *exch,
                      __global const uint *flipped, uint round)
{
    uint g = get_global_id(0);
    if (g >= nc || !win[g])
        return;
    int t = cand[2 * g] >> 2, u = cand[2 * g + 1] >> 2;
    p5_fix(opp, exch, flipped, round, t, 0);
    p5_fix(opp, exch, flipped, round, t, 2);
    p5_fix(opp, exch, flipped, round, u, 0);
    p5_fix(opp, exch, flipped, round, u, 1);
}

/* Next active list: both triangles of every candidate (flipped or
 * outvoted), once each (inact[] holds the round a triangle was listed in);
 * votes are reset.  Appends are aggregated per work-group. */
__kernel void p5_next(__global const int *cand, uint nc, __global uint *vote,
                      __global uint *inact, uint next_round, __global int *next,
                      __global uint *nnext)
{
    __local uint l_n, l_base;
    uint g = get_global_id(0), lid = get_local_id(0);
    int add[2];
    uint na = 0;
    if (lid == 0)
        l_n = 0;
    barrier(CLK_LOCAL_MEM_FENCE);
    if (g < nc) {
        int t = cand[2 * g] >> 2, u = cand[2 * g + 1] >> 2;
        vote[t] = GCD_EMPTY;
        vote[u] = GCD_EMPTY;
        if (atomic_xchg(&inact[t], next_round) != next_round)
            add[na++] = t;
        if (atomic_xchg(&inact[u], next_round) != next_round)
            add[na++] = u;
    }
    uint my = na ? atomic_add(&l_n, na) : 0;
    barrier(CLK_LOCAL_MEM_FENCE);
    if (lid == 0)
        l_base = l_n ? atomic_add(nnext, l_n) : 0;
    barrier(CLK_LOCAL_MEM_FENCE);
    for (uint k = 0; k < na; k++)
        next[l_base + my + k] = add[k];
}

/* Initial active list: every slot, marked with the round. */
__kernel void p5_all(uint T, __global int *active, __global uint *inact, uint round)
{
    uint t = get_global_id(0);
    if (t >= T)
        return;
    active[t] = (int)t;
    inact[t] = round;
}

/* Initial active list from a list of triangles (the insertion path). */
__kernel void p5_from_list(__global const int *list, uint n, __global int *active,
                           __global uint *inact, uint round)
{
    uint g = get_global_id(0);
    if (g >= n)
        return;
    active[g] = list[g];
    inact[list[g]] = round;
}

/* flag[t] = 1 for the triangles marked for round (to rebuild a long active
 * list in index order, which keeps the next round's reads local). */
__kernel void p5_round_flags(__global const uint *inact, uint T, uint round,
                             __global uint *flag)
{
    uint t = get_global_id(0);
    if (t < T)
        flag[t] = inact[t] == round ? 1u : 0u;
}
