/* mpi_run.c — one tiled job over the ranks of an MPI launch (see
 * private/mpi_run.h): a scheduler over the stages of private/stages.h.
 *
 * Protocol (tags below; every message is a gdt_pack of u64 fields):
 *   rank 0: tr_run_init .. tr_run_output_start, as a single process
 *     (the job's lock, journal, pass 1, pass 2, mesh writer), the passes
 *     shared through the hooks of mpi_pass1.c, mpi_spill.c, mpi_pass2.c;
 *     then GO to every other rank: the run's status so far, and when it is
 *     GDT_OK the job's id, the tiler's state and the rank's tiles with
 *     their journal records (those before the last quarter of the
 *     vertices), and whether tiles are left to take on demand: a rank
 *     asks for them with MORE and GRANT answers with the next ones in tile
 *     order and their records, or none.
 *   every rank: its tiles (tr_run_tiles over a tr_tile_set).  Another rank
 *     sends RECORD (durable finished tiles: k, size, checksum) and DONE
 *     (tile k finished or reused) to rank 0, which records them in the
 *     journal (its one writer) and tells its mesh writer of the prefix of
 *     tiles that have their files.  Then FINISHED: the rank's status, its
 *     error, its counts and times.
 *   rank 0: waits for every FINISHED (a rank's failure becomes the job's,
 *     and STOP tells the others to stop at their next tile), then merges
 *     and writes as a single process does, and sends FINAL: the job's
 *     status, which every rank returns, so mpirun's exit code is the job's.
 *     A plain PLY output is written by the tiles' owners instead: PARTS
 *     and WROTE before the merge's faces (mpi_parts.c).
 * A rank that is killed ends the job (mpirun stops the others); what rank
 * 0 recorded stays in the journal, and a rerun with any number of ranks
 * resumes from it.  The output does not depend on the number of ranks:
 * every tile's file is the same whoever computes it, and the mesh's records
 * are the tiles' in tile order, whoever writes them.  The shared passes (P1, P1DONE;
 * PLAN, SPILL, P2FAIL, RECS, RECDATA, FILES) are in mpi_pass1.c,
 * mpi_spill.c and mpi_pass2.c; private/mpi_sched.h holds what the files
 * share. */
#include "private/mpi_run.h"

#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "private/mpi_sched.h"
#include "private/run_stats.h"
#include "private/tiled_files.h"

/* The counts of a rank's tile stage, in FINISHED: the fields of tr_summary
 * that the tile stage fills, and the rank's own share. */
static void pack_report(gdt_pack *p, const tr_run *c, uint64_t tiles, uint64_t vertices,
                        uint64_t taken)
{
    const tr_summary *s = &c->s;
    const gdt_cert_stats *q = &s->cert;
    const uint64_t v[] = {tiles, vertices, taken, s->certified, c->seam_total, s->tiles_reused,
                          s->tiles_redone, s->gcd_tiles, s->insert_tiles, s->max_tile_points,
                          s->max_halo_points, q->triangles, q->certified, q->inner,
                          q->outside_known, q->halo_hit, q->halo_tests, q->pred.orient_calls,
                          q->pred.incircle_calls, q->pred.incircle_exact,
                          q->pred.tiebreak_calls};
    const double t[] = {s->t_tiles, s->t_core,   s->t_certify,
                        s->t_post,  s->t_device, s->t_device_span};
    for (size_t i = 0; i < sizeof v / sizeof v[0]; i++)
        gdt_pack_u64(p, v[i]);
    for (size_t i = 0; i < sizeof t / sizeof t[0]; i++)
        gdt_pack_f64(p, t[i]);
    gdt_pack_bytes(p, s->device, strlen(s->device));
    gdt_pack_u64(p, gdt_cloud_replayed(c->cloud));
    gdt_pack_f64(p, s->t_pass1_own);
    gdt_pack_f64(p, s->t_pass2_own);
}

/* Adds a FINISHED report to sum (seam vertices into *seam) and describes the
 * rank in *r. */
static void unpack_report(gdt_unpack *u, tr_summary *sum, uint64_t *seam, tr_rank_stats *r)
{
    gdt_cert_stats *q = &sum->cert;
    uint64_t v, w;
    size_t dl = 0;
    const unsigned char *dev;
    memset(r, 0, sizeof *r);
    r->tiles = gdt_unpack_u64(u);
    r->vertices = gdt_unpack_u64(u);
    r->on_demand = gdt_unpack_u64(u);
    r->certified = gdt_unpack_u64(u);
    sum->certified += r->certified;
    *seam += gdt_unpack_u64(u);
    r->reused = gdt_unpack_u64(u);
    sum->tiles_reused += r->reused;
    sum->tiles_redone += gdt_unpack_u64(u);
    sum->gcd_tiles += gdt_unpack_u64(u);
    sum->insert_tiles += gdt_unpack_u64(u);
    v = gdt_unpack_u64(u);
    w = gdt_unpack_u64(u);
    if (v > sum->max_tile_points)
        sum->max_tile_points = v;
    if (w > sum->max_halo_points)
        sum->max_halo_points = w;
    q->triangles += gdt_unpack_u64(u);
    q->certified += gdt_unpack_u64(u);
    q->inner += gdt_unpack_u64(u);
    q->outside_known += gdt_unpack_u64(u);
    q->halo_hit += gdt_unpack_u64(u);
    q->halo_tests += gdt_unpack_u64(u);
    q->pred.orient_calls += gdt_unpack_u64(u);
    q->pred.incircle_calls += gdt_unpack_u64(u);
    q->pred.incircle_exact += gdt_unpack_u64(u);
    q->pred.tiebreak_calls += gdt_unpack_u64(u);
    r->t_tiles = gdt_unpack_f64(u);
    r->t_core = gdt_unpack_f64(u);
    r->t_certify = gdt_unpack_f64(u);
    r->t_post = gdt_unpack_f64(u);
    r->t_device = gdt_unpack_f64(u);
    r->t_device_span = gdt_unpack_f64(u);
    sum->t_device += r->t_device;
    sum->t_device_span += r->t_device_span;
    sum->t_core += r->t_core;
    sum->t_certify += r->t_certify;
    sum->t_post += r->t_post;
    dev = gdt_unpack_bytes(u, &dl);
    if (dev != NULL)
        snprintf(r->device, sizeof r->device, "%.*s",
                 (int)(dl < sizeof r->device ? dl : sizeof r->device - 1), (const char *)dev);
    r->replayed = gdt_unpack_u64(u);
    r->t_pass1 = gdt_unpack_f64(u);
    r->t_pass2 = gdt_unpack_f64(u);
}

/* ---- rank 0 ---- */

/* Tile k has its file: the writer hears of the grown prefix. */
static void r0_mark(mr_ctx *m, uint64_t k)
{
    if (k >= m->ntiles || m->done[k])
        return;
    m->done[k] = 1;
    m->done_points += m->c->base[k + 1] - m->c->base[k];
    gdt_progress_update(&m->c->prog, m->done_points);
    while (m->prefix < m->ntiles && m->done[m->prefix])
        m->prefix++;
    if (m->c->out != NULL)
        tr_out_ready(m->c->out, m->prefix);
    tr_merge_ready(m->c, m->prefix);
    mr_parts_advance(m);
}

static void r0_done(void *ctx, uint64_t k)
{
    r0_mark(ctx, k);
    mr_parts_tile_done(ctx, k); /* its vertices into the mesh, in parts */
}

/* A rank's failure is the job's (the first one stands). */
void mr_fail(mr_ctx *m, int from, gdt_status st, int code, const char *msg)
{
    if (m->job_st != GDT_OK)
        return;
    m->job_st = st;
    gdt_error_clear(&m->job_err);
    m->job_err.status = st;
    m->job_err.code = code;
    {
        /* "rank R: " then as much of the message as fits */
        int w = snprintf(m->job_err.msg, sizeof m->job_err.msg, "rank %d: ", from);
        size_t at = w > 0 && (size_t)w < sizeof m->job_err.msg ? (size_t)w : 0;
        size_t room = sizeof m->job_err.msg - at - 1, ml = strlen(msg);
        memcpy(m->job_err.msg + at, msg, ml < room ? ml : room);
        m->job_err.msg[at + (ml < room ? ml : room)] = '\0';
    }
}

/* Tells every rank still at its tiles to stop. */
static void r0_stop_all(mr_ctx *m)
{
    if (m->stop_sent)
        return;
    m->stop_sent = 1;
    for (int r = 1; r < m->size; r++) {
        gdt_error e;
        uint64_t z = 0;
        gdt_error_clear(&e);
        if (!m->finished[r])
            gdt_comm_send(m->comm, r, TAG_STOP, &z, sizeof z, &e);
    }
}

/* Records another rank's durable tiles in the journal (one transaction). */
static gdt_status r0_record(mr_ctx *m, gdt_unpack *u, int from, gdt_error *err)
{
    tr_run *c = m->c;
    uint64_t n = gdt_unpack_u64(u);
    gdt_status st;
    if (u->bad || n > (u->n - u->at) / 24)
        return mr_bad_message(from, TAG_RECORD, err);
    st = gdt_job_begin(c->jobdb, err);
    for (uint64_t i = 0; st == GDT_OK && i < n; i++) {
        uint64_t k = gdt_unpack_u64(u), size = gdt_unpack_u64(u), sum = gdt_unpack_u64(u);
        gdt_tile_desc d;
        char *path = NULL;
        if (k >= m->ntiles) {
            st = mr_bad_message(from, TAG_RECORD, err);
            break;
        }
        st = gdt_tiler_tile_info(c->tiler, k, &d, err);
        if (st == GDT_OK)
            st = tr_tile_path(c->tiles_dir, &d, "tri", &path, err);
        if (st == GDT_OK)
            st = gdt_job_put_tile(c->jobdb, k, path, size, sum, err);
        free(path);
    }
    if (st == GDT_OK)
        st = gdt_job_commit(c->jobdb, err);
    return st;
}

static gdt_status r0_finished(mr_ctx *m, gdt_unpack *u, int from, gdt_error *err)
{
    gdt_status st = (gdt_status)gdt_unpack_u64(u);
    int code = (int)gdt_unpack_u64(u);
    size_t ml = 0;
    const unsigned char *msg = gdt_unpack_bytes(u, &ml);
    tr_rank_stats r;
    unpack_report(u, &m->remote, &m->remote_seam, &r);
    if (u->bad)
        return mr_bad_message(from, TAG_FINISHED, err);
    m->finished[from] = 1;
    m->nfinished++;
    if (m->c->s.ranks != NULL) {
        /* what GDONE told of the rank's ground filter stays */
        r.ground_tiles = m->c->s.ranks[from].ground_tiles;
        r.t_ground = m->c->s.ranks[from].t_ground;
        m->c->s.ranks[from] = r;
    }
    if (st != GDT_OK) {
        char text[GDT_ERROR_MSG_MAX];
        snprintf(text, sizeof text, "%.*s", (int)(ml < sizeof text ? ml : sizeof text - 1),
                 (const char *)msg);
        mr_fail(m, from, st, code, text);
        r0_stop_all(m);
    }
    return GDT_OK;
}

/* GRANT to rank r, which asked for more tiles: the next ones in tile
 * order (mr_grant_size of them) with their journal records, or none when
 * every tile is dealt (also after a failure: the job stops). */
static gdt_status r0_grant(mr_ctx *m, int r, gdt_error *err)
{
    tr_run *c = m->c;
    uint64_t g = m->job_st == GDT_OK ? mr_grant_size(m->next_tile, m->ntiles, m->size) : 0;
    gdt_status st = GDT_OK;
    gdt_pack p;
    memset(&p, 0, sizeof p);
    gdt_pack_u64(&p, g);
    for (uint64_t i = 0; st == GDT_OK && i < g; i++) {
        uint64_t k = m->next_tile++, size = 0, sum = 0;
        int found = 0;
        m->towner[k] = r;
        st = gdt_job_get_tile(c->jobdb, k, &found, &size, &sum, err);
        gdt_pack_u64(&p, k);
        gdt_pack_u64(&p, (uint64_t)found);
        gdt_pack_u64(&p, size);
        gdt_pack_u64(&p, sum);
    }
    if (st != GDT_OK) {
        gdt_pack_free(&p);
        return st;
    }
    return mr_send_pack(m, r, TAG_GRANT, &p, err);
}

/* The growing set of rank 0's tiles: when its own run out, it takes the
 * next tile not dealt yet, if any. */
static gdt_status r0_more(void *ctx, uint64_t i, uint64_t *n, gdt_error *err)
{
    mr_ctx *m = ctx;
    (void)err;
    if (i == m->nmine && m->next_tile < m->ntiles && m->job_st == GDT_OK) {
        uint64_t k = m->next_tile++;
        m->towner[k] = 0;
        m->mine[m->nmine++] = k;
        m->taken++;
    }
    *n = m->nmine;
    return GDT_OK;
}

/* Handles one waiting message, if any (*got). */
static gdt_status r0_handle(mr_ctx *m, int wait, int *got, gdt_error *err)
{
    int ready = 0, from = 0, tag = 0;
    size_t len = 0;
    unsigned char *buf = NULL;
    gdt_unpack u;
    gdt_status st = wait ? gdt_comm_wait(m->comm, -1, -1, NULL, &ready, &from, &tag, &len, err)
                         : gdt_comm_probe(m->comm, -1, -1, &ready, &from, &tag, &len, err);
    *got = ready;
    if (st != GDT_OK || !ready)
        return st;
    st = mr_recv(m, from, tag, len, &buf, err);
    if (st != GDT_OK) {
        free(buf);
        return st;
    }
    memset(&u, 0, sizeof u);
    u.p = buf;
    u.n = len;
    switch (tag) {
    case TAG_RECORD:
        /* after a failure the journal takes nothing more: the job stops */
        st = m->job_st == GDT_OK ? r0_record(m, &u, from, err) : GDT_OK;
        break;
    case TAG_DONE: {
        uint64_t k = gdt_unpack_u64(&u);
        if (u.bad || k >= m->ntiles)
            st = mr_bad_message(from, tag, err);
        else
            r0_mark(m, k);
        break;
    }
    case TAG_FINISHED:
        st = r0_finished(m, &u, from, err);
        break;
    case TAG_MORE:
        st = r0_grant(m, from, err);
        break;
    default:
        st = mr_bad_message(from, tag, err);
        break;
    }
    free(buf);
    return st;
}

/* The tile stage's poll on rank 0: every waiting message; a rank's
 * failure ends rank 0's tiles too. */
static gdt_status r0_poll(void *ctx, gdt_error *err)
{
    mr_ctx *m = ctx;
    int got = 1;
    gdt_status st = GDT_OK;
    while (st == GDT_OK && got)
        st = r0_handle(m, 0, &got, err);
    if (st == GDT_OK && m->job_st != GDT_OK) {
        *err = m->job_err;
        st = m->job_st;
    }
    return st;
}

/* The rank of tile k in the tile stage (m->towner: mr_tile_owners over
 * the tiles' vertex counts); the same for every run of the same job and
 * rank count. */
static int owner(const mr_ctx *m, uint64_t k)
{
    return m->towner[k];
}

/* GO for rank r: the run's status, then (when it is GDT_OK) the job, the
 * tiler's state and the rank's tiles with their records. */
static gdt_status r0_go(mr_ctx *m, int r, gdt_status run_st, const unsigned char *state,
                        size_t slen, gdt_error *err)
{
    tr_run *c = m->c;
    gdt_pack p;
    gdt_status st = GDT_OK;
    uint64_t n = 0;
    memset(&p, 0, sizeof p);
    gdt_pack_u64(&p, (uint64_t)run_st);
    if (run_st == GDT_OK) {
        gdt_pack_u64(&p, c->job_id[0]);
        gdt_pack_u64(&p, c->job_id[1]);
        gdt_pack_bytes(&p, state, slen);
        for (uint64_t k = 0; k < m->ntiles; k++)
            n += owner(m, k) == r;
        gdt_pack_u64(&p, n);
        for (uint64_t k = 0; st == GDT_OK && k < m->ntiles; k++) {
            int found = 0;
            uint64_t size = 0, sum = 0;
            if (owner(m, k) != r)
                continue;
            st = gdt_job_get_tile(c->jobdb, k, &found, &size, &sum, err);
            gdt_pack_u64(&p, k);
            gdt_pack_u64(&p, (uint64_t)found);
            gdt_pack_u64(&p, size);
            gdt_pack_u64(&p, sum);
        }
        /* whether tiles are left to take on demand, and how many there are */
        gdt_pack_u64(&p, (uint64_t)(m->next_tile < m->ntiles));
        gdt_pack_u64(&p, m->ntiles);
        mr_parts_pack_layout(m, &p);
    }
    if (st != GDT_OK) {
        gdt_pack_free(&p);
        return st;
    }
    return mr_send_pack(m, r, TAG_GO, &p, err);
}

static gdt_status run_share(mr_ctx *m, const uint64_t *ks, uint64_t n, const tr_tile_rec *rec,
                            int grows, gdt_error *err);

static gdt_status run_rank0(mr_ctx *m, tr_run *c, gdt_error *err)
{
    gdt_status st = tr_run_init(c, c->opts, err);
    unsigned char *state = NULL;
    size_t slen = 0;
    uint64_t vmine = 0;
    double t_tiles0 = 0, t_own = 0;

    /* the ranks share the removal of the tile files at the end */
    c->removal_parts = m->size;
    mr_pass1_hooks(m);
    c->p1share = &m->p1;
    mr_pass2_hooks(m);
    c->p2share = &m->p2;
    mr_ground_hooks(m);
    if (c->opts->ground)
        c->gshare = &m->gs;
    if (c->opts->ground_out != NULL)
        c->goshare = &m->gos;
    if (st == GDT_OK) {
        c->s.ranks = calloc((size_t)m->size, sizeof *c->s.ranks);
        c->s.nranks = m->size;
        if (c->s.ranks == NULL)
            st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    }
    c->cstart.preload_dem = c->opts->dem != NULL; /* rank 0 writes the DEM */
    if (st == GDT_OK)
        st = tr_run_start_core(c, err);
    if (st == GDT_OK)
        st = tr_run_prepare_job(c, err);
    if (st == GDT_OK)
        st = tr_run_pass1(c, err);
    if (st == GDT_OK)
        st = tr_run_pass2(c, err);
    if (st == GDT_OK && c->s.t_ground > 0 && c->s.ranks != NULL && m->raw_pre != NULL) {
        /* rank 0's own share of the ground filter (the others' came in GDONE) */
        for (uint64_t k = 0; k < m->raw_n; k++)
            c->s.ranks[0].ground_tiles += mr_owner_of(m->raw_pre, m->raw_n, k, m->size) == 0;
        c->s.ranks[0].t_ground = c->s.t_ground_own;
    }
    /* a plain PLY is written by the tiles' owners (mpi_parts.c) */
    c->out_parts = m->size > 1;
    if (st == GDT_OK)
        st = tr_run_output_start(c, err);
    if (st == GDT_OK)
        st = tr_run_merge_start(c, err);
    if (st == GDT_OK)
        st = gdt_tiler_export(c->tiler, &state, &slen, err);
    if (st == GDT_OK) {
        m->ntiles = gdt_tiler_tile_count(c->tiler);
        m->done = calloc(m->ntiles + 1, 1);
        m->mine = malloc((m->ntiles + 1) * sizeof *m->mine);
        m->towner = malloc((m->ntiles + 1) * sizeof *m->towner);
        if (m->done == NULL || m->mine == NULL || m->towner == NULL)
            st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        /* GO deals out the tiles before the last quarter of the vertices;
         * the rest are taken on demand, in tile order, by the ranks that
         * run out first (rank 0 takes its own without a message).  With
         * lanes rank 0 could not take a tile past its first ones, so then
         * every tile is dealt out at once. */
        m->next_tile = m->size > 1 && c->cstart.nmore == 0 && m->ntiles > 0
                           ? mr_tile_dealt(c->base, m->ntiles)
                           : m->ntiles;
        for (uint64_t k = 0; m->towner != NULL && k <= m->ntiles; k++)
            m->towner[k] = -1;
        if (st == GDT_OK)
            st = mr_tile_owners(c->base, m->next_tile, m->size, m->towner, err);
    }
    /* every other rank waits for its GO, also when there is nothing to do */
    for (int r = 1; r < m->size; r++) {
        gdt_error e2;
        gdt_status s2;
        gdt_error_clear(&e2);
        s2 = r0_go(m, r, st, state, slen, &e2);
        if (s2 != GDT_OK && st == GDT_OK) {
            /* this rank would wait for ever: the job cannot go on */
            gdt_error_print(&e2, stderr);
            gdt_comm_abort(m->comm, (int)s2);
        }
    }
    free(state);
    if (st != GDT_OK)
        return st;
    for (uint64_t k = 0; k < m->ntiles; k++)
        if (owner(m, k) == 0)
            m->mine[m->nmine++] = k;
    t_tiles0 = gdt_now();
    st = run_share(m, m->mine, m->nmine, NULL, m->next_tile < m->ntiles, err);
    t_own = c->s.t_tiles;
    for (uint64_t i = 0; i < m->nmine; i++)
        vmine += c->base[m->mine[i] + 1] - c->base[m->mine[i]];
    if (st != GDT_OK) {
        /* the job's error, or rank 0's own first */
        if (m->job_st == GDT_OK)
            m->job_st = st, m->job_err = *err;
        r0_stop_all(m);
    }
    /* every rank reports, whatever happened */
    while (m->nfinished < m->size - 1) {
        int got = 0;
        gdt_error e2;
        gdt_error_clear(&e2);
        gdt_status s2 = r0_handle(m, 1, &got, &e2);
        if (s2 != GDT_OK) {
            gdt_error_print(&e2, stderr);
            gdt_comm_abort(m->comm, (int)s2);
        }
    }
    if (m->job_st != GDT_OK) {
        *err = m->job_err;
        return m->job_st;
    }
    if (m->prefix != m->ntiles)
        return gdt_error_set(err, GDT_EINTERNAL, 7953,
                             "MPI: %" PRIu64 " of %" PRIu64 " tiles were never reported done",
                             m->ntiles - m->prefix, m->ntiles);
    {
        /* rank 0's own share, then every rank's counts in the summary */
        tr_summary *s = &c->s, *o = &m->remote;
        tr_rank_stats *r0 = &s->ranks[0];
        r0->tiles = m->nmine;
        r0->on_demand = m->taken;
        r0->t_pass1 = s->t_pass1_own;
        r0->t_pass2 = s->t_pass2_own;
        r0->vertices = vmine;
        r0->certified = s->certified;
        r0->reused = s->tiles_reused;
        r0->t_tiles = t_own;
        /* the job's tile stage: until the last rank reported */
        s->t_tiles = gdt_now() - t_tiles0;
        r0->t_core = s->t_core;
        r0->t_certify = s->t_certify;
        r0->t_post = s->t_post;
        r0->t_device = s->t_device;
        r0->t_device_span = s->t_device_span;
        r0->replayed = gdt_cloud_replayed(c->cloud);
        snprintf(r0->device, sizeof r0->device, "%.*s", (int)sizeof r0->device - 1, s->device);
        s->certified += o->certified;
        c->seam_total += m->remote_seam;
        s->tiles_reused += o->tiles_reused;
        s->tiles_redone += o->tiles_redone;
        s->gcd_tiles += o->gcd_tiles;
        s->insert_tiles += o->insert_tiles;
        if (o->max_tile_points > s->max_tile_points)
            s->max_tile_points = o->max_tile_points;
        if (o->max_halo_points > s->max_halo_points)
            s->max_halo_points = o->max_halo_points;
        s->cert.triangles += o->cert.triangles;
        s->cert.certified += o->cert.certified;
        s->cert.inner += o->cert.inner;
        s->cert.outside_known += o->cert.outside_known;
        s->cert.halo_hit += o->cert.halo_hit;
        s->cert.halo_tests += o->cert.halo_tests;
        gdt_pred_stats_add(&s->cert.pred, &o->cert.pred);
        s->t_core += o->t_core;
        s->t_certify += o->t_certify;
        s->t_post += o->t_post;
        s->t_device += o->t_device;
        s->t_device_span += o->t_device_span;
    }
    {
        int wait = 0;
        double t_parts0 = gdt_now();
        /* --concavity: a tile's kept faces are known from the merge's
         * trim graph only, so the parts follow the merge; otherwise they
         * are written beside it */
        const int after = c->out_parts && c->trim.concavity > 0;
        if (after) {
            st = tr_run_merge(c, err);
            if (st == GDT_OK) {
                tr_out_set_trim(c->out, c->tgraph);
                st = mr_parts_send(m, &wait, err);
            }
        } else {
            st = c->out_parts ? mr_parts_send(m, &wait, err) : GDT_OK;
            if (st == GDT_OK)
                st = tr_run_merge(c, err);
        }
        if (wait) {
            gdt_error e2;
            gdt_status s2;
            gdt_error_clear(&e2);
            s2 = mr_parts_wait(m, &e2);
            if (st == GDT_OK && s2 != GDT_OK) {
                st = s2;
                *err = e2;
            }
        }
        if (c->out_parts) /* beside the merge: until the last part was synced */
            c->s.t_parts = gdt_now() - t_parts0;
    }
    if (st == GDT_OK)
        st = tr_run_finish(c, err);
    return st;
}

/* ---- another rank ---- */

static gdt_status rn_record(void *ctx, const tr_pending *p, size_t n, gdt_error *err)
{
    mr_ctx *m = ctx;
    gdt_pack pk;
    memset(&pk, 0, sizeof pk);
    gdt_pack_u64(&pk, (uint64_t)n);
    for (size_t i = 0; i < n; i++) {
        gdt_pack_u64(&pk, p[i].k);
        gdt_pack_u64(&pk, p[i].size);
        gdt_pack_u64(&pk, p[i].checksum);
    }
    return mr_send_pack(m, 0, TAG_RECORD, &pk, err);
}

static void rn_done(void *ctx, uint64_t k)
{
    mr_ctx *m = ctx;
    gdt_error e;
    gdt_error_clear(&e);
    if (gdt_comm_send(m->comm, 0, TAG_DONE, &k, sizeof k, &e) != GDT_OK) {
        gdt_error_print(&e, stderr);
        gdt_comm_abort(m->comm, (int)e.status);
    }
    mr_parts_tile_done(m, k); /* its vertices into the mesh, in parts */
}

static gdt_status rn_take(mr_ctx *m, const unsigned char *msg, size_t len, gdt_error *err);

/* Every message with tag from rank 0 already waiting, each handled:
 * FPLACE placed, GRANT taken (rn_take). */
static gdt_status rn_drain(mr_ctx *m, int tag, gdt_error *err)
{
    for (;;) {
        int ready = 0, from = 0, got = 0;
        size_t len = 0;
        unsigned char *buf = NULL;
        gdt_status st = gdt_comm_probe(m->comm, 0, tag, &ready, &from, &got, &len, err);
        if (st != GDT_OK || !ready)
            return st;
        st = mr_recv(m, 0, tag, len, &buf, err);
        if (st == GDT_OK && tag == TAG_FPLACE)
            mr_parts_place(m, buf, len);
        else if (st == GDT_OK)
            st = rn_take(m, buf, len, err);
        free(buf);
        if (st != GDT_OK)
            return st;
    }
}

static gdt_status rn_poll(void *ctx, gdt_error *err)
{
    mr_ctx *m = ctx;
    int ready = 0, from = 0, tag = 0;
    size_t len = 0;
    /* the faces of done tiles whose place is known, between tiles */
    gdt_status st = rn_drain(m, TAG_FPLACE, err);
    if (st != GDT_OK)
        return st;
    st = gdt_comm_probe(m->comm, 0, TAG_STOP, &ready, &from, &tag, &len, err);
    if (st != GDT_OK || !ready)
        return st;
    {
        uint64_t z;
        st = len == sizeof z ? gdt_comm_recv(m->comm, 0, TAG_STOP, &z, sizeof z, err)
                             : mr_bad_message(0, TAG_STOP, err);
    }
    if (st != GDT_OK)
        return st;
    m->stopped = 1;
    return gdt_error_set(err, GDT_EINTERRUPTED, 1303, "stopped: another rank failed");
}

/* Takes a GRANT (msg, len): its tiles join the rank's own, or none are
 * left. */
static gdt_status rn_take(mr_ctx *m, const unsigned char *msg, size_t len, gdt_error *err)
{
    gdt_unpack u;
    uint64_t g;
    memset(&u, 0, sizeof u);
    u.p = msg;
    u.n = len;
    g = gdt_unpack_u64(&u);
    if (u.bad || g > (u.n - u.at) / 32 || g > m->own_cap - m->own_n)
        return mr_bad_message(0, TAG_GRANT, err);
    for (uint64_t i = 0; i < g; i++) {
        uint64_t k = gdt_unpack_u64(&u);
        tr_tile_rec *r = &m->own_rec[m->own_n];
        r->found = gdt_unpack_u64(&u) != 0;
        r->size = gdt_unpack_u64(&u);
        r->sum = gdt_unpack_u64(&u);
        if (u.bad || k >= m->own_cap || (m->own_n > 0 && k <= m->own_ks[m->own_n - 1]))
            return mr_bad_message(0, TAG_GRANT, err);
        m->own_ks[m->own_n++] = k;
    }
    m->asked = 0;
    m->no_more = g == 0;
    m->taken += g;
    return GDT_OK;
}

/* The growing set of this rank's tiles: takes the grants that came, asks
 * for more when MR_ASK_AHEAD tiles are left to start (the answer comes
 * while they run), and, out of tiles, waits for the answer, placing faces
 * as FPLACE comes meanwhile. */
static gdt_status rn_more(void *ctx, uint64_t i, uint64_t *n, gdt_error *err)
{
    mr_ctx *m = ctx;
    gdt_status st = rn_drain(m, TAG_GRANT, err);
    if (st == GDT_OK && !m->no_more && !m->asked && m->own_n - i <= MR_ASK_AHEAD) {
        uint64_t z = 0;
        st = gdt_comm_send(m->comm, 0, TAG_MORE, &z, sizeof z, err);
        m->asked = st == GDT_OK;
    }
    while (st == GDT_OK && i == m->own_n && !m->no_more) {
        int ready = 0, from = 0, tag = 0;
        size_t len = 0;
        unsigned char *buf = NULL;
        st = gdt_comm_wait(m->comm, 0, -1, NULL, &ready, &from, &tag, &len, err);
        if (st == GDT_OK && tag != TAG_GRANT && tag != TAG_FPLACE && tag != TAG_STOP)
            st = mr_bad_message(0, tag, err);
        if (st == GDT_OK)
            st = mr_recv(m, 0, tag, len, &buf, err);
        if (st == GDT_OK && tag == TAG_GRANT) {
            st = rn_take(m, buf, len, err);
        } else if (st == GDT_OK && tag == TAG_FPLACE) {
            mr_parts_place(m, buf, len);
        } else if (st == GDT_OK) {
            m->stopped = 1;
            st = gdt_error_set(err, GDT_EINTERRUPTED, 1303, "stopped: another rank failed");
        }
        free(buf);
    }
    *n = m->own_n;
    return st;
}

static gdt_status run_other(mr_ctx *m, tr_run *c, gdt_error *err)
{
    gdt_status st = tr_run_init(c, c->opts, err), run_st = GDT_OK;
    unsigned char *go = NULL, *fin = NULL;
    size_t len = 0;
    uint64_t *ks = NULL, n = 0, vmine = 0, ntiles = 0;
    tr_tile_rec *rec = NULL;
    gdt_unpack u;
    gdt_pack p;

    /* whatever happened here, GO comes (rank 0 sends it to every rank);
     * before it, this rank's share of pass 1 and of pass 2 */
    mr_wait_go(m, &st, err, &go, &len);
    memset(&u, 0, sizeof u);
    u.p = go;
    u.n = len;
    run_st = (gdt_status)gdt_unpack_u64(&u);
    if (u.bad)
        st = mr_bad_message(0, TAG_GO, err);
    if (run_st != GDT_OK) {
        /* rank 0 failed before the tiles and says why: nothing to report */
        free(go);
        return run_st;
    }
    if (st == GDT_OK) {
        uint64_t id[2];
        size_t slen = 0;
        const unsigned char *state;
        id[0] = gdt_unpack_u64(&u);
        id[1] = gdt_unpack_u64(&u);
        state = gdt_unpack_bytes(&u, &slen);
        n = gdt_unpack_u64(&u);
        if (u.bad || n > (u.n - u.at) / 32)
            st = mr_bad_message(0, TAG_GO, err);
        if (st == GDT_OK) {
            ks = malloc((n + 1) * sizeof *ks);
            rec = malloc((n + 1) * sizeof *rec);
            if (ks == NULL || rec == NULL)
                st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        }
        for (uint64_t i = 0; st == GDT_OK && i < n; i++) {
            ks[i] = gdt_unpack_u64(&u);
            rec[i].found = gdt_unpack_u64(&u) != 0;
            rec[i].size = gdt_unpack_u64(&u);
            rec[i].sum = gdt_unpack_u64(&u);
        }
        m->on_demand = gdt_unpack_u64(&u) != 0;
        ntiles = gdt_unpack_u64(&u);
        if (st == GDT_OK && (u.bad || n > ntiles))
            st = mr_bad_message(0, TAG_GO, err);
        if (st == GDT_OK)
            st = mr_parts_read_layout(m, &u, err);
        if (st == GDT_OK)
            st = tr_run_attach(c, id, state, slen, err);
        if (st == GDT_OK && ntiles != gdt_tiler_tile_count(c->tiler))
            st = mr_bad_message(0, TAG_GO, err);
        /* room for every tile this rank may take on demand */
        m->own_cap = m->on_demand ? ntiles : n;
        if (st == GDT_OK && m->on_demand) {
            uint64_t *k2 = realloc(ks, (ntiles + 1) * sizeof *ks);
            tr_tile_rec *r2 = k2 != NULL ? realloc(rec, (ntiles + 1) * sizeof *rec) : NULL;
            if (k2 != NULL)
                ks = k2;
            if (r2 != NULL)
                rec = r2;
            if (k2 == NULL || r2 == NULL)
                st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        }
        m->own_ks = ks;
        m->own_rec = rec;
        m->own_n = n;
        /* with --concavity this rank's faces are written after the merge,
         * from its .tri files: kept in the page cache for that, not read
         * from the disk at the end; otherwise they are read as their
         * places come, a tile or two behind, and with direct I/O as every
         * other tile file (through the page cache they cost rank 1 more
         * system time than the reads they save: K = 2 on 10M points was
         * 0.24 s slower on average over four pairs of runs) */
        if (st == GDT_OK && m->parts) {
            c->tri_cached = c->trim.concavity > 0;
            st = mr_parts_open(m, err);
        }
        if (st == GDT_OK && m->parts) {
            m->fwritten = calloc(m->own_cap + 1, 1);
            if (m->fwritten == NULL)
                st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        }
    }
    free(go);
    /* with lanes this rank takes no tile on demand: they run ahead over
     * its first ones (the others take what is left) */
    if (st == GDT_OK)
        st = run_share(m, ks, n, rec, m->on_demand && c->cstart.nmore == 0, err);
    n = m->own_n;
    for (uint64_t i = 0; i < n; i++)
        vmine += c->base != NULL && ks[i] < c->s.tiles ? c->base[ks[i] + 1] - c->base[ks[i]] : 0;
    m->own_rec = NULL;
    free(rec);
    /* FINISHED: rank 0 waits for it from every rank */
    memset(&p, 0, sizeof p);
    gdt_pack_u64(&p, (uint64_t)st);
    gdt_pack_u64(&p, st != GDT_OK ? (uint64_t)err->code : 0);
    gdt_pack_bytes(&p, st != GDT_OK ? err->msg : "", st != GDT_OK ? strlen(err->msg) : 0);
    pack_report(&p, c, n, vmine, m->taken);
    {
        gdt_error e2;
        gdt_error_clear(&e2);
        gdt_status s2 = mr_send_pack(m, 0, TAG_FINISHED, &p, &e2);
        /* PARTS (write this rank's tiles into the mesh) and GOUT (its
         * share of --ground-out) may come before FINAL */
        while (s2 == GDT_OK) {
            int ready = 0, from = 0, tag = 0;
            unsigned char *req = NULL;
            s2 = gdt_comm_wait(m->comm, 0, -1, NULL, &ready, &from, &tag, &len, &e2);
            if (s2 == GDT_OK && tag == TAG_FINAL) {
                s2 = mr_recv(m, 0, TAG_FINAL, len, &fin, &e2);
                break;
            }
            if (s2 == GDT_OK && tag != TAG_PARTS && tag != TAG_GOUT && tag != TAG_FPLACE &&
                tag != TAG_GRANT && tag != TAG_STOP)
                s2 = mr_bad_message(0, tag, &e2);
            if (s2 == GDT_OK)
                s2 = mr_recv(m, 0, tag, len, &req, &e2);
            /* dropped: a GRANT asked for before this rank's tiles stopped
             * early, a STOP sent before rank 0 read FINISHED (the job
             * fails either way, and FINAL says so) */
            if (s2 == GDT_OK && tag == TAG_PARTS)
                mr_parts_answer(m, ks, n, req, len);
            else if (s2 == GDT_OK && tag == TAG_FPLACE)
                mr_parts_place(m, req, len);
            else if (s2 == GDT_OK && tag == TAG_GOUT)
                mr_gout_answer(m, req, len);
            free(req);
        }
        if (s2 != GDT_OK) {
            gdt_error_print(&e2, stderr);
            gdt_comm_abort(m->comm, (int)s2);
        }
    }
    m->own_ks = NULL;
    m->own_n = 0;
    free(ks);
    mr_parts_drop(m); /* a part PARTS never came for */
    /* the job's status is every rank's; rank 0 reports the error */
    memset(&u, 0, sizeof u);
    u.p = fin;
    u.n = len;
    run_st = (gdt_status)gdt_unpack_u64(&u);
    m->remove_share = gdt_unpack_u64(&u) != 0;
    free(fin);
    if (u.bad) {
        m->remove_share = 0;
        return mr_bad_message(0, TAG_FINAL, err);
    }
    return run_st;
}

/* Rank 0, after FINAL asked every rank that reported to remove its share
 * of the tile files: its own share, then, once every such rank has said
 * REMOVED, what is left of the job (tr_remove_job_files). */
static void remove_shared(mr_ctx *m, tr_run *c)
{
    tr_remove_tile_share(c->tiles_dir, 0, m->size);
    for (int r = 1; r < m->size; r++) {
        int ready = 0, from = 0, tag = 0;
        size_t len = 0;
        unsigned char *buf = NULL;
        gdt_error e2;
        gdt_status s2;
        if (!m->finished[r])
            continue;
        gdt_error_clear(&e2);
        s2 = gdt_comm_wait(m->comm, r, TAG_REMOVED, NULL, &ready, &from, &tag, &len, &e2);
        if (s2 == GDT_OK)
            s2 = mr_recv(m, r, TAG_REMOVED, len, &buf, &e2);
        free(buf);
        if (s2 != GDT_OK) {
            gdt_error_print(&e2, stderr); /* the job is done: what is left stays */
            return;
        }
    }
    tr_remove_job_files(c->job, 1, c->own_dir);
}

/* The tile stage over this rank's tiles ks[0, n): rank 0 with the journal
 * (rec NULL), another rank with the records GO gave; when grows, ks and
 * rec have room for every tile and the set grows with the tiles the rank
 * takes on demand. */
static gdt_status run_share(mr_ctx *m, const uint64_t *ks, uint64_t n, const tr_tile_rec *rec,
                            int grows, gdt_error *err)
{
    tr_tile_set set;
    memset(&set, 0, sizeof set);
    set.k = ks;
    set.n = n;
    set.rec = rec;
    set.ctx = m;
    set.done = m->rank == 0 ? r0_done : rn_done;
    set.poll = m->rank == 0 ? r0_poll : rn_poll;
    set.record = m->rank == 0 ? NULL : rn_record;
    if (grows)
        set.more = m->rank == 0 ? r0_more : rn_more;
    return tr_run_tiles(m->c, &set, err);
}

gdt_status gdt_cli_tiled_mpi(const gdt_options *opts, gdt_comm *comm, gdt_error *err)
{
    tr_run c;
    mr_ctx m;
    gdt_status st;
    gdt_options quiet;

    memset(&m, 0, sizeof m);
    m.c = &c;
    m.comm = comm;
    m.rank = gdt_comm_rank(comm);
    m.size = gdt_comm_size(comm);
    m.job_st = GDT_OK;
    gdt_error_clear(&m.job_err);
    m.finished = calloc((size_t)m.size, sizeof *m.finished);
    if (m.finished == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    if (m.rank == 0) {
        /* tr_run_init zeroes c: opts is set through it */
        c.opts = opts;
        st = run_rank0(&m, &c, err);
        for (int r = 1; r < m.size; r++) {
            uint64_t v[2] = {(uint64_t)st, (uint64_t)c.removal_due};
            gdt_error e2;
            gdt_error_clear(&e2);
            /* only ranks that got GO and reported wait for FINAL; those
             * that got a failed GO have returned */
            if (m.finished[r] && gdt_comm_send(comm, r, TAG_FINAL, v, sizeof v, &e2) != GDT_OK) {
                gdt_error_print(&e2, stderr);
                m.finished[r] = 0; /* no REMOVED to wait for */
            }
        }
        if (c.removal_due)
            remove_shared(&m, &c);
    } else {
        /* the other ranks print nothing: progress, warnings and the job's
         * error come from rank 0 */
        quiet = *opts;
        quiet.verbosity = -1;
        quiet.json = NULL;
        c.opts = &quiet;
        st = run_other(&m, &c, err);
        if (m.remove_share) {
            gdt_error e2;
            gdt_error_clear(&e2);
            tr_remove_tile_share(c.tiles_dir, m.rank, m.size);
            if (gdt_comm_send(comm, 0, TAG_REMOVED, NULL, 0, &e2) != GDT_OK)
                gdt_error_print(&e2, stderr);
        }
    }
    st = tr_run_close(&c, st);
    free(m.raw_pre);
    free(m.part_path);
    free(m.p1_bounds);
    free(m.p1_kept);
    free(m.p1_counts);
    free(m.towner);
    free(m.mine);
    free(m.first);
    free(m.fwritten);
    if (m.rank != 0)
        gdt_error_clear(err); /* rank 0 reports the job's error */
    free(m.done);
    free(m.finished);
    return st;
}
