/* mpi_ground.c — the ground filter (--ground pmf) shared between the ranks
 * of an MPI job, inside pass 2.
 *
 * After the shared pass 2, rank 0 sends GROUND to every other rank: the
 * tiler's state after pass 2 (every tile's files, on the shared job
 * directory) and the rank's tiles (those it merged in pass 2: contiguous
 * shares of tile order balanced by the pass-1 counts) with the subsets
 * rank 0's journal holds of them.  Each rank classifies its tiles as a
 * single process does (run_ground.c: every point with the cloud's points
 * within the filter's reach, read from the neighbours' files whoever wrote
 * them), writes their subsets, and reports them (GREC, between tiles) and
 * its end (GDONE: its status, error and figures).  Rank 0 classifies its
 * own share meanwhile, records every subset in the journal as it hears of
 * it, and takes the subsets into its tiler once every rank is done.
 *
 * --ground-out: each rank sets the bits of its tiles' records in a bits
 * file of its own (J/ground.bits.R, sparse: a rank's tiles touch few of its
 * pages); rank 0 ORs them into J/ground.bits after the last GDONE and
 * removes them.  The classes of an ordinal come from the one tile that
 * holds its record, so the OR is the single process's bitmap.
 *
 * The subsets are the same files whoever writes them, so the job's files,
 * journal and output do not depend on the number of ranks. */
#define _GNU_SOURCE /* SEEK_DATA, SEEK_HOLE */
#include "private/mpi_sched.h"
#include "private/ground_out.h"

#include <errno.h>
#include <fcntl.h>
#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#define BITS_CHUNK (1u << 20)

static int g_owner(const mr_ctx *m, uint64_t k)
{
    return mr_owner_of(m->raw_pre, m->raw_n, k, m->size);
}

static int g_mine(void *ctx, uint64_t k)
{
    return g_owner(ctx, k) == 0;
}

/* J/ground.bits.R of rank r (malloc'd; NULL when out of memory). */
static char *bits_path(const tr_run *c, int r)
{
    size_t n = strlen(c->ground_bits) + 24;
    char *p = malloc(n);
    if (p != NULL)
        snprintf(p, n, "%s.%d", c->ground_bits, r);
    return p;
}

/* Rank 0: GROUND to every other rank. */
static gdt_status g_begin(void *ctx, gdt_error *err)
{
    mr_ctx *m = ctx;
    tr_run *c = m->c;
    unsigned char *state = NULL;
    size_t slen = 0;
    gdt_status st = GDT_OK;

    if (m->raw_pre == NULL || m->raw_n != gdt_tiler_tile_count(c->tiler))
        st = mr_raw_prefix(m, c->tiler, err);
    if (st == GDT_OK)
        st = gdt_tiler_export(c->tiler, &state, &slen, err);
    if (st != GDT_OK)
        return st; /* no rank was told: none reports */
    for (int r = 1; r < m->size; r++) {
        gdt_pack p;
        uint64_t n = 0;
        memset(&p, 0, sizeof p);
        gdt_pack_bytes(&p, state, slen);
        for (uint64_t k = 0; k < m->raw_n; k++)
            n += g_owner(m, k) == r;
        gdt_pack_u64(&p, n);
        for (uint64_t k = 0; st == GDT_OK && k < m->raw_n; k++) {
            const int kinds[2] = {GDT_JOB_FILE_GPTS, GDT_JOB_FILE_GEDGE};
            if (g_owner(m, k) != r)
                continue;
            gdt_pack_u64(&p, k);
            for (int j = 0; st == GDT_OK && j < 2; j++) {
                int found = 0;
                uint64_t size = 0, sum = 0;
                st = gdt_job_get_file(c->jobdb, k, kinds[j], &found, &size, &sum, err);
                gdt_pack_u64(&p, (uint64_t)found);
                gdt_pack_u64(&p, size);
                gdt_pack_u64(&p, sum);
            }
        }
        if (st == GDT_OK)
            st = mr_send_pack(m, r, TAG_GROUND, &p, err);
        else
            gdt_pack_free(&p);
        if (st != GDT_OK) {
            /* the ranks told so far would report to no one */
            gdt_error_print(err, stderr);
            gdt_comm_abort(m->comm, (int)st);
        }
    }
    free(state);
    m->g_left = m->size - 1;
    return GDT_OK;
}

/* Rank 0: GREC and GDONE as they come (see tr_ground_share). */
static gdt_status g_collect(void *ctx, int wait, tr_ground_rec **recs, size_t *n, int *left,
                            gdt_error *err)
{
    mr_ctx *m = ctx;
    tr_run *c = m->c;
    size_t cap = 0;
    gdt_status fail = GDT_OK;

    *recs = NULL;
    *n = 0;
    while (m->g_left > 0) {
        int ready = 0, from = 0, tag = 0;
        size_t len = 0;
        unsigned char *buf = NULL;
        gdt_unpack u;
        gdt_error e;
        gdt_status st;
        gdt_error_clear(&e);
        st = wait && *n == 0 && fail == GDT_OK
                 ? gdt_comm_wait(m->comm, -1, -1, NULL, &ready, &from, &tag, &len, &e)
                 : gdt_comm_probe(m->comm, -1, -1, &ready, &from, &tag, &len, &e);
        if (st == GDT_OK && !ready)
            break;
        if (st == GDT_OK)
            st = mr_recv(m, from, tag, len, &buf, &e);
        memset(&u, 0, sizeof u);
        u.p = buf;
        u.n = len;
        if (st == GDT_OK && tag == TAG_GREC) {
            uint64_t q = gdt_unpack_u64(&u);
            if (u.bad || q > (u.n - u.at) / 64 ||
                tr_reserve(recs, &cap, *n + (size_t)q + 1, sizeof **recs) != 0) {
                st = mr_bad_message(from, tag, &e);
            } else {
                for (uint64_t i = 0; i < q; i++) {
                    tr_ground_rec *r = &(*recs)[(*n)++];
                    memset(r, 0, sizeof *r);
                    r->k = gdt_unpack_u64(&u);
                    r->own = gdt_unpack_u64(&u);
                    r->files.points = gdt_unpack_u64(&u);
                    r->files.edge = gdt_unpack_u64(&u);
                    r->files.sum[0] = gdt_unpack_u64(&u);
                    r->files.sum[1] = gdt_unpack_u64(&u);
                    r->files.deepest = gdt_unpack_u64(&u);
                    r->adopted = gdt_unpack_u64(&u) != 0;
                }
                if (u.bad)
                    st = mr_bad_message(from, tag, &e);
            }
        } else if (st == GDT_OK && tag == TAG_GDONE) {
            gdt_status rst = mr_unpack_status(m, &u, from);
            uint64_t tiles = gdt_unpack_u64(&u);
            double t = gdt_unpack_f64(&u);
            if (u.bad) {
                st = mr_bad_message(from, tag, &e);
            } else {
                m->g_left--;
                if (c->s.ranks != NULL) {
                    c->s.ranks[from].ground_tiles = tiles;
                    c->s.ranks[from].t_ground = t;
                }
                if (rst != GDT_OK && fail == GDT_OK) {
                    *err = m->job_err; /* the first failure: the job's */
                    fail = rst;
                }
            }
        } else if (st == GDT_OK) {
            st = mr_bad_message(from, tag, &e);
        }
        free(buf);
        if (st != GDT_OK) {
            /* the protocol cannot go on */
            gdt_error_print(&e, stderr);
            gdt_comm_abort(m->comm, (int)st);
        }
    }
    *left = m->g_left;
    return fail;
}

/* Rank 0: ORs the bits of every other rank into fd and removes them. */
static gdt_status g_merge_bits(void *ctx, int fd, gdt_error *err)
{
    mr_ctx *m = ctx;
    tr_run *c = m->c;
    unsigned char *a = malloc(BITS_CHUNK), *b = malloc(BITS_CHUNK);
    const off_t size = (off_t)((c->plan->points + 7) / 8);
    gdt_status st = GDT_OK;

    if (a == NULL || b == NULL)
        st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    for (int r = 1; st == GDT_OK && r < m->size; r++) {
        char *path = bits_path(c, r);
        int in = path != NULL ? open(path, O_RDONLY | O_CLOEXEC) : -1;
        off_t at = 0;
        if (in < 0) {
            st = path == NULL ? gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory")
                              : gdt_error_set(err, GDT_EIO, 4504, "%s: %s", path,
                                              strerror(errno));
            free(path);
            break;
        }
        while (st == GDT_OK && at < size) {
            /* the pages rank r wrote (a file system without holes: all) */
            off_t d = at, hole = size;
            size_t want;
            ssize_t got;
#if defined(SEEK_DATA) && defined(SEEK_HOLE)
            d = lseek(in, at, SEEK_DATA);
            if (d < 0 && errno == ENXIO)
                break;
            if (d < 0)
                d = at;
            if (d >= size)
                break;
            hole = lseek(in, d, SEEK_HOLE);
            if (hole <= d || hole > size)
                hole = size;
#endif
            want = (size_t)(hole - d) < BITS_CHUNK ? (size_t)(hole - d) : BITS_CHUNK;
            got = pread(in, b, want, d);
            if (got == (ssize_t)want && pread(fd, a, want, d) == (ssize_t)want) {
                for (size_t i = 0; i < want; i++)
                    a[i] |= b[i];
                if (pwrite(fd, a, want, d) != (ssize_t)want)
                    st = gdt_error_set(err, GDT_EIO, 4503, "%s: write failed: %s",
                                       c->ground_bits, strerror(errno));
            } else {
                st = gdt_error_set(err, GDT_EIO, 4504, "%s: read failed or short: %s", path,
                                   strerror(errno));
            }
            at = d + (off_t)want;
        }
        close(in);
        if (st == GDT_OK)
            unlink(path);
        free(path);
    }
    free(a);
    free(b);
    return st;
}

/* ---- --ground-out in shares ----
 * Its records are the input records in input order, each of the same
 * length, so a rank writes those of its pass-1 share at their places:
 * GOUT (the temporary, where the records begin, the share and its first
 * ordinal), then GOUTDONE (status, error, kept records, the share's
 * statistics for the header).  Only when this run read pass 1 in shares
 * (their ordinal bases come from it); otherwise rank 0 writes them all. */

static gdt_status o_begin(void *ctx, const char *tmp, uint64_t points_at, int *shared,
                          uint64_t *first, uint64_t *end, uint64_t *ord_base, gdt_error *err)
{
    mr_ctx *m = ctx;
    uint64_t base;
    *shared = 0;
    if (!m->p1_shared || m->p1_bounds == NULL || m->p1_kept == NULL || m->size < 2)
        return GDT_OK;
    base = m->p1_kept[0];
    for (int r = 1; r < m->size; r++) {
        gdt_pack p;
        gdt_status st;
        memset(&p, 0, sizeof p);
        gdt_pack_bytes(&p, tmp, strlen(tmp));
        gdt_pack_u64(&p, points_at);
        gdt_pack_u64(&p, m->p1_bounds[r]);
        gdt_pack_u64(&p, m->p1_bounds[r + 1]);
        gdt_pack_u64(&p, base);
        base += m->p1_kept[r];
        st = mr_send_pack(m, r, TAG_GOUT, &p, err);
        if (st != GDT_OK) {
            gdt_error_print(err, stderr);
            gdt_comm_abort(m->comm, (int)st);
        }
    }
    m->go_left = m->size - 1;
    *shared = 1;
    *first = m->p1_bounds[0];
    *end = m->p1_bounds[1];
    *ord_base = 0;
    return GDT_OK;
}

static gdt_status o_wait(void *ctx, gdt_las_copy_stats *sum, uint64_t *kept, gdt_error *err)
{
    mr_ctx *m = ctx;
    gdt_status fail = GDT_OK;
    memset(sum, 0, sizeof *sum);
    *kept = 0;
    while (m->go_left > 0) {
        unsigned char *buf = NULL;
        size_t len = 0;
        int ready = 0, from = 0, tag = 0;
        gdt_unpack u;
        gdt_las_copy_stats s;
        gdt_status rst;
        uint64_t k;
        gdt_error e;
        gdt_error_clear(&e);
        gdt_status st = gdt_comm_wait(m->comm, -1, TAG_GOUTDONE, NULL, &ready, &from, &tag, &len,
                                      &e);
        if (st == GDT_OK)
            st = mr_recv(m, from, tag, len, &buf, &e);
        memset(&u, 0, sizeof u);
        u.p = buf;
        u.n = len;
        rst = st == GDT_OK ? mr_unpack_status(m, &u, from) : GDT_OK;
        k = gdt_unpack_u64(&u);
        memset(&s, 0, sizeof s);
        s.count = gdt_unpack_u64(&u);
        for (int i = 0; i < 15; i++)
            s.by_return[i] = gdt_unpack_u64(&u);
        for (int i = 0; i < 3; i++) {
            s.lo[i] = (int32_t)(uint32_t)gdt_unpack_u64(&u);
            s.hi[i] = (int32_t)(uint32_t)gdt_unpack_u64(&u);
        }
        if (st == GDT_OK && u.bad)
            st = mr_bad_message(from, tag, &e);
        if (st != GDT_OK) {
            free(buf);
            gdt_error_print(&e, stderr);
            gdt_comm_abort(m->comm, (int)st);
        }
        m->go_left--;
        if (rst != GDT_OK && fail == GDT_OK) {
            *err = m->job_err; /* the first failure: the job's */
            fail = rst;
        } else if (rst == GDT_OK) {
            gdt_las_copy_stats_add(sum, &s);
            *kept += k;
        }
        free(buf);
    }
    return fail;
}

void mr_gout_answer(mr_ctx *m, const unsigned char *msg, size_t len)
{
    gdt_unpack u;
    size_t tl = 0;
    const unsigned char *t;
    char *tmp = NULL;
    uint64_t at, first, end, base, kept = 0;
    gdt_las_copy_stats s;
    gdt_error err, e2;
    gdt_status st = GDT_OK;
    gdt_pack p;

    memset(&u, 0, sizeof u);
    u.p = msg;
    u.n = len;
    gdt_error_clear(&err);
    memset(&s, 0, sizeof s);
    t = gdt_unpack_bytes(&u, &tl);
    at = gdt_unpack_u64(&u);
    first = gdt_unpack_u64(&u);
    end = gdt_unpack_u64(&u);
    base = gdt_unpack_u64(&u);
    if (u.bad || t == NULL)
        st = mr_bad_message(0, TAG_GOUT, &err);
    else if ((tmp = malloc(tl + 1)) == NULL)
        st = gdt_error_set(&err, GDT_EINTERNAL, 7001, "out of memory");
    if (st == GDT_OK) {
        memcpy(tmp, t, tl);
        tmp[tl] = '\0';
        st = tr_ground_out_part(m->c, tmp, at, first, end, base, &s, &kept, &err);
    }
    free(tmp);
    memset(&p, 0, sizeof p);
    mr_pack_status(&p, st, &err);
    gdt_pack_u64(&p, kept);
    gdt_pack_u64(&p, s.count);
    for (int i = 0; i < 15; i++)
        gdt_pack_u64(&p, s.by_return[i]);
    for (int i = 0; i < 3; i++) {
        gdt_pack_u64(&p, (uint64_t)(uint32_t)s.lo[i]);
        gdt_pack_u64(&p, (uint64_t)(uint32_t)s.hi[i]);
    }
    gdt_error_clear(&e2);
    if (mr_send_pack(m, 0, TAG_GOUTDONE, &p, &e2) != GDT_OK) {
        gdt_error_print(&e2, stderr);
        gdt_comm_abort(m->comm, (int)e2.status);
    }
}

void mr_ground_hooks(mr_ctx *m)
{
    m->gs.mine = g_mine;
    m->gs.begin = g_begin;
    m->gs.collect = g_collect;
    m->gs.merge_bits = g_merge_bits;
    m->gs.ctx = m;
    m->gos.begin = o_begin;
    m->gos.wait = o_wait;
    m->gos.ctx = m;
}

/* Another rank: GREC with the subsets written since the last one. */
static gdt_status g_report(void *ctx, const tr_ground_rec *recs, size_t n, gdt_error *err)
{
    mr_ctx *m = ctx;
    gdt_pack p;
    memset(&p, 0, sizeof p);
    gdt_pack_u64(&p, (uint64_t)n);
    for (size_t i = 0; i < n; i++) {
        const tr_ground_rec *r = &recs[i];
        gdt_pack_u64(&p, r->k);
        gdt_pack_u64(&p, r->own);
        gdt_pack_u64(&p, r->files.points);
        gdt_pack_u64(&p, r->files.edge);
        gdt_pack_u64(&p, r->files.sum[0]);
        gdt_pack_u64(&p, r->files.sum[1]);
        gdt_pack_u64(&p, r->files.deepest);
        gdt_pack_u64(&p, (uint64_t)r->adopted);
    }
    return mr_send_pack(m, 0, TAG_GREC, &p, err);
}

void mr_ground_answer(mr_ctx *m, const unsigned char *msg, size_t len, gdt_status *st,
                      gdt_error *err)
{
    tr_run *c = m->c;
    gdt_unpack u;
    const unsigned char *state;
    size_t slen = 0;
    uint64_t n, classified = 0, *ks = NULL;
    tr_ground_known *known = NULL;
    char *bits = NULL;
    double t0 = gdt_now();
    gdt_pack p;
    gdt_error e2;

    memset(&u, 0, sizeof u);
    u.p = msg;
    u.n = len;
    state = gdt_unpack_bytes(&u, &slen);
    n = gdt_unpack_u64(&u);
    if (u.bad || n > (u.n - u.at) / 56) {
        gdt_error_clear(&e2);
        mr_bad_message(0, TAG_GROUND, &e2);
        gdt_error_print(&e2, stderr);
        gdt_comm_abort(m->comm, (int)e2.status);
    }
    ks = malloc((size_t)(n + 1) * sizeof *ks);
    known = calloc((size_t)(n + 1), sizeof *known);
    if ((ks == NULL || known == NULL) && *st == GDT_OK)
        *st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    for (uint64_t i = 0; *st == GDT_OK && i < n; i++) {
        ks[i] = gdt_unpack_u64(&u);
        for (int j = 0; j < 2; j++) {
            known[i].found[j] = gdt_unpack_u64(&u) != 0;
            known[i].size[j] = gdt_unpack_u64(&u);
            known[i].sum[j] = gdt_unpack_u64(&u);
        }
    }
    if (*st == GDT_OK && c->opts->ground_out != NULL && (bits = bits_path(c, m->rank)) == NULL)
        *st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    if (*st == GDT_OK)
        *st = tr_run_attach_ground(c, state, slen, err);
    if (*st == GDT_OK) {
        tr_ground_part part;
        memset(&part, 0, sizeof part);
        part.ks = ks;
        part.n = n;
        part.known = known;
        part.report = g_report;
        part.ctx = m;
        part.bits_path = bits;
        *st = tr_run_ground_part(c, &part, &classified, err);
    }
    free(ks);
    free(known);
    free(bits);
    /* GDONE, whatever happened: rank 0 waits for it */
    memset(&p, 0, sizeof p);
    mr_pack_status(&p, *st, err);
    gdt_pack_u64(&p, classified);
    gdt_pack_f64(&p, gdt_now() - t0);
    gdt_error_clear(&e2);
    if (mr_send_pack(m, 0, TAG_GDONE, &p, &e2) != GDT_OK) {
        gdt_error_print(&e2, stderr);
        gdt_comm_abort(m->comm, (int)e2.status);
    }
}
