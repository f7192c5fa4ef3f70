/* mesh.c — storage of gdt_mesh, combinatorial linking, canonical form and
 * the sorting helper shared by the mesh modules. */
#include "gdt_mesh.h"

#include <stdlib.h>
#include <string.h>

#include "private/mesh_ops.h"

void gdt_mesh_init(gdt_mesh *m)
{
    memset(m, 0, sizeof *m);
}

void gdt_mesh_free(gdt_mesh *m)
{
    if (m == NULL)
        return;
    free(m->pts);
    free(m->ids);
    free(m->tri);
    free(m->opp);
    gdt_mesh_init(m);
}

/* Resizes the array whose pointer is at pp (the address of a pointer of any
 * object type); the pointer is read and written with memcpy, not through a
 * void ** lvalue, which strict aliasing would let the optimiser ignore. */
static int grow(void *pp, size_t count, size_t size)
{
    void *p, *q;
    memcpy(&p, pp, sizeof p);
    q = realloc(p, count * size);
    if (q == NULL)
        return -1;
    memcpy(pp, &q, sizeof q);
    return 0;
}

gdt_status gdt_mesh_reserve(gdt_mesh *m, size_t nverts, size_t ntris, int with_ids, gdt_error *err)
{
    if (nverts > GDT_MESH_MAX_VERTS || ntris > GDT_MESH_MAX_TRIS)
        return gdt_error_set(err, GDT_EINTERNAL, 7301,
                             "mesh of %zu vertices and %zu triangles exceeds the limits "
                             "(%zu vertices, %zu triangles)",
                             nverts, ntris, GDT_MESH_MAX_VERTS, GDT_MESH_MAX_TRIS);
    if (nverts > m->cap_verts || (with_ids && m->ids == NULL)) {
        size_t cap = nverts > m->cap_verts ? nverts : m->cap_verts;
        size_t alloc = cap > 0 ? cap : 1;
        if (grow(&m->pts, alloc, sizeof *m->pts) != 0)
            goto oom;
        if ((with_ids || m->ids != NULL) && grow(&m->ids, alloc, sizeof *m->ids) != 0)
            goto oom;
        m->cap_verts = cap;
    }
    if (ntris > m->cap_tris) {
        if (grow(&m->tri, 3 * ntris, sizeof *m->tri) != 0)
            goto oom;
        if (grow(&m->opp, 3 * ntris, sizeof *m->opp) != 0)
            goto oom;
        m->cap_tris = ntris;
    }
    return GDT_OK;

oom:
    return gdt_error_set(err, GDT_EINTERNAL, 7001,
                         "out of memory for a mesh of %zu vertices and %zu triangles", nverts,
                         ntris);
}

gdt_status gdt_mesh_set_points(gdt_mesh *m, const gdt_ipt *pts, size_t n, gdt_error *err)
{
    gdt_status st = gdt_mesh_reserve(m, n, 0, 0, err);
    if (st != GDT_OK)
        return st;
    if (n > 0)
        memcpy(m->pts, pts, n * sizeof *pts);
    if (m->ids != NULL)
        for (size_t i = 0; i < n; i++)
            m->ids[i] = (int64_t)i;
    m->nverts = n;
    m->ntris = 0;
    return GDT_OK;
}

/* One half-edge in the edge table: the larger end vertex and the packed
 * (triangle, slot) it belongs to; the table is grouped by the smaller end. */
typedef struct half_edge {
    int32_t hi;
    int32_t he;
} half_edge;

static int half_edge_cmp(const void *x, const void *y)
{
    const half_edge *a = x, *b = y;
    if (a->hi != b->hi)
        return a->hi < b->hi ? -1 : 1;
    return (a->he > b->he) - (a->he < b->he);
}

static void sort_half_edges(half_edge *e, size_t n)
{
    if (n > 24) {
        qsort(e, n, sizeof *e, half_edge_cmp);
        return;
    }
    for (size_t i = 1; i < n; i++) {
        half_edge x = e[i];
        size_t j = i;
        while (j > 0 && half_edge_cmp(&e[j - 1], &x) > 0) {
            e[j] = e[j - 1];
            j--;
        }
        e[j] = x;
    }
}

/* design: counting sort of the 3F half-edges by their smaller end vertex
 * (CSR), then each vertex's short list is sorted by the larger end, so the
 * one or two half-edges of an edge are adjacent.  Linear apart from those
 * small sorts. */
gdt_status gdt_mesh_adjacency(const int32_t *tri, size_t ntris, size_t nverts, int32_t *opp,
                              gdt_error *err)
{
    gdt_status st = GDT_OK;
    uint32_t *start = NULL;
    half_edge *tab = NULL;

    if (ntris > GDT_MESH_MAX_TRIS || nverts > (size_t)INT32_MAX) {
        st = gdt_error_set(err, GDT_EINTERNAL, 7302,
                           "cannot link %zu triangles over %zu vertices: over the limits", ntris,
                           nverts);
        goto fail;
    }
    for (size_t t = 0; t < ntris; t++) {
        const int32_t *T = tri + 3 * t;
        for (int i = 0; i < 3; i++)
            if (T[i] < 0 || (size_t)T[i] >= nverts) {
                st = gdt_error_set(err, GDT_EINTERNAL, 7302,
                                   "triangle %zu slot %d: vertex index %d outside [0, %zu)", t, i,
                                   (int)T[i], nverts);
                goto fail;
            }
        if (T[0] == T[1] || T[1] == T[2] || T[2] == T[0]) {
            st = gdt_error_set(err, GDT_EINTERNAL, 7302,
                               "triangle %zu repeats a vertex: (%d, %d, %d)", t, (int)T[0],
                               (int)T[1], (int)T[2]);
            goto fail;
        }
    }
    start = calloc(nverts + 1, sizeof *start);
    tab = malloc((3 * ntris > 0 ? 3 * ntris : 1) * sizeof *tab);
    if (start == NULL || tab == NULL) {
        st = gdt_error_set(err, GDT_EINTERNAL, 7001,
                           "out of memory for the edge table of %zu triangles", ntris);
        goto fail;
    }
    for (size_t h = 0; h < 3 * ntris; h++) {
        int32_t a = tri[3 * (h / 3) + (size_t)mesh_next((int)(h % 3))];
        int32_t b = tri[3 * (h / 3) + (size_t)mesh_prev((int)(h % 3))];
        start[(a < b ? a : b) + 1]++;
    }
    for (size_t v = 0; v < nverts; v++)
        start[v + 1] += start[v];
    for (size_t h = 0; h < 3 * ntris; h++) {
        int32_t t = (int32_t)(h / 3);
        int s = (int)(h % 3);
        int32_t a = tri[3 * (size_t)t + (size_t)mesh_next(s)];
        int32_t b = tri[3 * (size_t)t + (size_t)mesh_prev(s)];
        int32_t lo = a < b ? a : b;
        half_edge e = {a < b ? b : a, gdt_opp_pack(t, s)};
        tab[start[lo]++] = e;
    }
    /* start[v] is now the end of v's list, i.e. the start of v+1's. */
    for (size_t v = nverts; v > 0; v--)
        start[v] = start[v - 1];
    start[0] = 0;
    for (size_t v = 0; v < nverts; v++) {
        half_edge *e = tab + start[v];
        size_t n = start[v + 1] - start[v];
        sort_half_edges(e, n);
        for (size_t i = 0; i < n;) {
            size_t k = i + 1;
            while (k < n && e[k].hi == e[i].hi)
                k++;
            int32_t h0 = e[i].he;
            if (k - i == 1) {
                *mesh_opp_ref(opp, h0) = GDT_MESH_NONE;
            } else {
                int32_t t0 = gdt_opp_tri(h0), t1 = gdt_opp_tri(e[i + 1].he);
                if (k - i > 2) {
                    st = gdt_error_set(err, GDT_EINTERNAL, 7303,
                                       "edge %zu-%d belongs to %zu triangles (%d, %d, %d...)", v,
                                       (int)e[i].hi, k - i, (int)t0, (int)t1,
                                       (int)gdt_opp_tri(e[i + 2].he));
                    goto fail;
                }
                int32_t h1 = e[i + 1].he;
                int32_t a0 = tri[3 * (size_t)t0 + (size_t)mesh_next(gdt_opp_slot(h0))];
                int32_t a1 = tri[3 * (size_t)t1 + (size_t)mesh_next(gdt_opp_slot(h1))];
                if (a0 == a1) {
                    st = gdt_error_set(err, GDT_EINTERNAL, 7303,
                                       "edge %d->%d is traversed in the same direction by "
                                       "triangles %d and %d (inconsistent orientation)",
                                       (int)a0, (int)(a0 == e[i].hi ? (int32_t)v : e[i].hi),
                                       (int)t0, (int)t1);
                    goto fail;
                }
                *mesh_opp_ref(opp, h0) = h1;
                *mesh_opp_ref(opp, h1) = h0;
            }
            i = k;
        }
    }

fail:
    free(start);
    free(tab);
    return st;
}

gdt_status gdt_mesh_link(gdt_mesh *m, gdt_error *err)
{
    return gdt_mesh_adjacency(m->tri, m->ntris, m->nverts, m->opp, err);
}

static int tri3_cmp(const void *x, const void *y)
{
    const int64_t *a = x, *b = y;
    for (int i = 0; i < 3; i++)
        if (a[i] != b[i])
            return a[i] < b[i] ? -1 : 1;
    return 0;
}

void gdt_mesh_canonical(const gdt_mesh *m, int64_t *out)
{
    for (size_t t = 0; t < m->ntris; t++) {
        int64_t k[3];
        for (int i = 0; i < 3; i++) {
            int32_t v = m->tri[3 * t + (size_t)i];
            k[i] = m->ids != NULL ? m->ids[v] : (int64_t)v;
        }
        int r = 0;
        if (k[1] < k[r])
            r = 1;
        if (k[2] < k[r])
            r = 2;
        for (int i = 0; i < 3; i++)
            out[3 * t + (size_t)i] = k[(r + i) % 3];
    }
    if (m->ntris > 1)
        qsort(out, m->ntris, 3 * sizeof *out, tri3_cmp);
}

void gdt_mesh_radix_sort(uint64_t *key, int32_t *val, size_t n, uint64_t *tkey, int32_t *tval)
{
    uint64_t *sk = key, *dk = tkey;
    int32_t *sv = val, *dv = tval;
    size_t count[256];

    if (n < 2)
        return;
    for (int shift = 0; shift < 64; shift += 8) {
        memset(count, 0, sizeof count);
        for (size_t i = 0; i < n; i++)
            count[(sk[i] >> shift) & 0xff]++;
        if (count[(sk[0] >> shift) & 0xff] == n)
            continue; /* every key has the same byte here */
        size_t sum = 0;
        for (int b = 0; b < 256; b++) {
            size_t c = count[b];
            count[b] = sum;
            sum += c;
        }
        for (size_t i = 0; i < n; i++) {
            size_t pos = count[(sk[i] >> shift) & 0xff]++;
            dk[pos] = sk[i];
            dv[pos] = sv[i];
        }
        uint64_t *xk = sk;
        sk = dk, dk = xk;
        int32_t *xv = sv;
        sv = dv, dv = xv;
    }
    if (sk != key) {
        memcpy(key, sk, n * sizeof *key);
        memcpy(val, sv, n * sizeof *val);
    }
}
