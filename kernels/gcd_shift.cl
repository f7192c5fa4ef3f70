/* gcd_shift.cl — Phase 3 of the gCD core: kept points move from their
 * texel corners back to their true positions (Algorithm 1 of Qi, Cao &
 * Tan), and the bad cases and the frame vertices are deleted in parallel
 * rounds of independent vertices (Algorithm 2).
 *
 * Shifting: a point is processed once every neighbour of smaller priority
 * (gcd_prio, a bijection, so no ties) was processed in an earlier round, so
 * no two neighbours move in the same round and every position read is
 * stable.  Moving p with its neighbours fixed keeps the triangulation valid
 * iff every triangle of its star stays strictly counter-clockwise (p stays
 * in the kernel of its link); otherwise p is a bad case.
 *
 * Deletion: every candidate marks its star triangles with atomic_min of its
 * priority; a candidate holding all its marks owns its star (winners are
 * pairwise non-adjacent) and re-triangulates the hole by ear clipping, in
 * its own star slots (k triangles become k - 2; two slots die and are kept
 * for the re-insertion of a bad case), with the two-phase link update of
 * kernels/gcd_tri.clh.
 * CPU references: the validity checks of tests/c/test_gcd_core.c after the
 * phase, and the reference triangulator for the final result. */
#include "gcd_tri.clh"

#define P3_MAX_DEGREE 1000000
/* Scratch fields per star entry of a deletion candidate. */
#define SC_STRI 0 /* star triangle (t << 2 | slot of p) */
#define SC_V 1    /* link vertex q (start of boundary edge q) */
#define SC_E 2    /* reference on the far side of polygon edge q */
#define SC_EO 3   /* old inner slot of edge q while E is an old outer reference, else -1 */
#define SC_NX 4   /* next remaining polygon vertex */
#define SC_PV 5   /* previous remaining polygon vertex */
#define SC_FIX 6  /* new slot that took boundary edge q (for the link phase) */
#define SC_N 8

/* Counters in stat[]. */
#define P3_SHIFTED 0
#define P3_BAD 1
#define P3_ERR 2
#define P3_ERRV 3

/* Algorithm 1, one round.  list: unprocessed kept points.  chk[v]: round in
 * which v was processed (0xffffffff: not yet). */
__kernel void p3_shift(__global const int *tri, __global const int *opp, __global int *pos,
                       __global const int *pts, __global const int *vt, int nreal, long cx,
                       long cy, __global const int *list, uint nl, __global uint *chk,
                       uint round, __global uint *bad, __global int *next,
                       __global uint *nnext, __global uint *stat)
{
    uint g = get_global_id(0);
    if (g >= nl)
        return;
    int p = list[g];
    uint pp = gcd_prio((uint)p);
    int t0 = vt[p], t = t0, k = gcd_slot_of(tri, t0, p);
    int deg = 0;
    /* every neighbour of smaller priority processed in an earlier round */
    do {
        int a = tri[3 * t + (k + 1) % 3];
        if (a < nreal && gcd_prio((uint)a) < pp && chk[a] >= round) {
            next[atomic_inc(nnext)] = p;
            return;
        }
        int nx = gcd_star_next(tri, opp, t, k);
        if (nx < 0 || ++deg > P3_MAX_DEGREE) {
            stat[P3_ERRV] = (uint)p;
            atomic_inc(&stat[P3_ERR]);
            return;
        }
        t = nx >> 2;
        k = nx & 3;
    } while (t != t0);
    gcd_spt q = gcd_spt_real((long)pts[2 * p], (long)pts[2 * p + 1], cx, cy);
    int good = 1;
    do {
        int a = tri[3 * t + (k + 1) % 3], b = tri[3 * t + (k + 2) % 3];
        if (gcd_orient(q, gcd_vpt(pos, a, nreal, cx, cy), gcd_vpt(pos, b, nreal, cx, cy)) <= 0) {
            good = 0;
            break;
        }
        int nx = gcd_star_next(tri, opp, t, k);
        t = nx >> 2;
        k = nx & 3;
    } while (t != t0);
    if (good) {
        pos[2 * p] = pts[2 * p];
        pos[2 * p + 1] = pts[2 * p + 1];
        atomic_inc(&stat[P3_SHIFTED]);
    } else {
        bad[p] = 1;
        atomic_inc(&stat[P3_BAD]);
    }
    chk[p] = round;
}

/* Bulk shifting before Algorithm 1: every kept point starts in the moving
 * set M (in[v] = 1).  A pass evaluates triangles with the points of M at
 * their true positions and the others where they are; a triangle that is
 * not strictly counter-clockwise drops its points from M (written to out[],
 * a copy of in[], so a pass does not depend on timing).  The first pass
 * evaluates every triangle, later ones only the stars of the points dropped
 * by the previous pass (listed once each: dropped[v] holds the pass).
 * When a pass drops nothing, moving all of M at once keeps every triangle
 * positively oriented, hence the triangulation valid; the points left out
 * go through Algorithm 1. */
inline void p3_bulk_eval(__global const int *tri, int t, __global const int *pos,
                         __global const int *pts, int nreal, long cx, long cy,
                         __global const uint *in, __global uint *out, __global uint *dropped,
                         uint pass, __global int *next, __global uint *nnext)
{
    gcd_spt s[3];
    int any = 0;
    for (int i = 0; i < 3; i++) {
        int v = tri[3 * t + i];
        if (v < nreal && in[v]) {
            s[i] = gcd_spt_real((long)pts[2 * v], (long)pts[2 * v + 1], cx, cy);
            any = 1;
        } else {
            s[i] = gcd_vpt(pos, v, nreal, cx, cy);
        }
    }
    if (!any || gcd_orient(s[0], s[1], s[2]) > 0)
        return;
    for (int i = 0; i < 3; i++) {
        int v = tri[3 * t + i];
        if (v < nreal && in[v]) {
            out[v] = 0;
            if (atomic_xchg(&dropped[v], pass) != pass)
                next[atomic_inc(nnext)] = v;
        }
    }
}

__kernel void p3_bulk_check(__global const int *tri, uint T, __global const int *pos,
                            __global const int *pts, int nreal, long cx, long cy,
                            __global const uint *in, __global uint *out,
                            __global uint *dropped, uint pass, __global int *next,
                            __global uint *nnext)
{
    uint t = get_global_id(0);
    if (t < T && tri[3 * t] >= 0)
        p3_bulk_eval(tri, (int)t, pos, pts, nreal, cx, cy, in, out, dropped, pass, next, nnext);
}

__kernel void p3_bulk_star(__global const int *tri, __global const int *opp,
                           __global const int *vt, __global const int *pos,
                           __global const int *pts, int nreal, long cx, long cy,
                           __global const uint *in, __global uint *out, __global uint *dropped,
                           uint pass, __global const int *list, uint nl, __global int *next,
                           __global uint *nnext)
{
    uint g = get_global_id(0);
    if (g >= nl)
        return;
    int p = list[g];
    int t0 = vt[p], t = t0, k = gcd_slot_of(tri, t0, p);
    do {
        p3_bulk_eval(tri, t, pos, pts, nreal, cx, cy, in, out, dropped, pass, next, nnext);
        int nx = gcd_star_next(tri, opp, t, k);
        if (nx < 0)
            return;
        t = nx >> 2;
        k = nx & 3;
    } while (t != t0);
}

/* Moves the points of M; flag[v] = 1 for a kept point left to Algorithm 1.
 * Kept points are the internal indices 0 .. kept-1. */
__kernel void p3_bulk_apply(__global int *pos, __global const int *pts, uint kept,
                            __global const uint *in, __global uint *chk, __global uint *flag,
                            __global uint *stat)
{
    uint v = get_global_id(0);
    if (v >= kept)
        return;
    if (in[v]) {
        pos[2 * v] = pts[2 * v];
        pos[2 * v + 1] = pts[2 * v + 1];
        chk[v] = 0;
        flag[v] = 0;
        atomic_inc(&stat[P3_SHIFTED]);
    } else {
        flag[v] = 1;
    }
}

/* Degree of every deletion candidate. */
__kernel void p3_del_deg(__global const int *tri, __global const int *opp,
                         __global const int *vt, __global const int *list, uint nl,
                         __global uint *deg, __global uint *stat)
{
    uint g = get_global_id(0);
    if (g >= nl)
        return;
    int p = list[g];
    int t0 = vt[p], t = t0, k = gcd_slot_of(tri, t0, p);
    uint d = 0;
    do {
        int nx = gcd_star_next(tri, opp, t, k);
        if (nx < 0 || ++d > P3_MAX_DEGREE) {
            stat[P3_ERRV] = (uint)p;
            atomic_inc(&stat[P3_ERR]);
            deg[g] = 0;
            return;
        }
        t = nx >> 2;
        k = nx & 3;
    } while (t != t0);
    deg[g] = d;
}

/* Records the star (scratch at off[g]) and marks its triangles. */
__kernel void p3_del_mark(__global const int *tri, __global const int *opp,
                          __global const int *vt, __global const int *list, uint nl,
                          __global const uint *off, __global int *sc, __global uint *mark)
{
    uint g = get_global_id(0);
    if (g >= nl)
        return;
    int p = list[g];
    uint pp = gcd_prio((uint)p);
    int t0 = vt[p], t = t0, k = gcd_slot_of(tri, t0, p);
    __global int *s = sc + SC_N * (size_t)off[g];
    int q = 0;
    do {
        s[SC_N * q + SC_STRI] = (t << 2) | k;
        s[SC_N * q + SC_V] = tri[3 * t + (k + 1) % 3];
        s[SC_N * q + SC_E] = opp[3 * t + k];
        s[SC_N * q + SC_EO] = (t << 2) | k;
        atomic_min(&mark[t], pp);
        int nx = gcd_star_next(tri, opp, t, k);
        t = nx >> 2;
        k = nx & 3;
        q++;
    } while (t != t0);
}

__kernel void p3_del_win(__global const int *list, uint nl, __global const uint *off,
                         __global const uint *deg, __global const int *sc,
                         __global const uint *mark, __global uint *win)
{
    uint g = get_global_id(0);
    if (g >= nl)
        return;
    uint pp = gcd_prio((uint)list[g]);
    __global const int *s = sc + SC_N * (size_t)off[g];
    uint w = deg[g] >= 3;
    for (uint q = 0; q < deg[g] && w; q++)
        w = mark[s[SC_N * q + SC_STRI] >> 2] == pp;
    win[g] = w;
}

/* Attaches polygon edge e of the hole (scratch s) to new slot (y, ys). */
inline void p3_attach(__global int *opp, __global int *exch, __global int *s, int e, int y,
                      int ys)
{
    int ref = s[SC_N * e + SC_E], old = s[SC_N * e + SC_EO];
    opp[3 * y + ys] = ref;
    if (old >= 0) {
        exch[3 * (old >> 2) + (old & 3)] = (y << 2) | ys;
        s[SC_N * e + SC_FIX] = (y << 2) | ys;
    } else if (ref >= 0) {
        opp[3 * (ref >> 2) + (ref & 3)] = (y << 2) | ys;
    }
}

/* Ear test for polygon vertex i (prev ip, next in) of the hole around p. */
inline int p3_is_ear(__global const int *pos, int nreal, long cx, long cy, __global int *s,
                     gcd_spt pp, int ip, int i, int in, int general)
{
    gcd_spt a = gcd_vpt(pos, s[SC_N * ip + SC_V], nreal, cx, cy);
    gcd_spt b = gcd_vpt(pos, s[SC_N * i + SC_V], nreal, cx, cy);
    gcd_spt c = gcd_vpt(pos, s[SC_N * in + SC_V], nreal, cx, cy);
    if (gcd_orient(a, b, c) <= 0)
        return 0;
    if (!general)
        return gcd_orient(a, c, pp) >= 0;
    /* no other remaining vertex in the closed triangle */
    for (int q = s[SC_N * in + SC_NX]; q != ip; q = s[SC_N * q + SC_NX]) {
        gcd_spt x = gcd_vpt(pos, s[SC_N * q + SC_V], nreal, cx, cy);
        if (gcd_orient(a, b, x) >= 0 && gcd_orient(b, c, x) >= 0 && gcd_orient(c, a, x) >= 0)
            return 0;
    }
    return 1;
}

/* Phase A of the deletions: winners re-triangulate their holes. */
__kernel void p3_del_apply(__global int *tri, __global int *opp, __global const int *pos,
                           int nreal, long cx, long cy, __global const int *list, uint nl,
                           __global const uint *off, __global const uint *deg,
                           __global const uint *win, __global int *sc, __global int *exch,
                           __global uint *modified, uint round, __global int *vt,
                           __global int *rslot, __global int *newl, __global uint *nnew,
                           __global uint *stat)
{
    uint g = get_global_id(0);
    if (g >= nl || !win[g])
        return;
    int p = list[g], m = (int)deg[g];
    __global int *s = sc + SC_N * (size_t)off[g];
    gcd_spt pp = gcd_vpt(pos, p, nreal, cx, cy);
    int used = 0;
    for (int q = 0; q < m; q++) {
        s[SC_N * q + SC_NX] = (q + 1) % m;
        s[SC_N * q + SC_PV] = (q + m - 1) % m;
        modified[s[SC_N * q + SC_STRI] >> 2] = round;
    }
    int cur = 0, left = m;
    while (left > 3) {
        int found = -1;
        for (int general = 0; general < 2 && found < 0; general++) {
            int i = cur;
            for (int tries = 0; tries < left; tries++, i = s[SC_N * i + SC_NX]) {
                int ip = s[SC_N * i + SC_PV], in = s[SC_N * i + SC_NX];
                if (p3_is_ear(pos, nreal, cx, cy, s, pp, ip, i, in, general)) {
                    found = i;
                    break;
                }
            }
        }
        if (found < 0) {
            stat[P3_ERRV] = (uint)p;
            atomic_inc(&stat[P3_ERR]);
            return;
        }
        int i = found, ip = s[SC_N * i + SC_PV], in = s[SC_N * i + SC_NX];
        int y = s[SC_N * (used++) + SC_STRI] >> 2;
        tri[3 * y] = s[SC_N * ip + SC_V];
        tri[3 * y + 1] = s[SC_N * i + SC_V];
        tri[3 * y + 2] = s[SC_N * in + SC_V];
        p3_attach(opp, exch, s, i, y, 0);
        p3_attach(opp, exch, s, ip, y, 2);
        /* the new diagonal in -> ip becomes polygon edge ip */
        s[SC_N * ip + SC_E] = (y << 2) | 1;
        s[SC_N * ip + SC_EO] = -1;
        s[SC_N * ip + SC_NX] = in;
        s[SC_N * in + SC_PV] = ip;
        newl[atomic_inc(nnew)] = y;
        cur = ip;
        left--;
    }
    {
        int i0 = cur, i1 = s[SC_N * i0 + SC_NX], i2 = s[SC_N * i1 + SC_NX];
        int y = s[SC_N * (used++) + SC_STRI] >> 2;
        tri[3 * y] = s[SC_N * i0 + SC_V];
        tri[3 * y + 1] = s[SC_N * i1 + SC_V];
        tri[3 * y + 2] = s[SC_N * i2 + SC_V];
        if (gcd_orient(gcd_vpt(pos, tri[3 * y], nreal, cx, cy),
                       gcd_vpt(pos, tri[3 * y + 1], nreal, cx, cy),
                       gcd_vpt(pos, tri[3 * y + 2], nreal, cx, cy)) <= 0) {
            stat[P3_ERRV] = (uint)p;
            atomic_inc(&stat[P3_ERR]);
        }
        p3_attach(opp, exch, s, i1, y, 0);
        p3_attach(opp, exch, s, i2, y, 1);
        p3_attach(opp, exch, s, i0, y, 2);
        newl[atomic_inc(nnew)] = y;
    }
    for (int q = used; q < m; q++)
        tri[3 * (s[SC_N * q + SC_STRI] >> 2)] = -1;
    /* p leaves the triangulation; its entry now names one of its former
     * neighbours (encoded -2 - q), where its re-insertion walk starts (a
     * real one if there is one: a walk from a fake, far away, is long),
     * and a bad case is re-inserted into the two slots it freed. */
    int nbv = s[SC_V];
    for (int q = 0; q < m && nbv >= nreal; q++)
        nbv = s[SC_N * q + SC_V] < nreal ? s[SC_N * q + SC_V] : nbv;
    vt[p] = -2 - nbv;
    if (p < nreal) {
        rslot[2 * p] = s[SC_N * used + SC_STRI] >> 2;
        rslot[2 * p + 1] = s[SC_N * (used + 1) + SC_STRI] >> 2;
    }
}

/* Phase B of the deletions. */
__kernel void p3_del_link(__global int *opp, __global const int *exch,
                          __global const uint *modified, uint round, uint nl,
                          __global const uint *off, __global const uint *deg,
                          __global const uint *win, __global const int *sc)
{
    uint g = get_global_id(0);
    if (g >= nl || !win[g])
        return;
    __global const int *s = sc + SC_N * (size_t)off[g];
    for (uint q = 0; q < deg[g]; q++) {
        int f = s[SC_N * q + SC_FIX];
        gcd_link_fix(opp, exch, modified, round, f >> 2, f & 3);
    }
}

/* Clears the marks of every candidate and lists the losers. */
__kernel void p3_del_next(__global const int *list, uint nl, __global const uint *off,
                          __global const uint *deg, __global const uint *win,
                          __global const int *sc, __global uint *mark, __global int *next,
                          __global uint *nnext)
{
    uint g = get_global_id(0);
    if (g >= nl)
        return;
    __global const int *s = sc + SC_N * (size_t)off[g];
    for (uint q = 0; q < deg[g]; q++)
        mark[s[SC_N * q + SC_STRI] >> 2] = GCD_EMPTY;
    if (!win[g])
        next[atomic_inc(nnext)] = list[g];
}

/* Vertices to delete: bad kept points and every frame vertex. */
__kernel void p3_del_flags(__global const uint *bad, uint n, uint frame_base, uint nv,
                           __global uint *flag)
{
    uint v = get_global_id(0);
    if (v < nv)
        flag[v] = (v < n && bad[v]) || v >= frame_base ? 1u : 0u;
}
