/* run_ground.c — the ground stage of a tiled run (--ground pmf): after the
 * --dup merge of pass 2, every tile's points are classified with the
 * progressive morphological filter (gdt_ground.h) and only the ground
 * points stay as the tile's points.
 *
 * A tile is classified with every point of the cloud within the filter's
 * reach of it (pass 2 wrote .edge files that wide), so each point gets the
 * class a whole-cloud run of the filter gives it, whatever the tiling.
 * The tiles are shared by up to --threads workers, each holding one tile
 * and its reach within its share of half the memory budget.  The subsets
 * replace the tile files only when every tile is classified (the others'
 * reach reads the full files until then), as part of pass 2: the journal
 * records pass 2 with the ground files.  Each tile's subset is recorded in
 * the journal as soon as it is written, and a redone pass 2 (a run stopped
 * during the filter) writes the same tile files and leaves the subsets
 * alone: a tile whose recorded subset verifies is not classified again.
 *
 * Under MPI (tr_ground_share, mpi_ground.c) each process runs the same
 * workers over its own tiles: another process reports its subsets to rank
 * 0 between tiles instead of recording them, and rank 0 records them as
 * they come and takes every subset into the tiler at the end.
 */
#include "private/cli_modes.h"
#include "private/job.h"
#include "private/stages.h"
#include "private/tiler_io.h"

#include <errno.h>
#include <fcntl.h>
#include <inttypes.h>
#include <pthread.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#define BITS_PAGE 4096

/* A ground location of a tile: the (x, y) of one of its ground points. */
typedef struct xy_key {
    int64_t x, y;
} xy_key;

typedef struct ground_ctx {
    tr_run *c;
    const gdt_pmf *f;
    gdt_tiler_tile_files *files;
    uint8_t *have;      /* per tile: its subset is in files[] */
    uint64_t ntiles;
    uint64_t max_points, max_bytes;
    /* the tiles this process classifies, in turn: every tile, rank 0's
     * share (sh->mine) or another process's (part->ks) */
    const uint64_t *order;
    uint64_t norder;
    const tr_ground_share *sh;  /* rank 0 of a shared filter */
    const tr_ground_part *part; /* another process's share */
    tr_ground_rec *pend;        /* part: subsets not yet reported */
    size_t npend, cap_pend;
    int left;                   /* sh: processes still to report */
    pthread_mutex_t mu;
    uint64_t next, done, adopted;
    uint64_t ground, nonground;
    gdt_status st;      /* the first failure */
    gdt_error err;
    /* --ground-out: one bit per input ordinal (the points the filter
     * kept, duplicates included), set for ground; bits_mu guards the file */
    int bits_fd;
    const char *bits_path;
    pthread_mutex_t bits_mu;
} ground_ctx;

typedef struct ground_worker {
    ground_ctx *g;
    pthread_t tid;
    int started, report;
    gdt_point_buf own, around;
    uint8_t *keep;
    size_t cap_keep;
    gdt_point_buf raw;  /* --ground-out: the tile's pass-2 records */
    xy_key *keys;
    size_t cap_keys;
    uint64_t *ords;
    size_t cap_ords;
} ground_worker;

static int key_cmp(const void *a, const void *b)
{
    const xy_key *p = a, *q = b;
    if (p->x != q->x)
        return p->x < q->x ? -1 : 1;
    return p->y < q->y ? -1 : p->y > q->y;
}

static int ord_cmp(const void *a, const void *b)
{
    uint64_t p = *(const uint64_t *)a, q = *(const uint64_t *)b;
    return p < q ? -1 : p > q;
}

/* pread / pwrite of all n bytes at off (EINTR and short transfers
 * retried); *got: bytes read (fewer at the end of the file).  returns 0 or
 * an errno value. */
static int rw_all(int fd, unsigned char *p, size_t n, uint64_t off, int write_it, size_t *got)
{
    size_t done = 0;
    while (done < n) {
        ssize_t k = write_it ? pwrite(fd, p + done, n - done, (off_t)(off + done))
                             : pread(fd, p + done, n - done, (off_t)(off + done));
        if (k < 0 && errno == EINTR)
            continue;
        if (k < 0)
            return errno;
        if (k == 0) {
            if (write_it)
                return EIO;
            break;
        }
        done += (size_t)k;
    }
    *got = done;
    return 0;
}

/* Sets the bits of ords[0, n) (ascending) in the bitmap file, a page at a
 * time; the caller holds bits_mu. */
static gdt_status set_bits(ground_ctx *g, const uint64_t *ords, size_t n, gdt_error *err)
{
    unsigned char page[BITS_PAGE];
    for (size_t i = 0; i < n;) {
        uint64_t off = ords[i] / 8 / BITS_PAGE * BITS_PAGE;
        size_t got = 0, put = 0;
        int e = rw_all(g->bits_fd, page, BITS_PAGE, off, 0, &got);
        if (e != 0)
            return gdt_error_set(err, GDT_EIO, 4504, "%s: read failed: %s", g->bits_path,
                                 strerror(e));
        for (; i < n && ords[i] / 8 < off + got; i++)
            page[ords[i] / 8 - off] |= (unsigned char)(1u << (ords[i] % 8));
        e = rw_all(g->bits_fd, page, got, off, 1, &put);
        if (e != 0)
            return gdt_error_set(err, GDT_EIO, 4503, "%s: write failed: %s", g->bits_path,
                                 strerror(e));
        if (got == 0)
            return gdt_error_set(err, GDT_EINTERNAL, 7705,
                                 "ordinal %" PRIu64 " beyond the ground bits of %s", ords[i],
                                 g->bits_path);
    }
    return GDT_OK;
}

/* --ground-out: every pass-2 record of tile k (duplicates too) whose (x, y)
 * is a ground location of the tile gets its ordinal's bit; the tile's .raw
 * file is removed after. */
static gdt_status mark_ground(ground_worker *w, uint64_t k, gdt_error *err)
{
    ground_ctx *g = w->g;
    size_t nk = 0, no = 0;
    gdt_status st;

    if (tr_reserve(&w->keys, &w->cap_keys, w->own.n + 1, sizeof *w->keys) != 0)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    for (size_t i = 0; i < w->own.n; i++)
        if (w->keep[i]) {
            w->keys[nk].x = w->own.pts[i].x;
            w->keys[nk++].y = w->own.pts[i].y;
        }
    qsort(w->keys, nk, sizeof *w->keys, key_cmp);
    st = gdt_tiler_load_raw(g->c->tiler, k, g->max_points, &w->raw, err);
    if (st != GDT_OK)
        return st;
    if (tr_reserve(&w->ords, &w->cap_ords, w->raw.n + 1, sizeof *w->ords) != 0)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    for (size_t i = 0; i < w->raw.n; i++) {
        xy_key q = {w->raw.pts[i].x, w->raw.pts[i].y};
        if (nk > 0 && bsearch(&q, w->keys, nk, sizeof q, key_cmp) != NULL)
            w->ords[no++] = w->raw.pts[i].ord;
    }
    qsort(w->ords, no, sizeof *w->ords, ord_cmp);
    pthread_mutex_lock(&g->bits_mu);
    st = set_bits(g, w->ords, no, err);
    pthread_mutex_unlock(&g->bits_mu);
    if (st == GDT_OK)
        gdt_tiler_drop_raw(g->c->tiler, k);
    return st;
}

/* Counts tile k's subset (own: the tile's points); the caller holds mu. */
static void done_tile(ground_ctx *g, uint64_t k, const gdt_tiler_tile_files *out, uint64_t own)
{
    g->files[k] = *out;
    g->have[k] = 1;
    g->ground += out->points;
    g->nonground += own - out->points;
    g->done++;
}

/* Appends a subset to part's pending reports; the caller holds mu. */
static int pend_add(ground_ctx *g, uint64_t k, const gdt_tiler_tile_files *out, uint64_t own,
                    int adopted)
{
    tr_ground_rec *r;
    if (tr_reserve(&g->pend, &g->cap_pend, g->npend + 1, sizeof *g->pend) != 0)
        return -1;
    r = &g->pend[g->npend++];
    memset(r, 0, sizeof *r);
    r->k = k;
    r->own = own;
    r->files = *out;
    r->adopted = adopted;
    return 0;
}

/* Tile k's subset (out; own: the tile's points) is written or adopted:
 * recorded in the journal (a classified tile, so that a run stopped later
 * takes it again) and counted; another process keeps it for its report
 * instead (rank 0 records it). */
static gdt_status finish_tile(ground_ctx *g, uint64_t k, const gdt_tiler_tile_files *out,
                              uint64_t own, int adopted, gdt_error *err)
{
    gdt_status st = GDT_OK;
    pthread_mutex_lock(&g->mu);
    if (g->part != NULL) {
        if (pend_add(g, k, out, own, adopted) != 0)
            st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    } else if (!adopted) {
        st = gdt_job_begin(g->c->jobdb, err);
        if (st == GDT_OK)
            st = gdt_job_put_file(g->c->jobdb, k, GDT_JOB_FILE_GPTS,
                                  out->points * GDT_TILER_REC_BYTES, out->sum[0], err);
        if (st == GDT_OK)
            st = gdt_job_put_file(g->c->jobdb, k, GDT_JOB_FILE_GEDGE,
                                  out->edge * GDT_TILER_REC_BYTES, out->sum[1], err);
        if (st == GDT_OK)
            st = gdt_job_commit(g->c->jobdb, err);
    }
    if (st == GDT_OK) {
        done_tile(g, k, out, own);
        g->adopted += adopted != 0;
    }
    pthread_mutex_unlock(&g->mu);
    return st;
}

/* Rank 0: the subsets other processes finished (recs[0, n)) are recorded
 * in the journal, one transaction, and counted. */
static gdt_status take_remote(ground_ctx *g, const tr_ground_rec *recs, size_t n, gdt_error *err)
{
    gdt_status st;
    if (n == 0)
        return GDT_OK;
    pthread_mutex_lock(&g->mu);
    st = gdt_job_begin(g->c->jobdb, err);
    for (size_t i = 0; st == GDT_OK && i < n; i++) {
        const tr_ground_rec *r = &recs[i];
        if (r->k >= g->ntiles || g->have[r->k] || r->files.points > r->own) {
            st = gdt_error_set(err, GDT_EINTERNAL, 7708,
                               "ground filter: a subset of tile %" PRIu64 " reported twice or "
                               "out of range",
                               r->k);
            break;
        }
        if (!r->adopted) {
            st = gdt_job_put_file(g->c->jobdb, r->k, GDT_JOB_FILE_GPTS,
                                  r->files.points * GDT_TILER_REC_BYTES, r->files.sum[0], err);
            if (st == GDT_OK)
                st = gdt_job_put_file(g->c->jobdb, r->k, GDT_JOB_FILE_GEDGE,
                                      r->files.edge * GDT_TILER_REC_BYTES, r->files.sum[1], err);
        }
        if (st == GDT_OK) {
            done_tile(g, r->k, &r->files, r->own);
            g->adopted += r->adopted != 0;
        }
    }
    if (st == GDT_OK)
        st = gdt_job_commit(g->c->jobdb, err);
    pthread_mutex_unlock(&g->mu);
    return st;
}

/* A subset an earlier run of the job wrote and recorded for tile k (d: the
 * tile after pass 2) is taken when its files verify (*adopted = 1); with
 * --ground-out its ground locations mark the tile's records. */
static gdt_status adopt_subset(ground_worker *w, uint64_t i, uint64_t k, const gdt_tile_desc *d,
                               int *adopted, gdt_error *err)
{
    ground_ctx *g = w->g;
    gdt_tiler_tile_files want;
    uint64_t size[2] = {0, 0};
    int found[2] = {0, 0}, ok = 0;
    gdt_status st;

    *adopted = 0;
    memset(&want, 0, sizeof want);
    if (g->part != NULL) {
        /* rank 0's journal, as it told this process */
        const tr_ground_known *kn = &g->part->known[i];
        for (int j = 0; j < 2; j++) {
            found[j] = kn->found[j];
            size[j] = kn->size[j];
            want.sum[j] = kn->sum[j];
        }
        st = GDT_OK;
    } else {
        pthread_mutex_lock(&g->mu);
        st = gdt_job_get_file(g->c->jobdb, k, GDT_JOB_FILE_GPTS, &found[0], &size[0],
                              &want.sum[0], err);
        if (st == GDT_OK)
            st = gdt_job_get_file(g->c->jobdb, k, GDT_JOB_FILE_GEDGE, &found[1], &size[1],
                                  &want.sum[1], err);
        pthread_mutex_unlock(&g->mu);
    }
    if (st != GDT_OK || !found[0] || !found[1] || size[0] % GDT_TILER_REC_BYTES != 0 ||
        size[1] % GDT_TILER_REC_BYTES != 0)
        return st;
    want.points = size[0] / GDT_TILER_REC_BYTES;
    want.edge = size[1] / GDT_TILER_REC_BYTES;
    st = gdt_tiler_check_subset(g->c->tiler, k, &want, g->bits_fd >= 0 ? &w->own : NULL, &ok,
                                err);
    if (st != GDT_OK || !ok)
        return st;
    if (g->bits_fd >= 0) {
        /* the subset is the tile's ground: every point kept */
        if (tr_reserve(&w->keep, &w->cap_keep, w->own.n + 1, 1) != 0)
            return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        memset(w->keep, 1, w->own.n);
        st = mark_ground(w, k, err);
        if (st != GDT_OK)
            return st;
    }
    *adopted = 1;
    return finish_tile(g, k, &want, d->points, 1, err);
}

static gdt_status classify_tile(ground_worker *w, uint64_t i, gdt_error *err)
{
    int adopted = 0;
    ground_ctx *g = w->g;
    const uint64_t k = g->order[i];
    const gdt_tile_plan *plan = g->c->plan;
    const gdt_pmf_box cloud = {plan->min_x, plan->max_x, plan->min_y, plan->max_y};
    gdt_pmf_box roi;
    gdt_tile_desc d;
    gdt_tiler_tile_files out;
    size_t n;
    gdt_status st = gdt_tiler_tile_info(g->c->tiler, k, &d, err);
    if (st != GDT_OK)
        return st;
    roi.x0 = d.x0;
    roi.x1 = d.x0 + plan->span - 1;
    roi.y0 = d.y0;
    roi.y1 = d.y0 + plan->span - 1;
    st = adopt_subset(w, i, k, &d, &adopted, err);
    if (st != GDT_OK || adopted)
        return st;
    st = gdt_tiler_load_reach(g->c->tiler, k, g->f->reach, g->max_points, &w->own, &w->around,
                              err);
    if (st == GDT_EUSAGE && err->code == 2506) {
        /* the tiler's message speaks of the tile stage's budget */
        gdt_error_clear(err);
        return gdt_error_set(err, GDT_EUSAGE, 2506,
                             "tile (%" PRId64 ", %" PRId64 ") with the ground filter's reach "
                             "holds more than %" PRIu64 " points, more than a filter worker's "
                             "share of three quarters of the memory budget of %" PRIu64
                             " bytes: use a smaller --tile, fewer --threads or a larger "
                             "--mem-budget",
                             d.i, d.j, g->max_points, gdt_tiler_get_stats(g->c->tiler)->mem_budget);
    }
    if (st != GDT_OK)
        return st;
    n = w->own.n + w->around.n;
    if (tr_reserve(&w->keep, &w->cap_keep, n, 1) != 0)
        return gdt_error_set(err, GDT_EINTERNAL, 7001,
                             "out of memory (ground filter of %zu points)", n);
    /* own points first: the classes of the reach are not kept */
    st = gdt_pmf_classify(g->f, w->own.pts, w->own.n, w->around.pts, w->around.n, &cloud, &roi,
                          w->keep, g->max_bytes, err);
    if (st == GDT_OK)
        st = gdt_tiler_write_subset(g->c->tiler, k, w->own.pts, w->own.n, w->keep, &out, err);
    if (st == GDT_OK && g->bits_fd >= 0)
        st = mark_ground(w, k, err);
    if (st != GDT_OK)
        return st;
    return finish_tile(g, k, &out, w->own.n, 0, err);
}

/* Keeps the first failure (the workers stop at their next tile). */
static void fail(ground_ctx *g, gdt_status st, const gdt_error *e)
{
    pthread_mutex_lock(&g->mu);
    if (g->st == GDT_OK) {
        g->st = st;
        g->err = *e;
    }
    pthread_mutex_unlock(&g->mu);
}

/* The messages of a shared filter, on the caller's thread: rank 0 takes
 * what the others finished (wait: until one message came, while some are
 * still at work); another process reports its pending subsets. */
static void exchange(ground_ctx *g, int wait)
{
    gdt_error e;
    gdt_status st = GDT_OK;
    gdt_error_clear(&e);
    if (g->sh != NULL && (g->left > 0 || !wait)) {
        tr_ground_rec *recs = NULL;
        size_t n = 0;
        st = g->sh->collect(g->sh->ctx, wait, &recs, &n, &g->left, &e);
        if (st != GDT_OK)
            fail(g, st, &e); /* a process's failure: the others are still collected */
        gdt_error_clear(&e);
        st = take_remote(g, recs, n, &e);
        free(recs);
    } else if (g->part != NULL) {
        tr_ground_rec *recs;
        size_t n;
        pthread_mutex_lock(&g->mu);
        recs = g->pend;
        n = g->npend;
        g->pend = NULL;
        g->npend = g->cap_pend = 0;
        pthread_mutex_unlock(&g->mu);
        if (n > 0)
            st = g->part->report(g->part->ctx, recs, n, &e);
        free(recs);
    }
    if (st != GDT_OK)
        fail(g, st, &e);
}

/* Takes tiles until none is left or one failed; worker 0 (the caller's
 * thread) reports progress. */
static void *worker_main(void *arg)
{
    ground_worker *w = arg;
    ground_ctx *g = w->g;
    for (;;) {
        gdt_error e;
        gdt_status st;
        uint64_t k;
        pthread_mutex_lock(&g->mu);
        k = g->next < g->norder && g->st == GDT_OK ? g->next++ : UINT64_MAX;
        pthread_mutex_unlock(&g->mu);
        if (k == UINT64_MAX)
            break;
        gdt_error_clear(&e);
        st = tr_stopped(g->c) ? gdt_error_set(&e, GDT_EINTERRUPTED, 1303,
                                              "stopped by a signal during the ground filter")
                              : classify_tile(w, k, &e);
        if (st != GDT_OK) {
            fail(g, st, &e);
            break;
        }
        if (w->report) {
            exchange(g, 0);
            pthread_mutex_lock(&g->mu);
            uint64_t done = g->done;
            pthread_mutex_unlock(&g->mu);
            gdt_progress_update(&g->c->prog, done);
        }
    }
    return NULL;
}

/* The ground stage holds at most three quarters of the memory budget:
 * nothing else of the run is large while it runs (pass 2's buffers are
 * gone, the core has not grown its tile buffers yet). */
static uint64_t ground_budget(const gdt_tiler_stats *ts)
{
    return ts->mem_budget / 4 * 3;
}

/* Workers: up to threads, as many as can each hold the largest tile with
 * its reach (its points times the reach's area growth at the same density,
 * and the filter's grid) within their share of the stage's budget; at
 * least one (a tile beyond it is refused when loaded, GDT-2506). */
static unsigned ground_workers(const tr_run *c, const gdt_pmf *f, const gdt_tiler_stats *ts,
                               unsigned threads)
{
    const gdt_tile_plan *pl = c->plan;
    const uint64_t ntiles = gdt_tiler_tile_count(c->tiler);
    const double T = (double)pl->span, grow = (T + 2.0 * (double)f->reach) / T;
    const double side = (T + 2.0 * (double)f->reach) * f->fx + 2.0 * (double)f->reach_cells;
    const double need = (double)ts->max_tile_points * grow * grow *
                            (double)(sizeof(gdt_point) + 1 + GDT_PMF_BYTES_PER_POINT) +
                        side * side * GDT_PMF_BYTES_PER_CELL;
    unsigned nw = threads > 0 ? threads : 1;
    if (nw > ntiles)
        nw = ntiles > 0 ? (unsigned)ntiles : 1;
    while (nw > 1 && need * nw > (double)ground_budget(ts))
        nw--;
    return nw;
}

/* Creates a --ground-out bits file of nbits zero bits (a sparse file). */
static gdt_status bits_create(const char *path, uint64_t nbits, int *fd, gdt_error *err)
{
    *fd = open(path, O_RDWR | O_CREAT | O_TRUNC | O_CLOEXEC, 0666);
    if (*fd < 0 || ftruncate(*fd, (off_t)((nbits + 7) / 8)) != 0)
        return gdt_error_set(err, GDT_EIO, 4502, "cannot create %s: %s", path, strerror(errno));
    return GDT_OK;
}

/* The filter over this process's tiles: alone (sh and part NULL), rank 0
 * of a shared filter (sh) or another process (part); see stages.h. */
static gdt_status ground_run(tr_run *c, const tr_ground_share *sh, const tr_ground_part *part,
                             uint64_t *classified, gdt_error *err)
{
    const gdt_options *opts = c->opts;
    const uint64_t ntiles = gdt_tiler_tile_count(c->tiler);
    const gdt_tiler_stats *ts = gdt_tiler_get_stats(c->tiler);
    ground_ctx g;
    ground_worker *w = NULL;
    uint64_t *order = NULL;
    gdt_pmf f;
    unsigned nw;
    double t0 = gdt_now();
    gdt_status st;

    st = gdt_pmf_init(&f, &opts->pmf, &c->plan->lattice, c->plan->min_z, err);
    if (st != GDT_OK)
        return st;
    memset(&g, 0, sizeof g);
    g.c = c;
    g.f = &f;
    g.ntiles = ntiles;
    g.sh = sh;
    g.part = part;
    g.bits_fd = -1;
    pthread_mutex_init(&g.mu, NULL);
    pthread_mutex_init(&g.bits_mu, NULL);
    g.files = calloc(ntiles > 0 ? ntiles : 1, sizeof *g.files);
    g.have = calloc(ntiles > 0 ? ntiles : 1, 1);
    if (part == NULL)
        order = malloc((ntiles > 0 ? ntiles : 1) * sizeof *order);
    if (g.files == NULL || g.have == NULL || (part == NULL && order == NULL)) {
        st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        goto out;
    }
    if (part != NULL) {
        for (uint64_t i = 0; i < part->n; i++)
            if (part->ks[i] >= ntiles) {
                st = gdt_error_set(err, GDT_EINTERNAL, 7708,
                                   "ground filter: tile %" PRIu64 " of %" PRIu64 " tiles",
                                   part->ks[i], ntiles);
                goto out;
            }
        g.order = part->ks;
        g.norder = part->n;
    } else {
        for (uint64_t k = 0; k < ntiles; k++)
            if (sh == NULL || sh->mine(sh->ctx, k))
                order[g.norder++] = k;
        g.order = order;
    }
    nw = ground_workers(c, &f, ts, (unsigned)gdt_cli_threads(opts->threads));
    if (nw > g.norder && g.norder > 0)
        nw = (unsigned)g.norder;
    /* each worker's share of the stage's budget: its points (own and
     * reach, 32 bytes and a class byte each), and the filter's arrays and
     * grid within the rest */
    g.max_bytes = ground_budget(ts) / nw;
    g.max_points = g.max_bytes / (sizeof(gdt_point) + 1 + GDT_PMF_BYTES_PER_POINT);
    w = calloc(nw, sizeof *w);
    if (w == NULL) {
        st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        goto out;
    }
    if (opts->ground_out != NULL) {
        /* one bit per ordinal, zero: not ground */
        g.bits_path = part != NULL ? part->bits_path : c->ground_bits;
        st = bits_create(g.bits_path, c->plan->points, &g.bits_fd, err);
        if (st != GDT_OK)
            goto out;
    }
    if (sh != NULL) {
        /* the others classify theirs beside this process */
        g.left = 0;
        st = sh->begin(sh->ctx, err);
        if (st != GDT_OK)
            goto out;
        g.left = 1; /* until collect says how many */
    }
    gdt_progress_stage(&c->prog, "ground filter", ntiles, "tiles");
    for (unsigned i = 0; i < nw; i++) {
        w[i].g = &g;
        if (i > 0 && pthread_create(&w[i].tid, NULL, worker_main, &w[i]) == 0)
            w[i].started = 1;
    }
    /* the caller's thread is worker 0 (it takes every tile if no thread
     * could start), reports progress and exchanges the messages of a
     * shared filter between tiles */
    w[0].report = 1;
    worker_main(&w[0]);
    for (unsigned i = 1; i < nw; i++)
        if (w[i].started)
            pthread_join(w[i].tid, NULL);
    c->s.t_ground_own = gdt_now() - t0;
    /* every other process reports, whatever happened here */
    while (sh != NULL && g.left > 0) {
        exchange(&g, 1);
        gdt_progress_update(&c->prog, g.done);
    }
    if (part != NULL)
        exchange(&g, 0);
    gdt_progress_update(&c->prog, g.done);
    gdt_progress_end(&c->prog);
    st = g.st;
    if (st != GDT_OK) {
        *err = g.err;
        goto out;
    }
    *classified = g.done;
    if (part != NULL) {
        /* the bits are rank 0's to merge once this process has reported */
        if (g.bits_fd >= 0 && fsync(g.bits_fd) != 0)
            st = gdt_error_set(err, GDT_EIO, 4505, "%s: fsync failed: %s", g.bits_path,
                               strerror(errno));
        goto out;
    }
    if (g.done != ntiles) {
        st = gdt_error_set(err, GDT_EINTERNAL, 7709,
                           "ground filter: %" PRIu64 " of %" PRIu64 " tiles have no subset",
                           ntiles - g.done, ntiles);
        goto out;
    }
    st = gdt_tiler_take_subsets(c->tiler, g.files, err);
    if (st == GDT_OK && g.bits_fd >= 0 && sh != NULL)
        st = sh->merge_bits(sh->ctx, g.bits_fd, err);
    if (st == GDT_OK && g.bits_fd >= 0) {
        /* durable, and its sum for the journal (recorded with pass 2) */
        if (fsync(g.bits_fd) != 0)
            st = gdt_error_set(err, GDT_EIO, 4505, "%s: fsync failed: %s", c->ground_bits,
                               strerror(errno));
        if (st == GDT_OK)
            st = tl_file_sum(c->ground_bits, gdt_job_file_seed(c->job_id, 0, GDT_JOB_FILE_BITS),
                             &c->s.ground_bits_size, &c->s.ground_bits_sum, err);
    }
    if (st == GDT_OK) {
        c->s.ground_points = g.ground;
        c->s.nonground_points = g.nonground;
        c->s.t_ground = gdt_now() - t0;
        c->s.ground_tiles_reused = g.adopted;
        gdt_log_note(&c->log,
                     "ground filter: %" PRIu64 " ground and %" PRIu64 " other points in %.2f s "
                     "(%d windows, reach %" PRId64 " lattice steps, %u workers%s; %" PRIu64
                     " tiles classified by an earlier run)",
                     g.ground, g.nonground, c->s.t_ground, f.rounds, f.reach, nw,
                     sh != NULL ? " on each rank" : "", g.adopted);
    }
out:
    for (unsigned i = 0; w != NULL && i < nw; i++) {
        gdt_point_buf_free(&w[i].own);
        gdt_point_buf_free(&w[i].around);
        gdt_point_buf_free(&w[i].raw);
        free(w[i].keep);
        free(w[i].keys);
        free(w[i].ords);
    }
    if (g.bits_fd >= 0)
        close(g.bits_fd);
    pthread_mutex_destroy(&g.bits_mu);
    pthread_mutex_destroy(&g.mu);
    free(w);
    free(order);
    free(g.pend);
    free(g.have);
    free(g.files);
    return st;
}

gdt_status tr_run_ground(tr_run *c, gdt_error *err)
{
    uint64_t n = 0;
    return ground_run(c, c->gshare, NULL, &n, err);
}

gdt_status tr_run_ground_part(tr_run *c, const tr_ground_part *part, uint64_t *classified,
                              gdt_error *err)
{
    *classified = 0;
    return ground_run(c, NULL, part, classified, err);
}
