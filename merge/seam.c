/* The seam merge (see gdt_seam.h for the argument). */
#include "gdt_seam.h"

#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "gdt_predicates.h"

static double now_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

void gdt_seam_free(gdt_seam *s)
{
    if (s == NULL)
        return;
    free(s->v);
    free(s->e);
    memset(s, 0, sizeof *s);
}

static int grow(void **p, size_t *cap, size_t need, size_t elem)
{
    size_t c = *cap > 0 ? *cap : 1024;
    void *q;
    if (need <= *cap)
        return 0;
    while (c < need)
        c *= 2;
    q = realloc(*p, c * elem);
    if (q == NULL)
        return -1;
    *p = q;
    *cap = c;
    return 0;
}

static int cmp_edge(const void *pa, const void *pb)
{
    const gdt_seam_edge *a = pa, *b = pb;
    if (a->a != b->a)
        return a->a < b->a ? -1 : 1;
    return (a->b > b->b) - (a->b < b->b);
}

gdt_status gdt_seam_extract(gdt_seam *s, const gdt_mesh *m, const uint8_t *cert,
                            uint64_t id_base, int64_t dx, int64_t dy, gdt_error *err)
{
    uint8_t *in_u = calloc(m->nverts > 0 ? m->nverts : 1, 1);
    size_t e0 = s->ne;
    gdt_status st = GDT_OK;

    if (in_u == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    if (m->ntris == 0)
        memset(in_u, 1, m->nverts);
    for (size_t t = 0; t < m->ntris; t++) {
        const int32_t *v = &m->tri[3 * t];
        for (int i = 0; i < 3; i++) {
            int32_t o = m->opp[3 * t + i];
            int nb_cert = o != GDT_MESH_NONE && cert[gdt_opp_tri(o)];
            if (!cert[t]) {
                in_u[v[i]] = 1;
                continue;
            }
            if (o == GDT_MESH_NONE) {
                in_u[v[(i + 1) % 3]] = 1;
                in_u[v[(i + 2) % 3]] = 1;
            }
            if (!nb_cert) {
                if (grow((void **)&s->e, &s->cap_e, s->ne + 1, sizeof *s->e) != 0) {
                    st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
                    goto fail;
                }
                s->e[s->ne].a = id_base + (uint64_t)v[(i + 1) % 3];
                s->e[s->ne].b = id_base + (uint64_t)v[(i + 2) % 3];
                s->ne++;
            }
        }
        /* hull edges of uncertified triangles: their vertices are already in */
    }
    for (size_t i = 0; i < m->nverts; i++) {
        int64_t x, y;
        if (!in_u[i])
            continue;
        x = m->pts[i].x + dx;
        y = m->pts[i].y + dy;
        if (x < 0 || y < 0 || x > GDT_COORD_MAX || y > GDT_COORD_MAX) {
            st = gdt_error_set(err, GDT_EINPUT, 3811,
                               "the cloud spans more than 2^31 - 1 lattice steps on an axis "
                               "(point at %lld, %lld from its corner); the seam merge needs "
                               "a coarser --quantum",
                               (long long)x, (long long)y);
            goto fail;
        }
        if (grow((void **)&s->v, &s->cap_v, s->nv + 1, sizeof *s->v) != 0) {
            st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
            goto fail;
        }
        s->v[s->nv].id = id_base + i;
        s->v[s->nv].x = x;
        s->v[s->nv].y = y;
        s->nv++;
    }
    qsort(s->e + e0, s->ne - e0, sizeof *s->e, cmp_edge);
fail:
    free(in_u);
    return st;
}

/* Open-addressing map from a directed edge (local vertex indices) to the
 * packed (triangle, slot) that traverses it.  Capacity: a power of two at
 * least twice the number of keys, so probes stay short. */
typedef struct edge_map {
    uint64_t *key; /* (a << 32 | b) + 1; 0 = empty */
    int32_t *val;
    size_t mask;
} edge_map;

static uint64_t mix(uint64_t k)
{
    k ^= k >> 33;
    k *= UINT64_C(0xff51afd7ed558ccd);
    k ^= k >> 33;
    return k;
}

static int edge_map_init(edge_map *em, size_t keys)
{
    size_t cap = 16;
    while (cap < 2 * keys)
        cap *= 2;
    em->key = calloc(cap, sizeof *em->key);
    em->val = malloc(cap * sizeof *em->val);
    em->mask = cap - 1;
    return em->key == NULL || em->val == NULL ? -1 : 0;
}

static void edge_map_put(edge_map *em, uint32_t a, uint32_t b, int32_t v)
{
    uint64_t k = (((uint64_t)a << 32) | b) + 1;
    size_t i = (size_t)mix(k) & em->mask;
    while (em->key[i] != 0)
        i = (i + 1) & em->mask;
    em->key[i] = k;
    em->val[i] = v;
}

static int32_t edge_map_get(const edge_map *em, uint32_t a, uint32_t b)
{
    uint64_t k = (((uint64_t)a << 32) | b) + 1;
    size_t i = (size_t)mix(k) & em->mask;
    while (em->key[i] != 0) {
        if (em->key[i] == k)
            return em->val[i];
        i = (i + 1) & em->mask;
    }
    return GDT_MESH_NONE;
}

static int find_vertex(const gdt_seam *s, uint64_t id, uint32_t *out)
{
    size_t lo = 0, hi = s->nv;
    while (lo < hi) {
        size_t mid = lo + (hi - lo) / 2;
        if (s->v[mid].id < id)
            lo = mid + 1;
        else
            hi = mid;
    }
    if (lo == s->nv || s->v[lo].id != id)
        return -1;
    *out = (uint32_t)lo;
    return 0;
}

static int cmp_face(const void *pa, const void *pb)
{
    const uint64_t *a = pa, *b = pb;
    for (int i = 0; i < 3; i++)
        if (a[i] != b[i])
            return a[i] < b[i] ? -1 : 1;
    return 0;
}

/* Flags per slot of DT(U): bit 0 barrier edge; per triangle: bit 1 covered
 * (over C), bit 2 on the uncovered side of some barrier edge. */
#define SLOT_BARRIER 1u
#define TRI_COVERED 2u
#define TRI_RSIDE 4u

gdt_status gdt_merge_seams(const gdt_seam *s, uint64_t **faces_out, size_t *nfaces_out,
                           gdt_merge_stats *ms, gdt_error *err)
{
    gdt_mesh dt;
    gdt_ipt *pts = NULL;
    edge_map em = {NULL, NULL, 0};
    uint8_t *slot = NULL, *tri = NULL;
    int32_t *stack = NULL;
    uint64_t *faces = NULL;
    size_t nstack = 0, nf = 0;
    gdt_status st;
    double t0 = now_s();

    gdt_mesh_init(&dt);
    memset(ms, 0, sizeof *ms);
    *faces_out = NULL;
    *nfaces_out = 0;
    ms->seam_vertices = s->nv;
    ms->barrier_edges = s->ne;
    for (size_t i = 1; i < s->nv; i++)
        if (s->v[i].id <= s->v[i - 1].id)
            return gdt_error_set(err, GDT_EINTERNAL, 7810,
                                 "seam vertex ids not increasing at %zu", i);
    pts = malloc((s->nv > 0 ? s->nv : 1) * sizeof *pts);
    if (pts == NULL) {
        st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        goto fail;
    }
    for (size_t i = 0; i < s->nv; i++) {
        pts[i].x = s->v[i].x;
        pts[i].y = s->v[i].y;
    }
    st = gdt_reference_triangulate(&ms->ref, pts, s->nv, &dt, err);
    if (st != GDT_OK)
        goto fail;
    ms->seam_triangles = dt.ntris;
    ms->t_triangulate = now_s() - t0;
    t0 = now_s();

    for (size_t t = 0; t < dt.ntris; t++)
        for (int i = 0; i < 3; i++)
            if (dt.opp[3 * t + i] == GDT_MESH_NONE)
                ms->hull_vertices++;

    slot = calloc(3 * dt.ntris + 1, 1);
    tri = calloc(dt.ntris + 1, 1);
    stack = malloc((dt.ntris + 1) * sizeof *stack);
    if (slot == NULL || tri == NULL || stack == NULL || edge_map_init(&em, 3 * dt.ntris) != 0) {
        st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        goto fail;
    }
    for (size_t t = 0; t < dt.ntris; t++)
        for (int i = 0; i < 3; i++)
            edge_map_put(&em, (uint32_t)dt.tri[3 * t + (i + 1) % 3],
                         (uint32_t)dt.tri[3 * t + (i + 2) % 3], gdt_opp_pack((int32_t)t, i));

    /* Seeds: the triangle left of each barrier edge lies over C. */
    for (size_t k = 0; k < s->ne; k++) {
        uint32_t a, b;
        int32_t o, t, i, twin;
        if (find_vertex(s, s->e[k].a, &a) != 0 || find_vertex(s, s->e[k].b, &b) != 0) {
            st = gdt_error_set(err, GDT_EINTERNAL, 7812,
                               "barrier edge %llu-%llu names a vertex that is not a seam vertex",
                               (unsigned long long)s->e[k].a, (unsigned long long)s->e[k].b);
            goto fail;
        }
        o = edge_map_get(&em, a, b);
        if (o == GDT_MESH_NONE) {
            st = gdt_error_set(err, GDT_EINTERNAL, 7811,
                               "barrier edge %llu-%llu is not an edge of the seam "
                               "triangulation: a certified triangle is not Delaunay",
                               (unsigned long long)s->e[k].a, (unsigned long long)s->e[k].b);
            goto fail;
        }
        t = gdt_opp_tri(o);
        i = gdt_opp_slot(o);
        slot[3 * t + i] |= SLOT_BARRIER;
        twin = dt.opp[3 * t + i];
        if (twin != GDT_MESH_NONE) {
            slot[3 * gdt_opp_tri(twin) + gdt_opp_slot(twin)] |= SLOT_BARRIER;
            tri[gdt_opp_tri(twin)] |= TRI_RSIDE;
        }
        if (!(tri[t] & TRI_COVERED)) {
            tri[t] |= TRI_COVERED;
            stack[nstack++] = t;
        }
    }
    /* Flood over C without crossing a barrier edge. */
    while (nstack > 0) {
        int32_t t = stack[--nstack];
        for (int i = 0; i < 3; i++) {
            int32_t o = dt.opp[3 * t + i], u;
            if (o == GDT_MESH_NONE || (slot[3 * t + i] & SLOT_BARRIER))
                continue;
            u = gdt_opp_tri(o);
            if (!(tri[u] & TRI_COVERED)) {
                tri[u] |= TRI_COVERED;
                stack[nstack++] = u;
            }
        }
    }
    for (size_t t = 0; t < dt.ntris; t++) {
        if ((tri[t] & (TRI_COVERED | TRI_RSIDE)) == (TRI_COVERED | TRI_RSIDE)) {
            st = gdt_error_set(err, GDT_EINTERNAL, 7811,
                               "seam triangle %zu lies on both sides of the certified "
                               "region's border: a certified triangle is not Delaunay", t);
            goto fail;
        }
        if (tri[t] & TRI_COVERED)
            ms->covered++;
    }
    nf = dt.ntris - ms->covered;
    faces = malloc((3 * nf + 1) * sizeof *faces);
    if (faces == NULL) {
        st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        goto fail;
    }
    nf = 0;
    for (size_t t = 0; t < dt.ntris; t++) {
        uint64_t f[3];
        int r = 0;
        if (tri[t] & TRI_COVERED)
            continue;
        for (int i = 0; i < 3; i++)
            f[i] = s->v[dt.tri[3 * t + i]].id;
        if (f[1] < f[r])
            r = 1;
        if (f[2] < f[r])
            r = 2;
        for (int i = 0; i < 3; i++)
            faces[3 * nf + i] = f[(r + i) % 3];
        nf++;
    }
    qsort(faces, nf, 3 * sizeof *faces, cmp_face);
    ms->faces = nf;
    ms->t_classify = now_s() - t0;
    *faces_out = faces;
    *nfaces_out = nf;
    faces = NULL;
    st = GDT_OK;
fail:
    free(faces);
    free(stack);
    free(tri);
    free(slot);
    free(em.key);
    free(em.val);
    free(pts);
    gdt_mesh_free(&dt);
    return st;
}
