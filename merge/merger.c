/* The seam merge by rows (see gdt_seam.h for the argument and the names
 * W_r, walls, covered / emitted / pending). */
#include "gdt_seam.h"

#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "gdt_predicates.h"
#include "gdt_grow.h"

/* Per slot of DT(W_r). */
#define SLOT_WALL 1u   /* the directed edge of this slot is a wall */
#define SLOT_HANDED 2u /* already handed on (a wall listed twice goes on once) */
/* Per triangle of DT(W_r). */
#define TRI_COVERED 1u
#define TRI_RSIDE 2u /* right of a wall whose reverse is no wall: must stay uncovered */
#define TRI_PENDING 4u
#define TRI_EMITTED 8u

/* Open-addressing map from a directed edge (band indices a -> b) to the
 * packed (triangle, slot) that traverses it.  Capacity: a power of two at
 * least twice the number of keys, so probes stay short. */
typedef struct edge_map {
    uint64_t *key; /* (a << 32 | b) + 1; 0 = empty */
    int32_t *val;
    size_t cap;  /* allocated entries */
    size_t mask; /* entries in use - 1 */
} edge_map;

struct gdt_merger {
    gdt_seam_vertex *w; /* the band, by increasing id */
    size_t nw, cap_w;
    gdt_seam_edge *wall; /* walls of the round: handed-on ones, then the row's */
    size_t nwall, cap_wall;
    gdt_seam_edge *next; /* walls handed on */
    size_t nnext, cap_next;
    size_t *wall_slot; /* per wall, the slot 3t + i of DT(W_r) traversing it */
    size_t cap_wall_slot;
    gdt_ipt *pts;
    size_t cap_pts;
    gdt_mesh dt;
    edge_map em;
    uint8_t *slot, *tri, *keep;
    size_t cap_slot, cap_tri, cap_keep;
    int32_t *stack;
    size_t cap_stack;
    uint64_t *faces;
    size_t cap_faces;
    gdt_ipt *fpts; /* the faces' vertices (merge frame) */
    double *fz;    /* and their z */
    size_t cap_fpts, cap_fz;
    size_t nw_carried;    /* band vertices handed on by the last triangulated round */
    size_t nwall_carried; /* walls handed on by it (the first walls of the list) */
    uint64_t last_id; /* largest id so far (valid when have_id) */
    int64_t x0, x1;   /* every vertex has x0 <= x <= x1 */
    int64_t y_floor;  /* every vertex of later rounds has y >= y_floor (the
                         largest y_next so far; valid when have_floor) */
    int have_id, have_floor, finished;
    gdt_merge_stats st;
};

static double now_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static int grow(void *pp, size_t *cap, size_t need, size_t elem)
{
    return gdt_grow(pp, cap, need, elem, 256);
}

static uint64_t mix(uint64_t k)
{
    k ^= k >> 33;
    k *= UINT64_C(0xff51afd7ed558ccd);
    k ^= k >> 33;
    return k;
}

/* Empties the map for up to keys entries. */
static int edge_map_reset(edge_map *em, size_t keys)
{
    size_t cap = 16;
    while (cap < 2 * keys)
        cap *= 2;
    if (cap > em->cap) {
        uint64_t *k = realloc(em->key, cap * sizeof *k);
        int32_t *v;
        if (k == NULL)
            return -1;
        em->key = k;
        v = realloc(em->val, cap * sizeof *v);
        if (v == NULL)
            return -1;
        em->val = v;
        em->cap = cap;
    }
    memset(em->key, 0, cap * sizeof *em->key);
    em->mask = cap - 1;
    return 0;
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

/* The slot 3t + i of a packed opposite pointer. */
static size_t slot_of(int32_t o)
{
    return 3 * (size_t)gdt_opp_tri(o) + (size_t)gdt_opp_slot(o);
}

/* Index of the band vertex with this id (the band is sorted by id). */
static int find_vertex(const gdt_merger *m, uint64_t id, uint32_t *out)
{
    size_t lo = 0, hi = m->nw;
    while (lo < hi) {
        size_t mid = lo + (hi - lo) / 2;
        if (m->w[mid].id < id)
            lo = mid + 1;
        else
            hi = mid;
    }
    if (lo == m->nw || m->w[lo].id != id)
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

/* Bytes held by the merger's arrays. */
static uint64_t held_bytes(const gdt_merger *m)
{
    uint64_t b = sizeof *m;
    b += m->cap_w * sizeof *m->w + m->cap_wall * sizeof *m->wall + m->cap_next * sizeof *m->next +
         m->cap_wall_slot * sizeof *m->wall_slot + m->cap_pts * sizeof *m->pts;
    b += m->dt.cap_verts * (sizeof *m->dt.pts + (m->dt.ids != NULL ? sizeof *m->dt.ids : 0));
    b += m->dt.cap_tris * 3 * (sizeof *m->dt.tri + sizeof *m->dt.opp);
    b += m->em.cap * (sizeof *m->em.key + sizeof *m->em.val);
    b += m->cap_fpts * sizeof *m->fpts + m->cap_fz * sizeof *m->fz;
    b += m->cap_slot + m->cap_tri + m->cap_keep + m->cap_stack * sizeof *m->stack +
         m->cap_faces * sizeof *m->faces;
    return b;
}

gdt_status gdt_merger_create(gdt_merger **out, int64_t x0, int64_t x1, gdt_error *err)
{
    gdt_merger *m;
    *out = NULL;
    if (x0 < 0 || x0 > x1 || x1 > GDT_COORD_MAX)
        return gdt_error_set(err, GDT_EINTERNAL, 7814,
                             "seam merge x range [%lld, %lld] is not within [0, 2^31 - 1]",
                             (long long)x0, (long long)x1);
    m = calloc(1, sizeof *m);
    if (m == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    gdt_mesh_init(&m->dt);
    m->x0 = x0;
    m->x1 = x1;
    *out = m;
    return GDT_OK;
}

void gdt_merger_destroy(gdt_merger *m)
{
    if (m == NULL)
        return;
    free(m->w);
    free(m->wall);
    free(m->next);
    free(m->wall_slot);
    free(m->pts);
    gdt_mesh_free(&m->dt);
    free(m->em.key);
    free(m->em.val);
    free(m->slot);
    free(m->tri);
    free(m->keep);
    free(m->stack);
    free(m->faces);
    free(m->fpts);
    free(m->fz);
    free(m);
}

const gdt_ipt *gdt_merger_face_points(const gdt_merger *m)
{
    return m->fpts;
}

const double *gdt_merger_face_z(const gdt_merger *m)
{
    return m->fz;
}


const gdt_merge_stats *gdt_merger_stats(const gdt_merger *m)
{
    return &m->st;
}

static gdt_status no_memory(gdt_error *err)
{
    return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
}

/* Appends the directed edge a -> b (band indices) to the walls handed on. */
static int hand_on(gdt_merger *m, uint32_t a, uint32_t b)
{
    if (grow(&m->next, &m->cap_next, m->nnext + 1, sizeof *m->next) != 0)
        return -1;
    m->next[m->nnext].a = m->w[a].id;
    m->next[m->nnext].b = m->w[b].id;
    m->nnext++;
    return 0;
}

gdt_status gdt_merger_round(gdt_merger *m, const gdt_seam *row, int64_t y_next, int last,
                            const uint64_t **faces_out, size_t *nfaces_out, gdt_error *err)
{
    const gdt_mesh *dt = &m->dt;
    size_t nstack = 0, nf = 0, ncov = 0, nhull = 0, nt, nkeep;
    double t0 = now_s();
    gdt_status st;

    *faces_out = NULL;
    *nfaces_out = 0;
    if (m->finished)
        return gdt_error_set(err, GDT_EINTERNAL, 7813, "a seam merge round after the last one");
    for (size_t i = 0; i < row->nv; i++) {
        if (m->have_id && row->v[i].id <= m->last_id) {
            st = gdt_error_set(err, GDT_EINTERNAL, 7810,
                               "seam vertex ids not increasing at %zu of round %llu", i,
                               (unsigned long long)m->st.rounds);
            goto fail;
        }
        m->last_id = row->v[i].id;
        m->have_id = 1;
        /* Q of the earlier rounds' finality test must hold every later vertex */
        if (row->v[i].x < m->x0 || row->v[i].x > m->x1 ||
            (m->have_floor && row->v[i].y < m->y_floor)) {
            st = gdt_error_set(err, GDT_EINTERNAL, 7814,
                               "seam vertex %llu at (%lld, %lld) of round %llu lies outside "
                               "[%lld, %lld] x [%lld, inf), where the earlier rounds assumed "
                               "every later vertex",
                               (unsigned long long)row->v[i].id, (long long)row->v[i].x,
                               (long long)row->v[i].y, (unsigned long long)m->st.rounds,
                               (long long)m->x0, (long long)m->x1,
                               (long long)(m->have_floor ? m->y_floor : 0));
            goto fail;
        }
    }
    if (grow(&m->w, &m->cap_w, m->nw + row->nv, sizeof *m->w) != 0 ||
        grow(&m->wall, &m->cap_wall, m->nwall + row->ne, sizeof *m->wall) != 0) {
        st = no_memory(err);
        goto fail;
    }
    if (row->nv > 0)
        memcpy(m->w + m->nw, row->v, row->nv * sizeof *row->v);
    if (row->ne > 0)
        memcpy(m->wall + m->nwall, row->e, row->ne * sizeof *row->e);
    m->nw += row->nv;
    m->nwall += row->ne;
    m->st.rounds++;
    m->st.seam_vertices += row->nv;
    m->st.barrier_edges += row->ne;
    if (m->nw > m->st.max_band_vertices)
        m->st.max_band_vertices = m->nw;
    if (m->nwall > m->st.max_walls)
        m->st.max_walls = m->nwall;
    /* A row that adds fewer than half as many vertices as the band carries
     * joins the next round's band instead (gdt_seam.h, "Deferred rows"):
     * the triangulations then cost O(|U|) vertices in all, where a band
     * that keeps most of its vertices (a strip whose every point is a hull
     * point) would cost O(|U|) per row. */
    if (!last && 2 * (m->nw - m->nw_carried) < m->nw_carried) {
        m->st.deferred++;
        return GDT_OK;
    }

    if (grow(&m->pts, &m->cap_pts, m->nw + 1, sizeof *m->pts) != 0) {
        st = no_memory(err);
        goto fail;
    }
    for (size_t i = 0; i < m->nw; i++) {
        m->pts[i].x = m->w[i].x;
        m->pts[i].y = m->w[i].y;
    }
    st = gdt_reference_triangulate(&m->st.ref, m->pts, m->nw, &m->dt, err);
    if (st != GDT_OK)
        goto fail;
    nt = dt->ntris;
    m->st.seam_triangles += nt;
    m->st.t_triangulate += now_s() - t0;
    t0 = now_s();

    if (grow(&m->slot, &m->cap_slot, 3 * nt + 1, 1) != 0 ||
        grow(&m->tri, &m->cap_tri, nt + 1, 1) != 0 ||
        grow(&m->keep, &m->cap_keep, m->nw + 1, 1) != 0 ||
        grow(&m->stack, &m->cap_stack, nt + 1, sizeof *m->stack) != 0 ||
        grow(&m->wall_slot, &m->cap_wall_slot, m->nwall + 1, sizeof *m->wall_slot) != 0 ||
        edge_map_reset(&m->em, 3 * nt) != 0) {
        st = no_memory(err);
        goto fail;
    }
    memset(m->slot, 0, 3 * nt);
    memset(m->tri, 0, nt);
    memset(m->keep, 0, m->nw);
    for (size_t t = 0; t < nt; t++)
        for (int i = 0; i < 3; i++)
            edge_map_put(&m->em, (uint32_t)dt->tri[3 * t + (i + 1) % 3],
                         (uint32_t)dt->tri[3 * t + (i + 2) % 3], gdt_opp_pack((int32_t)t, i));

    /* Seeds: the triangle left of each wall is covered (I3). */
    for (size_t k = 0; k < m->nwall; k++) {
        uint32_t a, b;
        int32_t o, t;
        if (find_vertex(m, m->wall[k].a, &a) != 0 || find_vertex(m, m->wall[k].b, &b) != 0) {
            st = gdt_error_set(err, GDT_EINTERNAL, 7812,
                               "border edge %llu-%llu of round %llu names a vertex that is "
                               "not in the seam band",
                               (unsigned long long)m->wall[k].a, (unsigned long long)m->wall[k].b,
                               (unsigned long long)m->st.rounds);
            goto fail;
        }
        o = edge_map_get(&m->em, a, b);
        if (o == GDT_MESH_NONE) {
            st = gdt_error_set(err, GDT_EINTERNAL, 7811,
                               "%s edge %llu-%llu is not an edge of the seam triangulation "
                               "of round %llu: a certified triangle is not Delaunay",
                               k < m->nwall_carried ? "border" : "barrier",
                               (unsigned long long)m->wall[k].a, (unsigned long long)m->wall[k].b,
                               (unsigned long long)m->st.rounds);
            goto fail;
        }
        m->wall_slot[k] = slot_of(o);
        m->slot[slot_of(o)] |= SLOT_WALL;
        t = gdt_opp_tri(o);
        if (!(m->tri[t] & TRI_COVERED)) {
            m->tri[t] |= TRI_COVERED;
            m->stack[nstack++] = t;
        }
    }
    for (size_t k = 0; k < m->nwall; k++) {
        int32_t twin = dt->opp[m->wall_slot[k]];
        if (twin != GDT_MESH_NONE && !(m->slot[slot_of(twin)] & SLOT_WALL))
            m->tri[gdt_opp_tri(twin)] |= TRI_RSIDE;
    }
    /* The flood never crosses a wall. */
    while (nstack > 0) {
        int32_t t = m->stack[--nstack];
        for (int i = 0; i < 3; i++) {
            int32_t o = dt->opp[3 * t + i], u;
            if (o == GDT_MESH_NONE || (m->slot[3 * t + i] & SLOT_WALL))
                continue;
            u = gdt_opp_tri(o);
            if (!(m->tri[u] & TRI_COVERED)) {
                m->tri[u] |= TRI_COVERED;
                m->stack[nstack++] = u;
            }
        }
    }

    /* Classification; the band vertices to keep. */
    for (size_t t = 0; t < nt; t++) {
        const int32_t *v = &dt->tri[3 * t];
        int final = last;
        if ((m->tri[t] & (TRI_COVERED | TRI_RSIDE)) == (TRI_COVERED | TRI_RSIDE)) {
            st = gdt_error_set(err, GDT_EINTERNAL, 7811,
                               "seam triangle %zu of round %llu lies on both sides of the "
                               "certified region's border: a certified triangle is not "
                               "Delaunay",
                               t, (unsigned long long)m->st.rounds);
            goto fail;
        }
        for (int i = 0; i < 3; i++)
            if (dt->opp[3 * t + i] == GDT_MESH_NONE) {
                m->keep[v[(i + 1) % 3]] = 1;
                m->keep[v[(i + 2) % 3]] = 1;
                nhull++;
            }
        if (m->tri[t] & TRI_COVERED) {
            ncov++;
            continue;
        }
        if (!final)
            final = gdt_circumdisk_misses_strip(NULL, m->pts[v[0]], m->pts[v[1]], m->pts[v[2]],
                                                m->x0, m->x1, y_next);
        if (final) {
            m->tri[t] |= TRI_EMITTED;
            nf++;
        } else {
            m->tri[t] |= TRI_PENDING;
            m->keep[v[0]] = m->keep[v[1]] = m->keep[v[2]] = 1;
        }
    }
    if (nt == 0)
        memset(m->keep, 1, m->nw);
    m->st.covered += ncov;

    if (grow(&m->faces, &m->cap_faces, 3 * nf + 3, sizeof *m->faces) != 0) {
        st = no_memory(err);
        goto fail;
    }
    nf = 0;
    for (size_t t = 0; t < nt; t++) {
        uint64_t f[3];
        int r = 0;
        if (!(m->tri[t] & TRI_EMITTED))
            continue;
        for (int i = 0; i < 3; i++)
            f[i] = m->w[dt->tri[3 * t + i]].id;
        if (f[1] < f[r])
            r = 1;
        if (f[2] < f[r])
            r = 2;
        for (int i = 0; i < 3; i++)
            m->faces[3 * nf + i] = f[(r + i) % 3];
        nf++;
    }
    qsort(m->faces, nf, 3 * sizeof *m->faces, cmp_face);
    m->st.faces += nf;
    /* their coordinates, while the band still holds every vertex (by
     * increasing id) */
    if (grow(&m->fpts, &m->cap_fpts, 3 * nf + 3, sizeof *m->fpts) != 0 ||
        grow(&m->fz, &m->cap_fz, 3 * nf + 3, sizeof *m->fz) != 0) {
        st = no_memory(err);
        goto fail;
    }
    for (size_t i = 0; i < 3 * nf; i++) {
        size_t lo = 0, hi = m->nw;
        while (hi - lo > 1) {
            size_t mid = lo + (hi - lo) / 2;
            if (m->w[mid].id <= m->faces[i])
                lo = mid;
            else
                hi = mid;
        }
        m->fpts[i].x = m->w[lo].x;
        m->fpts[i].y = m->w[lo].y;
        m->fz[i] = m->w[lo].z;
    }

    /* Walls handed on: right side pending or outside the hull. */
    m->nnext = 0;
    for (size_t k = 0; !last && k < m->nwall; k++) {
        size_t o = m->wall_slot[k], t = o / 3, i = o % 3;
        int32_t twin = dt->opp[o];
        if (m->slot[o] & SLOT_HANDED)
            continue;
        m->slot[o] |= SLOT_HANDED;
        if ((twin == GDT_MESH_NONE || (m->tri[gdt_opp_tri(twin)] & TRI_PENDING)) &&
            hand_on(m, (uint32_t)dt->tri[3 * t + (i + 1) % 3],
                    (uint32_t)dt->tri[3 * t + (i + 2) % 3]) != 0) {
            st = no_memory(err);
            goto fail;
        }
    }
    for (size_t t = 0; !last && t < nt; t++) {
        if (!(m->tri[t] & TRI_EMITTED))
            continue;
        for (int i = 0; i < 3; i++) {
            int32_t twin = dt->opp[3 * t + i];
            if ((twin == GDT_MESH_NONE || (m->tri[gdt_opp_tri(twin)] & TRI_PENDING)) &&
                hand_on(m, (uint32_t)dt->tri[3 * t + (i + 1) % 3],
                        (uint32_t)dt->tri[3 * t + (i + 2) % 3]) != 0) {
                st = no_memory(err);
                goto fail;
            }
        }
    }
    {
        uint64_t bytes = held_bytes(m);
        if (bytes > m->st.peak_bytes)
            m->st.peak_bytes = bytes;
    }
    if (last) {
        m->st.hull_vertices = nhull;
        m->finished = 1;
        m->nw = 0;
        m->nwall = 0;
        m->nw_carried = 0;
        m->nwall_carried = 0;
    } else {
        gdt_seam_edge *swap = m->wall;
        size_t cap = m->cap_wall;
        if (!m->have_floor || y_next > m->y_floor)
            m->y_floor = y_next;
        m->have_floor = 1;
        nkeep = 0;
        for (size_t i = 0; i < m->nw; i++)
            if (m->keep[i])
                m->w[nkeep++] = m->w[i];
        m->nw = nkeep;
        m->wall = m->next;
        m->cap_wall = m->cap_next;
        m->nwall = m->nnext;
        m->next = swap;
        m->cap_next = cap;
        m->nnext = 0;
        m->nw_carried = m->nw;
        m->nwall_carried = m->nwall;
    }
    m->st.t_classify += now_s() - t0;
    *faces_out = m->faces;
    *nfaces_out = nf;
    return GDT_OK;
fail:
    return st;
}

gdt_status gdt_merge_seams(const gdt_seam *s, uint64_t **faces_out, size_t *nfaces_out,
                           gdt_merge_stats *ms, gdt_error *err)
{
    gdt_merger *m = NULL;
    const uint64_t *f = NULL;
    uint64_t *faces = NULL;
    size_t nf = 0;
    gdt_status st;

    *faces_out = NULL;
    *nfaces_out = 0;
    memset(ms, 0, sizeof *ms);
    /* one round, the last: no finality test, so the widest x range */
    st = gdt_merger_create(&m, 0, GDT_COORD_MAX, err);
    if (st == GDT_OK)
        st = gdt_merger_round(m, s, 0, 1, &f, &nf, err);
    if (st != GDT_OK)
        goto fail;
    faces = malloc((3 * nf + 1) * sizeof *faces);
    if (faces == NULL) {
        st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        goto fail;
    }
    if (nf > 0)
        memcpy(faces, f, 3 * nf * sizeof *faces);
    *ms = m->st;
    *faces_out = faces;
    *nfaces_out = nf;
fail:
    gdt_merger_destroy(m);
    return st;
}
