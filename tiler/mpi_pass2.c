/* mpi_pass2.c — pass 2 shared between the ranks of an MPI job: rank 0
 * spills, ships each tile to its owner (a contiguous share of tile order
 * balanced by pass-1 counts) and merges its own; the owners merge theirs
 * into the shared job directory and report each tile's files. */
#include "private/mpi_sched.h"

#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "private/tiled_files.h"

/* The pass-1 prefix sums of the tiler's tiles into m->raw_pre. */
gdt_status mr_raw_prefix(mr_ctx *m, const gdt_tiler *t, gdt_error *err)
{
    uint64_t n = gdt_tiler_tile_count(t);
    free(m->raw_pre);
    m->raw_pre = malloc((n + 1) * sizeof *m->raw_pre);
    if (m->raw_pre == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    m->raw_n = n;
    m->raw_pre[0] = 0;
    for (uint64_t k = 0; k < n; k++) {
        gdt_tile_desc d;
        gdt_status st = gdt_tiler_tile_info(t, k, &d, err);
        if (st != GDT_OK)
            return st;
        m->raw_pre[k + 1] = m->raw_pre[k] + d.raw_points;
    }
    return GDT_OK;
}

static int p2_owner(const mr_ctx *m, uint64_t k)
{
    return mr_owner_of(m->raw_pre, m->raw_n, k, m->size);
}

static int p2_mine(void *ctx, uint64_t k)
{
    return p2_owner(ctx, k) == 0;
}

/* Rank 0, after pass 1: the tiler's state to every other rank. */
static gdt_status p2_begin(void *ctx, gdt_error *err)
{
    mr_ctx *m = ctx;
    tr_run *c = m->c;
    unsigned char *state = NULL;
    size_t slen = 0;
    gdt_status st = mr_raw_prefix(m, c->tiler, err);
    if (st == GDT_OK)
        st = gdt_tiler_export(c->tiler, &state, &slen, err);
    for (int r = 1; st == GDT_OK && r < m->size; r++) {
        gdt_pack p;
        uint64_t n = 0;
        for (uint64_t k = 0; k < m->raw_n; k++)
            n += p2_owner(m, k) == r;
        memset(&p, 0, sizeof p);
        gdt_pack_u64(&p, c->job_id[0]);
        gdt_pack_u64(&p, c->job_id[1]);
        gdt_pack_bytes(&p, state, slen);
        /* the tiles it will be shipped: it takes them (and answers for
         * each) even when it cannot take the state */
        gdt_pack_u64(&p, n);
        gdt_pack_u64(&p, 0); /* mode 0: rank 0 spills */
        gdt_pack_u64(&p, 0);
        gdt_pack_u64(&p, 0);
        gdt_pack_u64(&p, 0);
        st = mr_send_pack(m, r, TAG_PLAN, &p, err);
    }
    free(state);
    return st;
}

/* Rank 0: tile k's records (or where they are) to its owner. */
static gdt_status p2_ship(void *ctx, uint64_t k, const gdt_point *recs, uint64_t n,
                          gdt_error *err)
{
    mr_ctx *m = ctx;
    int to = p2_owner(m, k);
    gdt_pack p;
    gdt_status st;
    memset(&p, 0, sizeof p);
    gdt_pack_u64(&p, k);
    gdt_pack_u64(&p, n);
    gdt_pack_u64(&p, recs != NULL);
    st = mr_send_pack(m, to, TAG_RECS, &p, err);
    for (uint64_t at = 0; st == GDT_OK && recs != NULL && at < n; at += RECS_PER_MSG) {
        uint64_t q = n - at < RECS_PER_MSG ? n - at : RECS_PER_MSG;
        st = gdt_comm_send(m->comm, to, TAG_RECDATA, recs + at, (size_t)q * sizeof *recs, err);
    }
    if (st == GDT_OK)
        m->shipped++;
    return st;
}

/* Rank 0: the files of every shipped tile into the tiler. */
static gdt_status p2_collect(void *ctx, gdt_error *err)
{
    return mr_collect_files(ctx, err);
}

gdt_status mr_collect_files(mr_ctx *m, gdt_error *err)
{
    gdt_status st = GDT_OK;
    while (st == GDT_OK && m->files_got < m->shipped) {
        int ready = 0, from = 0, tag = 0;
        size_t len = 0;
        unsigned char *buf = NULL;
        gdt_unpack u;
        st = gdt_comm_wait(m->comm, -1, TAG_FILES, m->c->opts->stop, &ready, &from, &tag, &len,
                           err);
        if (st == GDT_OK && !ready)
            st = tr_interrupted(m->c->job, "pass 2", err);
        if (st == GDT_OK)
            st = mr_recv(m, from, tag, len, &buf, err);
        if (st == GDT_OK) {
            gdt_tiler_tile_files f;
            uint64_t k;
            gdt_status rst;
            int code;
            size_t ml = 0;
            const unsigned char *msg;
            memset(&u, 0, sizeof u);
            u.p = buf;
            u.n = len;
            k = gdt_unpack_u64(&u);
            rst = (gdt_status)gdt_unpack_u64(&u);
            code = (int)gdt_unpack_u64(&u);
            msg = gdt_unpack_bytes(&u, &ml);
            f.points = gdt_unpack_u64(&u);
            f.edge = gdt_unpack_u64(&u);
            f.sum[0] = gdt_unpack_u64(&u);
            f.sum[1] = gdt_unpack_u64(&u);
            f.deepest = gdt_unpack_u64(&u);
            if (u.bad) {
                st = mr_bad_message(from, tag, err);
            } else if (rst != GDT_OK) {
                char text[GDT_ERROR_MSG_MAX];
                snprintf(text, sizeof text, "%.*s",
                         (int)(ml < sizeof text ? ml : sizeof text - 1), (const char *)msg);
                mr_fail(m, from, rst, code, text);
                *err = m->job_err;
                st = rst;
            } else {
                st = gdt_tiler_set_tile_files(m->c->tiler, k, &f, err);
                m->files_got++;
            }
        }
        free(buf);
    }
    return st;
}

/* Another rank: one shipped tile, held until the rank has all of its own. */
typedef struct rn_tile {
    uint64_t k, n;
    gdt_point *recs; /* NULL: the tile's .raw file */
} rn_tile;

/* One tile's FILES report: its files (st GDT_OK) or why there are none. */
struct mr_report {
    uint64_t k;
    gdt_status st;
    int code;
    char *msg; /* st != GDT_OK: the message (NULL: out of memory for it) */
    gdt_tiler_tile_files f;
};

static void send_report(mr_ctx *m, uint64_t k, gdt_status st, int code, const char *msg,
                        const gdt_tiler_tile_files *f)
{
    gdt_pack p;
    gdt_error e;
    if (msg == NULL)
        msg = "";
    memset(&p, 0, sizeof p);
    gdt_pack_u64(&p, k);
    gdt_pack_u64(&p, (uint64_t)st);
    gdt_pack_u64(&p, st != GDT_OK ? (uint64_t)code : 0);
    gdt_pack_bytes(&p, st != GDT_OK ? msg : "", st != GDT_OK ? strlen(msg) : 0);
    gdt_pack_u64(&p, f->points);
    gdt_pack_u64(&p, f->edge);
    gdt_pack_u64(&p, f->sum[0]);
    gdt_pack_u64(&p, f->sum[1]);
    gdt_pack_u64(&p, f->deepest);
    gdt_error_clear(&e);
    if (mr_send_pack(m, 0, TAG_FILES, &p, &e) != GDT_OK) {
        gdt_error_print(&e, stderr);
        gdt_comm_abort(m->comm, (int)e.status);
    }
}

void mr_merge_report(mr_ctx *m, mr_reports *b, uint64_t k, gdt_point *recs, uint64_t n,
                     gdt_status st, const gdt_error *err)
{
    gdt_tiler_tile_files f;
    gdt_error e;
    struct mr_report *r;
    memset(&f, 0, sizeof f);
    gdt_error_clear(&e);
    if (st == GDT_OK)
        st = gdt_tiler_merge_shipped(m->c->tiler, k, recs, n, &f, &e);
    else
        e = *err;
    if (b->n == b->cap) {
        size_t cap = b->cap > 0 ? 2 * b->cap : 64;
        struct mr_report *g = realloc(b->r, cap * sizeof *g);
        if (g == NULL) {
            /* no room to hold it: the reports so far, and this one, now */
            mr_send_reports(m, b);
            if (st == GDT_OK) {
                gdt_error_clear(&e);
                st = gdt_tiler_sync_files(m->c->tiler, &e);
            }
            send_report(m, k, st, e.code, e.msg, &f);
            return;
        }
        b->r = g;
        b->cap = cap;
    }
    r = &b->r[b->n++];
    r->k = k;
    r->st = st;
    r->code = st != GDT_OK ? e.code : 0;
    r->msg = st != GDT_OK ? strdup(e.msg) : NULL;
    r->f = f;
}

void mr_send_reports(mr_ctx *m, mr_reports *b)
{
    gdt_error e;
    gdt_status sync = GDT_OK;
    int any = 0;
    for (size_t i = 0; i < b->n; i++)
        any |= b->r[i].st == GDT_OK;
    gdt_error_clear(&e);
    /* the files are durable before rank 0 can record pass 2 with them */
    if (any)
        sync = gdt_tiler_sync_files(m->c->tiler, &e);
    for (size_t i = 0; i < b->n; i++) {
        struct mr_report *r = &b->r[i];
        if (r->st == GDT_OK && sync != GDT_OK)
            send_report(m, r->k, sync, e.code, e.msg, &r->f);
        else
            send_report(m, r->k, r->st, r->code, r->msg, &r->f);
        free(r->msg);
    }
    free(b->r);
    memset(b, 0, sizeof *b);
}

/* Another rank: merges its shipped tiles and reports each one's files;
 * a failure (st, err: the rank could not take the state) is reported for
 * every tile instead. */
static void rn_merge_all(mr_ctx *m, rn_tile *tiles, size_t n, gdt_status st0,
                         const gdt_error *err0)
{
    mr_reports b;
    double t0 = gdt_now();
    memset(&b, 0, sizeof b);
    for (size_t i = 0; i < n; i++) {
        mr_merge_report(m, &b, tiles[i].k, tiles[i].recs, tiles[i].n, st0, err0);
        free(tiles[i].recs);
        tiles[i].recs = NULL;
    }
    mr_send_reports(m, &b);
    m->c->s.t_pass2_own = gdt_now() - t0;
}

void mr_pass2_hooks(mr_ctx *m)
{
    m->p2.sh.mine = p2_mine;
    m->p2.sh.ship = p2_ship;
    m->p2.sh.ctx = m;
    m->p2.begin = p2_begin;
    m->p2.collect = p2_collect;
    m->p2.ctx = m;
    mr_spill_hooks(m);
}

/* See private/mpi_sched.h. */
void mr_wait_go(mr_ctx *m, gdt_status *st, gdt_error *err, unsigned char **go, size_t *len)
{
    tr_run *c = m->c;
    gdt_unpack u;
    {
        gdt_error e2, pe;
        gdt_status s2 = GDT_OK, pst = *st;
        rn_tile *tl = NULL;
        size_t ntl = 0, want = 0;
        uint64_t mode = 0, sfirst = 0, send_ = 0, sbase = 0;
        int core_started = 0;
        gdt_error_clear(&e2);
        pe = *err;
        for (;;) {
            int ready = 0, from = 0, tag = 0;
            unsigned char *msg = NULL;
            s2 = gdt_comm_wait(m->comm, 0, -1, NULL, &ready, &from, &tag, len, &e2);
            /* the OpenCL core is built once this rank's share of pass 1
             * is read, while rank 0 takes the answers and plans (this rank
             * would only wait; rank 0 builds its own beside its share),
             * else after PLAN or at GO: the build would take the core a
             * share is read on */
            if (s2 == GDT_OK && tag == TAG_GO && !core_started) {
                core_started = 1;
                if (pst == GDT_OK)
                    pst = tr_run_start_core(c, &pe);
            }
            if (s2 == GDT_OK && tag == TAG_GO) {
                s2 = mr_recv(m, 0, TAG_GO, *len, go, &e2);
                break;
            }
            if (s2 == GDT_OK)
                s2 = mr_recv(m, 0, tag, *len, &msg, &e2);
            if (s2 == GDT_OK && tag == TAG_P1) {
                mr_pass1_answer(m, msg, *len, &pst, &pe, &core_started);
            } else if (s2 == GDT_OK && tag == TAG_GROUND) {
                mr_ground_answer(m, msg, *len, &pst, &pe);
            } else if (s2 == GDT_OK && tag == TAG_PLAN) {
                uint64_t id[2];
                size_t slen = 0;
                const unsigned char *state;
                memset(&u, 0, sizeof u);
                u.p = msg;
                u.n = *len;
                id[0] = gdt_unpack_u64(&u);
                id[1] = gdt_unpack_u64(&u);
                state = gdt_unpack_bytes(&u, &slen);
                want = (size_t)gdt_unpack_u64(&u);
                mode = gdt_unpack_u64(&u);
                sfirst = gdt_unpack_u64(&u);
                send_ = gdt_unpack_u64(&u);
                sbase = gdt_unpack_u64(&u);
                if (u.bad || want > (1u << 30) || mode > 2) {
                    s2 = mr_bad_message(0, tag, &e2);
                    free(msg);
                    break;
                }
                if (pst == GDT_OK)
                    pst = tr_run_attach(c, id, state, slen, &pe);
                if (mode >= 1)
                    mr_spill_answer(m, sfirst, send_, sbase, mode == 2, &pst, &pe);
                tl = calloc(want + 1, sizeof *tl);
                if (tl == NULL)
                    s2 = gdt_error_set(&e2, GDT_EINTERNAL, 7001, "out of memory");
                /* the core is built now, while rank 0 spills or merges */
                if (!core_started) {
                    core_started = 1;
                    if (pst == GDT_OK)
                        pst = tr_run_start_core(c, &pe);
                }
            } else if (s2 == GDT_OK && tag == TAG_RECS) {
                uint64_t rk, rn, inl;
                memset(&u, 0, sizeof u);
                u.p = msg;
                u.n = *len;
                rk = gdt_unpack_u64(&u);
                rn = gdt_unpack_u64(&u);
                inl = gdt_unpack_u64(&u);
                if (u.bad || tl == NULL || ntl >= want) {
                    s2 = mr_bad_message(0, tag, &e2);
                } else {
                    gdt_point *recs = NULL;
                    if (inl && (recs = malloc((size_t)(rn > 0 ? rn : 1) * sizeof *recs)) == NULL)
                        s2 = gdt_error_set(&e2, GDT_EINTERNAL, 7001,
                                           "out of memory (a shipped tile of %" PRIu64
                                           " points)",
                                           rn);
                    for (uint64_t at = 0; s2 == GDT_OK && inl && at < rn; at += RECS_PER_MSG) {
                        uint64_t q = rn - at < RECS_PER_MSG ? rn - at : RECS_PER_MSG;
                        int rd = 0, fr = 0, tg = 0;
                        size_t l2 = 0;
                        s2 = gdt_comm_wait(m->comm, 0, TAG_RECDATA, NULL, &rd, &fr, &tg, &l2,
                                           &e2);
                        if (s2 == GDT_OK && l2 != q * sizeof *recs)
                            s2 = mr_bad_message(0, TAG_RECDATA, &e2);
                        if (s2 == GDT_OK)
                            s2 = gdt_comm_recv(m->comm, 0, TAG_RECDATA, recs + at, l2, &e2);
                    }
                    tl[ntl].k = rk;
                    tl[ntl].n = rn;
                    tl[ntl].recs = recs;
                    ntl++;
                    /* all of this rank's tiles are here: merge them now,
                     * beside rank 0's own */
                    if (s2 == GDT_OK && ntl == want)
                        rn_merge_all(m, tl, ntl, pst, &pe);
                }
            } else if (s2 == GDT_OK) {
                s2 = mr_bad_message(0, tag, &e2);
            }
            free(msg);
            if (s2 != GDT_OK)
                break;
        }
        for (size_t i = 0; i < ntl; i++)
            free(tl[i].recs);
        free(tl);
        if (s2 != GDT_OK) {
            gdt_error_print(&e2, stderr);
            gdt_comm_abort(m->comm, (int)s2);
        }
        *st = pst;
        *err = pe;
    }
}
