/* busy_union.c — see busy_union.h. */
#include "busy_union.h"

#include <stdlib.h>

void gdt_busy_init(gdt_busy_union *u)
{
    u->iv = NULL;
    u->n = u->cap = 0;
    u->folded_s = 0.0;
    u->folded_end = 0;
}

void gdt_busy_free(gdt_busy_union *u)
{
    free(u->iv);
    gdt_busy_init(u);
}

void gdt_busy_add(gdt_busy_union *u, gdt_busy_queue *q, uint64_t t0, uint64_t t1)
{
    if (!(t1 > t0))
        return;
    if (u->n == u->cap) {
        size_t cap = u->cap ? 2 * u->cap : 1024;
        void *g = realloc(u->iv, cap * sizeof u->iv[0]);
        if (g != NULL) {
            u->iv = g;
            u->cap = cap;
        }
    }
    if (u->n < u->cap) {
        u->iv[u->n][0] = t0;
        u->iv[u->n][1] = t1;
        u->n++;
    } else {
        u->folded_s += 1e-9 * (double)(t1 - t0);
    }
    if (t1 > q->last_end)
        q->last_end = t1;
}

static int iv_cmp(const void *a, const void *b)
{
    const uint64_t *x = a, *y = b;
    return x[0] < y[0] ? -1 : x[0] > y[0] ? 1 : x[1] < y[1] ? -1 : x[1] > y[1];
}

void gdt_busy_fold(gdt_busy_union *u, const gdt_busy_queue *const *qs, size_t nq, int all)
{
    uint64_t t = UINT64_MAX;
    size_t keep = 0;

    if (!all)
        for (size_t i = 0; i < nq; i++)
            if (qs[i]->pending && qs[i]->last_end < t)
                t = qs[i]->last_end;
    if (u->n == 0)
        return;
    qsort(u->iv, u->n, sizeof u->iv[0], iv_cmp);
    for (size_t i = 0; i < u->n;) {
        uint64_t a = u->iv[i][0], b = u->iv[i][1];
        size_t j = i + 1;
        while (j < u->n && u->iv[j][0] <= b) {
            if (u->iv[j][1] > b)
                b = u->iv[j][1];
            j++;
        }
        if (b <= t) {
            /* every interval still to come starts at or after t >= b */
            if (a < u->folded_end)
                a = u->folded_end;
            if (b > a)
                u->folded_s += 1e-9 * (double)(b - a);
            if (b > u->folded_end)
                u->folded_end = b;
        } else {
            u->iv[keep][0] = a;
            u->iv[keep][1] = b;
            keep++;
        }
        i = j;
    }
    u->n = keep;
}

double gdt_busy_seconds(gdt_busy_union *u)
{
    gdt_busy_fold(u, NULL, 0, 1);
    return u->folded_s;
}
