/* gdt_cloud over generated LAS and PCD files: lattice mapping per input,
 * ordinal continuity, identical streams for every chunk size and after
 * rewind, CRS refusals, projection properties, and changed inputs.
 * argv[1]: a directory for the generated files. */
#include <inttypes.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "gdt_check.h"
#include "gdt_cloud.h"

static gdt_checks checks;

#define CHECK(cond, ...) GDT_CHECK(&checks, cond, __VA_ARGS__)

static uint64_t rng_state = UINT64_C(0xbb67ae8584caa73b);

static uint64_t rng(void) { return gdt_splitmix64(&rng_state); }

static int32_t rng_i32(int32_t r) { return (int32_t)((int64_t)(rng() % (uint64_t)(2 * (int64_t)r + 1)) - r); }

static char dir[4096];

static const char *tmp_path(const char *name)
{
    static char buf[8][4200];
    static int slot;
    char *p = buf[slot++ % 8];
    snprintf(p, 4200, "%s/%s", dir, name);
    return p;
}

/* ---- writers ------------------------------------------------------------- */

enum { CRS_NONE = 0, CRS_PROJECTED = 1, CRS_GEOGRAPHIC = 2 };

static void put16(unsigned char *p, unsigned v) { p[0] = (unsigned char)v; p[1] = (unsigned char)(v >> 8); }
static void put32(unsigned char *p, uint32_t v)
{
    for (int i = 0; i < 4; i++)
        p[i] = (unsigned char)(v >> (8 * i));
}
static void putd(unsigned char *p, double d)
{
    uint64_t u;
    memcpy(&u, &d, 8);
    for (int i = 0; i < 8; i++)
        p[i] = (unsigned char)(u >> (8 * i));
}

/* LAS 1.2, point format 0, optional GeoKey directory (model type and
 * ProjectedCSType or GeographicType).  xyz holds n triples of record ints. */
static int write_las(const char *path, const double scale[3], const double offset[3], int crs,
                     int epsg, const int32_t (*xyz)[3], size_t n)
{
    unsigned char h[227], vlr[54], keys[24], rec[20];
    double mn[3] = {INFINITY, INFINITY, INFINITY}, mx[3] = {-INFINITY, -INFINITY, -INFINITY};
    size_t vlr_len = crs != CRS_NONE ? sizeof vlr + sizeof keys : 0;
    FILE *f = fopen(path, "wb");
    if (f == NULL)
        return -1;
    for (size_t i = 0; i < n; i++)
        for (int a = 0; a < 3; a++) {
            double v = xyz[i][a] * scale[a] + offset[a];
            mn[a] = fmin(mn[a], v);
            mx[a] = fmax(mx[a], v);
        }
    if (n == 0)
        for (int a = 0; a < 3; a++)
            mn[a] = mx[a] = 0.0;
    memset(h, 0, sizeof h);
    memcpy(h, "LASF", 4);
    h[24] = 1;
    h[25] = 2;
    memcpy(h + 26, "test", 4);
    memcpy(h + 58, "test_cloud_stream", 17);
    put16(h + 94, 227);
    put32(h + 96, (uint32_t)(227 + vlr_len));
    put32(h + 100, crs != CRS_NONE ? 1 : 0);
    h[104] = 0;
    put16(h + 105, 20);
    put32(h + 107, (uint32_t)n);
    put32(h + 111, (uint32_t)n);
    for (int a = 0; a < 3; a++) {
        putd(h + 131 + 8 * a, scale[a]);
        putd(h + 155 + 8 * a, offset[a]);
        putd(h + 179 + 16 * a, mx[a]);
        putd(h + 187 + 16 * a, mn[a]);
    }
    fwrite(h, 1, sizeof h, f);
    if (crs != CRS_NONE) {
        memset(vlr, 0, sizeof vlr);
        memcpy(vlr + 2, "LASF_Projection", 15);
        put16(vlr + 18, 34735);
        put16(vlr + 20, sizeof keys);
        memcpy(vlr + 22, "GeoKeyDirectoryTag", 18);
        unsigned words[12] = {1, 1, 0, 2, 1024, 0, 1, crs == CRS_PROJECTED ? 1u : 2u,
                              crs == CRS_PROJECTED ? 3072u : 2048u, 0, 1, (unsigned)epsg};
        for (int i = 0; i < 12; i++)
            put16(keys + 2 * i, words[i]);
        fwrite(vlr, 1, sizeof vlr, f);
        fwrite(keys, 1, sizeof keys, f);
    }
    for (size_t i = 0; i < n; i++) {
        memset(rec, 0, sizeof rec);
        for (int a = 0; a < 3; a++)
            put32(rec + 4 * a, (uint32_t)xyz[i][a]);
        rec[14] = 0x09; /* return 1 of 1 */
        fwrite(rec, 1, sizeof rec, f);
    }
    return fclose(f) == 0 ? 0 : -1;
}

static int write_pcd(const char *path, const double (*xyz)[3], size_t n)
{
    FILE *f = fopen(path, "w");
    if (f == NULL)
        return -1;
    fprintf(f, "# test cloud\nVERSION 0.7\nFIELDS x y z\nSIZE 8 8 8\nTYPE F F F\nCOUNT 1 1 1\n"
               "WIDTH %zu\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS %zu\nDATA ascii\n",
            n, n);
    for (size_t i = 0; i < n; i++)
        fprintf(f, "%.17g %.17g %.17g\n", xyz[i][0], xyz[i][1], xyz[i][2]);
    return fclose(f) == 0 ? 0 : -1;
}

/* ---- helpers --------------------------------------------------------------- */

typedef struct stream {
    gdt_point *p;
    size_t n;
} stream;

static gdt_status open_cloud(gdt_cloud **c, const char **paths, size_t n, double quantum,
                             size_t buffer_bytes, gdt_log *log, gdt_error *err)
{
    gdt_cloud_opts o;
    memset(&o, 0, sizeof o);
    o.quantum = quantum;
    o.buffer_bytes = buffer_bytes;
    o.log = log;
    gdt_error_clear(err);
    return gdt_cloud_open(c, paths, n, &o, err);
}

static gdt_status read_stream(gdt_cloud *c, size_t chunk, stream *s, gdt_error *err)
{
    gdt_point *buf = malloc(chunk * sizeof *buf);
    size_t cap = 0, got = 0;
    gdt_status st;
    s->p = NULL;
    s->n = 0;
    for (;;) {
        st = gdt_cloud_read(c, buf, chunk, &got, err);
        if (st != GDT_OK || got == 0)
            break;
        CHECK(got <= chunk, "read %zu > chunk %zu", got, chunk);
        if (s->n + got > cap) {
            cap = 2 * (s->n + got);
            s->p = realloc(s->p, cap * sizeof *s->p);
        }
        memcpy(s->p + s->n, buf, got * sizeof *buf);
        s->n += got;
    }
    free(buf);
    return st;
}

/* ---- tests ----------------------------------------------------------------- */

#define NA 1000
#define NB 700
#define NC 300
#define ND 200
#define NE 150

static void test_mixed_lattices(void)
{
    static int32_t a[NA][3], b[NB][3], d[ND][3], e[NE][3];
    static double c[NC][3];
    const double sa[3] = {0.01, 0.01, 0.01}, oa[3] = {0.0, 0.0, 0.0};
    const double sb[3] = {0.01, 0.01, 0.01}, ob[3] = {1000.5, -250.25, 10.0};
    const double sd[3] = {0.02, 0.02, 0.01}, od[3] = {0.03, -0.05, 0.0};
    const double se[3] = {0.003, 0.003, 0.01}, oe[3] = {0.0, 0.0, 0.0};
    const char *paths[5] = {tmp_path("a.las"), tmp_path("b.las"), tmp_path("c.pcd"),
                            tmp_path("d.las"), tmp_path("e.las")};
    gdt_cloud *cl = NULL;
    gdt_error err;
    gdt_log log;
    stream ref, s;

    for (int i = 0; i < NA; i++)
        a[i][0] = rng_i32(100000000), a[i][1] = rng_i32(100000000), a[i][2] = rng_i32(100000);
    a[0][0] = INT32_MAX, a[0][1] = INT32_MIN; /* extreme record integers */
    for (int i = 0; i < NB; i++)
        b[i][0] = rng_i32(100000000), b[i][1] = rng_i32(100000000), b[i][2] = rng_i32(100000);
    b[0][0] = INT32_MIN, b[0][1] = INT32_MAX;
    for (int i = 0; i < NC; i++) {
        /* a lattice value plus an offset below 0.4 of a step, both signs */
        int64_t ix = rng_i32(50000000), iy = rng_i32(50000000);
        double fx = ((double)(rng() % 801) - 400.0) / 1000.0 * 0.01;
        double fy = ((double)(rng() % 801) - 400.0) / 1000.0 * 0.01;
        c[i][0] = (double)ix * 0.01 + fx;
        c[i][1] = (double)iy * 0.01 + fy;
        c[i][2] = (double)rng_i32(1000) / 8.0;
    }
    for (int i = 0; i < ND; i++)
        d[i][0] = rng_i32(50000000), d[i][1] = rng_i32(50000000), d[i][2] = rng_i32(100000);
    for (int i = 0; i < NE; i++)
        e[i][0] = rng_i32(300000000), e[i][1] = rng_i32(300000000), e[i][2] = rng_i32(100000);
    CHECK(write_las(paths[0], sa, oa, CRS_PROJECTED, 32610, (const int32_t(*)[3])a, NA) == 0, "a");
    CHECK(write_las(paths[1], sb, ob, CRS_PROJECTED, 32610, (const int32_t(*)[3])b, NB) == 0, "b");
    CHECK(write_pcd(paths[2], (const double(*)[3])c, NC) == 0, "c");
    CHECK(write_las(paths[3], sd, od, CRS_NONE, 0, (const int32_t(*)[3])d, ND) == 0, "d");
    CHECK(write_las(paths[4], se, oe, CRS_PROJECTED, 32610, (const int32_t(*)[3])e, NE) == 0, "e");

    gdt_log_init(&log, -1);
    if (open_cloud(&cl, paths, 5, 0.0, 0, &log, &err) != GDT_OK) {
        CHECK(0, "open: %s", err.msg);
        return;
    }
    const gdt_cloud_info *in = gdt_cloud_get_info(cl);
    CHECK(in->ninputs == 5 && in->point_count == NA + NB + NC + ND + NE, "count %" PRIu64,
          in->point_count);
    CHECK(in->lattice_native && in->lattice_input == 0 && in->lattice.sx == 0.01 &&
              in->lattice.sy == 0.01 && in->lattice.ox == 0.0 && in->lattice.oy == 0.0,
          "lattice of a.las");
    CHECK(in->epsg == 32610 && !in->projected, "epsg %d", in->epsg);
    CHECK(gdt_cloud_input_map_of(cl, 0)->kind == GDT_CLOUD_MAP_NATIVE, "a native");
    CHECK(gdt_cloud_input_map_of(cl, 1)->kind == GDT_CLOUD_MAP_SHIFT, "b shift");
    CHECK(gdt_cloud_input_map_of(cl, 2)->kind == GDT_CLOUD_MAP_SNAP, "c snap");
    CHECK(gdt_cloud_input_map_of(cl, 3)->kind == GDT_CLOUD_MAP_SHIFT, "d shift (m = 2)");
    CHECK(gdt_cloud_input_map_of(cl, 4)->kind == GDT_CLOUD_MAP_SNAP, "e snapped");
    CHECK(log.warnings == 1, "one warning (e.las snapped), got %lu", log.warnings);
    CHECK(strcmp(gdt_cloud_input_path(cl, 2), paths[2]) == 0, "path");

    CHECK(read_stream(cl, 4096, &ref, &err) == GDT_OK, "read: %s", err.msg);
    CHECK(ref.n == NA + NB + NC + ND + NE, "streamed %zu", ref.n);
    if (ref.n == NA + NB + NC + ND + NE) {
        size_t k = 0;
        int ok_ord = 1, ok_a = 1, ok_b = 1, ok_c = 1, ok_d = 1, ok_e = 1;
        for (size_t i = 0; i < ref.n; i++)
            ok_ord &= ref.p[i].ord == i;
        for (int i = 0; i < NA; i++, k++)
            ok_a &= ref.p[k].x == a[i][0] && ref.p[k].y == a[i][1] &&
                    ref.p[k].z == a[i][2] * 0.01;
        for (int i = 0; i < NB; i++, k++)
            ok_b &= ref.p[k].x == (int64_t)b[i][0] + 100050 &&
                    ref.p[k].y == (int64_t)b[i][1] - 25025;
        for (int i = 0; i < NC; i++, k++)
            ok_c &= ref.p[k].x == (int64_t)nearbyint(c[i][0] / 0.01) &&
                    ref.p[k].y == (int64_t)nearbyint(c[i][1] / 0.01) && ref.p[k].z == c[i][2];
        for (int i = 0; i < ND; i++, k++)
            ok_d &= ref.p[k].x == 2 * (int64_t)d[i][0] + 3 &&
                    ref.p[k].y == 2 * (int64_t)d[i][1] - 5;
        for (int i = 0; i < NE; i++, k++) {
            /* snapped: within half a step of the true position */
            double tx = e[i][0] * 0.003, ty = e[i][1] * 0.003;
            ok_e &= fabs((double)ref.p[k].x * 0.01 - tx) <= 0.005 + 1e-9 &&
                    fabs((double)ref.p[k].y * 0.01 - ty) <= 0.005 + 1e-9;
        }
        CHECK(ok_ord, "ordinals are not 0..n-1 in stream order");
        CHECK(ok_a, "a.las: lattice integers are not the record integers");
        CHECK(ok_b, "b.las: not the exact shift (+100050, -25025)");
        CHECK(ok_c, "c.pcd: not snapped to the nearest step");
        CHECK(ok_d, "d.las: not the exact map 2X + 3, 2Y - 5");
        CHECK(ok_e, "e.las: snapped points off by more than half a step");
    }
    /* same stream for every chunk size and read-buffer size, after rewind */
    static const size_t chunks[] = {1, 7, 999, 1000, 100000};
    for (size_t t = 0; t < sizeof chunks / sizeof chunks[0]; t++) {
        CHECK(gdt_cloud_rewind(cl, &err) == GDT_OK, "rewind");
        CHECK(read_stream(cl, chunks[t], &s, &err) == GDT_OK, "reread: %s", err.msg);
        CHECK(s.n == ref.n && memcmp(s.p, ref.p, s.n * sizeof *s.p) == 0,
              "chunk %zu: stream differs after rewind", chunks[t]);
        free(s.p);
    }
    /* shares: for every count, the shares one after the other are the
     * stream (ordinals from the records before each share: no filter);
     * no boundary inside c.pcd; a share inside LAS inputs starts at its
     * record; a boundary inside the PCD input is refused */
    for (int k = 1; k <= 7; k++) {
        uint64_t bounds[8];
        size_t at = 0;
        int ok = 1;
        CHECK(gdt_cloud_split(cl, k, bounds) == 1, "an uncompressed cloud is shared");
        CHECK(bounds[0] == 0 && bounds[k] == ref.n, "%d shares: bounds", k);
        for (int j = 0; j < k; j++) {
            uint64_t pcd0 = NA + NB, pcd1 = NA + NB + NC;
            CHECK(bounds[j] <= bounds[j + 1], "%d shares: bounds decrease", k);
            CHECK(bounds[j + 1] <= pcd0 || bounds[j + 1] >= pcd1, "%d shares: inside c.pcd", k);
            CHECK(gdt_cloud_rewind(cl, &err) == GDT_OK, "rewind");
            CHECK(gdt_cloud_set_range(cl, bounds[j], bounds[j + 1], bounds[j], &err) == GDT_OK,
                  "set share: %s", err.msg);
            CHECK(read_stream(cl, 97, &s, &err) == GDT_OK, "share: %s", err.msg);
            ok &= at + s.n <= ref.n && s.n == bounds[j + 1] - bounds[j] &&
                  (s.n == 0 || memcmp(s.p, ref.p + at, s.n * sizeof *s.p) == 0);
            at += s.n;
            free(s.p);
        }
        CHECK(ok && at == ref.n, "%d shares are not the stream", k);
    }
    {
        /* across a.las and b.las, and inside d.las to e.las */
        static const uint64_t r[2][2] = {{5, NA + 301}, {NA + NB + NC + 17, NA + NB + NC + ND + 3}};
        for (int q = 0; q < 2; q++) {
            CHECK(gdt_cloud_rewind(cl, &err) == GDT_OK, "rewind");
            CHECK(gdt_cloud_set_range(cl, r[q][0], r[q][1], r[q][0], &err) == GDT_OK, "%s",
                  err.msg);
            CHECK(read_stream(cl, 64, &s, &err) == GDT_OK, "share: %s", err.msg);
            CHECK(s.n == r[q][1] - r[q][0] &&
                      memcmp(s.p, ref.p + r[q][0], s.n * sizeof *s.p) == 0,
                  "share [%" PRIu64 ", %" PRIu64 ") differs", r[q][0], r[q][1]);
            free(s.p);
        }
        CHECK(gdt_cloud_rewind(cl, &err) == GDT_OK, "rewind");
        CHECK(gdt_cloud_set_range(cl, NA + NB + 1, ref.n, 0, &err) == GDT_EINTERNAL &&
                  strstr(err.msg, "c.pcd") != NULL,
              "a share starting inside the PCD input: %s", err.msg);
        CHECK(gdt_cloud_set_range(cl, 0, UINT64_MAX, 0, &err) == GDT_OK, "whole again");
        CHECK(read_stream(cl, 4096, &s, &err) == GDT_OK && s.n == ref.n &&
                  memcmp(s.p, ref.p, s.n * sizeof *s.p) == 0,
              "the whole cloud after shares");
        free(s.p);
    }
    gdt_cloud_close(cl);
    gdt_log_init(&log, -1);
    if (open_cloud(&cl, paths, 5, 0.0, 64, &log, &err) == GDT_OK) {
        CHECK(read_stream(cl, 333, &s, &err) == GDT_OK, "small buffer: %s", err.msg);
        CHECK(s.n == ref.n && memcmp(s.p, ref.p, s.n * sizeof *s.p) == 0,
              "64-byte read buffer changes the stream");
        free(s.p);
        /* at the end, reads keep returning 0 */
        size_t got = 1;
        gdt_point one;
        CHECK(gdt_cloud_read(cl, &one, 1, &got, &err) == GDT_OK && got == 0, "after end");
        gdt_cloud_close(cl);
    } else {
        CHECK(0, "open with small buffer: %s", err.msg);
    }
    /* reversed input order: ordinals follow the command line, and the lattice
     * becomes that of the first LAS input (b.las) */
    const char *rev[2] = {paths[1], paths[0]};
    if (open_cloud(&cl, rev, 2, 0.0, 0, &log, &err) == GDT_OK) {
        CHECK(read_stream(cl, 100, &s, &err) == GDT_OK, "%s", err.msg);
        CHECK(gdt_cloud_get_info(cl)->lattice.ox == 1000.5 && s.n == NA + NB, "reverse lattice");
        int ok = s.n == NA + NB;
        for (size_t i = 0; ok && i < NB; i++)
            ok &= s.p[i].x == b[i][0] && s.p[i].ord == i;
        for (size_t i = 0; ok && i < NA; i++)
            ok &= s.p[NB + i].x == (int64_t)a[i][0] - 100050 &&
                  s.p[NB + i].y == (int64_t)a[i][1] + 25025 && s.p[NB + i].ord == NB + i;
        CHECK(ok, "reverse order: mapping or ordinals wrong");
        free(s.p);
        gdt_cloud_close(cl);
    }
    free(ref.p);
}

static void test_quantum_half_way(void)
{
    /* quantum 0.25: x / q is exact, so these are true ties */
    const double pts[][3] = {{0.125, -0.125, 1}, {0.375, -0.375, 2}, {0.625, -0.625, 3},
                             {-1.125, 1.125, 4}, {1e6 + 0.125, -1e6 - 0.375, 5}};
    const int64_t want[][2] = {{0, 0}, {2, -2}, {2, -2}, {-4, 4}, {4000000, -4000002}};
    const char *p = tmp_path("half.pcd");
    gdt_cloud *cl = NULL;
    gdt_error err;
    stream s;
    CHECK(write_pcd(p, pts, 5) == 0, "write");
    if (open_cloud(&cl, &p, 1, 0.25, 0, NULL, &err) != GDT_OK) {
        CHECK(0, "%s", err.msg);
        return;
    }
    const gdt_cloud_info *in = gdt_cloud_get_info(cl);
    CHECK(!in->lattice_native && in->lattice.sx == 0.25 && in->lattice.ox == 0.0 && in->epsg == 0,
          "quantum lattice");
    CHECK(read_stream(cl, 2, &s, &err) == GDT_OK && s.n == 5, "%s", err.msg);
    for (size_t i = 0; i < s.n && i < 5; i++)
        CHECK(s.p[i].x == want[i][0] && s.p[i].y == want[i][1] && s.p[i].ord == i,
              "point %zu: (%" PRId64 ", %" PRId64 "), want (%" PRId64 ", %" PRId64 ")", i,
              s.p[i].x, s.p[i].y, want[i][0], want[i][1]);
    free(s.p);
    gdt_cloud_close(cl);
    /* default quantum is 0.001 */
    if (open_cloud(&cl, &p, 1, 0.0, 0, NULL, &err) == GDT_OK) {
        CHECK(gdt_cloud_get_info(cl)->lattice.sx == 0.001, "default quantum");
        gdt_cloud_close(cl);
    }
    CHECK(open_cloud(&cl, &p, 1, -1.0, 0, NULL, &err) == GDT_EUSAGE && err.code == 2401 &&
              cl == NULL, "negative quantum");
    CHECK(open_cloud(&cl, &p, 0, 0.0, 0, NULL, &err) == GDT_EUSAGE, "no input");
}

static void test_refusals(void)
{
    const double s1[3] = {0.01, 0.01, 0.01}, o0[3] = {0, 0, 0};
    const double s3[3] = {0.001, 0.001, 0.001}, ofar[3] = {1e13, 0, 0};
    const int32_t r[3][3] = {{1, 2, 3}, {4, 5, 6}, {7, 8, 9}};
    const double big[3][3] = {{1, 2, 3}, {4, 5, 6}, {1e20, 8, 9}};
    const char *p10 = tmp_path("z10.las"), *p11 = tmp_path("z11.las"), *pg = tmp_path("geo.las");
    const char *pn = tmp_path("nocrs.las"), *pbig = tmp_path("big.pcd"), *pfar = tmp_path("far.las");
    const char *pnear = tmp_path("near.las");
    gdt_cloud *cl = NULL;
    gdt_error err;
    stream s;
    const double sg[3] = {1e-7, 1e-7, 0.01}, og[3] = {-123, 45, 0};

    write_las(p10, s1, o0, CRS_PROJECTED, 32610, r, 3);
    write_las(p11, s1, o0, CRS_PROJECTED, 32611, r, 3);
    write_las(pg, sg, og, CRS_GEOGRAPHIC, 4326, r, 3);
    write_las(pn, s1, o0, CRS_NONE, 0, r, 3);
    write_pcd(pbig, big, 3);
    write_las(pfar, s3, ofar, CRS_NONE, 0, r, 3);
    write_las(pnear, s3, o0, CRS_NONE, 0, r, 3);

    const char *diff[3] = {p10, pn, p11};
    CHECK(open_cloud(&cl, diff, 3, 0, 0, NULL, &err) == GDT_EINPUT && err.code == 3410 &&
              strstr(err.msg, p11) != NULL && strstr(err.msg, p10) != NULL && cl == NULL,
          "different EPSG: %d %s", err.code, err.msg);
    const char *kind[2] = {pg, p10};
    CHECK(open_cloud(&cl, kind, 2, 0, 0, NULL, &err) == GDT_EINPUT && err.code == 3411,
          "geographic with projected: %d %s", err.code, err.msg);
    /* no CRS mixes with anything */
    const char *mix[3] = {pn, p10, pbig};
    if (open_cloud(&cl, mix, 3, 0, 0, NULL, &err) == GDT_OK) {
        CHECK(gdt_cloud_get_info(cl)->epsg == 32610, "CRS from the input that has one");
        /* the third point of big.pcd cannot be on a 0.01 lattice below 2^53 */
        gdt_status st = read_stream(cl, 100, &s, &err);
        CHECK(st == GDT_EINPUT && err.code == 3402 && strstr(err.msg, pbig) != NULL &&
                  strstr(err.msg, "point 2") != NULL,
              "huge coordinate: %d %s", err.code, err.msg);
        CHECK(s.n == 6, "points before the bad one were delivered (%zu)", s.n);
        free(s.p);
        /* the error is sticky until rewind */
        gdt_point one;
        size_t got = 9;
        gdt_error_clear(&err);
        CHECK(gdt_cloud_read(cl, &one, 1, &got, &err) == GDT_EINPUT && got == 0 &&
                  err.code == 3402, "sticky error");
        CHECK(gdt_cloud_rewind(cl, &err) == GDT_OK, "rewind");
        gdt_error_clear(&err);
        CHECK(gdt_cloud_read(cl, &one, 1, &got, &err) == GDT_OK && got == 1 && one.ord == 0,
              "read after rewind");
        gdt_cloud_close(cl);
    } else {
        CHECK(0, "unknown CRS refused: %s", err.msg);
    }
    /* an offset 1e16 steps away is neither an exact shift nor representable */
    const char *far[2] = {pnear, pfar};
    if (open_cloud(&cl, far, 2, 0, 0, NULL, &err) == GDT_OK) {
        CHECK(gdt_cloud_input_map_of(cl, 1)->kind == GDT_CLOUD_MAP_SNAP, "far offset snaps");
        CHECK(read_stream(cl, 100, &s, &err) == GDT_EINPUT && err.code == 3402 &&
                  strstr(err.msg, pfar) != NULL && strstr(err.msg, "point 0") != NULL,
              "far offset: %d %s", err.code, err.msg);
        free(s.p);
        gdt_cloud_close(cl);
    } else {
        CHECK(0, "%s", err.msg);
    }
    const char *missing = tmp_path("missing.las");
    CHECK(open_cloud(&cl, &missing, 1, 0, 0, NULL, &err) == GDT_EINPUT &&
              strstr(err.msg, "missing.las") != NULL, "missing file: %s", err.msg);
}

/* Record integers of (lon, lat) at scale 1e-7 and the given offset. */
static void geo_rec(int32_t r[3], double lon, double lat, const double off[3])
{
    r[0] = (int32_t)nearbyint((lon - off[0]) / 1e-7);
    r[1] = (int32_t)nearbyint((lat - off[1]) / 1e-7);
    r[2] = 1000;
}

static void test_projection(void)
{
    const double sg[3] = {1e-7, 1e-7, 0.01};
    gdt_cloud *cl = NULL;
    gdt_error err;
    gdt_log log;
    stream s;

    /* zone 10 (central meridian 123 W), northern centre */
    {
        const double off[3] = {-123, 0, 0};
        int32_t r[6][3];
        geo_rec(r[0], -123.0, 0.0, off);     /* on the central meridian, at the equator */
        geo_rec(r[1], -122.5, 10.0, off);    /* mirror pair about the central meridian */
        geo_rec(r[2], -123.5, 10.0, off);
        geo_rec(r[3], -122.8, 1.0, off);     /* equator mirror pair */
        geo_rec(r[4], -122.8, -1.0, off);
        geo_rec(r[5], -123.0, 30.0, off);
        const char *p = tmp_path("utm10.las");
        CHECK(write_las(p, sg, off, CRS_GEOGRAPHIC, 4326, (const int32_t(*)[3])r, 6) == 0, "w");
        gdt_log_init(&log, -1);
        if (open_cloud(&cl, &p, 1, 0.0, 0, &log, &err) == GDT_OK) {
            const gdt_cloud_info *in = gdt_cloud_get_info(cl);
            CHECK(in->projected && in->utm_zone == 10 && in->utm_north == 1 && in->epsg == 32610,
                  "zone %d north %d epsg %d", in->utm_zone, in->utm_north, in->epsg);
            CHECK(strcmp(in->crs_desc,
                         "EPSG:32610 (WGS 84 / UTM zone 10N, projected from EPSG:4326)") == 0,
                  "desc %s", in->crs_desc);
            CHECK(in->lattice.sx == 0.001 && in->lattice.ox == 0.0 && !in->lattice_native,
                  "quantum lattice");
            CHECK(log.warnings == 0, "WGS 84 gives no warning");
            CHECK(read_stream(cl, 4, &s, &err) == GDT_OK && s.n == 6, "%s", err.msg);
            if (s.n == 6) {
                CHECK(s.p[0].x == 500000000 && s.p[0].y == 0, "origin of zone: %" PRId64
                      " %" PRId64, s.p[0].x, s.p[0].y);
                CHECK(llabs(s.p[1].x + s.p[2].x - 1000000000) <= 1 &&
                          llabs(s.p[1].y - s.p[2].y) <= 1, "mirror about the central meridian");
                CHECK(llabs(s.p[3].y + s.p[4].y) <= 1 && llabs(s.p[3].x - s.p[4].x) <= 1 &&
                          s.p[4].y < 0, "south point continues below the equator: %" PRId64,
                      s.p[4].y);
                /* northing grows monotonically with latitude on the meridian */
                CHECK(s.p[5].x == 500000000 && s.p[5].y > 3000000000 && s.p[5].y < 3400000000,
                      "30 N: %" PRId64, s.p[5].y);
            }
            free(s.p);
            gdt_cloud_close(cl);
        } else {
            CHECK(0, "%s", err.msg);
        }
    }
    /* southern hemisphere, non-WGS 84 datum: projected with a warning */
    {
        const double off[3] = {20, -30, 0};
        int32_t r[2][3];
        geo_rec(r[0], 21.0, -30.0, off);
        geo_rec(r[1], 21.2, -30.5, off);
        const char *p = tmp_path("south.las");
        CHECK(write_las(p, sg, off, CRS_GEOGRAPHIC, 4269, (const int32_t(*)[3])r, 2) == 0, "w");
        gdt_log_init(&log, -1);
        if (open_cloud(&cl, &p, 1, 0.0, 0, &log, &err) == GDT_OK) {
            const gdt_cloud_info *in = gdt_cloud_get_info(cl);
            CHECK(in->utm_zone == 34 && in->utm_north == 0 && in->epsg == 32734,
                  "south zone %d epsg %d", in->utm_zone, in->epsg);
            CHECK(log.warnings == 1, "datum warning (%lu)", log.warnings);
            CHECK(strstr(in->crs_desc, "EPSG:4269") != NULL, "%s", in->crs_desc);
            CHECK(read_stream(cl, 4, &s, &err) == GDT_OK && s.n == 2, "%s", err.msg);
            if (s.n == 2)
                CHECK(s.p[0].x == 500000000 && s.p[0].y > 6600000000 && s.p[0].y < 6700000000,
                      "south: %" PRId64 " %" PRId64, s.p[0].x, s.p[0].y);
            free(s.p);
            gdt_cloud_close(cl);
        } else {
            CHECK(0, "%s", err.msg);
        }
    }
    /* beyond 84 N: UPS north; the pole is at (2000 km, 2000 km) */
    {
        const double off[3] = {0, 89, 0};
        int32_t r[2][3];
        geo_rec(r[0], 0.0, 90.0, off);
        geo_rec(r[1], 45.0, 88.0, off);
        const char *p = tmp_path("ups.las");
        CHECK(write_las(p, sg, off, CRS_GEOGRAPHIC, 4326, (const int32_t(*)[3])r, 2) == 0, "w");
        if (open_cloud(&cl, &p, 1, 0.0, 0, NULL, &err) == GDT_OK) {
            const gdt_cloud_info *in = gdt_cloud_get_info(cl);
            CHECK(in->utm_zone == 0 && in->utm_north == 1 && in->epsg == 32661, "UPS %d",
                  in->epsg);
            CHECK(read_stream(cl, 4, &s, &err) == GDT_OK && s.n == 2, "%s", err.msg);
            if (s.n == 2)
                CHECK(s.p[0].x == 2000000000 && s.p[0].y == 2000000000 &&
                          s.p[1].x > 2000000000 && s.p[1].y < 2000000000,
                      "UPS: %" PRId64 " %" PRId64, s.p[0].x, s.p[0].y);
            free(s.p);
            gdt_cloud_close(cl);
        } else {
            CHECK(0, "%s", err.msg);
        }
    }
    /* header bounds that are not lon/lat */
    {
        const double off[3] = {0, 0, 0}, sbad[3] = {1e-7, 0.01, 0.01};
        int32_t r[1][3] = {{0, 950000, 0}}; /* latitude 9500 */
        const char *p = tmp_path("badlat.las");
        CHECK(write_las(p, sbad, off, CRS_GEOGRAPHIC, 4326, (const int32_t(*)[3])r, 1) == 0, "w");
        CHECK(open_cloud(&cl, &p, 1, 0.0, 0, NULL, &err) == GDT_EINPUT && err.code == 3460 &&
                  strstr(err.msg, "badlat.las") != NULL, "bad bounds: %d %s", err.code, err.msg);
    }
}

static void test_changed_input(void)
{
    const double s1[3] = {0.01, 0.01, 0.01}, o0[3] = {0, 0, 0};
    const int32_t r[4][3] = {{1, 2, 3}, {4, 5, 6}, {7, 8, 9}, {10, 11, 12}};
    const char *p = tmp_path("changing.las");
    gdt_cloud *cl = NULL;
    gdt_error err;
    stream s;
    write_las(p, s1, o0, CRS_NONE, 0, r, 4);
    if (open_cloud(&cl, &p, 1, 0, 0, NULL, &err) != GDT_OK) {
        CHECK(0, "%s", err.msg);
        return;
    }
    CHECK(read_stream(cl, 10, &s, &err) == GDT_OK && s.n == 4, "%s", err.msg);
    free(s.p);
    write_las(p, s1, o0, CRS_NONE, 0, r, 3);
    CHECK(gdt_cloud_rewind(cl, &err) == GDT_OK, "rewind");
    CHECK(read_stream(cl, 10, &s, &err) == GDT_EINPUT && err.code == 3405 &&
              strstr(err.msg, "changing.las") != NULL, "changed file: %d %s", err.code, err.msg);
    free(s.p);
    gdt_cloud_close(cl);
}

/* A binary PCD file has fixed-size records: shares cut it anywhere, and a
 * share ends at its record even where the reader skips records with NaN
 * coordinates (they are not points, so counting points would run past). */
static void test_pcd_binary_shares(void)
{
    enum { NP = 3001 };
    const double s1[3] = {0.01, 0.01, 0.01}, o0[3] = {0, 0, 0};
    static int32_t a[500][3];
    const char *paths[2];
    char p0[4200], p1[4200];
    gdt_cloud *cl = NULL;
    gdt_error err;
    gdt_log log;
    stream ref, s;
    FILE *f;
    size_t nan = 0;

    snprintf(p0, sizeof p0, "%s", tmp_path("bin.pcd"));
    snprintf(p1, sizeof p1, "%s", tmp_path("after.las"));
    paths[0] = p0;
    paths[1] = p1;
    f = fopen(p0, "wb");
    CHECK(f != NULL, "bin.pcd");
    if (f == NULL)
        return;
    fprintf(f, "VERSION 0.7\nFIELDS x y z\nSIZE 8 8 8\nTYPE F F F\nCOUNT 1 1 1\nWIDTH %d\n"
               "HEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS %d\nDATA binary\n",
            NP, NP);
    for (int i = 0; i < NP; i++) {
        double r[3] = {(double)rng_i32(100000) * 0.01, (double)rng_i32(100000) * 0.01,
                       (double)rng_i32(1000) / 4.0};
        if (i % 97 == 5 || (i >= 1490 && i < 1530)) { /* NaN runs around the middle */
            r[0] = NAN;
            nan++;
        }
        fwrite(r, sizeof r, 1, f);
    }
    CHECK(fclose(f) == 0, "bin.pcd written");
    for (int i = 0; i < 500; i++)
        a[i][0] = rng_i32(100000), a[i][1] = rng_i32(100000), a[i][2] = rng_i32(1000);
    CHECK(write_las(p1, s1, o0, CRS_NONE, 0, (const int32_t(*)[3])a, 500) == 0, "after.las");
    gdt_log_init(&log, -1);
    if (open_cloud(&cl, paths, 2, 0.01, 0, &log, &err) != GDT_OK) {
        CHECK(0, "open: %s", err.msg);
        return;
    }
    CHECK(read_stream(cl, 4096, &ref, &err) == GDT_OK, "read: %s", err.msg);
    CHECK(ref.n == NP - nan + 500, "streamed %zu of %d", ref.n, (int)(NP - nan + 500));
    for (int k = 1; k <= 7; k++) {
        uint64_t bounds[8], kept = 0;
        size_t at = 0;
        int ok = 1, inside = 0;
        CHECK(gdt_cloud_split(cl, k, bounds) == 1, "a binary PCD cloud is shared");
        for (int j = 0; j < k; j++) {
            inside |= bounds[j + 1] > 0 && bounds[j + 1] < NP;
            CHECK(gdt_cloud_rewind(cl, &err) == GDT_OK, "rewind");
            /* ordinals: the points kept before the share */
            CHECK(gdt_cloud_set_range(cl, bounds[j], bounds[j + 1], kept, &err) == GDT_OK,
                  "set share: %s", err.msg);
            CHECK(read_stream(cl, 97, &s, &err) == GDT_OK, "share: %s", err.msg);
            ok &= at + s.n <= ref.n && (s.n == 0 || memcmp(s.p, ref.p + at, s.n * sizeof *s.p) == 0);
            at += s.n;
            kept += s.n;
            free(s.p);
        }
        CHECK(ok && at == ref.n, "%d shares of a binary PCD are not the stream", k);
        CHECK(k == 1 || inside, "%d shares: no boundary inside bin.pcd", k);
    }
    /* a share that starts inside the NaN run and one that ends there */
    {
        static const uint64_t r[2][2] = {{1500, 2200}, {10, 1520}};
        for (int q = 0; q < 2; q++) {
            uint64_t before = 0;
            for (uint64_t i = 0; i < r[q][0]; i++)
                before += !(i % 97 == 5 || (i >= 1490 && i < 1530));
            CHECK(gdt_cloud_rewind(cl, &err) == GDT_OK, "rewind");
            CHECK(gdt_cloud_set_range(cl, r[q][0], r[q][1], before, &err) == GDT_OK, "%s",
                  err.msg);
            CHECK(read_stream(cl, 64, &s, &err) == GDT_OK, "share: %s", err.msg);
            uint64_t want = 0;
            for (uint64_t i = r[q][0]; i < r[q][1]; i++)
                want += !(i % 97 == 5 || (i >= 1490 && i < 1530));
            CHECK(s.n == want && memcmp(s.p, ref.p + before, s.n * sizeof *s.p) == 0,
                  "share [%" PRIu64 ", %" PRIu64 ") of bin.pcd differs", r[q][0], r[q][1]);
            free(s.p);
        }
    }
    free(ref.p);
    gdt_cloud_close(cl);
}

int main(int argc, char **argv)
{
    snprintf(dir, sizeof dir, "%.4000s/cloud-XXXXXX", argc > 1 ? argv[1] : "/tmp");
    if (mkdtemp(dir) == NULL) {
        perror("mkdtemp");
        return 1;
    }
    test_mixed_lattices();
    test_quantum_half_way();
    test_refusals();
    test_projection();
    test_changed_input();
    test_pcd_binary_shares();
    static const char *names[] = {"bin.pcd", "after.las", "a.las", "b.las", "c.pcd", "d.las", "e.las", "half.pcd",
                                  "z10.las", "z11.las", "geo.las", "nocrs.las", "big.pcd",
                                  "far.las", "near.las", "utm10.las", "south.las", "ups.las",
                                  "badlat.las", "changing.las"};
    for (size_t i = 0; i < sizeof names / sizeof names[0]; i++)
        unlink(tmp_path(names[i]));
    rmdir(dir);
    return gdt_check_finish(&checks, "test_cloud_stream");
}
