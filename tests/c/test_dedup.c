/* gdt_points_dedup: policies, the lowest-ordinal rule, determinism under
 * permutation, and large degenerate inputs. */
#include <inttypes.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "gdt_check.h"
#include "gdt_cloud.h"

static gdt_checks checks;

#define CHECK(cond, ...) GDT_CHECK(&checks, cond, __VA_ARGS__)

static uint64_t rng_state = UINT64_C(0x853c49e6748fea9b);

static uint64_t rng(void) { return gdt_splitmix64(&rng_state); }

static void shuffle(gdt_point *p, size_t n)
{
    for (size_t i = n; i > 1; i--) {
        size_t j = (size_t)(rng() % i);
        gdt_point t = p[i - 1];
        p[i - 1] = p[j];
        p[j] = t;
    }
}

static size_t run_dedup(gdt_point *p, size_t n, gdt_dup_policy pol)
{
    gdt_error err;
    size_t kept = (size_t)-1;
    gdt_error_clear(&err);
    gdt_status st = gdt_points_dedup(p, n, pol, &kept, &err);
    CHECK(st == GDT_OK, "dedup failed: %s", err.msg);
    return kept;
}

static void test_small_group(void)
{
    /* one (x, y) with ordinals 5, 2, 9, 3 and z 3, 7, 1, 7; one lone point */
    const gdt_point in[] = {{4, -1, 3.0, 5}, {4, -1, 7.0, 2}, {-8, 3, 0.5, 4},
                            {4, -1, 1.0, 9}, {4, -1, 7.0, 3}};
    struct { gdt_dup_policy p; double z; } want[] = {
        {GDT_DUP_FIRST, 7.0}, {GDT_DUP_MIN_Z, 1.0}, {GDT_DUP_MAX_Z, 7.0}};
    for (size_t w = 0; w < 3; w++) {
        gdt_point p[5];
        memcpy(p, in, sizeof p);
        size_t kept = run_dedup(p, 5, want[w].p);
        CHECK(kept == 2, "kept %zu", kept);
        CHECK(p[0].x == -8 && p[0].y == 3 && p[0].z == 0.5 && p[0].ord == 4, "lone point");
        CHECK(p[1].x == 4 && p[1].y == -1 && p[1].z == want[w].z && p[1].ord == 2,
              "policy %s: z %g ord %" PRIu64, gdt_dup_policy_name(want[w].p), p[1].z, p[1].ord);
    }
    /* min-z tie between ordinals 7 and 3: the lowest ordinal's z (-0.0) is kept */
    gdt_point t[] = {{0, 0, 0.0, 7}, {0, 0, -0.0, 3}, {0, 0, 5.0, 1}};
    CHECK(run_dedup(t, 3, GDT_DUP_MIN_Z) == 1, "tie kept");
    CHECK(t[0].z == 0.0 && signbit(t[0].z) && t[0].ord == 1, "min-z tie: z %g sign %d ord %" PRIu64,
          t[0].z, signbit(t[0].z) != 0, t[0].ord);
    gdt_point u[] = {{0, 0, 2.0, 7}, {0, 0, -0.0, 3}, {0, 0, 0.0, 1}};
    CHECK(run_dedup(u, 3, GDT_DUP_MIN_Z) == 1 && u[0].z == 0.0 && !signbit(u[0].z),
          "min-z tie with +0 at lower ordinal");
    CHECK(run_dedup(NULL, 0, GDT_DUP_FIRST) == 0, "empty");
    gdt_error err;
    size_t kept;
    gdt_error_clear(&err);
    CHECK(gdt_points_dedup(t, 1, (gdt_dup_policy)17, &kept, &err) == GDT_EINTERNAL &&
              err.code == 7401, "bad policy");
}

/* Reference: for key k, the records with that key, scanned naively. */
static int key_cmp(const void *pa, const void *pb)
{
    const gdt_point *a = pa, *b = pb;
    if (a->x != b->x)
        return a->x < b->x ? -1 : 1;
    if (a->y != b->y)
        return a->y < b->y ? -1 : 1;
    return 0;
}

static void check_against_reference(const gdt_point *orig, size_t n, gdt_dup_policy pol,
                                    const gdt_point *out, size_t kept)
{
    gdt_point *s = malloc(n * sizeof *s);
    size_t groups = 0;
    memcpy(s, orig, n * sizeof *s);
    qsort(s, n, sizeof *s, key_cmp); /* group by key only; order within is arbitrary */
    for (size_t i = 0; i < n;) {
        size_t j = i;
        uint64_t lo = UINT64_MAX;
        double zfirst = 0, zbest = 0;
        uint64_t best_ord = UINT64_MAX;
        while (j < n && key_cmp(&s[i], &s[j]) == 0)
            j++;
        for (size_t k = i; k < j; k++) {
            if (s[k].ord < lo) {
                lo = s[k].ord;
                zfirst = s[k].z;
            }
        }
        for (size_t k = i; k < j; k++) {
            int better = best_ord == UINT64_MAX ||
                         (pol == GDT_DUP_MIN_Z && (s[k].z < zbest ||
                                                   (s[k].z == zbest && s[k].ord < best_ord))) ||
                         (pol == GDT_DUP_MAX_Z && (s[k].z > zbest ||
                                                   (s[k].z == zbest && s[k].ord < best_ord)));
            if (better) {
                zbest = s[k].z;
                best_ord = s[k].ord;
            }
        }
        double zwant = pol == GDT_DUP_FIRST ? zfirst : zbest;
        if (groups < kept) {
            const gdt_point *o = &out[groups];
            CHECK(o->x == s[i].x && o->y == s[i].y && o->ord == lo && o->z == zwant,
                  "group %zu (%" PRId64 ", %" PRId64 ") policy %s: got z %g ord %" PRIu64
                  ", want z %g ord %" PRIu64, groups, s[i].x, s[i].y, gdt_dup_policy_name(pol),
                  o->z, o->ord, zwant, lo);
        }
        groups++;
        i = j;
    }
    CHECK(groups == kept, "kept %zu, reference %zu groups", kept, groups);
    for (size_t i = 1; i < kept; i++)
        CHECK(key_cmp(&out[i - 1], &out[i]) < 0, "output not strictly (x, y) sorted at %zu", i);
    free(s);
}

static void test_random(void)
{
    const size_t n = 50000;
    gdt_point *orig = malloc(n * sizeof *orig), *a = malloc(n * sizeof *a),
              *b = malloc(n * sizeof *b);
    gdt_point *byp[3] = {malloc(n * sizeof *orig), malloc(n * sizeof *orig),
                         malloc(n * sizeof *orig)};
    size_t keptp[3];
    for (int round = 0; round < 6; round++) {
        int64_t range = round < 3 ? 60 : 4000;       /* few or many duplicates */
        int repeated_ords = round % 3 == 2;
        for (size_t i = 0; i < n; i++) {
            orig[i].x = (int64_t)(rng() % (uint64_t)range) - range / 2;
            orig[i].y = (int64_t)(rng() % (uint64_t)range) - range / 2;
            if (round == 1 && i % 7 == 0) {
                orig[i].x += INT64_C(9007199254740991) - range; /* near the lattice limit */
                orig[i].y = -orig[i].y - INT64_C(9007199254740000);
            }
            orig[i].z = (double)(int64_t)(rng() % 16) - 8.0; /* many z ties */
            if (rng() % 11 == 0)
                orig[i].z = -0.0;
            orig[i].ord = repeated_ords ? rng() % (n / 4) : i;
        }
        if (!repeated_ords)
            shuffle(orig, n);
        for (int p = 0; p < 3; p++) {
            gdt_dup_policy pol = (gdt_dup_policy)p;
            memcpy(a, orig, n * sizeof *a);
            size_t ka = run_dedup(a, n, pol);
            if (!repeated_ords)
                check_against_reference(orig, n, pol, a, ka);
            /* any permutation gives the same bytes */
            for (int perm = 0; perm < 3; perm++) {
                memcpy(b, orig, n * sizeof *b);
                shuffle(b, n);
                if (perm == 1)
                    qsort(b, n, sizeof *b, key_cmp);
                size_t kb = run_dedup(b, n, pol);
                CHECK(ka == kb && memcmp(a, b, ka * sizeof *a) == 0,
                      "round %d policy %s perm %d: output depends on input order", round,
                      gdt_dup_policy_name(pol), perm);
            }
            memcpy(byp[p], a, ka * sizeof *a);
            keptp[p] = ka;
        }
        /* the kept records differ between policies only in z */
        for (int p = 1; p < 3; p++) {
            CHECK(keptp[p] == keptp[0], "kept differs between policies");
            for (size_t i = 0; i < keptp[0] && keptp[p] == keptp[0]; i++)
                CHECK(byp[p][i].x == byp[0][i].x && byp[p][i].y == byp[0][i].y &&
                          byp[p][i].ord == byp[0][i].ord,
                      "round %d: record %zu differs beyond z between policies", round, i);
        }
    }
    free(orig);
    free(a);
    free(b);
    for (int p = 0; p < 3; p++)
        free(byp[p]);
}

static void test_large_degenerate(void)
{
    const size_t n = (size_t)1 << 21;
    gdt_point *p = malloc(n * sizeof *p);
    /* all one point, ordinals descending: one record, lowest ordinal */
    for (size_t i = 0; i < n; i++)
        p[i] = (gdt_point){-3, 5, (double)(i % 1000), (uint64_t)(n - 1 - i)};
    size_t kept = run_dedup(p, n, GDT_DUP_MAX_Z);
    CHECK(kept == 1 && p[0].ord == 0 && p[0].z == 999.0, "all equal: kept %zu ord %" PRIu64,
          kept, p[0].ord);
    /* already sorted and reverse sorted, all distinct */
    for (int dir = 0; dir < 2; dir++) {
        for (size_t i = 0; i < n; i++) {
            int64_t k = dir == 0 ? (int64_t)i : (int64_t)(n - i);
            p[i] = (gdt_point){k / 1024, k % 1024, 1.0, i};
        }
        kept = run_dedup(p, n, GDT_DUP_FIRST);
        CHECK(kept == n, "distinct: kept %zu", kept);
        int ok = 1;
        for (size_t i = 1; i < kept; i++)
            ok &= key_cmp(&p[i - 1], &p[i]) < 0;
        CHECK(ok, "distinct input not sorted");
    }
    free(p);
}

int main(void)
{
    test_small_group();
    test_random();
    test_large_degenerate();
    return gdt_check_finish(&checks, "test_dedup");
}
