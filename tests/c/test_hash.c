/* test_hash — the tile files' checksum (gdt_hash64_wide, tiler/job.c)
 * detects damage: on buffers of every length around its 32-byte blocks and
 * some long ones, every single-bit flip (all bits of short buffers, a
 * sample of long ones), a swap of two different 8-byte words, one byte
 * more or less, and another seed each change the value; the value does not
 * depend on the buffer's address.  The fingerprint hash gdt_hash64 gets the
 * bit-flip check as well.  The incremental form (gdt_hash_wide_*, as the
 * tiler checksums a file while writing or reading it) equals the one-shot
 * value for every split of short buffers into two or three pieces and for
 * random piece sizes on long ones; gdt_job_file_seed differs per job id,
 * tile and kind. */
#include <stdlib.h>
#include <string.h>

#include "gdt_check.h"
#include "private/job.h"

static gdt_checks T = {0, 0};

int main(void)
{
    static const size_t longs[] = {4096, 65536 + 13, 1000003};
    uint64_t s = 99;
    unsigned char *a = malloc(1000003 + 64), *b = malloc(1000003 + 64);

    if (a == NULL || b == NULL)
        return 1;
    for (size_t i = 0; i < 1000003 + 64; i++)
        a[i] = (unsigned char)gdt_splitmix64(&s);
    for (size_t n = 0; n <= 200 + sizeof longs / sizeof longs[0]; n++) {
        size_t len = n <= 200 ? n : longs[n - 201];
        uint64_t h = gdt_hash64_wide(a, len, 5), g = gdt_hash64(a, len, 5);
        size_t step = len <= 200 ? 1 : 8 * len / 64 + 1;
        for (size_t bit = 0; bit < 8 * len; bit += step) {
            a[bit / 8] ^= (unsigned char)(1u << (bit % 8));
            GDT_CHECK_QUIET_AFTER(&T, 10, gdt_hash64_wide(a, len, 5) != h,
                                  "len %zu: flipping bit %zu is not seen", len, bit);
            GDT_CHECK_QUIET_AFTER(&T, 10, gdt_hash64(a, len, 5) != g,
                                  "gdt_hash64, len %zu: flipping bit %zu is not seen", len, bit);
            a[bit / 8] ^= (unsigned char)(1u << (bit % 8));
        }
        if (len >= 16 && memcmp(a, a + 8, 8) != 0) {
            unsigned char t[8];
            memcpy(t, a, 8);
            memmove(a, a + 8, 8);
            memcpy(a + 8, t, 8);
            GDT_CHECK(&T, gdt_hash64_wide(a, len, 5) != h, "len %zu: swapped words not seen", len);
            memcpy(a + 8, a, 8);
            memcpy(a, t, 8);
        }
        GDT_CHECK(&T, gdt_hash64_wide(a, len + 1, 5) != h, "len %zu: one byte more not seen", len);
        if (len > 0)
            GDT_CHECK(&T, gdt_hash64_wide(a, len - 1, 5) != h, "len %zu: one byte less not seen",
                      len);
        GDT_CHECK(&T, gdt_hash64_wide(a, len, 6) != h, "len %zu: the seed is not seen", len);
        memcpy(b + 3, a, len);
        GDT_CHECK(&T, gdt_hash64_wide(b + 3, len, 5) == h, "len %zu: depends on the address",
                  len);
        GDT_CHECK(&T, gdt_hash64_wide(a, len, 5) == h, "len %zu: not repeatable", len);
    }
    /* every split of short buffers into two and three pieces */
    for (size_t len = 0; len <= 100; len++) {
        uint64_t h = gdt_hash64_wide(a, len, 77);
        for (size_t i = 0; i <= len; i++)
            for (size_t j = i; j <= len; j++) {
                gdt_hash_wide st;
                gdt_hash_wide_init(&st, 77);
                gdt_hash_wide_update(&st, a, i);
                GDT_CHECK_QUIET_AFTER(&T, 10, gdt_hash_wide_final(&st) == gdt_hash64_wide(a, i, 77),
                                      "prefix %zu: the running value is not the one-shot one", i);
                gdt_hash_wide_update(&st, a + i, j - i);
                gdt_hash_wide_update(&st, a + j, len - j);
                GDT_CHECK_QUIET_AFTER(&T, 10, gdt_hash_wide_final(&st) == h,
                                      "len %zu split at %zu, %zu: differs from the one-shot value",
                                      len, i, j);
            }
    }
    /* long buffers in random pieces (0 to 5000 bytes, some empty) */
    for (int round = 0; round < 50; round++) {
        size_t len = (size_t)(gdt_splitmix64(&s) % 1000003), done = 0;
        uint64_t seed = gdt_splitmix64(&s);
        gdt_hash_wide st;
        gdt_hash_wide_init(&st, seed);
        while (done < len) {
            size_t m = (size_t)(gdt_splitmix64(&s) % 5001);
            if (m > len - done)
                m = len - done;
            gdt_hash_wide_update(&st, a + done, m);
            done += m;
        }
        GDT_CHECK(&T, gdt_hash_wide_final(&st) == gdt_hash64_wide(a, len, seed),
                  "len %zu in random pieces: differs from the one-shot value", len);
    }
    {
        const uint64_t id[2] = {1, 2}, id2[2] = {1, 3}, id3[2] = {2, 2};
        uint64_t f = gdt_job_file_seed(id, 5, GDT_JOB_FILE_PTS);
        GDT_CHECK(&T, f == gdt_job_file_seed(id, 5, GDT_JOB_FILE_PTS), "file seed not repeatable");
        GDT_CHECK(&T, f != gdt_job_file_seed(id2, 5, GDT_JOB_FILE_PTS) &&
                          f != gdt_job_file_seed(id3, 5, GDT_JOB_FILE_PTS),
                  "file seed ignores the job id");
        GDT_CHECK(&T, f != gdt_job_file_seed(id, 6, GDT_JOB_FILE_PTS), "file seed ignores the tile");
        GDT_CHECK(&T, f != gdt_job_file_seed(id, 5, GDT_JOB_FILE_EDGE), "file seed ignores the kind");
    }
    free(a);
    free(b);
    return gdt_check_finish(&T, "test_hash");
}
