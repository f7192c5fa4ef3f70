/* test_ply — unit test of the streaming PLY writer.
 *
 *   test_ply WORKDIR
 *
 * Writes files in a fresh folder under WORKDIR and checks, byte by byte and
 * independently of the host byte order: the exact header, the records, the
 * file size, the temporary-then-rename protocol, and that every misuse
 * (vertices after faces, bad indices, bad comments, bad lattice, too many
 * vertices) is refused with its message number and leaves no file behind;
 * a file written in parts (gdt_ply_begin_parts, gdt_ply_part_*) has the
 * sequential writer's bytes, also in parts of many chunks written by two
 * part writers at once (their whole blocks directly), and a missing part
 * is refused.
 * The writer bypasses the page cache (O_DIRECT, whole 4 KiB blocks) where
 * the file system allows it; the large file crosses many block and buffer
 * boundaries with odd record counts per call.
 */
#define _GNU_SOURCE 1 /* O_DIRECT */
#include <dirent.h>
#include <errno.h>
#include <fcntl.h>
#include <inttypes.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "gdt_check.h"
#include "gdt_ply.h"

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
    return stat(p, &sb) == 0;
}

/* Number of entries in the work folder whose name starts with prefix. */
static int count_prefixed(const tctx *t, const char *prefix)
{
    int n = 0;
    struct dirent *e;
    DIR *d = opendir(t->dir);
    if (d == NULL)
        return -1;
    while ((e = readdir(d)) != NULL)
        if (strncmp(e->d_name, prefix, strlen(prefix)) == 0)
            n++;
    closedir(d);
    return n;
}

/* Removes the work folder, which holds only files once the tests ran. */
static void remove_workdir(const tctx *t)
{
    char p[4400];
    struct dirent *e;
    DIR *d = opendir(t->dir);
    if (d == NULL)
        return;
    while ((e = readdir(d)) != NULL) {
        if (strcmp(e->d_name, ".") == 0 || strcmp(e->d_name, "..") == 0)
            continue;
        snprintf(p, sizeof p, "%s/%s", t->dir, e->d_name);
        unlink(p);
    }
    closedir(d);
    rmdir(t->dir);
}

static unsigned char *slurp(const char *p, size_t *n)
{
    FILE *f = fopen(p, "rb");
    unsigned char *buf = NULL;
    long len;
    *n = 0;
    if (f == NULL)
        return NULL;
    if (fseek(f, 0, SEEK_END) != 0 || (len = ftell(f)) < 0 || fseek(f, 0, SEEK_SET) != 0)
        goto done;
    buf = malloc((size_t)len + 1);
    if (buf != NULL && fread(buf, 1, (size_t)len, f) != (size_t)len) {
        free(buf);
        buf = NULL;
        goto done;
    }
    *n = (size_t)len;
done:
    fclose(f);
    return buf;
}

static uint64_t le64(const unsigned char *p)
{
    uint64_t v = 0;
    for (int i = 7; i >= 0; i--)
        v = (v << 8) | p[i];
    return v;
}

static int32_t le32s(const unsigned char *p)
{
    uint32_t v = (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
    int32_t s;
    memcpy(&s, &v, sizeof s);
    return s;
}

static uint64_t bits_of(double d)
{
    uint64_t b;
    memcpy(&b, &d, sizeof b);
    return b;
}

static gdt_ply_meta plain_meta(void)
{
    gdt_ply_meta m;
    memset(&m, 0, sizeof m);
    m.lattice.sx = m.lattice.sy = 0.01;
    return m;
}

/* The header the writer must produce, with the given CRS line. */
static size_t expected_header(char *out, size_t size, const char *crs_line,
                              const char *lattice_line, const char *const *comments,
                              size_t ncomments, uint64_t v, uint64_t f)
{
    size_t n = (size_t)snprintf(out, size,
                                "ply\nformat binary_little_endian 1.0\n"
                                "comment generator gdt-tile %s\n%s\n%s\n",
                                GDT_TEST_VERSION, crs_line, lattice_line);
    for (size_t i = 0; i < ncomments; i++)
        n += (size_t)snprintf(out + n, size - n, "comment %s\n", comments[i]);
    n += (size_t)snprintf(out + n, size - n,
                          "element vertex %-20" PRIu64 "\nproperty double x\n"
                          "property double y\nproperty double z\n"
                          "element face %-20" PRIu64 "\n"
                          "property list uchar int vertex_indices\nend_header\n",
                          v, f);
    return n;
}

/* Checks header, size and every record of the file at path. */
static void check_file(tctx *t, const char *path, const char *header, size_t hlen,
                       const double *xyz, uint64_t v, const int32_t *tri, uint64_t f)
{
    size_t n = 0;
    unsigned char *buf = slurp(path, &n);
    CHECK(t, buf != NULL, "%s unreadable", path);
    if (buf == NULL)
        return;
    CHECK(t, n == hlen + 24 * v + 13 * f, "%s: size %zu, expected %zu", path, n,
          (size_t)(hlen + 24 * v + 13 * f));
    if (n != hlen + 24 * v + 13 * f) {
        free(buf);
        return;
    }
    CHECK(t, memcmp(buf, header, hlen) == 0, "%s: header differs:\n%.*s\nexpected:\n%s", path,
          (int)hlen, (const char *)buf, header);
    for (uint64_t i = 0; i < 3 * v; i++) {
        uint64_t got = le64(buf + hlen + 8 * i);
        if (got != bits_of(xyz[i])) {
            CHECK(t, got == bits_of(xyz[i]), "%s: coordinate %" PRIu64 " differs", path, i);
            break;
        }
    }
    for (uint64_t i = 0; i < f; i++) {
        const unsigned char *p = buf + hlen + 24 * v + 13 * i;
        if (p[0] != 3 || le32s(p + 1) != tri[3 * i] || le32s(p + 5) != tri[3 * i + 1] ||
            le32s(p + 9) != tri[3 * i + 2]) {
            CHECK(t, 0, "%s: face %" PRIu64 " differs", path, i);
            break;
        }
    }
    free(buf);
}

static void test_roundtrip(tctx *t)
{
    static const char *const comments[] = {"tile 4096 halo 12", "second\tline with tab"};
    const char wkt[] = "PROJCS[\"CH1903+ / LV95\",\r\n  GEOGCS[\"CH1903+\xc3\xa9\"]]";
    char path[4200], header[8192];
    gdt_ply_meta m = plain_meta();
    gdt_ply_writer *w = NULL;
    gdt_error err;
    double xyz[3 * 6] = {2600000.125, 1200000.5, 432.25, -0.0,   1e-320, -1.7976931348623157e308,
                         1.0 / 3.0,   -2.5,      0.0,    5e-324, 123.0,  -123.0,
                         7,           8,         9,      10,     11,     12};
    int32_t tri[3 * 4] = {0, 1, 2, 2, 1, 3, 5, 4, 3, 0, 5, 4};
    size_t hlen;

    gdt_error_clear(&err);
    path_in(t, path, sizeof path, "round.ply");
    m.lattice.sx = 0.001;
    m.lattice.sy = 0.25;
    m.lattice.ox = -123456.789;
    m.lattice.oy = 0.1;
    m.lattice.oy += 0.2; /* 0.30000000000000004: needs all 17 digits */
    m.crs_wkt = wkt;
    m.comments = comments;
    m.ncomments = 2;
    CHECK(t, gdt_ply_create(&w, path, &m, &err) == GDT_OK, "create: %s", err.msg);
    if (w == NULL)
        return;
    {
        char tmp[4300];
        snprintf(tmp, sizeof tmp, "%s.tmp-%ld", path, (long)getpid());
        CHECK(t, strcmp(gdt_ply_temp_path(w), tmp) == 0, "temp path %s", gdt_ply_temp_path(w));
        CHECK(t, exists(tmp), "temporary %s missing while writing", tmp);
    }
    CHECK(t, gdt_ply_write_vertices(w, xyz, 2, &err) == GDT_OK, "%s", err.msg);
    CHECK(t, gdt_ply_write_vertices(w, xyz + 6, 0, &err) == GDT_OK, "%s", err.msg);
    CHECK(t, gdt_ply_write_vertices(w, xyz + 6, 4, &err) == GDT_OK, "%s", err.msg);
    CHECK(t, gdt_ply_write_faces(w, tri, 1, &err) == GDT_OK, "%s", err.msg);
    CHECK(t, gdt_ply_write_faces(w, tri + 3, 3, &err) == GDT_OK, "%s", err.msg);
    CHECK(t, gdt_ply_vertex_count(w) == 6 && gdt_ply_face_count(w) == 4,
          "counts %" PRIu64 " %" PRIu64, gdt_ply_vertex_count(w), gdt_ply_face_count(w));
    CHECK(t, !exists(path), "final path exists before finish");
    CHECK(t, gdt_ply_finish(w, &err) == GDT_OK, "finish: %s", err.msg);
    CHECK(t, count_prefixed(t, "round.ply.tmp-") == 0, "temporary left after finish");
    hlen = expected_header(
        header, sizeof header, "comment crs PROJCS[\"CH1903+ / LV95\",    GEOGCS[\"CH1903+??\"]]",
        "comment lattice 0.001 0.25 -123456.789 0.30000000000000004", comments, 2, 6, 4);
    check_file(t, path, header, hlen, xyz, 6, tri, 4);
}

/* Header length does not depend on the counts; EPSG and unknown CRS lines. */
static void test_fixed_header(tctx *t)
{
    char p0[4200], p1[4200], header[4096];
    gdt_ply_meta m = plain_meta();
    gdt_ply_writer *w = NULL;
    gdt_error err;
    double xyz[12] = {1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12};
    int32_t tri[6] = {0, 1, 2, 3, 2, 1};
    size_t hlen;

    gdt_error_clear(&err);
    path_in(t, p0, sizeof p0, "empty.ply");
    path_in(t, p1, sizeof p1, "epsg.ply");
    m.crs_wkt = "";
    CHECK(t, gdt_ply_create(&w, p0, &m, &err) == GDT_OK, "%s", err.msg);
    CHECK(t, gdt_ply_finish(w, &err) == GDT_OK, "%s", err.msg);
    hlen = expected_header(header, sizeof header, "comment crs unknown",
                           "comment lattice 0.01 0.01 0 0", NULL, 0, 0, 0);
    check_file(t, p0, header, hlen, NULL, 0, NULL, 0);

    m.epsg = 2056;
    m.crs_wkt = "ignored when an EPSG code is given";
    CHECK(t, gdt_ply_create(&w, p1, &m, &err) == GDT_OK, "%s", err.msg);
    CHECK(t, gdt_ply_write_vertices(w, xyz, 4, &err) == GDT_OK, "%s", err.msg);
    CHECK(t, gdt_ply_write_faces(w, tri, 2, &err) == GDT_OK, "%s", err.msg);
    CHECK(t, gdt_ply_finish(w, &err) == GDT_OK, "%s", err.msg);
    CHECK(t,
          expected_header(header, sizeof header, "comment crs EPSG:2056",
                          "comment lattice 0.01 0.01 0 0", NULL, 0, 4,
                          2) == hlen + strlen("EPSG:2056") - strlen("unknown"),
          "header length depends on the counts");
    check_file(t, p1, header, strlen(header), xyz, 4, tri, 2);
}

/* Records crossing the internal buffer size many times, odd call sizes. */
static void test_large(tctx *t)
{
    const uint64_t nv = 100003, nf = 250007;
    char path[4200], header[4096];
    gdt_ply_meta m = plain_meta();
    gdt_ply_writer *w = NULL;
    gdt_error err;
    double *xyz = malloc(3 * nv * sizeof *xyz);
    int32_t *tri = malloc(3 * nf * sizeof *tri);
    uint64_t s = 42;

    gdt_error_clear(&err);
    path_in(t, path, sizeof path, "large.ply");
    if (xyz == NULL || tri == NULL)
        goto done;
    for (uint64_t i = 0; i < 3 * nv; i++) {
        uint64_t b = gdt_splitmix64(&s);
        memcpy(&xyz[i], &b, sizeof b);
        if (!isfinite(xyz[i]))
            xyz[i] = (double)(int64_t)b;
    }
    for (uint64_t i = 0; i < nf; i++) {
        tri[3 * i] = (int32_t)(i % nv);
        tri[3 * i + 1] = (int32_t)((i + 1 + gdt_splitmix64(&s) % (nv - 2)) % nv);
        do
            tri[3 * i + 2] = (int32_t)(gdt_splitmix64(&s) % nv);
        while (tri[3 * i + 2] == tri[3 * i] || tri[3 * i + 2] == tri[3 * i + 1]);
    }
    CHECK(t, gdt_ply_create(&w, path, &m, &err) == GDT_OK, "%s", err.msg);
    for (uint64_t i = 0; i < nv && w != NULL;) {
        size_t k = (size_t)(gdt_splitmix64(&s) % 20000);
        if (k > nv - i)
            k = (size_t)(nv - i);
        CHECK(t, gdt_ply_write_vertices(w, xyz + 3 * i, k, &err) == GDT_OK, "%s", err.msg);
        i += k;
    }
    for (uint64_t i = 0; i < nf && w != NULL;) {
        size_t k = (size_t)(gdt_splitmix64(&s) % 50000);
        if (k > nf - i)
            k = (size_t)(nf - i);
        CHECK(t, gdt_ply_write_faces(w, tri + 3 * i, k, &err) == GDT_OK, "%s", err.msg);
        i += k;
    }
    CHECK(t, gdt_ply_finish(w, &err) == GDT_OK, "%s", err.msg);
    check_file(t, path, header,
               expected_header(header, sizeof header, "comment crs unknown",
                               "comment lattice 0.01 0.01 0 0", NULL, 0, nv, nf),
               xyz, nv, tri, nf);
done:
    free(xyz);
    free(tri);
}

/* A refused call poisons the writer: finish reports the same error and
 * nothing is left, neither at the final path nor as a temporary. */
static void expect_refused(tctx *t, gdt_ply_writer *w, gdt_status st, const gdt_error *err,
                           gdt_status want, int code, const char *name, const char *what)
{
    char path[4200], prefix[512];
    gdt_error again;

    path_in(t, path, sizeof path, name);
    snprintf(prefix, sizeof prefix, "%s.tmp-", name);
    gdt_error_clear(&again);
    CHECK(t, st == want && err->code == code, "%s: status %d code %d (%s)", what, (int)st,
          err->code, err->msg);
    CHECK(t, strstr(err->msg, name) != NULL, "%s: message does not name the file: %s", what,
          err->msg);
    CHECK(t, count_prefixed(t, prefix) == 0, "%s: temporary not removed at once", what);
    CHECK(t, gdt_ply_write_faces(w, NULL, 0, &again) == want && again.code == code,
          "%s: writer usable after failure", what);
    gdt_error_clear(&again);
    CHECK(t, gdt_ply_finish(w, &again) == want && again.code == code, "%s: finish gave %d/%d", what,
          (int)again.status, again.code);
    CHECK(t, !exists(path), "%s: file at the final path", what);
}

static void test_misuse(tctx *t)
{
    const double xyz[12] = {0, 0, 0, 1, 0, 0, 0, 1, 0, 1, 1, 1};
    const int32_t ok[3] = {0, 1, 2};
    gdt_ply_meta m = plain_meta();
    char path[4200];
    gdt_error err;
    gdt_ply_writer *w = NULL;
    gdt_status st;

    path_in(t, path, sizeof path, "misuse.ply");

    gdt_error_clear(&err);
    gdt_ply_create(&w, path, &m, &err);
    gdt_ply_write_vertices(w, xyz, 3, &err);
    gdt_ply_write_faces(w, ok, 1, &err);
    st = gdt_ply_write_vertices(w, xyz + 9, 1, &err);
    expect_refused(t, w, st, &err, GDT_EINTERNAL, 7704, "misuse.ply", "vertex after face");

    gdt_error_clear(&err);
    gdt_ply_create(&w, path, &m, &err);
    gdt_ply_write_faces(w, NULL, 0, &err);
    st = gdt_ply_write_vertices(w, xyz, 0, &err);
    expect_refused(t, w, st, &err, GDT_EINTERNAL, 7704, "misuse.ply",
                   "empty vertex call after a face call");

    {
        static const int32_t bad[][3] = {
            {0, 1, 3}, {-1, 0, 1}, {0, 1, INT32_MAX}, {INT32_MIN, 1, 2}};
        for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
            gdt_error_clear(&err);
            gdt_ply_create(&w, path, &m, &err);
            gdt_ply_write_vertices(w, xyz, 3, &err);
            gdt_ply_write_faces(w, ok, 1, &err);
            st = gdt_ply_write_faces(w, bad[i], 1, &err);
            expect_refused(t, w, st, &err, GDT_EINTERNAL, 7705, "misuse.ply", "index out of range");
        }
    }

    gdt_error_clear(&err);
    gdt_ply_create(&w, path, &m, &err);
    st = gdt_ply_write_faces(w, ok, 1, &err);
    expect_refused(t, w, st, &err, GDT_EINTERNAL, 7705, "misuse.ply", "face before vertices");

    {
        static const int32_t rep[][3] = {{0, 0, 1}, {1, 2, 1}, {2, 1, 1}};
        for (size_t i = 0; i < sizeof rep / sizeof rep[0]; i++) {
            gdt_error_clear(&err);
            gdt_ply_create(&w, path, &m, &err);
            gdt_ply_write_vertices(w, xyz, 4, &err);
            st = gdt_ply_write_faces(w, rep[i], 1, &err);
            expect_refused(t, w, st, &err, GDT_EINTERNAL, 7706, "misuse.ply", "repeated index");
        }
    }

    {
        const double nonfinite[3][3] = {{NAN, 0, 0}, {0, INFINITY, 0}, {0, 0, -INFINITY}};
        for (size_t i = 0; i < 3; i++) {
            gdt_error_clear(&err);
            gdt_ply_create(&w, path, &m, &err);
            st = gdt_ply_write_vertices(w, nonfinite[i], 1, &err);
            expect_refused(t, w, st, &err, GDT_EINTERNAL, 7707, "misuse.ply", "non-finite vertex");
        }
    }

    /* The limit is checked before the array is read: xyz holds 4 vertices. */
    gdt_error_clear(&err);
    gdt_ply_create(&w, path, &m, &err);
    gdt_ply_write_vertices(w, xyz, 2, &err);
    st = gdt_ply_write_vertices(w, xyz, (size_t)(GDT_PLY_MAX_VERTICES - 1), &err);
    expect_refused(t, w, st, &err, GDT_EINPUT, 3701, "misuse.ply", "too many vertices");
    CHECK(t, strstr(err.msg, "2147483647") != NULL, "limit not named: %s", err.msg);

    gdt_error_clear(&err);
    gdt_ply_create(&w, path, &m, &err);
    st = gdt_ply_write_vertices(w, xyz, SIZE_MAX, &err);
    expect_refused(t, w, st, &err, GDT_EINPUT, 3701, "misuse.ply", "SIZE_MAX vertices");
}

static void expect_create_refused(tctx *t, const gdt_ply_meta *m, const char *name, gdt_status want,
                                  int code, const char *what)
{
    char path[4200], prefix[512];
    gdt_error err;
    gdt_ply_writer *w = (gdt_ply_writer *)&err; /* must be reset to NULL */
    gdt_status st;

    gdt_error_clear(&err);
    path_in(t, path, sizeof path, name);
    snprintf(prefix, sizeof prefix, "%s.tmp-", name);
    st = gdt_ply_create(&w, path, m, &err);
    CHECK(t, st == want && err.code == code, "%s: status %d code %d (%s)", what, (int)st, err.code,
          err.msg);
    CHECK(t, w == NULL, "%s: writer returned", what);
    if (w != NULL && st == GDT_OK)
        gdt_ply_abort(w);
    CHECK(t, count_prefixed(t, prefix) == 0, "%s: temporary left", what);
}

static void test_bad_meta(tctx *t)
{
    static const char *const nl[] = {"fine", "two\nlines"};
    static const char *const cr[] = {"carriage\rreturn"};
    static const char *const utf8[] = {"caf\xc3\xa9"};
    static const char *const nul[] = {"fine", NULL};
    gdt_ply_meta m = plain_meta();
    char path[4200];

    m.comments = nl;
    m.ncomments = 2;
    expect_create_refused(t, &m, "meta.ply", GDT_EINTERNAL, 7702, "comment with newline");
    m.comments = cr;
    m.ncomments = 1;
    expect_create_refused(t, &m, "meta.ply", GDT_EINTERNAL, 7702, "comment with CR");
    m.comments = utf8;
    expect_create_refused(t, &m, "meta.ply", GDT_EINTERNAL, 7702, "non-ASCII comment");
    m.comments = nul;
    m.ncomments = 2;
    expect_create_refused(t, &m, "meta.ply", GDT_EINTERNAL, 7701, "NULL comment");
    m.comments = NULL;
    expect_create_refused(t, &m, "meta.ply", GDT_EINTERNAL, 7701, "NULL comment array");
    m.ncomments = 0;

    m.lattice.sx = 0.0;
    expect_create_refused(t, &m, "meta.ply", GDT_EINTERNAL, 7703, "zero spacing");
    m.lattice.sx = 0.5;
    m.lattice.sy = -1.0;
    expect_create_refused(t, &m, "meta.ply", GDT_EINTERNAL, 7703, "negative spacing");
    m.lattice.sy = NAN;
    expect_create_refused(t, &m, "meta.ply", GDT_EINTERNAL, 7703, "NaN spacing");
    m.lattice.sy = 1.0;
    m.lattice.oy = INFINITY;
    expect_create_refused(t, &m, "meta.ply", GDT_EINTERNAL, 7703, "infinite origin");
    m.lattice.oy = 0.0;
    m.epsg = -4326;
    expect_create_refused(t, &m, "meta.ply", GDT_EINTERNAL, 7701, "negative EPSG");
    m.epsg = 0;

    expect_create_refused(t, &m, "no-such-dir/out.ply", GDT_EIO, 4701, "missing directory");
    expect_create_refused(t, &m, "", GDT_EIO, 4707, "work folder as output");
    path_in(t, path, sizeof path, "subdir");
    CHECK(t, mkdir(path, 0777) == 0, "mkdir %s: %s", path, strerror(errno));
    expect_create_refused(t, &m, "subdir", GDT_EIO, 4707, "directory as output");
    expect_create_refused(t, &m, "subdir/", GDT_EIO, 4707, "trailing slash");
    rmdir(path);
    expect_create_refused(t, NULL, "meta.ply", GDT_EINTERNAL, 7701, "NULL meta");
    CHECK(t, !exists(path), "leftover");
}

/* An existing file is replaced only by a complete one; abort leaves it. */
static void test_replace_and_abort(tctx *t)
{
    const double xyz[9] = {1, 2, 3, 4, 5, 6, 7, 8, 9};
    const int32_t tri[3] = {2, 0, 1};
    gdt_ply_meta m = plain_meta();
    char path[4200], header[4096];
    gdt_ply_writer *w = NULL;
    gdt_error err;
    size_t n = 0;
    unsigned char *old;
    FILE *f;

    gdt_error_clear(&err);
    path_in(t, path, sizeof path, "replace.ply");
    f = fopen(path, "wb");
    CHECK(t, f != NULL, "cannot create %s", path);
    if (f == NULL)
        return;
    fputs("previous content", f);
    fclose(f);

    CHECK(t, gdt_ply_create(&w, path, &m, &err) == GDT_OK, "%s", err.msg);
    gdt_ply_write_vertices(w, xyz, 3, &err);
    gdt_ply_abort(w);
    old = slurp(path, &n);
    CHECK(t, old != NULL && n == 16 && memcmp(old, "previous content", 16) == 0,
          "abort touched the existing file");
    free(old);
    CHECK(t, count_prefixed(t, "replace.ply.tmp-") == 0, "abort left the temporary");
    gdt_ply_abort(NULL);

    w = NULL;
    CHECK(t, gdt_ply_create(&w, path, &m, &err) == GDT_OK, "%s", err.msg);
    gdt_ply_write_vertices(w, xyz, 3, &err);
    gdt_ply_write_faces(w, tri, 1, &err);
    CHECK(t, gdt_ply_finish(w, &err) == GDT_OK, "%s", err.msg);
    check_file(t, path, header,
               expected_header(header, sizeof header, "comment crs unknown",
                               "comment lattice 0.01 0.01 0 0", NULL, 0, 3, 1),
               xyz, 3, tri, 1);
    CHECK(t, gdt_ply_finish(NULL, &err) == GDT_EINTERNAL, "finish(NULL) accepted");
}

/* An output path that is, or becomes while the mesh is written, a FIFO or
 * a symbolic link is never renamed over (a rename would replace the node
 * or the link itself). */
static void test_special_path_kept(tctx *t)
{
    const double xyz[9] = {1, 2, 3, 4, 5, 6, 7, 8, 9};
    const int32_t tri[3] = {2, 0, 1};
    gdt_ply_meta m = plain_meta();
    char path[4200], link_path[4200];
    gdt_ply_writer *w = NULL;
    gdt_error err;
    struct stat sb;

    gdt_error_clear(&err);
    path_in(t, path, sizeof path, "fifo.ply");
    path_in(t, link_path, sizeof link_path, "link.ply");
    CHECK(t, mkfifo(path, 0600) == 0, "mkfifo %s: %s", path, strerror(errno));
    CHECK(t, symlink("fifo.ply", link_path) == 0, "symlink: %s", strerror(errno));
    CHECK(t, gdt_ply_create(&w, path, &m, &err) == GDT_EIO && err.code == 4010 && w == NULL,
          "create over a FIFO: %d %d %s", (int)err.status, err.code, err.msg);
    gdt_error_clear(&err);
    CHECK(t, gdt_ply_create(&w, link_path, &m, &err) == GDT_EIO && err.code == 4010,
          "create over a link: %d %d %s", (int)err.status, err.code, err.msg);

    /* the FIFO appears while the mesh is written */
    unlink(path);
    gdt_error_clear(&err);
    w = NULL;
    CHECK(t, gdt_ply_create(&w, path, &m, &err) == GDT_OK, "%s", err.msg);
    if (w == NULL)
        return;
    gdt_ply_write_vertices(w, xyz, 3, &err);
    gdt_ply_write_faces(w, tri, 1, &err);
    CHECK(t, mkfifo(path, 0600) == 0, "mkfifo %s: %s", path, strerror(errno));
    CHECK(t, gdt_ply_finish(w, &err) == GDT_EIO && err.code == 4010,
          "finish over a FIFO: %d %d %s", (int)err.status, err.code, err.msg);
    CHECK(t, lstat(path, &sb) == 0 && S_ISFIFO(sb.st_mode), "the FIFO was replaced");
    CHECK(t, count_prefixed(t, "fifo.ply.tmp-") == 0, "temporary left after the refusal");
}

/* A file written in parts (vertex and face blocks in shuffled order, by two
 * part writers) has the bytes of the same records written in sequence; a
 * missing last part is refused; parts and sequential writes do not mix. */
static void test_parts(tctx *t)
{
    enum { NV = 1000, NF = 1500 };
    char seq[4200], par[4200];
    gdt_ply_meta m = plain_meta();
    gdt_ply_writer *w = NULL;
    gdt_ply_part *p[2] = {NULL, NULL};
    gdt_error err;
    double *xyz = malloc(3 * NV * sizeof *xyz);
    int32_t *tri = malloc(3 * NF * sizeof *tri);
    uint64_t hb = 0, vb[5] = {0, 1, 333, 700, NV}, fb[5] = {0, 499, 500, 1234, NF};
    unsigned char *a, *b;
    size_t na = 0, nb = 0;

    gdt_error_clear(&err);
    for (int i = 0; i < 3 * NV; i++)
        xyz[i] = 1000.0 * i + 1.0 / (i + 1);
    for (int f = 0; f < NF; f++) {
        tri[3 * f] = f % NV;
        tri[3 * f + 1] = (f * 7 + 1) % NV;
        tri[3 * f + 2] = (f * 13 + 2) % NV;
        if (tri[3 * f + 1] == tri[3 * f] || tri[3 * f + 2] == tri[3 * f] ||
            tri[3 * f + 2] == tri[3 * f + 1])
            tri[3 * f] = tri[3 * f + 1] = 0, tri[3 * f + 1] = 1, tri[3 * f + 2] = 2;
    }
    path_in(t, seq, sizeof seq, "seq.ply");
    path_in(t, par, sizeof par, "par.ply");
    CHECK(t, gdt_ply_create(&w, seq, &m, &err) == GDT_OK, "%s", err.msg);
    CHECK(t, gdt_ply_write_vertices(w, xyz, NV, &err) == GDT_OK, "%s", err.msg);
    CHECK(t, gdt_ply_write_faces(w, tri, NF, &err) == GDT_OK, "%s", err.msg);
    CHECK(t, gdt_ply_finish(w, &err) == GDT_OK, "%s", err.msg);

    CHECK(t, gdt_ply_create(&w, par, &m, &err) == GDT_OK, "%s", err.msg);
    CHECK(t, gdt_ply_begin_parts(w, NV, &hb, &err) == GDT_OK && hb > 100, "%s", err.msg);
    CHECK(t, gdt_ply_part_open(&p[0], gdt_ply_temp_path(w), hb, NV, &err) == GDT_OK, "%s",
          err.msg);
    CHECK(t, gdt_ply_part_open(&p[1], gdt_ply_temp_path(w), hb, NV, &err) == GDT_OK, "%s",
          err.msg);
    /* the blocks from the last to the first, alternating writers */
    for (int i = 3; i >= 0; i--) {
        CHECK(t, gdt_ply_part_faces(p[i % 2], fb[i], tri + 3 * fb[i], fb[i + 1] - fb[i], &err) ==
                     GDT_OK, "faces: %s", err.msg);
        CHECK(t, gdt_ply_part_vertices(p[(i + 1) % 2], vb[i], xyz + 3 * vb[i], vb[i + 1] - vb[i],
                                       &err) == GDT_OK, "vertices: %s", err.msg);
    }
    CHECK(t, gdt_ply_part_vertices(p[0], NV - 1, xyz, 2, &err) == GDT_EINTERNAL &&
                 err.code == 7722, "vertex beyond V: %d", err.code);
    {
        int32_t bad[3] = {0, 1, NV};
        gdt_error_clear(&err);
        CHECK(t, gdt_ply_part_faces(p[0], 0, bad, 1, &err) == GDT_EINTERNAL && err.code == 7705,
              "face index beyond V: %d", err.code);
    }
    gdt_error_clear(&err);
    CHECK(t, gdt_ply_write_faces(w, tri, 1, &err) == GDT_EINTERNAL && err.code == 7720,
          "sequential face after parts: %d", err.code);
    gdt_ply_abort(w); /* the sticky failure removed the temporary */
    gdt_ply_part_abort(p[0]);
    gdt_ply_part_abort(p[1]);

    /* again, cleanly */
    gdt_error_clear(&err);
    CHECK(t, gdt_ply_create(&w, par, &m, &err) == GDT_OK, "%s", err.msg);
    CHECK(t, gdt_ply_begin_parts(w, NV, &hb, &err) == GDT_OK, "%s", err.msg);
    CHECK(t, gdt_ply_part_open(&p[0], gdt_ply_temp_path(w), hb, NV, &err) == GDT_OK, "%s",
          err.msg);
    for (int i = 3; i >= 0; i--) {
        CHECK(t, gdt_ply_part_faces(p[0], fb[i], tri + 3 * fb[i], fb[i + 1] - fb[i], &err) ==
                     GDT_OK, "faces: %s", err.msg);
        CHECK(t, gdt_ply_part_vertices(p[0], vb[i], xyz + 3 * vb[i], vb[i + 1] - vb[i], &err) ==
                     GDT_OK, "vertices: %s", err.msg);
    }
    CHECK(t, gdt_ply_part_close(p[0], &err) == GDT_OK, "%s", err.msg);
    CHECK(t, gdt_ply_finish_parts(w, NF, &err) == GDT_OK, "%s", err.msg);
    a = slurp(seq, &na);
    b = slurp(par, &nb);
    CHECK(t, a != NULL && b != NULL && na == nb && memcmp(a, b, na) == 0,
          "parts differ from the sequential file (%zu and %zu bytes)", na, nb);
    free(a);
    free(b);

    /* the last face block missing: refused, nothing at the path */
    unlink(par);
    gdt_error_clear(&err);
    CHECK(t, gdt_ply_create(&w, par, &m, &err) == GDT_OK, "%s", err.msg);
    CHECK(t, gdt_ply_begin_parts(w, NV, &hb, &err) == GDT_OK, "%s", err.msg);
    CHECK(t, gdt_ply_part_open(&p[0], gdt_ply_temp_path(w), hb, NV, &err) == GDT_OK, "%s",
          err.msg);
    CHECK(t, gdt_ply_part_vertices(p[0], 0, xyz, NV, &err) == GDT_OK, "%s", err.msg);
    CHECK(t, gdt_ply_part_faces(p[0], 0, tri, NF - 1, &err) == GDT_OK, "%s", err.msg);
    CHECK(t, gdt_ply_part_close(p[0], &err) == GDT_OK, "%s", err.msg);
    gdt_error_clear(&err);
    CHECK(t, gdt_ply_finish_parts(w, NF, &err) == GDT_EINTERNAL && err.code == 7721,
          "a missing part: %d %s", err.code, err.msg);
    CHECK(t, !exists(par) && count_prefixed(t, "par.ply.tmp-") == 0,
          "%s", "a file left after a refused finish");
    /* parts after a record */
    gdt_error_clear(&err);
    CHECK(t, gdt_ply_create(&w, par, &m, &err) == GDT_OK, "%s", err.msg);
    CHECK(t, gdt_ply_write_vertices(w, xyz, 1, &err) == GDT_OK, "%s", err.msg);
    gdt_error_clear(&err);
    CHECK(t, gdt_ply_begin_parts(w, NV, &hb, &err) == GDT_EINTERNAL && err.code == 7720,
          "parts after a record: %d", err.code);
    gdt_ply_abort(w);
    CHECK(t, count_prefixed(t, "par.ply.tmp-") == 0, "%s", "temporary left");
    free(xyz);
    free(tri);
}

/* Whether the directory of path takes direct I/O (O_DIRECT), as the part
 * writers' direct writes need. */
static int takes_direct_io(const char *path)
{
    int fd = open(path, O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC | O_DIRECT, 0600);
    if (fd >= 0)
        close(fd);
    unlink(path);
    return fd >= 0;
}

/* Parts of several chunks each, written by two part writers at once in
 * shuffled order with boundaries at no block multiple, have the bytes of
 * the sequential file: the whole blocks inside a chunk go out with direct
 * I/O (where the file system takes it: counted by the writers), the
 * partial blocks at the chunks' ends, shared between writers, through the
 * page cache; flush reports nothing failed. */
static void test_parts_chunks(tctx *t)
{
    enum { NV = 140003, NF = 280011, NB = 7 };
    char seq[4200], par[4200], probe[4200];
    gdt_ply_meta m = plain_meta();
    gdt_ply_writer *w = NULL;
    gdt_ply_part *p[2] = {NULL, NULL};
    gdt_error err;
    double *xyz = malloc(3 * (size_t)NV * sizeof *xyz);
    int32_t *tri = malloc(3 * (size_t)NF * sizeof *tri);
    /* the blocks' bounds: a few records, then chunks and more */
    const uint64_t vb[NB + 1] = {0, 3, 4100, 50001, 50002, 97777, 131072, NV};
    const uint64_t fb[NB + 1] = {0, 1, 80659, 80660, 161319, 200000, 279000, NF};
    const int order[NB] = {5, 0, 3, 6, 1, 4, 2};
    uint64_t hb = 0, direct = 0;
    unsigned char *a, *b;
    size_t na = 0, nb = 0;

    CHECK(t, xyz != NULL && tri != NULL, "%s", "out of memory");
    if (xyz == NULL || tri == NULL) {
        free(xyz);
        free(tri);
        return;
    }
    gdt_error_clear(&err);
    for (int i = 0; i < 3 * NV; i++)
        xyz[i] = 0.5 * i - 1.0 / (i + 3);
    for (int f = 0; f < NF; f++) {
        tri[3 * f] = f % NV;
        tri[3 * f + 1] = (f + 1) % NV;
        tri[3 * f + 2] = (f + 2) % NV;
    }
    path_in(t, seq, sizeof seq, "chunks-seq.ply");
    path_in(t, par, sizeof par, "chunks-par.ply");
    path_in(t, probe, sizeof probe, "direct-probe");
    CHECK(t, gdt_ply_create(&w, seq, &m, &err) == GDT_OK, "%s", err.msg);
    CHECK(t, gdt_ply_write_vertices(w, xyz, NV, &err) == GDT_OK, "%s", err.msg);
    CHECK(t, gdt_ply_write_faces(w, tri, NF, &err) == GDT_OK, "%s", err.msg);
    CHECK(t, gdt_ply_finish(w, &err) == GDT_OK, "%s", err.msg);

    CHECK(t, gdt_ply_create(&w, par, &m, &err) == GDT_OK, "%s", err.msg);
    CHECK(t, gdt_ply_begin_parts(w, NV, &hb, &err) == GDT_OK, "%s", err.msg);
    for (int i = 0; i < 2; i++)
        CHECK(t, gdt_ply_part_open(&p[i], gdt_ply_temp_path(w), hb, NV, &err) == GDT_OK, "%s",
              err.msg);
    for (int j = 0; j < NB && p[0] != NULL && p[1] != NULL; j++) {
        int i = order[j];
        CHECK(t, gdt_ply_part_vertices(p[j % 2], vb[i], xyz + 3 * vb[i], vb[i + 1] - vb[i],
                                       &err) == GDT_OK, "vertices: %s", err.msg);
        CHECK(t, gdt_ply_part_faces(p[(j + 1) % 2], fb[i], tri + 3 * fb[i], fb[i + 1] - fb[i],
                                    &err) == GDT_OK, "faces: %s", err.msg);
    }
    for (int i = 0; i < 2 && p[i] != NULL; i++) {
        CHECK(t, gdt_ply_part_flush(p[i], &err) == GDT_OK, "flush: %s", err.msg);
        direct += gdt_ply_part_direct_bytes(p[i]);
        CHECK(t, gdt_ply_part_close(p[i], &err) == GDT_OK, "%s", err.msg);
    }
    CHECK(t, gdt_ply_finish_parts(w, NF, &err) == GDT_OK, "%s", err.msg);
    a = slurp(seq, &na);
    b = slurp(par, &nb);
    CHECK(t, a != NULL && b != NULL && na == nb && memcmp(a, b, na) == 0,
          "parts in chunks differ from the sequential file (%zu and %zu bytes)", na, nb);
    /* most of the records' bytes went directly, whole blocks only */
    if (takes_direct_io(probe))
        CHECK(t, direct % 4096 == 0 && direct > (uint64_t)na * 9 / 10,
              "%" PRIu64 " of %zu bytes written with direct I/O", direct, na);
    else
        CHECK(t, direct == 0, "%" PRIu64 " bytes direct where O_DIRECT is refused", direct);
    free(a);
    free(b);
    free(xyz);
    free(tri);
}

int main(int argc, char **argv)
{
    tctx t;
    char tmpl[4096];

    memset(&t, 0, sizeof t);
    if (argc != 2) {
        fprintf(stderr, "usage: test_ply WORKDIR\n");
        return 2;
    }
    snprintf(tmpl, sizeof tmpl, "%s/ply_unit.XXXXXX", argv[1]);
    if (mkdtemp(tmpl) == NULL) {
        fprintf(stderr, "test_ply: mkdtemp %s: %s\n", tmpl, strerror(errno));
        return 2;
    }
    snprintf(t.dir, sizeof t.dir, "%s", tmpl);

    test_roundtrip(&t);
    test_fixed_header(&t);
    test_large(&t);
    test_misuse(&t);
    test_bad_meta(&t);
    test_replace_and_abort(&t);
    test_special_path_kept(&t);
    test_parts(&t);
    test_parts_chunks(&t);

    int rc = gdt_check_finish(&t.c, "test_ply");
    if (rc == 0)
        remove_workdir(&t);
    return rc;
}
