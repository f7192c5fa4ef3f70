/* trim.c — --max-edge and --concavity (see gdt_trim.h for the rules and
 * the argument). */
#include "gdt_trim.h"

#include <stdlib.h>
#include <string.h>

#include "gdt_grow.h"

static gdt_status no_memory(gdt_error *err)
{
    return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
}

static int grow(void *pp, size_t *cap, size_t need, size_t elem)
{
    return gdt_grow(pp, cap, need, elem, 256);
}

int gdt_trim_cut(const gdt_trim_rule *r, gdt_ipt a, gdt_ipt b, gdt_ipt c)
{
    double L = r->max_edge;
    return gdt_trim_longer(r, L, b.x - a.x, b.y - a.y) ||
           gdt_trim_longer(r, L, c.x - b.x, c.y - b.y) ||
           gdt_trim_longer(r, L, a.x - c.x, a.y - c.y);
}

/* ---- union-find, the smaller index always the root -------------------- */

/* Invariant: parent[i] <= i, so a root is the smallest index of its set. */
static uint32_t uf_find32(uint32_t *parent, uint32_t i)
{
    while (parent[i] != i) {
        parent[i] = parent[parent[i]];
        i = parent[i];
    }
    return i;
}

static void uf_union32(uint32_t *parent, uint32_t a, uint32_t b)
{
    a = uf_find32(parent, a);
    b = uf_find32(parent, b);
    if (a < b)
        parent[b] = a;
    else if (b < a)
        parent[a] = b;
}

static uint64_t uf_find64(uint64_t *parent, uint64_t i)
{
    while (parent[i] != i) {
        parent[i] = parent[parent[i]];
        i = parent[i];
    }
    return i;
}

static void uf_union64(uint64_t *parent, uint64_t a, uint64_t b)
{
    a = uf_find64(parent, a);
    b = uf_find64(parent, b);
    if (a < b)
        parent[b] = a;
    else if (b < a)
        parent[a] = b;
}

/* ---- a tile ------------------------------------------------------------ */

void gdt_trim_tile_free(gdt_trim_tile *t)
{
    if (t == NULL)
        return;
    free(t->cut);
    free(t->cand);
    free(t->open);
    free(t->parent);
    free(t->rec);
    memset(t, 0, sizeof *t);
}

/* Records are (key, face) pairs of u64, key = smaller << 32 | larger. */
static int cmp_rec(const void *pa, const void *pb)
{
    const uint64_t *a = pa, *b = pb;
    if (a[0] != b[0])
        return a[0] < b[0] ? -1 : 1;
    return a[1] < b[1] ? -1 : a[1] > b[1];
}

gdt_status gdt_trim_tile_run(gdt_trim_tile *t, const gdt_trim_rule *r, const uint32_t *faces,
                             size_t nf, const gdt_ipt *pts, uint64_t base, gdt_error *err)
{
    size_t nrec = 0;
    double L = r->concavity;

    t->ncut = t->ncand = t->nopen = 0;
    if (nf >= UINT32_MAX)
        return gdt_error_set(err, GDT_EINTERNAL, 7891, "a tile of %zu faces cannot be trimmed",
                             nf);
    if (r->max_edge > 0) {
        for (size_t f = 0; f < nf; f++) {
            const uint32_t *v = faces + 3 * f;
            if (!gdt_trim_cut(r, pts[v[0]], pts[v[1]], pts[v[2]]))
                continue;
            if (grow(&t->cut, &t->cap_cut, t->ncut + 1, sizeof *t->cut) != 0)
                return no_memory(err);
            t->cut[t->ncut++] = (uint32_t)f;
        }
    }
    if (!(L > 0) || nf == 0)
        return GDT_OK;
    /* the long edges, each with its face */
    for (size_t f = 0; f < nf; f++) {
        const uint32_t *v = faces + 3 * f;
        for (int i = 0; i < 3; i++) {
            uint32_t a = v[i], b = v[(i + 1) % 3];
            gdt_ipt pa = pts[a], pb = pts[b];
            if (!gdt_trim_longer(r, L, pb.x - pa.x, pb.y - pa.y))
                continue;
            if (grow(&t->rec, &t->cap_rec, 2 * nrec + 2, sizeof *t->rec) != 0)
                return no_memory(err);
            t->rec[2 * nrec] = a < b ? (uint64_t)a << 32 | b : (uint64_t)b << 32 | a;
            t->rec[2 * nrec + 1] = f;
            nrec++;
        }
    }
    if (nrec == 0)
        return GDT_OK;
    qsort(t->rec, nrec, 2 * sizeof *t->rec, cmp_rec);
    /* parent[f] for the faces; the top bit of a root marks an open edge */
    if (grow(&t->parent, &t->cap_parent, nf, sizeof *t->parent) != 0)
        return no_memory(err);
    for (size_t f = 0; f < nf; f++)
        t->parent[f] = (uint32_t)f;
    for (size_t i = 0; i < nrec;) {
        size_t j = i + 1;
        while (j < nrec && t->rec[2 * j] == t->rec[2 * i])
            j++;
        if (j - i > 2)
            return gdt_error_set(err, GDT_EINTERNAL, 7892,
                                 "an edge of %zu faces in a tile's triangulation", j - i);
        if (j - i == 2)
            uf_union32(t->parent, (uint32_t)t->rec[2 * i + 1], (uint32_t)t->rec[2 * i + 3]);
        i = j;
    }
    /* open edges: labels are final now (no more unions) */
    {
        uint8_t *open_root = calloc(nf, 1);
        if (open_root == NULL)
            return no_memory(err);
        for (size_t i = 0; i < nrec;) {
            size_t j = i + 1;
            while (j < nrec && t->rec[2 * j] == t->rec[2 * i])
                j++;
            if (j - i == 1) {
                uint64_t key = t->rec[2 * i];
                uint32_t lab = uf_find32(t->parent, (uint32_t)t->rec[2 * i + 1]);
                if (grow(&t->open, &t->cap_open, t->nopen + 1, sizeof *t->open) != 0) {
                    free(open_root);
                    return no_memory(err);
                }
                t->open[t->nopen].a = base + (key >> 32);
                t->open[t->nopen].b = base + (key & UINT32_MAX);
                t->open[t->nopen].label = lab;
                t->nopen++;
                open_root[lab] = 1;
            }
            i = j;
        }
        for (size_t f = 0; f < nf; f++) {
            uint32_t lab = uf_find32(t->parent, (uint32_t)f);
            if (!open_root[lab])
                continue;
            if (grow(&t->cand, &t->cap_cand, 2 * t->ncand + 2, sizeof *t->cand) != 0) {
                free(open_root);
                return no_memory(err);
            }
            t->cand[2 * t->ncand] = (uint32_t)f;
            t->cand[2 * t->ncand + 1] = lab;
            t->ncand++;
        }
        free(open_root);
    }
    return GDT_OK;
}

/* ---- the graph ------------------------------------------------------------ */

/* A slot of the edge table: key (a, b) with a < b; node of the first side
 * met; count of sides met (0 = empty slot). */
typedef struct edge_slot {
    uint64_t a, b;
    uint64_t node;
    uint32_t count;
} edge_slot;

typedef struct tile_node {
    uint64_t tile;
    uint32_t label;
    uint64_t node;
} tile_node;

typedef struct face_node {
    uint64_t face; /* merge face number */
    uint64_t node;
} face_node;

struct gdt_trim_graph {
    gdt_trim_rule rule;
    edge_slot *slot; /* cap a power of two, at most half full */
    size_t cap, used;
    uint64_t *parent; /* per node */
    size_t nnodes, cap_parent;
    uint8_t *drop;    /* per node, after resolve */
    tile_node *tn;    /* by (tile, label) */
    size_t ntn, cap_tn;
    face_node *fn;    /* by face */
    size_t nfn, cap_fn;
    uint64_t *cut;    /* merge faces --max-edge drops, increasing */
    size_t ncut, cap_cut;
    uint64_t nfaces;  /* merge faces added */
    uint64_t last_tile;
    int have_tile, resolved;
    gdt_trim_counts counts;
    uint32_t *labels; /* scratch of add_tile */
    size_t cap_labels;
};

gdt_status gdt_trim_graph_create(gdt_trim_graph **out, const gdt_trim_rule *r, gdt_error *err)
{
    gdt_trim_graph *g = calloc(1, sizeof *g);
    *out = NULL;
    if (g == NULL)
        return no_memory(err);
    g->rule = *r;
    g->cap = 1024;
    g->slot = calloc(g->cap, sizeof *g->slot);
    if (g->slot == NULL) {
        free(g);
        return no_memory(err);
    }
    *out = g;
    return GDT_OK;
}

void gdt_trim_graph_destroy(gdt_trim_graph *g)
{
    if (g == NULL)
        return;
    free(g->slot);
    free(g->parent);
    free(g->drop);
    free(g->tn);
    free(g->fn);
    free(g->cut);
    free(g->labels);
    free(g);
}

static size_t slot_of(uint64_t a, uint64_t b, size_t mask)
{
    uint64_t h = a * UINT64_C(0x9e3779b97f4a7c15) ^ (b + UINT64_C(0x632be59bd9b4e019));
    h ^= h >> 29;
    h *= UINT64_C(0xbf58476d1ce4e5b9);
    h ^= h >> 32;
    return (size_t)h & mask;
}

static int table_grow(gdt_trim_graph *g)
{
    size_t cap = 2 * g->cap;
    edge_slot *s = calloc(cap, sizeof *s);
    if (s == NULL)
        return -1;
    for (size_t i = 0; i < g->cap; i++) {
        size_t j;
        if (g->slot[i].count == 0)
            continue;
        j = slot_of(g->slot[i].a, g->slot[i].b, cap - 1);
        while (s[j].count != 0)
            j = (j + 1) & (cap - 1);
        s[j] = g->slot[i];
    }
    free(g->slot);
    g->slot = s;
    g->cap = cap;
    return 0;
}

static gdt_status new_node(gdt_trim_graph *g, uint64_t *node, gdt_error *err)
{
    if (grow(&g->parent, &g->cap_parent, g->nnodes + 1, sizeof *g->parent) != 0)
        return no_memory(err);
    g->parent[g->nnodes] = g->nnodes;
    *node = g->nnodes++;
    return GDT_OK;
}

/* One side (node) of the long edge {u, v}. */
static gdt_status add_side(gdt_trim_graph *g, uint64_t u, uint64_t v, uint64_t node,
                           gdt_error *err)
{
    uint64_t a = u < v ? u : v, b = u < v ? v : u;
    size_t j;

    if (2 * (g->used + 1) > g->cap && table_grow(g) != 0)
        return no_memory(err);
    j = slot_of(a, b, g->cap - 1);
    while (g->slot[j].count != 0 && (g->slot[j].a != a || g->slot[j].b != b))
        j = (j + 1) & (g->cap - 1);
    if (g->slot[j].count == 0) {
        g->slot[j].a = a;
        g->slot[j].b = b;
        g->slot[j].node = node;
        g->slot[j].count = 1;
        g->used++;
        return GDT_OK;
    }
    if (g->slot[j].count >= 2)
        return gdt_error_set(err, GDT_EINTERNAL, 7892,
                             "the edge %llu-%llu has more than two faces",
                             (unsigned long long)a, (unsigned long long)b);
    g->slot[j].count = 2;
    uf_union64(g->parent, g->slot[j].node, node);
    return GDT_OK;
}

static int cmp_u32(const void *pa, const void *pb)
{
    uint32_t a = *(const uint32_t *)pa, b = *(const uint32_t *)pb;
    return a < b ? -1 : a > b;
}

gdt_status gdt_trim_graph_add_tile(gdt_trim_graph *g, uint64_t tile, const gdt_trim_open *e,
                                   size_t n, gdt_error *err)
{
    size_t nl = 0, first;

    if (g->resolved || (g->have_tile && tile <= g->last_tile))
        return gdt_error_set(err, GDT_EINTERNAL, 7892, "trim graph: tile %llu out of order",
                             (unsigned long long)tile);
    g->have_tile = 1;
    g->last_tile = tile;
    if (n == 0)
        return GDT_OK;
    if (grow(&g->labels, &g->cap_labels, n, sizeof *g->labels) != 0)
        return no_memory(err);
    for (size_t i = 0; i < n; i++)
        g->labels[i] = e[i].label;
    qsort(g->labels, n, sizeof *g->labels, cmp_u32);
    for (size_t i = 0; i < n; i++)
        if (nl == 0 || g->labels[i] != g->labels[nl - 1])
            g->labels[nl++] = g->labels[i];
    if (grow(&g->tn, &g->cap_tn, g->ntn + nl, sizeof *g->tn) != 0)
        return no_memory(err);
    first = g->ntn;
    for (size_t i = 0; i < nl; i++) {
        gdt_status st = new_node(g, &g->tn[g->ntn].node, err);
        if (st != GDT_OK)
            return st;
        g->tn[g->ntn].tile = tile;
        g->tn[g->ntn].label = g->labels[i];
        g->ntn++;
    }
    for (size_t i = 0; i < n; i++) {
        /* the tile's nodes are tn[first ..], by label */
        size_t lo = first, hi = g->ntn;
        gdt_status st;
        while (hi - lo > 1) {
            size_t mid = lo + (hi - lo) / 2;
            if (g->tn[mid].label <= e[i].label)
                lo = mid;
            else
                hi = mid;
        }
        st = add_side(g, e[i].a, e[i].b, g->tn[lo].node, err);
        if (st != GDT_OK)
            return st;
    }
    return GDT_OK;
}

gdt_status gdt_trim_graph_add_faces(gdt_trim_graph *g, const uint64_t *faces,
                                    const gdt_ipt *xy, size_t n, gdt_error *err)
{
    const gdt_trim_rule *r = &g->rule;

    if (g->resolved)
        return gdt_error_set(err, GDT_EINTERNAL, 7892, "trim graph: faces after resolve");
    for (size_t f = 0; f < n; f++, g->nfaces++) {
        const uint64_t *v = faces + 3 * f;
        const gdt_ipt *p = xy + 3 * f;
        uint64_t node = 0;
        int have = 0;
        if (r->max_edge > 0 && gdt_trim_cut(r, p[0], p[1], p[2])) {
            if (grow(&g->cut, &g->cap_cut, g->ncut + 1, sizeof *g->cut) != 0)
                return no_memory(err);
            g->cut[g->ncut++] = g->nfaces;
        }
        if (!(r->concavity > 0))
            continue;
        for (int i = 0; i < 3; i++) {
            gdt_ipt a = p[i], b = p[(i + 1) % 3];
            gdt_status st;
            if (!gdt_trim_longer(r, r->concavity, b.x - a.x, b.y - a.y))
                continue;
            if (!have) {
                st = new_node(g, &node, err);
                if (st != GDT_OK)
                    return st;
                if (grow(&g->fn, &g->cap_fn, g->nfn + 1, sizeof *g->fn) != 0)
                    return no_memory(err);
                g->fn[g->nfn].face = g->nfaces;
                g->fn[g->nfn].node = node;
                g->nfn++;
                have = 1;
            }
            st = add_side(g, v[i], v[(i + 1) % 3], node, err);
            if (st != GDT_OK)
                return st;
        }
    }
    return GDT_OK;
}

gdt_status gdt_trim_graph_resolve(gdt_trim_graph *g, gdt_error *err)
{
    uint8_t *ext = calloc(g->nnodes + 1, 1);
    size_t c = 0;
    uint64_t both = 0;

    g->drop = calloc(g->nnodes + 1, 1);
    if (ext == NULL || g->drop == NULL) {
        free(ext);
        return no_memory(err);
    }
    /* an edge met once is a hull edge: its side is reached from outside */
    for (size_t j = 0; j < g->cap; j++)
        if (g->slot[j].count == 1)
            ext[uf_find64(g->parent, g->slot[j].node)] = 1;
    for (uint64_t i = 0; i < g->nnodes; i++)
        g->drop[i] = ext[uf_find64(g->parent, i)];
    free(ext);
    g->resolved = 1;
    /* the merge faces' counts: cut and fn are both by increasing face */
    g->counts.faces = g->nfaces;
    g->counts.cut = g->ncut;
    for (size_t i = 0; i < g->nfn; i++) {
        if (!g->drop[g->fn[i].node])
            continue;
        g->counts.peeled++;
        while (c < g->ncut && g->cut[c] < g->fn[i].face)
            c++;
        if (c < g->ncut && g->cut[c] == g->fn[i].face)
            both++;
    }
    g->counts.dropped = g->counts.cut + g->counts.peeled - both;
    return GDT_OK;
}

int gdt_trim_graph_tile_dropped(const gdt_trim_graph *g, uint64_t tile, uint32_t label)
{
    size_t lo = 0, hi = g->ntn;
    while (lo < hi) {
        size_t mid = lo + (hi - lo) / 2;
        const tile_node *t = &g->tn[mid];
        if (t->tile < tile || (t->tile == tile && t->label < label))
            lo = mid + 1;
        else
            hi = mid;
    }
    return lo < g->ntn && g->tn[lo].tile == tile && g->tn[lo].label == label &&
           g->drop[g->tn[lo].node];
}

int gdt_trim_graph_face_dropped(const gdt_trim_graph *g, uint64_t i)
{
    size_t lo = 0, hi = g->ncut;
    while (lo < hi) {
        size_t mid = lo + (hi - lo) / 2;
        if (g->cut[mid] < i)
            lo = mid + 1;
        else
            hi = mid;
    }
    if (lo < g->ncut && g->cut[lo] == i)
        return 1;
    lo = 0;
    hi = g->nfn;
    while (lo < hi) {
        size_t mid = lo + (hi - lo) / 2;
        if (g->fn[mid].face < i)
            lo = mid + 1;
        else
            hi = mid;
    }
    return lo < g->nfn && g->fn[lo].face == i && g->drop[g->fn[lo].node];
}

gdt_trim_counts gdt_trim_graph_merge_counts(const gdt_trim_graph *g)
{
    return g->counts;
}

gdt_status gdt_trim_mesh(const gdt_trim_rule *r, const uint32_t *faces, size_t nf,
                         const gdt_ipt *pts, uint8_t *keep, gdt_trim_counts *counts,
                         gdt_error *err)
{
    gdt_trim_tile t;
    gdt_trim_graph *g = NULL;
    gdt_trim_counts n;
    gdt_status st;

    memset(&t, 0, sizeof t);
    memset(&n, 0, sizeof n);
    for (size_t f = 0; f < nf; f++)
        keep[f] = 1;
    st = gdt_trim_tile_run(&t, r, faces, nf, pts, 0, err);
    if (st == GDT_OK)
        st = gdt_trim_graph_create(&g, r, err);
    if (st == GDT_OK)
        st = gdt_trim_graph_add_tile(g, 0, t.open, t.nopen, err);
    if (st == GDT_OK)
        st = gdt_trim_graph_resolve(g, err);
    if (st == GDT_OK) {
        n.faces = nf;
        for (size_t i = 0; i < t.ncut; i++)
            keep[t.cut[i]] = 0;
        n.cut = t.ncut;
        for (size_t i = 0; i < t.ncand; i++) {
            if (!gdt_trim_graph_tile_dropped(g, 0, t.cand[2 * i + 1]))
                continue;
            n.peeled++;
            keep[t.cand[2 * i]] = 0;
        }
        for (size_t f = 0; f < nf; f++)
            n.dropped += !keep[f];
        if (counts != NULL)
            *counts = n;
    }
    gdt_trim_graph_destroy(g);
    gdt_trim_tile_free(&t);
    return st;
}
