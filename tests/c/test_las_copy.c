/* Unit test of the LAS copy written in parts (io/gdt_las_copy.h): the
 * records of one file written by several writers at their places, in any
 * order, give the bytes of the sequential writer, header counts and bounds
 * included. */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "gdt_check.h"
#include "gdt_las_copy.h"

static gdt_checks checks;

#define CHECK(cond) GDT_CHECK(&checks, cond, "%s", "")

#define NREC 5000
#define RL 20

static const double scale[3] = {0.01, 0.01, 0.001};
static const double offset[3] = {500000.0, 4100000.0, 0.0};

/* NREC point-format-0 records: coordinates spread over +-2^30, returns 1..5. */
static void make_records(unsigned char *r)
{
    uint64_t s = 0x9E3779B97F4A7C15ull;
    memset(r, 0, (size_t)NREC * RL);
    for (int i = 0; i < NREC; i++) {
        unsigned char *p = r + (size_t)i * RL;
        for (int k = 0; k < 3; k++) {
            s = s * 6364136223846793005ull + 1442695040888963407ull;
            int32_t v = (int32_t)(s >> 33) - (1 << 30);
            memcpy(p + 4 * k, &v, 4); /* little-endian hosts only */
        }
        p[14] = (unsigned char)(((i % 5) + 1) | (5 << 3)); /* return r of 5 */
        p[15] = (unsigned char)(i % 3 == 0 ? 2 : 1);
    }
}

static int sequential(const char *path, const unsigned char *recs)
{
    gdt_las_copy *w = NULL;
    gdt_error e;
    gdt_error_clear(&e);
    if (gdt_las_copy_open_new(&w, path, scale, offset, &e) != GDT_OK)
        return 0;
    /* in pieces of odd sizes */
    for (int at = 0; at < NREC;) {
        int n = NREC - at < 777 ? NREC - at : 777;
        if (gdt_las_copy_put(w, recs + (size_t)at * RL, (size_t)n, &e) != GDT_OK) {
            gdt_las_copy_abort(w);
            return 0;
        }
        at += n;
    }
    return gdt_las_copy_finish(w, &e) == GDT_OK;
}

/* The file in parts: cuts[0..nparts] bound the parts; part order[0] is the
 * owner's own, the others are written through parts, in the given order. */
static int in_parts(const char *path, const unsigned char *recs, const int *cuts, int nparts,
                    const int *order)
{
    gdt_las_copy *w = NULL;
    gdt_error e;
    gdt_source_info ti;
    const char *tmp;
    uint64_t at;
    int ok = 1;

    gdt_error_clear(&e);
    memset(&ti, 0, sizeof ti);
    ti.point_format = 0;
    ti.record_length = RL;
    if (gdt_las_copy_open_new(&w, path, scale, offset, &e) != GDT_OK)
        return 0;
    gdt_las_copy_layout(w, &tmp, &at);
    CHECK(at == 227);
    for (int q = 1; q < nparts && ok; q++) {
        int p = order[q];
        gdt_las_copy *pw = NULL;
        gdt_las_copy_stats s;
        ok = gdt_las_copy_open_part(&pw, tmp, at, &ti, &e) == GDT_OK &&
             gdt_las_copy_seek(pw, (uint64_t)cuts[p], &e) == GDT_OK &&
             gdt_las_copy_put(pw, recs + (size_t)cuts[p] * RL, (size_t)(cuts[p + 1] - cuts[p]),
                              &e) == GDT_OK &&
             gdt_las_copy_close_part(pw, &s, &e) == GDT_OK;
        if (ok) {
            CHECK(s.count == (uint64_t)(cuts[p + 1] - cuts[p]));
            gdt_las_copy_add_stats(w, &s);
        }
    }
    if (ok) {
        int p = order[0];
        ok = gdt_las_copy_seek(w, (uint64_t)cuts[p], &e) == GDT_OK &&
             gdt_las_copy_put(w, recs + (size_t)cuts[p] * RL, (size_t)(cuts[p + 1] - cuts[p]),
                              &e) == GDT_OK &&
             gdt_las_copy_seek(w, NREC, &e) == GDT_OK;
    }
    if (!ok) {
        fprintf(stderr, "%s\n", e.msg);
        gdt_las_copy_abort(w);
        return 0;
    }
    return gdt_las_copy_finish(w, &e) == GDT_OK;
}

int main(int argc, char **argv)
{
    char a[4096], b[4096];
    const char *dir = argc > 1 ? argv[1] : ".";
    unsigned char *recs = malloc((size_t)NREC * RL), *fa, *fb;
    size_t na = 0, nb = 0;
    static const int cuts3[] = {0, 1234, 1235, NREC};
    static const int cuts4[] = {0, 0, 2500, 4999, NREC}; /* an empty part too */
    static const int order3[][3] = {{0, 1, 2}, {2, 1, 0}, {1, 2, 0}};
    static const int order4[] = {3, 0, 2, 1};

    if (recs == NULL)
        return 1;
    make_records(recs);
    snprintf(a, sizeof a, "%s/las-copy-seq.las", dir);
    snprintf(b, sizeof b, "%s/las-copy-parts.las", dir);
    CHECK(sequential(a, recs));
    fa = gdt_check_slurp(a, &na);
    CHECK(fa != NULL && na == 227 + (size_t)NREC * RL);
    for (int t = 0; t < 4; t++) {
        int ok = t < 3 ? in_parts(b, recs, cuts3, 3, order3[t]) : in_parts(b, recs, cuts4, 4, order4);
        CHECK(ok);
        fb = gdt_check_slurp(b, &nb);
        GDT_CHECK(&checks, fa != NULL && fb != NULL && na == nb && memcmp(fa, fb, na) == 0,
                  "case %d: the file in parts differs from the sequential one", t);
        free(fb);
        unlink(b);
    }
    {
        /* a part of a file that is not there */
        gdt_las_copy *pw = NULL;
        gdt_source_info ti;
        gdt_error e;
        char missing[4200];
        memset(&ti, 0, sizeof ti);
        ti.record_length = RL;
        gdt_error_clear(&e);
        snprintf(missing, sizeof missing, "%s/no-such-dir/x.las.tmp-1", dir);
        CHECK(gdt_las_copy_open_part(&pw, missing, 227, &ti, &e) == GDT_EIO && e.code == 4151 &&
              pw == NULL);
    }
    unlink(a);
    free(fa);
    free(recs);
    return gdt_check_finish(&checks, "test_las_copy");
}
