/* dupcount.c — exact out-of-core count of distinct (x, y) lattice points.
 *
 * Invariants:
 *  - rec is an open-addressing hash table (linear probing, at most 3/4 full)
 *    of (x, y, n) records, n >= 1 in occupied slots, n == 0 in free ones; the
 *    sum of n over the table and over every spill file equals the number of
 *    keys added, and a key occupies at most one slot.
 *  - a key lives in memory or in exactly one level-0 partition, chosen by
 *    hash(key, level 0); a level-L partition being re-split sends each of its
 *    records to the level-(L+1) partition hash(key, L+1), so all records of
 *    one key always end up in one leaf partition, where they are collapsed.
 *  - spill files are unlinked right after mkstemp: they disappear with their
 *    descriptor, whatever happens to the process.
 */
#include "gdt_dupcount.h"
#include "private/fd_io.h"

#include <errno.h>
#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

/* Keys hashed and prefetched together when adding. */
#define DC_BATCH 16

typedef struct dc_rec {
    int64_t x, y;
    uint64_t n;
} dc_rec;

/* K spill files being written at one partition level. */
typedef struct dc_level {
    unsigned level;
    int fd[64];
    uint64_t nrec[64];
    size_t wlen[64];   /* records waiting in the write buffer of each file */
    dc_rec *wbuf;      /* K * wcap records */
} dc_level;

struct gdt_dupcount {
    size_t budget;
    char *temp_dir;
    gdt_log *log;
    unsigned k;        /* partitions per level, <= 64 */
    size_t wcap;       /* records per partition write buffer */
    dc_rec *rec;       /* open-addressing table of cap slots (power of two); n == 0: free */
    size_t cap, used;  /* used = occupied slots */
    size_t tcap;       /* slots in use as the table now: a power of two <= cap;
                        * every slot in [tcap, cap) is free */
    dc_rec *rbuf;      /* read buffer for spill files, rcap records */
    size_t rcap;
    dc_level *top;     /* level-0 partitions once spilling started, else NULL */
    gdt_dupcount_result res;
    int finished;
    gdt_error failed;  /* sticky */
};

static uint64_t mix64(uint64_t z)
{
    z ^= z >> 30;
    z *= UINT64_C(0xbf58476d1ce4e5b9);
    z ^= z >> 27;
    z *= UINT64_C(0x94d049bb133111eb);
    z ^= z >> 31;
    return z;
}

static unsigned part_of(const dc_rec *r, unsigned level, unsigned k)
{
    uint64_t h = mix64((uint64_t)r->x + UINT64_C(0x9e3779b97f4a7c15) * (level + 1));
    h = mix64(h ^ (uint64_t)r->y);
    return (unsigned)(((h >> 32) * k) >> 32);
}

/* Table slot of a key: a hash independent of the partition hash (another
 * seed, low bits), so the keys of one partition spread over the table. */
static size_t slot_of(int64_t x, int64_t y, size_t mask)
{
    uint64_t h = mix64((uint64_t)x ^ UINT64_C(0xd6e8feb86659fd93));
    h = mix64(h + (uint64_t)y);
    return (size_t)h & mask;
}

/* Adds n occurrences of (x, y) to the table (linear probing), starting at
 * slot i = slot_of(x, y, tcap - 1).  Precondition: the table has a free slot. */
static void table_add_at(gdt_dupcount *dc, size_t i, int64_t x, int64_t y, uint64_t n)
{
    size_t mask = dc->tcap - 1;
    for (;;) {
        dc_rec *r = &dc->rec[i];
        if (r->n == 0) {
            r->x = x;
            r->y = y;
            r->n = n;
            dc->used++;
            return;
        }
        if (r->x == x && r->y == y) {
            r->n += n;
            return;
        }
        i = (i + 1) & mask;
    }
}

static void table_add(gdt_dupcount *dc, int64_t x, int64_t y, uint64_t n)
{
    table_add_at(dc, slot_of(x, y, dc->tcap - 1), x, y, n);
}

/* The table is full enough to slow probing down: at most 3/4 occupied. */
static int table_full(const gdt_dupcount *dc) { return dc->used >= dc->tcap - dc->tcap / 4; }

/* Moves the occupied slots to rec[0..used), keeping their order. */
static void table_compact(gdt_dupcount *dc)
{
    size_t out = 0;
    for (size_t i = 0; i < dc->tcap && out < dc->used; i++)
        if (dc->rec[i].n != 0)
            dc->rec[out++] = dc->rec[i];
}

static void table_clear(gdt_dupcount *dc)
{
    memset(dc->rec, 0, dc->tcap * sizeof *dc->rec);
    dc->used = 0;
}

/* Sizes the empty table for about n keys (load <= 1/2, at most cap slots):
 * reading back a small partition must not sweep the whole budget. */
static void table_resize_empty(gdt_dupcount *dc, uint64_t n)
{
    size_t t = 16;
    while (t < dc->cap && (uint64_t)t < 2 * n)
        t *= 2;
    dc->tcap = t;
}

/* Counts the table: a leaf of the partition tree.  Leaves it empty. */
static void count_leaf(gdt_dupcount *dc)
{
    for (size_t i = 0; i < dc->tcap; i++) {
        if (dc->rec[i].n == 0)
            continue;
        dc->res.distinct++;
        if (dc->rec[i].n > dc->res.max_multiplicity)
            dc->res.max_multiplicity = dc->rec[i].n;
    }
    table_clear(dc);
}

static gdt_status write_all(gdt_dupcount *dc, int fd, const void *buf, size_t len,
                            gdt_error *err)
{
    int e = gdt_fd_write_all(fd, buf, len, -1);
    if (e != 0)
        return gdt_error_set(err, GDT_EIO, 4442,
                             "cannot write a duplicate-count spill file in %s: %s", dc->temp_dir,
                             strerror(e));
    return GDT_OK;
}

static void level_free(dc_level *lv)
{
    if (lv == NULL)
        return;
    for (unsigned i = 0; i < 64; i++)
        if (lv->fd[i] >= 0)
            close(lv->fd[i]);
    free(lv->wbuf);
    free(lv);
}

/* Partition files are created on their first write: deep levels of a small
 * budget leave most of them empty. */
static gdt_status level_new(gdt_dupcount *dc, unsigned level, dc_level **out, gdt_error *err)
{
    dc_level *lv = calloc(1, sizeof *lv);

    *out = NULL;
    if (lv == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    for (unsigned i = 0; i < 64; i++)
        lv->fd[i] = -1;
    lv->level = level;
    lv->wbuf = malloc((size_t)dc->k * dc->wcap * sizeof *lv->wbuf);
    if (lv->wbuf == NULL) {
        level_free(lv);
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    }
    if (level + 1 > dc->res.levels)
        dc->res.levels = level + 1;
    *out = lv;
    return GDT_OK;
}

static gdt_status spill_file(gdt_dupcount *dc, int *fd, gdt_error *err)
{
    size_t plen = strlen(dc->temp_dir) + 32;
    char *path = malloc(plen);

    if (path == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    snprintf(path, plen, "%s/gdt-dupcount-XXXXXX", dc->temp_dir);
    *fd = mkstemp(path);
    if (*fd < 0) {
        int e = errno;
        free(path);
        return gdt_error_set(err, GDT_EIO, 4441,
                             "cannot create a duplicate-count spill file in %s: %s",
                             dc->temp_dir, strerror(e));
    }
    unlink(path);
    free(path);
    return GDT_OK;
}

static gdt_status level_flush_one(gdt_dupcount *dc, dc_level *lv, unsigned p, gdt_error *err)
{
    gdt_status st;
    if (lv->wlen[p] == 0)
        return GDT_OK;
    if (lv->fd[p] < 0) {
        st = spill_file(dc, &lv->fd[p], err);
        if (st != GDT_OK)
            return st;
    }
    st = write_all(dc, lv->fd[p], lv->wbuf + (size_t)p * dc->wcap,
                   lv->wlen[p] * sizeof *lv->wbuf, err);
    if (st != GDT_OK)
        return st;
    lv->nrec[p] += lv->wlen[p];
    dc->res.spilled_records += lv->wlen[p];
    lv->wlen[p] = 0;
    return GDT_OK;
}

static gdt_status level_flush(gdt_dupcount *dc, dc_level *lv, gdt_error *err)
{
    for (unsigned p = 0; p < dc->k; p++) {
        gdt_status st = level_flush_one(dc, lv, p, err);
        if (st != GDT_OK)
            return st;
    }
    return GDT_OK;
}

/* Moves every record of the table into the partitions of lv and empties
 * the table. */
static gdt_status distribute(gdt_dupcount *dc, dc_level *lv, gdt_error *err)
{
    table_compact(dc);
    for (size_t i = 0; i < dc->used; i++) {
        unsigned p = part_of(&dc->rec[i], lv->level, dc->k);
        if (lv->wlen[p] == dc->wcap) {
            gdt_status st = level_flush_one(dc, lv, p, err);
            if (st != GDT_OK)
                return st;
        }
        lv->wbuf[(size_t)p * dc->wcap + lv->wlen[p]++] = dc->rec[i];
    }
    table_clear(dc);
    return GDT_OK;
}

/* The table is full: spill it into the level-0 partitions. */
static gdt_status make_room(gdt_dupcount *dc, gdt_error *err)
{
    gdt_status st;
    if (dc->top == NULL) {
        st = level_new(dc, 0, &dc->top, err);
        if (st != GDT_OK)
            return st;
        gdt_log_note(dc->log, "duplicate count: memory budget of %zu bytes reached, "
                              "spilling to %s", dc->budget, dc->temp_dir);
    }
    return distribute(dc, dc->top, err);
}

static gdt_status read_exact(gdt_dupcount *dc, int fd, void *buf, size_t len, gdt_error *err)
{
    char *p = buf;
    while (len > 0) {
        ssize_t r = read(fd, p, len);
        if (r < 0 && errno == EINTR)
            continue;
        if (r <= 0)
            return gdt_error_set(err, GDT_EIO, 4443,
                                 "cannot read back a duplicate-count spill file in %s: %s",
                                 dc->temp_dir, r < 0 ? strerror(errno) : "file is short");
        p += r;
        len -= (size_t)r;
    }
    return GDT_OK;
}

/* Counts the nrec records of spill file fd, a partition of level `level`.
 * The table must be empty on entry; it is empty on return.  When the
 * partition holds more distinct keys than the table takes, the whole
 * partition is re-split one level deeper (every record of a key follows the
 * same hash, so it still ends in one leaf).  Recursion depth is bounded by
 * GDT_DUPCOUNT_MAX_LEVEL. */
static gdt_status count_file(gdt_dupcount *dc, int fd, uint64_t nrec, unsigned level,
                             gdt_error *err)
{
    dc_level *sub = NULL;
    uint64_t left = nrec;
    gdt_status st = GDT_OK;

    if (nrec == 0)
        return GDT_OK;
    if (lseek(fd, 0, SEEK_SET) != 0)
        return gdt_error_set(err, GDT_EIO, 4443, "cannot rewind a spill file in %s: %s",
                             dc->temp_dir, strerror(errno));
    table_resize_empty(dc, nrec);
    while (left > 0) {
        size_t take = dc->rcap;
        if (take > left)
            take = (size_t)left;
        st = read_exact(dc, fd, dc->rbuf, take * sizeof *dc->rbuf, err);
        if (st != GDT_OK)
            goto fail;
        left -= take;
        for (size_t i = 0; i < take; i++) {
            if (table_full(dc)) {
                if (sub == NULL) {
                    if (level + 1 > GDT_DUPCOUNT_MAX_LEVEL) {
                        st = gdt_error_set(err, GDT_EINTERNAL, 7441,
                                           "duplicate count: partitioning did not converge "
                                           "after %u levels (memory budget %zu bytes too "
                                           "small?)",
                                           level, dc->budget);
                        goto fail;
                    }
                    st = level_new(dc, level + 1, &sub, err);
                    if (st != GDT_OK)
                        goto fail;
                }
                st = distribute(dc, sub, err);
                if (st != GDT_OK)
                    goto fail;
            }
            table_add(dc, dc->rbuf[i].x, dc->rbuf[i].y, dc->rbuf[i].n);
        }
    }
    if (sub == NULL) {
        count_leaf(dc);
        return GDT_OK;
    }
    st = distribute(dc, sub, err);
    if (st == GDT_OK)
        st = level_flush(dc, sub, err);
    for (unsigned p = 0; p < dc->k && st == GDT_OK; p++) {
        st = count_file(dc, sub->fd[p], sub->nrec[p], level + 1, err);
        if (sub->fd[p] >= 0)
            close(sub->fd[p]);
        sub->fd[p] = -1;
    }
fail:
    if (st != GDT_OK)
        table_clear(dc);
    level_free(sub);
    return st;
}

gdt_status gdt_dupcount_create(gdt_dupcount **out, const gdt_dupcount_opts *opts,
                             gdt_error *err)
{
    gdt_dupcount *dc;
    const char *dir = NULL;
    size_t budget = GDT_DUPCOUNT_DEFAULT_BUDGET;

    *out = NULL;
    if (opts != NULL && opts->mem_budget != 0)
        budget = opts->mem_budget;
    if (budget < GDT_DUPCOUNT_MIN_BUDGET)
        return gdt_error_set(err, GDT_EUSAGE, 2441,
                             "duplicate-count memory budget of %zu bytes is below the minimum "
                             "of %zu",
                             budget, GDT_DUPCOUNT_MIN_BUDGET);
    if (opts != NULL && opts->temp_dir != NULL && opts->temp_dir[0] != '\0')
        dir = opts->temp_dir;
    if (dir == NULL)
        dir = getenv("TMPDIR");
    if (dir == NULL || dir[0] == '\0')
        dir = "/tmp";
    dc = calloc(1, sizeof *dc);
    if (dc == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    dc->budget = budget;
    dc->log = opts != NULL ? opts->log : NULL;
    dc->temp_dir = strdup(dir);
    /* One level of write buffers takes 1/16 of a large budget (64 KiB per
     * file at 64 MiB), 1/4 of a small one (so that tiny test budgets still
     * write a few records per call). */
    dc->k = budget >= ((size_t)8 << 20) ? 64 : budget >= ((size_t)1 << 20) ? 32 : 8;
    dc->wcap = budget / (budget >= ((size_t)1 << 20) ? 16 : 4) / dc->k / sizeof(dc_rec);
    if (dc->wcap == 0)
        dc->wcap = 1;
    /* A read buffer of 1/16 of the budget; the table gets the largest power
     * of two of slots that fits in what is left. */
    dc->rcap = budget / 16 / sizeof(dc_rec);
    if (dc->rcap == 0)
        dc->rcap = 1;
    {
        size_t rest = (budget - (size_t)dc->k * dc->wcap * sizeof(dc_rec) -
                       dc->rcap * sizeof(dc_rec)) / sizeof(dc_rec);
        dc->cap = 16;
        while (dc->cap * 2 <= rest)
            dc->cap *= 2;
        dc->tcap = dc->cap;
    }
    dc->rec = calloc(dc->cap, sizeof *dc->rec);
    dc->rbuf = malloc(dc->rcap * sizeof *dc->rbuf);
    gdt_error_clear(&dc->failed);
    if (dc->temp_dir == NULL || dc->rec == NULL || dc->rbuf == NULL) {
        gdt_dupcount_destroy(dc);
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    }
    *out = dc;
    return GDT_OK;
}

gdt_status gdt_dupcount_add(gdt_dupcount *dc, const gdt_point *pts, size_t n, gdt_error *err)
{
    gdt_status st;
    if (dc->failed.status != GDT_OK)
        return gdt_error_set(err, dc->failed.status, dc->failed.code, "%s", dc->failed.msg);
    if (dc->finished)
        return gdt_error_set(err, GDT_EINTERNAL, 7442, "gdt_dupcount_add after finish");
    /* Blocks of DC_BATCH keys: their slots are computed and prefetched
     * first, so the table's cache misses overlap instead of queueing.  The
     * table is made roomy enough for a whole block before it starts. */
    for (size_t i = 0; i < n; i += DC_BATCH) {
        size_t m = n - i < DC_BATCH ? n - i : DC_BATCH;
        size_t slot[DC_BATCH];
        if (dc->used + m > dc->tcap - dc->tcap / 4) {
            st = make_room(dc, &dc->failed);
            if (st != GDT_OK)
                return gdt_error_set(err, st, dc->failed.code, "%s", dc->failed.msg);
        }
        for (size_t k = 0; k < m; k++) {
            slot[k] = slot_of(pts[i + k].x, pts[i + k].y, dc->tcap - 1);
#if defined(__GNUC__)
            __builtin_prefetch(&dc->rec[slot[k]], 1);
#endif
        }
        for (size_t k = 0; k < m; k++)
            table_add_at(dc, slot[k], pts[i + k].x, pts[i + k].y, 1);
    }
    dc->res.points += n;
    return GDT_OK;
}

gdt_status gdt_dupcount_finish(gdt_dupcount *dc, gdt_dupcount_result *res, gdt_error *err)
{
    gdt_status st = GDT_OK;

    memset(res, 0, sizeof *res);
    if (dc->failed.status != GDT_OK)
        return gdt_error_set(err, dc->failed.status, dc->failed.code, "%s", dc->failed.msg);
    if (dc->finished)
        return gdt_error_set(err, GDT_EINTERNAL, 7442, "gdt_dupcount_finish called twice");
    dc->finished = 1;
    if (dc->top == NULL) {
        count_leaf(dc);
    } else {
        st = distribute(dc, dc->top, &dc->failed);
        if (st == GDT_OK)
            st = level_flush(dc, dc->top, &dc->failed);
        for (unsigned p = 0; p < dc->k && st == GDT_OK; p++) {
            st = count_file(dc, dc->top->fd[p], dc->top->nrec[p], 0, &dc->failed);
            if (dc->top->fd[p] >= 0)
                close(dc->top->fd[p]);
            dc->top->fd[p] = -1;
        }
        level_free(dc->top);
        dc->top = NULL;
        if (st != GDT_OK)
            return gdt_error_set(err, st, dc->failed.code, "%s", dc->failed.msg);
    }
    dc->res.duplicates = dc->res.points - dc->res.distinct;
    *res = dc->res;
    return GDT_OK;
}

void gdt_dupcount_destroy(gdt_dupcount *dc)
{
    if (dc == NULL)
        return;
    level_free(dc->top);
    free(dc->rec);
    free(dc->rbuf);
    free(dc->temp_dir);
    free(dc);
}
