/* test_mpi_sched — how an MPI job shares its tiles (tiler/mpi_msg.c).
 *
 *   test_mpi_sched
 *
 * The tile stage's owners (mr_tile_owners): for weights of many shapes
 * (equal, random, one huge tile, zero weights, a ramp) and 1 to 9 ranks,
 * every tile has a rank in [0, size); after every prefix of tile order the
 * ranks' weights differ by at most the largest weight in it, so the ranks
 * pass through tile order together; each tile goes to the rank with the
 * least weight so far (the lowest on a tie), so equal weights go round
 * robin; the result is a pure function of the weights.  The shares of pass
 * 2 (mr_owner_of) stay contiguous runs of tile order that start at rank 0
 * and never go back.  GO deals out the shortest prefix of tile order that
 * holds all but a quarter of the weight (mr_tile_dealt); the rest goes in
 * grants that shrink to one tile and never exceed what is left
 * (mr_grant_size).
 */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "gdt_check.h"
#include "private/mpi_sched.h"

static gdt_checks T = {0, 0};

#define CHECK(cond) GDT_CHECK(&T, cond, "%s", "")

static uint64_t next(uint64_t *s)
{
    *s ^= *s << 13;
    *s ^= *s >> 7;
    *s ^= *s << 17;
    return *s;
}

static void one_case(const uint64_t *w, uint64_t n, int size)
{
    uint64_t *pre = malloc((n + 1) * sizeof *pre), *load = calloc((size_t)size, sizeof *load);
    int *own = malloc((n + 1) * sizeof *own), *again = malloc((n + 1) * sizeof *again);
    uint64_t wmax = 0;
    gdt_error err;
    CHECK(pre != NULL && load != NULL && own != NULL && again != NULL);
    pre[0] = 0;
    for (uint64_t k = 0; k < n; k++)
        pre[k + 1] = pre[k] + w[k];
    gdt_error_clear(&err);
    CHECK(mr_tile_owners(pre, n, size, own, &err) == GDT_OK);
    CHECK(mr_tile_owners(pre, n, size, again, &err) == GDT_OK);
    CHECK(memcmp(own, again, n * sizeof *own) == 0);
    for (uint64_t k = 0; k < n; k++) {
        int least = 0;
        uint64_t lo = UINT64_MAX, hi = 0;
        for (int r = 1; r < size; r++)
            if (load[r] < load[least])
                least = r;
        CHECK(own[k] >= 0 && own[k] < size);
        CHECK(own[k] == least);
        load[own[k]] += w[k];
        if (w[k] > wmax)
            wmax = w[k];
        for (int r = 0; r < size; r++) {
            lo = load[r] < lo ? load[r] : lo;
            hi = load[r] > hi ? load[r] : hi;
        }
        CHECK(hi - lo <= wmax);
    }
    /* pass 2's shares: contiguous, from rank 0 on, never back */
    for (uint64_t k = 0, last = 0; k < n; k++) {
        int r = mr_owner_of(pre, n, k, size);
        CHECK(r >= 0 && r < size && (uint64_t)r >= last);
        last = (uint64_t)r;
    }
    free(pre);
    free(load);
    free(own);
    free(again);
}

/* The tiles GO deals out: the shortest prefix holding at least all but
 * 1 / MR_TAIL_PARTS of the weights; the grants: a shrinking part of what
 * is left, at least one tile while any is left. */
static void dealt_case(const uint64_t *w, uint64_t n)
{
    uint64_t *pre = malloc((n + 1) * sizeof *pre), d, total;
    pre[0] = 17; /* an offset: only differences count */
    for (uint64_t k = 0; k < n; k++)
        pre[k + 1] = pre[k] + w[k];
    total = pre[n] - pre[0];
    d = mr_tile_dealt(pre, n);
    CHECK(d <= n);
    CHECK(pre[d] - pre[0] >= total - total / MR_TAIL_PARTS);
    CHECK(d == 0 || pre[d - 1] - pre[0] < total - total / MR_TAIL_PARTS);
    free(pre);
}

int main(void)
{
    enum { N = 300 };
    uint64_t w[N], s = 99;
    for (int size = 1; size <= 9; size++) {
        for (int shape = 0; shape < 5; shape++) {
            for (uint64_t k = 0; k < N; k++) {
                switch (shape) {
                case 0: w[k] = 1000; break;
                case 1: w[k] = next(&s) % 100000; break;
                case 2: w[k] = k == 7 ? 10000000 : 10 + k % 3; break;
                case 3: w[k] = k % 4 == 0 ? 0 : next(&s) % 50; break;
                default: w[k] = k * k; break;
                }
            }
            one_case(w, N, size);
            one_case(w, 1, size);
            one_case(w, 0, size);
        }
        {
            /* equal weights: round robin */
            uint64_t pre[13];
            int own[12];
            gdt_error err;
            gdt_error_clear(&err);
            for (int k = 0; k <= 12; k++)
                pre[k] = (uint64_t)k * 5;
            CHECK(mr_tile_owners(pre, 12, size, own, &err) == GDT_OK);
            for (int k = 0; k < 12; k++)
                CHECK(own[k] == k % size);
        }
    }
    {
        uint64_t eq[100], one[10] = {0, 0, 0, 0, 0, 0, 0, 0, 0, 50};
        for (int k = 0; k < 100; k++)
            eq[k] = 8;
        dealt_case(eq, 100);
        CHECK(mr_tile_dealt((const uint64_t[]){0, 8, 16, 24, 32}, 4) == 3);
        dealt_case(one, 10);
        dealt_case(w, N);
        dealt_case(w, 1);
        dealt_case(w, 0);
        for (uint64_t next = 0; next <= 100; next++)
            for (int size = 1; size <= 8; size++) {
                uint64_t g = mr_grant_size(next, 100, size);
                CHECK(next == 100 ? g == 0 : g >= 1 && g <= 100 - next);
                CHECK(next == 100 || g == 1 || g * 2 * (uint64_t)size <= 100 - next);
            }
        CHECK(mr_grant_size(0, 80, 2) == 20 && mr_grant_size(79, 80, 2) == 1);
    }
    return gdt_check_finish(&T, "test_mpi_sched");
}
