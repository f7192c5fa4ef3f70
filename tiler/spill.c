/* spill.c — pass 2: every point to its tile's spill file, in input order.
 *
 * design:
 *   level(source, tiles [a, b)):
 *     if b - a <= writers and the write budget gives every tile a buffer of
 *        at least min_file_recs: write each record to its tile's file (direct)
 *     else: cut [a, b) into G contiguous groups (G <= writers), write each
 *        record to its group's bucket file; then, for each bucket, level(bucket,
 *        its group) and remove the bucket.
 *   pass 2 = level(the cloud, all tiles)
 * Appending preserves order at every level, so each tile file holds its
 * points in input order whatever the budgets: the bytes do not depend on
 * them.  Only one level's write buffers and descriptors exist at a time
 * (a level's buckets are closed before its children run), so memory is at
 * most read buffer + write_bytes (one pool, split evenly between the
 * level's files), and descriptors at most writers + 1.
 * In memory: when half the budget holds every record (pass 1 counted them)
 * and the merge workers' hash tables, each record goes straight to its
 * tile's range of one array, in input order: the records the merge would
 * read back from the .raw files, without writing them.  The array's
 * pages are faulted in ahead of the scatter by a helper thread
 * (MADV_POPULATE_WRITE), on the core the single-threaded read leaves idle.
 */
#define _GNU_SOURCE 1 /* MADV_POPULATE_WRITE */
#include "private/tiler_impl.h"
#include "private/tiler_io.h"

#include <inttypes.h>
#include <pthread.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <unistd.h>

#ifndef MADV_POPULATE_WRITE
#define MADV_POPULATE_WRITE 23 /* Linux 5.14 */
#endif

typedef struct spill_src {
    gdt_cloud *cloud;   /* either the cloud ... */
    tl_rfile *rf;       /* ... or a bucket file */
} spill_src;

typedef struct bucket {
    uint64_t a, b;      /* tiles [a, b) */
    uint64_t nrec;
    char *path;         /* owned */
} bucket;

typedef struct bucket_list {
    bucket *v;
    size_t n;
} bucket_list;

/* Last tile found: points arrive in runs from one tile. */
typedef struct tile_cache {
    int64_t x0, y0;
    uint64_t k;
} tile_cache;

static void buckets_free(bucket_list *l)
{
    for (size_t i = 0; i < l->n; i++) {
        if (l->v[i].path != NULL)
            unlink(l->v[i].path);
        free(l->v[i].path);
    }
    free(l->v);
    memset(l, 0, sizeof *l);
}

static gdt_status src_read(spill_src *s, gdt_point *buf, size_t cap, size_t *n, gdt_error *err)
{
    if (s->cloud != NULL)
        return gdt_cloud_read(s->cloud, buf, cap, n, err);
    return tl_rfile_read(s->rf, buf, cap, n, err);
}

static uint64_t find_tile(const gdt_tiler *t, tile_cache *c, const gdt_point *p)
{
    const int64_t T = t->plan.span;
    uint64_t k;
    if (c->k != UINT64_MAX && (uint64_t)(p->x - c->x0) < (uint64_t)T &&
        (uint64_t)(p->y - c->y0) < (uint64_t)T)
        return c->k;
    k = tl_tile_of(t, p->x, p->y);
    if (k != UINT64_MAX) {
        c->k = k;
        c->x0 = t->tiles[k].i * T;
        c->y0 = t->tiles[k].j * T;
    }
    return k;
}

/* One level: reads s (src_recs records) to its end, writing tiles [a, b)
 * either to their tile files (*children empty) or to buckets (listed in
 * *children). */
static gdt_status run_level(gdt_tiler *t, spill_src *s, uint64_t src_recs, uint64_t a,
                            uint64_t b, unsigned level, gdt_point *buf, bucket_list *children,
                            gdt_error *err)
{
    const uint64_t m = b - a;
    const unsigned writers = t->fd_budget - 1;
    const size_t wrecs = t->sz.write_bytes / TL_REC;
    const int raw_final = t->opts.keep_spill;
    tl_wfile *w = NULL;
    unsigned char *pool = NULL;
    tile_cache cache = {0, 0, UINT64_MAX};
    uint64_t group = 1, nw, done = 0;
    size_t cap;
    gdt_status st = GDT_OK;

    memset(children, 0, sizeof *children);
    if (m <= writers && wrecs / m >= t->sz.min_file_recs) {
        nw = m;
    } else {
        uint64_t g = writers;
        if (g > wrecs / t->sz.min_file_recs)
            g = wrecs / t->sz.min_file_recs;
        if (g < 2)
            g = 2;
        group = (m + g - 1) / g;
        nw = (m + group - 1) / group;
    }
    /* No file can receive more than the source holds. */
    cap = wrecs / nw;
    if ((uint64_t)cap > src_recs)
        cap = (size_t)src_recs;
    if (cap < 1)
        cap = 1;
    w = calloc(nw, sizeof *w);
    pool = malloc(nw * cap * TL_REC);
    if (w == NULL || pool == NULL) {
        free(w);
        free(pool);
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory (pass 2 write buffers)");
    }
    /* The pool is touched at once (a non-zero fill, which the compiler cannot
     * turn into a lazy calloc): the footprint of pass 2 is the budget's, the
     * same for every input, not a function of how full the tiles get. */
    memset(pool, 0x5a, nw * cap * TL_REC);
    for (uint64_t d = 0; d < nw; d++)
        w[d].fd = -1;
    if (group > 1) {
        children->v = calloc(nw, sizeof *children->v);
        if (children->v == NULL) {
            st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
            goto fail;
        }
    }
    for (uint64_t d = 0; d < nw; d++) {
        char *tmp = NULL, *fin = NULL;
        if (group == 1) {
            tmp = tl_tile_file(t, a + d, "raw", 1);
            fin = raw_final ? tl_tile_file(t, a + d, "raw", 0) : NULL;
        } else {
            uint64_t ga = a + d * group, gb = ga + group < b ? ga + group : b;
            tmp = tl_path("%s/bucket_%u_%" PRIu64 ".tmp%s", t->tiles_dir, level, ga,
                          t->spill_part);
            children->v[d].a = ga;
            children->v[d].b = gb;
        }
        if (tmp == NULL || (raw_final && group == 1 && fin == NULL))
            st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        else
            st = tl_wfile_init_buf(&w[d], tmp, fin, pool + d * cap * TL_REC, cap,
                                   group == 1 && raw_final && !t->opts.test_nosync, err);
        free(tmp);
        free(fin);
        if (st != GDT_OK)
            goto fail;
    }
    for (;;) {
        size_t n = 0;
        st = src_read(s, buf, t->sz.read_cap, &n, err);
        if (st != GDT_OK)
            goto fail;
        if (n == 0)
            break;
        for (size_t i = 0; i < n; i++) {
            uint64_t k = find_tile(t, &cache, &buf[i]);
            if (k < a || k >= b) {
                st = gdt_error_set(err, GDT_EINPUT, 3501,
                                   "the input changed between the two passes: point %" PRIu64
                                   " at lattice (%" PRId64 ", %" PRId64
                                   ") is in no tile counted by pass 1",
                                   buf[i].ord, buf[i].x, buf[i].y);
                goto fail;
            }
            st = tl_wfile_put(&w[(k - a) / group], &buf[i], err);
            if (st != GDT_OK)
                goto fail;
        }
        done += n;
        if (s->cloud != NULL) {
            st = tl_progress(t, 2, done, t->plan.points, err);
            if (st != GDT_OK)
                goto fail;
        }
    }
    for (uint64_t d = 0; d < nw; d++) {
        uint64_t nrec = w[d].nrec;
        if (group > 1 && nrec == 0) {
            tl_wfile_abort(&w[d]);
            continue;
        }
        if (group > 1) {
            children->v[children->n].a = children->v[d].a;
            children->v[children->n].b = children->v[d].b;
            children->v[children->n].nrec = nrec;
            children->v[children->n].path = strdup(w[d].tmp_path);
            if (children->v[children->n].path == NULL) {
                st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
                goto fail;
            }
            children->n++;
            t->stats.bucket_records += nrec;
        } else {
            t->tiles[a + d].written += nrec;
        }
        st = tl_wfile_commit(&w[d], err);
        if (st != GDT_OK)
            goto fail;
    }
    if (group > 1 && level + 1 > t->stats.spill_levels)
        t->stats.spill_levels = level + 1;
    free(w);
    free(pool);
    return GDT_OK;
fail:
    for (uint64_t d = 0; d < nw; d++)
        tl_wfile_abort(&w[d]);
    free(w);
    free(pool);
    buckets_free(children);
    return st;
}

/* Distributes the records of bucket bk (a file of level `level`) and removes it. */
static gdt_status run_bucket(gdt_tiler *t, bucket *bk, unsigned level, gdt_point *buf,
                             gdt_error *err)
{
    tl_rfile rf;
    spill_src s = {NULL, &rf};
    bucket_list children = {0};
    gdt_status st;

    st = tl_rfile_open(&rf, bk->path, bk->nrec, t->sz.read_cap, err);
    if (st != GDT_OK)
        return st;
    st = run_level(t, &s, bk->nrec, bk->a, bk->b, level, buf, &children, err);
    tl_rfile_close(&rf);
    unlink(bk->path);
    if (st != GDT_OK)
        return st;
    for (size_t i = 0; i < children.n && st == GDT_OK; i++)
        st = run_bucket(t, &children.v[i], level + 1, buf, err);
    buckets_free(&children);
    return st;
}

/* Merge workers that can run on resident records: up to the tiler's
 * threads and half the descriptor budget (a worker writes two files at a
 * time), as long as the records and every worker's hash table for the
 * largest tile fit in half the budget; 0 when not even one does (or the
 * .raw files are wanted, or the test knobs force the file paths). */
unsigned tl_resident_workers(const gdt_tiler *t)
{
    uint64_t total = 0, largest = 0, half = t->budget / 2;
    unsigned w = t->opts.threads > 1 ? (unsigned)t->opts.threads : 1;
    if (t->opts.keep_spill || t->opts.test_tiny || t->ntiles == 0)
        return 0;
    for (uint64_t k = 0; k < t->ntiles; k++) {
        total += t->tiles[k].count;
        if (t->tiles[k].count > largest)
            largest = t->tiles[k].count;
    }
    if (total > half / sizeof(gdt_point) || total > SIZE_MAX / sizeof(gdt_point) ||
        largest >= TL_MERGE_CAP_MAX)
        return 0;
    if ((uint64_t)w > t->ntiles)
        w = (unsigned)t->ntiles;
    if (w > t->fd_budget / 2)
        w = t->fd_budget / 2; /* fd_budget >= 4 */
    while (w > 0 && total * sizeof(gdt_point) + w * tl_collapse_table_bytes(largest) > half)
        w--;
    return w;
}

/* Faults in [p, p + n) front to back, 8 MiB at a time, until done or
 * *stop (a kernel without MADV_POPULATE_WRITE ends it at once). */
typedef struct prefault {
    pthread_t tid;
    unsigned char *p;
    size_t n;
    int stop; /* __atomic accesses */
} prefault;

static void *prefault_main(void *arg)
{
    prefault *f = arg;
    const size_t step = (size_t)8 << 20;
    for (size_t at = 0; at < f->n && !__atomic_load_n(&f->stop, __ATOMIC_RELAXED); at += step)
        if (madvise(f->p + at, f->n - at < step ? f->n - at : step, MADV_POPULATE_WRITE) != 0)
            break;
    return NULL;
}

/* Starts a prefault of the whole pages inside [p, p + n); 0 if none runs. */
static int prefault_start(prefault *f, void *p, size_t n)
{
    long pg = sysconf(_SC_PAGESIZE);
    uintptr_t a = (uintptr_t)p, b = a + n;
    if (pg <= 0)
        return 0;
    a = (a + (uintptr_t)pg - 1) / (uintptr_t)pg * (uintptr_t)pg;
    b = b / (uintptr_t)pg * (uintptr_t)pg;
    if (b <= a || b - a < ((size_t)8 << 20))
        return 0; /* not worth a thread */
    f->p = (unsigned char *)a;
    f->n = b - a;
    __atomic_store_n(&f->stop, 0, __ATOMIC_RELAXED);
    return pthread_create(&f->tid, NULL, prefault_main, f) == 0;
}

/* Pass 2 into t->resident (see the design note). */
static gdt_status spill_resident(gdt_tiler *t, gdt_point *buf, gdt_error *err)
{
    tile_cache cache = {0, 0, UINT64_MAX};
    uint64_t *fill, done = 0;
    gdt_status st = GDT_OK;
    prefault pf;
    int pf_running;

    t->res_off = malloc((t->ntiles + 1) * sizeof *t->res_off);
    fill = malloc(t->ntiles * sizeof *fill);
    if (t->res_off == NULL || fill == NULL) {
        free(fill);
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    }
    t->res_off[0] = 0;
    for (uint64_t k = 0; k < t->ntiles; k++) {
        fill[k] = t->res_off[k];
        t->res_off[k + 1] = t->res_off[k] + t->tiles[k].count;
    }
    t->resident = malloc((size_t)t->res_off[t->ntiles] * sizeof *t->resident);
    if (t->resident == NULL) {
        free(fill);
        return gdt_error_set(err, GDT_EINTERNAL, 7001,
                             "out of memory (pass 2 in memory, %" PRIu64 " points)",
                             t->res_off[t->ntiles]);
    }
    pf_running = prefault_start(&pf, t->resident,
                                (size_t)t->res_off[t->ntiles] * sizeof *t->resident);
    for (;;) {
        size_t n = 0;
        st = gdt_cloud_read(t->cloud, buf, t->sz.read_cap, &n, err);
        if (st != GDT_OK || n == 0)
            break;
        for (size_t i = 0; i < n; i++) {
            uint64_t k = find_tile(t, &cache, &buf[i]);
            if (k == UINT64_MAX || fill[k] == t->res_off[k + 1]) {
                st = gdt_error_set(err, GDT_EINPUT, 3501,
                                   "the input changed between the two passes: point %" PRIu64
                                   " at lattice (%" PRId64 ", %" PRId64 ") is %s",
                                   buf[i].ord, buf[i].x, buf[i].y,
                                   k == UINT64_MAX ? "in no tile counted by pass 1"
                                                   : "one more than pass 1 counted in its tile");
                break;
            }
            t->resident[fill[k]++] = buf[i];
        }
        done += n;
        if (st == GDT_OK)
            st = tl_progress(t, 2, done, t->plan.points, err);
        if (st != GDT_OK)
            break;
    }
    if (pf_running) {
        __atomic_store_n(&pf.stop, 1, __ATOMIC_RELAXED);
        pthread_join(pf.tid, NULL);
    }
    for (uint64_t k = 0; k < t->ntiles; k++)
        t->tiles[k].written = fill[k] - t->res_off[k];
    free(fill);
    return st;
}

gdt_status tl_spill_files(gdt_tiler *t, gdt_error *err)
{
    spill_src s = {t->cloud, NULL};
    bucket_list children = {0};
    gdt_point *buf = malloc(t->sz.read_cap * sizeof *buf);
    gdt_status st;

    if (buf == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    st = run_level(t, &s, t->plan.points, 0, t->ntiles, 0, buf, &children, err);
    for (size_t i = 0; i < children.n && st == GDT_OK; i++)
        st = run_bucket(t, &children.v[i], 1, buf, err);
    buckets_free(&children);
    free(buf);
    return st;
}

gdt_status tl_spill(gdt_tiler *t, gdt_error *err)
{
    gdt_point *buf;
    gdt_status st;

    buf = malloc(t->sz.read_cap * sizeof *buf);
    if (buf == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    if (t->ntiles == 0) {
        /* Nothing can be written; the stream must still be empty. */
        size_t n = 0;
        st = gdt_cloud_read(t->cloud, buf, t->sz.read_cap, &n, err);
        if (st == GDT_OK && n > 0)
            st = gdt_error_set(err, GDT_EINPUT, 3501,
                               "the input changed between the two passes: it now has points");
        free(buf);
        return st;
    }
    t->res_workers = tl_resident_workers(t);
    if (t->res_workers > 0) {
        t->stats.spill_in_memory = 1;
        st = spill_resident(t, buf, err);
        free(buf);
        return st;
    }
    free(buf);
    return tl_spill_files(t, err);
}
