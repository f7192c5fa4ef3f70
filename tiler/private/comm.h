/* comm.h — the ranks of one job started by an MPI launcher.
 *
 * A thin layer over MPI point-to-point messages, so that the scheduler
 * (mpi_run.c) reads as a protocol and a build without MPI still compiles:
 * there gdt_comm_available() is 0 and gdt_comm_init refuses.
 *
 * Threads: MPI is initialised with MPI_THREAD_FUNNELED; every call below
 * must come from the thread that called gdt_comm_init.
 *
 * Waiting never spins: a rank that waits for a message (gdt_comm_wait)
 * probes, then sleeps a millisecond, so that ranks sharing a node's cores
 * with the OpenCL runtime's threads leave those cores to the work. */
#ifndef GDT_COMM_H
#define GDT_COMM_H

#include <signal.h>
#include <stddef.h>
#include <stdint.h>

#include "gdt_error.h"

typedef struct gdt_comm gdt_comm;

/* 1 when this build has MPI. */
int gdt_comm_available(void);

/* Initialises MPI (once per process) and returns the world's ranks.
 * returns: GDT_OK; GDT_EUSAGE 2952 (no MPI in this build), GDT_EINTERNAL
 * 7950 (MPI_Init failed).  Ownership: gdt_comm_finish. */
gdt_status gdt_comm_init(gdt_comm **out, gdt_error *err);

/* Finalises MPI and frees c; NULL is accepted. */
void gdt_comm_finish(gdt_comm *c);

/* This rank, the ranks of the job, and this rank among those of its node
 * (0, 1 and 0 for NULL: one process alone). */
int gdt_comm_rank(const gdt_comm *c);
int gdt_comm_size(const gdt_comm *c);
int gdt_comm_local_rank(const gdt_comm *c);

/* Sends len bytes to rank dest with tag (>= 0); returns when buf may be
 * reused.  returns: GDT_OK; GDT_EINTERNAL 7951. */
gdt_status gdt_comm_send(gdt_comm *c, int dest, int tag, const void *buf, size_t len,
                         gdt_error *err);

/* Whether a message waits (from src, or any rank when src < 0; with tag, or
 * any when tag < 0): *ready, and then its source, tag and length. */
gdt_status gdt_comm_probe(gdt_comm *c, int src, int tag, int *ready, int *from, int *got_tag,
                          size_t *len, gdt_error *err);

/* Waits (without spinning) for a message from src (any if < 0) with tag
 * (any if < 0) and gives its source, tag and length; stop (may be NULL)
 * ends the wait with *ready = 0 when it becomes nonzero. */
gdt_status gdt_comm_wait(gdt_comm *c, int src, int tag, const volatile sig_atomic_t *stop, int *ready,
                         int *from, int *got_tag, size_t *len, gdt_error *err);

/* Receives the message gdt_comm_probe/_wait announced (src, tag, len) into
 * buf (len bytes).  returns: GDT_OK; GDT_EINTERNAL 7951. */
gdt_status gdt_comm_recv(gdt_comm *c, int src, int tag, void *buf, size_t len, gdt_error *err);

/* Sends slen bytes to dest and receives rlen bytes from src, both with
 * tag, at once (a pairwise exchange cannot deadlock).  rlen must be the
 * length src sends.  returns: GDT_OK; GDT_EINTERNAL 7951. */
gdt_status gdt_comm_sendrecv(gdt_comm *c, int dest, const void *sbuf, size_t slen, int src,
                             void *rbuf, size_t rlen, int tag, gdt_error *err);

/* Ends every rank of the job at once (a rank that cannot go on and cannot
 * tell the others why). */
void gdt_comm_abort(gdt_comm *c, int code);

/* ---- message packing: little-endian u64 fields and byte strings ---- */

typedef struct gdt_pack {
    unsigned char *p;
    size_t n, cap;
    int oom;      /* an append failed: the message is incomplete */
} gdt_pack;

void gdt_pack_u64(gdt_pack *m, uint64_t v);
void gdt_pack_bytes(gdt_pack *m, const void *b, size_t n); /* u64 length, then the bytes */
void gdt_pack_f64(gdt_pack *m, double d);                  /* its bits, as a u64 */
void gdt_pack_free(gdt_pack *m);

typedef struct gdt_unpack {
    const unsigned char *p;
    size_t n, at;
    int bad;      /* a read went past the end */
} gdt_unpack;

uint64_t gdt_unpack_u64(gdt_unpack *u);
double gdt_unpack_f64(gdt_unpack *u);
/* The next byte string: a pointer into the message and its length. */
const unsigned char *gdt_unpack_bytes(gdt_unpack *u, size_t *n);

#endif
