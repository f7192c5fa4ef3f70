/* mpi_spill.c — pass 2 in shares: every rank reads the share of the records
 * it read in pass 1 and sends each point to the owner of its tile; each
 * owner runs the --dup merge of its tiles.
 *
 * Used when pass 1 was shared (its shares' kept counts give each share's
 * first ordinal, so every point has the ordinal a single process gives it);
 * otherwise rank 0 spills alone (mpi_pass2.c).  When the records do not fit
 * in memory (gdt_tiler_pass2_in_memory), each rank spills its share into
 * .raw files of its own in the shared job directory and each owner joins
 * its tiles' files in rank order (pass2_part.c) before the merge; the
 * exchange below then carries the statuses only.
 *
 * Protocol, after PLAN (mode 1 in memory, 2 in files: the share and its
 * first ordinal):
 *   every rank reads its share, keeping for each other rank the points of
 *   that rank's tiles (in input order);
 *   header exchange: each pair of ranks swaps (status, code, points for the
 *   other), so every rank knows every rank's status; the pairs meet in the
 *   rounds of a round-robin tournament, the lower rank sending first, so
 *   blocking sends cannot deadlock;
 *   when every rank read its share: data exchange in the same rounds; each
 *   owner holds its tiles' records from rank 0, 1, ... in that order, which
 *   is input order (shares are consecutive), groups them by tile (a stable
 *   counting sort), checks each tile's count against pass 1 and merges; the
 *   others report FILES as in mpi_pass2.c, rank 0 sets its own;
 *   when a rank failed: nobody merges; the first failing rank other than 0
 *   (if rank 0 read its share) sends P2FAIL with its error, which becomes
 *   the job's.
 * The files are those of a single process: each tile's records reach the
 * merge in input order with the same ordinals. */
#include "private/mpi_sched.h"

#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "private/tiled_files.h"

/* Points read per call. */
#define SP_READ 65536

typedef struct sp_bin {
    gdt_point *p;
    size_t n, cap;
} sp_bin;

/* The last tile found: points come in runs from one tile. */
typedef struct sp_cache {
    uint64_t k;
    int64_t x0, y0;
    int owner;
} sp_cache;

/* What this rank's share of pass 2 gave: its own tiles [ka, kb), their
 * records recs[off[k - ka], off[k - ka + 1]) in input order. */
typedef struct sp_own {
    uint64_t ka, kb;
    gdt_point *recs;
    uint64_t *off;
} sp_own;

static int sp_owner(const mr_ctx *m, uint64_t k)
{
    return mr_owner_of(m->raw_pre, m->raw_n, k, m->size);
}

/* The partner of rank r in round q of the tournament over size ranks, or
 * -1 when r sits the round out (an odd count). */
static int sp_partner(int r, int q, int size)
{
    int n = size + (size & 1), rounds = n - 1, p;
    if (r == n - 1)
        p = q;
    else if (r == q)
        p = n - 1;
    else
        p = ((2 * q - r) % rounds + rounds) % rounds;
    return p < size ? p : -1;
}

static uint64_t sp_tile(const mr_ctx *m, const gdt_tiler *t, int64_t span, sp_cache *c,
                        const gdt_point *p)
{
    gdt_tile_desc d;
    uint64_t k;
    if (c->k != UINT64_MAX && (uint64_t)(p->x - c->x0) < (uint64_t)span &&
        (uint64_t)(p->y - c->y0) < (uint64_t)span)
        return c->k;
    k = gdt_tiler_tile_of(t, p->x, p->y);
    if (k == UINT64_MAX || gdt_tiler_tile_info(t, k, &d, NULL) != GDT_OK)
        return UINT64_MAX;
    c->k = k;
    c->x0 = d.x0;
    c->y0 = d.y0;
    c->owner = sp_owner(m, k);
    return k;
}

/* Reads the share into one bin per owner.  returns: the cloud's errors;
 * GDT_EINPUT 3501 (a point in no tile); 7001; GDT_EINTERRUPTED (rank 0). */
static gdt_status sp_read(mr_ctx *m, uint64_t first, uint64_t end, uint64_t base, sp_bin *bins,
                          gdt_error *err)
{
    tr_run *c = m->c;
    const gdt_tiler *t = c->tiler;
    const int64_t span = gdt_tiler_get_plan(t)->span;
    sp_cache cache = {UINT64_MAX, 0, 0, 0};
    gdt_point *buf = malloc(SP_READ * sizeof *buf);
    gdt_status st;

    if (buf == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    st = gdt_cloud_set_range(c->cloud, first, end, base, err);
    while (st == GDT_OK) {
        size_t n = 0;
        st = gdt_cloud_read(c->cloud, buf, SP_READ, &n, err);
        if (st != GDT_OK || n == 0)
            break;
        for (size_t i = 0; i < n && st == GDT_OK; i++) {
            uint64_t k = sp_tile(m, t, span, &cache, &buf[i]);
            sp_bin *b;
            if (k == UINT64_MAX) {
                st = gdt_error_set(err, GDT_EINPUT, 3501,
                                   "the input changed between the two passes: point %" PRIu64
                                   " at lattice (%" PRId64 ", %" PRId64
                                   ") is in no tile counted by pass 1",
                                   buf[i].ord, buf[i].x, buf[i].y);
                break;
            }
            b = &bins[cache.owner];
            if (b->n == b->cap && tr_reserve(&b->p, &b->cap, b->n + 1, sizeof *b->p) != 0) {
                st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory (pass 2)");
                break;
            }
            b->p[b->n++] = buf[i];
        }
        if (st == GDT_OK && m->rank == 0 && tr_stopped(c))
            st = tr_interrupted(c->job, "pass 2", err);
    }
    free(buf);
    return st;
}

/* Sends or receives n records in RECS_PER_MSG pieces. */
static gdt_status sp_move(mr_ctx *m, int peer, int send, gdt_point *p, uint64_t n,
                          gdt_error *err)
{
    gdt_status st = GDT_OK;
    for (uint64_t at = 0; st == GDT_OK && at < n; at += RECS_PER_MSG) {
        uint64_t q = n - at < RECS_PER_MSG ? n - at : RECS_PER_MSG;
        st = send ? gdt_comm_send(m->comm, peer, TAG_SPILL, p + at, (size_t)q * sizeof *p, err)
                  : gdt_comm_recv(m->comm, peer, TAG_SPILL, p + at, (size_t)q * sizeof *p, err);
    }
    return st;
}

/* The records of own tiles [o->ka, o->kb) from all (input order), grouped
 * by tile into o->recs / o->off.  returns: 3501 (a tile's count is not
 * pass 1's); 7001. */
static gdt_status sp_group(mr_ctx *m, gdt_point *all, uint64_t n, sp_own *o, gdt_error *err)
{
    const gdt_tiler *t = m->c->tiler;
    const int64_t span = gdt_tiler_get_plan(t)->span;
    const uint64_t nt = o->kb - o->ka;
    sp_cache cache = {UINT64_MAX, 0, 0, 0};
    uint32_t *idx = malloc((n > 0 ? n : 1) * sizeof *idx);
    uint64_t *fill = calloc(nt + 1, sizeof *fill);
    gdt_status st = GDT_OK;

    o->off = calloc(nt + 1, sizeof *o->off);
    o->recs = malloc((n > 0 ? n : 1) * sizeof *o->recs);
    if (idx == NULL || fill == NULL || o->off == NULL || o->recs == NULL) {
        st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory (pass 2, %" PRIu64
                           " points)", n);
        goto done;
    }
    for (uint64_t i = 0; i < n; i++) {
        uint64_t k = sp_tile(m, t, span, &cache, &all[i]);
        if (k < o->ka || k >= o->kb) {
            st = gdt_error_set(err, GDT_EINTERNAL, 7955,
                               "MPI: a point of tile %" PRIu64 " reached the owner of [%" PRIu64
                               ", %" PRIu64 ")", k, o->ka, o->kb);
            goto done;
        }
        idx[i] = (uint32_t)(k - o->ka);
        o->off[idx[i] + 1]++;
    }
    for (uint64_t j = 0; j < nt; j++) {
        gdt_tile_desc d;
        uint64_t k = o->ka + j;
        st = gdt_tiler_tile_info(t, k, &d, err);
        if (st != GDT_OK)
            goto done;
        if (o->off[j + 1] != d.raw_points) {
            st = gdt_error_set(err, GDT_EINPUT, 3501,
                               "the input changed between the two passes: tile (%" PRId64
                               ", %" PRId64 ") received %" PRIu64 " points, pass 1 counted %"
                               PRIu64, d.i, d.j, o->off[j + 1], d.raw_points);
            goto done;
        }
        o->off[j + 1] += o->off[j];
        fill[j] = o->off[j];
    }
    for (uint64_t i = 0; i < n; i++)
        o->recs[fill[idx[i]]++] = all[i];
done:
    free(idx);
    free(fill);
    return st;
}

/* This rank's part of pass 2 in shares (see the top of the file): *st and
 * *err, this rank's status, become the job's (*st GDT_OK: o holds the own
 * tiles' records); *failed is the first failing rank, -1 when none.  Ends
 * the job when the messages fail. */
static void sp_run(mr_ctx *m, uint64_t first, uint64_t end, uint64_t base, int files,
                   gdt_status *st, gdt_error *err, sp_own *o, int *failed)
{
    const int size = m->size, rank = m->rank;
    const int rounds = size + (size & 1) - 1;
    sp_bin *bins = calloc((size_t)size, sizeof *bins);
    uint64_t *cnt = calloc((size_t)size, sizeof *cnt), *hdr = calloc(3 * (size_t)size,
                                                                      sizeof *hdr);
    gdt_point *all = NULL;
    uint64_t total = 0, *pos = NULL;
    gdt_error e2;
    gdt_status s2 = GDT_OK;

    memset(o, 0, sizeof *o);
    *failed = -1;
    gdt_error_clear(&e2);
    if (bins == NULL || cnt == NULL || hdr == NULL) {
        gdt_error_set(&e2, GDT_EINTERNAL, 7001, "out of memory");
        goto abort;
    }
    if (*st == GDT_OK && files) {
        /* out of core: into this rank's own .raw files */
        *st = gdt_cloud_set_range(m->c->cloud, first, end, base, err);
        if (*st == GDT_OK)
            *st = gdt_tiler_spill_part(m->c->tiler, rank, err);
    } else if (*st == GDT_OK) {
        *st = sp_read(m, first, end, base, bins, err);
    }
    /* the share's decoded records, read for the last time, are freed
     * before the pass-2 sync would write them out */
    if (*st == GDT_OK && tr_pass2_last_read(m->c->opts))
        gdt_cloud_release_replay(m->c->cloud);
    /* headers: every rank's status, and the points each sends this one */
    hdr[3 * rank] = (uint64_t)*st;
    hdr[3 * rank + 1] = *st != GDT_OK ? (uint64_t)err->code : 0;
    cnt[rank] = bins[rank].n;
    for (int q = 0; q < rounds && s2 == GDT_OK; q++) {
        int p = sp_partner(rank, q, size);
        uint64_t mine[3], theirs[3];
        if (p < 0)
            continue;
        mine[0] = hdr[3 * rank];
        mine[1] = hdr[3 * rank + 1];
        mine[2] = bins[p].n;
        if (rank < p) {
            s2 = gdt_comm_send(m->comm, p, TAG_SPILL, mine, sizeof mine, &e2);
            if (s2 == GDT_OK)
                s2 = gdt_comm_recv(m->comm, p, TAG_SPILL, theirs, sizeof theirs, &e2);
        } else {
            s2 = gdt_comm_recv(m->comm, p, TAG_SPILL, theirs, sizeof theirs, &e2);
            if (s2 == GDT_OK)
                s2 = gdt_comm_send(m->comm, p, TAG_SPILL, mine, sizeof mine, &e2);
        }
        hdr[3 * p] = theirs[0];
        hdr[3 * p + 1] = theirs[1];
        cnt[p] = theirs[2];
    }
    if (s2 != GDT_OK)
        goto abort;
    for (int r = 0; r < size && *failed < 0; r++)
        if ((gdt_status)hdr[3 * r] != GDT_OK)
            *failed = r;
    if (*failed >= 0) {
        if (*st == GDT_OK) {
            /* another rank's failure: the job's, said by that rank */
            *st = (gdt_status)hdr[3 * *failed];
            gdt_error_set(err, *st, (int)hdr[3 * *failed + 1], "rank %d failed in pass 2",
                          *failed);
        }
        goto out;
    }
    /* own tiles: a contiguous run of tile order */
    o->ka = o->kb = 0;
    for (uint64_t k = 0; k < m->raw_n; k++)
        if (sp_owner(m, k) == rank) {
            if (o->kb == o->ka)
                o->ka = k;
            o->kb = k + 1;
        }
    if (files)
        goto out; /* the owners join the files */
    /* data: the owner lays each rank's points out in rank order */
    pos = calloc((size_t)size + 1, sizeof *pos);
    if (pos == NULL) {
        gdt_error_set(&e2, GDT_EINTERNAL, 7001, "out of memory");
        goto abort;
    }
    for (int r = 0; r < size; r++)
        pos[r + 1] = pos[r] + cnt[r];
    total = pos[size];
    all = malloc((total > 0 ? total : 1) * sizeof *all);
    if (all == NULL) {
        gdt_error_set(&e2, GDT_EINTERNAL, 7001,
                      "out of memory (pass 2: %" PRIu64 " points of this rank's tiles)", total);
        goto abort;
    }
    if (bins[rank].n > 0)
        memcpy(all + pos[rank], bins[rank].p, bins[rank].n * sizeof *all);
    free(bins[rank].p);
    bins[rank].p = NULL;
    for (int q = 0; q < rounds && s2 == GDT_OK; q++) {
        int p = sp_partner(rank, q, size);
        if (p < 0)
            continue;
        if (rank < p) {
            s2 = sp_move(m, p, 1, bins[p].p, bins[p].n, &e2);
            if (s2 == GDT_OK)
                s2 = sp_move(m, p, 0, all + pos[p], cnt[p], &e2);
        } else {
            s2 = sp_move(m, p, 0, all + pos[p], cnt[p], &e2);
            if (s2 == GDT_OK)
                s2 = sp_move(m, p, 1, bins[p].p, bins[p].n, &e2);
        }
        free(bins[p].p);
        bins[p].p = NULL;
    }
    if (s2 != GDT_OK)
        goto abort;
    *st = sp_group(m, all, total, o, err);
    goto out;
abort:
    gdt_error_print(&e2, stderr);
    gdt_comm_abort(m->comm, (int)e2.status);
out:
    for (int r = 0; bins != NULL && r < size; r++)
        free(bins[r].p);
    free(bins);
    free(cnt);
    free(hdr);
    free(pos);
    free(all);
}

static void sp_own_free(sp_own *o)
{
    free(o->recs);
    free(o->off);
    memset(o, 0, sizeof *o);
}

/* The first ordinal of each share: the kept points of the shares before. */
static uint64_t sp_base(const mr_ctx *m, int r)
{
    uint64_t b = 0;
    for (int q = 0; q < r; q++)
        b += m->p1_kept[q];
    return b;
}

/* Rank 0: pass 2 in shares when it can be (see the top of the file). */
static gdt_status p2_spill(void *ctx, int *whole, gdt_error *err)
{
    mr_ctx *m = ctx;
    tr_run *c = m->c;
    unsigned char *state = NULL;
    size_t slen = 0;
    sp_own own;
    int failed = -1;
    size_t nin;
    int files;
    gdt_status st;
    double t_own;

    *whole = 0;
    if (!m->p1_shared || m->p1_bounds == NULL || m->p1_kept == NULL || m->p1_counts == NULL ||
        m->size < 2)
        return GDT_OK;
    *whole = 1;
    files = !gdt_tiler_pass2_in_memory(c->tiler);
    st = mr_raw_prefix(m, c->tiler, err);
    if (st == GDT_OK)
        st = gdt_tiler_export(c->tiler, &state, &slen, err);
    /* the tile directory is ready before any rank writes to it */
    if (st == GDT_OK)
        st = gdt_tiler_pass2_open(c->tiler, err);
    if (st != GDT_OK) {
        free(state);
        return st; /* no PLAN went out: GO tells the others */
    }
    for (int r = 1; r < m->size; r++) {
        gdt_pack p;
        memset(&p, 0, sizeof p);
        gdt_pack_u64(&p, c->job_id[0]);
        gdt_pack_u64(&p, c->job_id[1]);
        gdt_pack_bytes(&p, state, slen);
        gdt_pack_u64(&p, 0); /* no tiles shipped */
        gdt_pack_u64(&p, files ? 2 : 1); /* the rank reads its share: 1 in memory, 2 files */
        gdt_pack_u64(&p, m->p1_bounds[r]);
        gdt_pack_u64(&p, m->p1_bounds[r + 1]);
        gdt_pack_u64(&p, sp_base(m, r));
        st = mr_send_pack(m, r, TAG_PLAN, &p, err);
        if (st != GDT_OK) {
            gdt_error_print(err, stderr);
            gdt_comm_abort(m->comm, (int)st);
        }
    }
    free(state);
    t_own = gdt_now();
    sp_run(m, m->p1_bounds[0], m->p1_bounds[1], 0, files, &st, err, &own, &failed);
    /* the cloud counted this share: the whole pass's counts are pass 1's */
    nin = gdt_cloud_get_info(c->cloud)->ninputs;
    if (gdt_cloud_set_range(c->cloud, 0, UINT64_MAX, 0, NULL) == GDT_OK && m->p1_counts != NULL)
        for (size_t i = 0; i < nin; i++)
            gdt_cloud_add_counts(c->cloud, i, &m->p1_counts[i]);
    if (failed > 0) {
        /* another rank failed (st says so): it says why */
        size_t len = 0;
        unsigned char *buf = NULL;
        char text[GDT_ERROR_MSG_MAX];
        gdt_unpack u;
        const unsigned char *msg;
        size_t ml = 0;
        mr_wait_recv(m, failed, TAG_P2FAIL, &buf, &len);
        memset(&u, 0, sizeof u);
        u.p = buf;
        u.n = len;
        msg = gdt_unpack_bytes(&u, &ml); /* as gdt_pack_bytes wrote it */
        if (u.bad)
            snprintf(text, sizeof text, "failed in pass 2 (its message did not parse)");
        else
            snprintf(text, sizeof text, "%.*s",
                     (int)(ml < sizeof text ? ml : sizeof text - 1), (const char *)msg);
        free(buf);
        mr_fail(m, failed, st, err->code, text);
        *err = m->job_err;
    }
    if (st != GDT_OK) {
        sp_own_free(&own);
        return st;
    }
    /* rank 0's own tiles, while the others merge theirs */
    for (uint64_t k = own.ka; st == GDT_OK && k < own.kb; k++) {
        gdt_tiler_tile_files f;
        uint64_t j = k - own.ka;
        /* the merge itself marks the tile's files in this tiler */
        gdt_point *pr = NULL;
        uint64_t npr = 0;
        if (files)
            st = gdt_tiler_take_parts(c->tiler, k, m->size, &pr, &npr, err);
        if (st == GDT_OK && files)
            st = gdt_tiler_merge_shipped(c->tiler, k, pr, npr, &f, err);
        else if (st == GDT_OK)
            st = gdt_tiler_merge_shipped(c->tiler, k, own.recs + own.off[j],
                                         own.off[j + 1] - own.off[j], &f, err);
        free(pr);
    }
    sp_own_free(&own);
    /* rank 0's files are synced with the job's pass 2 (pass2_finish) */
    c->s.t_pass2_own = gdt_now() - t_own;
    m->shipped = 0;
    for (uint64_t k = 0; k < m->raw_n; k++)
        m->shipped += sp_owner(m, k) != 0;
    m->files_got = 0;
    /* every other rank reports its tiles, also when rank 0 failed here */
    {
        gdt_error e2;
        gdt_status s2;
        gdt_error_clear(&e2);
        s2 = mr_collect_files(m, &e2);
        if (st == GDT_OK && s2 != GDT_OK) {
            st = s2;
            *err = e2;
        }
    }
    if (st == GDT_OK)
        st = gdt_tiler_pass2_finish(c->tiler, err);
    if (st == GDT_OK)
        gdt_log_note(&c->log, "tiler pass 2: %" PRIu64 " points in shares of %d ranks (%s)",
                     gdt_tiler_get_plan(c->tiler)->points, m->size,
                     files ? "each rank's .raw files" : "in memory");
    return st;
}

void mr_spill_hooks(mr_ctx *m)
{
    m->p2.spill = p2_spill;
}

void mr_spill_answer(mr_ctx *m, uint64_t first, uint64_t end, uint64_t base, int files,
                     gdt_status *pst, gdt_error *pe)
{
    sp_own own;
    mr_reports reps;
    int failed = -1;
    gdt_status st = *pst;
    double t0 = gdt_now();

    if (st == GDT_OK)
        st = mr_raw_prefix(m, m->c->tiler, pe);
    sp_run(m, first, end, base, files, &st, pe, &own, &failed);
    if (failed >= 0) {
        if (failed == m->rank) {
            gdt_pack p;
            gdt_error e2;
            memset(&p, 0, sizeof p);
            gdt_pack_bytes(&p, pe->msg, strlen(pe->msg));
            gdt_error_clear(&e2);
            if (mr_send_pack(m, 0, TAG_P2FAIL, &p, &e2) != GDT_OK) {
                gdt_error_print(&e2, stderr);
                gdt_comm_abort(m->comm, (int)e2.status);
            }
        }
        *pst = st;
        sp_own_free(&own);
        return;
    }
    memset(&reps, 0, sizeof reps);
    for (uint64_t k = own.ka; k < own.kb; k++) {
        uint64_t j = k - own.ka;
        if (files) {
            gdt_error e;
            gdt_status js = st;
            gdt_error_clear(&e);
            gdt_point *pr = NULL;
            uint64_t npr = 0;
            if (js == GDT_OK)
                js = gdt_tiler_take_parts(m->c->tiler, k, m->size, &pr, &npr, &e);
            mr_merge_report(m, &reps, k, pr, npr, js, js != GDT_OK && st == GDT_OK ? &e : pe);
            free(pr);
        } else {
            mr_merge_report(m, &reps, k, own.recs + own.off[j], own.off[j + 1] - own.off[j],
                            st, pe);
        }
    }
    mr_send_reports(m, &reps);
    m->c->s.t_pass2_own = gdt_now() - t0;
    sp_own_free(&own);
    *pst = st;
}
