/* The ranks of an MPI launch (see private/comm.h). */
#define _POSIX_C_SOURCE 200809L /* nanosleep */
#include "private/comm.h"

#include <limits.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#ifdef GDT_HAVE_MPI
#include <mpi.h>
#endif

struct gdt_comm {
    int rank, size;
    int local_rank; /* rank among the ranks of this node */
};

/* ---- packing (no MPI needed) ---- */

static void pack_grow(gdt_pack *m, size_t more)
{
    size_t cap;
    unsigned char *p;
    if (m->oom || m->n + more <= m->cap)
        return;
    cap = m->cap > 0 ? m->cap : 256;
    while (cap < m->n + more)
        cap *= 2;
    p = realloc(m->p, cap);
    if (p == NULL) {
        m->oom = 1;
        return;
    }
    m->p = p;
    m->cap = cap;
}

void gdt_pack_u64(gdt_pack *m, uint64_t v)
{
    pack_grow(m, 8);
    if (m->oom)
        return;
    for (int i = 0; i < 8; i++)
        m->p[m->n++] = (unsigned char)(v >> (8 * i));
}

void gdt_pack_f64(gdt_pack *m, double d)
{
    uint64_t v;
    memcpy(&v, &d, sizeof v);
    gdt_pack_u64(m, v);
}

void gdt_pack_bytes(gdt_pack *m, const void *b, size_t n)
{
    gdt_pack_u64(m, (uint64_t)n);
    pack_grow(m, n);
    if (m->oom || n == 0)
        return;
    memcpy(m->p + m->n, b, n);
    m->n += n;
}

void gdt_pack_free(gdt_pack *m)
{
    free(m->p);
    memset(m, 0, sizeof *m);
}

double gdt_unpack_f64(gdt_unpack *u)
{
    uint64_t v = gdt_unpack_u64(u);
    double d;
    memcpy(&d, &v, sizeof d);
    return d;
}

uint64_t gdt_unpack_u64(gdt_unpack *u)
{
    uint64_t v = 0;
    if (u->bad || u->n - u->at < 8) {
        u->bad = 1;
        return 0;
    }
    for (int i = 0; i < 8; i++)
        v |= (uint64_t)u->p[u->at + (size_t)i] << (8 * i);
    u->at += 8;
    return v;
}

const unsigned char *gdt_unpack_bytes(gdt_unpack *u, size_t *n)
{
    uint64_t len = gdt_unpack_u64(u);
    const unsigned char *p;
    *n = 0;
    if (u->bad || len > u->n - u->at) {
        u->bad = 1;
        return NULL;
    }
    p = u->p + u->at;
    u->at += (size_t)len;
    *n = (size_t)len;
    return p;
}

int gdt_comm_rank(const gdt_comm *c)
{
    return c != NULL ? c->rank : 0;
}

int gdt_comm_size(const gdt_comm *c)
{
    return c != NULL ? c->size : 1;
}

int gdt_comm_local_rank(const gdt_comm *c)
{
    return c != NULL ? c->local_rank : 0;
}

static void nap(void)
{
    struct timespec ts = {0, 1000000L};
    nanosleep(&ts, NULL);
}

#ifdef GDT_HAVE_MPI

int gdt_comm_available(void)
{
    return 1;
}

static gdt_status mpi_fail(gdt_error *err, int code, const char *what)
{
    char msg[MPI_MAX_ERROR_STRING];
    int len = 0;
    if (MPI_Error_string(code, msg, &len) != MPI_SUCCESS)
        len = 0;
    msg[len > 0 && len < MPI_MAX_ERROR_STRING ? len : 0] = '\0';
    return gdt_error_set(err, GDT_EINTERNAL, 7951, "MPI: %s failed: %s", what,
                         msg[0] != '\0' ? msg : "no message");
}

gdt_status gdt_comm_init(gdt_comm **out, gdt_error *err)
{
    int provided = 0, inited = 0;
    gdt_comm *c = calloc(1, sizeof *c);
    *out = NULL;
    if (c == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    MPI_Initialized(&inited);
    if (!inited && MPI_Init_thread(NULL, NULL, MPI_THREAD_FUNNELED, &provided) != MPI_SUCCESS) {
        free(c);
        return gdt_error_set(err, GDT_EINTERNAL, 7950, "MPI_Init failed");
    }
    /* errors come back as codes, never as an abort inside the library */
    MPI_Comm_set_errhandler(MPI_COMM_WORLD, MPI_ERRORS_RETURN);
    MPI_Comm_rank(MPI_COMM_WORLD, &c->rank);
    MPI_Comm_size(MPI_COMM_WORLD, &c->size);
    {
        /* the ranks that share this node's memory: a node's devices go to
         * its local ranks in turn (--device gpu/local) */
        MPI_Comm node;
        if (MPI_Comm_split_type(MPI_COMM_WORLD, MPI_COMM_TYPE_SHARED, c->rank, MPI_INFO_NULL,
                                &node) == MPI_SUCCESS) {
            MPI_Comm_rank(node, &c->local_rank);
            MPI_Comm_free(&node);
        }
    }
    *out = c;
    return GDT_OK;
}

void gdt_comm_finish(gdt_comm *c)
{
    int fin = 0;
    if (c == NULL)
        return;
    MPI_Finalized(&fin);
    if (!fin)
        MPI_Finalize();
    free(c);
}

gdt_status gdt_comm_send(gdt_comm *c, int dest, int tag, const void *buf, size_t len,
                         gdt_error *err)
{
    int rc;
    (void)c;
    if (len > (size_t)INT_MAX)
        return gdt_error_set(err, GDT_EINTERNAL, 7951, "MPI: a message of %zu bytes", len);
    /* MPI_Send takes a non-const buffer in MPI 2; it only reads it */
    rc = MPI_Send((void *)buf, (int)len, MPI_BYTE, dest, tag, MPI_COMM_WORLD);
    return rc == MPI_SUCCESS ? GDT_OK : mpi_fail(err, rc, "MPI_Send");
}

gdt_status gdt_comm_probe(gdt_comm *c, int src, int tag, int *ready, int *from, int *got_tag,
                          size_t *len, gdt_error *err)
{
    MPI_Status s;
    int flag = 0, count = 0, rc;
    (void)c;
    *ready = 0;
    rc = MPI_Iprobe(src < 0 ? MPI_ANY_SOURCE : src, tag < 0 ? MPI_ANY_TAG : tag,
                    MPI_COMM_WORLD, &flag, &s);
    if (rc != MPI_SUCCESS)
        return mpi_fail(err, rc, "MPI_Iprobe");
    if (!flag)
        return GDT_OK;
    MPI_Get_count(&s, MPI_BYTE, &count);
    *ready = 1;
    *from = s.MPI_SOURCE;
    *got_tag = s.MPI_TAG;
    *len = count > 0 ? (size_t)count : 0;
    return GDT_OK;
}

gdt_status gdt_comm_recv(gdt_comm *c, int src, int tag, void *buf, size_t len, gdt_error *err)
{
    int rc;
    (void)c;
    rc = MPI_Recv(buf, (int)len, MPI_BYTE, src, tag, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
    return rc == MPI_SUCCESS ? GDT_OK : mpi_fail(err, rc, "MPI_Recv");
}

gdt_status gdt_comm_sendrecv(gdt_comm *c, int dest, const void *sbuf, size_t slen, int src,
                             void *rbuf, size_t rlen, int tag, gdt_error *err)
{
    int rc;
    (void)c;
    if (slen > (size_t)INT_MAX || rlen > (size_t)INT_MAX)
        return gdt_error_set(err, GDT_EINTERNAL, 7951, "MPI: a message of %zu bytes",
                             slen > rlen ? slen : rlen);
    rc = MPI_Sendrecv((void *)sbuf, (int)slen, MPI_BYTE, dest, tag, rbuf, (int)rlen, MPI_BYTE,
                      src, tag, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
    return rc == MPI_SUCCESS ? GDT_OK : mpi_fail(err, rc, "MPI_Sendrecv");
}

void gdt_comm_abort(gdt_comm *c, int code)
{
    (void)c;
    MPI_Abort(MPI_COMM_WORLD, code);
}

#else /* no MPI in this build */

int gdt_comm_available(void)
{
    return 0;
}

gdt_status gdt_comm_init(gdt_comm **out, gdt_error *err)
{
    *out = NULL;
    return gdt_error_set(err, GDT_EUSAGE, 2952, "this gdt-tile was built without MPI");
}

void gdt_comm_finish(gdt_comm *c)
{
    free(c);
}

gdt_status gdt_comm_send(gdt_comm *c, int dest, int tag, const void *buf, size_t len,
                         gdt_error *err)
{
    (void)c, (void)dest, (void)tag, (void)buf, (void)len;
    return gdt_error_set(err, GDT_EINTERNAL, 7951, "no MPI in this build");
}

gdt_status gdt_comm_probe(gdt_comm *c, int src, int tag, int *ready, int *from, int *got_tag,
                          size_t *len, gdt_error *err)
{
    (void)c, (void)src, (void)tag, (void)from, (void)got_tag, (void)len;
    *ready = 0;
    return gdt_error_set(err, GDT_EINTERNAL, 7951, "no MPI in this build");
}

gdt_status gdt_comm_recv(gdt_comm *c, int src, int tag, void *buf, size_t len, gdt_error *err)
{
    (void)c, (void)src, (void)tag, (void)buf, (void)len;
    return gdt_error_set(err, GDT_EINTERNAL, 7951, "no MPI in this build");
}

gdt_status gdt_comm_sendrecv(gdt_comm *c, int dest, const void *sbuf, size_t slen, int src,
                             void *rbuf, size_t rlen, int tag, gdt_error *err)
{
    (void)c, (void)dest, (void)sbuf, (void)slen, (void)src, (void)rbuf, (void)rlen, (void)tag;
    return gdt_error_set(err, GDT_EINTERNAL, 7951, "no MPI in this build");
}

void gdt_comm_abort(gdt_comm *c, int code)
{
    (void)c, (void)code;
    abort();
}

#endif

gdt_status gdt_comm_wait(gdt_comm *c, int src, int tag, const volatile sig_atomic_t *stop, int *ready,
                         int *from, int *got_tag, size_t *len, gdt_error *err)
{
    for (;;) {
        gdt_status st = gdt_comm_probe(c, src, tag, ready, from, got_tag, len, err);
        if (st != GDT_OK || *ready)
            return st;
        if (stop != NULL && *stop)
            return GDT_OK;
        nap();
    }
}
