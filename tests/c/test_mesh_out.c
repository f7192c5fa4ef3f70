/* test_mesh_out — unit test of the mesh writer's text formats (gdt_mesh_out.h).
 *
 *   test_mesh_out WORKDIR
 *
 * Checks, in a fresh folder under WORKDIR:
 *  - numbers: for special values and 200000 seeded random bit patterns, the
 *    text reads back (strtod) as the very same double, bit for bit, and is
 *    the first of %.15g, %.16g, %.17g that does (so never longer than
 *    needed), with '.' as decimal point; known shortest forms by hand;
 *  - the exact bytes of a small OBJ, and the structure of the same LandXML
 *    (namespace, Units, CoordinateSystem, northing easting elevation,
 *    1-based faces);
 *  - the .prj: the input's WKT as given, WKT made for a UTM code, none (and
 *    a stale one removed) for a code without WKT, a .prj path that is a
 *    directory refused at create with nothing left behind;
 *  - sticky errors: a misuse, and a write failure (RLIMIT_FSIZE), fail every
 *    later call with the first error, and leave neither the file nor a
 *    temporary;
 *  - the bytes do not depend on LC_NUMERIC (a comma-decimal locale, made
 *    with localedef in the work folder when none is installed; skipped with
 *    a note when that is impossible);
 *  - the format follows the extension, case-insensitively;
 *  - the linear unit of WKT 1 and WKT 2 strings (foot, US survey foot,
 *    metre; the base CRS's degree ignored), and hostile WKT (unbalanced
 *    brackets, open quotes) read without fault;
 *  - pyproj-independent facts of the WKT made for UTM codes (name, central
 *    meridian, false northing; tests/python checks them against pyproj).
 */
#include <dirent.h>
#include <errno.h>
#include <inttypes.h>
#include <locale.h>
#include <math.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <unistd.h>

#include "gdt_check.h"
#include "gdt_mesh_out.h"
#include "private/mesh_crs.h"

typedef struct tctx {
    char dir[4096];
    gdt_checks c;
} tctx;

#define CHECK(t, cond, ...) GDT_CHECK(&(t)->c, cond, __VA_ARGS__)

static void path_in(const tctx *t, char *out, size_t size, const char *name)
{
    snprintf(out, size, "%s/%s", t->dir, name);
}

static int exists(const char *p)
{
    struct stat sb;
    return lstat(p, &sb) == 0;
}

/* Entries of the work folder whose name contains ".tmp-". */
static int count_temps(const tctx *t)
{
    int n = 0;
    struct dirent *e;
    DIR *d = opendir(t->dir);
    if (d == NULL)
        return -1;
    while ((e = readdir(d)) != NULL)
        if (strstr(e->d_name, ".tmp-") != NULL)
            n++;
    closedir(d);
    return n;
}

static char *slurp(const char *p, size_t *n)
{
    FILE *f = fopen(p, "rb");
    char *buf = NULL;
    long len;
    *n = 0;
    if (f == NULL)
        return NULL;
    if (fseek(f, 0, SEEK_END) == 0 && (len = ftell(f)) >= 0 && fseek(f, 0, SEEK_SET) == 0) {
        buf = malloc((size_t)len + 1);
        if (buf != NULL && fread(buf, 1, (size_t)len, f) == (size_t)len) {
            buf[len] = '\0';
            *n = (size_t)len;
        } else {
            free(buf);
            buf = NULL;
        }
    }
    fclose(f);
    return buf;
}

static uint64_t bits_of(double d)
{
    uint64_t b;
    memcpy(&b, &d, sizeof b);
    return b;
}

static gdt_mesh_meta plain_meta(void)
{
    gdt_mesh_meta m;
    memset(&m, 0, sizeof m);
    m.lattice.sx = m.lattice.sy = 0.01;
    m.lattice.ox = 480000.0;
    m.lattice.oy = 4860000.0;
    m.stamp = 1700000000; /* 2023-11-14 22:13:20 UTC */
    return m;
}

/* ---- numbers ------------------------------------------------------------ */

/* The oracle: the first precision of 15..17 whose %g text strtod maps back
 * to d (the C locale is current here). */
static void first_roundtrip(char *out, size_t cap, double d)
{
    for (int p = 15; p <= 17; p++) {
        snprintf(out, cap, "%.*g", p, d);
        if (strtod(out, NULL) == d)
            return;
    }
}

static void check_number(tctx *t, double d, unsigned long *bad)
{
    char got[64], want[64];
    size_t n = gdt_mesh_format_double(got, sizeof got, d);
    first_roundtrip(want, sizeof want, d);
    if (n == 0 || n != strlen(got) || bits_of(strtod(got, NULL)) != bits_of(d) ||
        strcmp(got, want) != 0 || strchr(got, ',') != NULL) {
        if (++*bad <= 5)
            CHECK(t, 0, "%.17g (bits %016" PRIx64 "): got \"%s\", expected \"%s\"", d, bits_of(d),
                  got, want);
    }
}

static void test_numbers(tctx *t)
{
    static const double special[] = {0.0,
                                     -0.0,
                                     0.1,
                                     1.0 / 3.0,
                                     2.0 / 3.0,
                                     190.64000000000001,
                                     480017.75,
                                     4860019.14,
                                     5e-324,
                                     2.2250738585072014e-308,
                                     1.7976931348623157e308,
                                     -1.7976931348623157e308,
                                     9007199254740993.0,
                                     123456789012345678.0,
                                     1e21,
                                     1e-7,
                                     0.30000000000000004};
    static const struct {
        double d;
        const char *text;
    } known[] = {
        {0.1, "0.1"},
        {1.0 / 3.0, "0.3333333333333333"},
        {0.30000000000000004, "0.30000000000000004"},
        {-0.0, "-0"},
        {480017.75, "480017.75"},
        {5e-324, "4.94065645841247e-324"},
        {1e21, "1e+21"},
    };
    uint64_t seed = 12345;
    unsigned long bad = 0;
    char buf[64];

    for (size_t i = 0; i < sizeof special / sizeof special[0]; i++)
        check_number(t, special[i], &bad);
    for (size_t i = 0; i < sizeof known / sizeof known[0]; i++) {
        size_t n = gdt_mesh_format_double(buf, sizeof buf, known[i].d);
        CHECK(t, n > 0 && strcmp(buf, known[i].text) == 0, "%.17g: \"%s\", expected \"%s\"",
              known[i].d, buf, known[i].text);
    }
    /* the 19064 * 0.01 of a LAS z: not the double nearest 190.64 */
    {
        double z = 19064 * 0.01;
        gdt_mesh_format_double(buf, sizeof buf, z);
        CHECK(t, bits_of(strtod(buf, NULL)) == bits_of(z) && strcmp(buf, "190.64") != 0,
              "19064 * 0.01 written as %s", buf);
    }
    for (int i = 0; i < 200000; i++) {
        uint64_t b = gdt_splitmix64(&seed);
        double d;
        if (i % 4 == 1) /* lattice-like values: offset + scale * integer */
            d = 480000.0 + 0.01 * (double)(int64_t)(b % 100000000);
        else if (i % 4 == 2)
            d = (double)(int64_t)(b >> 11) * 0x1p-20;
        else
            memcpy(&d, &b, sizeof d);
        if (!isfinite(d))
            continue;
        check_number(t, d, &bad);
    }
    /* the integer-arithmetic range 1e-4 <= |d| < 1e14 and its edges: every
     * scale a LAS or PCD lattice uses, offsets, powers of ten and of two
     * and their neighbours, log-uniform magnitudes */
    {
        static const double steps[] = {1e-7, 1e-4, 0.001, 0.01, 0.025, 0.1, 0.25, 1.0 / 3.0};
        static const double offsets[] = {0.0, -1000.0, 480000.0, 4860000.0, 1e13, 123.456};
        for (int i = 0; i < 400000; i++) {
            uint64_t b = gdt_splitmix64(&seed);
            double d;
            switch (i % 5) {
            case 0:
                d = offsets[(b >> 3) % 6] +
                    steps[b % 8] * (double)(int64_t)((b >> 8) % 2000000001 - 1000000000);
                break;
            case 1: /* log-uniform over the range and a decade beyond each end */
                d = pow(10.0, -5.0 + 20.0 * (double)(b >> 11) * 0x1p-53);
                break;
            case 2: { /* 10^e and 2^e and their neighbours */
                int e = (int)(b % 40) - 20;
                double base = (b >> 6) & 1 ? pow(10.0, e) : ldexp(1.0, e * 2);
                int steps_away = (int)((b >> 7) % 5) - 2;
                d = base;
                for (int s = 0; s < steps_away; s++)
                    d = nextafter(d, INFINITY);
                for (int s = 0; s > steps_away; s--)
                    d = nextafter(d, 0.0);
                break;
            }
            case 3: /* short decimals and their neighbours */
                d = (double)(int64_t)(b % 100000000) / pow(10.0, (double)((b >> 40) % 12));
                if ((b >> 60) & 1)
                    d = nextafter(d, (b >> 61) & 1 ? INFINITY : 0.0);
                break;
            default: /* decimals rounding up to the next power of ten */
                d = pow(10.0, (double)((int)(b % 18) - 4)) *
                    (1.0 - (double)((b >> 8) % 1000) * 1e-17);
                break;
            }
            if ((b >> 62) & 1)
                d = -d;
            if (isfinite(d))
                check_number(t, d, &bad);
        }
    }
    CHECK(t, bad == 0, "%lu numbers failed", bad);
    CHECK(t, gdt_mesh_format_double(buf, sizeof buf, NAN) == 0, "NaN formatted");
    CHECK(t, gdt_mesh_format_double(buf, sizeof buf, INFINITY) == 0, "inf formatted");
}

/* ---- formats and paths -------------------------------------------------- */

static void test_format_of(tctx *t)
{
    static const struct {
        const char *path;
        gdt_mesh_format f;
    } cases[] = {
        {"a.obj", GDT_MESH_OBJ},     {"A.OBJ", GDT_MESH_OBJ},        {"d/x.Obj", GDT_MESH_OBJ},
        {"a.xml", GDT_MESH_LANDXML}, {"b.XmL", GDT_MESH_LANDXML},    {"a.ply", GDT_MESH_PLY},
        {"a.obj.ply", GDT_MESH_PLY}, {"dir.obj/mesh", GDT_MESH_PLY}, {"mesh", GDT_MESH_PLY},
        {".obj", GDT_MESH_PLY},      {"a.objx", GDT_MESH_PLY},       {"a.stl", GDT_MESH_PLY},
    };
    char *p;
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++)
        CHECK(t, gdt_mesh_format_of(cases[i].path) == cases[i].f, "%s: format %d", cases[i].path,
              (int)gdt_mesh_format_of(cases[i].path));
    CHECK(t, gdt_mesh_format_of(NULL) == GDT_MESH_PLY, "NULL path");
    p = gdt_mesh_prj_path("d.v/x.OBJ", GDT_MESH_OBJ);
    CHECK(t, p != NULL && strcmp(p, "d.v/x.prj") == 0, "prj of d.v/x.OBJ: %s", p ? p : "NULL");
    free(p);
    p = gdt_mesh_prj_path("x.xml", GDT_MESH_LANDXML);
    CHECK(t, p == NULL, "a LandXML has no .prj");
    free(p);
}

/* A unit square split into two CCW triangles, plus a centre point. */
static const double SQ_XYZ[3 * 5] = {
    480000.0, 4860000.0, 10.5,      480001.0, 4860000.0, 11.0,      480001.0,          4860001.0,
    0.1,      480000.0,  4860001.0, -2.25,    480000.5,  4860000.5, 190.64000000000001};
static const int32_t SQ_TRI[3 * 4] = {0, 1, 4, 1, 2, 4, 2, 3, 4, 3, 0, 4};

static gdt_status write_square(const char *path, gdt_mesh_format f, const gdt_mesh_meta *m,
                               gdt_error *err)
{
    gdt_mesh_writer *w = NULL;
    gdt_status st = gdt_mesh_create(&w, path, f, m, err);
    if (st == GDT_OK)
        st = gdt_mesh_write_vertices(w, SQ_XYZ, 2, err);
    if (st == GDT_OK)
        st = gdt_mesh_write_vertices(w, SQ_XYZ + 6, 3, err);
    if (st == GDT_OK)
        st = gdt_mesh_write_faces(w, SQ_TRI, 1, err);
    if (st == GDT_OK)
        st = gdt_mesh_write_faces(w, SQ_TRI + 3, 3, err);
    if (st != GDT_OK) {
        gdt_mesh_abort(w);
        return st;
    }
    return gdt_mesh_finish(w, err);
}

static const char OBJ_EXPECTED_BODY[] =
    "# lattice 0.01 0.01 480000 4860000\n"
    "# filter classes all returns all withheld drop\n"
    "# vertices (v x y z), then faces (f a b c: 1-based, counter-clockwise)\n"
    "v 480000 4860000 10.5\n"
    "v 480001 4860000 11\n"
    "v 480001 4860001 0.1\n"
    "v 480000 4860001 -2.25\n"
    "v 480000.5 4860000.5 190.64000000000001\n"
    "f 1 2 5\n"
    "f 2 3 5\n"
    "f 3 4 5\n"
    "f 4 1 5\n"
    "# 5 vertices, 4 faces\n";

static void test_obj(tctx *t)
{
    static const char *const comments[] = {"filter classes all returns all withheld drop"};
    char path[4200], prj[4200], expect[2048];
    gdt_mesh_meta m = plain_meta();
    gdt_error err;
    char *got, *p;
    size_t n;

    m.comments = comments;
    m.ncomments = 1;
    m.epsg = 32633;
    path_in(t, path, sizeof path, "sq.obj");
    path_in(t, prj, sizeof prj, "sq.prj");
    gdt_error_clear(&err);
    CHECK(t, write_square(path, GDT_MESH_OBJ, &m, &err) == GDT_OK, "write: %s", err.msg);
    snprintf(expect, sizeof expect, "# gdt-tile %s TIN (Wavefront OBJ)\n# crs EPSG:32633\n%s",
             GDT_TEST_VERSION, OBJ_EXPECTED_BODY);
    got = slurp(path, &n);
    CHECK(t, got != NULL && strcmp(got, expect) == 0, "OBJ differs:\n%s\nexpected:\n%s",
          got ? got : "(none)", expect);
    free(got);
    p = slurp(prj, &n);
    CHECK(t,
          p != NULL && strncmp(p, "PROJCS[\"WGS 84 / UTM zone 33N\",GEOGCS[\"WGS 84\"", 45) == 0 &&
              strstr(p, "PARAMETER[\"central_meridian\",15]") != NULL &&
              strstr(p, "AUTHORITY[\"EPSG\",\"32633\"]]\n") != NULL,
          "prj: %s", p ? p : "(none)");
    free(p);

    /* the input's own WKT, as given (line breaks kept in the .prj) */
    m.epsg = 0;
    m.crs_wkt = "PROJCS[\"Custom\",\n UNIT[\"metre\",1]]";
    gdt_error_clear(&err);
    CHECK(t, write_square(path, GDT_MESH_OBJ, &m, &err) == GDT_OK, "write: %s", err.msg);
    p = slurp(prj, &n);
    CHECK(t, p != NULL && strcmp(p, "PROJCS[\"Custom\",\n UNIT[\"metre\",1]]\n") == 0, "prj: %s",
          p ? p : "(none)");
    free(p);
    got = slurp(path, &n);
    CHECK(t, got != NULL && strstr(got, "# crs PROJCS[\"Custom\",  UNIT[\"metre\",1]]\n") != NULL,
          "OBJ crs line: %s", got ? got : "(none)");
    free(got);

    /* an EPSG code without WKT: no .prj, and the earlier one is gone */
    m.crs_wkt = NULL;
    m.epsg = 2227;
    gdt_error_clear(&err);
    CHECK(t, exists(prj), "no .prj before the stale test");
    CHECK(t, write_square(path, GDT_MESH_OBJ, &m, &err) == GDT_OK, "write: %s", err.msg);
    CHECK(t, !exists(prj), "a stale .prj was left beside the new OBJ");
    CHECK(t, exists(path), "OBJ missing");
    CHECK(t, count_temps(t) == 0, "temporaries left");

    /* the .prj path is a directory: refused at create, nothing written */
    unlink(path);
    CHECK(t, mkdir(prj, 0755) == 0, "mkdir %s", prj);
    m.epsg = 32633;
    gdt_error_clear(&err);
    CHECK(t, write_square(path, GDT_MESH_OBJ, &m, &err) == GDT_EIO && err.code == 4010,
          "prj directory: %d %d %s", (int)err.status, err.code, err.msg);
    CHECK(t, !exists(path) && count_temps(t) == 0, "files left after the refusal");
    rmdir(prj);
}

static void test_xml(tctx *t)
{
    char path[4200];
    gdt_mesh_meta m = plain_meta();
    gdt_error err;
    char *got;
    size_t n;

    m.epsg = 2227;
    m.crs_wkt = "PROJCS[\"NAD83 / California zone 3 (ftUS)\",GEOGCS[\"NAD83\",UNIT[\"degree\","
                "0.0174532925199433]],UNIT[\"US survey foot\",0.304800609601219]]";
    path_in(t, path, sizeof path, "Surf&1.XML");
    gdt_error_clear(&err);
    CHECK(t, write_square(path, GDT_MESH_LANDXML, &m, &err) == GDT_OK, "write: %s", err.msg);
    got = slurp(path, &n);
    CHECK(t, got != NULL, "no LandXML");
    if (got == NULL)
        return;
    CHECK(t, strncmp(got, "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n", 39) == 0, "prolog");
    CHECK(t, strstr(got, "<LandXML xmlns=\"http://www.landxml.org/schema/LandXML-1.2\"") != NULL,
          "namespace");
    CHECK(t, strstr(got, "version=\"1.2\" date=\"2023-11-14\" time=\"22:13:20\">") != NULL,
          "date and time from the stamp");
    CHECK(t,
          strstr(got, "<Units><Imperial areaUnit=\"squareFoot\" linearUnit=\"USSurveyFoot\"") !=
              NULL,
          "imperial units for a US survey foot CRS");
    CHECK(t,
          strstr(got, "epsgCode=\"2227\" ogcWktCode=\"PROJCS[&quot;NAD83 / California zone 3 "
                      "(ftUS)&quot;,") != NULL,
          "CoordinateSystem");
    CHECK(t,
          strstr(got, "<Surface name=\"Surf&amp;1\">\n<Definition surfType=\"TIN\">\n<Pnts>\n"
                      "<P id=\"1\">4860000 480000 10.5</P>\n"
                      "<P id=\"2\">4860000 480001 11</P>\n"
                      "<P id=\"3\">4860001 480001 0.1</P>\n"
                      "<P id=\"4\">4860001 480000 -2.25</P>\n"
                      "<P id=\"5\">4860000.5 480000.5 190.64000000000001</P>\n"
                      "</Pnts>\n<Faces>\n<F>1 2 5</F>\n<F>2 3 5</F>\n<F>3 4 5</F>\n"
                      "<F>4 1 5</F>\n</Faces>\n</Definition>\n</Surface>\n</Surfaces>\n"
                      "</LandXML>\n") != NULL,
          "surface:\n%s", got);
    free(got);
    unlink(path);

    /* metric by default (a metre WKT, or no CRS at all) */
    m.crs_wkt = NULL;
    m.epsg = 0;
    gdt_error_clear(&err);
    CHECK(t, write_square(path, GDT_MESH_LANDXML, &m, &err) == GDT_OK, "write: %s", err.msg);
    got = slurp(path, &n);
    CHECK(t,
          got != NULL &&
              strstr(got, "<Units><Metric areaUnit=\"squareMeter\" "
                          "linearUnit=\"meter\"") != NULL &&
              strstr(got, "<CoordinateSystem") == NULL,
          "metric, no CoordinateSystem: %s", got ? got : "(none)");
    free(got);
    unlink(path);
}

/* ---- sticky errors ------------------------------------------------------ */

static void test_sticky(tctx *t)
{
    char path[4200];
    gdt_mesh_meta m = plain_meta();
    gdt_mesh_writer *w = NULL;
    gdt_error err;
    const int32_t bad_tri[3] = {0, 1, 7};

    for (int f = GDT_MESH_OBJ; f <= GDT_MESH_LANDXML; f++) {
        path_in(t, path, sizeof path, f == GDT_MESH_OBJ ? "sticky.obj" : "sticky.xml");
        /* vertices after faces */
        gdt_error_clear(&err);
        CHECK(t, gdt_mesh_create(&w, path, (gdt_mesh_format)f, &m, &err) == GDT_OK, "%s", err.msg);
        CHECK(t, gdt_mesh_write_vertices(w, SQ_XYZ, 5, &err) == GDT_OK, "%s", err.msg);
        CHECK(t, gdt_mesh_write_faces(w, SQ_TRI, 1, &err) == GDT_OK, "%s", err.msg);
        gdt_error_clear(&err);
        CHECK(t, gdt_mesh_write_vertices(w, SQ_XYZ, 1, &err) == GDT_EINTERNAL && err.code == 7713,
              "vertices after faces: %d %s", err.code, err.msg);
        CHECK(t, count_temps(t) == 0, "temporary kept after a failure");
        gdt_error_clear(&err);
        CHECK(t, gdt_mesh_write_faces(w, SQ_TRI, 1, &err) == GDT_EINTERNAL && err.code == 7713,
              "faces after the failure: %d %s", err.code, err.msg);
        gdt_error_clear(&err);
        CHECK(t, gdt_mesh_finish(w, &err) == GDT_EINTERNAL && err.code == 7713,
              "finish after the failure: %d %s", err.code, err.msg);
        CHECK(t, !exists(path) && count_temps(t) == 0, "files left");

        /* an index out of range */
        gdt_error_clear(&err);
        CHECK(t, gdt_mesh_create(&w, path, (gdt_mesh_format)f, &m, &err) == GDT_OK, "%s", err.msg);
        CHECK(t, gdt_mesh_write_vertices(w, SQ_XYZ, 5, &err) == GDT_OK, "%s", err.msg);
        CHECK(t, gdt_mesh_write_faces(w, bad_tri, 1, &err) == GDT_EINTERNAL && err.code == 7714,
              "bad index: %d %s", err.code, err.msg);
        gdt_error_clear(&err);
        CHECK(t, gdt_mesh_finish(w, &err) == GDT_EINTERNAL && err.code == 7714,
              "finish after a bad index: %d %s", err.code, err.msg);
        CHECK(t, !exists(path) && count_temps(t) == 0, "files left");
    }

    /* a write failure (the file size limit) */
    {
        struct rlimit old, lim;
        const size_t nv = 200000;
        double *xyz = malloc(3 * nv * sizeof *xyz);
        gdt_status st = GDT_OK;
        size_t i;
        path_in(t, path, sizeof path, "full.obj");
        CHECK(t, xyz != NULL, "out of memory");
        if (xyz == NULL)
            return;
        for (i = 0; i < 3 * nv; i++)
            xyz[i] = 480000.0 + 0.01 * (double)i;
        signal(SIGXFSZ, SIG_IGN);
        getrlimit(RLIMIT_FSIZE, &old);
        lim = old;
        lim.rlim_cur = 256 * 1024;
        gdt_error_clear(&err);
        CHECK(t, gdt_mesh_create(&w, path, GDT_MESH_OBJ, &m, &err) == GDT_OK, "%s", err.msg);
        CHECK(t, setrlimit(RLIMIT_FSIZE, &lim) == 0, "setrlimit: %s", strerror(errno));
        for (i = 0; i < nv && st == GDT_OK; i += 1000)
            st = gdt_mesh_write_vertices(w, xyz + 3 * i, 1000, &err);
        CHECK(t, st == GDT_EIO && err.code == 4712, "write past the limit: %d %d %s", (int)st,
              err.code, err.msg);
        CHECK(t, count_temps(t) == 0, "temporary kept after the write failure");
        setrlimit(RLIMIT_FSIZE, &old);
        gdt_error_clear(&err);
        CHECK(t, gdt_mesh_write_vertices(w, xyz, 1, &err) == GDT_EIO && err.code == 4712,
              "sticky write: %d %s", err.code, err.msg);
        gdt_error_clear(&err);
        CHECK(t, gdt_mesh_write_faces(w, SQ_TRI, 0, &err) == GDT_EIO && err.code == 4712,
              "sticky faces: %d %s", err.code, err.msg);
        gdt_error_clear(&err);
        CHECK(t, gdt_mesh_finish(w, &err) == GDT_EIO && err.code == 4712, "sticky finish: %d %s",
              err.code, err.msg);
        CHECK(t, !exists(path) && count_temps(t) == 0, "files left after the write failure");
        free(xyz);
    }

    /* abort leaves nothing; a PLY through the same interface */
    path_in(t, path, sizeof path, "aborted.obj");
    gdt_error_clear(&err);
    CHECK(t, gdt_mesh_create(&w, path, GDT_MESH_OBJ, &m, &err) == GDT_OK, "%s", err.msg);
    gdt_mesh_abort(w);
    CHECK(t, !exists(path) && count_temps(t) == 0, "abort left files");
    path_in(t, path, sizeof path, "sq.ply");
    CHECK(t, write_square(path, GDT_MESH_PLY, &m, &err) == GDT_OK, "PLY: %s", err.msg);
    {
        size_t n = 0;
        char *got = slurp(path, &n);
        CHECK(t, got != NULL && strncmp(got, "ply\nformat binary_little_endian 1.0\n", 36) == 0,
              "PLY through gdt_mesh_out");
        free(got);
        unlink(path);
    }
}

/* ---- locale ------------------------------------------------------------- */

/* Makes a comma-decimal LC_NUMERIC current; 1 on success. */
static int comma_locale(const tctx *t)
{
    static const char *const names[] = {"de_DE.UTF-8", "de_DE.utf8", "fr_FR.UTF-8", "nl_NL.UTF-8"};
    char cmd[4600], loc[4200];
    for (int round = 0; round < 2; round++) {
        for (size_t i = 0; i < sizeof names / sizeof names[0]; i++)
            if (setlocale(LC_NUMERIC, names[i]) != NULL) {
                if (localeconv()->decimal_point[0] == ',')
                    return 1;
                setlocale(LC_NUMERIC, "C");
            }
        if (round == 1)
            break;
        /* none installed: make one in the work folder, if localedef can */
        path_in(t, loc, sizeof loc, "locale");
        mkdir(loc, 0755);
        snprintf(cmd, sizeof cmd, "localedef -i de_DE -f UTF-8 '%s/de_DE.UTF-8' >/dev/null 2>&1",
                 loc);
        if (system(cmd) != 0)
            break;
        setenv("LOCPATH", loc, 1);
    }
    return 0;
}

static void test_locale(tctx *t)
{
    char path[4200], cpath[4200];
    gdt_mesh_meta m = plain_meta();
    gdt_error err;
    char *a, *b;
    size_t na, nb;
    char buf[64];

    path_in(t, cpath, sizeof cpath, "c_locale.obj");
    path_in(t, path, sizeof path, "comma_locale.obj");
    gdt_error_clear(&err);
    CHECK(t, write_square(cpath, GDT_MESH_OBJ, &m, &err) == GDT_OK, "%s", err.msg);
    if (!comma_locale(t)) {
        printf("test_mesh_out: no comma-decimal locale could be made; the locale check is "
               "skipped\n");
        unlink(cpath);
        return;
    }
    snprintf(buf, sizeof buf, "%.2f", 1.5);
    CHECK(t, strcmp(buf, "1,50") == 0, "the comma locale is not current (%s)", buf);
    gdt_error_clear(&err);
    CHECK(t, write_square(path, GDT_MESH_OBJ, &m, &err) == GDT_OK, "%s", err.msg);
    CHECK(t, gdt_mesh_format_double(buf, sizeof buf, 0.1) == 3 && strcmp(buf, "0.1") == 0,
          "0.1 in the comma locale: %s", buf);
    setlocale(LC_NUMERIC, "C");
    a = slurp(cpath, &na);
    b = slurp(path, &nb);
    CHECK(t, a != NULL && b != NULL && na == nb && memcmp(a, b, na) == 0,
          "the OBJ depends on LC_NUMERIC:\n%s\nvs\n%s", a ? a : "", b ? b : "");
    free(a);
    free(b);
    unlink(cpath);
    unlink(path);
}

static void test_crs(tctx *t)
{
    static const struct {
        const char *wkt;
        int foot;
    } cases[] = {
        {"PROJCS[\"NAD83 / California zone 3 (ftUS)\",GEOGCS[\"NAD83\",UNIT[\"degree\","
         "0.0174532925199433]],PROJECTION[\"Lambert_Conformal_Conic_2SP\"],"
         "UNIT[\"US survey foot\",0.304800609601219]]",
         2},
        {"PROJCS[\"x\",GEOGCS[\"y\",UNIT[\"degree\",0.01745]],UNIT[\"foot\",0.3048]]", 1},
        {"PROJCS[\"x\",GEOGCS[\"y\",UNIT[\"degree\",0.01745]],UNIT[\"metre\",1]]", 0},
        {"COMPD_CS[\"c\",PROJCS[\"x\",GEOGCS[\"y\",UNIT[\"degree\",1]],UNIT[\"Foot_US\","
         "0.3048006096]],VERT_CS[\"v\",UNIT[\"metre\",1]]]",
         2},
        {"PROJCRS[\"NAD83(2011) / Texas Central (ftUS)\",BASEGEOGCRS[\"NAD83(2011)\","
         "ANGLEUNIT[\"degree\",0.0174532925199433]],CONVERSION[\"c\",METHOD[\"LCC\"],"
         "PARAMETER[\"Latitude\",30,ANGLEUNIT[\"degree\",0.01745],LENGTHUNIT[\"metre\",1]]],"
         "CS[Cartesian,2],AXIS[\"easting (X)\",east,ORDER[1],LENGTHUNIT[\"US survey foot\","
         "0.304800609601219]]]",
         2},
        {"PROJCRS[\"WGS 84 / UTM zone 33N\",BASEGEOGCRS[\"WGS 84\",ANGLEUNIT[\"degree\","
         "0.0174532925199433]],CS[Cartesian,2],AXIS[\"(E)\",east,LENGTHUNIT[\"metre\",1]]]",
         0},
        {"GEOGCS[\"WGS 84\",UNIT[\"degree\",0.0174532925199433]]", 0},
        {"PROJCS[\"unterminated", 0},
        {"PROJCS[[[[[[[[", 0},
        {"]]]]PROJCS[\"a\"]]]]UNIT[\"foot\"", 0},
        {"PROJCS(\"a\",UNIT(\"feet\",0.3048))", 1},
        {"PROJCS[\"a \"\"quoted\"\" UNIT[\"\"foot\",UNIT[\"metre\",1]]", 0},
        {"", 0},
    };
    char *s;
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++)
        CHECK(t, gdt_mesh_crs_wkt_foot(cases[i].wkt) == cases[i].foot, "case %zu (%s): %d", i,
              cases[i].wkt, gdt_mesh_crs_wkt_foot(cases[i].wkt));
    CHECK(t, gdt_mesh_crs_wkt_foot(NULL) == 0, "NULL WKT");
    s = gdt_mesh_crs_wkt_of_epsg(32719, NULL);
    CHECK(t,
          s != NULL && strstr(s, "\"WGS 84 / UTM zone 19S\"") != NULL &&
              strstr(s, "\"central_meridian\",-69]") != NULL &&
              strstr(s, "\"false_northing\",10000000]") != NULL && gdt_mesh_crs_wkt_foot(s) == 0,
          "32719: %s", s ? s : "NULL");
    free(s);
    s = gdt_mesh_crs_wkt_of_epsg(26901, NULL);
    CHECK(t,
          s != NULL && strstr(s, "\"NAD83 / UTM zone 1N\"") != NULL &&
              strstr(s, "\"central_meridian\",-177]") != NULL,
          "26901: %s", s ? s : "NULL");
    free(s);
    s = gdt_mesh_crs_wkt_of_epsg(32761, NULL);
    CHECK(t,
          s != NULL && strstr(s, "UPS South") != NULL &&
              strstr(s, "\"latitude_of_origin\",-90]") != NULL,
          "32761: %s", s ? s : "NULL");
    free(s);
    static const int none[] = {0, 4326, 26924, 32600, 32662, 32700, 2227, 3857, -1};
    for (size_t i = 0; i < sizeof none / sizeof none[0]; i++) {
        s = gdt_mesh_crs_wkt_of_epsg(none[i], NULL);
        CHECK(t, s == NULL, "EPSG %d has WKT: %s", none[i], s);
        free(s);
    }
}

/* Removes the work folder (files, and the locale folder if made). */
/* ---- a text mesh written in parts ---------------------------------------- */

#define PT_NV 900
#define PT_NF 700

/* A mesh of PT_NV vertices and PT_NF faces; vertex blocks [vb[i], vb[i+1])
 * and face blocks [fb[i], fb[i+1]) (the last face block is the writer's
 * own, written after resuming). */
static const size_t PT_VB[4] = {0, 250, 251, PT_NV};
static const size_t PT_FB[5] = {0, 300, 300, 650, PT_NF};

static void parts_data(double *xyz, int32_t *tri)
{
    for (size_t i = 0; i < PT_NV; i++) {
        xyz[3 * i] = 480000.0 + 0.01 * (double)(i * 7919 % 100000);
        xyz[3 * i + 1] = 4860000.0 + 0.01 * (double)(i * 104729 % 100000);
        xyz[3 * i + 2] = 19064 * 0.01 + (double)i * 0.25;
    }
    for (size_t f = 0; f < PT_NF; f++) {
        tri[3 * f] = (int32_t)(f % PT_NV);
        tri[3 * f + 1] = (int32_t)((f * 31 + 1) % PT_NV);
        tri[3 * f + 2] = (int32_t)((f * 17 + 2) % PT_NV);
        if (tri[3 * f + 1] == tri[3 * f] || tri[3 * f + 2] == tri[3 * f] ||
            tri[3 * f + 2] == tri[3 * f + 1]) {
            tri[3 * f + 1] = (int32_t)((f + 1) % PT_NV);
            tri[3 * f + 2] = (int32_t)((f + 2) % PT_NV);
        }
    }
}

/* Writes the mesh in parts: fragments made in a scrambled order, placed at
 * their offsets (one of them shift bytes off), the writer's own faces
 * last.  returns the writer's status. */
static gdt_status write_in_parts(tctx *t, const char *path, gdt_mesh_format fmt, const double *xyz,
                                 const int32_t *tri, int shift)
{
    gdt_mesh_meta m = plain_meta();
    gdt_mesh_writer *w = NULL, *fw = NULL;
    gdt_mesh_part *part = NULL;
    gdt_error err;
    gdt_status st;
    uint64_t header = 0, vlen[3], flen[3], at;
    char frag[4200];
    static const int order[3] = {2, 0, 1};
    const char *sep = gdt_mesh_text_separator(fmt);

    gdt_error_clear(&err);
    st = gdt_mesh_create(&w, path, fmt, &m, &err);
    if (st == GDT_OK)
        st = gdt_mesh_begin_text_parts(w, &header, &err);
    for (int j = 0; st == GDT_OK && j < 3; j++) {
        int i = order[j];
        snprintf(frag, sizeof frag, "%s/frag.v%d", t->dir, i);
        st = gdt_mesh_fragment_create(&fw, frag, fmt, PT_VB[i], 0, &err);
        if (st == GDT_OK)
            st = gdt_mesh_write_vertices(fw, xyz + 3 * PT_VB[i], PT_VB[i + 1] - PT_VB[i], &err);
        if (st == GDT_OK)
            st = gdt_mesh_fragment_close(fw, &vlen[i], &err);
        else
            gdt_mesh_abort(fw);
        snprintf(frag, sizeof frag, "%s/frag.f%d", t->dir, i);
        if (st == GDT_OK)
            st = gdt_mesh_fragment_create(&fw, frag, fmt, PT_NV, 1, &err);
        if (st == GDT_OK)
            st = gdt_mesh_write_faces(fw, tri + 3 * PT_FB[i], PT_FB[i + 1] - PT_FB[i], &err);
        if (st == GDT_OK)
            st = gdt_mesh_fragment_close(fw, &flen[i], &err);
        else
            gdt_mesh_abort(fw);
    }
    if (st == GDT_OK)
        st = gdt_mesh_part_open(&part, gdt_mesh_temp_path(w), &err);
    at = header;
    for (int i = 0; st == GDT_OK && i < 3; i++) {
        snprintf(frag, sizeof frag, "%s/frag.v%d", t->dir, i);
        st = gdt_mesh_part_copy(part, frag, vlen[i], at + (i == 1 ? (uint64_t)shift : 0), &err);
        at += vlen[i];
    }
    if (st == GDT_OK)
        st = gdt_mesh_part_write(part, sep, strlen(sep), at, &err);
    at += strlen(sep);
    for (int i = 0; st == GDT_OK && i < 3; i++) {
        snprintf(frag, sizeof frag, "%s/frag.f%d", t->dir, i);
        st = gdt_mesh_part_copy(part, frag, flen[i], at, &err);
        at += flen[i];
    }
    if (st == GDT_OK)
        st = gdt_mesh_part_close(part, &err);
    else
        gdt_mesh_part_abort(part);
    if (st == GDT_OK)
        st = gdt_mesh_resume_text(w, at, PT_NV, PT_FB[3], &err);
    if (st == GDT_OK)
        st = gdt_mesh_write_faces(w, tri + 3 * PT_FB[3], PT_NF - PT_FB[3], &err);
    if (st == GDT_OK)
        st = gdt_mesh_finish(w, &err);
    else
        gdt_mesh_abort(w);
    CHECK(t, st == GDT_OK, "%s in parts: %s", path, err.msg);
    return st;
}

static void test_text_parts(tctx *t)
{
    static double xyz[3 * PT_NV];
    static int32_t tri[3 * PT_NF];
    const gdt_mesh_format fmts[2] = {GDT_MESH_OBJ, GDT_MESH_LANDXML};
    gdt_mesh_meta m = plain_meta();

    parts_data(xyz, tri);
    for (int q = 0; q < 2; q++) {
        char seq[4200], par[4200], off[4200], frag[4200];
        const char *ext = fmts[q] == GDT_MESH_OBJ ? "obj" : "xml";
        gdt_mesh_writer *w = NULL;
        gdt_mesh_part *p = NULL;
        gdt_error err;
        gdt_status st;
        size_t na = 0, nb = 0, nc = 0;
        char *a, *b, *c;
        uint64_t len = 0;

        /* one stem: LandXML names its surface after it */
        snprintf(seq, sizeof seq, "%s/seq.%s", t->dir, ext);
        snprintf(par, sizeof par, "%s/par", t->dir);
        mkdir(par, 0777);
        snprintf(par, sizeof par, "%s/par/seq.%s", t->dir, ext);
        snprintf(off, sizeof off, "%s/off", t->dir);
        mkdir(off, 0777);
        snprintf(off, sizeof off, "%s/off/seq.%s", t->dir, ext);
        gdt_error_clear(&err);
        st = gdt_mesh_create(&w, seq, fmts[q], &m, &err);
        if (st == GDT_OK)
            st = gdt_mesh_write_vertices(w, xyz, PT_NV, &err);
        if (st == GDT_OK)
            st = gdt_mesh_write_faces(w, tri, PT_NF, &err);
        if (st == GDT_OK)
            st = gdt_mesh_finish(w, &err);
        else
            gdt_mesh_abort(w);
        CHECK(t, st == GDT_OK, "%s: %s", seq, err.msg);
        write_in_parts(t, par, fmts[q], xyz, tri, 0);
        write_in_parts(t, off, fmts[q], xyz, tri, 1);
        a = slurp(seq, &na);
        b = slurp(par, &nb);
        c = slurp(off, &nc);
        CHECK(t, a != NULL && b != NULL && na == nb && memcmp(a, b, na) == 0,
              "%s written in parts differs from the sequential file (%zu / %zu bytes)", ext, nb,
              na);
        CHECK(t, c != NULL && (nc != na || memcmp(a, c, na) != 0),
              "%s: a fragment placed one byte off went unnoticed", ext);
        free(a);
        free(b);
        free(c);

        /* a fragment whose length is not the one announced is refused */
        snprintf(frag, sizeof frag, "%s/frag.v0", t->dir);
        st = gdt_mesh_fragment_create(&w, frag, fmts[q], 0, 0, &err);
        if (st == GDT_OK)
            st = gdt_mesh_write_vertices(w, xyz, 3, &err);
        if (st == GDT_OK)
            st = gdt_mesh_fragment_close(w, &len, &err);
        if (st == GDT_OK)
            st = gdt_mesh_part_open(&p, seq, &err);
        CHECK(t, st == GDT_OK, "fragment: %s", err.msg);
        if (st == GDT_OK) {
            st = gdt_mesh_part_copy(p, frag, len + 1, 0, &err);
            CHECK(t, st == GDT_EJOB && err.code == 6802, "a short fragment was copied (%d)",
                  (int)st);
            gdt_mesh_part_abort(p);
        }
        /* a face fragment takes no vertices */
        gdt_error_clear(&err);
        st = gdt_mesh_fragment_create(&w, frag, fmts[q], 0, 1, &err);
        if (st == GDT_OK) {
            st = gdt_mesh_write_vertices(w, xyz, 3, &err);
            CHECK(t, st != GDT_OK && err.code == 7713, "vertices in a face fragment: %s", err.msg);
            gdt_mesh_abort(w);
            CHECK(t, !exists(frag), "a failed fragment was left behind");
        }
        /* the temporary of a text mesh in parts must already exist */
        gdt_error_clear(&err);
        st = gdt_mesh_part_open(&p, off, &err);
        CHECK(t, st == GDT_OK, "opening a finished file as a part: %s", err.msg);
        gdt_mesh_part_abort(p);
        snprintf(frag, sizeof frag, "%s/none.%s.tmp-1", t->dir, ext);
        st = gdt_mesh_part_open(&p, frag, &err);
        CHECK(t, st == GDT_EIO && err.code == 4720 && !exists(frag),
              "a part created a missing temporary: %s", err.msg);
    }
}

static void remove_workdir(const tctx *t)
{
    char cmd[4200];
    snprintf(cmd, sizeof cmd, "rm -rf '%s'", t->dir);
    if (system(cmd) != 0)
        fprintf(stderr, "test_mesh_out: could not remove %s\n", t->dir);
}

int main(int argc, char **argv)
{
    tctx t;
    char tmpl[4096];
    int rc;

    memset(&t, 0, sizeof t);
    if (argc != 2) {
        fprintf(stderr, "usage: test_mesh_out WORKDIR\n");
        return 2;
    }
    snprintf(tmpl, sizeof tmpl, "%s/mesh_out_unit.XXXXXX", argv[1]);
    if (mkdtemp(tmpl) == NULL) {
        fprintf(stderr, "test_mesh_out: mkdtemp %s: %s\n", tmpl, strerror(errno));
        return 2;
    }
    snprintf(t.dir, sizeof t.dir, "%s", tmpl);

    test_numbers(&t);
    test_format_of(&t);
    test_obj(&t);
    test_xml(&t);
    test_sticky(&t);
    test_locale(&t);
    test_crs(&t);
    test_text_parts(&t);

    rc = gdt_check_finish(&t.c, "test_mesh_out");
    if (rc == 0)
        remove_workdir(&t);
    return rc;
}
