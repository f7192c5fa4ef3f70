/* Lattice snapping, exact lattice relations and CRS comparison (no I/O). */
#include <float.h>
#include <inttypes.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "gdt_check.h"
#include "gdt_cloud.h"
#include "private/cloud_lattice.h"

static gdt_checks checks;

#define CHECK(cond, ...) GDT_CHECK(&checks, cond, __VA_ARGS__)

static uint64_t rng_state = UINT64_C(0x2545f4914f6cdd1d);

static uint64_t rng(void) { return gdt_splitmix64(&rng_state); }

/* Uniform integer in [-r, r]. */
static int64_t rng_int(int64_t r) { return (int64_t)(rng() % (uint64_t)(2 * r + 1)) - r; }

static int64_t snap_or(double v, double o, double s, int64_t dflt)
{
    int64_t out = dflt;
    if (gdt_cloud_snap(v, o, s, &out) != GDT_SNAP_OK)
        return dflt;
    return out;
}

static void test_snap_half_even(void)
{
    /* Steps that are powers of two make v / step exact, so these are true
     * half-way cases: they must go to the even neighbour. */
    static const struct { double v, o, s; int64_t want; } cases[] = {
        {0.25, 0.0, 0.5, 0},    {0.75, 0.0, 0.5, 2},    {1.25, 0.0, 0.5, 2},
        {1.75, 0.0, 0.5, 4},    {-0.25, 0.0, 0.5, 0},   {-0.75, 0.0, 0.5, -2},
        {-1.25, 0.0, 0.5, -2},  {-1.75, 0.0, 0.5, -4},  {2.5, 0.0, 1.0, 2},
        {3.5, 0.0, 1.0, 4},     {-2.5, 0.0, 1.0, -2},   {-3.5, 0.0, 1.0, -4},
        {0.5, 0.0, 1.0, 0},     {-0.5, 0.0, 1.0, 0},    {10.5, 10.0, 1.0, 0},
        {11.5, 10.0, 1.0, 2},   {-9.5, -10.0, 1.0, 0},  {-10.5, -10.0, 1.0, 0},
        {-11.5, -10.0, 1.0, -2}, {0.375, 0.0, 0.25, 2}, {0.125, 0.0, 0.25, 0},
        /* not half-way: ordinary rounding, both signs */
        {0.2600001, 0.0, 0.5, 1}, {-0.2600001, 0.0, 0.5, -1}, {0.7499, 0.0, 0.5, 1},
        {-0.7499, 0.0, 0.5, -1},
        /* decimal quantum: 0.3 / 0.1 is 2.9999999999999996 in binary */
        {0.3, 0.0, 0.1, 3}, {-0.3, 0.0, 0.1, -3}, {123.456, 0.0, 0.001, 123456},
        {-123.456, 0.0, 0.001, -123456},
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        int64_t got = INT64_MIN;
        gdt_snap_result r = gdt_cloud_snap(cases[i].v, cases[i].o, cases[i].s, &got);
        CHECK(r == GDT_SNAP_OK && got == cases[i].want, "snap(%.17g, o=%g, s=%g) = %" PRId64
              " (result %d), want %" PRId64, cases[i].v, cases[i].o, cases[i].s, got, (int)r,
              cases[i].want);
    }
}

static void test_snap_random(void)
{
    /* Binary steps: v = (i + f) * s exactly, f in (-1/2, 1/2) a multiple of
     * 2^-10: the snap must give i; f = +-1/2 must give the even one. */
    for (int t = 0; t < 200000; t++) {
        int e = (int)(rng() % 21) - 10;
        double s = ldexp(1.0, e);
        int64_t i = rng_int((int64_t)1 << 40);
        int64_t fnum = rng_int(511); /* f = fnum / 1024 */
        double v = ((double)i + (double)fnum / 1024.0) * s;
        CHECK(snap_or(v, 0.0, s, INT64_MIN) == i, "snap of %.17g with step 2^%d", v, e);
        double half = ((double)i + 0.5) * s;
        int64_t even = (i % 2 == 0) ? i : i + 1;
        CHECK(snap_or(half, 0.0, s, INT64_MIN) == even, "half-way %.17g, step 2^%d, want %" PRId64,
              half, e, even);
    }
    /* Decimal quantum: a lattice value written as i * q comes back as i. */
    static const double qs[] = {0.001, 0.01, 0.1, 0.0001, 0.005, 0.3};
    for (int t = 0; t < 200000; t++) {
        double q = qs[rng() % (sizeof qs / sizeof qs[0])];
        int64_t i = rng_int((int64_t)1 << 40);
        double v = (double)i * q;
        CHECK(snap_or(v, 0.0, q, INT64_MIN) == i, "decimal snap of %" PRId64 " * %g", i, q);
    }
}

static void test_snap_refusals(void)
{
    int64_t out = 77;
    CHECK(gdt_cloud_snap(NAN, 0.0, 0.001, &out) == GDT_SNAP_NONFINITE && out == 77, "NaN");
    CHECK(gdt_cloud_snap(INFINITY, 0.0, 0.001, &out) == GDT_SNAP_NONFINITE, "inf");
    CHECK(gdt_cloud_snap(-INFINITY, 0.0, 0.001, &out) == GDT_SNAP_NONFINITE, "-inf");
    CHECK(gdt_cloud_snap(1e300, 0.0, 1e-300, &out) == GDT_SNAP_RANGE, "overflow to inf");
    CHECK(gdt_cloud_snap(9007199254740992.0, 0.0, 1.0, &out) == GDT_SNAP_RANGE, "2^53");
    CHECK(gdt_cloud_snap(-9007199254740992.0, 0.0, 1.0, &out) == GDT_SNAP_RANGE, "-2^53");
    CHECK(gdt_cloud_snap(9007199254740991.0, 0.0, 1.0, &out) == GDT_SNAP_OK &&
              out == INT64_C(9007199254740991), "2^53 - 1");
    CHECK(gdt_cloud_snap(-9007199254740991.0, 0.0, 1.0, &out) == GDT_SNAP_OK &&
              out == -INT64_C(9007199254740991), "-(2^53 - 1)");
    /* 1e13 m on a 1 mm lattice is 1e16 > 2^53 */
    CHECK(gdt_cloud_snap(1e13, 0.0, 0.001, &out) == GDT_SNAP_RANGE, "1e13 / 0.001");
    CHECK(gdt_cloud_snap(9e12, 0.0, 0.001, &out) == GDT_SNAP_OK, "9e12 / 0.001");
}

static void test_relation_cases(void)
{
    int64_t m = -1, k = -1;
    CHECK(gdt_cloud_lattice_relation(0.01, 1000.5, 0.01, 0.0, &m, &k) && m == 1 && k == 100050,
          "shift 1000.5: m=%" PRId64 " k=%" PRId64, m, k);
    CHECK(gdt_cloud_lattice_relation(0.01, -250.25, 0.01, 0.0, &m, &k) && m == 1 && k == -25025,
          "negative shift: k=%" PRId64, k);
    CHECK(gdt_cloud_lattice_relation(0.01, 0.0, 0.01, 0.0, &m, &k) && m == 1 && k == 0,
          "identity");
    CHECK(gdt_cloud_lattice_relation(0.01, 637000.13, 0.01, 636000.07, &m, &k) && m == 1 &&
              k == 100006, "decimal offsets: k=%" PRId64, k);
    CHECK(gdt_cloud_lattice_relation(0.01, 5.0, 0.001, 2.0, &m, &k) && m == 10 && k == 3000,
          "coarser scale: m=%" PRId64 " k=%" PRId64, m, k);
    CHECK(!gdt_cloud_lattice_relation(0.001, 0.0, 0.01, 0.0, &m, &k), "finer scale maps");
    CHECK(!gdt_cloud_lattice_relation(0.01, 0.005, 0.01, 0.0, &m, &k), "half-step offset");
    CHECK(!gdt_cloud_lattice_relation(0.01, 1e-9, 0.01, 0.0, &m, &k), "1e-7 step offset");
    CHECK(gdt_cloud_lattice_relation(0.01, 1e-12, 0.01, 0.0, &m, &k) && k == 0,
          "1e-10 step offset is noise");
    CHECK(!gdt_cloud_lattice_relation(0.025, 0.0, 0.01, 0.0, &m, &k), "ratio 2.5");
    CHECK(!gdt_cloud_lattice_relation(0.01 * (1.0 + 1e-12), 0.0, 0.01, 0.0, &m, &k),
          "scale off by 1e-12");
    CHECK(!gdt_cloud_lattice_relation(NAN, 0.0, 0.01, 0.0, &m, &k), "NaN scale");
    CHECK(!gdt_cloud_lattice_relation(0.01, INFINITY, 0.01, 0.0, &m, &k), "inf offset");
    CHECK(!gdt_cloud_lattice_relation(0.0, 0.0, 0.01, 0.0, &m, &k), "zero scale");
    CHECK(!gdt_cloud_lattice_relation(-0.01, 0.0, -0.01, 0.0, &m, &k), "negative scale");
    /* offsets so large against the step that exactness cannot be judged */
    CHECK(!gdt_cloud_lattice_relation(1e-9, 1e9, 1e-9, 0.0, &m, &k), "noise above 1e-4 step");
}

static void test_relation_random(void)
{
    static const double scales[] = {0.01, 0.001, 0.1, 0.0001, 0.25, 1.0, 0.02};
    int accepted = 0;
    for (int t = 0; t < 100000; t++) {
        double s = scales[rng() % (sizeof scales / sizeof scales[0])];
        int64_t a = rng_int(1000000000), kk = rng_int(1000000000);
        /* offsets as a writer would compute them from decimal step counts */
        double o1 = (double)a * s, o2 = (double)(a + kk) * s;
        int64_t m = 0, k = 0;
        if (gdt_cloud_lattice_relation(s, o2, s, o1, &m, &k)) {
            accepted++;
            CHECK(m == 1 && k == kk, "s=%g a=%" PRId64 " k=%" PRId64 " got m=%" PRId64
                  " k=%" PRId64, s, a, kk, m, k);
            /* the two CRS positions agree to far below a step for any int32 X */
            int64_t X = rng_int(INT32_MAX);
            long double p1 = (long double)o2 + (long double)s * (long double)X;
            long double p2 = (long double)o1 + (long double)s * (long double)(X + k);
            CHECK(fabsl(p1 - p2) < 1e-4L * s, "positions differ by %Lg", p1 - p2);
        }
        /* the same pair moved by a third of a step never maps */
        CHECK(!gdt_cloud_lattice_relation(s, o2 + s / 3.0, s, o1, &m, &k),
              "third-step shift accepted: s=%g o1=%.17g o2=%.17g", s, o1, o2);
    }
    /* the noise rule may refuse only pairs with offsets beyond 1e6 steps of
     * 1e-16 relative precision; with |o| <= 1e9 steps nearly all pass */
    CHECK(accepted > 99000, "only %d of 100000 exact shifts recognised", accepted);
}

static gdt_source_info crs_info(int epsg, const char *wkt, int geographic, const char *desc)
{
    gdt_source_info in;
    memset(&in, 0, sizeof in);
    in.epsg = epsg;
    in.crs_wkt = wkt;
    in.crs_geographic = geographic;
    in.crs_desc = desc;
    return in;
}

static void test_crs(void)
{
    const char *w1 = "PROJCS[\"NAD83 / Oregon GIC\",GEOGCS[\"NAD83\",DATUM[\"North_American_"
                     "Datum_1983\",SPHEROID[\"GRS 1980\",6378137,298.257222101],"
                     "TOWGS84[0,0,0,0,0,0,0]]],UNIT[\"foot\",0.3048]]";
    const char *w1s = "PROJCS[ \"NAD83 / Oregon GIC\" ,\n  GEOGCS[\"NAD83\", DATUM[\"North_"
                      "American_Datum_1983\", SPHEROID[\"GRS 1980\",6378137,298.257222101],"
                      " TOWGS84[0,0,0,0,0,0,0]]], UNIT[\"foot\",0.3048]]";
    const char *w1q = "PROJCS[\"NAD83 / Oregon  GIC\",GEOGCS[\"NAD83\",DATUM[\"North_American_"
                      "Datum_1983\",SPHEROID[\"GRS 1980\",6378137,298.257222101],"
                      "TOWGS84[0,0,0,0,0,0,0]]],UNIT[\"foot\",0.3048]]";
    const char *wg = "GEOGCS[\"WGS 84\",DATUM[\"WGS_1984\",SPHEROID[\"WGS 84\",6378137,"
                     "298.257223563]],PRIMEM[\"Greenwich\",0],UNIT[\"degree\",0.0174532925199433]]";
    const char *wn = "GEOGCS[\"NAD83\",DATUM[\"North_American_Datum_1983\",SPHEROID[\"GRS 1980\","
                     "6378137,298.257222101],TOWGS84[0,0,0,0,0,0,0]],UNIT[\"degree\",0.01745]]";
    gdt_source_info u = crs_info(0, NULL, 0, "unknown"), e0 = crs_info(0, NULL, 0, "");
    gdt_source_info a = crs_info(32610, NULL, 0, "EPSG:32610");
    gdt_source_info b = crs_info(32611, NULL, 0, "EPSG:32611");
    gdt_source_info a2 = crs_info(32610, w1, 0, "EPSG:32610");
    gdt_source_info g = crs_info(4326, NULL, 1, "EPSG:4326");
    gdt_source_info x1 = crs_info(0, w1, 0, "WKT: NAD83 / Oregon GIC");
    gdt_source_info x2 = crs_info(0, w1s, 0, "WKT: NAD83 / Oregon GIC");
    gdt_source_info x3 = crs_info(0, w1q, 0, "WKT: NAD83 / Oregon  GIC");
    gdt_source_info gw = crs_info(0, wg, 1, "WKT: WGS 84");
    gdt_source_info gn = crs_info(0, wn, 1, "WKT: NAD83");
    gdt_source_info g4269 = crs_info(4269, NULL, 1, "EPSG:4269");
    gdt_source_info cit = crs_info(0, NULL, 0, "GeoTIFF: NAD83 / somewhere");
    gdt_source_info pcd = crs_info(0, NULL, 0, "unknown (PCD has no CRS)");
    pcd.format = GDT_FORMAT_PCD;

    CHECK(!gdt_cloud_crs_known(&u) && !gdt_cloud_crs_known(&e0) && !gdt_cloud_crs_known(&cit) &&
              !gdt_cloud_crs_known(&pcd), "unknown CRS");
    CHECK(gdt_cloud_crs_compare(&pcd, &g) == GDT_CRS_UNKNOWN, "PCD vs geographic");
    CHECK(gdt_cloud_crs_known(&a) && gdt_cloud_crs_known(&x1) && gdt_cloud_crs_known(&g), "known");
    CHECK(gdt_cloud_crs_compare(&u, &a) == GDT_CRS_UNKNOWN, "unknown vs EPSG");
    CHECK(gdt_cloud_crs_compare(&g, &e0) == GDT_CRS_UNKNOWN, "geographic vs unknown");
    CHECK(gdt_cloud_crs_compare(&a, &a2) == GDT_CRS_SAME, "same EPSG, one with WKT");
    CHECK(gdt_cloud_crs_compare(&a, &b) == GDT_CRS_DIFFERENT, "different EPSG");
    CHECK(gdt_cloud_crs_compare(&a, &g) == GDT_CRS_KIND, "projected vs geographic");
    CHECK(gdt_cloud_crs_compare(&g, &x1) == GDT_CRS_KIND, "geographic vs projected WKT");
    CHECK(gdt_cloud_crs_compare(&x1, &x2) == GDT_CRS_SAME, "WKT up to white space");
    CHECK(gdt_cloud_crs_compare(&x1, &x3) == GDT_CRS_DIFFERENT, "space inside a quoted name");
    CHECK(gdt_cloud_crs_compare(&a, &x1) == GDT_CRS_UNDECIDABLE, "EPSG vs WKT only");
    CHECK(gdt_cloud_crs_compare(&g, &g4269) == GDT_CRS_DIFFERENT, "4326 vs 4269");
    CHECK(gdt_cloud_crs_is_wgs84(&g) && gdt_cloud_crs_is_wgs84(&gw), "WGS 84");
    CHECK(!gdt_cloud_crs_is_wgs84(&gn), "NAD83 WKT with TOWGS84 is not WGS 84");
    CHECK(!gdt_cloud_crs_is_wgs84(&g4269), "EPSG:4269 is not WGS 84");
    CHECK(!gdt_cloud_crs_is_wgs84(&u), "unknown is not WGS 84");
}

static void test_policy_names(void)
{
    gdt_dup_policy p = GDT_DUP_MAX_Z;
    CHECK(gdt_dup_policy_parse("first", &p) == 0 && p == GDT_DUP_FIRST, "first");
    CHECK(gdt_dup_policy_parse("min-z", &p) == 0 && p == GDT_DUP_MIN_Z, "min-z");
    CHECK(gdt_dup_policy_parse("max-z", &p) == 0 && p == GDT_DUP_MAX_Z, "max-z");
    CHECK(gdt_dup_policy_parse("maxz", &p) != 0 && gdt_dup_policy_parse("", &p) != 0 &&
              gdt_dup_policy_parse(NULL, &p) != 0, "refusals");
    CHECK(strcmp(gdt_dup_policy_name(GDT_DUP_MIN_Z), "min-z") == 0, "name");
}

int main(void)
{
    test_snap_half_even();
    test_snap_random();
    test_snap_refusals();
    test_relation_cases();
    test_relation_random();
    test_crs();
    test_policy_names();
    return gdt_check_finish(&checks, "test_cloud_lattice");
}
