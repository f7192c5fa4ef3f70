/* check.c — exact verifiers of gdt_mesh: validity of the triangulation
 * (gdt_check_mesh) and local optimality with the tie-break
 * (gdt_check_delaunay).
 *
 * design (why the checks of gdt_check_mesh suffice for "a triangulation of
 * the point set whose boundary is the convex hull"): the triangles, all
 * strictly counter-clockwise, form an oriented pseudo-manifold whose hull
 * edges are exactly its boundary 1-cycle.  For a point q off every edge,
 * the number of triangles covering q equals the winding number of that
 * boundary cycle around q.  Once the boundary is one convex chain winding
 * once, every point inside it is covered exactly once and no point outside
 * is covered: the triangles tile the convex polygon without overlap.  With
 * distinct points all used, no point can lie inside a triangle or on an
 * edge it is not a vertex of.  Hence, once the earlier checks pass,
 * connectivity (7322), Euler's relation (7321) and "every point inside or on
 * the hull" (7320) hold; they are still verified directly, as stated
 * properties of the output, so that a flaw in this argument or a change of
 * the checks cannot go unnoticed.
 */
#include "gdt_mesh.h"

#include <stdlib.h>
#include <string.h>

#include "private/mesh_ops.h"

#define CHK_PT(p) (long long)(p).x, (long long)(p).y

static int pt_less(gdt_ipt a, gdt_ipt b)
{
    return a.x < b.x || (a.x == b.x && a.y < b.y);
}

/* For p on the line through a and b: p lies in the closed segment [a, b].
 * Along a line the lexicographic (x, y) order is the order of the points. */
static int on_segment(gdt_ipt a, gdt_ipt b, gdt_ipt p)
{
    gdt_ipt lo = pt_less(a, b) ? a : b, hi = pt_less(a, b) ? b : a;
    return !pt_less(p, lo) && !pt_less(hi, p);
}

/* Direction a -> b points into the upper half-plane of directions,
 * angle in [0, pi). */
static int dir_upper(gdt_ipt a, gdt_ipt b)
{
    return b.y > a.y || (b.y == a.y && b.x > a.x);
}

static gdt_status check_points(const gdt_mesh *m, gdt_error *err)
{
    gdt_status st = GDT_OK;
    size_t n = m->nverts;
    uint64_t *key = NULL, *tkey = NULL;
    int32_t *val = NULL, *tval = NULL;

    for (size_t v = 0; v < n; v++) {
        gdt_ipt p = m->pts[v];
        if (p.x < 0 || p.x > GDT_COORD_MAX || p.y < 0 || p.y > GDT_COORD_MAX)
            return gdt_error_set(err, GDT_EINTERNAL, 7311,
                                 "vertex %zu at (%lld, %lld) lies outside the tile-local "
                                 "range [0, 2^31-1]",
                                 v, CHK_PT(p));
    }
    if (n < 2)
        return GDT_OK;
    key = malloc(n * sizeof *key);
    tkey = malloc(n * sizeof *tkey);
    val = malloc(n * sizeof *val);
    tval = malloc(n * sizeof *tval);
    if (key == NULL || tkey == NULL || val == NULL || tval == NULL) {
        st = gdt_error_set(err, GDT_EINTERNAL, 7001,
                           "out of memory checking %zu vertices for duplicates", n);
        goto fail;
    }
    for (size_t v = 0; v < n; v++) {
        key[v] = ((uint64_t)m->pts[v].x << 31) | (uint64_t)m->pts[v].y;
        val[v] = (int32_t)v;
    }
    gdt_mesh_radix_sort(key, val, n, tkey, tval);
    for (size_t i = 1; i < n; i++)
        if (key[i] == key[i - 1]) {
            int32_t a = val[i - 1] < val[i] ? val[i - 1] : val[i];
            int32_t b = val[i - 1] < val[i] ? val[i] : val[i - 1];
            st = gdt_error_set(err, GDT_EINTERNAL, 7312,
                               "vertices %d and %d coincide at (%lld, %lld)", (int)a, (int)b,
                               CHK_PT(m->pts[a]));
            goto fail;
        }

fail:
    free(key);
    free(tkey);
    free(val);
    free(tval);
    return st;
}

/* No triangle: legal only for fewer than 3 points or all points collinear. */
static gdt_status check_no_triangles(gdt_pred_stats *st, const gdt_mesh *m, gdt_error *err)
{
    if (m->nverts < 3)
        return GDT_OK;
    /* The points are distinct, so pts[0] != pts[1]. */
    for (size_t k = 2; k < m->nverts; k++)
        if (gdt_orient2d(st, m->pts[0], m->pts[1], m->pts[k]) != 0)
            return gdt_error_set(err, GDT_EINTERNAL, 7323,
                                 "mesh has no triangles but its %zu vertices are not "
                                 "collinear (vertices 0, 1, %zu)",
                                 m->nverts, k);
    return GDT_OK;
}

static gdt_status check_triangles(gdt_pred_stats *st, const gdt_mesh *m, gdt_error *err)
{
    size_t nt = m->ntris;
    for (size_t t = 0; t < nt; t++) {
        const int32_t *T = m->tri + 3 * t;
        for (int i = 0; i < 3; i++)
            if (T[i] < 0 || (size_t)T[i] >= m->nverts)
                return gdt_error_set(err, GDT_EINTERNAL, 7313,
                                     "triangle %zu slot %d: vertex index %d outside [0, %zu)", t, i,
                                     (int)T[i], m->nverts);
        if (T[0] == T[1] || T[1] == T[2] || T[2] == T[0])
            return gdt_error_set(err, GDT_EINTERNAL, 7313,
                                 "triangle %zu repeats a vertex: (%d, %d, %d)", t, (int)T[0],
                                 (int)T[1], (int)T[2]);
    }
    for (size_t t = 0; t < nt; t++) {
        const int32_t *T = m->tri + 3 * t;
        int o = gdt_orient2d(st, m->pts[T[0]], m->pts[T[1]], m->pts[T[2]]);
        if (o <= 0)
            return gdt_error_set(err, GDT_EINTERNAL, 7314,
                                 "triangle %zu (%d, %d, %d) at (%lld, %lld), (%lld, %lld), "
                                 "(%lld, %lld) is %s",
                                 t, (int)T[0], (int)T[1], (int)T[2], CHK_PT(m->pts[T[0]]),
                                 CHK_PT(m->pts[T[1]]), CHK_PT(m->pts[T[2]]),
                                 o < 0 ? "clockwise" : "degenerate (collinear)");
    }
    return GDT_OK;
}

/* Every non-hull pointer designates a different triangle sharing the same
 * edge in the opposite direction, and points back. */
static gdt_status check_pointers(const gdt_mesh *m, gdt_error *err)
{
    size_t nt = m->ntris;
    for (size_t t = 0; t < nt; t++) {
        const int32_t *T = m->tri + 3 * t;
        for (int i = 0; i < 3; i++) {
            int32_t o = m->opp[3 * t + (size_t)i];
            int32_t a = T[mesh_next(i)], b = T[mesh_prev(i)];
            if (o == GDT_MESH_NONE)
                continue;
            int32_t u = gdt_opp_tri(o);
            int j = gdt_opp_slot(o);
            if (o < 0 || (size_t)u >= nt || j == 3 || (size_t)u == t)
                return gdt_error_set(err, GDT_EINTERNAL, 7315,
                                     "triangle %zu slot %d (edge %d-%d): invalid opposite "
                                     "pointer %d (triangle %d slot %d)",
                                     t, i, (int)a, (int)b, (int)o, (int)u, j);
            const int32_t *U = m->tri + 3 * (size_t)u;
            if (U[mesh_next(j)] != b || U[mesh_prev(j)] != a)
                return gdt_error_set(err, GDT_EINTERNAL, 7315,
                                     "triangle %zu slot %d (edge %d->%d) points to triangle "
                                     "%d slot %d, whose edge is %d->%d, not %d->%d",
                                     t, i, (int)a, (int)b, (int)u, j, (int)U[mesh_next(j)],
                                     (int)U[mesh_prev(j)], (int)b, (int)a);
            if (m->opp[3 * (size_t)u + (size_t)j] != gdt_opp_pack((int32_t)t, i))
                return gdt_error_set(err, GDT_EINTERNAL, 7315,
                                     "adjacency not symmetric: triangle %zu slot %d points to "
                                     "triangle %d slot %d, which points to %d (triangle %d "
                                     "slot %d)",
                                     t, i, (int)u, j, (int)m->opp[3 * (size_t)u + (size_t)j],
                                     (int)gdt_opp_tri(m->opp[3 * (size_t)u + (size_t)j]),
                                     gdt_opp_slot(m->opp[3 * (size_t)u + (size_t)j]));
        }
    }
    return GDT_OK;
}

/* Every edge lies in one or two triangles, and an edge of two triangles is
 * linked (never marked as hull). */
static gdt_status check_edges(const gdt_mesh *m, gdt_error *err)
{
    gdt_status st = GDT_OK;
    gdt_error e2;
    int32_t *opp = malloc(3 * m->ntris * sizeof *opp);

    if (opp == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001,
                             "out of memory checking the edges of %zu triangles", m->ntris);
    gdt_error_clear(&e2);
    st = gdt_mesh_adjacency(m->tri, m->ntris, m->nverts, opp, &e2);
    if (st != GDT_OK) {
        st = gdt_error_set(err, st, e2.code == 7001 ? 7001 : 7316, "%s", e2.msg);
        goto fail;
    }
    for (size_t h = 0; h < 3 * m->ntris; h++)
        if (opp[h] != m->opp[h]) {
            int i = (int)(h % 3);
            const int32_t *T = m->tri + 3 * (h / 3);
            st = gdt_error_set(err, GDT_EINTERNAL, 7316,
                               "triangle %zu slot %d: edge %d-%d is shared with triangle %d "
                               "slot %d but marked as a hull edge",
                               h / 3, i, (int)T[mesh_next(i)], (int)T[mesh_prev(i)],
                               (int)gdt_opp_tri(opp[h]), gdt_opp_slot(opp[h]));
            goto fail;
        }

fail:
    free(opp);
    return st;
}

static gdt_status check_used_connected(const gdt_mesh *m, gdt_error *err)
{
    gdt_status st = GDT_OK;
    size_t nt = m->ntris, nv = m->nverts;
    uint8_t *used = calloc(nv, 1);
    uint8_t *seen = calloc(nt, 1);
    int32_t *stack = malloc(nt * sizeof *stack);
    size_t top = 0, reached = 0;

    if (used == NULL || seen == NULL || stack == NULL) {
        st = gdt_error_set(err, GDT_EINTERNAL, 7001,
                           "out of memory checking the vertices of %zu triangles", nt);
        goto fail;
    }
    for (size_t h = 0; h < 3 * nt; h++)
        used[m->tri[h]] = 1;
    for (size_t v = 0; v < nv; v++)
        if (!used[v]) {
            st = gdt_error_set(err, GDT_EINTERNAL, 7317,
                               "vertex %zu at (%lld, %lld) belongs to no triangle", v,
                               CHK_PT(m->pts[v]));
            goto fail;
        }
    seen[0] = 1;
    stack[top++] = 0;
    while (top > 0) {
        int32_t t = stack[--top];
        reached++;
        for (int i = 0; i < 3; i++) {
            int32_t o = m->opp[3 * (size_t)t + (size_t)i];
            if (o != GDT_MESH_NONE && !seen[gdt_opp_tri(o)]) {
                seen[gdt_opp_tri(o)] = 1;
                stack[top++] = gdt_opp_tri(o);
            }
        }
    }
    if (reached != nt) {
        size_t t = 0;
        while (seen[t])
            t++;
        st = gdt_error_set(err, GDT_EINTERNAL, 7322,
                           "mesh is not connected: %zu of %zu triangles reachable from "
                           "triangle 0 (triangle %zu is not)",
                           reached, nt, t);
    }

fail:
    free(used);
    free(seen);
    free(stack);
    return st;
}

/* design: the hull edges (opp == NONE) are directed so that the interior is
 * on their left.  They must form a single cycle c_0 .. c_{h-1}; every turn
 * is a left turn or straight on (never back); the edge directions cross the
 * +x direction exactly once (total turning 2 pi: convex, winding once);
 * every vertex lies in the closed polygon (fan binary search from a
 * strictly convex corner c_0, O(log h) per point); and F = 2V - h - 2. */
static gdt_status check_hull(gdt_pred_stats *st, const gdt_mesh *m, gdt_error *err)
{
    gdt_status s = GDT_OK;
    size_t nt = m->ntris, nv = m->nverts;
    int32_t *next = malloc(nv * sizeof *next);
    int32_t *chain = NULL;
    size_t h = 0, first = 0;

    if (next == NULL) {
        s = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory checking the hull");
        goto fail;
    }
    for (size_t v = 0; v < nv; v++)
        next[v] = GDT_MESH_NONE;
    for (size_t t = 0; t < nt; t++)
        for (int i = 0; i < 3; i++) {
            if (m->opp[3 * t + (size_t)i] != GDT_MESH_NONE)
                continue;
            int32_t a = m->tri[3 * t + (size_t)mesh_next(i)];
            int32_t b = m->tri[3 * t + (size_t)mesh_prev(i)];
            if (next[a] != GDT_MESH_NONE) {
                s = gdt_error_set(err, GDT_EINTERNAL, 7318,
                                  "hull is not a simple closed chain: vertex %d starts two "
                                  "hull edges (%d->%d and %d->%d)",
                                  (int)a, (int)a, (int)next[a], (int)a, (int)b);
                goto fail;
            }
            next[a] = b;
            first = (size_t)a;
            h++;
        }
    if (h < 3) {
        s = gdt_error_set(err, GDT_EINTERNAL, 7318,
                          "mesh of %zu triangles has %zu hull edges: no closed hull chain", nt, h);
        goto fail;
    }
    chain = malloc(h * sizeof *chain);
    if (chain == NULL) {
        s = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory checking the hull");
        goto fail;
    }
    {
        size_t k = 0;
        int32_t v = (int32_t)first;
        do {
            if (k == h) {
                s = gdt_error_set(err, GDT_EINTERNAL, 7318,
                                  "hull chain from vertex %zu does not close after all %zu "
                                  "hull edges",
                                  first, h);
                goto fail;
            }
            chain[k++] = v;
            if (next[v] == GDT_MESH_NONE) {
                s = gdt_error_set(err, GDT_EINTERNAL, 7318,
                                  "hull chain from vertex %zu breaks at vertex %d: no hull "
                                  "edge leaves it",
                                  first, (int)v);
                goto fail;
            }
            v = next[v];
        } while (v != (int32_t)first);
        if (k != h) {
            s = gdt_error_set(err, GDT_EINTERNAL, 7318,
                              "hull edges form more than one closed chain: the chain through "
                              "vertex %zu has %zu of %zu hull edges",
                              first, k, h);
            goto fail;
        }
    }

    /* Convexity and winding; remember a strictly convex corner. */
    size_t wraps = 0, corner = h;
    for (size_t k = 0; k < h; k++) {
        gdt_ipt a = m->pts[chain[(k + h - 1) % h]], b = m->pts[chain[k]];
        gdt_ipt c = m->pts[chain[(k + 1) % h]];
        int o = gdt_orient2d(st, a, b, c);
        if (o < 0 || (o == 0 && !on_segment(a, c, b))) {
            s = gdt_error_set(err, GDT_EINTERNAL, 7319,
                              "hull is not convex at vertex %d (%lld, %lld): %s turn %d -> %d "
                              "-> %d",
                              (int)chain[k], CHK_PT(b), o < 0 ? "reflex" : "backward",
                              (int)chain[(k + h - 1) % h], (int)chain[k], (int)chain[(k + 1) % h]);
            goto fail;
        }
        if (o > 0 && corner == h)
            corner = k;
        if (!dir_upper(a, b) && dir_upper(b, c))
            wraps++;
    }
    if (wraps != 1) {
        s = gdt_error_set(err, GDT_EINTERNAL, 7319,
                          "hull chain of %zu vertices winds %zu times around the mesh, not "
                          "once",
                          h, wraps);
        goto fail;
    }
    if (nt != 2 * nv - h - 2) {
        s = gdt_error_set(err, GDT_EINTERNAL, 7321,
                          "Euler's relation fails: %zu triangles, but 2V - h - 2 = %zu for "
                          "V = %zu vertices and h = %zu hull vertices",
                          nt, 2 * nv - h - 2, nv, h);
        goto fail;
    }

    /* Inside test.  Rotate so that c_0 is the strictly convex corner; the
     * sides at c_0 end at c_f (first) and c_l (last); the rays c_0 -> c_j,
     * f <= j <= l, turn strictly counter-clockwise within an angle < pi. */
    {
        int32_t *c = next; /* reuse: next[] is no longer needed */
        for (size_t k = 0; k < h; k++)
            c[k] = chain[(corner + k) % h];
        gdt_ipt c0 = m->pts[c[0]];
        size_t f = 1, l = h - 1;
        while (f + 1 < h && gdt_orient2d(st, c0, m->pts[c[f]], m->pts[c[f + 1]]) == 0)
            f++;
        while (l > f && gdt_orient2d(st, c0, m->pts[c[l]], m->pts[c[l - 1]]) == 0)
            l--;
        gdt_ipt cf = m->pts[c[f]], cl = m->pts[c[l]];
        for (size_t v = 0; v < nv; v++) {
            gdt_ipt p = m->pts[v];
            const char *why = NULL;
            size_t e0 = 0, e1 = 0;
            int o1 = gdt_orient2d(st, c0, cf, p);
            int o2 = gdt_orient2d(st, c0, cl, p);
            if (o1 < 0 || (o1 == 0 && !on_segment(c0, cf, p))) {
                why = "right of or beyond the hull side", e0 = 0, e1 = f;
            } else if (o2 > 0 || (o2 == 0 && !on_segment(c0, cl, p))) {
                why = "right of or beyond the hull side", e0 = l, e1 = 0;
            } else if (o1 > 0 && o2 < 0) {
                size_t lo = f, hi = l - 1; /* invariant: orient(c0, c_lo, p) >= 0 */
                while (lo < hi) {
                    size_t mid = lo + (hi - lo + 1) / 2;
                    if (gdt_orient2d(st, c0, m->pts[c[mid]], p) >= 0)
                        lo = mid;
                    else
                        hi = mid - 1;
                }
                if (gdt_orient2d(st, m->pts[c[lo]], m->pts[c[lo + 1]], p) < 0)
                    why = "right of the hull edge", e0 = lo, e1 = lo + 1;
            }
            if (why != NULL) {
                s = gdt_error_set(err, GDT_EINTERNAL, 7320,
                                  "vertex %zu at (%lld, %lld) lies outside the hull: %s "
                                  "%d -> %d",
                                  v, CHK_PT(p), why, (int)c[e0], (int)c[e1]);
                goto fail;
            }
        }
    }

fail:
    free(next);
    free(chain);
    return s;
}

gdt_status gdt_check_mesh(gdt_pred_stats *st, const gdt_mesh *m, gdt_error *err)
{
    gdt_status s;

    if (m->nverts > GDT_MESH_MAX_VERTS || m->ntris > GDT_MESH_MAX_TRIS ||
        (m->nverts > 0 && m->pts == NULL) || (m->ntris > 0 && (m->tri == NULL || m->opp == NULL)))
        return gdt_error_set(err, GDT_EINTERNAL, 7310,
                             "mesh of %zu vertices and %zu triangles exceeds the limits or "
                             "lacks its arrays",
                             m->nverts, m->ntris);
    if ((s = check_points(m, err)) != GDT_OK)
        return s;
    if (m->ntris == 0)
        return check_no_triangles(st, m, err);
    if ((s = check_triangles(st, m, err)) != GDT_OK)
        return s;
    if ((s = check_pointers(m, err)) != GDT_OK)
        return s;
    if ((s = check_edges(m, err)) != GDT_OK)
        return s;
    if ((s = check_used_connected(m, err)) != GDT_OK)
        return s;
    return check_hull(st, m, err);
}

gdt_status gdt_check_delaunay(gdt_pred_stats *st, const gdt_mesh *m, gdt_error *err)
{
    size_t nt = m->ntris;
    for (size_t t = 0; t < nt; t++) {
        const int32_t *T = m->tri + 3 * t;
        for (int i = 0; i < 3; i++) {
            int32_t o = m->opp[3 * t + (size_t)i];
            if (o == GDT_MESH_NONE)
                continue;
            int32_t u = gdt_opp_tri(o);
            int j = gdt_opp_slot(o);
            if (o < 0 || (size_t)u >= nt || j == 3 || (size_t)u == t)
                return gdt_error_set(err, GDT_EINTERNAL, 7315,
                                     "triangle %zu slot %d: invalid opposite pointer %d", t, i,
                                     (int)o);
            if ((size_t)u < t)
                continue; /* each edge once, tested from both sides */
            int32_t ia = T[mesh_next(i)], ib = T[mesh_prev(i)], ic = T[i];
            int32_t id = m->tri[3 * (size_t)u + (size_t)j];
            if (ia < 0 || ib < 0 || ic < 0 || id < 0 || (size_t)ia >= m->nverts ||
                (size_t)ib >= m->nverts || (size_t)ic >= m->nverts || (size_t)id >= m->nverts)
                return gdt_error_set(err, GDT_EINTERNAL, 7313,
                                     "triangle %zu or %d holds a vertex index outside [0, %zu)", t,
                                     (int)u, m->nverts);
            gdt_ipt a = m->pts[ia], b = m->pts[ib], c = m->pts[ic], d = m->pts[id];
            int f1 = gdt_edge_needs_flip(st, a, b, c, d);
            int f2 = gdt_edge_needs_flip(st, b, a, d, c);
            if (f1 || f2) {
                int inc = gdt_incircle(st, a, b, c, d);
                return gdt_error_set(
                    err, GDT_EINTERNAL, 7330,
                    "edge %d-%d of triangles %zu (slot %d) and %d (slot %d) is not locally "
                    "optimal: %s; it must flip to %d-%d (a=(%lld, %lld) b=(%lld, %lld) "
                    "c=(%lld, %lld) d=(%lld, %lld), seen %s)",
                    (int)ia, (int)ib, t, i, (int)u, j,
                    inc > 0    ? "the opposite vertex lies strictly inside the circumcircle"
                    : inc == 0 ? "the four points are co-circular and the tie-break "
                                 "prefers the other diagonal"
                               : "the tie-break is inconsistent across the edge",
                    (int)ic, (int)id, CHK_PT(a), CHK_PT(b), CHK_PT(c), CHK_PT(d),
                    f1 && f2 ? "from both sides"
                    : f1     ? "from the first side only"
                             : "from the second side only");
            }
        }
    }
    return GDT_OK;
}
