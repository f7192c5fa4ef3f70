/* merge_dup.c — the --dup merge of one tile, in memory or out of core.
 *
 * All points sharing an (x, y) are in the same tile, so merging per tile is
 * exact.  The result of tile k is every distinct (x, y) of the tile once,
 * with ord = the lowest ordinal of its group and z chosen by --dup (see
 * gdt_points_dedup), sorted by ord: tile_<i>_<j>.pts, and the records within
 * h of the tile's border: tile_<i>_<j>.edge.
 *
 * design (merge_file, after the dupcount scheme):
 *   read records into a buffer of cap; when it is full, collapse it (a hash
 *     on (x, y), folding each group as gdt_points_dedup does); if it is still
 *     over 3/4 full, or partitions exist,
 *     move it into K partition files by a hash of (x, y, level)
 *   at the end: no partitions -> collapse, sort by ord, emit (in memory);
 *     else -> every partition is merged the same way one level deeper into
 *     a run sorted by ord, and the K runs are merged by ord into the output.
 * Collapsing is associative (ord = min, z = min/max or the z of the lowest
 * ord), so the result is the same for every cap: bytes do not depend on the
 * budget.  All records of one (x, y) meet in one leaf partition.
 * Memory: cap records plus the hash table (at most 4 cap 32-bit words) or the
 * sort scratch (cap records), K small write or read buffers.  Descriptors:
 * at most K + 2 at a time.
 */
#include "private/tiler_impl.h"
#include "private/tiler_io.h"

#include <inttypes.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#define MAX_MERGE_LEVEL 16
#define MERGE_CAP_MAX (UINT32_C(1) << 31) /* records held at once */

typedef struct sink {
    tl_wfile *pts;      /* every record */
    tl_wfile *edge;     /* border records, or NULL (intermediate runs) */
    int64_t x0, y0, span, h;
} sink;

typedef struct mctx {
    gdt_tiler *t;
    uint64_t k;         /* tile */
    gdt_point *buf;     /* owned by the caller of merge_file, cap records */
    size_t cap;
    unsigned deepest;
} mctx;

static gdt_status sink_put(sink *s, const gdt_point *p, gdt_error *err)
{
    gdt_status st = tl_wfile_put(s->pts, p, err);
    if (st != GDT_OK || s->edge == NULL || s->h == 0)
        return st;
    if (p->x - s->x0 < s->h || s->x0 + s->span - 1 - p->x < s->h || p->y - s->y0 < s->h ||
        s->y0 + s->span - 1 - p->y < s->h)
        st = tl_wfile_put(s->edge, p, err);
    return st;
}

static unsigned part_of(const gdt_point *p, unsigned level, unsigned k)
{
    uint64_t h = (uint64_t)p->x * UINT64_C(0x9e3779b97f4a7c15) + level + 1;
    h ^= h >> 31;
    h *= UINT64_C(0xbf58476d1ce4e5b9);
    h ^= (uint64_t)p->y;
    h ^= h >> 29;
    h *= UINT64_C(0x94d049bb133111eb);
    h ^= h >> 32;
    return (unsigned)(((h & 0xffffffffu) * k) >> 32);
}

/* Folds record r into the kept record k of the same (x, y): the lowest
 * ordinal, and z by the rule (first: the z of the lowest ordinal; min-z /
 * max-z: the extreme z, equal values resolved by the lowest ordinal, as in
 * gdt_points_dedup). */
static void fold(gdt_point *k, const gdt_point *r, gdt_dup_policy dup)
{
    int lower = r->ord < k->ord;
    switch (dup) {
    case GDT_DUP_FIRST:
        if (lower)
            k->z = r->z;
        break;
    case GDT_DUP_MIN_Z:
        if (r->z < k->z || (r->z == k->z && lower))
            k->z = r->z;
        break;
    case GDT_DUP_MAX_Z:
        if (r->z > k->z || (r->z == k->z && lower))
            k->z = r->z;
        break;
    }
    if (lower)
        k->ord = r->ord;
}

static size_t hash_xy(const gdt_point *p, size_t mask)
{
    uint64_t h = (uint64_t)p->x * UINT64_C(0x9e3779b97f4a7c15);
    h ^= (uint64_t)p->y + UINT64_C(0x7f4a7c159e3779b9) + (h << 6) + (h >> 2);
    h ^= h >> 32;
    h *= UINT64_C(0xd6e8feb86659fd93);
    h ^= h >> 32;
    return (size_t)h & mask;
}

/* Merges the records of m->buf[0..*used) that share an (x, y) (fold), in
 * place, keeping the order of first appearance; so input sorted by ord
 * stays sorted by ord.  design: open addressing on (x, y) holding index + 1,
 * one pass, O(used).  Scratch: a table of at most 4 used words. */
static gdt_status collapse(mctx *m, size_t *used, gdt_error *err)
{
    size_t n = *used, cap = 16, out = 0;
    gdt_point *b = m->buf;
    uint32_t *tab;

    if (n < 2)
        return GDT_OK;
    while (cap < 2 * n)
        cap *= 2;
    /* n <= MERGE_CAP_MAX < 2^32: indices + 1 fit 32 bits */
    if (cap > m->t->dup_tab_cap) {
        free(m->t->dup_tab);
        m->t->dup_tab_cap = 0;
        m->t->dup_tab = malloc(cap * sizeof *m->t->dup_tab);
        if (m->t->dup_tab == NULL)
            return gdt_error_set(err, GDT_EINTERNAL, 7001,
                                 "out of memory (--dup merge of %zu points)", n);
        m->t->dup_tab_cap = cap;
    }
    tab = m->t->dup_tab;
    memset(tab, 0, cap * sizeof *tab);
    for (size_t i = 0; i < n; i++) {
        size_t s = hash_xy(&b[i], cap - 1);
        for (;; s = (s + 1) & (cap - 1)) {
            if (tab[s] == 0) {
                b[out] = b[i];
                tab[s] = (uint32_t)++out;
                break;
            }
            if (b[tab[s] - 1].x == b[i].x && b[tab[s] - 1].y == b[i].y) {
                fold(&b[tab[s] - 1], &b[i], m->t->opts.dup);
                break;
            }
        }
    }
    *used = out;
    return GDT_OK;
}

static int sorted_by_ord(const gdt_point *p, size_t n)
{
    for (size_t i = 1; i < n; i++)
        if (p[i].ord < p[i - 1].ord)
            return 0;
    return 1;
}

static gdt_status distribute(mctx *m, tl_wfile *parts, unsigned level, size_t *used,
                             gdt_error *err)
{
    unsigned K = m->t->sz.merge_k;
    for (size_t i = 0; i < *used; i++) {
        gdt_status st = tl_wfile_put(&parts[part_of(&m->buf[i], level, K)], &m->buf[i], err);
        if (st != GDT_OK)
            return st;
    }
    *used = 0;
    return GDT_OK;
}

static char *part_path(const mctx *m, unsigned level, unsigned p, const char *what)
{
    const tl_tile *tl = &m->t->tiles[m->k];
    return tl_path("%s/merge_%" PRId64 "_%" PRId64 "_%u_%u.%s.tmp", m->t->tiles_dir, tl->i, tl->j,
                   level, p, what);
}

/* K-way merge by ord of the runs[0..K) (each sorted by ord) into out. */
static gdt_status merge_runs(mctx *m, char **runs, const uint64_t *nrec, sink *out,
                             gdt_error *err)
{
    unsigned K = m->t->sz.merge_k;
    tl_rfile *r = calloc(K, sizeof *r);
    gdt_point *head = calloc(K, sizeof *head);
    int *live = calloc(K, sizeof *live);
    gdt_status st = GDT_OK;

    if (r == NULL || head == NULL || live == NULL) {
        st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        goto fail;
    }
    for (unsigned p = 0; p < K; p++)
        r[p].fd = -1;
    for (unsigned p = 0; p < K; p++) {
        if (nrec[p] == 0)
            continue;
        st = tl_rfile_open(&r[p], runs[p], nrec[p], m->t->sz.merge_read_recs, err);
        if (st == GDT_OK)
            st = tl_rfile_next(&r[p], &head[p], &live[p], err);
        if (st != GDT_OK)
            goto fail;
    }
    for (;;) {
        unsigned best = K;
        for (unsigned p = 0; p < K; p++)
            if (live[p] && (best == K || head[p].ord < head[best].ord))
                best = p;
        if (best == K)
            break;
        st = sink_put(out, &head[best], err);
        if (st == GDT_OK)
            st = tl_rfile_next(&r[best], &head[best], &live[best], err);
        if (st != GDT_OK)
            goto fail;
    }
fail:
    if (r != NULL)
        for (unsigned p = 0; p < K; p++)
            tl_rfile_close(&r[p]);
    free(r);
    free(head);
    free(live);
    return st;
}

/* Merges the nrec records of path (a partition of `level`) into out. */
static gdt_status merge_file(mctx *m, const char *path, uint64_t nrec, unsigned level, sink *out,
                             gdt_error *err)
{
    gdt_tiler *t = m->t;
    const unsigned K = t->sz.merge_k;
    tl_rfile rf;
    tl_wfile *parts = NULL;
    char **names = NULL;
    uint64_t *counts = NULL;
    size_t used = 0;
    gdt_status st;

    st = tl_rfile_open(&rf, path, nrec, t->sz.merge_read_recs, err);
    if (st != GDT_OK)
        return st;
    for (;;) {
        size_t n = 0;
        st = tl_rfile_read(&rf, m->buf + used, m->cap - used, &n, err);
        if (st != GDT_OK)
            goto fail;
        if (n == 0)
            break;
        used += n;
        if (used < m->cap || rf.left == 0)
            continue; /* room left, or everything is in memory */
        st = collapse(m, &used, err);
        if (st != GDT_OK)
            goto fail;
        if (parts == NULL && used <= m->cap - m->cap / 4)
            continue;
        if (parts == NULL) {
            if (level + 1 > MAX_MERGE_LEVEL) {
                st = gdt_error_set(err, GDT_EINTERNAL, 7502,
                                   "--dup merge of tile (%" PRId64 ", %" PRId64
                                   ") did not converge after %u partition levels",
                                   t->tiles[m->k].i, t->tiles[m->k].j, level);
                goto fail;
            }
            parts = calloc(K, sizeof *parts);
            names = calloc(K, sizeof *names);
            counts = calloc(K, sizeof *counts);
            if (parts == NULL || names == NULL || counts == NULL) {
                st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
                goto fail;
            }
            for (unsigned p = 0; p < K; p++)
                parts[p].fd = -1;
            for (unsigned p = 0; p < K; p++) {
                names[p] = part_path(m, level + 1, p, "part");
                if (names[p] == NULL) {
                    st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
                    goto fail;
                }
                st = tl_wfile_init(&parts[p], names[p], NULL, t->sz.part_recs, 0, err);
                if (st != GDT_OK)
                    goto fail;
            }
            if (level + 1 > m->deepest)
                m->deepest = level + 1;
        }
        st = distribute(m, parts, level + 1, &used, err);
        if (st != GDT_OK)
            goto fail;
    }
    tl_rfile_close(&rf);
    st = collapse(m, &used, err);
    if (st != GDT_OK)
        goto fail;
    if (parts == NULL) {
        /* A whole tile in memory arrives in input order and stays sorted. */
        if (!sorted_by_ord(m->buf, used))
            st = tl_sort_by_ord(m->buf, used, NULL, err);
        for (size_t i = 0; i < used && st == GDT_OK; i++)
            st = sink_put(out, &m->buf[i], err);
        used = 0;
        return st;
    }
    st = distribute(m, parts, level + 1, &used, err);
    for (unsigned p = 0; p < K && st == GDT_OK; p++) {
        counts[p] = parts[p].nrec;
        st = tl_wfile_commit(&parts[p], err);
    }
    if (st != GDT_OK)
        goto fail;
    /* Each partition becomes a run sorted by ord, named like it with "run". */
    for (unsigned p = 0; p < K; p++) {
        char *run;
        tl_wfile rw;
        sink rs = {&rw, NULL, 0, 0, 0, 0};
        if (counts[p] == 0)
            continue;
        run = part_path(m, level + 1, p, "run");
        if (run == NULL) {
            st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
            goto fail;
        }
        st = tl_wfile_init(&rw, run, NULL, t->sz.part_recs, 0, err);
        if (st == GDT_OK)
            st = merge_file(m, names[p], counts[p], level + 1, &rs, err);
        unlink(names[p]);
        free(names[p]);
        names[p] = run;
        if (st == GDT_OK) {
            counts[p] = rw.nrec;
            st = tl_wfile_commit(&rw, err);
        } else {
            tl_wfile_abort(&rw);
        }
        if (st != GDT_OK)
            goto fail;
    }
    st = merge_runs(m, names, counts, out, err);
fail:
    tl_rfile_close(&rf);
    if (parts != NULL)
        for (unsigned p = 0; p < K; p++)
            tl_wfile_abort(&parts[p]);
    if (names != NULL)
        for (unsigned p = 0; p < K; p++) {
            if (names[p] != NULL)
                unlink(names[p]);
            free(names[p]);
        }
    free(parts);
    free(names);
    free(counts);
    return st;
}

gdt_status tl_merge_tile(gdt_tiler *t, uint64_t k, gdt_error *err)
{
    tl_tile *tl = &t->tiles[k];
    char *raw = tl_tile_file(t, k, "raw", !t->opts.keep_spill);
    char *pts_tmp = tl_tile_file(t, k, "pts", 1), *pts = tl_tile_file(t, k, "pts", 0);
    char *edge_tmp = tl_tile_file(t, k, "edge", 1), *edge = tl_tile_file(t, k, "edge", 0);
    tl_wfile wp, we;
    sink out;
    mctx m;
    gdt_status st = GDT_OK;

    memset(&m, 0, sizeof m);
    memset(&wp, 0, sizeof wp);
    memset(&we, 0, sizeof we);
    wp.fd = we.fd = -1;
    if (raw == NULL || pts_tmp == NULL || pts == NULL || edge_tmp == NULL || edge == NULL) {
        st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        goto fail;
    }
    m.t = t;
    m.k = k;
    m.cap = t->sz.merge_cap;
    if ((uint64_t)m.cap > tl->count)
        m.cap = (size_t)tl->count; /* a small tile needs no more */
    if (m.cap > MERGE_CAP_MAX)
        m.cap = MERGE_CAP_MAX; /* the result does not depend on cap */
    if (m.cap < 2)
        m.cap = 2;
    if (m.cap > t->dup_cap) {
        free(t->dup_buf);
        t->dup_cap = 0;
        t->dup_buf = malloc(m.cap * sizeof *t->dup_buf);
        if (t->dup_buf == NULL) {
            st = gdt_error_set(err, GDT_EINTERNAL, 7001,
                               "out of memory (--dup merge of %zu points)", m.cap);
            goto fail;
        }
        t->dup_cap = m.cap;
    }
    m.buf = t->dup_buf;
    st = tl_wfile_init(&wp, pts_tmp, pts, t->sz.part_recs, !t->opts.test_nosync, err);
    if (st == GDT_OK)
        st = tl_wfile_init(&we, edge_tmp, edge, t->sz.part_recs, !t->opts.test_nosync, err);
    if (st != GDT_OK)
        goto fail;
    out.pts = &wp;
    out.edge = &we;
    out.x0 = tl->i * t->plan.span;
    out.y0 = tl->j * t->plan.span;
    out.span = t->plan.span;
    out.h = t->plan.halo * t->plan.cell;
    st = merge_file(&m, raw, tl->count, 0, &out, err);
    if (st != GDT_OK)
        goto fail;
    tl->points = wp.nrec;
    tl->edge = we.nrec;
    st = tl_wfile_commit(&wp, err);
    if (st == GDT_OK)
        st = tl_wfile_commit(&we, err);
    if (st != GDT_OK)
        goto fail;
    if (!t->opts.keep_spill)
        unlink(raw);
    t->stats.merged_duplicates += tl->count - tl->points;
    if (m.deepest > 0)
        t->stats.external_merges++;
    if (m.deepest > t->stats.merge_levels)
        t->stats.merge_levels = m.deepest;
fail:
    tl_wfile_abort(&wp);
    tl_wfile_abort(&we);
    free(raw);
    free(pts_tmp);
    free(pts);
    free(edge_tmp);
    free(edge);
    return st;
}
