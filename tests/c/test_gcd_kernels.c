/* test_gcd_kernels — the utility kernels of the gCD core against their
 * sequential CPU references: the multi-level exclusive scan and the stream
 * compaction (gcd_scan.cl), on sizes around every level boundary and on
 * random, sparse and all-zero data; the stable radix sort against a stable
 * merge sort (ties keep their order), with few and many distinct keys.
 * Exit 77 without an OpenCL device. */
#include <stdlib.h>
#include <string.h>

#include "gen_degenerate.h"
#include "private/gcd_test.h"

static int cmp_u64(const void *a, const void *b)
{
    uint64_t x = *(const uint64_t *)a, y = *(const uint64_t *)b;
    return (x > y) - (x < y);
}

int main(void)
{
    tctx t = {0, 0};
    gdt_core *core = NULL;
    gdt_core_opts o;
    gdt_error err;
    gen_rng rng;
    static const size_t sizes[] = {1, 2, 255, 256, 257, 1000, 65535, 65536, 65537, 300000,
                                   16777217};

    memset(&o, 0, sizeof o);
    memset(&err, 0, sizeof err);
    o.device = getenv("GDT_TEST_DEVICE");
    if (gdt_core_create(&core, &o, &err) != GDT_OK) {
        gdt_error_print(&err, stderr);
        return err.status == GDT_EDEVICE && err.code == 5101 ? 77 : 1;
    }
    gen_seed(&rng, 4);
    for (size_t si = 0; si < sizeof sizes / sizeof sizes[0]; si++) {
        for (int kind = 0; kind < 3; kind++) {
            size_t n = sizes[si];
            uint32_t *in = malloc(4 * n), *out = malloc(4 * n), *fl = malloc(4 * n);
            uint32_t total = 0;
            size_t nf = 0;
            for (size_t i = 0; i < n; i++)
                in[i] = kind == 0 ? (uint32_t)gen_below(&rng, 100)
                        : kind == 1 ? (gen_below(&rng, 97) == 0)
                                    : 0;
            if (gcd_test_scan(core, in, n, out, &total, &nf, fl, &err) != GDT_OK) {
                CHECK(&t, 0, "n %zu: %s", n, err.msg);
            } else {
                uint32_t s = 0;
                size_t bad = 0, k = 0, badc = 0;
                for (size_t i = 0; i < n; i++) {
                    bad += out[i] != s;
                    s += in[i];
                    if (in[i] != 0)
                        badc += k >= nf || fl[k++] != i;
                }
                CHECK(&t, bad == 0 && total == s, "n %zu kind %d: %zu prefix sums wrong, total %u "
                      "vs %u", n, kind, bad, total, s);
                CHECK(&t, badc == 0 && k == nf, "n %zu kind %d: compaction gives %zu of %zu "
                      "(%zu wrong)", n, kind, nf, k, badc);
            }
            free(in);
            free(out);
            free(fl);
            if (n > 1000000)
                break;
        }
    }
    /* radix sort: (key, original position) pairs against qsort on (key, position) */
    static const size_t rsizes[] = {1, 5, 1023, 1024, 1025, 100000, 1000003};
    for (size_t si = 0; si < sizeof rsizes / sizeof rsizes[0]; si++) {
        for (int kind = 0; kind < 2; kind++) {
            size_t n = rsizes[si];
            unsigned bits = kind ? 28 : 8;
            uint32_t *k = malloc(4 * n), *v = malloc(4 * n);
            uint64_t *ref = malloc(8 * n);
            for (size_t i = 0; i < n; i++) {
                k[i] = (uint32_t)gen_below(&rng, kind ? (1u << 28) : 7u);
                v[i] = (uint32_t)i;
                ref[i] = ((uint64_t)k[i] << 32) | i;
            }
            qsort(ref, n, sizeof *ref, cmp_u64);
            if (gcd_test_radix(core, k, v, n, bits, &err) != GDT_OK) {
                CHECK(&t, 0, "radix n %zu: %s", n, err.msg);
            } else {
                size_t bad = 0;
                for (size_t i = 0; i < n; i++)
                    bad += k[i] != (uint32_t)(ref[i] >> 32) || v[i] != (uint32_t)ref[i];
                CHECK(&t, bad == 0, "radix n %zu bits %u: %zu pairs out of place", n, bits, bad);
            }
            free(k);
            free(v);
            free(ref);
        }
    }
    gdt_core_destroy(core);
    return gen_finish(&t, "test_gcd_kernels");
}
