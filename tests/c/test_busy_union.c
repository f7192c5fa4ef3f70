/* test_busy_union.c — the busy time of a device with several queues
 * (core/private/busy_union.h) against the brute-force union of every
 * interval, on simulated queues: each queue's commands run in order
 * without overlapping and start no earlier than they are enqueued, queues
 * report when they wait for their commands, in random interleavings, and
 * folds happen at random moments in between. */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "gdt_check.h"
#include "private/busy_union.h"

static gdt_checks C;

#define QMAX 5
#define CMAX 4096

static uint64_t rnd(uint64_t *s, uint64_t n)
{
    *s ^= *s << 13;
    *s ^= *s >> 7;
    *s ^= *s << 17;
    return *s % n;
}

static int cmp_iv(const void *a, const void *b)
{
    const uint64_t *x = a, *y = b;
    return x[0] < y[0] ? -1 : x[0] > y[0];
}

/* The length of the union of iv[0..n), by sorting. */
static uint64_t brute_union(uint64_t (*iv)[2], size_t n)
{
    uint64_t total = 0, a = 0, b = 0;
    int open = 0;
    qsort(iv, n, sizeof iv[0], cmp_iv);
    for (size_t i = 0; i < n; i++) {
        if (open && iv[i][0] <= b) {
            if (iv[i][1] > b)
                b = iv[i][1];
            continue;
        }
        if (open)
            total += b - a;
        a = iv[i][0];
        b = iv[i][1];
        open = 1;
    }
    return open ? total + (b - a) : total;
}

typedef struct sim_queue {
    gdt_busy_queue bq;
    uint64_t out[CMAX][2]; /* enqueued, not yet reported */
    size_t nout;
    uint64_t sched_end; /* when its last enqueued command ends */
} sim_queue;

static void run_case(uint64_t seed, int nq, int steps, int gap, int fold_every)
{
    static sim_queue q[QMAX];
    static uint64_t all[64 * CMAX][2];
    const gdt_busy_queue *qs[QMAX];
    size_t nall = 0;
    uint64_t s = seed * 2654435761u + 1, now = 1000;
    gdt_busy_union u;
    double got;
    uint64_t want;

    gdt_busy_init(&u);
    memset(q, 0, sizeof q);
    for (int i = 0; i < nq; i++)
        qs[i] = &q[i].bq;
    for (int k = 0; k < steps; k++) {
        int i = (int)rnd(&s, (uint64_t)nq);
        switch (rnd(&s, 4)) {
        case 0:
        case 1: /* queue i enqueues a command: it starts after now and after
                   the queue's previous one */
            if (q[i].nout < CMAX && nall < sizeof all / sizeof all[0]) {
                uint64_t t0 = (now > q[i].sched_end ? now : q[i].sched_end) +
                              rnd(&s, (uint64_t)gap + 1);
                uint64_t t1 = t0 + 1 + rnd(&s, 100);
                q[i].out[q[i].nout][0] = all[nall][0] = t0;
                q[i].out[q[i].nout][1] = all[nall][1] = t1;
                q[i].nout++;
                nall++;
                q[i].sched_end = t1;
                q[i].bq.pending = 1;
            }
            break;
        case 2: /* queue i waits for its commands and reports them */
            if (q[i].sched_end > now)
                now = q[i].sched_end;
            for (size_t c = 0; c < q[i].nout; c++)
                gdt_busy_add(&u, &q[i].bq, q[i].out[c][0], q[i].out[c][1]);
            q[i].nout = 0;
            q[i].bq.pending = 0;
            break;
        default: /* time passes */
            now += rnd(&s, 60);
            break;
        }
        if (fold_every > 0 && k % fold_every == 0)
            gdt_busy_fold(&u, qs, (size_t)nq, 0);
    }
    for (int i = 0; i < nq; i++) {
        for (size_t c = 0; c < q[i].nout; c++)
            gdt_busy_add(&u, &q[i].bq, q[i].out[c][0], q[i].out[c][1]);
        q[i].nout = 0;
        q[i].bq.pending = 0;
    }
    got = gdt_busy_seconds(&u);
    want = brute_union(all, nall);
    GDT_CHECK(&C, (uint64_t)(got * 1e9 + 0.5) == want,
              "seed %llu, %d queues, fold every %d: %.9f s, the union is %llu ns",
              (unsigned long long)seed, nq, fold_every, got, (unsigned long long)want);
    /* once folded, nothing is kept: the memory stays bounded */
    GDT_CHECK(&C, u.n == 0, "seed %llu: %zu intervals kept after the last fold",
              (unsigned long long)seed, u.n);
    gdt_busy_free(&u);
}

/* One queue: the union is the plain sum, whatever the folds. */
static void test_one_queue(void)
{
    gdt_busy_union u;
    gdt_busy_queue q = {0, 0};
    const gdt_busy_queue *qs[1] = {&q};
    gdt_busy_init(&u);
    q.pending = 1;
    gdt_busy_add(&u, &q, 10, 20);
    gdt_busy_add(&u, &q, 20, 25);
    gdt_busy_add(&u, &q, 30, 31);
    gdt_busy_add(&u, &q, 40, 40); /* empty: ignored */
    q.pending = 0;
    gdt_busy_fold(&u, qs, 1, 0);
    GDT_CHECK(&C, u.n == 0, "an idle queue's intervals all fold: %zu kept", u.n);
    GDT_CHECK(&C, (uint64_t)(gdt_busy_seconds(&u) * 1e9 + 0.5) == 16, "one queue: %.9f s",
              gdt_busy_seconds(&u));
    gdt_busy_free(&u);
}

/* A pending queue that has reported nothing holds every interval back: its
 * first command may have started at any time. */
static void test_pending_holds_back(void)
{
    gdt_busy_union u;
    gdt_busy_queue a = {0, 0}, b = {1, 0};
    const gdt_busy_queue *qs[2] = {&a, &b};
    gdt_busy_init(&u);
    gdt_busy_add(&u, &a, 100, 200);
    gdt_busy_fold(&u, qs, 2, 0);
    GDT_CHECK(&C, u.n == 1, "folded while another queue may overlap: %zu kept", u.n);
    gdt_busy_add(&u, &b, 150, 300); /* b's first command overlapped a's */
    b.pending = 0;
    GDT_CHECK(&C, (uint64_t)(gdt_busy_seconds(&u) * 1e9 + 0.5) == 200, "union %.9f s",
              gdt_busy_seconds(&u));
    gdt_busy_free(&u);
}

int main(void)
{
    test_one_queue();
    test_pending_holds_back();
    for (uint64_t seed = 1; seed <= 60; seed++) {
        int nq = 1 + (int)(seed % QMAX);
        run_case(seed, nq, 3000, seed % 3 == 0 ? 0 : 40, (int)(seed % 7) * 5);
    }
    return gdt_check_finish(&C, "test_busy_union");
}
