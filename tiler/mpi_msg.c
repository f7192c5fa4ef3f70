/* Message helpers of the MPI scheduler (private/mpi_sched.h). */
#include "private/mpi_sched.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

gdt_status mr_send_pack(mr_ctx *m, int dest, int tag, gdt_pack *p, gdt_error *err)
{
    gdt_status st = p->oom ? gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory")
                           : gdt_comm_send(m->comm, dest, tag, p->p, p->n, err);
    gdt_pack_free(p);
    return st;
}

/* Receives the message the probe announced; *buf is malloc'd. */
gdt_status mr_recv(mr_ctx *m, int from, int tag, size_t len, unsigned char **buf,
                           gdt_error *err)
{
    *buf = malloc(len > 0 ? len : 1);
    if (*buf == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    return gdt_comm_recv(m->comm, from, tag, *buf, len, err);
}

void mr_wait_recv(mr_ctx *m, int from, int tag, unsigned char **buf, size_t *len)
{
    int ready = 0, got_from = 0, got_tag = 0;
    gdt_error e;
    gdt_status st;
    gdt_error_clear(&e);
    *buf = NULL;
    st = gdt_comm_wait(m->comm, from, tag, NULL, &ready, &got_from, &got_tag, len, &e);
    if (st == GDT_OK)
        st = mr_recv(m, from, tag, *len, buf, &e);
    if (st != GDT_OK) {
        gdt_error_print(&e, stderr);
        gdt_comm_abort(m->comm, (int)st);
    }
}

gdt_status mr_bad_message(int from, int tag, gdt_error *err)
{
    return gdt_error_set(err, GDT_EINTERNAL, 7952,
                         "MPI: a malformed message (tag %d) from rank %d", tag, from);
}

/* The rank of tile k among size ranks, given the prefix sums pre[0, n]
 * of the tiles' weights: the rank whose share of the total holds the
 * middle of tile k's weight.  Contiguous runs of tile order, balanced by
 * weight; a pure function of the weights. */
int mr_owner_of(const uint64_t *pre, uint64_t n, uint64_t k, int size)
{
    uint64_t total = pre[n];
    long double mid = (long double)pre[k] + (long double)(pre[k + 1] - pre[k]) / 2;
    int r;
    if (total == 0)
        return 0;
    r = (int)(mid * size / (long double)total);
    return r < 0 ? 0 : r >= size ? size - 1 : r;
}


gdt_status mr_tile_owners(const uint64_t *pre, uint64_t n, int size, int *owner,
                          gdt_error *err)
{
    uint64_t *load = calloc((size_t)size, sizeof *load);
    if (load == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    for (uint64_t k = 0; k < n; k++) {
        int best = 0;
        for (int r = 1; r < size; r++)
            if (load[r] < load[best])
                best = r;
        owner[k] = best;
        load[best] += pre[k + 1] - pre[k];
    }
    free(load);
    return GDT_OK;
}

uint64_t mr_tile_dealt(const uint64_t *pre, uint64_t n)
{
    const uint64_t total = pre[n] - pre[0];
    uint64_t lo = 0, hi = n;
    /* the first k with pre[k] - pre[0] >= total - total / MR_TAIL_PARTS */
    while (lo < hi) {
        uint64_t mid = lo + (hi - lo) / 2;
        if (pre[mid] - pre[0] >= total - total / MR_TAIL_PARTS)
            hi = mid;
        else
            lo = mid + 1;
    }
    return lo;
}

uint64_t mr_grant_size(uint64_t next, uint64_t n, int size)
{
    uint64_t left = next < n ? n - next : 0, g = left / (2 * (uint64_t)(size > 0 ? size : 1));
    return left == 0 ? 0 : g < 1 ? 1 : g;
}

void mr_pack_status(gdt_pack *p, gdt_status st, const gdt_error *err)
{
    gdt_pack_u64(p, (uint64_t)st);
    gdt_pack_u64(p, st != GDT_OK ? (uint64_t)err->code : 0);
    gdt_pack_bytes(p, st != GDT_OK ? err->msg : "", st != GDT_OK ? strlen(err->msg) : 0);
}

gdt_status mr_unpack_status(mr_ctx *m, gdt_unpack *u, int from)
{
    gdt_status st = (gdt_status)gdt_unpack_u64(u);
    int code = (int)gdt_unpack_u64(u);
    size_t ml = 0;
    const unsigned char *msg = gdt_unpack_bytes(u, &ml);
    char text[GDT_ERROR_MSG_MAX];
    if (u->bad || st == GDT_OK)
        return GDT_OK;
    snprintf(text, sizeof text, "%.*s", (int)(ml < sizeof text ? ml : sizeof text - 1),
             (const char *)msg);
    mr_fail(m, from, st, code, text);
    return st;
}
