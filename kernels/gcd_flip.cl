/* gcd_flip.cl — Phase 5 of the gCD core: Lawson flipping to T_{d1,d2}
 * (and the shared flip machinery of the insertion path).
 *
 * On CPU devices Phase 5 starts with block-local sequential passes
 * (p5_local, p5_local_lists: see "block-local Lawson flipping" below);
 * the parallel rounds then finish from the slots they left.
 *
 * One parallel round:
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

/* Appends a candidate; past ccap entries it is only counted (the host
 * reports the overflow). */
inline void p5_candidate(__global uint *vote, __global int *cand, __global uint *ncand,
                         uint ccap, int t, int i, int u, int j)
{
    int e = (t << 2) | i, f = (u << 2) | j;
    uint prio = gcd_prio((uint)(e < f ? e : f));
    p5_vote(vote, t, u, prio);
    uint k = atomic_inc(ncand);
    if (k >= ccap)
        return;
    cand[2 * k] = e;
    cand[2 * k + 1] = f;
}

/* active[0..na): triangles to check; inact[t] == round marks them.
 * List appends and counters are aggregated per work-group in local memory
 * (one global atomic per group and list), so the lists' order depends on
 * scheduling but their content does not.  Each edge is tested once (from
 * its smaller slot when both are active), so a list of distinct triangles
 * gives at most 3 na / 2 entries in all; entries past ccap (cand) or xcap
 * (exact) are only counted, for the host to report. */
__kernel void p5_check(__global const int *tri, __global const int *opp,
                       __global const int *pos, int nreal, long cx, long cy,
                       __global const int *active, uint na, __global const uint *inact,
                       uint round, uint all_active, __global uint *vote, __global int *cand,
                       __global uint *ncand, __global int *exact, __global uint *nexact,
                       __global uint *stat, uint ccap, uint xcap)
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
            int flip = 0, undecided = 1;
#if defined(GDT_X_HAVE_F64)
            int d = tri[3 * u + j];
            if (!tfake && !gcd_is_fake(d, nreal)) {
                /* edge a-b of the counter-clockwise (a, b, c) and (b, a, d) */
                int i1 = i == 2 ? 0 : i + 1, i2 = i == 0 ? 2 : i - 1;
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
    for (uint k = 0; k < nc && l_bc + myc + k < ccap; k++) {
        cand[2 * (l_bc + myc + k)] = ce[k];
        cand[2 * (l_bc + myc + k) + 1] = cf[k];
    }
    for (uint k = 0; k < nx && l_bx + myx + k < xcap; k++)
        exact[l_bx + myx + k] = xe[k];
}

/* The quads the filter left undecided (or that hold a fake). */
__kernel void p5_exact(__global const int *tri, __global const int *opp,
                       __global const int *pos, int nreal, long cx, long cy,
                       __global const int *exact, uint nx, __global uint *vote,
                       __global int *cand, __global uint *ncand, __global uint *stat,
                       uint ccap)
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
        p5_candidate(vote, cand, ncand, ccap, t, i, u, j);
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

/* ---- block-local Lawson flipping (CPU devices) ----
 * A work-item owns a range [lo, lo + span) of triangle slots and runs the
 * sequential Lawson algorithm inside it: edges wait in a private FIFO
 * queue (first in, first out, like the parallel rounds: on sets of many
 * co-circular points a depth-first order can take many more flips), and a
 * flip appends its four outer edges.
 *
 * Ownership (why no two work-items ever touch the same slot): a slot whose
 * neighbour lies outside the range is frozen — never rewritten.  A flip of
 * t and u needs both in the range and their four outer neighbours in the
 * range (or absent), so it reads and writes only slots of the range; the
 * new triangles again have only neighbours in the range, so the set of
 * frozen slots does not change while the kernel runs, and an edge between
 * two ranges (two frozen slots) is never read by either side.
 *
 * Deferred slots (inact[t] = round, listed once): a slot with an edge out
 * of the range (not tested here), both slots of an edge that must flip
 * when the flip is not allowed here (a frozen slot, or a full queue), and
 * every slot whose edges are still waiting when the work-item has spent
 * its budget of tests (a bound on the time of one work-item).  An edge
 * that is tested and not deferred is locally optimal until its quad
 * changes again; a flip changes the quads of exactly its four outer edges,
 * which it queues, and of its new diagonal, which is locally optimal by
 * construction (the lifted determinant of the flipped quad is that of the
 * old one with an odd permutation of the rows, and both tie-breaks are
 * antisymmetric).  So every edge is locally optimal at the end unless one
 * of its slots is deferred.
 *
 * Passes: p5_local over blocks of bsize slots tests every edge; then
 * p5_local_lists over the blocks shifted by half a block takes the slots
 * the first pass deferred (mostly near a block boundary, now mid-range)
 * and tests all their edges, and so on, alternating the two partitions,
 * while the deferred slots become fewer (a flip wave through co-circular
 * points crosses half a block per pass).  What the last pass defers starts
 * the parallel rounds (p5_check ...), which end at T_{d1,d2} as from a
 * full start.  Slots are visited in a fixed order, so the result is
 * deterministic. */
#define P5_IN(x) ((uint)(x) - lo < span)

/* gcd_flip_code for a quad with a fake vertex, or one the double filter
 * left undecided: 1 to flip; *exact and *tie count its escalations. */
inline int p5_exact_test(__global const int *pos, int nreal, long cx, long cy, int a, int b,
                         int c, int d, uint *exact, uint *tie)
{
    unsigned code = gcd_flip_code(p5_pt(pos, a, nreal, cx, cy), p5_pt(pos, b, nreal, cx, cy),
                                  p5_pt(pos, c, nreal, cx, cy), p5_pt(pos, d, nreal, cx, cy),
                                  a, b, c, d);
    *exact += (code & GDT_X_USED_EXACT) != 0;
    *tie += (code & GDT_X_USED_TIEBREAK) != 0;
    return (code & GDT_X_FLIP) != 0;
}

/* lists = 0 (the first pass): work-item b owns block [b bsize,
 * (b+1) bsize) of the T slots and tests each edge between two of its live
 * slots once (from the slot of smaller index when the scan reaches it,
 * unless a flip queued it before).
 * lists = 1 (a later pass): work-item b owns block b of the shifted
 * (shift = 1) or unshifted partition (p5_range), which overlaps two blocks
 * of the other partition, used by the previous pass; it takes the slots
 * those blocks deferred in its range (still marked round_in: in_list at
 * the start of their block, in_count per block) and tests all their edges.
 * Every pass writes its deferred slots (marked round) to out_list[lo ...]
 * and their number to out_count[b]; a later pass also appends them to
 * all[] (count *nall).  queue: qcap edges per work-item (a power of two);
 * budget: tests per slot of the range. */
/* Range of block b of the unshifted (blocks [b bsize, (b+1) bsize)) or
 * the shifted (blocks [b bsize - bsize/2, b bsize + bsize/2)) partition of
 * [0, T); 0 if empty. */
inline int p5_range(uint b, uint T, uint bsize, uint shifted, uint *lo, uint *hi)
{
    uint nb = (T + bsize - 1) / bsize;
    if (shifted) {
        if (b > nb)
            return 0;
        *lo = b == 0 ? 0 : b * bsize - bsize / 2;
        *hi = b * bsize + bsize / 2 < T ? b * bsize + bsize / 2 : T;
    } else {
        if (b >= nb)
            return 0;
        *lo = b * bsize;
        *hi = *lo + bsize < T ? *lo + bsize : T;
    }
    return *lo < *hi;
}

/* One work-item of a pass over [lo, lo + span), queue qe, at most left
 * tests.  lists = 0: scan the range.  lists = 1: the candidates are the
 * slots the previous pass deferred in blocks kfirst..klast of its
 * partition (in_shift), in block order. */
inline void p5_local_run(__global int *tri, __global int *opp, __global const int *pos,
                         int nreal, long cx, long cy, uint lo, uint span, const uint lists,
                         uint T, uint bsize, uint in_shift, uint kfirst, uint klast,
                         __global int *qe, uint qcap, uint left, __global uint *inact,
                         uint round_in, uint round, __global const int *in_list,
                         __global const uint *in_count, __global int *lst, uint *ndeferred,
                         __global uint *stat)
{
    uint qmask = qcap - 1, head = 0, tail = 0, nd = 0;
    uint tested = 0, nexact = 0, tie = 0, flips = 0;
    /* the source of fresh edges: slot (or candidate) gs, its edge gi; in
     * lists mode, candidate gs of the list cur (ncur entries) of block k */
    uint gs = 0, gi = 0, k = kfirst, ncur = 0;
    __global const int *cur = in_list;
    if (lists) {
        uint ilo, ihi;
        if (k <= klast && p5_range(k, T, bsize, in_shift, &ilo, &ihi)) {
            cur = in_list + ilo;
            ncur = in_count[k];
        }
    }
    for (;;) {
        int e = -1;
        if (head != tail) {
            e = qe[head++ & qmask];
        } else if (!lists) {
            while (gs < span) {
                int t0 = (int)(lo + gs);
                if (gi == 3 || (gi == 0 && tri[3 * t0] < 0)) {
                    gs++;
                    gi = 0;
                    continue;
                }
                int o0 = opp[3 * t0 + gi], i0 = (int)gi++;
                if (o0 < 0 || (P5_IN(o0 >> 2) && (o0 >> 2) < t0))
                    continue; /* no neighbour, or tested from the other side */
                e = (t0 << 2) | i0;
                break;
            }
        } else {
            while (k <= klast) {
                if (gs >= ncur) {
                    uint ilo, ihi;
                    k++;
                    gs = gi = ncur = 0;
                    if (k <= klast && p5_range(k, T, bsize, in_shift, &ilo, &ihi)) {
                        cur = in_list + ilo;
                        ncur = in_count[k];
                    }
                    continue;
                }
                int t0 = cur[gs];
                if (gi == 3 ||
                    (gi == 0 && (!P5_IN(t0) || inact[t0] != round_in || tri[3 * t0] < 0))) {
                    gs++;
                    gi = 0;
                    continue;
                }
                e = (t0 << 2) | (int)gi++;
                break;
            }
        }
        if (e < 0)
            break;
        int t = e >> 2, i = e & 3;
        int o = opp[3 * t + i];
        if (o < 0)
            continue;
        int u = o >> 2, j = o & 3;
        if (!P5_IN(u) || left == 0) {
            if (inact[t] != round) {
                inact[t] = round;
                lst[nd++] = t;
            }
            continue;
        }
        left--;
        tested++;
        int i1 = i == 2 ? 0 : i + 1, i2 = i == 0 ? 2 : i - 1;
        int j1 = j == 2 ? 0 : j + 1, j2 = j == 0 ? 2 : j - 1;
        int c = tri[3 * t + i], a = tri[3 * t + i1], bb = tri[3 * t + i2];
        int d = tri[3 * u + j];
        int flip;
#if defined(GDT_X_HAVE_F64)
        /* in Phase 5 a vertex index >= nreal is a fake */
        if (max(max(a, bb), max(c, d)) < nreal) {
            long ax = pos[2 * a], ay = pos[2 * a + 1], bx = pos[2 * bb], by = pos[2 * bb + 1];
            long qx = pos[2 * c], qy = pos[2 * c + 1], dx = pos[2 * d], dy = pos[2 * d + 1];
            int sg = gdt_x_incircle_filter_d(ax - dx, ay - dy, bx - dx, by - dy, qx - dx,
                                             qy - dy);
            if (sg == 1) {
                flip = 1;
            } else if (sg == -1) {
                flip = 0;
            } else if (sg == 0) {
                flip = 0;
                if (gdt_x_orient2d(dx, dy, bx, by, qx, qy) > 0 &&
                    gdt_x_orient2d(qx, qy, ax, ay, dx, dy) > 0) {
                    tie++;
                    flip = gdt_x_prefer_diagonal(dx - qx, dy - qy, bx - ax, by - ay) > 0;
                }
            } else {
                flip = p5_exact_test(pos, nreal, cx, cy, a, bb, c, d, &nexact, &tie);
            }
        } else
#endif
            flip = p5_exact_test(pos, nreal, cx, cy, a, bb, c, d, &nexact, &tie);
        if (!flip)
            continue;
        int na = opp[3 * t + i1], nb2 = opp[3 * t + i2];
        int mb = opp[3 * u + j1], ma = opp[3 * u + j2];
        if ((na >= 0 && !P5_IN(na >> 2)) || (nb2 >= 0 && !P5_IN(nb2 >> 2)) ||
            (ma >= 0 && !P5_IN(ma >> 2)) || (mb >= 0 && !P5_IN(mb >> 2)) ||
            tail - head + 4 > qcap) {
            if (inact[t] != round) {
                inact[t] = round;
                lst[nd++] = t;
            }
            if (inact[u] != round) {
                inact[u] = round;
                lst[nd++] = u;
            }
            continue;
        }
        tri[3 * t] = c, tri[3 * t + 1] = a, tri[3 * t + 2] = d;
        tri[3 * u] = c, tri[3 * u + 1] = d, tri[3 * u + 2] = bb;
        opp[3 * t] = mb, opp[3 * t + 1] = (u << 2) | 2, opp[3 * t + 2] = nb2;
        opp[3 * u] = ma, opp[3 * u + 1] = na, opp[3 * u + 2] = (t << 2) | 1;
        if (mb >= 0)
            opp[3 * (mb >> 2) + (mb & 3)] = (t << 2) | 0;
        if (nb2 >= 0)
            opp[3 * (nb2 >> 2) + (nb2 & 3)] = (t << 2) | 2;
        if (ma >= 0)
            opp[3 * (ma >> 2) + (ma & 3)] = (u << 2) | 0;
        if (na >= 0)
            opp[3 * (na >> 2) + (na & 3)] = (u << 2) | 1;
        flips++;
        qe[tail++ & qmask] = (t << 2) | 0;
        qe[tail++ & qmask] = (t << 2) | 2;
        qe[tail++ & qmask] = (u << 2) | 0;
        qe[tail++ & qmask] = (u << 2) | 1;
    }
    *ndeferred = nd;
    if (tested)
        atomic_add(&stat[P5_TESTED], tested);
    if (nexact)
        atomic_add(&stat[P5_EXACT], nexact);
    if (tie)
        atomic_add(&stat[P5_TIEBREAK], tie);
    if (flips)
        atomic_add(&stat[P5_FLIPS], flips);
}

/* Tests allowed for n slots or candidates: budget each, and some to spare. */
inline uint p5_budget(uint budget, uint n)
{
    ulong b = (ulong)budget * n + 65536;
    return b < 0xffffffffUL ? (uint)b : 0xffffffffu;
}

/* Appends list[0..n) to all[] (count *nall). */
inline void p5_append(__global const int *list, uint n, __global int *all, __global uint *nall)
{
    if (n > 0) {
        uint base = atomic_add(nall, n);
        for (uint r = 0; r < n; r++)
            all[base + r] = list[r];
    }
}

/* The first pass (partition: unshifted). */
__kernel void p5_local(__global int *tri, __global int *opp, __global const int *pos, int nreal,
                       long cx, long cy, uint T, uint bsize, __global int *queue, uint qcap,
                       uint budget, __global uint *inact, uint round,
                       __global int *out_list, __global uint *out_count, __global uint *stat)
{
    uint b = get_global_id(0), lo, hi, nd = 0;
    if (!p5_range(b, T, bsize, 0, &lo, &hi))
        return;
    p5_local_run(tri, opp, pos, nreal, cx, cy, lo, hi - lo, 0, T, bsize, 0, 0, 0,
                 queue + (size_t)b * qcap, qcap, p5_budget(budget, hi - lo), inact, round, round,
                 out_list, out_count, out_list + lo, &nd, stat);
    out_count[b] = nd;
}

/* A later pass over the deferred slots of the previous one (in_list and
 * in_count, partition !shift).  whole = 0: work-item b owns block b of
 * partition shift and takes the two blocks of the previous partition that
 * overlap it.  whole = 1: one work-item owns every slot and takes every
 * block (the long chains of flips the blocks cut).  The deferred slots go
 * to out_list / out_count per block and are appended to all[]. */
__kernel void p5_local_lists(__global int *tri, __global int *opp, __global const int *pos,
                             int nreal, long cx, long cy, uint T, uint bsize, uint shift,
                             uint whole, __global int *queue, uint qcap, uint budget,
                             __global uint *inact, uint round_in, uint round,
                             __global const int *in_list, __global const uint *in_count,
                             __global int *out_list, __global uint *out_count,
                             __global int *all, __global uint *nall, __global uint *stat)
{
    uint b = get_global_id(0), lo, hi, nd = 0;
    uint nb = (T + bsize - 1) / bsize;
    if (whole) {
        /* budget tests per candidate (and some to spare) */
        uint klast = shift ? nb - 1 : nb, ncand = 0;
        if (b > 0)
            return;
        for (uint k = 0; k <= klast; k++)
            ncand += in_count[k];
        p5_local_run(tri, opp, pos, nreal, cx, cy, 0, T, 1, T, bsize, !shift, 0, klast, queue,
                     qcap, p5_budget(budget, ncand), inact, round_in, round, in_list, in_count,
                     out_list, &nd, stat);
        out_count[0] = nd;
        p5_append(out_list, nd, all, nall);
        return;
    }
    if (!p5_range(b, T, bsize, shift, &lo, &hi))
        return;
    /* the blocks of the other partition overlapping this one */
    uint ka = shift ? b - 1 : b;
    p5_local_run(tri, opp, pos, nreal, cx, cy, lo, hi - lo, 1, T, bsize, !shift,
                 shift && b == 0 ? 0 : ka, ka + 1, queue + (size_t)b * qcap, qcap,
                 p5_budget(budget, hi - lo), inact, round_in, round, in_list, in_count,
                 out_list + lo, &nd, stat);
    out_count[b] = nd;
    p5_append(out_list + lo, nd, all, nall);
}
