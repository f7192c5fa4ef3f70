/* gdt_dupcount: the out-of-core count equals an in-memory count for every
 * budget, spills leave no file behind, and spill failures are GDT_EIO.
 * argv[1]: a directory for the spill files. */
#include <dirent.h>
#include <inttypes.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <unistd.h>

#include "gdt_check.h"
#include "gdt_dupcount.h"

static gdt_checks checks;

#define CHECK(cond, ...) GDT_CHECK(&checks, cond, __VA_ARGS__)

static uint64_t rng_state = UINT64_C(0x6a09e667f3bcc909);

static uint64_t rng(void) { return gdt_splitmix64(&rng_state); }

static int key_cmp(const void *pa, const void *pb)
{
    const gdt_point *a = pa, *b = pb;
    if (a->x != b->x)
        return a->x < b->x ? -1 : 1;
    if (a->y != b->y)
        return a->y < b->y ? -1 : 1;
    return 0;
}

static void reference(const gdt_point *p, size_t n, uint64_t *distinct, uint64_t *maxm)
{
    gdt_point *s = malloc((n ? n : 1) * sizeof *s);
    memcpy(s, p, n * sizeof *s);
    qsort(s, n, sizeof *s, key_cmp);
    *distinct = 0;
    *maxm = 0;
    for (size_t i = 0; i < n;) {
        size_t j = i;
        while (j < n && key_cmp(&s[i], &s[j]) == 0)
            j++;
        (*distinct)++;
        if (j - i > *maxm)
            *maxm = j - i;
        i = j;
    }
    free(s);
}

static size_t dir_entries(const char *dir)
{
    size_t n = 0;
    DIR *d = opendir(dir);
    struct dirent *e;
    if (d == NULL)
        return (size_t)-1;
    while ((e = readdir(d)) != NULL)
        if (strcmp(e->d_name, ".") != 0 && strcmp(e->d_name, "..") != 0)
            n++;
    closedir(d);
    return n;
}

/* Counts p[0..n) with budget, adding in chunks of chunk points. */
static gdt_status count(const gdt_point *p, size_t n, size_t budget, const char *dir,
                        size_t chunk, gdt_dupcount_result *r, gdt_error *err)
{
    gdt_dupcount *dc = NULL;
    gdt_dupcount_opts o;
    gdt_status st;
    memset(&o, 0, sizeof o);
    o.mem_budget = budget;
    o.temp_dir = dir;
    gdt_error_clear(err);
    memset(r, 0, sizeof *r);
    st = gdt_dupcount_create(&dc, &o, err);
    for (size_t i = 0; i < n && st == GDT_OK; i += chunk)
        st = gdt_dupcount_add(dc, p + i, n - i < chunk ? n - i : chunk, err);
    if (st == GDT_OK)
        st = gdt_dupcount_finish(dc, r, err);
    gdt_dupcount_destroy(dc);
    return st;
}

static void test_random(const char *dir)
{
    const size_t n = 60000;
    gdt_point *p = malloc(n * sizeof *p);
    static const size_t budgets[] = {4096, 16384, 262144, (size_t)64 << 20};
    for (int round = 0; round < 4; round++) {
        /* round 0: ~2.6 points per key; 1: heavy clusters plus spread; 2: near
         * the lattice limits; 3: all distinct */
        for (size_t i = 0; i < n; i++) {
            int64_t r = round == 0 ? 200 : round == 1 ? 3000 : 400;
            p[i].x = (int64_t)(rng() % (uint64_t)r) - r / 2;
            p[i].y = (int64_t)(rng() % (uint64_t)r) - r / 2;
            if (round == 1 && rng() % 3 == 0)
                p[i].x = p[i].y = (int64_t)(rng() % 5);
            if (round == 2) {
                p[i].x += (rng() & 1) ? INT64_C(9007199254740000) : -INT64_C(9007199254740000);
                p[i].y = -p[i].y;
            }
            if (round == 3) {
                p[i].x = (int64_t)i * 7919 % 1000003;
                p[i].y = (int64_t)i;
            }
            p[i].z = 0.0;
            p[i].ord = i;
        }
        uint64_t distinct, maxm;
        reference(p, n, &distinct, &maxm);
        for (size_t b = 0; b < sizeof budgets / sizeof budgets[0]; b++) {
            gdt_dupcount_result r;
            gdt_error err;
            size_t chunk = 1 + (size_t)(rng() % 5000);
            gdt_status st = count(p, n, budgets[b], dir, chunk, &r, &err);
            CHECK(st == GDT_OK, "round %d budget %zu: %s", round, budgets[b], err.msg);
            CHECK(r.points == n && r.distinct == distinct && r.duplicates == n - distinct &&
                      r.max_multiplicity == maxm,
                  "round %d budget %zu: points %" PRIu64 " distinct %" PRIu64 " (want %" PRIu64
                  ") max %" PRIu64 " (want %" PRIu64 ")",
                  round, budgets[b], r.points, r.distinct, distinct, r.max_multiplicity, maxm);
            if (budgets[b] == 4096)
                CHECK(r.levels >= 2 && r.spilled_records > 0,
                      "round %d: a 4 KiB budget must re-partition (levels %u)", round, r.levels);
            if (budgets[b] == ((size_t)64 << 20))
                CHECK(r.levels == 0 && r.spilled_records == 0, "64 MiB must stay in memory");
            CHECK(dir_entries(dir) == 0, "spill files left in %s", dir);
        }
    }
    free(p);
}

static void test_degenerate(const char *dir)
{
    const size_t n = 200000;
    gdt_point *p = calloc(n, sizeof *p);
    gdt_dupcount_result r;
    gdt_error err;
    /* one key: collapses in memory, never spills, whatever the budget */
    for (size_t i = 0; i < n; i++)
        p[i].x = -17, p[i].y = 4;
    CHECK(count(p, n, 4096, dir, 999, &r, &err) == GDT_OK, "%s", err.msg);
    CHECK(r.distinct == 1 && r.max_multiplicity == n && r.duplicates == n - 1 && r.levels == 0 &&
              r.spilled_records == 0, "one key: distinct %" PRIu64 " levels %u", r.distinct,
          r.levels);
    /* two keys alternate, then many distinct: a partition holding one heavy
     * key and few others must not be re-split forever */
    for (size_t i = 0; i < n; i++) {
        p[i].x = i < n / 2 ? (int64_t)(i % 2) : (int64_t)i;
        p[i].y = 0;
    }
    uint64_t distinct, maxm;
    reference(p, n, &distinct, &maxm);
    CHECK(count(p, n, 4096, dir, 4096, &r, &err) == GDT_OK, "%s", err.msg);
    CHECK(r.distinct == distinct && r.max_multiplicity == maxm, "heavy keys");
    /* nothing */
    CHECK(count(p, 0, 4096, dir, 1, &r, &err) == GDT_OK && r.points == 0 && r.distinct == 0 &&
              r.max_multiplicity == 0, "empty");
    free(p);
}

static void test_errors(const char *dir)
{
    const size_t n = 20000;
    gdt_point *p = calloc(n, sizeof *p);
    gdt_dupcount *dc = NULL;
    gdt_dupcount_opts o;
    gdt_dupcount_result r;
    gdt_error err;
    char missing[4096];

    for (size_t i = 0; i < n; i++)
        p[i].x = (int64_t)i, p[i].y = (int64_t)(i * 3);
    memset(&o, 0, sizeof o);
    o.mem_budget = 100;
    gdt_error_clear(&err);
    CHECK(gdt_dupcount_create(&dc, &o, &err) == GDT_EUSAGE && err.code == 2441 && dc == NULL,
          "tiny budget accepted");
    snprintf(missing, sizeof missing, "%.4000s/no-such-dir/deeper", dir);
    gdt_status st = count(p, n, 4096, missing, 1000, &r, &err);
    CHECK(st == GDT_EIO && err.code == 4441 && strstr(err.msg, "no-such-dir") != NULL,
          "missing spill dir: status %d code %d: %s", (int)st, err.code, err.msg);
    /* add after finish */
    memset(&o, 0, sizeof o);
    gdt_error_clear(&err);
    CHECK(gdt_dupcount_create(&dc, &o, &err) == GDT_OK, "%s", err.msg);
    CHECK(gdt_dupcount_finish(dc, &r, &err) == GDT_OK, "%s", err.msg);
    CHECK(gdt_dupcount_add(dc, p, 1, &err) == GDT_EINTERNAL && err.code == 7442, "add after finish");
    gdt_dupcount_destroy(dc);
    /* a full disk, emulated by a file size limit: write fails with GDT_EIO */
    {
        struct rlimit old, lim;
        getrlimit(RLIMIT_FSIZE, &old);
        signal(SIGXFSZ, SIG_IGN);
        lim = old;
        lim.rlim_cur = 8192;
        CHECK(setrlimit(RLIMIT_FSIZE, &lim) == 0, "setrlimit");
        const size_t big = 400000;
        gdt_point *q = calloc(big, sizeof *q);
        for (size_t i = 0; i < big; i++)
            q[i].x = (int64_t)i, q[i].y = -(int64_t)i;
        st = count(q, big, 4096, dir, 5000, &r, &err);
        setrlimit(RLIMIT_FSIZE, &old);
        CHECK(st == GDT_EIO && err.code == 4442, "file size limit: status %d code %d: %s",
              (int)st, err.code, err.msg);
        free(q);
    }
    CHECK(dir_entries(dir) == 0, "spill files left after errors");
    free(p);
}

int main(int argc, char **argv)
{
    char dir[4096];
    snprintf(dir, sizeof dir, "%s/dupcount-XXXXXX", argc > 1 ? argv[1] : "/tmp");
    if (mkdtemp(dir) == NULL) {
        perror("mkdtemp");
        return 1;
    }
    test_random(dir);
    test_degenerate(dir);
    test_errors(dir);
    rmdir(dir);
    return gdt_check_finish(&checks, "test_dedup_count");
}
