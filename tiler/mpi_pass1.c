/* mpi_pass1.c — pass 1 shared between the ranks of an MPI job.
 *
 * Rank 0, its cloud open: the records are cut into one share per rank
 * (gdt_cloud_split: whole records of uncompressed LAS and PCD binary,
 * whole chunks of LAZ, whole inputs otherwise; a cloud with a LAZ input that cannot be cut
 * is read by rank 0 alone, whose pass 1 decodes it once for pass 2 as
 * well).  P1 tells rank r its share;
 * each rank reads its own (rank 0 too) and answers P1DONE with its status
 * and what it read (gdt_tiler_pass1_part_export) with its count of kept
 * points (pass 2's ordinals start there); rank 0 takes every
 * answer, whatever its own share gave, adds them in rank order and plans.
 * The plan is that of one pass over the whole cloud (pass1_part.c), so the
 * job does not depend on the number of ranks. */
#include "private/mpi_sched.h"

#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* Rank 0: the shares, and each other rank's to it. */
static gdt_status p1_begin(void *ctx, int *shared, uint64_t *first, uint64_t *end,
                           gdt_error *err)
{
    mr_ctx *m = ctx;
    uint64_t *b;
    gdt_status st = GDT_OK;

    *shared = 0;
    b = malloc(((size_t)m->size + 1) * sizeof *b);
    if (b == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    if (!gdt_cloud_split(m->c->cloud, m->size, b)) {
        free(b);
        return GDT_OK;
    }
    for (int r = 1; r < m->size; r++) {
        gdt_pack p;
        memset(&p, 0, sizeof p);
        gdt_pack_u64(&p, b[r]);
        gdt_pack_u64(&p, b[r + 1]);
        st = mr_send_pack(m, r, TAG_P1, &p, err);
        if (st != GDT_OK) {
            /* rank r would never answer, and ranks before it wait for
             * GO: the job cannot go on */
            gdt_error_print(err, stderr);
            gdt_comm_abort(m->comm, (int)st);
        }
    }
    *shared = 1;
    *first = b[0];
    *end = b[1];
    m->p1_shared = 1;
    free(m->p1_bounds);
    m->p1_bounds = b; /* pass 2 reads the same shares */
    return GDT_OK;
}

/* Rank 0: every other rank's share into the tiler, in rank order. */
static gdt_status p1_collect(void *ctx, gdt_status own, gdt_error *err)
{
    mr_ctx *m = ctx;
    gdt_status st = own;
    /* each share's kept points: pass 2's ordinal bases (rank 0's own share
     * is all the cloud counted so far) */
    free(m->p1_kept);
    m->p1_kept = calloc((size_t)m->size, sizeof *m->p1_kept);
    if (m->p1_kept == NULL && st == GDT_OK)
        st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    if (m->p1_kept != NULL)
        m->p1_kept[0] = gdt_cloud_total_counts(m->c->cloud).kept;
    for (int r = 1; r < m->size; r++) {
        size_t len = 0, pl = 0;
        unsigned char *buf = NULL;
        const unsigned char *part;
        uint64_t kept;
        gdt_status rst;
        gdt_unpack u;
        mr_wait_recv(m, r, TAG_P1DONE, &buf, &len);
        memset(&u, 0, sizeof u);
        u.p = buf;
        u.n = len;
        rst = mr_unpack_status(m, &u, r);
        kept = gdt_unpack_u64(&u);
        part = gdt_unpack_bytes(&u, &pl);
        if (m->p1_kept != NULL)
            m->p1_kept[r] = kept;
        if (u.bad) {
            if (st == GDT_OK)
                st = mr_bad_message(r, TAG_P1DONE, err);
        } else if (rst != GDT_OK) {
            if (st == GDT_OK) {
                *err = m->job_err;
                st = rst;
            }
        } else if (st == GDT_OK) {
            st = gdt_tiler_pass1_part_merge(m->c->tiler, part, pl, err);
        }
        free(buf);
    }
    /* the whole pass's filter counts, for a pass 2 in shares */
    if (st == GDT_OK) {
        size_t nin = gdt_cloud_get_info(m->c->cloud)->ninputs;
        free(m->p1_counts);
        m->p1_counts = calloc(nin + 1, sizeof *m->p1_counts);
        for (size_t i = 0; m->p1_counts != NULL && i < nin; i++)
            m->p1_counts[i] = *gdt_cloud_input_counts(m->c->cloud, i);
    }
    return st;
}

void mr_pass1_hooks(mr_ctx *m)
{
    m->p1.begin = p1_begin;
    m->p1.collect = p1_collect;
    m->p1.ctx = m;
}

void mr_pass1_answer(mr_ctx *m, const unsigned char *msg, size_t len, gdt_status *pst,
                     gdt_error *perr, int *core_started)
{
    gdt_unpack u;
    gdt_error e;
    gdt_pack p;
    unsigned char *part = NULL;
    size_t pl = 0;
    uint64_t first, end, kept = 0;
    gdt_status st = *pst;

    memset(&u, 0, sizeof u);
    u.p = msg;
    u.n = len;
    first = gdt_unpack_u64(&u);
    end = gdt_unpack_u64(&u);
    gdt_error_clear(&e);
    if (st != GDT_OK)
        e = *perr; /* this rank could not start: its failure is the answer */
    else if (u.bad || first > end)
        st = mr_bad_message(0, TAG_P1, &e);
    else {
        double t0 = gdt_now();
        st = tr_run_pass1_share(m->c, first, end, &part, &pl, &kept, &e);
        m->c->s.t_pass1_own = gdt_now() - t0;
    }
    /* the build runs beside the answer's wait (and beside the others'
     * reading, had they more to read) */
    if (!*core_started) {
        *core_started = 1;
        if (*pst == GDT_OK)
            *pst = tr_run_start_core(m->c, perr);
    }
    memset(&p, 0, sizeof p);
    mr_pack_status(&p, st, &e);
    gdt_pack_u64(&p, kept);
    gdt_pack_bytes(&p, part, st == GDT_OK ? pl : 0);
    free(part);
    gdt_error_clear(&e);
    if (mr_send_pack(m, 0, TAG_P1DONE, &p, &e) != GDT_OK) {
        gdt_error_print(&e, stderr);
        gdt_comm_abort(m->comm, (int)e.status);
    }
}
