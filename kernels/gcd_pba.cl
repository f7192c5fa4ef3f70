/* gcd_pba.cl — Phase 1 of the gCD core: the exact digital Voronoi diagram
 * of the tile's W x H texel grid by the Parallel Banding Algorithm, and the
 * debris detection of Algorithm A.1.
 *
 * Grid: texel (x, y), 0 <= x < W, 0 <= y < H, stored row-major at y*W + x.
 * A site is a texel holding a kept point; a texel's colour is the texel
 * index of its site.
 *
 * The fixed tie rule (one total order on (texel A, site S) pairs, consistent
 * with Euclidean distance):
 *     key(A, S) = (|A - S|^2, S.x, S.y, index(A)).
 * For one texel the Euclidean colouring picks the site of least key: nearest,
 * then smallest column, then smallest row.  This is the order the banding
 * algorithm realises with integer dominance tests: in a column the lower row
 * wins a tie; along a row the left column wins a tie (see p1_rows).
 * CPU reference: brute-force colouring and standard flooding in
 * tests/c/test_gcd_voronoi.c. */
#include "gcd_geom.clh"

#define P1_NONE 0xffffffffu

/* Texel of every point; the smallest point index wins a shared texel. */
__kernel void p1_splat(__global const int *pts, uint n, int xmin, int ymin, int cell, uint W,
                       __global uint *texel, __global uint *seed)
{
    uint i = get_global_id(0);
    if (i >= n)
        return;
    uint tx = (uint)((pts[2 * i] - xmin) / cell);
    uint ty = (uint)((pts[2 * i + 1] - ymin) / cell);
    uint t = ty * W + tx;
    texel[i] = t;
    atomic_min(&seed[t], i);
}

/* flag[i] = 1 for a point that lost its texel (a missing point). */
__kernel void p1_missing_flags(__global const uint *texel, __global const uint *seed, uint n,
                               __global uint *flag)
{
    uint i = get_global_id(0);
    if (i < n)
        flag[i] = seed[texel[i]] != i ? 1u : 0u;
}

/* The frame: every border texel becomes the site of frame vertex base + k
 * (overriding any point there, which becomes a missing point). */
__kernel void p1_frame(__global uint *seed, uint W, uint H, uint base)
{
    uint k = get_global_id(0);
    if (k < gcd_frame_count(W, H))
        seed[gcd_frame_texel(k, W, H)] = base + k;
}

/* Sites given as texel indices (tests and the fallback path). */
__kernel void p1_plant(__global const uint *sites, uint nsites, __global uint *seed)
{
    uint i = get_global_id(0);
    if (i < nsites)
        atomic_min(&seed[sites[i]], i);
}

/* Banding phase 1: for every texel, the row of the nearest site in its own
 * column (P1_NONE if the column has none); ties go to the lower row.  Each
 * work-item owns STRIP consecutive columns of one band of rows; a band
 * first sweeps its rows alone, then reads the nearest sites just outside
 * it from the band summaries written by p1_cols_band. */
#ifndef STRIP
#define STRIP 1
#endif

/* Band pass 1: per band and column, the lowest and highest site rows in the
 * band (P1_NONE when none), written to lo[band*W + x] and hi[...]. */
__kernel void p1_cols_band(__global const uint *seed, uint W, uint H, uint bands,
                           __global uint *lo, __global uint *hi)
{
    uint g = get_global_id(0);
    uint nstrips = (W + STRIP - 1) / STRIP;
    if (g >= nstrips * bands)
        return;
    uint band = g / nstrips, x0 = (g % nstrips) * STRIP;
    uint y0 = (uint)(((ulong)H * band) / bands), y1 = (uint)(((ulong)H * (band + 1)) / bands);
    for (uint k = 0; k < STRIP; k++) {
        uint x = x0 + k;
        if (x >= W)
            break;
        uint l = P1_NONE, h = P1_NONE;
        for (uint y = y0; y < y1; y++) {
            if (seed[y * W + x] != P1_NONE) {
                if (l == P1_NONE)
                    l = y;
                h = y;
            }
        }
        lo[band * W + x] = l;
        hi[band * W + x] = h;
    }
}

/* Band pass 2 (sequential over bands, parallel over columns): nearest site
 * row below each band (from bands underneath) and above it. */
__kernel void p1_cols_link(uint W, uint bands, __global const uint *lo, __global const uint *hi,
                           __global uint *below, __global uint *above)
{
    uint x = get_global_id(0);
    if (x >= W)
        return;
    uint last = P1_NONE;
    for (uint b = 0; b < bands; b++) {
        below[b * W + x] = last;
        if (hi[b * W + x] != P1_NONE)
            last = hi[b * W + x];
    }
    last = P1_NONE;
    for (uint b = bands; b-- > 0;) {
        above[b * W + x] = last;
        if (lo[b * W + x] != P1_NONE)
            last = lo[b * W + x];
    }
}

/* Band pass 3: each band sweeps down and up, seeded with the nearest sites
 * outside it, and writes the nearest site row of every texel to near. */
__kernel void p1_cols(__global const uint *seed, uint W, uint H, uint bands,
                      __global const uint *below, __global const uint *above,
                      __global uint *near)
{
    uint g = get_global_id(0);
    uint nstrips = (W + STRIP - 1) / STRIP;
    if (g >= nstrips * bands)
        return;
    uint band = g / nstrips, x0 = (g % nstrips) * STRIP;
    uint y0 = (uint)(((ulong)H * band) / bands), y1 = (uint)(((ulong)H * (band + 1)) / bands);
    uint last[STRIP], next[STRIP];
    uint nk = W - x0 < STRIP ? W - x0 : STRIP;
    for (uint k = 0; k < nk; k++)
        last[k] = below[band * W + x0 + k];
    for (uint y = y0; y < y1; y++) {
        for (uint k = 0; k < nk; k++) {
            uint t = y * W + x0 + k;
            if (seed[t] != P1_NONE)
                last[k] = y;
            near[t] = last[k];
        }
    }
    for (uint k = 0; k < nk; k++)
        next[k] = above[band * W + x0 + k];
    for (uint y = y1; y-- > y0;) {
        for (uint k = 0; k < nk; k++) {
            uint t = y * W + x0 + k;
            if (seed[t] != P1_NONE)
                next[k] = y;
            uint l = near[t];
            /* l <= y <= next: the lower row wins a tie. */
            if (next[k] != P1_NONE && (l == P1_NONE || next[k] - y < y - l))
                near[t] = next[k];
        }
    }
}

/* Dominance threshold of two row candidates a (column xa) left of b
 * (column xb > xa) with vertical offsets da, db from the row: a beats b at
 * column u (u integer) iff u <= m_ab, where
 *   (u - xa)^2 + da^2 <= (u - xb)^2 + db^2   (ties to the left column)
 *   <=> 2u (xb - xa) <= xb^2 - xa^2 + db^2 - da^2,
 * so m_ab = floor((xb^2 - xa^2 + db^2 - da^2) / (2 (xb - xa))) =
 * p1_floor_div(num, den). */
inline int p1_floor_div(int num, int den)
{
    /* |num| < 2^29 and 0 < den < 2^15 (W, H <= 16384): 32-bit division */
    return num >= 0 ? num / den : -((-num + den - 1) / den);
}

#define P1_PACK(x, gy) ((uint)(x) | ((uint)(gy) << 15))
#define P1_X(p) ((long)((p)&0x7fffu))
#define P1_GY(p) ((long)((p) >> 15))

/* Banding phases 2 and 3 for one row per work-item: the row's candidates
 * (the column-nearest sites) are reduced to the lower envelope by the
 * integer dominance test (b between a and c is dropped iff m_ab >= m_bc,
 * i.e. no texel of the row has b as its least-key site), kept as a stack
 * written over the row's near[] entries (stack slot <= column read, so in
 * place is safe), with the threshold m_k between stack entries k and k+1
 * (the last column site k owns) in the row's colour[] entry k.  The
 * thresholds increase strictly and m_0 >= 0 (a bottom site beaten at
 * every column >= 0 is dropped), so m_k >= k.  Then every texel takes the
 * envelope site owning it, from the right: site k owns (m_{k-1}, m_k], so
 * writing it never overwrites a threshold still to be read (index < k-1).
 * Precondition: W, H <= 16384 (15-bit packing); at least one site. */
__kernel void p1_rows(__global uint *near, uint W, uint H, __global uint *colour)
{
    uint y = get_global_id(0);
    if (y >= H)
        return;
    __global uint *row = near + (size_t)y * W;
    __global uint *out = colour + (size_t)y * W;
    __global int *thr = (__global int *)out;
    int top = -1;
    for (uint x = 0; x < W; x++) {
        uint gy = row[x];
        if (gy == P1_NONE)
            continue;
        long dc = (long)gy - (long)y;
        /* m_bc = p1_floor_div(num, den) with den > 0, so
         * m < m_bc <=> (m + 1) den <= num: the divisions are left to the
         * thresholds that stay on the stack */
        int num = 0, den = 1;
        while (top >= 0) {
            uint b = row[top];
            long xb = P1_X(b), db = P1_GY(b) - (long)y;
            num = (int)((long)x * (long)x - xb * xb + dc * dc - db * db);
            den = (int)(2 * ((long)x - xb));
            if (top == 0) {
                /* m_bc < 0: b beats c at no column u >= 0, so b owns no
                 * texel of the row whatever follows; it leaves the stack,
                 * and the bottom threshold is >= 0 */
                if (num < 0)
                    top = -1;
                break;
            }
            /* thr[top-1]: threshold between stack[top-1] and stack[top] */
            if ((long)(thr[top - 1] + 1) * den <= (long)num)
                break;
            top--;
        }
        if (top >= 0)
            thr[top] = p1_floor_div(num, den);
        row[++top] = P1_PACK(x, gy);
    }
    if (top < 0) {
        for (uint x = 0; x < W; x++)
            out[x] = P1_NONE;
        return;
    }
    /* site top owns up to W - 1; a threshold beyond W - 1 owns nothing */
    long hi = (long)W - 1;
    for (int k = top; k >= 0 && hi >= 0; k--) {
        long lo = k > 0 ? (long)thr[k - 1] : -1;
        uint cur = row[k], c = (uint)P1_GY(cur) * W + (uint)P1_X(cur);
        if (lo > hi)
            lo = hi;
        for (long x = hi; x > lo; x--)
            out[x] = c;
        hi = lo;
    }
}

/* key(B, S) < key(A, S) for two texels of the same site S. */
inline int p1_closer(long bx, long by, uint bi, long ax, long ay, uint ai, long sx, long sy)
{
    long db = (bx - sx) * (bx - sx) + (by - sy) * (by - sy);
    long da = (ax - sx) * (ax - sx) + (ay - sy) * (ay - sy);
    return db < da || (db == da && bi < ai);
}

/* Debris seeds: a texel that is not a site and has no 8-neighbour of its
 * colour closer (in key order) to the site is the closest texel of a debris
 * component (every bulk texel other than the site has such a neighbour, by
 * the Bulk Lemma of Cao, Edelsbrunner and Tan).  One row per work-item;
 * appended to list (order arbitrary: the host sorts it); *count may exceed
 * cap (then grow and rerun). */
__kernel void p1_debris(__global const uint *colour, uint W, uint H, __global uint *list,
                        uint cap, __global uint *count)
{
    uint y = get_global_id(0);
    if (y >= H)
        return;
    for (uint x = 0; x < W; x++) {
        uint i = y * W + x;
        uint s = colour[i];
        if (s == i || s == P1_NONE)
            continue;
        long sx = s % W, sy = s / W;
        /* the 8-neighbour one step towards the site is strictly closer to
         * it: if it has the colour, the texel is supported (the usual case) */
        long bx0 = x + (sx > x) - (sx < (long)x), by0 = y + (sy > y) - (sy < (long)y);
        if (colour[by0 * (long)W + bx0] == s)
            continue;
        int supported = 0;
        for (int dy = -1; dy <= 1 && !supported; dy++) {
            for (int dx = -1; dx <= 1; dx++) {
                long bx = (long)x + dx, by = (long)y + dy;
                if ((dx | dy) == 0 || bx < 0 || by < 0 || bx >= (long)W || by >= (long)H)
                    continue;
                uint b = (uint)(by * (long)W + bx);
                if (colour[b] == s && p1_closer(bx, by, b, x, y, i, sx, sy)) {
                    supported = 1;
                    break;
                }
            }
        }
        if (!supported) {
            uint k = atomic_inc(count);
            if (k < cap)
                list[k] = i;
        }
    }
}

/* The 3x3 neighbourhood colours of listed texels (row-major from (-1,-1);
 * P1_NONE outside the grid), for the host's debris recolouring. */
__kernel void p1_gather(__global const uint *colour, uint W, uint H, __global const uint *list,
                        uint m, __global uint *out)
{
    uint i = get_global_id(0);
    if (i >= m)
        return;
    long x = list[i] % W, y = list[i] / W;
    int k = 0;
    for (int dy = -1; dy <= 1; dy++) {
        for (int dx = -1; dx <= 1; dx++, k++) {
            long bx = x + dx, by = y + dy;
            out[9 * (size_t)i + k] = (bx < 0 || by < 0 || bx >= (long)W || by >= (long)H)
                                         ? P1_NONE
                                         : colour[by * (long)W + bx];
        }
    }
}

/* colour[pix[i]] = col[i]. */
__kernel void p1_scatter(__global uint *colour, __global const uint *pix,
                         __global const uint *col, uint m)
{
    uint i = get_global_id(0);
    if (i < m)
        colour[pix[i]] = col[i];
}

/* ---- internal numbering ----
 * Kept points are renumbered in texel (row-major) order, so that points
 * near each other have near indices (the dual triangles, positions and
 * per-vertex arrays are then read with locality); missing points follow,
 * sorted by the corner chunk of their texel (gcd_home_chunk: where Phase 2
 * reserves their triangle slots), in input order within a chunk.
 * int2in[k] is the input index of internal point k. */

/* flag[t] = 1 for a texel owned by a real point (seed < n). */
__kernel void p1_occ_flags(__global const uint *seed, uint npix, uint n, __global uint *flag)
{
    uint t = get_global_id(0);
    if (t < npix)
        flag[t] = seed[t] < n ? 1u : 0u;
}

/* rank: exclusive scan of p1_occ_flags.  The owner of texel t becomes
 * internal point rank[t]. */
__kernel void p1_number_kept(__global uint *seed, uint npix, uint n, __global const uint *rank,
                             __global uint *int2in)
{
    uint t = get_global_id(0);
    if (t >= npix || seed[t] >= n)
        return;
    int2in[rank[t]] = seed[t];
    seed[t] = rank[t];
}

/* Missing points (input indices, sorted by their home chunk) become
 * kept + j. */
__kernel void p1_number_missing(__global const uint *missing, uint m, uint kept,
                                __global uint *int2in)
{
    uint j = get_global_id(0);
    if (j < m)
        int2in[kept + j] = missing[j];
}

/* Points and texels in internal order. */
__kernel void p1_permute(__global const uint *int2in, uint n, __global const int *pts_in,
                         __global const uint *texel_in, __global int *pts, __global uint *texel)
{
    uint k = get_global_id(0);
    if (k >= n)
        return;
    uint i = int2in[k];
    pts[2 * k] = pts_in[2 * i];
    pts[2 * k + 1] = pts_in[2 * i + 1];
    texel[k] = texel_in[i];
}

/* Sort keys of the missing points: the home chunk of their texel. */
__kernel void p1_missing_keys(__global const uint *missing, uint m,
                              __global const uint *texel_in, uint W, uint H,
                              __global uint *keys)
{
    uint j = get_global_id(0);
    if (j < m)
        keys[j] = gcd_home_chunk(texel_in[missing[j]], W, H);
}

/* range[2c], range[2c+1]: the first and one past the last index j of the
 * sorted keys equal to c (both preset to 0 for chunks without any). */
__kernel void p1_missing_range(__global const uint *keys, uint m, __global uint *range)
{
    uint j = get_global_id(0);
    if (j >= m)
        return;
    uint k = keys[j];
    if (j == 0 || keys[j - 1] != k)
        range[2 * k] = j;
    if (j + 1 == m || keys[j + 1] != k)
        range[2 * k + 1] = j + 1;
}
