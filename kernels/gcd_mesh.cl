/* gcd_mesh.cl — triangle-list kernels shared by the phases of the gCD core.
 *
 * Layout (core/gdt_mesh.h): triangle t has vertices tri[3t..3t+2]; slot i
 * faces the edge tri[3t+(i+1)%3] -> tri[3t+(i+2)%3]; opp[3t+i] is
 * (u << 2 | j) for the neighbour u across it (its slot j), or -1.  A dead
 * slot has tri[3t] = -1.  vt[v] is one live triangle incident to vertex v.
 * CPU references: gdt_mesh_link (core/mesh.c) for the links, and the
 * checks of tests/c/test_gcd_phase2.c for the rest. */
#include "gcd_geom.clh"

/* Over the slots [from, T): cnt[v] += number of live triangles incident to
 * v (cnt preset to 0, or already counted for the slots before from). */
__kernel void m_vcount(__global const int *tri, uint from, uint T, __global uint *cnt)
{
    uint t = from + get_global_id(0);
    if (t >= T || tri[3 * t] < 0)
        return;
    for (int i = 0; i < 3; i++)
        atomic_inc(&cnt[tri[3 * t + i]]);
}

/* Vertex arrays: off[v] is the exclusive scan of the counts; v's corners
 * (t << 2 | slot of v in t) go to list[off[v] ...] in arbitrary order, and
 * pred[] receives the vertex before v in t.  off[v] is counted up to the
 * end of v's entries, i.e. the start of v + 1's. */
__kernel void m_vfill(__global const int *tri, uint T, __global uint *off, __global int *list,
                      __global int *pred)
{
    uint t = get_global_id(0);
    if (t >= T || tri[3 * t] < 0)
        return;
    for (int i = 0; i < 3; i++) {
        int v = tri[3 * t + i];
        uint k = atomic_inc(&off[v]);
        list[k] = ((int)t << 2) | i;
        pred[k] = tri[3 * t + (i + 2) % 3];
    }
}

/* vt[v] = the smallest live triangle incident to v, 0xffffffff for none,
 * from the vertex arrays (end[v] as for m_link): one sequential read of
 * v's entries instead of an atomic per corner while counting. */
__kernel void m_vt_min(__global const uint *end, __global const int *list, uint nv,
                       __global uint *vt)
{
    uint v = get_global_id(0);
    if (v >= nv)
        return;
    uint lo = v > 0 ? end[v - 1] : 0, hi = end[v], m = 0xffffffffu;
    for (uint k = lo; k < hi; k++)
        m = min(m, (uint)list[k] >> 2);
    vt[v] = m;
}

/* Neighbour links from the vertex arrays (end[v]: off after m_vfill, so
 * v's entries are [end[v-1], end[v])): the triangle across edge a -> b of
 * t is the one of a's corners whose predecessor of a is b (it traverses
 * b -> a, opposite the slot after a's).  Each interior edge is searched
 * once, by the side with a < b, which sets both links; opp must be preset
 * to -1 (hull edges keep it).  The result does not depend on the order of
 * the vertex arrays. */
__kernel void m_link(__global const int *tri, uint T, __global const uint *end,
                     __global const int *list, __global const int *pred, __global int *opp)
{
    uint t = get_global_id(0);
    if (t >= T || tri[3 * t] < 0)
        return;
    for (int i = 0; i < 3; i++) {
        int a = tri[3 * t + (i + 1) % 3], b = tri[3 * t + (i + 2) % 3];
        if (a > b)
            continue;
        uint lo = a > 0 ? end[a - 1] : 0, hi = end[a];
        for (uint k = lo; k < hi; k++) {
            if (pred[k] == b) {
                int u = list[k] >> 2, j = ((list[k] & 3) + 1) % 3;
                opp[3 * t + i] = (u << 2) | j;
                opp[3 * u + j] = ((int)t << 2) | i;
                break;
            }
        }
    }
}

/* Current positions: the texel corner for a point that owns its texel,
 * the true position otherwise. */
__kernel void m_snap(__global const int *pts, __global const uint *texel,
                     __global const uint *seed, uint n, int xmin, int ymin, int cell,
                     __global int *pos)
{
    uint i = get_global_id(0);
    if (i >= n)
        return;
    int x = pts[2 * i], y = pts[2 * i + 1];
    if (seed[texel[i]] == i) {
        x = xmin + (x - xmin) / cell * cell;
        y = ymin + (y - ymin) / cell * cell;
    }
    pos[2 * i] = x;
    pos[2 * i + 1] = y;
}

/* Frame vertex positions: the corner of their texel. */
__kernel void m_frame_pos(uint W, uint H, int xmin, int ymin, int cell, uint base,
                          __global int *pos)
{
    uint k = get_global_id(0);
    if (k >= gcd_frame_count(W, H))
        return;
    uint t = gcd_frame_texel(k, W, H);
    pos[2 * (base + k)] = xmin + (int)(t % W) * cell;
    pos[2 * (base + k) + 1] = ymin + (int)(t / W) * cell;
}

/* flag[t] = 1 for a live triangle whose three vertices are real (< nreal). */
__kernel void m_real_flags(__global const int *tri, uint T, int nreal, __global uint *flag)
{
    uint t = get_global_id(0);
    if (t >= T)
        return;
    flag[t] = (tri[3 * t] >= 0 && tri[3 * t] < nreal && tri[3 * t + 1] < nreal &&
               tri[3 * t + 2] < nreal)
                  ? 1u
                  : 0u;
}

/* Compaction of the triangle list by a scanned flag array pos (exclusive
 * sums; total = kept count): kept triangle t moves to pos[t] with its
 * vertices renumbered by map (internal to input indices); links to dropped
 * triangles become -1.  Out-of-place (ntri/nopp). */
__kernel void m_compact_tris(__global const int *tri, __global const int *opp, uint T,
                             __global const uint *pos, uint total,
                             __global const uint *map, __global int *ntri, __global int *nopp)
{
    uint t = get_global_id(0);
    if (t >= T)
        return;
    uint next = t + 1 < T ? pos[t + 1] : total;
    if (next == pos[t])
        return;
    uint d = pos[t];
    for (int i = 0; i < 3; i++) {
        ntri[3 * d + i] = (int)map[tri[3 * t + i]];
        int o = opp[3 * t + i];
        if (o >= 0) {
            uint u = (uint)o >> 2;
            uint un = u + 1 < T ? pos[u + 1] : total;
            o = un != pos[u] ? (int)((pos[u] << 2) | ((uint)o & 3u)) : GCD_NONE;
        }
        nopp[3 * d + i] = o;
    }
}

/* Vertices of the triangles written this round (listed in tl[0..m)) whose
 * vt entry no longer names a live triangle holding them: vnew[v] takes the
 * smallest such triangle (vnew preset to 0xffffffff). */
__kernel void m_fix_vt_collect(__global const int *tri, __global const int *tl, uint m,
                               __global const int *vt, __global uint *vnew)
{
    uint i = get_global_id(0);
    if (i >= m)
        return;
    int t = tl[i];
    for (int k = 0; k < 3; k++) {
        int v = tri[3 * t + k];
        int old = vt[v];
        int ok = old >= 0 && tri[3 * old] >= 0 &&
                 (tri[3 * old] == v || tri[3 * old + 1] == v || tri[3 * old + 2] == v);
        if (!ok)
            atomic_min(&vnew[v], (uint)t);
    }
}

__kernel void m_fix_vt_apply(__global const int *tri, __global const int *tl, uint m,
                             __global int *vt, __global uint *vnew)
{
    uint i = get_global_id(0);
    if (i >= m)
        return;
    int t = tl[i];
    for (int k = 0; k < 3; k++) {
        int v = tri[3 * t + k];
        uint nv = vnew[v];
        if (nv != GCD_EMPTY) {
            vt[v] = (int)nv;
            vnew[v] = GCD_EMPTY;
        }
    }
}

/* Reserved slots appended after the triangles in use: points first + j
 * (j < m) get the dead slots base + 2j and base + 2j + 1 (a grid without
 * corners, and the insertion path). */
__kernel void m_slots_seq(uint first, uint m, uint base, __global int *tri, __global int *rslot)
{
    uint j = get_global_id(0);
    if (j >= m)
        return;
    size_t s = (size_t)base + 2 * (size_t)j;
    for (int q = 0; q < 6; q++)
        tri[3 * s + q] = GCD_NONE;
    rslot[2 * ((size_t)first + j)] = (int)s;
    rslot[2 * ((size_t)first + j) + 1] = (int)s + 1;
}

/* ---- spatial re-ordering of the triangle list ----
 * Triangles are sorted by their smallest vertex (vertex indices follow the
 * texels, so this groups neighbours in memory), ties by old index: a
 * counting sort (m_sort_count, scan, m_sort_scatter), each bucket then put
 * in old-index order (m_sort_bucket), and the list rewritten with every
 * link renumbered (m_sort_inverse, m_sort_apply).  The order is a pure
 * function of the triangle list. */
inline int m_min3(__global const int *tri, uint t)
{
    int a = tri[3 * t], b = tri[3 * t + 1], c = tri[3 * t + 2];
    int m = a < b ? a : b;
    return m < c ? m : c;
}

__kernel void m_sort_count(__global const int *tri, uint T, __global uint *cnt)
{
    uint t = get_global_id(0);
    if (t < T && tri[3 * t] >= 0)
        atomic_inc(&cnt[m_min3(tri, t)]);
}

__kernel void m_sort_scatter(__global const int *tri, uint T, __global const uint *off,
                             __global uint *fill, __global int *order)
{
    uint t = get_global_id(0);
    if (t >= T || tri[3 * t] < 0)
        return;
    int k = m_min3(tri, t);
    order[off[k] + atomic_inc(&fill[k])] = (int)t;
}

/* fill[v] = cnt[v] after m_sort_scatter. */
__kernel void m_sort_bucket(__global const uint *off, __global const uint *cnt, uint nv,
                            __global int *order)
{
    uint v = get_global_id(0);
    if (v >= nv)
        return;
    uint lo = off[v], n = cnt[v];
    for (uint i = 1; i < n; i++) {
        int x = order[lo + i];
        uint j = i;
        while (j > 0 && order[lo + j - 1] > x) {
            order[lo + j] = order[lo + j - 1];
            j--;
        }
        order[lo + j] = x;
    }
}

__kernel void m_sort_inverse(__global const int *order, uint n, __global int *newidx)
{
    uint k = get_global_id(0);
    if (k < n)
        newidx[order[k]] = (int)k;
}

__kernel void m_sort_apply(__global const int *tri, __global const int *opp,
                           __global const int *order, __global const int *newidx, uint n,
                           __global int *ntri, __global int *nopp)
{
    uint k = get_global_id(0);
    if (k >= n)
        return;
    int t = order[k];
    for (int i = 0; i < 3; i++) {
        ntri[3 * k + i] = tri[3 * t + i];
        int o = opp[3 * t + i];
        nopp[3 * k + i] = o >= 0 ? ((newidx[o >> 2] << 2) | (o & 3)) : o;
    }
}

/* vt entries follow the permutation (deleted vertices keep their code). */
__kernel void m_sort_vt(__global int *vt, uint nv, __global const int *newidx, uint T)
{
    uint v = get_global_id(0);
    if (v < nv && vt[v] >= 0 && (uint)vt[v] < T)
        vt[v] = newidx[vt[v]];
}
