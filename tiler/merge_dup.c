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
 *
 * Tiles are independent, so tl_merge_tiles runs W workers (threads, the
 * caller's own among them) that take tiles in index order from a shared
 * counter, each with its own scratch of merge_cap / W records.  W is the
 * largest count up to the tiler's threads whose share still holds the
 * largest tile in memory (the one-tile path), within the descriptor budget.
 * When pass 2 left the records in memory (spill.c), each tile is collapsed
 * where it lies, on the workers pass 2 sized for that (resident_workers).
 * Each tile's files depend only on its records in input order, so the
 * bytes do not depend on W or the path; only the caller's thread reports
 * progress.
 */
#include "private/tiler_impl.h"
#include "private/tiler_io.h"

#include <inttypes.h>
#include <pthread.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#define MAX_MERGE_LEVEL 16
#define COLLAPSE_BATCH 16

typedef struct sink {
    tl_wfile *pts;      /* every record */
    tl_wfile *edge;     /* border records, or NULL (intermediate runs) */
    int64_t x0, y0, span, h;
} sink;

/* One worker's scratch, reused from tile to tile: records, and the hash
 * table of collapse. */
typedef struct scratch {
    gdt_point *buf;
    size_t cap;
    uint32_t *tab;
    size_t tab_cap;
} scratch;

typedef struct mctx {
    gdt_tiler *t;
    uint64_t k;         /* tile */
    gdt_point *buf;     /* the worker's records, cap of them */
    size_t cap;
    scratch *scr;
    unsigned deepest;
} mctx;

static gdt_status sink_put(sink *s, const gdt_point *p, gdt_error *err)
{
    gdt_status st = tl_wfile_put(s->pts, p, err);
    if (st != GDT_OK || s->edge == NULL || s->h == 0)
        return st;
    if (tl_on_edge(p, s->x0, s->y0, s->span, s->h))
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
    size_t n = *used, cap, out = 0;
    gdt_point *b = m->buf;
    uint32_t *tab;

    if (n < 2)
        return GDT_OK;
    cap = (size_t)(tl_collapse_table_bytes(n) / sizeof *tab);
    /* n <= TL_MERGE_CAP_MAX < 2^32: indices + 1 fit 32 bits */
    if (cap > m->scr->tab_cap) {
        free(m->scr->tab);
        m->scr->tab_cap = 0;
        m->scr->tab = malloc(cap * sizeof *m->scr->tab);
        if (m->scr->tab == NULL)
            return gdt_error_set(err, GDT_EINTERNAL, 7001,
                                 "out of memory (--dup merge of %zu points)", n);
        m->scr->tab_cap = cap;
    }
    tab = m->scr->tab;
    memset(tab, 0, cap * sizeof *tab);
    /* Blocks of COLLAPSE_BATCH records: their slots are computed and
     * prefetched first, so the table's cache misses overlap.  Hashing
     * record i + k before i is placed is safe: placement writes b[out],
     * out <= i. */
    for (size_t i0 = 0; i0 < n; i0 += COLLAPSE_BATCH) {
        size_t slot[COLLAPSE_BATCH], nb = n - i0 < COLLAPSE_BATCH ? n - i0 : COLLAPSE_BATCH;
        for (size_t k = 0; k < nb; k++) {
            slot[k] = hash_xy(&b[i0 + k], cap - 1);
            __builtin_prefetch(&tab[slot[k]], 1);
        }
        for (size_t k = 0; k < nb; k++) {
            size_t i = i0 + k;
            for (size_t s = slot[k];; s = (s + 1) & (cap - 1)) {
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
    }
    *used = out;
    return GDT_OK;
}

uint64_t tl_collapse_table_bytes(uint64_t n)
{
    uint64_t cap = 16;
    while (cap < 2 * n)
        cap *= 2;
    return cap * sizeof(uint32_t);
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

/* Merges the used records of m->buf, all of their (x, y) groups, into out
 * sorted by ord.  A whole tile in memory arrives in input order and stays
 * sorted. */
static gdt_status merge_memory(mctx *m, size_t used, sink *out, gdt_error *err)
{
    gdt_status st = collapse(m, &used, err);
    if (st == GDT_OK && !sorted_by_ord(m->buf, used))
        st = tl_sort_by_ord(m->buf, used, NULL, err);
    for (size_t i = 0; i < used && st == GDT_OK; i++)
        st = sink_put(out, &m->buf[i], err);
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
    if (parts == NULL)
        return merge_memory(m, used, out, err);
    st = collapse(m, &used, err);
    if (st != GDT_OK)
        goto fail;
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

/* The merge of tile k with the worker's scratch scr (cap records at most);
 * *deepest receives its partition depth (0: in memory). */
static gdt_status merge_tile(gdt_tiler *t, uint64_t k, gdt_point *recs, scratch *scr,
                             size_t cap, unsigned *deepest, gdt_error *err)
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
    m.scr = scr;
    m.cap = cap;
    if ((uint64_t)m.cap > tl->count)
        m.cap = (size_t)tl->count; /* a small tile needs no more */
    if (m.cap > TL_MERGE_CAP_MAX)
        m.cap = TL_MERGE_CAP_MAX; /* the result does not depend on cap */
    if (m.cap < 2)
        m.cap = 2;
    if (recs != NULL || t->resident != NULL) {
        /* the tile's records, in input order, where pass 2 left them
         * (resident_workers in spill.c: fewer than TL_MERGE_CAP_MAX) or
         * as another process shipped them */
        m.buf = recs != NULL ? recs : t->resident + t->res_off[k];
        m.cap = (size_t)tl->count;
    } else if (m.cap > scr->cap) {
        free(scr->buf);
        scr->cap = 0;
        scr->buf = malloc(m.cap * sizeof *scr->buf);
        if (scr->buf == NULL) {
            st = gdt_error_set(err, GDT_EINTERNAL, 7001,
                               "out of memory (--dup merge of %zu points)", m.cap);
            goto fail;
        }
        scr->cap = m.cap;
    }
    if (recs == NULL && t->resident == NULL)
        m.buf = scr->buf;
    /* renamed without waiting for the disk: their writeback starts here and
     * pass 2 waits for every tile's files at once before it is done
     * (gdt_tiler_sync_files); a file is only ever taken back against the
     * checksum the journal recorded */
    {
        int dur = t->opts.test_nosync ? TL_SYNC_NONE : TL_SYNC_LATER;
        st = tl_wfile_init(&wp, pts_tmp, pts, t->sz.part_recs, dur, err);
        if (st == GDT_OK)
            st = tl_wfile_init(&we, edge_tmp, edge, t->sz.part_recs, dur, err);
    }
    if (st != GDT_OK)
        goto fail;
    /* the checksums the journal records, computed as the bytes go out */
    tl_wfile_hash(&wp, gdt_job_file_seed(t->opts.file_id, k, GDT_JOB_FILE_PTS));
    tl_wfile_hash(&we, gdt_job_file_seed(t->opts.file_id, k, GDT_JOB_FILE_EDGE));
    out.pts = &wp;
    out.edge = &we;
    out.x0 = tl->i * t->plan.span;
    out.y0 = tl->j * t->plan.span;
    out.span = t->plan.span;
    out.h = tl_edge_width(t);
    if (recs != NULL || t->resident != NULL)
        st = merge_memory(&m, (size_t)tl->count, &out, err);
    else
        st = merge_file(&m, raw, tl->count, 0, &out, err);
    if (st != GDT_OK)
        goto fail;
    tl->points = wp.nrec;
    tl->edge = we.nrec;
    st = tl_wfile_sum(&wp, &tl->sum[0], err);
    if (st == GDT_OK)
        st = tl_wfile_sum(&we, &tl->sum[1], err);
    if (st == GDT_OK)
        st = tl_wfile_commit(&wp, err);
    if (st == GDT_OK)
        st = tl_wfile_commit(&we, err);
    if (st != GDT_OK)
        goto fail;
    if (!t->opts.keep_spill && recs == NULL && t->resident == NULL)
        unlink(raw);
    *deepest = m.deepest;
    /* distinct bytes per tile: the workers never share one */
    t->merge_mark[k] =
        (uint8_t)(TL_MARK_MERGED | (m.deepest < TL_MARK_DEPTH ? m.deepest : TL_MARK_DEPTH));
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

#define MAX_WORKERS 16

/* State shared by the workers of tl_merge_tiles; mu guards every field. */
typedef struct pool {
    gdt_tiler *t;
    const gdt_tiler_share *sh; /* NULL: every tile is this process's */
    size_t cap;          /* records per worker */
    pthread_mutex_t mu;
    uint64_t next;       /* the next tile to take */
    uint64_t done;       /* tiles merged */
    int stop;            /* an error or a stop request: take no more tiles */
    uint64_t err_k;      /* the lowest tile that failed (UINT64_MAX: none) */
    gdt_status st;
    gdt_error err;
    unsigned *deepest;   /* per tile */
} pool;

typedef struct worker {
    pool *p;
    scratch scr;
    pthread_t tid;
} worker;

/* Takes tiles until none is left or the pool stops; with report (the
 * caller's thread) also calls the progress callback once per merged tile,
 * in order of completion. */
static void work(worker *w, int report, uint64_t *reported)
{
    pool *p = w->p;
    for (;;) {
        uint64_t k, done;
        int stop;
        gdt_status st;
        gdt_error e;
        pthread_mutex_lock(&p->mu);
        k = p->stop ? p->t->ntiles : p->next++;
        pthread_mutex_unlock(&p->mu);
        if (k >= p->t->ntiles)
            return;
        gdt_error_clear(&e);
        if (p->sh != NULL && !p->sh->mine(p->sh->ctx, k)) /* shipped: its owner merges it */
            st = GDT_OK;
        else
            st = merge_tile(p->t, k, NULL, &w->scr, p->cap, &p->deepest[k], &e);
        pthread_mutex_lock(&p->mu);
        if (st != GDT_OK) {
            p->stop = 1;
            if (k < p->err_k) {
                p->err_k = k;
                p->st = st;
                p->err = e;
            }
        } else {
            p->done++;
        }
        done = p->done;
        stop = p->stop;
        pthread_mutex_unlock(&p->mu);
        while (report && !stop && *reported < done) {
            st = tl_progress(p->t, 3, ++*reported, p->t->ntiles, &e);
            if (st != GDT_OK) {
                pthread_mutex_lock(&p->mu);
                p->stop = stop = 1;
                if (p->err_k == UINT64_MAX) {
                    /* a stop request ranks after every tile's own error */
                    p->err_k = p->t->ntiles;
                    p->st = st;
                    p->err = e;
                }
                pthread_mutex_unlock(&p->mu);
            }
        }
    }
}

static void *worker_main(void *arg)
{
    work(arg, 0, NULL);
    return NULL;
}

/* Workers: as many as the tiler's threads allow while each share of the
 * records still holds the largest tile, and each has its descriptors. */
static unsigned worker_count(const gdt_tiler *t)
{
    uint64_t largest = 0;
    unsigned w = t->opts.threads > 1 ? (unsigned)t->opts.threads : 1;
    unsigned fd_per = t->sz.merge_k + 5;
    if (t->resident != NULL)
        /* fewer than resident_workers allowed only saves hash tables */
        return t->res_workers < 1 ? 1 : t->res_workers > MAX_WORKERS ? MAX_WORKERS
                                                                     : t->res_workers;
    for (uint64_t k = 0; k < t->ntiles; k++)
        if (t->tiles[k].count > largest)
            largest = t->tiles[k].count;
    if (w > MAX_WORKERS)
        w = MAX_WORKERS;
    if ((uint64_t)w > t->ntiles)
        w = t->ntiles > 0 ? (unsigned)t->ntiles : 1;
    while (w > 1 && ((uint64_t)(t->sz.merge_cap / w) < largest || w * fd_per > t->fd_budget))
        w--;
    return w;
}

gdt_status tl_merge_tiles(gdt_tiler *t, const gdt_tiler_share *sh, gdt_error *err)
{
    unsigned nw = worker_count(t), started = 0;
    worker ws[MAX_WORKERS];
    uint64_t reported = 0;
    pool p;
    gdt_status st = GDT_OK;

    st = tl_merge_marks(t, err);
    if (st != GDT_OK)
        return st;
    /* the other processes' tiles first, so that they merge beside ours */
    for (uint64_t k = 0; sh != NULL && k < t->ntiles; k++) {
        if (sh->mine(sh->ctx, k))
            continue;
        st = sh->ship(sh->ctx, k, t->resident != NULL ? t->resident + t->res_off[k] : NULL,
                      t->tiles[k].count, err);
        if (st != GDT_OK)
            return st;
    }
    memset(&p, 0, sizeof p);
    memset(ws, 0, sizeof ws);
    p.t = t;
    p.sh = sh;
    p.cap = t->sz.merge_cap / nw;
    p.err_k = UINT64_MAX;
    p.deepest = calloc(t->ntiles + 1, sizeof *p.deepest);
    if (p.deepest == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    if (pthread_mutex_init(&p.mu, NULL) != 0) {
        free(p.deepest);
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "cannot create a mutex");
    }
    for (unsigned i = 0; i < nw; i++)
        ws[i].p = &p;
    /* a worker that cannot be started leaves its tiles to the others */
    for (unsigned i = 1; i < nw; i++)
        if (pthread_create(&ws[i].tid, NULL, worker_main, &ws[i]) == 0)
            started |= 1u << i;
    work(&ws[0], 1, &reported);
    for (unsigned i = 1; i < nw; i++)
        if (started & (1u << i))
            pthread_join(ws[i].tid, NULL);
    /* progress the last tiles (merged by other workers after ours) */
    while (p.err_k == UINT64_MAX && reported < p.done) {
        st = tl_progress(t, 3, ++reported, t->ntiles, err);
        if (st != GDT_OK)
            break;
    }
    if (st == GDT_OK && p.err_k != UINT64_MAX) {
        st = p.st;
        *err = p.err;
    }
    if (st == GDT_OK && sh == NULL)
        tl_merge_stats(t);
    for (unsigned i = 0; i < nw; i++) {
        free(ws[i].scr.buf);
        free(ws[i].scr.tab);
    }
    tl_free_resident(t);
    pthread_mutex_destroy(&p.mu);
    free(p.deepest);
    return st;
}

void tl_merge_stats(gdt_tiler *t)
{
    for (uint64_t k = 0; k < t->ntiles; k++) {
        const tl_tile *tl = &t->tiles[k];
        t->stats.merged_duplicates += tl->count - tl->points;
        unsigned depth = t->merge_mark != NULL ? t->merge_mark[k] & TL_MARK_DEPTH : 0;
        if (depth > 0)
            t->stats.external_merges++;
        if (depth > t->stats.merge_levels)
            t->stats.merge_levels = depth;
        if (tl->points > t->stats.max_tile_points)
            t->stats.max_tile_points = tl->points;
    }
}

gdt_status tl_merge_one(gdt_tiler *t, uint64_t k, gdt_point *recs, uint64_t n, gdt_error *err)
{
    scratch scr;
    unsigned deepest = 0;
    gdt_status st;
    if (k >= t->ntiles || (recs != NULL && n != t->tiles[k].count))
        return gdt_error_set(err, GDT_EINTERNAL, 7504,
                             "tile %" PRIu64 ": %" PRIu64 " records shipped, pass 1 counted "
                             "%" PRIu64,
                             k, n, k < t->ntiles ? t->tiles[k].count : 0);
    st = tl_merge_marks(t, err);
    if (st != GDT_OK)
        return st;
    memset(&scr, 0, sizeof scr);
    st = merge_tile(t, k, recs, &scr, t->sz.merge_cap, &deepest, err);
    free(scr.buf);
    free(scr.tab);
    return st;
}

gdt_status tl_merge_marks(gdt_tiler *t, gdt_error *err)
{
    if (t->merge_mark == NULL && (t->merge_mark = calloc(t->ntiles + 1, 1)) == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    return GDT_OK;
}
