/* Unit tests of the LAS CRS interpretation (io/private/las_crs.c): GeoTIFF
 * key directories and WKT strings, well-formed and hostile. */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "gdt_check.h"
#include "private/las_crs.h"

static gdt_checks checks;

#define CHECK(cond) GDT_CHECK(&checks, cond, "%s", "")

/* Builds a key directory of n entries (4 words each) into out (little-endian). */
static size_t put_words(unsigned char *out, const unsigned *w, size_t nwords)
{
    for (size_t k = 0; k < nwords; k++) {
        out[2 * k] = (unsigned char)(w[k] & 0xff);
        out[2 * k + 1] = (unsigned char)(w[k] >> 8);
    }
    return 2 * nwords;
}

static void test_geokeys_projected(void)
{
    const unsigned w[] = {1,  1, 0,    4,     1024, 0,  1,    1, 1026, 34737,
                          22, 0, 2049, 34737, 7,    22, 3072, 0, 1,    32617};
    const char ascii[] = "WGS 84 / UTM zone 17N|WGS 84|";
    unsigned char dir[64];
    size_t n = put_words(dir, w, sizeof w / sizeof w[0]);
    gdt_las_geokeys k;
    gdt_las_crs crs;

    gdt_las_geokeys_parse(dir, n, ascii, sizeof ascii - 1, &k);
    CHECK(k.present && !k.malformed);
    CHECK(k.model == 1 && k.projected_code == 32617 && k.geographic_code == 0);
    CHECK(strcmp(k.citation, "WGS 84 / UTM zone 17N") == 0);
    gdt_las_crs_resolve(&k, NULL, 0, 0, &crs);
    CHECK(crs.epsg == 32617 && !crs.geographic);
    CHECK(strcmp(crs.desc, "EPSG:32617") == 0);
}

static void test_geokeys_geographic(void)
{
    const unsigned w[] = {1, 1, 0, 3, 1024, 0, 1, 2, 1025, 0, 1, 1, 2048, 0, 1, 4326};
    unsigned char dir[64];
    size_t n = put_words(dir, w, sizeof w / sizeof w[0]);
    gdt_las_geokeys k;
    gdt_las_crs crs;

    gdt_las_geokeys_parse(dir, n, NULL, 0, &k);
    gdt_las_crs_resolve(&k, NULL, 0, 0, &crs);
    CHECK(crs.epsg == 4326 && crs.geographic == 1);
    CHECK(strcmp(crs.desc, "EPSG:4326") == 0);

    /* Model type projected but only a geographic code: not lon/lat, no code. */
    const unsigned w2[] = {1, 1, 0, 2, 1024, 0, 1, 1, 2048, 0, 1, 4269};
    n = put_words(dir, w2, sizeof w2 / sizeof w2[0]);
    gdt_las_geokeys_parse(dir, n, NULL, 0, &k);
    gdt_las_crs_resolve(&k, NULL, 0, 0, &crs);
    CHECK(crs.epsg == 0 && crs.geographic == 0);
    CHECK(strcmp(crs.desc, "GeoTIFF keys (user-defined)") == 0);
}

static void test_geokeys_hostile(void)
{
    /* Claims 1000 keys but holds one; citation outside the ASCII params. */
    const unsigned w[] = {1, 1, 0, 1000, 3072, 0, 1, 26910, 3073, 34737, 500, 10};
    unsigned char dir[64];
    size_t n = put_words(dir, w, sizeof w / sizeof w[0]);
    gdt_las_geokeys k;

    gdt_las_geokeys_parse(dir, n, "abc|", 4, &k);
    CHECK(k.present && k.malformed);
    CHECK(k.projected_code == 26910);
    CHECK(k.citation[0] == '\0');

    /* Too short for its own header, and an odd byte count. */
    gdt_las_geokeys_parse(dir, 7, NULL, 0, &k);
    CHECK(!k.present);
    gdt_las_geokeys_parse(dir, 0, NULL, 0, &k);
    CHECK(!k.present);

    /* A user-defined projected CRS falls back to the citation. */
    const unsigned w2[] = {1, 1, 0, 2, 3072, 0, 1, 32767, 3073, 34737, 5, 0};
    n = put_words(dir, w2, sizeof w2 / sizeof w2[0]);
    gdt_las_geokeys_parse(dir, n, "Local|", 6, &k);
    gdt_las_crs crs;
    gdt_las_crs_resolve(&k, NULL, 0, 0, &crs);
    CHECK(crs.epsg == 0 && strcmp(crs.desc, "GeoTIFF: Local") == 0);
}

static void inspect(const char *wkt, gdt_las_wkt_facts *f, int expect_rc)
{
    int rc = gdt_las_wkt_inspect(wkt, strlen(wkt), f);
    GDT_CHECK(&checks, rc == expect_rc, "inspect(%s) returned %d, expected %d", wkt, rc,
              expect_rc);
}

static void test_wkt(void)
{
    gdt_las_wkt_facts f;

    inspect("GEOGCS[\"WGS 84\",DATUM[\"WGS_1984\",SPHEROID[\"WGS 84\",6378137,298.257223563,"
            "AUTHORITY[\"EPSG\",\"7030\"]],AUTHORITY[\"EPSG\",\"6326\"]],PRIMEM[\"Greenwich\",0],"
            "UNIT[\"degree\",0.0174532925199433],AUTHORITY[\"EPSG\",\"4326\"]]",
            &f, 0);
    CHECK(f.kind == GDT_LAS_WKT_GEOGRAPHIC && f.epsg == 4326 && strcmp(f.name, "WGS 84") == 0);

    /* The datum's authority is nested: it must not be taken for the CRS's. */
    inspect("PROJCS[\"NAD83 / UTM zone 10N\",GEOGCS[\"NAD83\",AUTHORITY[\"EPSG\",\"4269\"]],"
            "PROJECTION[\"Transverse_Mercator\"],AUTHORITY[\"EPSG\",\"26910\"]]",
            &f, 0);
    CHECK(f.kind == GDT_LAS_WKT_PROJECTED && f.epsg == 26910);
    CHECK(strcmp(f.name, "NAD83 / UTM zone 10N") == 0);

    inspect("PROJCS[\"Custom\",GEOGCS[\"NAD83\",AUTHORITY[\"EPSG\",\"4269\"]]]", &f, 0);
    CHECK(f.kind == GDT_LAS_WKT_PROJECTED && f.epsg == 0);

    /* Compound: horizontal part decides. */
    inspect("COMPD_CS[\"WGS 84 + EGM96\",GEOGCS[\"WGS 84\",AUTHORITY[\"EPSG\",\"4326\"]],"
            "VERT_CS[\"EGM96\",AUTHORITY[\"EPSG\",\"5773\"]]]",
            &f, 0);
    CHECK(f.kind == GDT_LAS_WKT_GEOGRAPHIC && f.epsg == 4326);
    CHECK(strcmp(f.name, "WGS 84 + EGM96") == 0);

    /* WKT2 */
    inspect("GEOGCRS[\"WGS 84\",DATUM[\"World Geodetic System 1984\"],CS[ellipsoidal,2],"
            "ID[\"EPSG\",4326]]",
            &f, 0);
    CHECK(f.kind == GDT_LAS_WKT_GEOGRAPHIC && f.epsg == 4326);
    inspect("GEODCRS[\"WGS 84\",CS[ellipsoidal,2],ID[\"EPSG\",4326]]", &f, 0);
    CHECK(f.kind == GDT_LAS_WKT_GEOGRAPHIC);
    inspect("GEODCRS[\"WGS 84 (geocentric)\",CS[Cartesian,3],ID[\"EPSG\",4978]]", &f, 0);
    CHECK(f.kind == GDT_LAS_WKT_GEOCENTRIC);
    inspect("PROJCRS[\"WGS 84 / UTM zone 31N\",BASEGEOGCRS[\"WGS 84\",ID[\"EPSG\",4326]],"
            "CS[Cartesian,2],ID[\"EPSG\",32631]]",
            &f, 0);
    CHECK(f.kind == GDT_LAS_WKT_PROJECTED && f.epsg == 32631);
    inspect("BOUNDCRS[SOURCECRS[GEOGCRS[\"NAD27\",CS[ellipsoidal,2],ID[\"EPSG\",4267]]],"
            "TARGETCRS[GEOGCRS[\"WGS 84\"]]]",
            &f, 0);
    CHECK(f.kind == GDT_LAS_WKT_GEOGRAPHIC && f.epsg == 4267);
    /* Parentheses, spaces, escaped quotes. */
    inspect("  GEOGCS ( \"a \"\"b\"\" (c]\" , AUTHORITY(\"epsg\", \"4326\") )", &f, 0);
    CHECK(f.kind == GDT_LAS_WKT_GEOGRAPHIC && f.epsg == 4326);

    /* Hostile or broken text. */
    inspect("", &f, -1);
    inspect("GEOGCS[\"WGS 84\"", &f, -1);
    inspect("GEOGCS[\"unterminated]", &f, -1);
    inspect("]]]][[[", &f, -1);
    inspect("\"just a string\"", &f, -1);
    inspect("LOCAL_CS[\"x\"]", &f, 0);
    CHECK(f.kind == GDT_LAS_WKT_UNKNOWN);
    inspect("GEOGCS[\"x\",AUTHORITY[\"EPSG\",\"99999999999999\"]]", &f, 0);
    CHECK(f.kind == GDT_LAS_WKT_GEOGRAPHIC && f.epsg == 0);

    /* The text ends at the first NUL (payloads are NUL-padded). */
    {
        const char padded[] = "GEOGCS[\"p\",AUTHORITY[\"EPSG\",\"4326\"]]\0\0garbage[";
        CHECK(gdt_las_wkt_inspect(padded, sizeof padded, &f) == 0 && f.epsg == 4326);
    }
    /* Not NUL-terminated: must not read past len. */
    {
        char *buf = malloc(8);
        if (buf != NULL) {
            memcpy(buf, "GEOGCS[\"", 8);
            CHECK(gdt_las_wkt_inspect(buf, 8, &f) == -1);
            free(buf);
        }
    }
    /* Deep nesting of compound CRSs: bounded, no crash. */
    {
        enum { DEPTH = 20000 };
        size_t cap = (size_t)DEPTH * 11 + 64;
        char *deep = malloc(cap);
        if (deep != NULL) {
            size_t n = 0;
            for (int d = 0; d < DEPTH; d++) {
                memcpy(deep + n, "COMPD_CS[", 9);
                n += 9;
            }
            memcpy(deep + n, "GEOGCS[\"g\"]", 11);
            n += 11;
            for (int d = 0; d < DEPTH; d++)
                deep[n++] = ']';
            CHECK(gdt_las_wkt_inspect(deep, n, &f) == 0);
            CHECK(f.kind == GDT_LAS_WKT_UNKNOWN);
            free(deep);
        }
    }
}

static void test_resolve(void)
{
    const char *geo = "GEOGCS[\"WGS 84\",AUTHORITY[\"EPSG\",\"4326\"]]";
    const char *proj = "PROJCS[\"NAD_1983_HARN_Lambert_Conformal_Conic\",GEOGCS[\"x\"]]";
    const unsigned w[] = {1, 1, 0, 2, 1024, 0, 1, 1, 3072, 0, 1, 32767};
    unsigned char dir[64];
    size_t n = put_words(dir, w, sizeof w / sizeof w[0]);
    gdt_las_geokeys k;
    gdt_las_crs crs;

    gdt_las_crs_resolve(NULL, NULL, 0, 0, &crs);
    CHECK(crs.epsg == 0 && !crs.geographic && strcmp(crs.desc, "unknown") == 0);
    /* User-defined keys: the WKT says more. */
    gdt_las_geokeys_parse(dir, n, NULL, 0, &k);
    gdt_las_crs_resolve(&k, proj, strlen(proj), 0, &crs);
    CHECK(crs.epsg == 0 && !crs.geographic);
    CHECK(strcmp(crs.desc, "WKT: NAD_1983_HARN_Lambert_Conformal_Conic") == 0);
    /* Keys with a code win unless the WKT is authoritative. */
    const unsigned w2[] = {1, 1, 0, 2, 1024, 0, 1, 1, 3072, 0, 1, 26910};
    n = put_words(dir, w2, sizeof w2 / sizeof w2[0]);
    gdt_las_geokeys_parse(dir, n, NULL, 0, &k);
    gdt_las_crs_resolve(&k, geo, strlen(geo), 0, &crs);
    CHECK(crs.epsg == 26910 && !crs.geographic);
    gdt_las_crs_resolve(&k, geo, strlen(geo), 1, &crs);
    CHECK(crs.epsg == 4326 && crs.geographic);
    gdt_las_crs_resolve(NULL, "%%%", 3, 1, &crs);
    CHECK(crs.epsg == 0 && strcmp(crs.desc, "WKT (unrecognised)") == 0);
}

int main(void)
{
    test_geokeys_projected();
    test_geokeys_geographic();
    test_geokeys_hostile();
    test_wkt();
    test_resolve();
    return gdt_check_finish(&checks, "test_las_crs");
}
