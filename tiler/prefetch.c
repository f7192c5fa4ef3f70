/* prefetch.c — the cloud read one batch ahead (private/prefetch.h).
 *
 * design: two slots.  The reader fills slot r (r = 0, 1, 0, ...) when it is
 * empty; the caller takes slot c in the same order and gives it back empty
 * on its next call.  A slot holds a batch, or the end (n = 0), or an error;
 * the reader stops after the end or an error, or when told to.  One mutex
 * and one condition variable guard the slot states and the stop flag.
 */
#include "private/prefetch.h"

#include <pthread.h>
#include <stdlib.h>

typedef struct slot {
    gdt_point *buf;
    size_t n;
    int full;          /* holds a batch, the end or an error for the caller */
    gdt_status st;
    gdt_error err;
} slot;

struct tl_prefetch {
    gdt_cloud *cloud;
    size_t cap;
    slot s[2];
    unsigned take;     /* the slot the caller takes next */
    int held;          /* the caller holds slot take ^ 1 (its previous batch) */
    int threaded;      /* a reader thread runs (else reads are synchronous) */
    int stop;
    pthread_t tid;
    pthread_mutex_t mu;
    pthread_cond_t cv;
};

static void *reader_main(void *arg)
{
    tl_prefetch *p = arg;
    for (unsigned r = 0;; r ^= 1) {
        slot *s = &p->s[r];
        pthread_mutex_lock(&p->mu);
        while (s->full && !p->stop)
            pthread_cond_wait(&p->cv, &p->mu);
        if (p->stop) {
            pthread_mutex_unlock(&p->mu);
            return NULL;
        }
        pthread_mutex_unlock(&p->mu);
        /* slot r is empty and the caller does not touch it until full */
        s->n = 0;
        s->st = gdt_cloud_read(p->cloud, s->buf, p->cap, &s->n, &s->err);
        pthread_mutex_lock(&p->mu);
        s->full = 1;
        pthread_cond_broadcast(&p->cv);
        pthread_mutex_unlock(&p->mu);
        if (s->st != GDT_OK || s->n == 0)
            return NULL;
    }
}

gdt_status tl_prefetch_start(tl_prefetch **out, gdt_cloud *cloud, size_t cap, gdt_error *err)
{
    tl_prefetch *p = calloc(1, sizeof *p);
    *out = NULL;
    if (p == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    p->cloud = cloud;
    p->cap = cap > 0 ? cap : 1;
    for (int i = 0; i < 2; i++) {
        p->s[i].buf = malloc(p->cap * sizeof *p->s[i].buf);
        if (p->s[i].buf == NULL) {
            free(p->s[0].buf);
            free(p);
            return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        }
    }
    if (pthread_mutex_init(&p->mu, NULL) == 0) {
        if (pthread_cond_init(&p->cv, NULL) == 0) {
            if (pthread_create(&p->tid, NULL, reader_main, p) == 0)
                p->threaded = 1;
            else
                pthread_cond_destroy(&p->cv);
        }
        if (!p->threaded)
            pthread_mutex_destroy(&p->mu);
    }
    *out = p;
    return GDT_OK;
}

gdt_status tl_prefetch_next(tl_prefetch *p, const gdt_point **pts, size_t *n, gdt_error *err)
{
    slot *s = &p->s[p->take];
    *pts = NULL;
    *n = 0;
    if (!p->threaded) {
        gdt_status st = gdt_cloud_read(p->cloud, s->buf, p->cap, n, err);
        *pts = s->buf;
        return st;
    }
    pthread_mutex_lock(&p->mu);
    if (p->held) {
        /* the previous batch is done with: its slot may be refilled */
        p->s[p->take ^ 1].full = 0;
        pthread_cond_broadcast(&p->cv);
    }
    while (!s->full)
        pthread_cond_wait(&p->cv, &p->mu);
    pthread_mutex_unlock(&p->mu);
    p->held = 1;
    p->take ^= 1;
    if (s->st != GDT_OK) {
        *err = s->err;
        return s->st;
    }
    *pts = s->buf;
    *n = s->n;
    return GDT_OK;
}

void tl_prefetch_stop(tl_prefetch *p)
{
    if (p == NULL)
        return;
    if (p->threaded) {
        pthread_mutex_lock(&p->mu);
        p->stop = 1;
        pthread_cond_broadcast(&p->cv);
        pthread_mutex_unlock(&p->mu);
        pthread_join(p->tid, NULL);
        pthread_cond_destroy(&p->cv);
        pthread_mutex_destroy(&p->mu);
    }
    free(p->s[0].buf);
    free(p->s[1].buf);
    free(p);
}
