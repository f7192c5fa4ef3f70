/* reference.c — CPU reference triangulator (see gdt_reference.h). */
#include "gdt_reference.h"

#include <stdlib.h>
#include <string.h>

#include "private/mesh_ops.h"

#define REF_SEED UINT64_C(0x9e3779b97f4a7c15)

typedef struct ref_ctx {
    gdt_pred_stats *ps;
    const gdt_ipt *pts; /* the n real vertices */
    int32_t inf;        /* index of the symbolic vertex at infinity (= n) */
    int32_t *tri, *opp; /* working triangles, ghosts included */
    size_t ntris;       /* triangles in use, ghosts included */
    int32_t *stack;     /* legalisation stack: triangles whose slot 0 is the new point */
    size_t top, cap;
    uint64_t rng;
    uint64_t walk_steps, flips;
} ref_ctx;

enum { LOC_INSIDE, LOC_OUTSIDE };

static uint64_t rng_next(uint64_t *s)
{
    uint64_t x = *s;
    x ^= x >> 12;
    x ^= x << 25;
    x ^= x >> 27;
    *s = x;
    return x * UINT64_C(0x2545f4914f6cdd1d);
}

/* Position along the Hilbert curve over the 2^31 x 2^31 lattice. */
static uint64_t hilbert_key(uint32_t x, uint32_t y)
{
    uint64_t d = 0;
    for (uint32_t s = UINT32_C(1) << 30; s > 0; s >>= 1) {
        uint32_t rx = (x & s) ? 1u : 0u, ry = (y & s) ? 1u : 0u;
        d += (uint64_t)s * s * ((3u * rx) ^ ry);
        if (ry == 0) {
            if (rx == 1) {
                /* Only the bits below s matter from here on. */
                x = s - 1 - x;
                y = s - 1 - y;
            }
            uint32_t tmp = x;
            x = y;
            y = tmp;
        }
    }
    return d;
}

static unsigned bit_length(size_t v)
{
    unsigned b = 0;
    while (v > 0) {
        b++;
        v >>= 1;
    }
    return b;
}

/* BRIO order: a fixed-seed shuffle cut into rounds [2^(r-1), 2^r), each
 * round sorted along the Hilbert curve.  Writes order[0..n). */
static gdt_status brio_order(const gdt_ipt *pts, size_t n, int32_t *order, gdt_error *err)
{
    gdt_status st = GDT_OK;
    uint64_t *key = malloc(n * sizeof *key);
    uint64_t *tkey = malloc(n * sizeof *tkey);
    int32_t *tval = malloc(n * sizeof *tval);
    uint64_t rng = REF_SEED;

    if (key == NULL || tkey == NULL || tval == NULL) {
        st = gdt_error_set(err, GDT_EINTERNAL, 7001,
                           "out of memory ordering %zu points for insertion", n);
        goto fail;
    }
    for (size_t i = 0; i < n; i++)
        order[i] = (int32_t)i;
    for (size_t i = n; i > 1; i--) {
        size_t j = (size_t)(rng_next(&rng) % i);
        int32_t x = order[i - 1];
        order[i - 1] = order[j];
        order[j] = x;
    }
    for (size_t i = 0; i < n; i++) {
        gdt_ipt p = pts[order[i]];
        key[i] = ((uint64_t)bit_length(i) << 59) | (hilbert_key((uint32_t)p.x, (uint32_t)p.y) >> 3);
    }
    gdt_mesh_radix_sort(key, order, n, tkey, tval);

fail:
    free(key);
    free(tkey);
    free(tval);
    return st;
}

static int is_ghost(const ref_ctx *c, int32_t t)
{
    const int32_t *T = c->tri + 3 * (size_t)t;
    return T[0] == c->inf || T[1] == c->inf || T[2] == c->inf;
}

static gdt_status push(ref_ctx *c, int32_t t, gdt_error *err)
{
    if (c->top == c->cap) {
        size_t cap = c->cap > 0 ? 2 * c->cap : 64;
        int32_t *s = realloc(c->stack, cap * sizeof *s);
        if (s == NULL)
            return gdt_error_set(err, GDT_EINTERNAL, 7001,
                                 "out of memory for the reference flip stack");
        c->stack = s;
        c->cap = cap;
    }
    c->stack[c->top++] = t;
    return GDT_OK;
}

/* Point location by exhaustive search; used only if a walk runs far longer
 * than any walk can in a valid triangulation. */
static int locate_scan(ref_ctx *c, gdt_ipt p, int32_t *tp, int o[3])
{
    const int32_t *tri = c->tri;
    for (size_t t = 0; t < c->ntris; t++) {
        if (is_ghost(c, (int32_t)t))
            continue;
        const int32_t *T = tri + 3 * t;
        int k;
        for (k = 0; k < 3; k++) {
            o[k] = gdt_orient2d(c->ps, c->pts[T[mesh_next(k)]], c->pts[T[mesh_prev(k)]], p);
            if (o[k] < 0)
                break;
        }
        if (k == 3) {
            *tp = (int32_t)t;
            return LOC_INSIDE;
        }
    }
    for (size_t t = 0; t < c->ntris; t++) {
        const int32_t *T = tri + 3 * t;
        for (int k = 0; k < 3; k++)
            if (T[k] == c->inf &&
                gdt_orient2d(c->ps, c->pts[T[mesh_next(k)]], c->pts[T[mesh_prev(k)]], p) < 0) {
                *tp = (int32_t)t;
                return LOC_OUTSIDE;
            }
    }
    return -1;
}

/* Remembering stochastic walk from the real triangle *tp.  Returns
 * LOC_INSIDE with o[k] = orient2d of p against the edge of slot k (p in the
 * closed triangle *tp), or LOC_OUTSIDE with *tp a ghost whose hull edge has
 * p strictly on its outer side; -1 if p is in no triangle (a bug). */
static int locate(ref_ctx *c, gdt_ipt p, int32_t *tp, int o[3])
{
    const int32_t *tri = c->tri, *opp = c->opp;
    int32_t t = *tp, prev = GDT_MESH_NONE;
    size_t steps = 0;

    for (;;) {
        if (is_ghost(c, t)) {
            *tp = t;
            return LOC_OUTSIDE;
        }
        if (++steps > c->ntris + 16)
            return locate_scan(c, p, tp, o);
        const int32_t *T = tri + 3 * (size_t)t;
        int k0 = (int)((rng_next(&c->rng) >> 33) % 3);
        int32_t to = GDT_MESH_NONE;
        for (int r = 0; r < 3; r++) {
            int k = (k0 + r) % 3;
            int32_t nb = gdt_opp_tri(opp[3 * (size_t)t + (size_t)k]);
            if (nb == prev) {
                o[k] = 1; /* crossed from there: p is strictly on this side */
                continue;
            }
            o[k] = gdt_orient2d(c->ps, c->pts[T[mesh_next(k)]], c->pts[T[mesh_prev(k)]], p);
            if (o[k] < 0) {
                to = nb;
                break;
            }
        }
        c->walk_steps++;
        if (to == GDT_MESH_NONE) {
            *tp = t;
            return LOC_INSIDE;
        }
        prev = t;
        t = to;
    }
}

/* Lawson test of the edge opposite slot 0 (the new point p) of triangle t,
 * ghosts included: an edge to infinity separates two ghosts and flips when
 * its finite end is a reflex hull vertex; a hull edge never flips. */
static int ref_needs_flip(ref_ctx *c, int32_t t)
{
    const int32_t *T = c->tri + 3 * (size_t)t;
    int32_t o = c->opp[3 * (size_t)t];
    int32_t p = T[0], a = T[1], b = T[2];
    int32_t d = c->tri[3 * (size_t)gdt_opp_tri(o) + (size_t)gdt_opp_slot(o)];
    const gdt_ipt *P = c->pts;

    if (a == c->inf) /* hull p -> b -> d */
        return gdt_orient2d(c->ps, P[p], P[b], P[d]) < 0;
    if (b == c->inf) /* hull d -> a -> p */
        return gdt_orient2d(c->ps, P[d], P[a], P[p]) < 0;
    if (d == c->inf)
        return 0;
    return gdt_edge_needs_flip(c->ps, P[a], P[b], P[p], P[d]);
}

/* Inserts vertex p located by locate(); *last receives a real triangle
 * incident to p. */
static gdt_status insert(ref_ctx *c, int32_t p, int loc, int32_t t, const int o[3], int32_t *last,
                         gdt_error *err)
{
    int32_t *tri = c->tri, *opp = c->opp;
    int32_t v[4], outer[4], ids[4];
    int k;
    gdt_status st;

    if (loc == LOC_INSIDE && (o[0] == 0) + (o[1] == 0) + (o[2] == 0) == 1) {
        /* On the edge opposite slot i: split t and its neighbour u. */
        int i = o[0] == 0 ? 0 : o[1] == 0 ? 1 : 2;
        int32_t *T = tri + 3 * (size_t)t;
        int32_t ou = opp[3 * (size_t)t + (size_t)i];
        int32_t u = gdt_opp_tri(ou);
        int j = gdt_opp_slot(ou);
        int32_t *U = tri + 3 * (size_t)u;
        v[0] = T[i], v[1] = T[mesh_next(i)], v[2] = U[j], v[3] = T[mesh_prev(i)];
        outer[0] = opp[3 * (size_t)t + (size_t)mesh_prev(i)];
        outer[1] = opp[3 * (size_t)u + (size_t)mesh_next(j)];
        outer[2] = opp[3 * (size_t)u + (size_t)mesh_prev(j)];
        outer[3] = opp[3 * (size_t)t + (size_t)mesh_next(i)];
        ids[0] = t, ids[1] = u, ids[2] = (int32_t)c->ntris, ids[3] = (int32_t)c->ntris + 1;
        k = 4;
    } else if (loc == LOC_OUTSIDE || (o[0] != 0 && o[1] != 0 && o[2] != 0)) {
        /* Strictly inside t, or in the ghost t: split t in three. */
        const int32_t *T = tri + 3 * (size_t)t;
        v[0] = T[0], v[1] = T[1], v[2] = T[2];
        outer[0] = opp[3 * (size_t)t + 2];
        outer[1] = opp[3 * (size_t)t + 0];
        outer[2] = opp[3 * (size_t)t + 1];
        ids[0] = t, ids[1] = (int32_t)c->ntris, ids[2] = (int32_t)c->ntris + 1;
        k = 3;
    } else {
        const int32_t *T = tri + 3 * (size_t)t;
        int s = o[0] != 0 ? 0 : o[1] != 0 ? 1 : 2;
        if ((o[0] == 0) + (o[1] == 0) + (o[2] == 0) == 2) {
            int32_t q = T[s];
            return gdt_error_set(err, GDT_EINTERNAL, 7341,
                                 "duplicate points: input %d and input %d are both "
                                 "(%lld, %lld); remove duplicates before triangulating",
                                 (int)(q < p ? q : p), (int)(q < p ? p : q), (long long)c->pts[p].x,
                                 (long long)c->pts[p].y);
        }
        return gdt_error_set(err, GDT_EINTERNAL, 7342,
                             "reference triangulator: degenerate triangle %d met while "
                             "inserting point %d",
                             (int)t, (int)p);
    }
    c->ntris += 2; /* both splits add two triangles */
    mesh_fan(tri, opp, p, v, outer, ids, k);

    *last = GDT_MESH_NONE;
    for (int q = 0; q < k; q++) {
        if (*last == GDT_MESH_NONE && !is_ghost(c, ids[q]))
            *last = ids[q];
        if ((st = push(c, ids[q], err)) != GDT_OK)
            return st;
    }
    while (c->top > 0) {
        int32_t f = c->stack[--c->top];
        if (!ref_needs_flip(c, f))
            continue;
        int32_t g = gdt_opp_tri(opp[3 * (size_t)f]);
        mesh_flip(tri, opp, f, 0); /* f = (p, a, d), g = (p, d, b) */
        c->flips++;
        if ((st = push(c, f, err)) != GDT_OK || (st = push(c, g, err)) != GDT_OK)
            return st;
    }
    return GDT_OK;
}

/* Duplicate check for the all-collinear case, where no triangle is built. */
static gdt_status check_distinct(const gdt_ipt *pts, size_t n, gdt_error *err)
{
    gdt_status st = GDT_OK;
    uint64_t *key = malloc(n * sizeof *key), *tkey = malloc(n * sizeof *tkey);
    int32_t *val = malloc(n * sizeof *val), *tval = malloc(n * sizeof *tval);

    if (key == NULL || tkey == NULL || val == NULL || tval == NULL) {
        st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory checking %zu points", n);
        goto fail;
    }
    for (size_t i = 0; i < n; i++) {
        key[i] = ((uint64_t)pts[i].x << 31) | (uint64_t)pts[i].y;
        val[i] = (int32_t)i;
    }
    gdt_mesh_radix_sort(key, val, n, tkey, tval);
    for (size_t i = 1; i < n; i++)
        if (key[i] == key[i - 1]) {
            int32_t a = val[i] < val[i - 1] ? val[i] : val[i - 1];
            int32_t b = val[i] < val[i - 1] ? val[i - 1] : val[i];
            st = gdt_error_set(err, GDT_EINTERNAL, 7341,
                               "duplicate points: input %d and input %d are both (%lld, %lld); "
                               "remove duplicates before triangulating",
                               (int)a, (int)b, (long long)pts[a].x, (long long)pts[a].y);
            goto fail;
        }

fail:
    free(key);
    free(tkey);
    free(val);
    free(tval);
    return st;
}

/* Drops the ghosts: real triangles keep their relative order, pointers to
 * ghosts become hull markers. */
static gdt_status compact(ref_ctx *c, gdt_mesh *out, gdt_error *err)
{
    int32_t *map = malloc(c->ntris * sizeof *map);
    size_t k = 0;

    if (map == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory compacting the mesh");
    for (size_t t = 0; t < c->ntris; t++)
        map[t] = is_ghost(c, (int32_t)t) ? GDT_MESH_NONE : (int32_t)k++;
    for (size_t t = 0; t < c->ntris; t++) {
        int32_t nt = map[t];
        if (nt == GDT_MESH_NONE)
            continue;
        for (int i = 0; i < 3; i++) {
            int32_t o = c->opp[3 * t + (size_t)i];
            int32_t u = map[gdt_opp_tri(o)];
            c->tri[3 * (size_t)nt + (size_t)i] = c->tri[3 * t + (size_t)i];
            c->opp[3 * (size_t)nt + (size_t)i] =
                u == GDT_MESH_NONE ? GDT_MESH_NONE : gdt_opp_pack(u, gdt_opp_slot(o));
        }
    }
    out->ntris = k;
    free(map);
    return GDT_OK;
}

gdt_status gdt_reference_triangulate(gdt_reference_stats *st, const gdt_ipt *pts, size_t n,
                                     gdt_mesh *out, gdt_error *err)
{
    gdt_status s = GDT_OK;
    gdt_reference_stats local;
    ref_ctx c;
    int32_t *order = NULL;

    memset(&local, 0, sizeof local);
    memset(&c, 0, sizeof c);
    if (st == NULL)
        st = &local;
    if (n > GDT_MESH_MAX_VERTS)
        return gdt_error_set(err, GDT_EINTERNAL, 7340,
                             "reference triangulator: %zu points exceed the limit of %zu", n,
                             GDT_MESH_MAX_VERTS);
    for (size_t i = 0; i < n; i++)
        if (pts[i].x < 0 || pts[i].x > GDT_COORD_MAX || pts[i].y < 0 || pts[i].y > GDT_COORD_MAX)
            return gdt_error_set(err, GDT_EINTERNAL, 7340,
                                 "reference triangulator: point %zu at (%lld, %lld) lies "
                                 "outside the tile-local range [0, 2^31-1]",
                                 i, (long long)pts[i].x, (long long)pts[i].y);
    if ((s = gdt_mesh_set_points(out, pts, n, err)) != GDT_OK)
        return s;
    if (n < 3)
        return n == 2 ? check_distinct(pts, n, err) : GDT_OK;
    if ((s = gdt_mesh_reserve(out, n, 2 * n + 4, 0, err)) != GDT_OK)
        return s;
    order = malloc(n * sizeof *order);
    if (order == NULL) {
        s = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory for %zu points", n);
        goto fail;
    }
    if ((s = brio_order(pts, n, order, err)) != GDT_OK)
        goto fail;

    c.ps = &st->pred;
    c.pts = out->pts;
    c.inf = (int32_t)n;
    c.tri = out->tri;
    c.opp = out->opp;
    c.rng = REF_SEED ^ UINT64_C(0x5851f42d4c957f2d);

    /* First triangle: order[0], order[1] and the first point off their line. */
    {
        gdt_ipt p0 = pts[order[0]], p1 = pts[order[1]];
        size_t k = 2;
        int o = 0;
        if (p0.x == p1.x && p0.y == p1.y) {
            s = check_distinct(pts, n, err);
            goto fail;
        }
        while (k < n && (o = gdt_orient2d(c.ps, p0, p1, pts[order[k]])) == 0)
            k++;
        if (k == n) {
            s = check_distinct(pts, n, err); /* all collinear: no triangle */
            goto fail;
        }
        int32_t x = order[2];
        order[2] = order[k];
        order[k] = x;
        if (o < 0) {
            x = order[0];
            order[0] = order[1];
            order[1] = x;
        }
        int32_t v0 = order[0], v1 = order[1], v2 = order[2], inf = c.inf;
        const int32_t init[12] = {v0, v1, v2, v1, v0, inf, v2, v1, inf, v0, v2, inf};
        /* Triangle 0 is real; ghost 1, 2, 3 lies beyond its edge of slot 2, 0, 1
         * (hull edges v0->v1, v1->v2, v2->v0) and faces it with its slot 2;
         * consecutive ghosts share their edges to infinity. */
        const int32_t link[12] = {gdt_opp_pack(2, 2), gdt_opp_pack(3, 2), gdt_opp_pack(1, 2),
                                  gdt_opp_pack(3, 1), gdt_opp_pack(2, 0), gdt_opp_pack(0, 2),
                                  gdt_opp_pack(1, 1), gdt_opp_pack(3, 0), gdt_opp_pack(0, 0),
                                  gdt_opp_pack(2, 1), gdt_opp_pack(1, 0), gdt_opp_pack(0, 1)};
        memcpy(c.tri, init, sizeof init);
        memcpy(c.opp, link, sizeof link);
        c.ntris = 4;
    }

    {
        int32_t last = 0;
        for (size_t k = 3; k < n; k++) {
            int32_t p = order[k];
            int o[3] = {1, 1, 1};
            int32_t t = last;
            int loc = locate(&c, pts[p], &t, o);
            if (loc < 0) {
                s = gdt_error_set(err, GDT_EINTERNAL, 7342,
                                  "reference triangulator: point %d at (%lld, %lld) lies in "
                                  "no triangle",
                                  (int)p, (long long)pts[p].x, (long long)pts[p].y);
                goto fail;
            }
            if ((s = insert(&c, p, loc, t, o, &last, err)) != GDT_OK)
                goto fail;
        }
    }
    if ((s = compact(&c, out, err)) != GDT_OK)
        goto fail;
    s = gdt_flip_to_delaunay(c.ps, &st->final, out, NULL, err);

fail:
    st->walk_steps += c.walk_steps;
    st->insert_flips += c.flips;
    if (s != GDT_OK)
        out->ntris = 0;
    free(order);
    free(c.stack);
    return s;
}
